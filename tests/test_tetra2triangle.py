"""Tetra2TriangleTopologicalMapping: the triangles SOFA's init writes to the output container (the
input container's triangle array, as TetrahedronSetTopologyContainer::createTriangleSetArray builds
it, filtered to the triangles of one tetrahedron), and a MechanicalObject given only rest positions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.geometry.fem_topology import tetrahedron_container_triangles
from sofac.pipeline import check_file

MESH = """\
<Node name="root"><DefaultAnimationLoop/>
  <TetrahedronSetTopologyContainer name="volume" position="{points}" tetrahedra="{tetrahedra}"/>
  <MechanicalObject name="dofs"/>
  <Node name="surface">
    <TriangleSetTopologyContainer name="skin"/>
    <Tetra2TriangleTopologicalMapping input="@../volume" output="@skin" {flags}/>
    <MechanicalObject name="skin_dofs" rest_position="@../dofs.rest_position"/>
    <IdentityMapping/>
  </Node>
</Node>
"""
UNIT = "0 0 0  1 0 0  0 1 0  0 0 1  1 1 1"


def _check(tmp_path: Path, text: str) -> tuple[object, np.ndarray]:
    path = tmp_path / "skin.scn"
    path.write_text(text)
    checked, diags = check_file(path)
    assert diags.errors == []
    components = checked.scene.root.components()
    skin = next(c for c in components if c.type_name == "TriangleSetTopologyContainer")
    value = checked.value(skin, "triangles")
    return checked, np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1, 3)


def test_one_tetrahedron_gives_its_four_faces_in_sofas_order(tmp_path: Path) -> None:
    """Faces (1 2 3), (0 3 2), (1 3 0), (0 2 1) of trianglesOrientationInTetrahedronArray, each
    turned to start at its smallest index: (1 3 0) becomes (0 1 3). Outward, the tetrahedron being
    positively oriented."""
    _, triangles = _check(tmp_path, MESH.format(points=UNIT, tetrahedra="0 1 2 3", flags=""))
    assert triangles.tolist() == [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]
    points = np.array(UNIT.split(), dtype=float).reshape(-1, 3)
    centre = points[:4].mean(axis=0)
    for a, b, c in triangles:
        normal = np.cross(points[b] - points[a], points[c] - points[a])
        assert normal @ (points[a] - centre) > 0


def test_flip_normals_exchanges_the_last_two_corners(tmp_path: Path) -> None:
    _, triangles = _check(tmp_path, MESH.format(points=UNIT, tetrahedra="0 1 2 3", flags='flipNormals="1"'))
    assert triangles.tolist() == [[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]]


def test_a_shared_face_is_left_out(tmp_path: Path) -> None:
    """Two tetrahedra on face (1 2 3): 8 faces, 7 distinct triangles in the container (the second
    tetrahedron's (1 3 2) is the first one's (1 2 3) turned), 6 on the surface: the second one's
    faces (4 2 3), (1 2 4), (4 3 1) start at their smallest index."""
    tetrahedra = np.array([[0, 1, 2, 3], [4, 1, 3, 2]])
    assert len(tetrahedron_container_triangles(tetrahedra)) == 7
    _, triangles = _check(tmp_path, MESH.format(points=UNIT, tetrahedra="0 1 2 3  4 1 3 2", flags=""))
    assert triangles.tolist() == [[0, 3, 2], [0, 1, 3], [0, 2, 1], [2, 3, 4], [1, 2, 4], [1, 4, 3]]


def test_no_initial_triangles(tmp_path: Path) -> None:
    _, triangles = _check(
        tmp_path, MESH.format(points=UNIT, tetrahedra="0 1 2 3", flags='noInitialTriangles="1"')
    )
    assert triangles.size == 0


GRID = """\
<Node name="root"><DefaultAnimationLoop/>
  <RegularGridTopology name="grid" n="{n}" min="0 0 0" max="{size}"/>
  <TetrahedronSetTopologyContainer name="volume" position="@grid.position"/>
  <Hexa2TetraTopologicalMapping input="@grid" output="@volume" swapping="true"/>
  <MechanicalObject name="dofs"/>
  <Node name="surface">
    <TriangleSetTopologyContainer name="skin"/>
    <Tetra2TriangleTopologicalMapping input="@../volume" output="@skin"/>
    <MechanicalObject name="skin_dofs" rest_position="@../dofs.rest_position"/>
    <IdentityMapping/>
  </Node>
</Node>
"""


@pytest.mark.parametrize(("n", "size"), [("2 2 2", "1 1 1"), ("5 3 2", "4 2 1"), ("25 5 5", "0.5 0.1 0.1")])
def test_the_surface_of_a_split_grid(tmp_path: Path, n: str, size: str) -> None:
    """Hexa2Tetra on an a x b x c grid of cells: 2 (2ab + 2bc + 2ca) boundary triangles, each in a
    face plane of the box, turned as its tetrahedron is (outward for a positive one). The
    last grid is fallingBeamLagrangianCollision.scn's."""
    checked, triangles = _check(tmp_path, GRID.format(n=n, size=size))
    a, b, c = (int(k) - 1 for k in n.split())
    assert len(triangles) == 2 * (2 * a * b + 2 * b * c + 2 * c * a)
    components = checked.scene.root.components()
    volume = next(c for c in components if c.type_name == "TetrahedronSetTopologyContainer")
    tetrahedra = np.asarray(checked.value(volume, "tetrahedra"), dtype=np.int64).reshape(-1, 4)
    points = np.asarray(checked.value(volume, "position"), dtype=float).reshape(-1, 3)
    top = np.array(size.split(), dtype=float)
    owner = {
        tuple(sorted(t[list(f)])): t for t in tetrahedra for f in ((1, 2, 3), (0, 3, 2), (1, 3, 0), (0, 2, 1))
    }
    for triangle in triangles:
        corners = points[triangle]
        on = [axis for axis in range(3) if np.ptp(corners[:, axis]) == 0]
        assert len(on) == 1  # in one face plane of the box
        axis = on[0]
        outward = np.zeros(3)
        outward[axis] = 1.0 if np.isclose(corners[0, axis], top[axis]) else -1.0
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        t = points[owner[tuple(sorted(triangle))]]
        volume_sign = np.sign(np.linalg.det(np.stack([t[1] - t[0], t[2] - t[0], t[3] - t[0]])))
        assert np.sign(normal @ outward) == volume_sign


def test_a_state_given_only_rest_positions_starts_from_them(tmp_path: Path) -> None:
    """MechanicalObject::init: rest_position longer than position ("X0 set but not X") is copied
    into position, so the mapped state has the volume's points (its topology has none)."""
    checked, _ = _check(tmp_path, GRID.format(n="3 2 2", size="2 1 1"))
    states = {c.name: c for c in checked.scene.root.components() if c.type_name == "MechanicalObject"}
    volume = checked.positions(states["dofs"])
    skin = checked.positions(states["skin_dofs"])
    assert skin is not None and volume is not None
    assert np.array_equal(skin, volume) and skin.shape == (12, 3)
