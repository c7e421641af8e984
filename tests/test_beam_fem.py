"""Beams between rigid frames (runtime/sofac/beam.h): BeamFEMForceField, BTDLinearSolver and
BeamLinearMapping.

Kernels, as C++ through a shim: the local stiffness against the Euler-Bernoulli beam matrix
(SOFA's shear areas are zero), the forces' derivative at rigidly moved rest shapes (where the
corotational stiffness R K R^T is the exact tangent) against finite differences, zero force under
any rigid motion, K dx against the assembled element matrix; the block-tridiagonal solve against a
dense solve; the mapping's J and J^T against each other, against finite differences of its apply
and against SOFA's formulas. Scenes: a cantilever's static tip deflection and rotation under a tip
load against Euler-Bernoulli, BTD against a sparse direct solve, and SOFA's BeamFEMForceField.scn
without its floor (tests/data/beam_fem_no_floor.scn).
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import I64, D, build_shim, doubles, indices

DATA = Path(__file__).parent / "data"

SHIM = r"""
#include "sofac/beam.h"
#include <Eigen/Sparse>
#include <vector>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

API void init(const Index* edges, Index n, const double* x0, const double* young, Index n_young,
              const double* poisson, Index n_poisson, double r, double r_inner, double* kloc,
              double* frames) {
    sofac::beam_fem_init(edges, n, x0, young, n_young, poisson, n_poisson, r, r_inner, kloc, frames);
}
API void add_force(const Index* edges, const Index* used, Index n, const double* kloc, const double* x0,
                   const double* x, double* f, double* frames) {
    sofac::beam_fem_add_force(edges, used, n, kloc, x0, x, f, frames);
}
API void add_dforce(const Index* edges, const Index* used, Index n, const double* kloc, const double* frames,
                    const double* dx, double* df, double kfact) {
    sofac::beam_fem_add_dforce(edges, used, n, kloc, frames, dx, df, kfact);
}
API void world_stiffness(const double* k0, const double* frame, int symmetric, double* k) {
    sofac::beam_fem_world_stiffness(k0, frame, symmetric != 0, k);
}
// A dense (6 blocks x 6) matrix through the sparse matrix the step assembles, then BTD.
API int btd_solve(const double* a, Index blocks, const double* b, double* x) {
    const Index n = 6 * blocks;
    Eigen::SparseMatrix<double> m(n, n);
    std::vector<Eigen::Triplet<double>> entries;
    for (Index i = 0; i < n; ++i)
        for (Index j = 0; j < n; ++j)
            if (a[n * i + j] != 0.0) entries.emplace_back(i, j, a[n * i + j]);
    m.setFromTriplets(entries.begin(), entries.end());
    sofac::BlockTridiagonal t;
    t.resize(blocks);
    t.add_matrix(m);
    t.factor();
    t.solve(b, x);
    return t.ok ? 1 : 0;
}
// Entries through BTDMatrix's add, then its projection of the `fixed` scalar DOFs: the band's
// 3 x blocks blocks (row-major 6x6 each) and the count of entries past the last row.
API Index btd_band(const Index* rows, const Index* cols, const double* values, Index count, Index blocks,
                   const char* fixed, double* band) {
    sofac::BlockTridiagonal t;
    t.resize(blocks);
    for (Index k = 0; k < count; ++k) t.add(rows[k], cols[k], values[k]);
    t.project(std::vector<char>(fixed, fixed + 6 * blocks));
    for (Index k = 0; k < 3 * blocks; ++k) std::copy_n(t.band[k].m, 36, band + 36 * k);
    return t.overflows;
}
API void block_invert(const double* m, double* inv) {
    sofac::Block6 a, r;
    for (int k = 0; k < 36; ++k) a.m[k] = m[k];
    sofac::btd_invert(r, a);
    for (int k = 0; k < 36; ++k) inv[k] = r.m[k];
}
API void map_apply(const double* in_x, double* out_x, const Index* frame, const double* local,
                   const double* length, double* rotated, Index n) {
    sofac::beam_linear_apply(in_x, out_x, frame, local, length, rotated, n);
}
API void map_j(const double* in_v, double* out_v, const Index* frame, const double* local,
               const double* rotated, Index n) {
    sofac::beam_linear_apply_j(in_v, out_v, frame, local, rotated, n);
}
API void map_jt(double* in_f, const double* out_f, const Index* frame, const double* local,
                const double* rotated, Index n) {
    sofac::beam_linear_apply_jt(in_f, out_f, frame, local, rotated, n);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    lib = build_shim(tmp_path_factory, "beam", SHIM)
    i64 = ctypes.c_int64
    lib.init.argtypes = [I64, i64, D, D, i64, D, i64, ctypes.c_double, ctypes.c_double, D, D]
    lib.add_force.argtypes = [I64, I64, i64, D, D, D, D, D]
    lib.add_dforce.argtypes = [I64, I64, i64, D, D, D, D, ctypes.c_double]
    lib.world_stiffness.argtypes = [D, D, ctypes.c_int, D]
    lib.btd_solve.argtypes = [D, i64, D, D]
    lib.btd_solve.restype = ctypes.c_int
    lib.btd_band.argtypes = [I64, I64, D, i64, i64, ctypes.c_char_p, D]
    lib.btd_band.restype = i64
    lib.block_invert.argtypes = [D, D]
    lib.map_apply.argtypes = [D, D, I64, D, D, D, i64]
    lib.map_j.argtypes = [D, D, I64, D, D, i64]
    lib.map_jt.argtypes = [D, D, I64, D, D, i64]
    return lib


# --- quaternions (x y z w), as Rigid3d stores them ---------------------------------------------


def quat_from_rotation_vector(w: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    return np.concatenate([np.asarray(w) / angle * math.sin(angle / 2), [math.cos(angle / 2)]])


def quat_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    va, vb = a[:3], b[:3]
    return np.concatenate([a[3] * vb + b[3] * va + np.cross(va, vb), [a[3] * b[3] - va @ vb]])


def rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def moved(x: np.ndarray, dx: np.ndarray, h: float) -> np.ndarray:
    """Rigid frames x (n, 7) moved by h dx (n, 6): centres translated, orientations turned by the
    world rotation vector h w (SOFA's Rigid3 integration)."""
    out = x.copy()
    for i in range(len(x)):
        out[i, :3] += h * dx[i, :3]
        out[i, 3:] = quat_product(quat_from_rotation_vector(h * dx[i, 3:]), x[i, 3:])
    return out


# --- BeamFEMForceField ---------------------------------------------------------------------------

E, NU, RADIUS = 2.0e7, 0.49, 0.1


class Beams:
    """A chain of beams (n frames along a bent line, random orientations at rest) and its kernels."""

    def __init__(
        self, lib: ctypes.CDLL, rest: np.ndarray, radius: float = RADIUS, inner: float = 0.0
    ) -> None:
        self.lib = lib
        self.rest = np.ascontiguousarray(rest, dtype=float)
        n = len(rest)
        self.edges = np.array([[i, i + 1] for i in range(n - 1)], dtype=np.int64).ravel()
        self.count = n - 1
        self.used = np.arange(self.count, dtype=np.int64)
        self.kloc = np.zeros(144 * self.count)
        self.frames = np.zeros(4 * self.count)
        young, poisson = np.array([E]), np.array([NU])
        lib.init(
            indices(self.edges),
            self.count,
            doubles(self.rest),
            doubles(young),
            1,
            doubles(poisson),
            1,
            radius,
            inner,
            doubles(self.kloc),
            doubles(self.frames),
        )

    def force(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=float)
        f = np.zeros(6 * len(x))
        self.lib.add_force(
            indices(self.edges),
            indices(self.used),
            len(self.used),
            doubles(self.kloc),
            doubles(self.rest),
            doubles(x),
            doubles(f),
            doubles(self.frames),
        )
        return f

    def dforce(self, dx: np.ndarray, kfact: float = 1.0) -> np.ndarray:
        dx = np.ascontiguousarray(dx, dtype=float).ravel()
        df = np.zeros_like(dx)
        self.lib.add_dforce(
            indices(self.edges),
            indices(self.used),
            len(self.used),
            doubles(self.kloc),
            doubles(self.frames),
            doubles(dx),
            doubles(df),
            kfact,
        )
        return df

    def world(self, element: int, symmetric: bool = False) -> np.ndarray:
        k = np.zeros(144)
        k0 = np.ascontiguousarray(self.kloc[144 * element : 144 * (element + 1)])
        frame = np.ascontiguousarray(self.frames[4 * element : 4 * (element + 1)])
        self.lib.world_stiffness(doubles(k0), doubles(frame), int(symmetric), doubles(k))
        return k.reshape(12, 12)


def random_rest(seed: int, n: int = 4) -> np.ndarray:
    """Frames along a bent line, each turned by its own random rotation."""
    rng = np.random.default_rng(seed)
    rest = np.zeros((n, 7))
    for i in range(n):
        rest[i, :3] = [1.0 * i, 0.3 * math.sin(i), 0.2 * i * i / n] + 0.05 * rng.standard_normal(3)
        rest[i, 3:] = quat_from_rotation_vector(0.4 * rng.standard_normal(3))
    return rest


def straight_rest(seed: int, n: int = 4) -> np.ndarray:
    """Frames along a straight line in a random direction, all with the orientation whose x axis
    is that direction (a random roll about it): beams as SOFA expects them."""
    rng = np.random.default_rng(seed)
    q = quat_from_rotation_vector(rng.standard_normal(3))
    axis = rotation(q) @ [1.0, 0.0, 0.0]
    rest = np.zeros((n, 7))
    lengths = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 1.5, n - 1))])
    for i in range(n):
        rest[i, :3] = lengths[i] * axis
        rest[i, 3:] = q
    return rest


