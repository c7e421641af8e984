"""Check stage: Scene -> CheckedScene, with diagnostics.

Reads every component through its registry spec: resolves names (aliases, renamed and former
names), parses each attribute into a typed field, resolves links and ``src=``, infers templates from
the mechanical states as SOFA's factory does, and checks the scene's structure (states, mappings,
solvers, indices, files). It never compiles anything and never raises for a scene problem: every
problem becomes a diagnostic with a file, a line and a hint.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sofac import registry
from sofac.check import evaluate
from sofac.diagnostics import Diagnostics, SceneError, SourceLoc
from sofac.front import datafiles, links, meshes
from sofac.front.model import Component, Node, Scene
from sofac.geometry.fem_topology import CELL_KINDS
from sofac.registry import Category, ComponentSpec, DataType, FieldSpec, NameStatus, Variant
from sofac.registry.components.common import MATRIX_TEMPLATE_ALIASES
from sofac.registry.components.mass import UNIFORM_MASS
from sofac.registry.components.ode import VARIATIONAL_SYMPLECTIC_SOLVER
from sofac.registry.components.utility import REQUIRED_PLUGIN
from sofac.registry.datatypes import DATATYPES, canonical_datatype, split_template
from sofac.registry.fields import (
    Coords,
    FieldValueError,
    JointSprings,
    Link,
    LinkList,
    MassValue,
    SofaData,
    Springs,
)

# Attributes SOFA handles itself rather than as Data of the component.
_RESERVED = frozenset({"template", "src", "type"})
# Link attributes that name the mechanical state(s) a component acts on.
_STATE_LINK_ROLES = ("mstate", "object1", "object2", "input", "output")


@dataclass
class CheckedComponent:
    component: Component
    spec: ComponentSpec | None  # None: unknown component
    template: str | None = None  # canonical template ("Vec3d", "Rigid3d,Vec3d", matrix type...)
    fields: dict[str, Any] = field(default_factory=dict)  # typed values of explicit attributes
    links: dict[str, Component | Node] = field(default_factory=dict)  # resolved object links
    link_lists: dict[str, list[Component]] = field(default_factory=dict)  # resolved multi-links
    # Attributes whose value is a link to another component's Data: field -> (path, location).
    data_links: dict[str, tuple[links.LinkPath, SourceLoc]] = field(default_factory=dict)
    src: Component | None = None
    # The state this component acts on (masses, force fields, constraints, collision models...).
    state: Component | None = None
    outputs: dict[str, np.ndarray] | None = None  # evaluated outputs (loaders, grids, BoxROI)
    size: int | None = None  # number of DOFs, for states whose size is known statically
    cache: dict[str, Any] = field(default_factory=dict)  # derived values (a state's positions)

    @property
    def category(self) -> Category | None:
        return self.spec.category if self.spec else None

    @property
    def datatype(self) -> DataType | None:
        if self.template is None:
            return None
        return DATATYPES.get(split_template(self.template)[0])


@dataclass
class CheckedScene:
    scene: Scene
    components: dict[int, CheckedComponent] = field(default_factory=dict)  # by id(component)
    check_seconds: float = 0.0
    # The checker, kept for the later stages' look-ups below (values are computed on demand:
    # a mesh or a grid is evaluated only if a later stage asks for it).
    resolver: _Checker | None = field(default=None, repr=False, compare=False)

    def _checker(self) -> _Checker:
        assert self.resolver is not None, "a CheckedScene made by check_scene"
        return self.resolver

    def value(self, component: Component, name: str) -> Any:
        """The value a component's field has: written, linked, from src, computed, or default."""
        return self._checker().value(self.of(component), name)

    def positions(self, state: Component) -> np.ndarray | None:
        """A MechanicalObject's initial positions (n, coord_size), as SOFA's init computes them."""
        return self._checker().positions(state)

    def node_state(self, node: Node) -> Component | None:
        """The mechanical state of a node, or of its nearest ancestor that has one (SOFA's context)."""
        return self._checker()._node_state(node)

    def context_singleton(self, node: Node, role: str) -> Component | None:
        """SOFA's fallback when a link names a node: its (or its ancestors') "state" / "topology"."""
        return self._checker()._singleton(node, role)

    def linear_solver_below(self, node: Node) -> Component | None:
        """The first linear solver in a node's subtree (the one its ODE solver uses)."""
        return self._checker()._linear_solver_below(node)

    def of(self, component: Component) -> CheckedComponent:
        return self.components[id(component)]

    def __iter__(self) -> Iterator[CheckedComponent]:
        return iter(self.components.values())

    def states(self) -> list[CheckedComponent]:
        return [c for c in self if c.category is Category.STATE]

    def mapping_of(self, state: Component) -> CheckedComponent | None:
        """The mechanical mapping whose output is ``state`` (None for an independent state)."""
        for checked in self:
            if (
                checked.category in (Category.MAPPING, Category.MULTI_MAPPING)
                and checked.links.get("output") is state
            ):
                return checked
        return None

    def solver_of(self, node: Node) -> CheckedComponent | None:
        """The ODE solver that integrates ``node`` (the topmost one on its path, as SOFA's visitor)."""
        for candidate in (*reversed(list(node.ancestors())), node):
            for component in candidate.objects:
                checked = self.components.get(id(component))
                if checked and checked.category is Category.ODE_SOLVER:
                    return checked
        return None


def _fmt_types(types: Sequence[str]) -> str:
    return ", ".join(types) if types else "(none)"


