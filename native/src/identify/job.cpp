// The job file ("viscoscope.job", version 1): what addon/operators/identify.py `write_job` writes,
// plus optional fields for the loop and for extracting the video ("extraction"). Validated up front
// so a bad job fails before any simulation.
#include "film/film.h"
#include "identify/identify.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>

namespace viscoscope::identify {

namespace {

namespace fs = std::filesystem;

fs::path resolve(const fs::path& base, const std::string& value) {
    const fs::path p(value);
    return p.is_absolute() || base.empty() ? p : base / p;
}

double finiteNumber(const nlohmann::json& doc, const std::string& key, const std::string& origin) {
    if (!doc.contains(key)) throw InputError(origin + ": " + key + ": missing");
    const nlohmann::json& value = doc.at(key);
    if (!value.is_number()) throw InputError(origin + ": " + key + ": must be a number");
    const double x = value.get<double>();
    if (!std::isfinite(x)) throw InputError(origin + ": " + key + ": must be finite, got " + value.dump());
    return x;
}

double optionalNumber(const nlohmann::json& doc, const std::string& key, double fallback, const std::string& origin) {
    if (!doc.contains(key) || doc.at(key).is_null()) return fallback;
    return finiteNumber(doc, key, origin);
}

int optionalInt(const nlohmann::json& doc, const std::string& key, int fallback, int minimum,
                const std::string& origin, int maximum = 1000000000) {
    if (!doc.contains(key) || doc.at(key).is_null()) return fallback;
    const nlohmann::json& value = doc.at(key);
    if (!value.is_number_integer()) throw InputError(origin + ": " + key + ": must be an integer");
    const long long v = value.get<long long>();
    if (v < minimum || v > maximum)
        throw InputError(origin + ": " + key + ": must be in [" + std::to_string(minimum) + ", " +
                         std::to_string(maximum) + "], got " + value.dump());
    return static_cast<int>(v);
}

// CMA-ES samples 4 + 3 ln n a generation; a thousand is far past any use, and a million is a
// generation that never ends.
constexpr int kMaxPopulation = 1000;

std::optional<std::string> optionalString(const nlohmann::json& doc, const std::string& key, const std::string& origin) {
    if (!doc.contains(key) || doc.at(key).is_null()) return std::nullopt;
    if (!doc.at(key).is_string() || doc.at(key).get<std::string>().empty())
        throw InputError(origin + ": " + key + ": must be a non-empty string");
    return doc.at(key).get<std::string>();
}

// A bound under either spelling: the add-on writes min/max, the design says lower/upper.
double bound(const nlohmann::json& p, const char* a, const char* b, double fallback, const std::string& where) {
    if (p.contains(a) && !p.at(a).is_null()) return finiteNumber(p, a, where);
    if (p.contains(b) && !p.at(b).is_null()) return finiteNumber(p, b, where);
    return fallback;
}

Eigen::Vector3d finiteVector(const nlohmann::json& doc, const std::string& key, const std::string& where) {
    if (!doc.contains(key)) throw InputError(where + "." + key + ": missing");
    const nlohmann::json& v = doc.at(key);
    if (!v.is_array() || v.size() != 3) throw InputError(where + "." + key + ": must be [x, y, z] (m)");
    Eigen::Vector3d x;
    for (int i = 0; i < 3; ++i) {
        if (!v.at(i).is_number() || !std::isfinite(v.at(i).get<double>()))
            throw InputError(where + "." + key + ": must be three finite numbers, got " + v.dump());
        x[i] = v.at(i).get<double>();
    }
    return x;
}

// {"csv", "column", "observable": "front" | "radius", "origin", "direction" (front), "band", "weight"}
MeasuredTrack parseMeasuredTrack(const nlohmann::json& track, const std::string& where, const fs::path& baseDir) {
    MeasuredTrack m;
    rejectUnknownKeys(track, {"csv", "column", "observable", "origin", "direction", "band", "weight"}, where + ".");
    m.csv = resolve(baseDir, track.at("csv").get<std::string>());
    if (!fs::exists(m.csv)) throw InputError(where + ".csv: " + m.csv.string() + " not found");
    const std::string observable = optionalString(track, "observable", where).value_or("");
    if (observable == "front") m.observable = TrackObservable::Front;
    else if (observable == "radius") m.observable = TrackObservable::Radius;
    else throw InputError(where + ".observable: expected \"front\" or \"radius\", got \"" + observable + "\"");
    m.origin = finiteVector(track, "origin", where);
    if (m.observable == TrackObservable::Front) {
        m.direction = finiteVector(track, "direction", where);
        if (std::hypot(m.direction.x(), m.direction.y()) == 0)
            throw InputError(where + ".direction: must have a horizontal component");
    }
    m.band = optionalNumber(track, "band", m.band, where);
    if (!(m.band > 0)) throw InputError(where + ".band: must be > 0 (m)");
    m.weight = optionalNumber(track, "weight", m.weight, where);
    if (!(m.weight > 0)) throw InputError(where + ".weight: must be > 0");
    m.data = loadScalarTrackCsv(m.csv);
    const auto column = optionalString(track, "column", where);
    if (!column) throw InputError(where + ".column: missing (the CSV's measured column, e.g. \"front_m\")");
    while (m.column < m.data.columns.size() && m.data.columns[m.column] != *column) ++m.column;
    if (m.column == m.data.columns.size()) throw InputError(m.csv.string() + ": no column \"" + *column + "\"");
    if (m.data.time.empty()) throw InputError(m.csv.string() + ": no samples");
    return m;
}

SceneParameter namedParameter(const nlohmann::json& p, const Scene& scene, const std::string& where) {
    if (!p.is_object()) throw InputError(where + ": must be an object");
    const auto name = optionalString(p, "name", where);
    if (!name) throw InputError(where + ".name: missing");
    return resolveParameter(scene, *name, where + ".name");
}

void requireWithinDeclaredBounds(const SceneParameter& parameter, double value, const std::string& where) {
    if (const std::string problem = boundsProblem(*parameter.declaration, value); !problem.empty())
        throw InputError(where + ": " + problem + " (" + parameter.name + "'s physical bounds)");
}


// {"name", "value", "uncertainty"}: the standard uncertainty (same unit), 0 when not known.
FixedParameter parseFixed(const nlohmann::json& p, const Scene& scene, const std::string& where) {
    FixedParameter fixed;
    fixed.parameter = namedParameter(p, scene, where);
    rejectUnknownKeys(p, {"name", "value", "uncertainty"}, where + ".");
    fixed.value = finiteNumber(p, "value", where);
    requireWithinDeclaredBounds(fixed.parameter, fixed.value, where + ".value");
    fixed.uncertainty = optionalNumber(p, "uncertainty", 0.0, where);
    if (!(fixed.uncertainty >= 0)) throw InputError(where + ".uncertainty: must be ≥ 0, got " + formatNumber(fixed.uncertainty));
    return fixed;
}

// The keys of a job file that belong to one run: with "runs" they are given in each of its entries.
const std::vector<std::string>& runKeys() {
    static const std::vector<std::string> keys{"scene",      "camera",     "silhouettes", "reference",
                                               "video",      "extraction", "track",       "area_track_weight",
                                               "ground_band", "frame_start", "frame_end", "max_frames",
                                               "time_offset_s"};
    return keys;
}

// Refuses runs whose material differs from the first run's, naming the first field that does, once
// every searched parameter holds the first run's value in both (their starting values may differ).
void requireOneMaterial(const std::vector<Job>& runs, const std::string& origin) {
    const Job& first = runs.front();
    const nlohmann::json material = sceneToJson(first.scene).at("material");
    for (size_t r = 1; r < runs.size(); ++r) {
        Scene scene = runs[r].scene;
        for (size_t i = 0; i < first.parameters.size(); ++i)
            setParameter(scene, runs[r].parameters[i].parameter, parameterValue(first.scene, first.parameters[i].parameter));
        const nlohmann::json other = sceneToJson(scene).at("material");
        const nlohmann::json patch = nlohmann::json::diff(material, other);
        if (patch.empty()) continue;
        const std::string path = patch.front().at("path").get<std::string>();
        std::string field = "material" + path;
        std::replace(field.begin(), field.end(), '/', '.');
        const nlohmann::json::json_pointer pointer(path);
        throw InputError(origin + ": runs[" + std::to_string(r) + "].scene: " + field + ": " +
                         (other.contains(pointer) ? other.at(pointer).dump() : std::string("absent")) + " where runs[0] has " +
                         (material.contains(pointer) ? material.at(pointer).dump() : std::string("none")) +
                         "; the runs of one job share one liquid");
    }
}

// A thin-film job scores the film's radius against a measured one from the emitters' centre, and
// has no grid to place against the scene.
void requireFilmJob(Job& job, const nlohmann::json& doc, const std::string& origin) {
    const std::string where = origin + ": forward_model: thin_film";
    if (job.hasSilhouettes() || job.trackCsv)
        throw InputError(where + " compares a measured track alone; the job has silhouettes");
    if (!job.measuredTrack || job.measuredTrack->observable != TrackObservable::Radius)
        throw InputError(where + " needs a measured track of the observable \"radius\"");
    Scene scene = job.scene;
    scene.domain.resolution = job.resolution;
    if (const std::string problem = film::filmProblem(scene); !problem.empty())
        throw InputError(origin + ": scene: " + problem);
    const Eigen::Vector2d centre = std::get<DiscEmitter>(scene.liquids.front()).center.head<2>();
    if ((job.measuredTrack->origin.head<2>() - centre).norm() > scene.cellSize())
        throw InputError(origin + ": track.origin: the thin-film radius is measured from the emitters' centre (" +
                         formatNumber(centre.x()) + ", " + formatNumber(centre.y()) + ")");
    if (optionalInt(doc, "grid_placements", 1, 1, origin) > 1)
        throw InputError(origin + ": grid_placements: the thin-film model has no grid to place; give 1 or none");
    job.gridPlacements = 1;
    job.placementSchedule = PlacementSchedule::EachEvaluation;
    job.alignmentCheck = false;
    job.resolutionCheck = false;
}

// A rheometer's flow curve: at least two rows of positive shear rate and stress.
std::vector<std::array<double, 2>> loadRheometer(const fs::path& file) {
    if (!fs::exists(file)) throw InputError(file.string() + ": rheometer: not found");
    const ScalarTrack csv = loadScalarTrackCsv(file, "shear_rate_per_s");
    const auto stress = std::find(csv.columns.begin(), csv.columns.end(), "stress_pa");
    if (stress == csv.columns.end()) throw InputError(file.string() + ": rheometer: no column \"stress_pa\"");
    const std::vector<double>& stresses = csv.values[stress - csv.columns.begin()];
    std::vector<std::array<double, 2>> curve;
    for (size_t i = 0; i < csv.time.size(); ++i) {
        if (!(csv.time[i] > 0 && std::isfinite(csv.time[i]) && stresses[i] > 0 && std::isfinite(stresses[i])))
            throw InputError(file.string() + ": rheometer: row " + std::to_string(i + 1) + ": shear rate and stress "
                             "must be positive numbers, got " + formatNumber(csv.time[i]) + ", " + formatNumber(stresses[i]));
        curve.push_back({csv.time[i], stresses[i]});
    }
    if (curve.size() < 2) throw InputError(file.string() + ": rheometer: needs at least two rows");
    return curve;
}

// {"runs": [{run keys}, ...], shared keys}: each run is parsed as a job of its own from the shared
// keys and its entry's, so that every check a single-run job gets applies to each run alike.
Job parseRuns(const nlohmann::json& doc, const std::string& origin, const fs::path& baseDir) {
    const nlohmann::json& runs = doc.at("runs");
    if (!runs.is_array() || runs.empty()) throw InputError(origin + ": runs: must be a non-empty array of runs");
    for (const std::string& key : runKeys())
        if (doc.contains(key))
            throw InputError(origin + ": " + key + ": belongs in each entry of runs, not beside them");
    std::vector<Job> parsed;
    for (size_t i = 0; i < runs.size(); ++i) {
        const std::string where = origin + ": runs[" + std::to_string(i) + "]";
        if (!runs.at(i).is_object()) throw InputError(where + ": must be an object");
        rejectUnknownKeys(runs.at(i), runKeys(), where + ".");
        nlohmann::json single = doc;
        single.erase("runs");
        for (const auto& [key, value] : runs.at(i).items()) single[key] = value;
        parsed.push_back(parseJob(single, where, baseDir));
    }
    requireOneMaterial(parsed, origin);
    Job job = std::move(parsed.front());
    job.document = doc;
    job.otherRuns.assign(std::make_move_iterator(parsed.begin() + 1), std::make_move_iterator(parsed.end()));
    return job;
}

}  // namespace

// Bounds and start default to the declaration's; a solid's dimensions to its value in the scene, and
// a factor 2 either side of it.
ParameterSpec parseSearchedParameter(const nlohmann::json& p, const Scene& scene, const std::string& where) {
    ParameterSpec spec;
    spec.parameter = namedParameter(p, scene, where);
    rejectUnknownKeys(p, {"name", "initial", "spread", "min", "max", "lower", "upper", "log"}, where + ".");
    const ParameterDeclaration& d = *spec.parameter.declaration;
    if (!d.searchable) throw InputError(where + ".name: \"" + spec.name() + "\" cannot be searched; fix it instead");
    const double sceneValue = parameterValue(scene, spec.parameter);
    spec.initial = optionalNumber(p, "initial", std::isnan(d.searchInitial) ? sceneValue : d.searchInitial, where);
    spec.spread = optionalNumber(p, "spread", spec.initial, where);
    spec.lower = bound(p, "min", "lower", std::isnan(d.searchLower) ? sceneValue / 2 : d.searchLower, where);
    spec.upper = bound(p, "max", "upper", std::isnan(d.searchUpper) ? sceneValue * 2 : d.searchUpper, where);
    if (p.contains("log") && p.at("log") != nlohmann::json(true))
        throw InputError(where + ".log: only log-space search is supported (log: true)");
    if (spec.lower <= 0)
        throw InputError(where + ".min: must be > 0 (the search is in log space), got " + formatNumber(spec.lower) +
                         (sceneValue == 0 ? " (the scene's value is 0: give min and max)" : ""));
    requireWithinDeclaredBounds(spec.parameter, spec.lower, where + ".min");
    requireWithinDeclaredBounds(spec.parameter, spec.upper, where + ".max");
    if (spec.lower > spec.upper)
        throw InputError(where + ": bounds: lower " + formatNumber(spec.lower) + " > upper " + formatNumber(spec.upper));
    if (spec.initial < spec.lower || spec.initial > spec.upper)
        throw InputError(where + ".initial: " + formatNumber(spec.initial) + " is outside the bounds [" +
                         formatNumber(spec.lower) + ", " + formatNumber(spec.upper) + "]");
    if (spec.spread <= 0) throw InputError(where + ".spread: must be > 0");
    // The search clips its spread to a third of the interval; one wider than the whole interval is a
    // mistake, not a request to be clipped silently.
    if (p.contains("spread") && spec.logSpread() > spec.logRange())
        throw InputError(where + ".spread: " + formatNumber(spec.spread) + " from " + formatNumber(spec.initial) +
                         " is a step wider than the whole interval [" + formatNumber(spec.lower) + ", " +
                         formatNumber(spec.upper) + "] searched in log space");
    return spec;
}

double defaultGroundBand(const Scene& scene) { return kDefaultGroundBandShare * outletHeight(scene); }

const char* placementScheduleName(PlacementSchedule schedule) {
    return schedule == PlacementSchedule::ByGeneration ? "by_generation" : "each_evaluation";
}

Job parseJob(const nlohmann::json& doc, const std::string& origin, const fs::path& baseDir) {
    if (!doc.is_object()) throw InputError(origin + ": must be a JSON object");
    if (doc.value("format", nlohmann::json()) != nlohmann::json("viscoscope.job"))
        throw InputError(origin + ": format: expected \"viscoscope.job\"");
    if (doc.value("version", nlohmann::json()) != nlohmann::json(1))
        throw InputError(origin + ": version: expected 1, got " + doc.value("version", nlohmann::json()).dump());
    std::vector<std::string> known{"format", "version", "parameters", "fixed", "resolution", "max_generations", "seed",
                                   "population", "tolerance_x", "tolerance_fun", "time_budget_s", "silhouette_method",
                                   "alignment_check", "resolution_check", "grid_placements", "grid_placement_schedule",
                                   "silhouette_comparison", "fidelity", "forward_model", "rheometer", "runs"};
    known.insert(known.end(), runKeys().begin(), runKeys().end());
    rejectUnknownKeys(doc, known, origin + ": ");
    if (doc.contains("runs")) return parseRuns(doc, origin, baseDir);
    Job job;
    job.document = doc;

    // The scene: a path, or the scene object inline.
    if (!doc.contains("scene")) throw InputError(origin + ": scene: missing");
    if (doc.at("scene").is_string()) job.scene = loadScene(resolve(baseDir, doc.at("scene").get<std::string>()));
    else if (doc.at("scene").is_object()) job.scene = parseScene(doc.at("scene"), origin + ": scene", baseDir);
    else throw InputError(origin + ": scene: must be a path or an object");

    // A measured track of a world-space observable can stand alone: no silhouettes, no camera.
    auto given = [&](const char* key) { return doc.contains(key) && !doc.at(key).is_null(); };
    const bool measuredOnly = given("track") && doc.at("track").is_object() && doc.at("track").contains("observable") &&
                              !given("silhouettes") && !given("reference") && !given("video");
    if (!given("camera")) {
        if (!measuredOnly) throw InputError(origin + ": camera: missing");
    } else if (doc.at("camera").is_string()) {
        job.cameraFile = resolve(baseDir, doc.at("camera").get<std::string>());
        job.camera = loadCamera(job.cameraFile);
    } else if (doc.at("camera").is_object()) {
        job.cameraFile = origin + ": camera";
        job.camera = parseCamera(doc.at("camera"), origin + ": camera");
    } else {
        throw InputError(origin + ": camera: must be a path or an object");
    }

    // The reference: an extracted manifest folder ("silhouettes", or "reference"), else the video,
    // which identify() extracts into OUT/reference first.
    std::optional<std::string> silhouettes = optionalString(doc, "silhouettes", origin);
    if (!silhouettes) silhouettes = optionalString(doc, "reference", origin);
    if (silhouettes) job.referenceDir = resolve(baseDir, *silhouettes);
    if (const auto video = optionalString(doc, "video", origin)) job.video = resolve(baseDir, *video);
    if (!silhouettes && !job.video && !measuredOnly)
        throw InputError(origin + ": silhouettes: missing (and no video to extract, nor a track with an observable)");
    if (job.video && !silhouettes && !fs::exists(*job.video))
        throw InputError(origin + ": video: " + job.video->string() + " not found");
    if (silhouettes && !fs::exists(job.referenceDir / "manifest.json"))
        throw InputError(origin + ": silhouettes: " + (job.referenceDir / "manifest.json").string() + " not found");
    // How to extract the video (clean plate, exclusion, weights, ...); `extract`'s parameter names.
    if (doc.contains("extraction") && !doc.at("extraction").is_null())
        job.extraction = parseExtractionOptions(doc.at("extraction"), origin + ": extraction", baseDir);

    if (doc.contains("track") && !doc.at("track").is_null()) {
        const nlohmann::json& track = doc.at("track");
        const std::string where = origin + ": track";
        if (track.is_string()) job.trackCsv = resolve(baseDir, track.get<std::string>());
        else if (track.is_object() && track.contains("csv") && track.at("csv").is_string()) {
            if (track.contains("observable")) {
                job.measuredTrack = parseMeasuredTrack(track, where, baseDir);
                const Domain& d = job.scene.domain;  // where the lab measured from is a point of the scene
                if ((job.measuredTrack->origin.array() < d.min.array()).any() ||
                    (job.measuredTrack->origin.array() > d.max.array()).any())
                    throw InputError(where + ".origin: lies outside the scene's domain; is it in another unit?");
            } else {
                rejectUnknownKeys(track, {"csv", "weight"}, where + ".");
                job.trackCsv = resolve(baseDir, track.at("csv").get<std::string>());
                job.trackWeight = optionalNumber(track, "weight", 1.0, where);
                if (job.trackWeight < 0) throw InputError(where + ".weight: must be ≥ 0");
            }
        } else throw InputError(where + ": must be a CSV path, {\"csv\": path, \"weight\": w} or a measured track "
                                        "{\"csv\", \"column\", \"observable\", \"origin\", ...}");
        if (job.trackCsv && !fs::exists(*job.trackCsv))
            throw InputError(where + ": " + job.trackCsv->string() + " not found");
    }

    job.areaTrackWeight = optionalNumber(doc, "area_track_weight", job.areaTrackWeight, origin);
    if (!(job.areaTrackWeight >= 0)) throw InputError(origin + ": area_track_weight: must be ≥ 0");
    job.groundBand = optionalNumber(doc, "ground_band", defaultGroundBand(job.scene), origin);
    requireGroundBandBelowOutlet(job.scene, job.groundBand, origin + ": ground_band");

    // Blender's frame_start is simulation time 0 and video frame 0; frames after frame_end are ignored.
    const int frameStart = optionalInt(doc, "frame_start", 0, -1000000, origin);
    const int frameEnd = optionalInt(doc, "frame_end", frameStart + 1000000, -1000000, origin);
    if (frameEnd < frameStart) throw InputError(origin + ": frame_end: before frame_start");
    job.maxFrames = optionalInt(doc, "max_frames", 0, 0, origin);
    job.timeOffset = optionalNumber(doc, "time_offset_s", 0.0, origin);
    job.lastSourceFrame = frameEnd - frameStart;

    // Nothing searched is a job only diagnose takes: every unknown fixed at a measured value (the
    // base model held there, each effect searching its own parameters).
    const bool allFixed = given("fixed") && doc.at("fixed").is_array() && !doc.at("fixed").empty();
    if (!allFixed && (!doc.contains("parameters") || !doc.at("parameters").is_array() || doc.at("parameters").empty()))
        throw InputError(origin + ": parameters: must be a non-empty array");
    if (given("parameters") && !doc.at("parameters").is_array())
        throw InputError(origin + ": parameters: must be an array");
    const nlohmann::json searchedParameters = given("parameters") ? doc.at("parameters") : nlohmann::json::array();
    std::set<std::string> names;
    for (size_t i = 0; i < searchedParameters.size(); ++i) {
        const std::string where = origin + ": parameters[" + std::to_string(i) + "]";
        ParameterSpec spec = parseSearchedParameter(searchedParameters.at(i), job.scene, where);
        if (!names.insert(spec.name()).second) throw InputError(where + ".name: \"" + spec.name() + "\" twice");
        job.parameters.push_back(spec);
    }
    if (given("fixed")) {
        if (!doc.at("fixed").is_array()) throw InputError(origin + ": fixed: must be an array");
        for (size_t i = 0; i < doc.at("fixed").size(); ++i) {
            const std::string where = origin + ": fixed[" + std::to_string(i) + "]";
            FixedParameter fixed = parseFixed(doc.at("fixed").at(i), job.scene, where);
            if (!names.insert(fixed.parameter.name).second)
                throw InputError(where + ".name: \"" + fixed.parameter.name + "\" is searched or fixed twice");
            setParameter(job.scene, fixed.parameter, fixed.value);
            job.fixed.push_back(fixed);
        }
    }

    job.resolution = optionalInt(doc, "resolution", job.scene.domain.resolution, kMinResolution, origin, kMaxResolution);
    job.maxGenerations = optionalInt(doc, "max_generations", 80, 1, origin);
    job.seed = static_cast<std::uint64_t>(optionalInt(doc, "seed", 1, 0, origin));
    job.populationSize = optionalInt(doc, "population", 0, 0, origin, kMaxPopulation);
    if (job.populationSize == 1) throw InputError(origin + ": population: must be ≥ 2 (or 0 for the default)");
    job.toleranceX = optionalNumber(doc, "tolerance_x", job.toleranceX, origin);
    job.toleranceFun = optionalNumber(doc, "tolerance_fun", job.toleranceFun, origin);
    if (job.toleranceX < 0 || job.toleranceFun < 0) throw InputError(origin + ": tolerance_x/tolerance_fun: must be ≥ 0");
    job.timeBudget = optionalNumber(doc, "time_budget_s", 0.0, origin);
    if (job.timeBudget < 0) throw InputError(origin + ": time_budget_s: must be ≥ 0 (0 = no budget)");
    if (doc.contains("silhouette_method")) {
        const auto method = optionalString(doc, "silhouette_method", origin);
        if (*method != "fast" && *method != "exact")
            throw InputError(origin + ": silhouette_method: expected \"fast\" or \"exact\"");
        job.exactSilhouettes = *method == "exact";
    }
    for (auto [key, check] : {std::pair{"alignment_check", &job.alignmentCheck}, {"resolution_check", &job.resolutionCheck}})
        if (doc.contains(key)) {
            if (!doc.at(key).is_boolean()) throw InputError(origin + ": " + key + ": must be true or false");
            *check = doc.at(key).get<bool>();
        }
    // Placements by generation need a one-dimensional profile of E's mean over them; a search over
    // several parameters defaults to a single placement.
    const bool oneParameter = job.parameters.size() == 1;
    if (!oneParameter) {
        job.gridPlacements = 1;
        job.placementSchedule = PlacementSchedule::EachEvaluation;
    }
    job.gridPlacements = optionalInt(doc, "grid_placements", job.gridPlacements, 1, origin);
    if (job.gridPlacements > kMaxGridPlacements)
        throw InputError(origin + ": grid_placements: must be at most " + std::to_string(kMaxGridPlacements) +
                         ", got " + std::to_string(job.gridPlacements));
    if (const auto schedule = optionalString(doc, "grid_placement_schedule", origin)) {
        if (*schedule == placementScheduleName(PlacementSchedule::ByGeneration))
            job.placementSchedule = PlacementSchedule::ByGeneration;
        else if (*schedule == placementScheduleName(PlacementSchedule::EachEvaluation))
            job.placementSchedule = PlacementSchedule::EachEvaluation;
        else
            throw InputError(origin + ": grid_placement_schedule: expected \"each_evaluation\" or \"by_generation\", got \"" +
                             *schedule + "\"");
        if (job.placementSchedule == PlacementSchedule::ByGeneration && !oneParameter)
            throw InputError(origin + ": grid_placement_schedule: \"by_generation\" needs exactly one parameter, got " +
                             std::to_string(job.parameters.size()));
    }
    if (const auto comparison = optionalString(doc, "silhouette_comparison", origin))
        job.silhouetteComparison = parseSilhouetteComparison(*comparison, origin + ": silhouette_comparison");
    if (doc.contains("fidelity") && !doc.at("fidelity").is_null()) {
        const nlohmann::json& f = doc.at("fidelity");
        const std::string where = origin + ": fidelity";
        if (!f.is_object()) throw InputError(where + ": must be an object");
        rejectUnknownKeys(f, {"coarse_factor", "coarse_time_share", "coarse_generations", "min_fine_generations"},
                          where + ".");
        job.fidelity.coarseFactor = optionalNumber(f, "coarse_factor", job.fidelity.coarseFactor, where);
        if (job.fidelity.coarseFactor <= 0 || job.fidelity.coarseFactor > 1)
            throw InputError(where + ".coarse_factor: must be in (0, 1]");
        job.fidelity.coarseTimeShare = optionalNumber(f, "coarse_time_share", job.fidelity.coarseTimeShare, where);
        if (job.fidelity.coarseTimeShare <= 0 || job.fidelity.coarseTimeShare > 1)
            throw InputError(where + ".coarse_time_share: must be in (0, 1]");
        job.fidelity.coarseGenerations = optionalInt(f, "coarse_generations", -1, -1, where);
        job.fidelity.minFineGenerations = optionalInt(f, "min_fine_generations", job.fidelity.minFineGenerations, 1, where);
    }
    if (const auto model = optionalString(doc, "forward_model", origin)) {
        if (*model == "thin_film") job.forwardModel = ForwardModel::ThinFilm;
        else if (*model != "simulation")
            throw InputError(origin + ": forward_model: expected \"simulation\" or \"thin_film\", got \"" + *model + "\"");
    }
    if (job.forwardModel == ForwardModel::ThinFilm) requireFilmJob(job, doc, origin);
    if (const auto rheometer = optionalString(doc, "rheometer", origin)) job.rheometer = loadRheometer(resolve(baseDir, *rheometer));
    // Check the reference against the camera now, before any simulation.
    if (silhouettes) {
        const ReferenceManifest reference = loadReferenceManifest(job.referenceDir);
        if (reference.width != job.camera.width || reference.height != job.camera.height)
            throw InputError(job.cameraFile.string() + ": camera image is " + std::to_string(job.camera.width) + "x" +
                             std::to_string(job.camera.height) + ", reference masks in " + job.referenceDir.string() +
                             " are " + std::to_string(reference.width) + "x" + std::to_string(reference.height));
    }
    return job;
}

Job loadJob(const fs::path& file) {
    std::ifstream stream(file);
    if (!stream) throw InputError(file.string() + ": cannot open the job file");
    const nlohmann::json doc = parseJsonStrictly(stream, file.string());
    Job job;
    try {
        job = parseJob(doc, file.string(), file.parent_path());
    } catch (const nlohmann::json::exception& e) {
        throw InputError(file.string() + ": wrong field type (" + std::string(e.what()) + ")");
    }
    job.file = file;
    return job;
}

}  // namespace viscoscope::identify