def euler_bernoulli(length: float, radius: float, inner: float = 0.0) -> np.ndarray:
    """The 12x12 Euler-Bernoulli beam matrix (local axes: x along the beam), DOFs u v w tx ty tz
    of each end, written out from the textbook, not from SOFA."""
    inertia = math.pi * (radius**4 - inner**4) / 4
    area = math.pi * (radius**2 - inner**2)
    shear = E / (2 * (1 + NU))
    L = length
    k = np.zeros((12, 12))

    def couple(i: int, j: int, value: float) -> None:
        k[i, j] += value
        if i != j:
            k[j, i] += value

    for a, b, stiffness in ((0, 6, E * area / L), (3, 9, shear * 2 * inertia / L)):
        couple(a, a, stiffness)
        couple(b, b, stiffness)
        couple(a, b, -stiffness)
    ei = E * inertia
    # bending in the x-y plane: v (1, 7) with theta_z (5, 11); in x-z: w (2, 8) with theta_y (4, 10),
    # whose sign is opposite (theta_y = -dw/dx)
    for v, t, sign in ((1, 5, 1.0), (2, 4, -1.0)):
        v2, t2 = v + 6, t + 6
        couple(v, v, 12 * ei / L**3)
        couple(v2, v2, 12 * ei / L**3)
        couple(v, v2, -12 * ei / L**3)
        for node_t in (t, t2):
            couple(v, node_t, sign * 6 * ei / L**2)
            couple(v2, node_t, -sign * 6 * ei / L**2)
        couple(t, t, 4 * ei / L)
        couple(t2, t2, 4 * ei / L)
        couple(t, t2, 2 * ei / L)
    return k


