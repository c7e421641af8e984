"""A SofaPython3-compatible API over sofac's scene model: ``Sofa``, ``Sofa.Core``, ``Sofa.Simulation``,
``Sofa.Helper`` and ``SofaRuntime``, for scene scripts written for SofaPython3.

``Sofa.Core.Node`` and ``Sofa.Core.Object`` wrap the model's Node and Component (model.py): a
script's ``addObject``/``addChild`` build the very tree the parse stage builds from XML, each
element located at the line of the call that made it. Data fields (``obj.position``,
``node.findData("dt")``) read and write the model's attribute text until the tree is compiled;
after that (``Sofa.Simulation.init`` or ``sofac.load``) they are numpy views of the compiled
state and parameters, as ``sim[path]`` and ``sim.param(key)`` are.

The module objects are not installed in ``sys.modules``: :func:`injected` puts them there only
while a scene script (or a controller called from the compiled loop) runs, and puts back whatever
was there before, so a real SOFA installation in the same interpreter is never shadowed outside
that window. Use ``from sofac.sofapython import Sofa`` to build a tree in ordinary Python code.

Anything of SofaPython3 this module does not provide raises :class:`SofaAPIError` (an
AttributeError, so ``hasattr`` still works) naming the missing name.
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import importlib.abc
import importlib.machinery
import inspect
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from sofac.diagnostics import SofacError, SourceLoc, relative_name
from sofac.front import model
from sofac.registry import lookup, node_spec
from sofac.simulation.loader import State

_PACKAGE_DIR = str(Path(__file__).resolve().parent)


class SofaAPIError(SofacError, AttributeError):
    """A script used a part of SofaPython3's API that sofac does not provide."""


def _missing(what: str, detail: str = "") -> SofaAPIError:
    return SofaAPIError(
        f"{what} is not part of the SofaPython3 API sofac provides{': ' + detail if detail else ''} "
        "(see docs/python-scenes.md for what is)"
    )


# --- where the user's code is ------------------------------------------------------------------


@functools.cache
def _is_user_frame(filename: str) -> bool:
    # Real paths: sofac may be imported through a symlink (an editable install, .pkg/sofac).
    if filename.startswith("<frozen"):
        return False
    return not os.path.realpath(filename).startswith(_PACKAGE_DIR + os.sep)


def user_loc() -> SourceLoc:
    """The file and line of the innermost caller outside sofac (the ``addObject`` line)."""
    frame = inspect.currentframe()
    while frame is not None and not _is_user_frame(frame.f_code.co_filename):
        frame = frame.f_back
    if frame is None:
        return SourceLoc("<python>", 0)
    return SourceLoc(display_file(frame.f_code.co_filename), frame.f_lineno)


#: File names as the user named them (the scene script as given on the command line).
_DISPLAY: dict[str, str] = {}


def display_file(filename: str) -> str:
    if filename in _DISPLAY or filename.startswith("<"):
        return _DISPLAY.get(filename, filename)
    return relative_name(Path(filename))


# --- wrappers and bindings ---------------------------------------------------------------------

# Kept on the model elements themselves (a wrapper and its element, a simulation and its tree,
# are freed together): a weak-keyed table would keep them alive through its values.
_WRAPPER = "_sofa_api"
_SIMULATION = "_sofa_simulation"


def wrap(element: model._Element) -> Any:
    """The API object of a model element (made on first use, then always the same one)."""
    wrapper = element.__dict__.get(_WRAPPER)
    if wrapper is None:
        wrapper = Node._of(element) if isinstance(element, model.Node) else Object._of(element)
    return wrapper


def controllers_of(node: model.Node) -> list[Controller]:
    """The controllers added to a node, in order."""
    wrapper = node.__dict__.get(_WRAPPER)
    return list(wrapper._controllers) if wrapper is not None else []


def bind(root: model.Node, sim: Any) -> None:
    """Make the Data of the tree under ``root`` views of ``sim`` (a compiled Simulation)."""
    root.__dict__[_SIMULATION] = sim


def bound_simulation(element: model._Element) -> Any:
    root = element if isinstance(element, model.Node) else element.parent
    if root is None:
        return None
    return root.root.__dict__.get(_SIMULATION)


