"""The plan's contact and constraint phases: the contact guard, the compiled collision pipelines
(models, the pairs their broad phase can produce, points mapped only when near) and
FreeMotionAnimationLoop's constraint phase (rows, corrections, the solve)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from sofac.check.checker import CheckedComponent
from sofac.registry import Variant

from .calls import Buffer, Call, Statement
from .groups import Group, Op, StatePlan


@dataclass
class ContactGuard:
    """Collision models that could touch, while contact response is not compiled: before every
    step, each model's box (its state's points grown by its radius, its contactDistance and half
    the alarm distance, so that two boxes meet where SOFA's proximity test would pair them) is
    tested against the others', and the step stops before the first pair that touches. A run
    that ends without a stop had no contact: it is SOFA's, exactly."""

    models: list[tuple[str, StatePlan]]  # (origin, state) per collision model
    margins: Buffer  # per model: radius + contactDistance + half the intersection's alarm distance
    pairs: Buffer  # i64 (model, model) rows: the pairs SOFA would test
    boxes: Buffer  # scratch, 6 numbers per model
    touching: Buffer  # i64 [1]: the pair that stopped the step, -1 if none


class Response(enum.Enum):
    """How a pipeline's contacts act: penalty forces (PenalityContactForceField under
    DefaultAnimationLoop) or rows of the constraint phase (FrictionContactConstraint under
    FreeMotionAnimationLoop: runtime lagrangian_contact.h)."""

    PENALTY = "penalty"
    FRICTION_CONTACT = "friction_contact"


class Resolution(enum.IntEnum):
    """How the constraint solver resolves a block of rows (runtime constraints.h Resolution, whose
    values these are: tests/test_layout.py checks them)."""

    BILATERAL_3 = 0
    BILATERAL_1 = 1
    UNILATERAL_1 = 2
    UNILATERAL_FRICTION_3 = 3
    STOPPER_1 = 4


# The phases of FreeMotionAnimationLoop's constraint step, in step order (each a list of Ops):
# J rows built on the constraints' states and carried up the mappings (applyJT), violations read
# from the free vectors, W from the corrections, the solve, then each correction's x, v update.
CONSTRAINT_PHASES = ("rows", "violation", "compliance", "solve", "correction")

# ``<loop>.constraint_report``: the solves (runtime record_solve: their count, the last one's
# iterations and residual, the solves that hit the iteration limit and the last such one's time,
# residual and iterations), then the seconds spent since creation or reset (steady clock) in each
# part of the step: the collision pipelines, the groups' free motion, each of CONSTRAINT_PHASES,
# and the groups' projections and mappings after the correction.
CONSTRAINT_REPORT_FIELDS = (
    "solves",
    "iterations",
    "residual",
    "limited_solves",
    "limited_time",
    "limited_residual",
    "limited_iterations",
    "detection_seconds",
    "free_motion_seconds",
    *(f"{phase}_seconds" for phase in CONSTRAINT_PHASES),
    "finish_seconds",
)


@dataclass
class Correction:
    """A constraint correction: how constraint forces on its (independent) state move it."""

    origin: str
    kind: Variant  # UNCOUPLED (a per-DOF compliance) or LINEAR_SOLVER (A^-1 of the group's solve)
    state: StatePlan
    group: Group
    checked: CheckedComponent | None = None


@dataclass
class ConstraintPhase:
    """FreeMotionAnimationLoop: each group's solve is the free motion; then the constraint rows,
    their solve by the loop's constraint solver and the corrections; then projections and mappings.

    With no row (``capacity`` 0) every correction adds C Jᵀ 0 = 0: x = x_free, v = v_free, which is
    the groups' own step. Independent states without a correction are ``frozen``: SOFA never writes
    their free motion back, so they keep x and v (``saved`` holds them over the groups' step)."""

    loop: str  # origin of the FreeMotionAnimationLoop
    solver: str  # origin of the constraint solver ("" : none in the scene, SOFA's default BGS)
    method: Variant  # BLOCK_GAUSS_SEIDEL, UNBUILT_GAUSS_SEIDEL, NNCG or LCP
    # maxIterations, tolerance, sor, regularization, scaleTolerance, allVerified (LCP: mu, minW...)
    settings: dict[str, Buffer]
    # f64 CONSTRAINT_REPORT_FIELDS: solves, iterations and residual of the last solve, solves that
    # hit the iteration limit, the time, residual and iterations of the last such solve (the run's
    # warning), and the seconds spent in each part of the step (with rows only)
    report: Buffer
    corrections: list[Correction] = field(default_factory=list)
    frozen: list[tuple[StatePlan, Group]] = field(default_factory=list)
    saved: dict[str, tuple[Buffer, Buffer]] = field(default_factory=dict)  # frozen state ident -> (x, v)
    capacity: int = 0  # constraint rows reserved (contacts' rows grow past it: CollisionPlan.problem)
    # Row blocks in row order: (first row, Resolution, parameter, offset of its kept forces
    # in ``kept`` or -1, upper bound (stoppers' max, else 0)), and the forces kept across steps
    # (bilateral warm start).
    blocks: list[tuple[int, int, float, int, float]] = field(default_factory=list)
    kept: Buffer | None = None
    # Jacobian entries per constrained state (ident): (row, dof, derivative values), SOFA's
    # MatrixDeriv before it is sorted into rows.
    entries: dict[str, list[tuple[int, int, tuple[float, ...]]]] = field(default_factory=dict)
    solve: list[Op] = field(default_factory=list)  # the solver on W, dfree, f (after ``compliance``)
    rows: list[Op] = field(default_factory=list)
    violation: list[Op] = field(default_factory=list)
    compliance: list[Op] = field(default_factory=list)
    correction: list[Op] = field(default_factory=list)

    def calls(self) -> list[Statement]:
        return [c for phase in CONSTRAINT_PHASES for op in getattr(self, phase) for c in op.calls]

    def frozen_in(self, group: Group) -> list[StatePlan]:
        """A group's states that the phase keeps where they were."""
        return [state for state, owner in self.frozen if owner is group]


