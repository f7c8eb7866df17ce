// The three conclusions (conclusion.h).
#include "diagnose/conclusion.h"

#include <boost/math/distributions/students_t.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

namespace viscoscope::diagnose {

using namespace identify;

namespace {

// The one-sided confidence a named gain stands above the scatter with.
constexpr double kGainConfidence = 0.95;

std::string percent(double share) { return std::to_string(std::lround(100 * share)) + " %"; }

// A budget to suggest: whole seconds, rounded up, at least one.
long wholeSecondsOver(double seconds) { return std::max(1L, long(std::ceil(seconds))); }

std::string joined(const std::vector<std::string>& items) {
    std::string all;
    for (size_t i = 0; i < items.size(); ++i) all += (i == 0 ? "" : i + 1 == items.size() ? " and " : ", ") + items[i];
    return all;
}

// How the scatter was measured, for the conclusion's sentence.
std::string scatterPhrase(const NoiseFloor& noise) {
    if (noise.deterministic) return "the forward model is deterministic: no scatter";
    return "the simulation's own scatter, over " + std::to_string(noise.heldOutE.size()) +
           " seeds and grid placements, explains gains up to " + percent(noise.visibleShare());
}

void addOnce(std::vector<std::string>& list, const std::vector<std::string>& items) {
    for (const std::string& item : items)
        if (std::find(list.begin(), list.end(), item) == list.end()) list.push_back(item);
}

// What shrinks the scatter against the effect: a finer grid, more placements averaged, more data.
void lessScatter(const Job& job, Conclusion& conclusion) {
    const int finer = int(std::lround(1.5 * job.resolution));
    addOnce(conclusion.whatWouldTell, {"a finer grid (resolution " + std::to_string(job.resolution) + " → " + std::to_string(finer) + ")",
                                       "more grid placements averaged (grid_placements " + std::to_string(job.gridPlacements) +
                                           " → " + std::to_string(2 * job.gridPlacements) + ")",
                                       job.otherRuns.empty() ? "a second run of the same liquid in another geometry (\"runs\")"
                                                             : "a longer clip of each run"});
    conclusion.suggestedSettings["resolution"] = finer;
    conclusion.suggestedSettings["grid_placements"] = 2 * job.gridPlacements;
}

// More time for fits cut short: twice the budget, the fits' own minimum not being known (nothing
// more where a budget predicted to hold the candidates is suggested already).
void moreTime(double timeBudget, Conclusion& conclusion) {
    if (conclusion.suggestedSettings.contains("time_budget_s")) return;
    if (timeBudget > 0) {
        const long twice = wholeSecondsOver(2 * timeBudget);
        addOnce(conclusion.whatWouldTell, {"more time for each fit (a --time-budget of " + std::to_string(twice) +
                                           " s, twice this one, or 0 to give each fit the job's own)"});
        conclusion.suggestedSettings["time_budget_s"] = twice;
    } else {
        addOnce(conclusion.whatWouldTell, {"more generations for each fit (max_generations, time_budget_s)"});
    }
}

}  // namespace

double NoiseFloor::logSpread() const {
    const size_t m = heldOutE.size();
    if (m < 2) return 0;
    std::vector<double> logs;
    for (double e : heldOutE) logs.push_back(std::log(std::max(e, 1e-300)));
    const double mean = std::accumulate(logs.begin(), logs.end(), 0.0) / m;
    double squares = 0;
    for (double l : logs) squares += (l - mean) * (l - mean);
    return std::sqrt(squares / (m - 1));
}

double NoiseFloor::visibleShare() const {
    if (deterministic) return 0;
    if (heldOutE.size() < 2) return 1;
    const boost::math::students_t t(double(heldOutE.size() - 1));
    return -std::expm1(-boost::math::quantile(t, kGainConfidence) * std::sqrt(2.0) * logSpread());
}

namespace {

// The share of the base's held-out E that `fit` gains.
double relativeGain(const ModelFit& fit, const ModelFit& base) {
    return base.heldOutE > 0 ? (base.heldOutE - fit.heldOutE) / base.heldOutE : 0.0;
}

}  // namespace

bool contends(const Judged& candidate, const ModelFit& base, const NoiseFloor& noise) {
    const double gain = relativeGain(*candidate.fit, base);
    return gain > kHeldOutGain && gain > noise.visibleShare() && !candidate.vanishes;
}

std::optional<size_t> preferredFit(const std::vector<const ModelFit*>& fits, const std::vector<bool>& eligible) {
    std::vector<size_t> order;
    for (size_t c = 0; c < fits.size(); ++c)
        if (eligible[c]) order.push_back(c);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        const ModelFit &fa = *fits[a], &fb = *fits[b];
        return fa.theta.size() != fb.theta.size() ? fa.theta.size() < fb.theta.size() : fa.heldOutE < fb.heldOutE;
    });
    std::optional<size_t> preferred;
    for (size_t c : order)
        if (!preferred || fits[c]->heldOutE < (1 - kHeldOutGain) * fits[*preferred]->heldOutE) preferred = c;
    return preferred;
}

