"""Parameter sweeps on Dask: one scene, compiled once, run for many parameter sets.

``sofac.sweep(scene, {"spring.stiffness": [10, 100, 1000]}, steps=500, record=["dofs.position"])``
returns an :class:`xarray.Dataset` with one entry per run along the ``run`` dimension, the swept
parameters as coordinates of ``run``, the recorded quantities sampled every ``every`` steps along
``sample`` (with their times in the ``time`` coordinate), and per run its ``status`` ("ok",
"diverged", "failed", or "invalid": a value its field's rule refuses, as in a scene file),
``message``, ``diverged_step`` and ``wall_seconds``.

Runs are Dask tasks (distributed): an embedded ``LocalCluster`` by default (one single-threaded
worker process per core, BLAS pinned to one thread), or any scheduler given by address. A task
gets the scene's path and the run's values, never compiled code: each worker process compiles the
scene into its node's cache (built once per node under a file lock, loaded from it afterwards),
instantiates it, sets the parameters, re-initializes and steps. Tasks whose worker dies are
rerun by Dask; runs that diverge or fail are recorded as such and the others go on.

Results are saved as NetCDF-4 (through xarray and h5netcdf): recorded states are arrays of shape
runs x samples x DOFs x coordinates labelled by the parameters, which a labelled N-dimensional
format keeps as they are and a table (Parquet) would have to flatten into one row per value. While
a sweep runs, each finished run is written to ``OUT.parts/`` at once; a sweep interrupted half-way
and started again with the same arguments continues from there.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import itertools
import json
import logging
import math
import os
import re
import shutil
import socket
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sofac import paths
from sofac.diagnostics import SofacError

STATUSES = ("ok", "diverged", "failed", "invalid")
FIELDS = ("position", "velocity", "force")
ENERGY = "energy"
#: Environment of each worker process: single-threaded BLAS/OpenMP, so that runs neither fight over
#: the cores nor depend on a thread count (results are bit-identical whatever runs where).
PINNED_THREADS = {
    name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
}


class SweepError(SofacError):
    """A sweep that cannot start: a bad parameter, value list, record request or output folder."""


# --- what to vary --------------------------------------------------------------------------------

_RANGE = re.compile(r"^\s*([^:]+):([^:]+)(?::(lin|log))?:(\d+)\s*$")


def parse_values(text: str) -> list[float]:
    """The values of ``--param KEY=VALUES``: a list (``1,2,5``) or a range ``START:STOP[:lin|log]:COUNT``
    (both ends included; ``1e3:1e5:log:3`` is 1e3, 1e4, 1e5)."""
    match = _RANGE.match(text)
    try:
        if match:
            start, stop, spacing, count = match.groups()
            low, high, n = float(start), float(stop), int(count)
            if n < 1:
                raise SweepError(f"bad range {text!r}: COUNT must be at least 1")
            if spacing == "log":
                if low <= 0 or high <= 0:
                    raise SweepError(f"bad range {text!r}: a log range needs positive ends")
                values = np.geomspace(low, high, n)
                values[0], values[-1] = low, high  # exact ends, whatever the rounding of geomspace
            else:
                values = np.linspace(low, high, n)
            return [float(v) for v in values]
        items = [item for item in text.replace(",", " ").split() if item]
        if not items:
            raise SweepError("empty list of values")
        return [float(item) for item in items]
    except ValueError:
        raise SweepError(
            f"bad values {text!r}: give a comma-separated list of numbers (1,2,5) or a range "
            "START:STOP[:lin|log]:COUNT (1e3:1e5:log:3)"
        ) from None


def parse_param(text: str) -> tuple[str, list[float]]:
    """``PATH.FIELD=VALUES`` -> (key, values)."""
    key, sep, values = text.partition("=")
    if not sep or not key.strip():
        raise SweepError(f"bad --param {text!r}: use PATH.FIELD=VALUES, e.g. spring.stiffness=10,100,1000")
    return key.strip(), parse_values(values)


def read_table(path: str | Path) -> list[dict[str, float]]:
    """Parameter sets from a CSV file (a header of keys, a row per run) or a JSON file (a list of
    {key: value} objects, or {key: [values...]} columns of equal length)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise SweepError(f"{path}: cannot read the parameter table ({error.strerror})") from None
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise SweepError(f"{path}:{error.lineno}: not valid JSON ({error.msg})") from None
        if isinstance(data, dict):
            lengths = {len(v) if isinstance(v, list) else -1 for v in data.values()}
            if len(lengths) != 1 or -1 in lengths:
                raise SweepError(f"{path}: a JSON object of columns needs lists of equal length")
            rows = [dict(zip(data, row, strict=True)) for row in zip(*data.values(), strict=True)]
        elif isinstance(data, list) and all(isinstance(row, dict) for row in data):
            rows = data
        else:
            raise SweepError(
                f"{path}: expected a list of {{parameter: value}} objects or an object of columns"
            )
        return [_numeric_row(row, f"{path}: run {i + 1}") for i, row in enumerate(rows)]
    reader = csv.DictReader(text.splitlines())
    if not reader.fieldnames:
        raise SweepError(f"{path}: empty parameter table (the first line names the parameters)")
    return [_numeric_row(row, f"{path}:{reader.line_num}") for row in reader]


