"""Lowerings of loads and other force fields: constant forces, rest-shape springs, plane and
ellipsoid contacts, damping, pressure.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import (
    OFFSET,
    Element,
    Env,
    Group,
    Op,
    Scheme,
    kernel,
    origin_of,
)
from sofac.plan.lower.common import _assemble, _call, _indices, _matrix_solver, _target, _topology_cells

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def lower_interaction_ellipsoid(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """InteractionEllipsoidForceField: ellipsoids carried by a rigid DOF of object2 push the points of
    object1 (object2 is read, not pushed: object2_forces must be false)."""
    component = checked.component
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        ends.append(planner.states.get(id(target)) if isinstance(target, Component) else None)
    points, frame = ends
    if points is None or frame is None:
        planner.unsupported(checked, "object1 and object2 must be MechanicalObjects")
        return
    group = owner.get(id(points.component))
    if group is None:
        planner.ignored.append((component, "object1 has no ODE solver"))
        return
    if points.datatype.name != "Vec3d" or frame.datatype.name != "Rigid3d":
        planner.unsupported(checked, "it is compiled for Vec3d points and a Rigid3d frame only")
        return
    if planner.value(component, "object2_forces") is not False or planner.value(component, "object2_invert"):
        planner.unsupported(checked, "object2_forces=true or object2_invert=true is not compiled yet")
        return
    index = int(planner.value(component, "object2_dof_index") or 0)
    if not 0 <= index < frame.size:
        planner.unsupported(checked, f"object2_dof_index {index} is not a DOF of object2")
        return
    center_value, radius_value = planner.value(component, "center"), planner.value(component, "vradius")
    centers = np.asarray(center_value if center_value is not None else [], dtype=float).reshape(-1, 3)
    radii = np.asarray(radius_value if radius_value is not None else [], dtype=float).reshape(-1, 3)
    count = max(len(centers), len(radii))
    table = []
    for e in range(count):
        r = radii[min(e, len(radii) - 1)] if len(radii) else np.ones(3)
        c = centers[min(e, len(centers) - 1)] if len(centers) else np.zeros(3)
        table.extend([*c.tolist(), *(1 / (float(v) * float(v)) for v in r)])
    ellipsoids = planner.buffer(component, "ellipsoids", np.asarray(table, dtype=float), columns=6)
    contacts = planner.buffer(component, "contacts", np.zeros(10 * points.size), columns=10, role="scratch")
    quaternion = planner.buffer(component, "frame", np.array([0.0, 0.0, 0.0, 1.0]), role="scratch")
    stiffness, damping = (
        float(planner.value(component, "stiffness")),
        float(planner.value(component, "damping")),
    )
    origin = origin_of(component)
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    "ellipsoid_add_force",
                    points.x,
                    points.v,
                    points.f,
                    points.size,
                    frame.x,
                    index,
                    ellipsoids,
                    count,
                    float(stiffness),
                    float(damping),
                    contacts,
                    quaternion,
                )
            ],
        )
    )
    if group.scheme is Scheme.IMPLICIT:
        if group.assembled:
            planner.unsupported(
                checked, f"{_matrix_solver(group)} with an ellipsoid force field is not compiled yet"
            )
            return
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "ellipsoid_add_dforce",
                        points.dx,
                        points.df,
                        points.size,
                        contacts,
                        quaternion,
                        Env.KFACT,
                    )
                ],
            )
        )


def lower_velocity_damping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """UniformVelocityDampingForceField: f -= c v; with implicit="true", B = -c I in the solves."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    value = float(planner.value(component, "dampingCoefficient"))
    if planner.prune and value == 0.0:
        planner.pruned[f"{component.path}.dampingCoefficient"] = (
            "dampingCoefficient is 0: no damping force computed"
        )
        return
    coefficient = planner.buffer(component, "dampingCoefficient", [value], role="param")
    scalars = state.size * state.datatype.deriv_size
    origin = origin_of(component)
    group.forces.append(
        Op(origin, [_call("velocity_damping_force", state.f, state.v, scalars, Element(coefficient))])
    )
    if planner.value(component, "implicit") and group.scheme is Scheme.IMPLICIT:
        if group.assembled:
            planner.unsupported(checked, f"implicit damping with {_matrix_solver(group)} is not compiled yet")
            return
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "velocity_damping_dforce",
                        state.df,
                        state.dx,
                        scalars,
                        Element(coefficient),
                        Env.BFACT,
                    )
                ],
            )
        )


