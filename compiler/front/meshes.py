"""Readers for the mesh and data files SOFA scenes load, and SOFA's point transformation.

Formats (chosen by file extension, case-insensitive):

============  =============================================================  ===================
extension     format                                                         reader
============  =============================================================  ===================
``.obj``      Wavefront OBJ (``v``, ``vn``, ``vt``, ``f``, ``l``)            own, vectorised
``.msh``      Gmsh format 1 (``$NOD``/``$ELM``) and format 2 ASCII           own
``.msh``      Gmsh format 2 binary, format 4 (ASCII or binary)               meshio (lazy import)
``.vtu/.vtp`` VTK XML UnstructuredGrid or PolyData, ASCII data arrays       own, hardened lxml
``.vtk``      legacy VTK ASCII or binary (UNSTRUCTURED_GRID, POLYDATA), < 5   own
``.vtk``      legacy VTK version 5.x                                         meshio (lazy import)
``.sph``      SOFA sphere list (``sphe id x y z r``)                         own
``.stl``      STL, ASCII (``solid``) or binary                               own (MeshSTLLoader)
``.rigid``    Xsp 3.0 rigid-body file (mass, volume, inertia, center)        own (read_rigid)
============  =============================================================  ===================

meshio costs about 100 ms to import, so it is only imported for the formats that need it; the
formats SOFA's own example files use are read without it.

Every reader follows what SOFA's loader for that format produces (MeshOBJLoader,
MeshGmshLoader, MeshVTKLoader, SphereLoader, UniformMass's rigid file reader); where SOFA
silently accepts a broken file (unknown node numbers, out-of-range indices, missing values) these
readers raise :class:`MeshError` with the line at fault instead. Deviations are listed in the
docstrings of the individual readers.

Results are cached on ``(path, mtime, size)``; the arrays of a cached :class:`Mesh` are read-only,
copy them before modifying. :func:`count_points` reads only what it needs to count the vertices,
for checks that do not need the whole mesh.

What the readers do *not* do (the loader components do it, with their own fields): the
loaders' ``translation``/``rotation``/``scale3d``/``transformation`` (use :func:`apply_transform`
or :func:`apply_matrix`), ``flipNormals``, ``triangulate``, and ``createSubelements`` (which
MeshGmshLoader switches on by default, deriving triangles/edges from the volume elements).

Transformation convention (checked against SOFA's ``Quat::createQuaterFromEuler``,
``MeshLoader::applyTransformation`` and ``MechanicalObject::reinit``): scale, then rotate, then
translate; Euler angles in degrees, rotating about the world X axis first, then world Y, then
world Z (``R = Rz @ Ry @ Rx``). See :func:`apply_transform`.
"""

from __future__ import annotations

import functools
import io
import math
import os
import re
import warnings
from collections.abc import Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "Mesh",
    "MeshError",
    "RigidFile",
    "Spheres",
    "apply_matrix",
    "apply_transform",
    "count_points",
    "euler_to_matrix",
    "euler_to_quaternion",
    "quaternion_multiply",
    "read_mesh",
    "read_rigid",
    "read_spheres",
    "rotate_by_quaternion",
    "transform_matrix",
]

#: Extensions :func:`read_mesh` and :func:`count_points` understand.
SUPPORTED_EXTENSIONS: tuple[str, ...] = (".obj", ".msh", ".vtu", ".vtp", ".vtk", ".sph", ".stl")

#: Files larger than this are refused (a guard against reading a wrong path into memory).
MAX_FILE_BYTES = 1 << 30


# --------------------------------------------------------------------------------------------
# Public types
# --------------------------------------------------------------------------------------------


class MeshError(Exception):
    """A mesh or data file could not be read.

    ``message`` says what is wrong, ``line`` (1-based, or ``None``) where, ``path`` which file.
    ``str(error)`` is ``"<path>:<line>: <message>"`` with the parts that are known.
    """

    def __init__(self, message: str, line: int | None = None, path: Path | str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.path = Path(path) if path is not None else None

    def __str__(self) -> str:
        where = ""
        if self.path is not None:
            where = f"{self.path}:"
            if self.line is not None:
                where += f"{self.line}:"
            where += " "
        elif self.line is not None:
            where = f"line {self.line}: "
        return where + self.message


def _empty_cells(n: int) -> np.ndarray:
    return np.zeros((0, n), dtype=np.int64)


def _frozen(array: np.ndarray) -> np.ndarray:
    """``array`` made read-only; copied first unless already read-only (callers keep theirs)."""
    if array.flags.writeable:
        array = array.copy()
        array.setflags(write=False)
    return array


def _as_cells(value: Any, n: int, name: str) -> np.ndarray:
    array = np.ascontiguousarray(value, dtype=np.int64)
    if array.size == 0:
        array = _empty_cells(n)
    if array.ndim != 2 or array.shape[1] != n:
        raise ValueError(f"{name} must have shape (k, {n}), got {array.shape}")
    return _frozen(array)


def _as_points(value: Any, width: int, name: str) -> np.ndarray:
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.size == 0:
        array = np.zeros((0, width), dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got {array.shape}")
    return _frozen(array)


@dataclass(frozen=True, eq=False)
class Mesh:
    """Points and elements of a mesh file, indices 0-based into ``positions``.

    Element arrays are ``int64`` of shape ``(k, n)``, ``(0, n)`` when the file has none.
    ``normals`` (N, 3) and ``texcoords`` (N, 2) are per vertex, or ``None`` when the file has none.
    ``notes`` lists what the reader skipped (unsupported element types and the like).
    ``source_index`` (OBJ read with ``handle_seams=True`` only) gives, per point, the 0-based
    ``v`` line it was made from (SOFA's ``vertPosIdx``).
    Arrays are read-only (results are cached and shared).
    """

    positions: np.ndarray
    edges: np.ndarray = field(default_factory=lambda: _empty_cells(2))
    triangles: np.ndarray = field(default_factory=lambda: _empty_cells(3))
    quads: np.ndarray = field(default_factory=lambda: _empty_cells(4))
    tetrahedra: np.ndarray = field(default_factory=lambda: _empty_cells(4))
    hexahedra: np.ndarray = field(default_factory=lambda: _empty_cells(8))
    normals: np.ndarray | None = None
    texcoords: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    source_index: np.ndarray | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "positions", _as_points(self.positions, 3, "positions"))
        for name, n in (("edges", 2), ("triangles", 3), ("quads", 4), ("tetrahedra", 4), ("hexahedra", 8)):
            set_(self, name, _as_cells(getattr(self, name), n, name))
        if self.normals is not None:
            set_(self, "normals", _as_points(self.normals, 3, "normals"))
        if self.texcoords is not None:
            set_(self, "texcoords", _as_points(self.texcoords, 2, "texcoords"))
        if self.source_index is not None:
            set_(self, "source_index", _frozen(np.ascontiguousarray(self.source_index, dtype=np.int64)))
        set_(self, "notes", tuple(self.notes))

    @property
    def n_points(self) -> int:
        return int(self.positions.shape[0])

    def max_index(self) -> int:
        """Largest vertex index used by any element, -1 when there are no elements."""
        best = -1
        for cells in (self.edges, self.triangles, self.quads, self.tetrahedra, self.hexahedra):
            if cells.size:
                best = max(best, int(cells.max()))
        return best


@dataclass(frozen=True, eq=False)
class Spheres:
    """A SOFA ``.sph`` sphere list: ``centers`` (N, 3) and ``radii`` (N,), in file order."""

    centers: np.ndarray
    radii: np.ndarray
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "centers", _as_points(self.centers, 3, "centers"))
        radii = np.ascontiguousarray(self.radii, dtype=np.float64).reshape(-1)
        if radii.shape[0] != self.centers.shape[0]:
            raise ValueError("radii and centers differ in length")
        object.__setattr__(self, "radii", _frozen(radii))
        object.__setattr__(self, "notes", tuple(self.notes))


@dataclass(frozen=True, eq=False)
class RigidFile:
    """An Xsp 3.0 ``.rigid`` file as read for ``UniformMass filename=...`` (Rigid3 templates).

    ``present`` holds the keywords the file set (``"mass"``, ``"volume"``, ``"inertia"``,
    ``"center"``); the other fields then hold SOFA's ``RigidMass`` defaults (mass 1, volume 1,
    identity inertia, center 0). In SOFA a value missing from the file keeps the value the
    UniformMass had before.
    """

    mass: float
    volume: float
    inertia: np.ndarray
    center: np.ndarray
    present: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        inertia = np.ascontiguousarray(self.inertia, dtype=np.float64).reshape(3, 3)
        center = np.ascontiguousarray(self.center, dtype=np.float64).reshape(3)
        object.__setattr__(self, "inertia", _frozen(inertia))
        object.__setattr__(self, "center", _frozen(center))
        object.__setattr__(self, "mass", float(self.mass))
        object.__setattr__(self, "volume", float(self.volume))


# --------------------------------------------------------------------------------------------
# Entry points and caching
# --------------------------------------------------------------------------------------------


def _stat_key(path: Path | str) -> tuple[str, int, int]:
    p = Path(path)
    try:
        st = p.stat()
    except OSError as error:
        raise MeshError(f"cannot read file: {error.strerror or error}", path=p) from None
    if not p.is_file():
        raise MeshError("not a regular file", path=p)
    if st.st_size > MAX_FILE_BYTES:
        raise MeshError(f"file is too large ({st.st_size} bytes, limit {MAX_FILE_BYTES})", path=p)
    return os.fspath(p.resolve()), st.st_mtime_ns, st.st_size


def _read_bytes(path: str) -> bytes:
    try:
        with open(path, "rb") as handle:
            return handle.read()
    except OSError as error:
        raise MeshError(f"cannot read file: {error.strerror or error}", path=path) from None


def _read_text(path: str) -> str:
    """The file as text with ``\\n`` line ends (latin-1: every byte maps to one character)."""
    text = _read_bytes(path).decode("latin-1")
    if "\r" in text:
        # CR is a line end only in files without LF (classic Mac); elsewhere it is a blank, so
        # "\r\r\n" (seen in the corpus) stays one line and line numbers match other tools.
        text = text.replace("\r", "\n") if "\n" not in text else text.replace("\r", " ")
    return text


def _extension(path: Path | str) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in SUPPORTED_EXTENSIONS:
        supported = ", ".join(SUPPORTED_EXTENSIONS)
        shown = suffix or "(none)"
        raise MeshError(f"unsupported mesh file extension {shown!r}; supported: {supported}", path=path)
    return suffix


def read_mesh(path: Path | str, *, handle_seams: bool = False) -> Mesh:
    """Read a mesh file; the format is chosen by extension (see :data:`SUPPORTED_EXTENSIONS`).

    ``handle_seams`` is MeshOBJLoader's ``handleSeams`` (OBJ only; ignored for other formats):
    one point per distinct (position, texcoord, normal) used by the faces.
    A ``.sph`` file gives a mesh of its sphere centers (no elements).
    Raises :class:`MeshError` for missing, unreadable, unsupported or malformed files.
    """
    suffix = _extension(path)
    return _read_mesh_cached(*_stat_key(path), handle_seams and suffix == ".obj")


def count_points(path: Path | str, *, handle_seams: bool = False) -> int:
    """Number of vertices :func:`read_mesh` would return, read cheaply (headers or line counts).

    For a well-formed file this equals ``len(read_mesh(path).positions)``; it does not check the
    rest of the file. With ``handle_seams`` (OBJ) the faces decide the count, so the file is
    read in full (and cached).
    """
    suffix = _extension(path)
    if handle_seams and suffix == ".obj":
        return read_mesh(path, handle_seams=True).n_points
    return _count_points_cached(*_stat_key(path))


