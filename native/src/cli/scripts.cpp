#include "cli/scripts.h"

#include <cstdlib>

namespace viscoscope::cli {

namespace fs = std::filesystem;

std::optional<fs::path> findScript(const std::string& name) {
    if (const char* dir = std::getenv("VISCOSCOPE_SCRIPTS")) {
        const fs::path p = fs::path(dir) / name;
        if (fs::exists(p)) return p;
    }
    std::error_code ec;
    fs::path here = fs::read_symlink("/proc/self/exe", ec).parent_path();
    for (int up = 0; up < 6 && !here.empty(); ++up, here = here.parent_path()) {
        const fs::path p = here / "scripts" / name;
        if (fs::exists(p)) return p;
        if (here == here.parent_path()) break;
    }
    return std::nullopt;
}

std::string plot(const std::string& name, const fs::path& outDir) {
    const auto script = findScript(name);
    if (!script) return "skipped: scripts/" + name + " not found";
    if (std::system("/usr/bin/python3 -c 'import matplotlib' > /dev/null 2>&1") != 0)
        return "skipped: /usr/bin/python3 with matplotlib not available";
    const std::string command = "/usr/bin/python3 '" + script->string() + "' '" + outDir.string() + "' > /dev/null 2>&1";
    return std::system(command.c_str()) == 0 ? "ok" : "failed: " + command;
}

}  // namespace viscoscope::cli
