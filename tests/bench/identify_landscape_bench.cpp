// The objective's landscape E(θ) of an identify job on grids moved sideways by fractions of a cell:
// how much of where the minimum lies is the discretization's placement against the scene, not the
// liquid. Evaluates every (θ, shift) pair of the job's first parameter at the job's resolution
// (exactly as identify's full-fidelity evaluations, all cores), prints E per pair, each shift's
// minimum of identify's profile parabola (in 1/θ for viscosity, else ln θ), and the minimum of the
// mean over the shifts; with a scalar track in E, the same again for the silhouettes alone (E
// without the track's term), to tell which term places the minimum; with a measured track (a
// lab's front, say), its relative error sqrt(Σ(sim − measured)² / Σ measured²). A job whose
// grid_placement_schedule is each_evaluation scores each pair as identify does, the mean over its
// grid_placements, each moved by the pair's shift too; by generation (the default), the pair's
// shift alone.
//
//   identify_landscape_bench --job JOB.json --work DIR --thetas 7,8,9,10,11,12.5 [--shifts 0,0.25,0.5,0.75]
//
// DIR holds the extracted reference silhouettes (an identify --out folder is reused as it is).
#include "identify/identify.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

using namespace viscoscope;

namespace {

// θ at the vertex of identify's profile parabola through all of the points, centred on the lowest.
std::string profileMinimum(const std::vector<double>& thetas, const std::vector<double>& E, bool inverse) {
    std::vector<std::pair<double, double>> points;
    for (size_t i = 0; i < thetas.size(); ++i) points.emplace_back(thetas[i], E[i]);
    const size_t lowest = std::min_element(E.begin(), E.end()) - E.begin();
    nlohmann::json info;
    const auto fit = identify::fitProfile(points, thetas[lowest], INFINITY, inverse, info);
    char text[32];
    std::snprintf(text, sizeof text, "%.4g", fit ? fit->vertex : NAN);
    return text;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"E(θ) of an identify job on grids moved sideways by fractions of a cell"};
    std::string jobFile, work;
    std::vector<double> thetas, shifts{0, 0.25, 0.5, 0.75};
    app.add_option("--job", jobFile, "job.json")->required();
    app.add_option("--work", work, "folder for the extracted reference")->required();
    app.add_option("--thetas", thetas, "values of the job's first parameter (five or more for the minima)")
        ->required()
        ->delimiter(',');
    app.add_option("--shifts", shifts, "grid shifts along x and y, in cells (added to each of the job's grid_placements scored on each evaluation)")->delimiter(',');
    CLI11_PARSE(app, argc, argv);
    if (!std::all_of(thetas.begin(), thetas.end(), [](double t) { return std::isfinite(t) && t > 0; }))
        return std::fprintf(stderr, "identify_landscape_bench: --thetas: every value must be positive and finite\n"), 2;
    try {
        openvdb::initialize();
        identify::Job job = identify::loadJob(jobFile);
        identify::prepareReference(job, work);
        const identify::Observation observation = identify::loadObservation(job);
        const size_t n = thetas.size(), m = shifts.size();
        std::vector<double> E(n * m), silhouettes(n * m, 0.0), trackErrors(n * m, NAN);
        tbb::parallel_for(size_t(0), n * m, [&](size_t k) {
            std::vector<double> point{thetas[k / m]};  // the other parameters at their initial values
            for (size_t p = 1; p < job.parameters.size(); ++p) point.push_back(job.parameters[p].initial);
            const identify::Evaluation ev = identify::evaluate(job, observation, point, job.resolution, {}, shifts[k % m]);
            E[k] = ev.E;
            if (ev.trackError) trackErrors[k] = *ev.trackError;
            for (size_t f = 0; f < ev.frameE.size(); ++f) silhouettes[k] += observation.reference.weights[f] * ev.frameE[f];
        });
        const bool inverse = job.parameters.front().profileInInverse();
        const auto printTable = [&](const char* title, const std::vector<double>& values) {
            std::printf("%s\n%10s", title, "θ \\ shift");
            for (double s : shifts) std::printf(" %9.3f", s);
            std::printf(" %9s\n", "mean");
            std::vector<double> mean(n, 0.0);
            for (size_t i = 0; i < n; ++i) {
                std::printf("%10.4g", thetas[i]);
                for (size_t j = 0; j < m; ++j) {
                    std::printf(" %9.4g", values[i * m + j]);
                    mean[i] += values[i * m + j] / m;
                }
                std::printf(" %9.4g\n", mean[i]);
            }
            std::printf("%10s", "minimum");
            for (size_t j = 0; j < m; ++j) {
                std::vector<double> column;
                for (size_t i = 0; i < n; ++i) column.push_back(values[i * m + j]);
                std::printf(" %9s", profileMinimum(thetas, column, inverse).c_str());
            }
            std::printf(" %9s\n", profileMinimum(thetas, mean, inverse).c_str());
        };
        printTable("E", E);
        if (observation.trackWeight > 0) printTable("silhouettes alone (E without the track's term)", silhouettes);
        if (job.measuredTrack) printTable("the measured track's relative error", trackErrors);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "identify_landscape_bench: %s\n", e.what());
        return 2;
    }
    return 0;
}
