// The liquid as if it went on through the walls: mirror images of the particles near a solid,
// which the liquid's distance (volume_fractions.h) and the curvature's level set
// (surface_tension.h) count beside the particles.
#pragma once

#include "sim/grid.h"

#include <vector>

namespace viscoscope::sim {

class SolidField;

// The mirror images, across the nearest wall, of the particles within `reach` (m) of a solid, in
// particle order whatever the thread count. `cellSolidDistance` holds the solids' distance at each
// cell centre of `grid` (see surelyClearOfSolids). Non-finite positions have no image.
std::vector<Vec3> wallImages(const std::vector<Vec3>& particles, const SolidField& solids, const Grid& grid,
                             const std::vector<double>& cellSolidDistance, double reach);

}  // namespace viscoscope::sim
