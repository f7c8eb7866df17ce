// diagnose on radii of thin films with a hidden effect, simulated on a grid 2.5 times finer and
// rounded to the half-millimetre pixels of the lab's record.
#include "diagnose/diagnose.h"
#include "film/film.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using namespace viscoscope;
using json = nlohmann::json;

// A current fed at 3 cm³/s through an 8 mm disc in a domain 0.4 m across, at `resolution` cells (the
// identification's 400: 1 mm, where the front at 200 sat 1–5 % out and η*, which the radius holds
// only to the power 1/8, 16 % off in a Newtonian control); the source stops at `sourceEnd` s.
json filmScene(int resolution, const json& material, double sourceEnd, double flux = 3e-6) {
    return {{"format", "viscoscope.scene"},
            {"version", 1},
            {"domain", {{"min", {-0.2, -0.2, -0.01}}, {"max", {0.2, 0.2, 0.05}}, {"resolution", resolution}}},
            {"solids", {{{"type", "ground"}, {"height", 0.0}}}},
            {"liquids", {{{"type", "emitter"}, {"center", {0, 0, 0}}, {"normal", {0, 0, 1}}, {"radius", 0.008},
                          {"flux", flux}, {"end", sourceEnd}}}},
            {"material", material},
            {"fps", 0.25},
            {"frames", 61}};
}

// DIR/radius.csv, the record: every 4 s for 240 s from a film of `material` on 0.4 mm cells, in
// 0.5 mm steps; and DIR/scene.json, the identification's Newtonian scene on 1 mm cells. The source
// runs throughout unless `sourceEnd` says when it stops; it feeds `flux` m³/s.
void writeRecordAndScene(const fs::path& dir, const json& material, double sourceEnd = 1e30, double flux = 3e-6) {
    film::AxisymmetricFilm reference(parseScene(filmScene(1000, material, sourceEnd, flux), "reference"));
    std::ofstream csv(dir / "radius.csv");
    csv << "time_s,radius_m\n";
    for (int f = 1; f <= 60; ++f) {
        reference.advanceTo(4.0 * f);
        csv << 4.0 * f << "," << 5e-4 * std::round(reference.frontRadius() / 5e-4) << "\n";
    }
    std::ofstream(dir / "scene.json") << filmScene(400, {{"density", 1000}, {"viscosity", 20.0}}, sourceEnd, flux).dump();
}

// The job of DIR/scene.json against DIR/radius.csv, with the film: η searched from 20 Pa·s.
json radiusJob() {
    return {{"format", "viscoscope.job"},
            {"version", 1},
            {"scene", "scene.json"},
            {"forward_model", "thin_film"},
            {"track", {{"csv", "radius.csv"}, {"column", "radius_m"}, {"observable", "radius"}, {"origin", {0, 0, 0}}}},
            {"parameters", {{{"name", "viscosity"}, {"initial", 20}, {"spread", 20}, {"min", 0.1}, {"max", 1e4}}}},
            // 30 left the Bingham fit along its K–τ_y valley, K 54 % high (FINDINGS).
            {"max_generations", 60},
            {"seed", 5}};
}

// diagnosis.json's entries of the first base fit and of its refit (null when none ran): the refit's
// "unused_fit" is whichever of the two the candidates were not judged against.
std::array<json, 2> firstBaseAndRefit(const json& doc) {
    if (!doc.contains("base_refit")) return {doc.at("base"), json()};
    const json& refit = doc.at("base_refit");
    if (refit.at("replaced_first_fit").get<bool>()) return {refit.at("unused_fit"), doc.at("base")};
    return {doc.at("base"), refit.at("unused_fit")};
}

struct HiddenEffect {
    const char* expected;  // the effect diagnose should name; "" for none
    json material;
    std::map<std::string, double> truth;  // the hidden parameters
    double sourceEnd = 1e30;              // s: when the source stops
};

