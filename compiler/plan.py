"""Plan stage: what SOFA's visitors would do each step, worked out once from a checked scene.

The plan is a small IR: the arrays the compiled instance owns (state vectors, parameters, bulk
data such as spring lists), the mechanical states in SOFA's traversal order, and for each ODE
solver its *group* (section 5.1 of the SOFA introduction): the independent states it integrates,
the mapped states below them in parent → child order, and the kernel calls of one step
(propagate down the mappings, accumulate forces, map forces up with Jᵀ, a = M⁻¹f, project).

Each component is lowered by the function its spec names (``ComponentSpec.kernel``); a component
that takes part in the step but has no lowering is reported as unsupported (E222), with its line.
Nothing from the scene text reaches C++: identifiers are made here from counters, and every
number and array is a buffer handed to the instance when it is created.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .check import CheckedComponent, CheckedScene
from .diagnostics import Diagnostics, SceneError
from .fem_topology import CELL_KINDS
from .model import Component, Node
from .registry import Category
from .registry.components.common import GRAPH_SCATTERED
from .registry.datatypes import DATATYPES, DataType

# C++ DataTypes names in runtime/sofac/types.h, by canonical template.
CPP_TYPES = {name: name for name in ("Vec1d", "Vec2d", "Vec3d", "Vec6d", "Rigid3d", "Rigid2d")}

# Categories whose components run inside the step and therefore need a lowering.
_STEP_CATEGORIES = frozenset(
    {
        Category.STATE,
        Category.MASS,
        Category.FORCEFIELD,
        Category.INTERACTION_FORCEFIELD,
        Category.PROJECTIVE_CONSTRAINT,
        Category.LAGRANGIAN_CONSTRAINT,
        Category.CONSTRAINT_SOLVER,
        Category.CONSTRAINT_CORRECTION,
        Category.ODE_SOLVER,
        Category.MAPPING,
        Category.MULTI_MAPPING,
    }
)


@dataclass
class Buffer:
    """An array the compiled instance owns, initialised from ``initial`` at creation."""

    ident: str  # C++ member name
    key: str  # name seen from Python: "<component path>.<field>"
    kind: str  # "f64" or "i64"
    initial: np.ndarray
    columns: int = 1  # row width of its numpy view
    role: str = "data"  # "state" (restored by reset), "param" (tunable), "data", "scratch"


@dataclass
class Op:
    """C++ statements of one component's part of the step, with where it comes from."""

    origin: str  # "TypeName 'path' (file:line)"
    code: list[str]


@dataclass
class MappingOp:
    """A mechanical mapping: how x and v go down, and J / Jᵀ for any pair of vectors."""

    origin: str
    parent: StatePlan
    child: StatePlan
    apply: list[str]  # x and v of the child from the parent's
    jacobian: Callable[[Buffer, Buffer], str]  # (parent vector, child vector) -> child = J parent
    transpose: Callable[[Buffer, Buffer], str] | None  # parent += Jᵀ child; None: mapForces="0"
    # Non-linear mappings: (parent dx, parent df) -> parent df += kfact dJᵀ/dx(child force) dx.
    geometric: Callable[[Buffer, Buffer], str] | None = None
    # Assembled systems: (child's first index, parent's first index) -> the code giving J's rows to
    # the assembler (Assembler::kMapped); None: a mapping whose J is not assembled yet.
    assembly: Callable[[str, str], str] | None = None


@dataclass
class Projection:
    """A projective constraint: zeroes the constrained part of a derivative-shaped vector."""

    origin: str
    state: StatePlan
    project: Callable[[Buffer], str]
    velocity: bool = False  # also projects the velocity after the update
    # Direct solvers: marks the constrained scalar DOFs of the assembled matrix (state offset -> code).
    mark: Callable[[int], str] | None = None
    # projectPosition: coordinates moved onto the constraint after each step and at init.
    position: Callable[[Buffer], str] | None = None
    # projectVelocity, when it is not ``project`` (an imposed velocity rather than a filter).
    project_velocity: Callable[[Buffer], str] | None = None


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
    rest: Buffer
    simulated: bool = False  # an ODE solver in its node or above
    acc: Buffer | None = None  # a = M⁻¹ f (explicit) or Δv (implicit), independent states only
    dx: Buffer | None = None  # implicit schemes: the vector a matrix-free product reads ...
    df: Buffer | None = None  # ... and the one it writes
    mass: Any = None  # (Buffer, stride) of the mass acting on it, if any
    # Runge-Kutta stage vectors (x0, v0 and, for RK4, the sums dx, dv), only where a scheme needs them.
    stages: dict[str, Buffer] = field(default_factory=dict)

    @property
    def cpp_type(self) -> str:
        return "sofac::" + CPP_TYPES[self.datatype.name]

    @property
    def path(self) -> str:
        return self.component.path


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
    assembled: bool = False  # it has an assembled system matrix: components record their blocks
    direct: bool = False  # the step solves with it (implicit; explicit with a non-diagonal mass)
    # PCGLinearSolver: iterations, tolerance; preconditioner (0: none, 1: Jacobi, 3: block Jacobi, -1: SSOR)
    pcg: dict[str, Buffer] = field(default_factory=dict)
    minres: dict[str, Buffer] = field(default_factory=dict)  # MinResLinearSolver: iterations, tolerance
    preconditioner: int = 0
    ssor_omega: Buffer | None = None
    # A PCGLinearSolver's PrecomputedWarpPreconditioner: SOFA's apply leaves the output as it was,
    # so the PCG stops before its first iteration and dv keeps its start (pcg is then empty).
    inert_preconditioner: Component | None = None
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

    def offset(self, state: StatePlan) -> int | None:
        """Where an independent state's DOFs start in the assembled system (None: mapped)."""
        start = 0
        for other in self.states:
            if other is state:
                return start
            start += other.size * other.datatype.deriv_size
        return None

    def assembly_offset(self, state: StatePlan, checked: CheckedComponent) -> str:
        """Where a state's DOFs start for the assembler: an independent state's offset, or, for a
        mapped one, indices past Assembler::kMapped that J routes to the independent DOFs."""
        offset = self.offset(state)
        if offset is not None:
            return str(offset)
        if id(state) not in self.routed:
            start = sum(s.size * s.datatype.deriv_size for s, _, _ in self.routed.values())
            self.routed[id(state)] = (state, start, checked)
        return f"sofac::Assembler::kMapped + {self.routed[id(state)][1]}"

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

    def buffer(self, key: str) -> Buffer:
        for buffer in self.buffers:
            if buffer.key == key:
                return buffer
        raise KeyError(key)


def origin_of(component: Component) -> str:
    """A one-line, comment-safe description of a component: type, path, file and line."""
    text = f"{component.type_name} {component.path!r} ({component.loc.file}:{component.loc.line})"
    return re.sub(r"[^\x20-\x7e]", "?", text).replace("*/", "*?")


