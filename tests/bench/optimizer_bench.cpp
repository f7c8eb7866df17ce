// Optimizer benchmark, after Fig. 5 of Takahashi & Lin 2019: the project's CMA-ES against NLopt's
// derivative-free Nelder–Mead (LN_NELDERMEAD) and BOBYQA (LN_BOBYQA) on one identification job.
// For each run it prints the evaluations and wall seconds until the best-so-far θ (lowest E) is
// first within 5 % of the true viscosity, the final θ and its error, and the totals; then medians
// over the seeds and the NLopt/CMA-ES ratios.
//
//   optimizer_bench --job JOB.json --truth ETA [--resolution N] [--budget 40] [--seeds 3] [--threads 0]
//
// Same conditions for every method:
//   * one fidelity (--resolution, default the job's) and the job's simulation seed for every θ;
//   * x = ln θ inside the job's bounds (identify::logSearchSpace), a start point x0 drawn from the
//     job's initial distribution N(ln θ0, s0²) per seed, and initial step s0;
//   * stop at --budget evaluations or when the step falls below the job's tolerance_x (CMA-ES:
//     every σ√C_ii; NLopt: xtol_abs), whichever comes first;
//   * nothing memoized: every evaluation is a simulation.
// CMA-ES evaluates its λ candidates in parallel (TBB, as identify does) and only learns their E at
// the end of the generation, so its "to 5 %" figures count whole generations. NLopt's methods are
// sequential by construction. Each simulation also runs TBB loops inside, for every method. The
// "evaluations" columns show the search's efficiency; the "wall" columns add the parallel gain.
// Powell's BOBYQA is stated for n ≥ 2, but NLopt's (2.7.1, checked) accepts a single parameter:
// its model then interpolates 2n + 1 = 3 points, which in 1-D is a full quadratic.
// NLopt is linked into this benchmark only; the engine does not depend on it.
#include "identify/identify.h"

#include <nlopt.hpp>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <functional>
#include <optional>
#include <random>

namespace fs = std::filesystem;
using namespace viscoscope;
using Clock = std::chrono::steady_clock;

