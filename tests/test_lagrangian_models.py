"""SOFA's common Lagrangian constraint models compiled under FreeMotionAnimationLoop, against
closed forms: FixedLagrangianConstraint<Vec3d> holds a particle at its rest position under
gravity with the multiplier m g dt per step (the impulse), and no drift, and <Rigid3d> pulls a frame
to its rest pose and holds it against gravity and a torque; StopperLagrangianConstraint
<Vec1d> stops a pushed particle on its bound; UniformLagrangianConstraint<Vec1d> holds every
coordinate at zero or at rest; SlidingLagrangianConstraint<Vec3d> keeps a point on its segment
under gravity, sliding as implicit Euler does, and stops it at the end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

FIXED = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop name="loop"/>
    <BlockGaussSeidelConstraintSolver maxIterations="100" tolerance="1e-12"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="dofs" position="0 1 0  1 1 0  2 1 0" {rest}/>
        <UniformMass vertexMass="0.5"/>
        <UncoupledConstraintCorrection template="Vec3d" defaultCompliance="2"/>
        <FixedLagrangianConstraint {fixed}/>
    </Node>
</Node>
"""


def scene(tmp_path: Path, fixed: str, rest: str = "") -> Path:
    path = tmp_path / "fixed.scn"
    path.write_text(FIXED.format(fixed=fixed, rest=rest))
    return path


def test_a_fixed_lagrangian_particle_stays_with_multiplier_m_g(tmp_path: Path) -> None:
    dt, mass, g = 0.01, 0.5, 9.81
    sim = sofac.load(scene(tmp_path, 'indices="0 2"'))
    phase = sim.plan.constraints
    assert phase is not None and phase.capacity == 6 and len(phase.blocks) == 2
    for _ in range(4):
        sim.step(10)
        dofs = sim["/A/dofs"]
        np.testing.assert_allclose(dofs.position[[0, 2]], [[0, 1, 0], [2, 1, 0]], atol=1e-12)
        np.testing.assert_allclose(dofs.velocity[[0, 2]], 0.0, atol=1e-12)
    # the free point falls: implicit Euler, x_k = x_0 - g dt^2 k (k + 1) / 2
    np.testing.assert_allclose(sim["/A/dofs"].position[1], [1, 1 - g * dt * dt * 40 * 41 / 2, 0], rtol=1e-12)
    impulse = sim.output("/.constraint_kept_forces")  # +e_k rows: the force holds the point up
    np.testing.assert_allclose(impulse / dt, [0, mass * g, 0] * 2, rtol=1e-9, atol=1e-9)


def test_fix_all_holds_every_point_at_its_rest_position(tmp_path: Path) -> None:
    # rest_position differs from the start: the rows pull the points there in one step, then hold
    rest = 'rest_position="0 0.9 0  1 0.9 0  2 0.9 0"'
    sim = sofac.load(scene(tmp_path, 'fixAll="1"', rest))
    sim.step(1)
    np.testing.assert_allclose(sim["/A/dofs"].position, [[0, 0.9, 0], [1, 0.9, 0], [2, 0.9, 0]], atol=1e-12)
    sim.step(5)
    np.testing.assert_allclose(sim["/A/dofs"].position, [[0, 0.9, 0], [1, 0.9, 0], [2, 0.9, 0]], atol=1e-12)
    np.testing.assert_allclose(sim["/A/dofs"].velocity, 0.0, atol=1e-12)


def test_a_fixed_lagrangian_constraint_not_compiled_is_refused_at_its_line(tmp_path: Path) -> None:
    from sofac.check.checker import check_file
    from sofac.plan.planner import plan_scene

    path = scene(tmp_path, 'indices="0" endTime="1"')
    checked, _ = check_file(path)
    assert checked is not None
    with pytest.raises(sofac.SceneError) as caught:
        plan_scene(checked)
    line = next(n for n, row in enumerate(FIXED.splitlines(), start=1) if "<FixedLagrangian" in row)
    assert f"unsupported component FixedLagrangianConstraint at line {line}" in str(caught.value)
    assert "endTime" in str(caught.value)


STOPPER = """<Node name="root" dt="0.01" gravity="0 0 0">
    <FreeMotionAnimationLoop name="loop"/>
    <{solver} maxIterations="100" tolerance="1e-12"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject template="Vec1d" name="dofs" position="0  0"/>
        <UniformMass template="Vec1d" vertexMass="0.5"/>
        <ConstantForceField template="Vec1d" indices="0 1" forces="{force}  {force}"/>
        <UncoupledConstraintCorrection template="Vec1d" defaultCompliance="2"/>
        <StopperLagrangianConstraint template="Vec1d" index="1" min="-0.03" max="0.05"/>
    </Node>
</Node>
"""


