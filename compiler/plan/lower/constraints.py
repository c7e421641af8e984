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
    Element,
    Env,
    Group,
    Op,
    StatePlan,
    call,
    kernel,
    origin_of,
)
from sofac.plan.lower.corrections import (
    carry_through_rigid_mappings,
    increasing_subset,
    linear_solver_correction,
    mapped_free_motion,
    mapping_of_state,
    moved_vectors,
    rigid_compliance,
    rigidly_mapped,
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


def values_of(planner: Planner, component: Component, name: str, dtype: type) -> np.ndarray:
    """A list field's values (empty when unset)."""
    value = planner.value(component, name)
    return np.asarray(value if value is not None else [], dtype=dtype).ravel()


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
    (``carry_through_rigid_mappings``), their values computed each step."""
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
    free_x = mapped_free_motion(planner, phase, contact_states)
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
    carry_through_rigid_mappings(planner, phase)
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
            linear_solver_correction(planner, phase, correction, body, J, lagrangian is not None, (W, f, n))
            continue
        comp = values_of(planner, component, "compliance", np.float64)
        if not state.datatype.rigid and 0 < len(comp) != state.size:
            # SOFA's init: a compliance not one per DOF becomes one per DOF, each the
            # defaultCompliance if set, else the compliance's first value
            given = component.get("defaultCompliance") is not None
            first = float(planner.value(component, "defaultCompliance")) if given else float(comp[0])
            comp = np.full(state.size, first)
        if state.datatype.rigid and len(comp) != 7:
            found = rigid_compliance(planner, checked, group, state)
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
        moved = moved_vectors(planner, component, state)
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
        mapping = mapping_of_state(planner, state)
        body = index.get(id(mapping.parent), -1) if mapping is not None else -1
        subset = increasing_subset(planner, mapping) if mapping is not None else None
        rigid = rigidly_mapped(planner, state)
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
