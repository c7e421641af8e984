"""Tests for sofac.front.meshes: mesh/data file readers and SOFA's point transformation."""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import re
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from sofac.front import meshes
from sofac.front.meshes import MeshError, apply_transform, count_points, read_mesh, read_rigid, read_spheres


def _shared() -> Path | None:
    candidates = [Path(__file__).resolve().parents[2] / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    for candidate in candidates:
        if (candidate / "corpus" / "sofa").is_dir():
            return candidate
    return None


SHARED = _shared()
CORPUS = SHARED / "corpus" / "sofa" if SHARED else None
MESH_SUFFIXES = (".obj", ".msh", ".vtu", ".vtk", ".sph")


def _corpus_files(suffixes: tuple[str, ...]) -> list[Path]:
    if CORPUS is None:
        return []
    return sorted(p for p in CORPUS.rglob("*") if p.suffix.lower() in suffixes and p.is_file())


def _params(files: list[Path]) -> list:
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(reason="SOFA corpus not available"))]
    return [pytest.param(p, id=str(p.relative_to(CORPUS))) for p in files]


needs_corpus = pytest.mark.skipif(CORPUS is None, reason="SOFA corpus not available")


@pytest.fixture(autouse=True)
def _fresh_cache():
    meshes.clear_cache()
    yield
    meshes.clear_cache()


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def raises_at(line: int | None, match: str | None = None):
    """Context manager: MeshError whose .line is ``line``."""

    class _Check:
        def __enter__(self):
            self.ctx = pytest.raises(MeshError, match=match)
            self.info = self.ctx.__enter__()
            return self.info

        def __exit__(self, *exc):
            result = self.ctx.__exit__(*exc)
            assert self.info.value.line == line, f"line {self.info.value.line} != {line}: {self.info.value}"
            return result

    return _Check()


# --------------------------------------------------------------------------------------------
# Every mesh/data file of the SOFA corpus
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", _params(_corpus_files(MESH_SUFFIXES)))
def test_corpus_file_reads(path: Path) -> None:
    mesh = read_mesh(path)
    n = mesh.positions.shape[0]
    assert mesh.positions.dtype == np.float64 and mesh.positions.shape == (n, 3)
    assert np.isfinite(mesh.positions).all()
    assert count_points(path) == n
    for name, width in (("edges", 2), ("triangles", 3), ("quads", 4), ("tetrahedra", 4), ("hexahedra", 8)):
        cells = getattr(mesh, name)
        assert cells.dtype == np.int64 and cells.ndim == 2 and cells.shape[1] == width
        if cells.size:
            assert cells.min() >= 0 and cells.max() < n, name
    for extra, width in ((mesh.normals, 3), (mesh.texcoords, 2)):
        if extra is not None:
            assert extra.shape == (n, width)
    assert not mesh.positions.flags.writeable  # cached arrays are shared


@pytest.mark.parametrize("path", _params(_corpus_files((".obj",))))
def test_corpus_obj_seams_count(path: Path) -> None:
    seams = read_mesh(path, handle_seams=True)
    assert count_points(path, handle_seams=True) == seams.n_points
    plain = read_mesh(path)
    assert seams.source_index is not None and seams.source_index.shape == (seams.n_points,)
    np.testing.assert_array_equal(seams.positions, plain.positions[seams.source_index])


@pytest.mark.parametrize("path", _params(_corpus_files((".sph",))))
def test_corpus_spheres(path: Path) -> None:
    spheres = read_spheres(path)
    assert spheres.centers.shape == (spheres.radii.shape[0], 3)
    assert (spheres.radii > 0).all()
    assert count_points(path) == spheres.radii.shape[0]


@pytest.mark.parametrize("path", _params(_corpus_files((".rigid",))))
def test_corpus_rigid(path: Path) -> None:
    rigid = read_rigid(path)
    assert rigid.present == {"mass", "volume", "inertia", "center"}
    assert rigid.mass > 0 and rigid.volume > 0
    np.testing.assert_allclose(rigid.inertia, rigid.inertia.T)  # all corpus inertias are symmetric


@needs_corpus
def test_corpus_referenced_files_exist_and_read() -> None:
    """Every mesh/data file the corpus manifest lists is readable by the matching reader."""
    import json

    manifest = json.loads((CORPUS / "manifest.json").read_text())
    files = sorted({f for scene in manifest["scenes"] for f in scene.get("files", [])})
    checked = 0
    for name in files:
        path = CORPUS / name
        suffix = path.suffix.lower()
        if suffix in MESH_SUFFIXES:
            read_mesh(path)
            checked += 1
        elif suffix == ".rigid":
            read_rigid(path)
            checked += 1
    assert checked >= 50


# Point and element counts checked by hand (wc/grep/awk on the files).
HAND_COUNTS = {
    # path: (points, edges, triangles, quads, tetrahedra, hexahedra)
    "mesh/liver.msh": (181, 0, 0, 0, 596, 0),
    "mesh/truthcylinder1.msh": (642, 72, 706, 0, 2524, 0),  # non-contiguous node numbers
    "mesh/nine_quads.msh": (16, 0, 0, 9, 0, 0),
    "mesh/cubeDof.msh": (27, 0, 0, 0, 0, 0),  # gmsh 2.0, numbering from 0, no elements
    "mesh/liver-smooth.obj": (2194, 0, 4384, 0, 0, 0),
    "mesh/dragon.obj": (1190, 0, 2564, 0, 0, 0),  # "f 1 2 3 \r\n": trailing blanks
    "mesh/man.obj": (3115, 0, 922, 2313, 0, 0),
    "mesh/floor3.obj": (12, 0, 4, 5, 0, 0),
    "mesh/SofaScene/FSkel.obj": (5, 4, 0, 0, 0, 0),
    "mesh/Armadillo_Tetra_4406.vtu": (1446, 0, 0, 0, 4406, 0),
    "mesh/test_quad.vtk": (312, 0, 0, 288, 0, 0),
    "mesh/SofaScene/A.vtk": (413, 1942, 2645, 0, 1116, 0),
    "mesh/liver.sph": (34, 0, 0, 0, 0, 0),
    "mesh/floor.sph": (2520, 0, 0, 0, 0, 0),
}


@needs_corpus
@pytest.mark.parametrize("name", sorted(HAND_COUNTS))
def test_hand_checked_counts(name: str) -> None:
    mesh = read_mesh(CORPUS / name)
    got = (
        mesh.n_points,
        len(mesh.edges),
        len(mesh.triangles),
        len(mesh.quads),
        len(mesh.tetrahedra),
        len(mesh.hexahedra),
    )
    assert got == HAND_COUNTS[name]
    assert count_points(CORPUS / name) == HAND_COUNTS[name][0]


