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
from sofac.plan.ir import ConstraintPhase, Correction, Group, origin_of
from sofac.registry import Category
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
        method = solver.spec.role
        names = _LCP_SETTINGS if method == "lcp" else _GENERIC_SETTINGS
        for name in names:
            value = planner.value(solver.component, name)
            settings[name] = planner.buffer(solver.component, name, [float(value)], role="param")
    report = planner.buffer(loop.component, "constraint_report", np.zeros(5), role="scratch")
    phase = ConstraintPhase(
        loop=origin_of(loop.component),
        solver=origin_of(solver.component) if solver is not None else "",
        method=method,
        settings=settings,
        report=report,
    )
    planner.constraint_phase = phase  # type: ignore[attr-defined]
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
    kind = checked.spec.role
    if kind == "linear_solver" and (group.scheme != "implicit" or group.linear_solver is None):
        planner.unsupported(
            checked,
            "it needs the linear solver of an implicit ODE solver (EulerImplicitSolver + a linear solver)",
        )
        return
    if any(c.state is state for c in phase.corrections):
        planner.unsupported(checked, f"{state.path!r} already has a constraint correction")
        return
    phase.corrections.append(Correction(origin_of(checked.component), kind, state, group))


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
    return phase
