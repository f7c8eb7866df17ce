// Diagnosis: fit the base model and each candidate effect to the first part of every run, predict
// the rest, and keep an effect only when it earns its parameters there.
//
// Out of sample, because in sample any added parameter lowers E: the fit sees each run's first
// fitShare of compared frames, and the held-out later frames are where a missing effect shows most
// (a front that stops in the footage but not in the simulation, a flow that slows differently). A
// candidate is chosen when (a) its held-out E is below (1 − kHeldOutGain) of the base's and (b) its
// BIC over the fitted frames is below the base's; of those, the one with the least held-out E.
#include "identify/diagnosis.h"

#include "identify/search_state.h"
#include "sim/sim.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace viscoscope::identify {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// The held-out improvement a candidate must make: a fifth of the base's held-out E, so that a
// candidate which only moves within the fits' own scatter (grid, seed) is not taken for an effect.
constexpr double kHeldOutGain = 0.2;
// A fit whose added parameters all end within this log distance of their base-equivalent values (n
// = 1, τ_y or the slip at its least, the channel at its widest) is the base model: when it predicts
// better, the base fit was not converged, which is not an effect (on the measured particle-laden dam
// break the power law ended at n = 1 with a better η than the base's: FINDINGS, "Diagnose on the
// measured particle-laden syrup dam break").
constexpr double kVanishedLogDistance = 0.01;
// Warm starts: the base's searched parameters start at the base fit (log spread 0.5 around it),
// an effect's new parameters at their declaration's start with a wide log spread; the power law its
// consistency at η* (its first generation scans powerLawRidge instead where it can).
constexpr double kWarmLogSpread = 0.5;
constexpr double kNewLogSpread = 1.5;
constexpr double kStartFlowIndex = 0.8;
// The power law's first generation scans n from 1 down to this along K γ̇_c^(n−1) = η*: thinner
// than most food and cosmetic liquids (xanthan solutions, ketchup: n ≈ 0.2–0.4).
constexpr double kLeastScannedFlowIndex = 0.25;

const std::vector<Effect> kEffects = {
    {"shear_thinning", "power law η = K γ̇^(n−1), n ≤ 1, in place of η: K and n searched",
     "Ostwald–de Waele power law; a gravity current spreads as t^{n/(3n+5)} (DESIGN.md)"},
    {"yield_stress", "Bingham liquid (Herschel–Bulkley with n = 1) in place of η: τ_y and K searched",
     "Herschel & Bulkley 1926; the arrest radius of Roussel & Coussot 2005"},
    {"wall_slip", "Navier slip at solid walls: the slip length searched beside the base's parameters",
     "Navier 1823; the film check in sim_physics_test"},
    {"side_walls", "the width of the scene's channel searched beside the base's parameters",
     "geometry the footage does not show: a channel's side walls slow the flow at every time"},
};

json searched(const std::string& name, double initial, double logSpread) {
    return {{"name", name}, {"initial", initial}, {"spread", initial * std::expm1(logSpread)}};
}

// ρ g h₀, h₀ the height the liquid spans at the start (along gravity); 0 without liquid at the
// start (emitters) or gravity.
double hydrostaticStress(const Scene& scene) {
    const bool emittersOnly = std::all_of(scene.liquids.begin(), scene.liquids.end(), [](const LiquidSource& source) {
        return std::holds_alternative<DiscEmitter>(source);
    });
    if (scene.gravity.norm() == 0 || emittersOnly) return 0.0;
    const sim::Simulation simulation(scene);
    const Eigen::Vector3d down = scene.gravity.normalized();
    double low = INFINITY, high = -INFINITY;
    for (const Eigen::Vector3d& x : simulation.particles().position) {
        low = std::min(low, x.dot(down));
        high = std::max(high, x.dot(down));
    }
    return high > low ? scene.material.density * scene.gravity.norm() * (high - low) : 0.0;
}

int indexOf(const Job& job, const std::string& name) {
    for (size_t i = 0; i < job.parameters.size(); ++i)
        if (job.parameters[i].name() == name) return static_cast<int>(i);
    return -1;
}

