"""Topologies: static meshes, grid generators, dynamic containers and their helpers, topological mappings."""

from __future__ import annotations

from ..fields import Bool, Color, Coords, FileName, Int, Ints, IntVector, Link, Real, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import MUST_BE_AT_LEAST_ONE, MUST_BE_NONNEGATIVE, MUST_BE_POSITIVE

_CONSTANT = "Sofa.Component.Topology.Container.Constant"
_GRID = "Sofa.Component.Topology.Container.Grid"
_DYNAMIC = "Sofa.Component.Topology.Container.Dynamic"
_MAPPING = "Sofa.Component.Topology.Mapping"
_TOPOLOGY = frozenset({Effect.TOPOLOGY})
_GENERATED = frozenset({Effect.TOPOLOGY, Effect.DATA})

_FILENAME = FieldSpec(
    "filename", FileName(), doc="mesh file to load the topology from", aliases=("fileTopology",)
)

# MeshTopology (static): arrays given directly, by src=, or read from a file.
_MESH_TOPOLOGY_FIELDS = (
    FieldSpec("position", Coords(), doc="vertex positions", aliases=("points",)),
    FieldSpec("edges", Ints(2), doc="edges", aliases=("lines",)),
    FieldSpec("triangles", Ints(3), doc="triangles"),
    FieldSpec("quads", Ints(4), doc="quads"),
    FieldSpec("tetrahedra", Ints(4), doc="tetrahedra", aliases=("tetras",)),
    FieldSpec("hexahedra", Ints(8), doc="hexahedra", aliases=("hexas",)),
    FieldSpec("prisms", Ints(6), doc="prisms"),
    FieldSpec("pyramids", Ints(5), doc="pyramids"),
    FieldSpec("uv", Reals(multiple=2), doc="texture coordinates", aliases=("texcoords",)),
    FieldSpec("computeAllBuffers", Bool(), False, "build every cross-reference buffer at init"),
    FieldSpec("drawEdges", Bool(), False),
    FieldSpec("drawTriangles", Bool(), False),
    FieldSpec("drawQuads", Bool(), False),
    FieldSpec("drawTetrahedra", Bool(), False),
    FieldSpec("drawHexahedra", Bool(), False),
    _FILENAME,
)

MESH_TOPOLOGY = ComponentSpec(
    name="MeshTopology",
    category=Category.TOPOLOGY,
    module=_CONSTANT,
    doc="Static mesh: points and elements, usually copied from a loader with src=.",
    former_names=("Mesh",),
    supported=True,
    effects=_TOPOLOGY,
    fields=_MESH_TOPOLOGY_FIELDS,
)

_LEGACY_BOUNDS = tuple(
    FieldSpec(name, Real(), doc=f"legacy bound (all six of xmin..zmax must be given): {name}")
    for name in ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
)
_LEGACY_COUNTS = tuple(
    FieldSpec(
        name,
        Int(),
        doc=f"legacy resolution (all three of nx ny nz must be given): {name}",
        valid=MUST_BE_AT_LEAST_ONE,
    )
    for name in ("nx", "ny", "nz")
)

_GRID_FIELDS = (
    FieldSpec("n", IntVector(3), (2, 2, 2), "number of points along x, y, z", valid=MUST_BE_AT_LEAST_ONE),
    *_LEGACY_COUNTS,
    FieldSpec("computeHexaList", Bool(), True),
    FieldSpec("computeQuadList", Bool(), True),
    FieldSpec("computeTriangleList", Bool(), True),
    FieldSpec("computeEdgeList", Bool(), True),
    FieldSpec("computePointList", Bool(), True),
    FieldSpec("createTexCoords", Bool(), False, "generate texture coordinates"),
    *_MESH_TOPOLOGY_FIELDS,
)

