"""The plan's vocabulary: typed data for the calls of a step, and nothing else.

A lowering describes each part of a step as :class:`Call` values — which runtime kernel, with
which template arguments and which arguments — built from buffers, numbers and a few named values
of the step's scope (:class:`Env`). No C++ text is made here: ``sofac.codegen`` alone spells these
out, and every pass that asks what a step touches reads :meth:`Call.buffers` instead of code.

Some calls are written once and placed several times, with other vectors each time (a mapping's
J is applied to velocities and to dx; a projection filters v, f, dx, ...): their moving parts are
:class:`Slot` values that code generation binds where it places the call.
"""

from __future__ import annotations

import dataclasses
import enum
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component, Node
from sofac.registry.datatypes import DataType


@dataclass(eq=False)
class Buffer:
    """An array the compiled instance owns, initialised from ``initial`` at creation."""

    ident: str  # the instance member's name (made from a counter and a sanitised field name)
    key: str  # name seen from Python: "<component path>.<field>"
    kind: str  # "f64" or "i64"
    initial: np.ndarray
    columns: int = 1  # row width of its numpy view
    role: str = "data"  # "state" (restored by reset), "param" (tunable), "data", "scratch"


# The DataTypes the runtime defines (runtime/sofac/types.h): states of other templates are refused.
COMPILED_DATATYPES = frozenset({"Vec1d", "Vec2d", "Vec3d", "Vec6d", "Rigid3d", "Rigid2d"})


class Env(enum.Enum):
    """Values in scope where a step's calls are placed (their C++ spelling is codegen's)."""

    ASSEMBLER = "assembler"  # the system matrix being assembled
    BAND = "band"  # BTDLinearSolver's block-tridiagonal matrix (runtime/sofac/beam.h)
    KFACT = "kfact"  # the stiffness factor of a product or an assembly
    MFACT = "mfact"  # the mass factor
    BFACT = "bfact"  # the damping factor
    FIXED = "fixed"  # the direct solver's marks of projected DOFs
    TIME = "time"  # the simulation time at the start of the step
    KINETIC = "kinetic"  # the energy sums being accumulated ...
    POTENTIAL = "potential"
    KINETIC_OUT = "kinetic_out"  # ... and their addresses, for kernels that add to both
    POTENTIAL_OUT = "potential_out"
    NONE = "none"  # an absent pointer
    CONTACTS = "contacts"  # the scene's penalty contacts, one per pipeline (runtime/sofac/penalty.h)
    LAGRANGIAN = "lagrangian"  # the scene's Lagrangian contacts (runtime/sofac/lagrangian_contact.h)


class FemMethod(enum.IntEnum):
    """The FEM force fields' ``method`` (small, large, polar, svd), as the runtime names it (fem.h)."""

    SMALL = 0
    LARGE = 1
    POLAR = 2
    SVD = 3


class SpringDamping(enum.Enum):
    """spring_forces' damping variant (kernels.h): Undamped when the plan proves every damping is 0."""

    UNDAMPED = "Undamped"
    DAMPED = "Damped"


class SpringFlags(enum.Enum):
    """spring_forces' flags variant (kernels.h): None when every spring is enabled and none is
    elongation-only, so the per-spring flags are not read."""

    NONE = "None"
    PER_SPRING = "PerSpring"


class Preconditioner(enum.Enum):
    """A PCGLinearSolver's preconditioner, as the runtime applies it (direct.h)."""

    NONE = "none"
    JACOBI = "jacobi"  # JacobiPreconditioner: the inverse diagonal
    BLOCK_JACOBI = "block_jacobi"  # BlockJacobiPreconditioner: inverse 3x3 diagonal blocks
    SSOR = "ssor"  # SSORPreconditioner
    # A direct solver's factorisation (also a WarpPreconditioner whose rotations stay the identity).
    FACTORIZATION = "factorization"


