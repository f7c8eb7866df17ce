// Reference silhouettes from video: MOG2 background subtraction (Zivkovic 2004), a threshold that
// drops shadows (but for the liquid's own shaded edge), edge pixels trimmed to half coverage,
// morphological closing (and optionally opening), speckle removal by blob size, and a static
// exclusion mask.
#include "observe/observe.h"

#include "observe/frame_source.h"
#include "scene/scene.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/background_segm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

namespace viscoscope {

namespace {

namespace fs = std::filesystem;

// The background model and the per-frame clean-up that turns its output into a binary mask.
class SilhouetteExtractor {
public:
    explicit SilhouetteExtractor(const ExtractionOptions& options)
        : options_(options),
          subtractor_(cv::createBackgroundSubtractorMOG2(std::max(options.backgroundFrames, 1),
                                                         options.varianceThreshold, /*detectShadows=*/true)),
          closeKernel_(ellipticKernel(options.closeKernel)),
          openKernel_(ellipticKernel(options.openKernel)) {
        subtractor_->setVarMin(options.minimumVariance);
        subtractor_->setShadowThreshold(options.shadowThreshold);
    }

    void learnFrame(const cv::Mat& frame) {
        cv::Mat unused;
        subtractor_->apply(frame, unused, -1);  // automatic rate: the running mean of the frames
    }
    void learnCleanPlate(const cv::Mat& plate) {
        cv::Mat unused;
        subtractor_->apply(plate, unused, 1.0);  // 1 = initialize the model from this image
    }

    // Learning is frozen (rate 0): a slow liquid would otherwise fade into the background.
    cv::Mat1b extract(const cv::Mat& frame, const cv::Mat1b& excluded) {
        const cv::Mat matched = options_.compensateGain ? gainMatched(frame) : frame;
        cv::Mat raw;
        subtractor_->apply(matched, raw, 0.0);
        cv::Mat1b mask;
        cv::threshold(raw, mask, options_.threshold, 255, cv::THRESH_BINARY);
        if (options_.edgeCoverage > 0) {
            addShadedEdges(raw, mask);
            dropThinlyCoveredEdges(matched, mask);
        }
        if (!closeKernel_.empty()) cv::morphologyEx(mask, mask, cv::MORPH_CLOSE, closeKernel_);
        if (!openKernel_.empty()) cv::morphologyEx(mask, mask, cv::MORPH_OPEN, openKernel_);
        if (options_.minBlobPixels > 1) dropSmallBlobs(mask);
        if (!excluded.empty()) mask.setTo(0, excluded);
        return mask;
    }

private:
    static cv::Mat ellipticKernel(int size) {
        return size > 1 ? cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(size, size)) : cv::Mat();
    }

    void dropSmallBlobs(cv::Mat1b& mask) const {
        cv::Mat1i labels, stats;
        cv::Mat centroids;
        cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
        for (int row = 0; row < mask.rows; ++row)
            for (int col = 0; col < mask.cols; ++col)
                if (labels(row, col) > 0 && stats(labels(row, col), cv::CC_STAT_AREA) < options_.minBlobPixels)
                    mask(row, col) = 0;
    }