def _numeric_row(row: Mapping[str, Any], where: str) -> dict[str, float]:
    out = {}
    for key, value in row.items():
        try:
            out[str(key).strip()] = float(value)
        except (TypeError, ValueError):
            raise SweepError(f"{where}: {key} = {value!r} is not a number") from None
    return out


@dataclass(frozen=True)
class Parameter:
    """A swept number: a tunable parameter of the compiled scene (one component of it for vectors)."""

    key: str  # the simulation's parameter key, "/oscillator/spring.stiffness"
    component: int | None  # index into a vector parameter ("/.gravity[1]"), None for scalars

    @property
    def name(self) -> str:
        """The dataset coordinate: the key without slashes (NetCDF names cannot hold them)."""
        base = self.key.strip("/").replace("/", ".").lstrip(".")
        return base if self.component is None else f"{base}[{self.component}]"


_COMPONENT = re.compile(r"^(.*)\[(\d+)\]$")


def resolve_parameter(text: str, sizes: Mapping[str, int | None]) -> Parameter:
    """Find ``text`` (a full key, a key without the leading slash, or ``component.field`` when the
    component's name is unique) among the scene's tunable parameters ``sizes`` ({key: length})."""
    match = _COMPONENT.match(text.strip())
    base, component = (match.group(1), int(match.group(2))) if match else (text.strip(), None)
    try:
        key = paths.resolve(base, sizes, "tunable parameter")
    except paths.UnknownPath as error:
        raise SweepError(
            f"--param {text}: {error} (fields computed when the scene is compiled, such as meshes or "
            "masses from a density, need one compilation per value: sweep over scene files instead)"
        ) from None
    size = sizes[key]
    if size is None:  # a parameter compiled out (the caller says so): nothing to check its index against
        return Parameter(key, component)
    if component is None and size != 1:
        raise SweepError(f"--param {text}: {key} has {size} components; sweep one with {text}[i]")
    if component is not None and not 0 <= component < size:
        raise SweepError(f"--param {text}: {key} has {size} components (0 to {size - 1})")
    return Parameter(key, component)


# --- what to record ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Record:
    """A recorded quantity: a field of a MechanicalObject (optionally some DOFs), or the energy."""

    state: str  # the state's path, "" for the energy
    field: str  # position, velocity, force, or energy
    dofs: tuple[int, ...] | None = None  # None: every DOF

    @property
    def name(self) -> str:
        if not self.state:
            return ENERGY
        return f"{self.state.strip('/').replace('/', '.')}.{self.field}"


_DOFS = re.compile(r"^(.*)\[([\d,\s]+)\]$")


