// Particle advection through the grid's velocity: Ralston's third-order Runge–Kutta, then out of
// the solids, and round the periodic axes.
#pragma once

#include "sim/grid_velocity.h"
#include "sim/sim.h"

#include <vector>

namespace viscoscope::sim {

// Particles are kept this far (in cells) outside solids, after seeding and after advection.
inline constexpr double kSolidMargin = 0.05;

// Moves every particle by dt through `velocity`. A particle that ends within kSolidMargin of a
// solid is pushed out along the solid's normal, and loses its velocity into it.
// `cellSolidDistance` holds the solids' distance at each cell centre (see surelyClearOfSolids).
void advectParticles(Particles& particles, const GridVelocity& velocity, double dt, const SolidField& solids,
                     const Grid& grid, const std::vector<double>& cellSolidDistance);

}  // namespace viscoscope::sim