bool isFixed(const Job& job, const std::string& name) {
    return std::any_of(job.fixed.begin(), job.fixed.end(), [&](const FixedParameter& f) { return f.parameter.name == name; });
}

// A searched parameter of the base, restarted at the base fit within its own bounds.
json warmStart(const ParameterSpec& p, double theta) {
    json spec = searched(p.name(), theta, kWarmLogSpread);
    spec["min"] = p.lower;
    spec["max"] = p.upper;
    return spec;
}

// The run's scene with the effect's model, or a reason it cannot hold it.
std::string withEffect(Scene& scene, const std::string& effect, double eta) {
    if (effect == "shear_thinning" || effect == "yield_stress") {
        if (!std::holds_alternative<Newtonian>(scene.material.model))
            return "the base model is not Newtonian";
        if (effect == "shear_thinning") scene.material.model = PowerLaw{eta, 1.0};
        else scene.material.model = HerschelBulkley{0.0, eta, 1.0};
    }
    return "";
}

// The base's parameters and the effect's as a job's "parameters", or a reason the job cannot take it;
// `shearRate` is the base flow's, where its forward model reports one.
std::string effectParameters(const Job& job, const std::vector<double>& theta, const std::optional<double>& shearRate,
                             const std::string& effect, json& out) {
    out = json::array();
    const int eta = indexOf(job, "viscosity");
    const bool materialLaw = effect == "shear_thinning" || effect == "yield_stress";
    if (materialLaw && eta < 0) return "the job does not search the viscosity the law replaces";
    for (size_t i = 0; i < job.parameters.size(); ++i)
        if (!(materialLaw && int(i) == eta)) out.push_back(warmStart(job.parameters[i], theta[i]));
    if (effect == "shear_thinning") {
        // From K = η* with a wide spread: where the base flow's shear rate is known (not on a thin
        // film), the first generation scans powerLawRidge instead of sampling around this.
        const ParameterSpec& p = job.parameters[eta];
        json consistency = searched("consistency", theta[eta], kNewLogSpread);
        consistency["min"] = p.lower;
        consistency["max"] = p.upper;
        out.push_back(consistency);
        // Thinning only (n ≤ 1), so that n = 1 is the base: a free n absorbed the difference of the
        // reference's grid in a Newtonian control and predicted it better (tests/bench/FINDINGS.md,
        // "Diagnose on synthetic fronts").
        json index = searched("flow_index", kStartFlowIndex, 0.3);
        index["max"] = 1.0;
        out.push_back(index);
    } else if (effect == "yield_stress") {
        // A Bingham liquid's apparent viscosity is K + τ_y/γ̇, so its K lies within [η*/100, η*], from
        // η*/3: above η* lies a plateau of near-Newtonian fits (K ≈ η*, τ_y a few Pa) that the search
        // stayed on. Not from K + τ_y/γ̇_c = η*: the base flow's γ̇_c is not the rate of a flow with
        // plugs, and that start fitted a hidden yield stress worse (FINDINGS, "Diagnose on synthetic
        // fronts"). τ_y up to the liquid's hydrostatic stress ρ g h₀, from a tenth of it, and down to
        // 1 % of it: below, a yield stress hardly changes the flow and E is flat over many decades of
        // ln τ_y, where the search drifted (FINDINGS, as above). Down to 1 % of the base flow's
        // viscous stress η* γ̇_c where that is less: the least τ_y is the base-equivalent point, and
        // in a slow flow 1 % of ρ g h₀ arrests the front (FINDINGS, "The particle-laden dam break
        // with every candidate").
        const ParameterSpec& p = job.parameters[eta];
        json consistency = searched("consistency", theta[eta] / 3, 1.0);
        consistency["min"] = std::max(p.lower, theta[eta] / 100);
        consistency["max"] = theta[eta];
        out.push_back(consistency);
        const ParameterDeclaration& d = *findParameterDeclaration("yield_stress");
        json yieldStress = searched("yield_stress", d.searchInitial, kNewLogSpread);
        if (const double stress = hydrostaticStress(job.scene); stress > 0) {
            yieldStress = searched("yield_stress", 0.1 * stress, 1.0);
            yieldStress["min"] = std::min(0.01 * stress, shearRate ? 0.01 * theta[eta] * *shearRate : INFINITY);
            yieldStress["max"] = stress;
        }
        out.push_back(yieldStress);
    } else if (effect == "wall_slip") {
        if (indexOf(job, "slip_length") >= 0 || isFixed(job, "slip_length")) return "the job already sets the slip length";
        if (job.scene.material.slipLength > 0) return "the scene already has a slip length";
        const ParameterDeclaration& d = *findParameterDeclaration("slip_length");
        out.push_back(searched("slip_length", d.searchInitial, kNewLogSpread));
    } else if (effect == "side_walls") {
        int channel = -1;
        for (size_t s = 0; s < job.scene.solids.size(); ++s)
            if (std::holds_alternative<ChannelSolid>(job.scene.solids[s])) channel = static_cast<int>(s);
        if (channel < 0) return "the scene has no channel solid";
        const std::string name = "solids[" + std::to_string(channel) + "].width";
        if (indexOf(job, name) >= 0 || isFixed(job, name)) return "the job already sets the channel's width";
        // From the scene's width, anywhere between 4 cells of the job's grid and the domain's
        // extent across: nobody measured it, so a factor 2 around a guess is not the bound.
        const Scene& s = job.scene;
        const double across = s.domain.max.y() - s.domain.min.y();
        const double narrowest = std::min(across, 4 * (s.domain.max - s.domain.min).maxCoeff() / job.resolution);
        if (across < 2 * narrowest) return "the domain is under 8 cells across, too narrow to search the channel's width";
        const double now = std::get<ChannelSolid>(s.solids[channel]).width;
        json width = searched(name, std::clamp(now, narrowest, across), kWarmLogSpread);
        width["min"] = narrowest;
        width["max"] = across;
        out.push_back(width);
    }
    return "";
}

