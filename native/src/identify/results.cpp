// What the identification reports beside θ*: doubts, timings and every evaluation as CSV.
#include "identify/search_state.h"

#include "sim/sim.h"

#include <cstdio>
#include <iomanip>
#include <map>
#include <sstream>

namespace viscoscope::identify {

using json = nlohmann::json;

namespace {

// The reference's liquid outside what the simulation can ever show, past this share of it: a camera
// or domain that does not match the footage, not extraction noise along the outline.
constexpr double kOutOfViewDoubtShare = 0.05;
// E over the full-fidelity evaluations changes by less than this share of its least value while they
// span at least kFlatSpan in some parameter: the footage does not tell those θ apart.
constexpr double kFlatObjectiveShare = 0.05;
constexpr double kFlatSpan = 2.0;

}  // namespace

std::vector<std::string> doubtsBeforeSearch(const Observation& obs) {
    std::vector<std::string> doubts;
    if (obs.referenceOutOfView > kOutOfViewDoubtShare) {
        char line[400];
        std::snprintf(line, sizeof line,
                      "reference: %.0f %% of the footage's liquid lies where the simulated liquid can never be seen "
                      "(outside the simulation domain, or behind an opaque solid): check the camera and the domain",
                      100 * obs.referenceOutOfView);
        doubts.push_back(line);
    }
    return doubts;
}

std::vector<std::string> doubtsAfterSearch(const Job& job, const LogSearchSpace& bounds,
                                           const std::vector<std::array<double, 2>>& intervals,
                                           const std::vector<EvaluationRecord>& evaluated) {
    std::vector<std::string> doubts;
    for (size_t i = 0; i < job.parameters.size(); ++i) {
        const std::string& name = job.parameters[i].name();
        const double lower = std::exp(bounds.lower[i]), upper = std::exp(bounds.upper[i]);
        for (const double bound : {lower, upper})
            if (std::abs(std::log(intervals[i][bound == lower ? 0 : 1] / bound)) < 1e-6) {
                std::ostringstream line;
                line << name << ": the interval reaches the search bound " << bound
                     << ", so the footage does not bound it there";
                doubts.push_back(line.str());
            }
    }
    double least = INFINITY, most = -INFINITY;
    const EvaluationRecord* best = nullptr;
    std::vector<double> thetaLow(job.parameters.size(), INFINITY), thetaHigh(job.parameters.size(), 0);
    for (const EvaluationRecord& e : evaluated) {
        if (e.fidelity != Fidelity::Full || !e.succeeded()) continue;
        if (e.E() < least) best = &e;
        least = std::min(least, e.E());
        most = std::max(most, e.E());
        for (size_t i = 0; i < thetaLow.size(); ++i) {
            thetaLow[i] = std::min(thetaLow[i], e.theta()[i]);
            thetaHigh[i] = std::max(thetaHigh[i], e.theta()[i]);
        }
    }
    for (size_t i = 0; i < thetaLow.size(); ++i)
        if (thetaHigh[i] >= kFlatSpan * thetaLow[i] && most - least < kFlatObjectiveShare * least) {
            std::ostringstream line;
            line << "E is nearly flat: it changes by " << std::setprecision(2) << 100 * (most - least) / least
                 << " % over " << job.parameters[i].name() << " from " << std::setprecision(4) << thetaLow[i] << " to "
                 << thetaHigh[i] << ", so the footage hardly tells these apart (check the camera, the masks and "
                                    "what the clip shows)";
            doubts.push_back(line.str());
            break;
        }
    if (best) {
        const std::string at = "the best evaluation (θ = " + json(best->theta()).dump() + ")";
        if (const double lost = best->evaluation.liquidLost; lost > sim::kLostLiquidShare)
            doubts.push_back(at + " lost " + std::to_string(int(100 * lost)) +
                             " % of its liquid (it left the domain or went into a solid), so θ* fits another amount "
                             "of liquid: check the domain, the solids and the fill");
        if (const int unconverged = best->evaluation.unconvergedFrames; unconverged > 0)
            doubts.push_back(at + " had " + std::to_string(unconverged) +
                             " frames whose pressure–viscosity solve stopped short of its tolerance: raise "
                             "solver.max_iterations");
    }
    return doubts;
}

json timingsOf(const std::vector<EvaluationRecord>& evaluated, double wallSeconds, double alignmentSeconds) {
    struct Sums {
        int resolution = 0, frames = 0, evaluations = 0;
        double seconds = 0, simulation = 0, silhouette = 0, fields = 0;
    };
    std::map<Fidelity, Sums> perFidelity;
    double evaluationSeconds = 0;
    for (const EvaluationRecord& e : evaluated) {
        Sums& s = perFidelity[e.fidelity];
        if (s.evaluations++ == 0) s.resolution = e.evaluation.resolution, s.frames = e.frames;
        s.seconds += e.evaluation.seconds;
        s.simulation += e.evaluation.simulationSeconds;
        s.silhouette += e.evaluation.silhouetteSeconds;
        s.fields += e.evaluation.fieldsSeconds;
        evaluationSeconds += e.evaluation.seconds;
    }
    json fidelities = json::object();
    for (const auto& [fidelity, s] : perFidelity)
        fidelities[fidelityName(fidelity)] = {{"resolution", s.resolution},   {"frames", s.frames},
                                              {"evaluations", s.evaluations}, {"seconds", s.seconds},
                                              {"simulation_s", s.simulation}, {"silhouette_s", s.silhouette},
                                              {"fields_s", s.fields},         {"mean_seconds", s.seconds / s.evaluations}};
    return {{"wall_s", wallSeconds},
            {"evaluation_cpu_s", evaluationSeconds},
            {"per_fidelity", fidelities},
            {"alignment_check_s", alignmentSeconds}};
}

void writeEvaluationsCsv(const Job& job, const std::vector<EvaluationRecord>& evaluated,
                         const std::filesystem::path& file) {
    writeFileAtomically(file, [&](std::ostream& csv) {
        csv << "generation,fidelity,resolution,frames";
        for (const ParameterSpec& p : job.parameters) csv << "," << p.name();
        csv << ",E,seconds,origin\n";
        csv << std::setprecision(17);
        for (const EvaluationRecord& e : evaluated) {
            csv << e.generation << "," << fidelityName(e.fidelity) << "," << e.evaluation.resolution << ","
                << e.frames;
            for (double t : e.theta()) csv << "," << t;
            csv << ",";
            if (e.succeeded()) csv << e.E();
            else csv << "nan";
            csv << "," << e.evaluation.seconds << "," << e.origin << "\n";
        }
    });
}

}  // namespace viscoscope::identify
