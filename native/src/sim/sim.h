// The forward model: a viscous free-surface liquid simulated with APIC particles on a MAC grid.
// Each step: particles → grid (APIC) → body forces and surface tension → implicit pressure and
// viscosity (StokesSolver or DecoupledViscositySolver) → grid → particles → RK3 advection.
// This is the stage's public header; everything else in sim/ is internal.
#pragma once

#include "scene/scene.h"
#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <Eigen/Core>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <iosfwd>
#include <memory>
#include <optional>
#include <random>
#include <stdexcept>
#include <vector>

namespace viscoscope {

struct TriangleMesh {
    std::vector<Eigen::Vector3d> vertices;  // world, metres
    std::vector<Eigen::Vector3i> triangles;
};
// OBJ or PLY (ASCII or binary little-endian); polygons are fan-triangulated. Throws InputError.
TriangleMesh loadMesh(const std::filesystem::path& file);

}  // namespace viscoscope

namespace viscoscope::sim {

class SolidField;
class MaterialLaw;
class GridVelocity;

// The material's dynamic viscosity (Pa·s) at shear rate γ̇ = √(2 D:D) (1/s), as the solver's law
// gives it per stress sample.
double apparentViscosity(const Material& material, double shearRate);

struct Particles {
    std::vector<Vec3> position;
    std::vector<Vec3> velocity;
    std::vector<Eigen::Matrix3d> affine;  // APIC C_p: row a is the gradient of velocity component a
};
// Keeps, in their order, the particles whose position `keep` accepts: carves a shape of liquid out
// of a seeded block.
void keepParticles(Particles& particles, const std::function<bool(const Vec3&)>& keep);

struct StepStats {
    double dt = 0;
    SolveStats solve;
    double transferSeconds = 0, solveSeconds = 0, otherSeconds = 0;
};

// A run whose particles left the real numbers: its scene asks for more than the time step can
// carry. Not bad input the reader could have refused, and not a fault of the engine's.
class Diverged : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// A share of the liquid lost (out of the domain, or into a solid) that makes a run's result
// probably wrong: a run conserves its volume to a few percent (tests/bench/FINDINGS.md, "The
// liquid's particle radius").
inline constexpr double kLostLiquidShare = 0.2;

// The share of a run's liquid lost since its fullest frame so far, fed one frame at a time.
class LiquidLoss {
public:
    explicit LiquidLoss(double initialVolume) : largestVolume_(initialVolume) {}
    // This frame's loss.
    double observe(double liquidVolume) {
        const double lost = 1 - liquidVolume / largestVolume_;
        largestVolume_ = std::max(largestVolume_, liquidVolume);
        return lost;
    }

private:
    double largestVolume_;
};

struct FrameStats {
    int frame = 0;
    int steps = 0;
    int solverIterations = 0;
    double simulatedTime = 0;
    double liquidVolume = 0;  // m³, from the cell volume fractions
    double maxSpeed = 0;      // m/s over particles
    // The shear rate the frame's flow dissipates at, at its end: exp of the mean of ln γ̇ over the
    // liquid's cells weighted by W γ̇² (a Newtonian liquid's dissipation over η), and the weight's sum
    // × Δx³ (m³/s²), to average frames with. Both 0 for a liquid at rest.
    double shearRate = 0, dissipationWeight = 0;
    double transferSeconds = 0, solveSeconds = 0, otherSeconds = 0;
    bool converged = true;
};

// A narrow-band level set (negative inside) of spheres of `radius` around the particles, rasterized
// as openvdb::tools::ParticlesToLevelSet would (through a dense box; see the .cpp), renormalized by
// tools::LevelSetTracker and smoothed by `smoothingPasses` Gaussian passes (tools::Filter). Voxel
// centres sit at `origin` + (i + ½) voxelSize, so with voxelSize = Δx they coincide with the cell
// centres.
// `halfWidth` is the narrow band's half-width in voxels.
inline constexpr double kDefaultBandHalfWidth = 3.0;
openvdb::FloatGrid::Ptr particleLevelSet(const std::vector<Vec3>& positions, double radius, double voxelSize,
                                         const Vec3& origin, int smoothingPasses,
                                         double halfWidth = kDefaultBandHalfWidth);

// The MAC grid a simulation of `scene` runs on: the domain's, lowered by under a cell (and one cell
// taller) so that the underside of the first cup with a hole lies just below a row of z-faces.
Grid sceneGrid(const Scene& scene);

// A cup's hole a few cells across passes more liquid than it should: its faces' open areas give its
// cross-section, but the grid cannot resolve the velocity's parabola across it, and the flux then
// depends on where the hole sits among the faces. As Peaceman's well
// model does for wells narrower than a reservoir grid's cells, the simulation adds a subgrid
// resistance to the faces in and around the hole, found per grid and placement by solving steady
// Stokes flow through the same hole on the same lattice: under a layer of liquid 4 hole radii
// deep, periodic sideways, with a jet as long hanging from the hole into air, as a cup drains.
// The resistance makes that box's flux kFreeJetFluxOverDagan × Dagan, Weinbaum & Pfeffer's (1982)
// Q = ΔP / (η (3/r³ + 8t/(π r⁴))) for a hole of radius r through a plate t thick with liquid on
// both sides. It is a drag proportional to η, so one calibration holds at every η and ρ. It is a
// drag rather than a smaller open area because a smaller area speeds the liquid in the hole up by
// the same factor, which drains too slowly where inertia matters. Its target is the free exit's
// flux, not Dagan's itself (a box full of liquid on both sides of the plate), which held the drain
// back once the hole emptied into a jet.
//
// kFreeJetFluxOverDagan is the flux the box's faces converge to as the lattice refines
// (tests/bench/hole_calibration.py, the means over four placements fitted linearly in Δx).
// The figures behind all of this: tests/bench/FINDINGS.md, "The hole's calibration".
inline constexpr double kFreeJetFluxOverDagan = 1.20;
struct HoleCalibration {
    int solid = 0;             // the cup's index in Scene::solids
    double resistance = 0;     // the drag on the hole's faces, β Δx²/η (VolumeFractions::faceResistance)
    double gridFlux = 0;       // the faces' steady flux without it, × Dagan's
    double calibratedFlux = 0; // with it, × Dagan's
    int solves = 0;            // steady Stokes solves it took (0: taken from the cache)
};

class Simulation {
public:
    explicit Simulation(const Scene& scene);
    ~Simulation();
    Simulation(const Simulation&) = delete;
    Simulation& operator=(const Simulation&) = delete;

