// The MAC grid: cell-centred, face-centred and edge-centred sample lattices over one box.
// Every sample kind is a Lattice with a per-axis offset of 0 (on a grid plane) or ½ (between planes);
// a periodic axis wraps and has no extra plane. Internal to the sim stage.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

namespace viscoscope::sim {

using Vec3 = Eigen::Vector3d;
using Vec3i = Eigen::Vector3i;

// Where the samples of one kind sit inside a cell: 1 = cell-centred along that axis, 0 = on a face.
using Stagger = std::array<int, 3>;
inline constexpr Stagger kCellCentre{1, 1, 1};
inline constexpr std::array<Stagger, 3> kFace{{{0, 1, 1}, {1, 0, 1}, {1, 1, 0}}};
// Off-diagonal stress τ_ab lives on the edges parallel to the third axis c: τ_yz on x-edges, etc.
inline constexpr std::array<Stagger, 3> kEdge{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};

struct Lattice {
    Vec3i size{0, 0, 0};
    Stagger stagger{1, 1, 1};
    std::array<bool, 3> periodic{false, false, false};

    Lattice() = default;
    Lattice(const Vec3i& cells, Stagger s, std::array<bool, 3> wrap) : stagger(s), periodic(wrap) {
        for (int a = 0; a < 3; ++a) size[a] = cells[a] + ((s[a] == 0 && !wrap[a]) ? 1 : 0);
    }
    int count() const { return size[0] * size[1] * size[2]; }
    int index(int i, int j, int k) const { return i + size[0] * (j + size[1] * k); }
    Vec3i coords(int idx) const {
        return {idx % size[0], (idx / size[0]) % size[1], idx / (size[0] * size[1])};
    }
    // Index i along periodic axis a, wrapped into [0, size[a]).
    int wrapped(int i, int a) const { return ((i % size[a]) + size[a]) % size[a]; }
    // Wraps periodic axes; returns false when (i,j,k) lies outside a non-periodic axis.
    bool resolve(Vec3i& c) const {
        for (int a = 0; a < 3; ++a) {
            if (periodic[a]) c[a] = wrapped(c[a], a);
            else if (c[a] < 0 || c[a] >= size[a]) return false;
        }
        return true;
    }
    // Index of a neighbour, or -1 outside the domain.
    int neighbour(const Vec3i& c, int axis, int delta) const {
        Vec3i n = c;
        n[axis] += delta;
        return resolve(n) ? index(n[0], n[1], n[2]) : -1;
    }
};

// The cells on either side of the face at `face` (lattice coordinates) on `axis`, −1 outside the
// domain: the face sits on the low side of the cell with its coordinates.
inline std::pair<int, int> faceCells(const Lattice& cells, const Vec3i& face, int axis) {
    Vec3i high = face;
    return {cells.neighbour(face, axis, -1), cells.resolve(high) ? cells.index(high[0], high[1], high[2]) : -1};
}

struct Grid {
    Vec3 origin{0, 0, 0};
    double dx = 1;
    Vec3i cells{1, 1, 1};
    std::array<bool, 3> periodic{false, false, false};

    Lattice lattice(const Stagger& s) const { return Lattice(cells, s, periodic); }
    // World position of sample (i,j,k) of a lattice with stagger s.
    Vec3 position(const Stagger& s, const Vec3i& c) const {
        return origin + dx * Vec3(c[0] + 0.5 * s[0], c[1] + 0.5 * s[1], c[2] + 0.5 * s[2]);
    }
    Vec3 extent() const { return dx * cells.cast<double>(); }
    // The shortest of the offsets that periodic images make of `offset`: a wrapped lattice index
    // across a periodic seam lies a whole period away from the sample it stands for.
    Vec3 nearestImage(Vec3 offset) const {
        const Vec3 period = extent();
        for (int a = 0; a < 3; ++a)
            if (periodic[a]) offset[a] -= period[a] * std::round(offset[a] / period[a]);
        return offset;
    }
};

// A scalar field on one lattice.
struct Field {
    Lattice lattice;
    std::vector<double> values;

