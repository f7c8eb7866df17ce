// Fitting one model of a diagnosis and scoring it alike with every other: the model's job (its
// scene and searched parameters in every run, the fitted frames), its search within a share of the
// diagnosis's budget, and θ* scored again over every frame of every run. Private to the stage.
#pragma once

#include "diagnose/diagnose.h"

#include <filesystem>
#include <string>
#include <vector>

namespace viscoscope::diagnose {

// The job and each of its other runs, to change in place.
std::vector<identify::Job*> everyRun(identify::Job& job);
// Each run of `job` as a job of its own.
std::vector<identify::Job> runsOf(const identify::Job& job);
std::vector<std::string> parameterNames(const identify::Job& job);

// The compared reference frames of a run, in time order.
std::vector<size_t> comparedFrames(const identify::Observation& obs);

// The job of a model: the base job with the effect's law (null: the base's material) and
// `parameters` (empty: the base's) in every run, limited to `maxFrames[r]` compared frames in run r
// when given.
identify::Job modelJob(const identify::Job& base, const Effect* effect, const nlohmann::json& parameters,
                       const std::vector<int>& maxFrames);

// A model's search over several parameters screens on one grid placement (fitModel scores it on all).
identify::Job screenedOnOnePlacement(identify::Job job);

// The diagnosis's time budget, spent fit by fit: each search gets an equal share of what is left
// (or `shares` of them, the other fits left one each), less the scoring the fit before it took (the
// next one's scoring costs about as much).
class FitBudget {
  public:
    FitBudget(double total, int fits) : total_(total), fitsLeft_(fits) {}
    // 0: no budget of the diagnosis's own (the job's time_budget_s stands). Never 0 otherwise, which
    // would mean none: an overspent budget still runs the minimum generations (and diagnose warns).
    double nextSearch(double shares = 1) const;
    // Whether `seconds` more end within the budget, or no later than kBudgetOverrun past it (always
    // without a budget).
    bool holds(double seconds) const;
    void spend(const ModelFit& fit);
    void spend(const NoiseFloor& noise);
    void spend(double scoringSeconds) { spent_ += scoringSeconds; }  // scorings outside a fit
    void forgo(int fits) { fitsLeft_ -= fits; }  // fits that will not run share no more of it
    double spent() const { return spent_; }

  private:
    double total_, spent_ = 0, lastScoring_ = 0;
    int fitsLeft_;
};

// What a fit costs on this machine: the wall seconds of an evaluation of its search and of its
// scoring.
struct FitCost {
    double perEvaluation = 0, scoring = 0;
    static FitCost of(const ModelFit& fit);  // as measured (no evaluation cost for a fit that searched nothing)
    // The dearer of the two in each part: the fits measured so far predict the next.
    void raiseTo(const FitCost& other);
    // The least wall seconds of a fit over `dimension` parameters in `job`: its minimum generations
    // of λ evaluations (one more in the first, for its known point) and its scoring.
    double leastFit(const identify::Job& job, int dimension) const;
};

// Fits a model (`fitting`: its job over the fitted frames) with `identifyOptions`' known point and
// start curve, if given, within `searchBudget` wall seconds (0: the job's), then scores θ* on every
// frame of every run of `full`. `runSeries` receives each run's residual over time.
ModelFit fitModel(const std::string& model, const identify::Job& full, identify::Job fitting,
                  const std::vector<identify::Observation>& observations, const std::vector<int>& fitCounts,
                  const std::filesystem::path& dir, identify::IdentifyOptions identifyOptions, double searchBudget,
                  nlohmann::json& runSeries);

// The whole E that θ (in `full`'s model) scores over every run of `full` but `except`: what a fit to
// run `except` alone predicts of the others.
double predictOtherRuns(const identify::Job& full, const std::vector<identify::Observation>& observations,
                        const std::vector<int>& fitCounts, const std::vector<double>& theta, size_t except);

// The noise floor at `fit`'s θ* (scored already: its held-out E is the first sample): each of
// `replicas` scores every run again on grid placements moved between the scoring's and on
// another particle seed.
NoiseFloor measureScatter(const identify::Job& full, const std::vector<identify::Observation>& observations,
                          const std::vector<int>& fitCounts, const ModelFit& fit, int replicas);

// A fit as diagnosis.json holds it; `folder` is its folder under OUT/fits.
nlohmann::json toJson(const ModelFit& fit, const nlohmann::json& series, const std::string& folder);

}  // namespace viscoscope::diagnose
