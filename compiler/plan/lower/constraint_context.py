"""What the constraint lowerings share while one scene is lowered: FreeMotionAnimationLoop's
phase, the loop's constraint solver, and the rows whose calls wait until every component is
lowered (their violations read free positions that the mappings' rows decide last).

The planner holds one :class:`ConstraintLowering` (``Planner.constraint_lowering``) from the first
constraint lowering on; scenes without FreeMotionAnimationLoop never make one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sofac.check.checker import CheckedComponent
from sofac.plan.ir import Aggregate, Buffer, ConstraintPhase, Element, Env, Group, StatePlan


@dataclass
class BilateralViolation:
    """Three rows per point pair from ``first_row`` on: x2[points2] - x1[points1] - rest."""

    origin: str
    first_row: int
    object1: StatePlan | Buffer  # a Buffer: constant positions (FixedLagrangianConstraint's rest)
    object2: StatePlan
    points1: Buffer
    points2: Buffer
    pairs: int
    rest: Buffer
    rest_count: int


@dataclass
class CoordinateViolation:
    """One row per coordinate of a state from ``first_row`` on: x (- rest, unless Env.NONE)."""

    origin: str
    first_row: int
    state: StatePlan
    rest: Buffer | Env
    count: int


@dataclass
class RigidFixedViolation:
    """Six rows per fixed frame from ``first_row`` on: the centre's and the orientation's move from
    the rest position (runtime rigid_fixed_violation)."""

    origin: str
    first_row: int
    state: StatePlan
    dofs: Buffer
    count: int


@dataclass
class StopperViolation:
    """One row: the coordinate ``index`` of a Vec1d state."""

    origin: str
    row: int
    state: StatePlan
    index: int


@dataclass
class SlidingRows:
    """A SlidingLagrangianConstraint's four rows, rebuilt every step: per state its J (values
    computed by the rows' call) and the values' buffer."""

    checked: CheckedComponent
    first_row: int
    jacobians: list[tuple[StatePlan, Aggregate, Buffer]]
    point: int
    segment: tuple[int, int]
    degenerate: Buffer


@dataclass
class ConstraintLowering:
    phase: ConstraintPhase
    solver: CheckedComponent | None  # the loop's constraint solver (None: SOFA's default BGS)
    bilateral: list[BilateralViolation] = field(default_factory=list)
    coordinates: list[CoordinateViolation] = field(default_factory=list)
    stoppers: list[StopperViolation] = field(default_factory=list)
    rigid_fixed: list[RigidFixedViolation] = field(default_factory=list)
    sliding: list[SlidingRows] = field(default_factory=list)
    # States whose J rows are computed each step (rows carried through a RigidMapping, sliding
    # rows), by state ident: the correction reads these instead of constant rows.
    computed_rows: dict[str, Aggregate] = field(default_factory=dict)
    groups: list[Group] = field(default_factory=list)  # every group, once all are lowered


@dataclass(frozen=True)
class ConstraintProblem:
    """The buffers of the constraint solve, sized by the phase's rows: W, the free violations
    dfree, the forces f, the displacements d, and the solvers' scratch (3 per row)."""

    W: Buffer
    dfree: Buffer
    f: Buffer
    d: Buffer
    scratch: Buffer
    rows: int

    def arguments(self) -> tuple[Buffer | int | Env, ...]:
        """As the runtime's solvers take them: W's pattern (the entries written), W, dfree, f, d,
        scratch, rows."""
        return (Env.CONSTRAINT_PATTERN, self.W, self.dfree, self.f, self.d, self.scratch, self.rows)


@dataclass(frozen=True)
class UncoupledBody:
    """An UncoupledConstraintCorrection with rows, as the unbuilt solvers take it: its DataType,
    J, state, default compliance and compliance values, and its index among the corrections."""

    datatype: str
    J: Aggregate
    state: StatePlan
    default_compliance: Element
    compliance: Buffer
    compliance_count: int
    body: int
