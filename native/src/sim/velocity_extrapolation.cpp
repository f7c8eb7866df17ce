#include "sim/velocity_extrapolation.h"

#include <utility>

namespace viscoscope::sim {

// A layer can only fill neighbours of the faces valid before it, so each pass visits those alone
// (the next pass: the neighbours of the faces the last one filled), not the whole box around the
// liquid, which is mostly air. A face's mean is over its neighbours in a fixed order either way.
void extrapolateVelocity(std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& validFace,
                         const VolumeFractions& fractions, const CellBox& active, int layers) {
    for (int a = 0; a < 3; ++a) {
        Field& u = velocity[a];
        const Lattice& lattice = u.lattice;
        std::vector<char>& valid = validFace[a];
        // Only faces near the liquid are ever read (by particles and the solve): stay in its box.
        const SampleBox box = nearBox(lattice, active, layers);
        std::vector<char> queued(lattice.count(), 0);
        std::vector<int> candidates;
        const auto queueNeighbours = [&](int f) {
            const Vec3i ijk = lattice.coords(f);
            for (int b = 0; b < 3; ++b)
                for (int d : {-1, 1})
                    if (const int nb = lattice.neighbour(ijk, b, d);
                        nb >= 0 && !queued[nb] && !valid[nb] && !fractions.solidFace[a][nb] && box.contains(lattice.coords(nb))) {
                        queued[nb] = 1;
                        candidates.push_back(nb);
                    }
        };
        for (int f = 0; f < lattice.count(); ++f)
            if (valid[f]) queueNeighbours(f);
        std::vector<std::pair<int, double>> filled;
        for (int layer = 0; layer < layers; ++layer) {
            filled.clear();
            for (const int f : candidates) {
                const Vec3i ijk = lattice.coords(f);
                double sum = 0;
                int count = 0;
                for (int b = 0; b < 3; ++b)
                    for (int d : {-1, 1})
                        if (const int nb = lattice.neighbour(ijk, b, d); nb >= 0 && valid[nb]) {
                            sum += u[nb];
                            ++count;
                        }
                filled.emplace_back(f, sum / count);  // a candidate has a valid neighbour
            }
            for (const auto& [f, value] : filled) {
                u[f] = value;
                valid[f] = 1;
            }
            candidates.clear();
            for (const auto& [f, value] : filled) queueNeighbours(f);
        }
    }
}

void markSolvedFaces(std::array<Field, 3>& velocity, std::array<std::vector<char>, 3>& valid,
                     const VolumeFractions& fractions, const CellBox& active) {
    const Lattice& cells = fractions.cell.lattice;
    for (int a = 0; a < 3; ++a) {
        Field& u = velocity[a];
        forEachNearBox(u.lattice, active, kActiveMargin, [&](int f, const Vec3i& c) {
            if (fractions.solidFace[a][f]) {
                u[f] = 0;
                return;
            }
            const auto [lo, hi] = faceCells(cells, c, a);
            if ((lo >= 0 && fractions.cell[lo] >= kMinWeight) || (hi >= 0 && fractions.cell[hi] >= kMinWeight))
                valid[a][f] = 1;
        });
    }
}

}  // namespace viscoscope::sim
