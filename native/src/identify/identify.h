// The identify stage: CMA-ES (Hansen, arXiv:1604.00772) over forward simulations, the job file,
// the identification loop with multi-fidelity, checkpoints and results.
//
// Parameters are searched in log space: the optimizer sees x = ln θ, so θ = exp(x) > 0 always;
// bounds [min, max] become [ln min, ln max] and a sample outside them is clipped to the boundary
// for evaluation (the CMA-ES state keeps the unclipped sample; the objective gets a quadratic
// penalty on the clipped distance, as in pycma's BoundPenalty, so the mean is pulled back inside).
#pragma once

#include "observe/observe.h"
#include "scene/scene.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace viscoscope::identify {

// ---------------------------------------------------------------------------------------------
// CMA-ES with Hansen's default strategy parameters (Table 1 of the tutorial), ask/tell.

struct CmaEsSettings {
    int populationSize = 0;  // λ; 0 = 4 + ⌊3 ln n⌋
};

class CmaEs {
public:
    CmaEs(const Eigen::VectorXd& initialMean, double initialSigma, std::uint64_t seed,
          const CmaEsSettings& settings = {});
    // With per-coordinate spreads: σ = 1 and C = diag(spread²)... expressed as σ0 = max spread and
    // C = diag((spread/σ0)²).
    CmaEs(const Eigen::VectorXd& initialMean, const Eigen::VectorXd& initialSpreads, std::uint64_t seed,
          const CmaEsSettings& settings = {});

    // λ candidates x_k = m + σ B D z_k, z_k ~ N(0, I). Deterministic given the seed and history.
    std::vector<Eigen::VectorXd> ask();
    // Fitness of the candidates returned by the last ask(), in the same order (minimized).
    void tell(const std::vector<Eigen::VectorXd>& candidates, const std::vector<double>& fitness);
    // Starts the search again at `mean` with per-coordinate spreads (σ and C as in the constructor,
    // evolution paths zero), keeping the generation and evaluation counters and the random stream.
    void restart(const Eigen::VectorXd& mean, const Eigen::VectorXd& spreads);
    // An outside point made fit to replace one of ask()'s candidates (Hansen 2011, "Injecting
    // external solutions into CMA-ES", eq. 4): its step from the mean is shortened to a Mahalanobis
    // length of at most √n + 2n/(n+2), so one far point cannot drag the mean or inflate σ.
    Eigen::VectorXd injectable(const Eigen::VectorXd& x) const;

    int dimension() const { return n_; }
    int lambda() const { return lambda_; }
    int mu() const { return mu_; }
    double muEff() const { return muEff_; }
    const Eigen::VectorXd& weights() const { return weights_; }
    const Eigen::VectorXd& mean() const { return mean_; }
    double sigma() const { return sigma_; }
    const Eigen::MatrixXd& covariance() const { return C_; }
    int generation() const { return generation_; }
    long evaluations() const { return evaluations_; }
    // σ·sqrt(C_ii): the standard deviation of the search distribution per coordinate.
    Eigen::VectorXd standardDeviations() const;
    // Learning rates (for tests and the report).
    double cSigma() const { return cSigma_; }
    double dSigma() const { return dSigma_; }
    double cC() const { return cC_; }
    double c1() const { return c1_; }
    double cMu() const { return cMu_; }

    // The complete state (strategy parameters are recomputed from n and λ); from/to JSON for
    // checkpoints. Doubles round-trip exactly (17 significant digits).
    nlohmann::json toJson() const;
    static CmaEs fromJson(const nlohmann::json& state);

private:
    void setStrategyParameters();
    void updateEigenDecomposition();
    double standardNormal();

    int n_ = 0, lambda_ = 0, mu_ = 0;
    Eigen::VectorXd weights_;
    double muEff_ = 0, cSigma_ = 0, dSigma_ = 0, cC_ = 0, c1_ = 0, cMu_ = 0, chiN_ = 0;
    Eigen::VectorXd mean_, pSigma_, pC_;
    Eigen::MatrixXd C_, B_;
    Eigen::VectorXd D_;  // sqrt of C's eigenvalues
    double sigma_ = 1;
    int generation_ = 0;
    long evaluations_ = 0;
    std::uint64_t seed_ = 0;
    std::mt19937_64 random_;
};