class _Planner:
    def __init__(
        self,
        checked: CheckedScene,
        diagnostics: Diagnostics,
        prune: bool = True,
        rigid_model: str = "sofa",
        threads: int = 1,
    ) -> None:
        self.checked = checked
        self.diags = diagnostics
        self.prune = prune
        self.rigid_model = rigid_model
        self.threads = threads
        self.guarded: list[CheckedComponent] = []  # collision models that could touch (ContactGuard)
        self.guard: ContactGuard | None = None
        self.pruned: dict[str, str] = {}  # parameter key -> why the code using it was left out
        self.refused: set[int] = set()  # components whose one refusal says all (no follow-up E222)
        self.lowered: list[Component] = []  # components whose kernels are in the step
        self.buffers: list[Buffer] = []
        self.buffer_count = 0  # buffers ever made: identifiers stay unique when one is dropped
        self.states: dict[int, StatePlan] = {}
        self.ignored: list[tuple[Component, str]] = []

    # --- helpers -------------------------------------------------------------------------------
    def value(self, component: Component, name: str) -> Any:
        return self.checked.value(component, name)

    def buffer(
        self,
        owner: Component | str,
        name: str,
        data: Any,
        kind: str = "f64",
        columns: int = 1,
        role: str = "data",
    ) -> Buffer:
        array = np.ascontiguousarray(
            np.asarray(data, dtype=np.float64 if kind == "f64" else np.int64).ravel()
        )
        key = f"{owner if isinstance(owner, str) else owner.path}.{name}"
        ident = f"b{self.buffer_count}_{re.sub(r'[^A-Za-z0-9]', '_', name)[:24]}"
        buffer = Buffer(ident, key, kind, array, columns, role)
        self.buffers.append(buffer)
        self.buffer_count += 1
        return buffer

    def add_gravity(self, group: Group, op: Op) -> None:
        """A mass's weight, unless gravity is zero and pruning is on (then no code at all)."""
        if self.prune and not self.gravity.initial.any():
            self.pruned.setdefault(self.gravity.key, "gravity is zero: no weight computed")
            return
        group.forces.append(op)

    def unsupported(self, checked: CheckedComponent, why: str) -> None:
        component = checked.component
        if id(component) in self.refused:
            return
        self.diags.add(
            "E222",
            component.loc,
            f"unsupported component {component.type_name} at line {component.loc.line}: {why}",
            "sofac check --allow-unsupported validates such scenes without compiling them",
        )

    # --- run -----------------------------------------------------------------------------------
    def run(self) -> Plan:
        root = self.checked.scene.root
        dt = float(self.value_node(root, "dt"))
        gravity = np.asarray(self.value_node(root, "gravity"), dtype=float)
        for checked in self.checked:
            if checked.spec and checked.spec.role == "gravity":
                if checked.component.node is root:
                    gravity = np.asarray(self.value(checked.component, "gravity"), dtype=float)
                else:
                    self.unsupported(checked, "a Gravity component below the root is not compiled yet")
        self.dt = self.buffer("/", "dt", [dt], role="param")
        self.gravity = self.buffer("/", "gravity", gravity, columns=3, role="param")
        self._screen()
        for checked in self.checked.states():
            self._plan_state(checked)
        groups = self._groups()
        if self.diags.has_errors():
            raise SceneError(self.diags.sorted())
        solving = {id(g.linear_solver) for g in groups if g.linear_solver is not None}  # in the step
        self.ignored = [(component, why) for component, why in self.ignored if id(component) not in solving]
        return Plan(
            scene_file=str(self.checked.scene.file),
            dt=self.dt,
            gravity=self.gravity,
            buffers=self.buffers,
            states=[self.states[id(c.component)] for c in self.checked.states()],
            groups=groups,
            ignored=self.ignored,
            pruned=self.pruned,
            effects=self._effects(groups),
            init_only=self._init_only(groups),
            threads=self.threads,
            rigid_model=self.rigid_model,
            contact_guard=self.guard,
        )

    def _init_only(self, groups: list[Group]) -> frozenset[str]:
        """The parameters the init code reads and no per-step code does."""

        def code(kinds: tuple[str, ...]) -> str:
            return "\n".join(
                line for g in groups for kind in kinds for op in getattr(g, kind) for line in op.code
            )

        init = code(("init",))
        step = code(("forces", "accelerations", "mass_dx", "stiffness_dx", "assemble", "energy"))
        return frozenset(
            buffer.key
            for buffer in self.buffers
            if buffer.role == "param"
            and re.search(rf"S\.{buffer.ident}\b", init)
            and not re.search(rf"S\.{buffer.ident}\b", step)
        )

    def _effects(self, groups: list[Group]) -> list[tuple[str, str, str]]:
        """What the compiled step does and why: one line per effect, naming its component."""
        effects = []
        for group in groups:
            states = ", ".join(s.path for s in group.states)
            scheme = (
                "static (Newton-Raphson)"
                if group.static
                else "Newmark"
                if group.newmark
                else "variational symplectic"
                if group.variational
                else group.scheme
            )
            effects.append(("integration", origin_of(group.solver), f"{scheme} scheme over {states}"))
            linear = group.linear_solver
            if linear is not None and all(linear is not c for c in self.lowered):
                effects.append(("linear_solve", origin_of(linear), f"solves the system of {states}"))
        if self.gravity.key not in self.pruned:
            effects.append(
                ("gravity", "root node", f"g = {self.gravity.initial.tolist()}, applied by the masses")
            )
        kept_out = {id(component) for component, _ in self.ignored}
        on_read: list[tuple[str, str, str]] = []
        for group in groups:
            for state in group.unread:
                mapping = self.checked.mapping_of(state.component)
                assert mapping is not None
                kept_out.add(id(mapping.component))
                on_read.append(
                    (
                        "computed on read",
                        origin_of(mapping.component),
                        f"nothing in the step reads {state.path} (no mass, force field, constraint or "
                        "mapping to one acts on it): mapped only when read (state views, WriteState, "
                        "regress), not in the step",
                    )
                )
        for component in self.lowered:
            if id(component) in kept_out:
                continue
            spec = self.checked.of(component).spec
            assert spec is not None
            for effect in sorted(e.value for e in spec.effects):
                if effect == "gravity" and self.gravity.key in self.pruned:
                    continue
                effects.append((effect, origin_of(component), spec.category.value))
        if self.guard is not None:
            for origin, state in self.guard.models:
                effects.append(
                    (
                        "collision",
                        origin,
                        f"contact guard on {state.path}: its box is tested against the other models' "
                        "before each step, which stops before a contact (response not compiled)",
                    )
                )
        for key, why in self.pruned.items():
            effects.append(("pruned", key, why))
        effects.extend(on_read)
        for component, why in self.ignored:
            effects.append(("kept out", origin_of(component), why))
        return effects

    def value_node(self, node: Node, name: str) -> Any:
        from .registry import node_spec

        spec = node_spec()
        attribute = node.attributes.get(name)
        field_spec = spec.field(name)
        assert field_spec is not None
        return field_spec.type.parse(attribute.value) if attribute else field_spec.default

    def _screen(self) -> None:
        """Every component that takes part in the step must have a lowering."""
        has_pipeline = any(c.category is Category.COLLISION_PIPELINE for c in self.checked)
        contacts = has_pipeline and self._contacts_possible()
        models = [c for c in self.checked if c.category is Category.COLLISION_MODEL]
        # Models of different nodes could touch: guarded (the step stops before a contact), unless
        # a model may touch itself, which a box cannot rule out.
        guard = contacts and not any(self.value(c.component, "selfCollision") for c in models)
        for checked in self.checked:
            spec = checked.spec
            if spec is None:
                continue
            if checked.category is Category.COLLISION_MODEL and contacts and guard:
                if self.value(checked.component, "active") is not False:
                    self.guarded.append(checked)  # an effect of the step (see _contact_guard)
                else:
                    self.ignored.append((checked.component, "inactive collision model"))
            elif checked.category is Category.COLLISION_MODEL and contacts:
                self.unsupported(checked, "self-collision detection and response are not compiled yet")
            elif checked.category is Category.TOPOLOGICAL_MAPPING and self._feeds_a_state(checked):
                self.unsupported(checked, "its output topology sizes a MechanicalObject; not evaluated yet")
            elif checked.category is Category.COLLISION_MODEL:
                self.ignored.append(
                    (checked.component, "no other collision model to touch: no contact possible")
                )
            elif checked.category in _STEP_CATEGORIES and not spec.kernel:
                if self._is_visual_mapping(checked):
                    self.ignored.append((checked.component, "visual mapping: computed only for rendering"))
                    continue
                self.unsupported(checked, f"sofac cannot compile {spec.name} yet")
            elif checked.category not in _STEP_CATEGORIES:
                self.ignored.append((checked.component, f"{checked.category.value}: no part in the step"))

    def _feeds_a_state(self, checked: CheckedComponent) -> bool:
        """Its output topology is what sizes a MechanicalObject (whose points are then unknown)."""
        output = checked.links.get("output")
        node = output.node if isinstance(output, Component) else None
        return node is not None and any(
            self.checked.of(c).category is Category.STATE and self.checked.positions(c) is None
            for c in node.objects
        )

    def _contacts_possible(self) -> bool:
        """SOFA tests pairs of collision models of different nodes (of one node: selfCollision)."""
        models = [c for c in self.checked if c.category is Category.COLLISION_MODEL]
        nodes = {id(c.component.node) for c in models}
        return len(nodes) > 1 or any(self.value(c.component, "selfCollision") for c in models)

    def _is_visual_mapping(self, checked: CheckedComponent) -> bool:
        output = checked.links.get("output")
        return (
            checked.category is Category.MAPPING
            and isinstance(output, Component)
            and self.checked.of(output).category is Category.VISUAL
        )

    # --- states --------------------------------------------------------------------------------
    def _plan_state(self, checked: CheckedComponent) -> None:
        component = checked.component
        datatype = checked.datatype or DATATYPES["Vec3d"]
        if datatype.name not in CPP_TYPES:
            self.unsupported(checked, f"template {datatype.name} is not compiled yet")
            return
        positions = self.checked.positions(component)
        if positions is None:
            positions = np.zeros((self._mapped_size(component), datatype.coord_size))
        n = len(positions)
        velocity = self.value(component, "velocity")
        v = np.zeros((n, datatype.deriv_size))
        if velocity is not None and np.size(velocity):
            given = np.asarray(velocity, dtype=float).reshape(-1, datatype.deriv_size)
            v[: min(n, len(given))] = given[: min(n, len(given))]
            if len(given) == 1 and n > 1:
                v[:] = given[0]
        rest_written = component.get("rest_position")
        rest = positions
        if rest_written is not None:
            rest_value = self.value(component, "rest_position")
            if rest_value is not None and np.size(rest_value) == positions.size:
                rest = np.asarray(rest_value, dtype=float).reshape(positions.shape)
        ident = f"s{len(self.states)}"
        mapped = self.checked.mapping_of(component) is not None
        state = StatePlan(
            component=component,
            ident=ident,
            datatype=datatype,
            size=n,
            mapped=mapped,
            x=self.buffer(component, "position", positions, columns=datatype.coord_size, role="state"),
            v=self.buffer(component, "velocity", v, columns=datatype.deriv_size, role="state"),
            f=self.buffer(component, "force", np.zeros_like(v), columns=datatype.deriv_size, role="scratch"),
            rest=self.buffer(component, "rest_position", rest, columns=datatype.coord_size),
        )
        state.simulated = self.checked.solver_of(component.node) is not None
        if not mapped:
            state.acc = self.buffer(
                component, "acceleration", np.zeros_like(v), columns=datatype.deriv_size, role="scratch"
            )
        self.states[id(component)] = state

    def _mapped_size(self, state: Component) -> int:
        """The size a mapping gives its output state at init when the state has no positions of its
        own (the distance mappings: one DOF per edge of their topology); else 0."""
        mapping = self.checked.mapping_of(state)
        if mapping is None or mapping.spec is None:
            return 0
        if mapping.spec.kernel not in ("distance_mapping", "distance_multi_mapping"):
            return 0
        topology = _topology_of(self, mapping)
        edges = self.value(topology, "edges") if topology is not None else None
        return int(np.size(edges) // 2) if edges is not None else 0

    def state_of(self, checked: CheckedComponent) -> StatePlan | None:
        return self.states.get(id(checked.state)) if checked.state is not None else None

    # --- groups --------------------------------------------------------------------------------
    def _groups(self) -> list[Group]:
        groups: dict[int, Group] = {}
        owner: dict[int, Group] = {}  # state id -> group
        for state in self.states.values():
            if state.mapped:
                continue
            solver = self.checked.solver_of(state.component.node)
            if solver is None:
                continue  # nothing integrates it: it stays where it is, as in SOFA
            group = groups.get(id(solver.component))
            if group is None:
                group = self._new_group(solver, len(groups))
                if group is None:
                    continue
                groups[id(solver.component)] = group
            group.states.append(state)
            owner[id(state.component)] = group
        self._attach_mapped(owner)
        for group in groups.values():
            if group.scheme == "implicit":
                for state in (*group.states, *group.mapped):
                    zeros = np.zeros_like(state.v.initial)
                    state.dx = self.buffer(
                        state.component, "dx", zeros, columns=state.v.columns, role="scratch"
                    )
                    state.df = self.buffer(
                        state.component, "df", zeros, columns=state.v.columns, role="scratch"
                    )
            names = {
                "euler": (),
                "rk2": ("x0", "v0"),
                "rk4": ("x0", "v0", "dx", "dv"),
                "implicit": ("r", "p", "z") if group.pcg else ("r", "p"),  # CG vectors (q is df)
            }[group.scheme]
            if group.inert_preconditioner is not None:
                names = ("r",)  # b only: no CG iteration
            if group.minres:
                names = ("r", "r1", "r2", "y", "w", "w2", "v")
            if group.newmark:
                names += ("a",)  # the previous step's acceleration
            if group.variational:  # x_k, the previous Newton iterate, the momenta p_k and p_k+1
                names += ("x0", "xi", "momentum", "new_momentum")
            for state in group.states:
                for name in names:
                    like = state.x if name in ("x0", "xi") else state.v
                    columns = like.columns
                    state.stages[name] = self.buffer(
                        state.component, name, np.zeros_like(like.initial), columns=columns, role="scratch"
                    )
        for checked in self.checked:
            lowering = LOWERINGS.get(checked.spec.kernel) if checked.spec else None
            if lowering is None or checked.category in (Category.STATE, Category.ODE_SOLVER):
                continue
            lowering(self, checked, owner)
            self.lowered.append(checked.component)
        for group in groups.values():
            if group.variational:
                self._screen_variational(group, owner)
            if group.routed:
                self._route_through_mappings(group)
        self.guard = self._contact_guard()
        if self.prune:
            self._leave_unread_out(list(groups.values()))
        return list(groups.values())

    def _contact_guard(self) -> ContactGuard | None:
        """The boxes the step tests before it runs (see ContactGuard): one per collision model on a
        state, the pairs SOFA would test (models of different nodes, not both static)."""
        models: list[tuple[CheckedComponent, StatePlan]] = []
        for checked in self.guarded:
            state = self.state_of(checked)
            if state is None or state.datatype.coord_size < 3:
                self.unsupported(checked, "a collision model needs a MechanicalObject with 3D positions")
                continue
            models.append((checked, state))
        if len(models) < 2:
            return None
        alarm = max(
            (
                float(self.value(c.component, "alarmDistance") or 0.0)
                for c in self.checked
                if c.category is Category.COLLISION_PIPELINE and c.spec and c.spec.field("alarmDistance")
            ),
            default=0.0,
        )
        margins, static = [], []
        for checked, _state in models:
            spec = checked.spec
            assert spec is not None
            radius = 0.0
            if spec.field("radius"):  # spheres: the largest radius
                radii = self.value(checked.component, "listRadius")
                radius = float(np.max(radii)) if radii is not None and np.size(radii) else 0.0
                radius = radius or float(self.value(checked.component, "radius") or 1.0)
            # SOFA's box test (BaseProximityIntersection) lets two boxes be alarmDistance plus both
            # models' contactDistance apart: half the alarm distance grows each box.
            contact = float(self.value(checked.component, "contactDistance") or 0.0)
            margins.append(radius + 0.5 * alarm + contact)
            static.append(
                not self.value(checked.component, "simulated") and not self.value(checked.component, "moving")
            )
        pairs = [
            (a, b)
            for a in range(len(models))
            for b in range(a + 1, len(models))
            if models[a][0].component.node is not models[b][0].component.node
            and not (static[a] and static[b])
        ]
        if not pairs:
            return None
        return ContactGuard(
            models=[(origin_of(c.component), state) for c, state in models],
            margins=self.buffer("/", "contact_margins", margins),
            pairs=self.buffer("/", "contact_pairs", np.array(pairs, dtype=np.int64), "i64", columns=2),
            boxes=self.buffer("/", "contact_boxes", np.zeros(6 * len(models)), columns=6, role="scratch"),
            touching=self.buffer("/", "contact_touching", [-1], "i64", role="state"),
        )

    def _route_through_mappings(self, group: Group) -> None:
        """The rows of J for every mapped state an assembled block lands on, and for their own
        mapped inputs (chains), recorded before the blocks: A gets J^T K J (SOFA's
        MatrixLinearSystem projects mapped matrices the same way). Refused where J is not known."""
        mappings = {id(m.child): m for m in group.mappings}
        rows: list[tuple[int, str]] = []
        done: set[int] = set()
        while len(done) < len(group.routed):
            for key, (state, start, checked) in list(group.routed.items()):
                if key in done:
                    continue
                done.add(key)
                mapping = mappings.get(key)
                where = f"on the mapped state {state.path}"
                if mapping is None or mapping.assembly is None:
                    self.unsupported(
                        checked,
                        f"a direct solver or assembled preconditioner {where}: its mapping's "
                        "Jacobian is not assembled yet (RigidMapping, BarycentricMapping, SubsetMapping "
                        "and IdentityMapping are); use CGLinearSolver",
                    )
                    continue
                if mapping.transpose is None:
                    self.unsupported(checked, f"an assembled system {where}: its mapping has mapForces=false")
                    continue
                if mapping.geometric is not None:
                    self.unsupported(
                        checked,
                        f"an assembled system {where}: its mapping's geometric stiffness is not "
                        "assembled yet",
                    )
                    continue
                parent = group.assembly_offset(mapping.parent, checked)
                code = mapping.assembly(f"sofac::Assembler::kMapped + {start}", parent)
                rows.append((start, f"// J: {mapping.origin}"))
                rows.append((start, code))
        rows.sort(key=lambda row: row[0])  # the assembler takes J's rows in order
        group.assemble[:0] = [Op("mappings' Jacobians, rows in order", [line for _, line in rows])]

    def _leave_unread_out(self, groups: list[Group]) -> None:
        """Moves the mapped states nothing in the step reads, and their mappings, out of the step.

        Read from the lowered plan itself: a mapped state is read when a projection constrains it,
        when code of a step (forces, masses, products, assembly, energy, init) names one of its
        vectors, or when it is an input of the mapping of a read state. Anything else (a collision
        model's points when no contact can happen, a mapped node kept for output) only costs time:
        its mapping runs when Python reads the state instead, with the same numbers, since mapping
        x and v is a function of the parents' x and v alone."""
        owners: dict[str, StatePlan] = {}
        for group in groups:
            for state in (*group.states, *group.mapped):
                for vector in (state.x, state.v, state.f, state.dx, state.df):
                    if vector is not None:
                        owners[vector.ident] = state

        def states_named(lines: list[str]) -> set[int]:
            return {
                id(owners[ident])
                for line in lines
                for ident in re.findall(r"\bS\.(\w+)", line)
                if ident in owners
            }

        kinds = ("forces", "accelerations", "mass_dx", "stiffness_dx", "assemble", "energy", "init")
        code = [line for g in groups for kind in kinds for op in getattr(g, kind) for line in op.code]
        read = states_named(code) | {id(p.state) for g in groups for p in g.projections}
        if self.guard is not None:  # the contact guard reads its models' positions before each step
            read |= {id(state) for _, state in self.guard.models}
        mappings = [m for g in groups for m in g.mappings]
        growing = True
        while growing:  # a read state's mapping reads its inputs (every input of a multi-mapping)
            growing = False
            for mapping in mappings:
                if id(mapping.child) in read:
                    inputs = states_named(mapping.apply) - read
                    growing = growing or bool(inputs)
                    read |= inputs
        mapped_by = {id(m.child) for m in mappings}
        for group in groups:
            unread = [s for s in group.mapped if id(s) not in read and id(s) in mapped_by]
            gone = {id(s) for s in unread}
            group.unread = unread
            group.on_read = [m for m in group.mappings if id(m.child) in gone]
            group.mapped = [s for s in group.mapped if id(s) not in gone]
            group.mappings = [m for m in group.mappings if id(m.child) not in gone]
            for state in unread:  # no product runs through them: no dx, df
                dropped = {id(state.dx), id(state.df)}
                self.buffers = [b for b in self.buffers if id(b) not in dropped]
                state.dx = state.df = None

    def _new_group(self, solver: CheckedComponent, index: int) -> Group | None:
        kernel = solver.spec.kernel if solver.spec else ""
        scheme = {
            "euler_explicit": "euler",
            "runge_kutta2": "rk2",
            "runge_kutta4": "rk4",
            "euler_implicit": "implicit",
            "static": "implicit",
            "newmark": "implicit",
            "variational": "implicit",
        }.get(kernel)
        if scheme is None:
            return None  # reported by _screen
        symplectic = bool(self.value(solver.component, "symplectic")) if scheme == "euler" else False
        group = Group(solver=solver.component, ident=f"g{index}", scheme=scheme, symplectic=symplectic)
        if kernel == "static" and not self._plan_static(solver, group):
            return None
        if kernel == "euler_implicit" and not self._plan_implicit(solver, group):
            return None
        if kernel == "newmark" and not self._plan_newmark(solver, group):
            return None
        if kernel == "variational" and not self._plan_variational(solver, group):
            return None
        if scheme == "euler":  # its linear solver serves only a non-diagonal mass: M a = f
            linear = solver.links.get("linearSolver")
            if not isinstance(linear, Component):
                linear = self.checked.resolver._linear_solver_below(solver.component.node)
            spec = self.checked.of(linear).spec if linear is not None else None
            if spec is not None and spec.kernel == "direct":
                group.linear_solver, group.assembled = linear, True
                group.llt = spec.role == "llt"
        return group

    def _plan_pcg(self, linear: CheckedComponent, group: Group) -> bool:
        """SOFA's PCGLinearSolver: warm-started CG, optionally (block) Jacobi, SSOR or Warp
        preconditioned; with a PrecomputedWarpPreconditioner, no iteration at all (see below)."""
        component = linear.component
        group.linear_solver = component
        preconditioner = linear.links.get("preconditioner")
        if (
            isinstance(preconditioner, Component)
            and self.value(component, "use_precond") is not False
            and getattr(self.checked.of(preconditioner).spec, "kernel", "") == "precomputed_warp"
        ):
            if not self._precomputed_warp_is_inert(self.checked.of(preconditioner), group):
                return False
            group.inert_preconditioner = preconditioner
            return True
        group.pcg = {
            "iterations": self.buffer(
                component, "iterations", [int(self.value(component, "iterations") or 25)], "i64"
            ),
            "tolerance": self.buffer(
                component, "tolerance", [float(self.value(component, "tolerance"))], role="param"
            ),
        }
        if isinstance(preconditioner, Component) and self.value(component, "use_precond") is not False:
            spec = self.checked.of(preconditioner).spec
            block = {"jacobi": 1, "block_jacobi": 3, "ssor": -1, "warp": 4}.get(spec.kernel if spec else "")
            if block == 4 and not self._warp_is_identity(self.checked.of(preconditioner), group):
                return False
            if block is None:
                self.unsupported(
                    self.checked.of(preconditioner), f"sofac cannot compile {spec.name if spec else '?'} yet"
                )
                return False
            if block == -1:
                group.ssor_omega = self.buffer(
                    preconditioner, "omega", [float(self.value(preconditioner, "omega"))], role="param"
                )
            group.preconditioner, group.assembled = block, True
        return True

    def _precomputed_warp_is_inert(self, warp: CheckedComponent, group: Group) -> bool:
        """PrecomputedWarpPreconditioner as SOFA runs it: it sizes its precomputed inverse from its
        PrecomputedMatrixSystem's matrix, which nothing assembles (SOFA only allocates it, 0x0), so the
        inverse is 0x0 (the shared, empty matrix counts as already built: no precomputation) and the
        rotated product loops over no DOF: its output vector is left as it was. The PCG's first output
        is a fresh, zero vector, so r.z = 0 ends it before any iteration: dv keeps its start.
        The configurations where SOFA does something else are refused."""
        system = warp.links.get("linearSystem")
        system_spec = self.checked.of(system).spec if isinstance(system, Component) else None
        if system_spec is None or system_spec.name != "PrecomputedMatrixSystem":
            self.unsupported(warp, "its linearSystem must link a PrecomputedMatrixSystem")
            return False
        if self.value(warp.component, "use_rotations") is False:
            self.unsupported(warp, "use_rotations false (SOFA then copies an empty product) is not compiled")
            return False
        if self.value(warp.component, "share_matrix") is False:
            self.unsupported(
                warp, "share_matrix false (SOFA then precomputes from files and solvers) is not compiled"
            )
            return False
        if group.static or group.newmark:
            self.unsupported(warp, "it is compiled under an EulerImplicitSolver only")
            return False
        return True

    def _warp_is_identity(self, warp: CheckedComponent, group: Group) -> bool:
        """WarpPreconditioner as sofac compiles it: its RotationMatrixSystem reassembles the main
        system every step (assemblingRate 1), which resets the rotations to identity, and its solver
        is a sparse direct one: the preconditioner is then that solver on this step's matrix."""
        system = warp.links.get("linearSystem")
        inner = warp.links.get("linearSolver")
        if not isinstance(inner, Component):
            solvers = [
                c
                for c in warp.component.node.objects
                if self.checked.of(c).category is Category.LINEAR_SOLVER
            ]
            inner = next(
                (c for c in solvers if getattr(self.checked.of(c).spec, "kernel", "") == "direct"), None
            )
        if isinstance(system, Component) and int(self.value(system, "assemblingRate") or 1) != 1:
            self.unsupported(
                warp,
                "a RotationMatrixSystem with assemblingRate > 1 (rotated factorisations) is not compiled yet",
            )
            return False
        spec = self.checked.of(inner).spec if isinstance(inner, Component) else None
        if spec is None or spec.kernel != "direct":
            self.unsupported(warp, "its linearSolver must be a sparse direct solver")
            return False
        group.llt = spec.role == "llt"
        return True

    def _plan_implicit(self, solver: CheckedComponent, group: Group) -> bool:
        """EulerImplicitSolver's parameters and its CG linear solver (matrix-free, as SOFA's)."""
        component = solver.component
        group.first_order = bool(self.value(component, "firstOrder"))
        group.trapezoidal = bool(self.value(component, "trapezoidalScheme"))
        for name in ("rayleighStiffness", "rayleighMass", "vdamping"):
            group.implicit[name] = self.buffer(
                component, name, [float(self.value(component, name) or 0.0)], role="param"
            )
        return self._plan_linear_solver(solver, group)

    def _plan_newmark(self, solver: CheckedComponent, group: Group) -> bool:
        """NewmarkImplicitSolver: Rayleigh damping, vdamping, gamma, beta; the linear solver."""
        component = solver.component
        for name in ("rayleighStiffness", "rayleighMass", "vdamping"):
            group.implicit[name] = self.buffer(
                component, name, [float(self.value(component, name) or 0.0)], role="param"
            )
        for name, default in (("gamma", 0.5), ("beta", 0.25)):
            value = self.value(component, name)
            group.newmark[name] = self.buffer(
                component, name, [float(default if value is None else value)], role="param"
            )
        group.newmark["started"] = self.buffer(component, "started", [0], "i64", role="scratch")
        return self._plan_refactoring_solver(solver, group)

    def _plan_refactoring_solver(self, solver: CheckedComponent, group: Group) -> bool:
        """The linear solver of a scheme whose matrix changes within a step (Newmark, the
        variational Newton loop): PrecomputedLinearSolver's single factorisation is refused."""
        if not self._plan_linear_solver(solver, group):
            return False
        if group.factor_once:
            name = solver.spec.name if solver.spec else solver.component.type_name
            self.unsupported(
                self.checked.of(group.linear_solver),
                f"PrecomputedLinearSolver under {name} is not compiled yet",
            )
            return False
        return True

    def _plan_variational(self, solver: CheckedComponent, group: Group) -> bool:
        """VariationalSymplecticSolver (implicit variant): Newton's tolerance and iteration cap,
        Rayleigh damping, the Hamiltonian outputs and the energy file; then the linear solver."""
        component = solver.component
        if self.value(component, "explicitIntegration"):
            self.unsupported(
                solver,
                "explicitIntegration=true is not compiled yet (the implicit variant, the default, is)",
            )
            return False
        for name in ("rayleighStiffness", "rayleighMass"):
            group.implicit[name] = self.buffer(
                component, name, [float(self.value(component, name) or 0.0)], role="param"
            )
        error = self.value(component, "newtonError")
        steps = self.value(component, "steps")
        group.variational = {
            "newtonError": self.buffer(
                component, "newtonError", [0.01 if error is None else float(error)], role="param"
            ),
            "steps": self.buffer(component, "steps", [5 if steps is None else int(steps)], "i64"),
            "started": self.buffer(component, "started", [0], "i64", role="scratch"),
            # m_incrementalPotentialEnergy: the potential at t = 0 plus -2 f.res at each step
            "incremental": self.buffer(component, "incrementalPotentialEnergy", [0.0], role="state"),
            # outputs: hamiltonianEnergy, and the kinetic and potential parts the energy file shows
            "hamiltonianEnergy": self.buffer(component, "hamiltonianEnergy", [0.0], role="state"),
            "energies": self.buffer(component, "energies", [0.0, 0.0], role="state"),
        }
        computed = self.value(component, "computeHamiltonian")
        group.hamiltonian = computed is None or bool(computed)
        incremental = self.value(component, "useIncrementalPotentialEnergy")
        group.incremental_potential = incremental is None or bool(incremental)
        group.energy_file = str(self.value(component, "file") or "")
        group.save_energy = bool(self.value(component, "saveEnergyInFile"))
        return self._plan_refactoring_solver(solver, group)

    def _screen_variational(self, group: Group, owner: dict[int, Group]) -> None:
        """What sofac's VariationalSymplecticSolver cannot take: rigid frames (SOFA adds and
        subtracts their coordinates as vectors, quaternions included), and masses on mapped states
        (SOFA's momentum M v stops at the mappings: they would have no inertia)."""
        solver = self.checked.of(group.solver)
        for state in group.states:
            if state.datatype.rigid:
                self.unsupported(
                    solver, f"VariationalSymplecticSolver on {state.datatype.name} is not compiled yet"
                )
        for checked in self.checked:
            spec = checked.spec
            is_mass = checked.category is Category.MASS or (spec is not None and spec.role == "and_mass")
            state = self.state_of(checked) if is_mass else None
            if state is not None and state.mapped and owner.get(id(state.component)) is group:
                self.unsupported(
                    checked,
                    "a mass on a mapped state under VariationalSymplecticSolver is not compiled yet "
                    "(SOFA's momentum M v leaves it out)",
                )

    def _plan_static(self, solver: CheckedComponent, group: Group) -> bool:
        """StaticSolver: Newton-Raphson on f(x) = 0 with the parameters of its NewtonRaphsonSolver
        (its `newtonSolver` link, else the first one in its node or below, else SOFA's defaults with
        the StaticSolver's deprecated attributes, as SOFA's init forwards them), then the linear solver."""
        component = solver.component
        newton = solver.links.get("newtonSolver")
        if not isinstance(newton, Component):
            newton = next(
                (
                    c
                    for node in _subtree(component.node)
                    for c in node.objects
                    if (spec := self.checked.of(c).spec) is not None and spec.name == "NewtonRaphsonSolver"
                ),
                None,
            )
        values: dict[str, float] = {}
        for name, default in _NEWTON_DEFAULTS.items():
            value = self.value(newton, name) if newton is not None else None
            values[name] = float(default if value is None else value)
        if newton is None:
            for legacy, name in _STATIC_LEGACY_FORWARDS:
                value = self.value(component, legacy)
                if value is not None:
                    values[name] = float(value)
        owner = newton if newton is not None else component
        for name, value in values.items():
            if name.startswith("maxNb"):
                group.static[name] = self.buffer(owner, name, [max(int(value), 0)], "i64")
            else:
                group.static[name] = self.buffer(owner, name, [value], role="param")
        return self._plan_linear_solver(solver, group)

    def _plan_linear_solver(self, solver: CheckedComponent, group: Group) -> bool:
        """The implicit group's linear solver: CG (matrix-free, as SOFA's), PCG or a direct solver."""
        component = solver.component
        linear = solver.links.get("linearSolver")
        if not isinstance(linear, Component):
            linear = self.checked.resolver._linear_solver_below(component.node)
        checked_linear = self.checked.of(linear) if linear is not None else None
        if checked_linear is None or checked_linear.spec is None:
            return False  # E221, reported by the checker
        if checked_linear.spec.kernel == "pcg":
            return self._plan_pcg(checked_linear, group)
        if checked_linear.spec.kernel == "minres":
            group.linear_solver = linear
            group.minres = {
                "iterations": self.buffer(
                    linear, "iterations", [int(self.value(linear, "iterations") or 25)], "i64"
                ),
                "tolerance": self.buffer(
                    linear, "tolerance", [float(self.value(linear, "tolerance"))], role="param"
                ),
            }
            return True
        if checked_linear.spec.kernel not in ("cg", "direct", "precomputed"):
            self.unsupported(checked_linear, f"sofac cannot compile {checked_linear.spec.name} yet")
            return False
        group.linear_solver = linear
        if checked_linear.spec.kernel in ("direct", "precomputed"):
            if not self._assembles_everything(checked_linear):
                return False
            group.assembled = group.direct = True
            group.factor_once = checked_linear.spec.kernel == "precomputed"
            group.llt = checked_linear.spec.role == "llt"
            return True
        if (checked_linear.template or GRAPH_SCATTERED) != GRAPH_SCATTERED:
            # SOFA assembles the system matrix and runs CG on it (CRS, sparse or full: the same numbers)
            group.assembled = group.assembled_cg = True
        group.cg = {
            "iterations": self.buffer(
                linear, "iterations", [int(self.value(linear, "iterations") or 25)], "i64"
            ),
            "tolerance": self.buffer(
                linear, "tolerance", [float(self.value(linear, "tolerance"))], role="param"
            ),
            "threshold": self.buffer(
                linear, "threshold", [float(self.value(linear, "threshold"))], role="param"
            ),
            "solves": self.buffer(linear, "solves", [0], "i64", role="scratch"),
        }
        return True

    def _assembles_everything(self, linear: CheckedComponent) -> bool:
        """The linear system a direct solver solves assembles M, K and the damping with the
        projections and the mapped components, as sofac's assembly does. Through a
        CompositeLinearSystem, that is its solverLinearSystem (else its first linear system, as
        SOFA picks); its other systems assemble only for display or output: nothing reads them."""
        system = linear.links.get("linearSystem")
        if not isinstance(system, Component):
            return True  # the default one SOFA creates: a MatrixLinearSystem
        checked = self.checked.of(system)
        if checked.spec is not None and checked.spec.name == "CompositeLinearSystem":
            chosen = checked.links.get("solverLinearSystem")
            if not isinstance(chosen, Component):
                listed = checked.links.get("linearSystems")
                chosen = next((c for c in listed or () if isinstance(c, Component)), None)
            if chosen is None:
                self.unsupported(checked, "it needs a solverLinearSystem or linearSystems to solve")
                return False
            system, checked = chosen, self.checked.of(chosen)
        plain = ("MatrixLinearSystem", "ConstantSparsityPatternSystem")
        if checked.spec is None or checked.spec.name not in plain:
            return True  # other systems are screened where they are planned
        flags = (
            "enableAssembly",
            "assembleStiffness",
            "assembleMass",
            "assembleDamping",
            "applyProjectiveConstraints",
            "applyMappedComponents",
        )
        off = [name for name in flags if self.value(system, name) is False]
        if off:
            self.unsupported(
                checked, f"{', '.join(off)}=false on the system a solver solves is not compiled yet"
            )
            return False
        return True

    def _attach_mapped(self, owner: dict[int, Group]) -> None:
        """Mapped states join their input's group, parents before children."""
        pending = [c for c in self.checked.states() if self.states[id(c.component)].mapped]
        progress = True
        while pending and progress:
            progress = False
            for checked in list(pending):
                mapping = self.checked.mapping_of(checked.component)
                assert mapping is not None
                source = mapping.links.get("input")
                if not isinstance(source, Component):  # a multi-mapping: its group is its first input's
                    inputs = _mapping_inputs(self, mapping)
                    source = inputs[0] if inputs else None
                group = owner.get(id(source)) if isinstance(source, Component) else None
                if (
                    group is None
                    and isinstance(source, Component)
                    and any(p.component is source for p in pending)
                ):
                    continue  # its parent is not placed yet
                pending.remove(checked)
                progress = True
                if group is not None:
                    group.mapped.append(self.states[id(checked.component)])
                    owner[id(checked.component)] = group


# NewtonRaphsonSolver's parameters and SOFA's defaults (the maxNb* are counts).
_NEWTON_DEFAULTS: dict[str, float] = {
    "maxNbIterationsNewton": 1,
    "absoluteResidualStoppingThreshold": 1e-5,
    "relativeInitialStoppingThreshold": 1e-5,
    "relativeSuccessiveStoppingThreshold": 1e-5,
    "absoluteEstimateDifferenceThreshold": 0.0,
    "relativeEstimateDifferenceThreshold": 0.0,
    "maxNbIterationsLineSearch": 1,
    "lineSearchCoefficient": 0.5,
}
# StaticSolver's deprecated attributes -> the NewtonRaphsonSolver parameter SOFA's init sets from
# them, in SOFA's order (both relative tolerances land on relativeEstimateDifferenceThreshold).
_STATIC_LEGACY_FORWARDS = (
    ("newton_iterations", "maxNbIterationsNewton"),
    ("absolute_correction_tolerance_threshold", "absoluteEstimateDifferenceThreshold"),
    ("relative_correction_tolerance_threshold", "relativeEstimateDifferenceThreshold"),
    ("absolute_residual_tolerance_threshold", "absoluteResidualStoppingThreshold"),
    ("relative_residual_tolerance_threshold", "relativeEstimateDifferenceThreshold"),
)


def _subtree(node: Any) -> list[Any]:
    """A node and its descendants, depth first."""
    nodes, pending = [], [node]
    while pending:
        current = pending.pop(0)
        nodes.append(current)
        pending[0:0] = list(current.children)
    return nodes


# --- lowerings ------------------------------------------------------------------------------------
# Each lowering reads its component's fields and appends kernel calls to its group.
Lowering = Callable[[_Planner, CheckedComponent, dict[int, Group]], None]


def _ptr(buffer: Buffer) -> str:
    return f"S.{buffer.ident}.data()"


def _call(function: str, *arguments: Any) -> str:
    """A kernel call statement; buffers become pointers to their data."""
    text = ", ".join(_ptr(a) if isinstance(a, Buffer) else str(a) for a in arguments)
    return f"sofac::{function}({text});"


def _count(buffer: Buffer, per: int = 1) -> str:
    return f"Index(S.{buffer.ident}.size() / {per})" if per != 1 else f"Index(S.{buffer.ident}.size())"


def _target(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
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


def _indices(
    planner: _Planner, checked: CheckedComponent, name: str, size: int, all_if_empty: bool = True
) -> np.ndarray:
    value = planner.value(checked.component, name)
    if value is None or np.size(value) == 0:
        return np.arange(size, dtype=np.int64) if all_if_empty else np.zeros(0, dtype=np.int64)
    return np.asarray(value, dtype=np.int64).ravel()


def _lower_uniform_mass(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
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


def _topology_of(planner: _Planner, checked: CheckedComponent) -> Component | None:
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
    planner: _Planner, checked: CheckedComponent, *, sparse_grid_ok: bool = False
) -> dict[str, np.ndarray] | None:
    """The elements of the topology a component uses. A SparseGridTopology's only serve callers
    that read nothing else or apply its per-cell coefficients themselves (``sparse_grid_ok``, see
    _sparse_grid_coefficients): SOFA's other FEM and masses on it are not compiled."""
    topology = _topology_of(planner, checked)
    if topology is None:
        return None
    spec = planner.checked.of(topology).spec
    if spec is not None and spec.role == "sparse_grid" and not sparse_grid_ok:
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


def _sparse_grid_coefficients(planner: _Planner, checked: CheckedComponent) -> np.ndarray | None:
    """The per-cell stiffness (= mass) coefficients of the SparseGridTopology a component uses (SOFA's
    HexahedronFEMForceField scales each element stiffness by them, ...AndMass each element mass and
    particle mass); None when its topology is not a sparse grid."""
    from .voxelize import cell_coefficients

    topology = _topology_of(planner, checked)
    spec = planner.checked.of(topology).spec if topology is not None else None
    if topology is None or spec is None or spec.role != "sparse_grid":
        return None
    boundary = planner.value(topology, "boundary_cells")
    if boundary is None:
        return None
    return cell_coefficients(np.asarray(boundary), bool(planner.value(topology, "fillWeighted")))


def _split_hexahedra(cells: dict[str, np.ndarray]) -> np.ndarray | None:
    """TetrahedronFEMForceField on hexahedra (a grid, a hexahedral mesh): 6 tetrahedra per cell, as
    SOFA splits them (mirrored by the cell's parity on a grid)."""
    from .fem_topology import tetrahedra_from_grid, tetrahedra_from_hexahedra

    if "resolution" in cells and (cells["resolution"] > 1).all():
        return np.asarray(tetrahedra_from_grid(cells["resolution"].tolist()), dtype=np.int64).ravel()
    if "hexahedra" in cells:
        return np.asarray(
            tetrahedra_from_hexahedra(cells["hexahedra"].reshape(-1, 8)), dtype=np.int64
        ).ravel()
    return None


def _lower_diagonal_mass(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from . import masses

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


def _written_float(planner: _Planner, component: Component, name: str) -> float | None:
    """A field's value when the scene sets it (or links it), else None (SOFA's isSet())."""
    if component.get(name) is None:
        return None
    value = planner.value(component, name)
    return None if value is None else float(np.asarray(value, dtype=float).ravel()[0])


def _lower_mesh_matrix_mass(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from . import masses

    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid:
        planner.unsupported(checked, "MeshMatrixMass on rigid frames is not compiled yet")
        return
    lumping = bool(planner.value(component, "lumping"))
    if group.scheme != "implicit" and not lumping:
        if group.scheme != "euler" or not group.assembled:
            planner.unsupported(
                checked, "a consistent mass with this solver needs a sparse direct linear solver"
            )
            return
        group.direct = True  # explicit Euler solves M a = f
    from .barycentric import mapper_for

    cells = _topology_cells(planner, checked) or {}
    topology = _topology_of(planner, checked)
    spec = planner.checked.of(topology).spec if topology is not None else None
    if spec is not None and mapper_for(spec.role) == "dynamic":
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
    coefficient = repr(float(data.lumping_coefficient)) if lumping else "1.0"
    lumped_factor = repr(float(data.lumping_coefficient))
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
        lambda offset: _call(
            "assemble_mesh_matrix_mass",
            "A",
            offset,
            vertex,
            n,
            edges,
            edge_mass,
            _count(edge_mass) if not lumping else 0,
            coefficient,
            "mfact",
            width,
        ),
    )
    if group.scheme == "implicit":
        if lumping:
            code = _call(
                "mesh_matrix_mass_multiply_lumped", state.df, state.dx, vertex, n, coefficient, "mfact", width
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
                _count(edge_mass),
                "mfact",
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
                "kinetic += "
                + _call(
                    "mesh_matrix_mass_kinetic_energy",
                    state.v,
                    vertex,
                    n,
                    edges,
                    edge_mass,
                    _count(edge_mass),
                    "true" if lumping else "false",
                    coefficient,
                    width,
                ),
                "potential += "
                + _call(f"gravity_potential<{state.cpp_type}>", state.x, n, vertex, g, lumped_factor),
            ],
        )
    )


_FEM_METHODS = {"small": 0, "large": 1, "polar": 2, "svd": 3}
# (kernel prefix, element kind, corners, data size per element by method)
_FEM_KINDS = {
    "tetra_fem": ("tetra_fem", "tetrahedra", 4, {0: 24, 1: 30, 2: 36, 3: 54}),
    "tetracorot_fem": ("tetracorot_fem", "tetrahedra", 4, {0: 24, 1: 30, 2: 36, 3: 54}),
    "hexa_fem": ("hexa_fem", "hexahedra", 8, {0: 609, 1: 609, 2: 609, 3: 609}),
    "trifem": ("trifem", "triangles", 3, {1: 35}),
}


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


def _split_argument(planner: _Planner, component: Component, cells: np.ndarray, corners: int) -> list[str]:
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
    fields = [_ptr(parts[0]), str(planner.threads), _ptr(parts[1]), _ptr(parts[2]), str(slot_node.size)]
    return [f"sofac::ElementSplit{{{', '.join([*fields, _ptr(deferred)])}}}"]


def _lower_fem(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    assert checked.spec is not None
    prefix, kind, corners, sizes = _FEM_KINDS[checked.spec.kernel]
    if state.datatype.name != "Vec3d":
        planner.unsupported(checked, f"{checked.spec.name} on {state.datatype.name} is not compiled yet")
        return
    method = _FEM_METHODS.get(str(planner.value(component, "method") or "large"), 1)
    if prefix == "trifem" and (method != 1 or group.assembled):
        planner.unsupported(
            checked, "TriangularFEMForceField is compiled for method large with the matrix-free CG only"
        )
        return
    if prefix != "tetra_fem" and method == 3:
        method = 1  # svd exists only for TetrahedronFEMForceField; SOFA falls back to large
    if prefix == "tetra_fem" and float(planner.value(component, "plasticMaxThreshold") or 0.0) > 0.0:
        planner.unsupported(checked, "plasticity (plasticMaxThreshold > 0) is not compiled yet")
        return
    if prefix == "tetra_fem" and planner.value(component, "updateStiffnessMatrix"):
        planner.unsupported(checked, "updateStiffnessMatrix=true is not compiled yet")
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
    young = planner.value(component, "youngModulus")
    poisson = planner.value(component, "poissonRatio")
    elements = planner.buffer(component, kind, cells, "i64", columns=corners)
    young_buffer = planner.buffer(
        component, "youngModulus", np.atleast_1d(young if young is not None else 5000.0), role="param"
    )
    poisson_buffer = planner.buffer(
        component, "poissonRatio", np.atleast_1d(poisson if poisson is not None else 0.45), role="param"
    )
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
                    _count(young_buffer),
                    poisson_buffer,
                    _count(poisson_buffer),
                    method,
                    data,
                    *([coefficient_buffer] if coefficient_buffer is not None else []),
                )
            ],
        )
    )
    split = _split_argument(planner, component, cells, corners) if prefix != "trifem" else []
    group.forces.append(
        Op(origin, [_call(f"{prefix}_add_force", elements, count, state.x, state.f, data, method, *split)])
    )
    and_mass = checked.spec.role == "and_mass"  # HexahedronFEMForceFieldAndMass: its weight after its force
    if and_mass and not _lower_hexa_mass(
        planner, checked, state, group, elements, count, data, method, coefficient_buffer
    ):
        return
    if prefix not in ("tetracorot_fem", "trifem"):  # SOFA's potential energy (0 for these, as SOFA)
        group.energy.append(
            Op(origin, ["potential += " + _call(f"{prefix}_energy", elements, count, state.x, data, method)])
        )
    if group.scheme == "implicit":
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        f"{prefix}_add_dforce",
                        elements,
                        count,
                        state.dx,
                        state.df,
                        "kfact",
                        data,
                        method,
                        *split,
                    )
                ],
            )
        )
        # Tetrahedra: element matrices a block of TETRA_LANES at once, one per vector lane (fem.h).
        if prefix in ("tetra_fem", "tetracorot_fem"):
            assembler = "assemble_elements<4, sofac::TETRA_LANES>"
            matrices = f"sofac::{prefix}_element_matrices"
        else:
            assembler, matrices = f"assemble_elements<{corners}>", f"sofac::{prefix}_element_matrix"
        _assemble(
            planner,
            checked,
            group,
            state,
            lambda offset: _call(assembler, "A", elements, count, data, method, offset, "kfact", matrices),
        )


