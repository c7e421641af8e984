"""Region-of-interest engines evaluated at compile time, as SOFA's doUpdate computes them:
SubsetTopology (boxes or spheres, with its local re-numbering), PlaneROI (slabs given by three
points and a depth) and PairBoxROI (inside one box, outside another).

Each function takes the engine's inputs as arrays and returns its outputs, elements and indices in
SOFA's order. Positions are ``(n, k)`` coordinates whose first three numbers are the point
(DataTypes::getCPos: a rigid frame's centre).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# The element kinds an engine selects: (kind, corners, index output, in-ROI output, out-of-ROI output).
ELEMENT_OUTPUTS = (
    ("edges", 2, "edgeIndices", "edgesInROI", "edgesOutROI"),
    ("triangles", 3, "triangleIndices", "trianglesInROI", "trianglesOutROI"),
    ("quads", 4, "quadIndices", "quadsInROI", "quadsOutROI"),
    ("tetrahedra", 4, "tetrahedronIndices", "tetrahedraInROI", "tetrahedraOutROI"),
    ("hexahedra", 8, "hexahedronIndices", "hexahedraInROI", "hexahedraOutROI"),
)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a.b summed x, then y, then z (sofa::type::Vec's operator*)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _normalized(v: np.ndarray) -> np.ndarray:
    """Vec::normalize: divided by its norm when the norm exceeds the machine epsilon, else unchanged."""
    norm = float(np.sqrt(_dot(v, v)))
    return v / norm if norm > np.finfo(float).eps else v


def in_boxes(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(n, boxes) inside flags: xmin <= x <= xmax, ... (bounds included)."""
    p = points[:, None, :3]
    return ((p >= boxes[None, :, :3]) & (p <= boxes[None, :, 3:6])).all(axis=2)


def in_spheres(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(n, spheres) inside flags: |p - c| <= r."""
    d = points[:, None, :3] - centers[None, :, :]
    return np.sqrt(_dot(d, d)) <= radii[None, :]


def subset_topology(
    coords: np.ndarray, inside: np.ndarray, cells: dict[str, np.ndarray], local: bool
) -> dict[str, np.ndarray]:
    """SubsetTopology::doUpdate. ``inside`` (n, regions) says which region holds which point; a
    point is in the ROI when one region holds it, an element when one region holds all its corners.
    With ``local`` the outputs are re-numbered: first the border points (inside region 0 and
    corner of a triangle, or of a tetrahedron if there are any, that has corners outside it), in
    increasing order, then the points inside and, separately, those outside, each counted from the
    number of border points; every output element (inside or out) is written with those numbers."""
    n = len(coords)
    border: list[int] = []
    if local:
        shells = cells["triangles"] if not len(cells["tetrahedra"]) else cells["tetrahedra"]
        for element in shells.tolist():
            flags = [bool(inside[p, 0]) for p in element]
            if any(flags) and not all(flags):
                for p, flag in zip(element, flags, strict=True):
                    if flag and p not in border:
                        border.append(p)
        border.sort()
    local_index = np.zeros(n, dtype=np.int64)
    border_set = set(border)
    indices: list[int] = list(border)
    points_in: list[np.ndarray] = [coords[p] for p in border]
    points_out: list[np.ndarray] = [coords[p] for p in border]
    counter_in = counter_out = len(border)
    for rank, p in enumerate(border):
        local_index[p] = rank
    in_roi = inside.any(axis=1)
    for p in range(n):
        if p in border_set:
            continue
        if in_roi[p]:
            indices.append(p)
            points_in.append(coords[p])
            local_index[p], counter_in = counter_in, counter_in + 1
        else:
            points_out.append(coords[p])
            local_index[p], counter_out = counter_out, counter_out + 1
    width = coords.shape[1]
    outputs: dict[str, np.ndarray] = {
        "indices": np.asarray(indices, dtype=np.int64),
        "pointsInROI": np.asarray(points_in, dtype=float).reshape(-1, width).ravel(),
        "pointsOutROI": np.asarray(points_out, dtype=float).reshape(-1, width).ravel(),
        "nbrborder": np.asarray([len(border)], dtype=np.int64),
    }
    for kind, corners, index_name, in_name, out_name in ELEMENT_OUTPUTS:
        elements = cells[kind].reshape(-1, corners)
        chosen = inside[elements].all(axis=1).any(axis=1) if len(elements) else np.zeros(0, dtype=bool)
        written = local_index[elements] if local else elements
        outputs[index_name] = np.flatnonzero(chosen).astype(np.int64)
        outputs[in_name] = written[chosen].astype(np.int64).ravel()
        outputs[out_name] = written[~chosen].astype(np.int64).ravel()
    return outputs


def in_planes(points: np.ndarray, planes: Sequence[Sequence[float]]) -> np.ndarray:
    """PlaneROI::isPointInPlane for every point and plane ((n, planes) flags). A plane is three
    points p0 p1 p2 and a depth: the slab of the rectangle p0, p1, p2, p0 + (p2 - p1), depth thick,
    with SOFA's computePlane vectors and tests (in its arithmetic)."""
    p = np.asarray(points, dtype=float)[:, :3]
    flags = np.zeros((len(p), len(planes)), dtype=bool)
    for k, plane in enumerate(planes):
        p0, p1, p2 = (np.asarray(plane[3 * i : 3 * i + 3], dtype=float) for i in range(3))
        depth = float(plane[9])
        vdepth = _normalized(_cross(p1 - p0, p2 - p0))
        p3 = p0 + (p2 - p1)
        p4 = p0 + vdepth * (depth / 2)
        p6 = p2 + vdepth * (depth / 2)
        plane0 = _normalized(_cross(p1 - p0, p4 - p0))
        plane1 = _normalized(_cross(p2 - p3, p6 - p3))
        plane2 = _normalized(_cross(p3 - p0, p4 - p0))
        plane3 = _normalized(_cross(p2 - p1, p6 - p2))
        width = abs(float(_dot(p2 - p0, plane0)))
        length = abs(float(_dot(p2 - p0, plane2)))
        pv0, pv1 = p - p0, p - p2
        flags[:, k] = (
            (np.abs(_dot(pv0, plane0)) <= width)
            & (np.abs(_dot(pv1, plane1)) <= width)
            & (np.abs(_dot(pv0, plane2)) <= length)
            & (np.abs(_dot(pv1, plane3)) <= length)
            & (np.abs(_dot(pv0, vdepth)) <= abs(depth / 2))
        )
    return flags


# sofa::type::Vec's operator== (EQUALITY_THRESHOLD in Vec.h).
_EQUALITY_THRESHOLD = 1e-6


def pair_box(points: np.ndarray, inclusive: np.ndarray, included: np.ndarray) -> np.ndarray:
    """PairBoxROI::doUpdate: the indices of the points inside ``inclusive`` and not inside
    ``included`` (each box's bounds put in order first); none if either box is zero (Vec6's ==,
    which takes numbers closer than 1e-6 as equal)."""
    if any((np.abs(box) < _EQUALITY_THRESHOLD).all() for box in (inclusive, included)):
        return np.zeros(0, dtype=np.int64)
    boxes = []
    for box in (inclusive, included):
        low, high = np.minimum(box[:3], box[3:]), np.maximum(box[:3], box[3:])
        boxes.append(np.concatenate([low, high]))
    flags = in_boxes(np.asarray(points, dtype=float), np.asarray(boxes))
    return np.flatnonzero(flags[:, 0] & ~flags[:, 1]).astype(np.int64)
