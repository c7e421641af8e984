"""Penalty contact as SOFA's DefaultAnimationLoop runs it, compiled for the model pairs that can meet.

At compile time: the pipeline's collision models in SOFA's order, the pairs its broad phase can
ever produce (different nodes or selfCollision, not both static, disjoint groups, an intersector
for the two types), each with its element test and model order fixed, and where each pair's
response goes (a static partner: inside the other model's group, in its force evaluations and K dx
products; two simulated models: one explicit force per step). At run time (runtime/sofac/penalty.h):
trees refit, broad and narrow phase, SOFA's contact order, the contacts' forces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component, Node
from sofac.registry import Category, Variant
from sofac.registry.components.collision import response_params

from .ir import (
    REPORT_FIELDS,
    Collision,
    CollisionModel,
    ContactPair,
    ElementTest,
    Env,
    Group,
    Op,
    Scheme,
    call,
    origin_of,
)

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# The intersector's type order: a pair's first model is the one of higher rank (SOFA registers
# Triangle-Line, Line-Point, Sphere-Point, Line-Sphere, Triangle-Sphere, never the other way).
_RANK = {Variant.TRIANGLE: 3, Variant.LINE: 2, Variant.SPHERE: 1, Variant.POINT: 0}
# The element tests each method registers (runtime/sofac/proximity.h), by (first, second) kind.
_TESTS = {
    Variant.NEW_PROXIMITY: {
        ("point", "point"),
        ("line", "point"),
        ("line", "line"),
        ("triangle", "point"),
        ("triangle", "line"),
        ("triangle", "triangle"),
        ("sphere", "sphere"),
        ("sphere", "point"),
        ("line", "sphere"),
        ("triangle", "sphere"),
    },
    # MinProximity ignores Triangle-Line and Triangle-Triangle (MinProximityIntersection::init).
    Variant.MIN_PROXIMITY: {
        ("point", "point"),
        ("line", "point"),
        ("line", "line"),
        ("triangle", "point"),
        ("sphere", "sphere"),
        ("sphere", "point"),
        ("triangle", "sphere"),
        ("line", "sphere"),
    },
}
# LocalMinDistance registers MinProximity's pairs (Triangle-Line and Triangle-Triangle ignored);
# sofac compiles its triangle, line and point tests (runtime local_min_distance::).
_TESTS[Variant.LOCAL_MIN_DISTANCE] = {
    ("point", "point"),
    ("line", "point"),
    ("line", "line"),
    ("triangle", "point"),
}
# Lagrangian contacts whose rows are reserved in the constraint problem at creation; a step with more
# doubles the reserve (lagrangian_contact.h, FrictionContacts::fit), a growth in the pipeline's report.
_CONTACT_CAPACITY = 128
_RESPONSES = {"PenalityContactForceField": "penalty", "FrictionContactConstraint": "friction_contact"}
# MinProximityIntersection's switches: the pairs each one removes.
_MIN_PROXIMITY_SWITCHES = {
    "usePointPoint": {("point", "point")},
    "useLinePoint": {("line", "point")},
    "useLineLine": {("line", "line")},
    "useSphereTriangle": {("triangle", "sphere")},
}


@dataclass
class _Setup:
    """One detection-and-response pipeline: a CollisionPipeline (its models are those below its
    node; its phases and response the first found there) or a SubCollisionPipeline (all linked)."""

    pipeline: CheckedComponent
    parts: dict[str, CheckedComponent]  # broad_phase, narrow_phase, intersection, contact_manager
    models: list[CheckedComponent]


_PARTS = {
    "broad_phase": "broadPhaseDetection",
    "narrow_phase": "narrowPhaseDetection",
    "intersection": "intersectionMethod",
    "contact_manager": "contactManager",
}


def _role(checked: CheckedComponent) -> str | None:
    role = checked.spec.variant if checked.spec else None
    return "intersection" if role in _TESTS else role


def _setups(planner: Planner) -> list[_Setup] | str:
    """The scene's pipelines in the order SOFA runs them, or why they are not compiled."""
    pipelines = [
        c for c in planner.checked if c.category is Category.COLLISION_PIPELINE and _role(c) in _PIPELINES
    ]
    if not pipelines:
        return "a collision pipeline"
    composite = next((c for c in pipelines if _role(c) == Variant.COMPOSITE_PIPELINE), None)
    setups: list[_Setup] = []
    if composite is not None:
        subs = composite.link_lists.get("subCollisionPipelines", [])
        if not subs:
            return "a CompositeCollisionPipeline with its subCollisionPipelines linked"
        for sub in subs:
            checked = planner.checked.of(sub)
            parts = {role: checked.links.get(name) for role, name in _PARTS.items()}
            if any(not isinstance(p, Component) for p in parts.values()):
                return f"SubCollisionPipeline {sub.label!r} with its four phases linked (else SOFA skips it)"
            models = [planner.checked.of(m) for m in checked.link_lists.get("collisionModels", [])]
            setups.append(_Setup(checked, {r: planner.checked.of(p) for r, p in parts.items()}, models))
        return setups
    pipeline = pipelines[0]
    found: dict[str, CheckedComponent] = {}
    models = []
    for checked in _below(planner, pipeline.component.node):
        role = _role(checked)
        if role in _PARTS:
            found.setdefault(role, checked)
        elif checked.category is Category.COLLISION_MODEL:
            models.append(checked)
    missing = [role for role in _PARTS if role not in found]
    if missing:
        return f"a CollisionPipeline with its {', '.join(missing)} below its node"
    return [_Setup(pipeline, found, models)]