@needs_corpus
def test_liver_msh_first_values() -> None:
    mesh = read_mesh(CORPUS / "mesh/liver.msh")
    np.testing.assert_allclose(mesh.positions[0], [-0.979259, 2.23512, 2.61245])
    # "1 4 1 1 4 128 141 138 142": node numbers 1..181 in order -> index = number - 1
    np.testing.assert_array_equal(mesh.tetrahedra[0], [127, 140, 137, 141])


@needs_corpus
def test_truthcylinder_noncontiguous_ids() -> None:
    path = CORPUS / "mesh/truthcylinder1.msh"
    lines = path.read_text().splitlines()
    n = int(lines[1])
    ids = [int(line.split()[0]) for line in lines[2 : 2 + n]]
    assert ids != list(range(1, n + 1))  # the file really is non-contiguous
    index = {node: k for k, node in enumerate(ids)}
    mesh = read_mesh(path)
    elements = lines[lines.index("$ELM") + 2 : lines.index("$ENDELM")]
    tets = [[index[int(t)] for t in e.split()[5:]] for e in elements if e.split()[1] == "4"]
    np.testing.assert_array_equal(mesh.tetrahedra, tets)


@needs_corpus
def test_vtu_values() -> None:
    mesh = read_mesh(CORPUS / "mesh/Armadillo_Tetra_4406.vtu")
    np.testing.assert_array_equal(mesh.positions[0], [3.14075, -3.05075, 1.16338])  # parsed as double


@needs_corpus
def test_liver_sph_values() -> None:
    spheres = read_spheres(CORPUS / "mesh/liver.sph")
    assert spheres.centers.shape == (34, 3)
    np.testing.assert_array_equal(spheres.centers[0], [-4, 1.25, 0])  # "sphe 1 -4 1.25 0 0.85"
    assert spheres.radii[0] == 0.85


@needs_corpus
def test_torus_rigid_values() -> None:
    rigid = read_rigid(CORPUS / "BehaviorModels/torus.rigid")
    assert rigid.mass == 5.0
    assert rigid.volume == pytest.approx(8.7452405401)
    np.testing.assert_allclose(np.diag(rigid.inertia), [1.3896649307, 3.2215295226, 1.9546878360])
    assert rigid.inertia[0, 2] == pytest.approx(0.0000003707)
    np.testing.assert_allclose(rigid.center, [0.0184738064, -0.0000000243, -0.0000006143])


@needs_corpus
def test_obj_trailing_nul_padding_is_accepted() -> None:
    # Two corpus OBJ files end with a NUL byte; SOFA ignores that line, so do we.
    path = CORPUS / "Tutorials/StepByStep/Dentistry_Haptics/data/mesh/head.obj"
    assert path.read_bytes().rstrip(b"\n").endswith(b"\x00")
    assert read_mesh(path).n_points == 3931


@needs_corpus
def test_obj_undefined_texcoords_are_ignored_with_note() -> None:
    # truthCylinder-Deformed.obj has 'f a/b' corners but no 'vt' line: SOFA ignores them.
    mesh = read_mesh(CORPUS / "Benchmark/Accuracy/mesh/truthCylinder-Deformed.obj")
    assert mesh.texcoords is None
    assert any("texture coordinate" in note for note in mesh.notes)


@needs_corpus
# --------------------------------------------------------------------------------------------
# Cross-checks against independent implementations
# --------------------------------------------------------------------------------------------


def reference_obj(path: Path, handle_seams: bool) -> dict:
    """Slow line-by-line OBJ reader written from MeshOBJLoader's description (the oracle)."""
    pos: list[list[float]] = []
    nor: list[list[float]] = []
    tex: list[list[float]] = []
    faces: list[tuple[bool, list[tuple[int, int, int]]]] = []
    for line in path.read_text(encoding="latin-1").splitlines():
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "v":
            pos.append([float(x) for x in tokens[1:4]])
        elif key == "vn":
            nor.append([float(x) for x in tokens[1:4]])
        elif key == "vt":
            tex.append([float(tokens[1]), float(tokens[2]) if len(tokens) > 2 else 0.0])
        elif key in ("f", "l"):
            corners = []
            for token in tokens[1:]:
                parts = [*token.split("/"), "", ""][:3]
                vtn = []
                for part, defined in zip(parts, (len(pos), len(tex), len(nor)), strict=True):
                    if not part:
                        vtn.append(-1)
                        continue
                    value = int(part)
                    vtn.append(value - 1 if value > 0 else value + defined)
                corners.append(tuple(vtn))
            faces.append((key == "l", corners))
    pos_a = np.array(pos).reshape(-1, 3)
    out: dict = {"edges": [], "triangles": [], "quads": []}
    if handle_seams:
        per_vertex: list[dict] = [dict() for _ in pos]
        for _, corners in faces:
            for v, t, n in corners:
                per_vertex[v][(t, n)] = 0
        new_pos, src, new_t, new_n = [], [], [], []
        for v, table in enumerate(per_vertex):
            for key in sorted(table):
                table[key] = len(new_pos)
                new_pos.append(pos[v])
                src.append(v)
                new_t.append(key[0])
                new_n.append(key[1])
        index = [[per_vertex[v][(t, n)] for v, t, n in corners] for _, corners in faces]
        out["positions"] = np.array(new_pos).reshape(-1, 3)
        if nor:
            normals = np.array([nor[n] if 0 <= n < len(nor) else [0, 0, 0] for n in new_n], dtype=float)
            lengths = np.linalg.norm(normals, axis=1)
            normals[lengths > 0] /= lengths[lengths > 0, None]
            out["normals"] = normals.reshape(-1, 3)
        if tex:
            chosen = [tex[t] if 0 <= t < len(tex) else [0, 0] for t in new_t]
            out["texcoords"] = np.array(chosen).reshape(-1, 2)
    else:
        index = [[v for v, _, _ in corners] for _, corners in faces]
        out["positions"] = pos_a
        if nor:
            normals = np.zeros((len(pos), 3))
            for _, corners in faces:
                for v, _, n in corners:
                    if 0 <= n < len(nor):
                        normals[v] += nor[n]
            lengths = np.linalg.norm(normals, axis=1)
            normals[lengths > 0] /= lengths[lengths > 0, None]
            out["normals"] = normals
        if tex:
            texcoords = np.zeros((len(pos), 2))
            for _, corners in faces:
                for v, t, _ in corners:
                    if 0 <= t < len(tex):
                        cur, cand = texcoords[v], np.array(tex[t])
                        if (cur == 0).all() or (cand[1] - cand[0]) > (cur[1] - cur[0]):
                            texcoords[v] = cand
            out["texcoords"] = texcoords
    for (is_line, _), nodes in zip(faces, index, strict=True):
        if len(nodes) == 2 or (is_line and len(nodes) > 2):
            for a, b in itertools.pairwise(nodes):
                out["edges"].append([min(a, b), max(a, b)])
        elif len(nodes) == 4:
            out["quads"].append(nodes)
        elif len(nodes) >= 3:
            for j in range(2, len(nodes)):
                out["triangles"].append([nodes[0], nodes[j - 1], nodes[j]])
    return out