def _text(value: Any, where: str) -> str:
    if isinstance(value, Data):
        return value.getLinkPath()
    if isinstance(value, _Base):
        return value.getLinkPath()
    if isinstance(value, (list, tuple)):
        return " ".join(_text(v, where) for v in value)
    try:
        return model._to_text(value)
    except TypeError:
        raise SofaAPIError(
            f"{where}: a {type(value).__name__} cannot be a SOFA data value "
            "(give a number, a string, a list or numpy array of numbers, or a link)"
        ) from None


def _field_spec(element: model._Element, name: str) -> Any:
    if isinstance(element, model.Node):
        return node_spec().field(name)
    resolution = lookup(element.tag)
    return resolution.spec.field(name) if resolution is not None else None


def _is_field(element: model._Element, name: str) -> bool:
    return name in element.attributes or _field_spec(element, name) is not None


class Data:
    """A data field of a node or object (SofaPython3's ``Sofa.Core.Data``)."""

    def __init__(self, owner: _Base, name: str) -> None:
        object.__setattr__(self, "_owner", owner)
        object.__setattr__(self, "_name", name)

    # --- value ---
    @property
    def value(self) -> Any:
        return self._owner._read(self._name, writeable=False)

    @value.setter
    def value(self, new: Any) -> None:
        self._owner._write(self._name, new)

    @contextlib.contextmanager
    def writeableArray(self) -> Iterator[np.ndarray]:
        """The value as a writeable array; a compiled field's native buffer itself."""
        array = self._owner._read(self._name, writeable=True)
        if array is None:
            raise SofaAPIError(f"{self.getPathName()} has no value yet: set .value first")
        if not isinstance(array, np.ndarray):
            raise SofaAPIError(f"{self.getPathName()} is a single value, not an array: set .value instead")
        yield array
        if bound_simulation(self._owner._element) is None:
            self._owner._write(self._name, array)

    def array(self) -> np.ndarray:
        return np.asarray(self.value)

    def toList(self) -> Any:
        value = self.value
        return value.tolist() if isinstance(value, np.ndarray) else value

    def getValueString(self) -> str:
        return _text(self.value, self.getPathName())

    def getName(self) -> str:
        return self._name

    def getOwner(self) -> Any:
        return self._owner

    def getPathName(self) -> str:
        return f"{self._owner._element.path}.{self._name}"

    def getLinkPath(self) -> str:
        return "@" + self.getPathName()

    @property
    def linkpath(self) -> str:
        return self.getLinkPath()

    def isSet(self) -> bool:
        return self._name in self._owner._element.attributes

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        raise _missing(f"Sofa.Core.Data.{name}", f"Data {self.getPathName()!r} has value, writeableArray()")

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "value":
            object.__setattr__(self, name, value)
            return
        raise _missing(f"setting Sofa.Core.Data.{name}", "set .value instead")

    def __repr__(self) -> str:
        return f"<Data {self.getPathName()} = {self.value!r}>"

    def __str__(self) -> str:
        return str(self.value)