_PIPELINES = (Variant.PIPELINE, Variant.COMPOSITE_PIPELINE)


def _below(planner: Planner, node: Node) -> list[CheckedComponent]:
    """The components of a node and below, as SOFA's get(SearchDown) lists them: a node's objects,
    then its children, depth first."""
    found: list[CheckedComponent] = [planner.checked.of(c) for c in node.objects]
    for child in node.children:
        found += _below(planner, child)
    return found


def contact_setup_refusal(planner: Planner) -> str:
    """Why the scene's contacts cannot be compiled ("" when they can)."""
    setups = _setups(planner)
    if isinstance(setups, str):
        return (
            f"penalty contact is compiled for {setups}: BruteForceBroadPhase, BVHNarrowPhase, "
            "MinProximityIntersection or NewProximityIntersection and a CollisionResponse"
        )
    loops = [
        c.spec.name for c in planner.checked if c.category is Category.ANIMATION_LOOP and c.spec is not None
    ]
    loop = loops[0] if loops else "DefaultAnimationLoop"
    for setup in setups:
        for role, checked in setup.parts.items():
            spec = checked.spec
            if spec is None or not spec.supported or (role == "intersection" and spec.variant not in _TESTS):
                return f"{checked.component.type_name} is not compiled yet"
        manager = setup.parts["contact_manager"]
        if manager.spec is not None and manager.spec.name == "RuleBasedContactManager":
            # its rules are triplets "name1 name2 response"; SOFA's parser stops at the first
            # incomplete one, so rules="default" gives no rule: CollisionResponse's behaviour
            words = str(planner.value(manager.component, "rules") or "").split()
            if len(words) >= 3:
                return "RuleBasedContactManager's rules (a response per pair of groups) are not compiled yet"
        response = str(planner.value(manager.component, "response") or "")
        kind = _RESPONSES.get(response)
        if kind is None:
            return (
                f"the contact response {response!r} is not compiled yet (PenalityContactForceField and "
                "FrictionContactConstraint are)"
            )
        if kind == "penalty" and loop != "DefaultAnimationLoop":
            return f"penalty contact under {loop} is not compiled yet (DefaultAnimationLoop is)"
        if kind == "friction_contact" and loop != "FreeMotionAnimationLoop":
            return (
                f"FrictionContactConstraint under {loop}: it needs FreeMotionAnimationLoop (free positions)"
            )
        if kind == "friction_contact" and len(setups) > 1:
            return "Lagrangian contact from several collision pipelines is not compiled yet"
        for checked in setup.models:
            spec = checked.spec
            assert spec is not None
            if spec.variant not in _RANK:
                return f"{spec.name} takes no part in compiled contacts"
            if kind == "friction_contact" and spec.variant is Variant.SPHERE:
                return "Lagrangian contact on spheres is not compiled yet"
            if checked.datatype is not None and checked.datatype.name != "Vec3d":
                return (
                    f"{spec.name}<{checked.datatype.name}> contacts are not compiled yet (Vec3d models are)"
                )
            if planner.value(checked.component, "selfCollision"):
                return "self-collision is not compiled yet"
            if planner.value(checked.component, "contactResponse"):
                return "a model's own contactResponse is not compiled yet"
    return ""


