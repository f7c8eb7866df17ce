// The scene file: what is simulated. Versioned JSON in SI units (m, s, kg, Pa·s).
// `loadScene` validates every field and throws InputError naming the field and the problem,
// so no stage downstream ever sees a silently defaulted or non-physical value.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include <array>
#include <filesystem>
#include <functional>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace viscoscope {

// Bad input from the user (a file, a field, a value). The CLI maps it to exit code 2.
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// A file the engine could not write (disk full, no permission, a folder in its place). The CLI maps
// it to exit 1; an identification stops on it rather than scoring around the lost evaluation.
class OutputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// A long operation stopped because a cancel was requested. The CLI maps it to exit code 3.
class Cancelled : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// A cancel is a request to the whole process (the CLI raises it on SIGINT and SIGTERM), so it is one
// flag that every long loop at every stage polls (a simulation step, a solver iteration, a
// voxelisation, an extraction frame), not a pointer threaded through the simulation, its solver, the
// hole calibration and OpenVDB's voxeliser. requestCancel is async-signal-safe.
void requestCancel() noexcept;
void withdrawCancel() noexcept;  // for a test that cancels and goes on in the same process
bool cancelRequested() noexcept;
// Throws Cancelled("WHAT cancelled") once a cancel was requested.
void throwIfCancelled(const char* what);

// The refusals of what is probably a mistake of scale rather than a liquid (a domain over
// kMaxDomainSide, a solid over kMaxSolidOverDomain times the domain, a grid larger than this
// machine's memory, a run longer than a month at its fastest) can be waived on purpose with
// `--ignore-limits`: one choice for the whole process, as the cancel request is. Each such refusal
// ends with kWaiveHint.
void waiveScaleLimits() noexcept;
bool scaleLimitsWaived() noexcept;
inline constexpr const char* kWaiveHint = " (--ignore-limits runs it anyway)";

using Vec3 = Eigen::Vector3d;

inline constexpr int kSceneFormatVersion = 1;

// Cells along a domain's longest side.
inline constexpr int kMinResolution = 4, kMaxResolution = 1024;

struct Domain {
    Vec3 min{0, 0, 0};
    Vec3 max{1, 1, 1};
    int resolution = 32;  // cells along the longest axis; cells are cubes
    std::array<bool, 3> periodic{false, false, false};
};

// Solids. Each becomes a signed distance (negative inside) in the simulation.
struct GroundSolid {
    double height = 0;  // the plane z = height; solid below
};
struct BoxSolid {
    Vec3 min, max;
};
// A cylindrical cup standing on its outer bottom face, axis along +z, with a round hole
// through the centre of its bottom. `position` is the centre of the outer bottom face.
struct CupSolid {
    Vec3 position{0, 0, 0};
    double innerRadius = 0.043;
    double height = 0.06;  // inner depth, from the inner bottom face to the rim
    double wallThickness = 0.003;
    double bottomThickness = 0.004;
    double holeRadius = 0.009;
};
struct MeshSolid {
    std::filesystem::path path;  // OBJ or PLY, resolved against the scene file's folder
};
// The side walls of a channel along x: solid wherever |y − centerY| > width / 2. A lab's channel is
// filmed through its walls, so they never hide the liquid (they have no boundary to draw), and its
// width is often what the footage does not show: a job may search it ("solids[i].width").
struct ChannelSolid {
    double centerY = 0;
    double width = 0.1;
};
using Solid = std::variant<GroundSolid, BoxSolid, CupSolid, MeshSolid, ChannelSolid>;

// Liquid sources.
struct LiquidBox {
    Vec3 min, max;
};
// Fill the cup solid with index `cup` in `solids` with `volume` m³ of liquid (hole included).
struct CupFill {
    int cup = 0;
    double volume = 1.7e-4;
};
// A disc that emits liquid along its normal at a constant volume flux (m³/s) between start and end.
struct DiscEmitter {
    Vec3 center, normal{0, 0, -1};
    double radius = 0.005;
    double flux = 1e-6;
    double start = 0, end = 1e30;
};
using LiquidSource = std::variant<LiquidBox, CupFill, DiscEmitter>;

// Rheology. η(γ̇) for generalized Newtonian models, evaluated per stress sample.
struct Newtonian {};
struct PowerLaw {  // η = K γ̇^(n-1), clamped to [etaMin, etaMax]
    double consistency = 1, index = 1, etaMin = 1e-3, etaMax = 1e4;
};
struct Carreau {  // η = η∞ + (η0 − η∞)(1 + (λγ̇)²)^((n−1)/2); η0 is Material::viscosity
    double etaInfinity = 0, relaxationTime = 1, index = 1;
};
struct HerschelBulkley {  // η = (τy + K γ̇^n)/γ̇, regularized by Papanastasiou-style cap etaMax
    double yieldStress = 0, consistency = 1, index = 1, etaMax = 1e4;
};
using MaterialModel = std::variant<Newtonian, PowerLaw, Carreau, HerschelBulkley>;

