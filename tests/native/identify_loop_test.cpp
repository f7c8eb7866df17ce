// The identification loop on a synthetic reference that avoids the inverse crime: the reference is
// simulated at another resolution (24 against the job's 20, or 16 where a test evaluates θ alone)
// and particle seed (11 vs 3), its surface is meshed and filled by the exact rasterizer into a
// camera of twice the resolution, and the masks are then area-downsampled to the scoring camera's
// size (identify draws its own silhouettes with the same exact fill, its default, at that size).
// Scene: a viscous column of 1400 kg/m³ liquid collapsing along x (front speed ∝ 1/η early on).
#include "identify/identify.h"
#include "identify/search_state.h"

#include "collapsing_column.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <openvdb/openvdb.h>
#include <tbb/task_arena.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>

namespace {

namespace fs = std::filesystem;
using namespace viscoscope;
using column::columnJobJson;
using column::sceneJson;
using column::writeMeasuredTrack;
using json = nlohmann::json;

constexpr double kEtaTrue = 3.0;

// A side camera looking along +y at the x–z plane; `scale` multiplies the image size and focal length.
json cameraJson(int scale) {
    const double f = 200.0 * scale, w = 96.0 * scale, h = 64.0 * scale;
    return {{"format", "viscoscope.camera"},
            {"version", 1},
            {"width", static_cast<int>(w)},
            {"height", static_cast<int>(h)},
            {"K", {{f, 0, (w - 1) / 2}, {0, f, (h - 1) / 2 - 6 * scale}, {0, 0, 1}}},
            {"distortion", {0, 0, 0, 0, 0}},
            {"R", {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}},
            {"t", {-0.05, 0.03, 0.25}}};
}

// Reference masks for frames 2, 4, …, 10: simulated at resolution 24 with seed 11, exact silhouettes
// at 192×128, downsampled (INTER_AREA, threshold at half) to 96×64.
void writeReference(const fs::path& dir) {
    fs::create_directories(dir / "masks");
    const Scene scene = parseScene(sceneJson(kEtaTrue, 24, 11, 10), "reference scene");
    const PinholeCamera fine = parseCamera(cameraJson(2), "reference camera");
    sim::Simulation simulation(scene);
    ReferenceManifest manifest;
    manifest.source = "synthetic: identify_loop_test";
    manifest.fps = 30;
    manifest.width = 96;
    manifest.height = 64;
    for (int frame = 1; frame <= 10; ++frame) {
        simulation.advanceFrame();
        if (frame % 2) continue;
        const auto levelSet = surface::liquidLevelSet(simulation);
        const cv::Mat1b big = silhouetteFromLevelSet(*levelSet, fine);
        cv::Mat small;
        cv::resize(big, small, cv::Size(96, 64), 0, 0, cv::INTER_AREA);
        const cv::Mat1b mask = small >= 128;
        char name[32];
        std::snprintf(name, sizeof name, "masks/mask_%05d.png", frame);
        cv::imwrite((dir / name).string(), mask);
        manifest.frames.push_back(frame);
        manifest.times.push_back(frame / 30.0);
        manifest.weights.push_back(1.0);
        manifest.maskFiles.push_back(name);
    }
    saveReferenceManifest(manifest, dir);
}

class IdentifyLoop : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        openvdb::initialize();
        dir_ = fs::temp_directory_path() / ("viscoscope_identify_loop_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        writeReference(dir_ / "reference");
        std::ofstream(dir_ / "scene.json") << sceneJson(8.0, 16, 3, 10).dump(1);
        std::ofstream(dir_ / "camera.json") << cameraJson(1).dump(1);
    }
    static void TearDownTestSuite() {
        if (!std::getenv("VISCOSCOPE_KEEP_TEST_DIR")) fs::remove_all(dir_);
        else std::printf("kept %s\n", dir_.c_str());
    }

    static json jobJson() {
        json doc = columnJobJson();
        doc["camera"] = "camera.json";
        doc["silhouettes"] = "reference";
        return doc;
    }
    static identify::Job job(const json& doc) {
        std::ofstream(dir_ / "job.json") << doc.dump(1);
        return identify::loadJob(dir_ / "job.json");
    }
    // Identifies from both runs and from each alone, printing each parameter against `truth`; the
    // largest relative error over the parameters of each (both, the first run, the second).
    static std::array<double, 3> identifyFromRunsAndAlone(const struct ColumnJobs& jobs, const std::vector<double>& truth);
    static fs::path dir_;
};
fs::path IdentifyLoop::dir_;

// A job that names a video extracts it into OUT/reference once and reuses that while the video,
// the extraction settings and the extraction's revision stay the same; when any changes, it extracts
// again rather than scoring against silhouettes of something else.
TEST_F(IdentifyLoop, AVideoReferenceIsExtractedAgainWhenItsSourceChanges) {
    const fs::path clip = dir_ / "clip.mp4", out = dir_ / "video_job_out";
    {
        cv::VideoWriter writer(clip.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), 30, {96, 64});
        ASSERT_TRUE(writer.isOpened());
        for (int f = 0; f < 8; ++f) {
            cv::Mat3b frame(64, 96, cv::Vec3b(90, 90, 90));
            if (f >= 4) cv::rectangle(frame, {30, 10 + 2 * f, 20, 20}, cv::Scalar(230, 230, 230), cv::FILLED);
            writer.write(frame);
        }
    }
    json doc = jobJson();
    doc.erase("silhouettes");
    doc["video"] = "clip.mp4";
    doc["extraction"] = {{"background_frames", 3}};
    auto prepared = [&](const json& d) {
        identify::Job j = job(d);
        identify::prepareReference(j, out);
        return std::make_pair(loadReferenceManifest(j.referenceDir).parameters.at("background_frames").get<int>(),
                              fs::last_write_time(j.referenceDir / "manifest.json"));
    };
    const auto first = prepared(doc);
    EXPECT_EQ(first.first, 3);
    EXPECT_EQ(prepared(doc).second, first.second) << "an unchanged source must be reused, not extracted again";
    doc["extraction"]["background_frames"] = 2;
    EXPECT_EQ(prepared(doc).first, 2) << "changed extraction settings must extract again";
    // As an older engine's extraction would have recorded it:
    const fs::path sourceFile = out / "reference" / "source.json";
    json source = json::parse(std::ifstream(sourceFile));
    ASSERT_EQ(source.at("extraction").at("revision"), kExtractionRevision);
    source["extraction"]["revision"] = kExtractionRevision - 1;
    std::ofstream(sourceFile) << source.dump(1);
    const fs::path older = out / "reference" / "older_extraction";
    std::ofstream(older) << "\n";
    prepared(doc);
    EXPECT_FALSE(fs::exists(older)) << "another extraction revision's masks must be extracted again";
    fs::remove_all(out);
}

