"""Parse stage: ``.scn``/``.xml`` scene text -> :class:`~sofac.front.model.Scene`.

Reads files safely (size cap, no DTD/entities, depth cap; see :mod:`sofac.front.xmlsafe`), accepts the
not-well-formed XML SOFA accepts (with W105 warnings), and expands ``<include>`` and unknown-tag
macros (``Objects/<Tag>.xml``) exactly as SOFA's XML loader does. Every element and attribute of
the model carries the file and line where it is written.

Fatal problems of the top file raise :class:`SceneError` at once; problems in included files are
all collected first, then :class:`SceneError` is raised if any of them is an error.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sofac.diagnostics import Diagnostics, SceneError, SourceLoc, relative_name
from sofac.front.datafiles import (
    DataFileLookup,
    default_data_roots,
    find_data_file,
    is_file,
    real_path,
    resolve_data_file,
)
from sofac.front.model import Attribute, Component, Node, Scene, _Element
from sofac.front.xmlsafe import MAX_DEPTH, XMLDocument, XMLReadError, attribute_name, read_xml, tag_name
from sofac.registry import NameStatus, lookup

__all__ = [
    "DEFAULT_MAX_BYTES",
    "MAX_DEPTH",
    "MAX_INCLUDE_DEPTH",
    "DataFileLookup",
    "default_data_roots",
    "find_data_file",
    "parse_scene",
    "parse_string",
    "resolve_data_file",
]

#: Largest scene or include file read (bigger ones are refused with E103).
DEFAULT_MAX_BYTES = 64 * 1024 * 1024
#: Deepest chain of includes/macros (cycles are caught separately, E107).
MAX_INCLUDE_DEPTH = 16

# Element names the loader handles itself; anything else is a component (or a macro).
_STRUCTURAL = frozenset({"Node", "Object", "include", "Attribute", "Data"})
# Macro file names are built from tag/type names: keep them plain identifiers (no paths).
_MACRO_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_GROUP_NAMES = frozenset({"Group", "_Group_"})
_MERGE_NAME = "_Merge_"


# --- reading files -------------------------------------------------------------------------------


class _TooLarge(Exception):
    pass


def _read_capped(path: Path, max_bytes: int) -> bytes:
    """The file's bytes, refusing non-regular files (FIFOs, devices) and more than ``max_bytes``."""
    with open(path, "rb") as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise IsADirectoryError(0, "not a regular file")
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise _TooLarge
    return data


@dataclass
class _File:
    """One parsed file: how it is named in diagnostics, where relative paths start, its tree."""

    display: str
    real: Path | None
    directory: Path
    doc: XMLDocument

    def loc(self, element: Any) -> SourceLoc:
        return SourceLoc(self.display, self.doc.line_of(element))

    def attributes(self, element: Any) -> list[Attribute]:
        out: list[Attribute] = []
        for key, value in element.attrib.items():
            name = attribute_name(key, element)
            loc = SourceLoc(self.display, self.doc.attribute_line(element, name), name)
            out.append(Attribute(name, value, loc))
        return out


def _subtree(element: _Element) -> Iterator[_Element]:
    """An element and everything below it (nodes and components), in document-like order."""
    if isinstance(element, Node):
        for node in element.walk():
            yield node
            yield from node.objects
    else:
        yield element


