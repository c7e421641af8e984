"""Load stage and the Python simulation API: ``sim = sofac.load("scene.scn")``.

A scene compiled by the pipeline (``sofac.pipeline``: checked, planned, generated and built, or
taken from the cache) is instantiated through the host module with its buffers (positions,
parameters, spring lists...). States and parameters are numpy views of the native instance:
writing into them changes the simulation.
"""

from __future__ import annotations

import contextlib
import importlib.util
import sys
import threading
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import IO, TYPE_CHECKING, Any, NamedTuple

import numpy as np
from sofac import param_rules, paths
from sofac.build import compiler as build
from sofac.diagnostics import Diagnostic, SofacError
from sofac.simulation.runspec import RunSpec

if TYPE_CHECKING:  # the front end is imported only when a scene is compiled (not for warm loads)
    from sofac.plan import ir as plan

_host: ModuleType | None = None
_host_built: build.Built | None = None  # the cache entry _host was loaded from


class PrunedEffectError(SofacError):
    """A run-time change that needs code the compiler left out (e.g. gravity on a zero-gravity scene)."""


class ParameterNeedsReset(SofacError):
    """A parameter read only when the simulation is initialised was changed between steps."""


class ContactWarning(UserWarning):
    """A compiled contact pipeline saw something the run's user should know: a buffer that outgrew
    the capacity reserved at init (the step then allocated), detection outputs SOFA would have made
    of NaN or of a zero distance, or a model that moved farther in one step than the detection's
    reach while near a partner (a contact may have been missed: tunnelling; reduce dt)."""


class ContactNotCompiled(SofacError):
    """Two collision models could touch, and sofac does not compile contact response yet: the
    simulation stopped before the step that SOFA would have run with a contact (see plan.ContactGuard)."""


Snapshot = dict[str, tuple[np.ndarray, np.ndarray]]  # state path -> (position, velocity) copies


class SimulationDiverged(SofacError):
    """A simulation stopped being finite, or its energy grew past a bound (see ``Simulation.step``).

    ``reason`` is ``"non-finite"`` (the step's guard found a NaN or infinity in an independent
    state's position or velocity) or ``"energy"`` (the total energy passed a bound set with
    ``step(n, energy_bound=...)`` or ``guard_energy(factor)``). Where it happened:

    * ``step``: the failing step, counted from the creation or the last ``reset()`` (1 = the first
      step ever run); ``time``: the simulation time after it (``sim.time``).
    * ``state``: the path of the state that failed (the first in traversal order); ``dof``: the
      first non-finite DOF (row) of that state, and ``field``: ``"position"``, ``"velocity"`` or
      ``"position and velocity"``. For an energy failure, the state and DOF with the largest speed.
    * ``solver``: the ODE solver of that state (``Type 'path' (file:line)``), ``hint``: what to try.
    * ``energy``/``bound``: the total energy and the bound it passed (energy failures only).

    The simulation's arrays hold the failing step's values: the compiled step stops right after
    the step whose state stopped being finite. ``last_finite`` ({state path: (position, velocity)},
    copies of the independent states) is the last state that was finite (and within the energy
    bound, if one was set), at ``last_finite_step`` / ``last_finite_time``: the chunk that failed
    is run again from its start to find it (``Simulation.restore_last_finite()`` puts it back into
    the live arrays). It is None when the state was not finite before the call (or snapshots are
    switched off).
    """

    def __init__(
        self,
        message: str,
        *,
        step: int,
        time: float,
        state: str,
        reason: str = "non-finite",
        dof: int | None = None,
        field: str = "",
        solver: str = "",
        hint: str = "",
        energy: float | None = None,
        bound: float | None = None,
        last_finite: Snapshot | None = None,
        last_finite_step: int | None = None,
        last_finite_time: float | None = None,
    ) -> None:
        super().__init__(message)
        self.step = step
        self.time = time
        self.state = state
        self.reason = reason
        self.dof = dof
        self.field = field
        self.solver = solver
        self.hint = hint
        self.energy = energy
        self.bound = bound
        self.last_finite = last_finite
        self.last_finite_step = last_finite_step
        self.last_finite_time = last_finite_time

    def __reduce__(self) -> tuple[Any, ...]:
        # Keyword-only arguments: rebuild from the attributes (exceptions cross process pools).
        return (_rebuild_diverged, (type(self), str(self), dict(self.__dict__)))


