"""The declarative description of a SOFA component, read by every stage of sofac."""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .fields import Bool, FieldType, Reals, Text, Words


class Category(str, enum.Enum):
    """What role a component plays in the scene graph."""

    STATE = "state"  # MechanicalObject
    MASS = "mass"
    FORCEFIELD = "forcefield"  # acts on the node's state
    INTERACTION_FORCEFIELD = "interaction_forcefield"  # acts on two states (object1/object2)
    PROJECTIVE_CONSTRAINT = "projective_constraint"
    LAGRANGIAN_CONSTRAINT = "lagrangian_constraint"
    CONSTRAINT_SOLVER = "constraint_solver"
    CONSTRAINT_CORRECTION = "constraint_correction"
    ODE_SOLVER = "ode_solver"
    LINEAR_SOLVER = "linear_solver"
    PRECONDITIONER = "preconditioner"
    LINEAR_SYSTEM = "linear_system"
    ORDERING = "ordering"
    MAPPING = "mapping"
    MULTI_MAPPING = "multi_mapping"
    TOPOLOGY = "topology"  # containers and generators that hold a mesh
    TOPOLOGY_HELPER = "topology_helper"  # Modifier / GeometryAlgorithms companions
    TOPOLOGICAL_MAPPING = "topological_mapping"
    LOADER = "loader"
    ENGINE = "engine"
    COLLISION_PIPELINE = "collision_pipeline"  # pipeline, broad/narrow phase, intersection, response
    COLLISION_MODEL = "collision_model"
    VISUAL = "visual"  # visual models
    RENDERING = "rendering"  # lights, cameras, styles, background: no physics
    ANIMATION_LOOP = "animation_loop"
    CONTEXT = "context"  # Gravity and similar context objects
    UTILITY = "utility"  # RequiredPlugin, settings

    @property
    def acts_on_state(self) -> bool:
        """Components of these categories act on the mechanical state of their node."""
        return self in _ACTS_ON_STATE


_ACTS_ON_STATE = frozenset(
    {Category.MASS, Category.FORCEFIELD, Category.PROJECTIVE_CONSTRAINT, Category.LAGRANGIAN_CONSTRAINT}
)


class Effect(str, enum.Enum):
    """The physical or computational effects a component brings into a simulation step."""

    STATE = "state"
    INERTIA = "inertia"
    GRAVITY = "gravity"
    INTERNAL_FORCE = "internal_force"
    EXTERNAL_FORCE = "external_force"
    STIFFNESS = "stiffness"  # contributes dF/dx to implicit solves
    DAMPING = "damping"
    PROJECTION = "projection"
    MAPPING = "mapping"
    INTEGRATION = "integration"
    LINEAR_SOLVE = "linear_solve"
    TOPOLOGY = "topology"
    DATA = "data"  # loaders and engines: evaluated at compile time
    COLLISION = "collision"
    CONSTRAINT_SOLVE = "constraint_solve"
    VISUAL = "visual"


class Variant(enum.StrEnum):
    """A finer kind that later stages tell apart inside a category or a lowering (a StrEnum, so
    plan data keyed by it prints and dumps as its name)."""

    # Linear solvers: the factorisation a direct solver uses (L D L^T when none is given).
    LLT = "llt"
    SVD = "svd"
    # Topologies: which of SOFA's barycentric mappers they get ("" = a mesh).
    REGULAR_GRID = "regular_grid"
    SPARSE_GRID = "sparse_grid"
    DYNAMIC = "dynamic"
    # Force fields, masses and data.
    COROTATIONAL = "corotational"  # an element force field's corotational formulation
    AND_MASS = "and_mass"  # a force field that is also the mass (HexahedronFEMForceFieldAndMass)
    GRAVITY = "gravity"
    NODAL_MASS_DENSITY = "nodal_mass_density"
    SQUARE = "square"  # SquareDistanceMapping (vs DistanceMapping)
    DATA_REPOSITORY = "data_repository"  # AddDataRepository
    VISUAL_STYLE = "visual_style"
    # Projective constraints: along a line or in a plane.
    LINE = "line"  # also LineCollisionModel
    PLANE = "plane"
    # Collision: the pipeline's parts, the intersection methods and the collision models' elements.
    PIPELINE = "pipeline"
    COMPOSITE_PIPELINE = "composite_pipeline"
    SUB_PIPELINE = "sub_pipeline"
    BROAD_PHASE = "broad_phase"
    # ParallelBruteForceBroadPhase: the same pairs, but a model's pair with itself comes first
    PARALLEL_BROAD_PHASE = "parallel_broad_phase"
    NARROW_PHASE = "narrow_phase"
    CONTACT_MANAGER = "contact_manager"
    MIN_PROXIMITY = "min_proximity"
    NEW_PROXIMITY = "new_proximity"
    LOCAL_MIN_DISTANCE = "local_min_distance"
    TRIANGLE = "triangle"
    SPHERE = "sphere"
    POINT = "point"
    # Lagrangian constraints: the constraint solvers and corrections.
    LCP = "lcp"
    BLOCK_GAUSS_SEIDEL = "block_gauss_seidel"
    NNCG = "nncg"
    UNBUILT_GAUSS_SEIDEL = "unbuilt_gauss_seidel"
    LINEAR_SOLVER = "linear_solver"  # LinearSolverConstraintCorrection
    UNCOUPLED = "uncoupled"


