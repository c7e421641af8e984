"""The Lagrangian constraint solvers and the uncoupled correction of runtime/sofac/constraints.h,
tested as C++ on their own.

A shim (plain C wrappers, loaded with ctypes) runs BlockGaussSeidel, NNCG, UnbuiltGaussSeidel and
the LCP Gauss-Seidel on problems given from NumPy. Checked against: direct solves of W f = -dfree
(bilateral rows), an enumeration of active sets (unilateral rows), Coulomb's cone (friction),
SOFA's iteration counting and stopping tests, J C Jᵀ computed by NumPy (uncoupled compliance),
and two closed forms run as a whole free motion + solve + correction loop: a particle hanging on a
bilateral attachment is at rest with the multiplier m g, and a rigid pendulum held at its end by a
bilateral constraint keeps its length.
"""

from __future__ import annotations

import ctypes
import itertools

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i

SHIM = r"""
#include "sofac/constraints.h"
#include "sofac/kernels.h"
#include <vector>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

// The unbuilt solver's corrections, here a dense compliance: the forces handed over so far, and
// d += W_full F for the rows asked.
struct DenseCorrections {
    const double* W;
    Index n;
    std::vector<double> forces;
    void add_displacement(double* d, Index first, Index last) {
        for (Index i = first; i <= last; ++i)
            for (Index k = 0; k < n; ++k) d[i] += W[n * i + k] * forces[k];
    }
    void set_force_change(const double* df, Index first, Index last) {
        for (Index i = first; i <= last; ++i) forces[i] += df[i];
    }
};

// The blocks in row order; previous: 3 kept forces a block, or null.
std::vector<sofac::RowBlock> row_blocks(const int* kinds, const double* parameters, double* previous,
                                        Index blocks) {
    std::vector<sofac::RowBlock> rows(blocks);
    Index first = 0;
    for (Index k = 0; k < blocks; ++k) {
        rows[k].first = first;
        rows[k].kind = sofac::Resolution(kinds[k]);
        rows[k].parameter = parameters[k];
        rows[k].previous = previous ? previous + 3 * k : nullptr;
        first += sofac::resolution_lines(rows[k].kind);
    }
    return rows;
}

// LCPConstraintSolver's nlcp_gaussseidel with these settings, the others the defaults.
sofac::ConstraintResult lcp_solve(sofac::ConstraintProblem& p, Index max_iterations, double tolerance,
                                  double mu) {
    sofac::LcpSettings lcp;
    lcp.max_iterations = max_iterations;
    lcp.tolerance = tolerance;
    lcp.mu = mu;
    return sofac::lcp_gauss_seidel(p, lcp);
}

// method: 0 BGS, 1 NNCG, 2 UGS (W_block for the resolutions, W for the corrections), 3 LCP
API void solve(int method, Index n, const double* W, const double* W_block, const double* dfree,
               double* f, const int* kinds, const double* parameters, double* previous, Index blocks,
               Index max_iterations, double tolerance, double sor, int scale, int all_verified, double* out) {
    std::vector<double> w(W_block ? W_block : W, (W_block ? W_block : W) + n * n), d(n), scratch(3 * n + 1);
    std::vector<double> free(dfree, dfree + n);
    std::vector<sofac::RowBlock> rows = row_blocks(kinds, parameters, previous, blocks);
    sofac::ConstraintProblem p{n, w.data(), free.data(), f, d.data(), rows.data(), blocks, scratch.data()};
    const sofac::ConstraintSettings settings{max_iterations, tolerance, sor, scale != 0, all_verified != 0};
    sofac::ConstraintResult r;
    if (method == 0) r = sofac::block_gauss_seidel(p, settings);
    if (method == 1) r = sofac::nncg(p, settings);
    if (method == 2) {
        DenseCorrections corrections{W, n, std::vector<double>(n, 0.0)};
        r = sofac::unbuilt_gauss_seidel(p, settings, corrections);
    }
    if (method == 3) r = lcp_solve(p, max_iterations, tolerance, parameters[0]);
    out[0] = double(r.iterations);
    out[1] = double(r.sweeps);
    out[2] = r.error;
    out[3] = r.converged ? 1.0 : 0.0;
    out[4] = double(r.singular_blocks);
    out[5] = r.stalled ? 1.0 : 0.0;
}

// W = J C J^T factor for a state of `dofs` DOFs (Vec3d: comp per DOF; Rigid3d: the 7 numbers),
// J given dense (rows x dofs*deriv), stored as SOFA's sparse rows (zero blocks left out).
template <class DT>
void compliance(Index rows, Index dofs, const double* dense, const double* comp, Index comp_size,
                double comp0, double factor, double* W) {
    std::vector<Index> row_index(rows), start(rows + 1, 0), dof;
    std::vector<double> values;
    for (Index r = 0; r < rows; ++r) {
        row_index[r] = r;
        for (Index i = 0; i < dofs; ++i) {
            bool any = false;
            for (int c = 0; c < DT::deriv; ++c) any |= dense[(r * dofs + i) * DT::deriv + c] != 0.0;
            if (!any) continue;
            dof.push_back(i);
            for (int c = 0; c < DT::deriv; ++c) values.push_back(dense[(r * dofs + i) * DT::deriv + c]);
        }
        start[r + 1] = Index(dof.size());
    }
    const sofac::JacobianRows J{rows, row_index.data(), start.data(), dof.data(), values.data()};
    std::vector<double> scaled(comp_size + 1);
    sofac::CompliancePattern P;
    P.start(W, rows);
    sofac::uncoupled_add_compliance<DT>(P, W, J, dofs, comp0, comp, comp_size, factor, scaled.data());
}

API void compliance_vec3(Index rows, Index dofs, const double* J, const double* comp, Index comp_size,
                         double comp0, double factor, double* W) {
    compliance<sofac::Vec3d>(rows, dofs, J, comp, comp_size, comp0, factor, W);
}

API void compliance_rigid(Index rows, const double* J, const double* comp, double factor, double* W) {
    compliance<sofac::Rigid3d>(rows, 1, J, comp, 7, 0.0, factor, W);
}

// The solvers on one W read two ways: whole, and through a CompliancePattern holding W's non-zero
// entries (written with add(), as the corrections write them). W_dense: n x n; previous: kept
// forces (3 a block) or null. out: the reports (6 numbers each: whole, then sparse) and whether
// the sparse run had rows to read (W sparse enough).
API void whole_and_sparse(int method, Index n, const double* W_dense, const double* dfree, const int* kinds,
                          const double* parameters, const double* previous, Index blocks,
                          Index max_iterations,
                          double tolerance, double* f_whole, double* f_sparse, double* out) {
    for (int sparse = 0; sparse < 2; ++sparse) {
        std::vector<double> w(n * n, 1.0), d(n), scratch(3 * n + 1), free(dfree, dfree + n);
        std::vector<double> kept(previous ? previous : dfree, previous ? previous + 3 * blocks : dfree);
        sofac::CompliancePattern P;
        P.reset(n);
        P.start(w.data(), n);
        for (Index i = 0; i < n; ++i)
            for (Index j = 0; j < n; ++j)
                if (W_dense[n * i + j] != 0.0) P.add(w.data(), i, j, W_dense[n * i + j]);
        P.finish();
        double* kept_forces = previous ? kept.data() : nullptr;
        std::vector<sofac::RowBlock> rows = row_blocks(kinds, parameters, kept_forces, blocks);
        double* f = sparse ? f_sparse : f_whole;
        sofac::ConstraintProblem p{n, w.data(), free.data(), f, d.data(), rows.data(), blocks,
                                   scratch.data()};
        if (sparse) P.view(p);
        const sofac::ConstraintSettings settings{max_iterations, tolerance, 1.0, true, false};
        sofac::ConstraintResult r;
        if (method == 0) r = sofac::block_gauss_seidel(p, settings);
        if (method == 1) r = sofac::nncg(p, settings);
        if (method == 3) r = lcp_solve(p, max_iterations, tolerance, parameters[0]);
        double* o = out + 6 * sparse;
        o[0] = double(r.iterations), o[1] = double(r.sweeps), o[2] = r.error;
        o[3] = r.converged ? 1.0 : 0.0, o[4] = double(r.singular_blocks), o[5] = r.stalled ? 1.0 : 0.0;
        if (sparse) out[12] = p.columns != nullptr ? 1.0 : 0.0;
    }
}

// UncoupledConstraintCorrection's W as SOFA builds it: every pair of rows tried.
void all_pairs_compliance(double* W, Index n, const sofac::JacobianRows& J, double comp0, const double* comp,
                          Index comp_size) {
    using DT = sofac::Vec3d;
    for (Index r = 0; r < J.rows; ++r) {
        if (J.start[r] == J.start[r + 1]) continue;
        const Index row = J.row_index[r];
        double w = 0.0;
        for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
            w += sofac::uncoupled_pair<DT>(J.dof[e], J.values + 3 * e, J.values + 3 * e, comp0, comp,
                                           comp_size);
        W[n * row + row] += w;
        for (Index s = r + 1; s < J.rows; ++s) {
            const Index column = J.row_index[s];
            double v = 0.0;
            for (Index a = J.start[r]; a < J.start[r + 1]; ++a)
                for (Index b = J.start[s]; b < J.start[s + 1]; ++b)
                    if (J.dof[a] == J.dof[b])
                        v += sofac::uncoupled_pair<DT>(J.dof[a], J.values + 3 * a, J.values + 3 * b, comp0,
                                                       comp, comp_size);
            if (v != 0.0) {
                W[n * row + column] += v;
                W[n * column + row] += v;
            }
        }
    }
}

// `corrections` Vec3d corrections' J (rows ascending, a row index possibly repeated; DOFs ascending
// in a row) added into one W, both ways, factor 1: W_pairs by all pairs, W by the pattern's
// correction. Then the pattern's rows (start: n + 1, columns) and W after the next step's start().
API void compliance_both_ways(Index n, Index corrections, const Index* rows, const Index* row_index,
                              const Index* start, const Index* dof, const double* values, Index dofs,
                              const double* comp, double* W_pairs, double* W, Index* pattern_start,
                              Index* pattern_columns, double* W_next) {
    sofac::CompliancePattern P;
    P.reset(n);
    P.start(W, n);
    std::vector<double> scaled(dofs);
    Index row_offset = 0, entry_offset = 0;
    for (Index c = 0; c < corrections; ++c) {
        std::vector<Index> begin(start + row_offset + c, start + row_offset + c + rows[c] + 1);
        for (Index& b : begin) b -= begin[0];
        const sofac::JacobianRows J{rows[c], row_index + row_offset, begin.data(), dof + entry_offset,
                                    values + 3 * entry_offset};
        all_pairs_compliance(W_pairs, n, J, 0.0, comp, dofs);
        sofac::uncoupled_add_compliance<sofac::Vec3d>(P, W, J, dofs, 0.0, comp, dofs, 1.0, scaled.data());
        row_offset += rows[c];
        entry_offset += begin[rows[c]];
    }
    P.finish();
    sofac::ConstraintProblem p{n, W, nullptr, nullptr, nullptr, nullptr, 0, nullptr};
    P.view(p);
    for (Index i = 0; i <= n && p.row_start; ++i) pattern_start[i] = p.row_start[i];
    for (Index e = 0; p.row_start && e < p.row_start[n]; ++e) pattern_columns[e] = p.columns[e];
    std::copy(W, W + n * n, W_next);
    P.start(W_next, n);
}

// After reset() W's values are not known (a recompiled instance takes the old W over): a step of
// n1 rows, then one of n2 > n1 rows, each starting on a W holding stale values. first: W after
// the first start().
API void stale_entries_cleared(Index capacity, Index n1, Index n2, double* W, double* first) {
    sofac::CompliancePattern P;
    P.reset(capacity);
    P.start(W, n1);
    std::copy(W, W + n2 * n2, first);
    P.add(W, 0, 1, 5.0);
    P.start(W, n2);
}

// A particle of mass m at the anchor (object2 of a BilateralLagrangianConstraint whose object1
// is a fixed point there), implicit Euler free motion v_f = v + dt g, x_f = x + dt v_f, then BGS
// with W = dt/m I and the uncoupled correction. out: x, v after `steps` steps, then f of the last.
API void hanging(double mass, double g, double dt, Index steps, double* out) {
    double x[3] = {0, 0, 0}, v[3] = {0, 0, 0}, f[3] = {0, 0, 0}, kept[3] = {0, 0, 0};
    const double anchor[3] = {0, 0, 0};
    const double gravity[3] = {0, -g, 0};
    const Index row_index[3] = {0, 1, 2}, start[4] = {0, 1, 2, 3}, dof[3] = {0, 0, 0};
    const double values[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // +e_x, +e_y, +e_z on object2
    const sofac::JacobianRows J{3, row_index, start, dof, values};
    for (Index step = 0; step < steps; ++step) {
        double x_free[3], v_free[3], W[9] = {}, dfree[3], d[3], scratch[3], scaled[1], lambda[3] = {}, dx[3];
        for (int c = 0; c < 3; ++c) {
            v_free[c] = v[c] + dt * gravity[c];
            x_free[c] = x[c] + dt * v_free[c];
            dfree[c] = x_free[c] - anchor[c];
        }
        const double comp = 1.0 / mass;
        sofac::CompliancePattern P;
        P.start(W, 3);
        sofac::uncoupled_add_compliance<sofac::Vec3d>(P, W, J, 1, comp, &comp, 1, dt, scaled);
        sofac::RowBlock block;
        block.kind = sofac::Resolution::Bilateral3;
        block.previous = kept;
        sofac::ConstraintProblem p{3, W, dfree, f, d, &block, 1, scratch};
        sofac::block_gauss_seidel(p, sofac::ConstraintSettings{});
        sofac::add_jacobian_transpose<sofac::Vec3d>(lambda, J, f);
        sofac::uncoupled_dx<sofac::Vec3d>(dx, lambda, 1, comp, &comp, 1);
        sofac::apply_motion_correction<sofac::Vec3d>(x, x_free, v, v_free, dx, 1, dt, 1.0);
    }
    for (int c = 0; c < 3; ++c) out[c] = x[c], out[3 + c] = v[c], out[6 + c] = f[c];
}

// A rigid bar (mass m, inertia I about its centre, identity-like but anisotropic), its end at
// r_local from the centre held at the origin by a bilateral constraint (RigidMapping's J: v = f,
// w = (R r) x f), gravity on the centre, implicit Euler free motion without stiffness: v_f = v +
// dt g, w_f = w, x_f = x + dt v_f (SOFA's rigid exponential update). BGS on W = dt J C J^T, uncoupled
// correction. out[k]: the distance from the origin to the centre after step k.
API void pendulum(double dt, Index steps, const double* start_position, const double* r_local, double* out) {
    const double mass = 2.0, inertia[3] = {0.5, 0.25, 0.4};
    double x[7], v[6] = {0, 0, 0, 0, 0, 0}, f[3] = {0, 0, 0}, kept[3] = {0, 0, 0};
    for (int c = 0; c < 7; ++c) x[c] = start_position[c];
    // rigid compliance (SOFA's comp[0..6]: 1/m, then the inverse inertia's 00 01 02 11 12 22)
    const double comp[7] = {1.0 / mass, 1.0 / inertia[0], 0, 0, 1.0 / inertia[1], 0, 1.0 / inertia[2]};
    const Index row_index[3] = {0, 1, 2}, begin[4] = {0, 1, 2, 3}, dof[3] = {0, 0, 0};
    for (Index step = 0; step < steps; ++step) {
        const sofac::Quat q = sofac::orientation(x, 0);
        const sofac::Vec3 arm = q * sofac::Vec3(r_local[0], r_local[1], r_local[2]);
        double values[18];
        for (int k = 0; k < 3; ++k) {  // row k: the end point's +e_k through the rigid mapping
            sofac::Vec3 e = sofac::Vec3::Zero();
            e[k] = 1.0;
            const sofac::Vec3 torque = arm.cross(e);
            for (int c = 0; c < 3; ++c) values[6 * k + c] = e[c], values[6 * k + 3 + c] = torque[c];
        }
        const sofac::JacobianRows J{3, row_index, begin, dof, values};
        double x_free[7], v_free[6], W[9] = {}, dfree[3], d[3], scratch[3], scaled[7], lambda[6] = {}, dx[6];
        for (int c = 0; c < 6; ++c) v_free[c] = v[c] + (c == 1 ? -9.81 * dt : 0.0);
        sofac::advance<sofac::Rigid3d>(x_free, x, v_free, dt, 1);
        // violation: the end point's free position (linearised, as SOFA's mapped free positions)
        const sofac::Vec3 w_free(v_free[3], v_free[4], v_free[5]);
        const sofac::Vec3 end_velocity = sofac::Vec3(v_free[0], v_free[1], v_free[2]) + w_free.cross(arm);
        for (int c = 0; c < 3; ++c) dfree[c] = x[c] + arm[c] + dt * end_velocity[c];
        sofac::CompliancePattern P;
        P.start(W, 3);
        sofac::uncoupled_add_compliance<sofac::Rigid3d>(P, W, J, 1, 0.0, comp, 7, dt, scaled);
        sofac::RowBlock block;
        block.kind = sofac::Resolution::Bilateral3;
        block.previous = kept;
        sofac::ConstraintProblem p{3, W, dfree, f, d, &block, 1, scratch};
        sofac::block_gauss_seidel(p, sofac::ConstraintSettings{});
        sofac::add_jacobian_transpose<sofac::Rigid3d>(lambda, J, f);
        sofac::uncoupled_dx<sofac::Rigid3d>(dx, lambda, 1, 0.0, comp, 7);
        sofac::apply_motion_correction<sofac::Rigid3d>(x, x_free, v, v_free, dx, 1, dt, 1.0);
        out[step] = std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    }
}
"""

