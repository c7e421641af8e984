"""What a new user tripped on (issue #20): each test reproduces one defect of that list."""

from __future__ import annotations

import errno
import io
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.cache_errors import CacheNotWritable
from sofac.cli.main import main
from sofac.param_rules import InvalidParameter, ParamRule, check
from sofac.pipeline import compile_scene
from sofac.resources import bundled_scene
from sofac.scene_warnings import SceneWarning, StrictSceneError
from sofac.sweeps import runner as sweeps

SPRING = '<SpringForceField template="Vec3d" name="spring" spring="0 1 100 0 1"/>'


def oscillator(folder: Path, replace: tuple[str, str] | None = None, name: str = "oscillator.scn") -> Path:
    """The bundled oscillator (one spring, explicit Euler), with one piece of text replaced."""
    text = bundled_scene("oscillator.scn").read_text()
    if replace is not None:
        assert replace[0] in text
        text = text.replace(*replace)
    path = folder / name
    path.write_text(text)
    return path


def typo_scene(folder: Path) -> Path:
    """The oscillator with a misspelt attribute (W203) on its spring, at line 31."""
    return oscillator(folder, (' name="spring" ', ' name="spring" stifness="3" '), "typo.scn")


W203 = re.compile(
    r"typo\.scn:31: warning W203 \[stifness\]: .*'stifness'\n    hint: did you mean 'stiffness'\?"
)


# --- 1. warnings shown by every command, SceneWarning from load, strict ---------------------------


def test_load_issues_scene_warnings_cold_and_warm(tmp_path: Path) -> None:
    path = typo_scene(tmp_path)
    for _ in range(2):  # compiled, then from the warm record
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sim = sofac.load(path)
        found = [w for w in caught if issubclass(w.category, SceneWarning)]
        assert len(found) == 1
        assert W203.search(str(found[0].message))
        assert found[0].message.diagnostic.code == "W203"  # type: ignore[union-attr]
        assert found[0].filename == __file__  # points at the caller's load()
    assert sim.compiled.warm


def test_load_strict_raises_with_every_warning(tmp_path: Path) -> None:
    path = typo_scene(tmp_path)
    with pytest.raises(StrictSceneError) as raised:
        sofac.load(path, strict=True)
    assert [d.code for d in raised.value.diagnostics] == ["W203"]
    assert "strict" in str(raised.value)
    with pytest.warns(SceneWarning):
        sofac.load(path)  # compiled and recorded warm
    with pytest.raises(StrictSceneError):
        sofac.load(path, strict=True)


def test_scene_warning_can_be_an_error_through_the_warnings_module(tmp_path: Path) -> None:
    path = typo_scene(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        with pytest.raises(SceneWarning):
            sofac.load(path)


@pytest.mark.parametrize(
    "command",
    [
        ["run", "--steps", "2"],
        ["compile"],
        ["emit"],
        ["inspect", "--schedule"],
        ["inspect", "--effects"],
        ["inspect"],
        ["check"],
    ],
)
def test_every_command_prints_the_warnings_once_and_strict_fails(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    path = typo_scene(tmp_path)
    assert main([*command, str(path)]) == 0
    out, err = capsys.readouterr()
    assert len(W203.findall(err + out)) == 1, err
    assert main([*command, str(path), "--strict"]) == 1
    out, err = capsys.readouterr()
    assert W203.search(err + out)


def test_render_prints_the_warnings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = typo_scene(tmp_path)
    assert main(["render", str(path), "--out", str(tmp_path / "a.png"), "--no-progress"]) == 0
    assert len(W203.findall(capsys.readouterr().err)) == 1
    assert main(["render", str(path), "--out", str(tmp_path / "b.png"), "--strict"]) == 1
    assert not (tmp_path / "b.png").exists()


def test_sweep_prints_the_warnings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = typo_scene(tmp_path)
    args = ["sweep", str(path), "--param", "spring.stiffness=50,100", "--steps", "5", "--no-plot"]
    args += ["--scheduler", "synchronous", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "s.nc")]) == 0
    assert len(W203.findall(capsys.readouterr().err)) == 1
    assert main([*args, "--out", str(tmp_path / "t.nc"), "--strict"]) == 1
    assert W203.search(capsys.readouterr().err)
    assert not (tmp_path / "t.nc").exists()


# --- 2. values set at run time get the registry's field rules ----------------------------------


