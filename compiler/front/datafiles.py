"""Where a scene's files are: the allowed data roots, and SOFA's lookup of a referenced file.

Kept apart from the parser (no XML here) because warm loads (``warm.py``) recompute the data roots
to tell whether a cached scene still reads the same files.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sofac.front.model import Scene


# --- data roots and file lookup ------------------------------------------------------------------


def real_path(path: Path) -> Path:
    """``path`` with symlinks and ``..`` resolved."""
    return Path(os.path.realpath(path))


def is_file(path: Path) -> bool:
    """Whether ``path`` is a regular file; False, not an exception, for a name the system cannot
    even look up (longer than its limit, 255 bytes a name on Linux: ENAMETOOLONG)."""
    try:
        return path.is_file()
    except OSError:
        return False


def _is_within(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def _auto_data_root(directory: Path) -> Path | None:
    """The nearest directory at or above ``directory`` holding ``Objects/`` or ``mesh/`` (a SOFA
    data tree, as in SOFA's ``share/`` + ``examples/``). The filesystem root is never used."""
    for candidate in (directory, *directory.parents):
        if candidate == Path(candidate.anchor):
            break
        if (candidate / "Objects").is_dir() or (candidate / "mesh").is_dir():
            return candidate
    return None


def _sofa_tree(directory: Path) -> Path | None:
    """The nearest directory above ``directory`` holding SOFA's ``share/mesh`` and ``examples/``."""
    for candidate in directory.parents:
        if candidate == Path(candidate.anchor):
            break
        if (candidate / "share" / "mesh").is_dir() and (candidate / "examples").is_dir():
            return candidate
    return None


def default_data_roots(scene_dir: Path, data_roots: Sequence[Path] = ()) -> list[Path]:
    """The ordered, de-duplicated allowed roots: the scene's directory, the explicit roots, the
    ``SOFAC_DATA_PATH`` entries, SOFA's own (``SOFA_DATA_PATH``, then ``$SOFA_ROOT/share`` and
    ``$SOFA_ROOT/examples``, as SOFA's DataRepository starts), then the auto-detected SOFA data root
    (with its ``share/`` when it is SOFA's ``examples/``). Only existing directories."""
    candidates: list[Path] = [Path(scene_dir), *(Path(r) for r in data_roots)]
    for variable in ("SOFAC_DATA_PATH", "SOFA_DATA_PATH"):
        env = os.environ.get(variable, "")
        candidates.extend(Path(entry) for entry in env.split(os.pathsep) if entry.strip())
    sofa_root = os.environ.get("SOFA_ROOT", "").strip()
    if sofa_root:
        candidates.extend((Path(sofa_root) / "share", Path(sofa_root) / "examples"))
    try:
        auto = _auto_data_root(real_path(Path(scene_dir)))
    except (OSError, ValueError, RuntimeError):
        auto = None
    if auto is not None:
        candidates.append(auto)
        if auto.name == "examples" and (auto.parent / "share" / "mesh").is_dir():
            candidates.append(auto.parent / "share")
    # Inside a SOFA tree (a plugin's applications/plugins/X/examples, or a folder of examples/ with
    # its own mesh/ such as Component/SceneUtility): SOFA's DataRepository still has share/ and examples/.
    tree = _sofa_tree(real_path(Path(scene_dir)))
    if tree is not None:
        candidates.extend((tree / "share", tree / "examples"))
    roots: list[Path] = []
    for candidate in candidates:
        try:
            real = real_path(candidate.expanduser())
        except (OSError, ValueError, RuntimeError):
            continue
        if real.is_dir() and real not in roots:
            roots.append(real)
    return roots


def add_data_folder(scene: Scene, folder: Path) -> str | None:
    """Append ``folder`` to the scene's data roots, as SOFA's AddDataRepository appends it to its
    DataRepository; what is wrong with it otherwise ("outside", "missing", "not a folder"). Only a
    folder inside an allowed root is probed: a scene cannot widen what sofac reads."""
    real = real_path(folder)
    if not any(_is_within(real, real_path(root)) for root in scene.data_roots):
        return "outside"
    if not real.exists():
        return "missing"
    if not real.is_dir():
        return "not a folder"
    if real not in scene.data_roots:
        scene.data_roots.append(real)
    return None


@dataclass(frozen=True)
class DataFileLookup:
    """Result of looking a referenced file up: the file found (its real path), the directories
    searched in order, and candidates refused because they lie outside every allowed root."""

    path: Path | None
    searched: tuple[Path, ...]
    refused: tuple[Path, ...]


def find_data_file(name: str, relative_to: Path, scene: Scene) -> DataFileLookup:
    """Locate ``name`` as SOFA does: relative to ``relative_to`` (the referencing file's directory)
    first, then in each data root. A candidate whose real path (symlinks resolved) is outside all
    allowed roots is refused, whether or not it exists (no probing outside the roots)."""
    relative_to = Path(relative_to)
    allowed = [real_path(r) for r in scene.data_roots] or [real_path(relative_to)]
    if not name or "\0" in name:
        return DataFileLookup(None, (), ())
    target = Path(name)
    bases = [] if target.is_absolute() else [relative_to, *(r for r in scene.data_roots if r != relative_to)]
    candidates = [target] if target.is_absolute() else [base / target for base in bases]
    refused: list[Path] = []
    for candidate in candidates:
        try:
            real = real_path(candidate)
        except (OSError, ValueError, RuntimeError):
            continue
        if not any(_is_within(real, root) for root in allowed):
            refused.append(candidate)
            continue
        found = is_file(real)
        scene.lookups.setdefault(real, found)  # what the result depends on (warm.py)
        if found:
            return DataFileLookup(real, tuple(bases), tuple(refused))
    return DataFileLookup(None, tuple(bases), tuple(refused))


def resolve_data_file(name: str, relative_to: Path, scene: Scene) -> Path | None:
    """The real path of a referenced file, or None if it is missing or outside the allowed roots
    (use :func:`find_data_file` to tell which: its ``refused`` is non-empty for E108)."""
    return find_data_file(name, relative_to, scene).path
