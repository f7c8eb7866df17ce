// The alignment check. The grid resolves a scene's small features unevenly: where the faces fall
// against the rim of a hole a few cells wide decides how much of it passes flux, and so the drain;
// and where the seeded particles fall moves the liquid's surface by a fraction of a cell. That
// scatter is the forward model's, not the fit's, and the profile band sees only the part the
// search's own draws show. So θ* and kAlignmentStep·θ* are scored again on the grid moved by half a
// cell along x and y with the particles seeded anew, and with the profile's curvature c the
// minimum there is u_s = ((u₁² − u₂²) − (E₁ − E₂)/c) / (2 (u₁ − u₂)).
// The profile of CMA-ES's spread-out samples is flatter than the landscape (E is more V than
// parabola near its minimum), so the widening errs wide. One other alignment is a sample of the
// error, not its sign: the interval is widened to θ*·exp(±|ln(θ_s/θ*)|). The sample cup's figures
// are in tests/bench/FINDINGS.md, "Figures moved from code comments".
#include "identify/search_state.h"

namespace viscoscope::identify {

using json = nlohmann::json;

namespace {

// Cells along x and y; with several grid placements, half their spacing, which puts the check's
// grids midway between the search's.
constexpr double kAlignmentShift = 0.5;
constexpr double kAlignmentStep = 1.15;
// Added to the particle seed: the check's draw of the seeding is not the search's.
constexpr unsigned kAlignmentSeedOffset = 1;

std::optional<double> shiftedMinimum(const ProfileFit& profile, bool inverse, const std::array<double, 2>& theta,
                                     const std::array<double, 2>& E) {
    const auto u = [&](double t) { return inverse ? 1 / t : std::log(t); };
    const double u1 = u(theta[0]), u2 = u(theta[1]);
    const double us = ((u1 * u1 - u2 * u2) - (E[0] - E[1]) / profile.curvature) / (2 * (u1 - u2));
    if (!std::isfinite(us)) return std::nullopt;
    if (inverse) return us > 0 ? std::optional<double>(1 / us) : std::optional<double>(INFINITY);
    return std::exp(us);
}

}  // namespace

AlignmentOutcome alignmentCheck(const Job& job, EvaluationPool& pool, const Observations& observations,
                                SearchState& state, const std::optional<ProfileFit>& profile, double thetaStar,
                                const TimeBudget& budget, const std::function<void()>& saved) {
    AlignmentOutcome outcome;
    const double shift = kAlignmentShift / job.gridPlacements;
    json& check = outcome.entry;
    check = {{"grid_shift_cells", {shift, shift, 0.0}}, {"seed_offset", kAlignmentSeedOffset}};
    const std::array<double, 2> thetas{thetaStar, kAlignmentStep * thetaStar};
    // A rerun of a finished job (or one killed after the check) takes the scores from the
    // checkpoint instead of simulating them again.
    const bool cached = state.alignment && state.alignment->theta == thetas;
    if (!profile) {
        check["skipped"] = "no profile fit to take E's curvature from";
        return outcome;
    }
    if (!cached && !budget.fits(budget.alignmentSeconds())) {
        // The minimum full-fidelity generations may have spent the budget (FINDINGS, "Figures moved
        // from code comments").
        outcome.warning = "alignment_check: skipped, its two evaluations (about " +
                          wholeSeconds(budget.alignmentSeconds()) + " s) do not fit time_budget_s (" +
                          wholeSeconds(job.timeBudget) + " s); the interval leaves out the grid's share of the error";
        check["skipped"] = *outcome.warning;
        return outcome;
    }
    if (!cached) {
        const auto start = Clock::now();
        const BatchResult ran =
            pool.evaluate(job, observations, {{{thetas[0]}, {thetas[1]}}, false, job.resolution, shift, {}, kAlignmentSeedOffset});
        outcome.seconds = std::chrono::duration<double>(Clock::now() - start).count();
        check["seconds"] = outcome.seconds;
        state.alignment = AlignmentScores{thetas, {ran.evaluations[0].E, ran.evaluations[1].E}, ran.errors};
        saved();
    }
    const AlignmentScores& scores = *state.alignment;
    check["from_checkpoint"] = cached;
    check["theta"] = thetas;
    check["E"] = {finiteOrNull(scores.E[0]), finiteOrNull(scores.E[1])};
    const bool bothFinite = std::isfinite(scores.E[0]) && std::isfinite(scores.E[1]);
    const std::optional<double> shifted =
        bothFinite ? shiftedMinimum(*profile, job.parameters[0].profileInInverse(), thetas, scores.E) : std::nullopt;
    if (shifted) {
        check["theta_min"] = std::isfinite(*shifted) ? json(*shifted) : json("infinite");
        outcome.spread = std::isfinite(*shifted) ? std::abs(std::log(*shifted / thetaStar)) : INFINITY;
    } else {
        check["failed"] = bothFinite ? json("no finite minimum") : json(scores.errors);
    }
    return outcome;
}

}  // namespace viscoscope::identify
