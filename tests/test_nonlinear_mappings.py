"""DistanceMapping / SquareDistanceMapping kernels (runtime/sofac/nonlinear.h): the mapped values by
hand, J against finite differences of apply, J^T as J's transpose, and the geometric stiffness
against finite differences of J^T(x) f."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d

SHIM = r"""
#include "sofac/nonlinear.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void apply(const double* px, double* cx, const Index* e, Index n, const double* rest, int kind,
               double* dir, double* inv) {
    sofac::distance_mapping_apply(px, cx, e, n, rest, kind, dir, inv);
}
API void j(const double* pv, double* cv, const Index* e, Index n, const double* dir) {
    sofac::distance_mapping_j(pv, cv, e, n, dir);
}
API void jt(double* pf, const double* cf, const Index* e, Index n, const double* dir) {
    sofac::distance_mapping_jt(pf, cf, e, n, dir);
}
API void djt(double* pdf, const double* pdx, const double* cf, const Index* e, Index n, const double* dir,
             const double* inv, int kind, int gs, double k) {
    sofac::distance_mapping_djt(pdf, pdx, cf, e, n, dir, inv, kind, gs, k);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "nonlinear", SHIM)
    n, integer, real = ctypes.c_int64, ctypes.c_int, ctypes.c_double
    library.apply.argtypes = [D, D, I64, n, D, integer, D, D]
    library.j.argtypes = [D, D, I64, n, D]
    library.jt.argtypes = [D, D, I64, n, D]
    library.djt.argtypes = [D, D, D, I64, n, D, D, integer, integer, real]
    return library


POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, -0.2], [0.3, 2.0, 1.0], [-1.0, 0.4, 0.7]])
EDGES = np.array([[0, 1], [2, 1], [3, 0], [2, 3]], dtype=np.int64)
REST = np.array([0.5, 1.0, 0.0, 2.0])


class Mapping:
    def __init__(self, lib: ctypes.CDLL, kind: int) -> None:
        self.lib, self.kind = lib, kind
        self.dir, self.inv = np.zeros(12), np.zeros(4)

    def apply(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros(4)
        x = np.ascontiguousarray(x, dtype=float)
        self.lib.apply(
            _d(x), _d(out), EDGES.ctypes.data_as(I64), 4, _d(REST), self.kind, _d(self.dir), _d(self.inv)
        )
        return out

    def jacobian(self) -> np.ndarray:
        columns = []
        for k in range(12):
            out = np.zeros(4)
            self.lib.j(_d(np.eye(12)[k].copy()), _d(out), EDGES.ctypes.data_as(I64), 4, _d(self.dir))
            columns.append(out)
        return np.column_stack(columns)

    def jt(self, f: np.ndarray) -> np.ndarray:
        out = np.zeros(12)
        self.lib.jt(_d(out), _d(np.ascontiguousarray(f)), EDGES.ctypes.data_as(I64), 4, _d(self.dir))
        return out

    def djt(self, f: np.ndarray, dx: np.ndarray, gs: int, k: float = 1.0) -> np.ndarray:
        out = np.zeros(12)
        self.lib.djt(
            _d(out), _d(np.ascontiguousarray(dx)), _d(np.ascontiguousarray(f)), EDGES.ctypes.data_as(I64), 4,
            _d(self.dir), _d(self.inv), self.kind, gs, k,
        )  # fmt: skip
        return out


@pytest.mark.parametrize("kind", [0, 1])
def test_values_jacobian_and_geometric_stiffness(lib: ctypes.CDLL, kind: int) -> None:
    mapping = Mapping(lib, kind)
    x = POINTS.ravel().copy()
    values = mapping.apply(x)
    lengths = np.linalg.norm(POINTS[EDGES[:, 1]] - POINTS[EDGES[:, 0]], axis=1)
    expected = lengths - REST if kind == 0 else lengths**2
    assert np.abs(values - expected).max() < 1e-14
    jacobian = mapping.jacobian()
    h = 1e-6
    fd = np.column_stack(
        [
            (Mapping(lib, kind).apply(x + h * e) - Mapping(lib, kind).apply(x - h * e)) / (2 * h)
            for e in np.eye(12)
        ]
    )
    assert np.abs(jacobian - fd).max() < 1e-8
    f = np.array([-3.0, 2.0, -0.5, -1.5])  # some edges pulled (f < 0), some pushed
    assert np.abs(mapping.jt(f) - jacobian.T @ f).max() < 1e-14
    # Exact geometric stiffness: d(J(x)^T f)/dx.
    exact = np.zeros((12, 12))
    for k, e in enumerate(np.eye(12)):
        plus, minus = Mapping(lib, kind), Mapping(lib, kind)
        plus.apply(x + h * e)
        minus.apply(x - h * e)
        exact[:, k] = (plus.jt(f) - minus.jt(f)) / (2 * h)
    mapping.apply(x)
    got = np.column_stack([mapping.djt(f, e.copy(), gs=1) for e in np.eye(12)])
    assert np.abs(got - exact).max() < 1e-7 * np.abs(exact).max()
    assert (
        np.abs(
            np.column_stack([mapping.djt(f, e.copy(), gs=1, k=-0.3) for e in np.eye(12)]) + 0.3 * got
        ).max()
        < 1e-12
    )
    # Stabilized: only the edges in extension (f < 0) keep their term; None: nothing.
    keep = f.copy()
    keep[f >= 0] = 0.0
    stabilized = np.column_stack([mapping.djt(f, e.copy(), gs=2) for e in np.eye(12)])
    only_pulled = np.column_stack([mapping.djt(keep, e.copy(), gs=1) for e in np.eye(12)])
    assert np.abs(stabilized - only_pulled).max() == 0.0
    assert not np.column_stack([mapping.djt(f, e.copy(), gs=0) for e in np.eye(12)]).any()


SCENE = """<Node name="root" dt="0.01" gravity="0 -10 0">
  <DefaultAnimationLoop/>
  <StringMeshCreator name="loader" resolution="4"/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="100" tolerance="1e-20" threshold="1e-20"/>
  <EdgeSetTopologyContainer name="topology" position="@loader.position" edges="@loader.edges"/>
  <MechanicalObject name="dofs" template="Vec3"/>
  <FixedProjectiveConstraint indices="0"/>
  <UniformMass totalMass="4"/>
  <Node name="lengths">
    <MechanicalObject template="Vec1" name="lengths"/>
    <DistanceMapping topology="@../topology" input="@../dofs" output="@lengths" applyRestPosition="true"/>
  </Node>
</Node>
"""


def test_string_mesh_and_mapped_lengths(tmp_path: Path) -> None:
    """StringMeshCreator's 4 points x/3 on the x axis; the mapped state holds one length minus the
    rest length per edge (0 at rest), sized by the mapping; it follows the parent as it falls."""
    scene = tmp_path / "distance.scn"
    scene.write_text(SCENE)
    sim = sofac.load(scene)
    dofs = np.asarray(sim["/dofs"].position)
    assert dofs.tolist() == [[x / 3, 0.0, 0.0] for x in range(4)]
    lengths = sim["/lengths/lengths"]
    assert np.asarray(lengths.position).shape == (3, 1)
    assert np.abs(np.asarray(lengths.position)).max() < 1e-15
    sim.step(3)
    x = np.asarray(sim["/dofs"].position)
    actual = np.linalg.norm(np.diff(x, axis=0), axis=1) - 1.0 / 3.0
    assert np.abs(np.asarray(lengths.position).ravel() - actual).max() < 1e-15
    assert np.abs(actual).max() > 1e-6  # the free points fell: the edges stretched
