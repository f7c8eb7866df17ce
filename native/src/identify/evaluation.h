// One evaluation (simulate θ, silhouettes through the camera, E = Σ ω_f E_f), the observation it is
// scored against, and the pools evaluations run in.
#pragma once

#include "identify/job.h"
#include "observe/observe.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace viscoscope::identify {

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
    // The measured track's simulated value at each reference frame (NaN where it is not compared), of
    // the first run: what diagnose reads the residual over time from.
    std::vector<double> trackSimulated;
    // The shear rate the flow dissipates at over the simulated frames (FrameStats::shearRate, the
    // frames weighted by their dissipation), of the first run's first placement; none for the
    // thin-film model or a liquid at rest. Diagnose starts its power law there.
    std::optional<double> shearRate;
    // Of the same simulation, each frame's FrameStats::shearRate, frames at rest left out: the
    // spread of shear rates the flow exercised.
    std::vector<double> frameShearRates;
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
// `job` with `seedOffset` added to the particle seed of every run: another draw of the seeding.
Job reseeded(Job job, unsigned seedOffset);
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
    unsigned seedOffset = 0;  // added to every run's particle seed: another draw of the seeding
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

}  // namespace viscoscope::identify
