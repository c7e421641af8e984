"""Generated C++ reads like hand-written code, and every change to it is a reviewable diff.

* Golden snapshots: the source generated for a few scenes (the hybrid pendulum, the liver, a beam
  with a sparse direct solver) is kept in tests/golden/. After an intended change to code
  generation, refresh them with ``SOFAC_UPDATE_GOLDEN=1 python -m pytest tests/test_generated_code.py``
  and review the diff.
* Warnings are errors: scenes are built with ``-Wall -Wextra -Werror`` (sofac.build), so every scene
  any test compiles is checked; here a sample of corpus scenes is compiled for syntax alone with the
  same flags, including scenes split over threads.
* No dead code: no empty functions, no ``(void)`` casts, no absolute paths.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest
from sofac import pipeline
from sofac.build import compiler as build

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "tests" / "golden"
SNAPSHOTS = {
    "hybrid_pendulum": REPO / "scenes" / "hybrid_pendulum.scn",
    "liver": REPO / "scenes" / "liver.scn",
    "beam_direct": GOLDEN / "beam_direct.scn",
}
# Corpus scenes covering mappings, projections, springs, FEM, shells, masses, assembled and direct
# systems, preconditioners, static, Newmark and variational solvers.
CORPUS_SAMPLE = [
    "Demos/mixedPendulum.scn",
    "Demos/simpleBoundaryConditions.scn",
    "Component/Mapping/NonLinear/DistanceMultiMapping.scn",
    "Component/Mapping/NonLinear/SquareDistanceMapping.scn",
    "Component/LinearSolver/Direct/FEMBAR_SparseLDLSolver.scn",
    "Component/LinearSystem/CompositeLinearSystem.scn",
    "Component/SolidMechanics/FEM/TriangularFEMForceFieldOptim.scn",
    "Component/Mass/MeshMatrixMass.scn",
    "Component/Mapping/NonLinear/RigidMapping-basic.scn",
    "Component/LinearSolver/Iterative/FEMBAR_MinResLinearSolver.scn",
    "Component/ODESolver/Backward/NewmarkImplicitSolver.scn",
    "Component/ODESolver/Backward/VariationalSymplecticSolver.scn",
]


def _source(path: Path, threads: int = 1) -> str:
    return pipeline.generate(pipeline.plan_file(path, threads=threads))


@pytest.mark.parametrize("name", sorted(SNAPSHOTS))
def test_golden_snapshot(name: str) -> None:
    source = _source(SNAPSHOTS[name])
    golden = GOLDEN / f"{name}.cpp"
    if os.environ.get("SOFAC_UPDATE_GOLDEN"):
        golden.write_text(source)
    assert golden.is_file(), f"{golden} is missing: run with SOFAC_UPDATE_GOLDEN=1 and review it"
    assert source == golden.read_text(), (
        f"the C++ generated for {SNAPSHOTS[name].name} changed: if intended, run "
        "SOFAC_UPDATE_GOLDEN=1 python -m pytest tests/test_generated_code.py and review the diff"
    )


@pytest.mark.parametrize("name", sorted(SNAPSHOTS))
def test_no_dead_code_and_no_absolute_paths(name: str) -> None:
    source = _source(SNAPSHOTS[name])
    assert "(void)" not in source
    assert not re.search(r"\)\s*\{\s*\}", source), "an empty function"
    assert str(REPO) not in source and "/work/" not in source


def _syntax_check(source: str, tmp_path: Path, name: str) -> None:
    path = tmp_path / f"{name}.cpp"
    path.write_text(source)
    includes = ["-I", str(REPO / "runtime"), "-isystem", str(build.eigen_include())]
    includes += ["-isystem", str(build.SUITESPARSE_INCLUDE)]
    flags = [f for f in build.SCENE_FLAGS if f not in ("-shared", "-fPIC")]
    command = [build.compiler(), *flags, "-fsyntax-only", "-fopenmp", *includes, str(path)]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]


def test_scenes_build_with_warnings_as_errors() -> None:
    assert {"-Wall", "-Wextra", "-Werror"} <= set(build.SCENE_FLAGS)
    assert "-w" not in build.SCENE_FLAGS


@pytest.mark.parametrize("scene", CORPUS_SAMPLE)
def test_corpus_sample_builds_without_warnings(scene: str, corpus_dir: Path, tmp_path: Path) -> None:
    path = corpus_dir / scene
    threads = 2 if scene.endswith("SparseLDLSolver.scn") else 1  # the threaded copies too
    _syntax_check(_source(path, threads=threads), tmp_path, path.stem)
