// Solids as one signed distance field (negative inside): the union of the scene's analytic
// primitives and triangle meshes, the latter converted with openvdb::tools::meshToVolume.
#pragma once

#include "scene/scene.h"
#include "sim/grid.h"

#include <openvdb/openvdb.h>

#include <vector>

namespace viscoscope::sim {

class SolidField {
public:
    SolidField(const std::vector<Solid>& solids, const Grid& grid);

    // Signed distance to the nearest solid surface (m). Outside the domain box counts as solid
    // on non-periodic axes: the box walls are part of the container.
    double distance(const Vec3& x) const;
    Vec3 normal(const Vec3& x) const;  // outward from the solid, unit length
    bool empty() const { return solids_.empty() && meshes_.empty(); }

private:
    double primitiveDistance(const Vec3& x) const;

    std::vector<Solid> solids_;
    std::vector<openvdb::FloatGrid::Ptr> meshes_;
    Grid grid_;
};

}  // namespace viscoscope::sim
