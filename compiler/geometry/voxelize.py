"""SparseGridTopology built from a closed triangle surface, as SOFA's SparseGridTopology::buildAsFinest.

1. The regular grid: ``n`` points per axis (at least 2) between ``min`` and ``max``; when both are 0
   the surface's bounding box grown by 1 % of its size on each side; ``cellWidth`` > 0 recomputes
   ``n`` as ceil(size / width) + 1.
2. Every cube is INSIDE at first. A cube holding a surface vertex, or cut by a triangle (Green and
   Hatch's polygon-cube test, in single precision, on the triangle scaled to the unit cube), is
   BOUNDARY. The non-BOUNDARY cubes reachable (6-neighbours) from a cube on the grid's border are
   OUTSIDE; the rest stay INSIDE.
3. The sparse grid: the BOUNDARY cubes in regular-grid order, then the INSIDE ones; its points are
   their distinct corners in lexicographic (x, y, z) order (SOFA's std::map<Vec3, index>); each
   hexahedron lists its corners in the grid's order (0,0,0) (1,0,0) (1,1,0) (0,1,0) then z + 1.

Every operation keeps SOFA's precision (double for positions, float where SOFA uses float), so the
point count, order and coordinates are SOFA's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from sofac.geometry.barycentric import RegularGrid, SparseGrid

OUTSIDE, INSIDE, BOUNDARY = 0, 1, 2
_F32 = np.float32
_FLOAT_EPSILON = float(np.finfo(np.float32).eps)
_CANDIDATES = 1 << 20  # (triangle, cube) pairs tested at once
MAX_CUBES = 20_000_000  # regular-grid cells sofac agrees to classify
_CORNERS = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))


class VoxelError(ValueError):
    """The surface cannot be voxelised as SOFA would (a vertex outside the grid, an empty mesh, a
    grid out of range); ``attribute`` names the field to fix."""

    def __init__(self, message: str, attribute: str = "filename") -> None:
        super().__init__(message)
        self.attribute = attribute


@dataclass(frozen=True, eq=False)
class Voxels:
    """The regular grid and the type (OUTSIDE, INSIDE, BOUNDARY) of each of its cubes."""

    grid: RegularGrid
    types: np.ndarray


def regular_grid(
    vertices: np.ndarray,
    n: tuple[int, int, int],
    low: tuple[float, float, float] = (0.0, 0.0, 0.0),
    high: tuple[float, float, float] = (0.0, 0.0, 0.0),
    cell_width: float = 0.0,
) -> RegularGrid:
    """SparseGridTopology::init then buildFromTriangleMesh: the regular grid around the surface."""
    if not np.isfinite(vertices).all():
        raise VoxelError("the surface has a non-finite vertex coordinate")
    counts = tuple(max(int(c), 2) for c in n)  # init: at least 2 points per axis
    lo = np.asarray(low, dtype=np.float64)
    hi = np.asarray(high, dtype=np.float64)
    if (np.abs(lo) < 1e-6).all() and (np.abs(hi) < 1e-6).all():  # Vec3 == Vec3() (1e-6 tolerance)
        if not len(vertices):
            raise VoxelError("the surface has no vertices")
        smallest, largest = vertices.min(axis=0), vertices.max(axis=0)
        grow = (largest - smallest) / 100.0
        lo, hi = smallest - grow, largest + grow
    if cell_width:
        counts = tuple(math.ceil((hi[a] - lo[a]) / cell_width) + 1 for a in range(3))
    nx, ny, nz = (int(c) for c in counts)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (lo == hi).any():
        raise VoxelError(
            f"the grid's box {lo.tolist()} - {hi.tolist()} is empty or not finite; fix min/max", "min"
        )
    cubes = max(nx - 1, 1) * max(ny - 1, 1) * max(nz - 1, 1)
    if min(nx, ny, nz) < 2 or cubes > MAX_CUBES:
        raise VoxelError(
            f"a grid of {nx} x {ny} x {nz} points ({cubes} cells) is out of range (2 to {MAX_CUBES} "
            "cells); lower n or raise cellWidth",
            "cellWidth" if cell_width else "n",
        )
    return RegularGrid(
        (nx, ny, nz), (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))
    )


def _cube_of(grid: RegularGrid, points: np.ndarray) -> np.ndarray:
    """RegularGridTopology::findCube: (n, 3) cube coordinates, -1 rows where outside the grid."""
    n = np.asarray(grid.resolution(), dtype=np.int64)
    origin, step = grid.frame()
    x = ((points - origin) * step) * (1.0 / (step * step))  # p.dx * inv_dx2, dx = (step_x, 0, 0)...
    cell = np.floor(np.clip(x, -1.0, n)).astype(np.int64)  # clipped: far points stay outside, no overflow
    inside = ((cell >= 0) & (cell <= n - 2)).all(axis=1)
    return np.where(inside[:, None], cell, -1)


def _vertex_cubes(grid: RegularGrid, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cube of each vertex (voxelizeTriangleMesh's first loop) and whether findHexa found it
    directly (only those cubes become BOUNDARY here; a vertex on the grid's border is moved half
    a cell inside to find its cube, which is then only used to bound its triangles)."""
    cells = _cube_of(grid, vertices)
    direct = cells[:, 0] >= 0
    if not direct.all():
        _, step = grid.frame()
        bottom, top = np.asarray(grid.min, dtype=np.float64), np.asarray(grid.max, dtype=np.float64)
        delta = step / 2  # (dx + dy + dz) / 2
        moved = vertices[~direct].copy()
        for a in range(3):
            below = moved[:, a] - _FLOAT_EPSILON < bottom[a]
            above = ~below & (moved[:, a] + _FLOAT_EPSILON > top[a])
            moved[below, a] = bottom[a] + delta[a]
            moved[above, a] = top[a] - delta[a]
        cells[~direct] = _cube_of(grid, moved)
        lost = np.flatnonzero(cells[:, 0] < 0)
        if len(lost):
            raise VoxelError(
                f"surface vertex {int(lost[0])} ({', '.join(f'{v:g}' for v in vertices[lost[0]])}) is "
                "outside the grid: SOFA fails on it; widen min/max or leave them unset"
            )
    return cells, direct