// The power law's curve of (K, n) that flow as the base fit at the base flow's shear rate γ̇_c, K =
// η* γ̇_c^(1−n), from n = 1 (the base's own flow) at s = 0 down to kLeastScannedFlowIndex at s = 1; the
// other parameters at their starts (the base fit). The search's first generation scans it: from
// independent samples of K and n, the synthetic fronts' hidden power law was missed (FINDINGS,
// "Diagnose on synthetic fronts", 11).
std::function<std::vector<double>(double)> powerLawRidge(const json& parameters, double eta, double shearRate) {
    std::vector<double> start;
    int consistency = -1, index = -1;
    for (size_t i = 0; i < parameters.size(); ++i) {
        start.push_back(parameters[i].at("initial").get<double>());
        if (parameters[i].at("name") == "consistency") consistency = static_cast<int>(i);
        if (parameters[i].at("name") == "flow_index") index = static_cast<int>(i);
    }
    const double lower = parameters[consistency].at("min").get<double>();
    const double upper = parameters[consistency].at("max").get<double>();
    return [=](double s) {
        std::vector<double> theta = start;
        theta[index] = 1 - s * (1 - kLeastScannedFlowIndex);
        theta[consistency] = std::clamp(eta * std::pow(shearRate, 1 - theta[index]), lower, upper);
        return theta;
    };
}

// The job and each of its other runs, to change in place.
std::vector<Job*> everyRun(Job& job) {
    std::vector<Job*> runs{&job};
    for (Job& run : job.otherRuns) runs.push_back(&run);
    return runs;
}

std::vector<std::string> parameterNames(const Job& job) {
    std::vector<std::string> names;
    for (const ParameterSpec& p : job.parameters) names.push_back(p.name());
    return names;
}