    Field() = default;
    explicit Field(const Lattice& l, double fill = 0) : lattice(l), values(l.count(), fill) {}
    double& operator[](int i) { return values[i]; }
    double operator[](int i) const { return values[i]; }
};

// Trilinear interpolation weights of point x on lattice s: the lower corner and fractions.
inline void interpolationStencil(const Grid& g, const Stagger& s, const Vec3& x, Vec3i& base,
                                 Vec3& frac) {
    const Vec3 local = (x - g.origin) / g.dx;
    for (int a = 0; a < 3; ++a) {
        const double u = local[a] - 0.5 * s[a];
        const double f = std::floor(u);
        base[a] = static_cast<int>(f);
        frac[a] = u - f;
    }
}

// Calls visit(index, weight, weightGradient, beyond) for the 8 lattice samples around x, where
// `beyond` is null for a sample in the lattice and, for one beyond a non-periodic boundary, points
// to its lattice position (periodic axes wrapped). Such samples are clamped onto the boundary
// (constant extension): skipping them instead would leave weight gradients that do not sum to
// zero, and APIC would read that as a spurious affine velocity. Callers that need another value
// there (a wall's ghost) read it from `beyond`. Stencils wholly inside the lattice, nearly all of
// them, skip the clamping and wrapping.
template <class Visit>
void forEachStencilSampleBeyond(const Grid& g, const Lattice& l, const Vec3& x, Visit&& visit) {
    Vec3i base;
    Vec3 f;
    interpolationStencil(g, l.stagger, x, base, f);
    const bool inside = (base.array() >= 0).all() && (base.array() + 1 < l.size.array()).all();
    for (int dk = 0; dk < 2; ++dk)
        for (int dj = 0; dj < 2; ++dj)
            for (int di = 0; di < 2; ++di) {
                Vec3i position = base + Vec3i(di, dj, dk);
                Vec3i c = position;
                bool beyond = false;
                if (!inside) {
                    for (int a = 0; a < 3; ++a) {
                        if (l.periodic[a]) c[a] = position[a] = l.wrapped(c[a], a);
                        else c[a] = std::clamp(c[a], 0, l.size[a] - 1);
                    }
                    beyond = c != position;
                }
                const double wx = di ? f[0] : 1 - f[0], wy = dj ? f[1] : 1 - f[1],
                             wz = dk ? f[2] : 1 - f[2];
                const Vec3 grad = Vec3((di ? 1 : -1) * wy * wz, (dj ? 1 : -1) * wx * wz,
                                       (dk ? 1 : -1) * wx * wy) / g.dx;
                visit(l.index(c[0], c[1], c[2]), wx * wy * wz, grad, beyond ? &position : nullptr);
            }
}

// As above, for callers to whom a clamped sample is the boundary's own value.
template <class Visit>
void forEachStencilSample(const Grid& g, const Lattice& l, const Vec3& x, Visit&& visit) {
    forEachStencilSampleBeyond(g, l, x, [&](int i, double w, const Vec3& dw, const Vec3i*) { visit(i, w, dw); });
}

// A box of cells, inclusive at both ends: the cells that can hold liquid this step.
struct CellBox {
    Vec3i lo{0, 0, 0}, hi{0, 0, 0};
};

// The samples of a lattice within some margin of a CellBox (one more along a staggered axis).
// Outside the active box no control volume holds liquid, so per-step passes that only concern
// liquid stay in it instead of sweeping the whole domain.
struct SampleBox {
    Vec3i from, to;  // inclusive
    bool contains(const Vec3i& c) const { return (c.array() >= from.array()).all() && (c.array() <= to.array()).all(); }
};
inline SampleBox nearBox(const Lattice& lattice, const CellBox& cells, int margin) {
    return {(cells.lo - Vec3i::Constant(margin)).cwiseMax(0),
            (cells.hi + Vec3i::Constant(margin + 1)).cwiseMin(lattice.size - Vec3i::Ones())};
}
// Calls visit(index, coordinates) for those samples, k slowest.
template <class Visit>
void forEachNearBox(const Lattice& lattice, const CellBox& cells, int margin, Visit&& visit) {
    const SampleBox box = nearBox(lattice, cells, margin);
    for (int k = box.from[2]; k <= box.to[2]; ++k)
        for (int j = box.from[1]; j <= box.to[1]; ++j)
            for (int i = box.from[0]; i <= box.to[0]; ++i) visit(lattice.index(i, j, k), Vec3i(i, j, k));
}

inline double interpolate(const Grid& g, const Field& field, const Vec3& x) {
    double sum = 0;
    forEachStencilSample(g, field.lattice, x, [&](int i, double w, const Vec3&) { sum += w * field[i]; });
    return sum;
}

}  // namespace viscoscope::sim
