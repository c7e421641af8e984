"""Masses SOFA computes from a topology at init: DiagonalMass and MeshMatrixMass.

Pure numpy, evaluated at compile time from the rest (or initial) positions and the topology's
element arrays. The arithmetic follows SOFA's own, operation by operation: the element measures of
``sofa::geometry`` (Edge::length, Triangle::area, Quad::area, Tetrahedron::volume,
Hexahedron::volume), the order elements are visited and their shares accumulated, and the
precedence between ``totalMass``, ``massDensity`` and ``vertexMass``. The masses therefore equal
SOFA's to the last bit, not merely to round-off.

Element type. Both components use the highest-dimension element type the topology has, in the
order hexahedra > tetrahedra > quads > triangles > edges (``getNbHexahedra() > 0`` first, ...);
the other types are ignored. Triangles and quads need 2-D or 3-D positions, tetrahedra and hexahedra
3-D ones (SOFA computes nothing otherwise, which these functions reject).

Edges. MeshMatrixMass puts mass on the topology's edges (``getEdges()``). When the topology
has none of its own, SOFA derives them from its elements (``topology_edges`` reproduces the list and
its order); when the scene gives edges, those are used and must contain every edge of the elements.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

EPSILON = float(np.finfo(np.float64).eps)

ELEMENT_NODES = {"edges": 2, "triangles": 3, "quads": 4, "tetrahedra": 4, "hexahedra": 8}

# The element type SOFA's masses use: the first of these the topology has.
PRECEDENCE = ("hexahedra", "tetrahedra", "quads", "triangles", "edges")

# Local edges of each element, SOFA's order: edgesInTetrahedronArray, edgesInHexahedronArray, and
# for triangles / quads edge j = (v[j+1], v[j+2]) (indices modulo the node count).
TETRAHEDRON_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
HEXAHEDRON_EDGES = np.array(
    [[0, 1], [0, 3], [0, 4], [1, 2], [1, 5], [2, 3], [2, 6], [3, 7], [4, 5], [4, 7], [5, 6], [6, 7]],
    dtype=np.int64,
)
TRIANGLE_EDGES = np.array([[1, 2], [2, 0], [0, 1]], dtype=np.int64)
QUAD_EDGES = np.array([[1, 2], [2, 3], [3, 0], [0, 1]], dtype=np.int64)
LOCAL_EDGES = {
    "tetrahedra": TETRAHEDRON_EDGES,
    "hexahedra": HEXAHEDRON_EDGES,
    "triangles": TRIANGLE_EDGES,
    "quads": QUAD_EDGES,
}

# DiagonalMass: each element gives density * measure / (node count) to each of its nodes.
_DIAGONAL_SHARE = {"edges": 2.0, "triangles": 3.0, "quads": 4.0, "tetrahedra": 4.0, "hexahedra": 8.0}


@dataclass(frozen=True)
class _ConsistentSpec:
    vertex_divisor: float  # vertexMass[v] += density * measure / vertex_divisor, per node
    edge_divisor: float  # edgeMass[e] += density * measure / edge_divisor, per element edge
    lumping: float  # m_massLumpingCoeff: vertexMass * lumping = the row sum of the consistent matrix


# MeshMatrixMass (computeMass and the apply*Creation functions).
_CONSISTENT = {
    "tetrahedra": _ConsistentSpec(10.0, 20.0, 2.5),
    "hexahedra": _ConsistentSpec(20.0, 40.0, 2.5),
    "triangles": _ConsistentSpec(6.0, 12.0, 2.0),
    "quads": _ConsistentSpec(8.0, 16.0, 2.0),
}

_MIN_DIMENSION = {"edges": 1, "triangles": 2, "quads": 2, "tetrahedra": 3, "hexahedra": 3}


# ---- input checking --------------------------------------------------------------------------------


def _points(positions: Any) -> np.ndarray:
    points = np.asarray(positions, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (1, 2, 3):
        raise ValueError(f"positions must have shape (n, 1..3), not {points.shape}")
    if points.shape[0] == 0:
        raise ValueError("positions are empty")
    if not np.isfinite(points).all():
        raise ValueError("positions must be finite")
    return points


def as_cells(value: Any, kind: str, n_points: int) -> np.ndarray:
    """Element array ``kind`` as (m, nodes) int64 (a flat array is accepted); indices checked."""
    nodes = ELEMENT_NODES[kind]
    if value is None:
        return np.zeros((0, nodes), dtype=np.int64)
    raw = np.asarray(value)
    if raw.size == 0:
        return np.zeros((0, nodes), dtype=np.int64)
    if raw.dtype.kind == "f":
        if not np.isfinite(raw).all() or (raw != np.round(raw)).any():
            raise ValueError(f"{kind}: indices must be integers")
    elif raw.dtype.kind not in "iu":
        raise ValueError(f"{kind}: indices must be integers, not {raw.dtype}")
    if raw.ndim == 1 and raw.size % nodes == 0:
        raw = raw.reshape(-1, nodes)
    if raw.ndim != 2 or raw.shape[1] != nodes:
        raise ValueError(f"{kind}: expected (m, {nodes}) vertex indices, got shape {raw.shape}")
    cells = raw.astype(np.int64)
    if cells.min() < 0 or cells.max() >= n_points:
        raise ValueError(f"{kind}: vertex index out of range [0, {n_points})")
    return cells


def _element_type(cells: dict[str, np.ndarray], component: str) -> str:
    for kind in PRECEDENCE:
        if len(cells[kind]):
            return kind
    raise ValueError(f"{component}: the topology has no elements (SOFA: 'Topology empty.')")


def _check_dimension(kind: str, dimension: int, component: str) -> None:
    if dimension < _MIN_DIMENSION[kind]:
        raise ValueError(
            f"{component}: {kind} need {_MIN_DIMENSION[kind]}-D positions; with {dimension}-D ones "
            "SOFA computes no mass"
        )


def _sequential_sum(values: np.ndarray) -> float:
    """Left-to-right sum starting from 0.0, as a C++ ``+=`` loop computes it."""
    if values.size == 0:
        return 0.0
    return float(np.add.accumulate(values.ravel())[-1])


# ---- element measures (sofa::geometry, same operations in the same order) --------------------------


def _norm2(v: np.ndarray) -> np.ndarray:
    result = v[:, 0] * v[:, 0]
    for d in range(1, v.shape[1]):
        result = result + v[:, d] * v[:, d]
    return result


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products, in sofa::type::cross's operation order."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _lengths(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    return np.sqrt(_norm2(p1 - p0))


def triangle_areas(n0: np.ndarray, n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """sofa::geometry::Triangle::area of each row's triangle, operation for operation."""
    dimension = n0.shape[1]
    if dimension == 3:
        return 0.5 * np.sqrt(_norm2(cross_rows(n1 - n0, n2 - n0)))
    if dimension == 2:  # SOFA's 2-D formula is signed (negative for clockwise triangles)
        x0, y0, x1, y1, x2, y2 = n0[:, 0], n0[:, 1], n1[:, 0], n1[:, 1], n2[:, 0], n2[:, 1]
        return 0.5 * (x0 * y1 + x1 * y2 + x2 * y0 - x1 * y0 - x2 * y1 - x0 * y2)
    a = _lengths(n0, n1)
    b = _lengths(n0, n2)
    c = _lengths(n1, n2)
    with np.errstate(invalid="ignore"):
        return 0.25 * np.sqrt((a + b + c) * (-a + b + c) * (a - b + c) * (a + b - c))


