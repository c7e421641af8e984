"""Diagnostics: what sofac tells the user about a scene.

Every problem sofac finds is a :class:`Diagnostic` with a stable code, a severity, a source
location (file, line, and attribute where it applies), a message naming the objects involved and
a hint saying what to do. Codes are listed once, in :data:`CODES`; tests assert them exactly.

Code ranges: ``E1xx``/``W1xx`` reading files, ``E2xx``/``W2xx`` checking the scene,
``E3xx`` building, ``E4xx`` running.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path


class Severity(enum.IntEnum):
    INFO = 0
    WARNING = 1
    ERROR = 2

    def __str__(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class CodeInfo:
    severity: Severity
    title: str


def _e(title: str) -> CodeInfo:
    return CodeInfo(Severity.ERROR, title)


def _w(title: str) -> CodeInfo:
    return CodeInfo(Severity.WARNING, title)


#: Every diagnostic code sofac can emit, with its default severity and a short title.
CODES: dict[str, CodeInfo] = {
    # --- reading files (parse stage)
    "E100": _e("file not found or unreadable"),
    "E101": _e("malformed XML"),
    "E102": _e("forbidden XML construct (DTD, entity, external reference)"),
    "E103": _e("file too large"),
    "E104": _e("nesting too deep"),
    "W105": _w("not well-formed XML repaired as SOFA's parser does"),
    "E106": _e("include not found"),
    "E107": _e("include cycle"),
    "E108": _e("path outside the allowed data roots"),
    "E109": _e("invalid include or Attribute element"),
    "W110": _w("unused include override"),
    "W111": _w("element ignored (not allowed at this place)"),
    "E112": _e("root element is not a Node"),
    "E113": _e("Python scene script failed (exception, no createScene, SofaPython3 API sofac lacks)"),
    "E114": _e("Python scene not run (--no-exec)"),
    # --- checking (check stage)
    "E200": _e("unknown component"),
    "E201": _e("component name no longer accepted by SOFA"),
    "W202": _w("legacy component name"),
    "W203": _w("unknown attribute"),
    "E204": _e("value does not parse"),
    "E205": _e("wrong number of values"),
    "E206": _e("non-finite number"),
    "E207": _e("non-physical value"),
    "E208": _e("unknown or incompatible template"),
    "W209": _w("template alias"),
    "E210": _e("template does not match the node's MechanicalObject"),
    "E211": _e("two MechanicalObjects in one node"),
    "E212": _e("no MechanicalObject to act on"),
    "E213": _e("broken link"),
    "E214": _e("mapping input/output types not supported"),
    "E215": _e("mapping input not reachable"),
    "E216": _e("mapping output not in the mapping's node"),
    "E217": _e("mapping cycle"),
    "E218": _e("index out of range"),
    "E219": _e("mesh or data file missing or unreadable"),
    "W220": _w("MechanicalObject with forces but no ODE solver above it (it never moves)"),
    "E221": _e("implicit ODE solver without a linear solver"),
    "E222": _e("component not supported by sofac yet"),
    "W223": _w("ambiguous or implicit link resolution"),
    "W224": _w("RequiredPlugin names an unknown module"),
    "W225": _w("redundant or ignored attribute"),
    "W229": _w("a loader nobody reads has a missing file"),
    "W230": _w("anisotropic rigid inertia on a rotating body (SOFA applies it in world axes)"),
    "W231": _w("a loader read only by visual models has a missing file"),
    "W232": _w("assembled solve of contacts with a static model (SOFA adds coupling blocks sofac omits)"),
    "W233": _w("a link to nothing SOFA goes on without (a Data at its default, an optional object)"),
    "W234": _w("collision models that could touch without a compiled contact response (the run stops)"),
    "E226": _e("missing required value"),
    "E227": _e("duplicate name"),
    "W245": _w("state without a constraint correction under FreeMotionAnimationLoop (it never moves)"),
    "E246": _e("Lagrangian constraint on a state without a constraint correction"),
    "W247": _w("constraint correction without a compliance (SOFA's default is used)"),
    # --- usage
    "E002": _e("usage error"),
}


@dataclass(frozen=True, order=True)
class SourceLoc:
    """Where something comes from: a file, a 1-based line and optionally an attribute."""

    file: str
    line: int = 0
    attribute: str | None = None

    def with_attribute(self, attribute: str | None) -> SourceLoc:
        return SourceLoc(self.file, self.line, attribute)

    def __str__(self) -> str:
        text = f"{self.file}:{self.line}" if self.line else self.file
        return f"{text} [{self.attribute}]" if self.attribute else text


@dataclass(frozen=True)
class Diagnostic:
    code: str
    loc: SourceLoc
    message: str
    hint: str = ""
    severity: Severity = field(default=Severity.ERROR)

    def as_dict(self) -> dict[str, object]:
        return {
            "file": self.loc.file,
            "line": self.loc.line,
            "attribute": self.loc.attribute,
            "severity": str(self.severity),
            "code": self.code,
            "message": self.message,
            "hint": self.hint,
        }

    def __str__(self) -> str:
        text = f"{self.loc}: {self.severity} {self.code}: {self.message}"
        return f"{text}\n    hint: {self.hint}" if self.hint else text


class Diagnostics:
    """An ordered collection of diagnostics that the stages append to."""

    def __init__(self, items: Iterable[Diagnostic] = ()) -> None:
        self._items: list[Diagnostic] = list(items)
        self.downgrade_unsupported = False

    def add(self, code: str, loc: SourceLoc, message: str, hint: str = "") -> Diagnostic:
        """Adds a diagnostic, once: the same one found again (a refusal reached from several
        places) is not repeated."""
        severity = CODES[code].severity
        if code == "E222" and self.downgrade_unsupported:
            severity = Severity.WARNING
        diag = Diagnostic(code, loc, message, hint, severity)
        if diag not in self._items:
            self._items.append(diag)
        return diag

    def extend(self, other: Iterable[Diagnostic]) -> None:
        self._items.extend(other)

    def __iter__(self) -> Iterator[Diagnostic]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self._items if d.severity is Severity.ERROR]

    @property
    def warnings(self) -> list[Diagnostic]:
        return [d for d in self._items if d.severity is Severity.WARNING]

    def has_errors(self) -> bool:
        return any(d.severity is Severity.ERROR for d in self._items)

    def sorted(self) -> list[Diagnostic]:
        return sorted(self._items, key=lambda d: (d.loc.file, d.loc.line, d.code))


class SofacError(Exception):
    """Base class of every error sofac raises on purpose."""


class SceneError(SofacError):
    """A scene could not be read or is invalid; carries the diagnostics that say why."""

    def __init__(self, diagnostics: Iterable[Diagnostic]) -> None:
        self.diagnostics = list(diagnostics)
        first = next((d for d in self.diagnostics if d.severity is Severity.ERROR), None)
        super().__init__(str(first) if first else "invalid scene")


def relative_name(path: Path, base: Path | None = None) -> str:
    """A short, stable display name for a file: relative to ``base`` (or the cwd) when possible."""
    for root in (base, Path.cwd()):
        if root is None:
            continue
        try:
            return str(path.resolve().relative_to(root.resolve()))
        except ValueError:
            continue
    return str(path)
