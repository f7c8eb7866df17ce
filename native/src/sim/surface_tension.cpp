#include "sim/surface_tension.h"

#include "sim/sim.h"

#include <openvdb/math/Operators.h>
#include <openvdb/tools/GridOperators.h>
#include <openvdb/tools/Interpolation.h>

#include <algorithm>
#include <cmath>

namespace viscoscope::sim {

namespace {
// The level set's sphere radius (cells) and Gaussian passes. Each pass moves a curved surface
// inwards (as curvature flow does), which reads too much pressure in a small drop; one pass reads
// the least (tests/bench/FINDINGS.md, "Surface tension's curvature").
constexpr double kSurfaceParticleRadius = 0.75;
constexpr int kCurvatureSmoothing = 1;
// Narrow-band half-width (voxels) of that level set: what its curvature stencil and smoothing need
// (the drop check reads the same pressure as with a wider band, and the spheres cost half as much).
constexpr double kCurvatureBandWidth = 1.5;
// C of the viscous-capillary time-step limit. Galusinski & Vigneaux fitted it to their solver; a
// drop at rest in zero gravity moved hardly faster with it than without, and less than at larger
// ones, so the small one is kept (tests/bench/FINDINGS.md, "Surface tension's curvature").
constexpr double kViscousCapillaryConstant = 0.2;
}  // namespace

double curvatureWallReach(double dx) { return (kSurfaceParticleRadius + kCurvatureBandWidth + 1) * dx; }

// Curvature differentiates twice, so it is taken on OpenVDB's smoothed particle level set rather
// than the kernel-averaged distance the fractions use, which gave parasitic currents several times
// larger in the hydrostatic test. Particles near a wall are mirrored into it, so that the surface
// meets the wall at a right angle (neutral wetting) instead of rounding off over it like a free
// edge: that false bend at every contact line drove the largest parasitic currents in a resting
// pool.
openvdb::FloatGrid::Ptr curvatureLevelSet(const std::vector<Vec3>& particlesAndImages, const Grid& grid) {
    return particleLevelSet(particlesAndImages, kSurfaceParticleRadius * grid.dx, grid.dx, grid.origin,
                            kCurvatureSmoothing, kCurvatureBandWidth);
}

void applySurfaceTension(const openvdb::FloatGrid& levelSet, double surfaceTension, double density, double dt,
                         const Grid& grid, const VolumeFractions& fractions, const CellBox& active,
                         Field& laplacePressure, std::array<Field, 3>& velocity) {
    std::fill(laplacePressure.values.begin(), laplacePressure.values.end(), 0.0);
    const double sigma = surfaceTension;
    const Lattice& cells = laplacePressure.lattice;
    const double dx = grid.dx;
    const auto curvature = openvdb::tools::meanCurvature(levelSet);
    const auto curvatureAccess = curvature->getConstAccessor();
    const auto distanceAccess = levelSet.getConstAccessor();
    const openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> curvatureAt(
        curvatureAccess, curvature->transform());
    forEachNearBox(cells, active, 1, [&](int c, const Vec3i& ijk) {
        if (fractions.cell[c] >= 1) return;
        bool nearLiquid = fractions.cell[c] >= kMinWeight;
        for (int a = 0; a < 3 && !nearLiquid; ++a)
            for (int d : {-1, 1})
                if (const int nb = cells.neighbour(ijk, a, d); nb >= 0 && fractions.cell[nb] >= kMinWeight) nearLiquid = true;
        if (!nearLiquid) return;
        // The jump belongs to the interface, not to the cell centre a fraction of a cell off it
        // (level sets around a drop of R cells curve as 1/(R + φ)), so the curvature is read at the
        // centre's closest point on the surface, x − φ ∇φ/|∇φ|: a drop's inside pressure then
        // agrees with 2σ/R, and parasitic currents are far weaker (tests/bench/FINDINGS.md,
        // "Surface tension's curvature").
        const openvdb::Coord v(ijk[0], ijk[1], ijk[2]);
        const openvdb::Vec3d normal = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(distanceAccess, v);
        const double phi = distanceAccess.getValue(v);
        openvdb::Vec3d index(ijk[0], ijk[1], ijk[2]);
        if (normal.length() > 1e-6 && std::abs(phi) < 2 * dx) index -= (phi / dx) * normal.unitSafe();
        // OpenVDB returns the mean curvature (κ1 + κ2)/2; the Laplace pressure needs κ1 + κ2.
        const double kappa = 2.0 * curvatureAt.isSample(index);
        laplacePressure[c] = (1 - fractions.cell[c]) * sigma * std::clamp(kappa, -2 / dx, 2 / dx);
    });
    for (int a = 0; a < 3; ++a) {
        Field& u = velocity[a];
        forEachNearBox(u.lattice, active, 1, [&](int f, const Vec3i& c) {
            if (fractions.solidFace[a][f]) return;
            const auto [lo, hi] = faceCells(cells, c, a);
            if (lo < 0 || hi < 0) return;
            if (fractions.cell[lo] < kMinWeight && fractions.cell[hi] < kMinWeight) return;
            const double mass = density * std::max(fractions.face[a][f], kMinMassFraction);
            u[f] -= dt * (laplacePressure[hi] - laplacePressure[lo]) / (dx * mass);
        });
    }
}

// Brackbill's limit takes the mean density of the two sides, ρ/2 at a free surface. The implicit
// viscosity damps the grid-scale capillary waves that set it, which Galusinski & Vigneaux fold in
// as ½(τ_η + √(τ_η² + 4 τ_c²)) with τ_η = C η̄ Δx / σ, η̄ the mean viscosity of the two sides (η/2
// against the air). At honey viscosities the capillary limit then no longer binds, and as η → 0
// it returns to Brackbill's.
double capillaryTimeStep(double density, double surfaceTension, double viscosity, double dx) {
    const double capillary = std::sqrt(density * dx * dx * dx / (4 * M_PI * surfaceTension));
    const double viscous = kViscousCapillaryConstant * 0.5 * viscosity * dx / surfaceTension;
    return 0.5 * (viscous + std::sqrt(viscous * viscous + 4 * capillary * capillary));
}

}  // namespace viscoscope::sim
