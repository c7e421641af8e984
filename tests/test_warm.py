"""Warm loads (sofac/warm.py): a scene loaded before is instantiated from its record without the
front end, and any change it depends on makes the record a miss."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.resources import bundled_scene
from sofac.simulation import warm

STATE = "/Liver/dofs"


def liver(folder: Path, mesh_folder: Path | None = None) -> Path:
    """The bundled liver, copied to ``folder`` (its volume mesh in ``mesh_folder`` if given)."""
    folder.mkdir(parents=True, exist_ok=True)
    source = bundled_scene("liver.scn").parent
    shutil.copy(source / "liver.scn", folder)
    shutil.copy(source / "liver-surface.obj", folder)
    shutil.copy(source / "liver.msh", mesh_folder or folder)
    return folder / "liver.scn"


def shifted_mesh(original: Path, target: Path, dx: float) -> None:
    """``original`` (Gmsh 2.2 ASCII) with every node moved by ``dx`` along x."""
    head, nodes, tail = re.split(r"(?<=\$Nodes\n)|(?=\$EndNodes)", original.read_text())
    lines = nodes.splitlines()
    moved = [lines[0]]
    for line in lines[1:]:
        index, x, y, z = line.split()
        moved.append(f"{index} {float(x) + dx!r} {y} {z}")
    target.write_text(head + "\n".join(moved) + "\n" + tail)


def run(path: Path, steps: int = 5, **options: object) -> tuple[sofac.Simulation, np.ndarray]:
    sim = sofac.load(path, **options)
    sim.step(steps)
    return sim, sim[STATE].position.copy()


def test_a_second_load_is_warm_and_steps_the_same(tmp_path: Path) -> None:
    path = liver(tmp_path)
    assert warm.lookup(path, data_roots=(), prune=True, rigid_model="sofa", threads=1) is None
    cold, cold_x = run(path)
    warm_sim, warm_x = run(path)
    assert not cold.compiled.warm and warm_sim.compiled.warm
    assert np.array_equal(cold_x, warm_x)
    assert warm_sim.compiled.built.library == cold.compiled.built.library
    # What the run spec leaves out is computed again on demand, the same as the cold load's.
    assert [b.key for b in warm_sim.plan.buffers] == [b.key for b in cold.plan.buffers]
    assert warm_sim.compiled.source == cold.compiled.source
    # Tuning and recompiling work on a warm instance as on a cold one.
    warm_sim.param("/.gravity")[:] = (0.0, -9.81, 0.0)
    cold.param("/.gravity")[:] = (0.0, -9.81, 0.0)
    warm_sim.step(3)
    cold.step(3)
    assert np.array_equal(warm_sim[STATE].position, cold[STATE].position)


def test_the_warm_path_imports_no_front_end(tmp_path: Path) -> None:
    path = liver(tmp_path)
    sofac.load(path)  # writes the record
    # Nor what only a compile, a build, a warning or a mistyped path needs: each module costs a warm
    # load its import (and, without bytecode files, its compilation). No subprocess: the host
    # module's entry comes from the record, so the compiler is not run for its version line.
    probe = (
        "import sys, sofac\n"
        f"sim = sofac.load({str(path)!r})\n"
        "front = sorted(m for m in ('lxml', 'jinja2', 'sofac.front.parse', 'sofac.check.checker',"
        " 'sofac.plan.planner', 'sofac.codegen.cpp', 'subprocess', 'sofac.build.guard', 'pybind11',"
        " 'sofac.scene_warnings', 'difflib') if m in sys.modules)\n"
        "print(sim.compiled.warm, front)\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True []"


def test_a_record_names_the_host_module_and_a_stale_host_entry_is_ignored(tmp_path: Path) -> None:
    from sofac.simulation import loader

    path = liver(tmp_path)
    sofac.load(path)
    record = warm.lookup(path, data_roots=(), prune=True, rigid_model="sofa", threads=1)
    loaded = loader.host_built()
    assert record is not None and record.host is not None and loaded is not None
    assert (record.host.library, record.host.key) == (loaded.library, loaded.key)
    assert warm._host([str(tmp_path / "gone" / "_sofac_host.so"), "0" * 64]) is None
    assert warm._host(None) is None


def test_an_edited_attribute_is_a_miss(tmp_path: Path) -> None:
    path = liver(tmp_path)
    _, before = run(path)
    path.write_text(path.read_text().replace('youngModulus="1e4"', 'youngModulus="2e4"'))
    sim, after = run(path)
    assert not sim.compiled.warm
    assert sim.spec.buffers[sim.spec.index("/Liver/FEM.youngModulus")].initial[0] == 2e4
    assert not np.array_equal(before, after)


def test_an_edited_mesh_is_a_miss(tmp_path: Path) -> None:
    path = liver(tmp_path)
    _, before = run(path, steps=0)
    shifted_mesh(tmp_path / "liver.msh", tmp_path / "liver.msh", 1.0)
    sim, after = run(path, steps=0)
    assert not sim.compiled.warm
    np.testing.assert_allclose(after[:, 0], before[:, 0] + 1.0, rtol=0, atol=1e-12)


def test_a_file_found_earlier_on_the_search_path_is_a_miss(tmp_path: Path) -> None:
    # The volume mesh is first found in a data root; then one appears next to the scene, which
    # SOFA's lookup tries first: the record, made when that candidate was absent, must not be used.
    library = tmp_path / "library"
    library.mkdir()
    path = liver(tmp_path / "scene", mesh_folder=library)
    _, before = run(path, steps=0, data_roots=[library])
    assert run(path, steps=0, data_roots=[library])[0].compiled.warm
    shifted_mesh(library / "liver.msh", path.parent / "liver.msh", 2.0)
    sim, after = run(path, steps=0, data_roots=[library])
    assert not sim.compiled.warm
    np.testing.assert_allclose(after[:, 0], before[:, 0] + 2.0, rtol=0, atol=1e-12)


def test_options_have_their_own_records(tmp_path: Path) -> None:
    path = liver(tmp_path)
    sofac.load(path)
    assert not sofac.load(path, prune=False).compiled.warm
    assert sofac.load(path, prune=False).compiled.warm and sofac.load(path).compiled.warm


@pytest.mark.parametrize("damage", ["truncate", "garbage", "library"])
def test_a_damaged_record_or_library_is_a_miss(tmp_path: Path, damage: str) -> None:
    path = liver(tmp_path)
    _, expected = run(path)
    records = list(Path(os.environ["SOFAC_CACHE_DIR"], "loads").glob("*/*.npz"))
    record = max(records, key=lambda r: r.stat().st_mtime_ns)
    meta = json.loads(np.load(record)["meta"].tobytes())
    assert meta["dependencies"][0][0] == str(path.resolve())
    if damage == "truncate":
        record.write_bytes(record.read_bytes()[:100])
    elif damage == "garbage":
        record.write_bytes(b"not a record")
    else:  # the build-cache entry it names was removed: the library is built again
        shutil.rmtree(Path(meta["library"]).parent)
    sim, x = run(path)
    assert not sim.compiled.warm
    assert np.array_equal(x, expected)
    assert run(path)[0].compiled.warm  # and the record was written again


def test_sofac_run_is_warm_the_second_time(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sofac.cli.main import main

    path = liver(tmp_path)
    outputs = []
    for _ in range(2):
        assert main(["run", str(path), "--steps", "3"]) == 0
        outputs.append(capsys.readouterr().out.splitlines())
    assert "(warm record)" not in outputs[0][0] and "(warm record)" in outputs[1][0]
    assert outputs[0][1:] == outputs[1][1:]  # the same states after 3 steps


def test_a_record_keeps_the_contact_reports_and_the_growable_buffers() -> None:
    # a warm load warns about contacts as a cold one, and takes its grown views again (RunSpec)
    from sofac.simulation.runspec import BufferSpec, RunSpec

    buffers = tuple(BufferSpec(f"/.b{i}", "f64", "state", np.zeros(i + 1)) for i in range(3))
    spec = RunSpec(
        buffers, (), (), (), None, frozenset(), {}, 1, "", False,
        contact_reports=(("/CollisionPipeline3", 1),), growable=(0, 2),
    )  # fmt: skip
    meta = json.loads(json.dumps({"spec": warm._spec_to_json(spec)}))["spec"]
    back = warm._spec_from_json(meta, [b.initial for b in buffers])
    assert back.contact_reports == spec.contact_reports and back.growable == spec.growable