@pytest.mark.parametrize("solver", ["BlockGaussSeidelConstraintSolver", "NNCGConstraintSolver"])
@pytest.mark.parametrize(("force", "bound"), [(2.0, 0.05), (-2.0, -0.03)])
def test_a_stopper_holds_a_pushed_particle_at_its_bound(
    tmp_path: Path, solver: str, force: float, bound: float
) -> None:
    dt, mass = 0.01, 0.5
    path = tmp_path / "stopper.scn"
    path.write_text(STOPPER.format(solver=solver, force=force))
    sim = sofac.load(path)
    # implicit Euler under a constant force: x_k = a dt^2 k (k + 1) / 2 until the bound is passed
    a = force / mass
    free = [a * dt * dt * k * (k + 1) / 2 for k in range(1, 41)]
    inside = next(k for k, x in enumerate(free, start=1) if abs(x) > abs(bound)) - 1
    sim.step(inside)
    np.testing.assert_allclose(sim["/A/dofs"].position[:, 0], [free[inside - 1]] * 2, rtol=1e-12)
    # the step that would pass the bound ends on it (x = x_free + W f = bound), at rest after it
    sim.step(1)
    assert sim["/A/dofs"].position[1, 0] == pytest.approx(bound, abs=1e-14)
    for _ in range(3):
        sim.step(5)
        dofs = sim["/A/dofs"]
        assert dofs.position[1, 0] == pytest.approx(bound, abs=1e-14)
        assert dofs.velocity[1, 0] == pytest.approx(0.0, abs=1e-12)
    k = inside + 16  # the other particle is free
    assert dofs.position[0, 0] == pytest.approx(a * dt * dt * k * (k + 1) / 2, rel=1e-12)


UNIFORM = """<Node name="root" dt="0.01" gravity="0 0 0">
    <FreeMotionAnimationLoop name="loop"/>
    <BlockGaussSeidelConstraintSolver maxIterations="100" tolerance="1e-12"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject template="Vec1d" name="dofs" position="0.1  -0.2  0.3" rest_position="1 2 3"/>
        <UniformMass template="Vec1d" vertexMass="0.5"/>
        <ConstantForceField template="Vec1d" indices="0 1 2" forces="2 -1 3"/>
        <UncoupledConstraintCorrection template="Vec1d" defaultCompliance="2"/>
        <UniformLagrangianConstraint template="Vec1d" {fields}/>
    </Node>
</Node>
"""


@pytest.mark.parametrize(("fields", "target"), [("", [0, 0, 0]), ('constrainToRestPos="1"', [1, 2, 3])])
def test_uniform_rows_hold_every_coordinate_at_zero_or_rest(
    tmp_path: Path, fields: str, target: list[float]
) -> None:
    dt = 0.01
    path = tmp_path / "uniform.scn"
    path.write_text(UNIFORM.format(fields=fields))
    sim = sofac.load(path)
    phase = sim.plan.constraints
    assert phase is not None and phase.capacity == 3 and len(phase.blocks) == 3
    sim.step(1)  # x = x_free + W f: on the target in one step, moving there at (target - x0) / dt
    dofs = sim["/A/dofs"]
    np.testing.assert_allclose(dofs.position[:, 0], target, atol=1e-13)
    np.testing.assert_allclose(dofs.velocity[:, 0], (np.array(target) - [0.1, -0.2, 0.3]) / dt, rtol=1e-10)
    sim.step(10)
    np.testing.assert_allclose(dofs.position[:, 0], target, atol=1e-13)
    np.testing.assert_allclose(dofs.velocity[:, 0], 0.0, atol=1e-10)


def test_uniform_not_iterative_is_refused_at_its_line(tmp_path: Path) -> None:
    from sofac.check.checker import check_file
    from sofac.plan.planner import plan_scene

    path = tmp_path / "uniform.scn"
    path.write_text(UNIFORM.format(fields='iterative="0"'))
    checked, _ = check_file(path)
    assert checked is not None
    with pytest.raises(sofac.SceneError) as caught:
        plan_scene(checked)
    line = next(n for n, row in enumerate(UNIFORM.splitlines(), start=1) if "<UniformLagrangian" in row)
    assert f"unsupported component UniformLagrangianConstraint at line {line}" in str(caught.value)
    assert "iterative=0" in str(caught.value)


SLIDING = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop name="loop"/>
    <BlockGaussSeidelConstraintSolver maxIterations="200" tolerance="1e-14"/>
    <Node name="P">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="point" position="0.1 0.1 0"/>
        <UniformMass vertexMass="0.5"/>
        <UncoupledConstraintCorrection template="Vec3d" defaultCompliance="2"/>
    </Node>
    <Node name="Rail">
        <MechanicalObject name="ends" position="9 9 9  0 0 0  1 -1 0"/>
    </Node>
    <SlidingLagrangianConstraint object1="@P/point" object2="@Rail/ends" sliding_point="0"
        axis_1="{a}" axis_2="{b}"/>