def plan_collisions(planner: Planner, owner: dict[int, Group]) -> list[Collision]:
    """The scene's compiled contacts, one per pipeline in SOFA's order, and their calls in the
    groups of the models they act on."""
    setups = _setups(planner)
    assert not isinstance(setups, str)
    collisions = []
    for index, setup in enumerate(setups):
        collision = _plan_collision(planner, setup, index, owner)
        if collision is not None:
            collisions.append(collision)
    return collisions


def _plan_collision(
    planner: Planner, setup: _Setup, number: int, owner: dict[int, Group]
) -> Collision | None:
    pipeline, intersection = setup.pipeline, setup.parts["intersection"]
    method = intersection.spec.variant if intersection.spec else None
    value = planner.value
    tests = set(_TESTS[method])
    if method == Variant.MIN_PROXIMITY:
        for switch, removed in _MIN_PROXIMITY_SWITCHES.items():
            if value(intersection.component, switch) is False:
                tests -= removed
    models: list[CollisionModel] = []
    checked_models = [c for c in setup.models if value(c.component, "active") is not False]
    for checked in checked_models:
        model = _model(planner, checked)
        if model is None:
            return None
        models.append(model)
    manager = setup.parts["contact_manager"].component
    response = _RESPONSES[str(value(manager, "response"))]
    collision = Collision(
        response=response,
        origin=origin_of(pipeline.component),
        method=method,
        alarm_distance=float(value(intersection.component, "alarmDistance")),
        contact_distance=float(value(intersection.component, "contactDistance")),
        depth=int(value(pipeline.component, "depth")),
        models=models,
        tests=[],
        pairs=[],
    )
    if method == Variant.LOCAL_MIN_DISTANCE:
        i = intersection.component
        collision.lmd = (
            value(i, "filterIntersection") is not False,
            float(value(i, "angleCone")),
            float(value(i, "coneFactor")),
            bool(value(i, "useLMDFilters")),
        )
    if response == "friction_contact":
        params = response_params(str(value(manager, "responseParams") or ""))
        collision.mu = float(params.get("mu", 0.8))  # >= 0: the contact manager's spec checks it
    use_line_line = method == Variant.NEW_PROXIMITY and bool(value(intersection.component, "useLineLine"))
    for later in range(len(models)):
        for earlier in range(later):
            a, b = models[later], models[earlier]
            why = _never(planner, checked_models[later], checked_models[earlier], a, b)
            first, second = (later, earlier) if _RANK[a.kind] >= _RANK[b.kind] else (earlier, later)
            kinds = (models[first].kind, models[second].kind)
            if not why and kinds not in tests:
                why = f"{method} has no {kinds[0]}-{kinds[1]} test"
            if why:
                collision.left_out.append((a.origin, b.origin, why))
                continue
            options: tuple[bool, ...] = ()
            if kinds == ("triangle", "triangle"):
                options = (False, use_line_line)
            elif kinds == ("triangle", "line") and method == Variant.NEW_PROXIMITY:
                options = (use_line_line,)
            elif kinds == ("triangle", "point") and method == Variant.MIN_PROXIMITY:
                options = (bool(value(intersection.component, "useSurfaceNormals")),)
            test = ElementTest(f"{method}::{kinds[0]}_{kinds[1]}", options)
            if test not in collision.tests:
                collision.tests.append(test)
            m1, m2 = models[first], models[second]
            if kinds == ("triangle", "triangle"):
                id_bound = 3 * m1.elements + 12 * m2.elements
            else:
                id_bound = max(m1.elements, m2.elements) + 1
            collision.pairs.append(
                ContactPair(
                    first, second, collision.tests.index(test), m1.simulated and m2.simulated, id_bound
                )
            )
    if not collision.pairs:
        return collision
    used = sorted({i for p in collision.pairs for i in (p.first, p.second)})
    for kind in _RANK:
        for view, index in enumerate(i for i in used if models[i].kind == kind):
            models[index].view = view
    rows = [
        (p.first, p.second, int(p.root), p.id_bound, p.test, models[p.first].view, models[p.second].view)
        for p in collision.pairs
    ]
    collision.table = planner.buffer(pipeline.component, "contact_pairs", rows, "i64", columns=7)
    collision.report = planner.buffer(
        pipeline.component, "contactReport", np.zeros(len(REPORT_FIELDS)), role="state"
    )
    if response == "friction_contact":
        ranks = _node_ranks(planner.checked.scene.root)
        nodes = [c.component.node for c in checked_models]
        for model, node in zip(models, nodes, strict=True):
            model.node_rank = ranks[id(node)]
        here = ranks[id(pipeline.component.node)]
        for pair in collision.pairs:
            a, b = models[pair.first], models[pair.second]
            collision.ranks.append(here if pair.root else (a.node_rank if a.simulated else b.node_rank))
        collision.row_capacity = (3 if collision.mu > 0 else 1) * _CONTACT_CAPACITY
        if method == Variant.LOCAL_MIN_DISTANCE:
            for model, checked in zip(models, checked_models, strict=True):
                _add_cone(planner, collision, model, checked)
        return collision
    _place(planner, collision, number, owner)
    return collision


