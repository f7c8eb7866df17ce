// `viscoscope identify` under mpirun, for a population too costly for one machine: rank 0 runs the
// loop (CMA-ES, checkpoints, progress, results) and hands every batch of evaluations out over all
// ranks in turn (evaluation k to rank k mod size, rank 0 included); the other ranks only evaluate.
// Every evaluation is a deterministic function of θ, so the result is the one process's, bit for
// bit. All ranks read the job and write fields into the output folder, which must therefore be on
// a file system they share. Built when CMake finds MPI (VISCOSCOPE_WITH_MPI).
#pragma once

#include "identify/identify.h"

#include <filesystem>
#include <memory>

namespace viscoscope::cli {

// Whether an MPI launcher (Open MPI's or MPICH's mpirun, or a PMIx one) started this process, read
// from its environment without initializing MPI: a plain run never touches MPI.
bool launchedByMpi();

#ifdef VISCOSCOPE_WITH_MPI
class MpiRanks : public identify::EvaluationPool {
public:
    // Initializes MPI; `threads` per rank (0 = all its cores).
    explicit MpiRanks(int threads);
    // Rank 0 first tells the others to stop; then MPI is finalized.
    ~MpiRanks() override;
    int rank() const { return rank_; }
    int size() const { return size_; }
    // Rank 0's side: the batch over all ranks.
    identify::BatchResult evaluate(const identify::Job& job, const identify::Observations& observations,
                                   const identify::EvaluationBatch& batch) override;
    int concurrency() const override { return concurrency_; }
    // The other ranks' side, until rank 0 says stop: each batch's share of `job`'s evaluations,
    // against the reference rank 0 prepared in `outDir`.
    void serve(const identify::Job& job, const std::filesystem::path& outDir);

private:
    int rank_ = 0, size_ = 1, concurrency_ = 1;
    std::unique_ptr<identify::ThreadPool> local_;
};
#endif

}  // namespace viscoscope::cli