def _lower_distance_mapping(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """DistanceMapping / SquareDistanceMapping (Vec3d -> Vec1d, one DOF per edge), with their
    geometric stiffness in the matrix-free products (SOFA's matrixFreeApplyDJT)."""
    import math

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
    kind = 1 if checked.spec is not None and checked.spec.role == "square" else 0
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

        def geometric(dx: Buffer, df: Buffer) -> str:
            return _call(
                "distance_mapping_djt",
                df,
                dx,
                child.f,
                edge_buffer,
                count,
                direction,
                inverse,
                kind,
                mode,
                "kfact",
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
            lambda up, down: _call("distance_mapping_j", up, down, edge_buffer, count, direction),
            (lambda up, down: _call("distance_mapping_jt", up, down, edge_buffer, count, direction))
            if maps_forces
            else None,
            geometric,
        )
    )


def _triangle_target(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group, dict[str, np.ndarray]] | None:
    """A triangle-based component's state (Vec3d), group and topology cells, triangles included."""
    found = _target(planner, checked, owner)
    if found is None:
        return None
    state, group = found
    if state.datatype.name != "Vec3d":
        planner.unsupported(
            checked, f"{checked.component.type_name} on {state.datatype.name} is not compiled yet"
        )
        return None
    cells = _topology_cells(planner, checked) or {}
    triangles = cells.get("triangles")
    if triangles is None or not triangles.size or planner.checked.positions(state.component) is None:
        planner.unsupported(checked, "it needs triangles known at compile time")
        return None
    return state, group, cells


