"""SOFA's link paths (``@../dofs``, ``@/Liver/dofs``, ``@[-1].indices``, ``src="@loader"``).

The grammar and the look-up rules follow SOFA's ``BaseLink::ParseString`` and
``Node::findLinkDestClass`` as described in ``sofa-semantics.md`` section 2:

- the part after the last ``.`` that follows the last ``/`` is a Data name (``..`` and ``.`` are paths);
- ``@/a/b`` is absolute; ``@a/b``, ``@a`` relative; ``..`` parent, ``.`` current node;
- ``@[-k]`` is the component k places before the current one in its node, ``@[]`` itself;
- each segment names a child node first, then an object of the current node; the *first* segment of
  a plain relative path is also searched in the ancestors when the current node lacks it.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from sofac.front.model import Component, Node

_INDEX_FORM = re.compile(r"^\[(-?\d*)\]$")


@dataclass(frozen=True)
class LinkPath:
    """A parsed link: the object path and the optional Data name after it."""

    path: str
    data: str | None

    @property
    def absolute(self) -> bool:
        return self.path.startswith("/")


def is_link(text: str) -> bool:
    return text.lstrip().startswith("@")


def parse_link(text: str) -> LinkPath | None:
    """Split ``@path.data``; None if the text is not a link."""
    text = text.strip()
    if not text.startswith("@"):
        return None
    body = text[1:]
    last_slash = body.rfind("/")
    tail = body[last_slash + 1 :]
    if tail not in ("", ".", "..") and "." in tail:
        dot = body.rfind(".")
        if dot > last_slash:
            return LinkPath(body[:dot], body[dot + 1 :] or None)
    return LinkPath(body, None)


Target = Node | Component


def resolve(
    link: LinkPath,
    origin: Component | Node,
    *,
    search_up: bool = True,
    clamp_at_root: bool = False,
) -> Target | None:
    """The node or component a link path names, seen from ``origin``; None if nothing matches.
    With ``clamp_at_root``, ``..`` at the root stays at the root (SOFA's ``Node::getObject``)."""
    node = origin.node if isinstance(origin, Component) else origin
    path = link.path
    index = _INDEX_FORM.match(path)
    if index is not None:
        if not isinstance(origin, Component):
            return None
        offset = int(index.group(1) or 0)
        position = node.objects.index(origin) + offset
        return node.objects[position] if 0 <= position < len(node.objects) else None
    if path.startswith("/"):
        node = node.root
        search_up = False
    segments = [s for s in path.split("/") if s]
    if not segments:
        return node
    if segments[0] in (".", ".."):
        search_up = False
    current: Target = node
    for position, segment in enumerate(segments):
        if not isinstance(current, Node):
            return None  # components have no children that links can reach
        if segment == ".":
            continue
        if segment == "..":
            if current.parent is None:
                if clamp_at_root:
                    continue
                return None
            current = current.parent
            continue
        found = _find_in(current, segment)
        if found is None and position == 0 and search_up:
            for ancestor in current.ancestors():
                found = _find_in(ancestor, segment)
                if found is not None:
                    break
        if found is None:
            return None
        current = found
    return current


def _find_in(node: Node, name: str) -> Target | None:
    return node.child(name) or node.object(name)


def resolve_src(text: str, origin: Component) -> Component | None:
    """``src="@loader"``: SOFA's simpler look-up, with no search in the ancestors."""
    link = parse_link(text)
    if link is None or link.data is not None:
        return None
    # SOFA finds src objects with DAGNode::getObject(path), where '../' at the root stays there
    # (Demos/collisionMultiple.scn writes src="@../../../Loader-floor" two levels below the root).
    target = resolve(link, origin, search_up=False, clamp_at_root=True)
    return target if isinstance(target, Component) else None


def pick_in_node(
    node: Node, accept: Callable[[Component], bool], *, climb: bool
) -> tuple[Component | None, int]:
    """The component of ``node`` that ``accept`` chooses (and how many matched); with ``climb``
    the nearest ancestor's, as SOFA does for singletons such as the mechanical state."""
    for candidate_node in (node, *node.ancestors()) if climb else (node,):
        matches = [c for c in candidate_node.objects if accept(c)]
        if matches:
            return matches[0], len(matches)
    return None, 0