TEST_F(IdentifyLoop, EvaluationIsIndependentOfTheThreadCount) {
    const identify::Job j = job(jobJson());
    const identify::Observation obs = identify::loadObservation(j);
    double e1 = 0, e2 = 0;
    tbb::task_arena(1).execute([&] { e1 = identify::evaluate(j, obs, {kEtaTrue}, 16).E; });
    tbb::task_arena(2).execute([&] { e2 = identify::evaluate(j, obs, {kEtaTrue}, 16).E; });
    std::printf("[ identify ] E(eta_true, 16^3) = %.6g with 1 thread, %.6g with 2\n", e1, e2);
    EXPECT_EQ(e1, e2);
    EXPECT_GT(e1, 0);
}

TEST_F(IdentifyLoop, GridPlacementsAverageEOverGridsMovedSideways) {
    json doc = jobJson();
    doc["grid_placements"] = 1;
    const identify::Job single = job(doc);
    const identify::Observation obs = identify::loadObservation(single);
    doc["grid_placements"] = 2;
    doc["grid_placement_schedule"] = "each_evaluation";
    const identify::Job placed = job(doc);
    ASSERT_EQ(placed.gridPlacements, 2);
    const identify::Evaluation aligned = identify::evaluate(single, obs, {kEtaTrue}, 16);
    const identify::Evaluation moved = identify::evaluate(single, obs, {kEtaTrue}, 16, {}, 0.5);
    const identify::Evaluation mean = identify::evaluate(placed, obs, {kEtaTrue}, 16);
    std::printf("[ identify ] E(eta_true, 16^3) = %.6g aligned, %.6g moved half a cell, %.6g over both\n",
                aligned.E, moved.E, mean.E);
    EXPECT_NE(aligned.E, moved.E) << "the move must change the discretization";
    EXPECT_DOUBLE_EQ(mean.E, 0.5 * (aligned.E + moved.E));
    EXPECT_DOUBLE_EQ(mean.frameE.back(), 0.5 * (aligned.frameE.back() + moved.frameE.back()));
    for (int bad : {0, identify::kMaxGridPlacements + 1}) {
        doc["grid_placements"] = bad;
        EXPECT_THROW(job(doc), InputError) << bad;
    }
}

// With placements by generation, each full-fidelity generation runs on one grid placement, in turn,
// at the cost of one placement; θ* is the lowest point of E's mean over the placements, and the
// fields in OUT/fields are θ*'s.
TEST_F(IdentifyLoop, PlacementsByGenerationTakeTurnsAndThetaStarIsTheMeansMinimum) {
    json doc = jobJson();
    doc["max_generations"] = 6;
    doc["fidelity"] = {{"coarse_generations", 2}};
    doc["grid_placements"] = 2;
    doc["grid_placement_schedule"] = "by_generation";
    identify::IdentifyOptions options;
    const fs::path out = dir_ / "by_generation_out";
    const identify::IdentificationResult result = identify::identify(job(doc), out, options);
    const json& history = result.document.at("history");
    ASSERT_EQ(history.size(), 6u);
    for (int g = 0; g < 6; ++g)
        EXPECT_EQ(history[g].at("grid_shift").get<double>(), g < 2 ? 0.0 : 0.5 * ((g - 2) % 2)) << "generation " << g + 1;
    EXPECT_EQ(result.evaluations, 6 * 4);  // λ = 4 a generation, as with one placement
    std::vector<identify::PlacedPoint> points;
    for (const json& e : result.document.at("evaluated"))
        if (e.at("fidelity") == "full" && !e.at("E").is_null())
            points.push_back({e.at("theta")[0].get<double>(), e.at("E").get<double>(), e.at("grid_shift").get<double>()});
    const auto profile = identify::placementMeanProfile(points, true);
    const auto lowest = std::min_element(profile.begin(), profile.end(),
                                         [](const auto& a, const auto& b) { return a.second < b.second; });
    ASSERT_NE(lowest, profile.end());
    std::printf("[ identify ] by generation: eta* = %.4f, E of the mean %.5g over %zu points\n", result.theta[0],
                result.E, profile.size());
    EXPECT_EQ(result.theta[0], lowest->first);
    EXPECT_EQ(result.E, lowest->second);
    std::ifstream ownerFile(out / "fields" / "evaluation.json");
    ASSERT_TRUE(ownerFile);
    EXPECT_EQ(json::parse(ownerFile).at("theta"), json(result.theta));
    // The profile is one-dimensional, and the schedule has two names.
    doc["grid_placement_schedule"] = "alternate";
    EXPECT_THROW(job(doc), InputError);
    doc["grid_placement_schedule"] = "by_generation";
    doc["parameters"].push_back({{"name", "surface_tension"}, {"initial", 0.05}, {"spread", 0.05}});
    EXPECT_THROW(job(doc), InputError);
    // Without the schedule, such a search takes one placement.
    doc.erase("grid_placement_schedule");
    doc.erase("grid_placements");
    EXPECT_EQ(job(doc).gridPlacements, 1);
    EXPECT_EQ(job(jobJson()).gridPlacements, 2);
    EXPECT_EQ(job(jobJson()).placementSchedule, identify::PlacementSchedule::ByGeneration);
    fs::remove_all(out);
}

TEST_F(IdentifyLoop, LandscapeHasItsMinimumNearTheTruth) {
    const identify::Job j = job(jobJson());
    const identify::Observation obs = identify::loadObservation(j);
    double bestE = INFINITY, bestEta = 0;
    for (double eta : {1.0, 2.0, 2.5, 3.0, 3.5, 4.5, 9.0}) {
        const identify::Evaluation ev = identify::evaluate(j, obs, {eta}, 16);
        std::printf("[ identify ] landscape eta=%5.2f E=%.6g (%.2f s)\n", eta, ev.E, ev.seconds);
        if (ev.E < bestE) bestE = ev.E, bestEta = eta;
    }
    EXPECT_GE(bestEta, 2.0);
    EXPECT_LE(bestEta, 4.5);
}

