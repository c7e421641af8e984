"""The whole SOFA corpus (``shared/corpus/sofa``) through ``sofac check``.

* every ``.scn`` file and every ``.xml`` file rooted at ``<Node>`` checks without an exception, and
  every diagnostic points at a line of its file that holds what it is about: the element (its tag
  is on the line) or the attribute it names (``name=`` is on the line);
* the same folder through the command line, in-process, gives the same diagnostics;
* the 10 negative scenes of ``manifest.json`` are rejected; the accepted ones fail, if at all, only
  with unsupported components (E222) or with files the corpus really does not ship (E219);
* every component of SOFA's 87 regression scenes (includes and macros expanded) is registered.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import pytest
from manifest_updates import IMPLEMENTED_SINCE_MANIFEST
from sofac import registry
from sofac.check.checker import CheckedScene, check_file
from sofac.cli.main import find_scenes, main
from sofac.diagnostics import Diagnostic, Diagnostics, Severity
from sofac.front.model import Component, Node
from sofac.front.parse import parse_scene
from sofac.pipeline import add_compile_refusals

# Diagnostics about the text itself: they may point at any line (an unclosed tag, a repaired '&').
TEXT_CODES = {"E101", "E102", "E104", "W105"}


@pytest.fixture(autouse=True)
def _no_env_data_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SOFAC_DATA_PATH", raising=False)


@dataclass
class Result:
    path: Path
    checked: CheckedScene | None
    diags: Diagnostics

    @property
    def errors(self) -> list[Diagnostic]:
        return self.diags.errors

    def error_codes(self) -> set[str]:
        return {d.code for d in self.errors}


@pytest.fixture(scope="module")
def results(corpus_dir: Path) -> dict[str, Result]:
    """Every scene of the corpus, checked once: {path relative to the corpus: result}."""
    out: dict[str, Result] = {}
    for path in sorted(find_scenes([str(corpus_dir)])):
        checked, diags = check_file(path)  # an exception here fails every test of this file
        add_compile_refusals(checked, diags)  # as `sofac check` does: what the compile would refuse
        out[path.relative_to(corpus_dir).as_posix()] = Result(path, checked, diags)
    return out


@pytest.fixture(scope="module")
def manifest(corpus_dir: Path) -> list[dict[str, object]]:
    scenes = json.loads((corpus_dir / "manifest.json").read_text(encoding="utf-8"))["scenes"]
    assert len(scenes) == 126
    return scenes  # type: ignore[no-any-return]


class Lines:
    """The text lines of the files diagnostics name, read once (line ends as XML counts them)."""

    def __init__(self) -> None:
        self._files: dict[str, list[str]] = {}

    def __call__(self, file: str) -> list[str]:
        if file not in self._files:
            data = Path(file).read_bytes().decode("utf-8", errors="replace")
            self._files[file] = data.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        return self._files[file]


def _elements_at(checked: CheckedScene | None) -> dict[tuple[str, int], list[Component | Node]]:
    """The model's nodes and components by the (file, line) of their start tag."""
    found: dict[tuple[str, int], list[Component | Node]] = {}
    if checked is None:
        return found
    for node in checked.scene.root.walk():
        for element in (node, *node.objects):
            found.setdefault((element.loc.file, element.loc.line), []).append(element)
    return found


def _tag_on_line(element: Component | Node, text: str) -> bool:
    name = "Node" if isinstance(element, Node) else element.type_name
    # <Name ...>, or the legacy <Object type="Name" ...>, or a macro/include that produced it.
    return bool(
        re.search(rf"<{re.escape(name)}\b", text)
        or re.search(rf"""\btype\s*=\s*["']{re.escape(name)}["']""", text)
        or re.search(r"<include\b", text)
    )


def _attribute_on_line(attribute: str, text: str) -> bool:
    return bool(re.search(rf"(?<![\w.:-]){re.escape(attribute)}\s*=", text))


def misplaced(result: Result, lines: Callable[[str], list[str]]) -> list[str]:
    """Diagnostics of one scene whose line does not hold what they are about."""
    problems: list[str] = []
    elements = _elements_at(result.checked)
    for diag in result.diags:
        file_lines = lines(diag.loc.file)
        if not 1 <= diag.loc.line <= len(file_lines):
            problems.append(f"{diag}: line {diag.loc.line} is not in the file ({len(file_lines)} lines)")
            continue
        if diag.code in TEXT_CODES:
            continue
        text = file_lines[diag.loc.line - 1]
        here = elements.get((diag.loc.file, diag.loc.line), [])
        attribute = diag.loc.attribute
        if attribute is not None:
            # The attribute is written on the line, or it is the implicit default of an element
            # that starts on the line (a mapping's input="@../", a BoxROI's input positions).
            ok = _attribute_on_line(attribute, text) or any(
                attribute not in e.attributes and _tag_on_line(e, text) for e in here
            )
        elif here:
            ok = any(_tag_on_line(e, text) for e in here)
        else:
            ok = bool(re.search(r"<[A-Za-z_]", text))  # no model (the scene could not be read)
        if not ok:
            problems.append(f"{diag}\n    line {diag.loc.line}: {text.strip()[:120]}")
    return problems


# --- every file --------------------------------------------------------------------------------


def test_corpus_has_the_expected_files(results: dict[str, Result]) -> None:
    scn = [name for name in results if name.endswith(".scn")]
    xml = [name for name in results if name.endswith(".xml")]
    assert len(scn) >= 126 and len(xml) >= 1, (len(scn), len(xml))


