// `viscoscope identify job.json --out DIR`: CMA-ES over simulations (identify stage). Re-running
// with the same --out resumes from DIR/checkpoint.json. SIGTERM/SIGINT: the current generation's
// evaluations finish, the checkpoint is written and the command exits 3. Under mpirun the
// evaluations are spread over the ranks (mpi_ranks.h).
#include "cli/commands.h"
#include "cli/mpi_ranks.h"
#include "cli/output_lock.h"
#include "cli/progress.h"
#include "cli/scripts.h"
#include "identify/identify.h"

#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <unistd.h>

namespace viscoscope::cli {

namespace {

namespace fs = std::filesystem;

struct IdentifyArguments {
    std::string job, outDir, progress = "text";
    int threads = 0;
    bool noPlots = false, noFields = false;
};

int runIdentify(const IdentifyArguments& args) {
    openvdb::initialize();
    identify::Job job = identify::loadJob(args.job);
    identify::IdentifyOptions options;
#ifdef VISCOSCOPE_WITH_MPI
    std::unique_ptr<MpiRanks> ranks;
    if (launchedByMpi()) {
        ranks = std::make_unique<MpiRanks>(args.threads);
        if (ranks->rank() > 0) {
            ranks->serve(job, args.outDir);
            return kExitOk;
        }
        options.pool = ranks.get();
    }
#else
    if (launchedByMpi())
        throw InputError("started by mpirun, but this viscoscope was built without MPI (install Debian's "
                         "mpi-default-dev and build again), and its ranks would each run the whole job");
#endif
    const OutputFolderLock lock(args.outDir, "identify");
    const ProgressReporter progress(args.progress);
    Scene atJobResolution = job.scene;
    atJobResolution.domain.resolution = job.resolution;
    for (const std::string& warning : resolutionWarnings(atJobResolution)) progress.warn(warning);
    options.threads = args.threads;
    options.writeFields = !args.noFields;
    options.onWarning = [&](const std::string& warning) { progress.warn(warning); };
    std::vector<std::string> names;
    for (const identify::ParameterSpec& p : job.parameters) names.push_back(p.name());
    options.onGeneration = [&](const identify::GenerationReport& r) { progress.report(generationEvent(names, r)); };
    try {
        const identify::IdentificationResult result = identify::identify(job, args.outDir, options);
        std::string plots = args.noPlots ? "skipped: --no-plots" : plot("plot_identification.py", args.outDir);
        nlohmann::json done{{"event", "done"},          {"stage", "identify"},         {"theta", result.theta},
                            {"interval", result.interval}, {"interval_method", result.intervalMethod},
                            {"E", result.E},             {"stop", identify::toString(result.stop)},
                            {"generations", result.generations}, {"evaluations", result.evaluations},
                            {"wall_s", result.seconds}, {"plots", plots}};
        if (result.resumedFromGeneration > 0) done["resumed_from_generation"] = result.resumedFromGeneration;
        progress.report(done);
        return kExitOk;
    } catch (const Cancelled& e) {
        progress.report({{"event", "cancelled"}, {"stage", "identify"}, {"message", e.what()}});
        return kExitCancelled;
    }
}

}  // namespace

Command addIdentifyCommand(CLI::App& app) {
    auto args = std::make_shared<IdentifyArguments>();
    CLI::App* sub = app.add_subcommand("identify", "Identify material parameters (viscosity) by CMA-ES over simulations; "
                                                   "under mpirun the ranks share the evaluations");
    sub->add_option("job", args->job, "job.json (format viscoscope.job, version 1)")->required();
    sub->add_option("--out", args->outDir, "Output folder: result.json, checkpoint.json, plots, fields/ (resumes)")
        ->required();
    sub->add_option("--progress", args->progress, "Progress format: text, json or none")
        ->check(CLI::IsMember({"text", "json", "none"}))
        ->capture_default_str();
    sub->add_option("--threads", args->threads, "Worker threads (0 = all cores), per rank under mpirun")
        ->check(CLI::NonNegativeNumber);
    sub->add_flag("--no-plots", args->noPlots, "Do not draw convergence.png / landscape.png");
    sub->add_flag("--no-fields", args->noFields, "Do not write θ*'s fields/frame_*.vdb (full-fidelity evaluations then write nothing to disk)");
    return {sub, [args] { return runIdentify(*args); }};
}

}  // namespace viscoscope::cli
