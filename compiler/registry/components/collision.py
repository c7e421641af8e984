"""Collision detection: pipeline, broad/narrow phase, intersection methods, responses, models."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..fields import Bool, Int, Link, LinkList, Options, Real, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import (
    COLLISION_MODEL_FIELDS,
    MUST_BE_NONNEGATIVE,
    MUST_BE_POSITIVE,
    TASK_SCHEDULER_FIELDS,
    TOPOLOGY_LINK,
)

_ALGORITHM = "Sofa.Component.Collision.Detection.Algorithm"
_INTERSECTION = "Sofa.Component.Collision.Detection.Intersection"
_RESPONSE = "Sofa.Component.Collision.Response.Contact"
_GEOMETRY = "Sofa.Component.Collision.Geometry"
_COLLISION = frozenset({Effect.COLLISION})

_DEPTH = FieldSpec("depth", Int(), 6, "maximum depth of the bounding-volume trees", valid=MUST_BE_POSITIVE)

_COMPOSITE_FIELDS = (
    FieldSpec("parallelDetection", Bool(), False, "run the sub-pipelines in parallel"),
    FieldSpec(
        "subCollisionPipelines", LinkList("collision_pipeline"), doc="sub-pipelines (default: created)"
    ),
    *TASK_SCHEDULER_FIELDS,
)

COLLISION_PIPELINE = ComponentSpec(
    name="CollisionPipeline",
    variant=Variant.PIPELINE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="The collision pipeline: reset, broad phase, narrow phase, contact responses, using the "
    "broad/narrow phase, intersection method and contact manager found below its node.",
    former_names=("DefaultPipeline",),
    supported=True,
    effects=_COLLISION,
    fields=(
        FieldSpec("verbose", Bool(), False, "log each step"),
        FieldSpec("draw", Bool(), False, "draw the detected contacts"),
        _DEPTH,
        *_COMPOSITE_FIELDS,
    ),
)

COMPOSITE_COLLISION_PIPELINE = ComponentSpec(
    name="CompositeCollisionPipeline",
    variant=Variant.COMPOSITE_PIPELINE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="Runs several SubCollisionPipelines, phase by phase, in link order.",
    supported=True,
    effects=_COLLISION,
    fields=_COMPOSITE_FIELDS,
)

SUB_COLLISION_PIPELINE = ComponentSpec(
    name="SubCollisionPipeline",
    variant=Variant.SUB_PIPELINE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="One collision pipeline over an explicit list of collision models (run by a "
    "CompositeCollisionPipeline).",
    supported=True,
    effects=_COLLISION,
    fields=(
        _DEPTH,
        FieldSpec("collisionModels", LinkList("collision_model"), doc="collision models handled"),
        FieldSpec("broadPhaseDetection", Link("collision_pipeline"), doc="broad phase"),
        FieldSpec("narrowPhaseDetection", Link("collision_pipeline"), doc="narrow phase"),
        FieldSpec("intersectionMethod", Link("collision_pipeline"), doc="intersection method"),
        FieldSpec("contactManager", Link("collision_pipeline"), doc="contact manager"),
    ),
)

BRUTE_FORCE_BROAD_PHASE = ComponentSpec(
    name="BruteForceBroadPhase",
    variant=Variant.BROAD_PHASE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="Broad phase testing the bounding boxes of every pair of collision models.",
    supported=True,
    effects=_COLLISION,
    fields=(FieldSpec("box", Reals(6), doc="optional AABB: models outside it are ignored"),),
)

BVH_NARROW_PHASE = ComponentSpec(
    name="BVHNarrowPhase",
    variant=Variant.NARROW_PHASE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="Narrow phase traversing the bounding-volume hierarchies of candidate pairs.",
    supported=True,
    effects=_COLLISION,
)

PARALLEL_BRUTE_FORCE_BROAD_PHASE = ComponentSpec(
    name="ParallelBruteForceBroadPhase",
    variant=Variant.PARALLEL_BROAD_PHASE,
    category=Category.COLLISION_PIPELINE,
    module="MultiThreading",
    doc="MultiThreading plugin: BruteForceBroadPhase's pair tests in tasks, concatenated in order; "
    "compiled as the sequential one (its threads change no result), with every model's pair with "
    "itself before the others, as its tasks hand them on.",
    supported=True,
    effects=_COLLISION,
    fields=(
        FieldSpec("box", Reals(6), doc="optional AABB: models outside it are ignored"),
        *TASK_SCHEDULER_FIELDS,
    ),
)

PARALLEL_BVH_NARROW_PHASE = ComponentSpec(
    name="ParallelBVHNarrowPhase",
    variant=Variant.NARROW_PHASE,
    category=Category.COLLISION_PIPELINE,
    module="MultiThreading",
    doc="MultiThreading plugin: BVHNarrowPhase with a task per pair, each into its own output vector "
    "created in pair order: the sequential one's outputs and order, compiled as it.",
    supported=True,
    effects=_COLLISION,
    fields=TASK_SCHEDULER_FIELDS,
)

BRUTE_FORCE_DETECTION = ComponentSpec(
    name="BruteForceDetection",
    variant=Variant.BROAD_PHASE,
    category=Category.COLLISION_PIPELINE,
    module=_ALGORITHM,
    doc="Deprecated: adds a BruteForceBroadPhase and a BVHNarrowPhase to its node.",
    deprecated="use BruteForceBroadPhase + BVHNarrowPhase (deprecated since v21.06)",
    unsupported_reason="BruteForceDetection is deprecated: use <BruteForceBroadPhase/> + <BVHNarrowPhase/>",
    effects=_COLLISION,
)

# BaseProximityIntersection.
_PROXIMITY = (
    FieldSpec(
        "alarmDistance", Real(), 1.0, "pairs farther apart than this are ignored", valid=MUST_BE_NONNEGATIVE
    ),
    FieldSpec(
        "contactDistance", Real(), 0.5, "separation the contact response keeps", valid=MUST_BE_NONNEGATIVE
    ),
)


def _alarm_covers_contact(value: Callable[[str], Any]) -> tuple[str, str, str, str] | None:
    """An alarm distance below the contact distance: pairs would be dropped before they come as
    near as the response keeps them (SOFA does not check it; every contact would start violated)."""
    alarm, contact = float(value("alarmDistance")), float(value("contactDistance"))
    if alarm >= contact:
        return None
    return (
        "E207",
        "alarmDistance",
        f"alarmDistance={alarm!r} must be >= contactDistance={contact!r} (pairs are detected within "
        "the alarm distance and pushed apart up to the contact distance)",
        "raise alarmDistance or lower contactDistance",
    )


MIN_PROXIMITY_INTERSECTION = ComponentSpec(
    name="MinProximityIntersection",
    variant=Variant.MIN_PROXIMITY,
    category=Category.COLLISION_PIPELINE,
    module=_INTERSECTION,
    doc="Proximity tests between element pairs closer than alarmDistance.",
    validate=_alarm_covers_contact,
    supported=True,
    effects=_COLLISION,
    fields=(
        *_PROXIMITY,
        FieldSpec("useSphereTriangle", Bool(), True),
        FieldSpec("usePointPoint", Bool(), True),
        FieldSpec("useLinePoint", Bool(), True),
        FieldSpec("useLineLine", Bool(), True),
        FieldSpec("useSurfaceNormals", Bool(), False, "contact normals from the surface normals"),
    ),
)

NEW_PROXIMITY_INTERSECTION = ComponentSpec(
    name="NewProximityIntersection",
    variant=Variant.NEW_PROXIMITY,
    category=Category.COLLISION_PIPELINE,
    module=_INTERSECTION,
    doc="Proximity tests based on triangle-triangle distances.",
    validate=_alarm_covers_contact,
    supported=True,
    effects=_COLLISION,
    fields=(*_PROXIMITY, FieldSpec("useLineLine", Bool(), False, "also test edge-edge pairs")),
)

DISCRETE_INTERSECTION = ComponentSpec(
    name="DiscreteIntersection",
    category=Category.COLLISION_PIPELINE,
    module=_INTERSECTION,
    doc="Exact overlap tests (sphere-sphere, sphere-point, ...), no alarm distance.",
    supported=True,
    effects=_COLLISION,
)

LOCAL_MIN_DISTANCE = ComponentSpec(
    name="LocalMinDistance",
    category=Category.COLLISION_PIPELINE,
    module=_INTERSECTION,
    doc="Proximity tests filtered by local minimum distance cones (used with constraint-based contacts).",
    variant=Variant.LOCAL_MIN_DISTANCE,
    validate=_alarm_covers_contact,
    supported=True,
    effects=_COLLISION,
    fields=(
        *_PROXIMITY,
        FieldSpec("filterIntersection", Bool(), True),
        FieldSpec("angleCone", Real(), 0.0),
        FieldSpec("coneFactor", Real(), 0.5),
        FieldSpec("useLMDFilters", Bool(), False),
    ),
)

CCD_TIGHT_INCLUSION_INTERSECTION = ComponentSpec(
    name="CCDTightInclusionIntersection",
    category=Category.COLLISION_PIPELINE,
    module=_INTERSECTION,
    doc="Continuous collision detection (Tight Inclusion).",
    unsupported_reason="continuous collision detection is not supported yet",
    effects=_COLLISION,
    fields=(
        *_PROXIMITY,
        FieldSpec("continuousCollisionType", Options(values=("None", "Inertia", "FreeMotion")), "None"),
        FieldSpec("tolerance", Real(), 1e-10, valid=MUST_BE_NONNEGATIVE),
        FieldSpec("maxIterations", Int(), 1000, valid=MUST_BE_POSITIVE),
    ),
)


def response_params(text: str) -> dict[str, str]:
    """A contact manager's responseParams, 'name=value&name=value' (SOFA's ContactManager)."""
    params = {}
    for item in text.split("&"):
        name, _, given = item.partition("=")
        if name.strip():
            params[name.strip()] = given.strip()
    return params


def _friction_is_nonnegative(value: Callable[[str], Any]) -> tuple[str, str, str, str] | None:
    """A FrictionContactConstraint's mu (responseParams) is a Coulomb coefficient: >= 0."""
    if str(value("response") or "") != "FrictionContactConstraint":
        return None
    given = response_params(str(value("responseParams") or "")).get("mu")
    try:
        mu = float(given) if given is not None else 0.0
    except ValueError:
        return ("E205", "responseParams", f"mu={given!r} is not a number", 'give responseParams="mu=0.8"')
    if mu >= 0:
        return None
    return (
        "E207",
        "responseParams",
        f"mu={mu!r} must be >= 0 (Coulomb's friction coefficient)",
        'give responseParams="mu=0.8" or another non-negative value',
    )


