"""Load stage and the Python simulation API: ``sim = sofac.load("scene.scn")``.

A scene is checked, planned, rendered and built (or fetched from the cache), then instantiated
through the host module with its buffers (positions, parameters, spring lists...). States and
parameters are numpy views of the native instance: writing into them changes the simulation.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np

from . import build, generate, plan
from .check import check_file
from .diagnostics import SceneError, SofacError

_host: ModuleType | None = None


class SimulationDiverged(SofacError):
    """A state stopped being finite during a step."""

    def __init__(self, message: str, *, step: int, time: float, state: str) -> None:
        super().__init__(message)
        self.step = step
        self.time = time
        self.state = state


def host() -> ModuleType:
    """The host extension module (built on first use, then taken from the cache)."""
    global _host
    if _host is None:
        built = build.build_host()
        spec = importlib.util.spec_from_file_location("_sofac_host", built.library)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules.setdefault("_sofac_host", module)
        _host = module
    return _host


class Energy(NamedTuple):
    kinetic: float
    potential: float

    @property
    def total(self) -> float:
        return self.kinetic + self.potential


@dataclass(frozen=True)
class StateInfo:
    path: str
    name: str
    mapped: bool
    template: str
    size: int
    simulated: bool  # an ODE solver in its node or above (SOFA records only those)


class State:
    """One MechanicalObject of a running simulation; arrays are views of the native state."""

    def __init__(
        self, info: StateInfo, position: np.ndarray, velocity: np.ndarray, force: np.ndarray
    ) -> None:
        self.info = info
        self.position = position
        self.velocity = velocity
        self.force = force

    def __repr__(self) -> str:
        return f"<State {self.info.path} {self.info.template} x{self.info.size}>"


class Compiled:
    """A compiled scene: its plan and library; ``instantiate()`` makes independent simulations."""

    def __init__(self, scene_plan: plan.Plan, source: str, built: build.Built) -> None:
        self.plan = scene_plan
        self.source = source
        self.built = built
        self._library = host().Library(str(built.library))

    def instantiate(self) -> Simulation:
        return Simulation(self)


class Simulation:
    """A running instance of a compiled scene."""

    def __init__(self, compiled: Compiled) -> None:
        self.compiled = compiled
        self.plan = compiled.plan
        initial = [b.initial.copy() for b in self.plan.buffers]
        self._native = host().create(compiled._library, initial)
        self._views = [self._native.buffer(i, b.kind == "i64") for i, b in enumerate(self.plan.buffers)]
        self._native.init()
        self._states: dict[str, State] = {}
        for state in self.plan.states:
            index = {id(b): i for i, b in enumerate(self.plan.buffers)}
            datatype = state.datatype
            name = sofa_name(state.component)
            info = StateInfo(state.path, name, state.mapped, datatype.name, state.size, state.simulated)
            self._states[state.path] = State(
                info,
                self._views[index[id(state.x)]].reshape(-1, datatype.coord_size),
                self._views[index[id(state.v)]].reshape(-1, datatype.deriv_size),
                self._views[index[id(state.f)]].reshape(-1, datatype.deriv_size),
            )

    # --- time ----------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self._native.time)

    @property
    def dt(self) -> float:
        return float(self.param("/.dt")[0])

    @dt.setter
    def dt(self, value: float) -> None:
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"dt must be a positive number, got {value!r}")
        self.param("/.dt")[0] = value

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps; raises SimulationDiverged if a state stops being finite."""
        if n < 0:
            raise ValueError("n must be >= 0")
        done = int(self._native.step(int(n)))
        if done < n or (n and not self._finite()):
            bad = next((s for s in self._states.values() if not self._state_finite(s)), None)
            path = bad.info.path if bad else "?"
            raise SimulationDiverged(
                f"the simulation diverged at step {done} (t={self.time:g}): {path} is no longer finite; "
                "try a smaller dt, or an implicit solver",
                step=done,
                time=self.time,
                state=path,
            )

    def _state_finite(self, state: State) -> bool:
        return bool(np.isfinite(state.position).all() and np.isfinite(state.velocity).all())

    def _finite(self) -> bool:
        return all(self._state_finite(s) for s in self._states.values() if not s.info.mapped)

    def reset(self) -> None:
        """Back to the initial state and time 0 (tuned parameters are kept)."""
        for buffer, view in zip(self.plan.buffers, self._views, strict=True):
            if buffer.role in ("state", "scratch"):
                view[:] = buffer.initial
        self._native.time = 0.0
        self._native.init()

    # --- inspection ----------------------------------------------------------------------------
    def objects(self) -> list[str]:
        """Paths of the scene's MechanicalObjects, in SOFA's traversal order."""
        return list(self._states)

    def states(self) -> list[StateInfo]:
        return [s.info for s in self._states.values()]

    def __getitem__(self, path: str) -> State:
        key = path if path.startswith("/") else "/" + path
        if key in self._states:
            return self._states[key]
        named = [s for s in self._states.values() if s.info.name == path]
        if len(named) == 1:
            return named[0]
        raise KeyError(f"no MechanicalObject {path!r}; the scene has: {', '.join(self._states)}")

    def param(self, key: str) -> np.ndarray:
        """A tunable parameter (``"/pendulum/spring.stiffness"``, ``"/.gravity"``, ``"/.dt"``) as a view."""
        for buffer, view in zip(self.plan.buffers, self._views, strict=True):
            if buffer.key == key and buffer.role == "param":
                return view
        names = ", ".join(b.key for b in self.plan.buffers if b.role == "param")
        raise KeyError(f"no parameter {key!r}; parameters: {names}")

    def params(self) -> dict[str, np.ndarray]:
        return {b.key: v for b, v in zip(self.plan.buffers, self._views, strict=True) if b.role == "param"}

    def energy(self) -> Energy:
        kinetic, potential = self._native.energy()
        return Energy(float(kinetic), float(potential))


def sofa_name(component: Any) -> str:
    """The name SOFA gives a component: its own, else class name + a per-node counter from 1."""
    if component.name:
        return component.name
    same = [c for c in component.node.objects if not c.name and c.type_name == component.type_name]
    return f"{component.type_name}{same.index(component) + 1}"


def compile_scene(path: str | Path, *, data_roots: Sequence[Path] = ()) -> Compiled:
    """Check, plan, generate and build a scene (or take it from the cache)."""
    checked, diagnostics = check_file(path, data_roots=data_roots)
    if checked is None or diagnostics.has_errors():
        raise SceneError(diagnostics.sorted())
    return compile_checked(checked, diagnostics)


def compile_checked(checked: Any, diagnostics: Any = None) -> Compiled:
    scene_plan = plan.plan_scene(checked, diagnostics)
    source = generate.render(scene_plan)
    direct = any(g.direct or g.preconditioner for g in scene_plan.groups)  # CHOLMOD / assembly
    return Compiled(scene_plan, source, build.build_scene(source, direct_solver=direct))


def load(path: str | Path, *, dt: float | None = None, data_roots: Sequence[Path] = ()) -> Simulation:
    """Compile (or fetch from the cache) and instantiate a scene."""
    started = time.perf_counter()
    sim = compile_scene(path, data_roots=data_roots).instantiate()
    sim.load_seconds = time.perf_counter() - started  # type: ignore[attr-defined]
    if dt is not None:
        sim.dt = dt
    return sim
