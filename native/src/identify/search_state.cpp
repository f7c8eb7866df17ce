// The search's records as JSON, the checkpoint, and the best evaluation so far.
#include "identify/search_state.h"

#include "scene/digest.h"

#include <algorithm>
#include <fstream>

namespace viscoscope::identify {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// Version 2 tags every evaluation with its fidelity (version 1 told them apart by resolution);
// version 3 adds the silhouettes' area track to E by default; version 4 is sealed (digest.h);
// version 5 gives every evaluation its grid shift.
constexpr int kCheckpointVersion = 5;

double finiteOrInfinite(const json& value) { return value.is_null() ? INFINITY : value.get<double>(); }

Fidelity fidelityFromName(const json& name) {
    if (name == fidelityName(Fidelity::Coarse)) return Fidelity::Coarse;
    if (name == fidelityName(Fidelity::Full)) return Fidelity::Full;
    throw std::runtime_error("unknown fidelity " + name.dump());
}

std::string fingerprintOf(const Job& job) {
    // A digest of the job document and the resolved inputs that change E.
    // Settings that change neither E nor the CMA-ES state may differ between runs of one job (the
    // rheometer's curve is only compared with the flow curve found).
    json doc = job.document;
    for (const char* key : {"max_generations", "tolerance_x", "tolerance_fun", "time_budget_s", "rheometer"}) doc.erase(key);
    doc["_scene"] = sceneToJson(job.scene);
    doc["_camera"] = cameraToJson(job.camera);
    doc["_reference"] = job.referenceDir.string();
    doc["_reference_source"] = referenceSource(job);
    if (job.measuredTrack) doc["_measured_track"] = {job.measuredTrack->data.time, job.measuredTrack->data.values};
    // Their defaults may change between engine versions:
    doc["_silhouette_comparison"] = silhouetteComparisonName(job.silhouetteComparison);
    doc["_silhouette_method"] = job.exactSilhouettes ? "exact" : "fast";
    doc["_grid_placements"] = job.gridPlacements;
    doc["_grid_placement_schedule"] = placementScheduleName(job.placementSchedule);
    for (const Job& run : job.otherRuns) doc["_runs"].push_back(fingerprintOf(run));
    return Digest().add(doc.dump()).hex();
}

}  // namespace

json finiteOrNull(double value) { return std::isfinite(value) ? json(value) : json(); }

const char* fidelityName(Fidelity fidelity) { return fidelity == Fidelity::Coarse ? "coarse" : "full"; }

json toJson(const EvaluationRecord& record) {
    json doc = toJson(record.evaluation);
    doc.update({{"generation", record.generation},
                {"fidelity", fidelityName(record.fidelity)},
                {"frames", record.frames},
                {"x", record.x},
                {"origin", record.origin},
                {"grid_shift", record.gridShift}});
    if (!record.error.empty()) doc["error"] = record.error;
    if (record.rank) doc["rank"] = *record.rank;
    return doc;
}

EvaluationRecord evaluationRecordFromJson(const json& doc) {
    EvaluationRecord record;
    record.evaluation = evaluationFromJson(doc);
    record.generation = doc.at("generation").get<int>();
    record.fidelity = fidelityFromName(doc.at("fidelity"));
    record.frames = doc.at("frames").get<int>();
    record.x = doc.at("x").get<std::vector<double>>();
    record.origin = doc.at("origin").get<std::string>();
    record.gridShift = doc.at("grid_shift").get<double>();
    record.error = doc.value("error", "");
    if (doc.contains("rank")) record.rank = doc.at("rank").get<int>();
    return record;
}

