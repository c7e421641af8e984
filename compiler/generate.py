"""Generate stage: render a plan as C++17 source from the Jinja2 templates in ``templates/``.

The template only arranges kernel calls that the plan prepared; identifiers come from the plan's
counters and comments are reduced to printable ASCII, so no scene text can change the code.
"""

from __future__ import annotations

import functools
import re
from typing import Any

import jinja2

from . import __version__
from .plan import Buffer, Group, Plan, StatePlan, origin_of
from .resources import resource_dir


def _comment(text: str) -> str:
    return re.sub(r"[^\x20-\x7e]", "?", text)


def _ptr(buffer: Buffer) -> str:
    return f"S.{buffer.ident}.data()"


def _size(buffer: Buffer) -> str:
    return f"Index(S.{buffer.ident}.size())"


@functools.lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(resource_dir("templates"))),
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,  # C++, not HTML: every interpolated value is produced by sofac itself
    )


class _StateView:
    """A state as the template sees it."""

    def __init__(self, state: StatePlan) -> None:
        self.x, self.v, self.f, self.acc = state.x, state.v, state.f, state.acc
        self.size = state.size
        self.cpp_type = state.cpp_type
        self.stages = state.stages
        self.path_comment = _comment(state.path)


class _GroupView:
    def __init__(self, group: Group) -> None:
        self.ident = group.ident
        self.scheme = group.scheme
        self.symplectic = group.symplectic
        self.origin = origin_of(group.solver)
        self.states = [_StateView(s) for s in group.states]
        self.all_states = [_StateView(s) for s in (*group.states, *group.mapped)]
        self.propagate = group.propagate
        self.forces = group.forces
        self.map_forces_up = group.map_forces_up
        self.accelerations = group.accelerations
        self.projections = group.projections
        self.energy = group.energy


def render(plan: Plan) -> str:
    """The C++ source of a plan's step (deterministic: same plan, same text)."""
    template = _environment().get_template("scene.cpp.j2")
    buffers: list[dict[str, Any]] = [
        {"ident": b.ident, "kind": b.kind, "comment": _comment(f"{b.key} ({b.role})")} for b in plan.buffers
    ]
    return template.render(
        version=__version__,
        scene_file=_comment(plan.scene_file),
        buffers=buffers,
        groups=[_GroupView(g) for g in plan.groups],
        dt=plan.dt,
        ptr=_ptr,
        size=_size,
    )
