// A simulation is a function of its scene and seed alone: identification compares evaluations
// that ran on different numbers of threads, and resuming must reproduce a run that was cut short.
#include "sim/sim.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdio>
#include <sstream>

using namespace viscoscope;

namespace {

// A block of liquid slumping in a box, large enough (about 30 000 rows in the solve) that the
// solver's parallel sums split into many pieces.
sim::Particles slumpedBlock(int threads) {
    const nlohmann::json doc = {
        {"format", "viscoscope.scene"},
        {"version", 1},
        {"domain", {{"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.04}}, {"resolution", 32}}},
        {"liquids", {{{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.025, 0.025, 0.0125}}}}},
        {"material", {{"density", 1000}, {"viscosity", 1.0}, {"surface_tension", 0.07}}},
        {"fps", 30},
        {"frames", 2},
        {"seed", 5}};
    sim::Particles particles;
    tbb::task_arena(threads).execute([&] {
        sim::Simulation s(parseScene(doc, "block"));
        s.advanceFrame();
        s.advanceFrame();
        particles = s.particles();
    });
    return particles;
}

}  // namespace

TEST(Determinism, ParticlesDoNotDependOnTheThreadCount) {
    const sim::Particles one = slumpedBlock(1), two = slumpedBlock(2);
    ASSERT_EQ(one.position.size(), two.position.size());
    double largest = 0;
    for (size_t p = 0; p < one.position.size(); ++p)
        largest = std::max({largest, (one.position[p] - two.position[p]).cwiseAbs().maxCoeff(),
                            (one.velocity[p] - two.velocity[p]).cwiseAbs().maxCoeff()});
    std::printf("largest difference between 1 and 2 threads, %zu particles after 2 frames: %g\n",
                one.position.size(), largest);
    EXPECT_EQ(largest, 0.0);
}

// A run restored from the state another saved between frames goes on bit for bit as that one
// did: the particles, the clock, an emitter's random stream and the solve's warm start all come
// back. Surface tension and an emitter pouring onto a slumping block exercise each of them.
TEST(Determinism, ARestoredRunGoesOnBitForBit) {
    nlohmann::json doc = {
        {"format", "viscoscope.scene"},
        {"version", 1},
        {"domain", {{"min", {0, 0, 0}}, {"max", {0.04, 0.04, 0.04}}, {"resolution", 20}}},
        {"liquids", {{{"type", "box"}, {"min", {0, 0, 0}}, {"max", {0.025, 0.025, 0.0125}}},
                     {{"type", "emitter"}, {"center", {0.02, 0.02, 0.03}}, {"normal", {0, 0, -1}},
                      {"radius", 0.003}, {"flux", 2e-6}}}},
        {"material", {{"density", 1000}, {"viscosity", 1.0}, {"surface_tension", 0.07}}},
        {"fps", 30},
        {"frames", 4},
        {"seed", 5}};
    const Scene scene = parseScene(doc, "pour");
    sim::Simulation whole(scene), first(scene);
    for (int f = 0; f < 4; ++f) whole.advanceFrame();
    first.advanceFrame();
    first.advanceFrame();
    std::stringstream state;
    first.saveState(state);

    sim::Simulation resumed(scene);
    resumed.restoreState(state);
    EXPECT_EQ(resumed.frame(), 2);
    resumed.advanceFrame();
    resumed.advanceFrame();
    ASSERT_EQ(resumed.particles().position.size(), whole.particles().position.size());
    EXPECT_GT(whole.particles().position.size(), first.particles().position.size());  // the emitter poured
    double largest = 0;
    for (size_t p = 0; p < whole.particles().position.size(); ++p)
        largest = std::max({largest, (resumed.particles().position[p] - whole.particles().position[p]).cwiseAbs().maxCoeff(),
                            (resumed.particles().velocity[p] - whole.particles().velocity[p]).cwiseAbs().maxCoeff(),
                            (resumed.particles().affine[p] - whole.particles().affine[p]).cwiseAbs().maxCoeff()});
    double pressure = 0;
    for (size_t c = 0; c < whole.fields().pressure.values.size(); ++c)
        pressure = std::max(pressure, std::abs(resumed.fields().pressure[c] - whole.fields().pressure[c]));
    std::printf("restored at frame 2 of 4: largest particle difference %g, pressure %g Pa, %zu particles\n", largest,
                pressure, whole.particles().position.size());
    EXPECT_EQ(largest, 0.0);
    EXPECT_EQ(pressure, 0.0);
    EXPECT_EQ(resumed.time(), whole.time());

    // A state from another grid is refused, and whatever it read is not half applied.
    doc["domain"]["resolution"] = 16;
    sim::Simulation other(parseScene(doc, "coarser pour"));
    const size_t seeded = other.particles().position.size();
    state.clear();
    state.seekg(0);
    EXPECT_THROW(other.restoreState(state), InputError);
    EXPECT_EQ(other.frame(), 0);
    EXPECT_EQ(other.particles().position.size(), seeded);
    std::stringstream garbage("not a state at all");
    EXPECT_THROW(other.restoreState(garbage), InputError);
}
