"""runtime/sofac/direct.h's DirectSolver against dense NumPy solves.

The assembled pattern leaves out the couplings of the projected DOFs (their contributions go to
the DOF's diagonal, which the projection overwrites), and each factorisation (L D L^T, CHOLMOD's
simplicial kernel; L L^T, sofac's supernodal kernel when CHOLMOD's analysis makes a supernodal
factor, else CHOLMOD's simplicial one)
must solve the projected system: rows and columns of the fixed DOFs cleared, diagonal 1. Two
factorisations in a row with other values check that the permuted matrix and the factor are
refilled, not reused stale.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i

SHIM = r"""
#include "sofac/direct.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

// A solver on the pattern of the entries (rows[k], cols[k]), DOFs with fixed[i] != 0 projected.
static void record_pattern(sofac::DirectSolver& D, Index n, const Index* rows, const Index* cols, Index count,
                           const Index* fixed) {
    D.resize(n);
    for (Index i = 0; i < n; ++i) D.fixed[i] = fixed[i] != 0;
    D.assembler.start_pattern();
    for (Index k = 0; k < count; ++k) D.assembler.add(rows[k], cols[k], 0.0);
    D.assembler.finish_pattern(D.matrix, n, D.fixed);
}

// Entries (rows[k], cols[k]) of an n x n matrix with values values[pass * count + k], two passes
// (two factorisations); fixed[i] != 0 projects DOF i. Out: each pass's solution of A x = b, and
// info = {stored entries, off-diagonal entries in fixed rows or columns, supernodal, ok}.
API void solve(Index n, const Index* rows, const Index* cols, const double* values, Index count,
               const Index* fixed, int llt, const double* b, double* x, Index* info) {
    sofac::DirectSolver D;
    record_pattern(D, n, rows, cols, count, fixed);
    D.analyze(llt ? sofac::Factorization::LLT : sofac::Factorization::LDLT);
    info[3] = 1;
    for (int pass = 0; pass < 2; ++pass) {
        D.assembler.start_values(D.matrix);
        for (Index k = 0; k < count; ++k) D.assembler.add(rows[k], cols[k], values[pass * count + k]);
        D.factor();
        for (Index i = 0; i < n; ++i) D.rhs[i] = b[pass * n + i];
        D.solve();
        for (Index i = 0; i < n; ++i) x[pass * n + i] = D.solution[i];
        info[3] = info[3] && D.ok;
    }
    info[0] = D.matrix.nonZeros();
    info[1] = 0;
    for (int c = 0; c < D.matrix.outerSize(); ++c)
        for (Eigen::SparseMatrix<double>::InnerIterator it(D.matrix, c); it; ++it)
            if (it.row() != it.col() && (D.fixed[it.row()] || D.fixed[it.col()])) ++info[1];
    info[2] = D.factorization.factor()->is_super;
}

// The same kind of input, one factorisation; `columns` right-hand sides b (n each) solved
// DirectSolver::kSolveColumns at a time by solve_columns (the last batch padded with zeros) into
// x_columns, and one at a time by solve() into x_single. info = {can_solve_columns, kSolveColumns}.
API void solve_in_columns(Index n, const Index* rows, const Index* cols, const double* values, Index count,
                          const Index* fixed, int llt, const double* b, Index columns, double* x_columns,
                          double* x_single, Index* info) {
    sofac::DirectSolver D;
    record_pattern(D, n, rows, cols, count, fixed);
    D.analyze(llt ? sofac::Factorization::LLT : sofac::Factorization::LDLT);
    D.assembler.start_values(D.matrix);
    for (Index k = 0; k < count; ++k) D.assembler.add(rows[k], cols[k], values[k]);
    D.factor();
    constexpr int C = sofac::DirectSolver::kSolveColumns;
    info[0] = D.can_solve_columns();
    info[1] = C;
    for (Index first = 0; info[0] && first < columns; first += C) {
        for (int c = 0; c < C; ++c)
            for (Index i = 0; i < n; ++i)
                D.rhs_columns(i, c) = first + c < columns ? b[(first + c) * n + i] : 0.0;
        D.solve_columns();
        for (int c = 0; c < C && first + c < columns; ++c)
            for (Index i = 0; i < n; ++i) x_columns[(first + c) * n + i] = D.column_solution(c)[i];
    }
    for (Index k = 0; k < columns; ++k) {
        for (Index i = 0; i < n; ++i) D.rhs[i] = b[k * n + i];
        D.solve();
        for (Index i = 0; i < n; ++i) x_single[k * n + i] = D.solution[i];
    }
}

