"""Force fields other than finite elements: springs, loads, context gravity."""

from __future__ import annotations

from ..fields import (
    Bool,
    Bools,
    Color,
    Coords,
    FileName,
    Int,
    Ints,
    IntVector,
    JointSprings,
    Link,
    Real,
    Reals,
    Springs,
    Text,
)
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import (
    FORCEFIELD_FIELDS,
    MUST_BE_NONNEGATIVE,
    PAIR_FORCEFIELD_FIELDS,
    TOPOLOGY_LINK,
)

_SPRING_MODULE = "Sofa.Component.SolidMechanics.Spring"
_LOAD_MODULE = "Sofa.Component.MechanicalLoad"
_SPRING_EFFECTS = frozenset({Effect.INTERNAL_FORCE, Effect.STIFFNESS, Effect.DAMPING})

# SpringForceField Data other than the uniform stiffness/damping lists (subclasses alias those).
_SPRING_LIST_FIELDS = (
    FieldSpec("spring", Springs(), doc="springs, 5 numbers each: i j stiffness damping restLength"),
    FieldSpec(
        "springsIndices1",
        Ints(),
        doc="spring ends in object1 (with springsIndices2)",
        aliases=("indices1",),
        indexes="object1",
    ),
    FieldSpec(
        "springsIndices2",
        Ints(),
        doc="spring ends in object2 (with springsIndices1)",
        aliases=("indices2",),
        indexes="object2",
    ),
    FieldSpec(
        "lengths",
        Reals(),
        doc="rest lengths for the indices1/indices2 springs (one, or per spring; empty: 0)",
        aliases=("length",),
        valid=MUST_BE_NONNEGATIVE,
    ),
    FieldSpec("elongationOnly", Bools(), (False,), "per spring (or one for all): only resist elongation"),
    FieldSpec("enabled", Bools(), (True,), "per spring (or one for all): spring active"),
    FieldSpec("filename", FileName(), doc="Xsp file of springs", aliases=("fileSprings",)),
    FieldSpec("showArrowSize", Real(), 0.01, "display size"),
    FieldSpec("drawMode", Int(), 0, "display: 0 line, 1 cylinder, 2 arrow"),
)

_UNIFORM_STIFFNESS = (
    FieldSpec(
        "stiffness",
        Reals(),
        (100.0,),
        "stiffness of the indices1/indices2 springs (one, or per spring)",
        valid=MUST_BE_NONNEGATIVE,
    ),
    FieldSpec(
        "damping",
        Reals(),
        (5.0,),
        "damping of the indices1/indices2 springs (one, or per spring)",
        valid=MUST_BE_NONNEGATIVE,
    ),
)

SPRING_FORCE_FIELD = ComponentSpec(
    name="SpringForceField",
    lowering="springs",
    category=Category.INTERACTION_FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Linear springs between DOFs of object1 and object2 (possibly the same state), with damping "
    "along the spring and full stiffness matrix. `spring` takes precedence over the index lists.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d"),
    default_template="Vec3d",
    renamed_from=("StiffSpringForceField",),
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(*_UNIFORM_STIFFNESS, *_SPRING_LIST_FIELDS, *PAIR_FORCEFIELD_FIELDS),
)


