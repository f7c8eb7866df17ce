// The parameter declarations (scene.h), and reading JSON strictly.
#include "scene/scene.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <istream>
#include <limits>
#include <set>
#include <sstream>

namespace viscoscope {

using nlohmann::json;

namespace {

constexpr double kRequired = std::numeric_limits<double>::quiet_NaN();
constexpr double kSceneValue = std::numeric_limits<double>::quiet_NaN();

struct SolidName {
    const char* operator()(const GroundSolid&) const { return "ground"; }
    const char* operator()(const BoxSolid&) const { return "box"; }
    const char* operator()(const CupSolid&) const { return "cup"; }
    const char* operator()(const MeshSolid&) const { return "mesh"; }
    const char* operator()(const ChannelSolid&) const { return "channel"; }
};

struct ModelName {
    const char* operator()(const Newtonian&) const { return "newtonian"; }
    const char* operator()(const PowerLaw&) const { return "power_law"; }
    const char* operator()(const Carreau&) const { return "carreau"; }
    const char* operator()(const HerschelBulkley&) const { return "herschel_bulkley"; }
};

// The class a pointer to a double member belongs to.
template <class Member>
struct OwnerOf;
template <class Owner>
struct OwnerOf<double Owner::*> {
    using type = Owner;
};

// The member of whichever of `Members`' classes `object` holds; nullptr if none.
template <class Variant, auto... Members>
double* heldMember(Variant& object) {
    double* found = nullptr;
    const auto look = [&](auto member) {
        using Owner = typename OwnerOf<decltype(member)>::type;
        if (Owner* owner = std::get_if<Owner>(&object); owner && !found) found = &(owner->*member);
    };
    (look(Members), ...);
    return found;
}

template <auto Member>
double* materialMember(Material& material) {
    return &(material.*Member);
}

// The places: the material's field, or the field of each model law or solid type that holds it.
template <auto Member>
ParameterPlace inMaterial() {
    return {ParameterHome::Material, {}, &materialMember<Member>, nullptr, nullptr};
}
template <auto... Members>
ParameterPlace inModel() {
    return {ParameterHome::MaterialModel, {ModelName{}(typename OwnerOf<decltype(Members)>::type{})...}, nullptr,
            &heldMember<MaterialModel, Members...>, nullptr};
}
template <auto... Members>
ParameterPlace inSolid() {
    return {ParameterHome::Solid, {SolidName{}(typename OwnerOf<decltype(Members)>::type{})...}, nullptr, nullptr,
            &heldMember<Solid, Members...>};
}

// Physical bounds are wide enough for any liquid and container a camera can film (ρ from oils to
// mercury, η from water's thousandth to pitch), and narrow enough to catch a wrong unit.
const std::vector<ParameterDeclaration> kDeclarations{
    {"density", "ρ", "kg/m³", "Density of the liquid", inMaterial<&Material::density>(),
     kRequired, 100, 25000, true, 500, 3000, kSceneValue, false},
    {"viscosity", "η", "Pa·s", "Dynamic viscosity; a Carreau liquid's zero-shear viscosity",
     inMaterial<&Material::viscosity>(), kRequired, 1e-6, 1e9, true, 1e-3, 1e4, 10, true},
    {"surface_tension", "σ", "N/m", "Surface tension against air", inMaterial<&Material::surfaceTension>(),
     0, 0, 1, true, 1e-4, 1, 0.05, false},
    {"slip_length", "b", "m", "Navier slip length at solid walls (0: no slip)", inMaterial<&Material::slipLength>(),
     0, 0, 1, true, 1e-6, 1e-2, 1e-4, false},
    {"consistency", "K", "Pa·sⁿ", "Consistency of a power-law or Herschel–Bulkley liquid",
     inModel<&PowerLaw::consistency, &HerschelBulkley::consistency>(), kRequired, 1e-6, 1e9, true, 1e-3, 1e4, 10, true},
    {"flow_index", "n", "1", "Flow index: below 1 shear thinning, above 1 shear thickening",
     inModel<&PowerLaw::index, &Carreau::index, &HerschelBulkley::index>(), kRequired, 0.05, 3, true, 0.1, 2, 1,
     false},
    {"eta_min", "η_min", "Pa·s", "Lower cap of a power-law liquid's viscosity", inModel<&PowerLaw::etaMin>(),
     1e-3, 1e-9, 1e12, false, 0, 0, 0, false},
    {"eta_max", "η_max", "Pa·s",
     "Upper cap of the viscosity (a yield-stress liquid's viscosity below its yield point)",
     inModel<&PowerLaw::etaMax, &HerschelBulkley::etaMax>(), 1e4, 1e-9, 1e12, false, 0, 0, 0, false},
    {"eta_infinity", "η∞", "Pa·s", "Infinite-shear viscosity of a Carreau liquid", inModel<&Carreau::etaInfinity>(),
     0, 0, 1e9, true, 1e-4, 1e3, 0.01, false},
    {"relaxation_time", "λ", "s", "Time constant of a Carreau liquid: thinning sets in at shear rate 1/λ",
     inModel<&Carreau::relaxationTime>(), kRequired, 1e-9, 1e6, true, 1e-3, 1e3, 1, false},
    {"yield_stress", "τ_y", "Pa", "Yield stress of a Herschel–Bulkley liquid", inModel<&HerschelBulkley::yieldStress>(),
     0, 0, 1e6, true, 1e-2, 1e3, 10, false},
    // A solid's dimensions: searched from the scene's value, within a factor 2 unless the job says.
    {"inner_radius", "R", "m", "Inner radius of a cup", inSolid<&CupSolid::innerRadius>(), kRequired, 1e-4, 10, true,
     kSceneValue, kSceneValue, kSceneValue, false},
    {"height", "H", "m", "Inner depth of a cup, from its inner bottom to its rim", inSolid<&CupSolid::height>(),
     kRequired, 1e-4, 10, true, kSceneValue, kSceneValue, kSceneValue, false},
    {"wall_thickness", "t_w", "m", "Wall thickness of a cup", inSolid<&CupSolid::wallThickness>(), kRequired, 1e-5, 1,
     true, kSceneValue, kSceneValue, kSceneValue, false},
    {"bottom_thickness", "t_b", "m", "Bottom thickness of a cup", inSolid<&CupSolid::bottomThickness>(), kRequired,
     1e-5, 1, true, kSceneValue, kSceneValue, kSceneValue, false},
    {"hole_radius", "r_h", "m", "Radius of the hole in a cup's bottom (0: none)", inSolid<&CupSolid::holeRadius>(), 0,
     0, 10, true, kSceneValue, kSceneValue, kSceneValue, false},
    {"width", "W", "m", "Width of a channel between its side walls", inSolid<&ChannelSolid::width>(), kRequired, 1e-4,
     100, true, kSceneValue, kSceneValue, kSceneValue, false},
};

const char* homeName(ParameterHome home) {
    switch (home) {
        case ParameterHome::Material: return "material";
        case ParameterHome::MaterialModel: return "material.model";
        case ParameterHome::Solid: return "solids[i]";
    }
    return "";
}

std::string format(double x) {
    std::ostringstream s;
    s << x;
    return s.str();
}

json orNull(double x) { return std::isnan(x) ? json(nullptr) : json(x); }

// Where a declared parameter's value lives in a scene; nullptr when the scene has no such field.
double* field(Scene& scene, const SceneParameter& p) {
    const ParameterPlace& place = p.declaration->place;
    switch (place.home) {
        case ParameterHome::Material: return place.inMaterial(scene.material);
        case ParameterHome::MaterialModel: return place.inModel(scene.material.model);
        case ParameterHome::Solid:
            if (p.solid < 0 || p.solid >= static_cast<int>(scene.solids.size())) return nullptr;
            return place.inSolid(scene.solids[p.solid]);
    }
    return nullptr;
}

size_t editDistance(const std::string& a, const std::string& b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        size_t diagonal = row[0];
        row[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t above = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diagonal = above;
        }
    }
    return row[b.size()];
}

}  // namespace

