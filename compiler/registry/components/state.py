"""The scene-graph Node and the mechanical state (MechanicalObject)."""

from __future__ import annotations

from ...limits import MAX_GENERATED_POINTS
from ..fields import AttributeNumber, Bool, Coords, Int, Real, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec
from .common import ALL_TYPES, MUST_BE_POSITIVE

NODE = ComponentSpec(
    name="Node",
    category=Category.CONTEXT,
    doc="A node of the scene graph. Only the root's dt and gravity count (children copy the root's).",
    supported=True,
    fields=(
        FieldSpec("gravity", Reals(3), (0.0, -9.81, 0.0), "gravity (only the root's value counts)"),
        FieldSpec("dt", Real(), 0.01, "time step (only the root's value counts)", valid=MUST_BE_POSITIVE),
        FieldSpec("time", Real(), 0.0, "current time"),
        FieldSpec("animate", Bool(), False, "start animating at load"),
        FieldSpec("activated", Bool(), True, "a deactivated subtree is skipped"),
        FieldSpec("sleeping", Bool(), False),
        FieldSpec("canChangeSleepingState", Bool(), False),
        FieldSpec("depend", Text(), doc="legacy dependency hints"),
        FieldSpec("multiThreadSimulation", Bool(), False),
        FieldSpec("showVisualModels", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showBehaviorModels", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showCollisionModels", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showMappings", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showForceFields", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showInteractionForceFields", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showWireFrame", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("showNormals", Bool(), doc="legacy display flag", deprecated=True),
        FieldSpec("processor", Int(), doc="legacy", deprecated=True),
    ),
)

_TRANSFORM_FIELDS = (
    FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0), "translation applied at init"),
    FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "rotation (Euler angles, degrees) applied at init"),
    FieldSpec("scale3d", Reals(3), (1.0, 1.0, 1.0), "scale applied at init"),
    FieldSpec("translation2", Reals(3), (0.0, 0.0, 0.0), "translation applied after the rest shape"),
    FieldSpec("rotation2", Reals(3), (0.0, 0.0, 0.0), "rotation applied after the rest shape"),
    # Legacy per-axis spellings, read by MechanicalObject::parse as single-precision floats.
    *(FieldSpec(a, AttributeNumber(), 0.0, "legacy translation component") for a in ("dx", "dy", "dz")),
    *(
        FieldSpec(a, AttributeNumber(), 0.0, "legacy rotation component (degrees)")
        for a in ("rx", "ry", "rz")
    ),
    *(FieldSpec(a, AttributeNumber(), 0.0, "legacy translation2 component") for a in ("dx2", "dy2", "dz2")),
    *(FieldSpec(a, AttributeNumber(), 0.0, "legacy rotation2 component") for a in ("rx2", "ry2", "rz2")),
    FieldSpec("scale", AttributeNumber(), 1.0, "legacy uniform scale", valid=MUST_BE_POSITIVE),
    *(
        FieldSpec(a, AttributeNumber(), 1.0, "legacy per-axis scale", valid=MUST_BE_POSITIVE)
        for a in ("sx", "sy", "sz")
    ),
)

MECHANICAL_OBJECT = ComponentSpec(
    name="MechanicalObject",
    lowering="mechanical_object",
    category=Category.STATE,
    module="Sofa.Component.StateContainer",
    doc="The degrees of freedom of a node: positions, velocities, forces.",
    templates=ALL_TYPES,
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.STATE}),
    fields=(
        FieldSpec("position", Coords(), doc="positions", aliases=("x",)),
        FieldSpec("velocity", Coords(deriv=True, allow_single=True), doc="velocities", aliases=("v",)),
        FieldSpec("force", Coords(deriv=True), doc="forces", aliases=("f",)),
        FieldSpec("externalForce", Coords(deriv=True), doc="external forces"),
        FieldSpec("derivX", Coords(deriv=True), doc="dx", aliases=("dx_",)),
        FieldSpec("free_position", Coords(), doc="free-motion positions"),
        FieldSpec("free_velocity", Coords(deriv=True), doc="free-motion velocities"),
        FieldSpec("rest_position", Coords(), doc="rest positions", aliases=("x0",)),
        FieldSpec("reset_position", Coords(), doc="positions restored on reset"),
        FieldSpec("reset_velocity", Coords(deriv=True), doc="velocities restored on reset"),
        FieldSpec(
            "restScale", Real(), 1.0, "scale of the rest shape (<1 pre-stresses)", valid=MUST_BE_POSITIVE
        ),
        FieldSpec("useTopology", Bool(), True, "take size/positions from the node's topology"),
        FieldSpec(
            "size",
            Int(nonnegative=True),
            0,
            "number of DOFs",
            valid=(lambda n: n <= MAX_GENERATED_POINTS, f"must be at most {MAX_GENERATED_POINTS}"),
        ),
        FieldSpec("reserve", Int(nonnegative=True), 0, "capacity to reserve"),
        FieldSpec("showObject", Bool(), False),
        FieldSpec("showObjectScale", Real(), 0.1),
        FieldSpec("showIndices", Bool(), False),
        FieldSpec("showIndicesScale", Real(), 0.02),
        FieldSpec("showVectors", Bool(), False),
        FieldSpec("showVectorsScale", Real(), 0.0001),
        FieldSpec("drawMode", Int(), 0),
        FieldSpec("showColor", Reals(4), doc="display color"),
        *_TRANSFORM_FIELDS,
    ),
)

COMPONENTS = (NODE, MECHANICAL_OBJECT)
