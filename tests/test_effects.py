"""Only the effects a scene calls for: what the plan leaves out, and what that means at run time."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sofac
from sofac.pipeline import compile_scene
from sofac.simulation.loader import PrunedEffectError

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
    from sofac.cli.main import main

    assert main(["inspect", str(REPO / "scenes" / "oscillator.scn"), "--effects"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^pruned\s+/\.gravity: gravity is zero", out, re.M)
    assert re.search(r"^integration\s+EulerExplicitSolver '/oscillator/odesolver'", out, re.M)


# --- mapped states nothing in the step reads: computed when read ---------------------------------

SPRINGS = """<Node name="root" gravity="0 -9.81 0" dt="0.01"><DefaultAnimationLoop/>
  <CollisionPipeline/><BruteForceBroadPhase/><BVHNarrowPhase/><DiscreteIntersection/>
  <Node name="body">
    <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
    <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-12"/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0  1 1 0" velocity="0 0 0  0 0 1  0.5 0 0"/>
    <UniformMass name="mass" vertexMass="1"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField name="spring" spring="0 1 40 0.5 1  1 2 40 0.5 1"/>{inside}
  </Node>
</Node>"""

# Collision spheres on two of the points: one collision model, so no contact can happen.
SKIN = """
    <Node name="skin">
      <MechanicalObject name="points" position="1 0 0  1 1 0"/>
      <SphereCollisionModel radius="0.1"/>
      <SubsetMapping indices="1 2" input="@../dofs" output="@points"/>{below}
    </Node>"""
# A point of the skin, mapped once more.
TIP = """
      <Node name="tip">
        <MechanicalObject name="tip" position="1 1 0"/>{tip}
        <SubsetMapping indices="1" input="@../points" output="@tip"/>
      </Node>"""


def springs(tmp_path: Path, name: str, inside: str = "") -> Path:
    path = tmp_path / name
    path.write_text(SPRINGS.format(inside=inside))
    return path


def _mapped_children(plan: Any) -> tuple[set[str], set[str]]:
    """(states mapped in the step, states mapped only when read), by path."""
    stepped = {m.child.path for g in plan.groups for m in g.mappings}
    on_read = {m.child.path for g in plan.groups for m in g.on_read}
    return stepped, on_read


def _step_functions(compiled: Any) -> str:
    """The generated functions of the step (each group's propagate, forces, products, step) and the
    energy, comments removed, with every buffer named by its key rather than its counter."""
    source = compiled.source
    code = source[source.index("// ---- group ") : source.index("SOFAC_EXPORT")]
    code = re.sub(r"void propagate_on_read_\w+\(Instance& S\) \{.*?\n\}\n", "", code, flags=re.S)
    keys = {b.ident: b.key for b in compiled.plan.buffers}
    code = re.sub(r"\bS\.(\w+)", lambda m: f"S.[{keys.get(m.group(1), m.group(1))}]", _code(code))
    return "\n".join(line for line in code.splitlines() if line.strip())


def _states(sim: Any) -> dict[str, np.ndarray]:
    return {f"{p}.{f}": getattr(sim[p], f).copy() for p in sim.objects() for f in ("position", "velocity")}


def test_liver_collision_spheres_are_mapped_only_when_read(
    corpus_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from sofac.cli.main import main

    scene = corpus_dir / "Demos" / "liver.scn"
    lazy, eager = compile_scene(scene), compile_scene(scene, prune=False)
    assert _mapped_children(lazy.plan) == (set(), {"/Liver/Surf/spheres"})
    assert _mapped_children(eager.plan) == ({"/Liver/Surf/spheres"}, set())
    spheres = next(s for s in lazy.plan.states if s.path == "/Liver/Surf/spheres")
    assert spheres.dx is None and spheres.df is None  # no product runs through it
    assert spheres.size == 34
    line = next(i for i, text in enumerate(scene.read_text().splitlines(), 1) if "sphere mapping" in text)
    assert (
        "computed on read",
        f"BarycentricMapping '/Liver/Surf/sphere mapping' ({scene}:{line})",
    ) in {(effect, origin) for effect, origin, _ in lazy.plan.effects}
    assert "propagate_on_read_" not in eager.source
    assert main(["inspect", str(scene), "--effects", "--format", "json"]) == 0
    rows = [r for r in json.loads(capsys.readouterr().out) if r["effect"] == "computed on read"]
    assert [r["component"] for r in rows] == [
        f"BarycentricMapping '/Liver/Surf/sphere mapping' ({scene}:{line})"
    ]
    assert "/Liver/Surf/spheres" in rows[0]["detail"]
    a, b = lazy.instantiate(), eager.instantiate()
    assert all(np.array_equal(x, y) for x, y in zip(_states(a).values(), _states(b).values(), strict=True))
    kept = a["spheres"].position
    before = kept.copy()
    a.step(1)
    b.step(1)
    assert np.array_equal(kept, before)  # not mapped by the step: a view kept from before waits...
    assert not np.array_equal(a["spheres"].position, before)  # ... for the state to be read again
    assert np.array_equal(kept, b["spheres"].position)
    for steps in (1, 6, 33):
        a.step(steps)
        b.step(steps)
        for key, value in _states(a).items():
            assert np.array_equal(value, _states(b)[key]), (key, a.steps)
        assert a.energy() == b.energy()
    a.reset()
    b.reset()
    a.step(3)
    b.step(3)
    for key, value in _states(a).items():
        assert np.array_equal(value, _states(b)[key]), key


def test_an_inert_mapped_collision_node_changes_neither_the_step_nor_the_results(tmp_path: Path) -> None:
    plain = compile_scene(springs(tmp_path, "plain.scn"))
    skinned = compile_scene(springs(tmp_path, "skinned.scn", SKIN.format(below=TIP.format(tip=""))))
    assert _mapped_children(skinned.plan) == (set(), {"/body/skin/points", "/body/skin/tip/tip"})
    assert _step_functions(plain) == _step_functions(skinned)
    assert "kept out" in {e for e, o, _ in skinned.plan.effects if o.startswith("SphereCollisionModel")}
    a, b = plain.instantiate(), skinned.instantiate()
    reference = compile_scene(
        springs(tmp_path, "eager.scn", SKIN.format(below=TIP.format(tip=""))), prune=False
    ).instantiate()
    for _ in range(4):
        a.step(25)
        b.step(25)
        reference.step(25)
        assert np.array_equal(a["dofs"].position, b["dofs"].position)
        assert np.array_equal(a["dofs"].velocity, b["dofs"].velocity)
        for path in ("/body/skin/points", "/body/skin/tip/tip"):
            for field in ("position", "velocity"):
                assert np.array_equal(getattr(b[path], field), getattr(reference[path], field))
    # A subset mapping copies: the skin's points are the body's last two, the tip the last one.
    assert np.array_equal(b["points"].position, b["dofs"].position[1:])
    assert np.array_equal(b["tip"].velocity, b["dofs"].velocity[2:])


def test_a_mapped_state_something_acts_on_is_computed_every_step(tmp_path: Path) -> None:
    pushed = '\n      <ConstantForceField forces="0 0 2  0 0 2"/>'
    # A force on the skin itself, and a force on the tip mapped from it: either way the skin is read.
    for name, inside, stepped, dofs in (
        ("pushed.scn", SKIN.format(below=pushed), {"/body/skin/points"}, [1, 2]),
        (
            "pushed_tip.scn",
            SKIN.format(below=TIP.format(tip='\n        <ConstantForceField forces="0 0 2"/>')),
            {"/body/skin/points", "/body/skin/tip/tip"},
            [2],
        ),
    ):
        compiled = compile_scene(springs(tmp_path, name, inside))
        assert _mapped_children(compiled.plan) == (stepped, set()), name
        assert "propagate_on_read_" not in compiled.source
        assert not any(e == "computed on read" for e, _, _ in compiled.plan.effects)
        # The force reaches the body through Jᵀ: the pushed points move up in z (about 2 N / 1 kg
        # over 0.2 s: 4 cm) compared with the body without the skin.
        sim, free = compiled.instantiate(), compile_scene(springs(tmp_path, "free.scn")).instantiate()
        sim.step(20)
        free.step(20)
        assert (sim["dofs"].position[dofs, 2] - free["dofs"].position[dofs, 2]).min() > 0.01
        eager = compile_scene(springs(tmp_path, "e" + name, inside), prune=False).instantiate()
        eager.step(20)
        for key, value in _states(sim).items():
            assert np.array_equal(value, _states(eager)[key]), key


def test_states_read_on_demand_are_what_writestate_and_sweeps_record(tmp_path: Path) -> None:
    from sofac.regress.states import export_states
    from sofac.sweeps.runner import sweep

    inside = SKIN.format(below=TIP.format(tip=""))
    lazy = compile_scene(springs(tmp_path, "lazy.scn", inside)).instantiate()
    eager = compile_scene(springs(tmp_path, "eager.scn", inside), prune=False).instantiate()
    written = [
        export_states(sim, 30, tmp_path / f"out{k}", every=7, mapped=True)
        for k, sim in enumerate((lazy, eager))
    ]
    assert [p.name for p in written[0]] == [p.name for p in written[1]]
    assert len(written[0]) == 3
    for mine, theirs in zip(*written, strict=True):
        assert mine.read_bytes() == theirs.read_bytes()
    record = ["/body/skin/tip/tip.position", "points.velocity", "energy"]
    results = [
        sweep(
            springs(tmp_path, "s.scn", inside),
            {"spring.stiffness[1]": [20.0, 60.0]},
            steps=30,
            every=10,
            record=record,
            scheduler="synchronous",
            prune=prune,
        )
        for prune in (True, False)
    ]
    for name in ("body.skin.tip.tip.position", "body.skin.points.velocity", "kinetic_energy"):
        values = results[0][name].values
        assert np.isfinite(values).all() and np.ptp(values) > 0
        assert np.array_equal(values, results[1][name].values)