class _Base:
    """What nodes and objects share: a model element, Data access by attribute, names, paths."""

    _element: model._Element

    @classmethod
    def _of(cls, element: model._Element) -> Any:
        wrapper = cls.__new__(cls)
        object.__setattr__(wrapper, "_element", element)
        element.__dict__[_WRAPPER] = wrapper
        return wrapper

    # --- names and paths ---
    @property
    def name(self) -> Data:
        return Data(self, "name")

    def getName(self) -> str:
        return self._element.label

    def setName(self, name: str) -> None:
        self._element.set("name", name, user_loc().with_attribute("name"))

    def getPathName(self) -> str:
        return self._element.path

    def getLinkPath(self) -> str:
        return "@" + self._element.path

    @property
    def linkpath(self) -> str:
        return self.getLinkPath()

    def findData(self, name: str) -> Data | None:
        return Data(self, name) if _is_field(self._element, name) else None

    getData = findData

    def getDataFields(self) -> list[Data]:
        return [Data(self, name) for name in self._element.attributes]

    def getInstanciationSourceFileName(self) -> str:
        return self._element.loc.file

    def getInstanciationSourceFilePos(self) -> int:
        return self._element.loc.line

    # --- data values ---
    def _read(self, name: str, *, writeable: bool) -> Any:
        sim = bound_simulation(self._element)
        if sim is not None and name == "time" and isinstance(self._element, model.Node):
            return sim.time  # the simulation's clock, as SOFA's context time
        if sim is not None:
            view = _compiled_view(sim, self._element, name)
            if view is not None:
                if writeable:
                    if f"{self._element.path}.{name}" in sim.spec.pruned:
                        sim.param(f"{self._element.path}.{name}")  # raises PrunedEffectError
                    return view
                if view.size == 1 and _is_scalar(self._element, name):
                    return view.item()
                out = view.view()
                out.flags.writeable = False
                return out
        if name == "name":
            return self._element.label
        return _parse_value(self._element, name, copy=writeable)

    def _write(self, name: str, value: Any) -> None:
        sim = bound_simulation(self._element)
        where = f"{self._element.path}.{name}"
        if sim is not None:
            if where in sim.spec.pruned:
                sim.param(where)  # raises PrunedEffectError: its effect was compiled out (zero gravity)
            view = _compiled_view(sim, self._element, name)
            if view is None:
                raise SofaAPIError(
                    f"{where} was fixed when the scene was compiled; only the compiled state (position, "
                    "velocity, force) and the parameters listed by sim.params() can change between steps"
                )
            new = np.asarray(value, dtype=view.dtype)
            if new.size != view.size:
                raise SofaAPIError(f"{where} holds {view.size} values; {new.size} given")
            view[...] = new.reshape(view.shape)
            return
        self._element.set(name, _text(value, where), user_loc().with_attribute(name))

    def __setattr__(self, name: str, value: Any) -> None:
        # As SofaPython3: a data field is set, anything else becomes a plain Python attribute.
        if not name.startswith("_") and _is_field(self._element, name):
            self._write(name, value)
        else:
            object.__setattr__(self, name, value)


def _is_scalar(element: model._Element, name: str) -> bool:
    spec = _field_spec(element, name)
    return spec is not None and spec.type.kind in ("real", "int", "bool")


def _parse_value(element: model._Element, name: str, *, copy: bool) -> Any:
    """A field's value from the model's text: typed by the registry where it knows the field."""
    text = element.get(name)
    spec = _field_spec(element, name)
    if text is None:
        default = spec.default if spec is not None else None
        if default is None:
            return None
        return np.array(default) if isinstance(default, (tuple, list)) else default
    if spec is not None:
        try:
            value = spec.type.parse(text)
        except (ValueError, TypeError):
            return text
        if isinstance(value, np.ndarray):
            array = value.copy() if copy else value
            if not copy:
                array.flags.writeable = False
            return array
        return value
    return text


def _compiled_view(sim: Any, element: model._Element, name: str) -> np.ndarray | None:
    """The native buffer behind a field of the compiled scene (cached per instance: controllers
    read the same fields at every step)."""
    cache = sim.__dict__.get("_data_views")
    if cache is None or cache[0] is not sim._native:  # recompile() swaps the native instance
        cache = sim.__dict__["_data_views"] = (sim._native, {})
    key = (id(element), name)
    if key not in cache[1]:
        cache[1][key] = _find_view(sim, element, name)
    found = cache[1][key]
    # A state's arrays are read through it: a mapped state left out of the step is mapped on read.
    return getattr(found, name) if isinstance(found, State) else found  # type: ignore[no-any-return]


def _find_view(sim: Any, element: model._Element, name: str) -> Any:
    """The State, or the native parameter shaped as SofaPython3 shapes it, behind a field."""
    path = element.path
    if isinstance(element, model.Component) and name in ("position", "velocity", "force"):
        with contextlib.suppress(KeyError):
            return sim[path]
    key = f"{path}.{name}"
    params = sim.params()
    view = params.get(key)
    if view is None:
        return None
    if isinstance(element, model.Component) and view.size > 1:
        spec = _field_spec(element, name)
        node_state = next(
            (sim[p] for p in sim.objects() if p.rsplit("/", 1)[0] == (element.node.path.rstrip("/"))),
            None,
        )
        if spec is not None and spec.type.kind.startswith("coord") and node_state is not None:
            width = node_state.velocity.shape[1]
            if view.size % width == 0:
                return view.reshape(-1, width)
    return view


