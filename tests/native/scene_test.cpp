// Scene validation: every bad field is named in the error; a valid scene round-trips.
#include "scene/scene.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <sstream>
#include <unistd.h>

using namespace viscoscope;
using nlohmann::json;

namespace {

json validScene() {
    return json::parse(R"({
      "format": "viscoscope.scene", "version": 1,
      "domain": {"min": [-0.09, -0.09, 0], "max": [0.09, 0.09, 0.18], "resolution": 32},
      "solids": [{"type": "ground", "height": 0},
                 {"type": "cup", "position": [0, 0, 0.1], "inner_radius": 0.043, "height": 0.05,
                  "wall_thickness": 0.006, "bottom_thickness": 0.005, "hole_radius": 0.009}],
      "liquids": [{"type": "cup_fill", "cup": 1, "volume": 1.7e-4}],
      "material": {"density": 1400, "viscosity": 8, "surface_tension": 0.07},
      "fps": 30, "frames": 10
    })");
}

std::string errorOf(const json& doc) {
    try {
        parseScene(doc, "scene.json");
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

}  // namespace

TEST(Scene, ValidSceneParsesInSiUnits) {
    const Scene s = parseScene(validScene(), "scene.json");
    EXPECT_DOUBLE_EQ(s.material.viscosity, 8);
    EXPECT_EQ(s.cellCounts(), Eigen::Vector3i(32, 32, 32));
    EXPECT_NEAR(s.cellSize(), 0.18 / 32, 1e-15);
    ASSERT_TRUE(std::holds_alternative<CupSolid>(s.solids[1]));
    EXPECT_DOUBLE_EQ(std::get<CupSolid>(s.solids[1]).holeRadius, 0.009);
}

// The surface smoothing is a length of the scene: a run on another grid draws the liquid alike.
TEST(Scene, SurfaceSmoothingStaysInMetresWhenTheResolutionChanges) {
    Scene s = parseScene(validScene(), "scene.json");
    const double atFileResolution = s.surfaceSmoothing();
    EXPECT_NEAR(atFileResolution, kSurfaceSmoothingPerCell * 0.18 / 32, 1e-15);
    s.domain.resolution = 64;
    EXPECT_EQ(s.surfaceSmoothing(), atFileResolution);
    EXPECT_EQ(parseScene(sceneToJson(s), "copy.json").surfaceSmoothing(), atFileResolution);
    json doc = validScene();
    doc["output"] = {{"surface_smoothing", 0.002}};
    EXPECT_EQ(parseScene(doc, "scene.json").surfaceSmoothing(), 0.002);
}

TEST(Scene, RoundTripsThroughJson) {
    const Scene a = parseScene(validScene(), "scene.json");
    const Scene b = parseScene(sceneToJson(a), "copy.json");
    EXPECT_EQ(sceneToJson(a), sceneToJson(b));
}

TEST(Scene, SolidsAreOpaqueUnlessMarkedTransparent) {
    json doc = validScene();
    EXPECT_TRUE(parseScene(doc, "scene.json").isOpaque(1));
    doc["solids"][1]["transparent"] = true;
    const Scene glass = parseScene(doc, "scene.json");
    EXPECT_EQ(glass.transparentSolids, std::vector<size_t>{1});
    EXPECT_TRUE(glass.isOpaque(0));
    EXPECT_FALSE(glass.isOpaque(1));
    EXPECT_EQ(sceneToJson(glass)["solids"][1]["transparent"], true);
    EXPECT_EQ(parseScene(sceneToJson(glass), "copy.json").transparentSolids, glass.transparentSolids);
    doc["solids"][1]["transparent"] = "yes";
    try {
        parseScene(doc, "scene.json");
        FAIL() << "a non-boolean transparent was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("scene.json.solids[1].transparent: must be true or false"),
                  std::string::npos) << e.what();
    }
}

