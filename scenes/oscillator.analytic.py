"""The analytic solution of oscillator.scn, for ``sofac accuracy scenes/oscillator.scn --reference analytic``.

A particle of mass 1 on a spring k = 100 (rest length 1) to a fixed anchor at the origin, released
at rest from x = 1.1: x(t) = 1 + 0.1 cos(10 t). ``positions(t)`` maps a MechanicalObject (path or
name) to its positions at time t; only the states it returns are compared.
"""

from __future__ import annotations

import math


def positions(t: float) -> dict[str, list[list[float]]]:
    return {"dofs": [[0.0, 0.0, 0.0], [1.0 + 0.1 * math.cos(10.0 * t), 0.0, 0.0]]}