BGS, NNCG, UGS, LCP = 0, 1, 2, 3
BILATERAL3, BILATERAL1, UNILATERAL1, FRICTION3 = 0, 1, 2, 3
LINES = {BILATERAL3: 3, BILATERAL1: 1, UNILATERAL1: 1, FRICTION3: 3}


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "constraints", SHIM)
    i64, c_int = ctypes.c_int64, ctypes.c_int
    ints = ctypes.POINTER(ctypes.c_int)
    library.solve.argtypes = [c_int, i64, D, D, D, D, ints, D, D, i64, i64, ctypes.c_double, ctypes.c_double]
    library.solve.argtypes += [c_int, c_int, D]
    library.compliance_vec3.argtypes = [i64, i64, D, D, i64, ctypes.c_double, ctypes.c_double, D]
    library.compliance_rigid.argtypes = [i64, D, D, ctypes.c_double, D]
    library.hanging.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.c_double, i64, D]
    library.whole_and_sparse.argtypes = [c_int, i64, D, D, ints, D, D, i64, i64, ctypes.c_double, D, D, D]
    library.compliance_both_ways.argtypes = [i64, i64, I64, I64, I64, I64, D, i64, D, D, D, I64, I64, D]
    library.stale_entries_cleared.argtypes = [i64, i64, i64, D, D]
    library.pendulum.argtypes = [ctypes.c_double, i64, D, D, D]
    return library


