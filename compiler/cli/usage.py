"""What every ``sofac`` command shares: exit codes, usage errors, and scene/sofac errors turned
into messages (never tracebacks)."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

from sofac.diagnostics import SceneError, Severity, SofacError

EXIT_OK = 0
EXIT_ERRORS = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130


class UsageError(Exception):
    """The command line asks for something impossible (reported as E002, exit code 2)."""


class Failed(Exception):
    """A command failed and has said why on standard error (exit code 1)."""


@contextlib.contextmanager
def reported() -> Iterator[None]:
    """Turn sofac errors into messages on stderr, then raise Failed (the caller returns 1)."""
    from sofac.cli.report import format_diagnostic
    from sofac.scene_warnings import StrictSceneError

    try:
        yield
    except SceneError as error:
        for diag in error.diagnostics:
            if diag.severity >= Severity.WARNING:
                print(format_diagnostic(diag), file=sys.stderr)
        if isinstance(error, StrictSceneError):
            print("sofac: error: --strict: the scene's warnings are errors; fix them", file=sys.stderr)
        raise Failed from None
    except SofacError as error:
        print(f"sofac: error: {error}", file=sys.stderr)
        raise Failed from None


def data_roots(values: Sequence[str] | None) -> list[Path]:
    """The folders of ``--data-path`` (repeatable), each checked to be one."""
    roots = []
    for value in values or ():
        path = Path(value)
        if not path.is_dir():
            raise UsageError(f"--data-path {value}: no such folder")
        roots.append(path)
    return roots


def layer_flags(args: argparse.Namespace) -> dict[str, bool]:
    """The layers ``--show`` turns on and ``--hide`` off (the later word wins)."""
    show: dict[str, bool] = {}
    for words, on in ((args.show or [], True), (args.hide or [], False)):
        for word in words:
            show[word] = on
    return show
