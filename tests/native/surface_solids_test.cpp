// Meshes of the scene's solids (surface::solidBoundary): closed, facing outward, and enclosing
// exactly the volume of the solid they stand for (the cup's N-gon cross-sections included); the
// liquid's surface against the solids and against the liquid's own extent.
#include "surface/surface.h"

#include <Eigen/Geometry>
#include <openvdb/tools/Interpolation.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <random>
#include <map>
#include <tuple>

using namespace viscoscope;

namespace {

// Σ v0·(v1 × v2) / 6: the enclosed volume, positive when every face points outward.
double signedVolume(const TriangleMesh& mesh) {
    double volume = 0;
    for (const Eigen::Vector3i& t : mesh.triangles)
        volume += mesh.vertices[t[0]].dot(mesh.vertices[t[1]].cross(mesh.vertices[t[2]])) / 6;
    return volume;
}

// Every edge, welded by position, is used once in each direction: no holes, consistent winding.
bool closedAndConsistent(const TriangleMesh& mesh) {
    std::map<std::tuple<long, long, long>, int> ids;
    const auto id = [&](const Eigen::Vector3d& p) {
        const auto key = std::make_tuple(std::lround(p.x() * 1e9), std::lround(p.y() * 1e9), std::lround(p.z() * 1e9));
        return ids.emplace(key, static_cast<int>(ids.size())).first->second;
    };
    std::map<std::pair<int, int>, int> directed;
    for (const Eigen::Vector3i& t : mesh.triangles)
        for (int e = 0; e < 3; ++e) ++directed[{id(mesh.vertices[t[e]]), id(mesh.vertices[t[(e + 1) % 3]])}];
    for (const auto& [edge, count] : directed) {
        const auto reverse = directed.find({edge.second, edge.first});
        if (count != 1 || reverse == directed.end() || reverse->second != 1) return false;
    }
    return !directed.empty();
}

}  // namespace

TEST(SolidBoundary, CupIsClosedAndHoldsItsVolume) {
    for (double hole : {0.009, 0.0}) {
        CupSolid cup;
        cup.position = {0.01, -0.02, 0.1};
        cup.innerRadius = 0.043;
        cup.height = 0.05;
        cup.wallThickness = 0.006;
        cup.bottomThickness = 0.005;
        cup.holeRadius = hole;
        for (int segments : {7, 96}) {
            const TriangleMesh mesh = surface::solidBoundary(cup, segments);
            const double outer = cup.innerRadius + cup.wallThickness;
            // Each horizontal slice is an annulus of regular N-gons: area (N/2) sin(2π/N) (R² − r²).
            const double ngon = segments / 2.0 * std::sin(2 * M_PI / segments);
            const double expected = ngon * ((outer * outer - hole * hole) * cup.bottomThickness +
                                             (outer * outer - cup.innerRadius * cup.innerRadius) * cup.height);
            EXPECT_NEAR(signedVolume(mesh), expected, 1e-12) << "hole " << hole << ", " << segments << " sides";
            EXPECT_TRUE(closedAndConsistent(mesh)) << "hole " << hole << ", " << segments << " sides";
            for (const Eigen::Vector3d& v : mesh.vertices) {
                EXPECT_GE(v.z(), cup.position.z() - 1e-15);
                EXPECT_LE(std::hypot(v.x() - cup.position.x(), v.y() - cup.position.y()), outer + 1e-15);
            }
        }
    }
}

TEST(SolidBoundary, BoxIsClosedAndGroundIsEmpty) {
    const TriangleMesh box = surface::solidBoundary(BoxSolid{{-0.1, 0.2, 0.0}, {0.3, 0.25, 0.07}});
    EXPECT_EQ(box.triangles.size(), 12u);
    EXPECT_NEAR(signedVolume(box), 0.4 * 0.05 * 0.07, 1e-15);
    EXPECT_TRUE(closedAndConsistent(box));
    EXPECT_TRUE(surface::solidBoundary(GroundSolid{0.0}).triangles.empty());
}

