"""What accuracy costs in time: one scene under many integration settings, against a reference.

``sweep(scene, solvers=..., dts=..., duration=...)`` swaps the scene's ODE solver at compile time
(explicit and symplectic Euler, RK2, RK4, implicit Euler with conjugate gradient at several
iteration counts and tolerances, implicit Euler with a sparse direct solver), runs every
configuration for the same simulated ``duration`` at every time step of ``dts``, and compares it
with a reference run. For each configuration it measures:

* ``max_error`` / ``rms_error``: position error against the reference over the whole run, relative
  to the scene's size (the diagonal of the bounding box of the initial positions). Positions are
  compared at common times, every ``sample_interval`` (default: the largest dt), so every dt must
  divide it. Every point of every MechanicalObject counts (mapped ones too, so a rigid body's
  rotation shows through the points it carries; a rigid DOF counts by its translation).
* ``energy_drift``: (E(T) - E(0)) / scale, and ``energy_drift_max`` = max |E(t) - E(0)| / scale,
  with E = kinetic + potential (gravity included) and scale the peak kinetic energy of the
  reference run (of the most accurate configuration when the reference is analytic).
* ``wall_per_sim_second``: seconds of stepping per simulated second (compilation, instantiation,
  sampling and energy evaluation excluded); ``compile_seconds`` apart (0 when cached).
* ``diverged`` (with the step, time and reason): a configuration whose state stops being finite,
  or strays farther than ``BLOWUP`` scene sizes from the reference, is a result, not an error; one
  that cannot be compiled has its reason in ``error``.

The reference is, by default, RK4 at the smallest dt / 16 (implicit Euler with the direct solver
when the scene keeps Rayleigh damping, which only the implicit solver models, or when RK4
diverges); ``reference="SOLVER@DT"`` picks another, ``reference=callable`` gives an analytic
solution (``callable(t) -> {state path or name: positions}``), and ``reference="analytic"`` loads
the one a scene declares in ``<scene>.analytic.py`` (a function ``positions(t)``).

The result is a :class:`Sweep`: a list of :class:`Record` (dataclasses) with the reference, the
measured orders of convergence and helpers (:func:`columns`, :func:`format_table`,
:func:`markdown_table`, :func:`write_json`, :func:`write_csv`; plots in :mod:`sofac.accuracy.plots`).
The command line is ``sofac accuracy`` (:mod:`sofac.accuracy.cli`); docs/accuracy.md shows it on the
bundled scenes.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import importlib.util
import json
import math
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sofac import registry, scene_warnings
from sofac.diagnostics import Diagnostics, SceneError, SofacError
from sofac.front.model import Component, Node, Scene
from sofac.pipeline import compile_checked
from sofac.progress import Progress
from sofac.simulation.loader import Compiled, Simulation, SimulationDiverged

__all__ = [
    "DEFAULT_SOLVERS",
    "INTEGRATORS",
    "AccuracyError",
    "Configuration",
    "Record",
    "Solver",
    "Sweep",
    "columns",
    "format_table",
    "load_analytic",
    "markdown_table",
    "measured_orders",
    "sweep",
    "write_csv",
    "write_json",
]

AnalyticSolution = Callable[[float], Mapping[str, Any]]

# Integrator names, as given to --solvers. "implicit" expands over the linear solvers (cg, direct);
# "variational" is VariationalSymplecticSolver (SOFA's defaults) with a sparse direct solver.
INTEGRATORS = ("euler", "symplectic", "rk2", "rk4", "implicit", "variational")
LINEAR_SOLVERS = ("cg", "direct")
DEFAULT_SOLVERS = ("euler", "symplectic", "rk2", "rk4", "implicit")
DEFAULT_CG_ITERATIONS = (25,)
DEFAULT_TOLERANCES = (1e-5,)
REFERENCE_DIVISOR = 16
# CGLinearSolver's threshold stops CG when |p.Ap| falls below it: an absolute value, which in a light
# scene (the cloth's nodes weigh 1.25 g) stops CG before it moves anything. The sweep makes it
# negligible by default, so that the iteration cap and the tolerance alone decide.
CG_THRESHOLD = 1e-30
# Stepping shorter than this (in seconds) is timed again in uninterrupted runs: sampling cuts the
# run into calls whose Python overhead would dominate the cost of a cheap scene.
MIN_TIMED_SECONDS = 0.5
MAX_TIMING_RUNS = 50
# A run whose points stray farther than BLOWUP scene sizes from the reference has diverged, even
# while its numbers stay finite (an unstable explicit step grows geometrically, to 1e300 and beyond).
BLOWUP = 10.0
# The reference has no reference: it has blown up when a point strays this many initial scene sizes
# from where it started.
REFERENCE_BLOWUP = 1000.0

_SOLVER_CATEGORIES = {
    registry.Category.ODE_SOLVER,
    registry.Category.LINEAR_SOLVER,
    registry.Category.PRECONDITIONER,
    registry.Category.LINEAR_SYSTEM,
    registry.Category.ORDERING,
}


class AccuracyError(SofacError, ValueError):
    """A sweep cannot be set up (bad solver name, dt that does not divide the sampling interval...)."""


# --- configurations ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Solver:
    """One integration setting: an integrator and, for implicit Euler, its linear solver.

    ``kind`` is ``euler`` (forward Euler), ``symplectic`` (semi-implicit Euler), ``rk2``, ``rk4``,
    ``implicit-cg`` (with ``iterations`` and ``tolerance``), ``implicit-direct`` or ``variational``
    (VariationalSymplecticSolver with SparseLDLSolver).
    """

    kind: str
    iterations: int | None = None
    tolerance: float | None = None
    threshold: float | None = None  # CG's denominator threshold (None: CG_THRESHOLD)

    @property
    def label(self) -> str:
        if self.kind == "implicit-cg":
            label = f"implicit-cg:{self.iterations}:{self.tolerance:g}"
            return label if self.threshold is None else f"{label}:{self.threshold:g}"
        return self.kind

    @property
    def implicit(self) -> bool:
        return self.kind.startswith("implicit") or self.kind == "variational"

    @property
    def theoretical_order(self) -> int:
        return {"rk2": 2, "rk4": 4, "variational": 2}.get(self.kind, 1)

    @classmethod
    def parse(cls, text: str) -> Solver:
        """``rk4``, ``implicit-direct``, ``variational``, ``implicit-cg:ITERATIONS:TOLERANCE[:THRESHOLD]``
        (labels)."""
        parts = text.strip().lower().split(":")
        kind = parts[0]
        if kind == "implicit-cg":
            usage = f"bad solver {text!r}: use implicit-cg:ITERATIONS:TOLERANCE[:THRESHOLD]"
            try:
                iterations = int(parts[1]) if len(parts) > 1 else DEFAULT_CG_ITERATIONS[0]
                tolerance = float(parts[2]) if len(parts) > 2 else DEFAULT_TOLERANCES[0]
                threshold = float(parts[3]) if len(parts) > 3 else None
            except ValueError:
                raise AccuracyError(usage) from None
            if len(parts) > 4 or iterations < 1 or not tolerance >= 0 or not (threshold or 0) >= 0:
                raise AccuracyError(usage)
            return cls(kind, iterations, tolerance, threshold)
        single = ("euler", "symplectic", "rk2", "rk4", "implicit-direct", "variational")
        if kind in single and len(parts) == 1:
            return cls(kind)
        raise AccuracyError(
            f"unknown solver {text!r}; known: euler, symplectic, rk2, rk4, implicit-direct, variational, "
            "implicit-cg:ITERATIONS:TOLERANCE"
        )


def expand_solvers(
    solvers: Iterable[str],
    linear_solvers: Iterable[str] = LINEAR_SOLVERS,
    cg_iterations: Iterable[int] = DEFAULT_CG_ITERATIONS,
    tolerances: Iterable[float] = DEFAULT_TOLERANCES,
    cg_threshold: float | None = None,
) -> list[Solver]:
    """The solver settings of a sweep: ``implicit`` expands over the linear solvers, and CG over
    iterations x tolerances (with ``cg_threshold``, default CG_THRESHOLD); explicit labels
    (``implicit-cg:50:1e-8``) are taken as they are."""
    linear = [s.strip().lower() for s in linear_solvers]
    for name in linear:
        if name not in LINEAR_SOLVERS:
            raise AccuracyError(f"unknown linear solver {name!r}; known: {', '.join(LINEAR_SOLVERS)}")
    iterations = list(cg_iterations)
    tols = list(tolerances)
    if any(i < 1 for i in iterations) or any(not t >= 0 for t in tols):
        raise AccuracyError("CG iterations must be >= 1 and tolerances >= 0")
    if cg_threshold is not None and not cg_threshold >= 0:
        raise AccuracyError("the CG threshold must be >= 0")
    out: list[Solver] = []
    for text in solvers:
        name = text.strip().lower()
        if name in ("implicit", "implicit-cg"):
            if name == "implicit" and "direct" in linear:
                out.append(Solver("implicit-direct"))
            if name == "implicit-cg" or "cg" in linear:
                out.extend(Solver("implicit-cg", i, t, cg_threshold) for i in iterations for t in tols)
        else:
            out.append(Solver.parse(name))
    unique = list(dict.fromkeys(out))
    if not unique:
        raise AccuracyError("no solver to run")
    return unique


@dataclass(frozen=True)
class Configuration:
    solver: Solver
    dt: float

    @property
    def label(self) -> str:
        return f"{self.solver.label}@{self.dt:g}"


@dataclass
class Record:
    """The measurements of one configuration (errors are NaN when it diverged or failed)."""

    solver: str  # Solver.label
    integrator: str  # Solver.kind
    dt: float
    steps: int  # steps run (up to the divergence)
    max_error: float
    rms_error: float
    energy_drift: float
    energy_drift_max: float
    wall_per_sim_second: float
    step_seconds: float
    compile_seconds: float
    cached: bool
    diverged: bool = False
    diverged_step: int | None = None
    diverged_time: float | None = None
    diverged_reason: str = ""
    cg_iterations: int | None = None
    cg_tolerance: float | None = None
    error: str = ""  # why the configuration could not run (compile or check failure)

    @property
    def ok(self) -> bool:
        return not self.diverged and not self.error


@dataclass
class SweepInfo:
    scene: str
    duration: float
    sample_interval: float
    samples: int
    scene_size: float
    reference: str  # a configuration label, or "analytic"
    energy_scale: float
    rayleigh: str  # "kept" / "removed" / "none"
    notes: list[str] = field(default_factory=list)


class Sweep(list[Record]):
    """The records of a sweep (a plain list of :class:`Record`), with its set-up in ``info``, the
    reference run in ``reference`` (None when analytic) and ``orders()``."""

    def __init__(self, records: Iterable[Record], info: SweepInfo, reference: Record | None) -> None:
        super().__init__(records)
        self.info = info
        self.reference = reference

    def orders(self) -> dict[str, float]:
        return measured_orders(self)

    def columns(self) -> dict[str, list[Any]]:
        return columns(self)


# --- the scene model ---------------------------------------------------------------------------


def _category(component: Component) -> registry.Category | None:
    found = registry.lookup(component.type_name)
    return found.spec.category if found else None


def _solver_components(solver: Solver, old: Component, rayleigh: tuple[str, str] | None) -> list[Component]:
    """The components that replace the ODE solver ``old`` (and its linear solver)."""
    made: list[Component] = []

    def add(type_name: str, **attributes: Any) -> Component:
        component = Component(type_name, old.loc)
        for key, value in attributes.items():
            component.set(key, value)
        made.append(component)
        return component

    name = {"name": old.name} if old.name else {}
    if solver.kind in ("euler", "symplectic"):
        add("EulerExplicitSolver", **name, symplectic=solver.kind == "symplectic")
    elif solver.kind == "rk2":
        add("RungeKutta2Solver", **name)
    elif solver.kind == "rk4":
        add("RungeKutta4Solver", **name)
    elif solver.kind == "variational":
        damping = {"rayleighStiffness": rayleigh[0], "rayleighMass": rayleigh[1]} if rayleigh else {}
        add("VariationalSymplecticSolver", **name, **damping)
        add("SparseLDLSolver", name="accuracy_linear_solver")
    else:
        damping = {"rayleighStiffness": rayleigh[0], "rayleighMass": rayleigh[1]} if rayleigh else {}
        add("EulerImplicitSolver", **name, **damping)
        if solver.kind == "implicit-direct":
            add("SparseLDLSolver", name="accuracy_linear_solver")
        else:
            add(
                "CGLinearSolver",
                name="accuracy_linear_solver",
                template="GraphScattered",
                iterations=solver.iterations,
                tolerance=solver.tolerance,
                threshold=CG_THRESHOLD if solver.threshold is None else solver.threshold,
            )
    return made


def _ode_solvers(root: Node) -> list[Component]:
    return [c for c in root.components() if _category(c) is registry.Category.ODE_SOLVER]


def _rayleigh_of(component: Component) -> tuple[str, str] | None:
    values = (component.get("rayleighStiffness") or "0", component.get("rayleighMass") or "0")
    try:
        if all(float(v) == 0 for v in values):
            return None
    except ValueError:
        return values  # a link or expression: kept as written
    return values


def with_solver(scene: Scene, solver: Solver, *, keep_rayleigh: bool) -> Scene:
    """A copy of ``scene`` whose every ODE solver (with the linear solvers of its node) is replaced
    by ``solver``. Rayleigh damping is carried to implicit Euler only when ``keep_rayleigh``."""
    variant = copy.deepcopy(scene)
    solvers = _ode_solvers(variant.root)
    if not solvers:
        raise AccuracyError(f"{scene.display_name}: no ODE solver to swap")
    for old in solvers:
        node = old.node
        rayleigh = _rayleigh_of(old) if keep_rayleigh else None
        index = node.objects.index(old)
        removed = [c for c in node.objects if _category(c) in _SOLVER_CATEGORIES]
        before = sum(1 for c in node.objects[:index] if c in removed)
        node.objects = [c for c in node.objects if c not in removed]
        for offset, component in enumerate(_solver_components(solver, old, rayleigh)):
            component.parent = node
            node.objects.insert(index - before + offset, component)
    return variant


def scene_rayleigh(scene: Scene) -> bool:
    """Whether an ODE solver of the scene has (non-zero) Rayleigh damping."""
    return any(_rayleigh_of(c) is not None for c in _ode_solvers(scene.root))


def _parse(path: Path, data_roots: Sequence[Path]) -> Scene:
    from sofac.front.parse import parse_scene

    diagnostics = Diagnostics()
    scene = parse_scene(path, diagnostics, data_roots=data_roots)
    if diagnostics.has_errors():
        raise SceneError(diagnostics.sorted())
    scene_warnings.issue(diagnostics.sorted())
    return scene


def compile_variant(scene: Scene, solver: Solver, *, keep_rayleigh: bool) -> Compiled:
    """Check, plan and build the scene with ``solver`` (or take it from the cache)."""
    from sofac.check.checker import check_scene

    diagnostics = Diagnostics()
    checked = check_scene(with_solver(scene, solver, keep_rayleigh=keep_rayleigh), diagnostics)
    if diagnostics.has_errors():
        raise SceneError(diagnostics.sorted())
    scene_warnings.issue(diagnostics.sorted())
    return compile_checked(checked, diagnostics)


# --- sampling one run --------------------------------------------------------------------------


def _point_dims(template: str, coord_size: int) -> int:
    """How many leading coordinates of a DOF are a point in space (a rigid DOF: its translation)."""
    if template.startswith("Rigid3"):
        return 3
    if template.startswith("Rigid2"):
        return 2
    return min(coord_size, 3)


def _as_points(positions: np.ndarray, template: str) -> np.ndarray:
    """A state's positions as (N, 3) points (zero-padded below 3D)."""
    dims = min(_point_dims(template, positions.shape[1]), positions.shape[1])
    block = np.zeros((positions.shape[0], 3))
    block[:, :dims] = positions[:, :dims]
    return block