// The job of a model: the base job with the effect's scene (none: the base's) and `parameters` (none:
// the base's) in every run, limited to `maxFrames[r]` compared frames in run r when given.
Job modelJob(const Job& base, const std::string& effect, const json& parameters, const std::vector<int>& maxFrames) {
    Job job = base;
    const std::vector<Job*> runs = everyRun(job);
    const double eta = job.scene.material.viscosity;
    for (size_t r = 0; r < runs.size(); ++r) {
        Job& run = *runs[r];
        if (!effect.empty()) withEffect(run.scene, effect, eta);
        if (!parameters.empty()) {
            run.parameters.clear();
            for (size_t i = 0; i < parameters.size(); ++i)
                run.parameters.push_back(parseSearchedParameter(
                    parameters[i], run.scene,
                    run.file.string() + ": diagnosis " + (effect.empty() ? "base" : effect) + ": parameters[" +
                        std::to_string(i) + "]"));
            run.document["parameters"] = parameters;
            if (!effect.empty()) run.document["_effect"] = effect;
            // As parseJob has it: placements by generation need a single parameter.
            if (run.parameters.size() > 1) run.placementSchedule = PlacementSchedule::EachEvaluation;
        }
        if (!maxFrames.empty()) {
            run.maxFrames = maxFrames[r];
            run.document["_max_frames"] = maxFrames[r];
        }
        // Every generation over the whole fitted part: an effect that shows late (a front that
        // stops) is not in the coarse phase's first third, whose best point the full-fidelity phase
        // then searches around (FINDINGS, "Diagnose on synthetic fronts").
        run.fidelity.coarseGenerations = 0;
    }
    return job;
}

// A model's search over several parameters screens on one grid placement: on all of them every
// evaluation runs each placement, where the base's one-parameter search takes one a generation, and
// the sample cup's candidates cost 2–3× the base's per evaluation (FINDINGS, "One diagnosis of the
// sample cup against a 30-minute budget"). Every fit is scored on all of them (scoreRun).
Job screenedOnOnePlacement(Job job) {
    for (Job* run : everyRun(job))
        if (run->parameters.size() > 1 && run->gridPlacements > 1) {
            run->gridPlacements = 1;
            run->document["grid_placements"] = 1;
        }
    return job;
}

// Whether `fit` ended where its effect vanishes: each parameter the effect adds (not the base's, nor
// the K that takes η's place) within kVanishedLogDistance of its value in `equivalent`.
bool effectVanishes(const ModelFit& fit, const Job& base, const std::vector<double>& equivalent) {
    for (size_t i = 0; i < fit.parameters.size(); ++i)
        if (indexOf(base, fit.parameters[i]) < 0 && fit.parameters[i] != "consistency" &&
            std::abs(std::log(fit.theta[i] / equivalent[i])) > kVanishedLogDistance)
            return false;
    return true;
}

// Each run of `job` as a job of its own.
std::vector<Job> runsOf(const Job& job) {
    std::vector<Job> runs{job};
    runs.front().otherRuns.clear();
    runs.insert(runs.end(), job.otherRuns.begin(), job.otherRuns.end());
    return runs;
}

struct RunScore {
    double fitted = 0, heldOut = 0, whole = 0;
    int fittedFrames = 0;
    std::optional<double> trackError, shearRate;
    json series = json::array();
};

// E of the reference frames in `frames` (indices): Σ ω_f E_f of the silhouettes and the measured
// track's weight × Σ(sim − measured)² / Σ measured² over them. (The silhouettes' area track, which
// identify adds to E, is left out: it is one term over the whole clip.)
double partE(const Job& run, const Observation& obs, const Evaluation& ev, const std::vector<size_t>& frames) {
    double E = 0, squaredError = 0, squaredMeasured = 0;
    for (size_t i : frames) {
        if (!obs.masks[i].empty()) E += obs.reference.weights[i] * ev.frameE[i];
        if (!obs.measured.empty() && std::isfinite(obs.measured[i]) && i < ev.trackSimulated.size()) {
            squaredError += std::pow(ev.trackSimulated[i] - obs.measured[i], 2);
            squaredMeasured += obs.measured[i] * obs.measured[i];
        }
    }
    if (squaredMeasured > 0) E += run.measuredTrack->weight * squaredError / squaredMeasured;
    return E;
}

