// `viscoscope simulate scene.json --out DIR`: runs the forward model and writes per-frame files
// (see surface/surface.h). DIR/simulation.json is written last, so its presence marks a complete run.
// A run that stops early (cancelled, killed) leaves DIR/resume.state; running the same scene into
// DIR again goes on from it; a completed one is kept.
#include "cli/simulation_folder.h"

#include "cli/commands.h"
#include "cli/output_lock.h"
#include "scene/digest.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <optional>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace viscoscope::cli {

std::string frameName(const char* prefix, int frame, const char* ext) {
    char name[64];
    std::snprintf(name, sizeof name, "%s_%05d.%s", prefix, frame, ext);
    return name;
}

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
        // The mesh is rendered (synth's reference, an artist's import): the smoothed particles' reach
        // into walls and below the ground, which would show through a thin wall, is cut off first,
        // as identify's silhouettes cut it.
        surface::clipToSolidExterior(*levelSet, simulation.solids());
        std::vector<openvdb::Vec3s> points;
        std::vector<openvdb::Vec3I> triangles;
        surface::meshLevelSet(*levelSet, points, triangles);
        surface::writeObj(dir / frameName("frame", f, "obj"), points, triangles);
    }
}

using Clock = std::chrono::steady_clock;

// The state is saved after the first frame, then after a frame once the longer of these has passed
// since the last save: at 96³ it is 0.13 GB (the sample cup), whose writing every frame would be
// felt, while a cancel inside a frame loses what was simulated since the last save.
constexpr double kMinResumeSaveInterval = 5;  // s
constexpr double kResumeSaveCostShare = 0.05;  // of the run's time spent saving, at most
const char* const kResumeFile = "resume.state";

// What a run says, once each, when its result is probably wrong: liquid lost and solves stopped
// short of their tolerance. Each warning reaches the progress lines and simulation.json; a resumed
// run says again what its frames before the cut found.
class RunDoubts {
public:
    RunDoubts(const nlohmann::json& framesSoFar, double initialVolume, const ProgressReporter& progress)
        : loss_(initialVolume) {
        for (const nlohmann::json& frame : framesSoFar)
            observe(frame.at("frame").get<int>(), frame.at("converged").get<bool>(), frame.at("volume").get<double>(),
                    progress);
    }
    void observe(int frame, bool converged, double liquidVolume, const ProgressReporter& progress) {
        if (!converged && unconvergedFrames_++ == 0)
            add("frame " + std::to_string(frame) + ": the pressure–viscosity solve stopped at "
                "solver.max_iterations short of solver.tolerance; the flow is not the model's (raise "
                "max_iterations, or check η, σ and the time step)", progress);
        const double lost = loss_.observe(liquidVolume);
        if (lost > sim::kLostLiquidShare && !lostReported_) {
            lostReported_ = true;
            add("frame " + std::to_string(frame) + ": the liquid has lost " + std::to_string(int(100 * lost)) +
                " % of its volume (it left the domain or went into a solid); the result describes another amount of "
                "liquid", progress);
        }
    }
    // With the count of frames whose solve did not converge.
    nlohmann::json warnings() const {
        nlohmann::json all = warnings_;
        if (unconvergedFrames_ > 1) all.push_back(std::to_string(unconvergedFrames_) + " frames had a solve stopped short of its tolerance");
        return all;
    }

private:
    void add(const std::string& warning, const ProgressReporter& progress) {
        progress.warn(warning);
        warnings_.push_back(warning);
    }
    sim::LiquidLoss loss_;
    bool lostReported_ = false;
    int unconvergedFrames_ = 0;
    nlohmann::json warnings_ = nlohmann::json::array();
};

// What the run has done so far besides the simulation's own state: resume.state holds it as a
// JSON header before Simulation::saveState's bytes.
struct RunRecord {
    nlohmann::json scene;  // sceneToJson of the scene it ran
    nlohmann::json frames = nlohmann::json::array();
    double initialVolume = 0;
    double wallSeconds = 0;  // before this process
};

void saveResumeState(const std::filesystem::path& dir, const RunRecord& record, double wallSeconds,
                     const sim::Simulation& simulation) {
    std::ostringstream stateBytes(std::ios::binary);
    simulation.saveState(stateBytes);
    const std::string state = stateBytes.str();
    // Sealed, with the state's digest: a damaged copy starts over instead of resuming from garbage.
    const std::string text = sealed({{"format", "viscoscope.resume"}, {"version", 1}, {"engine_build", engineBuild()},
                                     {"scene", record.scene},
                                     {"frames", record.frames}, {"initial_volume", record.initialVolume},
                                     {"wall_seconds", wallSeconds}, {"state_digest", Digest().add(state).hex()}})
                                 .dump();
    writeFileAtomically(dir / kResumeFile, [&](std::ostream& out) {  // a kill mid-write leaves the last one whole
        const uint64_t length = text.size();
        out.write(reinterpret_cast<const char*>(&length), sizeof length);
        out << text << state;
    });
}

