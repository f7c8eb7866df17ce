// `viscoscope simulate scene.json --out DIR`: runs the forward model and writes per-frame files
// (see surface/surface.h). DIR/simulation.json is written last, so its presence marks a complete run.
#include "cli/simulation_folder.h"

#include "cli/commands.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace viscoscope::cli {

namespace {

struct SimulateOptions {
    std::string scene;
    std::string out;
    std::string progress = "text";
};

void writeFrame(const sim::Simulation& simulation, const std::filesystem::path& dir) {
    const Scene& scene = simulation.scene();
    const int f = simulation.frame();
    if (scene.outputs.particles)
        surface::writeParticles(dir / frameName("particles", f, "bin"), simulation.particles());
    if (!scene.outputs.vdb && !scene.outputs.mesh) return;
    auto levelSet = surface::liquidLevelSet(simulation);
    if (scene.outputs.vdb) surface::writeFrameVdb(dir / frameName("frame", f, "vdb"), simulation, levelSet);
    if (scene.outputs.mesh) {
        std::vector<openvdb::Vec3s> points;
        std::vector<openvdb::Vec3I> triangles;
        surface::meshLevelSet(*levelSet, points, triangles);
        surface::writeObj(dir / frameName("frame", f, "obj"), points, triangles);
    }
}

}  // namespace

std::string frameName(const char* prefix, int frame, const char* ext) {
    char name[64];
    std::snprintf(name, sizeof name, "%s_%05d.%s", prefix, frame, ext);
    return name;
}

int simulateIntoFolder(const Scene& scene, const std::filesystem::path& dir, const ProgressReporter& progress) {
    for (const std::string& warning : resolutionWarnings(scene)) progress.warn(warning);
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) throw InputError(dir.string() + ": cannot create output folder (" + ec.message() + ")");
    std::filesystem::remove(dir / "simulation.json", ec);

    const auto start = std::chrono::steady_clock::now();
    sim::Simulation simulation(scene);
    const double initialVolume = simulation.liquidVolume();
    nlohmann::json holes = nlohmann::json::array();
    for (const sim::HoleCalibration& hole : simulation.holeCalibrations()) {
        holes.push_back({{"solid", hole.solid}, {"resistance", hole.resistance}, {"grid_flux_vs_dagan", hole.gridFlux},
                         {"calibrated_flux_vs_dagan", hole.calibratedFlux}, {"solves", hole.solves}});
        progress.report({{"event", "hole_calibration"}, {"stage", "simulate"}, {"solid", hole.solid},
                         {"resistance", hole.resistance}, {"grid_flux_vs_dagan", hole.gridFlux},
                         {"calibrated_flux_vs_dagan", hole.calibratedFlux}});
    }
    writeFrame(simulation, dir);

    nlohmann::json frames = nlohmann::json::array();
    for (int f = 0; f < scene.frames; ++f) {
        const sim::FrameStats stats = simulation.advanceFrame();
        writeFrame(simulation, dir);
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const nlohmann::json record = {
            {"frame", stats.frame},        {"time", stats.simulatedTime},
            {"steps", stats.steps},        {"solver_iterations", stats.solverIterations},
            {"volume", stats.liquidVolume}, {"max_speed", stats.maxSpeed},
            {"converged", stats.converged},
            {"seconds", {{"transfer", stats.transferSeconds}, {"solve", stats.solveSeconds}, {"other", stats.otherSeconds}}}};
        frames.push_back(record);
        progress.report({{"event", "progress"}, {"stage", "simulate"}, {"frame", stats.frame}, {"frames", scene.frames},
                         {"time", stats.simulatedTime}, {"steps", stats.steps},
                         {"iterations", stats.solverIterations}, {"volume", stats.liquidVolume},
                         {"elapsed", elapsed}, {"eta", elapsed / (f + 1) * (scene.frames - f - 1)}});
        if (g_cancelRequested) {
            progress.report({{"event", "cancelled"}, {"stage", "simulate"}, {"frame", stats.frame}});
            return kExitCancelled;
        }
    }
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double drift = initialVolume > 0 ? simulation.liquidVolume() / initialVolume - 1 : 0;
    const nlohmann::json summary = {{"format", "viscoscope.simulation"}, {"version", 1},
                                    {"scene", sceneToJson(scene)}, {"frames", frames},
                                    {"initial_volume", initialVolume}, {"volume_drift", drift},
                                    {"hole_calibrations", holes},
                                    {"wall_seconds", elapsed}};
    std::ofstream(dir / "simulation.json.tmp") << summary.dump(1);
    std::filesystem::rename(dir / "simulation.json.tmp", dir / "simulation.json");
    progress.report({{"event", "done"}, {"stage", "simulate"}, {"frames", scene.frames}, {"elapsed", elapsed},
                     {"volume_drift", drift}});
    return kExitOk;
}

Command addSimulateCommand(CLI::App& app) {
    auto options = std::make_shared<SimulateOptions>();
    CLI::App* sub = app.add_subcommand("simulate", "Simulate a scene and write per-frame surface, fields and particles");
    sub->add_option("scene", options->scene, "Scene JSON file")->required();
    sub->add_option("--out", options->out, "Output folder")->required();
    sub->add_option("--progress", options->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}));
    return {sub, [options] {
                return simulateIntoFolder(loadScene(options->scene), options->out, ProgressReporter(options->progress));
            }};
}

}  // namespace viscoscope::cli
