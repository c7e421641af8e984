"""Lowerings of FreeMotionAnimationLoop's constraint side: the constraint solver and the
constraint corrections, gathered into the plan's :class:`ConstraintPhase`.

SOFA's step under FreeMotionAnimationLoop (FreeMotionAnimationLoop::step): each ODE solver writes
its solve into the free vectors; the collision pipeline runs on the start-of-step positions; the
constraint solver builds the rows, W from the corrections, solves, and each correction writes
x = x_free + posFactor * dx, v = v_free + velFactor * dx; then projectPositionAndVelocity and the
mappings. A state without a correction never receives its free motion. With no row, every
correction adds C Jᵀ 0: the groups' own step, bit for bit (x_free + 0 for points; for rigid frames
SOFA's exponential update by a zero rotation gives back the orientation exactly).
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
    ConstraintPhase,
    Correction,
    Element,
    Env,
    Group,
    LinearSystem,
    MappingOp,
    Op,
    Preconditioner,
    StatePlan,
    bind,
    call,
    kernel,
    origin_of,
)
from sofac.registry import Category, Variant
from sofac.registry.components.lagrangian import BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER
from sofac.registry.spec import Effect

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# Settings the runtime's solvers read, by solver family (field names as the registry spells them).
_GENERIC_SETTINGS = (
    "maxIterations",
    "tolerance",
    "sor",
    "regularizationTerm",
    "scaleTolerance",
    "allVerified",
)
_LCP_SETTINGS = (
    "maxIt",
    "tolerance",
    "mu",
    "minW",
    "maxF",
    "regularizationTerm",
    "initial_guess",
    "build_lcp",
)

_ONLY_UNDER_FREE_MOTION = (
    "constraint solvers and corrections act only under FreeMotionAnimationLoop "
    "(this scene's animation loop never calls them)"
)


def _free_motion_loop(planner: Planner) -> CheckedComponent | None:
    """The scene's animation loop when it is one that solves constraints (FreeMotionAnimationLoop)."""
    for checked in planner.checked:
        if (
            checked.category is Category.ANIMATION_LOOP
            and checked.spec is not None
            and Effect.CONSTRAINT_SOLVE in checked.spec.effects
        ):
            return checked
    return None


def _loop_solver(planner: Planner, loop: CheckedComponent) -> CheckedComponent | None:
    """The loop's constraint solver: its `constraintSolver` link, else the first one found from the
    loop's node down (SOFA's getObject(SearchDown)); None: SOFA adds a default BGS."""
    linked = loop.links.get("constraintSolver")
    if isinstance(linked, Component):
        return planner.checked.of(linked)
    below = [
        c
        for c in planner.checked
        if c.category is Category.CONSTRAINT_SOLVER
        and (c.component.node is loop.component.node or loop.component.node in c.component.node.ancestors())
    ]
    return below[0] if below else None


def constraint_phase(planner: Planner) -> ConstraintPhase | None:
    """The plan's constraint phase, made the first time a lowering asks (None: not FreeMotion)."""
    phase: ConstraintPhase | None = getattr(planner, "constraint_phase", None)
    if phase is not None:
        return phase
    loop = _free_motion_loop(planner)
    if loop is None:
        return None
    solver = _loop_solver(planner, loop)
    settings = {}
    method = "block_gauss_seidel"
    if solver is not None and solver.spec is not None:
        method = solver.spec.variant
        names = _LCP_SETTINGS if method == Variant.LCP else _GENERIC_SETTINGS
        for name in names:
            value = planner.value(solver.component, name)
            settings[name] = planner.buffer(solver.component, name, [float(value)], role="param")
    report = planner.buffer(loop.component, "constraint_report", np.zeros(7), role="state")
    phase = ConstraintPhase(
        loop=origin_of(loop.component),
        solver=origin_of(solver.component) if solver is not None else "",
        method=method,
        settings=settings,
        report=report,
    )
    planner.constraint_phase = phase  # type: ignore[attr-defined]
    planner.pending_violations = []  # type: ignore[attr-defined]
    planner.pending_stoppers = []  # type: ignore[attr-defined]
    planner.pending_coordinates = []  # type: ignore[attr-defined]
    planner.pending_sliding = []  # type: ignore[attr-defined]
    planner.constraint_solver = solver  # type: ignore[attr-defined]
    return phase


