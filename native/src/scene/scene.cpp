#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace viscoscope {

std::string formatNumber(double x) {
    std::ostringstream s;
    s << x;
    return s.str();
}

using nlohmann::json;

namespace {

// Reads fields of one JSON object, naming "file: path.to.field" in every error.
class FieldReader {
public:
    FieldReader(const json& object, std::string path) : object_(object), path_(std::move(path)) {
        if (!object_.is_object()) fail("", "must be an object");
    }

    [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
        throw InputError(path_ + (field.empty() ? "" : "." + field) + ": " + problem);
    }
    std::string where(const std::string& field) const { return path_ + "." + field; }
    bool has(const std::string& field) const {
        asked_.push_back(field);
        return object_.contains(field);
    }
    const json& raw(const std::string& field) const {
        if (!has(field)) fail(field, "missing");
        return object_.at(field);
    }
    // Refuses the fields nothing asked for: a misspelt key would otherwise leave its default in use.
    void finish() const { rejectUnknownKeys(object_, asked_, path_ + "."); }

    double number(const std::string& field) const {
        const json& v = raw(field);
        if (!v.is_number()) fail(field, "must be a number");
        const double x = v.get<double>();
        if (!std::isfinite(x)) fail(field, "must be finite");
        return x;
    }
    double number(const std::string& field, double fallback) const {
        return has(field) ? number(field) : fallback;
    }
    // A declared parameter (parameterDeclarations), within its bounds; its default when absent.
    double parameter(const char* name) const {
        const ParameterDeclaration& d = *findParameterDeclaration(name);
        if (!has(name)) {
            if (std::isnan(d.defaultValue)) fail(name, "missing");
            return d.defaultValue;
        }
        const double x = number(name);
        if (const std::string problem = boundsProblem(d, x); !problem.empty()) fail(name, problem);
        return x;
    }
    double positive(const std::string& field) const {
        const double x = number(field);
        if (!(x > 0)) fail(field, "must be > 0, got " + formatNumber(x));
        return x;
    }
    double positive(const std::string& field, double fallback) const {
        return has(field) ? positive(field) : fallback;
    }
    // A number within [lo, hi] UNIT: beyond them it is a mistake or a run that never ends.
    double within(const std::string& field, double lo, double hi, const char* unit, double fallback) const {
        const double x = number(field, fallback);
        if (!(x >= lo && x <= hi))
            fail(field, "must be in [" + formatNumber(lo) + ", " + formatNumber(hi) + "] " + unit + ", got " + formatNumber(x));
        return x;
    }
    double nonNegative(const std::string& field, double fallback) const {
        const double x = number(field, fallback);
        if (x < 0) fail(field, "must be >= 0, got " + formatNumber(x));
        return x;
    }
    int integer(const std::string& field, int lo, int hi) const {
        const json& v = raw(field);
        if (!v.is_number_integer()) fail(field, "must be an integer");
        const long long x = v.get<long long>();
        if (x < lo || x > hi)
            fail(field, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                            std::to_string(x));
        return static_cast<int>(x);
    }
    int integer(const std::string& field, int lo, int hi, int fallback) const {
        return has(field) ? integer(field, lo, hi) : fallback;
    }
    bool boolean(const std::string& field, bool fallback) const {
        if (!has(field)) return fallback;
        if (!raw(field).is_boolean()) fail(field, "must be true or false");
        return raw(field).get<bool>();
    }
    std::string string(const std::string& field) const {
        const json& v = raw(field);
        if (!v.is_string()) fail(field, "must be a string");
        return v.get<std::string>();
    }
    Vec3 vec3(const std::string& field) const {
        const json& v = raw(field);
        if (!v.is_array() || v.size() != 3) fail(field, "must be an array of 3 numbers");
        Vec3 out;
        for (int i = 0; i < 3; ++i) {
            if (!v[i].is_number()) fail(field, "must be an array of 3 numbers");
            out[i] = v[i].get<double>();
            if (!std::isfinite(out[i])) fail(field, "must be finite");
        }
        return out;
    }
    Vec3 vec3(const std::string& field, const Vec3& fallback) const {
        return has(field) ? vec3(field) : fallback;
    }
    FieldReader child(const std::string& field) const { return FieldReader(raw(field), where(field)); }

private:
    const json& object_;
    std::string path_;
    mutable std::vector<std::string> asked_;
};

// Bounds past which a scene is a mistake or a run that never ends, not a liquid: a step of
// CFL·Δx/√(gΔx) stalls under 100 g, a CFL of 1e-6 takes a million steps a cell, a frame of 1e-9
// fps lasts 30 years.
constexpr double kMaxGravity = 1e3;       // m/s²
constexpr double kMinFps = 1e-3, kMaxFps = 1e6;
constexpr double kMinCfl = 1e-2, kMaxCfl = 10;

void requireOrderedBox(const FieldReader& r, const Vec3& lo, const Vec3& hi) {
    if (!(lo.array() < hi.array()).all()) r.fail("max", "must be greater than min on every axis");
}

// A cup, box or liquid that misses the domain, or a cup far wider than it, is a mistake (most often
// a unit: millimetres for metres), not a scene: it is refused with the field named, before the
// simulation spends minutes finding the domain empty.
std::string domainExtent(const Domain& d) {
    return "[" + formatNumber(d.min.x()) + ", " + formatNumber(d.min.y()) + ", " +
           formatNumber(d.min.z()) + "] to [" + formatNumber(d.max.x()) + ", " +
           formatNumber(d.max.y()) + ", " + formatNumber(d.max.z()) + "] m";
}

void requireBoxMeetsDomain(const FieldReader& r, const std::string& field, const Vec3& lo, const Vec3& hi,
                           const Domain& d) {
    if ((hi.array() < d.min.array()).any() || (lo.array() > d.max.array()).any())
        r.fail(field, "lies outside the domain (" + domainExtent(d) + "); is it in another unit?");
}

void requireInDomain(const FieldReader& r, const Solid& solid, const Domain& d) {
    if (const auto* cup = std::get_if<CupSolid>(&solid)) {
        const double outer = cup->innerRadius + cup->wallThickness;
        const double across = 2 * outer, domainSide = (d.max - d.min).maxCoeff();
        if (across > kMaxSolidOverDomain * domainSide && !scaleLimitsWaived())
            r.fail("inner_radius", "the cup is " + formatNumber(across) + " m across, over " +
                                       formatNumber(kMaxSolidOverDomain) + " times the domain's longest side (" +
                                       formatNumber(domainSide) + " m); is it in another unit?" + kWaiveHint);
        const Vec3 lo = cup->position - Vec3(outer, outer, 0);
        const Vec3 hi = cup->position + Vec3(outer, outer, cup->bottomThickness + cup->height);
        requireBoxMeetsDomain(r, "position", lo, hi, d);
    } else if (const auto* box = std::get_if<BoxSolid>(&solid)) {
        requireBoxMeetsDomain(r, "min", box->min, box->max, d);
    }
}

template <class Object>
using Locator = double* (*)(Object&);

// Every declared parameter `object` holds (located by `locator`: &ParameterPlace::inModel, …), read
// from `r`, its declared default where it is absent.
template <class Object>
void readDeclared(const FieldReader& r, Object& object, Locator<Object> ParameterPlace::*locator) {
    for (const ParameterDeclaration& d : parameterDeclarations())
        if (const Locator<Object> locate = d.place.*locator)
            if (double* value = locate(object)) *value = r.parameter(d.name);
}

Solid parseSolid(const FieldReader& r, const std::filesystem::path& baseDir) {
    const std::string type = r.string("type");
    if (type == "ground") return GroundSolid{r.number("height", 0.0)};
    if (type == "box") {
        BoxSolid box{r.vec3("min"), r.vec3("max")};
        requireOrderedBox(r, box.min, box.max);
        return box;
    }
    if (type == "cup") {
        Solid solid = CupSolid{r.vec3("position")};
        readDeclared(r, solid, &ParameterPlace::inSolid);
        const CupSolid& cup = std::get<CupSolid>(solid);
        if (cup.holeRadius >= cup.innerRadius)
            r.fail("hole_radius", "must be smaller than inner_radius (" +
                                      formatNumber(cup.innerRadius) + "), got " +
                                      formatNumber(cup.holeRadius));
        return solid;
    }
    if (type == "mesh") {
        std::filesystem::path path = r.string("path");
        // Absolute, so that the scene a run records (simulation.json, a job's checkpoint) still
        // names the file when read from another working directory, as `score` reads it.
        path = std::filesystem::absolute(baseDir / path);
        std::ifstream probe(path);
        if (!probe) r.fail("path", "cannot read mesh file '" + path.string() + "'");
        const std::string ext = path.extension().string();
        if (ext != ".obj" && ext != ".OBJ" && ext != ".ply" && ext != ".PLY")
            r.fail("path", "mesh must be .obj or .ply, got '" + path.filename().string() + "'");
        return MeshSolid{path};
    }
    if (type == "channel") {
        Solid solid = ChannelSolid{r.number("center_y", 0.0)};
        readDeclared(r, solid, &ParameterPlace::inSolid);
        return solid;
    }
    r.fail("type", "unknown solid type '" + type + "' (ground, box, cup, mesh, channel)");
}

LiquidSource parseLiquid(const FieldReader& r, const std::vector<Solid>& solids) {
    const std::string type = r.string("type");
    if (type == "box") {
        LiquidBox box{r.vec3("min"), r.vec3("max")};
        requireOrderedBox(r, box.min, box.max);
        return box;
    }
    if (type == "cup_fill") {
        CupFill fill;
        fill.cup = r.integer("cup", 0, 1 << 20);
        if (fill.cup >= static_cast<int>(solids.size()) ||
            !std::holds_alternative<CupSolid>(solids[fill.cup]))
            r.fail("cup", "must be the index of a solid of type 'cup'");
        fill.volume = r.positive("volume");
        const CupSolid& cup = std::get<CupSolid>(solids[fill.cup]);
        const double capacity = M_PI * cup.innerRadius * cup.innerRadius * cup.height;
        if (fill.volume > capacity)
            r.fail("volume", "exceeds the cup's capacity of " + formatNumber(capacity) + " m³");
        return fill;
    }
    if (type == "emitter") {
        DiscEmitter e;
        e.center = r.vec3("center");
        e.normal = r.vec3("normal");
        if (e.normal.norm() < 1e-12) r.fail("normal", "must not be zero");
        e.normal.normalize();
        e.radius = r.positive("radius");
        e.flux = r.positive("flux");
        e.start = r.nonNegative("start", 0.0);
        e.end = r.number("end", 1e30);
        if (e.end <= e.start) r.fail("end", "must be later than start");
        return e;
    }
    r.fail("type", "unknown liquid type '" + type + "' (box, cup_fill, emitter)");
}

MaterialModel parseModel(const FieldReader& r) {
    const std::string type = r.string("type");
    MaterialModel model;
    if (type == "power_law") model = PowerLaw{};
    else if (type == "carreau") model = Carreau{};
    else if (type == "herschel_bulkley") model = HerschelBulkley{};
    else if (type != "newtonian")
        r.fail("type", "unknown material model '" + type + "' (newtonian, power_law, carreau, herschel_bulkley)");
    readDeclared(r, model, &ParameterPlace::inModel);
    if (const auto* law = std::get_if<PowerLaw>(&model); law && law->etaMin >= law->etaMax)
        r.fail("eta_max", "must be greater than eta_min");
    return model;
}

}  // namespace

