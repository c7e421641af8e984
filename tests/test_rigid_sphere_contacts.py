"""SphereCollisionModel<Rigid3d> under penalty contact (issue #16): spheres centred on rigid
frames, their contact points fixed in the frames (SOFA's RigidContactMapper: a RigidMapping onto
the contact points), the contact forces applied to the frames as a force and a torque.

SOFA's detection puts a rigid sphere's contact point on its surface (getContactPointByNormal:
centre - n r) in the triangle and MinProximity tests, and its contact mapper adds the radius to the
contact distance as for a Vec3d sphere, whose contact point is its centre: a rigid sphere resting
on triangles floats one radius higher than a Vec3d one, at 2 r + d - m g / ks. NewProximity's
sphere-point test keeps the centres: r + d - m g / ks there. Both are reproduced."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.pipeline import plan_file

DATA = Path(__file__).parent / "data"
SPHERE_FLOOR = DATA / "contact_sphere_floor.scn"
RIGID = '<MechanicalObject name="dofs" template="Rigid3d" position="0.1 0.4 -0.2 0 0 0 1"/>'
D, R, KS = 0.2, 0.1, 10.0 * 10.0 / (0.2 + 0.1)  # contact distance, radius, k1 k2 / (d + r)


def rigid_scene(tmp_path: Path, name: str, text: str = "") -> Path:
    text = text or SPHERE_FLOOR.read_text()
    path = tmp_path / name
    path.write_text(text.replace('<MechanicalObject name="dofs" position="0.1 0.4 -0.2"/>', RIGID))
    return path


@pytest.mark.parametrize("method", ["NewProximityIntersection", "MinProximityIntersection"])
def test_rigid_sphere_rests_on_triangles_one_radius_higher(tmp_path: Path, method: str) -> None:
    """ks (2 r + d - h) = m g: the contact point on the sphere's surface, the radius in the
    distance. The force goes through the centre: no torque, the frame does not turn."""
    text = SPHERE_FLOOR.read_text().replace("NewProximityIntersection", method)
    path = rigid_scene(tmp_path, "rigid.scn", text)
    plan = plan_file(path)
    (pair,) = plan.collisions[0].pairs
    assert plan.collisions[0].models[pair.second].rigid and not pair.root
    sim = sofac.load(path)
    sim.step(800)
    frame = sim["/Particle/dofs"]
    assert frame.position[0, 1] == pytest.approx(2 * R + D - 1.0 * 9.81 / KS, abs=1e-9)
    assert frame.position[0, [0, 2]] == pytest.approx([0.1, -0.2], abs=1e-12)
    assert np.abs(frame.position[0, 3:6]).max() < 1e-12 and np.abs(frame.velocity[0]).max() < 1e-8


def test_rigid_sphere_on_a_point_rests_at_its_radius(tmp_path: Path) -> None:
    """NewProximity's sphere-point test compares the centre with the point: the sphere rests at
    r + d - m g / ks above the point (ks = k1 k2 / (d + r))."""
    text = SPHERE_FLOOR.read_text().replace(
        '<MechanicalObject name="points" position="-1 0 -1  1 0 -1  1 0 1  -1 0 1"/>',
        '<MechanicalObject name="points" position="0.1 0 -0.2"/>',
    )
    text = text.replace('<MeshTopology triangles="0 2 1  0 3 2"/>', "").replace(
        '<TriangleCollisionModel moving="0"', '<PointCollisionModel moving="0"'
    )
    sim = sofac.load(rigid_scene(tmp_path, "point.scn", text))
    sim.step(800)
    assert sim["/Particle/dofs"].position[0, 1] == pytest.approx(R + D - 9.81 / KS, abs=1e-9)


INCLINE = """<?xml version="1.0"?>
<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <CollisionPipeline depth="6"/>
    <BruteForceBroadPhase/>
    <BVHNarrowPhase/>
    <MinProximityIntersection alarmDistance="0.5" contactDistance="{d}"/>
    <CollisionResponse response="PenalityContactForceField"/>
    <Node name="Incline">
        <MechanicalObject name="points" position="{corners}"/>
        <MeshTopology triangles="0 1 2"/>
        <TriangleCollisionModel moving="0" simulated="0" contactStiffness="10"/>
    </Node>
    <Node name="Ball">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        <CGLinearSolver iterations="50" tolerance="1e-20" threshold="1e-30"/>
        <MechanicalObject name="dofs" template="Rigid3d" position="{start} 0 0 0 1"/>
        <UniformMass totalMass="{m}"/>
        <SphereCollisionModel radius="{r}" contactStiffness="10"/>
    </Node>
