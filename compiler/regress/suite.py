"""``sofac regress``: run SOFA's regression list and apply SOFA's own pass criterion.

SOFA's list (``scenes.regression-tests``) names, after comment lines and a reference-folder line,
one scene per line: ``SCENE STEPS EPSILON MAPPED LAST_ONLY``. For each scene SOFA stores one file
per compared MechanicalObject, ``<SCENE>.reference_<K>_<NAME>_mstate.txt.gz`` (WriteState format,
6 significant digits), K counting the compared states in traversal order (see
:func:`sofac.regress.states.select_states`).

The criterion, as SOFA's CompareState applies it (``MechanicalObject::compareVec``): at the
beginning of each step SOFA reads the reference blocks whose time is ``<= t + dt/1000`` and
compares the last of them; for a block, ``err_X`` is the mean over all scalars of ``|x - x_ref|``
where ``x`` is the current value *as printed with 6 significant digits*, likewise ``err_V``; each is
divided by the state's number of DOFs and summed over the compared blocks into ``dofError``. The
scene passes when ``sum(dofError) / number of compared states <= EPSILON``. SOFA runs STEPS steps,
so the last comparison is at the beginning of step STEPS-1 (the block stamped ``(STEPS-1)*dt``);
we stop there, as the last step's result is never compared.

Beside it we report a stricter figure: the largest position difference of any DOF coordinate at any
compared time, relative to the diagonal of the reference positions' bounding box.
"""

from __future__ import annotations

import enum
import json
import math
import os
import re
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sofac.diagnostics import Diagnostic, SceneError, Severity, SofacError
from sofac.regress.states import (
    SOFA_DEFAULT_PRECISION,
    Simulation,
    StateBlock,
    StateFileError,
    StateInfo,
    read_state_file,
    round_as_printed,
    select_states,
)

#: A function that loads a scene into a running simulation (default: ``sofac.load``).
Loader = Callable[[Path], Simulation]

LIST_NAME = "scenes.regression-tests"
# The fraction of dt SOFA's CompareState adds to the current time when looking for due blocks.
_TIME_TOLERANCE = 0.001


class RegressionListError(SofacError):
    """The regression list file cannot be read or has a malformed line."""


class Status(str, enum.Enum):
    """The outcome of one scene."""

    PASS = "PASS"
    FAIL = "FAIL"  # ran, but beyond SOFA's threshold (or a shape/finite-value mismatch)
    UNSUPPORTED = "UNSUPPORTED"  # a component sofac does not compile yet (E222)
    ERROR = "ERROR"  # invalid scene, sofac error while running, or states not matching the files
    MISSING = "MISSING"  # no reference files for the scene (or no scene file)

    def __str__(self) -> str:
        return self.value


# --- the list -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class RegressionEntry:
    """One line of the regression list."""

    scene: str  # path relative to the scenes root, as written in the list
    steps: int
    epsilon: float
    mapped: bool  # also compare states under a mapping
    last_only: bool  # the references hold only the first and the last recorded states
    line: int = 0  # line number in the list file


@dataclass
class RegressionList:
    """A parsed ``scenes.regression-tests`` file."""

    path: Path
    reference_folder: str  # the folder line as written (SOFA's layout; informative here)
    entries: list[RegressionEntry]


def _parse_flag(text: str, what: str, where: str) -> bool:
    if text not in ("0", "1"):
        raise RegressionListError(f"{where}: {what} must be 0 or 1, not {text!r}")
    return text == "1"


