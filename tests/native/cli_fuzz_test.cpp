// Mutation fuzzing of every path into the engine, as a careless or hostile user would feed it: one
// change at a time to a valid scene, job, camera, measured-track CSV, clip, reference (manifest and
// masks), solid mesh, simulate's resume state and identify's checkpoint, each read by the command
// that reads it under a time and memory limit. Every mutant must be accepted (exit 0, with the
// command's result file written and not empty) or refused with exit 2 and one line; never a crash,
// a hang, an exit 1 or a message on several lines. The corpora are drawn from fixed seeds, so a
// failure names a mutant that reproduces; inputs that once failed stay in kRegressions.
//
// VISCOSCOPE_FUZZ_MUTANTS sets another count per corpus for a longer run by hand;
// VISCOSCOPE_FUZZ_ENGINE runs the corpora against another build (FINDINGS' "before").
#include "cli_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using viscoscope::cli_test::CommandResult;
using viscoscope::cli_test::slurp;
using namespace viscoscope::cli_test::slump;

int mutantsPerCorpus() {
    const char* given = std::getenv("VISCOSCOPE_FUZZ_MUTANTS");
    return given ? std::max(1, std::atoi(given)) : 100;
}
// Corpora whose every mutant simulates (a second or two each) run half as many.
int simulatingMutants() { return std::max(1, mutantsPerCorpus() / 2); }

std::string engine() {
    const char* other = std::getenv("VISCOSCOPE_FUZZ_ENGINE");
    return other ? other : VISCOSCOPE_CLI;
}

constexpr int kSecondsPerRun = 60;   // the slowest command here runs in a few seconds: beyond this it hangs
constexpr int kMemoryKiB = 8 << 20;  // 8 GiB of address space: a reader that asks for more fails

// Values a field must survive: wrong types, zero, negative, tiny, past int and double ranges.
const std::vector<json> kHostileValues{
    -1, 0, 1e308, -1e308, 1e-320, 3.5, 2147483648.0, -2147483649.0, 1e18, "", "x", nullptr, true,
    json::array(), json::object(), json::array({1, 2, 3}), json{{"a", 1}}, json::array({json::array({})}),
};

// Inputs that once failed (crash, hang, exit 1 or a misleading message); each stays a case.
const std::vector<std::pair<std::string, std::string>> kRegressions{
    {"scene.json", R"({"format": "viscoscope.scene", "version": 1, "domain": {"min": [0, 0, 0], "max": [1e309, 1, 1]}})"},
    {"scene.json", std::string(100000, '[') + std::string(100000, ']')},
    {"job.json", R"({"format": "viscoscope.job", "version": 1, "scene": "."})"},
};

// A text or a file's bytes and what was done to it.
struct Mutant {
    std::string text, mutation;
};

// One change to a JSON document: a hostile value in a field, a field dropped, a key misspelt, the
// text cut short or a byte of it changed, a key given twice, text after the document. Empty text
// when the change does not apply (a one-letter key cannot lose a letter).
Mutant mutatedDocument(const json& valid, std::mt19937& random) {
    const json leaves = valid.flatten();
    std::vector<std::string> pointers;
    for (const auto& item : leaves.items()) pointers.push_back(item.key());
    const std::string pointer = pointers[random() % pointers.size()];
    json doc = valid;
    switch (random() % 6) {
        case 0: {
            const json& value = kHostileValues[random() % kHostileValues.size()];
            doc[json::json_pointer(pointer)] = value;
            return {doc.dump(1), pointer + " = " + value.dump()};
        }
        case 1: {  // the field's object loses the key (or its array the element)
            json::json_pointer at(pointer);
            const std::string last = at.back();
            at.pop_back();
            if (doc[at].is_object()) doc[at].erase(last);
            else doc[at].erase(std::stoul(last));
            return {doc.dump(1), "no " + pointer};
        }
        case 2: {  // one letter dropped from the name of the field's last key
            json::json_pointer at(pointer);
            std::string last = at.back();
            at.pop_back();
            if (!doc[at].is_object() || last.size() < 2) return {};
            const json value = doc[at][last];
            doc[at].erase(last);
            last.erase(random() % last.size(), 1);
            doc[at][last] = value;
            return {doc.dump(1), pointer + " misspelt " + last};
        }
        case 3: {
            std::string text = valid.dump(1);
            text.resize(random() % text.size());
            return {text, "the text cut at " + std::to_string(text.size())};
        }
        case 4: {
            std::string text = valid.dump(1);
            const size_t at = random() % text.size();
            text[at] = static_cast<char>(random() % 256);
            return {text, "byte " + std::to_string(at) + " changed"};
        }
        default: {
            std::string text = valid.dump(1);
            if (random() % 2) return {text.insert(1, "\"version\": 1, "), "\"version\" given twice"};
            return {text + " {}", "text after the document"};
        }
    }
}

