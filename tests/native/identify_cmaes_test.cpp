// CMA-ES on the classic test functions: these fail when an update rule or a default is wrong.
// Budgets are about 2-3x what pycma needs on average, so a correct implementation passes for any
// seed while a broken rank-one/rank-μ update, step-size rule or weight vector does not.
#include "identify/identify.h"

#include <Eigen/LU>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <vector>

namespace {

using viscoscope::identify::CmaEs;
using Function = std::function<double(const Eigen::VectorXd&)>;

double sphere(const Eigen::VectorXd& x) { return x.squaredNorm(); }
double ellipsoid(const Eigen::VectorXd& x) {  // condition number 1e4 (axis scales 1 … 1e2)
    const int n = static_cast<int>(x.size());
    double f = 0;
    for (int i = 0; i < n; ++i) f += std::pow(1e4, n > 1 ? double(i) / (n - 1) : 0.0) * x[i] * x[i];
    return f;
}
double rosenbrock(const Eigen::VectorXd& x) {
    double f = 0;
    for (int i = 0; i + 1 < x.size(); ++i)
        f += 100 * std::pow(x[i] * x[i] - x[i + 1], 2) + std::pow(1 - x[i], 2);
    return f;
}

struct Run {
    double best;
    long evaluations;
};

Run minimize(const Function& f, int n, double x0, double sigma0, long budget, std::uint64_t seed) {
    CmaEs es(Eigen::VectorXd::Constant(n, x0), sigma0, seed);
    double best = INFINITY;
    while (es.evaluations() < budget && best >= 1e-8) {
        const auto candidates = es.ask();
        std::vector<double> fitness;
        for (const auto& x : candidates) {
            fitness.push_back(f(x));
            best = std::min(best, fitness.back());
        }
        es.tell(candidates, fitness);
    }
    return {best, es.evaluations()};
}

void expectSolved(const char* name, const Function& f, int n, double x0, double sigma0, long budget) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
        const Run run = minimize(f, n, x0, sigma0, budget, seed);
        std::printf("[ cma-es   ] %-10s n=%2d seed=%llu  f=%.3g after %ld evaluations (budget %ld)\n", name, n,
                    static_cast<unsigned long long>(seed), run.best, run.evaluations, budget);
        EXPECT_LT(run.best, 1e-8) << name << " n=" << n << " seed " << seed;
    }
}

TEST(CmaEs, DefaultStrategyParametersFollowHansensTable1) {
    CmaEs es(Eigen::VectorXd::Zero(10), 1.0, 1);
    EXPECT_EQ(es.lambda(), 10);  // 4 + ⌊3 ln 10⌋
    EXPECT_EQ(es.mu(), 5);
    EXPECT_NEAR(es.weights().sum(), 1.0, 1e-12);
    for (int i = 1; i < es.mu(); ++i) EXPECT_GT(es.weights()[i - 1], es.weights()[i]);
    const double muEff = es.muEff();
    EXPECT_NEAR(muEff, 1 / es.weights().squaredNorm(), 1e-12);
    EXPECT_NEAR(es.cSigma(), (muEff + 2) / (10 + muEff + 5), 1e-12);
    EXPECT_NEAR(es.cC(), (4 + muEff / 10) / (10 + 4 + 2 * muEff / 10), 1e-12);
    EXPECT_NEAR(es.c1(), 2 / (11.3 * 11.3 + muEff), 1e-12);
    CmaEs one(Eigen::VectorXd::Zero(1), 1.0, 1);
    EXPECT_EQ(one.lambda(), 4);
    EXPECT_EQ(one.mu(), 2);
}

TEST(CmaEs, Sphere) {
    expectSolved("sphere", sphere, 1, 3, 2, 600);
    expectSolved("sphere", sphere, 2, 3, 2, 1000);
    expectSolved("sphere", sphere, 10, 3, 2, 4000);
}

TEST(CmaEs, Ellipsoid) {
    expectSolved("ellipsoid", ellipsoid, 2, 3, 2, 2000);
    expectSolved("ellipsoid", ellipsoid, 5, 3, 2, 6000);
    expectSolved("ellipsoid", ellipsoid, 10, 3, 2, 15000);
}

TEST(CmaEs, Rosenbrock) {
    expectSolved("rosenbrock", rosenbrock, 2, 0, 0.5, 3000);
    expectSolved("rosenbrock", rosenbrock, 5, 0, 0.5, 10000);
    expectSolved("rosenbrock", rosenbrock, 10, 0, 0.5, 30000);
}

