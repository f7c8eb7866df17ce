// One evaluation of the objective: θ → simulation at a resolution → per-frame liquid level set →
// silhouette through the camera → E = Σ_f ω_f E_f (+ a weighted scalar-track term).
#include "identify/identify.h"

#include "film/film.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>

namespace viscoscope::identify {

namespace fs = std::filesystem;

namespace {
// Tells a changed input file from the one used before: its size and time of last write (for a
// folder of images, each entry's).
nlohmann::json fileStamp(const fs::path& path) {
    auto stamp = [](const fs::path& p) {
        std::error_code error;
        const auto bytes = fs::is_regular_file(p, error) ? static_cast<long long>(fs::file_size(p, error)) : -1;
        const auto written = fs::last_write_time(p, error).time_since_epoch().count();
        return nlohmann::json{{"path", fs::absolute(p).string()}, {"bytes", bytes}, {"written", written}};
    };
    nlohmann::json result = stamp(path);
    std::error_code error;
    if (fs::is_directory(path, error)) {
        std::vector<fs::path> entries;
        for (const auto& entry : fs::directory_iterator(path, error)) entries.push_back(entry.path());
        std::sort(entries.begin(), entries.end());
        for (const fs::path& e : entries) result["entries"].push_back(stamp(e));
    }
    return result;
}

// Silhouette pixels inside the compared region C_f (all of them without one).
double comparedArea(const cv::Mat1b& mask, const cv::Mat1b& compared) {
    return silhouetteArea(compared.empty() ? mask : cv::Mat1b(mask & compared));
}

// The reference track's area at the times of the compared frames.
std::vector<double> referenceTrack(const Observation& obs) {
    size_t column = 0;
    while (obs.track->columns[column] != "area_px") ++column;
    std::vector<double> times;
    for (size_t i = 0; i < obs.simFrames.size(); ++i)
        if (obs.simFrames[i] >= 0) times.push_back(obs.reference.times[i]);
    return sampleTrack(*obs.track, column, times);
}

bool allZero(const std::vector<double>& values) {
    return std::all_of(values.begin(), values.end(), [](double v) { return v == 0; });
}

// A frame time counts as within a measured track's span up to this much outside it (s): a CSV's
// times carry a few significant digits (1/3 s written as 0.333333).
constexpr double kSpanTolerance = 1e-5;

// Without silhouettes the reference frames are the simulation frames (after frame 0) whose times
// lie within the measured track's span, each weighted 1.
ReferenceManifest framesOfMeasuredTrack(const Job& job) {
    const MeasuredTrack& track = *job.measuredTrack;
    ReferenceManifest frames;
    frames.directory = track.csv.parent_path();
    frames.source = track.csv.string();
    frames.fps = job.scene.fps;
    const double first = track.data.time.front() + job.timeOffset - kSpanTolerance,
                 last = track.data.time.back() + job.timeOffset + kSpanTolerance;
    const int firstFrame = std::max(1, static_cast<int>(std::ceil(first * job.scene.fps)));
    for (int f = firstFrame; f <= std::floor(last * job.scene.fps); ++f) {
        frames.frames.push_back(f);
        frames.times.push_back(f / job.scene.fps - job.timeOffset);
        frames.weights.push_back(1);
    }
    return frames;
}

// The measured track at the reference frames that are compared and lie within its span.
std::vector<double> measuredAtFrames(const MeasuredTrack& track, const Observation& obs) {
    std::vector<double> measured(obs.simFrames.size(), std::nan(""));
    for (size_t i = 0; i < obs.simFrames.size(); ++i) {
        const double t = obs.reference.times[i];
        if (obs.simFrames[i] >= 0 && t >= track.data.time.front() - kSpanTolerance &&
            t <= track.data.time.back() + kSpanTolerance)
            measured[i] = sampleTrack(track.data, track.column, {t}).front();
    }
    return measured;
}

// The simulated counterpart of a measured track's value.
double simulatedObservable(const MeasuredTrack& track, const sim::Simulation& simulation, double groundHeight) {
    const GroundObservables ground{groundHeight, track.band};
    const auto& particles = simulation.particles().position;
    if (track.observable == TrackObservable::Front)
        return frontAlongGround(particles, track.origin, track.direction, ground);
    return puddleDiameter(particles, track.origin, ground) / 2;
}

// The liquid the camera sees at the start, before it moves: the same for every θ.
cv::Mat1b initialSilhouette(const Job& job, const SceneVisibility& view) {
    std::vector<double> theta;
    for (const ParameterSpec& p : job.parameters) theta.push_back(p.initial);
    const sim::Simulation simulation(sceneWithParameters(job, theta, job.resolution, 0));
    const auto levelSet = surface::liquidLevelSet(simulation);
    surface::clipToSolidExterior(*levelSet, simulation.solids());
    return silhouetteFromLevelSet(*levelSet, job.camera, &view);
}

bool hasSilhouettes(const Observation& obs) {
    return std::any_of(obs.masks.begin(), obs.masks.end(), [](const cv::Mat1b& m) { return !m.empty(); });
}

}  // namespace

nlohmann::json referenceSource(const Job& job) {
    if (!job.video) return nullptr;
    nlohmann::json source = {{"video", fileStamp(*job.video)},
                             {"extraction", extractionParameters(job.extraction)}};
    if (job.extraction.cleanPlate) source["clean_plate"] = fileStamp(*job.extraction.cleanPlate);
    if (job.extraction.excludeMask) source["exclude_mask"] = fileStamp(*job.extraction.excludeMask);
    return source;
}

void prepareReference(Job& job, const fs::path& outDir) {
    for (size_t k = 0; k < job.otherRuns.size(); ++k)
        prepareReference(job.otherRuns[k], outDir / ("run" + std::to_string(k + 1)));
    if (!job.referenceDir.empty() || !job.video) return;
    const fs::path dir = outDir / "reference", sourceFile = dir / "source.json";
    // Silhouettes extracted from another video, plate or settings are extracted again, not reused.
    const nlohmann::json source = referenceSource(job);
    nlohmann::json extractedFrom;
    if (std::ifstream stream(sourceFile); stream) extractedFrom = nlohmann::json::parse(stream, nullptr, false);
    if (extractedFrom != source || !fs::exists(dir / "manifest.json")) {
        fs::remove_all(dir);
        extractSilhouettes(*job.video, job.extraction, dir);
        writeJsonAtomically(source, sourceFile);
    }
    job.referenceDir = dir;
    const ReferenceManifest reference = loadReferenceManifest(dir);
    if (reference.width != job.camera.width || reference.height != job.camera.height)
        throw InputError(job.cameraFile.string() + ": camera image is " + std::to_string(job.camera.width) + "x" +
                         std::to_string(job.camera.height) + ", the video " + job.video->string() + " is " +
                         std::to_string(reference.width) + "x" + std::to_string(reference.height));
}

Observation loadObservation(const Job& job) {
    Observation obs;
    const bool silhouettes = job.hasSilhouettes();
    obs.reference = silhouettes ? loadReferenceManifest(job.referenceDir) : framesOfMeasuredTrack(job);
    const ReferenceManifest& ref = obs.reference;
    const std::string origin =
        silhouettes ? (job.referenceDir / "manifest.json").string() : job.measuredTrack->csv.string();
    if (silhouettes && (ref.width != job.camera.width || ref.height != job.camera.height))
        throw InputError(job.cameraFile.string() + ": camera image is " + std::to_string(job.camera.width) + "x" +
                         std::to_string(job.camera.height) + ", reference masks are " + std::to_string(ref.width) +
                         "x" + std::to_string(ref.height));
    obs.masks.resize(ref.frames.size());
    obs.simFrames.assign(ref.frames.size(), -1);
    int used = 0;
    for (size_t i = 0; i < ref.frames.size(); ++i) {
        if (ref.weights[i] <= 0 || ref.frames[i] - ref.frames.front() > job.lastSourceFrame) continue;
        if (job.maxFrames > 0 && used >= job.maxFrames) continue;
        const double t = ref.times[i] + job.timeOffset;
        if (!std::isfinite(t) || t < -1e-9) continue;  // before the simulation starts
        obs.simFrames[i] = static_cast<int>(std::lround(t * job.scene.fps));
        if (silhouettes) obs.masks[i] = ref.mask(i);
        ++used;
    }
    if (used == 0)
        throw InputError(origin + ": no reference frames to compare (all weights 0, or all outside the job's "
                                  "frame range / before the simulation starts)");
    if (silhouettes) {
        obs.view = sceneVisibility(job.scene, job.camera);
        const cv::Mat1b compared = excludeGroundBand(ref.comparedPixels(), job.camera, job.scene, job.groundBand);
        obs.referenceOutOfView = liquidOutOfViewShare(obs.masks, compared, obs.view);
        const ComparedRegion region =
            comparedRegion(compared, obs.view, backgroundFromFootage(ref) ? initialSilhouette(job, obs.view) : cv::Mat1b());
        obs.compared = region.compared;
        obs.neverVisiblePixels = region.neverVisible;
        obs.inBackgroundPixels = region.inBackground;
    }
    if (job.measuredTrack) {
        obs.measured = measuredAtFrames(*job.measuredTrack, obs);
        std::vector<double> compared;
        for (double m : obs.measured)
            if (std::isfinite(m)) compared.push_back(m);
        if (allZero(compared))
            throw InputError(job.measuredTrack->csv.string() +
                             ": the measured track is 0 (or outside the compared frames' times) at every compared "
                             "frame; nothing to match");
    }
    if (job.trackCsv) {
        obs.track = loadScalarTrackCsv(*job.trackCsv);
        obs.trackWeight = job.trackWeight;
        bool known = false;
        for (const std::string& column : obs.track->columns) known |= column == "area_px";
        if (!known) throw InputError(job.trackCsv->string() + ": needs an \"area_px\" column (silhouette area)");
        if (allZero(referenceTrack(obs)))
            throw InputError(job.trackCsv->string() + ": area_px is 0 at every compared frame; nothing to match");
    } else if (silhouettes && job.areaTrackWeight > 0 &&
               informativeSimFrames(obs).size() >= size_t(kMinInformativeFrames)) {
        // (A reference that hardly shows liquid has no area to match: the silhouettes alone decide.)
        ScalarTrack area{{"area_px"}, {}, {{}}};
        for (size_t i = 0; i < ref.frames.size(); ++i)
            if (obs.simFrames[i] >= 0) {
                area.time.push_back(ref.times[i]);
                area.values[0].push_back(comparedArea(obs.masks[i], obs.compared));
            }
        obs.track = area;
        obs.trackWeight = job.areaTrackWeight;
    }
    for (const Job& run : job.otherRuns) obs.otherRuns.push_back(loadObservation(run));
    return obs;
}

int lastSimFrame(const Observation& observation) {
    return std::max(0, *std::max_element(observation.simFrames.begin(), observation.simFrames.end()));
}

std::vector<int> informativeSimFrames(const Observation& observation) {
    std::vector<int> frames;
    if (!hasSilhouettes(observation)) {
        for (size_t i = 0; i < observation.measured.size(); ++i)
            if (observation.simFrames[i] >= 0 && observation.measured[i] > 0)
                frames.push_back(observation.simFrames[i]);
        std::sort(frames.begin(), frames.end());
        return frames;
    }
    const double comparedPixels = observation.compared.empty() ? 0.0 : cv::countNonZero(observation.compared);
    for (size_t i = 0; i < observation.simFrames.size(); ++i) {
        if (observation.simFrames[i] < 0 || observation.masks[i].empty()) continue;
        const double pixels = comparedArea(observation.masks[i], observation.compared);
        const double total = observation.compared.empty() ? double(observation.masks[i].total()) : comparedPixels;
        if (pixels > 0 && pixels >= kInformativePixelShare * total) frames.push_back(observation.simFrames[i]);
    }
    std::sort(frames.begin(), frames.end());
    return frames;
}

Observation firstPartOf(const Observation& observation, double share) {
    Observation part = observation;
    int first = -1;
    for (int f : observation.simFrames)
        if (f >= 0) first = first < 0 ? f : std::min(first, f);
    // A high-η clip may show nothing outside the (excluded) cup for its first third: there every θ
    // above the truth scores E = 0 and CMA-ES drifted to the upper bound (η = 100 on the sample scene,
    // whose reference first shows liquid at frame 24 of 60).
    const int last = lastSimFrame(observation);
    const std::vector<int> informative = informativeSimFrames(observation);
    const int informativeEnd =
        informative.size() >= size_t(kMinInformativeFrames) ? informative[kMinInformativeFrames - 1] : last;
    const double end = std::max<double>({double(first), share * last, double(informativeEnd)});
    for (size_t i = 0; i < part.simFrames.size(); ++i)
        if (part.simFrames[i] > end + 1e-9) {
            part.simFrames[i] = -1;
            part.masks[i] = cv::Mat1b();
            if (!part.measured.empty()) part.measured[i] = std::nan("");
        }
    // A measured track may stay 0 through the first part (the liquid not yet in view of the
    // measurement): it has no scale to normalize by there, and the silhouettes decide alone.
    if (part.track && allZero(referenceTrack(part))) part.track.reset();
    // So may the job's measured track; with silhouettes, they decide alone there too.
    const auto measures = [](double m) { return std::isfinite(m) && m != 0; };
    if (hasSilhouettes(part) && std::none_of(part.measured.begin(), part.measured.end(), measures))
        part.measured.clear();
    for (Observation& run : part.otherRuns) run = firstPartOf(run, share);
    return part;
}

Job reseeded(Job job, unsigned seedOffset) {
    job.scene.seed += seedOffset;
    for (Job& run : job.otherRuns) run.scene.seed += seedOffset;
    return job;
}

Scene sceneWithParameters(const Job& job, const std::vector<double>& theta, int resolution, double gridShift) {
    Scene scene = job.scene;
    for (size_t i = 0; i < job.parameters.size(); ++i) setParameter(scene, job.parameters[i].parameter, theta.at(i));
    scene.domain.resolution = resolution;
    const double shift = gridShift * scene.cellSize();
    for (int a = 0; a < 2; ++a) {
        scene.domain.min[a] += shift;
        scene.domain.max[a] += shift;
    }
    // Every evaluation uses the job's seed (common random numbers): E depends on θ and the
    // resolution only, never on which thread or in which order it ran.
    scene.seed = static_cast<unsigned>(job.seed);
    scene.outputs = Outputs{false, false, false};
    return scene;
}

namespace {

// The measured track's term: its relative error, and E's share of it.
void scoreMeasuredTrack(const Job& job, const std::vector<double>& simulated, const std::vector<double>& measured,
                        Evaluation& ev) {
    if (measured.empty()) return;
    ev.trackError = std::sqrt(normalizedSquaredError(simulated, measured));
    ev.E += job.measuredTrack->weight * *ev.trackError * *ev.trackError;
}

// θ on the thin-film model: its front radius at every compared frame, scored against the measured
// radius (the job has no silhouettes; parseJob checks).
Evaluation evaluateFilm(const Job& job, const Observation& obs, const std::vector<double>& theta, int resolution) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    Evaluation ev;
    ev.theta = theta;
    ev.resolution = resolution;
    film::AxisymmetricFilm film(sceneWithParameters(job, theta, resolution));
    const double fps = job.scene.fps;
    ev.frameE.assign(obs.simFrames.size(), 0.0);
    ev.trackSimulated.assign(obs.simFrames.size(), NAN);
    std::vector<double> simulated, measured;
    for (int frame = 0; frame <= lastSimFrame(obs); ++frame) {
        const auto frameStart = Clock::now();
        film.advanceTo(frame / fps);
        for (size_t i = 0; i < obs.measured.size(); ++i)
            if (obs.simFrames[i] == frame && std::isfinite(obs.measured[i])) {
                ev.trackSimulated[i] = film.frontRadius();
                simulated.push_back(ev.trackSimulated[i]);
                measured.push_back(obs.measured[i]);
            }
        ev.frameSeconds.push_back(std::chrono::duration<double>(Clock::now() - frameStart).count());
    }
    scoreMeasuredTrack(job, simulated, measured, ev);
    ev.seconds = ev.simulationSeconds = std::chrono::duration<double>(Clock::now() - start).count();
    return ev;
}

// One simulation of θ on the grid moved by `gridShift` cells, scored.
Evaluation evaluateOnGrid(const Job& job, const Observation& obs, const std::vector<double>& theta, int resolution,
                          const fs::path& fieldsDir, double gridShift) {
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::time_point from, Clock::time_point to) { return std::chrono::duration<double>(to - from).count(); };
    const auto start = Clock::now();
    Evaluation ev;
    ev.theta = theta;
    ev.resolution = resolution;
    const Scene scene = sceneWithParameters(job, theta, resolution, gridShift);
    const auto setupStart = Clock::now();
    sim::Simulation simulation(scene);
    ev.simulationSeconds += seconds(setupStart, Clock::now());
    const std::optional<double> ground = groundHeight(scene);
    const bool writeFields = !fieldsDir.empty();
    if (writeFields) {
        fs::create_directories(fieldsDir);
        ev.fields = FieldsSummary{};
    }
    double groundSpeedSum = 0;
    const int lastFrame = lastSimFrame(obs);
    const size_t count = obs.simFrames.size();
    ev.frameE.assign(count, 0.0);
    if (job.measuredTrack) ev.trackSimulated.assign(count, NAN);
    std::vector<double> areas(count, 0.0);
    // The measured track's simulated values, where it is compared.
    std::vector<double> trackSimulated, trackMeasured;
    const double trackGround = ground ? *ground : scene.domain.min.z();
    const bool silhouettes = hasSilhouettes(obs);
    // A searched solid moves with θ, and with it what the camera can see of the liquid.
    std::optional<SceneVisibility> searchedView;
    if (silhouettes && std::any_of(job.parameters.begin(), job.parameters.end(),
                                   [](const ParameterSpec& p) { return p.parameter.solid >= 0; }))
        searchedView = sceneVisibility(scene, job.camera);
    sim::LiquidLoss loss(simulation.liquidVolume());
    double dissipationWeight = 0, weightedLogShearRate = 0;
    for (int frame = 0; frame <= lastFrame; ++frame) {
        const auto simStart = Clock::now();
        if (frame > 0) {
            const sim::FrameStats stats = simulation.advanceFrame();
            ev.unconvergedFrames += stats.converged ? 0 : 1;
            ev.liquidLost = std::max(ev.liquidLost, loss.observe(stats.liquidVolume));
            if (stats.dissipationWeight > 0) {
                dissipationWeight += stats.dissipationWeight;
                weightedLogShearRate += stats.dissipationWeight * std::log(stats.shearRate);
                ev.frameShearRates.push_back(stats.shearRate);
            }
        }
        auto lap = Clock::now();
        ev.simulationSeconds += seconds(simStart, lap);
        const bool compared = std::find(obs.simFrames.begin(), obs.simFrames.end(), frame) != obs.simFrames.end();
        for (size_t i = 0; i < obs.measured.size(); ++i)
            if (obs.simFrames[i] == frame && std::isfinite(obs.measured[i])) {
                ev.trackSimulated[i] = simulatedObservable(*job.measuredTrack, simulation, trackGround);
                trackSimulated.push_back(ev.trackSimulated[i]);
                trackMeasured.push_back(obs.measured[i]);
            }
        if ((!compared || !silhouettes) && !writeFields) {
            ev.frameSeconds.push_back(seconds(simStart, lap));
            continue;
        }
        const auto levelSet = surface::liquidLevelSet(simulation);
        const auto built = Clock::now();
        (compared && silhouettes ? ev.silhouetteSeconds : ev.fieldsSeconds) += seconds(lap, built);
        lap = built;
        if (writeFields) {
            // Written before the clip below: Blender shows the container itself.
            char name[32];
            std::snprintf(name, sizeof name, "frame_%05d.vdb", frame);
            surface::writeFrameVdb(fieldsDir / name, simulation, levelSet);
            ++ev.fields->frames;
            if (ground && frame > 0) {
                double sum = 0;
                int onGround = 0;
                const sim::Particles& p = simulation.particles();
                for (size_t i = 0; i < p.position.size(); ++i)
                    if (p.position[i].z() < *ground + 2 * scene.cellSize()) {
                        sum += p.velocity[i].norm();
                        ++onGround;
                    }
                if (onGround > 0) {
                    groundSpeedSum += sum / onGround;
                    ++ev.fields->groundFrames;
                }
            }
            const auto written = Clock::now();
            ev.fieldsSeconds += seconds(lap, written);
            lap = written;
        }
        if (compared && silhouettes) {
            surface::clipToSolidExterior(*levelSet, simulation.solids());
            const SceneVisibility& view = searchedView ? *searchedView : obs.view;
            const cv::Mat1b silhouette = job.exactSilhouettes
                                             ? silhouetteFromLevelSet(*levelSet, job.camera, &view)
                                             : silhouetteFromLevelSetFast(*levelSet, job.camera, &view);
            for (size_t i = 0; i < count; ++i) {
                if (obs.simFrames[i] != frame) continue;
                ev.frameE[i] = frameObjective(silhouette, obs.masks[i], obs.compared, job.silhouetteComparison);
                areas[i] = comparedArea(silhouette, obs.compared);
                ev.simulatedPixels += areas[i];
                ev.E += obs.reference.weights[i] * ev.frameE[i];
            }
        }
        const auto frameEnd = Clock::now();
        ev.silhouetteSeconds += seconds(lap, frameEnd);
        ev.frameSeconds.push_back(seconds(simStart, frameEnd));
    }
    if (ev.fields && ev.fields->groundFrames > 0) ev.fields->meanGroundSpeed = groundSpeedSum / ev.fields->groundFrames;
    if (dissipationWeight > 0) ev.shearRate = std::exp(weightedLogShearRate / dissipationWeight);
    if (obs.track) {
        std::vector<double> simulated;
        for (size_t i = 0; i < count; ++i)
            if (obs.simFrames[i] >= 0) simulated.push_back(areas[i]);
        ev.E += obs.trackWeight * normalizedSquaredError(simulated, referenceTrack(obs));
    }
    scoreMeasuredTrack(job, trackSimulated, trackMeasured, ev);
    ev.seconds = seconds(start, Clock::now());
    return ev;
}

}  // namespace

