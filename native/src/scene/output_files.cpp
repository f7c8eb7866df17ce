#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <cerrno>
#include <cstring>
#include <fstream>

namespace viscoscope {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void cannotWrite(const fs::path& file, const std::string& reason) {
    throw OutputError(file.string() + ": cannot write (" + (reason.empty() ? "unknown reason" : reason) + ")");
}

}  // namespace

void writeFileAtomically(const fs::path& file, const std::function<void(std::ostream&)>& write) {
    const fs::path partial = file.string() + ".partial";
    std::error_code ignored;
    try {
        errno = 0;
        std::ofstream stream(partial, std::ios::binary | std::ios::trunc);
        if (!stream) cannotWrite(file, std::strerror(errno));
        write(stream);
        stream.flush();
        // A stream's failure keeps no reason of its own; errno still holds the failed write(2)'s.
        if (!stream) cannotWrite(file, std::strerror(errno));
        stream.close();
        if (stream.fail()) cannotWrite(file, std::strerror(errno));
        std::error_code error;
        fs::rename(partial, file, error);
        if (error) cannotWrite(file, error.message());
    } catch (...) {
        fs::remove(partial, ignored);
        throw;
    }
}

void writeJsonAtomically(const nlohmann::json& doc, const fs::path& file) {
    writeFileAtomically(file, [&](std::ostream& out) { out << doc.dump(1) << "\n"; });
}

}  // namespace viscoscope