def parse_regression_list(path: str | Path) -> RegressionList:
    """Parse a regression list: comments (``#``) and blank lines skipped, the first other line is
    the reference folder, every following line ``SCENE STEPS EPSILON MAPPED LAST_ONLY``."""
    source = Path(path)
    try:
        text = source.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RegressionListError(f"{source}: cannot read the regression list: {exc}") from exc
    folder: str | None = None
    entries: list[RegressionEntry] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        where = f"{source}:{number}"
        if folder is None:
            if len(fields) != 1:
                raise RegressionListError(f"{where}: expected the reference-folder line, got {line!r}")
            folder = fields[0]
            continue
        if len(fields) != 5:
            raise RegressionListError(
                f"{where}: expected 'SCENE STEPS EPSILON MAPPED LAST_ONLY', got {len(fields)} fields"
            )
        scene, steps_text, epsilon_text, mapped_text, last_text = fields
        try:
            steps = int(steps_text)
            epsilon = float(epsilon_text)
        except ValueError as exc:
            raise RegressionListError(f"{where}: bad STEPS or EPSILON: {exc}") from exc
        if steps <= 0 or not math.isfinite(epsilon) or epsilon < 0:
            raise RegressionListError(f"{where}: STEPS must be > 0 and EPSILON >= 0")
        entries.append(
            RegressionEntry(
                scene,
                steps,
                epsilon,
                _parse_flag(mapped_text, "MAPPED", where),
                _parse_flag(last_text, "LAST_ONLY", where),
                number,
            )
        )
    if folder is None:
        raise RegressionListError(f"{source}: no reference-folder line and no scene")
    return RegressionList(source, folder, entries)


# --- reference files ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ReferenceFile:
    """One reference state file of a scene."""

    k: int
    name: str
    path: Path


def reference_files(reference_root: str | Path, scene: str) -> list[ReferenceFile]:
    """The state reference files of ``scene`` under ``reference_root``, ordered by K."""
    target = Path(reference_root) / scene
    prefix = target.name + ".reference_"
    pattern = re.compile(re.escape(prefix) + r"(\d+)_(.*)_mstate\.txt(?:\.gz)?$")
    found: list[ReferenceFile] = []
    if target.parent.is_dir():
        for candidate in target.parent.iterdir():
            match = pattern.match(candidate.name)
            if match and candidate.is_file():
                found.append(ReferenceFile(int(match.group(1)), match.group(2), candidate))
    return sorted(found, key=lambda ref: ref.k)


# --- results ------------------------------------------------------------------------------------


@dataclass
class StateComparison:
    """The comparison of one state with its reference file."""

    k: int
    name: str
    path: str  # the state's path in the simulation
    dofs: int
    frames: int = 0  # reference blocks compared
    error_x: float = 0.0  # sum over compared blocks of SOFA's err_X
    error_v: float = 0.0
    dof_error: float = 0.0  # sum over compared blocks of (err_X + err_V) / dofs: SOFA's dofError
    max_abs: float = 0.0  # largest |x - x_ref| over the spatial coordinates
    problem: str = ""  # a shape mismatch or non-finite values (makes the scene FAIL)


@dataclass
class SceneResult:
    """The outcome of one scene of the list."""

    scene: str
    status: Status
    epsilon: float
    steps: int
    error: float | None = None  # SOFA's figure: sum of dofError / number of compared states
    max_rel: float | None = None  # max position difference / reference bounding-box diagonal
    message: str = ""  # why it failed, errored or is unsupported
    component: str | None = None  # UNSUPPORTED: the first unsupported component
    location: str | None = None  # UNSUPPORTED: its file:line
    unsupported: list[str] = field(default_factory=list)  # every unsupported component (sorted, unique)
    states: list[StateComparison] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        """Whether this result makes ``sofac regress`` fail (UNSUPPORTED only with --strict)."""
        return self.status in (Status.FAIL, Status.ERROR, Status.MISSING)

    def as_dict(self) -> dict[str, Any]:
        """Plain data for JSON: non-finite numbers become the strings ``"inf"``/``"nan"``."""
        data = _json_safe(asdict(self))
        data["status"] = self.status.value
        return data


def _json_safe(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_json_safe(item) for item in value]
    return value


# --- SOFA's criterion -----------------------------------------------------------------------------


