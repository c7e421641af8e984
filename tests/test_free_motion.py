"""FreeMotionAnimationLoop without constraint rows: the constraint phase of the plan, SOFA's rule
for states without a correction, the check-time errors of the constraint side, and SOFA's
regression scene LinearVelocityProjectiveConstraint.scn (FreeMotion + BGS + LinearSolver
correction on EigenSparseLU, a rigid box driven by a keyed velocity)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.check.checker import check_file
from sofac.regress.suite import Status, run_regression

# A spring-held particle (implicit Euler + CG) and a falling rigid frame (implicit Euler + CG):
# the loop and its constraint side are filled in per test.
SCENE = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    {loop}
    <Node name="Particle">
        <EulerImplicitSolver rayleighMass="0.1" rayleighStiffness="0.1"/>
        <CGLinearSolver iterations="40" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0.5 0"/>
        <UniformMass totalMass="3"/>
        <FixedProjectiveConstraint indices="0"/>
        <SpringForceField name="springs" spring="0 1 200 0.5 1  1 2 200 0.5 1.1"/>
        {particle_correction}
    </Node>
    <Node name="Frame">
        <EulerImplicitSolver/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="frame" template="Rigid3d" velocity="0.1 0 0 0.5 1 0"
                          position="0 2 0 0 0 0.3826834323650898 0.9238795325112867"/>
        <UniformMass totalMass="0.5"/>
        {frame_correction}
    </Node>
</Node>
"""

FREE_MOTION = (
    '<FreeMotionAnimationLoop parallelODESolving="true"/>\n'
    '    <BlockGaussSeidelConstraintSolver maxIterations="100" tolerance="1e-6"/>'
)
UNCOUPLED = '<UncoupledConstraintCorrection template="{t}"/>'
LINEAR = "<LinearSolverConstraintCorrection/>"


def write(tmp_path: Path, name: str, **parts: str) -> Path:
    values = {"loop": "<DefaultAnimationLoop/>", "particle_correction": "", "frame_correction": ""} | parts
    path = tmp_path / name
    path.write_text(SCENE.format(**values))
    return path