@dataclass
class CollisionModel:
    """A collision model of the pipeline, in SOFA's order (depth first below the pipeline's node)."""

    origin: str
    kind: Variant  # TRIANGLE, LINE, POINT or SPHERE (runtime ContactSide)
    state: StatePlan  # its points (Vec3d), or a sphere model's frames (Rigid3d: ``rigid``)
    elements: int  # triangles, edges, points or spheres
    cells: Buffer | None  # i64 triangles (3 per) or edges (2 per)
    contact_distance: float
    contact_stiffness: float
    moving: bool  # boxes follow the points (False: computed at the first step only)
    simulated: bool
    compute_normals: bool = True  # triangle models' computeNormals
    view: int = -1  # its place among the paired models of its kind (-1: in no pair)
    radii: Buffer | None = None  # sphere models: listRadius (spheres past it take `radius`)
    radius: float = 0.0
    flagged: int = 0  # triangle models: the leading triangles that get SOFA's flags (not quads')
    # LocalMinDistance's cones (runtime local_min_distance::PointCone / LineCone): i64 CSR
    # adjacency of the model's topology: points (triangles, edges, trianglesAroundVertex offsets
    # and items, edgesAroundVertex offsets and items), lines (triangles, trianglesAroundEdge
    # offsets and items); None: SOFA accepts without reading them.
    cone: tuple[Buffer, ...] | None = None
    both_side: bool = False  # triangle models' bothSide
    node_rank: int = 0  # depth-first index of its node (where a Lagrangian contact is placed)
    rigid: bool = False  # spheres centred on Rigid3d frames: contact points fixed in the frames
    # line models in a self-collision filter: the i64 CSR edgesAroundVertex of their topology
    # (offsets, items), ascending edge indices as MeshTopology lists them
    edges_around_vertex: tuple[Buffer, Buffer] | None = None


class SelfFilter(enum.Enum):
    """BVHNarrowPhase's element filter for a pair of models of one node with selfCollision
    (CollisionElementIterator::canCollideWith), by the runtime's SelfCollisionFilter rule."""

    NONE = ""  # models of different nodes, or a pair SOFA's filter always lets through
    SAME_MODEL = "kSameModel"  # one triangle or sphere model: e1 < e2
    SAME_LINES = "kSameLines"  # one line model: e1 < e2, no shared point, no edge touching both
    TRIANGLE_POINT = "kTrianglePoint"  # the point is no vertex of the triangle
    LINE_POINT = "kLinePoint"  # the point is no end of the line nor of an edge around its ends
    NEVER = "never"  # one point model: index < index2 and index > index2, never both


@dataclass
class LazyPoints:
    """The points of a pipeline's collision models that nothing but their contacts reads, mapped
    by a linear mapping (each point a weighted sum of parent points): mapped only when a pair may
    meet. Before each detection the parent's box, grown by ``spread`` times its extent and
    ``rounding`` times its largest coordinate, encloses them (runtime penalty.h, LazyPoints); while
    no pair of enclosures can meet, the detection is skipped without mapping them."""

    origin: str  # the mapping
    models: list[int]  # the pipeline's models on these points
    parent_points: int
    spread: float  # the largest sum of a point's negative weights
    rounding: float  # |sum of weights - 1| and the sums' rounding, relative to the coordinates
    current: Call  # the points from the parent's positions
    previous: Call  # the points from ``saved``
    parent: Buffer  # the parent's positions
    saved: Buffer  # scratch: the parent's positions at the last detection that did not map them


