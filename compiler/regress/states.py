"""SOFA's WriteState text format: writing, reading, and recording a running simulation.

A WriteState file holds one block per recorded time, every vector on one line::

    T= 0.02
      X= 0 0 0 1 -1.0000000000000001e-05 0
      V= 0 0 0 0 -0.01 0

``T=`` is the simulation time at the *beginning* of a step (SOFA writes on AnimateBeginEvent), so
the block stamped ``k*dt`` holds the state after ``k`` steps, and a run of ``N`` steps records the
stamps ``0, dt, ..., (N-1)*dt``: the state after the last step is never written. ``X=`` holds all
position scalars of all DOFs (Rigid3d: ``x y z qx qy qz qw`` per DOF), ``V=`` all velocity scalars.
SOFA prints every number, the time included, with its stream precision (``%g`` style): 6
significant digits by default (the regression references), 17 in our reference build. Files whose
name ends in ``.gz`` are gzip-compressed.

:class:`StateRecorder` records a simulation the way WriteState does; :func:`export_states` is what
``sofac run --export-states DIR`` calls. Files are named ``<K>_<NAME>_mstate.txt.gz``, K counting
the recorded states in SOFA's traversal order (see :func:`select_states`).
"""

from __future__ import annotations

import gzip
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Protocol

import numpy as np
from sofac.diagnostics import SofacError

#: Significant digits sofac writes by default: enough to round-trip every double.
FULL_PRECISION = 17
#: SOFA's default stream precision, the one of its regression reference files.
SOFA_DEFAULT_PRECISION = 6
#: The vectors WriteState can write, in the order it writes them.
VECTOR_KEYS = ("X", "X0", "V", "F")


class StateFileError(SofacError):
    """A WriteState file could not be read: unreadable, truncated or not in WriteState format."""


# --- the simulation interface the recorder programs against -----------------------------------


class StateInfo(Protocol):
    """What ``sim.states()`` tells about one MechanicalObject."""

    @property
    def path(self) -> str: ...  # "/Liver/dofs"

    @property
    def name(self) -> str: ...  # the object's SOFA name ("dofs", "MechanicalObject1" if unnamed)

    @property
    def mapped(self) -> bool: ...  # under a mapping (in its node or above it)

    @property
    def template(self) -> str: ...  # "Vec3d", "Rigid3d", ...


class StateView(Protocol):
    """``sim[path]``: the arrays of one state, shape (n, coord size) and (n, deriv size)."""

    @property
    def position(self) -> np.ndarray: ...

    @property
    def velocity(self) -> np.ndarray: ...


class Simulation(Protocol):
    """The part of a loaded simulation (``sofac.load(path)``) that recording needs."""

    @property
    def dt(self) -> float: ...

    @property
    def time(self) -> float: ...

    def step(self, n: int = 1) -> None: ...

    def states(self) -> Sequence[StateInfo]: ...

    def __getitem__(self, path: str) -> StateView: ...


def select_states(states: Iterable[StateInfo], *, mapped: bool) -> list[StateInfo]:
    """The states SOFA records or compares, in order; their index in the result is K.

    SOFA's WriteStateCreator/CompareStateCreator visit the nodes depth first (a node before its
    children, children in document order) and take each node's MechanicalObject when an ODE
    solver is in that node or above it; with ``mapped=False`` they skip states with a mapping in
    their node or above it. Verified against all 87 scenes of SOFA's regression list (every
    reference file name, K and NAME). A state without the optional ``simulated`` attribute counts
    as simulated.
    """
    return [s for s in states if getattr(s, "simulated", True) and (mapped or not s.mapped)]


# --- formatting ---------------------------------------------------------------------------------


def format_number(value: float, precision: int = FULL_PRECISION) -> str:
    """One number as a C++ stream with ``setprecision(precision)`` prints it (``%.{precision}g``)."""
    return f"{value:.{precision}g}"


def format_vector(values: np.ndarray, precision: int = FULL_PRECISION) -> str:
    """All scalars of a vector, flattened in row order and separated by single spaces."""
    flat = np.asarray(values, dtype=np.float64).ravel()
    spec = f".{precision}g"
    return " ".join(format(x, spec) for x in flat.tolist())


def round_as_printed(values: np.ndarray, precision: int = SOFA_DEFAULT_PRECISION) -> np.ndarray:
    """The values as they read back after being printed with ``precision`` significant digits."""
    flat = np.asarray(values, dtype=np.float64).ravel()
    if flat.size == 0:
        return flat.copy()
    return np.char.mod(f"%.{precision}g", flat).astype(np.float64)


@dataclass
class StateBlock:
    """One recorded time: ``T=`` and the vectors written for it (flat float64 arrays)."""

    time: float
    vectors: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def x(self) -> np.ndarray | None:
        """The positions (``X=``), or None if the block has none."""
        return self.vectors.get("X")

    @property
    def v(self) -> np.ndarray | None:
        """The velocities (``V=``), or None if the block has none."""
        return self.vectors.get("V")