def _lower_triangular_bending_springs(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """TriangularBendingSprings: per edge shared by two triangles, a spring between the two vertices
    opposite it (m1 in the later triangle, m2 in the first one, as SOFA's applyTriangleCreation),
    in the topology's edge order; rest length from the rest positions."""
    import math

    from . import masses

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
    count = len(pairs)
    springs = planner.buffer(
        component, "springs", np.asarray(pairs, dtype=np.int64).reshape(-1), "i64", columns=2
    )
    values = planner.buffer(component, "springParams", np.asarray(params, dtype=float).reshape(-1), columns=3)
    dfdx = planner.buffer(component, "dfdx", np.zeros(9 * count), columns=9, role="scratch")
    origin = origin_of(component)
    group.forces.append(
        Op(
            origin,
            [_call("triangular_bending_add_force", springs, values, count, state.x, state.v, state.f, dfdx)],
        )
    )
    group.energy.append(
        Op(origin, ["potential += " + _call("triangular_bending_energy", springs, values, count, state.x)])
    )
    if group.scheme == "implicit":
        group.stiffness_dx.append(
            Op(
                origin,
                [_call("triangular_bending_add_dforce", springs, count, dfdx, state.dx, state.df, "kfact")],
            )
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            lambda offset: _call("assemble_triangular_bending", "A", offset, springs, count, dfdx, "kfact"),
        )


def _lower_quad_bending_springs(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """QuadBendingSprings: a spring between the opposite corners of two quads sharing an edge
    (SOFA's registerEdge / addSpring order, each pair once), rest length from the positions."""
    import math

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


def _lower_interaction_ellipsoid(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """InteractionEllipsoidForceField: ellipsoids carried by a rigid DOF of object2 push the points of
    object1 (object2 is read, not pushed: object2_forces must be false)."""
    component = checked.component
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        ends.append(planner.states.get(id(target)) if isinstance(target, Component) else None)
    points, frame = ends
    if points is None or frame is None:
        planner.unsupported(checked, "object1 and object2 must be MechanicalObjects")
        return
    group = owner.get(id(points.component))
    if group is None:
        planner.ignored.append((component, "object1 has no ODE solver"))
        return
    if points.datatype.name != "Vec3d" or frame.datatype.name != "Rigid3d":
        planner.unsupported(checked, "it is compiled for Vec3d points and a Rigid3d frame only")
        return
    if planner.value(component, "object2_forces") is not False or planner.value(component, "object2_invert"):
        planner.unsupported(checked, "object2_forces=true or object2_invert=true is not compiled yet")
        return
    index = int(planner.value(component, "object2_dof_index") or 0)
    if not 0 <= index < frame.size:
        planner.unsupported(checked, f"object2_dof_index {index} is not a DOF of object2")
        return
    center_value, radius_value = planner.value(component, "center"), planner.value(component, "vradius")
    centers = np.asarray(center_value if center_value is not None else [], dtype=float).reshape(-1, 3)
    radii = np.asarray(radius_value if radius_value is not None else [], dtype=float).reshape(-1, 3)
    count = max(len(centers), len(radii))
    table = []
    for e in range(count):
        r = radii[min(e, len(radii) - 1)] if len(radii) else np.ones(3)
        c = centers[min(e, len(centers) - 1)] if len(centers) else np.zeros(3)
        table.extend([*c.tolist(), *(1 / (float(v) * float(v)) for v in r)])
    ellipsoids = planner.buffer(component, "ellipsoids", np.asarray(table, dtype=float), columns=6)
    contacts = planner.buffer(component, "contacts", np.zeros(10 * points.size), columns=10, role="scratch")
    quaternion = planner.buffer(component, "frame", np.array([0.0, 0.0, 0.0, 1.0]), role="scratch")
    stiffness, damping = (
        float(planner.value(component, "stiffness")),
        float(planner.value(component, "damping")),
    )
    origin = origin_of(component)
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    "ellipsoid_add_force",
                    points.x,
                    points.v,
                    points.f,
                    points.size,
                    frame.x,
                    index,
                    ellipsoids,
                    count,
                    repr(stiffness),
                    repr(damping),
                    contacts,
                    quaternion,
                )
            ],
        )
    )
    if group.scheme == "implicit":
        if group.assembled:
            planner.unsupported(
                checked, f"{_matrix_solver(group)} with an ellipsoid force field is not compiled yet"
            )
            return
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "ellipsoid_add_dforce",
                        points.dx,
                        points.df,
                        points.size,
                        contacts,
                        quaternion,
                        "kfact",
                    )
                ],
            )
        )


