"""Lowerings of the projective constraints: fixed, partially fixed, line or plane, point, and
keyed velocities.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import (
    OFFSET,
    VECTOR,
    Aggregate,
    Count,
    Element,
    Env,
    Group,
    Projection,
    kernel,
    origin_of,
)
from sofac.plan.lower.common import (
    _call,
    _fixed_indices,
    _indices,
    _matrix_free_hint,
    _matrix_solver,
    _projected_target,
    _unit_vector,
)
from sofac.registry import Variant

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def lower_fixed(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    indices = planner.buffer(checked.component, "indices", _fixed_indices(planner, checked, state), "i64")
    t = state.datatype.name
    group.projections.append(
        Projection(
            origin_of(checked.component),
            state,
            _call(kernel("project_fixed", t), VECTOR, indices, Count(indices)),
            bool(planner.value(checked.component, "activate_projectVelocity")),
            _call(kernel("mark_fixed", t), Env.FIXED, OFFSET, indices, Count(indices)),
        )
    )


def lower_partial_fixed(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    width = state.datatype.deriv_size
    directions = planner.value(checked.component, "fixedDirections")
    flags = np.zeros(width, dtype=np.int64)
    if directions is not None:
        given = np.asarray(directions, dtype=bool).ravel()[:width]
        flags[: given.size] = given
    indices = planner.buffer(checked.component, "indices", _fixed_indices(planner, checked, state), "i64")
    mask = planner.buffer(checked.component, "fixedDirections", flags, "i64")
    t = state.datatype.name
    velocity = planner.value(checked.component, "projectVelocity") or planner.value(
        checked.component, "activate_projectVelocity"
    )
    group.projections.append(
        Projection(
            origin_of(checked.component),
            state,
            _call(kernel("project_partial", t), VECTOR, indices, Count(indices), mask),
            bool(velocity),
            _call(kernel("mark_fixed", t), Env.FIXED, OFFSET, indices, Count(indices), mask),
        )
    )


def lower_line_or_plane(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """Line- and PlaneProjectiveConstraint: responses and velocities through the block n n^T (line)
    or I - n n^T (plane) of the listed points; positions onto the line / plane after each step."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if group.assembled:
        planner.unsupported(
            checked,
            f"with {_matrix_solver(group)} (SOFA does not project the assembled matrix for it either); "
            f"{_matrix_free_hint(group)}",
        )
        return
    line = checked.spec is not None and checked.spec.variant is Variant.LINE
    width = min(state.datatype.spatial_dim, 3)  # the runtime's DT::spatial
    direction = _unit_vector(
        planner, component, "direction" if line else "normal", width, 0 if line else None
    )
    outer = np.array([[float(a) * float(b) for b in direction] for a in direction])
    block = outer if line else np.eye(width) - outer
    origin = np.zeros(width)
    given = planner.value(component, "origin")
    if given is not None:
        flat = np.asarray(given, dtype=float).ravel()[:width]
        origin[: flat.size] = flat
    indices = planner.buffer(component, "indices", _indices(planner, checked, "indices", state.size), "i64")
    block_buffer = planner.buffer(component, "projection", block)
    origin_buffer = planner.buffer(component, "origin", origin)
    direction_buffer = planner.buffer(component, "direction" if line else "normal", direction)
    t = state.datatype.name
    onto = "project_onto_line" if line else "project_onto_plane"
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(kernel("project_block", t), VECTOR, indices, Count(indices), block_buffer),
            velocity=True,
            position=_call(kernel(onto, t), VECTOR, indices, Count(indices), origin_buffer, direction_buffer),
        )
    )


