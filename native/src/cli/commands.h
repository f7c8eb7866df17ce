// The `viscoscope` sub-commands. Each file cli/<name>_command.cpp adds one sub-command to the app
// and returns it with the callback that runs it; main() maps exceptions to DESIGN.md's exit codes.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>

namespace viscoscope::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitInternal = 1;
inline constexpr int kExitBadInput = 2;
inline constexpr int kExitCancelled = 3;

struct Command {
    CLI::App* sub;
    std::function<int()> run;  // called only when `sub` was parsed
};

Command addSimulateCommand(CLI::App& app);
Command addExtractCommand(CLI::App& app);
Command addScoreCommand(CLI::App& app);
Command addCameraCommand(CLI::App& app);
Command addIdentifyCommand(CLI::App& app);
Command addDiagnoseCommand(CLI::App& app);
Command addSynthCommand(CLI::App& app);
Command addCompareCommand(CLI::App& app);
Command addSchemaCommand(CLI::App& app);
Command addCheckCommand(CLI::App& app);
Command addViscosityCommand(CLI::App& app);

}  // namespace viscoscope::cli