def resolve_record(text: str, states: Mapping[str, int]) -> Record:
    """``PATH.FIELD[dofs]`` (``/beam/dofs.position``, ``dofs.velocity[10]``, ``energy``) against the
    scene's MechanicalObjects ``states`` ({path: number of DOFs})."""
    text = text.strip()
    if text == ENERGY:
        return Record("", ENERGY)
    match = _DOFS.match(text)
    base, dofs = (match.group(1), match.group(2)) if match else (text, None)
    path, dot, name = base.rpartition(".")
    if not dot or name not in FIELDS:
        raise SweepError(
            f"--record {text}: use PATH.FIELD with FIELD one of {', '.join(FIELDS)} (PATH a "
            f"MechanicalObject: {', '.join(states)}), optionally [DOF,...], or 'energy'"
        )
    try:
        found = paths.resolve(path, states, "MechanicalObject")
    except paths.UnknownPath as error:
        raise SweepError(f"--record {text}: {error}") from None
    selected = None
    if dofs is not None:
        selected = tuple(int(d) for d in dofs.replace(",", " ").split())
        bad = [d for d in selected if d >= states[found]]
        if bad or not selected:
            raise SweepError(f"--record {text}: {found} has DOFs 0 to {states[found] - 1}")
    return Record(found, name, selected)


# --- one run -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """Everything a task needs besides its values: small, picklable, free of compiled code."""

    scene: str  # absolute path, readable on every worker (a shared folder on a real cluster)
    data_roots: tuple[str, ...]
    prune: bool
    rigid_model: str
    parameters: tuple[Parameter, ...]
    records: tuple[Record, ...]
    steps: int
    every: int  # sampling stride in steps; the last step is always sampled
    fingerprint: str  # the compiled scene's (source, initial buffers) hash: same scene everywhere

    def sample_steps(self) -> list[int]:
        steps = list(range(0, self.steps, self.every))
        return [*steps, self.steps] if self.every < self.steps else [0, self.steps]


_compiled: dict[tuple[str, bool, str, tuple[str, ...]], Any] = {}  # per worker process


def _compiled_scene(job: Job) -> Any:
    """The scene compiled in this process (built once per node into its cache, under a file lock)."""
    from sofac.pipeline import compile_scene
    from sofac.scene_warnings import quiet

    key = (job.scene, job.prune, job.rigid_model, job.data_roots)
    if key not in _compiled:
        if not Path(job.scene).is_file():
            raise SweepError(
                f"{job.scene}: no such file on worker host {socket.gethostname()}; workers read the "
                "scene from the same path as the client (put it on a shared folder)"
            )
        with quiet():  # the client issued them when it planned the sweep
            compiled = compile_scene(
                job.scene,
                data_roots=[Path(p) for p in job.data_roots],
                prune=job.prune,
                rigid_model=job.rigid_model,
            )
        if scene_fingerprint(compiled) != job.fingerprint:
            raise SweepError(f"{job.scene} differs on host {socket.gethostname()} from the client's copy")
        _compiled[key] = compiled
    return _compiled[key]


def scene_fingerprint(compiled: Any) -> str:
    digest = hashlib.sha256(compiled.source.encode())
    for buffer in compiled.plan.buffers:
        digest.update(buffer.key.encode())
        digest.update(np.ascontiguousarray(buffer.initial).tobytes())
    return digest.hexdigest()


def run_one(job: Job, values: Sequence[float]) -> dict[str, Any]:
    """Run one parameter set. Never raises: failures come back as ``status``/``message``."""
    from sofac.param_rules import InvalidParameter
    from sofac.simulation.loader import SimulationDiverged

    started = time.perf_counter()
    samples = job.sample_steps()
    out: dict[str, Any] = {"status": "ok", "message": "", "diverged_step": -1}
    arrays: dict[str, np.ndarray] = {}
    times = np.full(len(samples), np.nan)
    try:
        sim = _compiled_scene(job).instantiate()
        for parameter, value in zip(job.parameters, values, strict=True):
            sim.param(parameter.key)[parameter.component or 0] = value
        sim.reset()  # re-initialize: quantities computed at init (FEM stiffness...) see the new values
        for record in job.records:
            arrays[record.name] = np.full((len(samples), *_record_shape(sim, record)), np.nan)
        done = 0
        for index, step in enumerate(samples):
            try:
                sim.step(step - done)
            finally:
                done = step
            times[index] = sim.time
            for record in job.records:
                arrays[record.name][index] = _read(sim, record)
    except SimulationDiverged as error:
        out.update(status="diverged", message=str(error).splitlines()[0], diverged_step=error.step)
    except InvalidParameter as error:  # not run: the others go on
        out.update(status="invalid", message=str(error))
    except Exception as error:  # recorded, never fatal to the sweep: the other runs go on
        out.update(status="failed", message=_describe(error))
    out["wall_seconds"] = time.perf_counter() - started
    out["time"] = times
    out["arrays"] = arrays
    return out


