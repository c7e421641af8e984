"""Build stage: compile C++ into shared libraries kept in a content-addressed cache.

The key of an entry hashes everything the binary depends on: the source, the runtime headers,
the compiler (its version line) and flags, and sofac's version. An entry is a folder holding the
library and a manifest written last with the library's SHA-256; an entry whose manifest is
missing or does not match its library (a killed build, a truncated file) is rebuilt, never
loaded. Builds take a per-key file lock and happen in a private folder that is renamed into
place, so concurrent builds of one scene are safe. A failed build is never cached: the
compiler's output is kept in a log file named in the error.

Two kinds of libraries are built: one per scene (the generated step, plain C symbols, Eigen and
the kernels only) and the host extension module (pybind11), once per installation.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sofac import __version__
from sofac.cache_errors import CacheNotWritable
from sofac.diagnostics import SofacError
from sofac.resources import cache_dir, resource_dir

COMPILER_ENV = "CXX"
# No fused multiply-adds: SOFA's reference results are computed without them (bit-exact CG).
SCENE_FLAGS = (
    "-std=c++17",
    "-O2",
    "-ffp-contract=off",
    "-shared",
    "-fPIC",
    "-fvisibility=hidden",
    "-DNDEBUG",
    # Generated code and the runtime build warning-free (tests/test_generated_code.py); the
    # third-party headers (Eigen, CHOLMOD) are system includes, whose warnings are theirs.
    "-Wall",
    "-Wextra",
    "-Werror",
)
# Scenes with much data (a step doing real work) are compiled with -O3: inlining, loop unswitching
# and complete unrolling of the element kernels make the FEM steps about 2x faster. Small scenes
# keep -O2, which compiles 1-2 s faster. Both give the same numbers, bit for bit (no fast-math,
# no contraction): only the speed differs. $SOFAC_OPT=O2 or O3 forces one level.
OPT_ENV = "SOFAC_OPT"
LARGE_SCENE_NUMBERS = 10_000  # numbers in the instance's buffers from which a scene counts as large
LARGE_SCENE_FLAGS = tuple("-O3" if flag == "-O2" else flag for flag in SCENE_FLAGS)


def scene_flags(numbers: int) -> tuple[str, ...]:
    """The flags for a scene whose buffers hold ``numbers`` numbers (see LARGE_SCENE_NUMBERS)."""
    forced = os.environ.get(OPT_ENV, "").strip().upper()
    if forced in ("O2", "O3"):
        flags = LARGE_SCENE_FLAGS if forced == "O3" else SCENE_FLAGS
    else:
        flags = LARGE_SCENE_FLAGS if numbers >= LARGE_SCENE_NUMBERS else SCENE_FLAGS
    level = vector_level()
    return flags if level is None else (*flags, f"-DSOFAC_VECTOR_LEVEL={level}")


@functools.cache
def vector_level() -> int | None:
    """The widest vector copy of the runtime's kernels this processor runs (2: AVX-512 F+VL, 1:
    AVX2, 0: neither), read from /proc/cpuinfo on x86-64 Linux; None elsewhere (the kernels then
    ask the processor at run time). Only that copy is compiled into a scene, and being a flag, the
    level is part of the cache key: a cache shared with another processor builds its own."""
    if platform.machine() not in ("x86_64", "AMD64"):
        return None
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return None
    lines = [line for line in text.splitlines() if line.startswith("flags")]
    if not lines:
        return None
    flags = lines[0].split(":", 1)[1].split()
    if "avx512f" in flags and "avx512vl" in flags:
        return 2
    return 1 if "avx2" in flags else 0


EIGEN_CANDIDATES = ("/usr/include/eigen3", "/usr/local/include/eigen3", "/opt/homebrew/include/eigen3")


class BuildError(SofacError):
    """The C++ compiler failed or is missing; ``log`` is the file with its full output."""

    def __init__(self, message: str, log: Path | None = None) -> None:
        super().__init__(message)
        self.log = log


@dataclass(frozen=True)
class Built:
    library: Path
    key: str
    cached: bool  # True when taken from the cache
    seconds: float  # compile time (0 for a cache hit)


def compiler() -> str:
    return os.environ.get(COMPILER_ENV) or shutil.which("g++") or shutil.which("c++") or "g++"


@functools.lru_cache(maxsize=4)
def _compiler_identity(command: str) -> str:
    import subprocess  # only a key computed afresh runs the compiler (a warm load does not)

    try:
        result = subprocess.run(
            [command, "--version"], capture_output=True, text=True, timeout=60, check=False
        )
    except (OSError, subprocess.TimeoutExpired) as error:
        raise BuildError(
            f"no C++ compiler: {command!r} cannot be run ({error}); install g++ "
            "(bash scripts/setup.sh does) or set CXX"
        ) from None
    return result.stdout.splitlines()[0] if result.stdout else command


def eigen_include() -> Path:
    for candidate in EIGEN_CANDIDATES:
        if (Path(candidate) / "Eigen" / "Dense").is_file():
            return Path(candidate)
    raise BuildError("Eigen is not installed: run `bash scripts/setup.sh` (apt-get install libeigen3-dev)")


def _runtime_digest() -> str:
    digest = hashlib.sha256()
    root = resource_dir("runtime")
    for path in sorted(root.rglob("*")):
        if path.is_file():
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def valid_entry(entry: Path, key: str, name: str) -> bool:
    try:
        manifest = json.loads((entry / "manifest.json").read_text())
        return manifest.get("key") == key and manifest.get("sha256") == _sha256(entry / name)
    except (OSError, ValueError):
        return False


def build(
    source: str,
    *,
    kind: str,
    name: str,
    flags: tuple[str, ...],
    includes: tuple[Path, ...],
    libraries: tuple[str, ...] = (),
    announce: Callable[[], None] | None = None,
) -> Built:
    """Compile ``source`` into ``name`` in the cache (or reuse a valid entry, which needs no write);
    ``announce`` is called just before the compiler runs. Raises CacheNotWritable when the cache
    folder cannot take the build."""
    try:
        return _build(
            source,
            kind=kind,
            name=name,
            flags=flags,
            includes=includes,
            libraries=libraries,
            announce=announce,
        )
    except OSError as error:  # the compiler's own failures are BuildErrors: this is the folder
        raise CacheNotWritable(cache_dir(), error) from None


def _build(
    source: str,
    *,
    kind: str,
    name: str,
    flags: tuple[str, ...],
    includes: tuple[Path, ...],
    libraries: tuple[str, ...] = (),
    announce: Callable[[], None] | None = None,
) -> Built:
    command = compiler()
    identity = {
        "source": hashlib.sha256(source.encode()).hexdigest(),
        "runtime": _runtime_digest(),
        "compiler": _compiler_identity(command),
        "flags": list(flags),
        "includes": [str(p) for p in includes],
        "libraries": list(libraries),
        "sofac": __version__,
    }
    key = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()
    root = cache_dir() / kind
    entry = root / key[:2] / key
    if valid_entry(entry, key, name):
        return Built(entry / name, key, True, 0.0)
    import subprocess

    import filelock  # only a build takes the lock: a cached entry loads without importing it
    from sofac.build import guard as build_guard

    (root / "locks").mkdir(parents=True, exist_ok=True)
    with filelock.FileLock(str(root / "locks" / f"{key}.lock"), timeout=600):
        if valid_entry(entry, key, name):  # built by another process meanwhile
            return Built(entry / name, key, True, 0.0)
        started = time.perf_counter()
        _remove_stale_builds(root, key)
        if announce is not None:
            announce()
        staging = Path(tempfile.mkdtemp(prefix=f"build-{key[:16]}-", dir=root))
        try:
            (staging / "source.cpp").write_text(source)
            arguments = [command, *flags, *(f"-I{p}" for p in includes), "source.cpp", "-o", name, *libraries]
            try:
                result = build_guard.run(arguments, cwd=staging, timeout=BUILD_TIMEOUT)
            except (OSError, subprocess.TimeoutExpired) as error:
                raise BuildError(f"the C++ compiler could not run: {error}") from None
            if result.returncode != 0 and "No space left on device" in result.stderr:
                raise OSError(errno.ENOSPC, "No space left on device", str(staging))
            if result.returncode != 0:
                log = root / "logs" / f"{key}.log"
                log.parent.mkdir(parents=True, exist_ok=True)
                log.write_text(" ".join(arguments) + "\n\n" + result.stdout + result.stderr)
                first = next((line for line in result.stderr.splitlines() if "error" in line), "")
                raise BuildError(f"C++ compilation failed: {first.strip()} (full output: {log})", log)
            manifest = {"key": key, "sha256": _sha256(staging / name), **identity}
            (staging / "manifest.json").write_text(json.dumps(manifest, indent=1))
            if entry.exists():
                shutil.rmtree(entry)  # a stale or corrupt entry
            entry.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging, entry)
        finally:
            if staging.exists():
                shutil.rmtree(staging, ignore_errors=True)
        return Built(entry / name, key, False, time.perf_counter() - started)


BUILD_TIMEOUT = 900.0  # seconds a compiler run may take


def _remove_stale_builds(root: Path, key: str) -> None:
    """Private build folders left by a build that was killed: those of ``key`` (whose lock this
    process holds, so no one else is building it), and any older than two build timeouts."""
    now = time.time()
    for folder in root.glob("build-*"):
        try:
            old = now - folder.stat().st_mtime > 2 * BUILD_TIMEOUT
        except OSError:
            continue  # removed meanwhile
        if old or folder.name.startswith(f"build-{key[:16]}-"):
            shutil.rmtree(folder, ignore_errors=True)


SUITESPARSE_INCLUDE = Path("/usr/include/suitesparse")


def build_scene(source: str, *, direct_solver: bool = False, numbers: int = 0, openmp: bool = False) -> Built:
    """A generated scene's library (linked with CHOLMOD when it uses a sparse direct solver, with
    OpenMP when it has element loops split over threads); ``numbers``, the size of its data, picks
    the optimisation level (scene_flags)."""
    includes: tuple[Path, ...] = (resource_dir("runtime"),)
    system: tuple[str, ...] = ("-isystem", str(eigen_include()))
    libraries: tuple[str, ...] = ()
    if direct_solver:
        if not (SUITESPARSE_INCLUDE / "cholmod.h").is_file():
            raise BuildError(
                "SuiteSparse is not installed: run `bash scripts/setup.sh` "
                "(apt-get install libsuitesparse-dev)"
            )
        system += ("-isystem", str(SUITESPARSE_INCLUDE))
        # LAPACK and BLAS: direct.h's supernodal Cholesky calls them (the ones CHOLMOD is linked with)
        libraries = ("-lcholmod", "-llapack", "-lblas")
    return build(
        source,
        kind="scenes",
        name="scene.so",
        flags=scene_flags(numbers) + (("-fopenmp",) if openmp else ()) + system,
        includes=includes,
        libraries=libraries,
    )


def build_host(*, quiet: bool = False) -> Built:
    """The pybind11 host module, compiled once per installation (per compiler and Python; setup.sh
    builds it). Its compilation takes a while, so it is announced on stderr unless ``quiet``."""
    import sysconfig

    import pybind11

    source = (resource_dir("runtime") / "host" / "host.cpp").read_text()
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
    includes = (Path(pybind11.get_include()), Path(sysconfig.get_paths()["include"]))
    flags = ("-std=c++17", "-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-DNDEBUG", "-ldl")
    def announce() -> None:
        if not quiet:
            print(
                "sofac: building the Python bridge to compiled scenes (once per installation and "
                f"compiler, 10-30 s) in {cache_dir() / 'host'}; `bash scripts/setup.sh` builds it ahead",
                file=sys.stderr,
                flush=True,
            )

    return build(
        source, kind="host", name=f"_sofac_host{suffix}", flags=flags, includes=includes, announce=announce
    )