GRID_TOPOLOGY = ComponentSpec(
    name="GridTopology",
    category=Category.TOPOLOGY,
    module=_GRID,
    doc="Connectivity of an nx x ny x nz grid (base of RegularGridTopology), without geometry: its "
    "points are its own position list resized to nx ny nz (0 0 0 past its end, all of them without "
    "one), so the MechanicalObject usually gives the positions.",
    former_names=("Grid",),
    supported=True,
    effects=_GENERATED,
    compute="grid_topology",
    rewrites=("position",),
    fields=_GRID_FIELDS,
)

REGULAR_GRID_TOPOLOGY = ComponentSpec(
    name="RegularGridTopology",
    variant=Variant.REGULAR_GRID,
    category=Category.TOPOLOGY,
    module=_GRID,
    doc="Regular grid between min and max: points (index x + nx (y + ny z)), edges, all grid quads, "
    "triangles, hexahedra.",
    former_names=("RegularGrid",),
    supported=True,
    effects=_GENERATED,
    compute="grid",
    fields=(
        FieldSpec("min", Reals(3), (0.0, 0.0, 0.0), "lower corner"),
        FieldSpec("max", Reals(3), (1.0, 1.0, 1.0), "upper corner"),
        FieldSpec("p0", Reals(3), (0.0, 0.0, 0.0), "offset added to every point"),
        FieldSpec(
            "cellWidth", Real(), 0.0, "if > 0: fixed cell size (overrides n)", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec("scale", Real(), doc="legacy: scales the legacy bounds", valid=MUST_BE_POSITIVE),
        *_LEGACY_BOUNDS,
        *_GRID_FIELDS,
    ),
)

_SPARSE_GRID_FIELDS = (
    FieldSpec("n", IntVector(3), (2, 2, 2), "grid resolution (points per axis)", valid=MUST_BE_AT_LEAST_ONE),
    FieldSpec("min", Reals(3), (0.0, 0.0, 0.0), "lower corner (0 0 0 with max 0 0 0: the mesh bounding box)"),
    FieldSpec("max", Reals(3), (0.0, 0.0, 0.0), "upper corner"),
    FieldSpec("cellWidth", Real(), 0.0, "if > 0: fixed cell size", valid=MUST_BE_NONNEGATIVE),
    FieldSpec("fillWeighted", Bool(), True, "boundary cells count half"),
    FieldSpec("onlyInsideCells", Bool(), False, "keep only cells fully inside the surface"),
    FieldSpec("nbVirtualFinerLevels", Int(nonnegative=True), 0, "virtual finer levels for precise weights"),
    FieldSpec("dataResolution", IntVector(3, nonnegative=True), (0, 0, 0), "voxel file dimensions"),
    FieldSpec("voxelSize", Reals(3), (1.0, 1.0, 1.0), "size of one voxel"),
    FieldSpec("marchingCubeStep", Int(nonnegative=True), 1),
    FieldSpec("convolutionSize", Int(nonnegative=True), 0, "voxel smoothing kernel (0: none)"),
    FieldSpec("facets", Ints(), doc="input surface facets (with position)"),
    *_MESH_TOPOLOGY_FIELDS,
)

SPARSE_GRID_TOPOLOGY = ComponentSpec(
    name="SparseGridTopology",
    variant=Variant.SPARSE_GRID,
    category=Category.TOPOLOGY,
    module=_GRID,
    doc="Hexahedral cells of a regular grid that intersect or lie inside a closed surface mesh.",
    former_names=("SparseGrid",),
    supported=True,
    effects=_GENERATED,
    compute="sparse_grid",
    fields=_SPARSE_GRID_FIELDS,
)

SPARSE_GRID_RAMIFICATION_TOPOLOGY = ComponentSpec(
    name="SparseGridRamificationTopology",
    variant=Variant.SPARSE_GRID,
    category=Category.TOPOLOGY,
    module=_GRID,
    doc="Sparse grid that duplicates cells crossed by several disconnected parts of the surface.",
    former_names=("SparseGridRamification",),
    supported=True,
    effects=_GENERATED,
    compute="sparse_grid_ramification",
    fields=(
        FieldSpec("finestConnectivity", Bool(), True, "test connectivity at the finest level"),
        *_SPARSE_GRID_FIELDS,
    ),
)

CUBE_TOPOLOGY = ComponentSpec(
    name="CubeTopology",
    category=Category.TOPOLOGY,
    module=_CONSTANT,
    doc="Surface of a box between min and max: points, edges and quads (nx ny nz points per side).",
    supported=True,
    effects=_GENERATED,
    compute="cube_topology",
    fields=(
        *(
            FieldSpec(name, Int(), 0, f"resolution along {name[1]}", valid=MUST_BE_NONNEGATIVE)
            for name in ("nx", "ny", "nz")
        ),
        FieldSpec("internalPoints", Bool(), False, "also create the interior grid points"),
        FieldSpec("splitNormals", Bool(), False, "duplicate corner points for planar normals"),
        FieldSpec("min", Reals(3), (0.0, 0.0, 0.0), "lower corner"),
        FieldSpec("max", Reals(3), (1.0, 1.0, 1.0), "upper corner"),
        FieldSpec("scale", Real(), doc="legacy: scales the legacy bounds", valid=MUST_BE_POSITIVE),
        *_LEGACY_BOUNDS,
        *_MESH_TOPOLOGY_FIELDS,
    ),
)

# --- dynamic containers ----------------------------------------------------------------------

_POINT_SET = (
    FieldSpec("position", Coords(), doc="initial point positions", aliases=("points",)),
    FieldSpec("nbPoints", Int(nonnegative=True), 0, "number of points (when no positions)"),
    FieldSpec("checkTopology", Bool(), False, "run internal consistency checks"),
    _FILENAME,
)
_EDGE_SET = (
    FieldSpec("edges", Ints(2), doc="edges"),
    FieldSpec("checkConnexity", Bool(), False, "check that the mesh is connected"),
    *_POINT_SET,
)
_TRIANGLE_SET = (FieldSpec("triangles", Ints(3), doc="triangles"), *_EDGE_SET)
_QUAD_SET = (FieldSpec("quads", Ints(4), doc="quads"), *_EDGE_SET)
_TETRAHEDRON_SET = (
    FieldSpec("tetrahedra", Ints(4), doc="tetrahedra", aliases=("tetras",)),
    FieldSpec("createTriangleArray", Bool(), False, "create the triangles of the tetrahedra"),
    *_TRIANGLE_SET,
)
_HEXAHEDRON_SET = (
    FieldSpec("hexahedra", Ints(8), doc="hexahedra", aliases=("hexas",)),
    FieldSpec("createQuadArray", Bool(), False, "create the quads of the hexahedra"),
    *_QUAD_SET,
)

_KIND_FIELDS = {
    "Point": _POINT_SET,
    "Edge": _EDGE_SET,
    "Triangle": _TRIANGLE_SET,
    "Quad": _QUAD_SET,
    "Tetrahedron": _TETRAHEDRON_SET,
    "Hexahedron": _HEXAHEDRON_SET,
}
_KIND_ELEMENTS = {
    "Point": "points",
    "Edge": "edges",
    "Triangle": "triangles",
    "Quad": "quads",
    "Tetrahedron": "tetrahedra",
    "Hexahedron": "hexahedra",
}


def _container(kind: str) -> ComponentSpec:
    return ComponentSpec(
        name=f"{kind}SetTopologyContainer",
        # SOFA's barycentric mapper for dynamic containers; edges built from elements
        variant=Variant.DYNAMIC,
        category=Category.TOPOLOGY,
        module=_DYNAMIC,
        doc=f"Dynamic topology container of {_KIND_ELEMENTS[kind]} (and their sub-elements); static "
        "for sofac unless topological changes occur.",
        supported=True,
        effects=_TOPOLOGY,
        fields=_KIND_FIELDS[kind],
    )


_MODIFIER_EXTRA: dict[str, tuple[FieldSpec, ...]] = {
    "Point": (FieldSpec("propagateToDOF", Bool(), True, "propagate changes to the mechanical state"),),
    "Tetrahedron": (FieldSpec("removeIsolated", Bool(), True, "remove isolated DOFs"),),
    "Hexahedron": (FieldSpec("removeIsolated", Bool(), True, "remove isolated DOFs"),),
}
# *TopologyAlgorithms were merged into the Modifier / GeometryAlgorithms companions in v20.12.
_FORMER_ALGORITHMS = {kind: (f"{kind}SetTopologyAlgorithms",) for kind in _KIND_FIELDS}


def _modifier(kind: str) -> ComponentSpec:
    return ComponentSpec(
        name=f"{kind}SetTopologyModifier",
        category=Category.TOPOLOGY_HELPER,
        module=_DYNAMIC,
        doc=f"Applies topological changes to a {kind}SetTopologyContainer (no-op for a static mesh).",
        former_names=_FORMER_ALGORITHMS[kind],
        supported=True,
        effects=_TOPOLOGY,
        fields=(
            *_MODIFIER_EXTRA.get(kind, ()),
            *(_MODIFIER_EXTRA["Point"] if kind != "Point" else ()),
        ),
    )


_POINT_ALGORITHMS = (
    FieldSpec("showPointIndices", Bool(), False),
    FieldSpec("showIndicesScale", Real(), 1.0),
    FieldSpec("tagMechanics", Text(), doc="tag of the mechanical state to use"),
    FieldSpec("topology", Link("topology"), doc="container (default: the node's)"),
    FieldSpec("mstate", Link("state"), doc="state (default: the node's)"),
)
_EDGE_ALGORITHMS = (
    FieldSpec("showEdgeIndices", Bool(), False),
    FieldSpec("drawEdges", Bool(), False),
    FieldSpec("drawColorEdges", Color(), (0.4, 1.0, 0.3, 1.0)),
    *_POINT_ALGORITHMS,
)
_TRIANGLE_ALGORITHMS = (
    FieldSpec("showTriangleIndices", Bool(), False),
    FieldSpec("drawTriangles", Bool(), False),
    FieldSpec("drawColorTriangles", Color(), (0.3, 0.5, 0.8, 1.0)),
    FieldSpec("drawNormals", Bool(), False),
    FieldSpec("drawNormalLength", Real(), 10.0),
    FieldSpec("recomputeTrianglesOrientation", Bool(), False, "reorient triangles along the normals"),
    FieldSpec("flipNormals", Bool(), False, "flip the reference normal when reorienting"),
    *_EDGE_ALGORITHMS,
)
_QUAD_ALGORITHMS = (
    FieldSpec("showQuadIndices", Bool(), False),
    FieldSpec("drawQuads", Bool(), False),
    FieldSpec("drawColorQuads", Color(), (0.0, 0.4, 0.4, 1.0)),
    *_EDGE_ALGORITHMS,
)
_TETRAHEDRON_ALGORITHMS = (
    FieldSpec("showTetrahedraIndices", Bool(), False, aliases=("showTetrasIndices",)),
    FieldSpec("drawTetrahedra", Bool(), False, aliases=("drawTetra", "drawTetrahedron")),
    FieldSpec("drawScaleTetrahedra", Real(), 1.0),
    FieldSpec("drawColorTetrahedra", Color(), (1.0, 1.0, 0.0, 1.0)),
    *_TRIANGLE_ALGORITHMS,
)
_HEXAHEDRON_ALGORITHMS = (
    FieldSpec("showHexaIndices", Bool(), False),
    FieldSpec("drawHexahedra", Bool(), False, aliases=("drawHexa", "drawHexahedron")),
    FieldSpec("drawScaleHexahedra", Real(), 1.0),
    FieldSpec("drawColorHexahedra", Color(), (1.0, 0.5, 0.0, 1.0)),
    *_QUAD_ALGORITHMS,
)
_ALGORITHM_FIELDS = {
    "Point": _POINT_ALGORITHMS,
    "Edge": _EDGE_ALGORITHMS,
    "Triangle": _TRIANGLE_ALGORITHMS,
    "Quad": _QUAD_ALGORITHMS,
    "Tetrahedron": _TETRAHEDRON_ALGORITHMS,
    "Hexahedron": _HEXAHEDRON_ALGORITHMS,
}
_ALGORITHM_TEMPLATES = {
    "Point": ("Vec3d", "Vec2d", "Vec1d"),
    "Edge": ("Vec3d", "Vec2d", "Vec1d", "Rigid3d", "Rigid2d"),
}


def _geometry(kind: str) -> ComponentSpec:
    return ComponentSpec(
        name=f"{kind}SetGeometryAlgorithms",
        category=Category.TOPOLOGY_HELPER,
        module=_DYNAMIC,
        doc=f"Geometric queries on a {kind}SetTopologyContainer (and display options).",
        templates=_ALGORITHM_TEMPLATES.get(kind, ("Vec3d", "Vec2d")),
        default_template="Vec3d",
        supported=True,
        effects=_TOPOLOGY,
        fields=_ALGORITHM_FIELDS[kind],
    )


_KINDS = tuple(_KIND_FIELDS)
# The dynamic containers by element kind ("Edge", "Triangle", ...): what later stages compare with.
CONTAINERS = {kind: _container(kind) for kind in _KINDS}
DYNAMIC_TOPOLOGY = tuple(
    spec for kind in _KINDS for spec in (CONTAINERS[kind], _modifier(kind), _geometry(kind))
)

# --- topological mappings ----------------------------------------------------------------------

# SOFA's TopologicalMapping::create reads a missing input as "@../" and a missing output as "@./".
_TOPO_LINKS = (
    FieldSpec("input", Link("topology"), "@../", "input topology container", required=True),
    FieldSpec("output", Link("topology"), "@./", "output topology container", required=True),
)


def _topological_mapping(
    name: str, doc: str, *extra: FieldSpec, module: str = _MAPPING, compute: str = ""
) -> ComponentSpec:
    return ComponentSpec(
        name=name,
        category=Category.TOPOLOGICAL_MAPPING,
        module=module,
        doc=doc,
        supported=True,
        compute=compute,
        effects=_TOPOLOGY,
        fields=(*extra, *_TOPO_LINKS),
    )


HEXA2TETRA = _topological_mapping(
    "Hexa2TetraTopologicalMapping",
    "Splits each input hexahedron into tetrahedra written to the output container.",
    FieldSpec("swapping", Bool(), False, "alternate the split with the grid position (conforming mesh)"),
    compute="hexa_to_tetra",
)
HEXA2QUAD = _topological_mapping(
    "Hexa2QuadTopologicalMapping",
    "Writes the boundary quads of the input hexahedra to the output container.",
    FieldSpec("flipNormals", Bool(), False, "reverse the quad orientation"),
    compute="hexa_to_quad",
)
QUAD2TRIANGLE = _topological_mapping(
    "Quad2TriangleTopologicalMapping",
    "Splits each input quad into two triangles written to the output container.",
    FieldSpec("swapping", Bool(), True, "alternate the diagonal with the quad's grid position"),
    compute="quad_to_triangle",
)
TETRA2TRIANGLE = _topological_mapping(
    "Tetra2TriangleTopologicalMapping",
    "Writes the boundary triangles of the input tetrahedra to the output container.",
    FieldSpec("flipNormals", Bool(), False, "reverse the triangle orientation"),
    FieldSpec("noNewTriangles", Bool(), False, "do not add triangles on topological changes"),
    FieldSpec("noInitialTriangles", Bool(), False, "start with no triangles"),
    FieldSpec("modifier", Link("topology_helper"), doc="output modifier"),
    compute="tetra_to_triangle",
)
TRIANGLE2EDGE = _topological_mapping(
    "Triangle2EdgeTopologicalMapping",
    "Writes the boundary edges of the input triangles (the input container's edges that bound one "
    "triangle only, in its edge order) to the output edge container.",
    compute="triangle_to_edge",
)
MESH2POINT = _topological_mapping(
    "Mesh2PointTopologicalMapping",
    "Creates output points at given barycentric positions in each input point/edge/triangle/... element.",
    FieldSpec("pointBaryCoords", Reals(multiple=3), doc="positions relative to each input point"),
    FieldSpec("edgeBaryCoords", Reals(multiple=3), doc="barycentric positions in each input edge"),
    FieldSpec("triangleBaryCoords", Reals(multiple=3), doc="barycentric positions in each input triangle"),
    FieldSpec("quadBaryCoords", Reals(multiple=3), doc="barycentric positions in each input quad"),
    FieldSpec("tetraBaryCoords", Reals(multiple=3), doc="barycentric positions in each input tetrahedron"),
    FieldSpec("hexaBaryCoords", Reals(multiple=3), doc="barycentric positions in each input hexahedron"),
    FieldSpec("copyEdges", Bool(), False, "map input edges to output edges"),
    FieldSpec("copyTriangles", Bool(), False, "map input triangles to output triangles"),
    FieldSpec("copyTetrahedra", Bool(), False, "map input tetrahedra to output tetrahedra"),
    module="Sofa.Component.Mapping.Linear",
    compute="mesh_to_point",
)

TOPOLOGICAL_CHANGE_PROCESSOR = ComponentSpec(
    name="TopologicalChangeProcessor",
    category=Category.UTILITY,
    module="Sofa.Component.Topology.Utility",
    doc="Replays topological changes (adding/removing/cutting elements) from a file or Data lists.",
    unsupported_reason="runtime topological changes (TopologicalChangeProcessor) are not supported",
    effects=_TOPOLOGY,
    fields=(
        FieldSpec("filename", FileName(), doc="file of topological changes"),
        FieldSpec("listChanges", Reals(), doc="changes: 0 add, 1 remove, 2 cut, with indices"),
        FieldSpec("interval", Real(), 0.0, "time between two actions"),
        FieldSpec("shift", Real(), 0.0, "time shift of the file"),
        FieldSpec("loop", Bool(), False, "re-read the file at its end"),
        FieldSpec("useDataInputs", Bool(), False, "use the *ToRemove lists instead of a file"),
        FieldSpec("timeToRemove", Real(), 0.0),
        *(
            FieldSpec(f"{kind}ToRemove", Ints())
            for kind in ("points", "edges", "triangles", "quads", "tetrahedra", "hexahedra")
        ),
        FieldSpec("saveIndicesAtInit", Bool(), False),
        FieldSpec("epsilonSnapPath", Real(), 0.1),
        FieldSpec("epsilonSnapBorder", Real(), 0.25),
        FieldSpec("draw", Bool(), False),
        FieldSpec("topology", Link("topology")),
    ),
)

COMPONENTS = (
    MESH_TOPOLOGY,
    GRID_TOPOLOGY,
    REGULAR_GRID_TOPOLOGY,
    SPARSE_GRID_TOPOLOGY,
    SPARSE_GRID_RAMIFICATION_TOPOLOGY,
    CUBE_TOPOLOGY,
    *DYNAMIC_TOPOLOGY,
    HEXA2TETRA,
    HEXA2QUAD,
    QUAD2TRIANGLE,
    TETRA2TRIANGLE,
    TRIANGLE2EDGE,
    MESH2POINT,
    TOPOLOGICAL_CHANGE_PROCESSOR,
)