_RESPONSE_FIELDS = (
    FieldSpec(
        "response",
        Text(),
        doc="contact response: PenalityContactForceField, FrictionContactConstraint (Lagrangian), "
        "StickContactForceField, ...",
        required=True,
    ),
    FieldSpec("responseParams", Text(), doc="response parameters, 'name=value&name=value'"),
)

COLLISION_RESPONSE = ComponentSpec(
    name="CollisionResponse",
    variant=Variant.CONTACT_MANAGER,
    category=Category.COLLISION_PIPELINE,
    module=_RESPONSE,
    doc="Contact manager: creates a response (e.g. penalty springs) per colliding pair of models.",
    former_names=("DefaultContactManager",),
    validate=_friction_is_nonnegative,
    supported=True,
    effects=_COLLISION,
    fields=_RESPONSE_FIELDS,
)

RULE_BASED_CONTACT_MANAGER = ComponentSpec(
    name="RuleBasedContactManager",
    category=Category.COLLISION_PIPELINE,
    module=_RESPONSE,
    doc="Contact manager choosing the response per pair of model groups from rules.",
    validate=_friction_is_nonnegative,
    former_names=("RuleBasedCollisionResponse",),
    variant=Variant.CONTACT_MANAGER,
    supported=True,
    effects=_COLLISION,
    fields=(
        FieldSpec("variables", Text(), doc="variables used in the rules"),
        FieldSpec("rules", Text(), doc="rules: group1 group2 response, ..."),
        *_RESPONSE_FIELDS,
    ),
)