def _rebuild_diverged(cls: type[SimulationDiverged], message: str, attributes: dict[str, Any]) -> Any:
    error = cls.__new__(cls)
    Exception.__init__(error, message)
    error.__dict__.update(attributes)
    return error


def host(known: build.Built | None = None) -> ModuleType:
    """The host extension module (built on first use, then taken from the cache). ``known`` is a
    valid cache entry of it, from a warm record: loading it skips computing the host's cache key,
    which runs the C++ compiler for its version line."""
    global _host, _host_built
    if _host is None:
        built = known if known is not None else build.build_host()
        spec = importlib.util.spec_from_file_location("_sofac_host", built.library)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules.setdefault("_sofac_host", module)
        _host, _host_built = module, built
    return _host


def host_built() -> build.Built | None:
    """The cache entry of the host module loaded in this process (None before the first load)."""
    return _host_built


class _EnergyGuard(NamedTuple):
    factor: float
    scale: float
    start: float  # the total energy when the guard was set


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
    """One MechanicalObject of a running simulation; arrays are views of the native state.

    A mapped state that nothing in the step reads (``Group.unread`` in the plan) is left out of the
    compiled step: reading its ``position`` or ``velocity`` first maps it from its parents (at most
    once per step() or reset()), with the numbers the step would have computed. An array kept from
    an earlier read is brought up to date only by the next read of either attribute."""

    def __init__(
        self,
        info: StateInfo,
        position: np.ndarray,
        velocity: np.ndarray,
        force: np.ndarray,
        update: Callable[[], None] | None = None,
    ) -> None:
        self.info = info
        self._position = position
        self._velocity = velocity
        self.force = force
        self._update = update  # maps the states the step leaves out, when they are stale

    @property
    def position(self) -> np.ndarray:
        if self._update is not None:
            self._update()
        return self._position

    @property
    def velocity(self) -> np.ndarray:
        if self._update is not None:
            self._update()
        return self._velocity

    def __repr__(self) -> str:
        return f"<State {self.info.path} {self.info.template} x{self.info.size}>"


class _EnergyFile:
    """VariationalSymplecticSolver's energy file: SOFA opens (empties) `file` at init; with
    saveEnergyInFile it writes a CSV header at each step that starts at time 0 and, when the
    Hamiltonian is computed, one line per step (the step's start time and its energies, printed
    as a C++ stream prints them: 6 significant digits)."""

    HEADER = "time,kinetic energy,potential energy, hamiltonian energy\n"

    def __init__(self, path: str, save: bool, lines: bool, energies: np.ndarray, empty: bool = True) -> None:
        self.path = Path(path)
        self.save = save
        self.lines = lines
        self.energies = energies  # (kinetic, potential) of the last step
        try:
            if empty:
                self.path.write_text("")
        except OSError as error:  # SOFA's stream fails silently; sofac says so
            raise SofacError(f"cannot write the energy file {path}: {error}") from error

    def before(self, out: IO[str], start: float) -> None:
        if start == 0.0:
            out.write(self.HEADER)

    def after(self, out: IO[str], start: float) -> None:
        if self.lines:
            kinetic, potential = (float(e) for e in self.energies)
            out.write(f"{start:.6g},{kinetic:.6g},{potential:.6g},{kinetic + potential:.6g}\n")


class Compiled:
    """A compiled scene: its library and run spec; ``instantiate()`` makes independent simulations.

    ``plan``, ``source`` and ``checked`` (the checked scene, for rendering and recompiling) are kept
    when the scene was compiled in this process. A scene taken whole from the cache (``warm.py``)
    has only its run spec and library: they are computed again on first use."""

    #: The Python scene this was compiled from, kept by a warm load (sofac.pyscene), else None.
    python_scene: Any = None

    def __init__(
        self,
        spec: RunSpec,
        built: build.Built,
        *,
        scene_plan: plan.Plan | None = None,
        source: str | None = None,
        checked: Any = None,
        recompute: Callable[[], Compiled] | None = None,
        rebuild: Callable[..., Compiled] | None = None,
        warnings: tuple[Diagnostic, ...] = (),
        known_host: build.Built | None = None,
    ) -> None:
        self.spec = spec
        self.warnings = warnings  # the scene's warnings (sofac check's W codes), issued by load()
        self.built = built
        self._plan, self._source, self._checked = scene_plan, source, checked
        self._recompute = recompute
        # (checked, prune=, rigid_model=, threads=) -> Compiled: the pipeline's compile, for recompile()
        self._rebuild = rebuild
        self.warm = recompute is not None  # taken from a warm record, not compiled in this process
        self._library = host(known_host).Library(str(built.library))

    def _full(self) -> None:
        if self._plan is None:
            assert self._recompute is not None
            full = self._recompute()
            self._plan, self._source, self._checked = full.plan, full.source, full.checked

    @property
    def plan(self) -> plan.Plan:
        self._full()
        assert self._plan is not None
        return self._plan

    @property
    def source(self) -> str:
        self._full()
        assert self._source is not None
        return self._source

    @property
    def checked(self) -> Any:
        self._full()
        return self._checked

    def instantiate(self) -> Simulation:
        # A Python scene's controllers run with it (sofac.pyscene).
        scene = self.python_scene or getattr(self._checked, "scene", None)
        if getattr(scene, "controllers", None):
            from sofac.pyscene.script import instantiate

            return instantiate(self, scene)
        return Simulation(self)


