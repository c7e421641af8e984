"""Lagrangian contact under FreeMotionAnimationLoop: LocalMinDistance detection and the
FrictionContactConstraint response (runtime/sofac/lagrangian_contact.h), against closed-form
answers and SOFA's regression references."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import sofac
from lagrangian_scenes import CONTACT, DT, G, contact_root, static_floor
from sofac.check.checker import check_file
from sofac.diagnostics import SceneError
from sofac.plan.ir import Plan
from sofac.plan.planner import plan_scene
from sofac.regress.suite import Status, run_regression

MASS = 2.0


def scene(
    tmp_path: Path,
    floor: np.ndarray,
    start: tuple[float, float, float],
    *,
    mu: float = 0.0,
    solver: str = '<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="100"/>',
) -> Path:
    """A particle (mass 2, compliance 1/m) above a static floor of two triangles, no damping."""
    points = " ".join(f"{v:.17g}" for v in floor.ravel())
    text = (
        contact_root(solver, mu)
        + f"""    <Node name="Particle">
        <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0" />
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-20" />
        <MechanicalObject name="dofs" position="{start[0]:.17g} {start[1]:.17g} {start[2]:.17g}" />
        <UniformMass totalMass="{MASS}" />
        <UncoupledConstraintCorrection compliance="{1.0 / MASS}" />
        <PointCollisionModel />
    </Node>
"""
        + static_floor(points)
        + "</Node>\n"
    )
    path = tmp_path / "contact.scn"
    path.write_text(text)
    return path


FLAT = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=float)


def incline(theta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor turned by theta about z (down the slope: +x), its normal and its downhill axis."""
    c, s = math.cos(theta), math.sin(theta)
    turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return FLAT @ turn.T, turn @ np.array([0.0, 1.0, 0.0]), turn @ np.array([-1.0, 0.0, 0.0])


def test_a_particle_lands_and_rests_at_the_contact_distance(tmp_path: Path) -> None:
    sim = sofac.load(scene(tmp_path, FLAT, (0.3, 0.1, 0.2)))
    for _ in range(20):  # lands within 10 steps, stopped dead (a plastic impact)
        sim.step(1)
    heights, impulses = [], []
    for _ in range(100):
        sim.step(1)
        heights.append(sim["/Particle/dofs"].position[0, 1])
        impulses.append(sim.output("/.constraint_f")[0])
        assert sim.output("/CollisionPipeline3.contactReport")[0] == 1  # one contact
    # no penetration beyond the contact distance, no drift
    assert np.abs(np.array(heights) - CONTACT).max() < 1e-12
    assert abs(sim["/Particle/dofs"].velocity[0, 1]) < 1e-12
    # the normal impulse carries the weight over the step: m g dt
    assert np.allclose(impulses, MASS * G * DT, rtol=1e-12, atol=0)


@pytest.mark.parametrize("mu", [0.3, 0.6])
def test_a_block_on_an_incline_sticks_or_slides_by_coulomb(tmp_path: Path, mu: float) -> None:
    theta = math.radians(25.0)  # tan = 0.466: sticks with mu 0.6, slides with mu 0.3
    floor, normal, downhill = incline(theta)
    # inside triangle (0, 2, 1), off the diagonal both triangles share; at rest on the surface
    start = floor[0] + (floor[1] - floor[0]) * 0.6 + (floor[3] - floor[0]) * 0.3 + normal * CONTACT
    sim = sofac.load(scene(tmp_path, floor, tuple(start), mu=mu))
    steps = 30
    speeds = []
    for _ in range(steps):
        sim.step(1)
        speeds.append(float(sim["/Particle/dofs"].velocity[0] @ downhill))
        x = sim["/Particle/dofs"].position[0]
        assert abs((x - floor[0]) @ normal - CONTACT) < 1e-9  # on the surface throughout
    impulse = sim.output("/.constraint_f")[:3]
    assert math.hypot(impulse[1], impulse[2]) <= mu * impulse[0] * (1 + 1e-12)  # Coulomb's cone
    if mu > math.tan(theta):
        assert np.abs(speeds).max() < 1e-9
        assert np.linalg.norm(sim["/Particle/dofs"].position[0] - start) < 1e-9
    else:
        a = G * (math.sin(theta) - mu * math.cos(theta))
        expected = a * DT * np.arange(1, steps + 1)
        assert np.allclose(speeds, expected, rtol=1e-9, atol=1e-12)


def plan_of(path: Path) -> Plan:
    checked, _ = check_file(path)
    assert checked is not None
    return plan_scene(checked)


def test_the_effects_and_schedule_list_the_contact_rows(tmp_path: Path) -> None:
    from sofac.plan.report import format_effects, format_schedule

    plan = plan_of(scene(tmp_path, FLAT, (0.3, 0.1, 0.2), mu=0.4))
    schedule = format_schedule(plan)
    assert "constraint rows: 384 (reserved: 0 of the scene's constraints, then 128 contacts" in schedule
    assert "more contacts double the reserve" in schedule
    text = format_effects(plan)
    assert "local_min_distance::triangle_point, FrictionContactConstraint mu=0.4: 3 constraint row(s)" in text


