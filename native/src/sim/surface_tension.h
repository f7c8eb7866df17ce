// Surface tension by the ghost-fluid method at the free surface (after Fedkiw et al. 1999, in
// volume-fraction form): outside the liquid the pressure is the Laplace pressure σκ, so a face sees
// W p + (1 − W) σκ, and the known part (1 − W) σκ acts as a force before the solve. Only faces the
// interface crosses feel it, with κ taken where it crosses.
#pragma once

#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <openvdb/openvdb.h>

#include <array>
#include <vector>

namespace viscoscope::sim {

// How far from a wall (m) particles are mirrored into it (wallImages) for curvatureLevelSet.
double curvatureWallReach(double dx);

// The level set κ is taken from: spheres around the particles and their wall images, as
// cell-aligned voxels (negative in the liquid), renormalized and smoothed (particleLevelSet).
openvdb::FloatGrid::Ptr curvatureLevelSet(const std::vector<Vec3>& particlesAndImages, const Grid& grid);

// Sets `laplacePressure` to (1 − W) σκ at the cells by the surface around `active` (0 elsewhere),
// κ from `levelSet` (curvatureLevelSet), and takes its gradient's impulse over dt from the open
// faces beside liquid, per unit of their mass ρ W (clamped at kMinMassFraction).
void applySurfaceTension(const openvdb::FloatGrid& levelSet, double surfaceTension, double density, double dt,
                         const Grid& grid, const VolumeFractions& fractions, const CellBox& active,
                         Field& laplacePressure, std::array<Field, 3>& velocity);

// The longest step at which capillary waves stay stable: Brackbill, Kothe & Zemach 1992's limit,
// with the implicit viscosity's damping folded in as Galusinski & Vigneaux 2008 do. `viscosity`
// is the least in the liquid.
double capillaryTimeStep(double density, double surfaceTension, double viscosity, double dx);

}  // namespace viscoscope::sim