def _describe(error: BaseException) -> str:
    if isinstance(error, SofacError):
        return str(error).splitlines()[0]
    where = traceback.extract_tb(error.__traceback__)[-1:]
    site = f" ({Path(where[0].filename).name}:{where[0].lineno})" if where else ""
    return f"{type(error).__name__}: {error}{site}"


def _record_shape(sim: Any, record: Record) -> tuple[int, ...]:
    if record.field == ENERGY:
        return (2,)
    values = getattr(sim[record.state], record.field)
    count = len(record.dofs) if record.dofs is not None else values.shape[0]
    return (count, values.shape[1])


def _read(sim: Any, record: Record) -> np.ndarray:
    if record.field == ENERGY:
        energy = sim.energy()
        return np.array([energy.kinetic, energy.potential])
    values = getattr(sim[record.state], record.field)
    return values if record.dofs is None else values[list(record.dofs)]


# --- the sweep -----------------------------------------------------------------------------------


@dataclass
class Plan:
    """A sweep ready to run: the job, and the values of every run (rows of ``values``)."""

    job: Job
    values: np.ndarray  # runs x parameters
    grid: tuple[str, ...] = ()  # parameter names forming a full grid (the order of --param), if any
    spacing: dict[str, str] = field(default_factory=dict)  # name -> "log" for log-spaced axes

    def manifest(self) -> dict[str, Any]:
        return {"job": asdict(self.job), "values": self.values.tolist()}


def plan_sweep(
    scene: str | Path,
    params: Mapping[str, Sequence[float]] | None = None,
    *,
    table: Sequence[Mapping[str, float]] | str | Path | None = None,
    steps: int = 100,
    every: int | None = None,
    record: Sequence[str] | None = None,
    data_roots: Sequence[Path] = (),
    prune: bool = True,
    rigid_model: str = "sofa",
) -> Plan:
    """Compile the scene here (errors show before any task starts) and lay out the runs: the full
    grid of ``params`` ({key: values}), times the rows of ``table`` if both are given."""
    from sofac.pipeline import compile_scene

    if steps < 1:
        raise SweepError("steps must be at least 1")
    if every is not None and every < 1:
        raise SweepError("every must be at least 1")
    if not params and table is None:
        raise SweepError("nothing to sweep: give at least one --param KEY=VALUES or a --table")
    path = Path(scene).resolve()
    compiled = compile_scene(path, data_roots=data_roots, prune=prune, rigid_model=rigid_model)
    sim = compiled.instantiate()
    sizes: dict[str, int | None] = {key: int(view.size) for key, view in sim.params().items()}
    sizes.update({key: None for key in compiled.plan.pruned if key not in sizes})  # no buffer: no size

    def resolved(text: str) -> Parameter:
        parameter = resolve_parameter(text, sizes)
        if parameter.key in compiled.plan.pruned:
            raise SweepError(
                f"--param {text}: {compiled.plan.pruned[parameter.key]}, so the compiled step has no code "
                "for it; sweep with prune=False (sofac sweep --no-prune) to keep it"
            )
        return parameter

    columns: list[Parameter] = []
    axes: list[list[float]] = []
    spacing: dict[str, str] = {}
    for text, values in (params or {}).items():
        columns.append(resolved(text))
        axes.append([float(v) for v in values])
        if not axes[-1]:
            raise SweepError(f"--param {text}: no values")
        if _log_spaced(axes[-1]):
            spacing[columns[-1].name] = "log"
    rows: list[list[float]] = [list(combo) for combo in itertools.product(*axes)] if axes else [[]]
    grid = tuple(p.name for p in columns) if table is None else ()
    if table is not None:
        table_rows = read_table(table) if isinstance(table, (str, Path)) else [dict(r) for r in table]
        if not table_rows:
            raise SweepError("the parameter table has no rows")
        keys = list(table_rows[0])
        table_columns = [resolved(k) for k in keys]
        for i, row in enumerate(table_rows):
            if list(row) != keys:
                raise SweepError(f"parameter table row {i + 1} has keys {list(row)}, expected {keys}")
        columns = table_columns + columns
        rows = [[float(r[k]) for k in keys] + grid_row for r in table_rows for grid_row in rows]
    names = [p.name for p in columns]
    if len(set(names)) != len(names):
        raise SweepError(f"a parameter is swept twice: {', '.join(names)}")
    states = {s.path: s.size for s in sim.states()}
    records = tuple(resolve_record(r, states) for r in (record or _default_records(sim)))
    if len({r.name for r in records}) != len(records):
        raise SweepError("a quantity is recorded twice")
    job = Job(
        scene=str(path),
        data_roots=tuple(str(Path(p).resolve()) for p in data_roots),
        prune=prune,
        rigid_model=rigid_model,
        parameters=tuple(columns),
        records=records,
        steps=int(steps),
        every=int(every or steps),
        fingerprint=scene_fingerprint(compiled),
    )
    return Plan(job, np.array(rows, dtype=float).reshape(len(rows), len(columns)), grid, spacing)


