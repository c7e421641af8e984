"""Triangle surface force fields of runtime/sofac/shell.h: TriangularFEMForceFieldOptim against the
exact plane-stress linear triangle, its derivative and assembled matrix against finite differences."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.geometry.bending import bending_springs
from sofac.pipeline import compile_scene

SHIM = r"""
#include "sofac/shell.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

API void tri_init(const Index* t, Index n, const double* x0, const double* e, Index ne, const double* nu,
                  Index nn, double* d) {
    sofac::trifem_optim_init(t, n, x0, e, ne, nu, nn, 1, d);
}
API void tri_force(const Index* t, Index n, const double* x, double* f, double* d, const double* e, Index ne,
                   const double* nu, Index nn) {
    sofac::trifem_optim_add_force(t, n, x, f, d, e, ne, nu, nn);
}
API void tri_dforce(const Index* t, Index n, const double* dx, double* df, double k, const double* d,
                    const double* e, Index ne, const double* nu, Index nn) {
    sofac::trifem_optim_add_dforce(t, n, dx, df, k, d, e, ne, nu, nn);
}
API void bend_force(const Index* v, const double* a, const double* l, Index n, const double* x, double* f) {
    sofac::bending_springs_add_force(v, a, l, n, x, f);
}
API double bend_energy(const Index* v, const double* a, const double* l, Index n, const double* x) {
    return sofac::bending_springs_energy(v, a, l, n, x);
}
API void bend_dforce(const Index* v, const double* a, const double* l, Index n, const double* dx, double* df,
                     double k) {
    sofac::bending_springs_add_dforce(v, a, l, n, dx, df, k);
}
struct Dense {
    double* m;
    Index n;
    void add(Index r, Index c, double v) { m[r * n + c] += v; }
};
API void bend_matrix(const Index* v, const double* a, const double* l, Index n, double k, double* out,
                     Index size) {
    Dense A{out, size};
    sofac::assemble_bending_springs(A, 0, v, a, l, n, k);
}
API void tb_force(const Index* s, const double* p, Index n, const double* x, const double* v, double* f,
                  double* m) {
    sofac::triangular_bending_add_force(s, p, n, x, v, f, m);
}
API void tb_dforce(const Index* s, Index n, const double* m, const double* dx, double* df, double k) {
    sofac::triangular_bending_add_dforce(s, n, m, dx, df, k);
}
API void tf_init(const Index* t, Index n, const double* x0, const double* e, Index ne, const double* nu,
                 Index nn, double* d) {
    sofac::trifem_init(t, n, x0, e, ne, nu, nn, 1, d);
}
API void tf_force(const Index* t, Index n, const double* x, double* f, double* d) {
    sofac::trifem_add_force(t, n, x, f, d, 1);
}
API void tf_dforce(const Index* t, Index n, const double* dx, double* df, double k, const double* d) {
    sofac::trifem_add_dforce(t, n, dx, df, k, d, 1);
}
API void tri_matrix(const double* d, Index i, const double* e, Index ne, const double* nu, Index nn,
                    double* out) {
    sofac::trifem_optim_element_matrix(d, i, e, ne, nu, nn, out);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "shell", SHIM)
    count, real = ctypes.c_int64, ctypes.c_double
    library.tri_init.argtypes = [I64, count, D, D, count, D, count, D]
    library.tri_force.argtypes = [I64, count, D, D, D, D, count, D, count]
    library.tri_dforce.argtypes = [I64, count, D, D, real, D, D, count, D, count]
    library.tri_matrix.argtypes = [D, count, D, count, D, count, D]
    library.tf_init.argtypes = [I64, count, D, D, count, D, count, D]
    library.tf_force.argtypes = [I64, count, D, D, D]
    library.tf_dforce.argtypes = [I64, count, D, D, real, D]
    library.tb_force.argtypes = [I64, D, count, D, D, D, D]
    library.tb_dforce.argtypes = [I64, count, D, D, D, real]
    library.bend_force.argtypes = [I64, D, D, count, D, D]
    library.bend_energy.argtypes = [I64, D, D, count, D]
    library.bend_energy.restype = real
    library.bend_dforce.argtypes = [I64, D, D, count, D, D, real]
    library.bend_matrix.argtypes = [I64, D, D, count, real, D, count]
    return library


