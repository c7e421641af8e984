"""The compile pipeline against analytic solutions, SOFA's own trajectories, and its contracts
(cache, views, parameters, errors)."""

from __future__ import annotations

import csv
import itertools
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.build import compiler as build
from sofac.pipeline import compile_scene

REPO = Path(__file__).resolve().parents[1]

ROOT = '<Node name="root" gravity="{gravity}" dt="{dt}"><DefaultAnimationLoop/>{body}</Node>'


def scene(
    tmp_path: Path, body: str, *, dt: float = 0.01, gravity: str = "0 0 0", name: str = "s.scn"
) -> Path:
    path = tmp_path / name
    path.write_text(ROOT.format(gravity=gravity, dt=repr(dt), body=body))
    return path


def nums(values: object) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def oscillator(solver: str, *, damping: float = 0.0) -> str:
    """A particle of mass 1 on a spring k=100, L0=1, from x=1.1 at rest (omega = 10)."""
    return (
        f'<Node name="osc">{solver}<MechanicalObject name="dofs" position="0 0 0  1.1 0 0"/>'
        '<UniformMass vertexMass="1"/><FixedProjectiveConstraint indices="0"/>'
        f'<SpringForceField name="spring" spring="0 1 100 {damping!r} 1"/></Node>'
    )


SOLVERS = {
    "euler": ('<EulerExplicitSolver symplectic="0"/>', 1),
    "symplectic": ("<EulerExplicitSolver/>", 1),
    "rk2": ("<RungeKutta2Solver/>", 2),
    "rk4": ("<RungeKutta4Solver/>", 4),
}


def oscillator_error(tmp_path: Path, solver: str, dt: float, t_end: float = 1.0) -> float:
    sim = sofac.load(scene(tmp_path, oscillator(solver), dt=dt, name=f"osc{dt!r}.scn"))
    sim.step(round(t_end / dt))
    return abs(sim["dofs"].position[1, 0] - (1 + 0.1 * math.cos(10 * sim.time)))


@pytest.mark.parametrize("name", list(SOLVERS))
def test_order_of_convergence(tmp_path: Path, name: str) -> None:
    solver, order = SOLVERS[name]
    steps = (0.004, 0.002, 0.001)
    errors = [oscillator_error(tmp_path, solver, dt) for dt in steps]
    measured = [math.log2(a / b) for a, b in itertools.pairwise(errors)]
    assert all(abs(m - order) < 0.25 for m in measured), (errors, measured)


def test_damped_oscillator_matches_analytic(tmp_path: Path) -> None:
    c = 2.0  # damping coefficient: x'' = -100 u - 2 u'
    sim = sofac.load(scene(tmp_path, oscillator("<RungeKutta4Solver/>", damping=c), dt=1e-3))
    sim.step(1000)
    zeta_omega, omega_d = c / 2, math.sqrt(100 - (c / 2) ** 2)
    t = sim.time
    exact = (
        0.1
        * math.exp(-zeta_omega * t)
        * (math.cos(omega_d * t) + zeta_omega / omega_d * math.sin(omega_d * t))
    )
    assert sim["dofs"].position[1, 0] - 1 == pytest.approx(exact, abs=1e-10)


def test_free_fall(tmp_path: Path) -> None:
    body = (
        '<Node name="p"><RungeKutta4Solver/><MechanicalObject name="dofs" position="0 5 0"/>'
        '<UniformMass vertexMass="2"/></Node>'
    )
    sim = sofac.load(scene(tmp_path, body, dt=0.01, gravity="0 -9.81 0"))
    sim.step(100)
    t = sim.time
    assert sim["dofs"].position[0].tolist() == pytest.approx([0, 5 - 9.81 * t * t / 2, 0], abs=1e-12)
    assert sim["dofs"].velocity[0, 1] == pytest.approx(-9.81 * t, abs=1e-12)
    # symplectic Euler: v_n = -g n dt, y_n = y0 - g dt^2 n (n + 1) / 2, exactly
    sim2 = sofac.load(
        scene(
            tmp_path,
            body.replace("RungeKutta4Solver", "EulerExplicitSolver"),
            gravity="0 -9.81 0",
            name="e.scn",
        )
    )
    sim2.step(100)
    assert sim2["dofs"].position[0, 1] == pytest.approx(5 - 9.81 * 0.01**2 * 100 * 101 / 2, abs=1e-12)


