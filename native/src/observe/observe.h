// The observe stage: reference silhouettes from video, simulated silhouettes from surfaces, and the
// screen-space objective that compares them (Takahashi & Lin 2019, eq. 9).
//
// Masks are cv::Mat1b images with 255 inside the liquid and 0 outside, in the camera's pixel grid.
#pragma once

#include "camera/camera.h"
#include "sim/sim.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>
#include <opencv2/core.hpp>

#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace viscoscope {

// ---------------------------------------------------------------------------------------------
// Light as a sensor adds it. A pixel's footprint mixes colours in linear light, while video and
// renders store them sRGB-encoded; averaging and coverage estimates convert first.

cv::Mat srgbToLinear(const cv::Mat& image);  // 8-bit sRGB → float in [0, 1], same channels
cv::Mat linearToSrgb(const cv::Mat& image);  // float in [0, 1] → 8-bit sRGB, rounded

// The image in `file` decoded with cv::imread's `flags`; empty when the file is missing, empty or
// not a whole image. OpenCV's own complaint is not printed: the caller names the file and the problem.
cv::Mat readImage(const std::filesystem::path& file, int flags);
// Encodes `image` in the format of `file`'s extension and writes it whole or not at all (OpenCV's
// imwrite does not report a full disk). Throws OutputError.
void writeImage(const cv::Mat& image, const std::filesystem::path& file);

// ---------------------------------------------------------------------------------------------
// Reference extraction (`viscoscope extract`)

struct ExtractionOptions {
    int first = 0;   // first source frame index to extract
    int last = -1;   // last source frame index, inclusive; −1 = to the end
    int step = 1;
    std::optional<double> fps;  // overrides the video's own; required for image folders
    // The background model: MOG2 (Zivkovic 2004) learned from the source's first
    // `backgroundFrames` frames, which must show no liquid, or from a clean plate: an image, or one
    // frame of the source itself that shows no liquid outside the container (its index).
    int backgroundFrames = 10;
    std::optional<std::filesystem::path> cleanPlate;
    std::optional<int> cleanPlateFrame;
    double varianceThreshold = 16;  // MOG2's squared Mahalanobis distance for "foreground"
    // The floor on each pixel's learned variance (grey levels²). Compressed video re-quantizes a
    // static scene differently from frame to frame once anything moves, so the few learning frames
    // understate the noise; OpenCV's default floor of 4 turns those artifacts into speckles.
    double minimumVariance = 16;
    // Phones drift in exposure; each frame's gain per channel is matched to the background
    // (median ratio) so that a global brightness change is not taken for liquid.
    bool compensateGain = true;
    int threshold = 127;  // MOG2 marks shadows 127 and foreground 255; mask = value > threshold
    // MOG2's shadow test: a pixel darker than the background by a brightness ratio in [this, 1],
    // with no change of colour, is a shadow. OpenCV's 0.5 also takes a small dark drop for one: a
    // phone's 4:2:0 chroma turns a 2-px drop grey, and it reads 0.45–0.65 of the background. Cast
    // shadows in the sample references read 0.57–0.96. Scored against their own truth, the five
    // Table 1 references fit best at 0.7 (tests/bench/FINDINGS.md, "Figures moved from code comments").
    double shadowThreshold = 0.7;
    // Edge pixels the liquid covers less than this share of are dropped (0 = keep MOG2's outline).
    // MOG2 flags a pixel the outline only grazes, while a simulated silhouette holds
    // the pixels whose centre is inside, i.e. about half covered: without this the reference is
    // ~0.4 px fatter on every side, which biases η low (see extract.cpp). With it, pixels MOG2 calls
    // shadows that touch the liquid are tested too: a translucent liquid's edge reads as one.
    double edgeCoverage = 0.5;
    int closeKernel = 5;  // morphological closing, then opening; elliptic kernel diameters in px
    // Off by default: an opening also erases what is thinner than its kernel, a 2-px stream or a
    // drop just leaving the cup (the η = 100 sample reference lost 23 px of drop a frame), which the
    // simulated silhouettes keep. Speckles go by size instead:
    int openKernel = 0;
    // Blobs (8-connected) smaller than this many pixels are dropped: compression and render noise
    // leaves single pixels (14 a frame in that reference), liquid comes in larger pieces.
    int minBlobPixels = 3;
    // Static exclusion C (pixels not compared), e.g. the container: a PNG with nonzero = excluded,
    // and/or polygons in pixel coordinates. Masks are zeroed there too, so tracks ignore it.
    std::optional<std::filesystem::path> excludeMask;
    std::vector<std::vector<cv::Point2d>> excludePolygons;
    // Frame weights ω: "" (all 1), ranges of source frame indices "0-10:1,11-20:0" (frames not
    // named get 1), or one value per extracted frame "1,1,0,1".
    std::string weights;
};