def _per_element(prefix: str, stiffness: float, damping: float, what: str) -> tuple[FieldSpec, FieldSpec]:
    """The ``<prefix>Stiffness`` / ``<prefix>Damping`` pair of one element kind."""
    return (
        FieldSpec(
            f"{prefix}Stiffness", Real(), stiffness, f"stiffness of {what} springs", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec(
            f"{prefix}Damping", Real(), damping, f"damping of {what} springs", valid=MUST_BE_NONNEGATIVE
        ),
    )


_MESH_KINDS = ("lines", "triangles", "quads", "tetrahedra", "cubes")
_mesh_lines = _per_element("lines", 0.0, 0.0, "edge")
_mesh_triangles = _per_element("triangles", 0.0, 0.0, "triangle-edge")
_mesh_quads = _per_element("quads", 0.0, 0.0, "quad edge and diagonal")
_mesh_cubes = _per_element("cubes", 0.0, 0.0, "hexahedron")

MESH_SPRING_FORCE_FIELD = ComponentSpec(
    name="MeshSpringForceField",
    lowering="mesh_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="One spring per vertex pair of the node's topology elements; per-spring ks = stiffness / L0 and "
    "kd = damping / L0 (L0 the rest length).",
    templates=("Vec3d", "Vec2d", "Vec1d"),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec(
            "stiffness",
            Real(),
            doc="sets the stiffness of every element kind",
            sets=tuple(f"{k}Stiffness" for k in _MESH_KINDS),
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "damping",
            Real(),
            doc="sets the damping of every element kind",
            sets=tuple(f"{k}Damping" for k in _MESH_KINDS),
            valid=MUST_BE_NONNEGATIVE,
        ),
        *_mesh_lines,
        *_mesh_triangles,
        *_mesh_quads,
        FieldSpec(
            "tetrahedraStiffness",
            Real(),
            0.0,
            "stiffness of tetrahedron-edge springs",
            aliases=("tetrasStiffness",),
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "tetrahedraDamping",
            Real(),
            0.0,
            "damping of tetrahedron-edge springs",
            aliases=("tetrasDamping",),
            valid=MUST_BE_NONNEGATIVE,
        ),
        *_mesh_cubes,
        FieldSpec("noCompression", Bool(), False, "only resist elongation"),
        FieldSpec(
            "localRange", IntVector(2, nonnegative=True), doc="first and last DOF index used (default: all)"
        ),
        FieldSpec("drawMinElongationRange", Real(), 8.0),
        FieldSpec("drawMaxElongationRange", Real(), 15.0),
        FieldSpec("drawSpringSize", Real(), 8.0),
        *_SPRING_LIST_FIELDS,
        *PAIR_FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

_GRID_KINDS = ("lines", "quads", "cubes")

REGULAR_GRID_SPRING_FORCE_FIELD = ComponentSpec(
    name="RegularGridSpringForceField",
    lowering="grid_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Springs along the edges, face diagonals and cube diagonals of the node's RegularGridTopology, "
    "ks = stiffness / rest length; extra explicit springs as in SpringForceField.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d"),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec(
            "stiffness",
            Real(),
            doc="sets linesStiffness, quadsStiffness and cubesStiffness",
            sets=tuple(f"{k}Stiffness" for k in _GRID_KINDS),
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "damping",
            Real(),
            doc="sets linesDamping, quadsDamping and cubesDamping",
            sets=tuple(f"{k}Damping" for k in _GRID_KINDS),
            valid=MUST_BE_NONNEGATIVE,
        ),
        *_per_element("lines", 100.0, 5.0, "grid edge"),
        *_per_element("quads", 100.0, 5.0, "face diagonal"),
        *_per_element("cubes", 100.0, 5.0, "cube diagonal"),
        *_SPRING_LIST_FIELDS,
        *PAIR_FORCEFIELD_FIELDS,
    ),
)

