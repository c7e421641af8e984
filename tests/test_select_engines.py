"""SubsetTopology, PlaneROI and PairBoxROI evaluated when the scene is checked: their outputs
against transcriptions of SOFA's doUpdate on small inputs (exact element lists and order)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.check import checker
from sofac.geometry import selection

# A strip of 4 x 2 points (x = 0..3, y = 0..1), two triangles per cell: 6 triangles.
STRIP = "0 0 0  1 0 0  2 0 0  3 0 0  0 1 0  1 1 0  2 1 0  3 1 0"
STRIP_TRIANGLES = [[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6]]
STRIP_EDGES = [[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7], [0, 4], [1, 5], [2, 6], [3, 7]]


def _engine(tmp_path: Path, body: str, engine: str) -> tuple[checker.CheckedScene, object]:
    path = tmp_path / "engine.scn"
    path.write_text(f'<Node name="root"><DefaultAnimationLoop/>\n{body}\n</Node>')
    checked, diags = checker.check_file(path)
    assert diags.errors == []
    component = next(c for c in checked.scene.root.components() if c.type_name == engine)
    return checked, component


def _value(checked: checker.CheckedScene, component: object, name: str, width: int = 1) -> list:
    value = checked.value(component, name)  # type: ignore[arg-type]
    return np.asarray(value if value is not None else [], dtype=float).reshape(-1, width).tolist()


def _subset(tmp_path: Path, attributes: str) -> tuple[checker.CheckedScene, object]:
    triangles = " ".join(str(i) for t in STRIP_TRIANGLES for i in t)
    edges = " ".join(str(i) for e in STRIP_EDGES for i in e)
    body = (
        f'<MechanicalObject name="dofs" position="{STRIP}"/>\n'
        f'<MeshTopology name="mesh" triangles="{triangles}" edges="{edges}"/>\n'
        f'<SubsetTopology name="subset" {attributes}/>'
    )
    return _engine(tmp_path, body, "SubsetTopology")


def test_subset_topology_box(tmp_path: Path) -> None:
    """Box x in [-0.5, 1.5]: points 0 1 4 5 inside; an element is inside when all its corners are
    in one box; edges and triangles read from the node's topology, in its order."""
    checked, subset = _subset(tmp_path, 'box="1.5 1.5 1  -0.5 -0.5 -1"')  # bounds in any order
    assert _value(checked, subset, "indices") == [[0], [1], [4], [5]]
    assert _value(checked, subset, "triangleIndices") == [[0], [1]]
    assert _value(checked, subset, "trianglesInROI", 3) == STRIP_TRIANGLES[:2]
    assert _value(checked, subset, "trianglesOutROI", 3) == STRIP_TRIANGLES[2:]
    assert _value(checked, subset, "edgeIndices") == [[0], [3], [6], [7]]
    assert _value(checked, subset, "edgesOutROI", 2) == [STRIP_EDGES[k] for k in (1, 2, 4, 5, 8, 9)]
    points = np.array(STRIP.split(), dtype=float).reshape(-1, 3)
    assert _value(checked, subset, "pointsInROI", 3) == points[[0, 1, 4, 5]].tolist()
    assert _value(checked, subset, "pointsOutROI", 3) == points[[2, 3, 6, 7]].tolist()


def test_subset_topology_spheres(tmp_path: Path) -> None:
    """Spheres when centers is set: |p - c| <= r, the radius included (point 2 at distance 1)."""
    checked, subset = _subset(tmp_path, 'centers="3 0 0" radii="1"')
    assert _value(checked, subset, "indices") == [[2], [3], [7]]
    assert _value(checked, subset, "triangleIndices") == [[4]]


def test_subset_topology_local_indices(tmp_path: Path) -> None:
    """localIndices: border points (inside box 0, corner of a triangle with a corner outside) first,
    increasing: 1 5 (triangles 2, 3 cross the box); then the other inside points 0 4 numbered from 2,
    the outside points 2 3 6 7 numbered from 2 too; every element written with those numbers."""
    checked, subset = _subset(tmp_path, 'box="-0.5 -0.5 -1  1.5 1.5 1" localIndices="1"')
    local = {1: 0, 5: 1, 0: 2, 4: 3, 2: 2, 3: 3, 6: 4, 7: 5}
    assert _value(checked, subset, "nbrborder") == [[2]]
    assert _value(checked, subset, "indices") == [[1], [5], [0], [4]]
    assert _value(checked, subset, "trianglesInROI", 3) == [
        [local[i] for i in t] for t in STRIP_TRIANGLES[:2]
    ]
    assert _value(checked, subset, "trianglesOutROI", 3) == [
        [local[i] for i in t] for t in STRIP_TRIANGLES[2:]
    ]
    points = np.array(STRIP.split(), dtype=float).reshape(-1, 3)
    assert _value(checked, subset, "pointsInROI", 3) == points[[1, 5, 0, 4]].tolist()
    assert _value(checked, subset, "pointsOutROI", 3) == points[[1, 5, 2, 3, 6, 7]].tolist()


def test_subset_topology_reads_the_edges_a_triangle_container_computes(tmp_path: Path) -> None:
    """A TriangleSetTopologyContainer given triangles only computes its edges when it initialises
    (createEdgesInTriangleArray: (t[j+1], t[j+2]) first met): those are the engine's."""
    triangles = " ".join(str(i) for t in STRIP_TRIANGLES for i in t)
    body = (
        f'<MechanicalObject name="dofs" position="{STRIP}"/>\n'
        f'<TriangleSetTopologyContainer name="mesh" triangles="{triangles}"/>\n'
        '<SubsetTopology name="subset" box="-0.5 -0.5 -1  1.5 1.5 1"/>'
    )
    checked, subset = _engine(tmp_path, body, "SubsetTopology")
    # edges of 0 1 5, then 0 5 4: (1 5) (5 0) (0 1) (5 4) (4 0); the rest have a corner outside
    assert _value(checked, subset, "edgesInROI", 2) == [[1, 5], [5, 0], [0, 1], [5, 4], [4, 0]]


