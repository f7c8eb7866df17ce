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

double apparentViscosity(const Material& material, double shearRate) {
    return MaterialLaw(material).viscosity(shearRate);
}

}  // namespace viscoscope::sim
