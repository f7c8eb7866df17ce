// Body forces on the grid's velocity before the solve.
#pragma once

#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <array>

namespace viscoscope::sim {

// u += Δt g on every open face within kActiveMargin cells of `active` (the faces the velocity is
// extrapolated to, so that all of them carry the same acceleration).
void addGravity(std::array<Field, 3>& velocity, const VolumeFractions& fractions, const CellBox& active,
                const Vec3& gravity, double dt);

}  // namespace viscoscope::sim
