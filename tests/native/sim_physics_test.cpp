// Physics checks of the forward model against analytic solutions. Each prints the figures it
// measures; bounds are the accuracy we claim, not what happened to pass.
#include "sim/sim.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>

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

}  // namespace

// 1. A layer of liquid resting in a box stays at rest. Spurious speeds are measured against the
// speed of falling one cell, sqrt(g Δx) (0.157 m/s here). Claimed: below 5 % of it without surface
// tension; with σ the particle-built curvature is noisy and parasitic currents reach ~20 %, which
// this bound (25 %) documents rather than hides.
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
        EXPECT_LT(worst, (sigma > 0 ? 0.25 : 0.05) * fallSpeed);
        EXPECT_LT(std::abs(drift), 0.01);
    }
}

// 2. A film of thickness h on an incline at angle θ, periodic along the slope, no-slip on the bed
// and traction-free on top: u(z) = (ρ g sinθ / η)(h z − z²/2) (Nusselt). Error shrinks with Δx.
TEST(Physics, NusseltFilmProfileConverges) {
    const double h = 0.01, theta = 10 * M_PI / 180, rho = 1000, eta = 1.0, g = 9.81;
    double previous = 1e30;
    for (int resolution : {16, 32}) {
        json doc = baseScene(eta, resolution);
        doc["domain"] = {{"min", {0, 0, 0}}, {"max", {0.005, 0.005, 0.02}}, {"resolution", resolution},
                         {"periodic", {true, true, false}}};
        doc["liquids"].push_back({{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.005, 0.005, h}}});
        doc["gravity"] = {g * std::sin(theta), 0, -g * std::cos(theta)};
        doc["fps"] = 10;
        sim::Simulation s(parseScene(doc, "film"));
        for (int f = 0; f < 3; ++f) s.advanceFrame();  // 0.3 s ≫ the 0.04 s viscous time ρh²/(2.5η)
        double errorSq = 0, normSq = 0;
        const double dx = s.grid().dx;
        for (double z = 0.5 * dx; z < h - dx; z += dx) {
            const double exact = rho * g * std::sin(theta) / eta * (h * z - 0.5 * z * z);
            const double u = s.velocityAt(Vec3(0.0025, 0.0025, z)).x();
            errorSq += (u - exact) * (u - exact);
            normSq += exact * exact;
        }
        const double error = std::sqrt(errorSq / normSq);
        std::printf("Nusselt film %d cells/h: relative L2 velocity error %.4f\n", int(std::lround(h / dx)), error);
        EXPECT_LT(error, 0.05);
        EXPECT_LT(error, previous);
        previous = error;
    }
}

// 3. A ball in rigid rotation without gravity: rigid motion is in the null space of the viscous
// stress, so even a very viscous ball keeps its angular momentum.
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
        for (int f = 0; f < 3; ++f) s.advanceFrame();
        const double l1 = angularMomentum(s, centre).z();
        std::printf("rotating ball (%s): angular momentum kept %.4f after 0.1 s\n", scheme, l1 / l0);
        EXPECT_GT(l1 / l0, 0.9);
        EXPECT_LT(l1 / l0, 1.02);
    }
}

// Nothing blows up from syrup to tar on the draining-cup scene. (Known gap: at η = 1e-3 Pa·s,
// water, the stream breaks up and the step grows unstable; see issue notes.)
TEST(Physics, StableFromSyrupToTar) {
    for (double eta : {1.0, 1e3}) {
        json doc = baseScene(eta, 20);
        doc["domain"] = {{"min", {-0.09, -0.09, 0}}, {"max", {0.09, 0.09, 0.18}}, {"resolution", 20}};
        doc["solids"] = {{{"type", "ground"}, {"height", 0}},
                         {{"type", "cup"}, {"position", {0, 0, 0.1}}, {"inner_radius", 0.043}, {"height", 0.05},
                          {"wall_thickness", 0.006}, {"bottom_thickness", 0.005}, {"hole_radius", 0.018}}};
        doc["liquids"].push_back({{"type", "cup_fill"}, {"cup", 1}, {"volume", 1.7e-4}});
        doc["material"]["surface_tension"] = 0.07;
        sim::Simulation s(parseScene(doc, "cup"));
        for (int f = 0; f < 6; ++f) ASSERT_NO_THROW(s.advanceFrame()) << "eta=" << eta;
        EXPECT_TRUE(std::isfinite(s.liquidVolume()));
        EXPECT_LT(maxParticleSpeed(s), 5.0) << "eta=" << eta;  // free fall over the scene is < 2 m/s
        std::printf("cup eta=%g Pa·s: max speed %.3f m/s after 0.2 s\n", eta, maxParticleSpeed(s));
    }
}
