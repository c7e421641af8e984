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
    CONSTRAINT_REPORT_FIELDS,
    Aggregate,
    Buffer,
    Collision,
    ConstraintPhase,
    Correction,
    Env,
    Group,
    Op,
    Scheme,
    StatePlan,
    call,
    origin_of,
)
from sofac.plan.lower.constraint_context import ConstraintLowering, ConstraintProblem
from sofac.plan.lower.constraint_solve import (
    solve_constraints,
    solver_refusal,
    uncoupled_correction,
    values_of,
)
from sofac.plan.lower.corrections import (
    carry_through_linear_mappings,
    carry_through_rigid_mappings,
    contact_bodies,
    lagrangian_collision,
    linear_solver_correction,
    mapped_free_motion,
)
from sofac.registry import Category, Variant
from sofac.registry.components.constraint import FIXED_PROJECTIVE_CONSTRAINT
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


def constraint_lowering(planner: Planner) -> ConstraintLowering | None:
    """The constraint lowerings' shared context, made the first time a lowering asks (None: the
    scene's animation loop is not FreeMotionAnimationLoop)."""
    if planner.constraint_lowering is not None:
        return planner.constraint_lowering
    loop = _free_motion_loop(planner)
    if loop is None:
        return None
    solver = _loop_solver(planner, loop)
    settings = {}
    method = Variant.BLOCK_GAUSS_SEIDEL  # FreeMotionAnimationLoop's default solver
    if solver is not None and solver.spec is not None:
        method = solver.spec.variant
        names = _LCP_SETTINGS if method == Variant.LCP else _GENERIC_SETTINGS
        for name in names:
            value = planner.value(solver.component, name)
            settings[name] = planner.buffer(solver.component, name, [float(value)], role="param")
    report = planner.buffer(
        loop.component, "constraint_report", np.zeros(len(CONSTRAINT_REPORT_FIELDS)), role="state"
    )
    phase = ConstraintPhase(
        loop=origin_of(loop.component),
        solver=origin_of(solver.component) if solver is not None else "",
        method=method,
        settings=settings,
        report=report,
    )
    planner.constraint_lowering = ConstraintLowering(phase, solver)
    return planner.constraint_lowering


