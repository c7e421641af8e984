"""The ``sofac`` command line: a thin layer over the stage modules.

Exit codes: 0 no errors, 1 the scenes have errors, 2 usage error (E002), 3 internal error (a bug in
sofac; ``SOFAC_DEBUG=1`` shows the traceback), 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import sys
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NoReturn

from sofac import __version__
from sofac.cli.report import FORMATS, FileResult, format_diagnostic, render_results
from sofac.cli.usage import (
    EXIT_ERRORS,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    UsageError,
    data_roots,
)
from sofac.diagnostics import Diagnostic, Severity, relative_name

_EPILOG = (
    "exit codes: 0 no errors, 1 errors found, 2 usage error (E002), 3 internal error in sofac "
    "(set SOFAC_DEBUG=1 for the traceback)"
)


def _usage_message(message: str) -> str:
    return f"sofac: error E002: {message}"


class _Parser(argparse.ArgumentParser):
    """argparse, with its errors reported as E002 like sofac's own usage errors."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, _usage_message(message) + "\n")


# --- finding scenes ----------------------------------------------------------------------------

# Skipped before the root element: whitespace, the XML declaration, processing instructions,
# comments and a DOCTYPE (without an internal subset).
_PROLOGUE = r"(?:\s+|<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^\[>]*>)*"
_NODE_ROOT = re.compile(_PROLOGUE + r"<node[\s/>]", re.DOTALL | re.IGNORECASE)
_SNIFF_BYTES = 64 * 1024


def is_scene_xml(path: Path) -> bool:
    """Whether an ``.xml`` file's root element is ``<Node>`` (as SOFA's Objects/*.xml fragments)."""
    try:
        with path.open("rb") as stream:
            head = stream.read(_SNIFF_BYTES)
    except OSError:
        return False
    return _NODE_ROOT.match(head.decode("utf-8-sig", errors="replace")) is not None


def _scenes_in(folder: Path) -> Iterator[Path]:
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d != "__pycache__")
        for filename in sorted(filenames):
            path = Path(dirpath) / filename
            suffix = path.suffix.lower()
            if suffix == ".scn" or (suffix == ".xml" and is_scene_xml(path)):
                yield path


def find_scenes(paths: Sequence[str]) -> list[Path]:
    """The scene files named by ``paths``: files as given, folders searched recursively.

    In folders, a scene is a ``*.scn`` file or an ``*.xml`` file whose root element is ``<Node>``
    (hidden folders are skipped). Raises :class:`UsageError` for a missing path or when no scene
    is found at all.
    """
    found: list[Path] = []
    empty: list[str] = []
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise UsageError(f"no such file or folder: {raw}")
        if path.is_dir():
            scenes = list(_scenes_in(path))
            if not scenes:
                empty.append(raw)
            found.extend(scenes)
        else:
            found.append(path)
    if not found:
        where = ", ".join(paths)
        raise UsageError(
            f"no scene files found in {where} "
            "(looked for *.scn, and *.xml files whose root element is <Node>)"
        )
    for raw in empty:
        print(f"sofac: warning: no scene files in {raw}", file=sys.stderr)
    unique: dict[Path, Path] = {}
    for path in found:
        unique.setdefault(path.resolve(), path)
    return list(unique.values())


# --- commands ----------------------------------------------------------------------------------


def _cmd_check(args: argparse.Namespace) -> int:
    from sofac.check.checker import check_file
    from sofac.pipeline import add_compile_refusals

    roots = data_roots(args.data_path)
    files = find_scenes(args.paths)
    results: list[FileResult] = []
    has_errors = False
    for path in files:
        if args.no_exec and path.suffix.lower() == ".py":
            from sofac.pyscene.script import refused

            diagnostics = refused(path)
        else:
            allow = args.allow_unsupported
            checked, diagnostics = check_file(path, data_roots=roots, allow_unsupported=allow)
            add_compile_refusals(checked, diagnostics)
        items: list[Diagnostic] = diagnostics.sorted()
        if args.quiet:
            items = [d for d in items if d.severity is Severity.ERROR]
        has_errors = has_errors or diagnostics.has_errors() or bool(args.strict and diagnostics.warnings)
        results.append(FileResult(relative_name(path), tuple(items)))
    sys.stdout.write(render_results(results, args.format, with_summary=not args.quiet))
    return EXIT_ERRORS if has_errors else EXIT_OK


def _list_components(fmt: str) -> int:
    from sofac import registry

    specs = [spec for name, spec in sorted(registry.all_components().items()) if name != "Node"]
    if fmt == "json":
        items = [
            {"name": s.name, "category": s.category.value, "module": s.module, "supported": s.supported}
            for s in specs
        ]
        sys.stdout.write(json.dumps(items, indent=2) + "\n")
        return EXIT_OK
    width = max((len(s.name) for s in specs), default=0)
    for spec in specs:
        status = "supported" if spec.supported else "validated only"
        print(f"{spec.name:<{width}}  {spec.category.value:<22}  {status}")
    return EXIT_OK


