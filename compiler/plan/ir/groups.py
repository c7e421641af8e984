"""The plan's states and solver groups: each ODE solver's group with the phases of its step, as
lists of :class:`Op` (a component's calls and where it comes from)."""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.registry.datatypes import DataType

from .calls import Buffer, Call, Offset, Preconditioner, Statement


@dataclass
class Op:
    """One component's part of a phase of the step: its calls, and where it comes from."""

    origin: str  # "TypeName 'path' (file:line)"
    calls: list[Statement]


@dataclass
class MappingOp:
    """A mechanical mapping: how x and v go down, and J / Jᵀ for any pair of vectors (calls with
    the PARENT and CHILD slots, bound to the vectors of the kind being mapped)."""

    origin: str
    parent: StatePlan
    child: StatePlan
    apply: list[Call]  # x and v of the child from the parent's
    jacobian: Call  # child = J parent
    transpose: Call | None  # parent += Jᵀ child; None: mapForces="0"
    # Non-linear mappings: parent df += kfact dJᵀ/dx(child force) parent dx.
    geometric: Call | None = None
    # Assembled systems: J's rows for the assembler, at OFFSET (the child's first row past
    # Assembler::kMapped) from INPUT_OFFSET (the parent's); None: J is not assembled yet.
    assembly: list[Call] | None = None
    inputs: tuple[StatePlan, ...] = ()  # a multi-mapping's other parents (Slot("parent", input=1)...)
    # A collision models' state that only their contacts read: J and J^T of forces and products run
    # only while one of its models, (pipeline, model) each, is in contact.
    while_in_contact: tuple[tuple[int, int], ...] = ()
    # ... and its x and v too (the pipeline maps x when a pair may meet, Python maps it on read:
    # Collision.lazy).
    mapped_when_near: bool = False
    # A BarycentricMapping whose table pads short elements (tetrahedra among hexahedra): each
    # output point's number of real columns, the leading ones (constraint rows carried through
    # applyJT take only these); None: every column is real.
    element_nodes: Buffer | None = None


@dataclass
class Projection:
    """A projective constraint: zeroes the constrained part of a derivative-shaped vector (calls
    with the VECTOR slot)."""

    origin: str
    state: StatePlan
    project: Call | None  # None: responses are left alone (a constraint on positions only)
    velocity: bool = False  # also projects the velocity after the update
    # Direct solvers: marks the constrained scalar DOFs of the assembled matrix (at OFFSET).
    mark: Call | None = None
    # projectPosition: coordinates moved onto the constraint after each step and at init.
    position: Call | None = None
    # projectVelocity, when it is not ``project`` (an imposed velocity rather than a filter).
    project_velocity: Call | None = None


@dataclass
class StatePlan:
    component: Component
    ident: str
    datatype: DataType
    size: int
    mapped: bool
    x: Buffer
    v: Buffer
    f: Buffer
    rest: Buffer | None  # None when no call reads it (passes.drop_unread_rest_positions)
    simulated: bool = False  # an ODE solver in its node or above
    acc: Buffer | None = None  # a = M⁻¹ f (explicit) or Δv (implicit), independent states only
    dx: Buffer | None = None  # implicit schemes: the vector a matrix-free product reads ...
    df: Buffer | None = None  # ... and the one it writes
    mass: Any = None  # (Buffer, stride) of the mass acting on it, if any
    # Runge-Kutta stage vectors (x0, v0 and, for RK4, the sums dx, dv), only where a scheme needs them.
    stages: dict[str, Buffer] = field(default_factory=dict)

    @property
    def path(self) -> str:
        return self.component.path


class Scheme(enum.StrEnum):
    """How a group integrates: its ODE solver's family (static, Newmark and variational solvers
    are implicit schemes: same stiffness and solves, their own algorithm)."""

    EULER = "euler"  # explicit or symplectic Euler
    RK2 = "rk2"
    RK4 = "rk4"
    IMPLICIT = "implicit"


# The phases of a group's step, each a list of Ops (Group.init runs at creation and reset).
STEP_PHASES = ("forces", "accelerations", "mass_dx", "stiffness_dx", "assemble", "energy")