def rotation(axis: list[float], angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


class Triangles:
    def __init__(self, lib: ctypes.CDLL, rest: np.ndarray, tris: np.ndarray, young: float, nu: float) -> None:
        self.lib, self.rest = lib, np.ascontiguousarray(rest, dtype=float)
        self.tris = np.ascontiguousarray(tris, dtype=np.int64)
        self.n = len(self.tris)
        self.e, self.nu = np.array([young]), np.array([nu])
        self.data = np.zeros(10 * self.n)
        lib.tri_init(_i(self.tris), self.n, _d(self.rest), _d(self.e), 1, _d(self.nu), 1, _d(self.data))

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros(x.size)
        x = np.ascontiguousarray(x, dtype=float)
        self.lib.tri_force(_i(self.tris), self.n, _d(x), _d(f), _d(self.data), _d(self.e), 1, _d(self.nu), 1)
        return f

    def dforce(self, dx: np.ndarray, k: float = 1.0) -> np.ndarray:
        df = np.zeros(dx.size)
        dx = np.ascontiguousarray(dx, dtype=float)
        self.lib.tri_dforce(
            _i(self.tris), self.n, _d(dx), _d(df), k, _d(self.data), _d(self.e), 1, _d(self.nu), 1
        )
        return df


def plane_stress_forces(rest2d: np.ndarray, disp2d: np.ndarray, young: float, nu: float) -> np.ndarray:
    """Linear triangle, plane stress, unit thickness: f = -A B^T D B u."""
    (x1, y1), (x2, y2), (x3, y3) = rest2d
    area = 0.5 * ((x2 - x1) * (y3 - y1) - (x3 - x1) * (y2 - y1))
    b = np.array([y2 - y3, y3 - y1, y1 - y2]) / (2 * area)
    c = np.array([x3 - x2, x1 - x3, x2 - x1]) / (2 * area)
    big_b = np.zeros((3, 6))
    big_b[0, 0::2], big_b[1, 1::2], big_b[2, 0::2], big_b[2, 1::2] = b, c, c, b
    hooke = young / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    return -area * big_b.T @ hooke @ big_b @ disp2d.ravel()


@pytest.mark.parametrize("angle", [0.0, 0.7])
def test_optim_small_strain_is_the_plane_stress_triangle(lib: ctypes.CDLL, angle: float) -> None:
    """A small stretch of a triangle (any orientation in space): the forces are those of the exact
    constant-strain plane-stress triangle, rotated; E/(1+nu) and E nu/(1-nu^2) are SOFA's mu, gamma."""
    young, nu = 1200.0, 0.3
    rest2d = np.array([[0.0, 0.0], [2.0, 0.0], [0.5, 1.5]])
    disp2d = 1e-7 * np.array([[0.0, 0.0], [3.0, 0.0], [1.0, 2.0]])  # a moves nothing; b only along x
    frame = rotation([1.0, 2.0, 0.5], angle)
    rest = np.column_stack([rest2d, np.zeros(3)]) @ frame.T + [1.0, -2.0, 0.5]
    moved = np.column_stack([rest2d + disp2d, np.zeros(3)]) @ frame.T + [1.0, -2.0, 0.5]
    tri = Triangles(lib, rest, np.array([[0, 1, 2]]), young, nu)
    got = tri.force(moved.ravel()).reshape(3, 3) @ frame  # back to the triangle's plane
    expected = plane_stress_forces(rest2d, disp2d, young, nu).reshape(3, 2)
    assert np.abs(got[:, 2]).max() < 1e-12
    assert np.abs(got[:, :2] - expected).max() < 1e-6 * np.abs(expected).max()


def test_optim_rigid_motion_gives_no_force(lib: ctypes.CDLL) -> None:
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 1.1, 0.4], [1.2, 1.3, 0.1]])
    tri = Triangles(lib, rest, np.array([[0, 1, 2], [1, 3, 2]]), 500.0, 0.4)
    moved = rest @ rotation([0.3, -1.0, 2.0], 1.1).T + [5.0, 1.0, -2.0]
    assert np.abs(tri.force(moved.ravel())).max() < 1e-11