def _node_ranks(root: Node) -> dict[int, int]:
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


def _add_cone(
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


def _model(planner: Planner, checked: CheckedComponent) -> CollisionModel | None:
    from .lower.common import _topology_cells

    state = planner.state_of(checked)
    spec = checked.spec
    assert spec is not None
    if state is None or state.datatype.name != "Vec3d":
        planner.unsupported(checked, "a collision model needs a Vec3d MechanicalObject in its node")
        return None
    kind = spec.variant
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
    )


def _never(
    planner: Planner,
    a_checked: CheckedComponent,
    b_checked: CheckedComponent,
    a: CollisionModel,
    b: CollisionModel,
) -> str:
    """Why the broad phase never pairs two models ("" if it may): CollisionModel::canCollideWith
    and BruteForceBroadPhase's static test."""
    if a_checked.component.node is b_checked.component.node:
        return "models of one node collide only with selfCollision"
    groups_a = set(np.atleast_1d(planner.value(a_checked.component, "group") or []).tolist())
    groups_b = set(np.atleast_1d(planner.value(b_checked.component, "group") or []).tolist())
    if groups_a & groups_b:
        return "they share a collision group"
    if not a.simulated and not b.simulated:
        return "both are static (simulated=0)"
    if not a.elements or not b.elements:
        return "one of them has no element"
    return ""


def _place(planner: Planner, collision: Collision, pipeline: int, owner: dict[int, Group]) -> None:
    """Each simulated model's contact forces in the group integrating its state: in every force
    evaluation and, for its contacts with static models, in every K dx product."""
    in_pairs = {i for p in collision.pairs for i in (p.first, p.second)}
    for index, model in enumerate(collision.models):
        if index not in in_pairs or not model.simulated:
            continue
        group = owner.get(id(model.state.component))
        if group is None:
            continue  # nothing integrates it: the forces on it go nowhere, as in SOFA
        where = f"contact forces on {model.origin}"
        state = model.state
        group.forces.append(
            Op(where, [call("contact_add_force", Env.CONTACTS, pipeline, index, state.f, state.x)])
        )
        static_partner = any(
            not collision.models[p.second if p.first == index else p.first].simulated
            for p in collision.pairs
            if index in (p.first, p.second)
        )
        if group.assembled and static_partner:  # A += kfact K: blocks between each element's points
            offset = group.assembly_offset(state, planner.checked.of(state.component))
            assembly = (Env.CONTACTS, pipeline, index, Env.ASSEMBLER, offset, Env.KFACT)
            group.assemble.append(Op(where, [call("contact_assemble", *assembly)]))
            if group.btd:  # SOFA's coupling blocks with the static side, read as the system's DOFs
                group.assemble.append(
                    Op(where, [call("contact_assemble_static_coupling", *assembly, Env.BAND)])
                )
            elif group.linear_solver is not None:
                solver = group.linear_solver
                planner.diags.add(
                    "W232",
                    solver.loc,
                    f"{solver.type_name} at line {solver.loc.line} assembles the contacts of "
                    f"{model.origin} with a static model: SOFA's MatrixLinearSystem also adds their "
                    "coupling blocks at the static contact points' indices, read as this system's "
                    "DOFs; sofac leaves them out for this solver, so its solve can differ from SOFA's "
                    "while they touch",
                    "BTDLinearSolver and a matrix-free CGLinearSolver reproduce SOFA here",
                )
        if group.scheme is Scheme.IMPLICIT and static_partner and state.dx is not None:
            group.stiffness_dx.append(
                Op(
                    where,
                    [
                        call(
                            "contact_add_dforce", Env.CONTACTS, pipeline, index, state.df, state.dx, Env.KFACT
                        )
                    ],
                )
            )
