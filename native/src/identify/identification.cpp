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
//     climbing at 111 when its 600 s ran out;
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
#include "identify/identify.h"

#include "scene/digest.h"
#include "sim/sim.h"
#include "surface/surface.h"

#include <Eigen/QR>

#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <iomanip>
#include <map>
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

using Clock = std::chrono::steady_clock;

std::string fingerprint(const Job& job) {
    // A digest of the job document and the resolved inputs that change E.
    // Settings that change neither E nor the CMA-ES state may differ between runs of one job.
    json doc = job.document;
    for (const char* key : {"max_generations", "tolerance_x", "tolerance_fun", "time_budget_s"}) doc.erase(key);
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
    for (const Job& run : job.otherRuns) doc["_runs"].push_back(fingerprint(run));
    return Digest().add(doc.dump()).hex();
}

double clipped(double x, double lo, double hi) { return std::min(hi, std::max(lo, x)); }

// The coarse grid's optimum is not the fine grid's: on the sample scene (η = 8 Pa·s, 2 s) the cup
// drains 40 cm³ at 48³ and 64³, but 60 cm³ at 32³ and 69 cm³ at 36³, where the 18 mm hole is
// 3–4 cells wide, and the best 32³ evaluations sat 25–35 % above the truth in identify_bench and
// identification_table runs at 48³. On the job's grid, a third of the clip weighs the flow's phases
// differently from all of it (truth 10 against a 64³ reference: frames 1–19 favour 9.2–9.8, frames
// 21–39 favour 7.7), so the fine phase searches a log-space spread of ln 1.4 around the coarse best.
constexpr double kCoarseToFineShift = 0.35;
// With a time budget, the coarse phase may use at most 35 % of it, and no more than leaves time for
// the minimum full-fidelity generations. When the coarse grid was 32³, their (r/r_c)⁴ prediction
// was 190 s per generation where 125–139 s were measured, and the reservation alone left the coarse
// phase a single generation in a 10-minute run; hence the cap. Half the budget was too much once
// the grid placements took turns by generation: each placement then gets every other full
// generation, and at η = 300 on the sample cup (a scan and 7 more coarse generations, whose E over
// the first third of the clip steps between a few values, the best found in the 6th) the half-cell
// placement got one, and θ* sat 5.0 % high; with 35 % (a scan and 3 more) it got two, and 0.4 %.
// (η = 1, whose full-fidelity E is flat within its jitter, went from 3.7 to 10.5 % with the same
// two full generations; see the README's Table 1.) On the same grid over a third of the clip,
// scaled by the frame count alone, the prediction was low instead (the first frames are the
// cheapest): 110 and 126 s predicted, 135 and 133 s measured on the sample scene at 48³, η = 10, and
// 160 against 200–230 s at η = 3; see fineGenerationSeconds for the better prediction, and the margin.
constexpr double kCoarseBudgetShare = 0.35;
constexpr double kFineTimeMargin = 1.15;
// Closer than this in ln θ (0.3 %), a parabolic proposal repeats an evaluation (see parabolicProposal).
constexpr double kProposalSpacing = 3e-3;
// Version 2 tags every evaluation with its fidelity (version 1 told them apart by resolution);
// version 3 adds the silhouettes' area track to E by default; version 4 is sealed (digest.h).
constexpr int kCheckpointVersion = 4;
constexpr const char* kCoarse = "coarse";
constexpr const char* kFull = "full";

std::string wholeSeconds(double s) { return std::to_string(std::lround(s)); }

int coarseResolution(const Job& job) {
    return std::max(8, static_cast<int>(std::lround(job.fidelity.coarseFactor * job.resolution)));
}

int plannedCoarseGenerations(const Job& job, const Observation& obs, const Observation& coarseObs) {
    if (coarseResolution(job) >= job.resolution && lastSimFrame(coarseObs) >= lastSimFrame(obs)) return 0;
    int g = job.fidelity.coarseGenerations >= 0 ? job.fidelity.coarseGenerations
                                                : std::min(job.maxGenerations / 2, 10);
    return std::max(0, std::min(g, job.maxGenerations - 1));
}

json vec(const std::vector<double>& v) { return json(v); }

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

// The alignment check. The grid resolves a scene's small features unevenly: the sample cup's hole
// is 2.4 cells in radius at 48³, and where the faces fall against its rim decides how much of it passes
// flux (84–98 % of its area as the cup moved sideways by 0 to ½ cell) and so the drain (share out
// by frame 8 at η = 1: 0.133 to 0.154; 0.126–0.133 moved upwards). That error is the
// discretization's, not the fit's, and the profile band does not see it. So θ* and kAlignmentStep·θ*
// are scored again on the grid moved by half a cell along x and y, and with the profile's curvature
// c the minimum there is u_s = ((u₁² − u₂²) − (E₁ − E₂)/c) / (2 (u₁ − u₂)). Against the 64³ η = 1
// reference, E of the 48³ grid over η = 0.85 … 1.3 has its minimum near 0.86 aligned and 1.06
// shifted. With that landscape's curvature the two points gave 1.05–1.14; in the identification
// the profile of CMA-ES's spread-out samples was flatter (c = 1.04 against 1.8; E is more V than
// parabola there) and gave 1.27, so the widening errs wide. Against η = 10 it gave 9.72 for θ* =
// 9.04 (the landscape's shifted minimum is about 10.0). One other alignment is a sample of the
// error, not its sign: the interval is widened to θ*·exp(±|ln(θ_s/θ*)|). Against 96³ references
// (identify_landscape_bench at 18e9051), the minima on grids moved by 0, ¼ and ½ cell were
// 0.864 / 0.933 / 1.054 at η = 1, 8.88 / 9.04 / 9.41 at η = 10, 104 / 114 / 128 at η = 100 and
// 314 / 341 / 381 at η = 300; from θ* the check's two points said 9.95, 134 and 399 for the last three.
// Cells along x and y; with several grid placements, half their spacing, which puts the check's
// grids midway between the search's.
constexpr double kAlignmentShift = 0.5;
constexpr double kAlignmentStep = 1.15;

// E as JSON: null where a simulation failed (E = ∞), since JSON has no infinity.
json finiteOrNull(double value) { return std::isfinite(value) ? json(value) : json(); }

std::optional<double> shiftedMinimum(const ProfileFit& profile, bool inverse, const std::array<double, 2>& theta,
                                     const std::array<double, 2>& E) {
    const auto u = [&](double t) { return inverse ? 1 / t : std::log(t); };
    const double u1 = u(theta[0]), u2 = u(theta[1]);
    const double us = ((u1 * u1 - u2 * u2) - (E[0] - E[1]) / profile.curvature) / (2 * (u1 - u2));
    if (!std::isfinite(us)) return std::nullopt;
    if (inverse) return us > 0 ? std::optional<double>(1 / us) : std::optional<double>(INFINITY);
    return std::exp(us);
}