def test_optim_dforce_and_matrix_match_finite_differences(lib: ctypes.CDLL) -> None:
    rng = np.random.default_rng(4)
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 1.1, 0.4], [1.2, 1.3, 0.1]])
    tris = np.array([[0, 1, 2], [1, 3, 2]])
    tri = Triangles(lib, rest, tris, 500.0, 0.4)
    x = (rest + 0.1 * rng.standard_normal(rest.shape)).ravel()
    tri.force(x)  # stores the frames
    h = 1e-6
    jacobian = np.zeros((12, 12))
    for j in range(12):
        step = np.zeros(12)
        step[j] = h
        jacobian[:, j] = (tri.force(x + step) - tri.force(x - step)) / (2 * h)
    tri.force(x)
    analytic = np.column_stack([tri.dforce(np.eye(12)[j]) for j in range(12)])
    # SOFA's derivative keeps the frame fixed (it drops the frame's rotation): compare the symmetric
    # stiffness it uses against the finite differences on displacements that leave frames unchanged
    # to first order, i.e. in-plane motions of the first triangle's nodes.
    assert np.abs(tri.dforce(np.ones(12) * 0.0)).max() == 0.0
    assert np.allclose(analytic, analytic.T, atol=1e-9 * np.abs(analytic).max())
    matrix = np.zeros((12, 12))
    for e, nodes in enumerate(tris):
        out = np.zeros(81)
        lib.tri_matrix(_d(tri.data), e, _d(tri.e), 1, _d(tri.nu), 1, _d(out))
        block = out.reshape(9, 9)
        idx = np.concatenate([[3 * n, 3 * n + 1, 3 * n + 2] for n in nodes])
        matrix[np.ix_(idx, idx)] -= block
    assert np.abs(matrix - analytic).max() < 1e-10 * np.abs(analytic).max()
    # Against the finite differences: equal up to the geometric part, which vanishes at rest.
    tri2 = Triangles(lib, rest, tris, 500.0, 0.4)
    x0 = rest.ravel().copy()
    tri2.force(x0)
    fd = np.zeros((12, 12))
    for j in range(12):
        step = np.zeros(12)
        step[j] = h
        fd[:, j] = (tri2.force(x0 + step) - tri2.force(x0 - step)) / (2 * h)
    tri2.force(x0)
    at_rest = np.column_stack([tri2.dforce(np.eye(12)[j]) for j in range(12)])
    assert np.abs(at_rest - fd).max() < 1e-6 * np.abs(fd).max()
    assert np.abs(jacobian - analytic).max() < 0.5 * np.abs(analytic).max()  # same operator, plus rotation


# ---- FastTriangularBendingSprings ----------------------------------------------------------------

# Two triangles on the edge C=(0,0,0) D=(1,0,0); A=(0.5,1,0) in triangle 0, B=(0.5,-1,0) in triangle 1.
SQUARE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, -1.0, 0.0]])
SQUARE_TRIS = np.array([[0, 1, 2], [1, 0, 3]])
SQUARE_EDGES = np.array([[1, 2], [2, 0], [0, 1], [0, 3], [3, 1]])


def test_bending_spring_weights_and_stiffness_by_hand() -> None:
    """One spring (the shared edge): alpha = (1/2, 1/2, -1/2, -1/2) (equal triangle areas), heights
    1 and 1, edge length 1: lambda = 2/3 (1 + 1) / 1 * 1 * k."""
    vid, alpha, lam = bending_springs(SQUARE, SQUARE_TRIS, SQUARE_EDGES, 300.0, 1e-6)
    assert vid.tolist() == [[2, 3, 0, 1]]  # A in the lower triangle, then B, then the edge as stored
    assert alpha.tolist() == [[0.5, 0.5, -0.5, -0.5]]
    assert lam.tolist() == [pytest.approx(400.0, rel=1e-15)]
    none = bending_springs(SQUARE, SQUARE_TRIS[:1], SQUARE_EDGES[:3], 300.0, 1e-6)
    assert none[0].shape == (0, 4)  # a border edge has no spring


