// Diagnosis: fit the base model and each candidate effect to the first part of every run, predict
// the rest, measure how much the forward model alone moves that prediction, and conclude
// (conclusion.h).
//
// Out of sample, because in sample any added parameter lowers E: the fit sees each run's first
// fitShare of compared frames, and the held-out later frames are where a missing effect shows most
// (a front that stops in the footage but not in the simulation, a flow that slows differently).
#include "diagnose/diagnose.h"

#include "diagnose/conclusion.h"
#include "diagnose/effects/effects.h"
#include "diagnose/flow_curve.h"
#include "diagnose/model_fit.h"
#include "sim/sim.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

namespace viscoscope::diagnose {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace identify;

namespace {

// A fit whose added parameters all end within this log distance of their base-equivalent values (n
// = 1, τ_y or the slip at its least, the channel at its widest) is the base model: when it predicts
// better, the base fit was not converged, which is not an effect (on the measured particle-laden dam
// break the power law ended at n = 1 with a better η than the base's: tests/bench/FINDINGS.md,
// "Diagnose on the measured particle-laden syrup dam break").
constexpr double kVanishedLogDistance = 0.01;

// The base fit and its refit may each take this many fits' shares of the budget: every candidate is
// judged against the base, and a base cut short lets none be named, while what it leaves unspent
// the other fits share. With one share each, the lotion's base was cut short after 5–7
// generations, where its E had just settled (tests/bench/FINDINGS.md, "Fits that end on their own:
// tolerance_fun").
constexpr double kBaseShares = 3;

// A searched parameter of the base, restarted at the base fit within its own bounds.
json warmStart(const ParameterSpec& p, double theta) {
    json spec = searchedParameter(p.name(), theta, kWarmLogSpread);
    spec["min"] = p.lower;
    spec["max"] = p.upper;
    return spec;
}

// An effect as one fit of the diagnosis: the model's "parameters" (the base's kept ones restarted
// at the base fit, then the effect's) and what the effect added.
struct Candidate {
    const Effect* effect = nullptr;
    json parameters = json::array();
    std::vector<AddedParameter> added;
};

// The candidate of `effect` for `base`, or why the base's job cannot take it.
std::string candidateFor(const Effect& effect, const BaseFit& base, Candidate& candidate) {
    candidate = {&effect, json::array(), {}};
    const Job& job = base.job;
    if (effect.law) {
        if (!base.value("viscosity")) return "the job does not search the viscosity the law replaces";
        if (!std::holds_alternative<Newtonian>(job.scene.material.model)) return "the base model is not Newtonian";
    }
    for (size_t i = 0; i < job.parameters.size(); ++i)
        if (!(effect.law && job.parameters[i].name() == "viscosity"))
            candidate.parameters.push_back(warmStart(job.parameters[i], base.theta[i]));
    if (std::string why = effect.parameters(base, candidate.added); !why.empty()) return why;
    for (const AddedParameter& p : candidate.added) candidate.parameters.push_back(p.spec);
    return "";
}

const AddedParameter* findAdded(const Candidate& candidate, const std::string& name) {
    for (const AddedParameter& p : candidate.added)
        if (p.spec.at("name") == name) return &p;
    return nullptr;
}

// A candidate's parameters where its effect vanishes (AddedParameter::vanishesAt), the base fit's
// values for the rest. Scored with the fit's first generation, so that no candidate ends worse than
// the base in sample: from their own starts, the measured syrup dam break's material laws did
// (tests/bench/FINDINGS.md, "Diagnose on the measured syrup dam break"); and where a fit ends here,
// it is the base model (effectVanishes).
std::vector<double> baseEquivalent(const Job& model, const Candidate& candidate, const BaseFit& base) {
    std::vector<double> theta;
    for (const ParameterSpec& p : model.parameters) {
        const AddedParameter* added = findAdded(candidate, p.name());
        const double value = added ? added->vanishesAt : *base.value(p.name());
        theta.push_back(std::clamp(value, p.lower, p.upper));
    }
    return theta;
}

// Whether `fit` ended where its effect vanishes: each parameter the effect adds (not one that stands
// for a base parameter) within kVanishedLogDistance of its value in `equivalent`.
bool effectVanishes(const ModelFit& fit, const Candidate& candidate, const std::vector<double>& equivalent) {
    for (size_t i = 0; i < fit.parameters.size(); ++i) {
        const AddedParameter* added = findAdded(candidate, fit.parameters[i]);
        if (added && !added->standsForBase && std::abs(std::log(fit.theta[i] / equivalent[i])) > kVanishedLogDistance)
            return false;
    }
    return true;
}

// Where a candidate's fit puts the base: the base's parameters it shares at their fitted values, and
// the viscosity a material law takes the place of at the law's apparent viscosity at the fitted
// flow's shear rate (at 1 s⁻¹ where the forward model reports none, the thin film: the consistency of
// a power law, K + τ_y of a Bingham liquid).
std::vector<double> apparentBase(const ModelFit& fit, const Job& model, const Job& base) {
    const Material material = sceneWithParameters(model, fit.theta, model.resolution).material;
    std::vector<double> theta;
    for (const ParameterSpec& p : base.parameters) {
        const auto shared = std::find(fit.parameters.begin(), fit.parameters.end(), p.name());
        const double value = shared != fit.parameters.end() ? fit.theta[shared - fit.parameters.begin()]
                                                            : sim::apparentViscosity(material, fit.shearRate.value_or(1.0));
        theta.push_back(std::clamp(value, p.lower, p.upper));
    }
    return theta;
}

std::string effectNames(const std::vector<Effect>& catalogue) {
    std::string names;
    for (const Effect& e : catalogue) names += (names.empty() ? "" : ", ") + e.name;
    return names;
}

}  // namespace

json searchedParameter(const std::string& name, double initial, double logSpread) {
    return {{"name", name}, {"initial", initial}, {"spread", initial * std::expm1(logSpread)}};
}

std::optional<double> BaseFit::value(const std::string& name) const {
    for (size_t i = 0; i < job.parameters.size(); ++i)
        if (job.parameters[i].name() == name) return theta[i];
    return std::nullopt;
}

bool BaseFit::sets(const std::string& name) const {
    return value(name) || std::any_of(job.fixed.begin(), job.fixed.end(),
                                      [&](const FixedParameter& f) { return f.parameter.name == name; });
}

Diagnosis diagnose(const Job& jobIn, const fs::path& outDir, const DiagnoseOptions& options) {
    if (!(options.fitShare > 0 && options.fitShare < 1))
        throw InputError("diagnose: the fitted share must lie between 0 and 1, got " + std::to_string(options.fitShare));
    const std::vector<Effect>& catalogue = options.catalogue ? *options.catalogue : effects();
    for (const std::string& effect : options.effects)
        if (std::none_of(catalogue.begin(), catalogue.end(), [&](const Effect& e) { return effect == e.name; }))
            throw InputError("diagnose: unknown effect \"" + effect + "\" (" + effectNames(catalogue) + ")");
    if (!(options.timeBudget >= 0 && std::isfinite(options.timeBudget)))
        throw InputError("diagnose: the time budget must be a finite number of seconds ≥ 0 (0 = each fit's job budget), got " +
                         formatNumber(options.timeBudget));
    fs::create_directories(outDir);
    Job job = jobIn;
    prepareReference(job, outDir);
    for (size_t k = 0; k < job.otherRuns.size(); ++k) prepareReference(job.otherRuns[k], outDir / ("run" + std::to_string(k + 1)));

    // Each run's compared frames: the first fitShare of them are fitted, the rest held out.
    std::vector<Observation> observations;
    std::vector<int> fitCounts;
    for (const Job& run : runsOf(job)) {
        observations.push_back(loadObservation(run));
        const int compared = static_cast<int>(comparedFrames(observations.back()).size());
        const int fitted = std::max(kMinInformativeFrames, int(std::lround(options.fitShare * compared)));
        if (compared - fitted < 2)
            throw InputError(run.file.string() + ": diagnose: " + std::to_string(compared) +
                             " compared frames, too few to fit " + std::to_string(fitted) +
                             " and predict at least 2 more (a longer clip or track, or a smaller fitted share)");
        fitCounts.push_back(fitted);
    }

    // The candidates the job can take, in the declared order.
    std::vector<std::pair<std::string, std::string>> refused;  // effect, why
    std::vector<const Effect*> candidates;
    const std::vector<double> unfitted(job.parameters.size(), 1.0);
    for (const Effect& effect : catalogue) {
        const bool asked = options.effects.empty() ||
                           std::find(options.effects.begin(), options.effects.end(), effect.name) != options.effects.end();
        if (!asked) continue;
        Candidate probe;
        const std::string why = candidateFor(effect, {job, unfitted, std::nullopt}, probe);
        if (why.empty()) candidates.push_back(&effect);
        else if (!options.effects.empty()) throw InputError(job.file.string() + ": diagnose: " + effect.name + ": " + why);
        else refused.emplace_back(effect.name, why);
    }
    // With several runs, the base fitted to each alone too (nothing to fit when every unknown is fixed).
    const int runFits = job.otherRuns.empty() || job.parameters.empty() ? 0 : 1 + static_cast<int>(job.otherRuns.size());
    // And the best contender's fits to each run alone, which test it across the runs.
    int crossRunFits = candidates.empty() ? 0 : runFits;
    const int fits = 1 + static_cast<int>(candidates.size()) + runFits + crossRunFits;
    // The steps the progress counts: the fits and the noise floor after the base's.
    const bool measuresScatter = options.scatterReplicas > 0;
    int steps = fits + (measuresScatter ? 1 : 0);
    int step = 0;

    json warnings = json::array();
    const auto warn = [&](const std::string& line) {
        warnings.push_back(line);
        if (options.identify.onWarning) options.identify.onWarning(line);
    };
    Diagnosis diagnosis;
    json baseSeries;
    if (options.onFit) options.onFit("base", step++, steps, parameterNames(job));
    FitBudget budget(options.timeBudget, fits);
    diagnosis.base = fitModel("base", job, modelJob(job, nullptr, {}, fitCounts), observations, fitCounts, outDir / "fits" / "base",
                              options.identify, budget.nextSearch(kBaseShares), baseSeries);
    budget.spend(diagnosis.base);
    // Said at once, not after hours of candidates: a base cut short cannot be beaten fairly.
    if (!diagnosis.base.searchCompleted())
        warn("diagnose: the base fit was cut short (" + std::string(toString(*diagnosis.base.stop)) + ") after " +
             std::to_string(diagnosis.base.evaluations) + " evaluations: no effect will be named unless its refit "
             "completes (a larger --time-budget, or 0 to give each fit the job's own)");
    FitCost cost = FitCost::of(diagnosis.base);
    // The model `name` (`model`: its job over every run, with `effect`'s law) fitted to each run alone
    // over its fitted frames, restarted at `theta` and scoring it as a known point, into
    // fits/<name>_run<k>; each fit is scored on the other runs too (what it predicts of them).
    struct RunsAlone {
        std::vector<ModelFit> fits;
        json entries = json::array();  // for diagnosis.json
        double otherRunsE = 0;         // what the fits predict of the other runs, summed
    };
    const auto fitEachRunAlone = [&](const std::string& name, const Job& model, const Effect* effect,
                                     const std::vector<double>& theta) {
        json parameters = json::array();
        for (size_t i = 0; i < model.parameters.size(); ++i) parameters.push_back(warmStart(model.parameters[i], theta[i]));
        const std::vector<Job> runs = runsOf(model);
        RunsAlone alone;
        for (size_t r = 0; r < runs.size(); ++r) {
            const std::string folder = name + "_run" + std::to_string(r + 1);
            if (options.onFit) options.onFit(folder, step++, steps, parameterNames(model));
            IdentifyOptions identifyOptions = options.identify;
            identifyOptions.knownPoint = theta;
            json series;
            ModelFit& fit = alone.fits.emplace_back(
                fitModel(name, runs[r],
                         screenedOnOnePlacement(modelJob(runs[r], effect, parameters, {fitCounts[r]})), {observations[r]},
                         {fitCounts[r]}, outDir / "fits" / folder, identifyOptions, budget.nextSearch(), series));
            const auto started = std::chrono::steady_clock::now();
            const double predicted = predictOtherRuns(model, observations, fitCounts, fit.theta, r);
            fit.scoringSeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
            budget.spend(fit);
            alone.otherRunsE += predicted;
            json entry = toJson(fit, series, folder);
            entry["run"] = r + 1;
            entry["other_runs_E"] = predicted;
            alone.entries.push_back(entry);
        }
        return alone;
    };
    // Each run alone, restarted at the base fit: about one base fit's least in all, each run holding
    // its share of the frames.
    json runsDoc = json::array();
    std::optional<double> baseCrossRunE;  // what the base's fits to each run alone predict of the others
    if (runFits > 0 && !budget.holds(cost.leastFit(job, int(job.parameters.size())))) {
        warn("diagnose: the time budget cannot hold the base's fits to each run alone: the runs are not compared");
        budget.forgo(runFits + crossRunFits);
        steps -= runFits + crossRunFits;
        crossRunFits = 0;
    } else if (runFits > 0) {
        RunsAlone alone = fitEachRunAlone("base", job, nullptr, diagnosis.base.theta);
        diagnosis.runFits = std::move(alone.fits);
        runsDoc = alone.entries;
        baseCrossRunE = alone.otherRunsE;
    }
    const BaseFit baseFit{job, diagnosis.base.theta, diagnosis.base.shearRate};
    std::vector<Candidate> fitted(candidates.size());  // each candidate as it is fitted
    for (size_t c = 0; c < candidates.size(); ++c) candidateFor(*candidates[c], baseFit, fitted[c]);
    // Before the candidates' hours, and again before each: whether the budget holds the least fits
    // of those left at the dearest cost measured so far (the base's at first; a material law's
    // evaluation and scoring cost more than a Newtonian one's, so each fitted candidate may raise
    // it), and before the first the noise floor's scorings too (each as long as the base's). Those
    // it cannot hold are not fitted: the conclusion cannot then be "no missing effect", and it says
    // what budget would hold them.
    const int replicas = std::max(0, options.scatterReplicas);
    const double noiseSeconds = replicas * diagnosis.base.scoringSeconds;
    Unfitted beyondBudget;
    double droppedLeast = 0;  // the least fits of the candidates left unfitted so far
    // Keeps the candidates from `first` on, in their order, that the budget holds after `besides`
    // seconds more; whether it holds the one at `first`.
    const auto budgetHoldsFrom = [&](size_t first, double besides) {
        std::vector<double> least;
        for (size_t c = first; c < fitted.size(); ++c) least.push_back(cost.leastFit(job, int(fitted[c].parameters.size())));
        size_t kept = 0;
        double needed = besides;
        while (kept < least.size() && budget.holds(needed + least[kept])) needed += least[kept++];
        if (kept == least.size()) return true;
        const size_t dropped = least.size() - kept;
        // What a budget holding them all needs: what is spent, the fits left, and those dropped before.
        const double allLeft = std::accumulate(least.begin(), least.end(), besides);
        beyondBudget.budgetNeeded = budget.spent() + allLeft + droppedLeast;
        beyondBudget.candidates += int(dropped);
        droppedLeast += allLeft - needed;
        std::string names;
        for (size_t c = first + kept; c < candidates.size(); ++c) {
            names += (names.empty() ? "" : ", ") + candidates[c]->name;
            refused.emplace_back(candidates[c]->name, "the time budget: its fit takes about " +
                                                          std::to_string(std::lround(least[c - first])) +
                                                          " s at least (at the cost of the fits before it), more "
                                                          "than the budget had left");
        }
        warn("diagnose: the time budget cannot hold the least fits of " + names + ": they are not fitted (a "
             "--time-budget of about " + std::to_string(std::lround(beyondBudget.budgetNeeded)) +
             " s or more, or fewer --effects)");
        steps -= int(dropped);
        budget.forgo(int(dropped));
        candidates.resize(first + kept);
        fitted.resize(first + kept);
        return kept > 0;
    };
    budgetHoldsFrom(0, noiseSeconds);
    if (measuresScatter && options.onFit) options.onFit("noise_floor", step++, steps, {});
    diagnosis.noise = measureScatter(job, observations, fitCounts, diagnosis.base, budget.holds(noiseSeconds) ? replicas : 0);
    budget.spend(diagnosis.noise);
    json candidatesDoc = json::array();
    std::vector<json> candidateSeries;
    std::vector<Job> models;                       // each candidate's job over all frames
    std::vector<std::vector<double>> equivalents;  // each candidate's base-equivalent point
    for (size_t c = 0; c < candidates.size(); ++c) {
        if (c > 0 && !budgetHoldsFrom(c, 0)) break;
        const Effect& effect = *candidates[c];
        const Candidate& candidate = fitted[c];
        const json& parameters = candidate.parameters;
        if (options.onFit) {
            std::vector<std::string> names;
            for (const json& p : parameters) names.push_back(p.at("name").get<std::string>());
            options.onFit(effect.name, step++, steps, names);
        }
        // The base fit's values in every run's scene, where the effect's model takes its K from.
        Job base = job;
        for (Job* run : everyRun(base))
            for (size_t i = 0; i < run->parameters.size(); ++i)
                setParameter(run->scene, run->parameters[i].parameter, diagnosis.base.theta[i]);
        const Job& full = models.emplace_back(modelJob(base, &effect, parameters, {}));
        equivalents.push_back(baseEquivalent(full, candidate, baseFit));
        // An effect with a start curve scans it from the base's own flow (where it starts: the base
        // equivalent); the others score that point beside their first generation.
        IdentifyOptions identifyOptions = options.identify;
        if (effect.startCurve) identifyOptions.startCurve = effect.startCurve(parameters, baseFit);
        if (!identifyOptions.startCurve) identifyOptions.knownPoint = equivalents.back();
        json series;
        const Job fitting = screenedOnOnePlacement(modelJob(base, &effect, parameters, fitCounts));
        diagnosis.candidates.push_back(fitModel(effect.name, full, fitting, observations, fitCounts,
                                                outDir / "fits" / effect.name, identifyOptions, budget.nextSearch(), series));
        budget.spend(diagnosis.candidates.back());
        cost.raiseTo(FitCost::of(diagnosis.candidates.back()));
        candidateSeries.push_back(series);
    }

    const auto beats = [](const ModelFit& fit, const ModelFit& base) {
        return fit.heldOutE < (1 - kHeldOutGain) * base.heldOutE && fit.bic < base.bic;
    };
    // An effect is judged against a base refit from where that effect's fit puts it: a base search
    // that stopped short lets every candidate stand in for the viscosity it missed (FINDINGS, "An
    // unconverged base"). The refit starts at the apparent base of the candidate that predicts best
    // of those that beat the first base fit, scores that fit as a known point, and takes its place
    // when it fits the fitted frames better.
    std::optional<size_t> challenger;
    for (size_t c = 0; c < diagnosis.candidates.size(); ++c)
        if (beats(diagnosis.candidates[c], diagnosis.base) &&
            (!challenger || diagnosis.candidates[c].heldOutE < diagnosis.candidates[*challenger].heldOutE))
            challenger = c;
    std::string baseFolder = "base";
    json baseRefit;
    const double leastRefit = FitCost::of(diagnosis.base).leastFit(job, int(job.parameters.size()));
    if (challenger && !job.parameters.empty() && !budget.holds(leastRefit))
        warn("diagnose: no time left to refit the base (about " + std::to_string(std::lround(leastRefit)) +
             " s at least): the candidates are judged against the first base fit");
    else if (challenger && !job.parameters.empty()) {
        const ModelFit& from = diagnosis.candidates[*challenger];
        const std::vector<double> start = apparentBase(from, models[*challenger], job);
        json parameters = json::array();
        for (size_t i = 0; i < job.parameters.size(); ++i) parameters.push_back(warmStart(job.parameters[i], start[i]));
        const std::vector<std::string> names = parameterNames(job);
        if (options.onFit) options.onFit("base_refit", step++, steps + 1, names);
        IdentifyOptions identifyOptions = options.identify;
        identifyOptions.knownPoint = diagnosis.base.theta;
        json series;
        ModelFit refit = fitModel("base", job, modelJob(job, nullptr, parameters, fitCounts), observations, fitCounts,
                                  outDir / "fits" / "base_refit", identifyOptions, budget.nextSearch(kBaseShares), series);
        budget.spend(refit);
        const bool replaces = refit.fittedE < diagnosis.base.fittedE;
        if (replaces) {
            std::string at;
            for (size_t i = 0; i < names.size(); ++i) at += (i ? ", " : "") + names[i] + " " + formatNumber(start[i]);
            warn("diagnose: the base fit had not converged: refit from where " + from.model + "'s fit puts it (" + at +
                 "), it fits the fitted frames " +
                 std::to_string(int(std::lround(100 * (1 - refit.fittedE / diagnosis.base.fittedE)))) +
                 " % better, and the candidates are judged against the refit");
            std::swap(diagnosis.base, refit);
            std::swap(baseSeries, series);
            baseFolder = "base_refit";
        }
        baseRefit = {{"from", from.model},
                     {"replaced_first_fit", replaces},
                     {"unused_fit", toJson(refit, series, replaces ? "base" : "base_refit")}};
    }
    const ModelFit& base = diagnosis.base;
    std::vector<Judged> judged;
    for (size_t c = 0; c < diagnosis.candidates.size(); ++c) {
        const ModelFit& fit = diagnosis.candidates[c];
        const bool vanishes = effectVanishes(fit, fitted[c], equivalents[c]);
        if (beats(fit, base) && vanishes)
            warn("diagnose: " + fit.model + " ended where its effect vanishes, as the base model, yet predicts the "
                 "held-out frames " + std::to_string(int(std::lround(100 * (1 - fit.heldOutE / base.heldOutE)))) +
                 " % better than the base fit: the base fit is not converged (more generations or time, or fewer "
                 "--effects to share them)");
        judged.push_back({&fit, candidates[c], vanishes, std::nullopt});
    }
    // Across the runs: the best contender fitted to each run alone too, restarted at its fit to them
    // all, and what it predicts of the other runs against what the base's fits to each do (conclusion.h).
    std::vector<json> crossRunDocs(diagnosis.candidates.size());
    json testedAcrossRuns;  // its name
    if (baseCrossRunE) {
        // The one the conclusion would name of those that contend.
        std::vector<const ModelFit*> fits;
        std::vector<bool> contending;
        for (size_t c = 0; c < diagnosis.candidates.size(); ++c) {
            fits.push_back(&diagnosis.candidates[c]);
            contending.push_back(contends(judged[c], base, diagnosis.noise));
        }
        std::optional<size_t> contender = preferredFit(fits, contending);
        if (contender) {
            const ModelFit& fit = diagnosis.candidates[*contender];
            const double least = cost.leastFit(job, int(fit.theta.size()));
            if (!budget.holds(least)) {
                warn("diagnose: no time left to fit " + fit.model + " to each run alone (about " +
                     std::to_string(std::lround(least)) + " s at least): it is not tested across the runs");
                contender.reset();
            }
        }
        if (contender) {
            const size_t c = *contender;
            const RunsAlone alone =
                fitEachRunAlone(diagnosis.candidates[c].model, models[c], candidates[c], diagnosis.candidates[c].theta);
            judged[c].crossRunE = alone.otherRunsE;
            crossRunDocs[c] = {{"E", alone.otherRunsE}, {"per_run", alone.entries}};
            testedAcrossRuns = diagnosis.candidates[c].model;
        } else {
            budget.forgo(crossRunFits);
            steps -= crossRunFits;
        }
    }
    const Conclusion conclusion = conclude(job, options.timeBudget, base, judged, diagnosis.noise, beyondBudget,
                                           diagnosis.runFits, baseCrossRunE);
    diagnosis.verdict = conclusion.verdict;
    diagnosis.chosen = conclusion.chosen;
    for (size_t c = 0; c < diagnosis.candidates.size(); ++c) {
        const CandidateVerdict& v = conclusion.candidates[c];
        json entry = toJson(diagnosis.candidates[c], candidateSeries[c], diagnosis.candidates[c].model);
        entry["title"] = candidates[c]->title;
        entry["description"] = candidates[c]->description;
        entry["source"] = candidates[c]->source;
        entry["held_out_gain"] = v.relativeGain;
        entry["above_noise"] = v.aboveNoise;
        entry["effect_vanishes"] = judged[c].vanishes;
        entry["earns_its_parameters"] = v.earns;
        if (!crossRunDocs[c].is_null()) {
            entry["cross_run"] = crossRunDocs[c];
            entry["cross_run"]["gain"] = v.crossRunGain ? json(*v.crossRunGain) : json();
        }
        candidatesDoc.push_back(entry);
    }
    if (conclusion.verdict == Verdict::CannotTell) {
        std::string tell;
        for (const std::string& t : conclusion.whatWouldTell) tell += (tell.empty() ? "" : "; ") + t;
        // diagnosis.json and the panel hold it as the conclusion itself.
        if (options.identify.onWarning)
            options.identify.onWarning("diagnose: " + conclusion.sentence + (tell.empty() ? "" : " (what would tell: " + tell + ")"));
    }
    // Each search makes its minimum generations whatever its share, so a diagnosis can end late: say
    // so, with what would take less.
    if (options.timeBudget > 0 && budget.spent() > options.timeBudget)
        warn("diagnose: the fits took " + std::to_string(std::lround(budget.spent())) + " s of a " +
                 std::to_string(std::lround(options.timeBudget)) +
             " s budget: each search makes at least " + std::to_string(job.fidelity.minFineGenerations) +
             " generations (a coarser grid, a shorter clip or fewer --effects take less)");
    const NoiseFloor& noise = diagnosis.noise;
    json noiseJson{{"held_out_E", noise.heldOutE},
                   {"log_spread", noise.logSpread()},
                   {"visible_share", noise.visibleShare()},
                   {"deterministic", noise.deterministic},
                   {"seconds", noise.seconds}};
    json notTried = json::array();
    for (const auto& [effect, why] : refused) notTried.push_back({{"effect", effect}, {"why", why}});
    const ModelFit& after = diagnosis.chosen ? diagnosis.candidates[*diagnosis.chosen] : base;
    // Said in the progress lines too (the conclusion's sentence says it).
    if (diagnosis.chosen && !after.searchCompleted())
        warn("diagnose: the fit of the effect named, " + after.model + ", was cut short (" + toString(*after.stop) +
             ") after " + std::to_string(after.evaluations) + " evaluations: the effect stands, but its parameters "
             "and flow curve are not converged (a larger --time-budget, or fewer --effects)");
    const json curve = flowCurve(after, diagnosis.chosen ? models[*diagnosis.chosen] : job);
    if (curve.contains("rheometer") && curve.at("rheometer").at("log_stress_rms").is_number()) {
        const double rms = curve.at("rheometer").at("log_stress_rms").get<double>();
        if (rms > kRheometerLogStressWarning)
            warn("diagnose: the flow curve of " + after.model + " lies " + formatNumber(rms) +
                 " (log10 of stress, RMS) off the job's rheometer over the shear rates both cover: the liquid "
                 "filmed may not be the one measured, or the law found is not the liquid's");
    } else if (curve.contains("rheometer")) {
        warn("diagnose: the job's rheometer curve does not reach the shear rates the flow exercised: not compared");
    }
    json errors{{"E", {{"before", base.wholeE}, {"after", after.wholeE}}},
                {"held_out_E", {{"before", base.heldOutE}, {"after", after.heldOutE}}}};
    if (base.trackError && after.trackError)
        errors["track_error"] = {{"before", *base.trackError}, {"after", *after.trackError}};
    diagnosis.document = {
        {"format", "viscoscope.diagnosis"},
        {"version", 1},
        {"job", job.file.string()},
        {"chosen", diagnosis.chosen ? json(after.model) : json()},
        {"verdict", toString(conclusion.verdict)},
        {"conclusion", conclusion.sentence},
        {"what_would_tell", conclusion.whatWouldTell},
        {"suggested_settings", conclusion.suggestedSettings},
        {"grid", {{"resolution", job.resolution}, {"grid_placements", job.gridPlacements}}},
        {"criterion", "fitted on each run's first " + std::to_string(int(std::lround(100 * options.fitShare))) +
                          " % of compared frames; an effect earns its parameters when its E over the held-out rest is "
                          "below " + std::to_string(int(std::lround(100 * (1 - kHeldOutGain)))) +
                          " % of the base's, its gain exceeds the share the noise floor explains (visible_share), " +
                          (baseCrossRunE ? "its fits to each run alone predict the other runs by as much better than the "
                                           "base's do (cross_run)"
                                         : "its BIC over the fitted frames is below the base's") +
                          ", and the base fit's search was not cut short"},
        {"noise_floor", noiseJson},
        {"fitted_frames", fitCounts},
        {"time_budget_s", options.timeBudget},
        {"seconds", budget.spent()},
        {"warnings", warnings},
        {"base", toJson(base, baseSeries, baseFolder)},
        {"candidates", candidatesDoc},
        {"not_tried", notTried},
        {"errors", errors},
        {"flow_curve", curve}};
    if (!baseRefit.is_null()) diagnosis.document["base_refit"] = baseRefit;
    if (!runsDoc.empty()) {
        diagnosis.document["base_per_run"] = runsDoc;
        diagnosis.document["runs_disagree"] =
            conclusion.runsDisagreement ? json(*conclusion.runsDisagreement) : json();
        diagnosis.document["cross_run"] = {
            {"base_E", baseCrossRunE ? json(*baseCrossRunE) : json()},
            {"tested", testedAcrossRuns}};
    }
    writeJsonAtomically(diagnosis.document, outDir / "diagnosis.json");
    return diagnosis;
}

}  // namespace viscoscope::diagnose