// The best full-fidelity evaluation's fields live in OUT/fields, with OUT/fields/evaluation.json
// saying whose they are; full-fidelity evaluations write theirs into OUT/fields.partial/<k> and the
// generation's winner replaces them. Simulating θ* again for them took 26–97 s of a 10-minute
// identification on the sample scene at 48³ (η = 10…300); writing them costs each full-fidelity
// evaluation its .vdb writes (0.6 s of a 65 s evaluation at η = 3, 61 frames), and the level sets
// of frames it does not compare (longer clips, compared every few frames). θ* is simulated
// (and scored) again only when they are missing: a run killed while promoteFields swaps them, or
// one whose best evaluation ran without writing them. A kill -9 mid-generation leaves
// OUT/fields.partial until the next generation of the run.
const char* const kFieldsFolder = "fields";
const char* const kFieldsStaging = "fields.partial";
const char* const kFieldsOwner = "evaluation.json";

json fieldsOwner(const std::string& fingerprint, const Evaluation& ev, double gridShift, int frames) {
    return {{"fingerprint", fingerprint},
            {"theta", ev.theta},
            {"resolution", ev.resolution},
            {"grid_shift", gridShift},
            {"frames", frames},
            {"mean_ground_speed_m_s", ev.fields->groundFrames ? json(ev.fields->meanGroundSpeed) : json()}};
}

// Makes `staged` (an evaluation's fields folder) OUT/fields.
void promoteFields(const fs::path& staged, const json& owner, const fs::path& outDir) {
    writeJsonAtomically(owner, staged / kFieldsOwner);
    fs::remove_all(outDir / kFieldsFolder);
    fs::rename(staged, outDir / kFieldsFolder);
}

// OUT/fields' owner when it holds θ at this job, resolution, grid shift and frame count; null otherwise.
json fieldsOf(const fs::path& outDir, const std::string& fingerprint, const std::vector<double>& theta,
              int resolution, double gridShift, int frames) {
    std::ifstream stream(outDir / kFieldsFolder / kFieldsOwner);
    if (!stream) return nullptr;
    const json owner = json::parse(stream, nullptr, false);
    if (owner.is_discarded() || owner.value("fingerprint", "") != fingerprint || owner.value("resolution", 0) != resolution ||
        owner.value("grid_shift", 0.0) != gridShift || owner.value("frames", 0) != frames || !owner.contains("theta") ||
        owner.at("theta") != json(theta))
        return nullptr;
    return owner;
}

// The first coarse generation's points in one dimension: `count` evenly over ±2σ₀ around the start,
// clipped to the bounds (see the fidelity policy).
std::vector<Eigen::VectorXd> scanPoints(const LogSearchSpace& space, int count) {
    const double lo = std::max(space.lower[0], space.start[0] - 2 * space.spread[0]);
    const double hi = std::min(space.upper[0], space.start[0] + 2 * space.spread[0]);
    std::vector<Eigen::VectorXd> points;
    for (int k = 0; k < count; ++k) points.push_back(Eigen::VectorXd::Constant(1, lo + (hi - lo) * k / (count - 1)));
    return points;
}

// The evaluation of that fidelity with the lowest finite E, or null.
const json* lowestEvaluation(const json& evaluated, const char* fidelity) {
    const json* lowest = nullptr;
    for (const json& e : evaluated)
        if (e.at("fidelity") == fidelity && !e.at("E").is_null() &&
            (!lowest || e.at("E").get<double>() < lowest->at("E").get<double>()))
            lowest = &e;
    return lowest;
}

}  // namespace

std::optional<ProfileFit> fitProfile(const std::vector<std::pair<double, double>>& points, double thetaBest,
                                     double range, bool inverse, json& info) {
    const auto u = [&](double theta) { return inverse ? 1 / theta : std::log(theta); };
    const auto theta = [&](double value) { return inverse ? 1 / value : std::exp(value); };
    std::vector<std::pair<double, double>> near;
    for (const auto& p : points)
        if (std::abs(std::log(p.first / thetaBest)) <= range && std::isfinite(p.second))
            near.emplace_back(u(p.first) - u(thetaBest), p.second);
    info["points"] = near.size();
    info["variable"] = inverse ? "1/θ" : "ln θ";
    if (near.size() < 5) return std::nullopt;
    Eigen::MatrixXd A(near.size(), 3);
    Eigen::VectorXd y(near.size());
    double lowest = INFINITY, highest = -INFINITY;
    for (size_t i = 0; i < near.size(); ++i) {
        A.row(i) << 1, near[i].first, near[i].first * near[i].first;
        y[i] = near[i].second;
        lowest = std::min(lowest, near[i].first);
        highest = std::max(highest, near[i].first);
    }
    const Eigen::Vector3d coef = A.colPivHouseholderQr().solve(y);
    const double squaredResiduals = (A * coef - y).squaredNorm();
    const double rSquared = 1 - squaredResiduals / (y.array() - y.mean()).square().sum();
    // E's jitter: the residuals' spread over the n − 3 degrees of freedom the fit leaves. Their RMS
    // over n reads it √((n − 3)/n) low, 0.63× with the five points a short run often has.
    const double jitter = std::sqrt(squaredResiduals / (near.size() - 3));
    info["coefficients"] = {coef[0], coef[1], coef[2]};
    info["jitter"] = jitter;
    info["r_squared"] = rSquared;
    if (!(coef[2] > 0)) return std::nullopt;
    const double u0 = -coef[1] / (2 * coef[2]);
    const double eMin = coef[0] - coef[1] * coef[1] / (4 * coef[2]);
    const double dE = std::max(2 * jitter, 0.01 * std::abs(eMin));
    const double half = std::sqrt(dE / coef[2]);
    const double uMin = u(thetaBest) + u0;
    info["delta_E"] = dE;
    if (inverse && uMin <= 0) return std::nullopt;  // a vertex beyond 1/θ = 0 has no θ
    ProfileFit fit;
    fit.vertex = theta(uMin);
    fit.vertexAmongPoints = u0 >= lowest && u0 <= highest;
    fit.curvature = coef[2];
    const double lo = uMin - half, hi = uMin + half;
    // In 1/θ the band's lower end may pass 0: then it reaches θ = ∞ (clipped to the bounds later).
    fit.interval = inverse ? std::array<double, 2>{theta(hi), lo > 0 ? theta(lo) : INFINITY}
                           : std::array<double, 2>{theta(lo), theta(hi)};
    info["theta_min"] = fit.vertex;
    return fit;
}

