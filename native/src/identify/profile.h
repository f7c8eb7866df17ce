// E as a function of one parameter near its best: the profile fit that gives the interval, the
// parabolic proposal, and E's mean over grid placements.
#pragma once

#include <nlohmann/json.hpp>

#include <array>
#include <optional>
#include <utility>
#include <vector>

namespace viscoscope::identify {

// The profile's variable u for a value θ of the parameter, and back: u = 1/θ when `inverse`, else
// ln θ (see fitProfile for why).
double profileVariable(bool inverse, double theta);
double profileParameter(bool inverse, double u);

// The profile of E around the best full-fidelity evaluation θ_b of a single parameter: a
// least-squares parabola E ≈ a + b u + c u² over the points (θ, E) with |ln θ − ln θ_b| ≤ `range`
// (`inverse`: u = 1/θ, else ln θ), at least five of them; `info` receives the fit's figures.
// For viscosity u = 1/θ: a creeping flow moves at speeds ∝ 1/η, so a frame at time t looks like
// the truth's at t·η_true/η and E grows about evenly in 1/η − 1/η_true on both sides, while in ln θ
// its valley is steeper below the truth than above, and a parabola there puts the vertex high
// (tests/bench/FINDINGS.md, "The profile interval"). For other parameters u = ln θ. The interval is
// where the parabola stays within ΔE of its minimum, ΔE = 2 × the jitter in E (the residuals'
// standard deviation, √(Σr²/(n − 3))), at least E_min/100.
struct ProfileFit {
    double vertex = 0;                 // θ at the parabola's minimum
    std::array<double, 2> interval{};  // θ
    bool vertexAmongPoints = false;    // within the span of the fitted points (no extrapolation)
    double curvature = 0;              // c of E ≈ a + b u + c u²
    double jitter = 0;                 // E's scatter about the parabola
};
std::optional<ProfileFit> fitProfile(const std::vector<std::pair<double, double>>& points, double thetaBest,
                                     double range, bool inverse, nlohmann::json& info);
// E near its best in several parameters, the joint profile: a least-squares quadric in x = ln θ,
// E ≈ a + gᵀ(x − x_b) + ½ (x − x_b)ᵀ H (x − x_b), over the points (θ, E) within `range` of the best
// θ_b in every ln θ_i where E is low (see kLowEFactor; at least twice as many as the quadric's
// coefficients, the lowest; none with fewer in range); ΔE = max(2 × jitter, E_min/100) as in
// fitProfile. Each parameter's interval spans every point, within `range` or not, whose E lies
// within ΔE of the quadric's least, and where H is positive definite with its vertex
// within the points' span (bounded), also where the quadric, minimized over the other parameters,
// stays within ΔE of its least: x_v,i ± √(2ΔE (H⁻¹)_ii). Not bounded, E has no minimum along some
// line among the points: the parameters trade off along a ridge the data do not resolve, as a power
// law's K and n do over the narrow range of shear rates one flow exercises. The search's
// distribution, by contrast, narrows wherever the search happens to wander.
// `info` receives the figures: points, jitter, delta_E, curvatures (H's eigenvalues), bounded and,
// when bounded, theta_min (the quadric's vertex).
struct JointProfileFit {
    std::vector<std::array<double, 2>> interval;  // θ, per parameter
    bool bounded = false;                         // H positive definite, its vertex among the points
    std::vector<std::vector<double>> indistinguishable;  // θ of the points within ΔE of its least
};
std::optional<JointProfileFit> fitJointProfile(const std::vector<std::pair<std::vector<double>, double>>& points,
                                               const std::vector<double>& thetaBest, double range,
                                               nlohmann::json& info);

// The vertex of the parabola through the lowest point (θ, E) and its nearest neighbours in θ on
// either side (u = 1/θ when `inverse`, else ln θ, as for fitProfile): one step of successive
// parabolic interpolation, the proposal a one-parameter search injects (see identification.cpp).
// None when the lowest point has no neighbour on one side, or E is not finite there.
std::optional<double> bracketedVertex(const std::vector<std::pair<double, double>>& points, bool inverse);

// E's mean over grid placements as a profile, from evaluations that each ran on one placement (the
// job's "by_generation" schedule): `points` are (θ, E, grid shift). Each placement's points are
// joined by straight lines in u (1/θ when `inverse`, else ln θ; repeated θ averaged), and at every
// point's θ where all placements' lines reach, the profile holds the mean of their E there. The
// lines, not a fitted curve, because E is often a V near its minimum (FINDINGS, "The profile
// interval") and a parabola misplaces its tip. Points of a single placement are returned as they
// are; without a common span, every placement's points as they are (a run cut short by its time
// budget after one generation on each placement, their samples apart, would otherwise lose the
// better half: η = 1 on the sample cup, its first placement's points all below 0.71, the other's
// lowest E at 1.023).
struct PlacedPoint {
    double theta = 0, E = 0, gridShift = 0;
};
std::vector<std::pair<double, double>> placementMeanProfile(const std::vector<PlacedPoint>& points, bool inverse);

}  // namespace viscoscope::identify
