// The thin-film forward model against the lubrication theory of axisymmetric gravity currents: the
// constant-flux Newtonian current's similarity solution (Huppert 1982, J. Fluid Mech. 121), the
// power-law current's spreading exponent, and the arrest of a Bingham puddle (Roussel & Coussot 2005).
#include "film/film.h"

#include <gtest/gtest.h>

#include <cmath>

namespace viscoscope::film {
namespace {

constexpr double kPi = 3.14159265358979323846, kG = 9.81;

// A ground plane at z = 0 fed through a disc of 8 mm radius at the origin, in a domain `reach`
// (m) each way with `cells` radial cells.
Scene spreadScene(double flux, double reach = 0.3, int cells = 300) {
    Scene scene;
    scene.domain.min = {-reach, -reach, 0};
    scene.domain.max = {reach, reach, 0.05};
    scene.domain.resolution = 2 * cells;
    scene.solids = {GroundSolid{0}};
    DiscEmitter emitter;
    emitter.center = {0, 0, 0};
    emitter.normal = {0, 0, 1};
    emitter.radius = 0.008;
    emitter.flux = flux;
    scene.liquids = {emitter};
    scene.material.density = 1000;
    return scene;
}

// The front's spreading exponent d ln r / d ln t between t0 and t1.
double exponentBetween(AxisymmetricFilm& film, double t0, double t1) {
    film.advanceTo(t0);
    const double r0 = film.frontRadius();
    film.advanceTo(t1);
    return std::log(film.frontRadius() / r0) / std::log(t1 / t0);
}

TEST(Film, NewtonianConstantFluxFollowsHupperts) {
    const double Q = 3e-6, eta = 10;
    Scene scene = spreadScene(Q);
    scene.material.viscosity = eta;
    AxisymmetricFilm film(scene);
    const double nu = eta / scene.material.density;
    const auto similarity = [&](double t) { return 0.715 * std::pow(kG * Q * Q * Q / (3 * nu), 0.125) * std::sqrt(t); };
    for (double t : {50.0, 100.0, 200.0}) {
        film.advanceTo(t);
        EXPECT_NEAR(film.frontRadius() / similarity(t), 1.0, 0.02) << "t = " << t;
        EXPECT_NEAR(film.volume() / (Q * t), 1.0, 1e-6) << "t = " << t;
    }
    AxisymmetricFilm again(scene);
    EXPECT_NEAR(exponentBetween(again, 100, 200), 0.5, 0.01);
}

TEST(Film, PowerLawConstantFluxSpreadsWithItsSimilarityExponent) {
    for (double n : {0.5, 0.25}) {
        Scene scene = spreadScene(3e-6);
        scene.material.model = PowerLaw{10.0, n};
        AxisymmetricFilm film(scene);
        EXPECT_NEAR(exponentBetween(film, 100, 300), (2 * n + 2) / (3 * n + 5), 0.01) << "n = " << n;
    }
}

TEST(Film, SlipSpreadsFaster) {
    Scene scene = spreadScene(3e-6);
    scene.material.viscosity = 10;
    AxisymmetricFilm noSlip(scene);
    scene.material.slipLength = 2e-3;
    AxisymmetricFilm slip(scene);
    noSlip.advanceTo(100);
    slip.advanceTo(100);
    EXPECT_GT(slip.frontRadius(), 1.05 * noSlip.frontRadius());
}

TEST(Film, BinghamPuddleArrestsAtRousselAndCoussotsRadius) {
    // 100 cm³ poured in 10 s, then left to spread until it stops.
    const double Q = 1e-5, pour = 10, tauY = 20, rho = 1000;
    Scene scene = spreadScene(Q, 0.15, 300);
    std::get<DiscEmitter>(scene.liquids.front()).end = pour;
    scene.material.model = HerschelBulkley{tauY, 1.0, 1.0};
    AxisymmetricFilm film(scene);
    film.advanceTo(200);
    const double arrested = film.frontRadius();
    film.advanceTo(400);
    EXPECT_LT(std::abs(film.frontRadius() - arrested), 1e-4) << "still spreading";
    const double V = Q * pour;
    const double expected = std::pow(15 * V / (8 * kPi), 0.4) * std::pow(rho * kG / (2 * tauY), 0.2);
    EXPECT_NEAR(film.frontRadius() / expected, 1.0, 0.03);
    // The square-root profile h = sqrt(2 τ_y (R − r) / ρg), with R the film's own front.
    const std::vector<double> r = film.cellRadii();
    const double R = film.frontRadius();
    for (double share : {0.25, 0.5, 0.75}) {
        const size_t cell = static_cast<size_t>(share * R / (r[1] - r[0]));
        const double profile = std::sqrt(2 * tauY * (R - r[cell]) / (rho * kG));
        EXPECT_NEAR(film.thickness()[cell] / profile, 1.0, 0.05) << "r = " << r[cell];
    }
}

TEST(Film, RefusesWhatIsNoAxisymmetricFilm) {
    Scene scene = spreadScene(1e-6);
    EXPECT_EQ(filmProblem(scene), "");
    Scene boxed = scene;
    boxed.solids.push_back(BoxSolid{});
    EXPECT_NE(filmProblem(boxed).find("single ground plane"), std::string::npos);
    Scene carreau = scene;
    carreau.material.model = Carreau{};
    EXPECT_NE(filmProblem(carreau).find("carreau"), std::string::npos);
    Scene dam = scene;
    dam.liquids = {LiquidBox{{-0.1, -0.1, 0}, {0.1, 0.1, 0.05}}};
    EXPECT_NE(filmProblem(dam).find("disc emitters only"), std::string::npos);
    Scene raised = scene;
    std::get<DiscEmitter>(raised.liquids.front()).center.z() = 0.02;
    EXPECT_NE(filmProblem(raised).find("on the ground"), std::string::npos);
    EXPECT_THROW(AxisymmetricFilm{boxed}, InputError);
}

}  // namespace
}  // namespace viscoscope::film