std::optional<double> bracketedVertex(const std::vector<std::pair<double, double>>& points, bool inverse) {
    const std::pair<double, double>* best = nullptr;
    for (const auto& p : points)
        if (std::isfinite(p.second) && (!best || p.second < best->second)) best = &p;
    if (!best) return std::nullopt;
    const std::pair<double, double>*below = nullptr, *above = nullptr;
    for (const auto& p : points) {
        if (!std::isfinite(p.second)) continue;
        if (p.first < best->first && (!below || p.first > below->first)) below = &p;
        if (p.first > best->first && (!above || p.first < above->first)) above = &p;
    }
    if (!below || !above) return std::nullopt;
    const auto u = [&](double theta) { return inverse ? 1 / theta : std::log(theta); };
    // Relative to the lowest point, a = (u, E) below and c above in θ; both E ≥ its E, so the
    // parabola is convex (or flat: then the midpoint) and its vertex lies between them.
    const double ua = u(below->first) - u(best->first), uc = u(above->first) - u(best->first);
    const double ea = below->second - best->second, ec = above->second - best->second;
    const double denominator = ua * ec - uc * ea;
    const double u0 = denominator == 0 ? (ua + uc) / 2 : (ua * ua * ec - uc * uc * ea) / (2 * denominator);
    const double vertex = u(best->first) + u0;
    return inverse ? 1 / vertex : std::exp(vertex);
}

std::vector<std::pair<double, double>> placementMeanProfile(const std::vector<PlacedPoint>& points, bool inverse) {
    const auto u = [&](double theta) { return inverse ? 1 / theta : std::log(theta); };
    struct Node {
        double theta = 0, sumE = 0;
        int count = 0;
        double E() const { return sumE / count; }
    };
    // Each placement's line: u → its point (repeated θ averaged), placements in first-listed order.
    std::vector<std::pair<double, std::map<double, Node>>> lines;
    for (const PlacedPoint& p : points) {
        if (!std::isfinite(p.E)) continue;
        auto line = std::find_if(lines.begin(), lines.end(), [&](const auto& l) { return l.first == p.gridShift; });
        if (line == lines.end()) line = lines.insert(lines.end(), {p.gridShift, {}});
        Node& node = line->second[u(p.theta)];
        node.theta = p.theta;
        node.sumE += p.E;
        ++node.count;
    }
    std::vector<std::pair<double, double>> profile;
    if (lines.empty()) return profile;
    double lo = -INFINITY, hi = INFINITY;
    for (const auto& [shift, line] : lines) {
        lo = std::max(lo, line.begin()->first);
        hi = std::min(hi, line.rbegin()->first);
    }
    const auto at = [](const std::map<double, Node>& line, double x) {
        auto above = line.lower_bound(x);
        if (above->first == x) return above->second.E();
        const auto below = std::prev(above);
        const double w = (x - below->first) / (above->first - below->first);
        return (1 - w) * below->second.E() + w * above->second.E();
    };
    std::map<double, double> nodes;  // u → θ of every point within the common span
    for (const auto& [shift, line] : lines)
        for (const auto& [x, node] : line)
            if (x >= lo && x <= hi) nodes.emplace(x, node.theta);
    for (const auto& [x, theta] : nodes) {
        double sum = 0;
        for (const auto& [shift, line] : lines) sum += at(line, x);
        profile.emplace_back(theta, sum / lines.size());
    }
    if (lines.size() > 1 && !profile.empty()) return profile;
    profile.clear();
    for (const auto& [shift, line] : lines)
        for (const auto& [x, node] : line) profile.emplace_back(node.theta, node.E());
    return profile;
}

// Per evaluation near the coarse best rather than per coarse generation: the first coarse generation
// scans the whole initial range, and its lowest θ costs the most. On the sample cup at η = 300 a
// 77 s scan, the whole coarse phase, predicted 178 s per full generation where 68–77 s were
// measured, and warned that the run would overrun its budget. The first frames are cheap (the
// liquid is still in the cup and the time step long: 0.5 s a frame against 1.0–1.2 s later at
// η = 3, 48³), so scaling by the frame count alone predicted 1.2–1.4× too little at η = 1–3.
double predictedFullEvaluationSeconds(const json& evaluated, int coarseResolution, int fullResolution,
                                      int coarseFrames, int fullFrames) {
    const json* coarseBest = lowestEvaluation(evaluated, kCoarse);
    double sum = 0;
    int count = 0;
    for (const json& e : evaluated) {
        if (e.at("fidelity") != kCoarse) continue;
        bool near = true;
        for (size_t i = 0; coarseBest && i < e.at("theta").size(); ++i)
            near = near && std::abs(std::log(e.at("theta")[i].get<double>() /
                                             coarseBest->at("theta")[i].get<double>())) <= kCoarseToFineShift;
        if (!near) continue;
        double lengthening = (fullFrames + 1.0) / (coarseFrames + 1.0);
        const std::vector<double> frameSeconds = e.value("frame_s", std::vector<double>());
        const size_t tail = std::max<size_t>(1, frameSeconds.size() / 3);
        double all = 0, last = 0;
        for (size_t f = 0; f < frameSeconds.size(); ++f) {
            all += frameSeconds[f];
            if (f + tail >= frameSeconds.size()) last += frameSeconds[f];
        }
        if (all > 0) lengthening = (all + (fullFrames - coarseFrames) * last / tail) / all;
        sum += e.at("seconds").get<double>() * std::pow(double(fullResolution) / coarseResolution, 4) * lengthening;
        ++count;
    }
    return count ? sum / count : 0.0;
}

LogSearchSpace logSearchSpace(const Job& job) {
    const int n = static_cast<int>(job.parameters.size());
    LogSearchSpace space{Eigen::VectorXd(n), Eigen::VectorXd(n), Eigen::VectorXd(n), Eigen::VectorXd(n)};
    for (int i = 0; i < n; ++i) {
        const ParameterSpec& p = job.parameters[i];
        space.lower[i] = std::log(p.lower);
        space.upper[i] = std::log(p.upper);
        space.start[i] = std::log(p.initial);
        space.spread[i] = p.logSpread();
        if (p.logRange() > 0) space.spread[i] = std::min(space.spread[i], p.logRange() / 3);
        space.spread[i] = std::max(space.spread[i], 1e-6);
    }
    return space;
}

std::vector<double> thetaOf(const Eigen::VectorXd& x, const LogSearchSpace& space) {
    std::vector<double> theta(x.size());
    for (Eigen::Index i = 0; i < x.size(); ++i) theta[i] = std::exp(clipped(x[i], space.lower[i], space.upper[i]));
    return theta;
}

double boundPenalty(const Eigen::VectorXd& x, const LogSearchSpace& space) {
    double p = 0;
    for (Eigen::Index i = 0; i < x.size(); ++i) p += std::pow(x[i] - clipped(x[i], space.lower[i], space.upper[i]), 2);
    return p;
}