</Node>
"""


def test_rigid_sphere_slides_down_a_frictionless_incline(tmp_path: Path) -> None:
    """On a 30 degree incline, started where ks pen = m g cos(theta): the penalty force has no
    tangential part (SOFA's PenalityContactForceField ignores friction) and passes through the
    centre, so the sphere slides without turning, as implicit Euler integrates a constant force:
    v_k = k h g sin(theta), s_k = s_0 - h^2 g sin(theta) k (k + 1) / 2 along the slope."""
    theta, m, h = np.radians(30.0), 2.0, 0.01
    t = np.array([np.cos(theta), np.sin(theta), 0.0])  # up the slope
    n = np.array([-np.sin(theta), np.cos(theta), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    corners = [-10 * t - 10 * z, 10 * t - 10 * z, 10 * z]
    ks = 100.0 / (D + R)
    height = 2 * R + D - m * 9.81 * np.cos(theta) / ks  # the centre's distance from the plane
    start = 1.5 * t + height * n
    path = tmp_path / "incline.scn"
    path.write_text(
        INCLINE.format(
            d=D, m=m, r=R,
            corners="  ".join(" ".join(repr(float(c)) for c in p) for p in corners),
            start=" ".join(repr(float(c)) for c in start),
        )
    )  # fmt: skip
    sim = sofac.load(path)
    for k in range(1, 61):
        sim.step()
        x, v = sim["/Ball/dofs"].position[0], sim["/Ball/dofs"].velocity[0]
        along = 1.5 - h * h * 9.81 * np.sin(theta) * k * (k + 1) / 2
        assert (x[:3] - start) @ n == pytest.approx(0.0, abs=1e-9), k  # at its distance from the plane
        assert x[:3] @ t == pytest.approx(along, abs=1e-9), k
        assert v[:3] @ t == pytest.approx(-k * h * 9.81 * np.sin(theta), abs=1e-9), k
        assert np.abs(v[3:]).max() < 1e-12 and np.abs(x[3:6]).max() < 1e-12  # no rotation


def test_assembled_solver_takes_the_frames_contact_stiffness(tmp_path: Path) -> None:
    """SparseLDLSolver assembles the contact's J^T (-ks n n^T) J on the frame (6 x 6, J the
    contact point's RigidMapping row): the landing sphere follows the matrix-free CG's trajectory
    (converged to 1e-12) to 1e-9."""
    cg = sofac.load(rigid_scene(tmp_path, "cg.scn"))
    text = SPHERE_FLOOR.read_text().replace(
        '<CGLinearSolver iterations="50" tolerance="1e-12" threshold="1e-20"/>', "<SparseLDLSolver/>"
    )
    ldl = sofac.load(rigid_scene(tmp_path, "ldl.scn", text))
    for _ in range(8):
        cg.step(50)
        ldl.step(50)
        np.testing.assert_allclose(ldl["/Particle/dofs"].position, cg["/Particle/dofs"].position, atol=1e-9)


TWO_BALLS = """<?xml version="1.0"?>
<Node name="root" dt="0.001" gravity="0 0 0">
    <DefaultAnimationLoop/>
    <CollisionPipeline/>
    <BruteForceBroadPhase/>
    <BVHNarrowPhase/>
    <NewProximityIntersection alarmDistance="0.2" contactDistance="0.05"/>
    <CollisionResponse response="PenalityContactForceField"/>
    {root}
    <Node name="Left">
        {solver}
        <MechanicalObject name="dofs" template="Rigid3d" position="-0.5 0 0 0 0 0 1" velocity="1 0 0 0 0 0"/>
        <UniformMass totalMass="1"/>
        <SphereCollisionModel radius="0.1"/>
    </Node>
    <Node name="Right">
        {solver}
        {right}
        <UniformMass totalMass="3"/>
        <SphereCollisionModel radius="0.1"/>
    </Node>
</Node>
"""


RIGHT_RIGID = (
    '<MechanicalObject name="dofs" template="Rigid3d" position="0.5 0.08 0 0 0 0 1" '
    'velocity="-0.5 0 0 0 0 0"/>'
)
RIGHT_POINT = '<MechanicalObject name="dofs" position="0.5 0.08 0" velocity="-0.5 0 0"/>'
IMPLICIT = (
    '<EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>\n'
    '    <CGLinearSolver iterations="100" tolerance="1e-24" threshold="1e-30"/>'
)


@pytest.mark.parametrize(
    ("root", "solver", "right", "tolerance"),
    [
        ("", '<EulerExplicitSolver symplectic="1"/>', RIGHT_RIGID, 1e-14),
        (IMPLICIT, "", RIGHT_RIGID, 1e-10),
        ("", '<EulerExplicitSolver symplectic="1"/>', RIGHT_POINT, 1e-14),
    ],
    ids=["explicit, a solver each", "one solver at the pipeline's node", "a Vec3d sphere against it"],
)
def test_two_spheres_exchange_momentum(
    tmp_path: Path, root: str, solver: str, right: str, tolerance: float
) -> None:
    """A rigid sphere meets another sphere off-centre (centres 0.08 apart across the motion): a
    glancing contact. Equal and opposite forces keep the momentum (explicit: to round-off; in the
    group of a solver at the pipeline's node, both sides' K dx too: to the CG's tolerance); the
    forces pass through the centres: no spin. Against a Vec3d sphere the Vec3d one is the pair's
    first model (SOFA registers Sphere-RigidSphere)."""
    path = tmp_path / "balls.scn"
    path.write_text(TWO_BALLS.format(root=root, solver=solver, right=right))
    plan = plan_file(path)
    (pair,) = plan.collisions[0].pairs
    assert pair.root == (not root) and pair.grouped == bool(root)
    models = plan.collisions[0].models
    assert [models[pair.first].rigid, models[pair.second].rigid] == (
        [False, True] if right == RIGHT_POINT else [True, True]
    )
    sim = sofac.load(path)
    left, right_dofs = sim["/Left/dofs"], sim["/Right/dofs"]

    def momentum() -> np.ndarray:
        return 1.0 * left.velocity[0, :3] + 3.0 * right_dofs.velocity[0, :3]

    start = momentum()
    sim.step(1500)
    assert left.velocity[0, 1] < 0 < right_dofs.velocity[0, 1]  # deflected apart across the motion
    np.testing.assert_allclose(momentum(), start, atol=tolerance)
    spins = np.concatenate([left.velocity[0, 3:], right_dofs.velocity[0, 3:]])  # (a Vec3d sphere has none)
    assert np.abs(spins).max() < 1e-12
