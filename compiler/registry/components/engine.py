"""Engines: Data-to-Data functions evaluated lazily by SOFA (statically by sofac when possible)."""

from __future__ import annotations

from ..fields import Bool, Coords, Int, Ints, Real, Reals
from ..spec import Category, ComponentSpec, Effect, FieldSpec

_DATA = frozenset({Effect.DATA})

_ROI_ELEMENTS = (
    ("edges", "edge", "edgeIndices", "edgesInROI", 2),
    ("triangles", "triangle", "triangleIndices", "trianglesInROI", 3),
    ("quads", "quad", "quadIndices", "quadsInROI", 4),
    ("tetrahedra", "tetrahedron", "tetrahedronIndices", "tetrahedraInROI", 4),
    ("hexahedra", "hexahedron", "hexahedronIndices", "hexahedraInROI", 8),
)


def _element_fields() -> tuple[FieldSpec, ...]:
    fields: list[FieldSpec] = []
    for plural, _single, indices, in_roi, size in _ROI_ELEMENTS:
        quad = plural == "quads"
        compute = f"compute{plural[0].upper()}{plural[1:]}"
        fields += [
            FieldSpec(
                plural,
                Ints(size),
                doc=f"input {plural} (default: the node's topology)",
                aliases=("quad",) if quad else (),
            ),
            FieldSpec(
                compute,
                Bool(),
                True,
                f"select the {plural} inside the ROI",
                aliases=("computeQuad",) if quad else (),
            ),
            FieldSpec(indices, Ints(), doc=f"output: indices of the {plural} inside the ROI"),
            FieldSpec(
                in_roi,
                Ints(size),
                doc=f"output: {plural} inside the ROI",
                aliases=("quadInROI",) if quad else (),
            ),
        ]
    return tuple(fields)


BOX_ROI = ComponentSpec(
    name="BoxROI",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Select",
    doc="Selects the points (and elements) inside axis-aligned or oriented boxes; with static inputs "
    "a pure function of the rest positions.",
    templates=("Vec3d", "Vec2d", "Vec1d", "Rigid3d", "Vec6d"),
    default_template="Vec3d",
    supported=True,
    effects=_DATA,
    compute="box_roi",
    fields=(
        FieldSpec("box", Reals(multiple=6), doc="boxes, 6 numbers each: xmin ymin zmin xmax ymax zmax"),
        FieldSpec("orientedBox", Reals(multiple=10), doc="oriented boxes: three points p0 p1 p2 and a depth"),
        FieldSpec("position", Coords(), doc="input points (default: the node's rest positions)"),
        FieldSpec("strict", Bool(), True, "an element is inside only if all its nodes are"),
        FieldSpec("indices", Ints(), doc="output: indices of the points inside"),
        FieldSpec("pointsInROI", Coords(), doc="output: points inside"),
        FieldSpec("nbIndices", Int(), doc="output: number of points inside"),
        *_element_fields(),
        FieldSpec("indicesOut", Ints(), doc="output: indices of the points outside"),
        FieldSpec("pointsOutROI", Coords(), doc="output: points outside"),
        FieldSpec("edgeOutIndices", Ints(), doc="output"),
        FieldSpec("edgesOutROI", Ints(2), doc="output"),
        FieldSpec("triangleOutIndices", Ints(), doc="output"),
        FieldSpec("trianglesOutROI", Ints(3), doc="output"),
        FieldSpec("tetrahedronOutIndices", Ints(), doc="output"),
        FieldSpec("tetrahedraOutROI", Ints(4), doc="output"),
        FieldSpec("drawROI", Bool(), False, "draw the boxes", aliases=("drawBoxes",)),
        FieldSpec("drawPoints", Bool(), False),
        FieldSpec("drawEdges", Bool(), False),
        FieldSpec("drawTriangles", Bool(), False),
        FieldSpec("drawQuads", Bool(), False),
        FieldSpec("drawTetrahedra", Bool(), False),
        FieldSpec("drawHexahedra", Bool(), False),
        FieldSpec("drawSize", Real(), 1.0, "display size"),
        FieldSpec("doUpdate", Bool(), True, "update the selection at each step"),
    ),
)

