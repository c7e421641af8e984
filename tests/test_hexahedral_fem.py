"""HexahedralFEMForceField (runtime/sofac/hexahedral_fem.h): SOFA's closed-form element stiffness
(exact for cubes, SOFA's formula otherwise), its corotational force and K dx, the assembled matrix
with SOFA's transposed rotation, a uniformly stretched block (exact), a cantilever against beam
theory within the discretisation error, and SOFA's example scene.

SOFA's getPotentialEnergy returns 0 for this component, as sofac's does.
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
#include "sofac/hexahedral_fem.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void hx_init(const Index* h, Index n, const double* x0, double young, double nu, int method,
                 double* data) {
    sofac::hexahedral_fem_init(h, n, x0, &young, 1, &nu, 1, method, data);
}
API void hx_force(const Index* h, Index n, const double* x, double* f, double* data, int method) {
    sofac::hexahedral_fem_add_force(h, n, x, f, data, method);
}
API void hx_dforce(const Index* h, Index n, const double* dx, double* df, double k, const double* data,
                   int method) {
    sofac::hexahedral_fem_add_dforce(h, n, dx, df, k, data, method);
}
API void hx_matrix(const double* data, Index e, int method, double* out) {
    sofac::hexahedral_fem_element_matrix(data, e, method, out);
}
"""

LARGE, POLAR = 1, 2
DATA = 609
# SOFA's node order: reference coordinates of the 8 corners
CORNERS = np.array(
    [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]],
    dtype=float,
)


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "hexahedral_fem", SHIM)
    library.hx_init.argtypes = [I64, ctypes.c_int64, D, ctypes.c_double, ctypes.c_double, ctypes.c_int, D]
    library.hx_force.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_int]
    library.hx_dforce.argtypes = [I64, ctypes.c_int64, D, D, ctypes.c_double, D, ctypes.c_int]
    library.hx_matrix.argtypes = [D, ctypes.c_int64, ctypes.c_int, D]
    return library