def _points(sim: Simulation, paths: Sequence[str]) -> np.ndarray:
    """The points of the given states as one (P, 3) array."""
    blocks = [_as_points(sim[path].position, sim[path].info.template) for path in paths]
    return np.concatenate(blocks) if blocks else np.zeros((0, 3))


def _analytic_points(solution: AnalyticSolution, t: float, sim: Simulation) -> tuple[list[str], np.ndarray]:
    given = solution(t)
    paths: list[str] = []
    blocks = []
    for key, value in given.items():
        try:
            state = sim[key]
        except KeyError as exc:
            raise AccuracyError(f"analytic solution: {exc.args[0]}") from None
        array = np.asarray(value, dtype=float)
        if array.ndim == 1:
            array = array.reshape(state.position.shape[0], -1)
        if array.shape[0] != state.position.shape[0]:
            raise AccuracyError(
                f"analytic solution: {key!r} has {array.shape[0]} points, the state has "
                f"{state.position.shape[0]}"
            )
        blocks.append(_as_points(array, state.info.template))
        paths.append(state.info.path)
    return paths, np.concatenate(blocks) if blocks else np.zeros((0, 3))


@dataclass
class _Run:
    points: list[np.ndarray]  # one (P, 3) array per sample reached, sample 0 included
    energy: list[float]
    kinetic: list[float]
    steps: int
    step_seconds: float
    compile_seconds: float
    cached: bool
    diverged_step: int | None = None
    diverged_time: float | None = None
    diverged_reason: str = ""


