"""Mappings: a child state computed from a parent state (positions, velocities; forces mapped back)."""

from __future__ import annotations

from ..fields import Bool, Color, Coords, FileName, Int, Ints, Link, LinkList, Options, Real, Reals
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import GEOMETRIC_STIFFNESS, MAPPING_FIELDS, MUST_BE_NONNEGATIVE, TOPOLOGY_LINK

_LINEAR = "Sofa.Component.Mapping.Linear"
_NONLINEAR = "Sofa.Component.Mapping.NonLinear"
_MAPPING = frozenset({Effect.MAPPING})

# NonLinearMappingData<true>: the geometric stiffness may be exact or stabilised (made positive).
_GEOMETRIC_STIFFNESS = FieldSpec(
    "geometricStiffness",
    Options(values=GEOMETRIC_STIFFNESS),
    "Stabilized",
    "geometric stiffness of the mapping: None, Exact, or Stabilized (negative eigenvalues clamped)",
)

BARYCENTRIC_MAPPING = ComponentSpec(
    name="BarycentricMapping",
    lowering="barycentric_mapping",
    category=Category.MAPPING,
    module=_LINEAR,
    doc="Child points embedded in the cells of the parent's topology (grid cells, tetrahedra, "
    "hexahedra, triangles, ...), with barycentric coordinates fixed at init.",
    templates=("Vec3d,Vec3d",),
    default_template="Vec3d,Vec3d",
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec("useRestPosition", Bool(), False, "compute the embedding from rest positions"),
        FieldSpec("input_topology", Link("topology"), doc="parent topology (default: the input node's)"),
        FieldSpec("output_topology", Link("topology"), doc="child topology (default: the output node's)"),
        *MAPPING_FIELDS,
    ),
)

SUBSET_MAPPING = ComponentSpec(
    name="SubsetMapping",
    lowering="subset_mapping",
    category=Category.MAPPING,
    module=_LINEAR,
    doc="Child DOF i is parent DOF indices[i] (or matched by position within `radius`).",
    templates=("Vec3d,Vec3d", "Vec1d,Vec1d", "Rigid3d,Rigid3d"),
    default_template="Vec3d,Vec3d",
    former_names=("SurfaceIdentityMapping",),
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec("indices", Ints(), doc="parent DOF of each child DOF", indexes="input"),
        FieldSpec(
            "first", Int(nonnegative=True), doc="first parent index of a contiguous range", indexes="input"
        ),
        FieldSpec(
            "last", Int(nonnegative=True), doc="last parent index of a contiguous range", indexes="input"
        ),
        FieldSpec(
            "radius", Real(), 1e-5, "matching distance when no indices are given", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec("handleTopologyChange", Bool(), True),
        FieldSpec("ignoreNotFound", Bool(), False, "leave unmatched child points unmapped"),
        FieldSpec("resizeToModel", Bool(), False, "resize the child state to the number of indices"),
        *MAPPING_FIELDS,
        TOPOLOGY_LINK,
    ),
)

IDENTITY_MAPPING = ComponentSpec(
    name="IdentityMapping",
    lowering="identity_mapping",
    category=Category.MAPPING,
    module=_LINEAR,
    doc="Child = parent, DOF by DOF (Rigid to Vec keeps the positions).",
    templates=(
        "Vec3d,Vec3d",
        "Vec2d,Vec2d",
        "Vec1d,Vec1d",
        "Vec6d,Vec3d",
        "Vec6d,Vec6d",
        "Rigid3d,Rigid3d",
        "Rigid2d,Rigid2d",
        "Rigid3d,Vec3d",
        "Rigid2d,Vec2d",
    ),
    default_template="Vec3d,Vec3d",
    supported=True,
    effects=_MAPPING,
    fields=MAPPING_FIELDS,
)

