// `viscoscope identify` as the add-on runs it: bad jobs fail fast with exit 2 and one line; a run
// killed with SIGKILL between generations resumes to the same result as an uninterrupted run;
// SIGTERM checkpoints and exits 3; progress is JSON lines with the fields the add-on reads. Under
// mpirun, ranks share the evaluations and the result is the single process's.
// The problem is cli_support.h's slump, with 2–3 generations; identify_loop_test checks the
// recovered viscosity on a simulated reference.
#include "cli_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

using viscoscope::cli_test::CommandResult;
using viscoscope::cli_test::runCommand;
using viscoscope::cli_test::runViscoscope;
using viscoscope::cli_test::slurp;
using namespace viscoscope::cli_test::slump;

class CliIdentify : public ::testing::Test {
protected:
    void SetUp() override {
        const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        dir_ = fs::temp_directory_path() / ("viscoscope_cli_identify_" + test + "_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        writeSlumpCase(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    json job(int generations = 2) const { return slumpJob(generations); }

    fs::path writeJob(const json& doc, const std::string& name = "job.json") const {
        std::ofstream(dir_ / name) << doc.dump(1);
        return dir_ / name;
    }
    fs::path writeJobText(const std::string& text, const std::string& name) const {
        std::ofstream(dir_ / name) << text;
        return dir_ / name;
    }

    CommandResult run(const std::string& arguments) const { return runViscoscope(arguments, dir_); }

    // Starts identify in the background on one thread (the foreground runs use all cores, so a resumed
    // run that matches an uninterrupted one also shows the result does not depend on the thread count).
    pid_t start(const fs::path& jobFile, const fs::path& out) const {
        const pid_t pid = fork();
        if (pid == 0) {
            const std::string log = (dir_ / "background.out").string();
            freopen(log.c_str(), "w", stdout);
            freopen((dir_ / "background.err").string().c_str(), "w", stderr);
            execl(VISCOSCOPE_CLI, VISCOSCOPE_CLI, "identify", jobFile.c_str(), "--out", out.c_str(), "--progress",
                  "json", "--no-plots", "--no-fields", "--threads", "1", static_cast<char*>(nullptr));
            _exit(127);
        }
        return pid;
    }

    // Waits until OUT/checkpoint.json holds at least `generation` finished generations.
    static bool waitForGeneration(const fs::path& out, int generation, pid_t pid) {
        for (int i = 0; i < 60000; ++i) {
            if (fs::exists(out / "checkpoint.json")) {
                try {
                    const json cp = json::parse(slurp(out / "checkpoint.json"));
                    if (cp.at("cma").at("generation").get<int>() >= generation) return true;
                } catch (const std::exception&) {
                }
            }
            int status = 0;
            if (waitpid(pid, &status, WNOHANG) == pid) return false;  // ended early
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        return false;
    }

    void expectBadInput(const fs::path& jobFile, const std::string& fragment) const {
        const CommandResult r = run("identify " + jobFile.string() + " --out " + (dir_ / "out_bad").string() +
                                    " --progress json --no-plots --no-fields");
        EXPECT_EQ(r.exitCode, 2) << jobFile << ": " << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << "stderr: " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr: " << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "out_bad" / "result.json"));
        std::printf("[ bad job  ] %s\n", r.err.substr(0, r.err.size() - 1).c_str());
    }

    fs::path dir_;
};

TEST_F(CliIdentify, BadJobsFailFastWithExitCode2) {
    {  // no reference frames: all ω_f = 0
        writeSlumpMasks(dir_ / "reference_unweighted", 96, 64, {0.0, 0.0});
        json doc = job();
        doc["silhouettes"] = "reference_unweighted";
        expectBadInput(writeJob(doc, "no_frames.json"), "no reference frames");
    }
    {  // bounds lower > upper
        json doc = job();
        doc["parameters"][0]["min"] = 100.0;
        doc["parameters"][0]["max"] = 10.0;
        expectBadInput(writeJob(doc, "bounds.json"), "lower 100 > upper 10");
    }
    {  // a generation of a million simulations, which would never end
        json doc = job();
        doc["population"] = 1000000;
        expectBadInput(writeJob(doc, "population.json"), "population: must be in [0, 1000], got 1000000");
    }
    {  // a spread wider than the whole interval, which the search would clip without a word
        json doc = job();
        doc["parameters"][0]["spread"] = 1e308;
        expectBadInput(writeJob(doc, "spread.json"), "parameters[0].spread: 1e+308 from 5 is a step wider than");
    }
    {  // non-finite: 1e999 parses as infinity
        std::string text = job().dump();
        const std::string initial = "\"initial\":5.0";
        text.replace(text.find(initial), initial.size(), "\"initial\":1e999");
        expectBadInput(writeJobText(text, "infinite.json"), "a number past double's range");
        std::string nan = job().dump();
        nan.replace(nan.find("\"spread\":5.0"), 12, "\"spread\":NaN");
        expectBadInput(writeJobText(nan, "nan.json"), "not valid JSON");
    }
    {  // the reference image has another size than the camera
        writeSlumpMasks(dir_ / "reference_small", 48, 32, {1.0, 1.0});
        json doc = job();
        doc["silhouettes"] = "reference_small";
        expectBadInput(writeJob(doc, "size.json"), "reference masks");
    }
    {  // a camera that sees no liquid (it is behind the camera)
        writeSlumpCamera(dir_ / "camera_away.json", {-0.05, 0.03, -0.25});
        json doc = job();
        doc["camera"] = "camera_away.json";
        expectBadInput(writeJob(doc, "away.json"), "sees none of the liquid");
    }
    {  // a camera that sees only the block's top, compared after the block has slumped out of its view:
       // the message says what was compared, since the time offset or fps is the likelier cause
        writeSlumpCamera(dir_ / "camera_top.json", {-0.05, 0.087, 0.25});
        std::vector<double> weights(30, 0.0);
        weights[14] = weights[29] = 1.0;  // frames 30 and 60
        writeSlumpMasks(dir_ / "reference_late", 96, 64, weights);
        json doc = job();
        doc["camera"] = "camera_top.json";
        doc["silhouettes"] = "reference_late";
        expectBadInput(writeJob(doc, "late.json"), "were compared with simulation frames 30–60 at 30 fps, in ");
    }
    {  // a negative weight for the silhouettes' area track
        json doc = job();
        doc["area_track_weight"] = -1.0;
        expectBadInput(writeJob(doc, "area_weight.json"), "area_track_weight: must be ≥ 0");
    }
    {  // a negative height for the ground band
        json doc = job();
        doc["ground_band"] = -0.01;
        expectBadInput(writeJob(doc, "band.json"), "ground_band: must be a finite number ≥ 0");
    }
    {  // a ground band reaching the outlet of a cup 3 cm above the ground: nothing left to compare
        json doc = job();
        json scene = json::parse(slurp(dir_ / "scene.json"));
        scene["solids"].push_back({{"type", "cup"}, {"position", {0.05, 0.02, 0.03}}, {"inner_radius", 0.01},
                                   {"height", 0.02}, {"wall_thickness", 0.003}, {"bottom_thickness", 0.003},
                                   {"hole_radius", 0.003}});
        doc["scene"] = scene;
        doc["ground_band"] = 0.03;
        expectBadInput(writeJob(doc, "band_high.json"), "ground_band: must be below the outlet");
    }
    {  // an unknown way of comparing silhouettes
        json doc = job();
        doc["silhouette_comparison"] = "columns";
        expectBadInput(writeJob(doc, "comparison.json"), "silhouette_comparison: \"columns\" is not");
    }
    {  // a switch that is not true or false
        json doc = job();
        doc["alignment_check"] = "yes";
        expectBadInput(writeJob(doc, "alignment.json"), "alignment_check: must be true or false");
        doc.erase("alignment_check");
        doc["resolution_check"] = 1;
        expectBadInput(writeJob(doc, "resolution.json"), "resolution_check: must be true or false");
    }
    {  // a measured area track that never leaves 0
        std::ofstream(dir_ / "flat_track.csv") << "time_s,area_px\n0,0\n10,0\n";
        json doc = job();
        doc["track"] = "flat_track.csv";
        expectBadInput(writeJob(doc, "flat_track.json"), "area_px is 0 at every compared frame");
    }
    {  // measured fronts: a column the CSV lacks, an unknown observable, a vertical direction, a
       // track that is 0 throughout, and a track-only job whose track measures nothing
        std::ofstream(dir_ / "front.csv") << "time_s,front_m\n0,0\n0.1,0.004\n0.3,0.01\n";
        std::ofstream(dir_ / "front_flat.csv") << "time_s,front_m\n0,0\n0.3,0\n";
        json doc = job();
        doc.erase("silhouettes");
        doc.erase("camera");
        doc["track"] = {{"csv", "front.csv"}, {"column", "front_mm"}, {"observable", "front"},
                        {"origin", {0.035, 0.02, 0}}, {"direction", {1, 0, 0}}};
        expectBadInput(writeJob(doc, "track_column.json"), "front.csv: no column \"front_mm\"");
        doc["track"]["column"] = "front_m";
        doc["track"]["observable"] = "height";
        expectBadInput(writeJob(doc, "track_observable.json"), "track.observable: expected \"front\" or \"radius\"");
        doc["track"]["observable"] = "front";
        doc["track"]["direction"] = {0, 0, -1};
        expectBadInput(writeJob(doc, "track_direction.json"), "track.direction: must have a horizontal component");
        doc["track"]["direction"] = {1, 0, 0};
        doc["track"]["csv"] = "front_flat.csv";
        expectBadInput(writeJob(doc, "track_flat.json"), "the measured track is 0");
        doc["track"].erase("observable");
        expectBadInput(writeJob(doc, "track_alone.json"), "camera: missing");
    }
    {  // an unsupported format
        json doc = job();
        doc["format"] = "viscoscope.scene";
        expectBadInput(writeJob(doc, "format.json"), "format");
    }
    {  // extraction options: a misspelt name, a clean plate that is not there
        json doc = job();
        doc["extraction"] = {{"treshold", 100}};
        expectBadInput(writeJob(doc, "typo.json"), "extraction.treshold: unknown field; did you mean `threshold`?");
        doc["extraction"] = {{"clean_plate", "plate.png"}};
        expectBadInput(writeJob(doc, "plate.json"), "extraction.clean_plate");
    }
    {  // misspelt keys are refused, never run with their defaults; so are a repeated key and trailing text
        json doc = job();
        doc["max_generation"] = 3;
        expectBadInput(writeJob(doc, "misspelt.json"), "max_generation: unknown field; did you mean `max_generations`?");
        doc = job();
        doc["parameters"][0]["maximum"] = 100.0;
        expectBadInput(writeJob(doc, "misspelt_bound.json"), "parameters[0].maximum: unknown field");
        doc = job();
        doc["fidelity"]["coarse_generation"] = 1;
        expectBadInput(writeJob(doc, "misspelt_fidelity.json"), "did you mean `coarse_generations`?");
        const std::string text = job().dump();
        expectBadInput(writeJobText(text.substr(0, text.size() - 1) + ",\"seed\":5}", "repeated.json"),
                       "the key \"seed\" appears twice");
        expectBadInput(writeJobText(text + "\n{}", "trailing.json"), "not valid JSON");
        std::string deep = job().dump();
        deep.insert(deep.size() - 1, ",\"deep\":" + std::string(100000, '[') + std::string(100000, ']'));
        expectBadInput(writeJobText(deep, "deep.json"), "nested deeper than 64 levels");
    }
    {  // parameters: undeclared, not held by the scene's material model, searched outside its physical
       // bounds; a fixed value outside them, or fixed and searched at once
        json doc = job();
        doc["parameters"][0]["name"] = "viscosty";
        expectBadInput(writeJob(doc, "undeclared.json"), "\"viscosty\" is not a declared parameter; did you mean \"viscosity\"?");
        doc["parameters"][0] = {{"name", "flow_index"}};
        expectBadInput(writeJob(doc, "newtonian_n.json"), "the scene's material model is newtonian, and only power_law or carreau or herschel_bulkley has it");
        doc["parameters"][0] = {{"name", "viscosity"}, {"min", 1e-3}, {"max", 1e12}};
        expectBadInput(writeJob(doc, "physical.json"), "parameters[0].max: must be in [1e-06, 1e+09] Pa·s, got 1e+12");
        doc = job();
        doc["fixed"] = {{{"name", "density"}, {"value", 1e300}}};
        expectBadInput(writeJob(doc, "fixed_bounds.json"), "fixed[0].value: must be in [100, 25000] kg/m³");
        doc["fixed"] = {{{"name", "viscosity"}, {"value", 8.0}}};
        expectBadInput(writeJob(doc, "fixed_twice.json"), "\"viscosity\" is searched or fixed twice");
        doc["fixed"] = {{{"name", "surface_tension"}, {"value", 0.07}, {"uncertainty", -0.01}}};
        expectBadInput(writeJob(doc, "fixed_uncertainty.json"), "fixed[0].uncertainty: must be ≥ 0");
        doc["fixed"] = json::array();
        doc["parameters"][0] = {{"name", "solids[0].hole_radius"}};
        expectBadInput(writeJob(doc, "not_a_cup.json"), "solids[0] is a ground, and only a cup has it");
    }
}

// A second run on a folder in use would resume from the first's half-written state and answer
// otherwise: it is refused at once, naming the process; once that process is gone (even by kill -9,
// which leaves the lock file behind) the folder is free again.
// diagnose refuses in one line, before any fit: an effect it does not know, one the job cannot take
// when asked for by name, a time budget that is no number of seconds, and a reference too short to
// hold frames out of the fit.
TEST_F(CliIdentify, DiagnoseRefusesWhatItCannotDiagnoseInOneLine) {
    const auto expectRefused = [&](const std::string& arguments, const fs::path& jobFile, const std::string& fragment) {
        const CommandResult r = run("diagnose " + jobFile.string() + " --out " + (dir_ / "diagnosis").string() +
                                    " --progress json --no-plots " + arguments);
        EXPECT_EQ(r.exitCode, 2) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << "stderr: " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr: " << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "diagnosis" / "diagnosis.json"));
        EXPECT_FALSE(fs::exists(dir_ / "diagnosis" / "fits"));
        std::printf("[ diagnose ] %s\n", r.err.substr(0, r.err.size() - 1).c_str());
    };
    writeSlumpMasks(dir_ / "reference_long", 96, 64, std::vector<double>(8, 1.0));
    json doc = job();
    doc["silhouettes"] = "reference_long";
    const fs::path jobFile = writeJob(doc);
    expectRefused("--effects elasticity", jobFile, "unknown effect \"elasticity\"");
    expectRefused("--effects side_walls", jobFile, "side_walls: the scene has no channel solid");
    expectRefused("--time-budget nan", jobFile, "the time budget must be a finite number of seconds ≥ 0");
    expectRefused("--time-budget=-60", jobFile, "the time budget must be a finite number of seconds ≥ 0");
    // Two masks (frames 2 and 4): nothing left to predict after the three a fit needs at least.
    expectRefused("", writeJob(job(), "short.json"), "compared frames, too few to fit 3 and predict at least 2 more");
    // A rheometer curve that is missing, lacks its stress column or holds a stress of zero.
    const auto withRheometer = [&](const std::string& csv, const std::string& text) {
        if (!text.empty()) std::ofstream(dir_ / csv) << text;
        json rheometer = doc;
        rheometer["rheometer"] = csv;
        return writeJob(rheometer, "rheometer.json");
    };
    expectRefused("", withRheometer("absent.csv", ""), "absent.csv: rheometer: not found");
    expectRefused("", withRheometer("torque.csv", "shear_rate_per_s,torque_nm\n1,2\n10,3\n"),
                  "torque.csv: rheometer: no column \"stress_pa\"");
    expectRefused("", withRheometer("zero.csv", "shear_rate_per_s,stress_pa\n1,2\n10,0\n"),
                  "zero.csv: rheometer: row 2: shear rate and stress must be positive numbers, got 10, 0");
    expectRefused("", withRheometer("backwards.csv", "shear_rate_per_s,stress_pa\n10,2\n1,3\n"),
                  "backwards.csv:3: shear_rate_per_s goes backwards");
}

// A thin-film job whose scene or track the film cannot hold is refused before any work, in one line
// naming the field; a good one runs.
TEST_F(CliIdentify, AThinFilmJobRefusesWhatTheFilmCannotHoldInOneLine) {
    const json emitter = {{"type", "emitter"}, {"center", {0, 0, 0}}, {"normal", {0, 0, 1}}, {"radius", 0.008}, {"flux", 3e-6}};
    const json scene = {{"format", "viscoscope.scene"},
                        {"version", 1},
                        {"domain", {{"min", {-0.1, -0.1, -0.01}}, {"max", {0.1, 0.1, 0.03}}, {"resolution", 100}}},
                        {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
                        {"liquids", {emitter}},
                        {"material", {{"density", 1000}, {"viscosity", 20.0}}},
                        {"fps", 0.5},
                        {"frames", 11}};
    std::ofstream(dir_ / "radius.csv") << "time_s,radius_m\n4,0.03\n8,0.04\n12,0.048\n16,0.055\n20,0.06\n";
    const json track = {{"csv", "radius.csv"}, {"column", "radius_m"}, {"observable", "radius"}, {"origin", {0, 0, 0}}};
    const auto filmJob = [&](const json& sceneDoc) {
        std::ofstream(dir_ / "film_scene.json") << sceneDoc.dump();
        return json{{"format", "viscoscope.job"}, {"version", 1},  {"scene", "film_scene.json"}, {"track", track},
                    {"forward_model", "thin_film"},  {"parameters", {{{"name", "viscosity"}}}}, {"max_generations", 2}};
    };
    const auto expectRefused = [&](const json& doc, const std::string& fragment) {
        const CommandResult r = run("identify " + writeJob(doc, "film.json").string() + " --out " +
                                    (dir_ / "film_out").string() + " --progress json --no-plots");
        EXPECT_EQ(r.exitCode, 2) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << "stderr: " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr: " << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "film_out" / "result.json"));
        std::printf("[ film     ] %s", r.err.c_str());
    };
    json doc = filmJob(scene);
    doc["forward_model"] = "lattice_boltzmann";
    expectRefused(doc, "forward_model: expected \"simulation\" or \"thin_film\", got \"lattice_boltzmann\"");
    doc = job();
    doc["forward_model"] = "thin_film";
    expectRefused(doc, "forward_model: thin_film compares a measured track alone");
    doc = filmJob(scene);
    doc["track"]["observable"] = "front";
    doc["track"]["direction"] = {1, 0, 0};
    expectRefused(doc, "forward_model: thin_film needs a measured track of the observable \"radius\"");
    doc = filmJob(scene);
    doc["track"]["origin"] = {0.05, 0, 0};
    expectRefused(doc, "track.origin: the thin-film radius is measured from the emitters' centre (0, 0)");
    doc = filmJob(scene);
    doc["grid_placements"] = 2;
    expectRefused(doc, "grid_placements: the thin-film model has no grid to place");
    json carreau = scene;
    carreau["material"]["model"] = {{"type", "carreau"}, {"eta_infinity", 1.0}, {"relaxation_time", 1.0}, {"flow_index", 0.5}};
    expectRefused(filmJob(carreau), "scene: the thin-film model holds newtonian, power_law and herschel_bulkley materials");
    json walled = scene;
    walled["solids"].push_back({{"type", "box"}, {"min", {0.05, -0.1, -0.01}}, {"max", {0.1, 0.1, 0.03}}});
    expectRefused(filmJob(walled), "scene: the thin-film model needs a single ground plane");
    json raised = scene;
    raised["liquids"][0]["center"] = {0, 0, 0.02};
    expectRefused(filmJob(raised), "liquids[0]: the thin-film model needs the emitter on the ground");
    const CommandResult good = run("identify " + writeJob(filmJob(scene), "film.json").string() + " --out " +
                                   (dir_ / "film_out").string() + " --progress none --no-plots");
    EXPECT_EQ(good.exitCode, 0) << good.err;
    EXPECT_TRUE(fs::exists(dir_ / "film_out" / "result.json"));
    EXPECT_FALSE(fs::exists(dir_ / "film_out" / "fields"));
}

TEST_F(CliIdentify, ASecondRunOnAFolderInUseIsRefused) {
    const fs::path jobFile = writeJob(job(3));
    const fs::path out = dir_ / "shared_out";
    const pid_t pid = start(jobFile, out);
    ASSERT_TRUE(waitForGeneration(out, 1, pid)) << slurp(dir_ / "background.err");
    const CommandResult second = run("identify " + jobFile.string() + " --out " + out.string() + " --progress json");
    EXPECT_EQ(second.exitCode, 2) << second.err;
    EXPECT_NE(second.err.find("in use by process " + std::to_string(pid) + " (viscoscope identify)"), std::string::npos)
        << second.err;
    EXPECT_EQ(std::count(second.err.begin(), second.err.end(), '\n'), 1) << second.err;
    std::printf("[ in use   ] %s", second.err.c_str());
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    const CommandResult after = run("identify " + jobFile.string() + " --out " + out.string() +
                                    " --progress json --no-plots --no-fields");
    EXPECT_EQ(after.exitCode, 0) << after.err;
}

// An evaluation whose fields cannot be written stops the run with exit 1 naming the file: scored as
// a failed evaluation it would have changed the answer. RLIMIT_FSIZE stands in for a full disk (see
// cli_simulate_test): an evaluation's fields do not fit under it.
TEST_F(CliIdentify, AnEvaluationThatCannotWriteStopsTheRun) {
    const fs::path jobFile = writeJob(job(3)), out = dir_ / "out";
    const CommandResult r = runCommand("ulimit -f 32; trap '' XFSZ; exec " + std::string(VISCOSCOPE_CLI) +
                                           " identify " + jobFile.string() + " --out " + out.string() +
                                           " --progress json --no-plots",
                                       dir_);
    EXPECT_EQ(r.exitCode, 1) << r.err;
    EXPECT_NE(r.err.find((out / "fields.partial").string()), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(": cannot write (File too large)"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out / "result.json"));
}

// A best fit whose simulation is not the model's (its solve stopped short of the tolerance every
// frame) says so in the progress lines and result.json's doubts.
TEST_F(CliIdentify, ABestFitWhoseSolveDidNotConvergeIsDoubted) {
    json scene = json::parse(slurp(dir_ / "scene.json"));
    scene["solver"] = {{"max_iterations", 1}};
    std::ofstream(dir_ / "scene.json") << scene.dump(1);
    const CommandResult r = run("identify " + writeJob(job(2)).string() + " --out " + (dir_ / "out").string() +
                                " --progress json --no-plots --no-fields");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json doubts = json::parse(slurp(dir_ / "out/result.json")).at("doubts");
    const std::string expected = "frames whose pressure–viscosity solve stopped short of its tolerance";
    EXPECT_TRUE(std::any_of(doubts.begin(), doubts.end(),
                            [&](const json& d) { return d.get<std::string>().find(expected) != std::string::npos; }))
        << doubts;
    EXPECT_NE(r.out.find(expected), std::string::npos) << "not among the progress lines";
}

TEST_F(CliIdentify, ResumeAfterKillGivesTheUninterruptedResult) {
    const fs::path jobFile = writeJob(job(3));
    const auto t0 = std::chrono::steady_clock::now();
    const CommandResult whole = run("identify " + jobFile.string() + " --out " + (dir_ / "whole").string() +
                                    " --progress json --no-fields");
    const double wholeSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_EQ(whole.exitCode, 0) << whole.err;
    // Progress lines carry what the add-on reads.
    std::istringstream lines(whole.out);
    int progressLines = 0;
    for (std::string line; std::getline(lines, line);) {
        const json event = json::parse(line);
        if (event.at("event") != "progress") continue;
        ++progressLines;
        for (const char* key : {"generation", "generations", "evaluations", "best_eta", "best_E", "sigma", "elapsed", "remaining_s"})
            EXPECT_TRUE(event.contains(key)) << key << " missing in " << line;
    }
    EXPECT_EQ(progressLines, 3);
    const json a = json::parse(slurp(dir_ / "whole" / "result.json"));
    EXPECT_TRUE(a.at("viscosity").contains("value"));
    EXPECT_EQ(a.at("viscosity").at("interval").size(), 2u);
    if (std::system("/usr/bin/python3 -c 'import matplotlib' > /dev/null 2>&1") == 0) {
        EXPECT_TRUE(fs::exists(dir_ / "whole" / "convergence.png"));
        EXPECT_TRUE(fs::exists(dir_ / "whole" / "landscape.png"));
    }

    // Kill -9 once the first generation is checkpointed, then run the same job again.
    const fs::path out = dir_ / "killed";
    const pid_t pid = start(jobFile, out);
    ASSERT_TRUE(waitForGeneration(out, 1, pid)) << slurp(dir_ / "background.err");
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFSIGNALED(status));
    EXPECT_FALSE(fs::exists(out / "result.json"));
    const CommandResult resumed = run("identify " + jobFile.string() + " --out " + out.string() +
                                      " --progress json --no-plots --no-fields");
    ASSERT_EQ(resumed.exitCode, 0) << resumed.err;
    const json b = json::parse(slurp(out / "result.json"));
    std::printf("[ resume   ] killed after generation %d; eta %.6g (uninterrupted %.6g), E %.6g vs %.6g; "
                "uninterrupted run %.1f s\n",
                b.at("resumed_from_generation").get<int>(), b.at("viscosity").at("value").get<double>(),
                a.at("viscosity").at("value").get<double>(), b.at("E").get<double>(), a.at("E").get<double>(),
                wholeSeconds);
    EXPECT_GE(b.at("resumed_from_generation").get<int>(), 1);
    EXPECT_EQ(b.at("viscosity").at("value"), a.at("viscosity").at("value"));
    EXPECT_EQ(b.at("E"), a.at("E"));
    EXPECT_EQ(b.at("evaluations"), a.at("evaluations"));
    ASSERT_EQ(b.at("evaluated").size(), a.at("evaluated").size());
    for (size_t i = 0; i < a.at("evaluated").size(); ++i) {
        EXPECT_EQ(b["evaluated"][i]["theta"], a["evaluated"][i]["theta"]);
        EXPECT_EQ(b["evaluated"][i]["E"], a["evaluated"][i]["E"]);
    }
}

// A cancel abandons the generation in flight instead of finishing it (each of its evaluations takes
// about a second at 32³): the checkpoint stays at the generation before, and a resume redoes it.
TEST_F(CliIdentify, SigtermAbandonsTheGenerationInFlightThenResumes) {
    json slow = job(3);
    slow["resolution"] = 32;
    const fs::path jobFile = writeJob(slow), out = dir_ / "out";
    const pid_t pid = start(jobFile, out);
    ASSERT_TRUE(waitForGeneration(out, 1, pid)) << slurp(dir_ / "background.err");
    kill(pid, SIGTERM);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 3) << slurp(dir_ / "background.err");
    EXPECT_EQ(json::parse(slurp(out / "checkpoint.json")).at("cma").at("generation").get<int>(), 1);
    EXPECT_NE(slurp(dir_ / "background.out").find("cancelled in generation 2"), std::string::npos)
        << slurp(dir_ / "background.out");
    const CommandResult resumed = run("identify " + jobFile.string() + " --out " + out.string() +
                                      " --progress json --no-plots --no-fields");
    EXPECT_EQ(resumed.exitCode, 0) << resumed.err;
    EXPECT_EQ(json::parse(slurp(out / "result.json")).at("resumed_from_generation").get<int>(), 1);
}

TEST_F(CliIdentify, ACheckpointOfAnotherJobIsRefusedAndMoreGenerationsContinue) {
    const fs::path jobFile = writeJob(job(1));
    ASSERT_EQ(run("identify " + jobFile.string() + " --out " + (dir_ / "out").string() +
                  " --progress none --no-plots --no-fields").exitCode, 0);
    json other = job(1);
    other["seed"] = 5;
    const CommandResult r = run("identify " + writeJob(other, "other.json").string() + " --out " +
                                (dir_ / "out").string() + " --progress none --no-plots --no-fields");
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.err.find("checkpoint of a different job"), std::string::npos) << r.err;
    // The same job with a higher max_generations continues the finished run, with a rheometer's
    // curve named too: it changes no E, only what the flow curve found is compared with.
    std::ofstream(dir_ / "rheometer.csv") << "shear_rate_per_s,stress_pa\n1,10\n10,60\n";
    json moreGenerations = job(2);
    moreGenerations["rheometer"] = (dir_ / "rheometer.csv").string();
    const CommandResult more = run("identify " + writeJob(moreGenerations, "more.json").string() + " --out " +
                                   (dir_ / "out").string() + " --progress none --no-plots --no-fields");
    EXPECT_EQ(more.exitCode, 0) << more.err;
    const json result = json::parse(slurp(dir_ / "out" / "result.json"));
    EXPECT_EQ(result.at("generations").get<int>(), 2);
    EXPECT_EQ(result.at("resumed_from_generation").get<int>(), 1);
}

}  // namespace

