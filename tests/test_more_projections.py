"""Projective constraints of issue #19 (FixedPlane, Direction, LinearMovement, FixedTranslation,
FixedRotation) and the direct solvers compiled through sofac's factorisations (SVDLinearSolver's
dense SVD; CholeskySolver, LULinearSolver, AsyncSparseLDLSolver, EigenCholmodSupernodalLLT).

Each projection is checked against the closed form SOFA's code gives for a falling particle or a
rigid under symplectic Euler (v += dt a, x += dt v, projected after each step). SOFA evaluates
the key-time constraints at the step's start time, so after N steps of dt the movement read is
the one of t = (N - 1) dt.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from sofac.pipeline import compile_scene, plan_file
from sofac.simulation.loader import Simulation

DT = 0.1
STEPS = 5
GRAVITY = np.array([0.0, -10.0, -4.0])

PROJECTIONS = """\
<Node name="root" gravity="0 -10 -4" dt="0.1"><DefaultAnimationLoop/>
  <Node name="plane"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="plane_dofs" position="0 0 0  1 1 1" velocity="1 2 0  0 0 0"/>
    <UniformMass vertexMass="1"/>
    <FixedPlaneProjectiveConstraint direction="0 1 0" indices="0"/>
  </Node>
  <Node name="planes"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="planes_dofs" position="0 0 0  0 1 0  0 2 0  0 3 0"/>
    <UniformMass vertexMass="1"/>
    <FixedPlaneProjectiveConstraint direction="0 2 0" dmin="1" dmax="5"/>
  </Node>
  <Node name="line"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="line_dofs" position="1 2 3  4 5 6"/>
    <UniformMass vertexMass="1"/>
    <DirectionProjectiveConstraint direction="3 4 0" indices="1"/>
  </Node>
  <Node name="moving"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="moving_dofs" position="1 2 3  4 5 6"/>
    <UniformMass vertexMass="1"/>
    <LinearMovementProjectiveConstraint indices="1" keyTimes="0 0.3 2" movements="0 0 0  3 0 0  3 1.7 0"/>
  </Node>
  <Node name="absolute"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="absolute_dofs" position="1 2 3"/>
    <UniformMass vertexMass="1"/>
    <LinearMovementProjectiveConstraint relativeMovements="0" keyTimes="0 1" movements="5 5 5  6 5 5"/>
  </Node>
  <Node name="turning"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="turning_dofs" template="Rigid3d"
        position="1 2 3 0 0 0.38268343236508978 0.92387953251128674"/>
    <UniformMass vertexMass="1"/>
    <LinearMovementProjectiveConstraint template="Rigid3d" keyTimes="0 1"
        movements="0 0 0 0 0 0  0 0 -1 0 0 1.5"/>
  </Node>
  <Node name="translation"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="translation_dofs" template="Rigid3d" position="1 2 3 0 0 0 1"
        velocity="1 0 0 0 0 0.5"/>
    <UniformMass vertexMass="1"/>
    <FixedTranslationProjectiveConstraint template="Rigid3d"/>
  </Node>
  <Node name="rotation"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="rotation_dofs" template="Rigid3d"
        position="0 0 0 0 0 0 1  0 0 0 0 0 0.6 0.8" velocity="0 0 0 0 0 2  0 0 0 1 0 2"/>
    <UniformMass vertexMass="1"/>
    <FixedRotationProjectiveConstraint template="Rigid3d" FixedZRotation="1"/>
  </Node>
</Node>
"""


def _free_fall(steps: int, acceleration: np.ndarray) -> np.ndarray:
    """Symplectic Euler's displacement after `steps` steps from rest: dt^2 a (1 + 2 + ... + n)."""
    return DT * DT * acceleration * (steps * (steps + 1) / 2)


