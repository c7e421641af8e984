"""Kernel-level tests: a small C++ shim compiled against runtime/sofac, loaded with ctypes.

Flags as the generated scenes use them where numbers matter: C++17, no fused multiply-adds
(-ffp-contract=off, as SOFA's x86-64 reference build), warnings as errors.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess

import numpy as np
import pytest
from sofac.build.compiler import SUITESPARSE_INCLUDE, eigen_include
from sofac.resources import resource_dir

D = ctypes.POINTER(ctypes.c_double)
I64 = ctypes.POINTER(ctypes.c_int64)


def doubles(a: np.ndarray) -> ctypes._Pointer:
    """A contiguous float64 array as a ``double*``."""
    assert a.dtype == np.float64 and a.flags.c_contiguous
    return a.ctypes.data_as(D)


def indices(a: np.ndarray) -> ctypes._Pointer:
    """A contiguous int64 array as an ``Index*``."""
    assert a.dtype == np.int64 and a.flags.c_contiguous
    return a.ctypes.data_as(I64)


def build_shim(
    tmp_path_factory: pytest.TempPathFactory,
    name: str,
    source: str,
    *,
    optimize: str = "-O2",
    cholmod: bool = False,
) -> ctypes.CDLL:
    """Compile ``source`` into a shared library in a fresh folder and load it (skips without g++,
    or without SuiteSparse when ``cholmod``)."""
    compiler = shutil.which("g++")
    if compiler is None:
        pytest.skip("g++ is not installed")
    if cholmod and not (SUITESPARSE_INCLUDE / "cholmod.h").is_file():
        pytest.skip("SuiteSparse is not installed")
    folder = tmp_path_factory.mktemp(name)
    (folder / "shim.cpp").write_text(source)
    command = [
        compiler,
        "-std=c++17",
        optimize,
        "-ffp-contract=off",
        "-shared",
        "-fPIC",
        "-fvisibility=hidden",
    ]
    command += ["-Wall", "-Werror", f"-I{resource_dir('runtime')}", f"-I{eigen_include()}"]
    if cholmod:
        command.append(f"-I{SUITESPARSE_INCLUDE}")
    command += ["shim.cpp", "-o", "shim.so", *(["-lcholmod", "-llapack", "-lblas"] if cholmod else [])]
    result = subprocess.run(command, cwd=folder, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return ctypes.CDLL(str(folder / "shim.so"))
