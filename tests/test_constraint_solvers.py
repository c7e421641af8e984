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
from kernel_shim import D, build_shim
from kernel_shim import doubles as _d

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

// method: 0 BGS, 1 NNCG, 2 UGS (W_block for the resolutions, W for the corrections), 3 LCP
API void solve(int method, Index n, const double* W, const double* W_block, const double* dfree,
               double* f, const int* kinds, const double* parameters, double* previous, Index blocks,
               Index max_iterations, double tolerance, double sor, int scale, int all_verified, double* out) {
    std::vector<double> w(W_block ? W_block : W, (W_block ? W_block : W) + n * n), d(n), scratch(3 * n + 1);
    std::vector<double> free(dfree, dfree + n);
    std::vector<sofac::RowBlock> rows(blocks);
    Index first = 0;
    for (Index k = 0; k < blocks; ++k) {
        rows[k].first = first;
        rows[k].kind = sofac::Resolution(kinds[k]);
        rows[k].parameter = parameters[k];
        rows[k].previous = previous ? previous + 3 * k : nullptr;
        first += sofac::resolution_lines(rows[k].kind);
    }
    sofac::ConstraintProblem p{n, w.data(), free.data(), f, d.data(), rows.data(), blocks, scratch.data()};
    const sofac::ConstraintSettings settings{max_iterations, tolerance, sor, scale != 0, all_verified != 0};
    sofac::ConstraintResult r;
    if (method == 0) r = sofac::block_gauss_seidel(p, settings);
    if (method == 1) r = sofac::nncg(p, settings);
    if (method == 2) {
        DenseCorrections corrections{W, n, std::vector<double>(n, 0.0)};
        r = sofac::unbuilt_gauss_seidel(p, settings, corrections);
    }
    if (method == 3) {
        sofac::LcpSettings lcp;
        lcp.max_iterations = max_iterations;
        lcp.tolerance = tolerance;
        lcp.mu = parameters[0];
        r = sofac::lcp_gauss_seidel(p, lcp);
    }
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
    sofac::uncoupled_add_compliance<DT>(W, rows, J, comp0, comp, comp_size, factor, scaled.data());
}

API void compliance_vec3(Index rows, Index dofs, const double* J, const double* comp, Index comp_size,
                         double comp0, double factor, double* W) {
    compliance<sofac::Vec3d>(rows, dofs, J, comp, comp_size, comp0, factor, W);
}

API void compliance_rigid(Index rows, const double* J, const double* comp, double factor, double* W) {
    compliance<sofac::Rigid3d>(rows, 1, J, comp, 7, 0.0, factor, W);
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
        sofac::uncoupled_add_compliance<sofac::Vec3d>(W, 3, J, comp, &comp, 1, dt, scaled);
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
        sofac::uncoupled_add_compliance<sofac::Rigid3d>(W, 3, J, 0.0, comp, 7, dt, scaled);
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