def lower_constant_force(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    width = state.datatype.deriv_size
    indices = _indices(planner, checked, "indices", state.size)
    forces = planner.value(component, "forces")
    total = planner.value(component, "totalForce")
    single = planner.value(component, "force")
    if forces is not None and np.size(forces):
        rows = np.asarray(forces, dtype=float).reshape(-1, width)
        rows = rows if len(rows) == len(indices) else np.tile(rows[-1], (len(indices), 1))
    elif total is not None and np.size(total) and len(indices):
        rows = np.tile(np.asarray(total, dtype=float).ravel()[:width] / len(indices), (len(indices), 1))
    elif single is not None and np.size(single):
        rows = np.tile(np.asarray(single, dtype=float).ravel()[:width], (len(indices), 1))
    else:
        rows = np.zeros((len(indices), width))
    index_buffer = planner.buffer(component, "indices", indices, "i64")
    force_buffer = planner.buffer(component, "forces", rows, columns=width, role="param")
    group.forces.append(
        Op(
            origin_of(component),
            [
                _call(
                    kernel("constant_forces", state.datatype.name),
                    state.f,
                    index_buffer,
                    force_buffer,
                    len(indices),
                )
            ],
        )
    )


def lower_rest_shape(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid or checked.links.get("external_rest_shape") is not None:
        planner.unsupported(checked, "rigid or external rest shapes are not compiled yet")
        return
    indices = _indices(planner, checked, "points", state.size)
    stiffness = planner.value(component, "stiffness")
    stiffness = np.asarray(
        stiffness if stiffness is not None and np.size(stiffness) else [100.0], dtype=float
    )
    index_buffer = planner.buffer(component, "points", indices, "i64")
    k_buffer = planner.buffer(component, "stiffness", stiffness, role="param")
    origin = origin_of(component)
    arguments = (index_buffer, k_buffer, int(stiffness.size), len(indices))
    t = state.datatype.name
    group.forces.append(
        Op(
            origin,
            [_call(kernel("rest_shape_forces", t), state.f, state.x, state.rest, *arguments)],
        )
    )
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(origin, [_call(kernel("rest_shape_dforces", t), state.df, state.dx, *arguments, Env.KFACT)])
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            _call(kernel("assemble_rest_shape", t), Env.ASSEMBLER, OFFSET, *arguments, Env.KFACT),
        )
    group.energy.append(
        Op(
            origin,
            [_call(kernel("rest_shape_energy", t), state.x, state.rest, *arguments, into=Env.POTENTIAL)],
        )
    )


def lower_plane_force(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """PlaneForceField: a penalty on the points under the plane (stiffness in implicit solves)."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if group.assembled:
        planner.unsupported(
            checked, f"its contact-dependent stiffness is not assembled for {_matrix_solver(group)} yet"
        )
        return
    width = min(state.datatype.spatial_dim, 3)  # the runtime's DT::spatial
    normal = np.zeros(width)
    flat = np.asarray(planner.value(component, "normal"), dtype=float).ravel()[:width]
    normal[: flat.size] = flat
    first, last = (int(v) for v in planner.value(component, "localRange"))
    begin = first if first >= 0 else 0
    end = last + 1 if last >= 0 and last + 1 < state.size else state.size
    bilateral = bool(planner.value(component, "bilateral"))
    contact = planner.buffer(component, "contacts", np.zeros(state.size), "i64", role="scratch")
    normal_buffer = planner.buffer(component, "normal", normal, role="param")
    parameters = {
        name: planner.buffer(component, name, [float(planner.value(component, name))], role="param")
        for name in ("d", "stiffness", "damping", "maxForce")
    }
    origin = origin_of(component)
    t = state.datatype.name
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    kernel("plane_forces", t),
                    state.f,
                    state.x,
                    state.v,
                    contact,
                    normal_buffer,
                    parameters["d"],
                    parameters["stiffness"],
                    parameters["damping"],
                    parameters["maxForce"],
                    bilateral,
                    begin,
                    end,
                )
            ],
        )
    )
    if group.scheme is Scheme.IMPLICIT:
        stiffness = parameters["stiffness"]
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        kernel("plane_dforces", t),
                        state.df,
                        state.dx,
                        contact,
                        normal_buffer,
                        stiffness,
                        Env.KFACT,
                        begin,
                        end,
                    )
                ],
            )
        )
    group.energy.append(
        Op(
            origin,
            [
                _call(
                    kernel("plane_energy", t),
                    state.x,
                    normal_buffer,
                    parameters["d"],
                    parameters["stiffness"],
                    bilateral,
                    begin,
                    end,
                    into=Env.POTENTIAL,
                )
            ],
        )
    )


def lower_triangle_pressure(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """TrianglePressureForceField with useConstantForce: pressure x rest area on the listed triangles."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if not planner.value(component, "useConstantForce"):
        planner.unsupported(
            checked, 'useConstantForce="0" (a Cauchy stress on the current areas) is not compiled yet'
        )
        return
    chosen = _indices(planner, checked, "triangleList", 0, all_if_empty=False)
    triangles = (
        (_topology_cells(planner, checked) or {}).get("triangles", np.zeros(0, np.int64)).reshape(-1, 3)
    )
    points = planner.checked.positions(state.component)
    if len(chosen) and (points is None or chosen.max() >= len(triangles)):
        planner.unsupported(
            checked, f"its triangleList points past the {len(triangles)} triangles of its topology"
        )
        return
    corners = triangles[chosen]
    from sofac.geometry import masses

    areas = masses.triangle_areas(*(points[corners[:, k], :3] for k in range(3)))
    pressure = np.zeros(min(state.datatype.spatial_dim, 3))
    given = planner.value(component, "pressure")
    if given is not None and np.size(given):
        flat = np.asarray(given, dtype=float).ravel()[: pressure.size]
        pressure[: flat.size] = flat
    corner_buffer = planner.buffer(component, "triangles", corners, "i64")
    area_buffer = planner.buffer(component, "areas", areas)
    pressure_buffer = planner.buffer(component, "pressure", pressure, role="param")
    group.forces.append(
        Op(
            origin_of(component),
            [
                _call(
                    kernel("triangle_pressure", state.datatype.name),
                    state.f,
                    corner_buffer,
                    area_buffer,
                    len(corners),
                    pressure_buffer,
                )
            ],
        )
    )


def _edge_pressure_selection(
    planner: Planner, checked: CheckedComponent, edges: np.ndarray, rest: np.ndarray
) -> np.ndarray | None:
    """The edges EdgePressureForceField::init selects, as indices into the topology's edges: the
    last selection it makes wins (the edge list, else edgeIndices, else the plane dmin < x.n <
    dmax on the rest positions). An input edge is the last topology edge with the same two ends in
    the same order (edge 0 when there is none, as SOFA's search leaves it)."""
    component = checked.component
    given = planner.value(component, "edges")
    if given is not None and np.size(given):
        chosen = np.zeros(np.size(given) // 2, dtype=np.int64)
        for i, (a, b) in enumerate(np.asarray(given, dtype=np.int64).reshape(-1, 2).tolist()):
            for j, (c, d) in enumerate(edges.tolist()):
                if a == c and b == d:
                    chosen[i] = j
        return chosen
    listed = planner.value(component, "edgeIndices")
    if listed is not None and np.size(listed):
        chosen = np.asarray(listed, dtype=np.int64).ravel()
        bad = chosen[(chosen < 0) | (chosen >= len(edges))]
        if bad.size:
            planner.diags.add(
                "E218",
                component.attribute_loc("edgeIndices"),
                f"EdgePressureForceField {component.label!r}: edgeIndices contains {int(bad[0])}, but "
                f"its topology has {len(edges)} edges",
            )
            return None
        return chosen
    dmin, dmax = float(planner.value(component, "dmin")), float(planner.value(component, "dmax"))
    if dmin == dmax:
        return np.zeros(0, dtype=np.int64)
    normal = np.asarray(planner.value(component, "normal"), dtype=float)
    d = rest[:, 0] * normal[0] + rest[:, 1] * normal[1] + rest[:, 2] * normal[2]
    inside = (d > dmin) & (d < dmax)
    return np.flatnonzero(inside[edges].all(axis=1)).astype(np.int64)


def _edge_lengths(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """sofa::geometry::Edge::length: sqrt of (p1 - p0).(p1 - p0), summed x, y, z."""
    d = points[edges[:, 1], :3] - points[edges[:, 0], :3]
    return np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])


def lower_edge_pressure(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """EdgePressureForceField: each selected edge pushes both ends with half its force. With a
    non-zero `pressure`, the force is pressure x the edge's rest length. Else, with `binormal` and
    `p_intensity`, it is intensity x the rest length of the topology's edge of the same rank (SOFA
    reads edge i there, not the selected one) along normalize(binormal x edge direction), and SOFA
    recomputes it at the end of each addForce from the positions of that moment (of init at
    first): a step applies the directions of the previous force evaluation."""
    from sofac.geometry.masses import topology_edges

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    cells = _topology_cells(planner, checked)
    if cells is None:
        planner.unsupported(checked, "it needs a topology with edges")
        return
    rest = planner.checked.positions(state.component)
    if rest is None:
        planner.unsupported(checked, "its state's rest positions are not known at compile time")
        return
    if "edges" in cells:
        edges = cells["edges"].reshape(-1, 2)
    else:
        edges = topology_edges(
            len(rest), **{k: cells.get(k) for k in ("triangles", "quads", "tetrahedra", "hexahedra")}
        )
    chosen = _edge_pressure_selection(planner, checked, edges, rest)
    if chosen is None:
        return
    pressure = np.zeros(3)
    given = planner.value(component, "pressure")
    if given is not None and np.size(given):
        pressure[:] = np.asarray(given, dtype=float).ravel()[:3]
    selected = edges[chosen]
    stored_forces = planner.buffer(
        component, "edgeForces", np.zeros((len(chosen), 3)), columns=3, role="state"
    )
    edge_buffer = planner.buffer(component, "edges", selected, "i64", columns=2)
    origin = origin_of(component)
    apply = _call("edge_pressure_forces", state.f, edge_buffer, len(chosen), stored_forces)
    if np.sqrt(pressure @ pressure) > 0:  # SOFA's test: d_pressure.norm() > 0
        lengths = _edge_lengths(rest, selected)
        stored_forces.initial[:] = (pressure[None, :] * lengths[:, None]).ravel()
        group.forces.append(Op(origin, [apply]))
        return
    intensities = planner.value(component, "p_intensity")
    intensities = np.asarray(intensities if intensities is not None else [], dtype=float).ravel()
    if not intensities.size or not _is_set(planner, component, "binormal"):
        if not intensities.size:
            why = "without pressure or p_intensity SOFA applies uninitialised forces"
        else:
            why = "p_intensity without binormal (normals from a triangle topology) is not compiled yet"
        planner.unsupported(checked, why, "p_intensity")
        return
    if not (group.scheme is Scheme.EULER or (group.scheme is Scheme.IMPLICIT and _euler_implicit(group))):
        planner.unsupported(
            checked,
            "with binormal, SOFA updates the forces from the state's positions inside addForce: "
            "compiled under EulerImplicitSolver and explicit Euler only",
            "binormal",
        )
        return
    if len(chosen) > len(edges):
        planner.unsupported(checked, "more selected edges than the topology has (SOFA reads past its edges)")
        return
    binormal = np.asarray(planner.value(component, "binormal"), dtype=float)
    norm = float(np.sqrt(binormal[0] * binormal[0] + binormal[1] * binormal[1] + binormal[2] * binormal[2]))
    if norm > np.finfo(float).eps:  # Vec::normalize
        binormal = binormal / norm
    rank = np.arange(len(chosen))
    per_edge = np.where(
        (intensities.size > 1) & (rank < intensities.size),
        intensities[np.minimum(rank, intensities.size - 1)],
        intensities[0],
    )
    update = _call(
        "edge_pressure_update",
        stored_forces,
        state.x,
        edge_buffer,
        len(chosen),
        planner.buffer(component, "binormal", binormal, role="param"),
        planner.buffer(component, "intensities", per_edge, role="param"),
        planner.buffer(component, "lengths", _edge_lengths(rest, edges[: len(chosen)])),
    )
    group.init.append(Op(origin, [update]))
    group.forces.append(Op(origin, [apply, update]))


def _is_set(planner: Planner, component: Component, name: str) -> bool:
    checked = planner.checked.of(component)
    return name in checked.fields or name in checked.data_links


def _euler_implicit(group: Group) -> bool:
    """An implicit group integrated by EulerImplicitSolver (not Static, Newmark or variational)."""
    return not (group.static or group.newmark or group.variational)