    // A translucent liquid thinly covering a pixel darkens the background without changing its
    // colour, which is MOG2's test for a shadow: the sample references' drops and streams lost
    // their thin edges that way (tests/bench/FINDINGS.md, "Figures moved from code comments").
    // Such pixels touching the liquid join it, and the coverage test then decides: a cast shadow touching the liquid darkens too little to pass it.
    void addShadedEdges(const cv::Mat& raw, cv::Mat1b& mask) const {
        const cv::Mat1b shaded = (raw > 0) & (mask == 0);
        cv::Mat1b touching;
        cv::dilate(mask, touching, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
        mask.setTo(255, shaded & touching);
    }

    const cv::Mat& background() {
        if (background_.empty()) {
            subtractor_->getBackgroundImage(background_);
            linearBackground_ = srgbToLinear(background_);  // learning is frozen: converted once
        }
        return background_;
    }
    const cv::Mat& linearBackground() {
        background();
        return linearBackground_;
    }

    // A sensor adds light linearly, so a pixel the liquid covers by α reads α F + (1 − α) B in linear
    // light, F and B the liquid's and the background's colours. Its coverage is then its distance from
    // the background over F's: the largest distance among the mask's pixels within 2 px, one of which
    // the liquid covers fully unless the feature is thinner than a pixel (then it keeps its best
    // pixel). Only the outline is trimmed, one layer per pass, so a textured background that makes
    // fully covered pixels differ in contrast cannot punch holes inside the liquid. The video is taken
    // as sRGB-encoded, as phones and Blender write it. Hand-written: OpenCV has no coverage matting.
    void dropThinlyCoveredEdges(const cv::Mat& frame, cv::Mat1b& mask) {
        constexpr int kPasses = 2;  // camera blur spreads an outline over about two pixels
        const cv::Mat1f contrast = colourDistance(srgbToLinear(frame), linearBackground());
        const cv::Mat window = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5));
        const cv::Mat cross = cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3));
        cv::Mat1f maskedContrast(contrast.size(), 0.0f), fullContrast;
        contrast.copyTo(maskedContrast, mask);
        cv::dilate(maskedContrast, fullContrast, window);
        const cv::Mat1b thin = contrast < options_.edgeCoverage * fullContrast;
        for (int pass = 0; pass < kPasses; ++pass) {
            cv::Mat1b interior;
            cv::erode(mask, interior, cross);
            mask.setTo(0, (mask & ~interior) & thin);
        }
    }

    static cv::Mat1f colourDistance(const cv::Mat& frame, const cv::Mat& background) {
        cv::Mat difference;
        cv::absdiff(frame, background, difference);
        difference = difference.mul(difference);
        cv::Mat1f squared, distance;
        cv::transform(difference, squared, cv::Matx13f(1, 1, 1));
        cv::sqrt(squared, distance);
        return distance;
    }

    // Scales each channel by the median background/frame ratio over a sparse grid of pixels. The
    // median ignores the liquid as long as it covers less than half of the picture.
    cv::Mat gainMatched(const cv::Mat& frame) {
        const cv::Mat& plate = background();
        constexpr int kStride = 7;
        constexpr int kDarkest = 16;  // ratios of near-black pixels are mostly noise
        cv::Scalar gain(1, 1, 1);
        for (int channel = 0; channel < 3; ++channel) {
            std::vector<float> ratios;
            for (int row = kStride / 2; row < frame.rows; row += kStride)
                for (int col = kStride / 2; col < frame.cols; col += kStride) {
                    const int b = plate.at<cv::Vec3b>(row, col)[channel];
                    const int f = frame.at<cv::Vec3b>(row, col)[channel];
                    if (b >= kDarkest && f >= kDarkest) ratios.push_back(float(b) / float(f));
                }
            if (ratios.size() < 16) continue;
            std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
            gain[channel] = ratios[ratios.size() / 2];
        }
        cv::Mat matched;
        cv::multiply(frame, gain, matched);
        return matched;
    }

    const ExtractionOptions& options_;
    cv::Ptr<cv::BackgroundSubtractorMOG2> subtractor_;
    cv::Mat closeKernel_, openKernel_;
    cv::Mat background_, linearBackground_;
};

// Writes everything under temporary names and renames into place on commit(); whatever was not
// committed is removed, so a failed or cancelled run leaves no complete-looking output.
class StagedOutput {
public:
    explicit StagedOutput(const fs::path& outDir) : outDir_(outDir) {
        std::error_code error;
        fs::create_directories(outDir, error);
        if (error) throw InputError(outDir.string() + ": cannot create output folder (" + error.message() + ")");
        // An older manifest next to half-rewritten masks would look complete: it goes first.
        fs::remove(outDir / "manifest.json");
        fs::remove_all(staged("masks"));
        fs::create_directories(staged("masks"));
    }
    ~StagedOutput() {
        if (committed_) return;
        std::error_code ignored;
        for (const char* name : {"masks", "exclude.png", "preview.png", "manifest.json"})
            fs::remove_all(staged(name), ignored);
    }
    // The temporary path for `name`; the extension stays last so OpenCV picks the right codec.
    fs::path staged(const std::string& name) const {
        const fs::path path(name);
        return outDir_ / (path.stem().string() + ".partial" + path.extension().string());
    }
    void commit(const std::vector<std::string>& names) {
        for (const std::string& name : names) {  // the caller lists the manifest last
            fs::remove_all(outDir_ / name);
            fs::rename(staged(name), outDir_ / name);
        }
        committed_ = true;
    }

private:
    fs::path outDir_;
    bool committed_ = false;
};