# ---- Green and Hatch's polygon-cube test for triangles, vectorised, in single precision -----------


def _outcodes(values: list[np.ndarray], limit: float) -> np.ndarray:
    """One bit per side of each pair of parallel planes |value| = limit the point is outside of."""
    code = np.zeros(values[0].shape, dtype=np.int64)
    for bit, value in enumerate(values):
        code |= np.where(value > limit, 1 << (2 * bit), np.where(value < -limit, 1 << (2 * bit + 1), 0))
    return code


def _face_codes(p: np.ndarray) -> np.ndarray:
    return _outcodes([p[:, 0], p[:, 1], p[:, 2]], 0.5)


def _edge_codes(p: np.ndarray) -> np.ndarray:
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return _outcodes([x + y, x - y, x + z, x - z, y + z, y - z], 1.0)


def _corner_codes(p: np.ndarray) -> np.ndarray:
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return _outcodes([(x + y) + z, (x + y) - z, (x - y) + z, (x - y) - z], 1.5)


def _sign(v: np.ndarray) -> np.ndarray:
    """SIGN_NONZERO as a float: -1 for negatives, 1 otherwise (zero included)."""
    return np.where(v < 0, _F32(-1), _F32(1))


def _segment_hits_cube(v0: np.ndarray, v1: np.ndarray) -> np.ndarray:
    """Whether segment v0 v1 meets the unit cube centred at 0 (origin inside the swept cube)."""
    edge = v1 - v0
    sign = _sign(edge)
    hit = ~((v0 * sign > 0.5) | (v1 * sign < -0.5)).any(axis=1)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        along = edge[:, k] * v0[:, j] - edge[:, j] * v0[:, k]
        reach = _F32(0.5) * (edge[:, k] * sign[:, j] + edge[:, j] * sign[:, k])
        hit &= ~(along * along > reach * reach)
    return hit


def _contains(verts: list[np.ndarray], normal: np.ndarray, point: np.ndarray) -> np.ndarray:
    """polygon_contains_point_3d: the winding count of ``point`` (in the triangle's plane), in the
    projection that drops the normal's largest axis."""
    size = np.abs(normal)
    zaxis = np.where(
        size[:, 0] > size[:, 2],
        np.where(size[:, 0] > size[:, 1], 0, 1),
        np.where(size[:, 1] > size[:, 2], 1, 2),
    )
    flip = normal[np.arange(len(normal)), zaxis] < 0
    xaxis = np.where(flip, (zaxis + 2) % 3, (zaxis + 1) % 3)
    yaxis = np.where(flip, (zaxis + 1) % 3, (zaxis + 2) % 3)
    rows = np.arange(len(normal))

    def axis(v: np.ndarray, a: np.ndarray) -> np.ndarray:
        return v[rows, a]

    px, py = axis(point, xaxis), axis(point, yaxis)
    count = np.zeros(len(normal), dtype=np.int64)
    for i in range(3):
        v, w = verts[i], verts[(i + 1) % 3]
        vx, vy, wx, wy = axis(v, xaxis), axis(v, yaxis), axis(w, xaxis), axis(w, yaxis)
        xdir = (wx > px).astype(np.int64) - (vx > px).astype(np.int64)
        ycross = (wy > py).astype(np.int64) - (vy > py).astype(np.int64)
        s = xdir.astype(_F32)
        left = (s * (px - vx)) * (wy - vy)
        right = (s * (py - vy)) * (wx - vx)
        straddle = np.where(ycross != 0, left <= right, vy <= py)
        count += np.where((xdir != 0) & straddle, xdir, 0)
    return count


