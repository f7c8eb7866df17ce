// Shear thinning: the Ostwald–de Waele power law η = K γ̇^(n−1), n ≤ 1, in place of η.
#include "diagnose/effects/effects.h"

#include <algorithm>
#include <cmath>

namespace viscoscope::diagnose {

namespace {

constexpr double kStartFlowIndex = 0.8;
// The first generation scans n from 1 down to this along K γ̇_c^(n−1) = η*: thinner than most food
// and cosmetic liquids (xanthan solutions, ketchup: n ≈ 0.2–0.4).
constexpr double kLeastScannedFlowIndex = 0.25;

std::string parameters(const BaseFit& base, std::vector<AddedParameter>& added) {
    added.push_back(thinningConsistency(base));
    added.push_back(flowIndex());
    return "";
}

}  // namespace

AddedParameter thinningConsistency(const BaseFit& base) {
    // K from η* with a wide spread: where the base flow's shear rate is known (not on a thin film),
    // the first generation scans the ridge (thinningRidge) instead of sampling around this.
    const identify::ParameterSpec& eta = *std::find_if(base.job.parameters.begin(), base.job.parameters.end(),
                                                       [](const identify::ParameterSpec& p) { return p.name() == "viscosity"; });
    nlohmann::json consistency = searchedParameter("consistency", *base.value("viscosity"), kNewLogSpread);
    consistency["min"] = eta.lower;
    consistency["max"] = eta.upper;
    return {consistency, *base.value("viscosity"), true};
}

AddedParameter flowIndex() {
    // Thinning only (n ≤ 1), so that n = 1 is the base: a free n absorbed the difference of the
    // reference's grid in a Newtonian control and predicted it better (tests/bench/FINDINGS.md,
    // "Diagnose on synthetic fronts").
    nlohmann::json index = searchedParameter("flow_index", kStartFlowIndex, 0.3);
    index["max"] = 1.0;
    return {index, 1.0};
}

// From independent samples of K and n, the synthetic fronts' hidden power law was missed (FINDINGS,
// "Diagnose on synthetic fronts").
StartCurve thinningRidge(const nlohmann::json& parameters, const BaseFit& base) {
    if (!base.shearRate) return {};
    std::vector<double> start;
    size_t consistency = 0, index = 0;
    for (size_t i = 0; i < parameters.size(); ++i) {
        start.push_back(parameters[i].at("initial").get<double>());
        if (parameters[i].at("name") == "consistency") consistency = i;
        if (parameters[i].at("name") == "flow_index") index = i;
    }
    const double lower = parameters[consistency].at("min").get<double>();
    const double upper = parameters[consistency].at("max").get<double>();
    const double eta = *base.value("viscosity"), shearRate = *base.shearRate;
    return [=](double s) {
        std::vector<double> theta = start;
        theta[index] = 1 - s * (1 - kLeastScannedFlowIndex);
        theta[consistency] = std::clamp(eta * std::pow(shearRate, 1 - theta[index]), lower, upper);
        return theta;
    };
}

Effect shearThinning() {
    Effect effect;
    effect.name = "shear_thinning";
    effect.title = "shear thinning";
    effect.description = "power law η = K γ̇^(n−1), n ≤ 1, in place of η: K and n searched";
    effect.source = "Ostwald–de Waele power law; a gravity current spreads as t^{n/(3n+5)} (DESIGN.md)";
    effect.law = [](double eta) -> MaterialModel { return PowerLaw{eta, 1.0}; };
    effect.parameters = parameters;
    effect.startCurve = thinningRidge;
    return effect;
}

}  // namespace viscoscope::diagnose
