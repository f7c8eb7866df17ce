// The diagnose stage's face: from the residual of the best fit to the physical effect the model
// lacks (DESIGN.md, "Diagnosis: closing the loop"). The job's model (the base) and each candidate
// effect the scene can hold (effect.h, effects()) are fitted to the first part of the reference
// (each its own identification) and scored on all of it; a candidate is chosen only when it
// predicts the held-out rest better than the base by a clear margin and pays for its parameters in
// the fitted part (BIC), else "no missing effect".
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
    // every frame is predicted to take.
    double timeBudget = 0;
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
    double fittedE = 0;    // the fitted frames' E, every run
    double heldOutE = 0;   // the held-out frames' E: the prediction's error
    double wholeE = 0;     // all frames
    double bic = 0;        // N ln(fittedE / N) + k ln N over the N fitted frames
    std::optional<double> trackError;  // relative L2 of the measured track over all frames (first run)
    std::optional<double> shearRate;   // 1/s, the flow's at θ* over all frames (Evaluation::shearRate)
    long evaluations = 0;
    double seconds = 0;          // the search's
    double scoringSeconds = 0;   // θ* simulated again over every frame of every run
    double timeBudget = 0;       // the search's share of the diagnosis's budget (0: the job's own)
    std::optional<identify::StopReason> stop;  // why the search ended; none when there was nothing to search
    // The material θ* implies, as a scene file's "material" holds it: what the add-on applies.
    nlohmann::json material;
};

struct Diagnosis {
    ModelFit base;
    std::vector<ModelFit> candidates;
    std::optional<size_t> chosen;  // into candidates; none: no missing effect
    nlohmann::json document;       // what diagnosis.json holds
};

// Runs (or resumes: each fit keeps its own checkpoint under OUT/fits/<model>) the diagnosis and writes
// OUT/diagnosis.json. Throws InputError when the reference has too few frames to hold any out, or an
// asked-for effect is unknown or one the scene cannot hold; Cancelled on a cancel request.
Diagnosis diagnose(const identify::Job& job, const std::filesystem::path& outDir, const DiagnoseOptions& options = {});

}  // namespace viscoscope::diagnose