def test_torque_free_rigid_body_rotates_exactly(tmp_path: Path) -> None:
    omega = np.array([0.3, -0.2, 1.1])
    body = (
        '<Node name="r"><EulerExplicitSolver/>'
        '<MechanicalObject name="frame" template="Rigid3d" position="1 2 3  0 0 0 1" '
        f'velocity="0 0 0 {nums(omega)}"/>'
        '<UniformMass vertexMass="2 1 [1 0 0, 0 1 0, 0 0 1]"/></Node>'
    )
    sim = sofac.load(scene(tmp_path, body, dt=0.01))
    sim.step(250)
    t = sim.time
    angle = np.linalg.norm(omega) * t
    axis = omega / np.linalg.norm(omega)
    expected = [*(axis * math.sin(angle / 2)), math.cos(angle / 2)]
    frame = sim["frame"].position[0]
    assert frame[:3].tolist() == pytest.approx([1, 2, 3], abs=1e-14)
    assert frame[3:].tolist() == pytest.approx(expected, abs=1e-12)


RIGID_WITH_POINT = (
    '<Node name="body"><EulerExplicitSolver/>'
    '<MechanicalObject name="frame" template="Rigid3d" position="0.5 -1 2  {q}"/>'
    '<UniformMass vertexMass="3 1 [0.5 0 0, 0 0.7 0, 0 0 0.9]"/>'
    '<Node name="tip"><MechanicalObject name="point" position="0.4 -0.3 1.2"/><RigidMapping/>{tip}</Node>'
    "</Node>"
)


