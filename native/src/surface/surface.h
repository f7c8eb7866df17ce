// Particles → liquid surface → files. The surface is an OpenVDB narrow-band level set of the
// particles' smoothed density; it can be meshed with tools::volumeToMesh. Per-frame files:
//   frame_NNNNN.vdb   grids "surface" (level set, m), "velocity" (Vec3f, m/s), "pressure" (Pa),
//                     in world space (Blender's, Z-up, metres), cell-centred at the sim's Δx.
//   particles_NNNNN.bin  particles, little-endian: char[4] "VSCP", uint32 version (1),
//                     uint64 count, then count × {float32 position[3], float32 velocity[3]}.
//   frame_NNNNN.obj   optional triangle mesh of the surface.
// Also: the boundaries of the scene's solids as meshes, and the comparison of two simulations' fields.
#pragma once

#include "sim/sim.h"
#include "sim/solid_field.h"

#include <openvdb/openvdb.h>

#include <filesystem>
#include <vector>

namespace viscoscope::surface {

// The liquid's surface: the half level of the particles' volume density ρ(x) = V_p Σ_p G_σ(x − x_p),
// smoothed by a Gaussian of `smoothing` σ (m) and sampled on voxels of `voxelSize` (m). ρ is 1 inside
// the liquid and ½ at a flat edge whatever σ, so the surface lies where the liquid ends; across a
// stream of radius R it moves in by about σ²/2R. With σ and the voxels fixed in metres that is the
// same on every grid, unlike spheres around the particles (whose outline is the outermost
// particle, further out the more particles there are; tests/bench/surface_outline_bench, and
// tests/bench/FINDINGS.md, "Figures moved from code comments").
openvdb::FloatGrid::Ptr liquidLevelSet(const std::vector<Eigen::Vector3d>& positions, double particleVolume,
                                       double smoothing, double voxelSize);
// The surface of a simulation's liquid at its scene's surface smoothing σ, on voxels of
// σ / kVoxelsPerSmoothing: coarser voxels (the cell's half) drew that stream narrower than σ/1.5,
// which the finest reference's seeding spacing gives (FINDINGS, as above).
constexpr double kVoxelsPerSmoothing = 1.5;
double surfaceVoxelSize(double smoothing);
openvdb::FloatGrid::Ptr liquidLevelSet(const sim::Simulation& simulation);

// Removes what lies inside the simulation's solids from a liquid level set, φ ← max(φ, −d_solid):
// the smoothed particles reach a little below the ground and into walls, where no camera can see
// liquid, and a silhouette compared with footage must not include it.
void clipToSolidExterior(openvdb::FloatGrid& levelSet, const sim::SolidField& solids);

// Triangles of the zero iso-surface (quads split in two).
void meshLevelSet(const openvdb::FloatGrid& levelSet, std::vector<openvdb::Vec3s>& points,
                  std::vector<openvdb::Vec3I>& triangles);

void writeFrameVdb(const std::filesystem::path& file, const sim::Simulation& simulation,
                   openvdb::FloatGrid::Ptr levelSet);
void writeParticles(const std::filesystem::path& file, const sim::Particles& particles);
sim::Particles readParticles(const std::filesystem::path& file);
// OpenVDB's level-set meshes face inward; this writes them flipped, facing outward.
void writeObj(const std::filesystem::path& file, const std::vector<openvdb::Vec3s>& points,
              const std::vector<openvdb::Vec3I>& triangles);
// Writes the triangles with the winding they have.
void writeObj(const std::filesystem::path& file, const TriangleMesh& mesh);

// The boundary of a scene solid as outward-facing triangles, for rendering it and projecting it.
// A cup is built from its parameters as a surface of revolution with `segments` sides: its exact
// dimensions and sharp rims (a mesh of the sampled signed distance would round them off at the
// voxel size, and its outline would not be the one Blender draws). A box is 12 triangles, a mesh
// solid its file; the ground plane has no finite boundary and gives an empty mesh.
TriangleMesh solidBoundary(const Solid& solid, int segments = 96);

// The grids of one frame_NNNNN.vdb. Throws InputError naming the file and the grid.
struct FrameFields {
    openvdb::FloatGrid::Ptr surface, pressure;
    openvdb::Vec3fGrid::Ptr velocity;
};
FrameFields readFrameFields(const std::filesystem::path& file);

// Sums for relative L2 errors of a simulation's velocity and pressure against a reference's, taken
// at the reference's cell centres (its active velocity voxels) where both surfaces are inside the
// liquid (φ < 0), the reference cell and its 26 neighbours hold liquid, and every voxel the
// simulation's sample reads was written (cut cells at walls and the surface are left out). The simulation's grids are sampled trilinearly (openvdb BoxSampler), so the two
// may have different resolutions. Sums of several frames add up to the error over all of them.
struct FieldDifference {
    long samples = 0;
    double velocityError2 = 0, velocityNorm2 = 0;  // Σ|v − v_ref|², Σ|v_ref|²
    double pressureError2 = 0, pressureNorm2 = 0;  // Σ(p − p_ref)², Σp_ref²
    FieldDifference& operator+=(const FieldDifference& other);
    // sqrt(error² / norm²); NaN when the reference is zero there (e.g. the liquid at rest in frame 0).
    double relativeVelocityError() const;
    double relativePressureError() const;
};
FieldDifference compareFields(const FrameFields& reference, const FrameFields& simulation);

}  // namespace viscoscope::surface