def _timed_runs(compiled: Compiled, dt: float, steps: int) -> float:
    """The shortest time of uninterrupted runs of ``steps`` steps, repeated up to MIN_TIMED_SECONDS."""
    best = math.inf
    spent = 0.0
    for _ in range(MAX_TIMING_RUNS):
        sim = compiled.instantiate()
        sim.dt = dt
        started = time.perf_counter()
        sim.step(steps)
        elapsed = time.perf_counter() - started
        best = min(best, elapsed)
        spent += elapsed
        if spent >= MIN_TIMED_SECONDS:
            break
    return best


def _run(
    compiled: Compiled,
    dt: float,
    per_sample: int,
    samples: int,
    paths: Sequence[str] | None,
    reference: Sequence[np.ndarray] | None = None,
    limit: float = math.inf,
) -> _Run:
    """Run ``samples`` x ``per_sample`` steps, sampling points and energy in between. The run stops
    as diverged when a state stops being finite, or when a point is farther than ``limit`` from
    its place in ``reference`` (from its initial place without a reference)."""
    sim = compiled.instantiate()
    sim.dt = dt
    chosen = list(paths) if paths is not None else sim.objects()
    built = compiled.built
    run = _Run([], [], [], 0, 0.0, built.seconds, built.cached)

    def sample() -> None:
        run.points.append(_points(sim, chosen))
        energy = sim.energy()
        run.energy.append(energy.total)
        run.kinetic.append(energy.kinetic)

    sample()
    for k in range(1, samples + 1):
        started = time.perf_counter()
        try:
            sim.step(per_sample)
        except SimulationDiverged as exc:
            run.step_seconds += time.perf_counter() - started
            run.diverged_time = float(exc.time)
            # The exception counts the steps of the failing call: made global from the time reached.
            run.diverged_step = max(1, round(exc.time / dt))
            run.diverged_reason = "non-finite state"
            run.steps = run.diverged_step
            return run
        run.step_seconds += time.perf_counter() - started
        run.steps += per_sample
        sample()
        target = reference[k] if reference is not None else run.points[0]
        distance = np.linalg.norm(run.points[-1] - target, axis=1)
        if distance.size and not float(distance.max()) <= limit:
            run.diverged_step = run.steps
            run.diverged_time = run.steps * dt
            run.diverged_reason = (
                "non-finite state"
                if not np.isfinite(distance).all()
                else f"blew up (error > {BLOWUP:g} x size)"
            )
            return run
    if run.step_seconds < MIN_TIMED_SECONDS:
        run.step_seconds = min(run.step_seconds, _timed_runs(compiled, dt, run.steps))
    return run


