"""The constraint phase's solve and UncoupledConstraintCorrection on rows: W from each
correction's compliance, the loop's constraint solver on W and dfree (built: BGS, NNCG, LCP;
unbuilt: UGS, LCP with build_lcp=0, through the corrections), and each correction moving its
state by the forces found. Used by plan/lower/constraints.py once the rows are known.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.front.model import Component
from sofac.plan.ir import Aggregate, BuiltSolver, Collision, Correction, Element, Env, Op, call, kernel
from sofac.plan.lower.constraint_context import ConstraintLowering, ConstraintProblem, UncoupledBody
from sofac.plan.lower.corrections import moved_vectors, rigid_compliance
from sofac.registry import Variant
from sofac.registry.components.lagrangian import BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# The solvers compiled on the phase's rows: built ones solve on W, the unbuilt one through the corrections.
_BUILT = {Variant.BLOCK_GAUSS_SEIDEL: BuiltSolver.BLOCK_GAUSS_SEIDEL, Variant.NNCG: BuiltSolver.NNCG}
_ROW_SOLVERS = {*_BUILT, Variant.UNBUILT_GAUSS_SEIDEL}


def values_of(planner: Planner, component: Component, name: str, dtype: type) -> np.ndarray:
    """A list field's values (empty when unset)."""
    value = planner.value(component, name)
    return np.asarray(value if value is not None else [], dtype=dtype).ravel()


def solver_refusal(planner: Planner, lowering: ConstraintLowering, lagrangian: Collision | None) -> str:
    """Why the loop's constraint solver is not compiled on this phase's rows ("" when it is)."""
    phase, solver = lowering.phase, lowering.solver
    name = solver.spec.name if solver is not None and solver.spec is not None else ""
    if lagrangian is not None and phase.method == Variant.LCP:
        return _lcp_refusal(planner, lowering, lagrangian)
    if lagrangian is not None and phase.method not in _ROW_SOLVERS:
        return f"{name} with Lagrangian contacts is not compiled yet"
    if phase.method not in _ROW_SOLVERS and not (lagrangian is not None and phase.method == Variant.LCP):
        return f"{name} on constraint rows is not compiled yet"
    return ""


def _lcp_refusal(planner: Planner, lowering: ConstraintLowering, collision: Collision) -> str:
    """Why an LCPConstraintSolver on Lagrangian contacts is not compiled ("" when it is)."""
    solver = lowering.solver
    assert solver is not None
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


def uncoupled_correction(
    planner: Planner,
    lowering: ConstraintLowering,
    correction: Correction,
    body: int,
    J: Aggregate,
    problem: ConstraintProblem,
    contacts: bool,
) -> UncoupledBody | None:
    """UncoupledConstraintCorrection on rows: W += factor J C Jᵀ, then λ = Jᵀ f, dx = C λ,
    x = x_free + position dx, v = v_free + velocity dx. None when its compliance is refused."""
    checked = correction.checked
    assert checked is not None
    phase, state, group = lowering.phase, correction.state, correction.group
    component = checked.component
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
            return None
        comp = found
    comp_buffer = planner.buffer(component, "compliance", comp)
    scaled = planner.buffer(component, "scaled_compliance", np.zeros(len(comp) + 1), role="scratch")
    default = float(planner.value(component, "defaultCompliance"))
    comp0 = Element(planner.buffer(component, "defaultCompliance", [default], role="param"))
    dt = float(planner.dt.initial[0])
    use_ode = bool(planner.value(component, "useOdeSolverIntegrationFactors"))
    # EulerImplicitSolver: position factor dt, velocity factor 1 (its integration factors)
    factor = dt if use_ode else 1.0
    position = dt if use_ode else float(planner.value(component, "correctionPositionFactor"))
    velocity = 1.0 if use_ode else float(planner.value(component, "correctionVelocityFactor")) / dt
    t = state.datatype.name
    comp_args = (comp0, comp_buffer, len(comp))
    W, f, pattern = problem.W, problem.f, Env.CONSTRAINT_PATTERN
    if contacts:
        add = call(
            kernel("lagrangian_add_compliance", t),
            Env.LAGRANGIAN,
            body,
            pattern,
            W,
            J,
            state.size,
            *comp_args,
            factor,
            scaled,
        )
    else:
        add = call(
            kernel("uncoupled_add_compliance", t), pattern, W, J, state.size, *comp_args, factor, scaled
        )
    phase.compliance.append(Op(correction.origin, [add]))
    moved = moved_vectors(planner, component, state)
    if contacts:
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
    return UncoupledBody(t, J, state, comp0, comp_buffer, len(comp), body)


