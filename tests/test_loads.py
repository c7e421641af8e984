"""Line / Plane / Point projective constraints, PlaneForceField and UniformVelocityDampingForceField,
against closed-form discrete solutions (a free particle under gravity, geometric decay, a penalty
at rest)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.diagnostics import SceneError
from sofac.pipeline import compile_scene
from sofac.plan.report import format_effects

H = 0.01
GRAVITY = np.array([0.0, -10.0, 0.0])
SOLVERS = {
    "symplectic": "<EulerExplicitSolver/>",
    "implicit-cg": (
        '<EulerImplicitSolver/><CGLinearSolver iterations="50" tolerance="1e-14" threshold="1e-30"/>'
    ),
}


def particles(tmp_path: Path, body: str, *, solver: str, position: str, gravity: str = "0 -10 0") -> Path:
    path = tmp_path / "s.scn"
    path.write_text(
        f'<Node name="root" gravity="{gravity}" dt="{H!r}"><DefaultAnimationLoop/>'
        f'<Node name="n">{solver}<MechanicalObject name="dofs" position="{position}"/>'
        f'<UniformMass vertexMass="2"/>{body}</Node></Node>'
    )
    return path


def _free_fall(acceleration: np.ndarray, steps: int) -> np.ndarray:
    """Displacement after ``steps`` steps from rest of v += h a, x += h v (symplectic and implicit
    Euler agree when the force does not depend on the state)."""
    return H * H * acceleration * steps * (steps + 1) / 2


@pytest.mark.parametrize("solver", list(SOLVERS))
def test_line_constraint_slides_along_its_line(tmp_path: Path, solver: str) -> None:
    direction = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    body = '<LineProjectiveConstraint indices="0" origin="1 0 0" direction="2 -2 0"/>'
    # Point 0 starts off the line: SOFA's init puts it on the line (its foot, (1.5, -0.5, 0)).
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS[solver], position="2 0 0.5  0 0 0"))
    start = sim["dofs"].position.copy()
    assert start[0] == pytest.approx([1.5, -0.5, 0.0], abs=1e-15)
    sim.step(50)
    along = _free_fall(np.dot(GRAVITY, direction) * direction, 50)
    assert sim["dofs"].position[0] == pytest.approx(start[0] + along, abs=1e-12)
    assert sim["dofs"].position[1] == pytest.approx(_free_fall(GRAVITY, 50), abs=1e-12)  # unconstrained
    assert np.cross(sim["dofs"].velocity[0], direction) == pytest.approx(np.zeros(3), abs=1e-12)


@pytest.mark.parametrize("solver", list(SOLVERS))
def test_plane_constraint_keeps_points_in_its_plane(tmp_path: Path, solver: str) -> None:
    normal = np.array([0.0, 3.0, 4.0]) / 5.0
    body = '<PlaneProjectiveConstraint indices="0 1" origin="0 1 0" normal="0 3 4"/>'
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS[solver], position="0 2 0  1 1 1"))
    start = sim["dofs"].position.copy()
    assert (start - [0, 1, 0]) @ normal == pytest.approx([0.0, 0.0], abs=1e-15)
    sim.step(40)
    slide = _free_fall(GRAVITY - np.dot(GRAVITY, normal) * normal, 40)
    assert sim["dofs"].position == pytest.approx(start + slide, abs=1e-12)


def test_point_constraint_holds_dofs_at_its_point(tmp_path: Path) -> None:
    body = '<PointProjectiveConstraint indices="1" point="0.5 0.25 -1"/>'
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS["symplectic"], position="0 0 0  9 9 9"))
    assert sim["dofs"].position[1].tolist() == [0.5, 0.25, -1.0]
    sim.step(20)
    assert sim["dofs"].position[1].tolist() == [0.5, 0.25, -1.0]
    assert sim["dofs"].velocity[1].tolist() == [0.0, 0.0, 0.0]
    assert sim["dofs"].position[0] == pytest.approx(_free_fall(GRAVITY, 20), abs=1e-12)


def test_point_constraint_defaults_to_dof_0_at_the_origin(tmp_path: Path) -> None:
    # SOFA's constructor lists index 0 and its target is the zero coordinate.
    sim = sofac.load(
        particles(
            tmp_path, "<PointProjectiveConstraint/>", solver="<EulerExplicitSolver/>", position="3 4 5  1 1 1"
        )
    )
    assert sim["dofs"].position[0].tolist() == [0.0, 0.0, 0.0]


def test_point_constraint_with_a_direct_solver(tmp_path: Path) -> None:
    solver = "<EulerImplicitSolver/><SparseLDLSolver/>"
    body = '<PointProjectiveConstraint indices="0" point="0 0 0"/><SpringForceField spring="0 1 100 0 1"/>'
    sim = sofac.load(particles(tmp_path, body, solver=solver, position="0 0 0  1.2 0 0", gravity="0 0 0"))
    sim.step(5)
    assert sim["dofs"].position[0].tolist() == [0.0, 0.0, 0.0]
    assert sim["dofs"].position[1, 0] < 1.2  # pulled back by the spring


def test_line_constraint_with_a_direct_solver_is_refused(tmp_path: Path) -> None:
    path = particles(
        tmp_path,
        '<LineProjectiveConstraint direction="1 0 0"/>',
        solver="<EulerImplicitSolver/><SparseLDLSolver/>",
        position="0 0 0",
    )
    with pytest.raises(SceneError) as error:
        compile_scene(path)
    (diagnostic,) = error.value.diagnostics
    assert diagnostic.code == "E222" and diagnostic.loc.line == 1
    assert "LineProjectiveConstraint" in diagnostic.message and "use CGLinearSolver" in diagnostic.message


# --- PlaneForceField ------------------------------------------------------------------------------


def test_plane_force_pushes_penetrating_points_out(tmp_path: Path) -> None:
    body = '<PlaneForceField normal="0 1 0" d="0" stiffness="1000" damping="4"/>'
    path = particles(
        tmp_path, body, solver="<EulerExplicitSolver/>", position="0 -0.1 0  0 0.5 0", gravity="0 0 0"
    )
    sim = sofac.load(path)
    sim["dofs"].velocity[:] = [[0.5, -1.0, 0.0], [0.0, -1.0, 0.0]]
    sim.step(1)
    # f = -k delta n + c delta v with delta = -0.1 (SOFA's formula); the point above feels nothing.
    force = -1000 * -0.1 * np.array([0, 1, 0]) + 4 * -0.1 * np.array([0.5, -1.0, 0.0])
    assert sim["dofs"].velocity[0] == pytest.approx(np.array([0.5, -1.0, 0]) + H * force / 2, abs=1e-13)
    assert sim["dofs"].velocity[1].tolist() == [0.0, -1.0, 0.0]


def test_plane_force_is_clamped_by_max_force(tmp_path: Path) -> None:
    body = '<PlaneForceField normal="0 1 0" stiffness="1000" damping="0" maxForce="20"/>'
    sim = sofac.load(
        particles(tmp_path, body, solver="<EulerExplicitSolver/>", position="0 -0.1 0", gravity="0 0 0")
    )
    sim.step(1)
    assert sim["dofs"].velocity[0] == pytest.approx([0.0, H * 20 / 2, 0.0], abs=1e-15)


def test_a_resting_point_sinks_to_weight_over_stiffness(tmp_path: Path) -> None:
    # Implicit Euler with the plane's stiffness: the particle (m = 2) comes to rest at the depth
    # where k delta balances m g, delta = -2 * 10 / 1000.
    body = (
        '<PlaneForceField normal="0 1 0" d="0" stiffness="1000" damping="0"/>'
        '<UniformVelocityDampingForceField dampingCoefficient="20"/>'
    )
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS["implicit-cg"], position="0 0.05 0"))
    sim.step(600)
    assert sim["dofs"].position[0, 1] == pytest.approx(-0.02, abs=1e-9)
    energy = sim.energy()
    assert energy.potential == pytest.approx(0.5 * 1000 * 0.02**2 + 2 * 10 * -0.02, abs=1e-9)


# --- UniformVelocityDampingForceField -----------------------------------------------------------


@pytest.mark.parametrize("solver", list(SOLVERS))
def test_velocity_damping_decays_geometrically(tmp_path: Path, solver: str) -> None:
    body = '<UniformVelocityDampingForceField damping="3"/>'  # SOFA's alias of dampingCoefficient
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS[solver], position="0 0 0", gravity="0 0 0"))
    sim["dofs"].velocity[0] = [1.0, -2.0, 0.5]
    sim.step(10)
    # The force -c v is explicit (implicit="0"): v_{n+1} = (1 - h c / m) v_n for both schemes.
    factor = (1 - H * 3 / 2) ** 10
    assert sim["dofs"].velocity[0] == pytest.approx(factor * np.array([1.0, -2.0, 0.5]), rel=1e-12)


def test_zero_velocity_damping_is_compiled_out(tmp_path: Path) -> None:
    body = '<UniformVelocityDampingForceField name="damper" dampingCoefficient="0"/>'
    path = particles(tmp_path, body, solver="<EulerExplicitSolver/>", position="0 0 0")
    effects = format_effects(compile_scene(path).plan)
    assert "/n/damper.dampingCoefficient" in effects and "no damping force computed" in effects
    sim = sofac.load(path)
    with pytest.raises(sofac.simulation.loader.PrunedEffectError, match="prune=False"):
        sim.param("/n/damper.dampingCoefficient")
    kept = sofac.load(path, prune=False)
    kept.param("/n/damper.dampingCoefficient")[0] = 4.0
    kept["dofs"].velocity[0] = [1.0, 0.0, 0.0]
    kept.step(1)
    assert kept["dofs"].velocity[0, 0] == pytest.approx(1 - H * 4 / 2 + H * 0, abs=1e-15)


def test_implicit_velocity_damping_is_backward_euler(tmp_path: Path) -> None:
    # implicit="1" puts B = -c I in the implicit system: (m + h c) dv = h (-c v), so
    # v_{n+1} = v_n / (1 + h c / m), the backward-Euler decay.
    body = '<UniformVelocityDampingForceField dampingCoefficient="30" implicit="1"/>'
    sim = sofac.load(
        particles(tmp_path, body, solver=SOLVERS["implicit-cg"], position="0 0 0", gravity="0 0 0")
    )
    sim["dofs"].velocity[0] = [1.0, -2.0, 0.5]
    sim.step(10)
    factor = (1 + H * 30 / 2) ** -10
    assert sim["dofs"].velocity[0] == pytest.approx(factor * np.array([1.0, -2.0, 0.5]), rel=1e-12)


# --- TrianglePressureForceField and the surfaces it acts on -------------------------------------

PRESSED_CUBE = """\
<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
  <Node name="cube"><EulerExplicitSolver/>
    <RegularGridTopology name="grid" n="3 3 3" min="0 0 0" max="2 2 2"/>
    <MechanicalObject name="dofs"/>
    <UniformMass vertexMass="0.5"/>
    <Node name="tetra">
      <TetrahedronSetTopologyContainer name="volume"/>
      <Hexa2TetraTopologicalMapping input="@grid" output="@volume"/>
      <Node name="surface">
        <TriangleSetTopologyContainer name="skin"/>
        <Tetra2TriangleTopologicalMapping input="@volume" output="@skin"/>
        <BoxROI name="face" position="@../../dofs.position" triangles="@skin.triangles"
                box="1.99 -1 -1 3 3 3"/>
        <TrianglePressureForceField name="push" triangleList="@face.triangleIndices" pressure="{pressure}"/>
      </Node>
    </Node>
  </Node>
