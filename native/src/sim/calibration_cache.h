// One-off calibrations kept on disk between runs, so that identify, simulate, synth and a bake of
// the same grid pay for them once (see calibration_cache.cpp for where and how).
#pragma once

#include <nlohmann/json.hpp>

#include <optional>

namespace viscoscope::sim {

// The result this engine build stored under `key` (everything the calibration depends on), if any.
std::optional<nlohmann::json> cachedCalibration(const nlohmann::json& key);
// Stores `result` under `key`. A cache that cannot be written is passed over: the calibration then
// only runs again next time.
void cacheCalibration(const nlohmann::json& key, const nlohmann::json& result);

}  // namespace viscoscope::sim
