// The job file (format "viscoscope.job", version 1), as addon/operators/identify.py writes it:
// what is searched and fixed, the reference, and the search's settings.
#pragma once

#include "observe/observe.h"
#include "scene/scene.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace viscoscope::identify {

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
    // of it. The coarse phase ends early once its search is narrower than the full-fidelity phase's
    // restart spread (see the fidelity policy in identification.cpp). At the switch CMA-ES restarts
    // at the best coarse θ with a fixed log-space spread, and the best-so-far is reset, because E
    // values of the two fidelities are not comparable.
    // Stopping tolerances apply only at full fidelity, and at least `minFineGenerations` run there.
    double coarseFactor = 1;
    double coarseTimeShare = 1.0 / 3;
    int coarseGenerations = -1;  // −1 = ⌊maxGenerations / 2⌋ capped at 10; 0 = no coarse phase
    // Two fit a 10-minute budget on the sample scene at 48³, and the best evaluation after two of
    // them was close to the final one (tests/bench/FINDINGS.md, "Figures moved from code comments").
    int minFineGenerations = 2;
};

// A quarter of the fall: on the sample cup (10 cm) at η = 10 the rows above bands of 0.7–3.4 cm
// all scored least at the truth (see excludeGroundBand), and the stream fills most of the view.
constexpr double kDefaultGroundBandShare = 0.25;
// A job's ground_band when it gives none: kDefaultGroundBandShare of the outlet's height.
double defaultGroundBand(const Scene& scene);
constexpr int kMaxGridPlacements = 8;  // Job::gridPlacements
enum class PlacementSchedule { EachEvaluation, ByGeneration };  // Job::placementSchedule

// What simulates θ: the 3D solver ("simulation", the default) or, for an axisymmetric spread on a
// plane scored by a measured radius alone, the thin-film model of film/film.h ("thin_film"), which
// runs minutes of slow spreading in well under a second.
enum class ForwardModel { Simulation, ThinFilm };
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
    // on, nearby η can send the stream and puddle along other paths, and the best of a few
    // evaluations can land far off. The area term, which follows the drained volume, is smooth there
    // (tests/bench/FINDINGS.md, "Figures moved from code comments").
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
    double toleranceX = 1e-3;   // stop when every σ√C_ii (log space) < toleranceX (a relative step of toleranceX in θ)
    // ... or, with the simulation as the forward model, when in the last full-fidelity generations
    // (one per placement taken by generation, at least two) each generation's median E lies within
    // this share of its least (see settled in identification.cpp).
    double toleranceFun = 0.05;
    // Wall seconds for the whole identification (0 = none): a cap, not a plan. After the minimum
    // fine generations no generation starts that is predicted to end past it with the grid checks
    // (from the mean time of the fine generations so far, with a margin); a search it stops is
    // doubted as unconverged. Everything else (the coarse phase, the minimum generations, the grid
    // checks) runs alike on any machine.
    double timeBudget = 0;
    int maxFrames = 0;          // use only the first N weighted reference frames (0 = all)
    // Mesh + fill ("exact", the default) or the band splat ("fast"). The splat fills every pixel a
    // band voxel projects into, so it draws the liquid wider: on the sample cup's references it put
    // a run of the reference's own simulation wider than the exact fill, and the identification
    // off by more (tests/bench/FINDINGS.md, "Figures moved from code comments"). Both cost the same in identify;
    // building the level set dominates.
    bool exactSilhouettes = true;
    SilhouetteComparison silhouetteComparison = kDefaultSilhouetteComparison;
    // After a one-parameter search, θ* is scored again on the grid moved by half a cell along x and
    // y, with the particles seeded anew, and the interval is widened by how far that moves the
    // minimum; and on a coarser grid, and the interval reaches to where the minimum moves as the
    // cell shrinks to nothing (see grid_checks.cpp).
    bool alignmentCheck = true;
    bool resolutionCheck = true;
    // E is scored on this many placements of the grid, moved by k/n cells along x and y
    // (k = 0 … n − 1). Where a small feature sits against the faces then matters less: on the
    // sample cup at 48³ the minima of E on grids moved 0, ¼, ½ and ¾ cell were 105.5 / 104.3 / 95.9 /
    // 102.7 against the η = 100 reference, and that of their mean 102.3 (identify_landscape_bench;
    // tests/bench/FINDINGS.md). 1 by default when several parameters are searched.
    int gridPlacements = 2;
    // ByGeneration (the default): each full-fidelity generation runs on one placement, in turn (the
    // coarse ones on the job's grid), at no extra cost, and θ* is the lowest point of E's mean over
    // them (placementMeanProfile). EachEvaluation: every evaluation runs on all of them, at n times
    // the cost, and E is their mean; within a time budget that leaves half as many evaluations, too
    // few at low η (tests/bench/FINDINGS.md, "Figures moved from code comments"). Only EachEvaluation with several
    // parameters.
    PlacementSchedule placementSchedule = PlacementSchedule::ByGeneration;
    ForwardModel forwardModel = ForwardModel::Simulation;
    FidelitySchedule fidelity;
    // The liquid's flow curve measured on a rheometer, the job's "rheometer" CSV (columns
    // shear_rate_per_s, stress_pa; rising shear rates): diagnose compares the flow curve it finds
    // with it. Empty: none.
    std::vector<std::array<double, 2>> rheometer;  // (γ̇ 1/s, τ Pa)
    nlohmann::json document;  // the parsed job (for the checkpoint's fingerprint)
    // A job with "runs" (several runs of one liquid, each its own scene and reference, sharing the
    // material's parameters) is its first run, with the others here: each a Job of its own scene,
    // camera and reference, and this job's parameters and search settings. E is the sum of the
    // runs' E. Every searched and fixed parameter must exist in every run's scene, and the scenes
    // must hold the same material (parseJob refuses them otherwise).
    std::vector<Job> otherRuns;
};

// A searched parameter of `scene` as a job's "parameters" entry gives it ({"name", "initial",
// "spread", "min", "max"}), with the declaration's search bounds and start where it gives none;
// throws InputError prefixed by `where`.
ParameterSpec parseSearchedParameter(const nlohmann::json& spec, const Scene& scene, const std::string& where);

// Parses and validates everything needed before the first simulation; throws InputError naming
// the file and the field. Relative paths resolve against the job file's folder.
Job parseJob(const nlohmann::json& doc, const std::string& origin, const std::filesystem::path& baseDir);
Job loadJob(const std::filesystem::path& file);

}  // namespace viscoscope::identify