TEST(Scene, BadFieldsAreNamed) {
    struct Case {
        std::string pointer;
        json value;
        std::string expected;
    };
    const std::vector<Case> cases{
        {"/material/viscosity", -1.0, "scene.json.material.viscosity: must be in [1e-06, 1e+09] Pa·s, got -1"},
        {"/material/density", 1e300, "scene.json.material.density: must be in [100, 25000] kg/m³, got 1e+300"},
        {"/material/viscosity", "thick", "scene.json.material.viscosity: must be a number"},
        {"/solids/1/hole_radius", 0.05, "scene.json.solids[1].hole_radius: must be smaller than inner_radius"},
        {"/domain/resolution", 2, "scene.json.domain.resolution: must be in [4, 1024]"},
        {"/domain/max", json::array({-1, 1, 1}), "scene.json.domain.max: must be greater than min"},
        {"/liquids", json::array(), "scene.json.liquids: must be a non-empty array"},
        {"/liquids/0/cup", 0, "scene.json.liquids[0].cup: must be the index of a solid of type 'cup'"},
        {"/liquids/0/volume", 1.0, "scene.json.liquids[0].volume: exceeds the cup's capacity"},
        {"/version", 99, "scene.json.version: is 99, newer than this engine reads"},
        {"/solids/0/type", "sphere", "scene.json.solids[0].type: unknown solid type 'sphere'"},
        {"/output/surface_smoothing", -0.001, "scene.json.output.surface_smoothing: must be > 0"},
        {"/output/surface_smoothing", 0.03, "scene.json.output.surface_smoothing: must be below 4 cells"},
        {"/solids/1/inner_radius", 1e300, "scene.json.solids[1].inner_radius: must be in [0.0001, 10] m"},
        {"/material/surface_tension", 1e6, "scene.json.material.surface_tension: must be in [0, 1] N/m"},
        {"/material/surface_tenson", 0.07, "scene.json.material.surface_tenson: unknown field; did you mean `surface_tension`?"},
        {"/solids/1/hole_radus", 0.005, "scene.json.solids[1].hole_radus: unknown field; did you mean `hole_radius`?"},
        {"/frame", 10, "scene.json.frame: unknown field; did you mean `frames`?"},
        {"/solver/toleranse", 1e-5, "scene.json.solver.toleranse: unknown field; did you mean `tolerance`?"},
        {"/material/model", json{{"type", "power_law"}, {"consistency", 3}, {"index", 0.5}}, "scene.json.material.model.flow_index: missing"},
        {"/material/model", json{{"type", "power_law"}, {"consistency", 3}, {"flow_index", 0.5}, {"colour", 1}},
         "scene.json.material.model.colour: unknown field"},
        // Runaway values and other units: refused, not run for hours or in an empty domain.
        {"/fps", 1e-9, "scene.json.fps: must be in [0.001, 1e+06] frames/s, got 1e-09"},
        {"/solver/cfl", 1e-6, "scene.json.solver.cfl: must be in [0.01, 10] cells a step, got 1e-06"},
        {"/gravity", json::array({0, 0, -1e300}), "scene.json.gravity: must be at most 1000 m/s² long (9.81 on Earth), "
                                                  "got 1e+300"},
        {"/domain/max", json::array({0.09, 1e18, 0.18}), "scene.json.domain.max: the domain is 1e+18 m long, more than "
                                                          "1000 m; is it in another unit?"},
        {"/solids/1/inner_radius", 10.0, "scene.json.solids[1].inner_radius: the cup is 20.012 m across, over 100 times "
                                         "the domain's longest side (0.18 m); is it in another unit?"},
        {"/solids/1/position", json::array({0, 0, 5}), "scene.json.solids[1].position: lies outside the domain"},
        {"/liquids/0", json{{"type", "box"}, {"min", {1, 1, 1}}, {"max", {2, 2, 2}}},
         "scene.json.liquids[0].min: lies outside the domain ([-0.09, -0.09, 0] to [0.09, 0.09, 0.18] m)"},
    };
    for (const Case& c : cases) {
        json doc = validScene();
        doc[json::json_pointer(c.pointer)] = c.value;
        EXPECT_EQ(errorOf(doc).rfind(c.expected, 0), 0u) << c.pointer << " gave: " << errorOf(doc);
    }
    json missing = validScene();
    missing["material"].erase("density");
    EXPECT_EQ(errorOf(missing), "scene.json.material.density: missing");
}

