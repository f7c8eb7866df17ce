// `viscoscope compare --reference DIR --sim DIR [--frames A:B]`: how far a simulation's hidden fields
// are from a reference simulation's (Takahashi & Lin 2019, Table 1: ε_p, ε_v). Relative L2 errors
// of velocity and pressure per frame and over all frames, from the folders' frame_NNNNN.vdb files
// (see surface::compareFields); JSON on stdout.
#include "cli/commands.h"
#include "cli/simulation_folder.h"
#include "surface/surface.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <regex>

namespace viscoscope::cli {

namespace {

namespace fs = std::filesystem;

struct CompareArguments {
    std::string reference, sim, frames;
};

struct FrameRange {
    int first = 0, last = std::numeric_limits<int>::max();
    bool given = false;
};

// "A:B" (inclusive), "A:", ":B" or "A".
FrameRange parseRange(const std::string& text) {
    FrameRange range;
    if (text.empty()) return range;
    std::smatch m;
    if (!std::regex_match(text, m, std::regex(R"((\d*)(:?)(\d*))")) || (m[1].str().empty() && m[3].str().empty()))
        throw InputError("--frames: expected A:B, A:, :B or A (frame numbers), got \"" + text + "\"");
    range.given = true;
    if (!m[1].str().empty()) range.first = std::stoi(m[1].str());
    if (!m[3].str().empty()) range.last = std::stoi(m[3].str());
    else if (m[2].str().empty()) range.last = range.first;
    if (range.last < range.first) throw InputError("--frames: " + text + " ends before it starts");
    return range;
}

// The frame numbers of DIR/frame_NNNNN.vdb.
std::vector<int> vdbFrames(const fs::path& dir, const std::string& option) {
    if (!fs::is_directory(dir)) throw InputError(option + ": " + dir.string() + " is not a folder");
    std::vector<int> frames;
    const std::regex name(R"(frame_(\d{5})\.vdb)");
    for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
        std::smatch m;
        const std::string file = entry.path().filename().string();
        if (std::regex_match(file, m, name)) frames.push_back(std::stoi(m[1].str()));
    }
    std::sort(frames.begin(), frames.end());
    return frames;
}

nlohmann::json finiteOrNull(double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); }

int runCompare(const CompareArguments& args) {
    const FrameRange range = parseRange(args.frames);
    const fs::path referenceDir = args.reference, simDir = args.sim;
    const std::vector<int> referenceFrames = vdbFrames(referenceDir, "--reference");
    const std::vector<int> simFrames = vdbFrames(simDir, "--sim");
    const auto has = [](const std::vector<int>& list, int f) { return std::binary_search(list.begin(), list.end(), f); };
    const auto missing = [](const std::string& option, const fs::path& dir, int f) {
        return InputError(option + ": " + (dir / frameName("frame", f, "vdb")).string() + " missing (asked for by --frames)");
    };
    // A range with an end must be complete in both folders; otherwise the frames both have count.
    const bool bounded = range.given && range.last != std::numeric_limits<int>::max();
    std::vector<int> frames;
    if (bounded) {
        for (int f = range.first; f <= range.last; ++f) {
            if (!has(referenceFrames, f)) throw missing("--reference", referenceDir, f);
            if (!has(simFrames, f)) throw missing("--sim", simDir, f);
            frames.push_back(f);
        }
    } else {
        for (int f : referenceFrames)
            if (f >= range.first && has(simFrames, f)) frames.push_back(f);
    }
    if (frames.empty())
        throw InputError("--reference/--sim: no frame_NNNNN.vdb common to " + referenceDir.string() + " and " +
                         simDir.string() + (range.given ? " in --frames " + args.frames : ""));

    nlohmann::json perFrame = nlohmann::json::array();
    surface::FieldDifference total;
    for (int f : frames) {
        if (cancelRequested()) return kExitCancelled;
        const surface::FieldDifference d =
            surface::compareFields(surface::readFrameFields(referenceDir / frameName("frame", f, "vdb")),
                                   surface::readFrameFields(simDir / frameName("frame", f, "vdb")));
        total += d;
        perFrame.push_back({{"frame", f}, {"samples", d.samples},
                            {"epsilon_v", finiteOrNull(d.relativeVelocityError())},
                            {"epsilon_p", finiteOrNull(d.relativePressureError())}});
    }
    const nlohmann::json result{
        {"format", "viscoscope.compare"},
        {"version", 1},
        {"reference", referenceDir.string()},
        {"sim", simDir.string()},
        {"sampling", "reference cell centres inside both surfaces whose 26 neighbours hold liquid; the simulation "
                     "sampled trilinearly there, where all eight voxels it reads were written"},
        {"epsilon_v", finiteOrNull(total.relativeVelocityError())},
        {"epsilon_p", finiteOrNull(total.relativePressureError())},
        {"samples", total.samples},
        {"frames", perFrame}};
    std::cout << result.dump(1) << std::endl;
    return kExitOk;
}

}  // namespace

Command addCompareCommand(CLI::App& app) {
    auto args = std::make_shared<CompareArguments>();
    CLI::App* sub = app.add_subcommand(
        "compare",
        "Relative L2 errors of velocity (epsilon_v) and pressure (epsilon_p) of a simulation against a reference\n"
        "simulation, per frame and over all frames (JSON on stdout). Both folders hold simulate's\n"
        "frame_NNNNN.vdb; the grids may have different resolutions. Null where the reference field is zero.");
    sub->add_option("--reference", args->reference, "The reference simulation's folder (e.g. synth's DIR/simulation)")
        ->required();
    sub->add_option("--sim", args->sim, "The simulation to check (e.g. identify's OUT/fields)")->required();
    sub->add_option("--frames", args->frames, "A:B, inclusive (A:, :B and A work too); default: the frames both have");
    return {sub, [args] { return runCompare(*args); }};
}

}  // namespace viscoscope::cli