// The same kind of input, L L^T, one pass per set of values: sofac's supernodal factor (L->x)
// against cholmod_super_numeric's on the same symbolic factor, and sofac's solve. Out per pass:
// {max |L_sofac - L_cholmod|, max |L_cholmod|, ||A x - b|| / (||A||_F ||x|| + ||b||)}; info =
// {supernodal, supernodes, flops, then per pass: ok, L->minor (sofac), L->minor (CHOLMOD)}.
API void compare_supernodal(Index n, const Index* rows, const Index* cols, const double* values, Index count,
                            Index passes, const Index* fixed, const double* b, double* out, double* info) {
    sofac::DirectSolver D;
    record_pattern(D, n, rows, cols, count, fixed);
    D.analyze(sofac::Factorization::LLT);
    cholmod_common& common = D.factorization.cholmod();
    cholmod_factor* L = D.factorization.factor();
    info[0] = L->is_super;
    info[1] = static_cast<double>(L->nsuper);
    info[2] = common.fl;
    if (!L->is_super) return;
    cholmod_sparse* permuted = nullptr;
    for (Index pass = 0; pass < passes; ++pass) {
        D.assembler.start_values(D.matrix);
        for (Index k = 0; k < count; ++k) D.assembler.add(rows[k], cols[k], values[pass * count + k]);
        D.factor();
        for (Index i = 0; i < n; ++i) D.rhs[i] = b[i];
        D.solve();
        info[3 + 3 * pass] = D.ok;
        info[4 + 3 * pass] = static_cast<double>(L->minor);
        const Eigen::VectorXd residual = D.matrix * D.solution - D.rhs;
        out[3 * pass + 2] = residual.norm() / (D.matrix.norm() * D.solution.norm() + D.rhs.norm());
        const double* x = static_cast<const double*>(L->x);
        const std::vector<double> ours(x, x + L->xsize);
        // CHOLMOD's kernel on S = tril(A(p,p)) of the same (projected) values.
        const Eigen::SparseMatrix<double>& matrix = D.matrix;
        cholmod_sparse a = Eigen::viewAsCholmod(matrix.selfadjointView<Eigen::Upper>());
        cholmod_free_sparse(&permuted, &common);
        permuted = cholmod_ptranspose(&a, 2, static_cast<int*>(L->Perm), nullptr, 0, &common);
        double beta[2] = {0.0, 0.0};
        cholmod_super_numeric(permuted, nullptr, beta, L, &common);
        info[5 + 3 * pass] = static_cast<double>(L->minor);
        out[3 * pass] = out[3 * pass + 1] = 0.0;
        for (std::size_t k = 0; k < ours.size(); ++k) {
            out[3 * pass] = std::max(out[3 * pass], std::abs(ours[k] - x[k]));
            out[3 * pass + 1] = std::max(out[3 * pass + 1], std::abs(x[k]));
        }
    }
    cholmod_free_sparse(&permuted, &common);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "direct_solver", SHIM, optimize="-O1", cholmod=True)
    library.solve.argtypes = [ctypes.c_int64, I64, I64, D, ctypes.c_int64, I64, ctypes.c_int, D, D, I64]
    sizes = [ctypes.c_int64, ctypes.c_int64]
    library.compare_supernodal.argtypes = [ctypes.c_int64, I64, I64, D, *sizes, I64, D, D, D]
    solve_in_columns = [ctypes.c_int64, I64, I64, D, ctypes.c_int64, I64, ctypes.c_int, D, ctypes.c_int64]
    library.solve_in_columns.argtypes = [*solve_in_columns, D, D, I64]
    return library


