// A diagnosable effect as a record: what the model lacks, as the parameters it adds, how it changes
// the scene and where it gives the base model back. diagnose() runs every record of effects() alike;
// nothing compares an effect's name. A new effect is one file under effects/ and one line in
// effects/catalogue.cpp (docs/layout.md, "Adding an effect").
#pragma once

#include "identify/identify.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace viscoscope::diagnose {

// What an effect sees of the base: its job and its fit. Before the base is fitted (when diagnose
// only asks whether the job can take the effect) θ is 1 for every parameter and no shear rate is
// known.
struct BaseFit {
    const identify::Job& job;
    const std::vector<double>& theta;
    std::optional<double> shearRate;  // 1/s, the base flow's (none on a thin film)
    // θ of the base's searched parameter `name`; nullopt when the base does not search it.
    std::optional<double> value(const std::string& name) const;
    // Whether the job searches the parameter `name` or holds it fixed.
    bool sets(const std::string& name) const;
};

// One parameter an effect searches beside (or in place of) the base's.
struct AddedParameter {
    // A job's "parameters" entry: name, initial, spread and, where the effect sets them, min and max.
    nlohmann::json spec;
    // Where the effect vanishes, the model then being the base's (n = 1, the least yield stress),
    // clamped into the parameter's bounds: −∞ for its least value, +∞ for its greatest.
    double vanishesAt = -INFINITY;
    // It stands for a base parameter (K for η) rather than adding to the model: its vanishing
    // value is the base's, and it does not say whether the effect vanished.
    bool standsForBase = false;
};

// A curve θ(s), s ∈ [0, 1], for a fit's first generation to scan (identify::IdentifyOptions).
using StartCurve = std::function<std::vector<double>(double)>;

struct Effect {
    std::string name;         // as diagnosis.json and --effects name it
    std::string title;        // in words, as a conclusion names it ("shear thinning")
    std::string description;  // what it adds, one line
    std::string source;       // the law's paper or the reason to suspect it, one line
    // A material law in place of the Newtonian η, given η (its consistency K, with the law at its
    // vanishing point, flows as η): the base must be Newtonian and search η, which the law's
    // parameters replace. None: the effect keeps the base's material and parameters.
    std::function<MaterialModel(double eta)> law;
    // The effect's own parameters for a base, or why the base's job cannot take it (the returned
    // reason is non-empty; `added` is then ignored).
    std::function<std::string(const BaseFit& base, std::vector<AddedParameter>& added)> parameters;
    // A curve from the base's own flow (s = 0) over the effect's range, scanned in place of the
    // first generation's samples around the start; none (or an empty curve, when it needs the base
    // flow's shear rate and there is none): the base-equivalent point is scored beside them.
    // `parameters` are the model's whole "parameters", in order.
    std::function<StartCurve(const nlohmann::json& parameters, const BaseFit& base)> startCurve;
};

// A "parameters" entry searched in ln θ from `initial` with the log spread `logSpread`.
nlohmann::json searchedParameter(const std::string& name, double initial, double logSpread);

}  // namespace viscoscope::diagnose