def compare_vec(current: np.ndarray, reference: np.ndarray) -> float:
    """SOFA's ``MechanicalObject::compareVec``: mean of ``|ref - cur|`` over the common scalars, the
    current values rounded to 6 significant digits first (SOFA compares their printed text)."""
    cur = round_as_printed(current, SOFA_DEFAULT_PRECISION)
    ref = np.asarray(reference, dtype=np.float64).ravel()
    count = min(cur.size, ref.size)
    if count == 0:
        return 0.0
    return float(np.sum(np.abs(ref[:count] - cur[:count])) / count)


def state_file_error(
    current: Sequence[StateBlock],
    reference: Sequence[StateBlock],
    dofs: int,
    *,
    dt: float | None = None,
) -> tuple[float, int]:
    """SOFA's dofError of one state between two recordings, and how many blocks were compared.

    Each reference block is compared with the block of ``current`` at the same time: within
    ``dt/1000`` when ``dt`` is given, else within a relative 1e-5 (reference files print times
    with 6 digits). Reference blocks without a partner are not compared. ``dofs`` is the state's
    number of DOFs (points, not scalars).
    """
    total = 0.0
    frames = 0
    for ref in reference:
        tolerance = _TIME_TOLERANCE * dt if dt else max(1e-5 * abs(ref.time), 1e-12)
        match = min(current, key=lambda block: abs(block.time - ref.time), default=None)
        if match is None or abs(match.time - ref.time) > tolerance:
            continue
        frames += 1
        for key in ("X", "V"):
            ours, theirs = match.vectors.get(key), ref.vectors.get(key)
            if ours is not None and theirs is not None and dofs:
                total += compare_vec(ours, theirs) / dofs
    return total, frames


def scene_error(states: Sequence[StateComparison]) -> float:
    """SOFA's scene figure: the sum of the states' dofError over the number of compared states."""
    if not states:
        return math.nan
    return math.fsum(s.dof_error for s in states) / len(states)


def due_steps(times: Sequence[float], dt: float, steps: int) -> dict[int, int]:
    """Which reference block SOFA compares at which step beginning: ``{step index: block index}``.

    At the beginning of step ``i`` (time ``i*dt``) CompareState reads every block stamped at most
    ``i*dt + dt/1000`` that it has not read yet and compares only the last one. Steps run from 0 to
    ``steps - 1``; blocks due later are never compared.
    """
    due: dict[int, int] = {}
    tolerance = _TIME_TOLERANCE * dt
    for index, stamp in enumerate(times):
        if not math.isfinite(stamp):
            continue  # SOFA never reaches such a time
        step = max(0, math.ceil((stamp - tolerance) / dt - 1e-9))
        # ceil on a quotient can miss by one ulp: settle it against SOFA's own test.
        while step > 0 and stamp <= (step - 1) * dt + tolerance:
            step -= 1
        while stamp > step * dt + tolerance:
            step += 1
        if step < steps:
            due[step] = index  # a later block due at the same step replaces the earlier one
    return dict(sorted(due.items()))


_SPATIAL = {"Vec1": 1, "Vec2": 2, "Vec3": 3, "Vec6": 3, "Rigid2": 2, "Rigid3": 3}


def spatial_size(template: str, coord_size: int) -> int:
    """How many leading coordinates of a Coord are a point in space (Rigid3d: 3 of 7)."""
    for prefix, size in _SPATIAL.items():
        if template.startswith(prefix):
            return min(size, coord_size)
    return min(3, coord_size)


# --- running one scene ------------------------------------------------------------------------


def _default_loader(path: Path) -> Simulation:
    from sofac.pipeline import load
    from sofac.scene_warnings import quiet

    with quiet():  # a regression run reports each scene's status; its warnings are sofac check's
        return load(path)