// A few frames side by side with the mask tinted red, for a person to check the extraction.
class PreviewStrip {
public:
    static constexpr size_t kTiles = 4;
    // With no frames to show (a clip whose container does not say how many frames it holds), the
    // first kTiles offered.
    explicit PreviewStrip(std::vector<int> framesToShow) : framesToShow_(std::move(framesToShow)) {}

    void offer(int frameIndex, const cv::Mat& frame, const cv::Mat1b& mask) {
        const bool shown = framesToShow_.empty() ? tiles_.size() < kTiles
                                                 : std::find(framesToShow_.begin(), framesToShow_.end(),
                                                             frameIndex) != framesToShow_.end();
        if (!shown) return;
        cv::Mat tinted = frame.clone();
        tinted.setTo(cv::Scalar(0, 0, 255), mask);
        cv::addWeighted(frame, 0.5, tinted, 0.5, 0, tinted);
        const double scale = std::min(1.0, kHeight / double(frame.rows));
        cv::resize(tinted, tinted, cv::Size(), scale, scale, cv::INTER_AREA);
        cv::putText(tinted, std::to_string(frameIndex), {6, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.6, {255, 255, 255}, 2);
        tiles_.push_back(tinted);
    }
    void write(const fs::path& file) const {
        cv::Mat strip;
        if (!tiles_.empty()) cv::hconcat(tiles_, strip);
        writeImage(strip, file);
    }

private:
    static constexpr double kHeight = 240;
    std::vector<int> framesToShow_;
    std::vector<cv::Mat> tiles_;
};

std::vector<int> plannedFrames(const ExtractionOptions& options, int frameCount) {
    std::vector<int> frames;
    const int last = options.last >= 0 ? options.last : frameCount - 1;
    for (int f = options.first; f <= last; f += options.step) frames.push_back(f);
    return frames;
}

std::vector<int> previewFrames(const std::vector<int>& planned) {
    constexpr size_t kTiles = PreviewStrip::kTiles;
    if (planned.size() <= kTiles) return planned;
    std::vector<int> shown;
    for (size_t i = 0; i < kTiles; ++i) shown.push_back(planned[i * (planned.size() - 1) / (kTiles - 1)]);
    return shown;
}

void validateOptions(const ExtractionOptions& o) {
    if (o.first < 0) throw InputError("--first must be ≥ 0");
    if (o.last >= 0 && o.last < o.first) throw InputError("--last must be ≥ --first");
    if (o.step < 1) throw InputError("--step must be ≥ 1");
    if (!o.cleanPlate && !o.cleanPlateFrame && o.backgroundFrames < 1)
        throw InputError("--background-frames must be ≥ 1 without a clean plate");
    if (o.cleanPlate && o.cleanPlateFrame)
        throw InputError("--clean-plate and --clean-plate-frame both name a clean plate: give one");
    if (o.cleanPlateFrame && *o.cleanPlateFrame < 0) throw InputError("--clean-plate-frame must be ≥ 0");
    if (o.threshold < 0 || o.threshold > 254) throw InputError("--threshold must be in [0, 254]");
    if (!(o.shadowThreshold > 0 && o.shadowThreshold <= 1)) throw InputError("--shadow-threshold must be in (0, 1]");
    if (!(o.edgeCoverage >= 0 && o.edgeCoverage < 1)) throw InputError("--edge-coverage must be in [0, 1)");
    if (o.closeKernel < 0 || o.openKernel < 0) throw InputError("--close/--open kernel sizes must be ≥ 0");
    if (o.minBlobPixels < 0) throw InputError("--min-blob must be ≥ 0");
    if (!(o.varianceThreshold > 0)) throw InputError("--var-threshold must be > 0");
    if (!(o.minimumVariance > 0)) throw InputError("--min-variance must be > 0");
    if (o.fps && !(std::isfinite(*o.fps) && *o.fps > 0)) throw InputError("--fps must be > 0");
}

cv::Mat1b exclusionMask(const ExtractionOptions& options, cv::Size frameSize) {
    if (!options.excludeMask && options.excludePolygons.empty()) return {};
    cv::Mat1b excluded(frameSize, uchar(0));
    if (options.excludeMask) {
        const std::string file = options.excludeMask->string();
        const cv::Mat image = readImage(file, cv::IMREAD_GRAYSCALE);
        if (image.empty()) throw InputError(file + ": cannot read exclusion mask");
        if (image.size() != frameSize)
            throw InputError(file + ": exclusion mask is " + std::to_string(image.cols) + "x" +
                             std::to_string(image.rows) + ", frames are " + std::to_string(frameSize.width) + "x" +
                             std::to_string(frameSize.height));
        excluded.setTo(255, image != 0);
    }
    for (const auto& polygon : options.excludePolygons) {
        if (polygon.size() < 3) throw InputError("exclusion polygon needs at least 3 points");
        std::vector<cv::Point> points;
        for (const cv::Point2d& p : polygon) points.emplace_back(cvRound(p.x), cvRound(p.y));
        cv::fillPoly(excluded, std::vector<std::vector<cv::Point>>{points}, cv::Scalar(255));
    }
    return excluded;
}

void learnBackground(SilhouetteExtractor& extractor, const fs::path& source, const ExtractionOptions& options,
                     cv::Size frameSize) {
    if (options.cleanPlate) {
        const cv::Mat plate = readImage(*options.cleanPlate, cv::IMREAD_COLOR);
        if (plate.empty()) throw InputError(options.cleanPlate->string() + ": cannot read clean plate");
        if (plate.size() != frameSize) throw InputError(options.cleanPlate->string() + ": clean plate size differs from the frames'");
        extractor.learnCleanPlate(plate);
        return;
    }
    FrameSource frames(source, options.fps);
    cv::Mat frame;
    if (options.cleanPlateFrame) {
        while (frames.nextIndex() < *options.cleanPlateFrame)
            if (!frames.skip()) break;
        if (!frames.read(frame))
            throw InputError(source.string() + ": has " + std::to_string(frames.nextIndex()) +
                             " frames; the clean plate frame " + std::to_string(*options.cleanPlateFrame) +
                             " is not among them");
        extractor.learnCleanPlate(frame);
        return;
    }
    for (int i = 0; i < options.backgroundFrames; ++i) {
        if (!frames.read(frame))
            throw InputError(source.string() + ": has " + std::to_string(i) + " frames, fewer than the " +
                             std::to_string(options.backgroundFrames) + " background frames asked for");
        extractor.learnFrame(frame);
    }
}

// One field of a job's "extraction" object, typed.
struct OptionReader {
    const nlohmann::json& doc;
    const std::string& origin;

