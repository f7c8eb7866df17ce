#include "sim/sim.h"

#include "sim/advection.h"
#include "sim/apic_transfer.h"
#include "sim/body_forces.h"
#include "sim/grid_velocity.h"
#include "sim/material_model.h"
#include "sim/solid_field.h"
#include "sim/surface_tension.h"
#include "sim/velocity_extrapolation.h"
#include "sim/volume_fractions.h"
#include "sim/wall_images.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <unistd.h>

namespace viscoscope::sim {

namespace {

// The set-up's loops over every cell take seconds at 128³ around a mesh solid: they poll a cancel
// once a z-slab.
void pollCancelEachSlab(const Lattice& cells, int c, const char* what) {
    if (c % (cells.size[0] * cells.size[1]) == 0) throwIfCancelled(what);
}

// Volume correction (after Kim et al. 2007): the liquid the grid sees drifts where particle layers
// squeeze together, as in a thinning film, since its surface sits a fixed fraction of a cell beyond
// them. The pressure solve aims at a divergence that returns it to its first measured volume (plus
// what emitters added since) over this time.
constexpr double kVolumeRelaxationTime = 0.1;  // s
// A Picard iterate that moves η (RMS over the liquid, relative) by less than this ends the step's
// iteration. Ten times looser let a Bingham slump creep on past its arrest (its plugs' capped η
// hardly moves while their flow still does); this one leaves the slump and the power-law current as
// they were (tests/bench/FINDINGS.md, "Picard iterations while η changes").
constexpr double kPicardTolerance = 1e-3;
// The start of motion: until liquid released at rest could have fallen the domain's height, a step
// is at most this share of √(Δx/g). The CFL limit alone lets the first steps span 2 cells of fall,
// and liquid then gathers speed too late: the first liquid's tip out of the hole trailed a finer
// grid's, and identification took η low to make up for it (tests/bench/FINDINGS.md, the first
// section, "Identification on the sample cup: what was measured on the way to Table 1").
constexpr double kStartupStepShare = 0.2;

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

bool insideSource(const LiquidSource& source, const std::vector<Solid>& solids, const Vec3& x) {
    if (const auto* box = std::get_if<LiquidBox>(&source))
        return (x.array() >= box->min.array()).all() && (x.array() <= box->max.array()).all();
    if (const auto* fill = std::get_if<CupFill>(&source)) {
        const CupSolid& cup = std::get<CupSolid>(solids[fill->cup]);
        const double r = std::hypot(x.x() - cup.position.x(), x.y() - cup.position.y());
        const double zInner = cup.position.z() + cup.bottomThickness;
        const double level = fill->volume / (M_PI * cup.innerRadius * cup.innerRadius);
        const bool inCavity = r < cup.innerRadius && x.z() >= zInner && x.z() <= zInner + level;
        const bool inHole = r < cup.holeRadius && x.z() >= cup.position.z() && x.z() < zInner;
        return inCavity || inHole;
    }
    return false;  // emitters add liquid over time, not at the start
}

}  // namespace

// The grid is lowered by under a cell, and given one more layer of cells on top so that it still
// covers the domain, until the underside of the first cup with a hole lies just below a row of
// z-faces. Where the underside falls between faces decides how fast the pendant stream under the
// hole extends, by an error of order Δx; just below a face it is converged already at 48³. It is
// put a fiftieth of a cell below the face, not on it, where rounding would decide whether the face is shut.
// Lowered, never raised: a ground at the domain's floor stays inside the grid. The ground then sits
// wherever the fall puts it, and that moves the puddle by an error of order Δx too; a Δx that put
// both in place identified better but still far off, so the grid is left as it is. A slumping block
// spreads less only where the lowest x- and y-faces lie in the ground and are shut: the bulk's error
// is not the cup's foot's. (tests/bench/FINDINGS.md, "Where the grid sits under the cup".)
// Peak memory of a run, measured on the sample cup (tests/bench/FINDINGS.md): the process itself,
// then the per-cell fields, sub-cell solid fractions and particles of a partly filled domain.
constexpr double kBaseBytes = 110e6;
constexpr double kBytesPerCell = 470;

// A lower bound on the cost of a step on any machine: the per-step passes over every cell (fractions,
// transfers, the solve's set-up) take at least this (tests/bench/FINDINGS.md, "The least a step costs").
constexpr double kLeastSecondsPerCellStep = 20e-9;
constexpr double kMaxRunSeconds = 30 * 86400.0;

// What this machine cannot run is refused before anything is allocated: a grid larger than its
// memory (rather than bad_alloc, or the kernel's OOM killer, part way through), and a run that would
// take over a month even at the largest step gravity allows (stableTimeStep: CFL·√(Δx/g)), which
// is a duration or fps in another unit.
void requireRunFits(const Scene& scene, const Grid& grid) {
    if (scaleLimitsWaived()) return;
    const double cells = double(grid.cells[0]) * grid.cells[1] * grid.cells[2];
    const double needed = kBaseBytes + kBytesPerCell * cells;
    const double available = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
    std::ostringstream text;
    text << std::setprecision(3) << scene.sourceFile.filename().string() << ": ";
    if (available > 0 && needed > available) {
        text << "domain.resolution " << scene.domain.resolution << ": " << cells << " cells need about "
             << needed / 1e9 << " GB, more than this machine's " << available / 1e9 << " GB; lower the resolution"
             << kWaiveHint;
        throw InputError(text.str());
    }
    const double g = scene.gravity.norm();
    if (!(g > 0)) return;
    const double duration = scene.frames / scene.fps;
    const double steps = duration / (scene.solver.cfl * std::sqrt(grid.dx / g));
    const double seconds = steps * cells * kLeastSecondsPerCellStep;
    if (seconds > kMaxRunSeconds) {
        text << "frames / fps: " << scene.frames << " frames at " << scene.fps << " fps are " << duration
             << " s of flow, at least " << steps << " steps on " << cells << " cells: over " << seconds / 86400
             << " days on any machine; is the fps in another unit?" << kWaiveHint;
        throw InputError(text.str());
    }
}

Grid sceneGrid(const Scene& scene) {
    Grid grid;
    grid.origin = scene.domain.min;
    grid.dx = scene.cellSize();
    grid.cells = scene.cellCounts();
    grid.periodic = scene.domain.periodic;
    const CupSolid* cup = firstHoledCup(scene);
    if (grid.periodic[2] || !cup) return grid;
    constexpr double kUndersideBelowFace = 0.02;  // cells
    const double height = (cup->position.z() - grid.origin.z()) / grid.dx;
    double lowering = (1 - kUndersideBelowFace) - (height - std::floor(height));
    if (lowering < 0) lowering += 1;
    constexpr double kPlaced = 1e-9;  // cells: already placed, but for rounding
    if (lowering > kPlaced && lowering < 1 - kPlaced) {
        grid.origin.z() -= lowering * grid.dx;
        ++grid.cells[2];
    }
    return grid;
}

Simulation::Simulation(const Scene& scene)
    : scene_(scene), grid_(sceneGrid(scene)), random_(scene.seed) {
    requireRunFits(scene, grid_);
    solids_ = std::make_unique<SolidField>(scene.solids, grid_);
    material_ = std::make_unique<MaterialLaw>(scene.material);
    solver_ = makeSolver(scene.solver.scheme == StokesScheme::Unified);

    const Lattice cells = grid_.lattice(kCellCentre);
    state_.pressure = Field(cells);
    liquidPhi_ = Field(cells);
    laplacePressure_ = Field(cells);
    cellViscosity_ = Field(cells, scene.material.viscosity);
    fractions_.cell = Field(cells);
    for (int a = 0; a < 3; ++a) {
        state_.velocity[a] = Field(grid_.lattice(kFace[a]));
        state_.normalStress[a] = Field(cells);
        state_.shearStress[a] = Field(grid_.lattice(kEdge[a]));
        edgeViscosity_[a] = Field(grid_.lattice(kEdge[a]), scene.material.viscosity);
        fractions_.face[a] = Field(grid_.lattice(kFace[a]));
        fractions_.edge[a] = Field(grid_.lattice(kEdge[a]));
        validFace_[a].assign(fractions_.face[a].lattice.count(), 0);
    }
    cellSolidDistance_.resize(cells.count());
    for (int c = 0; c < cells.count(); ++c) {
        pollCancelEachSlab(cells, c, "sampling the solids");
        cellSolidDistance_[c] = solids_->distance(grid_.position(kCellCentre, cells.coords(c)));
    }

    halfCellOpen_ = halfCellOpenFractions(*solids_, grid_);
    openFaces(*solids_, grid_, halfCellOpen_, fractions_);
    if (scene.solver.holeConductance == HoleConductance::Dagan) calibrateHoles();

    seedParticles();
    if (particles_.position.empty() &&
        std::none_of(scene.liquids.begin(), scene.liquids.end(),
                     [](const LiquidSource& s) { return std::holds_alternative<DiscEmitter>(s); }))
        throw InputError(scene.sourceFile.filename().string() +
                         ": liquids: the liquid sources hold no liquid outside the solids");
    computeFractions();
}

Simulation::~Simulation() = default;

void keepParticles(Particles& particles, const std::function<bool(const Vec3&)>& keep) {
    size_t kept = 0;
    for (size_t p = 0; p < particles.position.size(); ++p) {
        if (!keep(particles.position[p])) continue;
        particles.position[kept] = particles.position[p];
        particles.velocity[kept] = particles.velocity[p];
        particles.affine[kept] = particles.affine[p];
        ++kept;
    }
    particles.position.resize(kept);
    particles.velocity.resize(kept);
    particles.affine.resize(kept);
}

void Simulation::seedParticles() {
    const int perCell = scene_.solver.particlesPerCell;
    const int perAxis = static_cast<int>(std::round(std::cbrt(perCell)));
    const bool stratified = perAxis * perAxis * perAxis == perCell;
    particleVolume_ = std::pow(grid_.dx, 3) / perCell;
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const Lattice cells = grid_.lattice(kCellCentre);
    for (int c = 0; c < cells.count(); ++c) {
        pollCancelEachSlab(cells, c, "seeding the liquid");
        const Vec3i ijk = cells.coords(c);
        for (int s = 0; s < perCell; ++s) {
            // Jittered stratified seeding: one particle per sub-cell, at a random point in it.
            Vec3 sub(unit(random_), unit(random_), unit(random_));
            if (stratified) sub = (sub + Vec3(s % perAxis, (s / perAxis) % perAxis, s / (perAxis * perAxis))) / perAxis;
            const Vec3 x = grid_.origin + grid_.dx * (ijk.cast<double>() + sub);
            if (solids_->distance(x) <= kSolidMargin * grid_.dx) continue;
            const bool liquid = std::any_of(scene_.liquids.begin(), scene_.liquids.end(),
                                            [&](const LiquidSource& src) { return insideSource(src, scene_.solids, x); });
            if (!liquid) continue;
            particles_.position.push_back(x);
            particles_.velocity.push_back(Vec3::Zero());
            particles_.affine.push_back(Eigen::Matrix3d::Zero());
        }
    }
}

void Simulation::emit(double dt) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (const LiquidSource& source : scene_.liquids) {
        const auto* e = std::get_if<DiscEmitter>(&source);
        if (!e || time_ + dt <= e->start || time_ >= e->end) continue;
        const double active = std::min(time_ + dt, e->end) - std::max(time_, e->start);
        const double speed = e->flux / (M_PI * e->radius * e->radius);
        emitterDebt_ += e->flux * active;
        // An orthonormal frame on the disc.
        const Vec3 t1 = e->normal.unitOrthogonal(), t2 = e->normal.cross(t1);
        for (; emitterDebt_ >= particleVolume_; emitterDebt_ -= particleVolume_) {
            const double r = e->radius * std::sqrt(unit(random_)), theta = 2 * M_PI * unit(random_);
            const Vec3 x = e->center + r * (std::cos(theta) * t1 + std::sin(theta) * t2) +
                           e->normal * (speed * active * unit(random_));
            if (solids_->distance(x) <= 0) continue;
            particles_.position.push_back(x);
            particles_.velocity.push_back(speed * e->normal);
            particles_.affine.push_back(Eigen::Matrix3d::Zero());
            if (volumeTarget_) *volumeTarget_ += particleVolume_;
        }
    }
}

