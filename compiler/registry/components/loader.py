"""Loaders: read a file (or generate a mesh) at init and expose its arrays as Data for src= links."""

from __future__ import annotations

from ..fields import AttributeNumber, Bool, Coords, FileName, Int, Ints, IntVector, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec
from .common import MUST_BE_POSITIVE

_MODULE = "Sofa.Component.IO.Mesh"
_DATA = frozenset({Effect.DATA})


def _at_least_two(x: float) -> bool:
    return x >= 2


_IDENTITY_4X4 = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _subelements(default: bool) -> FieldSpec:
    return FieldSpec(
        "createSubelements",
        Bool(),
        default,
        "append the missing boundary elements: quads of hexahedra, triangles of tetrahedra, edges "
        "of quads and triangles (MeshLoader::updateElements)",
    )


# core::loader::MeshLoader without the file name (BaseLoader's), which generators do not need.
_MESH_LOADER_DATA = (
    FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0), "translation applied at load (after rotation)"),
    FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "rotation (Euler angles, degrees) applied at load"),
    FieldSpec("scale3d", Reals(3), (1.0, 1.0, 1.0), "scale applied at load (first)"),
    FieldSpec(
        "scale", AttributeNumber(), doc="legacy uniform scale (multiplies scale3d)", valid=MUST_BE_POSITIVE
    ),
    FieldSpec(
        "transformation", Reals(16), _IDENTITY_4X4, "4x4 homogeneous transform; replaces the others if set"
    ),
    FieldSpec("flipNormals", Bool(), False, "reverse the element orientation"),
    FieldSpec("triangulate", Bool(), False, "split polygons into triangles"),
    _subelements(False),
    FieldSpec("onlyAttachedPoints", Bool(), False, "drop points not used by any element"),
    # outputs
    FieldSpec("position", Coords(), doc="vertex positions"),
    FieldSpec("polylines", Ints(), doc="polylines"),
    FieldSpec("edges", Ints(2), doc="edges"),
    FieldSpec("triangles", Ints(3), doc="triangles"),
    FieldSpec("quads", Ints(4), doc="quads"),
    FieldSpec("polygons", Ints(), doc="polygons"),
    FieldSpec("tetrahedra", Ints(4), doc="tetrahedra", aliases=("tetras",)),
    FieldSpec("hexahedra", Ints(8), doc="hexahedra", aliases=("hexas",)),
    FieldSpec("prisms", Ints(6), doc="prisms", aliases=("pentas", "pentahedra")),
    FieldSpec("pyramids", Ints(5), doc="pyramids"),
    FieldSpec("normals", Reals(multiple=3), doc="vertex normals"),
    *(
        FieldSpec(f"highOrder{kind}Positions", Reals(), doc=f"high-order {kind.lower()} points")
        for kind in ("Edge", "Triangle", "Quad", "Tetrahedron", "Hexahedron")
    ),
    *(
        FieldSpec(f"{kind}Groups", Text(), doc=f"groups of {kind}", aliases=aliases)
        for kind, aliases in (
            ("edges", ()),
            ("triangles", ()),
            ("quads", ()),
            ("polygons", ()),
            ("tetrahedra", ()),
            ("hexahedra", ()),
            ("prisms", ("pentahedraGroups",)),
            ("pyramids", ()),
        )
    ),
)
_FILE = FieldSpec("filename", FileName(), doc="file to read", required=True)
_MESH_LOADER_FIELDS = (_FILE, *_MESH_LOADER_DATA)


def _mesh_loader(
    name: str, doc: str, *extra: FieldSpec, former: tuple[str, ...] = (), subelements: bool = False
) -> ComponentSpec:
    fields = (*extra, *_MESH_LOADER_FIELDS)
    if subelements:
        fields = tuple(_subelements(True) if f.name == "createSubelements" else f for f in fields)
    return ComponentSpec(
        name=name,
        category=Category.LOADER,
        module=_MODULE,
        doc=doc,
        former_names=former,
        supported=True,
        effects=_DATA,
        compute="mesh_loader",
        fields=fields,
    )