class Constant(enum.Enum):
    """Layout constants of the runtime, named rather than copied (their values live in C++)."""

    TETRA_LANES = "TETRA_LANES"


@dataclass(frozen=True)
class Slot:
    """A value bound where the call is placed.

    ``parent``/``child``: a mapping's input and output vectors of the kind being mapped (``input``
    picks a multi-mapping's parent; ``vector`` fixes the kind, as "dx"); ``vector``: the vector a
    projection filters; ``offset``/``input_offset``: where a state's (or a mapping input's) DOFs
    start in an assembled system."""

    name: str
    input: int = 0
    vector: str = ""


PARENT = Slot("parent")
CHILD = Slot("child")
VECTOR = Slot("vector")
OFFSET = Slot("offset")
INPUT_OFFSET = Slot("input_offset")


@dataclass(frozen=True)
class Count:
    """The number of items in a buffer (its size divided by ``per``)."""

    buffer: Buffer
    per: int = 1


@dataclass(frozen=True)
class Element:
    """One number of a buffer, read where the call runs (a tunable scalar)."""

    buffer: Buffer
    index: int = 0


@dataclass(frozen=True)
class Offset:
    """Where a state's DOFs start in an assembled system: an independent state's first row, or
    (``mapped``) rows past the assembler's mapped range that a mapping's J routes on."""

    value: int
    mapped: bool = False


@dataclass(frozen=True)
class Function:
    """A runtime function passed as an argument (an element-matrix kernel)."""

    name: str


@dataclass(frozen=True)
class LinearSystem:
    """A group's direct solver (its factorisation of this step's system matrix), by group ident:
    what LinearSolverConstraintCorrection solves with."""

    group: str


@dataclass(frozen=True)
class Aggregate:
    """A runtime struct built from arguments (a spring table, an element split)."""

    type: str
    fields: tuple[Arg, ...]
    templates: tuple[TemplateArg, ...] = ()


Arg = Union[Buffer, Count, Element, Offset, Function, LinearSystem, Aggregate, Slot, Env, bool, int, float]  # noqa: UP007
# str: a DataType name ("Vec3d"); the enums: a kernel's variant, spelt as the runtime's enum class
TemplateArg = Union[str, int, bool, Constant, SpringDamping, SpringFlags]  # noqa: UP007


@dataclass(frozen=True)
class Call:
    """One call of a runtime kernel; ``into``: the energy sum its result is added to."""

    kernel: str
    args: tuple[Arg, ...]
    templates: tuple[TemplateArg, ...] = ()
    into: Env | None = None
    # Only while the assembler records its pattern: a constant block (a fixed selection's J).
    while_recording: bool = False

    def buffers(self) -> Iterator[Buffer]:
        """Every buffer the call reads or writes."""
        for arg in self.args:
            yield from _buffers(arg)


@dataclass(frozen=True)
class Note:
    """A line of explanation among calls (which mapping a block of J rows comes from)."""

    text: str

    def buffers(self) -> Iterator[Buffer]:
        return iter(())


Statement = Union[Call, Note]  # noqa: UP007


def _buffers(arg: Any) -> Iterator[Buffer]:
    if isinstance(arg, Buffer):
        yield arg
    elif isinstance(arg, (Count, Element)):
        yield arg.buffer
    elif isinstance(arg, Aggregate):
        for field in arg.fields:
            yield from _buffers(field)


def kernel(name: str, *templates: TemplateArg) -> tuple[str, tuple[TemplateArg, ...]]:
    """A kernel name with its template arguments, for :func:`call`."""
    return name, templates


def call(function: str | tuple[str, tuple[TemplateArg, ...]], *args: Arg, into: Env | None = None) -> Call:
    """A kernel call: ``call("name", ...)`` or ``call(kernel("name", "Vec3d"), ...)``."""
    name, templates = (function, ()) if isinstance(function, str) else function
    return Call(name, tuple(_plain(name, arg) for arg in args), templates, into)