def _quat(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return np.array([*(axis * math.sin(angle / 2)), math.cos(angle / 2)])


def test_rigid_mapping_positions_and_velocities_match_finite_differences(tmp_path: Path) -> None:
    q = _quat(np.array([1.0, 2.0, -0.5]), 0.8)
    sim = sofac.load(scene(tmp_path, RIGID_WITH_POINT.format(q=nums(q), tip="")))
    frame, point = sim["frame"], sim["point"]
    rotation = _rotation(q)
    local = np.array([0.4, -0.3, 1.2])
    assert point.position[0] == pytest.approx(np.array([0.5, -1, 2]) + rotation @ local, abs=1e-14)
    # J against finite differences: move the frame by h * v and compare the point's motion.
    v = np.array([0.1, -0.4, 0.3, 0.7, -0.2, 0.5])
    frame.velocity[0] = v
    sim._native.init()  # propagate x and v down the mapping
    mapped_v = point.velocity[0].copy()
    h = 1e-7
    turned = _quat_mul(_quat(v[3:], np.linalg.norm(v[3:]) * h), q)
    moved = np.array([0.5, -1, 2]) + h * v[:3] + _rotation(turned) @ local
    fd = (moved - point.position[0]) / h
    assert mapped_v == pytest.approx(fd, abs=1e-6)


def test_rigid_mapping_transposes_forces_into_force_and_torque(tmp_path: Path) -> None:
    q = _quat(np.array([0.0, 0.0, 1.0]), 0.3)
    force = np.array([1.0, -2.0, 0.5])
    tip = f'<ConstantForceField forces="{nums(force)}"/>'
    sim = sofac.load(scene(tmp_path, RIGID_WITH_POINT.format(q=nums(q), tip=tip), dt=1e-3))
    arm = sim["point"].position[0] - np.array([0.5, -1, 2])
    sim.step(1)
    v = sim["frame"].velocity[0]
    assert v[:3] == pytest.approx(1e-3 * force / 3, abs=1e-15)
    inertia = 3 * np.diag([0.5, 0.7, 0.9])  # applied in world axes, as SOFA does
    assert v[3:] == pytest.approx(1e-3 * np.linalg.solve(inertia, np.cross(arm, force)), abs=1e-15)


def _rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from sofac.front.meshes import quaternion_multiply

    return quaternion_multiply(a, b)


def _reference(path: Path) -> dict[int, np.ndarray]:
    """step -> rows (dof order) of a reference CSV from ../shared/reference/sofa/data."""
    frames: dict[int, list[list[float]]] = {}
    with path.open() as stream:
        for row in csv.DictReader(stream):
            values = [float(v) for k, v in row.items() if k not in ("step", "time", "dof")]
            frames.setdefault(int(row["step"]), []).append(values)
    return {k: np.array(v) for k, v in frames.items()}


CASES = [
    # cantilever beams: implicit Euler with CG (tetrahedra, hexahedra) and a sparse direct solver
    ("c1_beam_tetfem_cg", {"dofs": "c1_beam_tetfem_cg.csv"}),
    ("c2_beam_tetfem_ldl", {"dofs": "c2_beam_tetfem_ldl.csv"}),
    ("c3_beam_hexafem_cg", {"dofs": "c3_beam_hexafem_cg.csv"}),
    ("e_beam_large_cg25", {"dofs": "e_beam_large_cg25.csv"}),  # 23814 tetrahedra, CG capped at 25
    ("a_pendulum_euler_explicit", {"dofs": "a_pendulum_euler_explicit.every100.csv"}),
    ("a2_pendulum_euler_explicit_totalmass", {"dofs": "a2_pendulum_euler_explicit_totalmass.every100.csv"}),
    ("b1_pendulum_rk4", {"dofs": "b1_pendulum_rk4.every100.csv"}),
    ("b2_pendulum_euler_implicit_cg", {"dofs": "b2_pendulum_euler_implicit_cg.every100.csv"}),
    (
        "d2_rigid_pendulum_explicit",
        {
            "rigidDof": "d2_rigid_pendulum_explicit.rigid.csv",
            "attachedDof": "d2_rigid_pendulum_explicit.attached.csv",
        },
    ),
    (
        "d1_mixed_pendulum_explicit",
        {
            "Dof1": "d1_mixed_pendulum_explicit.Dof1.csv",
            "Dof2": "d1_mixed_pendulum_explicit.Dof2_rigid.csv",
            "Dof3": "d1_mixed_pendulum_explicit.Dof3.csv",
        },
    ),
]


@pytest.mark.parametrize(("name", "files"), CASES, ids=[c[0] for c in CASES])
def test_matches_sofa_reference_trajectories(shared_dir: Path, name: str, files: dict[str, str]) -> None:
    reference = shared_dir / "reference" / "sofa"
    sim = sofac.load(reference / "scenes" / f"{name}.scn")
    expected = {state: _reference(reference / "data" / file) for state, file in files.items()}
    done = 0
    for step in sorted(next(iter(expected.values()))):
        sim.step(step - done)
        done = step
        for state, frames in expected.items():
            s = sim[state]
            rows = frames[step]  # positions, and velocities when recorded
            got = np.hstack([s.position, s.velocity])[:, : rows.shape[1]]
            assert got == pytest.approx(rows, rel=1e-9, abs=1e-11), (state, step)


def test_hybrid_pendulum_builder_gives_the_same_trajectory(tmp_path: Path) -> None:
    out = tmp_path / "built.scn"
    subprocess.run(
        [sys.executable, str(REPO / "examples" / "hybrid_pendulum.py"), str(out)],
        check=True,
        capture_output=True,
    )
    bundled = sofac.load(REPO / "scenes" / "hybrid_pendulum.scn")
    built = sofac.load(out)
    bundled.step(300)
    built.step(300)
    for path in bundled.objects():
        assert np.array_equal(bundled[path].position, built[path].position)
    assert bundled["Dof2"].position[0, 1] < -0.5  # it fell


def test_views_instances_and_parameters(tmp_path: Path) -> None:
    path = scene(tmp_path, oscillator("<EulerExplicitSolver/>"), dt=1e-3)
    compiled = compile_scene(path)
    a, b = compiled.instantiate(), compiled.instantiate()
    a["dofs"].position[1, 0] = 1.2  # writing into the view changes the simulation
    a.param("/osc/spring.stiffness")[0] = 400.0  # no recompilation
    a.step(10)
    b.step(10)
    # omega = 20 for a, 10 for b (untouched); symplectic Euler is within 1e-3 here
    assert a["dofs"].position[1, 0] == pytest.approx(1 + 0.2 * math.cos(20 * 0.01), abs=1e-3)
    assert b["dofs"].position[1, 0] == pytest.approx(1 + 0.1 * math.cos(10 * 0.01), abs=1e-3)
    b.reset()
    assert b.time == 0 and b["dofs"].position[1, 0] == 1.1
    energy = b.energy()
    assert energy.potential == pytest.approx(0.5 * 100 * 0.1**2) and energy.kinetic == 0


def test_energy_is_conserved_by_rk4(tmp_path: Path) -> None:
    sim = sofac.load(scene(tmp_path, oscillator("<RungeKutta4Solver/>"), dt=1e-3))
    start = sim.energy().total
    sim.step(2000)
    assert sim.energy().total == pytest.approx(start, rel=1e-9)


def test_cache_hit_and_corrupt_entry_is_rebuilt(tmp_path: Path) -> None:
    path = scene(tmp_path, oscillator("<RungeKutta2Solver/>"), name="cache.scn")
    compiled = compile_scene(path)
    first = compiled.built
    again = compile_scene(path).built
    assert again.cached and again.library == first.library
    data = first.library.read_bytes()
    first.library.unlink()  # (the loaded copy stays mapped) replaced by a truncated file
    first.library.write_bytes(data[:100])
    rebuilt = build.build_scene(compiled.source)
    assert not rebuilt.cached and rebuilt.library == first.library
    assert first.library.read_bytes() == data


def test_concurrent_compiles_of_one_scene(tmp_path: Path) -> None:
    path = scene(tmp_path, oscillator('<EulerExplicitSolver symplectic="0"/>', damping=0.5), name="race.scn")
    cache = tmp_path / "cache"
    env = {**os.environ, "SOFAC_CACHE_DIR": str(cache)}
    runs = [
        subprocess.Popen(
            [sys.executable, "-m", "sofac", "compile", str(path)], env=env, stdout=subprocess.PIPE, text=True
        )
        for _ in range(2)
    ]
    outputs = [p.communicate(timeout=600)[0].strip() for p in runs]
    assert [p.returncode for p in runs] == [0, 0]
    assert outputs[0] == outputs[1] and Path(outputs[0]).is_file()


def test_compiler_failure_is_a_sofac_error_with_a_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CXX", "false")
    monkeypatch.setenv("SOFAC_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(build.BuildError) as failure:
        build.build_scene("int main() {}\n")
    assert failure.value.log is not None and failure.value.log.is_file()
    assert not list((tmp_path / "cache" / "scenes").glob("*/*/manifest.json"))  # never cached


def test_unsupported_component_names_itself_and_its_line(tmp_path: Path) -> None:
    body = (
        '<Node name="n">\n<VariationalSymplecticSolver explicitIntegration="1"/>\n<CGLinearSolver/>\n'
        '<MechanicalObject/>\n<UniformMass vertexMass="1"/>\n</Node>'
    )
    with pytest.raises(sofac.SceneError) as failure:
        sofac.load(scene(tmp_path, body))
    first = failure.value.diagnostics[0]
    assert first.code == "E222" and first.loc.line == 2
    assert "unsupported component VariationalSymplecticSolver at line 2" in first.message
    assert "explicitIntegration=true is not compiled yet" in first.message


def test_scene_text_never_reaches_the_code(tmp_path: Path) -> None:
    hostile = "x&quot;);system(&quot;rm -rf /&quot;);//&#10;*/ evil"
    body = oscillator("<EulerExplicitSolver/>").replace('name="dofs"', f'name="{hostile}"')
    sim = sofac.load(scene(tmp_path, body))
    source = sim.compiled.source
    code = [line.split("//", 1)[0] for line in source.splitlines()]
    assert not any("system" in part or "evil" in part for part in code)  # only in one-line comments
    sim.step(5)
    assert np.isfinite(sim[sim.objects()[0]].position).all()


def test_divergence_is_reported(tmp_path: Path) -> None:
    body = oscillator("<EulerExplicitSolver/>").replace("0 1 100 0.0 1", "0 1 1e9 0.0 1")
    sim = sofac.load(scene(tmp_path, body, dt=0.01))
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10000)
    assert failure.value.state == "/osc/dofs"


SOLVED_BEAM = """<Node name="root" gravity="0 -9.81 0" dt="0.02"><DefaultAnimationLoop/>
<Node name="beam"><EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>{solver}
<RegularGridTopology n="3 3 6" min="0 0 0" max="1 1 3"/>
<MechanicalObject name="dofs"/><UniformMass totalMass="1"/>
<BoxROI name="box" box="-1 -1 -0.001 2 2 0.001"/><FixedProjectiveConstraint indices="@box.indices"/>
<TetrahedronFEMForceField youngModulus="1e4" poissonRatio="0.3" method="large"/></Node></Node>"""


def test_cg_and_the_direct_solvers_agree_on_the_implicit_step(tmp_path: Path) -> None:
    solvers = {
        "cg": '<CGLinearSolver iterations="2000" tolerance="1e-15" threshold="1e-30"/>',
        "ldl": "<SparseLDLSolver/>",
        "cholesky": "<SparseCholeskySolver/>",
        "eigen_lu": "<EigenSparseLU/>",
        "pcg_jacobi": '<PCGLinearSolver iterations="2000" tolerance="1e-28" preconditioner="@p"/>'
        '<JacobiPreconditioner name="p"/>',
    }
    final = {}
    for name, solver in solvers.items():
        path = tmp_path / f"{name}.scn"
        path.write_text(SOLVED_BEAM.format(solver=solver))
        sim = sofac.load(path)
        sim.step(15)
        final[name] = sim["dofs"].position.copy()
    assert np.abs(final["cg"][-9:, 1] - final["cg"][:9, 1]).min() > 1e-3  # the beam bends
    for name, positions in final.items():
        assert np.abs(positions - final["ldl"]).max() < 1e-9, name


def test_direct_solver_refuses_a_mapping_whose_jacobian_it_cannot_assemble(tmp_path: Path) -> None:
    body = (
        '<Node name="n"><EulerImplicitSolver/><SparseLDLSolver/>\n'
        '<MechanicalObject name="dofs" position="0 0 0  1 0 0"/><UniformMass vertexMass="1"/>\n'
        '<EdgeSetTopologyContainer edges="0 1"/>\n'
        '<Node name="d"><MechanicalObject template="Vec1d" name="length"/>\n'
        '<UniformMass vertexMass="1"/>\n'
        '<DistanceMapping geometricStiffness="None"/></Node></Node>'
    )
    with pytest.raises(sofac.SceneError) as failure:
        sofac.load(scene(tmp_path, body))
    messages = [d.message for d in failure.value.diagnostics]
    assert any(
        "UniformMass at line 5" in m and "/n/d/length: its mapping's Jacobian is not assembled yet" in m
        for m in messages
    ), messages


def test_the_system_a_direct_solver_solves_assembles_everything(tmp_path: Path) -> None:
    system = '<MatrixLinearSystem name="s" assembleMass="false"/><SparseLDLSolver linearSystem="@s"/>'
    with pytest.raises(sofac.SceneError) as failure:
        sofac.load(scene(tmp_path, oscillator(f"<EulerImplicitSolver/>{system}")))
    message = failure.value.diagnostics[0].message
    assert "MatrixLinearSystem" in message and "assembleMass=false on the system a solver solves" in message


def test_composite_linear_system_solves_its_solver_linear_system(tmp_path: Path) -> None:
    """Its other systems (here one without the mass, and their GlobalSystemMatrixImage views) only
    assemble for display: the step is the plain SparseLDLSolver's, exactly."""
    composite = (
        '<EulerImplicitSolver/><Node name="m"><MatrixLinearSystem name="A"/>'
        '<MatrixLinearSystem name="K" assembleMass="false"/>'
        '<GlobalSystemMatrixImage linearSystem="@K"/></Node>'
        '<CompositeLinearSystem name="c" linearSystems="@m/A @m/K" solverLinearSystem="@m/A"/>'
        '<SparseLDLSolver linearSystem="@c"/>'
    )
    positions = []
    for name, solver in (("plain", "<EulerImplicitSolver/><SparseLDLSolver/>"), ("composite", composite)):
        sim = sofac.load(scene(tmp_path, oscillator(solver), name=f"{name}.scn"))
        sim.step(20)
        positions.append(sim["dofs"].position.copy())
    assert abs(positions[0][1, 0] - 1.1) > 1e-3  # it moved
    assert np.array_equal(positions[0], positions[1])


def test_rigid_frames_linked_to_grid_points_get_identity_orientations(tmp_path: Path) -> None:
    """SOFA copies a Vec3d link into Rigid3d coordinates element by element (genericCopyValueFrom):
    each frame takes a point's x y z and keeps the default, identity, orientation."""
    body = (
        '<Node name="n"><RegularGridTopology name="grid" n="1 1 3" min="0 1 0" max="0 1 2"/>'
        '<MechanicalObject template="Rigid3d" name="frames" position="@grid.position"/></Node>'
    )
    sim = sofac.load(scene(tmp_path, body))
    expected = [[0, 1, z, 0, 0, 0, 1] for z in (0.0, 1.0, 2.0)]
    assert np.array_equal(sim["frames"].position, expected)
