"""Bilateral constraint rows compiled end to end under FreeMotionAnimationLoop:
BilateralLagrangianConstraint<Vec3d> between unmapped states, UncoupledConstraintCorrection<Vec3d>
(compliance 1/m given per state), EulerImplicitSolver free motion, BGS or NNCG. Closed forms: a
particle hanging on a fixed anchor rests there with the multiplier m g; two particles joined by
a bilateral constraint move as one body with the momentum they had (a perfectly inelastic
merge); a solve that hits its iteration limit is a warning naming the residual."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.plan.ir import CONSTRAINT_REPORT_FIELDS

HANGING = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop name="loop"/>
    <{solver} maxIterations="{iterations}" tolerance="{tolerance}"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="dofs" position="0 1 0  1 1 0"/>
        <UniformMass vertexMass="{mass}"/>
        <UncoupledConstraintCorrection template="Vec3d" defaultCompliance="{compliance}"/>
    </Node>
    <Node name="B">
        <MechanicalObject name="anchor" position="0 1 0"/>
    </Node>
    <BilateralLagrangianConstraint object1="@B/anchor" object2="@A/dofs" first_point="0" second_point="0"/>
</Node>
"""

MERGE = """<Node name="root" dt="0.01" gravity="0 0 0">
    <FreeMotionAnimationLoop/>
    <BlockGaussSeidelConstraintSolver maxIterations="100" tolerance="1e-12"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="a" position="0 0 0" velocity="1 2 0"/>
        <UniformMass vertexMass="2"/>
        <UncoupledConstraintCorrection template="Vec3d" defaultCompliance="0.5"/>
    </Node>
    <Node name="B">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="b" position="0 0 0" velocity="-3 0 1"/>
        <UniformMass vertexMass="6"/>
        <UncoupledConstraintCorrection template="Vec3d" defaultCompliance="0.16666666666666666"/>
    </Node>
    <BilateralLagrangianConstraint object1="@A/a" object2="@B/b" first_point="0" second_point="0"/>
</Node>
"""


def hanging(tmp_path: Path, solver: str = "BlockGaussSeidelConstraintSolver", **values: object) -> Path:
    fields = {"iterations": 100, "tolerance": 1e-10, "mass": 0.5, "compliance": 2.0} | values
    path = tmp_path / f"hanging_{solver}.scn"
    path.write_text(HANGING.format(solver=solver, **fields))
    return path


@pytest.mark.parametrize("solver", ["BlockGaussSeidelConstraintSolver", "NNCGConstraintSolver"])
def test_a_hanging_particle_rests_on_its_anchor_with_multiplier_m_g(tmp_path: Path, solver: str) -> None:
    dt, mass, g = 0.01, 0.5, 9.81
    sim = sofac.load(hanging(tmp_path, solver))
    sim.step(40)
    dofs = sim["/A/dofs"]
    np.testing.assert_allclose(dofs.position[0], [0.0, 1.0, 0.0], atol=1e-12)  # held at the anchor
    np.testing.assert_allclose(dofs.velocity[0], 0.0, atol=1e-12)
    # the free point falls freely: implicit Euler, x_k = x_0 - g dt^2 k (k + 1) / 2
    np.testing.assert_allclose(dofs.position[1], [1.0, 1.0 - g * dt * dt * 40 * 41 / 2, 0.0], rtol=1e-12)
    force = sim.output("/.constraint_kept_forces")  # the impulse of a step (the resolution's store)
    np.testing.assert_allclose(force / dt, [0.0, mass * g, 0.0], rtol=1e-9, atol=1e-9)


def test_two_joined_particles_move_as_one_body_with_their_momentum(tmp_path: Path) -> None:
    path = tmp_path / "merge.scn"
    path.write_text(MERGE)
    sim = sofac.load(path)
    momentum = 2.0 * np.array([1.0, 2.0, 0.0]) + 6.0 * np.array([-3.0, 0.0, 1.0])
    for _ in range(5):
        sim.step(1)
        a, b = sim["/A/a"], sim["/B/b"]
        np.testing.assert_allclose(a.position, b.position, atol=1e-14)
        np.testing.assert_allclose(a.velocity[0], momentum / 8.0, rtol=1e-12)
        np.testing.assert_allclose(b.velocity[0], momentum / 8.0, rtol=1e-12)