@pytest.mark.parametrize("inner", [0.0, 0.04])
def test_local_stiffness_is_the_euler_bernoulli_beam_matrix(lib: ctypes.CDLL, inner: float) -> None:
    rest = np.zeros((2, 7))
    rest[1, 0] = 1.7
    rest[:, 6] = 1.0
    beams = Beams(lib, rest, inner=inner)
    expected = euler_bernoulli(1.7, RADIUS, inner)
    np.testing.assert_allclose(beams.kloc.reshape(12, 12), expected, rtol=1e-13, atol=1e-9 * expected.max())


def test_per_element_young_modulus_is_read_for_each_beam(lib: ctypes.CDLL) -> None:
    rest = np.zeros((3, 7))
    rest[:, 0] = [0.0, 1.0, 2.0]
    rest[:, 6] = 1.0
    edges = np.array([0, 1, 1, 2], dtype=np.int64)
    kloc, frames = np.zeros(288), np.zeros(8)
    young, poisson = np.array([1.0e6, 3.0e6]), np.array([0.3])
    lib.init(
        indices(edges),
        2,
        doubles(rest),
        doubles(young),
        2,
        doubles(poisson),
        1,
        0.1,
        0.0,
        doubles(kloc),
        doubles(frames),
    )
    area = math.pi * 0.01
    assert kloc[0] == pytest.approx(1.0e6 * area)
    assert kloc[144] == pytest.approx(3.0e6 * area)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_rigid_motion_gives_no_force(lib: ctypes.CDLL, seed: int) -> None:
    rest = random_rest(seed)
    beams = Beams(lib, rest)
    rng = np.random.default_rng(100 + seed)
    turn = quat_from_rotation_vector(2.5 * rng.standard_normal(3) / math.sqrt(3))  # large rotation
    shift = rng.standard_normal(3)
    x = rest.copy()
    for i in range(len(rest)):
        x[i, :3] = rotation(turn) @ rest[i, :3] + shift
        x[i, 3:] = quat_product(turn, rest[i, 3:])
    scale = np.abs(beams.force(moved(rest, rng.standard_normal((len(rest), 6)), 1e-3))).max()
    assert np.abs(beams.force(x)).max() < 1e-8 * scale


@pytest.mark.parametrize("seed", [0, 1])
def test_stiffness_is_the_derivative_of_the_forces_at_a_moved_rest_shape(lib: ctypes.CDLL, seed: int) -> None:
    """At any rigid placement of the rest shape the corotational K = -R K_loc R^T is the exact
    derivative of the forces: central differences of f along random rigid-frame increments. (For
    beams as SOFA builds them: both ends' frames with their x axis along the beam; otherwise
    K_loc's rigid modes are not the beam's and K is not the tangent.)"""
    rest = straight_rest(seed)
    beams = Beams(lib, rest)
    rng = np.random.default_rng(10 + seed)
    turn = quat_from_rotation_vector(rng.standard_normal(3))
    x = rest.copy()
    for i in range(len(rest)):
        x[i, :3] = rotation(turn) @ rest[i, :3]
        x[i, 3:] = quat_product(turn, rest[i, 3:])
    beams.force(x)  # sets the beams' frames, as a step's force pass does
    frames = beams.frames.copy()
    for _ in range(3):
        dx = rng.standard_normal((len(rest), 6))
        h = 1e-6
        numeric = (beams.force(moved(x, dx, h)) - beams.force(moved(x, dx, -h))) / (2 * h)
        beams.frames[:] = frames
        analytic = beams.dforce(dx)
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-5 * np.abs(analytic).max())


