// `viscoscope extract VIDEO --out DIR`: reference silhouettes, manifest and preview from footage.
#include "cli/commands.h"
#include "cli/output_lock.h"
#include "cli/progress.h"
#include "observe/observe.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>
#include <memory>

namespace viscoscope::cli {

namespace {

struct ExtractArguments {
    std::string source, outDir, cleanPlate, excludeMask, excludePolygons, frontRay, progress = "text";
    double fps = 0;
    bool noGainCompensation = false;
    ExtractionOptions options;
};

// polygons.json: [[[x, y], [x, y], ...], ...] in pixel coordinates.
std::vector<std::vector<cv::Point2d>> loadPolygons(const std::string& file) {
    std::ifstream stream(file);
    if (!stream) throw InputError(file + ": cannot open polygon file");
    try {
        std::vector<std::vector<cv::Point2d>> polygons;
        for (const auto& polygon : nlohmann::json::parse(stream)) {
            polygons.emplace_back();
            for (const auto& point : polygon) polygons.back().emplace_back(point.at(0).get<double>(), point.at(1).get<double>());
        }
        return polygons;
    } catch (const nlohmann::json::exception& e) {
        throw InputError(file + ": expected [[[x, y], ...], ...] (" + std::string(e.what()) + ")");
    }
}

// "x0,y0,dx,dy" in pixels.
ImageRay parseRay(const std::string& text) {
    double v[4];
    char tail = 0;
    if (std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf%c", &v[0], &v[1], &v[2], &v[3], &tail) != 4)
        throw InputError("--front-ray: expected X0,Y0,DX,DY in pixels, got \"" + text + "\"");
    return {{v[0], v[1]}, {v[2], v[3]}};
}

int runExtract(ExtractArguments& args) {
    ExtractionOptions& options = args.options;
    if (args.fps > 0) options.fps = args.fps;
    options.compensateGain = !args.noGainCompensation;
    if (!args.cleanPlate.empty()) options.cleanPlate = args.cleanPlate;
    if (!args.excludeMask.empty()) options.excludeMask = args.excludeMask;
    if (!args.excludePolygons.empty()) options.excludePolygons = loadPolygons(args.excludePolygons);
    const std::optional<ImageRay> ray = args.frontRay.empty() ? std::nullopt : std::optional(parseRay(args.frontRay));
    const OutputFolderLock lock(args.outDir, "extract");
    const ProgressReporter progress(args.progress);
    const auto report = [&progress](int done, int total) {
        progress.report({{"event", "progress"}, {"stage", "extract"}, {"done", done}, {"total", total}});
    };
    try {
        const ReferenceManifest manifest =
            extractSilhouettes(args.source, options, args.outDir, report);
        const std::filesystem::path tracks = std::filesystem::path(args.outDir) / "tracks.csv";
        saveScalarTrackCsv(tracksFromMasks(manifest, ray), tracks);
        progress.report({{"event", "done"}, {"frames", manifest.frames.size()},
                         {"manifest", (std::filesystem::path(args.outDir) / "manifest.json").string()}});
    } catch (const Cancelled&) {
        progress.report({{"event", "cancelled"}, {"stage", "extract"}});
        return kExitCancelled;
    }
    return kExitOk;
}

}  // namespace

Command addExtractCommand(CLI::App& app) {
    auto args = std::make_shared<ExtractArguments>();
    ExtractionOptions& o = args->options;
    CLI::App* sub = app.add_subcommand("extract", "Extract reference silhouettes from a video or an image folder");
    sub->add_option("VIDEO", args->source, "Video file (any FFmpeg format) or folder of numbered images")->required();
    sub->add_option("--out", args->outDir, "Output folder (masks/, manifest.json, preview.png, tracks.csv)")->required();
    sub->add_option("--first", o.first, "First frame index")->capture_default_str();
    sub->add_option("--last", o.last, "Last frame index, inclusive (-1: to the end)")->capture_default_str();
    sub->add_option("--step", o.step, "Frame step")->capture_default_str();
    sub->add_option("--fps", args->fps, "Frame rate (required for image folders; overrides the video's)");
    sub->add_option("--background-frames", o.backgroundFrames, "Leading liquid-free frames that train MOG2")
        ->capture_default_str();
    sub->add_option("--clean-plate", args->cleanPlate, "Image of the scene without liquid (instead of leading frames)");
    sub->add_option("--clean-plate-frame", o.cleanPlateFrame,
                    "Index of a frame of the source that shows no liquid outside the container: the clean plate");
    sub->add_option("--exclude", args->excludeMask, "PNG, nonzero = pixels left out of the comparison");
    sub->add_option("--exclude-polygons", args->excludePolygons, "JSON [[[x,y],...],...] of excluded polygons");
    sub->add_option("--weights", o.weights, "Frame weights: \"0-10:1,11-20:0\" or one value per frame \"1,1,0\"");
    sub->add_option("--close", o.closeKernel, "Closing kernel diameter, px")->capture_default_str();
    sub->add_option("--open", o.openKernel, "Opening kernel diameter, px (0 = none)")->capture_default_str();
    sub->add_option("--min-blob", o.minBlobPixels, "Drop blobs smaller than this many pixels")->capture_default_str();
    sub->add_option("--threshold", o.threshold, "Mask = MOG2 output > T (shadows are 127)")->capture_default_str();
    sub->add_option("--shadow-threshold", o.shadowThreshold,
                    "Darker than the background by a brightness ratio in [T, 1], colour unchanged: shadow")
        ->capture_default_str();
    sub->add_option("--edge-coverage", o.edgeCoverage, "Drop outline pixels the liquid covers less than this share of (0 = off)")
        ->capture_default_str();
    sub->add_option("--var-threshold", o.varianceThreshold, "MOG2 variance threshold")->capture_default_str();
    sub->add_option("--min-variance", o.minimumVariance, "Floor on MOG2's per-pixel variance (grey levels squared)")
        ->capture_default_str();
    sub->add_flag("--no-gain-compensation", args->noGainCompensation, "Do not match each frame's exposure to the background");
    sub->add_option("--front-ray", args->frontRay, "X0,Y0,DX,DY: measure the front along this image ray in tracks.csv");
    sub->add_option("--progress", args->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}))
        ->capture_default_str();
    return {sub, [args] { return runExtract(*args); }};
}

}  // namespace viscoscope::cli
