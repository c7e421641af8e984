"""Pictures and videos of a simulation (off-screen OpenGL): ``sofac.render.render(sim)``,
``Camera``, ``Renderer``; the command line is ``sofac render`` (cli)."""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    # The picture module is imported on first use, so that the CLI can register the command
    # without importing OpenGL.
    import importlib

    return getattr(importlib.import_module(f"{__name__}.picture"), name)