const std::vector<ParameterDeclaration>& parameterDeclarations() { return kDeclarations; }

const ParameterDeclaration* findParameterDeclaration(const std::string& name) {
    for (const ParameterDeclaration& d : kDeclarations)
        if (name == d.name) return &d;
    return nullptr;
}

std::string boundsProblem(const ParameterDeclaration& d, double value) {
    if (value >= d.lower && value <= d.upper) return {};
    return "must be in [" + format(d.lower) + ", " + format(d.upper) + "] " + d.unit + ", got " + format(value);
}

json parameterSchema() {
    json parameters = json::array();
    for (const ParameterDeclaration& d : kDeclarations) {
        json entry{{"name", d.name},
                   {"symbol", d.symbol},
                   {"unit", d.unit},
                   {"description", d.description},
                   {"home", homeName(d.place.home)},
                   {"default", orNull(d.defaultValue)},
                   {"lower", d.lower},
                   {"upper", d.upper},
                   {"searchable", d.searchable}};
        if (!d.place.types.empty()) entry["types"] = d.place.types;
        if (d.searchable)
            entry["search"] = {{"lower", orNull(d.searchLower)},
                               {"upper", orNull(d.searchUpper)},
                               {"initial", orNull(d.searchInitial)},
                               {"space", "log"},
                               {"profile", d.speedScalesInversely ? "1/theta" : "log"}};
        parameters.push_back(entry);
    }
    return {{"format", "viscoscope.schema"},
            {"version", 1},
            {"engine_version", VISCOSCOPE_VERSION},
            {"scene_version", kSceneFormatVersion},
            {"parameters", parameters},
            {"min_hole_cells", kMinHoleCells}};
}