@pytest.mark.parametrize("handle_seams", [False, True], ids=["plain", "seams"])
@pytest.mark.parametrize("path", _params(_corpus_files((".obj",))))
def test_corpus_obj_matches_reference(path: Path, handle_seams: bool) -> None:
    expected = reference_obj(path, handle_seams)
    mesh = read_mesh(path, handle_seams=handle_seams)
    np.testing.assert_array_equal(mesh.positions, expected["positions"])
    for name, width in (("edges", 2), ("triangles", 3), ("quads", 4)):
        np.testing.assert_array_equal(getattr(mesh, name), np.array(expected[name]).reshape(-1, width), name)
    for name in ("normals", "texcoords"):
        if name in expected:
            np.testing.assert_allclose(getattr(mesh, name), expected[name], atol=1e-12, err_msg=name)
        else:
            assert getattr(mesh, name) is None


@pytest.mark.parametrize("path", _params(_corpus_files((".vtu", ".vtk"))))
def test_corpus_vtk_matches_meshio(path: Path) -> None:
    meshio = pytest.importorskip("meshio")
    other = meshio.read(path)
    mesh = read_mesh(path)
    np.testing.assert_allclose(mesh.positions, other.points, rtol=1e-6, atol=1e-6)
    names = {
        "line": "edges",
        "triangle": "triangles",
        "quad": "quads",
        "tetra": "tetrahedra",
        "hexahedron": "hexahedra",
    }
    for meshio_name, name in names.items():
        blocks = [b.data for b in other.cells if b.type == meshio_name]
        expected = np.concatenate(blocks) if blocks else np.zeros((0, getattr(mesh, name).shape[1]))
        np.testing.assert_array_equal(getattr(mesh, name), expected, name)


# --------------------------------------------------------------------------------------------
# Wavefront OBJ
# --------------------------------------------------------------------------------------------

OBJ_QUADS = """\
# a unit square made of one quad and two triangles, plus a pentagon
mtllib nothing.mtl
o square
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0 0.5 0.5 0.5
usemtl red
s off
g group one
f 1 2 3 4
f -5 -4 -3
f 1/1 3/2 4/3
vt 0 0
vt 1 1
vt 0 1
f 1 2 5 3 4
l 1 2 3
l 4 1
f 2 1
"""


def test_obj_quads_triangles_fans_lines(tmp_path: Path) -> None:
    mesh = read_mesh(write(tmp_path, "a.obj", OBJ_QUADS))
    np.testing.assert_array_equal(mesh.positions[4], [2, 0, 0])  # vertex colours ignored
    np.testing.assert_array_equal(mesh.quads, [[0, 1, 2, 3]])
    # 'f -5 -4 -3' with 5 vertices so far -> 0 1 2; pentagon split as a fan from its first corner
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [0, 4, 2], [0, 2, 3]])
    # polyline 1-2-3, line 4-1 and the 2-corner face 2 1, each stored as (min, max)
    np.testing.assert_array_equal(mesh.edges, [[0, 1], [1, 2], [0, 3], [0, 1]])
    assert mesh.normals is None and mesh.texcoords is not None
    assert count_points(tmp_path / "a.obj") == 5


def test_obj_negative_indices_all_kinds(tmp_path: Path) -> None:
    text = """\
v 0 0 0
v 1 0 0
v 0 1 0
vt 0.1 0.2
vt 0.3 0.9
vn 0 0 2
f -3/-2/-1 -2/-1/-1 -1/-1/-1
v 5 5 5
vn 1 0 0
f -4//-1 -1//-1 -2//-2
"""
    mesh = read_mesh(write(tmp_path, "neg.obj", text))
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 2], [0, 3, 2]])
    # vertex 0 gets normals (0,0,2) and (1,0,0) summed then normalised
    np.testing.assert_allclose(mesh.normals[0], np.array([1, 0, 2]) / math.sqrt(5))
    np.testing.assert_allclose(mesh.normals[3], [1, 0, 0])
    np.testing.assert_allclose(mesh.texcoords[0], [0.1, 0.2])
    np.testing.assert_allclose(mesh.texcoords[1], [0.3, 0.9])


def test_obj_texcoord_rule_and_seams(tmp_path: Path) -> None:
    # vertex 1 is used with two texcoords: plain mode keeps the one with the larger v - u,
    # seam mode splits it into two points.
    text = """\
v 0 0 0
v 1 0 0
v 0 1 0
v 1 1 0
vt 0.5 0.5
vt 0.9 0.1
vt 0.2 0.8
vt 0.0 1.0
f 1/1 2/2 3/3
f 2/3 4/4 3/3
"""
    path = write(tmp_path, "uv.obj", text)
    plain = read_mesh(path)
    np.testing.assert_allclose(plain.texcoords[1], [0.2, 0.8])
    seams = read_mesh(path, handle_seams=True)
    assert seams.n_points == 5
    assert count_points(path) == 4 and count_points(path, handle_seams=True) == 5
    np.testing.assert_array_equal(seams.source_index, [0, 1, 1, 2, 3])
    np.testing.assert_allclose(seams.texcoords[1:3], [[0.9, 0.1], [0.2, 0.8]])
    np.testing.assert_array_equal(seams.triangles, [[0, 1, 3], [2, 4, 3]])


def test_obj_zero_texcoord_candidates_replayed(tmp_path: Path) -> None:
    # A (0,0) texcoord is replaced by the next candidate whatever its v - u (SOFA's rule).
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 0.9 0.1\nvt 0.5 0.5\nf 1/1 2/1 3/1\nf 1/2 2/3 3/1\n"
    mesh = read_mesh(write(tmp_path, "zero.obj", text))
    np.testing.assert_allclose(mesh.texcoords, [[0.9, 0.1], [0.5, 0.5], [0, 0]])