RIGID_MAPPING = ComponentSpec(
    name="RigidMapping",
    lowering="rigid_mapping",
    category=Category.MAPPING,
    module=_NONLINEAR,
    doc="Points (or frames) attached to rigid parent frames: x = c + R(q) p with p in local coordinates.",
    templates=("Rigid3d,Vec3d", "Rigid3d,Rigid3d", "Rigid2d,Vec2d"),
    default_template="Rigid3d,Vec3d",
    former_names=("RigidRigidMapping",),
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec(
            "initialPoints", Coords(), doc="child coordinates in the parent frame (default: the child's)"
        ),
        FieldSpec("index", Int(nonnegative=True), 0, "parent DOF driving every child", indexes="input"),
        FieldSpec("rigidIndexPerPoint", Ints(), doc="parent DOF of each child point", indexes="input"),
        FieldSpec("indexFromEnd", Bool(), False, "index counts from the last parent DOF"),
        FieldSpec("globalToLocalCoords", Bool(), False, "child positions are given in world coordinates"),
        FieldSpec("useX0", Bool(), False, "use the child's rest positions as local coordinates"),
        FieldSpec(
            "filename", FileName(), doc="Xsp or .sph file with the mapping", aliases=("fileRigidMapping",)
        ),
        FieldSpec(
            "d_repartition",
            Ints(),
            deprecated=True,
            doc="legacy: number of child points per parent DOF (converted to rigidIndexPerPoint)",
        ),
        FieldSpec(  # RigidMapping's constructor selects None (NonLinearMappingData defaults to Stabilized)
            "geometricStiffness",
            Options(values=GEOMETRIC_STIFFNESS),
            "None",
            "geometric stiffness of the mapping: None, Exact, or Stabilized (negative eigenvalues clamped)",
        ),
        *MAPPING_FIELDS,
    ),
)

_DISTANCE_TEMPLATES = ("Vec3d,Vec1d", "Rigid3d,Vec1d")
_DISTANCE_FIELDS = (
    FieldSpec("computeDistance", Bool(), False, "rest length 0 (map the distance itself)"),
    FieldSpec("restLengths", Reals(), doc="rest length per edge (default: initial lengths)"),
    FieldSpec("showObjectScale", Real(), 0.0),
    FieldSpec("showColor", Color(), (1.0, 1.0, 0.0, 1.0)),
    _GEOMETRIC_STIFFNESS,
)

DISTANCE_MAPPING = ComponentSpec(
    name="DistanceMapping",
    lowering="distance_mapping",
    category=Category.MAPPING,
    module=_NONLINEAR,
    doc="One scalar per edge of the topology: its length minus the rest length.",
    templates=_DISTANCE_TEMPLATES,
    default_template="Vec3d,Vec1d",
    supported=True,
    effects=_MAPPING,
    fields=(*_DISTANCE_FIELDS, *MAPPING_FIELDS, TOPOLOGY_LINK),
)

SQUARE_DISTANCE_MAPPING = ComponentSpec(
    name="SquareDistanceMapping",
    lowering="distance_mapping",
    variant=Variant.SQUARE,
    category=Category.MAPPING,
    module=_NONLINEAR,
    doc="One scalar per edge of the topology: its squared length.",
    templates=_DISTANCE_TEMPLATES,
    default_template="Vec3d,Vec1d",
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec("showObjectScale", Real(), 0.0),
        FieldSpec("showColor", Color(), (1.0, 1.0, 0.0, 1.0)),
        _GEOMETRIC_STIFFNESS,
        *MAPPING_FIELDS,
        TOPOLOGY_LINK,
    ),
)

DISTANCE_MULTI_MAPPING = ComponentSpec(
    name="DistanceMultiMapping",
    lowering="distance_multi_mapping",
    category=Category.MULTI_MAPPING,
    module=_NONLINEAR,
    doc="Distances between points of several parent states (edges refer to indexPairs).",
    templates=_DISTANCE_TEMPLATES,
    default_template="Vec3d,Vec1d",
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec("input", LinkList("state"), doc="parent states (several links)"),
        FieldSpec("indexPairs", Ints(2), doc="per child point: parent number and index in that parent"),
        *_DISTANCE_FIELDS,
        *MAPPING_FIELDS[1:],
        TOPOLOGY_LINK,
    ),
)

BEAM_LINEAR_MAPPING = ComponentSpec(
    name="BeamLinearMapping",
    category=Category.MAPPING,
    module=_LINEAR,
    doc="Points attached to beams between consecutive rigid frames (linear interpolation).",
    templates=("Rigid3d,Vec3d",),
    default_template="Rigid3d,Vec3d",
    lowering="beam_linear_mapping",
    supported=True,
    effects=_MAPPING,
    fields=(
        FieldSpec("index", Int(nonnegative=True), 0, "input DOF index"),
        FieldSpec("localCoord", Bool(), True, "child coordinates are in the beam's local frame"),
        *MAPPING_FIELDS,
    ),
)

COMPONENTS = (
    BARYCENTRIC_MAPPING,
    SUBSET_MAPPING,
    IDENTITY_MAPPING,
    RIGID_MAPPING,
    DISTANCE_MAPPING,
    SQUARE_DISTANCE_MAPPING,
    DISTANCE_MULTI_MAPPING,
    BEAM_LINEAR_MAPPING,
)
