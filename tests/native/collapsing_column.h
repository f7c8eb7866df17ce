// The collapsing column the identify and diagnose tests share: a viscous column of 1400 kg/m³
// liquid collapsing along x (front speed ∝ 1/η early on), its job, and a lab-like measured track of
// a reference run.
#pragma once

#include "observe/observe.h"
#include "scene/scene.h"
#include "sim/sim.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

namespace viscoscope::column {

using json = nlohmann::json;

inline json sceneJson(double eta, int resolution, unsigned seed, int frames) {
    return {{"format", "viscoscope.scene"},
            {"version", 1},
            {"domain", {{"min", {0, 0, 0}}, {"max", {0.1, 0.04, 0.06}}, {"resolution", resolution}}},
            {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
            {"liquids", {{{"type", "box"}, {"min", {0.0, 0.0, 0.0}}, {"max", {0.035, 0.04, 0.045}}}}},
            {"material", {{"density", 1400}, {"viscosity", eta}, {"surface_tension", 0.0}}},
            {"fps", 30},
            {"frames", frames},
            {"seed", seed},
            {"output", {{"particles", false}, {"vdb", false}, {"mesh", false}}}};
}

// The column's job: η searched from 10 Pa·s on 20 cells with seed 3, without a reference (the test
// adds silhouettes or a track).
inline json columnJobJson() {
    return {{"format", "viscoscope.job"},
            {"version", 1},
            {"scene", "scene.json"},
            {"parameters", {{{"name", "viscosity"}, {"initial", 10.0}, {"spread", 10.0}, {"min", 1e-2}, {"max", 1e3}}}},
            {"resolution", 20},  // a 16³ grid puts E's minimum above the truth
            {"max_generations", 12},
            {"tolerance_x", 0.01},
            {"seed", 3}};
}

// The reference run of `scene` (its resolution and seed) sampled `fps` times a second for `frames`
// frames (by default 60 times a second for a third of a second) into a CSV, as a lab would measure
// it: the front along x from `gate`, and the reach from the vertical through `wall`.
inline void writeMeasuredTrack(json scene, const Eigen::Vector3d& gate, const Eigen::Vector3d& wall,
                               const std::filesystem::path& file, int frames = 20, int fps = 60) {
    using namespace viscoscope;
    scene["fps"] = fps;
    sim::Simulation reference(parseScene(scene, "reference scene"));
    const GroundObservables ground{0.0, 0.005};
    std::ofstream csv(file);
    csv << "time_s,front_m,radius_m\n";
    for (int frame = 0; frame <= frames; ++frame) {
        if (frame > 0) reference.advanceFrame();
        const auto& particles = reference.particles().position;
        csv << double(frame) / fps << "," << frontAlongGround(particles, gate, Eigen::Vector3d::UnitX(), ground) << ","
            << puddleDiameter(particles, wall, ground) / 2 << "\n";
    }
}

}  // namespace viscoscope::column
