"""Quad2TriangleTopologicalMapping: the triangles SOFA's init writes to the output container."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.pipeline import check_file

GRID = """\
<Node name="root"><DefaultAnimationLoop/>
  <RegularGridTopology name="grid" n="4 3 1" min="0 0 0" max="3 2 0"/>
  <MechanicalObject name="dofs"/>
  <Node name="surface">
    <TriangleSetTopologyContainer name="triangles"/>
    <Quad2TriangleTopologicalMapping name="split" input="@../grid" output="@triangles" {swapping}/>
  </Node>
</Node>
"""


def _triangles(tmp_path: Path, text: str) -> np.ndarray:
    path = tmp_path / "split.scn"
    path.write_text(text)
    checked, diags = check_file(path)
    assert diags.errors == []
    components = checked.scene.root.components()
    container = next(c for c in components if c.type_name == "TriangleSetTopologyContainer")
    return np.asarray(checked.value(container, "triangles"), dtype=np.int64).reshape(-1, 3)


def _expected(swapping: bool) -> list[list[int]]:
    """SOFA's init on the grid's 3 x 2 quads (q = p0 p1 p2 p3, scale = nx - 1 = 3)."""
    triangles = []
    for i in range(6):
        x, y = i % 3, i // 3
        p0, p1, p2, p3 = x + 4 * y, x + 1 + 4 * y, x + 1 + 4 * (y + 1), x + 4 * (y + 1)
        if swapping and ((i % 3) ^ (i // 3)) & 1:
            triangles += [[p0, p1, p3], [p2, p3, p1]]
        else:
            triangles += [[p1, p2, p0], [p3, p0, p2]]
    return triangles


@pytest.mark.parametrize("swapping", [True, False])
def test_grid_quads_split_as_sofa_does(tmp_path: Path, swapping: bool) -> None:
    given = "" if swapping else 'swapping="0"'  # SOFA's default is swapping="1"
    triangles = _triangles(tmp_path, GRID.format(swapping=given))
    assert triangles.tolist() == _expected(swapping)


def test_quads_of_a_mesh_use_scale_two(tmp_path: Path) -> None:
    """Not a grid: SOFA takes nx = 2, so quads 1 and 2 (i mod 2 xor i div 2 odd) are turned."""
    quads = "0 1 2 3  1 4 5 2  4 6 7 5  6 8 9 7"
    text = (
        '<Node name="root"><DefaultAnimationLoop/>\n'
        f'  <QuadSetTopologyContainer name="quads" position="{" ".join(["0 0 0"] * 10)}" quads="{quads}"/>\n'
        '  <MechanicalObject name="dofs"/>\n'
        '  <Node name="surface"><TriangleSetTopologyContainer name="triangles"/>\n'
        '    <Quad2TriangleTopologicalMapping input="@../quads" output="@triangles"/></Node>\n'
        "</Node>\n"
    )
    triangles = _triangles(tmp_path, text)
    cells = np.array(quads.split(), dtype=np.int64).reshape(-1, 4)
    expected = []
    for i, (p0, p1, p2, p3) in enumerate(cells.tolist()):
        turned = ((i % 2) ^ (i // 2)) & 1
        expected += [[p0, p1, p3], [p2, p3, p1]] if turned else [[p1, p2, p0], [p3, p0, p2]]
    assert triangles.tolist() == expected