def _log_spaced(values: Sequence[float]) -> bool:
    positive = [v for v in values if v > 0]
    return len(positive) == len(values) >= 3 and max(positive) / min(positive) >= 100


def _default_records(sim: Any) -> list[str]:
    return [f"{s.path}.position" for s in sim.states() if not s.mapped]


def sweep(
    scene: str | Path,
    params: Mapping[str, Sequence[float]] | None = None,
    *,
    table: Sequence[Mapping[str, float]] | str | Path | None = None,
    steps: int = 100,
    every: int | None = None,
    record: Sequence[str] | None = None,
    out: str | Path | None = None,
    scheduler: Any = None,
    workers: int | None = None,
    progress: bool = False,
    fresh: bool = False,
    data_roots: Sequence[Path] = (),
    prune: bool = True,
    rigid_model: str = "sofa",
) -> Any:
    """Run ``scene`` for every parameter set and return the results as an xarray Dataset.

    ``params``: {key: values}, swept as a full grid (keys as in ``Simulation.params()``, with or
    without the leading slash, or ``component.field``; ``key[i]`` for one component of a vector).
    ``table``: parameter sets, a list of {key: value} or a CSV/JSON file (see ``read_table``).
    ``steps``: steps per run; ``every``: sample the recorded quantities every that many steps
    (default: only the first and last step). ``record``: ``PATH.FIELD[dofs]`` or ``"energy"``
    (default: the position of every independent MechanicalObject).
    ``scheduler``: None for an embedded LocalCluster (``workers`` processes, default one per
    core), a scheduler address (``"tcp://host:8786"``), a ``distributed.Client``, or
    ``"synchronous"`` to run every task in this process one after the other.
    ``out``: write the dataset there (NetCDF), keeping finished runs in ``OUT.parts/`` meanwhile so
    that an interrupted sweep resumes; ``fresh=True`` discards them.
    """
    plan = plan_sweep(
        scene,
        params,
        table=table,
        steps=steps,
        every=every,
        record=record,
        data_roots=data_roots,
        prune=prune,
        rigid_model=rigid_model,
    )
    return run_plan(plan, out=out, scheduler=scheduler, workers=workers, progress=progress, fresh=fresh)