def triangles_hit_cube(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """fast_polygon_intersects_cube on triangles already scaled to the unit cube at the origin,
    (m, 3) float32 corners each: whether each triangle meets the cube (surface, not volume)."""
    verts = [a, b, c]
    faces = [_face_codes(v) for v in verts]
    accept = (faces[0] == 0) | (faces[1] == 0) | (faces[2] == 0)
    reject = (faces[0] & faces[1] & faces[2]) != 0
    for codes in (_edge_codes, _corner_codes):
        found = [codes(v) for v in verts]
        reject |= (found[0] & found[1] & found[2]) != 0
    hit = accept.copy()
    todo = ~accept & ~reject
    if not todo.any():
        return hit
    va, vb, vc = a[todo], b[todo], c[todo]
    edges = _segment_hits_cube(va, vb) | _segment_hits_cube(vb, vc) | _segment_hits_cube(vc, va)
    # get_polygon_normal: (b - a) x (c - a), each component as a 2x2 determinant
    u, w = vb - va, vc - va
    normal = np.stack(
        [
            u[:, 1] * w[:, 2] + u[:, 2] * -w[:, 1],
            -(u[:, 0] * w[:, 2] + u[:, 2] * -w[:, 0]),
            u[:, 0] * w[:, 1] + u[:, 1] * -w[:, 0],
        ],
        axis=1,
    )
    diagonal = _sign(normal)
    flat = (normal == 0).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((normal[:, 0] * va[:, 0] + normal[:, 1] * va[:, 1]) + normal[:, 2] * va[:, 2]) / (
            (normal[:, 0] * diagonal[:, 0] + normal[:, 1] * diagonal[:, 1]) + normal[:, 2] * diagonal[:, 2]
        )
    t64 = t.astype(np.float64)  # IN_CLOSED_INTERVAL(-.5, t, .5) is evaluated in double
    crossing = ~flat & ((t64 + 0.5) * (t64 - 0.5) <= 0)
    interior = np.zeros(len(va), dtype=bool)
    if crossing.any():
        point = t[crossing, None] * diagonal[crossing]
        interior[crossing] = (
            _contains([va[crossing], vb[crossing], vc[crossing]], normal[crossing], point) != 0
        )
    hit[todo] = edges | interior
    return hit


# ---- the voxelisation ---------------------------------------------------------------------------


def classify(grid: RegularGrid, vertices: np.ndarray, triangles: np.ndarray) -> Voxels:
    """voxelizeTriangleMesh: each regular-grid cube OUTSIDE, INSIDE or BOUNDARY."""
    n = np.asarray(grid.resolution(), dtype=np.int64)
    cubes = n - 1
    types = np.full(int(cubes.prod()), INSIDE, dtype=np.int8)
    cells, direct = _vertex_cubes(grid, vertices)

    def index(c: np.ndarray) -> np.ndarray:
        return c[..., 0] + cubes[0] * (c[..., 1] + cubes[1] * c[..., 2])

    types[index(cells[direct])] = BOUNDARY
    origin, step = grid.frame()
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    corners = cells[tri]  # (t, 3 vertices, 3 axes)
    low, span = corners.min(axis=1), corners.max(axis=1) - corners.min(axis=1) + 1
    counts = span.prod(axis=1)
    done = 0
    while done < len(tri):  # (triangle, cube) candidates in chunks of bounded size
        stop = done + max(1, int(np.searchsorted(np.cumsum(counts[done:]), _CANDIDATES)))
        owner = np.repeat(np.arange(done, stop), counts[done:stop])
        local = np.arange(len(owner)) - np.repeat(
            np.cumsum(counts[done:stop]) - counts[done:stop], counts[done:stop]
        )
        sy, sz = span[owner, 1], span[owner, 2]
        cube = low[owner] + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], axis=1)
        done = stop
        keep = types[index(cube)] != BOUNDARY
        owner, cube = owner[keep], cube[keep]
        first = origin + step * cube  # corner 0 and corner 6 (+1, +1, +1) of each cube, as getPoint
        diagonal = (origin + step * (cube + 1)) - first
        centre = first + diagonal * 0.5
        scaled = [((vertices[tri[owner, k]] - centre) / diagonal).astype(_F32) for k in range(3)]
        hit = triangles_hit_cube(*scaled)
        types[index(cube[hit])] = BOUNDARY
    # Flood fill from the border: non-BOUNDARY cubes connected to it are OUTSIDE.
    free = (types != BOUNDARY).reshape(int(cubes[2]), int(cubes[1]), int(cubes[0]))
    reached = np.zeros_like(free)
    for axis in range(3):
        first_slab = [slice(None)] * 3
        first_slab[axis] = 0
        last_slab = [slice(None)] * 3
        last_slab[axis] = -1
        reached[tuple(first_slab)] |= free[tuple(first_slab)]
        reached[tuple(last_slab)] |= free[tuple(last_slab)]
    while True:
        grown = reached.copy()
        for axis in range(3):
            forward = [slice(None)] * 3
            backward = [slice(None)] * 3
            forward[axis], backward[axis] = slice(1, None), slice(None, -1)
            grown[tuple(forward)] |= reached[tuple(backward)]
            grown[tuple(backward)] |= reached[tuple(forward)]
        grown &= free
        if np.array_equal(grown, reached):
            break
        reached = grown
    types[reached.ravel()] = OUTSIDE
    return Voxels(grid, types)