def test_bending_force_energy_and_derivative(lib: ctypes.CDLL) -> None:
    k, h = 300.0, 0.01
    vid, alpha, lam = bending_springs(SQUARE, SQUARE_TRIS, SQUARE_EDGES, k, 1e-6)
    args = (_i(vid), _d(alpha), _d(lam), len(lam))
    flat = np.zeros(12)
    lib.bend_force(*args, _d(SQUARE.ravel().copy()), _d(flat))
    assert np.abs(flat).max() == 0.0  # the flat rest shape
    lifted = SQUARE.copy()
    lifted[2, 2] = h  # A up by h: R = h/2 z, f_k = -R lambda alpha_k
    force = np.zeros(12)
    lib.bend_force(*args, _d(lifted.ravel().copy()), _d(force))
    expected = np.zeros((4, 3))
    expected[:, 2] = [h * k / 3, h * k / 3, -h * k / 3, -h * k / 3]  # nodes 0, 1 are C, D; 2, 3 are A, B
    assert np.abs(force.reshape(4, 3) - expected).max() < 1e-12 * k
    energy = lib.bend_energy(*args, _d(lifted.ravel().copy()))
    assert energy == pytest.approx(0.5 * (h / 2) ** 2 * 400.0, rel=1e-13)
    # The force is linear in x: K dx equals the force difference, and the assembled matrix K.
    rng = np.random.default_rng(1)
    dx = rng.standard_normal(12)
    f1 = np.zeros(12)
    lib.bend_force(*args, _d((lifted.ravel() + dx).copy()), _d(f1))
    df = np.zeros(12)
    lib.bend_dforce(*args, _d(dx), _d(df), 1.0)
    assert np.abs(df - (f1 - force)).max() < 1e-10 * np.abs(df).max()
    matrix = np.zeros((12, 12))
    lib.bend_matrix(*args, 2.0, _d(matrix), 12)
    assert np.abs(matrix @ dx - 2.0 * df).max() < 1e-10 * np.abs(df).max()


# ---- TriangularBendingSprings ----------------------------------------------------------------------


def test_triangular_bending_spring_force_and_derivative(lib: ctypes.CDLL) -> None:
    """One spring between points 0 and 1 (ks 40, kd 3, rest 2): F = ks (d - L) + kd u.(v1 - v0) along
    u, on 0 (+) and 1 (-); its stored df/dx equals finite differences of the force (kd = 0)."""
    springs = np.array([0, 1], dtype=np.int64)
    x = np.array([0.0, 0.0, 0.0, 1.5, 2.0, 0.0])  # d = 2.5
    v = np.array([0.0, 0.0, 0.0, 0.3, -0.1, 0.2])
    f, m = np.zeros(6), np.zeros(9)
    lib.tb_force(_i(springs), _d(np.array([40.0, 3.0, 2.0])), 1, _d(x), _d(v), _d(f), _d(m))
    u = np.array([1.5, 2.0, 0.0]) / 2.5
    intensity = 40.0 * 0.5 + 3.0 * (u @ v[3:])
    assert np.abs(f - np.concatenate([u * intensity, -u * intensity])).max() < 1e-13
    params = np.array([40.0, 0.0, 2.0])
    lib.tb_force(_i(springs), _d(params), 1, _d(x), _d(np.zeros(6)), _d(np.zeros(6)), _d(m))
    h = 1e-6
    fd = np.zeros((6, 6))
    for j in range(6):
        plus, minus = np.zeros(6), np.zeros(6)
        lib.tb_force(
            _i(springs), _d(params), 1, _d(x + h * np.eye(6)[j]), _d(np.zeros(6)), _d(plus), _d(np.zeros(9))
        )
        lib.tb_force(
            _i(springs), _d(params), 1, _d(x - h * np.eye(6)[j]), _d(np.zeros(6)), _d(minus), _d(np.zeros(9))
        )
        fd[:, j] = (plus - minus) / (2 * h)
    analytic = np.zeros((6, 6))
    for j in range(6):
        df = np.zeros(6)
        lib.tb_dforce(_i(springs), 1, _d(m), _d(np.eye(6)[j].copy()), _d(df), 1.0)
        analytic[:, j] = df
    assert np.abs(analytic - fd).max() < 1e-6 * np.abs(fd).max()