def run_plan(
    plan: Plan,
    *,
    out: str | Path | None = None,
    scheduler: Any = None,
    workers: int | None = None,
    progress: bool = False,
    fresh: bool = False,
) -> Any:
    parts = _Parts(Path(f"{out}.parts"), plan, fresh) if out is not None else None
    results: dict[int, dict[str, Any]] = parts.load() if parts else {}
    pending = [i for i in range(len(plan.values)) if i not in results]
    from sofac.progress import Progress

    bar = Progress(len(plan.values), progress)
    bar.done = len(results)

    def finished(index: int, result: dict[str, Any]) -> None:
        results[index] = result
        if parts:
            parts.save(index, result)
        bar.advance(_label(plan, index, result))

    try:
        if pending:
            _execute(plan, pending, finished, scheduler, workers)
    finally:
        bar.close()
    dataset = to_dataset(plan, results, resumed=len(plan.values) - len(pending))
    if out is not None:
        write(dataset, Path(out))
        if parts:
            parts.remove()
    return dataset


def _label(plan: Plan, index: int, result: Mapping[str, Any]) -> str:
    values = ", ".join(
        f"{p.name}={v:g}" for p, v in zip(plan.job.parameters, plan.values[index], strict=True)
    )
    return f"{values}: {result['status']}"


def _execute(
    plan: Plan,
    pending: Sequence[int],
    finished: Callable[[int, dict[str, Any]], None],
    scheduler: Any,
    workers: int | None,
) -> None:
    if scheduler == "synchronous":
        for index in pending:
            finished(index, run_one(plan.job, plan.values[index].tolist()))
        return
    from distributed import as_completed

    with _connected(scheduler, workers) as client:
        futures = {
            client.submit(
                run_one,
                plan.job,
                plan.values[i].tolist(),
                key=f"sofac-run-{plan.job.fingerprint[:16]}-{i}",
                pure=False,
            ): i
            for i in pending
        }
        for future in as_completed(futures):
            index = futures[future]
            try:
                result = future.result()
            except Exception as error:  # a worker that kept dying on this task (KilledWorker), ...
                result = _lost(error)
            finished(index, result)


def _lost(error: BaseException) -> dict[str, Any]:
    message = _describe(error)
    if type(error).__name__ == "KilledWorker":
        message = f"the worker running it died each time it was tried (a crash in compiled code?): {error}"
    return {
        "status": "failed",
        "message": message,
        "diverged_step": -1,
        "wall_seconds": math.nan,
        "time": None,
        "arrays": {},
    }


@contextlib.contextmanager
def _connected(scheduler: Any, workers: int | None) -> Iterator[Any]:
    """A Dask client on the scheduler asked for; an embedded LocalCluster when none is.

    Worker processes started by a Nanny (LocalCluster, ``dask worker``) get one BLAS/OpenMP thread
    each from Dask's own defaults (``distributed.nanny.pre-spawn-environ``); the embedded cluster
    also sets it explicitly."""
    from distributed import Client, LocalCluster

    if scheduler is not None and not isinstance(scheduler, str):
        yield scheduler  # the caller's own Client: theirs to close
        return
    if scheduler is None:
        with (
            LocalCluster(
                n_workers=workers or os.cpu_count() or 1,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                env=PINNED_THREADS,
                silence_logs=logging.ERROR,
            ) as cluster,
            Client(cluster) as client,
        ):
            yield client
        return
    try:
        client = Client(scheduler, timeout="20s")
    except OSError as error:
        raise SweepError(f"cannot reach the Dask scheduler at {scheduler}: {error}") from None
    with client:
        yield client


class _Parts:
    """Finished runs on disk, one file each, so that an interrupted sweep resumes where it stopped."""

    def __init__(self, folder: Path, plan: Plan, fresh: bool) -> None:
        self.folder = folder
        manifest = json.dumps(plan.manifest(), sort_keys=True)
        path = folder / "sweep.json"
        if fresh and folder.exists():
            shutil.rmtree(folder)
        if path.exists() and path.read_text(encoding="utf-8") != manifest:
            raise SweepError(
                f"{folder} holds the finished runs of a different sweep (other scene, parameters or "
                "settings); run with --fresh to discard them, or choose another --out"
            )
        folder.mkdir(parents=True, exist_ok=True)
        _write_atomically(path, manifest.encode())

    def load(self) -> dict[int, dict[str, Any]]:
        results = {}
        for path in self.folder.glob("run-*.npz"):
            try:
                with np.load(path, allow_pickle=False) as data:
                    meta = json.loads(str(data["meta"]))
                    arrays = {k[2:]: data[k] for k in data.files if k.startswith("a:")}
                    results[int(path.stem[4:])] = {**meta, "time": data["time"], "arrays": arrays}
            except (OSError, ValueError, KeyError):
                path.unlink(missing_ok=True)  # a part cut short: run it again
        return results

    def save(self, index: int, result: Mapping[str, Any]) -> None:
        meta = {k: result[k] for k in ("status", "message", "diverged_step", "wall_seconds")}
        temporary = self.folder / f".run-{index}.tmp.npz"
        time_ = result["time"] if result["time"] is not None else np.array([])
        np.savez(
            temporary, meta=json.dumps(meta), time=time_, **{f"a:{k}": v for k, v in result["arrays"].items()}
        )
        os.replace(temporary, self.folder / f"run-{index}.npz")

    def remove(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def _write_atomically(path: Path, data: bytes) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)


