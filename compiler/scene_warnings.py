"""Scene warnings outside ``sofac check``: Python warnings from ``sofac.load`` & co., lines on
standard error from every command that reads a scene, errors under ``strict``.

A warning (``W2xx``: an unknown attribute, a legacy name...) can change a result silently (a
misspelt ``youngModulus`` runs with the default), so whatever compiles or loads a scene issues its
warnings as :class:`SceneWarning` (a ``UserWarning``: users filter them, or turn them into errors,
with the ``warnings`` module). ``strict=True`` (``--strict``) raises :class:`StrictSceneError`,
listing every warning, before anything is built.
"""

from __future__ import annotations

import contextlib
import contextvars
import sys
import warnings
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

from sofac.diagnostics import Diagnostic, SceneError, Severity, SourceLoc

# Set by the command line for the whole command (--strict), so that every stage it runs obeys it.
_strict: contextvars.ContextVar[bool] = contextvars.ContextVar("sofac_strict", default=False)


def _text(diagnostic: Diagnostic) -> str:
    from sofac.cli.report import format_diagnostic

    return format_diagnostic(diagnostic)


class SceneWarning(UserWarning):
    """A warning about a scene, with the text ``sofac check`` prints; ``.diagnostic`` is the
    :class:`~sofac.diagnostics.Diagnostic` (code, file, line, attribute, hint)."""

    def __init__(self, diagnostic: Diagnostic | str) -> None:
        # A warning made again from its text (pytest-xdist sends warnings between processes as their
        # arguments) keeps the text and has no diagnostic.
        super().__init__(diagnostic if isinstance(diagnostic, str) else _text(diagnostic))
        self.diagnostic = None if isinstance(diagnostic, str) else diagnostic


class StrictSceneError(SceneError):
    """The scene has warnings and they were asked to be errors (``strict=True``, ``--strict``)."""

    def __init__(self, diagnostics: Iterable[Diagnostic]) -> None:
        items = list(diagnostics)
        super().__init__(items)
        more = f" (and {len(items) - 1} more)" if len(items) > 1 else ""
        self.args = (f"{items[0]}{more}\nstrict: warnings are errors; fix the scene, or load without strict",)


def scene_warnings(diagnostics: Iterable[Diagnostic]) -> tuple[Diagnostic, ...]:
    return tuple(d for d in diagnostics if d.severity is Severity.WARNING)


def issue(diagnostics: Iterable[Diagnostic], *, strict: bool = False, stacklevel: int = 2) -> None:
    """Issue the warnings of ``diagnostics`` as SceneWarning (``stacklevel`` counts from the caller of
    issue()); with ``strict`` (or under ``--strict``), raise StrictSceneError instead."""
    items = scene_warnings(diagnostics)
    if not items:
        return
    if strict or _strict.get():
        raise StrictSceneError(items)
    for diagnostic in items:
        warnings.warn(SceneWarning(diagnostic), stacklevel=stacklevel + 1)


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """No SceneWarning inside (a scene compiled again whose warnings were already issued)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        yield


@contextlib.contextmanager
def on_stderr(strict: bool) -> Iterator[None]:
    """For one command: each scene warning printed once to standard error, as ``sofac check``
    prints it (other warnings as Python prints them); ``strict`` makes them errors."""
    shown: set[str] = set()
    token = _strict.set(strict)
    with warnings.catch_warnings():
        warnings.simplefilter("always", SceneWarning)
        default = warnings.showwarning

        def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any) -> None:
            if isinstance(message, SceneWarning):
                text = str(message)
                if text not in shown:
                    shown.add(text)
                    print(text, file=sys.stderr)
                return
            default(message, category, *args, **kwargs)

        warnings.showwarning = show
        try:
            yield
        finally:
            _strict.reset(token)


def to_json(diagnostics: Sequence[Diagnostic]) -> list[dict[str, object]]:
    return [d.as_dict() for d in diagnostics]


def from_json(items: Sequence[dict[str, Any]]) -> tuple[Diagnostic, ...]:
    return tuple(
        Diagnostic(
            str(item["code"]),
            SourceLoc(str(item["file"]), int(item["line"]), item["attribute"]),
            str(item["message"]),
            str(item["hint"]),
            Severity.WARNING,
        )
        for item in items
    )
