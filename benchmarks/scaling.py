"""Time per step against the number of DOFs, from 10^3 to 10^6, on the W1 / W2 cloth.

For each cloth size N (3 N^2 DOFs), the W1 cloth (explicit symplectic Euler, springs) and the W2
cloth (implicit Euler + CG, 25 iterations, tolerance = threshold = 0), written with a grid topology
and a RegularGridSpringForceField (``grid_cloth_scene``: the same springs, stiffnesses, masses and
solvers as ``scenegen.py``'s spring lists; they agree to rounding), are loaded with ``sofac.load``
and stepped: after warm-up steps, the fastest of ``--batches`` timed batches of about ``--seconds``
each. W2's time per CG iteration is its step
time divided by the 25 iterations (so it includes the step's force pass and right-hand side, one
product's worth: 26 products per step). The fitted slope is that of log(time) against log(DOFs)
by least squares: 1 means linear.

    python benchmarks/scaling.py                          # 10^3 .. 10^6 DOFs, table + plot
    python benchmarks/scaling.py --sizes 18 32 58 --plot out.png --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import scenegen  # noqa: E402
from machine import describe  # noqa: E402

# N such that 3 N^2 runs from ~10^3 to ~10^6 DOFs, about two sizes per decade.
SIZES = (18, 32, 58, 100, 183, 333, 577)
CG = scenegen.CG_ITERATIONS


def grid_cloth_scene(n: int, implicit: bool) -> str:
    """The W1 / W2 cloth as a RegularGridTopology n x 1 x n with a RegularGridSpringForceField:
    the same springs (edges and both face diagonals, 1000 N/m each: SOFA divides the given stiffness
    by the rest length), the same mass, corners and solvers, without an XML list of springs (the
    list scenes pass lxml's 10 MB attribute limit beyond ~250,000 DOFs)."""
    h = 1.0 / (n - 1)
    k = scenegen.CLOTH_STIFFNESS
    gx, gy, gz = scenegen.GRAVITY
    solver = (
        '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
        f'<CGLinearSolver iterations="{CG}" tolerance="0" threshold="0"/>'
        if implicit
        else '<EulerExplicitSolver symplectic="1"/>'
    )
    return (
        f'<Node name="root" gravity="{gx!r} {gy!r} {gz!r}" '
        f'dt="{scenegen.W2_DT if implicit else scenegen.W1_DT!r}"><DefaultAnimationLoop/>\n'
        f'  <Node name="cloth">{solver}\n'
        f'    <RegularGridTopology name="grid" nx="{n}" ny="1" nz="{n}" xmin="0" xmax="1" ymin="0" ymax="0" '
        'zmin="0" zmax="1"/>\n'
        '    <MechanicalObject template="Vec3d" name="dofs"/>\n'
        f'    <UniformMass template="Vec3d" name="mass" vertexMass="{scenegen.CLOTH_VERTEX_MASS!r}"/>\n'
        f'    <FixedProjectiveConstraint template="Vec3d" name="corners" indices="0 {n - 1}"/>\n'
        f'    <RegularGridSpringForceField name="springs" linesStiffness="{k * h!r}" '
        f'quadsStiffness="{k * h * 2**0.5!r}" linesDamping="0" quadsDamping="0"/>\n'
        "  </Node>\n</Node>\n"
    )


def time_steps(sim: object, seconds: float, batches: int) -> float:
    """Seconds per step: the fastest of ``batches`` batches of about ``seconds`` each, in the
    process's CPU time (on a shared machine, other processes' time slices do not count)."""
    sim.step(3)  # type: ignore[attr-defined]
    started = time.process_time()
    sim.step(2)  # type: ignore[attr-defined]
    estimate = max((time.process_time() - started) / 2, 1e-7)
    steps = max(1, int(seconds / estimate))
    best = float("inf")
    for _ in range(batches):
        started = time.process_time()
        sim.step(steps)  # type: ignore[attr-defined]
        best = min(best, (time.process_time() - started) / steps)
    return best


def measure(sizes: Sequence[int], seconds: float, batches: int, log: bool = True) -> list[dict[str, float]]:
    import sofac

    rows = []
    with tempfile.TemporaryDirectory(prefix="sofac-scaling-") as folder:
        for n in sizes:
            row: dict[str, float] = {"n": n, "dofs": 3 * n * n, "springs": len(scenegen.cloth(n).springs)}
            for implicit, key in ((False, "explicit"), (True, "implicit")):
                path = Path(folder) / f"cloth_{key}_{n}.scn"
                path.write_text(grid_cloth_scene(n, implicit))
                started = time.perf_counter()
                sim = sofac.load(path)
                row[f"{key}_load_s"] = time.perf_counter() - started
                row[f"{key}_step_s"] = time_steps(sim, seconds, batches)
                del sim
                path.unlink()
            row["cg_iteration_s"] = row["implicit_step_s"] / CG
            rows.append(row)
            if log:
                print(
                    f"N={n:4d} DOFs={row['dofs']:8d}: explicit {row['explicit_step_s'] * 1e3:.4g} ms/step, "
                    f"implicit {row['implicit_step_s'] * 1e3:.4g} ms/step "
                    f"({row['cg_iteration_s'] * 1e3:.4g} ms per CG iteration)",
                    file=sys.stderr,
                    flush=True,
                )
    return rows


def slope(dofs: Sequence[float], seconds: Sequence[float]) -> float:
    """Least-squares slope of log(seconds) against log(dofs)."""
    return float(np.polyfit(np.log(dofs), np.log(seconds), 1)[0])


def plot(rows: list[dict[str, float]], out: Path, note: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dofs = np.array([r["dofs"] for r in rows], dtype=float)
    fig, ax = plt.subplots(figsize=(7, 5))
    for key, label, marker in (
        ("explicit_step_s", "explicit step (W1)", "o"),
        ("cg_iteration_s", "CG iteration (W2 step / 25)", "s"),
    ):
        t = np.array([r[key] for r in rows]) * 1e3
        k = slope(dofs, t)
        fit = np.exp(np.polyval(np.polyfit(np.log(dofs), np.log(t), 1), np.log(dofs)))
        ax.loglog(dofs, t, marker=marker, linestyle="none", label=f"{label}: slope {k:.2f}")
        ax.loglog(dofs, fit, linestyle="--", linewidth=1, color=ax.lines[-1].get_color())
    ax.set_xlabel("degrees of freedom")
    ax.set_ylabel("ms")
    ax.set_title("sofac: time against DOFs (mass-spring cloth, one thread)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.text(0.01, 0.01, note, fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    fig.savefig(out, dpi=110)
    plt.close(fig)


def table(rows: list[dict[str, float]]) -> str:
    lines = [
        "| N | DOFs | springs | explicit ms/step | implicit ms/step | ms per CG iteration "
        "| load s (explicit) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['dofs']} | {r['springs']} | {r['explicit_step_s'] * 1e3:.4g} | "
            f"{r['implicit_step_s'] * 1e3:.4g} | {r['cg_iteration_s'] * 1e3:.4g} | "
            f"{r['explicit_load_s']:.2g} |"
        )
    dofs = [r["dofs"] for r in rows]
    if len(rows) >= 2:
        lines.append("")
        lines.append(
            f"Fitted slopes of log(time) against log(DOFs): explicit step "
            f"{slope(dofs, [r['explicit_step_s'] for r in rows]):.3f}, CG iteration "
            f"{slope(dofs, [r['cg_iteration_s'] for r in rows]):.3f} (1 = linear)."
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument(
        "--sizes", type=int, nargs="+", default=list(SIZES), help="cloth sizes N (3 N^2 DOFs)"
    )
    parser.add_argument("--seconds", type=float, default=0.3, help="length of a timed batch (default 0.3 s)")
    parser.add_argument("--batches", type=int, default=3, help="timed batches per scene (default 3)")
    parser.add_argument("--plot", type=Path, default=HERE / "scaling.png", help="the plot (PNG)")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON")
    parser.add_argument("--markdown", type=Path, help="also write the table as Markdown")
    args = parser.parse_args(argv)
    before = f"{describe()}, Python {platform.python_version()}"
    rows = measure(args.sizes, args.seconds, args.batches)
    note = f"{time.strftime('%Y-%m-%d %H:%M')}; {before}"
    text = table(rows)
    print(note)
    print(text)
    if args.plot:
        plot(rows, args.plot, note)
    if args.json:
        args.json.write_text(json.dumps({"machine": note, "rows": rows}, indent=1))
    if args.markdown:
        args.markdown.write_text(note + "\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