def _first_unsupported(diagnostics: Sequence[Diagnostic]) -> tuple[Diagnostic | None, list[str]]:
    unsupported = [d for d in diagnostics if d.code == "E222"]
    names = sorted({_component_of(d) for d in unsupported})
    if not unsupported:
        return None, names
    first = min(unsupported, key=lambda d: (d.loc.line == 0, d.loc.file, d.loc.line))
    return first, names


def _component_of(diag: Diagnostic) -> str:
    match = re.search(r"unsupported component (\S+)", diag.message)
    return match.group(1) if match else diag.message


def _scene_error_result(result: SceneResult, exc: SceneError, scenes_root: Path) -> SceneResult:
    first, names = _first_unsupported(exc.diagnostics)
    others = [d for d in exc.diagnostics if d.code != "E222" and d.severity is Severity.ERROR]
    if first is not None:
        result.status = Status.UNSUPPORTED
        result.component = _component_of(first)
        result.location = f"{_short(first.loc.file, scenes_root)}:{first.loc.line}"
        result.unsupported = names
        result.message = first.message
        if others:
            result.message += (
                f" (and {len(others)} other error(s), first: {others[0].code} {others[0].message})"
            )
        return result
    result.status = Status.ERROR
    shown = others[0] if others else (exc.diagnostics[0] if exc.diagnostics else None)
    if shown is None:
        result.message = str(exc) or "invalid scene"
    else:
        where = f"{_short(shown.loc.file, scenes_root)}:{shown.loc.line}"
        result.message = f"{shown.code} {where}: {shown.message}"
    return result


def _short(file: str, root: Path) -> str:
    try:
        return str(Path(file).resolve().relative_to(root.resolve()))
    except (ValueError, OSError):
        return file


def _pair_states(selected: Sequence[StateInfo], references: Sequence[ReferenceFile]) -> str | None:
    """Why the states sofac selected cannot be paired with the reference files (None if they can)."""
    ours = [s.name for s in selected]
    theirs = [r.name for r in references]
    if [r.k for r in references] != list(range(len(references))):
        return f"reference files are not numbered 0..{len(references) - 1}: {[r.k for r in references]}"
    if ours != theirs:
        return (
            f"compared states differ from the reference files: sofac has {len(ours)} {ours}, "
            f"the references {len(theirs)} {theirs}"
        )
    return None


def _as_2d(array: np.ndarray) -> np.ndarray:
    values = np.asarray(array, dtype=np.float64)
    return values.reshape(len(values), -1) if values.ndim != 2 else values


def run_scene(
    entry: RegressionEntry,
    scenes_root: str | Path,
    reference_root: str | Path,
    *,
    loader: Loader | None = None,
) -> SceneResult:
    """Load one scene, run its STEPS and compare with its reference files; never raises."""
    started = time.perf_counter()
    result = SceneResult(entry.scene, Status.ERROR, entry.epsilon, entry.steps)
    try:
        _run_scene(entry, Path(scenes_root), Path(reference_root), loader or _default_loader, result)
    except SceneError as exc:
        _scene_error_result(result, exc, Path(scenes_root))
    except SofacError as exc:
        result.status = Status.ERROR
        result.message = str(exc) or type(exc).__name__
    except Exception as exc:  # a bug in sofac must not stop the whole regression run
        result.status = Status.ERROR
        result.message = f"internal error: {type(exc).__name__}: {exc}"
    result.seconds = time.perf_counter() - started
    return result


