"""Lowerings of the FEM force fields: tetrahedra, hexahedra, triangles (plain and optimised) and
the element FEM of other cells.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import (
    OFFSET,
    Aggregate,
    Buffer,
    Constant,
    Count,
    Env,
    FemMethod,
    Function,
    Group,
    Op,
    Scheme,
    StatePlan,
    kernel,
    origin_of,
)
from sofac.plan.lower.common import (
    _FEM_METHODS,
    TETRA_LANES,
    _assemble,
    _call,
    _default,
    _element_target,
    _rayleigh_refused,
    _sparse_grid_coefficients,
    _split_argument,
    _split_hexahedra,
    _target,
    _topology_cells,
    _triangle_target,
    _vec3_target,
    _written_float,
)
from sofac.plan.lower.masses import lower_hexa_mass
from sofac.registry import Variant

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


# (kernel prefix, element kind, corners, data size per element by method)
FEM_KINDS = {
    "tetra_fem": ("tetra_fem", "tetrahedra", 4, {0: 24, 1: 30, 2: 36, 3: 54}),
    "tetracorot_fem": ("tetracorot_fem", "tetrahedra", 4, {0: 24, 1: 30, 2: 36, 3: 54}),
    "hexa_fem": ("hexa_fem", "hexahedra", 8, {0: 609, 1: 609, 2: 609, 3: 609}),
    "hexahedral_fem": ("hexahedral_fem", "hexahedra", 8, {1: 609, 2: 609}),
    "trifem": ("trifem", "triangles", 3, {1: 35}),
}
# runtime quad_bending.h QUAD_BENDING_DATA: doubles per quad (rest offsets 12, material 4)
QUAD_BENDING_DATA = 16
# runtime shell.h triangle_fem_data_size: doubles per triangle (rotation 9, rest 4, J 18, K 5)
TRIANGLE_FEM_DATA = 36
# The runtime's data sizes of those kinds, which tests/test_layout.py checks against this table.
DATA_SIZE_FUNCTIONS = {
    "tetra_fem": "tetra_fem_data_size",
    "tetracorot_fem": "tetracorot_fem_data_size",
    "hexa_fem": "hexa_fem_data_size",
    "hexahedral_fem": "hexahedral_fem_data_size",
    "trifem": "trifem_data_size",
}


def _material(planner: Planner, checked: CheckedComponent) -> tuple[Buffer, Buffer]:
    """Young's modulus and Poisson's ratio (one, or per element) as tunable buffers. An empty
    list takes the registry's default, as SOFA's getVecRealInElement does (so every kernel reads
    at least one value and none carries a default of its own)."""
    buffers = []
    for name in ("youngModulus", "poissonRatio"):
        value = planner.value(checked.component, name)
        values = np.atleast_1d(value if value is not None else [])
        if values.size == 0:
            values = np.atleast_1d(_default(checked, name))
        buffers.append(planner.buffer(checked.component, name, values, role="param"))
    return buffers[0], buffers[1]


def _plasticity(planner: Planner, checked: CheckedComponent, count: int) -> Aggregate | None:
    """TetrahedronFEMForceField's plasticity when plasticMaxThreshold > 0 (SOFA's test): each
    element's plastic strain (6 numbers, a state: reset restores zeros) and the three thresholds."""
    values = {
        name: float(planner.value(checked.component, name) or 0.0)
        for name in ("plasticMaxThreshold", "plasticYieldThreshold", "plasticCreep")
    }
    if values["plasticMaxThreshold"] <= 0.0:
        return None
    strains = planner.buffer(
        checked.component, "plasticStrains", np.zeros(count * 6), columns=6, role="state"
    )
    return Aggregate(
        "TetraPlasticity",
        (strains, values["plasticMaxThreshold"], values["plasticYieldThreshold"], values["plasticCreep"]),
    )


