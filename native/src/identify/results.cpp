// What the identification reports: θ* and its intervals, doubts, timings, result.json and every
// evaluation as CSV.
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
// The profiles fit E over the evaluations within this of the best in ln θ (every ln θ_i).
constexpr double kProfileRange = 0.5;

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

json timingsOf(const std::vector<EvaluationRecord>& evaluated, double wallSeconds, double alignmentSeconds,
               double resolutionSeconds) {
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
            {"alignment_check_s", alignmentSeconds},
            {"resolution_check_s", resolutionSeconds}};
}

ParameterEstimate estimateParameter(const Job& job, const LogSearchSpace& bounds, const CmaEs& es,
                                    const std::vector<EvaluationRecord>& evaluated, int i, double value,
                                    const std::optional<JointProfileFit>& joint) {
    const Eigen::VectorXd sd = es.standardDeviations();
    const double lower = std::exp(bounds.lower[i]), upper = std::exp(bounds.upper[i]);
    ParameterEstimate estimate;
    estimate.value = value;
    estimate.cmaMean = std::exp(es.mean()[i]);
    estimate.logStd = sd[i];
    // The final search distribution: exp(m ± 2σ√C_ii), two standard deviations of CMA-ES's sampling
    // law in log space, the spread it still considers plausible; not a statistical confidence interval.
    estimate.cma = {std::clamp(std::exp(es.mean()[i] - 2 * sd[i]), lower, upper),
                    std::clamp(std::exp(es.mean()[i] + 2 * sd[i]), lower, upper)};
    if (job.parameters.size() == 1) {
        json info;
        estimate.profile = profileNear(job, evaluated, value, info);
        estimate.profileFit = info;
    }
    if (joint) estimate.jointProfile = joint->interval[i];
    return estimate;
}

std::optional<JointProfileFit> jointProfileNear(const std::vector<EvaluationRecord>& evaluated, int lastGeneration,
                                                const std::vector<double>& best, json& info) {
    std::vector<std::pair<std::vector<double>, double>> points;
    for (const EvaluationRecord& e : evaluated)
        if (e.fidelity == Fidelity::Full && e.succeeded() && e.generation <= lastGeneration)
            points.emplace_back(e.theta(), e.E());
    return fitJointProfile(points, best, kProfileRange, info);
}

std::optional<ProfileFit> profileNear(const Job& job, const std::vector<EvaluationRecord>& evaluated, double value,
                                      json& info, int lastGeneration) {
    std::optional<ProfileFit> profile = fitProfile(fullFidelityProfile(job, evaluated, lastGeneration), value,
                                                   kProfileRange, job.parameters[0].profileInInverse(), info);
    // A vertex beyond the fitted points is an extrapolation, and so is its band
    // (tests/bench/FINDINGS.md, "The profile interval").
    if (profile && !profile->vertexAmongPoints) profile.reset();
    return profile;
}

void settleInterval(ParameterEstimate& estimate, const LogSearchSpace& bounds, int i) {
    const double lower = std::exp(bounds.lower[i]), upper = std::exp(bounds.upper[i]);
    const double value = estimate.value;
    std::array<double, 2> band = estimate.profile        ? estimate.profile->interval
                                 : estimate.jointProfile ? *estimate.jointProfile
                                                         : estimate.cma;
    for (const std::optional<GridCheckOutcome>* check : {&estimate.alignment, &estimate.resolution})
        if (estimate.widenedBy(*check)) {
            const double reach = *(*check)->widening;
            band[0] = std::min(band[0], value * std::exp(-reach));
            band[1] = std::max(band[1], value * std::exp(reach));
        }
    band[0] = std::max(std::min(band[0], value), lower);
    band[1] = std::min(std::max(band[1], value), upper);
    estimate.interval = band;
}

std::string intervalMethodName(const ParameterEstimate& estimate) {
    const char* band = estimate.profile ? "profile" : estimate.jointProfile ? "joint_profile" : "cma";
    return std::string(band) + (estimate.widenedBy(estimate.alignment) ? "+alignment" : "") +
           (estimate.widenedBy(estimate.resolution) ? "+resolution" : "");
}

