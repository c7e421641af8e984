"""Bounds on the sizes a scene asks for, checked before anything that size is allocated.

A scene's numbers are untrusted input: ``RegularGridTopology nz="2147483648"`` would ask for
16 GiB of points. Sizes past these bounds are refused with the attribute named (E207); they lie
far beyond what a compiled step could run at an interactive rate anyway.
"""

from __future__ import annotations

from collections.abc import Sequence

#: Points a generated topology (a grid, a string of points) may have: 240 MB of coordinates.
MAX_GENERATED_POINTS = 10_000_000


def too_many_points(counts: Sequence[int]) -> str | None:
    """Why a generator of ``counts`` points per axis is refused, or None when it is within bounds."""
    total = 1
    for count in counts:
        total *= max(int(count), 1)  # Python integers: no overflow on the way
    if total <= MAX_GENERATED_POINTS:
        return None
    shown = " x ".join(str(int(c)) for c in counts) + f" = {total}" if len(counts) > 1 else str(total)
    return f"{shown} points is more than sofac generates ({MAX_GENERATED_POINTS}); lower the resolution"