struct Material {
    double density = 1400;         // ρ, kg/m³
    double viscosity = 8;          // η, Pa·s (zero-shear viscosity for shear-dependent models)
    double surfaceTension = 0;     // σ, N/m
    double slipLength = 0;         // Navier slip length at solid walls, m (0 = no-slip)
    MaterialModel model = Newtonian{};
};

enum class StokesScheme { Unified, Decoupled };
// How a cup's hole conducts liquid. Grid: as its cut faces do, which at a few cells across passes
// more than the Stokes flux, by where the grid sits. Dagan: a drag on those faces, sized so that
// the grid's steady Stokes flux into a free jet matches the free exit's, a fixed multiple of Dagan,
// Weinbaum & Pfeffer's flux with liquid on both sides (HoleCalibration in sim/sim.h; the figures:
// tests/bench/FINDINGS.md, "Figures moved from code comments").
enum class HoleConductance { Dagan, Grid };

struct SolverSettings {
    StokesScheme scheme = StokesScheme::Unified;
    double tolerance = 1e-4;      // relative residual of the Stokes solve
    int maxIterations = 2000;
    // Cells a particle may cross per step. 2 rather than 1 halves the steps of fast flows at nearly
    // the same drain (tests/bench/FINDINGS.md, "Figures moved from code comments"). Its
    // first liquid's tip fell too slowly at 2 until the start of motion got shorter steps of its
    // own (kStartupStepShare in sim/simulation.cpp).
    double cfl = 2.0;
    int particlesPerCell = 8;
    int picardIterations = 3;     // for shear-dependent models only
    HoleConductance holeConductance = HoleConductance::Dagan;
};

struct Outputs {
    bool particles = true;
    bool vdb = true;
    bool mesh = false;
    // σ (m) of the Gaussian that draws the liquid's surface from its particles (surface::liquidLevelSet);
    // 0: kSurfaceSmoothingPerCell of the scene's cell. parseScene sets it from the file's
    // "surface_smoothing" or that default at the file's resolution, so it stays when a run changes
    // the resolution (synth's finer reference, identify's grids): every grid draws the liquid alike.
    double surfaceSmoothing = 0;
};
// 0.75 of the seeding spacing at 8 particles per cell: about 19 particles under the kernel, so the
// density inside the liquid varies by about a quarter, and seeded liquid shows no holes at its half
// level (surface_solids_test).
constexpr double kSurfaceSmoothingPerCell = 0.375;

struct Scene {
    std::filesystem::path sourceFile;
    Domain domain;
    std::vector<Solid> solids;
    // Indices into `solids` of those the camera sees through (a glass cup: a solid's "transparent").
    // The others are opaque: they hide the liquid behind and inside them in simulated silhouettes.
    std::vector<size_t> transparentSolids;
    std::vector<LiquidSource> liquids;
    Material material;
    Vec3 gravity{0, 0, -9.81};
    double fps = 30;
    int frames = 60;
    unsigned seed = 1;
    SolverSettings solver;
    Outputs outputs;

    double cellSize() const;
    Eigen::Vector3i cellCounts() const;
    double surfaceSmoothing() const;  // outputs.surfaceSmoothing, resolved
    bool isOpaque(size_t solid) const;
};

// ---------------------------------------------------------------------------------------------
// The physical and geometric parameters, each declared once: the scene reader checks its fields
// against these bounds, a job searches or fixes any of them by name, `viscoscope schema` prints them
// and the add-on reads that (addon/schema.py).

enum class ParameterHome {
    Material,       // material.NAME
    MaterialModel,  // material.model.NAME, for the model types in `types`
    Solid,          // solids[i].NAME, for the solid types in `types`; a job names it "solids[i].NAME"
};

// Where a declared parameter's value lives, which is how the scene reader reads it, the writer writes
// it and a job sets it: the one locator of its home, nullptr where the object cannot hold it (a
// Newtonian model and "flow_index").
struct ParameterPlace {
    ParameterHome home;
    std::vector<const char*> types;  // the model or solid types that hold it
    double* (*inMaterial)(Material&) = nullptr;
    double* (*inModel)(MaterialModel&) = nullptr;
    double* (*inSolid)(Solid&) = nullptr;
};