TEST_F(IdentifyLoop, RecoversViscosityWithinTenPercent) {
    const identify::Job j = job(jobJson());
    identify::IdentifyOptions options;
    options.writeFields = false;
    options.onGeneration = [](const identify::GenerationReport& r) {
        std::printf("[ identify ] gen %2d/%d res %d evals %3ld best eta %.4f E %.5g sigma %.3g elapsed %.1f s\n",
                    r.generation, r.generations, r.resolution, r.evaluations,
                    r.bestTheta.empty() ? NAN : r.bestTheta[0], r.bestE, r.sigma, r.elapsed);
    };
    const auto start = std::chrono::steady_clock::now();
    const identify::IdentificationResult result = identify::identify(j, dir_ / "out", options);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double error = std::abs(result.theta[0] - kEtaTrue) / kEtaTrue;
    std::printf("[ identify ] identified eta = %.4f Pa·s (truth %.1f, error %.1f %%), interval [%.3f, %.3f] (%s), "
                "%d generations, %ld evaluations, stop %s, %.1f s wall\n",
                result.theta[0], kEtaTrue, 100 * error, result.interval[0][0], result.interval[0][1],
                result.intervalMethod.c_str(), result.generations, result.evaluations, identify::toString(result.stop), wall);
    std::printf("[ identify ] profile vertex eta = %.4f (not used as θ*)\n",
                result.document.at("viscosity").at("profile_fit").value("theta_min", NAN));
    EXPECT_LT(error, 0.10);
    // The coarse generations simulate the job's grid over the first third of the clip (frame 3 of
    // 10), extended to the third reference frame that shows liquid (frames 2, 4, 6).
    int coarse = 0;
    for (const json& e : result.document.at("evaluated")) {
        const bool isCoarse = e.at("fidelity") == "coarse";
        coarse += isCoarse;
        EXPECT_EQ(e.at("resolution").get<int>(), 20);
        EXPECT_EQ(e.at("frames").get<int>(), isCoarse ? 6 : 10);
    }
    EXPECT_GT(coarse, 0);
    // The first generation scans; the first full-fidelity generation scores the coarse best in
    // place of its last sample; later ones score the vertex of the parabola through the full-
    // fidelity points so far, or a point on the way to it from the CMA-ES mean (clipped). Coarse
    // generations after the scan refine it: their points lie strictly inside the bracket
    // m ± 2σ the generation before left, around the best coarse point so far.
    double coarseBestE = INFINITY, coarseBestEta = NAN;
    for (const json& e : result.document.at("evaluated"))
        if (e.at("fidelity") == "coarse" && e.at("E").get<double>() < coarseBestE)
            coarseBestE = e.at("E").get<double>(), coarseBestEta = e.at("theta")[0].get<double>();
    const int firstFull = result.document.at("coarse_generations").get<int>() + 1;
    const json& evaluated = result.document.at("evaluated");
    const json& generations = result.document.at("history");
    int restarts = 0, proposals = 0;
    for (size_t k = 0; k < evaluated.size(); ++k) {
        const json& e = evaluated[k];
        const int g = e.at("generation").get<int>();
        const std::string origin = e.at("origin");
        const bool last = k + 1 == evaluated.size() || evaluated[k + 1].at("generation").get<int>() != g;
        const double eta = e.at("theta")[0].get<double>();
        if (g == 1) EXPECT_EQ(origin, "scan");
        else if (g < firstFull) {
            EXPECT_EQ(origin, "refine") << "generation " << g;
            const json& before = generations[g - 2];
            const double m = before.at("mean_theta")[0].get<double>(), reach = 2 * before.at("log_std")[0].get<double>();
            EXPECT_GT(eta, m * std::exp(-reach)) << "generation " << g;
            EXPECT_LT(eta, m * std::exp(reach)) << "generation " << g;
        } else if (g == firstFull && last) {
            EXPECT_EQ(origin, "restart");
            EXPECT_NEAR(eta / coarseBestEta, 1, 1e-12);
            ++restarts;
        } else if (origin == "parabola") {
            EXPECT_TRUE(last && g > firstFull) << "generation " << g;
            // By default the generations take the two grid placements in turn, and the proposal
            // comes from E's mean over them.
            std::vector<identify::PlacedPoint> before;
            for (const json& p : evaluated)
                if (p.at("fidelity") == "full" && p.at("generation").get<int>() < g)
                    before.push_back({p.at("theta")[0].get<double>(), p.at("E").get<double>(),
                                      p.at("grid_shift").get<double>()});
            const std::optional<double> vertex =
                identify::bracketedVertex(identify::placementMeanProfile(before, true), true);
            ASSERT_TRUE(vertex) << "generation " << g;
            const double mean = generations[g - 2].at("mean_theta")[0].get<double>();
            EXPECT_GE(eta, std::min(*vertex, mean) * (1 - 1e-9)) << "generation " << g;
            EXPECT_LE(eta, std::max(*vertex, mean) * (1 + 1e-9)) << "generation " << g;
            ++proposals;
        } else if (origin == "extension") {
            EXPECT_TRUE(last && g > firstFull) << "generation " << g;
            ++proposals;
        } else EXPECT_EQ(origin, "sample") << "generation " << g;
    }
    EXPECT_EQ(restarts, 1);
    EXPECT_GT(proposals, 0);
    EXPECT_LE(result.interval[0][0], result.theta[0]);
    EXPECT_GE(result.interval[0][1], result.theta[0]);
    // The alignment check scores θ* and 1.15 θ* on the grid moved by half a cell, and the interval
    // holds θ*·exp(±|ln(θ_s/θ*)|) of its minimum θ_s.
    const json& check = result.document.at("viscosity").at("alignment_check");
    std::printf("[ identify ] alignment check: %s\n", check.dump().c_str());
    ASSERT_TRUE(check.contains("theta_min")) << check.dump();
    EXPECT_FALSE(check.at("from_checkpoint").get<bool>());
    const double spread = std::abs(std::log(check.at("theta_min").get<double>() / result.theta[0]));
    EXPECT_LE(result.interval[0][0], result.theta[0] * std::exp(-spread) * (1 + 1e-12));
    EXPECT_GE(result.interval[0][1], result.theta[0] * std::exp(spread) * (1 - 1e-12));
    // The resolution check scores the same two points on both placements of a grid of 0.8× the cells,
    // and the interval holds θ*·exp(±(h/(h_c − h))·(|ln(θ_s/θ_c)| + 1.645 σ)) of its minimum θ_c, σ the
    // move's noise.
    const json& coarser = result.document.at("viscosity").at("resolution_check");
    std::printf("[ identify ] resolution check: %s\n", coarser.dump().c_str());
    ASSERT_TRUE(coarser.contains("theta_min")) << coarser.dump();
    const int cells = coarser.at("resolution").get<int>();
    EXPECT_EQ(cells, 16);
    EXPECT_EQ(coarser.at("theta"), check.at("theta"));
    const double move = std::abs(std::log(check.at("theta_min").get<double>() / coarser.at("theta_min").get<double>()));
    EXPECT_NEAR(coarser.at("move_ln").get<double>(), move, 1e-12);
    const double noise = coarser.at("move_noise_ln").get<double>();
    EXPECT_GT(noise, 0.0);
    const double gridError = double(cells) / (20 - cells) * (move + 1.645 * noise);
    EXPECT_NEAR(coarser.at("error_ln").get<double>(), gridError, 1e-12);
    EXPECT_LE(result.interval[0][0], result.theta[0] * std::exp(-gridError) * (1 + 1e-12));
    EXPECT_GE(result.interval[0][1], result.theta[0] * std::exp(gridError) * (1 - 1e-12));
    EXPECT_EQ(result.intervalMethod, "profile+alignment+resolution");
    EXPECT_TRUE(fs::exists(dir_ / "out" / "result.json"));
    EXPECT_TRUE(fs::exists(dir_ / "out" / "checkpoint.json"));
    // Re-running a finished job does not simulate again and gives the same answer.
    const identify::IdentificationResult again = identify::identify(j, dir_ / "out", options);
    EXPECT_EQ(again.theta, result.theta);
    EXPECT_EQ(again.evaluations, result.evaluations);
    const json& checkAgain = again.document.at("viscosity").at("alignment_check");
    EXPECT_TRUE(checkAgain.at("from_checkpoint").get<bool>());
    EXPECT_EQ(checkAgain.at("E"), check.at("E"));
    const json& coarserAgain = again.document.at("viscosity").at("resolution_check");
    EXPECT_TRUE(coarserAgain.at("from_checkpoint").get<bool>());
    EXPECT_EQ(coarserAgain.at("E"), coarser.at("E"));
    EXPECT_EQ(again.interval, result.interval);
}