// What `extract` wrote, as read back from manifest.json.
struct ReferenceManifest {
    std::filesystem::path directory;
    std::string source;
    double fps = 0;
    int width = 0, height = 0;
    std::vector<int> frames;      // source frame indices
    std::vector<double> times;    // seconds since source frame 0
    std::vector<double> weights;  // ω_f
    std::vector<std::string> maskFiles;  // relative to `directory`
    std::optional<std::string> excludeFile;  // 255 = excluded from the objective
    nlohmann::json parameters;

    cv::Mat1b mask(size_t i) const;  // throws InputError on a missing or wrongly sized mask
    cv::Mat1b comparedPixels() const;  // C_f: 255 where pixels count, 0 where excluded; empty = all
};

using ProgressCallback = std::function<void(int done, int total)>;

// Reads `source` (a video file any FFmpeg build reads, rotated as its metadata says, or a folder
// of numbered images) and writes outDir/masks/mask_%05d.png, outDir/exclude.png (when there is
// an exclusion), outDir/preview.png and, last, outDir/manifest.json. Outputs go to temporary
// names first, so a failed or cancelled run never leaves a complete-looking manifest.
// Throws InputError for bad input and Cancelled once a cancel is requested.
ReferenceManifest extractSilhouettes(const std::filesystem::path& source, const ExtractionOptions& options,
                                     const std::filesystem::path& outDir, const ProgressCallback& progress = {});

ReferenceManifest loadReferenceManifest(const std::filesystem::path& directory);
// Writes `manifest` as directory/manifest.json (the masks it names must be there already), for
// references made by other means than `extract`, such as synthetic ones in tests and benchmarks.
void saveReferenceManifest(const ReferenceManifest& manifest, const std::filesystem::path& directory);

// The extraction's revision: raise it whenever extract's masks change for the same options (as
// af89b92's shadow handling did), so that identify extracts a video again instead of reusing masks
// an older engine drew.
inline constexpr int kExtractionRevision = 2;
// Every option as manifest.json's "parameters" records it, defaults included, and the revision: what
// identify compares to tell whether silhouettes extracted earlier (perhaps by an engine with other
// defaults or another extraction) still hold.
nlohmann::json extractionParameters(const ExtractionOptions& options);
// Where the background model comes from, as "parameters" records it: "clean_plate" (an image),
// "clean_plate_frame" (a frame of the source) or "leading_frames". With the last two the liquid
// the footage shows in those frames is part of the background, and extraction cannot see it there.
const char* backgroundSourceName(const ExtractionOptions& options);
// ExtractionOptions from a JSON object (a job's "extraction"), with the names `extract` records in
// manifest.json's "parameters": first, last, step, fps, background_frames, clean_plate,
// clean_plate_frame, exclude_mask, exclude_polygons ([[[x, y], ...], ...] px), weights, mog2_variance_threshold,
// mog2_minimum_variance, compensate_gain, threshold, mog2_shadow_threshold, edge_coverage, close_kernel_px,
// open_kernel_px, min_blob_px. Missing names keep their defaults; paths resolve against `baseDir` ("" = none).
// Unknown names, wrong types, bad values and missing files throw InputError("<origin>.<name>: ...").
ExtractionOptions parseExtractionOptions(const nlohmann::json& doc, const std::string& origin,
                                         const std::filesystem::path& baseDir);

