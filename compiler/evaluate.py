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

from . import meshes


class EvaluationError(Exception):
    """An output could not be computed; ``attribute`` names the field at fault."""

    def __init__(self, message: str, attribute: str | None = None, code: str = "E219") -> None:
        super().__init__(message)
        self.attribute = attribute
        self.code = code


class UnknownInput(Exception):
    """An input exists but its value cannot be known before run time; outputs stay unknown."""


class Context(Protocol):
    """What an evaluator may ask of the checker about the component it evaluates."""

    def value(self, name: str) -> Any: ...

    def is_set(self, name: str) -> bool: ...

    def file(self, name: str) -> Path | None: ...

    def input_positions(self) -> np.ndarray | None: ...


Outputs = dict[str, np.ndarray]


def _transform(ctx: Context, points: np.ndarray) -> np.ndarray:
    return meshes.apply_transform(
        points,
        translation=np.asarray(ctx.value("translation"), dtype=float),
        rotation_deg=np.asarray(ctx.value("rotation"), dtype=float),
        scale=np.asarray(ctx.value("scale3d"), dtype=float),
    )


def _file(ctx: Context) -> Path:
    path = ctx.file("filename")
    if path is None:
        raise EvaluationError("no readable file", "filename")
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


def sphere_loader(ctx: Context) -> Outputs:
    try:
        spheres = meshes.read_spheres(_file(ctx))
    except meshes.MeshError as error:
        raise EvaluationError(str(error), "filename") from None
    return {"position": spheres.centers.ravel(), "listRadius": spheres.radii}


def grid(ctx: Context) -> Outputs:
    """RegularGridTopology / GridTopology points: index = x + nx (y + ny z)."""
    legacy_counts = ("nx", "ny", "nz")
    if any(ctx.is_set(name) for name in legacy_counts):
        counts = np.array([int(ctx.value(name) or 1) for name in legacy_counts], dtype=np.int64)
    else:
        counts = np.asarray(ctx.value("n"), dtype=np.int64)
    legacy_bounds = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
    if all(ctx.is_set(name) for name in legacy_bounds):
        bounds = np.array([float(ctx.value(name)) for name in legacy_bounds])
        low, high = bounds[:3], bounds[3:]
    else:
        low = np.asarray(ctx.value("min"), dtype=float)
        high = np.asarray(ctx.value("max"), dtype=float)
    if (counts < 1).any():
        raise EvaluationError(f"grid resolution {counts.tolist()} must be >= 1 per axis", "n", code="E207")
    axes = [
        np.linspace(low[a], high[a], int(counts[a])) if counts[a] > 1 else np.array([low[a]])
        for a in range(3)
    ]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    return {"position": points.ravel(), **_grid_cells(counts)}


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
    return {"indices": np.flatnonzero(inside).astype(np.int64)}


EVALUATORS: dict[str, Callable[[Context], Outputs]] = {
    "mesh_loader": mesh_loader,
    "sphere_loader": sphere_loader,
    "grid": grid,
    "box_roi": box_roi,
}