def lower_point_constraint(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """PointProjectiveConstraint: the listed DOFs (all with fixAll) held at ``point``."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    indices = planner.buffer(component, "indices", _fixed_indices(planner, checked, state), "i64")
    target = np.zeros(state.datatype.coord_size)
    given = planner.value(component, "point")
    if given is not None:
        flat = np.asarray(given, dtype=float).ravel()[: target.size]
        target[: flat.size] = flat
    target_buffer = planner.buffer(component, "point", target)
    t = state.datatype.name
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(kernel("project_fixed", t), VECTOR, indices, Count(indices)),
            velocity=True,
            mark=_call(kernel("mark_fixed", t), Env.FIXED, OFFSET, indices, Count(indices)),
            position=_call(kernel("project_onto_point", t), VECTOR, indices, Count(indices), target_buffer),
        )
    )


def lower_linear_velocity(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """LinearVelocityProjectiveConstraint: the listed DOFs move at a velocity interpolated between key
    times (SOFA's findKeyTimes at each step's start time), integrated explicitly from their last
    projected positions; their solver increments are zeroed while it is active."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    width, coord = state.datatype.deriv_size, state.datatype.coord_size
    times = np.asarray(planner.value(component, "keyTimes"), dtype=float).ravel()
    given = planner.value(component, "velocities")  # SOFA starts the list with one zero velocity
    velocities = np.asarray(given if given is not None and np.size(given) else np.zeros(width), dtype=float)
    velocities = velocities.reshape(-1, width)
    if len(times) != len(velocities):
        planner.unsupported(checked, f"it has {len(times)} keyTimes but {len(velocities)} velocities")
        return
    after_end = bool(planner.value(component, "continueAfterEnd"))
    # A direct solver's matrix is marked once, at creation: only a constraint active at every step
    # (keys around the start time, continued after the last one) keeps those marks right.
    always_active = len(times) >= 2 and times[0] <= 0.0 < times[-1] and after_end
    if group.assembled and not always_active:
        planner.unsupported(
            checked,
            f"with {_matrix_solver(group)} it is compiled only when active at every step (keyTimes "
            f'starting at 0 or before, continueAfterEnd="1"); {_matrix_free_hint(group)}',
        )
        return
    coordinates = _indices(planner, checked, "coordinates", 0, all_if_empty=False)
    if state.datatype.rigid and len(coordinates):
        planner.unsupported(checked, "on rigid DOFs it is compiled without `coordinates` only")
        return
    if len(coordinates) and (coordinates.min() < 0 or coordinates.max() >= width):
        planner.unsupported(checked, f"its coordinates must be between 0 and {width - 1}")
        return
    indices = planner.buffer(component, "indices", _fixed_indices(planner, checked, state), "i64")
    count = len(indices.initial)
    memory = planner.buffer(component, "memory", np.zeros(4 + 2 * width + count * coord), role="scratch")
    time_buffer = planner.buffer(component, "keyTimes", times)
    velocity_buffer = planner.buffer(component, "velocities", velocities, columns=width)
    coordinate_buffer = planner.buffer(component, "coordinates", coordinates, "i64")
    t = state.datatype.name
    keyed = Aggregate("KeyedVelocity", (memory, time_buffer, velocity_buffer, len(times), after_end), (t,))
    selected = (indices, Count(indices))
    chosen = (coordinate_buffer, Count(coordinate_buffer))
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(kernel("keyed_velocity_response", t), keyed, VECTOR, *selected, Env.TIME),
            velocity=True,
            mark=_call(kernel("mark_fixed", t), Env.FIXED, OFFSET, indices, Count(indices))
            if group.assembled
            else None,
            position=_call(
                kernel("keyed_velocity_position", t),
                keyed,
                VECTOR,
                *selected,
                *chosen,
                Env.TIME,
                Element(planner.dt),
            ),
            project_velocity=_call(
                kernel("keyed_velocity_velocity", t), keyed, VECTOR, *selected, *chosen, Env.TIME
            ),
        )
    )


def _refuse_assembled(planner: Planner, checked: CheckedComponent, group: Group, why: str) -> bool:
    """True (and E222) when the group solves an assembled matrix the constraint cannot project."""
    if not group.assembled:
        return False
    planner.unsupported(checked, f"with {_matrix_solver(group)} {why}; {_matrix_free_hint(group)}")
    return True


