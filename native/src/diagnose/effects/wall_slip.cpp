// Wall slip: a Navier slip length at solid walls, searched beside the base's parameters.
#include "diagnose/effects/effects.h"

namespace viscoscope::diagnose {

namespace {

std::string parameters(const BaseFit& base, std::vector<AddedParameter>& added) {
    if (base.sets("slip_length")) return "the job already sets the slip length";
    if (base.job.scene.material.slipLength > 0) return "the scene already has a slip length";
    added.push_back({searchedParameter("slip_length", findParameterDeclaration("slip_length")->searchInitial, kNewLogSpread)});
    return "";
}

}  // namespace

Effect wallSlip() {
    Effect effect;
    effect.name = "wall_slip";
    effect.title = "wall slip";
    effect.description = "Navier slip at solid walls: the slip length searched beside the base's parameters";
    effect.source = "Navier 1823; the film check in sim_physics_test";
    effect.parameters = parameters;
    return effect;
}

}  // namespace viscoscope::diagnose