def test_obj_crlf_tabs_indent_and_comments(tmp_path: Path) -> None:
    text = "v\t0 0 0\r\n  v 1 0 0 # trailing comment\r\n v  0  1   0\r\nf 1 2 3 # comment\r\n"
    path = write(tmp_path, "crlf.obj", text)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 2]])
    assert count_points(path) == 3


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("v 0 0 0\nv 1 x 0\n", 2, "expected a number"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "vertex 4"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", 4, "index 0"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n# c\nf 1 2 x\n", 5, "expected an integer"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf -4 1 2\n", 5, "before this line"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", 4, "malformed face corner"),
        ("v 0 0 0\nv 1 0\nvn 0 x 0\n", 3, "normal"),
        ("v 0 0 0\nv nan 0 0\n", 2, "non-finite"),
        ("v 0 0 0\nv 1\x000 0\nv 2 0 0\n", 2, "binary data"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3.", 5, None),  # truncated last line
    ],
)
def test_obj_errors_have_lines(tmp_path: Path, text: str, line: int, match: str | None) -> None:
    with raises_at(line, match):
        read_mesh(write(tmp_path, "bad.obj", text))


def test_obj_short_lines_keep_the_previous_numbers(tmp_path: Path) -> None:
    """SOFA reads every v/vn/vt line into one Vec3 with `>>`: a number past the end of a short line
    stays what the previous v, vn or vt line left (0 at first). share/mesh/raptorTemperature.obj
    ("v 0" a line) is a scalar field TetrahedronDiffusionFEMForceField.scn loads this way."""
    text = "v 5\nv 1 2 3\nvt 7\nv 4\nvn 0 0 1\nv 6\nvt 8 9\nf 1 2 3\n"
    mesh = read_mesh(write(tmp_path, "short.obj", text))
    np.testing.assert_array_equal(mesh.positions, [[5, 0, 0], [1, 2, 3], [4, 2, 3], [6, 0, 1]])
    assert count_points(tmp_path / "short.obj") == 4


def test_obj_error_message_names_file_and_line(tmp_path: Path) -> None:
    path = write(tmp_path, "bad.obj", "v 0 0 0\nv 1 x\n")
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    assert str(info.value).startswith(f"{path.resolve()}:2: ")
    assert info.value.path == path.resolve()


def test_obj_without_faces(tmp_path: Path) -> None:
    mesh = read_mesh(write(tmp_path, "pts.obj", "v 0 0 0\nv 1 2 3\nvn 0 0 1\n"))
    assert mesh.n_points == 2 and mesh.triangles.shape == (0, 3) and mesh.edges.shape == (0, 2)
    np.testing.assert_array_equal(mesh.normals, np.zeros((2, 3)))


# --------------------------------------------------------------------------------------------
# Gmsh
# --------------------------------------------------------------------------------------------

GMSH1_NONCONTIGUOUS = """\
$NOD
5
10 0 0 0
3 1 0 0
7 0 1 0
100 0 0 1
4 1 1 1
$ENDNOD
$ELM
5
1 4 1 1 4 10 3 7 100
2 2 1 1 3 3 7 4
3 1 1 1 2 100 4
4 15 1 1 1 7
5 6 1 1 6 10 3 7 100 4 3
$ENDELM
"""


def test_gmsh1_noncontiguous_ids(tmp_path: Path) -> None:
    path = write(tmp_path, "a.msh", GMSH1_NONCONTIGUOUS)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    np.testing.assert_array_equal(mesh.tetrahedra, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[1, 2, 4]])
    np.testing.assert_array_equal(mesh.edges, [[3, 4]])
    assert any("type 6" in note and "prism" in note for note in mesh.notes)  # skipped with a note
    assert count_points(path) == 5


def test_gmsh1_large_sparse_ids(tmp_path: Path) -> None:
    text = (
        "$NOD\n3\n1000000 0 0 0\n5 1 0 0\n77777777 0 1 0\n$ENDNOD\n"
        "$ELM\n1\n1 2 1 1 3 5 77777777 1000000\n$ENDELM\n"
    )
    mesh = read_mesh(write(tmp_path, "sparse.msh", text))
    np.testing.assert_array_equal(mesh.triangles, [[1, 2, 0]])


def test_gmsh2_ascii(tmp_path: Path) -> None:
    text = """\
$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
1
3 1 "volume"
$EndPhysicalNames
$Nodes
9
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
5 0 0 1
6 1 0 1
7 1 1 1
8 0 1 1
20 5 5 5
$EndNodes
$Elements
4
1 5 2 1 1 1 2 3 4 5 6 7 8
2 3 2 1 1 1 2 3 4
3 15 2 0 1 20
4 11 2 1 1 1 2 3 5 6 7 8 4 2 3
$EndElements
"""
    path = write(tmp_path, "b.msh", text)
    mesh = read_mesh(path)
    assert mesh.n_points == 9 and count_points(path) == 9
    np.testing.assert_array_equal(mesh.hexahedra, [list(range(8))])
    np.testing.assert_array_equal(mesh.quads, [[0, 1, 2, 3]])
    assert mesh.tetrahedra.shape == (0, 4)
    assert any("type 11" in note for note in mesh.notes)


def test_gmsh_duplicate_ids_last_wins(tmp_path: Path) -> None:
    text = "$NOD\n3\n1 0 0 0\n2 1 0 0\n1 9 9 9\n$ENDNOD\n$ELM\n1\n1 1 1 1 2 1 2\n$ENDELM\n"
    mesh = read_mesh(write(tmp_path, "dup.msh", text))
    np.testing.assert_array_equal(mesh.edges, [[2, 1]])
    assert any("repeated" in note for note in mesh.notes)


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        # element refers to node 9, which does not exist
        ("$NOD\n2\n1 0 0 0\n2 1 0 0\n$ENDNOD\n$ELM\n1\n1 1 1 1 2 1 9\n$ENDELM\n", 8, "node 9"),
        # node line with a missing coordinate
        ("$NOD\n3\n1 0 0 0\n2 1 0\n3 0 1 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n", 4, "number x y z"),
        # garbage in a coordinate
        ("$NOD\n2\n1 0 0 0\n2 1 zero 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n", 4, "expected a number"),
        # fewer nodes than announced
        ("$NOD\n3\n1 0 0 0\n2 1 0 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n", 5, "only 2 of the 3"),
        # truncated: no $ENDELM
        ("$NOD\n1\n1 0 0 0\n$ENDNOD\n$ELM\n1\n1 15 1 1 1 1\n", 5, "not closed"),
        # element announces 4 nodes, lists 3
        (
            "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3\n$ENDELM\n",
            10,
            "announces 4 nodes",
        ),
        # fewer elements than announced
        ("$NOD\n1\n1 0 0 0\n$ENDNOD\n$ELM\n2\n1 15 1 1 1 1\n$ENDELM\n", 5, "only 1 of the 2"),
        # not gmsh at all
        ("hello\n", 1, "not a Gmsh file"),
        # bad node count
        ("$NOD\nmany\n$ENDNOD\n$ELM\n0\n$ENDELM\n", 2, "number of nodes"),
        # format 2: wrong node count for a triangle
        (
            "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n"
            "$Elements\n1\n1 2 2 0 1 1 2\n$EndElements\n",
            12,
            "needs 3 nodes",
        ),
    ],
)
def test_gmsh_errors_have_lines(tmp_path: Path, text: str, line: int, match: str) -> None:
    with raises_at(line, match):
        read_mesh(write(tmp_path, "bad.msh", text))


