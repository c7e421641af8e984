"""Penalty contact as SOFA's DefaultAnimationLoop runs it, compiled for the model pairs that can meet.

At compile time: the pipeline's collision models in SOFA's order, the pairs its broad phase can
ever produce (different nodes, or one node with selfCollision; not both static, disjoint groups, an
intersector for the two types), each with its element test, model order and, for models of one
node, SOFA's element filter fixed, and where each pair's response goes (a static partner: inside
the other model's group, in its force evaluations and K dx products; two simulated models: at the
pipeline's node, one explicit force per step, or inside the group of a solver integrating that
node) and which response the models' own contactResponse chooses. At run time
(runtime/sofac/penalty.h): trees refit, broad and narrow phase, SOFA's contact order, the
contacts' forces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component, Node
from sofac.registry import Category, Variant
from sofac.registry.components.collision import RULE_BASED_CONTACT_MANAGER, response_params
from sofac.registry.spec import Effect

from .collision_models import add_cone, add_edges_around_vertex, collision_model, node_ranks
from .contact_placement import pipeline_group, place_contacts, place_in_group
from .ir import (
    REPORT_FIELDS,
    Collision,
    CollisionModel,
    ContactPair,
    ElementTest,
    Group,
    Response,
    SelfFilter,
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
# The contact responses compiled, by the name a contact manager's `response` gives.
_RESPONSES = {
    "PenalityContactForceField": Response.PENALTY,
    "FrictionContactConstraint": Response.FRICTION_CONTACT,
}
# A model's own contactResponse under the penalty response: SOFA's contact factory name, or
# "nullptr", SOFA's way to make no contact for the pair (CollisionResponse::createNewContacts).
_MODEL_RESPONSES = ("PenalityContactForceField", "nullptr")
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
    if role is Variant.PARALLEL_BROAD_PHASE:
        return Variant.BROAD_PHASE
    return "intersection" if role in _TESTS else role


def _broad_phase_order(setup: _Setup, count: int) -> list[tuple[int, int]]:
    """The (later, earlier) model pairs in the order the broad phase hands them to the narrow
    phase: BruteForceBroadPhase::addCollisionModel adds a model against itself, then against each
    earlier one; ParallelBruteForceBroadPhase adds the self pairs as the models come and the others
    after its tasks, in the same order."""
    spec = setup.parts["broad_phase"].spec
    if spec is not None and spec.variant is Variant.PARALLEL_BROAD_PHASE:
        return [(i, i) for i in range(count)] + [(later, e) for later in range(count) for e in range(later)]
    return [(later, e) for later in range(count) for e in (later, *range(later))]


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
    loops = [c.spec for c in planner.checked if c.category is Category.ANIMATION_LOOP and c.spec is not None]
    loop = loops[0].name if loops else "DefaultAnimationLoop"
    # FreeMotionAnimationLoop gives the free positions and the constraint phase contact rows need
    solves_constraints = bool(loops) and Effect.CONSTRAINT_SOLVE in loops[0].effects
    for setup in setups:
        for role, checked in setup.parts.items():
            spec = checked.spec
            if spec is None or not spec.supported or (role == "intersection" and spec.variant not in _TESTS):
                return f"{checked.component.type_name} is not compiled yet"
            if role == Variant.BROAD_PHASE and checked.component.get("box") is not None:
                return f"{checked.component.type_name}'s box (models outside it left out) is not compiled yet"
        manager = setup.parts["contact_manager"]
        if manager.spec is RULE_BASED_CONTACT_MANAGER:
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
        if kind is Response.PENALTY and solves_constraints:
            return f"penalty contact under {loop} is not compiled yet (DefaultAnimationLoop is)"
        if kind is Response.FRICTION_CONTACT and not solves_constraints:
            return (
                f"FrictionContactConstraint under {loop}: it needs FreeMotionAnimationLoop (free positions)"
            )
        if kind is Response.FRICTION_CONTACT and len(setups) > 1:
            return "Lagrangian contact from several collision pipelines is not compiled yet"
        for checked in setup.models:
            spec = checked.spec
            assert spec is not None
            if spec.variant not in _RANK:
                return f"{spec.name} takes no part in compiled contacts"
            intersection = setup.parts["intersection"].spec
            if (
                kind is Response.FRICTION_CONTACT
                and spec.variant is Variant.SPHERE
                and intersection is not None
                and intersection.variant is Variant.LOCAL_MIN_DISTANCE
            ):
                return "LocalMinDistance's sphere tests (Lagrangian contact on spheres) are not compiled yet"
            datatype = checked.datatype.name if checked.datatype is not None else "Vec3d"
            rigid_sphere = (
                datatype == "Rigid3d" and spec.variant is Variant.SPHERE and kind is Response.PENALTY
            )
            if datatype != "Vec3d" and not rigid_sphere:
                return (
                    f"{spec.name}<{datatype}> contacts are not compiled yet (Vec3d models and "
                    "SphereCollisionModel<Rigid3d> are)"
                )
            if kind is Response.FRICTION_CONTACT and planner.value(checked.component, "selfCollision"):
                return "self-collision under FrictionContactConstraint is not compiled yet (penalty is)"
        why = _one_node_refusal(planner, setup)
        if why:
            return why
    return ""


def contact_response_refusals(planner: Planner) -> list[tuple[CheckedComponent, str]]:
    """The collision models whose own contactResponse sofac cannot compile, and why: under
    DefaultAnimationLoop's penalty response "PenalityContactForceField" and "nullptr" (no contact)
    are compiled, under FrictionContactConstraint none yet. (E222 at the attribute.)"""
    setups = _setups(planner)
    if isinstance(setups, str):
        return []
    refused = []
    for setup in setups:
        manager = setup.parts["contact_manager"].component
        kind = _RESPONSES.get(str(planner.value(manager, "response") or ""))
        for checked in setup.models:
            given = _own_response(planner, checked)
            if not given:
                continue
            if kind is Response.FRICTION_CONTACT:
                refused.append(
                    (checked, f"contactResponse={given!r}: a model's own response under "
                     "FrictionContactConstraint is not compiled yet")
                )  # fmt: skip
            elif given not in _MODEL_RESPONSES:
                refused.append(
                    (checked, f"contactResponse={given!r} is not compiled: under DefaultAnimationLoop "
                     "sofac compiles 'PenalityContactForceField' and 'nullptr' (no contact)")
                )  # fmt: skip
    return refused


def _own_response(planner: Planner, checked: CheckedComponent) -> str:
    return str(planner.value(checked.component, "contactResponse") or "").strip()


def _responds(planner: Planner, a: CheckedComponent, b: CheckedComponent) -> bool:
    """Whether SOFA makes a contact for a pair of models (CollisionResponse::getContactResponse:
    the models' own responses when set and not in conflict, else the manager's)."""
    first, second = _own_response(planner, a), _own_response(planner, b)
    if first and second and first != second:
        return True  # the manager's response (penalty)
    return (first or second or "PenalityContactForceField") != "nullptr"


def _one_node_refusal(planner: Planner, setup: _Setup) -> str:
    """Models of one node that SOFA would pair (both with selfCollision) but whose element filter
    never returns: LineCollisionModel::canCollideWithElement and PointCollisionModel's hand the
    question to the other model, which hands it back (two line models, two point models, a line
    model and a point model other than the first of its node)."""
    intersection = setup.parts["intersection"]
    tests = _method_tests(planner, intersection)
    active = [c for c in setup.models if planner.value(c.component, "active") is not False]
    for k, a in enumerate(active):
        for b in active[:k]:
            if a.component.node is not b.component.node:
                continue
            if not (
                planner.value(a.component, "selfCollision") and planner.value(b.component, "selfCollision")
            ):
                continue
            assert a.spec is not None and b.spec is not None
            kinds = tuple(sorted((a.spec.variant, b.spec.variant), key=lambda v: -_RANK[v]))
            if kinds not in tests:
                continue
            looping = kinds in (("line", "line"), ("point", "point")) or (
                kinds == ("line", "point")
                and _node_points(planner, a.component.node) not in (a.component, b.component)
            )
            if looping:
                return (
                    f"{a.spec.name} at line {a.component.loc.line} and {b.spec.name} at line "
                    f"{b.component.loc.line} of one node with selfCollision: SOFA's element filter "
                    "(canCollideWithElement) passes the question between them without end"
                )
    return ""


def _node_points(planner: Planner, node: Node) -> Component | None:
    """The first PointCollisionModel of a node: the `mpoints` of its line and triangle models."""
    for component in node.objects:
        spec = planner.checked.of(component).spec
        if spec is not None and spec.variant is Variant.POINT:
            return component
    return None


def _method_tests(planner: Planner, intersection: CheckedComponent) -> set[tuple[str, str]]:
    """The (first, second) kinds the intersection method has an element test for."""
    method = intersection.spec.variant if intersection.spec else None
    tests = set(_TESTS.get(method, ()))
    if method == Variant.MIN_PROXIMITY:
        for switch, removed in _MIN_PROXIMITY_SWITCHES.items():
            if planner.value(intersection.component, switch) is False:
                tests -= removed
    return tests


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
    tests = _method_tests(planner, intersection)
    models: list[CollisionModel] = []
    checked_models = [c for c in setup.models if value(c.component, "active") is not False]
    for checked in checked_models:
        model = collision_model(planner, checked)
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
    if response is Response.FRICTION_CONTACT:
        params = response_params(str(value(manager, "responseParams") or ""))
        collision.mu = float(params.get("mu", 0.8))  # >= 0: the contact manager's spec checks it
    use_line_line = method == Variant.NEW_PROXIMITY and bool(value(intersection.component, "useLineLine"))
    # Pairs of two simulated models go to the pipeline's node: explicit when no solver integrates
    # it, else into that solver's group (penalty; the Lagrangian response places rows itself).
    home = pipeline_group(planner, pipeline, owner) if response is Response.PENALTY else None
    for later, earlier in _broad_phase_order(setup, len(models)):
        a, b = models[later], models[earlier]
        a_checked, b_checked = checked_models[later], checked_models[earlier]
        if later == earlier:
            why = _never_self(planner, a_checked, a)
            if why is None:
                continue  # no selfCollision: nothing to list
        else:
            why = _never(planner, a_checked, b_checked, a, b)
        first, second = (later, earlier) if _first_in_order(a, b) else (earlier, later)
        kinds = (models[first].kind, models[second].kind)
        if not why and kinds not in tests:
            why = f"{method} has no {kinds[0]}-{kinds[1]} test"
        if why:
            collision.left_out.append((a.origin, b.origin, why))
            continue
        one_node = a_checked.component.node is b_checked.component.node
        self_filter = (
            _self_filter(planner, checked_models[first], checked_models[second], later == earlier)
            if one_node
            else SelfFilter.NONE
        )
        options: tuple[bool, ...] = ()
        if kinds == ("triangle", "triangle"):
            options = (later == earlier, use_line_line)
        elif kinds == ("triangle", "line") and method == Variant.NEW_PROXIMITY:
            options = (use_line_line,)
        elif kinds == ("triangle", "point") and method == Variant.MIN_PROXIMITY:
            options = (bool(value(intersection.component, "useSurfaceNormals")),)
        guard = {SelfFilter.NONE: "", SelfFilter.NEVER: "never"}.get(self_filter, "filter")
        test = ElementTest(f"{method}::{kinds[0]}_{kinds[1]}", options, guard)
        if test not in collision.tests:
            collision.tests.append(test)
        m1, m2 = models[first], models[second]
        if self_filter in (SelfFilter.SAME_LINES, SelfFilter.LINE_POINT):
            add_edges_around_vertex(planner, m1, checked_models[first])
        if kinds == ("triangle", "triangle"):
            id_bound = 3 * m1.elements + 12 * m2.elements
        else:
            id_bound = max(m1.elements, m2.elements) + 1
        both = m1.simulated and m2.simulated
        collision.pairs.append(
            ContactPair(
                first,
                second,
                collision.tests.index(test),
                both and home is None,
                id_bound,
                grouped=both and home is not None,
                self_filter=self_filter,
                one_node=one_node,
                respond=response is not Response.PENALTY or _responds(planner, a_checked, b_checked),
            )
        )
    if not collision.pairs:
        return collision
    used = sorted({i for p in collision.pairs for i in (p.first, p.second)})
    for kind in _RANK:
        for view, index in enumerate(i for i in used if models[i].kind == kind):
            models[index].view = view
    rows = [
        (p.first, p.second, p.placement, p.id_bound, p.test, models[p.first].view, models[p.second].view)
        for p in collision.pairs
    ]
    collision.table = planner.buffer(pipeline.component, "contact_pairs", rows, "i64", columns=7)
    collision.report = planner.buffer(
        pipeline.component, "contactReport", np.zeros(len(REPORT_FIELDS)), role="state"
    )
    if response is Response.FRICTION_CONTACT:
        ranks = node_ranks(planner.checked.scene.root)
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
                add_cone(planner, collision, model, checked)
        return collision
    place_contacts(planner, collision, number, owner)
    if home is not None:
        place_in_group(planner, collision, number, home, owner)
    return collision


def _first_in_order(a: CollisionModel, b: CollisionModel) -> bool:
    """Whether `a` (the later model) is the intersector's first: Triangle before Line before Point,
    Sphere before Point, Line and Triangle before Sphere, and a Vec3d sphere before a Rigid3d one
    (SOFA registers SphereCollisionModel<Vec3d>-RigidSphereModel, never the other way)."""
    if a.kind == b.kind == Variant.SPHERE and a.rigid != b.rigid:
        return not a.rigid
    return _RANK[a.kind] >= _RANK[b.kind]


def _never_self(planner: Planner, checked: CheckedComponent, model: CollisionModel) -> str | None:
    """Why the broad phase never pairs a model with itself (BruteForceBroadPhase::doesSelfCollide);
    None when its selfCollision is off (nothing worth listing)."""
    if not planner.value(checked.component, "selfCollision"):
        return None
    if not model.simulated:
        return "a static model (simulated=0) never collides with itself"
    if not model.elements:
        return "it has no element"
    return ""


def _self_filter(
    planner: Planner, first: CheckedComponent, second: CheckedComponent, same_model: bool
) -> SelfFilter:
    """SOFA's element filter for two models of one node, `first` the intersector's first
    (CollisionElementIterator::canCollideWith and the first model's canCollideWithElement)."""
    assert first.spec is not None and second.spec is not None
    kind = first.spec.variant
    if same_model:
        return {
            Variant.TRIANGLE: SelfFilter.SAME_MODEL,
            Variant.SPHERE: SelfFilter.SAME_MODEL,
            Variant.LINE: SelfFilter.SAME_LINES,
            Variant.POINT: SelfFilter.NEVER,
        }[kind]
    points = _node_points(planner, first.component.node)  # its canCollideWithElement's point model
    if second.spec.variant is Variant.POINT and second.component is points:
        if kind is Variant.TRIANGLE:
            return SelfFilter.TRIANGLE_POINT
        if kind is Variant.LINE:
            return SelfFilter.LINE_POINT
    return SelfFilter.NONE  # the filters answer true (or hand over to a sphere's, which does)


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
        # canCollideWith: one node -> both models' selfCollision decide (their groups do not)
        if not (
            planner.value(a_checked.component, "selfCollision")
            and planner.value(b_checked.component, "selfCollision")
        ):
            return "models of one node collide only with selfCollision"
    elif _share_group(planner, a_checked, b_checked):
        return "they share a collision group"
    if not a.simulated and not b.simulated:
        return "both are static (simulated=0)"
    if not a.elements or not b.elements:
        return "one of them has no element"
    return ""


def _share_group(planner: Planner, a_checked: CheckedComponent, b_checked: CheckedComponent) -> bool:
    groups_a = set(np.atleast_1d(planner.value(a_checked.component, "group") or []).tolist())
    groups_b = set(np.atleast_1d(planner.value(b_checked.component, "group") or []).tolist())
    return bool(groups_a & groups_b)