MESH_OBJ_LOADER = _mesh_loader(
    "MeshOBJLoader",
    "Wavefront OBJ (v, vt, vn, f; materials from .mtl).",
    FieldSpec("handleSeams", Bool(), False, "duplicate vertices at UV/normal seams (else merge by position)"),
    FieldSpec("loadMaterial", Bool(), True, "read the .mtl file"),
    FieldSpec("defaultMaterial", Text(), doc="material used without a .mtl", aliases=("material",)),
    FieldSpec("materials", Text(), doc="output: materials"),
    FieldSpec("faceList", Text(), doc="output: face definitions"),
    FieldSpec("texcoordsIndex", Text(), doc="output: texture coordinate indices of the faces"),
    FieldSpec("positionsDefinition", Coords(), doc="output: positions as defined in the file"),
    FieldSpec("texcoordsDefinition", Reals(multiple=2), doc="output: texture coordinates as defined"),
    FieldSpec("normalsIndex", Text(), doc="output: normal indices of the faces"),
    FieldSpec("normalsDefinition", Reals(multiple=3), doc="output: normals as defined"),
    FieldSpec("texcoords", Reals(multiple=2), doc="output: texture coordinates per vertex"),
    FieldSpec("computeMaterialFaces", Bool(), False, "output face lists per material"),
    FieldSpec("vertPosIdx", Ints(), doc="output (handleSeams): position index of each vertex"),
    FieldSpec("vertNormIdx", Ints(), doc="output (handleSeams): normal index of each vertex"),
    former=("MeshObjLoader",),
)
# MeshGmshLoader::doLoad sets createSubelements to true when the scene does not set it.
MESH_GMSH_LOADER = _mesh_loader("MeshGmshLoader", "Gmsh .msh (format 1, 2 ASCII, 4).", subelements=True)
MESH_VTK_LOADER = _mesh_loader(
    "MeshVTKLoader", "Legacy VTK (.vtk) and XML UnstructuredGrid or PolyData (.vtu, .vtp)."
)
MESH_STL_LOADER = _mesh_loader(
    "MeshSTLLoader",
    "STL triangles, ASCII or binary (vertices merged by exact equality, in order of first appearance).",
    FieldSpec("headerSize", Int(), 80, "bytes of a binary file's header (sofac reads 80)"),
    FieldSpec("forceBinary", Bool(), False, "read as binary even if the file starts with 'solid'"),
    FieldSpec("mergePositionUsingMap", Bool(), True, "merge equal vertices with a map (same result)"),
)

SPHERE_LOADER = ComponentSpec(
    name="SphereLoader",
    category=Category.LOADER,
    module=_MODULE,
    doc="Sphere list (.sph: 'sphe id x y z r'): centres and radii.",
    supported=True,
    effects=_DATA,
    compute="sphere_loader",
    fields=(
        _FILE,
        FieldSpec("position", Coords(), doc="output: sphere centres", aliases=("sphere_centers",)),
        FieldSpec("listRadius", Reals(), doc="output: sphere radii"),
        FieldSpec("scale", Reals(3), (1.0, 1.0, 1.0), "scale of centres and radii", aliases=("scale3d",)),
        FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "rotation (degrees)"),
        FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0), "translation"),
    ),
)

STRING_MESH_CREATOR = ComponentSpec(
    name="StringMeshCreator",
    compute="string_mesh",
    category=Category.LOADER,
    module=_MODULE,
    doc="Generates a 1-D mesh: `resolution` points on the unit segment along x, joined by edges.",
    supported=True,
    effects=_DATA,
    fields=(
        FieldSpec("resolution", Int(), 2, "number of vertices", valid=(_at_least_two, "must be >= 2")),
        FieldSpec("filename", FileName(), doc="unused by this generator"),
        *_MESH_LOADER_DATA,
    ),
)

GRID_MESH_CREATOR = ComponentSpec(
    name="GridMeshCreator",
    compute="grid_mesh",
    category=Category.LOADER,
    module=_MODULE,
    doc="Generates a 2-D mesh of resolution[0] x resolution[1] points on the unit square (z = 0): "
    "quads, or two triangles per cell (alternate, upward or downward), and their edges.",
    supported=True,
    effects=_DATA,
    fields=(
        FieldSpec(
            "resolution",
            IntVector(2),
            (2, 2),
            "number of vertices along x and y",
            valid=(_at_least_two, "must be >= 2"),
        ),
        FieldSpec(
            "trianglePattern",
            Int(),
            2,
            "0: quads, 1: alternate triangles, 2: upward triangles, 3: downward triangles",
        ),
        # canLoad() is true: SOFA never reads the file (the Data is read-only)
        FieldSpec("filename", Text(), doc="unused by this generator"),
        *_MESH_LOADER_DATA,
    ),
)

COMPONENTS = (
    MESH_OBJ_LOADER,
    MESH_GMSH_LOADER,
    MESH_VTK_LOADER,
    MESH_STL_LOADER,
    SPHERE_LOADER,
    STRING_MESH_CREATOR,
    GRID_MESH_CREATOR,
)