def lower_fem(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    assert checked.spec is not None
    prefix, kind, corners, sizes = FEM_KINDS[checked.spec.lowering]
    if state.datatype.name != "Vec3d":
        planner.unsupported(checked, f"{checked.spec.name} on {state.datatype.name} is not compiled yet")
        return
    method = _FEM_METHODS.get(str(planner.value(component, "method") or "large"), FemMethod.LARGE)
    if prefix == "trifem" and method != FemMethod.LARGE:
        planner.unsupported(checked, "TriangularFEMForceField is compiled for method large only", "method")
        return
    if prefix != "tetra_fem" and method == FemMethod.SVD:
        method = FemMethod.LARGE  # svd exists only for TetrahedronFEMForceField; SOFA falls back to large
    updating = (
        prefix == "tetra_fem"
        and method != FemMethod.SMALL
        and bool(planner.value(component, "updateStiffnessMatrix"))
    )
    plastic = prefix == "tetra_fem" and float(planner.value(component, "plasticMaxThreshold") or 0.0) > 0.0
    if plastic and planner.value(component, "computeGlobalMatrix"):
        # SOFA's small and large methods then log "Support for assembling system matrix when using
        # plasticity" and add no force at all
        planner.unsupported(
            checked, "plasticity with computeGlobalMatrix=true is not compiled (SOFA refuses it)"
        )
        return
    if updating and method == FemMethod.LARGE and group.assembled:
        planner.unsupported(
            checked, "updateStiffnessMatrix=true with method large in an assembled system is not compiled yet"
        )
        return
    # HexahedronFEMForceField(AndMass) applies a SparseGridTopology's cell coefficients (below)
    topology = _topology_cells(planner, checked, sparse_grid_ok=prefix == "hexa_fem") or {}
    cells = topology.get(kind)
    if (cells is None or not cells.size) and prefix == "tetra_fem":
        cells = _split_hexahedra(topology)
    if cells is None or not cells.size:
        planner.unsupported(checked, f"it needs {kind} known at compile time")
        return
    count = cells.size // corners
    elements = planner.buffer(component, kind, cells, "i64", columns=corners)
    young_buffer, poisson_buffer = _material(planner, checked)
    padded = -(-count // TETRA_LANES) * TETRA_LANES if kind == "tetrahedra" else count
    data = planner.buffer(component, "elements", np.zeros(padded * sizes[method]), role="scratch")
    coefficients = _sparse_grid_coefficients(planner, checked) if prefix == "hexa_fem" else None
    if coefficients is not None and len(coefficients) != count:
        planner.unsupported(checked, "its SparseGridTopology's cell coefficients do not match its hexahedra")
        return
    coefficient_buffer = (
        planner.buffer(component, "stiffnessCoefs", coefficients) if coefficients is not None else None
    )
    origin = origin_of(component)
    group.init.append(
        Op(
            origin,
            [
                _call(
                    f"{prefix}_init",
                    elements,
                    count,
                    state.rest,
                    young_buffer,
                    Count(young_buffer),
                    poisson_buffer,
                    Count(poisson_buffer),
                    method,
                    data,
                    *([coefficient_buffer] if coefficient_buffer is not None else []),
                )
            ],
        )
    )
    split = _split_argument(planner, component, cells, corners) if prefix != "trifem" else []
    plasticity = _plasticity(planner, checked, count) if prefix == "tetra_fem" else None
    # large + updateStiffnessMatrix: the rewritten normal-column cofactors (fem.h TetraStiffnessUpdate)
    normals = None
    if updating and method == FemMethod.LARGE:
        normals = planner.buffer(component, "updatedStrainDisplacement", np.zeros(count * 12), role="scratch")
        group.init.append(Op(origin, [_call("tetra_fem_copy_normals", count, data, method, normals)]))
    if plasticity is not None or updating:
        options = (
            plasticity if plasticity is not None else Aggregate("TetraPlasticity", (Env.NONE, 0.0, 0.0, 0.0)),
            Aggregate("TetraStiffnessUpdate", (updating, normals if normals is not None else Env.NONE)),
        )
        force = _call(
            "tetra_fem_add_force_options", elements, count, state.x, state.f, data, method, *options, *split
        )
    else:
        force = _call(f"{prefix}_add_force", elements, count, state.x, state.f, data, method, *split)
    group.forces.append(Op(origin, [force]))
    # HexahedronFEMForceFieldAndMass: its weight after its force
    and_mass = checked.spec.variant is Variant.AND_MASS
    if and_mass and not lower_hexa_mass(
        planner, checked, state, group, elements, count, data, method, coefficient_buffer
    ):
        return
    if prefix not in ("tetracorot_fem", "trifem", "hexahedral_fem"):  # SOFA's energy (0 for these)
        group.energy.append(
            Op(
                origin,
                [_call(f"{prefix}_energy", elements, count, state.x, data, method, into=Env.POTENTIAL)],
            )
        )
    if group.scheme is Scheme.IMPLICIT:
        dforce = (
            _call(
                "tetra_fem_add_dforce_normals",
                elements,
                count,
                state.dx,
                state.df,
                Env.KFACT,
                data,
                method,
                normals,
                *split,
            )
            if normals is not None
            else _call(
                f"{prefix}_add_dforce", elements, count, state.dx, state.df, Env.KFACT, data, method, *split
            )
        )
        group.stiffness_dx.append(Op(origin, [dforce]))
        # Tetrahedra: element matrices a block of TETRA_LANES at once, one per vector lane (fem.h).
        if prefix in ("tetra_fem", "tetracorot_fem"):
            assembler = kernel("assemble_elements", 4, Constant.TETRA_LANES)
            matrices = Function(f"{prefix}_element_matrices")
        else:
            assembler, matrices = kernel("assemble_elements", corners), Function(f"{prefix}_element_matrix")
        _assemble(
            planner,
            checked,
            group,
            state,
            _call(assembler, Env.ASSEMBLER, elements, count, data, method, OFFSET, Env.KFACT, matrices),
        )


def _initial_points(
    planner: Planner, checked: CheckedComponent, state: StatePlan, cells: np.ndarray
) -> Buffer | None:
    """A FEM's ``initialPoints`` when the scene gives them (SOFA's init keeps a non-empty list), else
    the state's rest positions; None (refused) when they do not cover the elements' nodes."""
    given = planner.value(checked.component, "initialPoints")
    if given is None or not np.size(given):
        return state.rest
    points = np.asarray(given, dtype=float).reshape(-1, 3)
    if cells.size and int(cells.max()) >= len(points):
        planner.unsupported(
            checked,
            f"its initialPoints hold {len(points)} points, its elements use point {int(cells.max())}",
            "initialPoints",
        )
        return None
    return planner.buffer(checked.component, "initialPoints", points.ravel(), columns=3)


def lower_triangle_fem(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """TriangleFEMForceField: its topology's triangles, or two per quad (q0 q1 q2)(q0 q2 q3) when it
    has none, as SOFA's init; method large or small (runtime shell.h triangle_fem_*)."""
    found = _vec3_target(planner, checked, owner)
    if found is None or _rayleigh_refused(planner, checked):
        return
    state, group, cells = found
    component = checked.component
    triangles = cells.get("triangles")
    if (triangles is None or not triangles.size) and cells.get("quads") is not None:
        quads = cells["quads"].reshape(-1, 4)
        triangles = np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).ravel()
    if triangles is None or not triangles.size:
        planner.ignored.append((component, "its topology has no triangles or quads: SOFA applies no force"))
        return
    method = FemMethod.SMALL if planner.value(component, "method") == "small" else FemMethod.LARGE
    initial = _initial_points(planner, checked, state, triangles)
    if initial is None:
        return
    if method is FemMethod.SMALL:
        # SOFA's small method builds J from the world x, y of the edges ab, ac and stops (the
        # component turns invalid) when b_x c_y is below machine epsilon
        points = initial.initial.reshape(-1, 3)
        tri = triangles.reshape(-1, 3)
        ab, ac = points[tri[:, 1]] - points[tri[:, 0]], points[tri[:, 2]] - points[tri[:, 0]]
        if np.any(np.abs(ab[:, 0] * ac[:, 1]) < np.finfo(float).eps):
            planner.unsupported(
                checked,
                "method small divides by b_x c_y of each triangle's world edges, zero here (SOFA stops "
                "with 'Null determinant')",
                "method",
            )
            return
    count = triangles.size // 3
    elements = planner.buffer(component, "triangles", triangles, "i64", columns=3)
    young_buffer, poisson_buffer = _material(planner, checked)
    thickness = float(planner.value(component, "thickness") or _default(checked, "thickness"))
    plane_strain = bool(planner.value(component, "planeStrain"))
    data = planner.buffer(component, "elements", np.zeros(count * TRIANGLE_FEM_DATA), role="scratch")
    origin = origin_of(component)
    material = (young_buffer, Count(young_buffer), poisson_buffer, Count(poisson_buffer))
    group.init.append(
        Op(
            origin,
            [
                _call(
                    "triangle_fem_init",
                    elements,
                    count,
                    initial,
                    *material,
                    thickness,
                    plane_strain,
                    method,
                    data,
                )
            ],
        )
    )
    group.forces.append(
        Op(origin, [_call("triangle_fem_add_force", elements, count, state.x, state.f, data, method)])
    )
    if group.scheme is not Scheme.IMPLICIT:
        return
    group.stiffness_dx.append(
        Op(
            origin,
            [_call("triangle_fem_add_dforce", elements, count, state.dx, state.df, Env.KFACT, data, method)],
        )
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        _call(
            kernel("assemble_elements", 3),
            Env.ASSEMBLER,
            elements,
            count,
            data,
            method,
            OFFSET,
            Env.KFACT,
            Function("triangle_fem_element_matrix"),
        ),
    )


# SOFA's FastTetrahedralCorotationalForceField method names, as its RotationDecompositionMethod
# (runtime fast_tetra_fem.h FastTetraMethod: polar, qr, polar2, linear)
FAST_TETRA_METHODS = {"polar": 0, "qr": 1, "large": 1, "polar2": 2, "none": 3, "linear": 3, "small": 3}
# runtime fast_tetra_fem.h fast_tetra_fem_data_size: doubles per tetrahedron
FAST_TETRA_DATA = 144


def lower_fast_tetra_fem(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FastTetrahedralCorotationalForceField: the topology's tetrahedra, K dx on its edges (SOFA's
    order, or the edges of the tetrahedra as SOFA creates them), runtime fast_tetra_fem.h."""
    from sofac.geometry import masses

    found = _vec3_target(planner, checked, owner)
    if found is None or _rayleigh_refused(planner, checked):
        return
    state, group, cells = found
    component = checked.component
    tetrahedra = cells.get("tetrahedra")
    if tetrahedra is None or not tetrahedra.size:
        # SOFA: "No tetrahedra found in linked Topology" (a grid's hexahedra are not split for it)
        planner.unsupported(
            checked,
            "its topology has no tetrahedra known at compile time "
            "(a grid's hexahedra: split them with Hexa2TetraTopologicalMapping)",
        )
        return
    tets = tetrahedra.reshape(-1, 4)
    edges = cells.get("edges")
    edges = (
        masses.topology_edges(state.size, tetrahedra=tets) if edges is None or not edges.size else edges
    ).reshape(-1, 2)
    try:
        tet_edges = masses.element_edge_indices("tetrahedra", tets, edges, state.size)
    except ValueError as error:
        planner.unsupported(checked, str(error))
        return
    method = FAST_TETRA_METHODS[str(planner.value(component, "method") or _default(checked, "method"))]
    count, n_edges = len(tets), len(edges)
    elements = planner.buffer(component, "tetrahedra", tets, "i64", columns=4)
    edges_in = planner.buffer(component, "edgesInTetrahedron", tet_edges, "i64", columns=6)
    edge_list = planner.buffer(component, "edges", edges, "i64", columns=2)
    young_buffer, poisson_buffer = _material(planner, checked)
    material = (young_buffer, Count(young_buffer), poisson_buffer, Count(poisson_buffer))
    data = planner.buffer(component, "tetrahedronInfo", np.zeros(count * FAST_TETRA_DATA), role="scratch")
    origin = origin_of(component)
    group.init.append(
        Op(
            origin,
            [
                _call(
                    "fast_tetra_fem_init",
                    elements,
                    count,
                    state.rest,
                    *material,
                    method,
                    edges_in,
                    edge_list,
                    data,
                )
            ],
        )
    )
    force = _call("fast_tetra_fem_add_force", elements, count, state.x, state.f, data, method)
    if group.scheme is not Scheme.IMPLICIT:
        group.forces.append(Op(origin, [force]))
        return
    edge_matrices = planner.buffer(component, "edgeInfo", np.zeros(9 * n_edges), columns=9, role="scratch")
    # SOFA rebuilds the edge blocks at the first K dx after a force pass: here right after it
    group.forces.append(
        Op(
            origin,
            [force, _call("fast_tetra_fem_edge_matrices", edges_in, count, n_edges, data, edge_matrices)],
        )
    )
    group.stiffness_dx.append(
        Op(
            origin,
            [
                _call(
                    "fast_tetra_fem_add_dforce",
                    edge_list,
                    n_edges,
                    edge_matrices,
                    state.dx,
                    state.df,
                    Env.KFACT,
                )
            ],
        )
    )
    if group.assembled:
        points = planner.buffer(component, "pointInfo", np.zeros(9 * state.size), columns=9, role="scratch")
        _assemble(
            planner,
            checked,
            group,
            state,
            _call(
                "assemble_fast_tetra_fem",
                Env.ASSEMBLER,
                OFFSET,
                elements,
                count,
                state.size,
                edge_list,
                n_edges,
                edge_matrices,
                data,
                points,
                Env.KFACT,
            ),
        )


def lower_quad_bending(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """QuadBendingFEMForceField: SOFA's small method on the topology's quads, its stiffness
    recomputed from the positions at every force and derivative pass (as SOFA)."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    if state.datatype.name != "Vec3d":
        planner.unsupported(checked, f"QuadBendingFEMForceField on {state.datatype.name} is not compiled yet")
        return
    if group.assembled:
        # SOFA's buildStiffnessMatrix reads 3x3 blocks at 3-strides of its 5-unknown-per-node matrix
        planner.unsupported(checked, "QuadBendingFEMForceField in an assembled system is not compiled yet")
        return
    quads = (_topology_cells(planner, checked) or {}).get("quads")
    if quads is None or not quads.size:
        planner.unsupported(checked, "it needs quads known at compile time")
        return
    component = checked.component
    count = quads.size // 4
    elements = planner.buffer(component, "quads", quads, "i64", columns=4)
    young_buffer, poisson_buffer = _material(planner, checked)
    thickness = float(planner.value(component, "thickness") or _default(checked, "thickness"))
    data = planner.buffer(component, "quadInfo", np.zeros(count * QUAD_BENDING_DATA), role="scratch")
    origin = origin_of(component)
    material = (young_buffer, Count(young_buffer), poisson_buffer, Count(poisson_buffer))
    group.init.append(
        Op(origin, [_call("quad_bending_init", elements, count, state.rest, *material, thickness, data)])
    )
    group.forces.append(
        Op(origin, [_call("quad_bending_add_force", elements, count, state.x, state.f, data)])
    )
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "quad_bending_add_dforce",
                        elements,
                        count,
                        state.x,
                        state.dx,
                        state.df,
                        Env.KFACT,
                        data,
                    )
                ],
            )
        )