// Wall slip shows only where the film thins: under a film fed throughout (1.5 cm thick) a slip
// length of 3 mm spreads like a Newtonian liquid of a third the viscosity, to within the record's
// half-millimetre steps (tests/bench/FINDINGS.md, "The thin-film forward model"). So its case, and
// a Newtonian control beside it, stop the source after 20 s: the released film thins to 3–4 mm,
// where the same slip length speeds it up more and more.
TEST(FilmDiagnosis, NamesEachHiddenEffectAndNoneInANewtonianControl) {
    const std::vector<HiddenEffect> cases{
        {"", {{"density", 1000}, {"viscosity", 50.0}}, {{"viscosity", 50.0}}},
        {"shear_thinning",
         {{"density", 1000}, {"viscosity", 20.0}, {"model", {{"type", "power_law"}, {"consistency", 20.0}, {"flow_index", 0.4}}}},
         {{"consistency", 20.0}, {"flow_index", 0.4}}},
        {"yield_stress",
         {{"density", 1000},
          {"viscosity", 20.0},
          {"model", {{"type", "herschel_bulkley"}, {"yield_stress", 10.0}, {"consistency", 20.0}, {"flow_index", 1.0}}}},
         {{"yield_stress", 10.0}, {"consistency", 20.0}}},
        {"", {{"density", 1000}, {"viscosity", 50.0}}, {{"viscosity", 50.0}}, 20},
        {"wall_slip", {{"density", 1000}, {"viscosity", 50.0}, {"slip_length", 0.003}},
         {{"viscosity", 50.0}, {"slip_length", 0.003}}, 20},
    };
    const fs::path root = fs::temp_directory_path() / ("viscoscope_film_diagnosis_" + std::to_string(::getpid()));
    for (const HiddenEffect& hidden : cases) {
        const fs::path dir = root / ((*hidden.expected ? hidden.expected : "newtonian") +
                                     std::string(hidden.sourceEnd < 1e30 ? "_released" : ""));
        fs::create_directories(dir);
        writeRecordAndScene(dir, hidden.material, hidden.sourceEnd);
        std::ofstream(dir / "job.json") << radiusJob().dump();
        const diagnose::Diagnosis d = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out");
        const std::string chosen = d.chosen ? d.candidates[*d.chosen].model : "";
        const diagnose::ModelFit& after = d.chosen ? d.candidates[*d.chosen] : d.base;
        std::printf("hidden %s%s: named \"%s\"; radius error %.2f %% before, %.2f %% after;",
                    *hidden.expected ? hidden.expected : "nothing",
                    hidden.sourceEnd < 1e30 ? " (source stopped)" : "", chosen.c_str(), 100 * *d.base.trackError,
                    100 * *after.trackError);
        for (size_t i = 0; i < after.parameters.size(); ++i) {
            const auto truth = hidden.truth.find(after.parameters[i]);
            std::printf(" %s %.4g [%.4g, %.4g]", after.parameters[i].c_str(), after.theta[i], after.interval[i][0],
                        after.interval[i][1]);
            if (truth != hidden.truth.end()) std::printf(" (truth %.4g, %+.1f %%)", truth->second, 100 * (after.theta[i] / truth->second - 1));
        }
        std::printf("\n");
        EXPECT_EQ(chosen, hidden.expected);
        // The film is deterministic: nothing scatters, and a control is plainly without an effect.
        EXPECT_TRUE(d.noise.deterministic);
        EXPECT_EQ(d.verdict, *hidden.expected ? diagnose::Verdict::MissingEffect : diagnose::Verdict::NoMissingEffect)
            << d.document.at("conclusion");
        if (d.chosen) EXPECT_LE(*after.trackError, 0.5 * *d.base.trackError) << hidden.expected;
        for (size_t i = 0; i < after.parameters.size(); ++i)
            if (const auto truth = hidden.truth.find(after.parameters[i]); truth != hidden.truth.end())
                EXPECT_NEAR(after.theta[i] / truth->second, 1.0, 0.25) << hidden.expected << " " << after.parameters[i];
        // Each candidate also scores its base-equivalent point (n = 1, τ_y and the slip length at
        // their least, from the first base fit), "known" in its checkpoint, and ends no worse; a
        // power law at n = 1 is that base fit itself.
        const double firstBaseE = firstBaseAndRefit(d.document)[0].at("fitted_E").get<double>();
        for (size_t c = 0; c < d.candidates.size(); ++c) {
            const fs::path folder = d.document.at("candidates")[c].at("folder").get<std::string>();
            const json evaluated = json::parse(std::ifstream(dir / "out" / folder / "checkpoint.json")).at("evaluated");
            const auto known = std::find_if(evaluated.begin(), evaluated.end(),
                                            [](const json& e) { return e.at("origin") == "known"; });
            ASSERT_NE(known, evaluated.end()) << d.candidates[c].model;
            const double knownE = known->at("E").get<double>();
            EXPECT_LE(d.candidates[c].fittedE, knownE * (1 + 1e-9)) << hidden.expected << ": " << d.candidates[c].model;
            if (d.candidates[c].model == "shear_thinning") EXPECT_NEAR(knownE / firstBaseE, 1.0, 1e-9) << hidden.expected;
        }
    }
    fs::remove_all(root);
}

