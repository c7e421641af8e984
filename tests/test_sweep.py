"""``sofac sweep`` / ``sofac.sweep``: parameter sweeps on Dask (issue 8).

The oscillator sweep recovers the analytic frequency for every stiffness; a sweep on a 2-worker
LocalCluster equals the serial sweep bit for bit, also when a worker is killed while running a task;
a diverging parameter set is recorded, not fatal; an interrupted sweep resumes.
"""

from __future__ import annotations

import importlib.util
import json
import os
import pickle
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.cli.main import main
from sofac.sweeps import runner as sweeps
from sofac.sweeps.runner import SweepError

pytest.importorskip("distributed")
xr = pytest.importorskip("xarray")

ROOT = Path(__file__).resolve().parents[1]
OSCILLATOR = ROOT / "scenes" / "oscillator.scn"
BEAM = ROOT / "scenes" / "beam.scn"
STIFFNESS = "oscillator.spring.stiffness"
TIP = "beam.dofs.position"


# --- parsing -----------------------------------------------------------------------------------


def test_values_lists_and_ranges() -> None:
    assert sweeps.parse_values("1, 2,5") == [1.0, 2.0, 5.0]
    assert sweeps.parse_values("0:1:5") == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert sweeps.parse_values("0:1:lin:3") == [0.0, 0.5, 1.0]
    log = sweeps.parse_values("1e3:1e5:log:3")
    assert log[0] == 1e3 and log[-1] == 1e5 and log[1] == pytest.approx(1e4, rel=1e-12)
    assert sweeps.parse_param(" spring.stiffness = 1,2") == ("spring.stiffness", [1.0, 2.0])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty list"),
        ("1,x", "bad values '1,x'"),
        ("-1:10:log:3", "positive ends"),
        ("1:10:0", "at least 1"),
    ],
)
def test_bad_values_say_what_to_write(text: str, message: str) -> None:
    with pytest.raises(SweepError, match=message):
        sweeps.parse_values(text)


def test_parameter_names_resolve_like_the_simulation_names_them() -> None:
    sizes = {"/.dt": 1, "/.gravity": 3, "/a/spring.stiffness": 1, "/b/spring.stiffness": 1, "/b/m.mass": 1}
    assert sweeps.resolve_parameter("/a/spring.stiffness", sizes).key == "/a/spring.stiffness"
    assert sweeps.resolve_parameter("b/spring.stiffness", sizes).key == "/b/spring.stiffness"
    assert sweeps.resolve_parameter("m.mass", sizes) == sweeps.Parameter("/b/m.mass", None)
    gravity = sweeps.resolve_parameter("/.gravity[1]", sizes)
    assert (gravity.key, gravity.component, gravity.name) == ("/.gravity", 1, "gravity[1]")
    with pytest.raises(SweepError, match=r"spring\.stiffness: 'spring\.stiffness' is ambiguous"):
        sweeps.resolve_parameter("spring.stiffness", sizes)
    with pytest.raises(SweepError, match=r"no tunable parameter 'fem\.youngModulus'.*has: /\.dt, /\.gravity"):
        sweeps.resolve_parameter("fem.youngModulus", sizes)
    with pytest.raises(SweepError, match=r"has 3 components; sweep one with /\.gravity"):
        sweeps.resolve_parameter("/.gravity", sizes)
    with pytest.raises(SweepError, match=r"3 components \(0 to 2\)"):
        sweeps.resolve_parameter("/.gravity[3]", sizes)


def test_records_resolve_against_the_scene_states() -> None:
    states = {"/beam/dofs": 99, "/beam/visual/dofs": 20}
    assert sweeps.resolve_record("/beam/dofs.position", states) == sweeps.Record("/beam/dofs", "position")
    assert sweeps.resolve_record("beam/dofs.velocity[3, 98]", states).dofs == (3, 98)
    assert sweeps.resolve_record("energy", states).name == "energy"
    with pytest.raises(SweepError, match="'dofs' is ambiguous"):
        sweeps.resolve_record("dofs.position", states)
    with pytest.raises(SweepError, match="FIELD one of position, velocity, force"):
        sweeps.resolve_record("/beam/dofs.rest", states)
    with pytest.raises(SweepError, match="DOFs 0 to 98"):
        sweeps.resolve_record("/beam/dofs.position[99]", states)


