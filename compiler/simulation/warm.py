"""Warm loads: a scene loaded before is instantiated from the cache without being parsed,
checked, planned or generated again (as ccache's direct mode skips the preprocessor).

A record is keyed by the scene's path, the load options, what else could change its compilation
(the environment variables sofac reads, the data roots, the compiler, this processor's vector
level, sofac's own files) and Python's version. It lists every file the front end depended on:
those it read (the scene, its includes, meshes) with their SHA-256, and the candidates it tried
before finding a referenced file, which must still be absent. It is used only when all of these
still hold and its library is a valid entry of the build cache; anything else (an edit, a new or
missing file, a damaged record) is a miss, and the scene is compiled as usual.

A record is data only (JSON and arrays in one ``.npz``, read with ``allow_pickle=False``): it
holds the run spec (``runspec.py``), so that loading it runs no code from the cache.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from sofac import __version__
from sofac.build import compiler as build
from sofac.diagnostics import Diagnostic
from sofac.front.datafiles import default_data_roots, is_file
from sofac.param_rules import ParamRule
from sofac.resources import cache_dir, resource_dir
from sofac.simulation.runspec import BufferSpec, ContactSpec, EnergyFileSpec, RunSpec, SolverSpec, StateSpec

# 2: the scene's warnings are kept, so that a warm load issues them too; 3: the host module's
# cache entry is kept, so that a warm load does not compute its key (which runs the compiler)
FORMAT = 4
# Environment variables that change what a scene compiles to (see build.py and datafiles.py).
ENVIRONMENT = (build.COMPILER_ENV, build.OPT_ENV, "SOFAC_DATA_PATH")


@dataclasses.dataclass(frozen=True)
class Record:
    spec: RunSpec
    built: build.Built
    warnings: tuple[Diagnostic, ...] = ()
    host: build.Built | None = None  # the host module's cache entry, if still valid


@functools.cache
def _installation() -> str:
    """sofac's own files (Python, templates, runtime headers) by name, size and modification time,
    and the compiler binary: an edit to any of them makes every record a miss."""
    stamp = hashlib.sha256()
    package = Path(__file__).resolve().parents[1]
    for root in (package, resource_dir("templates"), resource_dir("runtime")):
        for path in _stamped_files(str(root)):
            info = os.stat(path)
            stamp.update(f"{path}\0{info.st_size}\0{info.st_mtime_ns}\n".encode())
    compiler = shutil.which(build.compiler())
    if compiler is not None:
        info = Path(compiler).resolve().stat()
        stamp.update(f"{compiler}\0{info.st_size}\0{info.st_mtime_ns}\n".encode())
    return stamp.hexdigest()


_STAMPED = (".py", ".json", ".j2", ".h", ".cpp")


def _stamped_files(root: str) -> list[str]:
    """The files under ``root`` that _installation() stamps, in path order. os.scandir, not
    Path.rglob: every warm load walks sofac's ~200 files, and pathlib's walk costs several ms."""
    found: list[str] = []
    pending = [root]
    while pending:
        folder = pending.pop()
        with os.scandir(folder) as entries:
            for entry in entries:
                if entry.is_dir():
                    if entry.name != "__pycache__":
                        pending.append(entry.path)
                elif entry.name.endswith(_STAMPED):
                    found.append(entry.path)
    return sorted(found, key=lambda path: path.split(os.sep))


def _key(path: Path, options: dict[str, Any]) -> str:
    identity = {
        "format": FORMAT,
        "path": str(path),
        "options": options,
        "roots": [str(r) for r in default_data_roots(path.parent, options["data_roots"])],
        "environment": {name: os.environ.get(name, "") for name in ENVIRONMENT},
        "vector_level": build.vector_level(),
        "installation": _installation(),
        "sofac": __version__,
        "python": sys.version,
        "numpy": np.__version__,
    }
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()


def _file(key: str) -> Path:
    return cache_dir() / "loads" / key[:2] / f"{key}.npz"


def _sha256(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _unchanged(path: Path, digest: str | None) -> bool:
    """A file read before still has its content; a candidate absent before is still absent."""
    return _sha256(path) == digest if digest is not None else not is_file(path)


def _options(
    data_roots: Sequence[Path], prune: bool, rigid_model: str, threads: int, interactive: bool = False
) -> dict[str, Any]:
    return {
        "data_roots": [str(Path(r)) for r in data_roots],
        "prune": prune,
        "rigid_model": rigid_model,
        "threads": threads,
        "interactive": interactive,
    }


def lookup(path: str | Path, **options: Any) -> Record | None:
    """The record of ``path`` loaded with ``options`` (load()'s keywords), if it is still valid."""
    try:
        real = Path(os.path.realpath(path))
        with np.load(_file(_key(real, _options(**options))), allow_pickle=False) as stored:
            meta = json.loads(stored["meta"].tobytes())
            if meta["format"] != FORMAT:
                return None
            if not all(_unchanged(Path(p), digest) for p, digest in meta["dependencies"]):
                return None
            library = Path(meta["library"])
            if not build.valid_entry(library.parent, meta["build_key"], library.name):
                return None
            arrays = [stored[f"b{i}"] for i in range(len(meta["spec"]["buffers"]))]
        return Record(
            _spec_from_json(meta["spec"], arrays),
            build.Built(library, meta["build_key"], True, 0.0),
            _warnings_from_json(meta["warnings"]),
            _host(meta["host"]),
        )
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        # No record, or a damaged one: a miss
        return None


def _warnings_from_json(items: list[dict[str, Any]]) -> tuple[Diagnostic, ...]:
    if not items:
        return ()  # most scenes: no need to import the warnings module
    from sofac import scene_warnings

    return scene_warnings.from_json(items)


def _host(entry: list[str] | None) -> build.Built | None:
    """The host module's cache entry a record names (its library and key), if still valid. The
    record's key covers what the host depends on (sofac's files, the compiler binary, Python);
    when the entry is gone, the host is found or built as usual."""
    if entry is None:
        return None
    library, key = Path(entry[0]), entry[1]
    if not build.valid_entry(library.parent, key, library.name):
        return None
    return build.Built(library, key, True, 0.0)


def store(
    path: str | Path,
    spec: RunSpec,
    built: build.Built,
    checked: Any,
    *,
    warnings: Sequence[Diagnostic] = (),
    **options: Any,
) -> None:
    """Record a scene just compiled; a failure to write only costs the next load its speed."""
    scene = checked.scene
    dependencies: list[tuple[str, str | None]] = [(str(p), _sha256(p)) for p in scene.sources]
    dependencies += [(str(p), _sha256(p) if found else None) for p, found in scene.lookups.items()]
    if any(digest is None for _, digest in dependencies[: len(scene.sources)]):
        return  # a source could not be read back: nothing to check a later load against
    from sofac import scene_warnings
    from sofac.simulation import loader

    host = loader.host_built()
    meta = {
        "format": FORMAT,
        "library": str(built.library),
        "build_key": built.key,
        "dependencies": dependencies,
        "spec": _spec_to_json(spec),
        "warnings": scene_warnings.to_json(warnings),
        "host": [str(host.library), host.key] if host is not None else None,
    }
    arrays = {f"b{i}": b.initial for i, b in enumerate(spec.buffers)}
    target = _file(_key(Path(os.path.realpath(path)), _options(**options)))
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        handle, staging = tempfile.mkstemp(dir=target.parent, suffix=".npz")
    except OSError:
        return
    try:
        with os.fdopen(handle, "wb") as out:
            np.savez(out, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), **arrays)
        os.replace(staging, target)  # readers see the old record or the whole new one
    except OSError:
        Path(staging).unlink(missing_ok=True)