TRANSFORM_ENGINE = ComponentSpec(
    name="TransformEngine",
    compute="transform_engine",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Transform",
    doc="Applies scale, rotation and translation (or their inverse) to a list of points.",
    templates=("Vec3d", "Vec1d", "Vec2d", "Rigid2d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    effects=_DATA,
    fields=(
        FieldSpec("input_position", Coords(), doc="input points"),
        FieldSpec("output_position", Coords(), doc="output: transformed points"),
        FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0)),
        FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "Euler angles (degrees)"),
        FieldSpec("quaternion", Reals(4), (0.0, 0.0, 0.0, 1.0), "rotation quaternion (x y z w)"),
        FieldSpec("scale", Reals(3), (1.0, 1.0, 1.0)),
        FieldSpec("inverse", Bool(), False, "apply the inverse transform"),
    ),
)

MERGE_VECTORS = ComponentSpec(
    name="MergeVectors",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Generate",
    doc="Concatenates nbInputs vectors input1, input2, ... into `output` (evaluated at compile time).",
    supported=True,
    compute="merge_vectors",
    effects=_DATA,
    fields=(
        FieldSpec("nbInputs", Int(nonnegative=True), 2, "number of inputs"),
        *(FieldSpec(f"input{i}", Reals(), doc=f"input vector {i}") for i in range(1, 9)),
        FieldSpec("output", Reals(), doc="output: concatenation"),
    ),
)

_SUBSET_ELEMENTS = (
    ("edges", "edge", 2),
    ("triangles", "triangle", 3),
    ("quads", "quad", 4),
    ("tetrahedra", "tetrahedron", 4),
    ("hexahedra", "hexahedron", 8),
)