std::optional<std::string> runsDisagree(const std::vector<ModelFit>& runFits) {
    if (runFits.size() < 2) return std::nullopt;
    for (size_t i = 0; i < runFits.front().parameters.size(); ++i) {
        double highestLow = -INFINITY, lowestHigh = INFINITY;
        std::string values;
        for (size_t r = 0; r < runFits.size(); ++r) {
            const std::array<double, 2>& interval = runFits[r].interval.at(i);
            highestLow = std::max(highestLow, interval[0]);
            lowestHigh = std::min(lowestHigh, interval[1]);
            values += (r ? ", run " : "run ") + std::to_string(r + 1) + " " + formatNumber(runFits[r].theta.at(i)) +
                      " [" + formatNumber(interval[0]) + ", " + formatNumber(interval[1]) + "]";
        }
        if (highestLow > lowestHigh)
            return "the runs fitted alone disagree on the base's " + runFits.front().parameters[i] + " (" + values +
                   "), which one base model cannot hold";
    }
    return std::nullopt;
}

const char* toString(Verdict verdict) {
    switch (verdict) {
        case Verdict::MissingEffect: return "missing_effect";
        case Verdict::NoMissingEffect: return "no_missing_effect";
        case Verdict::CannotTell: return "cannot_tell";
    }
    return "?";
}

