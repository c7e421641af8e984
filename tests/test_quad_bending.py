"""QuadBendingFEMForceField (runtime/sofac/quad_bending.h), SOFA's small method.

SOFA's element acts on translations only (its rotations are held at zero): a bilinear plane-stress
membrane on x, y (2x2 Gauss) and the transverse shear of w, Cs (grad w)^2 (1 Gauss point), so its
bending terms never act and Kirchhoff plate theory does not apply; the closed forms below are the
membrane's and the shear term's. SOFA has no energy for it (getPotentialEnergy is not implemented),
so the stiffness is checked against finite differences of the force at rest, where the
recomputation of K from the current positions does not contribute.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.regress.suite import Status, run_regression

SHIM = r"""
#include "sofac/quad_bending.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void quad_init(const Index* q, Index n, const double* x0, double young, double nu, double t,
                   double* data) {
    sofac::quad_bending_init(q, n, x0, &young, 1, &nu, 1, t, data);
}
API void quad_force(const Index* q, Index n, const double* x, double* f, const double* data) {
    sofac::quad_bending_add_force(q, n, x, f, data);
}
API void quad_dforce(const Index* q, Index n, const double* x, const double* dx, double* df, double k,
                     const double* data) {
    sofac::quad_bending_add_dforce(q, n, x, dx, df, k, data);
}
"""

YOUNG, NU, THICKNESS = 2000.0, 0.3, 0.5
SCENE = "Component/SolidMechanics/FEM/QuadBendingFEMForceField.scn"


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "quad_bending", SHIM)
    library.quad_init.argtypes = [I64, ctypes.c_int64, D] + [ctypes.c_double] * 3 + [D]
    library.quad_force.argtypes = [I64, ctypes.c_int64, D, D, D]
    library.quad_dforce.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_double, D]
    return library


class Plate:
    """Rectangular quads on the grid of node coordinates xs x ys in the plane z = 0 (by default nx x
    ny nodes evenly over [0, a] x [0, b]), SOFA's corner order counter-clockwise from the lower left."""

    def __init__(
        self,
        lib: ctypes.CDLL,
        nx: int,
        ny: int,
        a: float,
        b: float,
        xs: list[float] | None = None,
        ys: list[float] | None = None,
    ):
        self.lib = lib
        xs = np.linspace(0, a, nx) if xs is None else np.array(xs)
        ys = np.linspace(0, b, ny) if ys is None else np.array(ys)
        self.rest = np.array([[x, y, 0.0] for y in ys for x in xs])
        self.quads = np.array(
            [
                [j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
                for j in range(ny - 1)
                for i in range(nx - 1)
            ],
            dtype=np.int64,
        )
        self.n = len(self.quads)
        self.data = np.zeros(16 * self.n)
        lib.quad_init(_i(self.quads), self.n, _d(self.rest), YOUNG, NU, THICKNESS, _d(self.data))

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(self.rest)
        self.lib.quad_force(_i(self.quads), self.n, _d(np.ascontiguousarray(x)), _d(f), _d(self.data))
        return f

    def dforce(self, x: np.ndarray, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        df = np.zeros_like(self.rest)
        self.lib.quad_dforce(
            _i(self.quads),
            self.n,
            _d(np.ascontiguousarray(x)),
            _d(np.ascontiguousarray(dx)),
            _d(df),
            kfactor,
            _d(self.data),
        )
        return df


def membrane_c() -> np.ndarray:
    return YOUNG * THICKNESS / (1 - NU**2) * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])


def test_translation_gives_no_force(lib: ctypes.CDLL) -> None:
    plate = Plate(lib, 3, 3, 2.0, 1.0)
    assert np.array_equal(plate.force(plate.rest), np.zeros_like(plate.rest))
    moved = plate.rest + np.array([0.3, -1.2, 2.5])
    assert np.abs(plate.force(moved)).max() < 1e-12


def test_stiffness_is_the_jacobian_of_the_force_at_rest(lib: ctypes.CDLL) -> None:
    plate = Plate(lib, 3, 2, 2.0, 1.0)
    rng = np.random.default_rng(5)
    dx = rng.standard_normal(plate.rest.shape)
    h = 1e-6
    fd = (plate.force(plate.rest + h * dx) - plate.force(plate.rest - h * dx)) / (2 * h)
    df = plate.dforce(plate.rest, dx)
    assert np.allclose(df, fd, rtol=1e-7, atol=1e-7 * np.abs(fd).max())
    assert np.allclose(plate.dforce(plate.rest, dx, -0.25), -0.25 * df, rtol=1e-14, atol=0)