// Two runs of one liquid fed at 3 and 0.3 cm³/s, in one job: the base fitted to each alone reads a
// shear-thinning liquid's viscosity lower in the faster run, in intervals that share no value, and a
// Newtonian liquid's alike in both. The power law found, fitted to each run alone, predicts the other
// run better than the base fitted to it alone: the law carries across the runs.
TEST(FilmDiagnosis, EachRunAloneDisagreesOnAShearThinningLiquidsViscosityOnly) {
    const std::vector<HiddenEffect> cases{
        {"", {{"density", 1000}, {"viscosity", 50.0}}, {}},
        {"shear_thinning",
         {{"density", 1000}, {"viscosity", 20.0}, {"model", {{"type", "power_law"}, {"consistency", 20.0}, {"flow_index", 0.4}}}},
         {}},
    };
    const fs::path root = fs::temp_directory_path() / ("viscoscope_film_runs_" + std::to_string(::getpid()));
    for (const HiddenEffect& hidden : cases) {
        const fs::path dir = root / (*hidden.expected ? hidden.expected : "newtonian");
        json job = radiusJob();
        job.erase("scene");
        job["runs"] = json::array();
        for (const double flux : {3e-6, 3e-7}) {
            const std::string run = flux > 2e-6 ? "fast" : "slow";
            fs::create_directories(dir / run);
            writeRecordAndScene(dir / run, hidden.material, 1e30, flux);
            json track = job.at("track");
            track["csv"] = run + "/radius.csv";
            job["runs"].push_back({{"scene", run + "/scene.json"}, {"track", track}});
        }
        job.erase("track");
        std::ofstream(dir / "job.json") << job.dump();
        const diagnose::Diagnosis d = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out");
        ASSERT_EQ(d.runFits.size(), 2u);
        const json& perRun = d.document.at("base_per_run");
        ASSERT_EQ(perRun.size(), 2u);
        const double fast = d.runFits[0].theta[0], slow = d.runFits[1].theta[0];
        std::printf("hidden %s: η alone %.4g [%.4g, %.4g] at 3 cm³/s, %.4g [%.4g, %.4g] at 0.3 cm³/s; %s\n",
                    *hidden.expected ? hidden.expected : "nothing", fast, d.runFits[0].interval[0][0],
                    d.runFits[0].interval[0][1], slow, d.runFits[1].interval[0][0], d.runFits[1].interval[0][1],
                    d.document.at("conclusion").get<std::string>().c_str());
        EXPECT_EQ(perRun[0].at("run"), 1);
        EXPECT_EQ(perRun[1].at("parameters").at("viscosity").at("value"), slow);
        if (*hidden.expected) {
            EXPECT_LT(fast, slow);
            EXPECT_TRUE(d.document.at("runs_disagree").is_string()) << d.document.at("runs_disagree");
            EXPECT_EQ(d.chosen ? d.candidates[*d.chosen].model : "", hidden.expected) << d.document.at("conclusion");
            const json& tested = d.document.at("cross_run").at("tested");
            ASSERT_EQ(tested, hidden.expected) << d.document.at("cross_run");
            for (const json& candidate : d.document.at("candidates"))
                if (candidate.at("model") == tested) {
                    std::printf("  across the runs: %s\n", candidate.at("cross_run").dump().substr(0, 200).c_str());
                    EXPECT_GT(candidate.at("cross_run").at("gain").get<double>(), 0.2);
                }
        } else {
            EXPECT_TRUE(d.document.at("runs_disagree").is_null()) << d.document.at("runs_disagree");
            EXPECT_EQ(d.verdict, diagnose::Verdict::NoMissingEffect) << d.document.at("conclusion");
        }
    }
    fs::remove_all(root);
}

bool mentions(const json& lines, const std::string& part) {
    return std::any_of(lines.begin(), lines.end(),
                       [&](const json& line) { return line.get<std::string>().find(part) != std::string::npos; });
}

