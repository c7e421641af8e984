"""Offscreen pictures of a running simulation: ``render(sim)``, ``Renderer``, ``sofac render``.

What is drawn, as SOFA's viewer draws it:

* visual models (OglModel, VisualModel): their mesh (their own ``position``/``triangles``/``quads``,
  from ``src=@loader``, or the topology of their context), ``color`` or ``material``, the initial
  ``translation``/``rotation``/``scale3d`` (and the legacy ``dx``..``rz``, ``scale``, ``sx``..``sz``),
  moved by the mapping whose output they are (Identity, Subset, Rigid, Barycentric). Their positions
  and per-vertex normals are computed, in numpy, only when a frame is drawn;
* debug layers, where a VisualStyle's ``displayFlags`` (or the caller's ``show``) ask for them:
  behavior models (the DOFs of independent states; rigid frames as axes), force fields (springs, red
  when stretched and green when compressed; the element edges of FEM and spring force fields),
  interaction force fields, collision models (their points and edges), mappings (mapped DOFs, the
  attachment of rigidly mapped points);
* optionally, a ground grid perpendicular to gravity, under the scene.

The camera: the one given, else the scene's InteractiveCamera, else one fitted to the bounding box of
what is drawn (looking along -Z with Y up, SOFA's default view). ``Renderer.fit(frames)`` fixes it
over a whole animation.

Drawing is headless: OSMesa (Mesa's off-screen software rasterizer) through PyOpenGL, imported with
``PYOPENGL_PLATFORM=osmesa``, and legacy fixed-function OpenGL (vertex arrays, two directional
lights). It needs no display and no GPU; frames are supersampled (2x2 by default) to smooth edges.
``draw_primitives`` issues the same drawing into whatever OpenGL context is current: ``sofac view``'s
window (sofac/viewer.py) draws through it.
"""

from __future__ import annotations

import ctypes.util
import math
import os
import sys
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from sofac.diagnostics import SofacError
from sofac.front.model import Component, Node
from sofac.geometry.fem_topology import CELL_KINDS
from sofac.registry import Category, Variant
from sofac.registry.components.visual import INTERACTIVE_CAMERA

Vec3 = tuple[float, float, float]
RGBA = tuple[float, float, float, float]
#: Positions of a simulation's states at one instant: state path -> (n, coord_size) array.
Frame = dict[str, np.ndarray]

DEFAULT_BACKGROUND: RGBA = (0.16, 0.17, 0.20, 1.0)
MAX_SIZE = 8192  # pixels per side of the final image

_SETUP_HINT = (
    "run scripts/setup.sh (it installs the Debian package libosmesa6-dev and sofac's Python "
    "dependencies, PyOpenGL among them)"
)

# Colors of the debug layers.
_BEHAVIOR: RGBA = (0.98, 0.55, 0.15, 1.0)
_MAPPED: RGBA = (0.40, 0.70, 1.00, 1.0)
_STRETCHED: RGBA = (0.95, 0.25, 0.20, 1.0)
_COMPRESSED: RGBA = (0.25, 0.85, 0.35, 1.0)
_ELEMENTS: RGBA = (0.55, 0.60, 0.95, 1.0)
_COLLISION: RGBA = (0.95, 0.85, 0.25, 1.0)
_ATTACH: RGBA = (0.60, 0.80, 1.00, 1.0)
_GRID: RGBA = (0.55, 0.57, 0.62, 1.0)
_AXES: tuple[RGBA, RGBA, RGBA] = ((0.95, 0.2, 0.2, 1.0), (0.2, 0.9, 0.2, 1.0), (0.3, 0.4, 1.0, 1.0))

# Force fields whose element edges the force-field layer draws (FEM, mesh springs, ...).
_ELEMENT_FORCEFIELD_WORDS = ("FEM", "Spring", "Hyperelastic", "Elastic")


# --- display flags ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Layers:
    """What is drawn in a node's subtree (SOFA's DisplayFlags, as far as sofac draws them)."""

    visual: bool = True
    behavior: bool = False
    force_fields: bool = False
    interaction_force_fields: bool = False
    collision: bool = False
    mappings: bool = False
    wireframe: bool = False


_ALL_LAYERS = ("visual", "behavior", "force_fields", "interaction_force_fields", "collision", "mappings")

# displayFlags words (without their show/hide prefix, lower-case) -> the layers they switch.
_FLAG_WORDS: dict[str, tuple[str, ...]] = {
    "all": _ALL_LAYERS,
    "visual": ("visual",),
    "visualmodels": ("visual",),
    "behavior": ("behavior", "force_fields", "interaction_force_fields"),
    "behaviormodels": ("behavior",),
    "forcefields": ("force_fields",),
    "interactionforcefields": ("interaction_force_fields",),
    "collision": ("collision",),
    "collisionmodels": ("collision",),
    "boundingcollisionmodels": (),
    "mapping": ("mappings",),
    "mappings": ("mappings",),
    "mechanicalmappings": ("mappings",),
    "options": ("wireframe",),
    "wireframe": ("wireframe",),
    "rendering": (),
    "normals": (),
    "advancedrendering": (),
}


def flag_words() -> list[str]:
    """The layer words ``show`` and ``sofac render --show/--hide`` accept."""
    return sorted(_FLAG_WORDS)


def _layers_of(word: str) -> tuple[str, ...] | None:
    return _FLAG_WORDS.get(word.strip().lower().replace("_", "").replace("-", ""))


def _apply_words(layers: Layers, words: Iterable[str]) -> Layers:
    """``layers`` changed by displayFlags words (``showBehaviorModels``, ``hideVisual``, ...)."""
    changes: dict[str, bool] = {}
    for word in words:
        lower = word.strip().lower()
        if lower.startswith("show"):
            on, rest = True, lower[4:]
        elif lower.startswith("hide"):
            on, rest = False, lower[4:]
        else:
            continue
        for name in _layers_of(rest) or ():
            changes[name] = on
    return replace(layers, **changes) if changes else layers


def _apply_show(layers: Layers, show: Mapping[str, bool]) -> Layers:
    changes: dict[str, bool] = {}
    for word, on in show.items():
        for name in _layers_of(word) or ():
            changes[name] = bool(on)
    return replace(layers, **changes) if changes else layers


def check_show(show: Mapping[str, bool] | None) -> dict[str, bool]:
    """``show`` as a dict; ValueError for a word that names no layer."""
    if not show:
        return {}
    unknown = [word for word in show if _layers_of(word) is None]
    if unknown:
        raise ValueError(f"unknown layer {', '.join(map(repr, unknown))}; known: {', '.join(flag_words())}")
    return dict(show)


# --- camera -------------------------------------------------------------------------------------