TEST(Scene, NonFiniteAndMissingFilesAreRejected) {
    json doc = validScene();
    doc["gravity"] = json::array({0, 0, std::nan("")});  // serialized as null
    EXPECT_NE(errorOf(doc).find("gravity"), std::string::npos);
    EXPECT_THROW(loadScene("/nonexistent/scene.json"), InputError);
    doc = validScene();
    doc["solids"].push_back({{"type", "mesh"}, {"path", "/nonexistent/dipper.obj"}});
    EXPECT_NE(errorOf(doc).find("solids[2].path: cannot read mesh file"), std::string::npos);
}

// The sample cup's 18 mm hole at 32³ (Δx 5.6 mm) spans 3.2 cells: one warning naming the cup and
// the resolution that would do; at 48³ (4.8 cells) none, and a cup without a hole never warns.
TEST(Scene, WarnsWhenACupHoleSpansTooFewCells) {
    json doc = validScene();
    std::vector<std::string> warnings = resolutionWarnings(parseScene(doc, "scene.json"));
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("solids[1] (cup): its hole is 3.2 cells across at resolution 32"), std::string::npos)
        << warnings[0];
    EXPECT_NE(warnings[0].find("use resolution 45 or more"), std::string::npos) << warnings[0];
    doc["domain"]["resolution"] = 48;
    EXPECT_TRUE(resolutionWarnings(parseScene(doc, "scene.json")).empty());
    doc["domain"]["resolution"] = 16;
    doc["solids"][1]["hole_radius"] = 0;
    EXPECT_TRUE(resolutionWarnings(parseScene(doc, "scene.json")).empty());
}

