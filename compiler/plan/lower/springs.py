"""Lowerings of the spring force fields: springs between states, grid and mesh springs, bending
springs.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import (
    OFFSET,
    Aggregate,
    Env,
    Group,
    Op,
    Scheme,
    StatePlan,
    origin_of,
)
from sofac.plan.lower.common import (
    _add_springs,
    _assemble,
    _call,
    _rayleigh_refused,
    _springs_from_fields,
    _target,
    _topology_cells,
    _topology_of,
    _triangle_target,
    _vec3_target,
)

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def lower_triangular_bending_springs(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """TriangularBendingSprings: per edge shared by two triangles, a spring between the two vertices
    opposite it (m1 in the later triangle, m2 in the first one, as SOFA's applyTriangleCreation),
    in the topology's edge order; rest length from the rest positions."""

    from sofac.geometry import masses

    found = _triangle_target(planner, checked, owner)
    if found is None:
        return
    state, group, cells = found
    component = checked.component
    triangles = cells["triangles"]
    rest = planner.checked.positions(state.component)
    edges = cells.get("edges")
    if edges is None or not edges.size:
        edges = masses.topology_edges(state.size, triangles=triangles)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3).tolist()
    around: dict[tuple[int, int], list[int]] = {}
    for index, tri in enumerate(tris):
        for j in range(3):
            u, v = tri[(j + 1) % 3], tri[(j + 2) % 3]
            around.setdefault((min(u, v), max(u, v)), []).append(index)
    ks, kd = float(planner.value(component, "stiffness")), float(planner.value(component, "damping"))
    points = [tuple(float(v) for v in row[:3]) for row in np.asarray(rest, dtype=float)]
    pairs: list[tuple[int, int]] = []
    params: list[tuple[float, float, float]] = []
    for e1, e2 in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist():
        shell = around.get((min(e1, e2), max(e1, e2)), [])
        if len(shell) != 2:
            continue
        first, later = sorted(shell)
        m2 = next(v for v in tris[first] if v not in (e1, e2))
        m1 = next(v for v in tris[later] if v not in (e1, e2))
        d = [points[m1][k] - points[m2][k] for k in range(3)]
        pairs.append((m1, m2))
        params.append((ks, kd, math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])))
    kernels = ("triangular_bending_add_force", "triangular_bending_add_dforce", "triangular_bending_energy")
    _place_bending_springs(planner, checked, group, state, pairs, params, kernels)


def _place_bending_springs(
    planner: Planner,
    checked: CheckedComponent,
    group: Group,
    state: StatePlan,
    pairs: list[tuple[int, int]],
    params: list[tuple[float, float, float]],
    kernels: tuple[str, str, str | None],
) -> None:
    """The spring table (ends, then ks, kd, rest length per spring) of a bending-spring field as
    buffers, and its calls (shell.h): ``kernels`` = (the force, which leaves each spring's df/dx in
    a scratch buffer; K dx from those; the potential energy, or None), then the assembled blocks."""
    add_force, add_dforce, energy = kernels
    component = checked.component
    count = len(pairs)
    springs = planner.buffer(
        component, "springs", np.asarray(pairs, dtype=np.int64).reshape(-1), "i64", columns=2
    )
    values = planner.buffer(component, "springParams", np.asarray(params, dtype=float).reshape(-1), columns=3)
    dfdx = planner.buffer(component, "dfdx", np.zeros(9 * count), columns=9, role="scratch")
    origin = origin_of(component)
    group.forces.append(
        Op(origin, [_call(add_force, springs, values, count, state.x, state.v, state.f, dfdx)])
    )
    if energy is not None:
        group.energy.append(Op(origin, [_call(energy, springs, values, count, state.x, into=Env.POTENTIAL)]))
    if group.scheme is not Scheme.IMPLICIT:
        return
    group.stiffness_dx.append(
        Op(origin, [_call(add_dforce, springs, count, dfdx, state.dx, state.df, Env.KFACT)])
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        _call("assemble_triangular_bending", Env.ASSEMBLER, OFFSET, springs, count, dfdx, Env.KFACT),
    )


