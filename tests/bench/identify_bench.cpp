// Identification benchmark: the sample scene (sample_scenes/capture_cup.json, a cup of honey
// draining through its hole onto the ground) against a synthetic reference, with and without the
// coarse phase of the multi-fidelity schedule. Prints wall time, evaluations, where the time goes
// (simulation vs silhouettes, per resolution) and the identified η against the truth.
//
//   identify_bench [--resolution 24] [--reference-resolution 32] [--frames 30] [--generations 12]
//                  [--coarse-generations N] [--coarse-factor 1] [--coarse-time-share 0.333]
//                  [--time-budget S] [--eta 8] [--threads 0] [--keep DIR] [--no-single]
//
// The reference is simulated at --reference-resolution with another particle seed, its surface
// meshed and filled by the exact rasterizer at twice the scoring camera's resolution, then area-
// downsampled; the identification scores the fast band splat. The issue's goal (≤ 60 frames, 48³,
// ≤ 10 min on 2 cores) is `--resolution 48 --reference-resolution 64 --frames 60 --generations 40
// --time-budget 600 --no-single`.
#include "identify/identify.h"

#include "sim/sim.h"
#include "surface/surface.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <openvdb/openvdb.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace viscoscope;

namespace {

json cameraJson(int scale) {  // a side view of cup and ground, looking along +y
    const double f = 300.0 * scale, w = 160.0 * scale, h = 120.0 * scale;
    return {{"format", "viscoscope.camera"}, {"version", 1}, {"width", int(w)}, {"height", int(h)},
            {"K", {{f, 0, (w - 1) / 2}, {0, f, (h - 1) / 2}, {0, 0, 1}}}, {"distortion", {0, 0, 0, 0, 0}},
            {"R", {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}}, {"t", {0, 0.09, 0.5}}};
}

void writeReference(const Scene& base, double eta, int resolution, int frames, const fs::path& dir) {
    fs::create_directories(dir / "masks");
    Scene scene = base;
    scene.material.viscosity = eta;
    scene.domain.resolution = resolution;
    scene.seed = base.seed + 1000;
    const PinholeCamera fine = parseCamera(cameraJson(2), "reference camera");
    sim::Simulation simulation(scene);
    ReferenceManifest manifest;
    manifest.source = "identify_bench synthetic";
    manifest.fps = scene.fps;
    manifest.width = 160;
    manifest.height = 120;
    for (int frame = 1; frame <= frames; ++frame) {
        simulation.advanceFrame();
        if (frame % 3) continue;  // every third frame
        const auto levelSet = surface::liquidLevelSet(simulation);
        cv::Mat small;
        cv::resize(silhouetteFromLevelSet(*levelSet, fine), small, cv::Size(160, 120), 0, 0, cv::INTER_AREA);
        char name[32];
        std::snprintf(name, sizeof name, "masks/mask_%05d.png", frame);
        cv::imwrite((dir / name).string(), cv::Mat1b(small >= 128));
        manifest.frames.push_back(frame);
        manifest.times.push_back(frame / scene.fps);
        manifest.weights.push_back(1);
        manifest.maskFiles.push_back(name);
    }
    saveReferenceManifest(manifest, dir);
}

void printRun(const char* label, const identify::IdentificationResult& r, double truth) {
    const json& t = r.document.at("timings");
    const double vertex = r.document.at("viscosity").at("profile_fit").value("theta_min", NAN);
    std::printf("%-22s eta* = %8.4f Pa·s  error %5.1f %%  interval [%.3f, %.3f] (%s)  E %.5f\n", label, r.theta[0],
                100 * std::abs(r.theta[0] - truth) / truth, r.interval[0][0], r.interval[0][1],
                r.intervalMethod.c_str(), r.E);
    std::printf("%-22s profile vertex %.4f Pa·s (error %.1f %%; not used as θ*)\n", "", vertex,
                100 * std::abs(vertex - truth) / truth);
    std::printf("%-22s %d generations, %ld evaluations, stop %s, wall %.1f s, Σ evaluation time %.1f s\n", "",
                r.generations, r.evaluations, identify::toString(r.stop), t.at("wall_s").get<double>(),
                t.at("evaluation_cpu_s").get<double>());
    for (const auto& [fidelity, v] : t.at("per_fidelity").items())
        std::printf("%-22s   %s (%d³, frames 0..%d): %d evaluations, %.2f s each (simulation %.0f %%, silhouettes "
                    "%.0f %%)\n", "", fidelity.c_str(), v.at("resolution").get<int>(), v.at("frames").get<int>(),
                    v.at("evaluations").get<int>(), v.at("mean_seconds").get<double>(),
                    100 * v.at("simulation_s").get<double>() / v.at("seconds").get<double>(),
                    100 * v.at("silhouette_s").get<double>() / v.at("seconds").get<double>());
    // The budget rule's prediction of a full-fidelity generation, made at the switch, against them.
    double predicted = NAN, fullSeconds = 0;
    int fullGenerations = 0;
    for (const json& g : r.document.at("history")) {
        if (g.contains("predicted_fine_generation_s")) predicted = g.at("predicted_fine_generation_s").get<double>();
        if (g.at("fidelity") == "full") fullSeconds += g.at("seconds").get<double>(), ++fullGenerations;
    }
    if (std::isfinite(predicted) && fullGenerations > 0)
        std::printf("%-22s full generation: predicted %.1f s at the switch, measured %.1f s (mean of %d), ratio %.2f\n",
                    "", predicted, fullSeconds / fullGenerations, fullGenerations,
                    fullSeconds / fullGenerations / predicted);
}

}  // namespace

