// The weights of every control volume (VolumeFractions in stokes_solver.h), all from one sampling
// of half-cells so that they agree with each other: the solids' share of each half-cell, fixed in
// time, and the liquid's, from the particles at each step. The liquid's surface is the
// kernel-averaged particle distance of Zhu & Bridson 2005, "Animating sand as a fluid".
#pragma once

#include "sim/grid.h"
#include "sim/stokes_solver.h"

#include <vector>

namespace viscoscope::sim {

class SolidField;

// Kernel reach (cells) of the liquid's distance: particles and wall images this close to a cell
// centre count in it.
inline constexpr double kLiquidKernelRadius = 1.5;

// The non-solid fraction of every half-cell of `grid` (twice its cells per axis, x fastest): the one
// sub-cell sampling all control volumes share. Polls for cancellation.
std::vector<double> halfCellOpenFractions(const SolidField& solids, const Grid& grid);

// Which faces are shut by the solids and the open area of the others (VolumeFractions::solidFace
// and faceOpenArea), from the solids and halfCellOpenFractions.
void openFaces(const SolidField& solids, const Grid& grid, const std::vector<double>& halfCellOpen,
               VolumeFractions& fractions);

// The liquid's signed distance `phi` at cell centres (negative inside, at most 3 Δx) from the
// particles and their wall images (wallImages within kLiquidKernelRadius cells). Non-finite
// positions are skipped. The same at any thread count.
void liquidDistance(const std::vector<Vec3>& particles, const std::vector<Vec3>& wallImages, const Grid& grid,
                    Field& phi);

// The cells that can hold liquid: the particles' bounding box grown by the kernel's reach, and
// every cell along a periodic axis (or when no particle is finite).
CellBox activeCells(const std::vector<Vec3>& particles, const Grid& grid);

// The liquid × non-solid fraction of every cell, face and edge control volume around `active`
// (zero beyond), from `phi` (liquidDistance) and halfCellOpenFractions.
void liquidFractions(const Field& phi, const std::vector<double>& halfCellOpen, const Grid& grid,
                     const CellBox& active, VolumeFractions& fractions);

}  // namespace viscoscope::sim