def _tetrahedron_volumes(n0: np.ndarray, n1: np.ndarray, n2: np.ndarray, n3: np.ndarray) -> np.ndarray:
    return np.abs(_dot3(cross_rows(n1 - n0, n2 - n0), n3 - n0) / 6.0)


def element_measures(positions: Any, cells: Any, kind: str) -> np.ndarray:
    """Length, area or volume of each element as SOFA's ``sofa::geometry`` computes it.

    Quads: the areas of triangles (0,1,2) and (0,2,3). Hexahedra: the sum of six tetrahedra
    (0,5,1,6), (0,1,3,6), (1,3,6,2), (6,3,0,7), (6,7,0,5), (7,5,4,0) — exact for any hexahedron
    whose faces are planar.
    """
    points = _points(positions)
    elements = as_cells(cells, kind, len(points))
    _check_dimension(kind, points.shape[1], "element_measures")
    n = [points[elements[:, j]] for j in range(ELEMENT_NODES[kind])]
    if kind == "edges":
        return _lengths(n[0], n[1])
    if kind == "triangles":
        return triangle_areas(n[0], n[1], n[2])
    if kind == "quads":
        return triangle_areas(n[0], n[1], n[2]) + triangle_areas(n[0], n[2], n[3])
    if kind == "tetrahedra":
        return _tetrahedron_volumes(n[0], n[1], n[2], n[3])
    if kind == "hexahedra":
        return (
            _tetrahedron_volumes(n[0], n[5], n[1], n[6])
            + _tetrahedron_volumes(n[0], n[1], n[3], n[6])
            + _tetrahedron_volumes(n[1], n[3], n[6], n[2])
            + _tetrahedron_volumes(n[6], n[3], n[0], n[7])
            + _tetrahedron_volumes(n[6], n[7], n[0], n[5])
            + _tetrahedron_volumes(n[7], n[5], n[4], n[0])
        )
    raise ValueError(f"unknown element type {kind!r}")


