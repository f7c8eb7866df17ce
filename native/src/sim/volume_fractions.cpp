#include "sim/volume_fractions.h"

#include "sim/solid_field.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace viscoscope::sim {

namespace {

// Particle radius (cells) of the liquid's distance: set so that a seeded block of liquid measures
// its true volume (tests/bench/FINDINGS.md, "The liquid's particle radius").
constexpr double kParticleRadius = 0.45;

// Smooth Heaviside of a signed distance over a half-cell of width h: the inside fraction of a
// half-cell whose centre is at distance phi from a planar interface.
double insideFraction(double phi, double h) { return std::clamp(0.5 - phi / h, 0.0, 1.0); }

// Index of half-cell (i, j, k) among `fine` half-cells, x fastest.
size_t halfCellIndex(const Vec3i& fine, int i, int j, int k) { return i + fine[0] * (j + size_t(fine[1]) * k); }

// The non-solid share of a sample of size h (a half-cell, or a patch of a face) centred at x.
double nonSolidFraction(const SolidField& solids, const Vec3& x, double h) {
    return 1.0 - insideFraction(solids.distance(x), h);
}

// Non-solid fraction of the area of the face centred at `centre` across `axis`, whose centre is
// `centreDistance` from the solids, from 4×4 samples of the solid distance on it, each a linear
// step over the sample spacing like the half-cells'. Faces farther from every solid than their
// half-diagonal are wholly open or shut.
double faceOpenArea(const SolidField& solids, const Vec3& centre, double centreDistance, int axis, double dx) {
    if (std::abs(centreDistance) > dx) return centreDistance > 0 ? 1.0 : 0.0;
    constexpr int kSamples = 4;
    const double h = dx / kSamples;
    const int b = (axis + 1) % 3, c = (axis + 2) % 3;
    double open = 0;
    for (int i = 0; i < kSamples; ++i)
        for (int j = 0; j < kSamples; ++j) {
            Vec3 x = centre;
            x[b] += (i + 0.5 - 0.5 * kSamples) * h;
            x[c] += (j + 0.5 - 0.5 * kSamples) * h;
            open += nonSolidFraction(solids, x, h);
        }
    return open / (kSamples * kSamples);
}

}  // namespace

std::vector<double> halfCellOpenFractions(const SolidField& solids, const Grid& grid) {
    const Vec3i fine = 2 * grid.cells;
    const double h = 0.5 * grid.dx;
    std::vector<double> open(size_t(fine[0]) * fine[1] * fine[2]);
    tbb::parallel_for(0, fine[2], [&](int k) {
        throwIfCancelled("sampling the solids");
        for (int j = 0; j < fine[1]; ++j)
            for (int i = 0; i < fine[0]; ++i) {
                const Vec3 x = grid.origin + h * Vec3(i + 0.5, j + 0.5, k + 0.5);
                open[halfCellIndex(fine, i, j, k)] = nonSolidFraction(solids, x, h);
            }
    });
    return open;
}

// A face whose centre lies in a solid is shut: its velocity is the solid's, and the viscous rows
// put the wall where it really is through ghost values (see the Stokes solver). An open face passes
// flux through its non-solid area only. Opening also the partly open faces whose centre lies in a
// wall was tried and rejected twice, as were open areas from point samples on two planes around the
// face and handing a shut face's open area to its open neighbours: each moved the cup's drain with
// where the cup sits among the faces (tests/bench/FINDINGS.md, "Face openings at the cup's
// bottom").
//
// A face beside a cell with no non-solid volume is shut too, though its centre may lie a hair
// outside the solid: the pressure solve would take that cell for air and drain the liquid into the
// solid through the face (Physics.OrificeFluxDoesNotLeakThroughAHairlineCut).
void openFaces(const SolidField& solids, const Grid& grid, const std::vector<double>& halfCellOpen,
               VolumeFractions& fractions) {
    const Lattice cells = grid.lattice(kCellCentre);
    const Vec3i fine = 2 * grid.cells;
    std::vector<char> cellAllSolid(cells.count());
    tbb::parallel_for(0, cells.count(), [&](int c) {
        const Vec3i corner = 2 * cells.coords(c);
        double open = 0;
        for (int k = 0; k < 2; ++k)
            for (int j = 0; j < 2; ++j)
                for (int i = 0; i < 2; ++i)
                    open += halfCellOpen[halfCellIndex(fine, corner[0] + i, corner[1] + j, corner[2] + k)];
        cellAllSolid[c] = open / 8 < kMinWeight;
    });
    for (int a = 0; a < 3; ++a) {
        const Lattice faces = grid.lattice(kFace[a]);
        fractions.faceOpenArea[a] = Field(faces);
        fractions.solidFace[a].assign(faces.count(), 1);
        tbb::parallel_for(0, faces.count(), [&](int f) {
            const Vec3i ijk = faces.coords(f);
            const auto [lo, hi] = faceCells(cells, ijk, a);
            if ((lo >= 0 && cellAllSolid[lo]) || (hi >= 0 && cellAllSolid[hi])) return;
            const Vec3 centre = grid.position(kFace[a], ijk);
            const double distance = solids.distance(centre);
            if (distance <= 0) return;
            fractions.solidFace[a][f] = 0;
            fractions.faceOpenArea[a][f] = faceOpenArea(solids, centre, distance, a, grid.dx);
        });
    }
}

