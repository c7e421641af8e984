"""Check stage: Scene -> CheckedScene (typed fields, resolved links, templates), with diagnostics.

(Being written; the interface below is stable.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .diagnostics import Diagnostics
from .model import Component, Node, Scene
from .registry import ComponentSpec


@dataclass
class CheckedComponent:
    component: Component
    spec: ComponentSpec | None  # None: unknown component
    template: str | None = None  # canonical template ("Vec3d", "Rigid3d,Vec3d", matrix type...)
    fields: dict[str, Any] = field(default_factory=dict)  # typed values by canonical field name
    links: dict[str, Component | Node] = field(default_factory=dict)  # resolved object links


@dataclass
class CheckedScene:
    scene: Scene
    components: dict[int, CheckedComponent] = field(default_factory=dict)  # by id(component)

    def of(self, component: Component) -> CheckedComponent:
        return self.components[id(component)]


def check_scene(scene: Scene, diagnostics: Diagnostics, *, allow_unsupported: bool = False) -> CheckedScene:
    raise NotImplementedError


def check_file(
    path: str | Path, *, data_roots: Sequence[Path] = (), allow_unsupported: bool = False
) -> tuple[CheckedScene | None, Diagnostics]:
    """Parse and check one scene file; never raises for scene problems (they are diagnostics)."""
    raise NotImplementedError