# Named view directions (where the camera looks) and the up vector that goes with them.
VIEWS: dict[str, tuple[Vec3, Vec3]] = {
    "front": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "back": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "left": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "right": ((-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "top": ((0.0, -1.0, 0.0), (0.0, 0.0, -1.0)),
    "bottom": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "elevated": ((0.0, -0.45, -1.0), (0.0, 1.0, 0.0)),
    "iso": ((-1.0, -0.8, -1.0), (0.0, 1.0, 0.0)),
}


def _unit(vector: Any) -> np.ndarray:
    v = np.asarray(vector, dtype=float)
    norm = float(np.linalg.norm(v))
    if not norm > 0 or not math.isfinite(norm):
        raise ValueError(f"not a direction: {tuple(v)}")
    return v / norm


def _vec3(value: Any) -> Vec3:
    x, y, z = (float(c) for c in np.asarray(value, dtype=float).ravel()[:3])
    return (x, y, z)


@dataclass(frozen=True)
class Camera:
    """A perspective camera. Unset parts are fitted to the scene when a frame is drawn:

    * ``position`` and ``look_at``: used as given;
    * only ``position``: looks at the centre of the scene's bounding box;
    * only ``look_at``: placed along ``direction`` so that the whole scene is in view;
    * neither: both fitted (the default: SOFA's front view, looking along -Z).

    ``fov`` is the vertical field of view in degrees; ``margin`` the room left around the scene
    when fitting (1: the bounding box touches the image's edges).
    """

    position: Vec3 | None = None
    look_at: Vec3 | None = None
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: float = 45.0
    direction: Vec3 = (0.0, 0.0, -1.0)
    margin: float = 1.15

    def __post_init__(self) -> None:
        if not 0.0 < self.fov < 180.0:
            raise ValueError(f"fov must be in (0, 180) degrees, got {self.fov!r}")
        if not self.margin > 0:
            raise ValueError(f"margin must be > 0, got {self.margin!r}")

    @classmethod
    def view(cls, name: str, **kwargs: Any) -> Camera:
        """A camera fitted from a named side: front, back, left, right, top, bottom, elevated, iso."""
        if name not in VIEWS:
            raise ValueError(f"unknown view {name!r}; known: {', '.join(VIEWS)}")
        direction, up = VIEWS[name]
        return cls(direction=direction, up=up, **kwargs)

    @property
    def resolved(self) -> bool:
        return self.position is not None and self.look_at is not None

    def resolve(self, low: Any, high: Any, aspect: float) -> Camera:
        """This camera with its position and look-at point set, for a scene in the box [low, high]."""
        if self.resolved:
            return self
        low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        if self.position is not None:
            return replace(self, look_at=_vec3((low + high) / 2))
        center = np.asarray(self.look_at, dtype=float) if self.look_at is not None else (low + high) / 2
        forward, right, up = _basis(self.direction, self.up)
        corners = np.array(
            [[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])]
        )
        rel = corners - center
        x, y, depth = rel @ right, rel @ up, rel @ forward
        tan_y = math.tan(math.radians(self.fov) / 2) / self.margin
        tan_x = tan_y * aspect
        size = float(np.linalg.norm(high - low))
        if not size > 0:
            size = max(float(np.abs(center).max()), 1.0)
        distance = float(np.max(np.maximum(np.abs(x) / tan_x, np.abs(y) / tan_y) - depth))
        distance = max(distance, float(np.max(-depth)) + 0.05 * size, 0.5 * size / tan_y)
        return replace(self, position=_vec3(center - forward * distance), look_at=_vec3(center), up=_vec3(up))

    def view_matrix(self) -> np.ndarray:
        """The 4x4 world-to-eye matrix (OpenGL's modelview), of a resolved camera."""
        eye, target = self._ends()
        forward, right, up = _basis(target - eye, self.up)
        matrix = np.eye(4)
        matrix[0, :3], matrix[1, :3], matrix[2, :3] = right, up, -forward
        matrix[:3, 3] = -matrix[:3, :3] @ eye
        return matrix

    def projection_matrix(self, aspect: float, near: float = 0.1, far: float = 100.0) -> np.ndarray:
        """The 4x4 perspective projection (gluPerspective's)."""
        f = 1.0 / math.tan(math.radians(self.fov) / 2)
        return np.array(
            [
                [f / aspect, 0.0, 0.0, 0.0],
                [0.0, f, 0.0, 0.0],
                [0.0, 0.0, (far + near) / (near - far), 2 * far * near / (near - far)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )

    def project(self, points: Any, width: int, height: int) -> np.ndarray:
        """Image coordinates ``(x, y)`` of world points, (n, 2): x to the right and y down, in pixels,
        so that the point falls in pixel ``image[int(y), int(x)]``; NaN for points behind the camera."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))[:, :3]
        homogeneous = np.c_[pts, np.ones(len(pts))]
        clip = homogeneous @ (self.projection_matrix(width / height) @ self.view_matrix()).T
        w = clip[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / w[:, None]
        ndc[w <= 0] = np.nan
        return np.c_[(ndc[:, 0] + 1) / 2 * width, (1 - ndc[:, 1]) / 2 * height]

    def _ends(self) -> tuple[np.ndarray, np.ndarray]:
        if self.position is None or self.look_at is None:
            raise ValueError("the camera is not resolved: call resolve() (or render a frame) first")
        return np.asarray(self.position, dtype=float), np.asarray(self.look_at, dtype=float)


def _basis(direction: Any, up: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(forward, right, up) unit vectors of a camera looking along ``direction``."""
    forward = _unit(direction)
    up_hint = _unit(up)
    right = np.cross(forward, up_hint)
    if np.linalg.norm(right) < 1e-9:  # looking along the up vector: take another one
        other = np.array([0.0, 0.0, 1.0]) if abs(forward[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        right = np.cross(forward, other)
    right = _unit(right)
    return forward, right, np.cross(right, forward)


def _quaternion_matrices(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of quaternions (n, 4) stored ``x y z w``, as SOFA stores them."""
    q = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    norms = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(norms > 0, q / np.where(norms > 0, norms, 1.0), [0.0, 0.0, 0.0, 1.0])
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def scene_camera(checked: Any) -> Camera | None:
    """The camera of the scene's (first activated) InteractiveCamera, or None.

    ``position`` and ``lookAt`` as written; else ``orientation`` (the camera looks along its -Z axis,
    its Y axis up) with ``distance`` to place the missing one; ``fieldOfView`` as the vertical angle.
    """
    for item in checked:
        if item.spec is not INTERACTIVE_CAMERA:
            continue
        if checked.value(item.component, "activated") is False:
            continue
        given = item.fields
        fov = float(checked.value(item.component, "fieldOfView") or 45.0)
        position = _vec3(given["position"]) if "position" in given else None
        look_at = _vec3(given["lookAt"]) if "lookAt" in given else None
        up: Vec3 = (0.0, 1.0, 0.0)
        direction: Vec3 = (0.0, 0.0, -1.0)
        if "orientation" in given:
            rotation = _quaternion_matrices(np.asarray(given["orientation"], dtype=float))[0]
            direction, up = _vec3(rotation @ [0.0, 0.0, -1.0]), _vec3(rotation @ [0.0, 1.0, 0.0])
            distance = given.get("distance")
            if distance is not None and float(distance) > 0:
                if position is not None and look_at is None:
                    look_at = _vec3(np.asarray(position) + float(distance) * np.asarray(direction))
                elif look_at is not None and position is None:
                    position = _vec3(np.asarray(look_at) - float(distance) * np.asarray(direction))
        if position is not None and look_at is not None and np.allclose(position, look_at):
            look_at = None
        return Camera(position=position, look_at=look_at, up=up, fov=fov, direction=direction)
    return None


# --- materials ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Material:
    diffuse: RGBA = (0.75, 0.75, 0.75, 1.0)
    ambient: RGBA = (0.2, 0.2, 0.2, 1.0)
    specular: RGBA = (0.25, 0.25, 0.25, 1.0)
    shininess: float = 45.0

    @classmethod
    def of_color(cls, color: Sequence[float]) -> Material:
        """SOFA's Material::setColor: the diffuse color, an ambient of a fifth of it."""
        r, g, b, a = (float(c) for c in [*color, 1.0][:4])
        return cls((r, g, b, a), (0.2 * r, 0.2 * g, 0.2 * b, a), (0.25, 0.25, 0.25, a))

    @property
    def alpha(self) -> float:
        return self.diffuse[3]


def parse_material(text: str) -> Material:
    """A SOFA material string (``Default Diffuse 1 r g b a Ambient 1 r g b a Specular 0 ...
    Shininess 1 45``): the parts whose use flag is 1 replace the default material's."""
    words = text.split()
    parts: dict[str, Any] = {}
    index = 0
    while index < len(words):
        key = words[index].lower()
        try:
            if key in ("diffuse", "ambient", "specular"):
                use, *rgba = (float(w) for w in words[index + 1 : index + 6])
                if len(rgba) == 4 and use:
                    parts[key] = (rgba[0], rgba[1], rgba[2], rgba[3])
                index += 6
                continue
            if key == "shininess":
                use, value = (float(w) for w in words[index + 1 : index + 3])
                if use:
                    parts["shininess"] = value
                index += 3
                continue
        except ValueError:
            pass
        index += 1
    return replace(Material(), **parts)


# --- geometry helpers ---------------------------------------------------------------------------


def vertex_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit normals per vertex: the area-weighted mean of the normals of the triangles around it."""
    pts = np.asarray(points, dtype=float)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    normals = np.zeros_like(pts)
    if len(tris):
        a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
        face = np.cross(b - a, c - a)
        corners = tris.ravel()
        for axis in range(3):
            normals[:, axis] = np.bincount(corners, weights=np.repeat(face[:, axis], 3), minlength=len(pts))
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(lengths > 0, lengths, 1.0)


def _as_points3(positions: np.ndarray) -> np.ndarray:
    """3-D points of a state's coordinates: Vec1/2 padded with zeros, Vec3 as is, the centres of
    rigid frames (Rigid3d's 7 numbers, Rigid2d's x y theta) and the translations of Vec6."""
    x = np.asarray(positions, dtype=float)
    if x.ndim == 1:
        x = x.reshape(-1, 1)
    size = x.shape[1]
    if size >= 3 and size != 3:  # Rigid3d (7), Vec6d (6)
        return x[:, :3]
    if size == 3:
        return x
    return np.c_[x, np.zeros((len(x), 3 - size))]


def _edges_of(cells: Mapping[str, np.ndarray]) -> np.ndarray:
    """The unique edges (k, 2) of a topology's elements."""
    pairs: list[np.ndarray] = []
    local = {
        "edges": ((0, 1),),
        "triangles": ((0, 1), (1, 2), (2, 0)),
        "quads": ((0, 1), (1, 2), (2, 3), (3, 0)),
        "tetrahedra": ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)),
        "hexahedra": (
            (0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7),
        ),
    }  # fmt: skip
    for kind, corners in local.items():
        cell = cells.get(kind)
        if cell is None or not np.size(cell):
            continue
        width = {"edges": 2, "triangles": 3, "quads": 4, "tetrahedra": 4, "hexahedra": 8}[kind]
        cell = np.asarray(cell, dtype=np.int64).reshape(-1, width)
        pairs.extend(cell[:, list(pair)] for pair in corners)
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    edges = np.sort(np.concatenate(pairs), axis=1)
    return np.unique(edges, axis=0)


def _nice_step(length: float) -> float:
    """1, 2 or 5 times a power of ten, close to ``length``."""
    if not length > 0:
        return 1.0
    power = 10.0 ** math.floor(math.log10(length))
    for factor in (1.0, 2.0, 5.0, 10.0):
        if length <= factor * power * 1.5:
            return factor * power
    return 10.0 * power


# --- what is drawn ------------------------------------------------------------------------------


@dataclass
class _Mesh:
    points: np.ndarray
    triangles: np.ndarray  # (m, 3) uint32
    material: Material
    wireframe: bool = False


@dataclass
class _Lines:
    points: np.ndarray  # (2k, 3): segment ends, two by two
    colors: np.ndarray  # (2k, 4)
    width: float = 1.0


@dataclass
class _Points:
    points: np.ndarray
    color: RGBA
    size: float = 1.0


@dataclass
class _Feed:
    """How a visual model's positions follow a state."""

    kind: str  # "identity", "rigid", "linear"
    state: str  # the input state's path
    indices: np.ndarray | None = None  # identity/subset: input index per point; linear: (n, k)
    weights: np.ndarray | None = None  # linear: (n, k)
    local: np.ndarray | None = None  # rigid: points in their frame, (n, 3)
    frame_of: np.ndarray | None = None  # rigid: frame index per point


@dataclass
class _Visual:
    path: str
    node: Node
    rest: np.ndarray  # (n, 3) initial positions (after the model's own transform)
    triangles: np.ndarray  # (m, 3)
    edges: np.ndarray  # (k, 2), drawn when the model has no faces
    material: Material
    feed: _Feed | None


@dataclass
class _StateDots:
    path: str
    node: Node
    layer: str  # "behavior" or "mappings"
    rigid: bool


@dataclass
class _Springs:
    node: Node
    layer: str
    first: str
    second: str
    pairs: np.ndarray  # (k, 2)
    rest: np.ndarray  # (k,)


@dataclass
class _StateEdges:
    node: Node
    layer: str
    path: str
    edges: np.ndarray
    color: RGBA


@dataclass
class _Attachments:
    node: Node
    frames: str
    points: str
    frame_of: np.ndarray


@dataclass
class _Scene:
    visuals: list[_Visual] = field(default_factory=list)
    dots: list[_StateDots] = field(default_factory=list)
    springs: list[_Springs] = field(default_factory=list)
    edges: list[_StateEdges] = field(default_factory=list)
    attachments: list[_Attachments] = field(default_factory=list)
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))


def capture(sim: Any) -> Frame:
    """Copies of the positions of every state of ``sim``, now."""
    return {path: np.array(sim[path].position, dtype=float) for path in sim.objects()}


class Renderer:
    """Draws frames of one simulation. Set up once (visual meshes, mapping weights, layers); each
    ``render()`` computes the visual positions of that frame and draws them.

    ``camera``: a :class:`Camera` (default: the scene's InteractiveCamera, else fitted to each frame,
    or to all frames after ``fit``). ``show``: layer words mapped to on/off, applied over the
    scene's VisualStyle flags everywhere (``{"behaviorModels": True, "visual": False}``; words as in
    SOFA's displayFlags without show/hide, see :func:`flag_words`). ``supersample``: the image is
    drawn that many times larger per side, then averaged down.
    """

    def __init__(
        self,
        sim: Any,
        *,
        width: int = 640,
        height: int = 480,
        camera: Camera | None = None,
        grid: bool = False,
        show: Mapping[str, bool] | None = None,
        background: Sequence[float] = DEFAULT_BACKGROUND,
        supersample: int = 2,
    ) -> None:
        for name, value in (("width", width), ("height", height)):
            if not isinstance(value, (int, np.integer)) or not 1 <= value <= MAX_SIZE:
                raise ValueError(f"{name} must be an integer from 1 to {MAX_SIZE}, got {value!r}")
        if not isinstance(supersample, (int, np.integer)) or not 1 <= supersample <= 4:
            raise ValueError(f"supersample must be 1, 2, 3 or 4, got {supersample!r}")
        checked = getattr(getattr(sim, "compiled", None), "checked", None)
        if checked is None:
            raise SofacError(
                "this simulation carries no checked scene (sim.compiled.checked): load it with sofac.load()"
            )
        self.sim = sim
        self.checked = checked
        self.width, self.height = int(width), int(height)
        self.supersample = int(supersample)
        while self.supersample > 1 and max(self.width, self.height) * self.supersample > MAX_SIZE:
            self.supersample -= 1
        self.grid = grid
        self.background: RGBA = tuple(float(c) for c in [*background, 1.0][:4])  # type: ignore[assignment]
        self.show = check_show(show)
        self.warnings: list[str] = []
        self.camera_spec = camera if camera is not None else scene_camera(checked) or Camera()
        #: The camera of the last frame drawn (resolved: position and look-at set).
        self.camera: Camera | None = None
        self._fixed_bounds: tuple[np.ndarray, np.ndarray] | None = None
        self._axis_length: float | None = None
        self._flags: dict[int, Layers] = {}
        self._states = set(sim.objects())
        self._scene = _SceneBuilder(self).build()
        self._never_blank()

    def _never_blank(self) -> None:
        """A scene whose layers draw nothing (no visual model, no VisualStyle asking for more) gets
        its behavior models drawn, and a warning; when even they draw nothing, an error."""
        if self._primitives(self.capture(), 0.0):
            return
        hidden = any(not on and "behavior" in (_layers_of(word) or ()) for word, on in self.show.items())
        if not hidden:
            self.show = {**self.show, "behaviormodels": True}
            if self._primitives(self.capture(), 0.0):
                self.warnings.append(
                    "nothing in the scene would be drawn (no visual model shown, and no VisualStyle "
                    "asking for debug layers): drawing the behavior models (the DOFs) instead; choose "
                    "the layers with --show (Python: show=...), e.g. --show behavior,collision"
                )
                return
        raise SofacError(
            "nothing to draw: no visual model, DOF, force field or collision model is shown with these "
            "layers; give --show all (Python: show={'all': True}) or add an OglModel to the scene"
        )

    # --- public ----------------------------------------------------------------------------------
    def capture(self) -> Frame:
        """The simulation's state positions now (copies), to render now or later."""
        return capture(self.sim)

    def fit(self, frames: Iterable[Frame]) -> Camera:
        """Fix the camera (and the grid, and the length of rigid frames' axes) to the union of the
        bounding boxes of ``frames``."""
        frames = list(frames)
        if not frames:
            raise ValueError("fit() needs at least one frame")
        self._axis_length = _axis_length(_union(self._bounds(self._primitives(f, 0.0)) for f in frames))
        low, high = _union(self._bounds(self._primitives(f, self._axis_length)) for f in frames)
        self._fixed_bounds = (low, high)
        self.camera = self.camera_spec.resolve(low, high, self.width / self.height)
        return self.camera

    def render(self, frame: Frame | None = None) -> np.ndarray:
        """The picture of ``frame`` (default: the simulation now), (height, width, 3) uint8 RGB."""
        primitives, (low, high) = self.scene_primitives(frame)
        camera = self.camera_spec.resolve(low, high, self.width / self.height)
        self.camera = camera
        return _draw(self, primitives, camera)

    def scene_primitives(self, frame: Frame | None = None) -> tuple[list[Any], tuple[np.ndarray, np.ndarray]]:
        """What ``render`` draws for ``frame`` (default: now), grid included, and the bounding box
        the camera is fitted to; ``draw_primitives`` draws them into any OpenGL context."""
        frame = self.capture() if frame is None else frame
        primitives = self._primitives(frame, self._axis_length)
        low, high = self._fixed_bounds or self._bounds(primitives)
        if self.grid:
            scale = self.height / 480.0
            primitives.append(_grid((low, high), self._scene.up, max(1.0, scale)))
        return primitives, (low, high)

    def visual_positions(self, frame: Frame | None = None) -> dict[str, np.ndarray]:
        """The positions of every visual model in ``frame`` (default: now), by component path."""
        frame = self.capture() if frame is None else frame
        return {visual.path: self._positions(visual, frame) for visual in self._scene.visuals}

    # --- layers ----------------------------------------------------------------------------------
    def layers(self, node: Node) -> Layers:
        """What is drawn for the components of ``node``."""
        key = id(node)
        if key not in self._flags:
            parent = node.parent
            layers = self.layers(parent) if isinstance(parent, Node) else Layers()
            for component in node.objects:
                item = self.checked.components.get(id(component))
                if item is not None and item.spec is not None and item.spec.variant is Variant.VISUAL_STYLE:
                    words = self.checked.value(component, "displayFlags") or ()
                    layers = _apply_words(layers, [words] if isinstance(words, str) else words)
            self._flags[key] = layers
        return _apply_show(self._flags[key], self.show)

    # --- frames ----------------------------------------------------------------------------------
    def _positions(self, visual: _Visual, frame: Frame) -> np.ndarray:
        feed = visual.feed
        if feed is None or feed.state not in frame:
            return visual.rest
        x = frame[feed.state]
        if feed.kind == "identity":
            points = _as_points3(x)
            return points if feed.indices is None else points[feed.indices]
        if feed.kind == "linear":
            assert feed.indices is not None and feed.weights is not None
            return np.einsum("ij,ijk->ik", feed.weights, _as_points3(x)[feed.indices])
        assert feed.local is not None and feed.frame_of is not None
        frames = x[feed.frame_of]
        rotations = _quaternion_matrices(frames[:, 3:7])
        return frames[:, :3] + np.einsum("ijk,ik->ij", rotations, feed.local)

    def _primitives(self, frame: Frame, axis_length: float | None) -> list[_Mesh | _Lines | _Points]:
        """What to draw for ``frame`` (without the grid). Rigid frames get axes ``axis_length`` long
        (None: sized to the rest of the frame; 0: none)."""
        scale = self.height / 480.0
        point_size, line_width = max(3.0, 7.0 * scale), max(1.0, 2.0 * scale)
        out: list[_Mesh | _Lines | _Points] = []
        scene = self._scene
        for visual in scene.visuals:
            layers = self.layers(visual.node)
            if not layers.visual:
                continue
            points = self._positions(visual, frame)
            if len(visual.triangles):
                out.append(_Mesh(points, visual.triangles, visual.material, layers.wireframe))
            elif len(visual.edges):
                out.append(_line_set(points, visual.edges, visual.material.diffuse, line_width))
        for item in scene.edges:
            if getattr(self.layers(item.node), item.layer) and item.path in frame:
                out.append(_line_set(_as_points3(frame[item.path]), item.edges, item.color, 0.5 * line_width))
        for springs in scene.springs:
            if not getattr(self.layers(springs.node), springs.layer):
                continue
            if springs.first not in frame or springs.second not in frame:
                continue
            a = _as_points3(frame[springs.first])[springs.pairs[:, 0]]
            b = _as_points3(frame[springs.second])[springs.pairs[:, 1]]
            stretched = np.linalg.norm(b - a, axis=1) > springs.rest
            colors = np.where(stretched[:, None], _STRETCHED, _COMPRESSED)
            out.append(
                _Lines(np.stack([a, b], axis=1).reshape(-1, 3), np.repeat(colors, 2, axis=0), line_width)
            )
        for link in scene.attachments:
            if not self.layers(link.node).mappings or link.frames not in frame or link.points not in frame:
                continue
            a = _as_points3(frame[link.frames])[link.frame_of]
            b = _as_points3(frame[link.points])
            out.append(
                _Lines(np.stack([a, b], axis=1).reshape(-1, 3), np.tile(_ATTACH, (2 * len(a), 1)), line_width)
            )
        rigid_centres: list[np.ndarray] = []
        for dots in scene.dots:
            if not getattr(self.layers(dots.node), dots.layer) or dots.path not in frame:
                continue
            x = frame[dots.path]
            color = {"behavior": _BEHAVIOR, "mappings": _MAPPED}.get(dots.layer, _COLLISION)
            out.append(_Points(_as_points3(x), color, point_size))
            if dots.rigid and x.shape[1] == 7:
                rigid_centres.append(x)
        if rigid_centres and axis_length != 0.0:
            if axis_length is None:
                axis_length = _axis_length(self._bounds(out))
            for x in rigid_centres:
                out.append(_axes(x, axis_length, line_width))
        return out

    @staticmethod
    def _bounds(primitives: Sequence[_Mesh | _Lines | _Points]) -> tuple[np.ndarray, np.ndarray]:
        clouds = [p.points for p in primitives if len(p.points)]
        if not clouds:
            return np.full(3, -1.0), np.full(3, 1.0)
        points = np.concatenate(clouds)
        points = points[np.isfinite(points).all(axis=1)]
        if not len(points):
            return np.full(3, -1.0), np.full(3, 1.0)
        return points.min(axis=0), points.max(axis=0)


def render(
    sim: Any,
    width: int = 640,
    height: int = 480,
    camera: Camera | None = None,
    *,
    grid: bool = False,
    show: Mapping[str, bool] | None = None,
    background: Sequence[float] = DEFAULT_BACKGROUND,
    supersample: int = 2,
) -> np.ndarray:
    """A picture of ``sim`` now: (height, width, 3) uint8 RGB. See :class:`Renderer` for the options;
    what it could not draw as asked is issued as UserWarning."""
    renderer = Renderer(
        sim,
        width=width,
        height=height,
        camera=camera,
        grid=grid,
        show=show,
        background=background,
        supersample=supersample,
    )
    for text in renderer.warnings:
        warnings.warn(text, stacklevel=2)
    return renderer.render()


def _union(boxes: Iterable[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    lows, highs = zip(*boxes, strict=True)
    return np.min(lows, axis=0), np.max(highs, axis=0)


def _axis_length(bounds: tuple[np.ndarray, np.ndarray]) -> float:
    """The length of the axes drawn for rigid frames: an eighth of the scene's diagonal."""
    return 0.12 * (float(np.linalg.norm(bounds[1] - bounds[0])) or 1.0)


def _line_set(points: np.ndarray, edges: np.ndarray, color: RGBA, width: float) -> _Lines:
    segments = points[edges.reshape(-1)]
    return _Lines(segments, np.tile(color, (len(segments), 1)), width)


def _axes(frames: np.ndarray, length: float, width: float) -> _Lines:
    """The three axes of rigid frames (n, 7), red/green/blue."""
    centres = frames[:, :3]
    rotations = _quaternion_matrices(frames[:, 3:7])
    ends, colors = [], []
    for axis in range(3):
        tips = centres + length * rotations[:, :, axis]
        ends.append(np.stack([centres, tips], axis=1).reshape(-1, 3))
        colors.append(np.tile(_AXES[axis], (2 * len(centres), 1)))
    return _Lines(np.concatenate(ends), np.concatenate(colors), width)


def _grid(bounds: tuple[np.ndarray, np.ndarray], up: np.ndarray, width: float) -> _Lines:
    """A square grid perpendicular to ``up`` just under the box ``bounds``, about twice its size."""
    low, high = bounds
    center = (low + high) / 2
    size = max(float(np.max(high - low)), 1e-3)
    step = _nice_step(size / 6)
    count = max(2, math.ceil(size / step))
    _, u, v = _basis(-up, np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0]))
    corners = np.array(
        [[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])]
    )
    floor = float(np.min(corners @ up)) - 0.02 * size
    origin = center - (center @ up - floor) * up
    origin = origin - (origin @ u % step) * u - (origin @ v % step) * v  # lines through round coordinates
    ticks = np.arange(-count, count + 1) * step
    reach = count * step
    ends = []
    for t in ticks:
        ends.append([origin + t * u - reach * v, origin + t * u + reach * v])
        ends.append([origin + t * v - reach * u, origin + t * v + reach * u])
    points = np.asarray(ends, dtype=float).reshape(-1, 3)
    return _Lines(points, np.tile(_GRID, (len(points), 1)), width)


# --- scene set-up -------------------------------------------------------------------------------


class _SceneBuilder:
    """Reads the checked scene once: visual meshes and their mappings, debug layers, gravity."""

    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        self.checked = renderer.checked
        self.states = renderer._states
        self.warnings = renderer.warnings

    def value(self, component: Component, name: str) -> Any:
        try:
            return self.checked.value(component, name)
        except Exception:  # a value sofac cannot compute: drawn without it
            return None

    def build(self) -> _Scene:
        scene = _Scene(up=self._up())
        for item in self.checked:
            category = item.category
            if category is Category.VISUAL:
                visual = self._visual(item)
                if visual is not None:
                    scene.visuals.append(visual)
            elif category is Category.STATE:
                path = item.component.path
                if path in self.states:
                    mapped = self.checked.mapping_of(item.component) is not None
                    datatype = item.datatype
                    rigid = bool(datatype is not None and datatype.rigid)
                    node = item.component.node
                    scene.dots.append(_StateDots(path, node, "mappings" if mapped else "behavior", rigid))
            elif category in (Category.FORCEFIELD, Category.INTERACTION_FORCEFIELD):
                self._forcefield(item, scene)
            elif category is Category.COLLISION_MODEL:
                self._collision(item, scene)
            elif (
                category is Category.MAPPING
                and item.spec is not None
                and item.spec.lowering == "rigid_mapping"
            ):
                self._attachment(item, scene)
        return scene

    def _up(self) -> np.ndarray:
        text = self.checked.scene.root.get("gravity")
        try:
            gravity = np.array([float(v) for v in (text or "0 -9.81 0").split()][:3])
            return _unit(-gravity) if len(gravity) == 3 else np.array([0.0, 1.0, 0.0])
        except ValueError:
            return np.array([0.0, 1.0, 0.0])

    # --- topology ---------------------------------------------------------------------------------
    def topology_of(self, component: Component, link: Any = None) -> Component | None:
        """The topology a component uses: ``link``, else the last one of the nearest node holding one."""
        if isinstance(link, Component):
            return link
        node = component.node
        for candidate in (node, *node.ancestors()):
            found = [
                c
                for c in candidate.objects
                if (item := self.checked.components.get(id(c))) is not None
                and item.category is Category.TOPOLOGY
            ]
            if found:
                return found[-1]
        return None

    def cells(self, topology: Component | None) -> dict[str, np.ndarray]:
        """The elements of a topology, with those a topological mapping writes into it (the checker
        evaluates Hexa2Tetra, Tetra2Triangle, Hexa2Quad)."""
        cells: dict[str, np.ndarray] = {}
        if topology is None:
            return cells
        for kind in (*CELL_KINDS, "resolution", "bounds"):
            value = self.value(topology, kind)
            if value is not None and np.size(value):
                cells[kind] = np.asarray(value, dtype=float if kind == "bounds" else np.int64).ravel()
        return cells

    # --- visual models ----------------------------------------------------------------------------
    def _visual(self, item: Any) -> _Visual | None:
        component = item.component
        path = component.path
        if self.value(component, "enable") is False:
            return None
        points = self._array(component, "position", 3, float)
        triangles = self._array(component, "triangles", 3, np.int64)
        quads = self._array(component, "quads", 4, np.int64)
        edges = self._array(component, "edges", 2, np.int64)
        if not (len(triangles) or len(quads) or len(edges)):  # the topology of its context
            topology = self.topology_of(component, item.links.get("topology"))
            cells = self.cells(topology)
            triangles = cells.get("triangles", np.zeros(0, np.int64)).reshape(-1, 3)
            quads = cells.get("quads", np.zeros(0, np.int64)).reshape(-1, 4)
            if not len(points) and topology is not None:
                points = _reshape(self.value(topology, "position"), 3, float)
        faces = np.concatenate([triangles, quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int64)
        if len(points):
            points = self._transform(item, points)
        mapping = self.checked.mapping_of(component)
        feed = self._feed(mapping, points, path) if mapping is not None else None
        if feed is not None and not len(points):
            points = self._input_points(feed)
        count = len(points) if feed is None else self._feed_size(feed, len(points))
        if not count:
            self.warnings.append(f"{path}: no vertices known, not drawn")
            return None
        if not (len(faces) or len(edges)):
            self.warnings.append(f"{path}: no triangles, quads or edges known, not drawn")
            return None
        if len(points) != count:  # the mapping resized the model (SOFA resizes the output)
            points = (
                points[:count] if len(points) > count else np.r_[points, np.zeros((count - len(points), 3))]
            )
        keep = (faces < count).all(axis=1) & (faces >= 0).all(axis=1)
        if not keep.all():
            self.warnings.append(f"{path}: {int((~keep).sum())} faces use missing vertices, not drawn")
            faces = faces[keep]
        edges = edges[(edges < count).all(axis=1) & (edges >= 0).all(axis=1)]
        return _Visual(
            path, component.node, points, faces.astype(np.uint32), edges, self._material(component), feed
        )

    def _array(self, component: Component, name: str, width: int, dtype: Any) -> np.ndarray:
        return _reshape(self.value(component, name), width, dtype)

    def _transform(self, item: Any, points: np.ndarray) -> np.ndarray:
        """VisualModelImpl's initial transform: scale, then rotate (Euler angles, degrees), then translate."""
        from sofac.front.meshes import apply_transform

        given = item.fields

        def triple(name: str, legacy: tuple[str, str, str], default: float) -> np.ndarray:
            value = np.asarray(given.get(name, (default,) * 3), dtype=float).ravel()
            value = np.resize(value, 3) if value.size else np.full(3, default)
            for axis, key in enumerate(legacy):
                if key in given:
                    value[axis] = float(given[key])
            return value

        scale = triple("scale3d", ("sx", "sy", "sz"), 1.0)
        if "scale" in given:
            legacy = np.asarray(given["scale"], dtype=float).ravel()
            scale = np.resize(legacy, 3) if legacy.size else scale
            for axis, key in enumerate(("sx", "sy", "sz")):
                if key in given:
                    scale[axis] = float(given[key])
        rotation = triple("rotation", ("rx", "ry", "rz"), 0.0)
        translation = triple("translation", ("dx", "dy", "dz"), 0.0)
        if (scale == 1).all() and not rotation.any() and not translation.any():
            return points
        return np.asarray(apply_transform(points, translation, rotation, scale), dtype=float)

    def _material(self, component: Component) -> Material:
        color = self.value(component, "color")
        if color is not None:
            return Material.of_color(color)
        text = self.value(component, "material")
        return parse_material(text) if isinstance(text, str) and text.strip() else Material()

    # --- mappings ---------------------------------------------------------------------------------
    def _feed(self, mapping: Any, points: np.ndarray, path: str) -> _Feed | None:
        name = mapping.spec.name if mapping.spec is not None else mapping.component.type_name
        kernel = mapping.spec.lowering if mapping.spec is not None else ""
        source = mapping.links.get("input")
        if not isinstance(source, Component):
            self.warnings.append(f"{path}: its {name} has no input state; drawn at rest")
            return None
        state = source.path
        if state not in self.states:
            self.warnings.append(f"{path}: the input {state} of its {name} is not simulated; drawn at rest")
            return None
        template = self.checked.of(source).datatype
        rigid = bool(template is not None and template.rigid and template.coord_size == 7)
        try:
            if kernel in ("identity_mapping", "subset_mapping"):
                indices = None
                if kernel == "subset_mapping":
                    written = self.value(mapping.component, "indices")
                    if written is not None and np.size(written):
                        indices = np.asarray(written, dtype=np.int64).ravel()
                return _Feed("identity", state, indices=indices)
            if kernel == "rigid_mapping" and rigid:
                return self._rigid_feed(mapping, source, points, state)
            if kernel == "barycentric_mapping":
                return self._barycentric_feed(mapping, source, points, state)
        except (ValueError, IndexError) as error:
            self.warnings.append(f"{path}: its {name} cannot be set up ({error}); drawn at rest")
            return None
        self.warnings.append(f"{path}: {name} to a visual model is not drawn yet; drawn at rest")
        return None

    def _rigid_feed(self, mapping: Any, source: Component, points: np.ndarray, state: str) -> _Feed | None:
        component = mapping.component
        written = self.value(component, "initialPoints")
        local = _reshape(written, 3, float) if written is not None and np.size(written) else points
        frames = self.checked.positions(source)
        if frames is None or not len(frames):
            raise ValueError("its input frames are unknown")
        per_point = self.value(component, "rigidIndexPerPoint")
        if per_point is not None and np.size(per_point) == len(local):
            frame_of = np.asarray(per_point, dtype=np.int64).ravel()
        else:
            index = int(self.value(component, "index") or 0)
            if self.value(component, "indexFromEnd"):
                index = len(frames) - 1 - index
            frame_of = np.full(len(local), index, dtype=np.int64)
        if len(frame_of) and (frame_of.min() < 0 or frame_of.max() >= len(frames)):
            raise ValueError("its frame indices are out of range")
        if self.value(component, "globalToLocalCoords"):
            rotations = _quaternion_matrices(frames[frame_of, 3:7])
            local = np.einsum("ikj,ik->ij", rotations, local - frames[frame_of, :3])
        return _Feed("rigid", state, local=np.asarray(local, dtype=float), frame_of=frame_of)

    def _barycentric_feed(self, mapping: Any, source: Component, points: np.ndarray, state: str) -> _Feed:
        from sofac.geometry.barycentric import RegularGrid, embed_cells, mapper_for

        rest = self.checked.positions(source)
        if rest is None or rest.shape[1] != 3:
            raise ValueError("its input is not a Vec3 state with known positions")
        if not len(points):
            raise ValueError("the visual model has no vertices to embed")
        topology = self.topology_of(source, mapping.links.get("input_topology"))
        cells = self.cells(topology)
        spec = self.checked.of(topology).spec if topology is not None else None
        mode = mapper_for(spec.variant if spec is not None else None)
        grid = None
        if mode == "regular_grid" and "resolution" in cells and cells.get("bounds", np.zeros(0)).size >= 6:
            bounds = cells["bounds"]
            grid = RegularGrid(
                tuple(int(c) for c in cells["resolution"][:3]), tuple(bounds[:3]), tuple(bounds[3:6])
            )
        embedding = embed_cells(rest, points, cells, mode=mode, grid=grid)
        return _Feed("linear", state, indices=embedding.indices, weights=embedding.weights)

    def _input_points(self, feed: _Feed) -> np.ndarray:
        """A visual model without vertices of its own: its input state's initial points (identity)."""
        if feed.kind != "identity":
            return np.zeros((0, 3))
        source = next((c.component for c in self.checked.states() if c.component.path == feed.state), None)
        positions = self.checked.positions(source) if source is not None else None
        if positions is None:
            return np.zeros((0, 3))
        points = _as_points3(positions)
        return points if feed.indices is None else points[feed.indices]

    def _feed_size(self, feed: _Feed, own: int) -> int:
        if feed.kind == "identity":
            if feed.indices is not None:
                return len(feed.indices)
            state = self.renderer.sim[feed.state]
            return len(state.position)
        if feed.kind == "rigid":
            assert feed.local is not None
            return len(feed.local)
        assert feed.indices is not None
        return len(feed.indices) if len(feed.indices) else own

    def _attachment(self, item: Any, scene: _Scene) -> None:
        """RigidMapping between states: lines from each frame to its mapped points (mapping layer)."""
        source, target = item.links.get("input"), item.links.get("output")
        if not (isinstance(source, Component) and isinstance(target, Component)):
            return
        if source.path not in self.states or target.path not in self.states:
            return
        size = len(self.renderer.sim[target.path].position)
        frames = len(self.renderer.sim[source.path].position)
        per_point = self.value(item.component, "rigidIndexPerPoint")
        if per_point is not None and np.size(per_point) == size:
            frame_of = np.asarray(per_point, dtype=np.int64).ravel()
        else:
            index = int(self.value(item.component, "index") or 0)
            if self.value(item.component, "indexFromEnd"):
                index = frames - 1 - index
            frame_of = np.full(size, index, dtype=np.int64)
        if size and (frame_of.min() < 0 or frame_of.max() >= frames):
            return
        scene.attachments.append(_Attachments(item.component.node, source.path, target.path, frame_of))

    # --- force fields, collision models -----------------------------------------------------------
    def _forcefield(self, item: Any, scene: _Scene) -> None:
        component = item.component
        first, second = item.links.get("object1"), item.links.get("object2")
        if not isinstance(first, Component):
            first = item.state
        if not isinstance(second, Component):
            second = first
        if not isinstance(first, Component) or first.path not in self.states:
            return
        layer = "force_fields" if first is second else "interaction_force_fields"
        springs = None
        if item.spec is not None and item.spec.field("spring") is not None:
            springs = self.value(component, "spring")
        if springs is not None and np.size(springs):
            if second.path not in self.states:
                return
            table = np.asarray(springs, dtype=float).reshape(-1, 5)
            pairs = table[:, :2].astype(np.int64)
            sizes = (
                len(self.renderer.sim[first.path].position),
                len(self.renderer.sim[second.path].position),
            )
            keep = (pairs[:, 0] < sizes[0]) & (pairs[:, 1] < sizes[1])
            scene.springs.append(
                _Springs(component.node, layer, first.path, second.path, pairs[keep], table[keep, 4])
            )
            return
        name = item.spec.name if item.spec is not None else ""
        if first is second and any(word in name for word in _ELEMENT_FORCEFIELD_WORDS):
            self._topology_edges(item, first, layer, _ELEMENTS, scene)

    def _collision(self, item: Any, scene: _Scene) -> None:
        state = item.state
        if not isinstance(state, Component) or state.path not in self.states:
            return
        scene.dots.append(_StateDots(state.path, item.component.node, "collision", False))
        name = item.spec.name if item.spec is not None else ""
        if "Triangle" in name or "Line" in name:
            self._topology_edges(item, state, "collision", _COLLISION, scene)

    def _topology_edges(self, item: Any, state: Component, layer: str, color: RGBA, scene: _Scene) -> None:
        cells = self.cells(self.topology_of(item.component, item.links.get("topology")))
        edges = _edges_of(cells)
        size = len(self.renderer.sim[state.path].position)
        edges = edges[(edges < size).all(axis=1)] if len(edges) else edges
        if len(edges):
            scene.edges.append(_StateEdges(item.component.node, layer, state.path, edges, color))


def _reshape(value: Any, width: int, dtype: Any) -> np.ndarray:
    if value is None or not np.size(value):
        return np.zeros((0, width), dtype=dtype)
    array = np.asarray(value, dtype=dtype).ravel()
    if array.size % width:
        return np.zeros((0, width), dtype=dtype)
    return array.reshape(-1, width)


# --- OpenGL through OSMesa ----------------------------------------------------------------------

_gl: Any = None  # (GL module, osmesa module, context) once loaded


def _find_osmesa() -> str | None:
    """The OSMesa library the system has, or None."""
    return ctypes.util.find_library("OSMesa")


def _load_gl() -> Any:
    """PyOpenGL on OSMesa, loaded once per process; SofacError with a hint when it cannot be."""
    global _gl
    if _gl is not None:
        return _gl
    platform = os.environ.get("PYOPENGL_PLATFORM", "")
    if platform and platform != "osmesa":
        raise SofacError(
            f"PYOPENGL_PLATFORM={platform}: sofac renders off-screen with OSMesa only; unset it or set it "
            "to osmesa"
        )
    loaded = sys.modules.get("OpenGL.platform")
    if loaded is not None and "OSMesa" not in type(getattr(loaded, "PLATFORM", None)).__name__:
        raise SofacError(
            "PyOpenGL was already imported in this process for another platform; sofac needs it on "
            "OSMesa: import sofac.render (or set PYOPENGL_PLATFORM=osmesa) before anything imports OpenGL"
        )
    if _find_osmesa() is None:
        raise SofacError(f"OSMesa (libOSMesa, off-screen OpenGL) is not installed: {_SETUP_HINT}")
    os.environ["PYOPENGL_PLATFORM"] = "osmesa"  # must be set before OpenGL is imported
    try:
        from OpenGL import GL, arrays, osmesa
    except ImportError as error:
        raise SofacError(f"PyOpenGL cannot be imported ({error}): {_SETUP_HINT}") from None
    except Exception as error:  # the library was found but could not be loaded
        raise SofacError(
            f"OSMesa could not be loaded ({type(error).__name__}: {error}): {_SETUP_HINT}"
        ) from None
    context = osmesa.OSMesaCreateContextExt(osmesa.OSMESA_RGBA, 24, 0, 0, None)
    if not context:
        raise SofacError(f"OSMesa could not create a rendering context: {_SETUP_HINT}")
    _gl = (GL, arrays, osmesa, context)
    return _gl


def _draw(renderer: Renderer, primitives: Sequence[_Mesh | _Lines | _Points], camera: Camera) -> np.ndarray:
    GL, arrays, osmesa, context = _load_gl()
    ss = renderer.supersample
    width, height = renderer.width * ss, renderer.height * ss
    buffer = arrays.GLubyteArray.zeros((height, width, 4))
    if not osmesa.OSMesaMakeCurrent(context, buffer, GL.GL_UNSIGNED_BYTE, width, height):
        raise SofacError(f"OSMesa could not draw a {width}x{height} image")
    draw_primitives(GL, primitives, camera, width, height, renderer.background, ss)
    GL.glFinish()

    image = np.flipud(np.asarray(buffer)[:, :, :3])
    if ss > 1:
        blocks = image.reshape(renderer.height, ss, renderer.width, ss, 3).astype(np.float32)
        image = np.rint(blocks.mean(axis=(1, 3)))
    return np.ascontiguousarray(image, dtype=np.uint8)


def draw_primitives(
    GL: Any,
    primitives: Sequence[_Mesh | _Lines | _Points],
    camera: Camera,
    width: int,
    height: int,
    background: Sequence[float],
    line_scale: float = 1.0,
) -> None:
    """Draw ``primitives`` seen by a resolved ``camera`` into the current OpenGL context's
    framebuffer, ``width`` x ``height`` pixels (OSMesa's here, a window's in ``sofac view``).
    ``line_scale`` widens lines and points (the supersampling factor)."""
    ss = line_scale
    aspect = width / height
    near, far = _clip_planes(camera, primitives)

    GL.glViewport(0, 0, width, height)
    GL.glClearColor(*background)
    GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
    GL.glEnable(GL.GL_DEPTH_TEST)
    GL.glDepthFunc(GL.GL_LEQUAL)
    GL.glMatrixMode(GL.GL_PROJECTION)
    GL.glLoadMatrixd(np.ascontiguousarray(camera.projection_matrix(aspect, near, far).T))
    GL.glMatrixMode(GL.GL_MODELVIEW)
    GL.glLoadIdentity()
    _lights(GL)  # in eye coordinates: they follow the camera
    GL.glLoadMatrixd(np.ascontiguousarray(camera.view_matrix().T))

    meshes = [p for p in primitives if isinstance(p, _Mesh)]
    for mesh in (m for m in meshes if m.material.alpha >= 1.0):
        _draw_mesh(GL, mesh, ss)
    GL.glEnable(GL.GL_BLEND)
    GL.glBlendFunc(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA)
    for primitive in primitives:
        if isinstance(primitive, _Lines):
            _draw_lines(GL, primitive, ss)
    for primitive in primitives:
        if isinstance(primitive, _Points):
            _draw_points(GL, primitive, ss)
    GL.glDepthMask(GL.GL_FALSE)
    for mesh in (m for m in meshes if m.material.alpha < 1.0):
        _draw_mesh(GL, mesh, ss)
    GL.glDepthMask(GL.GL_TRUE)
    GL.glDisable(GL.GL_BLEND)


def _clip_planes(camera: Camera, primitives: Sequence[_Mesh | _Lines | _Points]) -> tuple[float, float]:
    eye, target = camera._ends()
    forward = _unit(target - eye)
    clouds = [p.points for p in primitives if len(p.points)]
    if not clouds:
        return 0.1, 100.0
    points = np.concatenate(clouds)
    depth = (points[np.isfinite(points).all(axis=1)] - eye) @ forward
    if not len(depth):
        return 0.1, 100.0
    far = max(float(depth.max()) * 1.05, 1e-6)
    near = max(float(depth.min()) * 0.95, far * 1e-4)
    return near, max(far, near * 1.01)


def _lights(GL: Any) -> None:
    GL.glEnable(GL.GL_LIGHT0)
    GL.glLightfv(GL.GL_LIGHT0, GL.GL_POSITION, (0.35, 0.55, 1.0, 0.0))
    GL.glLightfv(GL.GL_LIGHT0, GL.GL_DIFFUSE, (0.85, 0.85, 0.85, 1.0))
    GL.glLightfv(GL.GL_LIGHT0, GL.GL_SPECULAR, (0.6, 0.6, 0.6, 1.0))
    GL.glLightfv(GL.GL_LIGHT0, GL.GL_AMBIENT, (0.0, 0.0, 0.0, 1.0))
    GL.glEnable(GL.GL_LIGHT1)
    GL.glLightfv(GL.GL_LIGHT1, GL.GL_POSITION, (-0.6, -0.3, 0.4, 0.0))
    GL.glLightfv(GL.GL_LIGHT1, GL.GL_DIFFUSE, (0.3, 0.3, 0.32, 1.0))
    GL.glLightfv(GL.GL_LIGHT1, GL.GL_SPECULAR, (0.0, 0.0, 0.0, 1.0))
    GL.glLightModelfv(GL.GL_LIGHT_MODEL_AMBIENT, (0.3, 0.3, 0.3, 1.0))
    GL.glLightModeli(GL.GL_LIGHT_MODEL_TWO_SIDE, GL.GL_TRUE)
    GL.glShadeModel(GL.GL_SMOOTH)
    GL.glEnable(GL.GL_NORMALIZE)


def _draw_mesh(GL: Any, mesh: _Mesh, ss: float) -> None:
    points = np.ascontiguousarray(mesh.points, dtype=np.float32)
    normals = np.ascontiguousarray(vertex_normals(mesh.points, mesh.triangles), dtype=np.float32)
    triangles = np.ascontiguousarray(mesh.triangles, dtype=np.uint32)
    material = mesh.material
    GL.glEnable(GL.GL_LIGHTING)
    GL.glMaterialfv(GL.GL_FRONT_AND_BACK, GL.GL_DIFFUSE, material.diffuse)
    GL.glMaterialfv(GL.GL_FRONT_AND_BACK, GL.GL_AMBIENT, material.ambient)
    GL.glMaterialfv(GL.GL_FRONT_AND_BACK, GL.GL_SPECULAR, material.specular)
    GL.glMaterialf(GL.GL_FRONT_AND_BACK, GL.GL_SHININESS, min(max(material.shininess, 0.0), 128.0))
    if mesh.wireframe:
        GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_LINE)
        GL.glLineWidth(float(ss))
    else:
        GL.glEnable(GL.GL_POLYGON_OFFSET_FILL)  # lines drawn on the surface stay visible
        GL.glPolygonOffset(1.0, 1.0)
    GL.glEnableClientState(GL.GL_VERTEX_ARRAY)
    GL.glEnableClientState(GL.GL_NORMAL_ARRAY)
    GL.glVertexPointer(3, GL.GL_FLOAT, 0, points)
    GL.glNormalPointer(GL.GL_FLOAT, 0, normals)
    GL.glDrawElements(GL.GL_TRIANGLES, triangles.size, GL.GL_UNSIGNED_INT, triangles)
    GL.glDisableClientState(GL.GL_NORMAL_ARRAY)
    GL.glDisableClientState(GL.GL_VERTEX_ARRAY)
    GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
    GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)
    GL.glDisable(GL.GL_LIGHTING)


