"""``sofac accuracy``: what accuracy costs in time (see :mod:`sofac.accuracy.measure`).

Kept apart from the sweep itself so that building the parser imports nothing heavy.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from sofac.cli.usage import EXIT_ERRORS, EXIT_OK, Failed, UsageError, reported

_T = TypeVar("_T")


def _list_of(convert: Callable[[str], _T], what: str) -> Callable[[str], list[_T]]:
    """An argparse type: a comma-separated list (spaces allowed) of ``convert``-ed items."""

    def parse(text: str) -> list[_T]:
        items = [item for item in text.replace(",", " ").split() if item]
        if not items:
            raise argparse.ArgumentTypeError(f"empty list of {what}")
        try:
            return [convert(item) for item in items]
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a list of {what}: {text!r}") from None

    return parse


def cmd_accuracy(args: argparse.Namespace) -> int:
    from sofac.accuracy import measure as accuracy

    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    for value in args.dt or ():
        if not value > 0:
            raise UsageError("--dt values must be > 0")
    if not args.duration > 0:
        raise UsageError("--duration must be > 0")
    out = Path(args.out)
    try:
        with reported():
            try:
                result = accuracy.sweep(
                    path,
                    solvers=args.solvers,
                    dts=args.dt,
                    duration=args.duration,
                    linear_solvers=args.linear_solvers,
                    cg_iterations=args.cg_iterations,
                    tolerances=args.tolerances,
                    cg_threshold=args.cg_threshold,
                    reference=args.reference,
                    rayleigh=args.rayleigh,
                    sample_interval=args.sample_interval,
                    data_roots=[Path(p) for p in args.data_path or ()],
                    progress=not args.no_progress,
                )
            except accuracy.AccuracyError as exc:
                raise UsageError(str(exc)) from None
    except Failed:
        return EXIT_ERRORS
    sys.stdout.write(accuracy.format_table(result))
    out.mkdir(parents=True, exist_ok=True)
    written = [
        accuracy.write_json(result, out / "results.json"),
        accuracy.write_csv(result, out / "results.csv"),
    ]
    if not args.no_plots:
        from sofac.accuracy.plots import plot_all

        written.extend(plot_all(result, out))
    print(f"sofac: wrote {', '.join(str(p) for p in written)}", file=sys.stderr)
    return EXIT_OK


def register(commands: argparse._SubParsersAction, epilog: str) -> None:
    """Add ``accuracy`` to the ``sofac`` parser."""
    description = (
        "Run SCENE under many integration settings (the ODE solver swapped at compile time, several "
        "time steps) against a reference run, and measure each configuration: max and RMS position "
        "error over the run relative to the scene's size, energy drift, wall time per simulated "
        "second (stepping only; compile time apart), divergence. Writes a table, OUT/results.json, "
        "OUT/results.csv and two plots (error against cost, error against dt with the measured order "
        "of convergence)."
    )
    parser = commands.add_parser(
        "accuracy",
        help="measure what accuracy costs in time: a scene under many solvers and time steps",
        description=description,
        epilog=(
            "solvers: euler (forward), symplectic, rk2, rk4, implicit (expands over --linear-solvers: "
            "direct, and cg over --cg-iterations x --tolerances), variational "
            "(VariationalSymplecticSolver with a direct solver), or a label such as "
            "implicit-cg:50:1e-8. reference: analytic (the scene's <scene>.analytic.py), SOLVER@DT, "
            "SOLVER@/N (the smallest dt divided by N); default rk4@/16 (implicit-direct@/16 when the "
            "scene's Rayleigh damping is kept, or when rk4 diverges). " + epilog
        ),
    )
    parser.add_argument("scene", metavar="SCENE", help="the scene file")
    parser.add_argument(
        "--solvers",
        type=_list_of(str, "solvers"),
        default=["euler", "symplectic", "rk2", "rk4", "implicit"],
        metavar="LIST",
        help="comma-separated (default: euler,symplectic,rk2,rk4,implicit)",
    )
    parser.add_argument(
        "--dt",
        type=_list_of(float, "time steps"),
        metavar="LIST",
        help="time steps, each dividing the largest (default: the scene's dt x 2, 1, 1/2, 1/4)",
    )
    parser.add_argument(
        "--linear-solvers",
        type=_list_of(str, "linear solvers"),
        default=["cg", "direct"],
        metavar="LIST",
        help="for implicit Euler: cg, direct (default: both)",
    )
    parser.add_argument(
        "--cg-iterations",
        type=_list_of(int, "integers"),
        default=[25],
        metavar="LIST",
        help="CG iteration caps (default: 25)",
    )
    parser.add_argument(
        "--tolerances",
        type=_list_of(float, "numbers"),
        default=[1e-5],
        metavar="LIST",
        help="CG tolerances (default: 1e-5)",
    )
    parser.add_argument(
        "--cg-threshold",
        type=float,
        metavar="X",
        help="CG's absolute threshold on p.Ap (default 1e-30, negligible; SOFA's default is 1e-5, "
        "which stops CG early in light scenes)",
    )
    parser.add_argument(
        "--duration", type=float, default=1.0, metavar="T", help="simulated seconds (default: 1)"
    )
    parser.add_argument("--reference", metavar="SPEC", help="the reference run (see below)")
    parser.add_argument(
        "--rayleigh",
        choices=("auto", "keep", "remove"),
        default="auto",
        help="the scene's Rayleigh damping on implicit Euler: auto (default) removes it when explicit "
        "solvers take part, so that all configurations solve the same equations",
    )
    parser.add_argument(
        "--sample-interval",
        type=float,
        metavar="T",
        help="compare positions every T seconds (default: the largest dt)",
    )
    parser.add_argument(
        "--out", default="accuracy", metavar="DIR", help="output folder (default: ./accuracy)"
    )
    parser.add_argument("--no-plots", action="store_true", help="write no PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--data-path", action="append", metavar="DIR", help="folder to search (repeatable)")
    parser.set_defaults(handler=cmd_accuracy)