    // Advances to the end of the next output frame. Throws std::runtime_error if the state becomes
    // non-finite (which a stable solver must never do; tests check it).
    FrameStats advanceFrame();
    StepStats step(double dt);  // one step of exactly dt (tests use it directly)
    double stableTimeStep() const;

    const Scene& scene() const { return scene_; }
    const Grid& grid() const { return grid_; }
    const Particles& particles() const { return particles_; }
    Particles& particles() { return particles_; }  // to set initial velocities, or carve (keepParticles)
    const StokesState& fields() const { return state_; }  // velocity on faces, pressure at cells
    const VolumeFractions& fractions() const { return fractions_; }
    double time() const { return time_; }
    int frame() const { return frame_; }
    double liquidVolume() const;
    double particleVolume() const { return particleVolume_; }  // m³ of liquid each particle carries
    // The pressure at cell c's centre (Pa) as the faces feel it: the solve's unknown scaled by the
    // cell's liquid fraction W (its rows are W ∇·u), plus the Laplace pressure outside the liquid,
    // W p + (1 − W) σκ. It is the unknown itself in full cells; beside a wall the unknown alone reads
    // far from the hydrostatic pressure (tests/bench/FINDINGS.md, "Pressures in cut cells").
    double cellPressure(int c) const;
    // Trilinear on the staggered grid; beyond the domain's walls, their ghosts (wallGhostRatio).
    Vec3 velocityAt(const Vec3& x) const;
    const SolidField& solids() const { return *solids_; }
    // The level set surface tension takes its curvature from: the particles and their images
    // across the walls, as cell-aligned voxels (negative in the liquid).
    openvdb::FloatGrid::Ptr surfaceLevelSet() const;
    // One per cup with a hole, when scene().solver.holeConductance is Dagan.
    const std::vector<HoleCalibration>& holeCalibrations() const { return holeCalibrations_; }

    // Everything a run carries from one frame to the next (particles, clock, random stream, the
    // solve's last fields as its next start), in binary. A simulation of the same scene that
    // restores it, between frames, goes on bit for bit as this one would have: `simulate` and
    // `synth` resume from it. restoreState throws InputError when `in` is not such a state of a
    // simulation on this one's grid.
    void saveState(std::ostream& out) const;
    void restoreState(std::istream& in);

private:
    // The fields saveState writes besides the particles, in its order.
    template <class Self, class Visit>
    static void forEachCarriedField(Self& self, Visit&& visit);

    // The calibration of `cup`'s hole on `grid`'s lattice, cached per hole and lattice placement.
    static HoleCalibration calibrateHole(const CupSolid& cup, const Grid& grid, const SolverSettings& solver);
    void calibrateHoles();  // every cup with a hole: holeCalibrations_ and its faces' resistance
    void setHoleResistance(const CupSolid& cup, double resistance);
    double downwardFlux(double z) const;
    void seedParticles();
    void emit(double dt);
    void computeFractions();
    GridVelocity gridVelocity() const;  // the velocity the particles read
    // The Stokes solve's problem over this step's fractions and viscosities (its divergence target
    // is the step's own).
    StokesProblem stokesProblem(double dt) const;
    SolveStats solvePressureAndViscosity(double dt, const std::array<Field, 3>& flowBeforeForces);
    void measureShearRate(FrameStats& stats) const;

    Scene scene_;
    Grid grid_;
    std::unique_ptr<SolidField> solids_;
    std::unique_ptr<MaterialLaw> material_;
    std::unique_ptr<PressureViscositySolver> solver_;
    Particles particles_;
    StokesState state_;
    VolumeFractions fractions_;
    Field liquidPhi_;                 // signed distance to the liquid surface at cell centres
    std::optional<std::vector<Vec3>> fractionsPositions_;  // the particles fractions_ and liquidPhi_ are of
    std::array<std::vector<char>, 3> validFace_;  // faces whose velocity came from particles or the solve
    Field laplacePressure_;           // (1 − W) σκ at cells near the surface, this step's
    Field cellViscosity_;
    std::array<Field, 3> edgeViscosity_;
    std::vector<double> halfCellOpen_;  // non-solid fraction of each half-cell, fixed in time
    std::vector<double> cellSolidDistance_;  // solid signed distance at cell centres
    std::vector<HoleCalibration> holeCalibrations_;
    CellBox active_;                  // cells that can hold liquid this step
    double time_ = 0;
    int frame_ = 0;
    double particleVolume_ = 0;
    std::optional<double> volumeTarget_;  // m³: the liquid the grid should see (set on the first step)
    double emitterDebt_ = 0;
    std::mt19937_64 random_;
};

}  // namespace viscoscope::sim
