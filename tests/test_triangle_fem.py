"""TriangleFEMForceField (runtime/sofac/shell.h triangle_fem_*), against SOFA's own unit test
(TriangleFEMForceField_test.cpp: the element values of a two-triangle mesh at init and of a 40x40
grid after 100 steps, and that grid's trajectory), a NumPy transcription of SOFA's formulas,
finite differences of the force, the closed form of a stretched strip, and one scene of SOFA's tree.

SOFA's getPotentialEnergy returns 0 for this component, so there is no energy to check.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i

SHIM = r"""
#include "sofac/shell.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void tri_init(const Index* t, Index n, const double* x0, double young, double nu, double thickness,
                  int plane_strain, int method, double* data) {
    sofac::triangle_fem_init(t, n, x0, &young, 1, &nu, 1, thickness, plane_strain != 0, method, data);
}
API void tri_force(const Index* t, Index n, const double* x, double* f, double* data, int method) {
    sofac::triangle_fem_add_force(t, n, x, f, data, method);
}
API void tri_dforce(const Index* t, Index n, const double* dx, double* df, double k, const double* data,
                    int method) {
    sofac::triangle_fem_add_dforce(t, n, dx, df, k, data, method);
}
API void tri_matrix(const double* data, Index e, int method, double* out) {
    sofac::triangle_fem_element_matrix(data, e, method, out);
}
"""

SMALL, LARGE = 0, 1
DATA = 36  # shell.h triangle_fem_data_size


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "triangle_fem", SHIM)
    library.tri_init.argtypes = [I64, ctypes.c_int64, D, ctypes.c_double, ctypes.c_double, ctypes.c_double]
    library.tri_init.argtypes += [ctypes.c_int, ctypes.c_int, D]
    library.tri_force.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_int]
    library.tri_dforce.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int]
    library.tri_matrix.argtypes = [D, ctypes.c_int64, ctypes.c_int, D]
    return library


class Membrane:
    def __init__(
        self,
        lib: ctypes.CDLL,
        rest: np.ndarray,
        triangles: np.ndarray,
        *,
        young: float = 100.0,
        nu: float = 0.3,
        thickness: float = 1.0,
        plane_strain: bool = False,
        method: int = LARGE,
    ) -> None:
        self.lib, self.method = lib, method
        self.rest = np.ascontiguousarray(rest, dtype=float)
        self.tri = np.ascontiguousarray(triangles, dtype=np.int64)
        self.n = len(self.tri)
        self.data = np.zeros(DATA * self.n)
        lib.tri_init(
            _i(self.tri), self.n, _d(self.rest), young, nu, thickness, plane_strain, method, _d(self.data)
        )

    def element(self, e: int) -> dict[str, np.ndarray]:
        d = self.data[DATA * e : DATA * (e + 1)]
        return {"rotation": d[:9].reshape(3, 3), "rest": d[9:13], "J": d[13:31].reshape(6, 3), "K": d[31:]}

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(self.rest)
        x = np.ascontiguousarray(x)
        self.lib.tri_force(_i(self.tri), self.n, _d(x), _d(f), _d(self.data), self.method)
        return f

    def dforce(self, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        df = np.zeros_like(self.rest)
        self.lib.tri_dforce(
            _i(self.tri), self.n, _d(np.ascontiguousarray(dx)), _d(df), kfactor, _d(self.data), self.method
        )
        return df

    def stiffness(self) -> np.ndarray:
        """The global K from the element matrices (what an assembled solver adds, times -kfact)."""
        size = self.rest.size
        k = np.zeros((size, size))
        out = np.zeros(81)
        for e, t in enumerate(self.tri):
            self.lib.tri_matrix(_d(self.data), e, self.method, _d(out))
            dofs = (3 * t[:, None] + np.arange(3)).ravel()
            k[np.ix_(dofs, dofs)] += out.reshape(9, 9)
        return k


# SOFA's createSingleTriangleFEMScene: two triangles, one in the plane z = 0, one tilted
SOFA_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], dtype=float)
SOFA_TRIANGLES = np.array([[0, 1, 2], [1, 3, 2]], dtype=np.int64)


def test_init_matches_sofas_unit_test(lib: ctypes.CDLL) -> None:
    """TriangleFEMForceField_test::checkInit (E = 100, nu = 0.3, large), with its tolerance 1e-4:
    the rotated rest triangles, the rotations, the material stiffness, the strain-displacement."""
    mesh = Membrane(lib, SOFA_POINTS, SOFA_TRIANGLES)
    rotated = [
        [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0, 0, 0], [1.4142135, 0, 0], [0.707107, 1.2247449, 0]],
    ]
    rotations = [
        np.eye(3),
        [[0, -0.81649661, -0.57735], [0.707107, 0.40824831, -0.57735], [0.707107, -0.40824831, 0.57735]],
    ]
    stiffness = [
        [[54.945053, 16.483517, 0], [16.483517, 54.945053, 0], [0, 0, 19.23077]],
        [[95.1676, 28.550287, 0], [28.550287, 95.1676, 0], [0, 0, 33.30867]],
    ]
    strain_displacement = [
        [[-1, 0, -1], [0, -1, -1], [1, 0, 0], [0, 0, 1], [0, 0, 1], [0, 1, 0]],
        [
            [-0.707107, 0, -0.408248],
            [0, -0.408248, -0.707107],
            [0.707107, 0, -0.408248],
            [0, -0.408248, 0.707107],
            [0, 0, 0.816497],
            [0, 0.816497, 0],
        ],
    ]
    for e in range(2):
        got = mesh.element(e)
        b_x, b_y, c_x, c_y = got["rest"]
        assert [[0, 0, 0], [b_x, b_y, 0], [c_x, c_y, 0]] == pytest.approx(np.array(rotated[e]), abs=1e-4)
        assert got["rotation"] == pytest.approx(np.array(rotations[e]), abs=1e-4)
        k00, k01, k10, k11, k22 = got["K"]
        assert [[k00, k01, 0], [k10, k11, 0], [0, 0, k22]] == pytest.approx(np.array(stiffness[e]), abs=1e-4)
        assert got["J"] == pytest.approx(np.array(strain_displacement[e]), abs=1e-4)


def frame(pa: np.ndarray, pb: np.ndarray, pc: np.ndarray) -> np.ndarray:
    """SOFA's computeRotationLarge: rows x along ab, z the normal, y = z x x."""
    ex = (pb - pa) / np.linalg.norm(pb - pa)
    ez = np.cross(ex, pc - pa)
    ez /= np.linalg.norm(ez)
    return np.array([ex, np.cross(ez, ex), ez])