namespace {

// A doubt is a reason to think θ* wrong, one line each: result.json's "doubts", also sent as warnings.
// The reference's liquid outside what the simulation can ever show, past this share of it: a camera
// or domain that does not match the footage, not extraction noise along the outline.
constexpr double kOutOfViewDoubtShare = 0.05;
// E over the full-fidelity evaluations changes by less than this share of its least value while they
// span at least kFlatSpan in some parameter: the footage does not tell those θ apart.
constexpr double kFlatObjectiveShare = 0.05;
constexpr double kFlatSpan = 2.0;

json doubtsBeforeSearch(const Observation& obs) {
    json doubts = json::array();
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

json doubtsAfterSearch(const Job& job, const LogSearchSpace& bounds, const IdentificationResult& result,
                       const json& evaluated) {
    json doubts = json::array();
    for (size_t i = 0; i < job.parameters.size(); ++i) {
        const std::string& name = job.parameters[i].name();
        const double lower = std::exp(bounds.lower[i]), upper = std::exp(bounds.upper[i]);
        for (const double bound : {lower, upper})
            if (std::abs(std::log(result.interval[i][bound == lower ? 0 : 1] / bound)) < 1e-6) {
                std::ostringstream line;
                line << name << ": the interval reaches the search bound " << bound
                     << ", so the footage does not bound it there";
                doubts.push_back(line.str());
            }
    }
    double least = INFINITY, most = -INFINITY;
    const json* best = nullptr;
    std::vector<double> thetaLow(job.parameters.size(), INFINITY), thetaHigh(job.parameters.size(), 0);
    for (const json& e : evaluated) {
        if (e.at("fidelity") != kFull || e.at("E").is_null()) continue;
        if (e.at("E").get<double>() < least) best = &e;
        least = std::min(least, e.at("E").get<double>());
        most = std::max(most, e.at("E").get<double>());
        for (size_t i = 0; i < thetaLow.size(); ++i) {
            thetaLow[i] = std::min(thetaLow[i], e.at("theta")[i].get<double>());
            thetaHigh[i] = std::max(thetaHigh[i], e.at("theta")[i].get<double>());
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
        const std::string at = "the best evaluation (θ = " + best->at("theta").dump() + ")";
        if (const double lost = best->at("liquid_lost").get<double>(); lost > sim::kLostLiquidShare)
            doubts.push_back(at + " lost " + std::to_string(int(100 * lost)) +
                             " % of its liquid (it left the domain or went into a solid), so θ* fits another amount "
                             "of liquid: check the domain, the solids and the fill");
        if (const int unconverged = best->at("unconverged_frames").get<int>(); unconverged > 0)
            doubts.push_back(at + " had " + std::to_string(unconverged) +
                             " frames whose pressure–viscosity solve stopped short of its tolerance: raise "
                             "solver.max_iterations");
    }
    return doubts;
}

}  // namespace

IdentificationResult identify(const Job& jobIn, const fs::path& outDir, const IdentifyOptions& options) {
    const auto sessionStart = Clock::now();
    fs::create_directories(outDir);
    Job job = jobIn;
    prepareReference(job, outDir);
    const Observations observations = observe(job);
    const Observation& obs = observations.full;
    const Observation& coarseObs = observations.coarse;
    const size_t informativeFrames = informativeSimFrames(obs).size();
    json warnings = json::array();
    if (informativeFrames < size_t(kMinInformativeFrames)) {
        size_t compared = 0;
        for (int f : obs.simFrames) compared += f >= 0;
        warnings.push_back("reference: only " + std::to_string(informativeFrames) + " of " + std::to_string(compared) +
                           " compared frames show liquid outside the excluded region; every θ that keeps the "
                           "liquid out of sight fits as well, so the result is at best a lower bound (use a "
                           "longer clip)");
    }
    json doubts = doubtsBeforeSearch(obs);
    if (options.onWarning) {
        for (const json& w : warnings) options.onWarning(w.get<std::string>());
        for (const json& d : doubts) options.onWarning(d.get<std::string>());
    }
    const int n = static_cast<int>(job.parameters.size());
    const LogSearchSpace bounds = logSearchSpace(job);
    const int fineRes = job.resolution, coarseRes = coarseResolution(job);
    const int fineFrames = lastSimFrame(obs), coarseFrames = lastSimFrame(coarseObs);
    const double coarseTolerance = 0.02 + 10 * job.toleranceX;
    const std::string print = fingerprint(job);
    const fs::path checkpointFile = outDir / "checkpoint.json";

    CmaEsSettings settings;
    settings.populationSize = job.populationSize;
    CmaEs es(bounds.start, bounds.spread, job.seed, settings);
    int coarseEnd = plannedCoarseGenerations(job, obs, coarseObs);
    json evaluated = json::array(), generations = json::array();
    double elapsedBefore = 0;
    json alignmentScores;  // {"theta": [θ*, kAlignmentStep θ*], "E": [E₁, E₂]} of a finished alignment check
    std::optional<StopReason> stop;
    int resumedFrom = 0;
    if (fs::exists(checkpointFile)) {
        json cp;
        try {
            std::ifstream stream(checkpointFile);
            cp = json::parse(stream);
        } catch (const std::exception& e) {
            throw InputError(checkpointFile.string() + ": unreadable checkpoint (" + e.what() +
                             "); delete it or use another --out");
        }
        const json version = cp.is_object() ? cp.value("version", json()) : json();
        if (version != json(kCheckpointVersion))
            throw InputError(checkpointFile.string() + ": checkpoint of another Viscoscope (version " + version.dump() +
                             "); delete it or use another --out");
        if (!sealIsIntact(cp))
            throw InputError(checkpointFile.string() + ": damaged or edited checkpoint (its content_digest does not "
                                                       "match its content); delete it or use another --out");
        if (cp.value("fingerprint", "") != print)
            throw InputError(checkpointFile.string() + ": checkpoint of a different job (or changed scene, camera, "
                                                       "reference); use another --out or delete it");
        es = CmaEs::fromJson(cp.at("cma"));
        coarseEnd = cp.at("coarse_end").get<int>();
        evaluated = cp.at("evaluated");
        generations = cp.at("generations");
        elapsedBefore = cp.at("elapsed_s").get<double>();
        alignmentScores = cp.value("alignment_check", json());
        if (cp.contains("stop") && !cp.at("stop").is_null()) {
            const std::string s = cp.at("stop").get<std::string>();
            for (StopReason r : {StopReason::MaxGenerations, StopReason::ToleranceX, StopReason::ToleranceFun,
                                 StopReason::TimeBudget})
                if (s == toString(r)) stop = r;
            // A finished run continues when max_generations or the time budget was raised.
            if (stop == StopReason::MaxGenerations && es.generation() < job.maxGenerations) stop.reset();
            if (stop == StopReason::TimeBudget) stop.reset();  // decided again below, with this job's budget
        }
        resumedFrom = es.generation();
    } else {
        if (job.hasSilhouettes()) requireCameraSeesLiquid(job, coarseEnd > 0 ? coarseRes : fineRes);
        for (const Job& run : job.otherRuns)
            if (run.hasSilhouettes()) requireCameraSeesLiquid(run, coarseEnd > 0 ? coarseRes : fineRes);
    }

    std::optional<ThreadPool> ownPool;
    EvaluationPool& pool = options.pool ? *options.pool : ownPool.emplace(options.threads);

    // With placements by generation, full-fidelity generation g runs on the grid moved by
    // placementShift(g) cells, the job's placements in turn from the first one on.
    const bool byGeneration = job.placementSchedule == PlacementSchedule::ByGeneration && job.gridPlacements > 1;
    auto placementShift = [&](int g) {
        return byGeneration && g >= coarseEnd ? double((g - coarseEnd) % job.gridPlacements) / job.gridPlacements : 0.0;
    };
    // (θ, E) of the finished full-fidelity evaluations of a one-parameter search; with placements by
    // generation, E's mean over them (placementMeanProfile).
    auto fullFidelityPoints = [&] {
        std::vector<PlacedPoint> points;
        for (const json& e : evaluated)
            if (e.at("fidelity") == kFull && !e.at("E").is_null())
                points.push_back({e.at("theta")[0].get<double>(), e.at("E").get<double>(), e.value("grid_shift", 0.0)});
        if (byGeneration) return placementMeanProfile(points, job.parameters[0].profileInInverse());
        std::vector<std::pair<double, double>> plain;
        for (const PlacedPoint& p : points) plain.emplace_back(p.theta, p.E);
        return plain;
    };
    // The best θ at a fidelity and its E, as {"theta", "E"} (null when there is none): the lowest
    // evaluation, or at full fidelity with placements by generation the lowest point of E's mean.
    auto bestAt = [&](const char* fidelity) -> json {
        if (byGeneration && fidelity == std::string(kFull)) {
            const std::vector<std::pair<double, double>> profile = fullFidelityPoints();
            const auto lowest = std::min_element(profile.begin(), profile.end(),
                                                 [](const auto& a, const auto& b) { return a.second < b.second; });
            if (lowest == profile.end()) return json();
            // The placement θ* was first evaluated on, where its fields come from.
            double shift = 0;
            for (const json& e : evaluated)
                if (e.at("fidelity") == kFull && e.at("theta")[0].get<double>() == lowest->first) {
                    shift = e.value("grid_shift", 0.0);
                    break;
                }
            return json{{"theta", {lowest->first}}, {"E", lowest->second}, {"grid_shift", shift}};
        }
        const json* best = lowestEvaluation(evaluated, fidelity);
        return best ? json{{"theta", best->at("theta")}, {"E", best->at("E")}, {"grid_shift", best->value("grid_shift", 0.0)}}
                    : json();
    };
    auto maxStd = [&] { return es.standardDeviations().maxCoeff(); };
    std::vector<double> genSecondsCoarse, genSecondsFine;
    for (const json& g : generations)
        (g.at("fidelity") == kFull ? genSecondsFine : genSecondsCoarse).push_back(g.at("seconds").get<double>());
    auto mean = [](const std::vector<double>& v) {
        double s = 0;
        for (double x : v) s += x;
        return v.empty() ? 0.0 : s / v.size();
    };
    // Predicted seconds of a full-fidelity generation: the measured ones' mean, else ⌈λ / threads⌉
    // rounds of predictedFullEvaluationSeconds.
    auto fineGenerationSeconds = [&] {
        if (!genSecondsFine.empty()) return mean(genSecondsFine);
        const double threads = pool.concurrency();
        return std::ceil(es.lambda() / threads) *
               predictedFullEvaluationSeconds(evaluated, coarseRes, fineRes, coarseFrames, fineFrames);
    };
    // The alignment check's two evaluations, as a share of a full generation's rounds in the pool,
    // with the margin the minimum generations get (at η = 1 on the sample cup: 61.5 s measured where
    // half the mean full-fidelity generation, 55 s, was predicted).
    const bool alignmentPlanned = job.alignmentCheck && n == 1;
    auto alignmentSeconds = [&] {
        if (!alignmentPlanned) return 0.0;
        const double threads = pool.concurrency();
        return kFineTimeMargin * fineGenerationSeconds() * std::ceil(2 / threads) / std::ceil(es.lambda() / threads);
    };
    auto elapsedNow = [&] { return elapsedBefore + std::chrono::duration<double>(Clock::now() - sessionStart).count(); };
    auto fitsBudget = [&](double seconds) { return job.timeBudget <= 0 || elapsedNow() + seconds <= job.timeBudget; };

    // In one dimension, later full-fidelity generations also score the vertex of the parabola
    // through the best full-fidelity evaluation and its nearest neighbours (bracketedVertex), in
    // place of their last sample; not when an evaluation lies within kProposalSpacing of it, since
    // the same θ scores the same E. With λ = 4 and a spread of ln 1.4, CMA-ES's samples mostly land
    // away from the optimum it brackets: on the η = 30 row, 5 of 16 full evaluations fell within
    // ±7 % and the best was 31.45 (4.8 %); with the proposals, 30.36 (1.2 %), itself a proposal.
    auto parabolicProposal = [&]() -> std::optional<Eigen::VectorXd> {
        const std::vector<std::pair<double, double>> points = fullFidelityPoints();
        const std::optional<double> vertex = bracketedVertex(points, job.parameters[0].profileInInverse());
        if (!vertex) return std::nullopt;
        for (const auto& p : points)
            if (std::abs(std::log(*vertex / p.first)) < kProposalSpacing) return std::nullopt;
        return Eigen::VectorXd::Constant(1, std::log(*vertex));
    };

    auto checkpoint = [&](const Clock::time_point& now) {
        json cp{{"format", "viscoscope.identify_checkpoint"},
                {"version", kCheckpointVersion},
                {"fingerprint", print},
                {"cma", es.toJson()},
                {"coarse_end", coarseEnd},
                {"evaluated", evaluated},
                {"generations", generations},
                {"elapsed_s", elapsedBefore + std::chrono::duration<double>(now - sessionStart).count()},
                {"stop", stop ? json(toString(*stop)) : json()},
                {"alignment_check", alignmentScores}};
        writeJsonAtomically(sealed(cp), checkpointFile);
    };

    while (!stop) {
        const int g = es.generation();
        if (g >= job.maxGenerations) {
            stop = StopReason::MaxGenerations;
            checkpoint(Clock::now());
            break;
        }
        // Predicted with the margin the minimum generations are reserved with: without it, a
        // generation that ran past the mean of those before it ended the η = 30 row of the sample
        // cup's table 5 s past its 600 s budget.
        if (g - coarseEnd >= job.fidelity.minFineGenerations &&
            !fitsBudget(kFineTimeMargin * fineGenerationSeconds() + alignmentSeconds())) {
            stop = StopReason::TimeBudget;
            checkpoint(Clock::now());
            break;
        }
        const bool coarse = g < coarseEnd;
        const int resolution = coarse ? coarseRes : fineRes;
        const char* fidelity = coarse ? kCoarse : kFull;
        const auto genStart = Clock::now();
        std::vector<Eigen::VectorXd> xs = es.ask();
        const bool scan = g == 0 && coarse && n == 1 && xs.size() > 1;
        if (scan) xs = scanPoints(bounds, static_cast<int>(xs.size()));
        // Where each point came from, recorded with its evaluation: a CMA-ES sample, a scan point,
        // or an injected restart point or parabolic proposal.
        std::vector<std::string> origins(xs.size(), scan ? "scan" : "sample");
        // The first full-fidelity generation also scores the restart point, the coarse best, in
        // place of its last sample: with λ = 4 draws of spread ln 1.4, all four can miss the basin
        // the coarse phase found (η = 30: coarse best 28.6, full samples 14.1 / 36.8 / 20.5 / 19.5).
        // An injected mean is a zero step for CMA-ES's update (Hansen 2011, "Injecting external
        // solutions into CMA-ES"), so nothing else changes.
        if (g == coarseEnd && coarseEnd > 0) {
            xs.back() = es.mean();
            origins.back() = "restart";
        } else if (!coarse && n == 1) {
            if (const std::optional<Eigen::VectorXd> proposal = parabolicProposal()) {
                xs.back() = es.injectable(*proposal);
                origins.back() = "parabola";
            }
        }
        const bool stageFields = options.writeFields && !coarse;
        const fs::path staging = outDir / kFieldsStaging;
        fs::remove_all(staging);  // what a killed generation left
        auto stagedFields = [&](size_t k) { return stageFields ? staging / std::to_string(k) : fs::path(); };
        EvaluationBatch batch{{}, coarse, resolution, placementShift(g), {}};
        for (size_t k = 0; k < xs.size(); ++k) {
            batch.thetas.push_back(thetaOf(xs[k], bounds));
            batch.fieldsDirs.push_back(stagedFields(k));
        }
        const double gridShift = batch.gridShift;
        const BatchResult ran = [&] {
            try {
                return pool.evaluate(job, observations, batch);
            } catch (const Cancelled&) {
                throw Cancelled("identification cancelled in generation " + std::to_string(es.generation() + 1) +
                                "; a resume redoes it from the checkpoint");
            }
        }();
        const std::vector<Evaluation>& evals = ran.evaluations;
        const std::vector<std::string>& errors = ran.errors;
        if (g == 0 && job.hasSilhouettes()) {
            double pixels = 0;
            for (const Evaluation& e : evals) pixels += e.simulatedPixels;
            if (pixels == 0) throw InputError(noSimulatedLiquidSeen(job, batch.coarse ? coarseObs : obs, batch.thetas));
        }
        std::vector<double> fitness(xs.size());
        int bestK = 0;
        for (size_t k = 0; k < xs.size(); ++k) {
            fitness[k] = std::isfinite(evals[k].E) ? evals[k].E + boundPenalty(xs[k], bounds) : 1e30;
            if (fitness[k] < fitness[bestK]) bestK = static_cast<int>(k);
            json e = toJson(evals[k]);
            e.update({{"generation", g + 1},
                      {"fidelity", fidelity},
                      {"frames", coarse ? coarseFrames : fineFrames},
                      {"x", vec(std::vector<double>(xs[k].data(), xs[k].data() + xs[k].size()))},
                      {"origin", origins[k]}});
            if (byGeneration) e["grid_shift"] = gridShift;
            if (!errors[k].empty()) e["error"] = errors[k];
            if (!ran.ranks.empty()) e["rank"] = ran.ranks[k];
            evaluated.push_back(e);
        }
        if (stageFields) {
            // The new best full-fidelity evaluation, if this generation made it, keeps its fields.
            const json best = bestAt(kFull);
            const size_t first = evaluated.size() - xs.size();
            for (size_t k = 0; k < xs.size(); ++k)
                if (!best.is_null() && best.at("theta") == evaluated[first + k].at("theta") &&
                    best.at("grid_shift") == gridShift && evals[k].fields)
                    promoteFields(stagedFields(k), fieldsOwner(print, evals[k], gridShift, fineFrames + 1), outDir);
            fs::remove_all(staging);
        }
        es.tell(xs, fitness);
        if (scan) es.restart(xs[bestK], Eigen::VectorXd::Constant(1, std::max(0.5 * (xs[1][0] - xs[0][0]), 1e-6)));
        const double genSeconds = std::chrono::duration<double>(Clock::now() - genStart).count();
        (coarse ? genSecondsCoarse : genSecondsFine).push_back(genSeconds);
        const json best = bestAt(fidelity);
        std::vector<double> meanTheta = thetaOf(es.mean(), bounds);
        const Eigen::VectorXd sd = es.standardDeviations();
        generations.push_back({{"generation", g + 1},
                               {"fidelity", fidelity},
                               {"resolution", resolution},
                               {"grid_shift", gridShift},
                               {"generation_best_E", finiteOrNull(evals[bestK].E)},
                               {"generation_best_theta", vec(evals[bestK].theta)},
                               {"best_E", best.is_null() ? json() : best.at("E")},
                               {"best_theta", best.is_null() ? json() : best.at("theta")},
                               {"mean_theta", vec(meanTheta)},
                               {"sigma", es.sigma()},
                               {"log_std", vec(std::vector<double>(sd.data(), sd.data() + sd.size()))},
                               {"evaluations", es.evaluations()},
                               {"seconds", genSeconds}});

        // Phase switch and stopping rules, decided before the checkpoint so a resume agrees.
        const int done = es.generation();
        if (coarse && done < coarseEnd &&
            (maxStd() < coarseTolerance ||
             (job.timeBudget > 0 &&
              elapsedNow() + mean(genSecondsCoarse) >
                  std::min(kCoarseBudgetShare * job.timeBudget,
                           job.timeBudget - job.fidelity.minFineGenerations * kFineTimeMargin * fineGenerationSeconds() -
                               alignmentSeconds()))))
            coarseEnd = done;
        if (coarse && done == coarseEnd) {
            generations.back()["predicted_fine_generation_s"] = fineGenerationSeconds();  // to check it later
            // The minimum full-fidelity generations run whatever the budget says; when they cannot
            // fit (η = 300 on a 180-frame clip: 2 × 339 s predicted with 440 s left), say so now
            // and how long the run will take, instead of a remaining time that runs out early.
            const double fineMinimum = job.fidelity.minFineGenerations * fineGenerationSeconds();
            const double elapsed = elapsedNow();
            if (job.timeBudget > 0 && elapsed + fineMinimum > job.timeBudget) {
                const std::string warning =
                    "time_budget_s: the " + std::to_string(job.fidelity.minFineGenerations) +
                    " full-fidelity generations every run makes are predicted to take " + wholeSeconds(fineMinimum) +
                    " s with " + wholeSeconds(std::max(0.0, job.timeBudget - elapsed)) + " s of the " +
                    wholeSeconds(job.timeBudget) + " s budget left; the run will end after about " +
                    wholeSeconds(elapsed + fineMinimum) + " s (a shorter clip or a coarser grid takes less)";
                generations.back()["warning"] = warning;  // the result gathers it, after a resume too
                if (options.onWarning) options.onWarning(warning);
            }
            Eigen::VectorXd start = es.mean();
            if (const json coarseBest = bestAt(kCoarse); !coarseBest.is_null())
                for (int i = 0; i < n; ++i) start[i] = std::log(coarseBest.at("theta")[i].get<double>());
            es.restart(start, Eigen::VectorXd::Constant(n, kCoarseToFineShift));
        }
        const int fineDone = done - coarseEnd;
        if (!coarse && fineDone >= job.fidelity.minFineGenerations) {
            if (maxStd() < job.toleranceX) stop = StopReason::ToleranceX;
            else {
                const int window = std::min(fineDone, 10);
                double lo = INFINITY, hi = -INFINITY;
                for (int i = static_cast<int>(generations.size()) - window; i < static_cast<int>(generations.size()); ++i) {
                    const json& v = generations[i].at("generation_best_E");
                    if (v.is_null()) { hi = INFINITY; continue; }
                    lo = std::min(lo, v.get<double>());
                    hi = std::max(hi, v.get<double>());
                }
                if (fineDone >= 10 && hi - lo < job.toleranceFun) stop = StopReason::ToleranceFun;
            }
        }
        if (!stop && done >= job.maxGenerations) stop = StopReason::MaxGenerations;
        const auto now = Clock::now();
        checkpoint(now);

        if (options.onGeneration) {
            GenerationReport report;
            report.generation = done;
            report.generations = job.maxGenerations;
            report.evaluations = es.evaluations();
            report.resolution = resolution;
            report.coarse = coarse;
            if (!best.is_null()) report.bestTheta = best.at("theta").get<std::vector<double>>();
            report.bestE = best.is_null() ? NAN : best.at("E").get<double>();
            report.sigma = es.sigma();
            report.elapsed = elapsedBefore + std::chrono::duration<double>(now - sessionStart).count();
            const int coarseLeft = std::max(0, coarseEnd - done);
            report.remaining = stop ? alignmentSeconds()
                                    : coarseLeft * mean(genSecondsCoarse) +
                                          (job.maxGenerations - std::max(done, coarseEnd)) * fineGenerationSeconds() +
                                          alignmentSeconds();
            if (job.timeBudget > 0 && !stop) {
                const int fineLeft = std::max(0, job.fidelity.minFineGenerations - std::max(0, done - coarseEnd));
                report.remaining = std::min(report.remaining, std::max({0.0, job.timeBudget - report.elapsed,
                                                                        coarseLeft * mean(genSecondsCoarse) +
                                                                            fineLeft * fineGenerationSeconds() +
                                                                            alignmentSeconds()}));
            }
            report.resumed = resumedFrom > 0 && done == resumedFrom + 1;
            options.onGeneration(report);
        }
        if (!stop && cancelRequested())
            throw Cancelled("identification cancelled after generation " + std::to_string(done) + "; checkpoint saved");
    }

    // ---- Results.
    IdentificationResult result;
    result.stop = *stop;
    result.generations = es.generation();
    result.evaluations = es.evaluations();
    result.resumedFromGeneration = resumedFrom;
    json best = bestAt(kFull);
    if (best.is_null()) best = bestAt(kCoarse);
    if (best.is_null()) throw std::runtime_error("no successful evaluation");
    result.theta = best.at("theta").get<std::vector<double>>();
    result.E = best.at("E").get<double>();
    const Eigen::VectorXd sd = es.standardDeviations();
    json params = json::object();
    double alignmentCheckSeconds = 0;
    for (int i = 0; i < n; ++i) {
        const double bestTheta = result.theta[i];
        // The final search distribution: exp(m ± 2σ√C_ii) (a 95 % band of CMA-ES's sampling law in log
        // space, the spread it still considers plausible; not a statistical confidence interval).
        const std::array<double, 2> cma{std::exp(clipped(es.mean()[i] - 2 * sd[i], bounds.lower[i], bounds.upper[i])),
                                        std::exp(clipped(es.mean()[i] + 2 * sd[i], bounds.lower[i], bounds.upper[i]))};
        json entry{{"unit", job.parameters[i].parameter.declaration->unit},
                   {"best_evaluation", bestTheta},
                   {"cma_mean", std::exp(es.mean()[i])},
                   {"cma_interval", cma},
                   {"log_std", sd[i]}};
        std::optional<ProfileFit> profile;
        if (n == 1) {
            json info;
            profile = fitProfile(fullFidelityPoints(), bestTheta, 0.5, job.parameters[i].profileInInverse(), info);
            // A vertex beyond the fitted points is an extrapolation, and so is its band (measured: a
            // vertex at 5.1 over points up to 2.87 gave [2.82, 7.7] for a truth of 3).
            if (profile && !profile->vertexAmongPoints) profile.reset();
            entry["profile_fit"] = info;
            if (profile)
                entry["profile_interval"] = {profile->interval[0],
                                             std::min(profile->interval[1], std::exp(bounds.upper[i]))};
        }
        entry["value"] = result.theta[i];
        // The reported interval: the profile band when the fit is convex with its vertex among the
        // points, else the CMA band; always widened to contain θ*, and by the alignment check.
        std::array<double, 2> band = profile ? profile->interval : cma;
        std::optional<double> alignmentSpread;  // |ln(θ_s/θ*)|
        if (alignmentPlanned) {
            const double checkShift = kAlignmentShift / job.gridPlacements;
            json check{{"grid_shift_cells", {checkShift, checkShift, 0.0}}};
            const std::array<double, 2> thetas{bestTheta, kAlignmentStep * bestTheta};
            // A rerun of a finished job (or one killed after the check) takes the scores from the
            // checkpoint instead of simulating them again.
            const bool cached = alignmentScores.is_object() && alignmentScores.at("theta") == json(thetas);
            if (!profile) {
                check["skipped"] = "no profile fit to take E's curvature from";
            } else if (!cached && !fitsBudget(alignmentSeconds())) {
                // The minimum full-fidelity generations may have spent the budget (η = 300 on the
                // sample cup: 555 s of 600, and the check took 76 s more).
                const std::string warning = "alignment_check: skipped, its two evaluations (about " +
                                            wholeSeconds(alignmentSeconds()) + " s) do not fit time_budget_s (" +
                                            wholeSeconds(job.timeBudget) +
                                            " s); the interval leaves out the grid's share of the error";
                check["skipped"] = warning;
                warnings.push_back(warning);
                if (options.onWarning) options.onWarning(warning);
            } else {
                if (!cached) {
                    const auto checkStart = Clock::now();
                    const BatchResult shifted =
                        pool.evaluate(job, observations, {{{thetas[0]}, {thetas[1]}}, false, fineRes, checkShift, {}});
                    const std::array<double, 2> E{shifted.evaluations[0].E, shifted.evaluations[1].E};
                    alignmentCheckSeconds = std::chrono::duration<double>(Clock::now() - checkStart).count();
                    check["seconds"] = alignmentCheckSeconds;
                    alignmentScores = {{"theta", thetas},
                                       {"E", json::array({finiteOrNull(E[0]), finiteOrNull(E[1])})},
                                       {"errors", shifted.errors}};
                    checkpoint(Clock::now());
                }
                std::array<double, 2> E{NAN, NAN};
                for (int k = 0; k < 2; ++k)
                    if (!alignmentScores.at("E")[k].is_null()) E[k] = alignmentScores.at("E")[k].get<double>();
                check["from_checkpoint"] = cached;
                check["theta"] = thetas;
                check["E"] = alignmentScores.at("E");
                const std::optional<double> shifted =
                    std::isfinite(E[0]) && std::isfinite(E[1])
                        ? shiftedMinimum(*profile, job.parameters[i].profileInInverse(), thetas, E)
                        : std::nullopt;
                if (shifted) {
                    check["theta_min"] = std::isfinite(*shifted) ? json(*shifted) : json("infinite");
                    alignmentSpread = std::isfinite(*shifted) ? std::abs(std::log(*shifted / bestTheta)) : INFINITY;
                } else {
                    check["failed"] = std::isfinite(E[0]) && std::isfinite(E[1]) ? json("no finite minimum")
                                                                                   : alignmentScores.at("errors");
                }
            }
            entry["alignment_check"] = check;
        }
        if (alignmentSpread) {
            band[0] = std::min(band[0], bestTheta * std::exp(-*alignmentSpread));
            band[1] = std::max(band[1], bestTheta * std::exp(*alignmentSpread));
        }
        band[0] = std::max(std::min(band[0], result.theta[i]), std::exp(bounds.lower[i]));
        band[1] = std::min(std::max(band[1], result.theta[i]), std::exp(bounds.upper[i]));
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
    const double elapsed = elapsedBefore + std::chrono::duration<double>(Clock::now() - sessionStart).count();
    double evalSeconds = 0;
    json perFidelity = json::object();
    for (const json& e : evaluated) {
        evalSeconds += e.at("seconds").get<double>();
        json& r = perFidelity[e.at("fidelity").get<std::string>()];
        if (r.is_null())
            r = {{"resolution", e.at("resolution")}, {"frames", e.at("frames")}, {"evaluations", 0}, {"seconds", 0.0},
                 {"simulation_s", 0.0}, {"silhouette_s", 0.0}, {"fields_s", 0.0}};
        r["evaluations"] = r.value("evaluations", 0) + 1;
        r["simulation_s"] = r["simulation_s"].get<double>() + e.value("simulation_s", 0.0);
        r["silhouette_s"] = r["silhouette_s"].get<double>() + e.value("silhouette_s", 0.0);
        r["fields_s"] = r["fields_s"].get<double>() + e.value("fields_s", 0.0);
        r["seconds"] = r.value("seconds", 0.0) + e.at("seconds").get<double>();
    }
    for (auto& [key, r] : perFidelity.items()) r["mean_seconds"] = r["seconds"].get<double>() / r["evaluations"].get<int>();

    for (const json& g : generations)
        if (g.contains("warning")) warnings.push_back(g.at("warning"));
    for (const json& d : doubtsAfterSearch(job, bounds, result, evaluated)) {
        if (options.onWarning) options.onWarning(d.get<std::string>());
        doubts.push_back(d);
    }
    for (const json& d : doubts) warnings.push_back(d);
    json fixedParameters = json::object();
    for (const FixedParameter& f : job.fixed)
        fixedParameters[f.parameter.name] = {
            {"value", f.value}, {"uncertainty", f.uncertainty}, {"unit", f.parameter.declaration->unit}};
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
             {"resolution", fineRes},
             {"frames", fineFrames},
             {"grid_placements", job.gridPlacements},
             {"coarse_resolution", coarseRes},
             {"coarse_frames", coarseFrames},
             {"coarse_generations", coarseEnd},
             {"fidelity_policy", "generations 1.." + std::to_string(coarseEnd) + " at resolution " +
                                     std::to_string(coarseRes) + " over simulation frames 0.." +
                                     std::to_string(coarseFrames) + ", the rest at " + std::to_string(fineRes) +
                                     " over 0.." + std::to_string(fineFrames) +
                                     (byGeneration ? "; full-fidelity generations on the " +
                                                         std::to_string(job.gridPlacements) +
                                                         " grid placements in turn, θ* the minimum of E's mean over them"
                                                   : std::string("; θ* is the best full-fidelity evaluation"))},
             {"resumed_from_generation", resumedFrom},
             {"reference_informative_frames", informativeFrames},
             {"ground_band_m", job.groundBand},
             {"warnings", warnings},
             {"doubts", doubts},
             {"compared_pixels",
              {{"left_out_never_visible", obs.neverVisiblePixels},
               {"left_out_liquid_in_background", obs.inBackgroundPixels},
               {"reference_liquid_out_of_view_share", obs.referenceOutOfView}}},
             {"history", generations},
             {"evaluated", evaluated},
             {"timings", {{"wall_s", elapsed},
                          {"evaluation_cpu_s", evalSeconds},
                          {"per_fidelity", perFidelity},
                          {"alignment_check_s", alignmentCheckSeconds}}}};
    if (params.contains("viscosity")) doc["viscosity"] = params["viscosity"];
    // With several runs, how well θ* fits each: its evaluation's E per run, on the placement its
    // fields come from.
    for (const json& e : evaluated)
        if (e.contains("run_E") && e.at("theta") == best.at("theta") &&
            e.value("grid_shift", 0.0) == best.at("grid_shift").get<double>()) {
            doc["run_E"] = e.at("run_E");
            break;
        }
    if (options.writeFields) {
        const auto fieldsStart = Clock::now();
        const double bestShift = best.at("grid_shift").get<double>();
        json owner = fieldsOf(outDir, print, result.theta, fineRes, bestShift, fineFrames + 1);
        const bool kept = !owner.is_null();
        if (!kept) {
            const fs::path staged = outDir / kFieldsStaging / "best";
            const Evaluation ev = evaluate(job, obs, result.theta, fineRes, staged, bestShift);
            owner = fieldsOwner(print, ev, bestShift, fineFrames + 1);
            promoteFields(staged, owner, outDir);
            fs::remove_all(outDir / kFieldsStaging);
        }
        doc["fields"] = {{"folder", kFieldsFolder},
                         {"frames", owner.at("frames")},
                         {"grid_shift_cells", bestShift},
                         {"mean_ground_speed_m_s", owner.at("mean_ground_speed_m_s")},
                         {"source", kept ? "the best evaluation's run" : "θ* simulated again"},
                         {"seconds", std::chrono::duration<double>(Clock::now() - fieldsStart).count()}};
    }
    // Every evaluation as CSV for plotting.
    writeFileAtomically(outDir / "evaluations.csv", [&](std::ostream& csv) {
        csv << "generation,fidelity,resolution,frames";
        for (const ParameterSpec& p : job.parameters) csv << "," << p.name();
        csv << ",E,seconds,origin\n";
        csv << std::setprecision(17);
        for (const json& e : evaluated) {
            csv << e.at("generation").get<int>() << "," << e.at("fidelity").get<std::string>() << ","
                << e.at("resolution").get<int>() << "," << e.at("frames").get<int>();
            for (const json& t : e.at("theta")) csv << "," << t.get<double>();
            csv << ",";
            if (e.at("E").is_null()) csv << "nan";
            else csv << e.at("E").get<double>();
            csv << "," << e.at("seconds").get<double>() << "," << e.value("origin", "") << "\n";  // older checkpoints have none
        }
    });
    result.seconds = elapsed;
    result.document = doc;
    writeJsonAtomically(doc, outDir / "result.json");
    return result;
}

}  // namespace viscoscope::identify
