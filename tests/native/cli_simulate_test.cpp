// `viscoscope simulate` as a user runs it: a small scene end to end, bad scenes (exit 2 with one
// line naming the field), cancellation by SIGTERM (exit 3, no completion marker) and resuming.
#include "cli_support.h"
#include "scene/digest.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <fcntl.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using viscoscope::cli_test::CommandResult;

// `viscoscope simulate ARGUMENTS` without its progress lines.
CommandResult simulate(const std::string& arguments, const fs::path& dir) {
    return viscoscope::cli_test::runViscoscope("simulate " + arguments + " --progress none", dir);
}

json smallScene() {
    json scene;
    std::ifstream(fs::path(VISCOSCOPE_SOURCE_DIR) / "sample_scenes/capture_cup.json") >> scene;
    scene["domain"]["resolution"] = 16;
    scene["frames"] = 2;
    return scene;
}

class SimulateCommand : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("viscoscope_sim_" + std::to_string(::getpid()) + "_" +
                                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        // Each test's own calibration cache: a hole calibration found by an earlier test or run
        // would skip the solves a test (a cancel inside them) is about.
        ::setenv("VISCOSCOPE_CACHE_DIR", (dir_ / "cache").c_str(), 1);
    }
    void TearDown() override { fs::remove_all(dir_); }
    fs::path write(const json& scene) const {
        const fs::path file = dir_ / "scene.json";
        std::ofstream(file) << scene.dump(1);
        return file;
    }
    fs::path dir_;
};

}  // namespace

TEST_F(SimulateCommand, WritesEveryFrameAndASummary) {
    const CommandResult r = simulate(write(smallScene()).string() + " --out " + (dir_ / "out").string(), dir_);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    // At 16³ the cup's hole spans 1.6 cells: the run goes on and says why its drain rate is wrong.
    EXPECT_NE(r.err.find("warning: solids[1] (cup): its hole is 1.6 cells across at resolution 16"),
              std::string::npos) << r.err;
    for (int f = 0; f <= 2; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%05d.vdb", f);
        EXPECT_TRUE(fs::exists(dir_ / "out" / name)) << name;
        std::snprintf(name, sizeof name, "particles_%05d.bin", f);
        EXPECT_GT(fs::file_size(dir_ / "out" / name), 16u) << name;
    }
    json summary;
    std::ifstream(dir_ / "out/simulation.json") >> summary;
    EXPECT_EQ(summary["frames"].size(), 2u);
    EXPECT_LT(std::abs(summary["volume_drift"].get<double>()), 0.05);
    EXPECT_EQ(summary["warnings"], json::array());
}

// A run whose result is probably wrong says so, on stderr and in simulation.json: here one solver
// iteration a step leaves every solve short of its tolerance, and the liquid loses a third of its volume.
TEST_F(SimulateCommand, ARunThatStopsConvergingOrLosesItsLiquidSaysSo) {
    json scene = smallScene();
    scene["frames"] = 4;
    scene["solver"]["max_iterations"] = 1;
    const CommandResult r = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.err.find("warning: frame 1: the pressure–viscosity solve stopped at solver.max_iterations"),
              std::string::npos) << r.err;
    EXPECT_NE(r.err.find("% of its volume (it left the domain or went into a solid)"), std::string::npos) << r.err;
    const json warnings = json::parse(viscoscope::cli_test::slurp(dir_ / "out/simulation.json")).at("warnings");
    ASSERT_EQ(warnings.size(), 3u) << warnings;
    EXPECT_EQ(warnings[2], "4 frames had a solve stopped short of its tolerance");
}

