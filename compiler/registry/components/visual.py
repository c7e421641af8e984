"""Visual models and rendering-only components (no effect on the simulated motion)."""

from __future__ import annotations

from ..fields import (
    AttributeNumber,
    Bool,
    Color,
    Coords,
    Enum,
    FileName,
    Int,
    Ints,
    Link,
    Options,
    Real,
    Reals,
    Text,
    Words,
)
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import MUST_BE_POSITIVE, VISUAL_MODEL_FIELDS

_VISUAL = frozenset({Effect.VISUAL})
_VISUAL_MODULE = "Sofa.Component.Visual"
_GL3D = "Sofa.GL.Component.Rendering3D"
_SHADER = "Sofa.GL.Component.Shader"

# VisualModelImpl (+ VisualState and VisualModel): the GL-free visual model OglModel builds on.
_VISUAL_MODEL_IMPL_FIELDS = (
    FieldSpec("position", Coords(), doc="vertex positions (usually set by a mapping)"),
    FieldSpec("restPosition", Coords(), doc="rest vertex positions"),
    FieldSpec("normal", Reals(multiple=3), doc="vertex normals"),
    FieldSpec("vertices", Coords(), doc="vertices when some have several normals/texcoords"),
    FieldSpec("texcoords", Reals(multiple=2), doc="texture coordinates"),
    FieldSpec("tangents", Reals(multiple=3)),
    FieldSpec("bitangents", Reals(multiple=3)),
    FieldSpec("edges", Ints(2), doc="edges drawn"),
    FieldSpec("triangles", Ints(3), doc="triangles drawn"),
    FieldSpec("quads", Ints(4), doc="quads drawn"),
    FieldSpec("vertPosIdx", Ints(), doc="position index of each vertex (seams)"),
    FieldSpec("vertNormIdx", Ints(), doc="normal index of each vertex (seams)"),
    FieldSpec("filename", FileName(), doc="mesh file to load directly", aliases=("fileMesh",)),
    FieldSpec("texturename", Text(), doc="texture image file (rendering only: not looked up by sofac)"),
    FieldSpec("translation", Reals(3), (0.0, 0.0, 0.0), "initial translation"),
    FieldSpec("rotation", Reals(3), (0.0, 0.0, 0.0), "initial rotation (Euler angles, degrees)"),
    FieldSpec("scale3d", Reals(3), (1.0, 1.0, 1.0), "initial scale"),
    FieldSpec("scaleTex", Reals(2), (1.0, 1.0), "texture scale"),
    FieldSpec("translationTex", Reals(2), (0.0, 0.0), "texture translation"),
    FieldSpec("material", Text(), doc="material description"),
    FieldSpec("materials", Text(), doc="materials"),
    FieldSpec("groups", Text(), doc="element groups per material"),
    FieldSpec("initRestPositions", Bool(), False, "initialise the rest positions from the positions"),
    FieldSpec("useNormals", Bool(), True, "read normal smoothing groups from the file"),
    FieldSpec("updateNormals", Bool(), True, "recompute normals every step"),
    FieldSpec("computeTangents", Bool(), False),
    FieldSpec("updateTangents", Bool(), True),
    FieldSpec("computeTextureCoordinates", Bool(), False, "spherical texture coordinates"),
    FieldSpec("handleDynamicTopology", Bool(), True),
    FieldSpec("fixMergedUVSeams", Bool(), True),
    FieldSpec("keepLines", Bool(), False, "keep and draw lines"),
    FieldSpec("putOnlyTexCoords", Bool(), False),
    FieldSpec("srgbTexturing", Bool(), False),
    # Attributes read by VisualModelImpl::parse (legacy spellings).
    FieldSpec("color", Color(), doc="diffuse color (sets the material)"),
    # (integers and single-precision floats of getAttributeAs*: a text that is not one number is
    # SOFA's default, so normals="false" or a normal list leaves useNormals true)
    FieldSpec(
        "normals",
        AttributeNumber(flag=True),
        doc="legacy: sets useNormals (an integer)",
        sets=("useNormals",),
    ),
    FieldSpec("castshadow", AttributeNumber(flag=True), doc="cast shadows (an integer)"),
    FieldSpec("flip", Bool(), doc="flip the faces"),
    *(
        FieldSpec(a, AttributeNumber(), doc="legacy texture scale/translation component")
        for a in ("su", "sv", "du", "dv")
    ),
    *(FieldSpec(a, AttributeNumber(), doc="legacy translation component") for a in ("dx", "dy", "dz")),
    *(FieldSpec(a, AttributeNumber(), doc="legacy rotation component (degrees)") for a in ("rx", "ry", "rz")),
    FieldSpec("scale", AttributeNumber(), doc="legacy uniform scale (one number)", valid=MUST_BE_POSITIVE),
    *(
        FieldSpec(a, AttributeNumber(), doc="legacy per-axis scale", valid=MUST_BE_POSITIVE)
        for a in ("sx", "sy", "sz")
    ),
    FieldSpec("topology", Link("topology"), doc="topology to draw (default: none, own arrays)"),
    *VISUAL_MODEL_FIELDS,
)

