"""Reporters: text, json, github workflow commands, JUnit XML."""

from __future__ import annotations

import json

import pytest
from lxml import etree
from sofac.cli.report import (
    FORMATS,
    FileResult,
    escape_data,
    escape_property,
    format_diagnostic,
    github_command,
    group_by_file,
    render,
    render_results,
    summary,
)
from sofac.diagnostics import Diagnostic, Severity, SourceLoc


def diag(
    code: str = "E204",
    file: str = "a.scn",
    line: int = 3,
    message: str = "bad value",
    hint: str = "",
    severity: Severity = Severity.ERROR,
    attribute: str | None = None,
) -> Diagnostic:
    return Diagnostic(code, SourceLoc(file, line, attribute), message, hint, severity)


SAMPLE = [
    diag(
        "E204", "a.scn", 3, "youngModulus: 'abc' is not a number", "write a number", attribute="youngModulus"
    ),
    diag("W203", "a.scn", 5, "unknown attribute 'foo'", severity=Severity.WARNING),
    diag("E200", "b.scn", 7, "unknown component 'Foo'", "did you mean Bar?"),
]
FILES = ["a.scn", "b.scn", "c.scn"]


# --- text ------------------------------------------------------------------------------------------


def test_text_lines_hints_and_summary() -> None:
    out = render(SAMPLE, "text", FILES)
    lines = out.splitlines()
    assert lines[0] == "a.scn:3: error E204 [youngModulus]: youngModulus: 'abc' is not a number"
    assert lines[1] == "    hint: write a number"
    assert lines[2] == "a.scn:5: warning W203: unknown attribute 'foo'"
    assert lines[3] == "b.scn:7: error E200: unknown component 'Foo'"
    assert lines[4] == "    hint: did you mean Bar?"
    assert lines[-1] == "2 errors, 1 warning in 3 files"
    assert out.endswith("\n")


@pytest.mark.parametrize(
    ("diagnostics", "files", "expected"),
    [
        ([], ["a.scn"], "0 errors, 0 warnings in 1 file"),
        ([diag()], ["a.scn", "b.scn"], "1 error, 0 warnings in 2 files"),
        ([diag(severity=Severity.WARNING)] * 2, ["a.scn"], "0 errors, 2 warnings in 1 file"),
        ([diag(severity=Severity.INFO)], ["a.scn"], "0 errors, 0 warnings in 1 file"),
    ],
)
def test_summary_counts_and_plurals(diagnostics: list[Diagnostic], files: list[str], expected: str) -> None:
    assert summary(group_by_file(diagnostics, files)) == expected


def test_text_without_line_and_without_summary() -> None:
    out = render([diag(line=0)], "text", ["a.scn"], with_summary=False)
    assert out == "a.scn: error E204: bad value\n"


def test_format_diagnostic_matches_text_report() -> None:
    d = SAMPLE[0]
    assert render([d], "text", ["a.scn"], with_summary=False) == format_diagnostic(d) + "\n"


# --- json ------------------------------------------------------------------------------------------


def test_json_has_required_keys() -> None:
    items = json.loads(render(SAMPLE, "json", FILES))
    assert isinstance(items, list) and len(items) == 3
    for item in items:
        assert {"file", "line", "attribute", "severity", "code", "message", "hint"} <= item.keys()
    assert items[0] == {
        "file": "a.scn",
        "line": 3,
        "attribute": "youngModulus",
        "severity": "error",
        "code": "E204",
        "title": "value does not parse",
        "message": "youngModulus: 'abc' is not a number",
        "hint": "write a number",
    }
    assert items[1]["severity"] == "warning" and items[1]["attribute"] is None


def test_json_of_no_diagnostics_is_an_empty_list() -> None:
    assert json.loads(render([], "json", ["a.scn"])) == []


def test_json_keeps_unicode() -> None:
    out = render([diag(message="ν = 0.5 is not < 0.5")], "json", ["a.scn"])
    assert json.loads(out)[0]["message"] == "ν = 0.5 is not < 0.5"


# --- github ----------------------------------------------------------------------------------------


def test_github_escaping_functions() -> None:
    assert escape_data("100% done\r\nnext") == "100%25 done%0D%0Anext"
    assert escape_data("a:b,c") == "a:b,c"
    assert escape_property("dir,x/a:b%c\r\n.scn") == "dir%2Cx/a%3Ab%25c%0D%0A.scn"
    # % first: an already-escaped-looking text must not be decoded back by the runner
    assert escape_data("%0A") == "%250A"


