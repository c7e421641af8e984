"""sofac regress: the list, SOFA's pass criterion, the statuses, the table and the command line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from fakesim import FakeInfo, FakeView, FallingSim, regression_loader, two_body_sim
from sofac.cli import main as cli
from sofac.regress import suite as regress
from sofac.regress.states import StateBlock, export_states, read_state_file, write_state_file
from sofac.regress.suite import (
    RegressionEntry,
    RegressionListError,
    Status,
    compare_vec,
    due_steps,
    format_markdown,
    format_table,
    parse_regression_list,
    reference_files,
    results_as_json,
    run_regression,
    run_scene,
    state_file_error,
    summary_line,
)

# Hand-made references for fakesim.two_body_sim() (dt 0.5, gravity (0, -2, 0)), 4 steps, LAST_ONLY:
# blocks at T=0 (exact states) and T=1.5 (after 3 steps, a few scalars off by known amounts).
DOFS_REFERENCE = """T= 0
  X= 0 0 0 1 2 3
  V= 1 0 0 0 0 0
T= 1.5
  X= 1.5 -2.25 0 1 -0.25 3.06
  V= 1 -3 0 0 -3 0.12
"""
MO1_REFERENCE = """T= 0
  X= 5 5 5
T= 1.5
  X= 5 4.25 5.3
"""
# dofs (2 DOFs): err_X = 0.06/6 = 0.01, err_V = 0.12/6 = 0.02 at T=1.5 -> dofError (0.01+0.02)/2 = 0.015
# MechanicalObject1 (1 DOF, no V): err_X = 0.3/3 = 0.1 -> dofError 0.1
# scene: (0.015 + 0.1) / 2 states = 0.0575
HAND_ERROR = 0.0575

LIST_TEXT = """# a comment
### References relative path ###
$REGRESSION_DIR/references/examples

fall/two.scn 4 0.06 0 1
fall/tight.scn 4 0.05 0 1
fall/unsupported.scn 4 1e-4 0 1
fall/invalid.scn 4 1e-4 0 1
fall/diverging.scn 4 1e-4 0 1
fall/noref.scn 4 1e-4 0 1
"""


@pytest.fixture()
def mini(tmp_path: Path) -> Path:
    """A regression list with its scenes and references, in the shared folder's layout."""
    (tmp_path / "scenes.regression-tests").write_text(LIST_TEXT)
    scenes = tmp_path / "scenes" / "fall"
    scenes.mkdir(parents=True)
    for name in ("two", "tight", "unsupported", "invalid", "diverging", "noref", "crash"):
        (scenes / f"{name}.scn").write_text("<Node/>")
    refs = tmp_path / "fall"
    refs.mkdir()
    for name in ("two", "tight", "unsupported", "invalid", "diverging", "crash"):
        (refs / f"{name}.scn.reference").write_text("")
        write_refs(refs / f"{name}.scn.reference_0_dofs_mstate.txt.gz", DOFS_REFERENCE)
        write_refs(refs / f"{name}.scn.reference_1_MechanicalObject1_mstate.txt.gz", MO1_REFERENCE)
    return tmp_path


def write_refs(path: Path, text: str) -> None:
    from sofac.regress.states import parse_state_text

    write_state_file(path, parse_state_text(text), precision=6)


def entry(scene: str, epsilon: float = 0.06, steps: int = 4) -> RegressionEntry:
    return RegressionEntry(scene, steps, epsilon, False, True)


# --- the list ---------------------------------------------------------------------------------------


def test_shared_list_has_87_scenes(shared_dir: Path) -> None:
    reg = parse_regression_list(shared_dir / "reference" / "sofa-regression" / "scenes.regression-tests")
    assert len(reg.entries) == 87
    assert reg.reference_folder == "$REGRESSION_DIR/references/examples"
    first = reg.entries[0]
    assert (first.scene, first.steps, first.epsilon, first.mapped, first.last_only) == (
        "Demos/TriangleSurfaceCutting.scn",
        100,
        1e-4,
        True,
        True,
    )
    euler = next(e for e in reg.entries if e.scene.endswith("Forward/EulerExplicitSolver.scn"))
    assert (euler.steps, euler.epsilon, euler.mapped, euler.last_only) == (3000, 1e-4, False, True)
    assert sum(e.mapped for e in reg.entries) == 10
    for e in reg.entries:  # every scene has its reference files and its scene file
        assert reference_files(shared_dir / "reference" / "sofa-regression", e.scene), e.scene
        assert (shared_dir / "corpus" / "sofa" / e.scene).is_file(), e.scene


