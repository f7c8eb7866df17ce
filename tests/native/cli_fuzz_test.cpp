// Mutation fuzzing of the engine's readers, as a careless or hostile user would feed them: one
// change at a time to a valid scene, job, measured-track CSV and camera, each read by
// `viscoscope check` under a time limit. Every mutant must be accepted (exit 0) or refused with
// exit 2 and one line; never a crash, a hang, an exit 1 or a message on several lines. The corpus is
// drawn from a fixed seed, so a failure names a mutant that reproduces; inputs that once failed
// stay in kRegressions.
#include "cli_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using viscoscope::cli_test::CommandResult;
using viscoscope::cli_test::slurp;

// Per file; VISCOSCOPE_FUZZ_MUTANTS sets another count for a longer run by hand.
int mutantsPerFile() {
    const char* given = std::getenv("VISCOSCOPE_FUZZ_MUTANTS");
    return given ? std::max(1, std::atoi(given)) : 100;
}
constexpr int kSecondsPerRead = 30;  // `check` reads in well under a second: beyond this it hangs
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

class Fuzz : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("viscoscope_fuzz_" + std::to_string(::getpid()) + "_" +
                                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        std::ifstream(fs::path(VISCOSCOPE_SOURCE_DIR) / "sample_scenes/capture_cup.json") >> scene_;
        std::ifstream(fs::path(VISCOSCOPE_SOURCE_DIR) / "sample_scenes/capture_camera.json") >> camera_;
        job_ = {{"format", "viscoscope.job"},
                {"version", 1},
                {"scene", "scene.json"},
                {"track", {{"csv", "front.csv"}, {"column", "front_m"}, {"observable", "front"},
                           {"origin", {0, 0, 0}}, {"direction", {1, 0, 0}}}},
                {"parameters", {{{"name", "viscosity"}, {"initial", 8}, {"spread", 4}, {"min", 0.1}, {"max", 100},
                                 {"log", true}}}},
                {"fixed", {{{"name", "surface_tension"}, {"value", 0.07}, {"uncertainty", 0.005}}}},
                {"resolution", 24},
                {"max_generations", 3},
                {"seed", 2}};
        write("scene.json", scene_.dump(1));
        write("front.csv", kTrack);
    }
    void TearDown() override { fs::remove_all(dir_); }

    void write(const std::string& name, const std::string& text) const {
        std::ofstream(dir_ / name, std::ios::binary) << text;
    }

    // Reads `file` with `check` and records the outcome; returns a description of a broken promise.
    std::string probe(const std::string& file, const std::string& mutation) {
        const CommandResult r = viscoscope::cli_test::runCommand(
            "ulimit -v " + std::to_string(kMemoryKiB) + "; timeout -s KILL " + std::to_string(kSecondsPerRead) + " " +
                VISCOSCOPE_CLI + " check " + (dir_ / file).string(),
            dir_ / "run");
        ++outcomes_[r.exitCode];
        const auto lines = std::count(r.err.begin(), r.err.end(), '\n');
        if (r.exitCode == 0 && r.out.find(": ok (") != std::string::npos) {
            std::printf("[ accepted ] %s with %s\n", file.c_str(), mutation.c_str());
            return "";
        }
        if (r.exitCode == 2 && lines == 1 && r.err.rfind("viscoscope: ", 0) == 0) return "";
        return file + " with " + mutation + ": exit " + std::to_string(r.exitCode) + ", stderr: " + r.err;
    }

    // mutantsPerFile() mutants of `valid`, written to `file` one at a time and each probed, while the
    // files it refers to stay valid.
    void fuzzDocument(const std::string& file, const json& valid, unsigned seed) {
        fs::create_directories(dir_ / "run");
        std::mt19937 random(seed);
        const json leaves = valid.flatten();
        std::vector<std::string> pointers;
        for (const auto& item : leaves.items()) pointers.push_back(item.key());
        std::vector<std::string> failures;
        for (int m = 0; m < mutantsPerFile(); ++m) {
            const std::string pointer = pointers[random() % pointers.size()];
            json doc = valid;
            std::string text, mutation;
            switch (random() % 6) {
                case 0: {  // a hostile value in a field
                    const json& value = kHostileValues[random() % kHostileValues.size()];
                    doc[json::json_pointer(pointer)] = value;
                    mutation = pointer + " = " + value.dump();
                    break;
                }
                case 1: {  // the field's object loses the key (or its array the element)
                    json::json_pointer at(pointer);
                    const std::string last = at.back();
                    at.pop_back();
                    if (doc[at].is_object()) doc[at].erase(last);
                    else doc[at].erase(std::stoul(last));
                    mutation = "no " + pointer;
                    break;
                }
                case 2: {  // a misspelt key: one letter dropped from the name of the field's last key
                    json::json_pointer at(pointer);
                    std::string last = at.back();
                    at.pop_back();
                    if (!doc[at].is_object() || last.size() < 2) continue;
                    const json value = doc[at][last];
                    doc[at].erase(last);
                    last.erase(random() % last.size(), 1);
                    doc[at][last] = value;
                    mutation = pointer + " misspelt " + last;
                    break;
                }
                case 3: {  // the text cut short
                    text = valid.dump(1);
                    text.resize(random() % text.size());
                    mutation = "the text cut at " + std::to_string(text.size());
                    break;
                }
                case 4: {  // a byte of the text changed
                    text = valid.dump(1);
                    const size_t at = random() % text.size();
                    text[at] = static_cast<char>(random() % 256);
                    mutation = "byte " + std::to_string(at) + " changed";
                    break;
                }
                default: {  // a key repeated, or text after the document
                    text = valid.dump(1);
                    if (random() % 2) {
                        text.insert(1, "\"version\": 1, ");
                        mutation = "\"version\" given twice";
                    } else {
                        text += " {}";
                        mutation = "text after the document";
                    }
                }
            }
            write(file, text.empty() ? doc.dump(1) : text);
            if (const std::string failure = probe(file, mutation); !failure.empty()) failures.push_back(failure);
        }
        write(file, valid.dump(1));
        for (const std::string& failure : failures) ADD_FAILURE() << failure;
    }

    void printOutcomes(const char* what) const {
        std::printf("[ fuzz     ] %s:", what);
        for (const auto& [code, count] : outcomes_) std::printf(" %d × exit %d", count, code);
        std::printf("\n");
    }

    static constexpr const char* kTrack = "time_s,front_m\n0,0.05\n0.5,0.07\n1.0,0.08\n";
    fs::path dir_;
    json scene_, camera_, job_;
    std::map<int, int> outcomes_;
};

}  // namespace