def test_scene_errors_show_before_any_task() -> None:
    with pytest.raises(SweepError, match="nothing to sweep"):
        sweeps.plan_sweep(OSCILLATOR, {})
    with pytest.raises(SweepError, match=r"gravity.*no code for it; sweep with prune=False"):
        sweeps.plan_sweep(OSCILLATOR, {"/.gravity[1]": [-9.81]})
    plan = sweeps.plan_sweep(OSCILLATOR, {"/.gravity[1]": [-9.81, 0.0]}, prune=False, steps=3)
    assert plan.values.tolist() == [[-9.81], [0.0]]
    # A task carries the scene's path and settings, never compiled code.
    assert len(pickle.dumps(plan.job)) < 4000


# --- analytic: the oscillator's frequency for every stiffness ----------------------------------


def _frequency(times: np.ndarray, x: np.ndarray) -> float:
    """Angular frequency from the upward zero crossings of x (linearly interpolated)."""
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = times[up] - x[up] * (times[up + 1] - times[up]) / (x[up + 1] - x[up])
    assert len(crossings) >= 2, "the run must cover at least two periods"
    return 2 * np.pi * (len(crossings) - 1) / (crossings[-1] - crossings[0])


def test_stiffness_sweep_recovers_the_analytic_frequency() -> None:
    dataset = sofac.sweep(
        OSCILLATOR,
        {"spring.stiffness": sweeps.parse_values("25:1600:log:4")},
        steps=3000,
        every=1,
        record=["dofs.position[1]"],
        scheduler="synchronous",
    )
    assert list(dataset["status"].values) == ["ok"] * 4
    assert dataset["time"].values[0, -1] == pytest.approx(3.0)
    stiffness = dataset[STIFFNESS].values
    np.testing.assert_allclose(stiffness, [25, 100, 400, 1600], rtol=1e-12)
    for run, k in enumerate(stiffness):
        x = dataset["oscillator.dofs.position"].values[run, :, 0, 0] - 1.0  # rest length 1
        omega = _frequency(dataset["time"].values[run], x)
        # Symplectic Euler's frequency is off by (omega dt)^2 / 24 <= 7e-5 here.
        assert omega == pytest.approx(np.sqrt(k / 1.0), rel=5e-4), f"k = {k}"


def test_a_diverging_parameter_set_is_reported_not_fatal() -> None:
    # omega dt = 10 at k = 1e8: explicit Euler blows up; the other runs are unaffected.
    dataset = sofac.sweep(
        OSCILLATOR, {"spring.stiffness": [100.0, 1e8, 400.0]}, steps=400, scheduler="synchronous"
    )
    assert list(dataset["status"].values) == ["ok", "diverged", "ok"]
    step = int(dataset["diverged_step"].values[1])
    assert 0 < step <= 400
    assert "step" in str(dataset["message"].values[1])
    positions = dataset["oscillator.dofs.position"].values
    assert np.isfinite(positions[[0, 2]]).all()
    assert np.isnan(positions[1, -1]).all()  # nothing recorded past the failure


def test_a_run_that_cannot_start_is_recorded_as_failed(tmp_path: Path) -> None:
    plan = sweeps.plan_sweep(OSCILLATOR, {"spring.stiffness": [100.0]}, steps=2)
    job = sweeps.Job(**{**plan.job.__dict__, "scene": str(tmp_path / "gone.scn")})
    result = sweeps.run_one(job, [100.0])
    assert result["status"] == "failed"
    assert "gone.scn: no such file on worker host" in result["message"]


def test_parameter_tables_and_grids(tmp_path: Path) -> None:
    table = tmp_path / "sets.csv"
    table.write_text("spring.stiffness,mass.vertexMass\n100,1\n400,4\n", encoding="utf-8")
    dataset = sofac.sweep(OSCILLATOR, {"/.dt": [1e-3, 5e-4]}, table=table, steps=10, scheduler="synchronous")
    assert dataset.sizes["run"] == 4
    assert dataset[STIFFNESS].values.tolist() == [100, 100, 400, 400]
    assert dataset["dt"].values.tolist() == [1e-3, 5e-4, 1e-3, 5e-4]
    np.testing.assert_allclose(dataset["time"].values[:, -1], [1e-2, 5e-3, 1e-2, 5e-3], rtol=1e-12)
    # Same k/m, same dt: same motion.
    positions = dataset["oscillator.dofs.position"].values
    np.testing.assert_array_equal(positions[0], positions[2])
    as_json = tmp_path / "sets.json"
    as_json.write_text(json.dumps({"spring.stiffness": [100, 400]}), encoding="utf-8")
    assert sweeps.read_table(as_json) == [{"spring.stiffness": 100.0}, {"spring.stiffness": 400.0}]
    bad = tmp_path / "bad.csv"
    bad.write_text("spring.stiffness\n100\nabc\n", encoding="utf-8")
    with pytest.raises(SweepError, match=r"bad.csv:3: spring.stiffness = 'abc' is not a number"):
        sweeps.read_table(bad)