// The particles are the fractions' only input, and a frame's last fractions are the next step's first.
void Simulation::computeFractions() {
    if (fractionsPositions_ && particles_.position == *fractionsPositions_) return;
    fractionsPositions_ = particles_.position;
    liquidDistance(particles_.position,
                   wallImages(particles_.position, *solids_, grid_, cellSolidDistance_, kLiquidKernelRadius * grid_.dx),
                   grid_, liquidPhi_);
    active_ = activeCells(particles_.position, grid_);
    liquidFractions(liquidPhi_, halfCellOpen_, grid_, active_, fractions_);
}
openvdb::FloatGrid::Ptr Simulation::surfaceLevelSet() const {
    std::vector<Vec3> points = particles_.position;
    const std::vector<Vec3> images =
        wallImages(particles_.position, *solids_, grid_, cellSolidDistance_, curvatureWallReach(grid_.dx));
    points.insert(points.end(), images.begin(), images.end());
    return curvatureLevelSet(points, grid_);
}
StokesProblem Simulation::stokesProblem(double dt) const {
    StokesProblem problem;
    problem.grid = &grid_;
    problem.weights = &fractions_;
    problem.dt = dt;
    problem.density = scene_.material.density;
    problem.cellViscosity = &cellViscosity_;
    problem.edgeViscosity = &edgeViscosity_;
    problem.slipLength = scene_.material.slipLength;
    problem.solidDistance = [this](const Vec3& x) { return solids_->distance(x); };
    problem.tolerance = scene_.solver.tolerance;
    problem.maxIterations = scene_.solver.maxIterations;
    return problem;
}

