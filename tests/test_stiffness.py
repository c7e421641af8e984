"""Stiffness of the spring force fields against central finite differences of their forces.

The finite elements' stiffnesses are checked the same way in tests/test_fem_kernels.py (tetrahedra,
TetrahedralCorotational, hexahedra, every method) and tests/test_element_fem.py (the ElementFEM
family, matrix-free and assembled); this file fills the remaining dF/dx of the step: the springs of
SpringForceField / MeshSpringForceField / RegularGridSpringForceField (one kernel, one state or two,
Vec1d/2d/3d; the matrix-free product spring_dforces and the assembled blocks of the direct solvers)
and RestShapeSpringsForceField.

SOFA's spring Jacobian is (ks - F/d) n n^T + (F/d) I, with F the whole intensity, damping included:
exact for the elastic force, and it leaves out the derivative of the damping force's direction, so
with damping it is exact only at zero relative velocity (checked both ways below).
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
#include "sofac/kernels.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

static sofac::Springs table(const Index* a, const Index* b, const double* ks, const double* kd,
                            const double* l0, const Index* elong, const Index* on, Index n) {
    return sofac::Springs{a, b, ks, kd, l0, elong, on, n};
}

template <class DT>
void forces(const Index* a, const Index* b, const double* ks, const double* kd, const double* l0,
            const Index* elong, const Index* on, Index n, const double* x1, const double* v1, double* f1,
            const double* x2, const double* v2, double* f2, double* jac) {
    sofac::spring_forces<DT, DT>(table(a, b, ks, kd, l0, elong, on, n), x1, v1, f1, x2, v2, f2, jac);
}
template <class DT>
void dforces(const Index* a, const Index* b, const double* ks, const double* kd, const double* l0,
             const Index* elong, const Index* on, Index n, const double* jac, const double* dx1, double* df1,
             const double* dx2, double* df2, double kfact) {
    sofac::spring_dforces<DT, DT>(table(a, b, ks, kd, l0, elong, on, n), jac, dx1, df1, dx2, df2, kfact);
}
// Dense copy of the assembled spring blocks: states 1 and 2 at offsets 0 and off2 of a size x size matrix.
template <class DT>
void assemble(const Index* a, const Index* b, const double* ks, const double* kd, const double* l0,
              const Index* elong, const Index* on, Index n, const double* jac, Index off2, Index size,
              double kfact, double* out) {
    const sofac::Springs s = table(a, b, ks, kd, l0, elong, on, n);
    sofac::Assembler A;
    Eigen::SparseMatrix<double> m;
    A.start_pattern();
    sofac::assemble_springs<DT, DT>(A, s, jac, 0, off2, kfact);
    A.finish_pattern(m, size);
    A.start_values(m);
    sofac::assemble_springs<DT, DT>(A, s, jac, 0, off2, kfact);
    for (int c = 0; c < m.outerSize(); ++c)
        for (Eigen::SparseMatrix<double>::InnerIterator it(m, c); it; ++it)
            out[it.row() * size + it.col()] += it.value();
}

#define SPRINGS(N)                                                                                          \
    API void forces##N(const Index* a, const Index* b, const double* ks, const double* kd,                  \
                       const double* l0,                                                                    \
                       const Index* e, const Index* on, Index n, const double* x1, const double* v1,         \
                       double* f1, const double* x2, const double* v2, double* f2, double* jac) {            \
        forces<sofac::VecTypes<N>>(a, b, ks, kd, l0, e, on, n, x1, v1, f1, x2, v2, f2, jac);                \
    }                                                                                                       \
    API void dforces##N(const Index* a, const Index* b, const double* ks, const double* kd,                 \
                        const double* l0,                                                                   \
                        const Index* e, const Index* on, Index n, const double* jac, const double* dx1,      \
                        double* df1, const double* dx2, double* df2, double kfact) {                        \
        dforces<sofac::VecTypes<N>>(a, b, ks, kd, l0, e, on, n, jac, dx1, df1, dx2, df2, kfact);            \
    }                                                                                                       \
    API void assemble##N(const Index* a, const Index* b, const double* ks, const double* kd,                 \
                         const double* l0, const Index* e, const Index* on, Index n, const double* jac,     \
                         Index off2, Index size, double kfact, double* out) {                               \
        assemble<sofac::VecTypes<N>>(a, b, ks, kd, l0, e, on, n, jac, off2, size, kfact, out);              \
    }
SPRINGS(1)
SPRINGS(2)
SPRINGS(3)

API void rest_forces(double* f, const double* x, const double* rest, const Index* idx, const double* ks,
                     Index nks, Index n) {
    sofac::rest_shape_forces<sofac::Vec3d>(f, x, rest, idx, ks, nks, n);
}
API void rest_dforces(double* df, const double* dx, const Index* idx, const double* ks, Index nks, Index n,
                      double kfact) {
    sofac::rest_shape_dforces<sofac::Vec3d>(df, dx, idx, ks, nks, n, kfact);
}
API void rest_assemble(const Index* idx, const double* ks, Index nks, Index n, Index size, double kfact,
                       double* out) {
    sofac::Assembler A;
    Eigen::SparseMatrix<double> m;
    A.start_pattern();
    sofac::assemble_rest_shape<sofac::Vec3d>(A, 0, idx, ks, nks, n, kfact);
    A.finish_pattern(m, size);
    A.start_values(m);
    sofac::assemble_rest_shape<sofac::Vec3d>(A, 0, idx, ks, nks, n, kfact);
    for (int c = 0; c < m.outerSize(); ++c)
        for (Eigen::SparseMatrix<double>::InnerIterator it(m, c); it; ++it)
            out[it.row() * size + it.col()] += it.value();
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "stiffness", SHIM, optimize="-O1", cholmod=True)
    for n in (1, 2, 3):
        getattr(library, f"dforces{n}").argtypes = [
            I64,
            I64,
            D,
            D,
            D,
            I64,
            I64,
            ctypes.c_int64,
            D,
            D,
            D,
            D,
            D,
        ]
        getattr(library, f"dforces{n}").argtypes += [ctypes.c_double]
        getattr(library, f"assemble{n}").argtypes = [I64, I64, D, D, D, I64, I64, ctypes.c_int64, D]
        getattr(library, f"assemble{n}").argtypes += [ctypes.c_int64, ctypes.c_int64, ctypes.c_double, D]
    library.rest_dforces.argtypes = [D, D, I64, D, ctypes.c_int64, ctypes.c_int64, ctypes.c_double]
    library.rest_assemble.argtypes = [
        I64,
        D,
        ctypes.c_int64,
        ctypes.c_int64,
        ctypes.c_int64,
        ctypes.c_double,
        D,
    ]
    return library


class SpringSet:
    """Springs between state 1 (n1 points) and state 2 (n2 points; None: the same state)."""

    def __init__(self, lib: ctypes.CDLL, dim: int, n1: int, n2: int | None, springs: list[tuple]) -> None:
        self.lib, self.dim, self.n1, self.n2 = lib, dim, n1, n2
        rows = np.array(springs, dtype=float)
        self.a = np.ascontiguousarray(rows[:, 0], dtype=np.int64)
        self.b = np.ascontiguousarray(rows[:, 1], dtype=np.int64)
        self.ks, self.kd, self.l0 = (np.ascontiguousarray(rows[:, k]) for k in (2, 3, 4))
        self.elong = np.ascontiguousarray(rows[:, 5], dtype=np.int64)
        self.on = np.ones(len(rows), dtype=np.int64)
        self.count = len(rows)
        self.jac = np.zeros(self.count * (dim + 2))  # the factored blocks: c, t and n per spring

    def _table(self) -> list:
        return [_i(self.a), _i(self.b), _d(self.ks), _d(self.kd), _d(self.l0), _i(self.elong), _i(self.on)]

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One stacked vector -> (state 1, state 2) arrays (state 2 = state 1 for one state)."""
        first = np.ascontiguousarray(z[: self.n1 * self.dim])
        if self.n2 is None:
            return first, first
        return first, np.ascontiguousarray(z[self.n1 * self.dim :])

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Stacked forces at stacked positions / velocities; stores the Jacobian blocks."""
        x1, x2 = self.split(x)
        v1, v2 = self.split(v)
        f = np.zeros_like(x)
        f1, f2 = self.split(f)
        if self.n2 is None:
            f2 = f1
        fn = getattr(self.lib, f"forces{self.dim}")
        fn(
            *self._table(),
            ctypes.c_int64(self.count),
            _d(x1),
            _d(v1),
            _d(f1),
            _d(x2),
            _d(v2),
            _d(f2),
            _d(self.jac),
        )
        return f1.copy() if self.n2 is None else np.concatenate([f1, f2])

    def dforce(self, dx: np.ndarray, kfact: float) -> np.ndarray:
        dx1, dx2 = self.split(dx)
        df1 = np.zeros_like(dx1)
        df2 = df1 if self.n2 is None else np.zeros_like(dx2)
        fn = getattr(self.lib, f"dforces{self.dim}")
        fn(*self._table(), self.count, _d(self.jac), _d(dx1), _d(df1), _d(dx2), _d(df2), kfact)
        return df1 if self.n2 is None else np.concatenate([df1, df2])

    def dforce_matrix(self, size: int, kfact: float) -> np.ndarray:
        return np.array([self.dforce(np.eye(size)[k], kfact) for k in range(size)]).T

    def assembled(self, size: int, kfact: float) -> np.ndarray:
        out = np.zeros(size * size)
        offset = 0 if self.n2 is None else self.n1 * self.dim
        getattr(self.lib, f"assemble{self.dim}")(
            *self._table(), self.count, _d(self.jac), offset, size, kfact, _d(out)
        )
        return out.reshape(size, size)


def central_differences(force: callable, x: np.ndarray, h: float) -> np.ndarray:
    columns = []
    for k in range(x.size):
        step = np.zeros_like(x)
        step[k] = h
        columns.append((force(x + step) - force(x - step)) / (2 * h))
    return np.array(columns).T


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def random_springs(rng: np.random.Generator, n1: int, n2: int, count: int, damping: float) -> list[tuple]:
    springs = []
    for _ in range(count):
        a, b = int(rng.integers(n1)), int(rng.integers(n2))
        springs.append((a, b, rng.uniform(10, 200), damping * rng.uniform(0.5, 2), rng.uniform(0.3, 1.2), 0))
    return springs


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("two_states", [False, True], ids=["one state", "two states"])
def test_spring_stiffness_matches_central_differences(lib: ctypes.CDLL, dim: int, two_states: bool) -> None:
    rng = np.random.default_rng(10 * dim + two_states)
    n1, n2 = 6, 4
    springs = random_springs(rng, n1, n2 if two_states else n1, 12, damping=0.0)
    springs = [s for s in springs if two_states or s[0] != s[1]]
    field = SpringSet(lib, dim, n1, n2 if two_states else None, springs)
    size = (n1 + (n2 if two_states else 0)) * dim
    x = rng.uniform(-1.0, 1.0, size)
    v = np.zeros(size)
    field.force(x, v)  # stores the Jacobian blocks at x
    kfact = -0.42
    fd = central_differences(lambda y: field.force(y, v), x, 1e-6)
    field.force(x, v)
    matrix_free = field.dforce_matrix(size, kfact)
    assert rel(matrix_free, kfact * fd) < 1e-7
    # the direct solvers' assembled blocks are the same matrix
    assert rel(field.assembled(size, kfact), matrix_free) < 1e-14
    # a symmetric stiffness (a potential force), negative semi-definite when every spring is stretched
    assert rel(fd, fd.T) < 1e-7


def test_compressed_and_elongation_only_springs(lib: ctypes.CDLL) -> None:
    """A compressed spring's tangent (F/d < 0 across the spring) and elongation-only springs, which are
    off (no force, no stiffness) when compressed and on when stretched."""
    springs = [(0, 1, 50.0, 0.0, 2.0, 0), (1, 2, 80.0, 0.0, 2.0, 1), (2, 3, 30.0, 0.0, 0.5, 1)]
    field = SpringSet(lib, 3, 4, None, springs)
    x = np.array(
        [0.0, 0, 0, 1.0, 0.2, 0, 1.5, 0.5, 0.3, 2.5, 0.4, 0.1]
    )  # 0-1 and 1-2 compressed, 2-3 stretched
    v = np.zeros(12)
    f = field.force(x, v)
    assert f[0:3] @ (x[3:6] - x[0:3]) < 0  # spring 0 pushes its ends apart
    fd = central_differences(lambda y: field.force(y, v), x, 1e-7)
    field.force(x, v)
    assert rel(field.dforce_matrix(12, 1.0), fd) < 1e-7
    assert np.abs(fd[3:9, 3:9][np.ix_([0, 1, 2], [3, 4, 5])]).max() == 0  # spring 1 (compressed) is off


def test_damped_spring_stiffness_is_sofas_approximation(lib: ctypes.CDLL) -> None:
    """With damping, exact at zero relative velocity; otherwise off by the neglected term only."""
    rng = np.random.default_rng(3)
    springs = [s for s in random_springs(rng, 5, 5, 8, damping=5.0) if s[0] != s[1]]
    field = SpringSet(lib, 3, 5, None, springs)
    x = rng.uniform(-1.0, 1.0, 15)
    rigid_velocity = np.tile([0.3, -0.2, 0.5], 5)  # no relative velocity
    fd = central_differences(lambda y: field.force(y, rigid_velocity), x, 1e-6)
    field.force(x, rigid_velocity)
    assert rel(field.dforce_matrix(15, 1.0), fd) < 1e-7
    moving = rng.uniform(-1.0, 1.0, 15)
    fd = central_differences(lambda y: field.force(y, moving), x, 1e-6)
    field.force(x, moving)
    gap = rel(field.dforce_matrix(15, 1.0), fd)
    assert 1e-4 < gap < 1.0  # the neglected d(kd (v.n) n)/dx: visible, not dominant


def test_rest_shape_springs_stiffness(lib: ctypes.CDLL) -> None:
    rng = np.random.default_rng(4)
    n = 6
    rest = np.ascontiguousarray(rng.uniform(-1, 1, 3 * n))
    indices = np.array([0, 2, 3, 5], dtype=np.int64)
    ks = np.array([10.0, 20.0], dtype=np.float64)  # shorter list: its first value for the rest (SOFA)

    def force(x: np.ndarray) -> np.ndarray:
        f = np.zeros(3 * n)
        lib.rest_forces(_d(f), _d(np.ascontiguousarray(x)), _d(rest), _i(indices), _d(ks), 2, len(indices))
        return f

    x = rest + rng.uniform(-0.3, 0.3, 3 * n)
    fd = central_differences(force, x, 1e-6)
    kfact = 0.7
    columns = []
    for k in range(3 * n):
        df = np.zeros(3 * n)
        lib.rest_dforces(
            _d(df), _d(np.ascontiguousarray(np.eye(3 * n)[k])), _i(indices), _d(ks), 2, len(indices), kfact
        )
        columns.append(df)
    matrix_free = np.array(columns).T
    assert rel(matrix_free, kfact * fd) < 1e-9
    assembled = np.zeros(9 * n * n)
    lib.rest_assemble(_i(indices), _d(ks), 2, len(indices), 3 * n, kfact, _d(assembled))
    assert rel(assembled.reshape(3 * n, 3 * n), matrix_free) < 1e-15
    assert np.diag(fd).tolist() == pytest.approx(
        [-10.0] * 3 + [0.0] * 3 + [-20.0] * 3 + [-10.0] * 3 + [0.0] * 3 + [-10.0] * 3
    )
