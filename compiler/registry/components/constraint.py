"""Projective constraints: filters that project positions, velocities and solver increments."""

from __future__ import annotations

from ..fields import Bool, Bools, Coords, Int, Ints, Real, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import PAIR_LINKS, PROJECTIVE_FIELDS

_MODULE = "Sofa.Component.Constraint.Projective"
_PROJECTION = frozenset({Effect.PROJECTION})

# The six base DataTypes in SOFA's registration order (the first is the default template).
_SIX = ("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d", "Rigid2d")

_INDICES = FieldSpec("indices", Ints(), doc="constrained DOFs", indexes="state")
# Line, Plane, Point and LinearVelocity constraints start with index 0 in their list (SOFA's constructors).
_INDICES_FROM_0 = FieldSpec("indices", Ints(), (0,), "constrained DOFs (default: 0)", indexes="state")
_DRAW_SIZE = FieldSpec("drawSize", Real(), 0.0, "display size (0: points)")

_FIXED_FIELDS = (
    _INDICES,
    FieldSpec("fixAll", Bool(), False, "constrain every DOF"),
    FieldSpec("activate_projectVelocity", Bool(), False, "also force the velocity of the DOFs to zero"),
    FieldSpec("showObject", Bool(), True),
    _DRAW_SIZE,
    *PROJECTIVE_FIELDS,
)

FIXED_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="FixedProjectiveConstraint",
    lowering="fixed",
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Keeps the selected DOFs at their initial positions (whole DOF: every translation/rotation).",
    templates=_SIX,
    default_template="Vec3d",
    renamed_from=("FixedConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=_FIXED_FIELDS,
)

PARTIAL_FIXED_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="PartialFixedProjectiveConstraint",
    lowering="partial_fixed",
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Fixes the selected DOFs along some coordinates only (one 0/1 flag per Deriv coordinate).",
    templates=_SIX,
    default_template="Vec3d",
    renamed_from=("PartialFixedConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=(
        FieldSpec(
            "fixedDirections", Bools(), doc="per Deriv coordinate: 1 fixed, 0 free (default: all fixed)"
        ),
        FieldSpec("projectVelocity", Bool(), False, "also zero the velocity along fixed directions"),
        *_FIXED_FIELDS,
    ),
)

LINE_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="LineProjectiveConstraint",
    lowering="line_or_plane",
    variant=Variant.LINE,
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Projects the selected points onto a line (they may only slide along it).",
    templates=("Vec3d", "Vec2d"),
    default_template="Vec3d",
    renamed_from=("ProjectToLineConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=(
        _INDICES_FROM_0,
        FieldSpec("origin", Reals(), doc="a point of the line"),
        FieldSpec("direction", Reals(), doc="direction of the line"),
        _DRAW_SIZE,
        *PROJECTIVE_FIELDS,
    ),
)

PLANE_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="PlaneProjectiveConstraint",
    lowering="line_or_plane",
    variant=Variant.PLANE,
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Projects the selected points onto a plane (they may only move within it).",
    templates=("Vec3d", "Vec2d"),
    default_template="Vec3d",
    renamed_from=("ProjectToPlaneConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=(
        _INDICES_FROM_0,
        FieldSpec("origin", Reals(), doc="a point of the plane"),
        FieldSpec("normal", Reals(), doc="normal of the plane"),
        _DRAW_SIZE,
        *PROJECTIVE_FIELDS,
    ),
)

POINT_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="PointProjectiveConstraint",
    lowering="point_constraint",
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Projects the selected points onto a fixed target point.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d"),
    default_template="Vec3d",
    renamed_from=("ProjectToPointConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=(
        _INDICES_FROM_0,
        FieldSpec("point", Reals(), doc="target point"),
        FieldSpec("fixAll", Bool(), False, "project every DOF"),
        _DRAW_SIZE,
        *PROJECTIVE_FIELDS,
    ),
)

_KEYED = ("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d")