// ---------------------------------------------------------------------------------------------
// The job file (format "viscoscope.job", version 1), as addon/operators/identify.py writes it.

// A searched parameter: any declared one the scene holds (scene.h, parameterDeclarations), its
// bounds and start within the declaration's unless the job gives them.
struct ParameterSpec {
    SceneParameter parameter;
    double initial = 10;    // θ0 (SI)
    double spread = 10;     // initial spread in θ units
    double lower = 1e-3, upper = 1e4;
    const std::string& name() const { return parameter.name; }
    double logSpread() const { return std::log1p(spread / initial); }  // the search's σ0 in ln θ
    double logRange() const { return std::log(upper / lower); }
    // E's profile is fitted in 1/θ (fitProfile's `inverse`) when flow speeds scale as 1/θ.
    bool profileInInverse() const { return parameter.declaration->speedScalesInversely; }
};
// A parameter held at an independently measured value (a viscometer's reading) with its standard
// uncertainty, so that what the fit leaves is explained at the known value: the job's "fixed".
struct FixedParameter {
    SceneParameter parameter;
    double value = 0, uncertainty = 0;
};

struct FidelitySchedule {
    // Generations [0, coarseGenerations) simulate on the grid round(coarseFactor · resolution) and
    // only the first coarseTimeShare of the compared clip; the rest at the job's resolution over all
    // of it. The coarse phase ends early when its σ tolerance is met (or the time budget needs the
    // rest). At the switch CMA-ES restarts at the best coarse θ with a fixed log-space spread, and
    // the best-so-far is reset, because E values of the two fidelities are not comparable.
    // Stopping tolerances apply only at full fidelity, and at least `minFineGenerations` run there.
    double coarseFactor = 1;
    double coarseTimeShare = 1.0 / 3;
    int coarseGenerations = -1;  // −1 = ⌊maxGenerations / 2⌋ capped at 10; 0 = no coarse phase
    // Two fit a 10-minute budget on the sample scene at 48³: a full-fidelity generation took 120–135 s
    // at η = 10 and 200–230 s at η = 3, and in three such runs the best evaluation after two of them
    // was the final one or within 1.5 % of it.
    int minFineGenerations = 2;
};

// A quarter of the fall: on the sample cup (10 cm) at η = 10 the rows above bands of 0.7–3.4 cm
// all scored least at the truth (see excludeGroundBand), and the stream fills most of the view.
constexpr double kDefaultGroundBandShare = 0.25;
constexpr int kMaxGridPlacements = 8;  // Job::gridPlacements
enum class PlacementSchedule { EachEvaluation, ByGeneration };  // Job::placementSchedule
// The job's "grid_placement_schedule" names: "each_evaluation", "by_generation".
const char* placementScheduleName(PlacementSchedule schedule);

// A measured track of a world-space observable, such as a lab's front positions over time: the
// job's "track" with an "observable". The simulation's value comes from its particles
// (frontAlongGround, puddleDiameter) at the simulation frames within the track's time span, and E
// gains weight · Σ(sim − measured)² / Σ measured². It may stand alone, without silhouettes or a
// camera, or join them.
enum class TrackObservable {
    Front,   // how far the liquid on the ground reaches from `origin` along `direction` (m)
    Radius,  // the radius of the liquid on the ground around the vertical through `origin` (m)
};
struct MeasuredTrack {
    std::filesystem::path csv;
    ScalarTrack data;
    size_t column = 0;  // the measured column of `data`
    TrackObservable observable = TrackObservable::Front;
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
    double band = 0.005;  // m: liquid this close to the ground (and, for a front, to its line) counts
    double weight = 1;
};

