// The subgrid conductance of a cup's hole (see HoleCalibration in sim.h).
#include "sim/sim.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <mutex>

namespace viscoscope::sim {

namespace {

// The calibration box reaches 4 hole radii beyond the hole's axis and each of the bottom's faces.
// Reaching 8 moved the sample cup's unscaled flux at 48³ by −0.35 % (1.2401 → 1.2357 × Dagan).
constexpr double kReachInRadii = 4.0;
constexpr double kFluxTolerance = 0.005;  // |Q / Q_Dagan − 1| at which the secant iteration stops
constexpr int kMaxSolves = 4;
// Gravity is nearly all borne by the plate, so the flow is a small remainder of a large right-hand
// side: a relative residual of 1e-6 left the flux 0.4 % off (the box's other rows of faces up to
// 12 %), 1e-8 0.004 % (the sample cup's hole at 48³, against 1e-10).
constexpr double kSolveTolerance = 1e-8;
constexpr double kMaxResistance = 100;

// Dagan, Weinbaum & Pfeffer (1982): Stokes flux through a hole of radius r in a plate t thick
// under a pressure drop ΔP, interpolating Sampson's orifice (t = 0) and Poiseuille's pipe.
double daganFlux(double pressureDrop, double viscosity, double r, double t) {
    return pressureDrop / (viscosity * (3 / (r * r * r) + 8 * t / (M_PI * r * r * r * r)));
}

}  // namespace

void Simulation::setHoleResistance(const CupSolid& cup, double resistance) {
    const double reach = cup.holeRadius + grid_.dx;
    const double zLow = cup.position.z() - 0.5 * grid_.dx;
    const double zHigh = cup.position.z() + cup.bottomThickness + 0.5 * grid_.dx;
    const Field& area = fractions_.faceOpenArea[2];
    Field& faceResistance = fractions_.faceResistance[2];
    if (faceResistance.values.empty()) faceResistance = Field(area.lattice);
    for (int f = 0; f < area.lattice.count(); ++f) {
        if (area[f] <= 0) continue;
        const Vec3 x = grid_.position(kFace[2], area.lattice.coords(f));
        if (x.z() >= zLow && x.z() <= zHigh && std::hypot(x.x() - cup.position.x(), x.y() - cup.position.y()) <= reach)
            faceResistance[f] = resistance / (grid_.dx * grid_.dx);
    }
}

// The volume flux (m³/s) downwards through the row of z-faces nearest the middle of the domain.
// In a domain periodic across x and y every row carries the same flux, the velocity being
// divergence-free, so the row's choice does not matter.
double Simulation::downwardFlux() const {
    const Field& area = fractions_.faceOpenArea[2];
    const Field& w = state_.velocity[2];
    const int k = grid_.cells[2] / 2;
    double flux = 0;
    for (int j = 0; j < area.lattice.size[1]; ++j)
        for (int i = 0; i < area.lattice.size[0]; ++i) {
            const int f = area.lattice.index(i, j, k);
            flux += area[f] * w[f];
        }
    return -flux * grid_.dx * grid_.dx;
}

HoleCalibration Simulation::calibrateHole(const CupSolid& cup, const Grid& grid, const SolverSettings& solver) {
    const double dx = grid.dx, r = cup.holeRadius, t = cup.bottomThickness;
    const int across = 2 * static_cast<int>(std::ceil(kReachInRadii * r / dx));
    const int high = static_cast<int>(std::ceil((t + 2 * kReachInRadii * r) / dx));
    // The box's lattice is the simulation's moved by whole cells, so the hole sits among its faces
    // as it does in the simulation.
    const Vec3 cells = ((cup.position - grid.origin) / dx).array().floor();
    const Vec3 hole = (cup.position - grid.origin) / dx - cells;
    const std::array<double, 7> key{dx, r, t, hole.x(), hole.y(), hole.z(), double(solver.particlesPerCell)};
    static std::mutex mutex;
    static std::map<std::array<double, 7>, HoleCalibration> cache;
    {
        const std::lock_guard<std::mutex> lock(mutex);
        if (auto found = cache.find(key); found != cache.end()) {
            HoleCalibration cached = found->second;
            cached.solves = 0;
            return cached;
        }
    }

    // A plate as thick as the cup's bottom with the same hole, spanning a box periodic along every
    // axis and full of liquid. Gravity drives the liquid through the hole: across the plate, the
    // pressure less its hydrostatic part (p + ρ g z) drops by ρ g L, L being the period along z.
    // Dagan's flux is for walls without slip, so the box has none; a scene's slip length acts on
    // top of the drag.
    Scene box;
    box.sourceFile = "hole calibration";
    const Vec3 lowCorner = Vec3(cells.x() - across / 2, cells.y() - across / 2,
                                std::floor((cup.position.z() - grid.origin.z() - kReachInRadii * r) / dx));
    box.domain.min = grid.origin + dx * lowCorner;
    box.domain.max = box.domain.min + dx * Vec3(across, across, high);
    box.domain.resolution = std::max(across, high);
    box.domain.periodic = {true, true, true};
    CupSolid plate = cup;
    plate.innerRadius = 1e3 * dx * std::max(across, high);  // its walls far outside the box
    plate.height = 2 * dx * high;
    box.solids = {plate};
    box.liquids = {LiquidBox{box.domain.min, box.domain.max}};
    box.material = Material{};
    box.material.density = 1;
    box.material.viscosity = 1;
    box.gravity = Vec3(0, 0, -1);
    box.solver = solver;
    // One decoupled step is not the steady Stokes flow (at 48³ it passed 16× Dagan's flux), so both
    // schemes take the drag the unified scheme's steady solve asks for.
    box.solver.scheme = StokesScheme::Unified;
    box.solver.holeConductance = HoleConductance::Grid;
    box.solver.tolerance = kSolveTolerance;
    box.solver.maxIterations = std::max(solver.maxIterations, 20000);
    // One implicit step from rest 10³ viscous times across the box long is the steady flow.
    const double dt = 1e3 * std::pow(dx * std::max(across, high), 2);
    const double dagan = daganFlux(dx * high, 1.0, r, t);
    auto fluxRatio = [&](double resistance) {
        Simulation simulation(box);
        simulation.setHoleResistance(plate, resistance);
        simulation.step(dt);
        return simulation.downwardFlux() / dagan;
    };

    HoleCalibration calibration;
    calibration.gridFlux = fluxRatio(0.0);
    calibration.calibratedFlux = calibration.gridFlux;
    calibration.solves = 1;
    // A drag can only slow the hole down: faces passing less than Dagan's flux are left as they are.
    if (calibration.gridFlux > 1 + kFluxTolerance) {
        // Secant on 1/Q, which the drag raises about linearly, as a resistance in series with the
        // hole's own. The first guess is from the sample cup at 48³: a resistance of 0.44 took
        // 1/Q from 0.81 to 1.
        auto excess = [](double flux) { return 1 / flux - 1; };
        double previous = 0.0, previousExcess = excess(calibration.gridFlux);
        double resistance = -2.3 * previousExcess;
        double flux = fluxRatio(resistance);
        calibration.solves = 2;
        while (std::abs(flux - 1) > kFluxTolerance && calibration.solves < kMaxSolves &&
               excess(flux) != previousExcess) {
            const double next = std::clamp(resistance - excess(flux) * (resistance - previous) /
                                                            (excess(flux) - previousExcess),
                                           0.0, kMaxResistance);
            previous = resistance;
            previousExcess = excess(flux);
            resistance = next;
            flux = fluxRatio(resistance);
            ++calibration.solves;
        }
        calibration.resistance = resistance;
        calibration.calibratedFlux = flux;
    }
    const std::lock_guard<std::mutex> lock(mutex);
    cache.emplace(key, calibration);
    return calibration;
}

}  // namespace viscoscope::sim