// kMinHoleCells: below it the cup's drain depends on the hole's width in cells; above it, it still
// depends on where the grid sits, and identify's alignment check puts that spread into the interval
// rather than a warning here. Calibrated holes (solver.hole_conductance, HoleCalibration in
// sim/sim.h) drain nearly alike on every grid (tests/bench/FINDINGS.md, "Figures moved from code comments").

std::vector<std::string> resolutionWarnings(const Scene& scene) {
    std::vector<std::string> warnings;
    const double dx = scene.cellSize();
    for (size_t i = 0; i < scene.solids.size(); ++i) {
        const auto* cup = std::get_if<CupSolid>(&scene.solids[i]);
        if (!cup || cup->holeRadius <= 0) continue;
        const double cells = 2 * cup->holeRadius / dx;
        if (cells >= kMinHoleCells) continue;
        const int needed = static_cast<int>(std::ceil(scene.domain.resolution * kMinHoleCells / cells - 1e-9));
        char line[320];
        std::snprintf(line, sizeof line,
                      "solids[%zu] (cup): its hole is %.1f cells across at resolution %d; the drain rate needs "
                      "about %.1f (the sample cup drained 5%% too slowly at 3.6 with its hole calibrated, 1.65x "
                      "too fast without): use resolution %d or more",
                      i, cells, scene.domain.resolution, kMinHoleCells, needed);
        warnings.push_back(line);
    }
    return warnings;
}