_BOTH_SIDE = FieldSpec("bothSide", Bool(), False, "collide on both sides of the surface")
_FREE_POSITION = FieldSpec("displayFreePosition", Bool(), False)

SPHERE_COLLISION_MODEL = ComponentSpec(
    name="SphereCollisionModel",
    variant=Variant.SPHERE,
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="One sphere per DOF of the node's state (centres), radius from listRadius or radius.",
    templates=("Vec3d", "Rigid3d"),
    default_template="Vec3d",
    former_names=("Sphere", "SphereModel", "TSphereModel"),
    supported=True,
    effects=_COLLISION,
    fields=(
        FieldSpec("listRadius", Reals(), doc="radius of each sphere", valid=MUST_BE_POSITIVE),
        FieldSpec("radius", Real(), 1.0, "radius when listRadius is empty", valid=MUST_BE_POSITIVE),
        FieldSpec("showImpostors", Bool(), True),
        *COLLISION_MODEL_FIELDS,
    ),
)

TRIANGLE_COLLISION_MODEL = ComponentSpec(
    name="TriangleCollisionModel",
    variant=Variant.TRIANGLE,
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="The triangles of the node's topology.",
    templates=("Vec3d",),
    default_template="Vec3d",
    former_names=(
        "Triangle",
        "TriangleSet",
        "TriangleMesh",
        "TriangleSetModel",
        "TriangleMeshModel",
        "TriangleModel",
        "TTriangleModel",
    ),
    supported=True,
    effects=_COLLISION,
    fields=(
        _BOTH_SIDE,
        FieldSpec("computeNormals", Bool(), True, "compute the triangle normals"),
        FieldSpec("useCurvature", Bool(), False, "skip some self-intersection tests using the curvature"),
        *COLLISION_MODEL_FIELDS,
        TOPOLOGY_LINK,
    ),
)

