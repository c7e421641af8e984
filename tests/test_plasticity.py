"""TetrahedronFEMForceField's plasticity (runtime/sofac/fem.h, tetra_fem_add_force_options).

SOFA's rule (computeForce, plasticMaxThreshold > 0), per element and per force pass: with e the
total strain J^T D and p the plastic strain carried from pass to pass, if |e - p| > yield then
p += creep (e - p); if |p| > max then p *= max / |p|; the force is J K (e - p). SOFA's J holds
cofactors, 6 V times the shape-function gradients, so e is 6 V times the Voigt strain (xx yy zz,
engineering shears): the thresholds scale with the element's volume. Checked here against that
closed form on one tetrahedron under a homogeneous strain, and on SOFA's regression scene.

Also its updateStiffnessMatrix: every force pass recomputes the cofactors from the current local
points (polar, svd: all of J; large: SOFA rewrites only J's normal-strain columns), checked
against a NumPy rendering of that rule on a stretched tetrahedron.
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
#include "sofac/fem.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API Index tet_count(int method, Index n) { return sofac::tetra_fem_data_count(method, n); }
API void tet_init(const Index* t, Index n, const double* x0, double young, double nu, int method,
                  double* data) {
    sofac::tetra_fem_init(t, n, x0, &young, 1, &nu, 1, method, data);
}
API void tet_force(const Index* t, Index n, const double* x, double* f, double* data, int method) {
    sofac::tetra_fem_add_force(t, n, x, f, data, method);
}
API void tet_force_plastic(const Index* t, Index n, const double* x, double* f, double* data, int method,
                           double* strain, double max_threshold, double yield_threshold, double creep) {
    sofac::tetra_fem_add_force_options(t, n, x, f, data, method,
                                       sofac::TetraPlasticity{strain, max_threshold, yield_threshold, creep},
                                       sofac::TetraStiffnessUpdate{false, nullptr});
}
API void tet_dforce(const Index* t, Index n, const double* dx, double* df, double k, const double* data,
                    int method) {
    sofac::tetra_fem_add_dforce(t, n, dx, df, k, data, method);
}
API void tet_force_updating(const Index* t, Index n, const double* x, double* f, double* data, int method,
                            double* normals) {
    const sofac::TetraPlasticity none{nullptr, 0.0, 0.0, 0.0};
    const sofac::TetraStiffnessUpdate update{true, normals};
    sofac::tetra_fem_add_force_options(t, n, x, f, data, method, none, update);
}
API void tet_copy_normals(Index n, const double* data, int method, double* normals) {
    sofac::tetra_fem_copy_normals(n, data, method, normals);
}
API void tet_dforce_normals(const Index* t, Index n, const double* dx, double* df, double k,
                            const double* data, int method, const double* normals) {
    sofac::tetra_fem_add_dforce_normals(t, n, dx, df, k, data, method, normals);
}
"""

SMALL, LARGE, POLAR, SVD = 0, 1, 2, 3
REPO_SCENE = "Component/SolidMechanics/FEM/TetrahedronFEMForceField_plasticity.scn"


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "plasticity", SHIM)
    library.tet_count.restype = ctypes.c_int64
    library.tet_init.argtypes = [I64, ctypes.c_int64, D, ctypes.c_double, ctypes.c_double, ctypes.c_int, D]
    library.tet_force_plastic.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_int, D] + [
        ctypes.c_double
    ] * 3
    library.tet_dforce.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int]
    library.tet_force_updating.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_int, D]
    library.tet_copy_normals.argtypes = [ctypes.c_int64, D, ctypes.c_int, D]
    library.tet_dforce_normals.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int, D]
    return library


class PlasticTet:
    """One tetrahedron (scaled unit corner tetrahedron) with SOFA's plastic parameters."""

    def __init__(
        self, lib: ctypes.CDLL, method: int, scale: float, max_t: float, yield_t: float, creep: float
    ):
        self.lib, self.method = lib, method
        self.tetra = np.array([[0, 1, 2, 3]], dtype=np.int64)
        self.rest = scale * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
        self.six_volume = scale**3
        self.data = np.zeros(lib.tet_count(method, 1))
        lib.tet_init(_i(self.tetra), 1, _d(self.rest), 1000.0, 0.3, method, _d(self.data))
        self.strain = np.zeros(6)
        self.params = (max_t, yield_t, creep)

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(x)
        x = np.ascontiguousarray(x)
        self.lib.tet_force_plastic(
            _i(self.tetra), 1, _d(x), _d(f), _d(self.data), self.method, _d(self.strain), *self.params
        )
        return f

    def elastic_force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(x)
        data = self.data.copy()
        self.lib.tet_force(_i(self.tetra), 1, _d(np.ascontiguousarray(x)), _d(f), _d(data), self.method)
        return f