def test_gmsh4_through_meshio(tmp_path: Path) -> None:
    meshio = pytest.importorskip("meshio")
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]
    path = tmp_path / "v4.msh"
    meshio.write(str(path), meshio.Mesh(points, cells), file_format="gmsh", binary=False)
    assert path.read_text().splitlines()[1].startswith("4.1")
    mesh = read_mesh(path)
    np.testing.assert_allclose(mesh.positions, points)
    np.testing.assert_array_equal(mesh.tetrahedra, [[0, 1, 2, 3], [1, 2, 3, 4]])
    assert count_points(path) == 5


@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("bin22.msh", {"file_format": "gmsh22", "binary": True}),
        ("ascii22.msh", {"file_format": "gmsh22", "binary": False}),
        ("bin51.vtk", {"binary": True}),
        ("ascii51.vtk", {"binary": False}),
    ],
)
def test_gmsh2_binary_and_vtk5_variants(tmp_path: Path, name: str, options: dict) -> None:
    meshio = pytest.importorskip("meshio")
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    cells = [("tetra", np.array([[0, 1, 2, 3]])), ("triangle", np.array([[1, 2, 4]]))]
    path = tmp_path / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meshio.write(str(path), meshio.Mesh(points, cells), **options)
    mesh = read_mesh(path)
    np.testing.assert_allclose(mesh.positions, points)
    np.testing.assert_array_equal(mesh.tetrahedra, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[1, 2, 4]])
    assert count_points(path) == 5


# --------------------------------------------------------------------------------------------
# VTK
# --------------------------------------------------------------------------------------------

VTU = """\
<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="5" NumberOfCells="3">
      <Points>
        <DataArray type="Float32" NumberOfComponents="3" format="ascii">
          0 0 0  1 0 0  0 1 0  0 0 1  1 1 1
        </DataArray>
      </Points>
      <Cells>
        <DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 3  1 2 4  3 4</DataArray>
        <DataArray type="Int32" Name="offsets" format="ascii">4 7 9</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">10 5 3</DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"""


def test_vtu_ascii(tmp_path: Path) -> None:
    path = write(tmp_path, "a.vtu", VTU)
    mesh = read_mesh(path)
    assert mesh.n_points == 5 and count_points(path) == 5
    np.testing.assert_array_equal(mesh.tetrahedra, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[1, 2, 4]])
    np.testing.assert_array_equal(mesh.edges, [[3, 4]])


def test_vtu_binary_refused(tmp_path: Path) -> None:
    text = VTU.replace('NumberOfComponents="3" format="ascii"', 'NumberOfComponents="3" format="binary"')
    with raises_at(6, "binary VTU not supported"):
        read_mesh(write(tmp_path, "bin.vtu", text))
    appended = VTU.replace(
        "</UnstructuredGrid>", '</UnstructuredGrid>\n  <AppendedData encoding="raw">_</AppendedData>'
    )
    with pytest.raises(MeshError, match="binary VTU not supported"):
        read_mesh(write(tmp_path, "app.vtu", appended))


def test_vtu_entities_not_expanded(tmp_path: Path) -> None:
    text = VTU.replace('<?xml version="1.0"?>', '<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e "0 0 0">]>')
    with pytest.raises(MeshError, match="DOCTYPE"):
        read_mesh(write(tmp_path, "dtd.vtu", text))


@pytest.mark.parametrize(
    ("old", "new", "line", "match"),
    [
        ("0 0 0  1 0 0  0 1 0  0 0 1  1 1 1", "0 0 0  1 0 0  0 1 0  0 0 1  1 1", 6, "expected 15 values"),
        (
            '<DataArray type="Int32" Name="offsets" format="ascii">4 7 9',
            '<DataArray type="Int32" Name="offsets" format="ascii">4 7 x',
            12,
            "expected numbers",
        ),
        ("0 1 2 3  1 2 4  3 4", "0 1 2 3  1 2 4  3 9", 11, "point 9"),
        ("</VTKFile>\n", "", 17, "malformed XML"),
        ('type="UnstructuredGrid" version', 'type="PolyData" version', 2, "PolyData"),
    ],
)
def test_vtu_errors_have_lines(tmp_path: Path, old: str, new: str, line: int, match: str) -> None:
    assert old in VTU
    with raises_at(line, match):
        read_mesh(write(tmp_path, "bad.vtu", VTU.replace(old, new)))


VTK_LEGACY = """\
# vtk DataFile Version 2.0
test
ASCII
DATASET UNSTRUCTURED_GRID
POINTS 6 double
0 0 0 1 0 0 1 1 0
0 1 0 0 0 1 1 0 1
CELLS 4 18
4 0 1 2 3
3 0 1 4
2 4 5
5 0 1 5 4 3
CELL_TYPES 4
9
5
3
7
POINT_DATA 6
SCALARS s float 1
LOOKUP_TABLE default
1 2 3 4 5 6
"""


def test_vtk_legacy_ascii(tmp_path: Path) -> None:
    path = write(tmp_path, "a.vtk", VTK_LEGACY)
    mesh = read_mesh(path)
    assert mesh.n_points == 6 and count_points(path) == 6
    np.testing.assert_array_equal(mesh.quads, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 4], [0, 1, 5], [0, 5, 4], [0, 4, 3]])
    np.testing.assert_array_equal(mesh.edges, [[4, 5]])


def test_vtk_legacy_polydata(tmp_path: Path) -> None:
    text = """\
# vtk DataFile Version 3.0
poly
ASCII
DATASET POLYDATA
POINTS 5 float
0 0 0 1 0 0 1 1 0 0 1 0 0.1 0.2 0.3
POLYGONS 2 9
4 0 1 2 3
3 0 1 4
LINES 1 4
3 0 1 2
POINT_DATA 5
NORMALS n float
0 0 1 0 0 1 0 0 1 0 0 1 0 0 1
"""
    mesh = read_mesh(write(tmp_path, "p.vtk", text))
    np.testing.assert_array_equal(mesh.quads, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 4]])
    np.testing.assert_array_equal(mesh.edges, [[0, 1], [1, 2]])
    assert mesh.normals is not None and (mesh.normals[:, 2] == 1).all()
    assert mesh.positions[4, 0] == np.float32(0.1)  # 'float' points are single precision in SOFA


