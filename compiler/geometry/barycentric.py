"""The embedding SOFA's BarycentricMapping computes at init: for each mapped point, an element of the
input topology and its (barycentric / trilinear) coordinates in it.

The result is a constant linear map ``out_i = sum_j weights[i, j] * in[indices[i, j]]`` (apply, J),
whose transpose maps forces back (J^T); ``runtime/sofac/mapping.h`` has the kernels.

Which mapper SOFA uses depends on the *input* topology component (BarycentricMapping::
createMapperFromTopology), and each chooses elements its own way; ``barycentric_map`` reproduces
each one with SOFA's arithmetic (same operations, same order), so the weights, and the mapped
positions, are SOFA's to the last bit (checked on Demos/liver.scn's spheres):

* ``grid=RegularGrid(...)`` (RegularGridTopology with hexahedra): the cube is found by index
  arithmetic on the grid's own geometry (p0, cell steps), not on the input positions; a point outside
  the grid goes to the clamped nearest cube, coordinates outside [0, 1] (extrapolation).
* ``grid=SparseGrid(...)`` (SparseGridTopology): the regular-grid cube when it is part of the sparse
  grid, else the boundary cube whose centre is closest (distances in single precision, as SOFA).
* ``topology="dynamic"`` (Tetrahedron/Hexahedron/Quad/TriangleSetTopologyContainer): one element type,
  the first of hexahedra, tetrahedra, quads, triangles the container has. Elements are hashed into a
  grid of cells of the mean edge length; a point takes the element of its own cell where it is
  deepest inside (or, outside all, whose centre is nearest); if that distance exceeds half a cell the
  27 neighbouring cells are searched too; a point whose cell holds no element is compared with all.
  So a point outside the mesh is attached to a *nearby* element, not necessarily the closest one.
* ``topology="mesh"`` (MeshTopology, GridTopology and any other static topology): every element is
  compared (tetrahedra and hexahedra together when the mesh has any, else triangles and quads, else
  edges), the same criterion as above with an initial bound of 1e10.

Hexahedra (mesh mapper, dynamic mapper) use the affine frame of corners 1, 3, 4 around corner 0 to
compute the coordinates (exact for parallelepipeds only), then trilinear weights. Triangles and quads
keep the two in-plane coordinates: the mapped point is the projection on the element's plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sofac.geometry.masses import EPSILON, as_cells, cross_rows, topology_edges
from sofac.registry.spec import Variant

# Trilinear weights of a hexahedron with coordinates (fx, fy, fz), per node 0..7, as SOFA writes them.
_HEXA_ORDER_MESH = (0, 1, 3, 2, 4, 5, 7, 6)  # the mesh / grid mappers' summation order
_QUAD_ORDER_MESH = (0, 1, 3, 2)
_CHUNK = 1 << 21  # candidate (point, element) pairs evaluated at once


# The mapper SOFA's BarycentricMapping::createMapperFromTopology picks for an input topology class.


def mapper_for(topology: Variant | None) -> str:
    """Which mapper SOFA uses for an input topology, from its registry variant (ComponentSpec.variant):
    ``"regular_grid"`` (pass ``grid=RegularGrid(...)``), ``"sparse_grid"`` (``grid=SparseGrid(...)``),
    ``"dynamic"`` (``topology="dynamic"``: the *SetTopologyContainer family) or ``"mesh"``
    (``topology="mesh"``: MeshTopology, GridTopology, CubeTopology, ...)."""
    grids = (Variant.REGULAR_GRID, Variant.SPARSE_GRID, Variant.DYNAMIC)
    return topology.value if topology in grids and topology is not None else "mesh"


@dataclass(frozen=True)
class RegularGrid:
    """A RegularGridTopology: ``n`` points per axis, ``min``/``max`` corners, optional ``p0``
    (when the scene sets it) and ``cell_width`` (> 0: ``n`` recomputed from min/max as SOFA's init).

    SOFA reads the legacy ``xmin ... zmax`` attributes as single-precision floats: pass them as
    ``float(np.float32(value))`` (times ``scale``) to match.
    """

    n: tuple[int, int, int]
    min: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max: tuple[float, float, float] = (1.0, 1.0, 1.0)
    p0: tuple[float, float, float] | None = None
    cell_width: float = 0.0

    def resolution(self) -> tuple[int, int, int]:
        if self.cell_width:
            w = float(self.cell_width)
            nx, ny, nz = (math.ceil((self.max[a] - self.min[a]) / w) + 1 for a in range(3))
            return nx, ny, nz
        nx, ny, nz = (int(v) for v in self.n)
        return nx, ny, nz

    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(p0, step): the grid origin and the cell size per axis (RegularGridTopology::setPos)."""
        n = self.resolution()
        low = np.asarray(self.min, dtype=np.float64)
        high = np.asarray(self.max, dtype=np.float64)
        origin = low.copy()
        step = np.empty(3)
        for a in range(3):
            if n[a] - 1 > 0:
                step[a] = (high[a] - low[a]) / (n[a] - 1)
            else:
                step[a] = high[a] - low[a]
                if a < 2:  # SOFA centres a flat x or y axis, not z
                    origin[a] = (high[a] + low[a]) / 2
        if self.p0 is not None:
            origin = np.asarray(self.p0, dtype=np.float64)
        return origin, step

    def points(self) -> np.ndarray:
        """SOFA's grid points p0 + i dx + j dy + k dz, index i + nx (j + ny k)."""
        nx, ny, nz = self.resolution()
        origin, step = self.frame()
        k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
        ijk = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        return origin + step * ijk

    def hexahedra(self) -> np.ndarray:
        """(cubes, 8) corner point indices, cube index x + (nx-1)(y + (ny-1) z) (GridTopology order)."""
        nx, ny, nz = self.resolution()
        if min(nx, ny, nz) < 2:
            return np.zeros((0, 8), dtype=np.int64)
        k, j, i = (
            a.ravel()
            for a in np.meshgrid(np.arange(nz - 1), np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
        )
        corners = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))
        return np.stack([(i + a) + nx * ((j + b) + ny * (k + c)) for a, b, c in corners], axis=1).astype(
            np.int64
        )


