// Progress for long commands: one JSON object per line on stdout (`--progress json`, what the
// Blender add-on reads), a short human line on stderr (`text`), or nothing.
#pragma once

#include <nlohmann/json.hpp>

#include <iostream>
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

}  // namespace viscoscope::cli
