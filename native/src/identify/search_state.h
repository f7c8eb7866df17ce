// The identification's own state and the pieces of the loop that read it, private to the stage:
// the evaluations and generations so far (typed here; the checkpoint and result.json hold them as
// JSON), the checkpoint (search_state.cpp), the time budget (time_budget.cpp), the best
// evaluation's fields (fields_store.cpp), the grid checks (grid_checks.cpp) and the results
// (results.cpp). identification.cpp runs the loop over them.
#pragma once

#include "identify/identify.h"

#include <nlohmann/json.hpp>

#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace viscoscope::identify {

using Clock = std::chrono::steady_clock;

enum class Fidelity { Coarse, Full };
const char* fidelityName(Fidelity fidelity);  // "coarse", "full": the records' "fidelity"

// After a one-parameter search: the alignment check (θ* on a grid moved sideways, its particles seeded
// anew) and the resolution check (θ* on a coarser grid); see grid_checks.cpp.
enum class GridCheck { Alignment, Resolution };
bool gridCheckPlanned(const Job& job, GridCheck check);  // one parameter, and the job's setting

// The coarse grid's optimum is not the fine grid's: a grid where the cup's hole is only a few cells
// wide drains it faster, and its best evaluations sat above the truth. On the job's grid, a third of
// the clip weighs the flow's phases differently from all of it, so the fine phase searches a
// log-space spread of ln 1.4 around the coarse best (tests/bench/FINDINGS.md, "Figures moved from code comments").
constexpr double kCoarseToFineShift = 0.35;

// The grids and clips of the two fidelities (see the fidelity policy in identification.cpp).
struct FidelityPlan {
    int coarseResolution = 0, fullResolution = 0;
    int coarseFrames = 0, fullFrames = 0;  // the last simulation frame each compares
    int resolution(Fidelity f) const { return f == Fidelity::Coarse ? coarseResolution : fullResolution; }
    int frames(Fidelity f) const { return f == Fidelity::Coarse ? coarseFrames : fullFrames; }
};

// One finished evaluation of the search: result.json's and the checkpoint's "evaluated" records.
struct EvaluationRecord {
    Evaluation evaluation;
    int generation = 0;  // from 1
    Fidelity fidelity = Fidelity::Full;
    int frames = 0;
    std::vector<double> x;  // the optimizer's point, ln θ before clipping into the bounds
    std::string origin;     // "sample", "scan", "refine", "restart", "parabola" or "known"
    double gridShift = 0;   // cells along x and y
    std::string error;      // why the simulation failed (E = ∞)
    std::optional<int> rank;
    const std::vector<double>& theta() const { return evaluation.theta; }
    double E() const { return evaluation.E; }
    bool succeeded() const { return std::isfinite(evaluation.E); }
};
nlohmann::json toJson(const EvaluationRecord& record);
EvaluationRecord evaluationRecordFromJson(const nlohmann::json& doc);

struct BestPoint {
    std::vector<double> theta;
    double E = INFINITY;
    double gridShift = 0;  // the placement its fields come from
};

// One finished generation: result.json's "history".
struct GenerationRecord {
    int generation = 0;
    Fidelity fidelity = Fidelity::Full;
    int resolution = 0;
    double gridShift = 0;
    double generationBestE = INFINITY;
    std::vector<double> generationBestTheta;
    std::vector<double> bestTheta;  // the best so far at this fidelity (empty: none yet)
    double bestE = INFINITY;
    std::vector<double> meanTheta;
    double sigma = 0;
    std::vector<double> logStd;
    long evaluations = 0;
    double seconds = 0;
    std::optional<double> predictedFineGenerationSeconds;  // at the switch to full fidelity
    std::string warning;
};
nlohmann::json toJson(const GenerationRecord& record);
GenerationRecord generationRecordFromJson(const nlohmann::json& doc);

// The two points of a finished grid check (grid_checks.cpp): θ* and kCheckStep·θ*, scored on the
// check's grids.
struct CheckScores {
    std::array<double, 2> theta{};
    std::array<double, 2> E{INFINITY, INFINITY};  // ∞ where a simulation failed
    std::vector<std::string> errors;
};

// Everything a resume needs.
struct SearchState {
    explicit SearchState(CmaEs start) : es(std::move(start)) {}
    CmaEs es;
    int coarseEnd = 0;  // the first full-fidelity generation
    std::vector<EvaluationRecord> evaluated;
    std::vector<GenerationRecord> generations;
    double elapsedBefore = 0;  // wall seconds of earlier sessions
    std::optional<StopReason> stop;
    std::optional<CheckScores> alignment, resolution;
    int resumedFrom = 0;  // the generations a checkpoint held
};