int main(int argc, char** argv) {
    int resolution = 24, referenceResolution = 32, frames = 30, generations = 12, coarseGenerations = -1, threads = 0;
    double eta = 8, timeBudget = 0;
    const identify::FidelitySchedule defaults;
    double coarseFactor = defaults.coarseFactor, coarseTimeShare = defaults.coarseTimeShare;
    bool single = true;
    fs::path keep;
    for (int i = 1; i < argc; ++i) {
        auto next = [&] { return i + 1 < argc ? argv[++i] : (std::fprintf(stderr, "missing value\n"), std::exit(2), ""); };
        if (!std::strcmp(argv[i], "--resolution")) resolution = std::atoi(next());
        else if (!std::strcmp(argv[i], "--reference-resolution")) referenceResolution = std::atoi(next());
        else if (!std::strcmp(argv[i], "--frames")) frames = std::atoi(next());
        else if (!std::strcmp(argv[i], "--generations")) generations = std::atoi(next());
        else if (!std::strcmp(argv[i], "--coarse-generations")) coarseGenerations = std::atoi(next());
        else if (!std::strcmp(argv[i], "--coarse-factor")) coarseFactor = std::atof(next());
        else if (!std::strcmp(argv[i], "--coarse-time-share")) coarseTimeShare = std::atof(next());
        else if (!std::strcmp(argv[i], "--time-budget")) timeBudget = std::atof(next());
        else if (!std::strcmp(argv[i], "--eta")) eta = std::atof(next());
        else if (!std::strcmp(argv[i], "--threads")) threads = std::atoi(next());
        else if (!std::strcmp(argv[i], "--keep")) keep = next();
        else if (!std::strcmp(argv[i], "--no-single")) single = false;
        else return std::fprintf(stderr, "unknown option %s\n", argv[i]), 2;
    }
    openvdb::initialize();
    const fs::path dir = keep.empty() ? fs::temp_directory_path() / ("viscoscope_identify_bench_" + std::to_string(getpid()))
                                      : keep;
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path sceneFile = fs::path(__FILE__).parent_path().parent_path().parent_path() / "sample_scenes" / "capture_cup.json";
    const Scene base = loadScene(sceneFile);
    using Clock = std::chrono::steady_clock;
    auto t0 = Clock::now();
    writeReference(base, eta, referenceResolution, frames, dir / "reference");
    std::printf("reference: eta %.3g Pa·s at %d³, seed %u, %d frames → %.1f s\n", eta, referenceResolution,
                base.seed + 1000, frames, std::chrono::duration<double>(Clock::now() - t0).count());
    std::ofstream(dir / "camera.json") << cameraJson(1).dump(1);
    json doc{{"format", "viscoscope.job"}, {"version", 1}, {"scene", sceneFile.string()}, {"camera", "camera.json"},
             {"silhouettes", "reference"},
             {"parameters", {{{"name", "viscosity"}, {"initial", 30.0}, {"spread", 30.0}, {"min", 1e-2}, {"max", 1e3}}}},
             {"resolution", resolution}, {"max_generations", generations}, {"tolerance_x", 0.01}, {"seed", 1},
             {"fidelity", {{"coarse_generations", coarseGenerations}, {"coarse_factor", coarseFactor},
                           {"coarse_time_share", coarseTimeShare}}},
             {"time_budget_s", timeBudget}};
    std::printf("identification: %d³ (coarse %d³ over %.0f %% of the clip), %d frames, ≤ %d generations, threads %s\n",
                resolution, std::max(8, int(std::lround(coarseFactor * resolution))), 100 * coarseTimeShare, frames,
                generations,
                threads ? std::to_string(threads).c_str() : "all");
    identify::IdentifyOptions options;
    options.threads = threads;
    options.writeFields = false;
    options.onGeneration = [](const identify::GenerationReport& r) {
        std::printf("  gen %2d %-6s res %2d evals %3ld best eta %8.4f E %.5f sigma %.3f elapsed %6.1f s left %6.1f s\n",
                    r.generation, r.coarse ? "coarse" : "full", r.resolution, r.evaluations, r.bestTheta.empty() ? NAN : r.bestTheta[0], r.bestE,
                    r.sigma, r.elapsed, r.remaining);
        std::fflush(stdout);
    };
    std::ofstream(dir / "job.json") << doc.dump(1);
    const auto multi = identify::identify(identify::loadJob(dir / "job.json"), dir / "multi_fidelity", options);
    printRun("multi-fidelity:", multi, eta);
    if (single) {
        doc["fidelity"] = {{"coarse_generations", 0}};
        std::ofstream(dir / "job_single.json") << doc.dump(1);
        const auto one = identify::identify(identify::loadJob(dir / "job_single.json"), dir / "single_fidelity", options);
        printRun("single fidelity:", one, eta);
        std::printf("wall ratio multi/single: %.2f\n", multi.seconds / one.seconds);
    }
    if (keep.empty()) fs::remove_all(dir);
    else std::printf("outputs kept in %s\n", dir.c_str());
    return 0;
}
