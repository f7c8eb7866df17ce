// The calibration cache: a sealed JSON file per key in $VISCOSCOPE_CACHE_DIR, else
// $XDG_CACHE_HOME/viscoscope, else ~/.cache/viscoscope (VISCOSCOPE_CACHE_DIR set empty: no cache).
// Each file holds the key and the engine build that wrote it, and is read back only by the same
// build for the same key, so a rebuilt engine calibrates afresh; a damaged file is read as absent.
#include "sim/calibration_cache.h"

#include "scene/digest.h"
#include "scene/scene.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace viscoscope::sim {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

std::optional<fs::path> cacheFolder() {
    if (const char* dir = std::getenv("VISCOSCOPE_CACHE_DIR"))
        return *dir ? std::optional<fs::path>(dir) : std::nullopt;
    if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return fs::path(xdg) / "viscoscope";
    if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache/viscoscope";
    return std::nullopt;
}

// The file for `key`, none without a cache folder or an engine build to tell.
std::optional<fs::path> cacheFile(const json& key) {
    const std::optional<fs::path> folder = cacheFolder();
    if (!folder) return std::nullopt;
    try {
        return *folder / "calibrations" / (Digest().add(engineBuild()).add(key.dump()).hex() + ".json");
    } catch (const std::runtime_error&) {  // the executable cannot be read
        return std::nullopt;
    }
}

}  // namespace

std::optional<json> cachedCalibration(const json& key) {
    const std::optional<fs::path> file = cacheFile(key);
    if (!file) return std::nullopt;
    std::ifstream in(*file);
    if (!in) return std::nullopt;
    const json doc = json::parse(in, nullptr, false);
    if (!sealIsIntact(doc) || doc.value("engine_build", "") != engineBuild() || doc.value("key", json()) != key ||
        !doc.contains("result"))
        return std::nullopt;
    return doc.at("result");
}

void cacheCalibration(const json& key, const json& result) {
    const std::optional<fs::path> file = cacheFile(key);
    if (!file) return;
    std::error_code error;
    fs::create_directories(file->parent_path(), error);
    if (error) return;
    try {
        writeJsonAtomically(sealed({{"engine_build", engineBuild()}, {"key", key}, {"result", result}}), *file);
    } catch (const OutputError&) {
        // A read-only or full cache folder costs the next run a calibration, nothing more.
    }
}

}  // namespace viscoscope::sim
