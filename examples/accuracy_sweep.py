"""Regenerate the sweeps of ``docs/accuracy.md``: what accuracy costs in time on the bundled scenes.

For each sweep below, runs :func:`sofac.accuracy.sweep`, writes ``results.json``, ``results.csv``
and a Markdown table (``table.md``) under ``OUT/<name>/``, the two plots into ``docs/img/``
(``accuracy_<name>_error_vs_cost.png``, ``accuracy_<name>_error_vs_dt.png``) and the table into
``docs/accuracy.md``, between ``<!-- accuracy:NAME -->`` and ``<!-- /accuracy:NAME -->`` (the
prose around the tables is written by hand: re-read it when the numbers move). The liver of SOFA's
demos is not bundled: it runs when the shared scene corpus is found (``$SOFAC_SHARED``, else
``../shared`` next to the checkout).

Usage: ``python examples/accuracy_sweep.py [--out DIR] [--only NAME ...]`` (default ``out/accuracy``;
names: oscillator, hybrid_pendulum, beam, beam_damped, cloth, liver). All of them take about four
minutes on two cores, compilation included. Wall times depend on the machine; errors do not.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

from sofac.accuracy import measure as accuracy
from sofac.accuracy.plots import plot_all

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"
IMAGES = REPO / "docs" / "img"
DOC = REPO / "docs" / "accuracy.md"

HALVINGS = [0.02 / 2**k for k in range(7)]  # 0.02 ... 0.0003125

# name -> (scene, keyword arguments of sweep)
SWEEPS: dict[str, tuple[Path, dict[str, Any]]] = {
    # Analytic reference x(t) = 1 + 0.1 cos(10 t) (scenes/oscillator.analytic.py).
    "oscillator": (
        SCENES / "oscillator.scn",
        {"dts": [0.01, 0.005, 0.0025, 0.00125], "duration": 2.0, "reference": "analytic"},
    ),
    # Springs on a rigidly mapped state: the direct solver assembles them as J^T K J.
    "hybrid_pendulum": (
        SCENES / "hybrid_pendulum.scn",
        {"dts": [0.02, 0.01, 0.005, 0.0025], "duration": 2.0},
    ),
    # Undamped (Rayleigh damping removed, so that explicit and implicit solve the same equations).
    "beam": (
        SCENES / "beam.scn",
        {"dts": HALVINGS[:6], "duration": 1.0, "cg_iterations": [10, 100], "tolerances": [1e-5, 1e-9]},
    ),
    # As written: Rayleigh damping 0.1 / 0.1, which only implicit Euler models; reference
    # implicit Euler with the direct solver at dt / 16.
    "beam_damped": (
        SCENES / "beam.scn",
        {
            "solvers": ["implicit"],
            "dts": [0.04, 0.02, 0.01, 0.005, 0.0025],
            "duration": 2.0,
            "cg_iterations": [10, 100],
            "tolerances": [1e-5, 1e-9],
        },
    ),
    "cloth": (
        SCENES / "cloth.scn",
        {"dts": HALVINGS, "duration": 1.0, "cg_iterations": [25, 100], "tolerances": [1e-9]},
    ),
    "liver": (
        Path("corpus/sofa/Demos/liver.scn"),  # relative to the shared folder
        {"dts": [0.02, 0.01, 0.005, 0.0025, 0.00125], "duration": 2.0},
    ),
}


def shared_folder() -> Path | None:
    for candidate in (os.environ.get("SOFAC_SHARED"), REPO.parent / "shared"):
        if candidate and (Path(candidate) / "corpus" / "sofa").is_dir():
            return Path(candidate)
    return None


def update_doc(name: str, table: str) -> None:
    """Put ``table`` between the doc's markers for ``name`` (the doc is left alone without them)."""
    if not DOC.is_file():
        return
    text = DOC.read_text(encoding="utf-8")
    pattern = re.compile(rf"(<!-- accuracy:{name} -->\n).*?(<!-- /accuracy:{name} -->)", re.DOTALL)
    updated, count = pattern.subn(lambda m: m.group(1) + table + m.group(2), text)
    if count:
        DOC.write_text(updated, encoding="utf-8")
    else:
        print(f"{name}: no <!-- accuracy:{name} --> markers in {DOC}", file=sys.stderr)


def run(name: str, scene: Path, options: dict[str, Any], out: Path) -> None:
    started = time.perf_counter()
    result = accuracy.sweep(scene, progress=True, **options)
    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    accuracy.write_json(result, folder / "results.json")
    accuracy.write_csv(result, folder / "results.csv")
    table = accuracy.markdown_table(result, collapse_diverged=True)
    (folder / "table.md").write_text(table, encoding="utf-8")
    update_doc(name, table)
    plot_all(result, IMAGES, prefix=f"accuracy_{name}_")
    print(f"## {name} ({time.perf_counter() - started:.0f} s)\n")
    print(accuracy.format_table(result))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(REPO / "out" / "accuracy"), help="folder for results")
    parser.add_argument("--only", nargs="+", choices=list(SWEEPS), help="run only these sweeps")
    args = parser.parse_args(argv)
    shared = shared_folder()
    for name in args.only or SWEEPS:
        scene, options = SWEEPS[name]
        if name == "liver":
            if shared is None:
                print("liver: skipped (no shared scene corpus; set SOFAC_SHARED)", file=sys.stderr)
                continue
            scene = shared / scene
        run(name, scene, options, Path(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
