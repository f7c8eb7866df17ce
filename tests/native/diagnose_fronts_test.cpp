// diagnose on the collapsing column's front (collapsing_column.h), measured like a lab's from a
// reference run at another resolution and seed than the fits use.
#include "collapsing_column.h"
#include "diagnose/diagnose.h"
#include "diagnose/flow_curve.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>

namespace {

namespace fs = std::filesystem;
using namespace viscoscope;
using namespace viscoscope::column;

class DiagnoseFronts : public ::testing::Test {
protected:
    void SetUp() override {
        openvdb::initialize();
        dir_ = fs::temp_directory_path() / ("viscoscope_diagnose_fronts_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override {
        if (!std::getenv("VISCOSCOPE_KEEP_TEST_DIR")) fs::remove_all(dir_);
        else std::printf("kept %s\n", dir_.c_str());
    }
    identify::Job job(const json& doc) const {
        std::ofstream(dir_ / "job.json") << doc.dump(1);
        return identify::loadJob(dir_ / "job.json");
    }
    fs::path dir_;
};

// A yield stress or shear thinning nobody declared, and a Newtonian control: the column's front
// measured from a reference run (24 cells, seed 11) of a Bingham liquid (τ_y = 60 Pa, K = 10 Pa·s), a
// power-law one (K = 20 Pa·sⁿ, n = 0.4) and a Newtonian one (η = 10 Pa·s), 15 times a second for
// `kDiagnosisFrames` frames. diagnose fits η on the job's 16-cell grid (seed 3), then shear thinning
// and a yield stress, each to the first two thirds of the front, and predicts the rest; the hidden
// effects stand above the noise floor the base's replicas measure, and the control is not named
// (on this coarse grid its conclusion is "cannot tell": tests/bench/FINDINGS.md, "The noise floor of
// a diagnosis").
TEST_F(DiagnoseFronts, FindsAHiddenYieldStressOrPowerLawAndNoEffectInANewtonianControl) {
    constexpr int kDiagnosisFrames = 30, kDiagnosisFps = 15;
    const Eigen::Vector3d gate(0.035, 0.02, 0), wall(0, 0.02, 0);
    const json bingham{{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0},
                       {"model", {{"type", "herschel_bulkley"}, {"yield_stress", 60.0}, {"consistency", 10.0}, {"flow_index", 1.0}}}};
    const json powerLaw{{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0},
                        {"model", {{"type", "power_law"}, {"consistency", 20.0}, {"flow_index", 0.4}}}};
    const json newtonian{{"density", 1400}, {"viscosity", 10.0}, {"surface_tension", 0.0}};
    const std::map<std::string, std::string> hiddenEffect{{"bingham", "yield_stress"}, {"power_law", "shear_thinning"}};
    // Each liquid's flow curve as a rheometer would give it, the job's "rheometer".
    const std::map<std::string, std::function<double(double)>> hiddenStress{
        {"bingham", [](double rate) { return 60 + 10 * rate; }},
        {"power_law", [](double rate) { return 20 * std::pow(rate, 0.4); }},
        {"newtonian", [](double rate) { return 10 * rate; }}};
    for (const auto& [label, material] : {std::pair<const char*, json>{"bingham", bingham}, {"power_law", powerLaw},
                                          {"newtonian", newtonian}}) {
        json reference = sceneJson(10.0, 24, 11, kDiagnosisFrames);
        reference["material"] = material;
        const std::string csv = std::string(label) + "_front.csv";
        writeMeasuredTrack(reference, gate, wall, dir_ / csv, kDiagnosisFrames, kDiagnosisFps);
        json doc = columnJobJson();
        json scene = sceneJson(10.0, 16, 3, kDiagnosisFrames);
        scene["fps"] = kDiagnosisFps;
        doc["scene"] = scene;
        doc["track"] = {{"csv", csv}, {"column", "front_m"}, {"observable", "front"},
                        {"origin", {gate.x(), gate.y(), gate.z()}}, {"direction", {1, 0, 0}}};
        doc["max_generations"] = 12;
        const std::string rheometer = std::string(label) + "_rheometer.csv";
        std::ofstream flowCurve(dir_ / rheometer);
        flowCurve << "shear_rate_per_s,stress_pa\n";
        for (int k = 0; k <= 12; ++k) flowCurve << std::pow(10.0, -1 + k / 4.0) << "," << hiddenStress.at(label)(std::pow(10.0, -1 + k / 4.0)) << "\n";
        flowCurve.close();
        doc["rheometer"] = rheometer;
        diagnose::DiagnoseOptions options;
        options.effects = {"shear_thinning", "yield_stress"};
        const auto started = std::chrono::steady_clock::now();
        const diagnose::Diagnosis diagnosis = diagnose::diagnose(job(doc), dir_ / (std::string(label) + "_diagnosis"), options);
        const json& d = diagnosis.document;
        // The base flow's shear rate, where the material laws start.
        ASSERT_TRUE(diagnosis.base.shearRate.has_value());
        EXPECT_GT(*diagnosis.base.shearRate, 0.0);
        EXPECT_EQ(d.at("base").at("shear_rate_per_s").get<double>(), *diagnosis.base.shearRate);
        std::printf("[ diagnose ] %s (%.0f s): %s; base eta %.3f (shear rate %.3g 1/s), held-out E %.4g, track error "
                    "%.2f %% -> %.2f %%\n",
                    label, std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(),
                    d.at("conclusion").get<std::string>().c_str(), diagnosis.base.theta[0], *diagnosis.base.shearRate,
                    diagnosis.base.heldOutE,
                    100 * d.at("errors").at("track_error").at("before").get<double>(),
                    100 * d.at("errors").at("track_error").at("after").get<double>());
        const json& noise = d.at("noise_floor");
        std::printf("[ diagnose ]   %s; noise floor: held-out E %s, ln E spread %.3f, gains under %.0f %% within it\n",
                    d.at("verdict").get<std::string>().c_str(), noise.at("held_out_E").dump().c_str(),
                    noise.at("log_spread").get<double>(), 100 * noise.at("visible_share").get<double>());
        if (d.contains("base_refit")) {
            const json& refit = d.at("base_refit");
            const json& other = refit.at("unused_fit");
            std::printf("[ diagnose ]   base refit from %s's fit: %s (the other: eta %.3f, held-out E %.4g)\n",
                        refit.at("from").get<std::string>().c_str(),
                        refit.at("replaced_first_fit").get<bool>() ? "replaced the first fit" : "the first fit stands",
                        other.at("parameters").at("viscosity").at("value").get<double>(), other.at("held_out_E").get<double>());
        }
        for (const diagnose::ModelFit& fit : diagnosis.candidates) {
            std::printf("[ diagnose ]   %s:", fit.model.c_str());
            for (size_t i = 0; i < fit.theta.size(); ++i) std::printf(" %s = %.4g", fit.parameters[i].c_str(), fit.theta[i]);
            std::printf("; held-out E %.4g, BIC %.1f (base %.1f), %ld evaluations\n", fit.heldOutE, fit.bic,
                        diagnosis.base.bic, fit.evaluations);
        }
        // The answer's flow curve over the shear rates its flow exercised, against the hidden law's.
        const json& curve = d.at("flow_curve");
        const double rms = curve.at("rheometer").at("log_stress_rms").get<double>();
        std::printf("[ diagnose ]   flow curve of %s over %s 1/s: log10 stress RMS %.3f against the hidden law\n",
                    curve.at("model").get<std::string>().c_str(), curve.at("shear_rate_range_per_s").dump().c_str(), rms);
        EXPECT_LT(curve.at("shear_rate_range_per_s")[0].get<double>(), curve.at("shear_rate_range_per_s")[1].get<double>());
        if (diagnosis.verdict != diagnose::Verdict::CannotTell) EXPECT_LT(rms, diagnose::kRheometerLogStressWarning) << label;
        if (const auto hidden = hiddenEffect.find(label); hidden != hiddenEffect.end()) {
            ASSERT_TRUE(diagnosis.chosen.has_value()) << label;
            EXPECT_EQ(diagnosis.candidates[*diagnosis.chosen].model, hidden->second);
            EXPECT_LE(d.at("errors").at("track_error").at("after").get<double>(),
                      0.5 * d.at("errors").at("track_error").at("before").get<double>());
        } else {
            EXPECT_FALSE(diagnosis.chosen.has_value()) << d.at("conclusion");
            EXPECT_NE(d.at("verdict"), "missing_effect");
        }
    }
}

}  // namespace