# --- Sofa.Core.Node, Object, Controller --------------------------------------------------------


class _Listing(list):  # type: ignore[type-arg]
    """``node.children`` / ``node.objects``: a list that is also indexed by name."""

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, str):
            found = next((item for item in self if item.getName() == key), None)
            if found is None:
                raise KeyError(key)
            return found
        return super().__getitem__(key)


# SofaPython3 names sofac knows but does not provide, for a better message than "no child named".
_NODE_UNSUPPORTED = frozenset(
    {
        "addData", "addLink", "computeEnergy", "detachFromGraph", "getAsACreateObjectParameter",
        "getForceField", "getMass", "getMechanicalMapping", "hasODESolver", "moveChild", "sendEvent",
        "getRootPath", "add",
    }
)  # fmt: skip


class Node(_Base):
    """``Sofa.Core.Node``: a node of the scene graph."""

    def __init__(self, name: str = "root") -> None:
        node = model.Node(name, user_loc())
        object.__setattr__(self, "_element", node)
        object.__setattr__(self, "_controllers", [])
        node.__dict__[_WRAPPER] = self

    @classmethod
    def _of(cls, element: model._Element) -> Any:
        wrapper = super()._of(element)
        object.__setattr__(wrapper, "_controllers", [])
        return wrapper

    @property
    def _node(self) -> model.Node:
        assert isinstance(self._element, model.Node)
        return self._element

    def _editable(self, what: str) -> None:
        if bound_simulation(self._node) is not None:
            raise SofaAPIError(
                f"{what} on {self._node.path!r}: the scene is compiled, its components are fixed while it "
                "runs (change parameters and state through Data instead, or build and load a new tree)"
            )

    # --- building ---
    def addObject(self, type_name: Any, *args: Any, **attributes: Any) -> Any:
        loc = user_loc()
        self._editable("addObject")
        if isinstance(type_name, Controller):
            if args or attributes:
                raise SofaAPIError("addObject(controller) takes no other arguments")
            type_name._attach(self)
            self._controllers.append(type_name)
            return type_name
        if args:
            raise SofaAPIError(
                f"addObject({type_name!r}, ...) with positional arguments: give data as keywords "
                "(addObject('MechanicalObject', name='dofs', position=...))"
            )
        if isinstance(type_name, _Base) or not isinstance(type_name, str):
            raise _missing(
                f"addObject({type(type_name).__name__})",
                "addObject takes a component type name (a string) or a Sofa.Core.Controller",
            )
        component = model.Component(type_name, loc)
        for key, value in attributes.items():
            component.set(key, _text(value, f"{type_name} {key}"), loc.with_attribute(key))
        self._node.add_component(component)
        return wrap(component)

    createObject = addObject  # SofaPython2's name, still accepted by SofaPython3

    def addChild(self, child: Any, **attributes: Any) -> Node:
        loc = user_loc()
        self._editable("addChild")
        if isinstance(child, Node):
            if child._node.parent is not None:
                raise SofaAPIError(f"node {child.getPathName()!r} already has a parent")
            self._node.add_node(child._node)
            return child
        if not isinstance(child, str):
            raise SofaAPIError(f"addChild takes a name or a Sofa.Core.Node, not a {type(child).__name__}")
        node = model.Node(child, loc)
        for key, value in attributes.items():
            node.set(key, _text(value, f"node {child} {key}"), loc.with_attribute(key))
        self._node.add_node(node)
        return wrap(node)  # type: ignore[no-any-return]

    createChild = addChild

    def removeChild(self, child: Any) -> None:
        self._editable("removeChild")
        target = child._node if isinstance(child, Node) else self._node.child(str(child))
        if target is None or target not in self._node.children:
            raise SofaAPIError(f"node {self.getPathName()!r} has no child {child!r}")
        self._node.children.remove(target)
        target.parent = None

    def removeObject(self, obj: Any) -> None:
        self._editable("removeObject")
        if isinstance(obj, Controller):
            self._controllers.remove(obj)
            return
        target = obj._element if isinstance(obj, Object) else None
        if target is None or target not in self._node.objects:
            raise SofaAPIError(f"node {self.getPathName()!r} has no object {obj!r}")
        self._node.objects.remove(target)
        target.parent = None

    def init(self) -> None:
        """SOFA initialises the subtree; sofac does it when the scene is compiled."""

    # --- navigation ---
    def getChild(self, name: str) -> Node | None:
        found = self._node.child(name)
        return wrap(found) if found is not None else None

    def getObject(self, name: str) -> Any:
        found = self._node.object(name)
        if found is not None:
            return wrap(found)
        return next((c for c in self._controllers if c.getName() == name), None)

    def hasObject(self, name: str) -> bool:
        return self.getObject(name) is not None

    @property
    def children(self) -> _Listing:
        return _Listing(wrap(c) for c in self._node.children)

    @property
    def objects(self) -> _Listing:
        return _Listing([*(wrap(o) for o in self._node.objects), *self._controllers])

    @property
    def parents(self) -> list[Node]:
        return [wrap(self._node.parent)] if self._node.parent is not None else []

    def getRoot(self) -> Node:
        return wrap(self._node.root)  # type: ignore[no-any-return]

    def getMechanicalState(self) -> Any:
        found = next((o for o in self._node.objects if o.type_name == "MechanicalObject"), None)
        return wrap(found) if found is not None else None

    def isInitialized(self) -> bool:
        return bound_simulation(self._node) is not None

    def __getitem__(self, path: str) -> Any:
        """``node["child.dofs.position"]``: children, objects and data, separated by dots."""
        parts = [p for p in str(path).split(".") if p]
        if not parts:
            raise ValueError(f"invalid path {path!r}")
        here: Any = self
        for index, part in enumerate(parts):
            last = index == len(parts) - 1
            if isinstance(here, Node):
                found = here.getChild(part) or here.getObject(part)
                if found is None and last and _is_field(here._node, part):
                    found = Data(here, part)
            elif isinstance(here, (Object, Controller)) and last:
                found = here.findData(part)
            else:
                found = None
            if found is None:
                raise KeyError(f"{path!r}: nothing named {part!r} under {here.getPathName()!r}")
            here = found
        return here

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        node = self._node
        # SofaPython3's order: an object, then a child node, then a data field of that name.
        found = self.getObject(name) or self.getChild(name)
        if found is not None:
            return found
        if _is_field(node, name):
            return Data(self, name)
        if name in _NODE_UNSUPPORTED:
            raise _missing(f"Sofa.Core.Node.{name}")
        names = [c.label for c in node.children] + [o.label for o in node.objects]
        raise SofaAPIError(
            f"node {node.path!r} has no child, object or data named {name!r} "
            f"(it has: {', '.join(names) or 'nothing yet'}); "
            f"nor is Sofa.Core.Node.{name} part of the SofaPython3 API sofac provides"
        )

    def __repr__(self) -> str:
        return f"<Sofa.Core.Node {self._node.path!r}>"


