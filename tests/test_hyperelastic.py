"""TetrahedronHyperelasticityFEMForceField: the kernels of runtime/sofac/hyperelastic.h per material,
the check-time errors, and scenes.

Kernels (compiled once into a small shim): forces are minus the gradient of the strain energy
(central differences), the dforce product and the assembled matrix are the derivative of the forces
(central differences), a homogeneous deformation leaves no residual on interior nodes (patch test),
and a bar stretched uniaxially (lateral faces free) carries the first Piola-Kirchhoff stress of the
material's stress-stretch curve, derived here in Python from the strain energy in principal
stretches (complex-step derivative), itself checked against the textbook closed forms of
Neo-Hookean and St Venant-Kirchhoff. Scenes: SOFA's regression scene passes SOFA's criterion; the
matrix-free CG, the assembled direct solve and the explicit integrator agree on a bar.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import I64, D, build_shim, doubles, indices
from sofac.check.checker import check_file
from sofac.geometry.fem_topology import tetrahedra_from_grid
from sofac.plan.lower.hyperelastic import HYPERELASTIC_DATA_SIZE
from sofac.registry.components.fem import HYPERELASTIC_MATERIALS
from sofac.regress.suite import Status, run_regression

SHIM = r"""
#include <vector>
#include "sofac/hyperelastic.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

// A dense n x n matrix behind sofac::Assembler's add().
struct Dense {
    Index n;
    double* a;
    void add(Index r, Index c, double v) { a[r * n + c] += v; }
};

API int h_size() { return sofac::hyperelastic_data_size(); }
API void h_init(const Index* t, Index n, const double* rest, double* data) {
    sofac::hyperelastic_init(t, n, rest, data);
}
API void h_force(const Index* t, Index n, const double* x, double* f, double* data, int m, const double* p) {
    sofac::hyperelastic_add_force(t, n, x, f, data, m, p);
}
API void h_dforce(const Index* t, Index n, const double* dx, double* df, double k, double* data, int m,
                  const double* p) {
    sofac::hyperelastic_add_dforce(t, n, dx, df, k, data, m, p);
}
API double h_energy(const Index* t, Index n, const double* x, const double* data, int m, const double* p) {
    return sofac::hyperelastic_strain_energy(t, n, x, data, m, p);
}
API void h_matrix(const Index* t, Index n, double* data, int m, const double* p, Index size, double k,
                  double* out) {
    Dense dense{size, out};
    sofac::hyperelastic_assemble(dense, t, n, data, m, p, 0, k);
}
"""

# Parameters per material (SOFA's ParameterSet order); Ogden with a moderate exponent here, SOFA's
# example scene's (alpha1 = 500) in the regression scene below.
MATERIALS: dict[str, list[float]] = {
    "ArrudaBoyce": [3448.2759, 31034.483],
    "StVenantKirchhoff": [3448.2759, 31034.483],
    "NeoHookean": [3448.2759, 31034.483],
    "MooneyRivlin": [5000.0, 7000.0, 10.0],
    "VerondaWestman": [800.0, 1.5, 20000.0],
    "Ogden": [1500.0, 3.5, 5000.0],
    "StableNeoHookean": [3448.2759, 31034.483],
    # a k0 bff bfs bss bfn bsn bnn; k0 = 1 because SOFA's Costa tangent omits k0 in one term
    "Costa": [500.0, 1.0, 8.0, 4.0, 3.0, 4.0, 2.0, 3.0],
}
# The uniaxial bar needs a bulk modulus for its free lateral faces.
BAR_PARAMETERS = {**MATERIALS, "Costa": [500.0, 2000.0, 8.0, 4.0, 3.0, 4.0, 2.0, 3.0]}


class Kernels:
    """The shim's kernels on one mesh and material."""

    def __init__(
        self,
        lib: ctypes.CDLL,
        tetra: np.ndarray,
        rest: np.ndarray,
        material: str,
        params: list[float] | None = None,
    ) -> None:
        self.lib = lib
        self.tetra = np.ascontiguousarray(tetra, dtype=np.int64).ravel()
        self.count = self.tetra.size // 4
        self.rest = np.ascontiguousarray(rest, dtype=float).ravel()
        self.code = HYPERELASTIC_MATERIALS.index(material)
        self.params = np.asarray(MATERIALS[material] if params is None else params, dtype=float)
        self.data = np.zeros(self.count * HYPERELASTIC_DATA_SIZE + 1)
        lib.h_init(indices(self.tetra), self.count, doubles(self.rest), doubles(self.data))

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(self.rest)
        x = np.ascontiguousarray(x, dtype=float).ravel()
        self.lib.h_force(
            indices(self.tetra),
            self.count,
            doubles(x),
            doubles(f),
            doubles(self.data),
            self.code,
            doubles(self.params),
        )
        return f

    def energy(self, x: np.ndarray) -> float:
        x = np.ascontiguousarray(x, dtype=float).ravel()
        return float(
            self.lib.h_energy(
                indices(self.tetra),
                self.count,
                doubles(x),
                doubles(self.data),
                self.code,
                doubles(self.params),
            )
        )

    def dforce(self, x: np.ndarray, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        self.force(x)  # the tangent at x (SOFA: the force of the step, then the products)
        df = np.zeros_like(self.rest)
        dx = np.ascontiguousarray(dx, dtype=float).ravel()
        self.lib.h_dforce(
            indices(self.tetra),
            self.count,
            doubles(dx),
            doubles(df),
            kfactor,
            doubles(self.data),
            self.code,
            doubles(self.params),
        )
        return df

    def matrix(self, x: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        self.force(x)
        n = self.rest.size
        out = np.zeros((n, n))
        self.lib.h_matrix(
            indices(self.tetra),
            self.count,
            doubles(self.data),
            self.code,
            doubles(self.params),
            n,
            kfactor,
            doubles(out),
        )
        return out


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    shim = build_shim(tmp_path_factory, "hyperelastic", SHIM)
    shim.h_energy.restype = ctypes.c_double
    shim.h_init.argtypes = [I64, ctypes.c_int64, D, D]
    shim.h_force.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_int, D]
    shim.h_dforce.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int, D]
    shim.h_energy.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_int, D]
    shim.h_matrix.argtypes = [I64, ctypes.c_int64, D, ctypes.c_int, D, ctypes.c_int64, ctypes.c_double, D]
    return shim


