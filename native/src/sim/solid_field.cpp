#include "sim/solid_field.h"

#include "sim/sim.h"

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <sstream>

namespace viscoscope::sim {

namespace {

double boxDistance(const Vec3& x, const Vec3& lo, const Vec3& hi) {
    const Vec3 centre = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    const Vec3 q = (x - centre).cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

// Distance to a z-aligned solid cylinder r <= radius, z in [z0, z1], centred at (cx, cy).
// √(a² + b²) rather than std::hypot, whose care for overflow no scene length needs and which took a
// noticeable share of a simulation's time (tests/bench/FINDINGS.md, "Small costs and a
// scheduling fault").
double cylinderDistance(const Vec3& x, const Vec3& base, double radius, double z0, double z1) {
    const double r = Eigen::Vector2d(x.x() - base.x(), x.y() - base.y()).norm();
    const double dr = r - radius;
    const double dz = std::max(z0 - x.z(), x.z() - z1);
    return Eigen::Vector2d(std::max(dr, 0.0), std::max(dz, 0.0)).norm() + std::min(std::max(dr, dz), 0.0);
}

// The cup: an outer cylinder minus the inner cavity minus the hole through the bottom.
double cupDistance(const Vec3& x, const CupSolid& c) {
    const double outerR = c.innerRadius + c.wallThickness;
    const double zBottom = c.position.z(), zInner = zBottom + c.bottomThickness;
    const double zTop = zInner + c.height;
    const double outer = cylinderDistance(x, c.position, outerR, zBottom, zTop);
    // The cavity extends above the rim so that the cup is open at the top.
    const double cavity = cylinderDistance(x, c.position, c.innerRadius, zInner, zTop + outerR);
    // The hole reaches into the cavity and below the cup: with its ends flush with the bottom's
    // faces, max() would read 0 (on the surface) across the whole hole at those planes.
    const double hole = c.holeRadius > 0
                            ? cylinderDistance(x, c.position, c.holeRadius, zBottom - outerR, zInner + outerR)
                            : 1e30;
    return std::max({outer, -cavity, -hole});
}

struct PrimitiveDistance {
    const Vec3& x;
    double operator()(const GroundSolid& g) const { return x.z() - g.height; }
    double operator()(const BoxSolid& b) const { return boxDistance(x, b.min, b.max); }
    double operator()(const CupSolid& c) const { return cupDistance(x, c); }
    double operator()(const MeshSolid&) const { return 1e30; }
    double operator()(const ChannelSolid& c) const { return 0.5 * c.width - std::abs(x.y() - c.centerY); }
};

// A mesh exported in another unit (millimetres for metres) misses the domain or dwarfs it, and its
// voxelisation at the cell size would take minutes and gigabytes before the scene turned out empty:
// it is refused first. Only its part in the domain matters, so a large one can be cropped to it.
void requireMeshFitsDomain(const TriangleMesh& mesh, const std::filesystem::path& path, size_t index,
                           const Grid& grid) {
    Vec3 lo = Vec3::Constant(INFINITY), hi = Vec3::Constant(-INFINITY);
    for (const Vec3& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
    const Vec3 domainLo = grid.origin, domainHi = grid.origin + grid.extent();
    const std::string where = "solids[" + std::to_string(index) + "] (mesh) " + path.string();
    std::ostringstream bounds;
    bounds << "[" << lo.x() << ", " << lo.y() << ", " << lo.z() << "] to [" << hi.x() << ", " << hi.y() << ", "
           << hi.z() << "]";
    if ((hi.array() < domainLo.array()).any() || (lo.array() > domainHi.array()).any())
        throw InputError(where + ": its bounds " + bounds.str() + " lie outside the domain; is it in another unit?");
    const double ratio = (hi - lo).maxCoeff() / grid.extent().maxCoeff();
    if (ratio > kMaxSolidOverDomain && !scaleLimitsWaived())
        throw InputError(where + ": its bounds " + bounds.str() + " are " + std::to_string(int(ratio)) +
                         " times the domain's size; is it in millimetres? Scale it to metres, or crop it to the domain" +
                         kWaiveHint);
}

// OpenVDB's voxeliser polls this between its passes and stops on a cancel request.
struct CancelRequest : openvdb::util::NullInterrupter {
    bool wasInterrupted(int = -1) override { return cancelRequested(); }
};

}  // namespace

SolidField::SolidField(const std::vector<Solid>& solids, const Grid& grid) : grid_(grid) {
    openvdb::initialize();
    for (size_t i = 0; i < solids.size(); ++i) {
        const Solid& solid = solids[i];
        if (const auto* mesh = std::get_if<MeshSolid>(&solid)) {
            const TriangleMesh loaded = loadMesh(mesh->path);
            requireMeshFitsDomain(loaded, mesh->path, i, grid);
            std::vector<openvdb::Vec3s> points;
            std::vector<openvdb::Vec3I> triangles;
            for (const Eigen::Vector3d& v : loaded.vertices) points.emplace_back(v.x(), v.y(), v.z());
            for (const Eigen::Vector3i& t : loaded.triangles) triangles.emplace_back(t[0], t[1], t[2]);
            // Half the simulation cell resolves the solid finely enough for the fraction sampling.
            auto transform = openvdb::math::Transform::createLinearTransform(grid.dx * 0.5);
            std::vector<openvdb::Vec4I> quads;
            CancelRequest cancel;
            meshes_.push_back(openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
                cancel, *transform, points, triangles, quads, 4.0f));
            throwIfCancelled("voxelising the mesh");  // an interrupted voxelisation returns a partial grid
        } else {
            solids_.push_back(solid);
        }
    }
}

double SolidField::primitiveDistance(const Vec3& x) const {
    double d = 1e30;
    for (const Solid& s : solids_) d = std::min(d, std::visit(PrimitiveDistance{x}, s));
    return d;
}

double SolidField::distance(const Vec3& x) const {
    double d = primitiveDistance(x);
    for (const auto& mesh : meshes_) {
        const openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*mesh);
        d = std::min(d, double(sampler.wsSample(openvdb::Vec3d(x.x(), x.y(), x.z()))));
    }
    // Domain walls: the distance to leaving the box, on non-periodic axes.
    const Vec3 lo = grid_.origin, hi = grid_.origin + grid_.extent();
    for (int a = 0; a < 3; ++a)
        if (!grid_.periodic[a]) d = std::min({d, x[a] - lo[a], hi[a] - x[a]});
    return d;
}

Vec3 SolidField::normal(const Vec3& x) const {
    const double h = 0.25 * grid_.dx;
    Vec3 n;
    for (int a = 0; a < 3; ++a) {
        Vec3 e = Vec3::Zero();
        e[a] = h;
        n[a] = distance(x + e) - distance(x - e);
    }
    const double len = n.norm();
    return len > 0 ? Vec3(n / len) : Vec3(0, 0, 1);
}

}  // namespace viscoscope::sim
