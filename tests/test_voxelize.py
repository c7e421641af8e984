"""SparseGridTopology's voxelisation (sofac.geometry.voxelize, the ``sparse_grid`` evaluator): an analytic
closed cube, the polygon-cube test on hand-made cases, and the three dragons of SOFA's
SparseGridTopology.scn against the points SOFA recorded in its regression references."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from sofac.check.checker import check_file
from sofac.front import meshes
from sofac.geometry import voxelize
from sofac.geometry.barycentric import RegularGrid, barycentric_embedding
from sofac.geometry.voxelize import BOUNDARY, INSIDE, OUTSIDE

SCENE = "Component/Topology/Container/Grid/SparseGridTopology.scn"
# (n, dz) of DragonCoarse, DragonMiddle, DragonFine, and the number of points SOFA gave each.
DRAGONS = [((6, 5, 4), 0.0, 110), ((12, 9, 6), 15.0, 434), ((25, 20, 9), 30.0, 2061)]


def cube_surface(low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    """The closed surface of the cube [low, high]^3: 8 corners, 12 outward triangles."""
    corners = np.array([[x, y, z] for z in (low, high) for y in (low, high) for x in (low, high)], float)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return corners, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])


def test_closed_cube_cells_are_boundary_inside_outside() -> None:
    """Surface [0.5, 3.5]^3 in a grid of unit cells from -1 to 5: the 4x4x4 block of cells from 0 to
    4 meets the solid; its 8 central cells lie strictly inside the surface (INSIDE), the 56 around
    them contain part of it (BOUNDARY); the 152 cells of the outer layer are OUTSIDE."""
    vertices, triangles = cube_surface(0.5, 3.5)
    grid = RegularGrid((7, 7, 7), (-1.0, -1.0, -1.0), (5.0, 5.0, 5.0))
    types = voxelize.classify(grid, vertices, triangles).types.reshape(6, 6, 6)  # (z, y, x)
    block = np.zeros((6, 6, 6), dtype=bool)
    block[1:5, 1:5, 1:5] = True
    core = np.zeros((6, 6, 6), dtype=bool)
    core[2:4, 2:4, 2:4] = True
    assert (types[core] == INSIDE).all()
    assert (types[block & ~core] == BOUNDARY).all()
    assert (types[~block] == OUTSIDE).all()

    sparse = voxelize.sparse_grid(voxelize.classify(grid, vertices, triangles))
    assert sparse.hexahedra.shape == (64, 8) and sparse.boundary.sum() == 56
    assert not sparse.boundary[56:].any()  # BOUNDARY cells first, then INSIDE
    # Points: the 125 corners from 0 to 4, in lexicographic (x, y, z) order.
    expected = np.array([[x, y, z] for x in range(5) for y in range(5) for z in range(5)], float)
    assert np.array_equal(sparse.points, expected)
    # The first BOUNDARY cell is regular cube (1, 1, 1): corners (0,0,0) (1,0,0) (1,1,0) (0,1,0) ...
    first = sparse.points[sparse.hexahedra[0]]
    assert first.tolist() == [
        [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]
    ]  # fmt: skip
    assert sparse.regular_to_sparse[1 + 6 * (1 + 6 * 1)] == 0
    assert (sparse.regular_to_sparse[~block.ravel()] == -1).all()

    inner = voxelize.sparse_grid(voxelize.classify(grid, vertices, triangles), only_inside=True)
    assert inner.hexahedra.shape == (8, 8) and len(inner.points) == 27 and not inner.boundary.any()
    assert inner.points[0].tolist() == [1, 1, 1] and inner.points[-1].tolist() == [3, 3, 3]


def test_bounding_box_and_cell_width() -> None:
    """min = max = 0: the surface's box grown by 1 % of its size per side; cellWidth sets n."""
    vertices, _ = cube_surface(0.0, 2.0)
    grid = voxelize.regular_grid(vertices, (1, 3, 5))
    assert grid.n == (2, 3, 5)  # SOFA's init raises each count to at least 2
    assert grid.min == (-0.02, -0.02, -0.02) and grid.max == (2.02, 2.02, 2.02)
    sized = voxelize.regular_grid(vertices, (2, 2, 2), (0.0, 0.0, 0.0), (2.0, 1.0, 0.5), cell_width=0.25)
    assert sized.n == (9, 5, 3) and sized.min == (0.0, 0.0, 0.0)