def solve(
    lib: ctypes.CDLL,
    method: int,
    W: np.ndarray,
    dfree: np.ndarray,
    kinds: list[int],
    parameters: list[float] | None = None,
    *,
    max_iterations: int = 1000,
    tolerance: float = 1e-10,
    sor: float = 1.0,
    scale: bool = True,
    all_verified: bool = False,
    W_block: np.ndarray | None = None,
    previous: np.ndarray | None = None,
    f: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, float]]:
    n = len(dfree)
    assert sum(LINES[k] for k in kinds) == n or method == LCP
    W = np.ascontiguousarray(W, dtype=float)
    dfree = np.ascontiguousarray(dfree, dtype=float)
    f = np.zeros(n) if f is None else np.ascontiguousarray(f, dtype=float)
    kind_array = np.asarray(kinds, dtype=np.intc)
    params = np.asarray(parameters if parameters is not None else [1.0] * len(kinds), dtype=float)
    out = np.zeros(6)
    block = None if W_block is None else np.ascontiguousarray(W_block, dtype=float)
    lib.solve(
        method,
        n,
        _d(W),
        _d(block) if block is not None else None,
        _d(dfree),
        _d(f),
        kind_array.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
        _d(params),
        _d(previous) if previous is not None else None,
        len(kinds),
        max_iterations,
        tolerance,
        sor,
        int(scale),
        int(all_verified),
        _d(out),
    )
    names = ("iterations", "sweeps", "error", "converged", "singular", "stalled")
    report = dict(zip(names, out, strict=True))
    return f, report


