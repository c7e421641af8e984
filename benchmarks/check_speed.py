"""How long ``sofac check`` takes per scene, against the 100 ms target of issue 2.

Times the command in-process and warm: ``sofac.cli.main.main(["check", SCENE])`` with its output
discarded, after one untimed run (imports, registry tables and file caches are hot). This is what a
long-running tool or a folder check pays per scene; a fresh ``sofac check`` process adds the
interpreter and import start-up once, which ``--cold`` measures separately.

    python benchmarks/check_speed.py                 # bundled scenes + a few corpus scenes
    python benchmarks/check_speed.py --repeat 50 my.scn other.scn
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from sofac.cli.main import main as sofac_main

REPO = Path(__file__).resolve().parents[1]
TARGET_MS = 100.0
# Corpus scenes of various sizes: meshes to read, includes and macros, BoxROI, many components.
CORPUS_SCENES = (
    "Demos/liver.scn",
    "Demos/chainHybrid.scn",
    "Demos/collisionMultiple.scn",
    "Demos/caduceus_penalty.scn",
    "Component/SolidMechanics/FEM/TetrahedronFEMForceField.scn",
    "Component/Engine/Select/BoxROI_1d.scn",
    "Tutorials/StepByStep/Dentistry_Haptics/dentalSurgery_04.scn",
)


def find_corpus() -> Path | None:
    """``../shared/corpus/sofa`` beside the checkout, else ``$SOFAC_SHARED/corpus/sofa``."""
    candidates = [REPO.parent / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    for shared in candidates:
        if (shared / "corpus" / "sofa").is_dir():
            return shared / "corpus" / "sofa"
    return None


def default_scenes() -> list[Path]:
    scenes = sorted((REPO / "scenes").glob("*.scn"))
    corpus = find_corpus()
    if corpus is None:
        print("(corpus not found: timing the bundled scenes only; set SOFAC_SHARED)", file=sys.stderr)
    else:
        scenes += [corpus / name for name in CORPUS_SCENES if (corpus / name).is_file()]
    return scenes


def check_once(scene: Path) -> tuple[float, int]:
    """One in-process ``sofac check SCENE``: (seconds, exit code)."""
    sink = io.StringIO()
    started = time.perf_counter()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        code = sofac_main(["check", str(scene)])
    return time.perf_counter() - started, code


def cold_start(scene: Path) -> float:
    """A fresh ``python -m sofac check SCENE`` process, wall-clock seconds."""
    started = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "sofac", "check", "--quiet", str(scene)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=False,
    )
    return time.perf_counter() - started


def label(scene: Path) -> str:
    corpus = find_corpus()
    for base, prefix in ((REPO, ""), (corpus, "corpus:")):
        if base is not None:
            with contextlib.suppress(ValueError):
                return prefix + scene.resolve().relative_to(base.resolve()).as_posix()
    return str(scene)


def run(scenes: Sequence[Path], repeat: int, cold: bool) -> int:
    width = max(len(label(s)) for s in scenes)
    header = f"{'scene':<{width}}  {'median ms':>9}  {'min ms':>7}  {'x target':>8}  exit"
    if cold:
        header += "  cold ms"
    print(header)
    print("-" * len(header))
    medians: list[float] = []
    for scene in scenes:
        check_once(scene)  # warm-up, untimed
        times = []
        code = 0
        for _ in range(repeat):
            seconds, code = check_once(scene)
            times.append(seconds * 1000)
        median = statistics.median(times)
        medians.append(median)
        line = (
            f"{label(scene):<{width}}  {median:9.2f}  {min(times):7.2f}  {median / TARGET_MS:8.3f}  {code:>4}"
        )
        if cold:
            line += f"  {cold_start(scene) * 1000:7.0f}"
        print(line)
    worst = max(medians)
    print("-" * len(header))
    print(
        f"{len(scenes)} scenes, {repeat} runs each: median of medians {statistics.median(medians):.2f} ms, "
        f"slowest {worst:.2f} ms = {worst / TARGET_MS:.3f} x the {TARGET_MS:.0f} ms target"
    )
    return 0 if worst < TARGET_MS else 1


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("scenes", nargs="*", type=Path, help="scene files (default: bundled + corpus sample)")
    parser.add_argument("--repeat", type=int, default=20, help="timed runs per scene (default 20)")
    parser.add_argument("--cold", action="store_true", help="also time one fresh `python -m sofac` process")
    return parser.parse_args(argv)


def cli(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    scenes = list(args.scenes) or default_scenes()
    missing = [str(s) for s in scenes if not s.is_file()]
    if missing:
        print(f"check_speed: no such file: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.repeat < 1:
        print("check_speed: --repeat must be at least 1", file=sys.stderr)
        return 2
    return run(scenes, args.repeat, args.cold)


if __name__ == "__main__":
    sys.exit(cli())