TEST_F(Fuzz, MutatedScenesAreAcceptedOrRefusedInOneLine) {
    fuzzDocument("scene.json", scene_, 1);
    printOutcomes("scene.json");
}

TEST_F(Fuzz, MutatedJobsAreAcceptedOrRefusedInOneLine) {
    fuzzDocument("job.json", job_, 2);
    printOutcomes("job.json");
}

TEST_F(Fuzz, MutatedCamerasAreAcceptedOrRefusedInOneLine) {
    fuzzDocument("camera.json", camera_, 3);
    printOutcomes("camera.json");
}

// The measured track's CSV, read through a valid job: cut short, a byte changed, a line doubled.
TEST_F(Fuzz, MutatedTrackCsvsAreAcceptedOrRefusedInOneLine) {
    write("job.json", job_.dump(1));
    fs::create_directories(dir_ / "run");
    const std::string valid = kTrack;
    std::mt19937 random(4);
    std::vector<std::string> failures;
    for (int m = 0; m < mutantsPerFile(); ++m) {
        std::string text = valid;
        const size_t at = random() % text.size();
        std::string mutation;
        switch (random() % 4) {
            case 0: text.resize(at), mutation = "cut at " + std::to_string(at); break;
            case 1: text[at] = static_cast<char>(random() % 256), mutation = "byte " + std::to_string(at); break;
            case 2: text.insert(at, "-1e999"), mutation = "-1e999 at " + std::to_string(at); break;
            default: text.insert(at, "\n0.25,nan\n"), mutation = "a NaN row at " + std::to_string(at);
        }
        write("front.csv", text);
        if (const std::string failure = probe("job.json", "front.csv " + mutation); !failure.empty())
            failures.push_back(failure);
    }
    for (const std::string& failure : failures) ADD_FAILURE() << failure;
    printOutcomes("front.csv");
}

TEST_F(Fuzz, InputsThatOnceFailedStayRefusedInOneLine) {
    fs::create_directories(dir_ / "run");
    for (const auto& [file, text] : kRegressions) {
        write(file, text);
        const std::string failure = probe(file, "a regression case");
        EXPECT_TRUE(failure.empty()) << failure;
        EXPECT_EQ(outcomes_.count(0), 0u) << text.substr(0, 200) << " was accepted";
    }
}
