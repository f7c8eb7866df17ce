// How wide the particle surface draws a simulation's falling stream, against the surface's
// smoothing, its voxel size and the particles' density: what a silhouette sees of the same liquid on
// another grid.
//
// Reads the particles a `simulate`/`synth` run wrote (SIM/particles_NNNNN.bin and its scene,
// SIM/simulation.json) and surfaces them as the engine does (surface::liquidLevelSet), at each
// --smoothing-mm σ (default: the recorded scene's), each --voxel-mm (default: the engine's for σ)
// and each --coarsen c: a random 1/c³ of the particles at c times the spacing, as a grid c times
// coarser seeds them. It meshes each surface and prints the stream's mean outline
// width along x (what a camera on the y axis sees: the spread of the mesh's vertices in 2 mm bins
// of height, between the outlet of the first holed cup and a quarter of its fall above the ground,
// within 3 hole radii of its axis) and the diameter of a disc holding the liquid the particles
// carry in the same bins. With the defaults the first line is the surface `simulate` writes.
//
//   surface_outline_bench --sim DIR [--frames 10,15,...] [--smoothing-mm 1.4] [--voxel-mm 1.9,0.9]
//                         [--coarsen 1,2]
#include "scene/scene.h"
#include "surface/surface.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

using namespace viscoscope;

namespace {

constexpr double kBin = 0.002;  // m of height per outline sample

struct Stream {
    Eigen::Vector2d axis;
    double zLow = 0, zHigh = 0, reach = 0;
    bool contains(const Eigen::Vector3d& x) const {
        return x.z() >= zLow && x.z() < zHigh && (x.head<2>() - axis).norm() < reach;
    }
    // The top bin also takes the remainder of the range below zHigh.
    int bin(double z) const { return std::min(static_cast<int>((z - zLow) / kBin), bins() - 1); }
    int bins() const { return static_cast<int>((zHigh - zLow) / kBin); }
};

// Mean over the bins with liquid of the outline's width along x, in metres.
double meanOutlineWidth(const std::vector<openvdb::Vec3s>& points, const Stream& stream) {
    std::vector<double> lo(stream.bins(), INFINITY), hi(stream.bins(), -INFINITY);
    for (const openvdb::Vec3s& p : points) {
        const Eigen::Vector3d x(p.x(), p.y(), p.z());
        if (!stream.contains(x)) continue;
        const int b = stream.bin(x.z());
        lo[b] = std::min(lo[b], x.x());
        hi[b] = std::max(hi[b], x.x());
    }
    double sum = 0;
    int count = 0;
    for (int b = 0; b < stream.bins(); ++b)
        if (hi[b] > lo[b]) {
            sum += hi[b] - lo[b];
            ++count;
        }
    return count > 0 ? sum / count : NAN;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Outline width of a simulated stream against the surface's voxel size and particle density"};
    std::string simDir;
    std::vector<int> frames{10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 60}, coarsen{1, 2};
    std::vector<double> smoothingMm, voxelMm;
    app.add_option("--sim", simDir, "folder with particles_NNNNN.bin and simulation.json")->required();
    app.add_option("--frames", frames, "frames to average over")->delimiter(',');
    app.add_option("--smoothing-mm", smoothingMm, "surface smoothing σ (default: the recorded scene's)")->delimiter(',');
    app.add_option("--voxel-mm", voxelMm, "surface voxel sizes (default: what the engine picks for each σ)")
        ->delimiter(',');
    app.add_option("--coarsen", coarsen, "keep 1/c³ of the particles at c times the spacing")->delimiter(',');
    CLI11_PARSE(app, argc, argv);
    try {
        openvdb::initialize();
        const std::filesystem::path dir(simDir);
        const Scene scene = loadRecordedScene(dir / "simulation.json");
        const CupSolid* cup = firstHoledCup(scene);
        const std::optional<double> ground = groundHeight(scene);
        if (!cup || !ground) throw InputError(simDir + ": the scene needs a cup with a hole above the ground");
        Stream stream;
        stream.axis = cup->position.head<2>();
        stream.zHigh = cup->position.z() - scene.cellSize();
        stream.zLow = *ground + 0.25 * (cup->position.z() - *ground);
        stream.reach = 3 * cup->holeRadius;
        if (smoothingMm.empty()) smoothingMm.push_back(1000 * scene.surfaceSmoothing());

        // The liquid the particles carry, as the diameter of a disc per bin (mean over bins with liquid).
        const double volume = std::pow(scene.cellSize(), 3) / scene.solver.particlesPerCell;  // per particle
        double carried = 0;
        int carriedBins = 0;
        std::vector<std::vector<Eigen::Vector3d>> positions;
        for (int frame : frames) {
            char name[64];
            std::snprintf(name, sizeof name, "particles_%05d.bin", frame);
            positions.push_back(surface::readParticles(dir / name).position);
            std::vector<int> count(stream.bins(), 0);
            for (const Eigen::Vector3d& x : positions.back())
                if (stream.contains(x)) ++count[stream.bin(x.z())];
            for (int c : count)
                if (c > 0) {
                    carried += 2 * std::sqrt(c * volume / kBin / M_PI);
                    ++carriedBins;
                }
        }
        if (carriedBins == 0) throw InputError(simDir + ": no liquid below the outlet in the given frames");
        std::printf("%s: %zu frames, cell %.3f mm; the particles carry a disc %.3f mm across\n", simDir.c_str(),
                    frames.size(), 1000 * scene.cellSize(), 1000 * carried / carriedBins);
        std::printf("%8s %9s %9s %11s %9s %7s\n", "coarsen", "σ mm", "voxel mm", "outline mm", "/ carried",
                    "frames");
        for (int c : coarsen)
            for (double sigmaMm : smoothingMm)
                for (double vMm : voxelMm.empty() ? std::vector<double>{1000 * surface::surfaceVoxelSize(sigmaMm / 1000)}
                                                  : voxelMm) {
                    std::mt19937 random(7);
                    std::uniform_real_distribution<double> unit(0, 1);
                    double sum = 0;
                    int drawn = 0;  // frames whose surface reaches the stream's bins
                    for (const auto& all : positions) {
                        std::vector<Eigen::Vector3d> kept;
                        for (const Eigen::Vector3d& x : all)
                            if (unit(random) * c * c * c < 1) kept.push_back(x);
                        const auto levelSet =
                            surface::liquidLevelSet(kept, c * c * c * volume, sigmaMm / 1000, vMm / 1000);
                        std::vector<openvdb::Vec3s> points;
                        std::vector<openvdb::Vec3I> triangles;
                        surface::meshLevelSet(*levelSet, points, triangles);
                        const double width = meanOutlineWidth(points, stream);
                        if (std::isfinite(width)) {
                            sum += width;
                            ++drawn;
                        }
                    }
                    const double width = sum / drawn;
                    std::printf("%8d %9.3f %9.3f %11.3f %9.3f %7d\n", c, sigmaMm, vMm, 1000 * width,
                                width / (carried / carriedBins), drawn);
                }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "surface_outline_bench: %s\n", e.what());
        return 2;
    }
}