def lower_quad_bending_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """QuadBendingSprings: a spring between the opposite corners of two quads sharing an edge
    (SOFA's registerEdge / addSpring order, each pair once), rest length from the positions."""

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    quads = (_topology_cells(planner, checked) or {}).get("quads")
    rest = planner.checked.positions(state.component)
    if quads is None or not quads.size or rest is None:
        planner.unsupported(checked, "it needs quads known at compile time")
        return
    stiffness = np.atleast_1d(np.asarray(planner.value(component, "stiffness"), dtype=float))
    damping = np.atleast_1d(np.asarray(planner.value(component, "damping"), dtype=float))
    ks, kd = float(stiffness[0]), float(damping[0])
    low, high = (
        int(v) for v in np.asarray(planner.value(component, "localRange"), dtype=np.int64).ravel()[:2]
    )
    points = [tuple(float(v) for v in row[:3]) for row in np.asarray(rest, dtype=float)]
    rows = [tuple(float(v) for v in row) for row in _springs_from_fields(planner, checked)]
    edges: dict[tuple[int, int], tuple[int, int]] = {}
    springs: set[tuple[int, int]] = set()

    def add(a: int, b: int) -> None:
        if low >= 0 and a < low and b < low:
            return
        if high >= 0 and a > high and b > high:
            return
        key = (min(a, b), max(a, b))
        if key in springs:
            return
        springs.add(key)
        d = [points[a][k] - points[b][k] for k in range(3)]
        rows.append((a, b, ks, kd, math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])))

    def register(ab: tuple[int, int], cd: tuple[int, int]) -> None:
        if ab[0] > ab[1]:
            ab, cd = (ab[1], ab[0]), (cd[1], cd[0])
        if ab not in edges:
            edges[ab] = cd
        else:
            ef = edges[ab]
            add(cd[0], ef[0])
            add(cd[1], ef[1])

    for q in np.asarray(quads, dtype=np.int64).reshape(-1, 4).tolist():
        register((q[0], q[1]), (q[3], q[2]))
        register((q[1], q[2]), (q[0], q[3]))
        register((q[2], q[3]), (q[1], q[0]))
        register((q[3], q[0]), (q[2], q[1]))
    _add_springs(planner, checked, np.array(rows, dtype=float).reshape(-1, 5), state, state, group)


def quadular_springs(quads: np.ndarray, edges: np.ndarray, n_points: int) -> list[tuple[int, int]]:
    """QuadularBendingSprings' spring ends, in SOFA's order: for each edge (the topology's order)
    shared by exactly two quads, t2 the first quad listing it (the one whose creation initialises
    it) and t1 the other, i1 and i2 the edge's place in each (edge j of a quad is (q[j+1], q[j+2])):
    (t1[i1], t2[i2+3]) then (t1[i1+3], t2[i2]), indices mod 4."""
    from sofac.geometry import masses

    quads = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    edges_in_quad = masses.element_edge_indices("quads", quads, edges, n_points).tolist()
    around: dict[int, list[int]] = {}
    for index, in_quad in enumerate(edges_in_quad):
        for edge in in_quad:
            around.setdefault(edge, []).append(index)
    ends: dict[int, tuple[tuple[int, int], tuple[int, int]]] = {}
    initialised: set[int] = set()
    rows = quads.tolist()
    for index, in_quad in enumerate(edges_in_quad):
        for edge in in_quad:
            if edge in initialised:
                continue
            initialised.add(edge)
            shell = around[edge]
            if len(shell) != 2:
                continue
            other = shell[1] if shell[0] == index else shell[0]
            t1, t2 = rows[other], rows[index]
            i1, i2 = edges_in_quad[other].index(edge), in_quad.index(edge)
            ends[edge] = ((t1[i1], t2[(i2 + 3) % 4]), (t1[(i1 + 3) % 4], t2[i2]))
    return [pair for edge in sorted(ends) for pair in ends[edge]]