@dataclass(frozen=True, eq=False)
class SparseGrid:
    """A SparseGridTopology as its mapper sees it.

    ``regular``: the underlying regular grid (SparseGridTopology::_regularGrid); ``points`` (p, 3)
    and ``hexahedra`` (m, 8): the sparse grid's own; ``regular_to_sparse``: for each cube of the
    regular grid, its index in ``hexahedra`` or -1 (_indicesOfRegularCubeInSparseGrid);
    ``boundary``: which sparse cubes are BOUNDARY (not INSIDE); ``using_mc``: marching-cubes mode.
    """

    regular: RegularGrid
    points: np.ndarray
    hexahedra: np.ndarray
    regular_to_sparse: np.ndarray
    boundary: np.ndarray
    using_mc: bool = False


@dataclass(frozen=True, eq=False)
class Embedding:
    """Per mapped point: the element chosen (``element``, into the element list the mapper uses, see
    ``kind``) and SOFA's stored coordinates (``coords``); ``indices`` / ``weights`` (n, k) the
    resulting linear map, columns in SOFA's summation order (zero-weight padding repeats a node)."""

    kind: str
    element: np.ndarray
    coords: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    notes: tuple[str, ...] = field(default=())
    # Per mapped point, how many leading columns are its element's nodes (a mesh of tetrahedra and
    # hexahedra pads its tetrahedra to 8 columns); None: all of them. SOFA's applyJT on constraint
    # rows adds exactly these.
    nodes: np.ndarray | None = None


# ---- SOFA's small-matrix arithmetic -------------------------------------------------------------


def _inverse_of_transpose(rows: np.ndarray, failed: str) -> tuple[np.ndarray, np.ndarray]:
    """(m, 3, 3) inverse of the transpose of the matrices whose rows are ``rows`` (m, 3, 3), with
    sofa::type::invertMatrix's cofactor formulas. Where |det| <= machine epsilon SOFA's inversion fails
    and leaves the destination unchanged: the rows themselves (``failed="rows"``) or zeros.
    Returns (matrices, inverted)."""
    f = np.transpose(rows, (0, 2, 1))  # from(i, j)

    def e(i: int, j: int) -> np.ndarray:
        return f[:, i, j]

    det = (
        e(0, 0) * e(1, 1) * e(2, 2)
        + e(1, 0) * e(2, 1) * e(0, 2)
        + e(2, 0) * e(0, 1) * e(1, 2)
        - e(0, 0) * e(2, 1) * e(1, 2)
        - e(1, 0) * e(0, 1) * e(2, 2)
        - e(2, 0) * e(1, 1) * e(0, 2)
    )
    ok = np.abs(det) > EPSILON
    safe = np.where(ok, det, 1.0)
    out = np.empty_like(rows)
    out[:, 0, 0] = (e(1, 1) * e(2, 2) - e(2, 1) * e(1, 2)) / safe
    out[:, 1, 0] = (e(1, 2) * e(2, 0) - e(2, 2) * e(1, 0)) / safe
    out[:, 2, 0] = (e(1, 0) * e(2, 1) - e(2, 0) * e(1, 1)) / safe
    out[:, 0, 1] = (e(2, 1) * e(0, 2) - e(0, 1) * e(2, 2)) / safe
    out[:, 1, 1] = (e(2, 2) * e(0, 0) - e(0, 2) * e(2, 0)) / safe
    out[:, 2, 1] = (e(2, 0) * e(0, 1) - e(0, 0) * e(2, 1)) / safe
    out[:, 0, 2] = (e(0, 1) * e(1, 2) - e(1, 1) * e(0, 2)) / safe
    out[:, 1, 2] = (e(0, 2) * e(1, 0) - e(1, 2) * e(0, 0)) / safe
    out[:, 2, 2] = (e(0, 0) * e(1, 1) - e(1, 0) * e(0, 1)) / safe
    if not ok.all():
        out[~ok] = rows[~ok] if failed == "rows" else 0.0
    return out, ok


def _norm2(v: np.ndarray) -> np.ndarray:
    return v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]


@dataclass(frozen=True, eq=False)
class _Frames:
    """Per element: SOFA's base matrix, its origin (node 0), its centre, and the distance rule."""

    bases: np.ndarray  # (m, 3, 3)
    origins: np.ndarray  # (m, 3)
    centers: np.ndarray  # (m, 3)
    rules: np.ndarray  # (m,) element kind per element: 0 tetra, 1 hexa, 2 triangle, 3 quad
    rows: np.ndarray  # (m, 3, 3) the frame's edge vectors (rows of the matrix SOFA inverts)
    inverted: np.ndarray  # (m,) False where SOFA's inversion failed (|det| <= epsilon)


