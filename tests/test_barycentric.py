"""BarycentricMapping's embedding computed at compile time: SOFA's reference liver (the mapped
spheres of Demos/liver.scn at steps 0, 99 and 100), weights that sum to 1 and reproduce points, each
mapper against a literal (slow) transcription of SOFA's search loops, grids, surfaces, errors, speed;
and the C++ kernels of runtime/sofac/mapping.h."""

from __future__ import annotations

import ctypes
import gzip
import math
import time
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.front import meshes
from sofac.geometry import barycentric
from sofac.geometry.barycentric import (
    RegularGrid,
    SparseGrid,
    barycentric_embedding,
    barycentric_map,
    mapper_for,
)
from sofac.geometry.masses import mesh_matrix_mass, mesh_matrix_mass_multiply, topology_edges

RUNTIME = Path(__file__).resolve().parents[1] / "runtime"
KUHN = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])
HEX_CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]


def block_mesh(
    n: tuple[int, int, int], jitter: float, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box of n cells, points jittered; returns (points, hexahedra, tetrahedra) (6 tets per cell)."""
    nx, ny, nz = (v + 1 for v in n)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    points = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1).astype(float)
    rng = np.random.default_rng(seed)
    points += rng.uniform(-jitter, jitter, points.shape)
    k, j, i = (a.ravel() for a in np.meshgrid(*(np.arange(v) for v in n[::-1]), indexing="ij"))
    hexa = np.stack([(i + a) + nx * ((j + b) + ny * (k + c)) for a, b, c in HEX_CORNERS], axis=1)
    tets = hexa[:, KUHN].reshape(-1, 4)
    return points, hexa, tets


def apply(indices: np.ndarray, weights: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The C++ kernel's operation order: out = 0; out += x[idx_j] * w_j for j in order."""
    out = np.zeros((len(indices), x.shape[1]))
    for j in range(indices.shape[1]):
        out = out + x[indices[:, j]] * weights[:, j : j + 1]
    return out


# ---- the liver: SOFA's reference --------------------------------------------------------------------


def _states(path: Path) -> dict[int, np.ndarray]:
    rows = np.genfromtxt(path, delimiter=",", names=True)
    states = {}
    for step in np.unique(rows["step"]).astype(int):
        block = rows[rows["step"] == step]
        block = block[np.argsort(block["dof"])]
        states[int(step)] = np.stack([block["x"], block["y"], block["z"]], axis=1)
    return states


@pytest.fixture(scope="module")
def liver(shared_dir: Path) -> dict:
    corpus = shared_dir / "corpus" / "sofa" / "mesh"
    data = shared_dir / "reference" / "sofa" / "data"
    if not (data / "real_Demos_liver.liver_dofs.csv").exists():
        pytest.skip("SOFA's liver reference is not available")
    return {
        "mesh": meshes.read_mesh(corpus / "liver.msh"),
        "spheres": meshes.read_spheres(corpus / "liver.sph"),
        "dofs": _states(data / "real_Demos_liver.liver_dofs.csv"),
        "mapped": _states(data / "real_Demos_liver.liver_spheres_mapped.csv"),
    }


def test_liver_spheres_match_sofa(liver: dict) -> None:
    """Demos/liver.scn: TetrahedronSetTopologyContainer -> BarycentricMapperTetrahedronSetTopology.
    The embedding from the rest positions maps SOFA's DOF positions onto SOFA's sphere positions
    (observed: bit for bit)."""
    mesh, dofs, mapped = liver["mesh"], liver["dofs"], liver["mapped"]
    assert np.array_equal(dofs[0], mesh.positions)
    indices, weights = barycentric_map(
        mesh.positions, liver["spheres"].centers, tetrahedra=mesh.tetrahedra, topology="dynamic"
    )
    assert indices.shape == weights.shape == (34, 4)
    assert weights.sum(axis=1) == pytest.approx(1.0, abs=1e-14)
    for step in (0, 99, 100):
        assert set(mapped) == {0, 99, 100}
        ours = apply(indices, weights, dofs[step])
        scale = np.abs(mapped[step]).max()
        assert np.abs(ours - mapped[step]).max() <= 1e-12 * scale, step
    # The static mesh mapper chooses the same elements here.
    static = barycentric_map(mesh.positions, liver["spheres"].centers, tetrahedra=mesh.tetrahedra)
    assert np.array_equal(static[0], indices) and np.array_equal(static[1], weights)


def test_liver_element_choice_matters(liver: dict) -> None:
    """The one sphere centre outside the liver is extrapolated from its element: any other candidate
    element would put it elsewhere once the liver deforms, so the match above proves the choice."""
    mesh, dofs, mapped = liver["mesh"], liver["dofs"], liver["mapped"]
    centres = liver["spheres"].centers
    embedding = barycentric_embedding(mesh.positions, centres, tetrahedra=mesh.tetrahedra, topology="dynamic")
    outside = np.flatnonzero(embedding.weights.min(axis=1) < -1e-9)
    assert len(outside) == 1
    i = int(outside[0])
    p = mesh.positions[mesh.tetrahedra]
    for tet in np.argsort(np.linalg.norm(p.mean(axis=1) - centres[i], axis=1))[:6]:
        if tet == embedding.element[i]:
            continue
        frame = (p[tet, 1:] - p[tet, 0]).T
        f = np.linalg.solve(frame, centres[i] - p[tet, 0])
        w = np.r_[1 - f.sum(), f]
        moved = w @ dofs[100][mesh.tetrahedra[tet]]
        assert np.abs(moved - mapped[100][i]).max() > 1e-5


def _regression_states(shared: Path, scene: str, index: int) -> list[np.ndarray]:
    folder = shared / "reference" / "sofa-regression"
    matches = sorted(folder.glob(f"{scene}.reference_{index}_*_mstate.txt.gz"))
    if not matches:
        pytest.skip(f"SOFA's regression reference for {scene} is not available")
    with gzip.open(matches[0], "rt") as stream:
        lines = [line.split()[1:] for line in stream if line.strip().startswith("X=")]
    return [np.array(line, dtype=float).reshape(-1, 3) for line in lines]


def test_chain_hybrid_grid_and_mesh_mappers_match_sofa(shared_dir: Path) -> None:
    """Demos/chainHybrid.scn, SOFA's regression reference (6 digits, steps 0 and 99): the torus
    collision surfaces mapped from a RegularGridTopology (TorusFFD: the grid's own geometry decides,
    its DOFs are translated by the include's dx) and from a tetrahedral MeshTopology (TorusFEM)."""
    corpus = shared_dir / "corpus" / "sofa" / "mesh"
    surface = meshes.read_mesh(corpus / "torus_for_collision.obj").positions
    # TorusFFD: RegularGridTopology nx=6 ny=2 nz=5, x in [-2.5, 2.5], y in [-0.5, 0.5], z in [-2, 2].
    grid_dofs = _regression_states(shared_dir, "Demos/chainHybrid.scn", 4)
    mapped = _regression_states(shared_dir, "Demos/chainHybrid.scn", 5)
    grid = RegularGrid(n=(6, 2, 5), min=(-2.5, -0.5, -2.0), max=(2.5, 0.5, 2.0))
    assert grid_dofs[0] == pytest.approx(grid.points() + np.array([7.5, 0, 0]), abs=1e-12)
    indices, weights = barycentric_map(grid.points(), surface, grid=grid)
    assert len(grid_dofs) == len(mapped) == 2
    for dofs, expected in zip(grid_dofs, mapped, strict=True):
        assert np.abs(apply(indices, weights, dofs) - expected).max() < 2e-5
    # TorusFEM: MeshTopology of torus_low_res.msh, everything translated by dx=2.5.
    fem = meshes.read_mesh(corpus / "torus_low_res.msh")
    fem_dofs = _regression_states(shared_dir, "Demos/chainHybrid.scn", 0)
    mapped = _regression_states(shared_dir, "Demos/chainHybrid.scn", 1)
    shift = np.array([2.5, 0.0, 0.0])
    indices, weights = barycentric_map(fem.positions + shift, surface + shift, tetrahedra=fem.tetrahedra)
    for dofs, expected in zip(fem_dofs, mapped, strict=True):
        assert np.abs(apply(indices, weights, dofs) - expected).max() < 3e-5


# ---- literal transcriptions of SOFA's loops (slow, independent arithmetic) --------------------------


def _base(points: np.ndarray, element: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    p = points[element]
    if kind == "tetrahedra":
        rows = [p[1] - p[0], p[2] - p[0], p[3] - p[0]]
    elif kind == "hexahedra":
        rows = [p[1] - p[0], p[3] - p[0], p[4] - p[0]]
    elif kind == "triangles":
        rows = [p[1] - p[0], p[2] - p[0], np.cross(p[1] - p[0], p[2] - p[0])]
    else:
        rows = [p[1] - p[0], p[3] - p[0], np.cross(p[1] - p[0], p[3] - p[0])]
    return np.linalg.inv(np.array(rows).T), p.mean(axis=0)


def _distance(kind: str, v: np.ndarray) -> float:
    if kind == "tetrahedra":
        return max(-v[0], -v[1], -v[2], v[0] + v[1] + v[2] - 1)
    if kind == "hexahedra":
        return max(-v[0], -v[1], -v[2], v[0] - 1, v[1] - 1, v[2] - 1)
    if kind == "triangles":
        return max(-v[0], -v[1], abs(v[2]) - 0.01, v[0] + v[1] - 1)
    return max(-v[0], -v[1], v[0] - 1, v[1] - 1, abs(v[2]) - 0.01)


class _Search:
    def __init__(self, points: np.ndarray, elements: list[tuple[str, np.ndarray]]) -> None:
        self.items = [(kind, el, *_base(points, el, kind)) for kind, el in elements]
        self.points = points

    def check(self, e: int, p: np.ndarray, best: list) -> None:
        kind, el, base, centre = self.items[e]
        v = base @ (p - self.points[el[0]])
        d = _distance(kind, v)
        if d > 0:
            d = float(((p - centre) ** 2).sum())
        if d < best[1]:
            best[:] = [e, d, v]


def slow_container(points: np.ndarray, pts: np.ndarray, kind: str, elements: np.ndarray) -> tuple[list, list]:
    """BarycentricMapperTopologyContainer::init, line by line."""
    search = _Search(points, [(kind, el) for el in elements])
    edges = topology_edges(len(points), **{kind: elements})
    size = float(np.mean([np.linalg.norm(points[a] - points[b]) for a, b in edges]))
    conv = 1 / size
    table: dict[tuple[int, int, int], list[int]] = {}
    for e, el in enumerate(elements):
        low = np.floor(points[el].min(axis=0) * conv).astype(int)
        high = np.floor(points[el].max(axis=0) * conv).astype(int)
        for x in range(low[0], high[0] + 1):
            for y in range(low[1], high[1] + 1):
                for z in range(low[2], high[2] + 1):
                    table.setdefault((x, y, z), []).append(e)
    chosen, coords = [], []
    for p in pts:
        key = tuple(np.floor(p * conv).astype(int).tolist())
        best: list = [None, math.inf, None]
        for e in table.get(key, []):
            search.check(e, p, best)
        if best[0] is None:
            for e in range(len(elements)):
                search.check(e, p, best)
        elif abs(best[1]) > size / 2:
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dz in (-1, 0, 1):
                        for e in table.get((key[0] + dx, key[1] + dy, key[2] + dz), []):
                            search.check(e, p, best)
        chosen.append(best[0])
        coords.append(best[2])
    return chosen, coords


def slow_mesh(
    points: np.ndarray, pts: np.ndarray, elements: list[tuple[str, np.ndarray]]
) -> tuple[list, list]:
    """BarycentricMapperMeshTopology::init (3-D or 2-D branch), line by line."""
    search = _Search(points, elements)
    chosen, coords = [], []
    for p in pts:
        best: list = [None, 1e10, None]
        for e in range(len(elements)):
            search.check(e, p, best)
        chosen.append(best[0])
        coords.append(best[2])
    return chosen, coords


@pytest.fixture(params=["brute", "pruned"])
def search(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run a test with the brute-force element search and with the pruned one (forced)."""
    if request.param == "pruned":
        monkeypatch.setattr(barycentric, "_BRUTE_FORCE_PAIRS", 0)
    return request.param


@pytest.mark.parametrize("kind", ["tetrahedra", "hexahedra"])
def test_dynamic_mapper_matches_sofa_loops(kind: str, search: str) -> None:
    points, hexa, tets = block_mesh((4, 3, 3), jitter=0.2 if kind == "tetrahedra" else 0.0, seed=1)
    elements = tets if kind == "tetrahedra" else hexa
    rng = np.random.default_rng(2)
    pts = rng.uniform(-1.5, 5.5, (400, 3))  # many outside the mesh, some far
    embedding = barycentric_embedding(points, pts, topology="dynamic", **{kind: elements})
    chosen, coords = slow_container(points, pts, kind, elements)
    assert embedding.element.tolist() == chosen
    assert embedding.coords == pytest.approx(np.array(coords), rel=1e-9, abs=1e-9)
    assert embedding.weights.sum(axis=1) == pytest.approx(1.0, abs=1e-12)


def test_mesh_mapper_matches_sofa_loops(search: str) -> None:
    points, hexa, tets = block_mesh((3, 3, 2), jitter=0.0, seed=4)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1.0, 4.0, (300, 3))
    # Tetrahedra and hexahedra together (tetrahedra first), as MeshTopology holds them.
    some_tets, some_hexa = tets[: 6 * 8], hexa[8:]
    embedding = barycentric_embedding(points, pts, tetrahedra=some_tets, hexahedra=some_hexa)
    items = [("tetrahedra", t) for t in some_tets] + [("hexahedra", h) for h in some_hexa]
    chosen, coords = slow_mesh(points, pts, items)
    assert embedding.element.tolist() == chosen
    assert embedding.coords == pytest.approx(np.array(coords), rel=1e-9, abs=1e-9)
    assert embedding.indices.shape == (300, 8) and embedding.weights.sum(axis=1) == pytest.approx(1.0)
    # Surfaces: triangles then quads.
    flat_points = points[points[:, 2] == 0]
    quads = np.array([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6]])
    triangles = np.array([[4, 5, 9], [4, 9, 8], [5, 6, 10], [5, 10, 9]])
    pts2 = np.c_[rng.uniform(-0.5, 3.5, (200, 2)), rng.uniform(-0.02, 0.02, 200)]
    embedding = barycentric_embedding(flat_points, pts2, triangles=triangles, quads=quads)
    items = [("triangles", t) for t in triangles] + [("quads", q) for q in quads]
    chosen, coords = slow_mesh(flat_points, pts2, items)
    assert embedding.element.tolist() == chosen
    assert embedding.coords == pytest.approx(np.array(coords)[:, :2], rel=1e-9, abs=1e-9)


# ---- exactness for points inside, weights ---------------------------------------------------------


@pytest.mark.parametrize("topology", ["mesh", "dynamic"])
def test_points_inside_are_reproduced(topology: str) -> None:
    points, hexa, tets = block_mesh((3, 3, 3), jitter=0.15, seed=7)
    rng = np.random.default_rng(8)
    # Points inside: random convex combinations within random tetrahedra.
    chosen = rng.integers(0, len(tets), 200)
    w = rng.dirichlet(np.ones(4), 200)
    pts = np.einsum("nk,nkd->nd", w, points[tets[chosen]])
    indices, weights = barycentric_map(points, pts, tetrahedra=tets, topology=topology)
    assert weights.sum(axis=1) == pytest.approx(1.0, abs=1e-14)
    assert weights.min() >= -1e-12
    assert apply(indices, weights, points) == pytest.approx(pts, abs=1e-13)
    # Extrapolation is exact too for a tetrahedron (affine).
    far = rng.uniform(-2, 5, (50, 3))
    indices, weights = barycentric_map(points, far, tetrahedra=tets, topology=topology)
    assert apply(indices, weights, points) == pytest.approx(far, abs=1e-12)
    # Hexahedra of a (non-jittered) box: trilinear reproduces any point.
    box, hexa, _ = block_mesh((3, 2, 2), jitter=0.0, seed=0)
    box = box * [0.5, 2.0, 1.0] + [1, 2, 3]
    inner = rng.uniform([1, 2, 3], [2.5, 6, 5], (100, 3))
    indices, weights = barycentric_map(box, inner, hexahedra=hexa, topology=topology)
    assert weights.sum(axis=1) == pytest.approx(1.0, abs=1e-14) and weights.min() >= -1e-12
    assert apply(indices, weights, box) == pytest.approx(inner, abs=1e-13)


def test_surfaces_project_onto_the_plane() -> None:
    square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [4, 0, 0], [4, 2, 0]], dtype=float)
    rng = np.random.default_rng(9)
    pts = np.c_[rng.uniform(0, 4, (50, 2)), rng.uniform(-0.005, 0.005, 50)]
    for topology in ("mesh", "dynamic"):
        idx, w = barycentric_map(square, pts, quads=[[0, 1, 2, 3], [1, 4, 5, 2]], topology=topology)
        assert w.shape == (50, 4) and w.sum(axis=1) == pytest.approx(1.0)
        assert apply(idx, w, square) == pytest.approx(np.c_[pts[:, :2], np.zeros(50)], abs=1e-13)
        idx, w = barycentric_map(
            square, pts, triangles=[[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]], topology=topology
        )
        assert w.shape == (50, 3)
        assert apply(idx, w, square) == pytest.approx(np.c_[pts[:, :2], np.zeros(50)], abs=1e-13)
    # An edge-only static mesh: the first edge whose projection falls on it, else the last edge.
    line = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0]], dtype=float)
    embedding = barycentric_embedding(line, [[0.5, 1, 0], [2.0, 0, 1], [5.0, 0, 0]], edges=[[0, 1], [1, 2]])
    assert embedding.element.tolist() == [0, 1, 1]
    assert embedding.coords[:, 0] == pytest.approx([0.5, 0.5, 2.0])


# ---- grids ------------------------------------------------------------------------------------------


def test_regular_grid_finds_cubes_by_arithmetic() -> None:
    grid = RegularGrid(n=(4, 3, 5), min=(-1.0, 0.0, 2.0), max=(2.0, 1.0, 6.0))
    points = grid.points()
    assert points[0] == pytest.approx([-1, 0, 2]) and points[-1] == pytest.approx([2, 1, 6])
    rng = np.random.default_rng(11)
    inside = rng.uniform([-1, 0, 2], [2, 1, 6], (300, 3))
    embedding = barycentric_embedding(points, inside, grid=grid)
    assert embedding.weights.sum(axis=1) == pytest.approx(1.0, abs=1e-14)
    assert apply(embedding.indices, embedding.weights, points) == pytest.approx(inside, abs=1e-13)
    cells = np.floor((inside - [-1, 0, 2]) / [1.0, 0.5, 1.0]).astype(int)
    assert embedding.element.tolist() == (cells[:, 0] + 3 * (cells[:, 1] + 2 * cells[:, 2])).tolist()
    # The same points through the hexahedron container mapper land in the same cubes.
    other = barycentric_embedding(points, inside, hexahedra=grid.hexahedra(), topology="dynamic")
    assert apply(other.indices, other.weights, points) == pytest.approx(inside, abs=1e-13)
    # Outside: the clamped nearest cube, coordinates outside [0, 1], still exact (trilinear on a box).
    outside = np.array([[-2.0, 0.5, 3.0], [2.5, 1.5, 7.0]])
    embedding = barycentric_embedding(points, outside, grid=grid)
    assert embedding.element.tolist() == [0 + 3 * (1 + 2 * 1), 2 + 3 * (1 + 2 * 3)]
    assert embedding.coords[0, 0] == pytest.approx(-1.0) and embedding.notes
    assert apply(embedding.indices, embedding.weights, points) == pytest.approx(outside, abs=1e-13)
    # The grid's geometry, not the input positions, decides (SOFA ignores the input state here).
    assert np.array_equal(
        barycentric_map(points + 100, inside, grid=grid)[1], barycentric_map(points, inside, grid=grid)[1]
    )
    # cellWidth recomputes n; p0 moves the grid.
    assert RegularGrid(n=(2, 2, 2), max=(1.0, 1.0, 0.5), cell_width=0.25).resolution() == (5, 5, 3)
    shifted = RegularGrid(n=(2, 2, 2), p0=(10.0, 0.0, 0.0))
    coords = barycentric_embedding(shifted.points(), [[10.5, 0.5, 0.5]], grid=shifted).coords
    assert coords == pytest.approx(np.full((1, 3), 0.5))
    with pytest.raises(ValueError, match="no hexahedra"):
        barycentric_map(points, inside, grid=RegularGrid(n=(4, 3, 1)))


def test_sparse_grid() -> None:
    regular = RegularGrid(n=(3, 3, 3), min=(0.0, 0.0, 0.0), max=(2.0, 2.0, 2.0))
    points = regular.points()
    keep = np.arange(8) != 7  # the cube at (1, 1, 1) is not part of the sparse grid
    hexahedra = regular.hexahedra()[keep]
    table = np.where(keep, np.cumsum(keep) - 1, -1)
    grid = SparseGrid(regular, points, hexahedra, table, boundary=np.ones(7, dtype=bool))
    inside = np.array([[0.5, 0.5, 0.5], [1.5, 0.25, 1.75]])
    embedding = barycentric_embedding(points, inside, grid=grid)
    assert embedding.element.tolist() == [0, 5]
    assert apply(embedding.indices, embedding.weights, points) == pytest.approx(inside)
    # A point in the missing cube goes to the boundary cube of nearest centre, extrapolated.
    missing = np.array([[1.9, 1.6, 1.2]])
    embedding = barycentric_embedding(points, missing, grid=grid)
    centres = (points[hexahedra[:, 0]] + points[hexahedra[:, 6]]) / 2
    assert embedding.element[0] == int(np.argmin(np.linalg.norm(centres - missing, axis=1)))
    assert apply(embedding.indices, embedding.weights, points) == pytest.approx(missing)


def test_degenerate_elements_behave_as_in_sofa(search: str) -> None:
    """A flat tetrahedron: SOFA's inversion fails. The static mesh mapper keeps a zero frame, so the
    element is at distance 0 from every point and captures every point inside no other element
    (weight 1 on its first node); the dynamic mapper keeps the raw frame instead."""
    points, _, tets = block_mesh((2, 2, 2), jitter=0.1, seed=40)
    flat = np.array([[0, 1, 2, 2]])
    elements = np.vstack([tets[:5], flat, tets[5:]])
    rng = np.random.default_rng(41)
    inside_some = np.einsum(
        "nk,nkd->nd", rng.dirichlet(np.ones(4), 20), points[tets[rng.integers(0, 48, 20)]]
    )
    far = rng.uniform(3, 4, (10, 3))
    embedding = barycentric_embedding(points, np.vstack([inside_some, far]), tetrahedra=elements)
    assert embedding.notes and (embedding.element[20:] == 5).all()
    assert embedding.indices[20:, 0].tolist() == [0] * 10 and embedding.weights[20:, 0] == pytest.approx(1.0)
    assert apply(embedding.indices[:20], embedding.weights[:20], points) == pytest.approx(
        inside_some, abs=1e-12
    )
    dynamic = barycentric_embedding(
        points, np.vstack([inside_some, far]), tetrahedra=elements, topology="dynamic"
    )
    assert dynamic.notes and apply(dynamic.indices[:20], dynamic.weights[:20], points) == pytest.approx(
        inside_some
    )


# ---- errors and speed ----------------------------------------------------------------------------------


def test_errors() -> None:
    points, _, tets = block_mesh((1, 1, 1), jitter=0.0, seed=0)
    with pytest.raises(ValueError, match="no elements"):
        barycentric_map(points, [[0.5, 0.5, 0.5]])
    with pytest.raises(ValueError, match="edge-set"):
        barycentric_map(points, [[0.5, 0.5, 0.5]], edges=[[0, 1]], topology="dynamic")
    with pytest.raises(ValueError, match="topology must be"):
        barycentric_map(points, [[0.5, 0.5, 0.5]], tetrahedra=tets, topology="static")
    with pytest.raises(ValueError, match="shape"):
        barycentric_map(points[:, :2], [[0.5, 0.5, 0.5]], tetrahedra=tets)
    with pytest.raises(ValueError, match="out of range"):
        barycentric_map(points, [[0.5, 0.5, 0.5]], tetrahedra=tets + 1)
    with pytest.raises(ValueError, match="too far"):
        barycentric_map(points, [[1e6, 0, 0]], tetrahedra=tets)
    with pytest.raises(TypeError):
        barycentric_map(points, [[0.5, 0.5, 0.5]], grid=(2, 2, 2))  # type: ignore[arg-type]
    # Empty output: nothing to map.
    indices, weights = barycentric_map(points, np.zeros((0, 3)), tetrahedra=tets, topology="dynamic")
    assert indices.shape == (0, 4) and weights.shape == (0, 4)


def test_mapper_for_topology_classes() -> None:
    from sofac.registry import lookup

    def mapper(name: str) -> str:
        resolution = lookup(name)
        return mapper_for(resolution.spec.variant if resolution is not None else None)

    assert mapper("TetrahedronSetTopologyContainer") == "dynamic"
    assert mapper("HexahedronSetTopologyContainer") == "dynamic"
    assert mapper("MeshTopology") == "mesh" and mapper("GridTopology") == "mesh"
    assert mapper("RegularGridTopology") == "regular_grid"
    assert mapper("SparseGridTopology") == "sparse_grid"


def test_liver_sized_meshes_are_fast() -> None:
    points, _, tets = block_mesh((6, 6, 5), jitter=0.2, seed=12)  # 1080 tetrahedra
    rng = np.random.default_rng(13)
    pts = rng.uniform(-0.5, 6.5, (1000, 3))
    start = time.perf_counter()
    barycentric_map(points, pts, tetrahedra=tets, topology="dynamic")
    barycentric_map(points, pts, tetrahedra=tets)
    assert time.perf_counter() - start < 3.0


# ---- C++ kernels (runtime/sofac/mapping.h) --------------------------------------------------------------

SHIM = r"""
#include "sofac/mapping.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
API void apply(const double* in, double* out, const Index* idx, const double* w, Index n, int k, int width) {
    sofac::linear_map_apply(in, out, idx, w, n, k, width);
}
API void apply_jt(double* in_f, const double* out_f, const Index* idx, const double* w, Index n, int k,
              int width) {
    sofac::linear_map_apply_jt(in_f, out_f, idx, w, n, k, width);
}
API void mmm(double* df, const double* dx, const double* vm, Index n, const Index* edges, const double* em,
             Index ne, double factor, int width) {
    sofac::mesh_matrix_mass_multiply(df, dx, vm, n, edges, em, ne, factor, width);
}
API void mmm_lumped(double* df, const double* dx, const double* vm, Index n, double lumping, double factor,
                    int width) {
    sofac::mesh_matrix_mass_multiply_lumped(df, dx, vm, n, lumping, factor, width);
}
API void mmm_gravity(double* f, const double* vm, Index n, double lumping, const double* g, int width) {
    sofac::mesh_matrix_mass_gravity(f, vm, n, lumping, g, width);
}
API double mmm_energy(const double* v, const double* vm, Index n, const Index* edges, const double* em,
                      Index ne, int lumped, double lumping, int width) {
    return sofac::mesh_matrix_mass_kinetic_energy(v, vm, n, edges, em, ne, lumped != 0, lumping, width);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "mapping", SHIM)
    library.mmm_energy.restype = ctypes.c_double
    for name in ("apply", "apply_jt"):
        getattr(library, name).argtypes = [D, D, I64, D, ctypes.c_int64, ctypes.c_int, ctypes.c_int]
    library.mmm.argtypes = [D, D, D, ctypes.c_int64, I64, D, ctypes.c_int64, ctypes.c_double, ctypes.c_int]
    library.mmm_lumped.argtypes = [D, D, D, ctypes.c_int64, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    library.mmm_gravity.argtypes = [D, D, ctypes.c_int64, ctypes.c_double, D, ctypes.c_int]
    library.mmm_energy.argtypes = [
        D,
        D,
        ctypes.c_int64,
        I64,
        D,
        ctypes.c_int64,
        ctypes.c_int,
        ctypes.c_double,
    ]
    library.mmm_energy.argtypes += [ctypes.c_int]
    return library


def test_kernel_maps_the_liver_like_sofa(lib: ctypes.CDLL, liver: dict) -> None:
    mesh, dofs, mapped = liver["mesh"], liver["dofs"], liver["mapped"]
    indices, weights = barycentric_map(
        mesh.positions, liver["spheres"].centers, tetrahedra=mesh.tetrahedra, topology="dynamic"
    )
    n, k = indices.shape
    for step in (0, 99, 100):
        x = np.ascontiguousarray(dofs[step])
        out = np.full((n, 3), np.nan)
        lib.apply(_d(x), _d(out), _i(indices), _d(weights), n, k, 3)
        assert np.array_equal(out, apply(indices, weights, x))
        assert np.abs(out - mapped[step]).max() <= 1e-12 * np.abs(mapped[step]).max()


def test_kernel_jt_is_the_transpose(lib: ctypes.CDLL) -> None:
    points, _, tets = block_mesh((2, 2, 2), jitter=0.1, seed=20)
    rng = np.random.default_rng(21)
    pts = rng.uniform(-0.5, 2.5, (40, 3))
    indices, weights = barycentric_map(points, pts, tetrahedra=tets, topology="dynamic")
    n, k = indices.shape
    for width in (1, 3):
        f_out = rng.normal(size=(n, width))
        f_in = rng.normal(size=(len(points), width))
        expected = f_in.copy()
        np.add.at(expected, indices.ravel(), np.repeat(f_out, k, axis=0) * weights.reshape(-1, 1))
        lib.apply_jt(_d(f_in), _d(f_out), _i(indices), _d(weights), n, k, width)
        assert f_in == pytest.approx(expected, rel=1e-14, abs=1e-14)
        # <J x, f> == <x, J^T f>
        x = rng.normal(size=(len(points), width))
        jx = np.zeros((n, width))
        lib.apply(_d(x), _d(jx), _i(indices), _d(weights), n, k, width)
        jtf = np.zeros((len(points), width))
        lib.apply_jt(_d(jtf), _d(f_out), _i(indices), _d(weights), n, k, width)
        assert (jx * f_out).sum() == pytest.approx((x * jtf).sum(), rel=1e-12)


def test_kernel_mesh_matrix_mass(lib: ctypes.CDLL) -> None:
    points, _, tets = block_mesh((2, 2, 1), jitter=0.1, seed=30)
    data = mesh_matrix_mass(points, tetrahedra=tets, mass_density=3.0)
    rng = np.random.default_rng(31)
    n = len(points)
    dx = rng.normal(size=(n, 3))
    df = np.zeros((n, 3))
    edges = np.ascontiguousarray(data.edges)
    lib.mmm(_d(df), _d(dx), _d(data.vertex_mass), n, _i(edges), _d(data.edge_mass), len(edges), -0.7, 3)
    assert np.array_equal(
        df, mesh_matrix_mass_multiply(data.vertex_mass, edges, data.edge_mass, dx, factor=-0.7)
    )
    lumped = np.zeros((n, 3))
    lib.mmm_lumped(_d(lumped), _d(dx), _d(data.vertex_mass), n, data.lumping_coefficient, 2.0, 3)
    assert lumped == pytest.approx(2.0 * dx * data.lumped_vertex_mass[:, None], rel=1e-15)
    f = np.zeros((n, 3))
    g = np.array([0.0, -9.81, 0.0])
    lib.mmm_gravity(_d(f), _d(data.vertex_mass), n, data.lumping_coefficient, _d(g), 3)
    assert f.sum(axis=0) == pytest.approx(g * data.total_mass, rel=1e-13)
    v = rng.normal(size=(n, 3))
    energy = lib.mmm_energy(
        _d(v), _d(data.vertex_mass), n, _i(edges), _d(data.edge_mass), len(edges), 0, 2.5, 3
    )
    assert energy == pytest.approx(0.5 * (v * data.multiply(v)).sum(), rel=1e-13)
    lumped_energy = lib.mmm_energy(
        _d(v), _d(data.vertex_mass), n, _i(edges), _d(data.edge_mass), 0, 1, 2.5, 3
    )
    assert lumped_energy == pytest.approx(0.5 * (v * v * data.lumped_vertex_mass[:, None]).sum(), rel=1e-13)
