"""Write the registry's catalogue of SOFA's components from a SOFA source checkout.

    python scripts/sofa_components.py /path/to/sofa            # rewrite compiler/registry/sofa_catalog.json
    python scripts/sofa_components.py /path/to/sofa --check    # exit 1 if the catalogue is out of date

Reads every class SOFA's object factory registers (``ObjectRegistrationData(...).add<...>()`` and
the older ``RegisterObject(...)``) in the core (``Sofa/``) and in the plugins of SOFA's own
repository (``applications/``), leaving out tests and examples. For each class it records the
CMake project that builds it (what ``RequiredPlugin`` names), the factory's description, its
templates (SOFA's template names, default first), the factory aliases, the role its base classes
give it, and its Data and links with their C++ types, defaults and Data aliases, inherited ones
included. The C++ is read with regular expressions, not compiled: a default is the expression
written in the constructor, and a type is the one spelled in the header.

The output is plain data, loaded lazily by ``compiler/registry`` for names its hand-written specs
do not describe; refresh it for a new SOFA version by running this script again.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUTPUT = REPO / "compiler" / "registry" / "sofa_catalog.json"

# Roles by SOFA base class, nearest base first: the registry's Category values.
_ROLES: dict[str, str] = {
    "BaseMechanicalState": "state",
    "MechanicalState": "state",
    "Mass": "mass",
    "BaseMass": "mass",
    "PairInteractionForceField": "interaction_forcefield",
    "MixedInteractionForceField": "interaction_forcefield",
    "BaseInteractionForceField": "interaction_forcefield",
    "ForceField": "forcefield",
    "BaseForceField": "forcefield",
    "ProjectiveConstraintSet": "projective_constraint",
    "BaseProjectiveConstraintSet": "projective_constraint",
    "PairInteractionProjectiveConstraintSet": "projective_constraint",
    "BaseLagrangianConstraint": "lagrangian_constraint",
    "LagrangianConstraint": "lagrangian_constraint",
    "PairInteractionConstraint": "lagrangian_constraint",
    "MixedInteractionConstraint": "lagrangian_constraint",
    "BaseConstraintSet": "lagrangian_constraint",
    "ConstraintSolver": "constraint_solver",
    "BaseConstraintCorrection": "constraint_correction",
    "OdeSolver": "ode_solver",
    "BaseOrderingMethod": "ordering",
    "BaseMatrixLinearSystem": "linear_system",
    "BaseLinearSystem": "linear_system",
    "LinearSolver": "linear_solver",
    "BaseLinearSolver": "linear_solver",
    "TopologicalMapping": "topological_mapping",
    "BaseMultiMapping": "multi_mapping",
    "MultiMapping": "multi_mapping",
    "Multi2Mapping": "multi_mapping",
    "BaseMapping": "mapping",
    "Mapping": "mapping",
    "TopologyModifier": "topology_helper",
    "GeometryAlgorithms": "topology_helper",
    "TopologyAlgorithms": "topology_helper",
    "BaseTopology": "topology",
    "BaseMeshTopology": "topology",
    "TopologyContainer": "topology",
    "BaseLoader": "loader",
    "DataEngine": "engine",
    "CollisionModel": "collision_model",
    "Pipeline": "collision_pipeline",
    "CollisionAlgorithm": "collision_pipeline",
    "Intersection": "collision_pipeline",
    "BaseIntersector": "collision_pipeline",
    "ContactManager": "collision_pipeline",
    "BroadPhaseDetection": "collision_pipeline",
    "NarrowPhaseDetection": "collision_pipeline",
    "VisualModel": "visual",
    "BaseAnimationLoop": "animation_loop",
    "ContextObject": "context",
    "VisualManager": "rendering",
    "BaseCamera": "rendering",
    "Light": "rendering",
    "BaseVisualStyle": "rendering",
    "Shader": "rendering",
    "OglShaderElement": "rendering",
}
# Where the walk up the class hierarchy stops (their Data are the registry's BASE_FIELDS).
_ROOTS = frozenset({"BaseObject", "Base", "BaseContext", "BaseNode"})
# SOFA's C++ DataTypes names, as the factory names the templates (DataTypeInfo::name()).
_TYPE_NAMES = {"SReal": "d", "double": "d", "float": "f"}
_SKIPPED_PARTS = frozenset({"test", "tests", "examples", "extlibs", "doc", "Tutorials"})
_SKIPPED_SUFFIXES = ("_test", "_tests", ".tests")
_DEFAULT_LENGTH = 80
# Data and links every SOFA object has (Base, BaseObject): the registry's BASE_FIELDS.
_COMMON_DATA = frozenset(
    {"name", "printLog", "tags", "bbox", "componentState", "listening", "context", "slaves", "master"}
)


@dataclass
class Registration:
    name: str
    module: str
    doc: str
    templates: list[str] = field(default_factory=list)
    default_template: str | None = None
    aliases: list[str] = field(default_factory=list)


@dataclass
class ClassInfo:
    bases: list[str] = field(default_factory=list)
    types: dict[str, str] = field(default_factory=dict)  # member -> C++ type of its Data
    # (member, SOFA name, default or None, is a link), in constructor order
    data: list[tuple[str, str, str | None, bool]] = field(default_factory=list)
    aliases: dict[str, list[str]] = field(default_factory=dict)  # member -> Data aliases


# --- lexing helpers ---------------------------------------------------------------------------
_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)
_STRING = re.compile(r'"(?:\\.|[^"\\])*"', re.S)


def strip_comments(text: str) -> str:
    """Drop C++ comments, keeping string literals (which may hold '//')."""
    out: list[str] = []
    position = 0
    for match in re.finditer(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\])\'', text, re.S):
        out.append(text[position : match.start()])
        token = match.group()
        out.append(token if token[0] in "\"'" else " ")
        position = match.end()
    out.append(text[position:])
    return "".join(out)


def balanced(text: str, start: int, open_: str, close: str) -> int:
    """Index just past the bracket closing the one at ``start`` (strings skipped)."""
    depth = 0
    index = start
    while index < len(text):
        char = text[index]
        if char == '"':
            end = _STRING.match(text, index)
            index = end.end() if end else index + 1
            continue
        if char == open_:
            depth += 1
        elif char == close:
            depth -= 1
            if depth == 0:
                return index + 1
        index += 1
    return len(text)


def split_args(text: str) -> list[str]:
    """Top-level comma-separated parts of an argument list (brackets and strings respected)."""
    parts, depth, current, index = [], 0, [], 0
    while index < len(text):
        char = text[index]
        if char == '"':
            end = _STRING.match(text, index)
            stop = end.end() if end else index + 1
            current.append(text[index:stop])
            index = stop
            continue
        if char in "(<{[":
            depth += 1
        elif char in ")>}]":
            depth -= 1
        if char == "," and depth == 0:
            parts.append("".join(current).strip())
            current = []
        else:
            current.append(char)
        index += 1
    if "".join(current).strip():
        parts.append("".join(current).strip())
    return parts


def literal(text: str) -> str | None:
    """The value of a (possibly concatenated) C string literal, or None if ``text`` is not one."""
    pieces = _STRING.findall(text)
    if not pieces or _STRING.sub("", text).strip():
        return None
    return "".join(p[1:-1] for p in pieces).replace('\\"', '"').replace("\\\n", "").replace("\\n", " ")


def unqualified(name: str) -> str:
    return name.strip().split("::")[-1].strip()


# --- templates --------------------------------------------------------------------------------
def template_name(argument: str) -> str:
    """SOFA's name for one C++ template argument (``Vec3Types`` -> ``Vec3d``)."""
    argument = re.sub(r"\s+", "", argument)
    head, _, inner = argument.partition("<")
    head = unqualified(head)
    if inner:
        inner_args = split_args(inner[:-1])
        if head in ("CompressedRowSparseMatrix", "FullMatrix", "SparseMatrix", "DiagonalMatrix"):
            element = inner_args[0] if inner_args else "SReal"
            block = re.fullmatch(r"(?:\w+::)*Mat<(\d+),(\d+),(\w+)>", element)
            if block:
                return f"{head}Mat{block[1]}x{block[2]}{_TYPE_NAMES.get(block[3], block[3])}"
            return f"{head}{_TYPE_NAMES.get(unqualified(element), unqualified(element))}"
        return head
    match = re.fullmatch(r"(Cuda|OpenCL)?(Vec|Rigid)(\d)([df]?)(\d?)Types", head)
    if match:
        prefix, kind, dim, real, extra = match.groups()
        if prefix and not real:
            real = "f"
        return f"{prefix or ''}{kind}{dim}{real or 'd'}{extra}"
    return head[: -len("Types")] if head.endswith("Types") and len(head) > 5 else head