namespace {

constexpr double kTarget = 0.05;  // "within 5 % of the truth"

struct Context {
    identify::Job job;
    identify::Observations observations;
    identify::LogSearchSpace space;
    size_t viscosity = 0;  // index of the viscosity in θ
    double truth = 0;
    int resolution = 0;
    long budget = 0;
    int threads = 0;
};

// One optimizer run as the reader sees it.
struct Run {
    std::string method;
    std::vector<double> start;  // θ at x0
    long evaluations = 0;
    int failed = 0;                  // simulations that threw (E = ∞, ranked last)
    double evaluationSeconds = 0;    // Σ of the evaluations' own durations
    double bestE = INFINITY;
    std::vector<double> bestTheta;
    long reachedEvaluations = -1;    // −1: the best-so-far θ never came within 5 %
    double reachedSeconds = INFINITY;
    double wall = 0;
    std::string stop;
};

double relativeError(const Context& c, const std::vector<double>& theta) {
    return std::abs(theta[c.viscosity] - c.truth) / c.truth;
}

// A simulation that fails (unstable) gets E = ∞, as in identify; bad input propagates.
identify::Evaluation simulate(const Context& c, const std::vector<double>& theta) {
    try {
        return identify::evaluate(c.job, c.observations.full, theta, c.resolution);
    } catch (const InputError&) {
        throw;
    } catch (const std::exception&) {
        identify::Evaluation failed;
        failed.theta = theta;
        failed.E = INFINITY;
        return failed;
    }
}

void record(Run& run, const identify::Evaluation& e) {
    ++run.evaluations;
    run.evaluationSeconds += e.seconds;
    if (!std::isfinite(e.E)) ++run.failed;
    if (e.E < run.bestE) run.bestE = e.E, run.bestTheta = e.theta;
}

// Called when the optimizer knows every E recorded so far.
void markIfReached(Run& run, const Context& c, Clock::time_point start) {
    if (run.reachedEvaluations >= 0 || run.bestTheta.empty() || relativeError(c, run.bestTheta) > kTarget) return;
    run.reachedEvaluations = run.evaluations;
    run.reachedSeconds = std::chrono::duration<double>(Clock::now() - start).count();
}

Run runCmaEs(const Context& c, const Eigen::VectorXd& x0, std::uint64_t seed) {
    Run run;
    run.method = "CMA-ES";
    run.start = identify::thetaOf(x0, c.space);
    identify::CmaEsSettings settings;
    settings.populationSize = c.job.populationSize;
    identify::CmaEs es(x0, c.space.spread, seed, settings);
    identify::ThreadPool pool(c.threads);
    const auto start = Clock::now();
    run.stop = "budget";
    while (es.evaluations() + es.lambda() <= c.budget) {  // whole generations only
        const std::vector<Eigen::VectorXd> xs = es.ask();
        identify::EvaluationBatch batch{{}, false, c.resolution, 0, {}};
        for (const Eigen::VectorXd& x : xs) batch.thetas.push_back(identify::thetaOf(x, c.space));
        const std::vector<identify::Evaluation> evals = pool.evaluate(c.job, c.observations, batch).evaluations;
        std::vector<double> fitness(xs.size());
        for (size_t k = 0; k < xs.size(); ++k) {
            fitness[k] = std::isfinite(evals[k].E) ? evals[k].E + identify::boundPenalty(xs[k], c.space) : 1e30;
            record(run, evals[k]);
        }
        es.tell(xs, fitness);
        markIfReached(run, c, start);
        if (es.standardDeviations().maxCoeff() < c.job.toleranceX) {
            run.stop = "tolerance_x";
            break;
        }
    }
    run.wall = std::chrono::duration<double>(Clock::now() - start).count();
    return run;
}

Run runNlopt(const Context& c, nlopt::algorithm algorithm, const char* name, const Eigen::VectorXd& x0) {
    Run run;
    run.method = name;
    run.start = identify::thetaOf(x0, c.space);
    const auto toVector = [](const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); };
    nlopt::opt opt(algorithm, static_cast<unsigned>(x0.size()));
    opt.set_lower_bounds(toVector(c.space.lower));
    opt.set_upper_bounds(toVector(c.space.upper));
    opt.set_initial_step(toVector(c.space.spread));
    opt.set_xtol_abs(c.job.toleranceX);
    opt.set_maxeval(static_cast<int>(c.budget));
    // NLopt's C++ wrapper swallows a callback's exception into a bare error code, so bad input is
    // kept here and rethrown after NLopt has unwound.
    std::exception_ptr badInput;
    const auto start = Clock::now();
    std::function<double(const std::vector<double>&)> objective = [&](const std::vector<double>& x) {
        identify::Evaluation e;
        try {  // NLopt keeps x inside the bounds, so thetaOf's clip changes nothing
            e = simulate(c, identify::thetaOf(Eigen::Map<const Eigen::VectorXd>(x.data(), x.size()), c.space));
        } catch (const InputError&) {
            badInput = std::current_exception();
            throw nlopt::forced_stop();
        }
        record(run, e);
        markIfReached(run, c, start);
        return std::isfinite(e.E) ? e.E : 1e30;
    };
    opt.set_min_objective(
        [](const std::vector<double>& x, std::vector<double>&, void* data) {
            return (*static_cast<std::function<double(const std::vector<double>&)>*>(data))(x);
        },
        &objective);
    std::vector<double> x = toVector(x0);
    double f = 0;
    try {
        const nlopt::result result = opt.optimize(x, f);
        run.stop = result == nlopt::MAXEVAL_REACHED ? "budget"
                   : result == nlopt::XTOL_REACHED  ? "tolerance_x"
                                                    : nlopt_result_to_string(static_cast<nlopt_result>(result));
    } catch (const nlopt::roundoff_limited&) {  // the step cannot shrink further: a normal end, the best θ stands
        run.stop = "roundoff_limited";
    } catch (const nlopt::forced_stop&) {
        if (badInput) std::rethrow_exception(badInput);
        throw;
    }
    run.wall = std::chrono::duration<double>(Clock::now() - start).count();
    return run;
}

std::string format(const std::vector<double>& theta) {
    std::string text;
    for (double v : theta) {
        char number[24];
        std::snprintf(number, sizeof number, "%s%.4g", text.empty() ? "" : ",", v);
        text += number;
    }
    return text;
}

// Labels and headers are ASCII so that printf's byte-counted widths line up.
void printHeader() {
    std::printf("%-12s %4s %-12s %11s %10s  %-12s %7s %6s %8s %7s  %s\n", "method", "seed", "start theta",
                "evals to 5%", "wall to 5%", "final theta", "error", "evals", "wall", "s/eval", "stop");
}

void printRun(const Context& c, const Run& r, int seed) {
    char evals[16] = "not reached", wall[16] = "";
    if (r.reachedEvaluations >= 0) {
        std::snprintf(evals, sizeof evals, "%ld", r.reachedEvaluations);
        std::snprintf(wall, sizeof wall, "%.1f s", r.reachedSeconds);
    }
    const std::string failed = r.failed ? ", " + std::to_string(r.failed) + " failed simulations" : "";
    std::printf("%-12s %4d %-12s %11s %10s  %-12s %6.1f%% %6ld %6.1f s %7.2f  %s%s\n", r.method.c_str(), seed,
                format(r.start).c_str(), evals, wall, format(r.bestTheta).c_str(), 100 * relativeError(c, r.bestTheta),
                r.evaluations, r.wall, r.evaluationSeconds / std::max(1L, r.evaluations), r.stop.c_str(),
                failed.c_str());
    std::fflush(stdout);
}

