// How often identify's interval holds the truth (issue 89): the collapsing column's front, measured
// like a lab's from reference runs at another resolution and particle seed than the job's, for
// several η and seeds; each identified on the job's grid. Prints a row per reference (η*, the
// resolution check's grid error in ln η, the interval, whether it holds the truth, its width in
// ln η, the interval's method) and the coverage and mean width over all of them.
//
//   identify_coverage_bench [--etas 2,5,12] [--seeds 11,12,13,14] [--resolution 20]
//                           [--reference-resolution 24] [--generations 12] [--threads 0] [--keep DIR]
#include "../native/collapsing_column.h"
#include "identify/identify.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace viscoscope;

int main(int argc, char** argv) {
    std::vector<double> etas{2, 5, 12};
    std::vector<unsigned> seeds{11, 12, 13, 14};
    int resolution = 20, referenceResolution = 24, generations = 12, threads = 0;
    std::string keep;
    CLI::App app{"Coverage of identify's interval over synthetic references of the collapsing column"};
    app.add_option("--etas", etas, "true viscosities (Pa·s)")->delimiter(',');
    app.add_option("--seeds", seeds, "the references' particle seeds")->delimiter(',');
    app.add_option("--resolution", resolution, "the job's grid");
    app.add_option("--reference-resolution", referenceResolution, "the references' grid");
    app.add_option("--generations", generations, "max_generations of each identification");
    app.add_option("--threads", threads, "worker threads (0 = all cores)");
    app.add_option("--keep", keep, "folder to keep the jobs and results in");
    CLI11_PARSE(app, argc, argv);
    openvdb::initialize();

    const fs::path root = keep.empty() ? fs::temp_directory_path() / ("viscoscope_coverage_" + std::to_string(::getpid())) : fs::path(keep);
    const Eigen::Vector3d gate(0.035, 0.02, 0), wall(0, 0.02, 0);
    int held = 0, count = 0;
    double widthSum = 0;
    std::printf("%8s %6s %10s %10s %22s %6s %10s %s\n", "eta", "seed", "eta*", "grid error", "interval", "holds",
                "ln width", "method");
    for (double eta : etas)
        for (unsigned seed : seeds) {
            const fs::path dir = root / ("eta" + std::to_string(eta) + "_seed" + std::to_string(seed));
            fs::create_directories(dir);
            column::writeMeasuredTrack(column::sceneJson(eta, referenceResolution, seed, 20), gate, wall, dir / "front.csv");
            json job = column::columnJobJson();
            job["scene"] = column::sceneJson(10.0, resolution, 3, 10);
            job["resolution"] = resolution;
            job["max_generations"] = generations;
            job["track"] = {{"csv", "front.csv"}, {"column", "front_m"}, {"observable", "front"},
                            {"origin", {gate.x(), gate.y(), gate.z()}}, {"direction", {1, 0, 0}}};
            std::ofstream(dir / "job.json") << job.dump(1);
            identify::IdentifyOptions options;
            options.writeFields = false;
            options.threads = threads;
            const identify::IdentificationResult r = identify::identify(identify::loadJob(dir / "job.json"), dir / "out", options);
            const auto [low, high] = r.interval[0];
            const bool holds = low <= eta && eta <= high;
            held += holds;
            ++count;
            widthSum += std::log(high / low);
            const json& check = r.document.at("viscosity").value("resolution_check", json::object());
            const double gridError = check.value("error_ln", NAN);
            std::printf("%8.3g %6u %10.4g %10.4g [%9.4g, %9.4g] %6s %10.3f %s\n", eta, seed, r.theta[0], gridError, low,
                        high, holds ? "yes" : "no", std::log(high / low), r.intervalMethod.c_str());
            std::fflush(stdout);
        }
    std::printf("coverage %d/%d = %.0f %%, mean ln width %.3f\n", held, count, 100.0 * held / count, widthSum / count);
    if (keep.empty()) fs::remove_all(root);
    return 0;
}