# What a template part SOFA names looks like; a class with any other part (a C++ scalar type, a
# typedef the regular expressions cannot follow) gets no template list, so none is checked.
_NAMED_PART = re.compile(
    r"(Cuda|OpenCL)?(Vec|Rigid)\d[df]\d?|Image[A-Z]+|\w*Matrix\w*|Rigid3f?Mass"
    r"|Edge|Triangle|Quad|Tetrahedron|Hexahedron|Prism|Pyramid"
)


def registered_template(arguments: list[str]) -> str:
    """The factory's template name of one ``add<Class<args>>``: a linear solver names its matrix."""
    names = [template_name(a) for a in arguments]
    if len(names) == 2 and re.search(r"Matrix|GraphScattered", names[0]) and "Vector" in names[1]:
        return names[0]
    return ",".join(names)


# --- scanning ---------------------------------------------------------------------------------
def source_files(root: Path, suffixes: tuple[str, ...]) -> Iterator[Path]:
    for top in ("Sofa", "applications"):
        for path in sorted((root / top).rglob("*")):
            parts = path.relative_to(root).parts
            if path.suffix in suffixes and not any(
                p in _SKIPPED_PARTS or p.endswith(_SKIPPED_SUFFIXES) for p in parts
            ):
                yield path


def module_of(path: Path, root: Path, cache: dict[Path, str]) -> str:
    """The CMake project the file is built in (the module or plugin ``RequiredPlugin`` names)."""
    for folder in path.parents:
        if folder in cache:
            return cache[folder]
        cmake = folder / "CMakeLists.txt"
        if cmake.is_file():
            match = re.search(
                r"^\s*project\s*\(\s*([\w.\-]+)", cmake.read_text(errors="replace"), re.M | re.I
            )
            if match:
                cache[folder] = match.group(1)
                return match.group(1)
        if folder == root:
            break
    return ""


