// Files the engine runs but does not compile in: Python scripts under the repository's scripts/.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace viscoscope::cli {

// $VISCOSCOPE_SCRIPTS/<name> when that exists, else scripts/<name> in the nearest folder above the
// running executable that has it (build/bin/viscoscope → the source tree); nullopt when neither.
std::optional<std::filesystem::path> findScript(const std::string& name);

}  // namespace viscoscope::cli