# --- the sweep ---------------------------------------------------------------------------------


def _steps_per(interval: float, dt: float, what: str) -> int:
    ratio = interval / dt
    count = round(ratio)
    if count < 1 or abs(ratio - count) > 1e-9 * ratio:
        raise AccuracyError(
            f"{what} dt={dt:g} does not divide the sampling interval {interval:g}: "
            "choose time steps that divide the largest one (e.g. halvings), or set the sampling interval"
        )
    return count


def load_analytic(scene: str | Path) -> AnalyticSolution:
    """The analytic solution a scene declares: ``positions(t)`` of the file ``<scene>.analytic.py``.

    The file is Python, executed only when asked for (``reference="analytic"``).
    """
    path = Path(scene)
    sidecar = path.with_name(path.name + ".analytic.py")
    if not sidecar.is_file():
        sidecar = path.with_suffix(".analytic.py")
    if not sidecar.is_file():
        raise AccuracyError(f"{path} declares no analytic solution (no {path.with_suffix('.analytic.py')})")
    spec = importlib.util.spec_from_file_location(f"_sofac_analytic_{path.stem}", sidecar)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    function = getattr(module, "positions", None)
    if not callable(function):
        raise AccuracyError(f"{sidecar} defines no function positions(t)")
    return function  # type: ignore[no-any-return]


