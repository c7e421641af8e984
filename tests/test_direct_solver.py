"""runtime/sofac/direct.h's DirectSolver against dense NumPy solves.

The assembled pattern leaves out the couplings of the projected DOFs (their contributions go to
the DOF's diagonal, which the projection overwrites), and each factorisation (L D L^T, CHOLMOD's
simplicial kernel; L L^T, its supernodal kernel for big enough factors, else its simplicial one)
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

// Entries (rows[k], cols[k]) of an n x n matrix with values values[pass * count + k], two passes
// (two factorisations); fixed[i] != 0 projects DOF i. Out: each pass's solution of A x = b, and
// info = {stored entries, off-diagonal entries in fixed rows or columns, supernodal, ok}.
API void solve(Index n, const Index* rows, const Index* cols, const double* values, Index count,
               const Index* fixed, int llt, const double* b, double* x, Index* info) {
    sofac::DirectSolver D;
    D.resize(n);
    for (Index i = 0; i < n; ++i) D.fixed[i] = fixed[i] != 0;
    D.assembler.start_pattern();
    for (Index k = 0; k < count; ++k) D.assembler.add(rows[k], cols[k], 0.0);
    D.assembler.finish_pattern(D.matrix, n, D.fixed);
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
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "direct_solver", SHIM, optimize="-O1", cholmod=True)
    library.solve.argtypes = [ctypes.c_int64, I64, I64, D, ctypes.c_int64, I64, ctypes.c_int, D, D, I64]
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
        (12, 40, True, False),  # L L^T, dense blocks but < 1e8 flops: simplicial as well
        (20, 150, False, False),
        (20, 150, True, True),  # L L^T, dense blocks, ~4e8 flops: the supernodal kernel
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


def test_a_matrix_that_is_not_positive_definite_gives_nan(lib: ctypes.CDLL) -> None:
    """A failed L L^T factorisation (a negative pivot) is reported as NaN, for both of CHOLMOD's
    kernels (the supernodal one for the dense blocks, the simplicial one for the thin ones)."""
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
