// Files the engine runs but does not compile in: Python scripts under the repository's scripts/.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace viscoscope::cli {

// $VISCOSCOPE_SCRIPTS/<name> when that exists, else scripts/<name> in the nearest folder above the
// running executable that has it (build/bin/viscoscope → the source tree); nullopt when neither.
std::optional<std::filesystem::path> findScript(const std::string& name);

// Runs the plotting script `name` on `outDir` with /usr/bin/python3 and matplotlib: "ok", or why it
// was skipped or failed (a missing plotter is a note, not an error).
std::string plot(const std::string& name, const std::filesystem::path& outDir);

}  // namespace viscoscope::cli