// The compared reference frames of a run, in time order.
std::vector<size_t> comparedFrames(const Observation& obs) {
    std::vector<size_t> frames;
    for (size_t i = 0; i < obs.simFrames.size(); ++i)
        if (obs.simFrames[i] >= 0) frames.push_back(i);
    std::stable_sort(frames.begin(), frames.end(), [&](size_t a, size_t b) { return obs.simFrames[a] < obs.simFrames[b]; });
    return frames;
}

// θ scored over every frame of `run`, on each of its grid placements (E their mean), whatever its
// search took, so that every model is scored alike.
RunScore scoreRun(Job run, const Observation& obs, const std::vector<double>& theta, int fitCount) {
    run.placementSchedule = PlacementSchedule::EachEvaluation;
    const Evaluation ev = evaluate(run, obs, theta, run.resolution);
    const std::vector<size_t> frames = comparedFrames(obs);
    const std::vector<size_t> fitted(frames.begin(), frames.begin() + fitCount), heldOut(frames.begin() + fitCount, frames.end());
    RunScore score;
    score.fitted = partE(run, obs, ev, fitted);
    score.heldOut = partE(run, obs, ev, heldOut);
    score.whole = partE(run, obs, ev, frames);
    score.fittedFrames = fitCount;
    score.trackError = ev.trackError;
    score.shearRate = ev.shearRate;
    for (size_t k = 0; k < frames.size(); ++k) {
        const size_t i = frames[k];
        json point{{"time_s", obs.reference.times[i]}, {"sim_frame", obs.simFrames[i]}, {"fitted", k < size_t(fitCount)}};
        if (!obs.masks[i].empty()) point["frame_E"] = ev.frameE[i];
        if (!obs.measured.empty() && std::isfinite(obs.measured[i])) {
            point["measured"] = obs.measured[i];
            point["simulated"] = ev.trackSimulated[i];
        }
        score.series.push_back(point);
    }
    return score;
}

