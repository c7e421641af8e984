"""The component registry: every SOFA component sofac knows, described once.

Component families live in ``registry/components/*.py``; each module defines a ``COMPONENTS``
tuple of :class:`ComponentSpec`. This package collects them and answers name look-ups (current
names, silent aliases, renamed and former names) for every later stage.
"""

from __future__ import annotations

import difflib
import enum
import importlib
import pkgutil
from dataclasses import dataclass
from functools import cache

from . import components as _components_pkg
from .datatypes import DATATYPES, DataType, canonical_datatype, split_template
from .fields import FieldType
from .spec import Category, ComponentSpec, Effect, FieldSpec

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
    "all_components",
    "canonical_datatype",
    "lookup",
    "node_spec",
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
    return dict(_tables()[0])


def lookup(name: str) -> Resolution | None:
    """Resolve a component name as SOFA's factory would (current name, alias, renamed, former)."""
    return _tables()[1].get(name)


def node_spec() -> ComponentSpec:
    return _tables()[0]["Node"]


def suggest(name: str, limit: int = 3) -> list[str]:
    """Closest known component names, SOFA-style fuzzy matching (ratio >= 0.6)."""
    candidates = [n for n, r in _tables()[1].items() if r.status is not NameStatus.FORMER and n != "Node"]
    lowered = {c.lower(): c for c in candidates}
    exact = lowered.get(name.lower())
    if exact:
        return [exact]
    matches = difflib.get_close_matches(name.lower(), list(lowered), n=limit, cutoff=0.6)
    return [lowered[m] for m in matches]
