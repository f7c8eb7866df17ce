// A simulation is a function of its scene and seed alone: identification compares evaluations
// that ran on different numbers of threads, and resuming must reproduce a run that was cut short.
#include "sim/sim.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdio>

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
