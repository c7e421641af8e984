"""FreeMotionAnimationLoop's constraint step, measured: each scene's step split into its parts, and
the solve's cost against the number of constraint rows.

    python benchmarks/constraints.py                       # SOFA's constraint scenes, then the rows family
    python benchmarks/constraints.py --only scenes         # or: --only rows
    python benchmarks/constraints.py --sides 2 4 8 --solvers bgs --plot out.png --markdown out.md

The parts are timed inside the compiled step (a steady clock, ``<loop>.constraint_report``'s
``*_seconds`` fields, ``sofac.plan.ir.CONSTRAINT_REPORT_FIELDS``): the collision pipeline
(detection and the contacts' response), the groups' free motion (their solves), the constraint
phase's rows (J, free positions of mapped states, W and the forces cleared), violations, W (the
corrections' compliance), the solve, the correction, and the groups' projections and mappings
after it ("finish"). "rest" is the step's wall time (``sim.step(n)`` from Python) minus those.

1. **Scenes**: SOFA's regression scenes under FreeMotionAnimationLoop (``../shared/corpus/sofa``),
   each run from its start for its regression's step count, the best of ``--repeat`` runs (reset
   between them); ms per step averaged over the run, and the mean constraint rows per step.
2. **Rows**: ``side`` x ``side`` particles resting on a floor (UncoupledConstraintCorrection, friction
   0.5: three rows per contact, 12 to 2028 rows), for BlockGaussSeidel, NNCG and LCP (built); after
   warm-up steps, the fastest of ``--batches`` timed batches; a log-log plot of ms per step against
   the rows and the least-squares exponent of each part from ``--fit-from`` rows on.

Wall-clock time (the parts are wall-clock too): on a machine shared with other jobs, the load
average is printed with the results.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO / "tests"))

import sofac  # noqa: E402
from lagrangian_scenes import CONTACT, contact_root, particles, static_floor  # noqa: E402
from machine import describe  # noqa: E402
from sofac.plan.ir import CONSTRAINT_REPORT_FIELDS, Response  # noqa: E402

# SOFA's regression scenes under FreeMotionAnimationLoop: (scene, steps timed, steps run before),
# their regression's step counts from the start; and the falling beam at rest (92 contacts).
SCENES = (
    ("Component/Constraint/Lagrangian/BilateralLagrangianConstraint_PGS.scn", 100, 0),
    ("Component/Constraint/Lagrangian/BilateralLagrangianConstraint_NNCG.scn", 100, 0),
    ("Component/Constraint/Lagrangian/BilateralLagrangianConstraint_UGS.scn", 100, 0),
    ("Component/Collision/Response/FrictionContact.scn", 100, 0),
    ("Component/Collision/Response/RuleBasedContactManager.scn", 100, 0),
    ("Component/Constraint/Lagrangian/FrictionContact_LCP_with_friction.scn", 500, 0),
    ("Component/Constraint/Lagrangian/FrictionContact_LCP_without_friction.scn", 500, 0),
    ("Component/Constraint/Projective/LinearVelocityProjectiveConstraint.scn", 100, 0),
    ("Demos/fallingBeamLagrangianCollision.scn", 46, 0),
    ("Demos/fallingBeamLagrangianCollision.scn", 20, 80),
)
# The parts of a step, as the report names them (without "_seconds"), in step order.
PARTS = ("detection", "free_motion", "rows", "violation", "compliance", "solve", "correction", "finish")
HEADINGS = {"free_motion": "free motion", "rows": "rows (J)", "compliance": "W"}
SOLVERS = {
    "bgs": '<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="1000"/>',
    "nncg": '<NNCGConstraintSolver tolerance="1e-12" maxIterations="1000"/>',
    "lcp": '<LCPConstraintSolver maxIt="1000" tolerance="1e-12" initial_guess="true" build_lcp="true" '
    'mu="0.5"/>',
}
SIDES = (2, 3, 4, 6, 8, 12, 16, 20, 26)  # 3 side^2 rows: 12 .. 2028
MASS = 0.01


def shared() -> Path | None:
    for candidate in (os.environ.get("SOFAC_SHARED"), REPO.parent / "shared"):
        if candidate and (Path(candidate) / "corpus" / "sofa").is_dir():
            return Path(candidate)
    return None


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """The scenes' warnings (unknown attributes, a grown contact capacity) are not what is measured."""
    from sofac.scene_warnings import quiet as quiet_scene

    with quiet_scene(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def report_key(sim: sofac.Simulation) -> str | None:
    """The key of the scene's constraint report (None: no FreeMotionAnimationLoop)."""
    return next((b.key for b in sim.spec.buffers if b.key.endswith(".constraint_report")), None)


def load(path: Path) -> sofac.Simulation:
    """The scene, without the copy of its state that ``step()`` keeps to replay a divergence (a
    copy of W and the other carried buffers at each call, not part of a step)."""
    sim = sofac.load(path)
    sim.keep_last_finite = False
    return sim


@dataclass
class Split:
    """ms per step: the step's wall time and each part's; the solve's last iteration count."""

    total: float
    parts: dict[str, float] = field(default_factory=dict)
    iterations: float = 0.0
    rows: float = 0.0  # mean constraint rows per step

    @property
    def rest(self) -> float:
        return self.total - sum(self.parts.values())


def timed(sim: sofac.Simulation, steps: int) -> Split:
    """Runs ``steps`` steps in one call; the wall time and the parts' seconds, per step, in ms."""
    key = report_key(sim)
    before = sim.output(key).copy() if key else np.zeros(len(CONSTRAINT_REPORT_FIELDS))
    started = time.perf_counter()
    sim.step(steps)
    total = (time.perf_counter() - started) / steps * 1e3
    after = sim.output(key) if key else before
    spent = after - before
    parts = {p: spent[CONSTRAINT_REPORT_FIELDS.index(f"{p}_seconds")] / steps * 1e3 for p in PARTS}
    return Split(total, parts, float(after[CONSTRAINT_REPORT_FIELDS.index("iterations")]))


def rows_per_step(sim: sofac.Simulation, steps: int, skip: int = 0) -> float:
    """The mean number of constraint rows a step of the scene solves, stepping it one step at a time
    from a reset and ``skip`` steps: the scene's own rows, plus per contact of the step one row
    (three with friction)."""
    plan = sim.plan
    if plan.constraints is None:
        return 0.0
    lagrangian = [c for c in plan.collisions if c.response is Response.FRICTION_CONTACT and c.pairs]
    if not lagrangian:
        return float(plan.constraints.capacity)
    sim.reset()
    if skip:
        sim.step(skip)
    collision = lagrangian[0]  # (one pipeline: several are not compiled under FreeMotionAnimationLoop)
    contacts = sim.output(next(b.key for b in sim.spec.buffers if b.key.endswith(".contactReport")))
    lines = 3 if collision.mu > 0 else 1
    total = 0.0
    for _ in range(steps):
        sim.step(1)
        total += collision.static_rows + lines * contacts[0]
    return total / steps


def scene_split(path: Path, steps: int, repeat: int, skip: int = 0) -> Split:
    """The best of ``repeat`` runs of ``steps`` steps (by wall time), each from the scene's start
    after ``skip`` steps."""
    with quiet():
        sim = load(path)
        best: Split | None = None
        for _ in range(repeat):
            sim.reset()
            if skip:
                sim.step(skip)
            split = timed(sim, steps)
            if best is None or split.total < best.total:
                best = split
        assert best is not None
        best.rows = rows_per_step(sim, steps, skip)
    return best


def particles_scene(side: int, solver: str) -> str:
    """side x side particles of MASS resting at the contact distance on a static floor, 0.1 apart
    (off the floor's diagonal), friction 0.5: 3 side^2 constraint rows every step."""
    i, k = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    points = np.column_stack([-2.5 + 0.1 * i.ravel(), np.full(side * side, CONTACT), -2.45 + 0.1 * k.ravel()])
    return (
        contact_root(SOLVERS[solver], 0.5)
        + static_floor("-3 0 -3  3 0 -3  3 0 3  -3 0 3")
        + particles("Particles", points, MASS)
        + "</Node>\n"
    )


def rows_split(side: int, solver: str, batches: int, seconds: float, folder: Path) -> Split:
    """The fastest of ``batches`` batches of about ``seconds`` each, after warm-up steps."""
    path = folder / f"particles_{solver}_{side}.scn"
    path.write_text(particles_scene(side, solver))
    with quiet():
        sim = load(path)
        warm = timed(sim, 5)  # the first step grows the contact capacity past 128 contacts
        steps = max(3, int(seconds * 1e3 / max(warm.total, 1e-3)))
        best = min((timed(sim, steps) for _ in range(batches)), key=lambda s: s.total)
    best.rows = 3.0 * side * side
    return best


def slope(rows: Sequence[float], ms: Sequence[float]) -> float:
    """Least-squares slope of log(ms) against log(rows)."""
    return float(np.polyfit(np.log(rows), np.log(ms), 1)[0])


def _cell(value: float) -> str:
    return f"{value:.3g}"


def split_table(names: Sequence[str], splits: Sequence[Split], markdown: bool) -> str:
    heading = ["scene", "rows/step", "ms/step", *(HEADINGS.get(p, p) for p in PARTS), "rest", "iterations"]
    lines = [
        [
            name,
            f"{s.rows:.1f}",
            _cell(s.total),
            *(_cell(s.parts[p]) for p in PARTS),
            _cell(s.rest),
            f"{s.iterations:g}",
        ]
        for name, s in zip(names, splits, strict=True)
    ]
    return render([heading, *lines], markdown)


def render(cells: Sequence[Sequence[str]], markdown: bool) -> str:
    if markdown:
        out = ["| " + " | ".join(cells[0]) + " |", "|" + "---|" * len(cells[0])]
        return "\n".join(out + ["| " + " | ".join(row) + " |" for row in cells[1:]])
    widths = [max(len(row[c]) for row in cells) for c in range(len(cells[0]))]
    return "\n".join(
        "  ".join(
            cell.ljust(w) if c == 0 else cell.rjust(w)
            for c, (cell, w) in enumerate(zip(row, widths, strict=True))
        )
        for row in cells
    )


def fits(results: dict[str, list[Split]], fit_from: float) -> dict[str, dict[str, float]]:
    """Per solver, the fitted exponent of each part (and of the constraint phase, the step) from
    ``fit_from`` rows on."""
    out: dict[str, dict[str, float]] = {}
    for solver, splits in results.items():
        used = [s for s in splits if s.rows >= fit_from]
        if len(used) < 2:
            continue
        rows = [s.rows for s in used]
        series = {p: [s.parts[p] for s in used] for p in ("rows", "compliance", "solve")}
        series["constraint phase"] = [sum(s.parts[p] for p in PARTS[2:7]) for s in used]
        series["step"] = [s.total for s in used]
        out[solver] = {name: slope(rows, ms) for name, ms in series.items()}
    return out


def plot(results: dict[str, list[Split]], exponents: dict[str, dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(7, 5))
    for (solver, splits), colour in zip(results.items(), ("C0", "C1", "C2", "C3"), strict=False):
        rows = [s.rows for s in splits]
        fitted = exponents.get(solver, {}).get("solve", float("nan"))
        axes.loglog(
            rows,
            [s.parts["solve"] for s in splits],
            "o-",
            color=colour,
            label=f"{solver} solve (slope {fitted:.2f})",
        )
        axes.loglog(
            rows, [s.total for s in splits], "--", color=colour, alpha=0.6, label=f"{solver} whole step"
        )
    first, splits = next(iter(results.items()))
    rows = [s.rows for s in splits]
    axes.loglog(rows, [s.parts["compliance"] for s in splits], "-.", color="grey", label=f"W build ({first})")
    axes.loglog(rows, [s.parts["rows"] for s in splits], ":", color="grey", label=f"rows phase ({first})")
    axes.set_xlabel("constraint rows (3 per resting particle)")
    axes.set_ylabel("ms per step")
    axes.set_title("sofac: constraint solve against the rows (particles resting on a floor)")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("scenes", "rows"), help="run only one of the two parts")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each SOFA scene (the best is kept)")
    parser.add_argument("--sides", type=int, nargs="+", default=list(SIDES), help="particle grids' sides")
    parser.add_argument("--solvers", nargs="+", choices=sorted(SOLVERS), default=["bgs", "nncg", "lcp"])
    parser.add_argument("--batches", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=0.3, help="length of a timed batch")
    parser.add_argument(
        "--fit-from", type=float, default=100.0, help="rows from which the exponent is fitted"
    )
    parser.add_argument("--plot", type=Path, default=HERE / "constraint_rows.png")
    parser.add_argument("--markdown", type=Path, help="also write the tables as Markdown")
    args = parser.parse_args(argv)
    print(f"{time.strftime('%Y-%m-%d %H:%M')}; {describe()}; wall clock")
    markdown: list[str] = []
    if args.only in (None, "scenes"):
        root = shared()
        if root is None:
            print("SOFA's corpus (../shared/corpus/sofa) not found: scenes skipped")
        else:
            names, splits = [], []
            for scene, steps, skip in SCENES:
                names.append(Path(scene).stem + (f" (steps {skip}-{skip + steps})" if skip else ""))
                splits.append(scene_split(root / "corpus" / "sofa" / scene, steps, args.repeat, skip))
                print(f"  {names[-1]}: {splits[-1].total:.4g} ms/step", flush=True)
            print(split_table(names, splits, markdown=False))
            markdown.append(split_table(names, splits, markdown=True))
            print("SOFA's timings (../shared/reference/sofa/timings.md) have none of these scenes: no ratio.")
    if args.only in (None, "rows"):
        results: dict[str, list[Split]] = {}
        with tempfile.TemporaryDirectory() as folder:
            for solver in args.solvers:
                results[solver] = []
                for side in args.sides:
                    results[solver].append(rows_split(side, solver, args.batches, args.seconds, Path(folder)))
                    print(f"  {solver} {side}x{side}: {results[solver][-1].total:.4g} ms/step", flush=True)
        for solver, splits in results.items():
            names = [f"{solver} {int(s.rows)} rows" for s in splits]
            print(split_table(names, splits, markdown=False))
            markdown.append(split_table(names, splits, markdown=True))
        exponents = fits(results, args.fit_from)
        for solver, fitted in exponents.items():
            line = ", ".join(f"{name} {value:.2f}" for name, value in fitted.items())
            print(f"fitted exponents ({solver}, rows >= {args.fit_from:g}): {line}")
            markdown.append(f"Fitted exponents ({solver}, rows >= {args.fit_from:g}): {line}.")
        if exponents:
            plot(results, exponents, args.plot)
            print(f"plot: {args.plot}")
    if args.markdown:
        args.markdown.write_text("\n\n".join(markdown) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