struct Job {
    std::filesystem::path file;
    Scene scene;
    std::filesystem::path cameraFile;
    PinholeCamera camera;
    std::filesystem::path referenceDir;          // the `extract` manifest folder
    std::optional<std::filesystem::path> video;  // extracted into OUT/reference when no silhouettes
    ExtractionOptions extraction;                // how: the job's optional "extraction" object
    std::optional<std::filesystem::path> trackCsv;  // an "area_px" track for the silhouettes
    double trackWeight = 1;
    std::optional<MeasuredTrack> measuredTrack;
    // Silhouettes (extracted, or a video to extract) are compared; without them a measured track
    // alone is, and the camera is not needed.
    bool hasSilhouettes() const { return !referenceDir.empty() || video.has_value(); }
    // Without a track CSV, the reference silhouettes' area over time (in the compared region) is the
    // track, with this weight (0 = off). Silhouette E is rough in θ: from about a sixth of the clip
    // on, η 2 % apart can send the stream and puddle along other paths (η = 30 against a 64³
    // reference at 48³: E 0.174 at 20.4, 0.204 at 20.0, 0.185–0.20 at 24–30), and the best of a few
    // evaluations landed 32 % off. The area term, which follows the drained volume, is smooth there
    // (0.13 / 0.055 / 0.053 / 0.065 / 0.096 at 20 / 24 / 28 / 30 / 33). Its minimum sat about 10 % low
    // (also at η = 10: 8.95) while extraction kept the grazed outline pixels (fixed by edge_coverage).
    double areaTrackWeight = 1;
    // Image rows this high (m) above the ground at the outlet are left out of E (see excludeGroundBand):
    // the job's "ground_band", by default kDefaultGroundBandShare of the outlet's height; 0 = compare
    // the puddle too.
    double groundBand = 0;
    double timeOffset = 0;  // simulation time of reference time 0 (s)
    int lastSourceFrame = 1000000;  // frame_end − frame_start: later reference frames are ignored
    std::vector<ParameterSpec> parameters;
    std::vector<FixedParameter> fixed;  // already set in `scene`
    int resolution = 32;
    int maxGenerations = 80;
    std::uint64_t seed = 1;
    int populationSize = 0;  // 0 = CMA-ES default
    double toleranceX = 1e-3;   // stop when every σ√C_ii (log space) < toleranceX (≈ 0.1 % in θ)
    double toleranceFun = 1e-9; // ... or when best E over the last 10 fine generations changes < this
    // Wall seconds for the whole identification (0 = none). The coarse phase ends by 35 % of it
    // (kCoarseBudgetShare), and after the minimum fine generations no generation starts that is
    // predicted to end past it (from the mean time of the fine generations so far, with a margin).
    // With a budget the result depends on the machine's speed.
    double timeBudget = 0;
    int maxFrames = 0;          // use only the first N weighted reference frames (0 = all)
    // Mesh + fill ("exact", the default) or the band splat ("fast"). The splat fills every pixel a
    // band voxel projects into, so it draws the liquid wider: on the sample cup's references it put
    // a run of the reference's own simulation 2.8 px per row wider than the exact fill, and the
    // η = 100 identification at +10 % (exact: +0.3 %). Both cost the same in identify; building
    // the level set dominates.
    bool exactSilhouettes = true;
    SilhouetteComparison silhouetteComparison = kDefaultSilhouetteComparison;
    // After the search, θ* is scored again on the grid moved by half a cell along x and y, which
    // moves the simulation's discretization against the scene and nothing else, and the interval
    // is widened by how far that moves the minimum (see the alignment check in identification.cpp).
    // On the sample cup at 48³ the half-cell shift alone moved the best η against the 64³ η = 1
    // reference from 0.86 to about 1.06, and against η = 10 from about 9.3 to 10.0.
    bool alignmentCheck = true;
    // E is scored on this many placements of the grid, moved by k/n cells along x and y
    // (k = 0 … n − 1). Where a small feature sits against the faces then matters less: on the
    // sample cup at 48³ the minima of E on grids moved 0, ¼, ½ and ¾ cell were 105.5 / 104.3 / 95.9 /
    // 102.7 against the η = 100 reference, and that of their mean 102.3 (identify_landscape_bench;
    // tests/bench/FINDINGS.md). 1 by default when several parameters are searched.
    int gridPlacements = 2;
    // ByGeneration (the default): each full-fidelity generation runs on one placement, in turn (the
    // coarse ones on the job's grid), at no extra cost, and θ* is the lowest point of E's mean over
    // them (placementMeanProfile). EachEvaluation: every evaluation runs on all of them, at n times
    // the cost, and E is their mean. On Table 1 of the sample cup (600 s budget), 2 by generation
    // gave ε_η 3.7 / 0.8 / 1.2 / 2.5 / 1.7 / 5.0 % at η = 1 … 300, one placement 3.7 / 0.8 / 0.5 /
    // 0.8 / 5.2 / 5.5 %, and 2 on each evaluation 11.7 / 4.5 / 1.3 / 1.4 / 1.3 / 1.3 % (half as
    // many evaluations, too few at η = 1 and 3). Only EachEvaluation with several parameters.
    PlacementSchedule placementSchedule = PlacementSchedule::ByGeneration;
    FidelitySchedule fidelity;
    nlohmann::json document;  // the parsed job (for the checkpoint's fingerprint)
    // A job with "runs" (several runs of one liquid, each its own scene and reference, sharing the
    // material's parameters) is its first run, with the others here: each a Job of its own scene,
    // camera and reference, and this job's parameters and search settings. E is the sum of the
    // runs' E. Every searched and fixed parameter must exist in every run's scene, and the scenes
    // must hold the same material (parseJob refuses them otherwise).
    std::vector<Job> otherRuns;
};