Conclusion conclude(const Job& job, double timeBudget, const ModelFit& base, const std::vector<Judged>& candidates,
                    const NoiseFloor& noise, const Unfitted& unfitted, const std::vector<ModelFit>& runFits,
                    std::optional<double> baseCrossRunE) {
    Conclusion conclusion;
    conclusion.runsDisagreement = runsDisagree(runFits);
    const double visible = noise.visibleShare();
    std::vector<std::string> withinScatter, cutShort, notAcrossRuns, untestedAcrossRuns;
    for (size_t c = 0; c < candidates.size(); ++c) {
        const ModelFit& fit = *candidates[c].fit;
        CandidateVerdict& v = conclusion.candidates.emplace_back();
        v.gain = base.heldOutE - fit.heldOutE;
        v.relativeGain = relativeGain(fit, base);
        v.aboveNoise = v.relativeGain > visible;
        if (baseCrossRunE && candidates[c].crossRunE && *baseCrossRunE > 0)
            v.crossRunGain = 1 - *candidates[c].crossRunE / *baseCrossRunE;
        const bool splitGain = v.relativeGain > kHeldOutGain && !candidates[c].vanishes;
        const bool contender = contends(candidates[c], base, noise);  // splitGain, above the noise
        const bool acrossRuns = v.crossRunGain && *v.crossRunGain > std::max(kHeldOutGain, visible);
        const bool predictsBetter = splitGain && (baseCrossRunE ? acrossRuns : fit.bic < base.bic);
        v.earns = predictsBetter && v.aboveNoise;
        if (predictsBetter && !v.aboveNoise)
            withinScatter.push_back(candidates[c].effect->title + " predicts the held-out frames " + percent(v.relativeGain) +
                                    " better, within the scatter");
        if (contender && v.crossRunGain && !acrossRuns)
            notAcrossRuns.push_back(candidates[c].effect->title + " predicts the held-out frames " + percent(v.relativeGain) +
                                    " better, but fitted to each run alone it predicts the other runs " +
                                    (*v.crossRunGain >= 0 ? percent(*v.crossRunGain) + " better" : percent(-*v.crossRunGain) + " worse") +
                                    " than the base does, under the " + percent(std::max(kHeldOutGain, visible)) +
                                    " a law of the liquid must carry across geometries");
        if (contender && baseCrossRunE && !v.crossRunGain) untestedAcrossRuns.push_back(candidates[c].effect->title);
        if (!fit.searchCompleted()) cutShort.push_back(fit.model);
    }
    std::vector<const ModelFit*> fits;
    std::vector<bool> earns;
    for (size_t c = 0; c < candidates.size(); ++c) {
        fits.push_back(candidates[c].fit);
        earns.push_back(conclusion.candidates[c].earns);
    }
    const std::optional<size_t> best = preferredFit(fits, earns);
    const std::string scatter = scatterPhrase(noise);
    if (best && base.searchCompleted()) {
        const Judged& named = candidates[*best];
        conclusion.verdict = Verdict::MissingEffect;
        conclusion.chosen = best;
        const CandidateVerdict& v = conclusion.candidates[*best];
        conclusion.sentence = "missing effect: " + named.effect->title + " (" + named.effect->name +
                              "): it predicts the held-out frames " + percent(v.relativeGain) + " better than the base fit" +
                              (v.crossRunGain ? ", and fitted to each run alone the other runs " + percent(*v.crossRunGain) + " better," : "") +
                              " and " + scatter;
        // It stands against a converged base even when its own fit was cut short (already it predicts
        // better), but its parameters are where the search stopped.
        if (!named.fit->searchCompleted())
            conclusion.sentence += "; its own fit was cut short (" + std::string(toString(*named.fit->stop)) +
                                   "), so its parameters are not converged";
        return conclusion;
    }
    std::vector<std::string> why;
    if (unfitted.candidates > 0) {
        const long neededSeconds = wholeSecondsOver(unfitted.budgetNeeded);
        const std::string needed = std::to_string(neededSeconds);
        const std::string fits = unfitted.candidates == 1 ? "the least fit of one candidate"
                                                          : "the least fits of " + std::to_string(unfitted.candidates) + " candidates";
        why.push_back("the time budget could not hold " + fits + ", which a budget of about " + needed +
                      " s would hold on this machine");
        addOnce(conclusion.whatWouldTell, {"a --time-budget of at least " + needed + " s, or fewer --effects"});
        conclusion.suggestedSettings["time_budget_s"] = neededSeconds;
    } else if (candidates.empty()) {
        why.push_back("no effect could be tried on this job (not_tried says why)");
    }
    if (best) {
        why.push_back(candidates[*best].effect->title + " predicts the held-out frames " +
                      percent(conclusion.candidates[*best].relativeGain) + " better, but the base fit was cut short (" +
                      (base.stop ? toString(*base.stop) : "?") + "), and the gain may be its shortfall");
        moreTime(timeBudget, conclusion);
    }
    if (!withinScatter.empty()) {
        why.push_back(joined(withinScatter));
        lessScatter(job, conclusion);
    }
    if (!notAcrossRuns.empty()) {
        why.push_back(joined(notAcrossRuns));
        addOnce(conclusion.whatWouldTell, {"the candidates fitted longer, or other candidates (--effects)"});
    }
    if (!untestedAcrossRuns.empty() && !best) {
        why.push_back(joined(untestedAcrossRuns) + " predicted the held-out frames better but was not fitted to each "
                      "run alone, which would test it across the runs");
        moreTime(timeBudget, conclusion);
    }
    if (!(visible <= kHeldOutGain)) {
        why.push_back(noise.heldOutE.size() < 2 ? std::string("the simulation's scatter was not measured")
                                                : scatter + ", more than the " + percent(kHeldOutGain) + " an effect must show");
        if (noise.heldOutE.size() >= 2) lessScatter(job, conclusion);
        else addOnce(conclusion.whatWouldTell, {"the noise floor measured (--scatter-replicas 2 or more, and the time for them)"});
    }
    if (const std::optional<std::string>& disagreement = conclusion.runsDisagreement) {
        why.push_back(*disagreement + ": it lacks an effect that no fitted candidate predicted " + percent(kHeldOutGain) +
                      " better");
        addOnce(conclusion.whatWouldTell, {"the candidates fitted longer, or other candidates (--effects)"});
        moreTime(timeBudget, conclusion);
    }
    if (!base.searchCompleted()) cutShort.insert(cutShort.begin(), "base");
    if (!cutShort.empty() && !best) {
        why.push_back("the fits of " + joined(cutShort) + " were cut short by the time budget");
        moreTime(timeBudget, conclusion);
    }
    if (!why.empty()) {
        conclusion.verdict = Verdict::CannotTell;
        std::string reasons;
        for (const std::string& reason : why) reasons += (reasons.empty() ? "" : "; ") + reason;
        conclusion.sentence = "cannot tell at this grid and budget: " + reasons;
        return conclusion;
    }
    std::vector<std::string> tried;
    for (const Judged& j : candidates) tried.push_back(j.effect->title);
    conclusion.verdict = Verdict::NoMissingEffect;
    conclusion.sentence = "no missing effect: " +
                          (tried.size() == 1 ? tried[0] + " does not predict" : "none of " + joined(tried) + " predicts") +
                          " the held-out frames " + percent(kHeldOutGain) + " better than the base fit, and " + scatter;
    return conclusion;
}

}  // namespace viscoscope::diagnose