// The liquid's signed distance at cell centres from the particles, after Zhu & Bridson 2005: φ(x) =
// |x − x̄(x)| − r, with x̄ a kernel-weighted mean of nearby particles. Unlike a union of spheres
// this gives flat surfaces where the particles lie flat, and no gaps inside the bulk. Within the
// kernel's reach of a wall, x̄ leans away from it, since no particle lies beyond it, and φ reads
// less deep than the liquid is: the grid took some of the liquid within a cell of a round pipe's
// wall for air, which weakened the wall's drag (tests/bench/FINDINGS.md, "Wall images"). The
// particles' wall images therefore count too: cut cells at walls read as full of liquid, and the
// non-solid fraction removes the part inside the wall. The splat runs in slabs of cell layers, each
// over the points that reach it in their order (particles, then images), so every cell sums in the
// same order at any thread count.
void liquidDistance(const std::vector<Vec3>& particles, const std::vector<Vec3>& wallImages, const Grid& grid,
                    Field& phi) {
    const Lattice& cells = phi.lattice;
    const double dx = grid.dx, radius = kParticleRadius * dx, reach = kLiquidKernelRadius * dx;
    std::vector<double> kernelSum(cells.count(), 0.0);
    std::vector<Vec3> weightedPosition(cells.count(), Vec3::Zero());
    // A particle lies in its cell, so cells |d| away are at least (|d| − ½) Δx from it.
    const int span = static_cast<int>(std::ceil(kLiquidKernelRadius - 0.5));
    const size_t particleCount = particles.size();
    const auto point = [&](size_t p) -> const Vec3& {
        return p < particleCount ? particles[p] : wallImages[p - particleCount];
    };
    const auto baseCell = [&](const Vec3& x) -> Vec3i { return ((x - grid.origin) / dx).array().floor().cast<int>(); };
    constexpr int kSlab = 4;
    const int slabs = (cells.size[2] + kSlab - 1) / kSlab;
    std::vector<std::vector<size_t>> reaching(slabs);
    for (size_t p = 0; p < particleCount + wallImages.size(); ++p) {
        if (!point(p).allFinite()) continue;  // advanceFrame reports a blow-up; never index with it
        const int k = baseCell(point(p))[2];
        for (int dk = -span; dk <= span; ++dk) {
            Vec3i c(0, 0, k + dk);
            if (!cells.resolve(c)) continue;
            std::vector<size_t>& list = reaching[c[2] / kSlab];
            if (list.empty() || list.back() != p) list.push_back(p);
        }
    }
    auto splat = [&](const Vec3& x, int zLo, int zHi) {
        const Vec3i base = baseCell(x);
        for (int dk = -span; dk <= span; ++dk)
            for (int dj = -span; dj <= span; ++dj)
                for (int di = -span; di <= span; ++di) {
                    Vec3i c = base + Vec3i(di, dj, dk);
                    if (!cells.resolve(c) || c[2] < zLo || c[2] > zHi) continue;
                    Vec3 offset = x - grid.position(kCellCentre, base + Vec3i(di, dj, dk));
                    const double s2 = offset.squaredNorm() / (reach * reach);
                    if (s2 >= 1) continue;
                    const double k = (1 - s2) * (1 - s2) * (1 - s2);
                    const int idx = cells.index(c[0], c[1], c[2]);
                    kernelSum[idx] += k;
                    // Stored relative to the cell centre, so that periodic images average correctly.
                    weightedPosition[idx] += k * offset;
                }
    };
    tbb::parallel_for(0, slabs, [&](int slab) {
        for (const size_t p : reaching[slab]) splat(point(p), slab * kSlab, slab * kSlab + kSlab - 1);
    });
    for (int c = 0; c < cells.count(); ++c)
        phi[c] = kernelSum[c] > 0 ? std::min((weightedPosition[c] / kernelSum[c]).norm() - radius, 3 * dx) : 3 * dx;
}