def block_system(blocks: int, width: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contributions to two symmetric positive definite matrices of `blocks` x `blocks` dense blocks
    of `width` DOFs, each block coupled to the next two (a banded, 3D-FEM-like pattern): (rows,
    cols, the values of both passes). The diagonal gets two contributions, as from two elements."""
    rng = np.random.default_rng(seed)
    n = blocks * width
    index = np.arange(n)
    block = index // width
    near = np.abs(block[:, None] - block[None, :]) <= 2
    rows, cols = np.nonzero(near)
    rows = np.concatenate([rows, index]).astype(np.int64)
    cols = np.concatenate([cols, index]).astype(np.int64)
    values = []
    for _ in range(2):
        m = rng.standard_normal((n, n))
        symmetric = m + m.T
        entry = symmetric[rows, cols]
        entry[-n:] = 2.0 * n  # the second diagonal contribution makes it diagonally dominant
        values.append(entry)
    return rows, cols, np.concatenate(values)


def dense_projected(
    n: int, rows: np.ndarray, cols: np.ndarray, values: np.ndarray, fixed: np.ndarray
) -> np.ndarray:
    a = np.zeros((n, n))
    np.add.at(a, (rows, cols), values)
    a[fixed, :] = 0.0
    a[:, fixed] = 0.0
    a[fixed, fixed] = 1.0
    return a


@pytest.mark.parametrize(
    "blocks, width, llt, supernodal",
    [
        (40, 3, False, False),  # L D L^T: always simplicial
        (40, 3, True, False),  # L L^T, sparse: CHOLMOD picks its simplicial kernel
        (12, 40, True, True),  # L L^T, dense blocks: CHOLMOD picks a supernodal factor, sofac's kernel
        (20, 150, False, False),
        (20, 150, True, True),
    ],
)
def test_direct_solver_solves_the_projected_system(
    lib: ctypes.CDLL, blocks: int, width: int, llt: bool, supernodal: bool
) -> None:
    n = blocks * width
    rows, cols, values = block_system(blocks, width, seed=blocks + width)
    count = len(rows)
    fixed = np.zeros(n, dtype=np.int64)
    fixed[: width + 1] = 1  # the first block and one more DOF, as a clamped end
    fixed[n // 2] = 1
    rng = np.random.default_rng(7)
    b = rng.standard_normal(2 * n)
    b[np.concatenate([fixed, fixed]) != 0] = 0.0  # the step projects the right-hand side too
    x = np.zeros(2 * n)
    info = np.zeros(4, dtype=np.int64)
    lib.solve(n, _i(rows), _i(cols), _d(values), count, _i(fixed), int(llt), _d(b), _d(x), _i(info))
    stored, coupled, is_super, ok = (int(v) for v in info)
    assert ok == 1
    assert is_super == int(supernodal)
    assert coupled == 0  # no off-diagonal entry left in a projected row or column
    free = fixed == 0
    full = np.zeros((n, n), dtype=bool)
    full[rows, cols] = True
    assert stored == int(full[np.ix_(free, free)].sum()) + int((~free).sum())
    for p in range(2):
        a = dense_projected(n, rows, cols, values[p * count : (p + 1) * count], fixed != 0)
        expected = np.linalg.solve(a, b[p * n : (p + 1) * n])
        got = x[p * n : (p + 1) * n]
        assert np.abs(got - expected).max() < 1e-12 * np.abs(expected).max(), (p, llt, supernodal)
        assert np.all(got[fixed != 0] == 0.0)


@pytest.mark.parametrize("llt", [False, True])
def test_solves_in_columns_equal_single_solves_bit_for_bit(lib: ctypes.CDLL, llt: bool) -> None:
    """LinearSolverConstraintCorrection's W solves its rows kSolveColumns at a time
    (DirectSolver::solve_columns): on a simplicial factor (L D L^T of a 3-D beam; L L^T of a thin
    banded matrix, where CHOLMOD's analysis keeps the simplicial kernel), sparse right-hand sides like
    a contact row's J^T, and dense ones, give exactly solve()'s solutions."""
    if llt:
        rows, cols, values = block_system(40, 3, seed=4)
        values = values[: len(rows)]
        n, nodes, clamped = 120, 40, 3
    else:
        nx, ny, nz = 4, 4, 12
        rows, cols, values = hexahedral_beam(nx, ny, nz, seed=4)
        n, nodes, clamped = 3 * nx * ny * nz, nx * ny * nz, 3 * nx * ny
    fixed = np.zeros(n, dtype=np.int64)
    fixed[:clamped] = 1
    rng = np.random.default_rng(11)
    columns = 8  # not a multiple of kSolveColumns: the last batch is padded
    b = np.zeros((columns, n))
    for k in range(columns - 2):  # three DOFs of one node, as a contact's normal row
        node = rng.integers(clamped // 3, nodes)
        b[k, 3 * node : 3 * node + 3] = rng.standard_normal(3)
    b[-2:] = rng.standard_normal((2, n))
    b[:, fixed != 0] = 0.0
    b = b.ravel()
    in_columns, single = np.full(columns * n, np.nan), np.zeros(columns * n)
    info = np.zeros(2, dtype=np.int64)
    count = len(rows)
    lib.solve_in_columns(
        n,
        _i(rows),
        _i(cols),
        _d(values),
        count,
        _i(fixed),
        int(llt),
        _d(b),
        columns,
        _d(in_columns),
        _d(single),
        _i(info),
    )
    assert info[0] == 1 and info[1] > 1
    assert np.array_equal(in_columns, single)
    a = dense_projected(n, rows, cols, values, fixed != 0)
    expected = np.linalg.solve(a, b.reshape(columns, n).T).T.ravel()
    assert np.abs(single - expected).max() < 1e-10 * np.abs(expected).max()


def test_a_supernodal_factor_solves_one_column_at_a_time(lib: ctypes.CDLL) -> None:
    """CHOLMOD's supernodal solve of several columns runs other BLAS kernels than a one-column
    solve: solve_columns is not offered (W then takes one solve per row)."""
    blocks, width = 12, 40
    n = blocks * width
    rows, cols, values = block_system(blocks, width, seed=5)
    fixed = np.zeros(n, dtype=np.int64)
    b = np.ones(n)
    out = np.zeros(2 * n)
    info = np.zeros(2, dtype=np.int64)
    lib.solve_in_columns(
        n,
        _i(rows),
        _i(cols),
        _d(values[: len(rows)]),
        len(rows),
        _i(fixed),
        1,
        _d(b),
        1,
        _d(out[:n]),
        _d(out[n:]),
        _i(info),
    )
    assert info[0] == 0


def test_a_matrix_that_is_not_positive_definite_gives_nan(lib: ctypes.CDLL) -> None:
    """A failed L L^T factorisation (a negative pivot) is reported as NaN, for both kernels (sofac's
    supernodal one for the dense blocks, CHOLMOD's simplicial one for the thin ones)."""
    for blocks, width in ((20, 150), (40, 3)):
        n = blocks * width
        rows, cols, values = block_system(blocks, width, seed=3)
        values = -values  # negative definite
        fixed = np.zeros(n, dtype=np.int64)
        x = np.zeros(2 * n)
        info = np.zeros(4, dtype=np.int64)
        b = np.ones(2 * n)
        lib.solve(n, _i(rows), _i(cols), _d(values), len(rows), _i(fixed), 1, _d(b), _d(x), _i(info))
        assert info[3] == 0
        assert np.isnan(x).all(), (blocks, width)


def hexahedral_beam(nx: int, ny: int, nz: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contributions (rows, cols, values) to a 3-D FEM-like matrix on a beam of nx x ny x nz nodes,
    3 DOFs each: every hexahedron adds a random symmetric positive definite 24 x 24 block on its 8
    nodes, and every DOF a positive diagonal term (a mass), so the matrix is positive definite."""
    rng = np.random.default_rng(seed)
    node = np.arange(nx * ny * nz).reshape(nz, ny, nx)
    offsets = [(k, j, i) for k in (0, 1) for j in (0, 1) for i in (0, 1)]
    corners = [node[k : nz - 1 + k, j : ny - 1 + j, i : nx - 1 + i] for k, j, i in offsets]
    hexes = np.stack([c.ravel() for c in corners], axis=1)  # (elements, 8)
    dofs = (3 * hexes[:, :, None] + np.arange(3)).reshape(len(hexes), 24)
    b = rng.standard_normal((len(hexes), 24, 30))
    blocks = b @ b.transpose(0, 2, 1) / 30.0
    rows = np.repeat(dofs, 24, axis=1).ravel()
    cols = np.tile(dofs, (1, 24)).ravel()
    n = 3 * nx * ny * nz
    index = np.arange(n)
    rows = np.concatenate([rows, index]).astype(np.int64)
    cols = np.concatenate([cols, index]).astype(np.int64)
    values = np.concatenate([blocks.ravel(), np.full(n, 0.01)])
    return rows, cols, values


def test_supernodal_factor_matches_cholmods_kernel_on_a_3d_beam(lib: ctypes.CDLL) -> None:
    """sofac's supernodal L L^T (runtime/sofac/direct.h's SupernodalCholesky) against
    cholmod_super_numeric on the same symbolic factor of a clamped 3-D beam: hundreds of
    supernodes, each updated by its descendants. Two passes with other values (the factor must be
    refilled), then a third where one DOF's diagonal is negative: both kernels must stop at the
    same column (L->minor), and the solve gives NaN."""
    nx, ny, nz = 7, 7, 28
    n = 3 * nx * ny * nz
    rows, cols, first = hexahedral_beam(nx, ny, nz, seed=1)
    _, _, second = hexahedral_beam(nx, ny, nz, seed=2)
    third = second.copy()
    bad = 3 * (nx * ny * nz // 2) + 1  # a DOF in the middle of the beam
    third[-n + bad] = -1e3  # its (second) diagonal contribution: a negative pivot whatever the order
    values = np.concatenate([first, second, third])
    fixed = np.zeros(n, dtype=np.int64)
    fixed[: 3 * nx * ny] = 1  # the first layer of nodes clamped
    rng = np.random.default_rng(5)
    b = rng.standard_normal(n)
    b[fixed != 0] = 0.0
    out = np.zeros(9)
    info = np.zeros(12)
    count = len(rows)
    lib.compare_supernodal(n, _i(rows), _i(cols), _d(values), count, 3, _i(fixed), _d(b), _d(out), _d(info))
    is_super, supernodes, flops = info[:3]
    assert is_super == 1 and flops > 1e8  # CHOLMOD's analysis picks the supernodal kernel
    assert supernodes > 300
    for p in range(2):
        ok, minor, cholmod_minor = info[3 + 3 * p : 6 + 3 * p]
        difference, largest, backward = out[3 * p : 3 * p + 3]
        assert ok == 1 and minor == n and cholmod_minor == n
        assert difference <= 1e-12 * largest, (p, difference / largest)
        assert backward < 1e-14, (p, backward)
    ok, minor, cholmod_minor = info[9:12]
    assert ok == 0
    assert minor < n and minor == cholmod_minor