def lower_trifem_optim(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """TriangularFEMForceFieldOptim: corotational membrane triangles ("large" only, as SOFA)."""
    found = _triangle_target(planner, checked, owner)
    if found is None:
        return
    state, group, topology = found
    component = checked.component
    rest_scale = _written_float(planner, component, "restScale")
    if rest_scale is not None and rest_scale != 1.0:
        planner.unsupported(checked, "restScale other than 1 is not compiled yet")
        return
    cells = topology["triangles"]
    count = cells.size // 3
    elements = planner.buffer(component, "triangles", cells, "i64", columns=3)
    young_buffer, poisson_buffer = _material(planner, checked)
    material = (young_buffer, Count(young_buffer), poisson_buffer, Count(poisson_buffer))
    data = planner.buffer(component, "triangleInfo", np.zeros(count * 10), role="scratch")
    origin = origin_of(component)
    group.init.append(
        Op(origin, [_call("trifem_optim_init", elements, count, state.rest, *material, 1, data)])
    )
    group.forces.append(
        Op(origin, [_call("trifem_optim_add_force", elements, count, state.x, state.f, data, *material)])
    )
    if group.scheme is Scheme.IMPLICIT:
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "trifem_optim_add_dforce",
                        elements,
                        count,
                        state.dx,
                        state.df,
                        Env.KFACT,
                        data,
                        *material,
                    )
                ],
            )
        )
        matrix = Aggregate(
            "TrifemOptimElementMatrix",
            (young_buffer, Count(young_buffer), poisson_buffer, Count(poisson_buffer)),
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            _call(
                kernel("assemble_elements", 3),
                Env.ASSEMBLER,
                elements,
                count,
                data,
                1,
                OFFSET,
                Env.KFACT,
                matrix,
            ),
        )


