// The conclusion's rules (diagnose/conclusion.h), one case each: fits as diagnose scores them, with
// the noise floor a forward model of known scatter gives.
#include "diagnose/conclusion.h"

#include <gtest/gtest.h>

#include <cmath>

namespace {

using namespace viscoscope;
using diagnose::Verdict;

diagnose::ModelFit fitOf(const std::string& model, double heldOutE, double bic,
                         std::optional<identify::StopReason> stop = identify::StopReason::ToleranceFun) {
    diagnose::ModelFit fit;
    fit.model = model;
    fit.heldOutE = heldOutE;
    fit.bic = bic;
    fit.stop = stop;
    return fit;
}

diagnose::Effect effectOf(const std::string& name, const std::string& title) {
    diagnose::Effect effect;
    effect.name = name;
    effect.title = title;
    return effect;
}

// Three scorings of the base's θ* about 0.10, each `factor` from the next: a factor 1.01 lets gains
// over 4 % show, 1.1 only those over 33 %.
diagnose::NoiseFloor scatteredBy(double factor) { return {{0.10 / factor, 0.10, 0.10 * factor}, false, 0}; }

bool mentions(const std::vector<std::string>& lines, const std::string& part) {
    for (const std::string& line : lines)
        if (line.find(part) != std::string::npos) return true;
    return false;
}

class Conclusion : public ::testing::Test {
protected:
    Conclusion() {
        job_.resolution = 48;
        job_.gridPlacements = 2;
    }
    diagnose::Conclusion conclude(const diagnose::ModelFit& base, const std::vector<diagnose::ModelFit>& fits,
                                  const diagnose::NoiseFloor& noise, const std::vector<bool>& vanishes = {},
                                  const diagnose::Unfitted& unfitted = {}) {
        std::vector<diagnose::Judged> judged;
        for (size_t i = 0; i < fits.size(); ++i)
            judged.push_back({&fits[i], &effects_[i % effects_.size()], i < vanishes.size() && vanishes[i], std::nullopt});
        return diagnose::conclude(job_, timeBudget_, base, judged, noise, unfitted);
    }
    identify::Job job_;
    double timeBudget_ = 0;
    std::vector<diagnose::Effect> effects_{effectOf("shear_thinning", "shear thinning"), effectOf("wall_slip", "wall slip")};
};

TEST(NoiseFloor, GainVisibleAboveTheScatter) {
    EXPECT_EQ(diagnose::NoiseFloor({{0.1}, true, 0}).visibleShare(), 0.0);
    EXPECT_EQ(diagnose::NoiseFloor({{0.1}, false, 0}).visibleShare(), 1.0);
    const diagnose::NoiseFloor three{{std::exp(-1.0), 1, std::exp(1.0)}, false, 0};
    EXPECT_NEAR(three.logSpread(), 1.0, 1e-12);
    // t(0.95, 2 degrees of freedom) = 2.919986 (any table of Student's t), times √2, in ln E.
    EXPECT_NEAR(three.visibleShare(), 1 - std::exp(-2.919986 * std::sqrt(2.0)), 1e-6);
}

TEST_F(Conclusion, NamesAnEffectWhoseGainStandsAboveTheScatter) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.03, -70), fitOf("wall_slip", 0.07, -60)}, scatteredBy(1.01));
    EXPECT_EQ(c.verdict, Verdict::MissingEffect);
    ASSERT_TRUE(c.chosen.has_value());
    EXPECT_EQ(*c.chosen, 0u);
    EXPECT_NE(c.sentence.find("shear thinning"), std::string::npos) << c.sentence;
    // Both earn their parameters; the one that predicts best is named.
    EXPECT_TRUE(c.candidates[0].earns);
    EXPECT_TRUE(c.candidates[1].earns);
}

TEST_F(Conclusion, CannotTellAGainWithinTheScatter) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.07, -55)}, scatteredBy(1.1));
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_FALSE(c.chosen.has_value());
    EXPECT_FALSE(c.candidates[0].aboveNoise);
    EXPECT_TRUE(mentions(c.whatWouldTell, "finer grid (resolution 48 → 72)")) << c.sentence;
    EXPECT_TRUE(mentions(c.whatWouldTell, "grid_placements 2 → 4"));
    EXPECT_EQ(c.suggestedSettings.value("resolution", 0), 72);
    EXPECT_EQ(c.suggestedSettings.value("grid_placements", 0), 4);
}

TEST_F(Conclusion, FindsNoMissingEffectWhereOneWouldHaveShown) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.095, -49), fitOf("wall_slip", 0.11, -48)}, scatteredBy(1.01));
    EXPECT_EQ(c.verdict, Verdict::NoMissingEffect) << c.sentence;
    EXPECT_TRUE(c.whatWouldTell.empty());
}