class _Builder:
    def __init__(self, scene: Scene, diagnostics: Diagnostics, max_bytes: int) -> None:
        self.scene = scene
        self.diags = diagnostics
        self.max_bytes = max_bytes
        self.failed = False
        # Files being expanded (real path, where it was pulled in from), to detect cycles.
        self.stack: list[tuple[Path | None, SourceLoc]] = []
        self.macro_files: dict[tuple[Path, str], DataFileLookup] = {}

    # --- reporting ---
    def error(self, code: str, loc: SourceLoc, message: str, hint: str = "") -> None:
        self.diags.add(code, loc, message, hint)
        self.failed = True

    def warn(self, code: str, loc: SourceLoc, message: str, hint: str = "") -> None:
        self.diags.add(code, loc, message, hint)

    # --- files ---
    def load_bytes(
        self, data: bytes | str, display: str, real: Path | None, directory: Path, *, from_disk: bool = True
    ) -> _File | None:
        try:
            doc = read_xml(data)
        except XMLReadError as exc:
            self.error(exc.code, SourceLoc(display, exc.line), exc.message, exc.hint)
            return None
        for repair in doc.repairs:
            self.warn(
                "W105",
                SourceLoc(display, repair.line),
                f"not well-formed XML: {repair.what}",
                "SOFA's parser accepts this, other XML tools do not; make it well-formed "
                "(&lt; for '<', &amp; for '&', a space between attributes)",
            )
        if from_disk and real is not None and real not in self.scene.sources:
            self.scene.sources.append(real)
        return _File(display, real, directory, doc)

    def load_path(
        self, path: Path, display: str, at: SourceLoc, directory: Path | None = None
    ) -> _File | None:
        try:
            data = _read_capped(path, self.max_bytes)
        except _TooLarge:
            self.error(
                "E103",
                at,
                f"{display} is larger than {self.max_bytes} bytes; refused",
                "move large arrays into mesh files, or raise the limit if the file is trusted",
            )
            return None
        except (OSError, ValueError) as exc:
            reason = getattr(exc, "strerror", None) or str(exc)
            self.error("E100", at, f"cannot read {display}: {reason}")
            return None
        real = real_path(path)
        return self.load_bytes(data, display, real, directory or real.parent)

    # --- elements ---
    def build_root(self, f: _File) -> Node:
        root_el = f.doc.root
        name = tag_name(root_el)
        if name != "Node":
            self.error(
                "E112",
                f.loc(root_el),
                f"the root element is <{name}>; a scene's root element must be <Node>",
                'wrap the scene in <Node name="root"> ... </Node>',
            )
            raise SceneError(self.diags)
        return self.build_node(root_el, f, 1)

    def build_node(self, el: Any, f: _File, depth: int) -> Node:
        node = Node("", f.loc(el))
        for attribute in f.attributes(el):
            node.attributes[attribute.name] = attribute
        for child in el:
            self.build_child(child, node, f, depth + 1)
        return node

    def build_child(self, el: Any, parent: Node, f: _File, depth: int) -> None:
        if not isinstance(el.tag, str):
            return
        loc = f.loc(el)
        if depth > MAX_DEPTH:
            self.error("E104", loc, f"elements nested more than {MAX_DEPTH} levels deep (after includes)")
            return
        tag = tag_name(el)
        if tag == "Node":
            parent.add_node(self.build_node(el, f, depth))
            return
        if tag == "include":
            attributes = f.attributes(el)
            href = next((a for a in attributes if a.name == "href"), None)
            self.ignore_children(el, f, "<include>")
            if href is None or not href.value.strip():
                self.error(
                    "E109", loc, "<include> without an href attribute", 'write <include href="file.xml"/>'
                )
                return
            overrides = [a for a in attributes if a.name != "href"]
            self.include(href.value.strip(), href.loc, overrides, parent, f, depth, macro=None)
            return
        if tag == "Attribute":
            self.attribute_element(el, parent, f)
            return
        if tag == "Data":
            self.warn("W111", loc, "<Data> outside an <Attribute> element is ignored (SOFA cannot use it)")
            return
        attributes = f.attributes(el)
        type_name = tag
        if tag == "Object":
            # Legacy spelling: <Object type="X" .../> is <X .../>.
            type_attr = next((a for a in attributes if a.name == "type"), None)
            if type_attr is None or not type_attr.value.strip():
                self.error(
                    "E109", loc, "<Object> without a type attribute", 'write <Object type="ClassName" .../>'
                )
                return
            type_name = type_attr.value.strip()
            attributes = [a for a in attributes if a.name != "type"]
        if self.is_macro_candidate(type_name):
            key = (f.directory, type_name)
            found = self.macro_files.get(key)
            if found is None:
                found = self.macro_files[key] = find_data_file(
                    f"Objects/{type_name}.xml", f.directory, self.scene
                )
            if found.path is not None or found.refused:
                self.ignore_children(el, f, f"<{tag}> (a macro)")
                # As in SOFA, the element's attributes become the include's (its href is replaced).
                overrides = [a for a in attributes if a.name != "href"]
                self.include(f"Objects/{type_name}.xml", loc, overrides, parent, f, depth, macro=type_name)
                return
        component = Component(type_name, loc)
        for attribute in attributes:
            component.attributes[attribute.name] = attribute
        for child in el:
            if not isinstance(child.tag, str):
                continue
            if tag_name(child) == "Attribute":
                self.attribute_element(child, component, f)
            else:
                self.warn(
                    "W111",
                    f.loc(child),
                    f"<{tag_name(child)}> inside component <{type_name}> is ignored (SOFA ignores it too)",
                    "components cannot contain other elements; move it into a <Node>",
                )
        parent.add_component(component)

    def ignore_children(self, el: Any, f: _File, what: str) -> None:
        for child in el:
            if isinstance(child.tag, str):
                self.warn(
                    "W111",
                    f.loc(child),
                    f"<{tag_name(child)}> inside {what} is ignored (SOFA ignores it too)",
                )

    def attribute_element(self, el: Any, target: _Element, f: _File) -> None:
        """``<Attribute type="data"><Data value="v"/></Attribute>`` sets ``data="v"`` on the parent."""
        loc = f.loc(el)
        data_name = (el.get("type") or "").strip()
        if not data_name:
            self.error("E109", loc, "<Attribute> without a type attribute naming the data to set")
            return
        value, value_loc = "", loc.with_attribute(data_name)
        for child in el:
            if not isinstance(child.tag, str):
                continue
            if tag_name(child) == "Data":
                # As in SOFA, the last <Data> wins and a missing value means "".
                value = child.get("value", "")
                line = (
                    f.doc.attribute_line(child, "value") if "value" in child.attrib else f.doc.line_of(child)
                )
                value_loc = SourceLoc(f.display, line, data_name)
            else:
                self.warn("W111", f.loc(child), f"<{tag_name(child)}> inside <Attribute> is ignored")
        target.attributes[data_name] = Attribute(data_name, value, value_loc)

    def is_macro_candidate(self, type_name: str) -> bool:
        if type_name in _STRUCTURAL or not _MACRO_NAME_RE.match(type_name):
            return False
        resolution = lookup(type_name)
        # SOFA's factory has no creator for names it no longer accepts, so those may be macros too.
        return resolution is None or resolution.status is NameStatus.FORMER

    # --- includes and macros ---
    def include(
        self,
        href: str,
        at: SourceLoc,
        overrides: list[Attribute],
        parent: Node,
        f: _File,
        depth: int,
        macro: str | None,
    ) -> None:
        what = f"macro <{macro}> ({href})" if macro else f"include {href!r}"
        found = find_data_file(href, f.directory, self.scene)
        if found.path is None:
            if found.refused:
                self.error(
                    "E108",
                    at,
                    f"{what} resolves outside the allowed data roots "
                    f"({', '.join(str(r) for r in self.scene.data_roots)}); refused",
                    "keep included files under the scene's folder or a data root "
                    "(--data-path, SOFAC_DATA_PATH)",
                )
            else:
                searched = ", ".join(str(d) for d in found.searched)
                self.error(
                    "E106",
                    at,
                    f"{what}: file not found (searched {searched})",
                    "fix the href, or add the folder holding it with --data-path / SOFAC_DATA_PATH",
                )
            return
        path = found.path
        display = relative_name(path)
        for index, (real, where) in enumerate(self.stack):
            if real == path:
                origin = (
                    f"it is the scene file being read ({where.file})"
                    if index == 0
                    else f"included at {where}"
                )
                self.error(
                    "E107",
                    at,
                    f"include cycle: {what} pulls in {display} again, which is already being read: {origin}",
                    "remove one of the two includes",
                )
                return
        if len(self.stack) > MAX_INCLUDE_DEPTH:
            self.error("E104", at, f"{what}: includes nested more than {MAX_INCLUDE_DEPTH} levels deep")
            return
        sub = self.load_path(path, display, at)
        if sub is None:
            return
        holder = Node("", at)
        self.stack.append((path, at))
        try:
            self.build_child(sub.doc.root, holder, sub, depth)
        finally:
            self.stack.pop()
        items: list[_Element] = [*holder.children, *holder.objects]
        if len(items) == 1 and not holder.attributes:
            result: _Element = items[0]
            result.parent = None
        else:
            # The included root was itself an include/macro that spliced several elements.
            result = holder
            result.attributes["name"] = Attribute("name", "Group", at.with_attribute("name"))
        mode = self.include_mode(result.name, "child")
        mode = self.apply_overrides(result, overrides, mode, display)
        self.place(result, mode, parent)

    @staticmethod
    def include_mode(name: str, current: str) -> str:
        # As SOFA: a special root name sets the mode, a later rename never resets it.
        if name in _GROUP_NAMES:
            return "group"
        if name == _MERGE_NAME:
            return "merge"
        return current

    def apply_overrides(self, result: _Element, overrides: list[Attribute], mode: str, display: str) -> str:
        """Attributes of ``<include>``: ``name`` renames the included root; any other replaces the
        attribute of that name wherever it is already present in the included tree, or only on
        elements named ``N`` for ``N__attr``. The value keeps the include's location."""
        elements = list(_subtree(result))
        # Names as loaded: SOFA matches ``N__`` before applying any replacement (except the rename).
        names = {id(e): e.name for e in elements}
        for override in overrides:
            if override.name == "name":
                result.attributes["name"] = Attribute("name", override.value, override.loc)
                names[id(result)] = override.value
                mode = self.include_mode(override.value, mode)
                continue
            node_name, sep, attr = override.name.partition("__")
            if not sep:
                attr = override.name
            hits = 0
            for element in elements:
                if sep and names[id(element)] != node_name:
                    continue
                if attr in element.attributes:
                    element.attributes[attr] = Attribute(
                        attr, override.value, override.loc.with_attribute(attr)
                    )
                    hits += 1
            if hits == 0:
                target = f"an element named {node_name!r} with" if sep else "any element with"
                self.warn(
                    "W110",
                    override.loc,
                    f"{override.name}={override.value!r} overrides nothing: {display} has not {target} "
                    f"an attribute {attr!r}",
                    "an include only replaces attributes already written in the included file",
                )
        return mode

    def place(self, result: _Element, mode: str, parent: Node) -> None:
        if mode == "group":
            # Splice the content; the group root's own attributes are dropped (as in SOFA).
            if isinstance(result, Node):
                for child in list(result.children):
                    parent.add_node(child)
                for obj in list(result.objects):
                    parent.add_component(obj)
            return
        if mode == "merge":
            self.merge(parent, result)
            return
        if isinstance(result, Node):
            parent.add_node(result)
        else:
            assert isinstance(result, Component)
            parent.add_component(result)

    def merge(self, dest: _Element, src: _Element) -> None:
        """SOFA's ``_Merge_``: copy attributes (except name), merge children matched by type and
        name, move the unmatched ones."""
        for name, attribute in src.attributes.items():
            if name != "name":
                dest.attributes[name] = attribute
        if not isinstance(src, Node) or not isinstance(dest, Node):
            return
        for child in list(src.children):
            match = next((c for c in dest.children if child.name and c.name == child.name), None)
            if match is not None:
                self.merge(match, child)
            else:
                dest.add_node(child)
        for obj in list(src.objects):
            same = (
                o for o in dest.objects if obj.name and o.name == obj.name and o.type_name == obj.type_name
            )
            match_obj = next(same, None)
            if match_obj is not None:
                self.merge(match_obj, obj)
            else:
                dest.add_component(obj)


