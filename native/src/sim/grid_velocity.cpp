#include "sim/grid_velocity.h"

#include "sim/solid_field.h"

namespace viscoscope::sim {

// A sample beyond the domain's boundary is the wall ghost of the boundary sample it clamps to,
// against whatever solid lies there. A ground on the domain's floor then holds particles in the
// half cell above it to the solve's no-slip profile, whose mean over the face's cell is the face
// velocity; the clamped constant let them slip, and a spreading current ran ahead of its liquid.
// Solid faces inside the domain keep their zero: ghosts there as well (least-squares through the
// liquid neighbours) carried less than the face fluxes through the sample cup's hole
// (tests/bench/FINDINGS.md, "Particles beyond the domain's walls").
double GridVelocity::component(int axis, const Vec3& x, Vec3* gradient) const {
    // Two instances, so that interpolating without the gradient computes none.
    return gradient ? interpolate<true>(axis, x, gradient) : interpolate<false>(axis, x, nullptr);
}

template <bool kGradient>
double GridVelocity::interpolate(int a, const Vec3& x, Vec3* gradient) const {
    const Field& u = velocity_[a];
    double value = 0;
    if constexpr (kGradient) gradient->setZero();
    forEachStencilSampleBeyond(grid_, u.lattice, x, [&](int f, double w, const Vec3& dw, const Vec3i* beyond) {
        double sample = u[f];
        if (beyond && !fractions_.solidFace[a][f])
            sample *= wallGhostRatio(solids_.distance(grid_.position(kFace[a], u.lattice.coords(f))),
                                     solids_.distance(grid_.position(kFace[a], *beyond)), slipLength_, grid_.dx);
        value += w * sample;
        if constexpr (kGradient) *gradient += dw * sample;
    });
    return value;
}

}  // namespace viscoscope::sim