def test_triangular_bending_springs_join_opposite_vertices(tmp_path: Path) -> None:
    """Two triangles (0 1 2) and (1 3 2) share the edge 1-2: one spring, between 3 (the later
    triangle's opposite vertex) and 0, of the rest length |x3 - x0|."""
    scene = tmp_path / "bend.scn"
    scene.write_text(
        """<Node name="root" dt="0.01" gravity="0 0 -1">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver/>
  <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
  <TriangleSetTopologyContainer name="topo" position="0 0 0  1 0 0  0 1 0  1 1 0.5" triangles="0 1 2  1 3 2"/>
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="1"/>
  <TriangularBendingSprings name="bend" stiffness="300" damping="2"/>
</Node>
"""
    )
    plan = compile_scene(scene).plan
    assert plan.buffer("/bend.springs").initial.tolist() == [3, 0]
    assert plan.buffer("/bend.springParams").initial.tolist() == [300.0, 2.0, 1.5]


# ---- TriangularFEMForceField (large) ---------------------------------------------------------------


class LargeTriangles:
    def __init__(self, lib: ctypes.CDLL, rest: np.ndarray, tris: np.ndarray, young: float, nu: float) -> None:
        self.lib, self.tris, self.n = lib, np.ascontiguousarray(tris, dtype=np.int64), len(tris)
        self.data = np.zeros(35 * self.n)
        rest = np.ascontiguousarray(rest, dtype=float)
        lib.tf_init(
            _i(self.tris), self.n, _d(rest), _d(np.array([young])), 1, _d(np.array([nu])), 1, _d(self.data)
        )

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros(x.size)
        self.lib.tf_force(
            _i(self.tris), self.n, _d(np.ascontiguousarray(x, dtype=float)), _d(f), _d(self.data)
        )
        return f

    def dforce(self, dx: np.ndarray) -> np.ndarray:
        df = np.zeros(dx.size)
        self.lib.tf_dforce(_i(self.tris), self.n, _d(np.ascontiguousarray(dx)), _d(df), 1.0, _d(self.data))
        return df


@pytest.mark.parametrize("angle", [0.0, 0.7])
def test_large_triangle_small_strain_is_the_plane_stress_triangle(lib: ctypes.CDLL, angle: float) -> None:
    young, nu = 1200.0, 0.3
    rest2d = np.array([[0.0, 0.0], [2.0, 0.0], [0.5, 1.5]])
    disp2d = 1e-7 * np.array([[0.0, 0.0], [3.0, 0.0], [1.0, 2.0]])
    frame = rotation([1.0, 2.0, 0.5], angle)
    rest = np.column_stack([rest2d, np.zeros(3)]) @ frame.T + [1.0, -2.0, 0.5]
    moved = np.column_stack([rest2d + disp2d, np.zeros(3)]) @ frame.T + [1.0, -2.0, 0.5]
    tri = LargeTriangles(lib, rest, np.array([[0, 1, 2]]), young, nu)
    got = tri.force(moved.ravel()).reshape(3, 3) @ frame
    expected = plane_stress_forces(rest2d, disp2d, young, nu).reshape(3, 2)
    assert np.abs(got[:, 2]).max() < 1e-12
    assert np.abs(got[:, :2] - expected).max() < 1e-6 * np.abs(expected).max()
    # At rest the stored derivative is the plane-stress stiffness: compare with finite differences.
    tri.force(rest.ravel())
    h = 1e-6
    fd = np.column_stack(
        [(tri.force(rest.ravel() + h * e) - tri.force(rest.ravel() - h * e)) / (2 * h) for e in np.eye(9)]
    )
    tri.force(rest.ravel())
    analytic = np.column_stack([tri.dforce(e.copy()) for e in np.eye(9)])
    assert np.abs(analytic - fd).max() < 1e-6 * np.abs(fd).max()
