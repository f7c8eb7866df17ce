// The reference manifest written by `extract`, read back for scoring, and frame weights ω.
#include "observe/observe.h"

#include "scene/scene.h"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace viscoscope {

namespace {

namespace fs = std::filesystem;

double parseWeight(const std::string& text, const std::string& item) {
    size_t used = 0;
    double w = -1;
    try {
        w = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (used == 0 || used != text.size() || !std::isfinite(w) || w < 0)
        throw InputError("--weights: \"" + item + "\": weight must be a number ≥ 0");
    return w;
}

int parseFrameIndex(const std::string& text, const std::string& item) {
    if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos || text.size() > 9)
        throw InputError("--weights: \"" + item + "\": expected FIRST-LAST:WEIGHT or FRAME:WEIGHT");
    return std::stoi(text);
}

std::vector<std::string> splitOnComma(const std::string& spec) {
    std::vector<std::string> items;
    std::stringstream stream(spec);
    for (std::string item; std::getline(stream, item, ',');) {
        item.erase(std::remove_if(item.begin(), item.end(), ::isspace), item.end());
        if (item.empty()) throw InputError("--weights: empty entry in \"" + spec + "\"");
        items.push_back(item);
    }
    return items;
}

// "FIRST-LAST:W" or "FRAME:W" items; later items override earlier ones, unnamed frames get 1.
std::vector<double> weightsFromRanges(const std::vector<std::string>& items, const std::vector<int>& frames) {
    std::vector<double> weights(frames.size(), 1.0);
    for (const std::string& item : items) {
        const size_t colon = item.find(':');
        if (colon == std::string::npos) throw InputError("--weights: \"" + item + "\": missing \":WEIGHT\"");
        const std::string range = item.substr(0, colon);
        const size_t dash = range.find('-');
        const int first = parseFrameIndex(range.substr(0, dash), item);
        const int last = dash == std::string::npos ? first : parseFrameIndex(range.substr(dash + 1), item);
        if (last < first) throw InputError("--weights: \"" + item + "\": range ends before it starts");
        const double w = parseWeight(item.substr(colon + 1), item);
        for (size_t i = 0; i < frames.size(); ++i)
            if (frames[i] >= first && frames[i] <= last) weights[i] = w;
    }
    return weights;
}

const nlohmann::json& field(const nlohmann::json& doc, const std::string& name, const std::string& origin) {
    if (!doc.contains(name)) throw InputError(origin + ": " + name + ": missing");
    return doc.at(name);
}

template <typename T>
std::vector<T> arrayField(const nlohmann::json& doc, const std::string& name, const std::string& origin,
                          size_t expectedSize) {
    const nlohmann::json& value = field(doc, name, origin);
    try {
        std::vector<T> items = value.get<std::vector<T>>();
        if (items.size() == expectedSize) return items;
    } catch (const nlohmann::json::exception&) {
    }
    throw InputError(origin + ": " + name + ": must be an array of " + std::to_string(expectedSize) + " entries");
}

cv::Mat1b readMaskImage(const fs::path& file, int width, int height) {
    const cv::Mat image = readImage(file, cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw InputError(file.string() + ": missing or unreadable mask");
    if (image.cols != width || image.rows != height)
        throw InputError(file.string() + ": mask is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                         ", expected " + std::to_string(width) + "x" + std::to_string(height));
    return image;
}

}  // namespace

std::vector<double> parseFrameWeights(const std::string& spec, const std::vector<int>& frames) {
    if (spec.empty()) return std::vector<double>(frames.size(), 1.0);
    const std::vector<std::string> items = splitOnComma(spec);
    if (spec.find(':') != std::string::npos) return weightsFromRanges(items, frames);
    std::vector<double> weights;
    for (const std::string& item : items) weights.push_back(parseWeight(item, item));
    // With no frames this is a syntax check made before extraction, when the count is not known.
    if (!frames.empty() && weights.size() != frames.size())
        throw InputError("--weights: " + std::to_string(weights.size()) + " values for " +
                         std::to_string(frames.size()) + " extracted frames");
    return weights;
}

cv::Mat1b ReferenceManifest::mask(size_t i) const { return readMaskImage(directory / maskFiles.at(i), width, height); }

cv::Mat1b ReferenceManifest::comparedPixels() const {
    if (!excludeFile) return {};
    const cv::Mat1b excluded = readMaskImage(directory / *excludeFile, width, height);
    return excluded == 0;
}

ReferenceManifest loadReferenceManifest(const fs::path& directory) {
    const fs::path file = directory / "manifest.json";
    const std::string origin = file.string();
    std::ifstream stream(file);
    if (!stream) throw InputError(origin + ": missing (run `viscoscope extract` first)");
    const nlohmann::json doc = parseJsonStrictly(stream, origin);
    if (!doc.is_object() || doc.value("format", nlohmann::json()) != nlohmann::json("viscoscope.reference"))
        throw InputError(origin + ": format: expected \"viscoscope.reference\"");
    ReferenceManifest manifest;
    manifest.directory = directory;
    try {
        manifest.source = field(doc, "source", origin).get<std::string>();
        manifest.fps = field(doc, "fps", origin).get<double>();
        manifest.width = field(doc, "width", origin).get<int>();
        manifest.height = field(doc, "height", origin).get<int>();
        manifest.frames = field(doc, "frames", origin).get<std::vector<int>>();
    } catch (const nlohmann::json::exception& e) {
        throw InputError(origin + ": wrong field type (" + std::string(e.what()) + ")");
    }
    if (manifest.width <= 0 || manifest.height <= 0) throw InputError(origin + ": width/height: must be positive");
    if (manifest.frames.empty()) throw InputError(origin + ": frames: empty");
    const size_t count = manifest.frames.size();
    manifest.times = arrayField<double>(doc, "times_s", origin, count);
    manifest.weights = arrayField<double>(doc, "weights", origin, count);
    manifest.maskFiles = arrayField<std::string>(doc, "masks", origin, count);
    if (doc.contains("exclude") && doc["exclude"].is_string()) manifest.excludeFile = doc["exclude"].get<std::string>();
    manifest.parameters = doc.value("parameters", nlohmann::json::object());
    return manifest;
}

}  // namespace viscoscope
