"""The component registry: every SOFA component sofac knows, described once.

Component families live in ``registry/components/*.py``; each module defines a ``COMPONENTS``
tuple of :class:`ComponentSpec`. This package collects them and answers name look-ups (current
names, silent aliases, renamed and former names) for every later stage. Every other class SOFA's
factory registers comes from SOFA's own list (``catalogue.py``), read only when a name is not one
of these.
"""

from __future__ import annotations

import difflib
import enum
import importlib
import pkgutil
from dataclasses import dataclass
from functools import cache

from . import catalogue
from . import components as _components_pkg
from .datatypes import DATATYPES, DataType, canonical_datatype, split_template
from .fields import FieldType
from .spec import Category, ComponentSpec, Effect, FieldSpec, Variant

__all__ = [
    "DATATYPES",
    "Category",
    "ComponentSpec",
    "DataType",
    "Effect",
    "FieldSpec",
    "FieldType",
    "NameStatus",
    "Resolution",
    "Variant",
    "all_components",
    "canonical_datatype",
    "lookup",
    "node_spec",
    "provides_components",
    "sofa_has_template",
    "split_template",
    "suggest",
]


class NameStatus(enum.Enum):
    CURRENT = "current"
    ALIAS = "alias"  # SOFA maps it silently
    RENAMED = "renamed"  # SOFA maps it, with a warning
    FORMER = "former"  # SOFA no longer accepts it


@dataclass(frozen=True)
class Resolution:
    spec: ComponentSpec
    status: NameStatus


@cache
def _tables() -> tuple[dict[str, ComponentSpec], dict[str, Resolution]]:
    specs: dict[str, ComponentSpec] = {}
    for info in sorted(pkgutil.iter_modules(_components_pkg.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{_components_pkg.__name__}.{info.name}")
        for spec in getattr(module, "COMPONENTS", ()):
            if spec.name in specs:
                raise RuntimeError(f"component {spec.name} registered twice ({info.name})")
            specs[spec.name] = spec
    names: dict[str, Resolution] = {}
    for spec in specs.values():
        names[spec.name] = Resolution(spec, NameStatus.CURRENT)
    for spec in specs.values():
        for group, status in (
            (spec.aliases, NameStatus.ALIAS),
            (spec.renamed_from, NameStatus.RENAMED),
            (spec.former_names, NameStatus.FORMER),
        ):
            for alias in group:
                if alias in names:
                    raise RuntimeError(f"name {alias} is claimed by {names[alias].spec.name} and {spec.name}")
                names[alias] = Resolution(spec, status)
    return specs, names


def all_components() -> dict[str, ComponentSpec]:
    """Every registered component (including the scene-graph ``Node``), by canonical name."""
    specs = dict(_tables()[0])
    for name in catalogue.names():
        resolution = lookup(name)
        if resolution is not None:
            specs.setdefault(resolution.spec.name, resolution.spec)
    return specs


def lookup(name: str) -> Resolution | None:
    """Resolve a component name as SOFA's factory would (current name, alias, renamed, former)."""
    found = _tables()[1].get(name)
    if found is not None:
        return found
    from_sofa = catalogue.resolve(name)
    if from_sofa is None:
        return None
    spec, is_alias = from_sofa
    # A SOFA class whose name a hand-written spec claims (as an alias) is that spec's.
    claimed = _tables()[1].get(spec.name)
    if claimed is not None:
        return Resolution(claimed.spec, NameStatus.ALIAS if is_alias else claimed.status)
    return Resolution(spec, NameStatus.ALIAS if is_alias else NameStatus.CURRENT)


def sofa_has_template(spec: ComponentSpec, template: str) -> bool:
    """Does SOFA register ``spec``'s class for ``template`` (one sofac does not compile, then)?"""
    return template in catalogue.templates(spec.name)


def provides_components(plugin: str) -> bool:
    """Does a SOFA module or plugin (or a prefix of one: "Sofa.Component") provide known components?"""
    return plugin in _module_prefixes(False) or plugin in _module_prefixes(True)


@cache
def _module_prefixes(from_sofa: bool) -> frozenset[str]:
    modules = catalogue.modules() if from_sofa else {s.module for s in _tables()[0].values() if s.module}
    return frozenset(".".join(m.split(".")[:i]) for m in modules for i in range(1, m.count(".") + 2))


def node_spec() -> ComponentSpec:
    return _tables()[0]["Node"]


def suggest(name: str, limit: int = 3) -> list[str]:
    """Closest known component names, SOFA-style fuzzy matching (ratio >= 0.6)."""
    candidates = [n for n, r in _tables()[1].items() if r.status is not NameStatus.FORMER and n != "Node"]
    candidates += [n for n in catalogue.names() if n not in _tables()[1]]
    lowered = {c.lower(): c for c in candidates}
    exact = lowered.get(name.lower())
    if exact:
        return [exact]
    matches = difflib.get_close_matches(name.lower(), list(lowered), n=limit, cutoff=0.6)
    return [lowered[m] for m in matches]