def _cmd_inspect(args: argparse.Namespace) -> int:
    if args.components:
        return _list_components(args.format)
    if args.schedule and args.scene is not None:
        from sofac.cli.commands import cmd_schedule

        return cmd_schedule(args)
    if args.effects and args.scene is not None:
        from sofac.cli.commands import cmd_effects

        return cmd_effects(args)
    if args.plan_json and args.scene is not None:
        from sofac.cli.commands import cmd_plan_json

        return cmd_plan_json(args)
    if args.scene is None:
        raise UsageError("inspect needs a SCENE file (or --components)")
    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    roots = data_roots(args.data_path)

    from sofac.check.checker import check_file
    from sofac.cli.inspect import format_tree, tree_as_dict

    checked, diagnostics = check_file(path, data_roots=roots, allow_unsupported=args.allow_unsupported)
    for diag in diagnostics.sorted():
        if diag.severity >= Severity.WARNING:
            print(format_diagnostic(diag), file=sys.stderr)
    if checked is not None:
        if args.format == "json":
            sys.stdout.write(json.dumps(tree_as_dict(checked), indent=2, ensure_ascii=False) + "\n")
        else:
            sys.stdout.write(format_tree(checked) + "\n")
    failed = diagnostics.has_errors() or bool(args.strict and diagnostics.warnings)
    return EXIT_ERRORS if failed else EXIT_OK


def _cmd_regress(args: argparse.Namespace) -> int:
    from sofac.regress import suite as regress

    list_path = Path(args.list) if args.list else regress.default_list()
    if not list_path.is_file():
        hint = "" if args.list else " (pass LIST, or set SOFAC_SHARED to the shared folder)"
        raise UsageError(f"no regression list at {list_path}{hint}")
    scenes = Path(args.scenes) if args.scenes else regress.default_scenes_root()
    if not scenes.is_dir():
        raise UsageError(f"--scenes {scenes}: no such folder")
    references = Path(args.references) if args.references else regress.default_reference_root(list_path)
    if not references.is_dir():
        raise UsageError(f"--references {references}: no such folder")
    if args.jobs < 1:
        raise UsageError("--jobs must be at least 1")
    try:
        entries = regress.select_entries(regress.parse_regression_list(list_path).entries, args.only)
    except regress.RegressionListError as exc:
        raise UsageError(str(exc)) from exc
    if not entries:
        raise UsageError(f"no scene of {list_path} matches --only {' '.join(args.only or [])}")

    def progress(result: regress.SceneResult) -> None:
        if sys.stderr.isatty():
            print(f"  {result.status.value:<11} {result.scene} ({result.seconds:.1f}s)", file=sys.stderr)

    results = regress.run_regression(list_path, scenes, references, args.only, args.jobs, progress=progress)
    if args.format == "json":
        sys.stdout.write(regress.results_as_json(results, list_path))
    elif args.format == "markdown":
        sys.stdout.write(regress.format_markdown(results))
    else:
        sys.stdout.write(regress.format_table(results))
    failed = any(r.failed or (args.strict and r.status is regress.Status.UNSUPPORTED) for r in results)
    return EXIT_ERRORS if failed else EXIT_OK


def _cmd_version(args: argparse.Namespace) -> int:
    print(f"sofac {__version__}")
    return EXIT_OK


# --- parser ------------------------------------------------------------------------------------