// OUT/checkpoint.json: the state after every generation, sealed (scene/digest.h) and tied to the
// job by a fingerprint of everything that changes E.
class Checkpoint {
public:
    Checkpoint(const Job& job, const std::filesystem::path& outDir);
    const std::string& fingerprint() const { return fingerprint_; }
    // The saved state, or none without a checkpoint. Throws InputError for one that is unreadable,
    // of another version, damaged, or of another job. A finished run goes on when this job allows
    // more generations or has a time budget (its stop is decided again).
    std::optional<SearchState> load(const Job& job) const;
    void save(const SearchState& state, double elapsed) const;

private:
    std::filesystem::path file_;
    std::string fingerprint_;
};

// Full-fidelity generations take turns on the job's grid placements (Job::placementSchedule).
bool placementsByGeneration(const Job& job);
// (θ, E) of the finished full-fidelity evaluations of a one-parameter search, up to generation
// `lastGeneration`; with placements by generation, E's mean over them (placementMeanProfile).
std::vector<std::pair<double, double>> fullFidelityProfile(const Job& job, const std::vector<EvaluationRecord>& evaluated,
                                                          int lastGeneration = std::numeric_limits<int>::max());
// The best θ at a fidelity: the lowest evaluation, or at full fidelity with placements by
// generation the lowest point of E's mean over them; none before a finite E.
std::optional<BestPoint> bestAt(const Job& job, const std::vector<EvaluationRecord>& evaluated, Fidelity fidelity);

// The time budget's prediction of a full-fidelity evaluation before any has run: the mean, over
// the coarse evaluations within kCoarseToFineShift (ln θ, every coordinate) of the best coarse one,
// where the full-fidelity phase restarts, of their seconds scaled by (r/r_c)⁴ (cells × time steps)
// and by how much longer the full clip takes: its frames plus the remaining ones at the rate of
// the coarse clip's last third. 0 without coarse evaluations.
double predictedFullEvaluationSeconds(const std::vector<EvaluationRecord>& evaluated, const FidelityPlan& plan);

// Wall time against the job's time_budget_s, and what the rest of the search is predicted to take.
class TimeBudget {
public:
    TimeBudget(const Job& job, const SearchState& state, const FidelityPlan& plan, int concurrency);
    double elapsed() const;  // over every session
    bool fits(double seconds) const;  // always without a budget
    void addGeneration(Fidelity fidelity, double seconds);
    double coarseGenerationSeconds() const;  // the mean so far
    // The mean so far, else ⌈λ / concurrency⌉ rounds of predictedFullEvaluationSeconds.
    double fineGenerationSeconds() const;
    // A grid check's evaluations, with the margin the minimum generations get; 0 when none is planned.
    double checkSeconds(GridCheck check) const;
    double gridChecksSeconds() const;  // both
    // The last full-fidelity generation has run: the minimum generations have, and another would
    // end past the budget, with the grid checks when they could run now (`checksCanRun`: a profile to
    // take E's curvature from). Without one the minimum doubles, so that the checks the plan holds
    // are not dropped for want of a profile a generation or two more would give.
    bool fullPhaseOver(bool checksCanRun) const;
    // Seconds of the search left after `done` generations (of which coarseEnd coarse).
    double remaining(int done, bool stopped) const;

private:
    const Job& job_;
    const SearchState& state_;
    FidelityPlan plan_;
    int concurrency_;
    Clock::time_point sessionStart_;
    std::vector<double> coarseSeconds_, fineSeconds_;
};
// E as JSON: null where a simulation failed (E = ∞), since JSON has no infinity.
nlohmann::json finiteOrNull(double value);
// "%d" of whole seconds, for messages.
std::string wholeSeconds(double seconds);

// OUT/fields: the best full-fidelity evaluation's hidden fields, every frame as .vdb, with
// OUT/fields/evaluation.json saying whose they are. Full-fidelity evaluations write theirs into
// OUT/fields.partial/<k>, and the generation's winner replaces OUT/fields.
class FieldsStore {
public:
    FieldsStore(const std::filesystem::path& outDir, std::string fingerprint, int frames);
    std::filesystem::path staged(size_t k) const;
    void clearStaging() const;  // also what a killed generation left
    void promote(size_t k, const Evaluation& evaluation, double gridShift) const;
    // result.json's "fields" for θ*: its evaluation's own, or θ* simulated again when OUT/fields
    // does not hold it.
    nlohmann::json keep(const Job& job, const Observation& observation, const BestPoint& best, int resolution) const;

private:
    std::filesystem::path outDir_;
    std::string fingerprint_;
    int frames_;
};

// A grid check of a one-parameter search (see grid_checks.cpp): θ* scored again on other grids, the
// minimum there, and what it does to the interval.
struct GridCheckOutcome {
    nlohmann::json entry;                // the parameter's "alignment_check" or "resolution_check"
    std::optional<double> minimum;       // θ at the minimum on the check's grids, possibly infinite
    // How far the interval reaches either side of θ*, in ln θ: alignment |ln(θ_s/θ*)|, infinite when
    // the moved minimum is; resolution (h/(h_c − h))·(|ln(θ_s/θ_c)| + z·σ), σ that move's noise.
    std::optional<double> widening;
    std::optional<std::string> warning;  // skipped (no profile, no coarser grid), or a doubt on θ*
    double seconds = 0;                  // simulated in this session
};
// Each runs its check's evaluations unless `state` holds them for θ* (then takes them from there),
// storing them in `state` and calling `saved` after. Without a profile it is skipped and says why;
// the time budget never skips it: the checks are part of the plan the budget is held against (see
// TimeBudget::fullPhaseOver).
GridCheckOutcome alignmentCheck(const Job& job, EvaluationPool& pool, const Observations& observations,
                                SearchState& state, const std::optional<ProfileFit>& profile, double thetaStar,
                                const std::function<void()>& saved);
