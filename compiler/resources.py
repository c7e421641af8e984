"""Where sofac's non-Python files are at run time: the C++ runtime, the templates, the bundled scenes,
and the cache folder (libraries, compiled templates, warm records).

In the repository they are top-level folders (``runtime/``, ``templates/``, ``scenes/``) next to the
package folder ``compiler/``. A built wheel carries them inside the package as ``sofac/_runtime``,
``sofac/_templates`` and ``sofac/_scenes`` (``setup.py`` copies them at build time). Both places are
looked up here, the packaged one first; nothing else should hard-code these paths.
"""

from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

CACHE_ENV = "SOFAC_CACHE_DIR"

# name -> (folder inside the installed package, folder at the repository root)
_LOCATIONS = {
    "runtime": ("_runtime", "runtime"),
    "templates": ("_templates", "templates"),
    "scenes": ("_scenes", "scenes"),
}


class ResourceNotFoundError(FileNotFoundError):
    """A folder sofac ships with is missing: the installation is incomplete."""


def _package_dir() -> Path:
    root = importlib.resources.files(__package__ or "sofac")
    # A package installed on a file system (wheel or editable) gives a real path; sofac does not
    # support running from a zip file, since the C++ runtime must be on disk for the compiler.
    if not isinstance(root, Path):
        return Path(__file__).resolve().parent
    return root


def _repo_root() -> Path | None:
    """The repository root when sofac runs from a checkout (an editable install), else None."""
    package = Path(__file__).resolve().parent
    root = package.parent
    if package.name == "compiler" and (root / "pyproject.toml").is_file():
        return root
    return None


def candidates(name: str) -> list[Path]:
    """The places where the resource folder ``name`` is looked for, in order."""
    packaged, repo = _LOCATIONS[name]
    places = [_package_dir() / packaged]
    root = _repo_root()
    if root is not None:
        places.append(root / repo)
    return places


def resource_dir(name: str) -> Path:
    """The folder of resource ``name`` ("runtime", "templates" or "scenes")."""
    places = candidates(name)
    for place in places:
        if place.is_dir():
            return place
    searched = ", ".join(str(p) for p in places)
    raise ResourceNotFoundError(
        f"sofac's {name} folder is missing (searched {searched}); reinstall sofac, or from a "
        "checkout run `python3 -m pip install -e .`"
    )


def runtime_dir() -> Path:
    """The header-only C++ runtime (its ``sofac/`` include folder is inside)."""
    return resource_dir("runtime")


def templates_dir() -> Path:
    """The Jinja2 templates of the generated C++."""
    return resource_dir("templates")


def scenes_dir() -> Path:
    """The scenes bundled with sofac."""
    return resource_dir("scenes")


def bundled_scenes() -> list[Path]:
    """Every bundled scene file (``*.scn``), sorted."""
    return sorted(p for p in scenes_dir().rglob("*.scn") if p.is_file())


def bundled_scene(name: str) -> Path:
    """The bundled scene ``name`` (e.g. ``"hybrid_pendulum.scn"`` or ``"hybrid_pendulum"``)."""
    root = scenes_dir().resolve()
    for candidate in (name, f"{name}.scn"):
        path = (root / candidate).resolve()
        if not path.is_relative_to(root):
            raise ValueError(f"bundled scene name {name!r} points outside the scenes folder")
        if path.is_file():
            return path
    known = ", ".join(str(p.relative_to(root)) for p in bundled_scenes()) or "(none)"
    raise FileNotFoundError(f"no bundled scene {name!r}; the bundled scenes are: {known}")


def cache_dir() -> Path:
    """The cache folder: $SOFAC_CACHE_DIR, else the user's cache folder (platformdirs)."""
    override = os.environ.get(CACHE_ENV)
    if override:
        return Path(override)
    import platformdirs  # only here: finding bundled folders needs no third-party package

    return Path(platformdirs.user_cache_dir("sofac"))
