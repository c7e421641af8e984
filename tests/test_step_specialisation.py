"""The step specialised at compile time for what the scene holds, with the same results.

Springs whose damping is exactly zero get a kernel without the damping term (a pruned effect:
changing a damping at run time needs ``prune=False``), springs without flags skip the flag tests,
and the conjugate gradient's fused passes and the -O3 build of large scenes give the same numbers
bit for bit as the generic code (``prune=False``, ``SOFAC_OPT=O2``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.build import compiler as build
from sofac.pipeline import compile_scene
from sofac.simulation.loader import PrunedEffectError

CLOTH = """<Node name="root" gravity="0 -9.81 0" dt="{dt}"><DefaultAnimationLoop/>
  <Node name="cloth">{solver}
    <MechanicalObject name="dofs" position="{position}"/>
    <UniformMass name="mass" vertexMass="0.01"/>
    <FixedProjectiveConstraint indices="0 {corner}"/>
    <SpringForceField name="springs" spring="{springs}"/>
  </Node>
</Node>"""

EXPLICIT = '<EulerExplicitSolver symplectic="1"/>'
IMPLICIT = (
    '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
    '<CGLinearSolver iterations="25" tolerance="0" threshold="0"/>'
)


def cloth(tmp_path: Path, name: str, solver: str, damping: float, n: int = 6, dt: float = 1e-3) -> Path:
    """An n x n cloth of springs (structural and shear), corners 0 and n-1 fixed."""
    points = [(i / (n - 1), 0.0, j / (n - 1)) for j in range(n) for i in range(n)]
    springs = []
    for j in range(n):
        for i in range(n):
            a = j * n + i
            for b in (
                ([a + 1] if i + 1 < n else [])
                + ([a + n] if j + 1 < n else [])
                + ([a + n + 1] if i + 1 < n and j + 1 < n else [])
            ):
                length = float(np.linalg.norm(np.subtract(points[a], points[b])))
                springs.append(f"{a} {b} 1000 {damping} {length!r}")
    text = CLOTH.format(
        dt=dt,
        solver=solver,
        position="  ".join(f"{x!r} {y!r} {z!r}" for x, y, z in points),
        corner=n - 1,
        springs="  ".join(springs),
    )
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("solver", [EXPLICIT, IMPLICIT], ids=["explicit", "implicit"])
def test_zero_damping_is_pruned_with_identical_results(tmp_path: Path, solver: str) -> None:
    path = cloth(tmp_path, "undamped.scn", solver, damping=0.0)
    pruned, kept = sofac.load(path), sofac.load(path, prune=False)
    assert "/cloth/springs.damping" in pruned.plan.pruned
    assert "/cloth/springs.damping" not in kept.plan.pruned
    assert pruned.compiled.built.key != kept.compiled.built.key  # two different steps
    pruned.step(40)
    kept.step(40)
    assert np.array_equal(pruned["dofs"].position, kept["dofs"].position)
    assert np.array_equal(pruned["dofs"].velocity, kept["dofs"].velocity)
    with pytest.raises(PrunedEffectError, match="prune=False"):
        pruned.param("/cloth/springs.damping")
    # without pruning, the damping stays a live parameter
    damped = sofac.load(path, prune=False)
    damped.param("/cloth/springs.damping")[:] = 5.0
    damped.step(40)
    assert not np.allclose(damped["dofs"].velocity, kept["dofs"].velocity)


def test_nonzero_damping_is_kept(tmp_path: Path) -> None:
    sim = sofac.load(cloth(tmp_path, "damped.scn", EXPLICIT, damping=2.0))
    assert "/cloth/springs.damping" not in sim.plan.pruned
    assert sim.param("/cloth/springs.damping")[0] == 2.0


@pytest.mark.parametrize("solver", [EXPLICIT, IMPLICIT], ids=["explicit", "implicit"])
def test_optimisation_levels_give_the_same_numbers(
    tmp_path: Path, solver: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = cloth(tmp_path, "levels.scn", solver, damping=1.0, n=8)
    results = {}
    for level in ("O2", "O3"):
        monkeypatch.setenv(build.OPT_ENV, level)
        compiled = compile_scene(path)
        manifest = json.loads((compiled.built.library.parent / "manifest.json").read_text())
        assert ("-O3" if level == "O3" else "-O2") in manifest["flags"]
        sim = compiled.instantiate()
        sim.step(30)
        results[level] = (sim["dofs"].position.copy(), sim["dofs"].velocity.copy())
    assert np.array_equal(results["O2"][0], results["O3"][0])
    assert np.array_equal(results["O2"][1], results["O3"][1])


def test_large_scenes_get_o3_small_ones_o2(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(build.OPT_ENV, raising=False)
    assert "-O2" in build.scene_flags(10) and "-O3" not in build.scene_flags(10)
    assert "-O3" in build.scene_flags(build.LARGE_SCENE_NUMBERS)
    monkeypatch.setenv(build.OPT_ENV, "O2")
    assert "-O3" not in build.scene_flags(10**9)


def test_vector_level_follows_the_processor(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The scene is built with the kernels' vector copy for this processor only, named in its flags
    (so in its cache key); the level is read from /proc/cpuinfo's flags."""
    level = build.vector_level()
    flags = build.scene_flags(10)
    assert (f"-DSOFAC_VECTOR_LEVEL={level}" in flags) == (level is not None)
    cpuinfo = tmp_path / "cpuinfo"
    real_path = build.Path

    def fake_path(*parts: object) -> Path:
        return cpuinfo if parts == ("/proc/cpuinfo",) else real_path(*parts)

    monkeypatch.setattr(build.platform, "machine", lambda: "x86_64")
    monkeypatch.setattr(build, "Path", fake_path)
    for cpu_flags, expected in (("fpu sse2 avx2", 1), ("sse2 avx2 avx512f avx512vl", 2), ("sse2 avx512f", 0)):
        cpuinfo.write_text(f"processor\t: 0\nflags\t\t: {cpu_flags}\n")
        build.vector_level.cache_clear()
        assert build.vector_level() == expected
    build.vector_level.cache_clear()