def strained(rest: np.ndarray, gradient: np.ndarray, rotation: np.ndarray | None = None) -> np.ndarray:
    x = rest + rest @ gradient.T
    return x if rotation is None else x @ rotation.T


def voigt(gradient: np.ndarray) -> np.ndarray:
    """The small strain of x = (I + G) X in SOFA's Voigt order, engineering shears."""
    eps = (gradient + gradient.T) / 2
    return np.array([eps[0, 0], eps[1, 1], eps[2, 2], 2 * eps[0, 1], 2 * eps[1, 2], 2 * eps[2, 0]])


STRETCH = np.diag([0.02, -0.006, -0.006])  # |voigt| = 0.0217: above yield, below max
SHEAR = np.array([[0.0, 0.01, 0.0], [0.01, 0.0, 0.0], [0.0, 0.0, 0.0]])


def test_below_yield_nothing_flows(lib: ctypes.CDLL) -> None:
    tet = PlasticTet(lib, SMALL, 1.0, max_t=0.5, yield_t=0.1, creep=0.5)
    x = strained(tet.rest, STRETCH)
    f = tet.force(x)
    assert np.all(tet.strain == 0.0)
    assert np.array_equal(f, tet.elastic_force(x))


@pytest.mark.parametrize("scale", [1.0, 2.0])
@pytest.mark.parametrize("gradient", [STRETCH, SHEAR], ids=["stretch", "shear"])
def test_one_overload_moves_creep_times_the_strain_into_plastic_strain(
    lib: ctypes.CDLL, scale: float, gradient: np.ndarray
) -> None:
    """Yield exceeded once: p = creep e with e = 6 V strain (SOFA's J of cofactors); the force drops
    to (1 - creep) times the elastic force (small strains: linear)."""
    creep = 0.3
    tet = PlasticTet(lib, SMALL, scale, max_t=10.0, yield_t=1e-3, creep=creep)
    x = strained(tet.rest, gradient)
    f = tet.force(x)
    expected = creep * tet.six_volume * voigt(gradient)
    # SOFA's D is rest minus current: e = -6 V strain for this (positively oriented) element
    assert np.allclose(np.abs(tet.strain), np.abs(expected), rtol=1e-9, atol=1e-15)
    assert np.allclose(tet.strain, -expected, rtol=1e-9, atol=1e-15)
    assert np.allclose(f, (1 - creep) * tet.elastic_force(x), rtol=1e-9, atol=1e-12)


def test_creep_accumulates_geometrically_until_below_yield(lib: ctypes.CDLL) -> None:
    """At a fixed strain e, pass k leaves p_k = (1 - (1 - c)^k) e while |e - p_k| > yield, then stops."""
    creep, yield_t = 0.5, 0.003
    tet = PlasticTet(lib, SMALL, 1.0, max_t=10.0, yield_t=yield_t, creep=creep)
    x = strained(tet.rest, STRETCH)
    e = -voigt(STRETCH)
    norm = np.linalg.norm(e)
    flowing = int(np.ceil(np.log(yield_t / norm) / np.log(1 - creep)))  # passes with |e - p| > yield
    for _ in range(flowing + 3):
        tet.force(x)
    assert np.allclose(tet.strain, (1 - (1 - creep) ** flowing) * e, rtol=1e-9)
    assert np.linalg.norm(e - tet.strain) <= yield_t


@pytest.mark.parametrize("method", [SMALL, LARGE, POLAR, SVD])
def test_max_threshold_clamps_the_plastic_strain(lib: ctypes.CDLL, method: int) -> None:
    """creep 1 would make all of e plastic; |p| is clamped to max, along e."""
    max_t = 0.01
    tet = PlasticTet(lib, method, 1.0, max_t=max_t, yield_t=1e-4, creep=1.0)
    tet.force(strained(tet.rest, STRETCH))
    e = -voigt(STRETCH)
    assert np.linalg.norm(tet.strain) == pytest.approx(max_t, rel=1e-12)
    assert np.allclose(tet.strain, max_t * e / np.linalg.norm(e), rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("method", [LARGE, POLAR, SVD])
def test_corotational_plastic_strain_ignores_rigid_rotations(lib: ctypes.CDLL, method: int) -> None:
    """The corotational methods measure the strain in the element's frame: a rotated copy of the same
    stretch gives the same plastic strain and the rotated force."""
    angle = 0.7
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
    )
    straight = PlasticTet(lib, method, 1.0, max_t=1.0, yield_t=1e-4, creep=0.4)
    turned = PlasticTet(lib, method, 1.0, max_t=1.0, yield_t=1e-4, creep=0.4)
    f0 = straight.force(strained(straight.rest, STRETCH))
    f1 = turned.force(strained(turned.rest, STRETCH, rotation))
    assert np.allclose(turned.strain, straight.strain, rtol=1e-9, atol=1e-14)
    assert np.allclose(f1, f0 @ rotation.T, rtol=1e-9, atol=1e-12)


def test_stiffness_ignores_plasticity(lib: ctypes.CDLL) -> None:
    """SOFA's addDForce uses the elastic J K J^T whatever the plastic strain; it is the
    finite-difference Jacobian of the force with the plastic strain held fixed."""
    tet = PlasticTet(lib, LARGE, 1.0, max_t=1.0, yield_t=1e-4, creep=0.5)
    x = strained(tet.rest, STRETCH)
    tet.force(x)
    frozen = tet.strain.copy()
    rng = np.random.default_rng(3)
    dx = rng.standard_normal(x.shape)
    df = np.zeros_like(x)
    tet.lib.tet_dforce(_i(tet.tetra), 1, _d(np.ascontiguousarray(dx)), _d(df), 1.0, _d(tet.data), LARGE)
    h = 1e-7

    def held(y: np.ndarray) -> np.ndarray:
        tet.params = (1.0, 1e9, 0.5)  # yield never reached again: p stays `frozen`
        tet.strain[:] = frozen
        return tet.force(y)

    fd = (held(x + h * dx) - held(x - h * dx)) / (2 * h)
    # the corotational product neglects dR/dx: equal at small strain to about |strain|
    assert np.abs(df - fd).max() <= 0.05 * np.abs(fd).max()


# ---- updateStiffnessMatrix -----------------------------------------------------------------------

YOUNG, POISSON = 1000.0, 0.3


def shape_gradients(points: np.ndarray) -> tuple[np.ndarray, float]:
    """dN_k/dx of the linear tetrahedron (rows k) and its volume."""
    edges = (points[1:] - points[0]).T
    inverse = np.linalg.inv(edges)
    grads = np.vstack([-inverse.sum(axis=0), inverse])
    return grads, abs(np.linalg.det(edges)) / 6


def strain_rows(grads: np.ndarray) -> np.ndarray:
    """B (6x12): Voigt xx yy zz xy yz zx with engineering shears, SOFA's order."""
    b = np.zeros((6, 12))
    for k, (gx, gy, gz) in enumerate(grads):
        c = 3 * k
        b[0, c], b[1, c + 1], b[2, c + 2] = gx, gy, gz
        b[3, c], b[3, c + 1] = gy, gx
        b[4, c + 1], b[4, c + 2] = gz, gy
        b[5, c], b[5, c + 2] = gz, gx
    return b


def hooke() -> np.ndarray:
    lam = YOUNG * POISSON / ((1 + POISSON) * (1 - 2 * POISSON))
    mu = YOUNG / (2 * (1 + POISSON))
    c = np.zeros((6, 6))
    c[:3, :3] = lam
    c[np.arange(3), np.arange(3)] += 2 * mu
    c[np.arange(3, 6), np.arange(3, 6)] = mu
    return c


STRETCHED = np.diag([0.3, -0.1, 0.2])  # large enough that the current cofactors differ clearly


