// `viscoscope check FILE...`: reads each scene, job or camera file as `simulate`, `identify` and
// `camera` would, and prints "FILE: ok (FORMAT)" or exits 2 with the reader's one-line reason.
// The add-on's contract test has the engine read back every file the add-on writes through it.
#include "cli/commands.h"
#include "camera/camera.h"
#include "identify/identify.h"
#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace viscoscope::cli {

namespace {
std::string formatOf(const std::string& file) {
    std::ifstream in(file);
    if (!in) throw InputError(file + ": cannot open");
    const nlohmann::json doc = parseJsonStrictly(in, file);
    if (!doc.is_object() || !doc.contains("format") || !doc.at("format").is_string())
        throw InputError(file + ": format: missing (viscoscope.scene, viscoscope.job, viscoscope.camera or "
                                "viscoscope.blender_camera)");
    return doc.at("format").get<std::string>();
}
}  // namespace

Command addCheckCommand(CLI::App& app) {
    CLI::App* sub = app.add_subcommand("check", "Read scene, job or camera files as the engine would; exit 2 at the first problem");
    auto files = std::make_shared<std::vector<std::string>>();
    sub->add_option("files", *files, "Files to read (their \"format\" says what they are)")->required();
    return {sub, [files] {
                for (const std::string& file : *files) {
                    const std::string format = formatOf(file);
                    if (format == "viscoscope.scene") loadScene(file);
                    else if (format == "viscoscope.job") identify::loadJob(file);
                    else if (format == "viscoscope.camera" || format == "viscoscope.blender_camera") loadCamera(file);
                    else throw InputError(file + ": format: \"" + format + "\" is not a scene, job or camera");
                    std::cout << file << ": ok (" << format << ")\n";
                }
                return kExitOk;
            }};
}

}  // namespace viscoscope::cli
