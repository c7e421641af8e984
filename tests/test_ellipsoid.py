"""InteractionEllipsoidForceField (runtime/sofac/ellipsoid.h) against the hand formula, its derivative
against finite differences; QuadBendingSprings' springs from a grid of quads."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import D, build_shim
from kernel_shim import doubles as _d
from sofac.pipeline import compile_scene

SHIM = r"""
#include "sofac/loads.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void force(const double* x1, const double* v1, double* f1, Index n, const double* x2, const double* ell,
               Index ne, double k, double d, double* contacts, double* q) {
    sofac::ellipsoid_add_force(x1, v1, f1, n, x2, 0, ell, ne, k, d, contacts, q);
}
API void dforce(const double* dx, double* df, Index n, const double* contacts, const double* q, double k) {
    sofac::ellipsoid_add_dforce(dx, df, n, contacts, q, k);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "ellipsoid", SHIM)
    n, real = ctypes.c_int64, ctypes.c_double
    library.force.argtypes = [D, D, D, n, D, D, n, real, real, D, D]
    library.dforce.argtypes = [D, D, n, D, D, real]
    return library


ANGLE = 0.8
AXIS = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
QUAT = np.array([*(np.sin(ANGLE / 2) * AXIS), np.cos(ANGLE / 2)])
CENTER = np.array([1.0, -2.0, 0.5])
RADII = np.array([3.0, 1.0, 2.0])


def rotation() -> np.ndarray:
    k = np.array([[0, -AXIS[2], AXIS[1]], [AXIS[2], 0, -AXIS[0]], [-AXIS[1], AXIS[0], 0]])
    return np.eye(3) + np.sin(ANGLE) * k + (1 - np.cos(ANGLE)) * k @ k


def run(lib: ctypes.CDLL, local: np.ndarray, velocity: np.ndarray, k: float, damping: float):  # type: ignore[no-untyped-def]
    x1 = np.ascontiguousarray((local @ rotation().T + CENTER).ravel())
    v1 = np.ascontiguousarray(velocity.ravel())
    n = len(local)
    f = np.zeros(3 * n)
    contacts, q = np.zeros(10 * n), np.zeros(4)
    frame = np.array([*CENTER, *QUAT])
    ellipsoid = np.array([0.0, 0.0, 0.0, *(1 / RADII**2)])
    lib.force(_d(x1), _d(v1), _d(f), n, _d(frame), _d(ellipsoid), 1, k, damping, _d(contacts), _d(q))
    return f.reshape(-1, 3), contacts, q, x1


def test_push_along_a_local_axis_and_nothing_outside(lib: ctypes.CDLL) -> None:
    """A point at a < r_x on the frame's local x axis: f = k (1 - a / r_x) along the rotated x axis;
    a point outside the ellipsoid gets nothing."""
    k = 500.0
    local = np.array([[1.2, 0.0, 0.0], [0.0, 1.5, 0.0]])  # inside; outside (y radius 1)
    force, contacts, _, _ = run(lib, local, np.zeros((2, 3)), k, 0.0)
    expected = k * (1 - 1.2 / 3.0) * rotation()[:, 0]
    assert np.abs(force[0] - expected).max() < 1e-12 * k
    assert not force[1].any() and contacts[0] == 1.0 and contacts[10] == 0.0


def test_damping_opposes_the_velocity(lib: ctypes.CDLL) -> None:
    local, velocity = np.array([[1.2, 0.0, 0.0]]), np.array([[0.3, -0.2, 0.7]])
    pushed, *_ = run(lib, local, np.zeros((1, 3)), 500.0, 0.0)
    damped, *_ = run(lib, local, velocity, 500.0, 4.0)
    assert np.abs(damped[0] - pushed[0] - (-4.0 * (1 - 1.2 / 3.0)) * velocity[0]).max() < 1e-12


