// Digests that tell one job, file or engine build from another: 64-bit FNV-1a as 16 hex digits.
// Not cryptographic. Written by hand because it is a few lines and its value must never change
// with a library's version: checkpoints and simulation folders store it to recognise their run.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace viscoscope {

class Digest {
public:
    Digest& add(std::string_view bytes);
    std::string hex() const;

private:
    std::uint64_t state_ = 1469598103934665603ull;  // FNV-1a's offset basis
};

// The digest of a file's bytes. Throws std::runtime_error when it cannot be read.
std::string fileDigest(const std::filesystem::path& file);

// The digest of the running engine's executable: a run resumed or kept, or a calibration read back,
// must be one this code would make.
const std::string& engineBuild();

// A machine file that carries the digest of the rest of itself (its "content_digest"), so that its
// reader tells a damaged or hand-edited copy from what was written and refuses it whole, instead of
// failing on whichever value it reads first. `doc` must be an object.
nlohmann::json sealed(nlohmann::json doc);
bool sealIsIntact(const nlohmann::json& doc);

}  // namespace viscoscope