TEST(CmaEs, DeterministicForASeedAndResumableFromJson) {
    CmaEs a(Eigen::VectorXd::Constant(3, 1.0), 0.5, 42), b(Eigen::VectorXd::Constant(3, 1.0), 0.5, 42);
    for (int g = 0; g < 5; ++g) {
        auto xa = a.ask(), xb = b.ask();
        std::vector<double> fa, fb;
        for (auto& x : xa) fa.push_back(rosenbrock(x));
        for (auto& x : xb) fb.push_back(rosenbrock(x));
        a.tell(xa, fa);
        b.tell(xb, fb);
    }
    EXPECT_EQ(a.toJson(), b.toJson());
    // A copy restored from JSON (through text, as a checkpoint is) continues identically.
    CmaEs c = CmaEs::fromJson(nlohmann::json::parse(a.toJson().dump()));
    for (int g = 0; g < 5; ++g) {
        auto xa = a.ask(), xc = c.ask();
        ASSERT_EQ(xa.size(), xc.size());
        for (size_t k = 0; k < xa.size(); ++k) ASSERT_EQ(xa[k], xc[k]);
        std::vector<double> fa;
        for (auto& x : xa) fa.push_back(rosenbrock(x));
        a.tell(xa, fa);
        c.tell(xc, fa);
    }
    EXPECT_EQ(a.toJson(), c.toJson());
}

TEST(CmaEs, OneDimensionalLogViscosity) {
    // η alone, in log space: E(x) = (x − ln 7)², start at ln 50 with σ0 = 1.
    CmaEs es(Eigen::VectorXd::Constant(1, std::log(50.0)), 1.0, 5);
    for (int g = 0; g < 60; ++g) {
        auto xs = es.ask();
        std::vector<double> f;
        for (auto& x : xs) f.push_back(std::pow(x[0] - std::log(7.0), 2));
        es.tell(xs, f);
    }
    std::printf("[ cma-es   ] 1-D: eta=%.6f after %ld evaluations, sigma=%.2e\n", std::exp(es.mean()[0]),
                es.evaluations(), es.sigma());
    EXPECT_NEAR(std::exp(es.mean()[0]), 7.0, 1e-3);
}

// A restart (as at the switch to the fine grid) sets the mean and the spreads and clears the
// adapted shape, but the generation count goes on, and the search converges from there.
TEST(CmaEs, RestartKeepsCountersAndConvergesFromTheNewMean) {
    CmaEs es(Eigen::VectorXd::Constant(2, 3.0), 1.0, 7);
    for (int g = 0; g < 8; ++g) {
        auto xs = es.ask();
        std::vector<double> f;
        for (auto& x : xs) f.push_back(ellipsoid(x));
        es.tell(xs, f);
    }
    const long evaluations = es.evaluations();
    es.restart(Eigen::Vector2d(0.5, -0.5), Eigen::Vector2d(0.2, 0.1));
    EXPECT_EQ(es.generation(), 8);
    EXPECT_EQ(es.evaluations(), evaluations);
    EXPECT_EQ(es.mean(), Eigen::Vector2d(0.5, -0.5));
    EXPECT_DOUBLE_EQ(es.standardDeviations()[0], 0.2);
    EXPECT_DOUBLE_EQ(es.standardDeviations()[1], 0.1);
    for (int g = 0; g < 200; ++g) {
        auto xs = es.ask();
        std::vector<double> f;
        for (auto& x : xs) f.push_back(ellipsoid(x));
        es.tell(xs, f);
    }
    EXPECT_LT(es.mean().norm(), 1e-4);
    EXPECT_THROW(es.restart(Eigen::Vector2d(0, 0), Eigen::Vector2d(0.1, 0)), std::invalid_argument);
}

