"""StaticSolver: Newton-Raphson on f(x) = 0 with the parameters of its NewtonRaphsonSolver.

SOFA's scheme: each Newton iteration solves -K dx = f (projected), then x += alpha dx with a
backtracking line search on |f|; it stops on SOFA's criteria (absolute / relative-initial /
relative-successive residual, absolute / relative correction) or after maxNbIterationsNewton
(default 1); the velocities are not touched. Checked against closed-form equilibria.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

HANGING = """\
<Node name="root" gravity="0 -9.81 0" dt="0.1"><DefaultAnimationLoop/>
  <Node name="weight">
    <StaticSolver {static}/>
    {newton}
    {linear}
    <MechanicalObject template="Vec3d" name="dofs" position="0 0 0  {x} {y} 0"/>
    <UniformMass vertexMass="{mass}"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField name="spring" spring="0 1 {k} 0 {length}"/>
  </Node>
</Node>
"""
MASS, K, LENGTH = 2.0, 400.0, 1.0
STRETCHED = LENGTH + MASS * 9.81 / K  # the equilibrium length


def hanging(
    folder: Path,
    *,
    x: float = 0.0,
    y: float = -1.5,
    static: str = "",
    newton: str = "",
    linear: str = "<SparseLDLSolver/>",
) -> sofac.Simulation:
    # One file name for all: the generated code names its scene, so same-shaped scenes share a build.
    path = folder / "hanging.scn"
    path.write_text(
        HANGING.format(static=static, newton=newton, linear=linear, x=x, y=y, mass=MASS, k=K, length=LENGTH)
    )
    return sofac.load(path)


@pytest.mark.parametrize(
    "linear",
    [
        "<SparseLDLSolver/>",
        '<CGLinearSolver iterations="50" tolerance="1e-14" threshold="1e-30"/>',
        '<PCGLinearSolver iterations="50" tolerance="1e-28"/>',
    ],
    ids=["direct", "cg", "pcg"],
)
def test_one_newton_iteration_solves_a_linear_problem(tmp_path: Path, linear: str) -> None:
    """A vertical spring: linear along its axis, so the default single iteration lands on it (it
    starts stretched: a spring at its rest length has no sideways stiffness, a singular system)."""
    sim = hanging(tmp_path, linear=linear)
    dofs = sim["weight/dofs"]
    dofs.velocity[1] = [0.5, 0.0, 0.0]
    sim.step(1)
    assert dofs.position[1] == pytest.approx([0.0, -STRETCHED, 0.0], abs=1e-12)
    assert dofs.position[0].tolist() == [0.0, 0.0, 0.0]
    assert dofs.velocity[1].tolist() == [0.5, 0.0, 0.0]  # a static solver leaves velocities alone
    sim.step(3)  # at equilibrium: nothing moves
    assert dofs.position[1] == pytest.approx([0.0, -STRETCHED, 0.0], abs=1e-12)


def test_newton_iterations_converge_quadratically_on_a_nonlinear_problem(tmp_path: Path) -> None:
    """Start off to the side: the spring must turn, a nonlinear problem. One iteration per step
    (SOFA's default) creeps toward equilibrium; tight thresholds and enough iterations reach it
    within one step; the residual falls quadratically (checked through successive iteration caps)."""
    start = {"x": 0.6, "y": -0.9}
    errors = []
    for iterations in (1, 4, 5, 6, 8):
        newton = (
            f'<NewtonRaphsonSolver maxNbIterationsNewton="{iterations}" '
            'absoluteResidualStoppingThreshold="0" relativeInitialStoppingThreshold="0" '
            'relativeSuccessiveStoppingThreshold="0"/>'
        )
        sim = hanging(tmp_path, newton=newton, **start)
        sim.step(1)
        errors.append(float(np.linalg.norm(sim["weight/dofs"].position[1] - [0.0, -STRETCHED, 0.0])))
    assert errors[0] > 1e-2
    assert errors[-1] < 1e-12
    # quadratic: e_{k+1} <= C e_k^2 once close
    # (measured: 0.28 after one iteration, then 1.8e-3, 3.7e-6, 9.3e-11 after 4, 5, 6; 5e-36 after 8)
    assert errors[2] < 20 * errors[1] ** 2 and errors[3] < 20 * errors[2] ** 2, errors


def test_stopping_rules_and_line_search(tmp_path: Path) -> None:
    start = {"x": 0.6, "y": -0.9}
    # a large absolute threshold: converged before any iteration, nothing moves
    sim = hanging(tmp_path, newton='<NewtonRaphsonSolver absoluteResidualStoppingThreshold="1e6"/>', **start)
    sim.step(1)
    assert sim["weight/dofs"].position[1].tolist() == [0.6, -0.9, 0.0]
    # a large absolute correction threshold: stops after the first iteration even with 50 allowed
    capped = hanging(
        tmp_path,
        newton='<NewtonRaphsonSolver maxNbIterationsNewton="50" absoluteResidualStoppingThreshold="0" '
        'relativeInitialStoppingThreshold="0" relativeSuccessiveStoppingThreshold="0" '
        'absoluteEstimateDifferenceThreshold="1e3"/>',
        **start,
    )
    single = hanging(tmp_path, **start)
    capped.step(1)
    single.step(1)
    assert np.array_equal(capped["weight/dofs"].position, single["weight/dofs"].position)
    # line search: from (1, -0.1) the full Newton step overshoots (|f| grows from 19.5 to 3.5e3);
    # halving it until |f| decreases gives x0 + 2^-k dx
    start = np.array([1.0, -0.1, 0.0])
    after = {}
    for searches in (1, 8):
        sim = hanging(
            tmp_path,
            newton=f'<NewtonRaphsonSolver maxNbIterationsLineSearch="{searches}" '
            'absoluteResidualStoppingThreshold="0" relativeInitialStoppingThreshold="0" '
            'relativeSuccessiveStoppingThreshold="0"/>',
            x=1.0,
            y=-0.1,
        )
        sim.step(1)
        after[searches] = sim["weight/dofs"].position[1].copy()
    assert residual(after[1]) > 100 * residual(start)
    assert residual(after[8]) < residual(start)
    ratio = (after[8] - start)[:2] / (after[1] - start)[:2]
    assert ratio[0] == pytest.approx(ratio[1], rel=1e-9)
    assert np.log2(ratio[0]) == pytest.approx(round(np.log2(ratio[0])), abs=1e-9)
    assert 1 <= -round(np.log2(ratio[0])) <= 7


def residual(p: np.ndarray) -> float:
    """|f| at the weight: spring and gravity."""
    length = np.linalg.norm(p)
    return float(np.linalg.norm(-K * (length - LENGTH) * p / length + [0.0, -9.81 * MASS, 0.0]))


def test_deprecated_static_solver_attributes_are_forwarded(tmp_path: Path) -> None:
    """Without a NewtonRaphsonSolver, SOFA creates one and sets it from StaticSolver's old attributes."""
    start = {"x": 0.6, "y": -0.9}
    legacy = hanging(
        tmp_path,
        static='newton_iterations="4" absolute_residual_tolerance_threshold="0"',
        newton="",
        **start,
    )
    modern = hanging(
        tmp_path,
        newton='<NewtonRaphsonSolver maxNbIterationsNewton="4" absoluteResidualStoppingThreshold="0"/>',
        **start,
    )
    legacy.step(1)
    modern.step(1)
    assert np.array_equal(legacy["weight/dofs"].position, modern["weight/dofs"].position)
    single = hanging(tmp_path, **start)
    single.step(1)
    assert not np.array_equal(single["weight/dofs"].position, modern["weight/dofs"].position)
