"""Passes over the lowered groups: the contact guard, J routed through mappings for assembled
systems, mapped states nobody reads left out, init-only parameters, and the effects list.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import (
    INPUT_OFFSET,
    OFFSET,
    STEP_PHASES,
    Buffer,
    Call,
    ContactGuard,
    Group,
    Note,
    Offset,
    Op,
    Response,
    SelfFilter,
    Statement,
    StatePlan,
    bind,
    buffers_of,
    call,
    kernel,
    origin_of,
)
from sofac.registry import Category

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# What each self-collision filter lets through (the effects table).
_FILTERS = {
    SelfFilter.SAME_MODEL: "e1 < e2",
    SelfFilter.SAME_LINES: "e1 < e2, no shared point, no edge touching both",
    SelfFilter.TRIANGLE_POINT: "not a vertex of the triangle",
    SelfFilter.LINE_POINT: "not an end of the line nor of an edge around its ends",
}


def init_only(planner: Planner, groups: list[Group]) -> frozenset[str]:
    """The parameters the init code reads and no per-step code does."""

    init = buffers_of([c for g in groups for c in g.calls(("init",))])
    step = buffers_of([c for g in groups for c in g.calls(STEP_PHASES)])
    return frozenset(
        buffer.key
        for buffer in planner.buffers
        if buffer.role == "param" and buffer.ident in init and buffer.ident not in step
    )


def effects(planner: Planner, groups: list[Group]) -> list[tuple[str, str, str]]:
    """What the compiled step does and why: one line per effect, naming its component."""
    effects = []
    for group in groups:
        states = ", ".join(s.path for s in group.states)
        scheme = (
            "static (Newton-Raphson)"
            if group.static
            else "Newmark"
            if group.newmark
            else "variational symplectic"
            if group.variational
            else "BDF"
            if group.bdf
            else "central difference"
            if group.central_difference is not None
            else group.scheme
        )
        effects.append(("integration", origin_of(group.solver), f"{scheme} scheme over {states}"))
        linear = group.linear_solver
        if linear is not None and all(linear is not c for c in planner.lowered):
            effects.append(("linear_solve", origin_of(linear), f"solves the system of {states}"))
        for preconditioner in group.preconditioners:
            rate = group.pcg.get("assemblingRate")
            every = int(rate.initial[0]) if rate is not None else 1
            when = "every solve" if every == 1 else f"every {every} solves"
            effects.append(
                (
                    "linear_solve",
                    origin_of(preconditioner),
                    f"preconditions {origin_of(group.linear_solver)}, on the matrix assembled {when}",
                )
            )
    if planner.gravity.key not in planner.pruned:
        effects.append(
            ("gravity", "root node", f"g = {planner.gravity.initial.tolist()}, applied by the masses")
        )
    kept_out = {id(component) for component, _ in planner.ignored}
    on_read: list[tuple[str, str, str]] = []
    for group in groups:
        for state in group.unread:
            mapping = planner.checked.mapping_of(state.component)
            assert mapping is not None
            kept_out.add(id(mapping.component))
            on_read.append(
                (
                    "computed on read",
                    origin_of(mapping.component),
                    f"nothing in the step reads {state.path} (no mass, force field, constraint or "
                    "mapping to one acts on it): mapped only when read (state views, WriteState, "
                    "regress), not in the step",
                )
            )
    for component in planner.lowered:
        if id(component) in kept_out:
            continue
        spec = planner.checked.of(component).spec
        assert spec is not None
        for effect in sorted(e.value for e in spec.effects):
            if effect == "gravity" and planner.gravity.key in planner.pruned:
                continue
            effects.append((effect, origin_of(component), spec.category.value))
    if planner.guard is not None:
        for origin, state in planner.guard.models:
            effects.append(
                (
                    "collision",
                    origin,
                    f"contact guard on {state.path}: its box is tested against the other models' "
                    "before each step, which stops before a contact (response not compiled)",
                )
            )
    for collision in planner.collisions:
        models = collision.models
        for pair in collision.pairs:
            first, second = models[pair.first], models[pair.second]
            if pair.root:
                where = "explicit: once per step at its start (two simulated models)"
            elif pair.grouped:
                where = "in the group integrating the pipeline's node (two simulated models): forces and K dx"
            else:
                where = "in the group of the simulated model (a static partner): forces and K dx"
            if pair.self_filter is SelfFilter.NEVER:
                where += "; one point model: SOFA's element filter refuses every pair (no narrow phase)"
            elif pair.self_filter is not SelfFilter.NONE:
                where += f"; one node: SOFA's element filter ({_FILTERS[pair.self_filter]})"
            if not pair.respond:
                where += '; contactResponse "nullptr": detected, no contact'
            test = collision.tests[pair.test].name
            if collision.response is Response.FRICTION_CONTACT:
                rows = 3 if collision.mu > 0 else 1
                where = f"FrictionContactConstraint mu={collision.mu!r}: {rows} constraint row(s) per contact"
                effects.append(("contact pair", f"{first.origin} / {second.origin}", f"{test}, {where}"))
                continue
            effects.append(("contact pair", f"{first.origin} / {second.origin}", f"{test}, penalty {where}"))
        for lazy in collision.lazy:
            names = ", ".join(models[i].origin for i in lazy.models)
            effects.append(
                (
                    "mapped when near",
                    lazy.origin,
                    f"only {names} read its points: mapped by the step while in contact, by the "
                    "detection when a pair may meet (the parent's box, grown by the mapping's "
                    f"overshoot {lazy.spread:.3g} x its extent, against the partners'), and when read",
                )
            )
        reasons: dict[str, list[str]] = {}
        for first, second, why in collision.left_out:
            reasons.setdefault(why, []).append(f"{first} / {second}")
        for why, pairs in reasons.items():
            if len(pairs) <= 6:
                effects.extend(("no contact pair", pair, why) for pair in pairs)
            else:
                effects.append(("no contact pair", f"{len(pairs)} model pairs", why))
    for key, why in planner.pruned.items():
        effects.append(("pruned", key, why))
    effects.extend(on_read)
    for component, why in planner.ignored:
        effects.append(("kept out", origin_of(component), why))
    return effects


def contact_guard(planner: Planner) -> ContactGuard | None:
    """The boxes the step tests before it runs (see ContactGuard): one per collision model on a
    state, the pairs SOFA would test (models of different nodes, not both static)."""
    models: list[tuple[CheckedComponent, StatePlan]] = []
    for checked in planner.guarded:
        state = planner.state_of(checked)
        if state is None or state.datatype.coord_size < 3:
            planner.unsupported(checked, "a collision model needs a MechanicalObject with 3D positions")
            continue
        models.append((checked, state))
    if len(models) < 2:
        return None
    alarm = max(
        (
            float(planner.value(c.component, "alarmDistance") or 0.0)
            for c in planner.checked
            if c.category is Category.COLLISION_PIPELINE and c.spec and c.spec.field("alarmDistance")
        ),
        default=0.0,
    )
    margins, static = [], []
    for checked, _state in models:
        spec = checked.spec
        assert spec is not None
        radius = 0.0
        if spec.field("radius"):  # spheres: the largest radius
            radii = planner.value(checked.component, "listRadius")
            radius = float(np.max(radii)) if radii is not None and np.size(radii) else 0.0
            radius = radius or float(planner.value(checked.component, "radius") or 1.0)
        # SOFA's box test (BaseProximityIntersection) lets two boxes be alarmDistance plus both
        # models' contactDistance apart: half the alarm distance grows each box.
        contact = float(planner.value(checked.component, "contactDistance") or 0.0)
        margins.append(radius + 0.5 * alarm + contact)
        static.append(
            not planner.value(checked.component, "simulated")
            and not planner.value(checked.component, "moving")
        )
    pairs = [
        (a, b)
        for a in range(len(models))
        for b in range(a + 1, len(models))
        if models[a][0].component.node is not models[b][0].component.node and not (static[a] and static[b])
    ]
    if not pairs:
        return None
    return ContactGuard(
        models=[(origin_of(c.component), state) for c, state in models],
        margins=planner.buffer("/", "contact_margins", margins),
        pairs=planner.buffer("/", "contact_pairs", np.array(pairs, dtype=np.int64), "i64", columns=2),
        boxes=planner.buffer("/", "contact_boxes", np.zeros(6 * len(models)), columns=6, role="scratch"),
        touching=planner.buffer("/", "contact_touching", [-1], "i64", role="state"),
    )


def route_through_mappings(planner: Planner, group: Group) -> None:
    """The rows of J for every mapped state an assembled block lands on, and for their own
    mapped inputs (chains), recorded before the blocks: A gets J^T K J (SOFA's
    MatrixLinearSystem projects mapped matrices the same way). Refused where J is not known."""
    mappings = {id(m.child): m for m in group.mappings}
    rows: list[tuple[int, str]] = []
    done: set[int] = set()
    while len(done) < len(group.routed):
        for key, (state, start, checked) in list(group.routed.items()):
            if key in done:
                continue
            done.add(key)
            mapping = mappings.get(key)
            where = f"on the mapped state {state.path}"
            if mapping is None or mapping.assembly is None:
                planner.unsupported(
                    checked,
                    f"a direct solver or assembled preconditioner {where}: its mapping's "
                    "Jacobian is not assembled yet (RigidMapping, BarycentricMapping, SubsetMapping "
                    "and IdentityMapping are); use CGLinearSolver",
                )
                continue
            if mapping.transpose is None:
                planner.unsupported(checked, f"an assembled system {where}: its mapping has mapForces=false")
                continue
            if mapping.geometric is not None:
                planner.unsupported(
                    checked,
                    f"an assembled system {where}: its mapping's geometric stiffness is not assembled yet",
                )
                continue
            slots = {
                OFFSET: Offset(start, mapped=True),
                INPUT_OFFSET: group.assembly_offset(mapping.parent, checked),
            }
            rows.append((start, [Note(f"J: {mapping.origin}"), *(bind(c, slots) for c in mapping.assembly)]))
    rows.sort(key=lambda row: row[0])  # the assembler takes J's rows in order
    group.assemble[:0] = [Op("mappings' Jacobians, rows in order", [s for _, block in rows for s in block])]


def leave_unread_out(planner: Planner, groups: list[Group]) -> None:
    """Moves the mapped states nothing in the step reads, and their mappings, out of the step.

    Read from the lowered plan itself: a mapped state is read when a projection constrains it,
    when a call of a step (forces, masses, products, assembly, energy, init) takes one of its
    vectors, or when it is an input of the mapping of a read state. Anything else (a collision
    model's points when no contact can happen, a mapped node kept for output) only costs time:
    its mapping runs when Python reads the state instead, with the same numbers, since mapping
    x and v is a function of the parents' x and v alone."""
    owners: dict[str, StatePlan] = {}
    for group in groups:
        for state in (*group.states, *group.mapped):
            for vector in (state.x, state.v, state.f, state.dx, state.df):
                if vector is not None:
                    owners[vector.ident] = state

    def states_named(statements: list[Call] | list[Statement]) -> set[int]:
        return {id(owners[ident]) for ident in buffers_of(statements) if ident in owners}

    read = states_named([c for g in groups for c in g.calls()]) | {
        id(p.state) for g in groups for p in g.projections
    }
    if planner.constraints is not None:  # constraint rows read their states
        read |= states_named(planner.constraints.calls())
    if planner.guard is not None:  # the contact guard reads its models' positions before each step
        read |= {id(state) for _, state in planner.guard.models}
    mappings = [m for g in groups for m in g.mappings]
    growing = True
    while growing:  # a read state's mapping reads its inputs (every input of a multi-mapping)
        growing = False
        for mapping in mappings:
            if id(mapping.child) in read:
                inputs = states_named(mapping.apply) - read
                growing = growing or bool(inputs)
                read |= inputs
    mapped_by = {id(m.child) for m in mappings}
    for group in groups:
        unread = [s for s in group.mapped if id(s) not in read and id(s) in mapped_by]
        gone = {id(s) for s in unread}
        group.unread = unread
        group.on_read = [m for m in group.mappings if id(m.child) in gone]
        group.mapped = [s for s in group.mapped if id(s) not in gone]
        group.mappings = [m for m in group.mappings if id(m.child) not in gone]
        for state in unread:  # no product runs through them: no dx, df
            dropped = {id(state.dx), id(state.df)}
            planner.buffers = [b for b in planner.buffers if id(b) not in dropped]
            state.dx = state.df = None


def add_point_forces(planner: Planner, groups: list[Group]) -> None:
    """A force on one DOF of every state the step computes forces on, set from Python between
    steps without recompiling (``<state>.pointForceIndex``, -1: none, and ``<state>.pointForce``):
    how ``sofac view`` applies its mouse spring. On a mapped state it goes up through the mapping
    like any force. Added after the unread states are left out, so that it keeps none in."""
    for group in groups:
        for state in (*group.states, *group.mapped):
            if not state.size:
                continue
            width = state.datatype.deriv_size
            point = planner.buffer(state.component, "pointForceIndex", [-1], "i64", role="param")
            force = planner.buffer(
                state.component, "pointForce", np.zeros(width), columns=width, role="param"
            )
            pull = call(kernel("point_force", state.datatype.name), state.f, point, force, state.size)
            group.forces.append(Op(f"point force on {state.path} (set from Python)", [pull]))


_IR_PACKAGE = Call.__module__.rpartition(".")[0] + "."  # the plan's own types: sofac.plan.ir.*


def _buffers_held(value: Any) -> Iterator[str]:
    """The idents of every buffer a call in ``value`` takes, or a plan object (a collision model, a
    guard) holds, walking the plan's own types; a state's own vectors are not a use of them."""
    if isinstance(value, Call):
        yield from (b.ident for b in value.buffers())
    elif isinstance(value, Buffer):
        yield value.ident
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _buffers_held(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _buffers_held(item)
    elif (
        dataclasses.is_dataclass(value)
        and type(value).__module__.startswith(_IR_PACKAGE)
        and not isinstance(value, StatePlan)
    ):
        for field in dataclasses.fields(value):
            yield from _buffers_held(getattr(value, field.name))


def drop_unread_rest_positions(planner: Planner, groups: list[Group]) -> None:
    """A MechanicalObject's rest_position is allocated only when a call takes it (a FEM's init, a
    RestShapeSpringsForceField, a mapping's set-up): read from the plan itself, the calls of the
    groups (step, init, mappings computed in the step or on read, projections) and what the
    collision pipeline and the contact guard hold."""
    used = set(_buffers_held([groups, planner.collisions, planner.guard, planner.constraints]))
    for state in planner.states.values():
        if state.rest is not None and state.rest.ident not in used:
            rest = state.rest
            planner.buffers = [b for b in planner.buffers if b is not rest]
            state.rest = None