def lower_quadular_bending_springs(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """QuadularBendingSprings: two springs across each edge between two quads (quadular_springs),
    uniform stiffness and damping, rest lengths from the rest positions (runtime shell.h)."""
    from sofac.geometry import masses

    found = _vec3_target(planner, checked, owner)
    if found is None or _rayleigh_refused(planner, checked):
        return
    state, group, cells = found
    component = checked.component
    quads = cells.get("quads")
    rest = planner.checked.positions(state.component)
    if quads is None or not quads.size or rest is None:
        planner.unsupported(checked, "it needs quads known at compile time")
        return
    edges = cells.get("edges")
    if edges is None or not edges.size:
        edges = masses.topology_edges(state.size, quads=quads)
    try:
        pairs = quadular_springs(quads, np.asarray(edges).reshape(-1, 2), state.size)
    except ValueError as error:
        planner.unsupported(checked, str(error))
        return
    ks, kd = float(planner.value(component, "stiffness")), float(planner.value(component, "damping"))
    points = np.asarray(rest, dtype=float)
    params = [(ks, kd, float(np.sqrt(np.sum((points[a] - points[b]) ** 2)))) for a, b in pairs]
    kernels = ("quadular_bending_add_force", "quadular_bending_add_dforce", None)  # SOFA gives it no energy
    _place_bending_springs(planner, checked, group, state, pairs, params, kernels)


def lower_bending_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FastTriangularBendingSprings: one linear bending spring per edge between two triangles."""
    from sofac.geometry import bending, masses

    found = _triangle_target(planner, checked, owner)
    if found is None:
        return
    state, group, cells = found
    component = checked.component
    triangles = cells["triangles"]
    edges = cells.get("edges")
    if edges is None or not edges.size:
        edges = masses.topology_edges(state.size, triangles=triangles, quads=cells.get("quads"))
    stiffness = planner.value(component, "bendingStiffness")
    min_dist = planner.value(component, "minDistValidity")
    vid, alpha, lam = bending.bending_springs(
        planner.checked.positions(state.component),
        triangles,
        edges,
        1.0 if stiffness is None else float(stiffness),
        1e-6 if min_dist is None else float(min_dist),
    )
    count = len(lam)
    table = (
        planner.buffer(component, "vid", vid.ravel(), "i64", columns=4),
        planner.buffer(component, "alpha", alpha.ravel(), columns=4),
        planner.buffer(component, "lambda", lam),
        count,
    )
    origin = origin_of(component)
    group.forces.append(Op(origin, [_call("bending_springs_add_force", *table, state.x, state.f)]))
    group.energy.append(Op(origin, [_call("bending_springs_energy", *table, state.x, into=Env.POTENTIAL)]))
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(origin, [_call("bending_springs_add_dforce", *table, state.dx, state.df, Env.KFACT)])
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            _call("assemble_bending_springs", Env.ASSEMBLER, OFFSET, *table, Env.KFACT),
        )


def lower_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        if not isinstance(target, Component):
            target = checked.state or planner.checked.node_state(checked.component.node)
        ends.append(planner.states.get(id(target)) if target is not None else None)
    if ends[0] is None or ends[1] is None:
        planner.unsupported(checked, "a spring force field must join MechanicalObjects")
        return
    groups = {id(owner.get(id(e.component))) for e in ends}
    group = owner.get(id(ends[0].component))
    if group is None or len(groups) != 1:
        if group is None and owner.get(id(ends[1].component)) is None:
            planner.ignored.append((checked.component, "its states have no ODE solver"))
            return
        planner.unsupported(checked, "springs between states of different ODE solvers are not compiled yet")
        return
    if ends[0].datatype.coord_size not in (1, 2, 3, 7) or ends[1].datatype.coord_size not in (1, 2, 3, 7):
        planner.unsupported(checked, "springs on this template are not compiled yet")
        return
    springs = _springs_from_fields(planner, checked)
    _add_springs(planner, checked, springs, ends[0], ends[1], group)


def lower_grid_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """RegularGridSpringForceField: its own springs, then springs along the grid's edges, face
    diagonals and cube diagonals, in SOFA's loop order, ks = stiffness / rest length."""

    from sofac.geometry.barycentric import RegularGrid

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    topology = _topology_of(planner, checked)
    cells = _topology_cells(planner, checked) or {}
    if topology is None or "resolution" not in cells:
        planner.unsupported(checked, "it needs a RegularGridTopology in its node")
        return
    bounds = np.asarray(planner.value(topology, "bounds"), dtype=float)
    nx, ny, nz = (int(c) for c in cells["resolution"])
    _, step = RegularGrid((nx, ny, nz), tuple(bounds[:3]), tuple(bounds[3:])).frame()
    dx, dy, dz = (np.array([step[a] if a == axis else 0.0 for a in range(3)]) for axis in range(3))

    def norm(v: np.ndarray) -> float:
        return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])

    def coefficient(kind: str, name: str) -> float:
        both = planner.value(component, name.lower())  # `stiffness` / `damping` set all three
        return float(both if both is not None else planner.value(component, f"{kind}{name}") or 0.0)

    def point(x: int, y: int, z: int) -> int:
        return x + nx * (y + ny * z)

    rows = [tuple(r) for r in _springs_from_fields(planner, checked)]

    def add(kind: str, pairs: list[tuple[tuple[int, int], float, float | None]]) -> None:
        ks, kd = coefficient(kind, "Stiffness"), coefficient(kind, "Damping")
        if ks == 0.0 and kd == 0.0:
            return
        for (a, b), length, scale_length in pairs:
            divisor = scale_length if scale_length is not None else length
            rows.append((a, b, ks / divisor, kd / divisor, length))

    lines = []
    for axis, delta, size in (
        (0, dx, (nx - 1, ny, nz)),
        (1, dy, (nx, ny - 1, nz)),
        (2, dz, (nx, ny, nz - 1)),
    ):
        length = norm(delta)
        for z in range(size[2]):
            for y in range(size[1]):
                for x in range(size[0]):
                    offset = [(1, 0, 0), (0, 1, 0), (0, 0, 1)][axis]
                    lines.append(
                        ((point(x, y, z), point(x + offset[0], y + offset[1], z + offset[2])), length, None)
                    )
    add("lines", lines)
    quads = []
    for u, v, size, (o1, o2, o3, o4) in (
        (dx, dy, (nx - 1, ny - 1, nz), ((0, 0, 0), (1, 1, 0), (1, 0, 0), (0, 1, 0))),
        (dx, dz, (nx - 1, ny, nz - 1), ((0, 0, 0), (1, 0, 1), (1, 0, 0), (0, 0, 1))),
        (dy, dz, (nx, ny - 1, nz - 1), ((0, 0, 0), (0, 1, 1), (0, 1, 0), (0, 0, 1))),
    ):
        first, second = norm(u + v), norm(u - v)
        # SOFA divides the second YZ diagonal's stiffness by the first's length (kept as is).
        second_scale = first if u is dy else None
        for z in range(size[2]):
            for y in range(size[1]):
                for x in range(size[0]):
                    corner = [(x + o[0], y + o[1], z + o[2]) for o in (o1, o2, o3, o4)]
                    quads.append(((point(*corner[0]), point(*corner[1])), first, None))
                    quads.append(((point(*corner[2]), point(*corner[3])), second, second_scale))
    add("quads", quads)
    cubes = []
    diagonals = (
        ((0, 0, 0), (1, 1, 1), norm(dx + dy + dz)),
        ((1, 0, 0), (0, 1, 1), norm(-dx + dy + dz)),
        ((0, 1, 0), (1, 0, 1), norm(dx - dy + dz)),
        ((0, 0, 1), (1, 1, 0), norm(dx + dy - dz)),
    )
    for z in range(nz - 1):
        for y in range(ny - 1):
            for x in range(nx - 1):
                for a, b, length in diagonals:
                    ends = (point(x + a[0], y + a[1], z + a[2]), point(x + b[0], y + b[1], z + b[2]))
                    cubes.append((ends, length, None))
    add("cubes", cubes)
    springs = np.array(rows, dtype=float).reshape(-1, 5)
    _add_springs(planner, checked, springs, state, state, group)