_TETRA, _HEXA, _TRIANGLE, _QUAD = 0, 1, 2, 3


def _frames(points: np.ndarray, kind: str, elements: np.ndarray, failed: str) -> _Frames:
    p = [points[elements[:, j]] for j in range(elements.shape[1])]
    if kind == "tetrahedra":
        rows = np.stack([p[1] - p[0], p[2] - p[0], p[3] - p[0]], axis=1)
        centers = (p[0] + p[1] + p[2] + p[3]) * 0.25
        rule = _TETRA
    elif kind == "hexahedra":
        rows = np.stack([p[1] - p[0], p[3] - p[0], p[4] - p[0]], axis=1)
        centers = (p[0] + p[1] + p[2] + p[3] + p[4] + p[5] + p[6] + p[7]) * 0.125
        rule = _HEXA
    elif kind == "triangles":
        a, b = p[1] - p[0], p[2] - p[0]
        rows = np.stack([a, b, cross_rows(a, b)], axis=1)
        centers = (p[0] + p[1] + p[2]) / 3
        rule = _TRIANGLE
    elif kind == "quads":
        a, b = p[1] - p[0], p[3] - p[0]
        rows = np.stack([a, b, cross_rows(a, b)], axis=1)
        centers = (p[0] + p[1] + p[2] + p[3]) * 0.25
        rule = _QUAD
    else:
        raise ValueError(f"no barycentric frame for {kind}")
    bases, inverted = _inverse_of_transpose(rows, failed)
    return _Frames(bases, p[0], centers, np.full(len(elements), rule, dtype=np.int8), rows, inverted)


def _concat_frames(parts: list[_Frames]) -> _Frames:
    return _Frames(
        np.concatenate([f.bases for f in parts]),
        np.concatenate([f.origins for f in parts]),
        np.concatenate([f.centers for f in parts]),
        np.concatenate([f.rules for f in parts]),
        np.concatenate([f.rows for f in parts]),
        np.concatenate([f.inverted for f in parts]),
    )


