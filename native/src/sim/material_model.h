// Rheology per stress sample: η(γ̇) for the scene's material model. Newtonian is constant;
// the generalized Newtonian models are solved by Picard iteration on these per-sample values.
#pragma once

#include "scene/scene.h"
#include "sim/stokes_solver.h"

#include <array>
#include <optional>

namespace viscoscope::sim {

// τ = τ_y + K γ̇ⁿ above the yield stress, the liquid at rest below it.
struct YieldingPowerLaw {
    double yieldStress = 0, consistency = 1, index = 1;
};

class MaterialLaw {
public:
    explicit MaterialLaw(const Material& material) : material_(material) {}
    bool shearDependent() const { return !std::holds_alternative<Newtonian>(material_.model); }
    // Dynamic viscosity (Pa·s) at shear rate γ̇ = sqrt(2 D:D) (1/s).
    double viscosity(double shearRate) const;
    // The law as τ_y + K γ̇ⁿ without the caps on η a grid solve needs (a Newtonian liquid: 0, η, 1),
    // for a model that solves the flow analytically (the thin film); none for a Carreau liquid.
    std::optional<YieldingPowerLaw> yieldingPowerLaw() const;

private:
    Material material_;
};

// Sets the viscosity at every cell and edge of `problem` from `law` at that sample's own shear
// rate in `velocity`, and returns the RMS change of η over the liquid's samples relative to its
// RMS, which ends a Picard iteration (0 for a Newtonian law, whose η is `viscosity` everywhere).
// Samples without liquid keep `viscosity`, which no stress row reads.
double updateViscosity(const MaterialLaw& law, double viscosity, const StokesProblem& problem,
                       const std::array<Field, 3>& velocity, Field& cellViscosity,
                       std::array<Field, 3>& edgeViscosity);

}  // namespace viscoscope::sim
