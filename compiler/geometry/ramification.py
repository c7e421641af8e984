"""SparseGridRamificationTopology, as SOFA builds it at init: a sparse grid (see voxelize.py) whose
cells are duplicated where the surface inside a cell falls apart into disconnected pieces.

1. The finest grid: the voxelised sparse grid at ``n``, or, with ``nbVirtualFinerLevels`` k, at
   n -> 2n - 1 applied k times (a virtual level, min/max as given). Each of its cubes is one
   *connexion*; two face-adjacent cubes are connected unless ``finestConnectivity`` asks to test
   it and both are BOUNDARY: then they are connected only if an edge (j-1, j) of a surface facet
   crosses their common face (sharingTriangle, intersectionSegmentTriangle; SOFA's test takes the
   edge's start as the centre of a segment of half-length |edge|: reproduced).
2. With ``finestConnectivity`` the finest grid is the topology itself: buildRamifiedFinestLevel
   gives each cube its own 8 points and merges the points of connected faces.
3. Each coarser level (n -> n // 2 + 1, up to the scene's grid; buildFromFiner, the x index
   outermost): a coarse cube holds the connexions of its 8 children; each connected component of
   them (neighbours inside the coarse cube) is one coarse connexion, i.e. one hexahedron; coarse
   connexions are neighbours when two of their fine connexions are. Points are merged across the
   faces of neighbouring connexions, then numbered in order of first use.
4. Mass and stiffness coefficients: 0.5 (fillWeighted) or 1 per finest BOUNDARY cube, 1 inside;
   a coarse hexahedron sums its children's and divides by 8, in single precision.

SOFA's own index mix-ups are reproduced because its results depend on them: a coarse level reads
the finer level's types and coefficients at the finer *unramified* cube index; the children of a
duplicated cube keep only its last child; a finest level ramified in place keeps the coefficients
(and findCube's table) of its unramified cubes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sofac.geometry import voxelize
from sofac.geometry.barycentric import RegularGrid

UP, DOWN, RIGHT, LEFT, BEFORE, BEHIND = range(6)  # SparseGridTopology's neighbour directions
_CORNERS = np.asarray(voxelize._CORNERS, dtype=np.int64)
# Corner pairs merged across a face with the neighbour BEFORE (z - 1), DOWN (y - 1), LEFT (x - 1):
# (this hexahedron's corner, the neighbour's corner), in SOFA's order.
_FACE_PAIRS = (
    (BEFORE, ((0, 4), (1, 5), (2, 6), (3, 7))),
    (DOWN, ((0, 3), (4, 7), (5, 6), (1, 2))),
    (LEFT, ((0, 1), (4, 5), (7, 6), (3, 2))),
)
# The shared face of a cube with its neighbour in each direction (sharingTriangle's a b c d).
_FACES = {LEFT: (0, 4, 7, 3), DOWN: (0, 1, 5, 4), BEFORE: (0, 1, 2, 3)}


def _opposite(direction: int) -> int:
    return direction + 1 if direction % 2 == 0 else direction - 1


@dataclass(eq=False)
class Connexion:
    """One connected piece of a cube. ``uid`` orders the neighbour sets as SOFA's std::set of
    pointers does (allocation order)."""

    uid: int
    neighbors: list[set[Connexion]] = field(default_factory=lambda: [set() for _ in range(6)])
    children: list[tuple[int, Connexion]] = field(default_factory=list)  # (place 0-7, fine connexion)
    parent: Connexion | None = None
    hexa: int = 0  # index of its hexahedron in its level
    unramified: int = 0  # index of its cube in its level's unramified list
    cube: int = 0  # (coarse levels) the unramified cube holding it

    def sorted_neighbors(self, direction: int) -> list[Connexion]:
        return sorted(self.neighbors[direction], key=lambda c: c.uid)


@dataclass(eq=False)
class Level:
    """One level of the hierarchy: its regular grid, each regular cube's unramified index (or -1),
    per unramified cube its connexions, per hexahedron (as SOFA indexes them) the type flag and
    coefficient, and (when built) the hexahedra and points."""

    grid: RegularGrid
    regular_to_cube: np.ndarray
    connexions: list[list[Connexion]]
    boundary: np.ndarray  # SOFA's _types == BOUNDARY, by its own (sometimes mixed) index
    coefficients: np.ndarray  # float32 mass = stiffness coefficients
    hexahedra: np.ndarray | None = None
    points: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class RamifiedGrid:
    """The topology: ``points`` (p, 3) and ``hexahedra`` (m, 8); ``coefficients`` (m,) (SOFA's
    getMassCoef = getStiffnessCoef); ``finest`` the grid findCube starts from and
    ``finest_to_hexa`` each of its regular cubes' hexahedron (or -1); ``coarse`` the grid whose
    cubes give the barycentric fractions; ``boundary`` each hexahedron's BOUNDARY flag."""

    points: np.ndarray
    hexahedra: np.ndarray
    coefficients: np.ndarray
    boundary: np.ndarray
    coarse: RegularGrid
    finest: RegularGrid
    finest_to_hexa: np.ndarray
    levels: int