def lower_element_fem(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """CorotationalFEMForceField and LinearSmallStrainFEMForceField on tetrahedra or hexahedra."""
    from sofac.geometry import element_fem

    found = _element_target(planner, checked, owner)
    if found is None:
        return
    state, group, (element, corners, cells) = found
    component = checked.component
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a component-level rayleighStiffness is not compiled yet")
        return
    corotational = checked.spec is not None and checked.spec.variant is Variant.COROTATIONAL
    method = 0
    if corotational:
        name = planner.value(component, "rotationMethod")
        code = element_fem.rotation_method(name, element)
        if code is None:
            planner.unsupported(checked, f"rotationMethod {name!r} does not exist for {element}")
            return
        method = code
    count, size = cells.size // corners, 3 * corners
    elements = planner.buffer(component, element_fem.ELEMENTS[element][1], cells, "i64", columns=corners)
    young_buffer, poisson_buffer = _material(planner, checked)
    stiffness = planner.buffer(
        component, "elementStiffness", np.zeros(count * size * size), columns=size * size, role="scratch"
    )
    origin = origin_of(component)
    n = corners
    init = [
        _call(
            kernel("element_fem_stiffness_init", n),
            elements,
            count,
            state.rest,
            young_buffer,
            Count(young_buffer),
            poisson_buffer,
            Count(poisson_buffer),
            stiffness,
        )
    ]
    rotations = None
    if corotational:
        rotations = planner.buffer(component, "rotations", np.zeros(count * 18), columns=18, role="scratch")
        init.append(_call(kernel("element_corot_init", n), elements, count, state.rest, method, rotations))
        force = _call(
            kernel("element_corot_add_force", n),
            elements,
            count,
            state.x,
            state.rest,
            stiffness,
            method,
            rotations,
            state.f,
        )
    else:
        force = _call(
            kernel("element_linear_add_force", n), elements, count, state.x, state.rest, stiffness, state.f
        )
    group.init.append(Op(origin, init))
    group.forces.append(Op(origin, [force]))
    if group.scheme is not Scheme.IMPLICIT:
        return
    if rotations is not None:
        dforce = _call(
            kernel("element_corot_add_dforce", n),
            elements,
            count,
            state.dx,
            state.df,
            Env.KFACT,
            stiffness,
            rotations,
        )
    else:
        dforce = _call(
            kernel("element_linear_add_dforce", n), elements, count, state.dx, state.df, Env.KFACT, stiffness
        )
    group.stiffness_dx.append(Op(origin, [dforce]))
    _assemble(
        planner,
        checked,
        group,
        state,
        _call(
            kernel("element_fem_assemble", n),
            Env.ASSEMBLER,
            elements,
            count,
            stiffness,
            rotations if rotations is not None else Env.NONE,
            OFFSET,
            Env.KFACT,
        ),
    )
