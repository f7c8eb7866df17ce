#include "sim/stokes_solver.h"

#include "scene/scene.h"

#include <Eigen/SparseCore>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <functional>

namespace viscoscope::sim {

namespace {

using Vec = Eigen::VectorXd;
using SparseRows = Eigen::SparseMatrix<double, Eigen::RowMajor>;

// One constraint row (a pressure or stress sample) as coefficients on face velocities.
struct Term {
    int axis, face;
    double coefficient;
};
struct Row {
    std::vector<Term> terms;
    double compliance;  // W_τ/(2η) for stress rows, 0 for pressure rows
    enum Kind { Pressure, Normal, Shear } kind;
    int component, sample;  // which stress component / lattice index the row's unknown lives at
};

// The rows of H = [−W_p B ; W_τ D] (B: divergence, D: symmetric velocity gradient) for the
// samples whose control volume holds liquid. Off-diagonal stress samples carry τ_ab and τ_ba
// at once, so their weight W_τ is twice the edge fraction.
std::vector<Row> constraintRows(const StokesProblem& p, bool pressure, bool stress) {
    const Grid& g = *p.grid;
    const VolumeFractions& w = *p.weights;
    const Lattice cells = g.lattice(kCellCentre);
    std::array<Lattice, 3> faces;
    for (int a = 0; a < 3; ++a) faces[a] = g.lattice(kFace[a]);
    const double invDx = 1.0 / g.dx;
    std::vector<Row> rows;

    // Solid faces (and faces beyond the domain) hold the solid's zero velocity: they add nothing
    // to the divergence, so pressure rows leave them out; a row left with no face constrains nothing.
    auto faceAt = [&](int axis, Vec3i c) {
        if (!faces[axis].resolve(c)) return -1;
        const int f = faces[axis].index(c[0], c[1], c[2]);
        return w.solidFace[axis][f] ? -1 : f;
    };
    auto add = [&](Row& row, int axis, int face, double coefficient) {
        if (face >= 0) row.terms.push_back({axis, face, coefficient});
    };
    auto keep = [&](Row&& row) {
        if (!row.terms.empty()) rows.push_back(std::move(row));
    };
    // A velocity difference k (u(hi) − u(lo)) in a stress row. Where one of the two faces is solid,
    // its velocity is the wall's ghost value (wallGhostRatio), which keeps cut-cell walls
    // consistent with the cut-cell weights. The wall sits where the two faces' signed distances
    // put it by linear interpolation. In a plate under two cells thick a ghost's nearest surface
    // can be the plate's far face, which puts the wall too far out, and a film on a thin plate then
    // runs fast by where the plate sits among the faces. Placing the wall where the segment between
    // the two faces enters the solid (regula falsi on the distance) mended the film but made the
    // sample cup's drain agree less across grids, as did taking the nearer of the two wall
    // positions; neither was kept (tests/bench/FINDINGS.md, "The Stokes solve's walls").
    auto addDifference = [&](Row& row, int axis, const Vec3i& lo, const Vec3i& hi, double k, double slip) {
        const int fLo = faceAt(axis, lo), fHi = faceAt(axis, hi);
        if (fLo >= 0 && fHi >= 0) {
            add(row, axis, fHi, k);
            add(row, axis, fLo, -k);
            return;
        }
        if (fLo < 0 && fHi < 0) return;
        const Vec3i& fluid = fLo >= 0 ? lo : hi;
        const Vec3i& ghost = fLo >= 0 ? hi : lo;
        const double dFluid = std::max(p.solidDistance(g.position(kFace[axis], fluid)), 0.1 * g.dx);
        const double ratio =
            wallGhostRatio(dFluid, p.solidDistance(g.position(kFace[axis], ghost)), slip, g.dx);
        // With slip the wall itself dissipates, (η/λ) u_wall² per area. The edge's control volume
        // only covers the liquid side (w ≈ d_fluid/Δx), which leaves the ghost difference that
        // energy short by d_fluid/(d_fluid + λ); scaling the term by √(1 + λ/d_fluid) restores the
        // exact dissipation of the linear slip profile (no change when λ = 0).
        const double coefficient = k * (1 - ratio) * std::sqrt(1 + slip / dFluid);
        if (fHi >= 0) add(row, axis, fHi, coefficient);
        else add(row, axis, fLo, -coefficient);
    };

    for (int c = 0; c < cells.count(); ++c) {
        const double wc = w.cell[c];
        if (wc < kMinWeight) continue;
        const Vec3i ijk = cells.coords(c);
        if (pressure) {
            Row row{{}, 0.0, Row::Pressure, 0, c};
            for (int a = 0; a < 3; ++a) {
                const int low = faceAt(a, ijk), high = faceAt(a, ijk + Vec3i::Unit(a));
                if (low >= 0) add(row, a, low, wc * w.faceOpenArea[a][low] * invDx);
                if (high >= 0) add(row, a, high, -wc * w.faceOpenArea[a][high] * invDx);
            }
            keep(std::move(row));
        }
        if (stress)
            for (int a = 0; a < 3; ++a) {  // walls never slip in the normal direction
                Row row{{}, wc / (2 * (*p.cellViscosity)[c]), Row::Normal, a, c};
                addDifference(row, a, ijk, ijk + Vec3i::Unit(a), wc * invDx, 0.0);
                keep(std::move(row));
            }
    }
    if (stress)
        for (int e = 0; e < 3; ++e) {  // edges parallel to axis e carry τ_ab, {a, b, e} = {0, 1, 2}
            const int a = (e + 1) % 3, b = (e + 2) % 3;
            const Field& we = w.edge[e];
            for (int s = 0; s < we.lattice.count(); ++s) {
                if (we[s] < kMinWeight) continue;
                const Vec3i ijk = we.lattice.coords(s);
                const double k = we[s] * invDx;
                Row row{{}, we[s] / (*p.edgeViscosity)[e][s], Row::Shear, e, s};
                addDifference(row, a, ijk - Vec3i::Unit(b), ijk, k, p.slipLength);
                addDifference(row, b, ijk - Vec3i::Unit(a), ijk, k, p.slipLength);
                keep(std::move(row));
            }
        }
    return rows;
}

// The face velocities the rows touch: the velocity unknowns of the step.
struct FaceUnknowns {
    std::array<std::vector<int>, 3> dofOfFace;
    std::vector<std::pair<int, int>> faceOfDof;
    Vec mass;         // ρ W_u
    Vec inverseMass;  // of M + Δt B when the drag is included, else of M
};

// The drag β (kg/(m³ s)) on face f along `axis`.
double faceDrag(const StokesProblem& p, int axis, int f) {
    const Field& resistance = p.weights->faceResistance[axis];
    if (resistance.values.empty() || resistance[f] == 0) return 0;
    const Field& eta = *p.cellViscosity;
    const auto [lo, hi] = faceCells(eta.lattice, resistance.lattice.coords(f), axis);
    const double viscosity = lo >= 0 && hi >= 0 ? 0.5 * (eta[lo] + eta[hi]) : eta[lo >= 0 ? lo : hi];
    return viscosity * resistance[f];
}

FaceUnknowns faceUnknowns(const StokesProblem& p, const std::vector<Row>& rows, bool withDrag) {
    FaceUnknowns u;
    for (int a = 0; a < 3; ++a) u.dofOfFace[a].assign(p.weights->face[a].values.size(), -1);
    for (const Row& row : rows)
        for (const Term& t : row.terms)
            if (u.dofOfFace[t.axis][t.face] < 0) {
                u.dofOfFace[t.axis][t.face] = static_cast<int>(u.faceOfDof.size());
                u.faceOfDof.emplace_back(t.axis, t.face);
            }
    u.mass.resize(u.faceOfDof.size());
    u.inverseMass.resize(u.faceOfDof.size());
    for (size_t d = 0; d < u.faceOfDof.size(); ++d) {
        const auto [a, f] = u.faceOfDof[d];
        u.mass[d] = p.density * std::max(p.weights->face[a][f], kMinMassFraction);
        u.inverseMass[d] = 1.0 / (u.mass[d] + (withDrag ? p.dt * faceDrag(p, a, f) : 0.0));
    }
    return u;
}

SparseRows assemble(const std::vector<Row>& rows, const FaceUnknowns& u) {
    std::vector<Eigen::Triplet<double>> triplets;
    for (size_t r = 0; r < rows.size(); ++r)
        for (const Term& t : rows[r].terms)
            triplets.emplace_back(static_cast<int>(r), u.dofOfFace[t.axis][t.face], t.coefficient);
    SparseRows h(static_cast<int>(rows.size()), static_cast<int>(u.faceOfDof.size()));
    h.setFromTriplets(triplets.begin(), triplets.end());
    return h;
}

// y = A x for a row-major sparse A, rows split over TBB threads.
void multiply(const SparseRows& a, const Vec& x, Vec& y) {
    y.resize(a.rows());
    tbb::parallel_for(tbb::blocked_range<int>(0, static_cast<int>(a.rows()), 2048),
                      [&](const tbb::blocked_range<int>& range) {
                          for (int r = range.begin(); r != range.end(); ++r) {
                              double sum = 0;
                              for (SparseRows::InnerIterator it(a, r); it; ++it)
                                  sum += it.value() * x[it.col()];
                              y[r] = sum;
                          }
                      });
}

// The deterministic reduce splits the range the same way at any thread count and on every run, so
// the sums, and the simulation, do not depend on how the work was scheduled: with parallel_reduce
// two runs of one simulation drifted apart within a frame (tests/bench/FINDINGS.md, "Small costs and
// a scheduling fault").
double dot(const Vec& a, const Vec& b) {
    return tbb::parallel_deterministic_reduce(
        tbb::blocked_range<Eigen::Index>(0, a.size(), 8192), 0.0,
        [&](const tbb::blocked_range<Eigen::Index>& r, double sum) {
            return sum + a.segment(r.begin(), r.size()).dot(b.segment(r.begin(), r.size()));
        },
        std::plus<double>());
}

struct CgResult {
    int iterations = 0;
    double residual = 0;
    bool converged = false;
};

// Jacobi-preconditioned conjugate gradient on a matrix-free SPD operator, from the guess in x.
// Written here rather than Eigen::ConjugateGradient because the operator is a product of three
// factors that is never assembled, and Eigen's matrix-free path needs a wrapper longer than this loop.
// Jacobi because it won: on the sample cup's time steps incomplete Cholesky and hypre's BoomerAMG
// took fewer iterations but longer in all (tests/bench/FINDINGS.md, "Preconditioners for the
// unified solve").
CgResult conjugateGradient(const std::function<void(const Vec&, Vec&)>& apply, const Vec& diagonal,
                           const Vec& b, Vec& x, double tolerance, int maxIterations) {
    CgResult result;
    const double bNorm = std::sqrt(dot(b, b));
    if (bNorm == 0) {
        x.setZero();
        result.converged = true;
        return result;
    }
    const Vec inverseDiagonal = diagonal.cwiseInverse();
    Vec r(b.size()), ap(b.size());
    apply(x, ap);
    r = b - ap;
    Vec z = inverseDiagonal.cwiseProduct(r);
    Vec p = z;
    double rz = dot(r, z);
    for (; result.iterations < maxIterations; ++result.iterations) {
        throwIfCancelled("the pressure–viscosity solve");  // a large solve runs for seconds
        result.residual = std::sqrt(dot(r, r)) / bNorm;
        if (result.residual <= tolerance) break;
        apply(p, ap);
        const double alpha = rz / dot(p, ap);
        x += alpha * p;
        r -= alpha * ap;
        z = inverseDiagonal.cwiseProduct(r);
        const double rzNext = dot(r, z);
        p = z + (rzNext / rz) * p;
        rz = rzNext;
    }
    result.residual = std::sqrt(dot(r, r)) / bNorm;
    result.converged = result.residual <= tolerance && std::isfinite(result.residual);
    return result;
}

// The pressure rows whose liquid can change its volume: those joined, through faces two pressure
// rows share, to a face only one of them holds (a face onto air). Liquid that fills a sealed region
// (a closed box, a periodic pipe) cannot: the vector x_c = 1/W_c is then in the system's null space
// (Hᵀx is the plain divergence summed over the region, whose flux cancels), so a divergence target
// there is inconsistent and CG diverges, and a full periodic pipe lost its liquid (tests/bench/
// FINDINGS.md, "Figures moved from test comments").
std::vector<char> rowsThatCanChangeVolume(const std::vector<Row>& rows, const FaceUnknowns& u) {
    std::vector<int> parent(rows.size());
    for (size_t r = 0; r < rows.size(); ++r) parent[r] = static_cast<int>(r);
    auto root = [&](int r) {
        while (parent[r] != r) r = parent[r] = parent[parent[r]];
        return r;
    };
    std::vector<int> firstRow(u.faceOfDof.size(), -1);
    std::vector<char> shared(u.faceOfDof.size(), 0);
    for (size_t r = 0; r < rows.size(); ++r) {
        if (rows[r].kind != Row::Pressure) continue;
        for (const Term& t : rows[r].terms) {
            const int d = u.dofOfFace[t.axis][t.face];
            if (firstRow[d] < 0) {
                firstRow[d] = static_cast<int>(r);
            } else {
                parent[root(static_cast<int>(r))] = root(firstRow[d]);
                shared[d] = 1;
            }
        }
    }
    std::vector<char> open(rows.size(), 0);
    for (size_t d = 0; d < firstRow.size(); ++d)
        if (firstRow[d] >= 0 && !shared[d]) open[root(firstRow[d])] = 1;
    for (size_t r = 0; r < rows.size(); ++r) open[r] = rows[r].kind == Row::Pressure && open[root(static_cast<int>(r))];
    return open;
}

Vec gatherVelocity(const StokesState& s, const FaceUnknowns& u) {
    Vec v(u.faceOfDof.size());
    for (size_t d = 0; d < u.faceOfDof.size(); ++d) v[d] = s.velocity[u.faceOfDof[d].first][u.faceOfDof[d].second];
    return v;
}

void scatterVelocity(const Vec& v, const FaceUnknowns& u, StokesState& s) {
    for (size_t d = 0; d < u.faceOfDof.size(); ++d) s.velocity[u.faceOfDof[d].first][u.faceOfDof[d].second] = v[d];
}

Field& unknownField(StokesState& s, const Row& row) {
    switch (row.kind) {
        case Row::Pressure: return s.pressure;
        case Row::Normal: return s.normalStress[row.component];
        case Row::Shear: break;
    }
    return s.shearStress[row.component];
}

// Eliminated-velocity system [Δt H M̃⁻¹ Hᵀ + diag(compliance)] x = H ũ, then u = ũ − Δt M̃⁻¹ Hᵀ x,
// with M̃ = M + Δt B and ũ = M̃⁻¹ M u*: the drag slows the faces it acts on implicitly, and the system
// stays SPD. With pressure rows only, this is the classic variational pressure projection.
CgResult solveEliminated(const StokesProblem& p, StokesState& s, const std::vector<Row>& rows) {
    const FaceUnknowns u = faceUnknowns(p, rows, true);
    const SparseRows h = assemble(rows, u);
    const SparseRows ht = h.transpose();
    Vec compliance(rows.size()), x(rows.size());
    for (size_t r = 0; r < rows.size(); ++r) {
        compliance[r] = rows[r].compliance;
        x[r] = unknownField(s, rows[r])[rows[r].sample];  // warm start from the previous step
    }
    const Vec uTilde = gatherVelocity(s, u).cwiseProduct(u.mass).cwiseProduct(u.inverseMass);
    Vec b;
    multiply(h, uTilde, b);
    // Pressure rows are −W_p ∇·u; aiming at ∇·u = d moves W_p d to the right-hand side.
    if (p.divergence != 0) {
        const std::vector<char> open = rowsThatCanChangeVolume(rows, u);
        for (size_t r = 0; r < rows.size(); ++r)
            if (open[r]) b[r] += p.weights->cell[rows[r].sample] * p.divergence;
    }

    Vec diagonal = compliance;
    for (int r = 0; r < h.outerSize(); ++r)
        for (SparseRows::InnerIterator it(h, r); it; ++it)
            diagonal[r] += p.dt * it.value() * it.value() * u.inverseMass[it.col()];

    Vec faceForce;
    auto apply = [&](const Vec& in, Vec& out) {
        multiply(ht, in, faceForce);
        faceForce = (p.dt * u.inverseMass).cwiseProduct(faceForce);
        multiply(h, faceForce, out);
        out += compliance.cwiseProduct(in);
    };
    const CgResult cg = conjugateGradient(apply, diagonal, b, x, p.tolerance, p.maxIterations);

    multiply(ht, x, faceForce);
    scatterVelocity(uTilde - p.dt * u.inverseMass.cwiseProduct(faceForce), u, s);
    for (size_t r = 0; r < rows.size(); ++r) unknownField(s, rows[r])[rows[r].sample] = x[r];
    return cg;
}

// Implicit viscosity alone, in velocity unknowns: [M + Δt H_τᵀ diag(1/compliance) H_τ] u = M u*.
CgResult solveViscosity(const StokesProblem& p, StokesState& s, const std::vector<Row>& rows) {
    const FaceUnknowns u = faceUnknowns(p, rows, false);
    const SparseRows h = assemble(rows, u);
    const SparseRows ht = h.transpose();
    Vec stiffness(rows.size());
    for (size_t r = 0; r < rows.size(); ++r) stiffness[r] = p.dt / rows[r].compliance;
    const Vec& mass = u.mass;
    Vec x = gatherVelocity(s, u);
    const Vec b = mass.cwiseProduct(x);

    Vec diagonal = mass;
    for (int r = 0; r < h.outerSize(); ++r)
        for (SparseRows::InnerIterator it(h, r); it; ++it)
            diagonal[it.col()] += stiffness[r] * it.value() * it.value();

    Vec strain;
    auto apply = [&](const Vec& in, Vec& out) {
        multiply(h, in, strain);
        strain = stiffness.cwiseProduct(strain);
        multiply(ht, strain, out);
        out += mass.cwiseProduct(in);
    };
    const CgResult cg = conjugateGradient(apply, diagonal, b, x, p.tolerance, p.maxIterations);
    scatterVelocity(x, u, s);
    return cg;
}

void accumulate(SolveStats& stats, const CgResult& cg, size_t unknowns) {
    stats.iterations += cg.iterations;
    stats.residual = std::max(stats.residual, cg.residual);
    stats.unknowns = std::max(stats.unknowns, static_cast<int>(unknowns));
    stats.converged = stats.converged && cg.converged;
}

}  // namespace

ShearRates shearRates(const StokesProblem& p, const std::array<Field, 3>& velocity) {
    const Grid& g = *p.grid;
    const VolumeFractions& w = *p.weights;
    const Lattice cells = g.lattice(kCellCentre);
    // Each stress row is W (Δx⁻¹ differences): dividing by its weight leaves D_aa (normal rows)
    // or du_a/dx_b + du_b/dx_a = 2 D_ab (shear rows).
    std::array<Field, 3> normal{Field(cells), Field(cells), Field(cells)};
    std::array<Field, 3> shear;
    std::array<std::vector<char>, 3> hasShear;
    for (int e = 0; e < 3; ++e) {
        shear[e] = Field(w.edge[e].lattice);
        hasShear[e].assign(w.edge[e].values.size(), 0);
    }
    for (const Row& row : constraintRows(p, false, true)) {
        double sum = 0;
        for (const Term& t : row.terms) sum += t.coefficient * velocity[t.axis][t.face];
        if (row.kind == Row::Normal) {
            normal[row.component][row.sample] = sum / w.cell[row.sample];
        } else {
            shear[row.component][row.sample] = 0.5 * sum / w.edge[row.component][row.sample];
            hasShear[row.component][row.sample] = 1;
        }
    }
    // At the cells: Σ D_aa² and each D_ab² from the mean over the cell's four edges.
    ShearRates rates{Field(cells), {}};
    Field normalSquares(cells);
    std::array<Field, 3> cellShearSquares{Field(cells), Field(cells), Field(cells)};
    for (int c = 0; c < cells.count(); ++c) {
        if (w.cell[c] < kMinWeight) continue;
        const Vec3i ijk = cells.coords(c);
        for (int a = 0; a < 3; ++a) normalSquares[c] += normal[a][c] * normal[a][c];
        double dd = normalSquares[c];  // D:D
        for (int e = 0; e < 3; ++e) {
            const int a = (e + 1) % 3, b = (e + 2) % 3;
            double sum = 0;
            int count = 0;
            for (int da = 0; da <= 1; ++da)
                for (int db = 0; db <= 1; ++db) {
                    Vec3i s = ijk + da * Vec3i::Unit(a) + db * Vec3i::Unit(b);
                    if (!shear[e].lattice.resolve(s)) continue;
                    const int idx = shear[e].lattice.index(s[0], s[1], s[2]);
                    if (!hasShear[e][idx]) continue;
                    sum += shear[e][idx];
                    ++count;
                }
            if (count) cellShearSquares[e][c] = std::pow(sum / count, 2);
            dd += 2 * cellShearSquares[e][c];
        }
        rates.cell[c] = std::sqrt(2 * dd);
    }
    // At the edges: the edge's own D_ab², the rest from the mean over the liquid cells around it.
    for (int e = 0; e < 3; ++e) {
        const Lattice& edges = shear[e].lattice;
        rates.edge[e] = Field(edges);
        const int a = (e + 1) % 3, b = (e + 2) % 3;
        for (int s = 0; s < edges.count(); ++s) {
            if (!hasShear[e][s]) continue;
            const Vec3i ijk = edges.coords(s);
            double others = 0;
            int count = 0;
            for (int da = -1; da <= 0; ++da)
                for (int db = -1; db <= 0; ++db) {
                    Vec3i c = ijk + da * Vec3i::Unit(a) + db * Vec3i::Unit(b);
                    if (!cells.resolve(c)) continue;
                    const int idx = cells.index(c[0], c[1], c[2]);
                    if (w.cell[idx] < kMinWeight) continue;
                    others += normalSquares[idx] + 2 * (cellShearSquares[a][idx] + cellShearSquares[b][idx]);
                    ++count;
                }
            const double dd = 2 * shear[e][s] * shear[e][s] + (count ? others / count : 0);
            rates.edge[e][s] = std::sqrt(2 * dd);
        }
    }
    return rates;
}

SolveStats StokesSolver::solve(const StokesProblem& problem, StokesState& state) {
    SolveStats stats;
    const std::vector<Row> rows = constraintRows(problem, true, true);
    accumulate(stats, solveEliminated(problem, state, rows), rows.size());
    return stats;
}

SolveStats DecoupledViscositySolver::solve(const StokesProblem& problem, StokesState& state) {
    SolveStats stats;
    const std::vector<Row> stressRows = constraintRows(problem, false, true);
    accumulate(stats, solveViscosity(problem, state, stressRows), stressRows.size());
    const std::vector<Row> pressureRows = constraintRows(problem, true, false);
    accumulate(stats, solveEliminated(problem, state, pressureRows), pressureRows.size());
    return stats;
}

std::unique_ptr<PressureViscositySolver> makeSolver(bool unified) {
    if (unified) return std::make_unique<StokesSolver>();
    return std::make_unique<DecoupledViscositySolver>();
}

}  // namespace viscoscope::sim
