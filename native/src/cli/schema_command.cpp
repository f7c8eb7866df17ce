// `viscoscope schema`: the declared parameters (name, unit, default, bounds, search defaults) as
// JSON on stdout, for the add-on and for users writing jobs by hand.
#include "cli/commands.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <iostream>

namespace viscoscope::cli {

Command addSchemaCommand(CLI::App& app) {
    CLI::App* sub = app.add_subcommand("schema", "Print every declared parameter (unit, default, bounds) as JSON");
    return {sub, [] {
                std::cout << parameterSchema().dump(2) << "\n";
                return kExitOk;
            }};
}

}  // namespace viscoscope::cli
