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

    def is_set(self, name: str) -> bool: ...

    def file(self, name: str) -> Path | None: ...

    def input_positions(self) -> np.ndarray | None: ...

    def linked(self, link: str, name: str) -> Any:
        """The value of field ``name`` of the component the link field ``link`` points to."""
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
    return {
        "position": _transform(ctx, mesh.positions).ravel(),
        "edges": mesh.edges.ravel(),
        "triangles": mesh.triangles.ravel(),
        "quads": mesh.quads.ravel(),
        "tetrahedra": mesh.tetrahedra.ravel(),
        "hexahedra": mesh.hexahedra.ravel(),
    }


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


def grid(ctx: Context) -> Outputs:
    """RegularGridTopology / GridTopology points: index = x + nx (y + ny z)."""
    legacy_counts = ("nx", "ny", "nz")
    if any(ctx.is_set(name) for name in legacy_counts):
        counts = np.array(
            [int(_numbers(ctx, n, 1, integer=True)[0]) if ctx.is_set(n) else 1 for n in legacy_counts],
            dtype=np.int64,
        )
    else:
        counts = np.array([int(c) for c in _numbers(ctx, "n", 3, integer=True)], dtype=np.int64)
    legacy_bounds = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
    if all(ctx.is_set(name) for name in legacy_bounds):
        # SOFA reads the legacy bounds as single-precision floats.
        with np.errstate(over="ignore"):  # a bound past the float range: the points check reports it
            bounds = np.array([float(np.float32(_numbers(ctx, name, 1)[0])) for name in legacy_bounds])
        low, high = bounds[:3], bounds[3:]
    else:
        low = _numbers(ctx, "min", 3)
        high = _numbers(ctx, "max", 3)
    if (counts < 1).any():
        raise EvaluationError(f"grid resolution {counts.tolist()} must be >= 1 per axis", "n", code="E207")
    refused = limits.too_many_points(counts.tolist())
    if refused:
        legacy = any(ctx.is_set(name) for name in legacy_counts)
        attribute = legacy_counts[int(np.argmax(counts))] if legacy else "n"
        raise EvaluationError(f"grid resolution {refused}", attribute, code="E207")
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
    cells = _grid_cells(counts)
    if "quads" in cells and ctx.value("computeTriangleList") is not False:
        # A 2-D grid: SOFA's GridUpdate also splits each quad (q0 q1 q2) (q0 q2 q3) and, from those
        # triangles, derives the edges.
        quads = cells["quads"].reshape(-1, 4)
        triangles = np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
        cells["triangles"] = triangles.ravel()
        if ctx.value("computeEdgeList") is not False:
            cells["edges"] = triangle_edges(triangles).ravel()
    return {
        "position": points.ravel(),
        "resolution": counts.astype(np.int64),
        "bounds": np.concatenate([low, high]).astype(float),
        **cells,
    }


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges of triangles as SOFA's createEdgeSetArray makes them: for each triangle t and
    j = 0, 1, 2 the edge (t[j+1], t[j+2]) (indices mod 3), in the order first met, once each."""
    ends = np.stack([triangles[:, [1, 2]], triangles[:, [2, 0]], triangles[:, [0, 1]]], axis=1).reshape(-1, 2)
    keys = np.sort(ends, axis=1)
    _, first = np.unique(keys, axis=0, return_index=True)
    return ends[np.sort(first)]


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
    """Indices of the input points inside any of the boxes (xmin ymin zmin xmax ymax zmax)."""
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
    outputs = {"indices": np.flatnonzero(inside).astype(np.int64)}
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
    """Tetra2TriangleTopologicalMapping: the boundary triangles of the input tetrahedra, outward."""
    from sofac.geometry.fem_topology import TETRA_FACES

    return _surface(ctx, "tetrahedra", 4, TETRA_FACES, "triangles")


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
    "hexa_to_quad": hexa_to_quad,
    "mesh_loader": mesh_loader,
    "string_mesh": string_mesh,
    "sphere_loader": sphere_loader,
    "grid": grid,
    "sparse_grid": sparse_grid,
    "sparse_grid_ramification": sparse_grid_ramification,
    "box_roi": box_roi,
}
