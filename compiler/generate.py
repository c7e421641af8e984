"""Generate stage: render a plan as C++17 source from the Jinja2 templates in ``templates/``.

The template only arranges kernel calls that the plan prepared; identifiers come from the plan's
counters and comments are reduced to printable ASCII, so no scene text can change the code.
"""

from __future__ import annotations

import contextlib
import functools
import re
from typing import Any

import jinja2

from . import __version__
from .plan import Buffer, Group, MappingOp, Plan, Projection, StatePlan, origin_of
from .resources import resource_dir


def _comment(text: str) -> str:
    return re.sub(r"[^\x20-\x7e]", "?", text)


def _ptr(buffer: Buffer) -> str:
    return f"S.{buffer.ident}.data()"


def _size(buffer: Buffer) -> str:
    return f"Index(S.{buffer.ident}.size())"


class _BestEffortBytecodeCache(jinja2.FileSystemBytecodeCache):
    """Compiled templates kept when the folder takes them: a full disk only costs the next load
    its speed."""

    def dump_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        with contextlib.suppress(OSError):
            super().dump_bytecode(bucket)


def _bytecode_cache() -> jinja2.BytecodeCache | None:
    from .build import cache_dir

    folder = cache_dir() / "templates"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only cache folder: compile the templates each time
    return _BestEffortBytecodeCache(str(folder))


@functools.lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(resource_dir("templates"))),
        # Compiled templates are kept next to the build cache: loading a cached scene in a new
        # process then skips Jinja2's template compilation (tens of milliseconds).
        bytecode_cache=_bytecode_cache(),
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
        self.dx, self.df = state.dx, state.df
        self.size = state.size
        self.width = state.datatype.deriv_size
        self.coord_width = state.datatype.coord_size
        self.cpp_type = state.cpp_type
        self.rigid = state.datatype.rigid
        self.stages = state.stages
        self.path_comment = _comment(state.path)


class _MappingView:
    def __init__(self, mapping: MappingOp) -> None:
        self.origin = mapping.origin
        self.apply = mapping.apply
        parent, child = mapping.parent, mapping.child
        self.jacobian_dx = mapping.jacobian(parent.dx, child.dx) if parent.dx and child.dx else ""
        transpose = mapping.transpose
        self.transpose_f = transpose(parent.f, child.f) if transpose else ""
        self.transpose_df = transpose(parent.df, child.df) if transpose and parent.df and child.df else ""
        geometric = mapping.geometric
        self.geometric_df = geometric(parent.dx, parent.df) if geometric and parent.dx and parent.df else ""


class _ProjectionView:
    def __init__(self, projection: Projection) -> None:
        state = projection.state
        self.origin = projection.origin
        self.velocity = projection.velocity
        self.on_v = (projection.project_velocity or projection.project)(state.v)
        self.on_x = projection.position(state.x) if projection.position else ""
        self.on_acc = projection.project(state.acc) if state.acc else ""
        self.on_f = projection.project(state.f)
        self.on_df = projection.project(state.df) if state.df else ""
        self.on_r = projection.project(state.stages["r"]) if "r" in state.stages else ""


class _GroupView:
    """A group as the template reads it: views of its states, mappings and projections, and the
    values derived for the template; any other attribute is the group's own."""

    def __init__(self, group: Group) -> None:
        self._group = group
        self.origin = origin_of(group.solver)
        self.states = [_StateView(s) for s in group.states]
        self.mapped = [_StateView(s) for s in group.mapped]
        self.all_states = [_StateView(s) for s in (*group.states, *group.mapped)]
        self.mappings = [_MappingView(m) for m in group.mappings]
        self.transposes = [_MappingView(m) for m in reversed(group.mappings) if m.transpose]
        self.on_read = [_MappingView(m) for m in group.on_read]
        self.projections = [_ProjectionView(p) for p in group.projections]
        # an assembled system matrix: assemble_<g>, its pattern at init
        self.matrix = group.direct or bool(group.preconditioner) or group.assembled_cg
        # The instance member holding it: a direct solver (CHOLMOD, also the preconditioners'
        # container) or the assembled CG's block rows and vectors.
        self.system = f"cg_{group.ident}" if group.assembled_cg else f"direct_{group.ident}"
        self.cg_block = group.cg_block if group.assembled_cg else 0
        self.linear_origin = origin_of(group.linear_solver) if group.linear_solver is not None else ""
        inert = group.inert_preconditioner
        self.inert_origin = origin_of(inert) if inert is not None else ""
        self.marks = [p.mark(group.offset(p.state) or 0) for p in group.projections if p.mark and self.matrix]
        for view, state in zip(self.states, group.states, strict=True):
            view.offset = group.offset(state)
        self.trapezoidal = "0.5" if group.trapezoidal else "1.0"

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):  # not the group's (and no recursion before _group is set)
            raise AttributeError(name)
        return getattr(self._group, name)


def render(plan: Plan) -> str:
    """The C++ source of a plan's step (deterministic: same plan, same text). Compiled for
    threads, groups that share no buffer step in parallel (see independent_groups)."""
    template = _environment().get_template("scene.cpp.j2")
    buffers: list[dict[str, Any]] = [
        {"ident": b.ident, "kind": b.kind, "comment": _comment(f"{b.key} ({b.role})")} for b in plan.buffers
    ]

    def source(parallel_groups: bool) -> str:
        return template.render(
            version=__version__,
            scene_file=_comment(plan.scene_file),
            buffers=buffers,
            groups=[_GroupView(g) for g in plan.groups],
            any_direct=any(g.direct or g.preconditioner for g in plan.groups),
            on_read=any(g.on_read for g in plan.groups),
            any_assembled_cg=any(g.assembled_cg for g in plan.groups),
            dt=plan.dt,
            threads=plan.threads,
            guard=plan.contact_guard,
            parallel_groups=parallel_groups,
            ptr=_ptr,
            size=_size,
        )

    serial = source(False)
    if plan.threads > 1 and independent_groups(serial, plan):
        return source(True)
    return serial


def independent_groups(serial_source: str, plan: Plan) -> bool:
    """Whether the plan has several groups and no two of them touch a common member of the
    instance, except the parameters every group reads (dt, gravity). Read from the generated
    code itself: each group's section (its propagate/forces/.../step functions) names every
    buffer and solver its step uses."""
    if len(plan.groups) < 2:
        return False
    shared = {plan.dt.ident, plan.gravity.ident}
    starts = [serial_source.index(_group_marker(g)) for g in plan.groups]
    end = serial_source.index(_SECTIONS_END)
    used: set[str] = set()
    for start, stop in zip(starts, [*starts[1:], end], strict=True):
        members = set(re.findall(r"\bS\.(\w+)", serial_source[start:stop])) - shared
        if members & used:
            return False
        used |= members
    return True


# The generated source: each group's functions start at its marker; the last group's end where
# the whole-scene functions begin.
_SECTIONS_END = "double total_energy("


def _group_marker(group: Any) -> str:
    return f"// ---- group {group.ident}:"
