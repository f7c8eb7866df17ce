// diagnose's three conclusions on the collapsing column's front (issue 89): a hidden Bingham
// liquid, power law and wall slip, and a Newtonian control, each measured like a lab's from a
// reference run at another resolution and particle seed than the fits use, then diagnosed on the
// job's grid with every effect the column can hold. Prints a row per case: the verdict, the noise
// floor (what share of a held-out gain it explains), the base's and each candidate's held-out E and
// the time, so that the table of conclusions can be read at two grids.
//
//   diagnose_fronts_bench [--resolution 16] [--reference-resolution 24] [--cases bingham,power_law,slip,newtonian]
//                         [--generations 12] [--threads 0] [--keep DIR]
#include "../native/collapsing_column.h"
#include "diagnose/diagnose.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <map>

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace viscoscope;

int main(int argc, char** argv) {
    int resolution = 16, referenceResolution = 24, generations = 12, threads = 0;
    std::vector<std::string> cases{"bingham", "power_law", "slip", "newtonian"};
    std::string keep;
    CLI::App app{"diagnose on synthetic fronts with a hidden effect, and a Newtonian control"};
    app.add_option("--resolution", resolution, "the job's grid");
    app.add_option("--reference-resolution", referenceResolution, "the references' grid");
    app.add_option("--cases", cases, "bingham, power_law, slip, newtonian")->delimiter(',');
    app.add_option("--generations", generations, "max_generations of each fit");
    app.add_option("--threads", threads, "worker threads (0 = all cores)");
    app.add_option("--keep", keep, "folder to keep the jobs and diagnoses in");
    CLI11_PARSE(app, argc, argv);
    openvdb::initialize();

    // The hidden liquids: the materials of diagnose_fronts_test, and a Newtonian one that slips on
    // the ground by a third of the job's 16-cell spacing.
    const json newtonian{{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0}};
    std::map<std::string, json> materials{
        {"bingham", {{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0},
                     {"model", {{"type", "herschel_bulkley"}, {"yield_stress", 60.0}, {"consistency", 10.0}, {"flow_index", 1.0}}}}},
        {"power_law", {{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0},
                       {"model", {{"type", "power_law"}, {"consistency", 20.0}, {"flow_index", 0.4}}}}},
        {"slip", {{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0}, {"slip_length", 0.002}}},
        {"newtonian", newtonian}};
    constexpr int kFrames = 30, kFps = 15;
    const fs::path root = keep.empty() ? fs::temp_directory_path() / ("viscoscope_fronts_" + std::to_string(::getpid())) : fs::path(keep);
    const Eigen::Vector3d gate(0.035, 0.02, 0), wall(0, 0.02, 0);
    std::printf("job grid %d cells, references %d cells\n", resolution, referenceResolution);
    std::printf("%10s %18s %8s %8s %10s %s\n", "hidden", "verdict", "base eta", "noise", "base E", "candidates' held-out E");
    for (const std::string& label : cases) {
        if (!materials.count(label)) {
            std::fprintf(stderr, "unknown case %s\n", label.c_str());
            return 2;
        }
        const fs::path dir = root / label;
        fs::create_directories(dir);
        json reference = column::sceneJson(10.0, referenceResolution, 11, kFrames);
        reference["material"] = materials[label];
        column::writeMeasuredTrack(reference, gate, wall, dir / "front.csv", kFrames, kFps);
        json doc = column::columnJobJson();
        json scene = column::sceneJson(10.0, resolution, 3, kFrames);
        scene["fps"] = kFps;
        doc["scene"] = scene;
        doc["resolution"] = resolution;
        doc["track"] = {{"csv", "front.csv"}, {"column", "front_m"}, {"observable", "front"},
                        {"origin", {gate.x(), gate.y(), gate.z()}}, {"direction", {1, 0, 0}}};
        doc["max_generations"] = generations;
        std::ofstream(dir / "job.json") << doc.dump(1);
        diagnose::DiagnoseOptions options;
        options.identify.threads = threads;
        options.effects = {"shear_thinning", "yield_stress", "wall_slip"};
        const auto started = std::chrono::steady_clock::now();
        const diagnose::Diagnosis diagnosis = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "diagnosis", options);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
        const json& d = diagnosis.document;
        std::string candidates;
        for (const diagnose::ModelFit& fit : diagnosis.candidates) {
            char line[160];
            std::snprintf(line, sizeof line, "%s%s %.3g", candidates.empty() ? "" : ", ", fit.model.c_str(), fit.heldOutE);
            candidates += line;
        }
        std::printf("%10s %18s %8.3f %7.0f%% %10.3g %s; %.0f s\n", label.c_str(), d.at("verdict").get<std::string>().c_str(),
                    diagnosis.base.theta[0], 100 * d.at("noise_floor").at("visible_share").get<double>(),
                    diagnosis.base.heldOutE, candidates.c_str(), seconds);
        std::printf("%10s %s\n", "", d.at("conclusion").get<std::string>().c_str());
        std::fflush(stdout);
    }
    if (keep.empty()) fs::remove_all(root);
    return 0;
}
