"""Lowerings of the beam components between rigid frames: BeamFEMForceField (Rigid3d) and
BeamLinearMapping (Rigid3d -> Vec3d). Their kernels are in runtime/sofac/beam.h.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.plan.ir import (
    CHILD,
    INPUT_OFFSET,
    OFFSET,
    PARENT,
    Count,
    Element,
    Env,
    Group,
    MappingOp,
    Op,
    Scheme,
    origin_of,
)
from sofac.plan.lower.common import _assemble, _call, _default, _mapping_ends, _target, _topology_cells

if TYPE_CHECKING:
    from sofac.plan.planner import Planner

# Per beam: the 12x12 local stiffness and the frame quaternion (beam.h's BEAM_*_SIZE).
BEAM_STIFFNESS_SIZE = 144
BEAM_FRAME_SIZE = 4


def lower_beam_fem(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """BeamFEMForceField: one Euler-Bernoulli beam per topology edge (SOFA sets the shear areas to
    zero), corotational in the frame of its first node; listSegment restricts the beams used."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.name != "Rigid3d":
        planner.unsupported(
            checked, f"BeamFEMForceField on {state.datatype.name} is not compiled (Rigid3d is)"
        )
        return
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a component-level rayleighStiffness is not compiled yet")
        return
    cells = _topology_cells(planner, checked) or {}
    edges = cells.get("edges")
    if edges is None or not edges.size:
        planner.unsupported(checked, "it needs a topology with edges (lines) known at compile time")
        return
    count = edges.size // 2
    if int(edges.max()) >= state.size or int(edges.min()) < 0:
        planner.unsupported(checked, "its topology's edges name DOFs its MechanicalObject does not have")
        return
    pairs = edges.reshape(-1, 2)
    if group.btd and np.any(np.abs(pairs[:, 1] - pairs[:, 0]) != 1):
        planner.unsupported(
            checked,
            "under BTDLinearSolver its beams must join consecutive DOFs (a block-tridiagonal matrix)",
        )
        return
    # listSegment: the beams used, unless one is out of range (SOFA then warns and uses them all)
    listed = planner.value(component, "listSegment")
    used = np.arange(count, dtype=np.int64)
    if listed is not None and np.size(listed):
        chosen = np.asarray(listed, dtype=np.int64).ravel()
        if chosen.min() >= 0 and chosen.max() < count:
            used = chosen
    edge_buffer = planner.buffer(component, "edges", edges, "i64", columns=2)
    used_buffer = planner.buffer(component, "listSegment", used, "i64")
    material = []
    for name in ("youngModulus", "poissonRatio"):
        value = planner.value(component, name)
        value = value if value is not None else _default(checked, name)
        material.append(planner.buffer(component, name, np.atleast_1d(value), role="param"))
    young, poisson = material
    radius = planner.value(component, "radius")
    inner = planner.value(component, "radiusInner")
    radius_buffer = planner.buffer(
        component,
        "radius",
        [float(_default(checked, "radius") if radius is None else radius)],
        role="param",
    )
    inner_buffer = planner.buffer(
        component,
        "radiusInner",
        [float(_default(checked, "radiusInner") if inner is None else inner)],
        role="param",
    )
    kloc = planner.buffer(component, "k_loc", np.zeros(BEAM_STIFFNESS_SIZE * count), role="scratch")
    frames = planner.buffer(component, "beamQuat", np.zeros(BEAM_FRAME_SIZE * count), role="scratch")
    symmetric = 1 if planner.value(component, "useSymmetricAssembly") else 0
    n_used = int(used.size)
    origin = origin_of(component)
    group.init.append(
        Op(
            origin,
            [
                _call(
                    "beam_fem_init",
                    edge_buffer,
                    count,
                    state.rest,
                    young,
                    Count(young),
                    poisson,
                    Count(poisson),
                    Element(radius_buffer),
                    Element(inner_buffer),
                    kloc,
                    frames,
                )
            ],
        )
    )
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    "beam_fem_add_force",
                    edge_buffer,
                    used_buffer,
                    n_used,
                    kloc,
                    state.rest,
                    state.x,
                    state.f,
                    frames,
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
                    "beam_fem_add_dforce",
                    edge_buffer,
                    used_buffer,
                    n_used,
                    kloc,
                    frames,
                    state.dx,
                    state.df,
                    Env.KFACT,
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
            "assemble_beam_fem",
            Env.ASSEMBLER,
            OFFSET,
            edge_buffer,
            used_buffer,
            n_used,
            kloc,
            frames,
            symmetric,
            Env.KFACT,
        ),
    )


def _quat_product(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    """SOFA's Quat product a b, (x y z w) order, operation by operation."""
    w = a[3] * b[3] - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
    x = a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1]
    y = a[3] * b[1] + a[1] * b[3] + a[2] * b[0] - a[0] * b[2]
    z = a[3] * b[2] + a[2] * b[3] + a[0] * b[1] - a[1] * b[0]
    return (x, y, z, w)


