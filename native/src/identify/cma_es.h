// CMA-ES (Hansen, arXiv:1604.00772) with ask/tell and checkpointable state: the identify stage's optimizer.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <random>

namespace viscoscope::identify {

// Hansen's default strategy parameters (Table 1 of the tutorial).
struct CmaEsSettings {
    int populationSize = 0;  // λ; 0 = 4 + ⌊3 ln n⌋
};

// λ for a search over `dimension` parameters with `settings`.
int populationSize(int dimension, const CmaEsSettings& settings = {});

class CmaEs {
public:
    CmaEs(const Eigen::VectorXd& initialMean, double initialSigma, std::uint64_t seed,
          const CmaEsSettings& settings = {});
    // With per-coordinate spreads: σ = 1 and C = diag(spread²)... expressed as σ0 = max spread and
    // C = diag((spread/σ0)²).
    CmaEs(const Eigen::VectorXd& initialMean, const Eigen::VectorXd& initialSpreads, std::uint64_t seed,
          const CmaEsSettings& settings = {});

    // λ candidates x_k = m + σ B D z_k, z_k ~ N(0, I). Deterministic given the seed and history.
    std::vector<Eigen::VectorXd> ask();
    // Fitness of the candidates returned by the last ask(), in the same order (minimized).
    void tell(const std::vector<Eigen::VectorXd>& candidates, const std::vector<double>& fitness);
    // Starts the search again at `mean` with per-coordinate spreads (σ and C as in the constructor,
    // evolution paths zero), keeping the generation and evaluation counters and the random stream.
    void restart(const Eigen::VectorXd& mean, const Eigen::VectorXd& spreads);
    // The same with a full covariance of the distribution (σ² C, σ the largest standard deviation).
    void restartWithCovariance(const Eigen::VectorXd& mean, const Eigen::MatrixXd& covariance);
    // An outside point made fit to replace one of ask()'s candidates (Hansen 2011, "Injecting
    // external solutions into CMA-ES", eq. 4): its step from the mean is shortened to a Mahalanobis
    // length of at most √n + 2n/(n+2), so one far point cannot drag the mean or inflate σ.
    Eigen::VectorXd injectable(const Eigen::VectorXd& x) const;

    int dimension() const { return n_; }
    int lambda() const { return lambda_; }
    int mu() const { return mu_; }
    double muEff() const { return muEff_; }
    const Eigen::VectorXd& weights() const { return weights_; }
    const Eigen::VectorXd& mean() const { return mean_; }
    double sigma() const { return sigma_; }
    const Eigen::MatrixXd& covariance() const { return C_; }
    int generation() const { return generation_; }
    long evaluations() const { return evaluations_; }
    // σ·sqrt(C_ii): the standard deviation of the search distribution per coordinate.
    Eigen::VectorXd standardDeviations() const;
    // Learning rates (for tests and the report).
    double cSigma() const { return cSigma_; }
    double dSigma() const { return dSigma_; }
    double cC() const { return cC_; }
    double c1() const { return c1_; }
    double cMu() const { return cMu_; }

    // The complete state (strategy parameters are recomputed from n and λ); from/to JSON for
    // checkpoints. Doubles round-trip exactly (17 significant digits).
    nlohmann::json toJson() const;
    static CmaEs fromJson(const nlohmann::json& state);

private:
    void setStrategyParameters();
    void updateEigenDecomposition();
    double standardNormal();

    int n_ = 0, lambda_ = 0, mu_ = 0;
    Eigen::VectorXd weights_;
    double muEff_ = 0, cSigma_ = 0, dSigma_ = 0, cC_ = 0, c1_ = 0, cMu_ = 0, chiN_ = 0;
    Eigen::VectorXd mean_, pSigma_, pC_;
    Eigen::MatrixXd C_, B_;
    Eigen::VectorXd D_;  // sqrt of C's eigenvalues
    double sigma_ = 1;
    int generation_ = 0;
    long evaluations_ = 0;
    std::uint64_t seed_ = 0;
    std::mt19937_64 random_;
};

}  // namespace viscoscope::identify