def test_every_diagnostic_points_at_the_right_line(results: dict[str, Result]) -> None:
    lines = Lines()
    problems = [problem for result in results.values() for problem in misplaced(result, lines)]
    assert problems == [], "\n".join(problems)


def test_cli_in_process_gives_the_same_diagnostics(
    corpus_dir: Path, results: dict[str, Result], capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["check", "--format", "json", str(corpus_dir)])
    out, err = capsys.readouterr()
    assert code in (0, 1), err  # 2 would be a usage error, 3 an internal error (a traceback)
    assert "Traceback" not in err and "internal error" not in err
    reported = json.loads(out)
    expected = sum(len(r.diags) for r in results.values())
    assert len(reported) == expected
    assert code == (1 if any(r.errors for r in results.values()) else 0)


# --- the manifest's 126 scenes -------------------------------------------------------------------


def _missing_file(diag: Diagnostic, scene: Path, corpus_dir: Path, lines: Lines) -> bool:
    """An E219 is right: the file named on its line exists neither beside the scene nor in the corpus."""
    text = lines(diag.loc.file)[diag.loc.line - 1]
    match = re.search(rf"""\b{re.escape(diag.loc.attribute or "")}\s*=\s*["']([^"']*)["']""", text)
    if match is None:
        return False
    name = match.group(1)
    return not (Path(diag.loc.file).parent / name).exists() and not (corpus_dir / name).exists()


def test_negative_scenes_are_rejected(
    manifest: list[dict[str, object]], results: dict[str, Result], record_property: Callable[..., None]
) -> None:
    negative = [
        str(s["scene"])
        for s in manifest
        if str(s["expected"]).startswith("reject") and s["scene"] not in IMPLEMENTED_SINCE_MANIFEST
    ]
    assert len(negative) == 10 - len(IMPLEMENTED_SINCE_MANIFEST)
    assert all(not results[name].error_codes() for name in IMPLEMENTED_SINCE_MANIFEST)
    codes = {name: sorted(results[name].error_codes()) for name in negative}
    record_property("negative_scene_errors", json.dumps(codes))
    assert [name for name, found in codes.items() if not found] == []


def test_accepted_scenes_fail_only_for_support_or_missing_files(
    manifest: list[dict[str, object]],
    results: dict[str, Result],
    corpus_dir: Path,
    record_property: Callable[..., None],
) -> None:
    lines = Lines()
    counts: Counter[str] = Counter()
    unexplained: list[str] = []
    for entry in manifest:
        result = results[str(entry["scene"])]
        codes = result.error_codes()
        counts["clean" if not codes else "unsupported only" if codes == {"E222"} else "other errors"] += 1
        if not str(entry["expected"]).startswith("accept"):
            continue
        for diag in result.errors:
            if diag.code == "E222":
                continue
            if diag.code == "E219" and _missing_file(diag, result.path, corpus_dir, lines):
                continue
            unexplained.append(str(diag))
    record_property("manifest_counts", json.dumps(dict(counts)))
    assert sum(counts.values()) == 126
    assert unexplained == [], "\n".join(unexplained)


# --- the regression scenes -------------------------------------------------------------------------


def _regression_scenes(shared_dir: Path) -> list[str]:
    listing = shared_dir / "reference" / "sofa-regression" / "scenes.regression-tests"
    scenes = []
    for line in listing.read_text(encoding="utf-8").splitlines():
        fields = line.split()
        if fields and not line.startswith("#") and fields[0].endswith((".scn", ".xml")):
            scenes.append(fields[0])
    return scenes


def test_every_component_of_the_regression_scenes_is_registered(shared_dir: Path, corpus_dir: Path) -> None:
    scenes = _regression_scenes(shared_dir)
    assert len(scenes) == 87
    missing_files = [name for name in scenes if not (corpus_dir / name).is_file()]
    assert missing_files == []
    unknown: dict[str, set[str]] = {}
    used: set[str] = set()
    for name in scenes:
        scene = parse_scene(corpus_dir / name, Diagnostics())  # includes and macros expanded
        for component in scene.root.components():
            resolution = registry.lookup(component.type_name)
            if resolution is None:
                unknown.setdefault(component.type_name, set()).add(name)
            else:
                used.add(resolution.spec.name)
    assert unknown == {}
    # Registered, supported or not: the unsupported ones are reported as E222, never as unknown (E200).
    assert used <= set(registry.all_components())


def test_unsupported_components_are_errors_only_without_allow_unsupported(
    results: dict[str, Result], corpus_dir: Path
) -> None:
    # a scene refused by the checker itself (not only by the compile's refusals)
    candidates = (n for n, r in sorted(results.items()) if r.error_codes() == {"E222"})
    name = next(n for n in candidates if {d.code for d in check_file(corpus_dir / n)[1].errors} == {"E222"})
    _, diags = check_file(corpus_dir / name, allow_unsupported=True)
    assert not diags.has_errors()
    assert {d.code for d in diags if d.severity is Severity.WARNING} >= {"E222"}


def test_the_line_check_catches_a_wrong_line(results: dict[str, Result]) -> None:
    """misplaced() is not vacuous: the same diagnostics one line further down are reported (in the
    first scenes with E222s: one line down can land on a component of the same type)."""
    caught = []
    for _, result in sorted(results.items()):
        if not any(d.code == "E222" for d in result.diags):
            continue
        moved = Diagnostics(
            Diagnostic(d.code, replace(d.loc, line=d.loc.line + 1), d.message, d.hint, d.severity)
            for d in result.diags
            if d.code == "E222"
        )
        caught.append(bool(misplaced(Result(result.path, result.checked, moved), Lines())))
        if len(caught) == 3:
            break
    assert any(caught), caught