class _Counter:
    def __init__(self) -> None:
        self.next = 0

    def new(self) -> Connexion:
        self.next += 1
        return Connexion(self.next)


# ---- the finest level ---------------------------------------------------------------------------


def _segments_cross_triangle(
    s0: np.ndarray, s1: np.ndarray, t0: np.ndarray, t1: np.ndarray, t2: np.ndarray
) -> np.ndarray:
    """intersectionSegmentTriangle for many segments (s0, s1: (m, 3)) against one triangle."""

    def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]

    def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.stack(
            [
                a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
            ],
            axis=-1,
        )

    diff = s0 - t0
    edge1, edge2 = t1 - t0, t2 - t0
    normal = cross(edge1, edge2)
    direction = s1 - s0
    norm = np.sqrt(dot(direction, direction))
    with np.errstate(divide="ignore", invalid="ignore"):
        direction = direction / norm[:, None]
        along = dot(direction, normal)
        sign = np.where(along > 1.0e-10, 1.0, np.where(along < -1.0e-10, -1.0, 0.0))
        along = np.abs(along)
        first = sign * dot(direction, cross(diff, edge2))
        second = sign * dot(direction, cross(edge1, diff))
        height = -sign * dot(diff, normal)
        reach = norm * along
        return (
            (sign != 0)
            & (first >= 0.0)
            & (second >= 0.0)
            & (first + second <= along)
            & (-reach <= height)
            & (height <= reach)
        )