// Three ranks deal each generation's four evaluations out among themselves (rank 0 takes two), and
// every evaluation, θ*, E and the fields θ*'s run wrote come out as in a single process.
TEST_F(CliIdentify, MpiRanksShareTheEvaluationsAndGiveTheSingleProcessResult) {
#ifndef VISCOSCOPE_MPIEXEC
    GTEST_SKIP() << "built without MPI (Debian's mpi-default-dev)";
#else
    const fs::path jobFile = writeJob(job(3));
    const CommandResult single = run("identify " + jobFile.string() + " --out " + (dir_ / "single").string() +
                                     " --progress json --no-plots --threads 1");
    ASSERT_EQ(single.exitCode, 0) << single.err;
    // Open MPI runs as root only when told twice; three ranks on two cores need --oversubscribe.
    const std::string mpirun = "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 timeout 600 " +
                               std::string(VISCOSCOPE_MPIEXEC) + " --oversubscribe -n 3 " + VISCOSCOPE_CLI;
    const CommandResult ranks = runCommand(mpirun + " identify " + jobFile.string() + " --out " +
                                               (dir_ / "ranks").string() + " --progress json --no-plots --threads 1",
                                           dir_);
    ASSERT_EQ(ranks.exitCode, 0) << ranks.err;
    const json a = json::parse(slurp(dir_ / "single" / "result.json"));
    const json b = json::parse(slurp(dir_ / "ranks" / "result.json"));
    EXPECT_EQ(b.at("viscosity").at("value"), a.at("viscosity").at("value"));
    EXPECT_EQ(b.at("viscosity").at("interval"), a.at("viscosity").at("interval"));
    EXPECT_EQ(b.at("E"), a.at("E"));
    ASSERT_EQ(b.at("evaluated").size(), a.at("evaluated").size());
    std::map<int, int> perRank;
    for (size_t i = 0; i < a.at("evaluated").size(); ++i) {
        EXPECT_EQ(b["evaluated"][i]["theta"], a["evaluated"][i]["theta"]) << i;
        EXPECT_EQ(b["evaluated"][i]["E"], a["evaluated"][i]["E"]) << i;
        EXPECT_EQ(b["evaluated"][i]["frame_E"], a["evaluated"][i]["frame_E"]) << i;
        EXPECT_FALSE(a["evaluated"][i].contains("rank"));
        ++perRank[b["evaluated"][i].value("rank", -1)];
    }
    std::printf("[ mpi      ] %zu evaluations on ranks 0/1/2: %d/%d/%d; eta %.6g in both\n", b.at("evaluated").size(),
                perRank[0], perRank[1], perRank[2], b.at("viscosity").at("value").get<double>());
    EXPECT_EQ(perRank.count(-1), 0u);
    EXPECT_GT(perRank[1], 0);
    EXPECT_GT(perRank[2], 0);
    // θ*'s fields, written by whichever rank ran it into the shared output folder.
    auto vdbFiles = [](const fs::path& dir) {
        std::vector<std::string> names;
        if (fs::exists(dir))
            for (const auto& entry : fs::directory_iterator(dir))
                if (entry.path().extension() == ".vdb") names.push_back(entry.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    };
    const std::vector<std::string> fields = vdbFiles(dir_ / "single" / "fields");
    EXPECT_FALSE(fields.empty());
    EXPECT_EQ(vdbFiles(dir_ / "ranks" / "fields"), fields);
    EXPECT_EQ(b.at("fields").at("mean_ground_speed_m_s"), a.at("fields").at("mean_ground_speed_m_s"));
    EXPECT_EQ(b.at("fields").at("source"), a.at("fields").at("source"));
#endif
}