@pytest.mark.parametrize("symmetric", [False, True])
def test_k_dx_is_the_assembled_element_matrix(lib: ctypes.CDLL, symmetric: bool) -> None:
    """addDForce and the matrix that addKToMatrix / buildStiffnessMatrix assemble agree, at a
    deformed configuration (useSymmetricAssembly gives the same matrix: K_loc is symmetric)."""
    rest = random_rest(3, n=2)
    beams = Beams(lib, rest)
    rng = np.random.default_rng(7)
    beams.force(moved(rest, rng.standard_normal((2, 6)), 0.2))
    k = beams.world(0, symmetric)
    np.testing.assert_allclose(k, k.T, atol=1e-9 * np.abs(k).max())
    for _ in range(3):
        dx = rng.standard_normal(12)
        np.testing.assert_allclose(
            beams.dforce(dx, kfact=2.0), -2.0 * k @ dx, rtol=1e-12, atol=1e-9 * np.abs(k).max()
        )


def test_a_small_bend_gives_the_beam_forces(lib: ctypes.CDLL) -> None:
    """A straight beam whose end b is moved by a small transverse displacement: the forces are
    those of the linear beam, f = -K [0, d_b]."""
    rest = np.zeros((2, 7))
    rest[1, 0] = 2.0
    rest[:, 6] = 1.0
    beams = Beams(lib, rest)
    d = np.zeros((2, 6))
    d[1] = [0.0, 1e-5, 0.0, 0.0, 0.0, 0.0]
    f = beams.force(moved(rest, d, 1.0))
    expected = -euler_bernoulli(2.0, RADIUS) @ d.ravel()
    np.testing.assert_allclose(f, expected, rtol=0, atol=1e-6 * np.abs(expected).max())


def test_list_segment_restricts_the_forces_to_its_beams(lib: ctypes.CDLL) -> None:
    """listSegment: only the listed beams act; the forces of two subsets add up to all beams'."""
    rest = straight_rest(5, n=4)
    beams = Beams(lib, rest)
    x = moved(rest, np.random.default_rng(1).standard_normal((4, 6)), 0.01)
    every = beams.force(x)
    beams.used = np.array([1], dtype=np.int64)
    middle = beams.force(x)
    assert np.all(middle[:6] == 0.0) and np.all(middle[18:] == 0.0)  # frames 0 and 3: not in beam 1
    beams.used = np.array([0, 2], dtype=np.int64)
    np.testing.assert_allclose(middle + beams.force(x), every, rtol=1e-12, atol=1e-9)


# --- BTDLinearSolver -----------------------------------------------------------------------------


def block_tridiagonal_spd(seed: int, blocks: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = 6 * blocks
    a = np.zeros((n, n))
    for i in range(blocks - 1):  # a sum of SPD couplings between neighbours, plus a diagonal
        g = rng.standard_normal((12, 12))
        a[6 * i : 6 * i + 12, 6 * i : 6 * i + 12] += g @ g.T
    a += np.diag(rng.uniform(0.5, 2.0, n))
    return a


@pytest.mark.parametrize(("seed", "blocks"), [(0, 2), (1, 5), (2, 9)])
def test_btd_solves_block_tridiagonal_spd_systems(lib: ctypes.CDLL, seed: int, blocks: int) -> None:
    a = block_tridiagonal_spd(seed, blocks)
    b = np.random.default_rng(50 + seed).standard_normal(6 * blocks)
    x = np.zeros_like(b)
    assert lib.btd_solve(doubles(np.ascontiguousarray(a)), blocks, doubles(b), doubles(x)) == 1
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12 * np.abs(x).max())


def test_btd_matrix_add_and_projection_are_sofas(lib: ctypes.CDLL) -> None:
    """BTDMatrix::add drops an entry right of the band but writes one left of it at block index
    3 bi + (bj - bi + 1), inside another block of the band (SOFA's penalty contacts with a static
    partner make such entries); clearRowCol clears a fixed DOF's row and column inside the band only."""
    entries = [
        (7, 8, 2.0),  # block (1, 1): in place
        (1, 19, 3.0),  # block (0, 3), right of the band: dropped
        (19, 1, 5.0),  # block (3, 0): index 9 - 2 = 7, the diagonal block of row 2
        (13, 0, 7.0),  # block (2, 0): index 6 - 1 = 5, the upper block of row 1, column 0 of it
        (2, 9, 11.0),  # block (0, 1), a fixed row: cleared
        (9, 2, 13.0),  # block (1, 0), a fixed column: cleared
        (25, 3, 1.0),  # row 25 of a 24 x 24 matrix: counted, not written
    ]
    rows = np.array([e[0] for e in entries], dtype=np.int64)
    cols = np.array([e[1] for e in entries], dtype=np.int64)
    values = np.array([e[2] for e in entries])
    band = np.zeros(3 * 4 * 36)
    fixed = bytes([1] * 6 + [0] * 18)
    overflows = lib.btd_band(
        indices(rows), indices(cols), doubles(values), len(entries), 4, fixed, doubles(band)
    )
    band = band.reshape(4, 3, 6, 6)  # block row, (lower, diagonal, upper), 6 x 6
    expected = np.zeros_like(band)
    expected[0, 1] = np.eye(6)  # the fixed DOF: 1 on its diagonal
    expected[1, 1, 1, 2] = 2.0
    expected[2, 1, 1, 1] = 5.0
    expected[1, 2, 1, 0] = 7.0  # column 0 of block (1, 2) is not in the band's column 0
    assert overflows == 1
    np.testing.assert_array_equal(band, expected)