    [[noreturn]] void fail(const std::string& name, const std::string& problem) const {
        throw InputError(origin + "." + name + ": " + problem);
    }
    int integer(const std::string& name, int fallback) const {
        if (!doc.contains(name)) return fallback;
        if (!doc[name].is_number_integer()) fail(name, "must be an integer");
        return doc[name].get<int>();
    }
    double number(const std::string& name, double fallback) const {
        if (!doc.contains(name)) return fallback;
        if (!doc[name].is_number() || !std::isfinite(doc[name].get<double>())) fail(name, "must be a finite number");
        return doc[name].get<double>();
    }
    std::string text(const std::string& name) const {
        if (!doc.contains(name)) return "";
        if (!doc[name].is_string()) fail(name, "must be a string");
        return doc[name].get<std::string>();
    }
    std::optional<fs::path> file(const std::string& name, const fs::path& baseDir) const {
        const std::string value = text(name);
        if (value.empty()) return std::nullopt;
        const fs::path path = fs::path(value).is_absolute() || baseDir.empty() ? fs::path(value) : baseDir / value;
        if (!fs::is_regular_file(path)) fail(name, path.string() + " not found");
        return path;
    }
};

std::string maskName(int frameIndex) {
    char name[32];
    std::snprintf(name, sizeof name, "masks/mask_%05d.png", frameIndex);
    return name;
}

// The source ran out before the range did: `framesRead` frames were all there was.
void requireRangeInSource(const fs::path& source, const ExtractionOptions& options, const std::vector<int>& extracted,
                          int framesRead) {
    if (extracted.empty())
        throw InputError(source.string() + ": no frame in the range --first " + std::to_string(options.first) +
                         " (the source has " + std::to_string(framesRead) + " frames)");
    if (options.last >= 0 && framesRead <= options.last)
        throw InputError(source.string() + ": --last " + std::to_string(options.last) + " is past the last frame (" +
                         std::to_string(framesRead - 1) + ")");
}

void writeManifest(const ReferenceManifest& m, const fs::path& file) {
    nlohmann::json doc = {{"format", "viscoscope.reference"}, {"version", 1}, {"source", m.source}, {"fps", m.fps},
                          {"width", m.width}, {"height", m.height}, {"frames", m.frames}, {"times_s", m.times},
                          {"weights", m.weights}, {"masks", m.maskFiles},
                          {"exclude", m.excludeFile ? nlohmann::json(*m.excludeFile) : nlohmann::json()},
                          {"parameters", m.parameters}};
    if (fs::exists(file.parent_path() / "preview.png")) doc["preview"] = "preview.png";
    writeJsonAtomically(doc, file);
}

}  // namespace