LINEAR_VELOCITY_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="LinearVelocityProjectiveConstraint",
    lowering="linear_velocity",
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Imposes a velocity on the selected DOFs, interpolated linearly between key times.",
    templates=_KEYED,
    default_template="Vec3d",
    renamed_from=("LinearVelocityConstraint",),
    supported=True,
    effects=_PROJECTION,
    fields=(
        _INDICES_FROM_0,
        FieldSpec("keyTimes", Reals(), (0.0,), "key times (default: 0)"),
        FieldSpec("velocities", Coords(deriv=True), doc="velocity at each key time"),
        FieldSpec("coordinates", Ints(), doc="coordinates the velocity applies to (default: all)"),
        FieldSpec("continueAfterEnd", Bool(), False, "keep the last velocity after the last key time"),
        *PROJECTIVE_FIELDS,
    ),
)

LINEAR_MOVEMENT_PROJECTIVE_CONSTRAINT = ComponentSpec(
    name="LinearMovementProjectiveConstraint",
    category=Category.PROJECTIVE_CONSTRAINT,
    module=_MODULE,
    doc="Imposes a displacement on the selected DOFs, interpolated linearly between key times.",
    templates=_KEYED,
    default_template="Vec3d",
    renamed_from=("LinearMovementConstraint",),
    lowering="linear_movement",
    supported=True,
    effects=_PROJECTION,
    fields=(
        _INDICES_FROM_0,
        FieldSpec("keyTimes", Reals(), (0.0,), "key times (default: 0)"),
        FieldSpec("movements", Coords(deriv=True), doc="displacement at each key time (default: one zero)"),
        FieldSpec("relativeMovements", Bool(), True, "movements are relative to the initial positions"),
        FieldSpec("showMovement", Bool(), False),
        *PROJECTIVE_FIELDS,
    ),
)


def _compiled(
    name: str, old: str, lowering: str, templates: tuple[str, ...], doc: str, *fields: FieldSpec
) -> ComponentSpec:
    return ComponentSpec(
        name=name,
        lowering=lowering,
        category=Category.PROJECTIVE_CONSTRAINT,
        module=_MODULE,
        doc=doc,
        templates=templates,
        default_template=templates[0],
        renamed_from=(old,),
        supported=True,
        effects=_PROJECTION,
        fields=(*fields, *PROJECTIVE_FIELDS),
    )


FIXED_PLANE_PROJECTIVE_CONSTRAINT = _compiled(
    "FixedPlaneProjectiveConstraint",
    "FixedPlaneConstraint",
    "fixed_plane",
    ("Rigid3d", "Vec3d", "Vec6d"),
    "Removes, from the responses of the selected points, their component along `direction` (the "
    "points between the planes dmin < x.direction < dmax when dmin != dmax).",
    _INDICES,
    FieldSpec("direction", Reals(), doc="plane normal (used as given: not normalised)"),
    FieldSpec("dmin", Real(), 0.0, "minimum distance of the planes to the origin"),
    FieldSpec("dmax", Real(), 0.0, "maximum distance of the planes to the origin"),
)

FIXED_ROTATION_PROJECTIVE_CONSTRAINT = _compiled(
    "FixedRotationProjectiveConstraint",
    "FixedRotationConstraint",
    "fixed_rotation",
    ("Rigid3d",),
    "Prevents rotations of every rigid DOF about the selected axes (positions projected after each step).",
    FieldSpec("FixedXRotation", Bool(), False),
    FieldSpec("FixedYRotation", Bool(), False),
    FieldSpec("FixedZRotation", Bool(), False),
)

FIXED_TRANSLATION_PROJECTIVE_CONSTRAINT = _compiled(
    "FixedTranslationProjectiveConstraint",
    "FixedTranslationConstraint",
    "fixed_translation",
    ("Rigid3d", "Rigid2d", "Vec6d"),
    "Zeroes the responses of the selected DOFs (SOFA clears the whole derivative, rotations too); "
    "velocities and positions are left as they are.",
    _INDICES_FROM_0,
    FieldSpec("fixAll", Bool(), False),
    FieldSpec("coordinates", Coords(), doc="coordinates of the fixed points"),
    _DRAW_SIZE,
)