// One change to a file's bytes: cut short, a byte changed, 16 bytes overwritten, a line repeated or
// dropped, or one of `insertions` put in. Half of the changes fall within the first `header` bytes,
// where a format keeps what says how to read the rest.
Mutant mutatedBytes(const std::string& valid, std::mt19937& random, const std::vector<std::string>& insertions,
                    size_t header) {
    std::string bytes = valid;
    const size_t at = random() % (random() % 2 ? std::min(header, bytes.size()) : bytes.size());
    const std::string where = " at byte " + std::to_string(at);
    switch (random() % 6) {
        case 0: return {bytes.substr(0, at), "cut" + where};
        case 1: bytes[at] = static_cast<char>(random() % 256); return {bytes, "a byte changed" + where};
        case 2:
            for (size_t i = at; i < std::min(at + 16, bytes.size()); ++i) bytes[i] = static_cast<char>(random() % 256);
            return {bytes, "16 bytes overwritten" + where};
        case 3:
        case 4: {  // the line holding `at` repeated or dropped
            const size_t before = at == 0 ? std::string::npos : bytes.rfind('\n', at - 1);
            const size_t begin = before == std::string::npos ? 0 : before + 1;
            const size_t end = std::min(bytes.find('\n', at), bytes.size() - 1) + 1;
            const std::string line = bytes.substr(begin, end - begin);
            if (random() % 2) return {bytes.insert(begin, line), "the line" + where + " repeated"};
            return {bytes.erase(begin, end - begin), "the line" + where + " dropped"};
        }
        default: {
            if (insertions.empty()) return {bytes.erase(at, 1), "a byte dropped" + where};
            const std::string& insertion = insertions[random() % insertions.size()];
            const std::string shown = json(insertion).dump(-1, ' ', false, json::error_handler_t::replace);
            return {bytes.insert(at, insertion), shown + " inserted" + where};
        }
    }
}

