// `viscoscope score`: simulated surfaces against reference silhouettes, E = Σ_f ω_f E_f (eq. 9).
#include "cli/commands.h"
#include "cli/progress.h"
#include "identify/identify.h"
#include "observe/observe.h"
#include "scene/scene.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <openvdb/io/File.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>

namespace viscoscope::cli {

namespace {

namespace fs = std::filesystem;

struct ScoreArguments {
    std::string camera, reference, sim, scene, outDir, progress = "text",
                comparison = silhouetteComparisonName(kDefaultSilhouetteComparison);
    int simFirst = 0;
    double groundBand = 0;
    bool identifyGroundBand = false;
    bool fast = false;
};

std::string numbered(const char* pattern, int number) {
    char name[64];
    std::snprintf(name, sizeof name, pattern, number);
    return name;
}

// The simulator's frame_%05d.vdb, or a mesh frame_%05d.obj / .ply.
fs::path simulationFrame(const fs::path& simDir, int number) {
    for (const char* extension : {".vdb", ".obj", ".ply"}) {
        const fs::path file = simDir / (numbered("frame_%05d", number) + extension);
        if (fs::exists(file)) return file;
    }
    throw InputError((simDir / numbered("frame_%05d.{vdb,obj,ply}", number)).string() + ": missing simulation frame");
}

openvdb::FloatGrid::Ptr readSurfaceGrid(const fs::path& file) {
    try {
        openvdb::io::File vdb(file.string());
        vdb.open();
        const openvdb::GridBase::Ptr base = vdb.readGrid("surface");
        auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        if (!grid) throw InputError(file.string() + ": grid \"surface\" is not a float level set");
        return grid;
    } catch (const openvdb::Exception& e) {
        throw InputError(file.string() + ": cannot read grid \"surface\" (" + std::string(e.what()) + ")");
    }
}

// Geometry that lies wholly behind the camera means a wrong camera (a flipped axis, a Blender
// camera read as an OpenCV one), not an empty frame.
void requireInFront(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& geometry,
                    const std::string& cameraFile, const fs::path& simFile) {
    if (!geometry.empty() && !anyPointInFront(camera, geometry))
        throw InputError(cameraFile + ": all geometry of " + simFile.string() + " lies behind the camera");
}

// The world corners of the grid's active voxels; when all of them are behind, so is the surface.
std::vector<Eigen::Vector3d> boundingBoxCorners(const openvdb::FloatGrid& grid) {
    const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    std::vector<Eigen::Vector3d> corners;
    if (box.empty()) return corners;
    for (int corner = 0; corner < 8; ++corner) {
        const openvdb::Coord ijk((corner & 1 ? box.max() : box.min()).x(), (corner & 2 ? box.max() : box.min()).y(),
                                 (corner & 4 ? box.max() : box.min()).z());
        const openvdb::Vec3d p = grid.indexToWorld(ijk);
        corners.emplace_back(p.x(), p.y(), p.z());
    }
    return corners;
}

// --scene, or else the scene `simulate` recorded in SIM/simulation.json; none when neither is there
// (a folder of another program's surfaces).
std::optional<Scene> scoredScene(const ScoreArguments& args) {
    if (!args.scene.empty()) return loadScene(args.scene);
    const fs::path record = fs::path(args.sim) / "simulation.json";
    if (!fs::exists(record)) return std::nullopt;
    return loadRecordedScene(record);
}

// The scene's solids and what the camera sees of them; with these, surfaces are drawn as identify
// draws them: the parts inside solids (below the ground, in walls) removed, and what an opaque solid
// hides left out.
struct ScoredSolids {
    sim::SolidField field;
    SceneVisibility view;
};

// A surface's silhouette, as identify draws it when `solids` are known.
cv::Mat1b simulatedSilhouette(const fs::path& file, const PinholeCamera& camera, bool fast,
                              const std::string& cameraFile, const ScoredSolids* solids) {
    const SceneVisibility* view = solids ? &solids->view : nullptr;
    if (file.extension() == ".vdb") {
        const openvdb::FloatGrid::Ptr grid = readSurfaceGrid(file);
        requireInFront(camera, boundingBoxCorners(*grid), cameraFile, file);
        if (solids) surface::clipToSolidExterior(*grid, solids->field);
        return fast ? silhouetteFromLevelSetFast(*grid, camera, view) : silhouetteFromLevelSet(*grid, camera, view);
    }
    const TriangleMesh mesh = loadMesh(file);  // meshes are already cheap to fill: no fast path
    requireInFront(camera, mesh.vertices, cameraFile, file);
    return rasterizeMesh(mesh.vertices, mesh.triangles, camera, view);
}

int runScore(const ScoreArguments& args) {
    openvdb::initialize();
    const PinholeCamera camera = loadCamera(args.camera);
    const ReferenceManifest reference = loadReferenceManifest(args.reference);
    if (camera.width != reference.width || camera.height != reference.height)
        throw InputError(args.camera + ": camera image is " + std::to_string(camera.width) + "x" +
                         std::to_string(camera.height) + ", reference masks are " + std::to_string(reference.width) +
                         "x" + std::to_string(reference.height));
    if (!fs::is_directory(args.sim)) throw InputError(args.sim + ": simulation folder not found");
    const SilhouetteComparison comparison = parseSilhouetteComparison(args.comparison, "--comparison");
    const std::optional<Scene> scene = scoredScene(args);
    cv::Mat1b compared = reference.comparedPixels();
    if (args.identifyGroundBand && args.groundBand != 0)
        throw InputError("--identify-ground-band: give it or --ground-band, not both");
    double groundBand = args.groundBand;
    if (groundBand != 0 || args.identifyGroundBand) {
        const char* option = args.identifyGroundBand ? "--identify-ground-band" : "--ground-band";
        if (!scene) throw InputError(std::string(option) + ": needs the scene: give --scene (SIM has no simulation.json)");
        if (args.identifyGroundBand) groundBand = identify::defaultGroundBand(*scene);
        requireGroundBandBelowOutlet(*scene, groundBand, option);
        compared = excludeGroundBand(compared, camera, *scene, groundBand);
    }
    const std::unique_ptr<ScoredSolids> solids =
        scene ? std::make_unique<ScoredSolids>(
                    ScoredSolids{sim::SolidField(scene->solids, sim::sceneGrid(*scene)), sceneVisibility(*scene, camera)})
              : nullptr;
    bool clipped = solids != nullptr;  // and every frame a level set (meshes are drawn as they are)
    nlohmann::json leftOut;
    if (solids) {
        // As identify: the footage's own background holds the liquid of its first frame, here SIM's.
        const cv::Mat1b initial = backgroundFromFootage(reference)
                                      ? simulatedSilhouette(simulationFrame(args.sim, 0), camera, args.fast,
                                                            args.camera, solids.get())
                                      : cv::Mat1b();
        const ComparedRegion region = comparedRegion(compared, solids->view, initial);
        compared = region.compared;
        leftOut = {{"left_out_never_visible", region.neverVisible},
                   {"left_out_liquid_in_background", region.inBackground}};
    }
    fs::create_directories(args.outDir);
    fs::remove(fs::path(args.outDir) / "score.json");

    const ProgressReporter progress(args.progress);
    nlohmann::json frames = nlohmann::json::array();
    double objective = 0;
    const int total = static_cast<int>(reference.frames.size());
    for (int j = 0; j < total; ++j) {
        if (cancelRequested()) {
            progress.report({{"event", "cancelled"}, {"stage", "score"}});
            return kExitCancelled;
        }
        nlohmann::json entry{{"frame", reference.frames[j]}, {"time_s", reference.times[j]}, {"weight", reference.weights[j]}};
        if (reference.weights[j] != 0) {
            const fs::path simFile = simulationFrame(args.sim, args.simFirst + j);
            const cv::Mat1b simulated = simulatedSilhouette(simFile, camera, args.fast, args.camera, solids.get());
            const cv::Mat1b observed = reference.mask(j);
            const double frameE = frameObjective(simulated, observed, compared, comparison);
            objective += reference.weights[j] * frameE;
            clipped &= simFile.extension() == ".vdb";
            entry["sim_file"] = simFile.string();
            entry["E_f"] = frameE;
            entry["iou"] = intersectionOverUnion(simulated, observed, compared);
            const fs::path diff = fs::path(args.outDir) / numbered("diff_%05d.png", reference.frames[j]);
            writeImage(differenceImage(simulated, observed, compared), diff);
        }
        frames.push_back(entry);
        progress.report({{"event", "progress"}, {"stage", "score"}, {"done", j + 1}, {"total", total}});
    }
    const nlohmann::json score{{"format", "viscoscope.score"}, {"version", 1},
                               {"silhouette", args.fast ? "fast" : "exact"}, {"comparison", args.comparison},
                               {"clipped_to_solids", clipped}, {"ground_band_m", groundBand},
                               {"camera", args.camera},       {"reference", args.reference},
                               {"sim", args.sim},             {"pixels", reference.width * reference.height},
                               {"compared_pixels", leftOut},
                               {"E", objective},              {"frames", frames}};
    writeJsonAtomically(score, fs::path(args.outDir) / "score.json");
    progress.report({{"event", "done"}, {"E", objective}});
    return kExitOk;
}

}  // namespace

Command addScoreCommand(CLI::App& app) {
    auto args = std::make_shared<ScoreArguments>();
    CLI::App* sub = app.add_subcommand("score", "Score simulated surfaces against reference silhouettes (eq. 9)");
    sub->add_option("--camera", args->camera, "camera.json (viscoscope.camera or viscoscope.blender_camera)")->required();
    sub->add_option("--reference", args->reference, "Folder written by `extract` (manifest.json, masks/)")->required();
    sub->add_option("--sim", args->sim, "Folder of frame_%05d.vdb (float grid \"surface\", metres) or .obj/.ply")
        ->required();
    sub->add_option("--scene", args->scene,
                    "Scene whose solids clip the surfaces, as identify does (default: SIM/simulation.json's)");
    sub->add_option("--ground-band", args->groundBand,
                    "Leave out the image rows this many metres above the ground at the outlet, as identify's "
                    "ground_band does (needs the scene; 0 compares every row)")
        ->capture_default_str();
    sub->add_flag("--identify-ground-band", args->identifyGroundBand,
                  "Leave out the ground band a job gets when it gives none (a quarter of the outlet's height)");
    sub->add_option("--sim-first", args->simFirst, "Number of the simulation frame matching the first reference frame")
        ->capture_default_str();
    sub->add_option("--out", args->outDir, "Output folder (score.json, diff_%05d.png)")->required();
    sub->add_flag("--fast", args->fast, "Approximate silhouettes by splatting the level set's inner band");
    sub->add_option("--comparison", args->comparison,
                    "E_f from the disagreeing pixels (eq. 9) or each row's width, as identify's silhouette_comparison")
        ->check(CLI::IsMember({"pixels", "row_widths"}))
        ->capture_default_str();
    sub->add_option("--progress", args->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}))
        ->capture_default_str();
    return {sub, [args] { return runScore(*args); }};
}

}  // namespace viscoscope::cli