def _draw_lines(GL: Any, lines: _Lines, ss: float) -> None:
    if not len(lines.points):
        return
    points = np.ascontiguousarray(lines.points, dtype=np.float32)
    colors = np.ascontiguousarray(lines.colors, dtype=np.float32)
    GL.glLineWidth(max(1.0, lines.width * ss))
    GL.glEnableClientState(GL.GL_VERTEX_ARRAY)
    GL.glEnableClientState(GL.GL_COLOR_ARRAY)
    GL.glVertexPointer(3, GL.GL_FLOAT, 0, points)
    GL.glColorPointer(4, GL.GL_FLOAT, 0, colors)
    GL.glDrawArrays(GL.GL_LINES, 0, len(points))
    GL.glDisableClientState(GL.GL_COLOR_ARRAY)
    GL.glDisableClientState(GL.GL_VERTEX_ARRAY)


def _draw_points(GL: Any, dots: _Points, ss: float) -> None:
    if not len(dots.points):
        return
    points = np.ascontiguousarray(dots.points, dtype=np.float32)
    GL.glEnable(GL.GL_POINT_SMOOTH)
    GL.glPointSize(max(1.0, dots.size * ss))
    GL.glColor4f(*dots.color)
    GL.glEnableClientState(GL.GL_VERTEX_ARRAY)
    GL.glVertexPointer(3, GL.GL_FLOAT, 0, points)
    GL.glDrawArrays(GL.GL_POINTS, 0, len(points))
    GL.glDisableClientState(GL.GL_VERTEX_ARRAY)
    GL.glDisable(GL.GL_POINT_SMOOTH)


__all__ = [
    "DEFAULT_BACKGROUND",
    "VIEWS",
    "Camera",
    "Frame",
    "Layers",
    "Material",
    "Renderer",
    "capture",
    "check_show",
    "draw_primitives",
    "flag_words",
    "parse_material",
    "render",
    "scene_camera",
    "vertex_normals",
]
