#include "sim/body_forces.h"

#include "sim/velocity_extrapolation.h"

namespace viscoscope::sim {

void addGravity(std::array<Field, 3>& velocity, const VolumeFractions& fractions, const CellBox& active,
                const Vec3& gravity, double dt) {
    for (int a = 0; a < 3; ++a) {
        Field& u = velocity[a];
        forEachNearBox(u.lattice, active, kActiveMargin, [&](int f, const Vec3i&) {
            if (!fractions.solidFace[a][f]) u[f] += dt * gravity[a];
        });
    }
}

}  // namespace viscoscope::sim