TEST_F(Conclusion, CannotTellWhereTheScatterWouldHideAnEffect) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.095, -49)}, scatteredBy(1.1));
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_NE(c.sentence.find("scatter"), std::string::npos) << c.sentence;
    EXPECT_FALSE(c.whatWouldTell.empty());
    // Unmeasured, it is no better than large.
    EXPECT_EQ(conclude(base, {fitOf("shear_thinning", 0.095, -49)}, {{0.10}, false, 0}).verdict, Verdict::CannotTell);
}

TEST_F(Conclusion, NamesNothingAgainstABaseCutShort) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50, identify::StopReason::TimeBudget);
    timeBudget_ = 300;
    const auto c = conclude(base, {fitOf("shear_thinning", 0.03, -70)}, scatteredBy(1.01));
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_TRUE(c.candidates[0].earns);
    EXPECT_TRUE(mentions(c.whatWouldTell, "--time-budget of 600 s")) << c.sentence;
    EXPECT_EQ(c.suggestedSettings.value("time_budget_s", 0), 600);
}

TEST_F(Conclusion, SaysWhatBudgetWouldHoldTheCandidatesItLeftUnfitted) {
    timeBudget_ = 480;
    // The base cut short too: the budget that holds the candidates is what would tell, not twice this one.
    const auto c = conclude(fitOf("base", 0.10, -50, identify::StopReason::TimeBudget), {}, scatteredBy(1.01), {},
                            {4, 2399.6});
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_NE(c.sentence.find("4 candidates"), std::string::npos) << c.sentence;
    EXPECT_NE(c.sentence.find("2400 s"), std::string::npos) << c.sentence;
    EXPECT_TRUE(mentions(c.whatWouldTell, "fewer --effects"));
    EXPECT_FALSE(mentions(c.whatWouldTell, "twice this one"));
    EXPECT_EQ(c.suggestedSettings.value("time_budget_s", 0), 2400);
}

TEST_F(Conclusion, CannotTellWhileACandidateWasCutShort) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.095, -49, identify::StopReason::TimeBudget)}, scatteredBy(1.01));
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_NE(c.sentence.find("shear_thinning"), std::string::npos) << c.sentence;
}

// Against a converged base, an effect that already predicts better stands though its own fit was cut
// short; the conclusion says its parameters are not converged.
TEST_F(Conclusion, NamesAnEffectWhoseOwnFitWasCutShortAndSaysSo) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.03, -70, identify::StopReason::TimeBudget)}, scatteredBy(1.01));
    EXPECT_EQ(c.verdict, Verdict::MissingEffect) << c.sentence;
    EXPECT_NE(c.sentence.find("its own fit was cut short (time_budget), so its parameters are not converged"),
              std::string::npos) << c.sentence;
    const auto converged = conclude(base, {fitOf("shear_thinning", 0.03, -70)}, scatteredBy(1.01));
    EXPECT_EQ(converged.sentence.find("cut short"), std::string::npos) << converged.sentence;
}

TEST_F(Conclusion, NamesNoEffectThatEndedAsTheBase) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto c = conclude(base, {fitOf("shear_thinning", 0.03, -70)}, scatteredBy(1.01), {true});
    EXPECT_NE(c.verdict, Verdict::MissingEffect) << c.sentence;
    EXPECT_FALSE(c.candidates[0].earns);
}

// The base fitted to each run alone: viscosities whose intervals share no value are a base model
// that cannot hold both runs, so the data showed an effect even where no candidate predicted it.
TEST_F(Conclusion, RunsThatDisagreeRuleOutNoMissingEffect) {
    const auto runFit = [](double eta, double low, double high) {
        diagnose::ModelFit fit = fitOf("base", 0.05, -30);
        fit.parameters = {"viscosity"};
        fit.theta = {eta};
        fit.interval = {{low, high}};
        return fit;
    };
    const std::vector<diagnose::ModelFit> apart{runFit(1.56, 1.48, 1.61), runFit(2.26, 2.14, 2.58)};
    const std::vector<diagnose::ModelFit> overlapping{runFit(1.56, 1.48, 1.80), runFit(1.70, 1.62, 1.95)};
    EXPECT_FALSE(diagnose::runsDisagree(overlapping).has_value());
    EXPECT_FALSE(diagnose::runsDisagree({apart[0]}).has_value());
    const std::optional<std::string> disagreement = diagnose::runsDisagree(apart);
    ASSERT_TRUE(disagreement.has_value());
    EXPECT_NE(disagreement->find("run 1 1.56 [1.48, 1.61], run 2 2.26 [2.14, 2.58]"), std::string::npos) << *disagreement;

    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const std::vector<diagnose::ModelFit> noGain{fitOf("shear_thinning", 0.095, -49)};
    EXPECT_EQ(conclude(base, noGain, scatteredBy(1.01), {}, {}).verdict, Verdict::NoMissingEffect);
    std::vector<diagnose::Judged> judged{{&noGain[0], &effects_[0], false, std::nullopt}};
    const auto c = diagnose::conclude(job_, timeBudget_, base, judged, scatteredBy(1.01), {}, apart);
    EXPECT_EQ(c.verdict, Verdict::CannotTell) << c.sentence;
    EXPECT_NE(c.sentence.find("disagree on the base's viscosity"), std::string::npos) << c.sentence;
    EXPECT_TRUE(mentions(c.whatWouldTell, "candidates fitted longer")) << c.sentence;
    // A candidate that earns its parameters is still named.
    const std::vector<diagnose::ModelFit> gain{fitOf("shear_thinning", 0.03, -70)};
    judged = {{&gain[0], &effects_[0], false, std::nullopt}};
    const auto named = diagnose::conclude(job_, timeBudget_, base, judged, scatteredBy(1.01), {}, apart);
    EXPECT_EQ(named.verdict, Verdict::MissingEffect);
    EXPECT_EQ(named.runsDisagreement, disagreement);
}

