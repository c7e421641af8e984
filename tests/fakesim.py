"""A numpy stand-in for a loaded simulation: particles in free fall, with exact known states.

It offers what ``sofac.regress.states`` and ``sofac.regress.suite`` use of ``sofac.load(path)``: ``dt``,
``time`` (accumulated ``+= dt`` per step, as SOFA does), ``step(n)``, ``states()`` and
``sim[path].position/.velocity``. Positions follow ``x(t) = x0 + v0 t + g t^2 / 2`` evaluated at
``t = k dt`` exactly, so tests know every recorded value.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class FakeInfo:
    path: str
    name: str
    mapped: bool = False
    template: str = "Vec3d"
    simulated: bool = True


@dataclass
class FakeView:
    position: np.ndarray
    velocity: np.ndarray


class FallingSim:
    """Independent free-falling particle sets, one per state (mapped ones fall as well)."""

    def __init__(
        self,
        dt: float,
        states: Sequence[tuple[FakeInfo, np.ndarray, np.ndarray]],
        gravity: Sequence[float] = (0.0, -2.0, 0.0),
    ) -> None:
        self.dt = dt
        self.time = 0.0
        self.steps_done = 0
        self.step_calls: list[int] = []
        self.gravity = np.asarray(gravity, dtype=np.float64)
        self._states = [
            (info, np.array(x0, dtype=np.float64), np.array(v0, dtype=np.float64)) for info, x0, v0 in states
        ]

    def states(self) -> list[FakeInfo]:
        return [info for info, _, _ in self._states]

    def exact(self, path: str, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity of a state after ``steps`` steps."""
        for info, x0, v0 in self._states:
            if info.path == path:
                t = steps * self.dt
                g = self.gravity[: x0.shape[1]]
                return x0 + v0 * t + 0.5 * g * t * t, v0 + g * t
        raise KeyError(path)

    def step(self, n: int = 1) -> None:
        self.step_calls.append(n)
        for _ in range(n):
            self.time += self.dt
            self.steps_done += 1

    def __getitem__(self, path: str) -> FakeView:
        position, velocity = self.exact(path, self.steps_done)
        return FakeView(position, velocity)


def two_body_sim(dt: float = 0.5) -> FallingSim:
    """Two unmapped states ("dofs": 2 DOFs, unnamed "MechanicalObject1": 1 DOF) and a mapped one."""
    return FallingSim(
        dt,
        [
            (
                FakeInfo("/a/dofs", "dofs"),
                [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]],
                [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
            ),
            (FakeInfo("/a/visu/points", "points", mapped=True), [[0.0, 1.0, 0.0]], [[0.0, 0.0, 0.0]]),
            (FakeInfo("/b/MechanicalObject1", "MechanicalObject1"), [[5.0, 5.0, 5.0]], [[0.0, 1.0, 0.0]]),
        ],
    )


class DivergingSim(FallingSim):
    """Raises a sofac error on its second step, as a simulation that blows up would."""

    def step(self, n: int = 1) -> None:
        from sofac.diagnostics import SofacError

        if self.steps_done + n > 1:
            raise SofacError(
                f"the simulation diverged at step 1 (t={self.dt:g}): /a/dofs is no longer finite"
            )
        super().step(n)


def regression_loader(path: Path) -> FallingSim:
    """A stand-in for ``sofac.load`` keyed by the scene's file name (module level: picklable)."""
    from sofac.diagnostics import Diagnostic, SceneError, Severity, SourceLoc

    stem = Path(path).stem
    if stem.startswith("unsupported"):
        raise SceneError(
            [
                Diagnostic("W203", SourceLoc(str(path), 3), "unknown attribute", severity=Severity.WARNING),
                Diagnostic(
                    "E222", SourceLoc(str(path), 14), "unsupported component MeshMatrixMass at line 14: no"
                ),
                Diagnostic(
                    "E222", SourceLoc(str(path), 9), "unsupported component TriangleCollisionModel at line 9"
                ),
            ]
        )
    if stem.startswith("invalid"):
        raise SceneError([Diagnostic("E219", SourceLoc(str(path), 5), "mesh file 'liver.msh' not found")])
    if stem.startswith("diverging"):
        return DivergingSim(0.5, two_body_sim()._states)
    if stem.startswith("crash"):
        os._exit(3)  # a native crash: the process dies without a word
    return two_body_sim()
