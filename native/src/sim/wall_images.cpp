#include "sim/wall_images.h"

#include "sim/solid_field.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>

namespace viscoscope::sim {

namespace {
// How much thinner (cells) than its particle's distance the solid behind a wall image may be: mesh
// solids' distances are interpolated voxel samples, not exact.
constexpr double kImageDepthTolerance = 0.1;
}  // namespace

// An image d deep (d being its particle's distance from the wall) is kept only if the wall is solid
// a further d all round the point d beyond it, so that no image shows liquid on a thin wall's far
// side: a drop hanging from the cup's hole otherwise bent onto false liquid mirrored down to the
// bottom's underside, and its surface tension spread the drop's base and held it up. The price is
// at a thin wall's contact line, whose deeper images go too, and parasitic currents there are
// faster. Checking the image's own depth instead dropped the images in a box's corners; this keeps
// them (tests/bench/FINDINGS.md, "Wall images").
std::vector<Vec3> wallImages(const std::vector<Vec3>& particles, const SolidField& solids, const Grid& grid,
                             const std::vector<double>& cellSolidDistance, double reach) {
    const double dx = grid.dx;
    std::vector<Vec3> images(particles.size(), Vec3::Constant(std::numeric_limits<double>::quiet_NaN()));
    tbb::parallel_for(size_t(0), particles.size(), [&](size_t p) {
        const Vec3& x = particles[p];
        if (!x.allFinite()) return;
        if (surelyClearOfSolids(grid, cellSolidDistance, x, reach)) return;
        const double d = solids.distance(x);
        if (d >= reach) return;
        const Vec3 n = solids.normal(x);
        const Vec3 image = x - 2 * d * n;
        if (solids.distance(image) < 0 && -solids.distance(x - 3 * d * n) >= d - kImageDepthTolerance * dx)
            images[p] = image;
    });
    images.erase(std::remove_if(images.begin(), images.end(), [](const Vec3& v) { return !v.allFinite(); }),
                 images.end());
    return images;
}

}  // namespace viscoscope::sim