def _mapping_inputs(planner: _Planner, checked: CheckedComponent) -> list[Component]:
    """The parent states of a mapping: its ``input`` link, or each link of a multi-mapping's list (a
    node stands for its MechanicalObject)."""
    from . import links

    single = checked.links.get("input")
    if isinstance(single, Component):
        return [single]
    text = checked.component.get("input")
    found: list[Component] = []
    for word in str(text or "").split():
        path = links.parse_link(word)
        target = links.resolve(path, checked.component) if path is not None else None
        if isinstance(target, Node):
            target = planner.checked.resolver._node_state(target)
        if isinstance(target, Component):
            found.append(target)
    return found


def _lower_velocity_damping(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """UniformVelocityDampingForceField: f -= c v; with implicit="true", B = -c I in the solves."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    value = float(planner.value(component, "dampingCoefficient"))
    if planner.prune and value == 0.0:
        planner.pruned[f"{component.path}.dampingCoefficient"] = (
            "dampingCoefficient is 0: no damping force computed"
        )
        return
    coefficient = planner.buffer(component, "dampingCoefficient", [value], role="param")
    scalars = state.size * state.datatype.deriv_size
    origin = origin_of(component)
    group.forces.append(
        Op(origin, [_call("velocity_damping_force", state.f, state.v, scalars, f"S.{coefficient.ident}[0]")])
    )
    if planner.value(component, "implicit") and group.scheme == "implicit":
        if group.assembled:
            planner.unsupported(checked, f"implicit damping with {_matrix_solver(group)} is not compiled yet")
            return
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        "velocity_damping_dforce",
                        state.df,
                        state.dx,
                        scalars,
                        f"S.{coefficient.ident}[0]",
                        "bfact",
                    )
                ],
            )
        )


def _lower_distance_multi_mapping(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> None:
    """DistanceMultiMapping (Vec3d -> Vec1d): distances between points of two parent states, each
    edge from a point of the first input to one of the second (geometricStiffness None)."""
    import math

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

    def jt(up: Buffer, down: Buffer) -> str:
        other = second.f if up is first.f else second.df
        return _call("distance_multi_jt", up, other, down, *table, direction)

    def j(up: Buffer, down: Buffer) -> str:
        other = second.v if up is first.v else second.dx
        return _call("distance_multi_j", up, other, down, *table, direction)

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
                j(first.v, child.v),
            ],
            j,
            jt if maps_forces else None,
        )
    )


def _lower_trifem_optim(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
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
    young = planner.value(component, "youngModulus")
    poisson = planner.value(component, "poissonRatio")
    elements = planner.buffer(component, "triangles", cells, "i64", columns=3)
    young_buffer = planner.buffer(
        component, "youngModulus", np.atleast_1d(young if young is not None else 5000.0), role="param"
    )
    poisson_buffer = planner.buffer(
        component, "poissonRatio", np.atleast_1d(poisson if poisson is not None else 0.45), role="param"
    )
    material = (young_buffer, _count(young_buffer), poisson_buffer, _count(poisson_buffer))
    data = planner.buffer(component, "triangleInfo", np.zeros(count * 10), role="scratch")
    origin = origin_of(component)
    group.init.append(
        Op(origin, [_call("trifem_optim_init", elements, count, state.rest, *material, 1, data)])
    )
    group.forces.append(
        Op(origin, [_call("trifem_optim_add_force", elements, count, state.x, state.f, data, *material)])
    )
    if group.scheme == "implicit":
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
                        "kfact",
                        data,
                        *material,
                    )
                ],
            )
        )
        matrix = (
            "[&](const double* d, Index e, int, double* o) { sofac::trifem_optim_element_matrix(d, e, "
            f"{_ptr(young_buffer)}, {_count(young_buffer)}, {_ptr(poisson_buffer)}, "
            f"{_count(poisson_buffer)}, o); }}"
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            lambda offset: _call(
                "assemble_elements<3>", "A", elements, count, data, 1, offset, "kfact", matrix
            ),
        )


def _lower_bending_springs(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FastTriangularBendingSprings: one linear bending spring per edge between two triangles."""
    from . import bending, masses

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
    group.energy.append(Op(origin, ["potential += " + _call("bending_springs_energy", *table, state.x)]))
    if group.scheme == "implicit":
        group.stiffness_dx.append(
            Op(origin, [_call("bending_springs_add_dforce", *table, state.dx, state.df, "kfact")])
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            lambda offset: _call("assemble_bending_springs", "A", offset, *table, "kfact"),
        )


def _lower_hexa_mass(
    planner: _Planner,
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
    from . import element_fem

    component = checked.component
    if group.scheme != "implicit" and not (group.scheme == "euler" and group.assembled):
        # SOFA's accFromF is not implemented for this class: only a solve with M works.
        planner.unsupported(
            checked, "its mass needs an implicit solver, or explicit Euler with a sparse direct linear solver"
        )
        return False
    if group.scheme != "implicit":
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
                    "true" if lumped else "false",
                    values,
                    particle,
                    *([coefficients] if coefficients is not None else []),
                )
            ],
        )
    )
    planner.add_gravity(
        group,
        Op(origin, [_call("mass_gravity<sofac::Vec3d>", state.f, state.size, particle, 1, planner.gravity)]),
    )
    if group.scheme == "implicit":
        group.mass_dx.append(Op(origin, [_call("fem_mass_multiply", state.df, state.dx, *csr, "mfact")]))
    _assemble(
        planner, checked, group, state, lambda offset: _call("assemble_fem_mass", "A", offset, *csr, "mfact")
    )
    group.energy.append(
        Op(
            origin,
            [
                "kinetic += " + _call("fem_mass_kinetic_energy", state.v, *csr),
                "potential += "
                + _call(
                    "gravity_potential<sofac::Vec3d>", state.x, state.size, particle, planner.gravity, 1.0
                ),
            ],
        )
    )
    return True