def test_btd_with_projected_blocks(lib: ctypes.CDLL) -> None:
    """A fixed frame's rows and columns cleared with 1 on the diagonal (its blocks take SOFA's
    diagonal path): the solution's block is b's, the rest is the reduced system's solution."""
    a = block_tridiagonal_spd(4, 4)
    a[:6, :] = 0.0
    a[:, :6] = 0.0
    a[:6, :6] = np.eye(6)
    b = np.random.default_rng(3).standard_normal(24)
    x = np.zeros_like(b)
    assert lib.btd_solve(doubles(np.ascontiguousarray(a)), 4, doubles(b), doubles(x)) == 1
    np.testing.assert_array_equal(x[:6], b[:6])
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10)


def test_block_inversion_paths(lib: ctypes.CDLL) -> None:
    """SOFA's BTD invert: a block whose rows have nothing right of the diagonal above 1e-10 of it
    is inverted as a diagonal (its lower part ignored); any other by Gauss-Jordan."""
    lower = np.diag(np.arange(1.0, 7.0))
    lower[3, 1] = 0.5  # below the diagonal: not looked at
    inv = np.zeros(36)
    lib.block_invert(doubles(np.ascontiguousarray(lower)), doubles(inv))
    np.testing.assert_array_equal(inv.reshape(6, 6), np.diag(1.0 / np.arange(1.0, 7.0)))
    full = block_tridiagonal_spd(8, 2)[:6, :6].copy()
    lib.block_invert(doubles(np.ascontiguousarray(full)), doubles(inv))
    np.testing.assert_allclose(inv.reshape(6, 6) @ full, np.eye(6), atol=1e-12)


# --- BeamLinearMapping ---------------------------------------------------------------------------


def sofa_beam_mapping(
    frames: np.ndarray, first: np.ndarray, local: np.ndarray, length: np.ndarray
) -> np.ndarray:
    """BeamLinearMapping::apply written from SOFA's formula with rotation matrices."""
    out = []
    for in0, p, L in zip(first, local, length, strict=True):
        a, b = frames[in0], frames[in0 + 1]
        s = 3 * p[0] ** 2 - 2 * p[0] ** 3
        out0 = a[:3] + rotation(a[3:]) @ p * L
        out1 = b[:3] + rotation(b[3:]) @ (p - [1.0, 0.0, 0.0]) * L
        out.append(out0 * (1 - s) + out1 * s)
    return np.array(out)


