"""Compile-time evaluation of data-producing components: loaders, grid generators, BoxROI.

SOFA computes these at init; their outputs (positions, elements, selected indices) are pure
functions of the scene, so sofac evaluates them once, in the front end. The checker uses them to
check sizes and indices; later stages use them as the arrays handed to the compiled module.
Each evaluator is named by a component spec's ``compute`` attribute.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from sofac import limits
from sofac.front import meshes
from sofac.registry.components.topology import CONTAINERS


class EvaluationError(Exception):
    """An output could not be computed; ``attribute`` names the field at fault."""

    def __init__(self, message: str, attribute: str | None = None, code: str = "E219") -> None:
        super().__init__(message)
        self.attribute = attribute
        self.code = code


class MissingFile(EvaluationError):
    """The input file is missing: the checker reports that once, for the file (E219)."""


class UnknownInput(Exception):
    """An input exists but its value cannot be known before run time; outputs stay unknown."""


class Context(Protocol):
    """What an evaluator may ask of the checker about the component it evaluates."""

    def value(self, name: str) -> Any: ...

    def given(self, name: str) -> Any: ...

    def is_set(self, name: str) -> bool: ...

    def file(self, name: str) -> Path | None: ...

    def input_positions(self, name: str = "position") -> np.ndarray | None:
        """The points an engine reads: its field ``name`` when set (or linked by src=), else its
        state's initial positions."""
        ...

    def context_topology(self, name: str) -> tuple[str, Any] | None:
        """The topology found in the component's node or above: its component name and field ``name``."""
        ...

    def linked(self, link: str, name: str) -> Any:
        """The value of field ``name`` of the component the link field ``link`` points to."""
        ...

    def linked_type(self, link: str) -> str | None:
        """The component name (its spec's) the link field ``link`` points to, if any."""
        ...


Outputs = dict[str, np.ndarray]


def _transform(ctx: Context, points: np.ndarray) -> np.ndarray:
    scale = np.asarray(ctx.value("scale3d"), dtype=float)
    legacy = ctx.value("scale") if ctx.is_set("scale") else None
    if legacy is not None and np.size(legacy) == 1:  # MeshLoader::parse: scale3d *= scale
        scale = scale * float(np.asarray(legacy, dtype=float).ravel()[0])
    return meshes.apply_transform(
        points,
        translation=np.asarray(ctx.value("translation"), dtype=float),
        rotation_deg=np.asarray(ctx.value("rotation"), dtype=float),
        scale=scale,
        loader=True,
    )


def _file(ctx: Context) -> Path:
    path = ctx.file("filename")
    if path is None:
        raise MissingFile("no readable file", "filename")
    return path


def mesh_loader(ctx: Context) -> Outputs:
    try:
        mesh = meshes.read_mesh(_file(ctx))
    except meshes.MeshError as error:
        raise EvaluationError(str(error), "filename") from None
    cells = {kind: getattr(mesh, kind) for kind in ("edges", "triangles", "quads", "tetrahedra", "hexahedra")}
    cells = update_elements(cells, bool(ctx.value("createSubelements")))
    return {
        "position": _transform(ctx, mesh.positions).ravel(),
        **{kind: value.ravel() for kind, value in cells.items()},
    }


# MeshLoader::updateElements: the boundary elements of each kind, in its order.
_HEXAHEDRON_QUADS = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
_TETRAHEDRON_TRIANGLES = ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3))


