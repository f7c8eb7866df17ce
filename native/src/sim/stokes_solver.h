// The implicit pressure–viscosity step on the MAC grid, in two schemes behind one interface:
// - StokesSolver: Larionov, Batty & Bridson 2017, "Variational Stokes": pressure and stress solved
//   together in one SPD system after eliminating velocity.
// - DecoupledViscositySolver: Batty & Bridson 2008 variational viscosity, then a separate pressure
//   projection. Kept as the baseline the unified scheme is compared against.
//
// Discretization (both schemes): minimize ½|u − u*|²_M + ½Δt |u|²_B + Δt Σ η |D u|²_W subject to
// W_p ∇·(A u) = 0, where M = ρ W_u, A holds the faces' open (non-solid) area fractions and B the
// faces' subgrid drag (VolumeFractions::faceResistance; the decoupled scheme applies it in its
// projection). Every weight W is a liquid-and-non-solid volume fraction of the sample's control
// volume, all taken from one sub-cell sampling (see VolumeFractions), so they agree with each other.
#pragma once

#include "sim/grid.h"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <functional>
#include <memory>
#include <vector>

namespace viscoscope::sim {

// Volume fractions of every control volume, from one shared sub-cell sampling.
struct VolumeFractions {
    Field cell;                   // pressure and τ_aa samples
    std::array<Field, 3> face;    // velocity samples (mass)
    std::array<Field, 3> edge;    // τ_ab samples, indexed by the edge's axis
    std::array<std::vector<char>, 3> solidFace;  // velocity fixed to the solid's (zero) velocity
    // Non-solid fraction of each face's area: the face's flux in the divergence is A_f u_f Δx², as in
    // Batty, Bertails & Bridson 2007. A binary open/closed face would quantize an aperture (the
    // cup's hole) to whole faces, and the drain rate through it with it.
    std::array<Field, 3> faceOpenArea;
    // A face's subgrid resistance per unit viscosity, 1/m² (empty: none): its velocity feels a drag
    // β = η R per unit volume, η being the mean of the two cells' viscosity. The calibrated cup hole
    // sets it (see HoleCalibration in sim.h).
    std::array<Field, 3> faceResistance;
};

struct StokesProblem {
    const Grid* grid = nullptr;
    const VolumeFractions* weights = nullptr;
    double dt = 0;
    double density = 1;
    const Field* cellViscosity = nullptr;                 // η at cell centres
    const std::array<Field, 3>* edgeViscosity = nullptr;  // η at edges
    double slipLength = 0;                                // Navier slip at walls, m
    double divergence = 0;  // target ∇·u in every liquid cell, 1/s (0: incompressible; volume correction)
    std::function<double(const Vec3&)> solidDistance;     // signed, negative inside solids
    double tolerance = 1e-4;
    int maxIterations = 2000;
};

// The unknowns that persist between steps, so each solve starts from the last one's answer.
struct StokesState {
    std::array<Field, 3> velocity;  // in: u* (after body forces); out: the new velocity
    Field pressure;                 // Pa, the solve's unknown (the liquid's share of a cut cell's is W × it)
    Field normalStress[3];          // τ_xx, τ_yy, τ_zz at cells
    std::array<Field, 3> shearStress;  // τ_yz, τ_xz, τ_xy on x-, y-, z-edges
};

struct SolveStats {
    int iterations = 0;        // total CG iterations over all sub-solves
    double residual = 0;       // final relative residual (worst sub-solve)
    int unknowns = 0;          // rows of the largest system
    bool converged = true;
};

class PressureViscositySolver {
public:
    virtual ~PressureViscositySolver() = default;
    virtual SolveStats solve(const StokesProblem& problem, StokesState& state) = 0;
};

class StokesSolver final : public PressureViscositySolver {  // Larionov, Batty & Bridson 2017
public:
    SolveStats solve(const StokesProblem& problem, StokesState& state) override;
};

class DecoupledViscositySolver final : public PressureViscositySolver {  // Batty & Bridson 2008
public:
    SolveStats solve(const StokesProblem& problem, StokesState& state) override;
};

std::unique_ptr<PressureViscositySolver> makeSolver(bool unified);

// The shear rate √(2 D:D) at the stress samples, from the same velocity differences the stress rows
// use (wall ghost values included), so that a material law sees the strain the solver discretizes.
// At a cell centre D_aa comes from the cell's own difference and D_ab as the mean over the four
// edges around it; at an edge its own D_ab from the edge's difference and the other components as
// the mean over the cells around it. Each sample keeps the component it resolves: a yielded layer
// thinner than a cell (a yield-stress liquid near arrest, against its bed) shears at the bed's edges
// and hardly at the cell centres above, and averaged into the cells its rate was halved.
// Samples without liquid (no stress row) get 0.
struct ShearRates {
    Field cell;
    std::array<Field, 3> edge;
};
ShearRates shearRates(const StokesProblem& problem, const std::array<Field, 3>& velocity);

// The ghost value of a velocity sample inside a wall, as a multiple of the liquid sample beside it:
// the linear profile through the Navier slip condition u = λ ∂u/∂n at the wall (λ = 0: no-slip),
// from the two samples' signed distances to the solid (positive outside). This puts the wall
// condition where the wall really is, not at the solid sample. The solve's stress rows use it, and
// so does the particles' velocity interpolation beyond the domain's boundary.
// The liquid sample's distance is floored at 0.1 cell, which moves the wall below a closer sample
// and lets it slip (a slump spreads wider on a ground just below the lowest faces' centres); a
// smaller floor let a thin liquid's step go non-finite, so the floor stays (tests/bench/FINDINGS.md,
// "The Stokes solve's walls").
inline double wallGhostRatio(double liquidDistance, double ghostDistance, double slipLength, double dx) {
    const double liquid = std::max(liquidDistance, 0.1 * dx), ghost = std::min(ghostDistance, 0.0);
    return (ghost + slipLength) / (liquid + slipLength);
}

// Weight below which a control volume holds no liquid and its sample is not an unknown.
inline constexpr double kMinWeight = 1e-3;
// Velocity masses are clamped to this fraction of a full cell: a face whose control volume is almost
// empty would otherwise make the eliminated system arbitrarily stiff. The clamp is mass the liquid
// does not have, on the faces at and beyond the surface that stress rows touch (and in the surface
// tension's impulse), and it holds thin liquid back where viscosity couples those faces weakly.
// This clamp lets the sample cup's puddle at 48³ reach as far as smaller ones and as 96³, for
// somewhat more CG iterations (tests/bench/FINDINGS.md, "The Stokes solve's walls").
inline constexpr double kMinMassFraction = 0.002;

}  // namespace viscoscope::sim
