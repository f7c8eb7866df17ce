#include "sim/solid_field.h"

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <fstream>
#include <sstream>

namespace viscoscope::sim {

namespace {

double boxDistance(const Vec3& x, const Vec3& lo, const Vec3& hi) {
    const Vec3 centre = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    const Vec3 q = (x - centre).cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

// Distance to a z-aligned solid cylinder r <= radius, z in [z0, z1], centred at (cx, cy).
double cylinderDistance(const Vec3& x, const Vec3& base, double radius, double z0, double z1) {
    const double r = std::hypot(x.x() - base.x(), x.y() - base.y());
    const double dr = r - radius;
    const double dz = std::max(z0 - x.z(), x.z() - z1);
    return std::hypot(std::max(dr, 0.0), std::max(dz, 0.0)) + std::min(std::max(dr, dz), 0.0);
}

// The cup: an outer cylinder minus the inner cavity minus the hole through the bottom.
double cupDistance(const Vec3& x, const CupSolid& c) {
    const double outerR = c.innerRadius + c.wallThickness;
    const double zBottom = c.position.z(), zInner = zBottom + c.bottomThickness;
    const double zTop = zInner + c.height;
    const double outer = cylinderDistance(x, c.position, outerR, zBottom, zTop);
    // The cavity extends above the rim so that the cup is open at the top.
    const double cavity = cylinderDistance(x, c.position, c.innerRadius, zInner, zTop + outerR);
    const double hole = c.holeRadius > 0
                            ? cylinderDistance(x, c.position, c.holeRadius, zBottom - outerR, zInner + 1e-9)
                            : 1e30;
    return std::max({outer, -cavity, -hole});
}

struct PrimitiveDistance {
    const Vec3& x;
    double operator()(const GroundSolid& g) const { return x.z() - g.height; }
    double operator()(const BoxSolid& b) const { return boxDistance(x, b.min, b.max); }
    double operator()(const CupSolid& c) const { return cupDistance(x, c); }
    double operator()(const MeshSolid&) const { return 1e30; }
};

}  // namespace

void readTriangleMesh(const std::filesystem::path& path, std::vector<openvdb::Vec3s>& points,
                      std::vector<openvdb::Vec3I>& triangles) {
    std::ifstream in(path);
    if (!in) throw InputError(path.string() + ": cannot open mesh file");
    const std::string ext = path.extension().string();
    auto fail = [&](const std::string& why) { throw InputError(path.string() + ": " + why); };
    auto addPolygon = [&](const std::vector<unsigned>& poly) {
        if (poly.size() < 3) fail("face with fewer than 3 vertices");
        for (unsigned v : poly)
            if (v >= points.size()) fail("face refers to a missing vertex");
        for (size_t k = 1; k + 1 < poly.size(); ++k)  // fan triangulation of convex polygons
            triangles.emplace_back(poly[0], poly[k], poly[k + 1]);
    };
    std::string line;
    if (ext == ".obj" || ext == ".OBJ") {
        while (std::getline(in, line)) {
            std::istringstream s(line);
            std::string tag;
            s >> tag;
            if (tag == "v") {
                float a, b, c;
                if (!(s >> a >> b >> c)) fail("malformed vertex line: " + line.substr(0, 60));
                points.emplace_back(a, b, c);
            } else if (tag == "f") {
                std::vector<unsigned> poly;
                std::string corner;
                while (s >> corner) {
                    const long idx = std::strtol(corner.c_str(), nullptr, 10);
                    poly.push_back(idx > 0 ? static_cast<unsigned>(idx - 1)
                                           : static_cast<unsigned>(long(points.size()) + idx));
                }
                addPolygon(poly);
            }
        }
    } else {  // ASCII PLY with vertex x y z first and faces as "n i0 i1 ..."
        std::getline(in, line);
        if (line.rfind("ply", 0) != 0) fail("not a PLY file");
        size_t vertexCount = 0, faceCount = 0;
        while (std::getline(in, line) && line.rfind("end_header", 0) != 0) {
            std::istringstream s(line);
            std::string word, kind;
            s >> word;
            if (word == "format" && (s >> kind) && kind != "ascii") fail("only ASCII PLY is supported");
            if (word == "element" && (s >> kind)) (kind == "vertex" ? s >> vertexCount : s >> faceCount);
        }
        for (size_t i = 0; i < vertexCount && std::getline(in, line); ++i) {
            std::istringstream s(line);
            float a, b, c;
            if (!(s >> a >> b >> c)) fail("malformed vertex line");
            points.emplace_back(a, b, c);
        }
        for (size_t i = 0; i < faceCount && std::getline(in, line); ++i) {
            std::istringstream s(line);
            size_t n;
            s >> n;
            std::vector<unsigned> poly(n);
            for (auto& v : poly) s >> v;
            addPolygon(poly);
        }
    }
    if (triangles.empty()) fail("no triangles");
}

SolidField::SolidField(const std::vector<Solid>& solids, const Grid& grid) : grid_(grid) {
    openvdb::initialize();
    for (const Solid& solid : solids) {
        if (const auto* mesh = std::get_if<MeshSolid>(&solid)) {
            std::vector<openvdb::Vec3s> points;
            std::vector<openvdb::Vec3I> triangles;
            readTriangleMesh(mesh->path, points, triangles);
            // Half the simulation cell resolves the solid finely enough for the fraction sampling.
            auto transform = openvdb::math::Transform::createLinearTransform(grid.dx * 0.5);
            std::vector<openvdb::Vec4I> quads;
            meshes_.push_back(openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
                *transform, points, triangles, quads, 4.0f));
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
