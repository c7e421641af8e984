"""The divergence guard of ``Simulation.step``: what SimulationDiverged says (step, time, state, DOF,
solver, hint), the state it leaves readable (the failing step's values, ``last_finite``), the
energy bounds, and the command line's report (an error line, exit code 1, no traceback)."""

from __future__ import annotations

import math
import re
import subprocess
import sys

import numpy as np
import pytest
import sofac
from sofac.cli.main import main
from sofac.diagnostics import SofacError

from .scenes import EXACT_CG, Scenes, line, springs_body

# A particle on a spring k = 1e9 (mass 1) from x = 1.1: symplectic Euler at dt = 0.01 is far past
# its stability limit (omega dt = 316 > 2) and overflows within a few dozen steps.
BLOWUP = springs_body(
    "<EulerExplicitSolver/>",
    np.array([[0.0, 0, 0], [1.1, 0, 0]]),
    [(0, 1)],
    stiffness=1e9,
    damping=0.0,
    fixed=[0],
)
# An undamped oscillator under explicit Euler, whose energy grows slowly (k = 400, dt = 0.01).
SLOW_GAIN = springs_body(
    '<EulerExplicitSolver symplectic="false"/>', line(2), [(0, 1)], stiffness=400.0, damping=0.0, fixed=[0]
)
# The same oscillator with k = 100: stable at dt = 0.01 under an implicit solver.
GENTLE = springs_body(EXACT_CG, line(2), [(0, 1)], stiffness=100.0, damping=0.5, fixed=[0])


def blowup(scenes: Scenes) -> sofac.Simulation:
    return scenes.sim("blowup", BLOWUP)


def test_diverged_is_a_sofac_error_naming_step_time_state_dof_and_a_hint(scenes: Scenes) -> None:
    sim = blowup(scenes)
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    error = failure.value
    assert isinstance(error, SofacError)
    assert error.reason == "non-finite"
    assert 1 <= error.step < 200 and error.step == sim.steps
    assert error.time == pytest.approx(error.step * 0.01) and error.time == sim.time
    assert error.state == "/s/dofs" and error.dof == 1 and "position" in error.field
    message = str(error)
    assert f"diverged at step {error.step} (t={error.time:g})" in message
    assert "/s/dofs is no longer finite (DOF 1" in message
    assert "EulerExplicitSolver '/s/EulerExplicitSolver1'" in error.solver and error.solver in message
    assert "smaller dt" in error.hint and "implicit solver" in error.hint and error.hint in message
    assert "\n" not in message  # one line for the command line and logs


def test_arrays_hold_the_failing_step_and_last_finite_the_state_before_the_chunk(scenes: Scenes) -> None:
    sim = blowup(scenes)
    sim.chunk = 5
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    error = failure.value
    dofs = sim["dofs"]
    assert not np.isfinite(dofs.position[1]).all()  # the compiled step stopped right after it
    assert error.last_finite is not None and set(error.last_finite) == {"/s/dofs"}
    assert error.last_finite_step is not None and error.last_finite_time is not None
    assert error.step - 5 <= error.last_finite_step < error.step  # the start of the failing chunk
    assert error.last_finite_time == pytest.approx(error.last_finite_step * 0.01)
    position, velocity = error.last_finite["/s/dofs"]
    assert np.isfinite(position).all() and np.isfinite(velocity).all()
    assert f"last finite state: step {error.last_finite_step}" in str(error)
    # Re-running from that state reproduces the divergence at the same step, bit for bit.
    replay = blowup(scenes)
    replay.step(error.last_finite_step)
    assert np.array_equal(replay["dofs"].position, position)
    assert np.array_equal(replay["dofs"].velocity, velocity)
    with pytest.raises(sofac.SimulationDiverged) as again:
        replay.step(10_000)
    assert again.value.step == error.step


def test_with_chunk_1_last_finite_is_the_step_just_before(scenes: Scenes) -> None:
    sim = blowup(scenes)
    sim.chunk = 1
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    assert failure.value.last_finite_step == failure.value.step - 1


def test_stepping_again_after_a_divergence_says_so_and_reset_recovers(scenes: Scenes) -> None:
    sim = blowup(scenes)
    with pytest.raises(sofac.SimulationDiverged) as first:
        sim.step(10_000)
    with pytest.raises(sofac.SimulationDiverged) as second:
        sim.step(3)
    assert second.value.step == first.value.step + 1
    assert second.value.last_finite is None
    assert "already not finite before this call" in str(second.value)
    sim.reset()
    assert sim.steps == 0 and sim.time == 0.0
    sim.param("/s/springs.stiffness")[:] = 1.0  # now stable: omega dt = 0.01
    sim.step(100)
    assert np.isfinite(sim["dofs"].position).all()


def test_snapshots_can_be_switched_off(scenes: Scenes) -> None:
    sim = blowup(scenes)
    sim.keep_last_finite = False
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    assert failure.value.last_finite is None and "last finite" not in str(failure.value)


