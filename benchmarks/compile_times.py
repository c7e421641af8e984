"""Cold compile time, warm load time and step cost of the bundled scenes, against issue 3's targets.

Everything happens in a fresh compile cache (a temporary ``SOFAC_CACHE_DIR``), so nothing is
taken from an earlier run:

1. the host module (pybind11, built once per installation) is built first and timed on its own;
2. cold compile, per scene, in this process: ``sofac.load(SCENE)`` with the scene not yet in the
   cache: check, plan, generate, C++ build, load and instantiate. The C++ compiler's share is shown
   separately; the target is <= 3 s. The median of ``--cold-repeat`` compiles, each into an empty
   scene cache (the host module, loaded once, is not rebuilt);
3. warm load, per scene, in fresh processes (the scene now in the cache, with its warm record:
   no parsing, checking, planning or generating): ``python -c "import sofac; sofac.load(SCENE)"``,
   timed inside the process from before ``import sofac`` to the instance being ready (target
   <= 50 ms; numpy, imported first, is timed apart), and the same process timed from outside,
   which adds the interpreter's start-up. The median of ``--repeat`` processes. Also
   ``sofac.load(SCENE)`` again in this process, where the imports are done (what a script or a
   notebook that loads several scenes pays for each after the first);
4. step cost: milliseconds per ``sim.step()``, the median of a few batches of about 0.2 s each.

Scenes that sofac cannot compile yet are listed as unsupported, with the first reason.

    python benchmarks/compile_times.py                 # the bundled scenes (scenes/*.scn)
    python benchmarks/compile_times.py --repeat 9 a.scn
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from machine import describe

REPO = Path(__file__).resolve().parents[1]
COLD_TARGET_S = 3.0
WARM_TARGET_MS = 50.0

# Runs in a fresh interpreter: numpy's import (which any numerical Python program pays, and which
# sofac needs), then `import sofac` and the load up to a ready instance, in seconds.
WARM_PROBE = """\
import json, sys, time
started = time.perf_counter()
import numpy
imported = time.perf_counter()
import sofac
sim = sofac.load(sys.argv[1])
done = time.perf_counter()
assert sim.compiled.warm, "the scene was not taken from its warm record (warm.py)"
print(json.dumps({"numpy": imported - started, "sofac": done - imported}))
"""


@dataclass
class Result:
    scene: str
    dofs: int = 0
    cold_s: float = 0.0  # sofac.load with an empty scene cache
    build_s: float = 0.0  # the C++ compiler's share of it
    warm_ms: float = 0.0  # import sofac + sofac.load in a fresh process (after numpy), timed inside it
    numpy_ms: float = 0.0  # import numpy in that process, before
    process_ms: float = 0.0  # the whole process, timed from outside (interpreter start-up included)
    again_ms: float = 0.0  # sofac.load of the cached scene again in this process (imports done)
    step_us: float = 0.0
    unsupported: str = ""


def machine() -> str:
    from sofac.build import compiler as build

    compiler = build.compiler()
    try:
        version = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=False)
        compiler = version.stdout.splitlines()[0] if version.stdout else compiler
    except OSError:
        pass
    system = f"{platform.system()} {platform.release()}"
    return f"{describe()}, {system}; {compiler}; Python {platform.python_version()}"


def build_host() -> tuple[float, bool]:
    """Build the host module into the fresh cache; then load it and sofac's stages (not timed), so
    that the first scene's cold compile does not pay for imports."""
    from sofac.build import compiler as build

    started = time.perf_counter()
    built = build.build_host()
    seconds = time.perf_counter() - started
    from sofac import pipeline  # noqa: F401  (the stages, imported before timing)
    from sofac.codegen import cpp  # noqa: F401
    from sofac.plan import planner  # noqa: F401
    from sofac.simulation import loader

    loader.host()
    return seconds, built.cached


def cold(scene: Path, result: Result, cache: str, repeat: int) -> object | None:
    """Compile and instantiate ``scene``, not in the cache yet, ``repeat`` times (the first in
    ``cache``, the others each in a new empty folder); the median time. The simulation, or None if
    sofac cannot compile the scene."""
    import sofac
    from sofac.diagnostics import Severity

    totals, builds = [], []
    sim = None
    for attempt in range(repeat):
        os.environ["SOFAC_CACHE_DIR"] = (
            cache if attempt == 0 else tempfile.mkdtemp(prefix="again-", dir=cache)
        )
        started = time.perf_counter()
        try:
            loaded = sofac.load(scene)
        except sofac.SceneError as error:
            first = next((d for d in error.diagnostics if d.severity is Severity.ERROR), None)
            result.unsupported = f"{first.code}: {first.message}" if first else str(error)
            return None
        finally:
            os.environ["SOFAC_CACHE_DIR"] = cache
        totals.append(time.perf_counter() - started)
        builds.append(loaded.compiled.built.seconds)
        if loaded.compiled.built.cached:
            print(f"warning: {scene.name} was already in the fresh cache (same code as an earlier scene?)")
        sim = sim or loaded
    result.cold_s = statistics.median(totals)
    result.build_s = statistics.median(builds)
    result.dofs = sum(state.size for state in sim.states() if not state.mapped)  # type: ignore[union-attr]
    return sim