DIRECTION_PROJECTIVE_CONSTRAINT = _compiled(
    "DirectionProjectiveConstraint",
    "ProjectDirectionConstraint",
    "direction",
    ("Vec3d", "Vec2d"),
    "Restricts the motion of the selected points to the line through their initial positions along "
    "a direction.",
    _INDICES_FROM_0,
    FieldSpec("direction", Reals(), doc="allowed direction (normalised)"),
    _DRAW_SIZE,
)


# Other projective constraints of SOFA, registered so that their pre-v24.06 names resolve.
_MOTION = "prescribed motions and special projections are not supported yet"


def _other(name: str, old: str, templates: tuple[str, ...], doc: str, *fields: FieldSpec) -> ComponentSpec:
    return ComponentSpec(
        name=name,
        category=Category.PROJECTIVE_CONSTRAINT,
        module=_MODULE,
        doc=doc,
        templates=templates,
        default_template=templates[0],
        renamed_from=(old,),
        unsupported_reason=f"{name}: {_MOTION}",
        effects=_PROJECTION,
        fields=(*fields, *PROJECTIVE_FIELDS),
    )


_TIME_WINDOW = (
    FieldSpec("BeginTime", Real(), doc="start of the motion"),
    FieldSpec("EndTime", Real(), doc="end"),
)
_BILINEAR = (
    FieldSpec("meshIndices", Ints(), doc="indices of the mesh"),
    _INDICES,
    FieldSpec("beginConstraintTime", Real(), doc="start of the motion"),
    FieldSpec("endConstraintTime", Real(), doc="end of the motion"),
    FieldSpec("drawConstrainedPoints", Bool()),
)