@pytest.mark.parametrize(
    "text",
    [
        "",
        "# only comments\n",
        "folder\nscene.scn 100 1e-4 0\n",
        "folder\nscene.scn ten 1e-4 0 1\n",
        "folder\nscene.scn 100 1e-4 2 1\n",
        "folder\nscene.scn 0 1e-4 0 1\n",
        "a b\n",
    ],
)
def test_malformed_lists(tmp_path: Path, text: str) -> None:
    (tmp_path / "list").write_text(text)
    with pytest.raises(RegressionListError):
        parse_regression_list(tmp_path / "list")


# --- the criterion ----------------------------------------------------------------------------------


def test_compare_vec_is_sofas() -> None:
    assert compare_vec(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.5, 2.0])) == pytest.approx(0.5)
    # SOFA compares the printed current values (6 significant digits): 1.0000004 reads as 1.
    assert compare_vec(np.array([1.0000004, 2.0]), np.array([1.0, 2.0])) == 0.0
    assert compare_vec(np.array([1.000006]), np.array([1.0])) == pytest.approx(1e-5)  # prints 1.00001
    # Only the common scalars count; nothing to compare gives 0.
    assert compare_vec(np.array([1.0, 2.0, 9.0]), np.array([1.0, 3.0])) == pytest.approx(0.5)
    assert compare_vec(np.array([]), np.array([])) == 0.0


def test_due_steps_follow_comparestate() -> None:
    # LAST_ONLY: 3000 steps of 1e-5 -> compared at the beginning of steps 0 and 2999.
    assert due_steps([0.0, 0.02999], 1e-5, 3000) == {0: 0, 2999: 1}
    # 6-digit stamps of a dt that is not round: 99 * 0.03333 prints as 3.29967.
    assert due_steps([0.0, 3.29967], 0.03333, 100) == {0: 0, 99: 1}
    # A block due after the last step is never compared; two due at one step: the later one.
    assert due_steps([0.0, 1.0, 1.0004, 5.0], 0.5, 4) == {0: 0, 2: 2}
    assert due_steps([0.0, 0.25], 0.5, 4) == {0: 0, 1: 1}
    assert due_steps([0.0, math.inf, math.nan], 0.5, 4) == {0: 0}


def test_hand_made_pair_of_files(tmp_path: Path) -> None:
    sim = two_body_sim()
    ours = export_states(sim, 4, tmp_path / "ours")
    write_refs(tmp_path / "dofs.txt.gz", DOFS_REFERENCE)
    write_refs(tmp_path / "mo1.txt.gz", MO1_REFERENCE)
    dofs_error, frames = state_file_error(
        read_state_file(ours[0]), read_state_file(tmp_path / "dofs.txt.gz"), 2
    )
    assert frames == 2 and dofs_error == pytest.approx(0.015, rel=1e-12)
    mo1_error, frames = state_file_error(
        read_state_file(ours[1]), read_state_file(tmp_path / "mo1.txt.gz"), 1
    )
    assert frames == 2 and mo1_error == pytest.approx(0.1, rel=1e-12)
    assert (dofs_error + mo1_error) / 2 == pytest.approx(HAND_ERROR, rel=1e-12)
    # Blocks without a partner time are not compared.
    late = [StateBlock(7.0, {"X": np.zeros(6)})]
    assert state_file_error(read_state_file(ours[0]), late, 2) == (0.0, 0)


def test_scene_criterion_equals_hand_value(mini: Path) -> None:
    result = run_scene(entry("fall/two.scn"), mini / "scenes", mini, loader=regression_loader)
    assert result.status is Status.PASS, result.message
    assert result.error == pytest.approx(HAND_ERROR, rel=1e-12)
    assert [(s.k, s.name, s.frames, s.dofs) for s in result.states] == [
        (0, "dofs", 2, 2),
        (1, "MechanicalObject1", 2, 1),
    ]
    assert result.states[0].error_x == pytest.approx(0.01) and result.states[0].error_v == pytest.approx(0.02)
    # Stricter figure: largest position difference (0.3) over the reference bounding-box diagonal.
    diagonal = math.sqrt(5.0**2 + 7.25**2 + 5.3**2)
    assert result.max_rel == pytest.approx(0.3 / diagonal)
    # Compared at the beginning of steps 0 and 3; the 4th step is never compared, so never run.
    sims: list[FallingSim] = []
    run_scene(
        entry("fall/two.scn"), mini / "scenes", mini, loader=lambda p: sims.append(two_body_sim()) or sims[0]
    )
    assert sims[0].step_calls == [3]
    tight = run_scene(entry("fall/two.scn", epsilon=0.05), mini / "scenes", mini, loader=regression_loader)
    assert tight.status is Status.FAIL and tight.message == "error 0.0575 > epsilon 0.05"