// Liquid drawn into the ground (here particles placed through it) is cut off there, and the liquid
// above the ground stays as it was.
TEST(ClipToSolidExterior, RemovesLiquidBelowTheGroundOnly) {
    const nlohmann::json doc = {
        {"format", "viscoscope.scene"}, {"version", 1},
        {"domain", {{"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.04}}, {"resolution", 16}}},
        {"solids", {{{"type", "ground"}, {"height", 0.01}}}},
        {"liquids", {{{"type", "box"}, {"min", {0.01, 0.01, 0.01}}, {"max", {0.03, 0.03, 0.02}}}}},
        {"material", {{"density", 1000}, {"viscosity", 1.0}}}, {"fps", 30}, {"frames", 1}};
    sim::Simulation simulation(parseScene(doc, "clip"));
    for (Eigen::Vector3d& x : simulation.particles().position) x.z() -= 0.005;  // half the box below the ground
    const auto levelSet = surface::liquidLevelSet(simulation);
    auto insideVoxels = [&](bool below) {
        int count = 0;
        for (auto v = levelSet->cbeginValueOn(); v; ++v) {
            const double z = levelSet->transform().indexToWorld(v.getCoord()).z();
            if (*v < 0 && (below ? z < 0.01 : z > 0.01)) ++count;
        }
        return count;
    };
    const int belowBefore = insideVoxels(true), aboveBefore = insideVoxels(false);
    ASSERT_GT(belowBefore, 0);  // otherwise there is nothing to clip and the test proves nothing
    surface::clipToSolidExterior(*levelSet, simulation.solids());
    EXPECT_EQ(insideVoxels(true), 0);
    EXPECT_EQ(insideVoxels(false), aboveBefore);
}

// The liquid surface must lie where the liquid ends, whatever the grid: a surface reaching a fixed
// fraction of a cell beyond it would draw a coarse simulation's streams and puddles wider than a
// fine one's. Particles fill shapes of the sizes the sample cup shows: its stream (radius 2.4 cells
// at 48³ and 3.2 at 64³, and less where it narrows at 48³ and η = 1), the film on the ground,
// the edge of a film one or two cells thick (the front of a spreading puddle), a drop, and large
// bodies. They are placed as Simulation seeds them (jittered in sub-cells, 8 or 27 per cell) and as
// they lie after flowing, for which independent uniform points stand in: in the sample cup's stream
// their spacing is close to uniform points', not to the seeding's. The surface is the half level of
// the density smoothed over σ = 0.375 cells (the default at 8 per cell). That holds a flat edge, and
// takes a stream of R cells in by about σ²/2R (0.03–0.06 cells here). A film one cell thick is
// thinner than the kernel: its density peaks at erf(0.5 / √2σ) ≈ 0.82, and its edge recedes until
// the fall-off across it halves that peak, 0.105 cells; the test expects that figure there. Flowed
// particles are its weak case: their random gaps leave holes in a one-cell film and take its edge
// in by about a quarter cell, so for one-cell films they may move the surface by 0.2 cells from the
// seeded one and leave holes under 5 % of rays; elsewhere by 0.1 cells and 1 %. (Measured in
// tests/bench/FINDINGS.md: the narrowed stream in "Identification on the sample cup: what was
// measured on the way to Table 1"; the particles' spacing and the film's holes in "Figures moved
// from test comments".)
TEST(LiquidLevelSet, SurfaceLiesAtTheLiquidBoundary) {
    enum Shape { kColumn, kSlab, kBall, kFilmEdge };
    struct Case { const char* name; Shape shape; double size; };  // radius, or a slab's thickness, in cells
    const Case cases[] = {{"stream 1.3", kColumn, 1.3}, {"stream 2.4", kColumn, 2.4}, {"stream 3.2", kColumn, 3.2},
                          {"column 8", kColumn, 8},     {"film 1", kSlab, 1},         {"film 2", kSlab, 2},
                          {"film 3", kSlab, 3},         {"slab 8", kSlab, 8},         {"drop 3", kBall, 3},
                          {"edge 1", kFilmEdge, 1},     {"edge 2", kFilmEdge, 2}};
    struct Arrangement { const char* name; int perAxis; bool flowed; };
    const Arrangement seeded8{"seeded 8", 2, false}, seeded27{"seeded 27", 3, false}, flowed8{"flowed 8", 2, true};
    auto oneCellFilm = [](const Case& c) { return c.shape != kColumn && c.shape != kBall && c.size == 1; };
    const double dx = 0.004;
    std::mt19937 random(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);

    // The particles of one draw filling the case's shape, in metres.
    auto fill = [&](const Case& c, const Arrangement& arrangement) {
        const int n = arrangement.perAxis;
        std::vector<Eigen::Vector3d> particles;
        for (int i = -12; i < 12; ++i)
            for (int j = -12; j < 12; ++j)
                for (int k = -12; k < 12; ++k)
                    for (int s = 0; s < n * n * n; ++s) {
                        const Eigen::Vector3d jitter(unit(random), unit(random), unit(random));
                        const Eigen::Vector3d sub =
                            arrangement.flowed ? jitter : (Eigen::Vector3d(s % n, (s / n) % n, s / (n * n)) + jitter) / n;
                        const Eigen::Vector3d x = Eigen::Vector3d(i, j, k) + sub;  // in cells
                        const double extent = c.shape == kColumn ? x.head<2>().norm()
                                              : c.shape == kBall     ? x.norm()
                                                                     : 2 * std::abs(x.z());
                        if (extent <= c.size && (c.shape != kFilmEdge || x.x() <= 0)) particles.push_back(x * dx);
                    }
        return particles;
    };
    // The mean distance (cells) of the surface beyond the shape's boundary: the zero crossing along
    // rays outwards from its axis, plane or centre, found by bisection. One draw of particles varies
    // by ±0.05 cells for thin shapes, so four are averaged. A ray that starts in a hole of the
    // surface measures nothing; flowed particles leave a rare one in a one-cell film (1 of 400 rays).
    auto reach = [&](const Case& c, const Arrangement& arrangement) {
        const int draws = 4, rays = 100;
        const double boundary = c.shape == kSlab ? c.size / 2 : c.shape == kFilmEdge ? 6 : c.size;
        double sum = 0;
        int holes = 0;
        const int perCell = arrangement.perAxis * arrangement.perAxis * arrangement.perAxis;
        for (int draw = 0; draw < draws; ++draw) {
            const double smoothing = kSurfaceSmoothingPerCell * dx;
            const auto levelSet = surface::liquidLevelSet(fill(c, arrangement), std::pow(dx, 3) / perCell, smoothing,
                                                          surface::surfaceVoxelSize(smoothing));
            const openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> phi(*levelSet);
            for (int r = 0; r < rays; ++r) {
                const double a = 2 * M_PI * unit(random), cosB = 2 * unit(random) - 1, h = 12 * unit(random) - 6;
                const double sinB = std::sqrt(1 - cosB * cosB);
                const Eigen::Vector3d direction = c.shape == kColumn     ? Eigen::Vector3d(std::cos(a), std::sin(a), 0)
                                                  : c.shape == kSlab     ? Eigen::Vector3d(0, 0, 1)
                                                  : c.shape == kFilmEdge ? Eigen::Vector3d(1, 0, 0)
                                                                         : Eigen::Vector3d(sinB * std::cos(a), sinB * std::sin(a), cosB);
                const Eigen::Vector3d start = c.shape == kColumn     ? Eigen::Vector3d(0, 0, h)
                                              : c.shape == kSlab     ? Eigen::Vector3d(h, 12 * unit(random) - 6, 0)
                                              : c.shape == kFilmEdge ? Eigen::Vector3d(-6, h, 0)
                                                                     : Eigen::Vector3d::Zero();
                if (phi.wsSample(openvdb::Vec3d(start.x() * dx, start.y() * dx, start.z() * dx)) >= 0) {
                    ++holes;
                    continue;
                }
                double inside = 0, outside = boundary + 3;
                for (int step = 0; step < 30; ++step) {
                    const double middle = (inside + outside) / 2;
                    const Eigen::Vector3d x = (start + middle * direction) * dx;
                    (phi.wsSample(openvdb::Vec3d(x.x(), x.y(), x.z())) < 0 ? inside : outside) = middle;
                }
                sum += inside - boundary;
            }
        }
        // Seeded particles leave none, as the test has always required.
        const int allowedHoles = !arrangement.flowed ? 0 : oneCellFilm(c) ? draws * rays / 20 : draws * rays / 100;
        EXPECT_LE(holes, allowedHoles) << arrangement.name << ", " << c.name;
        const double mean = sum / (draws * rays - holes);
        std::printf("%-9s %-10s surface %+.3f cells beyond the liquid; rays starting in a hole: %d\n",
                    arrangement.name, c.name, mean, holes);
        return mean;
    };

    // Where the half level lies at the edge of a film one cell thick: ρ₁ Φ(−x/σ) = ½ (cells).
    const double sigma = kSurfaceSmoothingPerCell, peak = std::erf(0.5 / (std::sqrt(2.0) * sigma));
    double lo = -1, hi = 0;
    for (int step = 0; step < 50; ++step) {
        const double x = (lo + hi) / 2;
        (peak * 0.5 * std::erfc(x / (std::sqrt(2.0) * sigma)) > 0.5 ? lo : hi) = x;
    }
    const double oneCellEdge = lo;
    for (const Case& c : cases) {
        const double expected = c.shape == kFilmEdge && c.size == 1 ? oneCellEdge : 0.0;
        const double fromSeeded = reach(c, seeded8);
        EXPECT_LT(std::abs(fromSeeded - expected), 0.1) << seeded8.name << ", " << c.name;
        EXPECT_LT(std::abs(reach(c, seeded27) - expected), 0.1) << seeded27.name << ", " << c.name;
        EXPECT_LT(std::abs(reach(c, flowed8) - fromSeeded), oneCellFilm(c) ? 0.2 : 0.1) << flowed8.name << ", " << c.name;
    }
}

// The density is summed tile by tile, so liquid far apart costs its own tiles only: one box around
// both of these drops, 20 m apart along each axis at 1 mm voxels, would hold 8·10¹² floats.
TEST(LiquidLevelSet, DropsFarApartCostOnlyTheirOwnTiles) {
    const double dx = 0.004, smoothing = kSurfaceSmoothingPerCell * dx, volume = std::pow(dx, 3) / 8;
    std::mt19937 random(5);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<Eigen::Vector3d> drop;
    for (int i = -4; i < 4; ++i)
        for (int j = -4; j < 4; ++j)
            for (int k = -4; k < 4; ++k)
                for (int s = 0; s < 8; ++s) {
                    const Eigen::Vector3d x = Eigen::Vector3d(i, j, k) +
                                              (Eigen::Vector3d(s % 2, (s / 2) % 2, s / 4) +
                                               Eigen::Vector3d(unit(random), unit(random), unit(random))) / 2;
                    if (x.norm() <= 3) drop.push_back(x * dx);
                }
    const Eigen::Vector3d apart = Eigen::Vector3d::Constant(20.0);
    std::vector<Eigen::Vector3d> both = drop;
    for (const Eigen::Vector3d& x : drop) both.push_back(x + apart);
    const double voxel = surface::surfaceVoxelSize(smoothing);
    const auto one = surface::liquidLevelSet(drop, volume, smoothing, voxel);
    openvdb::FloatGrid::Ptr two;
    ASSERT_NO_THROW(two = surface::liquidLevelSet(both, volume, smoothing, voxel));
    EXPECT_NEAR(double(two->activeVoxelCount()) / double(one->activeVoxelCount()), 2.0, 0.04);
    const openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> phi(*two);
    const auto at = [&](const Eigen::Vector3d& x) { return phi.wsSample(openvdb::Vec3d(x.x(), x.y(), x.z())); };
    EXPECT_LT(at(Eigen::Vector3d::Zero()), 0);
    EXPECT_LT(at(apart), 0);
    EXPECT_GT(at(apart / 2), 0);
    EXPECT_GT(at(Eigen::Vector3d(4 * dx, 0, 0)), 0);  // beyond the drop's 3-cell radius
}
