#include "sim/apic_transfer.h"

#include <tbb/parallel_for.h>

#include <algorithm>

namespace viscoscope::sim {

// The three lattices are independent, so each is one task; within one, particles add in order.
void particlesToGrid(const Particles& particles, const Grid& grid, const VolumeFractions& fractions,
                     std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& validFace) {
    const size_t n = particles.position.size();
    tbb::parallel_for(0, 3, [&](int a) {
        Field& u = velocity[a];
        std::vector<double> weight(u.values.size(), 0.0);
        std::fill(u.values.begin(), u.values.end(), 0.0);
        for (size_t p = 0; p < n; ++p) {
            const Vec3& x = particles.position[p];
            const double vp = particles.velocity[p][a];
            const Eigen::RowVector3d cp = particles.affine[p].row(a);
            forEachStencilSample(grid, u.lattice, x, [&](int f, double w, const Vec3&) {
                const Vec3 offset = grid.nearestImage(grid.position(kFace[a], u.lattice.coords(f)) - x);
                u[f] += w * (vp + cp * offset);
                weight[f] += w;
            });
        }
        for (size_t f = 0; f < weight.size(); ++f) {
            validFace[a][f] = weight[f] > 1e-12 && !fractions.solidFace[a][f];
            u[f] = validFace[a][f] ? u[f] / weight[f] : 0.0;
        }
    });
}

void gridToParticles(const GridVelocity& velocity, Particles& particles) {
    const size_t n = particles.position.size();
    tbb::parallel_for(size_t(0), n, [&](size_t p) {
        const Vec3& x = particles.position[p];
        for (int a = 0; a < 3; ++a) {
            Vec3 gradient;
            particles.velocity[p][a] = velocity.component(a, x, &gradient);
            particles.affine[p].row(a) = gradient.transpose();
        }
    });
}

}  // namespace viscoscope::sim