def lower_constraint_solver(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    lowering = constraint_lowering(planner)
    if lowering is None:
        planner.unsupported(checked, _ONLY_UNDER_FREE_MOTION)
        return
    if lowering.solver is not checked:
        planner.ignored.append((checked.component, "not the animation loop's constraint solver"))


def lower_constraint_correction(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    lowering = constraint_lowering(planner)
    if lowering is None:
        planner.unsupported(checked, _ONLY_UNDER_FREE_MOTION)
        return
    phase = lowering.phase
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
    if kind == Variant.LINEAR_SOLVER and (group.scheme is not Scheme.IMPLICIT or group.linear_solver is None):
        planner.unsupported(
            checked,
            "it needs the linear solver of an implicit ODE solver (EulerImplicitSolver + a linear solver)",
        )
        return
    if any(c.state is state for c in phase.corrections):
        planner.unsupported(checked, f"{state.path!r} already has a constraint correction")
        return
    phase.corrections.append(Correction(origin_of(checked.component), kind, state, group, checked))


def _sliding_rows(planner: Planner, lowering: ConstraintLowering, dfree: Buffer) -> None:
    """The sliding constraints' rows (after the rigid mappings' rows are known): each state's J is
    the constraint's own, so a state it acts on takes no other constraint's rows."""
    phase = lowering.phase
    for sliding in lowering.sliding:
        (s1, J1, values1), (s2, J2, values2) = sliding.jacobians
        if any(phase.entries.get(s.ident) or s.ident in lowering.computed_rows for s in (s1, s2)):
            planner.unsupported(
                sliding.checked,
                "a state with a SlidingLagrangianConstraint and other constraint rows is not compiled yet",
            )
            continue
        lowering.computed_rows[s1.ident] = J1
        lowering.computed_rows[s2.ident] = J2
        a, b = sliding.segment
        rows = call(
            "sliding_rows",
            values1,
            values2,
            dfree,
            sliding.first_row,
            s1.x,
            s2.x,
            sliding.point,
            a,
            b,
            sliding.degenerate,
        )
        phase.rows.append(Op(origin_of(sliding.checked.component), [rows]))


def _jacobian_rows(
    planner: Planner,
    lowering: ConstraintLowering,
    state: StatePlan,
    entries: list[tuple[int, int, tuple[float, ...]]],
) -> Aggregate:
    """A state's J as SOFA's MatrixDeriv holds it: rows ascending, each row's DOFs ascending, the
    values of one (row, DOF) summed (addCol). A rigid state's rows come from its mapped points
    (``carry_through_rigid_mappings``), their values computed each step."""
    if state.ident in lowering.computed_rows:
        return lowering.computed_rows[state.ident]
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


def _phase_with_rows(planner: Planner, lowering: ConstraintLowering) -> None:
    """The calls of a phase that has rows: violations, W from the corrections, the solve, the
    corrections, on buffers sized by the rows."""
    phase = lowering.phase
    lagrangian = lagrangian_collision(planner)
    if not _rows_compiled(planner, lowering, lagrangian):
        return
    problem = _problem(planner, phase, lagrangian)
    contact_states = {m.state.ident for m in lagrangian.models} if lagrangian is not None else set()
    free_x = mapped_free_motion(planner, lowering, contact_states)
    _violations(lowering, problem.dfree, free_x)
    if lagrangian is not None:
        phase.violation.append(
            Op(lagrangian.origin, [call("lagrangian_violation", Env.LAGRANGIAN, problem.dfree)])
        )
    carry_through_linear_mappings(planner, lowering)
    carry_through_rigid_mappings(planner, lowering)
    _sliding_rows(planner, lowering, problem.dfree)
    bodies = contact_bodies(planner, lowering, lagrangian, free_x) if lagrangian is not None else set()
    uncoupled = []
    for body, correction in enumerate(phase.corrections):
        entries = phase.entries.get(correction.state.ident)
        if entries is None and body in bodies:
            entries = []
        if entries is None or not _correction_compiled(planner, correction, lagrangian is not None):
            continue
        if correction.kind == Variant.LINEAR_SOLVER:  # its A is projected: held DOFs get no response
            J = _jacobian_rows(planner, lowering, correction.state, entries)
            linear_solver_correction(planner, lowering, correction, body, J, lagrangian is not None, problem)
            continue
        kept = _without_held_dofs(planner, lowering, correction, entries)
        if kept is None:
            continue
        J = _jacobian_rows(planner, lowering, correction.state, kept)
        item = uncoupled_correction(planner, lowering, correction, body, J, problem, lagrangian is not None)
        if item is not None:
            uncoupled.append(item)
    solve_constraints(planner, lowering, problem, uncoupled, lagrangian is not None)


def _rows_compiled(planner: Planner, lowering: ConstraintLowering, lagrangian: Collision | None) -> bool:
    """Whether the phase's rows and solver are compiled (refused at the component otherwise); with
    Lagrangian contacts, the phase's capacity grows by the contacts' reserved rows."""
    phase, solver = lowering.phase, lowering.solver
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
                return False
        lagrangian.static_rows = phase.capacity
        phase.capacity += lagrangian.row_capacity
        if phase.kept is None:
            phase.kept = planner.buffer(
                planner.checked.scene.root.path, "constraint_kept_forces", [], role="state"
            )
    why = solver_refusal(planner, lowering, lagrangian)
    if why and solver is not None:
        planner.unsupported(solver, why)
    return not why


def _problem(planner: Planner, phase: ConstraintPhase, lagrangian: Collision | None) -> ConstraintProblem:
    """W, dfree, f, d and the solvers' scratch, sized by the phase's rows, cleared first each step
    (W where the last step wrote it: the instance's CompliancePattern)."""
    n = phase.capacity
    problem = ConstraintProblem(
        W=planner.buffer("/", "constraint_W", np.zeros(n * n), columns=n, role="scratch"),
        dfree=planner.buffer("/", "constraint_dfree", np.zeros(n), role="scratch"),
        # with contacts, the last solve's forces are an output (`/.constraint_f`: impulses, rows in order)
        f=planner.buffer(
            "/", "constraint_f", np.zeros(n), role="state" if lagrangian is not None else "scratch"
        ),
        d=planner.buffer("/", "constraint_d", np.zeros(n), role="scratch"),
        scratch=planner.buffer("/", "constraint_scratch", np.zeros(3 * n), role="scratch"),
        rows=n,
    )
    if lagrangian is not None:
        lagrangian.problem = [problem.W, problem.dfree, problem.f, problem.d, problem.scratch]
        clear = call(
            "lagrangian_begin",
            Env.LAGRANGIAN,
            Env.CONSTRAINT_PATTERN,
            problem.W,
            problem.dfree,
            problem.f,
            problem.d,
        )
    else:
        clear = call(
            "constraint_clear", Env.CONSTRAINT_PATTERN, problem.W, problem.dfree, problem.f, problem.d, n
        )
    phase.rows.append(Op(phase.loop, [clear]))
    return problem


def _violations(lowering: ConstraintLowering, dfree: Buffer, free_x: dict[str, Buffer]) -> None:
    """Each constraint model's rows of dfree, from the free positions (mapped states': ``free_x``)."""
    phase = lowering.phase
    for bilateral in lowering.bilateral:
        # object1 given as a Buffer: constant positions (FixedLagrangianConstraint's rest positions)
        first = bilateral.object1
        x1 = first if isinstance(first, Buffer) else free_x.get(first.ident, first.x)
        x2 = free_x.get(bilateral.object2.ident, bilateral.object2.x)
        violation = call(
            "bilateral_violation",
            dfree,
            bilateral.first_row,
            x1,
            x2,
            bilateral.points1,
            bilateral.points2,
            bilateral.pairs,
            bilateral.rest,
            bilateral.rest_count,
        )
        phase.violation.append(Op(bilateral.origin, [violation]))
    for coordinates in lowering.coordinates:
        violation = call(
            "coordinate_violation",
            dfree,
            coordinates.first_row,
            coordinates.state.x,
            coordinates.rest,
            coordinates.count,
        )
        phase.violation.append(Op(coordinates.origin, [violation]))
    for fixed in lowering.rigid_fixed:
        x, rest = fixed.state.x, fixed.state.rest
        assert rest is not None
        violation = call("rigid_fixed_violation", dfree, fixed.first_row, x, rest, fixed.dofs, fixed.count)
        phase.violation.append(Op(fixed.origin, [violation]))
    for stopper in lowering.stoppers:
        violation = call("stopper_violation", dfree, stopper.row, stopper.state.x, stopper.index)
        phase.violation.append(Op(stopper.origin, [violation]))


def _without_held_dofs(
    planner: Planner,
    lowering: ConstraintLowering,
    correction: Correction,
    entries: list[tuple[int, int, tuple[float, ...]]],
) -> list[tuple[int, int, tuple[float, ...]]] | None:
    """GenericConstraintSolver::buildSystem clears the constraint matrix's columns of the DOFs a
    projective constraint holds (projectJacobianMatrix) before W is built, so an uncoupled
    correction neither counts their compliance nor moves them: a FixedProjectiveConstraint's DOFs
    leave the rows here. Rows on the DOFs of another projective constraint (LinearMovement's only
    while between its key times, partial ones per axis), or computed on held frames (RigidMapping's
    rows), are refused (None)."""
    state = correction.state
    computed = lowering.computed_rows.get(state.ident)
    frames: set[int] = set()
    if computed is not None:  # RigidMapping's rows: (count, rows, starts, dofs, values)
        dof_buffer = computed.fields[3]
        assert isinstance(dof_buffer, Buffer)
        frames = set(np.asarray(dof_buffer.initial, dtype=np.int64).tolist())
    dofs = {dof for _, dof, _ in entries} | frames
    for checked in planner.checked:
        if checked.category is not Category.PROJECTIVE_CONSTRAINT or planner.state_of(checked) is not state:
            continue
        assert checked.spec is not None
        component = checked.component
        fix_all = checked.spec.field("fixAll") is not None and bool(planner.value(component, "fixAll"))
        held = (
            set(range(state.size))
            if fix_all
            else set(values_of(planner, component, "indices", np.int64).tolist())
        )
        if checked.spec is FIXED_PROJECTIVE_CONSTRAINT and not frames & held:
            entries = [entry for entry in entries if entry[1] not in held]
        elif dofs & held or checked.spec.field("indices") is None:
            assert correction.checked is not None
            planner.unsupported(
                correction.checked,
                f"constraint rows on DOFs {checked.spec.name} {component.label!r} holds: SOFA removes "
                "them from the constraint matrix while it projects them; not compiled yet for "
                "UncoupledConstraintCorrection",
            )
            return None
    return entries


def _correction_compiled(planner: Planner, correction: Correction, contacts: bool) -> bool:
    """Corrections with rows are compiled on Vec3d and Rigid3d states (Vec1d without contacts) of
    an EulerImplicitSolver group."""
    checked = correction.checked
    assert checked is not None
    compiled = ("Vec3d", "Rigid3d") if contacts else ("Vec3d", "Rigid3d", "Vec1d")
    if correction.state.datatype.name not in compiled:
        planner.unsupported(
            checked,
            "with constraint rows, a correction on Vec3d or Rigid3d (Vec1d without contacts) is compiled",
        )
        return False
    group = correction.group
    if group.scheme is not Scheme.IMPLICIT or group.static or group.newmark or group.variational:
        planner.unsupported(checked, "with constraint rows, it is compiled under EulerImplicitSolver only")
        return False
    return True


def finish_constraint_phase(planner: Planner, groups: list[Group]) -> ConstraintPhase | None:
    """The phase once every component is lowered: which independent states SOFA leaves frozen
    (no correction), with the buffers that keep their x and v over the groups' step."""
    lowering = constraint_lowering(planner)
    if lowering is None:
        return None
    phase = lowering.phase
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
    if phase.capacity or lagrangian_collision(planner) is not None:
        lowering.groups = groups
        _phase_with_rows(planner, lowering)
    return phase