VISUAL_MODEL_IMPL = ComponentSpec(
    name="VisualModelImpl",
    category=Category.VISUAL,
    module=_VISUAL_MODULE,
    doc="GL-free visual model (what the factory alias VisualModel creates); same Data as OglModel's base.",
    aliases=("VisualModel",),
    supported=True,
    effects=_VISUAL,
    fields=_VISUAL_MODEL_IMPL_FIELDS,
)

_GL_FACTORS = ("GL_ZERO", "GL_ONE", "GL_SRC_ALPHA", "GL_ONE_MINUS_SRC_ALPHA")

OGL_MODEL = ComponentSpec(
    name="OglModel",
    category=Category.VISUAL,
    module=_GL3D,
    doc="OpenGL visual model: Vec3 positions plus triangles/quads, usually driven by a mapping.",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("blendTranslucency", Bool(), True),
        FieldSpec("premultipliedAlpha", Bool(), False),
        FieldSpec("writeZTransparent", Bool(), False),
        FieldSpec("alphaBlend", Bool(), False),
        FieldSpec("depthTest", Bool(), True),
        FieldSpec("cullFace", Int(), 0, "0 none, 1 back faces, 2 front faces"),
        FieldSpec("lineWidth", Real(), 1.0),
        FieldSpec("pointSize", Real(), 1.0),
        FieldSpec("lineSmooth", Bool(), False),
        FieldSpec("pointSmooth", Bool(), False),
        FieldSpec(
            "primitiveType", Options(values=("DEFAULT", "LINES_ADJACENCY", "PATCHES", "POINTS")), "DEFAULT"
        ),
        FieldSpec(
            "blendEquation",
            Options(values=("GL_FUNC_ADD", "GL_FUNC_SUBTRACT", "GL_MIN", "GL_MAX")),
            "GL_FUNC_ADD",
        ),
        FieldSpec("sfactor", Options(values=_GL_FACTORS), "GL_SRC_ALPHA"),
        FieldSpec("dfactor", Options(values=_GL_FACTORS), "GL_ONE_MINUS_SRC_ALPHA"),
        FieldSpec("isEnabled", Bool(), doc="legacy: sets enable", sets=("enable",)),
        *_VISUAL_MODEL_IMPL_FIELDS,
    ),
)

VISUAL_STYLE = ComponentSpec(
    name="VisualStyle",
    variant=Variant.VISUAL_STYLE,
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="Display flags of its subtree (showVisual, showBehaviorModels, showForceFields, "
    "showCollisionModels, showWireframe, hideVisual, ...).",
    supported=True,
    effects=_VISUAL,
    fields=(FieldSpec("displayFlags", Words(), doc="display flags"),),
)

# BaseCamera.
_CAMERA_FIELDS = (
    FieldSpec("position", Reals(3), doc="camera position"),
    FieldSpec("orientation", Reals(4), doc="camera orientation (quaternion x y z w)"),
    FieldSpec("lookAt", Reals(3), doc="point looked at"),
    FieldSpec("distance", Real(), doc="distance to the look-at point"),
    FieldSpec("fieldOfView", Real(), 45.0, "field of view (degrees)", valid=MUST_BE_POSITIVE),
    FieldSpec("zNear", Real(), 0.01),
    FieldSpec("zFar", Real(), 100.0),
    FieldSpec("computeZClip", Bool(), True, "compute zNear/zFar from the scene bounding box"),
    FieldSpec("minBBox", Reals(3), (0.0, 0.0, 0.0)),
    FieldSpec("maxBBox", Reals(3), (1.0, 1.0, 1.0)),
    FieldSpec("widthViewport", Int(), 800),
    FieldSpec("heightViewport", Int(), 600),
    FieldSpec("projectionType", Options(values=("Perspective", "Orthographic")), "Perspective"),
    FieldSpec("activated", Bool(), True),
    FieldSpec("fixedLookAt", Bool(), False),
    FieldSpec("modelViewMatrix", Reals(16)),
    FieldSpec("projectionMatrix", Reals(16)),
)

INTERACTIVE_CAMERA = ComponentSpec(
    name="InteractiveCamera",
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="Camera controlled with mouse and keyboard.",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("zoomSpeed", Real(), 250.0),
        FieldSpec("panSpeed", Real(), 0.1),
        FieldSpec("pivot", Int(), 2, "0 look-at, 1 camera position, 2 scene centre, 3 world centre"),
        *_CAMERA_FIELDS,
    ),
)