def _quat_inverse(q: tuple[float, ...]) -> tuple[float, float, float, float]:
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if norm == 0.0:
        return (0.0, 0.0, 0.0, 0.0)
    norm = 1.0 / norm
    return (-q[0] * norm, -q[1] * norm, -q[2] * norm, q[3] * norm)


def _cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _inverse_rotate(q: tuple[float, ...], v: tuple[float, ...]) -> tuple[float, float, float]:
    """SOFA's Quat::inverseRotate."""
    u = (-q[0], -q[1], -q[2])
    t = tuple(c * 2 for c in _cross(u, v))
    ut = _cross(u, t)
    return tuple(v[k] + q[3] * t[k] + ut[k] for k in range(3))  # type: ignore[return-value]


def _rfloor(r: float) -> int:
    """SOFA's helper::rfloor: r rounded to a multiple of 2^-16 (adding 1.5 2^36), then floored."""
    shift = 1.5 * float(1 << 36)
    return math.floor((r + shift) - shift)


def beam_mapping_points(
    frames: np.ndarray, points: np.ndarray, local_coord: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """BeamLinearMapping::init and the constant part of apply: per point, the first frame of its
    beam (in0, clamped to [0, n-2]), its coordinates with p_x reduced by in0, and beamLength[in0].
    beamLength[i] is the norm of the RigidCoord x_i - x_{i+1} (centre and quaternion x y z)."""
    n = len(frames)
    lengths = []
    for i in range(n - 1):
        a, b = [float(v) for v in frames[i]], [float(v) for v in frames[i + 1]]
        d = (a[0] - b[0], a[1] - b[1], a[2] - b[2])
        q = _quat_product(_quat_inverse(tuple(b[3:7])), tuple(a[3:7]))
        lengths.append(
            math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        )
    if n >= 2:
        lengths.append(lengths[-1])
    first, local, length = [], [], []
    origin = [float(v) for v in frames[0]] if n else [0.0] * 7
    for row in np.asarray(points, dtype=float):
        p = [float(v) for v in row[:3]]
        if not local_coord:
            p = list(
                _inverse_rotate(tuple(origin[3:7]), (p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]))
            )
            j = 0
            while j < len(lengths) and p[0] >= lengths[j]:
                p[0] -= lengths[j]
                j += 1
            j = min(j, len(lengths) - 1)  # past the last beam: SOFA reads past its array; the last length
            p = [c / lengths[j] for c in p]
            p[0] += j
        in0 = _rfloor(p[0])
        in0 = 0 if in0 < 0 else min(in0, n - 2)
        p[0] -= in0
        first.append(in0)
        local.append(p)
        length.append(lengths[in0])
    return (
        np.asarray(first, dtype=np.int64),
        np.asarray(local, dtype=float).reshape(-1, 3),
        np.asarray(length, dtype=float),
    )


def lower_beam_linear_mapping(planner: Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """BeamLinearMapping Rigid3d -> Vec3d: each point follows the two frames of its beam, blended
    with the cubic 3 s^2 - 2 s^3 of its position s along the beam."""
    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    if (parent.datatype.name, child.datatype.name) != ("Rigid3d", "Vec3d"):
        planner.unsupported(
            checked,
            f"BeamLinearMapping {parent.datatype.name},{child.datatype.name} is not compiled "
            "(Rigid3d,Vec3d is)",
        )
        return
    frames = planner.checked.positions(parent.component)
    points = planner.checked.positions(child.component)
    if frames is None or len(frames) < 2 or points is None:
        planner.unsupported(
            checked, "it needs at least two input frames and output points known at compile time"
        )
        return
    local_coord = planner.value(component, "localCoord") is not False
    first, local, length = beam_mapping_points(frames, points, local_coord)
    n = len(first)
    first_buffer = planner.buffer(component, "beam", first, "i64")
    local_buffer = planner.buffer(component, "points", local, columns=3)
    length_buffer = planner.buffer(component, "beamLength", length)
    rotated = planner.buffer(component, "rotatedPoints", np.zeros(6 * n), columns=6, role="scratch")
    maps_forces = planner.value(component, "mapForces") is not False
    table = (first_buffer, local_buffer, rotated, n)
    group.mappings.append(
        MappingOp(
            origin_of(component),
            parent,
            child,
            [
                _call(
                    "beam_linear_apply",
                    parent.x,
                    child.x,
                    first_buffer,
                    local_buffer,
                    length_buffer,
                    rotated,
                    n,
                ),
                _call("beam_linear_apply_j", parent.v, child.v, *table),
            ],
            _call("beam_linear_apply_j", PARENT, CHILD, *table),
            _call("beam_linear_apply_jt", PARENT, CHILD, *table) if maps_forces else None,
            # J depends on this step's rotated points: refilled every assembly.
            assembly=[_call("beam_linear_jacobian", Env.ASSEMBLER, OFFSET, INPUT_OFFSET, *table)],
        )
    )