def _evaluate(
    bases: np.ndarray, origins: np.ndarray, centers: np.ndarray, rules: np.ndarray, pts: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """SOFA's distance of points to elements and the points' coordinates v = base (p - node0), all
    arguments broadcast against each other (bases (..., 3, 3), origins / centers / pts (..., 3)).
    Inside (or within tolerance of) an element the distance is <= 0 (how deep, in coordinates),
    outside it is the squared distance to the element's centre; NaN becomes +inf (never chosen)."""
    d = pts - origins
    v = np.stack(
        [
            bases[..., i, 0] * d[..., 0] + bases[..., i, 1] * d[..., 1] + bases[..., i, 2] * d[..., 2]
            for i in range(3)
        ],
        axis=-1,
    )
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    outside = np.maximum(-v0, -v1)
    dist = np.zeros(np.broadcast_shapes(v0.shape, rules.shape))
    present = np.unique(rules)
    for rule in present.tolist():
        if rule == _TETRA:
            value = np.maximum(outside, np.maximum(-v2, v0 + v1 + v2 - 1))
        elif rule == _HEXA:
            value = np.maximum(outside, np.maximum(np.maximum(-v2, v0 - 1), np.maximum(v1 - 1, v2 - 1)))
        elif rule == _TRIANGLE:
            value = np.maximum(outside, np.maximum(np.abs(v2) - 0.01, v0 + v1 - 1))
        else:
            value = np.maximum(
                outside, np.maximum(np.maximum(v1 - 1, v0 - 1), np.maximum(v2 - 0.01, -v2 - 0.01))
            )
        dist = value if len(present) == 1 else np.where(rules == rule, value, dist)
    far = dist > 0
    if far.any():
        dist = np.where(far, _norm2(pts - centers), dist)
    return np.where(np.isnan(dist), np.inf, dist), v


def _distances(frames: _Frames, pts: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, C) distances and (P, C, 3) coordinates of points ``pts`` (P, 3) in elements ``cand``."""
    return _evaluate(
        frames.bases[cand][None],
        frames.origins[cand][None],
        frames.centers[cand][None],
        frames.rules[cand][None],
        pts[:, None, :],
    )


def _nearest(
    frames: _Frames, pts: np.ndarray, cand: np.ndarray, bound: float = np.inf
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point, the first candidate (in ``cand`` order) of smallest distance below ``bound``
    (SOFA's ``if (d < distance)`` scan): (position in cand or -1, distance, coordinates)."""
    best = np.full(len(pts), -1, dtype=np.int64)
    best_dist = np.full(len(pts), bound)
    best_v = np.zeros((len(pts), 3))
    if len(cand) == 0 or len(pts) == 0:
        return best, best_dist, best_v
    step = max(1, _CHUNK // max(len(cand), 1))
    for start in range(0, len(pts), step):
        sl = slice(start, start + step)
        dist, v = _distances(frames, pts[sl], cand)
        arg = np.argmin(dist, axis=1)
        value = dist[np.arange(len(arg)), arg]
        take = value < best_dist[sl]
        rows = np.flatnonzero(take)
        best[sl][rows] = arg[rows]
        best_dist[sl][rows] = value[rows]
        best_v[sl][rows] = v[rows, arg[rows]]
    return best, best_dist, best_v


_BRUTE_FORCE_PAIRS = 4_000_000  # above this many (point, element) pairs, prune with a hash grid


def _nearest_everywhere(
    frames: _Frames, pts: np.ndarray, bound: float = np.inf
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_nearest`` over every element, in element order: brute force for small problems, else the
    same answer found by pruning (see ``_nearest_pruned``)."""
    m = len(frames.rules)
    if len(pts) * m <= _BRUTE_FORCE_PAIRS:
        return _nearest(frames, pts, np.arange(m), bound)
    return _nearest_pruned(frames, pts, bound)


def _regions(frames: _Frames) -> tuple[np.ndarray, np.ndarray]:
    """Per element, a box holding every point whose SOFA distance is <= 0 (padded for round-off):
    the tetrahedron, the parallelepiped of a hexahedron's frame, a surface element's slab of
    +-0.01 in its normal coordinate."""
    o = frames.origins
    e0, e1, e2 = frames.rows[:, 0], frames.rows[:, 1], frames.rows[:, 2]
    corners = np.empty((len(o), 8, 3))
    tetra = frames.rules == _TETRA
    corners[tetra] = np.stack([o, o + e0, o + e1, o + e2] * 2, axis=1)[tetra]
    hexa = frames.rules == _HEXA
    combos = [a * e0 + b * e1 + c * e2 for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    corners[hexa] = (o[:, None] + np.stack(combos, axis=1))[hexa]
    for rule, base in ((_TRIANGLE, [o, o + e0, o + e1, o]), (_QUAD, [o, o + e0, o + e1, o + e0 + e1])):
        chosen = frames.rules == rule
        slab = [q + s * 0.01 * e2 for s in (-1, 1) for q in base]
        corners[chosen] = np.stack(slab, axis=1)[chosen]
    low, high = corners.min(axis=1), corners.max(axis=1)
    pad = 1e-9 * (np.abs(corners).max(axis=(1, 2)) + (high - low).max(axis=1))[:, None]
    return low - pad, high + pad


def _nearest_pruned(
    frames: _Frames, pts: np.ndarray, bound: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first element of smallest SOFA distance, without comparing every pair.

    An element at distance <= 0 (the point is inside it) always beats one at a positive distance
    (a squared distance to its centre); so a point inside some element takes, among the elements
    whose ``_regions`` box holds it, the one of smallest distance (ties: lowest index), and a point
    inside none takes the element of nearest centre (ties: lowest index). Elements whose frame SOFA
    could not invert, or whose box is huge, are candidates for every point."""
    m, n = len(frames.rules), len(pts)
    low, high = _regions(frames)
    extent = (high - low).max(axis=1)
    usable = frames.inverted & np.isfinite(extent)
    cell = float(np.median(extent[usable])) if usable.any() else 1.0
    cell = cell if cell > 0 else 1.0
    conv = 1.0 / cell
    first = np.floor(low * conv).astype(np.int64)
    last = np.floor(high * conv).astype(np.int64)
    spans = np.where(usable[:, None], last - first + 1, 1)
    counts = spans.prod(axis=1)
    usable &= counts <= 64
    everywhere = np.flatnonzero(~usable)
    hashed = np.flatnonzero(usable)
    owner = np.repeat(hashed, counts[hashed])
    local = np.arange(len(owner)) - np.repeat(np.cumsum(counts[hashed]) - counts[hashed], counts[hashed])
    sy, sz = spans[owner, 1], spans[owner, 2]
    keys = first[owner] + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], axis=1)
    table: dict[tuple[int, ...], np.ndarray] = {}
    if len(keys):
        order = np.lexsort((owner, keys[:, 2], keys[:, 1], keys[:, 0]))
        keys, owner = keys[order], owner[order]
        starts = np.flatnonzero(np.r_[True, (np.diff(keys, axis=0) != 0).any(axis=1)])
        ends = np.r_[starts[1:], len(keys)]
        table = {tuple(keys[a].tolist()): owner[a:b] for a, b in zip(starts, ends, strict=True)}

    cells, group = np.unique(np.floor(pts * conv).astype(np.int64), axis=0, return_inverse=True)
    group = group.reshape(-1)
    members = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[members], np.arange(len(cells) + 1))
    point_parts, element_parts = [], []
    for g, cell_key in enumerate(cells.tolist()):
        found = table.get(tuple(cell_key))
        if found is not None:
            rows = members[bounds[g] : bounds[g + 1]]
            point_parts.append(np.repeat(rows, len(found)))
            element_parts.append(np.tile(found, len(rows)))
    if len(everywhere):
        point_parts.append(np.repeat(np.arange(n), len(everywhere)))
        element_parts.append(np.tile(everywhere, n))
    pi = np.concatenate(point_parts) if point_parts else np.zeros(0, dtype=np.int64)
    ei = np.concatenate(element_parts) if element_parts else np.zeros(0, dtype=np.int64)
    keep = ~usable[ei] | ((low[ei] <= pts[pi]) & (pts[pi] <= high[ei])).all(axis=1)
    pi, ei = pi[keep], ei[keep]

    best = np.full(n, -1, dtype=np.int64)
    best_dist = np.full(n, np.inf)
    best_v = np.zeros((n, 3))
    step = max(1, _CHUNK)
    inside_p, inside_e, inside_d, inside_v = [], [], [], []
    for a in range(0, len(pi), step):
        p_, e_ = pi[a : a + step], ei[a : a + step]
        f = frames
        dist, v = _evaluate(f.bases[e_], f.origins[e_], f.centers[e_], f.rules[e_], pts[p_])
        within = dist <= 0
        inside_p.append(p_[within])
        inside_e.append(e_[within])
        inside_d.append(dist[within])
        inside_v.append(v[within])
    if inside_p:
        ip, ie, idist, iv = (np.concatenate(x) for x in (inside_p, inside_e, inside_d, inside_v))
        order = np.lexsort((ie, idist, ip))
        ip, ie, idist, iv = ip[order], ie[order], idist[order], iv[order]
        head = np.r_[True, ip[1:] != ip[:-1]] if len(ip) else np.zeros(0, dtype=bool)
        best[ip[head]], best_dist[ip[head]], best_v[ip[head]] = ie[head], idist[head], iv[head]
    rest = np.flatnonzero(best < 0)
    if len(rest):  # inside no element: the nearest centre
        chunk = max(1, _CHUNK // m)
        for a in range(0, len(rest), chunk):
            rows = rest[a : a + chunk]
            gap = _norm2(pts[rows][:, None, :] - frames.centers[None, :, :])
            arg = np.argmin(gap, axis=1)
            e_ = arg
            dist, v = _evaluate(
                frames.bases[e_], frames.origins[e_], frames.centers[e_], frames.rules[e_], pts[rows]
            )
            best[rows], best_dist[rows], best_v[rows] = e_, dist, v
        odd = rest[~(best_dist[rest] > 0) | ~np.isfinite(best_dist[rest])]
        if len(odd):  # NaN frames or round-off at a box edge: settle these points by brute force
            b, d, v = _nearest(frames, pts[odd], np.arange(m), bound)
            best[odd], best_dist[odd], best_v[odd] = b, d, v
    beyond = ~(best_dist < bound)
    best[beyond] = -1
    return best, best_dist, best_v


# ---- weights -----------------------------------------------------------------------------------------


def _tetra_weights(f: np.ndarray) -> np.ndarray:
    return np.stack([1 - f[:, 0] - f[:, 1] - f[:, 2], f[:, 0], f[:, 1], f[:, 2]], axis=1)


def _hexa_weights(f: np.ndarray) -> np.ndarray:
    """Per node 0..7 (getBarycentricCoefficients / the apply expressions)."""
    fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]
    return np.stack(
        [
            (1 - fx) * (1 - fy) * (1 - fz),
            fx * (1 - fy) * (1 - fz),
            fx * fy * (1 - fz),
            (1 - fx) * fy * (1 - fz),
            (1 - fx) * (1 - fy) * fz,
            fx * (1 - fy) * fz,
            fx * fy * fz,
            (1 - fx) * fy * fz,
        ],
        axis=1,
    )


