// Digests that tell one job, file or engine build from another: 64-bit FNV-1a as 16 hex digits.
// Not cryptographic. Written by hand because it is a few lines and its value must never change
// with a library's version: checkpoints and simulation folders store it to recognise their run.
#pragma once

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

}  // namespace viscoscope
