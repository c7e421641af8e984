"""The finite-element kernels of runtime/sofac/fem.h and the grid splits of sofac.geometry.fem_topology.

The kernels are compiled once per session into a small shared library (plain C wrappers, loaded with
ctypes) and checked against: rigid-motion invariance, finite differences, the linear small-strain
stiffness, independent NumPy implementations of V B^T D B (tetrahedra) and of the 2x2x2 Gauss
integration of the trilinear brick (hexahedra), the exact grid split SOFA uses, and SOFA's own beam
trajectories (../shared/reference/sofa scenes c1, c2, c3), which they reproduce to the last bit.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.geometry.fem_topology import hexahedra_from_grid, tetrahedra_from_grid, tetrahedra_from_hexahedra
from sofac.plan.lower.common import TETRA_LANES

SHIM = r"""
#include "sofac/fem.h"
#include <cmath>
#include <vector>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API sofac::Index tet_count(int method, Index n) { return sofac::tetra_fem_data_count(method, n); }
API int tet_size(int method) { return sofac::tetra_fem_data_size(method); }
API int hex_size(int method) { return sofac::hexa_fem_data_size(method); }
API void tet_init(const Index* t, Index n, const double* x0, const double* e, Index ne, const double* nu,
                  Index nn, int method, double* data, const double* lsf, Index nf) {
    sofac::tetra_fem_init(t, n, x0, e, ne, nu, nn, method, data, lsf, nf);
}
API void tet_force(const Index* t, Index n, const double* x, double* f, double* data, int method) {
    sofac::tetra_fem_add_force(t, n, x, f, data, method);
}
API void tet_dforce(const Index* t, Index n, const double* dx, double* df, double k, const double* data,
                    int method) {
    sofac::tetra_fem_add_dforce(t, n, dx, df, k, data, method);
}
API double tet_energy(const Index* t, Index n, const double* x, const double* data, int method) {
    return sofac::tetra_fem_energy(t, n, x, data, method);
}
API void tet_matrix(const double* data, Index e, int method, double* out) {
    sofac::tetra_fem_element_matrix(data, e, method, out);
}
// The per-element kernels in the serial loop, the reference of the vectorised loops; the
// vectorised loops compiled for instruction-set level 0 (baseline), 1 (AVX2), 2 (AVX-512 F+VL).
API void tet_force_scalar(const Index* t, Index n, const double* x, double* f, double* data, int method) {
    sofac::serial_elements<4>(n, t, f, [&](Index i, double* out) {
        sofac::tetra_fem_force_of(t, i, x, data, method, out);
    });
}
API void tet_dforce_scalar(const Index* t, Index n, const double* dx, double* df, double k,
                           const double* data, int method) {
    sofac::serial_elements<4>(n, t, df, [&](Index i, double* out) {
        sofac::tetra_fem_dforce_of(t, i, dx, k, data, method, out);
    });
}
API int vector_level() {
#ifdef SOFAC_X86_VARIANTS
    return sofac::vector_level();
#else
    return 0;
#endif
}
API void tet_force_level(int level, const Index* t, Index n, const double* x, double* f, double* data) {
    using namespace sofac::fem_detail;
#ifdef SOFAC_X86_VARIANTS
    if (level == 2) return tetra_force_large_avx512(t, n, x, f, data, nullptr, nullptr);
    if (level == 1) return tetra_force_large_avx2(t, n, x, f, data, nullptr, nullptr);
#endif
    if (level == 0) tetra_force_large_default(t, n, x, f, data, nullptr, nullptr);
}
API void tet_dforce_level(int level, const Index* t, Index n, const double* dx, double* df, double k,
                          const double* data, int method) {
    using namespace sofac::fem_detail;
#ifdef SOFAC_X86_VARIANTS
    if (level == 2) return tetra_dforce_avx512(t, n, dx, df, k, data, method, nullptr, nullptr);
    if (level == 1) return tetra_dforce_avx2(t, n, dx, df, k, data, method, nullptr, nullptr);
#endif
    if (level == 0) tetra_dforce_default(t, n, dx, df, k, data, method, nullptr, nullptr);
}
// The element matrices of elements [0, n), a block of TETRA_LANES at a time (level -1: dispatched).
API void tet_matrices_level(int level, const double* data, Index n, int method, double* out) {
    using namespace sofac::fem_detail;
    const int lanes = sofac::TETRA_LANES, size = sofac::tetra_fem_data_size(method);
    std::vector<double> block(144 * lanes);
    for (Index first = 0; first < n; first += lanes) {
        const double* d = data + first * size;
        if (level < 0) sofac::tetra_fem_element_matrices(data, first, method, block.data());
#ifdef SOFAC_X86_VARIANTS
        if (level == 2) tetra_element_matrices_avx512(d, method, block.data());
        if (level == 1) tetra_element_matrices_avx2(d, method, block.data());
#endif
        if (level == 0) tetra_element_matrices_default(d, method, block.data());
        std::copy_n(block.data(), 144 * std::min<Index>(lanes, n - first), out + 144 * first);
    }
}
API void corot_force(const Index* t, Index n, const double* x, double* f, double* data, int method) {
    sofac::tetracorot_fem_add_force(t, n, x, f, data, method);
}
API void hex_init(const Index* h, Index n, const double* x0, const double* e, Index ne, const double* nu,
                  Index nn, int method, double* data, const double* coef) {
    sofac::hexa_fem_init(h, n, x0, e, ne, nu, nn, method, data, coef);
}
API void hex_force(const Index* h, Index n, const double* x, double* f, double* data, int method) {
    sofac::hexa_fem_add_force(h, n, x, f, data, method);
}
API void hex_dforce(const Index* h, Index n, const double* dx, double* df, double k, const double* data,
                    int method) {
    sofac::hexa_fem_add_dforce(h, n, dx, df, k, data, method);
}
API double hex_energy(const Index* h, Index n, const double* x, const double* data, int method) {
    return sofac::hexa_fem_energy(h, n, x, data, method);
}
API void hex_matrix(const double* data, Index e, int method, double* out) {
    sofac::hexa_fem_element_matrix(data, e, method, out);
}
API void polar(const double* m, double* q) {
    using namespace sofac::fem_detail;
    store_m(q, polar_rotation(load_m(m)));
}
API void svd_rotation(const double* m, double* q) {
    using namespace sofac::fem_detail;
    store_m(q, svd_stable_rotation(load_m(m)));
}
API void tet_matrices(const double* data, Index n, int method, double* out) {
    for (Index e = 0; e < n; ++e) sofac::tetra_fem_element_matrix(data, e, method, out + 144 * e);
}