struct ParameterDeclaration {
    const char* name;    // the scene file's key, and the job's name for it
    const char* symbol;  // as the panel shows it
    const char* unit;    // SI
    const char* description;
    ParameterPlace place;
    double defaultValue;              // NaN: required
    double lower, upper;              // physical bounds, inclusive: the readers refuse values outside
    bool searchable;                  // a job may search it (in ln θ: searchLower > 0)
    double searchLower, searchUpper;  // a job's search bounds when it gives none
    double searchInitial;             // θ0 when the job gives none; NaN: the scene's value
    // Flow speeds scale as 1/θ (η, K): identify fits E's profile in 1/θ rather than ln θ.
    bool speedScalesInversely;
};

const std::vector<ParameterDeclaration>& parameterDeclarations();
// The declaration named `name`; nullptr if none.
const ParameterDeclaration* findParameterDeclaration(const std::string& name);
// `viscoscope schema`: every declaration, and the file formats' versions.
nlohmann::json parameterSchema();

// One parameter of one scene: a material's ("viscosity"), its model's ("flow_index") or a solid's
// ("solids[1].hole_radius").
struct SceneParameter {
    std::string name;  // as a job names it
    const ParameterDeclaration* declaration = nullptr;
    int solid = -1;    // ParameterHome::Solid: the index into Scene::solids
};
// Resolves a job's parameter name against a scene; throws InputError (prefixed by `where`) when no
// declaration has that name or the scene cannot hold it (a Newtonian scene and "flow_index").
SceneParameter resolveParameter(const Scene& scene, const std::string& name, const std::string& where);
double parameterValue(const Scene& scene, const SceneParameter& parameter);
// Sets it; throws InputError when `value` lies outside the declared bounds.
void setParameter(Scene& scene, const SceneParameter& parameter, double value);
// "must be in [lower, upper] UNIT, got VALUE", or empty when `value` lies within the bounds.
std::string boundsProblem(const ParameterDeclaration& declaration, double value);

// ---------------------------------------------------------------------------------------------
// Writing the engine's files: whole or not at all.

// `write` fills FILE.partial, which is flushed, closed and checked, then renamed over `file`, so a
// reader (or a run resumed after a kill) sees the old file or the new one, never half of one.
// Throws OutputError("PATH: cannot write (REASON)") and leaves no .partial behind.
void writeFileAtomically(const std::filesystem::path& file, const std::function<void(std::ostream&)>& write);
void writeJsonAtomically(const nlohmann::json& doc, const std::filesystem::path& file);

// ---------------------------------------------------------------------------------------------
// Reading the engine's JSON files strictly.

// Parses one JSON document from `text`: trailing text, a key given twice in one object and nesting
// deeper than kMaxJsonDepth are refused with InputError("ORIGIN: ..."), as is invalid JSON or a
// number past double's range.
constexpr int kMaxJsonDepth = 64;
nlohmann::json parseJsonStrictly(std::istream& text, const std::string& origin);
// The known name closest to `given` by edit distance, when it is close enough to be a misspelling
// (at most a third of its letters, and 3, differ); empty otherwise.
std::string nearestName(const std::string& given, const std::vector<std::string>& known);
// Throws InputError("PREFIXKEY: unknown field; did you mean `K`?") for the first key of `object`
// not in `known` (prefix "scene.json.material." or "job.json: "). Forward compatibility goes
// through a file's "version".
void rejectUnknownKeys(const nlohmann::json& object, const std::vector<std::string>& known, const std::string& prefix);

// Parses and validates. Throws InputError("scene.json: material.viscosity: must be > 0, got -1").
Scene parseScene(const nlohmann::json& doc, const std::string& origin,
                 const std::filesystem::path& baseDir = {});
Scene loadScene(const std::filesystem::path& file);
// The scene a simulation folder's record (`simulate`'s DIR/simulation.json) says it ran.
Scene loadRecordedScene(const std::filesystem::path& record);
// Valid settings that will give wrong physics, one line each naming the solid and the fix: a cup's
// hole spanning fewer cells than the drain rate needs.
std::vector<std::string> resolutionWarnings(const Scene& scene);
// The cells across a cup's hole its drain rate needs (the measurements are in scene.cpp).
inline constexpr double kMinHoleCells = 4.5;
// A solid this many times the domain's longest side is taken for one in another unit and refused: a
// cup wider than a periodic domain is a plate with a hole (the hole-calibration benchmark), but one
// a hundred times wider, or a mesh exported in millimetres, is a mistake.
inline constexpr double kMaxSolidOverDomain = 100;
// x as a message shows it: six significant digits, as printf's %g.
std::string formatNumber(double x);
// A domain over a kilometre across is almost surely in another unit.
inline constexpr double kMaxDomainSide = 1e3;  // m
nlohmann::json sceneToJson(const Scene& scene);
// The first ground plane's height, if the scene has one.
std::optional<double> groundHeight(const Scene& scene);
// The first cup with a hole: where the liquid leaves (nullptr: none).
const CupSolid* firstHoledCup(const Scene& scene);

}  // namespace viscoscope
