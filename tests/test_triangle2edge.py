"""Triangle2EdgeTopologicalMapping and the loaders' createSubelements: the edges SOFA's init writes
to the output container (the input container's edges that bound one triangle only, in its edge
order), the edges a MeshGmshLoader appends, and a scene of SOFA's tree that runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.check import checker
from sofac.check.evaluate import update_elements
from sofac.pipeline import check_file

TREE = Path("/work/sofa-tree")

SCENE = """\
<Node name="root"><DefaultAnimationLoop/>
  <MechanicalObject name="dofs" position="{points}"/>
  <TriangleSetTopologyContainer name="triangles" triangles="{triangles}" {edges}/>
  <Node name="border">
    <EdgeSetTopologyContainer name="edges"/>
    <EdgeSetTopologyModifier/>
    <Triangle2EdgeTopologicalMapping input="@../triangles" output="@edges"/>
  </Node>
</Node>
"""
# Two triangles sharing edge 1-2 of a unit square: 0 1 2 and 2 1 3.
SQUARE = "0 0 0  1 0 0  0 1 0  1 1 0"


def _edges(tmp_path: Path, text: str) -> np.ndarray:
    path = tmp_path / "border.scn"
    path.write_text(text)
    checked, diags = check_file(path)
    assert diags.errors == []
    container = next(c for c in checked.scene.root.components() if c.type_name == "EdgeSetTopologyContainer")
    value = checked.value(container, "edges")
    return np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1, 2)


def test_computed_edges_keep_the_triangles_orientation(tmp_path: Path) -> None:
    """createEdgeSetArray: for each triangle t and j = 0, 1, 2 the edge (t[j+1], t[j+2]) first met:
    (1 2) (2 0) (0 1), then (1 3) and (3 2) of the second triangle ((2 1) is (1 2)); the shared
    edge (1 2) bounds two triangles and is left out."""
    edges = _edges(tmp_path, SCENE.format(points=SQUARE, triangles="0 1 2  2 1 3", edges=""))
    assert edges.tolist() == [[2, 0], [0, 1], [1, 3], [3, 2]]


def test_given_edges_are_kept_in_their_order(tmp_path: Path) -> None:
    """Given edges: a triangle's edge is the first given edge joining its two points, whatever its
    direction; an edge of no triangle (3 0) has none around it and is left out too."""
    given = 'edges="3 0  1 0  2 1  3 1  0 2  2 3"'
    edges = _edges(tmp_path, SCENE.format(points=SQUARE, triangles="0 1 2  2 1 3", edges=given))
    assert edges.tolist() == [[1, 0], [3, 1], [0, 2], [2, 3]]


def test_a_repeated_edge_counts_once(tmp_path: Path) -> None:
    """Edge (0 1) given twice: the triangle is counted on the first, the second has no triangle."""
    given = 'edges="0 1  1 2  2 0  1 0"'
    edges = _edges(tmp_path, SCENE.format(points=SQUARE[:17], triangles="0 1 2", edges=given))
    assert edges.tolist() == [[0, 1], [1, 2], [2, 0]]


def test_given_edges_missing_a_triangle_edge_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "border.scn"
    path.write_text(SCENE.format(points=SQUARE, triangles="0 1 2  2 1 3", edges='edges="0 1  1 2"'))
    _, diags = checker.check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E207", 7)]
    assert "no edge [2, 0] of triangle 0" in diags.errors[0].message


def test_the_output_container_is_cleared_by_the_mapping(tmp_path: Path) -> None:
    """SOFA's init clears the output container first: edges it was given do not last."""
    text = SCENE.format(points=SQUARE, triangles="0 1 2  2 1 3", edges="").replace(
        '<EdgeSetTopologyContainer name="edges"/>', '<EdgeSetTopologyContainer name="edges" edges="0 3"/>'
    )
    assert _edges(tmp_path, text).tolist() == [[2, 0], [0, 1], [1, 3], [3, 2]]


def test_create_subelements_appends_the_missing_faces_and_edges() -> None:
    """MeshLoader::updateElements: the tetrahedron's triangles (0 2 1) (0 1 3) (0 3 2) (1 2 3) not
    already given ((1 3 2) is (1 2 3)), then the edges (t[j+1], t[j+2]) of all triangles not
    already given ((1 0) is (0 1))."""
    cells = {
        "edges": np.array([[1, 0]]),
        "triangles": np.array([[1, 3, 2]]),
        "quads": np.zeros((0, 4), dtype=np.int64),
        "tetrahedra": np.array([[0, 1, 2, 3]]),
        "hexahedra": np.zeros((0, 8), dtype=np.int64),
    }
    out = update_elements(cells, True)
    assert out["triangles"].tolist() == [[1, 3, 2], [0, 2, 1], [0, 1, 3], [0, 3, 2]]
    assert out["edges"].tolist() == [[1, 0], [3, 2], [2, 1], [1, 3], [0, 2], [3, 0]]
    assert update_elements(cells, False) is cells


def test_gmsh_loader_creates_subelements_unless_told_not_to(tmp_path: Path) -> None:
    """MeshGmshLoader turns createSubelements on when the scene does not set it: one line element
    of the file first, then the edges of its triangles."""
    (tmp_path / "two.msh").write_text(
        "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 1 1 0\n$ENDNOD\n"
        "$ELM\n3\n1 1 0 0 2 2 4\n2 2 0 0 3 1 2 3\n3 2 0 0 3 3 2 4\n$ENDELM\n"
    )
    for flag, expected in (
        ("", [[1, 3], [1, 2], [2, 0], [0, 1], [3, 2]]),
        ('createSubelements="0"', [[1, 3]]),
    ):
        path = tmp_path / "load.scn"
        path.write_text(f'<Node name="root"><MeshGmshLoader name="l" filename="two.msh" {flag}/></Node>')
        checked, diags = check_file(path)
        assert diags.errors == []
        loader = next(iter(checked.scene.root.components()))
        assert np.asarray(checked.value(loader, "edges")).reshape(-1, 2).tolist() == expected


@pytest.mark.skipif(not TREE.is_dir(), reason="SOFA's examples tree is not extracted")
def test_the_tree_scene_gives_the_square_border(tmp_path: Path) -> None:
    """SOFA's Triangle2EdgeTopologicalMapping.scn: square3.msh's 96 line elements come first in the
    loader's edges (createSubelements adds the triangles' after them) and are exactly its border."""
    path = TREE / "examples/Component/Topology/Mapping/Triangle2EdgeTopologicalMapping.scn"
    checked, diags = check_file(path)
    assert diags.errors == []
    container = next(c for c in checked.scene.root.components() if c.type_name == "EdgeSetTopologyContainer")
    edges = np.asarray(checked.value(container, "edges")).reshape(-1, 2)
    assert len(edges) == 96 and edges[0].tolist() == [0, 4] and edges[-1].tolist() == [95, 0]
    triangles = next(
        c for c in checked.scene.root.components() if c.type_name == "TriangleSetTopologyContainer"
    )
    cells = np.asarray(checked.value(triangles, "triangles")).reshape(-1, 3)
    counts: dict[tuple[int, int], int] = {}
    for t in cells.tolist():
        for j in range(3):
            key = tuple(sorted((t[(j + 1) % 3], t[(j + 2) % 3])))
            counts[key] = counts.get(key, 0) + 1
    assert sorted(tuple(sorted(e)) for e in edges.tolist()) == sorted(k for k, c in counts.items() if c == 1)
