// Rheology per stress sample: η(γ̇) for the scene's material model. Newtonian is constant;
// the generalized Newtonian models are solved by Picard iteration on these per-sample values.
#pragma once

#include "scene/scene.h"

namespace viscoscope::sim {

class MaterialLaw {
public:
    explicit MaterialLaw(const Material& material) : material_(material) {}
    bool shearDependent() const { return !std::holds_alternative<Newtonian>(material_.model); }
    // Dynamic viscosity (Pa·s) at shear rate γ̇ = sqrt(2 D:D) (1/s).
    double viscosity(double shearRate) const;

private:
    Material material_;
};

}  // namespace viscoscope::sim