def _run_scene(
    entry: RegressionEntry, scenes_root: Path, reference_root: Path, loader: Loader, result: SceneResult
) -> None:
    scene_path = scenes_root / entry.scene
    if not scene_path.is_file():
        result.status = Status.MISSING
        result.message = f"scene file not found: {scene_path}"
        return
    references = reference_files(reference_root, entry.scene)
    if not references:
        result.status = Status.MISSING
        result.message = f"no reference files {entry.scene}.reference_<K>_<NAME>_mstate.txt.gz"
        return
    blocks: list[list[StateBlock]] = []
    for ref in references:
        try:
            blocks.append(read_state_file(ref.path))
        except StateFileError as exc:
            result.status = Status.MISSING
            result.message = f"unreadable reference: {exc}"
            return

    sim = loader(scene_path)
    selected = select_states(sim.states(), mapped=entry.mapped)
    problem = _pair_states(selected, references)
    if problem:
        result.status = Status.ERROR
        result.message = problem
        return

    dt = float(sim.dt)
    if not (math.isfinite(dt) and dt > 0):
        raise SofacError(f"the scene's dt is {dt}; cannot match reference times")
    # Each CompareState reads its own file: one schedule per state.
    schedules = [due_steps([b.time for b in file_blocks], dt, entry.steps) for file_blocks in blocks]
    comparisons = [
        StateComparison(ref.k, info.name, info.path, 0)
        for ref, info in zip(references, selected, strict=True)
    ]
    lows: list[np.ndarray] = []
    highs: list[np.ndarray] = []
    done = 0
    for step in sorted(set().union(*schedules)):
        if step > done:
            sim.step(step - done)
            done = step
        for comp, info, file_blocks, schedule in zip(comparisons, selected, blocks, schedules, strict=True):
            if step in schedule:
                _compare_state(comp, info, sim, file_blocks[schedule[step]], lows, highs)
    # SOFA then runs the last step, whose result it never compares: skipping it changes nothing.

    result.states = comparisons
    result.error = scene_error(comparisons)
    result.max_rel = _relative_max(comparisons, lows, highs)
    problems = [f"{c.k}_{c.name}: {c.problem}" for c in comparisons if c.problem]
    compared = sum(c.frames for c in comparisons)
    if problems:
        result.status = Status.FAIL
        result.message = "; ".join(problems)
    elif compared == 0:
        result.status = Status.ERROR
        result.message = f"no reference time fell within the {entry.steps} steps run (dt {dt:g})"
    elif result.error <= entry.epsilon:
        result.status = Status.PASS
    else:
        result.status = Status.FAIL
        result.message = f"error {result.error:.3g} > epsilon {entry.epsilon:g}"


def _compare_state(
    comp: StateComparison,
    info: StateInfo,
    sim: Simulation,
    block: StateBlock,
    lows: list[np.ndarray],
    highs: list[np.ndarray],
) -> None:
    view = sim[info.path]
    position = _as_2d(view.position).copy()
    comp.dofs = len(position)
    comp.frames += 1
    vectors: list[tuple[str, np.ndarray, np.ndarray]] = []
    if block.x is not None:
        vectors.append(("X", position, block.x))
    if block.v is not None:
        vectors.append(("V", _as_2d(view.velocity).copy(), block.v))
    for key, current, reference in vectors:
        if current.size != reference.size and not comp.problem:
            comp.problem = f"{key} has {current.size} scalars, the reference {reference.size}"
        if not np.all(np.isfinite(current)):
            comp.problem = comp.problem or f"non-finite {key} values"
            err = math.inf
        else:
            err = compare_vec(current, reference)
        if key == "X":
            comp.error_x += err
        else:
            comp.error_v += err
        if comp.dofs:
            comp.dof_error += err / comp.dofs
    if block.x is not None and position.size == block.x.size and position.size:
        width = position.shape[1]
        spatial = spatial_size(info.template, width)
        ref = block.x.reshape(-1, width)[:, :spatial]
        cur = position[:, :spatial]
        with np.errstate(invalid="ignore"):
            diff = float(np.max(np.abs(cur - ref)))
        comp.max_abs = max(comp.max_abs, diff) if math.isfinite(diff) else math.inf
        lows.append(ref.min(axis=0, initial=math.inf)[:3])
        highs.append(ref.max(axis=0, initial=-math.inf)[:3])


