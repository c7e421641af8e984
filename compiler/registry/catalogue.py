"""SOFA's own list of components (``sofa_catalog.json``, generated from SOFA's source by
``scripts/sofa_components.py``), turned into specs for the names the hand-written specs of
``components/`` do not describe.

Such a component is known, never "unknown": it is either rendering-only (a visual model, light,
shader...: accepted, no part in the step, drawn where ``sofac render`` knows its mesh) or reported
as supported by SOFA but not compiled by sofac yet (E222), naming its module. Its Data keep SOFA's
C++ types and default expressions; only its links are typed, so that the checker resolves them as
SOFA would. The catalogue is read on the first look-up the hand-written specs cannot answer, never
for a scene that only uses those.
"""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path
from typing import Any

from .fields import Link, LinkList, SofaData
from .spec import Category, ComponentSpec, FieldSpec

# Links SOFA's base classes resolve to a mechanical state or a topology (the rest name any object).
_LINK_TARGETS = {
    "mstate": "state",
    "input": "state",
    "output": "state",
    "input1": "state",  # Multi2Mapping's two kinds of input states
    "input2": "state",
    "object1": "state",
    "object2": "state",
    "topology": "topology",
}
# SOFA's defaults for links its base classes resolve when the scene does not write them.
_LINK_DEFAULTS = {
    Category.MAPPING: {"input": "@../", "output": "@./"},
    Category.TOPOLOGICAL_MAPPING: {"input": "@../", "output": "@./"},
    Category.INTERACTION_FORCEFIELD: {"object1": "@./", "object2": "@./"},
}
# Modules whose components only draw or drive the GUI: accepted and left out of the step.
_NO_PHYSICS_MODULES = ("Sofa.GL.Component.Shader", "Sofa.GL.Component.Rendering2D", "Sofa.GUI.Component")


_FILE = Path(__file__).with_name("sofa_catalog.json")


@cache
def _load() -> dict[str, Any]:
    return json.loads(_FILE.read_text(encoding="utf-8"))


@cache
def _catalogue() -> tuple[dict[str, list[Any]], dict[str, str]]:
    components = _load()["components"]
    aliases = {alias: name for name, entry in components.items() for alias in entry[4]}
    return components, aliases


def sofa_commit() -> str:
    """The SOFA commit the catalogue was read from."""
    return str(_load()["sofa_commit"])


def names() -> tuple[str, ...]:
    """Every class name and factory alias SOFA registers."""
    components, aliases = _catalogue()
    return (*components, *aliases)


def modules() -> frozenset[str]:
    """Every module and plugin providing components in SOFA's repository."""
    return frozenset(entry[0] for entry in _catalogue()[0].values() if entry[0])


def templates(name: str) -> tuple[str, ...]:
    """The templates SOFA's factory registers for class ``name`` (a hand-written spec lists only
    those sofac compiles)."""
    entry = _catalogue()[0].get(name)
    return tuple(entry[3]) if entry else ()


def resolve(name: str) -> tuple[ComponentSpec, bool] | None:
    """The spec of a class SOFA registers under ``name``, and whether ``name`` is a factory alias."""
    components, aliases = _catalogue()
    canonical = aliases.get(name, name)
    if canonical not in components:
        return None
    return spec(canonical), canonical != name


@cache
def spec(name: str) -> ComponentSpec:
    module, role, doc, templates, aliases, data = _catalogue()[0][name]
    category = Category(role)
    link_defaults = _LINK_DEFAULTS.get(category, {})
    # An alias SOFA gives several Data (BaseMapping's isMechanical) sets each of them.
    owners: dict[str, list[str]] = {}
    for field_name, _, _, *field_aliases in data:
        for alias in field_aliases:
            owners.setdefault(alias, []).append(field_name)
    fields = []
    for field_name, cpp_type, default, *field_aliases in data:
        if cpp_type == "link":
            default = link_defaults.get(field_name)
        if cpp_type == "link" and category is Category.MULTI_MAPPING and field_name.startswith("input"):
            field_type: Any = LinkList("state")  # a MultiMapping's inputs: several states
        elif cpp_type == "link" and field_name in _LINK_TARGETS:
            field_type = Link(_LINK_TARGETS[field_name])
        elif cpp_type == "link":  # single or multi-link: initLink does not say, so a list is read
            field_type = LinkList("object")
        else:
            field_type = SofaData(cpp_type)
        own = tuple(a for a in field_aliases if len(owners[a]) == 1)
        fields.append(FieldSpec(field_name, field_type, default, aliases=own))
    for alias, targets in owners.items():
        if len(targets) > 1 and alias not in {f.name for f in fields}:
            fields.append(FieldSpec(alias, SofaData(), doc=f"sets {', '.join(targets)}", sets=tuple(targets)))
    drawing = category in (Category.RENDERING, Category.VISUAL) or module.startswith(_NO_PHYSICS_MODULES)
    where = f"{'module' if module.startswith('Sofa.') else 'plugin'} {module}" if module else "its core"
    return ComponentSpec(
        name=name,
        category=category,
        doc=_first_sentence(doc),
        module=module,
        templates=tuple(templates),
        default_template=templates[0] if templates else None,
        fields=tuple(fields),
        aliases=tuple(aliases),
        supported=drawing,
        unsupported_reason=f"{name} is supported by SOFA ({where}), not compiled by sofac yet",
        from_sofa_source=True,
    )


def _first_sentence(text: str) -> str:
    match = re.match(r"(.+?\.)(\s|$)", text)
    return match.group(1) if match else text