def _put(view: np.ndarray, values: np.ndarray) -> None:
    """``view[:] = values``; for a buffer the step grew since ``values`` were taken (see
    ``Simulation._refit``), the values over its first entries and zeros after them."""
    if view.shape == values.shape:
        np.copyto(view, values)
        return
    flat, given = view.reshape(-1), np.asarray(values).reshape(-1)
    n = min(flat.size, given.size)
    flat[:n] = given[:n]
    flat[n:] = 0


class Simulation:
    """A running instance of a compiled scene."""

    def __init__(self, compiled: Compiled, *, resumed: bool = False) -> None:
        """``resumed``: the instance takes over from another (``recompile()``), so files it
        writes are appended to rather than emptied."""
        self.compiled = compiled
        spec = self.spec = compiled.spec
        initial = [b.initial.copy() for b in spec.buffers]
        self._native = host().create(compiled._library, initial)
        self._views = [self._native.buffer(i, b.kind == "i64") for i, b in enumerate(spec.buffers)]
        self._native.init()
        self._states: dict[str, State] = {}
        for state in spec.states:
            info = StateInfo(
                state.path, state.name, state.mapped, state.template, state.size, state.simulated
            )
            self._states[state.path] = State(
                info,
                self._views[state.x].reshape(-1, state.coord_size),
                self._views[state.v].reshape(-1, state.deriv_size),
                self._views[state.f].reshape(-1, state.deriv_size),
                self._native.update_mapped if state.computed_on_read else None,
            )
        self._solver_of = {s.path: spec.solvers[s.solver] for s in spec.states if s.solver >= 0}
        self._independent = [s for s in self._states.values() if not s.info.mapped]
        self._touching = self._views[spec.contact.touching] if spec.contact else None
        # FreeMotionAnimationLoop's solve report (ir.ConstraintPhase.report): a solve that hit its
        # iteration limit is a warning, as SOFA logs it.
        self._constraint_report = next(
            (
                (b.key, v)
                for b, v in zip(spec.buffers, self._views, strict=True)
                if b.key.endswith(".constraint_report")
            ),
            None,
        )
        self._limited_seen = 0  # solves that hit the limit, already warned about
        self._contact_seen = [np.zeros(4) for _ in spec.contact_reports]  # counters already reported
        self._steps = 0  # steps run since the creation or the last reset()
        self._energy_guard: _EnergyGuard | None = None
        # The buffers a step carries over ("state": positions, velocities, solver history): copied
        # at the start of each chunk, so that a failure can be replayed up to its last good step.
        self._carried = [v for b, v in zip(spec.buffers, self._views, strict=True) if b.role == "state"]
        self._snapshot: list[np.ndarray] | None = None  # preallocated copies, refilled at each chunk
        self._snapshot_step = 0
        self._snapshot_time = 0.0
        self._kept: tuple[list[np.ndarray], int, float] | None = None  # the last good state, if known
        # Parameters read only at init, with the values the instance was initialised with.
        self._init_params = [
            (buffer.key, view)
            for buffer, view in zip(spec.buffers, self._views, strict=True)
            if buffer.key in spec.init_only
        ]
        self._init_values = [view.copy() for _, view in self._init_params]
        self._energy_files = [
            _EnergyFile(f.path, f.save, f.hamiltonian, self._views[f.energies], empty=not resumed)
            for f in spec.energy_files
        ]
        self._saving = [f for f in self._energy_files if f.save]
        # Values set at run time get the rules of their fields (checked when they change).
        self._param_guard = param_rules.ParamGuard(self.params(), spec.rules)
        self._lock = threading.Lock()  # one step (reset...) of this instance at a time

    @property
    def plan(self) -> plan.Plan:
        """The scene's plan (computed again on first use for a scene taken from the warm cache)."""
        return self.compiled.plan

    #: Steps per call of the compiled step: between two chunks, ``step()`` checks the energy bound
    #: (if any) and copies the carried-over state, from which a failure is replayed to find
    #: ``SimulationDiverged.last_finite``.
    chunk: int = 1000
    #: Copy the state at the start of each chunk (``SimulationDiverged.last_finite``).
    keep_last_finite: bool = True

    # --- time ----------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self._native.time)

    @property
    def dt(self) -> float:
        return float(self.param("/.dt")[0])

    @dt.setter
    def dt(self, value: float) -> None:
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise param_rules.InvalidParameter(
                f"E204: /.dt = {value!r} is not a number", key="/.dt", code="E204"
            ) from None
        param_rules.check("/.dt", np.array([number]), self.spec.rules.get("/.dt"))
        self.param("/.dt")[0] = number

    @property
    def steps(self) -> int:
        """Steps run since the simulation was created or last reset."""
        return self._steps

    def step(self, n: int = 1, *, energy_bound: float | None = None) -> None:
        """Advance ``n`` steps (a whole number), in chunks of at most ``chunk`` steps.

        Raises SimulationDiverged when an independent state stops being finite (the compiled step
        checks every step and stops right after the failing one, whose values the arrays then
        hold), or, checked between chunks and at the end, when the total energy exceeds
        ``energy_bound`` or the bound set by ``guard_energy()``.

        Calls from several threads on one instance run one after the other (the native step
        releases the GIL: two at once would corrupt the state); separate instances step in parallel."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
            raise TypeError(f"step(n): n is a whole number of steps, got {type(n).__name__} {n!r}")
        with self._lock:
            self._step(int(n), energy_bound)

    def _step(self, n: int, energy_bound: float | None) -> None:
        if n < 0:
            raise ValueError("n must be >= 0")
        if energy_bound is not None and np.isnan(energy_bound):
            raise ValueError("energy_bound must be a number")
        self._param_guard.check()
        self._check_init_params()
        self._kept = None
        chunk = max(1, int(self.chunk))
        remaining = int(n)
        while remaining > 0:
            count = min(remaining, chunk)
            if self.keep_last_finite:
                self._take_snapshot()
            done = self._step_saving(count) if self._saving else int(self._native.step(count))
            self._refit()
            self._steps += done
            remaining -= count
            if self._touching is not None and self._touching[0] >= 0:
                raise self._contact_error(int(self._touching[0]))
            if self.spec.contact_reports:
                self._report_contacts()
            if done < count or not self._finite():
                raise self._non_finite_error()
            self._warn_unconverged_constraints()
            if energy_bound is not None or self._energy_guard is not None:
                self._check_energy(energy_bound)

    def _warn_unconverged_constraints(self) -> None:
        if self._constraint_report is None:
            return
        key, report = self._constraint_report
        limited = int(report[3])
        if limited > self._limited_seen:
            import warnings

            warnings.warn(
                f"{key.rsplit('.', 1)[0]}: the constraint solver reached its iteration limit in "
                f"{limited - self._limited_seen} solve(s) (last at t={float(report[4])!r}: residual "
                f"{float(report[5])!r}, SOFA's iteration count {int(report[6])}); raise maxIterations or "
                "the tolerance",
                RuntimeWarning,
                stacklevel=4,
            )
            self._limited_seen = limited

    def _step_saving(self, steps: int) -> int:
        """Runs ``steps`` steps one at a time, writing the energy files; returns the number done."""
        done = 0
        with contextlib.ExitStack() as stack:
            outs = [(f, stack.enter_context(f.path.open("a"))) for f in self._saving]
            while done < steps:
                start = float(self._native.time)
                for energy_file, out in outs:
                    energy_file.before(out, start)
                stepped = int(self._native.step(1))
                self._refit()
                if stepped < 1:
                    break
                done += 1
                for energy_file, out in outs:
                    energy_file.after(out, start)
                if not self._finite():
                    break  # step() reports it
        return done

    def _report_contacts(self) -> None:
        """A ContactWarning for each contact counter that grew since it was last reported."""
        what = (
            "time(s) contact buffers outgrew the capacity reserved at init and were grown (that step "
            "allocated; no contact was dropped)",
            "detection outputs were degenerate (NaN dropped, or a zero distance given the normal (1, 0, 0))",
            "times a model moved farther in one step than the detection's reach while near a partner: "
            "contacts may have been missed (tunnelling); reduce dt or raise alarmDistance",
            "contact(s) pushed through in a step (their points crossed over each other along the "
            "contact's normal, e.g. a point through a thin sheet; the penalty then pushes them on "
            "through): raise contactStiffness or contactDistance, or reduce dt",
        )
        for (origin, index), seen in zip(self.spec.contact_reports, self._contact_seen, strict=True):
            counters = self._views[index][[1, 2, 5, 7]]
            for k in np.flatnonzero(counters > seen):
                count = int(counters[k] - seen[k])
                where = f"step {self._steps} (t={self.time:g}), {origin}"
                warnings.warn(ContactWarning(f"{where}: {count} {what[k]}"), stacklevel=4)
            seen[:] = np.maximum(seen, counters)

    def _contact_error(self, pair: int) -> ContactNotCompiled:
        contact = self.spec.contact
        assert contact is not None
        a, b = (int(i) for i in self.spec.buffers[contact.pairs].initial.reshape(-1, 2)[pair])
        return ContactNotCompiled(
            f"step {self._steps + 1} (t={self.time:g}): collision models {contact.models[a]} and "
            f"{contact.models[b]} could touch (their boxes come within SOFA's proximity distance); "
            f"sofac does not compile contact response yet, so it stopped before this step instead of "
            f"running it without the contact. The states are those after step {self._steps}."
        )

    def guard_energy(self, factor: float | None, *, scale: float | None = None) -> None:
        """Make ``step()`` raise SimulationDiverged when the total energy gains more than
        ``factor`` x ``scale`` over its value now (checked between chunks and after each call).

        ``scale`` defaults to the energy scale now, |kinetic| + |potential|. Without external
        work, an implicit solver never gains energy, so a small factor catches a slow blow-up
        before it reaches infinity; ``guard_energy(None)`` switches the guard off. The bound is
        fixed when set (``reset()`` keeps it)."""
        if factor is None:
            self._energy_guard = None
            return
        if not (np.isfinite(factor) and factor > 0):
            raise ValueError(f"factor must be a positive number, got {factor!s}")
        energy = self.energy()
        if scale is None:
            scale = abs(energy.kinetic) + abs(energy.potential)
            if not (np.isfinite(scale) and scale > 0):
                raise ValueError(f"the energy scale is {scale:g} now; give guard_energy(factor, scale=...)")
        elif not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive number, got {scale!s}")
        self._energy_guard = _EnergyGuard(float(factor), float(scale), energy.total)

    # --- the divergence guard ------------------------------------------------------------------
    def _refit(self) -> None:
        """After a step: the views of the buffers it grew (``RunSpec.growable``: the Lagrangian
        contacts' constraint problem, past its reserved rows) taken again, in every list holding
        them (views taken before by the caller stay readable, with the values before the growth)."""
        for i in self.spec.growable:
            old = self._views[i]
            view = self._native.buffer(i, False)
            if view.size == old.size:
                continue
            self._views[i] = view
            self._carried = [view if v is old else v for v in self._carried]

    def _take_snapshot(self) -> None:
        if self._snapshot is None:
            self._snapshot = [view.copy() for view in self._carried]
        else:
            for k, (copy, view) in enumerate(zip(self._snapshot, self._carried, strict=True)):
                if copy.shape == view.shape:
                    np.copyto(copy, view)
                else:  # a buffer the step grew (_refit)
                    self._snapshot[k] = view.copy()
        self._snapshot_step = self._steps
        self._snapshot_time = self.time

    def _replay(self, limit: float | None) -> None:
        """Find the last good state of the chunk that failed: finite, and with a total energy at
        most ``limit`` if given. The chunk is run again from its snapshot, one step at a time; the
        live arrays get the failing step's values back. If the replay does not end on the very
        values of the failure (a step that depends on more than the carried state), the snapshot
        itself is kept, when it was good."""
        self._kept = None
        if self._snapshot is None or not self.keep_last_finite:
            return
        failing = [view.copy() for view in self._carried]
        failing_time, failing_steps = self._native.time, self._steps

        def good() -> bool:
            return self._finite() and (limit is None or self.energy().total <= limit)

        def copies() -> tuple[list[np.ndarray], int, float]:
            return [view.copy() for view in self._carried], steps, float(self._native.time)

        for view, copy in zip(self._carried, self._snapshot, strict=True):
            _put(view, copy)
        self._native.time = self._snapshot_time
        steps = self._snapshot_step
        kept = copies() if good() else None
        start = kept
        while steps < failing_steps and int(self._native.step(1)) == 1:
            self._refit()
            steps += 1
            if steps < failing_steps and kept is not None and kept[1] == steps - 1 and good():
                kept = copies()
        faithful = steps == failing_steps and all(
            np.array_equal(view, copy, equal_nan=True)
            for view, copy in zip(self._carried, failing, strict=True)
        )
        for view, copy in zip(self._carried, failing, strict=True):
            _put(view, copy)
        self._native.time = failing_time
        self._kept = kept if faithful else start

    def _last_finite(self) -> tuple[Snapshot | None, int | None, float | None]:
        if self._kept is None:
            return None, None, None
        copies, step, time = self._kept
        index = {id(view): i for i, view in enumerate(self._carried)}
        states = {}
        for spec in self.spec.states:
            x, v = (index.get(id(self._views[i])) for i in (spec.x, spec.v))
            if not spec.mapped and spec.simulated and x is not None and v is not None:
                states[spec.path] = (
                    copies[x].reshape(-1, spec.coord_size).copy(),
                    copies[v].reshape(-1, spec.deriv_size).copy(),
                )
        return states, step, time

    def restore_last_finite(self) -> int:
        """After SimulationDiverged: put the last good state (``error.last_finite``: finite, and
        within the energy bound if one was set) back into the live arrays, with its time and step
        count, and return that step. Raises SofacError when none is known."""
        if self._kept is None:
            raise SofacError(
                "no finite state is kept to restore: the simulation has not diverged, the state was "
                "not finite before the failing call, or keep_last_finite is off; reset() restarts it"
            )
        copies, step, time = self._kept
        with self._lock:
            for view, copy in zip(self._carried, copies, strict=True):
                _put(view, copy)
            self._native.time = time
            self._steps = step
        return step

    def _solver_and_hint(self, path: str, energy: bool = False) -> tuple[str, str]:
        group = self._solver_of.get(path)
        dt = f"{self.dt:g}"
        if group is None:
            return "", f"try a smaller dt (now {dt}) or an implicit solver"
        solver = group.origin
        if group.scheme != "implicit":
            return solver, (
                f"{group.type_name} is explicit, stable only for small enough steps: try a smaller "
                f"dt (now {dt}) or an implicit solver (EulerImplicitSolver with a CGLinearSolver)"
            )
        if group.direct:
            return solver, (
                f"try a smaller dt (now {dt}); a failed factorisation (a singular or indefinite system "
                "matrix: an inverted element, a stiff spring compressed at a large dt) also gives NaN"
            )
        linear = group.linear_solver or "the linear solver"
        gain = "an unconverged solve can add energy: " if energy else ""
        return solver, (
            f"try a smaller dt (now {dt}); {gain}give {linear} more iterations or a smaller tolerance, "
            "or use a direct solver (SparseLDLSolver)"
        )

    def _non_finite_error(self) -> SimulationDiverged:
        bad = next((s for s in self._independent if not self._state_finite(s)), None)
        path = bad.info.path if bad is not None else "?"
        dof: int | None = None
        where = ""
        if bad is not None:
            x_bad = ~np.isfinite(bad.position).all(axis=1)
            v_bad = ~np.isfinite(bad.velocity).all(axis=1)
            dof = int(np.argmax(x_bad | v_bad))
            where = " and ".join(
                name for name, rows in (("position", x_bad), ("velocity", v_bad)) if rows[dof]
            )
        solver, hint = self._solver_and_hint(path)
        self._replay(None)
        last, last_step, last_time = self._last_finite()
        kept = f"last finite state: step {last_step} (t={last_time:g})" if last is not None else ""
        if last is None and self.keep_last_finite:
            # Nothing to do with the time step: the state came into this call broken.
            hint = (
                "the state was already not finite before this call (a NaN or infinity written into "
                "it, or left by an earlier divergence): reset() restarts the simulation"
            )
        at = f" (DOF {dof}, its {where})" if dof is not None else ""
        under = f" under {solver}" if solver else ""
        message = (
            f"the simulation diverged at step {self._steps} (t={self.time:g}): {path} is no longer "
            f"finite{at}{under}; {hint}" + (f"; {kept}" if kept else "")
        )
        return SimulationDiverged(
            message,
            step=self._steps,
            time=self.time,
            state=path,
            dof=dof,
            field=where,
            solver=solver,
            hint=hint,
            last_finite=last,
            last_finite_step=last_step,
            last_finite_time=last_time,
        )

    def _check_energy(self, energy_bound: float | None) -> None:
        total = self.energy().total
        limits: list[tuple[float, str]] = []
        if energy_bound is not None:
            limits.append((float(energy_bound), "energy_bound"))
        guard = self._energy_guard
        if guard is not None:
            limits.append(
                (
                    guard.start + guard.factor * guard.scale,
                    f"guard_energy: {guard.start:g} + {guard.factor:g} x scale {guard.scale:g}",
                )
            )
        for limit, origin in limits:
            if total <= limit:
                continue
            fastest = self._fastest()
            path, dof, speed = fastest if fastest is not None else ("?", None, 0.0)
            solver, hint = self._solver_and_hint(path, energy=True)
            self._replay(limit)
            last, last_step, last_time = self._last_finite()
            at = f"; the fastest DOF is {path} DOF {dof} (|v| = {speed:g})" if dof is not None else ""
            under = f" under {solver}" if solver else ""
            message = (
                f"the simulation diverged at step {self._steps} (t={self.time:g}): the total energy "
                f"{total:g} exceeds its bound {limit:g} ({origin}){at}{under}; {hint}"
            )
            raise SimulationDiverged(
                message,
                step=self._steps,
                time=self.time,
                state=path,
                reason="energy",
                dof=dof,
                field="velocity" if dof is not None else "",
                solver=solver,
                hint=hint,
                energy=total,
                bound=limit,
                last_finite=last,
                last_finite_step=last_step,
                last_finite_time=last_time,
            )

    def _fastest(self) -> tuple[str, int, float] | None:
        best: tuple[str, int, float] | None = None
        for state in self._independent:
            if not state.velocity.size:
                continue
            speeds = np.linalg.norm(state.velocity, axis=1)
            row = int(np.argmax(speeds))
            if best is None or not speeds[row] <= best[2]:
                best = (state.info.path, row, float(speeds[row]))
        return best

    def _state_finite(self, state: State) -> bool:
        return _all_finite(state.position) and _all_finite(state.velocity)

    def _finite(self) -> bool:
        return all(self._state_finite(s) for s in self._independent)

    def _check_init_params(self) -> None:
        for (key, view), value in zip(self._init_params, self._init_values, strict=True):
            if not np.array_equal(view, value, equal_nan=True):
                raise ParameterNeedsReset(
                    f"{key} was changed after the simulation was initialised, but it is only read then "
                    "(it sets up data such as element stiffnesses): call reset() to restart with the new "
                    "value, or set it back"
                )

    def reset(self) -> None:
        """Back to the initial state and time 0 (tuned parameters are kept, and checked)."""
        with self._lock:
            self._reset()

    def _reset(self) -> None:
        self._param_guard.check()
        for buffer, view in zip(self.spec.buffers, self._views, strict=True):
            if buffer.role in ("state", "scratch"):
                _put(view, buffer.initial)
        self._native.time = 0.0
        self._steps = 0
        self._limited_seen = 0
        self._kept = None
        for seen in self._contact_seen:
            seen[:] = 0.0
        self._native.init()
        self._init_values = [view.copy() for _, view in self._init_params]

    # --- inspection ----------------------------------------------------------------------------
    def objects(self) -> list[str]:
        """Paths of the scene's MechanicalObjects, in SOFA's traversal order."""
        return list(self._states)

    def states(self) -> list[StateInfo]:
        return [s.info for s in self._states.values()]

    def __getitem__(self, path: str) -> State:
        """A MechanicalObject by its path (``"/pendulum/dofs"``, ``"pendulum/dofs"``, or its unique
        end, ``"dofs"``: see sofac.paths)."""
        return self._states[paths.resolve(path, self._states, "MechanicalObject")]

    def param(self, key: str, *, recompile: bool = False) -> np.ndarray:
        """A tunable parameter (``"/pendulum/spring.stiffness"``, ``"/.gravity"``, ``"/.dt"``) as a view.

        Parameters read at every step (stiffnesses of springs, masses, gravity, dt) take effect at the
        next step; those turned into data when the simulation is initialized (the element
        stiffnesses from ``youngModulus``/``poissonRatio``: ``plan.init_only``) at the next
        ``reset()``, and ``step()`` raises ParameterNeedsReset if one was changed without it.
        Raises PrunedEffectError for a parameter whose effect was compiled out (zero gravity),
        unless ``recompile``: then the scene is recompiled with every effect kept and the
        simulation goes on from where it is (see ``recompile()``). ``key`` may also be written
        without its leading slash, or by its unique end (``"spring.stiffness"``: see sofac.paths)."""
        params = [b.key for b in self.spec.buffers if b.role == "param"]
        key = paths.resolve(key, [*params, *(k for k in self.spec.pruned if k not in params)], "parameter")
        if key in self.spec.pruned:
            if not recompile:
                raise PrunedEffectError(
                    f"{key}: {self.spec.pruned[key]}, so the compiled step has no code for it and changing "
                    "it would have no effect; use sim.param(key, recompile=True) to recompile with it "
                    "(the state carries over), or load the scene with sofac.load(path, prune=False)"
                )
            self.recompile(prune=False)
        return next(
            view
            for buffer, view in zip(self.spec.buffers, self._views, strict=True)
            if buffer.key == key and buffer.role == "param"
        )

    def recompile(self, *, prune: bool = False) -> None:
        """Recompile the scene (``prune=False``: with the effects it compiled out, such as a zero
        gravity) and go on from the current state: positions, velocities, solver data, time,
        step count and parameters carry over, so the next steps are those of the new code.
        Arrays taken before (``sim[path].position``, ``sim.param(...)``) view the old instance:
        take them again."""
        rebuild = self.compiled._rebuild
        assert rebuild is not None, "a Compiled made by sofac.pipeline can be rebuilt"
        compiled = rebuild(
            self.compiled.checked,
            prune=prune,
            rigid_model=self.spec.rigid_model,
            threads=self.spec.threads,
            interactive=self.spec.interactive,
        )
        fresh = Simulation(compiled, resumed=True)
        now = {
            buffer.key: view
            for buffer, view in zip(self.spec.buffers, self._views, strict=True)
            if buffer.role != "data"
        }
        for buffer, view in zip(fresh.spec.buffers, fresh._views, strict=True):
            old = now.get(buffer.key)
            if buffer.role != "data" and old is not None and old.shape == view.shape:
                view[...] = old
        fresh._native.time = self._native.time
        initialised = dict(zip((key for key, _ in self._init_params), self._init_values, strict=True))
        fresh._init_values = [initialised.get(key, view.copy()) for key, view in fresh._init_params]
        fresh._steps, fresh._energy_guard = self._steps, self._energy_guard
        fresh.chunk, fresh.keep_last_finite = self.chunk, self.keep_last_finite
        self.__dict__.update(fresh.__dict__)

    def output(self, key: str) -> np.ndarray:
        """A read-only view of a value the step computes, such as a VariationalSymplecticSolver's
        ``"/node/solver.hamiltonianEnergy"`` (any buffer restored by reset(): states included; the
        path as sofac.paths reads it)."""
        outputs = {b.key: v for b, v in zip(self.spec.buffers, self._views, strict=True) if b.role == "state"}
        out = outputs[paths.resolve(key, outputs, "output")].view()
        out.flags.writeable = False
        return out

    def params(self) -> dict[str, np.ndarray]:
        return {b.key: v for b, v in zip(self.spec.buffers, self._views, strict=True) if b.role == "param"}

    def render(self, width: int = 640, height: int = 480, camera: Any = None, **options: Any) -> np.ndarray:
        """An off-screen picture (height, width, 3) of the scene's visual models (see sofac.render)."""
        from sofac.render.picture import render

        return render(self, width, height, camera, **options)

    def energy(self) -> Energy:
        kinetic, potential = self._native.energy()
        return Energy(float(kinetic), float(potential))


def _all_finite(array: np.ndarray) -> bool:
    return bool(np.isfinite(array).all())
