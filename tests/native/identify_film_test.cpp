// The thin-film forward model in identify against the 3D solver where both run: the 3D solver's
// Huppert check, a current released at rest, spread by each; VISCOSCOPE_FULL_VERIFICATION=1
// (scripts/verify_physics.sh) runs it on twice the 3D grid. diagnose_film_test diagnoses films.
#include "film/film.h"
#include "observe/observe.h"
#include "sim/sim.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace {

namespace fs = std::filesystem;
using namespace viscoscope;
using json = nlohmann::json;

bool fullVerification() {
    const char* v = std::getenv("VISCOSCOPE_FULL_VERIFICATION");
    return v && std::string(v) == "1";
}

// The 3D solver's Huppert check (sim_physics_test): 78.5 cm³ of a 50 Pa·s liquid released on the
// ground at rest as the similarity solution of t = 1 s, h = H (1 − (r/r_N)²)^{1/3}, and left to spread
// for 5 s. The film starts from the same profile; a disc emitter, which never emits (it starts after
// the check), places the axis.
TEST(FilmAgainstSimulation, ReleasedCurrentAgreesWithTheSolver) {
    const bool full = fullVerification();
    const int resolution = full ? 96 : 48;
    const double rho = 1400, eta = 50, g = 9.81, volume = 7.85e-5, tStart = 1, seconds = 5;
    const double scale = std::pow(rho * g * std::pow(volume, 3) / (3 * eta), 1.0 / 8);
    const double rStart = 0.894 * scale * std::pow(tStart, 1.0 / 8);
    const double hStart = 4 * volume / (3 * M_PI * rStart * rStart);
    const auto profile = [&](double r) { return r < rStart ? hStart * std::cbrt(1 - r * r / (rStart * rStart)) : 0.0; };
    json doc = {{"format", "viscoscope.scene"},
                {"version", 1},
                {"domain", {{"min", {-0.075, -0.075, 0}}, {"max", {0.075, 0.075, 0.03}}, {"resolution", resolution}}},
                {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
                {"liquids", {{{"type", "box"}, {"min", {-rStart, -rStart, 0}}, {"max", {rStart, rStart, hStart}}}}},
                {"material", {{"density", rho}, {"viscosity", eta}, {"surface_tension", 0.0}}},
                {"fps", 2},
                {"frames", static_cast<int>(seconds * 2) + 1},
                {"output", {{"particles", false}, {"vdb", false}, {"mesh", false}}}};
    const Scene scene = parseScene(doc, "released");
    sim::Simulation simulation(scene);
    sim::keepParticles(simulation.particles(), [&](const Eigen::Vector3d& x) { return x.z() <= profile(x.head<2>().norm()); });
    doc["liquids"] = {{{"type", "emitter"}, {"center", {0, 0, 0}}, {"normal", {0, 0, 1}}, {"radius", 0.005},
                       {"flux", 1e-9}, {"start", 1e3}}};
    doc["domain"]["resolution"] = 600;  // 0.25 mm: the film's own grid error well below the check's
    film::AxisymmetricFilm film(parseScene(doc, "released film"));
    film.setThickness(profile);
    const std::vector<double> radii = film.cellRadii();
    // The volume's root-mean-square distance from the axis: the bulk's reach, which both resolve
    // (the front's last cells the 3D grid does not; it is printed beside it).
    const auto filmRms = [&] {
        double moment = 0, sum = 0;
        for (size_t i = 0; i < radii.size(); ++i) {
            const double v = radii[i] * (film.thickness()[i] - film::kPrecursorThickness);
            moment += v * radii[i] * radii[i];
            sum += v;
        }
        return std::sqrt(moment / sum);
    };
    double worst = 0;
    for (int frame = 1; frame < scene.frames; ++frame) {
        simulation.advanceFrame();
        film.advanceTo(simulation.time());
        double simulated = 0;
        for (const Eigen::Vector3d& x : simulation.particles().position) simulated += x.head<2>().squaredNorm();
        simulated = std::sqrt(simulated / simulation.particles().position.size());
        const double share = filmRms() / simulated - 1;
        const double front = puddleDiameter(simulation.particles().position, Eigen::Vector3d::Zero(), {0.0, 0.005}) / 2;
        std::printf("t %.1f s: rms radius 3D %.2f mm, film %.2f mm (%+.1f %%); front 3D %.1f mm, film %.1f mm\n",
                    tStart + simulation.time(), 1e3 * simulated, 1e3 * filmRms(), 100 * share, 1e3 * front,
                    1e3 * film.frontRadius());
        worst = std::max(worst, std::abs(share));
    }
    std::printf("film against 3D (%d cells across): rms radius within %.1f %%\n", resolution, 100 * worst);
    EXPECT_LT(worst, 0.05);
}

}  // namespace