def _triangle_weights(f: np.ndarray) -> np.ndarray:
    return np.stack([1 - f[:, 0] - f[:, 1], f[:, 0], f[:, 1]], axis=1)


def _quad_weights(f: np.ndarray) -> np.ndarray:
    """Per node 0..3."""
    fx, fy = f[:, 0], f[:, 1]
    return np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), fx * fy, (1 - fx) * fy], axis=1)


_WEIGHTS = {"tetrahedra": _tetra_weights, "hexahedra": _hexa_weights, "triangles": _triangle_weights}
_WEIGHTS["quads"] = _quad_weights
_COORDS = {"tetrahedra": 3, "hexahedra": 3, "triangles": 2, "quads": 2, "edges": 1}


def _degenerate_note(frames: _Frames) -> tuple[str, ...]:
    failed = int((~frames.inverted).sum())
    if not failed:
        return ()
    return (
        f"{failed} degenerate elements (|det| <= machine epsilon): SOFA cannot invert their frames and "
        "keeps a zero (static mesh) or non-inverted (dynamic) frame, so they may capture points",
    )


def _linear_map(
    elements: np.ndarray, element: np.ndarray, weights: np.ndarray, order: tuple[int, ...] | None, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """(indices, weights) (n, k): columns in ``order`` (SOFA's summation order), zero-padded to k."""
    nodes = elements[element]
    if order is not None:
        nodes = nodes[:, order]
        weights = weights[:, order]
    pad = k - nodes.shape[1]
    if pad:
        nodes = np.concatenate([nodes, np.repeat(nodes[:, :1], pad, axis=1)], axis=1)
        weights = np.concatenate([weights, np.zeros((len(weights), pad))], axis=1)
    return nodes.astype(np.int64), np.ascontiguousarray(weights, dtype=np.float64)


# ---- mappers -----------------------------------------------------------------------------------------


def _grid_cubes(grid: RegularGrid, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RegularGridTopology::findCube, then findNearestCube: (cube index, fractions (n, 3), found)."""
    n = np.asarray(grid.resolution(), dtype=np.int64)
    origin, step = grid.frame()
    rel = pts - origin
    x = (rel * step) * (1.0 / (step * step))  # p.dx * inv_dx2 with dx = (step_x, 0, 0), ...
    ix = np.floor(x).astype(np.int64)
    found = ((ix >= 0) & (ix <= n - 2)).all(axis=1)
    clamped = np.clip(ix, 0, n - 2)
    f = x - clamped
    cube = clamped[:, 0] + (n[0] - 1) * (clamped[:, 1] + (n[1] - 1) * clamped[:, 2])
    return cube, f, found


def _map_regular_grid(grid: RegularGrid, pts: np.ndarray) -> Embedding:
    n = grid.resolution()
    if min(n) < 2:
        raise ValueError(
            f"RegularGridTopology n={list(n)} has no hexahedra: SOFA creates no barycentric mapper"
        )
    cube, f, found = _grid_cubes(grid, pts)
    hexahedra = grid.hexahedra()
    indices, weights = _linear_map(hexahedra, cube, _hexa_weights(f), _HEXA_ORDER_MESH, 8)
    notes = () if found.all() else (f"{int((~found).sum())} points outside the grid (extrapolated)",)
    return Embedding("hexahedra", cube, f, indices, weights, notes)


def _map_sparse_grid(grid: SparseGrid, pts: np.ndarray) -> Embedding:
    hexahedra = as_cells(grid.hexahedra, "hexahedra", len(grid.points))
    if len(hexahedra) == 0:
        raise ValueError("SparseGridTopology has no hexahedra: SOFA creates no barycentric mapper")
    regular_cube, f, found = _grid_cubes(grid.regular, pts)
    table = np.asarray(grid.regular_to_sparse, dtype=np.int64).reshape(-1)
    if len(table) != len(grid.regular.hexahedra()):
        raise ValueError("SparseGrid.regular_to_sparse must have one entry per cube of the regular grid")
    if np.size(grid.boundary) != len(hexahedra) or table.max(initial=-1) >= len(hexahedra):
        raise ValueError("SparseGrid.boundary / regular_to_sparse do not match its hexahedra")
    element = np.where(found, table[np.where(found, regular_cube, 0)], -1)
    missing = np.flatnonzero(element < 0)
    if len(missing):  # SparseGridTopology::findNearestCube, lengths in single precision
        points = np.asarray(grid.points, dtype=np.float64)
        usable = (
            np.ones(len(hexahedra), dtype=bool) if grid.using_mc else np.asarray(grid.boundary, dtype=bool)
        )
        centre = (points[hexahedra[:, 0]] + points[hexahedra[:, 6]]) * 0.5
        for i in missing:
            lengths = np.sqrt(_norm2(pts[i] - centre)).astype(np.float32)
            lengths = np.where(usable, lengths, np.float32(np.inf))
            best = int(np.argmin(lengths))
            if not lengths[best] < np.float32(99999999.0):
                best = 0
            p0 = points[hexahedra[best, 0]]
            p7 = points[hexahedra[best, 6]]
            element[i] = best
            f[i] = (pts[i] - p0) / (p7 - p0)
    indices, weights = _linear_map(hexahedra, element, _hexa_weights(f), _HEXA_ORDER_MESH, 8)
    notes = (
        (f"{len(missing)} points outside the sparse grid (nearest boundary cube)",) if len(missing) else ()
    )
    return Embedding("hexahedra", element, f, indices, weights, notes)


def ramified_grid_map(
    coarse: RegularGrid, finest: RegularGrid, finest_to_hexa: np.ndarray, hexahedra: np.ndarray, pts: Any
) -> tuple[np.ndarray, np.ndarray]:
    """BarycentricMapperSparseGridTopology on a SparseGridRamificationTopology: findCube finds the
    point's cube in the finest grid, takes the hexahedron its piece belongs to, and the fractions
    in the coarse grid's cube. Points outside every finest cube (SOFA then searches the nearest
    finest BOUNDARY cube) are refused."""
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
    fine_cube, _, fine_found = _grid_cubes(finest, pts)
    table = np.asarray(finest_to_hexa, dtype=np.int64).reshape(-1)
    element = np.where(fine_found, table[np.where(fine_found, fine_cube, 0)], -1)
    if (element < 0).any():
        first = int(np.flatnonzero(element < 0)[0])
        raise ValueError(
            f"point {first} ({', '.join(f'{v:g}' for v in pts[first])}) is in no cell of the ramified "
            "grid: its nearest-cell search is not compiled yet"
        )
    _, f, _ = _grid_cubes(coarse, pts)
    return _linear_map(
        np.asarray(hexahedra, dtype=np.int64).reshape(-1, 8), element, _hexa_weights(f), _HEXA_ORDER_MESH, 8
    )


def _map_mesh(points: np.ndarray, pts: np.ndarray, cells: dict[str, np.ndarray]) -> Embedding:
    """BarycentricMapperMeshTopology::init."""
    if len(cells["tetrahedra"]) or len(cells["hexahedra"]):
        kinds = ("tetrahedra", "hexahedra")
    elif len(cells["triangles"]) or len(cells["quads"]):
        kinds = ("triangles", "quads")
    elif len(cells["edges"]):
        return _map_mesh_edges(points, pts, cells["edges"])
    else:
        raise ValueError("the input topology has no elements: SOFA's BarycentricMapping maps nothing")
    present = [k for k in kinds if len(cells[k])]
    frames = _concat_frames([_frames(points, k, cells[k], failed="zeros") for k in present])
    best, _, v = _nearest_everywhere(frames, pts, bound=1e10)
    if (best < 0).any():
        raise ValueError(
            f"point {int(np.flatnonzero(best < 0)[0])} is too far from every element (SOFA fails on it)"
        )
    k = 8 if "hexahedra" in present else 4 if ("tetrahedra" in present or "quads" in present) else 3
    indices = np.zeros((len(pts), k), dtype=np.int64)
    weights = np.zeros((len(pts), k))
    offset = 0
    element = np.zeros(len(pts), dtype=np.int64)
    nodes = np.full(len(pts), k, dtype=np.int64)
    for kind in present:
        count = len(cells[kind])
        rows = np.flatnonzero((best >= offset) & (best < offset + count))
        local = best[rows] - offset
        coords = v[rows, : _COORDS[kind]]
        order = _HEXA_ORDER_MESH if kind == "hexahedra" else _QUAD_ORDER_MESH if kind == "quads" else None
        idx, w = _linear_map(cells[kind], local, _WEIGHTS[kind](coords), order, k)
        indices[rows], weights[rows], element[rows] = idx, w, best[rows]
        nodes[rows] = cells[kind].shape[1]
        offset += count
    kind = "+".join(present)
    coords = v[:, : _COORDS[present[0]]]
    padded = nodes if bool((nodes < k).any()) else None
    return Embedding(kind, element, coords, indices, weights, _degenerate_note(frames), padded)


def _map_mesh_edges(points: np.ndarray, pts: np.ndarray, edges: np.ndarray) -> Embedding:
    """BarycentricMapperMeshTopology::init on edges: the first edge whose projection parameter is in
    [0, 1], else the last edge (with its parameter)."""
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    axis = b - a
    length = np.sqrt(_norm2(axis))
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where((length > EPSILON)[:, None], axis / length[:, None], axis)
        rel = pts[:, None, :] - a[None, :, :]
        coef = (
            unit[None, :, 0] * rel[..., 0] + unit[None, :, 1] * rel[..., 1] + unit[None, :, 2] * rel[..., 2]
        ) / length
    inside = (coef >= 0) & (coef <= 1)
    element = np.where(inside.any(axis=1), np.argmax(inside, axis=1), len(edges) - 1)
    fx = coef[np.arange(len(pts)), element]
    weights = np.stack([1 - fx, fx], axis=1)
    indices, weights = _linear_map(edges, element, weights, None, 2)
    return Embedding("edges", element, fx[:, None], indices, weights)


def _cell_size(points: np.ndarray, elements: np.ndarray, edges: np.ndarray) -> float:
    """computeHashingCellSize: the mean length of the topology's edges (else of element sides 0-1)."""
    pairs = edges if len(edges) else elements[:, :2]
    lengths = np.sqrt(_norm2(points[pairs[:, 0]] - points[pairs[:, 1]]))
    return float(np.add.accumulate(lengths)[-1]) / float(len(pairs))


def _map_container(
    points: np.ndarray, pts: np.ndarray, kind: str, elements: np.ndarray, edges: np.ndarray
) -> Embedding:
    """BarycentricMapperTopologyContainer::init (spatial hashing)."""
    frames = _frames(points, kind, elements, failed="rows")
    size = _cell_size(points, elements, edges)
    if not size > 0 or not math.isfinite(size):
        raise ValueError(f"the input {kind} have zero mean edge length: SOFA's hashing grid is undefined")
    conv = 1.0 / size
    corners = points[elements]  # (m, nodes, 3)
    low = np.floor(corners.min(axis=1) * conv).astype(np.int64)
    high = np.floor(corners.max(axis=1) * conv).astype(np.int64)
    spans = high - low + 1
    counts = spans.prod(axis=1)
    if counts.sum() > 20_000_000:
        raise ValueError(
            f"the input {kind} span {int(counts.sum())} hashing cells (elements much larger than the mean "
            "edge length): too many to build SOFA's hash table"
        )
    owner = np.repeat(np.arange(len(elements)), counts)
    local = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    sz = spans[owner, 2]
    sy = spans[owner, 1]
    keys = low[owner] + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], axis=1)
    order = np.lexsort((owner, keys[:, 2], keys[:, 1], keys[:, 0]))
    keys, owner = keys[order], owner[order]
    starts = np.flatnonzero(np.r_[True, (np.diff(keys, axis=0) != 0).any(axis=1)])
    ends = np.r_[starts[1:], len(keys)]
    table = {tuple(keys[s].tolist()): owner[s:e] for s, e in zip(starts, ends, strict=True)}

    cells = np.floor(pts * conv).astype(np.int64)
    element = np.full(len(pts), -1, dtype=np.int64)
    coords = np.zeros((len(pts), 3))
    exhaustive = []  # points whose own cell has no (usable) element: compared with every element
    unique, group = np.unique(cells, axis=0, return_inverse=True)
    group = group.reshape(-1)
    members = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[members], np.arange(len(unique) + 1))
    neighbours = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    for g, cell in enumerate(unique.tolist()):
        rows = members[bounds[g] : bounds[g + 1]]
        own = table.get(tuple(cell))
        if own is None:
            exhaustive.append(rows)
            continue
        best, dist, v = _nearest(frames, pts[rows], own)
        exhaustive.append(rows[best < 0])
        rows, best, dist, v = rows[best >= 0], best[best >= 0], dist[best >= 0], v[best >= 0]
        chosen = own[best]
        wide = np.abs(dist) > size / 2.0  # the nearest in the cell may not be the best: look around
        if wide.any():
            around = [table.get((cell[0] + x, cell[1] + y, cell[2] + z)) for x, y, z in neighbours]
            cand = np.concatenate([own, *[c for c in around if c is not None]])
            b3, _, v3 = _nearest(frames, pts[rows[wide]], cand)
            chosen[wide], v[wide] = cand[b3], v3
        element[rows], coords[rows] = chosen, v
    rest = np.concatenate(exhaustive) if exhaustive else np.zeros(0, dtype=np.int64)
    if len(rest):
        best, _, v = _nearest_everywhere(frames, pts[rest])
        element[rest], coords[rest] = best, v
    if (element < 0).any():
        raise ValueError(
            f"point {int(np.flatnonzero(element < 0)[0])} could not be attached to any {kind[:-1]}"
        )
    coords = coords[:, : _COORDS[kind]]
    indices, weights = _linear_map(elements, element, _WEIGHTS[kind](coords), None, elements.shape[1])
    return Embedding(kind, element, coords, indices, weights, _degenerate_note(frames))


