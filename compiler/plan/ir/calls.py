"""The calls of a step as typed data: which runtime kernel, with which template arguments and
which arguments — buffers, numbers and a few named values of the step's scope (:class:`Env`).

No C++ text is made here: ``sofac.codegen`` alone spells these out, and every pass that asks what a
step touches reads :meth:`Call.buffers` instead of code. Some calls are written once and placed
several times, with other vectors each time (a mapping's J is applied to velocities and to dx; a
projection filters v, f, dx, ...): their moving parts are :class:`Slot` values that code
generation binds where it places the call.
"""

from __future__ import annotations

import dataclasses
import enum
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Union

import numpy as np
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component, Node
from sofac.registry.datatypes import DataType


@dataclass(eq=False)
class Buffer:
    """An array the compiled instance owns, initialised from ``initial`` at creation."""

    ident: str  # the instance member's name (made from a counter and a sanitised field name)
    key: str  # name seen from Python: "<component path>.<field>"
    kind: str  # "f64" or "i64"
    initial: np.ndarray
    columns: int = 1  # row width of its numpy view
    role: str = "data"  # "state" (restored by reset), "param" (tunable), "data", "scratch"


# The DataTypes the runtime defines (runtime/sofac/types.h): states of other templates are refused.
COMPILED_DATATYPES = frozenset({"Vec1d", "Vec2d", "Vec3d", "Vec6d", "Rigid3d", "Rigid2d"})


class Env(enum.Enum):
    """Values in scope where a step's calls are placed (their C++ spelling is codegen's)."""

    ASSEMBLER = "assembler"  # the system matrix being assembled
    BAND = "band"  # BTDLinearSolver's block-tridiagonal matrix (runtime/sofac/beam.h)
    KFACT = "kfact"  # the stiffness factor of a product or an assembly
    MFACT = "mfact"  # the mass factor
    BFACT = "bfact"  # the damping factor
    FIXED = "fixed"  # the direct solver's marks of projected DOFs
    TIME = "time"  # the simulation time at the start of the step
    KINETIC = "kinetic"  # the energy sums being accumulated ...
    POTENTIAL = "potential"
    KINETIC_OUT = "kinetic_out"  # ... and their addresses, for kernels that add to both
    POTENTIAL_OUT = "potential_out"
    NONE = "none"  # an absent pointer
    CONTACTS = "contacts"  # the scene's penalty contacts, one per pipeline (runtime/sofac/penalty.h)
    LAGRANGIAN = "lagrangian"  # the scene's Lagrangian contacts (runtime/sofac/lagrangian_contact.h)
    # the constraint phase's record of W's entries written (runtime/sofac/constraints.h CompliancePattern)
    CONSTRAINT_PATTERN = "constraint_pattern"


class FemMethod(enum.IntEnum):
    """The FEM force fields' ``method`` (small, large, polar, svd), as the runtime names it (fem.h)."""

    SMALL = 0
    LARGE = 1
    POLAR = 2
    SVD = 3


class SpringDamping(enum.Enum):
    """spring_forces' damping variant (kernels.h): Undamped when the plan proves every damping is 0."""

    UNDAMPED = "Undamped"
    DAMPED = "Damped"


class SpringFlags(enum.Enum):
    """spring_forces' flags variant (kernels.h): None when every spring is enabled and none is
    elongation-only, so the per-spring flags are not read."""

    NONE = "None"
    PER_SPRING = "PerSpring"


class BuiltSolver(enum.Enum):
    """A constraint solver that solves on the built W (constraints.h BuiltSolver), as the runtime
    names it."""

    BLOCK_GAUSS_SEIDEL = "BlockGaussSeidel"
    NNCG = "Nncg"


class Preconditioner(enum.Enum):
    """A PCGLinearSolver's preconditioner, as the runtime applies it (direct.h)."""

    NONE = "none"
    JACOBI = "jacobi"  # JacobiPreconditioner: the inverse diagonal
    BLOCK_JACOBI = "block_jacobi"  # BlockJacobiPreconditioner: inverse 3x3 diagonal blocks
    SSOR = "ssor"  # SSORPreconditioner
    # A direct solver's factorisation (also a WarpPreconditioner whose rotations stay the identity).
    FACTORIZATION = "factorization"


class Constant(enum.Enum):
    """Layout constants of the runtime, named rather than copied (their values live in C++)."""

    TETRA_LANES = "TETRA_LANES"


@dataclass(frozen=True)
class Slot:
    """A value bound where the call is placed.

    ``parent``/``child``: a mapping's input and output vectors of the kind being mapped (``input``
    picks a multi-mapping's parent; ``vector`` fixes the kind, as "dx"); ``vector``: the vector a
    projection filters; ``offset``/``input_offset``: where a state's (or a mapping input's) DOFs
    start in an assembled system."""

    name: str
    input: int = 0
    vector: str = ""


PARENT = Slot("parent")
CHILD = Slot("child")
VECTOR = Slot("vector")
OFFSET = Slot("offset")
INPUT_OFFSET = Slot("input_offset")


@dataclass(frozen=True)
class Count:
    """The number of items in a buffer (its size divided by ``per``)."""

    buffer: Buffer
    per: int = 1


@dataclass(frozen=True)
class Element:
    """One number of a buffer, read where the call runs (a tunable scalar)."""

    buffer: Buffer
    index: int = 0