def test_the_iteration_limit_is_a_warning_with_the_residual(tmp_path: Path) -> None:
    # the first solve starts from zero and stops after its one sweep, whose change of force is the
    # residual (|W f| = |dfree| = g dt^2); the next ones start from the kept force and converge
    sim = sofac.load(hanging(tmp_path, iterations=1, tolerance=1e-15))
    expected = r"limit in 1 solve\(s\) \(last at t=0\.0: residual 0\.00098"
    with pytest.warns(RuntimeWarning, match=expected) as caught:
        sim.step(3)
    assert "SOFA's iteration count 2" in str(caught[0].message)  # sweeps + 1, as SOFA counts
    seconds = dict(zip(CONSTRAINT_REPORT_FIELDS, sim.output("/loop.constraint_report"), strict=True))
    assert seconds["detection_seconds"] == 0.0  # no collision pipeline: no detection timed
    assert seconds["free_motion_seconds"] > 0 and seconds["solve_seconds"] > 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim.reset()
        report = sim.output("/loop.constraint_report")
        assert report.tolist() == [0.0] * len(CONSTRAINT_REPORT_FIELDS)  # the timers too


CHAIN = Path(__file__).parent / "data" / "constraints" / "bilateral_chain_no_collision.scn"
# (object1 points, index, object2 points, index) of the chain's four BilateralLagrangianConstraints
LINKS = [
    ("/CUBE_0/Constraints/points", 0, "/CUBE_1/Constraints/points", 0),
    ("/CUBE_1/Constraints/points", 1, "/CUBE_2/Constraints/points", 0),
    ("/CUBE_2/Constraints/points", 1, "/CUBE_3/Constraints/points", 0),
    ("/CUBE_2/Constraints/points", 1, "/CUBE_4/Constraints/points", 0),
]


def test_a_chain_of_rigid_cubes_holds_its_rigidly_mapped_attachments(corpus_dir: Path) -> None:
    """SOFA's BilateralLagrangianConstraint_PGS chain without its collision models: four rigid
    cubes (UncoupledConstraintCorrection<Rigid3d>, compliance from their UniformMass) hang by
    corner points mapped with RigidMapping; rows carried to the frames by applyJT. Before any
    contact could happen (their boxes first meet before step 49), the attachments hold while the
    chain swings fast, and it swings: the run is no constraint-free fall."""
    sim = sofac.load(CHAIN, data_roots=[corpus_dir])
    phase = sim.plan.constraints
    assert phase is not None and phase.capacity == 12 and len(phase.blocks) == 4
    for _ in range(4):
        sim.step(10)
        for first, i, second, j in LINKS:
            gap = np.linalg.norm(sim[first].position[i] - sim[second].position[j])
            assert gap < 2e-3, (first, second, gap)
    fastest = max(np.abs(sim[f"/CUBE_{k}/MechanicalObject3"].velocity[0, 3:]).max() for k in range(1, 5))
    assert fastest > 5.0  # rad/s: the cubes turn about their attachments
    # free fall for 40 ms would take a cube 0.78 down; the first one turns about its anchor instead
    assert sim["/CUBE_1/MechanicalObject3"].position[0, 1] > -0.78 / 2


@pytest.mark.parametrize(
    ("solver", "correction", "refused"),
    [
        ("LCPConstraintSolver", "UncoupledConstraintCorrection", "LCPConstraintSolver"),
        (
            "BlockGaussSeidelConstraintSolver",
            "LinearSolverConstraintCorrection",
            "LinearSolverConstraintCorrection",
        ),
    ],
)
def test_what_rows_are_not_compiled_for_is_refused_at_its_line(
    tmp_path: Path, solver: str, correction: str, refused: str
) -> None:
    from sofac.check.checker import check_file
    from sofac.plan.planner import plan_scene

    text = HANGING.format(solver=solver, iterations=100, tolerance=1e-6, mass=1.0, compliance=1.0)
    text = text.replace(
        '<UncoupledConstraintCorrection template="Vec3d" defaultCompliance="1.0"/>', f"<{correction}/>"
    )
    path = tmp_path / "refused.scn"
    path.write_text(text.replace("maxIterations", "maxIt") if solver == "LCPConstraintSolver" else text)
    checked, _ = check_file(path)
    assert checked is not None
    with pytest.raises(sofac.SceneError) as caught:
        plan_scene(checked)
    line = next(n for n, row in enumerate(text.splitlines(), start=1) if f"<{refused}" in row)
    assert f"unsupported component {refused} at line {line}" in str(caught.value)


