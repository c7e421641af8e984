"""`sofac inspect`: the resolved scene tree as text or JSON. (Being written.)"""

from __future__ import annotations

from typing import Any

from .check import CheckedScene


def tree_as_dict(checked: CheckedScene) -> dict[str, Any]:
    raise NotImplementedError


def format_tree(checked: CheckedScene) -> str:
    raise NotImplementedError
