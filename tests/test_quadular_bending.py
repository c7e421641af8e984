"""QuadularBendingSprings: SOFA's spring layout (two springs across each edge shared by two quads),
its forces against a NumPy transcription and the gradient of the springs' energy, its stiffness
against finite differences of the force, a folded hinge in closed form, the assembled and the
matrix-free solves, and SOFA's example scene.

SOFA's getPotentialEnergy returns 0 for this component, as sofac's does; the energy below is the
springs' own, ks (d - L)^2 / 2, whose gradient the force is when velocities are zero.
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
from sofac.geometry.masses import topology_edges
from sofac.plan.lower.springs import quadular_springs

SHIM = r"""
#include "sofac/shell.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void qb_force(const Index* s, const double* p, Index n, const double* x, const double* v, double* f,
                  double* dfdx) {
    sofac::quadular_bending_add_force(s, p, n, x, v, f, dfdx);
}
API void qb_dforce(const Index* s, Index n, const double* dfdx, const double* dx, double* df, double k) {
    sofac::quadular_bending_add_dforce(s, n, dfdx, dx, df, k);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "quadular", SHIM)
    library.qb_force.argtypes = [I64, D, ctypes.c_int64, D, D, D, D]
    library.qb_dforce.argtypes = [I64, ctypes.c_int64, D, D, D, ctypes.c_double]
    return library


def grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """nx x ny nodes on the unit spacing grid of the plane z = 0, quads counter-clockwise."""
    xs, ys = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    points = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    quads = [
        [j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
        for j in range(ny - 1)
        for i in range(nx - 1)
    ]
    return points, np.array(quads, dtype=np.int64)


def springs_of(points: np.ndarray, quads: np.ndarray) -> np.ndarray:
    edges = topology_edges(len(points), quads=quads)
    return np.array(quadular_springs(quads, edges, len(points)), dtype=np.int64)


def test_two_quads_get_the_two_straight_springs_across_their_edge() -> None:
    """Quads (0 1 4 3) and (1 2 5 4) share edge 1-4, edge 0 of the first (t2, which creates it) and
    edge 2 of the second (t1): SOFA's rule (t1[i1], t2[i2+3]), (t1[i1+3], t2[i2]) joins 5-3 then
    2-0, the lines that cross the edge at its ends; an edge of one quad gets none."""
    points, quads = grid(3, 2)
    assert springs_of(points, quads).tolist() == [[5, 3], [2, 0]]


def test_springs_follow_the_topologys_edge_order() -> None:
    """A 3x3-quad grid: one pair per interior edge (12 edges, 24 springs), each pair crossing its
    edge, in the order of the edges' indices (SOFA's createEdgeSetArray: (q[j+1], q[j+2]) of each
    quad, first seen first)."""
    points, quads = grid(4, 4)
    springs = springs_of(points, quads)
    assert len(springs) == 24
    edges = topology_edges(len(points), quads=quads)
    shared = [e for e in edges.tolist() if sum(set(e) <= set(q) for q in quads.tolist()) == 2]
    for (a, b), (c, d), edge in zip(springs[0::2], springs[1::2], shared, strict=True):
        p, q = points[edge]
        along = (q - p) / np.linalg.norm(q - p)
        for u, v in ((a, b), (c, d)):
            assert np.linalg.norm(points[v] - points[u]) == pytest.approx(2.0)  # straight, across
            assert abs((points[v] - points[u]) @ along) < 1e-12  # perpendicular to the edge
        assert {a, b, c, d}.isdisjoint(edge)


def numpy_force(
    springs: np.ndarray, params: np.ndarray, x: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    f = np.zeros_like(x)
    blocks = np.zeros((len(springs), 3, 3))
    for s, ((a, b), (ks, kd, rest)) in enumerate(zip(springs, params, strict=True)):
        u = x[b] - x[a]
        d = np.linalg.norm(u)
        if d <= 1e-4:
            continue
        n = u / d
        intensity = ks * (d - rest) + kd * n @ (v[b] - v[a])
        f[a] += n * intensity
        f[b] -= n * intensity
        blocks[s] = (ks - intensity / d) * np.outer(n, n) + intensity / d * np.eye(3)
    return f, blocks


class Sheet:
    def __init__(self, lib: ctypes.CDLL, nx: int = 4, ny: int = 3, ks: float = 300.0, kd: float = 2.0):
        self.lib = lib
        self.rest, quads = grid(nx, ny)
        self.springs = springs_of(self.rest, quads)
        lengths = np.linalg.norm(self.rest[self.springs[:, 1]] - self.rest[self.springs[:, 0]], axis=1)
        self.params = np.column_stack([np.full(len(lengths), ks), np.full(len(lengths), kd), lengths])
        self.n = len(self.springs)
        self.dfdx = np.zeros(9 * self.n)

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        f = np.zeros_like(self.rest)
        v = np.zeros_like(self.rest) if v is None else np.ascontiguousarray(v)
        self.lib.qb_force(
            _i(self.springs),
            _d(self.params),
            self.n,
            _d(np.ascontiguousarray(x)),
            _d(v),
            _d(f),
            _d(self.dfdx),
        )
        return f

    def dforce(self, dx: np.ndarray, kfactor: float = 1.0) -> np.ndarray:
        df = np.zeros_like(self.rest)
        self.lib.qb_dforce(
            _i(self.springs), self.n, _d(self.dfdx), _d(np.ascontiguousarray(dx)), _d(df), kfactor
        )
        return df

    def energy(self, x: np.ndarray) -> float:
        d = np.linalg.norm(x[self.springs[:, 1]] - x[self.springs[:, 0]], axis=1)
        return float(np.sum(self.params[:, 0] * (d - self.params[:, 2]) ** 2 / 2))


def test_forces_match_sofas_formulas(lib: ctypes.CDLL) -> None:
    sheet = Sheet(lib)
    rng = np.random.default_rng(11)
    x = sheet.rest + rng.normal(scale=0.1, size=sheet.rest.shape)
    v = rng.normal(size=sheet.rest.shape)
    expected, blocks = numpy_force(sheet.springs, sheet.params, x, v)
    assert sheet.force(x, v) == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert sheet.dfdx.reshape(-1, 3, 3) == pytest.approx(blocks, rel=1e-12, abs=1e-12)


def test_forces_are_minus_the_energy_gradient_at_rest_velocity(lib: ctypes.CDLL) -> None:
    sheet = Sheet(lib)
    x = sheet.rest + np.random.default_rng(12).normal(scale=0.1, size=sheet.rest.shape)
    h = 1e-6
    gradient = np.zeros(x.size)
    for k in range(x.size):
        step = np.zeros(x.size)
        step[k] = h
        up, down = (x.ravel() + step).reshape(x.shape), (x.ravel() - step).reshape(x.shape)
        gradient[k] = (sheet.energy(up) - sheet.energy(down)) / (2 * h)
    assert sheet.force(x).ravel() == pytest.approx(-gradient, rel=1e-6, abs=1e-6)


def test_stiffness_is_the_jacobian_of_the_force(lib: ctypes.CDLL) -> None:
    """With zero velocities SOFA's stored df/dx is the exact Jacobian, at any shape; K dx scales dx
    by kFactor first."""
    sheet = Sheet(lib)
    rng = np.random.default_rng(13)
    x = sheet.rest + rng.normal(scale=0.1, size=sheet.rest.shape)
    dx = rng.normal(size=x.shape)
    h = 1e-6
    fd = (sheet.force(x + h * dx) - sheet.force(x - h * dx)) / (2 * h)
    sheet.force(x)
    df = sheet.dforce(dx)
    assert df == pytest.approx(fd, rel=1e-6, abs=1e-6 * np.abs(fd).max())
    assert sheet.dforce(dx, -0.25) == pytest.approx(-0.25 * df, rel=1e-14, abs=1e-14)


def test_folded_hinge_in_closed_form(lib: ctypes.CDLL) -> None:
    """Two unit squares folded by an angle a about their shared edge: both springs shorten from 2 to
    2 cos(a/2) and pull their ends with ks (2 cos(a/2) - 2) along them; the hinge nodes feel nothing."""
    ks, angle = 300.0, 0.6
    sheet = Sheet(lib, nx=3, ny=2, ks=ks)
    x = sheet.rest.copy()
    half = angle / 2
    for node in (0, 3, 2, 5):  # rotate each outer side about the hinge x = 1, z = 0 (opposite ways)
        side = -1.0 if node in (0, 3) else 1.0
        x[node, 0] = 1 + side * np.cos(half)
        x[node, 2] = np.sin(half)
    f = sheet.force(x)
    length = 2 * np.cos(half)
    assert np.linalg.norm(x[2] - x[0]) == pytest.approx(length)
    pull = ks * (length - 2)
    assert pull < 0  # compressed: the springs push their ends apart
    assert f[0] == pytest.approx(pull * (x[2] - x[0]) / length, rel=1e-12)  # spring (2, 0)
    assert f[3] == pytest.approx(pull * (x[5] - x[3]) / length, rel=1e-12)  # spring (5, 3)
    assert f[2] == pytest.approx(-f[0], rel=1e-12)
    assert not f[[1, 4]].any()


SCENE = """\
<Node name="root" dt="0.01" gravity="0 -9.81 0">
  <DefaultAnimationLoop/>
  <Node name="cloth">
    <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
    <{solver}/>
    <RegularGridTopology name="grid" min="0 0 0" max="1 0 1" nx="6" ny="1" nz="6"/>
    <MechanicalObject name="dofs"/>
    <QuadSetTopologyContainer name="quads" quads="@grid.quads"/>
    <QuadularBendingSprings stiffness="3000" damping="1.0" topology="@quads"/>
    <DiagonalMass massDensity="1.5"/>
    <FixedProjectiveConstraint indices="0 5"/>
  </Node>
</Node>
"""


def test_assembled_and_matrix_free_solves_agree(tmp_path: Path) -> None:
    runs = []
    for name, solver in (
        ("direct", 'EigenSimplicialLDLT template="CompressedRowSparseMatrixMat3x3"'),
        ("cg", 'CGLinearSolver iterations="1000" tolerance="1e-30" threshold="1e-30"'),
    ):
        path = tmp_path / f"{name}.scn"
        path.write_text(SCENE.format(solver=solver))
        sim = sofac.load(path)
        sim.step(100)
        runs.append(sim["cloth/dofs"].position.copy())
    assert np.isfinite(runs[0]).all()
    assert np.abs(runs[0] - runs[1]).max() < 1e-9 * np.abs(runs[0]).max()
    assert runs[0][:, 1].min() < -0.5  # it falls: only two corners are held


def test_sofa_example_scene_runs() -> None:
    """SOFA's examples/Component/SolidMechanics/Spring/QuadularBendingSprings.scn (with its
    TriangularFEMForceField on the mapped triangles, a direct solver): 300 steps, finite, the two
    held corners in place, the cloth hanging below them by less than its size."""
    scene = Path("/work/sofa-tree/examples/Component/SolidMechanics/Spring/QuadularBendingSprings.scn")
    if not scene.is_file():
        pytest.skip("SOFA's examples tree is not extracted at /work/sofa-tree")
    sim = sofac.load(scene)
    dofs = sim["QuadularSprings/Quads"]
    rest = dofs.position.copy()
    sim.step(300)
    x = dofs.position
    assert np.isfinite(x).all()
    assert x[[0, 19]] == pytest.approx(rest[[0, 19]], abs=0)
    assert -1.5 < x[:, 1].min() < -0.2