def test_triangle_cube_test_cases() -> None:
    """Against the unit cube centred at 0: a large triangle through the middle (no vertex or edge in
    the cube: only the diagonal test sees it), one whose edge crosses the cube, one beside it, and
    one whose corners are outside different faces while it still cuts a corner region."""

    def hit(*triangle: tuple[float, float, float]) -> bool:
        a, b, c = (np.array([p], dtype=np.float32) for p in triangle)
        return bool(voxelize.triangles_hit_cube(a, b, c)[0])

    assert hit((-10, -10, 0.1), (10, -10, 0.1), (0, 10, 0.1))  # covers the cube's middle plane
    assert hit((-2, 0, 0), (2, 0.1, 0), (0, 5, 3))  # an edge through the cube
    assert hit((0.2, 0.2, 0.2), (5, 5, 5), (5, 6, 5))  # a vertex inside: trivial accept
    assert not hit((-10, -10, 0.6), (10, -10, 0.6), (0, 10, 0.6))  # parallel, above the top face
    assert not hit((0.9, 0.9, -5), (5, 0.9, 5), (0.9, 5, 5))  # outside one edge plane
    assert not hit((2, 2, 2), (3, 2, 2), (2, 3, 2))  # far away (trivial reject)
    # Thin slanted triangle passing just beyond the corner (0.5, 0.5, 0.5): x + y + z > 1.5 everywhere.
    assert not hit((1.6, 0, 0), (0, 1.6, 0), (0, 0, 1.6))
    assert hit((1.4, 0, 0), (0, 1.4, 0), (0, 0, 1.4))


def _reference_points(shared_dir: Path, k: int) -> np.ndarray:
    folder = shared_dir / "reference" / "sofa-regression" / Path(SCENE).parent
    (path,) = folder.glob(f"{Path(SCENE).name}.reference_{k}_*_mstate.txt.gz")
    with gzip.open(path, "rt") as stream:
        first = stream.read().split("T=")[1]
    return np.array(first.split("X=")[1].split("V=")[0].split(), dtype=float).reshape(-1, 3)


@pytest.mark.parametrize("k", range(3))
def test_dragon_points_are_sofas(shared_dir: Path, k: int) -> None:
    """Each dragon's sparse grid has SOFA's point count and SOFA's points, in SOFA's order (to the
    6 digits of the reference's T=0 block); every hexahedron is an axis-aligned cell of the grid."""
    n, dz, count = DRAGONS[k]
    mesh = meshes.read_mesh(shared_dir / "corpus" / "sofa" / "mesh" / "dragon.obj")
    grid = voxelize.regular_grid(mesh.positions, n)
    sparse = voxelize.sparse_grid(
        voxelize.classify(grid, mesh.positions, voxelize.triangulate(mesh.triangles, mesh.quads))
    )
    reference = _reference_points(shared_dir, k)
    assert len(sparse.points) == len(reference) == count
    points = sparse.points + np.array([0.0, 0.0, dz])
    assert np.abs(points - reference).max() <= 5e-6 * np.abs(reference).max()
    assert points[0] == pytest.approx(reference[0], rel=1e-5) and points[-1] == pytest.approx(
        reference[-1], rel=1e-5
    )
    _, step = grid.frame()
    corners = sparse.points[sparse.hexahedra]
    offsets = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    )
    assert np.allclose(corners - corners[:, :1], offsets * step, atol=1e-12)
    assert len(np.unique(sparse.hexahedra)) == count  # every point is a corner of some cell