// Parses and validates everything needed before the first simulation; throws InputError naming
// the file and the field. Relative paths resolve against the job file's folder.
Job parseJob(const nlohmann::json& doc, const std::string& origin, const std::filesystem::path& baseDir);
Job loadJob(const std::filesystem::path& file);

// ---------------------------------------------------------------------------------------------
// One evaluation: simulate with θ at a resolution, silhouettes through the camera, E = Σ ω_f E_f.

struct Observation {
    ReferenceManifest reference;
    std::vector<cv::Mat1b> masks;  // per reference frame (empty Mat where ω_f = 0)
    cv::Mat1b compared;            // C_f (empty = all pixels)
    // With silhouettes: what the camera sees of the scene (the simulated silhouettes are depth-tested
    // against its opaque solids), and the pixels left out of C where the footage cannot show liquid
    // whatever θ is (comparedRegion), with the share of the reference's liquid that lies there.
    SceneVisibility view;
    int neverVisiblePixels = 0, inBackgroundPixels = 0;
    double referenceOutOfView = 0;
    std::vector<int> simFrames;    // the simulation frame matched to each reference frame
    std::optional<ScalarTrack> track;  // with an "area_px" column: the job's CSV or the masks' area
    double trackWeight = 0;
    // Per reference frame, the job's measured track there (NaN where it is not compared). Without
    // silhouettes the reference frames are the simulation frames within the track's time span.
    std::vector<double> measured;
    std::vector<Observation> otherRuns;  // of Job::otherRuns, in order
};

// When the job names a video but no extracted silhouettes, extracts them into OUT/reference with
// job.extraction and points job.referenceDir there (a further run k's into OUT/run<k>/reference).
// A finished extraction is reused while referenceSource(job), kept beside it as source.json, is
// unchanged.
void prepareReference(Job& job, const std::filesystem::path& outDir);
// What a video reference is extracted from: the video, clean plate and exclusion mask files (size,
// time written) and the job's extraction settings with the engine's defaults filled in, so that
// silhouettes from an engine with other defaults are not reused; null without a video.
nlohmann::json referenceSource(const Job& job);