GridCheckOutcome resolutionCheck(const Job& job, EvaluationPool& pool, const Observations& observations,
                                 SearchState& state, const std::optional<ProfileFit>& profile, double thetaStar,
                                 const GridCheckOutcome& alignment, const std::function<void()>& saved);
// The resolution check's grid: cells along the longest axis.
int resolutionCheckCells(const Job& job);

// One searched parameter at the end of the search: θ*, the final CMA-ES band, in one dimension the
// profile fit and the grid checks, and the interval reported (results.cpp).
struct ParameterEstimate {
    double value = 0;  // θ*
    double cmaMean = 0, logStd = 0;
    std::array<double, 2> cma{};               // exp(m ± 2σ√C_ii), within the bounds
    std::optional<nlohmann::json> profileFit;  // fitProfile's account, one-parameter searches only
    std::optional<ProfileFit> profile;         // kept when its vertex lies among the fitted points
    std::optional<std::array<double, 2>> jointProfile;  // searches of several parameters: jointProfileNear's
    std::optional<GridCheckOutcome> alignment, resolution;
    std::array<double, 2> interval{};  // settleInterval's
    bool widenedBy(const std::optional<GridCheckOutcome>& check) const { return check && check->widening; }
};
// Parameter i's estimate at θ* = `value` before the grid checks: the CMA band from the final
// distribution and, in one dimension, the profile fit over the full-fidelity evaluations; in
// several, the joint profile's interval (`joint`, jointProfileNear's).
ParameterEstimate estimateParameter(const Job& job, const LogSearchSpace& bounds, const CmaEs& es,
                                    const std::vector<EvaluationRecord>& evaluated, int i, double value,
                                    const std::optional<JointProfileFit>& joint);
// The joint profile (fitJointProfile) of a search of several parameters over its successful
// full-fidelity evaluations up to generation `lastGeneration`, around θ* = `best`; `info` receives
// its account.
std::optional<JointProfileFit> jointProfileNear(const std::vector<EvaluationRecord>& evaluated, int lastGeneration,
                                                const std::vector<double>& best, nlohmann::json& info);
// The profile fit of a one-parameter search's full-fidelity evaluations (up to generation
// `lastGeneration`) around θ* = `value`, kept when its vertex lies among the fitted points; `info`
// receives fitProfile's account.
std::optional<ProfileFit> profileNear(const Job& job, const std::vector<EvaluationRecord>& evaluated, double value,
                                      nlohmann::json& info, int lastGeneration = std::numeric_limits<int>::max());
// The interval reported: the profile's band (or the joint profile's) when there is one, else the
// CMA band, widened by each grid check's reach, made to contain θ*, and clipped into the bounds.
void settleInterval(ParameterEstimate& estimate, const LogSearchSpace& bounds, int i);
// "profile", "joint_profile" or "cma", "+alignment" and "+resolution" for the checks that changed it:
// IdentificationResult::intervalMethod.
std::string intervalMethodName(const ParameterEstimate& estimate);

// result.json (but its "fields", which FieldsStore::keep gives): θ* and its intervals, the search's
// account (its history, every evaluation, timings), the warnings and the doubts.
nlohmann::json resultDocument(const Job& job, const IdentificationResult& result, const SearchState& state,
                              const FidelityPlan& plan, const Observation& observation,
                              const std::vector<ParameterEstimate>& estimates, const BestPoint& best,
                              const std::vector<std::string>& warnings, const std::vector<std::string>& doubts);

// A doubt is a reason to think θ* wrong, one line each: result.json's "doubts", also sent as warnings.
std::vector<std::string> doubtsBeforeSearch(const Observation& observation);
std::vector<std::string> doubtsAfterSearch(const Job& job, const LogSearchSpace& bounds,
                                           const std::vector<std::array<double, 2>>& intervals,
                                           const std::vector<EvaluationRecord>& evaluated);
// result.json's "timings": the wall time and each fidelity's evaluations, their seconds and parts.
nlohmann::json timingsOf(const std::vector<EvaluationRecord>& evaluated, double wallSeconds,
                         double alignmentSeconds, double resolutionSeconds);
// OUT/evaluations.csv: every evaluation, for plotting.
void writeEvaluationsCsv(const Job& job, const std::vector<EvaluationRecord>& evaluated,
                         const std::filesystem::path& file);

}  // namespace viscoscope::identify