# MeshSpringForceField: (topology field, corners per element, stiffness/damping prefix), in the
# order SOFA adds them; a vertex pair gets one spring, from the first element kind that has it.
_MESH_ELEMENTS = (
    ("edges", 2, "lines"),
    ("triangles", 3, "triangles"),
    ("quads", 4, "quads"),
    ("tetrahedra", 4, "tetrahedra"),
    ("hexahedra", 8, "cubes"),
)


def lower_mesh_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    topology = checked.links.get("topology")
    if not isinstance(topology, Component):
        topology = planner.checked.context_singleton(component.node, "topology")
    rest = planner.checked.positions(state.component)
    if topology is None or rest is None:
        planner.unsupported(checked, "it needs a topology whose elements are known at compile time")
        return
    both_k, both_d = planner.value(component, "stiffness"), planner.value(component, "damping")
    seen: set[tuple[int, int]] = set()
    rows: list[tuple[int, int, float, float, float]] = []
    for field_name, corners, prefix in _MESH_ELEMENTS:
        elements = planner.value(topology, field_name)
        if elements is None or not np.size(elements):
            continue
        ks = float(both_k if both_k is not None else planner.value(component, f"{prefix}Stiffness") or 0.0)
        kd = float(both_d if both_d is not None else planner.value(component, f"{prefix}Damping") or 0.0)
        if ks == 0.0 and kd == 0.0:  # SOFA skips the kind: its pairs stay free for the next kinds
            continue
        # SOFA's order: every corner pair (p, q), p < q (a hexahedron's 28, a SparseGridTopology's
        # only elements: it derives no edges or quads)
        pairs = [(p, q) for p in range(corners) for q in range(p + 1, corners)]
        cells = np.asarray(elements, dtype=np.int64).reshape(-1, corners)
        if cells.size and int(cells.max()) >= len(rest):
            planner.diags.add(
                "E218",
                component.loc,
                f"{origin_of(component)}: its topology's {field_name} use point {int(cells.max())}, but "
                f"{state.path} has {len(rest)} points",
                "give the state the topology's points (or none, to take them from the topology)",
            )
            return
        for element in cells:
            for a, b in pairs:
                i, j = sorted((int(element[a]), int(element[b])))
                if (i, j) in seen or i == j:
                    continue
                seen.add((i, j))
                # Vec3::norm() term by term: np.linalg.norm goes through BLAS, whose kernel (and
                # its use of FMA) depends on the processor
                square = 0.0
                for k in range(min(3, rest.shape[1])):
                    d = float(rest[j, k]) - float(rest[i, k])
                    square += d * d
                length = math.sqrt(square)
                if length > 1e-12:  # SOFA scales by the rest length (per unit length stiffness)
                    rows.append((i, j, ks / length, kd / length, length))
    springs = np.array(rows, dtype=float).reshape(-1, 5)
    _add_springs(planner, checked, springs, state, state, group)