// ω for each extracted frame from an ExtractionOptions::weights string. Throws InputError.
std::vector<double> parseFrameWeights(const std::string& spec, const std::vector<int>& frames);

// ---------------------------------------------------------------------------------------------
// Scalar tracks

// A scalar observable over time; `values[c][i]` is column `columns[c]` at `time[i]`.
struct ScalarTrack {
    std::vector<std::string> columns;
    std::vector<double> time;  // s, non-decreasing
    std::vector<std::vector<double>> values;
};

// A measured CSV: a header whose first column is the time in seconds ("time_s"), then value
// columns in SI units, one row per sample (see shared/data/measured/README.md). Throws InputError
// naming the file and line. With another `firstColumn` (a rheometer's "shear_rate_per_s"), `time`
// holds that column's values, which must not decrease either.
ScalarTrack loadScalarTrackCsv(const std::filesystem::path& file, const std::string& firstColumn = "time_s");
void saveScalarTrackCsv(const ScalarTrack& track, const std::filesystem::path& file);

// An image ray: from `origin` (px) along `direction` (px, any length).
struct ImageRay {
    Eigen::Vector2d origin, direction;
};
// Distance in px from the ray's origin to the farthest mask pixel on the ray (0 when none): the
// leading edge of a front that advances along the ray.
double frontAlongRay(const cv::Mat1b& mask, const ImageRay& ray);
// Silhouette area in px.
double silhouetteArea(const cv::Mat1b& mask);
// Columns "front_px" (when a ray is given) and "area_px" for every frame of the manifest.
ScalarTrack tracksFromMasks(const ReferenceManifest& reference, const std::optional<ImageRay>& ray);

// Linear interpolation of column `column` at `times` (clamped at both ends).
std::vector<double> sampleTrack(const ScalarTrack& track, size_t column, const std::vector<double>& times);
// Σ(a − b)² / Σ b², with `reference` = b. Throws InputError on a size mismatch or an all-zero b.
double normalizedSquaredError(const std::vector<double>& simulated, const std::vector<double>& reference);

// The same observables measured on a simulated liquid, from its particles (world frame, Z-up, m).
// "On the ground" means within `band` above `groundHeight`. Extremes are taken at the 99.5th
// percentile, so that a stray particle does not move a front.
struct GroundObservables {
    double groundHeight = 0;
    double band = 0.005;
};
// How far the liquid on the ground reaches from `origin` along the horizontal `direction` (m),
// counting the liquid within `band` of that line.
double frontAlongGround(const std::vector<Eigen::Vector3d>& particles, const Eigen::Vector3d& origin,
                        const Eigen::Vector3d& direction, const GroundObservables& ground);
// Twice the radius of the liquid on the ground around the vertical axis through `centre` (m).
double puddleDiameter(const std::vector<Eigen::Vector3d>& particles, const Eigen::Vector3d& centre,
                      const GroundObservables& ground);
// Volume of the liquid below `height` (m³): the particles there times the volume each carries.
double drainedVolume(const std::vector<Eigen::Vector3d>& particles, double particleVolume, double height);

// ---------------------------------------------------------------------------------------------
// Simulated silhouettes

// What the camera can see of the scene, per pixel (sampled at its centre): how deep (z in the camera
// frame, m) the nearest opaque solid lies, and whether liquid could be in view there at all. Solids
// do not move, so one map serves every simulation of a scene through one camera.
struct SceneVisibility {
    cv::Mat1f occluderDepth;  // nearest opaque solid, +inf where none; empty = nothing hides anything
    // 255 where some point the liquid can reach (inside the domain, outside every solid) lies in front
    // of the nearest opaque solid; 0 where no simulation, whatever its θ, can show liquid.
    cv::Mat1b liquidCanShow;
    // Liquid resting on a solid touches it within its surface's voxel, so liquid up to this far
    // (m) behind an occluder still shows: a puddle's edge on the ground, the liquid lining a wall.
    double depthTolerance = 0;