def _relative_max(comps: Sequence[StateComparison], lows: list[np.ndarray], highs: list[np.ndarray]) -> float:
    if not comps:
        return math.nan
    worst = max(c.max_abs for c in comps)
    if not lows:
        return worst
    size = max(len(v) for v in lows)
    low = np.full(size, math.inf)
    high = np.full(size, -math.inf)
    for lo, hi in zip(lows, highs, strict=True):
        low[: len(lo)] = np.minimum(low[: len(lo)], lo)
        high[: len(hi)] = np.maximum(high[: len(hi)], hi)
    extent = np.where(np.isfinite(high - low), high - low, 0.0)
    diagonal = float(np.linalg.norm(extent))
    return worst / diagonal if diagonal > 0 else worst


# --- the whole list ---------------------------------------------------------------------------


def select_entries(entries: Iterable[RegressionEntry], only: Sequence[str] | None) -> list[RegressionEntry]:
    """The entries whose scene path contains any of the ``only`` substrings (all if None/empty)."""
    chosen = list(entries)
    if only:
        chosen = [e for e in chosen if any(part in e.scene for part in only)]
    return chosen


def run_regression(
    list_path: str | Path,
    scenes_root: str | Path,
    reference_root: str | Path,
    only: list[str] | None = None,
    jobs: int = 1,
    *,
    loader: Loader | None = None,
    progress: Callable[[SceneResult], None] | None = None,
) -> list[SceneResult]:
    """Run every scene of the list (or those matching ``only``); results in list order.

    ``jobs > 1`` runs up to that many scenes at once, each in a process of its own (a crash costs
    only its scene, reported as ERROR); ``loader`` must then be picklable (a module-level function).
    ``progress`` is called with each result as it completes.
    """
    entries = select_entries(parse_regression_list(list_path).entries, only)
    scenes = Path(scenes_root)
    references = Path(reference_root)
    if jobs <= 1 or len(entries) <= 1:
        results = []
        for entry in entries:
            result = run_scene(entry, scenes, references, loader=loader)
            if progress:
                progress(result)
            results.append(result)
        return results
    return _run_parallel(entries, scenes, references, jobs, loader, progress)


def _worker(conn: Any, entry: RegressionEntry, scenes: Path, references: Path, loader: Loader | None) -> None:
    try:
        conn.send(run_scene(entry, scenes, references, loader=loader))
    finally:
        conn.close()


def _run_in_process(
    entry: RegressionEntry, scenes: Path, references: Path, loader: Loader | None, context: Any
) -> SceneResult:
    """Run one scene in a process of its own: a crash (a segfault in native code) costs only it."""
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_worker, args=(sender, entry, scenes, references, loader), daemon=True)
    started = time.perf_counter()
    process.start()
    sender.close()
    try:
        result: SceneResult | None = receiver.recv()
    except EOFError:
        result = None
    finally:
        receiver.close()
        process.join()
    if result is None:
        result = SceneResult(
            entry.scene,
            Status.ERROR,
            entry.epsilon,
            entry.steps,
            message=f"sofac crashed while running this scene (worker exit code {process.exitcode})",
            seconds=time.perf_counter() - started,
        )
    return result


def _run_parallel(
    entries: Sequence[RegressionEntry],
    scenes: Path,
    references: Path,
    jobs: int,
    loader: Loader | None,
    progress: Callable[[SceneResult], None] | None,
) -> list[SceneResult]:
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    results: list[SceneResult | None] = [None] * len(entries)
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        futures = {
            pool.submit(_run_in_process, entry, scenes, references, loader, context): index
            for index, entry in enumerate(entries)
        }
        for future in as_completed(futures):
            result = future.result()
            results[futures[future]] = result
            if progress:
                progress(result)
    return [r for r in results if r is not None]


# --- reports --------------------------------------------------------------------------------------


def counts(results: Sequence[SceneResult]) -> dict[str, int]:
    """How many scenes ended with each status."""
    tally = {status.value: 0 for status in Status}
    for result in results:
        tally[result.status.value] += 1
    return tally