def test_chunking_changes_nothing_in_the_trajectory(scenes: Scenes) -> None:
    runs = []
    for chunk in (1, 7, 1000):
        sim = scenes.sim("gentle", GENTLE)
        sim["dofs"].position[1] = [1.3, 0.2, -0.1]
        sim.chunk = chunk
        sim.step(250)
        runs.append((sim["dofs"].position.copy(), sim["dofs"].velocity.copy(), sim.time, sim.steps))
    for other in runs[1:]:
        assert np.array_equal(runs[0][0], other[0]) and np.array_equal(runs[0][1], other[1])
        assert runs[0][2] == other[2] and runs[0][3] == other[3] == 250


def test_the_failing_step_is_counted_across_calls(scenes: Scenes) -> None:
    whole = blowup(scenes)
    with pytest.raises(sofac.SimulationDiverged) as at_once:
        whole.step(10_000)
    piecewise = blowup(scenes)
    with pytest.raises(sofac.SimulationDiverged) as in_pieces:
        for _ in range(10_000):
            piecewise.step(3)
    assert in_pieces.value.step == at_once.value.step
    assert in_pieces.value.time == at_once.value.time


def test_energy_bound_of_a_call(scenes: Scenes) -> None:
    sim = scenes.sim("gentle", GENTLE)
    sim["dofs"].position[1, 0] = 1.1
    start = sim.energy().total  # 0.5 k 0.1^2 = 0.5
    sim.step(100, energy_bound=start * 1.000001)  # implicit Euler: the energy only decreases
    assert sim.energy().total < start
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10, energy_bound=start / 1e6)
    error = failure.value
    assert error.reason == "energy" and error.step == 110
    assert error.energy is not None and error.bound == start / 1e6 and error.energy > error.bound
    assert error.state == "/s/dofs" and error.dof == 1  # the fastest DOF
    assert "exceeds its bound" in str(error) and "(energy_bound)" in str(error)


def test_guard_energy_catches_a_slow_gain_before_it_overflows(scenes: Scenes) -> None:
    # Forward (not symplectic) Euler multiplies an undamped oscillator's energy by 1 + (omega h)^2
    # per step: 1.04 here (k = 400, m = 1, h = 0.01), x10 in about 60 steps, which the energy guard
    # reports long
    # before any infinity. (A negative damping would pump energy in too, but is refused at run
    # time as in a scene file.)
    sim = scenes.sim("slow-gain", SLOW_GAIN)
    sim["dofs"].position[1, 0] = 1.1
    sim.guard_energy(10.0)
    sim.chunk = 10
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(100_000)
    error = failure.value
    assert error.reason == "energy" and error.step % 10 == 0 and 40 <= error.step < 200
    assert error.energy is not None and math.isfinite(error.energy) and error.energy > error.bound
    assert error.bound == pytest.approx(0.5 * 400.0 * 0.1**2 * 11.0)
    assert "guard_energy" in str(error) and "smaller dt" in error.hint
    assert error.last_finite is not None and error.last_finite_step < error.step
    sim.guard_energy(None)
    sim.reset()


def test_cli_run_reports_divergence_as_an_error_line(
    scenes: Scenes, capsys: pytest.CaptureFixture[str]
) -> None:
    path = scenes.write("blowup-cli", BLOWUP)
    assert main(["run", str(path), "--steps", "1000"]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert lines[0].startswith("sofac: error: the simulation diverged at step ")
    assert "/s/dofs is no longer finite" in lines[0] and "smaller dt" in lines[0]
    # the real last finite step, before the one that diverged (the state there is still finite)
    assert re.match(r"sofac: the last finite state \(step [1-9][0-9]*, t=\S+\):", lines[1]), lines[1]
    assert lines[2].startswith("  /s/dofs <Vec3d>: 0 0 0; ")
    assert "Traceback" not in captured.err


def test_cli_run_divergence_exit_code_in_a_fresh_process(scenes: Scenes) -> None:
    path = scenes.write("blowup-cli", BLOWUP)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "sofac",
            "run",
            str(path),
            "--steps",
            "100",
            "--export-states",
            str(path.parent / "out"),
        ],
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 1, done.stderr
    assert "sofac: error: the simulation diverged at step" in done.stderr
    assert "Traceback" not in done.stderr
    # Exported frames before the failing step stay on disk.
    assert (path.parent / "out" / "0_dofs_mstate.txt.gz").is_file()


def test_a_finite_run_is_unchanged(scenes: Scenes) -> None:
    sim = scenes.sim("gentle", GENTLE)
    sim["dofs"].position[1, 0] = 1.1
    sim.step(0)
    assert sim.steps == 0
    sim.step(300)
    assert sim.steps == 300 and sim.time == pytest.approx(3.0)
    assert math.isfinite(sim.energy().total)
    with pytest.raises(ValueError):
        sim.step(-1)