def lower_vector_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """VectorSpringForceField as SOFA's bwdInit builds it: with useTopology, one spring per edge
    (i, j) of the topology with rest vector x0[j] - x0[i] (object1's rest positions), else one per
    point i of object1 joining object1[i] and object2[i] with a zero rest vector."""
    component = checked.component
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        if not isinstance(target, Component):
            target = checked.state or planner.checked.node_state(component.node)
        ends.append(planner.states.get(id(target)) if target is not None else None)
    first, second = ends
    if first is None or second is None:
        planner.unsupported(checked, "its springs must join MechanicalObjects")
        return
    group = owner.get(id(first.component))
    if group is None and owner.get(id(second.component)) is None:
        planner.ignored.append((component, "its states have no ODE solver"))
        return
    if group is None or owner.get(id(second.component)) is not group:
        planner.unsupported(checked, "springs between states of different ODE solvers are not compiled yet")
        return
    if planner.value(component, "springs"):
        # SOFA's bwdInit makes its edges only for the default springs (none given): with a `springs`
        # list its edge array stays empty and addForce / addDForce loop over no spring.
        planner.diags.add(
            "W225",
            component.attribute_loc("springs"),
            f"{origin_of(component)}: SOFA applies no spring when `springs` is given (its bwdInit "
            "builds the springs' ends only for the default springs)",
            "remove `springs` to get SOFA's default springs (stiffness, viscosity, useTopology)",
        )
        planner.ignored.append((component, "its `springs` list is given: SOFA applies no force then"))
        return
    if planner.value(component, "filename"):
        planner.unsupported(checked, "springs given by filename are not compiled yet")
        return
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a rayleighStiffness of its own is not compiled yet")
        return
    if bool(planner.value(component, "useTopology")):
        topology = checked.links.get("topology")
        if not isinstance(topology, Component):
            topology = _topology_of(planner, checked)
        edges = planner.value(topology, "edges") if topology is not None else None
        rest = planner.checked.positions(first.component)
        if edges is None or not np.size(edges) or rest is None:
            planner.unsupported(
                checked, "with useTopology it needs a topology whose edges are known at compile time"
            )
            return
        pairs = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        rest = np.asarray(rest, dtype=float).reshape(-1, 3)
        vectors = rest[pairs[:, 1]] - rest[pairs[:, 0]]
    else:
        pairs = np.repeat(np.arange(first.size, dtype=np.int64)[:, None], 2, axis=1)
        vectors = np.zeros((first.size, 3))
    if len(pairs) and (pairs[:, 0].max() >= first.size or pairs[:, 1].max() >= second.size):
        planner.unsupported(checked, "its springs use points past the end of object1 or object2")
        return
    ends_1 = planner.buffer(component, "indices1", pairs[:, 0].copy(), "i64")
    ends_2 = planner.buffer(component, "indices2", pairs[:, 1].copy(), "i64")
    rest_buffer = planner.buffer(component, "restVector", vectors, columns=3)
    ks = planner.buffer(component, "stiffness", [float(planner.value(component, "stiffness"))], role="param")
    kd = planner.buffer(component, "viscosity", [float(planner.value(component, "viscosity"))], role="param")
    table = Aggregate("VectorSprings", (ends_1, ends_2, rest_buffer, ks, kd, len(pairs)))
    origin = origin_of(component)
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    "vector_spring_forces",
                    table,
                    first.x,
                    first.v,
                    first.f,
                    second.x,
                    second.v,
                    second.f,
                )
            ],
        )
    )
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(
                origin,
                [_call("vector_spring_dforces", table, first.dx, first.df, second.dx, second.df, Env.KFACT)],
            )
        )
        if group.direct or group.assembled_cg:
            offsets = (group.assembly_offset(first, checked), group.assembly_offset(second, checked))
            group.assemble.append(
                Op(origin, [_call("assemble_vector_springs", Env.ASSEMBLER, table, *offsets, Env.KFACT)])
            )


