"""What accuracy costs in time: ``sofac.accuracy.sweep`` (measure), plots (plots), and the
``sofac accuracy`` command (cli)."""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    # The measure module is imported on first use, so that the CLI can register the command
    # without importing numpy and the compiler stages.
    import importlib

    return getattr(importlib.import_module(f"{__name__}.measure"), name)
