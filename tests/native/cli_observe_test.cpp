// The extract / score / camera commands as a user runs them: good runs, and bad input that must
// end with exit code 2, one line on stderr, and no complete-looking output.
#include "cli_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace fs = std::filesystem;

namespace {

using viscoscope::cli_test::CommandResult;
using viscoscope::cli_test::runViscoscope;
using viscoscope::cli_test::slurp;

class CliObserve : public ::testing::Test {
protected:
    void SetUp() override {
        // One folder per test and process: CTest runs the cases of this file in parallel.
        const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        dir_ = fs::temp_directory_path() / ("viscoscope_cli_observe_" + test + "_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        if (!viscoscope::cli_test::haveFfmpeg()) GTEST_SKIP() << "ffmpeg not installed";
    }

    CommandResult run(const std::string& arguments) const { return runViscoscope(arguments, dir_); }

    fs::path makeVideo(const std::string& name, int frames) const {
        const fs::path video = dir_ / name;
        EXPECT_TRUE(viscoscope::cli_test::makeTestClip(video, frames));
        return video;
    }

    void writeCamera(const fs::path& file) const {
        const nlohmann::json camera{{"format", "viscoscope.camera"}, {"version", 1}, {"width", 96}, {"height", 72},
                                    {"K", {{100, 0, 47.5}, {0, 100, 35.5}, {0, 0, 1}}},
                                    {"distortion", {0, 0, 0, 0, 0}},
                                    {"R", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}},
                                    {"t", {0, 0, 0}}};
        std::ofstream(file) << camera.dump();
    }

    // A black clip extracted into dir_/ref: every reference mask empty.
    bool extractEmptyReference() const {
        const fs::path black = dir_ / "black.mp4";
        if (std::system(("ffmpeg -v error -y -f lavfi -i color=c=black:size=96x72:rate=10 -frames:v 3 -c:v mpeg4 " +
                         black.string()).c_str()) != 0)
            return false;
        // A clean plate image: with the clip's own frames as background, score would leave out the
        // pixels of the simulation's first liquid (comparedRegion), and the tests below compare it all.
        const fs::path plate = dir_ / "black.png";
        if (std::system(("ffmpeg -v error -y -f lavfi -i color=c=black:size=96x72 -frames:v 1 " + plate.string()).c_str()) != 0)
            return false;
        return run("extract " + black.string() + " --out " + (dir_ / "ref").string() + " --clean-plate " +
                   plate.string()).exitCode == 0;
    }

    // dir_/camera.json: 96x72, looking level along +y from kLevelDistance in front of the origin,
    // kLevelEye above the ground (image rows grow downwards, with −z).
    static constexpr double kLevelFocal = 400, kLevelCy = 35.5, kLevelEye = 0.02, kLevelDistance = 0.3;
    void writeLevelCamera() const {
        const nlohmann::json camera{{"format", "viscoscope.camera"}, {"version", 1}, {"width", 96}, {"height", 72},
                                    {"K", {{kLevelFocal, 0, 47.5}, {0, kLevelFocal, kLevelCy}, {0, 0, 1}}},
                                    {"distortion", {0, 0, 0, 0, 0}},
                                    {"R", {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}},
                                    {"t", {0, kLevelEye, kLevelDistance}}};
        std::ofstream(dir_ / "camera.json") << camera.dump();
    }

    // One triangle per frame, at depth `z` in front of (z > 0) or behind (z < 0) the camera.
    fs::path writeMeshFrames(const std::string& name, int frames, double z) const {
        const fs::path sim = dir_ / name;
        fs::create_directories(sim);
        for (int f = 0; f < frames; ++f) {
            char file[32];
            std::snprintf(file, sizeof file, "frame_%05d.obj", f);
            std::ofstream(sim / file) << "v -0.1 -0.1 " << z << "\nv 0.1 -0.1 " << z << "\nv 0 0.1 " << z << "\nf 1 2 3\n";
        }
        return sim;
    }

    void expectBadInput(const CommandResult& result, const fs::path& outDir) const {
        EXPECT_EQ(result.exitCode, 2) << result.err;
        EXPECT_FALSE(result.err.empty());
        EXPECT_EQ(std::count(result.err.begin(), result.err.end(), '\n'), 1) << result.err;
        EXPECT_EQ(result.err.rfind("viscoscope: ", 0), 0u) << result.err;
        EXPECT_FALSE(fs::exists(outDir / "manifest.json"));
        EXPECT_FALSE(fs::exists(outDir / "score.json"));
    }

    void TearDown() override { fs::remove_all(dir_); }

    fs::path dir_;
};

}  // namespace