def _parse_reference(spec: str, smallest_dt: float) -> Configuration:
    """``SOLVER``, ``SOLVER@DT`` or ``SOLVER@/N`` (N-th of the smallest dt; default N = 16)."""
    solver_text, _, dt_text = spec.partition("@")
    solver = Solver.parse(solver_text)
    if not dt_text:
        return Configuration(solver, smallest_dt / REFERENCE_DIVISOR)
    try:
        dt = smallest_dt / float(dt_text[1:]) if dt_text.startswith("/") else float(dt_text)
    except ValueError:
        raise AccuracyError(f"bad reference {spec!r}: use SOLVER@DT or SOLVER@/N") from None
    if not dt > 0 or not math.isfinite(dt):
        raise AccuracyError(f"bad reference {spec!r}: dt must be > 0")
    return Configuration(solver, dt)


def _record(config: Configuration, run: _Run | None, error: str = "") -> Record:
    nan = math.nan
    solver = config.solver
    base = {
        "solver": solver.label,
        "integrator": solver.kind,
        "dt": config.dt,
        "cg_iterations": solver.iterations,
        "cg_tolerance": solver.tolerance,
    }
    if run is None:
        return Record(
            **base,
            steps=0,
            max_error=nan,
            rms_error=nan,
            energy_drift=nan,
            energy_drift_max=nan,
            wall_per_sim_second=nan,
            step_seconds=0.0,
            compile_seconds=0.0,
            cached=False,
            error=error,
        )
    simulated = run.steps * config.dt
    return Record(
        **base,
        steps=run.steps,
        max_error=nan,
        rms_error=nan,
        energy_drift=nan,
        energy_drift_max=nan,
        wall_per_sim_second=run.step_seconds / simulated if simulated > 0 else nan,
        step_seconds=run.step_seconds,
        compile_seconds=run.compile_seconds,
        cached=run.cached,
        diverged=run.diverged_step is not None,
        diverged_step=run.diverged_step,
        diverged_time=run.diverged_time,
        diverged_reason=run.diverged_reason,
    )


def _errors(run: _Run, reference: Sequence[np.ndarray], size: float) -> tuple[float, float]:
    if len(run.points) != len(reference):
        return math.nan, math.nan
    if len(run.points) < 2:
        return 0.0, 0.0
    mine = np.stack(run.points[1:])
    theirs = np.stack(list(reference[1:]))
    if mine.shape != theirs.shape:
        raise AccuracyError(f"the configurations have different states ({mine.shape} vs {theirs.shape})")
    distance = np.linalg.norm(mine - theirs, axis=2)
    if not np.isfinite(distance).all():
        return math.inf, math.inf
    return float(distance.max() / size), float(math.sqrt(float(np.mean(distance**2))) / size)


def _energy_drift(run: _Run, scale: float) -> tuple[float, float]:
    if not run.energy or not scale > 0:
        return math.nan, math.nan
    energy = np.asarray(run.energy)
    change = energy - energy[0]
    return float(change[-1] / scale), float(np.abs(change).max() / scale)


def _scene_size(initial: np.ndarray, trajectory: Sequence[np.ndarray]) -> float:
    """Bounding-box diagonal of the initial points; of the whole trajectory if they coincide."""
    for points in (initial, np.concatenate(list(trajectory)) if trajectory else initial):
        if len(points):
            diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
            if diagonal > 0 and math.isfinite(diagonal):
                return diagonal
    return 1.0


@dataclass
class _Setup:
    """A sweep's set-up, validated: the scene model, what to run, when to sample, the reference."""

    path: Path
    model: Scene
    configs: list[Configuration]
    interval: float
    samples: int
    keep_rayleigh: bool
    rayleigh: str  # SweepInfo.rayleigh
    reference: list[Configuration]  # candidates in order (fallbacks after the first); empty if analytic
    analytic: AnalyticSolution | None
    notes: list[str]
    compiled: dict[Solver, Compiled | str] = field(default_factory=dict)

    def per_sample(self, config: Configuration) -> int:
        return _steps_per(self.interval, config.dt, config.solver.label)

    def build(self, solver: Solver) -> Compiled | str:
        """The compiled variant, or why it could not be compiled (compiled once per solver)."""
        if solver not in self.compiled:
            try:
                self.compiled[solver] = compile_variant(self.model, solver, keep_rayleigh=self.keep_rayleigh)
            except scene_warnings.StrictSceneError:
                raise  # the scene's own warnings under --strict: no configuration can run
            except SofacError as exc:
                self.compiled[solver] = f"{type(exc).__name__}: {exc}"
        return self.compiled[solver]