def lower_fixed_plane(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FixedPlaneProjectiveConstraint: responses lose their component along ``direction`` (as given,
    not normalised) on the listed points, or, when dmin != dmax, on the points whose initial
    x.direction lies strictly between them (SOFA's selectVerticesAlongPlane at init). Velocities and
    positions are left alone; an assembled matrix loses the rows and columns where direction != 0
    (SOFA's applyConstraint)."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    datatype = state.datatype
    width = datatype.spatial_dim if datatype.rigid else datatype.deriv_size
    direction = np.zeros(datatype.coord_size)
    given = planner.value(component, "direction")
    if given is not None:
        flat = np.asarray(given, dtype=float).ravel()[: direction.size]
        direction[: flat.size] = flat
    indices = list(_indices(planner, checked, "indices", state.size, all_if_empty=False))
    dmin, dmax = (
        float(planner.value(component, "dmin") or 0.0),
        float(planner.value(component, "dmax") or 0.0),
    )
    if dmin != dmax:
        positions = np.asarray(state.x.initial, dtype=float).reshape(state.size, datatype.coord_size)
        for i, point in enumerate(positions):
            distance = sum(float(point[c]) * float(direction[c]) for c in range(width))
            if dmin < distance < dmax:
                indices.append(i)
    index_buffer = planner.buffer(component, "indices", np.asarray(indices, dtype=np.int64), "i64")
    direction_buffer = planner.buffer(component, "direction", direction[:width])
    mask = planner.buffer(
        component, "cleared", (direction[: datatype.deriv_size] != 0.0).astype(np.int64), "i64"
    )
    t = datatype.name
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(
                kernel("project_out_direction", t),
                VECTOR,
                index_buffer,
                Count(index_buffer),
                direction_buffer,
            ),
            mark=_call(kernel("mark_fixed", t), Env.FIXED, OFFSET, index_buffer, Count(index_buffer), mask),
        )
    )


def lower_fixed_translation(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FixedTranslationProjectiveConstraint: the listed DOFs' responses zeroed (SOFA's projectResponse
    clears the whole derivative); velocities and positions are not projected. SOFA does not
    project an assembled matrix for it (applyConstraint is not implemented): refused there."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    if _refuse_assembled(planner, checked, group, "it is not compiled (SOFA does not project the matrix)"):
        return
    indices = planner.buffer(checked.component, "indices", _fixed_indices(planner, checked, state), "i64")
    t = state.datatype.name
    group.projections.append(
        Projection(
            origin_of(checked.component),
            state,
            _call(kernel("project_fixed", t), VECTOR, indices, Count(indices)),
        )
    )


def lower_direction(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """DirectionProjectiveConstraint: responses and velocities through n n^T on the listed points
    (indices past the state dropped, as SOFA's init does); positions onto the line through each
    point's initial position along n."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if _refuse_assembled(planner, checked, group, "it is not compiled yet"):
        return
    width = min(state.datatype.spatial_dim, 3)
    direction = _unit_vector(planner, component, "direction", width, None)
    block = np.array([[float(a) * float(b) for b in direction] for a in direction])
    indices = _indices(planner, checked, "indices", state.size, all_if_empty=False)
    indices = indices[indices < state.size]
    positions = np.asarray(state.x.initial, dtype=float).reshape(state.size, state.datatype.coord_size)
    origins = positions[indices, :width] if len(indices) else np.zeros((0, width))
    index_buffer = planner.buffer(component, "indices", indices, "i64")
    block_buffer = planner.buffer(component, "projection", block)
    origin_buffer = planner.buffer(component, "origins", origins, columns=width)
    direction_buffer = planner.buffer(component, "direction", direction)
    t = state.datatype.name
    selected = (index_buffer, Count(index_buffer))
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(kernel("project_block", t), VECTOR, *selected, block_buffer),
            velocity=True,
            position=_call(
                kernel("project_onto_lines", t), VECTOR, *selected, origin_buffer, direction_buffer
            ),
        )
    )


def lower_fixed_rotation(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FixedRotationProjectiveConstraint: after each step every rigid's rotation about the fixed
    axes is replaced by that of its initial orientation (SOFA projects positions only)."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    axes = np.array(
        [bool(planner.value(component, f"Fixed{axis}Rotation")) for axis in "XYZ"], dtype=np.int64
    )
    positions = np.asarray(state.x.initial, dtype=float).reshape(state.size, state.datatype.coord_size)
    initial = planner.buffer(component, "previousOrientation", positions[:, 3:7].copy(), columns=4)
    axis_buffer = planner.buffer(component, "fixedAxes", axes, "i64")
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            None,
            position=_call("fixed_rotation_position", VECTOR, state.size, initial, axis_buffer),
        )
    )


def lower_linear_movement(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """LinearMovementProjectiveConstraint: between key times, the listed DOFs follow the movement
    interpolated linearly (rigids: orientation slerped between the keys' Euler angles), relative to
    their positions at the first projection or absolute; their responses are zeroed and their
    velocities set to the keys' slope. SOFA's findKeyTimes runs at the step's start time."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid and state.datatype.coord_size != 7:
        planner.unsupported(checked, "on Rigid2d it is not compiled yet")
        return
    if _refuse_assembled(planner, checked, group, "it is not compiled yet"):
        return
    width, coord = state.datatype.deriv_size, state.datatype.coord_size
    times = np.asarray(planner.value(component, "keyTimes"), dtype=float).ravel()
    given = planner.value(component, "movements")  # SOFA starts the list with one zero movement
    movements = np.asarray(given if given is not None and np.size(given) else np.zeros(width), dtype=float)
    movements = movements.reshape(-1, width)
    if len(times) > len(movements):
        planner.unsupported(checked, f"it has {len(times)} keyTimes but only {len(movements)} movements")
        return
    indices = planner.buffer(component, "indices", _fixed_indices(planner, checked, state), "i64")
    count = len(indices.initial)
    memory = planner.buffer(component, "memory", np.zeros(1 + count * coord), role="scratch")
    time_buffer = planner.buffer(component, "keyTimes", times)
    movement_buffer = planner.buffer(component, "movements", movements, columns=width)
    relative = bool(planner.value(component, "relativeMovements"))
    t = state.datatype.name
    keyed = Aggregate("KeyedMovement", (memory, time_buffer, movement_buffer, len(times), relative), (t,))
    selected = (indices, Count(indices))
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            _call(kernel("keyed_movement_response", t), keyed, VECTOR, *selected, Env.TIME),
            velocity=True,
            position=_call(kernel("keyed_movement_position", t), keyed, VECTOR, *selected, Env.TIME),
            project_velocity=_call(kernel("keyed_movement_velocity", t), keyed, VECTOR, *selected, Env.TIME),
        )
    )
