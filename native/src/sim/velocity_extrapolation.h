// Velocity beyond the liquid: the faces next to it that neither the particles nor the solve set
// take the mean of their valid neighbours, layer by layer, so that particles near the surface and
// the solve's stencils read a continued flow rather than zeros.
#pragma once

#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <array>
#include <vector>

namespace viscoscope::sim {

// How far (cells) beyond the active box velocities are extrapolated, and so need body forces.
inline constexpr int kActiveMargin = 3;

// Fills `layers` layers of faces around the `valid` ones (within `layers` cells of `active`, solid
// faces excepted) and marks them valid. The same at any thread count.
void extrapolateVelocity(std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& valid,
                         const VolumeFractions& fractions, const CellBox& active, int layers);

// After the solve: its faces (those beside a cell holding liquid) become valid too, and solid
// faces are put back at rest.
void markSolvedFaces(std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& valid,
                     const VolumeFractions& fractions, const CellBox& active);

}  // namespace viscoscope::sim
