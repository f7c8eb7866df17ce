// Physics checks of the forward model against analytic solutions. Each prints the figures it
// measures; bounds are the accuracy we claim, not what happened to pass.
#include "sim/sim.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

using namespace viscoscope;
using nlohmann::json;
using sim::Vec3;

namespace {

json baseScene(double viscosity, int resolution) {
    json s = {{"format", "viscoscope.scene"},
              {"version", 1},
              {"domain", {{"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.04}}, {"resolution", resolution}}},
              {"liquids", json::array()},
              {"material", {{"density", 1000}, {"viscosity", viscosity}, {"surface_tension", 0.0}}},
              {"fps", 30},
              {"frames", 1},
              {"seed", 3}};
    return s;
}

json sampleCupScene() {
    json doc;
    std::ifstream(std::string(VISCOSCOPE_SOURCE_DIR) + "/sample_scenes/capture_cup.json") >> doc;
    return doc;
}

double maxParticleSpeed(const sim::Simulation& s) {
    double v = 0;
    for (const Vec3& p : s.particles().velocity) v = std::max(v, p.norm());
    return v;
}

Vec3 angularMomentum(const sim::Simulation& s, const Vec3& centre) {
    Vec3 l = Vec3::Zero();
    const auto& p = s.particles();
    for (size_t i = 0; i < p.position.size(); ++i) l += (p.position[i] - centre).cross(p.velocity[i]);
    return l;
}

// Stokes flow through the sample cup's hole (radius 9 mm, bottom 5 mm) in a box 120 mm wide at 32
// cells (Δx = 3.75 mm, as the sample cup's at 48³); gravity drives the liquid through the hole. The
// cup sits `sideways` cells off the faces' corners along x and y and `lift` cells above a row of
// z-faces. Exits:
// - BothSides: the box is periodic along z and full of liquid, the bottom spanning it (Dagan,
//   Weinbaum & Pfeffer's setting);
// - FreeJet: a layer 4 hole radii deep inside the cup, with a jet as long hanging from the hole
//   into air (the hole calibration's setting, but inside the cup's walls instead of periodic).
// Returns the flux through the row of z-faces nearest the middle of the bottom over Dagan's orifice
// flux Δp/(η (3/r³ + 8t/(π r⁴))), and the simulation's hole calibration in `calibration`. `steady`
// reads it after one implicit step 10³ viscous times long (solved to a relative residual of 1e-8,
// as gravity is nearly all borne by the bottom), otherwise after two frames.
constexpr double kOrificeRadius = 0.009, kOrificeBottom = 0.005;
enum class OrificeExit { BothSides, FreeJet };
double orificeFluxOverDagan(OrificeExit exit, double sideways, double lift, const std::string& conductance,
                            bool steady, sim::HoleCalibration* calibration = nullptr) {
    const double width = 0.12, rho = 1000, eta = 100, g = 9.81, r = kOrificeRadius, t = kOrificeBottom;
    const int resolution = 32;
    const double dx = width / resolution;
    const bool jet = exit == OrificeExit::FreeJet;
    const double length = jet ? 28 * dx : 0.06, bottom = (jet ? 13 + lift : 8 + lift) * dx;
    json doc = baseScene(eta, resolution);
    doc["domain"] = {{"min", {-width / 2, -width / 2, 0}}, {"max", {width / 2, width / 2, length}},
                     {"resolution", resolution}, {"periodic", {false, false, !jet}}};
    // Walls thicker than the box's half-diagonal: below the cup's bottom the box, above it the cup.
    const double innerRadius = 0.043;
    doc["solids"] = {{{"type", "cup"}, {"position", {sideways * dx, sideways * dx, bottom}},
                      {"inner_radius", innerRadius}, {"height", 3}, {"wall_thickness", 0.05},
                      {"bottom_thickness", t}, {"hole_radius", r}}};
    const double drop = jet ? 8 * r : length;  // ρ g × this across the hole
    if (jet) {
        const double half = 0.5 * std::sqrt(M_PI) * r;  // a square as wide as the hole
        const double x = sideways * dx;
        const double layer = M_PI * innerRadius * innerRadius * 4 * r + M_PI * r * r * t;  // hole included
        doc["liquids"].push_back({{"type", "cup_fill"}, {"cup", 0}, {"volume", layer}});
        doc["liquids"].push_back({{"type", "box"}, {"min", {x - half, x - half, bottom - 4 * r}},
                                  {"max", {x + half, x + half, bottom}}});
    } else {
        doc["liquids"].push_back({{"type", "box"}, {"min", {-width / 2, -width / 2, 0}}, {"max", {width / 2, width / 2, length}}});
    }
    doc["gravity"] = {0, 0, -g};
    doc["frames"] = 2;  // 67 ms, twice the box's viscous time ρ L²/η; every run is read alike
    doc["solver"] = {{"hole_conductance", conductance}};
    if (steady) doc["solver"].update({{"tolerance", 1e-8}, {"max_iterations", 20000}});
    sim::Simulation s(parseScene(doc, "orifice"));
    if (steady) s.step(1e3 * rho * width * width / eta);
    else for (int f = 0; f < 2; ++f) s.advanceFrame();
    const sim::Field& w = s.fields().velocity[2];
    const sim::Field& open = s.fractions().faceOpenArea[2];
    const int k = static_cast<int>(std::lround((bottom + 0.5 * t - s.grid().origin.z()) / dx));
    double q = 0;
    for (int j = 0; j < w.lattice.size[1]; ++j)
        for (int i = 0; i < w.lattice.size[0]; ++i)
            q -= w[w.lattice.index(i, j, k)] * open[open.lattice.index(i, j, k)] * dx * dx;
    if (calibration && !s.holeCalibrations().empty()) *calibration = s.holeCalibrations().front();
    return q / (rho * g * drop / (eta * (3 / (r * r * r) + 8 * t / (M_PI * r * r * r * r))));
}

}  // namespace

// 1. A layer of liquid resting in a box stays at rest. Spurious speeds are measured against the
// speed of falling one cell, sqrt(g Δx) (0.157 m/s here). Claimed: below 5 % of it without surface
// tension and below 10 % with water's σ, whose parasitic currents come from the curvature of a
// particle-built surface.
TEST(Physics, HydrostaticRestWithAndWithoutSurfaceTension) {
    for (double sigma : {0.0, 0.07}) {
        json doc = baseScene(1.0, 16);
        doc["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.02}}});
        doc["material"]["surface_tension"] = sigma;
        sim::Simulation s(parseScene(doc, "hydrostatic"));
        const double v0 = s.liquidVolume();
        double worst = 0;
        for (int f = 0; f < 6; ++f) {
            s.advanceFrame();
            worst = std::max(worst, maxParticleSpeed(s));
        }
        const double drift = s.liquidVolume() / v0 - 1;
        std::printf("hydrostatic sigma=%.2f: max spurious speed %.2e m/s, volume drift %.2e\n", sigma, worst, drift);
        const double fallSpeed = std::sqrt(9.81 * s.grid().dx);
        EXPECT_LT(worst, (sigma > 0 ? 0.10 : 0.05) * fallSpeed);
        EXPECT_LT(std::abs(drift), 0.01);
    }
}

// 1a. A blob of liquid in free fall accelerates at g: no force but gravity acts on it as a whole
// (the solve's pressure and stress are internal), whatever the weights of its surface faces. The
// falling stream under the cup depends on it. (Scaling gravity by each face's liquid fraction, so
// that nearly empty faces do not weigh their clamped mass, slowed this blob; measured:
// tests/bench/FINDINGS.md, "Figures moved from test comments".)
TEST(Physics, FreeFallingBlobAcceleratesAtG) {
    json doc = baseScene(1.0, 32);
    doc["domain"] = {{"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.16}}, {"resolution", 32}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {0.01, 0.01, 0.12}}, {"max", {0.03, 0.03, 0.15}}});
    sim::Simulation s(parseScene(doc, "free fall"));
    for (int f = 0; f < 3; ++f) s.advanceFrame();
    double meanVz = 0;
    for (const Vec3& v : s.particles().velocity) meanVz += v.z() / s.particles().velocity.size();
    const double expected = -9.81 * s.time();
    std::printf("free fall: mean vertical velocity %.5f m/s after %.3f s, g t = %.5f m/s (%+.3f %%)\n", meanVz,
                s.time(), expected, 100 * (meanVz / expected - 1));
    EXPECT_NEAR(meanVz / expected, 1.0, 0.005);
}

// 1a'. A lone particle that falls onto the ground comes to rest there. Alone it is too little
// liquid for any cell to enter the solve (W = 0 everywhere), so nothing but the ground's push
// holds it. It falls from 3 cells up (impact speed √(2 g h) = 0.38 m/s) and lies on the ground
// for the rest of the second. Before the push also stopped its motion into the ground, it kept
// gaining speed there, and its speed shortened the steps (measured: tests/bench/FINDINGS.md,
// "Figures moved from test comments").
TEST(Physics, LoneDropletComesToRestOnTheGround) {
    json doc = baseScene(300.0, 16);
    doc["solids"] = json::array({{{"type", "ground"}, {"height", 0.0}}});
    doc["liquids"].push_back({{"type", "box"}, {"min", {0.01, 0.01, 0.01}}, {"max", {0.03, 0.03, 0.03}}});
    doc["frames"] = 30;
    sim::Simulation s(parseScene(doc, "lone droplet"));
    const double dx = s.grid().dx;
    sim::Particles& p = s.particles();
    p.position.assign(1, Vec3(0.02, 0.02, 3 * dx));
    p.velocity.assign(1, Vec3::Zero());
    p.affine.assign(1, Eigen::Matrix3d::Zero());
    double fastestLastHalf = 0;
    int stepsLastFrame = 0;
    for (int f = 0; f < 30; ++f) {
        stepsLastFrame = s.advanceFrame().steps;
        if (f >= 15) fastestLastHalf = std::max(fastestLastHalf, maxParticleSpeed(s));
    }
    const Vec3 x = s.particles().position[0];
    std::printf("lone droplet on the ground: height %.3f cells, fastest over the last 0.5 s %.3f m/s, "
                "%d steps in the last frame\n", x.z() / dx, fastestLastHalf, stepsLastFrame);
    EXPECT_GE(x.z(), 0.0);
    EXPECT_LT(x.z(), dx);
    EXPECT_LT(fastestLastHalf, std::sqrt(2 * 9.81 * 3 * dx));  // slower than it hit the ground
}

// 1b. Surface tension's strength: a drop at rest in zero gravity carries the Laplace pressure
// 2σ/R inside. Read from the pressure of the cells deep inside (they hold it once the solve has
// balanced the surface's push) against R from the liquid volume the grid measures. Claimed: within
// 5 %, and the drop stays still (spurious speed below 5 % of the capillary speed σ/η).
TEST(Physics, DropCarriesLaplacePressure) {
    const double sigma = 0.07, eta = 1.0, radius = 0.008;
    json doc = baseScene(eta, 32);
    doc["liquids"].push_back({{"type", "box"}, {"min", {0.01, 0.01, 0.01}}, {"max", {0.03, 0.03, 0.03}}});
    doc["gravity"] = {0, 0, 0};
    doc["material"]["surface_tension"] = sigma;
    sim::Simulation s(parseScene(doc, "drop"));
    const Vec3 centre = Vec3::Constant(0.02);
    sim::keepParticles(s.particles(), [&](const Vec3& x) { return (x - centre).norm() <= radius; });
    for (int f = 0; f < 3; ++f) s.advanceFrame();
    const double measuredRadius = std::cbrt(3 * s.liquidVolume() / (4 * M_PI));
    const auto& cells = s.fractions().cell;
    double pressureSum = 0;
    int samples = 0;
    for (int c = 0; c < cells.lattice.count(); ++c) {
        const Vec3 x = s.grid().position(sim::kCellCentre, cells.lattice.coords(c));
        if (cells[c] < 1 || (x - centre).norm() > measuredRadius - 2 * s.grid().dx) continue;
        pressureSum += s.fields().pressure[c];
        ++samples;
    }
    ASSERT_GT(samples, 0);
    const double laplace = 2 * sigma / measuredRadius, inside = pressureSum / samples;
    const double spurious = maxParticleSpeed(s) / (sigma / eta);
    std::printf("drop R=%.2f cells: inside pressure %.3f Pa vs 2σ/R %.3f Pa (%+.2f %%), spurious speed %.3f σ/η\n",
                measuredRadius / s.grid().dx, inside, laplace, 100 * (inside / laplace - 1), spurious);
    EXPECT_NEAR(inside / laplace, 1.0, 0.05);
    EXPECT_LT(spurious, 0.05);
}

// 1c. The pressure a simulation reports (and writes to .vdb) is hydrostatic up to the walls: in a
// pool at rest in a round cup, whose wall cuts cells at every fraction, every cell holding at least
// a tenth of liquid and lying 1.5 cells or more below the surface reads ρ g (depth) within 5 %
// of the bottom's pressure. (The solve's unknown alone, written before, was far off; measured:
// tests/bench/FINDINGS.md, "Figures moved from test comments".)
TEST(Physics, ReportedPressureIsHydrostaticInCutCells) {
    const double density = 1000, g = 9.81, innerRadius = 0.015, floor = 0.005, volume = 1.0e-5;
    json doc = baseScene(1.0, 24);
    doc["solids"] = {{{"type", "cup"}, {"position", {0.02, 0.02, floor - 0.003}}, {"inner_radius", innerRadius},
                      {"height", 0.03}, {"wall_thickness", 0.003}, {"bottom_thickness", 0.003}}};
    doc["liquids"] = {{{"type", "cup_fill"}, {"cup", 0}, {"volume", volume}}};
    sim::Simulation s(parseScene(doc, "pool in a cup"));
    for (int f = 0; f < 3; ++f) s.advanceFrame();
    const double surface = floor + s.liquidVolume() / (M_PI * innerRadius * innerRadius);
    const double bottomPressure = density * g * (surface - floor);
    const auto& cells = s.fractions().cell;
    double worst = 0, worstCut = 0;
    int cutCells = 0;
    for (int c = 0; c < cells.lattice.count(); ++c) {
        const Vec3 x = s.grid().position(sim::kCellCentre, cells.lattice.coords(c));
        if (cells[c] < 0.1 || x.z() > surface - 1.5 * s.grid().dx) continue;
        const double error = std::abs(s.cellPressure(c) - density * g * (surface - x.z())) / bottomPressure;
        worst = std::max(worst, error);
        if (cells[c] < 0.9) {
            worstCut = std::max(worstCut, error);
            ++cutCells;
        }
    }
    std::printf("pool in a cup: worst pressure error %.2f %% of ρgh (%.1f Pa), %.2f %% in %d cut cells\n",
                100 * worst, bottomPressure, 100 * worstCut, cutCells);
    ASSERT_GT(cutCells, 0);
    EXPECT_LT(worst, 0.05);
}

// 1d. The air under a thin wall stays air for surface tension: with the sample cup full at 48³
// (its bottom 1.3 cells thick), the level set surface tension takes its curvature from reads no
// liquid in the cells just under the bottom beside the hole. The particles' images across the walls
// used to show the liquid in the hole and on the floor there, on the bottom's far side; a drop
// hanging from the hole bent onto that false liquid, and its surface tension held the drop up.
// The grid is lowered (by under a cell) until the cup's underside lies 2 % of a cell below a row
// of z-faces, whatever the resolution, and still covers the whole domain (see sim::sceneGrid).
TEST(Physics, GridPutsTheCupsUndersideJustBelowARowOfFaces) {
    json doc = sampleCupScene();
    for (const int resolution : {32, 48, 64, 96}) {
        doc["domain"]["resolution"] = resolution;
        const Scene scene = parseScene(doc, "sample cup");
        const sim::Grid grid = sim::sceneGrid(scene);
        const double underside = std::get<CupSolid>(scene.solids.at(1)).position.z();
        const double height = (underside - grid.origin.z()) / grid.dx;
        EXPECT_NEAR(height - std::floor(height), 0.98, 1e-9) << resolution << "³";
        EXPECT_LE(grid.origin.z(), scene.domain.min.z());
        EXPECT_GT(grid.origin.z(), scene.domain.min.z() - grid.dx);
        EXPECT_GE(grid.origin.z() + grid.extent().z(), scene.domain.max.z() - 1e-12);
        // Already placed: left as it is.
        Scene placed = scene;
        placed.domain.min.z() = grid.origin.z();
        placed.domain.max.z() = grid.origin.z() + grid.dx * scene.cellCounts().z();
        EXPECT_DOUBLE_EQ(sim::sceneGrid(placed).origin.z(), grid.origin.z());
    }
}

TEST(Physics, NoLiquidAppearsUnderTheCupsThinBottom) {
    json doc = sampleCupScene();
    doc["domain"]["resolution"] = 48;
    sim::Simulation s(parseScene(doc, "sample cup"));
    const CupSolid* cup = nullptr;
    for (const Solid& solid : s.scene().solids)
        if (!cup) cup = std::get_if<CupSolid>(&solid);
    ASSERT_NE(cup, nullptr);
    const auto levelSet = s.surfaceLevelSet();
    const auto distance = levelSet->getConstAccessor();
    const sim::Lattice cells = s.grid().lattice(sim::kCellCentre);
    const double dx = s.grid().dx, bottom = cup->position.z();
    double nearest = std::numeric_limits<double>::infinity();
    int probed = 0;
    for (int c = 0; c < cells.count(); ++c) {
        const sim::Vec3i ijk = cells.coords(c);
        const Vec3 x = s.grid().position(sim::kCellCentre, ijk);
        const double r = std::hypot(x.x() - cup->position.x(), x.y() - cup->position.y());
        if (x.z() >= bottom || x.z() < bottom - 1.5 * dx || r < cup->holeRadius + 0.5 * dx ||
            r > cup->holeRadius + 3 * dx)
            continue;
        nearest = std::min(nearest, double(distance.getValue(openvdb::Coord(ijk[0], ijk[1], ijk[2]))) / dx);
        ++probed;
    }
    std::printf("thin bottom: the surface tension's level set %.2f cells from liquid under the bottom (%d cells)\n",
                nearest, probed);
    ASSERT_GT(probed, 0);
    EXPECT_GT(nearest, 0.0);
}

// The first liquid out of the sample cup's hole falls as it does with steps 8× shorter: at low η
// the identification reads η from how fast that tip falls. The tip is the lowest particle within
// 1 cm of the cup's axis, over the 0.23 s it takes to near the ground at η = 3 Pa·s. Claimed: within
// half a cell at every frame. The start-up cap of sim/simulation.cpp is what keeps it there: with
// the CFL limit alone the tip falls more than a cell behind (measured in tests/bench/FINDINGS.md:
// at 32³ in "Figures moved from test comments", at 48³ in "Identification on the sample cup: what
// was measured on the way to Table 1").
TEST(Physics, FirstLiquidOutOfTheHoleFallsAsWithShorterSteps) {
    json doc = sampleCupScene();
    doc["domain"]["resolution"] = 32;
    doc["material"]["viscosity"] = 3.0;
    doc["frames"] = 7;
    std::vector<double> tips[2];
    double dx = 0;
    for (const double cfl : {2.0, 0.25}) {
        doc["solver"]["cfl"] = cfl;
        sim::Simulation s(parseScene(doc, "sample cup"));
        const CupSolid& cup = *firstHoledCup(s.scene());
        dx = s.grid().dx;
        for (int f = 0; f < 7; ++f) {
            s.advanceFrame();
            double tip = cup.position.z();
            for (const Vec3& x : s.particles().position)
                if (std::hypot(x.x() - cup.position.x(), x.y() - cup.position.y()) < 0.01) tip = std::min(tip, x.z());
            tips[cfl < 1].push_back(tip);
        }
    }
    std::printf("first liquid's tip, cfl 2 against 0.25 (cells):");
    for (size_t f = 0; f < tips[0].size(); ++f) std::printf(" %+.2f", (tips[0][f] - tips[1][f]) / dx);
    std::printf("\n");
    for (size_t f = 0; f < tips[0].size(); ++f) EXPECT_NEAR(tips[0][f], tips[1][f], 0.5 * dx) << "frame " << f + 1;
}

// 2. A film of thickness h on an incline at angle θ, periodic along the slope, traction-free on
// top, after 0.3 s ≫ its viscous time. Returns the relative L2 error of the velocity along the
// slope against `exact(z)`, sampled one per cell through the film.
namespace {
const double kFilmDepth = 0.01, kFilmDrive = 1000 * 9.81 * std::sin(10 * M_PI / 180);  // ρ g sinθ

Scene filmScene(const json& material, int resolution) {
    const double theta = 10 * M_PI / 180, g = 9.81;
    json doc = baseScene(1.0, resolution);
    doc["domain"] = {{"min", {0, 0, 0}}, {"max", {0.005, 0.005, 0.02}}, {"resolution", resolution},
                     {"periodic", {true, true, false}}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.005, 0.005, kFilmDepth}}});
    doc["material"] = material;
    doc["gravity"] = {g * std::sin(theta), 0, -g * std::cos(theta)};
    doc["fps"] = 10;
    return parseScene(doc, "film");
}

double filmProfileError(const json& material, int resolution, const std::function<double(double)>& exact,
                        const char* label) {
    const double h = kFilmDepth;
    sim::Simulation s(filmScene(material, resolution));
    for (int f = 0; f < 3; ++f) s.advanceFrame();
    double errorSq = 0, normSq = 0;
    const double dx = s.grid().dx;
    for (double z = 0.5 * dx; z < h - dx; z += dx) {
        const double u = s.velocityAt(Vec3(0.0025, 0.0025, z)).x();
        errorSq += (u - exact(z)) * (u - exact(z));
        normSq += exact(z) * exact(z);
    }
    const double error = std::sqrt(errorSq / normSq);
    std::printf("film (%s), %d cells/h: relative L2 velocity error %.4f\n", label, int(std::lround(h / dx)), error);
    return error;
}
}  // namespace

// Newtonian, no-slip bed: u(z) = (ρ g sinθ / η)(h z − z²/2) (Nusselt). The error shrinks with Δx.
TEST(Physics, NusseltFilmProfileConverges) {
    const double eta = 1.0, h = kFilmDepth;
    const json material = {{"density", 1000}, {"viscosity", eta}};
    double previous = 1e30;
    for (int resolution : {16, 32}) {
        const double error =
            filmProfileError(material, resolution, [&](double z) { return kFilmDrive / eta * (h * z - 0.5 * z * z); },
                             "Newtonian");
        EXPECT_LT(error, 0.05);
        EXPECT_LT(error, previous);
        previous = error;
    }
}

// The frame's dissipation-weighted shear rate (FrameStats::shearRate), where diagnose starts its laws
// of γ̇: in the Nusselt film γ̇ = G (1 − z/h), G = ρ g sinθ h / η, and the mean of ln γ̇ weighted by γ̇²
// is ln G + 3 ∫₀¹ s² ln s ds = ln G − 1/3.
TEST(Physics, NusseltFilmDissipatesAtItsWeightedShearRate) {
    const double eta = 1.0, expected = kFilmDrive * kFilmDepth / eta * std::exp(-1.0 / 3);
    sim::Simulation s(filmScene({{"density", 1000}, {"viscosity", eta}}, 32));
    sim::FrameStats stats;
    for (int f = 0; f < 3; ++f) stats = s.advanceFrame();
    std::printf("film's dissipation-weighted shear rate %.3f 1/s, exact %.3f (%+.1f %%)\n", stats.shearRate, expected,
                100 * (stats.shearRate / expected - 1));
    EXPECT_NEAR(stats.shearRate, expected, 0.05 * expected);
    // Σ W γ̇² Δx³ is the film's dissipation over η: ∫ γ̇² dV = G² h A / 3.
    const double area = 0.005 * 0.005, G = kFilmDrive * kFilmDepth / eta;
    EXPECT_NEAR(stats.dissipationWeight, G * G * kFilmDepth * area / 3, 0.1 * G * G * kFilmDepth * area / 3);
}

// Shear-thinning power law τ = K γ̇ⁿ (the Picard path): the shear stress is still ρ g sinθ (h − z),
// so γ̇ = (τ/K)^{1/n} and u(z) = (ρ g sinθ/K)^{1/n} n/(n+1) [h^{(n+1)/n} − (h − z)^{(n+1)/n}].
TEST(Physics, PowerLawFilmMatchesItsProfile) {
    const double K = 3.4, n = 0.5, h = kFilmDepth;
    const json material = {{"density", 1000},
                           {"viscosity", 1.0},
                           {"model", {{"type", "power_law"}, {"consistency", K}, {"flow_index", n}}}};
    const double a = std::pow(kFilmDrive / K, 1 / n) * n / (n + 1), p = (n + 1) / n;
    const double error = filmProfileError(
        material, 16, [&](double z) { return a * (std::pow(h, p) - std::pow(h - z, p)); }, "power law n=0.5");
    EXPECT_LT(error, 0.05);
}

// A power law of index 1 is the Newtonian liquid of η = K: its Picard iterates leave η as it was, so
// each step solves once (kPicardTolerance), not picard_iterations times, and flows as the Newtonian.
TEST(Physics, PowerLawOfIndexOneFlowsAsNewtonianInOneSolveAStep) {
    json newtonian = baseScene(4.0, 24);
    newtonian["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
    newtonian["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.015, 0.04, 0.02}}});
    json powerLaw = newtonian;
    powerLaw["material"]["model"] = {{"type", "power_law"}, {"consistency", 4.0}, {"flow_index", 1.0}};
    sim::Simulation a(parseScene(newtonian, "newtonian")), b(parseScene(powerLaw, "power law n = 1"));
    long iterationsA = 0, iterationsB = 0, steps = 0;
    for (int f = 0; f < 6; ++f) {
        const sim::FrameStats frame = a.advanceFrame();
        iterationsA += frame.solverIterations;
        steps += frame.steps;
        iterationsB += b.advanceFrame().solverIterations;
    }
    double apart = 0;
    for (size_t p = 0; p < a.particles().position.size(); ++p)
        apart = std::max(apart, (a.particles().position[p] - b.particles().position[p]).norm());
    std::printf("power law n = 1 against Newtonian, %ld steps: solver iterations %ld against %ld, particles at most "
                "%.3g m apart\n", steps, iterationsB, iterationsA, apart);
    EXPECT_EQ(iterationsB, iterationsA);
    EXPECT_LT(apart, 1e-9);
}

// Carreau η = η∞ + (η0 − η∞)(1 + (λγ̇)²)^{(n−1)/2} (Carreau 1972): η0 = 5 Pa·s thins from η0 at the top
// (γ̇ → 0) to a quarter of it at the bed (λγ̇ ≈ 10 there). The stress profile is the power law's,
// ρ g sinθ (h − z); γ̇ at each height solves η(γ̇) γ̇ = τ (monotone in γ̇), found by bisection, and
// u(z) is its integral from the bed (Simpson, 400 intervals).
TEST(Physics, CarreauFilmMatchesItsProfile) {
    const double eta0 = 5.0, etaInfinity = 0.01, lambda = 0.75, n = 0.4, h = kFilmDepth;
    const json material = {{"density", 1000},
                           {"viscosity", eta0},
                           {"model", {{"type", "carreau"}, {"eta_infinity", etaInfinity}, {"relaxation_time", lambda},
                                      {"flow_index", n}}}};
    auto stress = [&](double rate) {
        return rate * (etaInfinity + (eta0 - etaInfinity) * std::pow(1 + lambda * lambda * rate * rate, 0.5 * (n - 1)));
    };
    auto rateAt = [&](double z) {
        const double tau = kFilmDrive * (h - z);
        double lo = 0, hi = tau / etaInfinity;  // η ≥ η∞ bounds the rate
        for (int i = 0; i < 200; ++i) (stress(0.5 * (lo + hi)) < tau ? lo : hi) = 0.5 * (lo + hi);
        return 0.5 * (lo + hi);
    };
    auto exact = [&](double z) {
        const int intervals = 400;
        const double step = z / intervals;
        double sum = rateAt(0) + rateAt(z);
        for (int i = 1; i < intervals; ++i) sum += (i % 2 ? 4 : 2) * rateAt(i * step);
        return sum * step / 3;
    };
    std::printf("Carreau film: λγ̇ at the bed %.1f, η there %.2f η0\n", lambda * rateAt(0),
                kFilmDrive * h / rateAt(0) / eta0);
    EXPECT_LT(filmProfileError(material, 16, exact, "Carreau n=0.4"), 0.05);
}

// Navier slip of length b on the bed: the Nusselt profile plus a slip velocity b·(du/dz)_bed =
// b ρ g sinθ h / η. b = h/5 makes the slip 40 % of the no-slip surface speed.
TEST(Physics, NavierSlipFilmMatchesItsProfile) {
    const double eta = 1.0, h = kFilmDepth, b = 0.2 * h;
    const json material = {{"density", 1000}, {"viscosity", eta}, {"slip_length", b}};
    const double error = filmProfileError(
        material, 16, [&](double z) { return kFilmDrive / eta * (h * z - 0.5 * z * z + b * h); }, "slip b=h/5");
    EXPECT_LT(error, 0.05);
}

// 2a. Poiseuille flow down a round pipe that the liquid fills, periodic along its axis: the mean
// speed is ρ g R² / (8η). The pipe's wall cuts cells at every fraction, as the sample cup's hole
// does. Liquid that fills a sealed region cannot change its volume, and before the volume
// correction knew that, its divergence target made this solve diverge (the pipe lost nearly all its
// liquid within a frame; here it turned non-finite). Claimed: the flux within 2 % at R = 7.2 Δx and
// the volume within 1 % (measured: tests/bench/FINDINGS.md, "Figures moved from test comments").
TEST(Physics, PipeFullOfLiquidCarriesPoiseuilleFlux) {
    const double radius = 0.009, rho = 1000, eta = 1.0, g = 9.81;
    json doc = baseScene(eta, 24);  // Δx = 1.25 mm across the 30 mm box
    doc["domain"] = {{"min", {-0.015, -0.015, 0}}, {"max", {0.015, 0.015, 0.005}}, {"resolution", 24},
                     {"periodic", {false, false, true}}};
    // A cup far taller than the domain, without a bottom in it: a pipe along z.
    doc["solids"] = {{{"type", "cup"}, {"position", {0, 0, -1}}, {"inner_radius", radius}, {"height", 3},
                      {"wall_thickness", 0.01}, {"bottom_thickness", 0.5}}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {-0.015, -0.015, 0}}, {"max", {0.015, 0.015, 0.005}}});
    doc["gravity"] = {0, 0, -g};
    doc["fps"] = 10;  // 0.4 s: five times ρR²/η
    sim::Simulation s(parseScene(doc, "pipe"));
    const double startVolume = s.liquidVolume();
    for (int f = 0; f < 4; ++f) s.advanceFrame();

    // The volume flux through one layer of z-faces, counting each face's open area.
    const sim::Field& w = s.fields().velocity[2];
    const sim::Field& open = s.fractions().faceOpenArea[2];
    const double dx = s.grid().dx;
    double flux = 0;
    for (int j = 0; j < w.lattice.size[1]; ++j)
        for (int i = 0; i < w.lattice.size[0]; ++i) {
            const Vec3 centre = s.grid().position(sim::kFace[2], sim::Vec3i(i, j, 0));
            if (std::hypot(centre.x(), centre.y()) < radius + dx)  // the pipe, not the box's corners
                flux -= w[w.lattice.index(i, j, 0)] * open[open.lattice.index(i, j, 0)] * dx * dx;
        }
    const double meanSpeed = flux / (M_PI * radius * radius), exact = rho * g * radius * radius / (8 * eta);
    const double volumeDrift = s.liquidVolume() / startVolume - 1;
    std::printf("pipe, R = %.1f cells: mean speed %.4f m/s against %.4f (%+.2f %%), volume drift %+.3f %%\n",
                radius / dx, meanSpeed, exact, 100 * (meanSpeed / exact - 1), 100 * volumeDrift);
    EXPECT_NEAR(meanSpeed / exact, 1.0, 0.02);
    EXPECT_LT(std::abs(volumeDrift), 0.01);
}

// 2b. The flux through the hole must hardly depend on whether the bottom's underside lies a hair
// above or below a row of z-faces (the faces as they are, without the hole's calibration). A face a
// hair outside the solid beside a cell with no non-solid volume used to stay open, and the solve
// took that cell for air, and the flux read many times higher a thousandth of a cell above the row
// than below it. With the hole's axis between columns of z-faces, the faces under the hole's rim are
// open above the row (partly, to the hole) and shut below it: the bound there is 10 %, on a column
// 1 % (measured: tests/bench/FINDINGS.md, "Figures moved from test comments").
TEST(Physics, OrificeFluxDoesNotLeakThroughAHairlineCut) {
    for (const double sideways : {0.5, 0.0}) {  // the hole's axis on a column of z-faces, then between them
        const double above = orificeFluxOverDagan(OrificeExit::BothSides, sideways, 1e-3, "grid", false);
        const double below = orificeFluxOverDagan(OrificeExit::BothSides, sideways, -1e-3, "grid", false);
        std::printf("orifice, axis %.1f cell off the faces' corners: flux %.3f × Dagan with the bottom a thousandth "
                    "of a cell above a row of faces, %.3f below (%+.2f %%)\n",
                    sideways, above, below, 100 * (above / below - 1));
        EXPECT_NEAR(above / below, 1.0, sideways == 0.5 ? 0.01 : 0.1);
    }
}

// 2c. With the hole's conductance calibrated (the default; see HoleCalibration), the steady flux
// of a cup draining into a free jet hardly depends on where the hole sits and matches the free
// exit's, sim::kFreeJetFluxOverDagan × Dagan's. The calibration solves another box, periodic
// across x and y, so this checks that its resistance carries over to a layer held by the cup's
// walls (4.8 hole radii from the axis instead of a periodic 4). The lifts differ only in the domain:
// the grid puts the bottom's underside just below a row of faces either way (sim::sceneGrid).
// The calibration before matched Dagan's flux in a box full of liquid, but draining into a free jet
// its drag let too little through (measured: tests/bench/FINDINGS.md, "Figures moved from test
// comments").
TEST(Physics, CalibratedHoleFluxMatchesTheFreeExitWhereverItSits) {
    std::vector<double> fluxes;
    for (const auto& [sideways, lift] : std::vector<std::pair<double, double>>{{0, 0.667}, {0.5, 0.667}, {0.25, 0.25}}) {
        sim::HoleCalibration calibration;
        const double grid = orificeFluxOverDagan(OrificeExit::FreeJet, sideways, lift, "grid", true);
        const double calibrated = orificeFluxOverDagan(OrificeExit::FreeJet, sideways, lift, "dagan", true, &calibration);
        std::printf("orifice into a free jet, cup %.2f cell sideways and %.3f up: faces alone %.3f × Dagan, calibrated "
                    "%.3f (resistance %.3f; in the calibration's own box %.3f × Dagan before, %.3f after)\n",
                    sideways, lift, grid, calibrated, calibration.resistance, calibration.gridFlux, calibration.calibratedFlux);
        EXPECT_NEAR(calibration.calibratedFlux / sim::kFreeJetFluxOverDagan, 1.0, 0.01);
        fluxes.push_back(calibrated / sim::kFreeJetFluxOverDagan);
    }
    const double spread = *std::max_element(fluxes.begin(), fluxes.end()) / *std::min_element(fluxes.begin(), fluxes.end()) - 1;
    std::printf("orifice into a free jet, calibrated: spread over placements %+.2f %%\n", 100 * spread);
    EXPECT_LT(spread, 0.03);
    for (const double flux : fluxes) EXPECT_NEAR(flux, 1.0, 0.03);
}

// 2d. A shear wave u_x = A sin(kz) in liquid filling a box periodic on every axis decays at the
// viscous rate νk², and the particles' affine velocities carry it across the seams: a transfer
// that took a wrapped grid sample's offset at face value put it a period L away, an error of
// C·L = 2πA on the seam's faces (a liquid slug falling through a periodic pipe blew up from it).
// The solve is backward Euler, so the decay to match is Π (1 + ν k_h² Δt)⁻¹ with the grid's own
// wavenumber k_h² = (4/Δx²) sin²(kΔx/2) (measured against it, and with the offsets taken at face
// value: tests/bench/FINDINGS.md, "Figures moved from test comments").
TEST(Physics, ShearWaveDecaysAtTheViscousRateAcrossPeriodicSeams) {
    const double eta = 1.0, rho = 1000, amplitude = 0.05, length = 0.04, k = 2 * M_PI / length, fps = 120;
    const int frames = 4;
    json doc = baseScene(eta, 16);
    doc["domain"]["periodic"] = {true, true, true};
    doc["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {length, length, length}}});
    doc["gravity"] = {0, 0, 0};
    doc["fps"] = fps;
    sim::Simulation s(parseScene(doc, "shear wave"));
    sim::Particles& particles = s.particles();
    for (size_t i = 0; i < particles.position.size(); ++i) {
        const double z = particles.position[i].z();
        particles.velocity[i] = Vec3(amplitude * std::sin(k * z), 0, 0);
        particles.affine[i].setZero();
        particles.affine[i](0, 2) = amplitude * k * std::cos(k * z);
    }
    const double dx = s.grid().dx, rate = eta / rho * 4 / (dx * dx) * std::pow(std::sin(0.5 * k * dx), 2);
    double expected = 1, worst = 0;
    for (int f = 0; f < frames; ++f) {
        const sim::FrameStats frame = s.advanceFrame();
        expected *= std::pow(1 + rate / (fps * frame.steps), -frame.steps);
        worst = std::max(worst, maxParticleSpeed(s));
    }
    double projection = 0, norm = 0;  // least-squares amplitude of u_x on sin(kz)
    for (size_t i = 0; i < particles.position.size(); ++i) {
        const double basis = std::sin(k * particles.position[i].z());
        projection += particles.velocity[i].x() * basis;
        norm += basis * basis;
    }
    const double kept = projection / norm / amplitude;
    std::printf("shear wave: amplitude kept %.4f after %.3f s, backward Euler %.4f (%+.2f %%), exact %.4f; "
                "fastest particle %.4f m/s of %.4f\n",
                kept, frames / fps, expected, 100 * (kept / expected - 1),
                std::exp(-eta / rho * k * k * frames / fps), worst, amplitude);
    EXPECT_NEAR(kept / expected, 1.0, 0.01);
    EXPECT_LT(worst, amplitude);
}

// 3. A ball in rigid rotation without gravity: rigid motion is in the null space of the viscous
// stress, so even a very viscous ball keeps its angular momentum. What a splitting scheme does
// lose: particles keep their velocity's direction while they turn by θ = ω Δt in a step, and the
// next projection removes the radial part of that field, leaving rotation at ω cos θ. So the
// best a step can keep is cos θ, whatever the viscosity (measured: tests/bench/FINDINGS.md,
// "Figures moved from test comments"); the check holds the solver to within 1 % of that limit.
TEST(Physics, RotatingViscousBallKeepsAngularMomentum) {
    for (const char* scheme : {"unified", "decoupled"}) {
        json doc = baseScene(100.0, 24);
        doc["liquids"].push_back({{"type", "box"}, {"min", {0.01, 0.01, 0.01}}, {"max", {0.03, 0.03, 0.03}}});
        doc["gravity"] = {0, 0, 0};
        doc["solver"] = {{"scheme", scheme}, {"tolerance", 1e-6}};
        Scene scene = parseScene(doc, "ball");
        sim::Simulation s(scene);
        // Spin the block about z at 10 rad/s through its particles (the initial condition).
        sim::Particles& particles = s.particles();
        const Vec3 centre(0.02, 0.02, 0.02), omega(0, 0, 10);
        for (size_t i = 0; i < particles.position.size(); ++i) {
            particles.velocity[i] = omega.cross(particles.position[i] - centre);
            particles.affine[i] << 0, -omega.z(), 0, omega.z(), 0, 0, 0, 0, 0;
        }
        const double l0 = angularMomentum(s, centre).z();
        double splittingLimit = 1;
        int steps = 0;
        for (int f = 0; f < 3; ++f) {
            const sim::FrameStats frame = s.advanceFrame();
            splittingLimit *= std::pow(std::cos(omega.z() / scene.fps / frame.steps), frame.steps);
            steps += frame.steps;
        }
        const double l1 = angularMomentum(s, centre).z();
        std::printf("rotating ball (%s): angular momentum kept %.4f after 0.1 s in %d steps (splitting limit %.4f)\n",
                    scheme, l1 / l0, steps, splittingLimit);
        EXPECT_GT(l1 / l0, 0.99 * splittingLimit);
        EXPECT_LT(l1 / l0, 1.02);
    }
}

// Nothing blows up across six decades of viscosity on the draining-cup scene. A blow-up creates
// energy, so the test holds the solver to the energy budget of this closed scene: the kinetic
// energy may never exceed the gravitational energy released since the start (the test prints its
// largest share). A bound on the fastest particle was used before; at 20³ the water's sheet
// spreading on the ground runs up the domain's corners at about twice the free-fall speed, so one
// particle's speed tells little about stability (measured: tests/bench/FINDINGS.md, "Figures moved
// from test comments").
TEST(Physics, StableFromWaterToTar) {
    auto sumOverParticles = [](const sim::Simulation& s, auto&& perParticle) {
        double sum = 0;
        for (size_t i = 0; i < s.particles().position.size(); ++i)
            sum += perParticle(s.particles().position[i], s.particles().velocity[i]);
        return sum;
    };
    for (double eta : {1e-3, 1.0, 1e3}) {
        json doc = baseScene(eta, 20);
        doc["domain"] = {{"min", {-0.09, -0.09, 0}}, {"max", {0.09, 0.09, 0.18}}, {"resolution", 20}};
        doc["solids"] = {{{"type", "ground"}, {"height", 0}},
                         {{"type", "cup"}, {"position", {0, 0, 0.1}}, {"inner_radius", 0.043}, {"height", 0.05},
                          {"wall_thickness", 0.006}, {"bottom_thickness", 0.005}, {"hole_radius", 0.018}}};
        doc["liquids"].push_back({{"type", "cup_fill"}, {"cup", 1}, {"volume", 1.7e-4}});
        doc["material"]["surface_tension"] = 0.07;
        const Scene scene = parseScene(doc, "cup");
        sim::Simulation s(scene);
        // Per unit particle mass: all particles weigh the same, and none are added or removed here.
        const size_t particleCount = s.particles().position.size();
        auto potential = [&](const Vec3& x, const Vec3&) { return -scene.gravity.dot(x); };
        auto kineticEnergy = [](const Vec3&, const Vec3& v) { return 0.5 * v.squaredNorm(); };
        const double potential0 = sumOverParticles(s, potential);
        double worstShare = 0;
        for (int f = 0; f < 6; ++f) {
            ASSERT_NO_THROW(s.advanceFrame()) << "eta=" << eta;
            ASSERT_EQ(s.particles().position.size(), particleCount);
            const double kinetic = sumOverParticles(s, kineticEnergy);
            const double released = potential0 - sumOverParticles(s, potential);
            ASSERT_TRUE(std::isfinite(kinetic)) << "eta=" << eta;
            EXPECT_LE(kinetic, released) << "eta=" << eta << ", frame " << f + 1;
            worstShare = std::max(worstShare, kinetic / released);
        }
        EXPECT_TRUE(std::isfinite(s.liquidVolume()));
        EXPECT_FALSE(s.particles().position.empty());
        std::printf("cup eta=%g Pa·s: kinetic energy at most %.2f of the potential energy released; "
                    "fastest particle %.3f m/s after 0.2 s\n",
                    eta, worstShare, maxParticleSpeed(s));
    }
}

namespace {
// VISCOSCOPE_FULL_VERIFICATION=1 (scripts/verify_physics.sh) runs the slow checks at full size;
// CI runs the same code on coarser grids.
bool fullVerification() {
    const char* v = std::getenv("VISCOSCOPE_FULL_VERIFICATION");
    return v && std::string(v) == "1";
}

// A spreading current's r(t) against the similarity law r = c · scale · t^β: the least-squares
// exponent of ln r against ln t, and the prefactor c as the mean of r / (scale t^β).
std::array<double, 2> similarityFit(const std::vector<double>& times, const std::vector<double>& radii, double scale,
                                    double beta) {
    const size_t n = times.size();
    double sx = 0, sl = 0, sxx = 0, sxl = 0, prefactor = 0;
    for (size_t i = 0; i < n; ++i) {
        const double x = std::log(times[i]), l = std::log(radii[i]);
        sx += x, sl += l, sxx += x * x, sxl += x * l;
        prefactor += radii[i] / (scale * std::pow(times[i], beta)) / n;
    }
    return {(n * sxl - sx * sl) / (n * sxx - sx * sx), prefactor};
}

double percentileRadius(const sim::Particles& p, const Vec3& axisPoint, double fraction) {
    std::vector<double> r;
    for (const Vec3& x : p.position) r.push_back(std::hypot(x.x() - axisPoint.x(), x.y() - axisPoint.y()));
    std::sort(r.begin(), r.end());
    return r.empty() ? 0 : r[static_cast<size_t>(fraction * (r.size() - 1))];
}
}  // namespace

// 4. Huppert (1982): a fixed volume V spreading on the ground under gravity and viscosity has
// front radius r_N = 0.894 (ρ g V³ t / 3η)^{1/8} and height h = H (1 − r²/r_N²)^{1/3}, with
// H = 4V / (3π r_N²). That is an intermediate asymptotic: a released column takes until r ≫ r₀ to
// forget its shape, so a fit on the slump measures the transient, not the law. The current
// therefore starts as the similarity solution at t_i (Stokes flow adjusts its velocity at once)
// and is fitted against absolute time. The law is also the thin-film (lubrication) limit, H ≪ r:
// started at t_i = 1 s (H/r = 0.36) the current lagged the law at first, on 48 and on 96 cells alike
// (physics, not the grid), and caught up over the next 10 s, which alone read as an exponent error
// beyond the 3 % goal (measured: tests/bench/FINDINGS.md, "Figures moved from test comments"). The
// full check therefore starts at t_i = 4 s (H/r = 0.21); the CI one at 1 s, to keep more cells
// across its coarser film. The front is read from the particles at a volume fraction (the 95th
// percentile of radius lies where the film is still ~½H thick, not in the sub-cell tip):
// for this profile the volume beyond ξ = r/r_N is (1 − ξ²)^{4/3}, so r_95 = r_N √(1 − 0.05^{3/4}).
TEST(Physics, HuppertViscousGravityCurrent) {
    const bool full = fullVerification();
    const double rho = 1400, eta = 50, g = 9.81, volume = 7.85e-5;
    const double scale = std::pow(rho * g * std::pow(volume, 3) / (3 * eta), 1.0 / 8);
    const double tStart = full ? 4.0 : 1.0, tEnd = full ? 16.0 : 6.0;
    const double rStart = 0.894 * scale * std::pow(tStart, 1.0 / 8);
    const double hStart = 4 * volume / (3 * M_PI * rStart * rStart);
    json doc = baseScene(eta, full ? 96 : 48);
    doc["domain"] = {{"min", {-0.075, -0.075, 0}}, {"max", {0.075, 0.075, 0.03}}, {"resolution", full ? 96 : 48}};
    doc["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
    // Scenes have no profiled liquid source: seed a box, then trim its particles to the profile.
    doc["liquids"].push_back({{"type", "box"}, {"min", {-rStart, -rStart, 0}}, {"max", {rStart, rStart, hStart}}});
    doc["material"] = {{"density", rho}, {"viscosity", eta}};
    doc["fps"] = 4;
    Scene scene = parseScene(doc, "huppert");
    sim::Simulation s(scene);
    sim::keepParticles(s.particles(), [&](const Vec3& x) {
        const double xi2 = (x.x() * x.x() + x.y() * x.y()) / (rStart * rStart);
        return xi2 < 1 && x.z() <= hStart * std::cbrt(1 - xi2);
    });
    // r_N from the particles, two ways. The second moment: for the similarity profile ⟨r²⟩ = (3/7) r_N²
    // over the volume, dominated by the resolved bulk. The 95th percentile: the volume beyond
    // ξ = r/r_N is (1 − ξ²)^{4/3}, so r_95 = r_N √(1 − 0.05^{3/4}); it reads the thin front, which
    // a late, thin current resolves with only a cell or two, so it is printed, not asserted.
    // The second moment of the grid's liquid volume fractions is printed beside them: particles
    // count as volume only while they stay evenly spread, and in the CI film they drift outwards
    // against the grid's liquid (measured: tests/bench/FINDINGS.md, "Figures moved from test
    // comments").
    const double frontFraction = std::sqrt(1 - std::pow(0.05, 0.75));
    std::vector<double> times, momentRadii, frontRadii, gridMomentRadii;
    while (s.time() + tStart < tEnd - 1e-9) {
        s.advanceFrame();
        const double t = s.time() + tStart;
        // Skip the first half second, in which the at-rest start picks up the similarity velocity.
        if (t < tStart + 0.5) continue;
        double r2 = 0;
        for (const Vec3& x : s.particles().position) r2 += x.x() * x.x() + x.y() * x.y();
        times.push_back(t);
        momentRadii.push_back(std::sqrt(7.0 / 3.0 * r2 / s.particles().position.size()));
        frontRadii.push_back(percentileRadius(s.particles(), Vec3::Zero(), 0.95) / frontFraction);
        const auto& fractions = s.fractions().cell;
        double gridR2 = 0, gridVolume = 0;
        for (int c = 0; c < fractions.lattice.count(); ++c) {
            const Vec3 x = s.grid().position(sim::kCellCentre, fractions.lattice.coords(c));
            gridR2 += fractions[c] * (x.x() * x.x() + x.y() * x.y());
            gridVolume += fractions[c];
        }
        gridMomentRadii.push_back(std::sqrt(7.0 / 3.0 * gridR2 / gridVolume));
    }
    const auto fit = [&](const std::vector<double>& radii) { return similarityFit(times, radii, scale, 1.0 / 8); };
    const auto [exponent, prefactor] = fit(momentRadii);
    const auto [frontExponent, frontPrefactor] = fit(frontRadii);
    const auto [gridExponent, gridPrefactor] = fit(gridMomentRadii);
    std::printf("Huppert (%s, %d cells across, t %.0f–%.0f s, H from %.1f to %.1f cells): second moment: exponent %.4f "
                "(theory 0.125, error %.1f%%), prefactor %.4f (theory 0.894, error %.1f%%); 95th percentile: "
                "exponent %.4f (%.1f%%), prefactor %.4f (%.1f%%); grid volume second moment: exponent %.4f (%.1f%%), "
                "prefactor %.4f (%.1f%%)\n",
                full ? "full" : "CI", s.grid().cells.x(), tStart, tEnd, hStart / s.grid().dx,
                4 * volume / (3 * M_PI * std::pow(momentRadii.back(), 2)) / s.grid().dx, exponent,
                100 * (exponent / 0.125 - 1), prefactor, 100 * (prefactor / 0.894 - 1), frontExponent,
                100 * (frontExponent / 0.125 - 1), frontPrefactor, 100 * (frontPrefactor / 0.894 - 1), gridExponent,
                100 * (gridExponent / 0.125 - 1), gridPrefactor, 100 * (gridPrefactor / 0.894 - 1));
    // Goal: exponent within 3 %, prefactor within 5 %, asserted on the particles' second moment. The
    // coarse CI film (3–5 cells) guards against regressions with 10 %.
    EXPECT_NEAR(exponent, 0.125, (full ? 0.03 : 0.10) * 0.125);
    EXPECT_NEAR(prefactor, 0.894, 0.05 * 0.894);
}

// 4a. A power-law fluid (τ = K γ̇ⁿ) spreading as a fixed volume V on the ground. Its thin-film flux
// q = n/(2n+1) (ρg/K)^{1/n} h^{(2n+1)/n} |∂h/∂r|^{1/n} has the similarity solution
// r_N = c_n (ρg/K)^{1/(3n+5)} V^{(n+2)/(3n+5)} t^β, β = n/(3n+5), Huppert's at n = 1. Zero flux at the
// axis integrates its profile once: h = H (1 − ξ^{n+1})^{1/(n+2)}, ξ = r/r_N, H = V / (2π I r_N²) with
// I = ∫₀¹ ξ (1 − ξ^{n+1})^{1/(n+2)} dξ = B(2/(n+1), (n+3)/(n+2)) / (n+1), and
// c_n = (2πI)^{−(n+2)/(3n+5)} [(n+2)/(n+1) βⁿ ((2n+1)/n)ⁿ]^{−1/(3n+5)} (0.894 / 3^{1/8} at n = 1).
// Source: Di Federico, Malaguti & Marchetti (2006); Sayag & Worster (2013).
// n = 0.5 puts β at 1/13 = 0.0769, and Newtonian spreading (0.125) 60 % above it. As in the Huppert
// check the current starts at rest as the similarity solution (its own, not the Newtonian one) at
// t_i = 0.25 s and is fitted against absolute time, up to 16 t_i. The first doubling of time is left
// out: from rest, and from a front the thin-film law makes vertical, which Stokes flow rounds off,
// the current falls behind r_N and then catches up slowly, alike on 48, 64 and 96 cells (with the
// Picard iteration converged; measured: tests/bench/FINDINGS.md, "Figures moved from test
// comments"). The CI current starts as thick as the Huppert CI one (H/r = 0.38, 5.6 cells); the
// full one, with K a third, at H/r = 0.23 on twice the cells. The bounds are the
// Huppert check's: over the fit's ln 8 they allow the same drift of ln r (0.5 % full, 1.6 % CI) as
// its bounds over its window.
TEST(Physics, PowerLawGravityCurrentSpreadsAtItsSimilarityExponent) {
    const bool full = fullVerification();
    const double rho = 1400, g = 9.81, volume = 7.85e-5, K = full ? 10 : 30, n = 0.5;
    const double beta = n / (3 * n + 5), b = (n + 3) / (n + 2);
    auto betaFunction = [](double x, double y) { return std::exp(std::lgamma(x) + std::lgamma(y) - std::lgamma(x + y)); };
    const double integral = betaFunction(2 / (n + 1), b) / (n + 1);
    const double coefficient = std::pow(2 * M_PI * integral, -(n + 2) / (3 * n + 5)) *
                               std::pow((n + 2) / (n + 1) * std::pow(beta, n) * std::pow((2 * n + 1) / n, n),
                                        -1 / (3 * n + 5));
    const double scale = std::pow(rho * g / K, 1 / (3 * n + 5)) * std::pow(volume, (n + 2) / (3 * n + 5));
    // ⟨r²⟩ over the volume is B(4/(n+1), b) / B(2/(n+1), b) r_N² (3/7 at n = 1). 5 % of the volume
    // lies beyond ξ₉₅, found from the volume beyond ξ, ∫_ξ¹ ξ' (1 − ξ'^{n+1})^{1/(n+2)} dξ' / I.
    const double secondMoment = betaFunction(4 / (n + 1), b) / betaFunction(2 / (n + 1), b);
    auto volumeBeyond = [&](double xi) {
        const int steps = 4000;  // midpoint rule; the integrand is bounded
        double sum = 0;
        for (int i = 0; i < steps; ++i) {
            const double x = xi + (i + 0.5) * (1 - xi) / steps;
            sum += x * std::pow(1 - std::pow(x, n + 1), 1 / (n + 2));
        }
        return sum * (1 - xi) / steps / integral;
    };
    double lo = 0, hi = 1;
    for (int i = 0; i < 40; ++i) (volumeBeyond(0.5 * (lo + hi)) > 0.05 ? lo : hi) = 0.5 * (lo + hi);
    const double frontFraction = 0.5 * (lo + hi);
    const double tStart = 0.25, tEnd = 16 * tStart;
    const double rStart = coefficient * scale * std::pow(tStart, beta);
    const double hStart = volume / (2 * M_PI * integral * rStart * rStart);
    const int resolution = full ? 96 : 48;
    json doc = baseScene(K, resolution);
    doc["domain"] = {{"min", {-0.075, -0.075, 0}}, {"max", {0.075, 0.075, 0.03}}, {"resolution", resolution}};
    doc["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {-rStart, -rStart, 0}}, {"max", {rStart, rStart, hStart}}});
    // The bed's shear rate falls from about 10 s⁻¹ to 1 s⁻¹ over the run. η_max binds below
    // γ̇ = (K/η_max)^{1/(1−n)} ≤ 10⁻³ s⁻¹: at the axis and in the top 3 % of the film, whose shear
    // carries no flux; η_min never binds. "viscosity" (K, η at 1 s⁻¹) only stands for the empty cells.
    doc["material"] = {{"density", rho}, {"viscosity", K},
                       {"model", {{"type", "power_law"}, {"consistency", K}, {"flow_index", n},
                                  {"eta_min", 1.0}, {"eta_max", 1e3}}}};
    doc["fps"] = 8;
    sim::Simulation s(parseScene(doc, "power-law current"));
    sim::keepParticles(s.particles(), [&](const Vec3& x) {
        const double xi = std::hypot(x.x(), x.y()) / rStart;
        return xi < 1 && x.z() <= hStart * std::pow(1 - std::pow(xi, n + 1), 1 / (n + 2));
    });
    std::vector<double> times, momentRadii, frontRadii;
    while (s.time() + tStart < tEnd - 1e-9) {
        s.advanceFrame();
        const double t = s.time() + tStart;
        if (t < 2 * tStart - 1e-9) continue;
        double r2 = 0;
        for (const Vec3& x : s.particles().position) r2 += x.x() * x.x() + x.y() * x.y();
        times.push_back(t);
        momentRadii.push_back(std::sqrt(r2 / s.particles().position.size() / secondMoment));
        frontRadii.push_back(percentileRadius(s.particles(), Vec3::Zero(), 0.95) / frontFraction);
    }
    const auto fit = [&](const std::vector<double>& radii) { return similarityFit(times, radii, scale, beta); };
    const auto [exponent, prefactor] = fit(momentRadii);
    const auto [frontExponent, frontPrefactor] = fit(frontRadii);
    std::printf("power-law current n=%.1f (%s, %d cells across, t %.2f–%.0f s, H from %.1f to %.1f cells): second "
                "moment: exponent %.4f (theory %.4f, error %.1f%%), prefactor %.4f (theory %.4f, error %.1f%%); 95th "
                "percentile: exponent %.4f (%.1f%%), prefactor %.4f (%.1f%%)\n",
                n, full ? "full" : "CI", s.grid().cells.x(), times.front(), tEnd, hStart / s.grid().dx,
                volume / (2 * M_PI * integral * std::pow(momentRadii.back(), 2)) / s.grid().dx, exponent, beta,
                100 * (exponent / beta - 1), prefactor, coefficient, 100 * (prefactor / coefficient - 1), frontExponent,
                100 * (frontExponent / beta - 1), frontPrefactor, 100 * (frontPrefactor / coefficient - 1));
    // Asserted on the particles' second moment: within 3 % (full), 10 % (CI) of 1/13; 0.125 lies far outside.
    EXPECT_NEAR(exponent, beta, (full ? 0.03 : 0.10) * beta);
}

// 4b. A Bingham column released on the ground slumps and stops where the ground's shear stress
// under its slope, ρ g h |∂h/∂r|, has fallen to the yield stress τ_y: in the thin ("pancake")
// limit h(r) = √(2τ_y (R∞ − r) / (ρg)), whose volume (8π/15) √(2τ_y/(ρg)) R∞^{5/2} = V gives
// R∞ = (15V/8π)^{2/5} (ρg/(2τ_y))^{1/5}. Source: Roussel & Coussot (2005), J. Rheol. 49, 705.
// τ_y = 12 Pa, V = 72 cm³, ρ = 1000: R∞ = 59.6 mm, H∞ = h(0) = 12.1 mm = 0.2 R∞, 4.1 cells at CI
// size. What the limit leaves out is of relative size τ_y/(ρ g H∞) = H∞/(2R∞) = 0.1 (the front, whose
// slope is no longer small, spans τ_y/(ρg) = 1.2 mm, 2 % of R∞), or its square (the plug's
// extensional stresses in the yield criterion, 1 % on R∞ ∝ τ_y^{−1/5}). Claimed: R∞ within 3 % full,
// 10 % CI; heights at r/R∞ = 0, ¼, ½, ¾ within 5 % (full), 10 % (CI) of H∞.
// R∞ is read from the particles' second moment: for this profile ⟨r²⟩ = B(4, 3/2)/B(2, 3/2) R∞²
// = (8/21) R∞². The volume beyond r = R∞ (1 − w) is (5/2) w^{3/2} − (3/2) w^{5/2}, which puts the
// 95th percentile of radius at 0.924 R∞ (printed: it reads the front, a cell or two thick).
// Heights are read from the grid's liquid fractions, over the columns within a cell of each radius,
// against the profile's mean over the same columns.
// K = 4 Pa·s: near arrest the flow slows as 1/t² on a time ∝ K, so a smaller K nears it sooner,
// while the collapse stays viscous (ρ U H / K ≲ 0.5 at its fastest, 0.1 m/s). The regularization
// caps η at η_max = 10⁴ Pa·s below yield: there the pancake creeps as a Newtonian film under a basal
// stress τ_y, which moves its second moment's radius at (21/8) π τ_y² R∞³ / (9 η_max ρ g V) = 4 μm/s,
// 0.07 % of R∞ over the run. The slump counts as arrested when that radius grows less than 0.1 % of
// R∞ over a second (15× that creep); it must arrest within 10 s, and its creep is printed.
// The slump stops 7 % short of R∞ at 48, 64 and 96 cells alike, so the full-size claim fails; the
// shortfall shrinks with τ_y (so with H∞/R∞) as the thin limit's own first-order error would
// (tests/bench/FINDINGS.md, "Yield stress sampled where it acts").
TEST(Physics, YieldStressSlumpArrestsAtItsRadius) {
    const bool full = fullVerification();
    const double rho = 1000, g = 9.81, tauY = 12, K = 4, etaMax = 1e4, volume = 7.2e-5, tCap = 10;
    const double radius = std::pow(15 * volume / (8 * M_PI), 0.4) * std::pow(rho * g / (2 * tauY), 0.2);
    const double height = std::sqrt(2 * tauY * radius / (rho * g));
    auto profile = [&](double r) { return r < radius ? std::sqrt(2 * tauY * (radius - r) / (rho * g)) : 0.0; };
    const double creep = 21.0 / 8.0 * M_PI * tauY * tauY * std::pow(radius, 3) / (9 * etaMax * rho * g * volume);
    double w = 0.5, step = 0.25;  // 5 % of the volume beyond r = R∞ (1 − w)
    for (int i = 0; i < 40; ++i, step /= 2) w += (2.5 * std::pow(w, 1.5) - 1.5 * std::pow(w, 2.5) > 0.05 ? -step : step);
    const double frontFraction = 1 - w;
    const double columnRadius = 0.03, columnHeight = volume / (M_PI * columnRadius * columnRadius);
    const int resolution = full ? 96 : 48;
    json doc = baseScene(K, resolution);
    doc["domain"] = {{"min", {-0.07, -0.07, 0}}, {"max", {0.07, 0.07, 0.03}}, {"resolution", resolution}};
    doc["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {-columnRadius, -columnRadius, 0}},
                              {"max", {columnRadius, columnRadius, columnHeight}}});
    doc["material"] = {{"density", rho}, {"viscosity", K},
                       {"model", {{"type", "herschel_bulkley"}, {"yield_stress", tauY}, {"consistency", K},
                                  {"flow_index", 1.0}, {"eta_max", etaMax}}}};
    doc["fps"] = 10;
    sim::Simulation s(parseScene(doc, "yield-stress slump"));
    sim::keepParticles(s.particles(), [&](const Vec3& x) { return std::hypot(x.x(), x.y()) < columnRadius; });
    auto momentRadius = [&] {
        double r2 = 0;
        for (const Vec3& x : s.particles().position) r2 += x.x() * x.x() + x.y() * x.y();
        return std::sqrt(21.0 / 8.0 * r2 / s.particles().position.size());
    };
    std::vector<double> radii{momentRadius()};  // one a frame
    const int window = static_cast<int>(std::lround(s.scene().fps));  // a second of frames
    double speed = NAN;
    bool arrested = false;
    while (!arrested && s.time() < tCap - 1e-9) {
        s.advanceFrame();
        radii.push_back(momentRadius());
        if (radii.size() > static_cast<size_t>(window)) {
            speed = radii.back() - radii[radii.size() - 1 - window];  // over the last second
            arrested = speed < 1e-3 * radius;
        }
    }
    const double dx = s.grid().dx, measured = radii.back();
    const double front = percentileRadius(s.particles(), Vec3::Zero(), 0.95) / frontFraction;
    const auto& fractions = s.fractions().cell;
    const sim::Lattice& cells = fractions.lattice;
    const std::array<double, 4> shares{0.0, 0.25, 0.5, 0.75};
    std::array<double, 4> heights{}, expected{};
    for (size_t a = 0; a < shares.size(); ++a) {
        int columns = 0;
        for (int j = 0; j < cells.size[1]; ++j)
            for (int i = 0; i < cells.size[0]; ++i) {
                const Vec3 x = s.grid().position(sim::kCellCentre, sim::Vec3i(i, j, 0));
                const double r = std::hypot(x.x(), x.y());
                if (std::abs(r - shares[a] * radius) > dx) continue;
                for (int k = 0; k < cells.size[2]; ++k) heights[a] += fractions[cells.index(i, j, k)] * dx;
                expected[a] += profile(r);
                ++columns;
            }
        heights[a] /= columns;
        expected[a] /= columns;
    }
    double worstHeight = 0;
    for (size_t a = 0; a < shares.size(); ++a) worstHeight = std::max(worstHeight, std::abs(heights[a] - expected[a]) / height);
    std::printf("yield-stress slump (%s, %d cells across, H∞ %.1f cells): %s at t = %.1f s; second moment: R %.4f m "
                "(theory R∞ %.4f, error %.1f%%); 95th percentile %.4f (%.1f%%); heights at r/R∞ 0, ¼, ½, ¾: %.2f %.2f %.2f "
                "%.2f cells (theory %.2f %.2f %.2f %.2f; worst %.1f%% of H∞); R grew %.1e m/s over the last second "
                "(regularized creep %.1e)\n",
                full ? "full" : "CI", s.grid().cells.x(), height / dx, arrested ? "arrested" : "NOT arrested", s.time(),
                measured, radius, 100 * (measured / radius - 1), front, 100 * (front / radius - 1), heights[0] / dx,
                heights[1] / dx, heights[2] / dx, heights[3] / dx, expected[0] / dx, expected[1] / dx, expected[2] / dx,
                expected[3] / dx, 100 * worstHeight, speed, creep);
    EXPECT_TRUE(arrested);
    EXPECT_NEAR(measured / radius, 1.0, full ? 0.03 : 0.10);
    EXPECT_LT(worstHeight, full ? 0.05 : 0.10);
}

// 5. A viscous thread falling onto the ground buckles and coils (Ribe 2004; Batty & Bridson 2008
// show it with their solver). Honey-like liquid (η = 100 Pa·s, ρ = 1400) from a 5 mm nozzle 35 mm
// up at 1 cm³/s: a viscous-regime fall (H < (ν²/g)^{1/3} ≈ 8 cm). The thread's lower part is
// followed through the centroid of the liquid in a slab 8–11 mm above the ground, above the pile:
// its largest distance from the axis (in thread radii) and how far it winds around the axis after
// 0.6 s (unwrapped angle; a planar fold flips back and forth and winds ~0 turns, a coil keeps going).
TEST(Physics, FallingViscousThreadCoils) {
    const bool full = fullVerification();
    const double radius = 0.0025;
    for (const char* scheme : {"unified", "decoupled"}) {
        json doc = baseScene(100.0, full ? 56 : 44);
        doc["domain"] = {{"min", {-0.025, -0.025, 0}}, {"max", {0.025, 0.025, 0.04}}, {"resolution", full ? 56 : 44}};
        doc["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
        doc["liquids"].push_back({{"type", "emitter"}, {"center", {0, 0, 0.035}}, {"normal", {0, 0, -1}},
                                  {"radius", radius}, {"flux", 1e-6}});
        doc["material"] = {{"density", 1400}, {"viscosity", 100.0}};
        doc["solver"] = {{"scheme", scheme}};
        sim::Simulation s(parseScene(doc, "coiling"));
        double excursion = 0, winding = 0, previousAngle = NAN;
        int turnsForward = 0, turnsBack = 0;
        const auto start = std::chrono::steady_clock::now();
        for (int f = 0; f < 36; ++f) {
            s.advanceFrame();
            Eigen::Vector2d sum = Eigen::Vector2d::Zero();
            int count = 0;
            for (const Vec3& x : s.particles().position)
                if (x.z() >= 0.008 && x.z() < 0.011) sum += x.head<2>(), ++count;
            if (count < 5) continue;
            const Eigen::Vector2d centroid = sum / count;
            excursion = std::max(excursion, centroid.norm());
            const double angle = std::atan2(centroid.y(), centroid.x());
            if (s.time() >= 0.6 && std::isfinite(previousAngle)) {
                const double step = std::remainder(angle - previousAngle, 2 * M_PI);
                winding += step;
                (step > 0 ? turnsForward : turnsBack)++;
            }
            previousAngle = angle;
        }
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::printf("coiling (%s, %d cells across): lateral excursion %.1f thread radii, winding %.2f turns after "
                    "0.6 s (%d frame steps one way, %d the other), %.0f s wall\n",
                    scheme, s.grid().cells.x(), excursion / radius, winding / (2 * M_PI),
                    std::max(turnsForward, turnsBack), std::min(turnsForward, turnsBack), seconds);
        // Both schemes buckle the thread; the claim that it coils is the unified scheme's. The
        // decoupled baseline is printed for comparison: it may fold back and forth instead, or coil
        // less steadily (measured: tests/bench/FINDINGS.md, "Figures moved from test comments").
        EXPECT_GT(excursion, radius) << scheme;
        if (std::string(scheme) == "unified") EXPECT_GT(std::abs(winding) / (2 * M_PI), 1.0);
    }
}

// 6. Against measured data: the lock-release dam break of corn syrup in
// shared/data/measured/dambreak_syrup_validation.csv (lock 0.2 m long, 0.0443 m deep, ρ = 1540,
// viscometer fit K = 9.712 Pa·sⁿ, n = 0.979, so nearly Newtonian). The channel's width is not
// known, so the channel is modelled as infinitely wide (periodic across): side-wall drag, which
// slows the real current, is missing from the model. The fronts are compared as distances from the
// lock's back wall (the source's own model comparison does the same), frame by frame.
TEST(Physics, DamBreakFrontMatchesMeasuredSyrup) {
    const std::string csv = std::string(VISCOSCOPE_SOURCE_DIR) + "/../shared/data/measured/dambreak_syrup_validation.csv";
    std::ifstream in(csv);
    if (!in) GTEST_SKIP() << "measured data not found at " << csv;
    std::vector<std::pair<double, double>> measured;
    std::string line;
    std::getline(in, line);  // header: time_s,front_m
    while (std::getline(in, line)) {
        double t, x;
        if (std::sscanf(line.c_str(), "%lf,%lf", &t, &x) == 2) measured.emplace_back(t, x);
    }
    ASSERT_GT(measured.size(), 100u);

    const bool full = fullVerification();
    const double lock = 0.2, depth = 0.0443, duration = full ? 20.0 : 8.0;
    json doc = baseScene(9.712, full ? 200 : 100);
    doc["domain"] = {{"min", {0, 0, 0}}, {"max", {0.55, 0.011, 0.055}}, {"resolution", full ? 200 : 100},
                     {"periodic", {false, true, false}}};
    doc["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {lock, 0.011, depth}}});
    doc["material"] = {{"density", 1540}, {"viscosity", 9.712},
                       {"model", {{"type", "power_law"}, {"consistency", 9.712}, {"flow_index", 0.979}}}};
    doc["fps"] = 4;
    sim::Simulation s(parseScene(doc, "dambreak"));
    double errorSq = 0, normSq = 0;
    size_t next = 0;
    std::printf("dam break (%d cells long): t, measured front, simulated front (m)\n", s.grid().cells.x());
    for (int f = 0; f < static_cast<int>(duration * 4); ++f) {
        s.advanceFrame();
        std::vector<double> x;
        for (const Vec3& p : s.particles().position) x.push_back(p.x());
        std::sort(x.begin(), x.end());
        const double front = x[static_cast<size_t>(0.999 * (x.size() - 1))] - lock;
        while (next < measured.size() && measured[next].first < s.time()) ++next;
        if (next == 0 || next >= measured.size()) continue;
        const double m = measured[next].second;  // the first sample at or after this frame (1/30 s)
        if (s.time() >= 0.5) {
            errorSq += (front - m) * (front - m);
            normSq += (m + lock) * (m + lock);
        }
        if (f % 4 == 3) std::printf("  %.2f  %.4f  %.4f\n", s.time(), m, front);
    }
    const double error = std::sqrt(errorSq / normSq);
    std::printf("dam break: RMS front error %.3f of the distance from the back wall, over 0.5–%.0f s\n", error, duration);
    EXPECT_LT(error, full ? 0.10 : 0.15);
}