def spd(n: int, seed: int, coupling: float = 0.3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    return np.eye(n) + coupling * (A @ A.T) / n


def test_one_bilateral_block_is_solved_exactly_then_stops_at_the_second_sweep(lib: ctypes.CDLL) -> None:
    W = spd(3, 1)
    dfree = np.array([0.3, -0.2, 0.1])
    f, report = solve(lib, BGS, W, dfree, [BILATERAL3])
    np.testing.assert_allclose(f, -np.linalg.solve(W, dfree), rtol=1e-13)
    # sweep 1 moves f (error |W f| > tol), sweep 2 changes nothing: SOFA counts sweeps + 1
    assert report["sweeps"] == 2 and report["iterations"] == 3 and report["converged"] == 1
    assert report["error"] < 1e-14  # rounding only


@pytest.mark.parametrize("method", [BGS, NNCG, UGS])
def test_coupled_bilateral_rows_converge_to_the_direct_solution(lib: ctypes.CDLL, method: int) -> None:
    W = spd(9, 2)
    dfree = np.random.default_rng(3).normal(size=9)
    blocks = np.zeros_like(W)
    for b in range(3):
        blocks[3 * b : 3 * b + 3, 3 * b : 3 * b + 3] = W[3 * b : 3 * b + 3, 3 * b : 3 * b + 3]
    f, report = solve(lib, method, W, dfree, [BILATERAL3] * 3, W_block=blocks if method == UGS else None)
    # NNCG may stop when the forces stop changing, which SOFA reports as not converged
    assert report["converged"] == 1 or (method == NNCG and report["stalled"] == 1)
    np.testing.assert_allclose(f, -np.linalg.solve(W, dfree), atol=1e-9)


def test_nncg_needs_fewer_sweeps_than_gauss_seidel_on_a_stiff_chain(lib: ctypes.CDLL) -> None:
    n = 12  # a chain of 1-row bilateral constraints: tridiagonal, badly conditioned
    W = 2.0 * np.eye(n) - 0.99 * (np.eye(n, k=1) + np.eye(n, k=-1))
    dfree = np.linspace(-1.0, 1.0, n)
    f_gs, gs = solve(lib, BGS, W, dfree, [BILATERAL1] * n, tolerance=1e-9)
    f_cg, cg = solve(lib, NNCG, W, dfree, [BILATERAL1] * n, tolerance=1e-9)
    exact = -np.linalg.solve(W, dfree)
    assert gs["converged"] == 1 and (cg["converged"] == 1 or cg["stalled"] == 1)
    assert cg["sweeps"] < gs["sweeps"] / 2
    np.testing.assert_allclose(f_cg, exact, atol=1e-5)
    np.testing.assert_allclose(f_gs, exact, atol=1e-5)


def lcp_by_enumeration(W: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The solution of f >= 0, W f + q >= 0, f.(W f + q) = 0 for a small SPD W."""
    n = len(q)
    for active in itertools.product([False, True], repeat=n):
        index = np.flatnonzero(active)
        f = np.zeros(n)
        if len(index):
            f[index] = -np.linalg.solve(W[np.ix_(index, index)], q[index])
        if (f >= -1e-12).all() and (W @ f + q >= -1e-12).all():
            return f
    raise AssertionError("no solution")


def test_unilateral_rows_solve_the_complementarity_problem(lib: ctypes.CDLL) -> None:
    W = spd(5, 4)
    dfree = np.array([-0.5, 0.2, -0.1, 0.4, -0.3])
    f, report = solve(lib, BGS, W, dfree, [UNILATERAL1] * 5, tolerance=1e-12)
    assert report["converged"] == 1
    np.testing.assert_allclose(f, lcp_by_enumeration(W, dfree), atol=1e-9)
    assert (f >= 0).all()


@pytest.mark.parametrize("method", [BGS, LCP])
def test_friction_forces_stay_in_coulombs_cone(lib: ctypes.CDLL, method: int) -> None:
    mu = 0.3
    W = spd(6, 5, coupling=0.1)
    # two contacts pressed in (negative normal gap) and pushed sideways hard: both slide
    dfree = np.array([-0.2, 0.5, -0.4, -0.1, -0.6, 0.2])
    kinds = [FRICTION3, FRICTION3] if method == BGS else [0]
    f, report = solve(lib, method, W, dfree, kinds, [mu, mu], tolerance=1e-12)
    assert report["converged"] == 1
    for c in range(2):
        normal, tangent = f[3 * c], f[3 * c + 1 : 3 * c + 3]
        assert normal > 0
        assert np.linalg.norm(tangent) <= mu * normal * (1 + 1e-12)
        np.testing.assert_allclose(np.linalg.norm(tangent), mu * normal, rtol=1e-9)  # sliding: on the cone
    d = W @ f + dfree
    np.testing.assert_allclose(d[[0, 3]], 0.0, atol=1e-9)  # in contact: no normal gap left


def test_a_sticking_contact_gets_the_exact_force(lib: ctypes.CDLL) -> None:
    W = np.diag([1.0, 2.0, 2.0])
    dfree = np.array([-0.5, 0.01, -0.02])  # a small slip: inside the cone
    f, report = solve(lib, LCP, W, dfree, [0], [0.8], tolerance=1e-14)
    np.testing.assert_allclose(f, -np.linalg.solve(W, dfree), rtol=1e-12)
    assert report["converged"] == 1


def test_redundant_bilateral_rows_converge_and_a_singular_block_is_reported(lib: ctypes.CDLL) -> None:
    # the same scalar constraint twice: W is rank 1, the pair still meets the violation
    W = np.array([[0.5, 0.5], [0.5, 0.5]])
    dfree = np.array([0.2, 0.2])
    f, report = solve(lib, BGS, W, dfree, [BILATERAL1, BILATERAL1], tolerance=1e-12)
    assert report["converged"] == 1 and np.isfinite(f).all()
    np.testing.assert_allclose(W @ f + dfree, 0.0, atol=1e-12)
    # one 3-row block with a repeated row: SOFA's inverse fails and stays zero, no NaN comes out
    J = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 0, 0]])
    f, report = solve(lib, BGS, J @ J.T, np.array([0.1, 0.2, 0.1]), [BILATERAL3])
    assert report["singular"] == 1 and np.isfinite(f).all()


def test_the_iteration_limit_is_reported_with_its_residual(lib: ctypes.CDLL) -> None:
    n = 12
    W = 2.0 * np.eye(n) - 0.99 * (np.eye(n, k=1) + np.eye(n, k=-1))
    dfree = np.linspace(-1.0, 1.0, n)
    _, report = solve(lib, BGS, W, dfree, [BILATERAL1] * n, max_iterations=5, tolerance=1e-9)
    assert report["converged"] == 0 and report["sweeps"] == 5 and report["iterations"] == 6
    assert report["error"] > 1e-9 * n  # the residual that missed the (row-scaled) tolerance


def test_the_tolerance_is_scaled_by_the_number_of_rows(lib: ctypes.CDLL) -> None:
    n = 12
    W = 2.0 * np.eye(n) - 0.99 * (np.eye(n, k=1) + np.eye(n, k=-1))
    dfree = np.linspace(-1.0, 1.0, n)
    _, scaled = solve(lib, BGS, W, dfree, [BILATERAL1] * n, tolerance=1e-4)
    _, plain = solve(lib, BGS, W, dfree, [BILATERAL1] * n, tolerance=1e-4, scale=False)
    assert scaled["error"] < 1e-4 * n and plain["error"] < 1e-4
    assert plain["sweeps"] > scaled["sweeps"]


def test_bilateral_forces_warm_start_from_the_last_solve(lib: ctypes.CDLL) -> None:
    W = spd(3, 6)
    dfree = np.array([0.1, 0.0, -0.1])
    previous = np.zeros(3)
    f, first = solve(lib, BGS, W, dfree, [BILATERAL3], previous=previous)
    np.testing.assert_array_equal(previous, f)  # stored
    _, second = solve(lib, BGS, W, dfree, [BILATERAL3], previous=previous)
    assert second["sweeps"] == 1 < first["sweeps"]  # started at the answer
    # the unbuilt solver erases the warm start: the same sweeps as from zero
    _, unbuilt = solve(lib, UGS, W, dfree, [BILATERAL3], W_block=W, previous=previous)
    assert unbuilt["sweeps"] == first["sweeps"]


def test_uncoupled_compliance_is_factor_j_c_jt(lib: ctypes.CDLL) -> None:
    rng = np.random.default_rng(7)
    rows, dofs = 5, 4
    J = rng.normal(size=(rows, dofs, 3))
    J[1, 2] = 0.0  # a zero block: left out of the sparse row
    J[3] = 0.0  # an empty row: no compliance
    comp = np.array([0.5, 2.0])  # DOFs 2 and 3 take the default
    W = np.zeros((rows, rows))
    lib.compliance_vec3(rows, dofs, _d(np.ascontiguousarray(J)), _d(comp), 2, 0.25, 0.01, _d(W))
    C = np.kron(np.diag([0.5, 2.0, 0.25, 0.25]), np.eye(3))
    flat = J.reshape(rows, -1)
    np.testing.assert_allclose(W, 0.01 * flat @ C @ flat.T, rtol=1e-13, atol=1e-17)
    rigid_J = np.ascontiguousarray(rng.normal(size=(3, 1, 6)))
    comp7 = np.array([0.5, 2.0, 0.1, 0.2, 3.0, 0.3, 4.0])
    W = np.zeros((3, 3))
    lib.compliance_rigid(3, _d(rigid_J), _d(comp7), 0.02, _d(W))
    inverse_inertia = np.array([[2.0, 0.1, 0.2], [0.1, 3.0, 0.3], [0.2, 0.3, 4.0]])
    C = np.block([[0.5 * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), inverse_inertia]])
    flat = rigid_J.reshape(3, 6)
    np.testing.assert_allclose(W, 0.02 * flat @ C @ flat.T, rtol=1e-13)


@pytest.mark.parametrize("mass", [0.1, 3.0])
def test_a_particle_on_a_bilateral_attachment_rests_with_multiplier_m_g(
    lib: ctypes.CDLL, mass: float
) -> None:
    g, dt = 9.81, 0.01
    out = np.zeros(9)
    lib.hanging(mass, g, dt, 50, _d(out))
    np.testing.assert_allclose(out[:3], 0.0, atol=1e-15)  # at the anchor
    np.testing.assert_allclose(out[3:6], 0.0, atol=1e-15)  # at rest
    # f is the impulse over the step: lambda = f / dt holds the weight up
    np.testing.assert_allclose(out[6:9] / dt, [0.0, mass * g, 0.0], rtol=1e-12, atol=1e-12)


def test_a_pendulum_held_by_a_bilateral_constraint_keeps_its_length(lib: ctypes.CDLL) -> None:
    # a bar of half-length 1 held at its end, started horizontal: it swings through the bottom
    start = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    r_local = np.array([-1.0, 0.0, 0.0])
    steps = 400
    out = np.zeros(steps)
    lib.pendulum(0.005, steps, _d(start), _d(r_local), _d(out))
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out, 1.0, atol=2e-3)  # the linearised correction drifts by O(dt^2 w^2)


# ---- W read through its written entries (CompliancePattern): the same numbers, bit for bit ----


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


def whole_and_sparse(
    lib: ctypes.CDLL,
    method: int,
    W: np.ndarray,
    dfree: np.ndarray,
    kinds: list[int],
    parameters: list[float],
    previous: np.ndarray | None = None,
    max_iterations: int = 1000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f and the reports of one solve read two ways: W whole, and W's written entries only."""
    n = len(dfree)
    W, dfree = np.ascontiguousarray(W, dtype=float), np.ascontiguousarray(dfree, dtype=float)
    kind_array = np.asarray(kinds, dtype=np.intc)
    params = np.asarray(parameters, dtype=float)
    f_whole, f_sparse, out = np.zeros(n), np.zeros(n), np.zeros(13)
    lib.whole_and_sparse(
        method,
        n,
        _d(W),
        _d(dfree),
        kind_array.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
        _d(params),
        _d(np.ascontiguousarray(previous, dtype=float)) if previous is not None else None,
        len(kinds),
        max_iterations,
        1e-12,
        _d(f_whole),
        _d(f_sparse),
        _d(out),
    )
    return f_whole, f_sparse, out


def contacts_on_particles(contacts: int, particles: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """W = J C Jᵀ of contacts of three rows, each on one particle (several share one, so W has
    coupled blocks and exact zeros), and violations pressing them in, some exactly -0."""
    rng = np.random.default_rng(seed)
    J = np.zeros((3 * contacts, 3 * particles))
    for c in range(contacts):
        p = rng.integers(particles)
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        t = np.cross(normal, [0.3, 1.0, 0.2])
        t /= np.linalg.norm(t)
        J[3 * c : 3 * c + 3, 3 * p : 3 * p + 3] = [normal, t, np.cross(normal, t)]
    C = np.kron(np.diag(rng.uniform(0.5, 2.0, particles)), np.eye(3))
    dfree = rng.normal(scale=0.1, size=3 * contacts)
    dfree[0::3] = -np.abs(dfree[0::3])
    dfree[[1, 5, 8]] = -0.0
    return J @ C @ J.T, dfree


@pytest.mark.parametrize("method", [BGS, NNCG, LCP])
def test_reading_only_the_written_entries_of_w_changes_no_bit(lib: ctypes.CDLL, method: int) -> None:
    W, dfree = contacts_on_particles(contacts=16, particles=12, seed=11)
    assert (W == 0).mean() > 0.75  # a sparse W
    kinds = [FRICTION3] * 16 if method != LCP else [0]
    f_whole, f_sparse, out = whole_and_sparse(lib, method, W, dfree, kinds, [0.5] * 16)
    assert out[12] == 1  # the sparse rows were read
    np.testing.assert_array_equal(_bits(f_sparse), _bits(f_whole))
    np.testing.assert_array_equal(out[6:12], out[:6])  # iterations, error, convergence
    assert (f_whole[0::3] >= 0).all() and f_whole[0::3].max() > 0  # contacts pushing


def test_a_w_more_than_a_quarter_written_is_read_whole(lib: ctypes.CDLL) -> None:
    # LinearSolverConstraintCorrection's W (A^-1 couples every row of its state): the pattern
    # stops noting entries and the solvers read W whole, the same bits
    W, dfree = spd(9, 5), np.array([-0.3, 0.1, 0.2, -0.1, 0.0, 0.4, -0.2, 0.3, -0.5])
    f_whole, f_sparse, out = whole_and_sparse(lib, BGS, W, dfree, [FRICTION3] * 3, [0.5] * 3)
    assert out[12] == 0 and out[3] == 1
    np.testing.assert_array_equal(_bits(f_sparse), _bits(f_whole))


def test_a_sum_starting_at_minus_zero_reads_every_column(lib: ctypes.CDLL) -> None:
    # row 0: dfree -0 and its own term -0 (f warm-started at -0): W f summed over every column adds
    # 0 * 1.33 = +0 and gives +0, so f[0] stays -0; over its written entries only, d would stay -0
    # and f[0] become +0. The sparse run reads row 0 whole.
    W = np.diag([2.0, 3.0, *[1.0] * 8])  # (ten rows: W sparse enough to be read so)
    previous = np.zeros(30)
    previous[[0, 3]] = -0.0, 1.0
    dfree = np.array([-0.0, -4.0, *[-1.0] * 8])
    f_whole, f_sparse, out = whole_and_sparse(lib, BGS, W, dfree, [BILATERAL1] * 10, [1.0] * 10, previous)
    assert out[12] == 1 and out[3] == 1
    assert f_whole[0] == 0 and np.signbit(f_whole[0])
    np.testing.assert_array_equal(_bits(f_sparse), _bits(f_whole))


@pytest.mark.parametrize("method", [BGS, LCP])
def test_a_non_finite_force_makes_the_sweeps_read_every_column(lib: ctypes.CDLL, method: int) -> None:
    # 0 * inf is NaN: an unwritten W entry facing an infinite force spreads NaN over the dense sum,
    # and the sparse sweeps read W whole once a force is not finite, the same NaN bits.
    if method == BGS:  # a warm start at inf in the second (uncoupled) block
        W, dfree, kinds = np.diag([2.0, 3.0, *[1.0] * 8]), np.array([0.5, *[1.0] * 9]), [BILATERAL1] * 10
        previous: np.ndarray | None = np.zeros(30)
        previous[3] = np.inf
    else:  # the first contact has no compliance: its force becomes infinite
        W = np.zeros((15, 15))  # (five contacts: W sparse enough to be read so)
        for c in range(1, 5):
            W[3 * c : 3 * c + 3, 3 * c : 3 * c + 3] = spd(3, 8 + c)
        dfree, kinds, previous = np.tile([-0.1, 0.1, 0.0], 5), [0], None
    f_whole, f_sparse, out = whole_and_sparse(lib, method, W, dfree, kinds, [0.5] * 10, previous, 5)
    assert out[12] == 1
    assert np.isnan(f_whole[0] if method == BGS else f_whole[3])
    np.testing.assert_array_equal(_bits(f_sparse), _bits(f_whole))
    np.testing.assert_array_equal(out[6:12], out[:6], strict=False)


def test_uncoupled_compliance_tries_only_rows_sharing_a_dof_and_clears_what_it_wrote(
    lib: ctypes.CDLL,
) -> None:
    # three corrections writing into one W, against SOFA's every-pair loop, bit for bit: rows on one
    # to three DOFs, DOFs shared by several rows, a row index repeated (a contact with both sides
    # on one body), an empty row, and two rows sharing a DOF with orthogonal directions (a zero sum:
    # not written)
    rng = np.random.default_rng(12)
    n, dofs = 18, 9
    jacobians = []
    for correction in range(3):
        rows = sorted(rng.choice(n, size=10, replace=False).tolist())
        rows.insert(3, rows[3])  # a repeated row index
        entries = []
        for k, _ in enumerate(rows):
            count = 0 if k == 5 else int(rng.integers(1, 4))
            entries.append(sorted(rng.choice(dofs, size=count, replace=False).tolist()))
        values = [[rng.normal(size=3) for _ in row] for row in entries]
        if correction == 0:  # rows 0 and 1 on DOF 8 only, orthogonal
            entries[0], entries[1] = [8], [8]
            values[0], values[1] = [np.array([1.0, 0, 0])], [np.array([0, 2.0, 0])]
        jacobians.append((rows, entries, values))
    row_counts = np.array([len(r) for r, _, _ in jacobians], dtype=np.int64)
    row_index = np.array([i for r, _, _ in jacobians for i in r], dtype=np.int64)
    starts = np.array(
        [s for _, e, _ in jacobians for s in np.concatenate([[0], np.cumsum([len(x) for x in e])])],
        dtype=np.int64,
    )
    dof = np.array([g for _, e, _ in jacobians for row in e for g in row], dtype=np.int64)
    values = np.ascontiguousarray([v for _, _, vs in jacobians for row in vs for v in row], dtype=float)
    comp = rng.uniform(0.5, 2.0, dofs)
    W_pairs, W, W_next = np.zeros((n, n)), np.full((n, n), 7.0), np.zeros((n, n))
    pattern_start, pattern_columns = np.zeros(n + 1, dtype=np.int64), np.zeros(n * n, dtype=np.int64)
    lib.compliance_both_ways(
        n,
        3,
        _i(row_counts),
        _i(row_index),
        _i(starts),
        _i(dof),
        _d(values),
        dofs,
        _d(comp),
        _d(W_pairs),
        _d(W),
        _i(pattern_start),
        _i(pattern_columns),
        _d(W_next),
    )
    np.testing.assert_array_equal(_bits(W), _bits(W_pairs))
    assert (W != 0).sum() > n and (W == 0).any()
    first_rows = jacobians[0][0]
    assert W_pairs[first_rows[0], first_rows[1]] == 0  # the orthogonal pair
    if pattern_start[n] > 0:  # the rows handed to the solvers: W's non-zeros, sorted, and the diagonal
        for i in range(n):
            columns = pattern_columns[pattern_start[i] : pattern_start[i + 1]]
            assert (np.diff(columns) > 0).all() and i in columns
            assert set(np.flatnonzero(W[i])) <= set(columns.tolist())
    # the next step's start() zeroes every entry written (+0, not a stale value)
    assert not _bits(W_next).any()


def test_a_step_with_more_rows_than_any_before_clears_the_new_entries(lib: ctypes.CDLL) -> None:
    W, first = np.full(25, 3.0), np.zeros(25)  # a recompiled instance takes the old W over
    lib.stale_entries_cleared(2, 3, 5, _d(W), _d(first))
    assert not _bits(first[:9]).any() and (first[9:] == 3.0).all()  # its 3 rows only
    assert not _bits(W).any()  # then the 5 rows: the written entry and the stale ones beyond
