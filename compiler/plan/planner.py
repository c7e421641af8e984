"""Plan stage: what SOFA's visitors would do each step, worked out once from a checked scene.

The plan is a small IR: the arrays the compiled instance owns (state vectors, parameters, bulk
data such as spring lists), the mechanical states in SOFA's traversal order, and for each ODE
solver its *group* (section 5.1 of the SOFA introduction): the independent states it integrates,
the mapped states below them in parent → child order, and the kernel calls of one step
(propagate down the mappings, accumulate forces, map forces up with Jᵀ, a = M⁻¹f, project).

Each component is lowered by the function its spec names (``ComponentSpec.lowering``); a component
that takes part in the step but has no lowering is reported as unsupported (E222), with its line.
Nothing from the scene text reaches C++: identifiers are made here from counters, and every
number and array is a buffer handed to the instance when it is created.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from sofac.check.checker import CheckedComponent, CheckedScene
from sofac.diagnostics import Diagnostics, SceneError
from sofac.front.model import Component, Node
from sofac.plan.contacts import contact_response_refusals, contact_setup_refusal, plan_collisions
from sofac.plan.ir import (
    COMPILED_DATATYPES,
    Buffer,
    Collision,
    ConstraintPhase,
    ContactGuard,
    Group,
    Op,
    Plan,
    Response,
    Scheme,
    StatePlan,
    independent_groups,
)
from sofac.plan.lazy_contacts import map_contact_states_while_touching
from sofac.plan.lower import LOWERINGS
from sofac.plan.lower.common import _mapping_inputs, _topology_of
from sofac.plan.lower.constraint_context import ConstraintLowering
from sofac.plan.lower.constraints import finish_constraint_phase
from sofac.plan.passes import (
    add_point_forces,
    contact_guard,
    drop_unread_rest_positions,
    effects,
    init_only,
    leave_unread_out,
    route_through_mappings,
)
from sofac.plan.solvers import new_group, screen_bdf, screen_btd, screen_variational
from sofac.registry import Category, Variant
from sofac.registry.datatypes import DATATYPES

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


class Planner:
    def __init__(
        self,
        checked: CheckedScene,
        diagnostics: Diagnostics,
        prune: bool = True,
        rigid_model: str = "sofa",
        threads: int = 1,
        interactive: bool = False,
    ) -> None:
        self.checked = checked
        self.interactive = interactive
        self.diags = diagnostics
        self.prune = prune
        self.rigid_model = rigid_model
        self.threads = threads
        self.guarded: list[CheckedComponent] = []  # collision models that could touch (ContactGuard)
        self.guard: ContactGuard | None = None
        self.colliding = False  # contacts compiled (plan/contacts.py) rather than guarded
        self.contact_refusal = ""  # why the scene's contacts are not compiled (then guarded)
        self.collisions: list[Collision] = []
        self.pruned: dict[str, str] = {}  # parameter key -> why the code using it was left out
        self.refused: set[int] = set()  # components whose one refusal says all (no follow-up E222)
        self.lowered: list[Component] = []  # components whose kernels are in the step
        self.buffers: list[Buffer] = []
        self.buffer_count = 0  # buffers ever made: identifiers stay unique when one is dropped
        self.states: dict[int, StatePlan] = {}
        self.ignored: list[tuple[Component, str]] = []
        self.constraints: ConstraintPhase | None = None  # FreeMotionAnimationLoop's constraint phase
        # What the constraint lowerings share while they run (plan/lower/constraint_context.py).
        self.constraint_lowering: ConstraintLowering | None = None

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

    def unsupported(self, checked: CheckedComponent, why: str, attribute: str | None = None) -> None:
        """E222 at the component, or at its `attribute` when the scene writes it."""
        component = checked.component
        if id(component) in self.refused:
            return
        written = component.attributes.get(attribute) if attribute is not None else None
        self.diags.add(
            "E222",
            written.loc if written is not None else component.loc,
            f"unsupported component {component.type_name} at line {component.loc.line}: {why}",
            "sofac check --allow-unsupported validates such scenes without compiling them",
        )

    # --- run -----------------------------------------------------------------------------------
    def run(self) -> Plan:
        root = self.checked.scene.root
        dt = float(self.value_node(root, "dt"))
        gravity = np.asarray(self.value_node(root, "gravity"), dtype=float)
        for checked in self.checked:
            if checked.spec and checked.spec.variant is Variant.GRAVITY:
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
        solving |= {id(c) for g in groups for c in g.preconditioners}
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
            effects=effects(self, groups),
            init_only=init_only(self, groups),
            threads=self.threads,
            rigid_model=self.rigid_model,
            interactive=self.interactive,
            contact_guard=self.guard,
            collisions=self.collisions,
            constraints=self.constraints,
            parallel_groups=self.threads > 1
            and independent_groups(groups, {self.dt.ident, self.gravity.ident}),
        )

    def value_node(self, node: Node, name: str) -> Any:
        from sofac.registry import node_spec

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
        self.contact_refusal = contact_setup_refusal(self) if contacts else ""
        self.colliding = contacts and not self.contact_refusal
        if contacts:
            for checked, why in contact_response_refusals(self):
                self.unsupported(checked, why, attribute="contactResponse")
        for checked in self.checked:
            spec = checked.spec
            if spec is None:
                continue
            if checked.category is Category.COLLISION_MODEL and self.colliding:
                if self.value(checked.component, "active") is False:
                    self.ignored.append((checked.component, "inactive collision model"))
            elif checked.category is Category.COLLISION_MODEL and contacts and guard:
                if self.value(checked.component, "active") is not False:
                    self.guarded.append(checked)  # an effect of the step (see _contact_guard)
                else:
                    self.ignored.append((checked.component, "inactive collision model"))
            elif checked.category is Category.COLLISION_MODEL and contacts:
                # a model may touch itself (no box can rule it out), and this setup is not compiled
                self.unsupported(checked, f"self-collision: {self.contact_refusal}")
            elif checked.category is Category.TOPOLOGICAL_MAPPING and self._feeds_a_state(checked):
                self.unsupported(checked, "its output topology sizes a MechanicalObject; not evaluated yet")
            elif checked.category is Category.COLLISION_MODEL:
                self.ignored.append(
                    (checked.component, "no other collision model to touch: no contact possible")
                )
            elif checked.category in _STEP_CATEGORIES and not spec.lowering:
                if self._is_visual_mapping(checked):
                    self.ignored.append((checked.component, "visual mapping: computed only for rendering"))
                    continue
                self.unsupported(checked, f"sofac cannot compile {spec.name} yet")
            elif checked.category not in _STEP_CATEGORIES:
                self.ignored.append((checked.component, f"{checked.category.value}: no part in the step"))

    def _warn_contact_guard(self) -> None:
        """What a run may stop on (ContactNotCompiled), said by ``sofac check`` too: at the contact
        manager (else the pipeline, else the first guarded model), with why contacts are not compiled."""
        assert self.guard is not None
        roles = [c for c in self.checked if c.category is Category.COLLISION_PIPELINE]
        manager = next((c for c in roles if c.spec and c.spec.variant is Variant.CONTACT_MANAGER), None)
        where = (manager or (roles[0] if roles else self.guarded[0])).component
        models = len(self.guard.models)
        self.diags.add(
            "W234",
            where.loc,
            f"{models} collision models of this scene could touch and their contact response is not "
            f"compiled ({self.contact_refusal}): a run stops with ContactNotCompiled before the first "
            "step in which two of them come within reach; a run that ends without it had no contact",
            "`sofac inspect --effects` lists the guarded models",
        )

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
        if datatype.name not in COMPILED_DATATYPES:
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
        own (the distance mappings: one DOF per edge of their topology; IdentityMapping: one per input
        DOF); else 0."""
        mapping = self.checked.mapping_of(state)
        if mapping is None or mapping.spec is None:
            return 0
        if mapping.spec.lowering == "identity_mapping":  # IdentityMapping::init: the input's size
            source = mapping.links.get("input")
            given = self.checked.positions(source) if isinstance(source, Component) else None
            return len(given) if given is not None else 0
        if mapping.spec.lowering not in ("distance_mapping", "distance_multi_mapping"):
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
                group = new_group(self, solver, len(groups))
                if group is None:
                    continue
                groups[id(solver.component)] = group
            group.states.append(state)
            owner[id(state.component)] = group
        self._attach_mapped(owner)
        for group in groups.values():
            if group.scheme is Scheme.IMPLICIT:
                for state in (*group.states, *group.mapped):
                    zeros = np.zeros_like(state.v.initial)
                    state.dx = self.buffer(
                        state.component, "dx", zeros, columns=state.v.columns, role="scratch"
                    )
                    state.df = self.buffer(
                        state.component, "df", zeros, columns=state.v.columns, role="scratch"
                    )
            names = {
                Scheme.EULER: (),
                Scheme.RK2: ("x0", "v0"),
                Scheme.RK4: ("x0", "v0", "dx", "dv"),
                # The right-hand side b (CG's residual); PCG's direction p and z (CG's p is dx, q is df).
                Scheme.IMPLICIT: ("r", "p", "z") if group.pcg else ("r",),
            }[group.scheme]
            if group.inert_preconditioner is not None:
                names = ("r",)  # b only: no CG iteration
            if group.minres:
                names = ("r", "r1", "r2", "y", "w", "w2", "v")
            if group.newmark:
                names += ("a",)  # the previous step's acceleration
            if group.variational:  # x_k, the previous Newton iterate, the momenta p_k and p_k+1
                names += ("x0", "xi", "momentum", "new_momentum")
            if group.bdf:  # x and v of the step's start, the residuals r1 and r2
                names += ("x_previous", "v_previous", "residual_x", "residual_v")
            for state in group.states:
                for name in names:
                    like = state.x if name in ("x0", "xi", "x_previous") else state.v
                    columns = like.columns
                    state.stages[name] = self.buffer(
                        state.component, name, np.zeros_like(like.initial), columns=columns, role="scratch"
                    )
        for checked in self.checked:
            lowering = LOWERINGS.get(checked.spec.lowering) if checked.spec else None
            if lowering is None or checked.category in (Category.STATE, Category.ODE_SOLVER):
                continue
            lowering(self, checked, owner)
            self.lowered.append(checked.component)
        if self.colliding:  # before J is routed: contacts add blocks on mapped collision states
            self.collisions = plan_collisions(self, owner)
        self.constraints = finish_constraint_phase(self, list(groups.values()))  # Lagrangian contacts' rows
        for group in groups.values():
            if group.variational:
                screen_variational(self, group, owner)
            if group.bdf:
                screen_bdf(self, group)
            if group.btd:
                screen_btd(self, group)
            if group.routed:
                route_through_mappings(self, group)
        self.guard = contact_guard(self)
        if self.guard is not None:
            self._warn_contact_guard()
        if self.prune:
            leave_unread_out(self, list(groups.values()))
        if self.interactive:
            add_point_forces(self, list(groups.values()))
        if any(c.response is Response.PENALTY for c in self.collisions):  # after the point forces
            map_contact_states_while_touching(self, list(groups.values()))
        drop_unread_rest_positions(self, list(groups.values()))
        return list(groups.values())

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


def plan_scene(
    checked: CheckedScene,
    diagnostics: Diagnostics | None = None,
    *,
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
    interactive: bool = False,
) -> Plan:
    """The static schedule of a checked scene; raises SceneError (E222...) when it cannot be compiled.
    With ``prune``, effects the scene makes vanish (zero gravity) get no code. ``rigid_model="exact"``
    turns rigid inertias with their bodies and keeps the gyroscopic term (explicit solvers; SOFA's
    model, the default, applies the inertia in world axes). ``threads`` > 1 splits large element
    loops over that many OpenMP threads, with the serial results bit for bit. ``interactive`` adds
    a force on one DOF of each state, set from Python between steps (``sofac view``'s mouse
    spring); scenes compiled without it pay nothing for it."""
    if rigid_model not in ("sofa", "exact"):
        raise ValueError(f"rigid_model must be 'sofa' or 'exact', not {rigid_model!r}")
    if not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, not {threads!r}")
    return Planner(
        checked,
        diagnostics if diagnostics is not None else Diagnostics(),
        prune,
        rigid_model,
        threads,
        interactive,
    ).run()
