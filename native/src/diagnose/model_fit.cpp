// Fitting and scoring one model of a diagnosis (model_fit.h).
#include "diagnose/model_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace viscoscope::diagnose {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace identify;

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

Job modelJob(const Job& base, const Effect* effect, const json& parameters, const std::vector<int>& maxFrames) {
    Job job = base;
    const std::vector<Job*> runs = everyRun(job);
    const double eta = job.scene.material.viscosity;
    const std::string model = effect ? effect->name : "base";
    for (size_t r = 0; r < runs.size(); ++r) {
        Job& run = *runs[r];
        if (effect && effect->law) run.scene.material.model = effect->law(eta);
        if (!parameters.empty()) {
            run.parameters.clear();
            for (size_t i = 0; i < parameters.size(); ++i)
                run.parameters.push_back(parseSearchedParameter(
                    parameters[i], run.scene,
                    run.file.string() + ": diagnosis " + model + ": parameters[" + std::to_string(i) + "]"));
            run.document["parameters"] = parameters;
            if (effect) run.document["_effect"] = effect->name;
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

// One placement: on all of them every evaluation of a search over several parameters runs each
// placement, where the base's one-parameter search takes one a generation, and a candidate cost the
// base's evaluations several times over (tests/bench/FINDINGS.md, "One diagnosis of the sample cup
// against a 30-minute budget").
Job screenedOnOnePlacement(Job job) {
    for (Job* run : everyRun(job))
        if (run->parameters.size() > 1 && run->gridPlacements > 1) {
            run->gridPlacements = 1;
            run->document["grid_placements"] = 1;
        }
    return job;
}

std::vector<Job> runsOf(const Job& job) {
    std::vector<Job> runs{job};
    runs.front().otherRuns.clear();
    runs.insert(runs.end(), job.otherRuns.begin(), job.otherRuns.end());
    return runs;
}

std::vector<size_t> comparedFrames(const Observation& obs) {
    std::vector<size_t> frames;
    for (size_t i = 0; i < obs.simFrames.size(); ++i)
        if (obs.simFrames[i] >= 0) frames.push_back(i);
    std::stable_sort(frames.begin(), frames.end(), [&](size_t a, size_t b) { return obs.simFrames[a] < obs.simFrames[b]; });
    return frames;
}

namespace {

struct RunScore {
    double fitted = 0, heldOut = 0, whole = 0;
    int fittedFrames = 0;
    std::optional<double> trackError, shearRate;
    std::vector<double> frameShearRates;
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

// θ scored over every frame of `run`, on each of its grid placements (E their mean), whatever its
// search took, so that every model is scored alike; a replica moves the placements by `gridShift`
// cells and seeds the particles with the scene's seed + `seedOffset`.
RunScore scoreRun(const Job& asked, const Observation& obs, const std::vector<double>& theta, int fitCount,
                  double gridShift = 0, unsigned seedOffset = 0) {
    Job run = reseeded(asked, seedOffset);
    run.placementSchedule = PlacementSchedule::EachEvaluation;
    const Evaluation ev = evaluate(run, obs, theta, run.resolution, {}, gridShift);
    const std::vector<size_t> frames = comparedFrames(obs);
    const std::vector<size_t> fitted(frames.begin(), frames.begin() + fitCount), heldOut(frames.begin() + fitCount, frames.end());
    RunScore score;
    score.fitted = partE(run, obs, ev, fitted);
    score.heldOut = partE(run, obs, ev, heldOut);
    score.whole = partE(run, obs, ev, frames);
    score.fittedFrames = fitCount;
    score.trackError = ev.trackError;
    score.shearRate = ev.shearRate;
    score.frameShearRates = ev.frameShearRates;
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

// The share of frames the shear-rate range leaves out at each end: a frame's rate is a mean over its
// liquid, and the first frame's is the release's, not the liquid's flow.
constexpr double kShearRateRangeShare = 0.1;

// The `share` and 1 − `share` percentiles of `values`, linearly interpolated between ranks.
std::array<double, 2> percentiles(std::vector<double> values, double share) {
    std::sort(values.begin(), values.end());
    const auto at = [&](double q) {
        const double rank = q * double(values.size() - 1);
        const size_t below = size_t(std::floor(rank));
        const size_t above = std::min(below + 1, values.size() - 1);
        return values[below] + (rank - double(below)) * (values[above] - values[below]);
    };
    return {at(share), at(1 - share)};
}

}  // namespace

// How far past its budget a diagnosis may end: a search stops only between generations, and the
// fits after the base are predicted from its cost, not measured.
constexpr double kBudgetOverrun = 0.1;

double FitBudget::nextSearch(double shares) const {
    if (total_ <= 0) return 0.0;
    const double share = (total_ - spent_) * shares / std::max(shares, fitsLeft_ - 1 + shares);
    return std::max(1e-3, share - lastScoring_);
}

bool FitBudget::holds(double seconds) const { return total_ <= 0 || spent_ + seconds <= (1 + kBudgetOverrun) * total_; }

void FitBudget::spend(const ModelFit& fit) {
    spent_ += fit.seconds + fit.scoringSeconds;
    lastScoring_ = fit.scoringSeconds;
    --fitsLeft_;
}

void FitBudget::spend(const NoiseFloor& noise) { spent_ += noise.seconds; }

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
        const IdentificationResult result = identify::identify(fitting, dir, identifyOptions);
        fit.theta = result.theta;
        fit.interval = result.interval;
        fit.indistinguishable = result.indistinguishable;
        fit.evaluations = result.evaluations;
        fit.seconds = result.seconds;
        fit.stop = result.stop;
        fit.doubts = result.document.at("doubts").get<std::vector<std::string>>();
    }
    fit.material = sceneToJson(sceneWithParameters(full, fit.theta, full.resolution)).at("material");
    const std::vector<Job> runs = runsOf(full);
    int fittedFrames = 0;
    runSeries = json::array();
    const auto scoringStart = std::chrono::steady_clock::now();
    std::vector<double> frameShearRates;
    for (size_t r = 0; r < runs.size(); ++r) {
        const RunScore score = scoreRun(runs[r], observations[r], fit.theta, fitCounts[r]);
        frameShearRates.insert(frameShearRates.end(), score.frameShearRates.begin(), score.frameShearRates.end());
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
    if (!frameShearRates.empty()) fit.shearRateRange = percentiles(frameShearRates, kShearRateRangeShare);
    const double n = fittedFrames, k = double(fit.theta.size());
    fit.bic = n * std::log(std::max(fit.fittedE, 1e-300) / n) + k * std::log(n);
    return fit;
}

FitCost FitCost::of(const ModelFit& fit) {
    return {fit.evaluations > 0 ? fit.seconds / fit.evaluations : 0.0, fit.scoringSeconds};
}

void FitCost::raiseTo(const FitCost& other) {
    perEvaluation = std::max(perEvaluation, other.perEvaluation);
    scoring = std::max(scoring, other.scoring);
}

double FitCost::leastFit(const Job& job, int dimension) const {
    const int generation = populationSize(dimension, {job.populationSize});
    return (job.fidelity.minFineGenerations * generation + 1) * perEvaluation + scoring;
}

bool ModelFit::searchCompleted() const {
    return !stop || (*stop != StopReason::TimeBudget && *stop != StopReason::Cancelled);
}

double predictOtherRuns(const Job& full, const std::vector<Observation>& observations, const std::vector<int>& fitCounts,
                        const std::vector<double>& theta, size_t except) {
    const std::vector<Job> runs = runsOf(full);
    double E = 0;
    for (size_t r = 0; r < runs.size(); ++r)
        if (r != except) E += scoreRun(runs[r], observations[r], theta, fitCounts[r]).whole;
    return E;
}

NoiseFloor measureScatter(const Job& full, const std::vector<Observation>& observations,
                          const std::vector<int>& fitCounts, const ModelFit& fit, int replicas) {
    NoiseFloor noise;
    noise.heldOutE.push_back(fit.heldOutE);
    noise.deterministic = full.forwardModel == ForwardModel::ThinFilm;
    if (noise.deterministic) return noise;
    const auto start = std::chrono::steady_clock::now();
    const std::vector<Job> runs = runsOf(full);
    for (int k = 1; k <= replicas; ++k) {
        // Between the scoring's placements, k/(replicas + 1) of their spacing on.
        const double shift = double(k) / ((replicas + 1) * full.gridPlacements);
        double heldOut = 0;
        for (size_t r = 0; r < runs.size(); ++r)
            heldOut += scoreRun(runs[r], observations[r], fit.theta, fitCounts[r], shift, unsigned(k)).heldOut;
        noise.heldOutE.push_back(heldOut);
    }
    noise.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return noise;
}

json toJson(const ModelFit& fit, const json& series, const std::string& folder) {
    json parameters = json::object();
    for (size_t i = 0; i < fit.parameters.size(); ++i)
        parameters[fit.parameters[i]] = {{"value", fit.theta[i]}, {"interval", fit.interval[i]}};
    json doc{{"model", fit.model},         {"parameters", parameters},   {"fitted_E", fit.fittedE},
             {"held_out_E", fit.heldOutE}, {"whole_E", fit.wholeE},      {"bic", fit.bic},
             {"evaluations", fit.evaluations}, {"seconds", fit.seconds}, {"scoring_seconds", fit.scoringSeconds},
             {"time_budget_s", fit.timeBudget},   {"material", fit.material},
             {"folder", "fits/" + folder},        {"residual_over_time", series},
             {"doubts", fit.doubts}};
    if (fit.trackError) doc["track_error"] = *fit.trackError;
    if (fit.shearRate) doc["shear_rate_per_s"] = *fit.shearRate;
    if (fit.shearRateRange) doc["shear_rate_range_per_s"] = *fit.shearRateRange;
    if (fit.stop) doc["stopped"] = toString(*fit.stop);
    return doc;
}


}  // namespace viscoscope::diagnose