def _plain(name: str, arg: Any) -> Arg:
    """numpy scalars as Python numbers (they print as ``np.float64(...)``); anything that is not a
    plan argument (C++ text above all) is refused."""
    if isinstance(arg, np.generic):
        arg = arg.item()
    if not isinstance(arg, _ARG_TYPES):
        raise TypeError(f"{name}: {arg!r} is not a plan argument")
    return arg


_ARG_TYPES = (Buffer, Count, Element, Offset, Function, LinearSystem, Aggregate, Slot, Env, bool, int, float)


def bind(statement: Call, values: dict[Slot, Arg]) -> Call:
    """A call with its slots replaced by the values given for them (others left as they are)."""

    def bound(arg: Arg) -> Arg:
        if isinstance(arg, Slot):
            return values.get(arg, arg)
        if isinstance(arg, Aggregate):
            return Aggregate(arg.type, tuple(bound(f) for f in arg.fields), arg.templates)
        return arg

    return dataclasses.replace(statement, args=tuple(bound(a) for a in statement.args))


def recorded_once(statement: Call) -> Call:
    """A constant block of the assembled matrix: given while the assembler records its pattern."""
    return dataclasses.replace(statement, while_recording=True)


def buffers_of(statements: Iterator[Statement] | list[Statement]) -> set[str]:
    """The identifiers of the buffers a list of statements touches."""
    return {buffer.ident for statement in statements for buffer in statement.buffers()}


