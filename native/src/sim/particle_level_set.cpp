// particleLevelSet (declared in sim.h): the union of spheres around particles as a narrow-band
// OpenVDB level set, renormalized and smoothed.
#include "sim/sim.h"

#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Filter.h>
#include <openvdb/tools/LevelSetTracker.h>
#include <openvdb/tools/Prune.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace viscoscope::sim {

namespace {
// The union of equal spheres as tools::ParticlesToLevelSet::rasterizeSpheres writes it: each voxel
// within R + w voxels of a centre holds dx (min |c − P| − R) in float, every other voxel stays
// inactive at the background w dx. Written by hand because ParticlesToLevelSet probes and sets the
// tree for each of a sphere's voxels and merges one tree per thread. With equal radii the union is
// the nearest centre's sphere, so a dense box keeps the least squared distance in a contiguous
// z-run per (i, j) and takes one square root per voxel at the end; copyFromDense then builds the
// tree. Slabs of z run in parallel, each with the particles that reach it, so no two threads write
// one voxel and the result is the same at any thread count.
openvdb::FloatGrid::Ptr rasterizeSpheres(const std::vector<Vec3>& positions, double radius, double halfWidth,
                                         const openvdb::math::Transform::Ptr& transform) {
    auto grid = openvdb::createLevelSet<openvdb::FloatGrid>(transform->voxelSize()[0], halfWidth);
    grid->setTransform(transform);
    if (positions.empty()) return grid;
    const double dx = transform->voxelSize()[0];
    const double r = radius / dx, reach = r + halfWidth;
    const float reach2 = static_cast<float>(reach * reach);
    std::vector<openvdb::Vec3d> centres(positions.size());
    openvdb::Vec3d lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (size_t p = 0; p < positions.size(); ++p) {
        centres[p] = transform->worldToIndex(openvdb::Vec3d(positions[p].x(), positions[p].y(), positions[p].z()));
        lo = openvdb::math::minComponent(lo, centres[p]);
        hi = openvdb::math::maxComponent(hi, centres[p]);
    }
    const openvdb::Coord first(openvdb::Coord::floor(lo - openvdb::Vec3d(reach)));
    const openvdb::Coord last(openvdb::Coord::ceil(hi + openvdb::Vec3d(reach)));
    openvdb::tools::Dense<float> dense(openvdb::CoordBBox(first, last), reach2);  // squared distances first
    const openvdb::Coord size = dense.bbox().dim();
    constexpr int kSlab = 8;
    const int slabs = (size.z() + kSlab - 1) / kSlab;
    std::vector<std::vector<size_t>> reaching(slabs);
    for (size_t p = 0; p < centres.size(); ++p) {
        const int z0 = static_cast<int>(std::floor(centres[p].z() - reach)) - first.z();
        const int z1 = static_cast<int>(std::ceil(centres[p].z() + reach)) - first.z();
        for (int slab = std::max(z0, 0) / kSlab; slab <= std::min(z1, size.z() - 1) / kSlab; ++slab) reaching[slab].push_back(p);
    }
    float* values = dense.data();
    const float background = grid->background();
    tbb::parallel_for(0, slabs, [&](int slab) {
        const int zLo = first.z() + slab * kSlab, zHi = std::min(zLo + kSlab - 1, last.z());
        for (const size_t p : reaching[slab]) {
            const openvdb::Vec3d& c = centres[p];
            const openvdb::Coord from = openvdb::Coord::floor(c - openvdb::Vec3d(reach));
            const openvdb::Coord to = openvdb::Coord::ceil(c + openvdb::Vec3d(reach));
            const int kFrom = std::max(from.z(), zLo), kTo = std::min(to.z(), zHi);
            for (int i = from.x(); i <= to.x(); ++i) {
                const float x2 = static_cast<float>((i - c.x()) * (i - c.x()));
                for (int j = from.y(); j <= to.y(); ++j) {
                    const float x2y2 = x2 + static_cast<float>((j - c.y()) * (j - c.y()));
                    float* run = values + dense.coordToOffset(openvdb::Coord(i, j, kFrom));
                    for (int k = kFrom; k <= kTo; ++k, ++run) {
                        const float dz = static_cast<float>(k - c.z());
                        *run = std::min(*run, x2y2 + dz * dz);
                    }
                }
            }
        }
        // This slab's squared distances become the signed distance, or the background beyond the band.
        for (int i = first.x(); i <= last.x(); ++i) {
            for (int j = first.y(); j <= last.y(); ++j) {
                float* run = values + dense.coordToOffset(openvdb::Coord(i, j, zLo));
                for (int k = zLo; k <= zHi; ++k, ++run)
                    *run = *run < reach2 ? static_cast<float>(dx * (std::sqrt(double(*run)) - r)) : background;
            }
        }
    });
    openvdb::tools::copyFromDense(dense, *grid, 0.0f);  // voxels left at the background stay off
    openvdb::tools::pruneLevelSet(grid->tree());
    return grid;
}
}  // namespace

openvdb::FloatGrid::Ptr particleLevelSet(const std::vector<Vec3>& positions, double radius, double voxelSize,
                                         const Vec3& origin, int smoothingPasses, double halfWidth) {
    openvdb::initialize();
    auto transform = openvdb::math::Transform::createLinearTransform(voxelSize);
    const Vec3 offset = origin + Vec3::Constant(0.5 * voxelSize);
    transform->postTranslate(openvdb::Vec3d(offset.x(), offset.y(), offset.z()));
    auto grid = rasterizeSpheres(positions, radius, halfWidth, transform);
    grid->setName("surface");
    openvdb::tools::LevelSetTracker<openvdb::FloatGrid> tracker(*grid);
    tracker.track();  // a union of spheres is no distance inside
    if (smoothingPasses > 0) {
        // Renormalized once after the plain Gaussian passes: LevelSetFilter renormalizes after each
        // of a pass's four box filters, which costs more for the same drop pressure
        // (tests/bench/FINDINGS.md, "Surface tension's curvature").
        openvdb::tools::Filter<openvdb::FloatGrid>(*grid).gaussian(1, smoothingPasses);
        tracker.track();
    }
    return grid;
}

}  // namespace viscoscope::sim