def barycentric_embedding(
    input_positions: Any,
    points: Any,
    *,
    tetrahedra: Any = None,
    hexahedra: Any = None,
    triangles: Any = None,
    quads: Any = None,
    edges: Any = None,
    grid: RegularGrid | SparseGrid | None = None,
    topology: str = "mesh",
) -> Embedding:
    """The element and coordinates SOFA's BarycentricMapping gives each of ``points`` at init.

    ``input_positions``: the input state's positions at init (its rest positions with
    ``useRestPosition``), (N, 3); ``points``: the output state's, (n, 3). Element arrays: the input
    topology's. ``edges``: the topology's own edge list, if it has one (the dynamic mapper's hashing
    cell is the mean edge length; with ``None`` the edges SOFA derives from the elements are used; an
    edge-only static mesh maps onto them). ``grid``: the RegularGridTopology / SparseGridTopology
    (then the element arrays are ignored). ``topology``: ``"mesh"`` for MeshTopology and other static
    topologies, ``"dynamic"`` for the *SetTopologyContainer family. See the module doc for the rules.
    """
    src = np.asarray(input_positions, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"input positions must have shape (N, 3), not {src.shape}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 1 and pts.size % 3 == 0:
        pts = pts.reshape(-1, 3)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"mapped points must have shape (n, 3), not {pts.shape}")
    if not (np.isfinite(src).all() and np.isfinite(pts).all()):
        raise ValueError("positions must be finite")
    if isinstance(grid, RegularGrid):
        embedding = _map_regular_grid(grid, pts)
    elif isinstance(grid, SparseGrid):
        embedding = _map_sparse_grid(grid, pts)
    elif grid is not None:
        raise TypeError(f"grid must be a RegularGrid or a SparseGrid, not {type(grid).__name__}")
    else:
        n = len(src)
        cells = {
            "tetrahedra": as_cells(tetrahedra, "tetrahedra", n),
            "hexahedra": as_cells(hexahedra, "hexahedra", n),
            "triangles": as_cells(triangles, "triangles", n),
            "quads": as_cells(quads, "quads", n),
            "edges": as_cells(edges, "edges", n),
        }
        if topology == "mesh":
            embedding = _map_mesh(src, pts, cells)
        elif topology == "dynamic":
            kind = next((k for k in ("hexahedra", "tetrahedra", "quads", "triangles") if len(cells[k])), None)
            if kind is None:
                raise ValueError(
                    "the input container has no hexahedra, tetrahedra, quads or triangles "
                    "(SOFA's edge-set barycentric mapper is not implemented)"
                )
            own_edges = cells["edges"]
            if len(own_edges) == 0:
                own_edges = topology_edges(n, **{kind: cells[kind]})
            embedding = _map_container(src, pts, kind, cells[kind], own_edges)
        else:
            raise ValueError(f"topology must be 'mesh' or 'dynamic', not {topology!r}")
    if len(embedding.indices) and embedding.indices.max() >= len(src):
        raise ValueError(
            f"the mapping uses input point {int(embedding.indices.max())} but the input state has {len(src)}"
        )
    return embedding