// A budget far under a generation: the base makes its minimum generations, and the budget cannot hold
// the candidates' least fits predicted from the base's cost, so none is fitted. The diagnosis cannot
// tell, lists each candidate as not tried for the budget, and suggests the budget that would hold
// them, which holds them when given (the second diagnosis): there the budget is shared by the fits.
// The first gets an equal share, each later one what the fits before it left, less the scoring the
// one before took, and a refit of the base what is left.
TEST(FilmDiagnosis, RefusesTheCandidatesABudgetCannotHoldAndSharesOneThatCan) {
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_film_budget_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    writeRecordAndScene(dir, {{"density", 1000}, {"viscosity", 50.0}});
    std::ofstream(dir / "job.json") << radiusJob().dump();
    diagnose::DiagnoseOptions options;
    options.timeBudget = 0.01;
    const diagnose::Diagnosis tight = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out", options);
    const json& refused = tight.document;
    EXPECT_EQ(refused.at("base").at("stopped"), "time_budget");
    EXPECT_TRUE(tight.candidates.empty());
    EXPECT_EQ(refused.at("verdict"), "cannot_tell") << refused.at("conclusion");
    EXPECT_NE(refused.at("conclusion").get<std::string>().find("least fits"), std::string::npos) << refused.at("conclusion");
    EXPECT_TRUE(mentions(refused.at("what_would_tell"), "fewer --effects")) << refused.at("what_would_tell");
    int forTheBudget = 0;
    for (const json& n : refused.at("not_tried")) forTheBudget += n.at("why").get<std::string>().rfind("the time budget", 0) == 0;
    EXPECT_EQ(forTheBudget, 4) << refused.at("not_tried");  // all but side_walls, which the scene cannot hold
    const double suggested = refused.at("suggested_settings").at("time_budget_s").get<double>();
    EXPECT_GT(suggested, refused.at("seconds").get<double>());
    EXPECT_EQ(refused.at("grid").at("resolution"), identify::loadJob(dir / "job.json").resolution);

    // A budget well over the suggestion: the candidates are fitted, each within its share of what is
    // left, the base and its refit within three.
    options.timeBudget = 4 * suggested;
    const diagnose::Diagnosis d = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out_held", options);
    const json& doc = d.document;
    ASSERT_EQ(d.candidates.size(), 4u) << doc.at("warnings");
    const auto [first, refit] = firstBaseAndRefit(doc);
    std::vector<json> fits{first};
    for (const json& candidate : doc.at("candidates")) fits.push_back(candidate);
    if (!refit.is_null()) fits.push_back(refit);
    const int planned = 1 + static_cast<int>(d.candidates.size());
    double spent = 0, lastScoring = 0;
    for (size_t f = 0; f < fits.size(); ++f) {
        const json& fit = fits[f];
        const bool isBase = f == 0 || (!refit.is_null() && f + 1 == fits.size());
        const double shares = isBase ? 3 : 1, left = planned - int(f);
        const double share =
            std::max(1e-3, (options.timeBudget - spent) * shares / std::max(shares, left - 1 + shares) - lastScoring);
        EXPECT_DOUBLE_EQ(fit.at("time_budget_s").get<double>(), share) << fit.at("model");
        spent += fit.at("seconds").get<double>() + fit.at("scoring_seconds").get<double>();
        lastScoring = fit.at("scoring_seconds").get<double>();
        // The noise floor's scorings are spent after the base's fit (none on a thin film).
        if (f == 0) spent += doc.at("noise_floor").at("seconds").get<double>();
    }
    EXPECT_EQ(doc.at("time_budget_s").get<double>(), options.timeBudget);
    fs::remove_all(dir);
}

// A base search stopped short lets every candidate stand in for the viscosity it missed: here 2
// generations from 20 Pa·s, the record's liquid Newtonian at 50. Before an effect is named, the base
// is refit from where the best candidate puts it; against the refit, none earns its parameters.
TEST(FilmDiagnosis, RefitsAnUnconvergedBaseBeforeNamingAnEffect) {
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_film_unconverged_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const double eta = 50;
    writeRecordAndScene(dir, {{"density", 1000}, {"viscosity", eta}});
    json job = radiusJob();
    job["max_generations"] = 2;
    std::ofstream(dir / "job.json") << job.dump();
    const diagnose::Diagnosis d = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out");
    const json& refit = d.document.at("base_refit");
    const json first = firstBaseAndRefit(d.document)[0];
    std::printf("first base: viscosity %.4g, held-out E %.3g\n", first.at("parameters").at("viscosity").at("value").get<double>(),
                first.at("held_out_E").get<double>());
    for (const diagnose::ModelFit& fit : d.candidates) {
        std::printf("%s:", fit.model.c_str());
        for (size_t i = 0; i < fit.parameters.size(); ++i) std::printf(" %s %.4g", fit.parameters[i].c_str(), fit.theta[i]);
        std::printf(", held-out E %.3g\n", fit.heldOutE);
    }
    std::printf("refit from %s: viscosity %.4g (truth %.4g), held-out E %.3g; named \"%s\"\n",
                refit.at("from").get<std::string>().c_str(), d.base.theta[0], eta, d.base.heldOutE,
                d.chosen ? d.candidates[*d.chosen].model.c_str() : "");
    EXPECT_TRUE(refit.at("replaced_first_fit").get<bool>());
    EXPECT_NEAR(d.base.theta[0] / eta, 1.0, 0.1);
    EXPECT_FALSE(d.chosen.has_value());
    fs::remove_all(dir);
}

