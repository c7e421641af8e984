"""``sofac sweep``: one scene run for many parameter sets on Dask (see :mod:`sofac.sweeps.runner`).

Kept apart from the sweep itself so that building the parser imports nothing heavy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sofac.cli.usage import EXIT_ERRORS, EXIT_OK, Failed, UsageError, reported


def cmd_sweep(args: argparse.Namespace) -> int:
    from sofac.sweeps import runner as sweep

    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    out = Path(args.out)
    if out.suffix.lower() not in (".nc", ".nc4", ".netcdf"):
        raise UsageError(f"--out {args.out}: the results are NetCDF; name the file *.nc")
    try:
        with reported():
            try:
                params = dict(sweep.parse_param(text) for text in args.param or ())
                plan = sweep.plan_sweep(
                    path,
                    params,
                    table=args.table,
                    steps=args.steps,
                    every=args.every,
                    record=[r for text in args.record or () for r in text.split(",") if r.strip()] or None,
                    data_roots=[Path(p) for p in args.data_path or ()],
                    prune=not args.no_prune,
                )
                print(
                    f"sofac: sweeping {len(plan.values)} runs of {args.steps} steps on "
                    f"{args.scheduler or 'a local Dask cluster'}",
                    file=sys.stderr,
                )
                dataset = sweep.run_plan(
                    plan,
                    out=out,
                    scheduler=args.scheduler,
                    workers=args.workers,
                    progress=not args.no_progress,
                    fresh=args.fresh,
                )
            except sweep.SweepError as exc:
                raise UsageError(str(exc)) from None
    except Failed:
        return EXIT_ERRORS
    rows = sweep.summary(dataset)
    sys.stdout.write(sweep.format_summary(rows))
    written = [out, sweep.write_summary(rows, out.with_suffix(".summary.csv"))]
    if not args.no_plot:
        written.append(sweep.plot(dataset, out.with_suffix(".png")))
    resumed = int(dataset.attrs["resumed_runs"])
    if resumed:
        print(f"sofac: {resumed} runs were taken from an earlier, interrupted sweep", file=sys.stderr)
    statuses = [row["status"] for row in rows]
    counts = ", ".join(f"{statuses.count(s)} {s}" for s in sweep.STATUSES if s in statuses)
    print(f"sofac: {counts}; wrote {', '.join(str(p) for p in written)}", file=sys.stderr)
    return EXIT_OK if statuses.count("ok") == len(statuses) else EXIT_ERRORS


def register(commands: argparse._SubParsersAction, epilog: str) -> None:
    """Add ``sweep`` to the ``sofac`` parser."""
    parser = commands.add_parser(
        "sweep",
        help="run a scene for many parameter sets on Dask, results in one NetCDF file",
        description=(
            "Compile SCENE once and run it for every parameter set (the full grid of the --param "
            "options, times the rows of --table) as Dask tasks: an embedded local cluster (a "
            "single-threaded worker per core) or the scheduler given by --scheduler. Each run sets "
            "the parameters, steps, and records the --record quantities; runs that diverge or fail "
            "are recorded as such. Writes OUT (NetCDF: parameters as coordinates of 'run', recorded "
            "quantities along 'sample'), OUT's .summary.csv and a .png plot; prints the summary. "
            "Finished runs are kept in OUT.parts/ meanwhile: run the same command again to resume "
            "an interrupted sweep. Exit code 1 when a run diverged or failed."
        ),
        epilog=(
            "VALUES: 10,100,1000 or START:STOP[:lin|log]:COUNT (1e3:1e5:log:10). KEY: a tunable parameter "
            "as Simulation.params() names it (/beam/fem.youngModulus, beam/fem.youngModulus or "
            "fem.youngModulus when unique; /.gravity[1] for one component); a wrong KEY lists them all. "
            "QUANTITY: PATH.FIELD with FIELD position, velocity or force (dofs.position, "
            "/beam/dofs.position[98] for DOF 98 only), or energy. " + epilog
        ),
    )
    parser.add_argument("scene", metavar="SCENE", help="the scene file")
    parser.add_argument(
        "--param",
        action="append",
        metavar="KEY=VALUES",
        help="a swept parameter (repeatable: the runs are the full grid)",
    )
    parser.add_argument(
        "--table", metavar="FILE", help="parameter sets: CSV (a column per KEY) or JSON (a list of objects)"
    )
    parser.add_argument("--steps", type=int, default=100, metavar="N", help="steps per run (default: 100)")
    parser.add_argument(
        "--every", type=int, metavar="K", help="record every K steps (default: the first and last step only)"
    )
    parser.add_argument(
        "--record",
        action="append",
        metavar="QUANTITY[,...]",
        help="what to record (default: the positions of every independent MechanicalObject)",
    )
    parser.add_argument("--out", default="sweep.nc", metavar="FILE", help="results file (default: sweep.nc)")
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://host:8786); 'synchronous' runs every task in this process",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local cluster size (default: a worker per core)",
    )
    parser.add_argument("--fresh", action="store_true", help="discard the runs of an interrupted sweep")
    parser.add_argument(
        "--no-prune",
        action="store_true",
        help="keep zero effects (e.g. gravity) sweepable",
    )
    parser.add_argument("--no-plot", action="store_true", help="write no PNG plot")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--data-path", action="append", metavar="DIR", help="folder to search (repeatable)")
    parser.set_defaults(handler=cmd_sweep)