// Loads the reference (checking image size against the camera and that frames remain) and maps
// reference times onto simulation frames; each further run's as well.
Observation loadObservation(const Job& job);
// The simulation frames of the reference frames that show liquid: a silhouette covering at least
// kInformativePixelShare of the compared pixels (extraction noise stays below it), or without
// silhouettes a measured value above 0, sorted.
constexpr double kInformativePixelShare = 1e-3;
std::vector<int> informativeSimFrames(const Observation& observation);
// So many informative frames the coarse clip must hold, and below which the reference cannot bound
// θ from above (every θ that keeps the liquid out of sight scores the same E).
constexpr int kMinInformativeFrames = 3;
// The same observation limited to the reference frames within the first `share` of the simulated
// clip, extended to its kMinInformativeFrames-th informative frame (the whole clip when it has
// fewer). The first compared frame always stays. Each further run's is cut alike.
Observation firstPartOf(const Observation& observation, double share);
// The last simulation frame any reference frame is compared with.
int lastSimFrame(const Observation& observation);

// What an evaluation wrote of its simulation's hidden fields (see evaluate).
struct FieldsSummary {
    int frames = 0;
    double meanGroundSpeed = 0;  // m/s, particles within 2 Δx above the ground plane, mean over frames
    int groundFrames = 0;        // frames with liquid on the ground (0: no ground, or none reached it)
};

struct Evaluation {
    std::vector<double> theta;
    int resolution = 0;
    double E = 0;
    std::vector<double> frameE;
    double simulatedPixels = 0;  // total silhouette area over frames (0 = the camera saw nothing)
    // Signs the simulation is not the model's: the largest share of its liquid lost since its
    // fullest frame, and the frames whose solve stopped short of its tolerance (over placements).
    double liquidLost = 0;
    int unconvergedFrames = 0;
    // The measured track's relative error, sqrt(Σ(sim − measured)² / Σ measured²), when one is compared
    // (of the first run).
    std::optional<double> trackError;
    // With several runs, each run's E (their sum is E); frameE, the track error and the fields are
    // the first run's.
    std::vector<double> runE;
    double seconds = 0;
    // Where the time went; fieldsSeconds is the .vdb writes and the level sets only they need.
    double simulationSeconds = 0, silhouetteSeconds = 0, fieldsSeconds = 0;
    std::vector<double> frameSeconds;  // per simulated frame 0..lastSimFrame (all of the above)
    std::optional<FieldsSummary> fields;  // when asked to write them
};

// `gridShift` moves the simulation grid by that many cells along x and y (the scene's solids,
// liquid and camera stay where they are).
Scene sceneWithParameters(const Job& job, const std::vector<double>& theta, int resolution, double gridShift = 0);
// Simulates θ at `resolution` and scores it, on each of the job's gridPlacements in turn (E, the
// frames' E and the silhouette area are their means, the timings their sums), or with the
// ByGeneration schedule on the grid moved by `gridShift` alone. With a `fieldsDir`,
// the first placement also writes every frame 0..lastSimFrame there as frame_%05d.vdb (surface,
// velocity, pressure) for Blender, so that the best evaluation's own run can be kept instead of
// simulated again. A job's further runs are scored alike (without fields) and added to E.
Evaluation evaluate(const Job& job, const Observation& observation, const std::vector<double>& theta,
                    int resolution, const std::filesystem::path& fieldsDir = {}, double gridShift = 0);
// An evaluation as JSON: the core of its checkpoint record, and what it travels between MPI ranks as.
nlohmann::json toJson(const Evaluation& evaluation);
Evaluation evaluationFromJson(const nlohmann::json& doc);

// ---------------------------------------------------------------------------------------------
// Where the loop's evaluations run.

// The reference as the full-fidelity and the coarse generations compare with it.
struct Observations {
    Observation full, coarse;
};
// Of a job whose reference is prepared (prepareReference): loadObservation and its first part
// (firstPartOf with the job's fidelity.coarse_time_share).
Observations observe(const Job& job);

