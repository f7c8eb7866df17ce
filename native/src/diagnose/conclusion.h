// A diagnosis's conclusion, one of three said plainly: a missing effect, named because its fit
// predicts the held-out frames better than the base by more than the forward model's own scatter
// explains; no missing effect, where a gain of that size would have shown and none did; or cannot
// tell, with what would tell. Private to the stage.
#pragma once

#include "diagnose/diagnose.h"

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

namespace viscoscope::diagnose {

// The held-out gain a candidate must make over the base, as a share of the base's held-out E, for
// the diagnosis to name it; and the gain that must be visible above the scatter for "no missing
// effect" to mean the data could have shown one.
constexpr double kHeldOutGain = 0.2;

// One candidate as the conclusion weighs it.
struct Judged {
    const ModelFit* fit = nullptr;
    const Effect* effect = nullptr;
    bool vanishes = false;  // it ended where its effect vanishes: the base model
    // With several runs, the whole E its fits to each run alone score on the other runs (the
    // cross-run prediction); measured for the best contender only.
    std::optional<double> crossRunE;
};

// What the conclusion found of each candidate, in the order given.
struct CandidateVerdict {
    double gain = 0;          // the base's held-out E less the candidate's
    double relativeGain = 0;  // gain over the base's held-out E
    bool aboveNoise = false;  // relativeGain > NoiseFloor::visibleShare()
    // 1 − its cross-run E over the base's, where both were measured.
    std::optional<double> crossRunGain;
    // Named if the base converged: above the noise, kHeldOutGain, not vanished, and across runs (with
    // the base's cross-run E) or by BIC (without).
    bool earns = false;
};

// Candidates left unfitted because the time budget could not hold their fits' minimum generations.
struct Unfitted {
    int candidates = 0;
    double budgetNeeded = 0;  // wall seconds of a budget predicted to hold them all
};

struct Conclusion {
    Verdict verdict = Verdict::CannotTell;
    std::optional<size_t> chosen;             // into the candidates, with MissingEffect
    std::string sentence;                     // the conclusion in words
    std::vector<std::string> whatWouldTell;   // with CannotTell: what would decide it
    // The same as settings to act on, by their names in a job or on diagnose's command line
    // ("resolution", "grid_placements", "time_budget_s").
    nlohmann::json suggestedSettings = nlohmann::json::object();
    std::vector<CandidateVerdict> candidates;
    std::optional<std::string> runsDisagreement;  // runsDisagree's sentence for the runs fitted alone
};

// Whether `candidate` predicts the held-out frames better than `base` by kHeldOutGain and by more
// than `noise` explains, without having ended where its effect vanishes: what an effect must show
// before its parameters are weighed (by BIC, or across the runs).
bool contends(const Judged& candidate, const ModelFit& base, const NoiseFloor& noise);

// Of the fits `eligible` says may be named, the one with the fewest parameters, unless one with more
// predicts the held-out frames better by kHeldOutGain (the margin the base had to be beaten by: a
// Herschel–Bulkley fit whose yield stress ends near its least is the power law); none when none is.
std::optional<size_t> preferredFit(const std::vector<const ModelFit*>& fits, const std::vector<bool>& eligible);

// Where the base fitted to each run alone puts a parameter in intervals that share no value, as a
// sentence naming each run's value and interval: one base model cannot hold every run (a
// shear-thinning liquid reads a lower viscosity in the geometry that shears it faster). None with
// fewer than two runs fitted or intervals that overlap.
std::optional<std::string> runsDisagree(const std::vector<ModelFit>& runFits);

// `base` and `candidates` fitted and scored alike, `noise` measured at the base's θ*, `unfitted`
// the candidates the budget could not hold, `runFits` the base fitted to each run alone (none with
// a single run) and `baseCrossRunE` what they predict of the other runs; `job` for what would tell
// (its grid, placements and runs) and `timeBudget` the diagnosis's (0: none of its own). Runs that
// disagree (runsDisagree) rule out "no missing effect". With the base's cross-run E, an effect must
// carry across runs: its fits to each run alone predict the other runs better than the base's by
// kHeldOutGain and the scatter's visible share, in place of BIC (an out-of-sample test of its
// parameters, where BIC is an in-sample one); a contender that does not leaves "cannot tell".
Conclusion conclude(const identify::Job& job, double timeBudget, const ModelFit& base,
                    const std::vector<Judged>& candidates, const NoiseFloor& noise, const Unfitted& unfitted = {},
                    const std::vector<ModelFit>& runFits = {}, std::optional<double> baseCrossRunE = std::nullopt);

}  // namespace viscoscope::diagnose