// Where a law of γ̇ must match the flow to dissipate as a Newtonian one does: to first order in
// ln γ̇, at the W γ̇²-weighted mean of ln γ̇. Diagnose starts its power law there.
void Simulation::measureShearRate(FrameStats& stats) const {
    const ShearRates rates = shearRates(stokesProblem(0), state_.velocity);
    double weight = 0, weightedLog = 0;
    for (int c = 0; c < rates.cell.lattice.count(); ++c) {
        const double rate = rates.cell[c], w = fractions_.cell[c] * rate * rate;
        if (fractions_.cell[c] < kMinWeight || !(w > 0)) continue;
        weight += w;
        weightedLog += w * std::log(rate);
    }
    if (!(weight > 0)) return;
    stats.shearRate = std::exp(weightedLog / weight);
    stats.dissipationWeight = weight * std::pow(grid_.dx, 3);
}

double Simulation::cellPressure(int c) const {
    return fractions_.cell[c] * state_.pressure[c] + laplacePressure_[c];
}

GridVelocity Simulation::gridVelocity() const {
    return GridVelocity(grid_, state_.velocity, fractions_, *solids_, scene_.material.slipLength);
}

Vec3 Simulation::velocityAt(const Vec3& x) const { return gridVelocity()(x); }
double Simulation::stableTimeStep() const {
    double maxSpeed = 0;
    for (const Vec3& v : particles_.velocity) maxSpeed = std::max(maxSpeed, v.norm());
    const double dx = grid_.dx;
    // Gravity can accelerate a resting liquid across a cell within one step; count it in.
    const double g = scene_.gravity.norm();
    double dt = scene_.solver.cfl * dx / (maxSpeed + std::sqrt(g * dx) + 1e-12);
    if (g > 0) {
        const double height = std::abs((scene_.domain.max - scene_.domain.min).dot(scene_.gravity / g));
        if (time_ < std::sqrt(2 * height / g)) dt = std::min(dt, kStartupStepShare * std::sqrt(dx / g));
    }
    const double sigma = scene_.material.surfaceTension;
    if (sigma > 0) {
        // Capillary wave limit (Brackbill et al. 1992) with the mean density of the two sides, ρ/2
        // at a free surface. The implicit viscosity damps the grid-scale capillary waves that set
        // it, which Galusinski & Vigneaux (2008) fold in as ½(τ_η + √(τ_η² + 4 τ_c²)) with
        // τ_η = C η̄ Δx / σ, η̄ the mean viscosity of the two sides. At honey viscosities the
        // capillary limit then no longer binds, and as η → 0 it returns to Brackbill's.
        // η̄ = η/2 against the air, with η the smallest in the liquid: only shear-dependent laws
        // vary it from cell to cell, so only they need the sweep.
        double eta = scene_.material.viscosity;
        if (material_->shearDependent())
            for (int c = 0; c < cellViscosity_.lattice.count(); ++c)
                if (fractions_.cell[c] >= kMinWeight) eta = std::min(eta, cellViscosity_[c]);
        dt = std::min(dt, capillaryTimeStep(scene_.material.density, sigma, eta, dx));
    }
    return dt;
}