def test_subset_topology_refuses_edges_a_volume_container_would_compute(tmp_path: Path) -> None:
    path = tmp_path / "engine.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        f'<MechanicalObject name="dofs" position="{STRIP}"/>\n'
        '<TetrahedronSetTopologyContainer name="mesh" tetrahedra="0 1 4 5"/>\n'
        '<SubsetTopology name="subset"/>\n</Node>'
    )
    _, diags = checker.check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E222", 4)]


def _plane_roi(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, depth: float, p: np.ndarray) -> bool:
    """PlaneROI::computePlane and isPointInPlane, written out."""

    def unit(v: np.ndarray) -> np.ndarray:
        n = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        return v / n if n > np.finfo(float).eps else v

    vdepth = unit(np.cross(p1 - p0, p2 - p0))
    p3, p4, p6 = p0 + (p2 - p1), p0 + vdepth * (depth / 2), p2 + vdepth * (depth / 2)
    plane0, plane1 = unit(np.cross(p1 - p0, p4 - p0)), unit(np.cross(p2 - p3, p6 - p3))
    plane2, plane3 = unit(np.cross(p3 - p0, p4 - p0)), unit(np.cross(p2 - p1, p6 - p2))
    width, length = abs((p2 - p0) @ plane0), abs((p2 - p0) @ plane2)
    pv0, pv1 = p - p0, p - p2
    return bool(
        abs(pv0 @ plane0) <= width
        and abs(pv1 @ plane1) <= width
        and abs(pv0 @ plane2) <= length
        and abs(pv1 @ plane3) <= length
        and abs(pv0 @ vdepth) <= abs(depth / 2)
    )


def test_plane_roi_slab(tmp_path: Path) -> None:
    """The rectangle (0 0 0) (2 0 0) (2 1 0), 0.2 deep: points of the strip's first two cells, and
    the elements all of whose corners are inside; a point 0.11 off the plane is out."""
    points = STRIP + "  1 0.5 0.09  1 0.5 0.11"
    triangles = " ".join(str(i) for t in STRIP_TRIANGLES for i in t)
    body = (
        f'<MechanicalObject name="dofs" position="{points}"/>\n'
        f'<MeshTopology name="mesh" triangles="{triangles}" edges="0 1  1 2  2 3  8 9"/>\n'
        '<PlaneROI name="roi" plane="0 0 0  2 0 0  2 1 0  0.2"/>'
    )
    checked, roi = _engine(tmp_path, body, "PlaneROI")
    xyz = np.array(points.split(), dtype=float).reshape(-1, 3)
    corners = [np.array(v, dtype=float) for v in ((0, 0, 0), (2, 0, 0), (2, 1, 0))]
    expected = [i for i in range(len(xyz)) if _plane_roi(*corners, 0.2, xyz[i])]
    assert expected == [0, 1, 2, 4, 5, 6, 8]
    assert _value(checked, roi, "indices") == [[i] for i in expected]
    assert _value(checked, roi, "triangleIndices") == [[0], [1], [2], [3]]
    assert _value(checked, roi, "edgeIndices") == [[0], [1]]
    assert _value(checked, roi, "pointsInROI", 3) == xyz[expected].tolist()


def test_plane_roi_default_plane_takes_every_point(tmp_path: Path) -> None:
    """SOFA's default plane is all zeros: every test compares 0 <= 0, every point is in."""
    body = f'<MechanicalObject name="dofs" position="{STRIP}"/>\n<PlaneROI name="roi"/>'
    checked, roi = _engine(tmp_path, body, "PlaneROI")
    assert _value(checked, roi, "indices") == [[i] for i in range(8)]


@pytest.mark.parametrize(
    ("inclusive", "included", "expected"),
    [
        ("-0.5 -0.5 -1  3.5 1.5 1", "0.5 -0.5 -1  2.5 1.5 1", [0, 3, 4, 7]),
        ("3.5 1.5 1  -0.5 -0.5 -1", "2.5 1.5 1  0.5 -0.5 -1", [0, 3, 4, 7]),  # bounds swapped back
        ("-0.5 -0.5 -1  3.5 1.5 1", "0 0 0  0 0 0.0000005", []),  # a zero box (Vec6 ==): nothing
    ],
)
def test_pair_box_roi(tmp_path: Path, inclusive: str, included: str, expected: list[int]) -> None:
    body = (
        f'<MechanicalObject name="dofs" position="{STRIP}"/>\n'
        f'<PairBoxROI name="pair" inclusiveBox="{inclusive}" includedBox="{included}"/>'
    )
    checked, pair = _engine(tmp_path, body, "PairBoxROI")
    assert _value(checked, pair, "indices") == [[i] for i in expected]


def test_pair_box_on_rigid_frames_reads_their_centres() -> None:
    frames = np.array([[0.0, 0, 0, 0, 0, 0, 1], [2, 0, 0, 0, 0, 0, 1]])
    inclusive, included = np.array([-1.0, -1, -1, 3, 1, 1]), np.array([-0.5, -0.5, -0.5, 0.5, 0.5, 0.5])
    assert selection.pair_box(frames, inclusive, included).tolist() == [1]