// The evaluations one step of the loop asks for: every θ on one grid, at one fidelity.
struct EvaluationBatch {
    std::vector<std::vector<double>> thetas;
    bool coarse = false;  // compared with Observations::coarse
    int resolution = 0;
    double gridShift = 0;
    std::vector<std::filesystem::path> fieldsDirs;  // per θ (empty path: no fields); empty: none
    nlohmann::json toJson() const;
    static EvaluationBatch fromJson(const nlohmann::json& doc);
};
// In the batch's order. A simulation that fails gets E = ∞ and its message in `errors` (it ranks
// last and never aborts the run); bad input throws InputError.
struct BatchResult {
    std::vector<Evaluation> evaluations;
    std::vector<std::string> errors;
    std::vector<int> ranks;  // the MPI rank each ran on; empty when all ran in this process
};

class EvaluationPool {
public:
    virtual ~EvaluationPool() = default;
    virtual BatchResult evaluate(const Job& job, const Observations& observations, const EvaluationBatch& batch) = 0;
    // How many evaluations run at once (the time budget's rounds per generation).
    virtual int concurrency() const = 0;
};

// This process's threads: every θ of a batch at once, on up to `threads` of them (0 = all cores).
class ThreadPool : public EvaluationPool {
public:
    explicit ThreadPool(int threads);
    ~ThreadPool() override;
    BatchResult evaluate(const Job& job, const Observations& observations, const EvaluationBatch& batch) override;
    int concurrency() const override;

private:
    struct Threads;
    std::unique_ptr<Threads> threads_;
};

// The profile of E around the best full-fidelity evaluation θ_b of a single parameter: a
// least-squares parabola E ≈ a + b u + c u² over the points (θ, E) with |ln θ − ln θ_b| ≤ `range`
// (`inverse`: u = 1/θ, else ln θ), at least five of them; `info` receives the fit's figures.
// For viscosity u = 1/θ: a creeping flow moves at speeds ∝ 1/η, so a frame at time t looks like
// the truth's at t·η_true/η and E grows about evenly in 1/η − 1/η_true on both sides, while in ln θ
// its valley is steeper below the truth than above, and a parabola there puts the vertex high
// (measured: +2.3 % and +10.1 % against +1.9 % and +3.4 % in 1/η, on a 48³ and a 20³ run). For other
// parameters u = ln θ. The interval is where the parabola stays within ΔE of its minimum, ΔE =
// 2 × the jitter in E (the residuals' standard deviation, √(Σr²/(n − 3))), at least 1 % of E_min.
struct ProfileFit {
    double vertex = 0;                 // θ at the parabola's minimum
    std::array<double, 2> interval{};  // θ
    bool vertexAmongPoints = false;    // within the span of the fitted points (no extrapolation)
    double curvature = 0;              // c of E ≈ a + b u + c u²
};
std::optional<ProfileFit> fitProfile(const std::vector<std::pair<double, double>>& points, double thetaBest,
                                     double range, bool inverse, nlohmann::json& info);
// The vertex of the parabola through the lowest point (θ, E) and its nearest neighbours in θ on
// either side (u = 1/θ when `inverse`, else ln θ, as for fitProfile): one step of successive
// parabolic interpolation, the proposal a one-parameter search injects (see identification.cpp).
// None when the lowest point has no neighbour on one side, or E is not finite there.
std::optional<double> bracketedVertex(const std::vector<std::pair<double, double>>& points, bool inverse);

// The time budget's prediction of a full-fidelity evaluation before any has run: the mean, over
// the coarse evaluations within kCoarseToFineShift (ln θ, every coordinate) of the best coarse one,
// where the full-fidelity phase restarts, of their seconds scaled by (r/r_c)⁴ (cells × time steps)
// and by how much longer the full clip takes: its frames plus the remaining ones at the rate of
// the coarse clip's last third. `evaluated` holds the checkpoint's evaluation records ("fidelity",
// "theta", "E", "seconds", "frame_s"). 0 without coarse evaluations.
double predictedFullEvaluationSeconds(const nlohmann::json& evaluated, int coarseResolution, int fullResolution,
                                      int coarseFrames, int fullFrames);

