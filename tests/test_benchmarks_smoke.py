"""The performance benchmarks (benchmarks/workloads.py, constraints.py) still run: tiny sizes, no timing
assertions."""

from __future__ import annotations

import importlib
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _benchmark(name: str) -> Iterator[ModuleType]:
    """A script of benchmarks/ imported as a module (the folder on sys.path meanwhile)."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        yield importlib.import_module(name)
    finally:
        sys.path.remove(str(BENCHMARKS))


@pytest.fixture(scope="module")
def workloads() -> Iterator[ModuleType]:
    yield from _benchmark("workloads")


def test_cloth_matches_the_workload_definition(workloads: ModuleType) -> None:
    scenegen = workloads.scenegen
    n = 100
    cloth = scenegen.cloth(n)
    assert len(cloth.positions) == n * n
    assert len(cloth.springs) == 2 * n * (n - 1) + 2 * (n - 1) ** 2 == 39_402
    assert cloth.fixed == (0, n - 1)
    assert cloth.positions[n - 1] == (1.0, 0.0, 0.0)
    text = scenegen.cloth_scene(3, implicit=True)
    assert 'iterations="25" tolerance="0" threshold="0"' in text
    assert "0 1 1000.0 0 0.5" in text  # "i j stiffness damping rest-length"


def test_generated_scenes_check_clean(workloads: ModuleType, tmp_path: Path) -> None:
    from sofac.cli.main import main as sofac_main

    beams = workloads.scenegen.write_beam(tmp_path, 3, 3, 4).values()
    spheres = tmp_path / "w5_n2.scn"
    spheres.write_text(workloads.scenegen.sphere_scene(2))
    scenes = [*workloads.scenegen.write_cloth(tmp_path, 4), *beams, spheres]
    assert sofac_main(["check", "--quiet", *map(str, scenes)]) == 0


@pytest.mark.skipif(shutil.which("g++") is None, reason="needs g++")
def test_cloth_workloads_run_and_agree(workloads: ModuleType, tmp_path: Path) -> None:
    setup = workloads.Setup(n=5, w1_steps=3, w2_steps=3, batches=2, check_steps=3, workdir=tmp_path)
    rows, checks = workloads.run(["w1", "w2"], setup, lambda _: None)
    implementations = {(r.workload, r.implementation) for r in rows}
    assert {("w1", "sofac"), ("w1", "hand-written C++"), ("w1", "NumPy")} <= implementations
    assert {("w2", "sofac"), ("w2", "hand-written C++")} <= implementations
    assert all(r.ms > 0 for r in rows)
    # the same algorithm gives the same positions to rounding (few steps: W2 amplifies rounding)
    for workload in ("w1", "w2"):
        short = {k: v for k, v in checks[workload].items() if k.endswith("after 3 steps")}
        assert short and all(v < 1e-9 for v in short.values()), checks[workload]
    cells = workloads.table(rows, sofa=False)
    assert cells[0][:3] == ["workload", "implementation", "ms/step"]
    assert any(c[1] == "sofac" and c[0] == "w1" and "hand-written" in c[6] for c in cells)
    assert workloads.render(cells, markdown=True).startswith("| workload |")


def test_beam_mesh_matches_the_workload_definition(workloads: ModuleType) -> None:
    beam = workloads.scenegen.beam()
    assert len(beam.positions) == 10 * 10 * 50
    assert len(beam.tetrahedra) == 6 * 9 * 9 * 49 == 23_814
    assert beam.positions[-1] == (1.0, 1.0, 5.0)
    assert len(beam.fixed) == 100 and all(beam.positions[i][2] == 0.0 for i in beam.fixed)
    # Hexa2TetraTopologicalMapping's first cell, corners 0 1 11 10 100 101 111 110: (0, 5, 1, 6)...
    assert beam.tetrahedra[:2] == [(0, 101, 1, 111), (0, 1, 10, 111)]
    # the 6 tetrahedra fill each cell: their volumes sum to the cell's
    points = np.array(beam.positions)
    corners = points[np.array(beam.tetrahedra[:6])]
    edges = corners[:, 1:] - corners[:, :1]
    volume = np.abs(np.linalg.det(edges)).sum() / 6
    assert volume == pytest.approx((1 / 9) * (1 / 9) * (5 / 49))


@pytest.mark.skipif(shutil.which("g++") is None, reason="needs g++")
def test_beam_workloads_run_and_agree(workloads: ModuleType, tmp_path: Path) -> None:
    from sofac.build.compiler import SUITESPARSE_INCLUDE

    if not (SUITESPARSE_INCLUDE / "cholmod.h").is_file():
        pytest.skip("needs SuiteSparse (CHOLMOD)")
    setup = workloads.Setup(w3_steps=3, ldl_steps=3, batches=2, beam_grid=(3, 3, 5), workdir=tmp_path)
    rows, checks = workloads.run(["w3", "w3asm", "w3ldl"], setup, lambda _: None)
    implementations = {(r.workload, r.implementation) for r in rows}
    assert ("w3asm", "sofac (matrix-free CG)") in implementations
    for workload in ("w3", "w3asm", "w3ldl"):
        assert {(workload, "sofac"), (workload, "hand-written C++")} <= implementations
    if workloads.have_scipy():
        assert {("w3", "SciPy"), ("w3ldl", "SciPy")} <= implementations
    scipy_checks = 1 if workloads.have_scipy() else 0
    # the same physics: the hand-written loops' and SciPy's tip displacement is sofac's to rounding
    # (~1e-13) with the direct solve; 25 CG iterations amplify the rounding differences of their
    # other formulas by the system's conditioning (~1e-8 on this small grid)
    assert len(checks["w3ldl"]) == 2 + scipy_checks, checks
    assert all(v < 1e-10 for v in checks["w3ldl"].values()), checks
    assert len(checks["w3"]) == 4 + 2 * scipy_checks, checks
    assert all(v < 1e-6 for v in checks["w3"].values()), checks
    assert len(checks["w3asm"]) == 2 and all(v < 1e-6 for v in checks["w3asm"].values()), checks
    assert all(r.ms > 0 for r in rows)
    cells = workloads.table(rows, sofa=False)
    hand = {c[0]: c[4] for c in cells if c[1] == "sofac"}
    assert hand["w3"] != "-" and hand["w3asm"] != "-" and hand["w3ldl"] != "-"


def test_sphere_floor_matches_the_workload_definition(workloads: ModuleType) -> None:
    scenegen = workloads.scenegen
    spheres = scenegen.spheres(4)
    assert len(spheres.positions) == 16
    assert len(spheres.triangles) == 2 * scenegen.W5_FLOOR_SQUARES**2
    assert all(y == 0.0 for _x, y, _z in spheres.floor)
    # every sphere starts out of contact (no initial penetration) and over the floor's interior
    reach = scenegen.W5_RADIUS + scenegen.W5_CONTACT
    assert all(y > reach and 0.05 < x < 0.95 and 0.05 < z < 0.95 for x, y, z in spheres.positions)
    # ks = k1 k2 / (contactDistance + r) = 1 * 0.5 / 0.005; rest: ks (0.005 - h) = 0.01 * 9.81
    assert scenegen.w5_contact_stiffness() == pytest.approx(100.0)
    assert scenegen.w5_rest_height() == pytest.approx(0.005 - 0.0981 / 100.0)


@pytest.mark.skipif(shutil.which("g++") is None, reason="needs g++")
def test_sphere_floor_workload_runs_agrees_and_rests(workloads: ModuleType, tmp_path: Path) -> None:
    # 1540 steps of 1 ms: the damped spheres (decay rate c / 2m = 10 / s in contact) are at rest
    setup = workloads.Setup(w5_steps=700, w5_sides=(3,), batches=2, workdir=tmp_path)
    rows, checks = workloads.run(["w5"], setup, lambda _: None)
    assert {(r.workload, r.implementation) for r in rows} == {("w5-9", "sofac"), ("w5-9", "hand-written C++")}
    assert all(r.ms > 0 for r in rows)
    found = checks["w5-9"]
    assert len(found) == 3, found
    # the same algorithm gives the same positions to rounding
    assert all(v < 1e-12 for k, v in found.items() if k.startswith("sofac vs hand-written")), found
    # both rest where ks (contactDistance + r - h) = m g, h = 4.019 mm, to 1e-8 m
    assert all(v < 1e-8 for k, v in found.items() if k.startswith("rest height")), found
    cells = workloads.table(rows, sofa=False)
    assert next(c for c in cells if c[:2] == ["w5-9", "hand-written C++"])[4] == "1.00"


@pytest.fixture(scope="module")
def constraints() -> Iterator[ModuleType]:
    yield from _benchmark("constraints")


@pytest.mark.skipif(shutil.which("g++") is None, reason="needs g++")
def test_constraint_benchmark_splits_the_step(constraints: ModuleType, tmp_path: Path) -> None:
    from sofac.plan.ir import CONSTRAINT_REPORT_FIELDS

    path = tmp_path / "particles.scn"
    path.write_text(constraints.particles_scene(2, "bgs"))
    split = constraints.scene_split(path, steps=5, repeat=1)
    assert split.rows == 12.0  # four particles resting on the floor from the first step, 3 rows each
    assert split.iterations >= 1
    assert {f"{part}_seconds" for part in split.parts} <= set(CONSTRAINT_REPORT_FIELDS)
    assert set(split.parts) == set(constraints.PARTS)
    # every part of the step is timed, inside the step's wall time
    assert all(seconds > 0 for seconds in split.parts.values()), split.parts
    assert sum(split.parts.values()) <= split.total
    assert split.rest >= 0
    table = constraints.split_table(["particles"], [split], markdown=True)
    assert table.startswith("| scene | rows/step | ms/step | detection | free motion | rows (J) |")


def test_constraint_benchmark_fits_and_plots(constraints: ModuleType, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    parts = dict.fromkeys(constraints.PARTS, 0.1)
    # the solve grows as rows^2, the W build as rows: the fitted exponents say so
    splits = [
        constraints.Split(1 + r * r * 1e-6, {**parts, "solve": r * r * 1e-6, "compliance": r * 1e-3}, rows=r)
        for r in (12.0, 120.0, 1200.0)
    ]
    exponents = constraints.fits({"bgs": splits}, fit_from=100)
    assert exponents["bgs"]["solve"] == pytest.approx(2.0)
    assert exponents["bgs"]["compliance"] == pytest.approx(1.0)
    plot = tmp_path / "rows.png"
    constraints.plot({"bgs": splits}, exponents, plot)
    assert plot.read_bytes().startswith(b"\x89PNG")
