// Side walls: geometry the footage does not show, the width of the scene's channel searched beside
// the base's parameters.
#include "diagnose/effects/effects.h"

#include <algorithm>

namespace viscoscope::diagnose {

namespace {

std::string parameters(const BaseFit& base, std::vector<AddedParameter>& added) {
    const Scene& s = base.job.scene;
    int channel = -1;
    for (size_t i = 0; i < s.solids.size(); ++i)
        if (std::holds_alternative<ChannelSolid>(s.solids[i])) channel = static_cast<int>(i);
    if (channel < 0) return "the scene has no channel solid";
    const std::string name = "solids[" + std::to_string(channel) + "].width";
    if (base.sets(name)) return "the job already sets the channel's width";
    // From the scene's width, anywhere between 4 cells of the job's grid and the domain's extent
    // across: nobody measured it, so a factor 2 around a guess is not the bound.
    const double across = s.domain.max.y() - s.domain.min.y();
    const double narrowest = std::min(across, 4 * (s.domain.max - s.domain.min).maxCoeff() / base.job.resolution);
    if (across < 2 * narrowest) return "the domain is under 8 cells across, too narrow to search the channel's width";
    const double now = std::get<ChannelSolid>(s.solids[channel]).width;
    nlohmann::json width = searchedParameter(name, std::clamp(now, narrowest, across), kWarmLogSpread);
    width["min"] = narrowest;
    width["max"] = across;
    // The widest channel is the open one: the base.
    added.push_back({width, INFINITY});
    return "";
}

}  // namespace

Effect sideWalls() {
    Effect effect;
    effect.name = "side_walls";
    effect.title = "side walls nearer than the scene's";
    effect.description = "the width of the scene's channel searched beside the base's parameters";
    effect.source = "geometry the footage does not show: a channel's side walls slow the flow at every time";
    effect.parameters = parameters;
    return effect;
}

}  // namespace viscoscope::diagnose
