"""What lowerings share: finding a component's state and group, its topology and cells, and the
calls common to several families (masses, springs, assembly blocks).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.meshes import rotate_by_quaternion
from sofac.front.model import Component, Node
from sofac.geometry.fem_topology import CELL_KINDS
from sofac.plan.ir import (
    OFFSET,
    Aggregate,
    Buffer,
    Call,
    Env,
    FemMethod,
    Group,
    Op,
    Scheme,
    SpringDamping,
    SpringFlags,
    StatePlan,
    bind,
    call,
    kernel,
    origin_of,
)
from sofac.registry import Category, Variant

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


# --- lowerings ------------------------------------------------------------------------------------
# Each lowering reads its component's fields and appends kernel calls to its group.
Lowering = Callable[["Planner", CheckedComponent, dict[int, Group]], None]


_call = call


def _default(checked: CheckedComponent, name: str) -> Any:
    """A field's default, as the registry states it (the one place defaults live)."""
    assert checked.spec is not None
    spec = checked.spec.field(name)
    assert spec is not None, f"{checked.spec.name} has no field {name}"
    return spec.default


def _target(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group] | None:
    state = planner.state_of(checked)
    if state is None:
        planner.ignored.append((checked.component, "no MechanicalObject to act on"))
        return None
    group = owner.get(id(state.component))
    if group is None:
        planner.ignored.append((checked.component, "its state has no ODE solver: it never moves"))
        return None
    return state, group