CellBox activeCells(const std::vector<Vec3>& particles, const Grid& grid) {
    const Lattice cells = grid.lattice(kCellCentre);
    Vec3i lo = cells.size, hi = Vec3i::Constant(-1);
    for (const Vec3& x : particles) {
        if (!x.allFinite()) continue;
        const Vec3i c = ((x - grid.origin) / grid.dx).array().floor().cast<int>();
        lo = lo.cwiseMin(c);
        hi = hi.cwiseMax(c);
    }
    const int margin = static_cast<int>(std::ceil(kLiquidKernelRadius)) + 1;
    for (int a = 0; a < 3; ++a) {
        const bool all = grid.periodic[a] || hi[a] < lo[a];
        lo[a] = all ? 0 : std::max(lo[a] - margin, 0);
        hi[a] = all ? cells.size[a] - 1 : std::min(hi[a] + margin, cells.size[a] - 1);
    }
    return {lo, hi};
}

void liquidFractions(const Field& phi, const std::vector<double>& halfCellOpen, const Grid& grid,
                     const CellBox& active, VolumeFractions& fractions) {
    const Lattice& cells = phi.lattice;
    const Vec3i &lo = active.lo, &hi = active.hi;
    // Liquid × non-solid fraction of every half-cell in the active box. A half-cell's φ interpolates
    // the 8 cell centres around it, all among its cell's 27 neighbours: where their range lies wholly
    // outside (or inside) ±h/2 the fraction is 0 (or 1) without interpolating, which spares most of
    // the box around a thin stream.
    const Vec3i fine = 2 * grid.cells;
    const double h = 0.5 * grid.dx;
    std::vector<double> fineFraction(halfCellOpen.size(), 0.0);
    tbb::parallel_for(lo[2], hi[2] + 1, [&](int ck) {
        for (int cj = lo[1]; cj <= hi[1]; ++cj)
            for (int ci = lo[0]; ci <= hi[0]; ++ci) {
                double phiMin = phi[cells.index(ci, cj, ck)], phiMax = phiMin;
                for (int dk = -1; dk <= 1; ++dk)
                    for (int dj = -1; dj <= 1; ++dj)
                        for (int di = -1; di <= 1; ++di) {
                            Vec3i c(ci + di, cj + dj, ck + dk);
                            if (!cells.resolve(c)) continue;  // interpolation clamps to the domain
                            const double value = phi[cells.index(c[0], c[1], c[2])];
                            phiMin = std::min(phiMin, value);
                            phiMax = std::max(phiMax, value);
                        }
                if (phiMin >= 0.5 * h) continue;
                for (int k = 2 * ck; k < 2 * ck + 2; ++k)
                    for (int j = 2 * cj; j < 2 * cj + 2; ++j)
                        for (int i = 2 * ci; i < 2 * ci + 2; ++i) {
                            const size_t idx = halfCellIndex(fine, i, j, k);
                            if (halfCellOpen[idx] == 0) continue;
                            const Vec3 x = grid.origin + h * Vec3(i + 0.5, j + 0.5, k + 0.5);
                            fineFraction[idx] = halfCellOpen[idx] *
                                                (phiMax <= -0.5 * h ? 1.0 : insideFraction(interpolate(grid, phi, x), h));
                        }
            }
    });

    // A sample's control volume is the cell-sized box around it: 2×2×2 half-cells.
    auto average = [&](Field& out, const Stagger& s) {
        const Lattice& l = out.lattice;
        tbb::parallel_for(0, l.count(), [&](int idx) {
            const Vec3i c = l.coords(idx);
            if ((c.array() < lo.array()).any() || (c.array() > hi.array() + 1).any()) {
                out[idx] = 0;
                return;
            }
            double sum = 0;
            for (int dk = 0; dk < 2; ++dk)
                for (int dj = 0; dj < 2; ++dj)
                    for (int di = 0; di < 2; ++di) {
                        Vec3i f(2 * c[0] + s[0] - 1 + di, 2 * c[1] + s[1] - 1 + dj, 2 * c[2] + s[2] - 1 + dk);
                        bool inside = true;
                        for (int a = 0; a < 3; ++a) {
                            if (grid.periodic[a]) f[a] = (f[a] % fine[a] + fine[a]) % fine[a];
                            else inside = inside && f[a] >= 0 && f[a] < fine[a];
                        }
                        if (inside) sum += fineFraction[halfCellIndex(fine, f[0], f[1], f[2])];
                    }
            out[idx] = sum / 8;
        });
    };
    average(fractions.cell, kCellCentre);
    for (int a = 0; a < 3; ++a) {
        average(fractions.face[a], kFace[a]);
        average(fractions.edge[a], kEdge[a]);
    }
}

}  // namespace viscoscope::sim