// The record of the run DIR/resume.state continues, with `simulation` restored to its last frame;
// nothing when there is none, or when it is of another scene or unreadable (said in a warning).
std::optional<RunRecord> resumeRun(const std::filesystem::path& dir, const Scene& scene,
                                   sim::Simulation& simulation, const ProgressReporter& progress) {
    const std::filesystem::path file = dir / kResumeFile;
    std::ifstream in(file, std::ios::binary);
    if (!in) return std::nullopt;
    try {
        uint64_t length = 0;
        std::string text;
        if (in.read(reinterpret_cast<char*>(&length), sizeof length) && length < (uint64_t(1) << 32)) {
            text.resize(length);
            in.read(text.data(), std::streamsize(length));
        }
        const nlohmann::json header = nlohmann::json::parse(text, nullptr, false);
        const std::string state{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        if (!sealIsIntact(header) || header.value("format", "") != "viscoscope.resume" ||
            header.value("state_digest", "") != Digest().add(state).hex())
            throw InputError("damaged, or not a resume file");
        RunRecord record{header.at("scene"), header.at("frames"), header.at("initial_volume").get<double>(),
                         header.at("wall_seconds").get<double>()};
        if (record.scene.dump() != sceneToJson(scene).dump()) {
            progress.warn(file.string() + " is of another scene; starting over");
            return std::nullopt;
        }
        if (header.value("engine_build", "") != engineBuild()) {
            progress.warn(file.string() + " was written by another build of the engine; starting over");
            return std::nullopt;
        }
        std::istringstream stateIn(state, std::ios::binary);
        simulation.restoreState(stateIn);
        return record;
    } catch (const std::exception& e) {
        progress.warn(file.string() + ": cannot resume from it (" + e.what() + "); starting over");
        return std::nullopt;
    }
}

// The frame files a previous run left in DIR: a run that starts over removes them, so that none
// passes for one of its own.
void removeFrameFiles(const std::filesystem::path& dir) {
    static const std::regex frameFile(R"((frame_\d{5}\.(vdb|obj))|(particles_\d{5}\.bin))");
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
        if (std::regex_match(entry.path().filename().string(), frameFile)) std::filesystem::remove(entry.path(), ec);
}

// Whether DIR holds a completed run of `scene` by this engine build with all its frame files.
bool holdsCompletedRun(const std::filesystem::path& dir, const Scene& scene) {
    std::ifstream in(dir / "simulation.json");
    if (!in) return false;
    const nlohmann::json summary = nlohmann::json::parse(in, nullptr, false);
    if (summary.is_discarded() || summary.value("engine_build", "") != engineBuild() ||
        summary.value("scene", nlohmann::json()).dump() != sceneToJson(scene).dump())
        return false;
    for (int f = 0; f <= scene.frames; ++f)
        if ((scene.outputs.particles && !std::filesystem::exists(dir / frameName("particles", f, "bin"))) ||
            (scene.outputs.vdb && !std::filesystem::exists(dir / frameName("frame", f, "vdb"))) ||
            (scene.outputs.mesh && !std::filesystem::exists(dir / frameName("frame", f, "obj"))))
            return false;
    return true;
}

}  // namespace

