// What the `viscoscope` command-line tests share: running the built engine (VISCOSCOPE_CLI) as a
// subprocess and reading what it wrote. The cli_* tests link only the scene stage, so this is all
// they know of the engine.
#pragma once

#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace viscoscope::cli_test {

inline std::string slurp(const std::filesystem::path& file) {
    std::ifstream stream(file);
    std::stringstream text;
    text << stream.rdbuf();
    return text.str();
}

struct CommandResult {
    int exitCode;  // −1 when the engine did not exit normally (a crash)
    std::string out, err;
};

// A shell command line, its stdout and stderr kept in `dir`.
inline CommandResult runCommand(const std::string& command, const std::filesystem::path& dir) {
    const std::string redirected = command + " > " + (dir / "stdout").string() + " 2> " + (dir / "stderr").string();
    const int status = std::system(redirected.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(dir / "stdout"), slurp(dir / "stderr")};
}

// `viscoscope ARGUMENTS`, its stdout and stderr kept in `dir`.
inline CommandResult runViscoscope(const std::string& arguments, const std::filesystem::path& dir) {
    return runCommand(std::string(VISCOSCOPE_CLI) + " " + arguments, dir);
}

inline bool haveFfmpeg() { return std::system("ffmpeg -version > /dev/null 2>&1") == 0; }

// A short 96×72 test-pattern clip at 10 fps, MPEG-4 as a phone writes it, made by the ffmpeg tool
// (the cli tests link no OpenCV); false when ffmpeg failed.
inline bool makeTestClip(const std::filesystem::path& clip, int frames) {
    const std::string command = "ffmpeg -v error -y -f lavfi -i testsrc=size=96x72:rate=10 -frames:v " +
                                std::to_string(frames) + " -c:v mpeg4 " + clip.string();
    return std::system(command.c_str()) == 0;
}

// The smallest identification there is, for the tests of `identify`'s input and output: a liquid
// block slumping on the ground at 16³ (coarse 11³), two hand-drawn reference masks (these tests
// link no OpenCV), λ = 4.
namespace slump {

using nlohmann::json;

inline json slumpScene() {
    return {{"format", "viscoscope.scene"},
            {"version", 1},
            {"domain", {{"min", {0, 0, 0}}, {"max", {0.1, 0.04, 0.06}}, {"resolution", 16}}},
            {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
            {"liquids", {{{"type", "box"}, {"min", {0.0, 0.0, 0.0}}, {"max", {0.035, 0.04, 0.045}}}}},
            {"material", {{"density", 1400}, {"viscosity", 5.0}}},
            {"fps", 30},
            {"frames", 4},
            {"seed", 1}};
}

// A 96×64 camera looking along +y at the block from `t`.
inline void writeSlumpCamera(const std::filesystem::path& file, const std::vector<double>& t) {
    const json camera{{"format", "viscoscope.camera"}, {"version", 1}, {"width", 96}, {"height", 64},
                      {"K", {{200, 0, 47.5}, {0, 200, 25.5}, {0, 0, 1}}},
                      {"distortion", {0, 0, 0, 0, 0}},
                      {"R", {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}},
                      {"t", t}};
    std::ofstream(file) << camera.dump();
}

// Masks of the block slumping to the right, as binary PGM (P5) files, frames 2, 4, … (one per weight).
inline void writeSlumpMasks(const std::filesystem::path& dir, int width, int height, const std::vector<double>& weights) {
    std::filesystem::create_directories(dir / "masks");
    json manifest{{"format", "viscoscope.reference"}, {"version", 1}, {"source", "hand-drawn"}, {"fps", 30.0},
                  {"width", width}, {"height", height}};
    std::vector<int> frames;
    std::vector<double> times;
    std::vector<std::string> masks;
    for (size_t i = 0; i < weights.size(); ++i) {
        const int frame = 2 * static_cast<int>(i + 1);
        const std::string name = "masks/mask_" + std::to_string(frame) + ".pgm";
        std::ofstream pgm(dir / name, std::ios::binary);
        pgm << "P5\n" << width << " " << height << "\n255\n";
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const bool inside = x > width * 0.2 && x < width * (0.5 + 0.05 * frame) && y > height * 0.4 &&
                                    y < height * 0.75;
                pgm.put(static_cast<char>(inside ? 255 : 0));
            }
        frames.push_back(frame);
        times.push_back(frame / 30.0);
        masks.push_back(name);
    }
    manifest["frames"] = frames;
    manifest["times_s"] = times;
    manifest["weights"] = weights;
    manifest["masks"] = masks;
    std::ofstream(dir / "manifest.json") << manifest.dump(1);
}

// DIR/scene.json, DIR/camera.json and DIR/reference (frames 2 and 4), which slumpJob names.
inline void writeSlumpCase(const std::filesystem::path& dir) {
    std::ofstream(dir / "scene.json") << slumpScene().dump(1);
    writeSlumpCamera(dir / "camera.json", {-0.05, 0.03, 0.25});
    writeSlumpMasks(dir / "reference", 96, 64, {1.0, 1.0});
}

inline json slumpJob(int generations) {
    return {{"format", "viscoscope.job"},
            {"version", 1},
            {"scene", "scene.json"},
            {"camera", "camera.json"},
            {"video", nullptr},
            {"silhouettes", "reference"},
            {"frame_start", 1},
            {"frame_end", 250},
            {"parameters", {{{"name", "viscosity"}, {"initial", 5.0}, {"spread", 5.0}, {"min", 1e-3}, {"max", 1e4},
                             {"log", true}}}},
            {"resolution", 16},
            {"max_generations", generations},
            {"fidelity", {{"coarse_generations", 1}}},
            {"seed", 4}};
}

}  // namespace slump

}  // namespace viscoscope::cli_test
