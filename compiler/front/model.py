"""The scene model: a tree of Nodes holding Components, every piece with its source location.

The parse stage builds it from ``.scn`` files; the SofaPython3-style API below builds the same model
from Python (``root.addChild("body").addObject("MechanicalObject", template="Rigid3d")``). Attribute
values are kept as the text SOFA would read; the check stage turns them into typed fields.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sofac.diagnostics import SourceLoc


@dataclass
class Attribute:
    name: str
    value: str
    loc: SourceLoc


def _to_text(value: Any) -> str:
    """SOFA's text form of a Python value: bools as 0/1, numbers exactly, sequences flattened."""
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        x = float(value)
        if math.isfinite(x) and x.is_integer() and abs(x) < 1e16:
            return str(int(x))
        return repr(x)
    if isinstance(value, np.ndarray):
        return " ".join(_to_text(v) for v in value.ravel().tolist())
    if isinstance(value, (list, tuple)):
        return " ".join(_to_text(v) for v in value)
    if isinstance(value, Component):
        return "@" + value.path
    if isinstance(value, Node):
        return "@" + value.path
    raise TypeError(f"cannot write a {type(value).__name__} as a SOFA attribute")


def _caller_loc() -> SourceLoc:
    """Location of the user's code that called the builder API (first frame outside this module)."""
    frame = inspect.currentframe()
    while frame is not None and frame.f_code.co_filename == __file__:
        frame = frame.f_back
    if frame is None:
        return SourceLoc("<python>", 0)
    return SourceLoc(frame.f_code.co_filename, frame.f_lineno)


class _Element:
    """What Nodes and Components share: a tag, ordered attributes and a location."""

    def __init__(self, tag: str, loc: SourceLoc) -> None:
        self.tag = tag
        self.loc = loc
        self.attributes: dict[str, Attribute] = {}
        self.parent: Node | None = None

    def get(self, name: str) -> str | None:
        attribute = self.attributes.get(name)
        return attribute.value if attribute else None

    def set(self, name: str, value: Any, loc: SourceLoc | None = None) -> None:
        self.attributes[name] = Attribute(name, _to_text(value), loc or self.loc.with_attribute(name))

    def attribute_loc(self, name: str) -> SourceLoc:
        attribute = self.attributes.get(name)
        return attribute.loc if attribute else self.loc.with_attribute(name)

    @property
    def name(self) -> str:
        return self.get("name") or ""


class Component(_Element):
    """One component (``<MechanicalObject .../>``): its class name as written and its attributes."""

    def __init__(self, type_name: str, loc: SourceLoc) -> None:
        super().__init__(type_name, loc)

    @property
    def type_name(self) -> str:
        return self.tag

    @property
    def node(self) -> Node:
        assert self.parent is not None, "component is not attached to a node"
        return self.parent

    @property
    def index(self) -> int:
        return self.node.objects.index(self)

    @property
    def label(self) -> str:
        """The name if it has one, else a SOFA-like generated one (Type + index in its node)."""
        return self.name or f"{self.type_name}{self.index + 1}"

    @property
    def path(self) -> str:
        base = self.node.path
        return f"{base.rstrip('/')}/{self.label}"

    def __repr__(self) -> str:
        return f"<{self.type_name} {self.path!r} at {self.loc}>"


class Node(_Element):
    """A node of the scene graph, holding components and child nodes."""

    def __init__(self, name: str = "", loc: SourceLoc | None = None) -> None:
        super().__init__("Node", loc or _caller_loc())
        if name:
            self.set("name", name)
        self.children: list[Node] = []
        self.objects: list[Component] = []

    # --- SofaPython3-style building API -------------------------------------------------------
    def addChild(self, name: str, **attributes: Any) -> Node:
        loc = _caller_loc()
        child = Node(name, loc)
        for key, value in attributes.items():
            child.set(key, value, loc.with_attribute(key))
        self.add_node(child)
        return child

    def addObject(self, type_name: str, **attributes: Any) -> Component:
        loc = _caller_loc()
        component = Component(type_name, loc)
        for key, value in attributes.items():
            component.set(key, value, loc.with_attribute(key))
        self.add_component(component)
        return component

    def add_node(self, child: Node) -> Node:
        child.parent = self
        self.children.append(child)
        return child

    def add_component(self, component: Component) -> Component:
        component.parent = self
        self.objects.append(component)
        return component

    # --- navigation ---------------------------------------------------------------------------
    @property
    def path(self) -> str:
        if self.parent is None:
            return "/"
        return f"{self.parent.path.rstrip('/')}/{self.label}"

    @property
    def label(self) -> str:
        if self.name:
            return self.name
        if self.parent is None:
            return "root"
        return f"Node{self.parent.children.index(self) + 1}"

    @property
    def root(self) -> Node:
        node = self
        while node.parent is not None:
            node = node.parent
        return node

    def child(self, name: str) -> Node | None:
        return next((c for c in self.children if c.name == name), None)

    def object(self, name: str) -> Component | None:
        return next((o for o in self.objects if o.name == name), None)

    def walk(self) -> Iterator[Node]:
        """This node and all its descendants, depth first, in document order (iteratively)."""
        stack = [self]
        while stack:
            node = stack.pop()
            yield node
            stack.extend(reversed(node.children))

    def components(self) -> Iterator[Component]:
        for node in self.walk():
            yield from node.objects

    def ancestors(self) -> Iterator[Node]:
        node = self.parent
        while node is not None:
            yield node
            node = node.parent

    def depth(self) -> int:
        return sum(1 for _ in self.ancestors())

    def __getattr__(self, name: str) -> Any:
        # SofaPython3 lets users write root.body.dofs; only for real child/object names.
        if name.startswith("_") or name in {"children", "objects", "attributes"}:
            raise AttributeError(name)
        found = self.child(name) or self.object(name)
        if found is None:
            raise AttributeError(f"node {self.path!r} has no child or object named {name!r}")
        return found

    def __repr__(self) -> str:
        return f"<Node {self.path!r} at {self.loc}>"


@dataclass
class Scene:
    """A whole scene: its root node, the file it came from and the files it pulled in."""

    root: Node
    file: Path | None = None
    # Directories searched for included files, meshes and macro files, in order.
    data_roots: list[Path] = field(default_factory=list)
    # Every file read while parsing (the scene, its includes), for caching and diagnostics.
    sources: list[Path] = field(default_factory=list)
    # Every referenced file looked up (meshes...), each candidate tried -> whether it was a file.
    lookups: dict[Path, bool] = field(default_factory=dict)

    @property
    def display_name(self) -> str:
        return str(self.file) if self.file else "<python>"
