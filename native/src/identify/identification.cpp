// The identification loop: CMA-ES in log-parameter space, the population simulated in parallel
// (TBB), two fidelities, a checkpoint after every generation, resume, stopping rules and results.
//
// Fidelity policy (measured in tests/bench/identify_bench.cpp):
//   * generations [0, G_c) simulate on the grid r_c = max(8, round(coarse_factor · r)) and only the
//     first coarse_time_share of the compared clip (at least up to the third reference frame that
//     shows liquid: see firstPartOf), G_c = fidelity.coarse_generations, by default
//     min(⌊max_generations / 2⌋, 10), and always ≤ max_generations − 1 so at least one generation
//     runs at full fidelity (the job's resolution r, every compared frame);
//   * by default the coarse phase keeps the job's grid and shortens the clip to its first third.
//     A coarser grid is biased: on the sample scene the cup drained 1.5× too fast at 32³ (1.16×
//     since faces pass flux through their open area only; see kCoarseToFineShift), so its optimum
//     sat 25–35 % above the truth, while the first 20 of 60 frames at 48³ put the minimum at the
//     truth (E 0.031 at 9 and 0.032 at 10 Pa·s, truth 10) for about the cost of all 60 frames at
//     32³ (17 s against 14 s per evaluation, two at once);
//   * the coarse phase ends early once every log-space standard deviation σ√C_ii < 0.02 + 10·tol_x
//     (the coarse optimum differs from the full-fidelity one by more than that, so more coarse
//     generations are wasted),
//     or, with a time budget, once another coarse generation would end past kCoarseBudgetShare of it
//     or past the time the minimum full-fidelity generations are predicted to need;
//   * at the switch CMA-ES restarts at the best coarse evaluation with a log-space spread of
//     kCoarseToFineShift in every coordinate (counters and random stream go on), the first full
//     generation scores that point too, and the best-so-far is reset: E values of different
//     fidelities are not comparable. In one dimension with
//     λ = 4, CMA-ES needs more generations to shrink σ than a 10-minute run has (at 32³ σ went
//     0.8 → 1.0 → 0.55 in 10 generations), so the coarse phase locates the basin and the fine one
//     searches it, starting from the coarse best rather than from a mean that lags behind;
//   * in one dimension the first coarse generation scans instead of sampling: its λ points lie evenly
//     over the initial distribution's ±2σ₀ in log space (within the bounds), and CMA-ES restarts at
//     the best of them with half their spacing as spread. Sampled, the four points of one draw can
//     all miss a far optimum, and σ grows too slowly to make up for it within a budget: from the
//     table's common start (17.3 Pa·s, spread ln 4) the 300 Pa·s reference's search was still
//     climbing at 111 when its 600 s ran out. A caller's start curve is scanned the same way, in any
//     dimension, with the restart's spread along the curve (restartAlongScan);
//   * in one dimension each later full-fidelity generation scores, in place of a sample, the
//     vertex of the parabola through the best full-fidelity evaluation and its neighbours (see
//     parabolicProposal), clipped as an injected solution;
//   * tolerances are checked only at full fidelity, after fidelity.min_fine_generations there.
//
// θ*: the best full-fidelity evaluation. A parabola fitted to E (against 1/η; see fitProfile) over
// the evaluations near it gives the interval; its vertex is reported (profile_fit.theta_min) but not
// used as θ*. E(θ) carries a jitter of its own (a drop that pinches off one frame earlier), of ~10 %
// of E between neighbouring η, which the vertex would average out, but E is not a parabola: against
// a Blender-rendered 64³ reference at η = 10 it is flat from 7.5 to 10.3 and then jumps (0.18 → 0.27
// by 10.8), and the vertex fell at 8.2–8.9 in all four 48³ runs (10.8–17.7 % off) where the best
// evaluation was 0.8–8.1 % off. The vertex did better only on the small CI problems and an
// exact-rasterized reference (1.9 against 2.3 %, 2.1 against 8 %), and worse on another (2.8 against
// 0.5 %).
//
// With the grid placements taken by generation (the default), full-fidelity generations alternate
// between grids moved k/n cell sideways, each generation on one so that its candidates rank
// against each other fairly, and θ* is the lowest point of E's mean over the placements
// (placementMeanProfile), which also feeds the parabolic proposals and the profile fit. The mean
// takes out most of where the grid falls against the cup's hole: on the sample cup at η = 100 one
// placement identified 105.2 and two in turn 101.7, in as many evaluations.
#include "identify/search_state.h"