int simulateIntoFolder(const Scene& scene, const std::filesystem::path& dir, const ProgressReporter& progress) {
    for (const std::string& warning : resolutionWarnings(scene)) progress.warn(warning);
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) throw InputError(dir.string() + ": cannot create output folder (" + ec.message() + ")");
    if (holdsCompletedRun(dir, scene)) {
        progress.report({{"event", "done"}, {"stage", "simulate"}, {"frames", scene.frames},
                         {"kept", "a completed run of this scene by this engine build"}});
        return kExitOk;
    }
    std::filesystem::remove(dir / "simulation.json", ec);

    const auto start = Clock::now();
    sim::Simulation simulation(scene);
    nlohmann::json holes = nlohmann::json::array();
    for (const sim::HoleCalibration& hole : simulation.holeCalibrations()) {
        holes.push_back({{"solid", hole.solid}, {"resistance", hole.resistance}, {"grid_flux_vs_dagan", hole.gridFlux},
                         {"calibrated_flux_vs_dagan", hole.calibratedFlux}, {"solves", hole.solves}});
        progress.report({{"event", "hole_calibration"}, {"stage", "simulate"}, {"solid", hole.solid},
                         {"resistance", hole.resistance}, {"grid_flux_vs_dagan", hole.gridFlux},
                         {"calibrated_flux_vs_dagan", hole.calibratedFlux}});
    }
    std::optional<RunRecord> resumed = resumeRun(dir, scene, simulation, progress);
    RunRecord record;
    if (resumed) {
        record = std::move(*resumed);
        progress.report({{"event", "resumed"}, {"stage", "simulate"}, {"frame", simulation.frame()},
                         {"frames", scene.frames}});
    } else {
        record.scene = sceneToJson(scene);
        record.initialVolume = simulation.liquidVolume();
        std::filesystem::remove(dir / kResumeFile, ec);  // an older run's must not outlive these frames
        removeFrameFiles(dir);
        writeFrame(simulation, dir);
    }
    const auto wallSeconds = [&] {
        return record.wallSeconds + std::chrono::duration<double>(Clock::now() - start).count();
    };

    RunDoubts doubts(record.frames, record.initialVolume, progress);
    const int firstFrame = simulation.frame();
    int savedFrame = resumed ? firstFrame : -1;  // the frame resume.state holds
    auto lastSave = Clock::now();
    double saveSeconds = 0;
    for (int f = firstFrame; f < scene.frames; ++f) {
        sim::FrameStats stats;
        try {
            stats = simulation.advanceFrame();
        } catch (const Cancelled&) {  // between two steps, a state no resume can start from
            progress.report({{"event", "cancelled"}, {"stage", "simulate"}, {"frame", simulation.frame()},
                             {"resumes_from_frame", std::max(savedFrame, 0)}});
            return kExitCancelled;
        }
        writeFrame(simulation, dir);
        doubts.observe(stats.frame, stats.converged, stats.liquidVolume, progress);
        const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
        record.frames.push_back(
            {{"frame", stats.frame},        {"time", stats.simulatedTime},
             {"steps", stats.steps},        {"solver_iterations", stats.solverIterations},
             {"volume", stats.liquidVolume}, {"max_speed", stats.maxSpeed},
             {"converged", stats.converged},
             {"seconds", {{"transfer", stats.transferSeconds}, {"solve", stats.solveSeconds}, {"other", stats.otherSeconds}}}});
        progress.report({{"event", "progress"}, {"stage", "simulate"}, {"frame", stats.frame}, {"frames", scene.frames},
                         {"time", stats.simulatedTime}, {"steps", stats.steps},
                         {"iterations", stats.solverIterations}, {"volume", stats.liquidVolume},
                         {"elapsed", elapsed}, {"remaining_s", elapsed / (f + 1 - firstFrame) * (scene.frames - f - 1)}});
        if (f + 1 == scene.frames) break;  // complete, even if cancelled just now
        const double sinceSave = std::chrono::duration<double>(Clock::now() - lastSave).count();
        if (savedFrame < 0 || cancelRequested() ||
            sinceSave >= std::max(kMinResumeSaveInterval, saveSeconds / kResumeSaveCostShare)) {
            const auto saveStart = Clock::now();
            saveResumeState(dir, record, wallSeconds(), simulation);
            lastSave = Clock::now();
            saveSeconds = std::chrono::duration<double>(lastSave - saveStart).count();
            savedFrame = stats.frame;
        }
        if (cancelRequested()) {
            progress.report({{"event", "cancelled"}, {"stage", "simulate"}, {"frame", stats.frame}});
            return kExitCancelled;
        }
    }
    const double drift = record.initialVolume > 0 ? simulation.liquidVolume() / record.initialVolume - 1 : 0;
    nlohmann::json summary = {{"format", "viscoscope.simulation"}, {"version", 1}, {"engine_build", engineBuild()},
                              {"scene", record.scene}, {"frames", record.frames},
                              {"initial_volume", record.initialVolume}, {"volume_drift", drift},
                              {"hole_calibrations", holes},
                              {"warnings", doubts.warnings()},
                              {"wall_seconds", wallSeconds()}};
    if (resumed) summary["resumed_from_frame"] = firstFrame;
    writeJsonAtomically(summary, dir / "simulation.json");
    std::filesystem::remove(dir / kResumeFile, ec);
    progress.report({{"event", "done"}, {"stage", "simulate"}, {"frames", scene.frames},
                     {"elapsed", std::chrono::duration<double>(Clock::now() - start).count()},
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
                const Scene scene = loadScene(options->scene);
                const OutputFolderLock lock(options->out, "simulate");
                return simulateIntoFolder(scene, options->out, ProgressReporter(options->progress));
            }};
}

}  // namespace viscoscope::cli
