// CMA-ES following Hansen, "The CMA Evolution Strategy: A Tutorial" (arXiv:1604.00772), Table 1
// default strategy parameters with positive log-weights (no active update), as pycma's purecma.
#include "identify/identify.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>

namespace viscoscope::identify {

namespace {

nlohmann::json vectorToJson(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

Eigen::VectorXd vectorFromJson(const nlohmann::json& j) {
    const std::vector<double> values = j.get<std::vector<double>>();
    return Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
}

}  // namespace

int populationSize(int dimension, const CmaEsSettings& settings) {
    return settings.populationSize > 0 ? settings.populationSize
                                       : 4 + static_cast<int>(std::floor(3 * std::log(static_cast<double>(dimension))));
}

CmaEs::CmaEs(const Eigen::VectorXd& initialMean, double initialSigma, std::uint64_t seed,
             const CmaEsSettings& settings)
    : CmaEs(initialMean, Eigen::VectorXd::Constant(initialMean.size(), initialSigma), seed, settings) {}

CmaEs::CmaEs(const Eigen::VectorXd& initialMean, const Eigen::VectorXd& initialSpreads, std::uint64_t seed,
             const CmaEsSettings& settings)
    : n_(static_cast<int>(initialMean.size())), seed_(seed), random_(seed) {
    if (n_ < 1) throw std::invalid_argument("CmaEs: dimension must be ≥ 1");
    lambda_ = populationSize(n_, settings);
    if (lambda_ < 2) throw std::invalid_argument("CmaEs: population size must be ≥ 2");
    setStrategyParameters();
    restart(initialMean, initialSpreads);
}

void CmaEs::restart(const Eigen::VectorXd& mean, const Eigen::VectorXd& spreads) {
    if (mean.size() != n_ || spreads.size() != n_ || !(spreads.array() > 0).all() || !spreads.allFinite() ||
        !mean.allFinite())
        throw std::invalid_argument("CmaEs: mean and spreads must be finite, of the dimension, spreads > 0");
    mean_ = mean;
    sigma_ = spreads.maxCoeff();
    C_ = (spreads / sigma_).array().square().matrix().asDiagonal();
    pSigma_ = Eigen::VectorXd::Zero(n_);
    pC_ = Eigen::VectorXd::Zero(n_);
    updateEigenDecomposition();
}

void CmaEs::restartWithCovariance(const Eigen::VectorXd& mean, const Eigen::MatrixXd& covariance) {
    if (covariance.rows() != n_ || covariance.cols() != n_ || !covariance.allFinite() ||
        covariance.llt().info() != Eigen::Success)
        throw std::invalid_argument("CmaEs: the covariance must be finite, positive definite and of the dimension");
    restart(mean, covariance.diagonal().cwiseSqrt().eval());
    C_ = covariance / (sigma_ * sigma_);
    updateEigenDecomposition();
}

void CmaEs::setStrategyParameters() {
    const double n = n_;
    mu_ = lambda_ / 2;
    weights_.resize(mu_);
    for (int i = 0; i < mu_; ++i) weights_[i] = std::log((lambda_ + 1) / 2.0) - std::log(i + 1.0);
    weights_ /= weights_.sum();
    muEff_ = 1 / weights_.squaredNorm();
    cSigma_ = (muEff_ + 2) / (n + muEff_ + 5);
    dSigma_ = 1 + 2 * std::max(0.0, std::sqrt((muEff_ - 1) / (n + 1)) - 1) + cSigma_;
    cC_ = (4 + muEff_ / n) / (n + 4 + 2 * muEff_ / n);
    const double alphaCov = 2;
    c1_ = alphaCov / ((n + 1.3) * (n + 1.3) + muEff_);
    cMu_ = std::min(1 - c1_, alphaCov * (muEff_ - 2 + 1 / muEff_) / ((n + 2) * (n + 2) + alphaCov * muEff_ / 2));
    chiN_ = std::sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n * n));
}

void CmaEs::updateEigenDecomposition() {
    C_ = (C_ + C_.transpose()) / 2;  // keep it exactly symmetric
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(C_);
    if (solver.info() != Eigen::Success) throw std::runtime_error("CmaEs: eigen decomposition failed");
    B_ = solver.eigenvectors();
    D_ = solver.eigenvalues().cwiseMax(1e-300).cwiseSqrt();
}

double CmaEs::standardNormal() {
    // Box–Muller from two 53-bit uniforms; no cached second value, so the state is just the engine.
    const double u1 = (static_cast<double>(random_() >> 11) + 0.5) * 0x1.0p-53;
    const double u2 = static_cast<double>(random_() >> 11) * 0x1.0p-53;
    return std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
}

std::vector<Eigen::VectorXd> CmaEs::ask() {
    std::vector<Eigen::VectorXd> candidates;
    candidates.reserve(lambda_);
    for (int k = 0; k < lambda_; ++k) {
        Eigen::VectorXd z(n_);
        for (int i = 0; i < n_; ++i) z[i] = standardNormal();
        candidates.push_back(mean_ + sigma_ * (B_ * D_.asDiagonal() * z));
    }
    return candidates;
}