# --- resuming --------------------------------------------------------------------------------------


def test_an_interrupted_sweep_resumes_where_it_stopped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    params = {"spring.stiffness": [100.0, 200.0, 300.0, 400.0]}
    out = tmp_path / "osc.nc"
    calls: list[float] = []
    run_one = sweeps.run_one

    def interrupted(job: sweeps.Job, values: list[float]) -> dict:
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(values[0])
        return run_one(job, values)

    monkeypatch.setattr(sweeps, "run_one", interrupted)
    with pytest.raises(KeyboardInterrupt):
        sofac.sweep(OSCILLATOR, params, steps=50, out=out, scheduler="synchronous")
    assert not out.exists()
    assert sorted(p.name for p in (tmp_path / "osc.nc.parts").glob("run-*.npz")) == ["run-0.npz", "run-1.npz"]

    monkeypatch.setattr(
        sweeps, "run_one", lambda job, values: calls.append(values[0]) or run_one(job, values)
    )
    resumed = sofac.sweep(OSCILLATOR, params, steps=50, out=out, scheduler="synchronous")
    assert calls == [100.0, 200.0, 300.0, 400.0]  # runs 0 and 1 were not run again
    assert resumed.attrs["resumed_runs"] == 2
    assert not (tmp_path / "osc.nc.parts").exists()
    whole = sofac.sweep(OSCILLATOR, params, steps=50, scheduler="synchronous")
    xr.testing.assert_equal(resumed.drop_vars("wall_seconds"), whole.drop_vars("wall_seconds"))
    xr.testing.assert_equal(
        sweeps.open_dataset(out).drop_vars("wall_seconds"), whole.drop_vars("wall_seconds")
    )


def test_parts_of_another_sweep_are_not_mixed_in(tmp_path: Path) -> None:
    out = tmp_path / "osc.nc"
    parts = sweeps._Parts(
        Path(f"{out}.parts"), sweeps.plan_sweep(OSCILLATOR, {"spring.stiffness": [1.0]}), False
    )
    assert parts.load() == {}
    with pytest.raises(SweepError, match=r"different sweep.*--fresh"):
        sofac.sweep(OSCILLATOR, {"spring.stiffness": [2.0]}, out=out, scheduler="synchronous")
    fresh = sofac.sweep(OSCILLATOR, {"spring.stiffness": [2.0]}, out=out, scheduler="synchronous", fresh=True)
    assert fresh[STIFFNESS].values.tolist() == [2.0]


# --- Dask: a LocalCluster of 2 workers --------------------------------------------------------------


@pytest.fixture(scope="module")
def dask_client():
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        yield client


def _beam_plan(steps: int) -> sweeps.Plan:
    return sweeps.plan_sweep(
        BEAM,
        {"fem.youngModulus": [2e5, 5e5, 1e6, 2e6, 5e6, 1e7]},
        steps=steps,
        every=50,
        record=["/beam/dofs.position[98]", "energy"],
    )


def _without_timings(dataset: xr.Dataset) -> xr.Dataset:
    return dataset.drop_vars("wall_seconds")


def test_a_cluster_sweep_equals_the_serial_sweep_bit_for_bit(dask_client) -> None:
    plan = _beam_plan(200)
    # By address, as `sofac sweep --scheduler tcp://host:8786` connects to a running cluster.
    address = dask_client.scheduler.address
    assert address.startswith("tcp://")
    on_cluster = sweeps.run_plan(plan, scheduler=address)
    serial = sweeps.run_plan(plan, scheduler="synchronous")
    assert list(on_cluster["status"].values) == ["ok"] * 6
    xr.testing.assert_identical(_without_timings(on_cluster), _without_timings(serial))
    # Stiffer beams sag less (the tip's y at the last sample rises with E, past the first bounce).
    assert len(set(on_cluster[TIP].values[:, -1, 0, 1].tolist())) == 6


