"""NewmarkImplicitSolver and EulerImplicitSolver's firstOrder on a mass-spring oscillator.

A unit of mass m hangs on a spring of stiffness k and rest length L from a fixed point, with no
gravity: along the spring's axis the force is exactly -k (x - L), a linear oscillator of
frequency w = sqrt(k / m). Each variant is a node of one scene, with its own solver.

Newmark (SOFA's NewmarkImplicitSolver) on a linear system with damping c = rm m + rk k is the
textbook scheme: (m + h gamma c + h^2 beta k) a' = -k (x + h v + h^2 (1/2 - beta) a)
- c (v + h (1 - gamma) a), then x' = x + h v + h^2 ((1/2 - beta) a + beta a'), v' = v + h ((1 - gamma) a
+ gamma a'). With gamma = 1/2, beta = 1/4 (average acceleration) and no damping, started from
rest at x0 - L = A (so a0 = -w^2 A), it is the trapezoidal rule: x_n - L = A cos(n theta) exactly,
with cos(theta) = (1 - W^2 / 4) / (1 + W^2 / 4), W = w h, and the energy is conserved exactly.

firstOrder: SOFA solves (M - h K) v' = f and sets v = v', x += h v: backward Euler on the
first-order system m x' = -k (x - L), so x_n - L = A (m / (m + h k))^n, which tends to
A exp(-k t / m) with an error of first order in h (these variants use a softer spring, k = 1).
"""

from __future__ import annotations

import pathlib

import numpy as np
import pytest
import sofac

M, K, L, A, DT = 0.5, 50.0, 1.0, 0.2, 0.05
K_FIRST = 1.0  # the first-order variants: a decay time m / k = 0.5 s, ten steps
W = np.sqrt(K / M)

NODE = """\
  <Node name="{name}">
    {solver}
    {linear}
    <MechanicalObject template="Vec3d" name="dofs" position="0 0 0  {x0!r} 0 0"/>
    <UniformMass vertexMass="{m!r}"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="0 1 {k!r} 0 {length!r}"/>
  </Node>
"""
LDL = "<SparseLDLSolver/>"
CG = '<CGLinearSolver iterations="100" tolerance="1e-15" threshold="1e-40"/>'
VARIANTS = {
    "average": ("<NewmarkImplicitSolver/>", LDL),
    "average_cg": ("<NewmarkImplicitSolver/>", CG),
    "dissipative": ('<NewmarkImplicitSolver gamma="0.6" beta="0.3025"/>', LDL),
    "damped": ('<NewmarkImplicitSolver rayleighMass="0.4" rayleighStiffness="0.01"/>', LDL),
    "first": ('<EulerImplicitSolver firstOrder="1"/>', LDL),
    "first_rayleigh": (
        '<EulerImplicitSolver firstOrder="1" rayleighMass="0.3" rayleighStiffness="0.2"/>',
        CG,
    ),
    "first_half": ('<EulerImplicitSolver firstOrder="1"/>', LDL),  # run at dt / 2 in its own scene
}
STEPS = 200


def run(tmp_path_factory: pytest.TempPathFactory, names: list[str], dt: float) -> dict[str, np.ndarray]:
    """x(t_n) - L of the moving point for n = 0..STEPS, per variant (and its velocity, name + ":v")."""
    nodes = "".join(
        NODE.format(
            name=n, solver=VARIANTS[n][0], linear=VARIANTS[n][1], x0=L + A, m=M, k=spring(n), length=L
        )
        for n in names
    )
    path = tmp_path_factory.mktemp("oscillators") / "oscillators.scn"
    path.write_text(
        f'<Node name="root" gravity="0 0 0" dt="{dt!r}"><DefaultAnimationLoop/>\n{nodes}</Node>\n'
    )
    sim = sofac.load(path)
    history = {n: [sim[f"{n}/dofs"].position[1, 0] - L] for n in names}
    history.update({f"{n}:v": [0.0] for n in names})
    for _ in range(STEPS):
        sim.step(1)
        for n in names:
            position = sim[f"{n}/dofs"].position
            assert position[1, 1:].tolist() == [0.0, 0.0]
            history[n].append(position[1, 0] - L)
            history[f"{n}:v"].append(sim[f"{n}/dofs"].velocity[1, 0])
    return {n: np.array(h) for n, h in history.items()}


def spring(name: str) -> float:
    return K_FIRST if name.startswith("first") else K


