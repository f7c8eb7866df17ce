// How well surface tension holds thin liquid at rest: the pressure inside a drop and inside liquid
// cylinders a few cells across, against Laplace's σ/R (2σ/R for the drop), and the fastest
// particle's speed against the capillary speed σ/η (a still liquid's would be 0).
//
// Zero gravity, η and σ as given, a cube of 0.04 m at --resolution cells. Each cylinder stands
// between the box's floor and ceiling, which count as walls and meet the surface at a right angle
// (the particles' wall images), so it reads as an infinite one. The liquid is carved from the
// seeded box; R comes from the volume the grid measures after --frames frames. The pressure is the
// liquid-weighted mean of Simulation::cellPressure over the cells within ¾ cell of the axis in the
// middle third of the height (the drop: the full cells 2 cells or more inside). A falling stream
// narrows to a cell or two at coarse grids (the sample cup's at 48³ to about 1.2 cells of radius
// 6 cm below its outlet), so this is where the curvature's resolution shows.
//
//   sim_capillary_bench [--resolution 32] [--radii 1.2,1.5,2,3,4,6.4] [--frames 3]
#include "scene/scene.h"
#include "sim/sim.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

using namespace viscoscope;

namespace {

constexpr double kBox = 0.04;  // m

struct Reading {
    double radiusCells, pressure, laplace, spuriousSpeed;
};

// Carves a drop or a cylinder (along z) of `carveRadius` (m) around `centre` out of the seeded box,
// simulates it, and reads it as above.
Reading settle(int resolution, int frames, double viscosity, double sigma, bool drop, double carveRadius,
               const sim::Vec3& centre) {
    const nlohmann::json doc = {
        {"format", "viscoscope.scene"},
        {"version", 1},
        {"domain", {{"min", {0, 0, 0}}, {"max", {kBox, kBox, kBox}}, {"resolution", resolution}}},
        {"liquids", {{{"type", "box"}, {"min", {0, 0, 0}}, {"max", {kBox, kBox, kBox}}}}},
        {"material", {{"density", 1000}, {"viscosity", viscosity}, {"surface_tension", sigma}}},
        {"gravity", {0, 0, 0}},
        {"fps", 30},
        {"frames", frames},
        {"seed", 3}};
    sim::Simulation s(parseScene(doc, "capillary bench"));
    sim::keepParticles(s.particles(), [&](const sim::Vec3& x) {
        return (drop ? (x - centre).norm() : (x - centre).head<2>().norm()) <= carveRadius;
    });
    for (int f = 0; f < frames; ++f) s.advanceFrame();

    const double dx = s.grid().dx, volume = s.liquidVolume();
    const double radius = drop ? std::cbrt(3 * volume / (4 * M_PI)) : std::sqrt(volume / (M_PI * kBox));
    const auto& w = s.fractions().cell;
    double weighted = 0, weight = 0;
    for (int c = 0; c < w.lattice.count(); ++c) {
        const sim::Vec3 x = s.grid().position(sim::kCellCentre, w.lattice.coords(c));
        const bool inside = drop ? w[c] >= 1 && (x - centre).norm() <= radius - 2 * dx
                                 : (x - centre).head<2>().norm() <= 0.75 * dx && std::abs(x.z() - centre.z()) <= kBox / 6;
        if (!inside) continue;
        weighted += w[c] * s.cellPressure(c);
        weight += w[c];
    }
    double fastest = 0;
    for (const sim::Vec3& v : s.particles().velocity) fastest = std::max(fastest, v.norm());
    return {radius / dx, weight > 0 ? weighted / weight : NAN, (drop ? 2 : 1) * sigma / radius,
            fastest / (sigma / viscosity)};
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Laplace pressure and spurious speeds of a drop and thin liquid cylinders at rest"};
    int resolution = 32, frames = 3;
    double viscosity = 1.0, sigma = 0.07;
    std::vector<double> radii{1.2, 1.5, 2, 3, 4, 6.4};
    app.add_option("--resolution", resolution, "cells along the 0.04 m box")->check(CLI::Range(8, 256));
    app.add_option("--radii", radii, "cylinder radii, in cells")->delimiter(',')->check(CLI::PositiveNumber);
    app.add_option("--frames", frames, "frames to settle (1/30 s each)")->check(CLI::Range(1, 100));
    app.add_option("--viscosity", viscosity, "η, Pa·s")->check(CLI::PositiveNumber);
    app.add_option("--surface-tension", sigma, "σ, N/m")->check(CLI::PositiveNumber);
    CLI11_PARSE(app, argc, argv);

    const double dx = kBox / resolution;
    // Off the cell centres, so that no radius meets the lattice symmetrically.
    const sim::Vec3 centre(kBox / 2 + 0.3 * dx, kBox / 2 + 0.1 * dx, kBox / 2);
    std::printf("%d³ cells of %.3f mm, η %.3g Pa·s, σ %.3g N/m, after %d frames\n", resolution, 1e3 * dx, viscosity,
                sigma, frames);
    std::printf("%-9s %8s %12s %12s %8s %14s\n", "shape", "R cells", "pressure Pa", "Laplace Pa", "ratio",
                "fastest / σ/η");
    auto print = [](const char* shape, const Reading& r) {
        std::printf("%-9s %8.2f %12.3f %12.3f %8.3f %14.3f\n", shape, r.radiusCells, r.pressure, r.laplace,
                    r.pressure / r.laplace, r.spuriousSpeed);
    };
    print("drop", settle(resolution, frames, viscosity, sigma, true, 0.2 * kBox, centre));
    for (const double cells : radii)
        print("cylinder", settle(resolution, frames, viscosity, sigma, false, cells * dx, centre));
    return 0;
}