# The commands that read a scene: each prints its warnings (as check does), or fails under --strict.
_SCENE_COMMANDS = ("check", "inspect", "compile", "emit", "run", "render", "accuracy", "sweep")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sofac",
        description="A compiler for SOFA physics scenes (.scn XML).",
        epilog=_EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"sofac {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    check = commands.add_parser(
        "check",
        help="validate scene files and report problems",
        description=(
            "Parse and check scene files; report every problem with file, line and a hint. A .py "
            "file is a SofaPython3 scene: checking it RUNS its code (createScene), as SOFA does; "
            "--no-exec refuses such files instead."
        ),
        epilog=_EPILOG,
    )
    check.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="scene files, or folders searched for *.scn (and *.xml rooted at <Node>)",
    )
    check.add_argument("--format", choices=FORMATS, default="text", help="report format (default: text)")
    check.add_argument(
        "--allow-unsupported",
        action="store_true",
        help="report components sofac cannot compile yet (E222) as warnings, not errors",
    )
    check.add_argument(
        "--data-path",
        action="append",
        metavar="DIR",
        help="folder to search for meshes and included files (repeatable)",
    )
    check.add_argument("--quiet", "-q", action="store_true", help="report errors only, without a summary")
    check.add_argument(
        "--no-exec",
        action="store_true",
        help="never run code: refuse .py scene scripts (E114) instead of executing them",
    )
    check.set_defaults(handler=_cmd_check)

    inspect = commands.add_parser(
        "inspect",
        help="show a scene's resolved tree",
        description="Check a scene and print its tree: templates, links, DOF counts and roles.",
        epilog=_EPILOG,
    )
    inspect.add_argument("scene", nargs="?", metavar="SCENE", help="the scene file")
    inspect.add_argument("--format", choices=("text", "json"), default="text", help="output format")
    inspect.add_argument("--data-path", action="append", metavar="DIR", help="folder to search (repeatable)")
    inspect.add_argument(
        "--allow-unsupported", action="store_true", help="treat unsupported components (E222) as warnings"
    )
    inspect.add_argument(
        "--components", action="store_true", help="list the components sofac knows instead of a scene"
    )
    inspect.add_argument(
        "--effects", action="store_true", help="list the effects the compiled step contains, and why"
    )
    inspect.add_argument(
        "--schedule", action="store_true", help="print the compiled step's plan: groups, states, kernel calls"
    )
    inspect.add_argument(
        "--plan-json", action="store_true", help="print the plan (typed data: buffers, groups, calls) as JSON"
    )
    inspect.set_defaults(handler=_cmd_inspect)

    regress = commands.add_parser(
        "regress",
        help="run SOFA's regression scenes and compare with SOFA's reference states",
        description=(
            "Run each scene of SOFA's regression list for its STEPS and apply SOFA's pass criterion "
            "(mean absolute state error per DOF, summed over the stored times, averaged over the "
            "compared states, <= EPSILON). Defaults come from the shared folder: $SOFAC_SHARED, "
            "else ../shared next to the repository."
        ),
        epilog=(
            "exit codes: 0 no scene failed (UNSUPPORTED is not a failure unless --strict), "
            "1 a scene FAILed, ERRORed or has no reference, 2 usage error (E002)"
        ),
    )
    regress.add_argument(
        "list",
        nargs="?",
        metavar="LIST",
        help="the regression list (default: the shared scenes.regression-tests)",
    )
    regress.add_argument("--scenes", metavar="ROOT", help="folder the list's scene paths are relative to")
    regress.add_argument(
        "--references", metavar="ROOT", help="folder of the reference files (default: the list's folder)"
    )
    regress.add_argument(
        "--only",
        nargs="+",
        action="extend",
        metavar="SUBSTRING",
        help="run only scenes whose path contains one",
    )
    regress.add_argument(
        "--format", choices=("text", "json", "markdown"), default="text", help="output format"
    )
    regress.add_argument("--strict", action="store_true", help="count UNSUPPORTED scenes as failures")
    regress.add_argument(
        "--jobs", "-j", type=int, default=1, metavar="N", help="run N scenes at once, each in its own process"
    )
    regress.set_defaults(handler=_cmd_regress)

    from sofac.cli.commands import register

    register(commands, _EPILOG)
    from sofac.accuracy.cli import register as register_accuracy

    register_accuracy(commands, _EPILOG)
    from sofac.render.cli import register as register_render

    register_render(commands, _EPILOG)
    from sofac.viewer.cli import register as register_view

    register_view(commands, _EPILOG)
    from sofac.sweeps.cli import register as register_sweep

    register_sweep(commands, _EPILOG)

    for name in _SCENE_COMMANDS:
        commands.choices[name].add_argument(
            "--strict", action="store_true", help="treat the scene's warnings as errors (exit code 1)"
        )
    version = commands.add_parser("version", help="print sofac's version")
    version.set_defaults(handler=_cmd_version)
    return parser


# --- entry point -------------------------------------------------------------------------------


def _configure_streams() -> None:
    # Never fail on a character the terminal's encoding cannot show (file names, tree drawing).
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors="backslashreplace")


def _report_internal_error(exc: BaseException) -> None:
    if os.environ.get("SOFAC_DEBUG", "") not in ("", "0"):
        traceback.print_exc(file=sys.stderr)
    detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    print(f"sofac: internal error: {detail}", file=sys.stderr)
    print(
        "This is a bug in sofac, not a problem in your scene. Please report it with the command and "
        "the scene that caused it (run again with SOFAC_DEBUG=1 to include the traceback).",
        file=sys.stderr,
    )


def main(argv: Sequence[str] | None = None) -> int:
    _configure_streams()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    if getattr(args, "handler", None) is None:
        parser.print_help(sys.stderr)
        print(_usage_message("no command given"), file=sys.stderr)
        return EXIT_USAGE
    from sofac.scene_warnings import on_stderr

    try:
        with on_stderr(strict=bool(getattr(args, "strict", False)) and args.command in _SCENE_COMMANDS):
            code = args.handler(args)
        sys.stdout.flush()
        return code
    except UsageError as exc:
        print(_usage_message(str(exc)), file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("sofac: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (`sofac inspect ... | head`): stop quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_ERRORS
    except Exception as exc:
        _report_internal_error(exc)
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
