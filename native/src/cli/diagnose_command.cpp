// `viscoscope diagnose job.json --out DIR`: the base model and each candidate effect fitted to the
// first part of the reference and scored on the rest (diagnose/diagnose.h). Re-running with the
// same --out resumes: each fit keeps its checkpoint in DIR/fits/<model>. SIGTERM/SIGINT: the current
// generation finishes, its checkpoint is written and the command exits 3.
#include "cli/commands.h"
#include "cli/output_lock.h"
#include "cli/progress.h"
#include "cli/scripts.h"
#include "diagnose/diagnose.h"

#include <openvdb/openvdb.h>

#include <memory>
#include <sstream>

namespace viscoscope::cli {

namespace {

struct DiagnoseArguments {
    std::string job, outDir, progress = "text";
    int threads = 0;
    double fitShare = 2.0 / 3;
    double timeBudget = 0;
    int scatterReplicas = diagnose::DiagnoseOptions{}.scatterReplicas;
    std::vector<std::string> effects;
    bool noPlots = false;
};

int runDiagnose(const DiagnoseArguments& args) {
    openvdb::initialize();
    const identify::Job job = identify::loadJob(args.job);
    const OutputFolderLock lock(args.outDir, "diagnose");
    const ProgressReporter progress(args.progress);
    diagnose::DiagnoseOptions options;
    options.fitShare = args.fitShare;
    options.effects = args.effects;
    options.timeBudget = args.timeBudget;
    options.scatterReplicas = args.scatterReplicas;
    options.identify.threads = args.threads;
    options.identify.onWarning = [&](const std::string& warning) { progress.warn(warning); };
    std::string model;
    std::vector<std::string> names;
    options.onFit = [&](const std::string& fit, int index, int count, const std::vector<std::string>& parameters) {
        model = fit;
        names = parameters;
        progress.report({{"event", "progress"}, {"stage", "diagnose"}, {"model", fit}, {"fit", index + 1},
                         {"fits", count}, {"parameters", parameters}});
    };
    options.identify.onGeneration = [&](const identify::GenerationReport& r) {
        nlohmann::json event = generationEvent(names, r);
        event["model"] = model;
        progress.report(event);
    };
    try {
        const diagnose::Diagnosis diagnosis = diagnose::diagnose(job, args.outDir, options);
        const nlohmann::json& doc = diagnosis.document;
        progress.report({{"event", "done"},
                         {"stage", "diagnose"},
                         {"verdict", doc.at("verdict")},
                         {"conclusion", doc.at("conclusion")},
                         {"chosen", doc.at("chosen")},
                         {"errors", doc.at("errors")},
                         {"plots", args.noPlots ? "skipped: --no-plots" : plot("plot_diagnosis.py", args.outDir)}});
        return kExitOk;
    } catch (const Cancelled& e) {
        progress.report({{"event", "cancelled"}, {"stage", "diagnose"}, {"message", e.what()}});
        return kExitCancelled;
    }
}

}  // namespace

Command addDiagnoseCommand(CLI::App& app) {
    auto args = std::make_shared<DiagnoseArguments>();
    std::ostringstream effects;
    for (const diagnose::Effect& e : diagnose::effects()) effects << (effects.tellp() ? ", " : "") << e.name;
    CLI::App* sub = app.add_subcommand("diagnose", "Find the effect the model lacks: fit the job's model and each "
                                                   "candidate effect to the first part of the reference, predict "
                                                   "the rest, report the error before and after");
    sub->add_option("job", args->job, "job.json (format viscoscope.job, version 1)")->required();
    sub->add_option("--out", args->outDir, "Output folder: diagnosis.json, fits/<model>/ (resumes)")->required();
    sub->add_option("--progress", args->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}))
        ->capture_default_str();
    sub->add_option("--threads", args->threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
    sub->add_option("--fit-share", args->fitShare, "Share of each run's compared frames fitted; the rest is predicted")
        ->check(CLI::Range(0.1, 0.9))
        ->capture_default_str();
    sub->add_option("--time-budget", args->timeBudget,
                    "Wall seconds for the whole diagnosis, shared by its fits (0 = each fit has the job's time_budget_s)")
        ->capture_default_str();
    sub->add_option("--scatter-replicas", args->scatterReplicas,
                    "Scorings of the base's best fit on other particle seeds and grid placements, which measure the "
                    "noise floor an effect must stand above (0 = none: the diagnosis then cannot name an effect)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    sub->add_option("--effects", args->effects, "Candidate effects (default: every one the scene can hold): " + effects.str())
        ->delimiter(',');
    sub->add_flag("--no-plots", args->noPlots, "Do not draw diagnosis.png");
    return {sub, [args] { return runDiagnose(*args); }};
}

}  // namespace viscoscope::cli