@pytest.fixture(scope="module")
def projected(tmp_path_factory: pytest.TempPathFactory) -> Simulation:
    path = tmp_path_factory.mktemp("projections") / "projections.scn"
    path.write_text(PROJECTIONS)
    sim = compile_scene(path).instantiate()
    sim.step(STEPS)
    return sim


def test_fixed_plane_removes_the_normal_component_of_responses(projected: Simulation) -> None:
    """The y part of gravity is projected out; the initial y velocity is kept (SOFA projects
    responses only, not velocities)."""
    x = projected["plane_dofs"].position
    t = STEPS * DT
    expected = np.array([t * 1.0, t * 2.0, 0.0]) + _free_fall(STEPS, GRAVITY * [0, 0, 1])
    assert x[0] == pytest.approx(expected, abs=1e-12)
    assert x[1] == pytest.approx(np.array([1.0, 1.0, 1.0]) + _free_fall(STEPS, GRAVITY), abs=1e-12)


def test_fixed_plane_selects_points_between_dmin_and_dmax_with_the_direction_as_given(
    projected: Simulation,
) -> None:
    """dmin < x.dir < dmax with dir = (0, 2, 0): the points at y = 1 and 2 (2y = 2, 4). SOFA does
    not normalise dir: the response becomes a - dir (a.dir), here a_y - 4 a_y = -3 a_y."""
    x = projected["planes_dofs"].position
    free = _free_fall(STEPS, GRAVITY)
    for i in (0, 3):
        assert x[i] == pytest.approx(np.array([0.0, i, 0.0]) + free, abs=1e-12)
    for i in (1, 2):
        assert x[i] == pytest.approx(np.array([0.0, i, 0.0]) + free * [0, -3, 1], abs=1e-12)


def test_direction_keeps_points_on_the_line_through_their_start(projected: Simulation) -> None:
    n = np.array([0.6, 0.8, 0.0])
    x = projected["line_dofs"].position
    assert x[1] == pytest.approx(np.array([4.0, 5.0, 6.0]) + _free_fall(STEPS, n * (n @ GRAVITY)), abs=1e-12)
    assert x[0] == pytest.approx(np.array([1.0, 2.0, 3.0]) + _free_fall(STEPS, GRAVITY), abs=1e-12)


def test_linear_movement_interpolates_the_keys_at_the_steps_start_time(projected: Simulation) -> None:
    t = (STEPS - 1) * DT  # 0.4: between the keys 0.3 and 2
    movement = np.array([3.0, 0.0, 0.0]) + (t - 0.3) / (2 - 0.3) * np.array([0.0, 1.7, 0.0])
    moving = projected["moving_dofs"]
    assert moving.position[1] == pytest.approx(np.array([4.0, 5.0, 6.0]) + movement, abs=1e-12)
    assert moving.velocity[1] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)  # (m1 - m0) / (t1 - t0)
    free = np.array([1.0, 2.0, 3.0]) + _free_fall(STEPS, GRAVITY)
    assert moving.position[0] == pytest.approx(free, abs=1e-12)
    # Index 0 by default, absolute movements: x = m.
    assert projected["absolute_dofs"].position[0] == pytest.approx([5.0 + t, 5.0, 5.0], abs=1e-12)


def test_linear_movement_of_a_rigid_slerps_its_euler_rotation(projected: Simulation) -> None:
    """x0's orientation (45 degrees about z) times slerp(identity, Euler(0, 0, 1.5), t)."""
    t = (STEPS - 1) * DT
    x = projected["turning_dofs"].position[0]
    angle = math.pi / 4 + 1.5 * t
    assert x[:3] == pytest.approx([1.0, 2.0, 3.0 - t], abs=1e-12)
    assert x[3:] == pytest.approx([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)], abs=1e-9)


