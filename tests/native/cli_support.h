// What the `viscoscope` command-line tests share: running the built engine (VISCOSCOPE_CLI) as a
// subprocess and reading what it wrote. The cli_* tests link only the scene stage, so this is all
// they know of the engine.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace viscoscope::cli_test {

inline std::string slurp(const std::filesystem::path& file) {
    std::ifstream stream(file);
    std::stringstream text;
    text << stream.rdbuf();
    return text.str();
}

struct CommandResult {
    int exitCode;  // −1 when the engine did not exit normally (a crash)
    std::string out, err;
};

// A shell command line, its stdout and stderr kept in `dir`.
inline CommandResult runCommand(const std::string& command, const std::filesystem::path& dir) {
    const std::string redirected = command + " > " + (dir / "stdout").string() + " 2> " + (dir / "stderr").string();
    const int status = std::system(redirected.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(dir / "stdout"), slurp(dir / "stderr")};
}

// `viscoscope ARGUMENTS`, its stdout and stderr kept in `dir`.
inline CommandResult runViscoscope(const std::string& arguments, const std::filesystem::path& dir) {
    return runCommand(std::string(VISCOSCOPE_CLI) + " " + arguments, dir);
}

}  // namespace viscoscope::cli_test
