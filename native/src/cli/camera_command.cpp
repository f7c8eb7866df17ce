// `viscoscope camera convert|pnp|calibrate`: camera JSON from Blender, clicked points or checkerboards.
#include "cli/commands.h"
#include "camera/camera.h"
#include "observe/observe.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>

namespace viscoscope::cli {

namespace {

struct CameraArguments {
    std::string input, out, points, intrinsics, pattern = "9x6";
    std::vector<std::string> images;
    double squareSize = 0;
};

// points.json: {"world": [[x, y, z], ...], "image": [[u, v], ...]}, metres and pixels.
void loadPointPairs(const std::string& file, std::vector<Eigen::Vector3d>& world, std::vector<Eigen::Vector2d>& image) {
    std::ifstream stream(file);
    if (!stream) throw InputError(file + ": cannot open points file");
    try {
        const nlohmann::json doc = nlohmann::json::parse(stream);
        for (const auto& p : doc.at("world")) world.emplace_back(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
        for (const auto& p : doc.at("image")) image.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
    } catch (const nlohmann::json::exception& e) {
        throw InputError(file + ": expected {\"world\": [[x,y,z],...], \"image\": [[u,v],...]} (" + std::string(e.what()) + ")");
    }
    for (const auto& p : world)
        if (!p.allFinite()) throw InputError(file + ": world: non-finite coordinate");
    for (const auto& p : image)
        if (!p.allFinite()) throw InputError(file + ": image: non-finite coordinate");
}

cv::Size parsePattern(const std::string& text) {
    int columns = 0, rows = 0;
    char tail = 0;
    if (std::sscanf(text.c_str(), "%dx%d%c", &columns, &rows, &tail) != 2 || columns < 2 || rows < 2)
        throw InputError("--pattern: expected inner corners as COLSxROWS, e.g. 9x6, got \"" + text + "\"");
    return {columns, rows};
}

void reportCamera(const PinholeCamera& camera, const std::string& out) {
    saveCamera(camera, out);
    std::cout << "wrote " << out;
    if (camera.reprojectionErrorPx) std::cout << " (reprojection RMS " << *camera.reprojectionErrorPx << " px)";
    std::cout << "\n";
}

int runPnp(const CameraArguments& args) {
    std::vector<Eigen::Vector3d> world;
    std::vector<Eigen::Vector2d> image;
    loadPointPairs(args.points, world, image);
    const PinholeCamera intrinsics = loadCamera(args.intrinsics);
    try {
        reportCamera(poseFromPoints(intrinsics, world, image), args.out);
    } catch (const InputError& e) {
        throw InputError(args.points + ": " + e.what());  // name the file the user gave
    }
    return kExitOk;
}

int runCalibrate(const CameraArguments& args) {
    std::vector<cv::Mat> images;
    for (const std::string& file : args.images) {
        images.push_back(readImage(file, cv::IMREAD_GRAYSCALE));
        if (images.back().empty()) throw InputError(file + ": cannot read image");
    }
    const CheckerboardCalibration result = calibrateFromCheckerboards(images, parsePattern(args.pattern), args.squareSize);
    for (size_t i = 0; i < args.images.size(); ++i)
        if (!result.boardFound[i]) std::cerr << "viscoscope: no checkerboard found in " << args.images[i] << "\n";
    reportCamera(result.camera, args.out);
    return kExitOk;
}

}  // namespace

Command addCameraCommand(CLI::App& app) {
    auto args = std::make_shared<CameraArguments>();
    CLI::App* sub = app.add_subcommand("camera", "Make a camera.json from Blender, clicked points or checkerboards");
    sub->require_subcommand(1);

    CLI::App* convert = sub->add_subcommand("convert", "Blender camera JSON (or camera JSON) to camera.json");
    convert->add_option("INPUT", args->input, "viscoscope.blender_camera or viscoscope.camera file")->required();
    convert->add_option("--out", args->out, "camera.json to write")->required();

    CLI::App* pnp = sub->add_subcommand("pnp", "Pose from >= 4 known world points and their pixels (solvePnP)");
    pnp->add_option("--points", args->points, "points.json {\"world\":[[x,y,z]...],\"image\":[[u,v]...]}")->required();
    pnp->add_option("--intrinsics", args->intrinsics, "camera.json whose K and distortion are used")->required();
    pnp->add_option("--out", args->out, "camera.json to write")->required();

    CLI::App* calibrate = sub->add_subcommand("calibrate", "Intrinsics from checkerboard photos (calibrateCamera)");
    calibrate->add_option("IMAGES", args->images, "Checkerboard photos, all the same size")->required();
    calibrate->add_option("--pattern", args->pattern, "Inner corners COLSxROWS")->capture_default_str();
    calibrate->add_option("--square", args->squareSize, "Square size, metres")->required();
    calibrate->add_option("--out", args->out, "camera.json to write")->required();

    return {sub, [args, convert, pnp] {
                if (convert->parsed()) {
                    reportCamera(loadCamera(args->input), args->out);
                    return kExitOk;
                }
                return pnp->parsed() ? runPnp(*args) : runCalibrate(*args);
            }};
}

}  // namespace viscoscope::cli
