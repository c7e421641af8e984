"""OpenMP speed-up: the same scene loaded with ``threads=1`` and ``threads=N``, stepped in one run.

sofac's OpenMP is optional and off by default (``sofac.load(path, threads=N)``, ``--threads N``):
tetrahedral and hexahedral FEM loops of at least ``MIN_ELEMENTS_PER_THREAD`` elements per thread
are split over the threads, and groups (ODE solvers) that share no buffer step side by side. The
results equal the serial ones bit for bit; this script checks that too, then reports wall time per
step (threads add CPU time; the gain is in elapsed time) and the speed-up.

    python benchmarks/openmp.py                      # the W3 beam, SOFA's e beam, two beams side by side
    python benchmarks/openmp.py --threads 2 --seconds 3 my.scn

The machine is shared: each figure is the fastest of ``--batches`` batches, and the two variants
alternate batch by batch so that a busy spell hits both.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import sofac  # noqa: E402
from machine import describe  # noqa: E402

SHARED_BEAM = HERE.parents[1] / "shared" / "reference" / "sofa" / "scenes" / "e_beam_large_cg25_noexport.scn"


def two_beams(folder: Path) -> Path:
    """Two W3 beams (10 x 10 x 50 nodes, 23,814 tetrahedra each), each with its own solver."""
    beam = (HERE / "scenes" / "w3_beam_cg25.scn").read_text()
    start, end = beam.index('<Node name="beam"'), beam.rindex("</Node>")
    body = beam[start:end]
    shifted = body
    for old, new in (
        ('name="beam"', 'name="beam2"'),
        ('min="0 0 0" max="1 1 5.0"', 'min="2 0 0" max="3 1 5.0"'),
        ('box="-0.01 -0.01 -0.01 1.01 1.01 0.01"', 'box="1.99 -0.01 -0.01 3.01 1.01 0.01"'),
    ):
        assert old in shifted, old
        shifted = shifted.replace(old, new, 1)
    path = folder / "two_beams.scn"
    path.write_text(beam[:start] + body + shifted + beam[end:])
    return path


def states(sim: sofac.Simulation) -> np.ndarray:
    return np.concatenate([np.ravel(sim[p].position) for p in sim.objects()])


def measure(path: Path, threads: int, seconds: float, batches: int) -> dict[str, float | str | bool]:
    sims = {t: sofac.load(path, threads=t) for t in (1, threads)}
    for sim in sims.values():
        sim.step(3)
    same = bool(np.array_equal(states(sims[1]), states(sims[threads])))
    start = time.perf_counter()
    sims[1].step(1)
    per_batch = max(1, int(seconds / max(time.perf_counter() - start, 1e-6)))
    best = {t: float("inf") for t in sims}
    for _ in range(batches):
        for t, sim in sims.items():
            start = time.perf_counter()
            sim.step(per_batch)
            best[t] = min(best[t], (time.perf_counter() - start) / per_batch * 1e3)
    return {
        "scene": path.name,
        "serial ms": best[1],
        "threaded ms": best[threads],
        "speed-up": best[1] / best[threads],
        "identical": same,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "scenes", nargs="*", type=Path, help="scenes (default: the W3 beam, SOFA's e beam, two beams)"
    )
    parser.add_argument("--threads", type=int, default=2, help="threads of the parallel variant (default 2)")
    parser.add_argument("--seconds", type=float, default=2.0, help="length of a batch (default 2 s)")
    parser.add_argument("--batches", type=int, default=3, help="batches per variant (default 3)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        scenes = args.scenes or [
            HERE / "scenes" / "w3_beam_cg25.scn",
            *([SHARED_BEAM] if SHARED_BEAM.is_file() else []),
            two_beams(Path(folder)),
        ]
        print(f"Machine: {describe()}; {args.threads} threads against 1, wall time per step.\n")
        print("| scene | 1 thread (ms/step) | threads (ms/step) | speed-up | same numbers |")
        print("|---|---|---|---|---|")
        for scene in scenes:
            row = measure(scene, args.threads, args.seconds, args.batches)
            print(
                f"| {row['scene']} | {row['serial ms']:.2f} | {row['threaded ms']:.2f} | "
                f"{row['speed-up']:.2f}x | {'yes' if row['identical'] else 'NO'} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
