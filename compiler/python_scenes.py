"""A Python scene given where an XML scene is expected: said so, instead of an XML parse error.

SOFA scenes are also written in Python (a ``createScene(rootNode)`` function, run by SofaPython3).
Until sofac reads them, a ``.py`` scene is refused with what it is and what to do (E113).
"""

from __future__ import annotations

from pathlib import Path

from .diagnostics import Diagnostics, SourceLoc

SUFFIXES = (".py", ".pyscn")


def refuse(path: Path, display: str, diagnostics: Diagnostics) -> bool:
    """Report E113 and return True when ``path`` is a Python scene."""
    if path.suffix.lower() not in SUFFIXES:
        return False
    diagnostics.add(
        "E113",
        SourceLoc(display, 0),
        f"{display} is a Python scene (SofaPython3's createScene); sofac reads XML scenes (.scn, .xml) only",
        "write the scene as an XML .scn file (the same components and attributes, as elements), or run "
        "it with SOFA's runSofa",
    )
    return True
