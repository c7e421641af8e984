"""``sofac accuracy`` and ``sofac.accuracy.measure.sweep``: orders of convergence against the oscillator's
analytic solution, outputs of the command, divergence as a result, the solver swap in the model."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from sofac.accuracy import measure as accuracy
from sofac.accuracy.measure import AccuracyError, Record, Solver, Sweep, SweepInfo
from sofac.accuracy.plots import pareto_front
from sofac.cli.main import main
from sofac.diagnostics import SofacError

REPO = Path(__file__).resolve().parents[1]
OSCILLATOR = REPO / "scenes" / "oscillator.scn"
BEAM = REPO / "scenes" / "beam.scn"


@pytest.fixture(autouse=True)
def _quick_timing(monkeypatch: pytest.MonkeyPatch) -> None:
    # Wall-time figures are not under test here: no repeated timing runs.
    monkeypatch.setattr(accuracy, "MIN_TIMED_SECONDS", 0.0)


def oscillator_exact(t: float) -> dict[str, list[list[float]]]:
    return {"dofs": [[0.0, 0.0, 0.0], [1.0 + 0.1 * math.cos(10.0 * t), 0.0, 0.0]]}


def record(solver: str, dt: float, error: float, wall: float = 1.0, **extra: object) -> Record:
    values: dict[str, object] = {
        "solver": solver,
        "integrator": accuracy.solver_family(solver),
        "dt": dt,
        "steps": 10,
        "max_error": error,
        "rms_error": error / 2,
        "energy_drift": 0.0,
        "energy_drift_max": 0.0,
        "wall_per_sim_second": wall,
        "step_seconds": wall,
        "compile_seconds": 1.0,
        "cached": False,
    }
    values.update(extra)
    return Record(**values)  # type: ignore[arg-type]


# --- against the analytic solution -----------------------------------------------------------------


def test_orders_of_convergence_against_the_analytic_solution() -> None:
    result = accuracy.sweep(
        OSCILLATOR,
        solvers=["euler", "rk2", "rk4", "variational"],
        dts=[0.004, 0.002, 0.001],
        duration=1.0,
        reference=oscillator_exact,
    )
    assert isinstance(result, Sweep) and all(isinstance(r, Record) for r in result)
    assert [(r.solver, r.dt) for r in result][:3] == [("euler", 0.004), ("euler", 0.002), ("euler", 0.001)]
    assert not any(r.diverged or r.error for r in result)
    orders = result.orders()
    assert orders["euler"] == pytest.approx(1, abs=0.25)
    assert orders["rk2"] == pytest.approx(2, abs=0.25)
    assert orders["rk4"] == pytest.approx(4, abs=0.25)
    assert orders["variational"] == pytest.approx(2, abs=0.05)
    info = result.info
    assert info.reference == "analytic" and result.reference is None
    assert info.scene_size == pytest.approx(1.1)  # anchor at 0, particle at 1.1
    assert info.samples == 250 and info.duration == pytest.approx(1.0)
    for r in result:
        assert r.steps == round(1.0 / r.dt)
        assert r.wall_per_sim_second > 0 and math.isfinite(r.wall_per_sim_second)
        assert r.rms_error <= r.max_error
    # Forward Euler gains energy on an oscillator; RK4 keeps it to a few 1e-9 at these steps.
    euler = next(r for r in result if r.solver == "euler" and r.dt == 0.004)
    assert euler.energy_drift > 0.1
    assert all(abs(r.energy_drift_max) < 1e-6 for r in result if r.solver == "rk4")


def test_columns_and_the_default_numeric_reference() -> None:
    result = accuracy.sweep(OSCILLATOR, solvers=["symplectic"], dts=[0.02, 0.01], duration=0.2)
    assert result.info.reference == "rk4@0.000625"  # the smallest dt / 16
    assert result.reference is not None and result.reference.max_error == 0.0
    assert result.info.energy_scale == pytest.approx(0.5, rel=1e-3)  # peak kinetic energy k A^2 / 2
    table = accuracy.columns(result)
    assert table["solver"] == ["symplectic", "symplectic"]
    assert table["dt"] == [0.02, 0.01]
    assert len(table) == len(accuracy.dataclasses.fields(Record))
    assert 0 < table["max_error"][1] < table["max_error"][0] < 0.1


# --- the command line ------------------------------------------------------------------------------


def test_cli_writes_table_json_csv_and_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    code = main(
        [
            "accuracy",
            str(OSCILLATOR),
            "--solvers",
            "symplectic,rk4",
            "--dt",
            "0.02, 0.01",
            "--duration",
            "0.4",
            "--reference",
            "analytic",
            "--no-progress",
            "--out",
            str(out),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "reference analytic" in captured.out
    assert "order of convergence" in captured.out
    lines = captured.out.splitlines()
    assert sum(line.startswith(("symplectic ", "rk4 ")) for line in lines) == 4

    data = json.loads((out / "results.json").read_text())
    assert data["reference"] == "analytic" and data["samples"] == 20
    assert [(r["solver"], r["dt"]) for r in data["records"]] == [
        ("symplectic", 0.02),
        ("symplectic", 0.01),
        ("rk4", 0.02),
        ("rk4", 0.01),
    ]
    assert set(data["orders"]) == {"symplectic", "rk4"}

    with (out / "results.csv").open() as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 4 and {"solver", "dt", "max_error", "wall_per_sim_second", "diverged"} <= set(rows[0])

    for name in ("error_vs_cost.png", "error_vs_dt.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["accuracy", str(tmp_path / "missing.scn")]) == 2
    assert main(["accuracy", str(OSCILLATOR), "--dt", "0.01,abc"]) == 2
    # 0.003 does not divide the sampling interval 0.01: said before anything is compiled.
    code = main(["accuracy", str(OSCILLATOR), "--dt", "0.01,0.003", "--out", str(tmp_path)])
    assert code == 2
    assert "does not divide" in capsys.readouterr().err


# --- divergence is a result ------------------------------------------------------------------------


STIFF = """<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
<Node name="chain"><EulerExplicitSolver symplectic="1"/>
<MechanicalObject name="dofs" position="0 0 0  1.1 0 0  2.2 0 0"/>
<UniformMass vertexMass="1"/><FixedProjectiveConstraint indices="0"/>
<SpringForceField spring="0 1 10000 0 1  1 2 10000 0 1"/></Node></Node>"""


def test_a_diverging_configuration_is_reported_not_raised(tmp_path: Path) -> None:
    # omega = sqrt(k/m) ~ 170 rad/s: explicit steps are stable below dt ~ 0.01, not at 0.04 or 0.02.
    scene = tmp_path / "stiff.scn"
    scene.write_text(STIFF)
    result = accuracy.sweep(
        scene, solvers=["symplectic", "implicit-direct"], dts=[0.04, 0.02, 0.005], duration=2.0
    )
    by = {(r.solver, r.dt): r for r in result}
    for dt in (0.04, 0.02):
        bad = by[("symplectic", dt)]
        assert bad.diverged and not bad.ok
        assert bad.diverged_step is not None and 1 <= bad.diverged_step < round(2.0 / dt)
        assert bad.diverged_time == pytest.approx(bad.diverged_step * dt)
        assert bad.diverged_reason
        assert math.isnan(bad.max_error)
    assert by[("symplectic", 0.005)].ok
    assert all(by[("implicit-direct", dt)].ok for dt in (0.04, 0.02, 0.005))
    assert "diverged at step" in accuracy.format_table(result)
    assert set(result.orders()) == {"implicit-direct"}  # symplectic: a single dt that ran
    data = accuracy.as_dict(result)
    json.dumps(data, allow_nan=False)  # NaN errors are written as null
    assert data["records"][0]["max_error"] is None


def test_a_reference_that_diverges_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = tmp_path / "stiff.scn"
    scene.write_text(STIFF)
    with pytest.raises(AccuracyError, match=r"no reference run \(symplectic@0.04\).*diverged at step"):
        accuracy.sweep(scene, solvers=["symplectic"], dts=[0.04], duration=2.0, reference="symplectic@0.04")
    code = main(
        ["accuracy", str(scene), "--dt", "0.04", "--reference", "symplectic@0.04", "--out", str(tmp_path)]
    )
    assert code == 2 and "no reference run" in capsys.readouterr().err


def test_a_non_finite_state_stops_the_run() -> None:
    model = accuracy._parse(OSCILLATOR, [])
    compiled = accuracy.compile_variant(model, Solver("euler"), keep_rayleigh=False)
    run = accuracy._run(compiled, dt=1.0, per_sample=100, samples=10, paths=None)
    assert run.diverged_step is not None and run.diverged_reason == "non-finite state"
    assert run.steps == run.diverged_step < 1000


def test_a_configuration_that_cannot_compile_is_a_failed_record(monkeypatch: pytest.MonkeyPatch) -> None:
    real = accuracy.compile_variant

    def compile_variant(scene: object, solver: Solver, *, keep_rayleigh: bool) -> object:
        if solver.kind == "rk2":
            raise SofacError("no RK2 today")
        return real(scene, solver, keep_rayleigh=keep_rayleigh)  # type: ignore[arg-type]

    monkeypatch.setattr(accuracy, "compile_variant", compile_variant)
    result = accuracy.sweep(OSCILLATOR, solvers=["rk2", "rk4"], dts=[0.01], duration=0.1)
    failed, fine = result
    assert failed.error == "SofacError: no RK2 today" and not failed.ok and not failed.diverged
    assert fine.ok
    assert "failed rk2: SofacError: no RK2 today" in accuracy.format_table(result)


# --- the solver swap -------------------------------------------------------------------------------


def test_with_solver_replaces_the_ode_and_linear_solvers() -> None:
    model = accuracy._parse(BEAM, [])
    assert accuracy.scene_rayleigh(model)

    def beam_objects(variant: accuracy.Scene) -> list[tuple[str, dict[str, str]]]:
        beam = variant.root.child("beam")
        assert beam is not None
        return [(c.type_name, {k: a.value for k, a in c.attributes.items()}) for c in beam.objects]

    rk4 = beam_objects(accuracy.with_solver(model, Solver("rk4"), keep_rayleigh=True))
    assert rk4[0] == ("RungeKutta4Solver", {"name": "odesolver"})
    assert rk4[1][0] == "RegularGridTopology"  # the CG solver is gone, the rest in place
    cg = beam_objects(accuracy.with_solver(model, Solver("implicit-cg", 50, 1e-8), keep_rayleigh=True))
    assert cg[0] == (
        "EulerImplicitSolver",
        {"name": "odesolver", "rayleighStiffness": "0.1", "rayleighMass": "0.1"},
    )
    assert cg[1][0] == "CGLinearSolver"
    assert cg[1][1]["iterations"] == "50" and cg[1][1]["tolerance"] == "1e-08"
    direct = beam_objects(accuracy.with_solver(model, Solver("implicit-direct"), keep_rayleigh=False))
    assert direct[0] == ("EulerImplicitSolver", {"name": "odesolver"})
    assert direct[1][0] == "SparseLDLSolver"
    euler = beam_objects(accuracy.with_solver(model, Solver("euler"), keep_rayleigh=False))
    assert euler[0] == ("EulerExplicitSolver", {"name": "odesolver", "symplectic": "0"})
    variational = beam_objects(accuracy.with_solver(model, Solver.parse("variational"), keep_rayleigh=True))
    assert variational[0] == (
        "VariationalSymplecticSolver",
        {"name": "odesolver", "rayleighStiffness": "0.1", "rayleighMass": "0.1"},
    )
    assert variational[1][0] == "SparseLDLSolver"
    # The parsed model itself is untouched.
    assert [c.type_name for c in model.root.child("beam").objects][:2] == [
        "EulerImplicitSolver",
        "CGLinearSolver",
    ]


def test_solver_names_and_expansion() -> None:
    assert Solver.parse("implicit-cg:50:1e-8") == Solver("implicit-cg", 50, 1e-8)
    assert Solver.parse("implicit-cg:50:1e-8").label == "implicit-cg:50:1e-08"
    assert Solver.parse("RK4").theoretical_order == 4
    assert Solver.parse("variational").theoretical_order == 2 and Solver.parse("variational").implicit
    with pytest.raises(AccuracyError, match="unknown solver"):
        Solver.parse("rk5")
    with pytest.raises(AccuracyError):
        Solver.parse("implicit-cg:many")
    expanded = accuracy.expand_solvers(["rk4", "implicit"], ["cg", "direct"], [10, 100], [1e-5])
    assert [s.label for s in expanded] == [
        "rk4",
        "implicit-direct",
        "implicit-cg:10:1e-05",
        "implicit-cg:100:1e-05",
    ]
    assert [s.label for s in accuracy.expand_solvers(["implicit"], ["direct"])] == ["implicit-direct"]
    # CG's absolute threshold: negligible unless given, and then part of the label.
    assert Solver.parse("implicit-cg:25:1e-5:1e-5").label == "implicit-cg:25:1e-05:1e-05"
    with_threshold = accuracy.expand_solvers(["implicit"], ["cg"], [25], [1e-5], cg_threshold=1e-5)
    assert [s.label for s in with_threshold] == ["implicit-cg:25:1e-05:1e-05"]
    with pytest.raises(AccuracyError, match="linear solver"):
        accuracy.expand_solvers(["implicit"], ["lu"])


def test_reference_specs() -> None:
    parse = accuracy._parse_reference
    assert parse("rk4", 0.01) == accuracy.Configuration(Solver("rk4"), 0.01 / 16)
    assert parse("implicit-direct@/4", 0.01).dt == pytest.approx(0.0025)
    assert parse("implicit-cg:100:1e-10@1e-4", 0.01) == accuracy.Configuration(
        Solver("implicit-cg", 100, 1e-10), 1e-4
    )
    with pytest.raises(AccuracyError):
        parse("rk4@-1", 0.01)
    assert accuracy.load_analytic(OSCILLATOR)(0.0) == {"dofs": [[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]]}
    with pytest.raises(AccuracyError, match="no analytic solution"):
        accuracy.load_analytic(BEAM)


# --- results helpers -------------------------------------------------------------------------------


def test_measured_orders_and_pareto_front() -> None:
    records = [
        record("rk2", 0.01, 1e-4, wall=1.0),
        record("rk2", 0.005, 2.5e-5, wall=2.0),
        record("euler", 0.01, 1e-2, wall=0.5),
        record("euler", 0.005, 5e-3, wall=1.0),
        record("euler", 0.02, math.nan, wall=0.2, diverged=True, diverged_step=3),
        record("rk4", 0.01, 1e-8, wall=3.0),
    ]
    orders = accuracy.measured_orders(records)
    assert orders == {"rk2": pytest.approx(2.0), "euler": pytest.approx(1.0)}
    front = pareto_front(records)
    assert [(r.solver, r.dt) for r in front] == [
        ("euler", 0.01),
        ("rk2", 0.01),
        ("rk2", 0.005),
        ("rk4", 0.01),
    ]


def test_markdown_table_collapses_diverged_rows() -> None:
    info = SweepInfo("s.scn", 1.0, 0.1, 10, 1.0, "analytic", 1.0, "none")
    records = [
        record("rk4", 0.01, 1e-8),
        record("rk4", 0.005, 6.25e-10),
        record("euler", 0.01, math.nan, diverged=True, diverged_step=7, diverged_time=0.07),
    ]
    full = accuracy.markdown_table(Sweep(records, info, None))
    assert full.count("\n| `") == 3 and "diverged at step 7 (t=0.07)" in full
    short = accuracy.markdown_table(Sweep(records, info, None), collapse_diverged=True)
    assert short.count("\n| `") == 2
    assert "Diverged, at dt (step): `euler` 0.01 (step 7)." in short
    assert "`rk4` **4.00**" in short


def test_csv_writes_every_field(tmp_path: Path) -> None:
    info = SweepInfo("s.scn", 1.0, 0.1, 10, 1.0, "analytic", 1.0, "none")
    result = Sweep([record("rk4", 0.01, 1e-8), record("euler", 0.01, math.nan, diverged=True)], info, None)
    path = accuracy.write_csv(result, tmp_path / "r.csv")
    with path.open() as stream:
        rows = list(csv.DictReader(stream))
    assert rows[0]["solver"] == "rk4" and rows[1]["diverged"] == "True" and rows[1]["cg_iterations"] == ""
    written = json.loads(accuracy.write_json(result, tmp_path / "r.json").read_text())
    assert written["records"][1]["max_error"] is None and written["orders"] == {}
