"""A collision pipeline's models as the plan holds them: each model's elements and contact
settings, and what its element tests and filters read from its topology (LocalMinDistance's cones,
a line model's edges around each vertex). Used by plan/contacts.py."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Node
from sofac.registry import Variant

from .ir import Collision, CollisionModel, origin_of

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def node_ranks(root: Node) -> dict[int, int]:
    """Each node's index in a depth-first pre-order walk (SOFA's top-down visitors)."""
    ranks: dict[int, int] = {}
    pending = [root]
    while pending:
        node = pending.pop()
        ranks[id(node)] = len(ranks)
        pending.extend(reversed(node.children))
    return ranks


def _csr(lists: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.zeros(len(lists) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(items) for items in lists])
    items = np.array([i for items in lists for i in items], dtype=np.int64)
    return offsets, items


def add_cone(
    planner: Planner, collision: Collision, model: CollisionModel, checked: CheckedComponent
) -> None:
    """LocalMinDistance's testValidity data for a point or line model: its topology's triangles,
    edges and adjacency lists (ascending, as MeshTopology builds them). A point model of a node
    without a LineCollisionModel is always valid (no cone)."""
    from sofac.geometry import masses

    from .lower.common import _topology_cells

    assert collision.lmd is not None
    if model.kind not in ("point", "line") or not collision.lmd[0]:
        return
    node = checked.component.node
    if model.kind == Variant.POINT and not any(
        planner.checked.of(c).spec is not None and planner.checked.of(c).spec.variant is Variant.LINE
        for c in node.objects
    ):
        return
    cells = _topology_cells(planner, checked) or {}
    n = model.state.size
    triangles = np.asarray(cells.get("triangles", np.zeros(0)), dtype=np.int64).reshape(-1, 3)
    edges = cells.get("edges")
    if edges is None or not np.size(edges):
        edges = masses.topology_edges(n, triangles=cells.get("triangles"), quads=cells.get("quads"))
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    owner = checked.component
    tri_buffer = planner.buffer(owner, "cone_triangles", triangles, "i64", columns=3)
    if model.kind == Variant.POINT:
        around_vertex: list[list[int]] = [[] for _ in range(n)]
        for t, tri in enumerate(triangles):
            for v in tri:
                around_vertex[int(v)].append(t)
        edges_around: list[list[int]] = [[] for _ in range(n)]
        for e, edge in enumerate(edges):
            for v in edge:
                edges_around[int(v)].append(e)
        tav, eav = _csr(around_vertex), _csr(edges_around)
        model.cone = (
            tri_buffer,
            planner.buffer(owner, "cone_edges", edges, "i64", columns=2),
            planner.buffer(owner, "triangles_around_vertex_offsets", tav[0], "i64"),
            planner.buffer(owner, "triangles_around_vertex", tav[1], "i64"),
            planner.buffer(owner, "edges_around_vertex_offsets", eav[0], "i64"),
            planner.buffer(owner, "edges_around_vertex", eav[1], "i64"),
        )
    else:
        index = {tuple(sorted((int(a), int(b)))): e for e, (a, b) in enumerate(model_edges(planner, model))}
        around_edge: list[list[int]] = [[] for _ in range(model.elements)]
        for t, tri in enumerate(triangles):
            for j in range(3):
                key = tuple(sorted((int(tri[(j + 1) % 3]), int(tri[(j + 2) % 3]))))
                if key in index:
                    around_edge[index[key]].append(t)
        tae = _csr([sorted(set(items)) for items in around_edge])
        model.cone = (
            tri_buffer,
            planner.buffer(owner, "triangles_around_edge_offsets", tae[0], "i64"),
            planner.buffer(owner, "triangles_around_edge", tae[1], "i64"),
        )


def model_edges(planner: Planner, model: CollisionModel) -> np.ndarray:
    """A line model's edges (its cells)."""
    assert model.cells is not None
    return model.cells.initial.reshape(-1, 2)


def collision_model(planner: Planner, checked: CheckedComponent) -> CollisionModel | None:
    from .lower.common import _topology_cells

    state = planner.state_of(checked)
    spec = checked.spec
    assert spec is not None
    kind = spec.variant
    rigid = state is not None and state.datatype.name == "Rigid3d" and kind == Variant.SPHERE
    if state is None or (state.datatype.name != "Vec3d" and not rigid):
        planner.unsupported(
            checked,
            "a collision model needs a Vec3d MechanicalObject in its node (a Rigid3d one for spheres)",
        )
        return None
    value = planner.value
    cells_buffer = radii = None
    elements = flagged = state.size
    if kind == Variant.SPHERE:
        listed = value(checked.component, "listRadius")
        if listed is not None and np.size(listed):
            radii = planner.buffer(checked.component, "listRadius", listed)
    if kind in ("triangle", "line"):
        cells = _topology_cells(planner, checked) or {}
        if kind == Variant.TRIANGLE:
            # The topology's triangles, then two per quad (TriangleCollisionModel::updateFromTopology:
            # (q1, q2, q0) and (q3, q0, q2)); only the first ones get vertex and edge flags.
            array = np.asarray(cells.get("triangles", np.zeros(0)), dtype=np.int64).reshape(-1, 3)
            flagged = len(array)
            quads = np.asarray(cells.get("quads", np.zeros(0)), dtype=np.int64).reshape(-1, 4)
            if len(quads):
                halves = np.stack([quads[:, [1, 2, 0]], quads[:, [3, 0, 2]]], axis=1).reshape(-1, 3)
                array = np.concatenate([array, halves])
        else:
            from sofac.geometry import masses

            array = cells.get("edges")
            if array is None or not np.size(array):
                array = masses.topology_edges(
                    state.size, triangles=cells.get("triangles"), quads=cells.get("quads")
                )
            array = np.asarray(array, dtype=np.int64).reshape(-1, 2)
        if array.size and (array.min() < 0 or array.max() >= state.size):
            planner.unsupported(checked, f"its topology names points beyond the {state.size} of its state")
            return None
        elements = len(array)
        cells_buffer = planner.buffer(checked.component, kind + "s", array, "i64", columns=array.shape[1])
    return CollisionModel(
        origin=origin_of(checked.component),
        kind=kind,
        state=state,
        elements=elements,
        cells=cells_buffer,
        contact_distance=float(value(checked.component, "contactDistance")),
        contact_stiffness=float(value(checked.component, "contactStiffness")),
        moving=bool(value(checked.component, "moving")),
        simulated=bool(value(checked.component, "simulated")),
        compute_normals=kind == Variant.TRIANGLE and bool(value(checked.component, "computeNormals")),
        radii=radii,
        radius=float(value(checked.component, "radius")) if kind == Variant.SPHERE else 0.0,
        flagged=flagged if kind == Variant.TRIANGLE else 0,
        both_side=bool(value(checked.component, "bothSide")) if kind == Variant.TRIANGLE else False,
        rigid=rigid,
    )


def add_edges_around_vertex(planner: Planner, model: CollisionModel, checked: CheckedComponent) -> None:
    """A line model's edgesAroundVertex (its edges are its topology's), for its element filter."""
    if model.edges_around_vertex is not None:
        return
    around: list[list[int]] = [[] for _ in range(model.state.size)]
    for e, (a, b) in enumerate(model_edges(planner, model)):
        around[int(a)].append(e)
        if int(b) != int(a):
            around[int(b)].append(e)
    offsets, items = _csr(around)
    owner = checked.component
    model.edges_around_vertex = (
        planner.buffer(owner, "edges_around_vertex_offsets", offsets, "i64"),
        planner.buffer(owner, "edges_around_vertex", items, "i64"),
    )