#include "sim/sim.h"
#include "surface/surface.h"

#include <iomanip>
#include <sstream>

namespace viscoscope::identify {

namespace fs = std::filesystem;
using json = nlohmann::json;

const char* toString(StopReason reason) {
    switch (reason) {
        case StopReason::MaxGenerations: return "max_generations";
        case StopReason::ToleranceX: return "tolerance_x";
        case StopReason::ToleranceFun: return "tolerance_fun";
        case StopReason::TimeBudget: return "time_budget";
        case StopReason::Cancelled: return "cancelled";
    }
    return "?";
}

namespace {

// Closer than this in ln θ (0.3 %), a parabolic proposal repeats an evaluation (see parabolicProposal).
constexpr double kProposalSpacing = 3e-3;

int coarseResolution(const Job& job) {
    return std::max(8, static_cast<int>(std::lround(job.fidelity.coarseFactor * job.resolution)));
}

int plannedCoarseGenerations(const Job& job, const Observation& obs, const Observation& coarseObs) {
    if (coarseResolution(job) >= job.resolution && lastSimFrame(coarseObs) >= lastSimFrame(obs)) return 0;
    int g = job.fidelity.coarseGenerations >= 0 ? job.fidelity.coarseGenerations
                                                : std::min(job.maxGenerations / 2, 10);
    return std::max(0, std::min(g, job.maxGenerations - 1));
}

// Does the camera see the initial liquid at all? A wrong camera fails here, before any simulation.
void requireCameraSeesLiquid(const Job& job, int resolution) {
    const Scene scene = sceneWithParameters(job, std::vector<double>(job.parameters.size(), 1.0), resolution);
    sim::Simulation simulation(scene);
    const auto& positions = simulation.particles().position;
    if (positions.empty()) return;  // emitters: nothing to check before the liquid appears
    const cv::Mat1b mask = silhouetteFromParticles(positions, scene.cellSize(), job.camera);
    if (silhouetteArea(mask) == 0)
        throw InputError(job.cameraFile.string() + ": the camera sees none of the liquid (" +
                         std::to_string(positions.size()) + " particles project outside the " +
                         std::to_string(job.camera.width) + "x" + std::to_string(job.camera.height) +
                         " image or lie behind the camera)");
}

// The first generation showed no liquid in any compared frame, though the camera sees the liquid at
// the start (requireCameraSeesLiquid): the cause lies in when the frames are compared or in θ's
// range more often than in the camera, so the message says what was compared.
std::string noSimulatedLiquidSeen(const Job& job, const Observation& obs, const std::vector<std::vector<double>>& thetas) {
    std::ostringstream text;
    text << std::setprecision(3) << job.file.string() << ": no simulated liquid shows in any compared frame for any θ"
         << " of the first generation (";
    for (size_t i = 0; i < job.parameters.size(); ++i) {
        double lo = INFINITY, hi = -INFINITY;
        for (const std::vector<double>& theta : thetas) lo = std::min(lo, theta[i]), hi = std::max(hi, theta[i]);
        text << (i ? ", " : "") << job.parameters[i].name() << " " << lo << "–" << hi;
    }
    text << "), though the camera sees the liquid at the start";
    std::vector<size_t> compared;
    for (size_t i = 0; i < obs.simFrames.size(); ++i)
        if (obs.simFrames[i] >= 0) compared.push_back(i);
    if (!compared.empty()) {
        const size_t first = compared.front(), last = compared.back();
        text << ": the clip's times " << obs.reference.times[first] << "–" << obs.reference.times[last] << " s at "
             << obs.reference.fps << " fps, with time_offset_s " << job.timeOffset << ", were compared with simulation"
             << " frames " << obs.simFrames[first] << "–" << obs.simFrames[last] << " at " << job.scene.fps << " fps";
    }
    const int pixels = job.camera.width * job.camera.height;
    const int comparedPixels = obs.compared.empty() ? pixels : cv::countNonZero(obs.compared);
    text << ", in " << comparedPixels << " of the image's " << pixels << " pixels (the rest excluded: the "
         << "container, ground_band, the background); check time_offset_s, the clip's fps, ground_band and the "
         << "parameters' bounds, then the camera";
    return text.str();
}

// The first generation's points when it scans (see the fidelity policy), in log space: `count` evenly
// along the caller's curve, or in one dimension evenly over ±2σ₀ around the start, within the bounds.
std::vector<Eigen::VectorXd> scanPoints(const LogSearchSpace& space, int count,
                                        const std::function<std::vector<double>(double)>& curve) {
    const double lo = std::max(space.lower[0], space.start[0] - 2 * space.spread[0]);
    const double hi = std::min(space.upper[0], space.start[0] + 2 * space.spread[0]);
    std::vector<Eigen::VectorXd> points;
    for (int k = 0; k < count; ++k) {
        const double s = double(k) / (count - 1);
        if (!curve) {
            points.push_back(Eigen::VectorXd::Constant(1, lo + (hi - lo) * s));
            continue;
        }
        const std::vector<double> theta = curve(s);
        if (theta.size() != size_t(space.start.size()))
            throw std::logic_error("identify: the start curve has " + std::to_string(theta.size()) +
                                   " parameters, the job searches " + std::to_string(space.start.size()));
        points.push_back(Eigen::Map<const Eigen::VectorXd>(theta.data(), space.start.size()).array().log().matrix());
    }
    return points;
}

// Where CMA-ES starts again after a scan (points in the curve's order): at the best point, its
// standard deviation along the chord through the best point's neighbours a quarter of that chord
// (half a step of an even scan), across it kAcrossScan of that. A diagonal spread as wide across
// as along put most samples off the curve, where E is high (FINDINGS, "One diagnosis of the sample
// cup").
constexpr double kAcrossScan = 0.5;
void restartAlongScan(CmaEs& es, const std::vector<Eigen::VectorXd>& xs, int best) {
    const int last = static_cast<int>(xs.size()) - 1, n = es.dimension();
    const Eigen::VectorXd chord = xs[std::min(best + 1, last)] - xs[std::max(best - 1, 0)];
    const double along = std::max(chord.norm() / (best == 0 || best == last ? 2 : 4), 1e-6);
    const Eigen::VectorXd u = chord.norm() > 0 ? Eigen::VectorXd(chord.normalized()) : Eigen::VectorXd::Unit(n, 0);
    const Eigen::MatrixXd alongOnly = u * u.transpose();
    const Eigen::MatrixXd across = Eigen::MatrixXd::Identity(n, n) - alongOnly;
    es.restartWithCovariance(xs[best], along * along * (alongOnly + kAcrossScan * kAcrossScan * across));
}

}  // namespace

IdentificationResult identify(const Job& jobIn, const fs::path& outDir, const IdentifyOptions& options) {
    if (jobIn.parameters.empty())
        throw InputError(jobIn.file.string() + ": parameters: nothing to search, every unknown is fixed (diagnose takes "
                         "such a job)");
    fs::create_directories(outDir);
    Job job = jobIn;
    prepareReference(job, outDir);
    const Observations observations = observe(job);
    const Observation& obs = observations.full;
    const size_t informativeFrames = informativeSimFrames(obs).size();
    std::vector<std::string> warnings;
    if (informativeFrames < size_t(kMinInformativeFrames)) {
        size_t compared = 0;
        for (int f : obs.simFrames) compared += f >= 0;
        warnings.push_back("reference: only " + std::to_string(informativeFrames) + " of " + std::to_string(compared) +
                           " compared frames show liquid outside the excluded region; every θ that keeps the "
                           "liquid out of sight fits as well, so the result is at best a lower bound (use a "
                           "longer clip)");
    }
    std::vector<std::string> doubts = doubtsBeforeSearch(obs);
    const auto warn = [&](const std::string& line) {
        if (options.onWarning) options.onWarning(line);
    };
    for (const std::string& line : warnings) warn(line);
    for (const std::string& line : doubts) warn(line);
    const int n = static_cast<int>(job.parameters.size());
    const LogSearchSpace bounds = logSearchSpace(job);
    const FidelityPlan plan{coarseResolution(job), job.resolution, lastSimFrame(observations.coarse), lastSimFrame(obs)};
    const double coarseTolerance = 0.02 + 10 * job.toleranceX;
    const Checkpoint checkpoint(job, outDir);
    const FieldsStore fields(outDir, checkpoint.fingerprint(), plan.fullFrames + 1);
    // The thin-film model has a radius, no 3D fields for Blender.
    const bool writeFields = options.writeFields && job.forwardModel == ForwardModel::Simulation;

    SearchState state = [&] {
        if (std::optional<SearchState> saved = checkpoint.load(job)) return std::move(*saved);
        CmaEsSettings settings;
        settings.populationSize = job.populationSize;
        SearchState fresh(CmaEs(bounds.start, bounds.spread, job.seed, settings));
        fresh.coarseEnd = plannedCoarseGenerations(job, obs, observations.coarse);
        const int firstResolution = fresh.coarseEnd > 0 ? plan.coarseResolution : plan.fullResolution;
        if (job.hasSilhouettes()) requireCameraSeesLiquid(job, firstResolution);
        for (const Job& run : job.otherRuns)
            if (run.hasSilhouettes()) requireCameraSeesLiquid(run, firstResolution);
        return fresh;
    }();
    CmaEs& es = state.es;

    std::optional<ThreadPool> ownPool;
    EvaluationPool& pool = options.pool ? *options.pool : ownPool.emplace(options.threads);
    const bool byGeneration = placementsByGeneration(job);
    const bool alignmentPlanned = job.alignmentCheck && n == 1;
    TimeBudget budget(job, state, plan, pool.concurrency(), alignmentPlanned);
    const auto save = [&] { checkpoint.save(state, budget.elapsed()); };

    // With placements by generation, full-fidelity generation g runs on the grid moved by
    // placementShift(g) cells, the job's placements in turn from the first one on.
    auto placementShift = [&](int g) {
        return byGeneration && g >= state.coarseEnd ? double((g - state.coarseEnd) % job.gridPlacements) / job.gridPlacements
                                                    : 0.0;
    };
    auto maxStd = [&] { return es.standardDeviations().maxCoeff(); };

    // In one dimension, later full-fidelity generations also score the vertex of the parabola
    // through the best full-fidelity evaluation and its nearest neighbours (bracketedVertex), in
    // place of their last sample; not when an evaluation lies within kProposalSpacing of it, since
    // the same θ scores the same E. With λ = 4 and a spread of ln 1.4, CMA-ES's samples mostly land
    // away from the optimum it brackets: on the η = 30 row, 5 of 16 full evaluations fell within
    // ±7 % and the best was 31.45 (4.8 %); with the proposals, 30.36 (1.2 %), itself a proposal.
    auto parabolicProposal = [&]() -> std::optional<Eigen::VectorXd> {
        const std::vector<std::pair<double, double>> points = fullFidelityProfile(job, state.evaluated);
        const std::optional<double> vertex = bracketedVertex(points, job.parameters[0].profileInInverse());
        if (!vertex) return std::nullopt;
        for (const auto& p : points)
            if (std::abs(std::log(*vertex / p.first)) < kProposalSpacing) return std::nullopt;
        return Eigen::VectorXd::Constant(1, std::log(*vertex));
    };

    while (!state.stop) {
        const int g = es.generation();
        if (g >= job.maxGenerations) {
            state.stop = StopReason::MaxGenerations;
            save();
            break;
        }
        if (budget.fullPhaseOver()) {
            state.stop = StopReason::TimeBudget;
            save();
            break;
        }
        const Fidelity fidelity = g < state.coarseEnd ? Fidelity::Coarse : Fidelity::Full;
        const bool coarse = fidelity == Fidelity::Coarse;
        const auto genStart = Clock::now();
        std::vector<Eigen::VectorXd> xs = es.ask();
        const bool scan = g == 0 && xs.size() > 1 && (options.startCurve || (coarse && n == 1));
        if (scan) xs = scanPoints(bounds, static_cast<int>(xs.size()), options.startCurve);
        // Where each point came from, recorded with its evaluation: a CMA-ES sample, a scan point,
        // or an injected restart point or parabolic proposal.
        std::vector<std::string> origins(xs.size(), scan ? "scan" : "sample");
        // The first full-fidelity generation also scores the restart point, the coarse best, in
        // place of its last sample: with λ = 4 draws of spread ln 1.4, all four can miss the basin
        // the coarse phase found (η = 30: coarse best 28.6, full samples 14.1 / 36.8 / 20.5 / 19.5).
        // An injected mean is a zero step for CMA-ES's update (Hansen 2011, "Injecting external
        // solutions into CMA-ES"), so nothing else changes.
        if (g == state.coarseEnd && state.coarseEnd > 0) {
            xs.back() = es.mean();
            origins.back() = "restart";
        } else if (!coarse && n == 1) {
            if (const std::optional<Eigen::VectorXd> proposal = parabolicProposal()) {
                xs.back() = es.injectable(*proposal);
                origins.back() = "parabola";
            }
        }
        const size_t sampled = xs.size();
        if (g == state.coarseEnd && !options.knownPoint.empty()) {
            if (options.knownPoint.size() != size_t(n))
                throw std::logic_error("identify: the known point has " + std::to_string(options.knownPoint.size()) +
                                       " parameters, the job searches " + std::to_string(n));
            xs.push_back(Eigen::Map<const Eigen::VectorXd>(options.knownPoint.data(), n).array().log().matrix());
            origins.push_back("known");
        }
        const bool stageFields = writeFields && !coarse;
        fields.clearStaging();
        EvaluationBatch batch{{}, coarse, plan.resolution(fidelity), placementShift(g), {}};
        for (size_t k = 0; k < xs.size(); ++k) {
            batch.thetas.push_back(thetaOf(xs[k], bounds));
            batch.fieldsDirs.push_back(stageFields ? fields.staged(k) : fs::path());
        }
        const BatchResult ran = [&] {
            try {
                return pool.evaluate(job, observations, batch);
            } catch (const Cancelled&) {
                throw Cancelled("identification cancelled in generation " + std::to_string(g + 1) +
                                "; a resume redoes it from the checkpoint");
            }
        }();
        const std::vector<Evaluation>& evals = ran.evaluations;
        if (g == 0 && job.hasSilhouettes()) {
            double pixels = 0;
            for (const Evaluation& e : evals) pixels += e.simulatedPixels;
            if (pixels == 0)
                throw InputError(noSimulatedLiquidSeen(job, coarse ? observations.coarse : obs, batch.thetas));
        }
        std::vector<double> fitness(xs.size());
        int bestK = 0;
        for (size_t k = 0; k < xs.size(); ++k) {
            fitness[k] = std::isfinite(evals[k].E) ? evals[k].E + boundPenalty(xs[k], bounds) : 1e30;
            if (fitness[k] < fitness[bestK]) bestK = static_cast<int>(k);
            EvaluationRecord record{evals[k], g + 1, fidelity, plan.frames(fidelity),
                                    std::vector<double>(xs[k].data(), xs[k].data() + xs[k].size()),
                                    origins[k], batch.gridShift, ran.errors[k], std::nullopt};
            if (!ran.ranks.empty()) record.rank = ran.ranks[k];
            state.evaluated.push_back(std::move(record));
        }
        if (stageFields) {
            // The new best full-fidelity evaluation, if this generation made it, keeps its fields.
            const std::optional<BestPoint> best = bestAt(job, state.evaluated, Fidelity::Full);
            for (size_t k = 0; k < xs.size(); ++k)
                if (best && best->theta == evals[k].theta && best->gridShift == batch.gridShift && evals[k].fields)
                    fields.promote(k, evals[k], batch.gridShift);
            fields.clearStaging();
        }
        es.tell({xs.begin(), xs.begin() + sampled}, {fitness.begin(), fitness.begin() + sampled});
        if (scan) restartAlongScan(es, xs, bestK);
        const double genSeconds = std::chrono::duration<double>(Clock::now() - genStart).count();
        budget.addGeneration(fidelity, genSeconds);
        const std::optional<BestPoint> best = bestAt(job, state.evaluated, fidelity);
        const Eigen::VectorXd sd = es.standardDeviations();
        GenerationRecord generation;
        generation.generation = g + 1;
        generation.fidelity = fidelity;
        generation.resolution = batch.resolution;
        generation.gridShift = batch.gridShift;
        generation.generationBestE = evals[bestK].E;
        generation.generationBestTheta = evals[bestK].theta;
        if (best) generation.bestTheta = best->theta, generation.bestE = best->E;
        generation.meanTheta = thetaOf(es.mean(), bounds);
        generation.sigma = es.sigma();
        generation.logStd.assign(sd.data(), sd.data() + sd.size());
        generation.evaluations = es.evaluations();
        generation.seconds = genSeconds;
        state.generations.push_back(generation);

        // Phase switch and stopping rules, decided before the checkpoint so a resume agrees.
        const int done = es.generation();
        if (coarse && done < state.coarseEnd && (maxStd() < coarseTolerance || budget.coarsePhaseOver()))
            state.coarseEnd = done;
        if (coarse && done == state.coarseEnd) {
            GenerationRecord& last = state.generations.back();
            last.predictedFineGenerationSeconds = budget.fineGenerationSeconds();  // to check it later
            // The minimum full-fidelity generations run whatever the budget says; when they cannot
            // fit (η = 300 on a 180-frame clip: 2 × 339 s predicted with 440 s left), say so now
            // and how long the run will take, instead of a remaining time that runs out early.
            const double fineMinimum = job.fidelity.minFineGenerations * budget.fineGenerationSeconds();
            const double elapsed = budget.elapsed();
            if (job.timeBudget > 0 && elapsed + fineMinimum > job.timeBudget) {
                last.warning = "time_budget_s: the " + std::to_string(job.fidelity.minFineGenerations) +
                               " full-fidelity generations every run makes are predicted to take " +
                               wholeSeconds(fineMinimum) + " s with " +
                               wholeSeconds(std::max(0.0, job.timeBudget - elapsed)) + " s of the " +
                               wholeSeconds(job.timeBudget) + " s budget left; the run will end after about " +
                               wholeSeconds(elapsed + fineMinimum) +
                               " s (a shorter clip or a coarser grid takes less)";
                warn(last.warning);  // the result gathers it from the history, after a resume too
            }
            Eigen::VectorXd start = es.mean();
            if (const std::optional<BestPoint> coarseBest = bestAt(job, state.evaluated, Fidelity::Coarse))
                for (int i = 0; i < n; ++i) start[i] = std::log(coarseBest->theta[i]);
            es.restart(start, Eigen::VectorXd::Constant(n, kCoarseToFineShift));
        }
        const int fineDone = done - state.coarseEnd;
        if (!coarse && fineDone >= job.fidelity.minFineGenerations) {
            if (maxStd() < job.toleranceX) {
                state.stop = StopReason::ToleranceX;
            } else if (fineDone >= 10) {
                double lo = INFINITY, hi = -INFINITY;
                for (auto it = state.generations.end() - 10; it != state.generations.end(); ++it) {
                    lo = std::min(lo, it->generationBestE);
                    hi = std::max(hi, it->generationBestE);
                }
                if (hi - lo < job.toleranceFun) state.stop = StopReason::ToleranceFun;
            }
        }
        if (!state.stop && done >= job.maxGenerations) state.stop = StopReason::MaxGenerations;
        save();

        if (options.onGeneration) {
            GenerationReport report;
            report.generation = done;
            report.generations = job.maxGenerations;
            report.evaluations = es.evaluations();
            report.resolution = batch.resolution;
            report.coarse = coarse;
            if (best) report.bestTheta = best->theta;
            report.bestE = best ? best->E : NAN;
            report.sigma = es.sigma();
            report.elapsed = budget.elapsed();
            report.remaining = budget.remaining(done, state.stop.has_value());
            report.resumed = state.resumedFrom > 0 && done == state.resumedFrom + 1;
            options.onGeneration(report);
        }
        if (!state.stop && cancelRequested())
            throw Cancelled("identification cancelled after generation " + std::to_string(done) + "; checkpoint saved");
    }

    // ---- Results.
    IdentificationResult result;
    result.stop = *state.stop;
    result.generations = es.generation();
    result.evaluations = es.evaluations();
    result.resumedFromGeneration = state.resumedFrom;
    std::optional<BestPoint> best = bestAt(job, state.evaluated, Fidelity::Full);
    if (!best) best = bestAt(job, state.evaluated, Fidelity::Coarse);
    if (!best) throw std::runtime_error("no successful evaluation");
    result.theta = best->theta;
    result.E = best->E;
    const Eigen::VectorXd sd = es.standardDeviations();
    json params = json::object();
    double alignmentCheckSeconds = 0;
    for (int i = 0; i < n; ++i) {
        const double bestTheta = result.theta[i];
        const double lower = std::exp(bounds.lower[i]), upper = std::exp(bounds.upper[i]);
        // The final search distribution: exp(m ± 2σ√C_ii) (a 95 % band of CMA-ES's sampling law in log
        // space, the spread it still considers plausible; not a statistical confidence interval).
        const std::array<double, 2> cma{std::clamp(std::exp(es.mean()[i] - 2 * sd[i]), lower, upper),
                                        std::clamp(std::exp(es.mean()[i] + 2 * sd[i]), lower, upper)};
        json entry{{"unit", job.parameters[i].parameter.declaration->unit},
                   {"best_evaluation", bestTheta},
                   {"cma_mean", std::exp(es.mean()[i])},
                   {"cma_interval", cma},
                   {"log_std", sd[i]}};
        std::optional<ProfileFit> profile;
        if (n == 1) {
            json info;
            profile = fitProfile(fullFidelityProfile(job, state.evaluated), bestTheta, 0.5,
                                 job.parameters[i].profileInInverse(), info);
            // A vertex beyond the fitted points is an extrapolation, and so is its band (measured: a
            // vertex at 5.1 over points up to 2.87 gave [2.82, 7.7] for a truth of 3).
            if (profile && !profile->vertexAmongPoints) profile.reset();
            entry["profile_fit"] = info;
            if (profile) entry["profile_interval"] = {profile->interval[0], std::min(profile->interval[1], upper)};
        }
        entry["value"] = bestTheta;
        // The reported interval: the profile band when the fit is convex with its vertex among the
        // points, else the CMA band; always widened to contain θ*, and by the alignment check.
        std::array<double, 2> band = profile ? profile->interval : cma;
        std::optional<double> alignmentSpread;  // |ln(θ_s/θ*)|
        if (alignmentPlanned) {
            const AlignmentOutcome check =
                alignmentCheck(job, pool, observations, state, profile, bestTheta, budget, save);
            entry["alignment_check"] = check.entry;
            alignmentSpread = check.spread;
            alignmentCheckSeconds += check.seconds;
            if (check.warning) {
                warnings.push_back(*check.warning);
                warn(*check.warning);
            }
        }
        if (alignmentSpread) {
            band[0] = std::min(band[0], bestTheta * std::exp(-*alignmentSpread));
            band[1] = std::max(band[1], bestTheta * std::exp(*alignmentSpread));
        }
        band[0] = std::max(std::min(band[0], bestTheta), lower);
        band[1] = std::min(std::max(band[1], bestTheta), upper);
        entry["interval"] = band;
        std::string method = profile ? "profile: parabola fit of E against 1/η (ln θ for other parameters) "
                                       "over full-fidelity evaluations within ±0.5 in ln θ of the best "
                                       "one, band where it is within ΔE = max(2·jitter, 1 % E_min) "
                                       "of its minimum"
                                     : "cma: exp(m ± 2σ√C_ii) of the final CMA-ES distribution in log space";
        if (alignmentSpread)
            method += "; alignment: widened to θ*·exp(±|ln(θ_s/θ*)|), θ_s the minimum on the grid moved along x "
                      "and y by half a cell, or half the spacing of the grid placements (alignment_check)";
        entry["interval_method"] = method;
        result.interval.push_back(band);
        if (i == 0) result.intervalMethod = std::string(profile ? "profile" : "cma") + (alignmentSpread ? "+alignment" : "");
        params[job.parameters[i].name()] = entry;
    }
    const double elapsed = budget.elapsed();

    for (const GenerationRecord& g : state.generations)
        if (!g.warning.empty()) warnings.push_back(g.warning);
    for (const std::string& line : doubtsAfterSearch(job, bounds, result.interval, state.evaluated)) {
        warn(line);
        doubts.push_back(line);
    }
    warnings.insert(warnings.end(), doubts.begin(), doubts.end());
    json fixedParameters = json::object();
    for (const FixedParameter& f : job.fixed)
        fixedParameters[f.parameter.name] = {
            {"value", f.value}, {"uncertainty", f.uncertainty}, {"unit", f.parameter.declaration->unit}};
    json evaluated = json::array(), history = json::array();
    for (const EvaluationRecord& e : state.evaluated) evaluated.push_back(toJson(e));
    for (const GenerationRecord& g : state.generations) history.push_back(toJson(g));
    const std::string coarseEnd = std::to_string(state.coarseEnd);
    json doc{{"format", "viscoscope.identify_result"},
             {"version", 1},
             {"job", job.file.string()},
             {"parameters", params},
             {"fixed", fixedParameters},
             {"E", result.E},
             {"stop", toString(result.stop)},
             {"generations", result.generations},
             {"evaluations", result.evaluations},
             {"population", es.lambda()},
             {"resolution", plan.fullResolution},
             {"frames", plan.fullFrames},
             {"grid_placements", job.gridPlacements},
             {"coarse_resolution", plan.coarseResolution},
             {"coarse_frames", plan.coarseFrames},
             {"coarse_generations", state.coarseEnd},
             {"fidelity_policy", "generations 1.." + coarseEnd + " at resolution " +
                                     std::to_string(plan.coarseResolution) + " over simulation frames 0.." +
                                     std::to_string(plan.coarseFrames) + ", the rest at " +
                                     std::to_string(plan.fullResolution) + " over 0.." +
                                     std::to_string(plan.fullFrames) +
                                     (byGeneration ? "; full-fidelity generations on the " +
                                                         std::to_string(job.gridPlacements) +
                                                         " grid placements in turn, θ* the minimum of E's mean over them"
                                                   : std::string("; θ* is the best full-fidelity evaluation"))},
             {"resumed_from_generation", state.resumedFrom},
             {"reference_informative_frames", informativeFrames},
             {"ground_band_m", job.groundBand},
             {"warnings", warnings},
             {"doubts", doubts},
             {"compared_pixels",
              {{"left_out_never_visible", obs.neverVisiblePixels},
               {"left_out_liquid_in_background", obs.inBackgroundPixels},
               {"reference_liquid_out_of_view_share", obs.referenceOutOfView}}},
             {"history", history},
             {"evaluated", evaluated},
             {"timings", timingsOf(state.evaluated, elapsed, alignmentCheckSeconds)}};
    if (params.contains("viscosity")) doc["viscosity"] = params["viscosity"];
    // With several runs, how well θ* fits each: its evaluation's E per run, on the placement its
    // fields come from.
    for (const EvaluationRecord& e : state.evaluated)
        if (!e.evaluation.runE.empty() && e.theta() == best->theta && e.gridShift == best->gridShift) {
            doc["run_E"] = e.evaluation.runE;
            break;
        }
    if (writeFields) doc["fields"] = fields.keep(job, obs, *best, plan.fullResolution);
    writeEvaluationsCsv(job, state.evaluated, outDir / "evaluations.csv");
    result.seconds = elapsed;
    result.document = doc;
    writeJsonAtomically(doc, outDir / "result.json");
    return result;
}
}  // namespace viscoscope::identify