OTHER_PROJECTIVE_CONSTRAINTS = (
    _other(
        "AffineMovementProjectiveConstraint",
        "AffineMovementConstraint",
        ("Vec3d", "Rigid3d"),
        "Imposes an affine motion (rotation + translation) on border points.",
        *_BILINEAR,
        FieldSpec("rotation", Reals(9), doc="rotation matrix"),
        FieldSpec("quaternion", Reals(4), doc="rotation quaternion"),
        FieldSpec("translation", Reals(3), doc="translation"),
    ),
    _other(
        "HermiteSplineProjectiveConstraint",
        "HermiteSplineConstraint",
        ("Vec3d", "Rigid3d"),
        "Moves the selected points along a cubic Hermite spline.",
        _INDICES,
        *_TIME_WINDOW,
        *(FieldSpec(n, Reals(), doc="spline control data") for n in ("X0", "dX0", "X1", "dX1", "SX0", "SX1")),
    ),
    _other(
        "OscillatorProjectiveConstraint",
        "OscillatorConstraint",
        ("Vec3d", "Rigid3d"),
        "Sinusoidal motion of selected particles.",
        FieldSpec("oscillators", Reals(), doc="index, mean, amplitude, pulsation, phase per oscillator"),
    ),
    _other(
        "ParabolicProjectiveConstraint",
        "ParabolicConstraint",
        ("Vec3d", "Rigid3d"),
        "Moves the selected points along a parabola through three points.",
        _INDICES,
        FieldSpec("P1", Reals(3)),
        FieldSpec("P2", Reals(3)),
        FieldSpec("P3", Reals(3)),
        *_TIME_WINDOW,
    ),
    _other(
        "PartialLinearMovementProjectiveConstraint",
        "PartialLinearMovementConstraint",
        _KEYED,
        "Linear movement of the selected DOFs along some directions only.",
        _INDICES,
        FieldSpec("keyTimes", Reals()),
        FieldSpec("movements", Coords(deriv=True)),
        FieldSpec("showMovement", Bool(), False),
        FieldSpec("linearMovementBetweenNodesInIndices", Bool(), False),
        FieldSpec("mainIndice", Int()),
        FieldSpec("minDepIndice", Int()),
        FieldSpec("maxDepIndice", Int()),
        FieldSpec("imposedDisplacmentOnMacroNodes", Reals()),
        FieldSpec("X0", Real(), 0.0),
        FieldSpec("Y0", Real(), 0.0),
        FieldSpec("Z0", Real(), 0.0),
        FieldSpec("movedDirections", Bools()),
    ),
    _other(
        "PatchTestMovementProjectiveConstraint",
        "PatchTestMovementConstraint",
        ("Vec3d", "Rigid3d"),
        "Bilinear boundary motion for patch tests.",
        *_BILINEAR,
        FieldSpec("constrainedPoints", Coords()),
        FieldSpec("cornerMovements", Coords(deriv=True)),
        FieldSpec("cornerPoints", Coords()),
    ),
    _other(
        "PositionBasedDynamicsProjectiveConstraint",
        "PositionBasedDynamicsConstraint",
        ("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d"),
        "Blends positions towards target positions (position-based dynamics).",
        FieldSpec("stiffness", Real(), 1.0, "blend factor"),
        FieldSpec("position", Coords(), doc="target positions"),
        FieldSpec("velocity", Coords(deriv=True)),
        FieldSpec("old_position", Coords()),
    ),
    _other(
        "SkeletalMotionProjectiveConstraint",
        "SkeletalMotionConstraint",
        ("Rigid3d",),
        "Drives rigid DOFs from a skeleton animation.",
        FieldSpec("joints", Text()),
        FieldSpec("bones", Text()),
        FieldSpec("animationSpeed", Real(), 1.0),
        FieldSpec("active", Bool(), True),
    ),
    ComponentSpec(
        name="AttachProjectiveConstraint",
        category=Category.PROJECTIVE_CONSTRAINT,
        module=_MODULE,
        doc="Projects points of object2 onto points of object1 (an attachment by projection).",
        templates=("Vec3d", "Vec2d", "Vec1d", "Rigid3d", "Rigid2d"),
        default_template="Vec3d",
        renamed_from=("AttachConstraint",),
        unsupported_reason=f"AttachProjectiveConstraint: {_MOTION}",
        effects=_PROJECTION,
        fields=(
            FieldSpec("indices1", Ints(), doc="source points in object1", indexes="object1"),
            FieldSpec("indices2", Ints(), doc="attached points in object2", indexes="object2"),
            FieldSpec("twoWay", Bool(), False),
            FieldSpec("freeRotations", Bool(), False),
            FieldSpec("lastFreeRotation", Bool(), False),
            FieldSpec("restRotations", Bool(), False),
            FieldSpec("lastPos", Reals(3)),
            FieldSpec("lastDir", Reals(3)),
            FieldSpec("clamp", Bool(), False),
            FieldSpec("minDistance", Real(), -1.0),
            FieldSpec("positionFactor", Real(), 1.0),
            FieldSpec("velocityFactor", Real(), 1.0),
            FieldSpec("responseFactor", Real(), 1.0),
            FieldSpec("constraintFactor", Reals()),
            FieldSpec("endTime", Real(), -1.0),
            *PAIR_LINKS,
        ),
    ),
)

COMPONENTS = (
    FIXED_PROJECTIVE_CONSTRAINT,
    PARTIAL_FIXED_PROJECTIVE_CONSTRAINT,
    LINE_PROJECTIVE_CONSTRAINT,
    PLANE_PROJECTIVE_CONSTRAINT,
    POINT_PROJECTIVE_CONSTRAINT,
    LINEAR_VELOCITY_PROJECTIVE_CONSTRAINT,
    LINEAR_MOVEMENT_PROJECTIVE_CONSTRAINT,
    FIXED_PLANE_PROJECTIVE_CONSTRAINT,
    FIXED_ROTATION_PROJECTIVE_CONSTRAINT,
    FIXED_TRANSLATION_PROJECTIVE_CONSTRAINT,
    DIRECTION_PROJECTIVE_CONSTRAINT,
    *OTHER_PROJECTIVE_CONSTRAINTS,
)
