#include "sim/advection.h"

#include "sim/solid_field.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace viscoscope::sim {

void advectParticles(Particles& particles, const GridVelocity& velocity, double dt, const SolidField& solids,
                     const Grid& grid, const std::vector<double>& cellSolidDistance) {
    const Vec3 lo = grid.origin, extent = grid.extent();
    tbb::parallel_for(size_t(0), particles.position.size(), [&](size_t p) {
        Vec3 x = particles.position[p];
        const Vec3 k1 = velocity(x);
        const Vec3 k2 = velocity(x + 0.5 * dt * k1);
        const Vec3 k3 = velocity(x + 0.75 * dt * k2);
        x += dt * (2.0 / 9.0 * k1 + 1.0 / 3.0 * k2 + 4.0 / 9.0 * k3);
        const double margin = kSolidMargin * grid.dx;
        const bool clear = surelyClearOfSolids(grid, cellSolidDistance, x, margin);
        bool pushedOut = false;
        for (int iter = 0; iter < 3 && !clear; ++iter) {
            const double d = solids.distance(x);
            if (d >= margin) break;
            x += (margin - d) * solids.normal(x);
            pushedOut = true;
        }
        // A particle pushed out of a solid stops moving into it. Liquid in the solve already does
        // (its solid faces are at rest), but a lone particle gives no cell a liquid fraction, so no
        // solve holds its faces and it took gravity's Δt g back from them every step: a drop that
        // dripped from the sample cup then lay on the ground at a fall's speed, and the CFL limit
        // on it made frames many times slower (tests/bench/FINDINGS.md, "Particles beyond the
        // domain's walls").
        if (pushedOut) {
            const Vec3 n = solids.normal(x);
            Vec3& v = particles.velocity[p];
            v -= std::min(v.dot(n), 0.0) * n;
        }
        for (int a = 0; a < 3; ++a)
            if (grid.periodic[a]) x[a] = lo[a] + std::fmod(std::fmod(x[a] - lo[a], extent[a]) + extent[a], extent[a]);
        particles.position[p] = x;
    });
}

}  // namespace viscoscope::sim