def test_statuses(mini: Path) -> None:
    def run(name: str) -> regress.SceneResult:
        return run_scene(entry(f"fall/{name}.scn"), mini / "scenes", mini, loader=regression_loader)

    unsupported = run("unsupported")
    assert unsupported.status is Status.UNSUPPORTED
    assert unsupported.component == "TriangleCollisionModel"  # the first one in the file
    assert unsupported.location is not None and unsupported.location.endswith("fall/unsupported.scn:9")
    assert unsupported.unsupported == ["MeshMatrixMass", "TriangleCollisionModel"]
    invalid = run("invalid")
    assert invalid.status is Status.ERROR and "E219" in invalid.message and "liver.msh" in invalid.message
    diverging = run("diverging")
    assert diverging.status is Status.ERROR and "diverged" in diverging.message
    missing = run("noref")
    assert missing.status is Status.MISSING and "no reference files" in missing.message
    no_scene = run_scene(entry("fall/absent.scn"), mini / "scenes", mini, loader=regression_loader)
    assert no_scene.status is Status.MISSING and "scene file not found" in no_scene.message

    def broken(path: Path) -> object:
        raise ZeroDivisionError("oops")

    bug = run_scene(entry("fall/two.scn"), mini / "scenes", mini, loader=broken)  # type: ignore[arg-type]
    assert bug.status is Status.ERROR and bug.message == "internal error: ZeroDivisionError: oops"


def test_states_must_pair_with_the_references(mini: Path) -> None:
    def renamed(path: Path) -> object:
        sim = two_body_sim()
        info, x0, v0 = sim._states[2]
        sim._states[2] = (FakeInfo(info.path, "MechanicalObject3"), x0, v0)
        return sim

    result = run_scene(entry("fall/two.scn"), mini / "scenes", mini, loader=renamed)  # type: ignore[arg-type]
    assert result.status is Status.ERROR
    assert "MechanicalObject3" in result.message and "MechanicalObject1" in result.message

    def resized(path: Path) -> object:
        sim = two_body_sim()
        info = sim._states[2][0]
        sim._states[2] = (info, np.zeros((2, 3)), np.zeros((2, 3)))
        return sim

    result = run_scene(entry("fall/two.scn"), mini / "scenes", mini, loader=resized)  # type: ignore[arg-type]
    assert result.status is Status.FAIL and "X has 6 scalars, the reference 3" in result.message


def test_non_finite_state_fails(mini: Path) -> None:
    class NaNSim:
        dt = 0.5
        time = 0.0

        def __init__(self) -> None:
            self.inner = two_body_sim()

        def states(self) -> list[FakeInfo]:
            return self.inner.states()

        def step(self, n: int = 1) -> None:
            self.inner.step(n)

        def __getitem__(self, path: str) -> FakeView:
            view = self.inner[path]
            if self.inner.steps_done:
                view.position[0, 0] = math.nan
            return view

    result = run_scene(entry("fall/two.scn"), mini / "scenes", mini, loader=lambda p: NaNSim())  # type: ignore[arg-type,return-value]
    assert result.status is Status.FAIL and "non-finite X" in result.message
    assert result.error == math.inf
    json.loads(results_as_json([result]))  # inf is written as a string, the JSON stays valid


def test_perfect_replay_of_a_real_scene(shared_dir: Path) -> None:
    """A stand-in that replays SOFA's own reference states passes with error 0 (real list, files
    and times: Demos/liver.scn, MAPPED=1, 100 steps of 0.02, blocks at T=0 and T=1.98)."""
    ref_root = shared_dir / "reference" / "sofa-regression"
    refs = reference_files(ref_root, "Demos/liver.scn")
    recorded = [read_state_file(r.path) for r in refs]

    class Replay:
        dt = 0.02

        def __init__(self) -> None:
            self.steps_done = 0
            self.time = 0.0

        def states(self) -> list[FakeInfo]:
            return [FakeInfo(f"/s{r.k}", r.name, mapped=r.k > 0) for r in refs]

        def step(self, n: int = 1) -> None:
            self.steps_done += n
            self.time = self.steps_done * self.dt

        def __getitem__(self, path: str) -> FakeView:
            blocks = recorded[int(path[2:])]
            block = next((b for b in blocks if round(b.time / self.dt) == self.steps_done), blocks[0])
            return FakeView(block.x.reshape(-1, 3), block.v.reshape(-1, 3))

    results = run_regression(
        ref_root / "scenes.regression-tests",
        shared_dir / "corpus" / "sofa",
        ref_root,
        only=["Demos/liver.scn"],
        loader=lambda path: Replay(),  # type: ignore[arg-type,return-value]
    )
    assert len(results) == 1
    (result,) = results
    assert result.status is Status.PASS and result.error == 0.0 and result.max_rel == 0.0
    assert [(s.name, s.frames, s.dofs) for s in result.states] == [("dofs", 2, 181), ("spheres", 2, 34)]


