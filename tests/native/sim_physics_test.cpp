// Physics checks of the forward model against analytic solutions. Each prints the figures it
// measures; bounds are the accuracy we claim, not what happened to pass.
#include "sim/sim.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

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

// Nothing blows up across six decades of viscosity on the draining-cup scene.
TEST(Physics, StableFromWaterToTar) {
    for (double eta : {1e-3, 1.0, 1e3}) {
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
        EXPECT_FALSE(s.particles().position.empty());
        std::printf("cup eta=%g Pa·s: max speed %.3f m/s after 0.2 s\n", eta, maxParticleSpeed(s));
    }
}

namespace {
// VISCOSCOPE_FULL_VERIFICATION=1 (scripts/verify_physics.sh) runs the slow checks at full size;
// CI runs the same code on coarser grids.
bool fullVerification() {
    const char* v = std::getenv("VISCOSCOPE_FULL_VERIFICATION");
    return v && std::string(v) == "1";
}

double percentileRadius(const sim::Particles& p, const Vec3& axisPoint, double fraction) {
    std::vector<double> r;
    for (const Vec3& x : p.position) r.push_back(std::hypot(x.x() - axisPoint.x(), x.y() - axisPoint.y()));
    std::sort(r.begin(), r.end());
    return r.empty() ? 0 : r[static_cast<size_t>(fraction * (r.size() - 1))];
}
}  // namespace

// 4. Huppert (1982): a fixed volume V spreading on the ground under gravity and viscosity has
// front radius r_N = 0.894 (ρ g V³ t / 3η)^{1/8}. Fit r⁸ = A (t − t₀) (the virtual origin absorbs
// the initial collapse), then the exponent of r against t − t₀ and the prefactor.
TEST(Physics, HuppertViscousGravityCurrent) {
    const bool full = fullVerification();
    // A tall column, so that the current stays several cells thick while it spreads to twice r0.
    const double rho = 1400, eta = 50, g = 9.81, r0 = 0.025, h0 = 0.04;
    const double volume = M_PI * r0 * r0 * h0;
    json doc = baseScene(eta, full ? 96 : 48);
    doc["domain"] = {{"min", {-0.07, -0.07, 0}}, {"max", {0.07, 0.07, 0.05}}, {"resolution", full ? 96 : 48}};
    doc["solids"] = {{{"type", "ground"}, {"height", 0.0}}};
    // Scenes have no cylindrical liquid source: seed a box, then trim its particles to a cylinder.
    doc["liquids"].push_back({{"type", "box"}, {"min", {-r0, -r0, 0}}, {"max", {r0, r0, h0}}});
    doc["material"] = {{"density", rho}, {"viscosity", eta}};
    doc["fps"] = 4;
    Scene scene = parseScene(doc, "huppert");
    sim::Simulation s(scene);
    sim::Particles& p = s.particles();
    for (size_t i = p.position.size(); i-- > 0;)
        if (std::hypot(p.position[i].x(), p.position[i].y()) > r0) {
            p.position.erase(p.position.begin() + i);
            p.velocity.erase(p.velocity.begin() + i);
            p.affine.erase(p.affine.begin() + i);
        }
    std::vector<double> times, radii;
    const int frames = full ? 24 : 16;
    for (int f = 0; f < frames; ++f) {
        s.advanceFrame();
        if (s.time() >= 1.0) {
            times.push_back(s.time());
            radii.push_back(percentileRadius(s.particles(), Vec3::Zero(), 0.99));
        }
    }
    // Least squares r⁸ = A t + B, so t₀ = −B/A.
    const size_t n = times.size();
    double st = 0, sy = 0, stt = 0, sty = 0;
    for (size_t i = 0; i < n; ++i) {
        const double y = std::pow(radii[i], 8);
        st += times[i], sy += y, stt += times[i] * times[i], sty += times[i] * y;
    }
    const double a = (n * sty - st * sy) / (n * stt - st * st), b = (sy - a * st) / n, t0 = -b / a;
    double sx = 0, sl = 0, sxx = 0, sxl = 0;
    for (size_t i = 0; i < n; ++i) {
        const double x = std::log(times[i] - t0), l = std::log(radii[i]);
        sx += x, sl += l, sxx += x * x, sxl += x * l;
    }
    const double exponent = (n * sxl - sx * sl) / (n * sxx - sx * sx);
    const double prefactor = std::pow(a / (rho * g * std::pow(volume, 3) / (3 * eta)), 1.0 / 8);
    std::printf("Huppert (%s, %d cells across): r(t_end)=%.4f m, t0=%.2f s, exponent %.4f (theory 0.125, error %.1f%%), "
                "prefactor %.4f (theory 0.894, error %.1f%%)\n",
                full ? "full" : "CI", s.grid().cells.x(), radii.back(), t0, exponent, 100 * (exponent / 0.125 - 1),
                prefactor, 100 * (prefactor / 0.894 - 1));
    // Goal at full size: exponent within 3 %, prefactor within 5 %. The CI grid leaves the current
    // only ~3 cells thick, so there it guards against regressions with 15 % / 10 %.
    EXPECT_NEAR(exponent, 0.125, (full ? 0.03 : 0.15) * 0.125);
    EXPECT_NEAR(prefactor, 0.894, (full ? 0.05 : 0.10) * 0.894);
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
                       {"model", {{"type", "power_law"}, {"consistency", 9.712}, {"index", 0.979}}}};
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