# --- entry points --------------------------------------------------------------------------------


def _finish(builder: _Builder, f: _File, errors_before: int) -> Scene:
    builder.stack.append((f.real, SourceLoc(f.display, 0)))
    root = builder.build_root(f)
    builder.stack.pop()
    builder.scene.root = root
    if builder.failed or len(builder.diags.errors) > errors_before:
        raise SceneError(builder.diags)
    return builder.scene


def parse_scene(
    path: str | Path,
    diagnostics: Diagnostics,
    *,
    data_roots: Sequence[Path] = (),
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> Scene:
    """Read a scene file into the model, includes and macros expanded.

    Diagnostics name the file as given (``path`` is not made absolute); included files are named
    relative to the cwd when possible. Raises :class:`SceneError` if the scene cannot be read.
    A ``.py`` file is a SofaPython3 scene script: it is run (sofac.pyscene) to build the tree.
    """
    if Path(path).suffix.lower() == ".py":
        from sofac.pyscene.script import execute_script

        return execute_script(path, diagnostics, data_roots=data_roots, max_bytes=max_bytes)
    display = str(path)
    given = Path(path)
    errors_before = len(diagnostics.errors)
    scene_dir = Path(os.path.abspath(given)).parent
    scene = Scene(
        Node("", SourceLoc(display, 0)), file=given, data_roots=default_data_roots(scene_dir, data_roots)
    )
    builder = _Builder(scene, diagnostics, max_bytes)
    # Relative references start from the folder the user named (even if the file is a symlink).
    f = builder.load_path(given, display, SourceLoc(display, 0), directory=scene_dir)
    if f is None:
        raise SceneError(diagnostics)
    return _finish(builder, f, errors_before)


def parse_string(
    text: str | bytes,
    diagnostics: Diagnostics,
    *,
    filename: str = "<string>",
    data_roots: Sequence[Path] = (),
    base_dir: Path | None = None,
) -> Scene:
    """Read scene text. Includes resolve relative to ``base_dir`` (default: the cwd), which also
    serves as the scene directory for the data roots; ``filename`` names it in diagnostics."""
    directory = real_path(Path(base_dir) if base_dir is not None else Path.cwd())
    errors_before = len(diagnostics.errors)
    scene = Scene(
        Node("", SourceLoc(filename, 0)),
        file=Path(filename),
        data_roots=default_data_roots(directory, data_roots),
    )
    builder = _Builder(scene, diagnostics, DEFAULT_MAX_BYTES)
    size = len(text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text)
    if size > DEFAULT_MAX_BYTES:
        builder.error(
            "E103", SourceLoc(filename, 0), f"{filename} is larger than {DEFAULT_MAX_BYTES} bytes; refused"
        )
        raise SceneError(diagnostics)
    # A string that names a real file can still be part of a cycle; otherwise it has no path.
    candidate = directory / filename
    real = real_path(candidate) if not filename.startswith("<") and is_file(candidate) else None
    f = builder.load_bytes(text, filename, real, directory, from_disk=False)
    if f is None:
        raise SceneError(diagnostics)
    return _finish(builder, f, errors_before)