def test_github_command_shape() -> None:
    line = github_command(diag("E200", "scenes/a.scn", 7, "unknown component 'Foo'"))
    assert line == "::error file=scenes/a.scn,line=7,title=E200::unknown component 'Foo'"


def test_github_escapes_message_and_file_name() -> None:
    d = diag(
        "E204",
        file="odd,dir/x:y%z\n.scn",
        line=12,
        message="50% of 'a,b:c'\r\nsecond line",
        hint="fix: it, now",
    )
    line = github_command(d)
    assert "\n" not in line and "\r" not in line
    prefix, message = line.split("::", 2)[1:]
    assert prefix == "error file=odd%2Cdir/x%3Ay%25z%0A.scn,line=12,title=E204"
    # message: %, CR, LF escaped; ':' and ',' left alone
    assert message == "50%25 of 'a,b:c'%0D%0Asecond line%0Ahint: fix: it, now"


def test_github_severities_and_missing_line() -> None:
    assert github_command(diag(severity=Severity.WARNING)).startswith("::warning file=a.scn,line=3,")
    assert github_command(diag(severity=Severity.INFO)).startswith("::notice ")
    assert github_command(diag(line=0)).startswith("::error file=a.scn,title=E204::")


def test_github_report_is_one_command_per_diagnostic_then_summary() -> None:
    lines = render(SAMPLE, "github", FILES).splitlines()
    assert [line.split(" ", 1)[0] for line in lines[:3]] == ["::error", "::warning", "::error"]
    assert lines[3] == "2 errors, 1 warning in 3 files"


# --- junit -----------------------------------------------------------------------------------------


def parse_junit(text: str) -> etree._Element:
    return etree.fromstring(text.encode("utf-8"))


def test_junit_one_testcase_per_file_and_failures_per_error() -> None:
    suite = parse_junit(render(SAMPLE, "junit", FILES))
    assert suite.tag == "testsuite"
    assert suite.get("tests") == "3"
    assert suite.get("failures") == "2"  # files with errors: a.scn and b.scn
    assert suite.get("errors") == "0"
    cases = suite.findall("testcase")
    assert [c.get("name") for c in cases] == FILES
    a, b, c = cases
    assert [f.get("type") for f in a.findall("failure")] == ["E204"]
    assert "hint: write a number" in a.find("failure").text
    assert "W203" in a.find("system-out").text  # warnings are reported, not failures
    assert [f.get("type") for f in b.findall("failure")] == ["E200"]
    assert b.find("failure").get("message") == "E200: unknown component 'Foo'"
    assert c.find("failure") is None and c.find("system-out") is None


def test_junit_counts_every_error_of_a_file() -> None:
    diagnostics = [diag(line=i) for i in range(1, 4)] + [diag(severity=Severity.WARNING)]
    suite = parse_junit(render(diagnostics, "junit", ["a.scn"]))
    assert suite.get("failures") == "1"
    assert len(suite.findall("testcase/failure")) == 3


def test_junit_all_passing() -> None:
    suite = parse_junit(render([], "junit", ["a.scn", "b.scn"]))
    assert suite.get("tests") == "2" and suite.get("failures") == "0"
    assert suite.findall(".//failure") == []


def test_junit_escapes_markup_and_control_characters() -> None:
    d = diag(file='x"<&>.scn', message="<Node> & ]]> \x01 \x1b[31m", hint="use </Node>")
    text = render([d], "junit", ['x"<&>.scn'])
    assert text.startswith("<?xml")
    suite = parse_junit(text)
    case = suite.find("testcase")
    assert case.get("name") == 'x"<&>.scn'
    failure = case.find("failure")
    assert "<Node> & ]]>" in failure.get("message")
    assert "\x01" not in failure.text and "use </Node>" in failure.text


def test_junit_keeps_diagnostics_from_included_files() -> None:
    included = diag(file="Objects/part.xml", line=2)
    suite = parse_junit(render([included], "junit", ["a.scn"]))
    assert [c.get("name") for c in suite.findall("testcase")] == ["a.scn", "Objects/part.xml"]


# --- common ----------------------------------------------------------------------------------------


def test_render_results_keeps_the_given_grouping() -> None:
    results = [FileResult("main.scn", (diag(file="inc.xml"),)), FileResult("other.scn")]
    suite = parse_junit(render_results(results, "junit"))
    assert [c.get("name") for c in suite.findall("testcase")] == ["main.scn", "other.scn"]
    assert suite.get("failures") == "1"


def test_unknown_format_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown report format"):
        render([], "sarif", [])
    assert FORMATS == ("text", "json", "github", "junit")
