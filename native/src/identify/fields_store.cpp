// OUT/fields: θ*'s hidden fields, kept from the best evaluation's own run.
//
// Simulating θ* again for them costs a whole evaluation at the end; writing them costs each
// full-fidelity evaluation only its .vdb writes and the level sets of frames it does not compare
// (longer clips, compared every few frames) (tests/bench/FINDINGS.md, "Figures moved from code
// comments"). θ* is simulated (and scored) again only when they are missing:
// a run killed while promote swaps them, or one whose best evaluation ran without writing them. A
// kill -9 mid-generation leaves OUT/fields.partial until the next generation of the run.
#include "identify/search_state.h"

#include <fstream>

namespace viscoscope::identify {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const char* const kFieldsFolder = "fields";
const char* const kFieldsStaging = "fields.partial";
const char* const kFieldsOwner = "evaluation.json";

json ownerOf(const std::string& fingerprint, const Evaluation& ev, double gridShift, int frames) {
    return {{"fingerprint", fingerprint},
            {"theta", ev.theta},
            {"resolution", ev.resolution},
            {"grid_shift", gridShift},
            {"frames", frames},
            {"mean_ground_speed_m_s", ev.fields->groundFrames ? json(ev.fields->meanGroundSpeed) : json()}};
}

// Makes `staged` (an evaluation's fields folder) OUT/fields.
void promoteFolder(const fs::path& staged, const json& owner, const fs::path& outDir) {
    writeJsonAtomically(owner, staged / kFieldsOwner);
    fs::remove_all(outDir / kFieldsFolder);
    fs::rename(staged, outDir / kFieldsFolder);
}

}  // namespace

FieldsStore::FieldsStore(const fs::path& outDir, std::string fingerprint, int frames)
    : outDir_(outDir), fingerprint_(std::move(fingerprint)), frames_(frames) {}

fs::path FieldsStore::staged(size_t k) const { return outDir_ / kFieldsStaging / std::to_string(k); }

void FieldsStore::clearStaging() const { fs::remove_all(outDir_ / kFieldsStaging); }

void FieldsStore::promote(size_t k, const Evaluation& evaluation, double gridShift) const {
    promoteFolder(staged(k), ownerOf(fingerprint_, evaluation, gridShift, frames_), outDir_);
}

json FieldsStore::keep(const Job& job, const Observation& observation, const BestPoint& best, int resolution) const {
    const auto start = Clock::now();
    // OUT/fields' owner when it holds θ* at this job, resolution, grid shift and frame count.
    json owner = [&]() -> json {
        std::ifstream stream(outDir_ / kFieldsFolder / kFieldsOwner);
        if (!stream) return nullptr;
        const json doc = json::parse(stream, nullptr, false);
        if (doc.is_discarded() || doc.value("fingerprint", "") != fingerprint_ ||
            doc.value("resolution", 0) != resolution || doc.value("grid_shift", 0.0) != best.gridShift ||
            doc.value("frames", 0) != frames_ || !doc.contains("theta") || doc.at("theta") != json(best.theta))
            return nullptr;
        return doc;
    }();
    const bool kept = !owner.is_null();
    if (!kept) {
        const fs::path staging = outDir_ / kFieldsStaging / "best";
        const Evaluation ev = evaluate(job, observation, best.theta, resolution, staging, best.gridShift);
        owner = ownerOf(fingerprint_, ev, best.gridShift, frames_);
        promoteFolder(staging, owner, outDir_);
        clearStaging();
    }
    return {{"folder", kFieldsFolder},
            {"frames", owner.at("frames")},
            {"grid_shift_cells", best.gridShift},
            {"mean_ground_speed_m_s", owner.at("mean_ground_speed_m_s")},
            {"source", kept ? "the best evaluation's run" : "θ* simulated again"},
            {"seconds", std::chrono::duration<double>(Clock::now() - start).count()}};
}

}  // namespace viscoscope::identify
