"""The command line: exit codes, usage errors (E002), scene discovery, formats, internal errors.

Three groups:

* usage and version tests run ``sofac`` both as ``python -m sofac`` and as the installed console script;
* command-flow tests run the CLI with ``sofac.check.checker.check_file`` replaced by a fake, so they do not
  depend on the parse and check stages;
* end-to-end tests use the real ``check_file`` and are skipped until ``sofac.front.parse`` exists.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import sofac
from lxml import etree
from sofac.cli.main import find_scenes, is_scene_xml, main

REPO = Path(__file__).resolve().parents[1]
HAVE_PARSE = importlib.util.find_spec("sofac.front.parse") is not None
needs_parse = pytest.mark.skipif(not HAVE_PARSE, reason="sofac.front.parse is not written yet")


def _console_script() -> str | None:
    beside = Path(sys.executable).parent / "sofac"
    if beside.is_file():
        return str(beside)
    return shutil.which("sofac")


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "SOFAC_DEBUG"}
    env.update(extra)
    return env


@pytest.fixture(params=["module", "script"])
def sofac_cmd(request: pytest.FixtureRequest) -> list[str]:
    if request.param == "module":
        return [sys.executable, "-m", "sofac"]
    script = _console_script()
    if script is None:
        pytest.skip("the sofac console script is not installed (run `bash scripts/setup.sh`)")
    return [script]


def run(cmd: list[str], *args: str, cwd: Path | None = None, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*cmd, *args], capture_output=True, text=True, cwd=cwd, env=_env(**env), stdin=subprocess.DEVNULL
    )


# --- usage errors and version (both entry points) -------------------------------------------------


def test_version(sofac_cmd: list[str]) -> None:
    result = run(sofac_cmd, "version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"sofac {sofac.__version__}"
    assert run(sofac_cmd, "--version").stdout.strip() == f"sofac {sofac.__version__}"


def test_check_nonexistent_path(sofac_cmd: list[str], tmp_path: Path) -> None:
    result = run(sofac_cmd, "check", str(tmp_path / "nope.scn"))
    assert result.returncode == 2
    assert "E002" in result.stderr and "nope.scn" in result.stderr
    assert result.stdout == ""
    assert "Traceback" not in result.stderr


def test_check_empty_folder(sofac_cmd: list[str], tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("not a scene")
    (tmp_path / "pom.xml").write_text("<project/>")
    result = run(sofac_cmd, "check", str(tmp_path))
    assert result.returncode == 2
    assert "E002" in result.stderr and "no scene files" in result.stderr


def test_check_bad_format(sofac_cmd: list[str], tmp_path: Path) -> None:
    result = run(sofac_cmd, "check", "--format", "sarif", str(tmp_path))
    assert result.returncode == 2
    assert "E002" in result.stderr and "invalid choice" in result.stderr


def test_check_without_path(sofac_cmd: list[str]) -> None:
    result = run(sofac_cmd, "check")
    assert result.returncode == 2 and "E002" in result.stderr


def test_no_command_and_unknown_command(sofac_cmd: list[str]) -> None:
    for args in ([], ["compile-everything"]):
        result = run(sofac_cmd, *args)
        assert result.returncode == 2, args
        assert "E002" in result.stderr


def test_check_missing_data_path(sofac_cmd: list[str], tmp_path: Path) -> None:
    scene = tmp_path / "a.scn"
    scene.write_text("<Node/>")
    result = run(sofac_cmd, "check", "--data-path", str(tmp_path / "nowhere"), str(scene))
    assert result.returncode == 2 and "E002" in result.stderr and "--data-path" in result.stderr


def test_inspect_usage_errors(sofac_cmd: list[str], tmp_path: Path) -> None:
    missing = run(sofac_cmd, "inspect", str(tmp_path / "nope.scn"))
    assert missing.returncode == 2 and "E002" in missing.stderr
    folder = run(sofac_cmd, "inspect", str(tmp_path))
    assert folder.returncode == 2 and "E002" in folder.stderr
    nothing = run(sofac_cmd, "inspect")
    assert nothing.returncode == 2 and "E002" in nothing.stderr
    bad_format = run(sofac_cmd, "inspect", "--format", "junit", "x.scn")
    assert bad_format.returncode == 2 and "E002" in bad_format.stderr


def test_help_lists_commands_and_exit_codes(sofac_cmd: list[str]) -> None:
    result = run(sofac_cmd, "--help")
    assert result.returncode == 0
    for word in ("check", "inspect", "version", "exit codes"):
        assert word in result.stdout


def test_inspect_components_lists_the_registry() -> None:
    result = run([sys.executable, "-m", "sofac"], "inspect", "--components")
    assert result.returncode == 0
    assert "MechanicalObject" in result.stdout.split()
    items = json.loads(
        run([sys.executable, "-m", "sofac"], "inspect", "--components", "--format", "json").stdout
    )
    assert {"name", "category", "module", "supported"} <= items[0].keys()


# --- scene discovery -------------------------------------------------------------------------------


def test_is_scene_xml(tmp_path: Path) -> None:
    cases = {
        "plain.xml": "<Node name='root'/>",
        "prologue.xml": '\ufeff<?xml version="1.0"?>\n<!-- a comment -->\n<!DOCTYPE x>\n<Node>\n</Node>',
        "lower.xml": "<node/>",
        "other.xml": "<project><Node/></project>",
        "prefix.xml": "<NodeList/>",
        "empty.xml": "",
    }
    for name, text in cases.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    found = {name for name in cases if is_scene_xml(tmp_path / name)}
    assert found == {"plain.xml", "prologue.xml", "lower.xml"}


def test_find_scenes_recurses_and_filters(tmp_path: Path) -> None:
    (tmp_path / "b").mkdir()
    (tmp_path / ".hidden").mkdir()
    (tmp_path / "Objects").mkdir()
    (tmp_path / "a.scn").write_text("<Node/>")
    (tmp_path / "b" / "c.scn").write_text("<Node/>")
    (tmp_path / "Objects" / "fragment.xml").write_text("<Node name='part'/>")
    (tmp_path / "Objects" / "config.xml").write_text("<config/>")
    (tmp_path / ".hidden" / "d.scn").write_text("<Node/>")
    (tmp_path / "readme.txt").write_text("")
    found = find_scenes([str(tmp_path)])
    assert [p.relative_to(tmp_path).as_posix() for p in found] == ["a.scn", "Objects/fragment.xml", "b/c.scn"]
    # an explicit file is checked whatever its name; duplicates are dropped
    explicit = tmp_path / "readme.txt"
    assert find_scenes([str(explicit), str(tmp_path / "a.scn"), str(tmp_path)])[:2] == [
        explicit,
        tmp_path / "a.scn",
    ]
    assert len(find_scenes([str(tmp_path), str(tmp_path)])) == 3


def test_main_in_process_returns_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["version"]) == 0
    assert capsys.readouterr().out.strip() == f"sofac {sofac.__version__}"
    assert main(["check", str(tmp_path / "nope")]) == 2
    assert "E002" in capsys.readouterr().err
    assert main(["check", "--format", "nope", "x"]) == 2


# --- command flow with a fake check stage ----------------------------------------------------------

# Replaces sofac.check.checker.check_file: the scene text decides the diagnostics.
FAKE_CHECK = """
import sys
from pathlib import Path