def solve_constraints(
    planner: Planner,
    lowering: ConstraintLowering,
    problem: ConstraintProblem,
    uncoupled: list[UncoupledBody],
    contacts: bool,
) -> None:
    """The loop's constraint solver on the phase's rows, as its method and settings say."""
    phase, solver = lowering.phase, lowering.solver
    if phase.method == Variant.LCP:  # LCPConstraintSolver on the contacts' rows
        names = ("maxIt", "tolerance", "mu", "minW", "maxF", "regularizationTerm", "initial_guess")
        lcp_settings = [Element(phase.settings[name]) for name in names]
        if solver is not None and not planner.value(solver.component, "build_lcp"):
            _lcp_unbuilt(planner, lowering, uncoupled, problem, lcp_settings)
            return
        lcp = call(
            "lagrangian_solve_lcp",
            Env.LAGRANGIAN,
            *problem.arguments(),
            *lcp_settings,
            phase.report,
            Env.TIME,
        )
        phase.solve.append(Op(phase.solver, [lcp]))
        return
    firsts = planner.buffer("/", "constraint_block_first", [b[0] for b in phase.blocks], "i64")
    kinds = planner.buffer("/", "constraint_block_kind", [b[1] for b in phase.blocks], "i64")
    parameters = planner.buffer(
        "/", "constraint_block_parameter", [(b[2], b[4]) for b in phase.blocks], columns=2
    )
    kept = planner.buffer("/", "constraint_block_kept", [b[3] for b in phase.blocks], "i64")
    assert phase.kept is not None
    blocks = (firsts, kinds, parameters, kept, phase.kept)
    if phase.method == Variant.UNBUILT_GAUSS_SEIDEL:
        _unbuilt_solve(planner, lowering, uncoupled, problem, blocks, contacts)
        return
    order = ("maxIterations", "tolerance", "sor", "scaleTolerance", "allVerified", "regularizationTerm")
    if phase.settings:
        settings: list[Element | float] = [Element(phase.settings[name]) for name in order]
    else:  # no solver in the scene: FreeMotionAnimationLoop makes a BlockGaussSeidelConstraintSolver
        default = BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER.field
        settings = [float(default(name).default) for name in order]  # type: ignore[union-attr]
    method = _BUILT[phase.method]
    arguments = (*problem.arguments(), *blocks, *settings, phase.report, Env.TIME)
    if contacts:
        solve = call(kernel("lagrangian_solve", len(phase.blocks)), Env.LAGRANGIAN, method, *arguments)
    else:
        solve = call(kernel("solve_constraints", len(phase.blocks)), method, *arguments)
    phase.solve.append(Op(phase.solver or phase.loop, [solve]))


def _unbuilt_items(planner: Planner, uncoupled: list[UncoupledBody], contacts: bool) -> list[Aggregate]:
    """The corrections as the unbuilt solvers reach them (runtime UnbuiltUncoupled: J, the
    compliance, and the force and displacement vectors they fill), each with its body index when
    the rows include contacts."""
    aggregates = []
    for item in uncoupled:
        state = item.state
        zeros = np.zeros_like(state.v.initial)
        force = planner.buffer(
            state.component, "constraint_force", zeros, columns=state.v.columns, role="scratch"
        )
        disp = planner.buffer(
            state.component, "constraint_disp", zeros, columns=state.v.columns, role="scratch"
        )
        fields = (
            item.J,
            state.size,
            item.default_compliance,
            item.compliance,
            item.compliance_count,
            force,
            disp,
        )
        aggregate = Aggregate("UnbuiltUncoupled", fields, (item.datatype,))
        aggregates.append(
            Aggregate("LagrangianUnbuilt", (item.body, aggregate), (item.datatype,))
            if contacts
            else aggregate
        )
    return aggregates


def _lcp_unbuilt(
    planner: Planner,
    lowering: ConstraintLowering,
    uncoupled: list[UncoupledBody],
    problem: ConstraintProblem,
    settings: list[Element],
) -> None:
    """LCPConstraintSolver with build_lcp=0 and mu=0 (lcp_gaussseidel_unbuilt): no W built (the
    compliance calls are dropped), the 1x1 blocks and displacements through the corrections."""
    phase, solver = lowering.phase, lowering.solver
    phase.compliance.clear()
    types = {item.datatype for item in uncoupled}
    if len(types) != 1:
        if solver is not None:
            planner.unsupported(solver, "unbuilt, it is compiled for corrections of one DataType")
        return
    (t,) = types
    aggregates = _unbuilt_items(planner, uncoupled, contacts=True)
    solve = call(
        kernel("lagrangian_solve_lcp_unbuilt", t),
        Env.LAGRANGIAN,
        *problem.arguments(),
        *settings,
        phase.report,
        Env.TIME,
        *aggregates,
    )
    phase.solve.append(Op(phase.solver, [solve]))


def _unbuilt_solve(
    planner: Planner,
    lowering: ConstraintLowering,
    uncoupled: list[UncoupledBody],
    problem: ConstraintProblem,
    blocks: tuple,
    contacts: bool,
) -> None:
    """UnbuiltGaussSeidelConstraintSolver: W's diagonal blocks from the raw compliances, the
    displacements through the corrections (no built W: the compliance calls are dropped)."""
    phase, solver = lowering.phase, lowering.solver
    phase.compliance.clear()
    types = {item.datatype for item in uncoupled}
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
    aggregates = _unbuilt_items(planner, uncoupled, contacts)
    settings = [
        Element(phase.settings[name])
        for name in ("maxIterations", "tolerance", "sor", "scaleTolerance", "allVerified")
    ]
    arguments = (*problem.arguments(), *blocks, *settings, phase.report, Env.TIME, *aggregates)
    if contacts:
        solve = call(kernel("lagrangian_solve_unbuilt", t, len(phase.blocks)), Env.LAGRANGIAN, *arguments)
    else:
        solve = call(kernel("solve_unbuilt", t, len(phase.blocks)), *arguments)
    phase.solve.append(Op(phase.solver, [solve]))
