"""Lowerings of the masses: UniformMass, DiagonalMass, MeshMatrixMass and the FEM masses."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import (
    OFFSET,
    Buffer,
    Count,
    Env,
    Group,
    Op,
    Scheme,
    StatePlan,
    kernel,
    origin_of,
)
from sofac.plan.lower.common import (
    _add_mass,
    _assemble,
    _call,
    _element_target,
    _nodal_mass_density,
    _target,
    _topology_cells,
    _topology_of,
    _written_float,
)

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def lower_uniform_mass(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    datatype = state.datatype
    total = planner.value(component, "totalMass")
    vertex = planner.value(component, "vertexMass")
    if datatype.rigid and datatype.coord_size == 7:
        values = np.asarray(vertex if vertex is not None else [1.0], dtype=float).ravel()
        mass = values[0] if total is None else float(total) / max(state.size, 1)
        inertia = values[2:11].reshape(3, 3) if values.size >= 11 else np.eye(3)
        from sofac.front import parse

        given = planner.value(component, "filename")
        rigid_file = (
            parse.resolve_data_file(str(given), Path(component.loc.file).parent, planner.checked.scene)
            if given and str(given) != "unused"
            else None
        )
        if given and str(given) != "unused" and rigid_file is None:
            planner.unsupported(checked, f"its rigid file {given!r} is not found")
            return
        if rigid_file is not None:
            read = _rigid_file(rigid_file)
            if isinstance(read, str):
                planner.unsupported(checked, read)
                return
            if "inertia" in read:
                inertia = read["inertia"]
            if "mass" in read:  # the file's vertexMass wins over totalMass (SOFA unsets it)
                mass = float(read["mass"])
        data = np.concatenate([[mass], (inertia * mass).ravel()])
        stride = 10
    elif datatype.rigid:
        values = np.asarray(vertex if vertex is not None else [1.0], dtype=float).ravel()
        mass = values[0] if total is None else float(total) / max(state.size, 1)
        inertia = values[2] if values.size >= 3 else 1.0
        data, stride = np.array([mass, inertia * mass]), 2
    else:
        if total is not None:
            mass = float(total) / max(state.size, 1)
        else:
            mass = float(np.asarray(vertex if vertex is not None else [1.0], dtype=float).ravel()[0])
        data, stride = np.array([mass]), 1
    buffer = planner.buffer(component, "vertexMass", data, columns=stride, role="param")
    _add_mass(planner, checked, state, group, buffer, 0)


def _rigid_file(path: Path) -> dict[str, Any] | str:
    """UniformMass<Rigid3d>::loadRigidMass: the first line skipped, then keywords: inrt (the 3x3
    inertia), vertexMass, and others read and unused here (volm, center/cntr, frme, grav, visc,
    stck, step, prec, # comments)."""
    try:
        lines = path.read_text(errors="replace").splitlines()[1:]
    except OSError as error:
        return f"its rigid file cannot be read ({error.strerror})"
    words: list[str] = []
    for line in lines:
        words += line.split() if not line.lstrip().startswith("#") else []
    counts = {"inrt": 9, "vertexMass": 1, "volm": 1, "center": 3, "cntr": 3, "frme": 4, "grav": 3}
    counts.update({"visc": 1, "stck": 1, "step": 1, "prec": 1})
    found: dict[str, Any] = {}
    k = 0
    while k < len(words):
        word = words[k]
        n = counts.get(word)
        if n is None:
            return f"its rigid file {path.name} has the keyword {word!r}, which sofac does not read"
        try:
            numbers = [float(w) for w in words[k + 1 : k + 1 + n]]
        except ValueError:
            return f"its rigid file {path.name} has a malformed {word!r}"
        if len(numbers) != n:
            return f"its rigid file {path.name} ends inside {word!r}"
        if word == "inrt":
            found["inertia"] = np.array(numbers).reshape(3, 3)
        elif word == "vertexMass":
            found["mass"] = numbers[0]
        k += 1 + n
    return found


def lower_diagonal_mass(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from sofac.geometry import masses

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    if state.datatype.rigid:
        planner.unsupported(checked, "DiagonalMass on rigid frames is not compiled yet")
        return
    component = checked.component
    vertex = planner.value(component, "vertexMass")
    if component.get("totalMass") is None and component.get("massDensity") is None and vertex is not None:
        values = np.asarray(vertex, dtype=float).ravel()
    else:
        cells = _topology_cells(planner, checked) or {}
        rest = planner.checked.positions(state.component)
        try:
            values = masses.diagonal_mass(
                rest,
                edges=cells.get("edges"),
                triangles=cells.get("triangles"),
                quads=cells.get("quads"),
                tetrahedra=cells.get("tetrahedra"),
                hexahedra=cells.get("hexahedra"),
                mass_density=_written_float(planner, component, "massDensity"),
                total_mass=_written_float(planner, component, "totalMass"),
                vertex_mass=vertex,
            )
        except ValueError as error:
            planner.unsupported(checked, f"its masses cannot be computed: {error}")
            return
    if values.size != state.size:
        planner.unsupported(checked, f"it gives {values.size} masses for {state.size} DOFs")
        return
    buffer = planner.buffer(component, "vertexMass", values, role="param")
    _add_mass(planner, checked, state, group, buffer, 1)


def lower_mesh_matrix_mass(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from sofac.geometry import masses

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid:
        planner.unsupported(checked, "MeshMatrixMass on rigid frames is not compiled yet")
        return
    lumping = bool(planner.value(component, "lumping"))
    if group.scheme is not Scheme.IMPLICIT and not lumping:
        if group.scheme is not Scheme.EULER or not group.assembled:
            planner.unsupported(
                checked, "a consistent mass with this solver needs a sparse direct linear solver"
            )
            return
        group.direct = True  # explicit Euler solves M a = f
    from sofac.geometry.barycentric import mapper_for

    cells = _topology_cells(planner, checked) or {}
    topology = _topology_of(planner, checked)
    spec = planner.checked.of(topology).spec if topology is not None else None
    if spec is not None and mapper_for(spec.variant) == "dynamic":
        cells.pop("edges", None)  # a dynamic container builds its whole edge array from its elements
    density = planner.value(component, "massDensity") if component.get("massDensity") is not None else None
    try:
        data = masses.mesh_matrix_mass(
            planner.checked.positions(state.component),
            edges=cells.get("edges"),
            triangles=cells.get("triangles"),
            quads=cells.get("quads"),
            tetrahedra=cells.get("tetrahedra"),
            hexahedra=cells.get("hexahedra"),
            mass_density=density,
            total_mass=_written_float(planner, component, "totalMass"),
            lumping=lumping,
        )
    except ValueError as error:
        planner.unsupported(checked, f"its masses cannot be computed: {error}")
        return
    width, n = state.datatype.deriv_size, state.size
    vertex = planner.buffer(component, "vertexMass", data.vertex_mass, role="param")
    edges = planner.buffer(component, "edges", data.edges, "i64", columns=2)
    edge_mass = planner.buffer(component, "edgeMass", data.edge_mass, role="param")
    coefficient = float(data.lumping_coefficient) if lumping else 1.0
    lumped_factor = float(data.lumping_coefficient)
    origin = origin_of(component)
    g = planner.gravity
    planner.add_gravity(
        group, Op(origin, [_call("mesh_matrix_mass_gravity", state.f, vertex, n, lumped_factor, g, width)])
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        _call(
            "assemble_mesh_matrix_mass",
            Env.ASSEMBLER,
            OFFSET,
            vertex,
            n,
            edges,
            edge_mass,
            Count(edge_mass) if not lumping else 0,
            coefficient,
            Env.MFACT,
            width,
        ),
    )
    if group.scheme is Scheme.IMPLICIT:
        if lumping:
            code = _call(
                "mesh_matrix_mass_multiply_lumped",
                state.df,
                state.dx,
                vertex,
                n,
                coefficient,
                Env.MFACT,
                width,
            )
        else:
            code = _call(
                "mesh_matrix_mass_multiply",
                state.df,
                state.dx,
                vertex,
                n,
                edges,
                edge_mass,
                Count(edge_mass),
                Env.MFACT,
                width,
            )
        group.mass_dx.append(Op(origin, [code]))
    elif state.acc is not None and lumping:
        group.accelerations.append(
            Op(
                origin,
                [
                    _call(
                        "mesh_matrix_mass_acceleration_lumped",
                        state.acc,
                        state.f,
                        vertex,
                        n,
                        coefficient,
                        width,
                    )
                ],
            )
        )
    group.energy.append(
        Op(
            origin,
            [
                _call(
                    "mesh_matrix_mass_kinetic_energy",
                    state.v,
                    vertex,
                    n,
                    edges,
                    edge_mass,
                    Count(edge_mass),
                    bool(lumping),
                    coefficient,
                    width,
                    into=Env.KINETIC,
                ),
                _call(
                    kernel("gravity_potential", state.datatype.name),
                    state.x,
                    n,
                    vertex,
                    g,
                    lumped_factor,
                    into=Env.POTENTIAL,
                ),
            ],
        )
    )


def lower_hexa_mass(
    planner: Planner,
    checked: CheckedComponent,
    state: StatePlan,
    group: Group,
    elements: Buffer,
    count: int,
    data: Buffer,
    method: int,
    coefficients: Buffer | None,
) -> bool:
    """HexahedronFEMForceFieldAndMass's mass: SOFA's element mass matrices (consistent, or lumped
    onto the diagonal) in a scalar CSR matrix, and its weight from the particle masses (vol/8),
    both scaled by a SparseGridTopology's cell coefficients (``coefficients``) when it has one."""
    from sofac.geometry import element_fem

    component = checked.component
    if group.scheme is not Scheme.IMPLICIT and not (group.scheme is Scheme.EULER and group.assembled):
        # SOFA's accFromF is not implemented for this class: only a solve with M works.
        planner.unsupported(
            checked, "its mass needs an implicit solver, or explicit Euler with a sparse direct linear solver"
        )
        return False
    if group.scheme is not Scheme.IMPLICIT:
        group.direct = True
    lumped = bool(planner.value(component, "lumpedMass"))
    cells = elements.initial.reshape(-1, 8)
    if lumped:
        pattern = element_fem.mass_pattern(np.arange(state.size, dtype=np.int64).reshape(-1, 1), state.size)
    else:
        pattern = element_fem.mass_pattern(cells, state.size)
    density_value = planner.value(component, "density")
    density = planner.buffer(
        component, "density", np.atleast_1d(1.0 if density_value is None else float(density_value))
    )
    rows = planner.buffer(component, "rowBegin", pattern.row_begin, "i64")
    cols = planner.buffer(component, "colsIndex", pattern.cols, "i64")
    values = planner.buffer(component, "massMatrices", np.zeros(pattern.nonzeros), role="scratch")
    particle = planner.buffer(component, "particleMasses", np.zeros(state.size), role="scratch")
    csr = (rows, cols, values, state.size)
    origin = origin_of(component)
    group.init.append(
        Op(
            origin,
            [
                _call(
                    "hexa_fem_mass_init",
                    elements,
                    count,
                    state.rest,
                    data,
                    method,
                    density,
                    rows,
                    cols,
                    state.size,
                    bool(lumped),
                    values,
                    particle,
                    *([coefficients] if coefficients is not None else []),
                )
            ],
        )
    )
    planner.add_gravity(
        group,
        Op(
            origin,
            [_call(kernel("mass_gravity", "Vec3d"), state.f, state.size, particle, 1, planner.gravity)],
        ),
    )
    if group.scheme is Scheme.IMPLICIT:
        group.mass_dx.append(Op(origin, [_call("fem_mass_multiply", state.df, state.dx, *csr, Env.MFACT)]))
    _assemble(
        planner, checked, group, state, _call("assemble_fem_mass", Env.ASSEMBLER, OFFSET, *csr, Env.MFACT)
    )
    group.energy.append(
        Op(
            origin,
            [
                _call("fem_mass_kinetic_energy", state.v, *csr, into=Env.KINETIC),
                _call(
                    kernel("gravity_potential", "Vec3d"),
                    state.x,
                    state.size,
                    particle,
                    planner.gravity,
                    1.0,
                    into=Env.POTENTIAL,
                ),
            ],
        )
    )
    return True


def lower_fem_mass(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FEMMass: the consistent scalar mass matrix of the elements, from a NodalMassDensity."""
    from sofac.geometry import element_fem

    found = _element_target(planner, checked, owner)
    if found is None:
        return
    state, group, (_, corners, cells) = found
    component = checked.component
    if group.scheme is not Scheme.IMPLICIT:
        if group.scheme is not Scheme.EULER or not group.assembled:
            planner.unsupported(
                checked,
                "FEMMass needs an implicit solver, or explicit Euler with a sparse direct linear solver",
            )
            return
        group.direct = True  # explicit Euler solves M a = f
    source = _nodal_mass_density(planner, checked)
    if source is None:
        planner.unsupported(checked, "no NodalMassDensity in its context (SOFA marks it invalid)")
        return
    pattern = element_fem.mass_pattern(cells.reshape(-1, corners), state.size)
    count, n = cells.size // corners, corners
    elements = planner.buffer(component, "elements", cells, "i64", columns=corners)
    density = planner.buffer(
        source, "property", element_fem.node_densities(planner.value(source, "property")), role="param"
    )
    rows = planner.buffer(component, "rowBegin", pattern.row_begin, "i64")
    cols = planner.buffer(component, "colsIndex", pattern.cols, "i64")
    values = planner.buffer(component, "colsValue", np.zeros(pattern.nonzeros), role="scratch")
    csr = (rows, cols, values, state.size)
    origin = origin_of(component)
    group.init.append(
        Op(
            origin,
            [
                _call(
                    kernel("fem_mass_init", n),
                    elements,
                    count,
                    state.rest,
                    density,
                    Count(density),
                    *csr[:2],
                    state.size,
                    values,
                )
            ],
        )
    )
    planner.add_gravity(group, Op(origin, [_call("fem_mass_gravity", state.f, *csr, planner.gravity)]))
    if group.scheme is Scheme.IMPLICIT:
        group.mass_dx.append(Op(origin, [_call("fem_mass_multiply", state.df, state.dx, *csr, Env.MFACT)]))
    _assemble(
        planner, checked, group, state, _call("assemble_fem_mass", Env.ASSEMBLER, OFFSET, *csr, Env.MFACT)
    )
    group.energy.append(
        Op(
            origin,
            [
                _call("fem_mass_kinetic_energy", state.v, *csr, into=Env.KINETIC),
                _call("fem_mass_potential_energy", state.x, *csr, planner.gravity, into=Env.POTENTIAL),
            ],
        )
    )
