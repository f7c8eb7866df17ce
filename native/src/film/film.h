// The thin-film (lubrication) forward model: an axisymmetric gravity current on a horizontal plane,
// fed by the scene's disc emitters at their common centre, for a Newtonian, power-law or
// Herschel–Bulkley liquid with Navier slip at the ground. It answers where the 3D solver is too dear:
// minutes of slow spreading in a film a few millimetres thick. The lubrication flux per unit
// circumference of a Herschel–Bulkley film of thickness h under the slope ∂h/∂r (Balmforth, Craster,
// Rust & Sassi 2006, J. Non-Newt. Fluid Mech. 139):
//   q = n/(n+1) (ρg|∂h/∂r|/K)^(1/n) Y^(1+1/n) (h − nY/(2n+1)) + ℓ h γ̇_base,  Y = h − τ_y/(ρg|∂h/∂r|),
// no flow where Y ≤ 0. Surface tension and inertia are left out (a film much thicker than the
// capillary length would need them at its front only). The models' η bounds (η_min, η_max) are the
// 3D solver's regularization and are not applied: the film's plug is exact.
#pragma once

#include "scene/scene.h"
#include "sim/material_model.h"

#include <functional>
#include <string>
#include <vector>

namespace viscoscope::film {

// Why `scene` cannot be simulated as an axisymmetric film (empty: it can): it needs a single ground
// plane for solid, gravity along −z, one or more disc emitters on the ground sharing one centre (the
// axis, also of a released current: setThickness) and a Newtonian, power-law or Herschel–Bulkley liquid.
std::string filmProblem(const Scene& scene);

// Thinner than this the ground counts as dry: the film lies on a precursor layer this thick, which
// keeps its front's degenerate flux finite and its Newton steps defined.
constexpr double kPrecursorThickness = 5e-6;  // m
// The front is where the film thins below this (20 precursor layers), interpolated between cells.
constexpr double kFrontThickness = 1e-4;  // m

class AxisymmetricFilm {
public:
    // Radial cells of the scene's cell size out to the nearest side of the domain from the emitters'
    // centre. Throws InputError with filmProblem's reason.
    explicit AxisymmetricFilm(const Scene& scene);
    // Sets the film's thickness to profile(r) at each cell's centre (no thinner than the precursor):
    // a current released from rest rather than fed.
    void setThickness(const std::function<double(double)>& profile);
    // Integrates (backward Euler, Newton, steps that adapt to the film's change) up to `time` (s).
    // Throws std::runtime_error if the step falls below 1 µs without converging.
    void advanceTo(double time);
    double time() const { return time_; }
    // Distance from the centre to the front (m); 0 before the film reaches kFrontThickness.
    double frontRadius() const;
    // Liquid volume above the precursor layer (m³).
    double volume() const;
    // Per radial cell: its centre (m) and the film's thickness there (m).
    std::vector<double> cellRadii() const;
    const std::vector<double>& thickness() const { return h_; }
    int steps() const { return steps_; }

private:
    // Volume flux through the cell face at radius `faceRadius` (outward positive, m³/s) and its
    // derivatives with respect to the thicknesses of the cells inside and outside it.
    struct FaceFlux {
        double flux, dInner, dOuter;
    };
    FaceFlux faceFlux(double faceRadius, double inner, double outer) const;
    bool step(double dt);  // false: Newton did not converge, the state is unchanged

    double dr_ = 0;
    std::vector<double> area_;  // of each annular cell (m²)
    std::vector<double> h_;
    double rhoG_ = 0, slipLength_ = 0;
    sim::YieldingPowerLaw law_;
    struct Emitter {
        double radius, flux, start, end;
    };
    std::vector<Emitter> emitters_;
    double time_ = 0, dt_ = 1e-3;
    int steps_ = 0;
};

}  // namespace viscoscope::film