@pytest.mark.parametrize(
    ("old", "new", "line", "match"),
    [
        ("0 1 0 0 0 1 1 0 1", "0 1 0 0 0 1 1 0", 5, "expected 18 values"),
        ("CELLS 4 18", "CELLS 4 19", 8, "expected 19 values"),
        ("3 0 1 4", "3 0 1 9", 8, "point 9"),
        ("CELL_TYPES 4\n9", "CELL_TYPES 4\n9x", 14, "expected a number"),
        ("DATASET UNSTRUCTURED_GRID", "DATASET STRUCTURED_POINTS", 4, "not supported"),
    ],
)
def test_vtk_errors_have_lines(tmp_path: Path, old: str, new: str, line: int, match: str) -> None:
    assert old in VTK_LEGACY
    with raises_at(line, match):
        read_mesh(write(tmp_path, "bad.vtk", VTK_LEGACY.replace(old, new)))


def test_vtk_xml_file_named_vtk(tmp_path: Path) -> None:
    """MeshVTKLoader picks its reader from the first lines, not the extension: share/mesh/Bunny.vtk
    (Component/Engine/Generate/VolumeFromVolumetricElements.scn) is XML, starting at <VTKFile."""
    expected = read_mesh(write(tmp_path, "a.vtu", VTU))
    for name, text in (("b.vtk", VTU), ("c.vtk", VTU.split("\n", 1)[1])):
        mesh = read_mesh(write(tmp_path, name, text))
        np.testing.assert_array_equal(mesh.positions, expected.positions)
        np.testing.assert_array_equal(mesh.tetrahedra, expected.tetrahedra)
        assert count_points(tmp_path / name) == 5


def test_vtk_xml_polydata(tmp_path: Path) -> None:
    """XMLVTKReader::loadPolydata (share/mesh/skull.vtp in Component/IO/Mesh/MeshVTKLoader.scn):
    Points, Polys by their offsets (2 points: an edge, 3: a triangle, 4: a quad, more: a polyline
    SOFA keeps apart) and PointData normals; Lines are not read."""
    text = """<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData>
    <Piece NumberOfPoints="5" NumberOfLines="1" NumberOfPolys="4">
      <PointData Normals="Normals">
        <DataArray type="Float32" Name="Normals" NumberOfComponents="3" format="ascii">
          0 0 1  0 0 1  0 0 1  0 0 1  0 0 1
        </DataArray>
      </PointData>
      <Points>
        <DataArray type="Float32" NumberOfComponents="3" format="ascii">
          0 0 0  1 0 0  1 1 0  0 1 0  0.1 0.2 0.3
        </DataArray>
      </Points>
      <Lines>
        <DataArray type="Int32" Name="connectivity" format="ascii">0 4</DataArray>
        <DataArray type="Int32" Name="offsets" format="ascii">2</DataArray>
      </Lines>
      <Polys>
        <DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 3  0 1 4  2 3  0 1 2 3 4</DataArray>
        <DataArray type="Int32" Name="offsets" format="ascii">4 7 9 14</DataArray>
      </Polys>
    </Piece>
  </PolyData>
</VTKFile>
"""
    mesh = read_mesh(write(tmp_path, "p.vtp", text))
    np.testing.assert_array_equal(mesh.quads, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 4]])
    np.testing.assert_array_equal(mesh.edges, [[2, 3]])
    assert mesh.positions[4].tolist() == [0.1, 0.2, 0.3]  # SOFA reads the points as Float64
    assert mesh.normals is not None and (mesh.normals[:, 2] == 1).all()
    assert count_points(tmp_path / "p.vtp") == 5


def _legacy_binary(text: str, order: str) -> bytes:
    """The BINARY form of a legacy ASCII file (its sections up to POINT_DATA), numbers in ``order``."""
    lines = text.split("\n")
    out = [lines[0], lines[1], "BINARY", lines[3]]
    blob = b""
    sections = "\n".join(lines[4:]).split("POINT_DATA")[0]
    for block in re.split(r"\n(?=[A-Z_]+ )", sections.strip()):
        head, _, body = block.partition("\n")
        dtype = {"float": "f4", "double": "f8"}.get(head.split()[-1], "i4")
        numbers = np.array(body.split(), dtype=float).astype(order + dtype)
        blob += (head + "\n").encode() + numbers.tobytes() + b"\n"
    return ("\n".join(out) + "\n").encode() + blob


@pytest.mark.parametrize("order", [">", "<"])
def test_vtk_legacy_binary_reads_as_ascii(tmp_path: Path, order: str) -> None:
    """share/mesh/liver.vtk (Component/IO/Mesh/MeshVTKLoader.scn) is BINARY POLYDATA: the raw
    numbers after each section line, big-endian as VTK writes them; SOFA also reads a file written
    in the machine's order (it swaps when the first cell count reads larger swapped back)."""
    polydata = (
        "# vtk DataFile Version 3.0\npoly\nASCII\nDATASET POLYDATA\nPOINTS 5 float\n"
        "0 0 0 1 0 0 1 1 0 0 1 0 0.1 0.2 0.3\nPOLYGONS 2 9\n4 0 1 2 3\n3 0 1 4\n"
    )
    for name, text in (("grid", VTK_LEGACY), ("poly", polydata)):
        ascii_mesh = read_mesh(write(tmp_path, f"{name}.vtk", text))
        path = tmp_path / f"{name}-binary.vtk"
        path.write_bytes(_legacy_binary(text, order))
        mesh = read_mesh(path)
        assert count_points(path) == ascii_mesh.n_points
        np.testing.assert_array_equal(mesh.positions, ascii_mesh.positions)
        for kind in ("edges", "triangles", "quads", "tetrahedra"):
            np.testing.assert_array_equal(getattr(mesh, kind), getattr(ascii_mesh, kind))
    assert mesh.positions[4, 0] == np.float32(0.1)
    truncated = path.read_bytes()[:-10]
    path.write_bytes(truncated)
    with raises_at(6, "the file ends before"):
        read_mesh(path)


# --------------------------------------------------------------------------------------------
# Spheres and rigid files
# --------------------------------------------------------------------------------------------