// The implicit pressure–viscosity solve, aiming at the volume correction's divergence, with a
// shear-dependent law's η by Picard iteration from the flow before this step's forces.
SolveStats Simulation::solvePressureAndViscosity(double dt, const std::array<Field, 3>& flowBeforeForces) {
    SolveStats stats;
    StokesProblem problem = stokesProblem(dt);
    if (const double gridVolume = liquidVolume(); gridVolume > 0) {
        if (!volumeTarget_) volumeTarget_ = gridVolume;
        problem.divergence = (*volumeTarget_ - gridVolume) / (gridVolume * std::max(kVolumeRelaxationTime, 2 * dt));
    }
    const int picard = material_->shearDependent() ? scene_.solver.picardIterations : 1;
    const std::array<Field, 3> uStar = state_.velocity;
    for (int it = 0; it < picard; ++it) {
        // η from the flow before the forces first, then from the last iterate's shear rates. Once
        // an iterate moves η by less than kPicardTolerance, the last solve's flow stands: a power
        // law at n = 1 (a diagnosis's base-equivalent point) then costs one solve a step, not
        // picard_iterations.
        const double change =
            updateViscosity(*material_, scene_.material.viscosity, problem,
                            it == 0 && material_->shearDependent() ? flowBeforeForces : state_.velocity,
                            cellViscosity_, edgeViscosity_);
        if (it > 0 && change < kPicardTolerance) break;
        if (it > 0) state_.velocity = uStar;
        const SolveStats s = solver_->solve(problem, state_);
        stats.iterations += s.iterations;
        stats.residual = s.residual;
        stats.unknowns = s.unknowns;
        stats.converged = s.converged;
    }
    return stats;
}