_OBJECT_UNSUPPORTED = frozenset(
    {"addData", "addLink", "findLink", "getLinks", "bwdInit", "reinit", "cleanup", "computeBBox"}
)


class Object(_Base):
    """``Sofa.Core.Object``: a component of the scene graph (made by ``node.addObject``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise SofaAPIError("Sofa.Core.Object cannot be made directly: use node.addObject('Type', ...)")

    def getClassName(self) -> str:
        resolution = lookup(self._element.tag)
        return resolution.spec.name if resolution is not None else self._element.tag

    def getTemplateName(self) -> str:
        return self._element.get("template") or ""

    def getContext(self) -> Node:
        return wrap(self._element.parent)  # type: ignore[no-any-return]

    def init(self) -> None:
        """SOFA initialises the object; sofac does it when the scene is compiled."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        element = self._element
        if _is_field(element, name):
            return Data(self, name)
        if name in _OBJECT_UNSUPPORTED:
            raise _missing(f"Sofa.Core.Object.{name}")
        resolution = lookup(element.tag)
        known = [*element.attributes, *(resolution.spec.field_names if resolution is not None else ())]
        close = difflib.get_close_matches(name, known, n=3, cutoff=0.75)
        raise SofaAPIError(
            f"{element.tag} {element.path!r} has no data named {name!r}"
            + (f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else "")
            + f", nor is Sofa.Core.Object.{name} part of the SofaPython3 API sofac provides"
        )

    def __repr__(self) -> str:
        return f"<Sofa.Core.Object {self._element.tag} {self._element.path!r}>"


