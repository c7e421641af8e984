"""Lowerings of the Lagrangian constraint models (BilateralLagrangianConstraint,
FixedLagrangianConstraint, StopperLagrangianConstraint, UniformLagrangianConstraint,
SlidingLagrangianConstraint): each adds its rows to FreeMotionAnimationLoop's constraint phase
(plan/lower/constraints.py), which solves them with the scene's contacts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import (
    Aggregate,
    ConstraintPhase,
    Env,
    Group,
    Resolution,
    StatePlan,
    origin_of,
)
from sofac.plan.lower.constraint_context import (
    BilateralViolation,
    ConstraintLowering,
    CoordinateViolation,
    RigidFixedViolation,
    SlidingRows,
    StopperViolation,
)
from sofac.plan.lower.constraint_solve import values_of
from sofac.plan.lower.constraints import (
    constraint_lowering,
)
from sofac.plan.lower.corrections import linearly_mapped, rigidly_mapped

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def _lowering_for(
    planner: Planner, checked: CheckedComponent, datatype: str | None = None
) -> ConstraintLowering | None:
    """The constraint phase a constraint model's rows go to, with its pending rows; None once it
    is refused (no FreeMotionAnimationLoop, or not the ``datatype`` it is compiled for)."""
    lowering = constraint_lowering(planner)
    if lowering is None:
        planner.unsupported(checked, "Lagrangian constraints act only under FreeMotionAnimationLoop")
        return None
    if datatype is not None and (checked.datatype is None or checked.datatype.name != datatype):
        planner.unsupported(checked, f"it is compiled for {datatype} only")
        return None
    return lowering


def _has_end_time(planner: Planner, checked: CheckedComponent) -> bool:
    """A constraint with an endTime is refused (its rows would stop at that time)."""
    if float(planner.value(checked.component, "endTime")) >= 0.0:
        planner.unsupported(checked, "a constraint with an endTime is not compiled yet")
        return True
    return False


def lower_bilateral(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """BilateralLagrangianConstraint<Vec3d>: three rows per pair of points, -e_k on object1's point
    and +e_k on object2's (buildConstraintMatrix), the violation x2_free - x1_free (- rest)."""
    lowering = _lowering_for(planner, checked, "Vec3d")
    if lowering is None:
        return
    phase, component = lowering.phase, checked.component
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
        if state.mapped and not (rigidly_mapped(planner, state) or linearly_mapped(planner, state)):
            planner.unsupported(
                checked,
                "constraint rows through mappings other than one RigidMapping, IdentityMapping, "
                f"SubsetMapping or BarycentricMapping from an independent state: not compiled yet ({name})",
            )
            return
        states.append(state)
    if states[0] is states[1]:
        planner.unsupported(checked, "object1 and object2 are the same state: not compiled yet")
        return
    first_points, second_points = (
        values_of(planner, component, name, np.int64) for name in ("first_point", "second_point")
    )
    pairs = min(len(first_points), len(second_points))
    if pairs == 0:
        planner.ignored.append((component, "no pair of points: no constraint row"))
        return
    for name, points, state in (
        ("first_point", first_points, states[0]),
        ("second_point", second_points, states[1]),
    ):
        # (indices past a state of known size are the checker's E218: here its positions are unknown)
        if int(np.max(points[:pairs])) >= state.size:
            planner.unsupported(
                checked,
                f"{name} names point {int(np.max(points[:pairs]))} of {state.component.label!r}, whose "
                "positions sofac does not know at compile time (an engine output it does not evaluate)",
                attribute=name,
            )
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
        phase.blocks.append((first_row + 3 * p, Resolution.BILATERAL_3, load, kept_offset + 3 * p, 0.0))
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
    lowering.bilateral.append(
        BilateralViolation(
            origin_of(component), first_row, states[0], states[1], m1, m2, pairs, rest_buffer, len(rest)
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
    with its kept forces (FixedLagrangianConstraint.cpp's Vec3 specialisation); <Rigid3d>: six rows
    per frame, see ``_fixed_rigid``."""
    lowering = _lowering_for(planner, checked)
    if lowering is None:
        return
    if checked.datatype is None or checked.datatype.name not in ("Vec3d", "Rigid3d"):
        planner.unsupported(checked, "it is compiled for Vec3d and Rigid3d only")
        return
    phase, component = lowering.phase, checked.component
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
        indices = values_of(planner, component, "indices", np.int64)
    count = len(indices)
    if count == 0:
        planner.ignored.append((component, "no index: no constraint row"))
        return
    if state.datatype.name != checked.datatype.name:
        planner.unsupported(checked, f"its template differs from its state's ({state.datatype.name})")
        return
    if state.datatype.rigid:
        _fixed_rigid(planner, lowering, checked, state, indices)
        return
    first_row = phase.capacity
    phase.capacity += 3 * count
    kept_offset = _kept_forces(planner, phase, 3 * count)
    for p, dof in enumerate(indices):
        phase.blocks.append((first_row + 3 * p, Resolution.BILATERAL_3, 1.0, kept_offset + 3 * p, 0.0))
        for k in range(3):
            unit = tuple(1.0 if c == k else 0.0 for c in range(3))
            phase.entries.setdefault(state.ident, []).append((first_row + 3 * p + k, int(dof), unit))
    fixed = planner.buffer(component, "fixed_indices", indices, "i64")
    no_rest = planner.buffer(component, "no_rest_vector", np.zeros((0, 3)), columns=3)
    # x_free[i] - rest[i]: the bilateral violation with object1 the rest positions, object2 the state
    assert state.rest is not None
    lowering.bilateral.append(
        BilateralViolation(
            origin_of(component), first_row, state.rest, state, fixed, fixed, count, no_rest, 0
        )
    )


def _fixed_rigid(
    planner: Planner,
    lowering: ConstraintLowering,
    checked: CheckedComponent,
    state: StatePlan,
    dofs: np.ndarray,
) -> None:
    """FixedLagrangianConstraint<Rigid3d>: per fixed frame six rows, (e_k, 0) then (0, e_k); the
    violation the centre's move and the Euler vector of q_free q_rest⁻¹; two
    BilateralConstraintResolution3Dof, on the kept forces' centre and orientation parts."""
    phase, component = lowering.phase, checked.component
    count = len(dofs)
    first_row = phase.capacity
    phase.capacity += 6 * count
    kept_offset = _kept_forces(planner, phase, 6 * count)
    for p, dof in enumerate(dofs):
        for half in (0, 3):
            phase.blocks.append(
                (first_row + 6 * p + half, Resolution.BILATERAL_3, 1.0, kept_offset + 6 * p + half, 0.0)
            )
        for k in range(6):
            unit = tuple(1.0 if c == k else 0.0 for c in range(6))
            phase.entries.setdefault(state.ident, []).append((first_row + 6 * p + k, int(dof), unit))
    buffer = planner.buffer(component, "fixed_indices", dofs, "i64")
    lowering.rigid_fixed.append(RigidFixedViolation(origin_of(component), first_row, state, buffer, count))


def lower_stopper(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """StopperLagrangianConstraint<Vec1d>: one row +1 on DOF `index`, violation x_free[index], its
    resolution keeping the free displacement in [min, max] (StopperLagrangianConstraintResolution1Dof)."""
    lowering = _lowering_for(planner, checked)
    if lowering is None:
        return
    phase, component = lowering.phase, checked.component
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
    phase.blocks.append((row, Resolution.STOPPER_1, low, -1, high))
    phase.entries.setdefault(state.ident, []).append((row, index, (1.0,)))
    lowering.stoppers.append(StopperViolation(origin_of(component), row, state, index))


def lower_uniform(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """UniformLagrangianConstraint<Vec1d>: a row +1 on every coordinate of every DOF, violation
    x_free (- rest_position with constrainToRestPos), one BilateralConstraintResolution per row
    (iterative) without kept forces."""
    lowering = _lowering_for(planner, checked)
    if lowering is None:
        return
    phase, component = lowering.phase, checked.component
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
            phase.blocks.append((row, Resolution.BILATERAL_1, 1.0, -1, 0.0))
            unit = tuple(1.0 if c == j else 0.0 for c in range(width))
            phase.entries.setdefault(state.ident, []).append((row, i, unit))
    rest = state.rest if planner.value(component, "constrainToRestPos") else Env.NONE
    lowering.coordinates.append(CoordinateViolation(origin_of(component), first, state, rest, count))


def lower_sliding(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """SlidingLagrangianConstraint<Vec3d>: object1's point slides on object2's segment axis_1-axis_2.
    Four rows built each step from the free positions (runtime sliding_rows): two bilateral across
    the axis, two unilateral at its ends (SOFA's BilateralConstraintResolution and
    UnilateralConstraintResolution, no kept forces)."""
    lowering = _lowering_for(planner, checked, "Vec3d")
    if lowering is None:
        return
    phase, component = lowering.phase, checked.component
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
    for row, kind in enumerate(
        (Resolution.BILATERAL_1, Resolution.BILATERAL_1, Resolution.UNILATERAL_1, Resolution.UNILATERAL_1)
    ):
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
    lowering.sliding.append(SlidingRows(checked, first, aggregates, point, (a, b), degenerate))
    for state in states:
        phase.entries.setdefault(state.ident, [])