import sofac.check.checker
from sofac.diagnostics import Diagnostics, SourceLoc, relative_name

def fake_check_file(path, *, data_roots=(), allow_unsupported=False):
    diags = Diagnostics()
    diags.downgrade_unsupported = allow_unsupported
    text = Path(path).read_text()
    name = relative_name(Path(path))
    print("checked", Path(path).name, [Path(r).name for r in data_roots], file=sys.stderr)
    if "CRASH" in text:
        raise RuntimeError("boom")
    if "BAD" in text:
        diags.add("E200", SourceLoc(name, 2), "unknown component 'Bad'", "did you mean Good?")
    if "WARN" in text:
        diags.add("W203", SourceLoc(name, 3, "foo"), "unknown attribute 'foo'")
    if "UNSUPPORTED" in text:
        diags.add("E222", SourceLoc(name, 4), "unsupported component X")
    return None, diags

sofac.check.checker.check_file = fake_check_file
from sofac.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def fake(*args: str, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return run([sys.executable, "-c", FAKE_CHECK], *args, cwd=cwd, **env)


@pytest.fixture
def scenes(tmp_path: Path) -> Path:
    (tmp_path / "ok.scn").write_text("<Node/>")
    (tmp_path / "warn.scn").write_text("<Node/> WARN")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "bad.scn").write_text("<Node/> BAD")
    return tmp_path


def test_check_clean_scene_exits_0(scenes: Path) -> None:
    result = fake("check", "ok.scn", cwd=scenes)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "0 errors, 0 warnings in 1 file\n"


def test_check_warnings_only_exit_0(scenes: Path) -> None:
    result = fake("check", "ok.scn", "warn.scn", cwd=scenes)
    assert result.returncode == 0
    assert result.stdout.splitlines() == [
        "warn.scn:3: warning W203 [foo]: unknown attribute 'foo'",
        "0 errors, 1 warning in 2 files",
    ]


def test_check_folder_with_errors_exits_1(scenes: Path) -> None:
    result = fake("check", ".", cwd=scenes)
    assert result.returncode == 1
    checked = [line.split()[1] for line in result.stderr.splitlines() if line.startswith("checked")]
    assert checked == ["ok.scn", "warn.scn", "bad.scn"]
    assert "sub/bad.scn:2: error E200: unknown component 'Bad'" in result.stdout
    assert "    hint: did you mean Good?" in result.stdout
    assert result.stdout.splitlines()[-1] == "1 error, 1 warning in 3 files"


