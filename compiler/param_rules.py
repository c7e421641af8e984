"""The registry's field rules applied to the values that enter at run time (``sim.param(...)``,
``sim.dt``, sweeps and their tables), with the message the same value gets in a scene file.

A run spec carries, per tunable parameter, the component type and field it comes from (plain data,
kept in the warm record); the predicates themselves are read from the registry when a value is
checked, so a warm load imports the registry only once a parameter has changed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from sofac.diagnostics import SofacError


@dataclass(frozen=True)
class ParamRule:
    """Where a tunable parameter comes from, to find its rule in the registry."""

    type_name: str  # the component's class, "Node" for the root's dt and gravity
    field: str  # the field the buffer holds (its registry name)
    origin: str  # "TypeName 'path' (file:line)"
    columns: int = 1  # row width of the buffer (a rigid mass: m and its inertia terms)


class InvalidParameter(SofacError, ValueError):
    """A value set at run time that the same rule refuses in a scene file (E206 / E207)."""

    def __init__(self, message: str, *, key: str, code: str) -> None:
        super().__init__(message)
        self.key = key
        self.code = code


def rules_of(checked: Any, buffers: Iterable[Any]) -> dict[str, ParamRule]:
    """The rule source of each parameter buffer of a plan (``checked``: the checked scene)."""
    from sofac.plan.ir import origin_of

    by_path = {c.component.path: c for c in checked}
    rules = {}
    for buffer in buffers:
        if buffer.role != "param":
            continue
        path, _, field = buffer.key.rpartition(".")
        owner = by_path.get(path)
        if owner is not None and owner.spec is not None:
            rules[buffer.key] = ParamRule(owner.spec.name, field, origin_of(owner.component), buffer.columns)
        elif path == "/":
            root = checked.scene.root
            rules[buffer.key] = ParamRule("Node", field, f"the root node ({root.loc.file}:{root.loc.line})")
    return rules


def _positive(x: float) -> bool:
    return x > 0


def _rule(rule: ParamRule) -> tuple[Callable[[float], bool], str, int] | None:
    """(predicate, phrase, stride): the predicate applies to every ``stride``-th value."""
    from sofac import registry
    from sofac.registry.fields import MassValue
    from sofac.registry.spec import Category

    if rule.type_name == "Node":
        spec = registry.node_spec()
    else:
        resolution = registry.lookup(rule.type_name)
        if resolution is None:
            return None
        spec = resolution.spec
    field = spec.field(rule.field)
    if field is None:
        return None
    if isinstance(field.type, MassValue) or (spec.category is Category.MASS and rule.field == "vertexMass"):
        # The mass itself (a rigid mass's inertia terms, after it in each row, may be 0 or negative).
        return _positive, "must be > 0 (a mass)", max(1, rule.columns)
    return (*field.valid, 1) if field.valid is not None else None


def check(key: str, values: np.ndarray, rule: ParamRule | None) -> None:
    """Raise InvalidParameter naming ``key`` when one of ``values`` breaks the rule of its field."""
    flat = np.asarray(values, dtype=float).ravel()
    where = f" ({rule.origin})" if rule is not None else ""
    bad = np.flatnonzero(~np.isfinite(flat))
    if bad.size:
        index = int(bad[0])
        raise InvalidParameter(
            f"E206: {_name(key, index, flat.size)} = {flat[index]:g} is not finite{where}: "
            "nan and inf are not valid parameter values; set a finite number",
            key=key,
            code="E206",
        )
    found = _rule(rule) if rule is not None else None
    if found is None:
        return
    predicate, phrase, stride = found
    for value in np.unique(flat[::stride]):
        if not predicate(float(value)):
            index = int(np.flatnonzero(flat == value)[0])
            raise InvalidParameter(
                f"E207: {_name(key, index, flat.size)} = {value:g} {phrase}{where}, as in a "
                "scene file: use a physically meaningful value",
                key=key,
                code="E207",
            )


def _name(key: str, index: int, size: int) -> str:
    return key if size == 1 else f"{key}[{index}]"


class ParamGuard:
    """Checks the tunable parameters of an instance before it steps: those changed since the last
    check are validated (a cheap comparison with a copy otherwise)."""

    def __init__(self, views: dict[str, np.ndarray], rules: dict[str, ParamRule]) -> None:
        self._watched = [(key, view, view.copy(), rules.get(key)) for key, view in views.items()]
        # A memoryview comparison costs a tenth of np.array_equal on the usual one-number parameter.
        self._fast = [(memoryview(view), memoryview(last)) for _, view, last, _ in self._watched]

    def check(self) -> None:
        for index, (now, before) in enumerate(self._fast):
            if now != before:
                key, view, last, rule = self._watched[index]
                check(key, view, rule)
                np.copyto(last, view)