_REGISTER = re.compile(r"\b(?:ObjectRegistrationData|RegisterObject)\s*\(")


def registrations(text: str, module: str) -> Iterator[Registration]:
    for match in _REGISTER.finditer(text):
        close = balanced(text, match.end() - 1, "(", ")")
        doc = literal(text[match.end() : close - 1]) or ""
        chain_end = text.find(";", close)
        chain = text[close:chain_end]
        found: Registration | None = None
        pending_aliases: list[str] = []
        for call in re.finditer(r"\.\s*(add|addAlias)\s*(<|\()", chain):
            if call.group(1) == "addAlias":
                stop = balanced(chain, call.end() - 1, "(", ")")
                alias = literal(chain[call.end() : stop - 1])
                if alias:
                    pending_aliases.append(alias)
                continue
            stop = balanced(chain, call.end() - 1, "<", ">")
            target = re.sub(r"\s+", " ", chain[call.end() : stop - 1]).strip()
            head, _, inner = target.partition("<")
            name = unqualified(head)
            arguments = split_args(inner.rsplit(">", 1)[0]) if inner else []
            is_default = bool(re.match(r"\s*\(\s*true\s*\)", chain[stop:]))
            if found is None:
                found = Registration(name, module, doc)
            elif found.name != name:  # one registration, several classes: not SOFA's usage
                continue
            if arguments:
                template = registered_template(arguments)
                if template not in found.templates:
                    found.templates.append(template)
                if is_default:
                    found.default_template = template
        if found is not None:
            found.aliases.extend(pending_aliases)
            yield found


_CLASS = re.compile(
    r"\b(?:class|struct)\s+(?:SOFA_\w+\s+|alignas\([^)]*\)\s+)*(\w+)\s*(?:<[^;{}()]*>\s*)?(?:final\s*)?(:[^;{]*)?\{"
)
# Template aliases (``using LinearMapping = CRTPLinearMapping<Mapping<In, Out>>``): bases in disguise.
_USING = re.compile(r"\busing\s+(\w+)\s*=\s*([^;]+);")
_DATA = re.compile(r"\bData\s*<|\bDataFileName(?:Vector)?\b")
_CONSTRUCTOR = re.compile(r"\b(?!template\b)(\w+)\s*(?:<[^(){};]*>)?\s*::\s*(\w+)\s*\(")


