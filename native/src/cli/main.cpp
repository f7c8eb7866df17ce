// Entry point: registers the sub-commands, installs the cancel signal handlers, and maps errors to
// exit codes (0 ok, 2 bad input with a one-line reason, 3 cancelled, 1 a failed write, a diverged
// simulation or an internal error).
#include "cli/commands.h"
#include "scene/scene.h"
#include "sim/sim.h"

#include <csignal>
#include <iostream>
#include <vector>

namespace {
extern "C" void onCancelSignal(int) { viscoscope::requestCancel(); }
}  // namespace

int main(int argc, char** argv) {
    using namespace viscoscope;
    // First, so that a cancel while the command line is read still ends in exit 3, not a kill.
    std::signal(SIGINT, onCancelSignal);
    std::signal(SIGTERM, onCancelSignal);
    CLI::App app{"Viscoscope: identify a liquid's viscosity from video, and simulate it."};
    app.set_version_flag("--version", std::string(VISCOSCOPE_VERSION));
    app.require_subcommand(1);
    bool ignoreLimits = false;
    app.add_flag("--ignore-limits", ignoreLimits,
                 "Run what looks like a mistake of scale anyway: a grid larger than this machine's memory, a run of "
                 "over a month, a domain over 1 km or a solid 100 times larger than it");
    app.fallthrough();  // so that it may follow the command's name, as the other options do

    const std::vector<cli::Command> commands{
        cli::addSimulateCommand(app),
        cli::addExtractCommand(app),
        cli::addScoreCommand(app),
        cli::addCameraCommand(app),
        cli::addIdentifyCommand(app),
        cli::addDiagnoseCommand(app),
        cli::addSynthCommand(app),
        cli::addCompareCommand(app),
        cli::addSchemaCommand(app),
        cli::addCheckCommand(app),
        cli::addViscosityCommand(app),
    };

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int code = app.exit(e);
        return code == 0 ? cli::kExitOk : cli::kExitBadInput;
    }

    try {
        if (ignoreLimits) waiveScaleLimits();
        for (const cli::Command& command : commands)
            if (command.sub->parsed()) return command.run();
        return cli::kExitBadInput;
    } catch (const InputError& e) {
        std::cerr << "viscoscope: " << e.what() << "\n";
        return cli::kExitBadInput;
    } catch (const Cancelled& e) {  // before a command's own loop, e.g. in a hole calibration
        std::cerr << "viscoscope: " << e.what() << "\n";
        return cli::kExitCancelled;
    } catch (const OutputError& e) {
        std::cerr << "viscoscope: " << e.what() << "\n";  // the disk's or the folder's fault, not the engine's
        return cli::kExitInternal;
    } catch (const sim::Diverged& e) {
        std::cerr << "viscoscope: " << e.what() << "\n";
        return cli::kExitInternal;
    } catch (const std::exception& e) {
        std::cerr << "viscoscope: internal error: " << e.what() << "\n";
        return cli::kExitInternal;
    }
}