Evaluation evaluate(const Job& job, const Observation& obs, const std::vector<double>& theta, int resolution,
                    const fs::path& fieldsDir, double gridShift) {
    // What another simulation of the same evaluation (a grid placement, a further run) adds: its
    // silhouette area, its doubts and its costs (per simulated frame, for the time budget's
    // prediction of a longer clip).
    const auto add = [](Evaluation& ev, const Evaluation& other) {
        ev.simulatedPixels += other.simulatedPixels;
        ev.liquidLost = std::max(ev.liquidLost, other.liquidLost);
        ev.unconvergedFrames += other.unconvergedFrames;
        ev.seconds += other.seconds;
        ev.simulationSeconds += other.simulationSeconds;
        ev.silhouetteSeconds += other.silhouetteSeconds;
        ev.fieldsSeconds += other.fieldsSeconds;
        if (other.frameSeconds.size() > ev.frameSeconds.size()) ev.frameSeconds.resize(other.frameSeconds.size(), 0.0);
        for (size_t i = 0; i < other.frameSeconds.size(); ++i) ev.frameSeconds[i] += other.frameSeconds[i];
    };
    const int n = job.placementSchedule == PlacementSchedule::EachEvaluation ? job.gridPlacements : 1;
    // The first placement is the grid as asked for, and only it writes the fields (a film has none).
    Evaluation ev = job.forwardModel == ForwardModel::ThinFilm
                        ? evaluateFilm(job, obs, theta, resolution)
                        : evaluateOnGrid(job, obs, theta, resolution, fieldsDir, gridShift);
    for (int k = 1; k < n; ++k) {
        const Evaluation other = evaluateOnGrid(job, obs, theta, resolution, {}, gridShift + double(k) / n);
        add(ev, other);
        ev.E += other.E;
        if (ev.trackError) ev.trackError = std::hypot(*ev.trackError, *other.trackError);
        for (size_t i = 0; i < ev.frameE.size(); ++i) ev.frameE[i] += other.frameE[i];
        for (size_t i = 0; i < ev.trackSimulated.size(); ++i) ev.trackSimulated[i] += other.trackSimulated[i];
    }
    ev.E /= n;
    ev.simulatedPixels /= n;
    if (ev.trackError) *ev.trackError /= std::sqrt(double(n));  // the RMS over the placements
    for (double& e : ev.frameE) e /= n;
    for (double& value : ev.trackSimulated) value /= n;
    if (!job.otherRuns.empty()) ev.runE = {ev.E};
    for (size_t k = 0; k < job.otherRuns.size(); ++k) {
        const Evaluation run = evaluate(job.otherRuns[k], obs.otherRuns.at(k), theta, resolution, {}, gridShift);
        add(ev, run);
        ev.runE.push_back(run.E);
        ev.E += run.E;
    }
    return ev;
}

}  // namespace viscoscope::identify
