"""VariationalSymplecticSolver (SOFA's implicit variant, alpha = 1/2) against physics and its formulas.

SOFA's scheme, per step, with the momentum p carried from step to step (p = M v at the start):
Newton iterations on the displacement res from x_k to the midpoint, from res = 0,

    ((4/h^2 + 4 rm/h) M - (1 + 4 rk/h) K(x_i)) res_i+1 = f(x_i) - K(x_i) res_i + (2/h) p   (projected)

with x_i = x_k + res_i, until |res_i+1 - res_i| <= newtonError |x_k| or `steps` iterations; then
v = (2/h) res, p' = (h/2) f(x_k + (h/2) v) (projected) + M v and x = x_k + h v.

On a linear oscillator (one Newton step is then exact) this is the implicit midpoint rule in
(x, p): a rotation of phase space, so the energy stays bounded (only the velocity reported, the
midpoint one, makes it oscillate by O(dt^2)) and the position converges with order 2; from rest
at x0 - L = A, x_n - L = A cos(n theta) exactly, with tan(theta / 2) = w h / 2. Implicit Euler
loses energy instead. A NumPy re-implementation of the formulas checks the compiled step on a
nonlinear spring system, with Rayleigh damping and several Newton iterations.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.check.checker import check_file

M, K, L, A = 1.0, 100.0, 1.0, 0.1  # omega = 10 rad/s
W = math.sqrt(K / M)

OSCILLATOR = """\
<Node name="root" gravity="0 0 0" dt="{dt!r}">
  <DefaultAnimationLoop/>
  <Node name="oscillator">
    {solver}
    {linear}
    <MechanicalObject template="Vec3d" name="dofs" position="0 0 0  {x0!r} 0 0"/>
    <UniformMass vertexMass="{m!r}"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="0 1 {k!r} 0 {length!r}"/>
  </Node>
</Node>
"""
LDL = "<SparseLDLSolver/>"
VSS_LINEAR = '<VariationalSymplecticSolver steps="1"/>'


def oscillator(tmp_path: Path, solver: str, dt: float, linear: str = LDL) -> sofac.Simulation:
    scene = tmp_path / f"oscillator_{len(list(tmp_path.iterdir()))}.scn"
    scene.write_text(OSCILLATOR.format(dt=dt, solver=solver, linear=linear, x0=L + A, m=M, k=K, length=L))
    return sofac.load(scene)


def test_energy_bounded_while_implicit_euler_loses_it(tmp_path: Path) -> None:
    dt, steps = 0.01, 10_000  # omega dt = 0.1: 159 periods
    e0 = 0.5 * K * A * A
    period = round(2 * math.pi / W / dt)
    solver = '<VariationalSymplecticSolver name="vss" steps="1" useIncrementalPotentialEnergy="0"/>'
    sim = oscillator(tmp_path, solver, dt)
    hamiltonian = sim.output("/oscillator/vss.hamiltonianEnergy")
    reported = np.empty(steps + 1)
    discrete = np.empty(steps)
    reported[0] = sim.energy().total
    for n in range(steps):
        sim.step()
        reported[n + 1] = sim.energy().total
        discrete[n] = hamiltonian[0]
    # The discrete energy p.M^-1 p / 2 + V(x) (SOFA's hamiltonianEnergy, potential from the state)
    # is what the midpoint rule conserves: no drift over 10,000 steps, to rounding.
    assert np.abs(discrete / e0 - 1.0).max() < 1e-11
    # The energy of the state (sim.energy()) pairs x_k with the velocity v = (p_k-1 + p_k) / 2m of
    # the step's midpoint: it oscillates, by O(w dt), but is bounded and does not drift either.
    assert reported[0] == pytest.approx(e0, rel=1e-12)
    deviation = np.abs(reported / e0 - 1.0)
    assert 0.1 * W * dt < deviation.max() < W * dt
    first, last = deviation[1:1001].max(), deviation[-1000:].max()  # 16 periods each
    assert abs(last - first) < 0.01 * first
    # Implicit Euler: |amplification|^2 = 1 / (1 + (w dt)^2) per step, all energy gone.
    euler = oscillator(tmp_path, "<EulerImplicitSolver/>", dt)
    euler.step(2 * period)
    assert euler.energy().total < 0.5 * e0
    euler.step(steps - 2 * period)
    assert euler.energy().total < 1e-6 * e0


def test_exact_midpoint_rotation(tmp_path: Path) -> None:
    """From rest, x_n - L = A cos(n theta), tan(theta / 2) = w h / 2: the compiled scheme is the
    implicit midpoint rule on the linear oscillator, to rounding."""
    dt, steps = 0.02, 500
    sim = oscillator(tmp_path, VSS_LINEAR, dt)
    theta = 2 * math.atan(W * dt / 2)
    x = np.empty(steps)
    for n in range(steps):
        sim.step()
        x[n] = sim["dofs"].position[1, 0] - L
    expected = A * np.cos(theta * np.arange(1, steps + 1))
    assert np.max(np.abs(x - expected)) < 1e-12


def test_second_order_convergence(tmp_path: Path) -> None:
    errors = []
    dts = (0.01, 0.005, 0.0025)
    for dt in dts:
        sim = oscillator(tmp_path, VSS_LINEAR, dt)
        sim.step(round(1.0 / dt))
        assert sim.time == pytest.approx(1.0)
        errors.append(abs(sim["dofs"].position[1, 0] - (L + A * math.cos(W * 1.0))))
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(len(dts) - 1)]
    assert orders == pytest.approx([2.0, 2.0], abs=0.05), (errors, orders)


# --- one step against a NumPy re-implementation of SOFA's formulas -------------------------------

POSITIONS = np.array([[0.0, 0.0, 0.0], [1.2, 0.1, 0.0], [1.9, -0.6, 0.3], [0.8, -1.1, -0.2]])
VELOCITIES = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.5], [-0.4, 0.1, 0.2], [0.1, 0.6, -0.3]])
SPRINGS = [(0, 1, 300.0, 1.0), (1, 2, 150.0, 0.8), (2, 3, 200.0, 1.1), (1, 3, 250.0, 1.0)]
MASS, GRAVITY = 0.7, np.array([0.0, -9.81, 0.0])
RK, RM = 0.02, 0.3

NONLINEAR = """\
<Node name="root" gravity="{gravity}" dt="{dt!r}">
  <DefaultAnimationLoop/>
  <Node name="net">
    <VariationalSymplecticSolver name="vss" steps="{steps}" newtonError="{error!r}" rayleighStiffness="{rk!r}"
        rayleighMass="{rm!r}" useIncrementalPotentialEnergy="{incremental}"/>
    <SparseLDLSolver/>
    <MechanicalObject template="Vec3d" name="dofs" position="{x}" velocity="{v}"/>
    <UniformMass vertexMass="{m!r}"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="{springs}"/>
  </Node>