    bool shows(int row, int column, double depth) const {
        return depth <= occluderDepth(row, column) + depthTolerance;
    }
};
// The scene's opaque solids (all but scene.transparentSolids; the ground plane included) drawn into
// a depth buffer, and the liquid's reach found by marching each pixel's ray through the domain.
SceneVisibility sceneVisibility(const Scene& scene, const PinholeCamera& camera);

// The compared pixels C (empty = all) without those where the footage cannot show liquid whatever θ
// is: where no liquid can be in view, and, when the reference's background was learned from the
// footage itself (backgroundFromFootage), where the liquid of the start lies (`initialLiquid`, its
// simulated silhouette, widened by 2 px for its outline; empty = none): that liquid is part of the
// background, so extraction can see neither it nor its leaving.
struct ComparedRegion {
    cv::Mat1b compared;    // 255 = compared
    int neverVisible = 0;  // pixels of C left out because no liquid can be seen there
    int inBackground = 0;  // ... because the background holds liquid there
};
ComparedRegion comparedRegion(const cv::Mat1b& compared, const SceneVisibility& view, const cv::Mat1b& initialLiquid);
// Whether the reference's background model holds the footage's own first frames (its manifest's
// "background" is "clean_plate_frame" or "leading_frames"), not a separate clean plate image.
bool backgroundFromFootage(const ReferenceManifest& reference);
// The share of the reference's liquid pixels within `compared` (over `masks`, empty ones skipped)
// that lie where no liquid can be in view: footage that the camera or the domain does not match.
double liquidOutOfViewShare(const std::vector<cv::Mat1b>& masks, const cv::Mat1b& compared,
                            const SceneVisibility& view);

// Fills every projected triangle into one mask (their union), sampling at pixel centres; with a
// `view`, only where the triangle lies in front of the opaque solids (a depth test).
// Triangles crossing the camera's near plane are clipped against it; geometry behind is ignored.
// Triangle edges stay straight in the image: with lens distortion, keep triangles small.
cv::Mat1b rasterizeMesh(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles,
                        const PinholeCamera& camera, const SceneVisibility* view = nullptr);
// The camera depth of the nearest triangle at each pixel centre (+inf where none): a depth buffer.
cv::Mat1f nearestDepth(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles,
                       const PinholeCamera& camera);

// The zero level set (negative inside) as triangles, via openvdb::tools::volumeToMesh.
// (TriangleMesh and loadMesh, for OBJ/PLY files, come from sim/sim.h.)
TriangleMesh meshFromLevelSet(const openvdb::FloatGrid& levelSet);

cv::Mat1b silhouetteFromLevelSet(const openvdb::FloatGrid& levelSet, const PinholeCamera& camera,
                                 const SceneVisibility* view = nullptr);
// The fast approximate path: splats each particle as its projected disc, then closes the mask
// with a kernel of `closeKernel` px to fill gaps between discs. With a `view`, a particle behind
// the opaque solids at the pixel it projects to is not drawn.
cv::Mat1b silhouetteFromParticles(const std::vector<Eigen::Vector3d>& points, double radius,
                                  const PinholeCamera& camera, int closeKernel = 3,
                                  const SceneVisibility* view = nullptr);
// The fast path for a level set: splats the inner band voxels (−h ≤ φ ≤ 0) as discs of radius h/2
// and closes the gaps. Any ray through a closed surface crosses that band, so it covers the
// silhouette without meshing. (h/2 rather than the half diagonal: that bloats the outline by about
// a third of a voxel and lowers the IoU against the exact path from 0.99 to 0.97.) A disc smaller
// than a pixel still fills the pixel it falls in, so outlines come out up to about a pixel wider
// than the exact path's: a preview, not what identify compares.
cv::Mat1b silhouetteFromLevelSetFast(const openvdb::FloatGrid& levelSet, const PinholeCamera& camera,
                                     const SceneVisibility* view = nullptr);