def test_stiffness_is_symmetric_and_follows_the_current_shape(lib: ctypes.CDLL) -> None:
    """K is symmetric; SOFA recomputes it from the current half sides, so a plate stretched by s
    along x has its x-x membrane terms scaled by 1/s and its y-y ones by s."""
    plate = Plate(lib, 2, 2, 2.0, 1.0)
    size = plate.rest.size
    columns = [-plate.dforce(plate.rest, np.eye(size)[k].reshape(-1, 3)).ravel() for k in range(size)]
    k = np.array(columns).T
    assert np.allclose(k, k.T, rtol=0, atol=1e-12 * np.abs(k).max())
    s = 1.5
    stretched = plate.rest * np.array([s, 1.0, 1.0])
    ux = np.zeros_like(plate.rest)
    ux[:, 0] = plate.rest[:, 0]  # u = x: pure xx strain 1 at rest
    energy_rest = ux.ravel() @ -plate.dforce(plate.rest, ux).ravel()
    energy_stretched = ux.ravel() @ -plate.dforce(stretched, ux).ravel()
    assert energy_stretched == pytest.approx(energy_rest / s, rel=1e-12)


@pytest.mark.parametrize(
    "gradient",
    [
        np.array([[0.01, 0.0], [0.0, 0.0]]),
        np.array([[0.0, 0.0], [0.0, -0.02]]),
        np.array([[0.003, 0.007], [-0.002, 0.004]]),
    ],
    ids=["xx", "yy", "mixed"],
)
def test_membrane_energy_of_a_homogeneous_strain(lib: ctypes.CDLL, gradient: np.ndarray) -> None:
    """u = G (x, y): u^T K u = A eps^T Cb eps with Cb = E t / (1 - nu^2) [1 nu 0; nu 1 0; 0 0 (1-nu)/2]
    and engineering shear (exact for the bilinear element with 2x2 Gauss points)."""
    a, b = 2.0, 1.5
    plate = Plate(lib, 2, 2, a, b)
    u = np.zeros_like(plate.rest)
    u[:, :2] = plate.rest[:, :2] @ gradient.T
    eps = np.array([gradient[0, 0], gradient[1, 1], gradient[0, 1] + gradient[1, 0]])
    expected = a * b * eps @ membrane_c() @ eps
    assert u.ravel() @ -plate.dforce(plate.rest, u).ravel() == pytest.approx(expected, rel=1e-12)
    # the force at the displaced positions is -K(x) D with D measured from the centroid
    assert np.allclose(plate.force(plate.rest + u).ravel() @ u.ravel(), -expected, rtol=0.05)


def test_patch_homogeneous_strain_leaves_interior_nodes_free(lib: ctypes.CDLL) -> None:
    """Patch test: on four unequal rectangles around one node, a linear in-plane field u = G X and a
    linear w = a x + b y give zero force at the interior node."""
    plate = Plate(lib, 3, 3, 0.0, 0.0, xs=[0.0, 0.7, 2.0], ys=[0.0, 0.4, 1.0])
    gradient = np.array([[0.004, -0.002], [0.003, 0.006]])
    u = np.zeros_like(plate.rest)
    u[:, :2] = plate.rest[:, :2] @ gradient.T
    u[:, 2] = 0.01 * plate.rest[:, 0] - 0.02 * plate.rest[:, 1]
    f = plate.dforce(plate.rest, u)
    assert np.abs(f[4]).max() < 1e-12 * np.abs(f).max()
    assert np.abs(f).max() > 1e-3  # the boundary nodes carry the load


def test_transverse_shear_energy_of_a_tilt(lib: ctypes.CDLL) -> None:
    """w = s x with zero rotations is a uniform transverse shear strain s: w^T K w = A Cs s^2 with
    Cs = (5/6) E t / (2 (1 + nu)). (SOFA's element has no bending action on w.)"""
    a, b, slope = 2.0, 0.8, 0.01
    plate = Plate(lib, 2, 2, a, b)
    w = np.zeros_like(plate.rest)
    w[:, 2] = slope * plate.rest[:, 0]
    cs = 5.0 / 6.0 * YOUNG * THICKNESS / (2 * (1 + NU))
    assert w.ravel() @ -plate.dforce(plate.rest, w).ravel() == pytest.approx(a * b * cs * slope**2, rel=1e-12)
    # in-plane and transverse motions do not couple
    assert np.all(plate.dforce(plate.rest, w)[:, :2] == 0.0)


def test_quad_bending_regression_scene_passes(shared_dir: Path) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[SCENE]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon
