// `viscoscope synth` and `viscoscope compare` as a user runs them. Bad input ends with exit 2 and one
// line before any simulation where it can; a tiny synth makes a clip that `extract` reads back into
// masks that match the simulated surface (scored by `score`, the engine's exact rasterizer, over
// the pixels the container does not hide); SIGTERM while Blender renders stops it and exits 3.
// compare gives 0 for a simulation against itself and a finite error against another resolution.
// Blender-dependent cases skip when blender is not installed.
#include "cli_support.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

using viscoscope::cli_test::CommandResult;
using viscoscope::cli_test::runViscoscope;
using viscoscope::cli_test::slurp;

bool blenderInstalled() { return std::system("blender --version > /dev/null 2>&1") == 0; }

// A column of liquid collapsing along +x next to a post (a box solid) standing in front of it, so
// that the camera's view of part of the liquid is hidden by a solid.
json sceneJson(int frames) {
    return {{"format", "viscoscope.scene"},
            {"version", 1},
            {"domain", {{"min", {0, 0, 0}}, {"max", {0.1, 0.04, 0.06}}, {"resolution", 12}}},
            {"solids",
             {{{"type", "ground"}, {"height", 0.0}},
              {{"type", "box"}, {"min", {0.045, 0.0, 0.0}}, {"max", {0.055, 0.01, 0.03}}}}},
            {"liquids", {{{"type", "box"}, {"min", {0.0, 0.0, 0.0}}, {"max", {0.035, 0.04, 0.045}}}}},
            {"material", {{"density", 1400}, {"viscosity", 2.0}}},
            {"fps", 30},
            {"frames", frames},
            {"seed", 1},
            {"output", {{"particles", false}, {"vdb", true}, {"mesh", false}}}};
}

// Looking along +y at the x–z plane from 0.25 m; `t` moves it.
json cameraJson(const std::vector<double>& t = {-0.05, 0.03, 0.25}) {
    return {{"format", "viscoscope.camera"}, {"version", 1}, {"width", 96}, {"height", 64},
            {"K", {{200, 0, 47.5}, {0, 200, 25.5}, {0, 0, 1}}},
            {"distortion", {0, 0, 0, 0, 0}},
            {"R", {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}},
            {"t", t}};
}

class CliSynth : public ::testing::Test {
protected:
    void SetUp() override {
        const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        dir_ = fs::temp_directory_path() / ("viscoscope_cli_synth_" + test + "_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override {
        if (!std::getenv("VISCOSCOPE_KEEP_TEST_DIR")) fs::remove_all(dir_);
    }

    fs::path write(const std::string& name, const std::string& text) const {
        std::ofstream(dir_ / name) << text;
        return dir_ / name;
    }
    CommandResult run(const std::string& arguments) const { return runViscoscope(arguments, dir_); }
    std::string synth(const fs::path& scene, const fs::path& camera, const std::string& extra = "") const {
        return "synth " + scene.string() + " --camera " + camera.string() + " --out " + (dir_ / "out").string() +
               " --progress none " + extra;
    }
    void expectBadInput(const CommandResult& r, const std::string& fragment) const {
        EXPECT_EQ(r.exitCode, 2) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << "stderr: " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "out" / "synth.json"));
        EXPECT_FALSE(fs::exists(dir_ / "out" / "simulation")) << "bad input must fail before simulating: " << r.err;
        std::printf("[ bad input ] %s", r.err.c_str());
    }

    fs::path dir_;
};

}  // namespace

TEST_F(CliSynth, BadInputsExitTwoWithOneLine) {
    const fs::path scene = write("scene.json", sceneJson(2).dump());
    const fs::path camera = write("camera.json", cameraJson().dump());
    expectBadInput(run(synth(dir_ / "absent.json", camera)), "absent.json");
    expectBadInput(run(synth(write("broken.json", "{ not json"), camera)), "broken.json");
    json negative = sceneJson(2);
    negative["material"]["viscosity"] = -1;
    expectBadInput(run(synth(write("negative.json", negative.dump()), camera)), "material.viscosity");
    expectBadInput(run(synth(scene, dir_ / "no_camera.json")), "no_camera.json");
    json noT = cameraJson();
    noT.erase("t");
    expectBadInput(run(synth(scene, write("no_t.json", noT.dump()))), "no_t.json: t: missing");
    json odd = cameraJson();
    odd["width"] = 95;
    expectBadInput(run(synth(scene, write("odd.json", odd.dump()))), "odd.json: width/height: the mp4 clip needs an even");
    json distorted = cameraJson();
    distorted["distortion"][0] = 0.1;
    expectBadInput(run(synth(scene, write("distorted.json", distorted.dump()))), "distortion");
    // Turned around: the scene is behind the camera.
    expectBadInput(run(synth(scene, write("away.json", cameraJson({-0.05, 0.03, -0.25}).dump()))),
                   "sees none of the simulation domain");
    expectBadInput(run(synth(scene, camera, "--blender " + (dir_ / "no_blender").string())), "not found");
}

