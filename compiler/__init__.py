"""sofac: a compiler for SOFA physics scenes.

The pipeline, one module per stage, data flowing one way::

    parse     (parse.py)     .scn text -> Scene model (model.py), includes and macros expanded
    check     (check.py)     Scene -> CheckedScene: types, links, templates, mappings; diagnostics
    plan      (plan.py)      CheckedScene -> Plan: buffers, mechanical groups, the step's kernel calls
    generate  (generate.py)  Plan -> C++ source (templates/*.j2 over runtime/sofac kernels)
    build     (build.py)     C++ -> shared library, in a content-addressed cache
    load      (loader.py)    library -> Simulation (numpy views of the native state)
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

__all__ = [
    "ContactNotCompiled",
    "InvalidParameter",
    "SceneError",
    "SceneWarning",
    "Simulation",
    "SimulationDiverged",
    "SofacError",
    "StrictSceneError",
    "__version__",
    "load",
    "sweep",
]

_LAZY = {
    "SceneError": "diagnostics",
    "SofacError": "diagnostics",
    "SceneWarning": "scene_warnings",
    "StrictSceneError": "scene_warnings",
    "InvalidParameter": "param_rules",
    "ContactNotCompiled": "loader",
    "Simulation": "loader",
    "SimulationDiverged": "loader",
    "load": "loader",
    "sweep": "sweeps",
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