// A distribution along a ridge (the restart after a scan along a curve): σ² C is the covariance
// asked for, and the samples follow it.
TEST(CmaEs, RestartWithACovarianceSamplesAlongIt) {
    Eigen::Matrix2d covariance;
    covariance << 0.64, -0.4, -0.4, 0.36;  // spreads 0.8 and 0.6, correlation −0.83
    CmaEs es(Eigen::Vector2d(2, -0.2), Eigen::Vector2d(0.5, 0.5), 5);
    es.restartWithCovariance(Eigen::Vector2d(2, -0.2), covariance);
    EXPECT_TRUE((es.sigma() * es.sigma() * es.covariance()).isApprox(covariance, 1e-12));
    Eigen::Matrix2d sampled = Eigen::Matrix2d::Zero();
    int count = 0;
    for (int g = 0; g < 2000; ++g)
        for (const Eigen::VectorXd& x : es.ask()) {
            const Eigen::Vector2d d = x - es.mean();
            sampled += d * d.transpose();
            ++count;
        }
    sampled /= count;
    EXPECT_NEAR(sampled(0, 0), 0.64, 0.03);
    EXPECT_NEAR(sampled(1, 1), 0.36, 0.02);
    EXPECT_NEAR(sampled(0, 1) / std::sqrt(sampled(0, 0) * sampled(1, 1)), -0.4 / (0.8 * 0.6), 0.02);
    Eigen::Matrix2d notPositive;
    notPositive << 0.64, 0.6, 0.6, 0.36;
    EXPECT_THROW(es.restartWithCovariance(Eigen::Vector2d(0, 0), notPositive), std::invalid_argument);
}

// An injected point keeps its direction from the mean, at a Mahalanobis length of at most
// √n + 2n/(n+2); one within that length is left as it is.
TEST(CmaEs, InjectedPointsAreClippedToHansensLength) {
    CmaEs es(Eigen::Vector2d(1, 2), Eigen::Vector2d(0.5, 2), 3);
    const double limit = std::sqrt(2.0) + 1;
    const auto mahalanobis = [&](const Eigen::VectorXd& x) {
        return std::sqrt((x - es.mean()).cwiseQuotient(es.standardDeviations()).squaredNorm());
    };
    const Eigen::Vector2d near(1.2, 3);
    EXPECT_EQ(es.injectable(near), near);
    const Eigen::Vector2d far(4, -10);
    const Eigen::VectorXd clipped = es.injectable(far);
    EXPECT_NEAR(mahalanobis(clipped), limit, 1e-12);
    const Eigen::VectorXd direction = (far - es.mean()).normalized();
    EXPECT_NEAR((clipped - es.mean()).normalized().dot(direction), 1, 1e-12);
}

}  // namespace

// The proposal a one-parameter identification injects: the vertex of the parabola, in 1/θ for a
// viscosity, through the best point and its nearest neighbours.
TEST(BracketedVertex, FindsAParabolasVertexFromItsBracket) {
    using viscoscope::identify::bracketedVertex;
    const auto parabolaInInverse = [](double theta) { return 0.3 + 50 * std::pow(1 / theta - 1 / 31.0, 2); };
    std::vector<std::pair<double, double>> points;
    for (double theta : {15.5, 40.4, 22.5, 29.2, 33.2, 60.0}) points.emplace_back(theta, parabolaInInverse(theta));
    points.emplace_back(25.0, NAN);  // a failed evaluation is ignored
    ASSERT_TRUE(bracketedVertex(points, true) && bracketedVertex(points, false));
    EXPECT_NEAR(*bracketedVertex(points, true), 31.0, 1e-9);
    // In ln θ the same three points give another vertex, still between 29.2 and 33.2.
    const double inLog = *bracketedVertex(points, false);
    EXPECT_GT(inLog, 29.2);
    EXPECT_LT(inLog, 33.2);
    EXPECT_GT(std::abs(inLog - 31.0), 1e-3);
    // No bracket: the lowest point at an end of the evaluated range, or nothing finite.
    EXPECT_FALSE(bracketedVertex({{10, 1}, {20, 2}, {30, 3}}, true));
    EXPECT_FALSE(bracketedVertex({{10, 3}, {20, 2}, {30, 1}}, true));
    EXPECT_FALSE(bracketedVertex({{10, NAN}, {20, INFINITY}}, true));
    // A flat bracket (ties go to the first point listed): the midpoint in u.
    const std::optional<double> flat = bracketedVertex({{20, 1}, {10, 1}, {40, 1}}, false);
    ASSERT_TRUE(flat);
    EXPECT_NEAR(*flat, 20.0, 1e-9);
}