class Fuzz : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("viscoscope_fuzz_" + std::to_string(::getpid()) + "_" +
                                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_ / "logs");
    }
    void TearDown() override { fs::remove_all(dir_); }

    void write(const fs::path& file, const std::string& text) const {
        std::ofstream(file.is_absolute() ? file : dir_ / file, std::ios::binary) << text;
    }

    // Runs `viscoscope ARGUMENTS` in dir_ under the limits and records the outcome. Accepted is
    // exit 0 with `result` (when given) written and not empty; returns a description of a broken
    // promise, or nothing.
    std::string probe(const std::string& arguments, const std::string& mutation, const fs::path& result = {}) {
        const CommandResult r = viscoscope::cli_test::runCommand(
            "cd " + dir_.string() + " && ulimit -v " + std::to_string(kMemoryKiB) + "; timeout -s KILL " +
                std::to_string(kSecondsPerRun) + " " + engine() + " " + arguments,
            dir_ / "logs");
        ++outcomes_[r.exitCode];
        // Warnings may come first, each a line of its own; a refusal is one more line, the last.
        std::istringstream errLines(r.err);
        int lines = 0;
        for (std::string line; std::getline(errLines, line);) lines += line.rfind("warning: ", 0) == 0 ? 0 : 1;
        const std::string lastLine = r.err.substr(r.err.rfind('\n', r.err.size() - 2) + 1);
        if (r.exitCode == 0) {
            std::error_code ec;
            if (!result.empty() && !(fs::exists(dir_ / result) && fs::file_size(dir_ / result, ec) > 0))
                return mutation + ": exit 0 without " + result.string();
            std::printf("[ accepted ] %s\n", mutation.c_str());
            return "";
        }
        if (r.exitCode == 2 && lines == 1 && lastLine.rfind("viscoscope: ", 0) == 0 && r.err.back() == '\n') return "";
        return mutation + ": exit " + std::to_string(r.exitCode) + ", stderr: " + r.err;
    }

    // `count` mutants made by `mutate`, each handed to `tryMutant`, which probes it; the broken
    // promises are the test's failures.
    void fuzz(int count, const std::function<Mutant()>& mutate,
              const std::function<std::string(const Mutant&)>& tryMutant) {
        std::vector<std::string> failures;
        for (int m = 0; m < count; ++m) {
            const Mutant mutant = mutate();
            if (mutant.mutation.empty()) continue;
            if (const std::string failure = tryMutant(mutant); !failure.empty()) failures.push_back(failure);
        }
        for (const std::string& failure : failures) ADD_FAILURE() << failure;
    }

    // Mutants of the document `valid`, each written to `file` and read by `check`.
    void fuzzChecked(const std::string& file, const json& valid, unsigned seed) {
        std::mt19937 random(seed);
        fuzz(mutantsPerCorpus(), [&] { return mutatedDocument(valid, random); },
             [&](const Mutant& m) {
                 write(file, m.text);
                 return probe("check " + file, file + " with " + m.mutation);
             });
        write(file, valid.dump(1));
    }

    void printOutcomes(const char* what) const {
        std::printf("[ fuzz     ] %s:", what);
        for (const auto& [code, count] : outcomes_) std::printf(" %d × exit %d", count, code);
        std::printf("\n");
    }

    // A measured-track job of the sample cup, for the readers `check` drives.
    void writeTrackJob() {
        std::ifstream(fs::path(VISCOSCOPE_SOURCE_DIR) / "sample_scenes/capture_cup.json") >> cupScene_;
        trackJob_ = {{"format", "viscoscope.job"},
                     {"version", 1},
                     {"scene", "scene.json"},
                     {"track", {{"csv", "front.csv"}, {"column", "front_m"}, {"observable", "front"},
                                {"origin", {0, 0, 0}}, {"direction", {1, 0, 0}}}},
                     {"parameters", {{{"name", "viscosity"}, {"initial", 8}, {"spread", 4}, {"min", 0.1},
                                      {"max", 100}, {"log", true}}}},
                     {"fixed", {{{"name", "surface_tension"}, {"value", 0.07}, {"uncertainty", 0.005}}}},
                     {"resolution", 24},
                     {"max_generations", 3},
                     {"seed", 2}};
        write("scene.json", cupScene_.dump(1));
        write("front.csv", kTrack);
        write("job.json", trackJob_.dump(1));
    }

    static constexpr const char* kTrack = "time_s,front_m\n0,0.05\n0.5,0.07\n1.0,0.08\n";
    // A valid 12-frame clip's bytes.
    std::string testClip() const {
        const fs::path clip = dir_ / "valid.mp4";
        EXPECT_TRUE(viscoscope::cli_test::makeTestClip(clip, 12));
        return slurp(clip);
    }

    static std::string identifyInto(const std::string& out) {
        return "identify job.json --out " + out + " --progress none --no-plots --no-fields";
    }
    fs::path dir_;
    json cupScene_, trackJob_;
    std::map<int, int> outcomes_;
};

}  // namespace

TEST_F(Fuzz, MutatedScenesAreAcceptedOrRefusedInOneLine) {
    writeTrackJob();
    fuzzChecked("scene.json", cupScene_, 1);
    printOutcomes("scene.json");
}

TEST_F(Fuzz, MutatedJobsAreAcceptedOrRefusedInOneLine) {
    writeTrackJob();
    fuzzChecked("job.json", trackJob_, 2);
    printOutcomes("job.json");
}

TEST_F(Fuzz, MutatedCamerasAreAcceptedOrRefusedInOneLine) {
    json camera;
    std::ifstream(fs::path(VISCOSCOPE_SOURCE_DIR) / "sample_scenes/capture_camera.json") >> camera;
    fuzzChecked("camera.json", camera, 3);
    printOutcomes("camera.json");
}

// The measured track's CSV, read through a valid job.
TEST_F(Fuzz, MutatedTrackCsvsAreAcceptedOrRefusedInOneLine) {
    writeTrackJob();
    std::mt19937 random(4);
    fuzz(mutantsPerCorpus(), [&] { return mutatedBytes(kTrack, random, {"-1e999", "\n0.25,nan\n", "\n-1,0.1\n", ","}, 16); },
         [&](const Mutant& m) {
             write("front.csv", m.text);
             return probe("check job.json", "front.csv with " + m.mutation);
         });
    printOutcomes("front.csv");
}