SUBSET_TOPOLOGY = ComponentSpec(
    name="SubsetTopology",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Select",
    doc="Splits a topology by boxes (or spheres): the points and elements inside, those outside, "
    "optionally re-numbered (localIndices) so that each part is a topology of its own.",
    templates=("Vec3d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    effects=_DATA,
    compute="subset_topology",
    fields=(
        FieldSpec(
            "box", Reals(multiple=6), (0.0, 0.0, 0.0, 1.0, 1.0, 1.0), "boxes: xmin ymin zmin xmax ymax zmax"
        ),
        FieldSpec("centers", Reals(multiple=3), doc="sphere centres (given: spheres instead of boxes)"),
        FieldSpec("radii", Reals(), doc="sphere radii"),
        FieldSpec("direction", Reals(3), (0.0, 0.0, 0.0), "unused by SOFA's update"),
        FieldSpec("normal", Reals(3), (0.0, 0.0, 0.0), "unused by SOFA's update"),
        FieldSpec("edgeAngle", Real(), 0.0, "unused by SOFA's update"),
        FieldSpec("triAngle", Real(), 0.0, "unused by SOFA's update"),
        FieldSpec("rest_position", Coords(), doc="input points (default: the state's positions)"),
        *(
            FieldSpec(
                plural,
                Ints(size),
                doc=f"input {plural}"
                + (
                    " (default: the context topology's)"
                    if plural in ("edges", "triangles", "tetrahedra")
                    else ""
                ),
            )
            for plural, _single, size in _SUBSET_ELEMENTS
        ),
        FieldSpec(
            "tetrahedraInput", Ints(), doc="indices of the tetrahedra to keep (instead of the regions)"
        ),
        FieldSpec("indices", Ints(), (0,), "output: indices of the points inside"),
        *(
            FieldSpec(f"{single}Indices", Ints(), doc=f"output: indices of the {plural} inside")
            for plural, single, _size in _SUBSET_ELEMENTS
        ),
        FieldSpec("pointsInROI", Coords(), doc="output: points inside"),
        FieldSpec("pointsOutROI", Coords(), doc="output: points outside"),
        *(
            FieldSpec(f"{plural}{side}ROI", Ints(size), doc=f"output: {plural} {side.lower()}side")
            for plural, _single, size in _SUBSET_ELEMENTS
            for side in ("In", "Out")
        ),
        FieldSpec("nbrborder", Int(), 0, "output (localIndices): number of points on the border"),
        FieldSpec("localIndices", Bool(), False, "re-number the outputs: border points first"),
        FieldSpec("drawROI", Bool(), False),
        FieldSpec("drawPoints", Bool(), False),
        FieldSpec("drawEdges", Bool(), False),
        FieldSpec("drawTriangle", Bool(), False),
        FieldSpec("drawTetrahedra", Bool(), False),
        FieldSpec("drawSize", Real(), 1.0, "display size"),
    ),
)

PLANE_ROI = ComponentSpec(
    name="PlaneROI",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Select",
    doc="Selects the points (and edges, triangles, tetrahedra) inside slabs, each given by three "
    "points of a rectangle and a depth.",
    templates=("Vec3d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    effects=_DATA,
    compute="plane_roi",
    fields=(
        FieldSpec(
            "plane",
            Reals(multiple=10),
            (0.0,) * 10,
            "slabs, 10 numbers each: three corners p0 p1 p2 of a rectangle and a depth",
        ),
        FieldSpec(
            "position",
            Coords(),
            doc="input points (default: the state's rest positions)",
            aliases=("rest_position",),
        ),
        FieldSpec("edges", Ints(2), doc="input edges (default: the context topology's)"),
        FieldSpec("triangles", Ints(3), doc="input triangles (default: the context topology's)"),
        FieldSpec("tetrahedra", Ints(4), doc="input tetrahedra (default: the context topology's)"),
        FieldSpec("computeEdges", Bool(), True, "select the edges inside"),
        FieldSpec("computeTriangles", Bool(), True, "select the triangles inside"),
        FieldSpec("computeTetrahedra", Bool(), True, "select the tetrahedra inside"),
        FieldSpec("indices", Ints(), (0,), "output: indices of the points inside"),
        FieldSpec("edgeIndices", Ints(), doc="output"),
        FieldSpec("triangleIndices", Ints(), doc="output"),
        FieldSpec("tetrahedronIndices", Ints(), doc="output"),
        FieldSpec("pointsInROI", Coords(), doc="output: points inside"),
        FieldSpec("edgesInROI", Ints(2), doc="output"),
        FieldSpec("trianglesInROI", Ints(3), doc="output"),
        FieldSpec("tetrahedraInROI", Ints(4), doc="output"),
        FieldSpec("drawBoxes", Bool(), False, aliases=("isVisible",)),
        FieldSpec("drawPoints", Bool(), False),
        FieldSpec("drawEdges", Bool(), False),
        FieldSpec("drawTriangles", Bool(), False),
        FieldSpec("drawTetrahedra", Bool(), False),
        FieldSpec("drawSize", Real(), 1.0, "display size"),
    ),
)

PAIR_BOX_ROI = ComponentSpec(
    name="PairBoxROI",
    category=Category.ENGINE,
    module="Sofa.Component.Engine.Select",
    doc="Selects the points inside an inclusive box and outside an included box.",
    templates=("Vec3d", "Rigid3d", "Vec6d"),
    default_template="Vec3d",
    supported=True,
    effects=_DATA,
    compute="pair_box_roi",
    fields=(
        FieldSpec("inclusiveBox", Reals(6), (0.0,) * 6, "outer box: xmin ymin zmin xmax ymax zmax"),
        FieldSpec("includedBox", Reals(6), (0.0,) * 6, "inner box, left out"),
        FieldSpec(
            "position",
            Coords(),
            doc="input points (default: the state's rest positions)",
            aliases=("rest_position",),
        ),
        FieldSpec("meshPosition", Coords(), doc="unused by SOFA's update"),
        FieldSpec("indices", Ints(), doc="output: indices of the points between the boxes"),
        FieldSpec("pointsInROI", Coords(), doc="output: those points", aliases=("pointsInBox",)),
        FieldSpec("drawInclusiveBox", Bool(), False),
        FieldSpec("drawIncludedBox", Bool(), False),
        FieldSpec("drawPoints", Bool(), False),
        FieldSpec("drawSize", Real(), 0.0, "display size"),
    ),
)

COMPONENTS = (BOX_ROI, TRANSFORM_ENGINE, MERGE_VECTORS, SUBSET_TOPOLOGY, PLANE_ROI, PAIR_BOX_ROI)