@dataclass(frozen=True)
class ElementTest:
    """An element test of runtime/sofac/proximity.h, ``<method>::<kind>_<kind>``, with its flags
    after the two models (same_model, useLineLine, useSurfaceNormals). ``self_filter``: "" for
    pairs of different nodes, "filter" when each pair's SelfCollisionFilter is asked before each
    element pair, "never" when SOFA's filter refuses every element pair (no traversal)."""

    name: str
    options: tuple[bool, ...] = ()
    self_filter: str = ""

    @property
    def kinds(self) -> tuple[str, str]:
        first, second = self.name.split("::")[1].split("_")
        return first, second


@dataclass
class ContactPair:
    """A model pair the broad phase can produce, models in the intersector's order."""

    first: int
    second: int
    test: int  # index in Collision.tests
    # Both simulated: SOFA places the response at the pipeline's node. ``root``: no solver
    # integrates that node, one explicit force per step; ``grouped``: inside the group of the
    # solver that integrates it (penalty only), in its force evaluations and K dx products.
    root: bool
    id_bound: int  # the outputs' ids are below it (the de-duplication's table)
    grouped: bool = False
    self_filter: SelfFilter = SelfFilter.NONE  # models of one node (selfCollision)
    one_node: bool = False  # both models in one node (one state): the motion watch skips it
    respond: bool = True  # False: the models' contactResponse is "nullptr", no contact is made

    @property
    def placement(self) -> int:
        """The pair table's placement column (runtime PenaltyContacts::Placement)."""
        return 2 if self.grouped else int(self.root)


REPORT_FIELDS = (
    "contacts",
    "growths",
    "degenerate",
    "detection_seconds",
    "response_seconds",
    "fast_motions",
    "unmapped_detections",
    "crossings",
)


@dataclass(frozen=True)
class ContactBody:
    """Where a Lagrangian contact model's rows land (runtime LagrangianModel): the constraint
    correction they reach (``body``, -1: none, a static obstacle), the positions the violation
    reads (the free positions when mapped), and how the rows go up the model's mapping: none (its
    own state), RigidMapping (``frames``, ``offsets``), IdentityMapping / SubsetMapping (``subset``:
    each point's parent DOF) or BarycentricMapping (``nodes``, ``weights``: ``width`` columns per
    point in its mapper's applyJT order, the first ``element_nodes`` of them real)."""

    body: int
    free: Buffer | None
    frames: Buffer | None = None
    offsets: Buffer | None = None
    subset: Buffer | None = None
    nodes: Buffer | None = None
    weights: Buffer | None = None
    element_nodes: Buffer | None = None
    width: int = 0


@dataclass
class Collision:
    """Detection and penalty response of a DefaultAnimationLoop scene, run before the groups step."""

    origin: str  # the pipeline
    method: Variant  # the intersection: NEW_PROXIMITY, MIN_PROXIMITY or LOCAL_MIN_DISTANCE
    alarm_distance: float
    contact_distance: float
    depth: int  # the bounding trees' depth (BVHNarrowPhase needs deep trees)
    models: list[CollisionModel]
    tests: list[ElementTest]  # those the pairs use, each compiled once
    pairs: list[ContactPair]
    # i64 rows (first, second, root, id_bound, test, first's view, second's view), one per pair
    table: Buffer | None = None
    # What the steps found, as ``<pipeline>.contactReport`` (REPORT_FIELDS): the last step's
    # contacts; since the instance was created or reset, buffers that outgrew their capacity,
    # degenerate outputs (NaN dropped or zero distance), the seconds spent in detection and in
    # response, the pairs a model came near after moving farther than the detection's reach, and
    # the detections that left the points mapped when near (``lazy``) unmapped, and the contacts
    # pushed through in a step (their points crossed along the contact's normal).
    report: Buffer | None = None
    # Why each other pair of models gets no code: ((first origin, second origin), reason).
    left_out: list[tuple[str, str, str]] = field(default_factory=list)
    response: Response = Response.PENALTY
    mu: float = 0.0  # FrictionContact's mu (0: one row per contact)
    # LocalMinDistance: filterIntersection, angleCone, coneFactor, useLMDFilters
    lmd: tuple[bool, float, float, bool] | None = None
    # friction_contact: the rank of each pair's placement node, and the constraint rows reserved
    ranks: list[int] = field(default_factory=list)
    row_capacity: int = 0
    static_rows: int = 0  # the scene's own constraint rows, before the contacts'
    bodies: list[ContactBody] = field(default_factory=list)  # friction_contact: per model
    # friction_contact: the constraint problem's buffers sized by the rows (W, dfree, f, d, scratch),
    # grown with the capacity when a step's contacts outgrow it (lagrangian_fit)
    problem: list[Buffer] = field(default_factory=list)
    lazy: list[LazyPoints] = field(default_factory=list)  # penalty: points mapped only when near