def run(path: Path, steps: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    sim = sofac.load(path)
    sim.step(steps)
    return {s: (sim[s].position.copy(), sim[s].velocity.copy()) for s in ("/Particle/dofs", "/Frame/frame")}


def test_free_motion_without_rows_is_the_default_step_bit_for_bit(tmp_path: Path) -> None:
    default = run(write(tmp_path, "default.scn"), 60)
    corrected = write(
        tmp_path,
        "free.scn",
        loop=FREE_MOTION,
        particle_correction=LINEAR,
        frame_correction=UNCOUPLED.format(t="Rigid3d"),
    )
    free = run(corrected, 60)
    for state, (x, v) in default.items():
        assert np.array_equal(free[state][0], x), state
        assert np.array_equal(free[state][1], v), state
    assert not np.array_equal(default["/Frame/frame"][0][0, :3], [0.0, 2.0, 0.0])  # it did move


def test_a_state_without_a_correction_keeps_its_position_and_velocity(tmp_path: Path) -> None:
    path = write(tmp_path, "frozen.scn", loop=FREE_MOTION, particle_correction=UNCOUPLED.format(t="Vec3d"))
    with pytest.warns(sofac.SceneWarning):
        sim = sofac.load(path)
    frame0 = (sim["/Frame/frame"].position.copy(), sim["/Frame/frame"].velocity.copy())
    particle0 = sim["/Particle/dofs"].position.copy()
    sim.step(30)
    np.testing.assert_array_equal(sim["/Frame/frame"].position, frame0[0])
    np.testing.assert_array_equal(sim["/Frame/frame"].velocity, frame0[1])
    assert not np.array_equal(sim["/Particle/dofs"].position, particle0)  # corrected: it moves


def test_the_frozen_state_is_a_warning_naming_the_state_and_the_fix(tmp_path: Path) -> None:
    path = write(tmp_path, "frozen.scn", loop=FREE_MOTION, particle_correction=UNCOUPLED.format(t="Vec3d"))
    with pytest.warns(sofac.SceneWarning, match=r"W245.*'/Frame/frame' has no constraint correction"):
        sofac.load(path)


def test_the_plan_has_a_constraint_phase(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "phase.scn",
        loop=FREE_MOTION,
        particle_correction=LINEAR,
        frame_correction=UNCOUPLED.format(t="Rigid3d"),
    )
    phase = sofac.load(path).plan.constraints
    assert phase is not None and phase.method == "block_gauss_seidel" and phase.capacity == 0
    assert [(c.kind, c.state.path) for c in phase.corrections] == [
        ("linear_solver", "/Particle/dofs"),
        ("uncoupled", "/Frame/frame"),
    ]
    assert phase.frozen == []
    assert phase.settings["maxIterations"].initial.tolist() == [100.0]
    assert phase.settings["tolerance"].initial.tolist() == [1e-6]


BAD = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop/>
    <BlockGaussSeidelConstraintSolver maxIterations="{iterations}" tolerance="{tolerance}"/>
    <Node name="A">
        <EulerImplicitSolver/>
        <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
        <MechanicalObject name="dofs" position="0 0 0"/>
        <UniformMass totalMass="1"/>
        {correction}
    </Node>
    <Node name="B">
        <MechanicalObject name="anchor" position="0 1 0"/>
    </Node>
    <BilateralLagrangianConstraint object1="@B/anchor" object2="@A/dofs" first_point="0" second_point="0"/>
</Node>
"""


def diagnostics_of(tmp_path: Path, **parts: str) -> list[tuple[str, int, str | None]]:
    values = {"iterations": "100", "tolerance": "1e-6", "correction": ""} | parts
    path = tmp_path / "bad.scn"
    path.write_text(BAD.format(**values))
    _, diagnostics = check_file(path, allow_unsupported=True)
    return [(d.code, d.loc.line, d.loc.attribute) for d in diagnostics if d.code != "E222"]


@pytest.mark.parametrize("iterations", ["0", "-5"])
def test_max_iterations_must_be_positive(tmp_path: Path, iterations: str) -> None:
    found = diagnostics_of(tmp_path, iterations=iterations, correction="<UncoupledConstraintCorrection/>")
    assert ("E207", 3, "maxIterations") in found


def test_a_negative_tolerance_is_refused(tmp_path: Path) -> None:
    found = diagnostics_of(tmp_path, tolerance="-1e-3", correction="<UncoupledConstraintCorrection/>")
    assert ("E207", 3, "tolerance") in found


def test_a_constraint_on_a_state_without_a_correction_is_an_error(tmp_path: Path) -> None:
    assert ("E246", 14, None) in diagnostics_of(tmp_path)
    # the static anchor needs none; with a correction on the moving state, nothing is reported
    assert not [
        d for d in diagnostics_of(tmp_path, correction="<UncoupledConstraintCorrection/>") if d[0] == "E246"
    ]


def test_a_constraint_solver_under_the_default_loop_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, "default_loop.scn", particle_correction=UNCOUPLED.format(t="Vec3d"))
    with pytest.raises(
        sofac.SceneError, match=r"UncoupledConstraintCorrection at line 10: .*FreeMotionAnimationLoop"
    ):
        sofac.load(path)


def test_linear_velocity_projective_constraint_scene_passes(shared_dir: Path) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    scene = "Component/Constraint/Projective/LinearVelocityProjectiveConstraint.scn"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[scene]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error == 0.0


def test_the_schedule_shows_the_constraint_phase(tmp_path: Path) -> None:
    from sofac.plan.planner import plan_scene
    from sofac.plan.report import format_effects, format_schedule

    path = write(tmp_path, "frozen.scn", loop=FREE_MOTION, particle_correction=UNCOUPLED.format(t="Vec3d"))
    checked, _ = check_file(path)
    assert checked is not None
    plan = plan_scene(checked)
    schedule = format_schedule(plan)
    assert "block_gauss_seidel (maxIterations=100.0, tolerance=1e-06," in schedule
    assert "constraint rows: 0 (x = x_free, v = v_free" in schedule
    assert "UncoupledConstraintCorrection '/Particle/UncoupledConstraintCorrection" in schedule
    assert (
        "frozen (no constraint correction, SOFA never writes its free motion back): /Frame/frame" in schedule
    )
    effects = format_effects(plan)
    assert "kept out          FreeMotionAnimationLoop" not in effects
    assert "constraint_solve  FreeMotionAnimationLoop" in effects
