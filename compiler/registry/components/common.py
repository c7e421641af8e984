"""Field groups shared by many components (SOFA's base classes), written once."""

from __future__ import annotations

from ..fields import Bool, Coords, FileName, Ints, Link, Reals, Text, Words
from ..spec import FieldSpec

ALL_VEC = ("Vec1d", "Vec2d", "Vec3d", "Vec6d")
ALL_TYPES = (*ALL_VEC, "Rigid2d", "Rigid3d")


def positive(x: float) -> bool:
    return x > 0


def nonnegative(x: float) -> bool:
    return x >= 0


MUST_BE_POSITIVE = (positive, "must be > 0")
MUST_BE_NONNEGATIVE = (nonnegative, "must be >= 0")

# BaseMapping / Mapping<In, Out>.
MAPPING_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("input", Link("state"), "@../", "input (parent) mechanical state"),
    FieldSpec("output", Link("state"), "@./", "output (child) state or visual model"),
    FieldSpec("mapForces", Bool(), True, "map forces from output to input"),
    FieldSpec("mapConstraints", Bool(), True, "map constraints from output to input"),
    FieldSpec("mapMasses", Bool(), True, "map masses from output to input"),
    FieldSpec("mapMatrices", Bool(), False, "map stiffness matrices"),
    FieldSpec("applyRestPosition", Bool(), False, "also map the rest position at init"),
)

# Links a component acting on one state may carry.
STATE_LINKS: tuple[FieldSpec, ...] = (
    FieldSpec("mstate", Link("state"), doc="mechanical state to act on (default: the node's)"),
    FieldSpec("topology", Link("topology"), doc="topology to use (default: the node's)"),
)

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