def read_spheres(path: Path | str) -> Spheres:
    """Read a SOFA ``.sph`` sphere file (see :func:`_parse_sph` for the format)."""
    key = _stat_key(path)
    return _read_spheres_cached(*key)


def read_rigid(path: Path | str) -> RigidFile:
    """Read an Xsp 3.0 ``.rigid`` file (see :func:`_parse_rigid` for the format)."""
    key = _stat_key(path)
    return _read_rigid_cached(*key)


@functools.lru_cache(maxsize=128)
def _read_mesh_cached(path: str, mtime_ns: int, size: int, handle_seams: bool = False) -> Mesh:
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".obj":
            return _parse_obj(_read_text(path), handle_seams)
        if suffix == ".msh":
            return _read_gmsh(path)
        if suffix in (".vtu", ".vtp", ".vtk"):  # which reader: the first lines say, as in SOFA
            return _parse_vtu(_read_bytes(path)) if _is_vtk_xml(path) else _read_vtk(path)
        if suffix == ".stl":
            return _parse_stl(_read_bytes(path))
        spheres = _parse_sph(_read_text(path))
        return Mesh(positions=spheres.centers, notes=spheres.notes)
    except MeshError as error:
        if error.path is None:
            error.path = Path(path)
        raise


@functools.lru_cache(maxsize=256)
def _count_points_cached(path: str, mtime_ns: int, size: int) -> int:
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".obj":
            return len(_OBJ_VERTEX_RE.findall(_read_text(path)))
        if suffix == ".msh":
            return _count_gmsh(path)
        if suffix in (".vtu", ".vtp", ".vtk"):  # which reader: the first lines say, as in SOFA
            return _count_vtu(_read_text(path)) if _is_vtk_xml(path) else _count_vtk(path)
        if suffix == ".stl":
            return _parse_stl(_read_bytes(path)).n_points
        text = _read_text(path)
        return len(_SPH_LINE_RE.findall(text, text.find("\n") + 1 if "\n" in text else len(text)))
    except MeshError as error:
        if error.path is None:
            error.path = Path(path)
        raise


@functools.lru_cache(maxsize=64)
def _read_spheres_cached(path: str, mtime_ns: int, size: int) -> Spheres:
    try:
        return _parse_sph(_read_text(path))
    except MeshError as error:
        error.path = Path(path)
        raise


@functools.lru_cache(maxsize=64)
def _read_rigid_cached(path: str, mtime_ns: int, size: int) -> RigidFile:
    try:
        return _parse_rigid(_read_text(path))
    except MeshError as error:
        error.path = Path(path)
        raise


def clear_cache() -> None:
    """Forget all cached reads (tests; files rewritten within the mtime resolution)."""
    for cached in (_read_mesh_cached, _count_points_cached, _read_spheres_cached, _read_rigid_cached):
        cached.cache_clear()


# --------------------------------------------------------------------------------------------
# Small parsing helpers
# --------------------------------------------------------------------------------------------


def _numbers(text: str, dtype: type = np.float64) -> np.ndarray | None:
    """All whitespace-separated numbers of ``text``; ``None`` if anything else is in it."""
    if not text or text.isspace():
        return np.zeros(0, dtype=dtype)
    try:
        with warnings.catch_warnings():
            # numpy < 2.? warns (DeprecationWarning) instead of raising on trailing garbage.
            warnings.simplefilter("error", DeprecationWarning)
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        return None