// What a file says twice, after its end or too deep is refused, not read as its last or first part.
TEST(Scene, StrictJsonRefusesRepeatedKeysTrailingTextAndDeepNesting) {
    const auto errorOfText = [](const std::string& text) {
        std::istringstream in(text);
        try {
            parseJsonStrictly(in, "scene.json");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    EXPECT_EQ(errorOfText(R"({"a": {"b": 1, "c": 2}, "d": [1, {"b": 3}]})"), "");
    EXPECT_EQ(errorOfText(R"({"a": {"b": 1, "b": 2}})"), "scene.json: the key \"b\" appears twice in one object");
    EXPECT_NE(errorOfText(R"({"a": 1} {"a": 2})").find("scene.json: not valid JSON"), std::string::npos);
    EXPECT_NE(errorOfText(R"({"a": 1e309})").find("scene.json: a number past double's range"), std::string::npos);
    EXPECT_EQ(errorOfText(std::string(100000, '[') + std::string(100000, ']')),
              "scene.json: nested deeper than 64 levels");
    // A folder given where a file belongs is bad input, not an internal error.
    EXPECT_THROW(loadScene(std::filesystem::temp_directory_path()), InputError);
}

// Each parameter is declared once; a job reaches any of them in the scene by name.
TEST(Scene, DeclaredParametersResolveSetAndRefuseWhatTheSceneCannotHold) {
    Scene scene = parseScene(validScene(), "scene.json");
    const SceneParameter eta = resolveParameter(scene, "viscosity", "job");
    EXPECT_DOUBLE_EQ(parameterValue(scene, eta), 8);
    setParameter(scene, eta, 3.5);
    EXPECT_DOUBLE_EQ(scene.material.viscosity, 3.5);
    EXPECT_THROW(setParameter(scene, eta, -1), InputError);
    const SceneParameter hole = resolveParameter(scene, "solids[1].hole_radius", "job");
    setParameter(scene, hole, 0.004);
    EXPECT_DOUBLE_EQ(std::get<CupSolid>(scene.solids[1]).holeRadius, 0.004);
    const auto messageOf = [&](const std::string& name) {
        try {
            resolveParameter(scene, name, "job");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    EXPECT_EQ(messageOf("flow_index"), "job: \"flow_index\": the scene's material model is newtonian, and only "
                                        "power_law or carreau or herschel_bulkley has it");
    EXPECT_EQ(messageOf("solids[0].hole_radius"),
              "job: \"solids[0].hole_radius\": solids[0] is a ground, and only a cup has it");
    EXPECT_EQ(messageOf("solids[7].hole_radius"), "job: \"solids[7].hole_radius\": the scene has 2 solids");
    EXPECT_EQ(messageOf("hole_radius"), "job: \"hole_radius\" is a solid's: name it \"solids[i].hole_radius\", i its index");
    EXPECT_EQ(messageOf("solids[1].viscosity"), "job: \"solids[1].viscosity\" is not a declared parameter; did you "
                                                 "mean \"viscosity\"? (viscoscope schema lists them)");
    json channel = validScene();
    channel["solids"].push_back({{"type", "channel"}, {"center_y", 0.01}, {"width", 0.08}});
    Scene channelScene = parseScene(channel, "scene.json");
    setParameter(channelScene, resolveParameter(channelScene, "solids[2].width", "job"), 0.05);
    EXPECT_DOUBLE_EQ(std::get<ChannelSolid>(channelScene.solids[2]).width, 0.05);
    EXPECT_DOUBLE_EQ(std::get<ChannelSolid>(parseScene(sceneToJson(channelScene), "again").solids[2]).width, 0.05);
    EXPECT_THROW(resolveParameter(channelScene, "solids[2].hole_radius", "job"), InputError);
    json powerLaw = validScene();
    powerLaw["material"]["model"] = {{"type", "power_law"}, {"consistency", 4.0}, {"flow_index", 0.6}};
    scene = parseScene(powerLaw, "scene.json");
    const SceneParameter n = resolveParameter(scene, "flow_index", "job");
    setParameter(scene, n, 0.5);
    EXPECT_DOUBLE_EQ(std::get<PowerLaw>(scene.material.model).index, 0.5);
    EXPECT_THROW(resolveParameter(scene, "yield_stress", "job"), InputError);
    // The schema lists every declaration, each with its unit and bounds, and a scene that writes them
    // reads back through the same declarations.
    const json schema = parameterSchema();
    ASSERT_EQ(schema.at("parameters").size(), parameterDeclarations().size());
    for (const json& p : schema.at("parameters")) {
        EXPECT_FALSE(p.at("unit").get<std::string>().empty()) << p;
        EXPECT_LE(p.at("lower").get<double>(), p.at("upper").get<double>()) << p;
        if (p.at("searchable").get<bool>() && !p.at("search").at("lower").is_null())
            EXPECT_GE(p.at("search").at("lower").get<double>(), p.at("lower").get<double>()) << p;
    }
    EXPECT_EQ(parseScene(sceneToJson(scene), "round trip").material.model.index(), scene.material.model.index());
}

// A write is whole or not at all: a full disk or a folder in the way is an OutputError naming the
// file and the reason, and leaves the previous file as it was and no .partial behind.
TEST(Scene, FilesAreWrittenWholeOrNotAtAll) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_output_files_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path file = dir / "result.json", partial = dir / "result.json.partial";
    writeJsonAtomically(json{{"E", 1}}, file);
    EXPECT_EQ(json::parse(std::ifstream(file)), (json{{"E", 1}}));
    EXPECT_FALSE(fs::exists(partial));

    const auto errorOfWrite = [&] {
        try {
            writeJsonAtomically(json{{"E", 2}}, file);
        } catch (const OutputError& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    fs::create_symlink("/dev/full", partial);  // every write to it fails with ENOSPC, as on a full disk
    EXPECT_EQ(errorOfWrite(), file.string() + ": cannot write (No space left on device)");
    EXPECT_FALSE(fs::exists(fs::symlink_status(partial)));
    fs::create_directories(partial / "blocking");
    EXPECT_NE(errorOfWrite().find(file.string() + ": cannot write (Is a directory)"), std::string::npos);
    fs::remove_all(partial);
    EXPECT_EQ(json::parse(std::ifstream(file)), (json{{"E", 1}}));

    fs::remove(file);
    fs::create_directories(file / "blocking");  // a folder where the file goes: the rename fails
    EXPECT_NE(errorOfWrite().find(file.string() + ": cannot write ("), std::string::npos);
    EXPECT_FALSE(fs::exists(partial));
    fs::remove_all(dir);
}