// A candidate's parameters where its effect vanishes, the base fit's values for the rest: n = 1 and
// K = η*, a yield stress and a slip length at their lower bounds, a channel at its widest. Scored
// with the fit's first generation, so that no candidate ends worse than the base in sample: from
// their own starts, the measured syrup dam break's material laws did (FINDINGS, "Diagnose on the
// measured syrup dam break"); and where a fit ends here, it is the base model (effectVanishes).
std::vector<double> baseEquivalent(const Job& model, const Job& base, const std::vector<double>& baseTheta) {
    std::vector<double> theta;
    for (const ParameterSpec& p : model.parameters) {
        double value = p.lower;
        if (const int i = indexOf(base, p.name()); i >= 0) value = baseTheta[i];
        else if (p.name() == "consistency") value = baseTheta[indexOf(base, "viscosity")];
        else if (p.name() == "flow_index") value = 1.0;
        else if (p.parameter.solid >= 0) value = p.upper;
        theta.push_back(std::clamp(value, p.lower, p.upper));
    }
    return theta;
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

// The diagnosis's time budget, spent fit by fit: each search gets an equal share of what is left,
// less the scoring the fit before it took (the next one's scoring costs about as much).
class FitBudget {
  public:
    FitBudget(double total, int fits) : total_(total), fitsLeft_(fits) {}
    // 0: no budget of the diagnosis's own (the job's time_budget_s stands). Never 0 otherwise, which
    // would mean none: an overspent budget still runs the minimum generations (and diagnose warns).
    double nextSearch() const {
        return total_ > 0 ? std::max(1e-3, (total_ - spent_) / std::max(1, fitsLeft_) - lastScoring_) : 0.0;
    }
    void spend(const ModelFit& fit) {
        spent_ += fit.seconds + fit.scoringSeconds;
        lastScoring_ = fit.scoringSeconds;
        --fitsLeft_;
    }
    double spent() const { return spent_; }

  private:
    double total_, spent_ = 0, lastScoring_ = 0;
    int fitsLeft_;
};

// Fits a model to the fitted frames (with `identifyOptions`' known point and start curve, if given)
// within `searchBudget` wall seconds (0: the job's), then scores θ* on every frame of every run.
ModelFit fitModel(const std::string& model, const Job& full, Job fitting, const std::vector<Observation>& observations,
                  const std::vector<int>& fitCounts, const fs::path& dir, IdentifyOptions identifyOptions,
                  double searchBudget, json& runSeries) {
    ModelFit fit;
    fit.model = model;
    for (const ParameterSpec& p : full.parameters) fit.parameters.push_back(p.name());
    if (searchBudget > 0) fitting.timeBudget = searchBudget;
    fit.timeBudget = fitting.timeBudget;
    // A base with every unknown fixed has nothing to fit: it is scored where it is held.
    if (!fitting.parameters.empty()) {
        identifyOptions.writeFields = false;
        const IdentificationResult result = identify(fitting, dir, identifyOptions);
        fit.theta = result.theta;
        fit.interval = result.interval;
        fit.evaluations = result.evaluations;
        fit.seconds = result.seconds;
        fit.stop = result.stop;
    }
    fit.material = sceneToJson(sceneWithParameters(full, fit.theta, full.resolution)).at("material");
    const std::vector<Job> runs = runsOf(full);
    int fittedFrames = 0;
    runSeries = json::array();
    const auto scoringStart = std::chrono::steady_clock::now();
    for (size_t r = 0; r < runs.size(); ++r) {
        const RunScore score = scoreRun(runs[r], observations[r], fit.theta, fitCounts[r]);
        fit.fittedE += score.fitted;
        fit.heldOutE += score.heldOut;
        fit.wholeE += score.whole;
        fittedFrames += score.fittedFrames;
        if (r == 0) {
            fit.trackError = score.trackError;
            fit.shearRate = score.shearRate;
        }
        runSeries.push_back(score.series);
    }
    fit.scoringSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - scoringStart).count();
    const double n = fittedFrames, k = double(fit.theta.size());
    fit.bic = n * std::log(std::max(fit.fittedE, 1e-300) / n) + k * std::log(n);
    return fit;
}

json toJson(const ModelFit& fit, const json& series, const std::string& folder) {
    json parameters = json::object();
    for (size_t i = 0; i < fit.parameters.size(); ++i)
        parameters[fit.parameters[i]] = {{"value", fit.theta[i]}, {"interval", fit.interval[i]}};
    json doc{{"model", fit.model},         {"parameters", parameters},   {"fitted_E", fit.fittedE},
             {"held_out_E", fit.heldOutE}, {"whole_E", fit.wholeE},      {"bic", fit.bic},
             {"evaluations", fit.evaluations}, {"seconds", fit.seconds}, {"scoring_seconds", fit.scoringSeconds},
             {"time_budget_s", fit.timeBudget},   {"material", fit.material},
             {"folder", "fits/" + folder},        {"residual_over_time", series}};
    if (fit.trackError) doc["track_error"] = *fit.trackError;
    if (fit.shearRate) doc["shear_rate_per_s"] = *fit.shearRate;
    if (fit.stop) doc["stopped"] = toString(*fit.stop);
    return doc;
}

}  // namespace

const std::vector<Effect>& diagnosisEffects() { return kEffects; }

