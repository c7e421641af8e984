"""What an instance of a compiled scene needs at run time, as plain data (no scene objects).

The Python API (``loader.Simulation``) reads this, not the plan. That keeps the data flow one way
(plan → run spec → instance) and lets a scene whose library is in the cache be instantiated from
a stored run spec, without parsing, checking or planning it again (``warm.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from sofac.param_rules import ParamRule

if TYPE_CHECKING:
    from sofac.front.model import Component
    from sofac.plan.ir import Plan


@dataclass(frozen=True)
class BufferSpec:
    key: str  # "<component path>.<field>"
    kind: str  # "f64" or "i64"
    role: str  # "state", "param", "data" or "scratch" (see plan.Buffer)
    initial: np.ndarray


@dataclass(frozen=True)
class SolverSpec:
    """An ODE solver, as error messages name it and hint at what to change."""

    origin: str  # "TypeName 'path' (file:line)"
    type_name: str
    scheme: str  # "euler", "rk2", "rk4", "implicit"
    direct: bool  # it solves with a factorised matrix
    linear_solver: str  # its linear solver's class ("" if none)


@dataclass(frozen=True)
class StateSpec:
    path: str
    name: str  # the name SOFA gives the MechanicalObject
    template: str  # its DataType (Vec3d, Rigid3d...)
    coord_size: int
    deriv_size: int
    size: int
    mapped: bool
    simulated: bool  # an ODE solver in its node or above
    x: int  # buffer indices
    v: int
    f: int
    computed_on_read: bool  # left out of the step (or mapped only when near), mapped when Python reads it
    solver: int  # index into RunSpec.solvers of the solver integrating it, -1 for none


@dataclass(frozen=True)
class EnergyFileSpec:
    """A VariationalSymplecticSolver's energy file (see loader._EnergyFile)."""

    path: str
    save: bool
    hamiltonian: bool
    energies: int  # buffer index of the last step's (kinetic, potential)


@dataclass(frozen=True)
class ContactSpec:
    models: tuple[str, ...]  # origin of each collision model
    pairs: int  # buffer indices (see plan.ContactGuard)
    touching: int


@dataclass(frozen=True)
class RunSpec:
    buffers: tuple[BufferSpec, ...]
    states: tuple[StateSpec, ...]  # SOFA's traversal order
    solvers: tuple[SolverSpec, ...]
    energy_files: tuple[EnergyFileSpec, ...]
    contact: ContactSpec | None
    init_only: frozenset[str]  # parameter keys read only when an instance is initialised
    pruned: dict[str, str]  # parameter key -> why its effect was compiled out
    threads: int
    rigid_model: str
    interactive: bool  # compiled with the point forces an interactive viewer pulls with
    rules: dict[str, ParamRule] = field(default_factory=dict)  # parameter key -> its field's rule
    # Compiled contacts: (pipeline origin, buffer index of its contactReport), per pipeline.
    contact_reports: tuple[tuple[str, int], ...] = ()
    # Buffers the step may grow (Lagrangian contacts' constraint problem past its reserved rows):
    # their views are taken again after a step that grew them.
    growable: tuple[int, ...] = ()

    def index(self, key: str) -> int:
        return next(i for i, b in enumerate(self.buffers) if b.key == key)


def run_spec(scene_plan: Plan) -> RunSpec:
    """The run-time part of a plan."""
    from sofac.plan.ir import origin_of

    index = {id(b): i for i, b in enumerate(scene_plan.buffers)}
    solvers = tuple(
        SolverSpec(
            origin_of(g.solver),
            g.solver.type_name,
            g.scheme.value,
            g.direct,
            g.linear_solver.type_name if g.linear_solver is not None else "",
        )
        for g in scene_plan.groups
    )
    solver_of = {id(s): i for i, g in enumerate(scene_plan.groups) for s in g.states}
    unread = {id(s) for g in scene_plan.groups for s in g.unread}
    unread |= {id(m.child) for g in scene_plan.groups for m in g.mappings if m.mapped_when_near}
    states = tuple(
        StateSpec(
            s.path,
            sofa_name(s.component),
            s.datatype.name,
            s.datatype.coord_size,
            s.datatype.deriv_size,
            s.size,
            s.mapped,
            s.simulated,
            index[id(s.x)],
            index[id(s.v)],
            index[id(s.f)],
            id(s) in unread,
            solver_of.get(id(s), -1),
        )
        for s in scene_plan.states
    )
    energy_files = tuple(
        EnergyFileSpec(g.energy_file, g.save_energy, g.hamiltonian, index[id(g.variational["energies"])])
        for g in scene_plan.groups
        if g.energy_file
    )
    guard = scene_plan.contact_guard
    contact = (
        ContactSpec(
            tuple(origin for origin, _ in guard.models), index[id(guard.pairs)], index[id(guard.touching)]
        )
        if guard is not None
        else None
    )
    return RunSpec(
        tuple(BufferSpec(b.key, b.kind, b.role, b.initial) for b in scene_plan.buffers),
        states,
        solvers,
        energy_files,
        contact,
        frozenset(scene_plan.init_only),
        dict(scene_plan.pruned),
        scene_plan.threads,
        scene_plan.rigid_model,
        scene_plan.interactive,
        contact_reports=tuple(
            (c.origin, index[id(c.report)]) for c in scene_plan.collisions if c.report is not None
        ),
        growable=tuple(index[id(b)] for c in scene_plan.collisions for b in c.problem),
    )


def sofa_name(component: Component) -> str:
    """The name SOFA gives a component: its own, else class name + a per-node counter from 1."""
    if component.name:
        return component.name
    same = [c for c in component.node.objects if not c.name and c.type_name == component.type_name]
    return f"{component.type_name}{same.index(component) + 1}"