// Test scaffolding, not sofac's solver: one step of SOFA's EulerImplicitSolver (rayleigh rk, rm) with
// a matrix-free CGLinearSolver, UniformMass m per point, gravity g, fixed points, in SOFA's order of
// operations (f = m g + fem; b = h (f - rm M v + (h + rk) K v), projected; CG on
// ((1 + h rm) M - h (h + rk) K) dv = b with SOFA's stopping rules; v += dv; x += h v).
static double vdot(const std::vector<double>& a, const std::vector<double>& b) {
    double r = 0;
    for (size_t i = 0; i < a.size(); i += 3) r += a[i] * b[i] + a[i + 1] * b[i + 1] + a[i + 2] * b[i + 2];
    return r;
}
API int implicit_step(int hexa, const Index* el, Index ne, double* x, double* v, Index n, double* data,
                      const Index* fixed, Index nfixed, int first_solve, double m, double gy, double h,
                      double rk, double rm, int max_iter, double tolerance, double threshold) {
    const Index size = 3 * n;
    auto add_dforce = [&](const double* dx, double* df, double k) {
        if (hexa) sofac::hexa_fem_add_dforce(el, ne, dx, df, k, data, 1);
        else sofac::tetra_fem_add_dforce(el, ne, dx, df, k, data, 1);
    };
    auto project = [&](std::vector<double>& a) {
        for (Index k = 0; k < nfixed; ++k) a[3 * fixed[k]] = a[3 * fixed[k] + 1] = a[3 * fixed[k] + 2] = 0.0;
    };
    std::vector<double> f(size, 0.0), p(size), q(size), dv(size, 0.0);
    for (Index i = 0; i < n; ++i) f[3 * i + 1] += gy * m;
    if (hexa) sofac::hexa_fem_add_force(el, ne, x, f.data(), data, 1);
    else sofac::tetra_fem_add_force(el, ne, x, f.data(), data, 1);
    std::vector<double> b = f;
    const double damping = m * -rm;
    for (Index i = 0; i < size; ++i) b[i] += v[i] * damping;
    add_dforce(v, b.data(), h + rk);
    for (double& e : b) e *= h;
    project(b);
    std::vector<double> r = b;
    const double normb = std::sqrt(vdot(b, b));
    double rho = 0.0, rho_1 = 0.0;
    int it = 1;
    for (; normb != 0.0 && it <= max_iter; ++it) {
        rho = vdot(r, r);
        if (std::sqrt(rho) / normb <= tolerance && !(it == 1 && first_solve)) break;
        if (it == 1) {
            p = r;
        } else {
            const double beta = rho / rho_1;
            for (Index i = 0; i < size; ++i) {
                p[i] *= beta;
                p[i] += r[i];
            }
        }
        const double mass = m * (1 + h * rm);
        for (Index i = 0; i < size; ++i) q[i] = 0.0 + p[i] * mass;
        add_dforce(p.data(), q.data(), -h * (h + rk));
        project(q);
        const double den = vdot(p, q);
        if (den != 0.0 && std::fabs(den) <= threshold && !(it == 1 && first_solve)) break;
        const double alpha = rho / den;
        for (Index i = 0; i < size; ++i) {
            dv[i] += p[i] * alpha;
            r[i] += q[i] * -alpha;
        }
        rho_1 = rho;
    }
    for (Index i = 0; i < size; ++i) {
        v[i] = v[i] + dv[i];
        x[i] = x[i] + v[i] * h;
    }
    return it;
}
"""

SMALL, LARGE, POLAR, SVD = 0, 1, 2, 3
TET_METHODS = (SMALL, LARGE, POLAR, SVD)
HEX_METHODS = (SMALL, LARGE, POLAR)


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "fem", SHIM)
    library.tet_energy.restype = ctypes.c_double
    library.tet_count.restype = ctypes.c_int64
    library.hex_energy.restype = ctypes.c_double
    for name in ("tet_dforce", "hex_dforce", "tet_dforce_scalar"):
        getattr(library, name).argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int]
    head = [ctypes.c_int, I64, ctypes.c_int64, D, D, ctypes.c_int64, D, I64, ctypes.c_int64, ctypes.c_int]
    tail = [ctypes.c_double] * 5 + [ctypes.c_int] + [ctypes.c_double] * 2
    library.implicit_step.argtypes = head + tail
    return library


class Field:
    """One force field instance over a mesh: init once, then force / dforce / energy / matrices."""

    def __init__(
        self,
        lib: ctypes.CDLL,
        kind: str,
        elements: np.ndarray,
        rest: np.ndarray,
        method: int,
        young: float | list[float] = 1e4,
        poisson: float | list[float] = 0.3,
        factor: list[float] | None = None,
        coef: list[float] | None = None,
    ) -> None:
        self.lib, self.kind, self.method = lib, kind, method
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        self.n = len(self.elements)
        self.rest = np.ascontiguousarray(rest, dtype=np.float64)
        e = np.atleast_1d(np.asarray(young, dtype=np.float64))
        nu = np.atleast_1d(np.asarray(poisson, dtype=np.float64))
        if kind == "tet":
            self.data = np.zeros(lib.tet_count(method, ctypes.c_int64(self.n)))
        else:
            self.data = np.zeros(self.n * lib.hex_size(method))
        if kind == "tet":
            lsf = np.asarray(factor if factor is not None else [1.0], dtype=np.float64)
            lib.tet_init(
                _i(self.elements),
                ctypes.c_int64(self.n),
                _d(self.rest),
                _d(e),
                ctypes.c_int64(len(e)),
                _d(nu),
                ctypes.c_int64(len(nu)),
                method,
                _d(self.data),
                _d(lsf),
                ctypes.c_int64(0 if factor is None else len(lsf)),
            )
        else:
            c = np.asarray(coef if coef is not None else [1.0] * self.n, dtype=np.float64)
            lib.hex_init(
                _i(self.elements),
                ctypes.c_int64(self.n),
                _d(self.rest),
                _d(e),
                ctypes.c_int64(len(e)),
                _d(nu),
                ctypes.c_int64(len(nu)),
                method,
                _d(self.data),
                _d(c),
            )

    def force(self, x: np.ndarray, data: np.ndarray | None = None) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64)
        f = np.zeros_like(x)
        target = self.data if data is None else data
        fn = self.lib.tet_force if self.kind == "tet" else self.lib.hex_force
        fn(_i(self.elements), ctypes.c_int64(self.n), _d(x), _d(f), _d(target), self.method)
        return f

    def dforce(self, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        dx = np.ascontiguousarray(dx, dtype=np.float64)
        df = np.zeros_like(dx)
        fn = self.lib.tet_dforce if self.kind == "tet" else self.lib.hex_dforce
        fn(_i(self.elements), self.n, _d(dx), _d(df), kfactor, _d(self.data), self.method)
        return df

    def energy(self, x: np.ndarray) -> float:
        x = np.ascontiguousarray(x, dtype=np.float64)
        fn = self.lib.tet_energy if self.kind == "tet" else self.lib.hex_energy
        return float(fn(_i(self.elements), ctypes.c_int64(self.n), _d(x), _d(self.data), self.method))

    def element_matrix(self, e: int = 0) -> np.ndarray:
        size = 12 if self.kind == "tet" else 24
        out = np.zeros(size * size)
        fn = self.lib.tet_matrix if self.kind == "tet" else self.lib.hex_matrix
        fn(_d(self.data), ctypes.c_int64(e), self.method, _d(out))
        return out.reshape(size, size)

    def global_matrix(self) -> np.ndarray:
        """Sum of the element matrices (SOFA's assembled R K R^T; the Jacobian is its negative)."""
        nodes = 4 if self.kind == "tet" else 8
        k = np.zeros((self.rest.size, self.rest.size))
        for e, element in enumerate(self.elements):
            ke = self.element_matrix(e)
            dofs = (3 * element[:, None] + np.arange(3)).ravel()
            k[np.ix_(dofs, dofs)] += ke
            assert ke.shape == (3 * nodes, 3 * nodes)
        return k


# ---- geometry helpers ---------------------------------------------------------------------------


def rotation(axis: Sequence[float], angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def grid_points(counts: tuple[int, int, int], size: tuple[float, float, float]) -> np.ndarray:
    nx, ny, nz = counts
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    unit = np.stack([i.ravel() / (nx - 1), j.ravel() / (ny - 1), k.ravel() / (nz - 1)], axis=1)
    return unit * np.asarray(size)


def signed_volumes(points: np.ndarray, tetra: np.ndarray) -> np.ndarray:
    p = points[tetra]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6


def tet_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A 2x2x2-cell grid split as SOFA does (both orientations present), slightly distorted."""
    rng = np.random.default_rng(7)
    points = grid_points((3, 3, 3), (1.0, 1.2, 0.9)) + 0.05 * rng.standard_normal((27, 3))
    return tetrahedra_from_grid((3, 3, 3)), points


def hex_mesh(distort: float) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(11)
    points = grid_points((3, 2, 3), (1.0, 0.5, 1.3)) + distort * rng.standard_normal((18, 3))
    return hexahedra_from_grid((3, 2, 3)), points


def fd_jacobian(force: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float) -> np.ndarray:
    flat = x.ravel()
    jac = np.zeros((flat.size, flat.size))
    for k in range(flat.size):
        plus, minus = flat.copy(), flat.copy()
        plus[k] += h
        minus[k] -= h
        jac[:, k] = (force(plus.reshape(x.shape)) - force(minus.reshape(x.shape))).ravel() / (2 * h)
    return jac


def dforce_matrix(field: Field, x: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
    field.force(x)  # sets the rotations
    size = x.size
    cols = [field.dforce(np.eye(size)[k].reshape(x.shape), kfactor).ravel() for k in range(size)]
    return np.array(cols).T


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


# ---- independent reference stiffnesses ------------------------------------------------------------


def hooke(young: float, nu: float) -> np.ndarray:
    """Isotropic Hooke matrix, Voigt order xx yy zz xy yz zx, engineering shear strains."""
    lam = young * nu / ((1 + nu) * (1 - 2 * nu))
    mu = young / (2 * (1 + nu))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] += 2 * mu
    d[3:, 3:] = mu * np.eye(3)
    return d


def strain_matrix(grads: np.ndarray) -> np.ndarray:
    """B (6 x 3n) from the shape-function gradients (n x 3)."""
    b = np.zeros((6, 3 * len(grads)))
    for n, (gx, gy, gz) in enumerate(grads):
        b[:, 3 * n : 3 * n + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx]]
    return b


def tet_reference(points: np.ndarray, young: float, nu: float) -> np.ndarray:
    m = np.hstack([np.ones((4, 1)), points])
    grads = np.linalg.inv(m)[1:].T  # row n: gradient of N_n
    volume = abs(np.linalg.det(m)) / 6
    b = strain_matrix(grads)
    return volume * b.T @ hooke(young, nu) @ b


HEX_SIGNS = np.array(
    [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
)


def hex_reference(nodes: np.ndarray, young: float, nu: float) -> np.ndarray:
    """Trilinear brick, N_i = prod_a (1 + s_ia xi_a) / 8, 2x2x2 Gauss points (weight 1)."""
    g = 1 / np.sqrt(3)
    k = np.zeros((24, 24))
    for xi in np.array(np.meshgrid([-g, g], [-g, g], [-g, g])).reshape(3, -1).T:
        factors = 1 + HEX_SIGNS * xi  # (8, 3)
        dn = np.empty((8, 3))
        for d in range(3):
            others = [a for a in range(3) if a != d]
            dn[:, d] = HEX_SIGNS[:, d] * factors[:, others[0]] * factors[:, others[1]] / 8
        jac = nodes.T @ dn  # dX/dxi
        grads = dn @ np.linalg.inv(jac)
        b = strain_matrix(grads)
        k += b.T @ hooke(young, nu) @ b * np.linalg.det(jac)
    return k


# ---- grid topology ------------------------------------------------------------------------------


def test_hexahedra_from_grid_order() -> None:
    hexa = hexahedra_from_grid((3, 2, 2))
    assert hexa.shape == (2, 8)
    # corners (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1), index i + 3 (j + 2 k)
    assert hexa[0].tolist() == [0, 1, 4, 3, 6, 7, 10, 9]
    assert hexa[1].tolist() == [1, 2, 5, 4, 7, 8, 11, 10]
    assert hexahedra_from_grid((4, 4, 1)).shape == (0, 8)


def test_grid_split_4x4x16() -> None:
    counts = (4, 4, 16)
    size = (1.0, 1.0, 4.0)
    points = grid_points(counts, size)
    tetra = tetrahedra_from_grid(counts)
    assert tetra.shape == (6 * 3 * 3 * 15, 4)
    volumes = signed_volumes(points, tetra)
    cell = (1 / 3) * (1 / 3) * (4 / 15)
    # every tetrahedron is a sixth of its cell; the split covers the box exactly
    np.testing.assert_allclose(np.abs(volumes), cell / 6, rtol=1e-12)
    assert np.abs(volumes).sum() == pytest.approx(4.0, rel=1e-12)
    # orientation: SOFA's mirrored cells give negative volumes; the sign is (-1)^(number of mirrors)
    cells = np.arange(len(tetra)) // 6
    ci, cj, ck = cells % 3, (cells // 3) % 3, cells // 9
    mirrors = (ci % 2 == 0).astype(int) + (cj % 2 == 1) + (ck % 2 == 1)
    np.testing.assert_array_equal(np.sign(volumes), np.where(mirrors % 2 == 1, -1.0, 1.0))
    assert (volumes > 0).sum() == 402 and (volumes < 0).sum() == 408
    # each tetrahedron uses 4 distinct corners of its own cell
    hexa = hexahedra_from_grid(counts)
    for t, c in zip(tetra, cells, strict=True):
        assert len(set(t.tolist())) == 4 and set(t.tolist()) <= set(hexa[c].tolist())


def test_grid_split_first_cells() -> None:
    """The exact lists for the first cells (hand-derived from SOFA's init: x-even cells are mirrored in x)."""
    tetra = tetrahedra_from_grid((3, 3, 3))
    # cell (0,0,0): corners 0 1 4 3 9 10 13 12, mirrored in x -> 1 0 3 4 10 9 12 13
    c = [1, 0, 3, 4, 10, 9, 12, 13]
    expected = [
        [c[0], c[5], c[1], c[6]],
        [c[0], c[1], c[3], c[6]],
        [c[1], c[3], c[6], c[2]],
        [c[6], c[3], c[0], c[7]],
        [c[6], c[7], c[0], c[5]],
        [c[7], c[5], c[4], c[0]],
    ]
    assert tetra[:6].tolist() == expected
    # cell (1,0,0) is not mirrored
    c = [1, 2, 5, 4, 10, 11, 14, 13]
    assert tetra[6].tolist() == [c[0], c[5], c[1], c[6]]
    # a non-grid topology uses nx=2, ny=1: cell 1 has odd x and y parity 1 % 1 == 0 -> no mirror
    hexa = np.arange(16).reshape(2, 8)
    assert tetrahedra_from_hexahedra(hexa)[6].tolist() == [8, 13, 9, 14]


# ---- tetrahedra ---------------------------------------------------------------------------------


@pytest.mark.parametrize("method", TET_METHODS)
def test_tetra_zero_force_at_rest_and_rigid_motion(lib: ctypes.CDLL, method: int) -> None:
    tetra, rest = tet_mesh()
    field = Field(lib, "tet", tetra, rest, method)
    scale = np.abs(field.force(rest + 0.01 * np.sin(rest))).max()
    assert np.abs(field.force(rest)).max() <= 1e-12 * scale
    assert np.abs(field.force(rest + np.array([0.3, -2.0, 1.5]))).max() <= 1e-10 * scale
    if method != SMALL:
        r = rotation([1.0, 2.0, -0.5], 1.1)
        moved = rest @ r.T + [0.2, 0.1, -3.0]
        assert np.abs(field.force(moved)).max() <= 1e-10 * scale


def test_tetra_small_is_linear(lib: ctypes.CDLL) -> None:
    tetra, rest = tet_mesh()
    field = Field(lib, "tet", tetra, rest, SMALL)
    k = field.global_matrix()
    rng = np.random.default_rng(1)
    for _ in range(3):
        u = 0.2 * rng.standard_normal(rest.shape)
        np.testing.assert_allclose(
            field.force(rest + u).ravel(), -k @ u.ravel(), rtol=0, atol=1e-9 * np.abs(k).max()
        )
    # dforce = -kfactor K dx, energy = 1/2 u.K.u
    u = 0.1 * rng.standard_normal(rest.shape)
    np.testing.assert_allclose(
        field.dforce(u, 0.25).ravel(), -0.25 * k @ u.ravel(), atol=1e-9 * np.abs(k).max()
    )
    assert field.energy(rest + u) == pytest.approx(0.5 * u.ravel() @ k @ u.ravel(), rel=1e-10)


@pytest.mark.parametrize("method", TET_METHODS)
def test_tetra_dforce_matches_finite_differences(lib: ctypes.CDLL, method: int) -> None:
    """Exact where SOFA's stiffness is exact: any state for small, rigidly moved states for the
    corotational methods (SOFA neglects the derivative of the rotation, which vanishes at zero strain)."""
    tetra, rest = tet_mesh()
    field = Field(lib, "tet", tetra, rest, method)
    rng = np.random.default_rng(3)
    if method == SMALL:
        x = rest + 0.1 * rng.standard_normal(rest.shape)
    else:
        x = rest @ rotation([0.3, -1.0, 0.7], 0.8).T + [1.0, 2.0, 3.0]
    kfactor = -0.37
    fd = fd_jacobian(lambda y: field.force(y, field.data.copy()), x, 1e-6)
    assert rel(dforce_matrix(field, x, kfactor), kfactor * fd) < 1e-6


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


@pytest.mark.parametrize("count", [45, 46, 47, 48])
@pytest.mark.parametrize("method", TET_METHODS)
def test_tetra_vectorised_loops_match_the_scalar_kernels(lib: ctypes.CDLL, method: int, count: int) -> None:
    """The loops running TETRA_LANES (4) elements at once give the per-element scalar kernels'
    numbers to the last bit, signed zeros included, with a short last block (count % 4 = 1, 2, 3),
    and store the same rotations: the dispatched loop and each instruction-set copy this processor
    can run (baseline, AVX2, AVX-512)."""
    tetra, rest = tet_mesh()
    tetra = np.ascontiguousarray(tetra[:count])
    n = ctypes.c_int64(count)
    rng = np.random.default_rng(count)
    x = rest @ rotation([0.2, 1.0, -0.4], 0.6).T + 0.08 * rng.standard_normal(rest.shape)
    dx = rng.standard_normal(rest.shape)
    dx[3] = 0.0  # exact zeros keep their sign through the products
    kfactor = -0.37
    reference = Field(lib, "tet", tetra, rest, method)
    force = np.zeros_like(x)
    lib.tet_force_scalar(_i(tetra), n, _d(x), _d(force), _d(reference.data), method)
    dforce = np.zeros_like(x)
    lib.tet_dforce_scalar(_i(tetra), count, _d(dx), _d(dforce), kfactor, _d(reference.data), method)
    assert np.abs(force).max() > 0 and np.abs(dforce).max() > 0
    # the elements' data, in blocks of 4 elements (number-major): the unused lanes may differ
    slot = np.arange(reference.data.size)
    used = slot // (reference.data.size // ((count + 3) // 4)) * 4 + slot % 4 < count
    levels = [None, *range(lib.vector_level() + 1)]  # None: the dispatched loop
    for level in levels:
        field = Field(lib, "tet", tetra, rest, method)
        f = np.zeros_like(x)
        if level is None:
            lib.tet_force(_i(tetra), n, _d(x), _d(f), _d(field.data), method)
        elif method == LARGE:  # the only vectorised add_force
            lib.tet_force_level(level, _i(tetra), n, _d(x), _d(f), _d(field.data))
        else:
            continue
        assert np.array_equal(bits(f), bits(force)), level
        assert np.array_equal(bits(field.data)[used], bits(reference.data)[used]), level
    for level in levels:
        df = np.zeros_like(x)
        if level is None:
            lib.tet_dforce(_i(tetra), n, _d(dx), _d(df), ctypes.c_double(kfactor), _d(reference.data), method)
        else:
            lib.tet_dforce_level(
                level, _i(tetra), n, _d(dx), _d(df), ctypes.c_double(kfactor), _d(reference.data), method
            )
        assert np.array_equal(bits(df), bits(dforce)), level


@pytest.mark.parametrize("method", [LARGE, POLAR, SVD])
def test_tetra_corotational_stiffness_is_r_k0_rt(lib: ctypes.CDLL, method: int) -> None:
    """Deformed states: addDForce is -R K0 R^T with R the rotation of the last addForce; its gap to
    the true Jacobian is first order in the strain."""
    tetra, rest = tet_mesh()
    field = Field(lib, "tet", tetra, rest, method)
    small = Field(lib, "tet", tetra, rest, SMALL)
    rng = np.random.default_rng(5)
    noise = rng.standard_normal(rest.shape)
    r = rotation([1.0, 1.0, 0.2], 0.6)
    gaps = []
    for strain in (1e-2, 1e-3):
        x = (rest + strain * noise) @ r.T
        jac = dforce_matrix(field, x)
        # the assembled matrices (SOFA's buildStiffnessMatrix) agree with addDForce
        assert rel(jac, -field.global_matrix()) < 1e-12
        gaps.append(rel(jac, fd_jacobian(lambda y: field.force(y, field.data.copy()), x, 1e-7)))
    assert gaps[1] < 0.2 * gaps[0]
    # at rest, the corotational stiffness is the small-displacement one
    field.force(rest)
    assert rel(field.global_matrix(), small.global_matrix()) < 1e-10


@pytest.mark.parametrize("method", TET_METHODS)
def test_single_tetra_stiffness_against_numpy(lib: ctypes.CDLL, method: int) -> None:
    points = np.array([[0.1, 0.0, 0.2], [1.3, 0.2, 0.1], [0.2, 0.9, -0.1], [0.3, 0.4, 1.1]])
    for order in ([0, 1, 2, 3], [1, 0, 2, 3]):  # both orientations
        tetra = np.array([order])
        young, nu = 3.5e3, 0.28
        field = Field(lib, "tet", tetra, points, method, young, nu)
        field.force(points)  # rotation at rest
        expected = tet_reference(points[order], young, nu)
        k = field.element_matrix()
        assert rel(k, expected) < 1e-12
        u = np.zeros_like(points)
        u[order] = 1e-3 * np.arange(12).reshape(4, 3)
        if method == SMALL:
            np.testing.assert_allclose(
                field.force(points + u)[order].ravel(), -expected @ u[order].ravel(), rtol=1e-12, atol=1e-12
            )


def sofa_tetra_element_matrix(element_data: np.ndarray, method: int) -> np.ndarray:
    """SOFA's computeStiffnessMatrix as it evaluates it: J (12x6) from the 12 cofactors, the
    material K (6x6), then J K J^T and RR (J K J^T) RR^T as generic Mat products over every entry,
    each sum from 0 in increasing order (plain Python floats: one rounding per operation)."""
    d = [float(v) for v in element_data]
    j = [[0.0] * 6 for _ in range(12)]
    for n in range(4):
        a, b, g = d[3 * n : 3 * n + 3]
        j[3 * n][0] = j[3 * n + 1][3] = j[3 * n + 2][5] = a
        j[3 * n][3] = j[3 * n + 1][1] = j[3 * n + 2][4] = b
        j[3 * n][5] = j[3 * n + 1][4] = j[3 * n + 2][2] = g
    k = [[0.0] * 6 for _ in range(6)]
    for r in range(3):
        for c in range(3):
            k[r][c] = d[12] if r == c else d[13]
        k[3 + r][3 + r] = d[14]
    identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    rot = identity if method == SMALL else [d[15:18], d[18:21], d[21:24]]
    rr = [[0.0] * 12 for _ in range(12)]
    for b in range(4):
        for r in range(3):
            for c in range(3):
                rr[3 * b + r][3 * b + c] = rot[r][c]

    def product(left: list, right: list, transpose: bool) -> list:
        rows, inner = len(left), len(left[0])
        cols = len(right) if transpose else len(right[0])
        out = [[0.0] * cols for _ in range(rows)]
        for r in range(rows):
            for c in range(cols):
                total = 0.0
                for m in range(inner):
                    total += left[r][m] * (right[c][m] if transpose else right[m][c])
                out[r][c] = total
        return out

    jkjt = product(product(j, k, False), j, True)
    return np.array(product(product(rr, jkjt, False), rr, True))


@pytest.mark.parametrize("method", [SMALL, LARGE])
def test_tetra_element_matrix_is_sofas_product_to_the_bit(lib: ctypes.CDLL, method: int) -> None:
    """tetra_fem_element_matrix skips the terms that are zero by construction: every entry must
    still be the number SOFA's full products give (sign of zeros aside, which adds nothing)."""
    tetra, rest = tet_mesh()
    field = Field(lib, "tet", tetra, rest, method, 2.5e4, 0.31)
    rng = np.random.default_rng(8)
    field.force(rest + 0.05 * rng.standard_normal(rest.shape))  # rotated elements (large)
    size = lib.tet_size(method)
    lanes = TETRA_LANES  # element data in blocks of this many elements, one field of each at a time
    for e in range(len(tetra)):
        start = e // lanes * lanes * size + e % lanes
        record = field.data[start : start + size * lanes : lanes]  # element e's numbers
        expected = sofa_tetra_element_matrix(record[:24], method)
        assert np.array_equal(field.element_matrix(e), expected), e
    # The assembled solvers' blocks of TETRA_LANES matrices (one per vector lane, every
    # instruction-set copy this processor runs) give the same numbers; n - 2 of them: a short last block.
    n = len(tetra) - 2
    assert n % lanes
    one_by_one = np.array([field.element_matrix(e) for e in range(n)])
    for level in (-1, *range(lib.vector_level() + 1)):
        blocks = np.zeros(144 * n)
        lib.tet_matrices_level(level, _d(field.data), ctypes.c_int64(n), method, _d(blocks))
        assert np.array_equal(blocks.reshape(-1, 12, 12), one_by_one), level


def test_tetra_material_lists_and_factors(lib: ctypes.CDLL) -> None:
    tetra, rest = tet_mesh()
    n = len(tetra)
    base = Field(lib, "tet", tetra, rest, SMALL, 1000.0, 0.3)
    k0 = [base.element_matrix(e) for e in range(n)]
    # per-element young list; a list shorter than the element count uses its first value beyond its end
    young = [1000.0 * (1 + e) for e in range(5)]
    per = Field(lib, "tet", tetra, rest, SMALL, young, 0.3)
    for e in range(n):
        factor = (1 + e) if e < 5 else 1
        assert rel(per.element_matrix(e), factor * k0[e]) < 1e-13
    # localStiffnessFactor: element e uses factor[e * M / n]
    factors = [1.0, 2.0, 3.0]
    scaled = Field(lib, "tet", tetra, rest, SMALL, 1000.0, 0.3, factor=factors)
    for e in range(n):
        assert rel(scaled.element_matrix(e), factors[e * 3 // n] * k0[e]) < 1e-13


@pytest.mark.parametrize("method", [SMALL, LARGE, POLAR])
def test_tetracorot_is_tetrahedron_fem(lib: ctypes.CDLL, method: int) -> None:
    tetra, rest = tet_mesh()
    a = Field(lib, "tet", tetra, rest, method)
    x = rest + 0.05 * np.cos(3 * rest)
    f = np.zeros_like(x)
    data = a.data.copy()
    lib.corot_force(_i(a.elements), ctypes.c_int64(a.n), _d(x), _d(f), _d(data), method)
    assert np.array_equal(f, a.force(x))
    assert np.array_equal(data, a.data)


def test_polar_and_svd_rotations(lib: ctypes.CDLL) -> None:
    rng = np.random.default_rng(9)
    for _ in range(20):
        m = rng.standard_normal((3, 3))
        if np.linalg.det(m) < 0:
            m[0] *= -1
        q = np.zeros(9)
        lib.polar(_d(np.ascontiguousarray(m)), _d(q))
        u, _, vt = np.linalg.svd(m)
        np.testing.assert_allclose(q.reshape(3, 3), u @ vt, atol=1e-9)
        lib.svd_rotation(_d(np.ascontiguousarray(m)), _d(q))
        np.testing.assert_allclose(q.reshape(3, 3), u @ vt, atol=1e-9)
    # an inverted matrix: the SVD rotation is proper (smallest singular direction flipped)
    m = np.diag([2.0, 1.0, -0.5])
    q = np.zeros(9)
    lib.svd_rotation(_d(np.ascontiguousarray(m)), _d(q))
    np.testing.assert_allclose(q.reshape(3, 3), np.eye(3), atol=1e-12)


def test_tetra_svd_handles_inverted_element(lib: ctypes.CDLL) -> None:
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    tetra = np.array([[0, 1, 2, 3]])
    svd = Field(lib, "tet", tetra, points, SVD)
    polar = Field(lib, "tet", tetra, points, POLAR)
    x = points.copy()
    x[3, 2] = -0.5  # inverted
    f = svd.force(x)
    assert np.all(np.isfinite(f))
    # the restoring force pushes node 3 back up (polar keeps the reflection and does not)
    assert f[3, 2] > 0
    assert polar.force(x)[3, 2] <= 0
    # not inverted: svd == polar
    x[3, 2] = 0.8
    np.testing.assert_array_equal(svd.force(x), polar.force(x))


# ---- hexahedra ----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", HEX_METHODS)
def test_hexa_zero_force_at_rest_and_rigid_motion(lib: ctypes.CDLL, method: int) -> None:
    hexa, rest = hex_mesh(0.03)
    field = Field(lib, "hex", hexa, rest, method)
    scale = np.abs(field.force(rest + 0.01 * np.sin(rest))).max()
    assert np.abs(field.force(rest)).max() <= 1e-12 * scale
    assert np.abs(field.force(rest + np.array([0.3, -2.0, 1.5]))).max() <= 1e-10 * scale
    if method != SMALL:
        moved = rest @ rotation([1.0, 2.0, -0.5], 1.1).T + [0.2, 0.1, -3.0]
        assert np.abs(field.force(moved)).max() <= 1e-10 * scale


@pytest.mark.parametrize("method", HEX_METHODS)
def test_hexa_dforce_matches_finite_differences(lib: ctypes.CDLL, method: int) -> None:
    hexa, rest = hex_mesh(0.03)
    field = Field(lib, "hex", hexa, rest, method)
    rng = np.random.default_rng(4)
    if method == SMALL:
        x = rest + 0.1 * rng.standard_normal(rest.shape)
    else:
        x = rest @ rotation([0.3, -1.0, 0.7], 0.8).T + [1.0, 2.0, 3.0]
    kfactor = 0.61
    jac = dforce_matrix(field, x, kfactor)
    assert rel(jac, kfactor * fd_jacobian(lambda y: field.force(y, field.data.copy()), x, 1e-6)) < 1e-6
    assert rel(jac, -kfactor * field.global_matrix()) < 1e-12


@pytest.mark.parametrize("method", [LARGE, POLAR])
def test_hexa_corotational_gap_is_first_order(lib: ctypes.CDLL, method: int) -> None:
    hexa, rest = hex_mesh(0.03)
    field = Field(lib, "hex", hexa, rest, method)
    noise = np.random.default_rng(6).standard_normal(rest.shape)
    r = rotation([0.2, 1.0, 1.0], -0.9)
    gaps = []
    for strain in (1e-2, 1e-3):
        x = (rest + strain * noise) @ r.T
        gaps.append(
            rel(dforce_matrix(field, x), fd_jacobian(lambda y: field.force(y, field.data.copy()), x, 1e-7))
        )
    assert gaps[1] < 0.2 * gaps[0]


@pytest.mark.parametrize("distort", [0.0, 0.04])
def test_hexa_stiffness_against_numpy(lib: ctypes.CDLL, distort: float) -> None:
    hexa, rest = hex_mesh(distort)
    young, nu = 2e3, 0.35
    field = Field(lib, "hex", hexa, rest, SMALL, young, nu)
    for e in range(len(hexa)):
        assert rel(field.element_matrix(e), hex_reference(rest[hexa[e]], young, nu)) < 1e-12
    # small method: f = -K (x - x0), energy 1/2 u.K.u
    k = field.global_matrix()
    u = 0.01 * np.random.default_rng(2).standard_normal(rest.shape)
    np.testing.assert_allclose(field.force(rest + u).ravel(), -k @ u.ravel(), atol=1e-10 * np.abs(k).max())
    assert field.energy(rest + u) == pytest.approx(0.5 * u.ravel() @ k @ u.ravel(), rel=1e-10)


@pytest.mark.parametrize("method", [LARGE, POLAR])
def test_hexa_corotational_matches_numpy_in_rotated_frame(lib: ctypes.CDLL, method: int) -> None:
    """A rotated box: the world stiffness R0^T Ke R0 is the reference brick stiffness of the rotated nodes."""
    _, box = hex_mesh(0.0)
    hexa = hexahedra_from_grid((3, 2, 3))
    r = rotation([1.0, -2.0, 0.5], 0.7)
    rest = box @ r.T
    young, nu = 2e3, 0.35
    field = Field(lib, "hex", hexa, rest, method, young, nu, coef=[1.0, 0.5, 1.0, 2.0])
    for e, c in enumerate([1.0, 0.5, 1.0, 2.0]):
        assert rel(field.element_matrix(e), c * hex_reference(rest[hexa[e]], young, nu)) < 1e-10


def test_hexa_energy_is_half_u_k_u_locally(lib: ctypes.CDLL) -> None:
    hexa, rest = hex_mesh(0.0)
    field = Field(lib, "hex", hexa, rest, LARGE)
    small = Field(lib, "hex", hexa, rest, SMALL)
    u = 0.01 * np.random.default_rng(8).standard_normal(rest.shape)
    r = rotation([0.0, 0.0, 1.0], 0.5)
    # rotating a deformed state leaves the corotational energy unchanged (to first order in u)
    e0 = small.energy(rest + u)
    assert field.energy((rest + u) @ r.T + 1.0) == pytest.approx(e0, rel=0.05)


# ---- SOFA's own trajectories (../shared/reference/sofa, scenes c1 c2 c3) -----------------------------


def reference_frames(path: Path) -> dict[int, np.ndarray]:
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    frames = {}
    for step in np.unique(table[:, 0]).astype(int):
        rows = table[table[:, 0] == step]
        frames[int(step)] = rows[np.argsort(rows[:, 2]), 3:6]
    return frames


def beam(lib: ctypes.CDLL, kind: str, rest: np.ndarray) -> tuple[Field, np.ndarray]:
    """The c* beams: grid 4x4x16 over (0,0,0)-(1,1,4), E 1e5, nu 0.3, method large, z=0 face fixed."""
    elements = tetrahedra_from_grid((4, 4, 16)) if kind == "tet" else hexahedra_from_grid((4, 4, 16))
    fixed = np.ascontiguousarray(np.flatnonzero(rest[:, 2] == 0.0), dtype=np.int64)
    assert len(fixed) == 16
    return Field(lib, kind, elements, rest, LARGE, 1e5, 0.3), fixed


@pytest.mark.parametrize(("kind", "scene"), [("tet", "c1_beam_tetfem_cg"), ("hex", "c3_beam_hexafem_cg")])
def test_beam_with_cg_is_bit_identical_to_sofa(
    lib: ctypes.CDLL, shared_dir: Path, kind: str, scene: str
) -> None:
    """200 implicit steps with SOFA's matrix-free CG (not converged at 100 iterations, so any
    difference in add_force/add_dforce would show): the positions equal SOFA's to the last bit."""
    frames = reference_frames(shared_dir / "reference" / "sofa" / "data" / f"{scene}.csv")
    x = np.ascontiguousarray(frames[0])  # SOFA's grid positions, as printed with 17 digits
    field, fixed = beam(lib, kind, x)
    v = np.zeros_like(x)
    for step in range(1, 201):
        lib.implicit_step(
            int(kind == "hex"),
            _i(field.elements),
            field.n,
            _d(x),
            _d(v),
            len(x),
            _d(field.data),
            _i(fixed),
            len(fixed),
            int(step == 1),
            1.0 / len(x),
            -9.81,
            0.01,
            0.1,
            0.1,
            100,
            1e-10,
            1e-10,
        )
        if step in frames:
            assert np.abs(x - frames[step]).max() <= 1e-15, step


def test_beam_with_direct_solve_matches_sofa_ldl(lib: ctypes.CDLL, shared_dir: Path) -> None:
    """c2 (SparseLDLSolver): the assembled element matrices, solved exactly, follow SOFA's states."""
    frames = reference_frames(shared_dir / "reference" / "sofa" / "data" / "c2_beam_tetfem_ldl.csv")
    x = frames[0].copy()
    field, fixed = beam(lib, "tet", x)
    n, h, rk, rm, m = len(x), 0.01, 0.1, 0.1, 1.0 / len(x)
    dofs = (3 * field.elements[:, :, None] + np.arange(3)).reshape(field.n, 12)
    flat = (np.repeat(dofs, 12, axis=1) * (3 * n) + np.tile(dofs, (1, 12))).ravel()
    blocked = (3 * fixed[:, None] + np.arange(3)).ravel()
    v = np.zeros_like(x)
    for step in range(1, 11):
        f = field.force(x) + m * np.array([0.0, -9.81, 0.0])
        b = h * (f + field.dforce(v, h + rk) - rm * m * v).ravel()
        matrices = np.zeros(field.n * 144)
        lib.tet_matrices(_d(field.data), ctypes.c_int64(field.n), LARGE, _d(matrices))
        a = np.bincount(flat, h * (h + rk) * matrices, minlength=(3 * n) ** 2).reshape(3 * n, 3 * n)
        a[np.diag_indices(3 * n)] += (1 + h * rm) * m
        a[blocked, :] = 0.0
        a[:, blocked] = 0.0
        a[blocked, blocked] = 1.0
        b[blocked] = 0.0
        v = v + np.linalg.solve(a, b).reshape(-1, 3)
        x = x + h * v
        if step in frames:
            assert np.abs(x - frames[step]).max() <= 1e-14, step
