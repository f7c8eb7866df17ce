#include "sim/material_model.h"

#include <algorithm>
#include <cmath>

namespace viscoscope::sim {

namespace {
// Shear rates below this are treated as this: power laws with n < 1 diverge at γ̇ = 0.
constexpr double kMinShearRate = 1e-6;

struct ViscosityAt {
    double eta0, rate;
    double operator()(const Newtonian&) const { return eta0; }
    double operator()(const PowerLaw& m) const {
        return std::clamp(m.consistency * std::pow(rate, m.index - 1), m.etaMin, m.etaMax);
    }
    double operator()(const Carreau& m) const {
        const double lr = m.relaxationTime * rate;
        return m.etaInfinity + (eta0 - m.etaInfinity) * std::pow(1 + lr * lr, 0.5 * (m.index - 1));
    }
    // Regularized: the apparent viscosity is capped at etaMax below the yield point.
    double operator()(const HerschelBulkley& m) const {
        return std::min(m.etaMax, (m.yieldStress + m.consistency * std::pow(rate, m.index)) / rate);
    }
};
}  // namespace

double MaterialLaw::viscosity(double shearRate) const {
    return std::visit(ViscosityAt{material_.viscosity, std::max(shearRate, kMinShearRate)},
                      material_.model);
}

std::optional<YieldingPowerLaw> MaterialLaw::yieldingPowerLaw() const {
    if (const auto* law = std::get_if<PowerLaw>(&material_.model)) return YieldingPowerLaw{0, law->consistency, law->index};
    if (const auto* hb = std::get_if<HerschelBulkley>(&material_.model))
        return YieldingPowerLaw{hb->yieldStress, hb->consistency, hb->index};
    if (std::holds_alternative<Newtonian>(material_.model)) return YieldingPowerLaw{0, material_.viscosity, 1};
    return std::nullopt;
}

double updateViscosity(const MaterialLaw& law, double viscosity, const StokesProblem& problem,
                       const std::array<Field, 3>& velocity, Field& cellViscosity,
                       std::array<Field, 3>& edgeViscosity) {
    const double eta0 = viscosity;
    if (!law.shearDependent()) {
        std::fill(cellViscosity.values.begin(), cellViscosity.values.end(), eta0);
        for (Field& eta : edgeViscosity) std::fill(eta.values.begin(), eta.values.end(), eta0);
        return 0.0;
    }
    const ShearRates rates = shearRates(problem, velocity);
    double squaredChange = 0, squared = 0;
    auto apply = [&](Field& eta, const Field& weight, const Field& rate) {
        for (int s = 0; s < eta.lattice.count(); ++s) {
            if (weight[s] < kMinWeight) {
                eta[s] = eta0;
                continue;
            }
            const double updated = law.viscosity(rate[s]);
            squaredChange += (updated - eta[s]) * (updated - eta[s]);
            squared += updated * updated;
            eta[s] = updated;
        }
    };
    apply(cellViscosity, problem.weights->cell, rates.cell);
    for (int e = 0; e < 3; ++e) apply(edgeViscosity[e], problem.weights->edge[e], rates.edge[e]);
    return squared > 0 ? std::sqrt(squaredChange / squared) : 0.0;
}

double apparentViscosity(const Material& material, double shearRate) {
    return MaterialLaw(material).viscosity(shearRate);
}

}  // namespace viscoscope::sim