// E's mean over grid placements from evaluations that each ran on one: each placement's points
// joined by straight lines in 1/θ, their mean at every point where all lines reach. Each placement
// here is a V with its tip at one of its own points, so its lines are exact and the profile is the
// mean of the two V's.
TEST(PlacementMeanProfile, AveragesThePlacementsLinesAtEveryPoint) {
    using viscoscope::identify::PlacedPoint;
    using viscoscope::identify::placementMeanProfile;
    const auto first = [](double theta) { return std::abs(1 / theta - 1 / 100.0); };
    const auto second = [](double theta) { return 2 * std::abs(1 / theta - 1 / 95.0); };
    std::vector<PlacedPoint> points;
    for (double theta : {80.0, 90.0, 100.0, 125.0}) points.push_back({theta, first(theta), 0.0});
    points.push_back({110.0, first(110.0) + 0.001, 0.0});  // the same θ twice: averaged
    points.push_back({110.0, first(110.0) - 0.001, 0.0});
    for (double theta : {85.0, 95.0, 105.0, 120.0, 130.0}) points.push_back({theta, second(theta), 0.5});
    points.push_back({115.0, NAN, 0.5});  // a failed evaluation is left out
    const auto profile = placementMeanProfile(points, true);
    // 1/θ spans [1/125, 1/80] on one placement and [1/130, 1/85] on the other: 80 and 130 are out.
    const std::vector<double> expected{85, 90, 95, 100, 105, 110, 120, 125};
    ASSERT_EQ(profile.size(), expected.size());
    std::vector<double> thetas;
    for (const auto& [theta, E] : profile) {
        thetas.push_back(theta);
        EXPECT_NEAR(E, 0.5 * (first(theta) + second(theta)), 1e-12) << theta;
    }
    std::sort(thetas.begin(), thetas.end());
    EXPECT_EQ(thetas, expected);
    const auto lowest = std::min_element(profile.begin(), profile.end(),
                                         [](const auto& a, const auto& b) { return a.second < b.second; });
    EXPECT_EQ(lowest->first, 95.0);  // the steeper V's tip
    // One placement: its points as they are; no common span: every placement's as they are, so
    // that the lowest of them all (21, on the second placement) stays in view.
    EXPECT_EQ(placementMeanProfile({{10, 1, 0}, {20, 2, 0}}, true).size(), 2u);
    auto apart = placementMeanProfile({{10, 3, 0}, {11, 2, 0}, {20, 4, 0.5}, {21, 1, 0.5}}, true);
    std::sort(apart.begin(), apart.end());
    const std::vector<std::pair<double, double>> all{{10, 3}, {11, 2}, {20, 4}, {21, 1}};
    EXPECT_EQ(apart, all);
}

// The profile's band is ΔE = 2 × E's jitter wide, so the jitter must not be read low from few
// points. Five noisy samples of a parabola, as a short run's profile has: the mean of the jitter²
// over many draws is the noise's variance. The residuals' RMS over all five points (what the band
// used before) averages 2/5 of it, and the interval came out about 0.8× as wide as it should.
TEST(ProfileFit, JitterEstimatesTheNoiseInEFromFivePoints) {
    using viscoscope::identify::fitProfile;
    constexpr double kNoise = 0.002, kTruth = 1.0;
    const std::vector<double> thetas{0.7, 0.84, 0.9, 0.98, 1.2};
    std::mt19937 random(7);
    std::normal_distribution<double> noise(0, kNoise);
    constexpr int kDraws = 4000;
    double meanSquare = 0;
    int fits = 0;
    for (int draw = 0; draw < kDraws; ++draw) {
        std::vector<std::pair<double, double>> points;
        for (double theta : thetas) points.emplace_back(theta, 0.045 + 0.04 * std::pow(1 / theta - 1 / kTruth, 2) + noise(random));
        nlohmann::json info;
        fitProfile(points, 0.9, 0.5, true, info);
        if (!info.contains("jitter")) continue;
        meanSquare += std::pow(info["jitter"].get<double>(), 2);
        ++fits;
    }
    ASSERT_EQ(fits, kDraws);  // the jitter is reported whether or not the fit is convex
    const double ratio = meanSquare / fits / (kNoise * kNoise);
    std::printf("mean jitter² / noise variance over %d draws of five points: %.3f\n", fits, ratio);
    // The mean of χ²₂/2 over 4000 draws: 1 ± 0.016 (one standard deviation).
    EXPECT_NEAR(ratio, 1.0, 0.06);
}