// A budget far below what the job needs cuts the search short but never changes its path: the
// coarse phase ends where it would without one, the minimum two full-fidelity generations and the
// grid checks run, and then the loop stops instead of starting another. The same job without a
// budget, stopped after as many generations, scores the same points to the same E and gives the
// same θ* and interval: a slower machine answers alike, or says it was cut short. A warning at the
// switch says the budget will be overrun and by how much, and a doubt at the end that θ* is
// unconverged. A rerun with the same budget evaluates nothing more; without a budget it goes on.
TEST_F(IdentifyLoop, ABudgetCutsTheSearchShortButNeverChangesItsPath) {
    json doc = jobJson();
    doc["max_generations"] = 40;
    doc["fidelity"] = {{"coarse_generations", 4}};
    doc["time_budget_s"] = 0.5;
    identify::IdentifyOptions options;
    options.writeFields = false;
    std::vector<std::string> warned;
    options.onWarning = [&](const std::string& w) { warned.push_back(w); };
    std::vector<double> remaining;
    options.onGeneration = [&](const identify::GenerationReport& r) { remaining.push_back(r.remaining); };
    const fs::path out = dir_ / "budget_out";
    const identify::IdentificationResult result = identify::identify(job(doc), out, options);
    const int coarse = result.document.at("coarse_generations").get<int>();
    std::printf("[ identify ] budget 0.5 s: stop %s after %d generations (%d coarse), %.1f s\n",
                identify::toString(result.stop), result.generations, coarse, result.seconds);
    auto budgetLines = [](const json& lines) {
        int count = 0;
        for (const json& w : lines) count += w.get<std::string>().rfind("time_budget_s:", 0) == 0;
        return count;
    };
    ASSERT_GE(warned.size(), 2u);
    EXPECT_EQ(warned[0].rfind("time_budget_s: the 2 full-fidelity generations and the grid checks", 0), 0u)
        << warned[0];
    const auto unconverged = std::find_if(warned.begin(), warned.end(), [](const std::string& w) {
        return w.rfind("time_budget_s: the search was stopped by the budget", 0) == 0;
    });
    ASSERT_NE(unconverged, warned.end());
    // The grid checks ran, and the interval holds their share of the error.
    for (const char* check : {"alignment_check", "resolution_check"}) {
        EXPECT_FALSE(result.document.at("viscosity").at(check).contains("skipped")) << check;
        EXPECT_TRUE(result.document.at("viscosity").at(check).contains("theta_min")) << check;
    }
    const json& doubts = result.document.at("doubts");
    EXPECT_EQ(std::count(doubts.begin(), doubts.end(), json(*unconverged)), 1);
    EXPECT_EQ(budgetLines(doubts), 1);
    EXPECT_EQ(budgetLines(result.document.at("warnings")), 2);
    // After the switch the estimate covers the full-fidelity generation still to come, not the
    // budget's spent remainder; at the end, the grid checks' evaluations.
    ASSERT_EQ(remaining.size(), size_t(result.generations));
    EXPECT_GT(remaining[coarse - 1], 0.0);
    EXPECT_GT(remaining[coarse], remaining.back());
    EXPECT_GT(remaining.back(), 0.0);
    EXPECT_EQ(result.stop, identify::StopReason::TimeBudget);
    // Two full-fidelity generations, or up to four while no profile lets the checks run.
    EXPECT_GE(result.generations, coarse + 2);
    EXPECT_LE(result.generations, coarse + 4);

    json unbudgetedDoc = doc;
    unbudgetedDoc["time_budget_s"] = 0;
    unbudgetedDoc["max_generations"] = result.generations;
    const identify::IdentificationResult unbudgeted =
        identify::identify(job(unbudgetedDoc), dir_ / "unbudgeted_out", options);
    EXPECT_EQ(unbudgeted.document.at("coarse_generations").get<int>(), coarse);
    EXPECT_EQ(unbudgeted.stop, identify::StopReason::MaxGenerations);
    const json& scored = result.document.at("evaluated");
    const json& unbudgetedScored = unbudgeted.document.at("evaluated");
    ASSERT_EQ(unbudgetedScored.size(), scored.size());
    for (size_t k = 0; k < scored.size(); ++k) {
        EXPECT_EQ(unbudgetedScored[k].at("theta"), scored[k].at("theta")) << "evaluation " << k;
        EXPECT_EQ(unbudgetedScored[k].at("E"), scored[k].at("E")) << "evaluation " << k;
    }
    EXPECT_EQ(unbudgeted.theta, result.theta);
    EXPECT_EQ(unbudgeted.interval, result.interval);
    EXPECT_EQ(budgetLines(unbudgeted.document.at("doubts")), 0);
    fs::remove_all(dir_ / "unbudgeted_out");

    const identify::IdentificationResult again = identify::identify(job(doc), out, options);
    EXPECT_EQ(again.evaluations, result.evaluations);
    EXPECT_EQ(again.stop, identify::StopReason::TimeBudget);
    EXPECT_EQ(budgetLines(again.document.at("doubts")), 1);
    doc["time_budget_s"] = 0;
    doc["max_generations"] = result.generations + 2;
    const identify::IdentificationResult more = identify::identify(job(doc), out, options);
    EXPECT_GT(more.generations, result.generations);
    EXPECT_NE(more.stop, identify::StopReason::TimeBudget);
    EXPECT_EQ(budgetLines(more.document.at("doubts")), 0);
    fs::remove_all(out);
}

// A simulation's E is rough, so tolerance_x comes late if at all: the search ends once two
// generations running (one on each grid placement) each hold their median E within tolerance_fun of
// their least, and a search that goes on without that rule finds its θ* within the first one's
// interval: the generations it saved would not have changed the answer. That one ends too, before
// its generations run out, once its distribution samples only θ the profile's interval cannot tell
// apart ("resolved").
TEST_F(IdentifyLoop, EndsOnceESettlesWhereMoreGenerationsChangeNothing) {
    json doc = jobJson();
    doc["max_generations"] = 30;
    doc["tolerance_x"] = 1e-3;
    identify::IdentifyOptions options;
    options.writeFields = false;
    const identify::IdentificationResult settled = identify::identify(job(doc), dir_ / "settled_out", options);
    std::printf("[ identify ] settled: eta %.4f [%.4f, %.4f], stop %s after %d generations, %ld evaluations\n",
                settled.theta[0], settled.interval[0][0], settled.interval[0][1], identify::toString(settled.stop),
                settled.generations, settled.evaluations);
    EXPECT_EQ(settled.stop, identify::StopReason::ToleranceFun);
    EXPECT_LT(settled.generations, 30);
    // The rule as result.json records it: the last two generations' own points.
    for (int g = settled.generations - 1; g <= settled.generations; ++g) {
        std::vector<double> E;
        for (const json& e : settled.document.at("evaluated"))
            if (e.at("generation").get<int>() == g && e.at("origin") != "known") E.push_back(e.at("E").get<double>());
        ASSERT_FALSE(E.empty()) << "generation " << g;
        std::sort(E.begin(), E.end());
        EXPECT_LE(E[E.size() / 2], 1.05 * E.front()) << "generation " << g;
    }
    doc["tolerance_fun"] = 0;
    doc["max_generations"] = settled.generations + 8;
    const identify::IdentificationResult longer = identify::identify(job(doc), dir_ / "longer_out", options);
    std::printf("[ identify ] without it: eta %.4f [%.4f, %.4f], stop %s after %d generations\n", longer.theta[0],
                longer.interval[0][0], longer.interval[0][1], identify::toString(longer.stop), longer.generations);
    EXPECT_EQ(longer.stop, identify::StopReason::Resolved);
    EXPECT_LT(longer.generations, settled.generations + 8);
    EXPECT_GT(longer.evaluations, settled.evaluations);
    EXPECT_GE(longer.theta[0], settled.interval[0][0]);
    EXPECT_LE(longer.theta[0], settled.interval[0][1]);
    fs::remove_all(dir_ / "settled_out");
    fs::remove_all(dir_ / "longer_out");
}