def warm(scene: Path, result: Result, repeat: int, env: dict[str, str]) -> None:
    inside, imports, outside = [], [], []
    for _ in range(repeat):
        started = time.perf_counter()
        run = subprocess.run(
            [sys.executable, "-c", WARM_PROBE, str(scene)],
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        outside.append(time.perf_counter() - started)
        if run.returncode != 0:
            raise RuntimeError(f"warm load of {scene} failed:\n{run.stderr}")
        times = json.loads(run.stdout.strip().splitlines()[-1])
        inside.append(times["sofac"])
        imports.append(times["numpy"])
    result.warm_ms = 1000 * statistics.median(inside)
    result.numpy_ms = 1000 * statistics.median(imports)
    result.process_ms = 1000 * statistics.median(outside)
    import sofac

    again = []
    for _ in range(repeat):
        started = time.perf_counter()
        sofac.load(scene)
        again.append(time.perf_counter() - started)
    result.again_ms = 1000 * statistics.median(again)


def step_cost(sim: object, batches: int = 5, seconds: float = 0.2) -> float:
    """Median microseconds per step over ``batches`` batches of about ``seconds`` each."""
    import sofac

    step = sim.step  # type: ignore[attr-defined]
    try:
        step(10)  # warm up: caches, first-touch page faults
        started = time.perf_counter()
        step(10)
        per_step = max((time.perf_counter() - started) / 10, 1e-7)
        count = max(1, int(seconds / per_step))
        samples = []
        for _ in range(batches):
            started = time.perf_counter()
            step(count)
            samples.append((time.perf_counter() - started) / count)
    except sofac.SimulationDiverged:
        return float("nan")
    return 1e6 * statistics.median(samples)


def table(results: list[Result], host: tuple[float, bool]) -> str:
    header = (
        "| scene | DOFs | cold compile (s) | of which C++ (s) | cold / 3 s | warm load (ms) | warm / 50 ms "
        "| numpy import before it (ms) | whole process (ms) | again in-process (ms) | step (µs) |"
    )
    lines = [header, "|" + "---|" * (header.count(" | ") + 1)]
    for r in results:
        if r.unsupported:
            lines.append(f"| {r.scene} | unsupported: {r.unsupported} |")
            continue
        lines.append(
            f"| {r.scene} | {r.dofs} | {r.cold_s:.2f} | {r.build_s:.2f} | {r.cold_s / COLD_TARGET_S:.2f} "
            f"| {r.warm_ms:.0f} | {r.warm_ms / WARM_TARGET_MS:.2f} | {r.numpy_ms:.0f} | {r.process_ms:.0f} "
            f"| {r.again_ms:.0f} "
            f"| {r.step_us:.3g} |"
        )
    seconds, cached = host
    lines.append("")
    lines.append(
        f"Host module (pybind11, built once per installation): {seconds:.2f} s"
        + (" (found in the cache!)" if cached else "")
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("scenes", nargs="*", type=Path, help="scenes (default: scenes/*.scn)")
    parser.add_argument("--repeat", type=int, default=5, help="fresh processes per warm load (median)")
    parser.add_argument("--cold-repeat", type=int, default=3, help="cold compiles per scene (median)")
    parser.add_argument("--json", type=Path, help="also write the results to this file")
    args = parser.parse_args(argv)
    scenes = [p.resolve() for p in args.scenes] or sorted((REPO / "scenes").glob("*.scn"))

    with tempfile.TemporaryDirectory(prefix="sofac-bench-cache-") as cache:
        os.environ["SOFAC_CACHE_DIR"] = cache
        env = {**os.environ, "SOFAC_CACHE_DIR": cache}
        print(f"machine: {machine()}")
        print(f"fresh cache: {cache}")
        host = build_host()
        print(f"host module built in {host[0]:.2f} s")
        results = []
        for scene in scenes:
            result = Result(scene.name)
            sim = cold(scene, result, cache, max(1, args.cold_repeat))
            if sim is not None:
                result.step_us = step_cost(sim)
                warm(scene, result, args.repeat, env)
                print(
                    f"{scene.name}: cold {result.cold_s:.2f} s (C++ {result.build_s:.2f} s), "
                    f"warm {result.warm_ms:.0f} ms (again in-process {result.again_ms:.0f} ms), "
                    f"{result.step_us:.3g} us/step"
                )
            else:
                print(f"{scene.name}: unsupported ({result.unsupported})")
            results.append(result)
    print()
    print(table(results, host))
    if args.json:
        payload = {"machine": machine(), "host_s": host[0], "results": [r.__dict__ for r in results]}
        args.json.write_text(json.dumps(payload, indent=1))
    compiled = [r for r in results if not r.unsupported]
    met = all(r.cold_s <= COLD_TARGET_S and r.warm_ms <= WARM_TARGET_MS for r in compiled)
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