@pytest.fixture(scope="module")
def histories(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    main = run(tmp_path_factory, [n for n in VARIANTS if n != "first_half"], DT)
    main["first_half"] = run(tmp_path_factory, ["first_half"], DT / 2)["first_half"]
    return main


def newmark_reference(gamma: float, beta: float, rm: float, rk: float, h: float) -> np.ndarray:
    """The textbook Newmark recurrence on m x'' + c x' + k x = 0 (x measured from the rest length)."""
    c = rm * M + rk * K
    x, v = A, 0.0
    a = -K * x / M
    out = [x]
    for _ in range(STEPS):
        predicted_x = x + h * v + h * h * (0.5 - beta) * a
        predicted_v = v + h * (1 - gamma) * a
        a_new = -(K * predicted_x + c * predicted_v) / (M + h * gamma * c + h * h * beta * K)
        x, v, a = predicted_x + h * h * beta * a_new, predicted_v + h * gamma * a_new, a_new
        out.append(x)
    return np.array(out)


def test_average_acceleration_is_exactly_the_trapezoidal_oscillation(histories: dict) -> None:
    big_w = W * DT
    theta = np.arccos((1 - big_w**2 / 4) / (1 + big_w**2 / 4))
    exact = A * np.cos(theta * np.arange(STEPS + 1))
    for name in ("average", "average_cg"):
        assert np.abs(histories[name] - exact).max() < 1e-12, name
    # the numerical period is longer than 2 pi / w by (w h)^2 / 12 to leading order
    period = 2 * np.pi * DT / theta
    assert period / (2 * np.pi / W) - 1 == pytest.approx(big_w**2 / 12, rel=0.05)


def test_average_acceleration_conserves_the_energy(histories: dict) -> None:
    x, v = histories["average"], histories["average:v"]
    energy = 0.5 * M * v**2 + 0.5 * K * x**2
    assert np.abs(v).max() > 0.9 * W * A  # it swings
    assert np.abs(energy / energy[0] - 1).max() < 1e-11


@pytest.mark.parametrize(
    ("name", "gamma", "beta", "rm", "rk"),
    [("dissipative", 0.6, 0.3025, 0.0, 0.0), ("damped", 0.5, 0.25, 0.4, 0.01)],
)
def test_newmark_matches_the_textbook_recurrence(
    histories: dict, name: str, gamma: float, beta: float, rm: float, rk: float
) -> None:
    reference = newmark_reference(gamma, beta, rm, rk, DT)
    assert np.abs(histories[name] - reference).max() < 1e-12
    # both lose amplitude: the last period's peak is well below A
    assert np.abs(histories[name][-40:]).max() < 0.9 * A


def test_first_order_is_backward_euler_on_the_first_order_system(histories: dict) -> None:
    n = np.arange(STEPS + 1)
    exact_discrete = A * (M / (M + DT * K_FIRST)) ** n
    np.testing.assert_allclose(histories["first"], exact_discrete, rtol=1e-12, atol=1e-15)
    assert histories["first"][20] < 0.2 * A  # it decays
    # SOFA's firstOrder ignores the Rayleigh coefficients
    np.testing.assert_allclose(histories["first_rayleigh"], exact_discrete, rtol=1e-9, atol=1e-15)
    # first order in h toward the exponential: halving dt halves the error (compared at t = 1)
    t = 1.0
    exact = A * np.exp(-K_FIRST * t / M)
    error = abs(histories["first"][round(t / DT)] - exact)
    error_half = abs(histories["first_half"][round(t / (DT / 2))] - exact)
    assert error > 1e-3 * A
    assert 1.6 < error / error_half < 2.4


def test_newmark_refuses_a_precomputed_solver(tmp_path: pathlib.Path) -> None:
    """PrecomputedLinearSolver factorises once; Newmark's system changes with its factors: E222."""
    scene = tmp_path / "newmark_precomputed.scn"
    scene.write_text(
        '<Node name="root"><DefaultAnimationLoop/><NewmarkImplicitSolver/><PrecomputedLinearSolver/>'
        '<MechanicalObject position="0 0 0"/><UniformMass/></Node>\n'
    )
    with pytest.raises(sofac.SceneError) as failure:
        sofac.load(scene)
    messages = [d.message for d in failure.value.diagnostics if d.code == "E222"]
    why = "PrecomputedLinearSolver under NewmarkImplicitSolver is not compiled yet"
    assert any(why in m for m in messages)
