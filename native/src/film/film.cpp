// Finite volumes on annular cells, backward Euler, Newton on the tridiagonal system. Written by hand:
// a 1D degenerate-diffusion solve of a few hundred unknowns is smaller than any library's set-up,
// and only its linear solve (Eigen's SparseLU, which pivots: the Jacobian is not diagonally dominant
// where the front floods the precursor) is a library's.
#include "film/film.h"

#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace viscoscope::film {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Newton converges when no thickness moves by more than this share of the thickest (plus 0.1 nm).
constexpr double kNewtonTolerance = 1e-8;
constexpr int kMaxNewtonIterations = 25;
// The front may cross this many cells per step: backward Euler's timing error at the front, which
// is all the observable sees, stays a fraction of a cell.
constexpr double kMaxFrontCellsPerStep = 1;
constexpr double kMinStep = 1e-6;  // s
constexpr int kMinCells = 8;

// The ground's height, or NaN when the scene's solids are not a single ground plane.
double singleGroundHeight(const Scene& scene) {
    if (scene.solids.size() != 1) return NAN;
    const auto* ground = std::get_if<GroundSolid>(&scene.solids.front());
    return ground ? ground->height : NAN;
}

// How far the film may spread from its axis at `c`: to the domain's nearest side.
double reachFrom(const Scene& scene, const Eigen::Vector2d& c) {
    return std::min({c.x() - scene.domain.min.x(), scene.domain.max.x() - c.x(), c.y() - scene.domain.min.y(),
                     scene.domain.max.y() - c.y()});
}

}  // namespace

std::string filmProblem(const Scene& scene) {
    const double ground = singleGroundHeight(scene);
    if (std::isnan(ground)) return "the thin-film model needs a single ground plane as the scene's only solid";
    if (scene.gravity.x() != 0 || scene.gravity.y() != 0 || !(scene.gravity.z() < 0))
        return "the thin-film model needs gravity along -z";
    if (scene.liquids.empty()) return "the thin-film model needs a disc emitter as the liquid's source";
    const DiscEmitter* first = nullptr;
    for (size_t i = 0; i < scene.liquids.size(); ++i) {
        const auto* emitter = std::get_if<DiscEmitter>(&scene.liquids[i]);
        if (!emitter) return "liquids[" + std::to_string(i) + "]: the thin-film model takes disc emitters only";
        if (std::abs(emitter->center.z() - ground) > emitter->radius)
            return "liquids[" + std::to_string(i) + "]: the thin-film model needs the emitter on the ground (within its radius)";
        if (!first) first = emitter;
        if ((emitter->center.head<2>() - first->center.head<2>()).norm() > 1e-6)
            return "liquids[" + std::to_string(i) + "]: the thin-film model needs every emitter at one centre";
    }
    const Eigen::Vector2d c = first->center.head<2>();
    const double reach = reachFrom(scene, c);
    if (!(reach >= kMinCells * scene.cellSize()))
        return "the thin-film model needs " + std::to_string(kMinCells) +
               " cells or more from the emitters' centre to the domain's nearest side";
    if (!sim::MaterialLaw(scene.material).yieldingPowerLaw())
        return "the thin-film model holds newtonian, power_law and herschel_bulkley materials, not carreau";
    return "";
}

AxisymmetricFilm::AxisymmetricFilm(const Scene& scene) {
    if (const std::string problem = filmProblem(scene); !problem.empty()) throw InputError(problem);
    dr_ = scene.cellSize();
    const Eigen::Vector2d c = std::get<DiscEmitter>(scene.liquids.front()).center.head<2>();
    const double reach = reachFrom(scene, c);
    const int cells = static_cast<int>(reach / dr_);
    for (int i = 0; i < cells; ++i) area_.push_back(kPi * dr_ * dr_ * (2.0 * i + 1.0));
    h_.assign(cells, kPrecursorThickness);
    rhoG_ = scene.material.density * -scene.gravity.z();
    law_ = *sim::MaterialLaw(scene.material).yieldingPowerLaw();
    slipLength_ = scene.material.slipLength;
    for (const LiquidSource& source : scene.liquids) {
        const auto& e = std::get<DiscEmitter>(source);
        emitters_.push_back({e.radius, e.flux, e.start, e.end});
    }
}

AxisymmetricFilm::FaceFlux AxisymmetricFilm::faceFlux(double faceRadius, double inner, double outer) const {
    const double h = 0.5 * (inner + outer), slope = (outer - inner) / dr_;
    // A vanishing slope keeps the Newtonian flux's derivative in the slope, which Newton needs to
    // start from a flat film.
    const double G = std::max(std::abs(slope), 1e-12);
    const double m = 1 / law_.index, n = law_.index;
    const double plugDepth = law_.yieldStress / (rhoG_ * G);  // above Y the liquid moves as a plug
    const double Y = h - plugDepth;
    if (h <= 0 || Y <= 0) return {0, 0, 0};
    const double dYdG = plugDepth / G;
    const double shear = std::pow(rhoG_ * G / law_.consistency, m);  // (ρgG/K)^(1/n)
    const double Ym = std::pow(Y, m);
    const double c = n / (n + 1), b = n / (2 * n + 1), bracket = h - b * Y;
    // q(h, G) of the header, and its partial derivatives.
    double q = c * shear * Ym * Y * bracket;
    const double dqdY = c * shear * ((1 + m) * Ym * bracket - Ym * Y * b);
    double dqdh = c * shear * ((1 + m) * Ym * bracket + Ym * Y * (1 - b));
    double dqdG = c * m * shear / G * Ym * Y * bracket + dqdY * dYdG;
    if (slipLength_ > 0) {  // the base slides at ℓ γ̇_base, γ̇_base = (ρgGY/K)^(1/n)
        q += slipLength_ * h * shear * Ym;
        dqdh += slipLength_ * shear * Ym * (1 + h * m / Y);
        dqdG += slipLength_ * h * shear * Ym * m * (1 / G + dYdG / Y);
    }
    // Outward flux through the face: down the slope.
    const double sign = slope > 0 ? 1.0 : (slope < 0 ? -1.0 : 0.0);
    const double perimeter = 2 * kPi * faceRadius;
    return {-sign * perimeter * q, perimeter * (-sign * 0.5 * dqdh + dqdG / dr_),
            perimeter * (-sign * 0.5 * dqdh - dqdG / dr_)};
}