def test_dragon_spheres_map_onto_the_sparse_grid(shared_dir: Path) -> None:
    """BarycentricMapperSparseGridTopology on the fine dragon: the collision spheres' centres are
    reproduced by the trilinear weights (inside a cell, or extrapolated from the nearest boundary
    cell), and every weight row sums to 1."""
    corpus = shared_dir / "corpus" / "sofa"
    mesh = meshes.read_mesh(corpus / "mesh" / "dragon.obj")
    grid = voxelize.regular_grid(mesh.positions, DRAGONS[2][0])
    sparse = voxelize.sparse_grid(
        voxelize.classify(grid, mesh.positions, voxelize.triangulate(mesh.triangles, mesh.quads))
    )
    centres = meshes.read_spheres(corpus / "mesh" / "dragon.sph").centers
    embedding = barycentric_embedding(sparse.points, centres, grid=sparse)
    mapped = np.einsum("nk,nkd->nd", embedding.weights, sparse.points[embedding.indices])
    assert np.abs(mapped - centres).max() < 1e-12
    assert np.allclose(embedding.weights.sum(axis=1), 1.0)
    cube = _regular_cube(grid, centres)
    own = np.where(cube >= 0, sparse.regular_to_sparse[np.maximum(cube, 0)], -1)
    inside = own >= 0
    assert (embedding.element[inside] == own[inside]).all()  # a point in a sparse cell keeps it
    assert sparse.boundary[embedding.element[~inside]].all()  # the others: a BOUNDARY cell


def _regular_cube(grid: RegularGrid, points: np.ndarray) -> np.ndarray:
    n = np.asarray(grid.resolution())
    origin, step = grid.frame()
    cell = np.floor((points - origin) / step).astype(np.int64)
    found = ((cell >= 0) & (cell <= n - 2)).all(axis=1)
    return np.where(found, cell[:, 0] + (n[0] - 1) * (cell[:, 1] + (n[1] - 1) * cell[:, 2]), -1)


@pytest.mark.parametrize(
    ("attribute", "value", "what"),
    [
        ("nbVirtualFinerLevels", "1", "nbVirtualFinerLevels"),
        ("fileTopology", "grid.raw", "voxel files"),
    ],
)
def test_unimplemented_options_are_refused(tmp_path: Path, attribute: str, value: str, what: str) -> None:
    vertices, triangles = cube_surface(0.0, 1.0)
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [
        f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles
    ]
    (tmp_path / "cube.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "grid.raw").write_bytes(b"\0" * 8)
    extra = f'{attribute}="{value}"' if attribute != "fileTopology" else ""
    source = 'fileTopology="cube.obj"' if attribute != "fileTopology" else f'fileTopology="{value}"'
    (tmp_path / "scene.scn").write_text(
        '<Node name="root" dt="0.01">\n'
        "  <EulerImplicitSolver/> <CGLinearSolver/>\n"
        f'  <SparseGridTopology n="3 3 3" {source} {extra}/>\n'
        "  <MechanicalObject/>\n"
        "</Node>\n"
    )
    _, diagnostics = check_file(tmp_path / "scene.scn")
    found = [d for d in diagnostics if d.code == "E222"]
    assert len(found) == 1 and what in found[0].message and found[0].loc.line == 3, list(diagnostics)


def test_scene_topology_outputs(corpus_dir: Path) -> None:
    """The checker evaluates each SparseGridTopology of the scene: its MechanicalObject starts on the
    sparse grid's points (translated by dz), SOFA's counts."""
    checked, diagnostics = check_file(corpus_dir / SCENE)
    assert checked is not None and not diagnostics.has_errors()
    states = [c for c in checked.states() if c.component.node.name.startswith("Dragon")]
    for k, state in enumerate(states):
        points = checked.positions(state.component)
        assert points is not None and len(points) == DRAGONS[k][2]
        reference = _reference_points(corpus_dir.parents[1], k)
        assert np.abs(points - reference).max() <= 5e-6 * np.abs(reference).max()


def test_oversized_grid_is_a_diagnostic_not_a_crash(tmp_path: Path) -> None:
    vertices, triangles = cube_surface(0.0, 1.0)
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [
        f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles
    ]
    (tmp_path / "cube.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "scene.scn").write_text(
        '<Node name="root" dt="0.01">\n'
        "  <EulerImplicitSolver/> <CGLinearSolver/>\n"
        '  <SparseGridTopology n="10000 10000 10000" fileTopology="cube.obj"/>\n'
        "  <MechanicalObject/>\n"
        "</Node>\n"
    )
    _, diagnostics = check_file(tmp_path / "scene.scn")
    (found,) = [d for d in diagnostics if d.code == "E207"]
    assert found.loc.line == 3 and found.loc.attribute == "n" and "lower n" in found.message
