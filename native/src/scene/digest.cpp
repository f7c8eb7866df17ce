#include "scene/digest.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <vector>

namespace viscoscope {

Digest& Digest::add(std::string_view bytes) {
    for (unsigned char c : bytes) state_ = (state_ ^ c) * 1099511628211ull;  // FNV-1a's prime
    return *this;
}

std::string Digest::hex() const {
    char text[17];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(state_));
    return text;
}

std::string fileDigest(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) throw std::runtime_error(file.string() + ": cannot read");
    Digest digest;
    std::vector<char> buffer(1 << 16);
    while (in.read(buffer.data(), std::streamsize(buffer.size())) || in.gcount() > 0)
        digest.add(std::string_view(buffer.data(), static_cast<size_t>(in.gcount())));
    return digest.hex();
}

const std::string& engineBuild() {
    static const std::string build = fileDigest("/proc/self/exe");
    return build;
}

namespace {
constexpr const char* kSealKey = "content_digest";
}  // namespace

nlohmann::json sealed(nlohmann::json doc) {
    doc.erase(kSealKey);
    const std::string digest = Digest().add(doc.dump()).hex();
    doc[kSealKey] = digest;
    return doc;
}

bool sealIsIntact(const nlohmann::json& doc) {
    if (!doc.is_object() || !doc.contains(kSealKey)) return false;
    nlohmann::json rest = doc;
    rest.erase(kSealKey);
    return doc.at(kSealKey) == nlohmann::json(Digest().add(rest.dump()).hex());
}

}  // namespace viscoscope
