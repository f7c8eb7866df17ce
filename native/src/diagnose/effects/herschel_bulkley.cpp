// Shear thinning with a yield stress: a Herschel–Bulkley liquid τ = τ_y + K γ̇ⁿ, n ≤ 1, in place of
// η, for the liquids that are both (sauces, creams, lotions).
#include "diagnose/effects/effects.h"

#include <cmath>

namespace viscoscope::diagnose {

namespace {

std::string parameters(const BaseFit& base, std::vector<AddedParameter>& added) {
    added.push_back(thinningConsistency(base));
    added.push_back(flowIndex());
    // Started one e-fold above its least, near the power law's ridge that the first generation
    // scans: the Bingham liquid's start, a tenth of ρ g h₀, is a flow far from the base's.
    AddedParameter yieldStress = yieldStressParameter(base);
    if (yieldStress.spec.contains("min")) {
        const double least = yieldStress.spec.at("min").get<double>();
        const nlohmann::json bounds{{"min", least}, {"max", yieldStress.spec.at("max")}};
        yieldStress.spec = searchedParameter("yield_stress", std::exp(1.0) * least, 1.0);
        yieldStress.spec.update(bounds);
    }
    added.push_back(yieldStress);
    return "";
}

}  // namespace

Effect herschelBulkley() {
    Effect effect;
    effect.name = "herschel_bulkley";
    effect.title = "shear thinning with a yield stress";
    effect.description = "Herschel–Bulkley liquid τ = τ_y + K γ̇ⁿ, n ≤ 1, in place of η: τ_y, K and n searched";
    effect.source = "Herschel & Bulkley 1926; two geometries separate τ_y from K (Hamamichi et al. 2023)";
    effect.law = [](double eta) -> MaterialModel { return HerschelBulkley{0.0, eta, 1.0}; };
    effect.parameters = parameters;
    effect.startCurve = thinningRidge;
    return effect;
}

}  // namespace viscoscope::diagnose
