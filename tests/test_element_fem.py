"""SOFA's element-based finite elements: runtime/sofac/element_fem.h and compiler/element_fem.py.

CorotationalFEMForceField / LinearSmallStrainFEMForceField (Vec3d on tetrahedra and hexahedra) and
FEMMass with a NodalMassDensity. The kernels are compiled once into a small shared library (plain C
wrappers, loaded with ctypes) and checked against: rigid motions, finite differences, independent
NumPy stiffness and mass matrices, the assembled blocks of the direct solvers; then two of SOFA's
Validation/cantilever_beam regression scenes run through sofac.load against SOFA's reference states.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.geometry import element_fem
from sofac.geometry.fem_topology import hexahedra_from_grid, tetrahedra_from_grid

SHIM = r"""
#include "sofac/element_fem.h"
#include <vector>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

struct Dense {  // an Assembler writing into a dense row-major matrix
    double* m;
    Index n;
    void add(Index r, Index c, double v) { m[r * n + c] += v; }
};

#define DISPATCH(N, CALL) if (N == 4) { constexpr int K = 4; CALL; } else { constexpr int K = 8; CALL; }

API void stiffness(int n, const Index* el, Index c, const double* x0, const double* e, Index ne,
                   const double* nu, Index nn, double* k) {
    DISPATCH(n, sofac::element_fem_stiffness_init<K>(el, c, x0, e, ne, nu, nn, k))
}
API void linear_force(int n, const Index* el, Index c, const double* x, const double* x0, const double* k,
                      double* f) {
    DISPATCH(n, sofac::element_linear_add_force<K>(el, c, x, x0, k, f))
}
API void linear_dforce(int n, const Index* el, Index c, const double* dx, double* df, double kf,
                       const double* k) {
    DISPATCH(n, sofac::element_linear_add_dforce<K>(el, c, dx, df, kf, k))
}
API void corot_init(int n, const Index* el, Index c, const double* x0, int method, double* rot) {
    DISPATCH(n, sofac::element_corot_init<K>(el, c, x0, method, rot))
}
API void corot_force(int n, const Index* el, Index c, const double* x, const double* x0, const double* k,
                     int method, double* rot, double* f) {
    DISPATCH(n, sofac::element_corot_add_force<K>(el, c, x, x0, k, method, rot, f))
}
API void corot_dforce(int n, const Index* el, Index c, const double* dx, double* df, double kf,
                      const double* k, const double* rot) {
    DISPATCH(n, sofac::element_corot_add_dforce<K>(el, c, dx, df, kf, k, rot))
}
API void assemble(int n, const Index* el, Index c, const double* k, const double* rot, double kf, double* out,
                  Index size) {
    Dense A{out, size};
    DISPATCH(n, sofac::element_fem_assemble<K>(A, el, c, k, rot, 0, kf))
}
API void mass_init(int n, const Index* el, Index c, const double* x0, const double* rho, Index nrho,
                   const Index* rows, const Index* cols, Index nrows, double* values) {
    DISPATCH(n, sofac::fem_mass_init<K>(el, c, x0, rho, nrho, rows, cols, nrows, values))
}
API void mass_gravity(double* f, const Index* rows, const Index* cols, const double* v, Index n,
                      const double* g) {
    sofac::fem_mass_gravity(f, rows, cols, v, n, g);
}
API void mass_multiply(double* df, const double* dx, const Index* rows, const Index* cols, const double* v,
                       Index n, double factor) {
    sofac::fem_mass_multiply(df, dx, rows, cols, v, n, factor);
}
API double mass_kinetic(const double* vel, const Index* rows, const Index* cols, const double* v, Index n) {
    return sofac::fem_mass_kinetic_energy(vel, rows, cols, v, n);
}
API void mass_assemble(const Index* rows, const Index* cols, const double* v, Index n, double mfact,
                       double* out) {
    Dense A{out, 3 * n};
    sofac::assemble_fem_mass(A, 0, rows, cols, v, n, mfact);
}
"""

FRAME, IDENTITY, POLAR, STABLE_POLAR = 0, 1, 2, 3


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "element_fem", SHIM)
    n, count, real, integer = ctypes.c_int, ctypes.c_int64, ctypes.c_double, ctypes.c_int
    signatures = {
        "stiffness": [n, I64, count, D, D, count, D, count, D],
        "linear_force": [n, I64, count, D, D, D, D],
        "linear_dforce": [n, I64, count, D, D, real, D],
        "corot_init": [n, I64, count, D, integer, D],
        "corot_force": [n, I64, count, D, D, D, integer, D, D],
        "corot_dforce": [n, I64, count, D, D, real, D, D],
        "assemble": [n, I64, count, D, D, real, D, count],
        "mass_init": [n, I64, count, D, D, count, I64, I64, count, D],
        "mass_gravity": [D, I64, I64, D, count, D],
        "mass_multiply": [D, D, I64, I64, D, count, real],
        "mass_kinetic": [D, I64, I64, D, count],
        "mass_assemble": [I64, I64, D, count, real, D],
    }
    for name, arguments in signatures.items():
        getattr(library, name).argtypes = arguments
        getattr(library, name).restype = real if name == "mass_kinetic" else None
    return library


class Field:
    """CorotationalFEMForceField (method given) or LinearSmallStrainFEMForceField (method None)."""

    def __init__(
        self,
        lib: ctypes.CDLL,
        elements: np.ndarray,
        rest: np.ndarray,
        method: int | None,
        young: float | list[float] = 1e4,
        poisson: float | list[float] = 0.3,
    ) -> None:
        self.lib = lib
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        self.n = self.elements.shape[1]
        self.count = len(self.elements)
        self.rest = np.ascontiguousarray(rest, dtype=float)
        self.method = method
        e = np.atleast_1d(np.asarray(young, dtype=float))
        nu = np.atleast_1d(np.asarray(poisson, dtype=float))
        size = 3 * self.n
        self.k = np.zeros(self.count * size * size)
        lib.stiffness(
            self.n, _i(self.elements), self.count, _d(self.rest), _d(e), e.size, _d(nu), nu.size, _d(self.k)
        )
        self.rotations = np.zeros(self.count * 18)
        if method is not None:
            lib.corot_init(self.n, _i(self.elements), self.count, _d(self.rest), method, _d(self.rotations))

    def element_stiffness(self, e: int = 0) -> np.ndarray:
        size = 3 * self.n
        return self.k[e * size * size : (e + 1) * size * size].reshape(size, size)

    def force(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=float)
        f = np.zeros_like(x)
        if self.method is None:
            self.lib.linear_force(
                self.n, _i(self.elements), self.count, _d(x), _d(self.rest), _d(self.k), _d(f)
            )
        else:
            self.lib.corot_force(
                self.n,
                _i(self.elements),
                self.count,
                _d(x),
                _d(self.rest),
                _d(self.k),
                self.method,
                _d(self.rotations),
                _d(f),
            )
        return f

    def dforce(self, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        dx = np.ascontiguousarray(dx, dtype=float)
        df = np.zeros_like(dx)
        if self.method is None:
            self.lib.linear_dforce(self.n, _i(self.elements), self.count, _d(dx), _d(df), kfactor, _d(self.k))
        else:
            self.lib.corot_dforce(
                self.n, _i(self.elements), self.count, _d(dx), _d(df), kfactor, _d(self.k), _d(self.rotations)
            )
        return df

    def dforce_matrix(self, x: np.ndarray) -> np.ndarray:
        self.force(x)  # sets the rotations
        size = x.size
        return np.array([self.dforce(np.eye(size)[k].reshape(x.shape)).ravel() for k in range(size)]).T

    def assembled(self, x: np.ndarray, kfactor: float) -> np.ndarray:
        self.force(x)
        size = x.size
        out = np.zeros(size * size)
        rotations = None if self.method is None else _d(self.rotations)
        self.lib.assemble(
            self.n, _i(self.elements), self.count, _d(self.k), rotations, kfactor, _d(out), size
        )
        return out.reshape(size, size)


class Mass:
    def __init__(
        self, lib: ctypes.CDLL, elements: np.ndarray, rest: np.ndarray, density: list[float]
    ) -> None:
        self.lib = lib
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        self.rest = np.ascontiguousarray(rest, dtype=float)
        self.nodes = len(rest)
        pattern = element_fem.mass_pattern(self.elements, self.nodes)
        self.rows, self.cols = pattern.row_begin, pattern.cols
        self.values = np.zeros(pattern.nonzeros)
        rho = element_fem.node_densities(density)
        lib.mass_init(
            self.elements.shape[1],
            _i(self.elements),
            len(self.elements),
            _d(self.rest),
            _d(rho),
            rho.size,
            _i(self.rows),
            _i(self.cols),
            self.nodes,
            _d(self.values),
        )

    def scalar_matrix(self) -> np.ndarray:
        m = np.zeros((self.nodes, self.nodes))
        for r in range(self.nodes):
            for k in range(self.rows[r], self.rows[r + 1]):
                m[r, self.cols[k]] = self.values[k]
        return m

    def gravity(self, g: list[float]) -> np.ndarray:
        f = np.zeros((self.nodes, 3))
        g_array = np.asarray(g, dtype=float)
        self.lib.mass_gravity(_d(f), _i(self.rows), _i(self.cols), _d(self.values), self.nodes, _d(g_array))
        return f

    def multiply(self, dx: np.ndarray, factor: float) -> np.ndarray:
        dx = np.ascontiguousarray(dx, dtype=float)
        df = np.zeros_like(dx)
        self.lib.mass_multiply(
            _d(df), _d(dx), _i(self.rows), _i(self.cols), _d(self.values), self.nodes, factor
        )
        return df


# ---- meshes and independent references ----------------------------------------------------------


def grid_points(counts: tuple[int, int, int], size: tuple[float, float, float]) -> np.ndarray:
    nx, ny, nz = counts
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    unit = np.stack([i.ravel() / (nx - 1), j.ravel() / (ny - 1), k.ravel() / (nz - 1)], axis=1)
    return unit * np.asarray(size)


def tet_mesh() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    points = grid_points((3, 3, 3), (1.0, 1.2, 0.9)) + 0.05 * rng.standard_normal((27, 3))
    return np.asarray(tetrahedra_from_grid((3, 3, 3)), dtype=np.int64), points


def hex_mesh(distort: float) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    points = grid_points((3, 2, 3), (1.0, 0.5, 1.3)) + distort * rng.standard_normal((18, 3))
    return np.asarray(hexahedra_from_grid((3, 2, 3)), dtype=np.int64), points


def rotation(axis: list[float], angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


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
    b = np.zeros((6, 3 * len(grads)))
    for n, (gx, gy, gz) in enumerate(grads):
        b[:, 3 * n : 3 * n + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx]]
    return b


def tet_stiffness(points: np.ndarray, young: float, nu: float) -> np.ndarray:
    m = np.hstack([np.ones((4, 1)), points])
    grads = np.linalg.inv(m)[1:].T
    b = strain_matrix(grads)
    return abs(np.linalg.det(m)) / 6 * b.T @ hooke(young, nu) @ b


SIGNS = np.array(
    [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
)


def gauss_points() -> np.ndarray:
    g = 1 / np.sqrt(3)
    return np.array(np.meshgrid([-g, g], [-g, g], [-g, g])).reshape(3, -1).T


def hex_shape(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    factors = 1 + SIGNS * xi
    shape = factors.prod(axis=1) / 8
    grads = np.empty((8, 3))
    for d in range(3):
        others = [a for a in range(3) if a != d]
        grads[:, d] = SIGNS[:, d] * factors[:, others[0]] * factors[:, others[1]] / 8
    return shape, grads


def hex_stiffness(nodes: np.ndarray, young: float, nu: float) -> np.ndarray:
    k = np.zeros((24, 24))
    for xi in gauss_points():
        _, dn = hex_shape(xi)
        jac = nodes.T @ dn
        b = strain_matrix(dn @ np.linalg.inv(jac))
        k += b.T @ hooke(young, nu) @ b * abs(np.linalg.det(jac))
    return k


def hex_mass(nodes: np.ndarray, rho: np.ndarray) -> np.ndarray:
    m = np.zeros((8, 8))
    for xi in gauss_points():
        n, dn = hex_shape(xi)
        m += np.outer(n, n) * (rho @ n) * abs(np.linalg.det(nodes.T @ dn))
    return m


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


MESHES = {"tetra": tet_mesh, "hexa": lambda: hex_mesh(0.04)}
FRAME_CASES = [(kind, method) for kind in MESHES for method in (FRAME, POLAR, STABLE_POLAR)]


# ---- stiffness ------------------------------------------------------------------------------------


@pytest.mark.parametrize("young,nu", [(1e4, 0.3), (2e6, 0.45)])
def test_tetra_stiffness_against_numpy(lib: ctypes.CDLL, young: float, nu: float) -> None:
    elements, points = tet_mesh()
    field = Field(lib, elements, points, None, young, nu)
    for e in (0, 7, len(elements) - 1):
        assert rel(field.element_stiffness(e), tet_stiffness(points[elements[e]], young, nu)) < 1e-12


@pytest.mark.parametrize("distort", [0.0, 0.08])
def test_hexa_stiffness_against_numpy(lib: ctypes.CDLL, distort: float) -> None:
    elements, points = hex_mesh(distort)
    field = Field(lib, elements, points, None, 2e6, 0.45)
    for e in range(len(elements)):
        # SOFA's Gauss abscissa uses sqrt(3) ~ 1.73205080757 (12 digits)
        assert rel(field.element_stiffness(e), hex_stiffness(points[elements[e]], 2e6, 0.45)) < 1e-10


def test_material_lists_per_element_and_short(lib: ctypes.CDLL) -> None:
    elements, points = tet_mesh()
    per_element = [1e4 * (1 + e) for e in range(len(elements))]
    field = Field(lib, elements, points, None, per_element, [0.3])
    assert rel(field.element_stiffness(5), tet_stiffness(points[elements[5]], 6e4, 0.3)) < 1e-12
    short = Field(lib, elements, points, None, [2e4, 3e4], [0.3])  # element 2 and later use the first value
    assert rel(short.element_stiffness(4), tet_stiffness(points[elements[4]], 2e4, 0.3)) < 1e-12
    # An empty list takes the registry's default in the plan (test_plan_ir.py); a negative Young's
    # modulus or a Poisson's ratio out of [0, 0.5) is a check error (E207), never a kernel's input.


# ---- forces -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(MESHES))
def test_linear_zero_at_rest_and_translation_and_linear(lib: ctypes.CDLL, kind: str) -> None:
    elements, points = MESHES[kind]()
    field = Field(lib, elements, points, None)
    assert np.abs(field.force(points)).max() == 0.0
    assert np.abs(field.force(points + np.array([0.3, -0.2, 0.1]))).max() < 1e-9
    rng = np.random.default_rng(1)
    u, w = rng.standard_normal(points.shape) * 1e-2, rng.standard_normal(points.shape) * 1e-2
    f_u, f_w = field.force(points + u), field.force(points + w)
    assert rel(field.force(points + u + w), f_u + f_w) < 1e-9
    assert rel(field.dforce(u, 2.0), 2.0 * f_u) < 1e-9  # df = kfactor * (df/dx) dx, df/dx = -K


@pytest.mark.parametrize("kind,method", FRAME_CASES)
def test_corotational_zero_under_rigid_motion(lib: ctypes.CDLL, kind: str, method: int) -> None:
    elements, points = MESHES[kind]()
    field = Field(lib, elements, points, method)
    scale = 1e4 * np.abs(points).max()
    assert np.abs(field.force(points)).max() < 1e-9 * scale
    moved = (points - 0.3) @ rotation([1.0, 2.0, -0.5], 0.9).T + [1.0, -2.0, 0.5]
    assert np.abs(field.force(moved)).max() < 1e-9 * scale


def test_identity_rotation_is_small_strain(lib: ctypes.CDLL) -> None:
    elements, points = tet_mesh()
    corot, linear = Field(lib, elements, points, IDENTITY), Field(lib, elements, points, None)
    x = points + np.random.default_rng(2).standard_normal(points.shape) * 1e-2
    assert rel(corot.force(x), linear.force(x)) < 1e-12


@pytest.mark.parametrize("kind,method", FRAME_CASES)
def test_corotational_stiffness_is_r_k_rt(lib: ctypes.CDLL, kind: str, method: int) -> None:
    """Under a rigid rotation R the force Jacobian is -R K R^T (SOFA's corotational stiffness)."""
    elements, points = MESHES[kind]()
    field, linear = Field(lib, elements, points, method), Field(lib, elements, points, None)
    r = rotation([0.3, -1.0, 0.4], 0.7)
    big_r = np.kron(np.eye(len(points)), r)
    k_rest = linear.dforce_matrix(points)
    assert rel(field.dforce_matrix(points @ r.T + 0.2), big_r @ k_rest @ big_r.T) < 1e-9


@pytest.mark.parametrize("kind", sorted(MESHES))
@pytest.mark.parametrize("method", [None, FRAME])
def test_dforce_matches_finite_differences(lib: ctypes.CDLL, kind: str, method: int | None) -> None:
    """At rest (and, for the linear law, anywhere) dF/dx is exactly the stiffness SOFA uses."""
    elements, points = MESHES[kind]()
    field = Field(lib, elements, points, method)
    x = points + (np.random.default_rng(4).standard_normal(points.shape) * 1e-2 if method is None else 0.0)
    h = 1e-6
    flat = x.ravel()
    jac = np.zeros((flat.size, flat.size))
    for k in range(flat.size):
        plus, minus = flat.copy(), flat.copy()
        plus[k] += h
        minus[k] -= h
        jac[:, k] = (field.force(plus.reshape(x.shape)) - field.force(minus.reshape(x.shape))).ravel() / (
            2 * h
        )
    assert rel(field.dforce_matrix(x), jac) < 1e-6


@pytest.mark.parametrize("kind", sorted(MESHES))
@pytest.mark.parametrize("method", [None, FRAME])
def test_assembled_blocks_match_dforce(lib: ctypes.CDLL, kind: str, method: int | None) -> None:
    elements, points = MESHES[kind]()
    field = Field(lib, elements, points, method)
    x = points @ rotation([1.0, 1.0, 0.0], 0.4).T
    jacobian = field.dforce_matrix(x)
    assert rel(field.assembled(x, -0.25), -0.25 * jacobian) < 1e-12


# ---- FEMMass -----------------------------------------------------------------------------------------


def test_mass_pattern_holds_the_element_node_pairs() -> None:
    pattern = element_fem.mass_pattern(np.array([[0, 2, 3, 4], [2, 1, 4, 3]]), 6)
    assert pattern.row_begin.tolist() == [0, 4, 8, 13, 18, 23, 23]
    assert pattern.cols[pattern.row_begin[2] : pattern.row_begin[3]].tolist() == [0, 1, 2, 3, 4]
    assert pattern.cols[:4].tolist() == [0, 2, 3, 4]


def test_tetra_mass_uses_sofas_one_point_rule(lib: ctypes.CDLL) -> None:
    """SOFA integrates the tetrahedron with its single Gauss point (the centroid, N_i = 1/4): every
    entry is rho V / 16, not the exact consistent matrix rho V / 20 (1 + delta_ij); same total mass."""
    points = np.array([[0.0, 0, 0], [1.0, 0.1, 0], [0.2, 0.9, 0.1], [0.1, 0.3, 1.2]])
    mass = Mass(lib, np.array([[0, 1, 2, 3]]), points, [1100.0])
    volume = abs(np.linalg.det(np.hstack([np.ones((4, 1)), points]))) / 6
    assert rel(mass.scalar_matrix(), np.full((4, 4), 1100.0 * volume / 16)) < 1e-12


@pytest.mark.parametrize("kind", sorted(MESHES))
def test_total_mass_is_density_times_volume(lib: ctypes.CDLL, kind: str) -> None:
    if kind == "tetra":
        elements, points = tet_mesh()
        cells = np.concatenate([np.ones((len(elements), 4, 1)), points[elements]], axis=2)
        volume = np.abs(np.linalg.det(cells)).sum() / 6
    else:
        elements, points = hex_mesh(0.0)
        volume = 1.0 * 0.5 * 1.3
    mass = Mass(lib, elements, points, [1100.0])
    assert abs(mass.scalar_matrix().sum() / (1100.0 * volume) - 1) < 1e-10
    gravity = mass.gravity([0.0, -9.81, 0.0])
    assert abs(gravity[:, 1].sum() / (-9.81 * 1100.0 * volume) - 1) < 1e-10
    assert np.abs(gravity[:, [0, 2]]).max() == 0.0


def test_hexa_mass_with_nodal_densities(lib: ctypes.CDLL) -> None:
    elements, points = hex_mesh(0.05)
    rho = 1000.0 + 100.0 * np.arange(len(points))
    mass = Mass(lib, elements, points, rho.tolist())
    expected = np.zeros((len(points), len(points)))
    for cell in elements:
        expected[np.ix_(cell, cell)] += hex_mass(points[cell], rho[cell])
    assert rel(mass.scalar_matrix(), expected) < 1e-10
    # NodalMassDensity: a node beyond the list takes its last value
    short = Mass(lib, elements, points, [1000.0, 2000.0])
    constant = Mass(lib, elements, points, [2000.0])
    values = short.scalar_matrix()
    assert values[5, 5] == pytest.approx(constant.scalar_matrix()[5, 5], rel=1e-12)


def test_mass_products_and_energy(lib: ctypes.CDLL) -> None:
    elements, points = tet_mesh()
    mass = Mass(lib, elements, points, [900.0])
    full = np.kron(mass.scalar_matrix(), np.eye(3))
    v = np.random.default_rng(9).standard_normal(points.shape)
    assert rel(mass.multiply(v, -0.5).ravel(), -0.5 * full @ v.ravel()) < 1e-12
    kinetic = lib.mass_kinetic(_d(v), _i(mass.rows), _i(mass.cols), _d(mass.values), mass.nodes)
    assert kinetic == pytest.approx(0.5 * v.ravel() @ full @ v.ravel(), rel=1e-12)
    out = np.zeros(full.size)
    lib.mass_assemble(_i(mass.rows), _i(mass.cols), _d(mass.values), mass.nodes, 1.5, _d(out))
    assert rel(out.reshape(full.shape), 1.5 * full) < 1e-15


# ---- SOFA's regression scenes --------------------------------------------------------------------


def _reference(path: Path) -> dict[float, np.ndarray]:
    import gzip

    blocks: dict[float, np.ndarray] = {}
    time = None
    with gzip.open(path, "rt") as stream:
        for line in stream:
            words = line.split()
            if words and words[0] == "T=":
                time = float(words[1])
            elif words and words[0] == "X=" and time is not None:
                blocks[time] = np.array(words[1:], dtype=float)
    return blocks


@pytest.mark.parametrize(
    "scene",
    [
        "hexahedron/linear/sequential/assembled/HexahedronLinearSmallStrainFEMForceField.scn",
        "tetrahedron/corotational/parallel/assembled/TetrahedronCorotationalFEMForceField.scn",
    ],
)
def test_cantilever_beam_matches_sofa(shared_dir: Path, scene: str) -> None:
    """99 steps of SOFA's cantilever (FEMMass + element FEM + SparseLDLSolver) against SOFA's
    reference: equal to the 6 printed digits (a few values on a rounding boundary excepted)."""
    import sofac

    corpus = shared_dir / "corpus" / "sofa" / "Validation" / "cantilever_beam" / scene
    reference = shared_dir / "reference" / "sofa-regression" / "Validation" / "cantilever_beam"
    blocks = _reference(reference / f"{scene}.reference_0_state_mstate.txt.gz")
    sim = sofac.load(corpus)
    sim.step(99)
    x = np.asarray(sim["/state"].position).ravel()
    expected = blocks[0.99]
    assert expected[1::3].min() < -0.03  # the tip has bent down by more than 3 cm
    # Every coordinate within half a unit of the 6th printed digit of SOFA's value (plus 1e-9 for
    # values on a rounding boundary); coordinates that are zero up to round-off (below 1e-9) too.
    unit = 10.0 ** (np.floor(np.log10(np.maximum(np.abs(expected), 1e-300))) - 5)
    significant = np.abs(expected) > 1e-9
    assert (np.abs(x - expected)[significant] <= 0.5 * unit[significant] + 1e-9).all()
    assert np.abs(x[~significant]).max() < 1e-9


EXPLICIT_SCENE = """<Node name="root" dt="0.001" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <EulerExplicitSolver symplectic="1"/>
    {linear}
    <RegularGridTopology name="grid" min="0 0 0" max="1 1 2" n="3 3 4"/>
    <MechanicalObject template="Vec3" name="state"/>
    <NodalMassDensity property="1000"/>
    <FEMMass template="Vec3,Hexahedron"/>
    <LinearSmallStrainFEMForceField template="Vec3,Hexahedron" youngModulus="1000" poissonRatio="0.3"/>
</Node>
"""


def test_explicit_euler_solves_the_fem_mass(tmp_path: Path) -> None:
    """Explicit Euler with a sparse direct solver solves M a = f: a free body falls at g exactly."""
    import sofac

    scene = tmp_path / "explicit.scn"
    scene.write_text(EXPLICIT_SCENE.format(linear=""))
    with pytest.raises(sofac.SceneError, match="FEMMass needs an implicit solver"):
        sofac.load(scene)
    scene.write_text(EXPLICIT_SCENE.format(linear='<SparseLDLSolver template="CompressedRowSparseMatrixd"/>'))
    sim = sofac.load(scene)
    sim.step(10)
    velocity = np.asarray(sim["/state"].velocity)
    assert np.abs(velocity - [0.0, -9.81 * 0.01, 0.0]).max() < 1e-12
    assert sim.energy().kinetic == pytest.approx(0.5 * 1000.0 * 2.0 * (9.81 * 0.01) ** 2, rel=1e-10)