# --- the whole list, reports --------------------------------------------------------------------------


def test_run_regression_table_and_json(mini: Path) -> None:
    seen: list[str] = []
    results = run_regression(
        mini / "scenes.regression-tests",
        mini / "scenes",
        mini,
        loader=regression_loader,
        progress=lambda r: seen.append(r.scene),
    )
    assert [r.status for r in results] == [
        Status.PASS,
        Status.FAIL,
        Status.UNSUPPORTED,
        Status.ERROR,
        Status.ERROR,
        Status.MISSING,
    ]
    assert seen == [r.scene for r in results]
    assert summary_line(results) == "1/6 pass (1 fail, 1 unsupported, 2 error, 1 missing)"
    table = format_table(results)
    assert table.splitlines()[0].split()[:6] == ["SCENE", "STATUS", "ERROR", "EPSILON", "MAX/BBOX", "TIME"]
    assert "TriangleCollisionModel at " in table and "(+1 more: MeshMatrixMass)" in table
    assert table.rstrip().endswith("1/6 pass (1 fail, 1 unsupported, 2 error, 1 missing)")
    markdown = format_markdown(results).splitlines()
    assert markdown[0].startswith("| scene | status |") and len(markdown) == 2 + len(results) + 2
    assert markdown[2].startswith(f"| {results[0].scene} | PASS |")
    document = json.loads(results_as_json(results, mini / "scenes.regression-tests"))
    assert document["summary"]["pass"] == 1 and document["summary"]["total"] == 6
    assert document["results"][0]["states"][1]["name"] == "MechanicalObject1"
    only = run_regression(
        mini / "scenes.regression-tests",
        mini / "scenes",
        mini,
        only=["two", "tight"],
        loader=regression_loader,
    )
    assert [r.scene for r in only] == ["fall/two.scn", "fall/tight.scn"]


def test_parallel_runs_isolate_crashes(mini: Path) -> None:
    text = LIST_TEXT + "fall/crash.scn 4 1e-4 0 1\n"
    (mini / "scenes.regression-tests").write_text(text)
    results = run_regression(
        mini / "scenes.regression-tests",
        mini / "scenes",
        mini,
        only=["two", "crash", "unsupported"],
        jobs=3,
        loader=regression_loader,
    )
    assert [(r.scene, r.status) for r in results] == [
        ("fall/two.scn", Status.PASS),
        ("fall/unsupported.scn", Status.UNSUPPORTED),
        ("fall/crash.scn", Status.ERROR),
    ]
    assert results[0].error == pytest.approx(HAND_ERROR)
    assert "crashed" in results[2].message and "exit code 3" in results[2].message


# --- command line -------------------------------------------------------------------------------------


def _regress(mini: Path, *extra: str) -> int:
    return cli.main(
        ["regress", str(mini / "scenes.regression-tests"), "--scenes", str(mini / "scenes"), *extra]
    )


def test_cli_exit_codes(
    mini: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(regress, "_default_loader", regression_loader)
    assert _regress(mini, "--only", "two.scn") == 0
    assert "1/1 pass" in capsys.readouterr().out
    assert _regress(mini, "--only", "two.scn", "unsupported") == 0  # UNSUPPORTED is not a failure...
    assert _regress(mini, "--only", "two.scn", "unsupported", "--strict") == 1  # ...unless --strict
    capsys.readouterr()
    assert _regress(mini, "--format", "json") == 1
    document = json.loads(capsys.readouterr().out)
    assert document["summary"] == {
        "pass": 1,
        "total": 6,
        "counts": {"PASS": 1, "FAIL": 1, "UNSUPPORTED": 1, "ERROR": 2, "MISSING": 1},
    }
    assert _regress(mini, "--only", "nothing-like-this") == 2
    assert "E002" in capsys.readouterr().err
    assert cli.main(["regress", str(mini / "absent.list")]) == 2
    assert _regress(mini, "--references", str(mini / "absent")) == 2
    assert _regress(mini, "--jobs", "0") == 2


def test_cli_defaults_point_at_the_shared_folder(monkeypatch: pytest.MonkeyPatch, shared_dir: Path) -> None:
    monkeypatch.delenv("SOFAC_SHARED", raising=False)
    assert regress.repository_root() == Path(cli.__file__).resolve().parents[2]
    assert regress.shared_root() == regress.repository_root().parent / "shared"
    monkeypatch.setenv("SOFAC_SHARED", str(shared_dir))
    assert regress.default_list() == shared_dir / "reference" / "sofa-regression" / "scenes.regression-tests"
    assert regress.default_list().is_file()
    assert regress.default_scenes_root() == shared_dir / "corpus" / "sofa"
    assert regress.default_reference_root(regress.default_list()) == regress.default_list().resolve().parent
