// Progress for long commands: one JSON object per line on stdout (`--progress json`, what the
// Blender add-on reads), a short human line on stderr (`text`), or nothing.
#pragma once

#include "identify/identify.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <iostream>
#include <vector>
#include <string>

namespace viscoscope::cli {

class ProgressReporter {
public:
    explicit ProgressReporter(std::string format) : format_(std::move(format)) {}
    // A warning reaches the user whatever the format: a JSON event, or a line on stderr.
    void warn(const std::string& message) const {
        if (format_ == "json") std::cout << nlohmann::json{{"event", "warning"}, {"message", message}}.dump() << std::endl;
        else std::cerr << "warning: " << message << '\n';
    }
    void report(const nlohmann::json& event) const {
        if (format_ == "json") {
            std::cout << event.dump() << std::endl;  // flushed: a reader polls line by line
        } else if (format_ == "text") {
            std::cerr << event.value("event", "") << ':';
            for (const auto& [key, value] : event.items())
                if (key != "event") std::cerr << ' ' << key << '=' << value.dump();
            std::cerr << '\n';
        }
    }

private:
    std::string format_;
};

// An identification's progress after a generation: identify's, and each fit of diagnose's.
// `names`: the searched parameters'.
inline nlohmann::json generationEvent(const std::vector<std::string>& names, const identify::GenerationReport& r) {
    nlohmann::json event{{"event", "progress"},         {"stage", "identify"},           {"generation", r.generation},
                         {"generations", r.generations}, {"evaluations", r.evaluations}, {"resolution", r.resolution},
                         {"fidelity", r.coarse ? "coarse" : "full"},
                         {"sigma", r.sigma},             {"elapsed", r.elapsed},         {"remaining_s", r.remaining}};
    if (!r.bestTheta.empty()) {
        nlohmann::json theta = nlohmann::json::object();
        for (size_t i = 0; i < names.size() && i < r.bestTheta.size(); ++i) {
            theta[names[i]] = r.bestTheta[i];
            if (names[i] == "viscosity") event["best_eta"] = r.bestTheta[i];
        }
        event["best_theta"] = theta;
    }
    if (std::isfinite(r.bestE)) event["best_E"] = r.bestE;
    if (r.resumed) event["resumed"] = true;
    return event;
}

}  // namespace viscoscope::cli