def as_json(value: Any) -> Any:
    """A plan value as JSON-ready data: buffers by identifier and key, arrays by shape, scene
    components by type and path, DataTypes by name."""
    if isinstance(value, CheckedComponent):
        value = value.component
    if isinstance(value, Component):
        return {"component": value.type_name, "path": value.path, "line": value.loc.line}
    if isinstance(value, Node):
        return {"node": value.path}
    if isinstance(value, DataType):
        return value.name
    if isinstance(value, Buffer):
        return {"buffer": value.ident, "key": value.key, "kind": value.kind, "role": value.role}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, np.ndarray):
        return {"shape": list(value.shape), "dtype": str(value.dtype)}
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if hasattr(value, "__dataclass_fields__"):
        fields = {name: as_json(getattr(value, name)) for name in value.__dataclass_fields__}
        return {"type": type(value).__name__, **fields}
    if isinstance(value, dict):
        return {str(k): as_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [as_json(v) for v in value]
    return value


# --- the plan: states, groups and their phases -------------------------------------------------


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


# The phases of a group's step, each a list of Ops (Group.init runs at creation and reset).
STEP_PHASES = ("forces", "accelerations", "mass_dx", "stiffness_dx", "assemble", "energy")


@dataclass
class Group:
    """One ODE solver and what it integrates."""

    solver: Component
    ident: str
    scheme: str  # "euler", "rk2", "rk4", "implicit"
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


@dataclass
class ContactGuard:
    """Collision models that could touch, while contact response is not compiled: before every
    step, each model's box (its state's points grown by its radius, its contactDistance and half
    the alarm distance, so that two boxes meet where SOFA's proximity test would pair them) is
    tested against the others', and the step stops before the first pair that touches. A run
    that ends without a stop had no contact: it is SOFA's, exactly."""

    models: list[tuple[str, StatePlan]]  # (origin, state) per collision model
    margins: Buffer  # per model: radius + contactDistance + half the intersection's alarm distance
    pairs: Buffer  # i64 (model, model) rows: the pairs SOFA would test
    boxes: Buffer  # scratch, 6 numbers per model
    touching: Buffer  # i64 [1]: the pair that stopped the step, -1 if none


# The phases of FreeMotionAnimationLoop's constraint step, in step order (each a list of Ops):
# J rows built on the constraints' states and carried up the mappings (applyJT), violations read
# from the free vectors, W from the corrections, the solve, then each correction's x, v update.
CONSTRAINT_PHASES = ("rows", "violation", "compliance", "solve", "correction")

# ``<loop>.constraint_report``: the solves (runtime record_solve: their count, the last one's
# iterations and residual, the solves that hit the iteration limit and the last such one's time,
# residual and iterations), then the seconds spent since creation or reset (steady clock) in each
# part of the step: the collision pipelines, the groups' free motion, each of CONSTRAINT_PHASES,
# and the groups' projections and mappings after the correction.
CONSTRAINT_REPORT_FIELDS = (
    "solves",
    "iterations",
    "residual",
    "limited_solves",
    "limited_time",
    "limited_residual",
    "limited_iterations",
    "detection_seconds",
    "free_motion_seconds",
    *(f"{phase}_seconds" for phase in CONSTRAINT_PHASES),
    "finish_seconds",
)


@dataclass
class Correction:
    """A constraint correction: how constraint forces on its (independent) state move it."""

    origin: str
    kind: str  # "uncoupled" (a per-DOF compliance) or "linear_solver" (A^-1 of the group's solve)
    state: StatePlan
    group: Group
    checked: CheckedComponent | None = None


@dataclass
class ConstraintPhase:
    """FreeMotionAnimationLoop: each group's solve is the free motion; then the constraint rows,
    their solve by the loop's constraint solver and the corrections; then projections and mappings.

    With no row (``capacity`` 0) every correction adds C Jᵀ 0 = 0: x = x_free, v = v_free, which is
    the groups' own step. Independent states without a correction are ``frozen``: SOFA never writes
    their free motion back, so they keep x and v (``saved`` holds them over the groups' step)."""

    loop: str  # origin of the FreeMotionAnimationLoop
    solver: str  # origin of the constraint solver ("" : none in the scene, SOFA's default BGS)
    method: str  # "block_gauss_seidel", "unbuilt_gauss_seidel", "nncg", "lcp"
    # maxIterations, tolerance, sor, regularization, scaleTolerance, allVerified (LCP: mu, minW...)
    settings: dict[str, Buffer]
    # f64 CONSTRAINT_REPORT_FIELDS: solves, iterations and residual of the last solve, solves that
    # hit the iteration limit, the time, residual and iterations of the last such solve (the run's
    # warning), and the seconds spent in each part of the step (with rows only)
    report: Buffer
    corrections: list[Correction] = field(default_factory=list)
    frozen: list[tuple[StatePlan, Group]] = field(default_factory=list)
    saved: dict[str, tuple[Buffer, Buffer]] = field(default_factory=dict)  # frozen state ident -> (x, v)
    capacity: int = 0  # constraint rows reserved (contacts' rows grow past it: CollisionPlan.problem)
    # Row blocks in row order: (first row, runtime Resolution, parameter, offset of its kept forces
    # in ``kept`` or -1, upper bound (stoppers' max, else 0)), and the forces kept across steps
    # (bilateral warm start).
    blocks: list[tuple[int, int, float, int, float]] = field(default_factory=list)
    kept: Buffer | None = None
    # Jacobian entries per constrained state (ident): (row, dof, derivative values), SOFA's
    # MatrixDeriv before it is sorted into rows.
    entries: dict[str, list[tuple[int, int, tuple[float, ...]]]] = field(default_factory=dict)
    solve: list[Op] = field(default_factory=list)  # the solver on W, dfree, f (after ``compliance``)
    rows: list[Op] = field(default_factory=list)
    violation: list[Op] = field(default_factory=list)
    compliance: list[Op] = field(default_factory=list)
    correction: list[Op] = field(default_factory=list)

    def calls(self) -> list[Statement]:
        return [c for phase in CONSTRAINT_PHASES for op in getattr(self, phase) for c in op.calls]

    def frozen_in(self, group: Group) -> list[StatePlan]:
        """A group's states that the phase keeps where they were."""
        return [state for state, owner in self.frozen if owner is group]


@dataclass
class CollisionModel:
    """A collision model of the pipeline, in SOFA's order (depth first below the pipeline's node)."""

    origin: str
    kind: str  # "triangle", "line", "point" or "sphere" (runtime ContactSide)
    state: StatePlan  # its points (Vec3d)
    elements: int  # triangles, edges, points or spheres
    cells: Buffer | None  # i64 triangles (3 per) or edges (2 per)
    contact_distance: float
    contact_stiffness: float
    moving: bool  # boxes follow the points (False: computed at the first step only)
    simulated: bool
    compute_normals: bool = True  # triangle models' computeNormals
    view: int = -1  # its place among the paired models of its kind (-1: in no pair)
    radii: Buffer | None = None  # sphere models: listRadius (spheres past it take `radius`)
    radius: float = 0.0
    flagged: int = 0  # triangle models: the leading triangles that get SOFA's flags (not quads')
    # LocalMinDistance's cones (runtime local_min_distance::PointCone / LineCone): i64 CSR
    # adjacency of the model's topology: points (triangles, edges, trianglesAroundVertex offsets
    # and items, edgesAroundVertex offsets and items), lines (triangles, trianglesAroundEdge
    # offsets and items); None: SOFA accepts without reading them.
    cone: tuple[Buffer, ...] | None = None
    both_side: bool = False  # triangle models' bothSide
    node_rank: int = 0  # depth-first index of its node (where a Lagrangian contact is placed)


@dataclass
class LazyPoints:
    """The points of a pipeline's collision models that nothing but their contacts reads, mapped
    by a linear mapping (each point a weighted sum of parent points): mapped only when a pair may
    meet. Before each detection the parent's box, grown by ``spread`` times its extent and
    ``rounding`` times its largest coordinate, encloses them (runtime penalty.h, LazyPoints); while
    no pair of enclosures can meet, the detection is skipped without mapping them."""

    origin: str  # the mapping
    models: list[int]  # the pipeline's models on these points
    parent_points: int
    spread: float  # the largest sum of a point's negative weights
    rounding: float  # |sum of weights - 1| and the sums' rounding, relative to the coordinates
    current: Call  # the points from the parent's positions
    previous: Call  # the points from ``saved``
    parent: Buffer  # the parent's positions
    saved: Buffer  # scratch: the parent's positions at the last detection that did not map them


@dataclass(frozen=True)
class ElementTest:
    """An element test of runtime/sofac/proximity.h, ``<method>::<kind>_<kind>``, with its flags
    after the two models (same_model, useLineLine, useSurfaceNormals)."""

    name: str
    options: tuple[bool, ...] = ()

    @property
    def kinds(self) -> tuple[str, str]:
        first, second = self.name.split("::")[1].split("_")
        return first, second


@dataclass
class ContactPair:
    """A model pair the broad phase can produce, models in the intersector's order."""

    first: int
    second: int
    test: int  # index in Collision.tests
    root: bool  # both simulated: one explicit force per step (SOFA places it at the pipeline's node)
    id_bound: int  # the outputs' ids are below it (the de-duplication's table)


REPORT_FIELDS = (
    "contacts",
    "growths",
    "degenerate",
    "detection_seconds",
    "response_seconds",
    "fast_motions",
    "unmapped_detections",
)


@dataclass
class Collision:
    """Detection and penalty response of a DefaultAnimationLoop scene, run before the groups step."""

    origin: str  # the pipeline
    method: str  # "new_proximity" or "min_proximity"
    alarm_distance: float
    contact_distance: float
    depth: int  # the bounding trees' depth (BVHNarrowPhase needs deep trees)
    models: list[CollisionModel]
    tests: list[ElementTest]  # those the pairs use, each compiled once
    pairs: list[ContactPair]
    # i64 rows (first, second, root, id_bound, test, first's view, second's view), one per pair
    table: Buffer | None = None
    # What the steps found, as ``<pipeline>.contactReport`` (REPORT_FIELDS): the last step's
    # contacts; since the instance was created or reset, buffers that outgrew their capacity,
    # degenerate outputs (NaN dropped or zero distance), the seconds spent in detection and in
    # response, the pairs a model came near after moving farther than the detection's reach, and
    # the detections that left the points mapped when near (``lazy``) unmapped.
    report: Buffer | None = None
    # Why each other pair of models gets no code: ((first origin, second origin), reason).
    left_out: list[tuple[str, str, str]] = field(default_factory=list)
    # "penalty" (DefaultAnimationLoop) or "friction_contact" (FrictionContactConstraint under
    # FreeMotionAnimationLoop: its contacts are rows of the constraint phase, lagrangian_contact.h)
    response: str = "penalty"
    mu: float = 0.0  # FrictionContact's mu (0: one row per contact)
    # LocalMinDistance: filterIntersection, angleCone, coneFactor, useLMDFilters
    lmd: tuple[bool, float, float, bool] | None = None
    # friction_contact: the rank of each pair's placement node, and the constraint rows reserved
    ranks: list[int] = field(default_factory=list)
    row_capacity: int = 0
    static_rows: int = 0  # the scene's own constraint rows, before the contacts'
    # friction_contact, per model: (correction index or -1, free positions, frames, offsets, subset
    # indices: RigidMapping's frames and offsets, or an identity/subset mapping's parent DOFs)
    bodies: list[tuple[int, Buffer | None, Buffer | None, Buffer | None, Buffer | None]] = field(
        default_factory=list
    )
    # friction_contact: the constraint problem's buffers sized by the rows (W, dfree, f, d, scratch),
    # grown with the capacity when a step's contacts outgrow it (lagrangian_fit)
    problem: list[Buffer] = field(default_factory=list)
    lazy: list[LazyPoints] = field(default_factory=list)  # penalty: points mapped only when near


@dataclass
class Plan:
    scene_file: str
    dt: Buffer
    gravity: Buffer
    buffers: list[Buffer]
    states: list[StatePlan]  # all MechanicalObjects, SOFA traversal order
    groups: list[Group]
    ignored: list[tuple[Component, str]]  # components kept out of the step, and why
    # Effects left out because the scene makes them vanish (parameter key -> why); changing such a
    # parameter at run time needs a recompilation (load(..., prune=False) keeps them).
    pruned: dict[str, str] = field(default_factory=dict)
    effects: list[tuple[str, str, str]] = field(default_factory=list)  # (effect, origin, detail)
    # Parameters read only when an instance is initialised (element stiffness from youngModulus...):
    # a change takes effect at the next reset(), which the Python API enforces.
    init_only: frozenset[str] = frozenset()
    # OpenMP threads for large element loops and independent groups (1: serial, built without OpenMP)
    threads: int = 1
    rigid_model: str = "sofa"  # how rigid bodies were compiled (plan_scene's rigid_model)
    contact_guard: ContactGuard | None = None
    collisions: list[Collision] = field(default_factory=list)  # compiled contacts, one per pipeline
    # Compiled for threads, with groups that share no buffer: they step side by side.
    parallel_groups: bool = False
    interactive: bool = False  # with a point force on each state, set from Python (plan_scene)
    constraints: ConstraintPhase | None = None  # FreeMotionAnimationLoop's constraint phase

    def buffer(self, key: str) -> Buffer:
        for buffer in self.buffers:
            if buffer.key == key:
                return buffer
        raise KeyError(key)


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


def origin_of(component: Component) -> str:
    """A one-line, comment-safe description of a component: type, path, file and line."""
    text = f"{component.type_name} {component.path!r} ({component.loc.file}:{component.loc.line})"
    return re.sub(r"[^\x20-\x7e]", "?", text).replace("*/", "*?")
