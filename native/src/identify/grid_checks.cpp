// The grid checks of a one-parameter search. θ* and its profile band come from the search's own
// draws on the job's grid; two errors of that grid are not in them, so after the search θ* and
// kCheckStep·θ* are scored again on another grid, and with the profile's curvature c the minimum
// there is u_m = ((u₁² − u₂²) − (E₁ − E₂)/c) / (2 (u₁ − u₂)). The profile of CMA-ES's spread-out
// samples is flatter than the landscape (E is more V than parabola near its minimum), so both
// checks err wide.
//
// The alignment check measures scatter. The grid resolves a scene's small features unevenly: where
// the faces fall against the rim of a hole a few cells wide decides how much of it passes flux, and
// so the drain; and where the seeded particles fall moves the liquid's surface by a fraction of a
// cell. Its grid is moved by half a cell along x and y, with the particles seeded anew. One other
// alignment is a sample of the error, not its sign: the interval is widened to θ*·exp(±|ln(θ_s/θ*)|).
// The sample cup's figures are in tests/bench/FINDINGS.md, "Figures moved from code comments".
//
// The resolution check measures bias: the part of the grid's error neither particle seeds nor
// placements show, against footage the error of a grid against a continuum. Its grids (the search's
// placements) have kCoarserCells of the job's cells; its two-point minimum θ_c is compared with the
// alignment check's θ_s, found by the same two points and curvature on the job's cell, so that what
// the curvature gets wrong cancels. To first order in the cell size h the minimum then lies
// h/(h_c − h) times that move from a continuum's; on coarse grids the minimum does not approach a
// finer grid's monotonically (FINDINGS, "Coverage of identify's interval against finer
// references"), so like the alignment check's the move is a size, not a sign. Each two-point
// minimum carries E's jitter j: σ(u_m) = √2·j / (2c|u₁ − u₂|), and the move's σ_m (in ln θ) combines
// both minima's; a move within that noise says little, and a grid error as large as the noise
// allows would pass unseen (the capture clip's did: same FINDINGS section). So the interval holds
// θ*·exp(±(h/(h_c − h))·(|ln(θ_s/θ_c)| + z·σ_m)), z that of a two-sided 90 % normal interval: Roache's
// grid convergence index carries the same move by the same factor, with a safety factor on top.
#include "identify/search_state.h"