def lower_constraint_solver(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    phase = constraint_phase(planner)
    if phase is None:
        planner.unsupported(checked, _ONLY_UNDER_FREE_MOTION)
        return
    if getattr(planner, "constraint_solver", None) is not checked:
        planner.ignored.append((checked.component, "not the animation loop's constraint solver"))


def lower_constraint_correction(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    phase = constraint_phase(planner)
    if phase is None:
        planner.unsupported(checked, _ONLY_UNDER_FREE_MOTION)
        return
    linked = checked.links.get("mstate")
    component = (
        linked if isinstance(linked, Component) else planner.checked.node_state(checked.component.node)
    )
    state = planner.states.get(id(component)) if component is not None else None
    if state is None:
        planner.ignored.append((checked.component, "no MechanicalObject to correct"))
        return
    if state.mapped:
        planner.unsupported(checked, "a correction on a mapped state is not compiled yet")
        return
    group = owner.get(id(state.component))
    if group is None:
        planner.ignored.append((checked.component, "its state has no ODE solver: it never moves"))
        return
    assert checked.spec is not None
    kind = checked.spec.variant
    if kind == Variant.LINEAR_SOLVER and planner.value(checked.component, "wire_optimization"):
        planner.unsupported(
            checked,
            "wire_optimization=1 (constraints reordered along a wire) is not compiled; remove it",
            "wire_optimization",
        )
        return
    if kind == Variant.LINEAR_SOLVER and (group.scheme != "implicit" or group.linear_solver is None):
        planner.unsupported(
            checked,
            "it needs the linear solver of an implicit ODE solver (EulerImplicitSolver + a linear solver)",
        )
        return
    if any(c.state is state for c in phase.corrections):
        planner.unsupported(checked, f"{state.path!r} already has a constraint correction")
        return
    phase.corrections.append(Correction(origin_of(checked.component), kind, state, group, checked))


# The runtime's Resolution values (runtime/sofac/constraints.h).
BILATERAL_3 = 0
BILATERAL_1 = 1
UNILATERAL_1 = 2
STOPPER_1 = 4

# The solvers the compiled phase runs on constraint rows (runtime/sofac/constraints.h, method codes).
_ROW_SOLVERS = {"block_gauss_seidel": 0, "nncg": 1, "unbuilt_gauss_seidel": 2}


def _values(planner: Planner, component: Component, name: str, dtype: type) -> np.ndarray:
    """A list field's values (empty when unset)."""
    value = planner.value(component, name)
    return np.asarray(value if value is not None else [], dtype=dtype).ravel()


def _phase_for(
    planner: Planner, checked: CheckedComponent, datatype: str | None = None
) -> ConstraintPhase | None:
    """The constraint phase a constraint model's rows go to; None once it is refused (no
    FreeMotionAnimationLoop, or not the ``datatype`` it is compiled for)."""
    phase = constraint_phase(planner)
    if phase is None:
        planner.unsupported(checked, "Lagrangian constraints act only under FreeMotionAnimationLoop")
        return None
    if datatype is not None and (checked.datatype is None or checked.datatype.name != datatype):
        planner.unsupported(checked, f"it is compiled for {datatype} only")
        return None
    return phase


def _has_end_time(planner: Planner, checked: CheckedComponent) -> bool:
    """A constraint with an endTime is refused (its rows would stop at that time)."""
    if float(planner.value(checked.component, "endTime")) >= 0.0:
        planner.unsupported(checked, "a constraint with an endTime is not compiled yet")
        return True
    return False


def lower_bilateral(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """BilateralLagrangianConstraint<Vec3d>: three rows per pair of points, -e_k on object1's point
    and +e_k on object2's (buildConstraintMatrix), the violation x2_free - x1_free (- rest)."""
    phase = _phase_for(planner, checked, "Vec3d")
    component = checked.component
    if phase is None:
        return
    if planner.value(component, "activate") is False:
        planner.ignored.append((component, "activate=0: no constraint"))
        return
    if _has_end_time(planner, checked):
        return
    states = []
    for name in ("object1", "object2"):
        linked = checked.links.get(name)
        state = planner.states.get(id(linked)) if isinstance(linked, Component) else None
        if state is None:
            planner.unsupported(checked, f"its {name} is not a compiled MechanicalObject")
            return
        if state.mapped and not _rigidly_mapped(planner, state):
            planner.unsupported(
                checked,
                f"constraint rows through mappings other than one RigidMapping are not compiled yet ({name})",
            )
            return
        states.append(state)
    if states[0] is states[1]:
        planner.unsupported(checked, "object1 and object2 are the same state: not compiled yet")
        return
    first_points, second_points = (
        _values(planner, component, name, np.int64) for name in ("first_point", "second_point")
    )
    pairs = min(len(first_points), len(second_points))
    if pairs == 0:
        planner.ignored.append((component, "no pair of points: no constraint row"))
        return
    first_row = phase.capacity
    phase.capacity += 3 * pairs
    if phase.kept is None:
        phase.kept = planner.buffer(
            planner.checked.scene.root.path, "constraint_kept_forces", [], role="state"
        )
    kept_offset = len(phase.kept.initial)
    phase.kept.initial = np.zeros(kept_offset + 3 * pairs)
    load = float(planner.value(component, "load"))
    for p in range(pairs):
        phase.blocks.append((first_row + 3 * p, BILATERAL_3, load, kept_offset + 3 * p, 0.0))
        for k in range(3):
            unit = tuple(1.0 if c == k else 0.0 for c in range(3))
            row = first_row + 3 * p + k
            phase.entries.setdefault(states[0].ident, []).append(
                (row, int(first_points[p]), tuple(-u for u in unit))
            )
            phase.entries.setdefault(states[1].ident, []).append((row, int(second_points[p]), unit))
    rest = planner.value(component, "rest_vector")
    rest = np.asarray(rest if rest is not None else [], dtype=float).reshape(-1, 3)
    m1 = planner.buffer(component, "first_point", first_points[:pairs], "i64")
    m2 = planner.buffer(component, "second_point", second_points[:pairs], "i64")
    rest_buffer = planner.buffer(component, "rest_vector", rest, columns=3)
    planner.pending_violations.append(  # type: ignore[attr-defined]
        (
            origin_of(component),
            first_row,
            states[0],
            states[1],
            m1,
            m2,
            pairs,
            rest_buffer,
            len(rest),
        )
    )


def _constrained_state(planner: Planner, checked: CheckedComponent) -> StatePlan | None:
    """The state a one-state constraint acts on: its `mstate` link, else its node's state."""
    linked = checked.links.get("mstate")
    component = (
        linked if isinstance(linked, Component) else planner.checked.node_state(checked.component.node)
    )
    return planner.states.get(id(component)) if component is not None else None


def _kept_forces(planner: Planner, phase: ConstraintPhase, count: int) -> int:
    """Room for `count` more kept forces (the resolutions' warm start); returns its offset."""
    if phase.kept is None:
        phase.kept = planner.buffer(
            planner.checked.scene.root.path, "constraint_kept_forces", [], role="state"
        )
    offset = len(phase.kept.initial)
    phase.kept.initial = np.zeros(offset + count)
    return offset


def lower_fixed_lagrangian(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FixedLagrangianConstraint<Vec3d>: rows +e_x, +e_y, +e_z on each fixed DOF (indices, or every
    DOF with fixAll), violation x_free - rest_position, one BilateralConstraintResolution3Dof per DOF
    with its kept forces (FixedLagrangianConstraint.cpp's Vec3 specialisation)."""
    phase = _phase_for(planner, checked, "Vec3d")
    component = checked.component
    if phase is None:
        return
    if _has_end_time(planner, checked):
        return
    state = _constrained_state(planner, checked)
    if state is None:
        planner.unsupported(checked, "it needs a compiled MechanicalObject in its node (or mstate)")
        return
    if state.mapped or state.rest is None:
        planner.unsupported(checked, "constraint rows on a mapped state are not compiled yet")
        return
    if planner.value(component, "fixAll"):
        indices = np.arange(state.size, dtype=np.int64)
    else:
        indices = _values(planner, component, "indices", np.int64)
    count = len(indices)
    if count == 0:
        planner.ignored.append((component, "no index: no constraint row"))
        return
    first_row = phase.capacity
    phase.capacity += 3 * count
    kept_offset = _kept_forces(planner, phase, 3 * count)
    for p, dof in enumerate(indices):
        phase.blocks.append((first_row + 3 * p, BILATERAL_3, 1.0, kept_offset + 3 * p, 0.0))
        for k in range(3):
            unit = tuple(1.0 if c == k else 0.0 for c in range(3))
            phase.entries.setdefault(state.ident, []).append((first_row + 3 * p + k, int(dof), unit))
    fixed = planner.buffer(component, "fixed_indices", indices, "i64")
    no_rest = planner.buffer(component, "no_rest_vector", np.zeros((0, 3)), columns=3)
    # x_free[i] - rest[i]: the bilateral violation with object1 the rest positions, object2 the state
    planner.pending_violations.append(  # type: ignore[attr-defined]
        (origin_of(component), first_row, state.rest, state, fixed, fixed, count, no_rest, 0)
    )


def lower_stopper(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """StopperLagrangianConstraint<Vec1d>: one row +1 on DOF `index`, violation x_free[index], its
    resolution keeping the free displacement in [min, max] (StopperLagrangianConstraintResolution1Dof)."""
    phase = _phase_for(planner, checked)
    component = checked.component
    if phase is None:
        return
    if _has_end_time(planner, checked):
        return
    state = _constrained_state(planner, checked)
    if state is None or state.datatype.name != "Vec1d":
        planner.unsupported(checked, "it needs a compiled Vec1d MechanicalObject in its node (or mstate)")
        return
    if state.mapped:
        planner.unsupported(checked, "constraint rows on a mapped state are not compiled yet")
        return
    index = int(planner.value(component, "index"))
    row = phase.capacity
    phase.capacity += 1
    low, high = float(planner.value(component, "min")), float(planner.value(component, "max"))
    _kept_forces(planner, phase, 0)  # (no warm start, but the solve takes the kept forces' buffer)
    phase.blocks.append((row, STOPPER_1, low, -1, high))
    phase.entries.setdefault(state.ident, []).append((row, index, (1.0,)))
    planner.pending_stoppers.append((origin_of(component), row, state, index))  # type: ignore[attr-defined]


def lower_uniform(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """UniformLagrangianConstraint<Vec1d>: a row +1 on every coordinate of every DOF, violation
    x_free (- rest_position with constrainToRestPos), one BilateralConstraintResolution per row
    (iterative) without kept forces."""
    phase = _phase_for(planner, checked)
    component = checked.component
    if phase is None:
        return
    if _has_end_time(planner, checked):
        return
    if not planner.value(component, "iterative"):
        planner.unsupported(
            checked, "iterative=0 (one BilateralConstraintResolutionNDof) is not compiled yet"
        )
        return
    state = _constrained_state(planner, checked)
    if state is None or state.datatype.name != "Vec1d":
        planner.unsupported(checked, "it needs a compiled Vec1d MechanicalObject in its node (or mstate)")
        return
    if state.mapped or state.rest is None:
        planner.unsupported(checked, "constraint rows on a mapped state are not compiled yet")
        return
    width = state.datatype.deriv_size
    count = state.size * width
    if count == 0:
        planner.ignored.append((component, "no DOF: no constraint row"))
        return
    first = phase.capacity
    phase.capacity += count
    _kept_forces(planner, phase, 0)
    for i in range(state.size):
        for j in range(width):
            row = first + width * i + j
            phase.blocks.append((row, BILATERAL_1, 1.0, -1, 0.0))
            unit = tuple(1.0 if c == j else 0.0 for c in range(width))
            phase.entries.setdefault(state.ident, []).append((row, i, unit))
    rest = state.rest if planner.value(component, "constrainToRestPos") else Env.NONE
    planner.pending_coordinates.append((origin_of(component), first, state, rest, count))  # type: ignore[attr-defined]


def lower_sliding(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """SlidingLagrangianConstraint<Vec3d>: object1's point slides on object2's segment axis_1-axis_2.
    Four rows built each step from the free positions (runtime sliding_rows): two bilateral across
    the axis, two unilateral at its ends (SOFA's BilateralConstraintResolution and
    UnilateralConstraintResolution, no kept forces)."""
    phase = _phase_for(planner, checked, "Vec3d")
    component = checked.component
    if phase is None:
        return
    if _has_end_time(planner, checked):
        return
    states = []
    for name in ("object1", "object2"):
        linked = checked.links.get(name)
        state = planner.states.get(id(linked)) if isinstance(linked, Component) else None
        if state is None or state.mapped:
            planner.unsupported(checked, f"its {name} is not a compiled unmapped MechanicalObject")
            return
        states.append(state)
    point, a, b = (int(planner.value(component, n)) for n in ("sliding_point", "axis_1", "axis_2"))
    axis = states[1].x.initial.reshape(-1, 3)
    if a == b or (max(a, b) < len(axis) and np.array_equal(axis[a], axis[b])):
        attribute = component.attributes.get("axis_2") or component.attributes.get("axis_1")
        planner.diags.add(
            "E207",
            attribute.loc if attribute is not None else component.loc,
            f"{component.type_name}: axis_1={a} and axis_2={b} of object2 are at the same position "
            f"{axis[a].tolist() if a < len(axis) else ''}: the sliding axis has zero length",
            "give axis_1 and axis_2 two points of object2 at different positions",
        )
        return
    if states[0] is states[1]:
        planner.unsupported(checked, "object1 = object2 is not compiled yet")
        return
    first = phase.capacity
    phase.capacity += 4
    _kept_forces(planner, phase, 0)
    for row, kind in enumerate((BILATERAL_1, BILATERAL_1, UNILATERAL_1, UNILATERAL_1)):
        phase.blocks.append((first + row, kind, 1.0, -1, 0.0))
    rows = list(range(first, first + 4))
    low, high = min(a, b), max(a, b)
    layouts = (
        ([0, 1, 2, 3, 4], [point] * 4, 13),
        ([0, 2, 4, 5, 6], [low, high, low, high, a, b], 18),
    )
    aggregates = []
    for state, (starts, dofs, size) in zip(states, layouts, strict=True):
        values = planner.buffer(state.component, "sliding_J_values", np.zeros(size), role="scratch")
        buffers = (
            planner.buffer(state.component, "sliding_J_rows", rows, "i64"),
            planner.buffer(state.component, "sliding_J_starts", starts, "i64"),
            planner.buffer(state.component, "sliding_J_dofs", dofs, "i64"),
            values,
        )
        aggregates.append((state, Aggregate("JacobianRows", (4, *buffers)), values))
    degenerate = planner.buffer(component, "degenerate_segments", np.zeros(1), role="state")
    planner.pending_sliding.append(  # type: ignore[attr-defined]
        (checked, first, aggregates, point, a, b, degenerate)
    )
    for state in states:
        phase.entries.setdefault(state.ident, [])


def _sliding_rows(planner: Planner, phase: ConstraintPhase, dfree: Buffer) -> None:
    """The sliding constraints' rows (after the rigid mappings' rows are known): each state's J is
    the constraint's own, so a state it acts on takes no other constraint's rows."""
    for checked, first, aggregates, point, a, b, degenerate in planner.pending_sliding:  # type: ignore[attr-defined]
        (s1, J1, values1), (s2, J2, values2) = aggregates
        if any(phase.entries.get(s.ident) or s.ident in planner.rigid_rows for s in (s1, s2)):  # type: ignore[attr-defined]
            planner.unsupported(
                checked,
                "a state with a SlidingLagrangianConstraint and other constraint rows is not compiled yet",
            )
            continue
        planner.rigid_rows[s1.ident] = J1  # type: ignore[attr-defined]
        planner.rigid_rows[s2.ident] = J2  # type: ignore[attr-defined]
        rows = call("sliding_rows", values1, values2, dfree, first, s1.x, s2.x, point, a, b, degenerate)
        phase.rows.append(Op(origin_of(checked.component), [rows]))


def _jacobian_rows(
    planner: Planner, state: StatePlan, entries: list[tuple[int, int, tuple[float, ...]]]
) -> Aggregate:
    """A state's J as SOFA's MatrixDeriv holds it: rows ascending, each row's DOFs ascending, the
    values of one (row, DOF) summed (addCol). A rigid state's rows come from its mapped points
    (``_carry_through_rigid_mappings``), their values computed each step."""
    if state.ident in getattr(planner, "rigid_rows", {}):
        return planner.rigid_rows[state.ident]  # type: ignore[attr-defined]
    merged: dict[tuple[int, int], list[float]] = {}
    for row, dof, values in entries:
        if (row, dof) in merged:
            merged[(row, dof)] = [a + b for a, b in zip(merged[(row, dof)], values, strict=True)]
        else:
            merged[(row, dof)] = list(values)
    rows = sorted({row for row, _ in merged})
    starts, dofs, values = [0], [], []
    for row in rows:
        for (r, dof), value in sorted(merged.items()):
            if r == row:
                dofs.append(dof)
                values.extend(value)
        starts.append(len(dofs))
    width = state.datatype.deriv_size
    buffers = (
        planner.buffer(state.component, "J_rows", rows, "i64"),
        planner.buffer(state.component, "J_starts", starts, "i64"),
        planner.buffer(state.component, "J_dofs", dofs, "i64"),
        planner.buffer(state.component, "J_values", values, columns=width),
    )
    return Aggregate("JacobianRows", (len(rows), *buffers))


def _phase_with_rows(planner: Planner, phase: ConstraintPhase) -> None:
    """The calls of a phase that has rows: violations, W from the corrections, the solve, the
    corrections, on buffers sized by the rows."""
    solver = getattr(planner, "constraint_solver", None)
    lagrangian = _lagrangian_collision(planner)
    n = phase.capacity + (lagrangian.row_capacity if lagrangian is not None else 0)
    if lagrangian is not None:
        root = planner.checked.scene.root
        for checked in planner.checked:
            if (
                phase.capacity
                and checked.category is Category.LAGRANGIAN_CONSTRAINT
                and checked.component.node is not root
            ):
                planner.unsupported(
                    checked,
                    "with Lagrangian contacts, sofac places the scene's own constraint rows before the "
                    "contacts', which SOFA does for constraints in the root node only; move it to the root",
                )
                return
        lagrangian.static_rows = phase.capacity
        phase.capacity = n
        if phase.kept is None:
            phase.kept = planner.buffer(
                planner.checked.scene.root.path, "constraint_kept_forces", [], role="state"
            )
    if lagrangian is not None and phase.method == Variant.LCP and solver is not None:
        why = _lcp_refusal(planner, solver, phase, lagrangian)
        if why:
            planner.unsupported(solver, why)
            return
    elif lagrangian is not None and phase.method not in _ROW_SOLVERS:
        if solver is not None:
            planner.unsupported(solver, f"{solver.spec.name} with Lagrangian contacts is not compiled yet")
        return
    if phase.method not in _ROW_SOLVERS and not (lagrangian is not None and phase.method == Variant.LCP):
        if solver is not None:
            planner.unsupported(solver, f"{solver.spec.name} on constraint rows is not compiled yet")
        return
    W = planner.buffer("/", "constraint_W", np.zeros(n * n), columns=n, role="scratch")
    dfree = planner.buffer("/", "constraint_dfree", np.zeros(n), role="scratch")
    # with contacts, the last solve's forces are an output (`/.constraint_f`: impulses, rows in order)
    f = planner.buffer(
        "/", "constraint_f", np.zeros(n), role="state" if lagrangian is not None else "scratch"
    )
    d = planner.buffer("/", "constraint_d", np.zeros(n), role="scratch")
    scratch = planner.buffer("/", "constraint_scratch", np.zeros(3 * n), role="scratch")
    if lagrangian is not None:
        lagrangian.problem = [W, dfree, f, d, scratch]
        clear = call("lagrangian_begin", Env.LAGRANGIAN, W, dfree, f, d)
    else:
        clear = call("constraint_clear", W, dfree, f, d, n)
    phase.rows.append(Op(phase.loop, [clear]))
    contact_states = {m.state.ident for m in lagrangian.models} if lagrangian is not None else set()
    free_x = _mapped_free_motion(planner, phase, contact_states)
    for origin, first, s1, s2, m1, m2, pairs, rest, rest_count in planner.pending_violations:  # type: ignore[attr-defined]
        # object1 given as a Buffer: constant positions (FixedLagrangianConstraint's rest positions)
        x1 = s1 if isinstance(s1, Buffer) else free_x.get(s1.ident, s1.x)
        x2 = free_x.get(s2.ident, s2.x)
        phase.violation.append(
            Op(origin, [call("bilateral_violation", dfree, first, x1, x2, m1, m2, pairs, rest, rest_count)])
        )
    for origin, row, state, rest, count in planner.pending_coordinates:  # type: ignore[attr-defined]
        phase.violation.append(Op(origin, [call("coordinate_violation", dfree, row, state.x, rest, count)]))
    for origin, row, state, index in planner.pending_stoppers:  # type: ignore[attr-defined]
        phase.violation.append(Op(origin, [call("stopper_violation", dfree, row, state.x, index)]))
    if lagrangian is not None:
        phase.violation.append(Op(lagrangian.origin, [call("lagrangian_violation", Env.LAGRANGIAN, dfree)]))
    _carry_through_rigid_mappings(planner, phase)
    _sliding_rows(planner, phase, dfree)
    bodies = _contact_bodies(planner, phase, lagrangian, free_x) if lagrangian is not None else set()
    unbuilt_items: list[tuple[str, Aggregate, StatePlan, Element, Buffer, int, int]] = []
    for body, correction in enumerate(phase.corrections):
        entries = phase.entries.get(correction.state.ident)
        if entries is None and body in bodies:
            entries = []
        if entries is None:
            continue
        checked = correction.checked
        assert checked is not None
        state = correction.state
        compiled = ("Vec3d", "Rigid3d") if lagrangian is not None else ("Vec3d", "Rigid3d", "Vec1d")
        if state.datatype.name not in compiled:
            planner.unsupported(
                checked,
                "with constraint rows, a correction on Vec3d or Rigid3d (Vec1d without contacts) is compiled",
            )
            continue
        group = correction.group
        if group.scheme != "implicit" or group.static or group.newmark or group.variational:
            planner.unsupported(
                checked, "with constraint rows, it is compiled under EulerImplicitSolver only"
            )
            continue
        component = checked.component
        J = _jacobian_rows(planner, state, entries)
        if correction.kind == Variant.LINEAR_SOLVER:
            _linear_solver_correction(planner, phase, correction, body, J, lagrangian is not None, (W, f, n))
            continue
        comp = _values(planner, component, "compliance", np.float64)
        if not state.datatype.rigid and 0 < len(comp) != state.size:
            # SOFA's init: a compliance not one per DOF becomes one per DOF, each the
            # defaultCompliance if set, else the compliance's first value
            given = component.get("defaultCompliance") is not None
            first = float(planner.value(component, "defaultCompliance")) if given else float(comp[0])
            comp = np.full(state.size, first)
        if state.datatype.rigid and len(comp) != 7:
            found = _rigid_compliance(planner, checked, group, state)
            if found is None:
                continue
            comp = found
        comp_buffer = planner.buffer(component, "compliance", comp)
        scaled = planner.buffer(component, "scaled_compliance", np.zeros(len(comp) + 1), role="scratch")
        comp0 = Element(
            planner.buffer(
                component,
                "defaultCompliance",
                [float(planner.value(component, "defaultCompliance"))],
                role="param",
            )
        )
        dt = float(planner.dt.initial[0])
        use_ode = bool(planner.value(component, "useOdeSolverIntegrationFactors"))
        # EulerImplicitSolver: position factor dt, velocity factor 1 (its integration factors)
        factor = dt if use_ode else 1.0
        position = dt if use_ode else float(planner.value(component, "correctionPositionFactor"))
        velocity = 1.0 if use_ode else float(planner.value(component, "correctionVelocityFactor")) / dt
        t = state.datatype.name
        unbuilt_items.append((t, J, state, comp0, comp_buffer, len(comp), body))
        comp_args = (comp0, comp_buffer, len(comp))
        if lagrangian is not None:
            add = call(
                kernel("lagrangian_add_compliance", t), Env.LAGRANGIAN, body, W, J, *comp_args, factor, scaled
            )
        else:
            add = call(kernel("uncoupled_add_compliance", t), W, n, J, *comp_args, factor, scaled)
        phase.compliance.append(Op(correction.origin, [add]))
        moved = _moved_vectors(planner, component, state)
        if lagrangian is not None:
            correct = call(
                kernel("lagrangian_correct", t),
                Env.LAGRANGIAN,
                body,
                *moved,
                J,
                f,
                state.size,
                *comp_args,
                position,
                velocity,
            )
        else:
            correct = call(
                kernel("uncoupled_correct", t), *moved, J, f, state.size, *comp_args, position, velocity
            )
        phase.correction.append(Op(correction.origin, [correct]))
    if phase.method == Variant.LCP:  # LCPConstraintSolver on the contacts' rows
        names = ("maxIt", "tolerance", "mu", "minW", "maxF", "regularizationTerm", "initial_guess")
        lcp_settings = [Element(phase.settings[name]) for name in names]
        if solver is not None and not planner.value(solver.component, "build_lcp"):
            _lcp_unbuilt(planner, phase, unbuilt_items, (W, dfree, f, d, scratch, n), lcp_settings)
            return
        lcp = call("lagrangian_solve_lcp", Env.LAGRANGIAN, W, dfree, f, d, scratch, n, *lcp_settings)
        phase.solve.append(Op(phase.solver, [call(lcp.kernel, *lcp.args, phase.report, Env.TIME)]))
        return
    firsts = planner.buffer("/", "constraint_block_first", [b[0] for b in phase.blocks], "i64")
    kinds = planner.buffer("/", "constraint_block_kind", [b[1] for b in phase.blocks], "i64")
    parameters = planner.buffer(
        "/", "constraint_block_parameter", [(b[2], b[4]) for b in phase.blocks], columns=2
    )
    kept = planner.buffer("/", "constraint_block_kept", [b[3] for b in phase.blocks], "i64")
    assert phase.kept is not None
    order = ("maxIterations", "tolerance", "sor", "scaleTolerance", "allVerified", "regularizationTerm")
    if phase.settings:
        settings: list[Element | float] = [Element(phase.settings[name]) for name in order]
    else:  # no solver in the scene: FreeMotionAnimationLoop makes a BlockGaussSeidelConstraintSolver
        default = BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER.field
        settings = [float(default(name).default) for name in order]  # type: ignore[union-attr]
    if phase.method == Variant.UNBUILT_GAUSS_SEIDEL:
        _unbuilt_solve(
            planner, phase, unbuilt_items, (W, dfree, f, d, scratch, n), (firsts, kinds, parameters, kept)
        )
        return
    solve = (
        call(kernel("lagrangian_solve", len(phase.blocks)), Env.LAGRANGIAN, _ROW_SOLVERS[phase.method])
        if lagrangian is not None
        else call(kernel("solve_constraints", len(phase.blocks)), _ROW_SOLVERS[phase.method])
    )
    phase.solve.append(
        Op(
            phase.solver or phase.loop,
            [
                call(
                    (solve.kernel, solve.templates),
                    *solve.args,
                    W,
                    dfree,
                    f,
                    d,
                    scratch,
                    n,
                    firsts,
                    kinds,
                    parameters,
                    kept,
                    phase.kept,
                    *settings,
                    phase.report,
                    Env.TIME,
                )
            ],
        )
    )


def _moved_vectors(planner: Planner, component: Component, state: StatePlan) -> tuple[Buffer, ...]:
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


def _linear_solver_correction(
    planner: Planner,
    phase: ConstraintPhase,
    correction: Correction,
    body: int,
    J: Aggregate,
    lagrangian: bool,
    problem: tuple[Buffer, Buffer, int],
) -> None:
    """LinearSolverConstraintCorrection on rows (runtime/sofac/linear_correction.h): W += dt J A^-1 J^T
    (+ regularizationTerm), then dx = A^-1 J^T f, x = x_free + dt dx, v = v_free + dx
    (EulerImplicitSolver's position and velocity integration factors)."""
    checked = correction.checked
    assert checked is not None
    solver = getattr(planner, "constraint_solver", None)
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
    W, f, n = problem
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
            W,
            J,
            system,
            0,
            dt,
            regularization,
        )
    else:
        add = call(kernel("linear_add_compliance", t), W, n, J, system, 0, dt, regularization)
    phase.compliance.append(Op(correction.origin, [add]))
    moved = _moved_vectors(planner, component, state)
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


def _lcp_unbuilt(
    planner: Planner,
    phase: ConstraintPhase,
    items: list[tuple[str, Aggregate, StatePlan, Element, Buffer, int, int]],
    problem: tuple,
    settings: list[Element],
) -> None:
    """LCPConstraintSolver with build_lcp=0 and mu=0 (lcp_gaussseidel_unbuilt): no W built (the
    compliance calls are dropped), the 1x1 blocks and displacements through the corrections."""
    phase.compliance.clear()
    types = {t for t, *_ in items}
    solver = getattr(planner, "constraint_solver", None)
    if len(types) != 1:
        if solver is not None:
            planner.unsupported(solver, "unbuilt, it is compiled for corrections of one DataType")
        return
    (t,) = types
    aggregates = []
    for _, J, state, comp0, comp, size, body in items:
        zeros = np.zeros_like(state.v.initial)
        force = planner.buffer(
            state.component, "constraint_force", zeros, columns=state.v.columns, role="scratch"
        )
        disp = planner.buffer(
            state.component, "constraint_disp", zeros, columns=state.v.columns, role="scratch"
        )
        item = Aggregate("UnbuiltUncoupled", (J, state.size, comp0, comp, size, force, disp), (t,))
        aggregates.append(Aggregate("LagrangianUnbuilt", (body, item), (t,)))
    solve = call(
        kernel("lagrangian_solve_lcp_unbuilt", t),
        Env.LAGRANGIAN,
        *problem,
        *settings,
        phase.report,
        Env.TIME,
        *aggregates,
    )
    phase.solve.append(Op(phase.solver, [solve]))


def _lcp_refusal(
    planner: Planner, solver: CheckedComponent, phase: ConstraintPhase, collision: Collision
) -> str:
    """Why an LCPConstraintSolver on Lagrangian contacts is not compiled ("" when it is)."""
    value = planner.value
    if collision.static_rows:
        return "LCPConstraintSolver on rows other than contacts' is not compiled yet"
    mu = float(value(solver.component, "mu"))
    if not value(solver.component, "build_lcp"):
        if (mu > 0) != (collision.mu > 0):
            return (
                "LCPConstraintSolver unbuilt is compiled when its mu and the contacts' are both 0 or both > 0"
            )
        return ""
    if mu <= 0 or collision.mu <= 0:
        return "LCPConstraintSolver built is compiled for contacts of three rows solved with mu > 0"
    return ""


def _lagrangian_collision(planner: Planner) -> Collision | None:
    """The scene's FrictionContactConstraint contacts (their rows join the phase), if compiled."""
    return next((c for c in planner.collisions if c.response == "friction_contact" and c.pairs), None)


def _contact_bodies(
    planner: Planner, phase: ConstraintPhase, collision: Collision, free_x: dict[str, Buffer]
) -> set[int]:
    """Where each collision model's contact rows land: the correction of its own state, or of
    the Rigid3d state its RigidMapping follows (the rows carried through applyJT), or none (a
    static obstacle); with the free positions the violation reads. Returns the bodies reached."""
    index = {id(c.state): k for k, c in enumerate(phase.corrections)}
    reached: set[int] = set()
    for model in collision.models:
        state = model.state
        if not state.mapped:
            body = index.get(id(state), -1)
            collision.bodies.append((body, state.x, None, None, None))
            if body >= 0:
                reached.add(body)
            continue
        mapping = _mapping_of_state(planner, state)
        body = index.get(id(mapping.parent), -1) if mapping is not None else -1
        subset = _increasing_subset(planner, mapping) if mapping is not None else None
        rigid = _rigidly_mapped(planner, state)
        if mapping is None or not (rigid or subset is not None) or state.ident not in free_x:
            planner.unsupported(
                planner.checked.of(state.component),
                "Lagrangian contact on a collision state mapped other than by one RigidMapping, "
                "IdentityMapping or SubsetMapping (increasing indices) from an independent state is not "
                "compiled yet",
            )
            collision.bodies.append((-1, state.x, None, None, None))
            continue
        if subset is not None:
            collision.bodies.append((body, free_x[state.ident], None, None, subset))
        else:
            frames, offsets = mapping.jacobian.args[2], mapping.jacobian.args[3]
            assert isinstance(frames, Buffer) and isinstance(offsets, Buffer)
            collision.bodies.append((body, free_x[state.ident], frames, offsets, None))
        if body >= 0:
            reached.add(body)
    return reached


def _unbuilt_solve(
    planner: Planner,
    phase: ConstraintPhase,
    items: list[tuple[str, Aggregate, StatePlan, Element, Buffer, int, int]],
    problem: tuple,
    blocks: tuple,
) -> None:
    """UnbuiltGaussSeidelConstraintSolver: W's diagonal blocks from the raw compliances, the
    displacements through the corrections (no built W: the compliance calls are dropped)."""
    phase.compliance.clear()
    types = {t for t, *_ in items}
    solver = getattr(planner, "constraint_solver", None)
    if len(types) != 1 or (
        solver is not None and float(planner.value(solver.component, "regularizationTerm")) > 0
    ):
        if solver is not None:
            planner.unsupported(
                solver,
                "on constraint rows it is compiled for corrections of one DataType, without regularization",
            )
        return
    (t,) = types
    lagrangian = _lagrangian_collision(planner) is not None
    aggregates = []
    for _, J, state, comp0, comp, size, body in items:
        zeros = np.zeros_like(state.v.initial)
        force = planner.buffer(
            state.component, "constraint_force", zeros, columns=state.v.columns, role="scratch"
        )
        disp = planner.buffer(
            state.component, "constraint_disp", zeros, columns=state.v.columns, role="scratch"
        )
        item = Aggregate("UnbuiltUncoupled", (J, state.size, comp0, comp, size, force, disp), (t,))
        aggregates.append(Aggregate("LagrangianUnbuilt", (body, item), (t,)) if lagrangian else item)
    settings = [
        Element(phase.settings[name])
        for name in ("maxIterations", "tolerance", "sor", "scaleTolerance", "allVerified")
    ]
    assert phase.kept is not None
    arguments = (*problem, *blocks, phase.kept, *settings, phase.report, Env.TIME, *aggregates)
    if lagrangian:
        solve = call(kernel("lagrangian_solve_unbuilt", t, len(phase.blocks)), Env.LAGRANGIAN, *arguments)
    else:
        solve = call(kernel("solve_unbuilt", t, len(phase.blocks)), *arguments)
    phase.solve.append(Op(phase.solver, [solve]))


def _rigidly_mapped(planner: Planner, state: StatePlan) -> bool:
    """Points (Vec3d) mapped by one RigidMapping from an independent Rigid3d state."""
    mapping = planner.checked.mapping_of(state.component)
    spec = mapping.spec if mapping is not None else None
    parent = mapping.links.get("input") if mapping is not None else None
    parent_state = planner.states.get(id(parent)) if isinstance(parent, Component) else None
    return (
        spec is not None
        and spec.lowering == "rigid_mapping"
        and parent_state is not None
        and not parent_state.mapped
        and parent_state.datatype.name == "Rigid3d"
        and state.datatype.name == "Vec3d"  # (Rigid3d frames: rows not carried yet)
    )


def _increasing_subset(planner: Planner, mapping: MappingOp) -> Buffer | None:
    """An IdentityMapping or SubsetMapping between states of one DataType, from an independent
    state, with strictly increasing indices (a contact row's DOFs keep their order): its indices."""
    jacobian = mapping.jacobian
    indices = jacobian.args[2] if jacobian.kernel == "subset_apply" else None
    if (
        not isinstance(indices, Buffer)
        or mapping.parent.mapped
        or mapping.parent.datatype.name != mapping.child.datatype.name
    ):
        return None
    values = np.asarray(indices.initial, dtype=np.int64).ravel()
    return indices if values.size == 0 or bool(np.all(np.diff(values) > 0)) else None


def _mapping_of_state(planner: Planner, state: StatePlan) -> MappingOp | None:
    for group in planner.constraint_groups:  # type: ignore[attr-defined]
        for mapping in group.mappings:
            if mapping.child is state:
                return mapping
    return None


def _mapped_free_motion(
    planner: Planner, phase: ConstraintPhase, also: set[str] | None = None
) -> dict[str, Buffer]:
    """Free positions of the constrained mapped states, as SOFA makes them: v_free = J v_free of
    the parent (propagateDx, with the mapping's rotated points of the last apply), then
    x_free = x + dt v_free (linearised, not the mapping of the parent's x_free)."""
    free: dict[str, Buffer] = {}
    for state in planner.states.values():
        if not state.mapped or (state.ident not in phase.entries and state.ident not in (also or set())):
            continue
        mapping = _mapping_of_state(planner, state)
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


def _carry_through_rigid_mappings(planner: Planner, phase: ConstraintPhase) -> None:
    """RigidMapping::applyJT on the constraint matrix: a mapped point's entry n on a row becomes its
    frame's (n, r x n), r the point's rotated offset; rows keep their index."""
    planner.rigid_rows = {}  # type: ignore[attr-defined]
    by_parent: dict[str, list[tuple[int, int, int, tuple[float, ...], MappingOp]]] = {}
    for state in planner.states.values():
        if not state.mapped or state.ident not in phase.entries:
            continue
        mapping = _mapping_of_state(planner, state)
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
        planner.rigid_rows[parent_ident] = Aggregate("JacobianRows", (len(rows), *buffers))  # type: ignore[attr-defined]
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


def _rigid_compliance(
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


def finish_constraint_phase(planner: Planner, groups: list[Group]) -> ConstraintPhase | None:
    """The phase once every component is lowered: which independent states SOFA leaves frozen
    (no correction), with the buffers that keep their x and v over the groups' step."""
    phase = constraint_phase(planner)
    if phase is None:
        return None
    loop = _free_motion_loop(planner)
    assert loop is not None
    # The loop is the step's driver, not a bystander: its effects are listed, it is not "kept out".
    planner.ignored = [(c, why) for c, why in planner.ignored if c is not loop.component]
    planner.lowered.append(loop.component)
    corrected = {id(c.state) for c in phase.corrections}
    for group in groups:
        for state in group.states:
            if id(state) in corrected:
                continue
            phase.frozen.append((state, group))
            phase.saved[state.ident] = (
                planner.buffer(
                    state.component,
                    "frozen_position",
                    state.x.initial,
                    columns=state.x.columns,
                    role="scratch",
                ),
                planner.buffer(
                    state.component,
                    "frozen_velocity",
                    state.v.initial,
                    columns=state.v.columns,
                    role="scratch",
                ),
            )
            planner.diags.add(
                "W245",
                state.component.loc,
                f"{state.path!r} has no constraint correction: under FreeMotionAnimationLoop SOFA never "
                "writes its free motion back, so it does not move",
                "add an UncoupledConstraintCorrection or a LinearSolverConstraintCorrection next to it",
            )
    if phase.capacity or _lagrangian_collision(planner) is not None:
        planner.constraint_groups = groups  # type: ignore[attr-defined]
        _phase_with_rows(planner, phase)
    return phase
