// Particles → liquid surface → files. The surface is an OpenVDB narrow-band level set built with
// tools::ParticlesToLevelSet and smoothed with tools::LevelSetFilter; it can be meshed with
// tools::volumeToMesh. Per-frame files:
//   frame_NNNNN.vdb   grids "surface" (level set, m), "velocity" (Vec3f, m/s), "pressure" (Pa),
//                     in world space (Blender's, Z-up, metres), cell-centred at the sim's Δx.
//   particles_NNNNN.bin  particles, little-endian: char[4] "VSCP", uint32 version (1),
//                     uint64 count, then count × {float32 position[3], float32 velocity[3]}.
//   frame_NNNNN.obj   optional triangle mesh of the surface.
#pragma once

#include "sim/sim.h"

#include <openvdb/openvdb.h>

#include <filesystem>
#include <vector>

namespace viscoscope::surface {

struct SurfaceOptions {
    double voxelsPerCell = 2;      // surface resolution relative to the simulation grid
    double particleRadius = 0.75;  // in simulation cells
    int smoothingPasses = 1;       // Gaussian LevelSetFilter passes
};

openvdb::FloatGrid::Ptr liquidLevelSet(const std::vector<Eigen::Vector3d>& positions, double cellSize,
                                       const SurfaceOptions& options = {});

// Triangles of the zero iso-surface (quads split in two).
void meshLevelSet(const openvdb::FloatGrid& levelSet, std::vector<openvdb::Vec3s>& points,
                  std::vector<openvdb::Vec3I>& triangles);

void writeFrameVdb(const std::filesystem::path& file, const sim::Simulation& simulation,
                   openvdb::FloatGrid::Ptr levelSet);
void writeParticles(const std::filesystem::path& file, const sim::Particles& particles);
sim::Particles readParticles(const std::filesystem::path& file);
void writeObj(const std::filesystem::path& file, const std::vector<openvdb::Vec3s>& points,
              const std::vector<openvdb::Vec3I>& triangles);

}  // namespace viscoscope::surface