// Of two laws that both earn their parameters, the one with fewer is named unless the other predicts
// the held-out frames better by the margin the base had to be beaten by.
TEST_F(Conclusion, NamesTheRicherLawOnlyWhereItPredictsClearlyBetter) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const auto law = [](const std::string& model, double heldOutE, size_t parameters) {
        diagnose::ModelFit fit = fitOf(model, heldOutE, -70);
        fit.theta.assign(parameters, 1.0);
        return fit;
    };
    effects_ = {effectOf("herschel_bulkley", "shear thinning with a yield stress"), effectOf("shear_thinning", "shear thinning")};
    const auto near = conclude(base, {law("herschel_bulkley", 0.028, 3), law("shear_thinning", 0.030, 2)}, scatteredBy(1.01));
    ASSERT_EQ(near.verdict, Verdict::MissingEffect) << near.sentence;
    EXPECT_EQ(near.chosen, 1u) << near.sentence;
    const auto clearly = conclude(base, {law("herschel_bulkley", 0.020, 3), law("shear_thinning", 0.030, 2)}, scatteredBy(1.01));
    EXPECT_EQ(clearly.chosen, 0u) << clearly.sentence;
}

// With several runs and what the base fitted to each alone predicts of the others, an effect is
// named only where its own fits to each run alone predict the others clearly better: in place of
// BIC, which here it fails.
TEST_F(Conclusion, AnEffectMustCarryAcrossTheRuns) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const std::vector<diagnose::ModelFit> fits{fitOf("shear_thinning", 0.05, -45)};
    const auto judge = [&](std::optional<double> crossRunE) {
        std::vector<diagnose::Judged> judged{{&fits[0], &effects_[0], false, crossRunE}};
        return diagnose::conclude(job_, timeBudget_, base, judged, scatteredBy(1.01), {}, {}, 0.40);
    };
    EXPECT_EQ(conclude(base, fits, scatteredBy(1.01)).verdict, Verdict::NoMissingEffect);  // by BIC, one run
    const auto carries = judge(0.10);
    EXPECT_EQ(carries.verdict, Verdict::MissingEffect) << carries.sentence;
    EXPECT_NEAR(*carries.candidates[0].crossRunGain, 0.75, 1e-12);
    EXPECT_NE(carries.sentence.find("the other runs 75 % better"), std::string::npos) << carries.sentence;
    const auto staysBehind = judge(0.38);
    EXPECT_EQ(staysBehind.verdict, Verdict::CannotTell) << staysBehind.sentence;
    EXPECT_NE(staysBehind.sentence.find("carry across geometries"), std::string::npos) << staysBehind.sentence;
    const auto untested = judge(std::nullopt);
    EXPECT_EQ(untested.verdict, Verdict::CannotTell) << untested.sentence;
    EXPECT_NE(untested.sentence.find("not fitted to each run alone"), std::string::npos) << untested.sentence;
}

TEST_F(Conclusion, ADeterministicModelNeedsOnlyTheGain) {
    const diagnose::ModelFit base = fitOf("base", 0.10, -50);
    const diagnose::NoiseFloor exact{{0.10}, true, 0};
    EXPECT_EQ(conclude(base, {fitOf("shear_thinning", 0.07, -55)}, exact).verdict, Verdict::MissingEffect);
    EXPECT_EQ(conclude(base, {fitOf("shear_thinning", 0.09, -55)}, exact).verdict, Verdict::NoMissingEffect);
    EXPECT_EQ(conclude(base, {}, exact).verdict, Verdict::CannotTell);
}

}  // namespace
