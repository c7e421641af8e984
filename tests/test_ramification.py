"""SparseGridRamificationTopology (compiler/geometry/ramification.py): SOFA's points in SOFA's order
for the regression scene's three C shapes, cells duplicated where two pieces of the surface share a
cell without touching inside it, connexions cut by the finest-level face test, and the regression
scene against SOFA's reference."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from sofac.check.checker import check_file
from sofac.front import meshes
from sofac.geometry import ramification
from sofac.geometry.barycentric import ramified_grid_map
from sofac.regress.suite import Status, run_regression

SCENE = "Component/Topology/Container/Grid/SparseGridRamificationTopology.scn"
# (n, nbVirtualFinerLevels, finestConnectivity, MechanicalObject dx) of the scene's three nodes
NODES = [((5, 2, 2), 3, False, 0.0), ((5, 2, 2), 3, False, 40.0), ((5, 3, 3), 0, True, 80.0)]


def _box(low: tuple[float, float, float], high: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A closed box surface: 8 corners, 12 outward triangles."""
    corners = np.array(
        [[(low, high)[(c >> a) & 1][a] for a in range(3)] for c in range(8)], dtype=np.float64
    )  # corner c: bit a picks low/high on axis a
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int64)
    return corners, triangles


def _box_quads(
    low: tuple[float, float, float], high: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The same box with its 6 faces as quads."""
    corners, triangles = _box(low, high)
    return corners, np.concatenate([triangles[0::2], triangles[1::2, 2:]], axis=1)


def _union(*boxes: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    points, cells, offset = [], [], 0
    for corners, triangles in boxes:
        points.append(corners)
        cells.append(triangles + offset)
        offset += len(corners)
    return np.concatenate(points), np.concatenate(cells)


def _reference_positions(shared_dir: Path, index: int) -> np.ndarray:
    path = (
        shared_dir
        / "reference"
        / "sofa-regression"
        / f"{SCENE}.reference_{index}_MechanicalObject1_mstate.txt.gz"
    )
    with gzip.open(path, "rt") as stream:
        stream.readline()  # T= 0
        values = stream.readline().split()[1:]
    return np.asarray(values, dtype=float).reshape(-1, 3)


@pytest.fixture(scope="module")
def c_mesh(corpus_dir: Path) -> meshes.Mesh:
    return meshes.read_mesh(corpus_dir / "mesh" / "c.obj")


@pytest.mark.parametrize("index", range(3))
def test_scene_grids_have_sofas_points_in_sofas_order(
    shared_dir: Path, c_mesh: meshes.Mesh, index: int
) -> None:
    n, levels, connectivity, dx = NODES[index]
    grid = ramification.ramified_grid(
        c_mesh.positions, c_mesh.triangles, n, virtual_levels=levels, finest_connectivity=connectivity
    )
    reference = _reference_positions(shared_dir, index)
    assert len(grid.points) == len(reference)  # 32, 32 and 54 points
    # SOFA's reference prints 6 significant digits
    assert np.allclose(grid.points + np.array([dx, 0.0, 0.0]), reference, rtol=1e-5, atol=1e-4)
    # every hexahedron has 8 distinct points, every point is used
    assert all(len(set(h)) == 8 for h in grid.hexahedra.tolist())
    assert set(grid.hexahedra.ravel().tolist()) == set(range(len(grid.points)))


def test_c_with_virtual_levels_duplicates_the_cells_its_arms_share(c_mesh: meshes.Mesh) -> None:
    """n = 5 2 2: 4 cells along x; the C's back fills the first, its two arms cross the other three
    apart: those are split in two, each piece joined to its own arm only."""
    grid = ramification.ramified_grid(
        c_mesh.positions, c_mesh.triangles, (5, 2, 2), virtual_levels=3, finest_connectivity=False
    )
    plain = ramification.ramified_grid(
        c_mesh.positions, c_mesh.triangles, (5, 2, 2), virtual_levels=0, finest_connectivity=False
    )
    assert (len(plain.hexahedra), len(plain.points)) == (4, 20)
    assert (len(grid.hexahedra), len(grid.points)) == (7, 32)
    h = grid.hexahedra
    right, left = [1, 2, 5, 6], [0, 3, 4, 7]  # x-max and x-min face corners
    # both pieces of cell 2 hang on the back's x-max face; each later piece on one piece before it
    assert h[1][left].tolist() == h[0][right].tolist() == h[2][left].tolist()
    assert h[3][left].tolist() == h[1][right].tolist() and h[5][left].tolist() == h[3][right].tolist()
    assert h[4][left].tolist() == h[2][right].tolist() and h[6][left].tolist() == h[4][right].tolist()
    assert not set(h[[3, 5]].ravel()) & set(h[[4, 6]].ravel())  # the arms never share a point
    # the coefficients SOFA derives through the virtual levels (its last-child rule included)
    assert grid.coefficients.tolist() == [0.3671875] + [0.03125] * 6


def test_u_shape_arms_in_one_cell_are_two_hexahedra() -> None:
    """A U: a back x in [0, 1] and two arms to x = 4, 1.5 apart in y; two cells along x. The second
    cell holds both arm tips, unconnected inside it: two hexahedra, each sharing the first cell's
    x-max face (16 points instead of 12)."""
    back = _box((0.0, 0.0, 0.0), (1.0, 3.5, 1.0))
    lower = _box((1.0, 0.0, 0.0), (4.0, 1.0, 1.0))
    upper = _box((1.0, 2.5, 0.0), (4.0, 3.5, 1.0))
    vertices, triangles = _union(back, lower, upper)
    grid = ramification.ramified_grid(
        vertices, triangles, (3, 2, 2), virtual_levels=3, finest_connectivity=False
    )
    assert (len(grid.hexahedra), len(grid.points)) == (3, 16)
    h = grid.hexahedra
    assert h[1][[0, 3, 4, 7]].tolist() == h[0][[1, 2, 5, 6]].tolist() == h[2][[0, 3, 4, 7]].tolist()
    assert not set(h[1][[1, 2, 5, 6]]) & set(h[2][[1, 2, 5, 6]])
    # each arm's points map into its own piece of the cell: the lower arm's tip into hexahedron 1
    tips = np.array([[3.9, 0.5, 0.5], [3.9, 3.0, 0.5]])
    indices, weights = ramified_grid_map(grid.coarse, grid.finest, grid.finest_to_hexa, grid.hexahedra, tips)
    used = [set(indices[k][weights[k] != 0].tolist()) for k in range(2)]
    assert used[0] <= set(h[1].tolist()) and used[1] <= set(h[2].tolist())
    assert np.allclose(weights.sum(axis=1), 1.0)
    # without virtual levels nothing tells the arms apart: one hexahedron per cell
    flat = ramification.ramified_grid(
        vertices, triangles, (3, 2, 2), virtual_levels=0, finest_connectivity=False
    )
    assert (len(flat.hexahedra), len(flat.points)) == (2, 12)


def test_finest_connectivity_cuts_cells_no_facet_edge_joins() -> None:
    """Two boxes in neighbouring cells: with finestConnectivity their common face (x = 1) is crossed
    by no edge of the surface, so the two cells keep their own points (16); a single box across the
    face is crossed and stays joined (12), as without the test. The boxes are short (0.4): SOFA's
    segment test reaches one segment length behind the segment's start (see below)."""
    apart = _union(_box((0.0, 0.0, 0.0), (0.4, 1.0, 1.0)), _box((1.6, 0.0, 0.0), (2.0, 1.0, 1.0)))
    across = _box((0.0, 0.0, 0.0), (2.0, 1.0, 1.0))
    counts = {}
    for name, (vertices, triangles) in {"apart": apart, "across": across}.items():
        for connectivity in (True, False):
            grid = ramification.ramified_grid(
                vertices, triangles, (3, 2, 2), finest_connectivity=connectivity
            )
            counts[name, connectivity] = (len(grid.hexahedra), len(grid.points))
    # quads: the face test walks their edges (0 1) (1 2) (2 3), the voxeliser their two triangles
    quads = _union(_box_quads((0.0, 0.0, 0.0), (0.4, 1.0, 1.0)), _box_quads((1.6, 0.0, 0.0), (2.0, 1.0, 1.0)))
    empty = np.zeros((0, 3), dtype=np.int64)
    grid = ramification.ramified_grid(quads[0], empty, (3, 2, 2), quads=quads[1])
    assert (len(grid.hexahedra), len(grid.points)) == (2, 16)
    assert counts == {
        ("apart", True): (2, 16),
        ("apart", False): (2, 12),
        ("across", True): (2, 12),
        ("across", False): (2, 12),
    }


def test_segment_triangle_test_counts_touching_edges() -> None:
    """intersectionSegmentTriangle: a segment through the triangle, one ending on it (closed),
    one parallel to it, one passing beside it; and SOFA's reach: it takes s0 as the centre of a
    segment of half-length |s1 - s0|, so a segment pointing away from the triangle from 0.5 above
    it hits it when 1 long, not when 0.1 long."""
    t0, t1, t2 = np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    s0 = np.array([[0.2, 0.2, -1.0], [0.2, 0.2, 0.0], [0.2, 0.2, 0.5], [2.0, 2.0, -1.0], [0.2, 0.2, 0.5]])
    s1 = np.array([[0.2, 0.2, 1.0], [0.2, 0.2, 1.0], [0.6, 0.2, 0.5], [2.0, 2.0, 1.0], [0.2, 0.2, 1.5]])
    hits = ramification._segments_cross_triangle(s0, s1, t0, t1, t2)
    assert hits.tolist() == [True, True, False, False, True]
    short = ramification._segments_cross_triangle(s0[4:], np.array([[0.2, 0.2, 0.6]]), t0, t1, t2)
    assert short.tolist() == [False]


def test_the_scene_checks_clean(corpus_dir: Path) -> None:
    _, diags = check_file(corpus_dir / SCENE)
    assert [d.code for d in diags if d.severity.name == "ERROR"] == []


def test_regression_scene_passes(shared_dir: Path) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[SCENE]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon
