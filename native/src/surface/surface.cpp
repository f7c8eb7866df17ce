#include "surface/surface.h"

#include "scene/scene.h"

#include <openvdb/io/Archive.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>

namespace viscoscope::surface {

namespace {

openvdb::math::Transform::Ptr cellCentredTransform(const sim::Grid& grid) {
    auto transform = openvdb::math::Transform::createLinearTransform(grid.dx);
    const Eigen::Vector3d centre = grid.origin + Eigen::Vector3d::Constant(0.5 * grid.dx);
    transform->postTranslate(openvdb::Vec3d(centre.x(), centre.y(), centre.z()));
    return transform;
}

// openvdb::io::File writes through a stream of its own and never checks it, so a full disk leaves a
// truncated .vdb behind without an error. This writes the same seekable file format (File's) into a
// stream the caller checks.
class VdbFileWriter : public openvdb::io::Archive {
public:
    void write(std::ostream& out, const openvdb::GridPtrVec& grids) const {
        openvdb::io::Archive::write(out, grids, /*seekable=*/true);
    }
};

}  // namespace

openvdb::FloatGrid::Ptr liquidLevelSet(const std::vector<Eigen::Vector3d>& positions, double particleVolume,
                                       double smoothing, double voxelSize) {
    auto transform = openvdb::math::Transform::createLinearTransform(voxelSize);
    transform->postTranslate(openvdb::Vec3d(0.5 * voxelSize));  // voxel centres at (i + ½) h
    const float band = static_cast<float>(sim::kDefaultBandHalfWidth * voxelSize);
    auto grid = openvdb::FloatGrid::create(band);  // outside beyond the band
    grid->setTransform(transform);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("surface");
    if (positions.empty()) return grid;
    // The density is splatted by hand: OpenVDB rasterizes points as spheres or trilinear weights,
    // not as a Gaussian of a given width. Separable weights cost 3·(2R+1) exponentials per particle
    // instead of (2R+1)³. It is summed tile by tile, each in a small dense box, so that memory
    // follows the tiles the liquid reaches, not the box around all of it (liquid spread over a
    // 128³ domain would need about 0.5 GB at once). Each voxel sums the same particles in the same
    // order whatever the tiling.
    const double h = voxelSize;
    const int reach = static_cast<int>(std::ceil(3 * smoothing / h));
    const int width = 2 * reach + 2;  // the voxels a particle's weights cover along each axis
    constexpr int kTile = 64;         // voxels along a tile's side
    std::vector<openvdb::Vec3d> index(positions.size());
    // Per tile, the particles whose weights reach into it or its one-voxel rim (the gradient's).
    std::map<openvdb::Coord, std::vector<size_t>> tiles;
    const auto tileOf = [](const openvdb::Coord& c) {
        const auto floorDiv = [](int v) { return (v >= 0 ? v : v - kTile + 1) / kTile; };
        return openvdb::Coord(floorDiv(c.x()), floorDiv(c.y()), floorDiv(c.z()));
    };
    for (size_t p = 0; p < positions.size(); ++p) {
        index[p] = openvdb::Vec3d(positions[p].x(), positions[p].y(), positions[p].z()) / h - openvdb::Vec3d(0.5);
        const openvdb::Coord first = openvdb::Coord::floor(index[p]).offsetBy(-reach);
        const openvdb::Coord from = tileOf(first.offsetBy(-1)), to = tileOf(first.offsetBy(width));
        for (int i = from.x(); i <= to.x(); ++i)
            for (int j = from.y(); j <= to.y(); ++j)
                for (int k = from.z(); k <= to.z(); ++k) tiles[openvdb::Coord(i, j, k)].push_back(p);
    }
    const double norm = particleVolume / std::pow(std::sqrt(2 * M_PI) * smoothing, 3);
    std::vector<double> weight(3 * width);
    auto access = grid->getAccessor();
    for (const auto& [tile, particles] : tiles) {
        const openvdb::Coord origin(tile.x() * kTile, tile.y() * kTile, tile.z() * kTile);
        const openvdb::CoordBBox inner(origin, origin.offsetBy(kTile - 1));
        const openvdb::CoordBBox box(inner.min().offsetBy(-1), inner.max().offsetBy(1));
        openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> density(box, 0.f);
        for (size_t p : particles) {
            const openvdb::Vec3d& u = index[p];
            const openvdb::Coord first = openvdb::Coord::floor(u).offsetBy(-reach);
            for (int a = 0; a < 3; ++a)
                for (int i = 0; i < width; ++i) {
                    const double d = (first[a] + i - u[a]) * h;
                    weight[a * width + i] = std::exp(-d * d / (2 * smoothing * smoothing));
                }
            // The part of the particle's cube inside the tile's box.
            const openvdb::Coord lo = openvdb::Coord::maxComponent(first, box.min()) - first;
            const openvdb::Coord hi = openvdb::Coord::minComponent(first.offsetBy(width - 1), box.max()) - first;
            for (int i = lo.x(); i <= hi.x(); ++i)
                for (int j = lo.y(); j <= hi.y(); ++j) {
                    const double wij = norm * weight[i] * weight[width + j];
                    // The row from its first voxel inside the box: a pointer before it may lie
                    // outside the box's array.
                    float* row = &density.getValue(first.offsetBy(i, j, lo.z()));
                    for (int k = lo.z(); k <= hi.z(); ++k)
                        row[k - lo.z()] += static_cast<float>(wij * weight[2 * width + k]);
                }
        }
        // Near the half level, (½ − ρ)/|∇ρ| is the distance to it to first order, which is all a
        // narrow band needs (at σ from it, 1.4 times the distance). Rebuilding a distance field
        // through a mesh (tools::levelSetRebuild) cost many times the rest and drew the sample
        // cup's stream narrower (tests/bench/FINDINGS.md, "Figures moved from code comments").
        const auto rho = [&](const openvdb::Coord& c) { return density.getValue(c); };
        for (auto voxel = inner.begin(); voxel; ++voxel) {
            const openvdb::Coord& c = *voxel;
            if (rho(c) == 0.f) continue;
            const openvdb::Vec3f gradient(rho(c.offsetBy(1, 0, 0)) - rho(c.offsetBy(-1, 0, 0)),
                                          rho(c.offsetBy(0, 1, 0)) - rho(c.offsetBy(0, -1, 0)),
                                          rho(c.offsetBy(0, 0, 1)) - rho(c.offsetBy(0, 0, -1)));
            const float slope = gradient.length() / static_cast<float>(2 * h);
            const float d = (0.5f - rho(c)) / std::max(slope, 1e-12f);
            if (d <= -band) access.setValueOff(c, -band);  // inside beyond the band
            else if (d < band) access.setValueOn(c, d);
        }
    }
    openvdb::tools::pruneLevelSet(grid->tree());
    return grid;
}

double surfaceVoxelSize(double smoothing) { return smoothing / kVoxelsPerSmoothing; }

openvdb::FloatGrid::Ptr liquidLevelSet(const sim::Simulation& simulation) {
    const double smoothing = simulation.scene().surfaceSmoothing();
    return liquidLevelSet(simulation.particles().position, simulation.particleVolume(), smoothing,
                          surfaceVoxelSize(smoothing));
}

void clipToSolidExterior(openvdb::FloatGrid& levelSet, const sim::SolidField& solids) {
    const openvdb::math::Transform& transform = levelSet.transform();
    for (auto voxel = levelSet.tree().beginValueOn(); voxel; ++voxel) {
        const openvdb::Vec3d x = transform.indexToWorld(voxel.getCoord());
        const double outside = -solids.distance(Eigen::Vector3d(x.x(), x.y(), x.z()));
        if (outside > *voxel) voxel.setValue(static_cast<float>(outside));
    }
}

void meshLevelSet(const openvdb::FloatGrid& levelSet, std::vector<openvdb::Vec3s>& points,
                  std::vector<openvdb::Vec3I>& triangles) {
    std::vector<openvdb::Vec4I> quads;
    points.clear();
    triangles.clear();
    openvdb::tools::volumeToMesh(levelSet, points, triangles, quads, 0.0);
    for (const openvdb::Vec4I& q : quads) {
        triangles.emplace_back(q[0], q[1], q[2]);
        triangles.emplace_back(q[0], q[2], q[3]);
    }
}

void writeFrameVdb(const std::filesystem::path& file, const sim::Simulation& simulation,
                   openvdb::FloatGrid::Ptr levelSet) {
    const sim::Grid& grid = simulation.grid();
    const sim::Lattice cells = grid.lattice(sim::kCellCentre);
    const sim::VolumeFractions& fractions = simulation.fractions();
    auto velocity = openvdb::Vec3fGrid::create(openvdb::Vec3f(0));
    auto pressure = openvdb::FloatGrid::create(0.f);
    velocity->setName("velocity");
    pressure->setName("pressure");
    velocity->setTransform(cellCentredTransform(grid));  // sampled at cell centres
    pressure->setTransform(cellCentredTransform(grid));
    auto vAccess = velocity->getAccessor();
    auto pAccess = pressure->getAccessor();
    for (int c = 0; c < cells.count(); ++c) {
        if (fractions.cell[c] < sim::kMinWeight) continue;
        const Eigen::Vector3i ijk = cells.coords(c);
        const Eigen::Vector3d v = simulation.velocityAt(grid.position(sim::kCellCentre, ijk));
        const openvdb::Coord coord(ijk[0], ijk[1], ijk[2]);
        vAccess.setValue(coord, openvdb::Vec3f(v.x(), v.y(), v.z()));
        pAccess.setValue(coord, static_cast<float>(simulation.cellPressure(c)));
    }
    const openvdb::GridPtrVec grids{levelSet, velocity, pressure};
    writeFileAtomically(file, [&](std::ostream& out) { VdbFileWriter().write(out, grids); });
}

void writeParticles(const std::filesystem::path& file, const sim::Particles& particles) {
    const uint32_t version = 1;
    const uint64_t count = particles.position.size();
    std::vector<float> record(6 * count);
    for (size_t p = 0; p < count; ++p)
        for (int a = 0; a < 3; ++a) {
            record[6 * p + a] = static_cast<float>(particles.position[p][a]);
            record[6 * p + 3 + a] = static_cast<float>(particles.velocity[p][a]);
        }
    writeFileAtomically(file, [&](std::ostream& out) {
        out.write("VSCP", 4);
        out.write(reinterpret_cast<const char*>(&version), sizeof version);
        out.write(reinterpret_cast<const char*>(&count), sizeof count);
        out.write(reinterpret_cast<const char*>(record.data()), std::streamsize(record.size() * sizeof(float)));
    });
}

sim::Particles readParticles(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    char magic[4];
    uint32_t version = 0;
    uint64_t count = 0;
    if (!in.read(magic, 4) || std::memcmp(magic, "VSCP", 4) != 0 ||
        !in.read(reinterpret_cast<char*>(&version), sizeof version) || version != 1 ||
        !in.read(reinterpret_cast<char*>(&count), sizeof count))
        throw InputError(file.string() + ": not a Viscoscope particle file (version 1)");
    std::vector<float> record(6 * count);
    if (!in.read(reinterpret_cast<char*>(record.data()), std::streamsize(record.size() * sizeof(float))))
        throw InputError(file.string() + ": truncated particle file");
    sim::Particles particles;
    for (size_t p = 0; p < count; ++p) {
        particles.position.emplace_back(record[6 * p], record[6 * p + 1], record[6 * p + 2]);
        particles.velocity.emplace_back(record[6 * p + 3], record[6 * p + 4], record[6 * p + 5]);
        particles.affine.push_back(Eigen::Matrix3d::Zero());
    }
    return particles;
}

void writeObj(const std::filesystem::path& file, const std::vector<openvdb::Vec3s>& points,
              const std::vector<openvdb::Vec3I>& triangles) {
    TriangleMesh mesh;
    mesh.vertices.reserve(points.size());
    for (const auto& p : points) mesh.vertices.emplace_back(p.x(), p.y(), p.z());
    mesh.triangles.reserve(triangles.size());
    // OpenVDB's winding faces inward for level sets; OBJ expects counter-clockwise outward faces.
    for (const auto& t : triangles) mesh.triangles.emplace_back(t[0], t[2], t[1]);
    writeObj(file, mesh);
}

void writeObj(const std::filesystem::path& file, const TriangleMesh& mesh) {
    writeFileAtomically(file, [&](std::ostream& out) {
        for (const auto& p : mesh.vertices) out << "v " << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
        for (const auto& t : mesh.triangles) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
    });
}

}  // namespace viscoscope::surface