// A clip damaged as a failing card or an interrupted copy leaves it, through `extract`.
TEST_F(Fuzz, MutatedClipsAreExtractedOrRefusedInOneLine) {
    if (!viscoscope::cli_test::haveFfmpeg()) GTEST_SKIP() << "ffmpeg not installed";
    const std::string valid = testClip();
    std::mt19937 random(5);
    fuzz(simulatingMutants(), [&] { return mutatedBytes(valid, random, {std::string(64, '\0')}, 1024); },
         [&](const Mutant& m) {
             fs::remove_all(dir_ / "out");
             write("clip.mp4", m.text);
             return probe("extract clip.mp4 --out out --progress none", "clip.mp4 with " + m.mutation,
                          "out/manifest.json");
         });
    printOutcomes("clip.mp4");
}

// The reference silhouettes a job compares with: its manifest and a mask, through `identify`.
TEST_F(Fuzz, MutatedReferencesAreIdentifiedOrRefusedInOneLine) {
    writeSlumpCase(dir_);
    write("job.json", slumpJob(1).dump(1));
    const json manifest = json::parse(slurp(dir_ / "reference/manifest.json"));
    const std::string mask = slurp(dir_ / "reference/masks/mask_2.pgm");
    std::mt19937 random(6);
    fuzz(simulatingMutants(),
         [&] {
             if (random() % 2) {
                 Mutant m = mutatedDocument(manifest, random);
                 m.mutation = m.mutation.empty() ? "" : "manifest.json with " + m.mutation;
                 return m;
             }
             Mutant m = mutatedBytes(mask, random, {"P5\n", "-1 ", "99999999 "}, 15);
             m.mutation = "mask_2.pgm with " + m.mutation;
             return m;
         },
         [&](const Mutant& m) {
             write("reference/manifest.json", manifest.dump(1));
             write("reference/masks/mask_2.pgm", mask);
             write(m.mutation.rfind("manifest", 0) == 0 ? "reference/manifest.json" : "reference/masks/mask_2.pgm",
                   m.text);
             fs::remove_all(dir_ / "out");
             return probe(identifyInto("out"), m.mutation, "out/result.json");
         });
    printOutcomes("reference");
}

// A solid's OBJ, as exporters and hand edits damage it, through `simulate`.
TEST_F(Fuzz, MutatedMeshesAreSimulatedOrRefusedInOneLine) {
    json scene = slumpScene();
    scene["frames"] = 1;
    scene["solids"].push_back({{"type", "mesh"}, {"path", "block.obj"}});
    write("scene.json", scene.dump(1));
    std::string cube;  // a 1 cm block on the ground beside the liquid
    for (int corner = 0; corner < 8; ++corner)
        cube += "v " + std::to_string(corner & 1 ? 0.07 : 0.06) + " " + std::to_string(corner & 2 ? 0.03 : 0.02) +
                " " + std::to_string(corner & 4 ? 0.01 : 0.0) + "\n";
    for (const char* face : {"1 3 2", "2 3 4", "5 6 7", "6 8 7", "1 2 5", "2 6 5", "3 7 4", "4 7 8", "1 5 3",
                             "3 5 7", "2 4 6", "4 8 6"})
        cube += std::string("f ") + face + "\n";
    std::mt19937 random(7);
    fuzz(simulatingMutants(),
         [&] {
             return mutatedBytes(cube, random,
                                 {"v 1e308 0 0\n", "v nan 0 0\n", "f 1 2 99999999\n", "f 0 0 0\n", "f -1 -2 -3\n",
                                  "f 1 2\n", "f 1//1 2//1 3//1\n", "vt 0 0\n", "o block\n", "v 10 10 10\n"},
                                 cube.size());
         },
         [&](const Mutant& m) {
             write("block.obj", m.text);
             fs::remove_all(dir_ / "out");
             return probe("simulate scene.json --out out --progress none", "block.obj with " + m.mutation,
                          "out/simulation.json");
         });
    printOutcomes("block.obj");
}

