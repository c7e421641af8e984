"""Field groups shared by many components (SOFA's base classes), written once."""

from __future__ import annotations

from ..fields import Bool, Color, Coords, FileName, Int, Ints, Link, Real, Reals, Text
from ..spec import FieldSpec

ALL_VEC = ("Vec1d", "Vec2d", "Vec3d", "Vec6d")
ALL_TYPES = (*ALL_VEC, "Rigid2d", "Rigid3d")

# Assembled matrix types (the template of matrix-based linear solvers and linear systems), by the
# canonical name SOFA's factory registers.
CRS_SCALAR = "CompressedRowSparseMatrixd"
CRS_MAT3 = "CompressedRowSparseMatrixMat3x3d"
CRS_BLOCKS = tuple(f"CompressedRowSparseMatrixMat{n}x{n}d" for n in (2, 3, 4, 6, 8))
GRAPH_SCATTERED = "GraphScattered"  # matrix-free: products evaluated by visiting the scene graph

# Element-based FEM components (CorotationalFEMForceField, FEMMass, ...) take "DataType,ElementType".
_ELEMENTS_BY_DIM = (
    ("Vec1d", "Edge"),
    ("Vec2d", "Edge"),
    ("Vec3d", "Edge"),
    ("Vec2d", "Triangle"),
    ("Vec3d", "Triangle"),
    ("Vec2d", "Quad"),
    ("Vec3d", "Quad"),
    ("Vec3d", "Tetrahedron"),
    ("Vec3d", "Hexahedron"),
    ("Vec3d", "Prism"),
    ("Vec3d", "Pyramid"),
)
ELEMENT_TEMPLATES = tuple(f"{dt},{element}" for dt, element in _ELEMENTS_BY_DIM)

# Template spellings SOFA accepts for matrix types (TemplatesAliases.cpp), mapped to the canonical
# names above. datatypes.canonical_datatype only knows DataTypes; the checker should consult this too.
MATRIX_TEMPLATE_ALIASES: dict[str, str] = {
    "CompressedRowSparseMatrix": CRS_SCALAR,
    "CompressedRowSparseMatrixMat3x3": CRS_MAT3,
}


def positive(x: float) -> bool:
    return x > 0


def nonnegative(x: float) -> bool:
    return x >= 0


def poisson_range(x: float) -> bool:
    """Poisson's ratio of an isotropic elastic material: -1 < nu < 1/2 (1/2 is incompressible)."""
    return -1.0 < x < 0.5


def at_least_one(x: float) -> bool:
    return x >= 1


def unit_interval(x: float) -> bool:
    return 0.0 <= x <= 1.0


MUST_BE_POSITIVE = (positive, "must be > 0")
MUST_BE_NONNEGATIVE = (nonnegative, "must be >= 0")
POISSON_RATIO = (poisson_range, "must be in (-1, 0.5)")
MUST_BE_AT_LEAST_ONE = (at_least_one, "must be >= 1")
MUST_BE_IN_UNIT_INTERVAL = (unit_interval, "must be in [0, 1]")

# BaseMapping / Mapping<In, Out>.
MAPPING_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("input", Link("state"), "@../", "input (parent) mechanical state"),
    FieldSpec("output", Link("state"), "@./", "output (child) state or visual model"),
    FieldSpec("mapForces", Bool(), True, "map forces from output to input"),
    FieldSpec("mapConstraints", Bool(), True, "map constraints from output to input"),
    FieldSpec("mapMasses", Bool(), True, "map masses from output to input"),
    FieldSpec("mapMatrices", Bool(), False, "map stiffness matrices"),
    FieldSpec("applyRestPosition", Bool(), False, "also map the rest position at init"),
    FieldSpec(
        "isMechanical",
        Bool(),
        doc="legacy switch: sets mapForces, mapConstraints and mapMasses together",
        sets=("mapForces", "mapConstraints", "mapMasses"),
    ),
)

# Geometric stiffness option of non-linear mappings (NonLinearMappingData).
GEOMETRIC_STIFFNESS = ("None", "Exact", "Stabilized")

# Links a component acting on one state may carry.
STATE_LINKS: tuple[FieldSpec, ...] = (
    FieldSpec("mstate", Link("state"), doc="mechanical state to act on (default: the node's)"),
    FieldSpec("topology", Link("topology"), doc="topology to use (default: the node's)"),
)
MSTATE_LINK = STATE_LINKS[0]
TOPOLOGY_LINK = STATE_LINKS[1]

# Arrays a mesh loader or topology container exposes (for src= links).
MESH_ARRAYS: tuple[FieldSpec, ...] = (
    FieldSpec("position", Coords(), doc="vertex positions", aliases=("points",)),
    FieldSpec("edges", Ints(2), doc="edges", aliases=("lines",)),
    FieldSpec("triangles", Ints(3), doc="triangles"),
    FieldSpec("quads", Ints(4), doc="quads"),
    FieldSpec("tetrahedra", Ints(4), doc="tetrahedra", aliases=("tetras",)),
    FieldSpec("hexahedra", Ints(8), doc="hexahedra", aliases=("hexas",)),
)