// One step: the terms in the order they act on the flow.
StepStats Simulation::step(double dt) {
    throwIfCancelled("simulation");
    StepStats stats;
    stats.dt = dt;
    auto t0 = Clock::now();
    emit(dt);
    particlesToGrid(particles_, grid_, fractions_, state_.velocity, validFace_);
    stats.transferSeconds += secondsSince(t0);

    t0 = Clock::now();
    computeFractions();
    extrapolateVelocity(state_.velocity, validFace_, fractions_, active_, 2);
    // The first Picard iterate's shear rates come from the flow before this step's forces: gravity's
    // g Δt, uniform in the liquid but cut to zero at the walls, reads as a shear of g Δt / Δx there
    // and yields a liquid at rest (tests/bench/FINDINGS.md, "Shear-dependent laws and yield stress").
    std::array<Field, 3> flowBeforeForces;
    if (material_->shearDependent()) flowBeforeForces = state_.velocity;
    addGravity(state_.velocity, fractions_, active_, scene_.gravity, dt);
    if (const double sigma = scene_.material.surfaceTension; sigma > 0)
        applySurfaceTension(*surfaceLevelSet(), sigma, scene_.material.density, dt, grid_, fractions_, active_,
                            laplacePressure_, state_.velocity);
    stats.otherSeconds += secondsSince(t0);

    t0 = Clock::now();
    stats.solve = solvePressureAndViscosity(dt, flowBeforeForces);
    stats.solveSeconds += secondsSince(t0);

    t0 = Clock::now();
    markSolvedFaces(state_.velocity, validFace_, fractions_, active_);
    extrapolateVelocity(state_.velocity, validFace_, fractions_, active_, 3);
    gridToParticles(gridVelocity(), particles_);
    stats.transferSeconds += secondsSince(t0);

    t0 = Clock::now();
    advectParticles(particles_, gridVelocity(), dt, *solids_, grid_, cellSolidDistance_);
    stats.otherSeconds += secondsSince(t0);
    time_ += dt;
    return stats;
}

FrameStats Simulation::advanceFrame() {
    FrameStats stats;
    const double end = (frame_ + 1) / scene_.fps;
    while (time_ < end - 1e-12) {
        double dt = stableTimeStep();
        const double remaining = end - time_;
        // Split what is left of the frame evenly rather than ending on a sliver of a step.
        dt = remaining <= dt ? remaining : remaining / std::ceil(remaining / dt);
        const StepStats s = step(dt);
        ++stats.steps;
        stats.solverIterations += s.solve.iterations;
        stats.converged = stats.converged && s.solve.converged;
        stats.transferSeconds += s.transferSeconds;
        stats.solveSeconds += s.solveSeconds;
        stats.otherSeconds += s.otherSeconds;
    }
    time_ = end;
    ++frame_;
    computeFractions();  // so that the frame's volume and weights describe its end state
    for (const Vec3& x : particles_.position)
        if (!x.allFinite())
            throw Diverged("the simulation diverged at frame " + std::to_string(frame_) +
                           " (a particle's position is no longer a number): lower the CFL number, or check η, σ, "
                           "gravity and the emitters");
    stats.frame = frame_;
    stats.simulatedTime = time_;
    stats.liquidVolume = liquidVolume();
    for (const Vec3& v : particles_.velocity) stats.maxSpeed = std::max(stats.maxSpeed, v.norm());
    measureShearRate(stats);
    return stats;
}

double Simulation::liquidVolume() const {
    double sum = 0;
    for (double w : fractions_.cell.values) sum += w;
    return sum * std::pow(grid_.dx, 3);
}

}  // namespace viscoscope::sim