</Node>
"""


@pytest.mark.parametrize(("a", "b"), [(1, 2), (2, 1)])
def test_a_point_slides_down_its_segment_and_stops_at_the_end(tmp_path: Path, a: int, b: int) -> None:
    """A point on the segment (0 0 0)-(1 -1 0) under gravity: it stays on the line, moves along it
    with implicit Euler's s_k = s_0 + g' dt^2 k (k + 1) / 2 (g' = g / sqrt 2, the bilateral rows
    only remove the motion across the axis), then rests at the lower end (the unilateral row)."""
    dt, g = 0.01, 9.81
    path = tmp_path / "sliding.scn"
    path.write_text(SLIDING.format(a=a, b=b))
    sim = sofac.load(path)
    axis = np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    sim.step(2)  # the point starts off the line (0.1 0.1 0): the first step puts it on it
    start, speed = sim["/P/point"].position[0] @ axis, sim["/P/point"].velocity[0] @ axis
    for m in range(1, 29):
        sim.step(1)
        p = sim["/P/point"].position[0]
        along = p @ axis
        assert np.linalg.norm(p - along * axis) < 1e-13  # on the line
        expected = start + speed * dt * m + g / np.sqrt(2) * dt * dt * m * (m + 1) / 2
        assert along == pytest.approx(expected, rel=1e-9)
    sim.step(100)
    np.testing.assert_allclose(sim["/P/point"].position[0], [1.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sim["/P/point"].velocity[0], 0.0, atol=1e-10)


@pytest.mark.parametrize(("a", "b"), [(1, 1), (1, 3)])
def test_a_zero_length_sliding_axis_is_an_error_at_its_attribute(tmp_path: Path, a: int, b: int) -> None:
    """axis_1 = axis_2, or two points of object2 at the same position: no direction to slide along
    (SOFA would divide by the zero length): E207 at axis_2, with the line and the fix."""
    from sofac.check.checker import check_file
    from sofac.plan.planner import plan_scene

    path = tmp_path / "sliding.scn"
    path.write_text(SLIDING.format(a=a, b=b).replace("0 0 0  1 -1 0", "0 0 0  1 -1 0  0 0 0"))
    checked, _ = check_file(path)
    assert checked is not None
    with pytest.raises(sofac.SceneError) as caught:
        plan_scene(checked)
    (diagnostic,) = [d for d in caught.value.diagnostics if d.code == "E207"]
    line = next(n for n, row in enumerate(SLIDING.splitlines(), start=1) if "axis_2=" in row)
    assert (diagnostic.loc.line, diagnostic.loc.attribute) == (line, "axis_2")
    assert f"axis_1={a} and axis_2={b}" in diagnostic.message and "zero length" in diagnostic.message


RIGID_FIXED = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop name="loop"/>
    <BlockGaussSeidelConstraintSolver maxIterations="100" tolerance="1e-14"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-20"/>
        <MechanicalObject name="frame" template="Rigid3d" position="0.1 1.2 0  0 0 0.0998334166 0.9950041653"
            rest_position="0 1 0  0 0 0.3826834323650898 0.9238795325112867"/>
        <UniformMass totalMass="0.5"/>
        <ConstantForceField template="Rigid3d" forces="0 0 0  0 0 {torque}"/>
        <UncoupledConstraintCorrection template="Rigid3d"/>
        <FixedLagrangianConstraint template="Rigid3d" indices="0"/>
    </Node>
</Node>
"""


def test_a_fixed_rigid_frame_is_pulled_to_its_rest_pose_and_held_against_a_torque(tmp_path: Path) -> None:
    # FixedLagrangianConstraint<Rigid3d>: six rows (e_k, 0), (0, e_k); the centre's violation is
    # linear (pulled home in one step), the orientation's the Euler vector of q q_rest⁻¹ (home
    # after a few steps); then the kept impulses carry the weight and the torque over a step
    dt, mass, g, torque = 0.01, 0.5, 9.81, 0.3
    path = tmp_path / "rigid_fixed.scn"
    path.write_text(RIGID_FIXED.format(torque=torque))
    sim = sofac.load(path)
    phase = sim.plan.constraints
    assert phase is not None and phase.capacity == 6 and len(phase.blocks) == 2
    sim.step(1)
    frame = sim["/A/frame"]
    np.testing.assert_allclose(frame.position[0, :3], [0, 1, 0], atol=1e-12)
    sim.step(49)
    rest = [0, 1, 0, 0, 0, 0.3826834323650898, 0.9238795325112867]
    np.testing.assert_allclose(frame.position[0], rest, atol=1e-12)
    np.testing.assert_allclose(frame.velocity, 0.0, atol=1e-12)
    impulse = sim.output("/.constraint_kept_forces")
    np.testing.assert_allclose(impulse, [0, mass * g * dt, 0, 0, 0, -torque * dt], rtol=1e-9, atol=1e-14)
