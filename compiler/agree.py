"""What ``sofac run`` would refuse, reported by ``sofac check``: one rule, in the planner.

The checker knows a scene is valid SOFA; only the planner knows whether sofac can compile it (a
force field whose triangles come from a generator it does not evaluate, a rest shape read from
another state...). Rather than a second copy of those rules in the checker, a scene that checks
clean is planned (no code generated, no build: tens of milliseconds) and the planner's refusals
join the check's diagnostics, with the code, file and line the compile would give.
"""

from __future__ import annotations

import contextlib

from .check import CheckedScene
from .diagnostics import Diagnostics, SceneError


def add_compile_refusals(checked: CheckedScene | None, diagnostics: Diagnostics) -> None:
    """Plan a cleanly checked scene and keep what the planner refuses (E222...) in ``diagnostics``.
    A scene with errors (or with unsupported components let through as warnings) is not planned:
    its own diagnostics already say why it will not compile."""
    if checked is None or diagnostics.has_errors() or any(d.code == "E222" for d in diagnostics):
        return
    from . import plan

    with contextlib.suppress(SceneError):  # its diagnostics are in ``diagnostics`` already
        plan.plan_scene(checked, diagnostics)