def test_check_quiet_reports_errors_only(scenes: Path) -> None:
    result = fake("check", "--quiet", ".", cwd=scenes)
    assert result.returncode == 1
    assert "W203" not in result.stdout and "E200" in result.stdout
    assert "in 3 files" not in result.stdout
    assert fake("check", "-q", "ok.scn", "warn.scn", cwd=scenes).stdout == ""


def test_check_formats(scenes: Path) -> None:
    as_json = fake("check", "--format", "json", ".", cwd=scenes)
    assert as_json.returncode == 1
    assert [item["code"] for item in json.loads(as_json.stdout)] == ["W203", "E200"]

    github = fake("check", "--format", "github", ".", cwd=scenes)
    assert (
        "::error file=sub/bad.scn,line=2,title=E200::unknown component 'Bad'%0Ahint: did you mean Good?"
        in (github.stdout.splitlines())
    )

    junit = fake("check", "--format", "junit", ".", cwd=scenes)
    suite = etree.fromstring(junit.stdout.encode())
    assert suite.get("tests") == "3" and suite.get("failures") == "1"
    assert [c.get("name") for c in suite.findall("testcase")] == ["ok.scn", "warn.scn", "sub/bad.scn"]


def test_check_passes_options_through(scenes: Path) -> None:
    (scenes / "meshes").mkdir()
    (scenes / "unsupported.scn").write_text("UNSUPPORTED")
    strict = fake("check", "unsupported.scn", cwd=scenes)
    assert strict.returncode == 1 and "error E222" in strict.stdout
    lenient = fake("check", "--allow-unsupported", "--data-path", "meshes", "unsupported.scn", cwd=scenes)
    assert lenient.returncode == 0 and "warning E222" in lenient.stdout
    assert "checked unsupported.scn ['meshes']" in lenient.stderr


def test_internal_error_exits_3_without_traceback(scenes: Path) -> None:
    (scenes / "crash.scn").write_text("CRASH")
    result = fake("check", "crash.scn", cwd=scenes)
    assert result.returncode == 3
    assert "sofac: internal error: RuntimeError: boom" in result.stderr
    assert "report" in result.stderr and "SOFAC_DEBUG=1" in result.stderr
    assert "Traceback" not in result.stderr
    debug = fake("check", "crash.scn", cwd=scenes, SOFAC_DEBUG="1")
    assert debug.returncode == 3
    assert "Traceback" in debug.stderr and "fake_check_file" in debug.stderr


# --- end to end with the real check stage ----------------------------------------------------------

VALID = (
    '<Node name="root" dt="0.01">\n'
    '  <MechanicalObject name="dofs" template="Vec3d" position="0 0 0"/>\n'
    "</Node>\n"
)
INVALID = '<Node name="root">\n  <NoSuchComponentAtAll name="x"/>\n</Node>\n'


@needs_parse
def test_real_check_valid_and_invalid(sofac_cmd: list[str], tmp_path: Path) -> None:
    (tmp_path / "valid.scn").write_text(VALID)
    (tmp_path / "invalid.scn").write_text(INVALID)
    valid = run(sofac_cmd, "check", "valid.scn", cwd=tmp_path)
    assert valid.returncode == 0, valid.stdout + valid.stderr
    invalid = run(sofac_cmd, "check", "--format", "json", "invalid.scn", cwd=tmp_path)
    assert invalid.returncode == 1
    assert "E200" in [item["code"] for item in json.loads(invalid.stdout)]


@needs_parse
def test_real_inspect(tmp_path: Path) -> None:
    (tmp_path / "valid.scn").write_text(VALID)
    text = run([sys.executable, "-m", "sofac"], "inspect", "valid.scn", cwd=tmp_path)
    assert text.returncode == 0, text.stderr
    assert "MechanicalObject" in text.stdout
    tree = json.loads(
        run([sys.executable, "-m", "sofac"], "inspect", "--format", "json", "valid.scn", cwd=tmp_path).stdout
    )
    assert tree["components"][0]["type"] == "MechanicalObject"
    (tmp_path / "invalid.scn").write_text(INVALID)
    invalid = run([sys.executable, "-m", "sofac"], "inspect", "invalid.scn", cwd=tmp_path)
    assert invalid.returncode == 1 and "E200" in invalid.stderr
    assert "NoSuchComponentAtAll" in invalid.stdout  # the tree is still shown


@needs_parse
@pytest.mark.skipif(
    not (REPO / "scenes" / "hybrid_pendulum.scn").is_file(), reason="bundled scene not written yet"
)
def test_demo_scene_checks_clean() -> None:
    result = run([sys.executable, "-m", "sofac"], "check", "scenes/hybrid_pendulum.scn", cwd=REPO)
    assert result.returncode == 0, result.stdout + result.stderr