def _append_missing(cells: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``cells`` followed by the faces (rows, in order) no cell nor earlier face has, compared as
    sets of corners (MeshLoader's uniqueOrder keys)."""
    seen = {tuple(sorted(cell)) for cell in cells.tolist()}
    added = []
    for face in faces.tolist():
        key = tuple(sorted(face))
        if key not in seen:
            seen.add(key)
            added.append(face)
    if not added:
        return cells
    return np.concatenate([cells, np.asarray(added, dtype=np.int64)]).astype(np.int64)


def update_elements(cells: dict[str, np.ndarray], create_subelements: bool) -> dict[str, np.ndarray]:
    """SOFA's MeshLoader::updateElements with createSubelements: the quads of the hexahedra
    missing from the quads, the triangles of the tetrahedra missing from the triangles, then the
    edges (t[j+1], t[j+2]) of the quads and then of the triangles missing from the edges, each kind
    appended in element order. (MeshGmshLoader turns it on unless the scene sets it.)"""
    if not create_subelements:
        return cells
    out = {kind: np.asarray(value, dtype=np.int64) for kind, value in cells.items()}
    for volume, surface, faces in (
        ("hexahedra", "quads", _HEXAHEDRON_QUADS),
        ("tetrahedra", "triangles", _TETRAHEDRON_TRIANGLES),
    ):
        if len(out[volume]):
            found = out[volume][:, np.asarray(faces)].reshape(-1, len(faces[0]))
            out[surface] = _append_missing(out[surface], found)
    for surface in ("quads", "triangles"):
        elements = out[surface]
        if len(elements):
            corners = elements.shape[1]
            order = [[(j + 1) % corners, (j + 2) % corners] for j in range(corners)]
            out["edges"] = _append_missing(out["edges"], elements[:, order].reshape(-1, 2))
    return out


def string_mesh(ctx: Context) -> Outputs:
    """StringMeshCreator: ``resolution`` points x / (resolution - 1) on the x axis, edges (i-1, i)."""
    count = int(ctx.value("resolution"))
    if count < 2:
        raise EvaluationError("resolution must be >= 2", "resolution")
    refused = limits.too_many_points([count])
    if refused:
        raise EvaluationError(f"resolution: {refused}", "resolution", code="E207")
    points = np.zeros((count, 3))
    points[:, 0] = [(x * 1.0) / (count - 1) for x in range(count)]
    edges = np.array([[e - 1, e] for e in range(1, count)], dtype=np.int64)
    empty = np.zeros(0, dtype=np.int64)
    return {
        "position": _transform(ctx, points).ravel(),
        "edges": edges.ravel(),
        "triangles": empty,
        "quads": empty,
        "tetrahedra": empty,
        "hexahedra": empty,
    }


def grid_mesh(ctx: Context) -> Outputs:
    """GridMeshCreator::doLoad: points x / (nx - 1), y / (ny - 1), 0, x fastest; per cell (x, y),
    y outer, the quad or the two triangles of the pattern; the edges of those elements as its
    std::set keeps them: (a, b) unless (b, a) is there already, sorted."""
    nx, ny = (int(v) for v in _numbers(ctx, "resolution", 2, integer=True))
    if nx < 2 or ny < 2:
        raise EvaluationError("resolution must be >= 2 along x and y", "resolution", code="E207")
    refused = limits.too_many_points([nx, ny])
    if refused:
        raise EvaluationError(f"resolution: {refused}", "resolution", code="E207")
    points = np.array(
        [[(x * 1.0) / (nx - 1), (y * 1.0) / (ny - 1), 0.0] for y in range(ny) for x in range(nx)]
    )

    def vert(x: int, y: int) -> int:
        return x + y * nx

    pattern = int(ctx.value("trianglePattern"))
    quads: list[tuple[int, ...]] = []
    triangles: list[tuple[int, ...]] = []
    for y in range(ny - 1):
        for x in range(nx - 1):
            a, b, c, d = vert(x, y), vert(x + 1, y), vert(x + 1, y + 1), vert(x, y + 1)
            if pattern == 0:
                quads.append((a, b, c, d))
            elif pattern == 2 or (pattern == 1 and (x + y) % 2 == 0):  # upward
                triangles += [(a, b, c), (a, c, d)]
            elif pattern in (1, 3):  # downward
                triangles += [(a, b, d), (b, c, d)]
    unique: set[tuple[int, int]] = set()
    for element in [*triangles, *quads]:  # one pattern at a time: never both
        for k in range(len(element)):
            a, b = element[k], element[(k + 1) % len(element)]
            if (b, a) not in unique:
                unique.add((a, b))
    cells = {
        "edges": np.asarray(sorted(unique), dtype=np.int64).reshape(-1, 2),
        "triangles": np.asarray(triangles, dtype=np.int64).reshape(-1, 3),
        "quads": np.asarray(quads, dtype=np.int64).reshape(-1, 4),
        "tetrahedra": np.zeros((0, 4), dtype=np.int64),
        "hexahedra": np.zeros((0, 8), dtype=np.int64),
    }
    cells = update_elements(cells, bool(ctx.value("createSubelements")))
    return {
        "position": _transform(ctx, points).ravel(),
        **{kind: value.ravel() for kind, value in cells.items()},
    }


def sphere_loader(ctx: Context) -> Outputs:
    try:
        spheres = meshes.read_spheres(_file(ctx))
    except meshes.MeshError as error:
        raise EvaluationError(str(error), "filename") from None
    return {"position": spheres.centers.ravel(), "listRadius": spheres.radii}


def _numbers(ctx: Context, name: str, count: int, *, integer: bool = False) -> np.ndarray:
    """``count`` finite numbers of field ``name`` (integers if ``integer``), checked here because
    a linked value can be anything (written values are checked when they are parsed)."""
    value = ctx.value(name)
    if value is None:
        raise EvaluationError(
            f"{name} has no value known when the scene is compiled (a link cycle, or a Data computed at "
            "run time); give the numbers",
            name,
            code="E213",
        )
    try:
        numbers = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise EvaluationError(f"{name} is not a list of numbers", name, code="E204") from None
    if numbers.size != count:
        raise EvaluationError(f"{name} needs {count} numbers, its value has {numbers.size}", name, "E205")
    if not np.isfinite(numbers).all():
        raise EvaluationError(f"{name} has a value that is not finite", name, code="E206")
    if integer and (numbers != np.round(numbers)).any():
        raise EvaluationError(f"{name} needs whole numbers, got {numbers.tolist()}", name, code="E204")
    return numbers


_LEGACY_COUNTS = ("nx", "ny", "nz")


def _grid_counts(ctx: Context) -> np.ndarray:
    """A grid's resolution: n, or the legacy nx ny nz (1 for one not given)."""
    if any(ctx.is_set(name) for name in _LEGACY_COUNTS):
        counts = np.array(
            [int(_numbers(ctx, n, 1, integer=True)[0]) if ctx.is_set(n) else 1 for n in _LEGACY_COUNTS],
            dtype=np.int64,
        )
    else:
        counts = np.array([int(c) for c in _numbers(ctx, "n", 3, integer=True)], dtype=np.int64)
    if (counts < 1).any():
        raise EvaluationError(f"grid resolution {counts.tolist()} must be >= 1 per axis", "n", code="E207")
    refused = limits.too_many_points(counts.tolist())
    if refused:
        legacy = any(ctx.is_set(name) for name in _LEGACY_COUNTS)
        attribute = _LEGACY_COUNTS[int(np.argmax(counts))] if legacy else "n"
        raise EvaluationError(f"grid resolution {refused}", attribute, code="E207")
    return counts


def grid_topology(ctx: Context) -> Outputs:
    """GridTopology (no geometry): GridUpdate's elements for the resolution, and its points as SOFA's
    getPoint(i) gives them (what computePointList copies and a MechanicalObject without positions
    reads): its own `position` list resized to nx ny nz points, 0 0 0 past its end; without
    `position`, every point at the origin (the MechanicalObject then usually gives positions)."""
    counts = _grid_counts(ctx)
    cells = _grid_update(counts, {flag: ctx.value(flag) is not False for flag in _GRID_FLAGS})
    outputs: Outputs = {"resolution": counts.astype(np.int64), **cells}
    given = ctx.given("position")
    flat = np.asarray(given if given is not None else [], dtype=float).ravel()
    points = np.zeros((int(np.prod(counts)), 3))
    known = flat[: (flat.size // 3) * 3].reshape(-1, 3)[: len(points)]
    points[: len(known)] = known
    outputs["position"] = points.ravel()
    return outputs


def grid(ctx: Context) -> Outputs:
    """RegularGridTopology points: index = x + nx (y + ny z)."""
    counts = _grid_counts(ctx)
    legacy_bounds = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
    if all(ctx.is_set(name) for name in legacy_bounds):
        # SOFA reads the legacy bounds as single-precision floats.
        with np.errstate(over="ignore"):  # a bound past the float range: the points check reports it
            bounds = np.array([float(np.float32(_numbers(ctx, name, 1)[0])) for name in legacy_bounds])
        low, high = bounds[:3], bounds[3:]
    else:
        low = _numbers(ctx, "min", 3)
        high = _numbers(ctx, "max", 3)
    from sofac.geometry.barycentric import RegularGrid  # SOFA's grid geometry: p0 + i dx + j dy + k dz

    # p0, when the scene sets it, replaces the origin setPos derives from min (SOFA's d_p0.isSet())
    p0 = tuple(map(float, _numbers(ctx, "p0", 3))) if ctx.is_set("p0") else None
    lattice = RegularGrid(
        tuple(int(c) for c in counts), tuple(map(float, low)), tuple(map(float, high)), p0=p0
    )
    with np.errstate(all="ignore"):  # bounds near the float range: said below, not warned about
        points = lattice.points()
    if not np.isfinite(points).all():
        legacy = all(ctx.is_set(name) for name in legacy_bounds)
        raise EvaluationError(
            "the grid's points are not finite: its bounds are too large"
            + (" for the single-precision numbers SOFA reads xmin..zmax as" if legacy else ""),
            "xmin" if legacy else "min",
            code="E206",
        )
    cells = _grid_update(counts, {flag: ctx.value(flag) is not False for flag in _GRID_FLAGS})
    return {
        "position": points.ravel(),
        "resolution": counts.astype(np.int64),
        "bounds": np.concatenate([low, high]).astype(float),
        # the Data SOFA's parse writes from the legacy nx ny nz / xmin..zmax, which another grid's
        # src= reads (Component/Visual/DataDisplay.scn)
        "n": counts.astype(np.int64),
        "min": np.asarray(low, dtype=float),
        "max": np.asarray(high, dtype=float),
        **cells,
    }


def cube_topology(ctx: Context) -> Outputs:
    """CubeTopology (without splitNormals): the points of the box's surface (all grid points with
    internalPoints, or when an axis has one point), p0 + i dx + j dy + k dz, numbered as
    SOFA's getPoint; its edges along the surface and its quads, in SOFA's order (updateEdges/updateQuads)."""
    n = [
        int(_numbers(ctx, name, 1, integer=True)[0]) if ctx.is_set(name) else 0 for name in ("nx", "ny", "nz")
    ]
    if ctx.value("splitNormals"):
        return {}
    if any(c < 1 for c in n):
        raise EvaluationError(f"CubeTopology resolution {n} must be >= 1 per axis", "nx", code="E207")
    refused = limits.too_many_points(n)
    if refused:
        raise EvaluationError(f"cube resolution {refused}", "nx", code="E207")
    nx, ny, nz = n
    legacy_bounds = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
    if all(ctx.is_set(name) for name in legacy_bounds):
        # SOFA's parse reads them (and scale) as single-precision floats, multiplied in float
        scale = np.float32(_numbers(ctx, "scale", 1)[0]) if ctx.is_set("scale") else np.float32(1.0)
        bounds = [float(np.float32(np.float32(_numbers(ctx, b, 1)[0]) * scale)) for b in legacy_bounds]
        low, high = bounds[:3], bounds[3:]
    else:
        low = [float(v) for v in _numbers(ctx, "min", 3)]
        high = [float(v) for v in _numbers(ctx, "max", 3)]
    step = [(high[k] - low[k]) / (n[k] - 1) if n[k] > 1 else 0.0 for k in range(3)]
    surface = not ctx.value("internalPoints") and nx > 1 and ny > 1 and nz > 1

    def index(x: int, y: int, z: int) -> int:  # CubeTopology::point
        if not surface:
            return x + nx * (y + ny * z)
        if z == 0:
            return x + nx * y
        if z == nz - 1:
            return x + nx * (y + ny)
        base = nx * ny * 2 + (2 * nx + 2 * ny - 4) * (z - 1)
        if y == 0:
            return base + x
        if y == ny - 1:
            return base + x + nx
        if x == 0:
            return base + 2 * nx + (y - 1)
        return base + 2 * nx + (ny - 2) + (y - 1)

    count = nx * ny * 2 + (nz - 2) * (2 * nx + 2 * ny - 4) if surface else nx * ny * nz
    points = np.zeros((count, 3))
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                if surface and 0 < z < nz - 1 and 0 < y < ny - 1 and 0 < x < nx - 1:
                    continue
                points[index(x, y, z)] = [low[k] + step[k] * (x, y, z)[k] for k in range(3)]
    edges = []
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                if x < nx - 1 and (y in (0, ny - 1) or z in (0, nz - 1)):
                    edges.append((index(x, y, z), index(x + 1, y, z)))
                if y < ny - 1 and (x in (0, nx - 1) or z in (0, nz - 1)):
                    edges.append((index(x, y, z), index(x, y + 1, z)))
                if z < nz - 1 and (x in (0, nx - 1) or y in (0, ny - 1)):
                    edges.append((index(x, y, z), index(x, y, z + 1)))
    quads = []
    for y in range(ny - 1):
        for x in range(nx - 1):
            quads.append((index(x, y, 0), index(x, y + 1, 0), index(x + 1, y + 1, 0), index(x + 1, y, 0)))
    if nz > 1:
        for y in range(ny - 1):
            for x in range(nx - 1):
                z = nz - 1
                quads.append((index(x, y, z), index(x + 1, y, z), index(x + 1, y + 1, z), index(x, y + 1, z)))
    for z in range(nz - 1):
        for x in range(nx - 1):
            quads.append((index(x, 0, z), index(x + 1, 0, z), index(x + 1, 0, z + 1), index(x, 0, z + 1)))
    if ny > 1:
        for z in range(nz - 1):
            for x in range(nx - 1):
                y = ny - 1
                quads.append((index(x, y, z), index(x, y, z + 1), index(x + 1, y, z + 1), index(x + 1, y, z)))
    for z in range(nz - 1):
        for y in range(ny - 1):
            quads.append((index(0, y, z), index(0, y, z + 1), index(0, y + 1, z + 1), index(0, y + 1, z)))
    if nx > 1:
        for z in range(nz - 1):
            for y in range(ny - 1):
                x = nx - 1
                quads.append((index(x, y, z), index(x, y + 1, z), index(x, y + 1, z + 1), index(x, y, z + 1)))
    return {
        "position": points.ravel(),
        "edges": np.asarray(edges, dtype=np.int64).reshape(-1),
        "quads": np.asarray(quads, dtype=np.int64).reshape(-1),
    }


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges of triangles as SOFA's createEdgeSetArray makes them: for each triangle t and
    j = 0, 1, 2 the edge (t[j+1], t[j+2]) (indices mod 3), in the order first met, once each."""
    ends = np.stack([triangles[:, [1, 2]], triangles[:, [2, 0]], triangles[:, [0, 1]]], axis=1).reshape(-1, 2)
    keys = np.sort(ends, axis=1)
    _, first = np.unique(keys, axis=0, return_index=True)
    return ends[np.sort(first)]


_GRID_FLAGS = ("computeHexaList", "computeQuadList", "computeTriangleList", "computeEdgeList")


def _grid_update(counts: np.ndarray, flags: dict[str, bool]) -> dict[str, np.ndarray]:
    """The elements SOFA's GridTopology::GridUpdate makes, in its order, for a grid of any
    dimension: hexahedra; quads in the XY, then XZ, then YZ planes; triangles (q0 q1 q2) (q0 q2 q3)
    of each quad (made from the quads even without computeQuadList); edges from those triangles as
    createEdgeSetArray does, or, without triangles, the grid lines along X, then Y, then Z."""
    nx, ny, nz = (int(c) for c in counts)

    def point(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        return x + nx * (y + ny * z)

    def lattice(sx: int, sy: int, sz: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x fastest, then y, then z: SOFA's loops over x < sx, y < sy, z < sz."""
        z, y, x = np.meshgrid(
            np.arange(max(sz, 0)), np.arange(max(sy, 0)), np.arange(max(sx, 0)), indexing="ij"
        )
        return x.ravel(), y.ravel(), z.ravel()

    cells: dict[str, np.ndarray] = {}
    if flags["computeHexaList"]:
        x, y, z = lattice(nx - 1, ny - 1, nz - 1)
        corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        if len(x):
            cells["hexahedra"] = np.stack([point(x + a, y + b, z + c) for a, b, c in corners], axis=1).ravel()
    quads = np.zeros((0, 4), dtype=np.int64)
    if flags["computeQuadList"] or flags["computeTriangleList"]:
        planes = []
        x, y, z = lattice(nx - 1, ny - 1, nz)  # XY
        planes.append(
            np.stack([point(x, y, z), point(x + 1, y, z), point(x + 1, y + 1, z), point(x, y + 1, z)], 1)
        )
        x, y, z = lattice(nx - 1, ny, nz - 1)  # XZ
        planes.append(
            np.stack([point(x, y, z), point(x + 1, y, z), point(x + 1, y, z + 1), point(x, y, z + 1)], 1)
        )
        x, y, z = lattice(nx, ny - 1, nz - 1)  # YZ
        planes.append(
            np.stack([point(x, y, z), point(x, y + 1, z), point(x, y + 1, z + 1), point(x, y, z + 1)], 1)
        )
        quads = np.concatenate(planes).astype(np.int64).reshape(-1, 4)
        if len(quads):
            cells["quads"] = quads.ravel()
    triangles = np.zeros((0, 3), dtype=np.int64)
    if flags["computeTriangleList"] and len(quads):
        triangles = np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
        cells["triangles"] = triangles.ravel()
    if flags["computeEdgeList"]:
        if len(triangles):
            edges = triangle_edges(triangles)
        else:
            lines = []
            x, y, z = lattice(nx - 1, ny, nz)
            lines.append(np.stack([point(x, y, z), point(x + 1, y, z)], 1))
            x, y, z = lattice(nx, ny - 1, nz)
            lines.append(np.stack([point(x, y, z), point(x, y + 1, z)], 1))
            x, y, z = lattice(nx, ny, nz - 1)
            lines.append(np.stack([point(x, y, z), point(x, y, z + 1)], 1))
            edges = np.concatenate(lines).astype(np.int64).reshape(-1, 2)
        if len(edges):
            cells["edges"] = edges.ravel()
    return {kind: np.asarray(value, dtype=np.int64) for kind, value in cells.items()}


def _grid_cells(counts: np.ndarray) -> dict[str, np.ndarray]:
    """The cells of a grid, corners in SOFA's order: hexahedra (3-D), quads (2-D) or edges (1-D)."""
    nx, ny, nz = (int(c) for c in counts)

    def index(i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        return i + nx * (j + ny * k)

    live = [axis for axis, n in enumerate((nx, ny, nz)) if n > 1]
    ranges = [np.arange(max(n - 1, 1)) if n > 1 else np.zeros(1, dtype=np.int64) for n in (nx, ny, nz)]
    k, j, i = (a.ravel() for a in np.meshgrid(ranges[2], ranges[1], ranges[0], indexing="ij"))
    steps = [np.array(d) for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1))]
    if len(live) == 3:
        corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        cells = np.stack([index(i + a, j + b, k + c) for a, b, c in corners], axis=1)
        return {"hexahedra": cells.astype(np.int64).ravel()}
    if len(live) == 2:
        u, v = (steps[a] for a in live)
        corners = [0 * u, u, u + v, v]
        cells = np.stack([index(i + c[0], j + c[1], k + c[2]) for c in corners], axis=1)
        return {"quads": cells.astype(np.int64).ravel()}
    if len(live) == 1:
        u = steps[live[0]]
        cells = np.stack([index(i, j, k), index(i + u[0], j + u[1], k + u[2])], axis=1)
        return {"edges": cells.astype(np.int64).ravel()}
    return {}


def _voxel_surface(ctx: Context) -> meshes.Mesh:
    """The surface a sparse grid voxelises: its fileTopology, an .obj mesh."""
    path = ctx.file("filename")
    if path is None:
        if ctx.is_set("filename"):
            raise MissingFile("no readable file", "filename")
        raise EvaluationError(
            "building the grid from position/triangles/facets (no fileTopology) is not supported yet; "
            'give the surface as fileTopology="mesh.obj"',
            "position" if ctx.is_set("position") else None,
            code="E222",
        )
    if path.suffix.lower() != ".obj":
        raise EvaluationError(
            f"voxelising {path.suffix or 'extensionless'} files is not supported yet (only .obj "
            "surfaces; .raw/.voxel voxel files and other formats are not); convert the surface to .obj",
            "filename",
            code="E222",
        )
    try:
        mesh = meshes.read_mesh(path)
    except meshes.MeshError as error:
        raise EvaluationError(str(error), "filename") from None
    given = [name for name in ("position", "edges", "triangles", "quads", "hexahedra") if ctx.is_set(name)]
    if given:  # SOFA clears the points but appends its cells to the given ones: not reproduced
        raise EvaluationError(
            f"{given[0]} given with fileTopology is not supported (SOFA mixes it with the voxelised "
            "grid); remove it",
            given[0],
            code="E222",
        )
    return mesh


def _triple(ctx: Context, name: str) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in np.asarray(ctx.value(name), dtype=float).ravel()[:3])
    return x, y, z


_EMPTY_GRID = (
    "the surface encloses no cell of the grid (SOFA leaves the topology invalid); "
    "check the mesh and n/min/max"
)


def sparse_grid(ctx: Context) -> Outputs:
    """SparseGridTopology voxelising a surface mesh file (see voxelize.py): its points and hexahedra,
    plus what its barycentric mapper needs (the regular grid, each regular cube's sparse index or -1,
    which sparse cubes are BOUNDARY). Like SOFA's, it derives no edges, triangles or quads."""
    from sofac.geometry import voxelize

    levels = int(ctx.value("nbVirtualFinerLevels") or 0)
    if levels:
        raise EvaluationError(
            f"nbVirtualFinerLevels={levels} (virtual finer grids) is not supported yet; remove it",
            "nbVirtualFinerLevels",
            code="E222",
        )
    mesh = _voxel_surface(ctx)
    try:
        nx, ny, nz = (int(c) for c in _triple(ctx, "n"))
        grid = voxelize.regular_grid(
            mesh.positions,
            (nx, ny, nz),
            _triple(ctx, "min"),
            _triple(ctx, "max"),
            float(ctx.value("cellWidth") or 0.0),
        )
        triangles = voxelize.triangulate(mesh.triangles, mesh.quads)
        voxels = voxelize.classify(grid, mesh.positions, triangles)
    except voxelize.VoxelError as error:
        raise EvaluationError(str(error), error.attribute, code="E207") from None
    sparse = voxelize.sparse_grid(voxels, only_inside=bool(ctx.value("onlyInsideCells")))
    if not len(sparse.hexahedra):
        raise EvaluationError(_EMPTY_GRID, "filename", code="E207")
    return {
        "position": sparse.points.ravel(),
        "hexahedra": sparse.hexahedra.ravel(),
        "grid_resolution": np.asarray(grid.resolution(), dtype=np.int64),
        "grid_bounds": np.concatenate([grid.min, grid.max]).astype(float),
        "regular_to_sparse": sparse.regular_to_sparse,
        "boundary_cells": sparse.boundary.astype(np.int64),
    }


def sparse_grid_ramification(ctx: Context) -> Outputs:
    """SparseGridRamificationTopology (see ramification.py): the sparse grid's outputs, with the
    hexahedra duplicated where the surface inside a cell is in disconnected pieces, the per-cell
    coefficients SOFA derives through its virtual finer levels, and what its findCube reads (the
    finest grid and each of its cubes' hexahedron)."""
    from sofac.geometry import ramification, voxelize

    mesh = _voxel_surface(ctx)
    try:
        nx, ny, nz = (int(c) for c in _triple(ctx, "n"))
        grid = ramification.ramified_grid(
            mesh.positions,
            mesh.triangles,
            (nx, ny, nz),
            _triple(ctx, "min"),
            _triple(ctx, "max"),
            virtual_levels=int(ctx.value("nbVirtualFinerLevels") or 0),
            finest_connectivity=ctx.value("finestConnectivity") is not False,
            fill_weighted=ctx.value("fillWeighted") is not False,
            only_inside=bool(ctx.value("onlyInsideCells")),
            cell_width=float(ctx.value("cellWidth") or 0.0),
            quads=mesh.quads,
        )
    except voxelize.VoxelError as error:
        raise EvaluationError(str(error), error.attribute, code="E207") from None
    coarse, finest = grid.coarse, grid.finest
    return {
        "position": grid.points.ravel(),
        "hexahedra": grid.hexahedra.ravel(),
        "grid_resolution": np.asarray(coarse.resolution(), dtype=np.int64),
        "grid_bounds": np.concatenate([coarse.min, coarse.max]).astype(float),
        "boundary_cells": grid.boundary.astype(np.int64),
        "cell_coefficients": grid.coefficients.astype(np.float64),
        "finest_grid_resolution": np.asarray(finest.resolution(), dtype=np.int64),
        "finest_grid_bounds": np.concatenate([finest.min, finest.max]).astype(float),
        "finest_to_hexa": grid.finest_to_hexa,
    }


def box_roi(ctx: Context) -> Outputs:
    """Indices (and positions) of the input points inside any of the boxes (xmin ymin zmin xmax ymax
    zmax), and of the elements inside."""
    value = ctx.value("box")
    if value is None or np.size(value) == 0 or np.size(value) % 6:
        # No usable box (missing, or invalid and reported as such): the selection is not known.
        raise UnknownInput("BoxROI has no valid box")
    boxes = np.asarray(value, dtype=float).reshape(-1, 6)
    points = ctx.input_positions()
    if points is None:
        raise EvaluationError("BoxROI has no input positions", "position", code="E212")
    dim = points.shape[1]
    inside = np.zeros(len(points), dtype=bool)
    for box in boxes:
        low, high = box[:3], box[3:]
        padded = np.zeros((len(points), 3))
        padded[:, : min(dim, 3)] = points[:, :3]
        inside |= ((padded >= low) & (padded <= high)).all(axis=1)
    # BoxROI::doUpdate: pointsInROI lists the input points inside, in index order.
    outputs = {
        "indices": np.flatnonzero(inside).astype(np.int64),
        "pointsInROI": np.asarray(points, dtype=float)[inside].ravel(),
        "nbIndices": int(inside.sum()),
    }
    for elements, corners, output in _ROI_ELEMENTS:
        given = ctx.value(elements)
        if given is None or not np.size(given) or not ctx.value(f"compute{elements.capitalize()}"):
            continue
        cells = np.asarray(given, dtype=np.int64).reshape(-1, corners)
        if cells.max() >= len(points):
            raise EvaluationError(f"BoxROI's {elements} use points past its {len(points)} points", elements)
        if ctx.value("strict"):  # every corner inside
            chosen = inside[cells].all(axis=1)
        else:  # the centre inside (SOFA's getCenter: the mean of the corners)
            centres = np.zeros((len(cells), 3))
            centres[:, : min(dim, 3)] = points[cells].mean(axis=1)[:, :3]
            chosen = np.zeros(len(cells), dtype=bool)
            for box in boxes:
                chosen |= ((centres >= box[:3]) & (centres <= box[3:])).all(axis=1)
        outputs[output] = np.flatnonzero(chosen).astype(np.int64)
    return outputs


_HIGHER_CELLS = {
    "edges": ("triangles", "quads", "tetrahedra", "hexahedra"),
    "triangles": ("tetrahedra",),
    "tetrahedra": (),
}


def _engine_cells(ctx: Context, name: str, corners: int, *, from_topology: bool) -> np.ndarray:
    """An engine's element input: its own (given, linked, or by src=), else (``from_topology``)
    the field of the topology in its node or above, as SOFA's init links them. A topology that is
    not given them computes them when it initialises (from its larger elements): a
    TriangleSetTopologyContainer's edges are computed here as it does, the others refused."""
    value = ctx.value(name)
    if value is not None or ctx.is_set(name) or not from_topology:
        return np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1, corners)
    found = ctx.context_topology(name)
    if found is None:
        return np.zeros((0, corners), dtype=np.int64)
    topology, cells = found
    if cells is not None and np.size(cells):
        return np.asarray(cells, dtype=np.int64).reshape(-1, corners)
    if topology == CONTAINERS["Triangle"].name and name == "edges":  # createEdgesInTriangleArray's
        triangles = ctx.context_topology("triangles")
        if triangles is not None and triangles[1] is not None and np.size(triangles[1]):
            return triangle_edges(np.asarray(triangles[1], dtype=np.int64).reshape(-1, 3))
    for larger in _HIGHER_CELLS[name]:
        other = ctx.context_topology(larger)
        if other is not None and other[1] is not None and np.size(other[1]):
            raise EvaluationError(
                f"it reads the {name} {topology} computes from its {larger} when it initialises; "
                f"sofac does not evaluate it on them: give {name}= (e.g. from the loader)",
                None,
                code="E222",
            )
    return np.zeros((0, corners), dtype=np.int64)


def _engine_points(ctx: Context, name: str) -> np.ndarray:
    """An engine's input points: its field ``name`` (given, linked, by src=), else its state's."""
    points = ctx.input_positions(name)
    if points is None:
        raise UnknownInput(f"the {name} points are not known at compile time")
    return np.asarray(points, dtype=float)


def subset_topology(ctx: Context) -> Outputs:
    """SubsetTopology (see geometry.selection.subset_topology): boxes, or spheres when centers is
    set; edges, triangles and tetrahedra default to the context topology's, quads and hexahedra
    are only read when given."""
    from sofac.geometry import selection

    if ctx.is_set("tetrahedraInput"):
        raise EvaluationError("tetrahedraInput is not evaluated yet", "tetrahedraInput", code="E222")
    coords = _engine_points(ctx, "rest_position")
    if ctx.is_set("centers"):
        centers = np.asarray(ctx.value("centers"), dtype=float).reshape(-1, 3)
        radii = np.asarray(ctx.value("radii") if ctx.value("radii") is not None else [], dtype=float).ravel()
        if not len(centers) or len(centers) != len(radii):
            raise EvaluationError(
                f"{len(centers)} centers and {len(radii)} radii: SOFA then selects nothing (it keeps "
                "its defaults); give one radius per centre",
                "radii",
                code="E205",
            )
        inside = selection.in_spheres(coords, centers, radii)
    else:
        boxes = np.asarray(ctx.value("box"), dtype=float).reshape(-1, 6)
        low, high = np.minimum(boxes[:, :3], boxes[:, 3:]), np.maximum(boxes[:, :3], boxes[:, 3:])
        inside = selection.in_boxes(coords, np.concatenate([low, high], axis=1))
    cells = {}
    for kind, corners, *_ in selection.ELEMENT_OUTPUTS:
        cells[kind] = _engine_cells(ctx, kind, corners, from_topology=kind in _HIGHER_CELLS)
        if len(cells[kind]) and cells[kind].max() >= len(coords):
            raise EvaluationError(f"{kind} use points past the {len(coords)} points", kind, code="E218")
    return selection.subset_topology(coords, inside, cells, bool(ctx.value("localIndices")))


def plane_roi(ctx: Context) -> Outputs:
    """PlaneROI (see geometry.selection.in_planes): the points inside one of the slabs, and the
    edges, triangles, tetrahedra (each when its compute flag is on) whose corners all are in one."""
    from sofac.geometry import selection

    value = ctx.value("plane")
    planes = np.asarray(value if value is not None else [], dtype=float).reshape(-1, 10)
    if not len(planes):  # SOFA's doUpdate returns at once: the outputs keep their defaults
        return {"indices": np.zeros(1, dtype=np.int64)}
    coords = _engine_points(ctx, "position")
    inside = selection.in_planes(coords, planes)
    chosen = inside.any(axis=1)
    outputs = {
        "indices": np.flatnonzero(chosen).astype(np.int64),
        "pointsInROI": coords[chosen].ravel(),
    }
    # SOFA's init links the missing inputs to the topology's only when edges or triangles are missing
    linking = not (ctx.is_set("edges") and ctx.is_set("triangles"))
    for kind, corners, index_name, in_name, _ in selection.ELEMENT_OUTPUTS:
        if kind not in _HIGHER_CELLS:
            continue
        flag = f"compute{kind.capitalize()}"
        if not ctx.value(flag):
            continue
        cells = _engine_cells(ctx, kind, corners, from_topology=linking)
        if len(cells) and cells.max() >= len(coords):
            raise EvaluationError(f"{kind} use points past the {len(coords)} points", kind, code="E218")
        selected = inside[cells].all(axis=1).any(axis=1) if len(cells) else np.zeros(0, dtype=bool)
        outputs[index_name] = np.flatnonzero(selected).astype(np.int64)
        outputs[in_name] = cells[selected].ravel()
    return outputs


def pair_box_roi(ctx: Context) -> Outputs:
    """PairBoxROI (see geometry.selection.pair_box)."""
    from sofac.geometry import selection

    coords = _engine_points(ctx, "position")
    inclusive, included = (
        np.asarray(ctx.value(name), dtype=float) for name in ("inclusiveBox", "includedBox")
    )
    indices = selection.pair_box(coords, inclusive, included)
    return {"indices": indices, "pointsInROI": coords[indices].ravel()}


# BoxROI's element inputs, their corner counts and the output listing those inside.
_ROI_ELEMENTS = (
    ("edges", 2, "edgeIndices"),
    ("triangles", 3, "triangleIndices"),
    ("quads", 4, "quadIndices"),
    ("tetrahedra", 4, "tetrahedronIndices"),
    ("hexahedra", 8, "hexahedronIndices"),
)


def hexa_to_tetra(ctx: Context) -> Outputs:
    """Hexa2TetraTopologicalMapping: 6 tetrahedra per input hexahedron, in SOFA's patterns; with
    ``swapping`` the corners are mirrored by the cell's grid parity (a conforming mesh)."""
    from sofac.geometry.fem_topology import HEXA_X_EDGES, HEXA_Y_EDGES, HEXA_Z_EDGES, TETRA_SPLIT

    hexahedra = ctx.linked("input", "hexahedra")
    if hexahedra is None or not np.size(hexahedra):
        raise UnknownInput("the input topology's hexahedra are not known at compile time")
    cells = np.asarray(hexahedra, dtype=np.int64).reshape(-1, 8).copy()
    resolution = ctx.linked("input", "resolution")
    nx, ny = (int(resolution[0]) - 1, int(resolution[1]) - 1) if resolution is not None else (2, 1)
    swaps = np.zeros(len(cells), dtype=np.int64)
    if ctx.value("swapping"):
        index = np.arange(len(cells))
        for mask, edges in (
            ((index % max(nx, 1)) % 2 == 0, HEXA_X_EDGES),
            (((index // max(nx, 1)) % max(ny, 1)) % 2 == 1, HEXA_Y_EDGES),
            ((index // max(nx * ny, 1)) % 2 == 1, HEXA_Z_EDGES),
        ):
            for a, b in edges:
                cells[mask, a], cells[mask, b] = cells[mask, b].copy(), cells[mask, a].copy()
            swaps += mask
    straight = np.array(TETRA_SPLIT, dtype=np.int64)
    mirrored = straight[:, [0, 1, 3, 2]]  # SOFA's swapped pattern: the last two corners exchanged
    tetrahedra = np.where((swaps % 2 == 1)[:, None, None], cells[:, mirrored], cells[:, straight])
    return {"tetrahedra": tetrahedra.reshape(-1)}


def _volume_points(ctx: Context) -> np.ndarray | None:
    """The points of a topological mapping's input elements, when known (to orient surfaces)."""
    try:
        points = ctx.input_positions()
    except UnknownInput:
        return None
    return None if points is None else np.asarray(points, dtype=float)[:, :3]


def _surface(ctx: Context, volume: str, corners: int, faces: Any, surface: str) -> Outputs:
    from sofac.geometry.fem_topology import boundary_faces

    cells = ctx.linked("input", volume)
    if cells is None or not np.size(cells):
        raise UnknownInput(f"the input topology's {volume} are not known at compile time")
    found = boundary_faces(np.asarray(cells, dtype=np.int64).reshape(-1, corners), faces, _volume_points(ctx))
    if ctx.value("flipNormals"):
        found = found[:, ::-1]
    return {surface: found.reshape(-1)}


def tetra_to_triangle(ctx: Context) -> Outputs:
    """Tetra2TriangleTopologicalMapping: the input container's triangles that bound one
    tetrahedron only, in SOFA's order (see tetrahedron_surface_triangles)."""
    from sofac.geometry.fem_topology import tetrahedron_surface_triangles

    tetrahedra = ctx.linked("input", "tetrahedra")
    if tetrahedra is None or not np.size(tetrahedra):
        raise UnknownInput("the input topology's tetrahedra are not known at compile time")
    if ctx.value("noInitialTriangles"):
        return {"triangles": np.zeros(0, dtype=np.int64)}
    given = ctx.linked("input", "triangles")
    surface = tetrahedron_surface_triangles(tetrahedra, given, bool(ctx.value("flipNormals")))
    return {"triangles": surface.reshape(-1)}


def _container_edges(triangles: np.ndarray, given: Any) -> tuple[np.ndarray, np.ndarray]:
    """A TriangleSetTopologyContainer's edges (those it is given, else createEdgeSetArray's) and
    each edge's number of triangles (trianglesAroundEdge). A triangle's edge (t[j+1], t[j+2]) is the
    first given edge joining the same two points (createEdgesInTriangleArray's search); a triangle
    edge missing from the given ones leaves SOFA's container invalid: refused."""
    if given is None or not np.size(given):
        edges = triangle_edges(triangles)
    else:
        edges = np.asarray(given, dtype=np.int64).reshape(-1, 2)
    first: dict[tuple[int, int], int] = {}
    for index, (a, b) in enumerate(edges.tolist()):
        first.setdefault((min(a, b), max(a, b)), index)
    counts = np.zeros(len(edges), dtype=np.int64)
    for number, triangle in enumerate(triangles.tolist()):
        for j in range(3):
            a, b = triangle[(j + 1) % 3], triangle[(j + 2) % 3]
            index = first.get((min(a, b), max(a, b)))
            if index is None:
                raise EvaluationError(
                    f"the input container's edges have no edge [{a}, {b}] of triangle {number} "
                    f"{triangle} (SOFA leaves the container invalid); give it the triangles only, "
                    "its edges are then computed",
                    "input",
                    code="E207",
                )
            counts[index] += 1
    return edges, counts


def triangle_to_edge(ctx: Context) -> Outputs:
    """Triangle2EdgeTopologicalMapping: the input container's edges that bound one triangle only,
    in the container's edge order, as written (SOFA's init)."""
    source, target = CONTAINERS["Triangle"].name, CONTAINERS["Edge"].name
    for link, expected in (("input", source), ("output", target)):
        found = ctx.linked_type(link)
        if found is not None and found != expected:
            raise EvaluationError(
                f"{link} is a {found}: sofac evaluates this mapping from a {source} to an {target} only",
                link,
                code="E222",
            )
    triangles = ctx.linked("input", "triangles")
    if triangles is None or not np.size(triangles):
        raise UnknownInput("the input topology's triangles are not known at compile time")
    cells = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges, counts = _container_edges(cells, ctx.linked("input", "edges"))
    return {"edges": edges[counts == 1].reshape(-1)}


def quad_to_triangle(ctx: Context) -> Outputs:
    """Quad2TriangleTopologicalMapping: two triangles per input quad (p1 p2 p0) (p3 p0 p2), or with
    ``swapping`` on the quads where (i mod s) xor (i div s) is odd, (p0 p1 p3) (p2 p3 p1); s is the
    grid's nx - 1 (ny - 1 when nx is 1), 2 when the input is not a grid (SOFA's init)."""
    quads = ctx.linked("input", "quads")
    if quads is None or not np.size(quads):
        raise UnknownInput("the input topology's quads are not known at compile time")
    cells = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    resolution = ctx.linked("input", "resolution")
    nx, ny = (int(resolution[0]) - 1, int(resolution[1]) - 1) if resolution is not None else (2, 1)
    if nx == 0 and ny == 0:
        raise EvaluationError(
            "the input grid has one point along x and y: SOFA's Quad2TriangleTopologicalMapping is "
            "invalid for it",
            "input",
            code="E207",
        )
    scale = nx if nx else ny
    index = np.arange(len(cells))
    swapped = (((index % scale) ^ (index // scale)) & 1).astype(bool) & bool(ctx.value("swapping"))
    straight = np.stack([cells[:, [1, 2, 0]], cells[:, [3, 0, 2]]], axis=1)
    turned = np.stack([cells[:, [0, 1, 3]], cells[:, [2, 3, 1]]], axis=1)
    return {"triangles": np.where(swapped[:, None, None], turned, straight).reshape(-1)}


def hexa_to_quad(ctx: Context) -> Outputs:
    """Hexa2QuadTopologicalMapping: the boundary quads of the input hexahedra, outward."""
    from sofac.geometry.fem_topology import HEXA_FACES

    return _surface(ctx, "hexahedra", 8, HEXA_FACES, "quads")


# The order in which the edges of each tetrahedron first appear in the edge array of SOFA's
# tetrahedral containers, as SOFA's regression references of Mesh2PointTopologicalMapping record it
# (all 914 edges of the liver mesh); it is not the order of Topology.cpp's edgesInTetrahedronArray.
_CONTAINER_TETRA_EDGES = ((1, 2), (0, 1), (0, 2), (1, 3), (0, 3), (2, 3))


def _tetrahedral_container_edges(tetrahedra: np.ndarray) -> np.ndarray:
    seen: set[tuple[int, int]] = set()
    edges: list[tuple[int, int]] = []
    for tetrahedron in tetrahedra.tolist():
        for a, b in _CONTAINER_TETRA_EDGES:
            key = (min(tetrahedron[a], tetrahedron[b]), max(tetrahedron[a], tetrahedron[b]))
            if key not in seen:
                seen.add(key)
                edges.append(key)
    return np.asarray(edges, dtype=np.int64).reshape(-1, 2)


# MergeVectors' input Data the registry declares (SOFA creates nbInputs of them).
_MERGE_INPUTS = 8


def merge_vectors(ctx: Context) -> Outputs:
    """MergeVectors: input1, ..., input<nbInputs> one after the other (an unset input is empty)."""
    count = int(ctx.value("nbInputs") or 0)
    if count > _MERGE_INPUTS:
        raise EvaluationError(
            f"nbInputs={count}: sofac evaluates MergeVectors with at most {_MERGE_INPUTS} inputs",
            "nbInputs",
            code="E222",
        )
    parts = []
    for i in range(1, count + 1):
        value = ctx.value(f"input{i}")
        if value is not None and np.size(value):
            parts.append(np.asarray(value).ravel())
    return {"output": np.concatenate(parts) if parts else np.zeros(0)}


def transform_engine(ctx: Context) -> Outputs:
    """TransformEngine on Vec3 points: scale then translation, in SOFA's order (each operation one
    rounding); inverse: translation by -t first, then scale by 1/s. Rotations are not evaluated."""
    value = ctx.value("input_position")
    if value is None or not np.size(value):
        raise UnknownInput("input_position is not known at compile time")
    if np.size(value) % 3:  # not points: the count check reports it (E205)
        raise UnknownInput("input_position is not a list of x y z points")
    points = np.asarray(value, dtype=float).reshape(-1, 3).copy()
    scale = np.asarray(ctx.value("scale"), dtype=float)
    translation = np.asarray(ctx.value("translation"), dtype=float)
    rotation = np.asarray(ctx.value("rotation"), dtype=float)
    quaternion = np.asarray(ctx.value("quaternion"), dtype=float)
    if rotation.any() or not np.array_equal(quaternion, [0.0, 0.0, 0.0, 1.0]):
        raise UnknownInput("TransformEngine rotations are not evaluated yet")
    inverse = bool(ctx.value("inverse"))
    operations = []
    if not np.array_equal(scale, [1.0, 1.0, 1.0]):
        factors = 1.0 / scale if inverse else scale
        operations.append(lambda p: p * factors)
    if translation.any():
        shift = -translation if inverse else translation
        operations.append(lambda p: p + shift)
    for operation in reversed(operations) if inverse else operations:
        points = operation(points)
    return {"output_position": points.ravel()}


def mesh_to_point(ctx: Context) -> Outputs:
    """Mesh2PointTopologicalMapping's output points (SOFA's init order): per input point
    p + pointBaryCoords[j]; per edge p0 (1 - fx) + p1 fx; per triangle p0 (1 - fx - fy) + p1 fx + p2 fy;
    per tetrahedron p0 (1 - fx - fy - fz) + p1 fx + p2 fy + p3 fz. Quads and hexahedra are not evaluated."""
    from sofac.geometry.masses import topology_edges

    position = ctx.linked("input", "position")
    if position is None or not np.size(position):
        raise UnknownInput("the input topology's points are not known at compile time")
    points = np.asarray(position, dtype=float).reshape(-1, 3)

    def coords(name: str) -> np.ndarray:
        value = ctx.value(name)
        return np.asarray(value if value is not None else [], dtype=float).reshape(-1, 3)

    def cells(name: str, corners: int) -> np.ndarray:
        value = ctx.linked("input", name)
        return np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1, corners)

    for name in ("quadBaryCoords", "hexaBaryCoords"):
        if coords(name).size:
            raise UnknownInput(f"{name} is not evaluated yet")
    out: list[np.ndarray] = []
    for offset in coords("pointBaryCoords"):
        out.append(points + offset)
    per_point = np.stack(out, axis=1).reshape(-1, 3) if out else np.zeros((0, 3))
    rows: list[np.ndarray] = [per_point]
    tetrahedra, triangles = cells("tetrahedra", 4), cells("triangles", 3)
    edge_coords = coords("edgeBaryCoords")
    if edge_coords.size:
        edges = cells("edges", 2)
        if len(tetrahedra):
            edges = _tetrahedral_container_edges(tetrahedra)
        elif not len(edges):
            edges = topology_edges(len(points), triangles=triangles, quads=cells("quads", 4))
        p0, p1 = points[edges[:, 0]], points[edges[:, 1]]
        rows.append(np.stack([p0 * (1 - fx) + p1 * fx for fx, _, _ in edge_coords], axis=1).reshape(-1, 3))
    triangle_coords = coords("triangleBaryCoords")
    if triangle_coords.size:
        t = [points[triangles[:, k]] for k in range(3)]
        rows.append(
            np.stack(
                [t[0] * (1 - fx - fy) + t[1] * fx + t[2] * fy for fx, fy, _ in triangle_coords], axis=1
            ).reshape(-1, 3)
        )
    tetra_coords = coords("tetraBaryCoords")
    if tetra_coords.size:
        t = [points[tetrahedra[:, k]] for k in range(4)]
        rows.append(
            np.stack(
                [
                    t[0] * (1 - fx - fy - fz) + t[1] * fx + t[2] * fy + t[3] * fz
                    for fx, fy, fz in tetra_coords
                ],
                axis=1,
            ).reshape(-1, 3)
        )
    return {"position": np.concatenate(rows).ravel()}


EVALUATORS: dict[str, Callable[[Context], Outputs]] = {
    "mesh_to_point": mesh_to_point,
    "transform_engine": transform_engine,
    "hexa_to_tetra": hexa_to_tetra,
    "tetra_to_triangle": tetra_to_triangle,
    "triangle_to_edge": triangle_to_edge,
    "hexa_to_quad": hexa_to_quad,
    "mesh_loader": mesh_loader,
    "string_mesh": string_mesh,
    "grid_mesh": grid_mesh,
    "sphere_loader": sphere_loader,
    "grid": grid,
    "grid_topology": grid_topology,
    "quad_to_triangle": quad_to_triangle,
    "merge_vectors": merge_vectors,
    "cube_topology": cube_topology,
    "sparse_grid": sparse_grid,
    "sparse_grid_ramification": sparse_grid_ramification,
    "box_roi": box_roi,
    "subset_topology": subset_topology,
    "plane_roi": plane_roi,
    "pair_box_roi": pair_box_roi,
}