@dataclass(frozen=True)
class FieldSpec:
    """One Data of a component: its name, aliases, type, default and documentation."""

    name: str
    type: FieldType
    default: Any = None
    doc: str = ""
    aliases: tuple[str, ...] = ()
    # Physical validity: a predicate over one numeric value and the phrase shown when it fails
    # (e.g. ``(lambda x: x > 0, "must be > 0")``). Applied to every element of a vector.
    valid: tuple[Callable[[float], bool], str] | None = None
    required: bool = False
    # Legacy spelling, accepted with a warning (e.g. StaticSolver's newton_iterations).
    deprecated: bool = False
    # For index lists: which state the indices point into, checked against its size:
    # "state" (the component's own state), "input"/"output" (a mapping's), "object1"/"object2".
    indexes: str | None = None
    # An umbrella attribute: SOFA registers this name as an alias of several Data, so a value given
    # here is written to each of these fields (e.g. MeshSpringForceField ``stiffness`` sets
    # ``linesStiffness``, ``trianglesStiffness``, ...). Such a field has no value of its own.
    sets: tuple[str, ...] = ()


# Data every SOFA object has (sofa::core::objectmodel::Base / BaseObject).
BASE_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("name", Text(), doc="object name"),
    FieldSpec("printLog", Bool(), False, "print debug messages"),
    FieldSpec("tags", Words(), doc="subsets the object belongs to"),
    FieldSpec("bbox", Reals(6), doc="bounding box (display)"),
    FieldSpec("componentState", Text(), doc="read-only validity state"),
    FieldSpec("listening", Bool(), False, "receive events"),
)


@dataclass(frozen=True)
class ComponentSpec:
    """A SOFA component class as sofac knows it."""

    name: str
    category: Category
    doc: str = ""
    # SOFA module that provides it (what RequiredPlugin names), e.g. "Sofa.Component.Mass".
    module: str = ""
    # DataTypes (or "In,Out" pairs for mappings, matrix types for linear solvers) it is instantiated for.
    templates: tuple[str, ...] = ()
    default_template: str | None = None
    fields: tuple[FieldSpec, ...] = ()
    effects: frozenset[Effect] = frozenset()
    # Names SOFA maps silently to this class.
    aliases: tuple[str, ...] = ()
    # Old names SOFA still maps to this class, with a rename warning.
    renamed_from: tuple[str, ...] = ()
    # Old names SOFA no longer accepts (removed or de-aliased); using them is an error naming this class.
    former_names: tuple[str, ...] = ()
    supported: bool = False
    # Why it is not supported (shown in the "unsupported" diagnostic).
    unsupported_reason: str = ""
    # For ODE solvers: does it need a linear solver (implicit schemes)?
    needs_linear_solver: bool = False
    deprecated: str = ""  # non-empty: SOFA marks the class deprecated; the text says what to use
    # Name of the front-end evaluator (in evaluate.py) that computes this component's output Data
    # at compile time: "mesh_loader", "sphere_loader", "grid", "box_roi", ... ("" = none).
    compute: str = ""
    # Fields the evaluator rewrites even when the scene gives them (GridTopology's position, resized
    # to the grid by computePointList): their value is the evaluator's output.
    rewrites: tuple[str, ...] = ()
    # Name of the lowering (plan/lower/__init__.py LOWERINGS) that turns it into calls of the
    # runtime's kernels in the compiled step; "" = the compiler cannot compile it yet (components
    # with no part in the step need none).
    lowering: str = ""
    # A finer kind that later stages distinguish inside a category or lowering (see Variant).
    variant: Variant | None = None
    # Described only by SOFA's source (registry/catalogue.py): its Data are those the constructors
    # declare, not the ones some components create at run time (MeshSplittingEngine's position1...).
    from_sofa_source: bool = False
    # A rule across fields, run by the checker: given a reader of the component's field values (as
    # CheckedScene.value gives them), (code, attribute, message, hint) for a combination sofac
    # refuses, else None (e.g. a hyperelastic material and the length of its ParameterSet).
    validate: Callable[[Callable[[str], Any]], tuple[str, str, str, str] | None] | None = None

    _by_name: dict[str, FieldSpec] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        table: dict[str, FieldSpec] = {}
        for spec in (*self.fields, *BASE_FIELDS):
            for key in (spec.name, *spec.aliases):
                table.setdefault(key, spec)
        object.__setattr__(self, "_by_name", table)

    def field(self, name: str) -> FieldSpec | None:
        """The field an attribute name sets (by name or alias)."""
        return self._by_name.get(name)

    @property
    def field_names(self) -> tuple[str, ...]:
        return tuple(self._by_name)
