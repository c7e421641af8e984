"""GridMeshCreator: the points, quads or triangles and edges SOFA's doLoad makes (evaluated when the
scene is checked), against a transcription of its loops on a 3 x 3 grid."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.check import checker


def _outputs(tmp_path: Path, attributes: str) -> dict[str, np.ndarray]:
    path = tmp_path / "grid.scn"
    path.write_text(f'<Node name="root"><GridMeshCreator name="grid" {attributes}/></Node>')
    checked, diags = checker.check_file(path)
    assert diags.errors == []
    grid = next(iter(checked.scene.root.components()))
    return {
        kind: np.asarray(checked.value(grid, kind)) for kind in ("position", "edges", "triangles", "quads")
    }


def _expected(pattern: int) -> tuple[list[list[int]], list[list[int]], list[list[int]]]:
    """doLoad on resolution 3 3 (vert(x, y) = x + 3 y), cells y outer, x inner; the edges of each
    element (a b) (b c) ... inserted unless their reverse is there, then listed sorted."""
    triangles, quads = [], []
    for y in range(2):
        for x in range(2):
            a, b, c, d = x + 3 * y, x + 1 + 3 * y, x + 1 + 3 * (y + 1), x + 3 * (y + 1)
            if pattern == 0:
                quads.append([a, b, c, d])
            elif pattern == 2 or (pattern == 1 and (x + y) % 2 == 0):
                triangles += [[a, b, c], [a, c, d]]
            else:
                triangles += [[a, b, d], [b, c, d]]
    edges: set[tuple[int, int]] = set()
    for element in triangles + quads:
        for k in range(len(element)):
            a, b = element[k], element[(k + 1) % len(element)]
            if (b, a) not in edges:
                edges.add((a, b))
    return triangles, quads, [list(e) for e in sorted(edges)]


@pytest.mark.parametrize("pattern", [0, 1, 2, 3])
def test_elements_and_edges_as_sofa_makes_them(tmp_path: Path, pattern: int) -> None:
    out = _outputs(tmp_path, f'resolution="3 3" trianglePattern="{pattern}"')
    triangles, quads, edges = _expected(pattern)
    assert out["triangles"].reshape(-1, 3).tolist() == triangles
    assert out["quads"].reshape(-1, 4).tolist() == quads
    assert out["edges"].reshape(-1, 2).tolist() == edges
    assert len(edges) == 12 if pattern == 0 else len(edges) == 16


def test_points_on_the_unit_square_x_fastest(tmp_path: Path) -> None:
    points = _outputs(tmp_path, 'resolution="4 3"')["position"].reshape(-1, 3)
    expected = [[(x * 1.0) / 3, (y * 1.0) / 2, 0.0] for y in range(3) for x in range(4)]
    assert points.tolist() == expected


def test_the_loader_transform_applies(tmp_path: Path) -> None:
    """MeshLoader's scale3d, rotation (degrees) and translation: scale, then rotate, then translate."""
    points = _outputs(tmp_path, 'resolution="2 2" scale3d="2 3 1" rotation="0 0 90" translation="1 0 0"')
    points = points["position"].reshape(-1, 3)
    assert np.allclose(points, [[1, 0, 0], [1, 2, 0], [-2, 0, 0], [-2, 2, 0]], atol=1e-15)


def test_a_resolution_below_two_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "grid.scn"
    path.write_text('<Node name="root">\n<GridMeshCreator name="grid" resolution="1 3"/></Node>')
    _, diags = checker.check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E207", 2)]