# --- results -------------------------------------------------------------------------------------


def to_dataset(plan: Plan, results: Mapping[int, Mapping[str, Any]], resumed: int = 0) -> Any:
    import xarray as xr

    job = plan.job
    runs = len(plan.values)
    samples = job.sample_steps()
    coords: dict[str, Any] = {"run": np.arange(runs), "step": ("sample", np.array(samples))}
    for column, parameter in enumerate(job.parameters):
        coords[parameter.name] = ("run", plan.values[:, column], {"key": parameter.key})
    times = np.full((runs, len(samples)), np.nan)
    for index, result in results.items():
        if result["time"] is not None and len(result["time"]):
            times[index] = result["time"]
    coords["time"] = (("run", "sample"), times, {"units": "s"})
    data: dict[str, Any] = {
        "status": ("run", np.array([results[i]["status"] for i in range(runs)], dtype=object)),
        "message": ("run", np.array([results[i]["message"] for i in range(runs)], dtype=object)),
        "diverged_step": (
            "run",
            np.array([results[i]["diverged_step"] for i in range(runs)], dtype=np.int64),
        ),
        "wall_seconds": ("run", np.array([results[i]["wall_seconds"] for i in range(runs)], dtype=float)),
    }
    for record in job.records:
        shape = next(
            (r["arrays"][record.name].shape[1:] for r in results.values() if record.name in r["arrays"]), None
        )
        if shape is None:
            continue  # no run got far enough to read it
        values = np.full((runs, len(samples), *shape), np.nan)
        for index, result in results.items():
            if record.name in result["arrays"]:
                values[index] = result["arrays"][record.name]
        if record.field == ENERGY:
            data["kinetic_energy"] = (("run", "sample"), values[..., 0], {"units": "J"})
            data["potential_energy"] = (("run", "sample"), values[..., 1], {"units": "J"})
            continue
        dof_dim, axis_dim = f"{record.name}.dof", f"{record.name}.axis"
        coords[dof_dim] = np.array(record.dofs if record.dofs is not None else range(shape[0]))
        data[record.name] = (
            ("run", "sample", dof_dim, axis_dim),
            values,
            {"state": record.state, "field": record.field},
        )
    attrs = {
        "scene": job.scene,
        "steps": job.steps,
        "every": job.every,
        "parameters": json.dumps([p.name for p in job.parameters]),
        "grid": json.dumps(list(plan.grid)),
        "log_spaced": json.dumps(sorted(n for n, s in plan.spacing.items() if s == "log")),
        "fingerprint": job.fingerprint,
        "resumed_runs": resumed,
        "created_by": "sofac sweep",
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def write(dataset: Any, path: Path) -> Path:
    """The dataset as NetCDF-4 (h5netcdf), written beside and renamed into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.tmp")
    encoding = {name: {"dtype": str} for name in ("status", "message")}
    dataset.to_netcdf(temporary, engine="h5netcdf", encoding=encoding)
    os.replace(temporary, path)
    return path


def open_dataset(path: str | Path) -> Any:
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as dataset:
        return dataset.load()


def summary(dataset: Any) -> list[dict[str, Any]]:
    """One row per run: its parameters, status and one number per recorded quantity (the largest
    displacement, speed or force over the recorded DOFs at the last sample; the final total energy)."""
    parameters = json.loads(dataset.attrs["parameters"])
    rows = []
    for run in range(dataset.sizes["run"]):
        row: dict[str, Any] = {"run": run}
        row.update({name: float(dataset[name].values[run]) for name in parameters})
        row["status"] = str(dataset["status"].values[run])
        for name, value in summary_values(dataset).items():
            row[name] = float(value[run])
        row["wall_seconds"] = float(dataset["wall_seconds"].values[run])
        if row["status"] != "ok":
            row["message"] = str(dataset["message"].values[run])
        rows.append(row)
    return rows


def summary_values(dataset: Any) -> dict[str, np.ndarray]:
    """{label: one number per run} (see ``summary``)."""
    out = {}
    for name, variable in dataset.data_vars.items():
        if variable.attrs.get("field") in FIELDS:
            values = variable.values[..., :3]  # translations of rigid states
            if variable.attrs["field"] == "position":
                label = f"{name} max |x(T)-x(0)|"
                vectors = values[:, -1] - values[:, 0]
            else:
                label = (
                    f"{name} max |v(T)|" if variable.attrs["field"] == "velocity" else f"{name} max |f(T)|"
                )
                vectors = values[:, -1]
            out[label] = np.linalg.norm(vectors, axis=-1).max(axis=-1)
    if "kinetic_energy" in dataset:
        out["energy(T)"] = (dataset["kinetic_energy"] + dataset["potential_energy"]).values[:, -1]
    return out


def write_summary(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    columns: list[str] = []
    for row in rows:
        columns.extend(k for k in row if k not in columns)
    with path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    return path


def format_summary(rows: Sequence[Mapping[str, Any]]) -> str:
    if not rows:
        return ""
    columns = [c for c in rows[0] if c != "message"]
    cells = [[_cell(row.get(c)) for c in columns] for row in rows]
    widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(columns)]
    lines = ["  ".join(c.rjust(w) for c, w in zip(columns, widths, strict=True))]
    for row, line in zip(rows, cells, strict=True):
        text = "  ".join(v.rjust(w) for v, w in zip(line, widths, strict=True))
        lines.append(text + (f"  {row['message']}" if row.get("message") else ""))
    return "\n".join(lines) + "\n"


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def plot(dataset: Any, path: Path) -> Path:
    """The first summary number against the first swept parameter, a line per value of the others;
    diverged and failed runs as red crosses on the axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parameters = json.loads(dataset.attrs["parameters"])
    values = summary_values(dataset)
    label, quantity = next(iter(values.items()), ("", None))
    x_name = parameters[0]
    x = dataset[x_name].values
    ok = dataset["status"].values == "ok"
    others = parameters[1:]
    figure, axes = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    if quantity is not None:
        groups: dict[tuple[float, ...], list[int]] = {}
        for run in np.flatnonzero(ok):
            groups.setdefault(tuple(float(dataset[n].values[run]) for n in others), []).append(int(run))
        for key, members in groups.items():
            members.sort(key=lambda r: x[r])
            legend = ", ".join(f"{n}={v:g}" for n, v in zip(others, key, strict=True)) or None
            style = "o-" if len(groups) <= 8 else "o"
            axes.plot(
                x[members], quantity[members], style, markersize=4, label=legend if len(groups) <= 8 else None
            )
        axes.set_ylabel(label)
    bad = np.flatnonzero(~ok)
    if bad.size:
        axes.plot(
            x[bad],
            np.zeros(bad.size),
            "x",
            color="red",
            markersize=9,
            transform=axes.get_xaxis_transform(),
            clip_on=False,
            label="diverged / failed",
        )
    if x_name in json.loads(dataset.attrs.get("log_spaced", "[]")):
        axes.set_xscale("log")
    axes.set_xlabel(x_name)
    axes.set_title(Path(dataset.attrs["scene"]).name)
    axes.grid(True, alpha=0.3)
    if axes.get_legend_handles_labels()[0]:
        axes.legend(fontsize=8)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    plt.close(figure)
    return path
