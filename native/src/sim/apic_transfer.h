// APIC transfers between the particles and the MAC grid's faces (Jiang et al. 2015, "The affine
// particle-in-cell method"), with trilinear weights on each face lattice.
#pragma once

#include "sim/grid_velocity.h"
#include "sim/sim.h"

#include <array>
#include <vector>

namespace viscoscope::sim {

// Particles → faces: each face's weighted mean of its particles' affine velocities. `validFace`
// marks the faces that got weight and are not shut by a solid; every other face is 0. The same at
// any thread count.
void particlesToGrid(const Particles& particles, const Grid& grid, const VolumeFractions& fractions,
                     std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& validFace);

// Faces → particles: each particle's velocity and affine matrix C_p (from the weight gradients).
void gridToParticles(const GridVelocity& velocity, Particles& particles);

}  // namespace viscoscope::sim