def test_the_tasks_of_a_killed_worker_are_rerun(dask_client) -> None:
    plan = _beam_plan(1500)  # long enough to catch a task running
    killed: list[str] = []

    def kill_a_busy_worker() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            busy = [address for address, keys in dask_client.processing().items() if keys]
            if busy:
                time.sleep(0.2)  # let the task start stepping
                pid = dask_client.run(os.getpid, workers=busy[:1])[busy[0]]
                os.kill(pid, signal.SIGKILL)
                killed.append(busy[0])
            time.sleep(0.02)

    killer = threading.Thread(target=kill_a_busy_worker)
    killer.start()
    on_cluster = sweeps.run_plan(plan, scheduler=dask_client)
    killer.join()
    assert killed, "no worker was ever busy"
    assert list(on_cluster["status"].values) == ["ok"] * 6
    serial = sweeps.run_plan(plan, scheduler="synchronous")
    xr.testing.assert_identical(_without_timings(on_cluster), _without_timings(serial))


# --- the command -------------------------------------------------------------------------------


def test_sweep_command_writes_dataset_summary_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "k.nc"
    code = main(
        [
            "sweep", str(OSCILLATOR), "--param", "spring.stiffness=100,1e8", "--steps", "300",
            "--record", "dofs.position,energy", "--out", str(out), "--scheduler", "synchronous",
            "--no-progress",
        ]
    )  # fmt: skip
    captured = capsys.readouterr()
    assert code == 1  # one run diverged
    assert "1 ok, 1 diverged; wrote" in captured.err
    lines = captured.out.splitlines()
    assert lines[0].split()[:3] == ["run", STIFFNESS, "status"]
    assert lines[2].split()[2] == "diverged"
    dataset = sweeps.open_dataset(out)
    assert dataset.attrs["steps"] == 300 and dataset.sizes["sample"] == 2
    assert {"kinetic_energy", "potential_energy", "oscillator.dofs.position"} <= set(dataset.data_vars)
    summary = (tmp_path / "k.summary.csv").read_text(encoding="utf-8").splitlines()
    assert summary[0].startswith(f"run,{STIFFNESS},status,")
    assert len(summary) == 3
    assert (tmp_path / "k.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sweep_command_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = str(tmp_path / "x.nc")
    assert main(["sweep", str(OSCILLATOR), "--param", "nope.k=1", "--out", out]) == 2
    err = capsys.readouterr().err
    assert "nope.k: no tunable parameter 'nope.k'; " in err and "the scene has: /.dt" in err
    assert main(["sweep", str(OSCILLATOR), "--param", "spring.stiffness=1:x:3", "--out", out]) == 2
    assert "bad values '1:x:3'" in capsys.readouterr().err
    assert (
        main(["sweep", str(OSCILLATOR), "--param", "spring.stiffness=1", "--out", str(tmp_path / "x.csv")])
        == 2
    )
    assert "name the file *.nc" in capsys.readouterr().err


def test_calibration_example_recovers_the_modulus() -> None:
    spec = importlib.util.spec_from_file_location("calibrate_beam", ROOT / "examples" / "calibrate_beam.py")
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    true_modulus = 4e6
    measured = example.tip_drop(sofac.load(BEAM), true_modulus)
    modulus, runs = example.calibrate(measured, scheduler="synchronous")
    assert modulus == pytest.approx(true_modulus, rel=1e-3)
    assert runs < 40


def test_a_parameter_compiled_out_names_the_way_to_keep_it(tmp_path: Path) -> None:
    # A zero damping coefficient has no code and no buffer: the message says why and what to do.
    text = OSCILLATOR.read_text().replace(
        '<SpringForceField template="Vec3d" name="spring"',
        '<UniformVelocityDampingForceField name="damper" dampingCoefficient="0"/>\n'
        '        <SpringForceField template="Vec3d" name="spring"',
    )
    scene = tmp_path / "damped.scn"
    scene.write_text(text)
    with pytest.raises(SweepError, match=r"damper\.dampingCoefficient: dampingCoefficient is 0.*--no-prune"):
        sweeps.plan_sweep(scene, {"damper.dampingCoefficient": [0.1, 1.0]})
    kept = sweeps.plan_sweep(scene, {"damper.dampingCoefficient": [0.1, 1.0]}, prune=False, steps=5)
    assert [p.key for p in kept.job.parameters] == ["/oscillator/damper.dampingCoefficient"]
