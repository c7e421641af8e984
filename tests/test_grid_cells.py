"""The cells of a 3-D RegularGridTopology, numbered as SOFA's GridTopology::GridUpdate makes them
(points x + nx (y + ny z))."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sofac.check.checker import check_file

SCENE = """\
<Node name="root"><DefaultAnimationLoop/>
  <RegularGridTopology name="grid" n="2 2 2" min="0 0 0" max="1 1 1" {flags}/>
  <MechanicalObject name="dofs"/>
</Node>
"""


def _cells(tmp_path: Path, flags: str = "") -> dict[str, list[list[int]]]:
    path = tmp_path / "grid.scn"
    path.write_text(SCENE.format(flags=flags))
    checked, diags = check_file(path)
    assert diags.errors == []
    grid = next(c for c in checked.scene.root.components() if c.type_name == "RegularGridTopology")
    out = {}
    for kind, corners in (("hexahedra", 8), ("quads", 4), ("triangles", 3), ("edges", 2)):
        value = checked.value(grid, kind)
        out[kind] = [] if value is None else np.asarray(value, dtype=np.int64).reshape(-1, corners).tolist()
    return out


def test_a_cube_has_sofas_quads_triangles_and_edges(tmp_path: Path) -> None:
    cells = _cells(tmp_path)
    assert cells["hexahedra"] == [[0, 1, 3, 2, 4, 5, 7, 6]]
    # XY planes (z = 0, 1), then XZ (y = 0, 1), then YZ (x = 0, 1)
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    assert cells["quads"] == quads
    assert cells["triangles"] == [t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])]
    # createEdgeSetArray on those triangles: (t1 t2) (t2 t0) (t0 t1), each pair once, first met
    assert cells["edges"][:5] == [[1, 3], [3, 0], [0, 1], [3, 2], [2, 0]]
    assert len(cells["edges"]) == 12 + 6  # the cube's edges and one diagonal per face


def test_without_triangles_the_edges_are_the_grid_lines(tmp_path: Path) -> None:
    cells = _cells(tmp_path, 'computeTriangleList="0" computeQuadList="0"')
    assert cells["quads"] == [] and cells["triangles"] == []
    x_lines = [[0, 1], [2, 3], [4, 5], [6, 7]]
    y_lines = [[0, 2], [1, 3], [4, 6], [5, 7]]
    z_lines = [[0, 4], [1, 5], [2, 6], [3, 7]]
    assert cells["edges"] == x_lines + y_lines + z_lines
