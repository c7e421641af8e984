"""Collision points that only their contacts read cost nothing while they touch nothing.

A collision model's state that nothing else reads (a surface mapped onto the mechanics for
collision only): the J and J^T of its mapping run only while one of its models is in contact, and
when the mapping is linear its points are mapped only when a pair may meet (``ir.LazyPoints``:
the parent's box grown to enclose them decides, before each detection).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from sofac.registry import Variant

from .ir import (
    CHILD,
    PARENT,
    Buffer,
    Call,
    Group,
    LazyPoints,
    MappingOp,
    Response,
    Statement,
    bind,
    buffers_of,
)

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def map_contact_states_while_touching(planner: Planner, groups: list[Group]) -> None:
    """A collision models' state that nothing but their contacts reads (a surface mapped onto the
    mechanics for collision only): the J and J^T of its mapping, in every force evaluation and
    every product of the solve, run only while one of its models has a contact; its forces are
    zero otherwise. When its mapping is linear (each point a weighted sum of parent points), its
    positions and velocities are mapped in the step only while in contact too, and otherwise by
    the detection when a pair may meet (``Collision.lazy``) and on read from Python."""
    models_of: dict[int, list[tuple[int, int]]] = {}
    for number, collision in enumerate(planner.collisions):
        if collision.response is not Response.PENALTY:
            continue
        for index, model in enumerate(collision.models):
            models_of.setdefault(id(model.state), []).append((number, index))

    def not_contacts(calls: list[Statement]) -> set[str]:
        return buffers_of([c for c in calls if not (isinstance(c, Call) and c.kernel.startswith("contact_"))])

    # positions and velocities read by any step but the contacts' (the other groups', the
    # constraints', the contact guard's)
    read = not_contacts([c for g in groups for c in g.calls()])
    if planner.constraints is not None:
        read |= buffers_of(planner.constraints.calls())
    if planner.guard is not None:
        read |= {state.x.ident for _, state in planner.guard.models}
    for group in groups:
        used = not_contacts(group.calls())
        for mapping in group.mappings:
            child = mapping.child
            if id(child) not in models_of:
                continue
            a_parent = any(m.parent is child or child in m.inputs for m in group.mappings)
            vectors = {b.ident for b in (child.f, child.dx, child.df) if b is not None}
            if a_parent or vectors & used:
                continue
            mapping.while_in_contact = tuple(models_of[id(child)])
            projected = any(p.state is child for p in group.projections)
            if not projected and not {child.x.ident, child.v.ident} & read:
                _map_when_near(planner, mapping)


def _map_when_near(planner: Planner, mapping: MappingOp) -> None:
    """Makes a linear mapping's collision points lazy (see LazyPoints) when all its models are of
    one penalty pipeline and none is a sphere (their boxes grow by radii the enclosure leaves out)."""
    pipelines = {number for number, _ in mapping.while_in_contact}
    if len(pipelines) != 1 or mapping.inputs:
        return
    (number,) = pipelines
    collision = planner.collisions[number]
    indices = [index for _, index in mapping.while_in_contact]
    if any(collision.models[i].kind is Variant.SPHERE for i in indices):
        return
    parent, child, jacobian = mapping.parent, mapping.child, mapping.jacobian
    if jacobian.kernel != "linear_map_apply" or mapping.apply != [
        bind(jacobian, {PARENT: parent.x, CHILD: child.x}),
        bind(jacobian, {PARENT: parent.v, CHILD: child.v}),
    ]:
        return  # not the linear map of x and v the enclosure is derived for
    weights = next(a for a in jacobian.args if isinstance(a, Buffer) and a.kind == "f64")
    table = np.asarray(weights.initial, dtype=float).reshape(child.size, -1)
    spread = float(np.max(np.sum(np.maximum(-table, 0.0), axis=1), initial=0.0))
    off = max((abs(math.fsum(row) - 1.0) for row in table), default=0.0)
    # A mapped coordinate sum_j w_j x_j lies within [lo - spread ext - off X, hi + spread ext + off X]
    # of the parent's box (lo, hi, extent ext, X = max(|lo|, |hi|)); its k roundings add at most
    # k eps sum_j |w_j x_j| <= k eps (1 + off + 2 spread) X. Twice that, and a few eps more for the
    # growth's own arithmetic, is the rounding term.
    k = table.shape[1]
    rounding = off * (1.0 + 1e-6) + (2 * k + 8) * _EPS * (1.0 + off + 2.0 * spread)
    saved = planner.buffer(
        child.component, "lazy_parent", np.zeros_like(parent.x.initial), columns=3, role="scratch"
    )
    mapping.mapped_when_near = True
    collision.lazy.append(
        LazyPoints(
            origin=mapping.origin,
            models=indices,
            parent_points=parent.size,
            spread=spread * (1.0 + 8 * _EPS),
            rounding=rounding,
            current=bind(jacobian, {PARENT: parent.x, CHILD: child.x}),
            previous=bind(jacobian, {PARENT: saved, CHILD: child.x}),
            parent=parent.x,
            saved=saved,
        )
    )


_EPS = float(np.finfo(float).eps)
