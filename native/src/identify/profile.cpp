// E's profile near its best: the parabola fit, the bracketed vertex, the mean over placements.
#include "identify/profile.h"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <map>

namespace viscoscope::identify {

using json = nlohmann::json;

namespace {
// The joint profile's quadric is fitted over the points whose E lies within this factor of the least.
constexpr double kLowEFactor = 3;
}  // namespace

double profileVariable(bool inverse, double theta) { return inverse ? 1 / theta : std::log(theta); }
double profileParameter(bool inverse, double u) { return inverse ? 1 / u : std::exp(u); }

std::optional<ProfileFit> fitProfile(const std::vector<std::pair<double, double>>& points, double thetaBest,
                                     double range, bool inverse, json& info) {
    const auto u = [&](double theta) { return profileVariable(inverse, theta); };
    const auto theta = [&](double value) { return profileParameter(inverse, value); };
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
    // over n reads it √((n − 3)/n) low, √(2/5) with the five points a short run often has.
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
    fit.jitter = jitter;
    const double lo = uMin - half, hi = uMin + half;
    // In 1/θ the band's lower end may pass 0: then it reaches θ = ∞ (clipped to the bounds later).
    fit.interval = inverse ? std::array<double, 2>{theta(hi), lo > 0 ? theta(lo) : INFINITY}
                           : std::array<double, 2>{theta(lo), theta(hi)};
    info["theta_min"] = fit.vertex;
    return fit;
}

std::optional<JointProfileFit> fitJointProfile(const std::vector<std::pair<std::vector<double>, double>>& points,
                                               const std::vector<double>& thetaBest, double range, json& info) {
    const int d = static_cast<int>(thetaBest.size());
    const int coefficients = (d + 1) * (d + 2) / 2;
    // x relative to the best, so that the constant term is E there and the fit well conditioned.
    std::vector<Eigen::VectorXd> near;
    std::vector<double> E;
    for (const auto& [theta, e] : points) {
        if (!std::isfinite(e) || theta.size() != thetaBest.size()) continue;
        Eigen::VectorXd x(d);
        for (int i = 0; i < d; ++i) x[i] = std::log(theta[i] / thetaBest[i]);
        if (x.cwiseAbs().maxCoeff() > range) continue;
        near.push_back(x);
        E.push_back(e);
    }
    if (near.size() < size_t(2 * coefficients)) {
        info["points"] = near.size();
        return std::nullopt;
    }
    // Only where E is low: across a ridge E rises steeply and far from quadratically, and the misfit,
    // read as jitter, would widen ΔE (FINDINGS, "Several parameters: the joint profile"). The points
    // within kLowEFactor of the least, or else the 2 × coefficients lowest.
    std::vector<size_t> order(near.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return E[a] < E[b]; });
    size_t kept = 2 * coefficients;
    while (kept < order.size() && E[order[kept]] <= kLowEFactor * E[order.front()]) ++kept;
    order.resize(kept);
    const int m = static_cast<int>(kept);
    info["points"] = m;
    info["variable"] = "ln θ";
    // Columns 1, x_i, then ½x_i² and x_i x_j (i < j), so that the coefficients are E, g and H.
    Eigen::MatrixXd A(m, coefficients);
    Eigen::VectorXd y(m);
    for (int r = 0; r < m; ++r) {
        const Eigen::VectorXd& x = near[order[r]];
        int c = 0;
        A(r, c++) = 1;
        for (int i = 0; i < d; ++i) A(r, c++) = x[i];
        for (int i = 0; i < d; ++i)
            for (int j = i; j < d; ++j) A(r, c++) = i == j ? 0.5 * x[i] * x[i] : x[i] * x[j];
        y[r] = E[order[r]];
    }
    const Eigen::VectorXd coef = A.colPivHouseholderQr().solve(y);
    const Eigen::VectorXd fitted = A * coef;
    const double jitter = std::sqrt((fitted - y).squaredNorm() / (m - coefficients));
    const Eigen::VectorXd g = coef.segment(1, d);
    Eigen::MatrixXd H(d, d);
    for (int i = 0, c = 1 + d; i < d; ++i)
        for (int j = i; j < d; ++j) H(i, j) = H(j, i) = coef[c++];
    const Eigen::VectorXd curvatures = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(H).eigenvalues();
    Eigen::VectorXd lowest = near[order.front()], highest = lowest;
    for (size_t k : order) lowest = lowest.cwiseMin(near[k]), highest = highest.cwiseMax(near[k]);
    std::optional<Eigen::VectorXd> vertex;
    if (curvatures.minCoeff() > 0) {
        const Eigen::VectorXd v = H.ldlt().solve(-g);
        if ((v.array() >= lowest.array()).all() && (v.array() <= highest.array()).all()) vertex = v;
    }
    JointProfileFit fit;
    const double least = vertex ? coef[0] + 0.5 * g.dot(*vertex) : fitted.minCoeff();
    const double deltaE = std::max(2 * jitter, 0.01 * std::abs(least));
    // Every point E cannot tell from the least, also beyond `range` (a ridge runs on past it): the
    // quadric alone would leave out a curved valley's far points, whose misfit it reads as jitter.
    fit.interval.assign(d, {INFINITY, 0});
    const auto include = [&](int i, double theta) {
        fit.interval[i] = {std::min(fit.interval[i][0], theta), std::max(fit.interval[i][1], theta)};
    };
    for (const auto& [at, e] : points)
        if (at.size() == thetaBest.size() && e <= least + deltaE) {
            for (int i = 0; i < d; ++i) include(i, at[i]);
            fit.indistinguishable.push_back(at);
        }
    if (vertex) {
        const Eigen::MatrixXd covariance = H.inverse();
        std::vector<double> thetaMin;
        for (int i = 0; i < d; ++i) {
            const double half = std::sqrt(2 * deltaE * covariance(i, i));
            include(i, thetaBest[i] * std::exp((*vertex)[i] - half));
            include(i, thetaBest[i] * std::exp((*vertex)[i] + half));
            thetaMin.push_back(thetaBest[i] * std::exp((*vertex)[i]));
        }
        fit.bounded = true;
        info["theta_min"] = thetaMin;
    }
    for (int i = 0; i < d; ++i) include(i, thetaBest[i]);
    info["jitter"] = jitter;
    info["delta_E"] = deltaE;
    info["curvatures"] = std::vector<double>(curvatures.data(), curvatures.data() + d);
    info["bounded"] = fit.bounded;
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
    const auto u = [&](double theta) { return profileVariable(inverse, theta); };
    // Relative to the lowest point, a = (u, E) below and c above in θ; both E ≥ its E, so the
    // parabola is convex (or flat: then the midpoint) and its vertex lies between them.
    const double ua = u(below->first) - u(best->first), uc = u(above->first) - u(best->first);
    const double ea = below->second - best->second, ec = above->second - best->second;
    const double denominator = ua * ec - uc * ea;
    const double u0 = denominator == 0 ? (ua + uc) / 2 : (ua * ua * ec - uc * uc * ea) / (2 * denominator);
    const double vertex = u(best->first) + u0;
    return profileParameter(inverse, vertex);
}

std::vector<std::pair<double, double>> placementMeanProfile(const std::vector<PlacedPoint>& points, bool inverse) {
    const auto u = [&](double theta) { return profileVariable(inverse, theta); };
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

}  // namespace viscoscope::identify