// E's mean over grid placements as a profile, from evaluations that each ran on one placement (the
// job's "by_generation" schedule): `points` are (θ, E, grid shift). Each placement's points are
// joined by straight lines in u (1/θ when `inverse`, else ln θ; repeated θ averaged), and at every
// point's θ where all placements' lines reach, the profile holds the mean of their E there. The
// lines, not a fitted curve, because E is often a V near its minimum (on the sample cup at η = 10 it
// was 0.034 at the truth and 0.045–0.058 at ±10 % on both placements) and a parabola misplaces its
// tip. Points of a single placement are returned as they are; without a common span, every
// placement's points as they are (a run cut short by its time budget after one generation on each
// placement, their samples apart, would otherwise lose the better half: η = 1 on the sample cup, its
// first placement's points all below 0.71, the other's lowest E at 1.023).
struct PlacedPoint {
    double theta = 0, E = 0, gridShift = 0;
};
std::vector<std::pair<double, double>> placementMeanProfile(const std::vector<PlacedPoint>& points, bool inverse);

// ---------------------------------------------------------------------------------------------
// The search space the optimizer sees (see the top of this file), shared with benchmarks that run
// other optimizers on the same job.

struct LogSearchSpace {
    Eigen::VectorXd lower, upper;  // ln min, ln max
    Eigen::VectorXd start;         // ln θ0
    Eigen::VectorXd spread;        // ln(1 + spread/θ0), at most a third of the range, at least 1e-6
};
LogSearchSpace logSearchSpace(const Job& job);
// θ = exp(x clipped into the bounds).
std::vector<double> thetaOf(const Eigen::VectorXd& x, const LogSearchSpace& space);
// Σ (x − clip(x))², the squared distance outside the bounds, which CMA-ES adds to E.
double boundPenalty(const Eigen::VectorXd& x, const LogSearchSpace& space);

// ---------------------------------------------------------------------------------------------
// The loop.

struct GenerationReport {
    int generation = 0, generations = 0;
    long evaluations = 0;
    int resolution = 0;
    bool coarse = false;  // a coarse-fidelity generation
    std::vector<double> bestTheta;
    double bestE = 0;
    double sigma = 0;
    double elapsed = 0, remaining = 0;
    bool resumed = false;
};

enum class StopReason { MaxGenerations, ToleranceX, ToleranceFun, TimeBudget, Cancelled };
const char* toString(StopReason reason);

struct IdentificationResult {
    std::vector<double> theta;
    std::vector<std::array<double, 2>> interval;
    std::string intervalMethod;
    double E = 0;  // of θ*, the best full-fidelity evaluation
    StopReason stop = StopReason::MaxGenerations;
    int generations = 0;
    long evaluations = 0;
    int resumedFromGeneration = 0;
    double seconds = 0;
    nlohmann::json document;  // what result.json holds
};

struct IdentifyOptions {
    int threads = 0;  // 0 = all cores (tbb default)
    // Where evaluations run; null: a ThreadPool of `threads`. `viscoscope identify` under mpirun
    // passes one that spreads each batch over the ranks (cli/mpi_ranks.h).
    EvaluationPool* pool = nullptr;
    std::function<void(const GenerationReport&)> onGeneration;
    std::function<void(const std::string&)> onWarning;  // a result the user should doubt, and why
    bool writeFields = true;  // θ*'s simulation, every frame as .vdb, into OUT/fields
};

// Runs (or resumes from OUT/checkpoint.json) the identification and writes OUT/result.json,
// OUT/evaluations.csv. On a cancel request: abandons the evaluations in flight and throws Cancelled;
// the checkpoint of the last finished generation stays, and a resume redoes the abandoned ones
// (CMA-ES draws them again from its saved state). A checkpoint of a different job throws InputError.
IdentificationResult identify(const Job& job, const std::filesystem::path& outDir, const IdentifyOptions& options = {});

}  // namespace viscoscope::identify