</Node>
"""


def test_surface_of_the_tetrahedra_and_the_triangles_a_box_selects(tmp_path: Path) -> None:
    from sofac.check.checker import check_file

    path = tmp_path / "pressed.scn"
    path.write_text(PRESSED_CUBE.format(pressure="0 0 0"))
    checked, diagnostics = check_file(path)
    assert checked is not None and not diagnostics.has_errors()
    by_name = {item.component.name: item.component for item in checked}
    points = checked.positions(by_name["dofs"])
    triangles = np.asarray(checked.value(by_name["skin"], "triangles")).reshape(-1, 3)
    assert len(triangles) == 6 * 4 * 2  # 2 x 2 squares per face of the cube, 2 triangles each
    centre = points.mean(axis=0)
    a, b, c = (points[triangles[:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3 - centre)
    assert (outward > 0).all()
    chosen = np.asarray(checked.value(by_name["face"], "triangleIndices"))
    assert len(chosen) == 8 and np.allclose(points[triangles[chosen]][..., 0], 2.0)


def test_triangle_pressure_pushes_with_pressure_times_area(tmp_path: Path) -> None:
    path = tmp_path / "pressed.scn"
    path.write_text(PRESSED_CUBE.format(pressure="3 -1 0"))
    sim = sofac.load(path)
    sim.step(1)
    forces = sim["dofs"].velocity * 0.5 / 0.01  # explicit step from rest: f = m v / h
    on_face = sim["dofs"].position[:, 0] > 1.99
    assert forces[~on_face] == pytest.approx(np.zeros_like(forces[~on_face]), abs=1e-15)
    assert forces.sum(axis=0) == pytest.approx([3 * 4.0, -1 * 4.0, 0.0], rel=1e-12)  # face area 4
    # Each corner of a pressed triangle gets a third of pressure x area: along the pressure.
    pressure = np.array([3.0, -1.0, 0.0])
    on = forces[on_face]
    assert np.cross(on, pressure) == pytest.approx(np.zeros_like(on), abs=1e-12)
    assert (on @ pressure > 0).all()


def test_simple_boundary_conditions_pass_sofas_regression_criterion(shared_dir: Path) -> None:
    # Point, Line and Plane constraints, a pressure on Tetra2Triangle's surface selected by a BoxROI.
    from sofac.regress.suite import Status, run_regression

    reference = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        reference / "scenes.regression-tests",
        shared_dir / "corpus" / "sofa",
        reference,
        only=["Demos/simpleBoundaryConditions.scn"],
    )
    assert result.status is Status.PASS, result
    # SOFA's own run at the corpus commit is off these references by about 1% (the shared README).
    assert result.error < 1e-4 and result.max_rel < 2e-2


def test_implicit_velocity_damping_under_newmark_follows_sofas_recurrence(tmp_path: Path) -> None:
    # SOFA's NewmarkImplicitSolver (gamma 1/2, beta 1/4) with B = -c I: its right-hand side is
    # f + B v + h (1 - gamma) B a (f already holds -c v: SOFA counts the damping twice there), its
    # matrix m - h gamma B; a starts as f / m.
    solver = '<NewmarkImplicitSolver/><CGLinearSolver iterations="50" tolerance="1e-14" threshold="1e-30"/>'
    body = '<UniformVelocityDampingForceField dampingCoefficient="30" implicit="1"/>'
    sim = sofac.load(particles(tmp_path, body, solver=solver, position="0 0 0", gravity="0 0 0"))
    v = np.array([1.0, -2.0, 0.5])
    sim["dofs"].velocity[0] = v
    sim.step(10)
    m, c, gamma = 2.0, 30.0, 0.5
    a = -c * v / m
    for _ in range(10):
        a_next = (-c * v - c * v - H * (1 - gamma) * c * a) / (m + H * gamma * c)
        v, a = v + H * ((1 - gamma) * a + gamma * a_next), a_next
    assert sim["dofs"].velocity[0] == pytest.approx(v, rel=1e-10)


# --- LinearVelocityProjectiveConstraint -----------------------------------------------------------


def _keyed_positions(
    x0: np.ndarray, steps: int, keys: list[tuple[float, np.ndarray]], dt: float
) -> np.ndarray:
    """SOFA's recurrence for a DOF under LinearVelocityProjectiveConstraint: at each step's start
    time t (and once at init, t = 0) x = x_previous + v(t) dt, v(t) linear between the keys."""

    def velocity(t: float) -> np.ndarray:
        (t0, v0), (t1, v1) = keys
        return v1 if t > t1 else (v1 - v0) * ((t - t0) / (t1 - t0)) + v0  # after the end: the last one

    x, t = x0 + velocity(0.0) * dt, 0.0
    for _ in range(steps):
        x = x + velocity(t) * dt
        t += dt
    return x


@pytest.mark.parametrize("solver", list(SOLVERS))
def test_linear_velocity_drives_its_dofs_between_key_times(tmp_path: Path, solver: str) -> None:
    body = (
        '<LinearVelocityProjectiveConstraint indices="0" keyTimes="0 1" velocities="0 0 0  2 0 -1"/>'
        '<SpringForceField spring="0 1 50 0 1"/>'
    )
    sim = sofac.load(particles(tmp_path, body, solver=SOLVERS[solver], position="0 0 0  1 0 0"))
    sim.step(8)
    keys = [(0.0, np.zeros(3)), (1.0, np.array([2.0, 0.0, -1.0]))]
    assert sim["dofs"].position[0] == pytest.approx(_keyed_positions(np.zeros(3), 8, keys, H), abs=1e-14)
    assert sim["dofs"].velocity[0] == pytest.approx(keys[1][1] * (7 * H), abs=1e-14)  # v(t) at the last start
    assert sim["dofs"].position[1, 0] > 1.0  # the spring drags the free particle along


def test_linear_velocity_on_some_coordinates_and_after_its_end(tmp_path: Path) -> None:
    body = (
        '<LinearVelocityProjectiveConstraint indices="0" keyTimes="0 0.05" velocities="0 0 0  0 3 0" '
        'coordinates="1" continueAfterEnd="1"/>'
    )
    sim = sofac.load(particles(tmp_path, body, solver="<EulerExplicitSolver/>", position="0 0 0"))
    sim.step(30)
    # y follows the keys, then keeps the last velocity (continueAfterEnd); gravity (along -y) does
    # not move it: that coordinate is imposed. x and z are free and feel no force.
    assert sim["dofs"].velocity[0, 1] == pytest.approx(3.0, abs=1e-14)
    keys = [(0.0, np.zeros(3)), (0.05, np.array([0.0, 3.0, 0.0]))]
    assert sim["dofs"].position[0, 1] == pytest.approx(
        _keyed_positions(np.zeros(3), 30, keys, H)[1], abs=1e-14
    )
    assert sim["dofs"].position[0, [0, 2]].tolist() == [0.0, 0.0]


# --- parameters read only at init ------------------------------------------------------------------


def test_a_parameter_read_only_at_init_needs_a_reset() -> None:
    from sofac.simulation.loader import ParameterNeedsReset

    beam = Path(__file__).resolve().parents[1] / "scenes" / "beam.scn"
    sim = sofac.load(beam)
    assert sim.plan.init_only == {"/beam/fem.youngModulus", "/beam/fem.poissonRatio"}
    sim.param("/beam/mass.vertexMass")[0] *= 1.5  # read at every step: no reset needed
    sim.step(2)
    sim.param("/beam/fem.youngModulus")[0] = 4e6
    with pytest.raises(ParameterNeedsReset, match=r"/beam/fem\.youngModulus .* call reset\(\)"):
        sim.step(1)
    assert sim.steps == 2  # nothing ran
    sim.reset()
    sim.step(50)
    stiff = sim["dofs"].position[-1, 1]
    sim.param("/beam/fem.youngModulus")[0] = 1e6
    sim.reset()
    sim.step(50)
    assert stiff > sim["dofs"].position[-1, 1]  # the stiffer beam sags less
