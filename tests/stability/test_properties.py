"""Property-based runs (hypothesis) of random small spring and tetrahedral FEM scenes.

Scene *structures* come from a small fixed set (three spring graphs, two tetrahedra under three FEM
methods), compiled once each; every example varies the numbers through parameter views and the
initial state (stiffness 1e-2..1e6, damping 0..10, masses 1e-3..1e3, dt 1e-4..0.1, Young's
modulus 1e2..1e6, Poisson's ratio 0..0.49, random positions and velocities), which needs no
recompilation.

The properties, and where they hold (SOFA's implicit Euler is *linearly* implicit: one Newton
step per time step, spring damping integrated explicitly):

* every run ends with a finite state or raises SimulationDiverged consistent with the arrays (a
  non-finite DOF, or an energy past the guard's bound), never a silent NaN, for any of these
  numbers, damped or not, springs of any rest length, elements flattened or inverted;
* no energy gain without external work (no gravity, no applied force) where the scheme guarantees
  it: linear force fields, i.e. zero-length undamped springs and the "small" FEM method (whose
  strain energy sim.energy() counts, checked against the work of its force); corotational FEM
  ("large", "polar") vibrating by about a tenth of its size around its rest shape (kinetic energy
  never above its start).

Outside those domains SOFA's scheme can gain energy, and so does sofac (the same formulas):
nonlinear springs far from their rest length at large dt (one linearised step overshoots), damping
of springs whose ends cross, corotational elements deformed past inversion.

``SOFAC_HYPOTHESIS_EXAMPLES`` sets the number of examples per property (30 by default).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import numpy as np
import sofac
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from .scenes import EXACT_CG, TWO_TETS, TWO_TETS_POINTS, Scenes, finite, nums, springs_body, tetra_body

EXAMPLES = int(os.environ.get("SOFAC_HYPOTHESIS_EXAMPLES", "30"))
RUN = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SAMPLES, PER_SAMPLE = 10, 20  # 200 steps, energy checked every 20
ENERGY_RTOL = 1e-7  # converged CG (tolerance 1e-14) on at most 18 unknowns
# Absolute floors: a spring shorter than 1e-9 gives no force (SOFA's rule) though its energy counts,
# 0.5 k (1e-9)^2 at most; FEM displacements are rounded to the ulp of coordinates of order 1.
SPRING_CUTOFF = 1e-9
FEM_ROUNDING = 1e-14

GRAPHS: dict[int, list[tuple[int, int]]] = {
    2: [(0, 1)],
    4: [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)],
    6: [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 2), (1, 3), (2, 4), (3, 5)],
}


def log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(math.log10(low), math.log10(high)).map(lambda e: 10.0**e)


def vectors(strategy: st.SearchStrategy[float], count: int) -> st.SearchStrategy[np.ndarray]:
    return st.lists(strategy, min_size=count, max_size=count).map(np.array)


def spring_sim(scenes: Scenes, n: int) -> sofac.Simulation:
    mass = f'<DiagonalMass name="mass" vertexMass="{nums(np.ones(n))}"/>'
    body = springs_body(EXACT_CG, np.eye(n, 3) * 0.5, GRAPHS[n], mass=mass)
    return scenes.sim(f"prop-springs-{n}", body)


@st.composite
def spring_cases(draw: Callable[..., Any]) -> dict[str, Any]:
    n = draw(st.sampled_from(sorted(GRAPHS)))
    count = len(GRAPHS[n])
    return {
        "n": n,
        "stiffness": draw(vectors(log_uniform(1e-2, 1e6), count)),
        "damping": draw(vectors(st.one_of(st.just(0.0), st.floats(0.0, 10.0)), count)),
        "lengths": draw(vectors(st.one_of(st.just(0.0), st.floats(0.0, 2.0)), count)),
        "masses": draw(vectors(log_uniform(1e-3, 1e3), n)),
        "dt": draw(log_uniform(1e-4, 0.1)),
        "x": draw(vectors(st.floats(-2.0, 2.0), 3 * n)).reshape(n, 3),
        "v": draw(vectors(st.floats(-5.0, 5.0), 3 * n)).reshape(n, 3),
    }


def set_springs(sim: sofac.Simulation, case: dict[str, Any]) -> None:
    sim.reset()
    sim.param("/s/springs.stiffness")[:] = case["stiffness"]
    sim.param("/s/springs.damping")[:] = case["damping"]
    sim.param("/s/springs.lengths")[:] = case["lengths"]
    sim.param("/s/mass.vertexMass")[:] = case["masses"]
    sim.dt = case["dt"]
    sim["dofs"].position[:] = case["x"]
    sim["dofs"].velocity[:] = case["v"]


def run_or_diverge(sim: sofac.Simulation, steps: int) -> sofac.SimulationDiverged | None:
    """Run; a divergence must be consistent: a DOF whose values are not finite, or an energy past
    its bound, at the step and time reached."""
    start = sim.steps
    try:
        sim.step(steps)
    except sofac.SimulationDiverged as error:
        assert start < error.step <= start + steps
        assert error.time == sim.time and error.step == sim.steps
        state = sim[error.state]
        assert error.dof is not None
        row = np.r_[state.position[error.dof], state.velocity[error.dof]]
        if error.reason == "non-finite":
            assert not np.isfinite(row).all()
        else:
            assert error.reason == "energy" and finite(sim)
            assert error.energy is not None and error.bound is not None and not error.energy <= error.bound
        assert all(
            np.isfinite(x).all() and np.isfinite(v).all() for x, v in (error.last_finite or {}).values()
        )
        return error
    assert finite(sim)
    return None


# --- springs -------------------------------------------------------------------------------------


@RUN
@given(case=spring_cases())
def test_random_springs_end_finite_or_reported(scenes: Scenes, case: dict[str, Any]) -> None:
    # A blow-up can end on finite values whose energy has overflowed (x ~ 1e152): the energy guard,
    # checked every PER_SAMPLE steps, reports those.
    sim = spring_sim(scenes, case["n"])
    set_springs(sim, case)
    energy = sim.energy()
    sim.guard_energy(1e12, scale=abs(energy.kinetic) + abs(energy.potential) or 1.0)
    sim.chunk = PER_SAMPLE
    if run_or_diverge(sim, SAMPLES * PER_SAMPLE) is None:
        assert math.isfinite(sim.energy().total)


@RUN
@given(case=spring_cases())
def test_linear_springs_never_gain_energy(scenes: Scenes, case: dict[str, Any]) -> None:
    # Zero-length springs without damping are linear (f = k (x_b - x_a)): implicit Euler only
    # dissipates. Spring damping is not linear (its direction flips where two points cross) and
    # SOFA integrates it explicitly: damped springs are covered by the property above.
    case["lengths"] = np.zeros(len(GRAPHS[case["n"]]))
    case["damping"] = np.zeros(len(GRAPHS[case["n"]]))
    sim = spring_sim(scenes, case["n"])
    set_springs(sim, case)
    start = sim.energy().total
    for _ in range(SAMPLES):
        assert run_or_diverge(sim, PER_SAMPLE) is None
        energy = sim.energy().total
        floor = case["stiffness"].sum() * SPRING_CUTOFF**2
        assert energy <= start * (1 + ENERGY_RTOL) + floor, (energy, start, sim.steps)


# --- tetrahedral FEM -----------------------------------------------------------------------------

REST = TWO_TETS_POINTS


def fem_sim(scenes: Scenes, method: str) -> sofac.Simulation:
    return scenes.sim(f"prop-fem-{method}", tetra_body(EXACT_CG, REST, TWO_TETS, method))


@st.composite
def fem_cases(draw: Callable[..., Any], perturbation: float) -> dict[str, Any]:
    return {
        "young": draw(log_uniform(1e2, 1e6)),
        "poisson": draw(st.floats(0.0, 0.49)),
        "mass": draw(log_uniform(1e-3, 1e3)),
        "dt": draw(log_uniform(1e-4, 0.1)),
        "dx": draw(vectors(st.floats(-perturbation, perturbation), REST.size)).reshape(REST.shape),
        "v": draw(vectors(st.floats(-1.0, 1.0), REST.size)).reshape(REST.shape),
    }


def set_fem(sim: sofac.Simulation, case: dict[str, Any], *, velocity: bool = True) -> None:
    sim.param("/t/fem.youngModulus")[:] = case["young"]
    sim.param("/t/fem.poissonRatio")[:] = case["poisson"]
    sim.param("/t/mass.vertexMass")[:] = case["mass"]
    sim.reset()  # the element matrices are computed at init, from these parameters
    sim.dt = case["dt"]
    sim["dofs"].position[:] = REST + case["dx"]
    sim["dofs"].velocity[:] = case["v"] if velocity else 0.0


def elastic_energy(probe: sofac.Simulation, case: dict[str, Any], x: np.ndarray) -> float:
    """Strain energy of a linear force field, -f(x).(x - rest) / 2, with f(x) measured by one
    implicit step of 1e-9 s from rest (dv = h M^-1 f up to h^2 K / M ~ 1e-12)."""
    h = 1e-9
    set_fem(probe, {**case, "dx": x - REST}, velocity=False)
    probe.dt = h
    probe.step(1)
    force = case["mass"] * probe["dofs"].velocity / h
    return float(-0.5 * np.sum(force * (x - REST)))


@RUN
@given(case=fem_cases(perturbation=0.3))
def test_small_strain_fem_never_gains_energy(scenes: Scenes, case: dict[str, Any]) -> None:
    sim, probe = fem_sim(scenes, "small"), fem_sim(scenes, "small")
    set_fem(sim, case)
    floor = case["young"] * FEM_ROUNDING**2
    # sim.energy() counts the strain energy (SOFA's getPotentialEnergy, method small): it agrees
    # with the work of the force the step applies, measured by the probe.
    start_x = sim["dofs"].position.copy()
    strain = elastic_energy(probe, case, start_x)
    assert math.isclose(
        elastic_energy(probe, case, REST + 2 * (start_x - REST)), 4 * strain, rel_tol=1e-6, abs_tol=floor
    )
    assert math.isclose(sim.energy().potential, strain, rel_tol=1e-6, abs_tol=floor)
    start = sim.energy().total
    for _ in range(SAMPLES):
        assert run_or_diverge(sim, PER_SAMPLE) is None
        energy = sim.energy().total
        assert energy <= start * (1 + ENERGY_RTOL) + floor, (energy, start, sim.steps)


@RUN
@given(method=st.sampled_from(["large", "polar"]), case=fem_cases(perturbation=0.0))
def test_corotational_fem_from_rest_never_gains_kinetic_energy(
    scenes: Scenes, method: str, case: dict[str, Any]
) -> None:
    # From the rest shape the strain energy starts at 0, so E(t) <= E(0) implies KE(t) <= KE(0).
    # Velocities scaled to sqrt(E / m) / 10: vibrations of about a tenth of the size, rigid motions
    # of any amplitude. Far larger deformations (inverted elements) can gain energy under "large",
    # whose forces are then not torque-free (test_hard_scenes shows one).
    case["v"] = case["v"] * 0.1 * math.sqrt(case["young"] / case["mass"])
    sim = fem_sim(scenes, method)
    set_fem(sim, case)
    start = sim.energy().kinetic
    for _ in range(SAMPLES):
        assert run_or_diverge(sim, PER_SAMPLE) is None
        kinetic = sim.energy().kinetic
        assert kinetic <= start * (1 + ENERGY_RTOL) + case["young"] * FEM_ROUNDING**2, (
            kinetic,
            start,
            sim.steps,
        )


@RUN
@given(method=st.sampled_from(["small", "large", "polar"]), case=fem_cases(perturbation=0.8))
def test_perturbed_fem_ends_finite_or_reported(scenes: Scenes, method: str, case: dict[str, Any]) -> None:
    # Perturbations up to 0.8 of the edge length: elements flatten and invert.
    sim = fem_sim(scenes, method)
    set_fem(sim, case)
    run_or_diverge(sim, SAMPLES * PER_SAMPLE)