SceneParameter resolveParameter(const Scene& scene, const std::string& name, const std::string& where) {
    SceneParameter p;
    p.name = name;
    std::string key = name;
    if (name.rfind("solids[", 0) == 0) {
        const size_t close = name.find("].");
        size_t digits = 0;
        int index = -1;
        try {
            index = std::stoi(name.substr(7, close - 7), &digits);
        } catch (const std::exception&) {
        }
        if (close == std::string::npos || digits != close - 7 || index < 0)
            throw InputError(where + ": \"" + name + "\" is not a solid's parameter (\"solids[i].NAME\")");
        if (index >= static_cast<int>(scene.solids.size()))
            throw InputError(where + ": \"" + name + "\": the scene has " + std::to_string(scene.solids.size()) +
                             " solids");
        p.solid = index;
        key = name.substr(close + 2);
    }
    p.declaration = findParameterDeclaration(key);
    if (p.declaration && p.declaration->place.home == ParameterHome::Solid && p.solid < 0)
        throw InputError(where + ": \"" + name + "\" is a solid's: name it \"solids[i]." + name + "\", i its index");
    if (!p.declaration || (p.declaration->place.home == ParameterHome::Solid) != (p.solid >= 0)) {
        std::vector<std::string> names;
        for (const ParameterDeclaration& d : kDeclarations) names.push_back(d.name);
        const std::string near = nearestName(key, names);
        throw InputError(where + ": \"" + name + "\" is not a declared parameter" +
                         (near.empty() ? "" : "; did you mean \"" + near + "\"?") + " (viscoscope schema lists them)");
    }
    if (!field(const_cast<Scene&>(scene), p)) {
        std::string types;
        for (const char* t : p.declaration->place.types) types += std::string(types.empty() ? "" : " or ") + t;
        if (p.declaration->place.home == ParameterHome::Solid)
            throw InputError(where + ": \"" + name + "\": solids[" + std::to_string(p.solid) + "] is a " +
                             std::visit(SolidName{}, scene.solids[p.solid]) + ", and only a " + types + " has it");
        throw InputError(where + ": \"" + name + "\": the scene's material model is " +
                         std::visit(ModelName{}, scene.material.model) + ", and only " + types + " has it");
    }
    return p;
}

double parameterValue(const Scene& scene, const SceneParameter& parameter) {
    // field() only reads through the pointer here.
    return *field(const_cast<Scene&>(scene), parameter);
}

void setParameter(Scene& scene, const SceneParameter& parameter, double value) {
    if (const std::string problem = boundsProblem(*parameter.declaration, value); !problem.empty())
        throw InputError(parameter.name + ": " + problem);
    *field(scene, parameter) = value;
}

std::string nearestName(const std::string& given, const std::vector<std::string>& known) {
    std::string best;
    size_t bestDistance = std::min<size_t>(3, std::max<size_t>(1, given.size() / 3)) + 1;
    for (const std::string& name : known) {
        const size_t d = editDistance(given, name);
        if (d < bestDistance) best = name, bestDistance = d;
    }
    return best;
}

void rejectUnknownKeys(const json& object, const std::vector<std::string>& known, const std::string& prefix) {
    if (!object.is_object()) return;
    for (const auto& item : object.items()) {
        if (std::find(known.begin(), known.end(), item.key()) != known.end()) continue;
        const std::string near = nearestName(item.key(), known);
        throw InputError(prefix + item.key() + ": unknown field" +
                         (near.empty() ? "" : "; did you mean `" + near + "`?"));
    }
}

json parseJsonStrictly(std::istream& text, const std::string& origin) {
    // A stack of the keys seen in each open object: nlohmann keeps the last of a repeated key.
    std::vector<std::set<std::string>> keys;
    const json::parser_callback_t check = [&](int depth, json::parse_event_t event, json& parsed) {
        if (depth > kMaxJsonDepth)
            throw InputError(origin + ": nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
        if (event == json::parse_event_t::object_start) keys.emplace_back();
        else if (event == json::parse_event_t::object_end) keys.pop_back();
        else if (event == json::parse_event_t::key && !keys.empty() &&
                 !keys.back().insert(parsed.get<std::string>()).second)
            throw InputError(origin + ": the key \"" + parsed.get<std::string>() + "\" appears twice in one object");
        return true;
    };
    try {
        return json::parse(text, check);
    } catch (const json::out_of_range& e) {
        throw InputError(origin + ": a number past double's range (" + e.what() + ")");
    } catch (const json::parse_error& e) {
        throw InputError(origin + ": not valid JSON (" + e.what() + ")");
    } catch (const std::ios_base::failure& e) {  // a folder, or a file that cannot be read
        throw InputError(origin + ": cannot read (" + e.what() + ")");
    }
}

}  // namespace viscoscope
