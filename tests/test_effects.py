"""Only the effects a scene calls for: what the plan leaves out, and what that means at run time."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.loader import PrunedEffectError, compile_scene

REPO = Path(__file__).resolve().parents[1]

FALLING = """<Node name="root" gravity="{gravity}" dt="0.01"><DefaultAnimationLoop/>
  <Node name="body"><EulerExplicitSolver/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0"/>
    <UniformMass name="mass" vertexMass="1"/>
    <SpringForceField name="spring" spring="0 1 10 0 1"/>
  </Node>{extra}
</Node>"""

VISUAL_NODES = """
  <Node name="looks"><OglModel name="shape" position="0 0 0  1 0 0  0 1 0" triangles="0 1 2"/>
    <Node name="more"><VisualStyle displayFlags="showVisual"/>
      <OglModel name="shape2" position="0 0 1  1 0 1  0 1 1" triangles="0 1 2"/></Node>
  </Node>"""


def write(tmp_path: Path, name: str, gravity: str = "0 -9.81 0", extra: str = "") -> Path:
    path = tmp_path / name
    path.write_text(FALLING.format(gravity=gravity, extra=extra))
    return path


def test_zero_gravity_has_no_code_and_refuses_a_run_time_change(tmp_path: Path) -> None:
    compiled = compile_scene(write(tmp_path, "weightless.scn", gravity="0 0 0"))
    plan = compiled.plan
    mass = next(s for s in plan.states if s.path == "/body/dofs")
    # the mass still gives inertia, but no force: no force op comes from it
    force_origins = [op.origin for group in plan.groups for op in group.forces]
    assert not any("UniformMass" in origin for origin in force_origins)
    assert "/.gravity" in plan.pruned and mass.size == 2
    assert "gravity" not in {effect for effect, _, _ in plan.effects}
    sim = compiled.instantiate()
    with pytest.raises(PrunedEffectError, match="prune=False"):
        sim.param("/.gravity")
    kept = sofac.load(write(tmp_path, "weightless2.scn", gravity="0 0 0"), prune=False)
    kept.param("/.gravity")[:] = [0.0, -10.0, 0.0]
    kept.step(10)
    assert kept["dofs"].position[:, 1] == pytest.approx([-10 * 0.01**2 * 55] * 2)


def test_asking_for_a_pruned_effect_recompiles_and_goes_on(tmp_path: Path) -> None:
    """sim.param(key, recompile=True) on a pruned effect: the scene is recompiled with it and the
    run continues from where it was, as if it had been compiled with the effect from the start."""
    path = write(tmp_path, "weightless.scn", gravity="0 0 0")
    sim, kept = sofac.load(path), sofac.load(path, prune=False)
    for run in (sim, kept):
        run["dofs"].velocity[:] = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]  # some state to carry over
        run.step(20)
    assert "/.gravity" in sim.plan.pruned
    sim.param("/.gravity", recompile=True)[:] = [0.0, -10.0, 0.0]
    kept.param("/.gravity")[:] = [0.0, -10.0, 0.0]
    assert "/.gravity" not in sim.plan.pruned
    assert sim.steps == 20 and sim.time == pytest.approx(0.2)
    for run in (sim, kept):
        run.step(30)
    np.testing.assert_array_equal(sim["dofs"].position, kept["dofs"].position)
    np.testing.assert_array_equal(sim["dofs"].velocity, kept["dofs"].velocity)
    assert sim["dofs"].position[0, 1] < -0.04  # it fell once gravity was on
    assert sim.time == kept.time
    sim.reset()  # back to the scene's initial state, the new gravity kept
    assert sim.time == 0.0 and sim.param("/.gravity")[1] == -10.0


def test_gravity_is_an_effect_when_present(tmp_path: Path) -> None:
    plan = compile_scene(write(tmp_path, "heavy.scn")).plan
    assert plan.gravity.key not in plan.pruned
    assert ("gravity", "root node", "g = [0.0, -9.81, 0.0], applied by the masses") in plan.effects


def _code(source: str) -> str:
    """The generated source without its comments (which name files and lines)."""
    return "\n".join(re.sub(r"//.*", "", line).rstrip() for line in source.splitlines())


def test_inert_visual_nodes_change_neither_the_step_nor_the_results(tmp_path: Path) -> None:
    plain = compile_scene(write(tmp_path, "plain.scn"))
    dressed = compile_scene(write(tmp_path, "dressed.scn", extra=VISUAL_NODES))
    assert _code(plain.source) == _code(dressed.source)
    kept_out = {origin.split(" ")[0] for effect, origin, _ in dressed.plan.effects if effect == "kept out"}
    assert {"OglModel", "VisualStyle"} <= kept_out
    a, b = plain.instantiate(), dressed.instantiate()
    a.step(50)
    b.step(50)
    assert np.array_equal(a["dofs"].position, b["dofs"].position)


def test_inspect_effects_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sofac.cli import main

    assert main(["inspect", str(REPO / "scenes" / "oscillator.scn"), "--effects"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^pruned\s+/\.gravity: gravity is zero", out, re.M)
    assert re.search(r"^integration\s+EulerExplicitSolver '/oscillator/odesolver'", out, re.M)