def updating_force(lib: ctypes.CDLL, method: int, x: np.ndarray, rest: np.ndarray) -> np.ndarray:
    tetra = np.array([[0, 1, 2, 3]], dtype=np.int64)
    data = np.zeros(lib.tet_count(method, 1))
    lib.tet_init(_i(tetra), 1, _d(rest), YOUNG, POISSON, method, _d(data))
    normals = np.zeros(12)
    lib.tet_copy_normals(1, _d(data), method, _d(normals))
    f = np.zeros_like(x)
    lib.tet_force_updating(_i(tetra), 1, _d(np.ascontiguousarray(x)), _d(f), _d(data), method, _d(normals))
    return f


@pytest.mark.parametrize("method", [POLAR, SVD])
def test_update_recomputes_all_cofactors_for_polar_and_svd(lib: ctypes.CDLL, method: int) -> None:
    """SOFA's J of cofactors is 6 V B; with K = C / (36 V0) the updated force on a stretch (rotation
    identity) is -(V^2 / V0) B^T C B u, B and V those of the current shape."""
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    x = strained(rest, STRETCHED)
    b0, v0 = shape_gradients(rest)
    b1, v1 = shape_gradients(x)
    bc = strain_rows(b1)
    expected = -(v1**2 / v0) * bc.T @ hooke() @ bc @ (x - rest).ravel()
    assert np.allclose(updating_force(lib, method, x, rest).ravel(), expected, rtol=1e-9, atol=1e-9)
    # and not the force without the update
    b = strain_rows(b0)
    assert not np.allclose(expected, -v0 * b.T @ hooke() @ b @ (x - rest).ravel(), rtol=1e-2)


def test_update_of_large_rewrites_the_normal_columns_only(lib: ctypes.CDLL) -> None:
    """large: J's normal-strain columns from the current shape, its shear columns from the rest shape
    (SOFA's 9 rewritten entries), K = C / (36 V0)."""
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    x = strained(rest, STRETCHED + np.array([[0, 0.05, 0], [0, 0, 0], [0, 0, 0]]))  # some shear too
    b0, v0 = shape_gradients(rest)
    b1, v1 = shape_gradients(x)
    mixed = np.vstack([6 * v1 * strain_rows(b1)[:3], 6 * v0 * strain_rows(b0)[3:]])  # J^T, 6x12
    # the large frame of this shape: x along edge 0-1, z normal to face 0-1-2
    ex = (x[1] - x[0]) / np.linalg.norm(x[1] - x[0])
    ez = np.cross(ex, x[2] - x[0])
    ez /= np.linalg.norm(ez)
    frame = np.vstack([ex, np.cross(ez, ex), ez])
    local = (x - x[0]) @ frame.T
    assert np.allclose(local[1, 1:], 0) and abs(local[2, 2]) < 1e-15
    rest_local = rest - rest[0]  # the rest frame of the unit corner tetrahedron is the identity
    d = (rest_local - local).ravel()
    local_force = mixed.T @ (hooke() / (36 * v0)) @ mixed @ d
    expected = local_force.reshape(4, 3) @ frame
    f = updating_force(lib, LARGE, x, rest)
    assert np.allclose(f, expected, rtol=1e-9, atol=1e-9)
    whole = 6 * v1 * strain_rows(b1)  # had the shear columns been rewritten too
    assert not np.allclose(f, (whole.T @ (hooke() / (36 * v0)) @ whole @ d).reshape(4, 3) @ frame, rtol=1e-3)


@pytest.mark.parametrize("method", [LARGE, POLAR, SVD])
def test_update_keeps_rigid_motions_force_free(lib: ctypes.CDLL, method: int) -> None:
    rest = np.array([[0, 0, 0], [1.2, 0.1, 0], [0.2, 0.9, 0.1], [0.1, 0.2, 1.1]], dtype=np.float64)
    angle = 0.9
    c, s = np.cos(angle), np.sin(angle)
    turned = rest @ np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]).T + np.array([2.0, -1.0, 0.5])
    assert np.abs(updating_force(lib, method, turned, rest)).max() < 1e-10


