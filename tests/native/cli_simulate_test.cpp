// `viscoscope simulate` as a user runs it: a small scene end to end, bad scenes (exit 2 with one
// line naming the field), and cancellation by SIGTERM (exit 3, no completion marker).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Result {
    int exitCode;
    std::string stderrText;
};

Result runViscoscope(const std::string& arguments, const fs::path& dir) {
    const fs::path err = dir / "stderr.txt";
    const std::string command = std::string(VISCOSCOPE_CLI) + " " + arguments + " --progress none 2> " + err.string();
    const int status = std::system(command.c_str());
    std::ifstream in(err);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return {WEXITSTATUS(status), text};
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
    const Result r = runViscoscope("simulate " + write(smallScene()).string() + " --out " + (dir_ / "out").string(), dir_);
    ASSERT_EQ(r.exitCode, 0) << r.stderrText;
    // At 16³ the cup's hole spans 1.6 cells: the run goes on and says why its drain rate is wrong.
    EXPECT_NE(r.stderrText.find("warning: solids[1] (cup): its hole is 1.6 cells across at resolution 16"),
              std::string::npos) << r.stderrText;
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
    };
    for (const Case& c : cases) {
        json scene = smallScene();
        scene[json::json_pointer(c.pointer)] = c.value;
        const Result r = runViscoscope("simulate " + write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
        EXPECT_EQ(r.exitCode, 2) << c.pointer;
        EXPECT_NE(r.stderrText.find(c.mentions), std::string::npos) << r.stderrText;
        EXPECT_EQ(std::count(r.stderrText.begin(), r.stderrText.end(), '\n'), 1) << r.stderrText;
        EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
    }
    // An empty domain: the liquid box lies entirely inside a solid.
    json scene = smallScene();
    scene["liquids"] = json::array({{{"type", "box"}, {"min", {-0.05, -0.05, -0.01}}, {"max", {0.05, 0.05, 0.0}}}});
    scene["solids"] = json::array({{{"type", "ground"}, {"height", 0.01}}});
    Result r = runViscoscope("simulate " + write(scene).string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2) << r.stderrText;
    EXPECT_NE(r.stderrText.find("liquids"), std::string::npos) << r.stderrText;

    std::ofstream(dir_ / "broken.json") << "{ not json";
    r = runViscoscope("simulate " + (dir_ / "broken.json").string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2);
    r = runViscoscope("simulate " + (dir_ / "absent.json").string() + " --out " + (dir_ / "out").string(), dir_);
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.stderrText.find("absent.json"), std::string::npos);
}

TEST_F(SimulateCommand, SigtermStopsCleanlyWithExitThree) {
    json scene = smallScene();
    scene["frames"] = 100000;
    const std::string scenePath = write(scene).string(), out = (dir_ / "out").string();
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        ::execl(VISCOSCOPE_CLI, VISCOSCOPE_CLI, "simulate", scenePath.c_str(), "--out", out.c_str(),
                "--progress", "none", static_cast<char*>(nullptr));
        ::_exit(127);
    }
    // Wait until some frames exist, then cancel.
    for (int i = 0; i < 600 && !fs::exists(dir_ / "out/particles_00002.bin"); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ::kill(pid, SIGTERM);
    int status = 0;
    ::waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 3);
    EXPECT_TRUE(fs::exists(dir_ / "out/particles_00002.bin"));
    EXPECT_FALSE(fs::exists(dir_ / "out/simulation.json"));
}
