"""The plan as typed data, and nothing else: the calls of a step (``calls``), the states and
solver groups with the phases of their step (``groups``), the contact and constraint phases
(``contacts``), and the whole :class:`Plan` (here). No C++ text and no callables: ``sofac.codegen``
alone spells calls out, and every pass reads what a step touches from these values.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from sofac.front.model import Component

from .calls import (
    CHILD,
    COMPILED_DATATYPES,
    INPUT_OFFSET,
    OFFSET,
    PARENT,
    VECTOR,
    Aggregate,
    Arg,
    Buffer,
    BuiltSolver,
    Call,
    Constant,
    Count,
    Element,
    Env,
    FemMethod,
    Function,
    LinearSystem,
    Note,
    Offset,
    Preconditioner,
    Slot,
    SpringDamping,
    SpringFlags,
    Statement,
    TemplateArg,
    as_json,
    bind,
    buffers_of,
    call,
    kernel,
    recorded_once,
)
from .contacts import (
    CONSTRAINT_PHASES,
    CONSTRAINT_REPORT_FIELDS,
    REPORT_FIELDS,
    Collision,
    CollisionModel,
    ConstraintPhase,
    ContactBody,
    ContactGuard,
    ContactPair,
    Correction,
    ElementTest,
    LazyPoints,
    Resolution,
    Response,
    SelfFilter,
)
from .groups import (
    STEP_PHASES,
    Group,
    MappingOp,
    Op,
    Projection,
    Scheme,
    StatePlan,
    group_buffers,
    independent_groups,
)


@dataclass
class Plan:
    scene_file: str
    dt: Buffer
    gravity: Buffer
    buffers: list[Buffer]
    states: list[StatePlan]  # all MechanicalObjects, SOFA traversal order
    groups: list[Group]
    ignored: list[tuple[Component, str]]  # components kept out of the step, and why
    # Effects left out because the scene makes them vanish (parameter key -> why); changing such a
    # parameter at run time needs a recompilation (load(..., prune=False) keeps them).
    pruned: dict[str, str] = field(default_factory=dict)
    effects: list[tuple[str, str, str]] = field(default_factory=list)  # (effect, origin, detail)
    # Parameters read only when an instance is initialised (element stiffness from youngModulus...):
    # a change takes effect at the next reset(), which the Python API enforces.
    init_only: frozenset[str] = frozenset()
    # OpenMP threads for large element loops and independent groups (1: serial, built without OpenMP)
    threads: int = 1
    rigid_model: str = "sofa"  # how rigid bodies were compiled (plan_scene's rigid_model)
    contact_guard: ContactGuard | None = None
    collisions: list[Collision] = field(default_factory=list)  # compiled contacts, one per pipeline
    # Compiled for threads, with groups that share no buffer: they step side by side.
    parallel_groups: bool = False
    interactive: bool = False  # with a point force on each state, set from Python (plan_scene)
    constraints: ConstraintPhase | None = None  # FreeMotionAnimationLoop's constraint phase

    def buffer(self, key: str) -> Buffer:
        for buffer in self.buffers:
            if buffer.key == key:
                return buffer
        raise KeyError(key)


def origin_of(component: Component) -> str:
    """A one-line, comment-safe description of a component: type, path, file and line."""
    text = f"{component.type_name} {component.path!r} ({component.loc.file}:{component.loc.line})"
    return re.sub(r"[^\x20-\x7e]", "?", text).replace("*/", "*?")


__all__ = [
    "CHILD",
    "COMPILED_DATATYPES",
    "CONSTRAINT_PHASES",
    "CONSTRAINT_REPORT_FIELDS",
    "INPUT_OFFSET",
    "OFFSET",
    "PARENT",
    "REPORT_FIELDS",
    "STEP_PHASES",
    "VECTOR",
    "Aggregate",
    "Arg",
    "Buffer",
    "BuiltSolver",
    "Call",
    "Collision",
    "CollisionModel",
    "Constant",
    "ConstraintPhase",
    "ContactBody",
    "ContactGuard",
    "ContactPair",
    "Correction",
    "Count",
    "Element",
    "ElementTest",
    "Env",
    "FemMethod",
    "Function",
    "Group",
    "LazyPoints",
    "LinearSystem",
    "MappingOp",
    "Note",
    "Offset",
    "Op",
    "Plan",
    "Preconditioner",
    "Projection",
    "Resolution",
    "Response",
    "Scheme",
    "SelfFilter",
    "Slot",
    "SpringDamping",
    "SpringFlags",
    "StatePlan",
    "Statement",
    "TemplateArg",
    "as_json",
    "bind",
    "buffers_of",
    "call",
    "group_buffers",
    "independent_groups",
    "kernel",
    "origin_of",
    "recorded_once",
]