def test_update_of_large_is_what_add_dforce_uses(lib: ctypes.CDLL) -> None:
    """After an updating force pass the product uses the rewritten cofactors: at x itself, K dx for
    dx = x - rest (no rotation change) is minus the force (both R J K J^T R^T (x - rest))."""
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    x = strained(rest, STRETCHED)
    tetra = np.array([[0, 1, 2, 3]], dtype=np.int64)
    data = np.zeros(lib.tet_count(LARGE, 1))
    lib.tet_init(_i(tetra), 1, _d(rest), YOUNG, POISSON, LARGE, _d(data))
    normals = np.zeros(12)
    lib.tet_copy_normals(1, _d(data), LARGE, _d(normals))
    f = np.zeros_like(x)
    lib.tet_force_updating(_i(tetra), 1, _d(x), _d(f), _d(data), LARGE, _d(normals))
    df = np.zeros_like(x)
    dx = np.ascontiguousarray(x - rest)
    lib.tet_dforce_normals(_i(tetra), 1, _d(dx), _d(df), 1.0, _d(data), LARGE, _d(normals))
    assert np.allclose(df, f, rtol=1e-12, atol=1e-12)
    plain = np.zeros_like(x)
    lib.tet_dforce(_i(tetra), 1, _d(dx), _d(plain), 1.0, _d(data), LARGE)
    assert not np.allclose(plain, f, rtol=1e-2)


def test_update_compiles_in_a_scene_and_is_refused_where_it_is_not_compiled(tmp_path: Path) -> None:
    """SOFA's Demos/oneTetrahedron.scn (polar, updateStiffnessMatrix) runs; large with the update in an
    assembled system is refused with E222 at its line."""
    import sofac

    scene = tmp_path / "update.scn"
    body = (
        '<Node name="root" dt="0.01" gravity="0 -10 0"><DefaultAnimationLoop/>\n'
        "<EulerImplicitSolver/>{solver}\n"
        '<MeshTopology tetrahedra="0 1 2 3"/>'
        '<MechanicalObject name="dofs" position="0 10 0  10 0 0  -5 0 8.66  -5 0 -8.66"/>\n'
        '<UniformMass totalMass="2"/><FixedProjectiveConstraint indices="0"/>\n'
        '<TetrahedronFEMForceField method="{method}" updateStiffnessMatrix="true" youngModulus="6" '
        'poissonRatio="0.45"/>\n'
        "</Node>\n"
    )
    scene.write_text(
        body.format(
            solver='<CGLinearSolver iterations="25" tolerance="1e-5" threshold="1e-5"/>', method="polar"
        )
    )
    sim = sofac.load(scene)
    sim.step(50)
    moved = sim["dofs"].position
    assert np.all(np.isfinite(moved)) and moved[1:, 1].max() < 0.0  # hanging from node 0
    scene.write_text(body.format(solver="<SparseLDLSolver/>", method="large"))
    with pytest.raises(sofac.SceneError) as refused:
        sofac.load(scene)
    first = refused.value.diagnostics[0]
    assert first.code == "E222" and first.loc.line == 5
    assert (
        "updateStiffnessMatrix=true with method large in an assembled system is not compiled yet"
        in first.message
    )


def test_plasticity_regression_scene_passes(shared_dir: Path) -> None:
    """Four tori dropped on a plane (three plastic, one elastic), 300 steps: SOFA's criterion. Their
    collision models are proved apart by the contact guard at every step (the run would stop)."""
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[REPO_SCENE]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon


def test_plasticity_with_an_assembled_global_matrix_is_refused(tmp_path: Path) -> None:
    """SOFA logs an error and adds no force for plasticity with computeGlobalMatrix=true: refused."""
    import sofac

    scene = tmp_path / "assembling.scn"
    scene.write_text(
        '<Node name="root" dt="0.01"><DefaultAnimationLoop/>\n'
        '<EulerImplicitSolver/><CGLinearSolver/><RegularGridTopology n="2 2 2" min="0 0 0" max="1 1 1"/>\n'
        '<MechanicalObject/><UniformMass totalMass="1"/>\n'
        '<TetrahedronFEMForceField plasticMaxThreshold="0.02" computeGlobalMatrix="true"/>\n</Node>\n'
    )
    with pytest.raises(sofac.SceneError) as refused:
        sofac.load(scene)
    first = refused.value.diagnostics[0]
    assert first.code == "E222" and first.loc.line == 4
    assert "plasticity with computeGlobalMatrix=true is not compiled" in first.message
