// The search space the optimizer sees.
//
// Parameters are searched in log space: the optimizer sees x = ln θ, so θ = exp(x) > 0 always;
// bounds [min, max] become [ln min, ln max] and a sample outside them is clipped to the boundary
// for evaluation (the CMA-ES state keeps the unclipped sample; the objective gets a quadratic
// penalty on the clipped distance, as in pycma's BoundPenalty, so the mean is pulled back inside).
#pragma once

#include "identify/job.h"

#include <Eigen/Core>

#include <vector>

namespace viscoscope::identify {

// Shared with benchmarks that run other optimizers on the same job.
struct LogSearchSpace {
    Eigen::VectorXd lower, upper;  // ln min, ln max
    Eigen::VectorXd start;         // ln θ0
    Eigen::VectorXd spread;        // ln(1 + spread/θ0), at most a third of the range, at least 1e-6
};
LogSearchSpace logSearchSpace(const Job& job);
// θ = exp(x clipped into the bounds).
std::vector<double> thetaOf(const Eigen::VectorXd& x, const LogSearchSpace& space);
// Σ (x − clip(x))², the squared distance outside the bounds, which CMA-ES adds to E.
double boundPenalty(const Eigen::VectorXd& x, const LogSearchSpace& space);

}  // namespace viscoscope::identify