def test_the_ugs_chain_without_collision_models_matches_sofa(
    tmp_path: Path, shared_dir: Path, corpus_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SOFA's BilateralLagrangianConstraint_UGS.scn without its collision models, scored against the
    original scene's reference with SOFA's criterion. UGS solves with W's diagonal blocks of the raw
    compliance (no dt factor: SOFA's inconsistency, reproduced), so the chain is soft and its cubes
    never come near each other: the reference holds no contact. Every step of it has to be SOFA's:
    free motion, RigidMapping's applyJT and linearised free positions, the rigid compliance from
    the UniformMass, the unbuilt sweeps and the correction."""
    from sofac.regress.suite import Status, run_regression

    scene = "Component/Constraint/Lagrangian/BilateralLagrangianConstraint_UGS.scn"
    target = tmp_path / scene
    target.parent.mkdir(parents=True)
    target.write_text((CHAIN.parent / "bilateral_chain_ugs_no_collision.scn").read_text())
    monkeypatch.setenv("SOFAC_DATA_PATH", str(corpus_dir))
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(root / "scenes.regression-tests", tmp_path, root, only=[scene])
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= 1e-6


PENDULUM = """<Node name="root" dt="0.001" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop/>
    <BlockGaussSeidelConstraintSolver maxIterations="200" tolerance="1e-12"/>
    <Node name="Body">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
        <MechanicalObject name="frame" template="Rigid3d" position="1 0 0  0 0 0 1"/>
        <UniformMass totalMass="0.1"/>
        <UncoupledConstraintCorrection template="Rigid3d"/>
        <Node name="Pivot">
            <MechanicalObject name="point" template="Vec3d" position="-1 0 0"/>
            <RigidMapping/>
        </Node>
    </Node>
    <Node name="Anchor">
        <MechanicalObject name="anchor" position="0 0 0"/>
    </Node>
    <BilateralLagrangianConstraint object1="@Anchor/anchor" object2="@Body/Pivot/point" first_point="0"
        second_point="0"/>
</Node>
"""


def test_a_rigid_pendulum_held_by_a_bilateral_constraint_keeps_its_length(tmp_path: Path) -> None:
    """A rigid body of length 1 from its pivot, released horizontally: the bilateral row on its
    RigidMapping'd pivot point holds the pivot on the anchor, so the centre of mass stays 1 from
    it while the body swings down through a quarter turn. (UniformMass's default inertia is m per
    axis: a radius of gyration of 1, an equivalent simple pendulum of length 2 that reaches the
    bottom after about 0.84 s.)"""
    path = tmp_path / "pendulum.scn"
    path.write_text(PENDULUM)
    sim = sofac.load(path)
    lowest = 0.0
    for _ in range(100):
        sim.step(10)
        centre = sim["/Body/frame"].position[0, :3]
        pivot = sim["/Body/Pivot/point"].position[0]
        assert np.linalg.norm(pivot) < 1e-4
        assert abs(np.linalg.norm(centre) - 1.0) < 1e-4
        lowest = min(lowest, centre[1])
    assert lowest < -0.95  # it swung down (a free fall of 1 s would take it 4.9 down, off the circle)


def test_points_of_a_state_whose_positions_are_unknown_are_refused_at_the_attribute(tmp_path: Path) -> None:
    """A state whose positions come from an engine output sofac does not evaluate (BoxROI's
    pointsOutROI) has no known size: rows on its points are refused (E222 at second_point, what
    `sofac check` reports too), not planned on a state of 0 points (an IndexError while carrying
    them through a RigidMapping: SOFA's BilateralLagrangianConstraint_Soft_Rigid_Bodies.scn, before
    BoxROI's pointsInROI was evaluated)."""
    from sofac.check.checker import check_file
    from sofac.pipeline import add_compile_refusals

    text = HANGING.format(
        solver="BlockGaussSeidelConstraintSolver", iterations=100, tolerance=1e-6, mass=1.0, compliance=1.0
    )
    text = text.replace(
        '<MechanicalObject name="dofs" position="0 1 0  1 1 0"/>',
        '<BoxROI name="roi" box="-1 -1 -1 0.5 2 1" position="0 1 0  1 1 0"/>\n'
        '        <MechanicalObject name="dofs" position="@roi.pointsOutROI"/>',
    )
    path = tmp_path / "unknown.scn"
    path.write_text(text)
    checked, diagnostics = check_file(path)
    add_compile_refusals(checked, diagnostics)
    line = next(
        n for n, row in enumerate(text.splitlines(), start=1) if "<BilateralLagrangianConstraint" in row
    )
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diagnostics.errors] == [
        ("E222", line, "second_point")
    ]
    assert "whose positions sofac does not know at compile time" in diagnostics.errors[0].message


def test_box_roi_points_in_roi_give_a_state_its_positions(tmp_path: Path) -> None:
    """BoxROI::doUpdate's pointsInROI, the input points inside in index order, evaluated at compile
    time: a MechanicalObject reading them has those positions."""
    from sofac.check.checker import check_file

    path = tmp_path / "roi.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        '  <BoxROI name="roi" box="0.5 -1 -1 3 1 1" position="0 0 0  1 0 0  5 0 0  2 0.5 0"/>\n'
        '  <MechanicalObject name="dofs" position="@roi.pointsInROI"/>\n'
        "</Node>\n"
    )
    checked, diagnostics = check_file(path)
    assert diagnostics.errors == []
    dofs = next(c for c in checked.scene.root.components() if c.label == "dofs")
    assert checked.positions(dofs).tolist() == [[1, 0, 0], [2, 0.5, 0]]


def test_a_fixed_end_leaves_the_rows_as_in_sofa(tmp_path: Path) -> None:
    """GenericConstraintSolver::buildSystem clears the constraint matrix's columns of the DOFs a
    projective constraint holds (projectJacobianMatrix): a particle joined to a FixedProjectiveConstraint'd
    one (at rest: SOFA's fixed DOF keeps its velocity) gets the whole correction (W = C_a alone) and
    reaches it in one step, which stays put. With the fixed particle's compliance counted, a would
    only go part of the way and b would move."""
    fixed = '<UniformMass vertexMass="6"/>\n        <FixedProjectiveConstraint indices="0"/>'
    text = MERGE.replace('<UniformMass vertexMass="6"/>', fixed).replace(
        'velocity="-3 0 1"', 'velocity="0 0 0"'
    )
    path = tmp_path / "fixed_end.scn"
    path.write_text(text)
    sim = sofac.load(path)
    sim.step(3)
    np.testing.assert_allclose(sim["A/a"].position, [[0, 0, 0]], atol=1e-12)
    assert sim["B/b"].position.tolist() == [[0.0, 0.0, 0.0]]


def test_rows_on_a_moved_frame_are_refused_at_its_correction(tmp_path: Path) -> None:
    """LinearMovementProjectiveConstraint clears its DOFs' columns only between its key times: rows
    reaching them under an UncoupledConstraintCorrection are refused (E222 at the correction), as
    SOFA's BilateralLagrangianConstraint_Soft_Rigid_Bodies.scn is (sofac's run of it diverged)."""
    from sofac.check.checker import check_file
    from sofac.pipeline import add_compile_refusals

    moved = '<LinearMovementProjectiveConstraint keyTimes="0 1" movements="0 0 0  1 0 0"/>'
    text = MERGE.replace('<UniformMass vertexMass="6"/>', f'<UniformMass vertexMass="6"/>\n        {moved}')
    path = tmp_path / "moved.scn"
    path.write_text(text)
    checked, diagnostics = check_file(path)
    add_compile_refusals(checked, diagnostics)
    line = next(n for n, row in enumerate(text.splitlines(), start=1) if 'defaultCompliance="0.1666' in row)
    assert [(d.code, d.loc.line) for d in diagnostics.errors] == [("E222", line)]
    assert "LinearMovementProjectiveConstraint" in diagnostics.errors[0].message