const char* backgroundSourceName(const ExtractionOptions& options) {
    if (options.cleanPlate) return "clean_plate";
    return options.cleanPlateFrame ? "clean_plate_frame" : "leading_frames";
}

nlohmann::json extractionParameters(const ExtractionOptions& o) {
    nlohmann::json polygons = nlohmann::json::array();
    for (const auto& polygon : o.excludePolygons) {
        nlohmann::json points = nlohmann::json::array();
        for (const cv::Point2d& p : polygon) points.push_back({p.x, p.y});
        polygons.push_back(points);
    }
    return {{"revision", kExtractionRevision},
            {"first", o.first},
            {"last", o.last},
            {"step", o.step},
            {"background", backgroundSourceName(o)},
            {"background_frames", o.cleanPlate || o.cleanPlateFrame ? 0 : o.backgroundFrames},
            {"clean_plate", o.cleanPlate ? fs::absolute(*o.cleanPlate).string() : ""},
            {"clean_plate_frame", o.cleanPlateFrame ? *o.cleanPlateFrame : -1},
            {"mog2_variance_threshold", o.varianceThreshold},
            {"mog2_minimum_variance", o.minimumVariance},
            {"mog2_detect_shadows", true},
            {"mog2_shadow_threshold", o.shadowThreshold},
            {"compensate_gain", o.compensateGain},
            {"threshold", o.threshold},
            {"edge_coverage", o.edgeCoverage},
            {"close_kernel_px", o.closeKernel},
            {"open_kernel_px", o.openKernel},
            {"min_blob_px", o.minBlobPixels},
            {"exclude_mask", o.excludeMask ? fs::absolute(*o.excludeMask).string() : ""},
            {"exclude_polygons", polygons},
            {"weights", o.weights}};
}