class Controller:
    """``Sofa.Core.Controller``: subclass it, define ``onAnimateBeginEvent(self, event)`` and/or
    ``onAnimateEndEvent(self, event)`` (or ``onEvent``), and add it with ``node.addObject(...)``.

    As in SofaPython3, the keyword arguments of the constructor become attributes (``name`` names
    the controller). The callbacks run between the compiled steps (see pyscene.py)."""

    _node: Node | None = None
    _controller_name: str = ""
    _loc: SourceLoc = SourceLoc("<python>", 0)
    _running = False  # set once a compiled simulation calls it

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._controller_name = str(kwargs.pop("name", ""))
        self._loc = user_loc()
        for key, value in kwargs.items():
            setattr(self, key, value)

    def _attach(self, node: Node) -> None:
        if self._node is not None:
            raise SofaAPIError(
                f"controller {self.getName()!r} was already added to {self._node.getPathName()!r}"
            )
        self._node = node
        self._loc = user_loc()

    @property
    def name(self) -> Data:
        return _ControllerName(self)  # type: ignore[return-value]

    @name.setter
    def name(self, value: Any) -> None:  # `self.name = "x"` sets the data, as in SofaPython3
        self._controller_name = str(value)

    def getName(self) -> str:
        return self._controller_name or type(self).__name__

    def getContext(self) -> Node:
        if self._node is None:
            raise SofaAPIError(f"controller {self.getName()!r} is not in a scene yet (node.addObject(it))")
        return self._node

    def getPathName(self) -> str:
        base = self._node.getPathName().rstrip("/") if self._node is not None else ""
        return f"{base}/{self.getName()}"

    def getLinkPath(self) -> str:
        return "@" + self.getPathName()

    def findData(self, name: str) -> Any:
        return _ControllerName(self) if name == "name" else None

    def getClassName(self) -> str:
        return type(self).__name__

    def init(self) -> None:
        """Called once the scene is compiled (SOFA's init); override it."""

    def reinit(self) -> None:
        """Kept for scripts that call it; sofac has nothing to redo."""

    def bwdInit(self) -> None:
        """Kept for scripts that define or call it."""

    @property
    def location(self) -> SourceLoc:
        """Where the controller was added to the scene (or made)."""
        return self._loc


class _ControllerName:
    def __init__(self, controller: Controller) -> None:
        self._controller = controller

    @property
    def value(self) -> str:
        return self._controller.getName()

    @value.setter
    def value(self, new: str) -> None:
        self._controller._controller_name = str(new)

    def __str__(self) -> str:
        return self.value


# --- Sofa.Simulation ---------------------------------------------------------------------------


def _simulation_of(root: Any, function: str) -> Any:
    if not isinstance(root, Node):
        raise SofaAPIError(f"Sofa.Simulation.{function} takes a Sofa.Core.Node, not {type(root).__name__}")
    sim = bound_simulation(root._node)
    if sim is None:
        raise SofaAPIError(f"Sofa.Simulation.{function}: call Sofa.Simulation.init(root) first")
    return sim


def _init(root: Any) -> None:
    if not isinstance(root, Node):
        raise SofaAPIError(f"Sofa.Simulation.init takes a Sofa.Core.Node, not {type(root).__name__}")
    from sofac.pipeline import load

    load(root)


def _animate(root: Any, dt: float | None = None) -> None:
    sim = _simulation_of(root, "animate")
    if dt is not None and float(dt) != sim.dt:
        sim.dt = float(dt)
    sim.step(1)


