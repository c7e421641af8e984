"""Masses: the inertia of a mechanical state (and the gravity force m g it receives)."""

from __future__ import annotations

from ..fields import Bool, FileName, Ints, IntVector, Link, MassValue, Real, Reals
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import ELEMENT_TEMPLATES, MASS_FIELDS, MUST_BE_POSITIVE, TOPOLOGY_LINK

_MASS_EFFECTS = frozenset({Effect.INERTIA, Effect.GRAVITY})
_MODULE = "Sofa.Component.Mass"

# Display Data common to the masses below.
_DISPLAY = (
    FieldSpec("showGravityCenter", Bool(), False, "draw the centre of gravity"),
    FieldSpec("showAxisSizeFactor", Real(), 1.0, "axis length when drawing rigid masses"),
)

# Masses computed from a density over the elements of a topology (DOF type, optionally geometry type).
_DENSITY_TEMPLATES = ("Vec3d", "Vec2d", "Vec2d,Vec3d", "Vec1d", "Vec1d,Vec2d", "Vec1d,Vec3d")

UNIFORM_MASS = ComponentSpec(
    name="UniformMass",
    lowering="uniform_mass",
    category=Category.MASS,
    module=_MODULE,
    doc="The same mass for every DOF: vertexMass each, or totalMass spread evenly. One of the two is "
    "required (SOFA marks the component invalid otherwise); if both are set totalMass wins.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d", "Rigid2d"),
    default_template="Vec3d",
    supported=True,
    effects=_MASS_EFFECTS,
    fields=(
        FieldSpec(
            "vertexMass", MassValue(), doc="mass of each DOF (Rigid3d: m volume I00..I22 per unit mass)"
        ),
        FieldSpec("totalMass", Real(), doc="total mass spread evenly over the DOFs", valid=MUST_BE_POSITIVE),
        FieldSpec("filename", FileName(), doc=".rigid (Xsp 3.0) file with mass, volume and inertia"),
        FieldSpec("indices", Ints(), doc="DOFs the mass applies to (default: all)", indexes="state"),
        FieldSpec("localRange", IntVector(2), (-1, -1), "first and last DOF index the mass applies to"),
        FieldSpec("compute_mapping_inertia", Bool(), False, "add inertia forces when placed under a mapping"),
        FieldSpec("preserveTotalMass", Bool(), False, "keep totalMass when DOFs are removed"),
        *_DISPLAY,
        FieldSpec("showInitialCenterOfGravity", Bool(), False),
        FieldSpec("showX0", Bool(), False, "draw the rest positions"),
        *MASS_FIELDS,
        TOPOLOGY_LINK,
    ),
)

DIAGONAL_MASS = ComponentSpec(
    name="DiagonalMass",
    lowering="diagonal_mass",
    category=Category.MASS,
    module=_MODULE,
    doc="Lumped mass from the node's topology: each element gives density x measure / nodes to its "
    "nodes. Precedence: totalMass > massDensity > vertexMass.",
    templates=(
        "Vec3d",
        "Vec2d",
        "Vec2d,Vec3d",
        "Vec1d",
        "Vec1d,Vec2d",
        "Vec1d,Vec3d",
        "Rigid3d",
        "Rigid2d",
        "Rigid2d,Rigid3d",
    ),
    default_template="Vec3d",
    supported=True,
    effects=_MASS_EFFECTS,
    fields=(
        FieldSpec("vertexMass", Reals(), doc="mass of each vertex"),
        FieldSpec("massDensity", Real(), 1.0, "mass per unit length/area/volume", valid=MUST_BE_POSITIVE),
        FieldSpec("totalMass", Real(), 1.0, "total mass, rescales the lumped masses", valid=MUST_BE_POSITIVE),
        FieldSpec("computeMassOnRest", Bool(), True, "compute element measures on the rest positions"),
        FieldSpec("filename", FileName(), doc="Xsp 3.0 file with the masses", aliases=("fileMass",)),
        FieldSpec("geometryState", Link("state"), doc="state giving the geometry (two-template forms)"),
        *_DISPLAY,
        *MASS_FIELDS,
        TOPOLOGY_LINK,
    ),
)

MESH_MATRIX_MASS = ComponentSpec(
    name="MeshMatrixMass",
    lowering="mesh_matrix_mass",
    category=Category.MASS,
    module=_MODULE,
    doc="Consistent finite-element mass matrix (vertex and edge terms) from the node's topology; "
    "lumping=true sums each row onto the diagonal.",
    templates=_DENSITY_TEMPLATES,
    default_template="Vec3d",
    supported=True,
    effects=_MASS_EFFECTS,
    fields=(
        FieldSpec("massDensity", Reals(), doc="mass density (one, or per element)", valid=MUST_BE_POSITIVE),
        FieldSpec("totalMass", Real(), 1.0, "total mass", valid=MUST_BE_POSITIVE),
        FieldSpec("vertexMass", Reals(), doc="internal: mass terms on vertices"),
        FieldSpec("edgeMass", Reals(), doc="internal: mass terms on edges"),
        FieldSpec("computeMassOnRest", Bool(), False, "compute element measures on the rest positions"),
        FieldSpec("lumping", Bool(), False, "lump the matrix onto its diagonal"),
        FieldSpec("printMass", Bool(), False, "log the mass for checking"),
        FieldSpec("geometryState", Link("state"), doc="state giving the geometry (two-template forms)"),
        *_DISPLAY,
        *MASS_FIELDS,
        TOPOLOGY_LINK,
    ),
)


FEM_MASS = ComponentSpec(
    name="FEMMass",
    lowering="fem_mass",
    category=Category.MASS,
    module=_MODULE,
    doc='Consistent finite-element mass matrix of one element type (template "Vec3d,Tetrahedron" or '
    '"Vec3d,Hexahedron" compiled), integrated with the density of a NodalMassDensity (its link, '
    "else the first one in its context) interpolated from the nodes; needs an implicit solver.",
    templates=ELEMENT_TEMPLATES,
    default_template=ELEMENT_TEMPLATES[0],
    supported=True,
    effects=_MASS_EFFECTS,
    fields=(
        FieldSpec("nodalMassDensity", Link("object"), doc="NodalMassDensity giving the density per node"),
        *MASS_FIELDS,
        TOPOLOGY_LINK,
    ),
)

NODAL_MASS_DENSITY = ComponentSpec(
    name="NodalMassDensity",
    variant=Variant.NODAL_MASS_DENSITY,
    category=Category.UTILITY,
    module=_MODULE,
    doc="A mass density value per node, read by FEMMass (a node beyond the list takes its last value).",
    supported=True,
    effects=frozenset({Effect.DATA}),
    fields=(FieldSpec("property", Reals(), (1.0,), "density per node (one value, or one per node)"),),
)

COMPONENTS = (UNIFORM_MASS, DIAGONAL_MASS, MESH_MATRIX_MASS, FEM_MASS, NODAL_MASS_DENSITY)