LINE_COLLISION_MODEL = ComponentSpec(
    name="LineCollisionModel",
    variant=Variant.LINE,
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="The edges of the node's topology.",
    templates=("Vec3d",),
    default_template="Vec3d",
    former_names=("Line", "TLineModel", "LineMeshModel", "LineSetModel", "LineMesh", "LineSet", "LineModel"),
    supported=True,
    effects=_COLLISION,
    fields=(_BOTH_SIDE, _FREE_POSITION, *COLLISION_MODEL_FIELDS, TOPOLOGY_LINK),
)

POINT_COLLISION_MODEL = ComponentSpec(
    name="PointCollisionModel",
    variant=Variant.POINT,
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="The points of the node's state.",
    templates=("Vec3d",),
    default_template="Vec3d",
    former_names=("Point", "TPointModel", "PointModel", "PointMesh", "PointSet"),
    supported=True,
    effects=_COLLISION,
    fields=(
        _BOTH_SIDE,
        FieldSpec("computeNormals", Bool(), False, "compute point normals (needed by some tests)"),
        _FREE_POSITION,
        *COLLISION_MODEL_FIELDS,
        TOPOLOGY_LINK,
    ),
)

_OTHER_MODELS = "only sphere, triangle, line and point collision models are supported"

CUBE_COLLISION_MODEL = ComponentSpec(
    name="CubeCollisionModel",
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="Axis-aligned boxes (bounding-volume hierarchy nodes).",
    former_names=("Cube", "CubeModel"),
    unsupported_reason=_OTHER_MODELS,
    effects=_COLLISION,
    fields=COLLISION_MODEL_FIELDS,
)

