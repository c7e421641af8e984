"""sofac: a compiler for SOFA physics scenes.

The pipeline, one module per stage, data flowing one way::

    parse     (parse.py)     .scn text -> Scene model (model.py), includes and macros expanded
    check     (check.py)     Scene -> CheckedScene: types, links, templates, mappings; diagnostics
    plan      (plan.py)      CheckedScene -> Plan: buffers, mechanical groups, the step's kernel calls
    generate  (generate.py)  Plan -> C++ source (templates/*.j2 over runtime/sofac kernels)
    build     (build.py)     C++ -> shared library, in a content-addressed cache
    load      (load.py)      library -> Simulation (numpy views of the native state)
"""

from __future__ import annotations

__version__ = "0.1.0"

from .diagnostics import SceneError, SofacError
from .load import Simulation, SimulationDiverged, load

__all__ = ["SceneError", "Simulation", "SimulationDiverged", "SofacError", "__version__", "load"]
