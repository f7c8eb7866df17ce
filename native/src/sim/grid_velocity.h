// The grid's velocity as the particles read it: trilinear on each face lattice and, beyond the
// domain's walls, the walls' ghosts under the Navier slip condition (wallGhostRatio in
// stokes_solver.h), so that particles by a wall move as the solve's wall rows say.
#pragma once

#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <array>

namespace viscoscope::sim {

class SolidField;

// A view of the fields it is built on: they must outlive it.
class GridVelocity {
public:
    GridVelocity(const Grid& grid, const std::array<Field, 3>& velocity, const VolumeFractions& fractions,
                 const SolidField& solids, double slipLength)
        : grid_(grid), velocity_(velocity), fractions_(fractions), solids_(solids), slipLength_(slipLength) {}

    // Component `axis` at x and, when `gradient` is given, its gradient there.
    double component(int axis, const Vec3& x, Vec3* gradient) const;
    Vec3 operator()(const Vec3& x) const {
        return {component(0, x, nullptr), component(1, x, nullptr), component(2, x, nullptr)};
    }

private:
    template <bool kGradient>
    double interpolate(int axis, const Vec3& x, Vec3* gradient) const;

    const Grid& grid_;
    const std::array<Field, 3>& velocity_;
    const VolumeFractions& fractions_;
    const SolidField& solids_;
    double slipLength_;
};

}  // namespace viscoscope::sim
