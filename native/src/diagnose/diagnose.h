// The diagnose stage's face: from the residual of the best fit to the physical effect the model
// lacks (DESIGN.md, "Diagnosis: closing the loop"). The job's model (the base) and each candidate
// effect the scene can hold (effect.h, effects()) are fitted to the first part of the reference
// (each its own identification) and scored on all of it. The base's θ* is scored again on other
// particle seeds and grid placements, which measures how much the forward model alone moves the
// held-out E (the noise floor); with several runs, the base is also fitted to each run alone. The
// conclusion is one of three: a missing effect, named when its fit
// predicts the held-out rest better than the base by a clear margin, by more than the noise floor
// explains, and pays for its parameters in the fitted part (BIC); no missing effect, where such a
// gain would have shown and none did; or cannot tell, with what would tell.
#pragma once

#include "diagnose/effect.h"
#include "identify/identify.h"

#include <nlohmann/json.hpp>

#include <array>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace viscoscope::diagnose {

// Every effect diagnose can add, in the order it fits them.
const std::vector<Effect>& effects();

struct DiagnoseOptions {
    identify::IdentifyOptions identify;  // for every fit (its fields are not written)
    // The share of each run's compared frames fitted; the later rest is predicted and scored.
    double fitShare = 2.0 / 3;
    // The candidates by name; empty: every effect of `catalogue` the scene can hold.
    std::vector<std::string> effects;
    // The effects to choose from; null: effects().
    const std::vector<Effect>* catalogue = nullptr;
    // Wall seconds for the whole diagnosis (0: each fit has the job's own time_budget_s). Each fit's
    // search gets an equal share of what the fits before it left, less the time its scoring on
    // every frame is predicted to take; candidates whose least fits the rest cannot hold, predicted
    // from the fits before them, are not fitted.
    double timeBudget = 0;
    // Further scorings of the base's θ* on other particle seeds and grid placements, for the noise
    // floor (a thin film has none to measure: its model is deterministic).
    int scatterReplicas = 2;
    // Before each fit: its model ("base" or an effect's name), its index, the number of fits and the
    // parameters it searches.
    std::function<void(const std::string& model, int index, int count, const std::vector<std::string>& parameters)> onFit;
};

// One fitted model, scored over the whole reference.
struct ModelFit {
    std::string model;  // "base" or an effect's name
    std::vector<std::string> parameters;
    std::vector<double> theta;
    std::vector<std::array<double, 2>> interval;
    std::vector<std::vector<double>> indistinguishable;  // several parameters: identify's, for the flow curve's band
    double fittedE = 0;    // the fitted frames' E, every run
    double heldOutE = 0;   // the held-out frames' E: the prediction's error
    double wholeE = 0;     // all frames
    double bic = 0;        // N ln(fittedE / N) + k ln N over the N fitted frames
    std::optional<double> trackError;  // relative L2 of the measured track over all frames (first run)
    std::optional<double> shearRate;   // 1/s, the flow's at θ* over all frames (Evaluation::shearRate)
    // 1/s, the shear rates the flow at θ* exercised: the 10th and 90th percentiles of every run's
    // frames' (Evaluation::frameShearRates), each frame counted once; none for the thin film.
    std::optional<std::array<double, 2>> shearRateRange;
    long evaluations = 0;
    double seconds = 0;          // the search's
    double scoringSeconds = 0;   // θ* simulated again over every frame of every run
    double timeBudget = 0;       // the search's share of the diagnosis's budget (0: the job's own)
    std::optional<identify::StopReason> stop;  // why the search ended; none when there was nothing to search
    std::vector<std::string> doubts;  // why its search's result is probably wrong (result.json's doubts)
    // The material θ* implies, as a scene file's "material" holds it: what the add-on applies.
    nlohmann::json material;
    // Its search ran to its own end (a tolerance or the job's max_generations), or there was nothing
    // to search: it was not cut short by a time budget or a cancel.
    bool searchCompleted() const;
};

// The forward model's own scatter at the base's θ*: its held-out E on the base's seed and grid
// placements and again on others. Measured in ln E: E sums squared errors, and its scatter grows
// with it (the collapsing column's held-out E moved by a factor 2.7 over three scorings where the
// base fitted poorly: tests/bench/FINDINGS.md, "The noise floor of a diagnosis").
struct NoiseFloor {
    std::vector<double> heldOutE;  // the base's scoring first, then each replica's
    bool deterministic = false;    // a forward model without seed or grid (the thin film)
    double seconds = 0;            // the replicas'
    double logSpread() const;      // the sample standard deviation of ln heldOutE
    // The least held-out gain of one fit over another, as a share of the other's held-out E, that
    // the scatter does not explain: 1 − exp(−t(0.95, m − 1) √2 · logSpread) over m samples; 0 for a
    // deterministic model, 1 (no gain) with fewer than two samples.
    double visibleShare() const;
};

enum class Verdict { MissingEffect, NoMissingEffect, CannotTell };
const char* toString(Verdict verdict);  // "missing_effect", "no_missing_effect", "cannot_tell"

struct Diagnosis {
    ModelFit base;
    std::vector<ModelFit> candidates;
    // With several runs, the base fitted to each run alone (its first part), in the job's order of
    // runs: the values a run's geometry alone gives, which one base model cannot hold when they
    // disagree.
    std::vector<ModelFit> runFits;
    NoiseFloor noise;
    Verdict verdict = Verdict::CannotTell;
    std::optional<size_t> chosen;  // into candidates, with Verdict::MissingEffect
    nlohmann::json document;       // what diagnosis.json holds
};

// Runs (or resumes: each fit keeps its own checkpoint under OUT/fits/<model>) the diagnosis and writes
// OUT/diagnosis.json. Throws InputError when the reference has too few frames to hold any out, or an
// asked-for effect is unknown or one the scene cannot hold; Cancelled on a cancel request.
Diagnosis diagnose(const identify::Job& job, const std::filesystem::path& outDir, const DiagnoseOptions& options = {});

}  // namespace viscoscope::diagnose