def test_fixed_translation_zeroes_responses_but_keeps_velocities(projected: Simulation) -> None:
    """SOFA clears the whole derivative of the response (gravity has no effect) and leaves the
    initial velocity: the rigid drifts at v0 and keeps turning at w0."""
    x = projected["translation_dofs"].position[0]
    t = STEPS * DT
    assert x[:3] == pytest.approx([1.0 + t, 2.0, 3.0], abs=1e-12)
    angle = 0.5 * t
    assert x[3:] == pytest.approx([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)], abs=1e-9)


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions (SOFA's Quat::operator*)."""
    (ax, ay, az, aw), (bx, by, bz, bw) = a, b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by + ay * bw + az * bx - ax * bz,
            aw * bz + az * bw + ax * by - ay * bx,
            aw * bw - (ax * bx + ay * by + az * bz),
        ]
    )


def test_fixed_rotation_keeps_the_initial_twist_about_the_fixed_axis(projected: Simulation) -> None:
    """SOFA's swing-twist projection: q = swing(q) * twist0, where swing(q) has no twist about z
    (its z component is 0) and twist0 is the initial orientation's twist about z."""
    rigid = projected["rotation_dofs"].position
    # Turning about z only: the orientation stays the initial one.
    assert rigid[0, 3:] == pytest.approx([0.0, 0.0, 0.0, 1.0], abs=1e-12)
    # Turning about x and z from 2 atan2(0.6, 0.8) about z.
    q, initial = rigid[1, 3:], np.array([0.0, 0.0, 0.6, 0.8])
    swing = _product(q, initial * [-1, -1, -1, 1])
    assert swing[2] == pytest.approx(0.0, abs=1e-12)
    assert abs(swing[0]) > 0.05  # the rotation about x is kept
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)


# ---- direct solvers -----------------------------------------------------------------------------

BEAM = """\
<Node name="root" dt="0.02" gravity="0 -10 0"><DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
  <{solver}/>
  <MechanicalObject name="beam"/>
  <UniformMass totalMass="32"/>
  <RegularGridTopology nx="2" ny="2" nz="5" xmin="0" xmax="1" ymin="0" ymax="1" zmin="0" zmax="4"/>
  <BoxROI name="box" box="-1 -1 -0.001  2 2 0.001"/>
  <FixedProjectiveConstraint indices="@box.indices"/>
  <HexahedronFEMForceField youngModulus="4000" poissonRatio="0.3" method="large"/>
</Node>
"""


def _beam(tmp_path: Path, solver: str) -> Path:
    path = tmp_path / f"{solver.split()[0]}.scn"
    path.write_text(BEAM.format(solver=solver))
    return path


def test_svd_solver_matches_the_sparse_ldl_solution(tmp_path: Path) -> None:
    """A well-conditioned system: the pseudo-inverse is the inverse, SVD and L D L^T agree."""
    ends = {}
    for solver in ("SVDLinearSolver", "SparseLDLSolver"):
        sim = compile_scene(_beam(tmp_path, solver)).instantiate()
        sim.step(10)
        ends[solver] = sim["beam"].position.copy()
        assert np.isfinite(ends[solver]).all()
    moved = np.abs(ends["SparseLDLSolver"] - ends["SVDLinearSolver"]).max()
    assert moved < 1e-10
    assert ends["SVDLinearSolver"][:, 1].min() < -0.01  # it did bend


@pytest.mark.parametrize(
    ("solver", "llt", "svd"),
    [
        ("AsyncSparseLDLSolver", False, False),
        ('CholeskySolver template="FullMatrix"', True, False),
        ("LULinearSolver", False, False),
        ("EigenCholmodSupernodalLLT", True, False),
        ('SVDLinearSolver minSingularValue="0.25"', False, True),
    ],
)
def test_direct_solvers_plan_a_factorisation(tmp_path: Path, solver: str, llt: bool, svd: bool) -> None:
    (group,) = plan_file(_beam(tmp_path, solver)).groups
    assert group.direct and group.assembled
    assert group.llt is llt
    assert (group.svd_threshold is not None) is svd
    if svd:
        assert group.svd_threshold.initial.tolist() == [0.25]