namespace viscoscope::identify {

using json = nlohmann::json;

namespace {

constexpr double kCheckStep = 1.15;
// Cells along x and y; with several grid placements, half their spacing, which puts the alignment
// check's grids midway between the search's.
constexpr double kAlignmentShift = 0.5;
// Added to the particle seed: the alignment check's draw of the seeding is not the search's.
constexpr unsigned kAlignmentSeedOffset = 1;
// Coarser by this factor, the resolution check costs about its fourth power of an evaluation (cells
// × time steps) and stays near enough the job's grid for a first-order estimate; its move is then
// carried four times as far to a continuum.
constexpr double kCoarserCells = 0.8;
constexpr double kNinetyPercentZ = 1.645;
// A measured grid error beyond this (in ln θ, ln 1.5), the move carried to a continuum, is a doubt
// on θ*: it then outweighs the scatter the interval otherwise holds. The move's noise widens the
// interval but is no reason to think θ* wrong: a check that cannot measure the move says the
// interval is wide, not that the minimum moved (FINDINGS, "A plan the machine's speed does not
// change").
constexpr double kResolutionDoubt = 0.405;

struct GridCheckSpec {
    const char* name;
    int resolution;
    std::vector<double> gridShifts;  // E is the mean over these grids
    unsigned seedOffset;
    std::optional<CheckScores> SearchState::*scores;
};

// σ of ln θ_m for a two-point minimum θ_m (see the resolution check above).
double minimumNoise(const ProfileFit& profile, bool inverse, const std::array<double, 2>& theta, double minimum) {
    const auto u = [&](double t) { return profileVariable(inverse, t); };
    const double sigmaU = std::sqrt(2.0) * profile.jitter / (2 * profile.curvature * std::abs(u(theta[0]) - u(theta[1])));
    return inverse ? sigmaU * minimum : sigmaU;  // |d ln θ / du|
}

std::optional<double> checkMinimum(const ProfileFit& profile, bool inverse, const std::array<double, 2>& theta,
                                   const std::array<double, 2>& E) {
    const auto u = [&](double t) { return profileVariable(inverse, t); };
    const double u1 = u(theta[0]), u2 = u(theta[1]);
    const double um = ((u1 * u1 - u2 * u2) - (E[0] - E[1]) / profile.curvature) / (2 * (u1 - u2));
    if (!std::isfinite(um)) return std::nullopt;
    if (inverse && um <= 0) return INFINITY;  // beyond 1/θ = 0
    return profileParameter(inverse, um);
}

// Scores the check's two evaluations unless `state` holds them for θ* (a rerun of a finished job,
// or one killed after the check), and finds the minimum on its grid.
GridCheckOutcome runGridCheck(const GridCheckSpec& spec, const Job& job, EvaluationPool& pool,
                              const Observations& observations, SearchState& state,
                              const std::optional<ProfileFit>& profile, double thetaStar,
                              const std::function<void()>& saved) {
    GridCheckOutcome outcome;
    json& check = outcome.entry;
    const std::string name = spec.name;
    const std::array<double, 2> thetas{thetaStar, kCheckStep * thetaStar};
    std::optional<CheckScores>& scores = state.*spec.scores;
    const bool cached = scores && scores->theta == thetas;
    if (!profile) {
        outcome.warning = name + ": skipped, no profile fit of E near θ* to take its curvature from (too few "
                          "full-fidelity evaluations near it); the interval leaves out the grid's share of the error";
        check["skipped"] = *outcome.warning;
        return outcome;
    }
    if (!cached) {
        const auto start = Clock::now();
        CheckScores scored{thetas, {0.0, 0.0}, {}};
        for (double shift : spec.gridShifts) {
            const BatchResult ran = pool.evaluate(
                job, observations, {{{thetas[0]}, {thetas[1]}}, false, spec.resolution, shift, {}, spec.seedOffset});
            for (int k = 0; k < 2; ++k) scored.E[k] += ran.evaluations[k].E / spec.gridShifts.size();
            for (const std::string& error : ran.errors)
                if (!error.empty()) scored.errors.push_back(error);
        }
        outcome.seconds = std::chrono::duration<double>(Clock::now() - start).count();
        check["seconds"] = outcome.seconds;
        scores = scored;
        saved();
    }
    check["from_checkpoint"] = cached;
    check["theta"] = thetas;
    check["E"] = {finiteOrNull(scores->E[0]), finiteOrNull(scores->E[1])};
    const bool bothFinite = std::isfinite(scores->E[0]) && std::isfinite(scores->E[1]);
    outcome.minimum = bothFinite ? checkMinimum(*profile, job.parameters[0].profileInInverse(), thetas, scores->E)
                                 : std::nullopt;
    if (outcome.minimum)
        check["theta_min"] = std::isfinite(*outcome.minimum) ? json(*outcome.minimum) : json("infinite");
    else
        check["failed"] = bothFinite ? json("no finite minimum") : json(scores->errors);
    return outcome;
}

}  // namespace

bool gridCheckPlanned(const Job& job, GridCheck check) {
    // The resolution check's move is measured from the alignment check's minimum.
    return job.parameters.size() == 1 && job.alignmentCheck && (check == GridCheck::Alignment || job.resolutionCheck);
}

int resolutionCheckCells(const Job& job) {
    return std::max(kMinResolution,
                    std::min(job.resolution - 1, static_cast<int>(std::lround(kCoarserCells * job.resolution))));
}

GridCheckOutcome alignmentCheck(const Job& job, EvaluationPool& pool, const Observations& observations,
                                SearchState& state, const std::optional<ProfileFit>& profile, double thetaStar,
                                const std::function<void()>& saved) {
    const double shift = kAlignmentShift / job.gridPlacements;
    GridCheckOutcome outcome = runGridCheck({"alignment_check", job.resolution, {shift}, kAlignmentSeedOffset,
                                             &SearchState::alignment},
                                            job, pool, observations, state, profile, thetaStar, saved);
    outcome.entry["grid_shift_cells"] = {shift, shift, 0.0};
    outcome.entry["seed_offset"] = kAlignmentSeedOffset;
    if (outcome.minimum)
        outcome.widening = std::isfinite(*outcome.minimum) ? std::abs(std::log(*outcome.minimum / thetaStar)) : INFINITY;
    return outcome;
}

GridCheckOutcome resolutionCheck(const Job& job, EvaluationPool& pool, const Observations& observations,
                                 SearchState& state, const std::optional<ProfileFit>& profile, double thetaStar,
                                 const GridCheckOutcome& alignment, const std::function<void()>& saved) {
    const int cells = resolutionCheckCells(job);
    // On every placement the search took in turn, as θ* is their mean's minimum.
    std::vector<double> shifts{0.0};
    for (int k = 1; placementsByGeneration(job) && k < job.gridPlacements; ++k) shifts.push_back(double(k) / job.gridPlacements);
    if (!alignment.minimum || !std::isfinite(*alignment.minimum)) {
        GridCheckOutcome outcome;
        outcome.entry["skipped"] = "the alignment check found no minimum on the job's cell to compare with";
        return outcome;
    }
    if (cells >= job.resolution) {
        GridCheckOutcome outcome;
        outcome.warning = "resolution_check: skipped, a grid of " + std::to_string(job.resolution) +
                          " cells has no coarser one; the interval leaves out the grid's resolution error";
        outcome.entry["skipped"] = *outcome.warning;
        return outcome;
    }
    GridCheckOutcome outcome = runGridCheck({"resolution_check", cells, shifts, 0, &SearchState::resolution},
                                            job, pool, observations, state, profile, thetaStar, saved);
    outcome.entry["resolution"] = cells;
    if (outcome.entry.contains("skipped")) return outcome;
    if (!outcome.minimum || !std::isfinite(*outcome.minimum)) {
        outcome.warning = "resolution_check: no finite minimum on " + std::to_string(cells) +
                          " cells; the interval leaves out the grid's resolution error";
        return outcome;
    }
    // h/(h_c − h) with h ∝ 1/r.
    const double reach = double(cells) / (job.resolution - cells);
    const bool inverse = job.parameters[0].profileInInverse();
    const std::array<double, 2> thetas = outcome.entry.at("theta").get<std::array<double, 2>>();
    const double noise = std::hypot(minimumNoise(*profile, inverse, thetas, *alignment.minimum),
                                    minimumNoise(*profile, inverse, thetas, *outcome.minimum));
    const double move = std::abs(std::log(*alignment.minimum / *outcome.minimum));
    outcome.widening = reach * (move + kNinetyPercentZ * noise);
    outcome.entry["move_ln"] = move;
    outcome.entry["move_noise_ln"] = noise;
    outcome.entry["error_ln"] = *outcome.widening;
    if (reach * move > kResolutionDoubt)
        outcome.warning = "resolution_check: the minimum moves from " + formatNumber(*outcome.minimum) + " on " +
                          std::to_string(cells) + " cells to " + formatNumber(*alignment.minimum) + " on " +
                          std::to_string(job.resolution) + ", a grid error of a factor " +
                          formatNumber(std::exp(reach * move)) + " against a continuum: the grid is too coarse "
                          "for θ* (a finer grid would tell)";
    return outcome;
}

}  // namespace viscoscope::identify
