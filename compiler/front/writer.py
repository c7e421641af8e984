"""Write the scene model back to SOFA ``.scn`` XML.

The inverse of the parse stage: ``parse(write_scene(scene))`` gives the same tree (same node and
component tags, same attribute names, order and values). Within each node the components come
first, then the child nodes, each in stored order; this is how SOFA's XML loader expects a node to
read. The document is built with :mod:`lxml.etree`, which does all escaping (quotes, ``<``, ``&``,
newlines and tabs in values become character references), and is pretty-printed with four-space
indentation. Source locations and XML comments are not part of the model and are not written.

:func:`same_structure` compares two trees and lists their differences; tests use it to state the
round-trip property, and it is handy for comparing a Python-built scene with a ``.scn`` file.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from lxml import etree
from sofac.diagnostics import SofacError
from sofac.front.model import Component, Node, Scene, _Element

__all__ = ["WriteError", "same_structure", "save_scene", "to_element", "write_scene"]

XML_DECLARATION = '<?xml version="1.0"?>'
INDENT = "    "


class WriteError(SofacError, ValueError):
    """The model holds something XML cannot represent (bad tag/attribute name, control character)."""


def _root_of(scene_or_root: Scene | Node) -> Node:
    if isinstance(scene_or_root, Scene):
        return scene_or_root.root
    if isinstance(scene_or_root, Node):
        return scene_or_root
    raise TypeError(f"expected a Scene or a Node, not {type(scene_or_root).__name__}")


def _describe(element: _Element) -> str:
    path = element.path if element.parent is not None or isinstance(element, Node) else element.tag
    return f"{element.tag} {path!r} ({element.loc})"


def _make_element(element: _Element, parent: etree._Element | None) -> etree._Element:
    """One XML element for a Node or Component, with its attributes in stored order."""
    if element.tag.startswith("{"):
        # lxml would read "{uri}name" as a namespaced name; SOFA tags never are.
        raise WriteError(f"cannot write {_describe(element)}: invalid tag name {element.tag!r}")
    try:
        xml = etree.Element(element.tag) if parent is None else etree.SubElement(parent, element.tag)
    except ValueError as error:
        raise WriteError(f"cannot write {_describe(element)}: {error}") from None
    for attribute in element.attributes.values():
        if attribute.name.startswith("{"):
            # lxml would read "{uri}name" as a namespaced name; SOFA attributes never are.
            raise WriteError(f"cannot write {_describe(element)}: invalid attribute name {attribute.name!r}")
        try:
            xml.set(attribute.name, attribute.value)
        except (ValueError, TypeError) as error:
            raise WriteError(
                f"cannot write attribute {attribute.name!r} of {_describe(element)}: {error}"
            ) from None
    return xml


def to_element(scene_or_root: Scene | Node) -> etree._Element:
    """The lxml element tree of a scene (not indented). Built iteratively: deep trees are fine."""
    root = _root_of(scene_or_root)
    xml_root = _make_element(root, None)
    stack: list[tuple[Node, etree._Element]] = [(root, xml_root)]
    while stack:
        node, xml = stack.pop()
        for component in node.objects:
            _make_element(component, xml)
        pending = [(child, _make_element(child, xml)) for child in node.children]
        stack.extend(reversed(pending))
    return xml_root


def write_scene(scene_or_root: Scene | Node) -> str:
    """The ``.scn`` text of a scene (or of the tree under a node), ending with a newline."""
    xml_root = to_element(scene_or_root)
    etree.indent(xml_root, space=INDENT)
    body = etree.tostring(xml_root, encoding="unicode")
    return f"{XML_DECLARATION}\n{body}\n"


def save_scene(scene_or_root: Scene | Node, path: str | os.PathLike[str]) -> Path:
    """Write the scene to ``path`` as UTF-8 (the XML default encoding); returns the path."""
    text = write_scene(scene_or_root)
    target = Path(path)
    target.write_text(text, encoding="utf-8", newline="\n")
    return target


# --- structural comparison ------------------------------------------------------------------


def _numbers(text: str) -> list[float] | None:
    """The whitespace-separated numbers of a value, or None if some token is not a number."""
    tokens = text.split()
    try:
        return [float(token) for token in tokens]
    except ValueError:
        return None


def _same_value(a: str, b: str, numeric: bool) -> bool:
    if a == b:
        return True
    if not numeric:
        return False
    xs, ys = _numbers(a), _numbers(b)
    if xs is None or ys is None or len(xs) != len(ys) or not xs:
        return False
    return all(
        x == y or (math.isnan(x) and math.isnan(y)) or math.isclose(x, y) for x, y in zip(xs, ys, strict=True)
    )


def _compare_element(a: _Element, b: _Element, where: str, numeric: bool, order: bool) -> list[str]:
    differences: list[str] = []
    if a.tag != b.tag:
        differences.append(f"{where}: tag {a.tag!r} != {b.tag!r}")
    names_a, names_b = list(a.attributes), list(b.attributes)
    only_a = [n for n in names_a if n not in b.attributes]
    only_b = [n for n in names_b if n not in a.attributes]
    if only_a:
        differences.append(f"{where}: attributes only in the first: {', '.join(only_a)}")
    if only_b:
        differences.append(f"{where}: attributes only in the second: {', '.join(only_b)}")
    for name in names_a:
        if name in b.attributes:
            va, vb = a.attributes[name].value, b.attributes[name].value
            if not _same_value(va, vb, numeric):
                differences.append(f"{where}: attribute {name!r}: {va!r} != {vb!r}")
    if order and not only_a and not only_b and names_a != names_b:
        differences.append(f"{where}: attribute order {names_a} != {names_b}")
    return differences


def same_structure(
    a: Scene | Node, b: Scene | Node, *, numeric: bool = False, attribute_order: bool = True
) -> list[str]:
    """The differences between two scene trees; an empty list means they are the same.

    Compared: tree shape, node and component tags, attribute names and values, and (unless
    ``attribute_order`` is false) attribute order. Values are compared as text, or with
    ``numeric=True`` as lists of numbers when both parse as such (so ``1e-5`` equals ``0.00001``).
    Source locations are ignored. Iterative, so deep trees are fine.
    """
    differences: list[str] = []
    stack: list[tuple[Node, Node]] = [(_root_of(a), _root_of(b))]
    while stack:
        node_a, node_b = stack.pop()
        where = node_a.path
        differences += _compare_element(node_a, node_b, f"node {where}", numeric, attribute_order)
        if len(node_a.objects) != len(node_b.objects):
            differences.append(
                f"node {where}: {len(node_a.objects)} components != {len(node_b.objects)}: "
                f"{[c.tag for c in node_a.objects]} vs {[c.tag for c in node_b.objects]}"
            )
        for index, (comp_a, comp_b) in enumerate(zip(node_a.objects, node_b.objects, strict=False)):
            differences += _compare_element(
                comp_a, comp_b, f"component #{index} {_label(comp_a)} in {where}", numeric, attribute_order
            )
        if len(node_a.children) != len(node_b.children):
            differences.append(
                f"node {where}: {len(node_a.children)} child nodes != {len(node_b.children)}: "
                f"{[c.label for c in node_a.children]} vs {[c.label for c in node_b.children]}"
            )
        stack.extend(reversed(list(zip(node_a.children, node_b.children, strict=False))))
    return differences


def _label(component: Component) -> str:
    return f"{component.tag} {component.name!r}" if component.name else component.tag