# ---- topology edges ----------------------------------------------------------------------------------


def _element_edge_pairs(kind: str, elements: np.ndarray) -> tuple[np.ndarray, bool]:
    """(m * e, 2) vertex pairs of each element's local edges, element-major; and whether SOFA
    stores new edges sorted (volumes, quads) or as first seen (triangles)."""
    local = LOCAL_EDGES[kind]
    pairs = elements[:, local].reshape(-1, 2)
    return pairs, kind != "triangles"


def _edge_keys(pairs: np.ndarray, n_points: int) -> np.ndarray:
    return np.minimum(pairs[:, 0], pairs[:, 1]) * n_points + np.maximum(pairs[:, 0], pairs[:, 1])


def topology_edges(
    n_points: int,
    *,
    triangles: Any = None,
    quads: Any = None,
    tetrahedra: Any = None,
    hexahedra: Any = None,
) -> np.ndarray:
    """The edge list SOFA derives from the elements when the topology has no edges of its own.

    Volume topologies (MeshTopology's EdgeUpdate, TetrahedronSet / HexahedronSet containers): the edges
    of the tetrahedra then of the hexahedra, in order of first appearance, each stored (min, max).
    Surface topologies: the edges of the triangles stored as first met, (t[j+1], t[j+2]), then those
    of the quads stored (min, max). Returns (k, 2) int64.
    """
    cells = {
        "triangles": as_cells(triangles, "triangles", n_points),
        "quads": as_cells(quads, "quads", n_points),
        "tetrahedra": as_cells(tetrahedra, "tetrahedra", n_points),
        "hexahedra": as_cells(hexahedra, "hexahedra", n_points),
    }
    if len(cells["tetrahedra"]) or len(cells["hexahedra"]):
        kinds = ("tetrahedra", "hexahedra")
    else:
        kinds = ("triangles", "quads")
    stored = []
    for kind in kinds:
        pairs, sort = _element_edge_pairs(kind, cells[kind])
        if sort:
            pairs = np.stack([pairs.min(axis=1), pairs.max(axis=1)], axis=1)
        stored.append(pairs)
    every = np.concatenate(stored) if stored else np.zeros((0, 2), dtype=np.int64)
    if len(every) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    _, first = np.unique(_edge_keys(every, n_points), return_index=True)
    return every[np.sort(first)].astype(np.int64)


def element_edge_indices(kind: str, elements: np.ndarray, edges: np.ndarray, n_points: int) -> np.ndarray:
    """(m, e) index into ``edges`` of each local edge of each element (SOFA's getEdgesIn*)."""
    pairs, _ = _element_edge_pairs(kind, elements)
    if len(pairs) == 0:
        return np.zeros((0, len(LOCAL_EDGES[kind])), dtype=np.int64)
    keys = _edge_keys(edges, n_points)
    order = np.argsort(keys, kind="stable")  # duplicates: the first one listed
    sorted_keys = keys[order]
    wanted = _edge_keys(pairs, n_points)
    slot = np.minimum(np.searchsorted(sorted_keys, wanted), len(sorted_keys) - 1)
    found = sorted_keys[slot] == wanted if len(sorted_keys) else np.zeros(len(wanted), dtype=bool)
    if not found.all():
        missing = pairs[np.flatnonzero(~found)[0]]
        raise ValueError(
            f"the topology's edges do not contain edge ({missing[0]}, {missing[1]}) of its {kind} "
            "(SOFA would index past its edge array)"
        )
    return order[slot].reshape(len(elements), -1).astype(np.int64)