REST_SHAPE_SPRINGS_FORCE_FIELD = ComponentSpec(
    name="RestShapeSpringsForceField",
    lowering="rest_shape_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Springs pulling DOFs back to their rest positions (or to another state's positions); for "
    "rigids also an angular spring. If stiffness is empty, 100 is used.",
    templates=("Vec3d", "Vec1d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE, Effect.STIFFNESS}),
    fields=(
        FieldSpec("points", Ints(), doc="DOFs held (default: all)", indexes="state"),
        FieldSpec(
            "stiffness", Reals(), doc="stiffness (one, or per point; empty: 100)", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec(
            "angularStiffness",
            Reals(),
            doc="rotational stiffness for rigids (one, or per point)",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("pivot_points", Reals(multiple=3), doc="pivot points used instead of the rigid centres"),
        # RestShapeSpringsForceField::init: a path to nothing is a warning, the own rest state is used
        FieldSpec(
            "external_rest_shape", Link("state", optional=True), doc="state whose positions are the anchors"
        ),
        FieldSpec("external_points", Ints(), doc="anchor indices in external_rest_shape"),
        FieldSpec("recompute_indices", Bool(), True, "recompute the indices at init"),
        FieldSpec("activeDirections", Bools(), doc="per-coordinate mask of active directions (default: all)"),
        FieldSpec("drawSpring", Bool(), False),
        FieldSpec("springColor", Color(), (0.0, 1.0, 0.0, 1.0)),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

JOINT_SPRING_FORCE_FIELD = ComponentSpec(
    name="JointSpringForceField",
    lowering="joint_springs",
    category=Category.INTERACTION_FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Six-degree-of-freedom joint springs between rigid frames (SOFA's formulas: hard or soft "
    "stiffness per translation and rotation axis in object1's frame, pivot cases, angle limits held "
    "by the bloc stiffness, damping kd (v2 - v1)); K dx as SOFA's addDForce (no damping, the frame "
    "held). Output files are not written; infile (constant joint forces) is refused.",
    templates=("Rigid3d",),
    default_template="Rigid3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec(
            "spring",
            JointSprings(),
            doc="joint springs: BEGIN_SPRING m1 m2 [FREE_AXIS, KS_T, KS_R, KS_B, KD, R_LIM_X/Y/Z, REST_T, "
            "REST_R] END_SPRING each",
        ),
        FieldSpec("outfile", FileName(output=True), doc="output file (not written by sofac)"),
        FieldSpec("infile", FileName(), doc="input file of constant joint forces"),
        FieldSpec("period", Real(), 0.0, "time between outputs"),
        FieldSpec("reinit", Bool(), False, "rewrite the output file each step"),
        FieldSpec("showLawfulTorsion", Bool(), False),
        FieldSpec("showExtraTorsion", Bool(), False),
        FieldSpec("showFactorSize", Real(), 1.0),
        *PAIR_FORCEFIELD_FIELDS,
    ),
)

QUAD_BENDING_SPRINGS = ComponentSpec(
    name="QuadBendingSprings",
    lowering="quad_bending_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Springs across the quads of a mesh that resist bending.",
    templates=("Vec3d", "Vec2d"),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        *_UNIFORM_STIFFNESS,
        FieldSpec("localRange", IntVector(2), (-1, -1), "first and last DOF index used"),
        *_SPRING_LIST_FIELDS,
        *PAIR_FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

TRIANGULAR_BENDING_SPRINGS = ComponentSpec(
    name="TriangularBendingSprings",
    lowering="triangular_bending_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Springs between the opposite vertices of adjacent triangles, resisting bending.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec("stiffness", Real(), 100000.0, "spring stiffness", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("damping", Real(), 1.0, "spring damping", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("showSprings", Bool(), True),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

QUADULAR_BENDING_SPRINGS = ComponentSpec(
    name="QuadularBendingSprings",
    lowering="quadular_bending_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Two springs across each edge shared by two quads, between the vertices next to the edge's "
    "ends (SOFA's applyQuadCreation, in the topology's edge order); rest lengths from the rest "
    "positions. SOFA has no energy for it.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec(
            "stiffness", Real(), 100000.0, "uniform stiffness of the springs", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec("damping", Real(), 1.0, "uniform damping of the springs", valid=MUST_BE_NONNEGATIVE),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

FAST_TRIANGULAR_BENDING_SPRINGS = ComponentSpec(
    name="FastTriangularBendingSprings",
    lowering="bending_springs",
    category=Category.FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Bending springs across triangle edges (linear bending model).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec("bendingStiffness", Real(), 1.0, "bending stiffness", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("minDistValidity", Real(), 1e-6, "distance under which a spring is ignored"),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

CONSTANT_FORCE_FIELD = ComponentSpec(
    name="ConstantForceField",
    lowering="constant_force",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="A constant force on selected DOFs: `forces` (one, or per index) or `totalForce` spread evenly.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d", "Rigid2d"),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE}),
    fields=(
        FieldSpec("indices", Ints(), doc="DOFs receiving the force (default: all)", indexes="state"),
        FieldSpec("indexFromEnd", Bool(), False, "indices count from the last DOF"),
        FieldSpec(
            "forces", Coords(deriv=True, allow_single=True), doc="force per index (one value is replicated)"
        ),
        FieldSpec("totalForce", Coords(deriv=True), doc="total force, divided evenly among the indices"),
        FieldSpec("showArrowSize", Real(), 0.0, "arrow display size (0: none)"),
        FieldSpec("showColor", Color(), (0.2, 0.9, 0.3, 1.0)),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

PLANE_FORCE_FIELD = ComponentSpec(
    name="PlaneForceField",
    lowering="plane_force",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="Penalty repulsion of points below the plane x.normal = d: f = -stiffness delta n + damping.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE, Effect.STIFFNESS, Effect.DAMPING}),
    fields=(
        FieldSpec("normal", Reals(), (0.0, 1.0, 0.0), "plane normal (spatial dimension of the DataType)"),
        FieldSpec("d", Real(), 0.0, "plane offset along the normal"),
        FieldSpec("stiffness", Real(), 500.0, "penalty stiffness", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("damping", Real(), 5.0, "penalty damping", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("maxForce", Real(), 0.0, "force clamp (0: unlimited)", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("bilateral", Bool(), False, "act on both sides of the plane"),
        FieldSpec("localRange", IntVector(2), (-1, -1), "first and last DOF index used"),
        FieldSpec("showPlane", Bool(), False),
        FieldSpec("planeColor", Color(), (0.0, 0.5, 0.2, 1.0)),
        FieldSpec("showPlaneSize", Real(), 10.0),
        *FORCEFIELD_FIELDS,
    ),
)

_ELLIPSOID_FIELDS = (
    FieldSpec("center", Reals(), doc="ellipsoid centre(s)"),
    FieldSpec("vradius", Reals(), doc="ellipsoid radii"),
    FieldSpec("stiffness", Real(), 500.0, "repulsion stiffness (negative: inward)"),
    FieldSpec("damping", Real(), 5.0, "repulsion damping"),
    FieldSpec("color", Color(), (0.0, 0.5, 1.0, 1.0)),
)

ELLIPSOID_FORCE_FIELD = ComponentSpec(
    name="EllipsoidForceField",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="Penalty repulsion by an ellipsoid.",
    templates=("Vec3d", "Vec2d", "Vec1d"),
    default_template="Vec3d",
    unsupported_reason="EllipsoidForceField is not implemented yet",
    effects=frozenset({Effect.EXTERNAL_FORCE, Effect.STIFFNESS}),
    fields=(*_ELLIPSOID_FIELDS, *FORCEFIELD_FIELDS),
)

INTERACTION_ELLIPSOID_FORCE_FIELD = ComponentSpec(
    name="InteractionEllipsoidForceField",
    lowering="interaction_ellipsoid",
    category=Category.INTERACTION_FORCEFIELD,
    module=_LOAD_MODULE,
    doc="Ellipsoid repulsion whose frame is a rigid DOF of object2.",
    templates=("Vec3d,Rigid3d",),
    default_template="Vec3d,Rigid3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE, Effect.STIFFNESS}),
    fields=(
        *_ELLIPSOID_FIELDS,
        FieldSpec("draw", Bool(), True),
        FieldSpec("object2_dof_index", Int(), 0, "rigid DOF of object2 carrying the ellipsoid"),
        FieldSpec("object2_forces", Bool(), True, "apply the reaction to object2"),
        FieldSpec("object2_invert", Bool(), False, "invert object2's transform"),
        *PAIR_FORCEFIELD_FIELDS,
    ),
)

TRIANGLE_PRESSURE_FORCE_FIELD = ComponentSpec(
    name="TrianglePressureForceField",
    lowering="triangle_pressure",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="Pressure on selected triangles of the topology.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE}),
    fields=(
        FieldSpec("pressure", Coords(deriv=True), doc="pressure vector (force per unit area)"),
        FieldSpec("cauchyStress", Reals(6), doc="Cauchy stress applied on the triangle normals"),
        FieldSpec("triangleList", Ints(), doc="triangles under pressure"),
        FieldSpec("showForces", Bool(), False),
        FieldSpec("useConstantForce", Bool(), True, "force from the rest area (not the current one)"),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

EDGE_PRESSURE_FORCE_FIELD = ComponentSpec(
    name="EdgePressureForceField",
    lowering="edge_pressure",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="A force on selected edges of the topology, half on each end: pressure x rest length, or "
    "p_intensity x rest length along binormal x the edge's direction (updated after each force "
    "evaluation, SOFA's way).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.EXTERNAL_FORCE}),
    fields=(
        FieldSpec("pressure", Coords(deriv=True), doc="force per unit length (a vector)"),
        FieldSpec("edgeIndices", Ints(), doc="edges under pressure (indices into the topology's edges)"),
        FieldSpec("edges", Ints(2), doc="edges under pressure, as point pairs of the topology's edges"),
        FieldSpec("normal", Reals(3), (0.0, 0.0, 0.0), "normal of the selection planes (with dmin, dmax)"),
        FieldSpec("dmin", Real(), 0.0, "edges whose ends have dmin < x.normal < dmax (when dmin != dmax)"),
        FieldSpec("dmax", Real(), 0.0, "see dmin"),
        FieldSpec("arrowSizeCoef", Real(), 0.0, "display size of the arrows"),
        FieldSpec("p_intensity", Reals(), doc="intensity of the pressure along the edge normals"),
        FieldSpec("binormal", Reals(3), (0.0, 0.0, 0.0), "binormal of the plane of the edges"),
        FieldSpec("showForces", Bool(), False, "draw the forces"),
        FieldSpec("edgePressureMap", Text(), doc="per-edge pressure data (computed)"),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

UNIFORM_VELOCITY_DAMPING_FORCE_FIELD = ComponentSpec(
    name="UniformVelocityDampingForceField",
    lowering="velocity_damping",
    category=Category.FORCEFIELD,
    module=_LOAD_MODULE,
    doc="Viscous damping force -c v on every DOF.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d", "Rigid2d"),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.DAMPING}),
    fields=(
        FieldSpec(
            "dampingCoefficient",
            Real(),
            0.1,
            "damping coefficient c",
            aliases=("damping",),
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("implicit", Bool(), False, "add df/dv to implicit solves"),
        *FORCEFIELD_FIELDS,
    ),
)

GRAVITY = ComponentSpec(
    name="Gravity",
    variant=Variant.GRAVITY,
    category=Category.CONTEXT,
    module=_LOAD_MODULE,
    doc="Sets the gravity of its node's subtree (re-applied after the root's values are copied down).",
    supported=True,
    effects=frozenset({Effect.GRAVITY}),
    fields=(FieldSpec("gravity", Reals(3), (0.0, 0.0, 0.0), "gravity vector in world coordinates"),),
)

VECTOR_SPRING_FORCE_FIELD = ComponentSpec(
    name="VectorSpringForceField",
    lowering="vector_springs",
    category=Category.INTERACTION_FORCEFIELD,
    module=_SPRING_MODULE,
    doc="Linear vector springs f = ks (x2[j] - x1[i] - r) + kd (v2[j] - v1[i]): with useTopology, one "
    "per edge of the topology (r from the rest positions), else one per point i = j of object1 "
    "(r = 0), coupling the two states point by point. No damping in the stiffness (SOFA's).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_SPRING_EFFECTS,
    fields=(
        FieldSpec("springs", Text(), doc="springs (ks kd rest vector); SOFA then applies none"),
        FieldSpec("filename", FileName(), doc="file of edges and springs"),
        FieldSpec("stiffness", Real(), 1.0, "stiffness of the default springs"),
        FieldSpec("viscosity", Real(), 1.0, "damping of the default springs"),
        FieldSpec("useTopology", Bool(), False, "one spring per edge of the topology"),
        TOPOLOGY_LINK,
        *PAIR_FORCEFIELD_FIELDS,
    ),
)

COMPONENTS = (
    VECTOR_SPRING_FORCE_FIELD,
    SPRING_FORCE_FIELD,
    MESH_SPRING_FORCE_FIELD,
    REGULAR_GRID_SPRING_FORCE_FIELD,
    REST_SHAPE_SPRINGS_FORCE_FIELD,
    JOINT_SPRING_FORCE_FIELD,
    QUAD_BENDING_SPRINGS,
    TRIANGULAR_BENDING_SPRINGS,
    QUADULAR_BENDING_SPRINGS,
    FAST_TRIANGULAR_BENDING_SPRINGS,
    CONSTANT_FORCE_FIELD,
    PLANE_FORCE_FIELD,
    ELLIPSOID_FORCE_FIELD,
    INTERACTION_ELLIPSOID_FORCE_FIELD,
    TRIANGLE_PRESSURE_FORCE_FIELD,
    EDGE_PRESSURE_FORCE_FIELD,
    UNIFORM_VELOCITY_DAMPING_FORCE_FIELD,
    GRAVITY,
)
