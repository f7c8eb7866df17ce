// `viscoscope schema`: the declared parameters (name, unit, default, bounds, search defaults) and
// the effects diagnose can add, as JSON on stdout, for the add-on and for users writing jobs by hand.
#include "cli/commands.h"
#include "diagnose/diagnose.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <iostream>

namespace viscoscope::cli {

Command addSchemaCommand(CLI::App& app) {
    CLI::App* sub = app.add_subcommand(
        "schema", "Print every declared parameter (unit, default, bounds) and every effect diagnose can add as JSON");
    return {sub, [] {
                nlohmann::json schema = parameterSchema();
                schema["effects"] = nlohmann::json::array();
                for (const diagnose::Effect& e : diagnose::effects())
                    schema["effects"].push_back(
                        {{"name", e.name}, {"title", e.title}, {"description", e.description}, {"source", e.source}});
                std::cout << schema.dump(2) << "\n";
                return kExitOk;
            }};
}

}  // namespace viscoscope::cli