namespace {

// A parameter's entry in result.json's "parameters".
json parameterEntry(const Job& job, const LogSearchSpace& bounds, const ParameterEstimate& estimate, int i) {
    const double upper = std::exp(bounds.upper[i]);
    json entry{{"unit", job.parameters[i].parameter.declaration->unit},
               {"best_evaluation", estimate.value},
               {"cma_mean", estimate.cmaMean},
               {"cma_interval", estimate.cma},
               {"log_std", estimate.logStd}};
    if (estimate.profileFit) {
        entry["profile_fit"] = *estimate.profileFit;
        if (estimate.profile)
            entry["profile_interval"] = {estimate.profile->interval[0], std::min(estimate.profile->interval[1], upper)};
    }
    entry["value"] = estimate.value;
    if (estimate.alignment) entry["alignment_check"] = estimate.alignment->entry;
    if (estimate.resolution) entry["resolution_check"] = estimate.resolution->entry;
    entry["interval"] = estimate.interval;
    std::string method = estimate.profile ? "profile: parabola fit of E against 1/η (ln θ for other parameters) "
                                            "over full-fidelity evaluations within ±0.5 in ln θ of the best "
                                            "one, band where it is within ΔE = max(2·jitter, 1 % E_min) "
                                            "of its minimum"
                       : estimate.jointProfile
                           ? "joint profile: quadric fit of E in ln θ over full-fidelity evaluations within ±0.5 "
                             "of the best one in every ln θ_i and with E within 3× its E; band spanning the "
                             "evaluations whose E is within ΔE = max(2·jitter, 1 % E_min) of its least and, where "
                             "it has a minimum among them, where its least over the other parameters stays within "
                             "ΔE (joint_profile)"
                           : "cma: exp(m ± 2σ√C_ii) of the final CMA-ES distribution in log space";
    if (estimate.widenedBy(estimate.alignment))
        method += "; alignment: widened to θ*·exp(±|ln(θ_s/θ*)|), θ_s the minimum on the grid moved along x "
                  "and y by half a cell, or half the spacing of the grid placements (alignment_check)";
    if (estimate.widenedBy(estimate.resolution))
        method += "; resolution: widened to θ*·exp(±(h/(h_c − h))·(|ln(θ_s/θ_c)| + 1.645 σ)), θ_c the minimum on the "
                  "grids of cell h_c > h by the same two points, σ the move's noise from E's jitter (resolution_check)";
    entry["interval_method"] = method;
    return entry;
}

}  // namespace

json resultDocument(const Job& job, const IdentificationResult& result, const SearchState& state,
                    const FidelityPlan& plan, const Observation& obs, const std::vector<ParameterEstimate>& estimates,
                    const BestPoint& best, const std::vector<std::string>& warnings,
                    const std::vector<std::string>& doubts) {
    const LogSearchSpace bounds = logSearchSpace(job);
    json params = json::object();
    double alignmentCheckSeconds = 0, resolutionCheckSeconds = 0;
    for (size_t i = 0; i < estimates.size(); ++i) {
        params[job.parameters[i].name()] = parameterEntry(job, bounds, estimates[i], static_cast<int>(i));
        if (estimates[i].alignment) alignmentCheckSeconds += estimates[i].alignment->seconds;
        if (estimates[i].resolution) resolutionCheckSeconds += estimates[i].resolution->seconds;
    }
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
             {"population", state.es.lambda()},
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
                                     (placementsByGeneration(job)
                                          ? "; full-fidelity generations on the " + std::to_string(job.gridPlacements) +
                                                " grid placements in turn, θ* the minimum of E's mean over them"
                                          : std::string("; θ* is the best full-fidelity evaluation"))},
             {"resumed_from_generation", state.resumedFrom},
             {"reference_informative_frames", informativeSimFrames(obs).size()},
             {"ground_band_m", job.groundBand},
             {"warnings", warnings},
             {"doubts", doubts},
             {"compared_pixels",
              {{"left_out_never_visible", obs.neverVisiblePixels},
               {"left_out_liquid_in_background", obs.inBackgroundPixels},
               {"reference_liquid_out_of_view_share", obs.referenceOutOfView}}},
             {"history", history},
             {"evaluated", evaluated},
             {"timings", timingsOf(state.evaluated, result.seconds, alignmentCheckSeconds, resolutionCheckSeconds)}};
    if (params.contains("viscosity")) doc["viscosity"] = params["viscosity"];
    // With several runs, how well θ* fits each: its evaluation's E per run, on the placement its
    // fields come from.
    for (const EvaluationRecord& e : state.evaluated)
        if (!e.evaluation.runE.empty() && e.theta() == best.theta && e.gridShift == best.gridShift) {
            doc["run_E"] = e.evaluation.runE;
            break;
        }
    return doc;
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
