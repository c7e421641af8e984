"""Hard contact cases (issue #16), each with its expected outcome: a body started deep inside the
contact distance is pushed out and settles where the contact balances its weight; a penalty
contact far too stiff for an explicit step is reported (energy guard), never a silent blow-up; thin
objects hold what their contacts can and report what is pushed or tunnels through; the energy
across a bounce per solver (docs/contacts.md's table)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from test_self_collision import grid_triangles

FLOOR = Path(__file__).resolve().parents[1] / "data" / "contact_sphere_floor.scn"


def test_deep_initial_penetration_recovers_and_settles(tmp_path: Path) -> None:
    """The sphere's centre starts 0.01 above the floor, 0.29 into its contact distance (0.3): the
    contact force (97 N on 1 kg) throws it up; implicit Euler with Rayleigh mass damping brings it
    back to rest at d - m g / ks, finite at every step."""
    scene = tmp_path / "deep.scn"
    scene.write_text(FLOOR.read_text().replace('position="0.1 0.4 -0.2"', 'position="0.1 0.01 -0.2"'))
    sim = sofac.load(scene)
    heights = []
    for _ in range(100):
        sim.step(10)
        heights.append(sim["/Particle/dofs"].position[0, 1])
    assert np.all(np.isfinite(heights)) and max(heights) < 2.0
    ks = 100.0 / 0.3
    assert heights[-1] == pytest.approx(0.3 - 9.81 / ks, abs=1e-9)


def test_contact_too_stiff_for_an_explicit_step_is_reported(tmp_path: Path) -> None:
    """ks = 1e8 / 0.3 on 1 kg: omega dt = 183 with dt = 0.01, far past symplectic Euler's limit of 2.
    The first contact step throws the sphere off with a huge velocity; the energy guard names the
    step instead of letting the run go on."""
    scene = tmp_path / "stiff.scn"
    text = FLOOR.read_text().replace('contactStiffness="10"', 'contactStiffness="1e4"')
    text = text.replace(
        '<EulerImplicitSolver rayleighMass="2" rayleighStiffness="0"/>',
        '<EulerExplicitSolver symplectic="1"/>',
    )
    scene.write_text(
        text.replace('<CGLinearSolver iterations="50" tolerance="1e-12" threshold="1e-20"/>', "")
    )
    sim = sofac.load(scene)
    sim.guard_energy(10.0)
    with pytest.raises(sofac.SimulationDiverged) as diverged:
        for _ in range(200):
            sim.step()
    assert "energy" in str(diverged.value)
    assert sim.steps < 40  # it reaches the contact distance after about 12 steps; stopped soon after


def test_a_fast_body_tunnelling_through_a_thin_floor_is_reported(tmp_path: Path) -> None:
    """At 100 m/s with dt = 0.01 the sphere moves 1 m per step, past the floor's reach (alarm 0.5)
    between two detections: it goes through. The run says so (ContactWarning), it is not silent."""
    scene = tmp_path / "fast.scn"
    text = FLOOR.read_text().replace('position="0.1 0.4 -0.2"', 'position="0.1 3.5 -0.2" velocity="0 -100 0"')
    scene.write_text(text)
    sim = sofac.load(scene)
    with pytest.warns(sofac.ContactWarning, match="tunnelling") as caught:
        sim.step(10)
    assert sim["/Particle/dofs"].position[0, 1] < -1.0  # it did go through
    assert "contactReport" not in str(caught[0].message) and "CollisionPipeline" in str(caught[0].message)


PARTICLE_FLOOR = Path(__file__).resolve().parents[1] / "data" / "contact_particle_floor.scn"


def _on_thin_floor(tmp_path: Path, mass: float) -> sofac.Simulation:
    """contact_particle_floor.scn's particle (now `mass` kg), started at rest at the contact
    distance above the floor: two triangles of no thickness. ks = 10 x 10 / 0.2 = 500 N/m, so the
    contact holds at most ks x 0.2 = 100 N before the particle reaches the floor's plane."""
    text = PARTICLE_FLOOR.read_text().replace('position="0.1 0.4 -0.2"', 'position="0.1 0.2 -0.2"')
    path = tmp_path / f"thin_{mass!r}.scn"
    path.write_text(text.replace('<UniformMass totalMass="1"/>', f'<UniformMass totalMass="{mass!r}"/>'))
    return sofac.load(path)