TEST_F(SimulateCommand, BadScenesExitTwoWithOneLineNamingTheField) {
    struct Case {
        std::string pointer;
        json value;
        std::string mentions;
    };
    const std::vector<Case> cases{
        {"/material/viscosity", -2.0, "material.viscosity"},
        {"/material/density", -1.0, "material.density"},
        {"/solids/1/hole_radius", 0.1, "hole_radius"},
        {"/liquids", json::array(), "liquids"},
        {"/solids/1", json{{"type", "mesh"}, {"path", "missing_dipper.obj"}}, "path"},
        {"/domain/resolution", 1024, "cells need about 505 GB, more than this machine's"},  // not bad_alloc
    };
    for (const Case& c : cases) {
        json scene = smallScene();
        scene[json::json_pointer(c.pointer)] = c.value;
        const CommandResult r = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(r.exitCode, 2) << c.pointer;
        EXPECT_NE(r.err.find(c.mentions), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
    }
    {  // a million frames at one per 1000 s: years of flow at any step gravity allows, refused at once
        json scene = smallScene();
        scene["domain"]["resolution"] = 48;
        scene["frames"] = 1000000;
        scene["fps"] = 0.001;
        const CommandResult r = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(r.exitCode, 2) << r.err;
        EXPECT_NE(r.err.find("scene.json: frames / fps: 1000000 frames at 0.001 fps are 1e+09 s of flow, at least "),
                  std::string::npos) << r.err;
        EXPECT_NE(r.err.find("(--ignore-limits runs it anyway)"), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
    {  // a cup a hundred times wider than the domain is taken for one in another unit, unless waived
        json scene = smallScene();
        scene["solids"][1]["inner_radius"] = 10.0;
        const fs::path file = write(scene);
        const CommandResult refused = viscoscope::cli_test::runViscoscope("check " + file.string(), dir_);
        EXPECT_EQ(refused.exitCode, 2) << refused.err;
        EXPECT_NE(refused.err.find("is it in another unit? (--ignore-limits runs it anyway)"), std::string::npos)
            << refused.err;
        for (const std::string& arguments :
             {"--ignore-limits check " + file.string(), "check " + file.string() + " --ignore-limits"}) {
            const CommandResult waived = viscoscope::cli_test::runViscoscope(arguments, dir_);
            EXPECT_EQ(waived.exitCode, 0) << arguments << ": " << waived.err;
        }
    }
    {  // a hole far narrower than a cell, which the hole calibration's box cannot hold: the message
       // names the scene's cup and field, not the calibration's own box (after the resolution warning)
        json scene = smallScene();
        scene["solids"][1]["hole_radius"] = 1e-4;
        const CommandResult r = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(r.exitCode, 2) << r.err;
        EXPECT_NE(r.err.find("viscoscope: scene.json: solids[1] (cup): its hole (hole_radius 0.0001 m, 0.0178 cells "
                             "across at resolution 16) is too small for the grid to calibrate its drain"),
                  std::string::npos) << r.err;
    }
    {  // a solid in another unit: a 10 cm cube exported in millimetres, refused before its voxelisation,
       // and a cup or liquid that misses the domain
        std::ofstream obj(dir_ / "cube_mm.obj");
        for (int v = 0; v < 8; ++v) obj << "v " << 100 * (v & 1) << " " << 100 * (v >> 1 & 1) << " " << 100 * (v >> 2) << "\n";
        obj << "f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\nf 2 6 8\nf 2 8 4\n";
        obj.close();
        json scene = smallScene();
        scene["solids"].push_back({{"type", "mesh"}, {"path", "cube_mm.obj"}});
        const CommandResult mesh = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(mesh.exitCode, 2) << mesh.err;
        EXPECT_NE(mesh.err.find("solids[2] (mesh) "), std::string::npos) << mesh.err;
        EXPECT_NE(mesh.err.find("times the domain's size; is it in millimetres? Scale it to metres"), std::string::npos) << mesh.err;
        scene = smallScene();
        scene["solids"][1]["position"] = {0, 0, 5};
        const CommandResult cup = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(cup.exitCode, 2) << cup.err;
        EXPECT_NE(cup.err.find("scene.json.solids[1].position: lies outside the domain ([-0.09, -0.09, 0] to "
                               "[0.09, 0.09, 0.18] m); is it in another unit?"), std::string::npos) << cup.err;
    }
    // An empty domain: the liquid box lies entirely inside a solid.
    json scene = smallScene();
    scene["liquids"] = json::array({{{"type", "box"}, {"min", {-0.05, -0.05, -0.01}}, {"max", {0.05, 0.05, 0.0}}}});
    scene["solids"] = json::array({{{"type", "ground"}, {"height", 0.01}}});
    CommandResult r = simulate(write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2) << r.err;
    EXPECT_NE(r.err.find("liquids"), std::string::npos) << r.err;

    std::ofstream(dir_ / "broken.json") << "{ not json";
    r = simulate((dir_ / "broken.json").string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2);
    r = simulate((dir_ / "absent.json").string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.err.find("absent.json"), std::string::npos);
}

namespace {

// Runs `simulate` into `out`, its stderr into OUT.stderr, and sends it SIGTERM once `marker`
// exists; returns its exit code.
int simulateUntil(const std::string& scenePath, const fs::path& out, const fs::path& marker) {
    const std::string errFile = out.string() + ".stderr";
    const pid_t pid = ::fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        const int err = ::open(errFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (err >= 0) ::dup2(err, 2);
        ::execl(VISCOSCOPE_CLI, VISCOSCOPE_CLI, "simulate", scenePath.c_str(), "--out", out.c_str(),
                "--progress", "none", static_cast<char*>(nullptr));
        ::_exit(127);
    }
    for (int i = 0; i < 600 && !fs::exists(marker); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ::kill(pid, SIGTERM);
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

// `viscosity` answers with the solver's law: a power law's K γ̇^(n−1) at the asked rate, a Newtonian
// liquid's η whatever the rate; a rate that is no rate is refused in one line.
TEST_F(SimulateCommand, ViscosityIsTheMaterialLawAtAShearRate) {
    json scene = smallScene();
    scene["material"]["model"] = {{"type", "power_law"}, {"consistency", 7.86}, {"flow_index", 0.4}};
    const fs::path powerLaw = write(scene);
    const CommandResult r = viscoscope::cli_test::runViscoscope("viscosity " + powerLaw.string() + " --shear-rate 9", dir_);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json answer = json::parse(r.out);
    EXPECT_NEAR(answer.at("viscosity_pa_s").get<double>(), 7.86 * std::pow(9.0, -0.6), 1e-9);
    EXPECT_TRUE(answer.at("shear_dependent").get<bool>());
    for (const char* rate : {"0", "-1", "nan"}) {
        const CommandResult bad =
            viscoscope::cli_test::runViscoscope("viscosity " + powerLaw.string() + " --shear-rate " + rate, dir_);
        EXPECT_EQ(bad.exitCode, 2) << rate;
        EXPECT_NE(bad.err.find("--shear-rate"), std::string::npos) << bad.err;
        EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1) << bad.err;
    }
    scene["material"].erase("model");
    const CommandResult newtonian =
        viscoscope::cli_test::runViscoscope("viscosity " + write(scene).string() + " --shear-rate 100", dir_);
    ASSERT_EQ(newtonian.exitCode, 0) << newtonian.err;
    EXPECT_EQ(json::parse(newtonian.out).at("viscosity_pa_s").get<double>(), scene["material"]["viscosity"].get<double>());
}

TEST_F(SimulateCommand, SigtermStopsCleanlyWithExitThree) {
    json scene = smallScene();
    scene["frames"] = 100000;
    EXPECT_EQ(simulateUntil(write(scene).string(), dir_ / "out", dir_ / "out/particles_00002.bin"), 3);
    EXPECT_TRUE(fs::exists(dir_ / "out/particles_00002.bin"));
    EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
    EXPECT_TRUE(fs::exists(dir_ / "out/resume.state"));
}

// A cancel inside a long frame stops the run there, not at the frame's end: the one frame here (20 s
// of flow) never completes, and there is no state to resume from yet.
TEST_F(SimulateCommand, SigtermInsideAFrameStopsWithoutFinishingIt) {
    json scene = smallScene();
    scene["frames"] = 1;
    scene["fps"] = 0.05;
    EXPECT_EQ(simulateUntil(write(scene).string(), dir_ / "out", dir_ / "out/particles_00000.bin"), 3);
    EXPECT_FALSE(fs::exists(dir_ / "out/particles_00001.bin"));
    EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
    EXPECT_FALSE(fs::exists(dir_ / "out/resume.state"));
}

// The hole's calibration is kept for the next run of the same grid, which takes it without a
// solve and makes every frame byte for byte as the first run did; a damaged cache file is passed
// over (the run calibrates again), and an empty VISCOSCOPE_CACHE_DIR keeps nothing.
TEST_F(SimulateCommand, TheHoleCalibrationIsKeptForTheNextRunOfTheSameGrid) {
    const std::string scene = write(smallScene()).string();
    const auto run = [&](const std::string& out) {
        const CommandResult r = simulate(scene + " --out " + (dir_ / out).string(), dir_);
        EXPECT_EQ(r.exitCode, 0) << r.err;
        json summary;
        std::ifstream(dir_ / out / "simulation.json") >> summary;
        return summary.at("hole_calibrations").at(0);
    };
    const json first = run("first");
    EXPECT_GT(first.at("solves").get<int>(), 0);
    ASSERT_TRUE(fs::exists(dir_ / "cache/calibrations"));
    const json second = run("second");
    EXPECT_EQ(second.at("solves"), 0);
    for (const char* figure : {"resistance", "grid_flux_vs_dagan", "calibrated_flux_vs_dagan"})
        EXPECT_EQ(second.at(figure), first.at(figure)) << figure;
    for (int f = 0; f <= 2; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "particles_%05d.bin", f);
        EXPECT_EQ(viscoscope::fileDigest(dir_ / "second" / name), viscoscope::fileDigest(dir_ / "first" / name)) << name;
    }

    for (const fs::directory_entry& entry : fs::directory_iterator(dir_ / "cache/calibrations"))
        std::ofstream(entry.path()) << "{\"engine_build\": \"damaged\"";
    const json afterDamage = run("after_damage");
    EXPECT_GT(afterDamage.at("solves").get<int>(), 0);
    EXPECT_EQ(afterDamage.at("resistance"), first.at("resistance"));

    ::setenv("VISCOSCOPE_CACHE_DIR", "", 1);
    fs::remove_all(dir_ / "cache");
    EXPECT_GT(run("uncached").at("solves").get<int>(), 0);
    EXPECT_FALSE(fs::exists(dir_ / "cache"));
}

// The hole calibration (a minute of steady solves at 64³, before frame 0) stops on a cancel too.
TEST_F(SimulateCommand, SigtermDuringTheHoleCalibrationStopsIt) {
    json scene = smallScene();
    scene["domain"]["resolution"] = 64;
    EXPECT_EQ(simulateUntil(write(scene).string(), dir_ / "out", dir_ / "out/.viscoscope.lock"), 3);
    EXPECT_FALSE(fs::exists(dir_ / "out/particles_00000.bin"));
    const std::string err = viscoscope::cli_test::slurp(dir_ / "out.stderr");
    EXPECT_NE(err.find("cancelled"), std::string::npos) << err;
}

// With the disk full, the run is exit 1 naming the file and the reason, never "done", and leaves no
// half-written file. RLIMIT_FSIZE stands in for the full disk: with SIGXFSZ ignored, every write
// past the limit fails with EFBIG where a full disk fails with ENOSPC, through the same checks.
TEST_F(SimulateCommand, AFailedWriteIsExitOneNamingTheFileNeverDone) {
    const CommandResult r = viscoscope::cli_test::runCommand(
        "ulimit -f 8; trap '' XFSZ; exec " + std::string(VISCOSCOPE_CLI) + " simulate " + write(smallScene()).string() +
            " --out " + (dir_ / "out").string() + " --progress json",
        dir_);
    EXPECT_EQ(r.exitCode, 1) << r.err;
    const std::string lastLine = r.err.substr(r.err.rfind('\n', r.err.size() - 2) + 1);
    EXPECT_NE(lastLine.find("viscoscope: " + (dir_ / "out").string()), std::string::npos) << r.err;
    EXPECT_NE(lastLine.find(": cannot write (File too large)"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("\"done\""), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
    for (const fs::directory_entry& entry : fs::directory_iterator(dir_ / "out")) {
        EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
        if (entry.path().filename() != ".viscoscope.lock")
            EXPECT_GT(fs::file_size(entry.path()), 0u) << entry.path();
    }
}

// Run again after a cancel, the same scene goes on from the last frame whose state was saved (the
// first, when the cancel comes inside a frame a few seconds in) and ends with every frame's
// particles byte for byte those of a run that was never stopped. Another scene starts
// over and leaves none of the first run's frames behind.
TEST_F(SimulateCommand, RunningTheSameSceneAgainResumesBitForBit) {
    json scene = smallScene();
    scene["frames"] = 16;
    const std::string scenePath = write(scene).string();
    ASSERT_EQ(simulate(scenePath + " --out " + (dir_ / "whole").string(), dir_).exitCode, 0);
    ASSERT_EQ(simulateUntil(scenePath, dir_ / "cut", dir_ / "cut/particles_00003.bin"), 3);
    ASSERT_TRUE(fs::exists(dir_ / "cut/resume.state"));
    const CommandResult r = simulate(scenePath + " --out " + (dir_ / "cut").string(), dir_);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    json summary;
    std::ifstream(dir_ / "cut/simulation.json") >> summary;
    const int resumedFrom = summary.value("resumed_from_frame", -1);
    std::printf("cut at frame %d of 16, resumed\n", resumedFrom);
    EXPECT_GE(resumedFrom, 1);
    EXPECT_LT(resumedFrom, 16);
    EXPECT_EQ(summary["frames"].size(), 16u);
    EXPECT_FALSE(fs::exists(dir_ / "cut/resume.state"));
    for (int f = 0; f <= 16; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "particles_%05d.bin", f);
        const std::string whole = viscoscope::cli_test::slurp(dir_ / "whole" / name);
        EXPECT_FALSE(whole.empty()) << name;
        EXPECT_TRUE(whole == viscoscope::cli_test::slurp(dir_ / "cut" / name)) << name << " differs from the uninterrupted run's";
    }

    json shorter = smallScene();
    shorter["frames"] = 100000;
    ASSERT_EQ(simulateUntil(write(shorter).string(), dir_ / "other", dir_ / "other/particles_00003.bin"), 3);
    shorter["frames"] = 2;
    shorter["material"]["viscosity"] = 50.0;
    const CommandResult again = simulate(write(shorter).string() + " --out " + (dir_ / "other").string(), dir_);
    ASSERT_EQ(again.exitCode, 0) << again.err;
    EXPECT_NE(again.err.find("another scene; starting over"), std::string::npos) << again.err;
    EXPECT_TRUE(fs::exists(dir_ / "other/particles_00002.bin"));
    EXPECT_FALSE(fs::exists(dir_ / "other/particles_00003.bin"));
    EXPECT_FALSE(fs::exists(dir_ / "other/resume.state"));
}

// A run cut and resumed keeps what its frames before the cut found.
TEST_F(SimulateCommand, AResumedRunKeepsTheWarningsOfItsFirstPart) {
    json scene = smallScene();
    scene["frames"] = 16;
    scene["solver"]["max_iterations"] = 1;
    const std::string scenePath = write(scene).string();
    ASSERT_EQ(simulate(scenePath + " --out " + (dir_ / "whole").string(), dir_).exitCode, 0);
    ASSERT_EQ(simulateUntil(scenePath, dir_ / "cut", dir_ / "cut/particles_00004.bin"), 3);
    ASSERT_EQ(simulate(scenePath + " --out " + (dir_ / "cut").string(), dir_).exitCode, 0);
    const json whole = json::parse(viscoscope::cli_test::slurp(dir_ / "whole/simulation.json"));
    const json resumed = json::parse(viscoscope::cli_test::slurp(dir_ / "cut/simulation.json"));
    ASSERT_GE(resumed.value("resumed_from_frame", -1), 1) << "the run was not cut after its first frames";
    EXPECT_EQ(resumed.at("warnings"), whole.at("warnings"));
    EXPECT_EQ(whole.at("warnings").size(), 3u) << whole.at("warnings");
}

// A completed run of the same scene by the same engine build is kept as it is (it would come out
// bit for bit the same); a missing frame file or another build's run is simulated again, and so is
// a cut run whose resume state another build wrote.
TEST_F(SimulateCommand, ACompletedRunIsKeptUnlessAFrameOrTheEngineBuildDiffers) {
    const std::string scenePath = write(smallScene()).string(), out = " --out " + (dir_ / "out").string();
    ASSERT_EQ(simulate(scenePath + out, dir_).exitCode, 0);
    const std::string completed = viscoscope::cli_test::slurp(dir_ / "out/simulation.json");
    const std::string build = json::parse(completed).at("engine_build");
    ASSERT_EQ(build.size(), 16u);

    ASSERT_EQ(simulate(scenePath + out, dir_).exitCode, 0);
    EXPECT_EQ(viscoscope::cli_test::slurp(dir_ / "out/simulation.json"), completed) << "the completed run was redone";

    fs::remove(dir_ / "out/particles_00001.bin");
    ASSERT_EQ(simulate(scenePath + out, dir_).exitCode, 0);
    EXPECT_TRUE(fs::exists(dir_ / "out/particles_00001.bin"));
    const std::string redone = viscoscope::cli_test::slurp(dir_ / "out/simulation.json");
    EXPECT_NE(redone, completed) << "a run missing a frame file was kept";

    json summary = json::parse(redone);
    summary["engine_build"] = std::string(16, '0');
    std::ofstream(dir_ / "out/simulation.json") << summary.dump();
    ASSERT_EQ(simulate(scenePath + out, dir_).exitCode, 0);
    EXPECT_EQ(json::parse(viscoscope::cli_test::slurp(dir_ / "out/simulation.json")).at("engine_build"), build)
        << "another build's run was kept";

    json endless = smallScene();
    endless["frames"] = 100000;
    const std::string endlessPath = write(endless).string();
    ASSERT_EQ(simulateUntil(endlessPath, dir_ / "cut", dir_ / "cut/particles_00002.bin"), 3);
    {  // the state as another build would seal it: its header (after its length) names that build
        const std::string state = viscoscope::cli_test::slurp(dir_ / "cut/resume.state");
        uint64_t length = 0;
        std::memcpy(&length, state.data(), sizeof length);
        json header = json::parse(state.substr(sizeof length, length));
        const std::string simulationState = state.substr(sizeof length + length);
        ASSERT_EQ(header.at("engine_build"), build);
        header["engine_build"] = std::string(16, '0');
        const std::string text = viscoscope::sealed(header).dump();
        length = text.size();
        std::ofstream out(dir_ / "cut/resume.state", std::ios::binary);
        out.write(reinterpret_cast<const char*>(&length), sizeof length);
        out << text << simulationState;
    }
    // (Frame 30 is beyond where the cut run stopped, so only the second run writes it.)
    ASSERT_EQ(simulateUntil(endlessPath, dir_ / "cut", dir_ / "cut/particles_00030.bin"), 3);
    const std::string err = viscoscope::cli_test::slurp(dir_ / "cut.stderr");
    EXPECT_NE(err.find("another build of the engine; starting over"), std::string::npos) << err;
}