def sparse_grid(voxels: Voxels, *, only_inside: bool = False) -> SparseGrid:
    """buildFromRegularGridTypes: the BOUNDARY cubes (unless ``only_inside``) then the INSIDE ones,
    their corners numbered in lexicographic (x, y, z) order."""
    types = voxels.types
    boundary = np.flatnonzero(types == BOUNDARY) if not only_inside else np.zeros(0, dtype=np.int64)
    kept = np.concatenate([boundary, np.flatnonzero(types == INSIDE)])
    grid = voxels.grid
    n = np.asarray(grid.resolution(), dtype=np.int64)
    cube = np.stack(
        [kept % (n[0] - 1), (kept // (n[0] - 1)) % (n[1] - 1), kept // ((n[0] - 1) * (n[1] - 1))], 1
    )
    corner = cube[:, None, :] + np.asarray(_CORNERS)[None]  # (m, 8, 3) grid coordinates, getHexaCopy order
    used, inverse = np.unique(
        corner[..., 0] + n[0] * (corner[..., 1] + n[1] * corner[..., 2]), return_inverse=True
    )
    origin, step = grid.frame()
    coords = origin + step * np.stack([used % n[0], (used // n[0]) % n[1], used // (n[0] * n[1])], 1)
    # std::map<Vec3, index>: lexicographic on the exact coordinates; equal positions share a point
    order = np.lexsort((coords[:, 2], coords[:, 1], coords[:, 0]))
    ordered = coords[order]
    fresh = np.ones(len(ordered), dtype=bool)
    fresh[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.cumsum(fresh) - 1
    hexahedra = rank[inverse].reshape(-1, 8)
    table = np.full(len(types), -1, dtype=np.int64)
    table[kept] = np.arange(len(kept))
    is_boundary = np.zeros(len(kept), dtype=bool)
    is_boundary[: len(boundary)] = True
    return SparseGrid(grid, ordered[fresh], hexahedra, table, is_boundary)


def triangulate(triangles: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """The triangles SOFA's voxeliser walks: each facet as a fan (0, j-1, j)."""
    quads = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    fans = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return np.concatenate([np.asarray(triangles, dtype=np.int64).reshape(-1, 3), fans])


def cell_coefficients(boundary: np.ndarray, fill_weighted: bool) -> np.ndarray:
    """SparseGridTopology's per-cell stiffness and mass coefficients (getStiffnessCoef and
    getMassCoef, equal when built from a surface without virtual finer levels): 0.5 for a BOUNDARY
    cell when ``fillWeighted``, else 1. ``boundary``: whether each sparse cell is BOUNDARY."""
    flags = np.asarray(boundary, dtype=bool).ravel()
    return np.where(flags & bool(fill_weighted), 0.5, 1.0)
