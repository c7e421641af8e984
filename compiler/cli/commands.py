"""The ``sofac`` subcommands that compile and run scenes: compile, emit, run (and inspect --schedule).

Scene problems and build failures are reported as diagnostics / sofac errors with exit code 1,
never as tracebacks.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sofac.cli.usage import EXIT_ERRORS, EXIT_INTERRUPTED, EXIT_OK, Failed, UsageError, reported

if TYPE_CHECKING:
    from sofac.simulation.loader import Compiled, SimulationDiverged


def _scene(args: argparse.Namespace) -> Path:
    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    return path


def _threads(args: argparse.Namespace) -> int:
    if args.threads < 1:
        raise UsageError("--threads must be >= 1")
    return int(args.threads)


def _load_options(args: argparse.Namespace) -> dict[str, Any]:
    return {"data_roots": [Path(p) for p in args.data_path or ()], "threads": _threads(args)}


def _compile(args: argparse.Namespace) -> Compiled:
    from sofac import pipeline

    return pipeline.compile_scene(_scene(args), **_load_options(args))


def cmd_compile(args: argparse.Namespace) -> int:
    try:
        with reported():
            compiled = _compile(args)
    except Failed:
        return EXIT_ERRORS
    built = compiled.built
    how = "from the cache" if built.cached else f"compiled in {built.seconds:.2f} s"
    print(built.library)
    print(f"sofac: {how}", file=sys.stderr)
    return EXIT_OK


def cmd_emit(args: argparse.Namespace) -> int:
    from sofac import pipeline

    try:
        with reported():
            sys.stdout.write(pipeline.generate(pipeline.plan_file(_scene(args), threads=_threads(args))))
    except Failed:
        return EXIT_ERRORS
    return EXIT_OK


def cmd_schedule(args: argparse.Namespace) -> int:
    from sofac import pipeline
    from sofac.plan.report import format_schedule

    try:
        with reported():
            print(format_schedule(pipeline.plan_file(_scene(args))))
    except Failed:
        return EXIT_ERRORS
    return EXIT_OK


def cmd_effects(args: argparse.Namespace) -> int:
    import json

    from sofac import pipeline
    from sofac.plan.report import format_effects

    try:
        with reported():
            scene_plan = pipeline.plan_file(_scene(args))
    except Failed:
        return EXIT_ERRORS
    if getattr(args, "format", "text") == "json":
        rows = [{"effect": e, "component": o, "detail": d} for e, o, d in scene_plan.effects]
        print(json.dumps(rows, indent=2))
    else:
        print(format_effects(scene_plan))
    return EXIT_OK


def cmd_plan_json(args: argparse.Namespace) -> int:
    import json

    from sofac import pipeline
    from sofac.plan.ir import as_json

    try:
        with reported():
            scene_plan = pipeline.plan_file(_scene(args))
    except Failed:
        return EXIT_ERRORS
    print(json.dumps(as_json(scene_plan), indent=1, allow_nan=False))
    return EXIT_OK


def cmd_run(args: argparse.Namespace) -> int:
    from sofac.simulation.loader import SimulationDiverged

    if args.steps < 0:
        raise UsageError("--steps must be >= 0")
    if args.dt is not None and not args.dt > 0:
        raise UsageError("--dt must be > 0")
    if args.every < 1:
        raise UsageError("--every must be >= 1")
    try:
        with reported():
            from sofac import pipeline

            started = time.perf_counter()
            # load(): a scene run before starts from its warm record, without the front end.
            sim = pipeline.load(_scene(args), dt=args.dt, **_load_options(args))
            ready = time.perf_counter()
            try:
                written, interrupted = _run_steps(sim, args)
            except SimulationDiverged as error:
                _report_divergence(error, sim, args.show)
                raise Failed from None
            stepped = time.perf_counter()
    except Failed:
        return EXIT_ERRORS
    if interrupted:
        what = f"the state files in {args.export_states} ({len(written)}) hold the records up to there"
        print(
            f"sofac: interrupted at step {sim.steps} of {args.steps} (t={sim.time:g}); "
            + (what if args.export_states else "nothing was written"),
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    built = sim.compiled.built
    how = "cache hit" if built.cached else f"compiled in {built.seconds:.2f} s"
    how = "warm record" if sim.compiled.warm else how
    per_step = (stepped - ready) / args.steps * 1e3 if args.steps else 0.0
    print(
        f"{args.steps} steps of dt={sim.dt:g} to t={sim.time:g}; load {ready - started:.3f} s ({how}), "
        f"{per_step:.4f} ms/step"
    )
    for path in sim.objects():
        state = sim[path]
        if state.info.mapped and not args.mapped:
            continue
        print(_state_line(path, state.info.template, state.position, args.show))
    return EXIT_OK


def _run_steps(sim: Any, args: argparse.Namespace) -> tuple[list[Path], bool]:
    """The run's steps, in slices (run_progress.py): the state files written, and whether Ctrl-C
    stopped it (between two slices)."""
    from sofac.cli.run_progress import StepBar, deferred_interrupt, run_in_slices

    bar = StepBar(args.steps, not args.no_progress)
    try:
        with deferred_interrupt() as stop:
            if not args.export_states:
                run_in_slices(sim.step, args.steps, now=lambda: sim.time, bar=bar, stop=stop)
                return [], stop.is_set()
            from sofac.regress.states import StateRecorder, select_states

            states = select_states(sim.states(), mapped=args.mapped)
            with StateRecorder(sim, states, Path(args.export_states), every=args.every) as recorder:
                run_in_slices(recorder.run, args.steps, now=lambda: sim.time, bar=bar, stop=stop)
            return list(recorder.paths), stop.is_set()
    finally:
        bar.close()


def _state_line(path: str, template: str, position: Any, show: int) -> str:
    rows = position[:show]
    more = f" ... ({len(position)} DOFs)" if len(position) > show else ""
    values = "; ".join(" ".join(f"{v:.6g}" for v in row) for row in rows)
    return f"  {path} <{template}>: {values}{more}"


def _report_divergence(error: SimulationDiverged, sim: Any, show: int) -> None:
    """The error line, then where the independent states were at the last finite step."""
    print(f"sofac: error: {error}", file=sys.stderr)
    if error.last_finite:
        when = f"step {error.last_finite_step}, t={error.last_finite_time:g}"
        print(f"sofac: the last finite state ({when}):", file=sys.stderr)
        for path, (position, _velocity) in error.last_finite.items():
            print(_state_line(path, sim[path].info.template, position, show), file=sys.stderr)


def register(commands: argparse._SubParsersAction, epilog: str) -> None:
    """Add compile, emit and run to the ``sofac`` parser."""

    def scene_parser(name: str, help_text: str) -> argparse.ArgumentParser:
        parser = commands.add_parser(name, help=help_text, description=help_text, epilog=epilog)
        parser.add_argument("scene", metavar="SCENE", help="the scene file")
        parser.add_argument(
            "--data-path", action="append", metavar="DIR", help="folder to search (repeatable)"
        )
        return parser

    def threaded(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
        parser.add_argument(
            "--threads",
            type=int,
            default=1,
            metavar="N",
            help="run large element loops (FEM) on N OpenMP threads, same numbers as 1 (default 1: off)",
        )
        return parser

    threaded(
        scene_parser("compile", "compile a scene (or take it from the cache) and print the library's path")
    ).set_defaults(handler=cmd_compile)
    threaded(scene_parser("emit", "print the C++ generated for a scene")).set_defaults(handler=cmd_emit)
    run = threaded(scene_parser("run", "compile and run a scene, printing where its states end up"))
    run.add_argument("--steps", type=int, default=100, help="number of steps (default 100)")
    run.add_argument("--dt", type=float, help="time step (default: the scene's)")
    run.add_argument(
        "--export-states", metavar="DIR", help="write SOFA WriteState files <K>_<NAME>_mstate.txt.gz"
    )
    run.add_argument("--every", type=int, default=1, help="record every K steps (default 1)")
    run.add_argument("--mapped", action="store_true", help="also export / print mapped states")
    run.add_argument("--show", type=int, default=4, help="DOFs printed per state (default 4)")
    run.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (one is drawn on a terminal for runs longer than a second)",
    )
    run.set_defaults(handler=cmd_run)
