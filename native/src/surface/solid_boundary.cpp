// Scene solids as triangle meshes (surface.h: solidBoundary).
#include "surface/surface.h"

#include <cmath>

namespace viscoscope::surface {

namespace {

// Revolves a closed profile (r, z), counter-clockwise with the solid on its left, about the vertical
// axis through `centre`: each profile segment becomes a band of `segments` quads facing outward.
// A segment end on the axis (r = 0) closes its band as a fan; a segment along the axis adds nothing.
TriangleMesh lathe(const std::vector<Eigen::Vector2d>& profile, const Vec3& centre, int segments) {
    TriangleMesh mesh;
    const int n = static_cast<int>(profile.size());
    for (const Eigen::Vector2d& rz : profile)
        for (int k = 0; k < segments; ++k) {
            const double angle = 2 * M_PI * k / segments;
            mesh.vertices.emplace_back(centre.x() + rz.x() * std::cos(angle), centre.y() + rz.x() * std::sin(angle), rz.y());
        }
    const auto vertex = [segments](int j, int k) { return j * segments + k % segments; };
    for (int p = 0; p < n; ++p) {
        const int q = (p + 1) % n;
        const bool pOnAxis = profile[p].x() == 0, qOnAxis = profile[q].x() == 0;
        for (int k = 0; k < segments; ++k) {
            const int a = vertex(p, k), b = vertex(q, k), c = vertex(q, k + 1), d = vertex(p, k + 1);
            if (!qOnAxis) mesh.triangles.emplace_back(a, c, b);
            if (!pOnAxis) mesh.triangles.emplace_back(a, d, c);
        }
    }
    return mesh;
}

TriangleMesh cupBoundary(const CupSolid& cup, int segments) {
    // The cross-section of solid_field.cpp's cup: outer wall, rim, inner wall, inner bottom, hole.
    const double hole = cup.holeRadius, inner = cup.innerRadius, outer = cup.innerRadius + cup.wallThickness;
    const double bottom = cup.position.z(), floor = bottom + cup.bottomThickness, rim = floor + cup.height;
    return lathe({{hole, bottom}, {outer, bottom}, {outer, rim}, {inner, rim}, {inner, floor}, {hole, floor}},
                 cup.position, segments);
}

TriangleMesh boxBoundary(const BoxSolid& box) {
    TriangleMesh mesh;
    for (int corner = 0; corner < 8; ++corner)
        mesh.vertices.emplace_back(corner & 1 ? box.max.x() : box.min.x(), corner & 2 ? box.max.y() : box.min.y(),
                                   corner & 4 ? box.max.z() : box.min.z());
    // Two triangles per face, counter-clockwise seen from outside.
    const int faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
    for (const auto& f : faces) {
        mesh.triangles.emplace_back(f[0], f[1], f[2]);
        mesh.triangles.emplace_back(f[0], f[2], f[3]);
    }
    return mesh;
}

struct BoundaryOf {
    int segments;
    TriangleMesh operator()(const GroundSolid&) const { return {}; }
    TriangleMesh operator()(const BoxSolid& box) const { return boxBoundary(box); }
    TriangleMesh operator()(const CupSolid& cup) const { return cupBoundary(cup, segments); }
    TriangleMesh operator()(const MeshSolid& mesh) const { return loadMesh(mesh.path); }
    TriangleMesh operator()(const ChannelSolid&) const { return {}; }  // seen through (scene.h)
};

}  // namespace

TriangleMesh solidBoundary(const Solid& solid, int segments) {
    if (segments < 3) throw std::invalid_argument("solidBoundary: segments must be ≥ 3");
    return std::visit(BoundaryOf{segments}, solid);
}

}  // namespace viscoscope::surface