def scan_classes(text: str, classes: dict[str, ClassInfo]) -> None:
    """Class declarations (bases, Data member types) and constructors (initData/initLink/addAlias)."""
    marks: list[tuple[int, str]] = []
    for match in _CLASS.finditer(text):
        name = match.group(1)
        info = classes.setdefault(name, ClassInfo())
        if match.group(2):
            for base in split_args(match.group(2)[1:]):
                base = re.sub(r"\b(public|protected|private|virtual)\b", "", base).strip()
                # The head, then classes in its arguments (CRTP and accessor bases derive from them).
                for part in (base.split("<")[0], *re.findall(r"([\w:]+)\s*<", base)[1:]):
                    part = unqualified(part)
                    if part and part not in info.bases and part != name:
                        info.bases.append(part)
        marks.append((match.start(), name))
    for match in _USING.finditer(text):
        info = classes.setdefault(match.group(1), ClassInfo())
        for base in re.findall(r"(\w+)\s*<", match.group(2)):
            if base not in info.bases and base != match.group(1):
                info.bases.append(base)
    for match in _CONSTRUCTOR.finditer(text):
        if match.group(1) == match.group(2):
            marks.append((match.start(), match.group(1)))
    marks.sort()

    def owner(position: int) -> str | None:
        best = None
        for start, name in marks:
            if start > position:
                break
            best = name
        return best

    for match in _DATA.finditer(text):
        if match.group().startswith("DataFileName"):
            stop, cpp_type = match.end(), match.group()
        else:
            stop = balanced(text, match.end() - 1, "<", ">")
            cpp_type = re.sub(r"\s+", " ", text[match.end() : stop - 1]).strip()
        declared = re.match(r"\s*((?:\w+\s*,\s*)*\w+)\s*;", text[stop:])
        name = owner(match.start())
        if not declared or name is None:
            continue
        for member in re.split(r"\s*,\s*", declared.group(1)):
            classes.setdefault(name, ClassInfo()).types.setdefault(member, cpp_type)
    for match in re.finditer(r"\b(initData|initLink)\s*\(", text):
        stop = balanced(text, match.end() - 1, "(", ")")
        args = split_args(text[match.end() : stop - 1])
        name = owner(match.start())
        if name is None or not args:
            continue
        member_match = re.search(r"(\w+)\s*\)*\s*$", re.sub(r"^\s*&\s*", "", args[0]))
        before = text[max(0, match.start() - 200) : match.start()]
        member_of = re.search(r"(\w+)\s*[({]\s*$", before)
        if match.group(1) == "initLink":
            label = literal(args[0])
            member = member_of.group(1) if member_of else ""
            if label:
                classes.setdefault(name, ClassInfo()).data.append((member, label, None, True))
            continue
        if member_match is None:
            continue
        member = member_match.group(1)
        strings = [literal(a) for a in args[1:]]
        if (
            len(strings) >= 2
            and strings[0] is not None
            and strings[1] is not None
            and (len(strings) < 3 or strings[2] is None)
        ):
            label, default = strings[0], None
        elif len(strings) >= 3 and strings[1] is not None:
            label, default = strings[1], re.sub(r"\s+", " ", args[1]).strip()
        else:
            continue
        if label and re.fullmatch(r"[\w.]+", label):
            classes.setdefault(name, ClassInfo()).data.append((member, label, default, False))
    for match in re.finditer(r"\baddAlias\s*\(\s*&?\s*(?:this\s*->\s*)?(\w+)\s*,\s*(\"[^\"]*\")\s*\)", text):
        name = owner(match.start())
        alias = literal(match.group(2))
        if name is not None and alias:
            classes.setdefault(name, ClassInfo()).aliases.setdefault(match.group(1), []).append(alias)


def role_of(name: str, classes: dict[str, ClassInfo]) -> str:
    """The nearest SOFA base class with a role (breadth first, the class itself included)."""
    queue, seen = [name], set()
    while queue:
        current = queue.pop(0)
        if current in seen:
            continue
        seen.add(current)
        if current in _ROLES and current != name:
            return _ROLES[current]
        info = classes.get(current)
        if info:
            queue.extend(info.bases)
    return "utility"


