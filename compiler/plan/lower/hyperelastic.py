"""Lowering of TetrahedronHyperelasticityFEMForceField (runtime/sofac/hyperelastic.h)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import OFFSET, Env, Group, Op, Scheme, origin_of
from sofac.plan.lower.common import _assemble, _call, _target, _topology_cells
from sofac.registry.components.fem import HYPERELASTIC_MATERIALS, hyperelastic_problem

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# runtime hyperelastic.h hyperelastic_data_size() (tests/test_layout.py checks it)
HYPERELASTIC_DATA_SIZE = 84


def lower_hyperelastic(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.name != "Vec3d":
        planner.unsupported(checked, f"{component.type_name} on {state.datatype.name} is not compiled yet")
        return
    material = str(planner.value(component, "materialName") or "ArrudaBoyce")
    written = planner.value(component, "ParameterSet")
    parameters = np.asarray(written if written is not None else [], dtype=float).ravel()
    problem = hyperelastic_problem(material, parameters)
    if problem is not None:  # the checker reports it first (ComponentSpec.validate); never silent
        planner.unsupported(checked, problem[2])
        return
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a component-level rayleighStiffness is not compiled yet")
        return
    cells = (_topology_cells(planner, checked) or {}).get("tetrahedra")
    if cells is None or not cells.size:
        planner.unsupported(
            checked, "it needs tetrahedra known at compile time (SOFA needs a tetrahedral topology)"
        )
        return
    count = cells.size // 4
    code = HYPERELASTIC_MATERIALS.index(material)
    elements = planner.buffer(component, "tetrahedra", cells, "i64", columns=4)
    parameter_buffer = planner.buffer(component, "ParameterSet", parameters, role="param")
    # one more number after the elements: the tangent is stale (SOFA's m_updateMatrix)
    data = planner.buffer(
        component, "tetrahedronInfo", np.zeros(count * HYPERELASTIC_DATA_SIZE + 1), role="scratch"
    )
    origin = origin_of(component)
    group.init.append(Op(origin, [_call("hyperelastic_init", elements, count, state.rest, data)]))
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    "hyperelastic_add_force", elements, count, state.x, state.f, data, code, parameter_buffer
                )
            ],
        )
    )
    if group.scheme is not Scheme.IMPLICIT:
        return
    group.stiffness_dx.append(
        Op(
            origin,
            [
                _call(
                    "hyperelastic_add_dforce",
                    elements,
                    count,
                    state.dx,
                    state.df,
                    Env.KFACT,
                    data,
                    code,
                    parameter_buffer,
                )
            ],
        )
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        _call(
            "hyperelastic_assemble",
            Env.ASSEMBLER,
            elements,
            count,
            data,
            code,
            parameter_buffer,
            OFFSET,
            Env.KFACT,
        ),
    )
