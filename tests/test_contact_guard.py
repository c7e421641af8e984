"""Collision models that could touch, with a response sofac does not compile (StickContactForceField
here; penalty contact is compiled, tests/test_contacts.py): the step runs while their boxes stay
apart, and stops with ContactNotCompiled before the first step whose start has two of them within
reach."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.pipeline import compile_scene

TWO_BALLS = """<Node name="root" gravity="0 0 0" dt="0.1"><DefaultAnimationLoop/>
  <CollisionPipeline/><BruteForceBroadPhase/><BVHNarrowPhase/>{intersection}
  <CollisionResponse response="StickContactForceField"/>
  <Node name="left"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="dofs" position="0 0 0" velocity="1 0 0"/><UniformMass vertexMass="1"/>
    <SphereCollisionModel radius="{radius}"{left}/></Node>
  <Node name="right"><EulerExplicitSolver symplectic="1"/>
    <MechanicalObject name="dofs" position="10 0 0" velocity="-1 0 0"/><UniformMass vertexMass="1"/>
    <SphereCollisionModel radius="{radius}"{right}/></Node>
</Node>
"""


def write(
    tmp_path: Path,
    name: str,
    intersection: str = "<DiscreteIntersection/>",
    radius: float = 0.55,
    left: str = "",
    right: str = "",
) -> Path:
    path = tmp_path / name
    path.write_text(TWO_BALLS.format(intersection=intersection, radius=radius, left=left, right=right))
    return path


def test_the_step_stops_before_the_balls_could_touch(tmp_path: Path) -> None:
    """The balls close in at 2 m/s from 10 m apart; each box is grown by the radius 0.55, so they
    overlap once the centres are 1.1 m apart or less: after 45 steps of 0.1 s (1.0 m apart), not
    after 44 (1.2 m). The 45 steps run; the 46th does not."""
    sim = sofac.load(write(tmp_path, "balls.scn"))
    sim.step(44)  # 1.2 m apart: no stop
    with pytest.raises(sofac.ContactNotCompiled) as stopped:
        sim.step(10)
    assert sim.steps == 45
    assert sim["left/dofs"].position[0, 0] == pytest.approx(4.5)
    assert sim["right/dofs"].position[0, 0] == pytest.approx(5.5)
    message = str(stopped.value)
    assert message.startswith("step 46 (t=4.5): collision models SphereCollisionModel '/left/")
    assert "balls.scn:6" in message and "balls.scn:9" in message
    sim.reset()  # the guard starts over with the state
    sim.step(44)
    assert sim.steps == 44


def test_the_alarm_distance_widens_the_reach(tmp_path: Path) -> None:
    """NewProximityIntersection's alarmDistance 2 is the gap SOFA's box test allows between two
    models (each box grows by half of it): 3.1 m of reach, reached after 35 steps (3.0 m apart),
    not 34 (3.2 m). The intersection's own contactDistance does not count."""
    proximity = '<NewProximityIntersection alarmDistance="2" contactDistance="0.5"/>'
    sim = sofac.load(write(tmp_path, "near.scn", intersection=proximity))
    with pytest.raises(sofac.ContactNotCompiled):
        sim.step(100)
    assert sim.steps == 35


def test_a_models_contact_distance_widens_its_reach(tmp_path: Path) -> None:
    """The left model's contactDistance 1 adds to its box: 2.1 m of reach, reached after 40 steps
    (2.0 m apart), not 39 (2.2 m)."""
    sim = sofac.load(write(tmp_path, "skin.scn", left=' contactDistance="1"'))
    with pytest.raises(sofac.ContactNotCompiled):
        sim.step(100)
    assert sim.steps == 40


def test_a_run_without_contact_is_the_plain_run(tmp_path: Path) -> None:
    """Balls that never come within reach: the guarded run equals the one without collision
    models bit for bit (the guard only reads positions)."""
    guarded = sofac.load(write(tmp_path, "apart.scn", radius=0.1))
    guarded.step(20)  # 6 m apart at the end
    bare = tmp_path / "bare.scn"
    collision = r"<(BruteForceBroadPhase|BVHNarrowPhase|DiscreteIntersection|\w*Collision\w*)[^>]*/>"
    bare.write_text(re.sub(collision, "", (tmp_path / "apart.scn").read_text()))
    plain = sofac.load(bare)
    plain.step(20)
    assert plain.plan.contact_guard is None
    for path in ("left/dofs", "right/dofs"):
        np.testing.assert_array_equal(guarded[path].position, plain[path].position)
    assert guarded.plan.contact_guard is not None
    paths = [origin.split("'")[1] for origin, _ in guarded.plan.contact_guard.models]
    assert [p.rsplit("/", 1)[0] for p in paths] == ["/left", "/right"]


def test_static_obstacles_and_inactive_models_are_not_guarded(tmp_path: Path) -> None:
    static = ' simulated="0" moving="0"'
    both_static = compile_scene(write(tmp_path, "static.scn", left=static, right=static)).plan
    assert both_static.contact_guard is None  # two static models: SOFA tests no pair
    inactive = compile_scene(write(tmp_path, "inactive.scn", right=' active="0"')).plan
    assert inactive.contact_guard is None


def test_self_collision_is_still_refused(tmp_path: Path) -> None:
    with pytest.raises(sofac.SceneError) as refused:
        sofac.load(write(tmp_path, "self.scn", left=' selfCollision="1"'))
    first = refused.value.diagnostics[0]
    assert first.code == "E222" and first.loc.line == 6
    # a model may touch itself (no box rules it out) and this setup's contacts are not compiled:
    # refused, saying why (DiscreteIntersection and StickContactForceField are not compiled)
    assert "unsupported component SphereCollisionModel at line 6: self-collision: " in first.message
    assert "penalty contact is compiled for" in first.message


def test_check_says_that_a_run_may_stop(tmp_path: Path) -> None:
    """What a run stops on, `sofac check` says (check and compile agree): W234 at the contact
    manager, naming why the contacts are not compiled (SOFA's Component/Collision/Geometry/
    SphereModel.scn stops at step 69 when its spheres reach the floor)."""
    from sofac.check.checker import check_file
    from sofac.pipeline import add_compile_refusals

    checked, diagnostics = check_file(write(tmp_path, "balls.scn"))
    add_compile_refusals(checked, diagnostics)
    assert diagnostics.errors == []
    assert [(d.code, d.loc.line) for d in diagnostics.warnings] == [("W234", 3)]
    message = diagnostics.warnings[0].message
    assert message.startswith("2 collision models of this scene could touch")
    # the planner's reason: the first part of the setup it does not compile (DiscreteIntersection)
    assert "(penalty contact is compiled for a CollisionPipeline with its intersection" in message
    assert "a run stops with ContactNotCompiled" in message