def fields_of(name: str, classes: dict[str, ClassInfo]) -> list[tuple]:
    """Data and links of a class and its bases, base first: (name, C++ type, default, aliases)."""
    order: list[str] = []

    def visit(current: str, depth: int) -> None:
        if current in _ROOTS or current in order or depth > 40:
            return
        info = classes.get(current)
        if info is None:
            return
        for base in info.bases:
            visit(base, depth + 1)
        order.append(current)

    visit(name, 0)
    out: dict[str, tuple] = {}
    for current in order:
        info = classes[current]
        for member, label, default, is_link in info.data:
            if label in _COMMON_DATA:
                continue
            if is_link:
                cpp_type = "link"
            else:
                cpp_type = info.types.get(member) or next(
                    (classes[c].types[member] for c in reversed(order) if member in classes[c].types), "?"
                )
            if default is not None and len(default) > _DEFAULT_LENGTH:
                default = default[: _DEFAULT_LENGTH - 3] + "..."
            aliases = tuple(a for a in info.aliases.get(member, ()) if a != label)
            out[label] = (label, cpp_type, default, aliases)
    return list(out.values())


def collect(root: Path) -> dict[str, dict]:
    classes: dict[str, ClassInfo] = {}
    for path in source_files(root, (".h", ".inl", ".cpp")):
        scan_classes(strip_comments(path.read_text(errors="replace")), classes)
    found: dict[str, Registration] = {}
    modules: dict[Path, str] = {}
    for path in source_files(root, (".cpp",)):
        text = path.read_text(errors="replace")
        if not _REGISTER.search(text) or path.name == "ObjectFactory.cpp":
            continue
        module = module_of(path, root, modules)
        for registration in registrations(strip_comments(text), module):
            known = found.get(registration.name)
            if known is None:
                found[registration.name] = registration
                continue
            # A second library adding templates (SofaCUDA...): the core module stays the provider.
            if not known.module.startswith("Sofa.") and registration.module.startswith("Sofa."):
                known.module, known.doc = registration.module, registration.doc or known.doc
                if registration.default_template:
                    known.default_template = registration.default_template
            known.templates.extend(t for t in registration.templates if t not in known.templates)
            known.aliases.extend(a for a in registration.aliases if a not in known.aliases)
    catalogue: dict[str, dict] = {}
    for name in sorted(found):
        registration = found[name]
        templates = list(registration.templates)
        if not all(_NAMED_PART.fullmatch(p) for t in templates for p in t.split(",")):
            templates = []
        if registration.default_template in templates:
            templates.remove(registration.default_template)
            templates.insert(0, registration.default_template)
        catalogue[name] = {
            "module": registration.module,
            "role": role_of(name, classes),
            "doc": registration.doc.strip(),
            "templates": tuple(templates),
            "aliases": tuple(sorted(set(registration.aliases) - {name})),
            "fields": tuple(fields_of(name, classes)),
        }
    return catalogue


def render(catalogue: dict[str, dict], commit: str) -> str:
    """JSON, one component a line: {name: [module, role, description, templates (default first),
    factory aliases, fields as [name, C++ type, default expression or null, Data aliases...]]}."""
    lines = ["{", f'"sofa_commit": {json.dumps(commit)},', '"generated_by": "scripts/sofa_components.py",']
    lines.append('"components": {')
    entries = []
    for name, entry in catalogue.items():
        fields = [[n, t, d, *a] for n, t, d, a in entry["fields"]]
        value = [entry["module"], entry["role"], entry["doc"], entry["templates"], entry["aliases"], fields]
        entries.append(f"{json.dumps(name)}: {json.dumps(value, separators=(',', ':'))}")
    lines.append(",\n".join(entries))
    lines.append("}}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "sofa", type=Path, help="a SOFA source checkout (its root holds Sofa/ and applications/)"
    )
    parser.add_argument("--commit", default="", help="the checkout's commit (default: read from its .git)")
    parser.add_argument(
        "--check", action="store_true", help="only compare with the catalogue in the registry"
    )
    parser.add_argument("--output", type=Path, default=OUTPUT)
    args = parser.parse_args(argv)
    if not (args.sofa / "Sofa").is_dir():
        print(f"error: {args.sofa} is not a SOFA checkout (no Sofa/ folder)", file=sys.stderr)
        return 2
    commit = args.commit or _git_commit(args.sofa)
    text = render(collect(args.sofa), commit)
    if args.check:
        current = args.output.read_text() if args.output.is_file() else ""
        print("up to date" if current == text else f"{args.output} is out of date")
        return 0 if current == text else 1
    args.output.write_text(text)
    print(f"wrote {args.output} ({text.count(chr(10)) - 5} components)")
    return 0


def _git_commit(root: Path) -> str:
    import subprocess

    result = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True)
    return result.stdout.strip() if result.returncode == 0 else "unknown"


if __name__ == "__main__":
    sys.exit(main())
