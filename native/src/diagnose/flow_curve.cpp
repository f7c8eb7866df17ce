// The fitted law's flow curve (flow_curve.h).
#include "diagnose/flow_curve.h"

#include "sim/sim.h"

#include <algorithm>
#include <cmath>

namespace viscoscope::diagnose {

using json = nlohmann::json;
using namespace identify;

namespace {

constexpr int kCurvePoints = 16;  // log-spaced over the range

std::vector<double> logSpaced(double low, double high, int count) {
    std::vector<double> rates;
    for (int k = 0; k < count; ++k) rates.push_back(low * std::pow(high / low, count > 1 ? double(k) / (count - 1) : 0.0));
    return rates;
}

// The rheometer's stress at γ̇, interpolated linearly in log γ̇ and log τ (γ̇ within its span).
double rheometerStress(const std::vector<std::array<double, 2>>& curve, double rate) {
    const auto above = std::lower_bound(curve.begin(), curve.end(), rate,
                                        [](const std::array<double, 2>& point, double g) { return point[0] < g; });
    if (above == curve.begin()) return curve.front()[1];
    if (above == curve.end()) return curve.back()[1];
    const std::array<double, 2>& a = *(above - 1);
    const std::array<double, 2>& b = *above;
    if (b[0] == a[0]) return b[1];
    const double t = std::log(rate / a[0]) / std::log(b[0] / a[0]);
    return std::exp(std::log(a[1]) + t * std::log(b[1] / a[1]));
}

}  // namespace

json flowCurve(const ModelFit& fit, const Job& model) {
    if (!fit.shearRateRange) return json();
    const auto [low, high] = *fit.shearRateRange;
    const auto stress = [](const Material& material, double rate) { return rate * sim::apparentViscosity(material, rate); };
    const Material best = sceneWithParameters(model, fit.theta, model.resolution).material;
    // The band's materials: with several parameters, every evaluation E cannot tell from θ*, since
    // the corners of the intervals' box lie off the ridge along which such parameters trade off (a
    // power law's high K with its high n); else every corner of that box, 2^k materials for k.
    std::vector<Material> band;
    for (const std::vector<double>& theta : fit.indistinguishable)
        band.push_back(sceneWithParameters(model, theta, model.resolution).material);
    const size_t k = fit.theta.size();
    const bool corners = band.empty();
    for (size_t mask = 0; corners && k > 0 && fit.interval.size() == k && mask < (size_t(1) << k); ++mask) {
        std::vector<double> corner = fit.theta;
        for (size_t i = 0; i < k; ++i) corner[i] = fit.interval[i][(mask >> i) & 1];
        band.push_back(sceneWithParameters(model, corner, model.resolution).material);
    }
    json points = json::array();
    for (double rate : logSpaced(low, high, kCurvePoints)) {
        json point{{"shear_rate_per_s", rate}, {"stress_pa", stress(best, rate)},
                   {"viscosity_pa_s", sim::apparentViscosity(best, rate)}};
        if (!band.empty()) {
            double least = INFINITY, greatest = -INFINITY;
            for (const Material& material : band) {
                least = std::min(least, stress(material, rate));
                greatest = std::max(greatest, stress(material, rate));
            }
            point["stress_band_pa"] = {least, greatest};
        }
        points.push_back(point);
    }
    json curve{{"model", fit.model}, {"shear_rate_range_per_s", {low, high}}, {"points", points}};
    if (!model.rheometer.empty()) {
        const double from = std::max(low, model.rheometer.front()[0]), to = std::min(high, model.rheometer.back()[0]);
        json compared{{"points", model.rheometer}};
        if (from <= to) {
            double squares = 0;
            const std::vector<double> rates = logSpaced(from, to, kCurvePoints);
            for (double rate : rates) squares += std::pow(std::log10(stress(best, rate) / rheometerStress(model.rheometer, rate)), 2);
            compared["shear_rate_range_per_s"] = {from, to};
            compared["log_stress_rms"] = std::sqrt(squares / double(rates.size()));
        } else {
            compared["log_stress_rms"] = nullptr;  // the rheometer does not reach the flow's rates
        }
        curve["rheometer"] = compared;
    }
    return curve;
}

}  // namespace viscoscope::diagnose