def test_a_negative_or_zero_dt_set_at_run_time_is_refused(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    sim.param("/.dt")[:] = -0.01
    with pytest.raises(
        InvalidParameter, match=r"^E207: /\.dt = -0\.01 must be > 0 \(the root node \(.*:15\)\)"
    ):
        sim.step(1)
    assert sim.steps == 0 and sim.time == 0.0  # nothing ran backwards
    with pytest.raises(InvalidParameter, match=r"E207: /\.dt = 0 must be > 0"):
        sim.dt = 0
    sim.param("/.dt")[:] = 0.002
    sim.step(2)
    assert sim.time == pytest.approx(0.004)


def test_a_negative_mass_or_a_nan_set_at_run_time_is_refused(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    sim.param("/oscillator/mass.vertexMass")[:] = -1.0
    with pytest.raises(
        InvalidParameter, match=r"E207: /oscillator/mass\.vertexMass = -1 must be > 0 \(a mass\)"
    ):
        sim.reset()
    with pytest.raises(InvalidParameter) as raised:
        sim.step(1)
    assert raised.value.key == "/oscillator/mass.vertexMass" and raised.value.code == "E207"
    sim.param("/oscillator/mass.vertexMass")[:] = 2.0
    sim.param("/oscillator/spring.lengths")[:] = np.nan
    with pytest.raises(InvalidParameter, match=r"E206: /oscillator/spring\.lengths = nan is not finite"):
        sim.step(1)


def test_the_poisson_ratio_rule_is_the_registry_s() -> None:
    rule = ParamRule(
        "HexahedronFEMForceField", "poissonRatio", "HexahedronFEMForceField '/beam/fem' (b.scn:9)"
    )
    check("/beam/fem.poissonRatio", np.array([0.3]), rule)
    with pytest.raises(
        InvalidParameter, match=r"poissonRatio = 0\.7 must be in \(-1, 0\.5\) \(Hexa.*b\.scn:9\)\)"
    ):
        check("/beam/fem.poissonRatio", np.array([0.7]), rule)
    many = np.full(5, 1e5)
    many[3] = -2.0
    young = ParamRule("HexahedronFEMForceField", "youngModulus", "x")
    with pytest.raises(InvalidParameter, match=r"youngModulus\[3\] = -2 must be > 0"):
        check("/beam/fem.youngModulus", many, young)


def test_a_sweep_records_invalid_runs_and_goes_on(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = oscillator(tmp_path)
    dataset = sofac.sweep(
        path,
        {"/.dt": [-0.001, 0.001], "mass.vertexMass": [-1.0, 1.0]},
        steps=10,
        scheduler="synchronous",
    )
    statuses = [str(s) for s in dataset["status"].values]
    assert statuses == ["invalid", "invalid", "invalid", "ok"]
    messages = [str(m) for m in dataset["message"].values]
    assert messages[0].startswith("E207: /.dt = -0.001 must be > 0")
    assert messages[2].startswith("E207: /oscillator/mass.vertexMass = -1 must be > 0")
    assert dataset["time"].values[3][-1] == pytest.approx(0.01)
    table = sofac.sweep(
        path, table=[{"mass.vertexMass": 0.0}, {"mass.vertexMass": 2.0}], steps=5, scheduler="synchronous"
    )
    assert [str(s) for s in table["status"].values] == ["invalid", "ok"]
    args = ["sweep", str(path), "--param", "/.dt=-0.001,0.001", "--steps", "5", "--no-plot"]
    assert main([*args, "--scheduler", "synchronous", "--no-progress", "--out", str(tmp_path / "s.nc")]) == 1
    assert "1 ok, 1 invalid" in capsys.readouterr().err


# --- 3. the last finite state: its real step, restored on request, a hint that fits ---------------

STIFF = ('spring="0 1 100 0 1"', 'spring="0 1 1e6 0 1"')  # unstable for explicit Euler at dt = 0.01
DOFS = "/oscillator/dofs"


def diverging(tmp_path: Path) -> sofac.Simulation:
    sim = sofac.load(oscillator(tmp_path, STIFF, "wild.scn"))
    sim.dt = 0.01
    return sim


def positions_after(tmp_path: Path, steps: int) -> np.ndarray:
    """The state after ``steps`` steps, from a fresh instance stepped one step at a time."""
    sim = diverging(tmp_path)
    for _ in range(steps):
        sim.step(1)
    return sim[DOFS].position.copy()


@pytest.mark.parametrize("chunk", [1000, 30])
def test_the_last_finite_state_is_the_step_before_the_failure(tmp_path: Path, chunk: int) -> None:
    sim = diverging(tmp_path)
    sim.chunk = chunk
    with pytest.raises(sofac.SimulationDiverged) as raised:
        sim.step(1000)
    error = raised.value
    assert error.step == 79 and error.last_finite_step == 78
    assert error.last_finite_time == pytest.approx(0.78)
    assert "last finite state: step 78 (t=0.78)" in str(error)
    expected = positions_after(tmp_path, 78)
    assert np.isfinite(expected).all() and abs(expected[1, 0]) > 1e100
    assert error.last_finite is not None
    assert np.array_equal(error.last_finite[DOFS][0], expected)
    assert not np.isfinite(sim[DOFS].position).all()  # the live arrays keep the failing step
    assert sim.restore_last_finite() == 78
    assert sim.steps == 78 and sim.time == pytest.approx(0.78)
    assert np.array_equal(sim[DOFS].position, expected)


def test_the_last_state_within_the_energy_bound(tmp_path: Path) -> None:
    probe = diverging(tmp_path)
    energies = []
    for _ in range(60):
        probe.step(1)
        energies.append(probe.energy().total)
    bound = energies[40]  # steps 1..41 stay within it, step 42 passes it
    assert energies[41] > bound
    sim = diverging(tmp_path)
    with pytest.raises(sofac.SimulationDiverged) as raised:
        sim.step(60, energy_bound=bound)
    assert raised.value.reason == "energy" and raised.value.step == 60
    assert raised.value.last_finite_step == 41
    sim.restore_last_finite()
    assert sim.energy().total == bound


def test_a_state_broken_before_the_call_gets_a_hint_that_fits(tmp_path: Path) -> None:
    sim = diverging(tmp_path)
    sim[DOFS].position[1, 0] = np.nan
    with pytest.raises(sofac.SimulationDiverged) as raised:
        sim.step(5)
    assert "smaller dt" not in raised.value.hint
    assert "already not finite before this call" in raised.value.hint
    assert raised.value.last_finite is None
    with pytest.raises(sofac.SofacError, match="no finite state is kept"):
        sim.restore_last_finite()


def test_a_nan_dt_is_refused_not_reported_as_a_divergence(tmp_path: Path) -> None:
    sim = diverging(tmp_path)
    sim.param("/.dt")[:] = np.nan
    with pytest.raises(InvalidParameter, match=r"E206: /\.dt = nan is not finite"):
        sim.step(5)


def test_run_reports_the_real_last_finite_step(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = oscillator(tmp_path, STIFF, "wild.scn")
    assert main(["run", str(path), "--dt", "0.01", "--steps", "1000"]) == 1
    err = capsys.readouterr().err
    assert "diverged at step 79" in err and "sofac: the last finite state (step 78, t=0.78):" in err


# --- 5. inspect agrees with itself; no numpy repr in what a user reads ---------------------------


def test_effects_and_schedule_agree_on_the_linear_solver(capsys: pytest.CaptureFixture[str]) -> None:
    liver = str(bundled_scene("liver.scn"))
    assert main(["inspect", liver, "--effects"]) == 0
    effects = capsys.readouterr().out
    assert re.search(
        r"^linear_solve +CGLinearSolver '/Liver/linearsolver' \(.*liver\.scn:42\)", effects, re.M
    )
    assert "CGLinearSolver '/Liver/linearsolver'" not in "".join(
        line for line in effects.splitlines() if line.startswith("kept out")
    )
    assert main(["inspect", liver, "--schedule"]) == 0
    schedule = capsys.readouterr().out
    assert "with CGLinearSolver '/Liver/linearsolver'" in schedule
    assert "kept out of the step: CGLinearSolver" not in schedule
    assert "\ndt = 0.02, gravity = [0.0, -9.81, 0.0]\n" in schedule


SWEEP_OPTIONS = ("--no-plot", "--scheduler", "synchronous", "--no-progress")
NUMPY_REPR = re.compile(r"\bnp\.\w+\(|\barray\(|\bdtype=")


def test_no_numpy_repr_reaches_any_command_output(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = str(oscillator(tmp_path))
    liver = str(bundled_scene("liver.scn"))
    commands = [
        ["check", scene],
        ["check", scene, "--format", "json"],
        ["inspect", liver],
        ["inspect", liver, "--format", "json"],
        ["inspect", liver, "--schedule"],
        ["inspect", liver, "--effects"],
        ["inspect", liver, "--effects", "--format", "json"],
        ["inspect", "--components"],
        ["compile", scene],
        ["run", scene, "--steps", "3"],
        ["run", scene, "--steps", "3", "--dt", "1e-4"],
        ["render", scene, "--out", str(tmp_path / "o.png"), "--no-progress"],
        [
            "sweep",
            scene,
            "--param",
            "spring.stiffness=50,100",
            "--steps",
            "3",
            *SWEEP_OPTIONS,
            f"--out={tmp_path}/s.nc",
        ],
    ]
    for command in commands:
        assert main(command) == 0, command
        out, err = capsys.readouterr()
        assert not NUMPY_REPR.search(out + err), (command, NUMPY_REPR.search(out + err))
    sim = sofac.load(scene)
    for bad in (
        lambda: sim.guard_energy(np.float64(-1.0)),
        lambda: sim.guard_energy(1.0, scale=np.float64(-2)),
    ):
        with pytest.raises(ValueError) as raised:
            bad()
        assert not NUMPY_REPR.search(str(raised.value))


# --- 8. one path rule for states, parameters, outputs, sweep and record keys ---------------------


def test_every_path_takes_the_same_forms(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    for form in ("/oscillator/spring.stiffness", "oscillator/spring.stiffness", "spring.stiffness"):
        assert sim.param(form) is sim.param("/oscillator/spring.stiffness"), form
    for form in ("/oscillator/dofs", "oscillator/dofs", "dofs"):
        assert sim[form] is sim["/oscillator/dofs"], form
    for form in ("/.dt", ".dt"):
        assert sim.param(form)[0] == 0.001
    assert sim.output("dofs.position").shape == (6,)  # output keys: "<state path>.position"
    assert sweeps.resolve_parameter("spring.stiffness", {k: 1 for k in sim.params()}).key == (
        "/oscillator/spring.stiffness"
    )
    record = sweeps.resolve_record("oscillator/dofs.position", {"/oscillator/dofs": 2})
    assert record.state == "/oscillator/dofs"


def test_a_missed_path_says_what_was_meant(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    with pytest.raises(KeyError) as raised:
        sim.param("sprung.stiffness")
    message = str(raised.value)
    assert message.startswith("no parameter 'sprung.stiffness'; did you mean '/oscillator/spring.stiffness'?")
    assert "the scene has: /.dt, /.gravity, /oscillator/mass.vertexMass" in message
    with pytest.raises(KeyError, match=r"did you mean '/oscillator/dofs'\?"):
        sim["oscillator/dof"]
    with pytest.raises(
        KeyError, match=r"^no output 'dofs.positio'; did you mean '/oscillator/dofs.position'\?"
    ):
        sim.output("dofs.positio")
    with pytest.raises(sweeps.SweepError, match=r"no tunable parameter 'sprung.stiffness'; did you mean"):
        sweeps.resolve_parameter("sprung.stiffness", {k: 1 for k in sim.params()})


# --- 10. threads stepping one instance are serialised ------------------------------------------


def test_threads_stepping_one_instance_get_the_serial_result() -> None:
    import threading

    liver = bundled_scene("liver.scn")
    serial = sofac.load(liver)
    serial.step(200)
    shared = sofac.load(liver)
    threads = [threading.Thread(target=lambda: [shared.step(1) for _ in range(50)]) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert shared.steps == 200 and shared.time == pytest.approx(serial.time)
    assert np.array_equal(shared["/Liver/dofs"].position, serial["/Liver/dofs"].position)
    assert np.array_equal(shared["/Liver/dofs"].velocity, serial["/Liver/dofs"].velocity)


# --- 16. small things: non-integer steps, missing data roots, a non-string path -------------------


def test_step_refuses_a_fraction_of_a_step(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    with pytest.raises(TypeError, match=r"n is a whole number of steps, got float 1\.5"):
        sim.step(1.5)  # type: ignore[arg-type]
    sim.step(np.int64(2))
    assert sim.steps == 2


def test_load_refuses_a_missing_data_root(tmp_path: Path) -> None:
    with pytest.raises(sofac.SofacError, match=r"data_roots: /nonexistent: no such folder"):
        sofac.load(oscillator(tmp_path), data_roots=[Path("/nonexistent")])


def test_a_state_is_named_by_a_string(tmp_path: Path) -> None:
    sim = sofac.load(oscillator(tmp_path))
    with pytest.raises(
        TypeError, match=r"a MechanicalObject is named by its path, a string, such as '/oscillator/dofs'"
    ):
        sim[None]  # type: ignore[index]


# --- 11. a file name longer than the system allows ------------------------------------------------


def test_a_mesh_name_longer_than_255_bytes_is_a_missing_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    long_name = "m" * 300 + ".msh"
    path = tmp_path / "long.scn"
    path.write_text(bundled_scene("liver.scn").read_text().replace("liver.msh", long_name))
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "<MeshGmshLoader" in text)
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"long.scn:{line}: error E219 [filename]: MeshGmshLoader 'meshLoader': file '{long_name}'" in out
    assert "hint: a file or folder name has at most 255 bytes: shorten it" in out
    with pytest.raises(sofac.SceneError, match="E219"):
        sofac.load(path)


# --- 12. sizes read from a scene are bounded before anything is allocated -----------------------

BEAM_GRID = 'n="11 3 3"'


def beam(folder: Path, replace: tuple[str, str]) -> Path:
    text = bundled_scene("beam.scn").read_text()
    assert replace[0] in text
    path = folder / "beam.scn"
    path.write_text(text.replace(*replace))
    return path


def grid_line(path: Path) -> int:
    return next(i for i, t in enumerate(path.read_text().splitlines(), 1) if "<RegularGridTopology" in t)


def check_output(path: Path, capsys: pytest.CaptureFixture[str], status: int = 1) -> str:
    """``sofac check`` on ``path`` (address space capped at 4 GiB: a 16 GiB allocation fails)."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, hard))
    try:
        assert main(["check", str(path)]) == status
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
    return capsys.readouterr().out


@pytest.mark.parametrize(
    ("grid", "attribute", "points"),
    [
        ('nx="11" ny="3" nz="2147483648"', "nz", "11 x 3 x 2147483648 = 70866960384 points"),
        ('n="2147483647 2147483647 3"', "n", "2147483647 x 2147483647 x 3 = 13835058042397261827 points"),
    ],
)
def test_a_huge_grid_is_refused_before_it_is_allocated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], grid: str, attribute: str, points: str
) -> None:
    path = beam(tmp_path, (BEAM_GRID, grid))
    out = check_output(path, capsys)
    assert (
        f"beam.scn:{grid_line(path)}: error E207 [{attribute}]: RegularGridTopology 'grid': grid resolution "
        f"{points} is more than sofac generates (10000000); lower the resolution"
    ) in out


def test_a_huge_state_size_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = oscillator(tmp_path, (' position="0 0 0  1.1 0 0" velocity="0 0 0  0 0 0"', ' size="2147483648"'))
    out = check_output(path, capsys)
    assert (
        "oscillator.scn:28: error E207 [size]: MechanicalObject 'dofs': size='2147483648' must be at most"
        in out
    )


# --- 13. broken links in computed values, a scalar where points are expected --------------------


@pytest.mark.parametrize(
    ("replace", "message"),
    [
        (
            ('min="0 0 0"', 'min="@../x"'),
            "warning W233 [min]: RegularGridTopology 'grid': min=@../x points to nothing",
        ),
        (
            (BEAM_GRID, 'n="@nothere.n"'),
            "warning W233 [n]: RegularGridTopology 'grid': n=@nothere.n points to nothing",
        ),
        (
            (BEAM_GRID, 'n="@dofs.nothing"'),
            "warning W233 [n]: RegularGridTopology 'grid': n links to MechanicalObject 'dofs'",
        ),
        ((BEAM_GRID, 'n="@grid.n"'), "error E213 [n]: RegularGridTopology 'grid': n has no value known when"),
        (
            (BEAM_GRID, 'n="@mass.totalMass"'),
            "error E205 [n]: RegularGridTopology 'grid': n needs 3 numbers, its",
        ),
        (
            ('min="0 0 0"', 'min="@clamped.indices"'),
            "error E213 [min]: RegularGridTopology 'grid': min has no",
        ),
    ],
)
def test_a_broken_link_in_a_grid_is_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], replace: tuple[str, str], message: str
) -> None:
    path = beam(tmp_path, replace)
    out = check_output(path, capsys, status=0 if message.startswith("warning") else 1)
    assert f"beam.scn:{grid_line(path)}: {message}" in out


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (
            "0",
            "warning W225 [input_position]: TransformEngine 't': input_position: 1 numbers is not a multiple",
        ),
        (
            "@nothere.position",
            "warning W233 [input_position]: TransformEngine 't': input_position=@nothere.position",
        ),
    ],
)
def test_transform_engine_input_that_is_no_points(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str, message: str
) -> None:
    path = tmp_path / "t.scn"
    path.write_text(
        '<Node name="root" dt="0.01">\n  <Node name="n">\n'
        f'    <TransformEngine name="t" input_position="{value}" translation="1 0 0"/>\n'
        '    <MechanicalObject name="dofs" position="@t.output_position"/>\n  </Node>\n</Node>\n'
    )
    out = check_output(path, capsys, status=0 if message.startswith("warning") else 1)
    assert f"t.scn:3: {message}" in out


# --- 14. a cache folder that cannot be written -------------------------------------------------


def fresh_scene(folder: Path, tag: int) -> Path:
    """An oscillator no cache holds yet (its own dt, hence its own C++)."""
    return oscillator(folder, ('dt="0.001"', f'dt="0.00{tag}7"'), f"fresh{tag}.scn")


def refuse(error_number: int) -> object:
    def fail(*args: object, **kwargs: object) -> None:
        raise OSError(error_number, os.strerror(error_number), str(args[0]) if args else None)

    return fail


def test_a_full_cache_names_the_folder_and_the_fix(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from sofac.build import compiler as build

    monkeypatch.setattr(build.tempfile, "mkdtemp", refuse(errno.ENOSPC))
    path = fresh_scene(tmp_path, 1)
    with pytest.raises(
        CacheNotWritable, match=r"cannot write the compile cache .*: the disk is full"
    ) as raised:
        sofac.load(path)
    assert raised.value.folder == build.cache_dir()
    assert main(["run", str(path), "--steps", "1"]) == 1
    err = capsys.readouterr().err
    assert f"sofac: error: cannot write the compile cache {build.cache_dir()}: the disk is full" in err
    assert "set SOFAC_CACHE_DIR to a writable folder" in err and "internal error" not in err


def test_a_cache_path_that_is_a_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "cache"
    blocker.write_text("not a folder")
    monkeypatch.setenv("SOFAC_CACHE_DIR", str(blocker))
    with pytest.raises(CacheNotWritable, match=r"a file stands where a folder should be"):
        sofac.load(fresh_scene(tmp_path, 2))


def test_a_read_only_cache_still_runs_a_scene_loaded_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pathlib
    import tempfile

    path = oscillator(tmp_path)
    sofac.load(path).step(3)
    for owner, name in ((tempfile, "mkdtemp"), (tempfile, "mkstemp"), (pathlib.Path, "mkdir")):
        monkeypatch.setattr(owner, name, refuse(errno.EROFS))
    sim = sofac.load(path)
    assert sim.compiled.warm
    sim.step(3)
    assert sim.time == pytest.approx(0.003)


# --- 15. a killed compile leaves no compiler running and no build folder for long -------------


def processes_in(folder: Path) -> list[str]:
    """The processes whose working directory is inside ``folder`` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and Path(os.readlink(entry / "cwd")).is_relative_to(folder):
                found.append((entry / "comm").read_text().strip())
        except OSError:
            continue
    return found


@pytest.mark.skipif(not Path("/proc/self/cwd").exists(), reason="needs Linux /proc")
def test_kill_9_during_a_build_ends_the_compiler_and_the_next_build_cleans_up(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import signal
    import subprocess
    import sys
    import time

    cache = tmp_path / "cache"
    scene = oscillator(tmp_path)
    environment = {**os.environ, "SOFAC_CACHE_DIR": str(cache)}
    child = subprocess.Popen([sys.executable, "-m", "sofac", "compile", str(scene)], env=environment)
    deadline = time.monotonic() + 120
    while "cc1plus" not in processes_in(cache) and time.monotonic() < deadline:
        assert child.poll() is None, "the build ended before cc1plus was seen"
        time.sleep(0.05)
    assert "cc1plus" in processes_in(cache)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    deadline = time.monotonic() + 5  # cc1plus alone would run on for seconds
    while processes_in(cache) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert processes_in(cache) == []
    left = list((cache / "scenes").glob("build-*"))
    assert len(left) == 1  # killed half-way: its private folder stays until the next build
    monkeypatch.setenv("SOFAC_CACHE_DIR", str(cache))
    compiled = compile_scene(scene)
    assert compiled.built.library.is_file() and not compiled.built.cached
    assert not left[0].exists() and list((cache / "scenes").glob("build-*")) == []


# --- 4. never a blank picture without a word -------------------------------------------------------

NO_STYLE = ('<VisualStyle displayFlags="showBehaviorModels showForceFields"/>', "")


def test_render_without_visual_models_draws_the_dofs_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import imageio.v3 as iio

    path = oscillator(tmp_path, NO_STYLE)
    out = tmp_path / "o.png"
    assert main(["render", str(path), "--out", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "nothing in the scene would be drawn" in err and "choose the layers with --show" in err
    picture = iio.imread(out)
    assert len(np.unique(picture.reshape(-1, 3), axis=0)) > 1  # not one colour
    with pytest.warns(UserWarning, match="drawing the behavior models"):
        image = sofac.load(path).render(160, 120)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 1


def test_render_with_every_layer_hidden_fails_instead_of_a_blank_picture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = oscillator(tmp_path, NO_STYLE)
    out = tmp_path / "o.png"
    assert main(["render", str(path), "--out", str(out), "--hide", "behaviormodels", "--no-progress"]) == 1
    assert "sofac: error: nothing to draw:" in capsys.readouterr().err
    assert not out.exists()


# --- 6. long runs say where they are; Ctrl-C says where they stopped -----------------------------


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_run_bar_shows_steps_time_speed_and_eta() -> None:
    from sofac.cli.run_progress import StepBar

    bar = StepBar(1000, enabled=True, stream=Terminal())
    bar.started -= 2.0  # as if 2 s had passed
    line = bar.line(250, 5.0, 0.0)
    step, _, rest = line.partition(" t=5 ")
    assert step == "step 250/1000 (25%)"
    per_step, _, rest = rest.partition(" ms/step ")
    assert float(per_step) == pytest.approx(8.0, rel=0.01)  # 2 s / 250 steps
    assert rest.startswith("2.5x real time ETA 6s") or rest.startswith("2.49x real time ETA 6s")
    assert not StepBar(10, enabled=True, stream=io.StringIO()).enabled  # not a terminal: no bar
    assert not StepBar(10, enabled=False, stream=Terminal()).enabled  # --no-progress


def test_slices_grow_to_a_fifth_of_a_second_and_stop_on_request() -> None:
    import threading

    from sofac.cli.run_progress import Slicer, StepBar, run_in_slices

    slicer = Slicer()
    sizes = []
    for _ in range(8):
        sizes.append(slicer.next(10**9))
        slicer.took(sizes[-1], sizes[-1] * 1e-3)  # 1 ms a step
    assert sizes == [1, 4, 16, 64, 200, 200, 200, 200]
    calls: list[int] = []
    stop = threading.Event()

    def step(count: int) -> None:
        calls.append(count)
        if sum(calls) >= 5:
            stop.set()  # as Ctrl-C does, between two slices

    done = run_in_slices(step, 10**6, now=lambda: 0.0, bar=StepBar(10**6, False), stop=stop)
    assert done == sum(calls) >= 5 and done < 10**6


def test_ctrl_c_says_which_step_was_reached_and_what_was_written(tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys
    import time

    scene = oscillator(tmp_path)
    sofac.load(scene)  # compiled: the child loads it warm
    out = tmp_path / "states"
    command = [sys.executable, "-m", "sofac", "run", str(scene), "--steps", "1000000000", "--every", "100000"]
    child = subprocess.Popen(
        [*command, "--export-states", str(out)],
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while not list(out.glob("*_mstate.txt.gz")) and time.monotonic() < deadline:
        assert child.poll() is None
        time.sleep(0.05)
    time.sleep(0.5)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 130, err
    found = re.search(
        r"sofac: interrupted at step (\d+) of 1000000000 \(t=([\d.e+-]+)\); the state files in", err
    )
    assert found, err
    assert int(found.group(1)) > 0 and float(found.group(2)) == pytest.approx(int(found.group(1)) * 0.001)
    assert f"the state files in {out} (1) hold the records up to there" in err


# --- 7. the one-time host build says what it is, while it happens ---------------------------------


def test_a_build_is_announced_only_when_the_compiler_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from sofac.build import compiler as build

    monkeypatch.setenv("SOFAC_CACHE_DIR", str(tmp_path))
    calls: list[str] = []
    source = 'extern "C" int sofac_test_answer() { return 42; }\n'
    options = {"kind": "test", "name": "answer.so", "flags": ("-shared", "-fPIC"), "includes": ()}
    first = build.build(source, announce=lambda: calls.append("built"), **options)  # type: ignore[arg-type]
    again = build.build(source, announce=lambda: calls.append("again"), **options)  # type: ignore[arg-type]
    assert calls == ["built"] and not first.cached and again.cached


def test_the_host_build_names_itself_and_the_setup_script(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from sofac.build import compiler as build

    def fake_build(source: str, **options: object) -> str:
        announce = options["announce"]
        assert callable(announce)
        announce()
        return "built"

    monkeypatch.setattr(build, "build", fake_build)
    assert build.build_host() == "built"
    err = capsys.readouterr().err
    assert err.startswith("sofac: building the Python bridge to compiled scenes (once per installation")
    assert "bash scripts/setup.sh` builds it ahead" in err
    assert build.build_host(quiet=True) == "built" and capsys.readouterr().err == ""


def test_setup_builds_the_host_module() -> None:
    setup = (Path(__file__).resolve().parents[1] / "scripts" / "setup.sh").read_text()
    assert "compiler.build_host(quiet=True)" in setup


# --- 9. a Python scene is read as one, never as broken XML -------------------------------------------


def test_a_python_scene_is_read_as_python(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A .py file is run as a SofaPython3 scene (tests/test_pyscene.py); a script without
    createScene is said to be that, at its file, not an XML error."""
    path = tmp_path / "scene.py"
    path.write_text("x = 1\n")
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    assert "error E113" in out and "createScene" in out and "E101" not in out
    with pytest.raises(sofac.SceneError) as raised:
        sofac.load(path)
    assert [d.code for d in raised.value.diagnostics] == ["E113"]


def test_accuracy_prints_the_warnings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = typo_scene(tmp_path)
    args = ["accuracy", str(path), "--solvers", "symplectic", "--dt", "0.01", "--duration", "0.1"]
    args += ["--no-plots", "--no-progress", "--out", str(tmp_path / "acc")]
    assert main(args) == 0
    out, err = capsys.readouterr()
    assert len(W203.findall(err)) == 1
    assert not NUMPY_REPR.search(out + err)
    assert main([*args, "--strict"]) == 1
    assert W203.search(capsys.readouterr().err)


def test_a_huge_string_of_points_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "s.scn"
    path.write_text(
        '<Node name="root" dt="0.01">\n  <Node name="n">\n'
        '    <StringMeshCreator name="s" resolution="2147483648"/>\n'
        '    <MechanicalObject name="dofs" position="@s.position"/>\n  </Node>\n</Node>\n'
    )
    out = check_output(path, capsys)
    assert (
        "s.scn:3: error E207 [resolution]: StringMeshCreator 's': resolution: 2147483648 points is more"
        in out
    )


def test_render_progress_without_a_terminal_prints_at_least_every_second() -> None:
    from sofac.render.cli import _Progress

    stream = io.StringIO()
    bar = _Progress(1000, "simulate", True, stream)
    bar.advance(10)  # 1 %: no quarter reached, no second passed
    assert stream.getvalue() == ""
    bar._printed -= 1.5  # as if 1.5 s had passed since the last line
    bar.advance(10)
    assert stream.getvalue() == "simulate: 20/1000\n"


# --- 13 (fuzzing, continued): values the planner met unchecked ---------------------------------


def test_a_link_on_a_node_data_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = oscillator(tmp_path, ('gravity="0 0 0"', 'gravity="@."'))
    assert main(["emit", str(path)]) == 1
    err = capsys.readouterr().err
    assert (
        "oscillator.scn:15: error E222 [gravity]: node '/': gravity='@.': sofac does not follow links" in err
    )


def test_mesh_springs_over_a_topology_larger_than_the_state(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cube.scn"
    path.write_text(
        '<Node name="root" dt="0.01">\n  <Node name="Cube">\n    <EulerExplicitSolver/>\n'
        '    <MechanicalObject name="Particles" position="0 0 0"/>\n'
        '    <MeshTopology name="Topology" hexas="0 4 6 2 1 5 7 3"/>\n    <UniformMass vertexMass="1"/>\n'
        '    <MeshSpringForceField name="Springs" stiffness="100" damping="1"/>\n  </Node>\n</Node>\n'
    )
    assert main(["emit", str(path)]) == 1
    err = capsys.readouterr().err
    assert "cube.scn:7: error E218: MeshSpringForceField '/Cube/Springs' (" in err
    assert "its topology's hexahedra use point 7, but /Cube/Particles has 1 points" in err


@pytest.mark.parametrize(
    ("grid", "attribute"),
    [
        ('n="11 3 3" min="-1e308 0 0" max="1e308 0.2 0.2"', "min"),
        ('n="11 3 3" xmin="0" ymin="0" zmin="0" xmax="1e300" ymax="0.2" zmax="0.2"', "xmin"),
    ],
)
def test_grid_bounds_too_large_for_finite_points(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], grid: str, attribute: str
) -> None:
    path = beam(tmp_path, ('n="11 3 3" min="0 0 0" max="1 0.2 0.2"', grid))
    out = check_output(path, capsys)
    assert f"error E206 [{attribute}]: RegularGridTopology 'grid': the grid's points are not finite" in out


def test_box_roi_positions_that_are_no_points(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "box.scn"
    path.write_text(
        '<Node name="root" dt="0.02">\n  <Node name="n">\n'
        '    <RegularGridTopology min="0 0 0" max="1 1 1"/>\n'
        '    <MechanicalObject/>\n    <BoxROI name="box" box="0 0.75 0 1 1 1" position="0"/>\n'
        '    <FixedProjectiveConstraint indices="@box.indices"/>\n  </Node>\n</Node>\n'
    )
    out = check_output(path, capsys, status=0)  # SOFA reads no point: an empty box
    assert (
        "box.scn:5: warning W225 [position]: BoxROI 'box': position: 1 numbers is not a multiple of 3" in out
    )


def test_ctrl_c_during_a_render_says_where_it_stopped(tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys

    scene = oscillator(tmp_path)
    sofac.load(scene)  # compiled: the child loads it warm
    out = tmp_path / "o.png"
    child = subprocess.Popen(
        [sys.executable, "-m", "sofac", "render", str(scene), "--steps", "1000000000", "--out", str(out)],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stderr is not None
    first = child.stderr.readline()  # a progress line a second at least: the run is stepping
    assert first.startswith("simulate: "), first
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 130, err
    assert re.search(
        r"sofac: interrupted at step \d+ of 1000000000 \(t=[\d.e+-]+\); nothing was written", err
    )
    assert not out.exists()