double Scene::cellSize() const { return (domain.max - domain.min).maxCoeff() / domain.resolution; }

double Scene::surfaceSmoothing() const {
    return outputs.surfaceSmoothing > 0 ? outputs.surfaceSmoothing : kSurfaceSmoothingPerCell * cellSize();
}

bool Scene::isOpaque(size_t solid) const {
    return std::find(transparentSolids.begin(), transparentSolids.end(), solid) == transparentSolids.end();
}

Eigen::Vector3i Scene::cellCounts() const {
    const Vec3 extent = (domain.max - domain.min) / cellSize();
    return extent.array().round().cast<int>().max(1);
}

Scene parseScene(const json& doc, const std::string& origin, const std::filesystem::path& baseDir) {
    const FieldReader root(doc, origin);
    if (root.string("format") != "viscoscope.scene")
        root.fail("format", "must be \"viscoscope.scene\"");
    const int version = root.integer("version", 1, 1 << 20);
    if (version > kSceneFormatVersion)
        root.fail("version", "is " + std::to_string(version) + ", newer than this engine reads (" +
                                 std::to_string(kSceneFormatVersion) + ")");

    Scene scene;
    const FieldReader domain = root.child("domain");
    scene.domain.min = domain.vec3("min");
    scene.domain.max = domain.vec3("max");
    requireOrderedBox(domain, scene.domain.min, scene.domain.max);
    if ((scene.domain.max - scene.domain.min).maxCoeff() > kMaxDomainSide && !scaleLimitsWaived())
        domain.fail("max", "the domain is " + formatNumber((scene.domain.max - scene.domain.min).maxCoeff()) +
                               " m long, more than " + formatNumber(kMaxDomainSide) + " m; is it in another unit?" +
                               kWaiveHint);
    scene.domain.resolution = domain.integer("resolution", kMinResolution, kMaxResolution);
    if (domain.has("periodic")) {
        const json& p = domain.raw("periodic");
        if (!p.is_array() || p.size() != 3 || !p[0].is_boolean() || !p[1].is_boolean() ||
            !p[2].is_boolean())
            domain.fail("periodic", "must be an array of 3 booleans");
        for (int i = 0; i < 3; ++i) scene.domain.periodic[i] = p[i].get<bool>();
    }
    domain.finish();

    if (root.has("solids")) {
        const json& solids = root.raw("solids");
        if (!solids.is_array()) root.fail("solids", "must be an array");
        for (size_t i = 0; i < solids.size(); ++i) {
            const FieldReader solid(solids[i], root.where("solids[" + std::to_string(i) + "]"));
            scene.solids.push_back(parseSolid(solid, baseDir));
            requireInDomain(solid, scene.solids.back(), scene.domain);
            if (solid.boolean("transparent", false)) scene.transparentSolids.push_back(i);
            solid.finish();
        }
    }
    const json& liquids = root.raw("liquids");
    if (!liquids.is_array() || liquids.empty())
        root.fail("liquids", "must be a non-empty array: the scene has no liquid");
    for (size_t i = 0; i < liquids.size(); ++i) {
        const FieldReader liquid(liquids[i], root.where("liquids[" + std::to_string(i) + "]"));
        scene.liquids.push_back(parseLiquid(liquid, scene.solids));
        if (const auto* box = std::get_if<LiquidBox>(&scene.liquids.back()))
            requireBoxMeetsDomain(liquid, "min", box->min, box->max, scene.domain);
        else if (const auto* emitter = std::get_if<DiscEmitter>(&scene.liquids.back()))
            requireBoxMeetsDomain(liquid, "center", emitter->center, emitter->center, scene.domain);
        liquid.finish();
    }

    const FieldReader material = root.child("material");
    readDeclared(material, scene.material, &ParameterPlace::inMaterial);
    if (material.has("model")) {
        const FieldReader model = material.child("model");
        scene.material.model = parseModel(model);
        model.finish();
    }
    material.finish();

    scene.gravity = root.vec3("gravity", scene.gravity);
    if (scene.gravity.stableNorm() > kMaxGravity)
        root.fail("gravity", "must be at most " + formatNumber(kMaxGravity) + " m/s² long (9.81 on Earth), got " +
                                 formatNumber(scene.gravity.stableNorm()));
    scene.fps = root.within("fps", kMinFps, kMaxFps, "frames/s", 30.0);
    if (root.has("frames") && root.has("duration"))
        root.fail("duration", "give either frames or duration, not both");
    if (root.has("duration"))
        scene.frames = std::max(1, static_cast<int>(std::lround(root.positive("duration") * scene.fps)));
    else
        scene.frames = root.integer("frames", 1, 1000000, 60);
    scene.seed = static_cast<unsigned>(root.integer("seed", 0, 1 << 30, 1));

    if (root.has("solver")) {
        const FieldReader s = root.child("solver");
        if (s.has("scheme")) {
            const std::string scheme = s.string("scheme");
            if (scheme == "unified") scene.solver.scheme = StokesScheme::Unified;
            else if (scheme == "decoupled") scene.solver.scheme = StokesScheme::Decoupled;
            else s.fail("scheme", "must be \"unified\" or \"decoupled\", got '" + scheme + "'");
        }
        scene.solver.tolerance = s.positive("tolerance", scene.solver.tolerance);
        scene.solver.maxIterations = s.integer("max_iterations", 1, 1000000, scene.solver.maxIterations);
        scene.solver.cfl = s.within("cfl", kMinCfl, kMaxCfl, "cells a step", scene.solver.cfl);
        scene.solver.particlesPerCell = s.integer("particles_per_cell", 1, 64, scene.solver.particlesPerCell);
        scene.solver.picardIterations = s.integer("picard_iterations", 1, 50, scene.solver.picardIterations);
        if (s.has("hole_conductance")) {
            const std::string model = s.string("hole_conductance");
            if (model == "dagan") scene.solver.holeConductance = HoleConductance::Dagan;
            else if (model == "grid") scene.solver.holeConductance = HoleConductance::Grid;
            else s.fail("hole_conductance", "must be \"dagan\" or \"grid\", got '" + model + "'");
        }
        s.finish();
    }
    if (root.has("output")) {
        const FieldReader o = root.child("output");
        scene.outputs.particles = o.boolean("particles", scene.outputs.particles);
        scene.outputs.vdb = o.boolean("vdb", scene.outputs.vdb);
        scene.outputs.mesh = o.boolean("mesh", scene.outputs.mesh);
        if (o.has("surface_smoothing")) {
            scene.outputs.surfaceSmoothing = o.positive("surface_smoothing");
            if (!(scene.outputs.surfaceSmoothing < 4 * scene.cellSize()))
                o.fail("surface_smoothing", "must be below 4 cells (" + formatNumber(4 * scene.cellSize()) +
                                                " m), got " + formatNumber(scene.outputs.surfaceSmoothing));
        }
        o.finish();
    }
    scene.outputs.surfaceSmoothing = scene.surfaceSmoothing();
    root.finish();
    return scene;
}