TEST_F(CliSynth, ACameraThatSeesNoLiquidFailsBeforeRendering) {
    if (!blenderInstalled()) GTEST_SKIP() << "blender not installed";
    // 0.1 m to the right: it sees the right end of the domain, never the liquid at its left.
    const json camera = cameraJson({-0.15, 0.03, 0.25});
    const CommandResult r = run(synth(write("scene.json", sceneJson(2).dump()), write("camera.json", camera.dump())));
    EXPECT_EQ(r.exitCode, 2) << r.err;
    EXPECT_NE(r.err.find("sees no liquid in any of the 3 frames"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out" / "render" / "blender.log"));
}

TEST_F(CliSynth, ATinySynthMakesAClipThatExtractReadsBack) {
    if (!blenderInstalled()) GTEST_SKIP() << "blender not installed";
    const fs::path out = dir_ / "out";
    const CommandResult made = run(synth(write("scene.json", sceneJson(6).dump()), write("camera.json", cameraJson().dump()),
                                         "--resolution 16 --seed 5 --samples 4 --supersample 2"));
    ASSERT_EQ(made.exitCode, 0) << made.err;
    const json summary = json::parse(slurp(out / "synth.json"));
    EXPECT_EQ(summary.at("truth").at("viscosity").get<double>(), 2.0);
    EXPECT_EQ(summary.at("resolution").get<int>(), 16);
    EXPECT_EQ(summary.at("seed").get<int>(), 5);
    EXPECT_EQ(summary.at("render").at("width").get<int>(), 192);
    for (const char* file : {"reference.mp4", "clean_plate.png", "exclude.png", "camera.json",
                             "simulation/frame_00006.vdb", "simulation/simulation.json"})
        EXPECT_TRUE(fs::exists(out / file)) << file;

    const CommandResult extracted = run("extract " + (out / "reference.mp4").string() + " --out " +
                                        (dir_ / "extracted").string() + " --clean-plate " +
                                        (out / "clean_plate.png").string() + " --exclude " +
                                        (out / "exclude.png").string() + " --progress none");
    ASSERT_EQ(extracted.exitCode, 0) << extracted.err;
    const json manifest = json::parse(slurp(dir_ / "extracted" / "manifest.json"));
    EXPECT_EQ(manifest.at("frames").size(), 7u);
    EXPECT_EQ(manifest.at("width").get<int>(), 96);
    EXPECT_NEAR(manifest.at("fps").get<double>(), 30, 1e-6);

    // The extracted masks against the reference simulation's own surfaces, outside the post.
    const CommandResult scored = run("score --camera " + (out / "camera.json").string() + " --reference " +
                                     (dir_ / "extracted").string() + " --sim " + (out / "simulation").string() +
                                     " --out " + (dir_ / "score").string() + " --progress none");
    ASSERT_EQ(scored.exitCode, 0) << scored.err;
    const json score = json::parse(slurp(dir_ / "score" / "score.json"));
    double worst = 1, sum = 0;
    for (const json& frame : score.at("frames")) {
        worst = std::min(worst, frame.at("iou").get<double>());
        sum += frame.at("iou").get<double>();
    }
    std::printf("[ synth    ] 96x64 clip of a 16^3 simulation: IoU of extracted vs true masks mean %.3f, worst %.3f; "
                "simulate %.1f s, render %.1f s, encode %.2f s\n",
                sum / score.at("frames").size(), worst, summary["timings"]["simulate_s"].get<double>(),
                summary["timings"]["render_s"].get<double>(), summary["timings"]["encode_s"].get<double>());
    EXPECT_GT(worst, 0.85);
}

namespace {

// A cup of liquid draining through its hole onto the ground, seen from the side and 22° above, so
// that the camera sees into the cup's mouth. `transparent` makes the cup glass, which synth does not
// draw at all.
json cupSceneJson(bool transparent) {
    return {{"format", "viscoscope.scene"},
            {"version", 1},
            {"domain", {{"min", {-0.05, -0.05, 0.0}}, {"max", {0.05, 0.05, 0.12}}, {"resolution", 20}}},
            {"solids",
             {{{"type", "ground"}, {"height", 0.0}},
              {{"type", "cup"}, {"position", {0, 0, 0.04}}, {"inner_radius", 0.025}, {"height", 0.04},
               {"wall_thickness", 0.003}, {"bottom_thickness", 0.004}, {"hole_radius", 0.008},
               {"transparent", transparent}}}},
            {"liquids", {{{"type", "cup_fill"}, {"cup", 1}, {"volume", 6.5e-5}}}},
            {"material", {{"density", 1400}, {"viscosity", 0.3}}},
            {"fps", 30},
            {"frames", 10},
            {"seed", 1},
            {"output", {{"particles", false}, {"vdb", true}, {"mesh", false}}}};
}

json cameraAbove() {
    const Eigen::Vector3d centre(0, -0.25, 0.16), target(0, 0, 0.06);
    const Eigen::Vector3d forward = (target - centre).normalized();
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    Eigen::Matrix3d R;
    R << right.transpose(), down.transpose(), forward.transpose();
    const Eigen::Vector3d t = -R * centre;
    json rows = json::array();
    for (int i = 0; i < 3; ++i) rows.push_back({R(i, 0), R(i, 1), R(i, 2)});
    // Twice the other tests' image size: the liquid seen through the mouth is a band a few pixels
    // tall, and a pixel's disagreement along an outline would be most of it.
    return {{"format", "viscoscope.camera"}, {"version", 1}, {"width", 192}, {"height", 128},
            {"K", {{260, 0, 95.5}, {0, 260, 63.5}, {0, 0, 1}}},
            {"distortion", {0, 0, 0, 0, 0}},
            {"R", rows},
            {"t", {t.x(), t.y(), t.z()}}};
}

}  // namespace

// The engine's silhouettes of a simulation against Blender's own render of what the camera sees of
// its liquid (synth --true-masks): an opaque cup hides the liquid behind and inside it but for what
// shows through its mouth, a glass one hides nothing. Scored as if its cup were the other kind, each
// must do worse, or the depth test would not be what matches them.
TEST_F(CliSynth, SimulatedSilhouettesSeeWhatBlenderRendersOfACupOpaqueOrGlass) {
    if (!blenderInstalled()) GTEST_SKIP() << "blender not installed";
    const fs::path camera = write("camera.json", cameraAbove().dump());
    for (const bool transparent : {false, true}) {
        const std::string kind = transparent ? "glass" : "opaque";
        const fs::path out = dir_ / kind;
        const fs::path scene = write(kind + ".json", cupSceneJson(transparent).dump());
        const fs::path otherScene = write(kind + "_other.json", cupSceneJson(!transparent).dump());
        const CommandResult made =
            run("synth " + scene.string() + " --camera " + camera.string() + " --out " + out.string() +
                " --seed 5 --samples 4 --supersample 2 --true-masks --progress none");
        ASSERT_EQ(made.exitCode, 0) << made.err;
        const auto iou = [&](const fs::path& asScene, const std::string& name) {
            const CommandResult scored = run("score --camera " + (out / "camera.json").string() + " --reference " +
                                             (out / "true_masks").string() + " --sim " + (out / "simulation").string() +
                                             " --scene " + asScene.string() + " --out " + (out / name).string() +
                                             " --progress none");
            EXPECT_EQ(scored.exitCode, 0) << scored.err;
            const json score = json::parse(slurp(out / name / "score.json"));
            double worst = 1, sum = 0;
            for (const json& frame : score.at("frames")) {
                worst = std::min(worst, frame.at("iou").get<double>());
                sum += frame.at("iou").get<double>();
            }
            return std::pair{worst, sum / score.at("frames").size()};
        };
        const auto [worst, mean] = iou(scene, "score");
        const auto [otherWorst, otherMean] = iou(otherScene, "score_other");
        std::printf("[ synth    ] %s cup seen from above: IoU of the rendered masks against the engine's "
                    "mean %.3f, worst %.3f; drawn as the other kind: mean %.3f, worst %.3f\n",
                    kind.c_str(), mean, worst, otherMean, otherWorst);
        EXPECT_GT(worst, 0.85) << kind;
        EXPECT_LT(otherMean, mean - 0.05) << kind;
    }
}

// Cancelled while Blender renders, synth exits 3 and Blender stops. Run again, it keeps the
// simulation and the whole renders, renders the rest and completes.
TEST_F(CliSynth, SigtermWhileRenderingStopsBlenderAndRunningAgainFinishesTheRest) {
    if (!blenderInstalled()) GTEST_SKIP() << "blender not installed";
    const std::string scene = write("scene.json", sceneJson(40).dump()).string();
    const std::string camera = write("camera.json", cameraJson().dump()).string();
    const std::string out = (dir_ / "out").string();
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        execl(VISCOSCOPE_CLI, VISCOSCOPE_CLI, "synth", scene.c_str(), "--camera", camera.c_str(), "--out", out.c_str(),
              "--resolution", "8", "--samples", "64", "--progress", "none", static_cast<char*>(nullptr));
        _exit(127);
    }
    const fs::path firstFrame = dir_ / "out" / "render" / "frame_00000.png";
    for (int i = 0; i < 1200 && !fs::exists(firstFrame); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ASSERT_TRUE(fs::exists(firstFrame));
    kill(pid, SIGTERM);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 3);
    EXPECT_FALSE(fs::exists(dir_ / "out" / "synth.json"));
    EXPECT_FALSE(fs::exists(dir_ / "out" / "reference.mp4"));
    // Blender is gone: no frame appears after the exit.
    const auto rendered = [&] {
        int count = 0;
        for (const auto& entry : fs::directory_iterator(dir_ / "out" / "render")) count += entry.path().extension() == ".png";
        return count;
    };
    const int atExit = rendered();
    std::this_thread::sleep_for(std::chrono::seconds(2));
    EXPECT_EQ(rendered(), atExit);

    const fs::path summary = dir_ / "out" / "simulation" / "simulation.json";
    const auto simulated = fs::last_write_time(summary), firstRendered = fs::last_write_time(firstFrame);
    const CommandResult again = run(synth(scene, camera, "--resolution 8 --samples 64"));
    ASSERT_EQ(again.exitCode, 0) << again.err;
    EXPECT_TRUE(fs::exists(dir_ / "out" / "synth.json"));
    EXPECT_EQ(fs::last_write_time(summary), simulated) << "the completed simulation was run again";
    EXPECT_EQ(fs::last_write_time(firstFrame), firstRendered) << "a whole render was rendered again";
    EXPECT_EQ(rendered(), 42);  // the clean plate and frames 0–40
}

TEST_F(CliSynth, CompareGivesZeroForItselfAndNamesMissingFrames) {
    json fine = sceneJson(3);
    fine["domain"]["resolution"] = 14;
    json coarse = sceneJson(3);
    coarse["seed"] = 2;
    for (const auto& [name, scene] : {std::pair{"fine", fine}, {"coarse", coarse}})
        ASSERT_EQ(run("simulate " + write(std::string(name) + ".json", scene.dump()).string() + " --out " +
                      (dir_ / name).string() + " --progress none").exitCode, 0);
    const std::string fineDir = (dir_ / "fine").string(), coarseDir = (dir_ / "coarse").string();

    const CommandResult self = run("compare --reference " + fineDir + " --sim " + fineDir);
    ASSERT_EQ(self.exitCode, 0) << self.err;
    const json same = json::parse(self.out);
    EXPECT_EQ(same.at("frames").size(), 4u);
    EXPECT_EQ(same.at("epsilon_v").get<double>(), 0);
    EXPECT_EQ(same.at("epsilon_p").get<double>(), 0);
    EXPECT_GT(same.at("samples").get<long>(), 0);
    EXPECT_TRUE(same.at("frames")[0].at("epsilon_v").is_null()) << "frame 0 is at rest: no relative error";

    const CommandResult other = run("compare --reference " + fineDir + " --sim " + coarseDir + " --frames 1:3");
    ASSERT_EQ(other.exitCode, 0) << other.err;
    const json d = json::parse(other.out);
    std::printf("[ compare  ] 14^3 vs 12^3 (other seed), frames 1-3: eps_v %.3f, eps_p %.3f over %ld samples\n",
                d.at("epsilon_v").get<double>(), d.at("epsilon_p").get<double>(), d.at("samples").get<long>());
    EXPECT_EQ(d.at("frames").size(), 3u);
    EXPECT_GT(d.at("epsilon_v").get<double>(), 0);
    EXPECT_LT(d.at("epsilon_v").get<double>(), 1);
    EXPECT_GT(d.at("epsilon_p").get<double>(), 0);
    EXPECT_LT(d.at("epsilon_p").get<double>(), 1);

    CommandResult r = run("compare --reference " + fineDir + " --sim " + coarseDir + " --frames 2:9");
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.err.find("frame_00004.vdb missing"), std::string::npos) << r.err;
    r = run("compare --reference " + fineDir + " --sim " + coarseDir + " --frames two");
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.err.find("--frames"), std::string::npos) << r.err;
    r = run("compare --reference " + (dir_ / "nowhere").string() + " --sim " + coarseDir);
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.err.find("nowhere"), std::string::npos) << r.err;
}