def lower_joint_springs(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """JointSpringForceField (Rigid3d): the `spring` rows as JointSprings.parse reads them (SOFA's
    stream format); per spring a rest offset (7 numbers, taken from the positions at the first force
    pass when REST_T was given, as SOFA's bwdInit) and the force pass's frame and stiffnesses for K dx
    and the assembled blocks (runtime/sofac/joint_springs.h)."""
    from sofac.registry.fields import JOINT_SPRING_COLUMNS

    component = checked.component
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        if not isinstance(target, Component):
            target = checked.state or planner.checked.node_state(component.node)
        ends.append(planner.states.get(id(target)) if target is not None else None)
    first, second = ends
    if first is None or second is None:
        planner.unsupported(checked, "its springs must join MechanicalObjects")
        return
    if first.datatype.name != "Rigid3d" or second.datatype.name != "Rigid3d":
        planner.unsupported(checked, "it joins Rigid3d states only")
        return
    group = owner.get(id(first.component))
    if group is None and owner.get(id(second.component)) is None:
        planner.ignored.append((component, "its states have no ODE solver"))
        return
    if group is None or owner.get(id(second.component)) is not group:
        planner.unsupported(checked, "springs between states of different ODE solvers are not compiled yet")
        return
    if planner.value(component, "infile"):
        planner.unsupported(checked, "constant joint forces read from infile are not compiled yet")
        return
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a rayleighStiffness of its own is not compiled yet")
        return
    if planner.value(component, "outfile"):
        attribute = "outfile"
        planner.diags.add(
            "W225",
            component.attribute_loc(attribute),
            f"{origin_of(component)}: sofac does not write JointSpringForceField's output file",
            "read the rigid states from Python (sim[path].position) instead",
        )
    value = planner.value(component, "spring")
    width = len(JOINT_SPRING_COLUMNS)
    rows = np.asarray(value if value is not None else np.zeros((0, width)), dtype=float).reshape(-1, width)
    if not len(rows):
        planner.ignored.append((component, "it has no springs"))
        return
    pairs = rows[:, :2].astype(np.int64)
    if pairs[:, 0].max() >= first.size or pairs[:, 1].max() >= second.size:
        planner.unsupported(checked, "its springs use DOFs past the end of object1 or object2")
        return
    params = rows[:, 2:20]  # free[6], ksT, khT, ksR, khR, kBloc, kd, limits[6] (JOINT_PARAMS)
    rest = rows[:, 20:27]
    pending = rows[:, 27].astype(np.int64)
    a = planner.buffer(component, "indices1", pairs[:, 0].copy(), "i64")
    b = planner.buffer(component, "indices2", pairs[:, 1].copy(), "i64")
    parameters = planner.buffer(component, "spring", params, columns=params.shape[1])
    rest_buffer = planner.buffer(component, "rest", rest, columns=7, role="scratch")
    pending_buffer = planner.buffer(component, "pending", pending, "i64", role="scratch")
    memory = planner.buffer(component, "memory", np.zeros((len(rows), 10)), columns=10, role="scratch")
    table = Aggregate("JointSprings", (a, b, parameters, rest_buffer, pending_buffer, memory, len(rows)))
    origin = origin_of(component)
    group.forces.append(
        Op(
            origin,
            [_call("joint_spring_forces", table, first.x, first.v, first.f, second.x, second.v, second.f)],
        )
    )
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(
                origin,
                [_call("joint_spring_dforces", table, first.dx, first.df, second.dx, second.df, Env.KFACT)],
            )
        )
        if group.direct or group.assembled_cg:
            offsets = (group.assembly_offset(first, checked), group.assembly_offset(second, checked))
            group.assemble.append(
                Op(origin, [_call("assemble_joint_springs", Env.ASSEMBLER, table, *offsets, Env.KFACT)])
            )