def test_a_negative_mu_is_an_error_of_check_with_its_line(tmp_path: Path) -> None:
    _, diagnostics = check_file(scene(tmp_path, FLAT, (0.3, 0.1, 0.2), mu=-0.5))
    (diagnostic,) = [d for d in diagnostics.sorted() if d.code == "E207"]
    assert diagnostic.loc.line == 9 and diagnostic.loc.attribute == "responseParams"
    assert "mu=-0.5 must be >= 0" in diagnostic.message


def test_a_correction_without_compliance_is_said_as_sofa_says_it(tmp_path: Path) -> None:
    # A point state: SOFA warns and gives every DOF defaultCompliance's default (W247).
    points = scene(tmp_path, FLAT, (0.3, 0.1, 0.2))
    points.write_text(points.read_text().replace(f'compliance="{1.0 / MASS}"', ""))
    _, diagnostics = check_file(points)
    (warning,) = [d for d in diagnostics.sorted() if d.code == "W247"]
    assert warning.loc.line == 15 and "defaultCompliance's default, 1e-05" in warning.message
    assert not diagnostics.has_errors()
    # A rigid state without a UniformMass has no compliance at all: an error of check (E226).
    dofs = 'name="dofs" template="Rigid3d"'
    rigid = re.sub(r'name="dofs" position="[^"]*"', dofs, points.read_text(), count=1)
    rigid = rigid.replace(f'<UniformMass totalMass="{MASS}" />', "").replace("<PointCollisionModel />", "")
    points.write_text(rigid)
    _, diagnostics = check_file(points)
    (error,) = [d for d in diagnostics.sorted() if d.code == "E226"]
    assert error.loc.line == 15 and "no UniformMass to compute it from" in error.message


def test_a_constraint_below_the_root_with_contacts_is_refused(tmp_path: Path) -> None:
    path = scene(tmp_path, FLAT, (0.3, 0.1, 0.2))
    bilateral = (
        '        <BilateralLagrangianConstraint object1="@/Floor/dofs" object2="@/Particle/dofs" '
        'first_point="0" second_point="0"/>\n'
    )
    text = path.read_text().replace(
        "        <PointCollisionModel />\n", "        <PointCollisionModel />\n" + bilateral
    )
    path.write_text(text)
    with pytest.raises(SceneError) as error:
        plan_of(path)
    (diagnostic,) = [d for d in error.value.diagnostics if d.code == "E222"]
    assert diagnostic.loc.line == 17 and "move it to the root" in diagnostic.message


def test_penalty_contact_under_free_motion_keeps_the_contact_guard(tmp_path: Path) -> None:
    path = scene(tmp_path, FLAT, (0.3, 0.1, 0.2))
    path.write_text(path.read_text().replace("FrictionContactConstraint", "PenalityContactForceField"))
    plan = plan_of(path)  # not compiled: the step stops before the first possible contact
    assert plan.collisions == [] and plan.contact_guard is not None


# SOFA's regression scenes with LocalMinDistance and FrictionContactConstraint (contacts occur in
# all but the Bilateral ones' first 93 steps); each compiles a scene (30-70 s).
SCENES = [
    "Component/Constraint/Lagrangian/BilateralLagrangianConstraint_PGS.scn",
    "Component/Constraint/Lagrangian/BilateralLagrangianConstraint_NNCG.scn",
    "Component/Constraint/Lagrangian/BilateralLagrangianConstraint_UGS.scn",
    "Component/Collision/Response/FrictionContact.scn",  # LCP built, 3-30 contacts a step
    "Component/Collision/Response/RuleBasedContactManager.scn",  # BGS, .rigid masses
    "Component/Constraint/Lagrangian/FrictionContact_LCP_without_friction.scn",  # LCP unbuilt, guess
]


@pytest.mark.long
@pytest.mark.parametrize("name", SCENES)
def test_lagrangian_regression_scene_passes(shared_dir: Path, name: str) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[name]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon


def test_one_compliance_for_many_points_is_each_point_s(tmp_path: Path) -> None:
    # SOFA's UncoupledConstraintCorrection::init: a compliance that is not one per DOF becomes one
    # per DOF, each its first value (defaultCompliance when that is set)
    path = scene(tmp_path, FLAT, (0.3, 0.1, 0.2))
    first = f'position="{0.3:.17g}'
    text = path.read_text().replace(first, 'position="0.5 0.1 0.2  ' + first[len('position="') :])
    assert text != path.read_text()
    path.write_text(text)
    plan = plan_of(path)
    (compliance,) = [b for b in plan.buffers if b.key.endswith("UncoupledConstraintCorrection5.compliance")]
    assert compliance.initial.tolist() == [1.0 / MASS, 1.0 / MASS]
    path.write_text(
        text.replace(
            "<UncoupledConstraintCorrection ", '<UncoupledConstraintCorrection defaultCompliance="3" '
        )
    )
    (compliance,) = [
        b for b in plan_of(path).buffers if b.key.endswith("UncoupledConstraintCorrection5.compliance")
    ]
    assert compliance.initial.tolist() == [3.0, 3.0]