// A measured track alone, like a lab's front positions, with no camera and no silhouettes: the
// column's front along the ground, and its reach from the vertical through the middle of the wall it
// leans on (the "radius" observable), sampled 60 times a second from the reference simulation (24
// cells, seed 11) and written as a CSV, each identify η on the job's 20-cell grid with seed 3.
TEST_F(IdentifyLoop, RecoversViscosityFromAMeasuredTrackAlone) {
    const Eigen::Vector3d gate(0.035, 0.02, 0), wall(0, 0.02, 0);
    writeMeasuredTrack(sceneJson(kEtaTrue, 24, 11, 20), gate, wall, dir_ / "measured.csv");
    for (const char* observable : {"front", "radius"}) {
        const Eigen::Vector3d& origin = std::string(observable) == "front" ? gate : wall;
        json doc = jobJson();
        doc.erase("camera");
        doc.erase("silhouettes");
        doc["track"] = {{"csv", "measured.csv"}, {"column", std::string(observable) + "_m"}, {"observable", observable},
                        {"origin", {origin.x(), origin.y(), origin.z()}}, {"direction", {1, 0, 0}}, {"band", 0.005}};
        identify::IdentifyOptions options;
        options.writeFields = false;
        const identify::IdentificationResult result = identify::identify(job(doc), dir_ / "track_out", options);
        const double error = std::abs(result.theta[0] - kEtaTrue) / kEtaTrue;
        double trackError = NAN;
        for (const json& e : result.document.at("evaluated"))
            if (e.at("fidelity") == "full" && e.at("theta")[0] == result.theta[0])
                trackError = e.at("track_error").get<double>();
        std::printf("[ identify ] from the %s alone: eta = %.4f Pa·s (truth %.1f, error %.1f %%), interval "
                    "[%.3f, %.3f], track error %.2f %%, %ld evaluations\n", observable, result.theta[0], kEtaTrue,
                    100 * error, result.interval[0][0], result.interval[0][1], 100 * trackError, result.evaluations);
        EXPECT_LT(error, 0.10) << observable;
        // 10 frames of the job's 30 fps fall within the track's third of a second.
        EXPECT_EQ(result.document.at("frames").get<int>(), 10) << observable;
        EXPECT_LT(trackError, 0.05) << observable;
        fs::remove_all(dir_ / "track_out");
    }
}

// Two runs of one liquid, `material`: the column above and a low one (5 cm wide, 2 cm high, under half
// the driving pressure), each with its measured front from its own reference run (seed 11),
// as a job of both runs and as a job of each alone (without camera and silhouettes; the search
// settings of `job`). The runs' scenes are the references' on 16 cells with seed 3; what the job
// searches is overwritten in them at every evaluation.
struct ColumnJobs {
    json both;
    std::array<json, 2> alone;
};
ColumnJobs columnJobs(const json& material, const json& parameters, const std::string& label, const fs::path& dir,
                      const json& job, int referenceResolution) {
    const std::array<double, 2> widths{0.035, 0.05}, heights{0.045, 0.02};
    json shared = job;
    shared["parameters"] = parameters;
    for (const char* key : {"scene", "camera", "silhouettes"}) shared.erase(key);
    ColumnJobs jobs{shared, {shared, shared}};
    for (size_t r = 0; r < widths.size(); ++r) {
        json scene = sceneJson(material.at("viscosity").get<double>(), referenceResolution, 11, 20);
        scene["material"] = material;
        scene["liquids"][0]["max"] = {widths[r], 0.04, heights[r]};
        const std::string csv = label + "_run" + std::to_string(r) + ".csv";
        writeMeasuredTrack(scene, {widths[r], 0.02, 0}, {0, 0.02, 0}, dir / csv);
        scene["domain"]["resolution"] = 16;
        scene["seed"] = 3;
        scene["frames"] = 10;
        const json run{{"scene", scene},
                       {"track", {{"csv", csv}, {"column", "front_m"}, {"observable", "front"},
                                  {"origin", {widths[r], 0.02, 0}}, {"direction", {1, 0, 0}}}}};
        jobs.both["runs"].push_back(run);
        jobs.alone[r].update(run);
    }
    return jobs;
}