TEST_F(CliObserve, ExtractThenScoreWithJsonProgress) {
    const fs::path video = makeVideo("clip.mp4", 12);
    const CommandResult extracted = run("extract " + video.string() + " --out " + (dir_ / "ref").string() +
                              " --background-frames 3 --weights 0-2:0 --progress json --front-ray 0,36,1,0");
    ASSERT_EQ(extracted.exitCode, 0) << extracted.err;
    std::istringstream lines(extracted.out);
    int progressLines = 0;
    for (std::string line; std::getline(lines, line);) {
        const nlohmann::json event = nlohmann::json::parse(line);  // throws if a line is not JSON
        if (event.at("event") == "progress") ++progressLines;
    }
    EXPECT_EQ(progressLines, 12);
    const nlohmann::json manifest = nlohmann::json::parse(slurp(dir_ / "ref" / "manifest.json"));
    EXPECT_EQ(manifest.at("frames").size(), 12u);
    EXPECT_TRUE(fs::exists(dir_ / "ref" / "tracks.csv"));
    EXPECT_EQ(slurp(dir_ / "ref" / "tracks.csv").rfind("time_s,front_px,area_px\n", 0), 0u);

    writeCamera(dir_ / "camera.json");
    const fs::path sim = writeMeshFrames("sim", 12, 1.0);
    const CommandResult scored = run("score --camera " + (dir_ / "camera.json").string() + " --reference " +
                           (dir_ / "ref").string() + " --sim " + sim.string() + " --out " + (dir_ / "score").string());
    ASSERT_EQ(scored.exitCode, 0) << scored.err;
    const nlohmann::json score = nlohmann::json::parse(slurp(dir_ / "score" / "score.json"));
    EXPECT_EQ(score.at("frames").size(), 12u);
    EXPECT_FALSE(score.at("frames")[0].contains("E_f"));  // ω = 0: not scored
    EXPECT_GT(score.at("E").get<double>(), 0);
    EXPECT_TRUE(fs::exists(dir_ / "score" / "diff_00005.png"));
}

