// The time budget: what the search has spent and what its remaining generations will take.
#include "identify/search_state.h"

#include <algorithm>

namespace viscoscope::identify {

namespace {

// Generations are predicted with this margin: without it, a generation that ran past the mean of
// those before it ended a run past its budget, and so did an alignment check that took longer than
// half the mean full-fidelity generation (FINDINGS, "Figures moved from code comments").
constexpr double kFineTimeMargin = 1.15;

double mean(const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / v.size();
}

}  // namespace

std::string wholeSeconds(double seconds) { return std::to_string(std::lround(seconds)); }

// Per evaluation near the coarse best rather than per coarse generation: the first coarse generation
// scans the whole initial range, and its lowest θ costs the most: per generation, a scan that was
// the whole coarse phase predicted more than twice what the full generations took, and warned of an
// overrun that did not come. The first frames are cheap (the liquid is still in the cup and the
// time step long), so scaling by the frame count alone predicts too little (tests/bench/FINDINGS.md,
// "Figures moved from code comments").
double predictedFullEvaluationSeconds(const std::vector<EvaluationRecord>& evaluated, const FidelityPlan& plan) {
    const std::optional<BestPoint> coarseBest = [&]() -> std::optional<BestPoint> {
        const EvaluationRecord* lowest = nullptr;
        for (const EvaluationRecord& e : evaluated)
            if (e.fidelity == Fidelity::Coarse && e.succeeded() && (!lowest || e.E() < lowest->E())) lowest = &e;
        return lowest ? std::optional<BestPoint>(BestPoint{lowest->theta(), lowest->E()}) : std::nullopt;
    }();
    double sum = 0;
    int count = 0;
    for (const EvaluationRecord& e : evaluated) {
        if (e.fidelity != Fidelity::Coarse) continue;
        bool near = true;
        for (size_t i = 0; coarseBest && i < e.theta().size(); ++i)
            near = near && std::abs(std::log(e.theta()[i] / coarseBest->theta[i])) <= kCoarseToFineShift;
        if (!near) continue;
        double lengthening = (plan.fullFrames + 1.0) / (plan.coarseFrames + 1.0);
        const std::vector<double>& frameSeconds = e.evaluation.frameSeconds;
        const size_t tail = std::max<size_t>(1, frameSeconds.size() / 3);
        double all = 0, last = 0;
        for (size_t f = 0; f < frameSeconds.size(); ++f) {
            all += frameSeconds[f];
            if (f + tail >= frameSeconds.size()) last += frameSeconds[f];
        }
        if (all > 0) lengthening = (all + (plan.fullFrames - plan.coarseFrames) * last / tail) / all;
        sum += e.evaluation.seconds * std::pow(double(plan.fullResolution) / plan.coarseResolution, 4) * lengthening;
        ++count;
    }
    return count ? sum / count : 0.0;
}

TimeBudget::TimeBudget(const Job& job, const SearchState& state, const FidelityPlan& plan, int concurrency)
    : job_(job), state_(state), plan_(plan), concurrency_(std::max(1, concurrency)), sessionStart_(Clock::now()) {
    for (const GenerationRecord& g : state.generations) addGeneration(g.fidelity, g.seconds);
}

double TimeBudget::elapsed() const {
    return state_.elapsedBefore + std::chrono::duration<double>(Clock::now() - sessionStart_).count();
}

bool TimeBudget::fits(double seconds) const { return job_.timeBudget <= 0 || elapsed() + seconds <= job_.timeBudget; }

void TimeBudget::addGeneration(Fidelity fidelity, double seconds) {
    (fidelity == Fidelity::Full ? fineSeconds_ : coarseSeconds_).push_back(seconds);
}

double TimeBudget::coarseGenerationSeconds() const { return mean(coarseSeconds_); }

double TimeBudget::fineGenerationSeconds() const {
    if (!fineSeconds_.empty()) return mean(fineSeconds_);
    return std::ceil(double(state_.es.lambda()) / concurrency_) * predictedFullEvaluationSeconds(state_.evaluated, plan_);
}

double TimeBudget::checkSeconds(GridCheck check) const {
    if (!gridCheckPlanned(job_, check)) return 0.0;
    const double pair = kFineTimeMargin * fineGenerationSeconds() * std::ceil(2.0 / concurrency_) /
                        std::ceil(double(state_.es.lambda()) / concurrency_);
    if (check == GridCheck::Alignment) return pair;
    // On each placement taken by generation, on a grid whose evaluations cost (r_c/r)⁴ as much.
    const int grids = placementsByGeneration(job_) ? job_.gridPlacements : 1;
    return grids * pair * std::pow(double(resolutionCheckCells(job_)) / job_.resolution, 4);
}

double TimeBudget::gridChecksSeconds() const {
    return checkSeconds(GridCheck::Alignment) + checkSeconds(GridCheck::Resolution);
}

bool TimeBudget::fullPhaseOver(bool checksCanRun) const {
    // The grid checks are part of every run's plan: while no profile lets them run, up to twice the
    // minimum full-fidelity generations run whatever the budget says.
    const bool awaitingProfile = gridCheckPlanned(job_, GridCheck::Alignment) && !checksCanRun;
    const int minimum = job_.fidelity.minFineGenerations * (awaitingProfile ? 2 : 1);
    return state_.es.generation() - state_.coarseEnd >= minimum &&
           !fits(kFineTimeMargin * fineGenerationSeconds() + (checksCanRun ? gridChecksSeconds() : 0.0));
}

double TimeBudget::remaining(int done, bool stopped) const {
    if (stopped) return gridChecksSeconds();
    const int coarseLeft = std::max(0, state_.coarseEnd - done);
    const double coarse = coarseLeft * coarseGenerationSeconds();
    double left = coarse + (job_.maxGenerations - std::max(done, state_.coarseEnd)) * fineGenerationSeconds() +
                  gridChecksSeconds();
    if (job_.timeBudget > 0) {
        const int fineLeft = std::max(0, job_.fidelity.minFineGenerations - std::max(0, done - state_.coarseEnd));
        left = std::min(left, std::max({0.0, job_.timeBudget - elapsed(),
                                        coarse + fineLeft * fineGenerationSeconds() + gridChecksSeconds()}));
    }
    return left;
}

}  // namespace viscoscope::identify