def test_a_thin_floor_holds_a_heavy_particle_within_its_capacity(tmp_path: Path) -> None:
    """5 kg (49 N < 100 N): held at 0.2 - m g / ks above the sheet, no contact pushed through."""
    sim = _on_thin_floor(tmp_path, 5.0)
    sim.step(2000)
    assert sim["/Particle/dofs"].position[0, 1] == pytest.approx(0.2 - 5.0 * 9.81 / 500.0, abs=1e-9)
    assert sim.output("/CollisionPipeline2.contactReport")[7] == 0


def test_a_particle_pushed_through_a_thin_floor_is_reported(tmp_path: Path) -> None:
    """20 kg (196 N > 100 N): the contact cannot hold it; it sinks slowly (no fast motion) and
    crosses the floor's plane. Past it the detection finds the floor again with the normal
    reversed, and the penalty pushes it on down: the run says so (ContactWarning, the report's
    crossings), it is not silent."""
    sim = _on_thin_floor(tmp_path, 20.0)
    with pytest.warns(sofac.ContactWarning, match="pushed through") as caught:
        sim.step(200)
    assert sim["/Particle/dofs"].position[0, 1] < -0.1  # below the sheet
    report = sim.output("/CollisionPipeline2.contactReport")
    assert report[7] == 1 and report[5] == 0  # one crossing, no fast motion
    assert not any("tunnelling" in str(w.message) for w in caught)


def _sheet(n: int = 11) -> str:
    """A 1 m square sheet of n x n points (MeshSpringForceField), its border held, and a 1 kg
    Vec3d sphere (r 0.05) let go 2 cm above it; one implicit solver at the root: the sheet-sphere
    contacts (two simulated models) are in its group."""
    xs = np.linspace(-0.5, 0.5, n)
    points = [(float(x), 0.0, float(z)) for x in xs for z in xs]
    border = [i * n + j for i in range(n) for j in range(n) if i in (0, n - 1) or j in (0, n - 1)]
    triangles = grid_triangles(n - 1, n - 1)
    return f"""<?xml version="1.0"?>
<Node name="root" dt="0.005" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <CollisionPipeline depth="6"/>
    <BruteForceBroadPhase/>
    <BVHNarrowPhase/>
    <NewProximityIntersection alarmDistance="0.05" contactDistance="0.01"/>
    <CollisionResponse response="PenalityContactForceField"/>
    <EulerImplicitSolver rayleighMass="5" rayleighStiffness="0"/>
    <CGLinearSolver iterations="200" tolerance="1e-14" threshold="1e-24"/>
    <Node name="Sheet">
        <MeshTopology position="{" ".join(f"{x!r} {y!r} {z!r}" for x, y, z in points)}"
            triangles="{" ".join(f"{a} {b} {c}" for a, b, c in triangles)}"/>
        <MechanicalObject name="dofs"/>
        <UniformMass totalMass="0.5"/>
        <MeshSpringForceField stiffness="500" damping="0"/>
        <FixedProjectiveConstraint indices="{" ".join(map(str, border))}"/>
        <TriangleCollisionModel contactStiffness="10"/>
    </Node>
    <Node name="Ball">
        <MechanicalObject name="dofs" position="0.02 0.07 0.03"/>
        <UniformMass totalMass="1"/>
        <SphereCollisionModel radius="0.05" contactStiffness="10"/>
    </Node>
</Node>
"""


