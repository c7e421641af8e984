"""sofac: a compiler for SOFA physics scenes.

The pipeline, one module per stage, data flowing one way::

    parse  (parse.py)   .scn text -> Scene model (model.py), includes and macros expanded
    check  (check.py)   Scene -> CheckedScene: types, links, templates, mappings; diagnostics
"""

from __future__ import annotations

__version__ = "0.1.0"
