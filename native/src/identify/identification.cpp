// The identification loop: CMA-ES in log-parameter space, the population simulated in parallel
// (TBB), two fidelities, a checkpoint after every generation, resume, stopping rules and results.
//
// Fidelity policy (measured with tests/bench/identify_bench.cpp; the figures in
// tests/bench/FINDINGS.md, "Figures moved from code comments" and "The profile interval"):
//   * generations [0, G_c) simulate on the grid r_c = max(8, round(coarse_factor · r)) and only the
//     first coarse_time_share of the compared clip (at least up to the third reference frame that
//     shows liquid: see firstPartOf), G_c = fidelity.coarse_generations, by default
//     min(⌊max_generations / 2⌋, 10), and always ≤ max_generations − 1 so at least one generation
//     runs at full fidelity (the job's resolution r, every compared frame);
//   * by default the coarse phase keeps the job's grid and shortens the clip to its first third.
//     A coarser grid is biased: the cup's hole a few cells wide drains too fast, so its optimum
//     sits above the truth (see kCoarseToFineShift), while the first third of the frames on the
//     job's grid put the minimum at the truth for about the cost of all frames on the coarser grid;
//   * the coarse phase ends early once every log-space standard deviation σ√C_ii is below
//     kCoarseToFineShift, the spread the full-fidelity phase restarts with: a narrower coarse search
//     is discarded at the switch. The time budget never ends it: the plan follows from the job and
//     the data, so that a slower machine runs the same generations (the budget only cuts the
//     full-fidelity phase short, and says so);
//   * at the switch CMA-ES restarts at the best coarse evaluation with a log-space spread of
//     kCoarseToFineShift in every coordinate (counters and random stream go on), the first full
//     generation scores that point too, and the best-so-far is reset: E values of different
//     fidelities are not comparable. In one dimension with λ = 4, CMA-ES needs more generations
//     to shrink σ than a 10-minute run has, so the coarse phase locates the basin and the fine one
//     searches it, starting from the coarse best rather than from a mean that lags behind;
//   * in one dimension the first coarse generation scans instead of sampling: its λ points lie evenly
//     over the initial distribution's ±2σ₀ in log space (within the bounds), and CMA-ES restarts at
//     the best of them with half their spacing as spread. Sampled, the four points of one draw can
//     all miss a far optimum, and σ grows too slowly to make up for it within a budget (the
//     300 Pa·s reference's search from the table's common start ran out of time far below it).
//     A caller's start curve is scanned the same way, in any
//     dimension, with the restart's spread along the curve (restartAlongScan). Later coarse
//     generations in one dimension refine the scan (refinePoints): their λ points lie evenly inside
//     the best point's bracket, and CMA-ES restarts at the best coarse point with half their
//     spacing, a bracketing line search that narrows the bracket by (λ + 1)/2 a generation, where
//     CMA-ES's own σ shrinks slowly with λ = 4 (FINDINGS, "A plan the machine's speed does not
//     change");
//   * in one dimension each later full-fidelity generation scores, in place of a sample, the
//     vertex of the parabola through the best full-fidelity evaluation and its neighbours, or a
//     step beyond the best when it ends the profile (see profileProposal), clipped as an injected
//     solution;
//   * tolerances are checked only at full fidelity, after fidelity.min_fine_generations there:
//     tolerance_x on the search distribution's spread, tolerance_fun on a simulation's E (see
//     settled), in one dimension only once the evaluations give a profile (the interval's, and the
//     grid checks'), and "resolved" once the search samples only what the profile's interval
//     cannot tell apart (see resolved).
//
// θ*: the best full-fidelity evaluation. A parabola fitted to E (against 1/η; see fitProfile) over
// the evaluations near it gives the interval; its vertex is reported (profile_fit.theta_min) but not
// used as θ*. E(θ) carries a jitter of its own (a drop that pinches off one frame earlier) between
// neighbouring η, which the vertex would average out, but E is not a parabola: it is flat and then
// jumps, and on Blender-rendered references the vertex fell further from the truth than the best
// evaluation (tests/bench/FINDINGS.md, "The profile interval").
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