def strain_displacement(b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """SOFA's computeStrainDisplacementLocal (b = (b_x, 0), c = (c_x, c_y))."""
    inv = 1.0 / (b[0] * c[1])
    j = np.zeros((6, 3))
    j[0, 0] = j[1, 2] = -c[1] * inv
    j[0, 2] = j[1, 1] = (c[0] - b[0]) * inv
    j[2, 0] = j[3, 2] = c[1] * inv
    j[2, 2] = j[3, 1] = -c[0] * inv
    j[4, 2] = j[5, 1] = b[0] * inv
    return j


def hooke(young: float, nu: float, area: float, plane_strain: bool) -> np.ndarray:
    if plane_strain:
        e = young / ((1 + nu) * (1 - 2 * nu)) * area
        return e * np.array([[1 - nu, nu, 0], [nu, 1 - nu, 0], [0, 0, 0.5 - nu]])
    e = young / (1 - nu * nu) * area
    return e * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, 0.5 * (1 - nu)]])


def numpy_forces(
    rest: np.ndarray, tri: np.ndarray, x: np.ndarray, young: float, nu: float, plane_strain: bool, method: int
) -> np.ndarray:
    """SOFA's accumulateForceLarge / accumulateForceSmall transcribed."""
    f = np.zeros_like(x)
    for a, b, c in tri:
        area = 0.5 * np.linalg.norm(np.cross(rest[b] - rest[a], rest[c] - rest[a]))
        k = hooke(young, nu, area, plane_strain)
        if method == LARGE:
            r0 = frame(rest[a], rest[b], rest[c])
            rb, rc = r0 @ rest[b] - r0 @ rest[a], r0 @ rest[c] - r0 @ rest[a]
            r = frame(x[a], x[b], x[c])
            db, dc = r @ (x[b] - x[a]), r @ (x[c] - x[a])
            d = np.array([0, 0, rb[0] - db[0], 0, rc[0] - dc[0], rc[1] - dc[1]])
        else:
            rb, rc = rest[b] - rest[a], rest[c] - rest[a]
            db, dc = x[b] - x[a], x[c] - x[a]
            d = np.array([0, 0, rb[0] - db[0], rb[1] - db[1], rc[0] - dc[0], rc[1] - dc[1]])
            r = np.eye(3)
        j = strain_displacement(db, dc)
        local = j @ (k @ (j.T @ d))
        for node, index in enumerate((a, b, c)):
            f[index] += r.T @ np.array([local[2 * node], local[2 * node + 1], 0.0])
    return f


