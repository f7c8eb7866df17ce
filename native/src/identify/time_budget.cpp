// The time budget: what the search has spent and what its remaining generations will take.
#include "identify/search_state.h"

#include <algorithm>

namespace viscoscope::identify {

namespace {

// With a time budget, the coarse phase may use at most 35 % of it, and no more than leaves time for
// the minimum full-fidelity generations. When the coarse grid was 32³, their (r/r_c)⁴ prediction
// was 190 s per generation where 125–139 s were measured, and the reservation alone left the coarse
// phase a single generation in a 10-minute run; hence the cap. Half the budget was too much once
// the grid placements took turns by generation: each placement then gets every other full
// generation, and at η = 300 on the sample cup (a scan and 7 more coarse generations, whose E over
// the first third of the clip steps between a few values, the best found in the 6th) the half-cell
// placement got one, and θ* sat 5.0 % high; with 35 % (a scan and 3 more) it got two, and 0.4 %.
// (η = 1, whose full-fidelity E is flat within its jitter, went from 3.7 to 10.5 % with the same
// two full generations; see the README's Table 1.) On the same grid over a third of the clip,
// scaled by the frame count alone, the prediction was low instead (the first frames are the
// cheapest): 110 and 126 s predicted, 135 and 133 s measured on the sample scene at 48³, η = 10, and
// 160 against 200–230 s at η = 3; see predictedFullEvaluationSeconds for the better prediction.
constexpr double kCoarseBudgetShare = 0.35;
// Generations are predicted with this margin: without it, a generation that ran past the mean of
// those before it ended the η = 30 row of the sample cup's table 5 s past its 600 s budget, and the
// alignment check at η = 1 took 61.5 s where half the mean full-fidelity generation, 55 s, was
// predicted.
constexpr double kFineTimeMargin = 1.15;

double mean(const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / v.size();
}

}  // namespace

std::string wholeSeconds(double seconds) { return std::to_string(std::lround(seconds)); }

// Per evaluation near the coarse best rather than per coarse generation: the first coarse generation
// scans the whole initial range, and its lowest θ costs the most. On the sample cup at η = 300 a
// 77 s scan, the whole coarse phase, predicted 178 s per full generation where 68–77 s were
// measured, and warned that the run would overrun its budget. The first frames are cheap (the
// liquid is still in the cup and the time step long: 0.5 s a frame against 1.0–1.2 s later at
// η = 3, 48³), so scaling by the frame count alone predicted 1.2–1.4× too little at η = 1–3.
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

TimeBudget::TimeBudget(const Job& job, const SearchState& state, const FidelityPlan& plan, int concurrency,
                       bool alignmentPlanned)
    : job_(job), state_(state), plan_(plan), concurrency_(std::max(1, concurrency)),
      alignmentPlanned_(alignmentPlanned), sessionStart_(Clock::now()) {
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

double TimeBudget::alignmentSeconds() const {
    if (!alignmentPlanned_) return 0.0;
    return kFineTimeMargin * fineGenerationSeconds() * std::ceil(2.0 / concurrency_) /
           std::ceil(double(state_.es.lambda()) / concurrency_);
}

bool TimeBudget::coarsePhaseOver() const {
    if (job_.timeBudget <= 0) return false;
    const double reserved = job_.fidelity.minFineGenerations * kFineTimeMargin * fineGenerationSeconds() +
                            alignmentSeconds();
    return elapsed() + coarseGenerationSeconds() >
           std::min(kCoarseBudgetShare * job_.timeBudget, job_.timeBudget - reserved);
}

bool TimeBudget::fullPhaseOver() const {
    return state_.es.generation() - state_.coarseEnd >= job_.fidelity.minFineGenerations &&
           !fits(kFineTimeMargin * fineGenerationSeconds() + alignmentSeconds());
}

double TimeBudget::remaining(int done, bool stopped) const {
    if (stopped) return alignmentSeconds();
    const int coarseLeft = std::max(0, state_.coarseEnd - done);
    const double coarse = coarseLeft * coarseGenerationSeconds();
    double left = coarse + (job_.maxGenerations - std::max(done, state_.coarseEnd)) * fineGenerationSeconds() +
                  alignmentSeconds();
    if (job_.timeBudget > 0) {
        const int fineLeft = std::max(0, job_.fidelity.minFineGenerations - std::max(0, done - state_.coarseEnd));
        left = std::min(left, std::max({0.0, job_.timeBudget - elapsed(),
                                        coarse + fineLeft * fineGenerationSeconds() + alignmentSeconds()}));
    }
    return left;
}

}  // namespace viscoscope::identify