Diagnosis diagnose(const Job& jobIn, const fs::path& outDir, const DiagnoseOptions& options) {
    if (!(options.fitShare > 0 && options.fitShare < 1))
        throw InputError("diagnose: the fitted share must lie between 0 and 1, got " + std::to_string(options.fitShare));
    for (const std::string& effect : options.effects)
        if (std::none_of(kEffects.begin(), kEffects.end(), [&](const Effect& e) { return effect == e.name; }))
            throw InputError("diagnose: unknown effect \"" + effect + "\" (shear_thinning, yield_stress, wall_slip, side_walls)");
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
    for (const Effect& effect : kEffects) {
        const bool asked = options.effects.empty() ||
                           std::find(options.effects.begin(), options.effects.end(), effect.name) != options.effects.end();
        if (!asked) continue;
        json parameters;
        std::string why =
            effectParameters(job, std::vector<double>(job.parameters.size(), 1.0), std::nullopt, effect.name, parameters);
        if (why.empty()) {
            Scene probe = job.scene;
            why = withEffect(probe, effect.name, job.scene.material.viscosity);
        }
        if (why.empty()) candidates.push_back(&effect);
        else if (!options.effects.empty()) throw InputError(job.file.string() + ": diagnose: " + effect.name + ": " + why);
        else refused.emplace_back(effect.name, why);
    }
    const int fits = 1 + static_cast<int>(candidates.size());

    Diagnosis diagnosis;
    json baseSeries;
    if (options.onFit) options.onFit("base", 0, fits, parameterNames(job));
    FitBudget budget(options.timeBudget, fits);
    diagnosis.base = fitModel("base", job, modelJob(job, "", {}, fitCounts), observations, fitCounts, outDir / "fits" / "base",
                              options.identify, budget.nextSearch(), baseSeries);
    budget.spend(diagnosis.base);
    json candidatesDoc = json::array();
    std::vector<json> candidateSeries;
    std::vector<Job> models;                       // each candidate's job over all frames
    std::vector<std::vector<double>> equivalents;  // each candidate's base-equivalent point
    for (size_t c = 0; c < candidates.size(); ++c) {
        const std::string name = candidates[c]->name;
        json parameters;
        effectParameters(job, diagnosis.base.theta, diagnosis.base.shearRate, name, parameters);
        if (options.onFit) {
            std::vector<std::string> names;
            for (const json& p : parameters) names.push_back(p.at("name").get<std::string>());
            options.onFit(name, static_cast<int>(c + 1), fits, names);
        }
        // The base fit's values in every run's scene, where the effect's model takes its K from.
        Job base = job;
        for (Job* run : everyRun(base))
            for (size_t i = 0; i < run->parameters.size(); ++i)
                setParameter(run->scene, run->parameters[i].parameter, diagnosis.base.theta[i]);
        const Job& full = models.emplace_back(modelJob(base, name, parameters, {}));
        equivalents.push_back(baseEquivalent(full, job, diagnosis.base.theta));
        // The power law scans its ridge from the base's own flow (its n = 1 point is the base
        // equivalent); the other candidates score that point beside their first generation.
        IdentifyOptions identifyOptions = options.identify;
        if (name == "shear_thinning" && diagnosis.base.shearRate)
            identifyOptions.startCurve =
                powerLawRidge(parameters, diagnosis.base.theta[indexOf(job, "viscosity")], *diagnosis.base.shearRate);
        else
            identifyOptions.knownPoint = equivalents.back();
        json series;
        const Job fitting = screenedOnOnePlacement(modelJob(base, name, parameters, fitCounts));
        diagnosis.candidates.push_back(fitModel(name, full, fitting, observations, fitCounts, outDir / "fits" / name,
                                                identifyOptions, budget.nextSearch(), series));
        budget.spend(diagnosis.candidates.back());
        candidateSeries.push_back(series);
    }

    json warnings = json::array();
    const auto warn = [&](const std::string& line) {
        warnings.push_back(line);
        if (options.identify.onWarning) options.identify.onWarning(line);
    };
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
    if (challenger && !job.parameters.empty()) {
        const ModelFit& from = diagnosis.candidates[*challenger];
        const std::vector<double> start = apparentBase(from, models[*challenger], job);
        json parameters = json::array();
        for (size_t i = 0; i < job.parameters.size(); ++i) parameters.push_back(warmStart(job.parameters[i], start[i]));
        const std::vector<std::string> names = parameterNames(job);
        if (options.onFit) options.onFit("base_refit", fits, fits + 1, names);
        IdentifyOptions identifyOptions = options.identify;
        identifyOptions.knownPoint = diagnosis.base.theta;
        json series;
        ModelFit refit = fitModel("base", job, modelJob(job, "", parameters, fitCounts), observations, fitCounts,
                                  outDir / "fits" / "base_refit", identifyOptions, budget.nextSearch(), series);
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
    for (size_t c = 0; c < diagnosis.candidates.size(); ++c) {
        const ModelFit& fit = diagnosis.candidates[c];
        const bool better = beats(fit, base);
        const bool vanishes = effectVanishes(fit, job, equivalents[c]);
        const bool earns = better && !vanishes;
        if (better && vanishes)
            warn("diagnose: " + fit.model + " ended where its effect vanishes, as the base model, yet predicts the "
                 "held-out frames " + std::to_string(int(std::lround(100 * (1 - fit.heldOutE / base.heldOutE)))) +
                 " % better than the base fit: the base fit is not converged (more generations or time, or fewer "
                 "--effects to share them)");
        if (earns && (!diagnosis.chosen || fit.heldOutE < diagnosis.candidates[*diagnosis.chosen].heldOutE))
            diagnosis.chosen = c;
        json entry = toJson(fit, candidateSeries[c], fit.model);
        entry["description"] = candidates[c]->description;
        entry["source"] = candidates[c]->source;
        entry["held_out_gain"] = base.heldOutE > 0 ? 1 - fit.heldOutE / base.heldOutE : 0.0;
        entry["effect_vanishes"] = vanishes;
        entry["earns_its_parameters"] = earns;
        candidatesDoc.push_back(entry);
    }
    // Each search makes its minimum generations whatever its share, so a diagnosis can end late: say
    // so, with what would take less.
    if (options.timeBudget > 0 && budget.spent() > options.timeBudget)
        warn("diagnose: the fits took " + wholeSeconds(budget.spent()) + " s of a " + wholeSeconds(options.timeBudget) +
             " s budget: each search makes at least " + std::to_string(job.fidelity.minFineGenerations) +
             " generations (a coarser grid, a shorter clip or fewer --effects take less)");
    json notTried = json::array();
    for (const auto& [effect, why] : refused) notTried.push_back({{"effect", effect}, {"why", why}});
    const ModelFit& after = diagnosis.chosen ? diagnosis.candidates[*diagnosis.chosen] : base;
    json errors{{"E", {{"before", base.wholeE}, {"after", after.wholeE}}},
                {"held_out_E", {{"before", base.heldOutE}, {"after", after.heldOutE}}}};
    if (base.trackError && after.trackError)
        errors["track_error"] = {{"before", *base.trackError}, {"after", *after.trackError}};
    diagnosis.document = {
        {"format", "viscoscope.diagnosis"},
        {"version", 1},
        {"job", job.file.string()},
        {"chosen", diagnosis.chosen ? json(after.model) : json()},
        {"conclusion", diagnosis.chosen ? "missing effect: " + after.model : std::string("no missing effect")},
        {"criterion", "fitted on each run's first " + std::to_string(int(std::lround(100 * options.fitShare))) +
                          " % of compared frames; an effect earns its parameters when its E over the held-out rest is "
                          "below " + std::to_string(int(std::lround(100 * (1 - kHeldOutGain)))) +
                          " % of the base's and its BIC over the fitted frames is below the base's"},
        {"fitted_frames", fitCounts},
        {"time_budget_s", options.timeBudget},
        {"seconds", budget.spent()},
        {"warnings", warnings},
        {"base", toJson(base, baseSeries, baseFolder)},
        {"candidates", candidatesDoc},
        {"not_tried", notTried},
        {"errors", errors}};
    if (!baseRefit.is_null()) diagnosis.document["base_refit"] = baseRefit;
    writeJsonAtomically(diagnosis.document, outDir / "diagnosis.json");
    return diagnosis;
}

}  // namespace viscoscope::identify
