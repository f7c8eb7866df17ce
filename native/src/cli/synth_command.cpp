// `viscoscope synth SCENE --camera CAM --out DIR`: a synthetic reference without the inverse crime
// (DESIGN.md, Testing). The scene is simulated at another resolution and seed than identification
// uses; Blender (Cycles) renders its surfaces with the container and the ground in front of a plain
// backdrop; the renders are area-downsampled and encoded lossily like a phone clip. Identification
// then has to extract that clip like real footage.
//
//   DIR/simulation/   `simulate`'s files: frame_*.vdb (surface, velocity, pressure: the hidden fields
//                     that `compare` checks) and frame_*.obj (the surfaces Blender renders)
//   DIR/render/       solids.obj, render.json (what Blender is asked), blender.log, and the
//                     supersampled frame_*.png and clean_plate.png
//   DIR/reference.mp4 the clip, at the scene's fps, frame k = simulation frame k
//   DIR/clean_plate.png, DIR/exclude.png (the container's projection: 255 = not compared),
//   DIR/camera.json   (viscoscope.camera), and DIR/synth.json last (truth, settings, timings).
#include "cli/commands.h"
#include "cli/output_lock.h"
#include "cli/progress.h"
#include "cli/scripts.h"
#include "cli/simulation_folder.h"
#include "observe/observe.h"
#include "surface/surface.h"

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <thread>