def _set_up(
    path: Path,
    *,
    solvers: Sequence[str],
    dts: Sequence[float] | None,
    duration: float,
    linear_solvers: Sequence[str],
    cg_iterations: Sequence[int],
    tolerances: Sequence[float],
    cg_threshold: float | None,
    reference: str | AnalyticSolution | None,
    rayleigh: str,
    sample_interval: float | None,
    data_roots: Sequence[Path],
) -> _Setup:
    if not path.is_file():
        raise AccuracyError(f"no such scene: {path}")
    if rayleigh not in ("auto", "keep", "remove"):
        raise AccuracyError(f"rayleigh must be auto, keep or remove, not {rayleigh!r}")
    if not duration > 0 or not math.isfinite(duration):
        raise AccuracyError("the duration must be > 0")
    model = _parse(path, [path.resolve().parent, *data_roots])
    settings = expand_solvers(solvers, linear_solvers, cg_iterations, tolerances, cg_threshold)
    if dts is None:
        scene_dt = float(model.root.get("dt") or 0.01)
        dts = [scene_dt * f for f in (2.0, 1.0, 0.5, 0.25)]
    steps = sorted({float(dt) for dt in dts}, reverse=True)
    if not steps or any(not dt > 0 or not math.isfinite(dt) for dt in steps):
        raise AccuracyError("time steps must be > 0")
    interval = float(sample_interval) if sample_interval is not None else steps[0]
    if not interval > 0 or not math.isfinite(interval):
        raise AccuracyError("the sampling interval must be > 0")
    configs = [Configuration(s, dt) for s in settings for dt in steps]

    notes: list[str] = []
    damped = scene_rayleigh(model)
    explicit = any(not s.implicit for s in settings)
    keep = damped and (rayleigh == "keep" or (rayleigh == "auto" and not explicit))
    if damped and not keep:
        notes.append(
            "Rayleigh damping removed from the scene's implicit solver: the explicit solvers have "
            "none, so every configuration integrates the same undamped equations"
        )
    elif keep and explicit:
        notes.append("Rayleigh damping kept on the implicit solvers only: explicit solvers run undamped")

    analytic: AnalyticSolution | None = None
    candidates: list[Configuration] = []
    if callable(reference):
        analytic = reference
    elif reference == "analytic":
        analytic = load_analytic(path)
    elif reference is None:
        finest = steps[-1] / REFERENCE_DIVISOR
        direct = Configuration(Solver("implicit-direct"), finest)
        candidates = [direct] if keep else [Configuration(Solver("rk4"), finest), direct]
    else:
        candidates = [_parse_reference(reference, steps[-1])]
    setup = _Setup(
        path=path,
        model=model,
        configs=configs,
        interval=interval,
        samples=max(1, round(duration / interval)),
        keep_rayleigh=keep,
        rayleigh="none" if not damped else ("kept" if keep else "removed"),
        reference=candidates,
        analytic=analytic,
        notes=notes,
    )
    for config in [*configs, *candidates]:
        setup.per_sample(config)  # every dt must divide the sampling interval
    return setup


@dataclass
class _Reference:
    label: str
    points: list[np.ndarray]
    paths: list[str] | None  # the compared states (None: all)
    size: float
    energy_scale: float  # NaN until known (analytic)
    record: Record | None


def _numeric_reference(setup: _Setup, bar: Progress) -> _Reference:
    """Run the reference candidates in turn until one does not diverge."""
    for candidate in setup.reference:
        bar.start(f"reference {candidate.label}")
        built = setup.build(candidate.solver)
        if isinstance(built, str):
            setup.notes.append(f"the reference {candidate.label} cannot be compiled: {built}")
            continue
        probe = built.instantiate()
        start = _points(probe, probe.objects())
        extent = float(np.linalg.norm(start.max(axis=0) - start.min(axis=0))) if len(start) else 0.0
        limit = REFERENCE_BLOWUP * extent if extent > 0 else math.inf
        run = _run(built, candidate.dt, setup.per_sample(candidate), setup.samples, None, None, limit)
        if run.diverged_step is not None:
            setup.notes.append(f"the reference {candidate.label} diverged at step {run.diverged_step}")
            continue
        if candidate is not setup.reference[0]:
            setup.notes.append(f"reference fell back to {candidate.label}")
        record = _record(candidate, run)
        record.max_error = record.rms_error = 0.0
        scale = max(run.kinetic)
        record.energy_drift, record.energy_drift_max = _energy_drift(run, scale)
        bar.advance(f"reference {candidate.label}")
        size = _scene_size(run.points[0], run.points)
        return _Reference(candidate.label, run.points, None, size, scale, record)
    tried = ", ".join(c.label for c in setup.reference)
    raise AccuracyError(
        f"no reference run ({tried}): {'; '.join(setup.notes[-len(setup.reference) :])}; "
        "pass reference='SOLVER@DT' with a configuration that compiles and stays stable"
    )


def _analytic_reference(setup: _Setup, solution: AnalyticSolution) -> _Reference:
    probe = next((b for c in setup.configs if not isinstance(b := setup.build(c.solver), str)), None)
    if probe is None:
        raise AccuracyError("no configuration compiles")
    sim = probe.instantiate()
    paths, _ = _analytic_points(solution, 0.0, sim)
    points = [_analytic_points(solution, k * setup.interval, sim)[1] for k in range(setup.samples + 1)]
    size = _scene_size(_points(sim, paths), points)
    return _Reference("analytic", points, paths, size, math.nan, None)


