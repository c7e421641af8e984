"""`sofac inspect`: the resolved scene tree, with templates, links and roles, as text or JSON."""

from __future__ import annotations

from typing import Any

from sofac.check.checker import CheckedComponent, CheckedScene
from sofac.front.model import Component, Node
from sofac.registry import Category

_PHYSICS = (
    Category.MASS,
    Category.FORCEFIELD,
    Category.INTERACTION_FORCEFIELD,
    Category.PROJECTIVE_CONSTRAINT,
)


def node_roles(checked: CheckedScene, node: Node) -> list[str]:
    """What a node is for: mechanical (an integrated state), mapped, visual, collision."""
    roles: list[str] = []
    categories = {checked.of(c).category for c in node.objects}
    for component in node.objects:
        if checked.of(component).category is Category.STATE:
            if checked.mapping_of(component) is not None:
                roles.append("mapped")
            elif checked.solver_of(node) is not None:
                roles.append("mechanical")
            else:
                roles.append("static")
    if Category.VISUAL in categories:
        roles.append("visual")
    if Category.COLLISION_MODEL in categories:
        roles.append("collision")
    return roles


def _component_role(checked: CheckedScene, item: CheckedComponent) -> str | None:
    if item.category is Category.MAPPING:
        output = item.links.get("output")
        if isinstance(output, Component) and checked.of(output).category is Category.VISUAL:
            return "visual mapping"
        return "mechanical mapping"
    if item.category is Category.STATE:
        mapping = checked.mapping_of(item.component)
        if mapping is not None:
            return f"mapped by {mapping.component.label!r}"
        solver = checked.solver_of(item.component.node)
        return f"integrated by {solver.component.label!r}" if solver else "static (no solver)"
    if item.category in _PHYSICS and item.state is not None:
        return f"acts on {item.state.label!r}"
    return None


def _component_dict(checked: CheckedScene, component: Component) -> dict[str, Any]:
    item = checked.of(component)
    spec = item.spec
    return {
        "type": component.type_name,
        "class": spec.name if spec else None,
        "name": component.label,
        "path": component.path,
        "file": component.loc.file,
        "line": component.loc.line,
        "category": spec.category.value if spec else None,
        "template": item.template,
        "supported": bool(spec and spec.supported),
        "size": item.size,
        "role": _component_role(checked, item),
        "links": {name: target.path for name, target in item.links.items()},
    }


def tree_as_dict(checked: CheckedScene) -> dict[str, Any]:
    def visit(node: Node) -> dict[str, Any]:
        return {
            "name": node.label,
            "path": node.path,
            "file": node.loc.file,
            "line": node.loc.line,
            "roles": node_roles(checked, node),
            "components": [_component_dict(checked, c) for c in node.objects],
            "children": [visit(child) for child in node.children],
        }

    return visit(checked.scene.root)


def format_tree(checked: CheckedScene) -> str:
    lines: list[str] = []

    def describe(entry: dict[str, Any]) -> str:
        text = entry["type"]
        if entry["class"] and entry["class"] != entry["type"]:
            text += f" (= {entry['class']})"
        text += f" {entry['name']!r}"
        if entry["template"]:
            text += f" <{entry['template']}>"
        if entry["size"] is not None:
            text += f" {entry['size']} DOFs"
        for name, path in entry["links"].items():
            text += f" {name}={path}"
        if entry["role"]:
            text += f"  [{entry['role']}]"
        if entry["class"] and not entry["supported"]:
            text += "  [UNSUPPORTED]"
        elif entry["class"] is None:
            text += "  [UNKNOWN]"
        return f"{text}  (line {entry['line']})"

    def visit(entry: dict[str, Any], prefix: str, last: bool, top: bool) -> None:
        roles = f"  [{', '.join(entry['roles'])}]" if entry["roles"] else ""
        head = f"Node {entry['name']!r}{roles}  (line {entry['line']})"
        if top:
            lines.append(head)
            inner = ""
        else:
            lines.append(f"{prefix}{'└── ' if last else '├── '}{head}")
            inner = prefix + ("    " if last else "│   ")
        items = [("c", c) for c in entry["components"]] + [("n", n) for n in entry["children"]]
        for position, (kind, item) in enumerate(items):
            is_last = position == len(items) - 1
            if kind == "c":
                lines.append(f"{inner}{'└── ' if is_last else '├── '}{describe(item)}")
            else:
                visit(item, inner, is_last, False)

    visit(tree_as_dict(checked), "", True, True)
    return "\n".join(lines)