Scene loadScene(const std::filesystem::path& file) {
    std::ifstream in(file);
    if (!in) throw InputError(file.string() + ": cannot open scene file");
    const json doc = parseJsonStrictly(in, file.string());
    Scene scene = parseScene(doc, file.filename().string(), file.parent_path());
    scene.sourceFile = file;
    return scene;
}

Scene loadRecordedScene(const std::filesystem::path& record) {
    std::ifstream in(record);
    const json doc = json::parse(in, nullptr, false);
    if (doc.is_discarded() || !doc.contains("scene"))
        throw InputError(record.string() + ": not a simulation record with a \"scene\"");
    return parseScene(doc["scene"], record.string() + ": scene");
}

namespace {
json toJson(const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); }

struct SolidWriter {
    json operator()(const GroundSolid& g) const { return {{"type", "ground"}, {"height", g.height}}; }
    json operator()(const BoxSolid& b) const {
        return {{"type", "box"}, {"min", toJson(b.min)}, {"max", toJson(b.max)}};
    }
    json operator()(const CupSolid& c) const { return {{"type", "cup"}, {"position", toJson(c.position)}}; }
    json operator()(const MeshSolid& m) const { return {{"type", "mesh"}, {"path", m.path.string()}}; }
    json operator()(const ChannelSolid& c) const { return {{"type", "channel"}, {"center_y", c.centerY}}; }
};
struct LiquidWriter {
    json operator()(const LiquidBox& b) const {
        return {{"type", "box"}, {"min", toJson(b.min)}, {"max", toJson(b.max)}};
    }
    json operator()(const CupFill& f) const {
        return {{"type", "cup_fill"}, {"cup", f.cup}, {"volume", f.volume}};
    }
    json operator()(const DiscEmitter& e) const {
        return {{"type", "emitter"}, {"center", toJson(e.center)}, {"normal", toJson(e.normal)},
                {"radius", e.radius}, {"flux", e.flux}, {"start", e.start}, {"end", e.end}};
    }
};
struct ModelWriter {
    json operator()(const Newtonian&) const { return {{"type", "newtonian"}}; }
    json operator()(const PowerLaw&) const { return {{"type", "power_law"}}; }
    json operator()(const Carreau&) const { return {{"type", "carreau"}}; }
    json operator()(const HerschelBulkley&) const { return {{"type", "herschel_bulkley"}}; }
};