def _rayleigh_refused(planner: Planner, checked: CheckedComponent) -> bool:
    """A component-level rayleighStiffness (SOFA's kFactorIncludingRayleighDamping) is refused."""
    if float(planner.value(checked.component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(
            checked, "a component-level rayleighStiffness is not compiled yet", "rayleighStiffness"
        )
        return True
    return False


def _vec3_target(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group, dict[str, np.ndarray]] | None:
    """State, group and topology cells of a component compiled on Vec3d only (E222 otherwise)."""
    found = _target(planner, checked, owner)
    if found is None:
        return None
    state, group = found
    if state.datatype.name != "Vec3d":
        name = checked.component.type_name
        planner.unsupported(checked, f"{name} on {state.datatype.name} is not compiled yet")
        return None
    return state, group, _topology_cells(planner, checked) or {}


def _indices(
    planner: Planner, checked: CheckedComponent, name: str, size: int, all_if_empty: bool = True
) -> np.ndarray:
    value = planner.value(checked.component, name)
    if value is None or np.size(value) == 0:
        return np.arange(size, dtype=np.int64) if all_if_empty else np.zeros(0, dtype=np.int64)
    return np.asarray(value, dtype=np.int64).ravel()


def _topology_of(planner: Planner, checked: CheckedComponent) -> Component | None:
    """The topology a component uses: its ``topology`` link, else the one in its context."""
    topology = checked.links.get("topology")
    if isinstance(topology, Component):
        return topology
    # A node holds one topology link: the last topology added to it (SOFA's NodeSingle), searched
    # from the component's node up.
    for node in (checked.component.node, *checked.component.node.ancestors()):
        found = [c for c in node.objects if planner.checked.of(c).category is Category.TOPOLOGY]
        if found:
            return found[-1]
    return None


def _topology_cells(
    planner: Planner, checked: CheckedComponent, *, sparse_grid_ok: bool = False
) -> dict[str, np.ndarray] | None:
    """The elements of the topology a component uses. A SparseGridTopology's only serve callers
    that read nothing else or apply its per-cell coefficients themselves (``sparse_grid_ok``, see
    _sparse_grid_coefficients): SOFA's other FEM and masses on it are not compiled."""
    topology = _topology_of(planner, checked)
    if topology is None:
        return None
    spec = planner.checked.of(topology).spec
    if spec is not None and spec.variant is Variant.SPARSE_GRID and not sparse_grid_ok:
        planner.unsupported(
            checked,
            "on a SparseGridTopology it is not compiled yet (HexahedronFEMForceField(AndMass) and "
            "BarycentricMapping are)",
        )
        planner.refused.add(id(checked.component))  # its "needs cells" follow-up would mislead
        return None
    cells: dict[str, np.ndarray] = {}
    for kind in (*CELL_KINDS, "resolution"):
        value = planner.value(topology, kind)
        if value is not None and np.size(value):
            cells[kind] = np.asarray(value, dtype=np.int64).ravel()
    return cells


def _sparse_grid_coefficients(planner: Planner, checked: CheckedComponent) -> np.ndarray | None:
    """The per-cell stiffness (= mass) coefficients of the SparseGridTopology a component uses (SOFA's
    HexahedronFEMForceField scales each element stiffness by them, ...AndMass each element mass and
    particle mass); None when its topology is not a sparse grid."""
    from sofac.geometry.voxelize import cell_coefficients

    topology = _topology_of(planner, checked)
    spec = planner.checked.of(topology).spec if topology is not None else None
    if topology is None or spec is None or spec.variant is not Variant.SPARSE_GRID:
        return None
    computed = planner.value(topology, "cell_coefficients")  # SparseGridRamificationTopology's own
    if computed is not None:
        return np.asarray(computed, dtype=float)
    boundary = planner.value(topology, "boundary_cells")
    if boundary is None:
        return None
    return cell_coefficients(np.asarray(boundary), bool(planner.value(topology, "fillWeighted")))


def _split_hexahedra(cells: dict[str, np.ndarray]) -> np.ndarray | None:
    """TetrahedronFEMForceField on hexahedra (a grid, a hexahedral mesh): 6 tetrahedra per cell, as
    SOFA splits them (mirrored by the cell's parity on a grid)."""
    from sofac.geometry.fem_topology import tetrahedra_from_grid, tetrahedra_from_hexahedra

    if "resolution" in cells and (cells["resolution"] > 1).all():
        return np.asarray(tetrahedra_from_grid(cells["resolution"].tolist()), dtype=np.int64).ravel()
    if "hexahedra" in cells:
        return np.asarray(
            tetrahedra_from_hexahedra(cells["hexahedra"].reshape(-1, 8)), dtype=np.int64
        ).ravel()
    return None


def _written_float(planner: Planner, component: Component, name: str) -> float | None:
    """A field's value when the scene sets it (or links it), else None (SOFA's isSet())."""
    if component.get(name) is None:
        return None
    value = planner.value(component, name)
    return None if value is None else float(np.asarray(value, dtype=float).ravel()[0])


_FEM_METHODS = {m.name.lower(): m for m in FemMethod}


# runtime fem.h TETRA_LANES: tetrahedron element data is stored in blocks of this many elements (a
# structure of arrays per block, for the vectorised kernels), so its buffer holds whole blocks.
TETRA_LANES = 4


# Element loops are split over threads only when each thread gets this many elements: below it,
# starting the threads costs more than they save.
MIN_ELEMENTS_PER_THREAD = 1024


def element_split(cells: np.ndarray, chunks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A split of an element loop over ``chunks`` threads that keeps the serial sums (runtime
    parallel.h): the chunks' element bounds, each element corner's deferred slot (-1: added
    directly) and each slot's node. A node belongs to the first chunk touching it; later chunks
    defer their contributions to it, numbered in serial (element, corner) order."""
    count, corners = cells.shape
    # chunks start at whole blocks of TETRA_LANES elements (the vectorised kernels' unit)
    bounds = np.minimum((np.linspace(0, count, chunks + 1) / TETRA_LANES).round() * TETRA_LANES, count)
    bounds = bounds.astype(np.int64)
    bounds[-1] = count
    chunk = np.repeat(np.arange(chunks), np.diff(bounds))
    owner = np.full(int(cells.max()) + 1, chunks, dtype=np.int64)
    np.minimum.at(owner, cells, np.broadcast_to(chunk[:, None], cells.shape))
    deferred = (chunk[:, None] > owner[cells]).ravel()
    slot_of = np.full(count * corners, -1, dtype=np.int64)
    slot_of[deferred] = np.arange(int(deferred.sum()))
    return bounds, slot_of, cells.ravel()[deferred].astype(np.int64)


def _split_argument(planner: Planner, component: Component, cells: np.ndarray, corners: int) -> list[str]:
    """The ElementSplit argument of an element kernel when the scene is compiled for threads and
    the loop is large enough; else nothing (the serial loop)."""
    count = cells.size // corners
    if planner.threads < 2 or count < MIN_ELEMENTS_PER_THREAD * planner.threads:
        return []
    bounds, slot_of, slot_node = element_split(cells.reshape(count, corners), planner.threads)
    parts = [
        planner.buffer(component, name, data, "i64")
        for name, data in (("split_bounds", bounds), ("split_slots", slot_of), ("split_nodes", slot_node))
    ]
    deferred = planner.buffer(component, "split_deferred", np.zeros(3 * slot_node.size), role="scratch")
    return [
        Aggregate(
            "ElementSplit", (parts[0], planner.threads, parts[1], parts[2], int(slot_node.size), deferred)
        )
    ]


def _triangle_target(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group, dict[str, np.ndarray]] | None:
    """A triangle-based component's state (Vec3d), group and topology cells, triangles included."""
    found = _vec3_target(planner, checked, owner)
    if found is None:
        return None
    state, group, cells = found
    triangles = cells.get("triangles")
    if triangles is None or not triangles.size or planner.checked.positions(state.component) is None:
        planner.unsupported(checked, "it needs triangles known at compile time")
        return None
    return state, group, cells


def _mapping_inputs(planner: Planner, checked: CheckedComponent) -> list[Component]:
    """The parent states of a mapping: its ``input`` link, or each link of a multi-mapping's list (a
    node stands for its MechanicalObject)."""
    from sofac.front import links

    single = checked.links.get("input")
    if isinstance(single, Component):
        return [single]
    text = checked.component.get("input")
    found: list[Component] = []
    for word in str(text or "").split():
        path = links.parse_link(word)
        target = links.resolve(path, checked.component) if path is not None else None
        if isinstance(target, Node):
            target = planner.checked.node_state(target)
        if isinstance(target, Component):
            found.append(target)
    return found


def _add_mass(
    planner: Planner, checked: CheckedComponent, state: StatePlan, group: Group, buffer: Buffer, stride: int
) -> None:
    origin = origin_of(checked.component)
    t, n = state.datatype.name, state.size
    stride_value = stride if stride else 0
    planner.add_gravity(
        group,
        Op(origin, [_call(kernel("mass_gravity", t), state.f, n, buffer, stride_value, planner.gravity)]),
    )
    group.energy.append(
        Op(
            origin,
            [
                _call(
                    kernel("mass_energy", t),
                    state.x,
                    state.v,
                    n,
                    buffer,
                    stride_value,
                    planner.gravity,
                    Env.KINETIC_OUT,
                    Env.POTENTIAL_OUT,
                )
            ],
        )
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        _call(kernel("assemble_mass", t), Env.ASSEMBLER, OFFSET, n, buffer, stride_value, Env.MFACT),
    )
    if group.scheme is Scheme.IMPLICIT:
        if planner.rigid_model == "exact" and state.datatype.name == "Rigid3d":
            planner.unsupported(checked, "the exact rigid model is compiled for explicit solvers only")
        group.mass_dx.append(
            Op(
                origin,
                [_call(kernel("mass_multiply", t), state.df, state.dx, n, buffer, stride_value, Env.MFACT)],
            )
        )
    elif state.acc is not None:
        state.mass = (buffer, stride_value)
        if planner.rigid_model == "exact" and state.datatype.name == "Rigid3d":
            code = _call(
                "rigid_acceleration_exact", state.acc, state.f, state.x, state.v, n, buffer, stride_value
            )
            group.accelerations.append(
                Op(origin + " [exact rigid model: rotated inertia, gyroscopic term]", [code])
            )
        else:
            group.accelerations.append(
                Op(
                    origin,
                    [_call(kernel("mass_acceleration", t), state.acc, state.f, n, buffer, stride_value)],
                )
            )


def _springs_from_fields(planner: Planner, checked: CheckedComponent) -> np.ndarray:
    """Springs as rows (i, j, ks, kd, L0) from ``spring`` or the indices/stiffness/... lists."""
    component = checked.component
    listed = planner.value(component, "spring")
    if listed is not None and np.size(listed):
        return np.asarray(listed, dtype=float).reshape(-1, 5)
    first = planner.value(component, "springsIndices1")
    second = planner.value(component, "springsIndices2")
    if first is None or second is None or not np.size(first):
        return np.zeros((0, 5))
    first = np.asarray(first, dtype=float).ravel()
    count = len(first)

    def spread(name: str, default: float) -> np.ndarray:
        value = planner.value(component, name)
        values = np.asarray(value if value is not None and np.size(value) else [default], dtype=float).ravel()
        return values if values.size == count else np.full(count, values[0])

    return np.column_stack(
        [
            first,
            np.asarray(second, dtype=float).ravel()[:count],
            spread("stiffness", 100.0),
            spread("damping", 5.0),
            spread("lengths", 0.0),
        ]
    )


def _flags(planner: Planner, component: Component, name: str, count: int, default: bool) -> np.ndarray:
    value = planner.value(component, name)
    values = np.asarray(value if value is not None and np.size(value) else [default], dtype=bool).ravel()
    return (values if values.size == count else np.full(count, values[0])).astype(np.int64)


def _add_springs(
    planner: Planner,
    checked: CheckedComponent,
    springs: np.ndarray,
    first: StatePlan,
    second: StatePlan,
    group: Group,
) -> None:
    component = checked.component
    count = len(springs)
    a = planner.buffer(component, "indices1", springs[:, 0], "i64")
    b = planner.buffer(component, "indices2", springs[:, 1], "i64")
    ks = planner.buffer(component, "stiffness", springs[:, 2], role="param")
    kd = planner.buffer(component, "damping", springs[:, 3], role="param")
    rest = planner.buffer(component, "lengths", springs[:, 4], role="param")
    elongation = planner.buffer(
        component, "elongationOnly", _flags(planner, component, "elongationOnly", count, False), "i64"
    )
    enabled = planner.buffer(component, "enabled", _flags(planner, component, "enabled", count, True), "i64")
    table = Aggregate("Springs", (a, b, ks, kd, rest, elongation, enabled, count))
    types = (first.datatype.name, second.datatype.name)
    # Specialised at compile time: no damping term when every damping is exactly zero (a pruned
    # effect: setting a damping later needs prune=False), no flag tests when no spring is disabled
    # or elongation-only (the flags are not tunable).
    damped = not planner.prune or bool(np.any(springs[:, 3] != 0.0))
    if not damped and count:
        planner.pruned.setdefault(kd.key, "every spring's damping is zero: no damping term computed")
    flagged = bool(np.any(elongation.initial)) or not bool(np.all(enabled.initial))
    variant = (
        *types,
        SpringDamping.DAMPED if damped else SpringDamping.UNDAMPED,
        SpringFlags.PER_SPRING if flagged else SpringFlags.NONE,
    )
    origin = origin_of(component)
    jacobians: Buffer | Env = Env.NONE
    if group.scheme is Scheme.IMPLICIT:  # dF/dx per spring, stored by the force pass, used by K dx
        dim = {"Rigid3d": 3, "Rigid2d": 2}.get(first.datatype.name, min(first.datatype.coord_size, 3))
        blocks = planner.buffer(component, "dfdx", np.zeros(count * (dim + 2)), role="scratch")  # factored
        jacobians = blocks
        if group.direct or group.assembled_cg:
            offset1, offset2 = group.assembly_offset(first, checked), group.assembly_offset(second, checked)
            code = _call(
                kernel("assemble_springs", *types),
                Env.ASSEMBLER,
                table,
                jacobians,
                offset1,
                offset2,
                Env.KFACT,
            )
            group.assemble.append(Op(origin, [code]))
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        kernel("spring_dforces", *types),
                        table,
                        jacobians,
                        first.dx,
                        first.df,
                        second.dx,
                        second.df,
                        Env.KFACT,
                    )
                ],
            )
        )
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    kernel("spring_forces", *variant),
                    table,
                    first.x,
                    first.v,
                    first.f,
                    second.x,
                    second.v,
                    second.f,
                    jacobians,
                )
            ],
        )
    )
    group.energy.append(
        Op(
            origin,
            [_call(kernel("spring_energy", *types), table, first.x, second.x, into=Env.POTENTIAL)],
        )
    )