// World positions of the level set's inner band voxels (what the fast path splats).
std::vector<Eigen::Vector3d> innerBandPoints(const openvdb::FloatGrid& levelSet);

// ---------------------------------------------------------------------------------------------
// The objective

// What of two silhouettes E_f compares.
enum class SilhouetteComparison {
    // Eq. 9: E_f = (1/2M) Σ_pixels C_f (g_f − ĝ_f)², masks read as 0/1, M the pixel count.
    kPixels,
    // E_f = (1/2M) Σ_rows |Σ_cols C_f g_f − Σ_cols C_f ĝ_f|: each image row's liquid width, wherever
    // in the row it lies; never more than the pixels' E_f. A falling stream and its puddle wander
    // sideways with the particle seeding (the sample cup at 64³, η = 10: seed 3 against a render of
    // seed 11 had pixel E 0.207, the same seed 0.078; by widths 0.091 and 0.076), and that wander
    // says nothing of η. Rows should be about level in the world.
    kRowWidths,
};
// What `identify` and `score` use unless told otherwise.
constexpr SilhouetteComparison kDefaultSilhouetteComparison = SilhouetteComparison::kRowWidths;
// Parses "pixels" / "row_widths"; throws InputError naming `where` otherwise.
SilhouetteComparison parseSilhouetteComparison(const std::string& name, const std::string& where);
std::string silhouetteComparisonName(SilhouetteComparison comparison);

// E_f of one frame (see SilhouetteComparison). An empty `compared` means C_f = 1 everywhere.
double frameObjective(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared = {},
                      SilhouetteComparison comparison = SilhouetteComparison::kPixels);
// |g ∩ ĝ| / |g ∪ ĝ| over compared pixels; 1 when both are empty.
double intersectionOverUnion(const cv::Mat1b& simulated, const cv::Mat1b& reference,
                             const cv::Mat1b& compared = {});
// A picture of the difference: agreement in grey, false positives (simulated only) in orange,
// false negatives (reference only) in blue, excluded pixels darkened.
cv::Mat3b differenceImage(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared = {});

// The total objective is a weighted sum of normalized terms:
//   E_total = w_silhouette · Σ_f ω_f E_f  +  Σ_k w_k · Σ_i (a_k,i − b_k,i)² / Σ_i b_k,i²
// where k runs over scalar tracks (simulated a, reference b sampled at the reference times).
struct ObjectiveTerm {
    std::string name;
    double weight = 1;
    double value = 0;
};
double totalObjective(const std::vector<ObjectiveTerm>& terms);

// The puddle's rows: on a coarse identification grid the liquid spreading on the ground is
// resolved worst, and its radius grows only as η^(-1/8), so it says little about η and much about
// Δx: on the sample cup the rows above the band scored least at the truth and the rows in it below
// it (tests/bench/FINDINGS.md, "Figures moved from code comments").
// The band is the image rows on the ground's side of the point `band` metres above the ground on
// the axis of the first cup with a hole (its outlet); `compared` is returned with them set to 0
// (an empty `compared`, all pixels, becomes a mask of the camera's size first). Unchanged when
// band is 0, the scene has no ground or no cup with a hole, or either point is behind the camera.
cv::Mat1b excludeGroundBand(const cv::Mat1b& compared, const PinholeCamera& camera, const Scene& scene, double band);
// The outlet's height above the ground (0 without a ground or a cup with a hole).
double outletHeight(const Scene& scene);
// Throws InputError naming `where` unless band is finite and ≥ 0 and, where the scene has an outlet,
// lies below it.
void requireGroundBandBelowOutlet(const Scene& scene, double band, const std::string& where);

}  // namespace viscoscope
