"""Hard scenes, each with its expected outcome: stays finite and bounded (and dissipates, under
implicit Euler without external work), recovers, or is reported as diverged with its step.

Some outcomes are SOFA's own behaviour, reproduced on purpose and written down here: spring damping
is integrated explicitly by SOFA's implicit Euler, the polar decomposition keeps a reflection (an
inverted element stays inverted), the "large" corotational method is not torque-free once an
element is badly deformed.

``SOFAC_LONG=1`` runs the long liver run at its full 10^5 steps (10^4 by default).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import sofac

from .scenes import (
    DIRECT,
    EXACT_CG,
    GRAVITY,
    ONE_TET,
    ONE_TET_POINTS,
    TWO_TETS,
    TWO_TETS_POINTS,
    Scenes,
    beam,
    chain_pairs,
    finite,
    implicit,
    line,
    nums,
    springs_body,
    tetra_body,
    volumes,
)

LONG = os.environ.get("SOFAC_LONG", "") not in ("", "0")


def bent_chain(n: int, seed: int = 1) -> np.ndarray:
    """Points about 1 apart along x, bent out of line (springs of rest length 1 start stretched)."""
    rng = np.random.default_rng(seed)
    steps = np.c_[np.full(n, 1.05), rng.normal(0, 0.1, n), rng.normal(0, 0.1, n)]
    return np.cumsum(steps, axis=0) - steps[0]


# --- stiff springs: k/m = 1e8 at dt = 0.01 ---------------------------------------------------------

STIFF = {"stiffness": 1e8, "damping": 0.0}


def test_stiff_springs_under_implicit_euler_stay_bounded_and_never_gain_energy(scenes: Scenes) -> None:
    body = springs_body(implicit(), bent_chain(5), chain_pairs(5), **STIFF)
    sim = scenes.sim("stiff-implicit", body, dt=0.01)
    energies = [sim.energy().total]
    for _ in range(1000):
        sim.step(1)
        energies.append(sim.energy().total)
    energy = np.array(energies)
    assert finite(sim)
    assert energy[0] > 1e4  # stretched by 5 %: 0.5 k 0.05^2 per spring and more
    gains = np.diff(energy)
    assert gains.max() <= 1e-9 * energy[0], f"energy gained {gains.max():g} at step {int(gains.argmax()) + 1}"
    assert energy[-1] < 1e-3 * energy[0]
    assert np.abs(sim["dofs"].position).max() < 10


def test_stiff_springs_under_explicit_euler_are_reported_diverged_with_the_step(scenes: Scenes) -> None:
    body = springs_body("<EulerExplicitSolver/>", bent_chain(5), chain_pairs(5), **STIFF)
    sim = scenes.sim("stiff-explicit", body, dt=0.01)
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    error = failure.value
    assert error.reason == "non-finite" and 1 <= error.step <= 200
    assert f"diverged at step {error.step} " in str(error)
    assert error.time == pytest.approx(error.step * 0.01)
    assert error.state == "/s/dofs" and error.dof is not None
    assert "EulerExplicitSolver" in error.solver and "implicit solver" in error.hint
    assert error.last_finite is not None  # the initial state: the whole run was one chunk


# --- mass ratio 1e6, a 1000-link chain, zero-length springs, coincident particles -----------------


def test_mass_ratio_1e6_along_a_hanging_chain_settles_on_the_static_solution(scenes: Scenes) -> None:
    n, k = 8, 1e9
    masses = np.where(np.arange(n) % 2 == 1, 1e6, 1.0)
    hanging = line(n, axis=1) * -1.0
    mass = f'<DiagonalMass name="mass" vertexMass="{nums(masses)}"/>'
    body = springs_body(
        implicit(100, 1e-12, 1e-30), hanging, chain_pairs(n), stiffness=k, damping=0.0, mass=mass, fixed=[0]
    )
    sim = scenes.sim("mass-ratio", body, dt=0.01, gravity=GRAVITY)
    sim.step(5000)  # the stretching modes (omega = 31 rad/s for the heavy masses) die out
    assert finite(sim)
    below = np.cumsum(masses[::-1])[::-1]  # mass hanging from each spring's lower end
    stretch = np.r_[0.0, 1.0 + 9.81 * below[1:] / k]
    expected = -np.cumsum(stretch)
    assert sim["dofs"].position[:, 1] == pytest.approx(expected, abs=1e-9)
    assert np.abs(sim["dofs"].position[:, [0, 2]]).max() < 1e-9
    assert np.abs(sim["dofs"].velocity).max() < 1e-6


def test_a_1000_link_chain_stays_finite(scenes: Scenes) -> None:
    n = 1001
    body = springs_body(implicit(), line(n), chain_pairs(n), stiffness=1e4, damping=0.0, fixed=[0])
    sim = scenes.sim("chain-1000", body, dt=0.01, gravity=GRAVITY)
    sim.step(500)
    assert finite(sim)
    x = sim["dofs"].position
    fall = 9.81 * sim.time**2 / 2
    assert x[:, 1].min() >= -fall - 1.0 and x[:, 1].max() <= 1e-9  # no faster than free fall
    assert np.abs(x[:, 0]).max() <= n  # within its own length of the fixed end


ZERO_AND_COINCIDENT = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]])
# 0-1 zero rest length, coincident; 1-2 rest length 1 between coincident points; 2-3 zero rest
# length, stretched; 3-4 rest length 1, coincident.
ZERO_PAIRS = [(0, 1), (1, 2), (2, 3), (3, 4)]
ZERO_LENGTHS = [0.0, 1.0, 0.0, 1.0]


@pytest.mark.parametrize("solver", ["implicit", "explicit"])
def test_zero_length_springs_and_coincident_particles_give_no_nan(scenes: Scenes, solver: str) -> None:
    text, dt = (implicit(), 0.01) if solver == "implicit" else ("<EulerExplicitSolver/>", 1e-3)
    body = springs_body(text, ZERO_AND_COINCIDENT, ZERO_PAIRS, stiffness=1e4, rest=ZERO_LENGTHS, fixed=[0])
    # At rest without gravity: springs between coincident points have no direction and give no
    # force; the stretched zero-length spring pulls its ends together.
    sim = scenes.sim(f"zero-{solver}", body, dt=dt)
    sim.step(1)
    assert finite(sim)
    assert np.array_equal(sim["dofs"].position[:2], ZERO_AND_COINCIDENT[:2])
    sim.step(2000)
    assert finite(sim)
    assert np.abs(sim["dofs"].position).max() < 10
    # With gravity, everything hangs from the fixed point and stays finite.
    hanging = scenes.sim(f"zero-{solver}-g", body, dt=dt, gravity=GRAVITY)
    hanging.step(2000)
    assert finite(hanging)
    assert np.abs(hanging["dofs"].position).max() < 10


# --- degenerate tetrahedra under corotational FEM -------------------------------------------------

REST_VOLUME = 1.0 / 6.0
BASE_FIXED = [0, 1, 2]  # the apex (3) is free
START = {
    "nearly-flat": ONE_TET_POINTS * [1, 1, 1e-6],
    "nearly-flat-inverted": ONE_TET_POINTS * [1, 1, -1e-6],
    "flat": ONE_TET_POINTS * [1, 1, 0],
    "inverted": ONE_TET_POINTS * [1, 1, -1],
    "far-inverted": ONE_TET_POINTS * [1, 1, -100],
}
# What each method does from each start (apex free, base fixed), SOFA's behaviour: "large" builds its
# frame from the fixed base and recovers from anything; "polar" keeps the improper orthogonal
# factor of a reflected element (det < 0) and stops on a singular one, so an inverted apex settles
# on the mirrored rest shape and an exactly flat one does not move; it recovers otherwise.
RECOVERS = {
    "large": set(START),
    "polar": {"nearly-flat", "far-inverted"},
    "svd": set(START),
}


@pytest.mark.parametrize("method", ["large", "polar", "svd"])
def test_flat_and_inverted_tetrahedra_recover_or_stay_bounded(scenes: Scenes, method: str) -> None:
    body = tetra_body(EXACT_CG, ONE_TET_POINTS, ONE_TET, method, fixed=BASE_FIXED)
    sim = scenes.sim(f"tet-{method}", body)
    outcomes = {}
    for name, start in START.items():
        sim.reset()
        sim["dofs"].position[:] = start
        sim.step(2000)
        assert finite(sim), (method, name)
        volume = float(volumes(sim["dofs"].position, ONE_TET)[0])
        assert abs(volume) <= REST_VOLUME * (1 + 1e-6), (method, name, volume)  # bounded
        assert np.abs(sim["dofs"].velocity).max() < 1e-6, (method, name)  # at rest again
        outcomes[name] = volume
    recovered = {name for name, volume in outcomes.items() if volume == pytest.approx(REST_VOLUME, rel=1e-6)}
    assert recovered == RECOVERS[method], outcomes
    if method == "polar":  # the mirrored rest shape, or no motion at all from a flat element
        assert outcomes["inverted"] == pytest.approx(-REST_VOLUME, rel=1e-6)
        assert outcomes["nearly-flat-inverted"] == pytest.approx(-REST_VOLUME, rel=1e-6)
        assert outcomes["flat"] == 0.0


def test_a_free_inverted_tetrahedron_under_large_turns_right_side_out_and_stays_bounded(
    scenes: Scenes,
) -> None:
    # Without any constraint, "large" recovers the volume's sign but its forces are not torque-free
    # on such a deformed element: it keeps spinning at a constant energy (bounded, never settling).
    body = tetra_body(EXACT_CG, ONE_TET_POINTS, ONE_TET, "large")
    sim = scenes.sim("free-tet-large", body)
    sim["dofs"].position[:] = ONE_TET_POINTS * [1, 1, -1]
    kinetic = []
    for _ in range(8):
        sim.step(1000)
        assert finite(sim)
        kinetic.append(sim.energy().kinetic)
    assert volumes(sim["dofs"].position, ONE_TET)[0] > 0
    x = sim["dofs"].position
    assert np.abs(x - x.mean(axis=0)).max() < 5  # its size stays bounded
    assert max(kinetic[2:]) <= 1.01 * min(kinetic[2:])  # no growth after the start
    assert np.abs(sim["dofs"].velocity.sum(axis=0)).max() < 1e-9  # linear momentum stays 0


@pytest.mark.parametrize("poisson", [0.3, 0.49])
def test_nearly_incompressible_cantilever_settles(scenes: Scenes, poisson: float) -> None:
    points, cells = beam(4)
    body = tetra_body(
        implicit(100, 1e-10, 1e-30), points, cells, "large", young=1e5, poisson=0.3, fixed=[0, 1, 2, 3]
    )
    sim = scenes.sim("beam-large", body, dt=0.01, gravity=GRAVITY)
    sim.param("/t/fem.poissonRatio")[:] = poisson
    sim.reset()  # element matrices from the new ratio
    for _ in range(6):
        sim.step(500)
        assert finite(sim)
    x = sim["dofs"].position
    sag = -x[:, 1].min()
    assert 0 < sag < 1.0  # a few percent of the length under its weight
    assert np.abs(sim["dofs"].velocity).max() < 1e-3
    assert (volumes(x, cells) > 0).all()
    # Nearly incompressible: volume kept within 1 %, element by element.
    if poisson == 0.49:
        assert volumes(x, cells) == pytest.approx(volumes(points, cells), rel=0.01)


# --- rigid body, free bodies, huge dt ------------------------------------------------------------


def test_rigid_body_spinning_at_1000_rad_s_keeps_a_unit_quaternion_under_rk4(scenes: Scenes) -> None:
    omega = 1000.0 * np.array([0.3, -0.5, 0.8]) / math.sqrt(0.98)
    body = (
        '<Node name="r"><RungeKutta4Solver/>'
        '<MechanicalObject name="frame" template="Rigid3d" position="0 0 0  0 0 0 1" '
        f'velocity="0.1 0 0 {nums(omega)}"/><UniformMass vertexMass="2 1 [1 0 0, 0 2 0, 0 0 3]"/></Node>'
    )
    sim = scenes.sim("spin", body, dt=1e-3)  # one radian per step
    start = sim.energy().total
    for _ in range(100):
        sim.step(100)
        q = sim["frame"].position[0, 3:]
        assert abs(np.linalg.norm(q) - 1.0) < 1e-9, sim.steps
        assert sim.energy().total == pytest.approx(start, rel=1e-9)
    assert sim.steps == 10_000 and finite(sim)


@pytest.mark.parametrize("linear", ["cg", "direct"])
def test_a_free_body_under_an_implicit_solver_stays_finite(scenes: Scenes, linear: str) -> None:
    # No constraint: the stiffness matrix is singular (rigid motions), M - h^2 K is not.
    solver = EXACT_CG if linear == "cg" else DIRECT
    sim = scenes.sim(f"free-{linear}", tetra_body(solver, TWO_TETS_POINTS, TWO_TETS, "large"))
    rng = np.random.default_rng(3)
    sim["dofs"].velocity[:] = rng.normal(size=(5, 3)) * 3
    momentum = sim["dofs"].velocity.sum(axis=0).copy()
    start = sim.energy().kinetic
    sim.step(2000)
    assert finite(sim)
    assert sim["dofs"].velocity.sum(axis=0) == pytest.approx(momentum, abs=1e-9)
    assert sim.energy().kinetic <= start
    assert (volumes(sim["dofs"].position, TWO_TETS) > 0).all()


HUGE_DT = 10.0


def test_huge_dt_under_an_implicit_solver_stays_finite(scenes: Scenes) -> None:
    body = springs_body(implicit(), bent_chain(6), chain_pairs(6), stiffness=100.0, damping=1.0, fixed=[0])
    sim = scenes.sim("huge-dt-implicit", body, dt=HUGE_DT, gravity=GRAVITY)
    sim.step(100)
    assert finite(sim)
    free = sim["dofs"].position[1:]
    assert np.abs(free).max() < 1e4  # hangs from the fixed point, stretched by its weight


def test_huge_dt_under_an_explicit_solver_is_reported_diverged(scenes: Scenes) -> None:
    body = springs_body("<EulerExplicitSolver/>", bent_chain(6), chain_pairs(6), stiffness=100.0, fixed=[0])
    sim = scenes.sim("huge-dt-explicit", body, dt=HUGE_DT, gravity=GRAVITY)
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    assert 1 <= failure.value.step < 400 and failure.value.time == pytest.approx(failure.value.step * HUGE_DT)
    assert "now 10" in failure.value.hint


def test_explicit_spring_damping_past_its_limit_is_reported_not_silent(scenes: Scenes) -> None:
    # SOFA's implicit Euler treats spring damping explicitly (SpringForceField::addDForce ignores
    # bFactor): kd dt / m = 10 here, so the run diverges, and the guard reports it.
    body = springs_body(implicit(), np.zeros((2, 3)), [(0, 1)], stiffness=1.0, damping=1.0, rest=0.0)
    sim = scenes.sim("explicit-damping-coincident", body, dt=0.1)
    sim.param("/s/mass.vertexMass")[:] = 0.01
    sim["dofs"].velocity[1] = [0.0, 0.0, 1.0]
    with pytest.raises(sofac.SimulationDiverged) as failure:
        sim.step(10_000)
    assert failure.value.step < 1000 and "EulerImplicitSolver" in failure.value.solver
    # Within the limit (kd dt / m = 0.1), the same scene dissipates.
    sim.reset()
    sim.param("/s/mass.vertexMass")[:] = 1.0
    sim["dofs"].velocity[1] = [0.0, 0.0, 1.0]
    start = sim.energy().total
    sim.step(1000)
    assert finite(sim) and sim.energy().total < start


# --- the liver, for a long time -------------------------------------------------------------------


def test_liver_long_run_never_drifts_to_nan(corpus_dir: Path) -> None:
    steps = 100_000 if LONG else 10_000
    sim = sofac.load(corpus_dir / "Demos" / "liver.scn")
    dofs = sim["dofs"]
    rest = dofs.position.copy()
    done = 0
    while done < steps:
        sim.step(1000)
        done += 1000
        assert finite(sim), done
        # Hanging from three fixed points: it settles and stays put.
        assert np.abs(dofs.position - rest).max() < 3.0, done
        if done >= 5000:
            assert np.abs(dofs.velocity).max() < 1e-2, done
    assert sim.steps == steps and math.isfinite(sim.energy().total)