# ---- DiagonalMass ------------------------------------------------------------------------------------


def _note(notes: list[str] | None, message: str) -> None:
    if notes is not None:
        notes.append(message)


def diagonal_mass(
    positions: Any,
    *,
    edges: Any = None,
    triangles: Any = None,
    quads: Any = None,
    tetrahedra: Any = None,
    hexahedra: Any = None,
    mass_density: float | None = None,
    total_mass: float | None = None,
    vertex_mass: Any = None,
    notes: list[str] | None = None,
) -> np.ndarray:
    """Per-vertex masses of SOFA's DiagonalMass after init (``d_vertexMass``), shape (n,).

    ``positions``: the geometry state's rest positions (``computeMassOnRest``, default true) or
    positions, (n, 1..3). Element arrays as the topology has them. ``mass_density``, ``total_mass``,
    ``vertex_mass``: the scene's values, ``None`` when the scene does not set the field.

    Each element of the chosen type (see the module doc) gives ``density * measure / nodes`` to each
    of its nodes. Precedence, as ``DiagonalMass::massInitialization`` has it (the help strings say
    the opposite): ``totalMass`` when set (masses computed with density 1, then scaled by
    totalMass / their sum), else ``massDensity`` (a negative one falls back to totalMass = 1), else
    ``vertexMass`` (used as given; padded with its last value when shorter than n; wrong size or a
    negative value falls back to totalMass = 1), else totalMass = 1. Vertices in no element get 0.

    SOFA's warnings (overridden fields, fall-backs) are appended to ``notes`` when given.
    Raises ValueError when SOFA's component would be invalid (no elements, negative totalMass) or
    the masses would all be zero (zero total measure, zero density or total).
    """
    points = _points(positions)
    n = len(points)
    cells = {
        "edges": as_cells(edges, "edges", n),
        "triangles": as_cells(triangles, "triangles", n),
        "quads": as_cells(quads, "quads", n),
        "tetrahedra": as_cells(tetrahedra, "tetrahedra", n),
        "hexahedra": as_cells(hexahedra, "hexahedra", n),
    }
    kind = _element_type(cells, "DiagonalMass")
    _check_dimension(kind, points.shape[1], "DiagonalMass")
    elements = cells[kind]
    measure = element_measures(points, elements, kind)
    nodes = ELEMENT_NODES[kind]

    def compute(density: float) -> tuple[np.ndarray, float]:
        # DiagonalMass::computeVertexMass: masses[node] += mass, total += mass, element by element.
        share = (density * measure) / _DIAGONAL_SHARE[kind]
        shares = np.repeat(share, nodes)
        masses = np.zeros(n)
        np.add.at(masses, elements.ravel(), shares)
        return masses, _sequential_sum(shares)

    def from_total(total: float) -> np.ndarray:
        masses, measured = compute(1.0)
        density = 1.0 if measured < EPSILON else total / measured
        if measured < EPSILON and measured > 0.0:
            _note(notes, f"DiagonalMass: total measure {measured:g} < machine epsilon; SOFA keeps density 1")
        return masses * density

    if total_mass is not None:
        if mass_density is not None or vertex_mass is not None:
            _note(notes, "DiagonalMass: totalMass overrides the other mass information (SOFA warns)")
        if total_mass < 0.0:
            raise ValueError(
                f"DiagonalMass: totalMass={total_mass} is negative (SOFA resets it to 1 and marks the "
                "component invalid)"
            )
        masses = from_total(float(total_mass))
    elif mass_density is not None:
        if vertex_mass is not None:
            _note(notes, "DiagonalMass: massDensity overrides vertexMass (SOFA warns)")
        if mass_density < 0.0:
            _note(notes, f"DiagonalMass: negative massDensity={mass_density}; SOFA uses totalMass=1")
            masses = from_total(1.0)
        else:
            masses, _ = compute(float(mass_density))
    elif vertex_mass is not None:
        given = np.asarray(vertex_mass, dtype=np.float64).reshape(-1)
        if 0 < given.size < n:  # DiagonalMass::init pads with the last value
            given = np.concatenate([given, np.full(n - given.size, given[-1])])
        if given.size != n or (given < 0.0).any():
            _note(notes, "DiagonalMass: bad vertexMass (size or sign); SOFA uses totalMass=1")
            masses = from_total(1.0)
        else:
            masses = given.copy()
    else:
        masses = from_total(1.0)

    if not np.any(masses != 0.0):
        raise ValueError(
            f"DiagonalMass: every vertex mass is zero (total {kind} measure {_sequential_sum(measure):g})"
        )
    if (masses == 0.0).any():
        isolated = int((masses == 0.0).sum())
        _note(notes, f"DiagonalMass: {isolated} vertices belong to no element and have mass 0")
    return masses