// score draws a simulated surface as identify does: the surface's reach below the ground is
// cut off, with the solids of the scene `simulate` recorded beside the frames (or of --scene).
// Against an empty reference, E by pixels is the silhouette's area, so the cut must lower it.
TEST_F(CliObserve, ScoreClipsSurfacesToTheSceneSolids) {
    ASSERT_TRUE(extractEmptyReference());
    // A slab of liquid resting on the ground, seen level from 30 cm at 2 cm above the ground.
    const nlohmann::json scene{
        {"format", "viscoscope.scene"}, {"version", 1},
        {"domain", {{"min", {-0.05, -0.05, 0}}, {"max", {0.05, 0.05, 0.05}}, {"resolution", 16}}},
        {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
        {"liquids", {{{"type", "box"}, {"min", {-0.02, -0.02, 0}}, {"max", {0.02, 0.02, 0.01}}}}},
        {"material", {{"density", 1000}, {"viscosity", 10.0}}}, {"fps", 30}, {"frames", 2},
        {"output", {{"particles", false}, {"vdb", true}, {"mesh", false}}}};
    std::ofstream(dir_ / "scene.json") << scene.dump();
    ASSERT_EQ(run("simulate " + (dir_ / "scene.json").string() + " --out " + (dir_ / "sim").string() +
                  " --progress none").exitCode, 0);
    writeLevelCamera();
    auto score = [&](const std::string& name) {
        const CommandResult scored =
            run("score --comparison pixels --progress none --camera " + (dir_ / "camera.json").string() +
                " --reference " + (dir_ / "ref").string() + " --sim " + (dir_ / "sim").string() + " --out " +
                (dir_ / name).string());
        EXPECT_EQ(scored.exitCode, 0) << scored.err;
        return nlohmann::json::parse(slurp(dir_ / name / "score.json"));
    };
    const nlohmann::json clipped = score("clipped");
    fs::remove(dir_ / "sim" / "simulation.json");  // another program's surfaces: nothing to clip with
    const nlohmann::json unclipped = score("unclipped");
    EXPECT_TRUE(clipped.at("clipped_to_solids").get<bool>());
    EXPECT_FALSE(unclipped.at("clipped_to_solids").get<bool>());
    const double clippedE = clipped.at("E").get<double>(), unclippedE = unclipped.at("E").get<double>();
    std::printf("E against an empty reference: %.5f clipped, %.5f not\n", clippedE, unclippedE);
    EXPECT_GT(clippedE, 0);
    EXPECT_LT(clippedE, 0.99 * unclippedE);  // the same surfaces: without the cut the two are equal
}

// --ground-band leaves out the rows of the band as identify's ground_band does. A cup's outlet 3 cm
// above the ground, seen level from 30 cm at 2 cm above the ground; against an empty reference, E
// by pixels is the area of a wall of "liquid" from the ground to 4 cm, so the band (1 cm) must cut
// it to the share of its rows above the band's top.
TEST_F(CliObserve, ScoreLeavesOutTheGroundBand) {
    ASSERT_TRUE(extractEmptyReference());
    const nlohmann::json scene{
        {"format", "viscoscope.scene"}, {"version", 1},
        {"domain", {{"min", {-0.05, -0.05, 0}}, {"max", {0.05, 0.05, 0.1}}, {"resolution", 16}}},
        {"solids", {{{"type", "ground"}, {"height", 0.0}},
                    {{"type", "cup"}, {"position", {0, 0, 0.03}}, {"inner_radius", 0.01}, {"height", 0.02},
                     {"wall_thickness", 0.003}, {"bottom_thickness", 0.003}, {"hole_radius", 0.003},
                     {"transparent", true}}}},  // glass: it hides none of the wall drawn through it
        {"liquids", {{{"type", "cup_fill"}, {"cup", 1}, {"volume", 1e-6}}}},
        {"material", {{"density", 1000}, {"viscosity", 10.0}}}, {"fps", 30}, {"frames", 2}};
    std::ofstream(dir_ / "scene.json") << scene.dump();
    writeLevelCamera();
    const fs::path sim = dir_ / "sim";
    fs::create_directories(sim);
    for (int frame = 0; frame < 3; ++frame)
        std::ofstream(sim / ("frame_0000" + std::to_string(frame) + ".obj"))
            << "v -0.02 0 0\nv 0.02 0 0\nv 0.02 0 0.04\nv -0.02 0 0.04\nf 1 2 3\nf 1 3 4\n";
    const std::string common = "score --comparison pixels --progress none --camera " + (dir_ / "camera.json").string() +
                               " --reference " + (dir_ / "ref").string() + " --sim " + sim.string() + " --scene " +
                               (dir_ / "scene.json").string();
    auto score = [&](const std::string& name, const std::string& band) {
        const CommandResult scored = run(common + " --out " + (dir_ / name).string() + band);
        EXPECT_EQ(scored.exitCode, 0) << scored.err;
        return nlohmann::json::parse(slurp(dir_ / name / "score.json"));
    };
    const nlohmann::json all = score("all", ""), banded = score("banded", " --ground-band 0.01");
    EXPECT_EQ(all.at("ground_band_m").get<double>(), 0.0);
    EXPECT_EQ(banded.at("ground_band_m").get<double>(), 0.01);
    // Image rows of the wall's top, of the band's top and of the ground (row centres at integers).
    auto row = [&](double z) { return kLevelCy + kLevelFocal * (kLevelEye - z) / kLevelDistance; };
    const double top = row(0.04), bandTop = row(0.01), ground = row(0.0);
    const double kept = std::floor(bandTop) - std::ceil(top) + 1, rows = std::floor(ground) - std::ceil(top) + 1;
    const double ratio = banded.at("E").get<double>() / all.at("E").get<double>();
    std::printf("E with the band / without: %.4f (rows kept %g of %g)\n", ratio, kept, rows);
    EXPECT_NEAR(ratio, kept / rows, 1.5 / rows);  // the wall's edge rows may be drawn or not
    // --identify-ground-band leaves out what a job without "ground_band" would: a quarter of the
    // outlet's 3 cm.
    const nlohmann::json identified = score("identified", " --identify-ground-band");
    EXPECT_NEAR(identified.at("ground_band_m").get<double>(), 0.25 * 0.03, 1e-12);
    EXPECT_GT(identified.at("E").get<double>(), banded.at("E").get<double>());  // a thinner band
    EXPECT_LT(identified.at("E").get<double>(), all.at("E").get<double>());

    const fs::path out = dir_ / "bad";
    for (const char* band : {" --ground-band -0.01", " --ground-band nan", " --ground-band 0.03"}) {
        const CommandResult bad = run(common + " --out " + out.string() + band);
        expectBadInput(bad, out);
        EXPECT_NE(bad.err.find("--ground-band"), std::string::npos) << bad.err;
    }
    const CommandResult sceneless = run("score --progress none --camera " + (dir_ / "camera.json").string() +
                                        " --reference " + (dir_ / "ref").string() + " --sim " + sim.string() +
                                        " --out " + out.string() + " --ground-band 0.01");
    expectBadInput(sceneless, out);
    EXPECT_NE(sceneless.err.find("needs the scene"), std::string::npos) << sceneless.err;
    const CommandResult both = run(common + " --out " + out.string() + " --ground-band 0.01 --identify-ground-band");
    expectBadInput(both, out);
}

// Phones store portrait clips as landscape frames plus a rotation tag; masks must come out upright.
TEST_F(CliObserve, HonoursRotationMetadata) {
    const fs::path landscape = makeVideo("landscape.mp4", 4);
    const fs::path portrait = dir_ / "portrait.mp4";
    const std::string tag = "ffmpeg -v error -y -i " + landscape.string() + " -c copy -metadata:s:v:0 rotate=90 " +
                            portrait.string();
    ASSERT_EQ(std::system(tag.c_str()), 0);
    const CommandResult extracted =
        run("extract " + portrait.string() + " --out " + (dir_ / "ref").string() + " --background-frames 2");
    ASSERT_EQ(extracted.exitCode, 0) << extracted.err;
    const nlohmann::json manifest = nlohmann::json::parse(slurp(dir_ / "ref" / "manifest.json"));
    EXPECT_EQ(manifest.at("width"), 72);
    EXPECT_EQ(manifest.at("height"), 96);
}

// Progress goes to stdout as JSON (as the add-on runs it), so stderr holds only the error line.
TEST_F(CliObserve, BadVideosExitTwoWithOneLine) {
    const fs::path out = dir_ / "out";
    const std::string outArgs = " --progress json --out " + out.string();
    expectBadInput(run("extract " + (dir_ / "missing.mp4").string() + outArgs), out);

    std::mt19937 rng(1);
    std::ofstream corrupt(dir_ / "corrupt.mp4", std::ios::binary);
    for (int i = 0; i < 4096; ++i) corrupt.put(static_cast<char>(rng()));
    corrupt.close();
    expectBadInput(run("extract " + (dir_ / "corrupt.mp4").string() + outArgs), out);

    expectBadInput(run("extract " + makeVideo("empty.mp4", 0).string() + outArgs), out);

    // A named pipe would block the video's open until a writer came (the probe's hang); the time
    // limit keeps a regression from hanging the suite.
    ASSERT_EQ(::mkfifo((dir_ / "pipe.mp4").c_str(), 0600), 0);
    expectBadInput(viscoscope::cli_test::runCommand("timeout -s KILL 60 " + std::string(VISCOSCOPE_CLI) + " extract " +
                                                        (dir_ / "pipe.mp4").string() + outArgs,
                                                    dir_),
                   out);

    const fs::path video = makeVideo("short.mp4", 8);
    expectBadInput(run("extract " + video.string() + outArgs + " --background-frames 2 --first 20"), out);
    expectBadInput(run("extract " + video.string() + outArgs + " --background-frames 2 --last 30"), out);
    expectBadInput(run("extract " + video.string() + outArgs + " --weights 3-1:1"), out);
}

TEST_F(CliObserve, BadScoringInputsExitTwoWithOneLine) {
    const fs::path video = makeVideo("clip.mp4", 6);
    ASSERT_EQ(run("extract " + video.string() + " --out " + (dir_ / "ref").string() + " --background-frames 2").exitCode, 0);
    writeCamera(dir_ / "camera.json");
    const std::string common = "score --progress json --camera " + (dir_ / "camera.json").string() + " --reference ";
    const fs::path out = dir_ / "score";

    const fs::path behind = writeMeshFrames("behind", 6, -1.0);
    const CommandResult behindRun = run(common + (dir_ / "ref").string() + " --sim " + behind.string() + " --out " + out.string());
    expectBadInput(behindRun, out);
    EXPECT_NE(behindRun.err.find("behind the camera"), std::string::npos) << behindRun.err;

    // A mask of the wrong size: a 10x10 PGM where a 96x72 mask belongs.
    fs::copy(dir_ / "ref", dir_ / "ref_bad", fs::copy_options::recursive);
    std::ofstream pgm(dir_ / "ref_bad" / "masks" / "mask_00003.png", std::ios::binary);
    pgm << "P5\n10 10\n255\n" << std::string(100, '\0');
    pgm.close();
    const fs::path sim = writeMeshFrames("sim", 6, 1.0);
    const CommandResult wrongSize = run(common + (dir_ / "ref_bad").string() + " --sim " + sim.string() + " --out " + out.string());
    expectBadInput(wrongSize, out);
    EXPECT_NE(wrongSize.err.find("mask_00003.png"), std::string::npos) << wrongSize.err;

    expectBadInput(run(common + (dir_ / "ref").string() + " --sim " + (dir_ / "nowhere").string() + " --out " + out.string()), out);

    std::ofstream(dir_ / "points.json") << R"({"world": [[0,0,0],[1,0,0],[0,1,0]], "image": [[1,2],[3,4],[5,6]]})";
    expectBadInput(run("camera pnp --points " + (dir_ / "points.json").string() + " --intrinsics " +
                       (dir_ / "camera.json").string() + " --out " + (dir_ / "posed.json").string()),
                   out);
    std::ofstream(dir_ / "blender.json") << R"({"format": "viscoscope.blender_camera", "version": 1, "lens_mm": 50})";
    expectBadInput(run("camera convert " + (dir_ / "blender.json").string() + " --out " + (dir_ / "c.json").string()), out);
}