</Node>
"""


def _numbers(array: np.ndarray) -> str:
    return " ".join(repr(float(a)) for a in np.ravel(array))


def _forces(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """f(x) (springs and weight) and K = df/dx, 3n x 3n."""
    n = len(x)
    f = np.tile(MASS * GRAVITY, (n, 1))
    k = np.zeros((3 * n, 3 * n))
    for a, b, stiffness, length in SPRINGS:
        d = x[b] - x[a]
        distance = np.linalg.norm(d)
        u = d / distance
        f[a] += stiffness * (distance - length) * u
        f[b] -= stiffness * (distance - length) * u
        block = stiffness * (
            (1 - length / distance) * np.eye(3) + length / distance * np.outer(u, u)
        )  # d f_a / d x_b
        for i, j, sign in ((a, b, 1), (b, a, 1), (a, a, -1), (b, b, -1)):
            k[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += sign * block
    return f, k


def _potential(x: np.ndarray) -> float:
    springs = sum(0.5 * s * (np.linalg.norm(x[b] - x[a]) - length) ** 2 for a, b, s, length in SPRINGS)
    return springs - float(np.sum(MASS * x @ GRAVITY))


def reference_steps(
    steps: int, h: float, newton_steps: int, newton_error: float
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """SOFA's VariationalSymplecticSolver.cpp, implicit branch, in NumPy (point 0 fixed):
    (x, v, hamiltonianEnergy) after each step."""
    free = np.arange(3, 3 * len(POSITIONS))  # the unconstrained scalar DOFs
    mass = MASS * np.eye(3 * len(POSITIONS))
    x, v = POSITIONS.copy(), VELOCITIES.copy()
    p = mass @ v.ravel()
    potential = _potential(x)
    out = []
    for _ in range(steps):
        old = x.copy()
        norm = np.linalg.norm(old)
        res = np.zeros(x.size)
        previous = x.copy()
        iteration = 0
        while True:
            f, k = _forces(x)
            b = f.ravel() + 2.0 / h * p - k @ res
            matrix = (4.0 / (h * h) + 4 * RM / h) * mass + (-1.0 - 4 * RK / h) * k
            res = np.zeros(x.size)
            res[free] = np.linalg.solve(matrix[np.ix_(free, free)], b[free])
            x = old + res.reshape(-1, 3)
            change = np.linalg.norm(x - previous) / norm
            previous = x.copy()
            iteration += 1
            if not (iteration < newton_steps and change > newton_error):
                break
        potential += -2.0 * float(f.ravel() @ res)
        v = (2.0 / h * res).reshape(-1, 3)
        middle = old + h / 2 * v
        f, _ = _forces(middle)
        f[0] = 0.0
        p = h / 2 * f.ravel() + mass @ v.ravel()
        x = middle + h / 2 * v
        kinetic = 0.5 * p @ np.linalg.solve(mass, p)
        out.append((x, v, kinetic + potential))
    return out


@pytest.mark.parametrize(("newton_steps", "newton_error"), [(1, 0.01), (4, 1e-9), (6, 0.0)])
def test_steps_match_numpy(tmp_path: Path, newton_steps: int, newton_error: float) -> None:
    h, steps = 0.01, 3
    scene = tmp_path / "net.scn"
    scene.write_text(
        NONLINEAR.format(
            gravity=_numbers(GRAVITY),
            dt=h,
            steps=newton_steps,
            error=newton_error,
            rk=RK,
            rm=RM,
            incremental=1,
            x=_numbers(POSITIONS),
            v=_numbers(VELOCITIES),
            m=MASS,
            springs="  ".join(f"{a} {b} {s!r} 0 {length!r}" for a, b, s, length in SPRINGS),
        )
    )
    sim = sofac.load(scene)
    hamiltonian = sim.output("/net/vss.hamiltonianEnergy")
    for x, v, energy in reference_steps(steps, h, newton_steps, newton_error):
        sim.step()
        scale = np.abs(x).max()
        assert np.abs(sim["dofs"].position - x).max() <= 1e-12 * scale
        assert np.abs(sim["dofs"].velocity - v).max() <= 1e-12 * np.abs(v).max()
        assert hamiltonian[0] == pytest.approx(energy, rel=1e-12)


# --- what is refused, and SOFA's example scene ----------------------------------------------------

REFUSED = {
    "explicit": (
        '<VariationalSymplecticSolver explicitIntegration="1"/><CGLinearSolver/>'
        '<MechanicalObject position="0 0 0"/><UniformMass/>',
        "explicitIntegration=true is not compiled yet",
    ),
    "rigid": (
        "<VariationalSymplecticSolver/><CGLinearSolver/>"
        '<MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/><UniformMass/>',
        "VariationalSymplecticSolver on Rigid3d is not compiled yet",
    ),
    "precomputed": (
        "<VariationalSymplecticSolver/><PrecomputedLinearSolver/>"
        '<MechanicalObject position="0 0 0"/><UniformMass/>',
        "PrecomputedLinearSolver under VariationalSymplecticSolver is not compiled yet",
    ),
    "mapped mass": (
        '<VariationalSymplecticSolver/><CGLinearSolver/><MechanicalObject position="0 0 0"/>'
        '<UniformMass/><Node name="child"><MechanicalObject position="0 0 0"/><UniformMass/>'
        "<IdentityMapping/></Node>",
        "a mass on a mapped state under VariationalSymplecticSolver is not compiled yet",
    ),
}


@pytest.mark.parametrize("case", REFUSED)
def test_refused_with_a_diagnostic(tmp_path: Path, case: str) -> None:
    body, why = REFUSED[case]
    scene = tmp_path / "refused.scn"
    scene.write_text(f'<Node name="root">\n<DefaultAnimationLoop/>\n{body}\n</Node>\n')
    with pytest.raises(sofac.SceneError) as failure:
        sofac.load(scene)
    messages = [d.message for d in failure.value.diagnostics if d.code == "E222"]
    assert any(why in m for m in messages), messages


def test_sofa_example_scene_runs_and_writes_its_energies(
    corpus_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SOFA's example: a tetrahedral beam under gravity, 4 Newton steps with CG, saveEnergyInFile.
    The energy file (written in the working directory, as SOFA's stream opens it) has SOFA's
    header and one line per step; the Hamiltonian it shows stays at its first value (the beam falls:
    potential turns into kinetic energy)."""
    monkeypatch.chdir(tmp_path)
    scene = corpus_dir / "Component/ODESolver/Backward/VariationalSymplecticSolver.scn"
    sim = sofac.load(scene, data_roots=[corpus_dir])
    steps = 20
    sim.step(steps)
    lines = (tmp_path / "energy.txt").read_text().splitlines()
    assert lines[0] == "time,kinetic energy,potential energy, hamiltonian energy"
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    assert rows.shape == (steps, 4)
    assert rows[:, 0] == pytest.approx(0.02 * np.arange(steps))
    assert rows[:, 3] == pytest.approx(rows[:, 1] + rows[:, 2], rel=1e-5)
    assert rows[-1, 1] > 10 * rows[0, 1]  # it falls
    assert rows[:, 3] == pytest.approx(rows[0, 3], rel=1e-5)
    hamiltonian = sim.output("/Single/default0.hamiltonianEnergy")[0]
    assert hamiltonian == pytest.approx(rows[-1, 3], rel=1e-5)
    assert np.isfinite(sim["/Single/M1/MechanicalObject1"].position).all()
    sim.reset()  # SOFA writes the header again at time 0
    sim.step()
    lines = (tmp_path / "energy.txt").read_text().splitlines()
    assert lines[-2] == lines[0] and lines[-1].startswith("0,") and len(lines) == steps + 3


def test_save_energy_without_a_file_is_a_warning(tmp_path: Path) -> None:
    scene = tmp_path / "nofile.scn"
    scene.write_text(
        OSCILLATOR.format(
            dt=0.01,
            solver='<VariationalSymplecticSolver saveEnergyInFile="1"/>',
            linear=LDL,
            x0=L + A,
            m=M,
            k=K,
            length=L,
        )
    )
    _, diagnostics = check_file(scene)
    warnings = [d for d in diagnostics if d.code == "W225"]
    assert len(warnings) == 1 and "saveEnergyInFile=true without a file" in warnings[0].message
    assert warnings[0].loc.line == 4 and warnings[0].loc.attribute == "saveEnergyInFile"