def _line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def _to_float(token: str, line: int, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise MeshError(f"{what}: expected a number, found {token!r}", line) from None
    if not math.isfinite(value):
        raise MeshError(f"{what}: non-finite number {token!r}", line)
    return value


def _to_int(token: str, line: int, what: str) -> int:
    try:
        return int(token)
    except ValueError:
        raise MeshError(f"{what}: expected an integer, found {token!r}", line) from None


def _reject_binary(text: str) -> None:
    """Refuse text holding NUL bytes, except NUL padding at the very end (seen in the corpus)."""
    nul = text.find("\x00")
    if nul >= 0 and text[nul:].strip("\x00 \t\n"):
        raise MeshError("file contains binary data (NUL byte) where text was expected", _line_of(text, nul))


# --------------------------------------------------------------------------------------------
# Wavefront OBJ
# --------------------------------------------------------------------------------------------

_OBJ_VERTEX_RE = re.compile(r"^[ \t]*v[ \t]", re.M)
_OBJ_BLANKS_RE = re.compile(r"[ \t]+")
_EPS = float(np.finfo(np.float64).eps)
_MISSING = 0  # raw index meaning "no texcoord/normal given" (0 is not a valid OBJ index)


def _parse_obj(text: str, handle_seams: bool = False) -> Mesh:
    """Wavefront OBJ, as SOFA's MeshOBJLoader reads it.

    - ``v x y z [...]`` positions (extra values such as ``w`` or vertex colours are ignored);
      ``vn`` normals; ``vt u v [w]`` texture coordinates. A line with fewer numbers takes the
      missing ones from the previous v/vn/vt line, as SOFA's stream does (:func:`_obj_stream_vectors`).
    - ``f`` and ``l`` corners ``v``, ``v/t``, ``v//n``, ``v/t/n``; indices are 1-based, negative
      ones count back from the last element of that kind defined so far.
    - A 2-corner ``f`` or ``l`` is an edge stored as (min, max); a 3-corner ``f`` a triangle; a
      4-corner ``f`` a quad; larger ``f`` polygons are split as a fan (0, j-1, j).
      Deviation: an ``l`` with more than 2 corners is a polyline (consecutive edges, each stored
      as (min, max)); SOFA triangulates it like a face.
    - ``handle_seams=False`` (SOFA's default): points are the ``v`` lines; each point's normal is
      the normalised sum of the ``vn`` its corners reference; its texcoord is, among the ``vt``
      its corners reference, the first with the largest ``v - u`` (SOFA's rule), else (0, 0).
    - ``handle_seams=True``: one point per distinct (v, vt, vn) used by the faces, ordered by v,
      then vt, then vn (absent = first); unreferenced ``v`` are dropped. ``source_index`` gives
      the ``v`` (0-based) each point comes from (SOFA's ``vertPosIdx``).
    - ``mtllib``, ``usemtl``, ``g``, ``o``, ``s``, comments and unknown keywords are ignored.
    - A ``vt``/``vn`` index outside the defined ones is ignored with a note (as in SOFA).
    Errors (with line): non-numeric values, index 0, a vertex index outside the
    defined vertices (SOFA would build invalid topology).
    """
    _reject_binary(text)
    if "\t" in text:
        text = text.replace("\t", " ")
    lines = text.split("\n")
    if text.startswith(" ") or "\n " in text:
        lines = [line.lstrip(" ") for line in lines]
    v_bodies: list[str] = []
    vn_bodies: list[str] = []
    vt_bodies: list[str] = []
    f_bodies: list[str] = []  # 'f' and 'l' lines, in file order
    n_polylines = 0
    for line in lines:
        head = line[:2]
        if head == "v ":
            v_bodies.append(line[2:])
        elif head == "f ":
            f_bodies.append(line[2:])
        elif head == "vt":
            if line[2:3] == " ":
                vt_bodies.append(line[3:])
        elif head == "vn":
            if line[2:3] == " ":
                vn_bodies.append(line[3:])
        elif head == "l ":
            f_bodies.append(line[2:])
            n_polylines += 1

    def kinds() -> list[tuple[str, int]]:
        # (kind, line number) of every v/vt/vn/f/l line; used on rare paths only.
        out = []
        for number, line in enumerate(lines, start=1):
            head = line[:3]
            if head[:2] in ("v ", "f ", "l "):
                out.append((head[0], number))
            elif head in ("vt ", "vn "):
                out.append((head[:2], number))
        return out

    def line_of(kind: str, k: int) -> int:
        """Line number of the k-th line of the given kind ('face' = f or l)."""
        wanted = ("f", "l") if kind == "face" else (kind,)
        return [number for name, number in kinds() if name in wanted][k]

    try:
        positions = _obj_vectors(v_bodies, 3, 3, "vertex", lambda k: line_of("v", k))
        normals_list = _obj_vectors(vn_bodies, 3, 3, "normal", lambda k: line_of("vn", k))
        texcoords_list = _obj_vectors(vt_bodies, 2, 2, "texture coordinate", lambda k: line_of("vt", k))
    except _ShortObjLine:
        positions, normals_list, texcoords_list = _obj_stream_vectors(lines)
    n_v = positions.shape[0]
    notes: list[str] = [] if n_v else ["no vertices"]
    if not f_bodies:
        # Without faces every point keeps zero normal/texcoord; with seams no point is used.
        if handle_seams:
            positions = np.zeros((0, 3))
        n_out = positions.shape[0]
        return Mesh(
            positions=positions,
            normals=np.zeros((n_out, 3)) if vn_bodies else None,
            texcoords=np.zeros((n_out, 2)) if vt_bodies else None,
            notes=tuple(notes),
            source_index=np.zeros(0, np.int64) if handle_seams else None,
        )

    arity, raw_v, raw_t, raw_n = _obj_corners(f_bodies, lambda k: line_of("face", k))
    face_of_corner = np.repeat(np.arange(len(f_bodies)), arity)
    all_kinds: np.ndarray | None = None

    def resolve(raw: np.ndarray, kind: str) -> np.ndarray:
        # 1-based -> 0-based; negative: relative to the count of that kind defined so far.
        nonlocal all_kinds
        idx = np.where(raw == _MISSING, -1, raw - 1)
        negative = raw < 0
        if negative.any():
            if all_kinds is None:
                all_kinds = _obj_counts_before_faces(lines)
            defined = all_kinds[:, ("v", "vt", "vn").index(kind)]
            idx = np.where(negative, raw + defined[face_of_corner], idx)
            idx[negative & (idx < 0)] = -2  # before the first one: invalid
        return idx

    v_idx = resolve(raw_v, "v")
    bad = (v_idx < 0) | (v_idx >= n_v)
    if bad.any():
        corner = int(np.nonzero(bad)[0][0])
        raise MeshError(
            f"face refers to vertex {int(raw_v[corner])}, but the file defines {n_v} vertices"
            + (" before this line" if raw_v[corner] < 0 else ""),
            line_of("face", int(face_of_corner[corner])),
        )
    t_idx = resolve(raw_t, "vt")
    n_idx = resolve(raw_n, "vn")
    for idx, raw, total, what in (
        (t_idx, raw_t, texcoords_list.shape[0], "texture coordinate"),
        (n_idx, raw_n, normals_list.shape[0], "normal"),
    ):
        invalid = (raw != _MISSING) & ((idx < 0) | (idx >= total))
        if invalid.any():
            corner = int(np.nonzero(invalid)[0][0])
            line = line_of("face", int(face_of_corner[corner]))
            notes.append(
                f"{int(invalid.sum())} face corner(s) refer to a {what} that is not defined "
                f"(first at line {line}); ignored"
            )
    if n_polylines:
        is_line = np.array([name == "l" for name, _ in kinds() if name in ("f", "l")])
    else:
        is_line = np.zeros(len(f_bodies), dtype=bool)
    mesh_kw: dict[str, Any] = {}
    if handle_seams:
        keys = np.stack([v_idx, t_idx, n_idx], axis=1)
        unique, corner_point = np.unique(keys, axis=0, return_inverse=True)
        corner_point = corner_point.reshape(-1)
        mesh_kw.update(_obj_elements(arity, corner_point, is_line))
        positions = positions[unique[:, 0]]
        mesh_kw["source_index"] = unique[:, 0]
        if normals_list.shape[0]:
            normals = np.zeros((unique.shape[0], 3))
            ok = (unique[:, 2] >= 0) & (unique[:, 2] < normals_list.shape[0])
            normals[ok] = normals_list[unique[ok, 2]]
            length = np.linalg.norm(normals, axis=1)
            big = length > _EPS  # SOFA's Vec::normalize leaves tiny vectors unchanged
            normals[big] /= length[big, None]
            mesh_kw["normals"] = normals
        if texcoords_list.shape[0]:
            texcoords = np.zeros((unique.shape[0], 2))
            ok = (unique[:, 1] >= 0) & (unique[:, 1] < texcoords_list.shape[0])
            texcoords[ok] = texcoords_list[unique[ok, 1]]
            mesh_kw["texcoords"] = texcoords
    else:
        mesh_kw.update(_obj_elements(arity, v_idx, is_line))
        if normals_list.shape[0]:
            mesh_kw["normals"] = _obj_vertex_normals(n_v, v_idx, n_idx, normals_list)
        if texcoords_list.shape[0]:
            mesh_kw["texcoords"] = _obj_vertex_texcoords(n_v, v_idx, t_idx, texcoords_list)
    return Mesh(positions=positions, notes=tuple(notes), **mesh_kw)


def _token_counts(joined: str, n: int) -> tuple[np.ndarray, str]:
    """Token counts of the ``n`` newline-separated lines of ``joined``, and all tokens joined by
    single spaces."""
    if "\t" in joined:
        joined = joined.replace("\t", " ")
    if "  " in joined:
        joined = _OBJ_BLANKS_RE.sub(" ", joined)
    normalized = joined.replace(" \n", "\n").replace("\n ", "\n").strip(" ")
    raw = np.frombuffer(normalized.encode("latin-1"), dtype=np.uint8)
    ends = np.concatenate([np.flatnonzero(raw == 10), [raw.size]])  # end of each line
    spaces = np.bincount(np.searchsorted(ends, np.flatnonzero(raw == 32)), minlength=n)
    length = np.diff(ends, prepend=-1) - 1
    return np.where(length > 0, spaces + 1, 0).astype(np.int64), normalized.replace("\n", " ")


def _obj_counts_before_faces(lines: list[str]) -> np.ndarray:
    """For each f/l line, how many v, vt and vn lines come before it (for negative indices)."""
    n_v = n_t = n_n = 0
    out: list[tuple[int, int, int]] = []
    for line in lines:
        head = line[:2]
        if head == "v ":
            n_v += 1
        elif head in ("f ", "l "):
            out.append((n_v, n_t, n_n))
        elif head == "vt" and line[2:3] == " ":
            n_t += 1
        elif head == "vn" and line[2:3] == " ":
            n_n += 1
    return np.array(out, dtype=np.int64).reshape(-1, 3)


class _ShortObjLine(MeshError):
    """A v, vn or vt line with fewer numbers than its kind has (read by :func:`_obj_stream_vectors`)."""


def _obj_stream_vectors(lines: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, normals and texture coordinates as SOFA's MeshOBJLoader reads a file whose v, vn
    or vt lines are short (share/mesh/raptorTemperature.obj stores one number a vertex): every such
    line is ``values >> result[0] >> result[1] >> result[2]`` (two for vt) into one Vec3 declared
    before the loop, and an extraction past the end of the line leaves its number as it was. So a
    missing number is the one the previous v/vn/vt line left there (0 before the first)."""
    result = [0.0, 0.0, 0.0]
    read: dict[str, list[list[float]]] = {"v": [], "vn": [], "vt": []}
    names = {"v": "vertex", "vn": "normal", "vt": "texture coordinate"}
    for number, line in enumerate(lines, start=1):
        kind, space, body = line.partition(" ")
        if kind not in read or not space:  # a bare "v" is no vertex here either (_parse_obj)
            continue
        width = 2 if kind == "vt" else 3
        for j, token in enumerate(body.split("#", 1)[0].split()[:width]):
            try:
                result[j] = float(token)
            except ValueError:
                raise MeshError(f"{names[kind]}: expected a number, found {token!r}", number) from None
        read[kind].append(result[:width])
    positions, normals, texcoords = (
        np.array(read[k], dtype=np.float64).reshape(-1, w) for k, w in (("v", 3), ("vn", 3), ("vt", 2))
    )
    for kind, values in (("v", positions), ("vn", normals), ("vt", texcoords)):
        if not np.isfinite(values).all():
            row = int(np.nonzero(~np.isfinite(values).all(axis=1))[0][0])
            number = [n for n, line in enumerate(lines, start=1) if line.partition(" ")[0] == kind][row]
            raise MeshError(f"{names[kind]}: non-finite number", number)
    return positions, normals, texcoords


def _obj_vectors(bodies: list[str], width: int, minimum: int, what: str, line_of: Any) -> np.ndarray:
    if not bodies:
        return np.zeros((0, width))
    values: np.ndarray | None = None
    joined = "\n".join(bodies)
    if "#" not in joined:
        counts, flat_text = _token_counts(joined, len(bodies))
        flat = _numbers(flat_text)
        if flat is not None and flat.size == int(counts.sum()) and counts.min() >= minimum:
            start = np.cumsum(counts) - counts
            values = np.zeros((len(bodies), width))
            for j in range(width):
                has = counts > j
                values[has, j] = flat[start[has] + j]
    if values is None:
        values = np.zeros((len(bodies), width))
        for k, body in enumerate(bodies):
            tokens = body.split("#", 1)[0].split()
            if len(tokens) < minimum:
                raise _ShortObjLine(f"{what}: expected {minimum} numbers, found {len(tokens)}", line_of(k))
            for j, token in enumerate(tokens[:width]):
                try:
                    values[k, j] = float(token)
                except ValueError:
                    raise MeshError(f"{what}: expected a number, found {token!r}", line_of(k)) from None
    if not np.isfinite(values).all():
        row = int(np.nonzero(~np.isfinite(values).all(axis=1))[0][0])
        raise MeshError(f"{what}: non-finite number", line_of(row))
    return values


def _obj_corners(bodies: list[str], line_of: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-face corner counts and per-corner raw (1-based or negative) v, vt, vn indices.

    A missing vt or vn is :data:`_MISSING`. The common case is parsed with array operations on
    the whole text; anything unusual (comments, malformed corners, index 0) goes through the
    line-by-line parser, which reports the line at fault.
    """
    joined = "\n".join(bodies)
    if "#" not in joined:
        arity, flat = _token_counts(joined, len(bodies))
        fast = _obj_corner_fields(flat, int(arity.sum()))
        if fast is not None:
            return (arity, *fast)
    token_lists = [body.split("#", 1)[0].split() for body in bodies]
    arity = np.fromiter(map(len, token_lists), dtype=np.int64, count=len(token_lists))
    return (arity, *_obj_corners_slow(token_lists, line_of))


def _obj_corner_fields(flat: str, n_tok: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Fast path of :func:`_obj_corners` on space-separated tokens; ``None`` if unusual."""
    if n_tok == 0:
        return None
    if "/" not in flat:
        v = _numbers(flat, np.int64)
        if v is None or v.size != n_tok or not v.all():
            return None
        zeros = np.zeros(n_tok, np.int64)
        return v, zeros, zeros.copy()
    doubled = flat.count("//")
    normalized = flat.replace("//", "/0/")
    raw = np.frombuffer(normalized.encode("latin-1"), dtype=np.uint8)
    token_id = np.searchsorted(np.flatnonzero(raw == 32), np.flatnonzero(raw == 47))
    slashes = np.bincount(token_id, minlength=n_tok)
    if slashes.size != n_tok or slashes.max() > 2:
        return None
    values = _numbers(normalized.replace("/", " "), np.int64)
    fields = slashes + 1
    if values is None or values.size != int(fields.sum()):
        return None
    start = np.cumsum(fields) - fields
    v = values[start]
    t = np.where(fields >= 2, values[np.minimum(start + 1, values.size - 1)], 0)
    n = np.where(fields >= 3, values[np.minimum(start + 2, values.size - 1)], 0)
    # Index 0 is invalid; the only zeros allowed are the vt fields "//" was rewritten to.
    if not v.all() or not n[fields == 3].all() or int((t[fields >= 2] == 0).sum()) != doubled:
        return None
    return v, t, n


def _obj_corners_slow(
    token_lists: list[list[str]], line_of: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v: list[int] = []
    t: list[int] = []
    n: list[int] = []
    for k, tokens in enumerate(token_lists):
        for token in tokens:
            parts = token.split("/")
            if len(parts) > 3 or parts[0] == "":
                raise MeshError(f"malformed face corner {token!r}", line_of(k))
            values = []
            for part, what in zip(parts, ("vertex", "texture coordinate", "normal"), strict=False):
                if part == "":
                    values.append(_MISSING)
                    continue
                try:
                    value = int(part)
                except ValueError:
                    raise MeshError(
                        f"face {what} index: expected an integer, found {part!r}", line_of(k)
                    ) from None
                if value == 0:
                    raise MeshError(
                        f"invalid {what} index 0 in face corner {token!r} (OBJ counts from 1)", line_of(k)
                    )
                values.append(value)
            values += [_MISSING] * (3 - len(values))
            v.append(values[0])
            t.append(values[1])
            n.append(values[2])
    return np.array(v, np.int64), np.array(t, np.int64), np.array(n, np.int64)


def _obj_elements(arity: np.ndarray, v: np.ndarray, is_line: np.ndarray) -> dict[str, np.ndarray]:
    start = np.cumsum(arity) - arity
    out: dict[str, np.ndarray] = {}
    # Edges: 2-corner faces, and every 'l' with >= 2 corners as a polyline; stored as (min, max).
    edge_faces = np.nonzero((is_line & (arity >= 2)) | (~is_line & (arity == 2)))[0]
    if edge_faces.size:
        counts = arity[edge_faces] - 1
        first = np.repeat(start[edge_faces], counts)
        local = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        a, b = v[first + local], v[first + local + 1]
        out["edges"] = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    quad_faces = np.nonzero(~is_line & (arity == 4))[0]
    if quad_faces.size:
        out["quads"] = v[start[quad_faces, None] + np.arange(4)]
    tri_faces = np.nonzero(~is_line & ((arity == 3) | (arity >= 5)))[0]
    if tri_faces.size:
        counts = arity[tri_faces] - 2
        first = np.repeat(start[tri_faces], counts)
        j = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + 2
        out["triangles"] = np.stack([v[first], v[first + j - 1], v[first + j]], axis=1)
    return out


def _obj_vertex_normals(n_points: int, v: np.ndarray, n: np.ndarray, normals: np.ndarray) -> np.ndarray:
    out = np.zeros((n_points, 3))
    use = (n >= 0) & (n < normals.shape[0])
    np.add.at(out, v[use], normals[n[use]])
    length = np.linalg.norm(out, axis=1)
    big = length > _EPS  # SOFA's Vec::normalize leaves tiny vectors unchanged
    out[big] /= length[big, None]
    return out


def _obj_vertex_texcoords(n_points: int, v: np.ndarray, t: np.ndarray, texcoords: np.ndarray) -> np.ndarray:
    """SOFA's per-vertex texcoord choice (``handleSeams=false``).

    Going through the face corners in file order, a vertex's texcoord starts at (0, 0) and is
    replaced by a corner's texcoord when the current one is (0, 0) or the corner's ``v - u`` is
    larger. Without (0, 0) candidates that is "the first candidate with the largest v - u",
    computed with a sort; otherwise the corners are replayed one by one.
    """
    out = np.zeros((n_points, 2))
    use = np.nonzero((t >= 0) & (t < texcoords.shape[0]))[0]
    if use.size == 0:
        return out
    cv, cand = v[use], texcoords[t[use]]
    key = cand[:, 1] - cand[:, 0]
    if (cand == 0).all(axis=1).any():
        current: dict[int, tuple[float, float]] = {}
        for vertex, u, w in zip(cv.tolist(), cand[:, 0].tolist(), cand[:, 1].tolist(), strict=True):
            cu, cw = current.get(vertex, (0.0, 0.0))
            if (cu == 0.0 and cw == 0.0) or (w - u) > (cw - cu):
                current[vertex] = (u, w)
        if current:
            out[np.fromiter(current.keys(), np.int64)] = np.array(list(current.values()))
        return out
    order = np.lexsort((np.arange(use.size), -key, cv))
    first = np.ones(order.size, dtype=bool)
    first[1:] = cv[order][1:] != cv[order][:-1]
    best = order[first]
    out[cv[best]] = cand[best]
    return out


# --------------------------------------------------------------------------------------------
# Gmsh
# --------------------------------------------------------------------------------------------

# Gmsh element type -> (field of Mesh or None for "recognised, nothing stored", node count).
_GMSH_TYPES: dict[int, tuple[str | None, int]] = {
    1: ("edges", 2),
    2: ("triangles", 3),
    3: ("quads", 4),
    4: ("tetrahedra", 4),
    5: ("hexahedra", 8),
    15: (None, 1),
}
# Node counts of other gmsh element types (format 2 lines list no count, so they are needed to
# skip those elements; format 1 lines carry the count).
_GMSH_OTHER_NODES: dict[int, int] = {
    6: 6,
    7: 5,
    8: 3,
    9: 6,
    10: 9,
    11: 10,
    12: 27,
    13: 18,
    14: 14,
    16: 8,
    17: 20,
    18: 15,
    19: 13,
    20: 9,
    21: 10,
    22: 12,
    23: 15,
    24: 15,
    25: 21,
    26: 4,
    27: 5,
    28: 6,
    29: 20,
    30: 35,
    31: 56,
    92: 64,
    93: 125,
}
_GMSH_NAMES = {
    6: "prism",
    7: "pyramid",
    8: "2nd-order line",
    9: "2nd-order triangle",
    10: "2nd-order quad",
    11: "2nd-order tetrahedron",
    12: "2nd-order hexahedron",
}


def _gmsh_header(path: str) -> tuple[int, float, int]:
    """(format major version, full version, file type 0=ASCII 1=binary) from the file start."""
    with open(path, "rb") as handle:
        head = handle.read(256).decode("latin-1")
    lines = head.replace("\r", "").split("\n")
    first = lines[0].strip()
    if first.startswith("$NOD"):
        return 1, 1.0, 0
    if first.startswith("$MeshFormat"):
        fields = lines[1].split() if len(lines) > 1 else []
        if len(fields) < 2:
            raise MeshError("malformed $MeshFormat line (expected 'version file-type data-size')", 2)
        try:
            version = float(fields[0])
            file_type = int(fields[1])
        except ValueError:
            raise MeshError(f"malformed $MeshFormat line {lines[1].strip()!r}", 2) from None
        return int(version), version, file_type
    raise MeshError("not a Gmsh file: the first line is neither '$NOD' (format 1) nor '$MeshFormat'", 1)


def _read_gmsh(path: str) -> Mesh:
    major, version, file_type = _gmsh_header(path)
    if major <= 2 and file_type == 0:
        return _parse_gmsh_ascii(_read_text(path), major)
    if major in (2, 4):
        return _read_with_meshio(path, "gmsh")
    raise MeshError(f"Gmsh format {version:g} is not supported (formats 1, 2 and 4 are)", 2)


def _count_gmsh(path: str) -> int:
    major, _version, _file_type = _gmsh_header(path)
    marker = "$NOD" if major == 1 else "$Nodes"
    with open(path, "rb") as handle:
        line_no = 0
        found = False
        for raw in handle:
            line_no += 1
            line = raw.decode("latin-1").strip()
            if not found:
                found = line == marker
                continue
            fields = line.split()
            try:
                return int(fields[1] if major >= 4 else fields[0])
            except (ValueError, IndexError):
                raise MeshError(f"malformed node count after {marker}", line_no) from None
    raise MeshError(f"no {marker} section", None)


_GMSH_SECTION_RE = re.compile(r"^[ \t]*\$(\w+)[ \t]*$", re.M)


def _parse_gmsh_ascii(text: str, major: int) -> Mesh:
    """Gmsh format 1 (``$NOD``/``$ELM``) or 2 ASCII (``$Nodes``/``$Elements``), as SOFA reads it.

    Node numbers may be any non-negative integers in any order: points are kept in file order
    and elements refer to them through their numbers (a repeated number: the last node wins, as
    in SOFA). Element types 1 line, 2 triangle, 3 quad, 4 tetrahedron, 5 hexahedron are stored;
    15 (point) is accepted and stores nothing (as in SOFA); other types are skipped with a note.
    Deviations from SOFA: an element naming an unknown node is an error (SOFA uses node 0), and
    second-order elements are skipped instead of keeping their corner nodes.
    """
    _reject_binary(text)
    node_tag, end_node_tag = ("NOD", "ENDNOD") if major == 1 else ("Nodes", "EndNodes")
    elem_tag, end_elem_tag = ("ELM", "ENDELM") if major == 1 else ("Elements", "EndElements")
    sections: dict[str, tuple[int, int, int]] = {}  # name -> (body start offset, body end, header line)
    open_name: str | None = None
    open_start = open_line = 0
    for m in _GMSH_SECTION_RE.finditer(text):
        name = m.group(1)
        if open_name is None:
            open_name, open_start, open_line = name, m.end() + 1, _line_of(text, m.start())
        elif name.upper() == ("END" + open_name).upper():
            sections.setdefault(open_name, (open_start, m.start(), open_line))
            open_name = None
    if open_name is not None:
        raise MeshError(f"section ${open_name} is not closed (truncated file?)", open_line)
    for tag, end_tag in ((node_tag, end_node_tag), (elem_tag, end_elem_tag)):
        if tag not in sections:
            raise MeshError(f"no ${tag} ... ${end_tag} section", None)

    # --- nodes
    start, end, header_line = sections[node_tag]
    body = text[start:end] if start <= end else ""
    count_text, _, rest = body.lstrip(" \t").partition("\n")
    first_node_line = header_line + 2
    try:
        n_nodes = int(count_text.strip())
    except ValueError:
        raise MeshError(
            f"expected the number of nodes after ${node_tag}, found {count_text.strip()!r}", header_line + 1
        ) from None
    values = _numbers(rest)
    if values is None or values.size != 4 * n_nodes:
        _gmsh_node_lines_slow(rest, n_nodes, first_node_line, end_node_tag)
        raise MeshError("malformed node section", header_line)  # not reached
    table = values.reshape(n_nodes, 4)
    ids_f = table[:, 0]
    ids = ids_f.astype(np.int64)
    if n_nodes and (not np.array_equal(ids, ids_f) or ids.min() < 0):
        bad = int(np.nonzero((ids != ids_f) | (ids < 0))[0][0])
        raise MeshError(
            f"node number {table[bad, 0]!r} is not a non-negative integer",
            _nth_data_line(rest, bad, first_node_line),
        )
    positions = np.ascontiguousarray(table[:, 1:])
    if not np.isfinite(positions).all():
        bad = int(np.nonzero(~np.isfinite(positions).all(axis=1))[0][0])
        raise MeshError("non-finite node coordinate", _nth_data_line(rest, bad, first_node_line))
    notes: list[str] = []
    lookup = _gmsh_lookup(ids, notes)

    # --- elements
    start, end, header_line = sections[elem_tag]
    body = text[start:end] if start <= end else ""
    lines = body.split("\n")
    # lines[0] is the element count; skip blank lines like a stream reader would.
    k = 0
    while k < len(lines) and not lines[k].strip():
        k += 1
    if k >= len(lines):
        raise MeshError(f"expected the number of elements after ${elem_tag}", header_line + 1)
    try:
        n_elems = int(lines[k].strip())
    except ValueError:
        raise MeshError(
            f"expected the number of elements after ${elem_tag}, found {lines[k].strip()!r}",
            header_line + 1 + k,
        ) from None
    cells: dict[str, list[list[int]]] = {
        name: [] for name in ("edges", "triangles", "quads", "tetrahedra", "hexahedra")
    }
    cell_lines: dict[str, list[int]] = {name: [] for name in cells}
    skipped: dict[int, int] = {}
    seen = 0
    for j in range(k + 1, len(lines)):
        line = lines[j]
        tokens = line.split()
        if not tokens:
            continue
        line_no = header_line + 1 + j
        if seen == n_elems:
            raise MeshError(f"more element lines than the {n_elems} announced", line_no)
        seen += 1
        try:
            numbers = [int(t) for t in tokens]
        except ValueError:
            bad = next(t for t in tokens if not t.lstrip("+-").isdigit())
            raise MeshError(f"element: expected an integer, found {bad!r}", line_no) from None
        if major == 1:
            if len(numbers) < 5:
                raise MeshError(
                    "element line needs 'number type physical elementary node-count nodes...'", line_no
                )
            etype, nn = numbers[1], numbers[4]
            nodes = numbers[5:]
            if len(nodes) != nn:
                raise MeshError(f"element announces {nn} nodes but lists {len(nodes)}", line_no)
        else:
            if len(numbers) < 3:
                raise MeshError("element line needs 'number type tag-count tags... nodes...'", line_no)
            etype, ntags = numbers[1], numbers[2]
            nodes = numbers[3 + ntags :]
            expected = _GMSH_TYPES.get(etype, (None, _GMSH_OTHER_NODES.get(etype, -1)))[1]
            if expected >= 0 and len(nodes) != expected:
                raise MeshError(
                    f"element of type {etype} needs {expected} nodes after {ntags} tags, found {len(nodes)}",
                    line_no,
                )
        kind = _GMSH_TYPES.get(etype)
        if kind is None:
            skipped[etype] = skipped.get(etype, 0) + 1
            continue
        name, nn_expected = kind
        if len(nodes) != nn_expected:
            raise MeshError(f"element of type {etype} needs {nn_expected} nodes, found {len(nodes)}", line_no)
        if name is not None:
            cells[name].append(nodes)
            cell_lines[name].append(line_no)
    if seen < n_elems:
        raise MeshError(
            f"only {seen} of the {n_elems} announced elements (truncated file?)", sections[elem_tag][2]
        )
    for etype, count in sorted(skipped.items()):
        label = _GMSH_NAMES.get(etype, f"type {etype}")
        notes.append(f"skipped {count} gmsh element(s) of type {etype} ({label}): not supported")

    mesh_kw: dict[str, np.ndarray] = {}
    for name, rows in cells.items():
        if not rows:
            continue
        raw = np.array(rows, dtype=np.int64)
        mapped = _gmsh_map(raw, lookup)
        if (mapped < 0).any():
            row = int(np.nonzero((mapped < 0).any(axis=1))[0][0])
            bad = int(raw[row][mapped[row] < 0][0])
            raise MeshError(
                f"element refers to node {bad}, which is not in the node section", cell_lines[name][row]
            )
        mesh_kw[name] = mapped
    return Mesh(positions=positions, notes=tuple(notes), **mesh_kw)


def _gmsh_lookup(ids: np.ndarray, notes: list[str]) -> np.ndarray | dict[int, int]:
    """Node number -> 0-based index in file order (last duplicate wins, as in SOFA)."""
    n = ids.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if len(np.unique(ids)) != n:
        notes.append("repeated node numbers: elements use the last node with a given number")
    top = int(ids.max())
    if top <= 4 * n + 1024:
        table = np.full(top + 1, -1, dtype=np.int64)
        table[ids] = np.arange(n)  # with repeats numpy keeps the last assignment
        return table
    return {int(i): k for k, i in enumerate(ids)}


def _gmsh_map(raw: np.ndarray, lookup: np.ndarray | dict[int, int]) -> np.ndarray:
    if isinstance(lookup, dict):
        return np.vectorize(lambda i: lookup.get(int(i), -1), otypes=[np.int64])(raw).reshape(raw.shape)
    inside = (raw >= 0) & (raw < lookup.size)
    out = np.full(raw.shape, -1, dtype=np.int64)
    out[inside] = lookup[raw[inside]]
    return out


def _nth_data_line(body: str, row: int, first_line: int) -> int:
    count = -1
    for k, line in enumerate(body.split("\n")):
        if line.strip():
            count += 1
            if count == row:
                return first_line + k
    return first_line


def _gmsh_node_lines_slow(body: str, n_nodes: int, first_line: int, end_tag: str) -> None:
    """Find and raise the error in a node section whose fast parse failed."""
    seen = 0
    for k, line in enumerate(body.split("\n")):
        tokens = line.split()
        if not tokens:
            continue
        line_no = first_line + k
        if seen == n_nodes:
            raise MeshError(f"more node lines than the {n_nodes} announced", line_no)
        if len(tokens) != 4:
            raise MeshError(f"node line needs 'number x y z', found {len(tokens)} values", line_no)
        for token in tokens:
            _to_float(token, line_no, "node")
        seen += 1
    raise MeshError(
        f"only {seen} of the {n_nodes} announced nodes before ${end_tag} (truncated file?)",
        first_line + len(body.split("\n")) - 1,
    )


# --------------------------------------------------------------------------------------------
# meshio (formats SOFA's example files do not use)
# --------------------------------------------------------------------------------------------

# meshio cell type -> (Mesh field, node permutation or None)
_MESHIO_CELLS: dict[str, tuple[str | None, list[int] | None]] = {
    "line": ("edges", None),
    "triangle": ("triangles", None),
    "quad": ("quads", None),
    "tetra": ("tetrahedra", None),
    "hexahedron": ("hexahedra", None),
    "vertex": (None, None),
    "pixel": ("quads", [0, 1, 3, 2]),
    "voxel": ("hexahedra", [0, 1, 3, 2, 4, 5, 7, 6]),
}


def _read_with_meshio(path: str, file_format: str) -> Mesh:
    try:
        import meshio
    except ImportError:  # pragma: no cover - meshio is a dependency
        raise MeshError(f"reading this {file_format} file needs the 'meshio' package") from None
    said, complained = io.StringIO(), io.StringIO()
    try:
        with warnings.catch_warnings(), redirect_stdout(said), redirect_stderr(complained):
            warnings.simplefilter("ignore")
            data = meshio.read(path, file_format=file_format)
    except Exception as error:  # meshio raises many types (ReadError, ValueError, IndexError...)
        raise MeshError(f"cannot read {file_format} file (meshio: {error})") from None
    except SystemExit:  # on a file no reader takes (a POLYDATA .vtk) meshio prints why and exits
        why = " ".join(said.getvalue().split()) or "no reader accepts this file"
        raise MeshError(f"cannot read {file_format} file (meshio: {why})") from None
    points = np.asarray(data.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"unexpected point array of shape {points.shape}")
    if points.shape[1] == 2:
        points = np.hstack([points, np.zeros((points.shape[0], 1))])
    collected: dict[str, list[np.ndarray]] = {}
    notes: list[str] = []
    for block in data.cells:
        kind = _MESHIO_CELLS.get(block.type)
        if kind is None:
            notes.append(f"skipped {len(block.data)} cell(s) of type {block.type!r}: not supported")
            continue
        name, permutation = kind
        if name is None:
            continue
        cells = np.asarray(block.data, dtype=np.int64)
        if permutation is not None:
            cells = cells[:, permutation]
        collected.setdefault(name, []).append(cells)
    mesh_kw: dict[str, Any] = {name: np.concatenate(blocks) for name, blocks in collected.items()}
    for name, cells in mesh_kw.items():
        if cells.size and (cells.min() < 0 or cells.max() >= points.shape[0]):
            raise MeshError(f"{name} refer to points outside the {points.shape[0]} defined")
    normals = data.point_data.get("Normals") if data.point_data else None
    if normals is not None and np.shape(normals) == (points.shape[0], 3):
        mesh_kw["normals"] = normals
    return Mesh(positions=points, notes=tuple(notes), **mesh_kw)


# --------------------------------------------------------------------------------------------
# VTK: cell types shared by legacy and XML files
# --------------------------------------------------------------------------------------------

_VTK_NAMES = {
    0: "empty",
    1: "vertex",
    2: "poly-vertex",
    4: "poly-line",
    13: "wedge",
    14: "pyramid",
    21: "quadratic edge",
    22: "quadratic triangle",
    23: "quadratic quad",
    24: "quadratic tetrahedron",
    25: "quadratic hexahedron",
}


def _vtk_cells(
    types: np.ndarray, offsets: np.ndarray, conn: np.ndarray, n_points: int, line: int | None
) -> tuple[dict[str, np.ndarray], list[str]]:
    """Elements from VTK cell types; ``offsets[c]:offsets[c+1]`` are cell c's points in ``conn``.

    As in SOFA's MeshVTKLoader: 3 line, 5 triangle, 6 triangle strip (alternating orientation),
    7 polygon (fan), 8 pixel and 9 quad (quads, pixel reordered), 10 tetrahedron, 11 voxel and
    12 hexahedron (hexahedra, voxel reordered); 0/1/2 (empty, vertex, poly-vertex) store nothing;
    other types are skipped with a note.
    """
    sizes = np.diff(offsets)
    if conn.size and (conn.min() < 0 or conn.max() >= n_points):
        bad = int(conn[(conn < 0) | (conn >= n_points)][0])
        raise MeshError(f"cell refers to point {bad}, but the file defines {n_points} points", line)
    expected = {3: 2, 5: 3, 8: 4, 9: 4, 10: 4, 11: 8, 12: 8}
    for vtk_type, size in expected.items():
        mismatch = (types == vtk_type) & (sizes != size)
        if mismatch.any():
            c = int(np.nonzero(mismatch)[0][0])
            raise MeshError(
                f"cell {c} of VTK type {vtk_type} has {int(sizes[c])} points, expected {size}", line
            )
    blocks: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}  # name -> [(cell numbers, rows)]

    def fixed(vtk_type: int, name: str, permutation: list[int] | None = None) -> None:
        chosen = np.nonzero(types == vtk_type)[0]
        if chosen.size:
            block = conn[offsets[chosen, None] + np.arange(expected[vtk_type])]
            if permutation is not None:
                block = block[:, permutation]
            blocks.setdefault(name, []).append((chosen, block))

    fixed(3, "edges")
    fixed(5, "triangles")
    fixed(8, "quads", [0, 1, 3, 2])
    fixed(9, "quads")
    fixed(10, "tetrahedra")
    fixed(11, "hexahedra", [0, 1, 3, 2, 4, 5, 7, 6])
    fixed(12, "hexahedra")
    fans: list[list[int]] = []
    fan_cells: list[int] = []
    for c in np.nonzero((types == 6) | (types == 7))[0].tolist():
        pts = conn[offsets[c] : offsets[c + 1]].tolist()
        for j in range(len(pts) - 2):
            if types[c] == 7:
                fans.append([pts[0], pts[j + 1], pts[j + 2]])
            elif j & 1:
                fans.append([pts[j], pts[j + 1], pts[j + 2]])
            else:
                fans.append([pts[j], pts[j + 2], pts[j + 1]])
            fan_cells.append(c)
    if fans:
        blocks.setdefault("triangles", []).append((np.array(fan_cells), np.array(fans, dtype=np.int64)))
    out: dict[str, np.ndarray] = {}
    for name, parts in blocks.items():
        cell_numbers = np.concatenate([numbers for numbers, _ in parts])
        rows = np.concatenate([block for _, block in parts])
        out[name] = rows[np.argsort(cell_numbers, kind="stable")]  # file order of the cells
    notes = []
    known = {0, 1, 2, 3, 5, 6, 7, 8, 9, 10, 11, 12}
    for vtk_type in sorted(set(np.unique(types).tolist()) - known):
        count = int((types == vtk_type).sum())
        label = _VTK_NAMES.get(vtk_type, f"type {vtk_type}")
        notes.append(f"skipped {count} VTK cell(s) of type {vtk_type} ({label}): not supported")
    return out, notes


# --------------------------------------------------------------------------------------------
# VTK XML (.vtu)
# --------------------------------------------------------------------------------------------

_VTU_POINTS_RE = re.compile(r"<Piece\b[^>]*\bNumberOfPoints\s*=\s*[\"'](\d+)[\"']")


def _vtu_parser() -> Any:
    from lxml import etree

    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )


def _parse_vtu(data: bytes) -> Mesh:
    """VTK XML UnstructuredGrid or PolyData with ASCII data arrays (``format="ascii"``).

    PolyData as SOFA's XMLVTKReader::loadPolydata: only ``Points``, ``Polys`` and ``PointData``
    (Verts, Lines and Strips are not read); a polygon of 2, 3, 4 points is an edge, a triangle, a
    quad, a larger one a polyline (which sofac does not keep). SOFA splits the connectivity by
    text lines when ``offsets`` comes before it; sofac always follows the offsets.

    Binary or appended data is refused ("binary VTU not supported"). Several ``Piece`` elements
    are concatenated (SOFA keeps only the last one). A point-data array named ``Normals`` with 3
    components gives the normals.
    """
    from lxml import etree

    try:
        root = etree.fromstring(data, _vtu_parser())
    except etree.XMLSyntaxError as error:
        line = error.lineno if getattr(error, "lineno", None) else None
        message = error.msg if hasattr(error, "msg") else str(error)
        if "huge" in str(message).lower():
            message += " (an ASCII data array exceeds libxml2's size limit; use another mesh format)"
        raise MeshError(f"malformed XML: {message}", line) from None
    if root.getroottree().docinfo.internalDTD is not None or root.getroottree().docinfo.doctype:
        raise MeshError("DOCTYPE declarations are not allowed in VTU files", 1)
    if root.tag != "VTKFile":
        raise MeshError(f"not a VTK XML file (root element <{root.tag}>)", root.sourceline)
    file_type = root.get("type")
    if file_type not in ("UnstructuredGrid", "PolyData"):
        raise MeshError(
            f"VTK XML type {file_type!r} is not supported (only UnstructuredGrid and PolyData)",
            root.sourceline,
        )
    poly = file_type == "PolyData"
    if root.find("AppendedData") is not None:
        raise MeshError(
            "binary VTU not supported (AppendedData); save the file with ASCII data arrays",
            root.find("AppendedData").sourceline,
        )
    grid = root.find(file_type)
    if grid is None:
        raise MeshError(f"no <{file_type}> element", root.sourceline)
    pieces = grid.findall("Piece")
    if not pieces:
        raise MeshError("no <Piece> element", grid.sourceline)
    all_points: list[np.ndarray] = []
    all_normals: list[np.ndarray | None] = []
    collected: dict[str, list[np.ndarray]] = {}
    notes: list[str] = []
    offset = 0
    for piece in pieces:
        n_points = _vtu_int_attr(piece, "NumberOfPoints")
        n_cells = _vtu_int_attr(piece, "NumberOfPolys" if poly else "NumberOfCells")
        points_el = piece.find("Points/DataArray")
        if points_el is None:
            if n_points:
                raise MeshError("no <Points><DataArray> in piece", piece.sourceline)
            points = np.zeros((0, 3))
        else:
            ncomp = points_el.get("NumberOfComponents", "3").strip()
            if ncomp != "3":
                raise MeshError(f"points must have 3 components, found {ncomp}", points_el.sourceline)
            points = _vtu_array(points_el, np.float64, 3 * n_points).reshape(n_points, 3)
            if not np.isfinite(points).all():
                raise MeshError("non-finite point coordinate", points_el.sourceline)
        section = "Polys" if poly else "Cells"
        arrays = {el.get("Name"): el for el in piece.findall(f"{section}/DataArray")}
        if n_cells:
            for needed in ("connectivity", "offsets") if poly else ("connectivity", "offsets", "types"):
                if needed not in arrays:
                    raise MeshError(f'no <{section}><DataArray Name="{needed}">', piece.sourceline)
            conn = _vtu_array(arrays["connectivity"], np.int64, None)
            ends = _vtu_array(arrays["offsets"], np.int64, n_cells)
            offsets = np.concatenate([[0], ends])
            if (np.diff(offsets) < 0).any() or offsets[-1] != conn.size:
                raise MeshError(
                    "cell offsets do not match the connectivity array", arrays["offsets"].sourceline
                )
            if poly:  # XMLVTKReader::parsePolysIndices: the type from the size, polylines past 4
                types = np.select([np.diff(offsets) == k for k in (2, 3, 4)], [3, 5, 9], default=4)
            else:
                types = _vtu_array(arrays["types"], np.int64, n_cells)
            cells, cell_notes = _vtk_cells(types, offsets, conn, n_points, arrays["connectivity"].sourceline)
            notes.extend(cell_notes)
            for name, block in cells.items():
                collected.setdefault(name, []).append(block + offset)
        normals_el = next(
            (
                el
                for el in piece.findall("PointData/DataArray")
                if (el.get("Name") or "").lower() == "normals" and el.get("NumberOfComponents") == "3"
            ),
            None,
        )
        normals = None
        if normals_el is not None:
            normals = _vtu_array(normals_el, np.float64, 3 * n_points).reshape(n_points, 3)
        all_points.append(points)
        all_normals.append(normals)
        offset += n_points
    if len(pieces) > 1:
        notes.append(f"{len(pieces)} pieces concatenated")
    mesh_kw: dict[str, Any] = {name: np.concatenate(blocks) for name, blocks in collected.items()}
    if all(n is not None for n in all_normals):
        mesh_kw["normals"] = np.concatenate(all_normals)  # type: ignore[arg-type]
    return Mesh(positions=np.concatenate(all_points), notes=tuple(notes), **mesh_kw)


def _vtu_int_attr(el: Any, name: str) -> int:
    value = el.get(name)
    try:
        number = int(value)
    except (TypeError, ValueError):
        raise MeshError(f"<{el.tag}> needs an integer {name}, found {value!r}", el.sourceline) from None
    if number < 0:
        raise MeshError(f"<{el.tag}> {name} is negative", el.sourceline)
    return number


def _vtu_array(el: Any, dtype: type, count: int | None) -> np.ndarray:
    fmt = (el.get("format") or el.get("Format") or "").lower()
    name = el.get("Name") or "points"
    if fmt != "ascii":
        raise MeshError(
            f"binary VTU not supported (DataArray {name!r} has format={fmt!r}); "
            "save the file with ASCII data arrays",
            el.sourceline,
        )
    text = el.text or ""
    values = _numbers(text, np.float64)
    if values is None:
        bad = next((t for t in text.split() if not _is_number(t)), "?")
        raise MeshError(f"DataArray {name!r}: expected numbers, found {bad!r}", el.sourceline)
    if count is not None and values.size != count:
        raise MeshError(f"DataArray {name!r}: expected {count} values, found {values.size}", el.sourceline)
    if dtype is np.int64:
        ints = values.astype(np.int64)
        if not np.array_equal(ints, values):
            raise MeshError(f"DataArray {name!r}: expected integers", el.sourceline)
        return ints
    return values


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _count_vtu(text: str) -> int:
    counts = _VTU_POINTS_RE.findall(text)
    if not counts:
        raise MeshError("no <Piece NumberOfPoints=...> found")
    return sum(int(c) for c in counts)


# --------------------------------------------------------------------------------------------
# Legacy VTK (.vtk)
# --------------------------------------------------------------------------------------------

_VTK_KEYWORD_RE = re.compile(r"^[ \t]*([A-Za-z_][A-Za-z_0-9]*)([^\n]*)$", re.M)


def _is_vtk_xml(path: str) -> bool:
    """MeshVTKLoader::detectFileType: an XML file when the first line holds ``<?xml`` or
    ``<VTKFile``, whatever the extension (share/mesh/Bunny.vtk is XML). (SOFA also wants
    ``<VTKFile`` on the second line after ``<?xml``, else reads nothing; the XML reader says why.)"""
    with open(path, "rb") as handle:
        first = handle.readline()
    return b"<?xml" in first or b"<VTKFile" in first


def _vtk_header(path: str) -> tuple[str, str]:
    """(version string, 'ASCII'|'BINARY') from the first three lines."""
    with open(path, "rb") as handle:
        head = handle.read(1024).decode("latin-1").replace("\r", "")
    lines = head.split("\n")
    if not lines[0].startswith("# vtk DataFile Version"):
        raise MeshError("not a legacy VTK file (first line is not '# vtk DataFile Version x.y')", 1)
    version = lines[0].rsplit(" ", 1)[-1].strip()
    if len(lines) < 3:
        raise MeshError("truncated header", len(lines))
    encoding = lines[2].strip().upper()
    if encoding not in ("ASCII", "BINARY"):
        raise MeshError(f"third line must be ASCII or BINARY, found {lines[2].strip()!r}", 3)
    return version, encoding


def _read_vtk(path: str) -> Mesh:
    version, encoding = _vtk_header(path)
    major = version.split(".")[0]
    if major.isdigit() and int(major) >= 5:
        return _read_with_meshio(path, "vtk")
    if encoding == "BINARY":
        return _parse_vtk_binary(_read_bytes(path))
    return _parse_vtk_ascii(_read_text(path))


def _count_vtk(path: str) -> int:
    _vtk_header(path)
    with open(path, "rb") as handle:
        for line_no, raw in enumerate(handle, start=1):
            if raw.lstrip().upper().startswith(b"POINTS"):
                fields = raw.split()
                try:
                    return int(fields[1])
                except (ValueError, IndexError):
                    raise MeshError("malformed POINTS line", line_no) from None
    raise MeshError("no POINTS section")


def _parse_vtk_ascii(text: str) -> Mesh:
    """Legacy VTK ASCII (versions up to 4.2): UNSTRUCTURED_GRID (``CELLS``/``CELL_TYPES``) or
    POLYDATA (``VERTICES``, ``LINES``, ``POLYGONS``, ``TRIANGLE_STRIPS``).

    Cell types as in :func:`_vtk_cells`. ``POINTS n float`` values are rounded to single
    precision, as SOFA stores them (``double`` ones are kept). POLYDATA: POLYGONS with 4 points
    are quads, others fans of triangles (as in SOFA); LINES give one edge per segment (SOFA keeps
    them as polylines); VERTICES store nothing. ``NORMALS`` in ``POINT_DATA`` give the normals;
    other attribute data (SCALARS, FIELD, ...) is ignored.
    """
    _reject_binary(text)
    header_end = 0
    for _ in range(3):  # version, title, encoding
        header_end = text.find("\n", header_end) + 1
        if header_end == 0:
            raise MeshError("truncated header", None)
    sections = [m for m in _VTK_KEYWORD_RE.finditer(text, header_end)]
    dataset: str | None = None
    points: np.ndarray | None = None
    lists: dict[str, tuple[np.ndarray, int, int]] = {}  # keyword -> (values, cell count, line)
    cell_types: np.ndarray | None = None
    normals: np.ndarray | None = None
    mode = "geometry"
    for index, m in enumerate(sections):
        keyword = m.group(1).upper()
        args = m.group(2).split()
        line = _line_of(text, m.start())
        body_end = sections[index + 1].start() if index + 1 < len(sections) else len(text)
        body = text[m.end() : body_end]
        if keyword == "DATASET":
            dataset = _vtk_dataset(args, line)
        elif keyword in ("POINT_DATA", "CELL_DATA"):
            mode = keyword
        elif mode != "geometry":
            if keyword == "NORMALS" and mode == "POINT_DATA" and points is not None:
                normals = _vtk_body(body, points.size, np.float64, keyword, line).reshape(-1, 3)
        elif keyword == "POINTS":
            n_points = _vtk_count(args, 0, keyword, line)
            points = _vtk_body(body, 3 * n_points, np.float64, keyword, line).reshape(n_points, 3)
            if len(args) > 1 and args[1].lower() == "float":
                points = points.astype(np.float32).astype(np.float64)  # SOFA stores them as float
            if not np.isfinite(points).all():
                raise MeshError("non-finite point coordinate", line)
        elif keyword in ("CELLS", "VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"):
            n = _vtk_count(args, 0, keyword, line)
            size = _vtk_count(args, 1, keyword, line)
            lists[keyword] = (_vtk_body(body, size, np.int64, keyword, line), n, line)
        elif keyword == "CELL_TYPES":
            n = _vtk_count(args, 0, keyword, line)
            cell_types = _vtk_body(body, n, np.int64, keyword, line)
    return _vtk_mesh(dataset, points, lists, cell_types, normals)


def _vtk_mesh(
    dataset: str | None,
    points: np.ndarray | None,
    lists: dict[str, tuple[np.ndarray, int, int]],
    cell_types: np.ndarray | None,
    normals: np.ndarray | None,
) -> Mesh:
    """The mesh of a legacy file's sections, ASCII or binary: ``lists`` maps CELLS, VERTICES,
    LINES, POLYGONS, TRIANGLE_STRIPS to (count-prefixed values, cell count, line)."""
    if dataset is None:
        raise MeshError("no DATASET line", None)
    if points is None:
        raise MeshError("no POINTS section", None)
    n_points = points.shape[0]
    mesh_kw: dict[str, Any] = {}
    notes: list[str] = []
    if dataset == "UNSTRUCTURED_GRID":
        if "CELLS" in lists:
            flat, n, line = lists["CELLS"]
            conn, offsets = _vtk_unprefix(flat, n, "CELLS", line)
            if cell_types is None or cell_types.size != n:
                raise MeshError(f"CELL_TYPES must list one type per cell ({n})", line)
            mesh_kw, notes = _vtk_cells(cell_types, offsets, conn, n_points, line)
    else:
        collected: dict[str, list[np.ndarray]] = {}
        for keyword, vtk_type in (("VERTICES", 1), ("LINES", 4), ("POLYGONS", 7), ("TRIANGLE_STRIPS", 6)):
            if keyword not in lists:
                continue
            flat, n, line = lists[keyword]
            conn, offsets = _vtk_unprefix(flat, n, keyword, line)
            if conn.size and (conn.min() < 0 or conn.max() >= n_points):
                raise MeshError(f"{keyword} refer to points outside the {n_points} defined", line)
            sizes = np.diff(offsets)
            if keyword == "LINES":
                starts = np.repeat(offsets[:-1], np.maximum(sizes - 1, 0))
                local = np.arange(starts.size) - np.repeat(
                    np.cumsum(np.maximum(sizes - 1, 0)) - np.maximum(sizes - 1, 0), np.maximum(sizes - 1, 0)
                )
                if starts.size:
                    collected.setdefault("edges", []).append(
                        np.stack([conn[starts + local], conn[starts + local + 1]], axis=1)
                    )
                continue
            types = np.full(n, vtk_type)
            if keyword == "POLYGONS":
                types[sizes == 4] = 9
            cells, _ = _vtk_cells(types, offsets, conn, n_points, line)
            for name, block in cells.items():
                collected.setdefault(name, []).append(block)
        mesh_kw = {name: np.concatenate(blocks) for name, blocks in collected.items()}
    if normals is not None:
        mesh_kw["normals"] = normals
    return Mesh(positions=points, notes=tuple(notes), **mesh_kw)


def _vtk_dataset(args: list[str], line: int) -> str:
    """The kind a ``DATASET`` line names, one of those SOFA's legacy reader takes."""
    dataset = args[0].upper() if args else ""
    if dataset not in ("UNSTRUCTURED_GRID", "POLYDATA"):
        raise MeshError(
            f"VTK dataset {dataset or '?'} is not supported (only UNSTRUCTURED_GRID and POLYDATA)", line
        )
    return dataset


def _vtk_count(args: list[str], position: int, keyword: str, line: int) -> int:
    try:
        value = int(args[position])
    except (IndexError, ValueError):
        raise MeshError(f"malformed {keyword} line", line) from None
    if value < 0:
        raise MeshError(f"negative count in {keyword} line", line)
    return value


def _vtk_body(body: str, count: int, dtype: type, keyword: str, line: int) -> np.ndarray:
    values = _numbers(body, np.float64)
    if values is None:
        for k, body_line in enumerate(body.split("\n")):
            for token in body_line.split():
                if not _is_number(token):
                    raise MeshError(f"{keyword}: expected a number, found {token!r}", line + k)
        raise MeshError(f"{keyword}: malformed data", line)  # pragma: no cover
    if values.size != count:
        raise MeshError(f"{keyword}: expected {count} values, found {values.size} (truncated file?)", line)
    if dtype is np.int64:
        ints = values.astype(np.int64)
        if not np.array_equal(ints, values):
            raise MeshError(f"{keyword}: expected integers", line)
        return ints
    return values


def _vtk_unprefix(flat: np.ndarray, n: int, keyword: str, line: int) -> tuple[np.ndarray, np.ndarray]:
    """Split a legacy count-prefixed cell list into (connectivity, offsets[n + 1])."""
    if n > flat.size:
        raise MeshError(f"{keyword}: {n} cells announced but the list has only {flat.size} values", line)
    starts = np.zeros(n + 1, dtype=np.int64)
    position = 0
    values = flat.tolist()
    for c in range(n):
        starts[c] = position
        if position >= len(values):
            raise MeshError(f"{keyword}: the list ends after {c} of {n} cells", line)
        size = values[position]
        if size < 0:
            raise MeshError(f"{keyword}: cell {c} has a negative point count", line)
        position += size + 1
    if position != len(values):
        raise MeshError(f"{keyword}: the size field ({len(values)}) does not match the cell list", line)
    starts[n] = position
    keep = np.ones(flat.size, dtype=bool)
    keep[starts[:-1]] = False
    sizes = np.diff(starts) - 1
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    return flat[keep], offsets


_VTK_BINARY_TYPES = {
    "float": "f4", "double": "f8", "int": "i4", "unsigned_int": "u4", "long": "i8",
    "unsigned_long": "u8", "short": "i2", "unsigned_short": "u2", "char": "i1", "unsigned_char": "u1",
}  # fmt: skip


def _parse_vtk_binary(data: bytes) -> Mesh:
    """Legacy VTK BINARY (versions up to 4.2), as SOFA's LegacyVTKReader reads it: after each
    ``POINTS n type``, ``CELLS``/``POLYGONS``/``LINES``/... ``n size`` or ``CELL_TYPES n`` line come
    the raw numbers (``int`` for the cell lists). SOFA reads them in the machine's byte order and
    swaps them all when the first cell count (or cell type) reads larger than its swap: so
    big-endian, VTK's order, for any real file. It stops at the first POINT_DATA or CELL_DATA
    (sofac: no normals from a binary file) and, as SOFA, once points and polygons are read."""
    position = 0
    line_number = 0

    def next_line() -> str:
        nonlocal position, line_number
        end = data.find(b"\n", position)
        end = len(data) if end < 0 else end
        text = data[position:end].decode("latin-1").rstrip("\r")
        position = end + 1
        line_number += 1
        return text

    for _ in range(3):  # version, title, BINARY
        next_line()
    dataset: str | None = None
    raw: dict[str, tuple[bytes, str, int, int]] = {}  # keyword -> (bytes, dtype, cell count, line)
    while position < len(data):
        text = next_line()
        if not text.strip():
            continue
        words = text.split()
        keyword, args, line = words[0].upper(), words[1:], line_number
        if keyword == "DATASET":
            dataset = _vtk_dataset(args, line)
            continue
        if keyword in ("POINT_DATA", "CELL_DATA"):
            break
        if keyword == "POINTS":
            count = 3 * _vtk_count(args, 0, keyword, line)
            name = args[1].lower() if len(args) > 1 else ""
            if name not in _VTK_BINARY_TYPES:
                raise MeshError(f"POINTS: unknown number type {name or '?'}", line)
            dtype, cells = _VTK_BINARY_TYPES[name], 0
        elif keyword in ("CELLS", "VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"):
            cells, count, dtype = _vtk_count(args, 0, keyword, line), _vtk_count(args, 1, keyword, line), "i4"
        elif keyword == "CELL_TYPES":
            count, dtype, cells = _vtk_count(args, 0, keyword, line), "i4", 0
        else:
            raise MeshError(f"unexpected {keyword!r} in a binary VTK file", line)
        size = count * int(dtype[1])
        if position + size > len(data):
            raise MeshError(f"{keyword}: {count} values announced, the file ends before (truncated?)", line)
        raw[keyword] = (data[position : position + size], dtype, cells, line)
        position += size
        if data[position : position + 1] == b"\n":  # the end of the data's line (not a line of its own)
            position += 1
        if "POINTS" in raw and "POLYGONS" in raw:
            break
    # SOFA's test (on a little-endian machine): swap when the first int reads larger swapped back.
    first = raw.get("POLYGONS") or (raw.get("CELL_TYPES") if "CELLS" in raw else None)
    head = first[0][:4] if first is not None else b""
    swapped = len(head) == 4 and int.from_bytes(head, "little") > int.from_bytes(head, "big")
    order = ">" if swapped else "<"

    def values(keyword: str) -> np.ndarray:
        block, dtype, _, _ = raw[keyword]
        return np.frombuffer(block, dtype=order + dtype if dtype[1] != "1" else dtype)

    points = None
    if "POINTS" in raw:
        points = values("POINTS").astype(np.float64).reshape(-1, 3)
        if not np.isfinite(points).all():
            raise MeshError("non-finite point coordinate", raw["POINTS"][3])
    lists = {
        keyword: (values(keyword).astype(np.int64), raw[keyword][2], raw[keyword][3])
        for keyword in ("CELLS", "VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS")
        if keyword in raw
    }
    cell_types = values("CELL_TYPES").astype(np.int64) if "CELL_TYPES" in raw else None
    return _vtk_mesh(dataset, points, lists, cell_types, None)


# --------------------------------------------------------------------------------------------
# SOFA sphere files (.sph)
# --------------------------------------------------------------------------------------------

_SPH_LINE_RE = re.compile(r"^[ \t]*sphe[ \t]", re.M)


def _parse_sph(text: str) -> Spheres:
    """SOFA ``.sph`` sphere list, as SOFA's SphereLoader reads it.

    The first line (``sph 1.0``) is a header and is skipped whatever it says. Then, per line,
    ``nums N`` (announced count, informative), ``sphe id x y z r`` (a sphere; ``id`` is ignored,
    spheres keep file order), and comments: any token starting with ``#`` up to the end of the
    line (so ``#nums 27`` is a comment). An unknown keyword is skipped with a note (SOFA warns).
    Errors: a ``sphe`` line without 5 numbers, a malformed ``nums``.
    """
    _reject_binary(text)
    centers: list[tuple[float, float, float]] = []
    radii: list[float] = []
    notes: list[str] = []
    announced: int | None = None
    lines = text.split("\n")
    for index in range(1, len(lines)):
        tokens = lines[index].split()
        if not tokens or tokens[0].startswith("#"):
            continue
        line_no = index + 1
        keyword = tokens[0]
        if keyword == "sphe":
            fields = tokens[1:6]
            if len(fields) < 5 or any(f.startswith("#") for f in fields):
                raise MeshError(f"'sphe' needs 'id x y z radius', found {len(tokens) - 1} values", line_no)
            _to_int(fields[0], line_no, "sphere id")
            x, y, z, r = (_to_float(f, line_no, "sphere") for f in fields[1:])
            centers.append((x, y, z))
            radii.append(r)
        elif keyword == "nums":
            if len(tokens) < 2:
                raise MeshError("'nums' needs a count", line_no)
            announced = _to_int(tokens[1], line_no, "nums")
        else:
            notes.append(f"line {line_no}: unknown keyword {keyword!r} skipped")
    if announced is not None and announced != len(centers):
        notes.append(f"'nums {announced}' announced, {len(centers)} spheres read")
    return Spheres(
        centers=np.array(centers, dtype=np.float64).reshape(-1, 3),
        radii=np.array(radii, dtype=np.float64),
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------------------------
# Xsp rigid files (.rigid)
# --------------------------------------------------------------------------------------------

# keyword -> (field name or None for "read and ignored", number of values)
_RIGID_KEYWORDS: dict[str, tuple[str | None, int]] = {
    "vertexMass": ("mass", 1),
    "mass": ("mass", 1),
    "volm": ("volume", 1),
    "inrt": ("inertia", 9),
    "cntr": ("center", 3),
    "center": ("center", 3),
    "frme": (None, 4),
    "grav": (None, 3),
    "visc": (None, 1),
    "stck": (None, 1),
    "step": (None, 1),
    "prec": (None, 1),
}


def _parse_rigid(text: str) -> RigidFile:
    """Xsp 3.0 rigid file, as SOFA's ``UniformMass<Rigid3>`` reads ``filename=``.

    The first line (``Xsp 3.0``) is skipped. Keywords and values are read as a token stream:
    ``vertexMass m`` (also ``mass m``, which SOFA itself rejects as unknown), ``volm v``,
    ``inrt`` + 9 numbers (row-major 3x3 inertia, per unit mass), ``cntr``/``center`` + 3 numbers,
    and ``frme`` (4), ``grav`` (3), ``visc``/``stck``/``step``/``prec`` (1) which are read and
    ignored; a token starting with ``#`` comments out the rest of its line.
    Note: SOFA reads ``cntr`` but does not use it. Errors: unknown keywords (SOFA logs an error
    and skips the line), missing or non-numeric values.
    """
    _reject_binary(text)
    values: dict[str, Any] = {}
    tokens: list[tuple[str, int]] = []
    for index, line in enumerate(text.split("\n")[1:], start=2):
        for token in line.split():
            if token.startswith("#"):
                break
            tokens.append((token, index))
    k = 0
    while k < len(tokens):
        keyword, line_no = tokens[k]
        spec = _RIGID_KEYWORDS.get(keyword)
        if spec is None:
            raise MeshError(f"unknown keyword {keyword!r} in rigid file", line_no)
        name, count = spec
        args = tokens[k + 1 : k + 1 + count]
        if len(args) < count:
            raise MeshError(
                f"{keyword!r} needs {count} number(s), found {len(args)} (truncated file?)", line_no
            )
        numbers = [_to_float(token, arg_line, keyword) for token, arg_line in args]
        if name is not None:
            values[name] = numbers
        k += 1 + count
    return RigidFile(
        mass=values["mass"][0] if "mass" in values else 1.0,
        volume=values["volume"][0] if "volume" in values else 1.0,
        inertia=np.array(values["inertia"]).reshape(3, 3) if "inertia" in values else np.eye(3),
        center=np.array(values["center"]) if "center" in values else np.zeros(3),
        present=frozenset(values),
    )


# --------------------------------------------------------------------------------------------
# Transformations
# --------------------------------------------------------------------------------------------


def euler_to_quaternion(rotation_deg: Sequence[float] | np.ndarray) -> np.ndarray:
    """SOFA's quaternion ``(x, y, z, w)`` for Euler angles ``(a, b, c)`` in degrees.

    Convention (``Quat::createQuaterFromEuler`` with its default order ``EulerOrder::ZYX``):
    the rotation turns points by ``a`` about the X axis first, then by ``b`` about the Y axis,
    then by ``c`` about the Z axis, all three axes being the fixed world axes; i.e. the matrix is
    ``Rz(c) @ Ry(b) @ Rx(a)``. Angles are counter-clockwise (right-handed) when looking down the
    axis towards the origin.
    """
    # SOFA's callers pass ``rotation * M_PI / 180.0`` (not math.radians' single factor pi / 180)
    a, b, c = (float(v) * math.pi / 180.0 / 2.0 for v in _vec3(rotation_deg, 0.0, "rotation"))
    c1, c2, c3 = math.cos(a), math.cos(b), math.cos(c)
    s1, s2, s3 = math.sin(a), math.sin(b), math.sin(c)
    return np.array(
        [
            s1 * c2 * c3 - c1 * s2 * s3,
            c1 * s2 * c3 + s1 * c2 * s3,
            c1 * c2 * s3 - s1 * s2 * c3,
            c1 * c2 * c3 + s1 * s2 * s3,
        ]
    )


def quaternion_multiply(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of quaternions stored ``(x, y, z, w)``, as SOFA stores them."""
    ax, ay, az, aw = (float(c) for c in a)
    bx, by, bz, bw = (float(c) for c in b)
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def euler_to_matrix(rotation_deg: Sequence[float] | np.ndarray) -> np.ndarray:
    """3x3 rotation matrix ``Rz(c) @ Ry(b) @ Rx(a)`` of SOFA Euler angles in degrees."""
    x, y, z, w = euler_to_quaternion(rotation_deg)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _vec3(value: Any, default: float, name: str) -> np.ndarray:
    if value is None:
        return np.full(3, default)
    array = np.asarray(value, dtype=np.float64).reshape(-1)
    if array.size == 1:
        return np.full(3, float(array[0]))
    if array.size != 3:
        raise ValueError(f"{name} needs 3 values, got {array.size}")
    return array


def transform_matrix(
    translation: Sequence[float] | np.ndarray | None = None,
    rotation_deg: Sequence[float] | np.ndarray | None = None,
    scale: float | Sequence[float] | np.ndarray | None = None,
) -> np.ndarray:
    """4x4 matrix ``T @ R @ S`` that :func:`apply_transform` applies (MeshLoader's matrix)."""
    m = np.eye(4)
    m[:3, :3] = euler_to_matrix(_vec3(rotation_deg, 0.0, "rotation")) * _vec3(scale, 1.0, "scale")[None, :]
    m[:3, 3] = _vec3(translation, 0.0, "translation")
    return m


def apply_matrix(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Apply a 4x4 affine matrix (a loader's ``transformation``) to (N, 3) points.

    SOFA ignores a matrix whose last row is not ``0 0 0 1``; so does this function (the points
    are returned unchanged, as a copy).
    """
    m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    pts = np.array(points, dtype=np.float64, copy=True)
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        return pts
    return pts @ m[:3, :3].T + m[:3, 3]


def apply_transform(
    points: np.ndarray | Sequence[Sequence[float]],
    translation: Sequence[float] | np.ndarray | None = None,
    rotation_deg: Sequence[float] | np.ndarray | None = None,
    scale: float | Sequence[float] | np.ndarray | None = None,
    *,
    loader: bool = False,
) -> np.ndarray:
    """Transform points as SOFA's loaders and MechanicalObject do: scale, then rotate, then translate.

    ``p' = translation + R @ (scale * p)`` with ``R = Rz(c) @ Ry(b) @ Rx(a)`` for
    ``rotation_deg = (a, b, c)`` in degrees (see :func:`euler_to_quaternion`): a rotation about
    the world X axis first, then world Y, then world Z. ``scale`` is per axis (or one number).
    The arithmetic is SOFA's, operation for operation (never a BLAS product, whose kernel and use
    of FMA depend on the processor): with ``loader``, MeshLoader's ``Matrix4::transform`` of
    ``T R S``; otherwise MechanicalObject's applyScale, ``Quat::rotate`` and applyTranslation.

    ``points`` is (N, d) with d = 1, 2 or 3 (Vec1/Vec2/Vec3 states): missing coordinates are
    taken as 0 for the transformation and dropped from the result, as SOFA's
    MechanicalObject does. Returns a new float64 array; the input is not modified.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 1:
        pts = pts.reshape(-1, 3) if pts.size % 3 == 0 else pts.reshape(-1, 1)
    if pts.ndim != 2 or pts.shape[1] not in (1, 2, 3):
        raise ValueError(f"points must have shape (N, 1..3), got {pts.shape}")
    width = pts.shape[1]
    full = np.zeros((pts.shape[0], 3))
    full[:, :width] = pts
    s = _vec3(scale, 1.0, "scale")
    rotation = _vec3(rotation_deg, 0.0, "rotation")
    t = _vec3(translation, 0.0, "translation")
    if loader:
        if rotation.any() or (s != 1).any():
            # (T R S)(i, j) = R(i, j) s(j) exactly; transform sums row i left to right, then adds t(i)
            m = euler_to_matrix(rotation) * s[None, :]
            full = full[:, 0:1] * m[:, 0] + full[:, 1:2] * m[:, 1] + full[:, 2:3] * m[:, 2]
    else:
        full *= s
        if rotation.any():
            full = rotate_by_quaternion(full, euler_to_quaternion(rotation))
    full += t
    return np.ascontiguousarray(full[:, :width])


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vec3::cross row by row, its three differences as SOFA writes them."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def rotate_by_quaternion(points: np.ndarray, quaternion: Sequence[float] | np.ndarray) -> np.ndarray:
    """(N, 3) points turned by a unit quaternion (x, y, z, w) as SOFA's ``Quat::rotate``:
    ``t = 2 (q × v)``, then ``v + w t + q × t``."""
    q = np.asarray(quaternion, dtype=np.float64)
    axis = np.broadcast_to(q[:3], points.shape)
    turn = _cross_rows(axis, points) * 2
    return points + q[3] * turn + _cross_rows(axis, turn)


# --------------------------------------------------------------------------------------------
# STL (MeshSTLLoader)
# --------------------------------------------------------------------------------------------

_STL_HEADER = 80  # MeshSTLLoader's headerSize default
_STL_FACET = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _parse_stl(data: bytes) -> Mesh:
    """An STL file as SOFA's MeshSTLLoader reads it: ASCII when its first word is ``solid``, else
    binary (80-byte header, a little-endian facet count, 50 bytes per facet: the file size must be
    84 + 50 n). Vertices are merged by exact equality and numbered in order of first appearance;
    the binary reader drops degenerate triangles (two equal corners), the ASCII one keeps them, as
    SOFA's do. SOFA's per-facet normals are not kept (``normals`` is per vertex here)."""
    head = data[:256].lstrip()
    if head[:5] == b"solid" and (len(head) == 5 or head[5:6].isspace()):
        return _parse_stl_ascii(data.decode("latin-1"))
    if len(data) < _STL_HEADER + 4:
        raise MeshError(f"binary STL file of {len(data)} bytes: shorter than its 84-byte header")
    count = int(np.frombuffer(data, "<u4", 1, _STL_HEADER)[0])
    if len(data) != _STL_HEADER + 4 + 50 * count:
        raise MeshError(
            f"binary STL file of {len(data)} bytes, but its header announces {count} triangles "
            f"({_STL_HEADER + 4 + 50 * count} bytes); an ASCII STL file must start with 'solid'"
        )
    facets = np.frombuffer(data, _STL_FACET, count, _STL_HEADER + 4)
    corners = facets["corners"].astype(np.float64).reshape(-1, 3)
    positions, triangles = _merge_corners(corners)
    keep = (
        (triangles[:, 0] != triangles[:, 1])
        & (triangles[:, 1] != triangles[:, 2])
        & (triangles[:, 0] != triangles[:, 2])
    )
    notes = () if keep.all() else (f"{int((~keep).sum())} degenerate triangles dropped (as SOFA does)",)
    return Mesh(positions=positions, triangles=triangles[keep], notes=notes)


def _merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct corner positions in order of first appearance, and each triangle's indices."""
    if not len(corners):
        return np.zeros((0, 3)), _empty_cells(3)
    _, first, inverse = np.unique(corners, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # unique rows by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return corners[first[order]], rank[inverse.ravel()].reshape(-1, 3)


def _parse_stl_ascii(text: str) -> Mesh:
    corners: list[tuple[float, float, float]] = []
    in_facet = 0
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split()
        if not words:
            continue
        if words[0] == "vertex":
            if len(words) < 4:
                raise MeshError("'vertex' needs three coordinates", number)
            in_facet += 1
            if in_facet > 3:
                raise MeshError("a facet with more than three vertices (SOFA reads triangles)", number)
            corners.append(tuple(_to_float(w, number, "vertex coordinate") for w in words[1:4]))
        elif words[0] == "endfacet":
            if in_facet != 3:
                raise MeshError(f"a facet with {in_facet} vertices (MeshSTLLoader reads triangles)", number)
            in_facet = 0
        elif words[0] in ("endsolid", "end"):
            break
    positions, triangles = _merge_corners(np.asarray(corners, dtype=np.float64).reshape(-1, 3))
    return Mesh(positions=positions, triangles=triangles)