ExtractionOptions parseExtractionOptions(const nlohmann::json& doc, const std::string& origin, const fs::path& baseDir) {
    if (!doc.is_object()) throw InputError(origin + ": must be an object");
    static const std::vector<std::string> known{
        "first", "last", "step", "fps", "background_frames", "clean_plate", "clean_plate_frame", "exclude_mask",
        "exclude_polygons",
        "weights", "mog2_variance_threshold", "mog2_minimum_variance", "mog2_shadow_threshold", "compensate_gain",
        "threshold", "edge_coverage", "close_kernel_px", "open_kernel_px", "min_blob_px"};
    rejectUnknownKeys(doc, known, origin + ".");
    const OptionReader in{doc, origin};
    ExtractionOptions o;
    o.first = in.integer("first", o.first);
    o.last = in.integer("last", o.last);
    o.step = in.integer("step", o.step);
    if (doc.contains("fps")) o.fps = in.number("fps", 0);
    o.backgroundFrames = in.integer("background_frames", o.backgroundFrames);
    o.cleanPlate = in.file("clean_plate", baseDir);
    if (doc.contains("clean_plate_frame")) o.cleanPlateFrame = in.integer("clean_plate_frame", 0);
    o.excludeMask = in.file("exclude_mask", baseDir);
    if (doc.contains("exclude_polygons")) {
        try {
            for (const auto& polygon : doc["exclude_polygons"]) {
                o.excludePolygons.emplace_back();
                for (const auto& point : polygon)
                    o.excludePolygons.back().emplace_back(point.at(0).get<double>(), point.at(1).get<double>());
            }
        } catch (const nlohmann::json::exception&) {
            in.fail("exclude_polygons", "must be [[[x, y], ...], ...] in pixels");
        }
    }
    o.weights = in.text("weights");
    o.varianceThreshold = in.number("mog2_variance_threshold", o.varianceThreshold);
    o.minimumVariance = in.number("mog2_minimum_variance", o.minimumVariance);
    if (doc.contains("compensate_gain")) {
        if (!doc["compensate_gain"].is_boolean()) in.fail("compensate_gain", "must be true or false");
        o.compensateGain = doc["compensate_gain"].get<bool>();
    }
    o.threshold = in.integer("threshold", o.threshold);
    o.shadowThreshold = in.number("mog2_shadow_threshold", o.shadowThreshold);
    o.edgeCoverage = in.number("edge_coverage", o.edgeCoverage);
    o.closeKernel = in.integer("close_kernel_px", o.closeKernel);
    o.openKernel = in.integer("open_kernel_px", o.openKernel);
    o.minBlobPixels = in.integer("min_blob_px", o.minBlobPixels);
    try {
        validateOptions(o);
        parseFrameWeights(o.weights, {});
    } catch (const InputError& e) {
        throw InputError(origin + ": " + e.what());
    }
    return o;
}

ReferenceManifest extractSilhouettes(const fs::path& source, const ExtractionOptions& options, const fs::path& outDir,
                                     const ProgressCallback& progress) {
    validateOptions(options);
    parseFrameWeights(options.weights, {});  // reports syntax errors before any work
    FrameSource frames(source, options.fps);
    const cv::Size frameSize = frames.frameSize();
    const cv::Mat1b excluded = exclusionMask(options, frameSize);
    SilhouetteExtractor extractor(options);
    learnBackground(extractor, source, options, frameSize);

    StagedOutput output(outDir);
    const std::vector<int> planned = plannedFrames(options, frames.frameCount());
    PreviewStrip preview(previewFrames(planned));
    ReferenceManifest manifest;
    cv::Mat frame;
    while (options.last < 0 || frames.nextIndex() <= options.last) {
        throwIfCancelled("extraction");
        const int index = frames.nextIndex();
        const bool wanted = index >= options.first && (index - options.first) % options.step == 0;
        if (!(wanted ? frames.read(frame) : frames.skip())) break;
        if (!wanted) continue;
        const cv::Mat1b mask = extractor.extract(frame, excluded);
        const std::string name = maskName(index);
        writeImage(mask, output.staged("masks") / fs::path(name).filename());
        preview.offer(index, frame, mask);
        manifest.frames.push_back(index);
        manifest.times.push_back(index / frames.fps());
        manifest.maskFiles.push_back(name);
        if (progress) progress(static_cast<int>(manifest.frames.size()), static_cast<int>(planned.size()));
    }
    requireRangeInSource(source, options, manifest.frames, frames.nextIndex());

    manifest.directory = outDir;
    manifest.source = fs::absolute(source).string();
    manifest.fps = frames.fps();
    manifest.width = frameSize.width;
    manifest.height = frameSize.height;
    manifest.weights = parseFrameWeights(options.weights, manifest.frames);
    manifest.parameters = extractionParameters(options);
    std::vector<std::string> outputs{"masks", "preview.png"};
    if (!excluded.empty()) {
        writeImage(excluded, output.staged("exclude.png"));
        manifest.excludeFile = "exclude.png";
        outputs.push_back("exclude.png");
    }
    preview.write(output.staged("preview.png"));
    writeManifest(manifest, output.staged("manifest.json"));
    outputs.push_back("manifest.json");
    output.commit(outputs);
    return manifest;
}

void saveReferenceManifest(const ReferenceManifest& manifest, const fs::path& directory) {
    writeManifest(manifest, directory / "manifest.json");
}

}  // namespace viscoscope
