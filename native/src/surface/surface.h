// Particles → liquid surface → files. The surface is an OpenVDB narrow-band level set of spheres
// around the particles, closed by an inset (sim::particleLevelSet); it can be meshed with
// tools::volumeToMesh. Per-frame files:
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

struct SurfaceOptions {
    // Lengths are in units of the scale liquidLevelSet is given, the simulation cell at the default
    // 8 particles per cell (see surfaceScale).
    double voxelsPerCell = 2;      // surface resolution: voxels per unit
    double particleRadius = 0.75;
    // How far the renormalized union of the spheres is moved inwards: with the spheres' radius this
    // is a morphological closing, which fills the gaps between particles and leaves convex edges
    // where the liquid ends. The spheres alone reach 0.46–0.54 cells beyond the liquid they fill, so
    // a coarser grid would draw wider streams and puddles and bias an identification across
    // resolutions; with the inset the reach is −0.07…+0.05 cells for streams, films, a film's edge and
    // a drop of seeded particles, and up to 0.06 cells less once they have flowed
    // (tests/native/surface_solids_test).
    // Not smoothed: Gaussian passes move curved surfaces inwards as curvature flow does, and the
    // edge of a film one cell thick, like the front of a spreading puddle, receded 0.67 cells. The
    // sample cup's puddle at η = 1 then covered an area of radius 74.4 / 77.6 mm at 48³ / 64³ where
    // the particles reached 78.6 / 80.3 mm: the coarse grid's puddle looked 4 % narrower.
    double inset = 0.47;
};

// The unit of SurfaceOptions for a simulation's particles: twice their seeding spacing, which is the
// cell at 8 per cell. The spheres must shrink with the spacing for the inset to keep the surface at
// the liquid's edge: at 27 per cell, spheres sized to the cell would reach further out.
double surfaceScale(double cellSize, int particlesPerCell);

openvdb::FloatGrid::Ptr liquidLevelSet(const std::vector<Eigen::Vector3d>& positions, double scale,
                                       const SurfaceOptions& options = {});
// The surface of a simulation's liquid: its particles at surfaceScale of its grid and seeding.
openvdb::FloatGrid::Ptr liquidLevelSet(const sim::Simulation& simulation, const SurfaceOptions& options = {});

// Removes what lies inside the simulation's solids from a liquid level set, φ ← max(φ, −d_solid):
// the particle spheres reach a fraction of a cell below the ground and into walls, where no
// camera can see liquid, and a silhouette compared with footage must not include it.
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