RECORDED_CAMERA = ComponentSpec(
    name="RecordedCamera",
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="Camera moving along a predefined rotation or path.",
    supported=True,  # rendering only: accepted, no part in the step (sofac render keeps its own camera)
    effects=_VISUAL,
    fields=(
        FieldSpec("zoomSpeed", Real(), 250.0),
        FieldSpec("panSpeed", Real(), 0.1),
        FieldSpec("pivot", Int(), 0, "0 scene centre, 1 world centre"),
        FieldSpec("startTime", Real(), 0.0),
        FieldSpec("endTime", Real(), 200.0),
        FieldSpec("rotationMode", Bool(), False),
        FieldSpec("translationMode", Bool(), False),
        FieldSpec("navigationMode", Bool(), False),
        FieldSpec("rotationSpeed", Real(), 0.1),
        FieldSpec("rotationCenter", Reals(3)),
        FieldSpec("rotationStartPoint", Reals(3)),
        FieldSpec("rotationLookAt", Reals(3)),
        FieldSpec("rotationAxis", Reals(3), (0.0, 1.0, 0.0)),
        FieldSpec("cameraUp", Reals(3), (0.0, 0.0, 0.0)),
        FieldSpec("drawRotation", Bool(), False),
        FieldSpec("drawTranslation", Bool(), False),
        FieldSpec("cameraPositions", Reals(multiple=3)),
        FieldSpec("cameraOrientations", Reals(multiple=4)),
        *_CAMERA_FIELDS,
    ),
)

LIGHT_MANAGER = ComponentSpec(
    name="LightManager",
    category=Category.RENDERING,
    module=_SHADER,
    doc="Manages the OpenGL lights of the scene (and shadows).",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("shadows", Bool(), False),
        FieldSpec("softShadows", Bool(), False),
        FieldSpec("ambient", Color(), (0.0, 0.0, 0.0, 0.0)),
        FieldSpec("debugDraw", Bool(), False),
    ),
)

# Light base class.
_LIGHT_FIELDS = (
    FieldSpec("color", Color(), (1.0, 1.0, 1.0, 1.0)),
    FieldSpec("shadowTextureSize", Int(nonnegative=True), 0),
    FieldSpec("drawSource", Bool(), False),
    FieldSpec("zNear", Real()),
    FieldSpec("zFar", Real()),
    FieldSpec("shadowsEnabled", Bool(), True),
    FieldSpec("softShadows", Bool(), False),
    FieldSpec("shadowFactor", Real(), 1.0),
    FieldSpec("VSMLightBleeding", Real(), 0.05),
    FieldSpec("VSMMinVariance", Real(), 0.001),
    FieldSpec("textureUnit", Int(nonnegative=True), 1),
    FieldSpec("modelViewMatrix", Reals(16)),
    FieldSpec("projectionMatrix", Reals(16)),
    *VISUAL_MODEL_FIELDS,
)
_POSITIONAL_FIELDS = (
    FieldSpec("fixed", Bool(), False, "fixed relative to the camera"),
    FieldSpec("position", Reals(3), (-0.7, 0.3, 0.0)),
    FieldSpec("attenuation", Real(), 0.0),
    *_LIGHT_FIELDS,
)

DIRECTIONAL_LIGHT = ComponentSpec(
    name="DirectionalLight",
    category=Category.RENDERING,
    module=_SHADER,
    doc="Directional OpenGL light.",
    supported=True,
    effects=_VISUAL,
    fields=(FieldSpec("direction", Reals(3), (0.0, 0.0, -1.0)), *_LIGHT_FIELDS),
)

POSITIONAL_LIGHT = ComponentSpec(
    name="PositionalLight",
    category=Category.RENDERING,
    module=_SHADER,
    doc="Point OpenGL light.",
    supported=True,  # rendering only: accepted, no part in the step (sofac render lights the scene itself)
    effects=_VISUAL,
    fields=_POSITIONAL_FIELDS,
)

SPOT_LIGHT = ComponentSpec(
    name="SpotLight",
    category=Category.RENDERING,
    module=_SHADER,
    doc="Spot OpenGL light.",
    supported=True,  # rendering only: accepted, no part in the step (sofac render lights the scene itself)
    effects=_VISUAL,
    fields=(
        FieldSpec("direction", Reals(3), (0.0, 0.0, -1.0)),
        FieldSpec("cutoff", Real(), 30.0, "spot angle (degrees)"),
        FieldSpec("exponent", Real(), 1.0),
        FieldSpec("lookat", Bool(), False, "direction is the point the spot aims at"),
        *_POSITIONAL_FIELDS,
    ),
)