def format_block(
    time: float,
    x: np.ndarray | None,
    v: np.ndarray | None = None,
    *,
    precision: int = FULL_PRECISION,
    extra: dict[str, np.ndarray] | None = None,
) -> str:
    """One block of text exactly as WriteState writes it: ``T= t``, then ``  X= ...``, ``  V= ...``.

    ``extra`` may add ``X0`` and ``F`` vectors, written in WriteState's order (X, X0, V, F).
    """
    vectors = dict(extra or {})
    if x is not None:
        vectors["X"] = x
    if v is not None:
        vectors["V"] = v
    unknown = set(vectors) - set(VECTOR_KEYS)
    if unknown:
        raise ValueError(f"WriteState writes only {', '.join(VECTOR_KEYS)}, not {sorted(unknown)}")
    lines = [f"T= {format_number(time, precision)}\n"]
    for key in VECTOR_KEYS:
        if key in vectors:
            lines.append(f"  {key}= {format_vector(vectors[key], precision)}\n")
    return "".join(lines)


# --- files ---------------------------------------------------------------------------------------


def _is_gzip(path: Path) -> bool:
    return path.name.endswith(".gz")


class _Sink:
    """An open output file (gzip'd or plain by suffix) that owns its underlying file object."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._raw = path.open("wb")
        self._stream: IO[bytes] = (
            gzip.GzipFile(filename="", mode="wb", fileobj=self._raw, mtime=0) if _is_gzip(path) else self._raw
        )

    def write(self, text: str) -> None:
        self._stream.write(text.encode("ascii"))

    def close(self) -> None:
        try:
            if self._stream is not self._raw:
                self._stream.close()
        finally:
            self._raw.close()


def write_state_file(
    path: str | Path, blocks: Iterable[StateBlock], *, precision: int = FULL_PRECISION
) -> Path:
    """Write blocks to ``path`` in WriteState format (gzip'd if the name ends in ``.gz``)."""
    target = Path(path)
    sink = _Sink(target)
    try:
        for block in blocks:
            sink.write(format_block(block.time, None, None, precision=precision, extra=block.vectors))
    finally:
        sink.close()
    return target


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StateFileError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    if _is_gzip(path) or data[:2] == b"\x1f\x8b":
        try:
            data = gzip.decompress(data)
        except EOFError as exc:
            raise StateFileError(f"{path}: truncated gzip stream (the file is incomplete)") from exc
        except (OSError, zlib.error) as exc:
            raise StateFileError(f"{path}: not a valid gzip file: {exc}") from exc
    try:
        return data.decode("ascii")
    except UnicodeDecodeError as exc:
        raise StateFileError(f"{path}: not a WriteState text file (non-ASCII bytes)") from exc


def _parse_numbers(tokens: list[str], path: Path, line_no: int) -> np.ndarray:
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise StateFileError(f"{path}:{line_no}: not a number: {exc}") from exc


def parse_state_text(text: str, path: str | Path = "<text>") -> list[StateBlock]:
    """Parse WriteState text into blocks. Raises :class:`StateFileError` on anything else.

    Accepted: ``T= t`` lines opening a block, then ``KEY= numbers`` lines for the keys WriteState
    writes (X, X0, V, F), each vector on one line; blank lines are skipped.
    """
    where = Path(path)
    blocks: list[StateBlock] = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        tokens = line.split()
        if not tokens:
            continue
        head = tokens[0]
        if head == "T=":
            if len(tokens) != 2:
                raise StateFileError(f"{where}:{line_no}: 'T=' must be followed by exactly one time")
            blocks.append(StateBlock(float(_parse_numbers(tokens[1:], where, line_no)[0])))
            continue
        key = head[:-1] if head.endswith("=") else None
        if key not in VECTOR_KEYS:
            raise StateFileError(
                f"{where}:{line_no}: not a WriteState line (expected T=, X=, X0=, V= or F=): {line[:60]!r}"
            )
        if not blocks:
            raise StateFileError(f"{where}:{line_no}: '{head}' before the first 'T=' line")
        block = blocks[-1]
        if key in block.vectors:
            raise StateFileError(f"{where}:{line_no}: '{head}' given twice for T= {block.time:g}")
        block.vectors[key] = _parse_numbers(tokens[1:], where, line_no)
    return blocks


def read_state_file(path: str | Path) -> list[StateBlock]:
    """Read a WriteState file (gzip'd or plain) into its blocks, in file order."""
    target = Path(path)
    return parse_state_text(_read_text(target), target)


def state_file_name(k: int, name: str) -> str:
    """``<K>_<NAME>_mstate.txt.gz``, as SOFA names its state files (path separators replaced)."""
    safe = name.replace("/", "_").replace("\\", "_").replace("\0", "_") or "unnamed"
    return f"{k}_{safe}_mstate.txt.gz"


# --- recording a simulation ---------------------------------------------------------------------


def recorded_steps(steps: int, *, every: int = 1, last_only: bool = False, start: int = 0) -> list[int]:
    """At which step beginnings a run of ``steps`` steps records (global step indices).

    A step's beginning ``i`` is the state after ``i`` steps. WriteState records at ``i`` when
    ``i % every == 0``; with ``last_only`` (SOFA's regression references) only at the first and
    the last step beginnings of the run, ``start`` and ``start + steps - 1``.
    """
    if steps < 0:
        raise ValueError(f"steps must be >= 0, not {steps}")
    if every < 1:
        raise ValueError(f"every must be >= 1, not {every}")
    if steps == 0:
        return []
    if last_only:
        return sorted({start, start + steps - 1})
    return [i for i in range(start, start + steps) if i % every == 0]


class StateRecorder:
    """Records states of a running simulation into WriteState files, as SOFA's WriteState does.

    One file per state, ``<out_dir>/<K>_<NAME>_mstate.txt.gz`` with K the state's index in
    ``states``; :meth:`run` steps the simulation and records at the beginning of the chosen steps.
    Use it as a context manager (or call :meth:`close`) so the gzip streams are finished.
    """

    def __init__(
        self,
        sim: Simulation,
        states: Sequence[StateInfo],
        out_dir: str | Path,
        *,
        every: int = 1,
        precision: int = FULL_PRECISION,
        velocities: bool = True,
    ) -> None:
        if every < 1:
            raise ValueError(f"every must be >= 1, not {every}")
        self.sim = sim
        self.states = list(states)
        self.out_dir = Path(out_dir)
        self.every = every
        self.precision = precision
        self.velocities = velocities
        self.steps_done = 0
        self.blocks_written = 0
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.paths = [self.out_dir / state_file_name(k, s.name) for k, s in enumerate(self.states)]
        self._sinks: list[_Sink] = []
        try:
            for path in self.paths:
                self._sinks.append(_Sink(path))
        except OSError:
            self.close()
            raise

    def record(self) -> None:
        """Write one block per state with the simulation's current time and state."""
        if len(self._sinks) != len(self.states):
            raise ValueError("the recorder is closed")
        time = float(self.sim.time)
        for info, sink in zip(self.states, self._sinks, strict=True):
            view = self.sim[info.path]
            x = np.asarray(view.position)
            v = np.asarray(view.velocity) if self.velocities else None
            sink.write(format_block(time, x, v, precision=self.precision))
        self.blocks_written += 1

    def run(self, steps: int, *, last_only: bool = False) -> None:
        """Step ``steps`` times, recording at the beginning of the steps :func:`recorded_steps` picks."""
        todo = recorded_steps(steps, every=self.every, last_only=last_only, start=self.steps_done)
        end = self.steps_done + steps
        for index in todo:
            if index > self.steps_done:
                self.sim.step(index - self.steps_done)
                self.steps_done = index
            self.record()
        if end > self.steps_done:
            self.sim.step(end - self.steps_done)
            self.steps_done = end

    def close(self) -> None:
        """Finish and close every file (idempotent)."""
        sinks, self._sinks = self._sinks, []
        errors: list[BaseException] = []
        for sink in sinks:
            try:
                sink.close()
            except OSError as exc:
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> StateRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def export_states(
    sim: Simulation,
    steps: int,
    out_dir: str | Path,
    every: int = 1,
    mapped: bool = False,
    *,
    last_only: bool = False,
    precision: int = FULL_PRECISION,
) -> list[Path]:
    """Run ``steps`` steps and write every recorded state to ``out_dir``; return the files written.

    What ``sofac run SCENE --steps N --export-states DIR [--mapped] [--every K]`` does: the unmapped
    states (and the mapped ones with ``mapped=True``) chosen by :func:`select_states`, one file
    ``<K>_<NAME>_mstate.txt.gz`` each, recorded at the beginning of every ``every``-th step, with
    17 significant digits. Running a regression scene's STEPS with ``last_only=True`` gives exactly
    the stamps of SOFA's references, ``T= 0`` and ``T= (STEPS-1)*dt``.
    """
    states = select_states(sim.states(), mapped=mapped)
    with StateRecorder(sim, states, out_dir, every=every, precision=precision) as recorder:
        recorder.run(steps, last_only=last_only)
    return recorder.paths


def dumps(blocks: Iterable[StateBlock], precision: int = FULL_PRECISION) -> str:
    """Blocks as WriteState text (uncompressed)."""
    return "".join(
        format_block(block.time, None, None, precision=precision, extra=block.vectors) for block in blocks
    )