def sweep(
    scene: str | Path,
    *,
    solvers: Sequence[str] = DEFAULT_SOLVERS,
    dts: Sequence[float] | None = None,
    duration: float = 1.0,
    linear_solvers: Sequence[str] = LINEAR_SOLVERS,
    cg_iterations: Sequence[int] = DEFAULT_CG_ITERATIONS,
    tolerances: Sequence[float] = DEFAULT_TOLERANCES,
    cg_threshold: float | None = None,
    reference: str | AnalyticSolution | None = None,
    rayleigh: str = "auto",
    sample_interval: float | None = None,
    data_roots: Sequence[Path] = (),
    progress: bool = False,
) -> Sweep:
    """Run ``scene`` under every solver x dt and measure each against a reference (see the module).

    ``solvers``: names from ``euler, symplectic, rk2, rk4, implicit`` (``implicit`` expands over
    ``linear_solvers`` ``cg``/``direct``, CG over ``cg_iterations`` x ``tolerances``), or labels
    such as ``implicit-cg:50:1e-8``; ``cg_threshold`` is CG's absolute threshold on p.Ap (default
    1e-30: negligible, see CG_THRESHOLD; labels show it when given). ``dts`` default to the scene's
    dt x (2, 1, 1/2, 1/4).
    ``duration`` is rounded to a whole number of sampling intervals (at least one).
    ``reference``: None (default, see the module), ``"analytic"``, ``"SOLVER@DT"`` / ``"SOLVER@/N"``
    or a callable ``t -> {state: positions}``.
    ``rayleigh``: ``keep`` the scene's Rayleigh damping on implicit Euler, ``remove`` it, or
    ``auto``: remove it when explicit solvers take part (they have none, so all configurations
    solve the same equations), else keep it.
    ``progress``: show a progress bar on stderr.
    """
    setup = _set_up(
        Path(scene),
        solvers=solvers,
        dts=dts,
        duration=duration,
        linear_solvers=linear_solvers,
        cg_iterations=cg_iterations,
        tolerances=tolerances,
        cg_threshold=cg_threshold,
        reference=reference,
        rayleigh=rayleigh,
        sample_interval=sample_interval,
        data_roots=data_roots,
    )
    bar = Progress(len(setup.configs) + len(setup.reference[:1]), progress)
    records: list[Record] = []
    runs: list[_Run | None] = []
    try:
        if setup.analytic is not None:
            ref = _analytic_reference(setup, setup.analytic)
        else:
            ref = _numeric_reference(setup, bar)
        for config in setup.configs:
            bar.start(config.label)
            built = setup.build(config.solver)
            run = None
            if isinstance(built, str):
                record = _record(config, None, built)
            else:
                per_sample = setup.per_sample(config)
                run = _run(
                    built, config.dt, per_sample, setup.samples, ref.paths, ref.points, BLOWUP * ref.size
                )
                record = _record(config, run)
                if not record.diverged:
                    record.max_error, record.rms_error = _errors(run, ref.points, ref.size)
            records.append(record)
            runs.append(run)
            bar.advance(config.label)
    finally:
        bar.close()

    if math.isnan(ref.energy_scale):
        # Analytic reference: the peak kinetic energy of the most accurate configuration.
        ranked = sorted(
            (r.max_error, i) for i, r in enumerate(records) if r.ok and math.isfinite(r.max_error)
        )
        best = runs[ranked[0][1]] if ranked else None
        ref.energy_scale = max(best.kinetic) if best is not None else math.nan
    for record, run in zip(records, runs, strict=True):
        if run is not None and not record.diverged:
            record.energy_drift, record.energy_drift_max = _energy_drift(run, ref.energy_scale)

    info = SweepInfo(
        scene=str(scene),
        duration=setup.samples * setup.interval,
        sample_interval=setup.interval,
        samples=setup.samples,
        scene_size=ref.size,
        reference=ref.label,
        energy_scale=ref.energy_scale,
        rayleigh=setup.rayleigh,
        notes=setup.notes,
    )
    return Sweep(records, info, ref.record)


# --- results -----------------------------------------------------------------------------------


def columns(records: Iterable[Record]) -> dict[str, list[Any]]:
    """The records as a dict of columns (``pandas.DataFrame(columns(records))`` makes a frame)."""
    names = [f.name for f in dataclasses.fields(Record)]
    table: dict[str, list[Any]] = {name: [] for name in names}
    for record in records:
        for name in names:
            table[name].append(getattr(record, name))
    return table


def measured_orders(records: Iterable[Record]) -> dict[str, float]:
    """Per solver, the slope of log(max error) against log(dt): its measured order of convergence
    (least squares over its configurations that ran, with a finite non-zero error; at least two dts)."""
    points: dict[str, list[tuple[float, float]]] = {}
    for record in records:
        if record.ok and math.isfinite(record.max_error) and record.max_error > 0:
            points.setdefault(record.solver, []).append((math.log(record.dt), math.log(record.max_error)))
    orders: dict[str, float] = {}
    for solver, pairs in points.items():
        if len({x for x, _ in pairs}) >= 2:
            x, y = np.array(pairs).T
            orders[solver] = float(np.polyfit(x, y, 1)[0])
    return orders


