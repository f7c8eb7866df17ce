// Evaluations spread over MPI ranks (see mpi_ranks.h). Messages are JSON text: a broadcast from
// rank 0 ({"batch": …} or {"stop": true}), and each other rank's reply to rank 0 with its share.
#include "cli/mpi_ranks.h"

#include <cstdlib>

#ifdef VISCOSCOPE_WITH_MPI
#include <mpi.h>

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>
#endif

namespace viscoscope::cli {

bool launchedByMpi() {
    for (const char* variable : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"})
        if (std::getenv(variable)) return true;
    return false;
}

#ifdef VISCOSCOPE_WITH_MPI

namespace {

using json = nlohmann::json;
constexpr int kReplyTag = 1;

// Rank 0's text to every rank.
std::string broadcast(const std::string& text) {
    unsigned long long length = text.size();
    MPI_Bcast(&length, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD);
    std::string received = text;
    received.resize(length);
    MPI_Bcast(received.data(), static_cast<int>(length), MPI_CHAR, 0, MPI_COMM_WORLD);
    return received;
}

void sendToRankZero(const json& reply) {
    const std::string text = reply.dump();
    MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, 0, kReplyTag, MPI_COMM_WORLD);
}

json receiveFrom(int rank) {
    MPI_Status status;
    MPI_Probe(rank, kReplyTag, MPI_COMM_WORLD, &status);
    int length = 0;
    MPI_Get_count(&status, MPI_CHAR, &length);
    std::string text(length, '\0');
    MPI_Recv(text.data(), length, MPI_CHAR, rank, kReplyTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return json::parse(text);
}

// The batch's evaluations that fall to `rank`: k ≡ rank (mod size).
std::vector<size_t> shareOf(const identify::EvaluationBatch& batch, int rank, int size) {
    std::vector<size_t> share;
    for (size_t k = rank; k < batch.thetas.size(); k += size) share.push_back(k);
    return share;
}

identify::EvaluationBatch subBatch(const identify::EvaluationBatch& batch, const std::vector<size_t>& share) {
    identify::EvaluationBatch part = batch;
    part.thetas.clear();
    part.fieldsDirs.clear();
    for (size_t k : share) {
        part.thetas.push_back(batch.thetas[k]);
        if (!batch.fieldsDirs.empty()) part.fieldsDirs.push_back(batch.fieldsDirs[k]);
    }
    return part;
}

// A share's outcome as a reply: {"results": [{"k", "evaluation", "error"}]}, or the failure that
// stopped the whole share ({"input_error"} for bad input, else {"error"}).
json evaluateShare(identify::ThreadPool& pool, const identify::Job& job, const identify::Observations& observations,
                   const identify::EvaluationBatch& batch, const std::vector<size_t>& share) {
    try {
        const identify::BatchResult ran = pool.evaluate(job, observations, subBatch(batch, share));
        json results = json::array();
        for (size_t i = 0; i < share.size(); ++i)
            results.push_back({{"k", share[i]}, {"evaluation", identify::toJson(ran.evaluations[i])},
                               {"error", ran.errors[i]}});
        return {{"results", results}};
    } catch (const InputError& e) {
        return {{"input_error", e.what()}};
    } catch (const std::exception& e) {
        return {{"error", e.what()}};
    }
}

}  // namespace

MpiRanks::MpiRanks(int threads) {
    int provided = 0;
    // Only this (the main) thread calls MPI; TBB's workers never do.
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
    local_ = std::make_unique<identify::ThreadPool>(threads);
    // Evaluations dealt round robin finish together when every rank runs as many at once as the
    // one with the fewest threads.
    int fewest = local_->concurrency();
    MPI_Allreduce(MPI_IN_PLACE, &fewest, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    concurrency_ = size_ * fewest;
}

MpiRanks::~MpiRanks() {
    if (rank_ == 0) broadcast(json{{"stop", true}}.dump());
    local_.reset();
    MPI_Finalize();
}

identify::BatchResult MpiRanks::evaluate(const identify::Job& job, const identify::Observations& observations,
                                         const identify::EvaluationBatch& batch) {
    broadcast(json{{"batch", batch.toJson()}}.dump());
    std::vector<json> replies(size_);
    replies[0] = evaluateShare(*local_, job, observations, batch, shareOf(batch, 0, size_));
    // Every reply is received before any failure is raised, so that no rank is left sending.
    for (int r = 1; r < size_; ++r) replies[r] = receiveFrom(r);
    identify::BatchResult result;
    result.evaluations.resize(batch.thetas.size());
    result.errors.resize(batch.thetas.size());
    result.ranks.resize(batch.thetas.size());
    for (int r = 0; r < size_; ++r) {
        const json& reply = replies[r];
        if (reply.contains("input_error")) throw InputError(reply.at("input_error").get<std::string>());
        if (reply.contains("error"))
            throw std::runtime_error("rank " + std::to_string(r) + ": " + reply.at("error").get<std::string>());
        for (const json& entry : reply.at("results")) {
            const size_t k = entry.at("k").get<size_t>();
            result.evaluations[k] = identify::evaluationFromJson(entry.at("evaluation"));
            result.errors[k] = entry.at("error").get<std::string>();
            result.ranks[k] = r;
        }
    }
    return result;
}

void MpiRanks::serve(const identify::Job& job, const std::filesystem::path& outDir) {
    // The job as rank 0 runs it, once rank 0 has prepared its reference (before its first batch).
    std::optional<identify::Job> prepared;
    std::optional<identify::Observations> observations;
    for (;;) {
        const json message = json::parse(broadcast(""));
        if (message.contains("stop")) return;
        const identify::EvaluationBatch batch = identify::EvaluationBatch::fromJson(message.at("batch"));
        if (!prepared) {
            try {
                identify::Job copy = job;
                identify::prepareReference(copy, outDir);
                observations = identify::observe(copy);
                prepared = std::move(copy);
            } catch (const InputError& e) {
                sendToRankZero({{"input_error", "rank " + std::to_string(rank_) + ": " + e.what()}});
                continue;
            }
        }
        sendToRankZero(evaluateShare(*local_, *prepared, *observations, batch, shareOf(batch, rank_, size_)));
    }
}

#endif

}  // namespace viscoscope::cli