# ---- MeshMatrixMass ----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MeshMatrixMassData:
    """SOFA's MeshMatrixMass after init.

    The mass matrix (per spatial component, identical for x, y, z) is

        M[i, i] = vertex_mass[i]                (consistent)
        M[a, b] = M[b, a] = edge_mass[e]        for each edge e = (a, b)
        M = diag(vertex_mass * lumping_coefficient)            (lumped)

    so ``M dx`` is, per vertex i and component d (SOFA's addMDx, what the kernel computes)::

        df[i] += dx[i] * vertex_mass[i] * factor                      for every vertex, then
        df[a] += dx[b] * (edge_mass[e] * factor); df[b] += dx[a] * (edge_mass[e] * factor)  per edge

    and, lumped, ``df[i] += dx[i] * vertex_mass[i] * lumping_coefficient * factor``.
    Whatever the lumping, SOFA's gravity force is ``f[i] += g * vertex_mass[i] * lumping_coefficient``
    (the row sums of the consistent matrix) and accFromF (explicit solvers, lumped only) divides by
    ``vertex_mass[i] * lumping_coefficient``; SOFA refuses accFromF on the consistent matrix.
    """

    vertex_mass: np.ndarray  # (n,) SOFA's d_vertexMass (not multiplied by the lumping coefficient)
    edges: np.ndarray  # (k, 2) the topology's edges (getEdges())
    edge_mass: np.ndarray  # (k,) SOFA's d_edgeMass (zeros when lumped)
    lumping_coefficient: float  # m_massLumpingCoeff: 2.5 volumes, 2.0 surfaces
    lumped: bool
    element: str  # the element type used
    total_mass: float  # SOFA's d_totalMass after init
    mass_density: np.ndarray  # per element, SOFA's d_massDensity after init
    notes: tuple[str, ...] = ()

    @property
    def lumped_vertex_mass(self) -> np.ndarray:
        """``vertex_mass * lumping_coefficient``: the diagonal of the lumped matrix (row sums)."""
        return self.vertex_mass * self.lumping_coefficient

    def multiply(self, dx: Any, factor: float = 1.0) -> np.ndarray:
        """``factor * M dx`` (SOFA's addMDx on a zero vector), dx of shape (n, width)."""
        if self.lumped:
            d = np.asarray(dx, dtype=np.float64)
            return d * self.vertex_mass[:, None] * self.lumping_coefficient * factor
        return mesh_matrix_mass_multiply(self.vertex_mass, self.edges, self.edge_mass, dx, factor=factor)

    def triplets(self, width: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """COO (rows, cols, values) of the assembled (n*width)^2 matrix (SOFA's addMToMatrix)."""
        n = len(self.vertex_mass)
        d = np.arange(width)
        diagonal = self.lumped_vertex_mass if self.lumped else self.vertex_mass
        rows = [(np.arange(n)[:, None] * width + d).ravel()]
        cols = [rows[0]]
        values = [np.repeat(diagonal, width)]
        if not self.lumped and len(self.edges):
            a = (self.edges[:, 0:1] * width + d).ravel()
            b = (self.edges[:, 1:2] * width + d).ravel()
            em = np.repeat(self.edge_mass, width)
            rows += [a, b]
            cols += [b, a]
            values += [em, em]
        return np.concatenate(rows), np.concatenate(cols), np.concatenate(values)


def mesh_matrix_mass_multiply(
    vertex_mass: Any, edges: Any, edge_mass: Any, dx: Any, *, factor: float = 1.0
) -> np.ndarray:
    """Reference ``df = factor * M dx`` of the consistent MeshMatrixMass, in SOFA's operation order.

    ``vertex_mass`` (n,), ``edges`` (k, 2), ``edge_mass`` (k,), ``dx`` (n, width) -> (n, width).
    """
    vm = np.asarray(vertex_mass, dtype=np.float64).reshape(-1)
    d = np.asarray(dx, dtype=np.float64)
    if d.ndim != 2 or len(d) != len(vm):
        raise ValueError(f"dx must have shape ({len(vm)}, width), not {d.shape}")
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    em = np.asarray(edge_mass, dtype=np.float64).reshape(-1)
    if len(em) != len(e):
        raise ValueError("edges and edge_mass differ in length")
    result = d * vm[:, None] * factor
    if len(e):
        temp = (em * factor)[:, None]
        # per edge: res[a] += dx[b] * temp, then res[b] += dx[a] * temp (interleaved, in edge order)
        targets = e.ravel()
        sources = e[:, ::-1].ravel()
        np.add.at(result, targets, d[sources] * np.repeat(temp, 2, axis=0))
    return result


def mesh_matrix_mass(
    positions: Any,
    *,
    edges: Any = None,
    triangles: Any = None,
    quads: Any = None,
    tetrahedra: Any = None,
    hexahedra: Any = None,
    mass_density: Any = None,
    total_mass: float | None = None,
    vertex_mass: Any = None,
    edge_mass: Any = None,
    lumping: bool = False,
) -> MeshMatrixMassData:
    """SOFA's MeshMatrixMass after init (vertex and edge masses of the consistent mass matrix).

    ``positions``: the geometry state's positions at init (``computeMassOnRest`` defaults to false)
    or its rest positions when the scene sets it, (n, 1..3). ``edges``: the topology's own edge list
    when it has one, else ``None`` (derived from the elements as SOFA does, ``topology_edges``).
    ``mass_density``: a scalar or one value per element; ``total_mass``, ``vertex_mass``,
    ``edge_mass``: the scene's values, ``None`` when not set.

    Per element of measure V and density rho (tetrahedra: each vertex rho V/10, each of the 6 edges
    rho V/20; hexahedra: rho V/20 per vertex, rho V/40 on each of its 12 edges; triangles: rho A/6,
    rho A/12; quads (4 edges, no diagonals): rho A/8, rho A/16). Lumping coefficient 2.5 (volumes) or
    2 (surfaces). Precedence (massInitialization): totalMass (computed with density 1, then scaled),
    else massDensity (wrong size or negative -> totalMass 1), else vertexMass with edgeMass (used as
    given) or, lumped, vertexMass alone; else totalMass 1. A negative totalMass becomes 1.

    Raises ValueError for no elements, an edge-only topology (SOFA's MeshMatrixMass computes no mass
    from edges), positions of too low a dimension, given edges missing an element edge, or all-zero
    masses.
    """
    points = _points(positions)
    n = len(points)
    cells = {
        "edges": as_cells(edges, "edges", n),
        "triangles": as_cells(triangles, "triangles", n),
        "quads": as_cells(quads, "quads", n),
        "tetrahedra": as_cells(tetrahedra, "tetrahedra", n),
        "hexahedra": as_cells(hexahedra, "hexahedra", n),
    }
    kind = _element_type(cells, "MeshMatrixMass")
    if kind == "edges":
        raise ValueError("MeshMatrixMass: SOFA computes no mass on an edge topology (all masses would be 0)")
    _check_dimension(kind, points.shape[1], "MeshMatrixMass")
    elements = cells[kind]
    if edges is not None and len(cells["edges"]):
        topology_edge_list = cells["edges"]
    else:
        topology_edge_list = topology_edges(
            n,
            triangles=cells["triangles"],
            quads=cells["quads"],
            tetrahedra=cells["tetrahedra"],
            hexahedra=cells["hexahedra"],
        )
    element_edges = element_edge_indices(kind, elements, topology_edge_list, n)
    spec = _CONSISTENT[kind]
    measure = element_measures(points, elements, kind)
    m = len(elements)
    n_edges = len(topology_edge_list)
    notes: list[str] = []

    def compute(density: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """computeMass: (vertexMass, edgeMass, totalMass accumulated by the creation functions)."""
        vertex_share = (density * measure) / spec.vertex_divisor
        edge_share = (density * measure) / spec.edge_divisor
        nodes = elements.shape[1]
        per_element_edges = element_edges.shape[1]
        em = np.zeros(n_edges)
        totals = []
        if not lumping:
            np.add.at(em, element_edges.ravel(), np.repeat(edge_share, per_element_edges))
            totals.append(float(per_element_edges) * edge_share * 2.0)
            totals.append(float(nodes) * vertex_share)
        else:
            totals.append(float(nodes) * vertex_share * spec.lumping)
        vm = np.zeros(n)
        np.add.at(vm, elements.ravel(), np.repeat(vertex_share, nodes))
        return vm, em, _sequential_sum(np.concatenate(totals))

    def from_total(total: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        vm, em, measured = compute(np.ones(m))
        density = total / measured if measured > EPSILON else 1.0
        return vm * density, em * density, total, np.full(m, density)

    def density_ok(value: Any) -> np.ndarray | None:
        rho = np.asarray(value, dtype=np.float64).reshape(-1)
        if rho.size == 1:
            return None if rho[0] < 0.0 else np.full(m, rho[0])
        if rho.size != m:
            notes.append(f"MeshMatrixMass: massDensity has {rho.size} values, should be 1 or {m}")
            return None
        return None if (rho < 0.0).any() else rho

    def fallback(reason: str) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        notes.append(f"MeshMatrixMass: {reason}; SOFA uses totalMass=1")
        return from_total(1.0)

    given_vm = None if vertex_mass is None else np.asarray(vertex_mass, dtype=np.float64).reshape(-1)
    given_em = None if edge_mass is None else np.asarray(edge_mass, dtype=np.float64).reshape(-1)
    vm_ok = given_vm is not None and given_vm.size == n and not (given_vm < 0.0).any()
    em_ok = given_em is not None and given_em.size == n_edges and not (given_em < 0.0).any()

    if total_mass is not None:
        if mass_density is not None or vertex_mass is not None:
            notes.append("MeshMatrixMass: totalMass overrides the other mass information (SOFA warns)")
        total = float(total_mass)
        if total < 0.0:
            notes.append(f"MeshMatrixMass: negative totalMass={total}; SOFA uses totalMass=1")
            total = 1.0
        vm, em, total, rho = from_total(total)
    elif mass_density is not None:
        if vertex_mass is not None:
            notes.append("MeshMatrixMass: massDensity overrides vertexMass (SOFA warns)")
        checked = density_ok(mass_density)
        if checked is None:
            vm, em, total, rho = fallback("massDensity has the wrong size or a negative value")
        else:
            rho = checked
            vm, em, _ = compute(rho)
            if lumping:
                total = _sequential_sum(vm) * spec.lumping
            else:
                total = _sequential_sum(vm) + _sequential_sum(em) * 2.0
    elif given_vm is not None:
        if given_em is not None or lumping:
            if not vm_ok or (given_em is not None and not em_ok):
                vm, em, total, rho = fallback("vertexMass / edgeMass have the wrong size or a negative value")
            else:
                computed_vm, em, _ = compute(np.ones(m))
                volume = _sequential_sum(computed_vm * spec.lumping)
                vm = given_vm.copy()
                if given_em is not None:
                    em = given_em.copy()
                total = _sequential_sum(np.concatenate([vm, em if given_em is not None else []]))
                rho = np.full(m, total / volume if volume else np.inf)
        else:
            vm, em, total, rho = fallback("vertexMass without edgeMass needs lumping=true")
    else:
        vm, em, total, rho = from_total(1.0)

    if not np.any(vm != 0.0):
        raise ValueError(
            f"MeshMatrixMass: every vertex mass is zero (total {kind} measure {_sequential_sum(measure):g})"
        )
    return MeshMatrixMassData(
        vertex_mass=vm,
        edges=topology_edge_list.astype(np.int64),
        edge_mass=em,
        lumping_coefficient=spec.lumping,
        lumped=bool(lumping),
        element=kind,
        total_mass=float(total),
        mass_density=rho,
        notes=tuple(notes),
    )
