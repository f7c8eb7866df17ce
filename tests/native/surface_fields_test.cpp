// Comparing hidden fields (surface::compareFields): a field against itself gives 0, against a scaled
// copy on a grid of another resolution and offset the scale error, and only points inside both
// surfaces count. Linear fields make the expected values exact: trilinear sampling reproduces them.
#include "surface/surface.h"

#include <gtest/gtest.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>

using namespace viscoscope;

namespace {

openvdb::Vec3f velocityAt(const openvdb::Vec3d& x) { return openvdb::Vec3f(1 + x.x(), 2 * x.y(), 0.5 - 3 * x.z()); }
float pressureAt(const openvdb::Vec3d& x) { return static_cast<float>(1000 * (0.1 - x.z()) + 5 * x.x()); }

// A liquid ball of `radius` at the origin; velocity and pressure (scaled) on a cell-centred grid of
// spacing h, active over the cube |x|∞ ≤ `extent`.
surface::FrameFields fields(double radius, double h, double extent, double velocityScale, double pressureScale) {
    openvdb::initialize();
    surface::FrameFields f;
    f.surface = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, openvdb::Vec3f(0), 0.004f);
    auto transform = openvdb::math::Transform::createLinearTransform(h);
    transform->postTranslate(openvdb::Vec3d(0.5 * h));
    f.velocity = openvdb::Vec3fGrid::create();
    f.pressure = openvdb::FloatGrid::create();
    f.velocity->setTransform(transform);
    f.pressure->setTransform(transform);
    const int n = static_cast<int>(std::ceil(extent / h));
    for (int i = -n; i <= n; ++i)
        for (int j = -n; j <= n; ++j)
            for (int k = -n; k <= n; ++k) {
                const openvdb::Coord ijk(i, j, k);
                const openvdb::Vec3d x = transform->indexToWorld(ijk);
                f.velocity->tree().setValue(ijk, velocityAt(x) * static_cast<float>(velocityScale));
                f.pressure->tree().setValue(ijk, pressureAt(x) * static_cast<float>(pressureScale));
            }
    return f;
}

long voxelsWithin(const surface::FrameFields& f, double radius) {
    long count = 0;
    for (auto voxel = f.velocity->cbeginValueOn(); voxel; ++voxel)
        if (f.velocity->indexToWorld(voxel.getCoord()).length() < radius) ++count;
    return count;
}

}  // namespace

TEST(FieldComparison, ItselfGivesZeroAndAScaledCopyItsScale) {
    const surface::FrameFields reference = fields(0.05, 0.01, 0.06, 1, 1);
    const surface::FieldDifference self = surface::compareFields(reference, reference);
    EXPECT_GT(self.samples, 300);
    EXPECT_GE(self.samples, voxelsWithin(reference, 0.05 - 0.004));
    EXPECT_LE(self.samples, voxelsWithin(reference, 0.05 + 0.004));
    EXPECT_EQ(self.relativeVelocityError(), 0);
    EXPECT_EQ(self.relativePressureError(), 0);

    // Another resolution and cell offset, covering more than the ball so every stencil is full.
    const surface::FrameFields scaled = fields(0.05, 0.007, 0.08, 1.1, 0.7);
    const surface::FieldDifference d = surface::compareFields(reference, scaled);
    std::printf("[ figures  ] scaled copy on a 7 mm grid: eps_v %.7f (0.1), eps_p %.7f (0.3), %ld samples\n",
                d.relativeVelocityError(), d.relativePressureError(), d.samples);
    EXPECT_EQ(d.samples, self.samples);
    EXPECT_NEAR(d.relativeVelocityError(), 0.1, 1e-5);
    EXPECT_NEAR(d.relativePressureError(), 0.3, 1e-5);

    // Sums over frames pool: two identical frames give the same relative error.
    surface::FieldDifference twice = d;
    twice += d;
    EXPECT_EQ(twice.samples, 2 * d.samples);
    EXPECT_NEAR(twice.relativeVelocityError(), d.relativeVelocityError(), 1e-12);
}

TEST(FieldComparison, OnlyPointsInsideBothSurfacesCountAndZeroReferencesAreNaN) {
    const surface::FrameFields reference = fields(0.05, 0.01, 0.06, 1, 1);
    const surface::FrameFields smaller = fields(0.03, 0.01, 0.06, 1, 1);
    const surface::FieldDifference d = surface::compareFields(reference, smaller);
    EXPECT_GE(d.samples, voxelsWithin(reference, 0.03 - 0.004));
    EXPECT_LE(d.samples, voxelsWithin(reference, 0.03 + 0.004));
    EXPECT_EQ(d.relativeVelocityError(), 0);

    const surface::FrameFields atRest = fields(0.05, 0.01, 0.06, 0, 0);
    const surface::FieldDifference rest = surface::compareFields(atRest, reference);
    EXPECT_GT(rest.samples, 0);
    EXPECT_TRUE(std::isnan(rest.relativeVelocityError()));
    EXPECT_TRUE(std::isnan(rest.relativePressureError()));
}

TEST(FieldComparison, ReadsFramesBackAndNamesMissingGrids) {
    const auto dir = std::filesystem::temp_directory_path() / ("viscoscope_fields_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir);
    surface::FrameFields f = fields(0.05, 0.01, 0.06, 1, 1);
    f.surface->setName("surface");
    f.velocity->setName("velocity");
    f.pressure->setName("pressure");
    openvdb::io::File((dir / "frame.vdb").string()).write(openvdb::GridPtrVec{f.surface, f.velocity, f.pressure});
    const surface::FrameFields back = surface::readFrameFields(dir / "frame.vdb");
    EXPECT_EQ(surface::compareFields(f, back).relativePressureError(), 0);

    openvdb::io::File((dir / "no_pressure.vdb").string()).write(openvdb::GridPtrVec{f.surface, f.velocity});
    try {
        surface::readFrameFields(dir / "no_pressure.vdb");
        FAIL() << "a frame without pressure was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no_pressure.vdb: no grid \"pressure\""), std::string::npos) << e.what();
    }
    EXPECT_THROW(surface::readFrameFields(dir / "missing.vdb"), InputError);
    std::filesystem::remove_all(dir);
}