@dataclass(frozen=True)
class Offset:
    """Where a state's DOFs start in an assembled system: an independent state's first row, or
    (``mapped``) rows past the assembler's mapped range that a mapping's J routes on."""

    value: int
    mapped: bool = False


@dataclass(frozen=True)
class Function:
    """A runtime function passed as an argument (an element-matrix kernel)."""

    name: str


@dataclass(frozen=True)
class LinearSystem:
    """A group's direct solver (its factorisation of this step's system matrix), by group ident:
    what LinearSolverConstraintCorrection solves with."""

    group: str


@dataclass(frozen=True)
class Aggregate:
    """A runtime struct built from arguments (a spring table, an element split)."""

    type: str
    fields: tuple[Arg, ...]
    templates: tuple[TemplateArg, ...] = ()


Arg = Union[  # noqa: UP007
    Buffer,
    Count,
    Element,
    Offset,
    Function,
    LinearSystem,
    Aggregate,
    Slot,
    Env,
    BuiltSolver,
    bool,
    int,
    float,
]
# str: a DataType name ("Vec3d"); the enums: a kernel's variant, spelt as the runtime's enum class
TemplateArg = Union[str, int, bool, Constant, SpringDamping, SpringFlags]  # noqa: UP007


@dataclass(frozen=True)
class Call:
    """One call of a runtime kernel; ``into``: the energy sum its result is added to."""

    kernel: str
    args: tuple[Arg, ...]
    templates: tuple[TemplateArg, ...] = ()
    into: Env | None = None
    # Only while the assembler records its pattern: a constant block (a fixed selection's J).
    while_recording: bool = False

    def buffers(self) -> Iterator[Buffer]:
        """Every buffer the call reads or writes."""
        for arg in self.args:
            yield from _buffers(arg)


@dataclass(frozen=True)
class Note:
    """A line of explanation among calls (which mapping a block of J rows comes from)."""

    text: str

    def buffers(self) -> Iterator[Buffer]:
        return iter(())


Statement = Union[Call, Note]  # noqa: UP007


def _buffers(arg: Any) -> Iterator[Buffer]:
    if isinstance(arg, Buffer):
        yield arg
    elif isinstance(arg, (Count, Element)):
        yield arg.buffer
    elif isinstance(arg, Aggregate):
        for field in arg.fields:
            yield from _buffers(field)


def kernel(name: str, *templates: TemplateArg) -> tuple[str, tuple[TemplateArg, ...]]:
    """A kernel name with its template arguments, for :func:`call`."""
    return name, templates


def call(function: str | tuple[str, tuple[TemplateArg, ...]], *args: Arg, into: Env | None = None) -> Call:
    """A kernel call: ``call("name", ...)`` or ``call(kernel("name", "Vec3d"), ...)``."""
    name, templates = (function, ()) if isinstance(function, str) else function
    return Call(name, tuple(_plain(name, arg) for arg in args), templates, into)


def _plain(name: str, arg: Any) -> Arg:
    """numpy scalars as Python numbers (they print as ``np.float64(...)``); anything that is not a
    plan argument (C++ text above all) is refused."""
    if isinstance(arg, np.generic):
        arg = arg.item()
    if not isinstance(arg, _ARG_TYPES):
        raise TypeError(f"{name}: {arg!r} is not a plan argument")
    return arg


_ARG_TYPES = typing.get_args(Arg)


def bind(statement: Call, values: dict[Slot, Arg]) -> Call:
    """A call with its slots replaced by the values given for them (others left as they are)."""

    def bound(arg: Arg) -> Arg:
        if isinstance(arg, Slot):
            return values.get(arg, arg)
        if isinstance(arg, Aggregate):
            return Aggregate(arg.type, tuple(bound(f) for f in arg.fields), arg.templates)
        return arg

    return dataclasses.replace(statement, args=tuple(bound(a) for a in statement.args))


def recorded_once(statement: Call) -> Call:
    """A constant block of the assembled matrix: given while the assembler records its pattern."""
    return dataclasses.replace(statement, while_recording=True)


def buffers_of(statements: Iterator[Statement] | list[Statement]) -> set[str]:
    """The identifiers of the buffers a list of statements touches."""
    return {buffer.ident for statement in statements for buffer in statement.buffers()}


def as_json(value: Any) -> Any:
    """A plan value as JSON-ready data: buffers by identifier and key, arrays by shape, scene
    components by type and path, DataTypes by name."""
    if isinstance(value, CheckedComponent):
        value = value.component
    if isinstance(value, Component):
        return {"component": value.type_name, "path": value.path, "line": value.loc.line}
    if isinstance(value, Node):
        return {"node": value.path}
    if isinstance(value, DataType):
        return value.name
    if isinstance(value, Buffer):
        return {"buffer": value.ident, "key": value.key, "kind": value.kind, "role": value.role}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, np.ndarray):
        return {"shape": list(value.shape), "dtype": str(value.dtype)}
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if hasattr(value, "__dataclass_fields__"):
        fields = {name: as_json(getattr(value, name)) for name in value.__dataclass_fields__}
        return {"type": type(value).__name__, **fields}
    if isinstance(value, dict):
        return {str(k): as_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [as_json(v) for v in value]
    return value
