// Triangle meshes from OBJ and PLY files: mesh solids in scenes, and surfaces meshed elsewhere.
#include "sim/sim.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

namespace viscoscope {

namespace {

[[noreturn]] void fail(const std::filesystem::path& file, const std::string& problem) {
    throw InputError(file.string() + ": " + problem);
}

// Reading a mesh of millions of faces takes seconds: a cancel is polled every 65536 lines or elements.
void pollCancel(long long count) {
    if ((count & 0xFFFF) == 0) throwIfCancelled("reading the mesh");
}

void addPolygon(TriangleMesh& mesh, const std::vector<long long>& polygon, const std::filesystem::path& file) {
    if (polygon.size() < 3) fail(file, "a face has fewer than 3 vertices");
    for (long long index : polygon)
        if (index < 0 || index >= static_cast<long long>(mesh.vertices.size()))
            fail(file, "face index " + std::to_string(index) + " out of range");
    for (size_t i = 1; i + 1 < polygon.size(); ++i)
        mesh.triangles.emplace_back(int(polygon[0]), int(polygon[i]), int(polygon[i + 1]));
}

TriangleMesh loadObj(const std::filesystem::path& file) {
    std::ifstream stream(file);
    if (!stream) fail(file, "cannot open mesh");
    TriangleMesh mesh;
    std::string line;
    for (long long lines = 1; std::getline(stream, line); ++lines) {
        pollCancel(lines);
        std::istringstream in(line);
        std::string tag;
        in >> tag;
        if (tag == "v") {
            Eigen::Vector3d v;
            if (!(in >> v.x() >> v.y() >> v.z()) || !v.allFinite()) fail(file, "bad vertex line \"" + line + "\"");
            mesh.vertices.push_back(v);
        } else if (tag == "f") {
            std::vector<long long> polygon;
            for (std::string corner; in >> corner;) {
                const long long index = std::atoll(corner.c_str());  // "7/3/2" → 7
                // OBJ indices are 1-based; negative ones count back from the latest vertex.
                polygon.push_back(index < 0 ? static_cast<long long>(mesh.vertices.size()) + index : index - 1);
            }
            addPolygon(mesh, polygon, file);
        }
    }
    return mesh;
}

// PLY: ASCII or binary little-endian, a "vertex" element with x, y, z and a "face" element with a
// vertex index list. Other elements may follow these two.
struct PlyProperty {
    std::string name, type, countType;  // countType set for lists
};
struct PlyElement {
    std::string name;
    long long count = 0;
    std::vector<PlyProperty> properties;
};

size_t plyTypeSize(const std::string& type, const std::filesystem::path& file) {
    static const std::map<std::string, size_t> sizes{
        {"char", 1},  {"uchar", 1},  {"int8", 1},   {"uint8", 1},   {"short", 2},   {"ushort", 2},
        {"int16", 2}, {"uint16", 2}, {"int", 4},    {"uint", 4},    {"int32", 4},   {"uint32", 4},
        {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
    const auto found = sizes.find(type);
    if (found == sizes.end()) fail(file, "unknown PLY property type \"" + type + "\"");
    return found->second;
}

class PlyValueReader {
public:
    PlyValueReader(std::istream& stream, bool binary, const std::filesystem::path& file)
        : stream_(stream), binary_(binary), file_(file) {}

    double read(const std::string& type) {
        if (!binary_) {
            double value = 0;
            if (!(stream_ >> value)) fail(file_, "PLY data ends early or is not numeric");
            return value;
        }
        unsigned char bytes[8] = {};
        const size_t size = plyTypeSize(type, file_);
        if (!stream_.read(reinterpret_cast<char*>(bytes), static_cast<std::streamsize>(size)))
            fail(file_, "PLY data ends early");
        return decode(type, bytes);  // this machine is little-endian, like the file
    }

private:
    template <typename T>
    static double as(const unsigned char* bytes) {
        T value;
        std::memcpy(&value, bytes, sizeof(T));
        return static_cast<double>(value);
    }
    static double decode(const std::string& type, const unsigned char* bytes) {
        if (type == "char" || type == "int8") return as<int8_t>(bytes);
        if (type == "uchar" || type == "uint8") return as<uint8_t>(bytes);
        if (type == "short" || type == "int16") return as<int16_t>(bytes);
        if (type == "ushort" || type == "uint16") return as<uint16_t>(bytes);
        if (type == "int" || type == "int32") return as<int32_t>(bytes);
        if (type == "uint" || type == "uint32") return as<uint32_t>(bytes);
        if (type == "float" || type == "float32") return as<float>(bytes);
        return as<double>(bytes);
    }
    std::istream& stream_;
    bool binary_;
    const std::filesystem::path& file_;
};

std::vector<PlyElement> readPlyHeader(std::istream& stream, bool& binary, const std::filesystem::path& file) {
    std::string line;
    if (!std::getline(stream, line) || line.rfind("ply", 0) != 0) fail(file, "not a PLY file");
    std::vector<PlyElement> elements;
    while (std::getline(stream, line)) {
        std::istringstream in(line);
        std::string keyword;
        in >> keyword;
        if (keyword == "format") {
            std::string format;
            in >> format;
            if (format != "ascii" && format != "binary_little_endian") fail(file, "unsupported PLY format " + format);
            binary = format == "binary_little_endian";
        } else if (keyword == "element") {
            PlyElement element;
            in >> element.name >> element.count;
            elements.push_back(element);
        } else if (keyword == "property" && !elements.empty()) {
            PlyProperty property;
            in >> property.type;
            if (property.type == "list") in >> property.countType >> property.type;
            in >> property.name;
            elements.back().properties.push_back(property);
        } else if (keyword == "end_header") {
            return elements;
        }
    }
    fail(file, "PLY header has no end_header");
}

void readPlyVertices(const PlyElement& element, PlyValueReader& reader, TriangleMesh& mesh) {
    for (long long i = 0; i < element.count; ++i) {
        pollCancel(i);
        Eigen::Vector3d v = Eigen::Vector3d::Zero();
        for (const PlyProperty& property : element.properties) {
            const double value = reader.read(property.type);
            if (property.name == "x") v.x() = value;
            if (property.name == "y") v.y() = value;
            if (property.name == "z") v.z() = value;
        }
        mesh.vertices.push_back(v);
    }
}

void readPlyFaces(const PlyElement& element, PlyValueReader& reader, TriangleMesh& mesh,
                  const std::filesystem::path& file) {
    for (long long i = 0; i < element.count; ++i) {
        pollCancel(i);
        std::vector<long long> polygon;
        for (const PlyProperty& property : element.properties) {
            if (property.countType.empty()) {
                reader.read(property.type);
                continue;
            }
            const auto count = static_cast<long long>(reader.read(property.countType));
            std::vector<long long> indices;
            for (long long k = 0; k < count; ++k) indices.push_back(static_cast<long long>(reader.read(property.type)));
            if (property.name == "vertex_indices" || property.name == "vertex_index") polygon = indices;
        }
        addPolygon(mesh, polygon, file);
    }
}

TriangleMesh loadPly(const std::filesystem::path& file) {
    std::ifstream stream(file, std::ios::binary);
    if (!stream) fail(file, "cannot open mesh");
    bool binary = false;
    const std::vector<PlyElement> elements = readPlyHeader(stream, binary, file);
    PlyValueReader reader(stream, binary, file);
    TriangleMesh mesh;
    for (const PlyElement& element : elements) {
        if (element.name == "vertex")
            readPlyVertices(element, reader, mesh);
        else if (element.name == "face")
            readPlyFaces(element, reader, mesh, file);
        else
            break;  // elements after the mesh are not needed; ones before it cannot be skipped safely
    }
    return mesh;
}

}  // namespace

TriangleMesh loadMesh(const std::filesystem::path& file) {
    const std::string extension = file.extension().string();
    TriangleMesh mesh;
    if (extension == ".obj")
        mesh = loadObj(file);
    else if (extension == ".ply")
        mesh = loadPly(file);
    else
        fail(file, "unsupported mesh format (expected .obj or .ply)");
    if (mesh.triangles.empty()) fail(file, "mesh has no faces");
    for (const Eigen::Vector3d& v : mesh.vertices)
        if (!v.allFinite()) fail(file, "mesh has a non-finite vertex");
    return mesh;
}

}  // namespace viscoscope
