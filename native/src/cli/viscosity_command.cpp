// `viscoscope viscosity SCENE --shear-rate R`: the scene material's viscosity at one shear rate, as
// the solver's material law gives it, for a tool that holds one constant viscosity (the add-on
// sets Blender's Mantaflow from it for a shear-dependent liquid).
#include "cli/commands.h"
#include "scene/scene.h"
#include "sim/sim.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <iostream>
#include <memory>
#include <string>

namespace viscoscope::cli {

namespace {
struct ViscosityArguments {
    std::string scene;
    double shearRate = 0;
};
}  // namespace

Command addViscosityCommand(CLI::App& app) {
    auto args = std::make_shared<ViscosityArguments>();
    CLI::App* sub = app.add_subcommand("viscosity", "Print the scene material's viscosity at a shear rate as JSON");
    sub->add_option("scene", args->scene, "Scene JSON file (its material is read)")->required();
    sub->add_option("--shear-rate", args->shearRate, "Shear rate γ̇ = √(2 D:D), 1/s")->required();
    return {sub, [args] {
                if (!(std::isfinite(args->shearRate) && args->shearRate > 0))
                    throw InputError("--shear-rate: must be a finite number > 0 (1/s)");
                const Scene scene = loadScene(args->scene);
                const nlohmann::json out{{"format", "viscoscope.viscosity"},
                                         {"version", 1},
                                         {"shear_rate_per_s", args->shearRate},
                                         {"viscosity_pa_s", sim::apparentViscosity(scene.material, args->shearRate)},
                                         {"shear_dependent", !std::holds_alternative<Newtonian>(scene.material.model)}};
                std::cout << out.dump() << "\n";
                return kExitOk;
            }};
}

}  // namespace viscoscope::cli