def _reset(root: Any) -> None:
    _simulation_of(root, "reset").reset()


def _unload(root: Any) -> None:
    if isinstance(root, Node):
        root._node.root.__dict__.pop(_SIMULATION, None)


# --- Sofa.Helper messages ----------------------------------------------------------------------


def _message(kind: str) -> Callable[..., None]:
    def emit(*args: Any) -> None:
        if len(args) >= 2:
            emitter = args[0].getName() if hasattr(args[0], "getName") else str(args[0])
            text = " ".join(str(a) for a in args[1:])
        else:
            emitter, text = "PythonScript", " ".join(str(a) for a in args)
        print(f"[{kind}] [{emitter}] {text}", file=sys.stderr)

    emit.__name__ = f"msg_{kind.lower()}"
    return emit


def _import_plugin(name: str) -> bool:
    """SOFA loads a plugin library; sofac compiles components itself, so there is nothing to do."""
    return True


# --- the module objects ------------------------------------------------------------------------


def _module(name: str, members: dict[str, Any], doc: str) -> ModuleType:
    module = ModuleType(name, doc)
    module.__dict__.update(members)

    def missing(attribute: str) -> Any:
        if attribute.startswith("__"):
            raise AttributeError(attribute)
        raise _missing(f"{name}.{attribute}")

    module.__dict__["__getattr__"] = missing
    return module


_CORE = _module(
    "Sofa.Core",
    {"Node": Node, "Object": Object, "BaseObject": Object, "Controller": Controller, "Data": Data},
    "sofac's Sofa.Core: Node, Object, Controller, Data.",
)
_SIMULATION = _module(
    "Sofa.Simulation",
    {"init": _init, "initRoot": _init, "animate": _animate, "reset": _reset, "unload": _unload},
    "sofac's Sofa.Simulation: init/initRoot compile the tree, animate steps it, reset restarts it.",
)
_HELPER = _module(
    "Sofa.Helper",
    {f"msg_{k.lower()}": _message(k) for k in ("INFO", "WARNING", "ERROR", "DEPRECATED", "FATAL")},
    "sofac's Sofa.Helper: the msg_* functions (printed on stderr).",
)
Sofa = _module(
    "Sofa",
    {"Core": _CORE, "Simulation": _SIMULATION, "Helper": _HELPER},
    "sofac's SofaPython3-compatible API (see sofac.sofapython).",
)
Sofa.__path__ = []  # a package: `import Sofa.Gui` asks the finders, and _Placeholders answers
SofaRuntime = _module(
    "SofaRuntime",
    {"importPlugin": _import_plugin},
    "sofac's SofaRuntime: importPlugin (nothing to load: sofac compiles the components).",
)
_MODULES = {m.__name__: m for m in (Sofa, _CORE, _SIMULATION, _HELPER, SofaRuntime)}


class _Placeholders(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports of other SOFA modules (``Sofa.Gui``, ``SofaImGui``...) succeed, so that a script
    importing them for its ``main()`` still loads; using one raises SofaAPIError."""

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname.split(".")[0].startswith("Sofa"):
            return importlib.machinery.ModuleSpec(fullname, self, is_package=True)
        return None

    def create_module(self, spec: Any) -> ModuleType:
        module = _module(spec.name, {}, f"placeholder: {spec.name} is not provided by sofac")
        module.__path__ = []
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: every attribute access raises SofaAPIError."""


_FINDER = _Placeholders()


@contextlib.contextmanager
def injected() -> Iterator[None]:
    """``import Sofa`` / ``import SofaRuntime`` give these modules inside the block; outside it,
    sys.modules is as it was (a real SOFA install keeps its names)."""
    saved = {name: sys.modules.get(name) for name in _MODULES}
    placeholders_before = {n for n in sys.modules if n.split(".")[0].startswith("Sofa")}
    sys.modules.update(_MODULES)
    sys.meta_path.append(_FINDER)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            sys.meta_path.remove(_FINDER)
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module
        for name in [n for n in sys.modules if n.split(".")[0].startswith("Sofa")]:
            if name not in placeholders_before and getattr(sys.modules[name], "__loader__", None) is _FINDER:
                del sys.modules[name]