def grid(n: tuple[int, int, int], size: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Points (index x + nx (y + ny z)) and SOFA's 6-tetrahedra split of a regular grid."""
    axes = [np.linspace(0.0, s, k) for k, s in zip(n, size, strict=True)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    tetra = np.asarray(tetrahedra_from_grid(list(n)), dtype=np.int64).reshape(-1, 4)
    return points, tetra


def deformed(points: np.ndarray, amplitude: float, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return points + amplitude * rng.uniform(-1.0, 1.0, points.shape)


def test_runtime_data_size_is_the_planners(lib: ctypes.CDLL) -> None:
    assert lib.h_size() == HYPERELASTIC_DATA_SIZE


@pytest.mark.parametrize("material", MATERIALS)
def test_forces_are_minus_the_energy_gradient(lib: ctypes.CDLL, material: str) -> None:
    points, tetra = grid((3, 2, 2), (2.0, 1.0, 1.0))
    kernels = Kernels(lib, tetra, points, material)
    x = deformed(points, 0.08).ravel()
    force = kernels.force(x)
    h = 1e-6
    gradient = np.zeros_like(x)
    for i in range(x.size):
        step = np.zeros_like(x)
        step[i] = h
        gradient[i] = (kernels.energy(x + step) - kernels.energy(x - step)) / (2 * h)
    scale = np.abs(force).max()
    assert scale > 1.0  # the deformation does load the mesh
    np.testing.assert_allclose(force, -gradient, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize("material", MATERIALS)
def test_dforce_and_matrix_are_the_force_derivative(lib: ctypes.CDLL, material: str) -> None:
    points, tetra = grid((3, 2, 2), (2.0, 1.0, 1.0))
    kernels = Kernels(lib, tetra, points, material)
    x = deformed(points, 0.08).ravel()
    rng = np.random.default_rng(7)
    h = 1e-6
    for _ in range(3):
        direction = rng.uniform(-1.0, 1.0, x.size)
        expected = (kernels.force(x + h * direction) - kernels.force(x - h * direction)) / (2 * h)
        got = kernels.dforce(x, direction)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
        np.testing.assert_allclose(kernels.dforce(x, direction, -0.25), -0.25 * got, rtol=1e-13, atol=1e-9)
    matrix = kernels.matrix(x, 2.0)
    columns = np.stack([kernels.dforce(x, np.eye(x.size)[i], 2.0) for i in range(x.size)], axis=1)
    np.testing.assert_allclose(matrix, columns, rtol=0, atol=1e-9 * np.abs(columns).max())
    if material != "Ogden":  # hyperelastic: the force Jacobian is symmetric
        np.testing.assert_allclose(matrix, matrix.T, rtol=0, atol=1e-9 * np.abs(matrix).max())


@pytest.mark.parametrize("material", MATERIALS)
def test_rest_state_and_rigid_motion_are_stress_free(lib: ctypes.CDLL, material: str) -> None:
    points, tetra = grid((2, 2, 2), (1.0, 1.0, 1.0))
    kernels = Kernels(lib, tetra, points, material)
    assert np.abs(kernels.force(points)).max() < 1e-9
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    moved = points @ rotation.T + np.array([0.3, -2.0, 5.0])
    assert np.abs(kernels.force(moved)).max() < 1e-8 * MATERIALS[material][0]


@pytest.mark.parametrize("material", MATERIALS)
def test_patch_homogeneous_deformation_leaves_interior_nodes_balanced(
    lib: ctypes.CDLL, material: str
) -> None:
    points, tetra = grid((3, 3, 3), (1.0, 1.0, 1.0))
    kernels = Kernels(lib, tetra, points, material)
    gradient = np.array([[1.12, 0.05, -0.03], [0.02, 0.93, 0.04], [-0.06, 0.01, 1.05]])
    force = kernels.force(points @ gradient.T + np.array([0.5, 0.2, -0.1])).reshape(-1, 3)
    centre = 13  # the only interior node of a 3x3x3 grid
    assert np.allclose(points[centre], 0.5)
    assert np.abs(force).max() > 10.0
    assert np.abs(force[centre]).max() < 1e-10 * np.abs(force).max()
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-10 * np.abs(force).max())


# ---- uniaxial tension: stress-stretch curves from the energy in principal stretches --------------

_AB = (1 / 2, 1 / 160, 11 / (1050 * 64), 19 / (7000 * 512), 519 / (673750 * 4096))


def _energy(material: str, p: list[float], stretch: np.ndarray) -> complex:
    """Strain energy density in principal stretches (complex-safe)."""
    squares = stretch**2
    I1 = squares.sum()
    I2 = squares[0] * squares[1] + squares[1] * squares[2] + squares[0] * squares[2]
    J = stretch.prod()
    log_j = np.log(J)
    if material == "ArrudaBoyce":
        series = sum(c * (J ** (-2 * k / 3) * I1**k - 3**k) for k, c in enumerate(_AB, start=1))
        return p[0] * series + p[1] * log_j**2 / 2
    if material == "StVenantKirchhoff":
        strain = (squares - 1) / 2
        return p[1] / 2 * strain.sum() ** 2 + p[0] * (strain**2).sum()
    if material == "NeoHookean":
        return p[0] / 2 * (I1 - 3) - p[0] * log_j + p[1] / 2 * log_j**2
    if material == "MooneyRivlin":
        return p[0] * (J ** (-2 / 3) * I1 - 3) + p[1] * (J ** (-4 / 3) * I2 - 3) + p[2] * log_j**2 / 2
    if material == "VerondaWestman":
        return (
            p[0] * (np.exp(p[1] * (J ** (-2 / 3) * I1 - 3)) - 1)
            - p[0] * p[1] / 2 * (J ** (-4 / 3) * I2 - 3)
            + p[2] * log_j**2 / 2
        )
    if material == "Ogden":
        mu, alpha, k0 = p
        return mu / alpha**2 * (J ** (-alpha / 3) * (stretch**alpha).sum() - 3) + k0 * log_j**2 / 2
    if material == "Costa":
        a, k0, bff, _, bss, _, _, bnn = p
        strain = (squares - 1) / 2
        q = bff * strain[0] ** 2 + bss * strain[1] ** 2 + bnn * strain[2] ** 2
        return a * (np.exp(J ** (-4 / 3) * q) - 1) / 2 + k0 * (J * log_j - J - 1)
    assert material == "StableNeoHookean"
    mu, lam = p
    alpha = 1 + mu / (lam + mu)
    return 0.5 * (mu * (I1 - 3) + (lam + mu) * (J - alpha) ** 2)


def _piola(material: str, p: list[float], stretch: np.ndarray, axis: int) -> float:
    """P_axis,axis = dW/d(stretch_axis) by a complex step (exact to round-off)."""
    h = 1e-30
    probe = stretch.astype(complex)
    probe[axis] += 1j * h
    return float(np.imag(_energy(material, p, probe)) / h)


def _lateral_stretch(material: str, p: list[float], axial: float) -> float:
    """The lateral stretch with zero lateral stress (bisection on P_22)."""
    low, high = 0.5, 1.5

    def lateral(t: float) -> float:
        return _piola(material, p, np.array([axial, t, t]), 1)

    assert lateral(low) < 0 < lateral(high)
    for _ in range(200):
        middle = (low + high) / 2
        low, high = (middle, high) if lateral(middle) < 0 else (low, middle)
    return (low + high) / 2


def test_stress_stretch_curves_match_the_closed_forms() -> None:
    mu, lam = MATERIALS["NeoHookean"]
    for axial, lateral in ((1.2, 0.95), (0.85, 1.03)):
        stretch = np.array([axial, lateral, lateral])
        J = stretch.prod()
        neo = mu * (axial - 1 / axial) + lam * np.log(J) / axial
        assert _piola("NeoHookean", MATERIALS["NeoHookean"], stretch, 0) == pytest.approx(neo, rel=1e-12)
        strain = (stretch**2 - 1) / 2
        stvk = axial * (lam * strain.sum() + 2 * mu * strain[0])
        assert _piola("StVenantKirchhoff", [mu, lam], stretch, 0) == pytest.approx(stvk, rel=1e-12)


@pytest.mark.parametrize("material", MATERIALS)
def test_bar_in_uniaxial_tension_follows_the_stress_stretch_curve(lib: ctypes.CDLL, material: str) -> None:
    length, width = 3.0, 1.0
    points, tetra = grid((4, 2, 2), (length, width, width))
    params = BAR_PARAMETERS[material]
    kernels = Kernels(lib, tetra, points, material, params)
    for axial in (0.9, 1.1, 1.25):
        lateral = _lateral_stretch(material, params, axial)
        stretch = np.array([axial, lateral, lateral])
        force = kernels.force(points * stretch).reshape(-1, 3)
        # sum_a phi(X_a) f_a = -V P grad(phi) for a linear phi: with phi = X / length, the end
        # reaction -A P e_x; with phi = Y / width, -A_y P e_y (free lateral faces: 0)
        area = width * width
        axial_reaction = -(points[:, 0] / length) @ force / area
        lateral_reaction = -(points[:, 1] / width) @ force / (length * width)
        expected = _piola(material, params, stretch, 0)
        assert abs(expected) > 1.0
        assert axial_reaction[0] == pytest.approx(expected, rel=1e-9)
        np.testing.assert_allclose(axial_reaction[1:], 0.0, atol=1e-9 * abs(expected))
        np.testing.assert_allclose(lateral_reaction, 0.0, atol=1e-8 * abs(expected))


# ---- check-time errors ---------------------------------------------------------------------------

_BAD = """<Node name="root" dt="0.01">
  <DefaultAnimationLoop/>
  <Node name="bar">
    <EulerImplicitSolver/>
    <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
    <RegularGridTopology name="grid" min="0 0 0" max="1 1 2" n="2 2 3"/>
    <MechanicalObject name="dofs"/>
    <UniformMass totalMass="1"/>
    <Node name="tetras">
      <MeshTopology name="tets"/>
      <Hexa2TetraTopologicalMapping input="@../grid" output="@tets"/>
      <TetrahedronHyperelasticityFEMForceField name="foo" materialName="Foo" ParameterSet="1 2"/>
      <TetrahedronHyperelasticityFEMForceField name="short" materialName="Ogden"
          ParameterSet="1000 2"/>
      <TetrahedronHyperelasticityFEMForceField name="none"/>
      <TetrahedronHyperelasticityFEMForceField name="fine" materialName="MooneyRivlin" ParameterSet="1 2 3"/>
      <TetrahedronHyperelasticityFEMForceField name="flat" materialName="Ogden" ParameterSet="1000 0 5"/>
    </Node>
  </Node>
</Node>
"""


def test_unknown_materials_and_short_parameter_sets_are_check_errors(tmp_path: Path) -> None:
    scene = tmp_path / "bad.scn"
    scene.write_text(_BAD)
    _, diagnostics = check_file(scene)
    found = [(d.code, d.loc.line, d.loc.attribute) for d in diagnostics if d.code.startswith("E")]
    assert found == [
        ("E204", 12, "materialName"),
        ("E205", 14, "ParameterSet"),
        ("E205", 15, "ParameterSet"),
        ("E207", 17, "ParameterSet"),
    ]
    messages = [d.message for d in diagnostics if d.code.startswith("E")]
    assert "Foo" in messages[0] and "StableNeoHookean" in messages[0]  # the name and the choices
    assert "mu1 alpha1 k0" in messages[1] and "2 numbers" in messages[1]
    assert "no ParameterSet" in messages[2]


# ---- scenes --------------------------------------------------------------------------------------


def test_sofa_regression_scene_passes(shared_dir: Path) -> None:
    """The five materials of SOFA's example (Ogden with alpha1 = 500) under implicit Euler and a
    25-iteration CG, beside a corotational bar: SOFA's criterion."""
    root = shared_dir / "reference" / "sofa-regression"
    scene = "Component/SolidMechanics/FEM/TetrahedronHyperelasticityFEMForceField.scn"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[scene]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= 1e-3 * result.epsilon


_BAR = """
  <Node name="{name}">
    {solver}
    <RegularGridTopology name="grid" n="2 2 5" min="0 0 0" max="1 1 4"/>
    <MechanicalObject name="dofs"/>
    <UniformMass totalMass="2"/>
    <BoxROI name="clamp" box="-0.01 -0.01 -0.01 1.01 1.01 0.01"/>
    <FixedProjectiveConstraint indices="@clamp.indices"/>
    <Node name="tetras">
      <MeshTopology name="tets"/>
      <Hexa2TetraTopologicalMapping input="@../grid" output="@tets"/>
      <TetrahedronHyperelasticityFEMForceField materialName="NeoHookean" ParameterSet="300 1000"/>
    </Node>
  </Node>"""

_SOLVERS = {
    "cg": '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
    '<CGLinearSolver iterations="500" tolerance="1e-30" threshold="1e-30"/>',
    "ldl": '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/><SparseLDLSolver/>',
    "explicit": '<EulerExplicitSolver symplectic="1"/>',
}


def test_matrix_free_assembled_and_explicit_solves_agree(tmp_path: Path) -> None:
    """One bar per solver (one scene, one compile): implicit Euler with the matrix-free CG
    (addDForce) and with the assembled LDL solve (addKToMatrix) give the same motion; symplectic
    explicit Euler (addForce only) meets them at this small step (both schemes are first order)."""
    scene = tmp_path / "bars.scn"
    bars = "".join(_BAR.format(name=name, solver=solver) for name, solver in _SOLVERS.items())
    scene.write_text(f'<Node name="root" gravity="0 -9.81 0" dt="2e-4"><DefaultAnimationLoop/>{bars}</Node>')
    sim = sofac.load(scene)
    sim.step(1500)
    final = {name: np.asarray(sim[f"/{name}/dofs"].position, dtype=float).reshape(-1, 3) for name in _SOLVERS}
    sag = np.abs(final["cg"] - grid((2, 2, 5), (1.0, 1.0, 4.0))[0]).max()
    assert sag > 0.05  # the bar bends under its weight
    np.testing.assert_allclose(final["ldl"], final["cg"], rtol=0, atol=1e-8 * sag)
    assert np.abs(final["explicit"] - final["cg"]).max() < 0.005 * sag  # measured: 0.001


def test_a_grid_p0_set_in_the_scene_is_its_origin(tmp_path: Path) -> None:
    """RegularGridTopology: a p0 the scene sets replaces the origin min gives (SOFA's setPos keeps a
    set p0), as SOFA's hyperelastic example places its five bars."""
    scene = tmp_path / "grid.scn"
    scene.write_text(
        '<Node name="root"><RegularGridTopology name="a" min="0 0 0" max="1 1 2" n="2 2 3" p0="2 0 0"/>'
        '<RegularGridTopology name="b" min="0 0 0" max="1 1 2" n="2 2 3"/></Node>'
    )
    checked, diagnostics = check_file(scene)
    assert checked is not None and not diagnostics.has_errors()
    grids = {c.component.name: c.component for c in checked}
    shifted = np.asarray(checked.value(grids["a"], "position")).reshape(-1, 3)
    plain = np.asarray(checked.value(grids["b"], "position")).reshape(-1, 3)
    np.testing.assert_array_equal(shifted, plain + np.array([2.0, 0.0, 0.0]))
    assert plain.min(axis=0).tolist() == [0.0, 0.0, 0.0] and plain.max(axis=0).tolist() == [1.0, 1.0, 2.0]
