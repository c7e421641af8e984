"""sofac: a compiler for SOFA physics scenes.

The pipeline, one package per stage, data flowing one way (docs/architecture.md)::

    front/    .scn text -> Scene model (includes and macros expanded)
    check/    Scene -> CheckedScene: types, links, templates, mappings; diagnostics
    plan/     CheckedScene -> Plan: typed data (buffers, groups, the calls of each step)
    codegen/  Plan -> C++ source (templates/*.j2 arrange calls to the runtime/sofac kernels)
    build/    C++ -> shared library, in a content-addressed cache
    simulation/ library -> Simulation (numpy views of the native state)

pipeline.py drives them; the tools beside them (accuracy/, render/, sweeps/, regress/, cli/) use it.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

__all__ = [
    "ContactNotCompiled",
    "ContactWarning",
    "InvalidParameter",
    "SceneError",
    "SceneWarning",
    "Simulation",
    "SimulationDiverged",
    "SofacError",
    "StrictSceneError",
    "__version__",
    "load",
    "save",
    "sweep",
    "view",
]

_LAZY = {
    "SceneError": "diagnostics",
    "SofacError": "diagnostics",
    "ContactNotCompiled": "simulation.loader",
    "ContactWarning": "simulation.loader",
    "Simulation": "simulation.loader",
    "SimulationDiverged": "simulation.loader",
    "load": "pipeline",
    "sweep": "sweeps.runner",
    "view": "viewer.window",
    "save": "pyscene.script",
    "SceneWarning": "scene_warnings",
    "StrictSceneError": "scene_warnings",
    "InvalidParameter": "param_rules",
}


_SUBMODULES = ("accuracy", "render")  # `sofac.render.render(sim)` after a bare `import sofac`


def __getattr__(name: str) -> Any:
    # Imported on first use, so that `import sofac` stays light (no numpy) for tools that only read
    # its version or resources.
    import importlib

    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