def _faces_crossed(corners: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> bool:
    """sharingTriangle's test: does a facet edge cross the face a b c d (as triangles abc, acd)?"""
    a, b, c, d = corners
    return bool(
        _segments_cross_triangle(starts, ends, a, b, c).any()
        or _segments_cross_triangle(starts, ends, a, c, d).any()
    )


def _finest_level(
    grid: RegularGrid,
    vertices: np.ndarray,
    facets: np.ndarray,
    facet_edges: np.ndarray,
    *,
    connectivity: bool,
    fill_weighted: bool,
    only_inside: bool,
    counter: _Counter,
) -> tuple[Level, voxelize.SparseGrid]:
    """buildAsFinest then findConnexionsAtFinestLevel: the voxelised grid (of ``facets``, triangles),
    one connexion per cube, joined across faces (tested against ``facet_edges``)."""
    voxels = voxelize.classify(grid, vertices, facets)
    sparse = voxelize.sparse_grid(voxels, only_inside=only_inside)
    count = len(sparse.hexahedra)
    boundary = np.asarray(sparse.boundary, dtype=bool)
    coefficients = np.where(boundary & fill_weighted, np.float32(0.5), np.float32(1.0)).astype(np.float32)
    connexions = [[counter.new()] for _ in range(count)]
    nx, ny, nz = (c - 1 for c in grid.resolution())
    table = np.asarray(sparse.regular_to_sparse, dtype=np.int64)
    starts, ends = vertices[facet_edges[:, 0]], vertices[facet_edges[:, 1]]

    def connected(cube: int, neighbour: int, where: int) -> bool:
        if not connectivity or not (boundary[cube] and boundary[neighbour]):
            return True
        corners = sparse.points[sparse.hexahedra[cube][list(_FACES[where])]]
        return _faces_crossed(corners, starts, ends)

    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                cube = int(table[x + nx * (y + ny * z)])
                if cube < 0:
                    continue
                here = connexions[cube][0]
                for where, (dx, dy, dz), back in (
                    (LEFT, (1, 0, 0), RIGHT),
                    (DOWN, (0, 1, 0), UP),
                    (BEFORE, (0, 0, 1), BEHIND),
                ):
                    px, py, pz = x - dx, y - dy, z - dz
                    if px < 0 or py < 0 or pz < 0:
                        continue
                    other = int(table[px + nx * (py + ny * pz)])
                    if other >= 0 and connected(cube, other, where):
                        neighbour = connexions[other][0]
                        here.neighbors[where].add(neighbour)
                        neighbour.neighbors[back].add(here)
    for index, (connexion,) in enumerate(connexions):
        connexion.hexa = connexion.unramified = index
    return Level(grid, table, connexions, boundary, coefficients), sparse


# ---- merging the points of neighbouring connexions ----------------------------------------------


def _merge_points(connexions: list[list[Connexion]], corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hexahedra and points of a level whose connexions know their neighbours: 8 fresh points
    per connexion, SOFA's changeIndices across each BEFORE, DOWN and LEFT face, then the used
    labels renumbered in order, each placed at the corner of the first hexahedron using it.
    ``corners`` (cubes, 8, 3): each unramified cube's corner positions."""
    ordered = [c for cube in connexions for c in cube]
    hexahedra = np.arange(8 * len(ordered), dtype=np.int64).reshape(-1, 8)
    for index, connexion in enumerate(ordered):
        connexion.hexa = index
    for connexion in ordered:
        row = hexahedra[connexion.hexa]
        for direction, pairs in _FACE_PAIRS:
            for neighbour in connexion.sorted_neighbors(direction):
                other = hexahedra[neighbour.hexa]
                for mine, theirs in pairs:
                    old, new = int(row[mine]), int(other[theirs])
                    hit = hexahedra == old  # changeIndices: the first corner of each hexahedron
                    rows = np.flatnonzero(hit.any(axis=1))
                    hexahedra[rows, hit[rows].argmax(axis=1)] = new
    cube_of = np.asarray([c.unramified for c in ordered], dtype=np.int64)
    labels = hexahedra.ravel()
    used, first = np.unique(labels, return_index=True)
    renumbered = np.searchsorted(used, labels).reshape(hexahedra.shape)
    hexa_of, corner_of = np.divmod(first, 8)
    points = corners[cube_of[hexa_of], corner_of]
    return renumbered, points


def _cube_corners(grid: RegularGrid, cubes: np.ndarray) -> np.ndarray:
    """(m, 8, 3) corner positions of regular cubes (x, y, z index triples), as getPoint."""
    origin, step = grid.frame()
    return origin + step * (cubes[:, None, :] + _CORNERS[None]).astype(np.float64)


# ---- a coarser level ----------------------------------------------------------------------------


def _coarser_grid(finer: RegularGrid) -> RegularGrid:
    """buildFromFiner's grid: n // 2 + 1 points per axis from the same min, max = min + (n - 1) 2 dx."""
    n = tuple(c // 2 + 1 for c in finer.resolution())
    _, step = finer.frame()
    low = tuple(float(v) for v in finer.min)
    high = tuple(low[a] + (n[a] - 1) * 2.0 * float(step[a]) for a in range(3))
    return RegularGrid((n[0], n[1], n[2]), low, (high[0], high[1], high[2]))


def _coarser_level(finer: Level, counter: _Counter, *, build_points: bool) -> Level:
    grid = _coarser_grid(finer.grid)
    cx, cy, cz = (c - 1 for c in grid.resolution())
    fx, fy, fz = (c - 1 for c in finer.grid.resolution())
    table = np.full(cx * cy * cz, -1, dtype=np.int64)
    children: list[list[int]] = []
    inside_flags: list[bool] = []
    cubes: list[tuple[int, int, int]] = []
    for i in range(cx):
        for j in range(cy):
            for k in range(cz):
                fine = []
                for place in range(8):
                    x, y, z = 2 * i + (place & 1), 2 * j + (place & 2) // 2, 2 * k + (place & 4) // 4
                    inside_grid = x < fx and y < fy and z < fz
                    fine.append(int(finer.regular_to_cube[x + fx * (y + fy * z)]) if inside_grid else -1)
                inside = outside = True
                for child in fine:
                    if not (inside or outside):
                        break
                    if child < 0:
                        inside = False
                    elif finer.boundary[child]:  # the finer type at the unramified index, as SOFA
                        inside = outside = False
                    else:
                        outside = False
                if outside:
                    continue
                inside_flags.append(inside)
                table[i + cx * (j + cy * k)] = len(cubes)
                cubes.append((i, j, k))
                children.append(fine)
    connexions: list[list[Connexion]] = []
    for index, fine in enumerate(children):
        members: list[tuple[int, Connexion]] = [
            (place, c) for place, child in enumerate(fine) if child >= 0 for c in finer.connexions[child]
        ]
        position = {id(c): n for n, (_, c) in enumerate(members)}
        label = [-1] * len(members)
        for start in range(len(members)):  # propagateConnexionNumberToNeighbors
            if label[start] != -1:
                continue
            stack = [start]
            while stack:
                n = stack.pop()
                if label[n] != -1:
                    continue
                label[n] = start
                for direction in range(6):
                    for other in members[n][1].neighbors[direction]:
                        m = position.get(id(other))
                        if m is not None and label[m] == -1:
                            stack.append(m)
        pieces = []
        for piece in sorted(set(label)):
            coarse = counter.new()
            coarse.cube = coarse.unramified = index
            for n, (place, fine_connexion) in enumerate(members):
                if label[n] == piece:
                    coarse.children.append((place, fine_connexion))
                    fine_connexion.parent = coarse
            pieces.append(coarse)
        connexions.append(pieces)
    for cube in finer.connexions:
        for fine_connexion in cube:
            mine = fine_connexion.parent
            assert mine is not None
            for direction in range(6):
                for other in fine_connexion.neighbors[direction]:
                    theirs = other.parent
                    assert theirs is not None
                    if mine.cube != theirs.cube:
                        mine.neighbors[direction].add(theirs)
                        theirs.neighbors[_opposite(direction)].add(mine)
    cube_array = np.asarray(cubes, dtype=np.int64).reshape(-1, 3)
    level = Level(grid, table, connexions, np.zeros(0, dtype=bool), np.zeros(0, dtype=np.float32))
    if build_points:
        level.hexahedra, level.points = _merge_points(connexions, _cube_corners(grid, cube_array))
    else:
        for index, connexion in enumerate(c for cube in connexions for c in cube):
            connexion.hexa = index
    # _hierarchicalCubeMap and _types, then the coefficients from the finer level's
    boundary: list[bool] = []
    coefficients: list[np.float32] = []
    for index, pieces in enumerate(connexions):
        if len(pieces) == 1:
            rows = [children[index]]  # unramified children: finer unramified indices
            boundary.append(not inside_flags[index])
        else:
            rows = []
            for piece in pieces:
                row = [-1] * 8
                for _, child in piece.children:  # each child overwrites the row: the last one stays
                    row = [child.hexa if child.unramified == children[index][p] else -1 for p in range(8)]
                rows.append(row)
                boundary.append(True)
        for row in rows:
            total = np.float32(0.0)
            for child in row:
                if child >= 0:
                    total = np.float32(total + finer.coefficients[child])
            coefficients.append(np.float32(total / np.float32(8.0)))
    level.boundary = np.asarray(boundary, dtype=bool)
    level.coefficients = np.asarray(coefficients, dtype=np.float32)
    return level


# ---- the whole hierarchy ------------------------------------------------------------------------


def ramified_grid(
    vertices: np.ndarray,
    triangles: np.ndarray,
    n: tuple[int, int, int],
    low: tuple[float, float, float] = (0.0, 0.0, 0.0),
    high: tuple[float, float, float] = (0.0, 0.0, 0.0),
    *,
    virtual_levels: int = 0,
    finest_connectivity: bool = True,
    fill_weighted: bool = True,
    only_inside: bool = False,
    cell_width: float = 0.0,
    quads: np.ndarray | None = None,
) -> RamifiedGrid:
    """SparseGridRamificationTopology::init on a surface of ``triangles`` (t, 3) and ``quads``
    (q, 4), corners in the file's order: the voxeliser splits quads (0 1 2) (0 2 3);
    sharingTriangle walks each facet's edges (j - 1, j), j = 1 .. corners - 1."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    quads = (
        np.zeros((0, 4), dtype=np.int64)
        if quads is None
        else np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    )
    facet_edges = np.concatenate(
        [triangles[:, [0, 1]], triangles[:, [1, 2]], quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]]]
    )
    facets = voxelize.triangulate(triangles, quads)
    counts = [max(int(c), 2) for c in n]
    for _ in range(virtual_levels):
        counts = [(c - 1) * 2 + 1 for c in counts]
    counter = _Counter()
    # the virtual finest level gets n, min and max, not cellWidth (SOFA then ignores it)
    finest_grid = voxelize.regular_grid(
        vertices, (counts[0], counts[1], counts[2]), low, high, 0.0 if virtual_levels else cell_width
    )
    level, sparse = _finest_level(
        finest_grid,
        vertices,
        facets,
        facet_edges,
        connectivity=finest_connectivity,
        fill_weighted=fill_weighted,
        only_inside=only_inside and not virtual_levels,  # virtual levels keep the default
        counter=counter,
    )
    if not len(sparse.hexahedra):
        raise voxelize.VoxelError("the surface encloses no cell of the grid")
    finest = level
    if virtual_levels == 0:
        if finest_connectivity:
            cubes = sparse.points[sparse.hexahedra]  # (m, 8, 3) each cube's corners
            hexahedra, points = _merge_points(level.connexions, cubes)
        else:
            hexahedra, points = sparse.hexahedra, sparse.points
        # SOFA keeps the unramified coefficients and findCube table: hexahedron i reads cube i's
        if len(hexahedra) > len(level.coefficients):
            raise voxelize.VoxelError(
                f"the ramified grid has {len(hexahedra)} hexahedra for {len(level.coefficients)} cubes: "
                "SOFA reads their coefficients out of bounds; raise n or use nbVirtualFinerLevels",
                "finestConnectivity",
            )
        return RamifiedGrid(
            points,
            hexahedra,
            level.coefficients[: len(hexahedra)],
            level.boundary[: len(hexahedra)],
            level.grid,
            level.grid,
            level.regular_to_cube,
            0,
        )
    for step in range(virtual_levels):
        level = _coarser_level(level, counter, build_points=step == virtual_levels - 1)
    assert level.hexahedra is not None and level.points is not None
    # findCoarsestParents: each finest cube's first connexion, up to the top level
    finest_to_hexa = np.full(len(finest.regular_to_cube), -1, dtype=np.int64)
    for regular, cube in enumerate(finest.regular_to_cube):
        if cube >= 0:
            top = finest.connexions[int(cube)][0]
            while top.parent is not None:
                top = top.parent
            finest_to_hexa[regular] = top.hexa
    return RamifiedGrid(
        level.points,
        level.hexahedra,
        level.coefficients,
        level.boundary,
        level.grid,
        finest.grid,
        finest_to_hexa,
        virtual_levels,
    )
