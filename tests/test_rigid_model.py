"""SOFA's rigid-body simplification against the opt-in exact model, on the Dzhanibekov effect.

SOFA applies a rigid body's inertia in world axes, never rotated, with no gyroscopic term: a body
spinning about its intermediate principal axis then spins on for ever. Euler's equations say it flips
(the "tennis racket" instability). The exact model (``sofac.load(..., rigid_model="exact")``) turns
the inertia with the body and keeps ω × Iω; it must follow a reference integration of Euler's
equations, while SOFA's model must not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

INERTIA = np.array([1.0, 2.0, 3.0])  # principal moments; spin about the intermediate axis (y)
OMEGA0 = np.array([1e-3, 4.0, 1e-3])
RACKET = """<Node name="root" gravity="0 0 0" dt="{dt!r}"><DefaultAnimationLoop/>
  <Node name="racket"><RungeKutta4Solver/>
    <MechanicalObject name="body" template="Rigid3d" position="0 0 0  0 0 0 1" velocity="0 0 0  {w}"/>
    <UniformMass vertexMass="1 1 [1 0 0, 0 2 0, 0 0 3]"/>
  </Node>
</Node>"""


def euler_equations(omega: np.ndarray, duration: float, dt: float) -> np.ndarray:
    """Body-frame angular velocity after ``duration`` (RK4 on I dw/dt = (I w) x w)."""

    def rate(w: np.ndarray) -> np.ndarray:
        return np.cross(INERTIA * w, w) / INERTIA

    w = omega.copy()
    for _ in range(round(duration / dt)):
        k1 = rate(w)
        k2 = rate(w + 0.5 * dt * k1)
        k3 = rate(w + 0.5 * dt * k2)
        k4 = rate(w + dt * k3)
        w = w + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return w


def body_frame(position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    x, y, z, w = position[3:7]
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return rotation.T @ velocity[3:6]


@pytest.fixture(scope="module")
def racket(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("racket") / "racket.scn"
    path.write_text(RACKET.format(dt=1e-3, w=" ".join(repr(float(c)) for c in OMEGA0)))
    return path


def test_exact_model_follows_eulers_equations_through_the_flip(racket: Path) -> None:
    duration = 7.0  # the first flip happens around t = 4.5
    reference = euler_equations(OMEGA0, duration, 1e-4)
    assert reference[1] < -3.9  # the racket has flipped: the spin about y reversed
    sim = sofac.load(racket, rigid_model="exact")
    sim.step(round(duration / sim.dt))
    state = sim["body"]
    got = body_frame(state.position[0], state.velocity[0])
    assert got == pytest.approx(reference, abs=2e-3)
    assert np.linalg.norm(state.position[0, 3:]) == pytest.approx(1.0, abs=1e-9)


def test_sofa_model_never_flips(racket: Path) -> None:
    sim = sofac.load(racket)
    sim.step(4000)
    world = sim["body"].velocity[0, 3:]
    assert world == pytest.approx(OMEGA0, abs=1e-12)  # no gyroscopic term: the world ω never changes


def test_exact_model_is_refused_with_implicit_solvers(tmp_path: Path) -> None:
    path = tmp_path / "implicit.scn"
    text = RACKET.format(dt=1e-3, w="0 1 0").replace(
        "<RungeKutta4Solver/>", '<EulerImplicitSolver/><CGLinearSolver iterations="10"/>'
    )
    path.write_text(text)
    with pytest.raises(sofac.SceneError, match="exact rigid model"):
        sofac.load(path, rigid_model="exact")