def _matrix_solver(group: Group) -> str:
    """The linear solver of an assembled group, as messages name it."""
    if group.assembled_cg:
        return "a CGLinearSolver on an assembled matrix"
    if group.preconditioned:
        return "a PCGLinearSolver's assembled preconditioner"
    return "a sparse direct solver"


def _matrix_free_hint(group: Group) -> str:
    if group.assembled_cg:
        return 'use the matrix-free CGLinearSolver (template="GraphScattered", the default)'
    return "use CGLinearSolver"


def _assemble(
    planner: Planner, checked: CheckedComponent, group: Group, state: StatePlan, code: Call
) -> None:
    """An assembled solver's share of a component: its blocks of A, at the state's offset (the
    call's OFFSET; through the mappings' J for a mapped state)."""
    if not group.assembled:
        return
    offset = group.assembly_offset(state, checked)
    group.assemble.append(Op(origin_of(checked.component), [bind(code, {OFFSET: offset})]))


def _fixed_indices(planner: Planner, checked: CheckedComponent, state: StatePlan) -> np.ndarray:
    if planner.value(checked.component, "fixAll"):
        return np.arange(state.size, dtype=np.int64)
    return _indices(planner, checked, "indices", state.size, all_if_empty=False)


def _projected_target(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group] | None:
    """A projective constraint's state and group; None (kept out, with why) on a mapped state."""
    found = _target(planner, checked, owner)
    if found is not None and found[0].acc is None:
        planner.ignored.append(
            (checked.component, "on a mapped state: projections act on independent states")
        )
        return None
    return found


