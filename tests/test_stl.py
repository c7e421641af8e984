"""MeshSTLLoader: ASCII and binary STL read as SOFA's loader reads them (meshio stops at SOFA's
ASCII files' ``end`` lines, so sofac has its own reader)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from sofac.diagnostics import Diagnostics
from sofac.front.meshes import MeshError, clear_cache, count_points, read_mesh
from sofac.pipeline import check_file

# A tetrahedron's surface: corners (0,0,0), (1,0,0), (0,1,0), (0,0,1).
CORNERS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]

ASCII = (
    "solid tetra\n"
    + "".join(
        "  facet normal 0 0 0\n    outer loop\n"
        + "".join(f"      vertex {' '.join(repr(float(c)) for c in CORNERS[i])}\n" for i in face)
        + "    endloop\n  endfacet\n"
        for face in FACES
    )
    + "endsolid tetra\n"
)


def _binary(faces: list[tuple[int, ...]], header: bytes = b"binary tetra") -> bytes:
    body = b"".join(
        struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *CORNERS[i]) for i in face) + b"\0\0"
        for face in faces
    )
    return header.ljust(80, b" ") + struct.pack("<I", len(faces)) + body


@pytest.fixture(autouse=True)
def _fresh_cache() -> None:
    clear_cache()


def test_ascii_stl_vertices_merged_in_order_of_first_appearance(tmp_path: Path) -> None:
    path = tmp_path / "tetra.stl"
    path.write_text(ASCII)
    mesh = read_mesh(path)
    # first appearances: 0, 2, 1 (face 0), then 3
    assert mesh.positions.tolist() == CORNERS[[0, 2, 1, 3]].tolist()
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 1], [2, 1, 3]]
    assert count_points(path) == 4


def test_binary_stl_drops_degenerate_triangles(tmp_path: Path) -> None:
    path = tmp_path / "tetra_binary.stl"
    path.write_bytes(_binary([*FACES, (1, 1, 2)]))
    mesh = read_mesh(path)
    assert mesh.positions.tolist() == CORNERS[[0, 2, 1, 3]].tolist()
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 1], [2, 1, 3]]
    assert mesh.notes == ("1 degenerate triangles dropped (as SOFA does)",)


def test_binary_stl_of_the_wrong_size_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "cut.stl"
    path.write_bytes(_binary(FACES)[:-10])
    with pytest.raises(MeshError, match="announces 4 triangles"):
        read_mesh(path)


def test_a_scene_reads_an_stl_loader(tmp_path: Path) -> None:
    (tmp_path / "tetra.stl").write_bytes(_binary(FACES))
    scene = tmp_path / "stl.scn"
    scene.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        '  <MeshSTLLoader name="loader" filename="tetra.stl"/>\n'
        '  <MeshTopology src="@loader"/>\n'
        '  <MechanicalObject name="dofs" src="@loader"/>\n'
        "</Node>\n"
    )
    checked, diags = check_file(scene)
    assert isinstance(diags, Diagnostics) and diags.errors == []
    dofs = next(c for c in checked.scene.root.components() if c.type_name == "MechanicalObject")
    assert np.asarray(checked.value(dofs, "position"), dtype=float).reshape(-1, 3).tolist() == (
        CORNERS[[0, 2, 1, 3]].tolist()
    )