// The median, with "not reached" as +∞ (so a median of ∞ means most seeds did not reach 5 %).
double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t m = v.size() / 2;
    return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

std::string figure(double value, const char* format) {
    if (!std::isfinite(value)) return "not reached";
    char text[64];
    std::snprintf(text, sizeof text, format, value);
    return text;
}

std::string loadAverage() {
    double load[3] = {NAN, NAN, NAN};
    getloadavg(load, 3);
    char text[64];
    std::snprintf(text, sizeof text, "%.2f %.2f %.2f", load[0], load[1], load[2]);
    return text;
}

int usage(const char* message) {
    std::fprintf(stderr,
                 "optimizer_bench: %s\nusage: optimizer_bench --job JOB.json --truth ETA [--resolution N] "
                 "[--budget 40] [--seeds 3] [--threads 0]\n",
                 message);
    return 2;
}

}  // namespace

int main(int argc, char** argv) {
    fs::path jobFile;
    double truth = 0;
    int resolution = 0, seeds = 3, threads = 0;
    long budget = 40;
    for (int i = 1; i < argc; ++i) {
        if (i + 1 >= argc) return usage(("missing value or unknown option " + std::string(argv[i])).c_str());
        const char* option = argv[i];
        const char* value = argv[++i];
        if (!std::strcmp(option, "--job")) jobFile = value;
        else if (!std::strcmp(option, "--truth")) truth = std::atof(value);
        else if (!std::strcmp(option, "--resolution")) resolution = std::atoi(value);
        else if (!std::strcmp(option, "--budget")) budget = std::atol(value);
        else if (!std::strcmp(option, "--seeds")) seeds = std::atoi(value);
        else if (!std::strcmp(option, "--threads")) threads = std::atoi(value);
        else return usage(("unknown option " + std::string(option)).c_str());
    }
    if (jobFile.empty()) return usage("--job is required");
    if (!(truth > 0)) return usage("--truth must be a viscosity > 0 (Pa·s)");
    if (seeds < 1 || budget < 1 || threads < 0 || resolution < 0)
        return usage("bad --seeds, --budget, --threads or --resolution");

    openvdb::initialize();
    std::optional<tbb::global_control> threadLimit;  // also caps the TBB loops inside each simulation
    if (threads > 0) threadLimit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    fs::path extracted;
    int status = 0;
    try {
        Context c;
        c.job = identify::loadJob(jobFile);
        if (c.job.referenceDir.empty()) {  // a video: extract it once, like identify does into OUT/reference
            extracted = fs::temp_directory_path() / ("viscoscope_optimizer_bench_" + std::to_string(getpid()));
            identify::prepareReference(c.job, extracted);
        }
        c.observations = identify::observe(c.job);
        c.space = identify::logSearchSpace(c.job);
        c.truth = truth;
        c.resolution = resolution > 0 ? resolution : c.job.resolution;
        c.budget = budget;
        c.threads = threads;
        const auto& parameters = c.job.parameters;
        while (c.viscosity < parameters.size() && parameters[c.viscosity].name() != "viscosity") ++c.viscosity;
        if (c.viscosity == parameters.size())
            throw InputError(jobFile.string() + ": parameters: no \"viscosity\" to compare with --truth");
        identify::CmaEsSettings settings;
        settings.populationSize = c.job.populationSize;
        const int lambda = identify::CmaEs(c.space.start, c.space.spread, 1, settings).lambda();
        if (budget < lambda)
            throw InputError("--budget " + std::to_string(budget) + " is below one CMA-ES generation (λ = " +
                             std::to_string(lambda) + ")");

        std::printf("job %s: %zu parameter(s), truth η = %g Pa·s, %d³, simulation seed %llu, tolerance_x %g\n",
                    jobFile.c_str(), parameters.size(), truth, c.resolution,
                    static_cast<unsigned long long>(c.job.seed), c.job.toleranceX);
        std::printf("budget %ld evaluations, %d seeds, CMA-ES λ = %d, threads %s, load average %s\n", budget, seeds,
                    lambda, threads ? std::to_string(threads).c_str() : "all", loadAverage().c_str());
        printHeader();
        std::vector<std::vector<Run>> runs(3);  // CMA-ES, Nelder–Mead, BOBYQA
        for (int seed = 1; seed <= seeds; ++seed) {
            // x0 ~ N(ln θ0, s0²) clipped into the bounds; shared by the three methods of this seed. Its
            // engine is seeded through seed_seq, CmaEs's directly with `seed`: the start point and
            // CMA-ES's first samples must not come from the same random numbers.
            std::seed_seq sequence{seed};
            std::mt19937_64 random(sequence);
            std::normal_distribution<double> normal;
            Eigen::VectorXd x0 = c.space.start;
            for (Eigen::Index i = 0; i < x0.size(); ++i)
                x0[i] = std::clamp(x0[i] + c.space.spread[i] * normal(random), c.space.lower[i], c.space.upper[i]);
            // The methods of one seed run back to back, so load from other processes hits them alike.
            runs[0].push_back(runCmaEs(c, x0, seed));
            printRun(c, runs[0].back(), seed);
            runs[1].push_back(runNlopt(c, nlopt::LN_NELDERMEAD, "Nelder-Mead", x0));
            printRun(c, runs[1].back(), seed);
            runs[2].push_back(runNlopt(c, nlopt::LN_BOBYQA, "BOBYQA", x0));
            printRun(c, runs[2].back(), seed);
        }

        std::printf("\nmedians over %d seeds (not reached counts as ∞), load average %s\n", seeds,
                    loadAverage().c_str());
        std::printf("%-12s %7s %11s %11s %7s %6s %8s %7s\n", "method", "reached", "evals to 5%", "wall to 5%",
                    "error", "evals", "wall", "s/eval");
        // A run that never reached 5 % would have needed more than its totals: with those in place of
        // ∞, the medians become lower bounds, which still bound a ratio whose exact median is ∞.
        std::vector<double> evalsTo(3), wallTo(3), evalsAtLeast(3), wallAtLeast(3);
        for (size_t m = 0; m < runs.size(); ++m) {
            std::vector<double> e, w, eBound, wBound, error, total, seconds, perEvaluation;
            int reached = 0;
            for (const Run& r : runs[m]) {
                const bool hit = r.reachedEvaluations >= 0;
                reached += hit;
                e.push_back(hit ? r.reachedEvaluations : INFINITY);
                w.push_back(r.reachedSeconds);
                eBound.push_back(hit ? r.reachedEvaluations : r.evaluations);
                wBound.push_back(hit ? r.reachedSeconds : r.wall);
                error.push_back(100 * relativeError(c, r.bestTheta));
                total.push_back(r.evaluations);
                seconds.push_back(r.wall);
                perEvaluation.push_back(r.evaluationSeconds / std::max(1L, r.evaluations));
            }
            evalsTo[m] = median(e);
            wallTo[m] = median(w);
            evalsAtLeast[m] = median(eBound);
            wallAtLeast[m] = median(wBound);
            std::printf("%-12s %5d/%d %11s %11s %6.1f%% %6.0f %6.1f s %7.2f\n", runs[m].front().method.c_str(), reached,
                        seeds, figure(evalsTo[m], "%.0f").c_str(), figure(wallTo[m], "%.1f s").c_str(), median(error),
                        median(total), median(seconds), median(perEvaluation));
        }
        std::printf("\nratio NLopt / CMA-ES of the medians to 5 %% (< 1: NLopt needs less)\n");
        const auto ratio = [](double nlopt, double nloptAtLeast, double cma, double cmaAtLeast) -> std::string {
            if (std::isfinite(nlopt) && std::isfinite(cma)) return figure(nlopt / cma, "%.2f");
            if (std::isfinite(nlopt)) return figure(nlopt / cmaAtLeast, "≤ %.2f (CMA-ES's median not reached)");
            if (std::isfinite(cma)) return figure(nloptAtLeast / cma, "≥ %.2f (NLopt's median not reached)");
            return "n/a (neither median reached)";
        };
        for (size_t m = 1; m < runs.size(); ++m)
            std::printf("%-12s evaluations %s, wall %s\n", runs[m].front().method.c_str(),
                        ratio(evalsTo[m], evalsAtLeast[m], evalsTo[0], evalsAtLeast[0]).c_str(),
                        ratio(wallTo[m], wallAtLeast[m], wallTo[0], wallAtLeast[0]).c_str());
        std::printf("CMA-ES evaluates its λ = %d candidates in parallel; Nelder–Mead and BOBYQA evaluate one at a "
                    "time. The evaluation ratio compares the searches; the wall ratio adds that parallelism.\n",
                    lambda);
    } catch (const InputError& e) {
        status = (std::fprintf(stderr, "%s\n", e.what()), 2);
    } catch (const std::exception& e) {
        status = (std::fprintf(stderr, "optimizer_bench: %s\n", e.what()), 1);
    }
    if (!extracted.empty()) fs::remove_all(extracted);
    return status;
}
