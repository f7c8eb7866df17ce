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

// Whether x is surely at least `clearance` from every solid, from the solids' distance at its cell's
// centre alone (`cellSolidDistance`, one per cell of `grid`): distances are 1-Lipschitz, so this
// spares most particles a query of the solids.
inline bool surelyClearOfSolids(const Grid& grid, const std::vector<double>& cellSolidDistance, const Vec3& x,
                                double clearance) {
    const Lattice cells = grid.lattice(kCellCentre);
    const Vec3i c = ((x - grid.origin) / grid.dx).array().floor().cast<int>();
    const bool inGrid = (c.array() >= 0).all() && (c.array() < cells.size.array()).all();
    return inGrid && cellSolidDistance[cells.index(c[0], c[1], c[2])] - grid.dx >= clearance;
}

}  // namespace viscoscope::sim