def _spec_to_json(spec: RunSpec) -> dict[str, Any]:
    return {
        "buffers": [[b.key, b.kind, b.role] for b in spec.buffers],
        "states": [dataclasses.asdict(s) for s in spec.states],
        "solvers": [dataclasses.asdict(s) for s in spec.solvers],
        "energy_files": [dataclasses.asdict(f) for f in spec.energy_files],
        "contact": dataclasses.asdict(spec.contact) if spec.contact is not None else None,
        "init_only": sorted(spec.init_only),
        "pruned": spec.pruned,
        "threads": spec.threads,
        "rigid_model": spec.rigid_model,
        "interactive": spec.interactive,
        "rules": {key: dataclasses.asdict(rule) for key, rule in spec.rules.items()},
        "contact_reports": [list(r) for r in spec.contact_reports],
        "growable": list(spec.growable),
    }


def _spec_from_json(meta: dict[str, Any], arrays: list[np.ndarray]) -> RunSpec:
    contact = meta["contact"]
    return RunSpec(
        tuple(
            BufferSpec(key, kind, role, array)
            for (key, kind, role), array in zip(meta["buffers"], arrays, strict=True)
        ),
        tuple(StateSpec(**s) for s in meta["states"]),
        tuple(SolverSpec(**s) for s in meta["solvers"]),
        tuple(EnergyFileSpec(**f) for f in meta["energy_files"]),
        ContactSpec(tuple(contact["models"]), contact["pairs"], contact["touching"]) if contact else None,
        frozenset(meta["init_only"]),
        dict(meta["pruned"]),
        int(meta["threads"]),
        str(meta["rigid_model"]),
        bool(meta["interactive"]),
        {key: ParamRule(**rule) for key, rule in meta["rules"].items()},
        contact_reports=tuple((str(origin), int(i)) for origin, i in meta["contact_reports"]),
        growable=tuple(int(i) for i in meta["growable"]),
    )