// `entry` (an object's fields that are not parameters) with every declared parameter `object` holds.
template <class Object>
json withDeclared(json entry, Object object, Locator<Object> ParameterPlace::*locator) {
    for (const ParameterDeclaration& d : parameterDeclarations())
        if (const Locator<Object> locate = d.place.*locator)
            if (const double* value = locate(object)) entry[d.name] = *value;
    return entry;
}
}  // namespace

json sceneToJson(const Scene& s) {
    json solids = json::array(), liquids = json::array();
    for (size_t i = 0; i < s.solids.size(); ++i) {
        solids.push_back(withDeclared(std::visit(SolidWriter{}, s.solids[i]), s.solids[i], &ParameterPlace::inSolid));
        solids.back()["transparent"] = !s.isOpaque(i);
    }
    for (const LiquidSource& liquid : s.liquids) liquids.push_back(std::visit(LiquidWriter{}, liquid));
    return {
        {"format", "viscoscope.scene"},
        {"version", kSceneFormatVersion},
        {"domain",
         {{"min", toJson(s.domain.min)},
          {"max", toJson(s.domain.max)},
          {"resolution", s.domain.resolution},
          {"periodic", s.domain.periodic}}},
        {"solids", solids},
        {"liquids", liquids},
        {"material", withDeclared({{"model", withDeclared(std::visit(ModelWriter{}, s.material.model), s.material.model,
                                                          &ParameterPlace::inModel)}},
                                  s.material, &ParameterPlace::inMaterial)},
        {"gravity", toJson(s.gravity)},
        {"fps", s.fps},
        {"frames", s.frames},
        {"seed", s.seed},
        {"solver",
         {{"scheme", s.solver.scheme == StokesScheme::Unified ? "unified" : "decoupled"},
          {"tolerance", s.solver.tolerance},
          {"max_iterations", s.solver.maxIterations},
          {"cfl", s.solver.cfl},
          {"particles_per_cell", s.solver.particlesPerCell},
          {"picard_iterations", s.solver.picardIterations},
          {"hole_conductance", s.solver.holeConductance == HoleConductance::Dagan ? "dagan" : "grid"}}},
        {"output",
         {{"particles", s.outputs.particles}, {"vdb", s.outputs.vdb}, {"mesh", s.outputs.mesh},
          {"surface_smoothing", s.outputs.surfaceSmoothing}}},
    };
}

std::optional<double> groundHeight(const Scene& scene) {
    for (const Solid& solid : scene.solids)
        if (const auto* ground = std::get_if<GroundSolid>(&solid)) return ground->height;
    return std::nullopt;
}

const CupSolid* firstHoledCup(const Scene& scene) {
    for (const Solid& solid : scene.solids)
        if (const auto* cup = std::get_if<CupSolid>(&solid); cup && cup->holeRadius > 0) return cup;
    return nullptr;
}

}  // namespace viscoscope