def barycentric_map(
    input_rest_positions: Any,
    points: Any,
    *,
    tetrahedra: Any = None,
    hexahedra: Any = None,
    triangles: Any = None,
    quads: Any = None,
    edges: Any = None,
    grid: RegularGrid | SparseGrid | None = None,
    topology: str = "mesh",
) -> tuple[np.ndarray, np.ndarray]:
    """``(indices, weights)``, (n, k) int64 / float64: mapped point i is
    ``sum_j weights[i, j] * input[indices[i, j]]``; see ``barycentric_embedding``."""
    embedding = barycentric_embedding(
        input_rest_positions,
        points,
        tetrahedra=tetrahedra,
        hexahedra=hexahedra,
        triangles=triangles,
        quads=quads,
        edges=edges,
        grid=grid,
        topology=topology,
    )
    return embedding.indices, embedding.weights


def embed_cells(
    input_rest_positions: Any,
    points: Any,
    cells: dict[str, np.ndarray],
    *,
    mode: str,
    grid: RegularGrid | SparseGrid | None = None,
) -> Embedding:
    """:func:`barycentric_embedding` with a topology's element arrays by name (``edges``,
    ``triangles``, ``quads``, ``tetrahedra``, ``hexahedra``) and the mapper mode of :func:`mapper_for`."""
    return barycentric_embedding(
        input_rest_positions,
        points,
        tetrahedra=cells.get("tetrahedra"),
        hexahedra=cells.get("hexahedra"),
        triangles=cells.get("triangles"),
        quads=cells.get("quads"),
        edges=cells.get("edges"),
        grid=grid,
        topology="dynamic" if mode == "dynamic" else "mesh",
    )
