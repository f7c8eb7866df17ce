// The identification loop: CMA-ES over forward simulations in log parameter space, two
// fidelities, checkpoints, resume and results (identification.cpp). Its own state is private to the
// stage (search_state.h).
#pragma once

#include "identify/cma_es.h"
#include "identify/evaluation.h"
#include "identify/job.h"

#include <nlohmann/json.hpp>

#include <array>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace viscoscope::identify {

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

enum class StopReason { MaxGenerations, ToleranceX, ToleranceFun, Resolved, TimeBudget, Cancelled };
const char* toString(StopReason reason);

struct IdentificationResult {
    std::vector<double> theta;
    std::vector<std::array<double, 2>> interval;
    std::string intervalMethod;
    // Several parameters: the evaluations' θ that E cannot tell from θ* (JointProfileFit).
    std::vector<std::vector<double>> indistinguishable;
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
    // θ scored beside the first full-fidelity generation's samples (not told to CMA-ES), so that
    // the search ends no worse than it: a diagnosis's candidate at its base-equivalent point.
    std::vector<double> knownPoint;
    // A curve θ(s), s ∈ [0, 1], near which the caller expects the minimum (a diagnosis's power law:
    // the (K, n) that flow as the base fit). When set, the first generation scans it in place of
    // CMA-ES's samples, as a one-parameter search scans its start (identification.cpp).
    std::function<std::vector<double>(double)> startCurve;
};

// Runs (or resumes from OUT/checkpoint.json) the identification and writes OUT/result.json,
// OUT/evaluations.csv. On a cancel request: abandons the evaluations in flight and throws Cancelled;
// the checkpoint of the last finished generation stays, and a resume redoes the abandoned ones
// (CMA-ES draws them again from its saved state). A checkpoint of a different job throws InputError.
IdentificationResult identify(const Job& job, const std::filesystem::path& outDir, const IdentifyOptions& options = {});

}  // namespace viscoscope::identify
