// The search space the optimizer sees: log θ within the job's bounds.
#include "identify/search_space.h"

#include <algorithm>
#include <cmath>

namespace viscoscope::identify {

namespace {

double clipped(double x, double lo, double hi) { return std::min(hi, std::max(lo, x)); }

}  // namespace

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

}  // namespace viscoscope::identify