def _fmt(value: float | None, spec: str = ".2e") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return format(value, spec)


def _status(record: Record) -> str:
    if record.error:
        return "failed"
    if record.diverged:
        how = "" if record.diverged_reason in ("", "non-finite state") else ", blew up"
        return f"diverged at step {record.diverged_step} (t={record.diverged_time:g}{how})"
    return "ok"


def _row(record: Record, status: str) -> tuple[str, ...]:
    return (
        record.solver,
        f"{record.dt:g}",
        _fmt(record.max_error),
        _fmt(record.rms_error),
        _fmt(record.energy_drift, "+.2e"),
        _fmt(record.wall_per_sim_second, ".3g"),
        "cached" if record.cached else _fmt(record.compile_seconds, ".1f"),
        status,
    )


def format_table(result: Sweep) -> str:
    """The sweep as a text table, with its set-up above and the measured orders below."""
    info = result.info
    lines = [
        f"scene {info.scene}: {info.samples} samples every {info.sample_interval:g} s to "
        f"t={info.duration:g}; scene size {info.scene_size:.4g}; reference {info.reference}",
    ]
    lines.extend(f"note: {note}" for note in info.notes)
    header = ("solver", "dt", "max err", "rms err", "E drift", "wall/sim s", "compile s", "status")
    rows = [_row(result.reference, "reference")] if result.reference is not None else []
    rows.extend(_row(r, _status(r)) for r in result)
    widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(header)]
    numeric = range(1, 7)

    def line(cells: Sequence[str]) -> str:
        out = [
            c.rjust(w) if i in numeric else c.ljust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ]
        return "  ".join(out).rstrip()

    lines.append(line(header))
    lines.append("  ".join("-" * w for w in widths))
    lines.extend(line(row) for row in rows)
    failures = {r.solver: r.error.splitlines()[0] for r in result if r.error}
    lines.extend(f"failed {solver}: {error}" for solver, error in failures.items())
    orders = result.orders()
    if orders:
        text = ", ".join(f"{solver} {order:.2f}" for solver, order in orders.items())
        lines.append(f"order of convergence (slope of log max error vs log dt): {text}")
    lines.append(
        "errors: position error / scene size, max and RMS over all points and samples; E drift: "
        "(E(T) - E(0)) / peak kinetic energy of the reference; wall/sim s: seconds of stepping "
        "per simulated second"
    )
    return "\n".join(lines) + "\n"


def markdown_table(result: Sweep, *, collapse_diverged: bool = False) -> str:
    """The sweep's rows as a Markdown table (the reference first), then the measured orders.

    With ``collapse_diverged``, the configurations that diverged are listed below the table, one
    line per solver ("dt (step)"), instead of as rows.
    """
    header = ("solver", "dt", "max err", "rms err", "E drift", "wall/sim s", "compile s", "status")
    rows = [_row(result.reference, "reference")] if result.reference is not None else []
    shown = [r for r in result if not (collapse_diverged and r.diverged)]
    rows.extend(_row(r, "failed" if r.error else _status(r)) for r in shown)
    lines = [
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" if i in (0, 7) else "---:" for i in range(len(header))) + "|",
    ]
    lines.extend(
        "| " + " | ".join(f"`{c}`" if i == 0 else c for i, c in enumerate(row)) + " |" for row in rows
    )
    diverged: dict[str, list[str]] = {}
    for record in result:
        if collapse_diverged and record.diverged:
            diverged.setdefault(record.solver, []).append(f"{record.dt:g} (step {record.diverged_step})")
    if diverged:
        lines.append("")
        lines.append(
            "Diverged, at dt (step): " + "; ".join(f"`{s}` {', '.join(d)}" for s, d in diverged.items()) + "."
        )
    orders = result.orders()
    if orders:
        lines.append("")
        lines.append(
            "Measured orders (slope of log max error against log dt): "
            + ", ".join(f"`{solver}` **{order:.2f}**" for solver, order in orders.items())
            + "."
        )
    return "\n".join(lines) + "\n"


def _plain(value: Any) -> Any:
    """JSON has no NaN or infinity: they become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def as_dict(result: Sweep) -> dict[str, Any]:
    return _plain(
        {
            **dataclasses.asdict(result.info),
            "orders": result.orders(),
            "reference_run": dataclasses.asdict(result.reference) if result.reference else None,
            "records": [dataclasses.asdict(r) for r in result],
        }
    )


def write_json(result: Sweep, path: str | Path) -> Path:
    target = Path(path)
    target.write_text(json.dumps(as_dict(result), indent=2) + "\n", encoding="utf-8")
    return target


def write_csv(records: Iterable[Record], path: str | Path) -> Path:
    target = Path(path)
    table = columns(records)
    with target.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(table)
        for row in zip(*table.values(), strict=True):
            writer.writerow(["" if v is None else v for v in row])
    return target


_LABEL = re.compile(r"^[a-z0-9-]+")


def solver_family(label: str) -> str:
    """``implicit-cg:25:1e-05`` -> ``implicit-cg`` (the integrator part of a solver label)."""
    match = _LABEL.match(label)
    return match.group(0) if match else label