class _Checker:
    def __init__(self, scene: Scene, diagnostics: Diagnostics) -> None:
        self.scene = scene
        self.diags = diagnostics
        self.checked = CheckedScene(scene)
        self.checked.resolver = self
        self._readers: dict[int, list[CheckedComponent]] | None = None  # who links to each component
        self._links_resolved = False  # set once every component's links are resolved

    # ------------------------------------------------------------------------------------------
    def run(self) -> CheckedScene:
        components = list(self.scene.root.components())
        for component in components:
            self.checked.components[id(component)] = self._resolve_spec(component)
        for node in self.scene.root.walk():
            self._check_node(node)
        for checked in self.checked:
            if checked.spec is not None:
                self._parse_fields(checked)
        for checked in self.checked:
            if checked.spec is not None:
                self._resolve_links(checked)
                self._drop_broken_data_links(checked)
        self._links_resolved = True
        for node in self.scene.root.walk():
            self._check_states_of(node)
        for checked in self.checked:
            if checked.spec is not None:
                self._resolve_template(checked)
        for checked in self.checked:
            if checked.spec is not None:
                self._check_counts(checked)
                self._check_required(checked)
        self._check_mappings()
        self._check_solvers()
        self._check_constraint_corrections()
        self._check_uncoupled_compliance()
        self._add_data_repositories()
        for checked in self.checked:
            if checked.spec is not None:
                self._check_files(checked)
        for checked in self.checked:
            if checked.spec is not None:
                self._check_indices(checked)
        self._check_plugins()
        for checked in self.checked:
            if checked.spec is not None and checked.spec.lowering == "uniform_mass":
                self._check_rigid_inertia(checked)
        for checked in self.checked:
            if checked.spec is not None and checked.spec.validate is not None:
                self._check_rule(checked)
        for checked in self.checked.states():
            checked.size = self.state_size(checked.component)
        return self.checked

    def _check_constraint_corrections(self) -> None:
        """A Lagrangian constraint moves a simulated state only through a constraint correction on
        it (or on the independent state it is mapped from): without one, SOFA never applies it."""
        corrected = {
            id(state)
            for c in self.checked
            if c.category is Category.CONSTRAINT_CORRECTION
            for state in [c.links.get("mstate") or self._node_state(c.component.node)]
            if isinstance(state, Component)
        }
        for checked in self.checked:
            if checked.category is not Category.LAGRANGIAN_CONSTRAINT:
                continue
            states = [checked.links.get(name) for name in ("object1", "object2", "mstate")]
            if not any(isinstance(s, Component) for s in states):
                states = [self._node_state(checked.component.node)]
            for state in states:
                independent = state
                seen: set[int] = set()
                while isinstance(independent, Component) and id(independent) not in seen:
                    seen.add(id(independent))
                    mapping = self.checked.mapping_of(independent)
                    if mapping is None:
                        break
                    independent = mapping.links.get("input")
                if not isinstance(independent, Component) or id(independent) in corrected:
                    continue
                if self.checked.solver_of(independent.node) is None:
                    continue  # a static state: the constraint only reads it
                self.diags.add(
                    "E246",
                    checked.component.loc,
                    f"{checked.component.type_name} acts on {independent.path!r}, which has no constraint "
                    "correction: SOFA would never apply the constraint to it",
                    "add an UncoupledConstraintCorrection (or a LinearSolverConstraintCorrection) in the "
                    f"node of {independent.path!r}",
                )

    def _check_uncoupled_compliance(self) -> None:
        """UncoupledConstraintCorrection without `compliance` or `defaultCompliance`: SOFA's init
        warns and uses defaultCompliance's default for a point state; a rigid one takes its
        compliance from its node's UniformMass, and without one it has none (an error here)."""
        for checked in self.checked:
            spec, component = checked.spec, checked.component
            if spec is None or spec.variant is not Variant.UNCOUPLED:
                continue
            if component.get("compliance") is not None or component.get("defaultCompliance") is not None:
                continue
            linked = checked.links.get("mstate")
            state = linked if isinstance(linked, Component) else self._node_state(component.node)
            datatype = self.checked.of(state).datatype if state is not None else checked.datatype
            if datatype is not None and datatype.rigid:
                if any(self.checked.of(other).spec is UNIFORM_MASS for other in component.node.objects):
                    continue
                self.diags.add(
                    "E226",
                    component.loc,
                    f"{component.type_name} on a rigid state needs its compliance: neither 'compliance' "
                    "(7 values) nor 'defaultCompliance' is set, and its node has no UniformMass to compute "
                    "it from",
                    "add a UniformMass next to it, or set defaultCompliance",
                )
                continue
            default = spec.field("defaultCompliance")
            self.diags.add(
                "W247",
                component.loc,
                f"{component.type_name}: neither 'defaultCompliance' nor 'compliance' is set; SOFA (and "
                f"sofac) give every DOF defaultCompliance's default, {default.default if default else ''}",
                "set defaultCompliance (about dt^2 / mass for a point of that mass) or compliance",
            )

    # --- names -------------------------------------------------------------------------------
    def _resolve_spec(self, component: Component) -> CheckedComponent:
        name = component.type_name
        resolution = registry.lookup(name)
        if resolution is None or resolution.spec.name == "Node":
            suggestions = registry.suggest(name)
            hint = (
                f"did you mean {' or '.join(suggestions)}?"
                if suggestions
                else ("check the spelling; `sofac inspect --components` lists the known components")
            )
            self.diags.add("E200", component.loc, f"unknown component {name!r}", hint)
            return CheckedComponent(component, None)
        spec = resolution.spec
        if resolution.status is NameStatus.FORMER:
            self.diags.add(
                "E201",
                component.loc,
                f"{name!r} is no longer accepted by SOFA: the component is now {spec.name!r}",
                f"rename <{name}> to <{spec.name}>",
            )
        elif resolution.status is NameStatus.RENAMED:
            self.diags.add(
                "W202",
                component.loc,
                f"{name!r} is a legacy name of {spec.name!r}",
                f"rename <{name}> to <{spec.name}>",
            )
        if spec.deprecated:
            self.diags.add("W202", component.loc, f"{spec.name} is deprecated in SOFA", spec.deprecated)
        if not spec.supported:
            reason = spec.unsupported_reason or f"{spec.name} is not implemented in sofac yet"
            self.diags.add(
                "E222",
                component.loc,
                f"unsupported component {spec.name} at line {component.loc.line}: {reason}",
                "remove it, or pass --allow-unsupported to only validate the scene",
            )
        return CheckedComponent(component, spec)

    # --- nodes -------------------------------------------------------------------------------
    def _check_node(self, node: Node) -> None:
        spec = registry.node_spec()
        values = self._parse_attributes(node, spec, None, {})
        if node.parent is None:
            return
        root_values = {
            name: self._node_value(node.root, name) for name in ("dt", "gravity") if name in values
        }
        for name, root_value in root_values.items():
            if not np.allclose(values[name], root_value):
                self.diags.add(
                    "W225",
                    node.attribute_loc(name),
                    f"node {node.path!r} sets {name}, but SOFA uses only the root's {name} "
                    f"({spec.field(name).type.format(np.asarray(root_value))})",  # type: ignore[union-attr]
                    "use a <Gravity> component to change gravity for a subtree"
                    if name == "gravity"
                    else "set dt on the root node",
                )

    def _node_value(self, node: Node, name: str) -> Any:
        spec = registry.node_spec().field(name)
        assert spec is not None
        text = node.get(name)
        if text is not None:
            try:
                return spec.type.parse(text)
            except FieldValueError:
                pass
        return spec.default

    # --- fields ------------------------------------------------------------------------------
    def _parse_attributes(
        self,
        element: Component | Node,
        spec: ComponentSpec,
        checked: CheckedComponent | None,
        out: dict[str, Any],
    ) -> dict[str, Any]:
        owner = (
            f"{spec.name} {element.label!r}" if isinstance(element, Component) else f"node {element.path!r}"
        )
        for attribute in element.attributes.values():
            name = attribute.name
            if name.startswith(("_", "NO")) or (isinstance(element, Component) and name in _RESERVED):
                continue
            if isinstance(element, Node) and name == "name":
                continue
            field_spec = spec.field(name)
            if field_spec is None:
                self._unknown_attribute(spec, owner, attribute.name, attribute.loc)
                continue
            if field_spec.deprecated:
                self.diags.add(
                    "W225",
                    attribute.loc,
                    f"{owner}: attribute {name!r} is a legacy spelling SOFA warns about",
                )
            if links.is_link(attribute.value) and not isinstance(field_spec.type, Link):
                if checked is not None:
                    path = links.parse_link(attribute.value)
                    assert path is not None
                    checked.data_links[field_spec.name] = (path, attribute.loc)
                elif isinstance(element, Node):
                    self.diags.add(
                        "E222",
                        attribute.loc,
                        f"{owner}: {name}={attribute.value.strip()[:40]!r}: sofac does not follow links "
                        "on a node's Data yet",
                        "write the value itself",
                    )
                continue
            try:
                value = field_spec.type.parse(attribute.value)
            except FieldValueError as error:
                if attribute.value == "" and error.code.startswith("E"):
                    # Data<T>::read("") only resizes to 0: a fixed-size value (a number, a Vec3, a
                    # flag) cannot be, so SOFA keeps its default without a word (Base::parseField).
                    self.diags.add(
                        "W225",
                        attribute.loc,
                        f"{owner}: {name} is empty: SOFA keeps its default",
                        "remove the attribute or write a value",
                    )
                    continue
                self.diags.add(error.code, attribute.loc, f"{owner}: {name}: {error}", error.hint)
                if error.code.startswith("W") and error.value is not None:
                    out[field_spec.name] = error.value  # what SOFA reads from the text anyway
                # (otherwise the field keeps its default, as SOFA does after a warning)
                continue
            if isinstance(field_spec.type, MassValue) and np.size(value) and not float(value[0]) > 0:
                # Only the mass itself: a rigid mass's volume and inertia terms may be 0 (or negative
                # off the diagonal).
                self.diags.add(
                    "E207",
                    attribute.loc,
                    f"{owner}: {name}={attribute.value.strip()[:40]!r}: the mass (its first number) "
                    "must be > 0",
                    "use a physically meaningful value",
                )
                continue
            if field_spec.valid is not None and not self._valid(value, field_spec):
                self.diags.add(
                    "E207",
                    attribute.loc,
                    f"{owner}: {name}={attribute.value.strip()[:40]!r} {field_spec.valid[1]}",
                    "use a physically meaningful value",
                )
                continue
            out[field_spec.name] = value
        return out

    @staticmethod
    def _valid(value: Any, field_spec: FieldSpec) -> bool:
        assert field_spec.valid is not None
        predicate = field_spec.valid[0]
        numbers = np.atleast_1d(np.asarray(value, dtype=float)) if not isinstance(value, str) else None
        if numbers is None:
            return True
        return all(predicate(float(x)) for x in numbers)

    def _unknown_attribute(self, spec: ComponentSpec, owner: str, name: str, loc: SourceLoc) -> None:
        import difflib

        close = difflib.get_close_matches(name, spec.field_names, n=1, cutoff=0.7)
        hint = f"did you mean {close[0]!r}?" if close else "SOFA ignores attributes it does not know"
        self.diags.add("W203", loc, f"{owner} has no attribute {name!r}", hint)

    def _parse_fields(self, checked: CheckedComponent) -> None:
        assert checked.spec is not None
        self._parse_attributes(checked.component, checked.spec, checked, checked.fields)
        src_text = checked.component.get("src")
        if src_text is not None and src_text.strip() == "@":
            self.diags.add(
                "W225",
                checked.component.attribute_loc("src"),
                f'{checked.spec.name} {checked.component.label!r}: src="@" names no object: '
                "SOFA warns that it does nothing",
                'remove src="@", or name the loader: src="@loader"',
            )
        elif src_text is not None:
            loc = checked.component.attribute_loc("src")
            source = links.resolve_src(src_text, checked.component)
            if not src_text.startswith("@"):  # BaseComponent::parse's error
                self.diags.add(
                    "E213",
                    loc,
                    f"{checked.spec.name} {checked.component.label!r}: src={src_text!r} is not a link: "
                    "SOFA reports that it should start with '@'",
                    'write src="@name" with the name of a loader of this node, or remove src',
                )
            elif source is None:
                self.diags.add(
                    "E213",
                    loc,
                    f"{checked.spec.name} {checked.component.label!r}: src={src_text!r} names no object "
                    f"of node {checked.component.node.path!r}",
                    'src looks only in the current node: write src="@../name" for a parent\'s object',
                )
            else:
                checked.src = source

    # --- links -------------------------------------------------------------------------------
    def _resolve_links(self, checked: CheckedComponent) -> None:
        assert checked.spec is not None
        component = checked.component
        for field_spec in checked.spec.fields:
            if not isinstance(field_spec.type, Link):
                continue
            attribute = next(
                (
                    component.attributes[a]
                    for a in (field_spec.name, *field_spec.aliases)
                    if a in component.attributes
                ),
                None,
            )
            text = attribute.value if attribute else field_spec.default
            if text is None:
                continue
            loc = attribute.loc if attribute else component.loc
            if isinstance(field_spec.type, LinkList):
                targets = []
                for item in str(text).split():
                    path = links.parse_link(item if item.startswith("@") else "@" + item)
                    found = links.resolve(path, component) if path is not None else None
                    role = field_spec.type.target
                    if isinstance(found, Node) and role == "object":
                        continue  # a link of unknown kind may name a node (targetNode...)
                    if isinstance(found, Node):
                        found = self._singleton(found, role) if role in ("state", "topology") else None
                    if found is None:
                        self.diags.add(
                            "E213",
                            loc,
                            f"{checked.spec.name} {component.label!r}: {field_spec.name}: {item!r} "
                            "points to nothing",
                            "paths are relative to the component's node: '@../name' is in the parent node",
                        )
                    else:
                        targets.append(found)
                checked.link_lists[field_spec.name] = targets
                continue
            text = str(text).strip()
            if not text.startswith("@"):
                text = "@" + text  # old scenes write object1="name"
            path = links.parse_link(text)
            assert path is not None
            target = links.resolve(path, component)
            wanted = field_spec.type.target
            problem = "points to nothing" if target is None else ""
            if isinstance(target, Node) and wanted in ("state", "topology"):
                target = self._singleton(target, wanted)
                if target is None:
                    problem = (
                        f"names a node with no {'mechanical state' if wanted == 'state' else 'topology'}"
                    )
            if target is None:
                if attribute is not None:
                    self._broken_link(
                        checked, field_spec, f"{field_spec.name}={attribute.value!r}", problem, loc
                    )
                continue
            checked.links[field_spec.name] = target

    def _broken_link(
        self, checked: CheckedComponent, field_spec: FieldSpec, written: str, problem: str, loc: SourceLoc
    ) -> None:
        """E213, or W233 for a link SOFA's component goes on without (``Link.optional``)."""
        assert checked.spec is not None and isinstance(field_spec.type, Link)
        message = f"{checked.spec.name} {checked.component.label!r}: {written} {problem}"
        hint = "paths are relative to the component's node: '@../name' is in the parent node"
        if field_spec.type.optional:
            message += f": SOFA warns and goes on as if {field_spec.name} were not written"
            self.diags.add("W233", loc, message, hint)
        else:
            self.diags.add("E213", loc, message, hint if problem == "points to nothing" else "")

    def _singleton(self, node: Node, role: str) -> Component | None:
        """SOFA's fallback when a link names a node: its (or its ancestors') state / topology."""

        def accept(component: Component) -> bool:
            checked = self.checked.components.get(id(component))
            if checked is None or checked.spec is None:
                return False
            if role == "state":
                return checked.category in (Category.STATE, Category.VISUAL)
            return checked.category is Category.TOPOLOGY

        if role == "state":
            # A mechanical state takes precedence over a visual model in the same node.
            for candidate in (node, *node.ancestors()):
                states = [c for c in candidate.objects if self._is(c, Category.STATE)]
                if states:
                    return states[0]
                visuals = [c for c in candidate.objects if self._is(c, Category.VISUAL)]
                if visuals:
                    return visuals[0]
            return None
        found, _ = links.pick_in_node(node, accept, climb=True)
        return found

    def _is(self, component: Component, category: Category) -> bool:
        checked = self.checked.components.get(id(component))
        return checked is not None and checked.category is category

    def _drop_broken_data_links(self, checked: CheckedComponent) -> None:
        """A Data link to no object, or to an object without that Data: SOFA keeps the path and,
        when nothing ever answers it, the Data its default (BaseData::setParent), so sofac warns
        and reads the field as if the attribute were not written."""
        assert checked.spec is not None
        owner = f"{checked.spec.name} {checked.component.label!r}"
        for name, (path, loc) in list(checked.data_links.items()):
            target = links.resolve(path, checked.component)
            link = f"@{path.path}{'.' + path.data if path.data else ''}"
            if target is None or isinstance(target, Node):
                problem = f"{name}={link} points to nothing"
            else:
                source = self.checked.components.get(id(target))
                data = path.data or name
                known = source is not None and source.spec is not None and not source.spec.from_sofa_source
                if not known or source.spec.field(data) is not None:  # type: ignore[union-attr]
                    continue
                problem = f"{name} links to {source.spec.name} {target.label!r}, which has no Data {data!r}"  # type: ignore[union-attr]
            self.diags.add(
                "W233",
                loc,
                f"{owner}: {problem}: SOFA goes on as if {name} were not written",
                "a Data link is '@path/to/object.dataName', relative to the component's node",
            )
            del checked.data_links[name]

    # --- states and templates ----------------------------------------------------------------
    def _check_states_of(self, node: Node) -> None:
        states = [c for c in node.objects if self._is(c, Category.STATE)]
        if len(states) > 1:
            first = states[0]
            for extra in states[1:]:
                self.diags.add(
                    "E211",
                    extra.loc,
                    f"node {node.path!r} has two MechanicalObjects: {first.label!r} (line {first.loc.line}) "
                    f"and {extra.label!r}",
                    "put each state in its own child node",
                )
        for component in node.objects:
            checked = self.checked.components.get(id(component))
            if checked is None or checked.spec is None:
                continue
            if checked.category in (
                Category.MAPPING,
                Category.MULTI_MAPPING,
                Category.INTERACTION_FORCEFIELD,
            ):
                continue
            if not (checked.category.acts_on_state or checked.category is Category.COLLISION_MODEL):  # type: ignore[union-attr]
                continue
            first, second = checked.links.get("object1"), checked.links.get("object2")
            if first is not None or second is not None:
                # Acts between the two states it links (e.g. BilateralLagrangianConstraint); when both
                # are one state (MeshSpringForceField's default "@./" twice), it acts on that state.
                if first is second and isinstance(first, Component) and self._is(first, Category.STATE):
                    checked.state = first
                continue
            explicit = checked.links.get("mstate")
            state = explicit if isinstance(explicit, Component) else None
            if state is None:
                state, _ = links.pick_in_node(node, lambda c: self._is(c, Category.STATE), climb=True)
            if state is None:
                self.diags.add(
                    "E212",
                    component.loc,
                    f"{checked.spec.name} {component.label!r} has no MechanicalObject to act on "
                    f"(none in node {node.path!r} or its ancestors)",
                    "add a <MechanicalObject/> to the node",
                )
                continue
            checked.state = state

    def _unsupported_template(self, checked: CheckedComponent, template: str, loc: SourceLoc) -> None:
        spec = checked.spec
        assert spec is not None
        self.diags.add(
            "E222",
            loc,
            f"unsupported component {spec.name} at line {checked.component.loc.line}: {spec.name} "
            f"{template} is supported by SOFA, not compiled by sofac yet (sofac compiles "
            f"{_fmt_types(spec.templates)})",
            "remove it, or pass --allow-unsupported to only validate the scene",
        )

    def _parse_template(self, checked: CheckedComponent) -> list[str] | None:
        """The written template's parts, canonicalised; reports unknown spellings."""
        text = checked.component.get("template")
        if text is None:
            return None
        parts = []
        for part in split_template(text):
            if part in MATRIX_TEMPLATE_ALIASES:
                parts.append(MATRIX_TEMPLATE_ALIASES[part])
                continue
            canonical = canonical_datatype(part)
            if canonical is None:
                parts.append(part)
                continue
            name, warns = canonical
            if warns:
                self.diags.add(
                    "W209",
                    checked.component.attribute_loc("template"),
                    f"template {part!r} is read as {name!r}",
                    f'write template="{name}"',
                )
            parts.append(name)
        return parts

    def _resolve_template(self, checked: CheckedComponent) -> None:
        spec = checked.spec
        assert spec is not None
        written = self._parse_template(checked)
        loc = checked.component.attribute_loc("template")
        owner = f"{spec.name} {checked.component.label!r}"
        if spec.category in (Category.MAPPING, Category.MULTI_MAPPING):
            checked.template = ",".join(written) if written else None
            return  # checked with the mapping's input and output
        inferred: str | None = None
        if checked.state is not None:
            inferred = self.checked.of(checked.state).template
        elif spec.category is Category.INTERACTION_FORCEFIELD:
            ends = [checked.links.get(r) for r in ("object1", "object2")]
            if not any(ends):
                ends = [self._node_state(checked.component.node)]
            types = {self.checked.of(e).template for e in ends if isinstance(e, Component)}
            inferred = next(iter(types)) if len(types) == 1 else None
        if written:
            template = ",".join(written)
            unknown = template not in spec.templates and written[0] not in spec.templates
            if spec.templates and unknown and not spec.from_sofa_source:  # SOFA-only classes: E222
                # (SOFA's factory tries every creator when the written template has none: a pair
                # "A,A" for a class registered for A is A's, as SofaCUDA's scenes write DiagonalMass)
                if registry.sofa_has_template(spec, template) or (
                    len(set(written)) == 1 and registry.sofa_has_template(spec, written[0])
                ):
                    self._unsupported_template(checked, template, loc)
                else:
                    self.diags.add(
                        "E208",
                        loc,
                        f"{owner}: template {template!r} is not available; {spec.name} accepts "
                        f"{_fmt_types(spec.templates)}",
                    )
                checked.template = inferred
                return
            if inferred is not None and checked.state is not None and written[0] != inferred:
                self.diags.add(
                    "E210",
                    loc,
                    f"{owner} has template {written[0]!r} but acts on {checked.state.label!r}, "
                    f"a {inferred} MechanicalObject",
                    f'remove template= (it is inferred) or write template="{inferred}"',
                )
            checked.template = template
            return
        if inferred is not None and spec.templates and inferred not in spec.templates:
            self.diags.add(
                "E210",
                checked.component.loc,
                f"{owner} cannot act on {inferred} state {checked.state.label if checked.state else ''!r}: "
                f"it accepts {_fmt_types(spec.templates)}",
            )
        checked.template = inferred or spec.default_template

    def _node_state(self, node: Node) -> Component | None:
        state, _ = links.pick_in_node(node, lambda c: self._is(c, Category.STATE), climb=True)
        return state

    # --- values ------------------------------------------------------------------------------
    def value(self, checked: CheckedComponent, name: str, depth: int = 0, *, raw: bool = False) -> Any:
        """The value a field of a component will have: explicit, linked, from src, computed, default."""
        assert checked.spec is not None
        if depth > 32:
            return None
        field_spec = checked.spec.field(name)
        if field_spec is not None and isinstance(field_spec.type, SofaData):
            return None  # a Data known only from SOFA's source: sofac cannot say what it holds
        if checked.category is Category.TOPOLOGY and name in CELL_KINDS:
            # A topological mapping's init clears its output container and writes its elements
            # (those it does not write, the container computes when it initialises): what the
            # scene gives the container, by src= or attribute, does not last.
            writer = self._topology_writer(checked)
            if writer is not None:
                return self.value(writer, name, depth + 1)
        if name in checked.fields and (raw or name not in checked.spec.rewrites):
            return checked.fields[name]
        if checked.category is Category.STATE and name in ("rest_position", "reset_position"):
            name = "position"  # both start as a copy of the transformed positions
        if checked.category is Category.STATE and name == "position" and not raw:
            points = self.positions(checked.component)
            return None if points is None else points.ravel()
        if name in checked.data_links:
            path, _ = checked.data_links[name]
            target = links.resolve(path, checked.component)
            source = self.checked.components.get(id(target)) if isinstance(target, Component) else None
            if source is None or source.spec is None:
                return None
            return self.value(source, path.data or name, depth + 1)
        if checked.spec.compute:
            outputs = self._outputs(checked)
            if outputs is not None and name in outputs:
                return outputs[name]
        if checked.src is not None:
            source = self.checked.components.get(id(checked.src))
            # SOFA's src= fills the Data the component has from the source's of the same name
            if (
                source is not None
                and source.spec is not None
                and source.spec.field(name) is not None
                and checked.spec.field(name) is not None
            ):
                return self.value(source, name, depth + 1)
        if checked.category is Category.TOPOLOGY and name == "position":
            # Mesh2PointTopologicalMapping writes its output container's points.
            writer = self._topology_writer(checked)
            if writer is not None:
                written = self.value(writer, name, depth + 1)
                if written is not None and np.size(written):
                    return written
        field_spec = checked.spec.field(name)
        return field_spec.default if field_spec else None

    def _topology_writer(self, container: CheckedComponent) -> CheckedComponent | None:
        """The topological mapping sofac evaluates whose output is this container, if any."""
        if "writer" not in container.cache:
            found = next(
                (
                    writer
                    for writer in self.checked
                    if writer.category is Category.TOPOLOGICAL_MAPPING
                    and writer.spec is not None
                    and writer.spec.compute
                    and writer.links.get("output") is container.component
                ),
                None,
            )
            if not self._links_resolved:  # links still being resolved: not final yet
                return found
            container.cache["writer"] = found
        return container.cache["writer"]

    def _outputs(self, checked: CheckedComponent) -> dict[str, np.ndarray] | None:
        if checked.outputs is not None:
            return checked.outputs
        assert checked.spec is not None
        evaluator = evaluate.EVALUATORS[checked.spec.compute]
        checked.outputs = {}  # guards against cycles while evaluating
        try:
            checked.outputs = evaluator(_EvalContext(self, checked))
        except evaluate.UnknownInput:
            pass  # computed by a generator sofac cannot evaluate (yet): nothing to check against
        except evaluate.EvaluationError as error:
            if not isinstance(error, evaluate.MissingFile):  # missing files: reported by _check_files
                self.diags.add(
                    error.code,
                    checked.component.attribute_loc(self._attribute_name(checked, error.attribute))
                    if error.attribute
                    else checked.component.loc,
                    f"{checked.spec.name} {checked.component.label!r}: {error}",
                )
        return checked.outputs

    def positions(self, state: Component) -> np.ndarray | None:
        """Initial positions of a state, reshaped (n, coord_size), when they can be known statically.

        As SOFA's MechanicalObject::init: the written (or linked) positions, else its topology's,
        then scaled, rotated and translated (legacy ``dx``/``rx``/``scale`` attributes included).
        """
        checked = self.checked.of(state)
        if "position" in checked.cache:
            return checked.cache["position"]
        checked.cache["position"] = None  # guards against link cycles
        points = self._untransformed_positions(checked)
        if points is not None and points.shape[1] in (1, 2, 3, 7):
            points = self._transform_state(checked, points)
        checked.cache["position"] = points
        return points

    def _transform_state(self, checked: CheckedComponent, points: np.ndarray) -> np.ndarray:
        fields = checked.fields

        def triple(name: str, legacy: tuple[str, str, str], default: float) -> np.ndarray:
            value = np.asarray(fields.get(name, (default,) * 3), dtype=float)
            for axis, key in enumerate(legacy):
                if key in fields:
                    value[axis] = float(fields[key])
            return value

        scale = triple("scale3d", ("sx", "sy", "sz"), 1.0) * float(fields.get("scale", 1.0))
        rotation = triple("rotation", ("rx", "ry", "rz"), 0.0)
        translation = triple("translation", ("dx", "dy", "dz"), 0.0)
        if (scale == 1).all() and not rotation.any() and not translation.any():
            return points
        if points.shape[1] == 7:  # Rigid3d: move the frames' origins, turn their orientations
            moved = points.copy()
            moved[:, :3] = meshes.apply_transform(points[:, :3], translation, rotation, scale)
            if rotation.any():
                turn = meshes.euler_to_quaternion(rotation)
                moved[:, 3:] = [meshes.quaternion_multiply(turn, q) for q in points[:, 3:]]
            return moved
        return meshes.apply_transform(points, translation, rotation, scale)

    def _untransformed_positions(self, checked: CheckedComponent) -> np.ndarray | None:
        state = checked.component
        datatype = checked.datatype or DATATYPES["Vec3d"]
        value = self.value(checked, "position", raw=True)
        velocity = self.value(checked, "velocity", raw=True)
        # MechanicalObject::init: rest positions longer than the positions (one default coordinate
        # when none is given) are copied into them ("X0 set but not X").
        rest = self._written_rest_positions(checked)
        if rest is not None and len(rest) > max(np.size(value) // datatype.coord_size, 1):
            return rest
        # MechanicalObject::init also takes its topology's points when it holds one position and at
        # most one velocity (position="0 0 0" next to a grid gets the grid's points), unless a
        # size > 1 resized it at parse time.
        single = (
            np.size(value) == datatype.coord_size
            and np.size(velocity) <= datatype.deriv_size
            and int(checked.fields.get("size", 0)) <= 1
        )
        if value is None or np.size(value) == 0 or single:
            topology, _ = links.pick_in_node(
                state.node, lambda c: self._is(c, Category.TOPOLOGY), climb=False
            )
            points = self.value(self.checked.of(topology), "position") if topology is not None else None
            if points is not None and np.size(points) and np.size(points) % 3 == 0:
                # DataTypes::set(x, px, py, pz): the first min(3, dimension) numbers of each point
                # (a Vec2 state keeps x and y; a rigid frame its centre, with identity orientation).
                points = np.asarray(points, dtype=float).reshape(-1, 3)
                rest = np.zeros((len(points), datatype.coord_size))
                if datatype.coord_size == 7:
                    rest[:, 6] = 1.0
                copied = min(3, datatype.spatial_dim)
                rest[:, :copied] = points[:, :copied]
                return rest
        if value is None or np.size(value) == 0:
            count = int(checked.fields.get("size", 0))
            if not count and self._default_single(checked):
                count = 1  # MechanicalObject's constructor resizes to one default coordinate
            if not count:
                return None
            rest = np.zeros((count, datatype.coord_size))
            if datatype.coord_size == 7:
                rest[:, 6] = 1.0  # identity orientations
            return rest
        value = np.asarray(value, dtype=float)
        width = self._linked_width(checked, "position")
        if width is not None and width != datatype.coord_size and value.size % width == 0:
            # A link between position types of different widths (a grid's Vec3d points into Rigid3d
            # frames): SOFA's genericCopyValueFrom copies element by element, the first
            # min(widths) values of each, the rest keeping the default coordinate.
            points = value.reshape(-1, width)
            copied = min(width, datatype.coord_size)
            rest = np.zeros((len(points), datatype.coord_size))
            if datatype.coord_size == 7:
                rest[:, 6] = 1.0  # identity orientations
            rest[:, :copied] = points[:, :copied]
            return rest
        if value.size % datatype.coord_size:
            return None
        return value.reshape(-1, datatype.coord_size)

    def _written_rest_positions(self, checked: CheckedComponent) -> np.ndarray | None:
        """A state's rest_position as the scene writes or links it (None when it does neither)."""
        datatype = checked.datatype or DATATYPES["Vec3d"]
        if "rest_position" in checked.fields:
            value = checked.fields["rest_position"]
        elif "rest_position" in checked.data_links:
            path, _ = checked.data_links["rest_position"]
            target = links.resolve(path, checked.component)
            source = self.checked.components.get(id(target)) if isinstance(target, Component) else None
            if source is None or source.spec is None:
                return None
            value = self.value(source, path.data or "rest_position")
        else:
            return None
        if value is None or not np.size(value) or np.size(value) % datatype.coord_size:
            return None
        return np.asarray(value, dtype=float).reshape(-1, datatype.coord_size)

    def _default_single(self, checked: CheckedComponent) -> bool:
        """A state nothing gives positions (none written, linked or from src; no topology in its
        node, no mapping writing it) keeps the one coordinate SOFA's MechanicalObject starts with."""
        component = checked.component
        written = any(name in checked.fields or name in checked.data_links for name in ("position", "size"))
        if written or checked.src is not None or self.checked.mapping_of(component) is not None:
            return False
        node = component.node
        topology, _ = links.pick_in_node(node, lambda c: self._is(c, Category.TOPOLOGY), climb=False)
        return topology is None

    def _linked_width(self, checked: CheckedComponent, name: str) -> int | None:
        """Numbers per element of the positions a field links to: a state's coordinate size, or 3
        for a topology's points (None when not linked or not known)."""
        if name in checked.fields or name not in checked.data_links:
            return None
        path, _ = checked.data_links[name]
        target = links.resolve(path, checked.component)
        source = self.checked.components.get(id(target)) if isinstance(target, Component) else None
        if source is None or (path.data or name) != "position":
            return None
        if source.category is Category.STATE:
            return (source.datatype or DATATYPES["Vec3d"]).coord_size
        return 3 if source.category is Category.TOPOLOGY else None

    def state_size(self, state: Component) -> int | None:
        points = self.positions(state)
        if points is not None:
            return len(points)
        size = self.checked.of(state).fields.get("size")
        return int(size) if size else None

    # --- counts, required values ---------------------------------------------------------------
    def _check_counts(self, checked: CheckedComponent) -> None:
        assert checked.spec is not None
        datatype = checked.datatype
        if datatype is None:
            return
        for name, value in checked.fields.items():
            field_spec = checked.spec.field(name)
            assert field_spec is not None
            problem = field_spec.type.check_count(value, datatype)
            if problem and isinstance(field_spec.type, MassValue) and value.size > max(datatype.mass_sizes):
                # `istream >> MassType` reads one mass and leaves the rest of the text unread
                # (Component/Constraint/Lagrangian/BilateralLagrangianConstraint_Rigid.scn: 12 numbers)
                kept = max(datatype.mass_sizes)
                self.diags.add(
                    "W225",
                    checked.component.attribute_loc(self._attribute_name(checked, name)),
                    f"{checked.spec.name} {checked.component.label!r}: {name}: {problem}: SOFA reads the "
                    f"first {kept} and ignores the rest",
                    f"give {kept} numbers",
                )
                checked.fields[name] = value[:kept]
                continue
            if problem and isinstance(field_spec.type, Coords) and not field_spec.type.allow_single:
                # SOFA's vector<Coord>::read stops at the incomplete last value and drops it (the end
                # of the text clears the stream's error): a warning, and the complete values only.
                unit = field_spec.type.unit(datatype)
                kept = (value.size // unit) * unit
                what = ("Deriv" if field_spec.type.deriv else "Coord") + ("s" if kept != unit else "")
                dropped = value.size - kept
                self.diags.add(
                    "W225",
                    checked.component.attribute_loc(self._attribute_name(checked, name)),
                    f"{checked.spec.name} {checked.component.label!r}: {name}: {problem}: SOFA reads "
                    f"{kept // unit} {datatype.name} {what} and ignores the last "
                    f"{dropped} number{'s' if dropped > 1 else ''}",
                    f"give {unit} numbers per DOF",
                )
                checked.fields[name] = value[:kept]
                checked.cache.pop(name, None)
                continue
            if problem and not (
                isinstance(field_spec.type, Coords)
                and field_spec.type.allow_single
                and value.size == datatype.deriv_size
            ):
                per_dof = (
                    datatype.deriv_size if getattr(field_spec.type, "deriv", False) else datatype.coord_size
                )
                self.diags.add(
                    "E205",
                    checked.component.attribute_loc(self._attribute_name(checked, name)),
                    f"{checked.spec.name} {checked.component.label!r}: {name}: {problem}",
                    f"give {datatype.name} values: {per_dof} numbers per DOF",
                )

    @staticmethod
    def _attribute_name(checked: CheckedComponent, field_name: str) -> str:
        assert checked.spec is not None
        for attribute in checked.component.attributes:
            spec = checked.spec.field(attribute)
            if spec is not None and spec.name == field_name:
                return attribute
        return field_name

    def _check_required(self, checked: CheckedComponent) -> None:
        assert checked.spec is not None
        for field_spec in checked.spec.fields:
            if not field_spec.required:
                continue
            if field_spec.name in checked.fields or field_spec.name in checked.data_links:
                continue
            if checked.src is not None or field_spec.name in checked.links:
                continue
            unresolved = (
                f": none is written and {field_spec.default!r} reaches none"
                if isinstance(field_spec.type, Link) and field_spec.default
                else ""
            )
            self.diags.add(
                "E226",
                checked.component.loc,
                f"{checked.spec.name} {checked.component.label!r} needs {field_spec.name!r}{unresolved}",
                field_spec.doc,
            )

    def _check_rule(self, checked: CheckedComponent) -> None:
        """The spec's own rule across its fields (ComponentSpec.validate)."""
        assert checked.spec is not None and checked.spec.validate is not None
        component = checked.component
        problem = checked.spec.validate(lambda name: self.checked.value(component, name))
        if problem is None:
            return
        code, attribute, message, hint = problem
        self.diags.add(
            code,
            component.attribute_loc(self._attribute_name(checked, attribute)),
            f"{checked.spec.name} {component.label!r} at line {component.loc.line}: {message}",
            hint,
        )

    # --- mappings ----------------------------------------------------------------------------
    def _check_mappings(self) -> None:
        edges: dict[int, list[tuple[Component, CheckedComponent]]] = {}
        for checked in self.checked:
            if checked.category is not Category.MAPPING:
                continue
            spec = checked.spec
            assert spec is not None
            component = checked.component
            owner = f"{spec.name} {component.label!r}"
            source = checked.links.get("input")
            target = checked.links.get("output")
            if not isinstance(source, Component):
                written = component.get("input")
                if written is None or "input" not in checked.links:
                    self.diags.add(
                        "E215",
                        component.attribute_loc("input"),
                        f"{owner}: input {written or '@../'!r} reaches no mechanical state",
                        'point input= at the parent state, e.g. input="@../dofs"',
                    )
                continue
            if not isinstance(target, Component):
                self.diags.add(
                    "E216",
                    component.attribute_loc("output"),
                    f"{owner}: output {component.get('output') or '@./'!r} is not a state or visual model",
                )
                continue
            if target.node is not component.node:
                self.diags.add(
                    "E216",
                    component.attribute_loc("output"),
                    f"{owner}: output {target.label!r} is in node {target.node.path!r}, not in the mapping's "
                    f"node {component.node.path!r}",
                    "put the mapping in the node of its output",
                )
            in_type = self.checked.of(source).template
            out_type = self.checked.of(target).template or "Vec3d"
            actual = f"{in_type},{out_type}"
            written = self._parse_template(checked)
            if written and len(written) == 2 and ",".join(written) != actual:
                self.diags.add(
                    "E210",
                    component.attribute_loc("template"),
                    f"{owner} has template {','.join(written)!r} but maps {source.label!r} ({in_type}) "
                    f"to {target.label!r} ({out_type})",
                )
            # One-parameter mappings (DistanceToPlaneMapping<Vec3d>) name their input only.
            fits = not spec.templates or actual in spec.templates or in_type in spec.templates
            if in_type is None or spec.from_sofa_source:
                pass  # the input's template is reported at the input; SOFA-only classes are E222
            elif not fits and registry.sofa_has_template(spec, actual):
                self._unsupported_template(checked, actual, component.loc)
            elif not fits:
                inputs = sorted({t.split(",")[0] for t in spec.templates})
                self.diags.add(
                    "E214",
                    component.loc,
                    f"{owner} cannot map {in_type} {source.label!r} to {out_type} {target.label!r}: "
                    f"it supports {_fmt_types(spec.templates)}",
                    f"{spec.name} needs an input of type {' or '.join(inputs)}",
                )
            checked.template = actual
            edges.setdefault(id(source), []).append((target, checked))
        self._check_mapping_cycles(edges)

    def _check_mapping_cycles(self, edges: dict[int, list[tuple[Component, CheckedComponent]]]) -> None:
        reported: set[int] = set()
        for start in list(edges):
            # Iterative DFS from each mapped state looking for a path back to itself.
            stack = [(start, [])]  # (state id, mappings used)
            seen: set[int] = set()
            while stack:
                current, used = stack.pop()
                for target, mapping in edges.get(current, ()):
                    if id(target) == start and id(mapping.component) not in reported:
                        reported.update(id(m.component) for m in [*used, mapping])
                        chain = " -> ".join(m.component.label for m in [*used, mapping])
                        self.diags.add(
                            "E217",
                            mapping.component.loc,
                            f"mappings form a cycle: {chain}",
                            "a state cannot be computed from itself; remove one of these mappings",
                        )
                    elif id(target) not in seen:
                        seen.add(id(target))
                        stack.append((id(target), [*used, mapping]))

    # --- solvers -----------------------------------------------------------------------------
    def _check_solvers(self) -> None:
        for checked in self.checked:
            spec = checked.spec
            if spec is None:
                continue
            if spec.category is Category.ODE_SOLVER and spec.needs_linear_solver:
                node = checked.component.node
                explicit = checked.links.get("linearSolver")
                found = explicit if explicit is not None else self._linear_solver_below(node)
                found = found if found is not None else self._unknown_below(node)
                if found is None:
                    self.diags.add(
                        "E221",
                        checked.component.loc,
                        f"{spec.name} {checked.component.label!r} is implicit but node {node.path!r} has no "
                        "linear solver in it or below it",
                        'add e.g. <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/> '
                        "next to it",
                    )
            if spec.category is Category.STATE:
                self._check_state_integrated(checked)
            if spec is VARIATIONAL_SYMPLECTIC_SOLVER:
                component = checked.component
                if checked.fields.get("saveEnergyInFile") and not checked.fields.get("file"):
                    self.diags.add(
                        "W225",
                        component.attribute_loc("saveEnergyInFile"),
                        f"{spec.name} {component.label!r}: saveEnergyInFile=true without a file: SOFA "
                        "writes the energies nowhere",
                        'name the CSV file with file="energies.csv"',
                    )

    def _linear_solver_below(self, node: Node) -> Component | None:
        for descendant in node.walk():
            for component in descendant.objects:
                if self._is(component, Category.LINEAR_SOLVER):
                    return component
        return None

    def _unknown_below(self, node: Node) -> Component | None:
        """An unknown component (E200) in ``node`` or below: it may be the linear solver
        (SparseTAUCSLLtSolver), so no second diagnostic says there is none."""
        for descendant in node.walk():
            for component in descendant.objects:
                if self.checked.of(component).spec is None:
                    return component
        return None

    def _check_state_integrated(self, checked: CheckedComponent) -> None:
        state = checked.component
        if self.checked.mapping_of(state) is not None or self.checked.solver_of(state.node) is not None:
            return
        dynamic = [
            other
            for other in self.checked
            if other.state is state and other.category in (Category.MASS, Category.FORCEFIELD)
        ]
        if dynamic:
            names = ", ".join(f"{d.spec.name} {d.component.label!r}" for d in dynamic[:3])  # type: ignore[union-attr]
            self.diags.add(
                "W220",
                state.loc,
                f"MechanicalObject {state.label!r} has {names} acting on it but no ODE solver above it: "
                "it would never move",
                "add an ODE solver (e.g. <EulerImplicitSolver/> with a linear solver) "
                "to this node or an ancestor",
            )

    # --- rigid inertia -----------------------------------------------------------------------
    def _check_rigid_inertia(self, checked: CheckedComponent) -> None:
        """W230: an anisotropic inertia on a Rigid3d body that can rotate.

        SOFA's UniformMass<Rigid3d> applies the inertia matrix as given, in world axes: it is not
        turned with the body (R I R^T) and the gyroscopic term w x (I w) is left out. This is exact
        only for an isotropic inertia (a multiple of the identity) or a body that never rotates.
        """
        state = checked.state
        if state is None or checked.template != "Rigid3d" or not self._is(state, Category.STATE):
            return
        vertex = self.value(checked, "vertexMass")
        values = np.asarray(vertex if vertex is not None else (), dtype=float).ravel()
        if values.size != 11 or not np.isfinite(values).all():
            return  # the default inertia (identity), or a count error reported elsewhere
        inertia = values[2:].reshape(3, 3)
        if np.allclose(inertia, inertia[0, 0] * np.eye(3), rtol=1e-9, atol=0.0):
            return
        if self.checked.solver_of(state.node) is None:
            return  # never integrated: W220 says so when it matters
        size = self.state_size(state)
        if size is not None and self._fixed_dofs(state) >= set(range(size)):
            return
        why = self._rotation_cause(state)
        if why is None:
            return
        owner = f"UniformMass {checked.component.label!r}"
        principal = np.linalg.eigvalsh((inertia + inertia.T) / 2)
        self.diags.add(
            "W230",
            checked.component.attribute_loc(self._attribute_name(checked, "vertexMass")),
            f"{owner}: the inertia of {state.label!r} is anisotropic (principal values per unit mass "
            f"{', '.join(f'{v:.4g}' for v in principal)}) and the body can rotate ({why}); SOFA (and "
            "sofac, to match it) applies the inertia in world axes, without turning it with the body and "
            "without the gyroscopic term w x Iw, so a spinning anisotropic body moves wrongly",
            "results match SOFA, not rigid-body mechanics: where the body turns far from its initial "
            "orientation, use an isotropic inertia (a multiple of the identity) or check the motion "
            "against an exact rigid-body model",
        )

    def _fixed_dofs(self, state: Component) -> set[int]:
        """The DOFs of ``state`` that a FixedProjectiveConstraint holds."""
        fixed: set[int] = set()
        for other in self.checked:
            if other.state is not state or other.spec is None or other.spec.lowering != "fixed":
                continue
            if self.value(other, "fixAll"):
                return set(range(self.state_size(state) or 0))
            indices = self.value(other, "indices")
            if indices is not None:
                fixed.update(int(i) for i in np.ravel(indices))
        return fixed

    def _rotation_cause(self, state: Component) -> str | None:
        """Why a rigid state can rotate: an initial spin, or something that can apply a torque."""
        velocity = self.value(self.checked.of(state), "velocity")
        if velocity is not None and np.size(velocity) and np.size(velocity) % 6 == 0:
            spins = np.asarray(velocity, dtype=float).reshape(-1, 6)[:, 3:]
            if np.any(spins != 0):
                return "it starts with an angular velocity"
        acting = (
            Category.FORCEFIELD,
            Category.INTERACTION_FORCEFIELD,
            Category.LAGRANGIAN_CONSTRAINT,
            Category.COLLISION_MODEL,
        )
        for other in self.checked:
            if other.spec is None:
                continue
            label = f"{other.spec.name} {other.component.label!r}"
            if other.category in acting and (
                other.state is state or state in (other.links.get("object1"), other.links.get("object2"))
            ):
                return f"{label} acts on it"
            if other.category in (Category.MAPPING, Category.MULTI_MAPPING):
                inputs = [other.links.get("input"), *other.link_lists.get("input", ())]
                output = other.links.get("output")
                outputs = [output, *other.link_lists.get("output", ())]
                if any(i is state for i in inputs) and any(
                    isinstance(o, Component) and self._is(o, Category.STATE) for o in outputs
                ):
                    return f"{label} maps it to a mechanical state whose forces give it torques"
        return None

    # --- indices -----------------------------------------------------------------------------
    def _check_indices(self, checked: CheckedComponent) -> None:
        spec = checked.spec
        assert spec is not None
        for field_spec in spec.fields:
            if field_spec.indexes is None and not isinstance(field_spec.type, (Springs, JointSprings)):
                continue
            if field_spec.name not in checked.fields and field_spec.name not in checked.data_links:
                continue
            value = self.value(checked, field_spec.name)
            if value is None or np.size(value) == 0:
                continue
            if field_spec.name == "rigidIndexPerPoint" and np.size(value) != self._mapped_points(checked):
                continue  # SOFA ignores it then (and uses `index` for every point)
            attribute = self._attribute_name(checked, field_spec.name)
            loc = checked.component.attribute_loc(attribute)
            owner = f"{spec.name} {checked.component.label!r}"
            if isinstance(field_spec.type, (Springs, JointSprings)):
                springs = field_spec.type.ends(value)
                for column, role in ((0, "object1"), (1, "object2")):
                    state = self._indexed_state(checked, role)
                    self._report_range(
                        owner, field_spec.name, loc, springs[:, column].astype(np.int64), state
                    )
            else:
                state = self._indexed_state(checked, field_spec.indexes or "state")
                self._report_range(owner, field_spec.name, loc, np.asarray(value, dtype=np.int64), state)

    def _mapped_points(self, checked: CheckedComponent) -> int | None:
        """How many points a mapping maps: its output's positions (state or visual model), if known."""
        output = checked.links.get("output")
        if not isinstance(output, Component):
            return None
        target = self.checked.components.get(id(output))
        if target is None or target.spec is None or target.spec.field("position") is None:
            return None
        if target.category is Category.STATE:
            return self.state_size(output)
        value = self.value(target, "position")
        width = (target.datatype or DATATYPES["Vec3d"]).coord_size
        if value is None or np.size(value) == 0 or np.size(value) % width:
            return None
        return int(np.size(value)) // width

    def _indexed_state(self, checked: CheckedComponent, role: str) -> Component | None:
        if role == "state":
            return checked.state
        target = checked.links.get(role)
        if target is None and role in ("object1", "object2"):
            return self._node_state(checked.component.node)
        return target if isinstance(target, Component) else None

    def _report_range(
        self, owner: str, name: str, loc: SourceLoc, indices: np.ndarray, state: Component | None
    ) -> None:
        if state is None or not self._is(state, Category.STATE) or indices.size == 0:
            return
        size = self.state_size(state)
        if size is None:
            return
        bad = indices[(indices < 0) | (indices >= size)]
        if bad.size:
            self.diags.add(
                "E218",
                loc,
                f"{owner}: {name} contains index {int(bad[0])}, but {state.label!r} has {size} DOFs "
                f"(valid: 0..{size - 1}){f'; {bad.size} indices are out of range' if bad.size > 1 else ''}",
            )

    # --- files -------------------------------------------------------------------------------
    def _check_files(self, checked: CheckedComponent) -> None:
        from sofac.registry.fields import FileName

        spec = checked.spec
        assert spec is not None
        for name, value in checked.fields.items():
            field_spec = spec.field(name)
            if field_spec is None or not isinstance(field_spec.type, FileName) or not value:
                continue
            if field_spec.type.output:
                continue
            self.file_of(checked, name, report=True)
        if spec.compute:
            self._outputs(checked)

    def _loader_readers(self, checked: CheckedComponent) -> list[CheckedComponent] | None:
        """The components that read a loader's outputs (by link, src or data link); None if
        ``checked`` is not a loader."""
        if checked.category is not Category.LOADER:
            return None
        if self._readers is None:
            self._readers = {}
            for other in self.checked:
                targets = [*other.links.values(), *(t for ts in other.link_lists.values() for t in ts)]
                if other.src is not None:
                    targets.append(other.src)
                for path, _ in other.data_links.values():
                    target = links.resolve(path, other.component)
                    if target is not None:
                        targets.append(target)
                for target in targets:
                    readers = self._readers.setdefault(id(target), [])
                    if other not in readers:
                        readers.append(other)
        return self._readers.get(id(checked.component), [])

    def _missing_file_code(self, checked: CheckedComponent) -> tuple[str, str]:
        """The code and explanation of a loader's missing file: SOFA logs an error and goes on
        when nobody reads the loader (W229) or only visual models do (W231); anything feeding
        mechanics needs the data (E219)."""
        readers = self._loader_readers(checked)
        if readers is None:
            return "E219", ""
        if not readers:
            return "W229", "; nothing reads this loader's outputs"
        if all(reader.category is Category.VISUAL for reader in readers):
            names = ", ".join(sorted({r.spec.name if r.spec else r.component.type_name for r in readers}))
            return "W231", f"; only visual models ({names}) read it: they are left empty"
        return "E219", ""

    def file_of(self, checked: CheckedComponent, name: str, *, report: bool = False) -> Path | None:
        from sofac.front import parse

        value = checked.fields.get(name)
        if not value:
            return None
        component = checked.component
        base = Path(component.loc.file).parent
        path = parse.resolve_data_file(str(value), base, self.scene)
        if path is None and report:
            attribute = self._attribute_name(checked, name)
            roots = ", ".join(str(r) for r in self.scene.data_roots) or str(base)
            code, why = self._missing_file_code(checked)
            self.diags.add(
                code,
                component.attribute_loc(attribute),
                f"{checked.spec.name if checked.spec else component.type_name} {component.label!r}: "
                f"file {value!r} not found (searched {base} and the data roots: {roots})" + why,
                "a file or folder name has at most 255 bytes: shorten it"
                if any(len(part.encode()) > 255 for part in Path(str(value)).parts)
                else "fix the path, or add the folder holding it with --data-path",
            )
        return path

    def _add_data_repositories(self) -> None:
        """AddDataRepository: its folder (relative to the scene's) is searched for the files."""
        for checked in self.checked:
            spec = checked.spec
            if spec is None or spec.variant is not Variant.DATA_REPOSITORY or not checked.fields.get("path"):
                continue
            text = str(checked.fields["path"])
            folder = Path(checked.component.loc.file).parent / text
            problem = datafiles.add_data_folder(self.scene, folder)
            if problem is None:
                continue
            owner = f"AddDataRepository {checked.component.label!r}"
            loc = checked.component.attribute_loc("path")
            if problem == "outside":
                self.diags.add(
                    "E108",
                    loc,
                    f"{owner}: folder {text!r} is outside the allowed data roots",
                    f"pass it with --data-path {datafiles.real_path(folder)}",
                )
            else:
                self.diags.add(
                    "E219",
                    loc,
                    f"{owner}: folder {text!r} {'not found' if problem == 'missing' else 'is not a folder'}",
                    "fix the path (relative to the scene's folder)",
                )

    # --- plugins -----------------------------------------------------------------------------
    def _check_plugins(self) -> None:
        for checked in self.checked:
            spec = checked.spec
            if spec is not REQUIRED_PLUGIN:
                continue
            names = [*checked.fields.get("pluginName", ())]
            if not names and checked.component.name:
                names = [checked.component.name]
            for plugin in names:
                if registry.provides_components(plugin):
                    continue
                self.diags.add(
                    "W224",
                    checked.component.loc,
                    f"RequiredPlugin names {plugin!r}, which provides none of the components SOFA registers",
                    "old module names (SofaBaseMechanics...) were replaced by Sofa.Component.* "
                    "in SOFA v22.06",
                )


class _EvalContext:
    """The view of one component that evaluators get (see evaluate.Context)."""

    def __init__(self, checker: _Checker, checked: CheckedComponent) -> None:
        self.checker = checker
        self.checked = checked

    def value(self, name: str) -> Any:
        return self.checker.value(self.checked, name)

    def given(self, name: str) -> Any:
        """The value as the scene gives it, before the evaluator rewrites it (spec.rewrites)."""
        return self.checker.value(self.checked, name, raw=True)

    def is_set(self, name: str) -> bool:
        return name in self.checked.fields or name in self.checked.data_links

    def file(self, name: str) -> Path | None:
        return self.checker.file_of(self.checked, name)

    def linked(self, link: str, name: str) -> Any:
        target = self.checked.links.get(link)
        if not isinstance(target, Component):
            return None
        linked = self.checker.checked.of(target)
        return None if linked.spec is None else self.checker.value(linked, name)  # unknown type: no value

    def context_topology(self, name: str) -> tuple[str, Any] | None:
        """The component name and field ``name`` of the topology SOFA's getContext()->get finds
        (in the component's node, else the nearest ancestor's), if any."""
        found, _ = links.pick_in_node(
            self.checked.component.node, lambda c: self.checker._is(c, Category.TOPOLOGY), climb=True
        )
        if found is None:
            return None
        topology = self.checker.checked.of(found)
        if topology.spec is None:
            return None
        return topology.spec.name, self.checker.value(topology, name)

    def linked_type(self, link: str) -> str | None:
        target = self.checked.links.get(link)
        if not isinstance(target, Component):
            return None
        spec = self.checker.checked.of(target).spec
        return None if spec is None else spec.name

    def input_positions(self, name: str = "position") -> np.ndarray | None:
        source = self.checked.src
        from_src = source is not None and self.checker.checked.of(source).spec is not None
        if from_src:  # src="@loader" links the engine's position to the loader's
            from_src = self.checker.checked.of(source).spec.field(name) is not None  # type: ignore[union-attr]
        if self.is_set(name) or from_src:
            value = self.value(name)
            if value is None:
                # Linked to a Data sofac does not compute (an unsupported loader or mesh creator,
                # reported there): not known here, and no second error.
                raise evaluate.UnknownInput("the input positions are only known at run time")
            datatype = self.checked.datatype or DATATYPES["Vec3d"]
            if np.size(value) % datatype.coord_size:  # not points: the count check reports it (E205)
                raise evaluate.UnknownInput(f"{name} is not a list of {datatype.name} points")
            return np.asarray(value, dtype=float).reshape(-1, datatype.coord_size)
        state = self.checked.state or self.checker._node_state(self.checked.component.node)
        if state is None:
            return None
        points = self.checker.positions(state)
        if points is None:
            raise evaluate.UnknownInput(f"the positions of {state.label!r} are only known at run time")
        return points


def check_scene(scene: Scene, diagnostics: Diagnostics, *, allow_unsupported: bool = False) -> CheckedScene:
    """Check a parsed scene; problems are appended to ``diagnostics``."""
    started = time.perf_counter()
    diagnostics.downgrade_unsupported = allow_unsupported
    checked = _Checker(scene, diagnostics).run()
    checked.check_seconds = time.perf_counter() - started
    return checked


def check_file(
    path: str | Path, *, data_roots: Sequence[Path] = (), allow_unsupported: bool = False
) -> tuple[CheckedScene | None, Diagnostics]:
    """Parse and check one scene file; never raises for scene problems (they are diagnostics)."""
    from sofac.front import parse

    diagnostics = Diagnostics()
    diagnostics.downgrade_unsupported = allow_unsupported
    try:
        scene = parse.parse_scene(path, diagnostics, data_roots=data_roots)
    except SceneError:
        return None, diagnostics
    return check_scene(scene, diagnostics, allow_unsupported=allow_unsupported), diagnostics
