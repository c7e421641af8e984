"""Lowerings of the mechanical mappings: rigid, subset, barycentric, distance and distance
multi-mappings (x, v down; J, J^T and the geometric stiffness).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import (
    CHILD,
    INPUT_OFFSET,
    OFFSET,
    PARENT,
    Buffer,
    Call,
    Env,
    Group,
    MappingOp,
    Op,
    Slot,
    StatePlan,
    kernel,
    origin_of,
    recorded_once,
)
from sofac.plan.lower.common import (
    _call,
    _indices,
    _mapping_ends,
    _mapping_inputs,
    _to_local,
    _topology_cells,
    _topology_of,
)
from sofac.registry import Variant

if TYPE_CHECKING:
    from sofac.geometry.barycentric import RegularGrid
    from sofac.plan.planner import Planner


def lower_distance_mapping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """DistanceMapping / SquareDistanceMapping (Vec3d -> Vec1d, one DOF per edge), with their
    geometric stiffness in the matrix-free products (SOFA's matrixFreeApplyDJT)."""

    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    if parent.datatype.name != "Vec3d" or child.datatype.name != "Vec1d":
        planner.unsupported(checked, f"{component.type_name} is compiled for Vec3d -> Vec1d only")
        return
    topology = _topology_of(planner, checked)
    edges_value = planner.value(topology, "edges") if topology is not None else None
    if edges_value is None or not np.size(edges_value):
        planner.unsupported(checked, "it needs a topology with edges known at compile time")
        return
    edges = np.asarray(edges_value, dtype=np.int64).reshape(-1, 2)
    count = len(edges)
    if child.size != count:
        planner.unsupported(checked, f"its output state has {child.size} DOFs for {count} edges")
        return
    if not planner.value(component, "applyRestPosition"):
        planner.unsupported(
            checked, "applyRestPosition=false (rest positions left unmapped) is not compiled yet"
        )
        return
    kind = 1 if checked.spec is not None and checked.spec.variant is Variant.SQUARE else 0
    lengths = np.zeros(count)
    if kind == 0:
        given = planner.value(component, "restLengths")
        if given is not None and np.size(given) == count:
            lengths = np.asarray(given, dtype=float).ravel()
        elif not planner.value(component, "computeDistance"):
            points = parent.x.initial.reshape(-1, 3).tolist()
            for i, (a, b) in enumerate(edges.tolist()):
                d = [points[a][k] - points[b][k] for k in range(3)]
                lengths[i] = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    mode = {"None": 0, "Exact": 1, "Stabilized": 2}[str(planner.value(component, "geometricStiffness"))]
    edge_buffer = planner.buffer(component, "edges", edges.ravel(), "i64", columns=2)
    rest = planner.buffer(component, "restLengths", lengths)
    direction = planner.buffer(component, "directions", np.zeros(3 * count), columns=3, role="scratch")
    inverse = planner.buffer(component, "invlengths", np.zeros(count), role="scratch")
    origin = origin_of(component)
    group.init.append(
        Op(
            origin + " [rest positions]",
            [
                _call(
                    "distance_mapping_apply",
                    parent.rest,
                    child.rest,
                    edge_buffer,
                    count,
                    rest,
                    kind,
                    direction,
                    inverse,
                )
            ],
        )
    )
    maps_forces = planner.value(component, "mapForces") is not False
    geometric = None
    if mode and maps_forces:
        geometric = _call(
            "distance_mapping_djt",
            Slot("parent", vector="df"),
            Slot("parent", vector="dx"),
            child.f,
            edge_buffer,
            count,
            direction,
            inverse,
            kind,
            mode,
            Env.KFACT,
        )

    group.mappings.append(
        MappingOp(
            origin,
            parent,
            child,
            [
                _call(
                    "distance_mapping_apply",
                    parent.x,
                    child.x,
                    edge_buffer,
                    count,
                    rest,
                    kind,
                    direction,
                    inverse,
                ),
                _call("distance_mapping_j", parent.v, child.v, edge_buffer, count, direction),
            ],
            _call("distance_mapping_j", PARENT, CHILD, edge_buffer, count, direction),
            _call("distance_mapping_jt", PARENT, CHILD, edge_buffer, count, direction)
            if maps_forces
            else None,
            geometric,
        )
    )


def lower_distance_multi_mapping(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """DistanceMultiMapping (Vec3d -> Vec1d): distances between points of two parent states, each
    edge from a point of the first input to one of the second (geometricStiffness None)."""

    component = checked.component
    inputs = [planner.states.get(id(c)) for c in _mapping_inputs(planner, checked)]
    target = checked.links.get("output")
    child = planner.states.get(id(target)) if isinstance(target, Component) else None
    if len(inputs) != 2 or any(p is None for p in inputs) or child is None:
        planner.unsupported(checked, "it is compiled for two parent MechanicalObjects only")
        return
    first, second = inputs
    assert first is not None and second is not None
    group = owner.get(id(child.component))
    if (
        group is None
        or owner.get(id(first.component)) is not group
        or owner.get(id(second.component)) is not group
    ):
        planner.unsupported(checked, "its parents and output must share one ODE solver")
        return
    if any(s.datatype.name != "Vec3d" for s in (first, second)) or child.datatype.name != "Vec1d":
        planner.unsupported(checked, f"{component.type_name} is compiled for Vec3d -> Vec1d only")
        return
    if str(planner.value(component, "geometricStiffness")) != "None":
        planner.unsupported(checked, "its geometric stiffness is not compiled yet (geometricStiffness=0 is)")
        return
    if not planner.value(component, "applyRestPosition"):
        planner.unsupported(
            checked, "applyRestPosition=false (rest positions left unmapped) is not compiled yet"
        )
        return
    topology = _topology_of(planner, checked)
    edges_value = planner.value(topology, "edges") if topology is not None else None
    pairs_value = planner.value(component, "indexPairs")
    if edges_value is None or not np.size(edges_value) or pairs_value is None:
        planner.unsupported(checked, "it needs edges and indexPairs known at compile time")
        return
    edges = np.asarray(edges_value, dtype=np.int64).reshape(-1, 2)
    pairs = np.asarray(pairs_value, dtype=np.int64).reshape(-1, 2)
    if (
        edges.max() >= len(pairs)
        or not (pairs[edges[:, 0], 0] == 0).all()
        or not (pairs[edges[:, 1], 0] == 1).all()
    ):
        planner.unsupported(
            checked, "only edges from a point of the first input to one of the second are compiled"
        )
        return
    count = len(edges)
    ends_a, ends_b = pairs[edges[:, 0], 1], pairs[edges[:, 1], 1]
    if ends_a.max() >= first.size or ends_b.max() >= second.size or child.size != count:
        planner.unsupported(checked, "its indexPairs or output size do not match the states")
        return
    lengths = np.zeros(count)
    given = planner.value(component, "restLengths")
    if given is not None and np.size(given) == count:
        lengths = np.asarray(given, dtype=float).ravel()
    elif not planner.value(component, "computeDistance"):
        p0, p1 = first.x.initial.reshape(-1, 3).tolist(), second.x.initial.reshape(-1, 3).tolist()
        for i in range(count):
            d = [p0[ends_a[i]][k] - p1[ends_b[i]][k] for k in range(3)]
            lengths[i] = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    a = planner.buffer(component, "endsInFirst", ends_a, "i64")
    b = planner.buffer(component, "endsInSecond", ends_b, "i64")
    rest = planner.buffer(component, "restLengths", lengths)
    direction = planner.buffer(component, "directions", np.zeros(3 * count), columns=3, role="scratch")
    inverse = planner.buffer(component, "invlengths", np.zeros(count), role="scratch")
    origin = origin_of(component)
    table = (a, b, count)
    group.init.append(
        Op(
            origin + " [rest positions]",
            [
                _call(
                    "distance_multi_apply",
                    first.rest,
                    second.rest,
                    child.rest,
                    *table[:2],
                    count,
                    rest,
                    direction,
                    inverse,
                )
            ],
        )
    )

    # The second input's vector of the same kind: Slot("parent", input=1).
    jt = _call("distance_multi_jt", PARENT, Slot("parent", input=1), CHILD, *table, direction)
    j = _call("distance_multi_j", PARENT, Slot("parent", input=1), CHILD, *table, direction)

    maps_forces = planner.value(component, "mapForces") is not False
    group.mappings.append(
        MappingOp(
            origin,
            first,
            child,
            [
                _call(
                    "distance_multi_apply",
                    first.x,
                    second.x,
                    child.x,
                    *table[:2],
                    count,
                    rest,
                    direction,
                    inverse,
                ),
                _call("distance_multi_j", first.v, second.v, child.v, *table, direction),
            ],
            j,
            jt if maps_forces else None,
            inputs=(second,),
        )
    )


def lower_rigid_mapping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    pair = (parent.datatype.name, child.datatype.name)
    if pair not in (("Rigid3d", "Vec3d"), ("Rigid2d", "Vec2d"), ("Rigid3d", "Rigid3d")):
        planner.unsupported(checked, f"RigidMapping {pair[0]},{pair[1]} is not compiled yet")
        return
    frames_out = pair == ("Rigid3d", "Rigid3d")
    if str(planner.value(component, "geometricStiffness")) != "None":
        planner.unsupported(
            checked, "its geometric stiffness is not compiled yet (geometricStiffness=None is)"
        )
        return
    dim = child.datatype.coord_size
    points = planner.checked.positions(child.component)
    points = np.zeros((0, dim)) if points is None else points
    frames = planner.checked.positions(parent.component)
    frames = np.zeros((0, parent.datatype.coord_size)) if frames is None else frames
    per_point = planner.value(component, "rigidIndexPerPoint")
    if per_point is not None and np.size(per_point) == len(points):
        frame_of = np.asarray(per_point, dtype=np.int64).ravel()
    else:
        index = int(planner.value(component, "index") or 0)
        if planner.value(component, "indexFromEnd"):
            index = len(frames) - 1 - index
        frame_of = np.full(len(points), index, dtype=np.int64)
    if len(points) and (frame_of.max() >= len(frames) or frame_of.min() < 0):
        planner.unsupported(checked, "its frame indices are out of range")
        return
    local = np.array(points, dtype=float)
    if planner.value(component, "globalToLocalCoords"):
        if frames_out:  # SOFA's Rigid3 specialisation: centre q^-1 (x - c), orientation q^-1 q_child
            local[:, :3] = _to_local(frames, frame_of, local[:, :3])
            local[:, 3:] = [
                _quat_product(_quat_inverse(frames[f, 3:]), q)
                for f, q in zip(frame_of, local[:, 3:], strict=True)
            ]
        else:
            local = _to_local(frames, frame_of, local)
    local_buffer = planner.buffer(component, "initialPoints", local, columns=dim)
    frame_buffer = planner.buffer(component, "rigidIndexPerPoint", frame_of, "i64")
    offset = planner.buffer(
        component,
        "offsets",
        np.zeros((len(local), 3 if frames_out else dim)),
        columns=3 if frames_out else dim,
        role="scratch",
    )
    prefix = "rigid_frame" if frames_out else "rigid" if dim == 3 else "rigid2"
    n = len(points)
    origin = origin_of(component)
    maps_forces = planner.value(component, "mapForces") is not False
    group.mappings.append(
        MappingOp(
            origin,
            parent,
            child,
            [
                _call(f"{prefix}_apply", parent.x, child.x, local_buffer, frame_buffer, offset, n),
                _call(f"{prefix}_apply_j", parent.v, child.v, frame_buffer, offset, n),
            ],
            _call(f"{prefix}_apply_j", PARENT, CHILD, frame_buffer, offset, n),
            _call(f"{prefix}_apply_jt", PARENT, CHILD, frame_buffer, offset, n) if maps_forces else None,
            # J depends on the rotated offsets of this step's apply: refilled every assembly.
            assembly=[
                _call(f"{prefix}_jacobian", Env.ASSEMBLER, OFFSET, INPUT_OFFSET, frame_buffer, offset, n)
            ],
        )
    )


def _quat_product(p: np.ndarray, q: np.ndarray) -> list[float]:
    """SOFA's Quat operator* (x y z w), term by term."""
    return [
        p[3] * q[0] + p[0] * q[3] + p[1] * q[2] - p[2] * q[1],
        p[3] * q[1] + p[1] * q[3] + p[2] * q[0] - p[0] * q[2],
        p[3] * q[2] + p[2] * q[3] + p[0] * q[1] - p[1] * q[0],
        p[3] * q[3] - (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]),
    ]


def _quat_inverse(q: np.ndarray) -> np.ndarray:
    """SOFA's Quat::inverse: the conjugate over the norm."""
    norm = float(np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    if norm == 0.0:
        return np.zeros(4)
    inverse = 1.0 / norm
    return np.array([-q[0] * inverse, -q[1] * inverse, -q[2] * inverse, q[3] * inverse])


def lower_subset_mapping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    identity = bool(checked.spec and checked.spec.lowering == "identity_mapping")
    if parent.datatype is not child.datatype:
        if identity:
            _lower_leading_identity(planner, checked, parent, child, group)
        else:
            planner.unsupported(
                checked, f"{component.type_name} between different templates is not compiled yet"
            )
        return
    if identity:
        indices = np.arange(parent.size, dtype=np.int64)
    else:
        indices = _indices(planner, checked, "indices", 0, all_if_empty=False)
        first, last = planner.value(component, "first"), planner.value(component, "last")
        if not indices.size and first is not None:
            stop = int(last) if last is not None and int(last) >= 0 else parent.size - 1
            indices = np.arange(int(first), stop + 1, dtype=np.int64)
    if indices.size != child.size:
        planner.unsupported(checked, f"it maps {indices.size} DOFs onto a state of {child.size}")
        return
    buffer = planner.buffer(component, "indices", indices, "i64")
    t, n = parent.datatype.name, indices.size
    coord, deriv = parent.datatype.coord_size, parent.datatype.deriv_size
    origin = origin_of(component)
    maps_forces = planner.value(component, "mapForces") is not False
    group.mappings.append(
        MappingOp(
            origin,
            parent,
            child,
            [
                _call(kernel("subset_apply", t), parent.x, child.x, buffer, n, coord),
                _call(kernel("subset_apply", t), parent.v, child.v, buffer, n, deriv),
            ],
            _call(kernel("subset_apply", t), PARENT, CHILD, buffer, n, deriv),
            _call(kernel("subset_apply_jt", t), PARENT, CHILD, buffer, n) if maps_forces else None,
            # a constant selection: recorded once
            assembly=[
                recorded_once(
                    _call(kernel("subset_jacobian", t), Env.ASSEMBLER, OFFSET, INPUT_OFFSET, buffer, n)
                )
            ],
        )
    )


def _lower_leading_identity(
    planner: Planner, checked: CheckedComponent, parent: StatePlan, child: StatePlan, group: Group
) -> None:
    """IdentityMapping from a larger type (Rigid3d -> Vec3d, Rigid2d -> Vec2d, Vec6d -> Vec3d): SOFA's
    core::eq / peq keep the leading numbers (a rigid body's centre and linear velocity; J^T adds the
    force, no torque)."""
    component = checked.component
    n = parent.size
    if child.size != n:
        planner.unsupported(checked, f"it maps {n} DOFs onto a state of {child.size}")
        return
    p, c = parent.datatype, child.datatype
    if c.coord_size > p.coord_size or c.deriv_size > p.deriv_size:
        planner.unsupported(checked, f"IdentityMapping {p.name} -> {c.name} is not compiled yet")
        return
    maps_forces = planner.value(component, "mapForces") is not False
    group.mappings.append(
        MappingOp(
            origin_of(component),
            parent,
            child,
            [
                _call("leading_apply", parent.x, child.x, n, p.coord_size, c.coord_size),
                _call("leading_apply", parent.v, child.v, n, p.deriv_size, c.deriv_size),
            ],
            _call("leading_apply", PARENT, CHILD, n, p.deriv_size, c.deriv_size),
            _call("leading_apply_jt", PARENT, CHILD, n, p.deriv_size, c.deriv_size) if maps_forces else None,
            assembly=[
                recorded_once(
                    _call(
                        "leading_jacobian", Env.ASSEMBLER, OFFSET, INPUT_OFFSET, n, p.deriv_size, c.deriv_size
                    )
                )
            ],
        )
    )


@dataclass(frozen=True, eq=False)
class _Ramified:
    """What a SparseGridRamificationTopology's findCube reads: its grid, the finest (virtual) grid
    and each finest cube's hexahedron."""

    coarse: RegularGrid
    finest: RegularGrid
    table: np.ndarray


def _ramified_grid(planner: Planner, topology: Component) -> _Ramified:
    from sofac.geometry.barycentric import RegularGrid

    def grid(prefix: str) -> RegularGrid:
        resolution = np.asarray(planner.value(topology, f"{prefix}grid_resolution"), dtype=np.int64)
        bounds = np.asarray(planner.value(topology, f"{prefix}grid_bounds"), dtype=float)
        nx, ny, nz = (int(c) for c in resolution)
        low = (float(bounds[0]), float(bounds[1]), float(bounds[2]))
        high = (float(bounds[3]), float(bounds[4]), float(bounds[5]))
        return RegularGrid((nx, ny, nz), low, high)

    table = np.asarray(planner.value(topology, "finest_to_hexa"), dtype=np.int64)
    return _Ramified(grid(""), grid("finest_"), table)


def lower_barycentric_mapping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from sofac.geometry.barycentric import RegularGrid, SparseGrid, embed_cells, mapper_for, ramified_grid_map

    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    if parent.datatype.name != "Vec3d" or child.datatype.name != "Vec3d":
        planner.unsupported(checked, "BarycentricMapping other than Vec3d,Vec3d is not compiled yet")
        return
    # The input's topology: input_topology when given, else the one in the input state's context.
    given = checked.links.get("input_topology")
    probe = CheckedComponent(
        parent.component, None, links={"topology": given} if isinstance(given, Component) else {}
    )
    cells = _topology_cells(planner, probe, sparse_grid_ok=True) or {}
    # The input topology's class decides which of SOFA's mappers embeds the points.
    topology = _topology_of(planner, probe)
    topology_spec = planner.checked.of(topology).spec if topology is not None else None
    mode = mapper_for(topology_spec.variant if topology_spec else None)
    grid = None
    if mode == "regular_grid" and topology is not None:
        bounds = np.asarray(planner.value(topology, "bounds"), dtype=float)
        p0 = planner.value(topology, "p0") if topology.get("p0") is not None else None
        grid = RegularGrid(
            tuple(int(c) for c in cells["resolution"]),
            tuple(bounds[:3]),
            tuple(bounds[3:]),
            p0=tuple(float(c) for c in np.ravel(p0)) if p0 is not None else None,
        )
    elif (
        mode == "sparse_grid"
        and topology is not None
        and planner.value(topology, "finest_to_hexa") is not None
    ):
        grid = _ramified_grid(planner, topology)
    elif mode == "sparse_grid" and topology is not None:
        table = planner.value(topology, "regular_to_sparse")
        if table is None or "hexahedra" not in cells:
            planner.unsupported(checked, "its SparseGridTopology's cells are not known at compile time")
            return
        resolution = np.asarray(planner.value(topology, "grid_resolution"), dtype=np.int64)
        bounds = np.asarray(planner.value(topology, "grid_bounds"), dtype=float)
        grid = SparseGrid(
            RegularGrid(tuple(int(c) for c in resolution), tuple(bounds[:3]), tuple(bounds[3:])),
            np.asarray(planner.value(topology, "position"), dtype=float).reshape(-1, 3),
            cells["hexahedra"].reshape(-1, 8),
            np.asarray(table, dtype=np.int64),
            np.asarray(planner.value(topology, "boundary_cells"), dtype=bool),
        )
    rest = planner.checked.positions(parent.component)
    points = planner.checked.positions(child.component)
    if rest is None or points is None:
        planner.unsupported(checked, "its input or output positions are not known at compile time")
        return
    nodes = None
    try:
        if isinstance(grid, _Ramified):
            indices, weights = ramified_grid_map(
                grid.coarse, grid.finest, grid.table, cells["hexahedra"], points
            )
        else:
            embedding = embed_cells(rest, points, cells, mode=mode, grid=grid)
            indices, weights, nodes = embedding.indices, embedding.weights, embedding.nodes
    except ValueError as error:
        planner.unsupported(checked, f"it cannot embed its points: {error}")
        return
    n, k = indices.shape
    index_buffer = planner.buffer(component, "indices", indices, "i64", columns=k)
    weight_buffer = planner.buffer(component, "weights", weights, columns=k)
    maps_forces = planner.value(component, "mapForces") is not False

    def jacobian(up: Buffer | Slot, down: Buffer | Slot) -> Call:
        return _call("linear_map_apply", up, down, index_buffer, weight_buffer, n, k, 3)

    group.mappings.append(
        MappingOp(
            origin_of(component),
            parent,
            child,
            [jacobian(parent.x, child.x), jacobian(parent.v, child.v)],
            jacobian(PARENT, CHILD),
            _call("linear_map_apply_jt", PARENT, CHILD, index_buffer, weight_buffer, n, k, 3)
            if maps_forces
            else None,
            # constant weights: recorded once
            assembly=[
                recorded_once(
                    _call(
                        "linear_jacobian",
                        Env.ASSEMBLER,
                        OFFSET,
                        INPUT_OFFSET,
                        index_buffer,
                        weight_buffer,
                        n,
                        k,
                        3,
                    )
                )
            ],
            element_nodes=planner.buffer(component, "element_nodes", nodes, "i64")
            if nodes is not None
            else None,
        )
    )