json toJson(const GenerationRecord& record) {
    json doc{{"generation", record.generation},
             {"fidelity", fidelityName(record.fidelity)},
             {"resolution", record.resolution},
             {"grid_shift", record.gridShift},
             {"generation_best_E", finiteOrNull(record.generationBestE)},
             {"generation_best_theta", record.generationBestTheta},
             {"best_E", record.bestTheta.empty() ? json() : json(record.bestE)},
             {"best_theta", record.bestTheta.empty() ? json() : json(record.bestTheta)},
             {"mean_theta", record.meanTheta},
             {"sigma", record.sigma},
             {"log_std", record.logStd},
             {"evaluations", record.evaluations},
             {"seconds", record.seconds}};
    if (record.predictedFineGenerationSeconds) doc["predicted_fine_generation_s"] = *record.predictedFineGenerationSeconds;
    if (!record.warning.empty()) doc["warning"] = record.warning;
    return doc;
}

GenerationRecord generationRecordFromJson(const json& doc) {
    GenerationRecord record;
    record.generation = doc.at("generation").get<int>();
    record.fidelity = fidelityFromName(doc.at("fidelity"));
    record.resolution = doc.at("resolution").get<int>();
    record.gridShift = doc.at("grid_shift").get<double>();
    record.generationBestE = finiteOrInfinite(doc.at("generation_best_E"));
    record.generationBestTheta = doc.at("generation_best_theta").get<std::vector<double>>();
    if (!doc.at("best_E").is_null()) {
        record.bestTheta = doc.at("best_theta").get<std::vector<double>>();
        record.bestE = doc.at("best_E").get<double>();
    }
    record.meanTheta = doc.at("mean_theta").get<std::vector<double>>();
    record.sigma = doc.at("sigma").get<double>();
    record.logStd = doc.at("log_std").get<std::vector<double>>();
    record.evaluations = doc.at("evaluations").get<long>();
    record.seconds = doc.at("seconds").get<double>();
    if (doc.contains("predicted_fine_generation_s"))
        record.predictedFineGenerationSeconds = doc.at("predicted_fine_generation_s").get<double>();
    record.warning = doc.value("warning", "");
    return record;
}

Checkpoint::Checkpoint(const Job& job, const fs::path& outDir)
    : file_(outDir / "checkpoint.json"), fingerprint_(fingerprintOf(job)) {}

std::optional<SearchState> Checkpoint::load(const Job& job) const {
    if (!fs::exists(file_)) return std::nullopt;
    json cp;
    try {
        std::ifstream stream(file_);
        cp = json::parse(stream);
    } catch (const std::exception& e) {
        throw InputError(file_.string() + ": unreadable checkpoint (" + e.what() + "); delete it or use another --out");
    }
    const json version = cp.is_object() ? cp.value("version", json()) : json();
    if (version != json(kCheckpointVersion))
        throw InputError(file_.string() + ": checkpoint of another Viscoscope (version " + version.dump() +
                         "); delete it or use another --out");
    if (!sealIsIntact(cp))
        throw InputError(file_.string() + ": damaged or edited checkpoint (its content_digest does not match its "
                                          "content); delete it or use another --out");
    if (cp.value("fingerprint", "") != fingerprint_)
        throw InputError(file_.string() + ": checkpoint of a different job (or changed scene, camera, reference); "
                                          "use another --out or delete it");
    SearchState state(CmaEs::fromJson(cp.at("cma")));
    state.coarseEnd = cp.at("coarse_end").get<int>();
    for (const json& e : cp.at("evaluated")) state.evaluated.push_back(evaluationRecordFromJson(e));
    for (const json& g : cp.at("generations")) state.generations.push_back(generationRecordFromJson(g));
    state.elapsedBefore = cp.at("elapsed_s").get<double>();
    for (auto [key, scores] : {std::pair{"alignment_check", &state.alignment}, {"resolution_check", &state.resolution}})
        if (const json& a = cp.value(key, json()); !a.is_null())
            *scores = CheckScores{a.at("theta").get<std::array<double, 2>>(),
                                  {finiteOrInfinite(a.at("E")[0]), finiteOrInfinite(a.at("E")[1])},
                                  a.at("errors").get<std::vector<std::string>>()};
    if (const json& s = cp.at("stop"); !s.is_null()) {
        for (StopReason r : {StopReason::MaxGenerations, StopReason::ToleranceX, StopReason::ToleranceFun,
                             StopReason::Resolved, StopReason::TimeBudget})
            if (s == toString(r)) state.stop = r;
        // A finished run continues when max_generations or the time budget was raised.
        if (state.stop == StopReason::MaxGenerations && state.es.generation() < job.maxGenerations) state.stop.reset();
        if (state.stop == StopReason::TimeBudget) state.stop.reset();  // decided again with this job's budget
    }
    state.resumedFrom = state.es.generation();
    return state;
}