# MeshLoader base.
LOADER_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("filename", FileName(), doc="mesh file", required=True),
    FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0), "translation applied at load"),
    FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "rotation (degrees) applied at load"),
    FieldSpec("scale3d", Reals(3), (1.0, 1.0, 1.0), "scale applied at load"),
    FieldSpec("transformation", Reals(16), doc="4x4 transform (replaces the others)"),
    FieldSpec("flipNormals", Bool(), False),
    FieldSpec("triangulate", Bool(), False),
    FieldSpec("createSubelements", Bool(), False),
    FieldSpec("onlyAttachedPoints", Bool(), False),
    *MESH_ARRAYS,
)

# --- behaviour base classes ------------------------------------------------------------------

# BaseForceField (every force field and mass) + SingleStateAccessor.
RAYLEIGH_STIFFNESS = FieldSpec(
    "rayleighStiffness",
    Real(),
    0.0,
    "component-level Rayleigh stiffness coefficient (only for solvers that delegate damping)",
    valid=MUST_BE_NONNEGATIVE,
)
FORCEFIELD_FIELDS: tuple[FieldSpec, ...] = (RAYLEIGH_STIFFNESS, MSTATE_LINK)

# BaseMass Data (MASS_FIELDS adds the force-field ones: a mass is a force field too).
MASS_ONLY_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec(
        "rayleighMass",
        Real(),
        0.0,
        "component-level Rayleigh mass coefficient (only for solvers that delegate damping)",
        valid=MUST_BE_NONNEGATIVE,
    ),
    FieldSpec("separateGravity", Bool(), False, "add gravity to the velocity directly, not as a force"),
)
MASS_FIELDS: tuple[FieldSpec, ...] = (*FORCEFIELD_FIELDS, *MASS_ONLY_FIELDS)

# PairInteractionForceField: forces between two states (may be the same one).
PAIR_LINKS: tuple[FieldSpec, ...] = (
    FieldSpec("object1", Link("state"), "@./", "first mechanical state"),
    FieldSpec("object2", Link("state"), "@./", "second mechanical state"),
)
PAIR_FORCEFIELD_FIELDS: tuple[FieldSpec, ...] = (RAYLEIGH_STIFFNESS, *PAIR_LINKS)

# ProjectiveConstraintSet.
PROJECTIVE_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("endTime", Real(), -1.0, "time after which the constraint stops acting (negative: never)"),
    FieldSpec("group", Int(), 0, "id of the constraint group"),
    MSTATE_LINK,
    TOPOLOGY_LINK,
)

# BaseLinearElasticityFEMForceField: isotropic Hooke law, one value or one per element.
POSITIVE = MUST_BE_POSITIVE
ELASTICITY_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("youngModulus", Reals(), (5000.0,), "Young's modulus (one, or per element)", valid=POSITIVE),
    FieldSpec("poissonRatio", Reals(), (0.45,), "Poisson's ratio (one, or per element)", valid=POISSON_RATIO),
    *FORCEFIELD_FIELDS,
    TOPOLOGY_LINK,
)

# core::CollisionModel.
COLLISION_MODEL_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("active", Bool(), True, "take part in collision detection"),
    FieldSpec("moving", Bool(), True, "the model moves between steps"),
    FieldSpec("simulated", Bool(), True, "driven by a simulation (false: static obstacle)"),
    FieldSpec("selfCollision", Bool(), False, "may collide with itself"),
    FieldSpec(
        "contactDistance",
        Real(),
        0.0,
        "skin thickness added along the normal when creating contacts",
        aliases=("proximity",),
        valid=MUST_BE_NONNEGATIVE,
    ),
    FieldSpec("contactStiffness", Real(), 10.0, "penalty contact stiffness", valid=MUST_BE_NONNEGATIVE),
    FieldSpec("contactFriction", Real(), 0.0, "friction coefficient", valid=MUST_BE_NONNEGATIVE),
    FieldSpec("contactRestitution", Real(), 0.0, "restitution coefficient", valid=MUST_BE_NONNEGATIVE),
    FieldSpec("contactResponse", Text(), doc="response type overriding the contact manager's"),
    FieldSpec("color", Color(), (1.0, 0.0, 0.0, 1.0), "display color"),
    FieldSpec("group", Ints(), doc="group ids: models sharing one never collide"),
    FieldSpec("numberOfContacts", Int(nonnegative=True), 0, "output: models currently in contact"),
    MSTATE_LINK,
)

# MatrixLinearSolver (every linear solver and preconditioner).
LINEAR_SOLVER_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("linearSystem", Link("linear_system"), doc="linear system to solve (default: created)"),
    FieldSpec("parallelInverseProduct", Bool(), False, "parallelise J M^-1 J^T (constraint compliance)"),
)

# BaseAnimationLoop.
ANIMATION_LOOP_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("computeBoundingBox", Bool(), True, "update the scene bounding box every step"),
    FieldSpec("targetNode", Link("node"), doc="node the loop animates (default: its own)"),
)

# core::visual::VisualModel.
VISUAL_MODEL_FIELDS: tuple[FieldSpec, ...] = (FieldSpec("enable", Bool(), True, "display the object"),)

# TaskSchedulerUser (multithreaded components).
TASK_SCHEDULER_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("nbThreads", Int(), 0, "threads of the main task scheduler if not yet created (0: all cores)"),
    FieldSpec("taskSchedulerType", Text(), doc="task scheduler implementation"),
)