OGL_SCENE_FRAME = ComponentSpec(
    name="OglSceneFrame",
    category=Category.RENDERING,
    module=_GL3D,
    doc="Draws the world axes in a corner of the view.",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("draw", Bool(), True),
        FieldSpec("style", Enum(values=("Arrows", "Cylinders", "CubeCones")), "Cylinders"),
        FieldSpec(
            "alignment", Enum(values=("BottomLeft", "BottomRight", "TopRight", "TopLeft")), "BottomRight"
        ),
        FieldSpec("viewportSize", Int(), 150),
        *VISUAL_MODEL_FIELDS,
    ),
)

VISUAL_GRID = ComponentSpec(
    name="VisualGrid",
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="Draws a grid in a coordinate plane.",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("plane", Enum(values=("x", "y", "z")), "z", "plane normal axis"),
        FieldSpec("size", Real(), 10.0),
        FieldSpec("nbSubdiv", Int(), 16),
        FieldSpec("color", Color(), (0.34117647058, 0.34117647058, 0.34117647058, 1.0)),
        FieldSpec("thickness", Real(), 1.0),
        FieldSpec("nbLineSegments", Int(), 1),
        *VISUAL_MODEL_FIELDS,
    ),
)

LINE_AXIS = ComponentSpec(
    name="LineAxis",
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="Draws the world axes as lines.",
    supported=True,  # no part in the step: accepted and ignored by the compiler
    effects=_VISUAL,
    fields=(
        FieldSpec("axis", Text(), "xyz", "axes drawn"),
        FieldSpec("size", Real(), 10.0),
        FieldSpec("infinite", Bool(), False),
        FieldSpec("thickness", Real(), 1.0),
        FieldSpec("vanishing", Bool(), False),
        FieldSpec("nbLineSegments", Int(), 1),
        *VISUAL_MODEL_FIELDS,
    ),
)

OGL_LABEL = ComponentSpec(
    name="OglLabel",
    category=Category.RENDERING,
    module="Sofa.GL.Component.Rendering2D",
    doc="2-D text in the viewport (rendering only: no part in the step).",
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("prefix", Text(), ""),
        FieldSpec("label", Text(), ""),
        FieldSpec("suffix", Text(), ""),
        FieldSpec("x", Int(), 10),
        FieldSpec("y", Int(), 10),
        FieldSpec("fontsize", Int(), 14),
        FieldSpec("color", Color(), (0.5, 0.5, 0.5, 1.0)),
        FieldSpec("selectContrastingColor", Bool(), False),
        FieldSpec("updateLabelEveryNbSteps", Int(), 0),
        *VISUAL_MODEL_FIELDS,
    ),
)

VISUAL_3D_TEXT = ComponentSpec(
    name="Visual3DText",
    category=Category.RENDERING,
    module=_VISUAL_MODULE,
    doc="3-D text facing the camera.",
    supported=True,  # no part in the step: accepted and ignored by the compiler
    effects=_VISUAL,
    fields=(
        FieldSpec("text", Text()),
        FieldSpec("position", Reals(3), (0.0, 0.0, 0.0)),
        FieldSpec("scale", Real(), 1.0),
        FieldSpec("color", Color(), (1.0, 1.0, 1.0, 1.0)),
        FieldSpec("depthTest", Bool(), True),
        *VISUAL_MODEL_FIELDS,
    ),
)

BACKGROUND_SETTING = ComponentSpec(
    name="BackgroundSetting",
    category=Category.RENDERING,
    module="Sofa.Component.Setting",
    doc="Background color or image of the viewer.",
    former_names=("Background",),
    supported=True,
    effects=_VISUAL,
    fields=(
        FieldSpec("color", Color(), doc="background color"),
        FieldSpec("image", Text(), doc="background image file (rendering only: not looked up)"),
    ),
)

DEFAULT_VISUAL_MANAGER_LOOP = ComponentSpec(
    name="DefaultVisualManagerLoop",
    category=Category.RENDERING,
    module="Sofa.Simulation.Core",
    doc="Visual loop (added automatically when missing).",
    supported=True,
    effects=_VISUAL,
    fields=(FieldSpec("targetNode", Link("node"), doc="node drawn (default: its own)"),),
)

COMPONENTS = (
    VISUAL_MODEL_IMPL,
    OGL_MODEL,
    VISUAL_STYLE,
    INTERACTIVE_CAMERA,
    RECORDED_CAMERA,
    LIGHT_MANAGER,
    DIRECTIONAL_LIGHT,
    POSITIONAL_LIGHT,
    SPOT_LIGHT,
    OGL_SCENE_FRAME,
    VISUAL_GRID,
    LINE_AXIS,
    OGL_LABEL,
    VISUAL_3D_TEXT,
    BACKGROUND_SETTING,
    DEFAULT_VISUAL_MANAGER_LOOP,
)