#include <algorithm>
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
        case StopReason::Resolved: return "resolved";
        case StopReason::TimeBudget: return "time_budget";
        case StopReason::Cancelled: return "cancelled";
    }
    return "?";
}

namespace {

// Closer than this in ln θ, a parabolic proposal repeats an evaluation (see parabolicProposal).
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

// A one-dimensional coarse generation after the scan: `count` points evenly inside the bracket
// m ± 2σ (within the bounds) around CMA-ES's mean, which a scan or refinement set to the best coarse
// point with σ half the spacing, so the bracket reaches to the best point's neighbours; neither end
// nor, for an even count, the middle is scored again.
std::vector<Eigen::VectorXd> refinePoints(const CmaEs& es, const LogSearchSpace& space, int count) {
    const double reach = 2 * es.standardDeviations()[0];
    const double lo = std::max(space.lower[0], es.mean()[0] - reach);
    const double hi = std::min(space.upper[0], es.mean()[0] + reach);
    std::vector<Eigen::VectorXd> points;
    for (int k = 1; k <= count; ++k) points.push_back(Eigen::VectorXd::Constant(1, lo + (hi - lo) * k / (count + 1)));
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

// Generations that must each have settled (see settled) before a search stops on tolerance_fun:
// with placements by generation, one on each placement, whose E differ by where the grid falls.
int settledGenerations(const Job& job) { return std::max(2, placementsByGeneration(job) ? job.gridPlacements : 1); }

// Has the search settled where E cannot rank its points any more? In each of the `count` generations
// ending with `last`, the median E of the generation's own points (not an added known point) lies
// within `share` of the least: the search distribution sits where E differs by less than that, and
// more generations reshuffle points the comparison cannot tell apart. A simulation's E is rough and
// rarely meets tolerance_x: its jitter between neighbouring θ (a grid, particles) keeps the ranking
// random, and σ shrinks only slowly. The thin film's E is smooth, and along a valley (η against
// the slip length) its points differ little yet rank truly: it ends on tolerance_x (FINDINGS, "Fits
// that end on their own: tolerance_fun").
bool settled(const std::vector<EvaluationRecord>& evaluated, int last, int count, double share) {
    for (int g = last - count + 1; g <= last; ++g) {
        std::vector<double> E;
        for (const EvaluationRecord& e : evaluated)
            if (e.generation == g && e.origin != "known") E.push_back(e.succeeded() ? e.E() : INFINITY);
        if (E.empty()) return false;
        std::sort(E.begin(), E.end());
        if (!(E[E.size() / 2] <= (1 + share) * E.front())) return false;
    }
    return true;
}

// Has the search come down to what E can resolve? In each of the `count` full-fidelity generations
// ending with `last`, its distribution's band exp(m ± 2σ√C_ii) (within the bounds) lies, for every
// parameter, inside the profile's interval over the evaluations up to that generation (in one
// dimension the profile fit's, in several the joint profile's): it samples only θ the comparison
// cannot tell from the best, and more generations wander among them. tolerance_fun's medians need
// the distribution narrower than E's valley, which a power law's K and n never reached on the
// ViRheometry fronts (FINDINGS, "Several parameters: the joint profile"), and the sample cup's
// viscosity, whose E is a V, reached only after several generations more (FINDINGS, "A plan the
// machine's speed does not change").
bool resolved(const Job& job, const std::vector<GenerationRecord>& generations,
              const std::vector<EvaluationRecord>& evaluated, const LogSearchSpace& bounds, int last, int count) {
    for (int g = last - count + 1; g <= last; ++g) {
        const auto record = std::find_if(generations.begin(), generations.end(),
                                         [&](const GenerationRecord& r) { return r.generation == g; });
        if (record == generations.end() || record->fidelity != Fidelity::Full || record->bestTheta.empty())
            return false;
        json unused;
        std::vector<std::array<double, 2>> intervals;
        if (job.parameters.size() == 1) {
            const std::optional<ProfileFit> profile = profileNear(job, evaluated, record->bestTheta[0], unused, g);
            if (!profile) return false;
            intervals.push_back(profile->interval);
        } else {
            const std::optional<JointProfileFit> joint = jointProfileNear(evaluated, g, record->bestTheta, unused);
            if (!joint) return false;
            intervals = joint->interval;
        }
        for (size_t i = 0; i < intervals.size(); ++i) {
            const double m = std::log(record->meanTheta[i]), reach = 2 * record->logStd[i];
            const double low = std::exp(std::max(m - reach, bounds.lower[i]));
            const double high = std::exp(std::min(m + reach, bounds.upper[i]));
            if (low < intervals[i][0] || high > intervals[i][1]) return false;
        }
    }
    return true;
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
    TimeBudget budget(job, state, plan, pool.concurrency());
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
    // away from the optimum it brackets (tests/bench/FINDINGS.md, "Figures moved from code comments").
    // When the lowest point ends the profile, nothing brackets it: the proposal is then one of
    // CMA-ES's standard deviations beyond it ("extension"). The mean over placements spans only where
    // every placement has scored, and CMA-ES's samples on one placement can stay on one side of
    // the other's minimum for generations, leaving the profile, and so the interval and the grid
    // checks, without a minimum (FINDINGS, "A plan the machine's speed does not change").
    auto profileProposal = [&]() -> std::optional<std::pair<Eigen::VectorXd, const char*>> {
        const std::vector<std::pair<double, double>> points = fullFidelityProfile(job, state.evaluated);
        std::optional<double> proposal = bracketedVertex(points, job.parameters[0].profileInInverse());
        const char* origin = "parabola";
        if (!proposal && points.size() > 1) {
            const auto lowest = std::min_element(points.begin(), points.end(),
                                                 [](const auto& a, const auto& b) { return a.second < b.second; });
            const auto [least, most] = std::minmax_element(points.begin(), points.end());
            const double step = es.standardDeviations()[0];
            if (lowest->first == most->first) proposal = lowest->first * std::exp(step), origin = "extension";
            if (lowest->first == least->first) proposal = lowest->first * std::exp(-step), origin = "extension";
        }
        if (!proposal) return std::nullopt;
        for (const auto& p : points)
            if (std::abs(std::log(*proposal / p.first)) < kProposalSpacing) return std::nullopt;
        return std::make_pair(Eigen::VectorXd::Constant(1, std::log(*proposal)), origin);
    };

    // The grid checks need a profile of E near the best full-fidelity evaluation (grid_checks.cpp).
    auto checksCanRun = [&] {
        json unused;
        const std::optional<BestPoint> best = bestAt(job, state.evaluated, Fidelity::Full);
        return n == 1 && best && profileNear(job, state.evaluated, best->theta[0], unused).has_value();
    };

    while (!state.stop) {
        const int g = es.generation();
        if (g >= job.maxGenerations) {
            state.stop = StopReason::MaxGenerations;
            save();
            break;
        }
        if (budget.fullPhaseOver(checksCanRun())) {
            state.stop = StopReason::TimeBudget;
            save();
            break;
        }
        const Fidelity fidelity = g < state.coarseEnd ? Fidelity::Coarse : Fidelity::Full;
        const bool coarse = fidelity == Fidelity::Coarse;
        const auto genStart = Clock::now();
        std::vector<Eigen::VectorXd> xs = es.ask();
        const bool scan = g == 0 && xs.size() > 1 && (options.startCurve || (coarse && n == 1));
        const bool refine = g > 0 && coarse && n == 1 && !options.startCurve && xs.size() > 1;
        if (scan) xs = scanPoints(bounds, static_cast<int>(xs.size()), options.startCurve);
        if (refine) xs = refinePoints(es, bounds, static_cast<int>(xs.size()));
        // Where each point came from, recorded with its evaluation: a CMA-ES sample, a scan or
        // refinement point, or an injected restart point or parabolic proposal.
        std::vector<std::string> origins(xs.size(), scan ? "scan" : refine ? "refine" : "sample");
        // The first full-fidelity generation also scores the restart point, the coarse best, in
        // place of its last sample: with λ = 4 draws of spread ln 1.4, all four can miss the basin
        // the coarse phase found (η = 30: coarse best 28.6, full samples 14.1 / 36.8 / 20.5 / 19.5).
        // An injected mean is a zero step for CMA-ES's update (Hansen 2011, "Injecting external
        // solutions into CMA-ES"), so nothing else changes.
        if (g == state.coarseEnd && state.coarseEnd > 0) {
            xs.back() = es.mean();
            origins.back() = "restart";
        } else if (!coarse && n == 1) {
            if (const auto proposal = profileProposal()) {
                xs.back() = es.injectable(proposal->first);
                origins.back() = proposal->second;
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
        // The best so far at this generation's fidelity (E of the two fidelities are not comparable).
        const std::optional<BestPoint> best = bestAt(job, state.evaluated, fidelity);
        if (stageFields) {
            // The new best full-fidelity evaluation, if this generation made it, keeps its fields.
            for (size_t k = 0; k < xs.size(); ++k)
                if (best && best->theta == evals[k].theta && best->gridShift == batch.gridShift && evals[k].fields)
                    fields.promote(k, evals[k], batch.gridShift);
            fields.clearStaging();
        }
        const double refinedSpacing = refine ? std::abs(xs[1][0] - xs[0][0]) : 0.0;
        es.tell({xs.begin(), xs.begin() + sampled}, {fitness.begin(), fitness.begin() + sampled});
        if (scan) restartAlongScan(es, xs, bestK);
        if (refine && best)  // at the best coarse point
            es.restart(Eigen::VectorXd::Constant(1, std::log(best->theta[0])),
                       Eigen::VectorXd::Constant(1, std::max(refinedSpacing / 2, 1e-6)));
        const double genSeconds = std::chrono::duration<double>(Clock::now() - genStart).count();
        budget.addGeneration(fidelity, genSeconds);
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
        if (coarse && done < state.coarseEnd && maxStd() < kCoarseToFineShift)
            state.coarseEnd = done;
        if (coarse && done == state.coarseEnd) {
            GenerationRecord& last = state.generations.back();
            last.predictedFineGenerationSeconds = budget.fineGenerationSeconds();  // to check it later
            // The minimum full-fidelity generations and the grid checks run whatever the budget
            // says; when they cannot fit (a long clip at high η), say so now and how long the run
            // will take, instead of a remaining time that runs out early.
            const double fineMinimum =
                job.fidelity.minFineGenerations * budget.fineGenerationSeconds() + budget.gridChecksSeconds();
            const double elapsed = budget.elapsed();
            if (job.timeBudget > 0 && elapsed + fineMinimum > job.timeBudget) {
                last.warning = "time_budget_s: the " + std::to_string(job.fidelity.minFineGenerations) +
                               " full-fidelity generations" +
                               (gridCheckPlanned(job, GridCheck::Alignment) ? " and the grid checks" : "") +
                               " every run makes are predicted to take " + wholeSeconds(fineMinimum) + " s with " +
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
            if (maxStd() < job.toleranceX)
                state.stop = StopReason::ToleranceX;
            else if (job.forwardModel == ForwardModel::Simulation && fineDone >= settledGenerations(job) &&
                     settled(state.evaluated, done, settledGenerations(job), job.toleranceFun) && (n > 1 || checksCanRun()))
                state.stop = StopReason::ToleranceFun;
            else if (job.forwardModel == ForwardModel::Simulation && fineDone >= settledGenerations(job) &&
                     resolved(job, state.generations, state.evaluated, bounds, done, settledGenerations(job)))
                state.stop = StopReason::Resolved;
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
    std::optional<BestPoint> best = bestAt(job, state.evaluated, Fidelity::Full);
    if (!best) best = bestAt(job, state.evaluated, Fidelity::Coarse);
    if (!best) throw std::runtime_error("no successful evaluation");
    json jointProfileInfo;
    const std::optional<JointProfileFit> joint =
        n > 1 ? jointProfileNear(state.evaluated, es.generation(), best->theta, jointProfileInfo) : std::nullopt;
    if (joint && !joint->bounded) {
        std::string names;
        for (const ParameterSpec& p : job.parameters) names += (names.empty() ? "" : ", ") + p.name();
        const std::string line = names + ": E has no minimum along some line among the evaluations near θ*: the "
                                         "parameters trade off along a ridge the data do not resolve, and each "
                                         "interval spans the evaluations E cannot tell from the best";
        warn(line);
        doubts.push_back(line);
    }
    std::vector<ParameterEstimate> estimates;
    for (int i = 0; i < n; ++i) {
        ParameterEstimate estimate = estimateParameter(job, bounds, es, state.evaluated, i, best->theta[i], joint);
        if (gridCheckPlanned(job, GridCheck::Alignment))
            estimate.alignment = alignmentCheck(job, pool, observations, state, estimate.profile, estimate.value, save);
        if (gridCheckPlanned(job, GridCheck::Resolution))
            estimate.resolution = resolutionCheck(job, pool, observations, state, estimate.profile, estimate.value,
                                                  *estimate.alignment, save);
        // Skipped for want of a profile, the interval leaves out the grid's share: the result is doubted.
        for (const std::optional<GridCheckOutcome>* check : {&estimate.alignment, &estimate.resolution})
            if (*check && (*check)->warning) {
                doubts.push_back(*(*check)->warning);
                warn(*(*check)->warning);
            }
        settleInterval(estimate, bounds, i);
        estimates.push_back(std::move(estimate));
    }
    IdentificationResult result;
    result.stop = *state.stop;
    result.generations = es.generation();
    result.evaluations = es.evaluations();
    result.resumedFromGeneration = state.resumedFrom;
    result.theta = best->theta;
    result.E = best->E;
    for (const ParameterEstimate& estimate : estimates) result.interval.push_back(estimate.interval);
    result.intervalMethod = intervalMethodName(estimates.front());
    if (joint) result.indistinguishable = joint->indistinguishable;
    result.seconds = budget.elapsed();

    for (const GenerationRecord& g : state.generations)
        if (!g.warning.empty()) warnings.push_back(g.warning);
    if (result.stop == StopReason::TimeBudget) {
        const std::string line = "time_budget_s: the search was stopped by the budget (" +
                                 wholeSeconds(job.timeBudget) + " s) after " + std::to_string(result.generations) +
                                 " generations, before its own criteria ended it: θ* and its interval are unconverged "
                                 "(a larger budget, or 0 for none, goes on from the checkpoint)";
        warn(line);
        doubts.push_back(line);
    }
    for (const std::string& line : doubtsAfterSearch(job, bounds, result.interval, state.evaluated)) {
        warn(line);
        doubts.push_back(line);
    }
    warnings.insert(warnings.end(), doubts.begin(), doubts.end());
    result.document = resultDocument(job, result, state, plan, obs, estimates, *best, warnings, doubts);
    if (!jointProfileInfo.is_null()) result.document["joint_profile"] = jointProfileInfo;
    if (writeFields) result.document["fields"] = fields.keep(job, obs, *best, plan.fullResolution);
    writeEvaluationsCsv(job, state.evaluated, outDir / "evaluations.csv");
    writeJsonAtomically(result.document, outDir / "result.json");
    return result;
}
}  // namespace viscoscope::identify