// The joint profile of two parameters, from noisy samples of a tilted bowl E = E0 + ½ (x − x0)ᵀ H (x − x0)
// in x = ln θ: each interval is the bowl's projection where it rises ΔE = 2 σ above its floor,
// x0_i ± √(2 ΔE (H⁻¹)_ii), which the search's own distribution does not give.
TEST(JointProfileFit, ABowlsIntervalsAreItsProjectionAtTwiceTheNoise) {
    using viscoscope::identify::fitJointProfile;
    constexpr double kNoise = 0.0005, kFloor = 0.02;
    const Eigen::Vector2d x0(std::log(2.0), std::log(0.6));
    Eigen::Matrix2d H;
    H << 0.4, 0.3, 0.3, 0.5;
    std::mt19937 random(11);
    std::normal_distribution<double> noise(0, kNoise);
    std::uniform_real_distribution<double> offset(-0.45, 0.45);
    std::vector<std::pair<std::vector<double>, double>> points;
    for (int k = 0; k < 60; ++k) {
        const Eigen::Vector2d x = x0 + Eigen::Vector2d(offset(random), offset(random));
        points.push_back({{std::exp(x[0]), std::exp(x[1])}, kFloor + 0.5 * (x - x0).dot(H * (x - x0)) + noise(random)});
    }
    nlohmann::json info;
    const auto fit = fitJointProfile(points, {2.1, 0.62}, 0.5, info);
    ASSERT_TRUE(fit.has_value());
    ASSERT_TRUE(fit->bounded) << info.dump();
    const Eigen::Matrix2d covariance = H.inverse();
    for (int i = 0; i < 2; ++i) {
        const double expectedHalf = std::sqrt(2 * 2 * kNoise * covariance(i, i));
        const double half = 0.5 * std::log(fit->interval[i][1] / fit->interval[i][0]);
        const double centre = 0.5 * std::log(fit->interval[i][1] * fit->interval[i][0]);
        std::printf("parameter %d: half-width %.4f (bowl at 2σ: %.4f), centre %+.4f off\n", i, half, expectedHalf,
                    centre - x0[i]);
        // At least the bowl's projection; wider only by the noisy points near its rim.
        EXPECT_GE(half / expectedHalf, 0.85);
        EXPECT_LE(half / expectedHalf, 1.3);
        EXPECT_NEAR(centre, x0[i], 0.25 * expectedHalf);
    }
}

// Along a ridge E does not change (a power law's K and n where one flow fixes only K γ̇ⁿ⁻¹): in
// ln θ the ridge is curved, and a quadric fitted there finds a minimum with an interval far
// narrower than the ridge; each interval must span the ridge's evaluations instead.
TEST(JointProfileFit, ACurvedRidgesIntervalsSpanIt) {
    using viscoscope::identify::fitJointProfile;
    constexpr double kNoise = 0.0005, kFloor = 0.02, kShearRate = 30;
    std::mt19937 random(12);
    std::normal_distribution<double> noise(0, kNoise);
    std::uniform_real_distribution<double> along(std::log(0.5), std::log(1.0)), across(-0.3, 0.3);
    std::vector<std::pair<std::vector<double>, double>> points;
    double lowestIndex = 1, highestIndex = 0;
    for (int k = 0; k < 60; ++k) {
        // ln K = ln η + (1 − n) ln γ̇ on the ridge through η = 1 Pa·s at γ̇.
        const double lnN = along(random), offRidge = across(random);
        const double lnK = (1 - std::exp(lnN)) * std::log(kShearRate) + offRidge;
        points.push_back({{std::exp(lnK), std::exp(lnN)}, kFloor + 0.5 * offRidge * offRidge + noise(random)});
        if (std::abs(offRidge) < 0.02) {
            lowestIndex = std::min(lowestIndex, std::exp(lnN));
            highestIndex = std::max(highestIndex, std::exp(lnN));
        }
    }
    nlohmann::json info;
    const auto best = std::min_element(points.begin(), points.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    const auto fit = fitJointProfile(points, best->first, 0.5, info);
    ASSERT_TRUE(fit.has_value());
    std::printf("flow index: interval [%.3f, %.3f]; the ridge's points within 0.02 of it span [%.3f, %.3f]\n",
                fit->interval[1][0], fit->interval[1][1], lowestIndex, highestIndex);
    EXPECT_LE(fit->interval[1][0], lowestIndex);
    EXPECT_GE(fit->interval[1][1], highestIndex);
}