// DIR/job.json: the radius of a film of η = 50 Pa·s with a slip length of 3 mm, η fixed at the truth
// (an independent reading, a viscometer's) and nothing searched.
constexpr double kFixedEta = 50, kHiddenSlip = 0.003;
void writeFixedViscosityJob(const fs::path& dir) {
    fs::create_directories(dir);
    writeRecordAndScene(dir, {{"density", 1000}, {"viscosity", kFixedEta}, {"slip_length", kHiddenSlip}});
    json job = radiusJob();
    job.erase("parameters");
    job["fixed"] = {{{"name", "viscosity"}, {"value", kFixedEta}, {"uncertainty", 1.0}}};
    std::ofstream(dir / "job.json") << job.dump();
}

// With η fixed at an independent reading (a viscometer's), the slip the radius alone hides shows:
// the film spreads faster than that η allows, and only slip explains it. identify refuses such a job
// (nothing to search); diagnose holds the base at the fixed value and fits the slip length alone.
TEST(FilmDiagnosis, WithTheViscosityFixedItNamesHiddenSlip) {
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_film_fixed_" + std::to_string(::getpid()));
    writeFixedViscosityJob(dir);
    const double eta = kFixedEta, slip = kHiddenSlip;
    const identify::Job parsed = identify::loadJob(dir / "job.json");
    EXPECT_THROW(identify::identify(parsed, dir / "identify"), InputError);
    const diagnose::Diagnosis d = diagnose::diagnose(parsed, dir / "out");
    ASSERT_TRUE(d.chosen.has_value());
    const diagnose::ModelFit& after = d.candidates[*d.chosen];
    ASSERT_EQ(after.parameters, std::vector<std::string>{"slip_length"});
    std::printf("η fixed at %.0f, hidden slip %.1f mm: named \"%s\", slip %.3g mm [%.3g, %.3g] (%+.1f %%); radius error "
                "%.2f %% before, %.2f %% after; %zu candidates tried\n",
                eta, 1e3 * slip, after.model.c_str(), 1e3 * after.theta[0], 1e3 * after.interval[0][0],
                1e3 * after.interval[0][1], 100 * (after.theta[0] / slip - 1), 100 * *d.base.trackError,
                100 * *after.trackError, d.candidates.size());
    EXPECT_EQ(after.model, "wall_slip");
    EXPECT_LE(*after.trackError, 0.5 * *d.base.trackError);
    EXPECT_NEAR(after.theta[0] / slip, 1.0, 0.25);
    fs::remove_all(dir);
}

// A new effect is a record (diagnose/effect.h): this one, declared here and nowhere in the engine,
// searches the slip length under another name. diagnose fits and names it from the catalogue it is
// given, as it does the engine's own (with η fixed, as above, so that slip alone explains the film).
TEST(FilmDiagnosis, TakesANewEffectAsARecord) {
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_film_record_" + std::to_string(::getpid()));
    writeFixedViscosityJob(dir);
    const double slip = kHiddenSlip;
    diagnose::Effect toy;
    toy.name = "toy_slip";
    toy.title = "toy slip";
    toy.description = "the slip length, under a name the engine does not know";
    toy.source = "this test";
    toy.parameters = [](const diagnose::BaseFit&, std::vector<diagnose::AddedParameter>& added) {
        added.push_back({diagnose::searchedParameter("slip_length", 1e-4, 1.5)});
        return std::string();
    };
    const std::vector<diagnose::Effect> catalogue{toy};
    diagnose::DiagnoseOptions options;
    options.catalogue = &catalogue;
    const diagnose::Diagnosis d = diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out", options);
    ASSERT_EQ(d.candidates.size(), 1u);
    ASSERT_TRUE(d.chosen.has_value());
    const diagnose::ModelFit& after = d.candidates[*d.chosen];
    std::printf("toy_slip: slip %.3g mm (truth %.1f); radius error %.2f %% before, %.2f %% after\n", 1e3 * after.theta[0],
                1e3 * slip, 100 * *d.base.trackError, 100 * *after.trackError);
    EXPECT_EQ(d.document.at("chosen"), "toy_slip");
    EXPECT_EQ(d.document.at("candidates")[0].at("description"), toy.description);
    EXPECT_NEAR(after.theta[0] / slip, 1.0, 0.25);
    options.effects = {"wall_slip"};
    EXPECT_THROW(diagnose::diagnose(identify::loadJob(dir / "job.json"), dir / "out2", options), InputError);
    fs::remove_all(dir);
}

}  // namespace
