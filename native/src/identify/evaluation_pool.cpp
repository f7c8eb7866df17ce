// Where the loop's evaluations run: this process's threads (ThreadPool), and the JSON an
// evaluation and a batch travel as between MPI ranks (cli/mpi_ranks.cpp).
#include "identify/identify.h"

#include <openvdb/Exceptions.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <exception>
#include <mutex>
#include <optional>

namespace viscoscope::identify {

namespace fs = std::filesystem;
using json = nlohmann::json;

json toJson(const Evaluation& e) {
    json doc{{"theta", e.theta},
             {"resolution", e.resolution},
             {"E", std::isfinite(e.E) ? json(e.E) : json()},  // JSON has no infinity
             {"frame_E", e.frameE},
             {"simulated_pixels", e.simulatedPixels},
             {"liquid_lost", e.liquidLost},
             {"unconverged_frames", e.unconvergedFrames},
             {"seconds", e.seconds},
             {"simulation_s", e.simulationSeconds},
             {"silhouette_s", e.silhouetteSeconds},
             {"fields_s", e.fieldsSeconds},
             {"frame_s", e.frameSeconds}};
    if (e.trackError) doc["track_error"] = *e.trackError;
    if (e.shearRate) doc["shear_rate"] = *e.shearRate;
    if (!e.trackSimulated.empty()) {
        json& values = doc["track_simulated"] = json::array();
        for (double v : e.trackSimulated) values.push_back(std::isfinite(v) ? json(v) : json());
    }
    if (!e.runE.empty()) doc["run_E"] = e.runE;
    if (e.fields)
        doc["fields"] = {{"frames", e.fields->frames},
                         {"mean_ground_speed", e.fields->meanGroundSpeed},
                         {"ground_frames", e.fields->groundFrames}};
    return doc;
}

Evaluation evaluationFromJson(const json& doc) {
    Evaluation e;
    e.theta = doc.at("theta").get<std::vector<double>>();
    e.resolution = doc.at("resolution").get<int>();
    e.E = doc.at("E").is_null() ? INFINITY : doc.at("E").get<double>();
    e.frameE = doc.at("frame_E").get<std::vector<double>>();
    e.simulatedPixels = doc.at("simulated_pixels").get<double>();
    e.liquidLost = doc.at("liquid_lost").get<double>();
    e.unconvergedFrames = doc.at("unconverged_frames").get<int>();
    e.seconds = doc.at("seconds").get<double>();
    e.simulationSeconds = doc.at("simulation_s").get<double>();
    e.silhouetteSeconds = doc.at("silhouette_s").get<double>();
    e.fieldsSeconds = doc.at("fields_s").get<double>();
    e.frameSeconds = doc.at("frame_s").get<std::vector<double>>();
    if (doc.contains("track_error")) e.trackError = doc.at("track_error").get<double>();
    if (doc.contains("shear_rate")) e.shearRate = doc.at("shear_rate").get<double>();
    if (doc.contains("track_simulated"))
        for (const json& v : doc.at("track_simulated")) e.trackSimulated.push_back(v.is_null() ? NAN : v.get<double>());
    if (doc.contains("run_E")) e.runE = doc.at("run_E").get<std::vector<double>>();
    if (doc.contains("fields")) {
        const json& f = doc.at("fields");
        e.fields = FieldsSummary{f.at("frames").get<int>(), f.at("mean_ground_speed").get<double>(),
                                 f.at("ground_frames").get<int>()};
    }
    return e;
}

json EvaluationBatch::toJson() const {
    json dirs = json::array();
    for (const fs::path& dir : fieldsDirs) dirs.push_back(dir.string());
    return {{"thetas", thetas}, {"coarse", coarse}, {"resolution", resolution}, {"grid_shift", gridShift},
            {"fields_dirs", dirs}, {"seed_offset", seedOffset}};
}

EvaluationBatch EvaluationBatch::fromJson(const json& doc) {
    EvaluationBatch batch;
    batch.thetas = doc.at("thetas").get<std::vector<std::vector<double>>>();
    batch.coarse = doc.at("coarse").get<bool>();
    batch.resolution = doc.at("resolution").get<int>();
    batch.gridShift = doc.at("grid_shift").get<double>();
    for (const json& dir : doc.at("fields_dirs")) batch.fieldsDirs.emplace_back(dir.get<std::string>());
    batch.seedOffset = doc.at("seed_offset").get<unsigned>();
    return batch;
}

Observations observe(const Job& job) {
    Observations observations;
    observations.full = loadObservation(job);
    observations.coarse = firstPartOf(observations.full, job.fidelity.coarseTimeShare);
    return observations;
}

struct ThreadPool::Threads {
    std::optional<tbb::global_control> limit;
    std::unique_ptr<tbb::task_arena> arena;
};

ThreadPool::ThreadPool(int threads) : threads_(std::make_unique<Threads>()) {
    if (threads > 0)
        threads_->limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    const int concurrency = threads > 0 ? threads : int{tbb::task_arena::automatic};
    threads_->arena = std::make_unique<tbb::task_arena>(concurrency);
}

ThreadPool::~ThreadPool() = default;

int ThreadPool::concurrency() const { return threads_->arena->max_concurrency(); }

BatchResult ThreadPool::evaluate(const Job& asked, const Observations& observations, const EvaluationBatch& batch) {
    const Observation& observation = batch.coarse ? observations.coarse : observations.full;
    const std::optional<Job> reseededJob =
        batch.seedOffset != 0 ? std::optional<Job>(reseeded(asked, batch.seedOffset)) : std::nullopt;
    const Job& job = reseededJob ? *reseededJob : asked;
    const int count = static_cast<int>(batch.thetas.size());
    BatchResult result;
    result.evaluations.resize(count);
    result.errors.assign(count, "");
    // An exception leaving a TBB body cancels its whole task group, nested algorithms included:
    // OpenVDB's volumeToMesh in a sibling evaluation then returned a partial mesh and asked for
    // 24 GB (a cancel during a blender_addon CI run, killed by the OOM killer). So no body throws:
    // the first error that stops the run is kept and rethrown once every evaluation has returned
    // (on a cancel, each returns at its next poll of the same request).
    std::exception_ptr stop;
    std::mutex stopMutex;
    const auto keepStop = [&] {
        const std::lock_guard<std::mutex> lock(stopMutex);
        if (!stop) stop = std::current_exception();
    };
    threads_->arena->execute([&] {
        tbb::parallel_for(0, count, 1, [&](int k) {
            const fs::path fieldsDir = batch.fieldsDirs.empty() ? fs::path() : batch.fieldsDirs[k];
            try {
                result.evaluations[k] = identify::evaluate(job, observation, batch.thetas[k], batch.resolution,
                                                           fieldsDir, batch.gridShift);
            } catch (const InputError&) {
                keepStop();
            } catch (const Cancelled&) {
                keepStop();
            } catch (const OutputError&) {
                keepStop();  // a lost write stops the run: scored as a failed evaluation it would change the answer
            } catch (const fs::filesystem_error&) {
                keepStop();
            } catch (const openvdb::IoError&) {
                keepStop();  // the evaluation's own fields could not be read back
            } catch (const std::exception& e) {
                Evaluation& failed = result.evaluations[k];
                failed.theta = batch.thetas[k];
                failed.resolution = batch.resolution;
                failed.E = INFINITY;
                result.errors[k] = e.what();
            }
        });
    });
    if (stop) std::rethrow_exception(stop);
    return result;
}

}  // namespace viscoscope::identify