def _add_mass(
    planner: _Planner, checked: CheckedComponent, state: StatePlan, group: Group, buffer: Buffer, stride: int
) -> None:
    origin = origin_of(checked.component)
    t, n = state.cpp_type, state.size
    stride_value = stride if stride else 0
    planner.add_gravity(
        group, Op(origin, [_call(f"mass_gravity<{t}>", state.f, n, buffer, stride_value, planner.gravity)])
    )
    group.energy.append(
        Op(
            origin,
            [
                _call(
                    f"mass_energy<{t}>",
                    state.x,
                    state.v,
                    n,
                    buffer,
                    stride_value,
                    planner.gravity,
                    "&kinetic",
                    "&potential",
                )
            ],
        )
    )
    _assemble(
        planner,
        checked,
        group,
        state,
        lambda offset: _call(f"assemble_mass<{t}>", "A", offset, n, buffer, stride_value, "mfact"),
    )
    if group.scheme == "implicit":
        if planner.rigid_model == "exact" and state.datatype.name == "Rigid3d":
            planner.unsupported(checked, "the exact rigid model is compiled for explicit solvers only")
        group.mass_dx.append(
            Op(origin, [_call(f"mass_multiply<{t}>", state.df, state.dx, n, buffer, stride_value, "mfact")])
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
                Op(origin, [_call(f"mass_acceleration<{t}>", state.acc, state.f, n, buffer, stride_value)])
            )


def _springs_from_fields(planner: _Planner, checked: CheckedComponent) -> np.ndarray:
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


def _flags(planner: _Planner, component: Component, name: str, count: int, default: bool) -> np.ndarray:
    value = planner.value(component, name)
    values = np.asarray(value if value is not None and np.size(value) else [default], dtype=bool).ravel()
    return (values if values.size == count else np.full(count, values[0])).astype(np.int64)


def _add_springs(
    planner: _Planner,
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
    table = (
        f"sofac::Springs{{{_ptr(a)}, {_ptr(b)}, {_ptr(ks)}, {_ptr(kd)}, {_ptr(rest)}, {_ptr(elongation)}, "
        f"{_ptr(enabled)}, {count}}}"
    )
    types = f"{first.cpp_type}, {second.cpp_type}"
    # Specialised at compile time: no damping term when every damping is exactly zero (a pruned
    # effect: setting a damping later needs prune=False), no flag tests when no spring is disabled
    # or elongation-only (the flags are not tunable).
    damped = not planner.prune or bool(np.any(springs[:, 3] != 0.0))
    if not damped and count:
        planner.pruned.setdefault(kd.key, "every spring's damping is zero: no damping term computed")
    flagged = bool(np.any(elongation.initial)) or not bool(np.all(enabled.initial))
    variant = f"{types}, {'true' if damped else 'false'}, {'true' if flagged else 'false'}"
    origin = origin_of(component)
    jacobians = "nullptr"
    if group.scheme == "implicit":  # dF/dx per spring, stored by the force pass, used by K dx
        dim = {"Rigid3d": 3, "Rigid2d": 2}.get(first.datatype.name, min(first.datatype.coord_size, 3))
        blocks = planner.buffer(component, "dfdx", np.zeros(count * (dim + 2)), role="scratch")  # factored
        jacobians = _ptr(blocks)
        if group.direct or group.assembled_cg:
            offset1, offset2 = group.assembly_offset(first, checked), group.assembly_offset(second, checked)
            code = f"sofac::assemble_springs<{types}>(A, {table}, {jacobians}, {offset1}, {offset2}, kfact);"
            group.assemble.append(Op(origin, [code]))
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    f"sofac::spring_dforces<{types}>({table}, {jacobians}, "
                    f"{_ptr(first.dx)}, {_ptr(first.df)}, {_ptr(second.dx)}, {_ptr(second.df)}, kfact);"
                ],
            )
        )
    group.forces.append(
        Op(
            origin,
            [
                f"sofac::spring_forces<{variant}>({table}, "
                f"{_ptr(first.x)}, {_ptr(first.v)}, {_ptr(first.f)}, "
                f"{_ptr(second.x)}, {_ptr(second.v)}, {_ptr(second.f)}, {jacobians});"
            ],
        )
    )
    group.energy.append(
        Op(
            origin,
            [f"potential += sofac::spring_energy<{types}>({table}, {_ptr(first.x)}, {_ptr(second.x)});"],
        )
    )


def _matrix_solver(group: Group) -> str:
    """The linear solver of an assembled group, as messages name it."""
    if group.assembled_cg:
        return "a CGLinearSolver on an assembled matrix"
    if group.preconditioner:
        return "a PCGLinearSolver's assembled preconditioner"
    return "a sparse direct solver"


def _matrix_free_hint(group: Group) -> str:
    if group.assembled_cg:
        return 'use the matrix-free CGLinearSolver (template="GraphScattered", the default)'
    return "use CGLinearSolver"


def _assemble(
    planner: _Planner, checked: CheckedComponent, group: Group, state: StatePlan, code: Callable[[str], str]
) -> None:
    """An assembled solver's share of a component: its blocks of A, at the state's offset (through the
    mappings' J for a mapped state)."""
    if not group.assembled:
        return
    group.assemble.append(Op(origin_of(checked.component), [code(group.assembly_offset(state, checked))]))