void CmaEs::tell(const std::vector<Eigen::VectorXd>& candidates, const std::vector<double>& fitness) {
    if (static_cast<int>(candidates.size()) != lambda_ || fitness.size() != candidates.size())
        throw std::invalid_argument("CmaEs::tell: expected λ candidates and as many fitness values");
    std::vector<int> order(lambda_);
    std::iota(order.begin(), order.end(), 0);
    // NaN sorts last; ties keep the candidate order (stable), so results never depend on sorting.
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
        const double fa = std::isnan(fitness[a]) ? INFINITY : fitness[a];
        const double fb = std::isnan(fitness[b]) ? INFINITY : fitness[b];
        return fa < fb;
    });
    const Eigen::VectorXd oldMean = mean_;
    Eigen::MatrixXd y(n_, mu_);
    for (int i = 0; i < mu_; ++i) y.col(i) = (candidates[order[i]] - oldMean) / sigma_;
    const Eigen::VectorXd yw = y * weights_;
    mean_ = oldMean + sigma_ * yw;  // c_m = 1

    // C^{-1/2} y_w = B D^{-1} Bᵀ y_w
    const Eigen::VectorXd invSqrtCyw = B_ * (B_.transpose() * yw).cwiseQuotient(D_);
    pSigma_ = (1 - cSigma_) * pSigma_ + std::sqrt(cSigma_ * (2 - cSigma_) * muEff_) * invSqrtCyw;
    ++generation_;
    evaluations_ += lambda_;
    const double pSigmaNorm = pSigma_.norm();
    const bool hSigma = pSigmaNorm / std::sqrt(1 - std::pow(1 - cSigma_, 2.0 * generation_)) <
                        (1.4 + 2 / (n_ + 1.0)) * chiN_;
    pC_ = (1 - cC_) * pC_ + (hSigma ? std::sqrt(cC_ * (2 - cC_) * muEff_) : 0.0) * yw;
    const double deltaH = hSigma ? 0.0 : cC_ * (2 - cC_);
    Eigen::MatrixXd rankMu = Eigen::MatrixXd::Zero(n_, n_);
    for (int i = 0; i < mu_; ++i) rankMu += weights_[i] * y.col(i) * y.col(i).transpose();
    C_ = (1 + c1_ * deltaH - c1_ - cMu_ * weights_.sum()) * C_ + c1_ * pC_ * pC_.transpose() + cMu_ * rankMu;
    sigma_ *= std::exp(std::min(1.0, (cSigma_ / dSigma_) * (pSigmaNorm / chiN_ - 1)));
    updateEigenDecomposition();
}

Eigen::VectorXd CmaEs::injectable(const Eigen::VectorXd& x) const {
    const Eigen::VectorXd step = x - mean_;
    const double length = (B_.transpose() * step).cwiseQuotient(D_).norm() / sigma_;  // ‖C^{-1/2} step‖ / σ
    const double limit = std::sqrt(double(n_)) + 2.0 * n_ / (n_ + 2);
    return length > limit ? Eigen::VectorXd(mean_ + step * (limit / length)) : x;
}

Eigen::VectorXd CmaEs::standardDeviations() const { return sigma_ * C_.diagonal().cwiseSqrt(); }

nlohmann::json CmaEs::toJson() const {
    std::ostringstream engine;
    engine << random_;
    nlohmann::json covariance = nlohmann::json::array();
    for (int i = 0; i < n_; ++i) covariance.push_back(vectorToJson(C_.row(i).transpose()));
    return {{"algorithm", "CMA-ES (Hansen 2016, Table 1 defaults)"},
            {"n", n_},
            {"lambda", lambda_},
            {"mean", vectorToJson(mean_)},
            {"sigma", sigma_},
            {"C", covariance},
            {"p_sigma", vectorToJson(pSigma_)},
            {"p_c", vectorToJson(pC_)},
            {"generation", generation_},
            {"evaluations", evaluations_},
            {"seed", seed_},
            {"rng", engine.str()}};
}

CmaEs CmaEs::fromJson(const nlohmann::json& state) {
    const Eigen::VectorXd mean = vectorFromJson(state.at("mean"));
    CmaEsSettings settings;
    settings.populationSize = state.at("lambda").get<int>();
    CmaEs es(mean, 1.0, state.at("seed").get<std::uint64_t>(), settings);
    if (state.at("n").get<int>() != es.n_) throw std::runtime_error("CmaEs::fromJson: dimension mismatch");
    es.sigma_ = state.at("sigma").get<double>();
    for (int i = 0; i < es.n_; ++i) es.C_.row(i) = vectorFromJson(state.at("C").at(i)).transpose();
    es.pSigma_ = vectorFromJson(state.at("p_sigma"));
    es.pC_ = vectorFromJson(state.at("p_c"));
    es.generation_ = state.at("generation").get<int>();
    es.evaluations_ = state.at("evaluations").get<long>();
    std::istringstream engine(state.at("rng").get<std::string>());
    engine >> es.random_;
    if (!engine) throw std::runtime_error("CmaEs::fromJson: bad rng state");
    es.updateEigenDecomposition();
    return es;
}

}  // namespace viscoscope::identify