// simulate's resume state, cut short or damaged by a crash or a copy: resumed, or started over.
TEST_F(Fuzz, MutatedResumeStatesAreResumedOrRefusedInOneLine) {
    json scene = slumpScene();
    scene["frames"] = 16;
    write("scene.json", scene.dump(1));
    // Cancelled after its second frame, the run leaves cut/resume.state.
    ASSERT_EQ(viscoscope::cli_test::runCommand(
                  "cd " + dir_.string() + " && (" + engine() + " simulate scene.json --out cut --progress none & " +
                      "pid=$!; while [ ! -e cut/particles_00002.bin ] && kill -0 $pid; do sleep 0.01; done; " +
                      "kill -TERM $pid; wait $pid)",
                  dir_ / "logs").exitCode, 3);
    const std::string valid = slurp(dir_ / "cut/resume.state");
    ASSERT_GT(valid.size(), sizeof(uint64_t));
    uint64_t headerLength = 0;
    std::memcpy(&headerLength, valid.data(), sizeof headerLength);
    std::mt19937 random(8);
    fuzz(simulatingMutants(),
         [&] { return mutatedBytes(valid, random, {std::string(8, '\xff'), "{}"}, sizeof headerLength + headerLength); },
         [&](const Mutant& m) {
             fs::remove_all(dir_ / "out");
             fs::copy(dir_ / "cut", dir_ / "out", fs::copy_options::recursive);
             write("out/resume.state", m.text);
             return probe("simulate scene.json --out out --progress none", "resume.state with " + m.mutation,
                          "out/simulation.json");
         });
    printOutcomes("resume.state");
}

// identify's checkpoint, damaged or hand-edited between two runs of one job.
TEST_F(Fuzz, MutatedCheckpointsAreResumedOrRefusedInOneLine) {
    writeSlumpCase(dir_);
    write("job.json", slumpJob(1).dump(1));
    ASSERT_EQ(probe(identifyInto("done"), "the valid job", "done/result.json"), "");
    const json checkpoint = json::parse(slurp(dir_ / "done/checkpoint.json"));
    write("job.json", slumpJob(2).dump(1));  // one generation more: the resume goes on from the checkpoint
    std::mt19937 random(9);
    fuzz(simulatingMutants(), [&] { return mutatedDocument(checkpoint, random); },
         [&](const Mutant& m) {
             fs::remove_all(dir_ / "out");
             fs::copy(dir_ / "done", dir_ / "out", fs::copy_options::recursive);
             write("out/checkpoint.json", m.text);
             return probe(identifyInto("out"), "checkpoint.json with " + m.mutation, "out/result.json");
         });
    printOutcomes("checkpoint.json");
}

TEST_F(Fuzz, InputsThatOnceFailedStayRefusedInOneLine) {
    for (const auto& [file, text] : kRegressions) {
        write(file, text);
        const std::string failure = probe("check " + file, "a regression case");
        EXPECT_TRUE(failure.empty()) << failure;
        EXPECT_EQ(outcomes_.count(0), 0u) << text.substr(0, 200) << " was accepted";
    }
}

// Mutants of the other corpora that once failed: a clip whose container no longer says how many
// frames it holds (its preview had no frame to show: exit 1), a mask cut short (OpenCV's decoder
// printed its own two lines before ours), a checkpoint with a value of the wrong type (an internal
// error, exit 1).
TEST_F(Fuzz, DamagedFilesThatOnceFailedAreAcceptedOrRefusedInOneLine) {
    if (viscoscope::cli_test::haveFfmpeg()) {
        const std::string clip = testClip();
        write("clip.mp4", clip.substr(0, 5) + std::string(64, '\0') + clip.substr(5));
        EXPECT_EQ(probe("extract clip.mp4 --out clip_out --progress none", "clip.mp4 with 64 NULs at byte 5",
                        "clip_out/preview.png"), "");
    }
    writeSlumpCase(dir_);
    write("job.json", slumpJob(1).dump(1));
    ASSERT_EQ(probe(identifyInto("done"), "the valid job", "done/result.json"), "");
    const std::string mask = slurp(dir_ / "reference/masks/mask_2.pgm");
    write("reference/masks/mask_2.pgm", mask.substr(0, 43));
    EXPECT_EQ(probe(identifyInto("out"), "mask_2.pgm cut at byte 43"), "");
    write("reference/masks/mask_2.pgm", mask);
    json checkpoint = json::parse(slurp(dir_ / "done/checkpoint.json"));
    checkpoint["evaluated"][2]["seconds"] = true;
    write("done/checkpoint.json", checkpoint.dump(1));
    write("job.json", slumpJob(2).dump(1));
    EXPECT_EQ(probe(identifyInto("done"), "checkpoint.json with /evaluated/2/seconds = true"), "");
    EXPECT_EQ(outcomes_.at(2), 2) << "a damaged mask or checkpoint was accepted";
}