namespace viscoscope::cli {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct SynthArguments {
    std::string scene, camera, outDir, blender, progress = "text";
    int resolution = 0;   // 0: 4/3 of the scene's
    long long seed = -1;  // −1: the scene's + 1
    double viscosity = 0;  // 0: the scene's
    int frames = 0;       // 0: the scene's
    int samples = 8, supersample = 2;
    bool trueMasks = false;
};

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// The executable `name` (a path, or looked up on $PATH); InputError when there is none.
fs::path findExecutable(const std::string& name, const std::string& option) {
    const auto runnable = [](const fs::path& p) { return fs::is_regular_file(p) && access(p.c_str(), X_OK) == 0; };
    if (name.find('/') != std::string::npos) {
        if (runnable(name)) return name;
    } else if (const char* path = std::getenv("PATH")) {
        std::string dirs = path;
        for (size_t begin = 0, end; begin <= dirs.size(); begin = end + 1) {
            end = std::min(dirs.find(':', begin), dirs.size());
            const fs::path candidate = fs::path(dirs.substr(begin, end - begin)) / name;
            if (end > begin && runnable(candidate)) return candidate;
        }
    }
    throw InputError(option + ": Blender executable \"" + name + "\" not found (install Blender 3.x, or pass --blender PATH)");
}

// The same view at `factor` × the image size: pixel centres map as x' = factor·x + (factor − 1)/2, so
// averaging factor × factor blocks of the big image gives the camera's pixels back.
PinholeCamera supersampled(PinholeCamera camera, int factor) {
    camera.K.topRows<2>() *= factor;
    camera.K(0, 2) += 0.5 * (factor - 1);
    camera.K(1, 2) += 0.5 * (factor - 1);
    camera.width *= factor;
    camera.height *= factor;
    return camera;
}

// Every opaque solid but the ground, as one mesh: what the camera sees of the container. A
// transparent solid is not drawn at all: the render does not model a glass's refraction.
TriangleMesh containerMesh(const Scene& scene) {
    TriangleMesh all;
    for (size_t i = 0; i < scene.solids.size(); ++i) {
        if (!scene.isOpaque(i)) continue;
        const TriangleMesh part = surface::solidBoundary(scene.solids[i]);
        const int offset = static_cast<int>(all.vertices.size());
        all.vertices.insert(all.vertices.end(), part.vertices.begin(), part.vertices.end());
        for (const Eigen::Vector3i& t : part.triangles) all.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
    }
    return all;
}

// A wrong camera (looking away, behind the scene) fails here, before any simulation: the liquid
// never leaves the domain box.
void requireDomainInView(const Scene& scene, const PinholeCamera& camera, const std::string& cameraFile) {
    const TriangleMesh box = surface::solidBoundary(BoxSolid{scene.domain.min, scene.domain.max});
    if (cv::countNonZero(rasterizeMesh(box.vertices, box.triangles, camera)) == 0)
        throw InputError(cameraFile + ": the camera sees none of the simulation domain (it looks away from the scene)");
}

// Liquid pixels the camera sees in frame f (what the opaque solids do not hide), from the surface
// mesh. An empty OBJ is a frame without liquid.
double visibleLiquidPixels(const fs::path& obj, const PinholeCamera& camera, const SceneVisibility& view) {
    if (fs::file_size(obj) == 0) return 0;
    const TriangleMesh mesh = loadMesh(obj);
    return cv::countNonZero(rasterizeMesh(mesh.vertices, mesh.triangles, camera, &view));
}

// Runs Blender on the render script with `spec`, its output into `log`. Calls `poll` while waiting.
// Returns false when cancelled (Blender is stopped first); throws when Blender fails.
bool runBlender(const fs::path& blender, const fs::path& script, const fs::path& spec, const fs::path& log,
                const std::function<void()>& poll) {
    const std::vector<std::string> args{blender.string(), "-b", "--factory-startup", "--python-exit-code", "1",
                                        "--python", script.string(), "--", spec.string()};
    // Built before fork(): the child of a threaded process may only make async-signal-safe calls.
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    const std::string logFile = log.string();
    const pid_t pid = fork();
    if (pid < 0) throw std::runtime_error("cannot start Blender: fork failed");
    if (pid == 0) {
        const int fd = open(logFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) {
            dup2(fd, STDOUT_FILENO);
            dup2(fd, STDERR_FILENO);
        }
        execv(argv[0], argv.data());
        _exit(127);
    }
    int status = 0;
    while (waitpid(pid, &status, WNOHANG) == 0) {
        if (cancelRequested()) {
            kill(pid, SIGTERM);
            waitpid(pid, &status, 0);
            return false;
        }
        poll();
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return true;
    // The last error line Blender printed says what went wrong.
    std::ifstream in(log);
    std::string reason, line;
    while (std::getline(in, line))
        if (line.find("Error") != std::string::npos) reason = line;
    const std::string how = WIFEXITED(status) ? "exit " + std::to_string(WEXITSTATUS(status)) : "killed by a signal";
    throw std::runtime_error("Blender failed (" + how + (reason.empty() ? "" : ": " + reason) + "); see " + log.string());
}

// A render at the supersampled size, averaged down to the camera's pixels in linear light, as a
// sensor's pixel collects it (averaging sRGB values darkens mixed pixels, so a dark liquid on a
// bright backdrop came out with a fatter outline; FINDINGS, "Figures moved from code comments").
cv::Mat cameraPicture(const fs::path& file, const PinholeCamera& big, cv::Size size) {
    const cv::Mat image = readImage(file, cv::IMREAD_COLOR);
    if (image.cols != big.width || image.rows != big.height)
        throw std::runtime_error(file.string() + ": Blender's render is missing or not " + std::to_string(big.width) +
                                 "x" + std::to_string(big.height));
    cv::Mat small;
    cv::resize(srgbToLinear(image), small, size, 0, 0, cv::INTER_AREA);
    return linearToSrgb(small);
}

// Blender's renders of the liquid alone, lit by nothing but itself (white) before black solids,
// reduced to the camera's pixels as the clip is and kept where the liquid covers half a pixel or more:
// what the camera sees of the liquid, as an `extract`-style reference in `dir` (masks/, manifest.json).
void writeTrueMasks(const std::vector<fs::path>& renders, const PinholeCamera& big, cv::Size size, double fps,
                    const fs::path& dir) {
    fs::create_directories(dir / "masks");
    ReferenceManifest manifest;
    manifest.directory = dir;
    manifest.source = "blender";
    manifest.fps = fps;
    manifest.width = size.width;
    manifest.height = size.height;
    manifest.parameters = {{"background", "rendered_liquid_alone"}};
    for (size_t f = 0; f < renders.size(); ++f) {
        cv::Mat grey;
        cv::cvtColor(cameraPicture(renders[f], big, size), grey, cv::COLOR_BGR2GRAY);
        const cv::Mat1b mask = srgbToLinear(grey) >= 0.5;
        const std::string name = frameName("masks/mask", static_cast<int>(f), "png");
        writeImage(mask, dir / name);
        manifest.frames.push_back(static_cast<int>(f));
        manifest.times.push_back(f / fps);
        manifest.weights.push_back(1);
        manifest.maskFiles.push_back(name);
    }
    saveReferenceManifest(manifest, dir);
}

int runSynth(const SynthArguments& args) {
    openvdb::initialize();
    const auto start = Clock::now();
    // Everything that can be wrong with the input is checked before the simulation.
    Scene scene = loadScene(args.scene);
    scene.domain.resolution = args.resolution > 0 ? args.resolution
                                                  : static_cast<int>(std::ceil(scene.domain.resolution * 4.0 / 3.0));
    scene.seed = args.seed >= 0 ? static_cast<unsigned>(args.seed) : scene.seed + 1;
    if (args.viscosity > 0) scene.material.viscosity = args.viscosity;
    if (args.frames > 0) scene.frames = args.frames;
    scene.outputs.vdb = true;
    scene.outputs.mesh = true;
    const PinholeCamera camera = loadCamera(args.camera);
    // MPEG-4 stores 4:2:0 chroma; FFmpeg would silently crop an odd size to an even one.
    if (camera.width % 2 || camera.height % 2)
        throw InputError(args.camera + ": width/height: the mp4 clip needs an even image size, got " +
                         std::to_string(camera.width) + "x" + std::to_string(camera.height));
    const PinholeCamera big = supersampled(camera, args.supersample);
    const BlenderCameraParams renderCamera = blenderFromCamera(big, args.camera);
    const fs::path blender = findExecutable(args.blender, "--blender");
    const std::optional<fs::path> script = findScript("render_reference.py");
    if (!script) throw InputError("scripts/render_reference.py: not found next to the engine; set VISCOSCOPE_SCRIPTS");
    requireDomainInView(scene, camera, args.camera);

    const fs::path dir = args.outDir, renders = dir / "render", simulation = dir / "simulation";
    const OutputFolderLock lock(dir, "synth");
    std::error_code ec;
    fs::create_directories(renders, ec);
    if (ec) throw InputError(args.outDir + ": cannot create output folder (" + ec.message() + ")");
    fs::remove(dir / "synth.json", ec);
    const ProgressReporter progress(args.progress);

    // 1. The simulation: the hidden fields and the surfaces to render.
    if (simulateIntoFolder(scene, simulation, progress) == kExitCancelled) return kExitCancelled;
    const double simulateSeconds = secondsSince(start);

    // 2. The container: its mesh is rendered, and its projection is an exclusion mask for jobs that
    // want one (identify needs none: it depth-tests against the solids).
    const TriangleMesh container = containerMesh(scene);
    const cv::Mat1b excluded = rasterizeMesh(container.vertices, container.triangles, camera);
    const SceneVisibility view = sceneVisibility(scene, camera);
    nlohmann::json visible = nlohmann::json::array();
    double anyVisible = 0;
    for (int f = 0; f <= scene.frames; ++f) {
        visible.push_back(visibleLiquidPixels(simulation / frameName("frame", f, "obj"), camera, view));
        anyVisible += visible.back().get<double>();
    }
    if (anyVisible == 0)
        throw InputError(args.camera + ": the camera sees no liquid in any of the " + std::to_string(scene.frames + 1) +
                         " frames (out of the picture, or hidden by the container)");
    writeImage(excluded, dir / "exclude.png");
    if (!container.triangles.empty()) surface::writeObj(renders / "solids.obj", container);

    // 3. Blender renders the clean plate and every frame at the supersampled size. Renders that a
    // cancelled synth of the same simulation (its simulation.json's digest) and settings left are
    // kept, if whole, and Blender renders the rest; any others must not pass for this run's.
    const auto renderStart = Clock::now();
    nlohmann::json frames = nlohmann::json::array();
    std::vector<fs::path> images;
    std::vector<fs::path> maskImages;
    for (int f = 0; f <= scene.frames; ++f) {
        images.push_back(fs::absolute(renders / frameName("frame", f, "png")));
        frames.push_back({{"mesh", fs::absolute(simulation / frameName("frame", f, "obj")).string()},
                          {"image", images.back().string()}});
        if (args.trueMasks) {
            maskImages.push_back(fs::absolute(renders / frameName("mask", f, "png")));
            frames.back()["mask_image"] = maskImages.back().string();
        }
    }
    const std::optional<double> ground = groundHeight(scene);
    const nlohmann::json spec{
        {"camera", blenderCameraToJson(renderCamera)},
        {"samples", args.samples},
        {"seed", scene.seed},  // Cycles' noise pattern: fixed, so a synth is reproducible
        {"simulation_digest", fileDigest(simulation / "simulation.json")},
        {"solids", container.triangles.empty() ? nlohmann::json() : nlohmann::json(fs::absolute(renders / "solids.obj").string())},
        {"ground_height", ground ? nlohmann::json(*ground) : nlohmann::json()},
        {"clean_plate", fs::absolute(renders / "clean_plate.png").string()},
        {"frames", frames}};
    std::ifstream previousSpec(renders / "render.json");
    const bool sameRender = previousSpec && nlohmann::json::parse(previousSpec, nullptr, false) == spec;
    int kept = 0;
    auto keepIfWhole = [&](const fs::path& image) {
        if (sameRender && fs::exists(image)) {
            // A render cut off while Blender wrote it does not decode whole.
            const cv::Mat picture = readImage(image, cv::IMREAD_COLOR);
            if (picture.cols == big.width && picture.rows == big.height) return void(++kept);
        }
        fs::remove(image, ec);
    };
    keepIfWhole(renders / "clean_plate.png");
    for (const fs::path& image : images) keepIfWhole(image);
    for (const fs::path& image : maskImages) keepIfWhole(image);
    if (kept > 0) progress.report({{"event", "resumed"}, {"stage", "render"}, {"kept_images", kept}});
    writeJsonAtomically(spec, renders / "render.json");
    size_t rendered = 0;
    const auto reportRendered = [&] {
        while (rendered < images.size() && fs::exists(images[rendered])) {
            ++rendered;
            progress.report({{"event", "progress"}, {"stage", "render"}, {"done", rendered}, {"total", images.size()},
                             {"elapsed", secondsSince(start)}});
        }
    };
    if (!runBlender(blender, *script, renders / "render.json", renders / "blender.log", reportRendered)) {
        progress.report({{"event", "cancelled"}, {"stage", "render"}, {"done", rendered}});
        return kExitCancelled;
    }
    reportRendered();
    const double renderSeconds = secondsSince(renderStart);

    // 4. Down to the camera's size (area averaging in linear light) and into a lossy clip.
    const auto encodeStart = Clock::now();
    const cv::Size size(camera.width, camera.height);
    writeImage(cameraPicture(renders / "clean_plate.png", big, size), dir / "clean_plate.png");
    const fs::path partial = dir / "reference.partial.mp4";  // the extension picks the container
    cv::VideoWriter video(partial.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), scene.fps, size);
    if (!video.isOpened()) throw std::runtime_error(partial.string() + ": OpenCV cannot write an mp4v video");
    for (size_t f = 0; f < images.size(); ++f) {
        if (cancelRequested()) {
            progress.report({{"event", "cancelled"}, {"stage", "encode"}, {"done", f}});
            return kExitCancelled;
        }
        video.write(cameraPicture(images[f], big, size));
        progress.report({{"event", "progress"}, {"stage", "encode"}, {"done", f + 1}, {"total", images.size()}});
    }
    video.release();
    // VideoWriter reports no failed write (a full disk): the clip counts only if it reads back whole.
    if (cv::VideoCapture written(partial.string());
        !written.isOpened() || written.get(cv::CAP_PROP_FRAME_COUNT) != double(images.size()))
        throw OutputError(partial.string() + ": cannot write (the clip does not read back whole)");
    fs::rename(partial, dir / "reference.mp4");
    if (args.trueMasks) writeTrueMasks(maskImages, big, size, scene.fps, dir / "true_masks");
    saveCamera(camera, dir / "camera.json");
    const double encodeSeconds = secondsSince(encodeStart);

    const nlohmann::json summary{
        {"format", "viscoscope.synth"},
        {"version", 1},
        {"scene", fs::absolute(args.scene).string()},
        {"truth", sceneToJson(scene).at("material")},
        {"resolution", scene.domain.resolution},
        {"seed", scene.seed},
        {"frames", scene.frames},
        {"fps", scene.fps},
        {"render", {{"samples", args.samples}, {"supersample", args.supersample}, {"width", big.width},
                    {"height", big.height}, {"blender", blender.string()}}},
        {"camera", {{"file", "camera.json"}, {"width", camera.width}, {"height", camera.height}}},
        {"files", {{"video", "reference.mp4"}, {"clean_plate", "clean_plate.png"}, {"exclude", "exclude.png"},
                   {"simulation", "simulation"}, {"true_masks", args.trueMasks ? nlohmann::json("true_masks") : nlohmann::json()}}},
        {"visible_liquid_px", visible},
        {"timings", {{"simulate_s", simulateSeconds}, {"render_s", renderSeconds}, {"encode_s", encodeSeconds},
                     {"total_s", secondsSince(start)}}},
        {"simulated_scene", sceneToJson(scene)}};
    writeJsonAtomically(summary, dir / "synth.json");
    progress.report({{"event", "done"}, {"stage", "synth"}, {"video", (dir / "reference.mp4").string()},
                     {"simulate_s", simulateSeconds}, {"render_s", renderSeconds}, {"encode_s", encodeSeconds},
                     {"elapsed", secondsSince(start)}});
    return kExitOk;
}

}  // namespace

