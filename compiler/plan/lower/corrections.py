"""Constraint corrections with rows: how a constraint's force moves the DOFs it acts on.

LinearSolverConstraintCorrection's compliance W = J A⁻¹ Jᵀ from the group's own factorisation,
rows carried up rigid, identity and subset mappings to the independent DOFs, and the compliance of
a rigid body (UncoupledConstraintCorrection on Rigid3d). Used by plan/lower/constraints.py.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import (
    CHILD,
    PARENT,
    Aggregate,
    Buffer,
    Call,
    Collision,
    ContactBody,
    Correction,
    Element,
    Env,
    Group,
    LinearSystem,
    MappingOp,
    Op,
    Preconditioner,
    Response,
    StatePlan,
    bind,
    call,
    kernel,
)
from sofac.plan.lower.constraint_context import ConstraintLowering, ConstraintProblem
from sofac.registry import Category, Variant

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def moved_vectors(planner: Planner, component: Component, state: StatePlan) -> tuple[Buffer, ...]:
    """What a correction writes: x, v, and its lambda (J^T f) and constraint_dx vectors."""
    zeros = np.zeros_like(state.v.initial)
    lam = planner.buffer(component, "lambda", zeros, columns=state.v.columns, role="scratch")
    dx = planner.buffer(component, "constraint_dx", zeros, columns=state.v.columns, role="scratch")
    return (state.x, state.v, lam, dx)


def _linear_system_of(planner: Planner, checked: CheckedComponent, group: Group) -> LinearSystem | None:
    """The factorisation a LinearSolverConstraintCorrection solves with: its `linearSolver` link,
    else the first linear solver of its node (SOFA's Local search), which must be the direct
    solver factorising its group's system this step (the group's own, or its PCG's preconditioner)."""
    linked = checked.links.get("linearSolver")
    solver = (
        linked
        if isinstance(linked, Component)
        else next(
            (
                c
                for c in checked.component.node.objects
                if planner.checked.of(c).category is Category.LINEAR_SOLVER
            ),
            None,
        )
    )
    spec = planner.checked.of(solver).spec if solver is not None else None
    own = group.direct and solver is group.linear_solver
    preconditioner = group.preconditioner is Preconditioner.FACTORIZATION and any(
        c is solver for c in group.preconditioners
    )
    if (
        solver is None
        or spec is None
        or spec.lowering != "direct"
        or not (own or preconditioner)
        or group.btd
    ):
        name = solver.type_name if solver is not None else "none"
        planner.unsupported(
            checked,
            f"with constraint rows, its linear solver ({name}) must be the sparse direct solver its ODE "
            "solver's system is factorised by (the group's SparseLDLSolver..., or a PCGLinearSolver's "
            'direct preconditioner): link it with linearSolver="@<the direct solver>"',
            "linearSolver",
        )
        return None
    if len(group.states) != 1:
        planner.unsupported(checked, "with constraint rows, it is compiled for an ODE solver of one state")
        return None
    return LinearSystem(group.ident)


def linear_solver_correction(
    planner: Planner,
    lowering: ConstraintLowering,
    correction: Correction,
    body: int,
    J: Aggregate,
    lagrangian: bool,
    problem: ConstraintProblem,
) -> None:
    """LinearSolverConstraintCorrection on rows (runtime/sofac/linear_correction.h): W += dt J A^-1 J^T
    (+ regularizationTerm), then dx = A^-1 J^T f, x = x_free + dt dx, v = v_free + dx
    (EulerImplicitSolver's position and velocity integration factors)."""
    checked = correction.checked
    assert checked is not None
    phase, solver = lowering.phase, lowering.solver
    unbuilt = phase.method == Variant.UNBUILT_GAUSS_SEIDEL or (
        phase.method == Variant.LCP
        and solver is not None
        and not planner.value(solver.component, "build_lcp")
    )
    if unbuilt:
        planner.unsupported(
            checked, "under an unbuilt constraint solver it is not compiled yet (a built W is)"
        )
        return
    system = _linear_system_of(planner, checked, correction.group)
    if system is None:
        return
    W, f = problem.W, problem.f
    state, component = correction.state, checked.component
    dt = float(planner.dt.initial[0])
    regularization = Element(
        planner.buffer(
            component,
            "regularizationTerm",
            [float(planner.value(component, "regularizationTerm"))],
            role="param",
        )
    )
    t = state.datatype.name
    if lagrangian:
        add = call(
            kernel("lagrangian_linear_add_compliance", t),
            Env.LAGRANGIAN,
            body,
            Env.CONSTRAINT_PATTERN,
            W,
            J,
            system,
            0,
            dt,
            regularization,
        )
    else:
        add = call(
            kernel("linear_add_compliance", t), Env.CONSTRAINT_PATTERN, W, J, system, 0, dt, regularization
        )
    phase.compliance.append(Op(correction.origin, [add]))
    moved = moved_vectors(planner, component, state)
    if lagrangian:
        correct = call(
            kernel("lagrangian_linear_correct", t),
            Env.LAGRANGIAN,
            body,
            *moved,
            J,
            f,
            state.size,
            system,
            0,
            dt,
            1.0,
        )
    else:
        correct = call(kernel("linear_correct", t), *moved, J, f, state.size, system, 0, dt, 1.0)
    phase.correction.append(Op(correction.origin, [correct]))


def _mapped_from(planner: Planner, state: StatePlan) -> tuple[str, StatePlan] | None:
    """The lowering of the mapping whose output is ``state`` and the independent state it maps
    from (None: not mapped, or mapped from a mapped state)."""
    mapping = planner.checked.mapping_of(state.component)
    spec = mapping.spec if mapping is not None else None
    parent = mapping.links.get("input") if mapping is not None else None
    parent_state = planner.states.get(id(parent)) if isinstance(parent, Component) else None
    if spec is None or parent_state is None or parent_state.mapped:
        return None
    return spec.lowering, parent_state


def rigidly_mapped(planner: Planner, state: StatePlan) -> bool:
    """Points (Vec3d) mapped by one RigidMapping from an independent Rigid3d state."""
    found = _mapped_from(planner, state)
    return (
        found is not None
        and found[0] == "rigid_mapping"
        and found[1].datatype.name == "Rigid3d"
        and state.datatype.name == "Vec3d"  # (Rigid3d frames: rows not carried yet)
    )


# Mappings whose applyJT carries constraint rows with constant weights (carry_through_linear_mappings).
_LINEAR_MAPPINGS = ("identity_mapping", "subset_mapping", "barycentric_mapping")


def linearly_mapped(planner: Planner, state: StatePlan) -> bool:
    """A state mapped by one IdentityMapping or SubsetMapping (between states of one DataType) or
    BarycentricMapping from an independent state (whose rows then carry to that state's DOFs)."""
    found = _mapped_from(planner, state)
    return (
        found is not None
        and found[0] in _LINEAR_MAPPINGS
        and (found[0] == "barycentric_mapping" or found[1].datatype.name == state.datatype.name)
    )


def _subset(mapping: MappingOp) -> Buffer | None:
    """An IdentityMapping or SubsetMapping between states of one DataType, from an independent
    state: each child DOF's parent DOF."""
    jacobian = mapping.jacobian
    indices = jacobian.args[2] if jacobian.kernel == "subset_apply" else None
    if (
        not isinstance(indices, Buffer)
        or mapping.parent.mapped
        or mapping.parent.datatype.name != mapping.child.datatype.name
    ):
        return None
    return indices


def increasing_subset(planner: Planner, mapping: MappingOp) -> Buffer | None:
    """An IdentityMapping or SubsetMapping (see _subset) with strictly increasing indices (a
    contact row's DOFs keep their order): its indices."""
    indices = _subset(mapping)
    if indices is None:
        return None
    values = np.asarray(indices.initial, dtype=np.int64).ravel()
    return indices if values.size == 0 or bool(np.all(np.diff(values) > 0)) else None


def mapping_of_state(lowering: ConstraintLowering, state: StatePlan) -> MappingOp | None:
    """The mapping whose child is ``state`` (None: not mapped by a group's mapping)."""
    for group in lowering.groups:
        for mapping in group.mappings:
            if mapping.child is state:
                return mapping
    return None


def mapped_free_motion(
    planner: Planner, lowering: ConstraintLowering, also: set[str] | None = None
) -> dict[str, Buffer]:
    """Free positions of the constrained mapped states, as SOFA makes them: v_free = J v_free of
    the parent (propagateDx, with the mapping's rotated points of the last apply), then
    x_free = x + dt v_free (linearised, not the mapping of the parent's x_free)."""
    phase = lowering.phase
    free: dict[str, Buffer] = {}
    for state in planner.states.values():
        if not state.mapped or (state.ident not in phase.entries and state.ident not in (also or set())):
            continue
        mapping = mapping_of_state(lowering, state)
        if mapping is None:
            continue
        zeros_v, zeros_x = np.zeros_like(state.v.initial), np.zeros_like(state.x.initial)
        v_free = planner.buffer(
            state.component, "freeVelocity", zeros_v, columns=state.v.columns, role="scratch"
        )
        x_free = planner.buffer(
            state.component, "freePosition", zeros_x, columns=state.x.columns, role="scratch"
        )
        jacobian = bind(mapping.jacobian, {PARENT: mapping.parent.v, CHILD: v_free})
        t = state.datatype.name
        advance = call(kernel("advance", t), x_free, state.x, v_free, Element(planner.dt), state.size)
        phase.rows.append(Op(mapping.origin, [jacobian, advance]))
        free[state.ident] = x_free
    return free


def carry_through_linear_mappings(planner: Planner, lowering: ConstraintLowering) -> None:
    """IdentityMapping, SubsetMapping and BarycentricMapping::applyJT on the constraint matrix: a
    mapped point's entry (row, point, n) becomes (row, DOF, n w) on each DOF of the parent it
    follows (w = 1 through identity and subset), in the mapper's column order. The parent's J
    then sums a (row, DOF) met twice (``_jacobian_rows``): no more than two entries meet there
    (a row has two objects), so the sum's order does not matter, as in SOFA's compress."""
    phase = lowering.phase
    for state in planner.states.values():
        if not state.mapped or state.ident not in phase.entries:
            continue
        mapping = mapping_of_state(lowering, state)
        if mapping is None or not linearly_mapped(planner, state):
            continue
        carried = phase.entries.setdefault(mapping.parent.ident, [])
        subset, barycentric = _subset(mapping), barycentric_mapping(mapping)
        if subset is not None:
            parents = np.asarray(subset.initial, dtype=np.int64).ravel()
            carried.extend(
                (row, int(parents[point]), values) for row, point, values in phase.entries[state.ident]
            )
        elif barycentric is not None:
            nodes_buffer, weights_buffer, width = barycentric
            nodes = np.asarray(nodes_buffer.initial, dtype=np.int64).reshape(-1, width)
            weights = np.asarray(weights_buffer.initial, dtype=np.float64).reshape(-1, width)
            counts = mapping.element_nodes
            real = np.asarray(counts.initial, dtype=np.int64) if counts is not None else None
            for row, point, values in phase.entries[state.ident]:
                for j in range(int(real[point]) if real is not None else width):
                    w = float(weights[point, j])
                    carried.append((row, int(nodes[point, j]), tuple(v * w for v in values)))
        else:  # (linearly_mapped holds, so the mapping was lowered otherwise: not expected)
            checked = planner.checked.of(state.component)
            planner.unsupported(checked, "constraint rows through its mapping are not compiled yet")
        del phase.entries[state.ident]


def carry_through_rigid_mappings(planner: Planner, lowering: ConstraintLowering) -> None:
    """RigidMapping::applyJT on the constraint matrix: a mapped point's entry n on a row becomes its
    frame's (n, r x n), r the point's rotated offset; rows keep their index."""
    phase = lowering.phase
    by_parent: dict[str, list[tuple[int, int, int, tuple[float, ...], MappingOp]]] = {}
    for state in planner.states.values():
        if not state.mapped or state.ident not in phase.entries:
            continue
        mapping = mapping_of_state(lowering, state)
        if mapping is None:
            continue
        frames = mapping.jacobian.args[2]
        assert isinstance(frames, Buffer)
        for row, point, values in phase.entries[state.ident]:
            frame = int(frames.initial[point])
            by_parent.setdefault(mapping.parent.ident, []).append((row, frame, point, values, mapping))
    for parent_ident, items in by_parent.items():
        parent = next(s for s in planner.states.values() if s.ident == parent_ident)
        keys = [(row, frame) for row, frame, _, _, _ in items]
        if (
            len(set(keys)) != len(keys)
            or parent_ident in phase.entries
            or len({id(i[4]) for i in items}) != 1
        ):
            planner.unsupported(
                planner.checked.of(parent.component),
                "constraint rows from several mapped states, or several entries of one row on one frame, "
                "are not compiled yet",
            )
            continue
        order = sorted(range(len(items)), key=lambda i: keys[i])
        rows = sorted({row for row, _ in keys})
        starts, dofs, points, directions = [0], [], [], []
        for row in rows:
            for i in order:
                if items[i][0] == row:
                    dofs.append(items[i][1])
                    points.append(items[i][2])
                    directions.extend(items[i][3])
            starts.append(len(dofs))
        mapping = items[0][4]
        offsets = mapping.jacobian.args[3]
        assert isinstance(offsets, Buffer)
        values = planner.buffer(
            parent.component, "J_values", np.zeros(6 * len(dofs)), columns=6, role="scratch"
        )
        buffers = (
            planner.buffer(parent.component, "J_rows", rows, "i64"),
            planner.buffer(parent.component, "J_starts", starts, "i64"),
            planner.buffer(parent.component, "J_dofs", dofs, "i64"),
            values,
        )
        point_buffer = planner.buffer(parent.component, "J_points", points, "i64")
        direction_buffer = planner.buffer(parent.component, "J_directions", directions, columns=3)
        kernel_call = call(
            "rigid_constraint_jacobian", values, point_buffer, direction_buffer, offsets, len(dofs)
        )
        phase.rows.append(Op(mapping.origin, [kernel_call]))
        lowering.computed_rows[parent_ident] = Aggregate("JacobianRows", (len(rows), *buffers))
        phase.entries[parent_ident] = []  # rows known: the correction finds them


def _invert3(m: list[float]) -> list[float]:
    """SOFA's type::invertMatrix for 3x3, operation for operation (runtime invert3)."""
    det = (
        m[0] * m[4] * m[8]
        + m[3] * m[7] * m[2]
        + m[6] * m[1] * m[5]
        - m[0] * m[7] * m[5]
        - m[3] * m[1] * m[8]
        - m[6] * m[4] * m[2]
    )
    out = [0.0] * 9
    out[0] = (m[4] * m[8] - m[7] * m[5]) / det
    out[3] = (m[5] * m[6] - m[8] * m[3]) / det
    out[6] = (m[3] * m[7] - m[6] * m[4]) / det
    out[1] = (m[7] * m[2] - m[1] * m[8]) / det
    out[4] = (m[8] * m[0] - m[2] * m[6]) / det
    out[7] = (m[6] * m[1] - m[0] * m[7]) / det
    out[2] = (m[1] * m[5] - m[4] * m[2]) / det
    out[5] = (m[2] * m[3] - m[5] * m[0]) / det
    out[8] = (m[0] * m[4] - m[3] * m[1]) / det
    return out


def rigid_compliance(
    planner: Planner, checked: CheckedComponent, group: Group, state: StatePlan
) -> np.ndarray | None:
    """UncoupledConstraintCorrection<Rigid3d>::init without 7 compliance values: 1/m and the inverse
    of inertia * m from the node's UniformMass (or defaultCompliance and a unit mass's inverse)."""
    component = checked.component
    use_ode = bool(planner.value(component, "useOdeSolverIntegrationFactors"))
    dt = float(planner.dt.initial[0])
    ode_factor = 1.0 if use_ode else dt * dt
    if component.get("defaultCompliance") is not None:
        first = float(planner.value(component, "defaultCompliance"))
        inertia_mass = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    else:
        masses = [
            c.args[3]
            for op in group.mass_dx
            for c in op.calls
            if isinstance(c, Call) and c.kernel == "mass_multiply" and c.args[0] is state.df
        ]
        mass = masses[0].initial if len(masses) == 1 and isinstance(masses[0], Buffer) else None
        if mass is None or len(mass) != 10:
            planner.unsupported(
                checked, "its compliance needs the state's one UniformMass (or compliance, defaultCompliance)"
            )
            return None
        first = ode_factor / float(mass[0])
        inertia_mass = [float(v) for v in mass[1:10]]
    inverse = _invert3(inertia_mass)
    return np.array([first, *(ode_factor * inverse[i] for i in (0, 1, 2, 4, 5, 8))])


def lagrangian_collision(planner: Planner) -> Collision | None:
    """The scene's FrictionContactConstraint contacts (their rows join the phase), if compiled."""
    return next((c for c in planner.collisions if c.response is Response.FRICTION_CONTACT and c.pairs), None)


def barycentric_mapping(mapping: MappingOp) -> tuple[Buffer, Buffer, int] | None:
    """A BarycentricMapping (Vec3d, from an independent state): its parent DOFs and weights per
    point (columns in its mapper's applyJT order) and their number of columns."""
    jacobian = mapping.jacobian
    if jacobian.kernel != "linear_map_apply" or mapping.parent.mapped:
        return None
    nodes, weights, width = jacobian.args[2], jacobian.args[3], jacobian.args[5]
    assert isinstance(nodes, Buffer) and isinstance(weights, Buffer) and isinstance(width, int)
    return nodes, weights, width


def contact_bodies(
    planner: Planner, lowering: ConstraintLowering, collision: Collision, free_x: dict[str, Buffer]
) -> set[int]:
    """Where each collision model's contact rows land: the correction of its own state, or of the
    state its mapping follows (RigidMapping, IdentityMapping, SubsetMapping with increasing
    indices, BarycentricMapping: the rows carried through applyJT), or none (a static obstacle);
    with the free positions the violation reads. Returns the bodies reached."""
    index = {id(c.state): k for k, c in enumerate(lowering.phase.corrections)}
    reached: set[int] = set()
    for model in collision.models:
        state = model.state
        if not state.mapped:
            body = index.get(id(state), -1)
            collision.bodies.append(ContactBody(body, state.x))
            if body >= 0:
                reached.add(body)
            continue
        mapping = mapping_of_state(lowering, state)
        body = index.get(id(mapping.parent), -1) if mapping is not None else -1
        subset = increasing_subset(planner, mapping) if mapping is not None else None
        barycentric = barycentric_mapping(mapping) if mapping is not None else None
        rigid = rigidly_mapped(planner, state)
        if (
            mapping is None
            or not (rigid or subset is not None or barycentric is not None)
            or state.ident not in free_x
        ):
            planner.unsupported(
                planner.checked.of(state.component),
                "Lagrangian contact on a collision state mapped other than by one RigidMapping, "
                "IdentityMapping, SubsetMapping (increasing indices) or BarycentricMapping from an "
                "independent state is not compiled yet",
            )
            collision.bodies.append(ContactBody(-1, state.x))
            continue
        free = free_x[state.ident]
        if subset is not None:
            collision.bodies.append(ContactBody(body, free, subset=subset))
        elif barycentric is not None:
            nodes, weights, width = barycentric
            collision.bodies.append(
                ContactBody(
                    body, free, nodes=nodes, weights=weights, element_nodes=mapping.element_nodes, width=width
                )
            )
        else:
            frames, offsets = mapping.jacobian.args[2], mapping.jacobian.args[3]
            assert isinstance(frames, Buffer) and isinstance(offsets, Buffer)
            collision.bodies.append(ContactBody(body, free, frames, offsets))
        if body >= 0:
            reached.add(body)
    _one_kind_per_barycentric_body(planner, lowering, collision)
    return reached


def _one_kind_per_barycentric_body(
    planner: Planner, lowering: ConstraintLowering, collision: Collision
) -> None:
    """A correction whose contact rows come through a BarycentricMapping takes them from
    barycentrically mapped models only (the runtime rebuilds such a body's rows as SOFA's
    MatrixDeriv compresses them)."""
    kinds: dict[int, set[bool]] = {}
    for body in collision.bodies:
        if body.body >= 0:
            kinds.setdefault(body.body, set()).add(body.nodes is not None)
    for number, found in kinds.items():
        if len(found) > 1:
            correction = lowering.phase.corrections[number].checked
            assert correction is not None
            planner.unsupported(
                correction,
                "contacts on a state through a BarycentricMapping and otherwise (its own collision "
                "models, another mapping) are not compiled yet",
            )