def mapping_setup(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    frames = random_rest(seed, n=4)
    first = rng.integers(0, 3, 6).astype(np.int64)
    local = np.column_stack([rng.uniform(0, 1, 6), 0.2 * rng.standard_normal((6, 2))])
    length = rng.uniform(0.5, 1.5, 6)
    return frames, first, np.ascontiguousarray(local), length


def run_mapping(
    lib: ctypes.CDLL, frames: np.ndarray, first: np.ndarray, local: np.ndarray, length: np.ndarray
):
    n = len(first)
    out = np.zeros(3 * n)
    rotated = np.zeros(6 * n)
    lib.map_apply(
        doubles(np.ascontiguousarray(frames)),
        doubles(out),
        indices(first),
        doubles(local),
        doubles(length),
        doubles(rotated),
        n,
    )
    return out.reshape(-1, 3), rotated


@pytest.mark.parametrize("seed", [0, 1])
def test_beam_mapping_apply_is_sofas_formula(lib: ctypes.CDLL, seed: int) -> None:
    frames, first, local, length = mapping_setup(seed)
    out, _ = run_mapping(lib, frames, first, local, length)
    np.testing.assert_allclose(out, sofa_beam_mapping(frames, first, local, length), rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("seed", [0, 1])
def test_beam_mapping_j_and_jt(lib: ctypes.CDLL, seed: int) -> None:
    """<J dx, f> = <dx, J^T f>, and J dx is the derivative of apply along dx."""
    frames, first, local, length = mapping_setup(seed)
    _, rotated = run_mapping(lib, frames, first, local, length)
    rng = np.random.default_rng(20 + seed)
    n = len(first)
    dx = rng.standard_normal((len(frames), 6))
    f = rng.standard_normal(3 * n)
    jdx, jtf = np.zeros(3 * n), np.zeros(6 * len(frames))
    lib.map_j(
        doubles(np.ascontiguousarray(dx.ravel())),
        doubles(jdx),
        indices(first),
        doubles(local),
        doubles(rotated),
        n,
    )
    lib.map_jt(doubles(jtf), doubles(f), indices(first), doubles(local), doubles(rotated), n)
    assert jdx @ f == pytest.approx(dx.ravel() @ jtf, rel=1e-12)
    h = 1e-6
    plus, _ = run_mapping(lib, moved(frames, dx, h), first, local, length)
    minus, _ = run_mapping(lib, moved(frames, dx, -h), first, local, length)
    np.testing.assert_allclose(jdx, ((plus - minus) / (2 * h)).ravel(), rtol=0, atol=1e-7 * np.abs(jdx).max())


def test_beam_mapping_global_coordinates_map_points_back() -> None:
    """localCoord false: points given in world space are expressed along the beams at init
    (SOFA's init), and the first apply puts them back where they were."""
    from sofac.plan.lower.beams import beam_mapping_points

    frames = np.zeros((3, 7))
    frames[:, 0] = [0.0, 2.0, 3.0]
    frames[:, 6] = 1.0
    points = np.array([[0.5, 0.1, -0.2], [2.5, 0.0, 0.3], [1.0, 0.2, 0.0]])
    first, local, length = beam_mapping_points(frames, points, local_coord=False)
    assert first.tolist() == [0, 1, 0]
    np.testing.assert_allclose(length, [2.0, 1.0, 2.0])
    np.testing.assert_allclose(sofa_beam_mapping(frames, first, local, length), points, atol=1e-15)


# --- scenes --------------------------------------------------------------------------------------

CANTILEVER = """<?xml version="1.0"?>
<Node name="root" dt="1" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <Node name="beam">
    <StaticSolver/>
    <NewtonRaphsonSolver maxNbIterationsNewton="20" absoluteResidualStoppingThreshold="1e-12"/>
    <{solver} template="{template}"/>
    <MechanicalObject template="Rigid3d" name="frames" position="{positions}"/>
    <MeshTopology lines="{lines}"/>
    <FixedProjectiveConstraint indices="0"/>
    <UniformMass totalMass="1"/>
    <BeamFEMForceField radius="{radius}" youngModulus="{young}" poissonRatio="0.3"/>
    <ConstantForceField indices="{tip}" forces="0 {load} 0 0 0 0"/>
  </Node>
</Node>
"""


def cantilever(folder: Path, solver: str, template: str, segments: int = 6) -> sofac.Simulation:
    length, radius, young, load = 3.0, 0.05, 1.0e7, -0.01
    positions = "  ".join(f"{length * i / segments} 0 0 0 0 0 1" for i in range(segments + 1))
    lines = " ".join(f"{i} {i + 1}" for i in range(segments))
    path = folder / f"cantilever_{solver}.scn"
    path.write_text(
        CANTILEVER.format(
            solver=solver,
            template=template,
            positions=positions,
            lines=lines,
            radius=radius,
            young=young,
            tip=segments,
            load=load,
        )
    )
    return sofac.load(path)


@pytest.fixture(scope="module")
def btd_cantilever(tmp_path_factory: pytest.TempPathFactory) -> sofac.Simulation:
    return cantilever(tmp_path_factory.mktemp("cantilever"), "BTDLinearSolver", "BTDMatrix6d")


def test_cantilever_tip_deflection_and_rotation_are_euler_bernoulli(btd_cantilever: sofac.Simulation) -> None:
    """A clamped beam under a small tip load P: tip deflection P L^3 / (3 E I) and rotation
    P L^2 / (2 E I) (cubic beam elements are exact at the nodes for a tip load; the load is small
    enough that the corotational formulation's geometric terms stay below 1e-5)."""
    sim = btd_cantilever
    sim.reset()
    sim.step(1)
    inertia = math.pi * 0.05**4 / 4
    ei = 1.0e7 * inertia
    tip = sim["frames"].position[-1]
    deflection = -0.01 * 3.0**3 / (3 * ei)
    assert abs(deflection / 3.0) < 0.01  # small: a linear regime
    assert tip[1] == pytest.approx(deflection, rel=1e-4)
    angle = 2 * math.atan2(tip[5], tip[6])  # about z
    assert angle == pytest.approx(-0.01 * 3.0**2 / (2 * ei), rel=1e-4)
    # the deflected shape along the beam: v(x) = P x^2 (3 L - x) / (6 E I)
    x = sim["frames"].position[:, 0]
    np.testing.assert_allclose(
        sim["frames"].position[:, 1], -0.01 * x**2 * (3 * 3.0 - x) / (6 * ei), rtol=2e-4, atol=1e-9
    )


def test_btd_and_a_sparse_direct_solve_agree_on_a_cantilever(
    btd_cantilever: sofac.Simulation, tmp_path: Path
) -> None:
    btd = btd_cantilever
    ldl = cantilever(tmp_path, "SparseLDLSolver", "CompressedRowSparseMatrixMat3x3d")
    btd.reset()
    btd.step(1)
    ldl.step(1)
    np.testing.assert_allclose(btd["frames"].position, ldl["frames"].position, rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def floorless() -> sofac.Simulation:
    with pytest.warns(sofac.SceneWarning):  # W230, the anisotropic inertia SOFA keeps in world axes
        return sofac.load(DATA / "beam_fem_no_floor.scn")


def test_floorless_scene_beams_fall_as_cantilevers(floorless: sofac.Simulation) -> None:
    """SOFA's BeamFEMForceField.scn without its floor: the clamped beams sag under gravity, the
    two BTD beams identically (same beams, same masses), the fixed frames stay; the second beam's
    surface starts on CubeTopology's points and follows its frames by SOFA's formula."""
    floorless.reset()
    # CubeTopology nx=15 ny=2 nz=2 between (0 -0.1 -0.1) and (7 0.1 0.1): its z = min plane
    # (x fastest, then y), then its z = max plane; no point in between
    grid = np.linspace(0.0, 7.0, 15)
    points = np.array([[x, y, z] for z in (-0.1, 0.1) for y in (-0.1, 0.1) for x in grid])
    surface = floorless["/beam-withTriangulatedCubeCollision/Collision/surface"].position
    np.testing.assert_allclose(surface, points + np.array([0.0, 0.0, -1.0]), atol=1e-15)  # frames at z = -1
    floorless.step(30)
    first = floorless["/beam-withPointCollision/DOFs"].position
    second = floorless["/beam-withTriangulatedCubeCollision/DOFs"].position
    np.testing.assert_array_equal(first[0], [0, 0, 0, 0, 0, 0, 1])
    np.testing.assert_allclose(second[:, [0, 1]], first[:, [0, 1]], atol=1e-12)
    np.testing.assert_allclose(second[:, 2], first[:, 2] - 1.0, atol=1e-12)
    assert np.all(np.diff(first[:, 1]) < 0)  # sagging further along the beam
    # localCoord (the default): the points are beam coordinates; beams of length 1
    first_frame = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, 6)
    local = points - np.column_stack([first_frame, np.zeros((60, 2))])
    expected = sofa_beam_mapping(second, first_frame, local, np.ones(60))
    surface = floorless["/beam-withTriangulatedCubeCollision/Collision/surface"].position
    np.testing.assert_allclose(surface, expected, rtol=0, atol=1e-12)


# --- what is refused -----------------------------------------------------------------------------

REFUSED = """<?xml version="1.0"?>
<Node name="root" dt="0.01">
  <Node name="beam">
    <EulerImplicitSolver/>
    <{solver}/>
    <MechanicalObject template="{template}" position="{positions}"/>
    <MeshTopology lines="{lines}"/>
    <UniformMass totalMass="1"/>
    <BeamFEMForceField radius="0.1"/>
  </Node>
</Node>
"""

RIGID3 = "0 0 0 0 0 0 1  1 0 0 0 0 0 1  2 0 0 0 0 0 1"


@pytest.mark.parametrize(
    ("solver", "template", "positions", "lines", "code", "line", "reason"),
    [
        # beams between frames 0 and 2: not block-tridiagonal
        ("BTDLinearSolver", "Rigid3d", RIGID3, "0 1 0 2", "E222", 9, "consecutive DOFs"),
        ("BTDLinearSolver subpartSolve='1'", "Rigid3d", RIGID3, "0 1 1 2", "E222", 5, "subpartSolve"),
        ("CGLinearSolver", "Vec3d", "0 0 0  1 0 0  2 0 0", "0 1 1 2", "E210", 9, "Rigid3d"),
    ],
)
def test_what_sofac_cannot_compile_is_refused_at_its_line(
    tmp_path: Path, solver: str, template: str, positions: str, lines: str, code: str, line: int, reason: str
) -> None:
    """`sofac check`'s diagnostics (the planner's refusals included) name the line and why."""
    from sofac.check.checker import check_file
    from sofac.pipeline import add_compile_refusals

    scene = tmp_path / "refused.scn"
    scene.write_text(REFUSED.format(solver=solver, template=template, positions=positions, lines=lines))
    checked, diags = check_file(scene)
    add_compile_refusals(checked, diags)
    errors = [d for d in diags if d.severity.name == "ERROR"]
    assert [(d.code, d.loc.line) for d in errors] == [(code, line)], [str(d) for d in diags]
    assert reason in errors[0].message


@pytest.mark.parametrize(("counts", "internal"), [((4, 3, 5), False), ((4, 3, 5), True), ((5, 1, 3), False)])
def test_cube_topology_points_edges_and_quads(
    tmp_path: Path, counts: tuple[int, int, int], internal: bool
) -> None:
    """CubeTopology evaluated at compile time: SOFA's point count (the box's surface unless
    internalPoints or a flat axis), each point at p0 + i dx + j dy + k dz, its surface edges and
    quads as many as SOFA reserves, each quad a unit square of the lattice on the box's surface."""
    from sofac.check.checker import check_file

    nx, ny, nz = counts
    scene = tmp_path / "cube.scn"
    scene.write_text(
        f'<Node name="root"><CubeTopology name="cube" nx="{nx}" ny="{ny}" nz="{nz}" min="-1 0 2" '
        f'max="2 1 4" internalPoints="{int(internal)}"/><MechanicalObject/></Node>'
    )
    checked, diags = check_file(scene)
    assert not diags.has_errors()
    cube = next(c.component for c in checked if c.component.type_name == "CubeTopology")
    points = np.asarray(checked.value(cube, "position")).reshape(-1, 3)
    surface = not internal and min(counts) > 1
    assert len(points) == (nx * ny * 2 + (nz - 2) * (2 * nx + 2 * ny - 4) if surface else nx * ny * nz)
    steps = [
        (hi - lo) / (n - 1) if n > 1 else 0.0 for lo, hi, n in zip((-1, 0, 2), (2, 1, 4), counts, strict=True)
    ]
    lattice = np.rint((points - [-1.0, 0.0, 2.0]) / np.where(np.array(steps) > 0, steps, 1.0))
    np.testing.assert_allclose(points, [-1.0, 0.0, 2.0] + lattice * steps, atol=1e-14)
    assert len({tuple(p) for p in lattice}) == len(points)  # no point twice
    edges = np.asarray(checked.value(cube, "edges")).reshape(-1, 2)
    if min(counts) > 1:  # the edges along the box's surface (SOFA's reserve)
        expected_edges = (nx - 1) * (2 * ny + 2 * nz - 4) + (ny - 1) * (2 * nx + 2 * nz - 4)
        expected_edges += (nz - 1) * (2 * nx + 2 * ny - 4)
    else:  # a flat box: every lattice edge is on its surface
        expected_edges = (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    assert len(edges) == expected_edges
    assert np.all(np.abs(lattice[edges[:, 0]] - lattice[edges[:, 1]]).sum(axis=1) == 1)
    quads = np.asarray(checked.value(cube, "quads")).reshape(-1, 4)
    expected_quads = (nx - 1) * (ny - 1) * (2 if nz > 1 else 1)
    expected_quads += (nx - 1) * (nz - 1) * (2 if ny > 1 else 1) + (ny - 1) * (nz - 1) * (2 if nx > 1 else 1)
    assert len(quads) == expected_quads
    for quad in quads:
        corners = lattice[quad]
        assert np.all(np.abs(np.diff(corners[[0, 1, 2, 3, 0]], axis=0)).sum(axis=1) == 1)


MAPPED_MASS = """<?xml version="1.0"?>
<Node name="root" dt="0.01">
  <DefaultAnimationLoop/>
  <Node name="beam">
    <EulerImplicitSolver rayleighMass="0.1"/>
    <{solver}/>
    <MechanicalObject template="Rigid3d" name="frames"
        position="0 0 0 0 0 0 1  1 0 0 0 0 0 1  2 0 0 0 0 0 1  3 0 0 0 0 0 1"/>
    <MeshTopology lines="0 1 1 2 2 3"/>
    <FixedProjectiveConstraint indices="0"/>
    <UniformMass totalMass="4"/>
    <BeamFEMForceField radius="0.05" youngModulus="1e6" poissonRatio="0.3"/>
    <Node name="skin">
      <MechanicalObject name="points" position="0.5 0.1 0  1.25 0 -0.1  2.75 0.05 0.05  3 0 0.1"/>
      <UniformMass totalMass="2"/>
      <BeamLinearMapping/>
    </Node>
  </Node>
</Node>
"""


def test_a_mass_on_mapped_points_btd_and_matrix_free_cg_agree(tmp_path: Path) -> None:
    """A mass on points mapped by BeamLinearMapping: the BTD solve assembles J^T M J from the
    mapping's assembled J; CG applies J and J^T matrix-free. Both give the same motion."""
    runs = {}
    for solver in ("BTDLinearSolver", 'CGLinearSolver iterations="200" tolerance="1e-20" threshold="1e-30"'):
        path = tmp_path / f"mapped_{solver.split()[0]}.scn"
        path.write_text(MAPPED_MASS.format(solver=solver))
        sim = sofac.load(path)
        sim.step(20)
        runs[solver.split()[0]] = sim["frames"].position.copy(), sim["points"].position.copy()
    btd, cg = runs["BTDLinearSolver"], runs["CGLinearSolver"]
    assert btd[0][-1, 1] < -1e-3  # it fell
    np.testing.assert_allclose(btd[0], cg[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(btd[1], cg[1], rtol=0, atol=1e-9)