std::array<double, 3> IdentifyLoop::identifyFromRunsAndAlone(const ColumnJobs& jobs, const std::vector<double>& truth) {
    identify::IdentifyOptions options;
    options.writeFields = false;
    const std::array<std::pair<const char*, const json*>, 3> cases{
        {{"both runs", &jobs.both}, {"the tall column", &jobs.alone[0]}, {"the low column", &jobs.alone[1]}}};
    std::array<double, 3> worst{};
    for (size_t c = 0; c < cases.size(); ++c) {
        const auto started = std::chrono::steady_clock::now();
        const identify::IdentificationResult result = identify::identify(job(*cases[c].second), dir_ / "runs_out", options);
        std::printf("[ identify ] from %s (%ld evaluations, %.0f s):", cases[c].first, result.evaluations,
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
        for (size_t i = 0; i < truth.size(); ++i) {
            const double error = std::abs(result.theta[i] - truth[i]) / truth[i];
            worst[c] = std::max(worst[c], error);
            std::printf(" %s = %.4f (truth %.2f, error %.1f %%, interval [%.3f, %.3f])",
                        cases[c].second->at("parameters")[i].at("name").get<std::string>().c_str(), result.theta[i],
                        truth[i], 100 * error, result.interval[i][0], result.interval[i][1]);
        }
        std::printf("\n");
        if (cases[c].second->contains("runs")) {
            EXPECT_EQ(result.document.at("run_E").size(), 2u);
            EXPECT_GT(result.document.at("run_E")[1].get<double>(), 0.0);
        }
        fs::remove_all(dir_ / "runs_out");
    }
    return worst;
}

// Several runs of one liquid in one job: its E is the sum of the runs' E, each scored as a job of
// its own would score it.
TEST_F(IdentifyLoop, SeveralRunsOfOneLiquidShareItsParameters) {
    const json material = {{"density", 1400}, {"viscosity", kEtaTrue}, {"surface_tension", 0.0}};
    const ColumnJobs jobs = columnJobs(material, jobJson().at("parameters"), "newtonian", dir_, jobJson(), 24);

    // E is the sum of what each run alone scores.
    const identify::Job both = job(jobs.both);
    ASSERT_EQ(both.otherRuns.size(), 1u);
    const identify::Evaluation together = identify::evaluate(both, identify::loadObservation(both), {5.0}, 20);
    ASSERT_EQ(together.runE.size(), 2u);
    for (size_t r = 0; r < jobs.alone.size(); ++r) {
        const identify::Job one = job(jobs.alone[r]);
        EXPECT_DOUBLE_EQ(together.runE[r], identify::evaluate(one, identify::loadObservation(one), {5.0}, 20).E);
    }
    EXPECT_DOUBLE_EQ(together.E, together.runE[0] + together.runE[1]);

    EXPECT_LT(identifyFromRunsAndAlone(jobs, {kEtaTrue})[0], 0.10);
}

// A shear-thinning liquid, a power law of K = 3 Pa·sⁿ and n = 0.6, and the search of both at once.
constexpr double kThinningConsistency = 3, kThinningIndex = 0.6;
const json kThinningMaterial = {
    {"density", 1400},
    {"viscosity", 1.0},
    {"surface_tension", 0.0},
    {"model", {{"type", "power_law"}, {"consistency", kThinningConsistency}, {"flow_index", kThinningIndex}}}};
const json kThinningSearch = {
    {{"name", "consistency"}, {"initial", 10.0}, {"spread", 10.0}, {"min", 0.1}, {"max", 100.0}},
    {{"name", "flow_index"}, {"initial", 1.0}, {"spread", 0.5}, {"min", 0.3}, {"max", 1.5}}};

// That liquid searched for K and n at once, from both runs and from each alone, on 28 cells against
// references of 36. It prints the figures and claims nothing: on the CI grids (20 against 24) the two runs together did worse than either alone, here
// better (tests/bench/FINDINGS.md, "Several runs of one liquid"). About 9 minutes, so it is run by
// hand (--gtest_also_run_disabled_tests), not in CI.
TEST_F(IdentifyLoop, DISABLED_SeveralRunsOfAShearThinningLiquidIdentifyItsLaw) {
    json search = jobJson();
    search["max_generations"] = 24;
    search["resolution"] = 28;
    const ColumnJobs jobs = columnJobs(kThinningMaterial, kThinningSearch, "power_law", dir_, search, 36);
    identifyFromRunsAndAlone(jobs, {kThinningConsistency, kThinningIndex});
}

// Two parameters on a rough E: tolerance_fun's medians need the search narrower than E's valley
// across a power law's K–n ridge, which it rarely gets. The search ends once, two generations
// running, it samples only θ that E cannot tell from the best (its ±2σ band inside the joint
// profile's interval), and that interval holds the hidden law: the liquid of the test above, from
// both runs on 16 cells against references of 24.
TEST_F(IdentifyLoop, SeveralParametersEndOnceTheSearchSamplesOnlyWhatECannotTellApart) {
    json search = jobJson();
    search["max_generations"] = 60;
    const ColumnJobs jobs = columnJobs(kThinningMaterial, kThinningSearch, "resolved", dir_, search, 24);
    identify::IdentifyOptions options;
    options.writeFields = false;
    const identify::IdentificationResult result = identify::identify(job(jobs.both), dir_ / "resolved_out", options);
    const std::array<double, 2> truth{kThinningConsistency, kThinningIndex};
    std::printf("[ identify ] stop %s after %d generations (%ld evaluations), interval method %s:", identify::toString(result.stop),
                result.generations, result.evaluations, result.intervalMethod.c_str());
    for (size_t i = 0; i < truth.size(); ++i)
        std::printf(" %.4f [%.4f, %.4f] (truth %.2f)", result.theta[i], result.interval[i][0], result.interval[i][1], truth[i]);
    std::printf("\n");
    EXPECT_EQ(result.stop, identify::StopReason::Resolved);
    EXPECT_LT(result.generations, 60);
    EXPECT_EQ(result.intervalMethod, "joint_profile");
    for (size_t i = 0; i < truth.size(); ++i) {
        EXPECT_LE(result.interval[i][0], truth[i]) << i;
        EXPECT_GE(result.interval[i][1], truth[i]) << i;
    }
    fs::remove_all(dir_ / "resolved_out");
}

// Runs of one job share one liquid, and each run's keys stay within its entry.
TEST_F(IdentifyLoop, RunsThatDisagreeOnTheMaterialAreRefused) {
    json doc = jobJson();
    for (const char* key : {"scene", "camera", "silhouettes"}) doc.erase(key);
    json other = sceneJson(8.0, 16, 3, 10);
    other["material"]["density"] = 1000;
    doc["runs"] = {{{"scene", "scene.json"}, {"camera", "camera.json"}, {"silhouettes", "reference"}},
                   {{"scene", other}, {"camera", "camera.json"}, {"silhouettes", "reference"}}};
    auto refusal = [&](const json& d) {
        try {
            job(d);
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    EXPECT_NE(refusal(doc).find("runs[1].scene: material.density: 1000.0 where runs[0] has 1400.0"), std::string::npos)
        << refusal(doc);
    other["material"]["density"] = 1400;
    other["material"]["viscosity"] = 2.0;  // searched: the runs' own values do not matter
    doc["runs"][1]["scene"] = other;
    EXPECT_EQ(refusal(doc), "accepted");
    json beside = doc;
    beside["camera"] = "camera.json";
    EXPECT_NE(refusal(beside).find("camera: belongs in each entry of runs"), std::string::npos) << refusal(beside);
    json unknown = doc;
    unknown["runs"][1]["resolution"] = 12;
    EXPECT_NE(refusal(unknown).find("runs[1].resolution"), std::string::npos) << refusal(unknown);
    json empty = doc;
    empty["runs"] = json::array();
    EXPECT_NE(refusal(empty).find("runs: must be a non-empty array"), std::string::npos) << refusal(empty);
}

// The budget's prediction of a full-fidelity evaluation comes from the coarse evaluations near the
// coarse best, where the full-fidelity phase restarts, not from the scan's far and slow points, and
// the frames the full clip adds cost what the coarse clip's last third did.
TEST(TimeBudget, PredictsAFullEvaluationFromTheCoarseOnesNearTheBest) {
    using identify::EvaluationRecord;
    using identify::Fidelity;
    using identify::predictedFullEvaluationSeconds;
    const auto record = [](Fidelity fidelity, double theta, double E, double seconds, std::vector<double> frames) {
        EvaluationRecord r;
        r.fidelity = fidelity;
        r.evaluation.theta = {theta};
        r.evaluation.E = E;
        r.evaluation.seconds = seconds;
        r.evaluation.frameSeconds = frames;
        return r;
    };
    const std::vector<double> even(60, 0.2), dearerLate = [] {
        std::vector<double> f(60, 0.1);
        for (int i = 40; i < 60; ++i) f[i] = 0.4;
        return f;
    }();
    const Fidelity coarse = Fidelity::Coarse;
    std::vector<EvaluationRecord> evaluated{record(coarse, 1, 5, 70, even),    record(coarse, 10, 3, 30, even),
                                            record(coarse, 100, 2, 20, even),  record(coarse, 300, 1, 12, even),
                                            record(coarse, 250, 1.5, 14, even), record(Fidelity::Full, 300, 0.5, 1000, even)};
    // Frames 0–59 coarse, 0–179 full: three times the frames at the same rate.
    EXPECT_NEAR(predictedFullEvaluationSeconds(evaluated, {48, 48, 59, 179}), 3 * (12 + 14) / 2.0, 1e-9);
    // A coarser grid: (48/24)⁴ as many cells × steps.
    EXPECT_NEAR(predictedFullEvaluationSeconds(evaluated, {24, 48, 59, 179}), 16 * 3 * (12 + 14) / 2.0, 1e-9);
    // Cheap early frames: the 120 added frames at the last third's 0.4 s, against 12 s for 60.
    evaluated = {record(coarse, 300, 1, 12, dearerLate)};
    EXPECT_NEAR(predictedFullEvaluationSeconds(evaluated, {48, 48, 59, 179}), 12 * (12 + 120 * 0.4) / 12, 1e-9);
    EXPECT_EQ(predictedFullEvaluationSeconds({}, {48, 48, 59, 179}), 0.0);
}

// OUT/fields holds θ*'s hidden fields for every frame. They are the best full-fidelity evaluation's
// own, kept from the search rather than simulated again, and equal to a fresh simulation of θ*,
// which the run falls back to when they are missing.
TEST_F(IdentifyLoop, KeepsTheBestEvaluationsFieldsInsteadOfSimulatingAgain) {
    json doc = jobJson();
    doc["max_generations"] = 3;
    doc["resolution"] = 16;
    const fs::path out = dir_ / "fields_out";
    const identify::IdentificationResult result = identify::identify(job(doc), out, {});
    const json& fields = result.document.at("fields");
    EXPECT_EQ(fields.at("source"), "the best evaluation's run");
    EXPECT_EQ(fields.at("frames"), 11);  // frames 0..10
    EXPECT_FALSE(fs::exists(out / "fields.partial"));
    int files = 0;
    for (const auto& entry : fs::directory_iterator(out / "fields")) files += entry.path().extension() == ".vdb";
    EXPECT_EQ(files, 11);
    std::ifstream ownerFile(out / "fields" / "evaluation.json");
    const json owner = json::parse(ownerFile);
    EXPECT_EQ(owner.at("theta"), json(result.theta));
    ASSERT_GE(result.document.at("coarse_generations").get<int>(), 1);
    // Every full-fidelity evaluation wrote fields, and the coarse ones did not.
    for (const json& e : result.document.at("evaluated"))
        EXPECT_EQ(e.at("fields_s").get<double>() > 0, e.at("fidelity") == "full") << e.dump();

    fs::rename(out / "fields", dir_ / "kept_fields");
    const identify::IdentificationResult again = identify::identify(job(doc), out, {});
    EXPECT_EQ(again.theta, result.theta);
    EXPECT_EQ(again.document.at("fields").at("source"), "θ* simulated again");
    for (const char* frame : {"frame_00005.vdb", "frame_00010.vdb"}) {
        const surface::FrameFields kept = surface::readFrameFields(dir_ / "kept_fields" / frame);
        const surface::FrameFields fresh = surface::readFrameFields(out / "fields" / frame);
        EXPECT_EQ(kept.velocity->activeVoxelCount(), fresh.velocity->activeVoxelCount()) << frame;
        const surface::FieldDifference d = surface::compareFields(fresh, kept);
        EXPECT_GT(d.samples, 0) << frame;
        EXPECT_EQ(d.velocityError2, 0.0) << frame;
        EXPECT_EQ(d.pressureError2, 0.0) << frame;
    }
    fs::remove_all(out);
    fs::remove_all(dir_ / "kept_fields");
}

// Without a track CSV, E also compares the silhouettes' area over time with the reference's: the
// track holds each compared reference frame's mask area; weight 0 turns it off.
TEST_F(IdentifyLoop, TheReferenceAreaIsATrackUnlessTurnedOff) {
    json doc = jobJson();
    const identify::Observation obs = identify::loadObservation(job(doc));
    ASSERT_TRUE(obs.track.has_value());
    EXPECT_EQ(obs.trackWeight, 1.0);
    ASSERT_EQ(obs.track->values[0].size(), 5u);
    for (size_t i = 0; i < obs.masks.size(); ++i) {
        EXPECT_NEAR(obs.track->time[i], obs.reference.times[i], 1e-12);
        EXPECT_EQ(obs.track->values[0][i], cv::countNonZero(obs.masks[i]));
    }
    const identify::Evaluation withArea = identify::evaluate(job(doc), obs, {kEtaTrue * 2}, 16);
    doc["area_track_weight"] = 0.0;
    const identify::Observation silhouettesOnly = identify::loadObservation(job(doc));
    EXPECT_FALSE(silhouettesOnly.track.has_value());
    const identify::Evaluation without = identify::evaluate(job(doc), silhouettesOnly, {kEtaTrue * 2}, 16);
    EXPECT_GT(withArea.E, without.E);  // the area term: its silhouettes differ from the truth's in area
}

// A reference that shows no liquid outside its excluded region (a thick liquid that stays in the
// cup for the whole clip) cannot bound η from above: the run says so, in its result and by warning.
TEST_F(IdentifyLoop, WarnsWhenTheReferenceNeverShowsTheLiquid) {
    const fs::path empty = dir_ / "empty_reference";
    fs::create_directories(empty / "masks");
    ReferenceManifest manifest = loadReferenceManifest(dir_ / "reference");
    for (const std::string& name : manifest.maskFiles) cv::imwrite((empty / name).string(), cv::Mat1b::zeros(64, 96));
    saveReferenceManifest(manifest, empty);
    json doc = jobJson();
    doc["silhouettes"] = "empty_reference";
    doc["max_generations"] = 1;
    identify::IdentifyOptions options;
    options.writeFields = false;
    std::vector<std::string> warnings;
    options.onWarning = [&](const std::string& w) { warnings.push_back(w); };
    const fs::path out = dir_ / "empty_out";
    const identify::IdentificationResult result = identify::identify(job(doc), out, options);
    ASSERT_GE(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("only 0 of 5 compared frames"), std::string::npos) << warnings[0];
    EXPECT_EQ(result.document.at("warnings"), json(warnings));
    // The doubt the empty reference casts on θ* is among them: E hardly changes with η.
    const json& doubts = result.document.at("doubts");
    ASSERT_EQ(doubts.size(), warnings.size() - 1);
    ASSERT_GE(doubts.size(), 1u);
    EXPECT_TRUE(std::any_of(doubts.begin(), doubts.end(), [](const json& d) {
        return d.get<std::string>().find("E is nearly flat") != std::string::npos;
    })) << doubts.dump();
    for (const json& d : doubts) EXPECT_NE(std::find(warnings.begin(), warnings.end(), d.get<std::string>()), warnings.end());
    EXPECT_EQ(result.document.at("reference_informative_frames"), 0);
    fs::remove_all(out);
}

// The coarse clip: a third of the simulated frames, but at least up to the third reference frame
// whose silhouette shows liquid in the compared region; liquid only where the region excludes
// (the cup) or a speckle below 0.1 % of the compared pixels does not count.
TEST(CoarseClip, ReachesTheThirdFrameThatShowsLiquid) {
    identify::Observation obs;
    obs.compared = cv::Mat1b(100, 100, uchar(255));
    obs.compared(cv::Rect(0, 0, 100, 40)).setTo(0);  // the excluded cup: rows 0–39
    auto clip = [&](int firstLiquidFrame) {
        obs.simFrames.clear();
        obs.masks.clear();
        for (int frame = 0; frame <= 60; ++frame) {
            cv::Mat1b mask = cv::Mat1b::zeros(100, 100);
            mask(cv::Rect(30, 10, 40, 25)).setTo(255);  // liquid in the cup, always
            mask(cv::Rect(90, 90, 2, 2)).setTo(255);    // 4 px of extraction noise (< 6 = 0.1 %)
            if (frame >= firstLiquidFrame) mask(cv::Rect(48, 40, 4, 30)).setTo(255);  // the stream
            obs.simFrames.push_back(frame);
            obs.masks.push_back(mask);
        }
        const identify::Observation part = identify::firstPartOf(obs, 1.0 / 3);
        return identify::lastSimFrame(part);
    };
    EXPECT_EQ(clip(2), 20);   // liquid from frame 2: a third of 60 frames
    EXPECT_EQ(clip(30), 32);  // liquid from frame 30: frames 30, 31, 32
    EXPECT_EQ(clip(59), 60);  // two informative frames: the whole clip
    EXPECT_EQ(clip(100), 60);
    EXPECT_EQ(identify::informativeSimFrames(obs).size(), 0u);

    // A measured area track that is still 0 over the coarse clip has nothing to normalize by there:
    // the coarse part scores silhouettes alone, the whole clip keeps the track.
    clip(2);
    obs.reference.times.clear();
    for (int frame = 0; frame <= 60; ++frame) obs.reference.times.push_back(frame / 30.0);
    obs.track = ScalarTrack{{"area_px"}, {0.0, 1.0, 2.0}, {{0.0, 0.0, 900.0}}};
    EXPECT_FALSE(identify::firstPartOf(obs, 1.0 / 3).track.has_value());
    obs.track->values[0][0] = 10;
    EXPECT_TRUE(identify::firstPartOf(obs, 1.0 / 3).track.has_value());
}

// ---------------------------------------------------------------------------------------------
// The real requirement: a reference made by `viscoscope synth` from the truth scene at 24³ with
// seed 11: Blender (Cycles, a plain backdrop, one light, the ground) renders it at 192×128, and it
// is area-downsampled to 96×64 and encoded as an mp4 like a phone clip. identify extracts that clip
// like footage (MOG2 against the rendered clean plate). The camera is a "viscoscope.blender_camera"
// file: Blender renders through its inverse conversion, and the engine reads it with
// cameraFromBlender, as it does for the add-on's export.

std::string slurp(const fs::path& file) {
    std::ifstream stream(file);
    return {std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
}

json blenderCameraJson() {
    // The side camera of cameraJson(1): 200 px focal length over 96 px = 75 mm on a 36 mm sensor,
    // the principal point 6 px above the centre. synth renders it at twice the size (--supersample 2).
    return {{"format", "viscoscope.blender_camera"}, {"version", 1}, {"lens_mm", 75.0}, {"sensor_width_mm", 36.0},
            {"sensor_height_mm", 24.0}, {"sensor_fit", "HORIZONTAL"}, {"shift_x", 0.0}, {"shift_y", -6.0 / 96.0},
            {"resolution_x", 96}, {"resolution_y", 64}, {"resolution_percentage", 100}, {"pixel_aspect_x", 1.0},
            {"pixel_aspect_y", 1.0},
            {"matrix_world", {{1, 0, 0, 0.05}, {0, 0, -1, -0.25}, {0, 1, 0, 0.03}, {0, 0, 0, 1}}}};
}

TEST_F(IdentifyLoop, RecoversViscosityFromABlenderRenderedReference) {
    if (std::system("blender --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "blender not installed";
    const fs::path work = dir_ / "blender";
    fs::create_directories(work);
    std::ofstream(work / "truth.json") << sceneJson(kEtaTrue, 24, 11, 10).dump(1);
    std::ofstream(work / "blender_camera.json") << blenderCameraJson().dump(1);
    const auto start = std::chrono::steady_clock::now();
    const std::string command = std::string(VISCOSCOPE_CLI) + " synth " + (work / "truth.json").string() + " --camera " +
                                (work / "blender_camera.json").string() + " --out " + (work / "synth").string() +
                                " --resolution 24 --seed 11 --samples 8 --supersample 2 --progress none > " +
                                (work / "synth.log").string() + " 2>&1";
    ASSERT_EQ(std::system(command.c_str()), 0) << slurp(work / "synth.log");
    const json synth = json::parse(slurp(work / "synth" / "synth.json"));
    const json& timings = synth.at("timings");
    json doc = jobJson();
    doc["camera"] = "blender/blender_camera.json";
    doc.erase("silhouettes");
    doc["video"] = "blender/synth/reference.mp4";
    doc["extraction"] = {{"clean_plate", "blender/synth/clean_plate.png"},
                         {"exclude_mask", "blender/synth/exclude.png"},
                         {"weights", "0:0"}};  // frame 0 is the same for every θ
    identify::IdentifyOptions options;
    options.writeFields = false;
    const identify::IdentificationResult result =
        identify::identify(job(doc), work / "out", options);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double error = std::abs(result.theta[0] - kEtaTrue) / kEtaTrue;
    const ReferenceManifest reference = loadReferenceManifest(work / "out" / "reference");
    EXPECT_EQ(reference.frames.size(), 11u);
    EXPECT_GT(silhouetteArea(reference.mask(10)), 100);
    std::printf("[ identify ] Blender-rendered reference: eta = %.4f Pa·s (truth %.1f, error %.1f %%), interval "
                "[%.3f, %.3f] (%s), E %.4g, %ld evaluations; synth %.1f s (simulate %.1f, render %.1f, encode %.1f), "
                "total %.1f s\n",
                result.theta[0], kEtaTrue, 100 * error, result.interval[0][0], result.interval[0][1],
                result.intervalMethod.c_str(), result.E, result.evaluations, timings.at("total_s").get<double>(),
                timings.at("simulate_s").get<double>(), timings.at("render_s").get<double>(),
                timings.at("encode_s").get<double>(), wall);
    std::printf("[ identify ] Blender-rendered reference: profile vertex eta = %.4f (not used as θ*)\n",
                result.document.at("viscosity").at("profile_fit").value("theta_min", NAN));
    EXPECT_LT(error, 0.10);
}

}  // namespace
