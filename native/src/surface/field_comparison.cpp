// Reading frame_NNNNN.vdb back and comparing two simulations' hidden fields (surface.h).
#include "surface/surface.h"

#include <openvdb/tools/Interpolation.h>

#include <cmath>
#include <limits>

namespace viscoscope::surface {

namespace {

template <typename GridType>
typename GridType::Ptr readGrid(openvdb::io::File& file, const std::string& name, const std::filesystem::path& path) {
    if (!file.hasGrid(name)) throw InputError(path.string() + ": no grid \"" + name + "\"");
    auto grid = openvdb::gridPtrCast<GridType>(file.readGrid(name));
    if (!grid) throw InputError(path.string() + ": grid \"" + name + "\" has the wrong value type");
    return grid;
}

// Is every voxel of the 3×3×3 block around `ijk` active? Only such cells are inside the liquid,
// away from the cut cells at walls and the free surface, whose values stand for a partial volume
// and cannot be compared pointwise between grids of different resolution.
template <typename Accessor>
bool interior(const Accessor& active, const openvdb::Coord& ijk) {
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx)
                if (!active.isValueOn(ijk.offsetBy(dx, dy, dz))) return false;
    return true;
}

// Are all eight voxels a trilinear sample at world position x reads active (written)?
template <typename GridType>
bool stencilWritten(const GridType& grid, typename GridType::ConstAccessor& access, const openvdb::Vec3d& x) {
    const openvdb::Vec3d index = grid.worldToIndex(x);
    const openvdb::Coord base(openvdb::Coord::floor(index));
    for (int dz = 0; dz <= 1; ++dz)
        for (int dy = 0; dy <= 1; ++dy)
            for (int dx = 0; dx <= 1; ++dx)
                if (!access.isValueOn(base.offsetBy(dx, dy, dz))) return false;
    return true;
}

double ratio(double error2, double norm2) {
    return norm2 > 0 ? std::sqrt(error2 / norm2) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

FrameFields readFrameFields(const std::filesystem::path& path) {
    openvdb::initialize();
    try {
        openvdb::io::File file(path.string());
        file.open();
        FrameFields fields;
        fields.surface = readGrid<openvdb::FloatGrid>(file, "surface", path);
        fields.velocity = readGrid<openvdb::Vec3fGrid>(file, "velocity", path);
        fields.pressure = readGrid<openvdb::FloatGrid>(file, "pressure", path);
        return fields;
    } catch (const openvdb::Exception& e) {
        throw InputError(path.string() + ": not a readable .vdb (" + std::string(e.what()) + ")");
    }
}

FieldDifference& FieldDifference::operator+=(const FieldDifference& o) {
    samples += o.samples;
    velocityError2 += o.velocityError2;
    velocityNorm2 += o.velocityNorm2;
    pressureError2 += o.pressureError2;
    pressureNorm2 += o.pressureNorm2;
    return *this;
}

double FieldDifference::relativeVelocityError() const { return ratio(velocityError2, velocityNorm2); }
double FieldDifference::relativePressureError() const { return ratio(pressureError2, pressureNorm2); }

FieldDifference compareFields(const FrameFields& reference, const FrameFields& simulation) {
    using openvdb::tools::BoxSampler;
    using FloatSampler = openvdb::tools::GridSampler<openvdb::FloatGrid, BoxSampler>;
    const FloatSampler referenceSurface(*reference.surface), referencePressure(*reference.pressure),
        simulationSurface(*simulation.surface), simulationPressure(*simulation.pressure);
    const openvdb::tools::GridSampler<openvdb::Vec3fGrid, BoxSampler> simulationVelocity(*simulation.velocity);
    auto referenceActive = reference.velocity->getConstAccessor();
    auto simulationActive = simulation.velocity->getConstAccessor();
    FieldDifference d;
    for (auto voxel = reference.velocity->cbeginValueOn(); voxel; ++voxel) {
        if (!voxel.isVoxelValue()) continue;
        const openvdb::Vec3d x = reference.velocity->indexToWorld(voxel.getCoord());
        if (!(referenceSurface.wsSample(x) < 0 && simulationSurface.wsSample(x) < 0)) continue;
        if (!interior(referenceActive, voxel.getCoord()) || !stencilWritten(*simulation.velocity, simulationActive, x))
            continue;
        // x is a voxel centre of the reference's grids, so sampling them there reads the stored value.
        const openvdb::Vec3d v = *voxel;
        const double p = referencePressure.wsSample(x);
        const openvdb::Vec3d dv = openvdb::Vec3d(simulationVelocity.wsSample(x)) - v;
        const double dp = simulationPressure.wsSample(x) - p;
        ++d.samples;
        d.velocityError2 += dv.lengthSqr();
        d.velocityNorm2 += v.lengthSqr();
        d.pressureError2 += dp * dp;
        d.pressureNorm2 += p * p;
    }
    return d;
}

}  // namespace viscoscope::surface