def _lower_springs(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = []
    for role in ("object1", "object2"):
        target = checked.links.get(role)
        if not isinstance(target, Component):
            target = checked.state or planner.checked.resolver._node_state(checked.component.node)
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


def _lower_grid_springs(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """RegularGridSpringForceField: its own springs, then springs along the grid's edges, face
    diagonals and cube diagonals, in SOFA's loop order, ks = stiffness / rest length."""
    import math

    from .barycentric import RegularGrid

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


def _lower_mesh_springs(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    topology = checked.links.get("topology")
    if not isinstance(topology, Component):
        topology = planner.checked.resolver._singleton(component.node, "topology")
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
                length = float(np.linalg.norm(rest[j, :3] - rest[i, :3]))
                if length > 1e-12:  # SOFA scales by the rest length (per unit length stiffness)
                    rows.append((i, j, ks / length, kd / length, length))
    springs = np.array(rows, dtype=float).reshape(-1, 5)
    _add_springs(planner, checked, springs, state, state, group)


def _lower_constant_force(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    width = state.datatype.deriv_size
    indices = _indices(planner, checked, "indices", state.size)
    forces = planner.value(component, "forces")
    total = planner.value(component, "totalForce")
    single = planner.value(component, "force")
    if forces is not None and np.size(forces):
        rows = np.asarray(forces, dtype=float).reshape(-1, width)
        rows = rows if len(rows) == len(indices) else np.tile(rows[-1], (len(indices), 1))
    elif total is not None and np.size(total) and len(indices):
        rows = np.tile(np.asarray(total, dtype=float).ravel()[:width] / len(indices), (len(indices), 1))
    elif single is not None and np.size(single):
        rows = np.tile(np.asarray(single, dtype=float).ravel()[:width], (len(indices), 1))
    else:
        rows = np.zeros((len(indices), width))
    index_buffer = planner.buffer(component, "indices", indices, "i64")
    force_buffer = planner.buffer(component, "forces", rows, columns=width, role="param")
    group.forces.append(
        Op(
            origin_of(component),
            [_call(f"constant_forces<{state.cpp_type}>", state.f, index_buffer, force_buffer, len(indices))],
        )
    )


def _lower_rest_shape(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid or checked.links.get("external_rest_shape") is not None:
        planner.unsupported(checked, "rigid or external rest shapes are not compiled yet")
        return
    indices = _indices(planner, checked, "points", state.size)
    stiffness = planner.value(component, "stiffness")
    stiffness = np.asarray(
        stiffness if stiffness is not None and np.size(stiffness) else [100.0], dtype=float
    )
    index_buffer = planner.buffer(component, "points", indices, "i64")
    k_buffer = planner.buffer(component, "stiffness", stiffness, role="param")
    origin = origin_of(component)
    arguments = f"{_ptr(index_buffer)}, {_ptr(k_buffer)}, {stiffness.size}, {len(indices)}"
    t = state.cpp_type
    group.forces.append(
        Op(
            origin,
            [_call(f"rest_shape_forces<{t}>", state.f, state.x, state.rest, arguments)],
        )
    )
    if group.scheme == "implicit":
        group.stiffness_dx.append(
            Op(origin, [_call(f"rest_shape_dforces<{t}>", state.df, state.dx, arguments, "kfact")])
        )
        _assemble(
            planner,
            checked,
            group,
            state,
            lambda offset: _call(f"assemble_rest_shape<{t}>", "A", offset, arguments, "kfact"),
        )
    group.energy.append(
        Op(
            origin,
            ["potential += " + _call(f"rest_shape_energy<{t}>", state.x, state.rest, arguments)],
        )
    )


def _fixed_indices(planner: _Planner, checked: CheckedComponent, state: StatePlan) -> np.ndarray:
    if planner.value(checked.component, "fixAll"):
        return np.arange(state.size, dtype=np.int64)
    return _indices(planner, checked, "indices", state.size, all_if_empty=False)


def _projected_target(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group] | None:
    """A projective constraint's state and group; None (kept out, with why) on a mapped state."""
    found = _target(planner, checked, owner)
    if found is not None and found[0].acc is None:
        planner.ignored.append(
            (checked.component, "on a mapped state: projections act on independent states")
        )
        return None
    return found


def _lower_fixed(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    indices = planner.buffer(checked.component, "indices", _fixed_indices(planner, checked, state), "i64")
    t = state.cpp_type
    group.projections.append(
        Projection(
            origin_of(checked.component),
            state,
            lambda vector: _call(f"project_fixed<{t}>", vector, indices, _count(indices)),
            bool(planner.value(checked.component, "activate_projectVelocity")),
            lambda offset: _call(f"mark_fixed<{t}>", "D.fixed", offset, indices, _count(indices)),
        )
    )


def _lower_partial_fixed(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    width = state.datatype.deriv_size
    directions = planner.value(checked.component, "fixedDirections")
    flags = np.zeros(width, dtype=np.int64)
    if directions is not None:
        given = np.asarray(directions, dtype=bool).ravel()[:width]
        flags[: given.size] = given
    indices = planner.buffer(checked.component, "indices", _fixed_indices(planner, checked, state), "i64")
    mask = planner.buffer(checked.component, "fixedDirections", flags, "i64")
    t = state.cpp_type
    velocity = planner.value(checked.component, "projectVelocity") or planner.value(
        checked.component, "activate_projectVelocity"
    )
    group.projections.append(
        Projection(
            origin_of(checked.component),
            state,
            lambda vector: _call(f"project_partial<{t}>", vector, indices, _count(indices), mask),
            bool(velocity),
            lambda offset: _call(f"mark_fixed<{t}>", "D.fixed", offset, indices, _count(indices), mask),
        )
    )


def _unit_vector(
    planner: _Planner, component: Component, name: str, width: int, zero: int | None
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


def _lower_line_or_plane(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """Line- and PlaneProjectiveConstraint: responses and velocities through the block n n^T (line)
    or I - n n^T (plane) of the listed points; positions onto the line / plane after each step."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if group.assembled:
        planner.unsupported(
            checked,
            f"with {_matrix_solver(group)} (SOFA does not project the assembled matrix for it either); "
            f"{_matrix_free_hint(group)}",
        )
        return
    line = checked.spec is not None and checked.spec.role == "line"
    width = min(state.datatype.spatial_dim, 3)  # the runtime's DT::spatial
    direction = _unit_vector(
        planner, component, "direction" if line else "normal", width, 0 if line else None
    )
    outer = np.array([[float(a) * float(b) for b in direction] for a in direction])
    block = outer if line else np.eye(width) - outer
    origin = np.zeros(width)
    given = planner.value(component, "origin")
    if given is not None:
        flat = np.asarray(given, dtype=float).ravel()[:width]
        origin[: flat.size] = flat
    indices = planner.buffer(component, "indices", _indices(planner, checked, "indices", state.size), "i64")
    block_buffer = planner.buffer(component, "projection", block)
    origin_buffer = planner.buffer(component, "origin", origin)
    direction_buffer = planner.buffer(component, "direction" if line else "normal", direction)
    t = state.cpp_type
    onto = "project_onto_line" if line else "project_onto_plane"
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            lambda vector: _call(f"project_block<{t}>", vector, indices, _count(indices), block_buffer),
            velocity=True,
            position=lambda x: _call(
                f"{onto}<{t}>", x, indices, _count(indices), origin_buffer, direction_buffer
            ),
        )
    )


def _lower_point_constraint(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """PointProjectiveConstraint: the listed DOFs (all with fixAll) held at ``point``."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    indices = planner.buffer(component, "indices", _fixed_indices(planner, checked, state), "i64")
    target = np.zeros(state.datatype.coord_size)
    given = planner.value(component, "point")
    if given is not None:
        flat = np.asarray(given, dtype=float).ravel()[: target.size]
        target[: flat.size] = flat
    target_buffer = planner.buffer(component, "point", target)
    t = state.cpp_type
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            lambda vector: _call(f"project_fixed<{t}>", vector, indices, _count(indices)),
            velocity=True,
            mark=lambda offset: _call(f"mark_fixed<{t}>", "D.fixed", offset, indices, _count(indices)),
            position=lambda x: _call(f"project_onto_point<{t}>", x, indices, _count(indices), target_buffer),
        )
    )


def _lower_linear_velocity(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """LinearVelocityProjectiveConstraint: the listed DOFs move at a velocity interpolated between key
    times (SOFA's findKeyTimes at each step's start time), integrated explicitly from their last
    projected positions; their solver increments are zeroed while it is active."""
    found = _projected_target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if state.datatype.rigid:
        planner.unsupported(checked, "on rigid DOFs it is not compiled yet (Vec types only)")
        return
    if group.assembled:
        planner.unsupported(
            checked, f"with {_matrix_solver(group)} it is not compiled yet; {_matrix_free_hint(group)}"
        )
        return
    width, coord = state.datatype.deriv_size, state.datatype.coord_size
    times = np.asarray(planner.value(component, "keyTimes"), dtype=float).ravel()
    given = planner.value(component, "velocities")  # SOFA starts the list with one zero velocity
    velocities = np.asarray(given if given is not None and np.size(given) else np.zeros(width), dtype=float)
    velocities = velocities.reshape(-1, width)
    if len(times) != len(velocities):
        planner.unsupported(checked, f"it has {len(times)} keyTimes but {len(velocities)} velocities")
        return
    coordinates = _indices(planner, checked, "coordinates", 0, all_if_empty=False)
    if len(coordinates) and (coordinates.min() < 0 or coordinates.max() >= width):
        planner.unsupported(checked, f"its coordinates must be between 0 and {width - 1}")
        return
    indices = planner.buffer(component, "indices", _fixed_indices(planner, checked, state), "i64")
    count = len(indices.initial)
    memory = planner.buffer(component, "memory", np.zeros(4 + 2 * width + count * coord), role="scratch")
    time_buffer = planner.buffer(component, "keyTimes", times)
    velocity_buffer = planner.buffer(component, "velocities", velocities, columns=width)
    coordinate_buffer = planner.buffer(component, "coordinates", coordinates, "i64")
    t = state.cpp_type
    after_end = "true" if planner.value(component, "continueAfterEnd") else "false"
    keyed = (
        f"sofac::KeyedVelocity<{t}>{{{_ptr(memory)}, {_ptr(time_buffer)}, {_ptr(velocity_buffer)}, "
        f"{len(times)}, {after_end}}}"
    )
    selected = (indices, _count(indices))
    chosen = (coordinate_buffer, _count(coordinate_buffer))
    group.projections.append(
        Projection(
            origin_of(component),
            state,
            lambda vector: _call(f"keyed_velocity_response<{t}>", keyed, vector, *selected, "S.time"),
            velocity=True,
            position=lambda x: _call(
                f"keyed_velocity_position<{t}>",
                keyed,
                x,
                *selected,
                *chosen,
                "S.time",
                f"S.{planner.dt.ident}[0]",
            ),
            project_velocity=lambda v: _call(
                f"keyed_velocity_velocity<{t}>", keyed, v, *selected, *chosen, "S.time"
            ),
        )
    )


def _lower_plane_force(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """PlaneForceField: a penalty on the points under the plane (stiffness in implicit solves)."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if group.assembled:
        planner.unsupported(
            checked, f"its contact-dependent stiffness is not assembled for {_matrix_solver(group)} yet"
        )
        return
    width = min(state.datatype.spatial_dim, 3)  # the runtime's DT::spatial
    normal = np.zeros(width)
    flat = np.asarray(planner.value(component, "normal"), dtype=float).ravel()[:width]
    normal[: flat.size] = flat
    first, last = (int(v) for v in planner.value(component, "localRange"))
    begin = first if first >= 0 else 0
    end = last + 1 if last >= 0 and last + 1 < state.size else state.size
    bilateral = "true" if planner.value(component, "bilateral") else "false"
    contact = planner.buffer(component, "contacts", np.zeros(state.size), "i64", role="scratch")
    normal_buffer = planner.buffer(component, "normal", normal, role="param")
    parameters = {
        name: planner.buffer(component, name, [float(planner.value(component, name))], role="param")
        for name in ("d", "stiffness", "damping", "maxForce")
    }
    origin = origin_of(component)
    t = state.cpp_type
    group.forces.append(
        Op(
            origin,
            [
                _call(
                    f"plane_forces<{t}>",
                    state.f,
                    state.x,
                    state.v,
                    contact,
                    normal_buffer,
                    parameters["d"],
                    parameters["stiffness"],
                    parameters["damping"],
                    parameters["maxForce"],
                    bilateral,
                    begin,
                    end,
                )
            ],
        )
    )
    if group.scheme == "implicit":
        stiffness = parameters["stiffness"]
        group.stiffness_dx.append(
            Op(
                origin,
                [
                    _call(
                        f"plane_dforces<{t}>",
                        state.df,
                        state.dx,
                        contact,
                        normal_buffer,
                        stiffness,
                        "kfact",
                        begin,
                        end,
                    )
                ],
            )
        )
    group.energy.append(
        Op(
            origin,
            [
                "potential += "
                + _call(
                    f"plane_energy<{t}>",
                    state.x,
                    normal_buffer,
                    parameters["d"],
                    parameters["stiffness"],
                    bilateral,
                    begin,
                    end,
                )
            ],
        )
    )


def _lower_triangle_pressure(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """TrianglePressureForceField with useConstantForce: pressure x rest area on the listed triangles."""
    found = _target(planner, checked, owner)
    if found is None:
        return
    state, group = found
    component = checked.component
    if not planner.value(component, "useConstantForce"):
        planner.unsupported(
            checked, 'useConstantForce="0" (a Cauchy stress on the current areas) is not compiled yet'
        )
        return
    chosen = _indices(planner, checked, "triangleList", 0, all_if_empty=False)
    triangles = (
        (_topology_cells(planner, checked) or {}).get("triangles", np.zeros(0, np.int64)).reshape(-1, 3)
    )
    points = planner.checked.positions(state.component)
    if len(chosen) and (points is None or chosen.max() >= len(triangles)):
        planner.unsupported(
            checked, f"its triangleList points past the {len(triangles)} triangles of its topology"
        )
        return
    corners = triangles[chosen]
    from . import masses

    areas = masses.triangle_areas(*(points[corners[:, k], :3] for k in range(3)))
    pressure = np.zeros(min(state.datatype.spatial_dim, 3))
    given = planner.value(component, "pressure")
    if given is not None and np.size(given):
        flat = np.asarray(given, dtype=float).ravel()[: pressure.size]
        pressure[: flat.size] = flat
    corner_buffer = planner.buffer(component, "triangles", corners, "i64")
    area_buffer = planner.buffer(component, "areas", areas)
    pressure_buffer = planner.buffer(component, "pressure", pressure, role="param")
    group.forces.append(
        Op(
            origin_of(component),
            [
                _call(
                    f"triangle_pressure<{state.cpp_type}>",
                    state.f,
                    corner_buffer,
                    area_buffer,
                    len(corners),
                    pressure_buffer,
                )
            ],
        )
    )


def _mapping_ends(
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
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


def _lower_rigid_mapping(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    pair = (parent.datatype.name, child.datatype.name)
    if pair not in (("Rigid3d", "Vec3d"), ("Rigid2d", "Vec2d")):
        planner.unsupported(checked, f"RigidMapping {pair[0]},{pair[1]} is not compiled yet")
        return
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
        local = _to_local(frames, frame_of, local)
    local_buffer = planner.buffer(component, "initialPoints", local, columns=dim)
    frame_buffer = planner.buffer(component, "rigidIndexPerPoint", frame_of, "i64")
    offset = planner.buffer(component, "offsets", np.zeros_like(local), columns=dim, role="scratch")
    prefix = "rigid" if dim == 3 else "rigid2"
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
            lambda up, down: _call(f"{prefix}_apply_j", up, down, frame_buffer, offset, n),
            (lambda up, down: _call(f"{prefix}_apply_jt", up, down, frame_buffer, offset, n))
            if maps_forces
            else None,
            # J depends on the rotated offsets of this step's apply: refilled every assembly.
            assembly=lambda first, input_first: _call(
                f"{prefix}_jacobian", "A", first, input_first, frame_buffer, offset, n
            ),
        )
    )


def _to_local(frames: np.ndarray, frame_of: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Global points expressed in their frame (globalToLocalCoords)."""
    local = np.empty_like(points)
    for k, (point, c) in enumerate(zip(points, frame_of, strict=True)):
        frame = frames[c]
        if frames.shape[1] == 7:
            x, y, z, w = frame[3:7]
            rotation = np.array(
                [
                    [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
                ]
            )
            local[k] = rotation.T @ (point - frame[:3])
        else:
            c_, s_ = np.cos(frame[2]), np.sin(frame[2])
            d = point - frame[:2]
            local[k] = [c_ * d[0] + s_ * d[1], -s_ * d[0] + c_ * d[1]]
    return local


def _lower_subset_mapping(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    ends = _mapping_ends(planner, checked, owner)
    if ends is None:
        return
    parent, child, group = ends
    component = checked.component
    if parent.datatype is not child.datatype:
        planner.unsupported(checked, f"{component.type_name} between different templates is not compiled yet")
        return
    if checked.spec and checked.spec.kernel == "identity_mapping":
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
    t, n = parent.cpp_type, indices.size
    coord, deriv = parent.datatype.coord_size, parent.datatype.deriv_size
    origin = origin_of(component)
    maps_forces = planner.value(component, "mapForces") is not False
    group.mappings.append(
        MappingOp(
            origin,
            parent,
            child,
            [
                _call(f"subset_apply<{t}>", parent.x, child.x, buffer, n, coord),
                _call(f"subset_apply<{t}>", parent.v, child.v, buffer, n, deriv),
            ],
            lambda up, down: _call(f"subset_apply<{t}>", up, down, buffer, n, deriv),
            (lambda up, down: _call(f"subset_apply_jt<{t}>", up, down, buffer, n)) if maps_forces else None,
            assembly=lambda first, input_first: (
                "if (A.recording()) "  # a constant selection: once
                + _call(f"subset_jacobian<{t}>", "A", first, input_first, buffer, n)
            ),
        )
    )


def _lower_barycentric_mapping(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    from .barycentric import RegularGrid, SparseGrid, map_cells, mapper_for

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
    mode = mapper_for(topology_spec.role if topology_spec else "")
    grid = None
    if mode == "regular_grid" and topology is not None:
        bounds = np.asarray(planner.value(topology, "bounds"), dtype=float)
        grid = RegularGrid(tuple(int(c) for c in cells["resolution"]), tuple(bounds[:3]), tuple(bounds[3:]))
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
    try:
        indices, weights = map_cells(rest, points, cells, mode=mode, grid=grid)
    except ValueError as error:
        planner.unsupported(checked, f"it cannot embed its points: {error}")
        return
    n, k = indices.shape
    index_buffer = planner.buffer(component, "indices", indices, "i64", columns=k)
    weight_buffer = planner.buffer(component, "weights", weights, columns=k)
    maps_forces = planner.value(component, "mapForces") is not False

    def jacobian(up: Buffer, down: Buffer) -> str:
        return _call("linear_map_apply", up, down, index_buffer, weight_buffer, n, k, 3)

    group.mappings.append(
        MappingOp(
            origin_of(component),
            parent,
            child,
            [jacobian(parent.x, child.x), jacobian(parent.v, child.v)],
            jacobian,
            (lambda up, down: _call("linear_map_apply_jt", up, down, index_buffer, weight_buffer, n, k, 3))
            if maps_forces
            else None,
            assembly=lambda first, input_first: (
                "if (A.recording()) "  # constant weights: once
                + _call("linear_jacobian", "A", first, input_first, index_buffer, weight_buffer, n, k, 3)
            ),
        )
    )


def _element_cells(
    planner: _Planner, checked: CheckedComponent, state: StatePlan
) -> tuple[str, int, np.ndarray] | None:
    """Element-based FEM (runtime/sofac/element_fem.h): the element type of a "Vec3d,Element"
    template, its nodes per element and the cells of the topology the component uses."""
    from . import element_fem

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
    planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]
) -> tuple[StatePlan, Group, tuple[str, int, np.ndarray]] | None:
    """The state, group and elements (type, corners, cells) an element component acts on."""
    found = _target(planner, checked, owner)
    if found is None:
        return None
    state, group = found
    geometry = _element_cells(planner, checked, state)
    return None if geometry is None else (state, group, geometry)


def _lower_element_fem(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """CorotationalFEMForceField and LinearSmallStrainFEMForceField on tetrahedra or hexahedra."""
    from . import element_fem

    found = _element_target(planner, checked, owner)
    if found is None:
        return
    state, group, (element, corners, cells) = found
    component = checked.component
    if float(planner.value(component, "rayleighStiffness") or 0.0) != 0.0:
        planner.unsupported(checked, "a component-level rayleighStiffness is not compiled yet")
        return
    corotational = checked.spec is not None and checked.spec.role == "corotational"
    method = 0
    if corotational:
        name = planner.value(component, "rotationMethod")
        code = element_fem.rotation_method(name, element)
        if code is None:
            planner.unsupported(checked, f"rotationMethod {name!r} does not exist for {element}")
            return
        method = code
    count, size = cells.size // corners, 3 * corners
    young = planner.value(component, "youngModulus")
    poisson = planner.value(component, "poissonRatio")
    elements = planner.buffer(component, element_fem.ELEMENTS[element][1], cells, "i64", columns=corners)
    young_buffer = planner.buffer(
        component, "youngModulus", np.atleast_1d(young if young is not None else []), role="param"
    )
    poisson_buffer = planner.buffer(
        component, "poissonRatio", np.atleast_1d(poisson if poisson is not None else []), role="param"
    )
    stiffness = planner.buffer(
        component, "elementStiffness", np.zeros(count * size * size), columns=size * size, role="scratch"
    )
    origin = origin_of(component)
    n = corners
    init = [
        _call(
            f"element_fem_stiffness_init<{n}>",
            elements,
            count,
            state.rest,
            young_buffer,
            _count(young_buffer),
            poisson_buffer,
            _count(poisson_buffer),
            stiffness,
        )
    ]
    rotations = None
    if corotational:
        rotations = planner.buffer(component, "rotations", np.zeros(count * 18), columns=18, role="scratch")
        init.append(_call(f"element_corot_init<{n}>", elements, count, state.rest, method, rotations))
        force = _call(
            f"element_corot_add_force<{n}>",
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
            f"element_linear_add_force<{n}>", elements, count, state.x, state.rest, stiffness, state.f
        )
    group.init.append(Op(origin, init))
    group.forces.append(Op(origin, [force]))
    if group.scheme != "implicit":
        return
    if rotations is not None:
        dforce = _call(
            f"element_corot_add_dforce<{n}>",
            elements,
            count,
            state.dx,
            state.df,
            "kfact",
            stiffness,
            rotations,
        )
    else:
        dforce = _call(
            f"element_linear_add_dforce<{n}>", elements, count, state.dx, state.df, "kfact", stiffness
        )
    group.stiffness_dx.append(Op(origin, [dforce]))
    _assemble(
        planner,
        checked,
        group,
        state,
        lambda offset: _call(
            f"element_fem_assemble<{n}>",
            "A",
            elements,
            count,
            stiffness,
            _ptr(rotations) if rotations is not None else "nullptr",
            offset,
            "kfact",
        ),
    )


def _nodal_mass_density(planner: _Planner, checked: CheckedComponent) -> Component | None:
    """FEMMass's density: its nodalMassDensity link, else the first NodalMassDensity of its context."""
    linked = checked.links.get("nodalMassDensity")
    if isinstance(linked, Component):
        return linked
    for node in (checked.component.node, *checked.component.node.ancestors()):
        for candidate in node.objects:
            spec = planner.checked.of(candidate).spec
            if spec is not None and spec.role == "nodal_mass_density":
                return candidate
    return None


def _lower_fem_mass(planner: _Planner, checked: CheckedComponent, owner: dict[int, Group]) -> None:
    """FEMMass: the consistent scalar mass matrix of the elements, from a NodalMassDensity."""
    from . import element_fem

    found = _element_target(planner, checked, owner)
    if found is None:
        return
    state, group, (_, corners, cells) = found
    component = checked.component
    if group.scheme != "implicit":
        if group.scheme != "euler" or not group.assembled:
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
                    f"fem_mass_init<{n}>",
                    elements,
                    count,
                    state.rest,
                    density,
                    _count(density),
                    *csr[:2],
                    state.size,
                    values,
                )
            ],
        )
    )
    planner.add_gravity(group, Op(origin, [_call("fem_mass_gravity", state.f, *csr, planner.gravity)]))
    if group.scheme == "implicit":
        group.mass_dx.append(Op(origin, [_call("fem_mass_multiply", state.df, state.dx, *csr, "mfact")]))
    _assemble(
        planner, checked, group, state, lambda offset: _call("assemble_fem_mass", "A", offset, *csr, "mfact")
    )
    group.energy.append(
        Op(
            origin,
            [
                "kinetic += " + _call("fem_mass_kinetic_energy", state.v, *csr),
                "potential += " + _call("fem_mass_potential_energy", state.x, *csr, planner.gravity),
            ],
        )
    )


LOWERINGS: dict[str, Lowering] = {
    "grid_springs": _lower_grid_springs,
    "element_fem": _lower_element_fem,
    "fem_mass": _lower_fem_mass,
    "mesh_matrix_mass": _lower_mesh_matrix_mass,
    "tetra_fem": _lower_fem,
    "tetracorot_fem": _lower_fem,
    "hexa_fem": _lower_fem,
    "trifem": _lower_fem,
    "trifem_optim": _lower_trifem_optim,
    "quad_bending_springs": _lower_quad_bending_springs,
    "triangular_bending_springs": _lower_triangular_bending_springs,
    "interaction_ellipsoid": _lower_interaction_ellipsoid,
    "distance_mapping": _lower_distance_mapping,
    "distance_multi_mapping": _lower_distance_multi_mapping,
    "velocity_damping": _lower_velocity_damping,
    "bending_springs": _lower_bending_springs,
    "barycentric_mapping": _lower_barycentric_mapping,
    "uniform_mass": _lower_uniform_mass,
    "diagonal_mass": _lower_diagonal_mass,
    "springs": _lower_springs,
    "mesh_springs": _lower_mesh_springs,
    "constant_force": _lower_constant_force,
    "rest_shape_springs": _lower_rest_shape,
    "fixed": _lower_fixed,
    "partial_fixed": _lower_partial_fixed,
    "line_or_plane": _lower_line_or_plane,
    "point_constraint": _lower_point_constraint,
    "linear_velocity": _lower_linear_velocity,
    "plane_force": _lower_plane_force,
    "triangle_pressure": _lower_triangle_pressure,
    "rigid_mapping": _lower_rigid_mapping,
    "identity_mapping": _lower_subset_mapping,
    "subset_mapping": _lower_subset_mapping,
}


def plan_scene(
    checked: CheckedScene,
    diagnostics: Diagnostics | None = None,
    *,
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
) -> Plan:
    """The static schedule of a checked scene; raises SceneError (E222...) when it cannot be compiled.
    With ``prune``, effects the scene makes vanish (zero gravity) get no code. ``rigid_model="exact"``
    turns rigid inertias with their bodies and keeps the gyroscopic term (explicit solvers; SOFA's
    model, the default, applies the inertia in world axes). ``threads`` > 1 splits large element
    loops over that many OpenMP threads, with the serial results bit for bit."""
    if rigid_model not in ("sofa", "exact"):
        raise ValueError(f"rigid_model must be 'sofa' or 'exact', not {rigid_model!r}")
    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, not {threads!r}")
    return _Planner(
        checked, diagnostics if diagnostics is not None else Diagnostics(), prune, rigid_model, threads
    ).run()


def format_effects(plan: Plan) -> str:
    """The effects the step contains, and those left out, for ``sofac inspect --effects``."""
    width = max((len(e) for e, _, _ in plan.effects), default=0)
    return "\n".join(f"{effect:<{width}}  {origin}: {detail}" for effect, origin, detail in plan.effects)


def format_schedule(plan: Plan) -> str:
    """The plan as text, for ``sofac inspect --schedule``."""
    lines = [
        f"scene {plan.scene_file}",
        f"dt = {float(plan.dt.initial[0])!r}, gravity = {plan.gravity.initial.tolist()}",
    ]
    for group in plan.groups:
        scheme = {
            "euler": "symplectic Euler" if group.symplectic else "explicit Euler",
            "rk2": "RK2 (midpoint)",
            "rk4": "RK4",
            "implicit": "static equilibrium (Newton-Raphson)"
            if group.static
            else "Newmark"
            if group.newmark
            else "variational symplectic (implicit midpoint)"
            if group.variational
            else "implicit Euler",
        }[group.scheme]
        lines.append(f"solver {origin_of(group.solver)}: {scheme}")
        lines.append(
            "  independent states: "
            + ", ".join(f"{s.path} <{s.datatype.name}> x{s.size}" for s in group.states)
        )
        if group.mapped:
            lines.append(
                "  mapped states: "
                + ", ".join(f"{s.path} <{s.datatype.name}> x{s.size}" for s in group.mapped)
            )
        sections: list[tuple[str, list[str]]] = [
            ("propagate x, v down the mappings", [m.origin for m in group.mappings]),
            ("reset forces, accumulate forces and gravity", [op.origin for op in group.forces]),
            ("map forces up (J^T), child first", [m.origin for m in reversed(group.mappings) if m.transpose]),
        ]
        if group.scheme == "implicit":
            if group.static:
                rhs, system = "b = f, projected", "Newton iterations: solve -K dx = f, x += alpha dx"
            elif group.newmark:
                rhs = "b = f + (-rm M + (rk + h) K) v + (...) a, projected"
                system = "solve ((1 + h gamma rm) M - (h^2 beta + h gamma rk) K) a' = b"
            elif group.variational:
                rhs = "Newton iterations: b = f(x + res) - K res + (2/h) p, projected"
                system = "solve ((4/h^2 + 4 rm/h) M - (1 + 4 rk/h) K) res = b"
            elif group.first_order:
                rhs, system = "b = f, projected (firstOrder)", "solve (M - h K) v' = b"
            else:
                rhs, system = (
                    "b = h (f - rm M v + (h + rk) K v), projected",
                    "solve ((1 + h rm) M - h (h + rk) K) dv = b",
                )
            sections += [
                (f"{rhs}; M dx", [op.origin for op in group.mass_dx]),
                ("K dx", [op.origin for op in group.stiffness_dx]),
            ]
            if group.assembled_cg:
                block = group.cg_block
                sections.append(
                    (
                        f"assemble mfact M + kfact K (rows of {block}x{block} blocks), projected",
                        [op.origin for op in group.assemble],
                    )
                )
            on = " on the assembled matrix" if group.assembled_cg else ""
            sections.append((f"{system} with {origin_of(group.linear_solver)}{on}", []))
        else:
            sections.append(("a = M^-1 f", [op.origin for op in group.accelerations]))
        sections.append(("project constraints", [p.origin for p in group.projections]))
        for title, origins in sections:
            lines.append(f"  {title}:")
            lines.extend(f"    - {origin}" for origin in origins)
        lines.append("  update x, v; propagate again")
        if group.on_read:
            lines.append("  mapped only when read from Python (nothing in the step reads them):")
            lines.extend(f"    - {m.origin} -> {m.child.path}" for m in group.on_read)
    idle = [s for s in plan.states if not s.mapped and not any(s in g.states for g in plan.groups)]
    for state in idle:
        lines.append(f"not integrated (no ODE solver): {state.path}")
    for component, why in plan.ignored:
        lines.append(f"kept out of the step: {origin_of(component)}: {why}")
    return "\n".join(lines)