def _unit_vector(
    planner: Planner, component: Component, name: str, width: int, zero: int | None
) -> np.ndarray:
    """A direction field as SOFA normalises it (times 1/|n|); a zero vector becomes the unit vector
    along axis ``zero``, or stays zero (no constraint) when ``zero`` is None."""
    given = np.zeros(width)
    value = planner.value(component, name)
    if value is not None:
        flat = np.asarray(value, dtype=float).ravel()[:width]
        given[: flat.size] = flat
    norm = math.sqrt(sum(float(c) * float(c) for c in given))
    if norm == 0.0:
        if zero is not None:
            given[zero] = 1.0
        return given
    inverse = 1.0 / norm
    return np.array([float(c) * inverse for c in given])


def _mapping_ends(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, StatePlan, Group] | None:
    source, target = checked.links.get("input"), checked.links.get("output")
    parent = planner.states.get(id(source)) if isinstance(source, Component) else None
    child = planner.states.get(id(target)) if isinstance(target, Component) else None
    if parent is None or child is None:
        planner.ignored.append((checked.component, "visual mapping: computed only for rendering"))
        return None
    group = owner.get(id(child.component))
    if group is None:
        planner.ignored.append((checked.component, "its input has no ODE solver"))
        return None
    return parent, child, group


def _to_local(frames: np.ndarray, frame_of: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Global points expressed in their frame (globalToLocalCoords)."""
    local = np.empty_like(points)
    for k, (point, c) in enumerate(zip(points, frame_of, strict=True)):
        frame = frames[c]
        if frames.shape[1] == 7:  # Quat::inverseRotate: the rotation by (-x, -y, -z, w)
            inverse = (-frame[3], -frame[4], -frame[5], frame[6])
            local[k] = rotate_by_quaternion((point - frame[:3]).reshape(1, 3), inverse)[0]
        else:
            c_, s_ = np.cos(frame[2]), np.sin(frame[2])
            d = point - frame[:2]
            local[k] = [c_ * d[0] + s_ * d[1], -s_ * d[0] + c_ * d[1]]
    return local


def _element_cells(
    planner: Planner, checked: CheckedComponent, state: StatePlan
) -> tuple[str, int, np.ndarray] | None:
    """Element-based FEM (runtime/sofac/element_fem.h): the element type of a "Vec3d,Element"
    template, its nodes per element and the cells of the topology the component uses."""
    from sofac.geometry import element_fem

    element = element_fem.element_of(checked.template)
    if state.datatype.name != "Vec3d" or element not in element_fem.ELEMENTS:
        planner.unsupported(
            checked,
            f"template {checked.template!r} is not compiled yet (Vec3d with Tetrahedron or Hexahedron)",
        )
        return None
    corners, kind = element_fem.ELEMENTS[element]
    cells = (_topology_cells(planner, checked) or {}).get(kind)
    if cells is None or not cells.size or cells.size % corners:
        planner.unsupported(checked, f"it needs {kind} known at compile time")
        return None
    if cells.min() < 0 or cells.max() >= state.size:
        planner.unsupported(checked, f"its {kind} index points outside its state of {state.size}")
        return None
    return element, corners, cells


def _element_target(
    planner: Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group, tuple[str, int, np.ndarray]] | None:
    """The state, group and elements (type, corners, cells) an element component acts on."""
    found = _target(planner, checked, owner)
    if found is None:
        return None
    state, group = found
    geometry = _element_cells(planner, checked, state)
    return None if geometry is None else (state, group, geometry)


def _nodal_mass_density(planner: Planner, checked: CheckedComponent) -> Component | None:
    """FEMMass's density: its nodalMassDensity link, else the first NodalMassDensity of its context."""
    linked = checked.links.get("nodalMassDensity")
    if isinstance(linked, Component):
        return linked
    for node in (checked.component.node, *checked.component.node.ancestors()):
        for candidate in node.objects:
            spec = planner.checked.of(candidate).spec
            if spec is not None and spec.variant is Variant.NODAL_MASS_DENSITY:
                return candidate
    return None
