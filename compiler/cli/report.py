"""Reporters: diagnostics rendered for people and for tools.

Formats:

``text``
    ``file:line: severity CODE [attribute]: message``, the hint indented on the next line, then a
    summary line (``2 errors, 1 warning in 3 files``).
``json``
    A JSON list of objects with ``file``, ``line``, ``attribute``, ``severity``, ``code``,
    ``title``, ``message`` and ``hint``.
``github``
    GitHub Actions workflow commands (``::error file=F,line=L,title=CODE::message``), escaped as the
    runner expects, then the summary line (a plain log line).
``junit``
    JUnit XML: one ``<testsuite>``, one ``<testcase>`` per checked file, one ``<failure>`` per error
    (warnings go to the test case's ``<system-out>``); ``failures`` counts the failing files.

Everything here is a pure function of its arguments.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

from lxml import etree
from sofac.diagnostics import CODES, Diagnostic, Severity

FORMATS = ("text", "json", "github", "junit")


@dataclass(frozen=True)
class FileResult:
    """The diagnostics found while checking one file (including those located in its includes)."""

    file: str
    diagnostics: tuple[Diagnostic, ...] = field(default_factory=tuple)

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity is Severity.ERROR]


def group_by_file(diagnostics: Sequence[Diagnostic], files: Sequence[str]) -> list[FileResult]:
    """One result per file of ``files``, diagnostics assigned by their location's file.

    A diagnostic located in a file that is not in ``files`` (an included fragment, say) gets a
    result of its own, after the others, so that nothing is dropped.
    """
    order = list(dict.fromkeys(files))
    by_file: dict[str, list[Diagnostic]] = {name: [] for name in order}
    for diag in diagnostics:
        by_file.setdefault(diag.loc.file, []).append(diag)
    return [FileResult(name, tuple(items)) for name, items in by_file.items()]


def render(
    diagnostics: Sequence[Diagnostic], fmt: str, files: Sequence[str], *, with_summary: bool = True
) -> str:
    """Render ``diagnostics`` found while checking ``files`` in format ``fmt`` (see :data:`FORMATS`).

    ``with_summary=False`` leaves out the summary line of the ``text`` and ``github`` formats.
    """
    return render_results(group_by_file(diagnostics, files), fmt, with_summary=with_summary)


def render_results(results: Sequence[FileResult], fmt: str, *, with_summary: bool = True) -> str:
    """Render per-file results; the CLI uses this to keep each diagnostic with the file it checked."""
    if fmt == "text":
        return _lines([format_diagnostic(d) for r in results for d in r.diagnostics], results, with_summary)
    if fmt == "github":
        return _lines([github_command(d) for r in results for d in r.diagnostics], results, with_summary)
    if fmt == "json":
        return _json(results)
    if fmt == "junit":
        return _junit(results)
    raise ValueError(f"unknown report format {fmt!r} (expected one of {', '.join(FORMATS)})")


def _lines(lines: list[str], results: Sequence[FileResult], with_summary: bool) -> str:
    if with_summary:
        lines = [*lines, summary(results)]
    return "".join(f"{line}\n" for line in lines)


# --- text --------------------------------------------------------------------------------------


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def summary(results: Sequence[FileResult]) -> str:
    """``2 errors, 1 warning in 3 files``."""
    diagnostics = [d for r in results for d in r.diagnostics]
    errors = sum(d.severity is Severity.ERROR for d in diagnostics)
    warnings = sum(d.severity is Severity.WARNING for d in diagnostics)
    return f"{_plural(errors, 'error')}, {_plural(warnings, 'warning')} in {_plural(len(results), 'file')}"


def format_diagnostic(diag: Diagnostic) -> str:
    """One diagnostic as ``file:line: severity CODE [attribute]: message`` plus an indented hint."""
    where = f"{diag.loc.file}:{diag.loc.line}" if diag.loc.line else diag.loc.file
    attribute = f" [{diag.loc.attribute}]" if diag.loc.attribute else ""
    text = f"{where}: {diag.severity} {diag.code}{attribute}: {diag.message}"
    if diag.hint:
        text += f"\n    hint: {diag.hint}"
    return text


# --- json --------------------------------------------------------------------------------------


def _json(results: Sequence[FileResult]) -> str:
    items = []
    for result in results:
        for diag in result.diagnostics:
            item = diag.as_dict()
            info = CODES.get(diag.code)
            item["title"] = info.title if info else ""
            items.append(item)
    return json.dumps(items, indent=2, ensure_ascii=False) + "\n"


# --- github ------------------------------------------------------------------------------------

_GITHUB_COMMAND = {Severity.ERROR: "error", Severity.WARNING: "warning", Severity.INFO: "notice"}


def escape_data(text: str) -> str:
    """Escape a workflow command's message (the part after ``::``)."""
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def escape_property(text: str) -> str:
    """Escape a workflow command's property value (``file=...``, ``title=...``)."""
    return escape_data(text).replace(":", "%3A").replace(",", "%2C")


def github_command(diag: Diagnostic) -> str:
    properties = [f"file={escape_property(diag.loc.file)}"]
    if diag.loc.line:
        properties.append(f"line={diag.loc.line}")
    properties.append(f"title={escape_property(diag.code)}")
    message = diag.message
    if diag.loc.attribute:
        message = f"[{diag.loc.attribute}] {message}"
    if diag.hint:
        message += f"\nhint: {diag.hint}"
    return f"::{_GITHUB_COMMAND[diag.severity]} {','.join(properties)}::{escape_data(message)}"


# --- junit -------------------------------------------------------------------------------------

# Characters XML 1.0 cannot hold (lxml refuses them); file names and messages may contain them.
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _xml_text(text: str) -> str:
    return _XML_INVALID.sub("\ufffd", text)


def _junit(results: Sequence[FileResult]) -> str:
    failing = sum(1 for r in results if r.errors)
    suite = etree.Element(
        "testsuite",
        name="sofac check",
        tests=str(len(results)),
        failures=str(failing),
        errors="0",
        skipped="0",
    )
    for result in results:
        case = etree.SubElement(
            suite,
            "testcase",
            classname="sofac.check.checker",
            name=_xml_text(result.file),
            file=_xml_text(result.file),
        )
        for diag in result.errors:
            failure = etree.SubElement(
                case, "failure", type=diag.code, message=_xml_text(f"{diag.code}: {diag.message}")
            )
            failure.text = _xml_text(format_diagnostic(diag))
        others = [d for d in result.diagnostics if d.severity is not Severity.ERROR]
        if others:
            out = etree.SubElement(case, "system-out")
            out.text = _xml_text("\n".join(format_diagnostic(d) for d in others))
    return etree.tostring(suite, xml_declaration=True, encoding="UTF-8", pretty_print=True).decode("utf-8")