void Checkpoint::save(const SearchState& state, double elapsed) const {
    json evaluated = json::array(), generations = json::array();
    for (const EvaluationRecord& e : state.evaluated) evaluated.push_back(toJson(e));
    for (const GenerationRecord& g : state.generations) generations.push_back(toJson(g));
    const auto checkJson = [](const std::optional<CheckScores>& scores) {
        return scores ? json{{"theta", scores->theta},
                             {"E", {finiteOrNull(scores->E[0]), finiteOrNull(scores->E[1])}},
                             {"errors", scores->errors}}
                      : json();
    };
    json cp{{"format", "viscoscope.identify_checkpoint"},
            {"version", kCheckpointVersion},
            {"fingerprint", fingerprint_},
            {"cma", state.es.toJson()},
            {"coarse_end", state.coarseEnd},
            {"evaluated", evaluated},
            {"generations", generations},
            {"elapsed_s", elapsed},
            {"stop", state.stop ? json(toString(*state.stop)) : json()},
            {"alignment_check", checkJson(state.alignment)},
            {"resolution_check", checkJson(state.resolution)}};
    writeJsonAtomically(sealed(cp), file_);
}

bool placementsByGeneration(const Job& job) {
    return job.placementSchedule == PlacementSchedule::ByGeneration && job.gridPlacements > 1 && job.parameters.size() == 1;
}

std::vector<std::pair<double, double>> fullFidelityProfile(const Job& job, const std::vector<EvaluationRecord>& evaluated,
                                                          int lastGeneration) {
    std::vector<PlacedPoint> points;
    for (const EvaluationRecord& e : evaluated)
        if (e.fidelity == Fidelity::Full && e.succeeded() && e.generation <= lastGeneration)
            points.push_back({e.theta()[0], e.E(), e.gridShift});
    if (placementsByGeneration(job)) return placementMeanProfile(points, job.parameters[0].profileInInverse());
    std::vector<std::pair<double, double>> plain;
    for (const PlacedPoint& p : points) plain.emplace_back(p.theta, p.E);
    return plain;
}

std::optional<BestPoint> bestAt(const Job& job, const std::vector<EvaluationRecord>& evaluated, Fidelity fidelity) {
    if (placementsByGeneration(job) && fidelity == Fidelity::Full) {
        const std::vector<std::pair<double, double>> profile = fullFidelityProfile(job, evaluated);
        const auto lowest = std::min_element(profile.begin(), profile.end(),
                                             [](const auto& a, const auto& b) { return a.second < b.second; });
        if (lowest == profile.end()) return std::nullopt;
        // The placement θ* was first evaluated on, where its fields come from.
        const auto first = std::find_if(evaluated.begin(), evaluated.end(), [&](const EvaluationRecord& e) {
            return e.fidelity == Fidelity::Full && e.theta()[0] == lowest->first;
        });
        return BestPoint{{lowest->first}, lowest->second, first == evaluated.end() ? 0.0 : first->gridShift};
    }
    const EvaluationRecord* lowest = nullptr;
    for (const EvaluationRecord& e : evaluated)
        if (e.fidelity == fidelity && e.succeeded() && (!lowest || e.E() < lowest->E())) lowest = &e;
    if (!lowest) return std::nullopt;
    return BestPoint{lowest->theta(), lowest->E(), lowest->gridShift};
}

}  // namespace viscoscope::identify