@dataclass
class Group:
    """One ODE solver and what it integrates."""

    solver: Component
    ident: str
    scheme: Scheme
    symplectic: bool
    states: list[StatePlan] = field(default_factory=list)  # independent
    mapped: list[StatePlan] = field(default_factory=list)  # parent → child order
    mappings: list[MappingOp] = field(default_factory=list)  # parent → child order
    # Mapped states nothing in the step reads (no mass, force field, constraint or read mapping
    # child acts on them), and their mappings: left out of the step, run only when Python reads
    # such a state (sofac_update_mapped). Parent → child order.
    unread: list[StatePlan] = field(default_factory=list)
    on_read: list[MappingOp] = field(default_factory=list)
    forces: list[Op] = field(default_factory=list)  # force fields and gravity
    accelerations: list[Op] = field(default_factory=list)  # a = M⁻¹ f (explicit schemes)
    projections: list[Projection] = field(default_factory=list)
    mass_dx: list[Op] = field(default_factory=list)  # df += mfact M dx (implicit)
    stiffness_dx: list[Op] = field(default_factory=list)  # df += kfact K dx (implicit)
    energy: list[Op] = field(default_factory=list)
    init: list[Op] = field(default_factory=list)  # once, when an instance is created or reset
    # Implicit Euler: parameter buffers (rayleighStiffness, rayleighMass, vdamping) and the linear solver.
    implicit: dict[str, Buffer] = field(default_factory=dict)
    linear_solver: Component | None = None
    cg: dict[str, Buffer] = field(default_factory=dict)  # iterations, tolerance, threshold, solves done
    assembled_cg: bool = False  # CGLinearSolver on an assembled matrix (a template other than GraphScattered)
    trapezoidal: bool = False  # EulerImplicitSolver's trapezoidalScheme (factor 1/2 on some h)
    factor_once: bool = False  # PrecomputedLinearSolver: the first step's factorisation is kept
    llt: bool = False  # the direct solver factors L L^T (registry role "llt"), else L D L^T
    # SVDLinearSolver (registry role "svd"): a dense SVD instead; its minSingularValue buffer.
    svd_threshold: Buffer | None = None
    assembled: bool = False  # it has an assembled system matrix: components record their blocks
    direct: bool = False  # the step solves with it (implicit; explicit with a non-diagonal mass)
    btd: bool = False  # BTDLinearSolver: the direct solve is the block-tridiagonal Thomas algorithm (6x6)
    pcg: dict[str, Buffer] = field(default_factory=dict)  # PCGLinearSolver: iterations, tolerance
    minres: dict[str, Buffer] = field(default_factory=dict)  # MinResLinearSolver: iterations, tolerance
    preconditioner: Preconditioner = Preconditioner.NONE
    ssor_omega: Buffer | None = None
    # A PCGLinearSolver's PrecomputedWarpPreconditioner: SOFA's apply leaves the output as it was,
    # so the PCG stops before its first iteration and dv keeps its start (pcg is then empty).
    inert_preconditioner: Component | None = None
    # The solvers the PCG's preconditioner runs (a direct solver; WarpPreconditioner and its inner
    # direct solver): part of the step, not kept out.
    preconditioners: list[Component] = field(default_factory=list)
    assemble: list[Op] = field(default_factory=list)  # A += mfact M + kfact K, block by block
    # StaticSolver (an "implicit" group: same stiffness and solves): its NewtonRaphsonSolver's
    # parameters; empty for a time integrator.
    static: dict[str, Buffer] = field(default_factory=dict)
    # NewmarkImplicitSolver (also "implicit"): gamma, beta, and a flag set once the initial
    # acceleration is computed; empty for other solvers.
    newmark: dict[str, Buffer] = field(default_factory=dict)
    # VariationalSymplecticSolver (also "implicit"): newtonError, steps, the Hamiltonian outputs and
    # a flag set once the momentum is initialised; empty for other solvers.
    variational: dict[str, Buffer] = field(default_factory=dict)
    # BDFOdeSolver (also "implicit"): its order, the time list and counts it keeps between steps,
    # room for its coefficients, and its NewtonRaphsonSolver's parameters; empty for other solvers.
    bdf: dict[str, Buffer] = field(default_factory=dict)
    # CentralDifferenceSolver (an "euler" group, symplectic): its rayleighMass; None for EulerExplicit.
    central_difference: Buffer | None = None
    hamiltonian: bool = False  # computeHamiltonian: one more solve per step, with M alone
    incremental_potential: bool = True  # useIncrementalPotentialEnergy
    # saveEnergyInFile: the CSV file the loader writes the energies to ("" = none); SOFA opens (and
    # empties) `file` at init even when it writes nothing, hence the separate flag.
    energy_file: str = ""
    save_energy: bool = False
    first_order: bool = False  # EulerImplicitSolver's firstOrder: (M - h K) v = f, x += h v

    # Assembled systems: the mapped states whose blocks go through their mappings' J, with their
    # first index past Assembler::kMapped and the component that first needed it (for diagnostics).
    routed: dict[int, tuple[StatePlan, int, CheckedComponent]] = field(default_factory=dict)

    def calls(self, phases: tuple[str, ...] = (*STEP_PHASES, "init")) -> list[Statement]:
        """The calls of some of the group's phases (default: all of them, init included)."""
        return [c for phase in phases for op in getattr(self, phase) for c in op.calls]

    @property
    def preconditioned(self) -> bool:
        """A PCGLinearSolver with an assembled preconditioner."""
        return self.preconditioner is not Preconditioner.NONE

    def offset(self, state: StatePlan) -> int | None:
        """Where an independent state's DOFs start in the assembled system (None: mapped)."""
        start = 0
        for other in self.states:
            if other is state:
                return start
            start += other.size * other.datatype.deriv_size
        return None

    def assembly_offset(self, state: StatePlan, checked: CheckedComponent) -> Offset:
        """Where a state's DOFs start for the assembler: an independent state's offset, or, for a
        mapped one, indices past Assembler::kMapped that J routes to the independent DOFs."""
        offset = self.offset(state)
        if offset is not None:
            return Offset(offset)
        if id(state) not in self.routed:
            start = sum(s.size * s.datatype.deriv_size for s, _, _ in self.routed.values())
            self.routed[id(state)] = (state, start, checked)
        return Offset(self.routed[id(state)][1], mapped=True)

    @property
    def system_size(self) -> int:
        return sum(s.size * s.datatype.deriv_size for s in self.states)

    @property
    def cg_block(self) -> int:
        """An assembled CG's block size: rows of 3x3 blocks when every state's derivatives come
        in threes (the product's numbers do not depend on it), else scalar rows."""
        return 3 if all(s.datatype.deriv_size % 3 == 0 for s in self.states) else 1


def group_buffers(group: Group) -> set[str]:
    """The identifiers of every buffer a group's step touches: its states' vectors, its solver's
    parameters, and the buffers of its calls."""
    found: set[str] = set()
    seen: set[int] = set()

    def visit(value: Any) -> None:
        if id(value) in seen or isinstance(value, (Component, CheckedComponent, DataType, np.ndarray, str)):
            return
        seen.add(id(value))
        if isinstance(value, Buffer):
            found.add(value.ident)
        elif dataclasses.is_dataclass(value):
            for item in dataclasses.fields(value):
                visit(getattr(value, item.name))
        elif isinstance(value, dict):
            for item in value.values():
                visit(item)
        elif isinstance(value, (list, tuple)):
            for item in value:
                visit(item)

    visit(group)
    return found


def independent_groups(groups: list[Group], shared: set[str]) -> bool:
    """Whether there are several groups and no two of them touch a common buffer, except the
    ``shared`` parameters every group reads (dt, gravity)."""
    if len(groups) < 2:
        return False
    used: set[str] = set()
    for group in groups:
        touched = group_buffers(group) - shared
        if touched & used:
            return False
        used |= touched
    return True