Command addSynthCommand(CLI::App& app) {
    auto args = std::make_shared<SynthArguments>();
    CLI::App* sub = app.add_subcommand(
        "synth",
        "Make a synthetic reference: simulate, render with Blender (Cycles), encode reference.mp4.\n"
        "To avoid the inverse crime, simulate finer than identification will and with another seed:\n"
        "by default the resolution is 4/3 of the scene's and the seed the scene's + 1.");
    sub->add_option("scene", args->scene, "Scene JSON file (the truth: its material is what identify must find)")
        ->required();
    sub->add_option("--camera", args->camera, "viscoscope.camera (K, R, t; no distortion) or viscoscope.blender_camera")
        ->required();
    sub->add_option("--out", args->outDir, "Output folder")->required();
    sub->add_option("--resolution", args->resolution, "Cells along the domain's longest axis (finer than identification's)")
        ->check(CLI::Range(4, 1024));
    sub->add_option("--seed", args->seed, "Particle seed (different from the identification job's)")
        ->check(CLI::Range(0LL, 4294967295LL));
    sub->add_option("--viscosity", args->viscosity, "η in Pa·s (default: the scene's)")->check(CLI::PositiveNumber);
    sub->add_option("--frames", args->frames, "Frames after the initial one (default: the scene's)")
        ->check(CLI::Range(1, 100000));
    sub->add_option("--samples", args->samples, "Cycles samples per pixel (no denoising)")
        ->check(CLI::Range(1, 4096))
        ->capture_default_str();
    sub->add_option("--supersample", args->supersample, "Render at N × the camera's size, then average N × N blocks")
        ->check(CLI::Range(1, 8))
        ->capture_default_str();
    sub->add_flag("--true-masks", args->trueMasks,
                  "Also render the liquid alone into DIR/true_masks/ (an extract-style reference of what the camera "
                  "sees of it, without extraction's errors)");
    sub->add_option("--blender", args->blender, "Blender executable (default: $VISCOSCOPE_BLENDER, else blender on PATH)");
    sub->add_option("--progress", args->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}))
        ->capture_default_str();
    return {sub, [args] {
                if (args->blender.empty()) {
                    const char* fromEnvironment = std::getenv("VISCOSCOPE_BLENDER");
                    args->blender = fromEnvironment ? fromEnvironment : "blender";
                }
                return runSynth(*args);
            }};
}

}  // namespace viscoscope::cli