def _fd_jacobian(lib: ctypes.CDLL, x1: np.ndarray, h: float = 1e-7) -> np.ndarray:
    frame = np.array([*CENTER, *QUAT])
    ellipsoid = np.array([0.0, 0.0, 0.0, *(1 / RADII**2)])
    n = x1.size
    columns = []
    for j in range(n):
        forces = []
        for sign in (1.0, -1.0):
            x = x1.copy()
            x[j] += sign * h
            f = np.zeros(n)
            scratch, q = np.zeros(10 * n // 3), np.zeros(4)
            lib.force(
                _d(x),
                _d(np.zeros(n)),
                _d(f),
                n // 3,
                _d(frame),
                _d(ellipsoid),
                1,
                500.0,
                0.0,
                _d(scratch),
                _d(q),
            )
            forces.append(f)
        columns.append((forces[0] - forces[1]) / (2 * h))
    return np.column_stack(columns)


def _dforce_matrix(lib: ctypes.CDLL, contacts: np.ndarray, q: np.ndarray, n: int) -> np.ndarray:
    columns = []
    for j in range(3 * n):
        df = np.zeros(3 * n)
        lib.dforce(_d(np.eye(3 * n)[j].copy()), _d(df), n, _d(contacts), _d(q), 1.0)
        columns.append(df)
    return np.column_stack(columns)


def test_dforce_is_sofas_matrix(lib: ctypes.CDLL) -> None:
    """df = R m R^T dx with SOFA's m = g g^T (f1 + f3 a_j) + diag(f2 a), a = 1/r^2, g = a dp,
    f1 = -k / (n |g|), f2 = -k (n - 1) / |g|, f3 = -k (n - 1) / |g|^2 (n = |dp|_r). SOFA's f3 is not
    the exact derivative (that is +k (n - 1) / |g|^3), so the matrix equals finite differences of
    the force only on the ellipsoid's surface (n = 1), where the f2 and f3 terms vanish."""
    k = 500.0
    local = np.array([[1.2, 0.3, -0.4]])
    _, contacts, q, _ = run(lib, local, np.zeros((1, 3)), k, 0.0)
    a = 1 / RADII**2
    g = local[0] * a
    n = np.sqrt(np.sum(local[0] ** 2 * a))
    gn = np.linalg.norm(g)
    m = np.outer(g, g) * (-k / (n * gn) + (-k * (n - 1) / gn**2) * a[None, :]) + np.diag(
        -k * (n - 1) / gn * a
    )
    expected = rotation() @ m @ rotation().T
    assert np.abs(_dforce_matrix(lib, contacts, q, 1) - expected).max() < 1e-10 * np.abs(expected).max()
    surface = local / np.sqrt(np.sum(local[0] ** 2 * a)) * (1 - 1e-5)  # just inside
    _, contacts, q, x1 = run(lib, surface, np.zeros((1, 3)), k, 0.0)
    fd = _fd_jacobian(lib, x1)
    assert np.abs(_dforce_matrix(lib, contacts, q, 1) - fd).max() < 1e-3 * np.abs(fd).max()


QUADS = """<Node name="root" dt="0.01" gravity="0 -1 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver/>
  <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="1"/>
  <RegularGridTopology nx="3" ny="1" nz="3" xmin="0" xmax="2" ymin="0" ymax="0" zmin="0" zmax="4"/>
  <QuadBendingSprings name="bend" stiffness="30" damping="2"/>
</Node>
"""


def test_quad_bending_springs_join_opposite_corners(tmp_path: Path) -> None:
    """A 3x3 grid of points (2x2 quads): every interior edge joins two quads and puts a spring on
    the corners opposite across it: 6 springs, lengths 2 (along x, 2 apart) or 4 (along z)."""
    scene = tmp_path / "quads.scn"
    scene.write_text(QUADS)
    plan = compile_scene(scene).plan
    first = plan.buffer("/bend.indices1").initial.astype(int)
    second = plan.buffer("/bend.indices2").initial.astype(int)
    pairs = {tuple(sorted(p)) for p in zip(first.tolist(), second.tolist(), strict=True)}
    assert pairs == {(0, 2), (3, 5), (6, 8), (0, 6), (1, 7), (2, 8)}
    lengths = plan.buffer("/bend.lengths").initial
    for a, b, length in zip(first.tolist(), second.tolist(), lengths.tolist(), strict=True):
        assert length == (2.0 if abs(b - a) == 2 else 4.0)
    assert set(plan.buffer("/bend.stiffness").initial) == {30.0}
    assert set(plan.buffer("/bend.damping").initial) == {2.0}