CYLINDER_COLLISION_MODEL = ComponentSpec(
    name="CylinderCollisionModel",
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="One cylinder per rigid DOF.",
    templates=("Rigid3d",),
    default_template="Rigid3d",
    former_names=("Cylinder", "CylinderModel"),
    unsupported_reason=_OTHER_MODELS,
    effects=_COLLISION,
    fields=(
        FieldSpec("radii", Reals(), doc="radius of each cylinder", valid=MUST_BE_POSITIVE),
        FieldSpec("heights", Reals(), doc="height of each cylinder", valid=MUST_BE_POSITIVE),
        FieldSpec("defaultRadius", Real(), 0.5, valid=MUST_BE_POSITIVE),
        FieldSpec("defaultHeight", Real(), 2.0, valid=MUST_BE_POSITIVE),
        FieldSpec("defaultLocalAxis", Reals(3), (0.0, 1.0, 0.0)),
        *COLLISION_MODEL_FIELDS,
    ),
)

RAY_COLLISION_MODEL = ComponentSpec(
    name="RayCollisionModel",
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="Rays (used for mouse picking).",
    former_names=("Ray", "RayModel"),
    unsupported_reason=_OTHER_MODELS,
    effects=_COLLISION,
    fields=(FieldSpec("defaultLength", Real(), 1.0, valid=MUST_BE_POSITIVE), *COLLISION_MODEL_FIELDS),
)

TETRAHEDRON_COLLISION_MODEL = ComponentSpec(
    name="TetrahedronCollisionModel",
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="The tetrahedra of the node's topology.",
    former_names=("Tetrahedron", "TetrahedronModel"),
    unsupported_reason=_OTHER_MODELS,
    effects=_COLLISION,
    fields=(*COLLISION_MODEL_FIELDS, TOPOLOGY_LINK),
)

TRIANGLE_OCTREE_COLLISION_MODEL = ComponentSpec(
    name="TriangleOctreeCollisionModel",
    category=Category.COLLISION_MODEL,
    module=_GEOMETRY,
    doc="Triangles indexed by an octree (ray casting).",
    renamed_from=("TriangleOctreeModel",),
    former_names=("TriangleOctree",),
    unsupported_reason=_OTHER_MODELS,
    effects=_COLLISION,
    fields=(
        FieldSpec("drawOctree", Bool(), False),
        _BOTH_SIDE,
        FieldSpec("computeNormals", Bool(), True),
        FieldSpec("useCurvature", Bool(), False),
        *COLLISION_MODEL_FIELDS,
        TOPOLOGY_LINK,
    ),
)

COMPONENTS = (
    COLLISION_PIPELINE,
    COMPOSITE_COLLISION_PIPELINE,
    SUB_COLLISION_PIPELINE,
    BRUTE_FORCE_BROAD_PHASE,
    BVH_NARROW_PHASE,
    PARALLEL_BRUTE_FORCE_BROAD_PHASE,
    PARALLEL_BVH_NARROW_PHASE,
    BRUTE_FORCE_DETECTION,
    MIN_PROXIMITY_INTERSECTION,
    NEW_PROXIMITY_INTERSECTION,
    DISCRETE_INTERSECTION,
    LOCAL_MIN_DISTANCE,
    CCD_TIGHT_INCLUSION_INTERSECTION,
    COLLISION_RESPONSE,
    RULE_BASED_CONTACT_MANAGER,
    SPHERE_COLLISION_MODEL,
    TRIANGLE_COLLISION_MODEL,
    LINE_COLLISION_MODEL,
    POINT_COLLISION_MODEL,
    CUBE_COLLISION_MODEL,
    CYLINDER_COLLISION_MODEL,
    RAY_COLLISION_MODEL,
    TETRAHEDRON_COLLISION_MODEL,
    TRIANGLE_OCTREE_COLLISION_MODEL,
)