def summary_line(results: Sequence[SceneResult]) -> str:
    """``N/M pass`` and the count of each other status."""
    tally = counts(results)
    others = ", ".join(f"{tally[s.value]} {s.value.lower()}" for s in Status if s is not Status.PASS)
    return f"{tally['PASS']}/{len(results)} pass ({others})"


def _fmt(value: float | None, spec: str = ".2e") -> str:
    if value is None:
        return "-"
    if not math.isfinite(value):
        return str(value)
    return format(value, spec)


def _detail(result: SceneResult) -> str:
    if result.status is Status.UNSUPPORTED:
        extra = len(result.unsupported) - 1
        more = f" (+{extra} more: {', '.join(n for n in result.unsupported if n != result.component)})"
        return f"{result.component} at {result.location}" + (more if extra > 0 else "")
    return result.message


def format_table(results: Sequence[SceneResult]) -> str:
    """A plain-text table, one scene a line, and the totals line ``N/M pass (...)``."""
    header = ("SCENE", "STATUS", "ERROR", "EPSILON", "MAX/BBOX", "TIME", "DETAIL")
    rows = [
        (
            r.scene,
            r.status.value,
            _fmt(r.error),
            f"{r.epsilon:g}",
            _fmt(r.max_rel),
            f"{r.seconds:.1f}s",
            _detail(r),
        )
        for r in results
    ]
    widths = [
        max(len(header[i]), *(len(row[i]) for row in rows)) if rows else len(header[i]) for i in range(6)
    ]
    lines = []
    for row in (header, *rows):
        cells = [row[i].ljust(widths[i]) for i in range(6)]
        lines.append(("  ".join(cells) + "  " + row[6]).rstrip())
    lines.append("")
    lines.append(summary_line(results))
    return "\n".join(lines) + "\n"


def format_markdown(results: Sequence[SceneResult]) -> str:
    """A Markdown table (docs/regression.md's per-scene table) and the totals line."""
    lines = ["| scene | status | SOFA's error | ε | max diff / bbox | detail |", "|---|---|---|---|---|---|"]
    for r in results:
        detail = _detail(r).replace("|", "/")
        cells = (r.scene, r.status.value, _fmt(r.error), f"{r.epsilon:g}", _fmt(r.max_rel), detail)
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", summary_line(results)]
    return "\n".join(lines) + "\n"


def results_as_json(results: Sequence[SceneResult], list_path: str | Path | None = None) -> str:
    """Every result with its per-state figures, and the totals, as a JSON document."""
    tally = counts(results)
    document = {
        "list": str(list_path) if list_path is not None else None,
        "results": [r.as_dict() for r in results],
        "summary": {"pass": tally["PASS"], "total": len(results), "counts": tally},
    }
    return json.dumps(document, indent=2, allow_nan=False) + "\n"


# --- where the shared material lives ------------------------------------------------------------------


def repository_root() -> Path:
    """The sofac source checkout this module belongs to (``Path(sofac.__file__).parents[1]``)."""
    return Path(__file__).resolve().parents[2]


def shared_root() -> Path:
    """``$SOFAC_SHARED`` if set, else the ``shared`` folder next to the repository (``../shared``)."""
    env = os.environ.get("SOFAC_SHARED")
    if env:
        return Path(env)
    return repository_root().parent / "shared"


def default_list() -> Path:
    """The shared copy of SOFA's regression list."""
    return shared_root() / "reference" / "sofa-regression" / LIST_NAME


def default_scenes_root() -> Path:
    """The shared SOFA scene corpus (the scenes of the list, with their meshes)."""
    return shared_root() / "corpus" / "sofa"


def default_reference_root(list_path: str | Path) -> Path:
    """Where the reference files are: beside the list, with the scenes' relative paths."""
    return Path(list_path).resolve().parent