def _sheet_below(x: np.ndarray, at: np.ndarray, n: int = 11) -> float:
    """The sheet's height under the point `at` (x, z), on its triangle (a, b, c) or (a, c, d)."""
    h = 1.0 / (n - 1)
    i, j = int((at[0] + 0.5) // h), int((at[1] + 0.5) // h)
    u, v = (at[0] + 0.5) / h - i, (at[1] + 0.5) / h - j
    a, b, c, d = (x[k, 1] for k in (i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1))
    return a + u * (b - a) + v * (c - b) if u >= v else a + v * (d - a) + u * (c - d)


def test_a_thin_deformable_sheet_holds_a_heavy_sphere(tmp_path: Path) -> None:
    """A 1 kg sphere on a 0.5 kg sheet held by its border: the sheet sags about 5 cm and the
    sphere stays on its upper side at every step, never through it (no crossing reported), and
    comes to rest about r + d above the sheet under its centre."""
    path = tmp_path / "sheet.scn"
    path.write_text(_sheet())
    sim = sofac.load(path)
    for _ in range(600):
        sim.step()
        ball = sim["/Ball/dofs"].position[0]
        assert ball[1] > _sheet_below(sim["/Sheet/dofs"].position, ball[[0, 2]]), sim.steps
    sag = -sim["/Sheet/dofs"].position[:, 1].min()
    ball = sim["/Ball/dofs"].position[0]
    assert 0.03 < sag < 0.1
    assert ball[1] - _sheet_below(sim["/Sheet/dofs"].position, ball[[0, 2]]) == pytest.approx(0.06, abs=0.01)
    assert np.abs(sim["/Ball/dofs"].velocity).max() < 1e-2
    assert sim.output("/CollisionPipeline2.contactReport")[7] == 0


UNDAMPED = '<EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>'
ENERGY_SOLVERS = {
    "explicit Euler": '<EulerExplicitSolver symplectic="0"/>',
    "symplectic Euler": '<EulerExplicitSolver symplectic="1"/>',
    "implicit Euler, CG": UNDAMPED + '<CGLinearSolver iterations="100" tolerance="1e-20" threshold="1e-30"/>',
    "implicit Euler, SparseLDL": UNDAMPED + "<SparseLDLSolver/>",
    "RK4": "<RungeKutta4Solver/>",
}


def _bounce(tmp_path: Path, name: str, solver: str) -> float:
    """The particle of contact_particle_floor.scn (1 kg, ks = 10 x 20 / 0.2 = 1000 N/m, omega dt
    = 0.03), no damping, dropped from 0.4 m: its energy (sim.energy(), gravity's and the contact's
    potential included) when it leaves the contact distance again, over its energy at the start."""
    text = PARTICLE_FLOOR.read_text().replace('dt="0.01"', 'dt="0.001"')
    text = text.replace(
        '<PointCollisionModel contactStiffness="10"/>', '<PointCollisionModel contactStiffness="20"/>'
    )
    text = text.replace(
        '<EulerImplicitSolver rayleighMass="2" rayleighStiffness="0"/>\n'
        '        <CGLinearSolver iterations="50" tolerance="1e-12" threshold="1e-20"/>',
        solver,
    )
    path = tmp_path / f"{name.replace(' ', '_').replace(',', '')}.scn"
    path.write_text(text)
    sim = sofac.load(path)
    start = sum(sim.energy())
    touched = False
    for _ in range(1000):
        sim.step()
        y, vy = sim["/Particle/dofs"].position[0, 1], sim["/Particle/dofs"].velocity[0, 1]
        touched = touched or y < 0.2
        if touched and y > 0.2 and vy > 0:
            return sum(sim.energy()) / start
    raise AssertionError("no bounce")


def test_energy_across_a_bounce_per_solver(tmp_path: Path) -> None:
    """docs/contacts.md's table: across one bounce (measured 2026-12-05) explicit Euler gains 6.2%,
    symplectic Euler 0.27% (the contact switching on and off within steps), RK4 keeps it to 1e-5,
    implicit Euler loses 5.5% (its numerical damping), the same with CG as with a direct solver."""
    ratios = {name: _bounce(tmp_path, name, solver) for name, solver in ENERGY_SOLVERS.items()}
    assert ratios["explicit Euler"] > 1.05
    assert 1.0 < ratios["symplectic Euler"] < 1.005
    assert ratios["RK4"] == pytest.approx(1.0, abs=1e-5)
    assert 0.93 < ratios["implicit Euler, CG"] < 0.96
    assert ratios["implicit Euler, SparseLDL"] == pytest.approx(ratios["implicit Euler, CG"], abs=1e-9)