def test_sph(tmp_path: Path) -> None:
    text = "sph 1.0\n#nums 3\nnums 2\n# comment\nsphe 7 1 2 3 0.5\n#sphe 1 0 0 0 1\nsphe 7 4 5 6 1.5\n"
    path = write(tmp_path, "a.sph", text)
    spheres = read_spheres(path)
    np.testing.assert_array_equal(spheres.centers, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(spheres.radii, [0.5, 1.5])
    assert count_points(path) == 2
    assert read_mesh(path).n_points == 2
    assert spheres.notes == ()


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("sph 1.0\nsphe 1 0 0 0 1\nsphe 2 0 0 1\n", 3, "needs 'id x y z radius'"),
        ("sph 1.0\nsphe 1 0 0 0 1\nsphe 2 0 a 0 1\n", 3, "expected a number"),
        ("sph 1.0\nnums x\n", 2, "expected an integer"),
    ],
)
def test_sph_errors(tmp_path: Path, text: str, line: int, match: str) -> None:
    with raises_at(line, match):
        read_spheres(write(tmp_path, "bad.sph", text))


def test_rigid(tmp_path: Path) -> None:
    text = (
        "Xsp 3.0\n# a comment\nmass 2.5\nvolm 3\ninrt 1 0 0\n 0 2 0 0 0 3 # split over lines\n"
        "cntr 1 2 3\nfrme 0 0 0 1\ngrav 0 -9.8 0\n"
    )
    rigid = read_rigid(write(tmp_path, "a.rigid", text))
    assert rigid.mass == 2.5 and rigid.volume == 3.0
    np.testing.assert_array_equal(rigid.inertia, np.diag([1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(rigid.center, [1, 2, 3])
    partial = read_rigid(write(tmp_path, "b.rigid", "Xsp 3.0\nvertexMass 4\n"))
    assert partial.present == {"mass"} and partial.volume == 1.0
    np.testing.assert_array_equal(partial.inertia, np.eye(3))


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("Xsp 3.0\nvertexMass 1\ninrt 1 0 0 0 1 0 0 1\n", 3, "needs 9"),
        ("Xsp 3.0\nvertexMass heavy\n", 2, "expected a number"),
        ("Xsp 3.0\nvertexMass 1\nspeed 3\n", 3, "unknown keyword"),
    ],
)
def test_rigid_errors(tmp_path: Path, text: str, line: int, match: str) -> None:
    with raises_at(line, match):
        read_rigid(write(tmp_path, "bad.rigid", text))


# --------------------------------------------------------------------------------------------
# Dispatch, caching, misc
# --------------------------------------------------------------------------------------------


def test_unknown_extension_names_supported(tmp_path: Path) -> None:
    path = write(tmp_path, "a.ply", "ply\n")
    with pytest.raises(MeshError, match=r"\.ply.*supported: \.obj, \.msh, \.vtu, \.vtp, \.vtk, \.sph, \.stl"):
        read_mesh(path)
    with pytest.raises(MeshError, match="supported"):
        count_points(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MeshError, match="cannot read file") as info:
        read_mesh(tmp_path / "nope.obj")
    assert info.value.line is None


def test_cache_and_invalidation(tmp_path: Path) -> None:
    path = write(tmp_path, "c.obj", "v 0 0 0\n")
    first = read_mesh(path)
    assert read_mesh(path) is first
    assert read_mesh(str(path)) is first
    path.write_text("v 0 0 0\nv 1 1 1\n")
    os.utime(path, ns=(time.time_ns() + 10**9, time.time_ns() + 10**9))
    assert read_mesh(path).n_points == 2
    assert count_points(path) == 2
    with pytest.raises(ValueError):
        first.positions[0, 0] = 1.0  # read-only


def test_mesh_validates_shapes() -> None:
    mesh = meshes.Mesh(positions=[[0, 0, 0]], triangles=[])
    assert mesh.triangles.shape == (0, 3) and mesh.hexahedra.shape == (0, 8)
    with pytest.raises(ValueError):
        meshes.Mesh(positions=[[0, 0]])
    assert mesh.max_index() == -1


# --------------------------------------------------------------------------------------------
# apply_transform: SOFA's Euler convention, order scale -> rotate -> translate
# --------------------------------------------------------------------------------------------


def sofa_quat_rotate(rotation_deg, point):
    """SOFA's Quat::createQuaterFromEuler (order ZYX) then Quat::rotate, transcribed."""
    a, b, c = (math.radians(x) / 2 for x in rotation_deg)
    c1, c2, c3, s1, s2, s3 = math.cos(a), math.cos(b), math.cos(c), math.sin(a), math.sin(b), math.sin(c)
    q = np.array(
        [
            s1 * c2 * c3 - c1 * s2 * s3,
            c1 * s2 * c3 + s1 * c2 * s3,
            c1 * c2 * s3 - s1 * s2 * c3,
            c1 * c2 * c3 + s1 * s2 * s3,
        ]
    )
    v = np.asarray(point, dtype=float)
    t = 2 * np.cross(q[:3], v)
    return v + q[3] * t + np.cross(q[:3], t)


@pytest.mark.parametrize(
    ("rotation", "point", "expected"),
    [
        ((90, 0, 0), (0, 1, 0), (0, 0, 1)),  # about X: y -> z
        ((90, 0, 0), (0, 0, 1), (0, -1, 0)),
        ((0, 90, 0), (0, 0, 1), (1, 0, 0)),  # about Y: z -> x
        ((0, 90, 0), (1, 0, 0), (0, 0, -1)),
        ((0, 0, 90), (1, 0, 0), (0, 1, 0)),  # about Z: x -> y
        ((0, 0, 90), (0, 1, 0), (-1, 0, 0)),
        ((-90, 0, 0), (0, 1, 0), (0, 0, -1)),
        # X first, then Y, then Z (world axes): (0,1,0) -X90-> (0,0,1) -Y90-> (1,0,0)
        ((90, 90, 0), (0, 1, 0), (1, 0, 0)),
        # (1,0,0) -Y90-> (0,0,-1) -Z90-> (0,0,-1); the other order would give (0,0,-1) too, so
        # use a point that tells them apart: (0,1,0) -Y90-> (0,1,0) -Z90-> (-1,0,0)
        ((0, 90, 90), (0, 1, 0), (-1, 0, 0)),
        ((90, 0, 90), (1, 0, 0), (0, 1, 0)),  # Rx leaves x alone, then Rz: x -> y
        ((90, 0, 90), (0, 1, 0), (0, 0, 1)),  # Rx: y -> z, Rz leaves z alone
        ((180, 0, 0), (1, 2, 3), (1, -2, -3)),
    ],
)
def test_rotation_hand_values(rotation, point, expected) -> None:
    got = apply_transform(np.array([point], dtype=float), rotation_deg=rotation)
    np.testing.assert_allclose(got[0], expected, atol=1e-12)
    np.testing.assert_allclose(sofa_quat_rotate(rotation, point), expected, atol=1e-12)


def test_rotation_matches_sofa_quaternion_formula() -> None:
    rng = np.random.default_rng(1)
    points = rng.normal(size=(20, 3))
    for _ in range(20):
        rotation = rng.uniform(-360, 360, size=3)
        got = apply_transform(points, rotation_deg=rotation)
        expected = np.array([sofa_quat_rotate(rotation, p) for p in points])
        np.testing.assert_allclose(got, expected, atol=1e-12)
        matrix = meshes.euler_to_matrix(rotation)
        np.testing.assert_allclose(matrix @ matrix.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(matrix) == pytest.approx(1.0)


def test_transform_order_scale_rotate_translate() -> None:
    points = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    got = apply_transform(points, translation=(10, 20, 30), rotation_deg=(0, 0, 90), scale=(2, 3, 1))
    # scale: (2,0,0), (0,3,0); rotate Z90: (0,2,0), (-3,0,0); translate
    np.testing.assert_allclose(got, [[10, 22, 30], [7, 20, 30]], atol=1e-12)
    np.testing.assert_allclose(points, [[1, 0, 0], [0, 1, 0]])  # input untouched
    matrix = meshes.transform_matrix((10, 20, 30), (0, 0, 90), (2, 3, 1))
    np.testing.assert_allclose(meshes.apply_matrix(points, matrix), got, atol=1e-12)
    np.testing.assert_allclose(apply_transform(points, scale=2.0), 2 * points)


def test_transform_identity_and_vec2() -> None:
    points = np.array([[1.5, -2.0, 3.0]])
    np.testing.assert_array_equal(apply_transform(points), points)
    np.testing.assert_array_equal(apply_transform(points, (0, 0, 0), (0, 0, 0), (1, 1, 1)), points)
    flat = np.array([[1.0, 0.0], [0.0, 2.0]])  # Vec2 state: z taken as 0 and dropped
    got = apply_transform(flat, (1, 1, 5), (0, 0, 90), None)
    np.testing.assert_allclose(got, [[1, 2], [-1, 1]], atol=1e-12)


def test_apply_matrix_ignores_non_affine() -> None:
    points = np.array([[1.0, 2.0, 3.0]])
    bad = np.eye(4)
    bad[3, 0] = 1.0
    np.testing.assert_array_equal(meshes.apply_matrix(points, bad), points)


@needs_corpus
def test_mutated_corpus_files_fail_cleanly(tmp_path: Path) -> None:
    """Truncated or corrupted copies of corpus files either read or raise MeshError, quickly."""
    import random

    rng = random.Random(1234)
    names = (
        "mesh/liver.msh",
        "mesh/truthcylinder1.msh",
        "mesh/cubeDof.msh",
        "mesh/floor3.obj",
        "mesh/meca_snake_900tri.obj",
        "mesh/test_quad.vtk",
        "mesh/SofaScene/LogoColli.sph",
        "BehaviorModels/torus.rigid",
        "mesh/Armadillo_Tetra_4406.vtu",
    )
    sources = [CORPUS / name for name in names]
    for k in range(150):
        source = rng.choice(sources)
        data = bytearray(source.read_bytes())
        op = rng.randrange(4)
        if op == 0:
            data = data[: rng.randrange(len(data) + 1)]
        elif op == 1:
            for _ in range(rng.randrange(1, 5)):
                data[rng.randrange(len(data))] = rng.choice(b'-+.e/ \n\x00abc019$<>"')
        elif op == 2:
            start = rng.randrange(len(data))
            del data[start : start + rng.randrange(200)]
        else:
            at = rng.randrange(len(data))
            data[at:at] = rng.choice([b"nan ", b"-1 ", b"0 ", b"//", b"\n", b"99999999999 ", b"$"])
        path = tmp_path / f"m{k}{source.suffix}"
        path.write_bytes(bytes(data))
        start_time = time.perf_counter()
        readers = [read_rigid] if source.suffix == ".rigid" else [read_mesh, count_points]
        for reader in readers:
            with contextlib.suppress(MeshError):
                reader(path)
        assert time.perf_counter() - start_time < 2.0, (source.name, op)


def _sofa_euler_quaternion(degrees: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """Quat::createQuaterFromEuler(rotation * M_PI / 180.0), ZYX, in plain double arithmetic."""
    a, b, c = (d * math.pi / 180.0 / 2 for d in degrees)
    c1, c2, c3, s1, s2, s3 = math.cos(a), math.cos(b), math.cos(c), math.sin(a), math.sin(b), math.sin(c)
    return (
        s1 * c2 * c3 - c1 * s2 * s3,
        c1 * s2 * c3 + s1 * c2 * s3,
        c1 * c2 * s3 - s1 * s2 * c3,
        c1 * c2 * c3 + s1 * s2 * s3,
    )


def test_transforms_are_sofas_arithmetic_operation_for_operation() -> None:
    """Loaders: Matrix4::transform of T R S (rows summed left to right, then t). States:
    applyScale, Quat::rotate (v + w t + q x t, t = 2 q x v), applyTranslation. No BLAS product,
    whose kernel depends on the processor."""
    rng = np.random.default_rng(7)
    points = rng.uniform(-3, 3, (50, 3))
    rotation, scale, translation = (30.0, -45.0, 110.0), (1.5, 0.7, 2.0), (0.1, -2.0, 3.3)
    x, y, z, w = _sofa_euler_quaternion(rotation)
    rows = [
        (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (z * x + y * w)),
        (2 * (x * y + z * w), 1 - 2 * (z * z + x * x), 2 * (y * z - x * w)),
        (2 * (z * x - y * w), 2 * (y * z + x * w), 1 - 2 * (y * y + x * x)),
    ]
    loader = meshes.apply_transform(points, translation, rotation, scale, loader=True)
    state = meshes.apply_transform(points, translation, rotation, scale)

    def cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])

    for p, got_loader, got_state in zip(points.tolist(), loader, state, strict=True):
        m = [[rows[i][j] * scale[j] for j in range(3)] for i in range(3)]
        want = [m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + translation[i] for i in range(3)]
        assert got_loader.tolist() == want
        v = tuple(p[j] * scale[j] for j in range(3))
        t = tuple(2 * c for c in cross((x, y, z), v))
        u = cross((x, y, z), t)
        want = [v[i] + w * t[i] + u[i] + translation[i] for i in range(3)]
        assert got_state.tolist() == want