def sheet(nx: int = 4, ny: int = 3, tilt: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """A tilted, slightly warped sheet of (nx-1)(ny-1) quads cut in two triangles each."""
    xs, ys = np.meshgrid(np.linspace(0, 3, nx), np.linspace(0, 2, ny))
    rest = np.column_stack([xs.ravel(), ys.ravel(), tilt * xs.ravel() + 0.05 * np.sin(ys.ravel())])
    tri = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            q = [j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
            tri += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return rest, np.array(tri, dtype=np.int64)


@pytest.mark.parametrize("plane_strain", [False, True], ids=["plane_stress", "plane_strain"])
def test_large_forces_match_sofas_formulas(lib: ctypes.CDLL, plane_strain: bool) -> None:
    rest, tri = sheet()
    mesh = Membrane(lib, rest, tri, young=250.0, nu=0.35, thickness=1.0, plane_strain=plane_strain)
    x = rest + np.random.default_rng(3).normal(scale=0.05, size=rest.shape)
    expected = numpy_forces(rest, tri, x, 250.0, 0.35, plane_strain, LARGE)
    assert mesh.force(x) == pytest.approx(expected, rel=1e-11, abs=1e-11 * np.abs(expected).max())


def test_thickness_scales_the_forces(lib: ctypes.CDLL) -> None:
    rest, tri = sheet()
    x = rest + np.random.default_rng(4).normal(scale=0.05, size=rest.shape)
    thin = Membrane(lib, rest, tri, thickness=1.0).force(x)
    thick = Membrane(lib, rest, tri, thickness=2.5).force(x)
    assert thick == pytest.approx(2.5 * thin, rel=1e-13, abs=1e-15)


def test_large_is_rotation_invariant(lib: ctypes.CDLL) -> None:
    """No force at rest nor after a rigid motion; a deformation then a rotation turns the forces."""
    rest, tri = sheet()
    mesh = Membrane(lib, rest, tri)
    assert np.abs(mesh.force(rest)).max() < 1e-12
    angle = 0.7
    q = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    assert np.abs(mesh.force(rest @ q.T + [1.0, -2.0, 0.5])).max() < 1e-10
    x = rest + np.random.default_rng(5).normal(scale=0.05, size=rest.shape)
    assert mesh.force(x @ q.T + [1.0, -2.0, 0.5]) == pytest.approx(mesh.force(x) @ q.T, abs=1e-10)


def test_stiffness_is_the_jacobian_at_rest(lib: ctypes.CDLL) -> None:
    """At rest (no stress) SOFA's corotational K (rotation held) is the exact Jacobian of the force."""
    rest, tri = sheet()
    mesh = Membrane(lib, rest, tri, young=300.0, nu=0.25)
    dx = np.random.default_rng(6).normal(size=rest.shape)
    h = 1e-6
    fd = (mesh.force(rest + h * dx) - mesh.force(rest - h * dx)) / (2 * h)
    mesh.force(rest)  # the pass K dx reads (rotations and J of the rest shape)
    df = mesh.dforce(dx)
    assert df == pytest.approx(fd, rel=1e-6, abs=1e-6 * np.abs(fd).max())
    assert mesh.dforce(dx, -0.3) == pytest.approx(-0.3 * df, rel=1e-14, abs=1e-14)


@pytest.mark.parametrize("method", [LARGE, SMALL], ids=["large", "small"])
def test_element_matrices_are_the_matrix_free_stiffness(lib: ctypes.CDLL, method: int) -> None:
    """What an assembled solver adds (SOFA's computeElementStiffnessMatrix, RR J K J^T RR^T) is the
    operator K dx applies, at the rotations and J of the last force pass; symmetric."""
    rest, tri = sheet(tilt=0.0 if method == SMALL else 0.4)
    mesh = Membrane(lib, rest, tri, method=method)
    mesh.force(rest + np.random.default_rng(7).normal(scale=0.05, size=rest.shape))
    size = rest.size
    columns = [-mesh.dforce(np.eye(size)[k].reshape(-1, 3)).ravel() for k in range(size)]
    matrix_free = np.array(columns).T
    k = mesh.stiffness()
    assert k == pytest.approx(matrix_free, abs=1e-10 * np.abs(k).max())
    assert k == pytest.approx(k.T, abs=1e-10 * np.abs(k).max())


def test_small_method_is_sofas_world_plane_element(lib: ctypes.CDLL) -> None:
    """SOFA's small method (its header warns it is unvalidated): world x, y displacements, J from the
    current edges, no force along z, K zero before the first force pass (init does not compute J)."""
    rest, tri = sheet(tilt=0.0)
    mesh = Membrane(lib, rest, tri, young=80.0, nu=0.2, method=SMALL)
    dx = np.random.default_rng(8).normal(size=rest.shape)
    assert not mesh.dforce(dx).any()
    x = rest + np.random.default_rng(9).normal(scale=0.05, size=rest.shape)
    f = mesh.force(x)
    assert f == pytest.approx(numpy_forces(rest, tri, x, 80.0, 0.2, False, SMALL), rel=1e-11, abs=1e-12)
    assert not f[:, 2].any()
    assert np.abs(mesh.force(rest)).max() < 1e-13
    assert np.abs(mesh.force(rest + np.array([0.3, -0.2, 0.7]))).max() < 1e-12  # translations


GRID = """\
<Node name="root" dt="0.01" gravity="0 10 0">
  <DefaultAnimationLoop/>
  <RegularGridTopology name="grid" n="40 40 1" min="0 0 0" max="10 10 0"/>
  <Node name="TriangleFEM">
    <EulerImplicitSolver/>
    <CGLinearSolver iterations="20" tolerance="1e-5" threshold="1e-6"/>
    <MechanicalObject name="dof" template="Vec3d" position="@../grid.position"/>
    <TriangleSetTopologyContainer name="topo" src="@../grid"/>
    <TriangleSetTopologyModifier name="Modifier"/>
    <TriangleSetGeometryAlgorithms name="GeomAlgo" template="Vec3d"/>
    <{component} name="FEM" youngModulus="100" poissonRatio="0.3" method="large"/>
    <DiagonalMass name="mass" massDensity="0.1"/>
    <FixedProjectiveConstraint name="fix" indices="0 39"/>
  </Node>
</Node>
"""


def _element_data(sim: sofac.Simulation, key: str) -> np.ndarray:
    return next(v for b, v in zip(sim.spec.buffers, sim._views, strict=True) if b.key.endswith(key))


def test_grid_matches_sofas_unit_test(tmp_path: Path) -> None:
    """TriangleFEMForceField_test::checkFEMValues: a 40x40 sheet hanging from two corners, 100 implicit
    steps; node 1515 and element 42 as SOFA's test expects them (its tolerance, 1e-4). The
    TriangularFEMForceField of the same scene follows the same path (SOFA's test expects the same
    node for both), up to round-off amplified by 20 CG iterations: both rest shapes and areas are
    computed in different orders."""
    path = tmp_path / "grid.scn"
    path.write_text(GRID.format(component="TriangleFEMForceField"))
    sim = sofac.load(path)
    dofs = sim["TriangleFEM/dof"]
    assert dofs.position[1515] == pytest.approx([8.97436, 9.48718, 0], abs=1e-4)
    sim.step(100)
    assert dofs.position[1515] == pytest.approx([8.9135, 14.2499, 0], abs=1e-4)
    e = _element_data(sim, "FEM.elements").reshape(-1, DATA)[42]
    assert e[9:13] == pytest.approx([0.25641, 0, 0.25641, 0.25641], abs=1e-4)
    assert e[:9].reshape(3, 3) == pytest.approx(
        np.array([[0.99992, -0.0126608, 0], [0.0126608, 0.99992, 0], [0, 0, 1]]), abs=1e-4
    )
    assert e[31:] == pytest.approx([3.61243, 1.08373, 1.08373, 3.61243, 1.26435], abs=1e-4)
    expected_j = [[-3.89456, 0, -0.00185328], [0, -0.00185328, -3.89456], [3.89456, 0, -3.89816]]
    expected_j += [[0, -3.89816, 3.89456], [0, 0, 3.90001], [0, 3.90001, 0]]
    assert e[13:31].reshape(6, 3) == pytest.approx(np.array(expected_j), abs=1e-4)
    other = tmp_path / "triangular.scn"
    other.write_text(GRID.format(component="TriangularFEMForceField"))
    sim2 = sofac.load(other)
    sim2.step(100)
    assert sim2["TriangleFEM/dof"].position == pytest.approx(dofs.position, abs=1e-5)


STRIP = """\
<Node name="root" dt="1" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <StaticSolver/>
  <{solver}/>
  <MechanicalObject name="dofs" template="Vec3d" position="{points}"/>
  <TriangleSetTopologyContainer triangles="{triangles}"/>
  <TriangleFEMForceField youngModulus="{young}" poissonRatio="{nu}" thickness="{thickness}"
                         planeStrain="{plane_strain}"/>
  <PartialFixedProjectiveConstraint indices="{left}" fixedDirections="1 0 1"/>
  <PartialFixedProjectiveConstraint indices="{others}" fixedDirections="0 0 1"/>
  <FixedProjectiveConstraint indices="0"/>
  <ConstantForceField indices="{right}" forces="{forces}"/>
</Node>
"""


@pytest.mark.parametrize(
    "solver,plane_strain",
    [
        ('CGLinearSolver iterations="500" tolerance="1e-30" threshold="1e-30"', False),
        ("SparseLDLSolver", False),
        ("SparseLDLSolver", True),
    ],
    ids=["cg", "direct", "direct-plane-strain"],
)
def test_stretched_strip_is_exact(tmp_path: Path, solver: str, plane_strain: bool) -> None:
    """Patch test: a strip L x h pulled by P at its end (consistent nodal loads), its left end held
    along x only. Constant strain triangles carry the uniform stress exactly: u = P L / (E' t h)
    and the lateral strain -nu' P / (E' t h), E' = E, nu' = nu in plane stress, E' = E / (1 - nu^2),
    nu' = nu / (1 - nu) in plane strain. One Newton step of the static solver (small load: linear)."""
    length, height, nx, ny = 4.0, 1.0, 9, 4
    young, nu, thickness, load = 1000.0, 0.3, 0.2, 0.02
    xs, ys = np.meshgrid(np.linspace(0, length, nx), np.linspace(0, height, ny))
    points = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    triangles = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            q = [j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
            triangles += [q[0], q[1], q[2], q[0], q[2], q[3]]
    left = [j * nx for j in range(ny)]
    right = [j * nx + nx - 1 for j in range(ny)]
    share = np.full(ny, load / (ny - 1))
    share[[0, -1]] /= 2
    forces = " ".join(f"{float(s)!r} 0 0" for s in share)
    path = tmp_path / "strip.scn"
    path.write_text(
        STRIP.format(
            solver=solver,
            points=" ".join(map(repr, points.ravel().tolist())),
            triangles=" ".join(map(str, triangles)),
            young=young,
            nu=nu,
            thickness=thickness,
            plane_strain=str(plane_strain).lower(),
            left=" ".join(map(str, left)),
            others=" ".join(str(k) for k in range(nx * ny) if k not in left),
            right=" ".join(map(str, right)),
            forces=forces,
        )
    )
    sim = sofac.load(path)
    sim.step(1)
    u = sim["dofs"].position - points
    e_eff, nu_eff = (young / (1 - nu**2), nu / (1 - nu)) if plane_strain else (young, nu)
    stress = load / (thickness * height)
    assert u[:, 0] == pytest.approx(stress / e_eff * points[:, 0], rel=1e-5, abs=1e-12)
    assert u[:, 1] == pytest.approx(-nu_eff * stress / e_eff * points[:, 1], rel=1e-5, abs=1e-12)


def test_sofa_example_scene_runs(corpus_dir: Path) -> None:
    """SOFA's examples/Component/SolidMechanics/FEM/TriangleFEMForceField.scn: three sheets held at
    corners, 300 steps; they sag under gravity and stay finite, their fixed corners in place."""
    sim = sofac.load(corpus_dir / "Component/SolidMechanics/FEM/TriangleFEMForceField.scn")
    states = [s.path for s in sim.states()]
    rest = {p: sim[p].position.copy() for p in states}
    sim.step(300)
    for p in states:
        moved = np.linalg.norm(sim[p].position - rest[p], axis=1)
        assert np.isfinite(sim[p].position).all()
        assert 0.5 < moved.max() < 20.0  # a 9-unit sheet sags by units, not by its size
        assert moved[0] == 0.0