bool AxisymmetricFilm::step(double dt) {
    const int cells = static_cast<int>(h_.size());
    // Each emitter's volume over the step, spread over the cells its disc overlaps.
    std::vector<double> emitted(cells, 0.0);
    for (const Emitter& e : emitters_) {
        const double active = std::max(0.0, std::min(time_ + dt, e.end) - std::max(time_, e.start));
        if (active <= 0) continue;
        for (int i = 0; i < cells && i * dr_ < e.radius; ++i) {
            const double in = i * dr_, out = std::min((i + 1) * dr_, e.radius);
            emitted[i] += e.flux * active / dt * (out * out - in * in) / (e.radius * e.radius);
        }
    }
    std::vector<double> h = h_;
    Eigen::SparseMatrix<double> jacobian(cells, cells);
    Eigen::VectorXd residual(cells);
    Eigen::SparseLU<Eigen::SparseMatrix<double>> lu;
    bool analyzed = false;
    for (int iteration = 0; iteration < kMaxNewtonIterations; ++iteration) {
        std::vector<Eigen::Triplet<double>> entries;
        for (int i = 0; i < cells; ++i) {
            residual[i] = area_[i] * (h[i] - h_[i]) / dt - emitted[i];
            entries.emplace_back(i, i, area_[i] / dt);
        }
        for (int i = 0; i + 1 < cells; ++i) {  // the face between cells i and i + 1
            const FaceFlux f = faceFlux((i + 1) * dr_, h[i], h[i + 1]);
            residual[i] += f.flux;
            residual[i + 1] -= f.flux;
            entries.emplace_back(i, i, f.dInner);
            entries.emplace_back(i, i + 1, f.dOuter);
            entries.emplace_back(i + 1, i, -f.dInner);
            entries.emplace_back(i + 1, i + 1, -f.dOuter);
        }
        jacobian.setFromTriplets(entries.begin(), entries.end());
        if (!analyzed) {
            lu.analyzePattern(jacobian);
            analyzed = true;
        }
        lu.factorize(jacobian);
        if (lu.info() != Eigen::Success) return false;
        const Eigen::VectorXd delta = lu.solve(-residual);
        if (!delta.allFinite()) return false;
        double largest = 0, thickest = 0;
        for (int i = 0; i < cells; ++i) {
            // A Newton step may overshoot below the dry ground at the front; the floor keeps the flux
            // defined, and the converged state satisfies the equations with it.
            h[i] = std::max(h[i] + delta[i], 1e-3 * kPrecursorThickness);
            largest = std::max(largest, std::abs(delta[i]));
            thickest = std::max(thickest, h[i]);
        }
        if (largest <= kNewtonTolerance * thickest + 1e-10) {
            h_.swap(h);
            return true;
        }
    }
    return false;
}

void AxisymmetricFilm::advanceTo(double time) {
    while (time_ < time) {
        const double dt = std::min(dt_, time - time_);
        const std::vector<double> before = h_;
        const double frontBefore = frontRadius();
        bool accepted = step(dt);
        // (Not the film's first appearance, which puts its front half a cell out or more at once.)
        if (accepted && frontBefore > 0 && std::abs(frontRadius() - frontBefore) > kMaxFrontCellsPerStep * dr_ &&
            dt > kMinStep) {
            h_ = before;
            accepted = false;
        }
        if (!accepted) {
            dt_ = 0.5 * dt;
            if (dt_ < kMinStep)
                throw std::runtime_error("the thin-film step fell below 1 µs at t = " + std::to_string(time_) +
                                         " s without converging");
            continue;
        }
        time_ += dt;
        ++steps_;
        // Grow again after a full step (not after the last, shortened one before `time`).
        if (dt == dt_) dt_ *= 1.5;
    }
}

void AxisymmetricFilm::setThickness(const std::function<double(double)>& profile) {
    for (size_t i = 0; i < h_.size(); ++i) h_[i] = std::max(profile((i + 0.5) * dr_), kPrecursorThickness);
}

double AxisymmetricFilm::frontRadius() const {
    for (int i = static_cast<int>(h_.size()) - 1; i >= 0; --i) {
        if (h_[i] < kFrontThickness) continue;
        if (i + 1 == static_cast<int>(h_.size())) return h_.size() * dr_;  // at the domain's edge
        return (i + 0.5) * dr_ + dr_ * (h_[i] - kFrontThickness) / (h_[i] - h_[i + 1]);
    }
    return 0;
}

double AxisymmetricFilm::volume() const {
    double v = 0;
    for (size_t i = 0; i < h_.size(); ++i) v += area_[i] * (h_[i] - kPrecursorThickness);
    return v;
}

std::vector<double> AxisymmetricFilm::cellRadii() const {
    std::vector<double> r(h_.size());
    for (size_t i = 0; i < r.size(); ++i) r[i] = (i + 0.5) * dr_;
    return r;
}

}  // namespace viscoscope::film