class Block:
    def __init__(
        self,
        lib: ctypes.CDLL,
        rest: np.ndarray,
        hexa: np.ndarray,
        young: float,
        nu: float,
        method: int = LARGE,
    ) -> None:
        self.lib, self.method = lib, method
        self.rest = np.ascontiguousarray(rest, dtype=float)
        self.hexa = np.ascontiguousarray(hexa, dtype=np.int64)
        self.n = len(self.hexa)
        self.data = np.zeros(DATA * self.n)
        lib.hx_init(_i(self.hexa), self.n, _d(self.rest), young, nu, method, _d(self.data))

    def stiffness(self, e: int = 0) -> np.ndarray:
        return self.data[DATA * e : DATA * e + 576].reshape(24, 24)

    def force(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(self.rest)
        x = np.ascontiguousarray(x)
        self.lib.hx_force(_i(self.hexa), self.n, _d(x), _d(f), _d(self.data), self.method)
        return f

    def dforce(self, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        df = np.zeros_like(self.rest)
        dx = np.ascontiguousarray(dx)
        self.lib.hx_dforce(_i(self.hexa), self.n, _d(dx), _d(df), kfactor, _d(self.data), self.method)
        return df

    def element_matrix(self, e: int = 0) -> np.ndarray:
        out = np.zeros(576)
        self.lib.hx_matrix(_d(self.data), e, self.method, _d(out))
        return out.reshape(24, 24)


def box(a: float, b: float, c: float) -> np.ndarray:
    return (CORNERS + 1) / 2 * np.array([a, b, c])


def trilinear_stiffness(nodes: np.ndarray, young: float, nu: float) -> np.ndarray:
    """The textbook trilinear hexahedron stiffness, 2x2x2 Gauss points (exact for a box)."""
    lam, mu = young * nu / ((1 + nu) * (1 - 2 * nu)), young / (2 * (1 + nu))
    hooke = np.zeros((6, 6))
    hooke[:3, :3] = lam
    hooke[:3, :3] += 2 * mu * np.eye(3)
    hooke[3:, 3:] = mu * np.eye(3)
    k = np.zeros((24, 24))
    g = 1 / np.sqrt(3)
    for point in np.array(np.meshgrid([-g, g], [-g, g], [-g, g])).reshape(3, -1).T:
        grad = np.array(
            [
                [
                    c[0] * (1 + c[1] * point[1]) * (1 + c[2] * point[2]) / 8,
                    (1 + c[0] * point[0]) * c[1] * (1 + c[2] * point[2]) / 8,
                    (1 + c[0] * point[0]) * (1 + c[1] * point[1]) * c[2] / 8,
                ]
                for c in CORNERS
            ]
        )
        jacobian = grad.T @ nodes
        dn = grad @ np.linalg.inv(jacobian).T
        strain = np.zeros((6, 24))
        for i, (gx, gy, gz) in enumerate(dn):
            strain[0, 3 * i], strain[1, 3 * i + 1], strain[2, 3 * i + 2] = gx, gy, gz
            strain[3, 3 * i], strain[3, 3 * i + 1] = gy, gx
            strain[4, 3 * i + 1], strain[4, 3 * i + 2] = gz, gy
            strain[5, 3 * i], strain[5, 3 * i + 2] = gz, gx
        k += strain.T @ hooke @ strain * np.linalg.det(jacobian)
    return k


@pytest.mark.parametrize("side", [1.0, 0.3, 2.5])
def test_cube_stiffness_is_the_trilinear_element(lib: ctypes.CDLL, side: float) -> None:
    """For a cube SOFA's closed form is the trilinear element's stiffness, each entry rounded to float."""
    young, nu = 1000.0, 0.3
    nodes = box(side, side, side)
    k = Block(lib, nodes, np.arange(8)[None], young, nu).stiffness()
    exact = trilinear_stiffness(nodes, young, nu)
    assert k == pytest.approx(exact, rel=1e-7, abs=1e-7 * np.abs(exact).max())
    assert np.array_equal(k, k.T)
    vol = side**3 / 8
    scaled = k / vol  # SOFA: vol * float(integrated entry); exact for the power-of-two volume of side 1
    if side == 1.0:
        assert np.array_equal(scaled.astype(np.float32).astype(float), scaled)


def test_box_stiffness_is_sofas_cube_formula(lib: ctypes.CDLL) -> None:
    """SOFA's formula is exact for cubes only ('only accurate for orthogonal regular hexa'): on an
    a x b x c box the xx block of node 0 is float((2/a)^2 (2 M00 + 4 M33) / 9) abc / 8 (it reads
    only J^-1_00), not the trilinear element's."""
    young, nu, (a, b, c) = 1000.0, 0.3, (2.0, 1.0, 0.5)
    nodes = box(a, b, c)
    k = Block(lib, nodes, np.arange(8)[None], young, nu).stiffness()
    scale = young * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    m00, m33 = scale, (1 - 2 * nu) / (2 * (1 - nu)) * scale
    expected = float(np.float32((2 / a) ** 2 * (2 * m00 + 4 * m33) / 9)) * (a * b * c / 8)
    assert k[0, 0] == pytest.approx(expected, rel=1e-15)
    exact = trilinear_stiffness(nodes, young, nu)
    assert abs(k[0, 0] - exact[0, 0]) > 0.5 * exact[0, 0]  # far from it
    for d in range(3):  # still translation-free (to the float rounding of its entries)
        shift = np.zeros(24)
        shift[d::3] = 1.0
        assert np.abs(k @ shift).max() < 1e-6 * np.abs(k).max()


def cubes(nx: int, ny: int, nz: int, side: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A grid of cubes in SOFA's RegularGridTopology order (x fastest), SOFA's corner order."""
    idx = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nz + 1, ny + 1, nx + 1)
    zs, ys, xs = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    points = side * np.column_stack([xs.ravel(), ys.ravel(), zs.ravel()]).astype(float)
    hexa = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                hexa.append([idx[k + (c[2] > 0), j + (c[1] > 0), i + (c[0] > 0)] for c in CORNERS])
    return points, np.array(hexa, dtype=np.int64)


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


@pytest.mark.parametrize("method", [LARGE, POLAR], ids=["large", "polar"])
def test_forces_are_corotational(lib: ctypes.CDLL, method: int) -> None:
    """No force at rest nor after a rigid motion (to the float rounding of SOFA's entries, which
    leaves the rows of Ke summing to ~1e-7 of their size: a translation t gives that times |t|);
    f(Q x) = Q f(x); the force of a small deformation is -Ke u in the rest frame (to first order)."""
    rest, hexa = cubes(2, 1, 1)
    block = Block(lib, rest, hexa, 500.0, 0.35, method)
    scale = np.abs(block.stiffness()).max()
    assert not block.force(rest).any()
    q = rotation(np.array([0.3, -1.0, 0.4]), 0.8)
    assert np.abs(block.force(rest @ q.T)).max() < 1e-12 * scale
    shift = np.array([0.5, 2.0, -1.0])
    assert np.abs(block.force(rest @ q.T + shift)).max() < 1e-6 * scale * np.linalg.norm(shift)
    u = np.random.default_rng(21).normal(scale=1e-6, size=rest.shape)
    f = block.force(rest + u)
    assert block.force((rest + u) @ q.T) == pytest.approx(f @ q.T, abs=1e-9 * np.abs(f).max())
    k = np.zeros((rest.size, rest.size))
    for e, h in enumerate(hexa):
        dofs = (3 * h[:, None] + np.arange(3)).ravel()
        k[np.ix_(dofs, dofs)] += block.stiffness(e)
    assert f.ravel() == pytest.approx(-k @ u.ravel(), rel=1e-4, abs=1e-4 * np.abs(f).max())


@pytest.mark.parametrize("method", [LARGE, POLAR], ids=["large", "polar"])
def test_stiffness_is_the_jacobian_at_rest(lib: ctypes.CDLL, method: int) -> None:
    """K dx (rotation held) against central differences of the force at rest, where the rotation's
    derivative does not contribute; kFactor scales it."""
    rest, hexa = cubes(2, 2, 1, side=0.5)
    block = Block(lib, rest, hexa, 800.0, 0.25, method)
    dx = np.random.default_rng(22).normal(size=rest.shape)
    h = 1e-7
    fd = (block.force(rest + h * dx) - block.force(rest - h * dx)) / (2 * h)
    block.force(rest)
    df = block.dforce(dx)
    assert df == pytest.approx(fd, rel=1e-5, abs=1e-5 * np.abs(fd).max())
    assert block.dforce(dx, 0.4) == pytest.approx(0.4 * df, rel=1e-13, abs=1e-13 * np.abs(df).max())


def test_assembled_matrix_takes_the_rotation_the_other_way(lib: ctypes.CDLL) -> None:
    """SOFA's addKToMatrix / buildStiffnessMatrix: rotation^T Ke rotation with rotation = R^T, i.e.
    R Ke R^T, while K dx applies R^T Ke R: they agree on an unrotated element, not on a rotated one."""
    rest = box(1.0, 1.0, 1.0)
    block = Block(lib, rest, np.arange(8)[None], 300.0, 0.3)
    ke = block.stiffness()

    def matrix_free() -> np.ndarray:
        return np.array([-block.dforce(np.eye(24)[k].reshape(8, 3)).ravel() for k in range(24)]).T

    block.force(rest)
    assert block.element_matrix() == pytest.approx(matrix_free(), abs=1e-12 * np.abs(ke).max())
    q = rotation(np.array([1.0, 2.0, 0.5]), 0.9)
    block.force(rest @ q.T)
    r = block.data[600:609].reshape(3, 3)  # the stored rotation, world to local: R = Q^T
    assert r == pytest.approx(q.T, abs=1e-12)
    big_r = np.kron(np.eye(8), r)
    assert matrix_free() == pytest.approx(big_r.T @ ke @ big_r, abs=1e-10 * np.abs(ke).max())
    assert block.element_matrix() == pytest.approx(big_r @ ke @ big_r.T, abs=1e-10 * np.abs(ke).max())
    assert np.abs(block.element_matrix() - matrix_free()).max() > 0.1 * np.abs(ke).max()


BAR = """\
<Node name="root" dt="1" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <StaticSolver/>
  <NewtonRaphsonSolver maxNbIterationsNewton="{newton}"/>
  <{solver}/>
  <RegularGridTopology name="grid" n="{n}" min="0 0 0" max="{size}"/>
  <MechanicalObject name="dofs"/>
  <HexahedralFEMForceField youngModulus="{young}" poissonRatio="{nu}" method="{method}"/>
  {constraints}
  <ConstantForceField indices="{loaded}" forces="{forces}"/>
</Node>
"""


def _bar(
    path: Path,
    counts: tuple[int, int, int],
    size: tuple[float, float, float],
    constraints: str,
    loaded: np.ndarray,
    forces: np.ndarray,
    *,
    solver: str = "SparseLDLSolver",
    method: str = "large",
    newton: int = 1,
) -> sofac.Simulation:
    path.write_text(
        BAR.format(
            newton=newton,
            solver=solver,
            n=" ".join(str(c + 1) for c in counts),
            size=" ".join(map(repr, size)),
            young=1000.0,
            nu=0.3,
            method=method,
            constraints=constraints,
            loaded=" ".join(map(str, loaded)),
            forces=" ".join(f"{float(v)!r}" for v in np.ravel(forces)),
        )
    )
    return sofac.load(path)


@pytest.mark.parametrize(
    "solver,method",
    [
        ("SparseLDLSolver", "large"),
        ('CGLinearSolver iterations="1000" tolerance="1e-30" threshold="1e-30"', "polar"),
    ],
    ids=["direct-large", "cg-polar"],
)
def test_stretched_block_is_exact(tmp_path: Path, solver: str, method: str) -> None:
    """Patch test: a 3 x 2 x 2 block of unit cubes under a uniform traction s on its x = 3 face
    (consistent nodal loads), held by symmetry planes: u = (s/E x, -nu s/E y, -nu s/E z), exact up to
    the float rounding of SOFA's stiffness entries (a few 1e-7 relative)."""
    points, _ = cubes(3, 2, 2)
    stress = 0.5
    face = np.flatnonzero(points[:, 0] == 3.0)
    # each unit face quad gives a quarter of its load to each corner
    share = np.array([(1 + (0 < p[1] < 2)) * (1 + (0 < p[2] < 2)) for p in points[face]]) * stress / 4
    forces = np.column_stack([share, np.zeros_like(share), np.zeros_like(share)])
    planes = [" ".join(map(str, np.flatnonzero(points[:, d] == 0))) for d in range(3)]
    constraints = "\n".join(
        f'<PartialFixedProjectiveConstraint indices="{plane}" '
        f'fixedDirections="{" ".join("1" if k == d else "0" for k in range(3))}"/>'
        for d, plane in enumerate(planes)
    )
    sim = _bar(tmp_path / "block.scn", (3, 2, 2), (3.0, 2.0, 2.0), constraints, face, forces, solver=solver)
    sim.step(1)
    u = sim["dofs"].position - points
    strain = stress / 1000.0
    expected = points * np.array([strain, -0.3 * strain, -0.3 * strain])
    assert u == pytest.approx(expected, rel=1e-6, abs=1e-6 * strain)


def test_cantilever_converges_to_beam_theory(tmp_path: Path) -> None:
    """A 10 x 2 x 2 cantilever of cubes, clamped at x = 0, a load P at its tip: the mean tip
    deflection against Timoshenko's P L^3 / (3 E I) + P L / (k G A) (k = 5/6). Trilinear elements are
    too stiff in bending (shear locking): 14% short with cubes of side 1, 5% with side 1/2."""
    length, height, young, nu, load = 10.0, 2.0, 1000.0, 0.3, 0.01
    inertia, shear = height**4 / 12, young / (2 * (1 + nu))
    theory = load * length**3 / (3 * young * inertia) + load * length / (5 / 6 * shear * height**2)
    ratios = []
    for per_unit in (1, 2):
        counts = (int(length) * per_unit, int(height) * per_unit, int(height) * per_unit)
        points, _ = cubes(*counts, side=1.0 / per_unit)
        clamped = np.flatnonzero(points[:, 0] == 0.0)
        tip = np.flatnonzero(points[:, 0] == length)
        forces = np.tile([0.0, -load / len(tip), 0.0], (len(tip), 1))
        constraints = f'<FixedProjectiveConstraint indices="{" ".join(map(str, clamped))}"/>'
        sim = _bar(
            tmp_path / f"cantilever{per_unit}.scn",
            counts,
            (length, height, height),
            constraints,
            tip,
            forces,
            newton=3,
        )
        sim.step(1)
        ratios.append(-(sim["dofs"].position - points)[tip, 1].mean() / theory)
    assert 0.80 < ratios[0] < ratios[1] < 1.0
    assert ratios[1] > 0.93


def test_sofa_example_scene_runs() -> None:
    """SOFA's examples/Component/SolidMechanics/FEM/HexahedralFEMForceField.scn (nine hexahedra,
    CG, penalty contacts on the mapped triangles): 300 steps, finite, its four fixed nodes in place."""
    scene = Path("/work/sofa-tree/examples/Component/SolidMechanics/FEM/HexahedralFEMForceField.scn")
    if not scene.is_file():
        pytest.skip("SOFA's examples tree is not extracted at /work/sofa-tree")
    sim = sofac.load(scene)
    dofs = sim["H/Hexa"]
    rest = dofs.position.copy()
    sim.step(300)
    assert np.isfinite(dofs.position).all()
    assert dofs.position[[12, 15, 28, 31]] == pytest.approx(rest[[12, 15, 28, 31]], abs=0)
    moved = np.linalg.norm(dofs.position - rest, axis=1).max()
    assert 0.01 < moved < 2.0
