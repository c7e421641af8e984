"""The point force of scenes loaded with ``interactive=True`` (``<state>.pointForceIndex``,
``<state>.pointForce``): a force on one DOF set from Python between steps, without recompiling
(sofac view's mouse spring). Scenes loaded without it have no such code or parameter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

FREE_PARTICLES = """<Node name="root" gravity="0 0 0" dt="0.01">
  <DefaultAnimationLoop/>
  <Node name="cloud">
    <EulerExplicitSolver/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0 0"/>
    <UniformMass vertexMass="2"/>
  </Node>
</Node>
"""

# An implicit solver on one point; the force is put on a state mapped from it.
MAPPED = """<Node name="root" gravity="0 0 0" dt="0.05">
  <DefaultAnimationLoop/>
  <Node name="body">
    <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
    <CGLinearSolver iterations="25" tolerance="1e-20" threshold="1e-30"/>
    <MechanicalObject name="dofs" position="0 0 0"/>
    <UniformMass vertexMass="4"/>
    <Node name="handle">
      <MechanicalObject name="points" position="0 0 0"/>
      <IdentityMapping input="@../dofs" output="@points"/>
    </Node>
  </Node>
</Node>
"""


def _load(tmp_path: Path, text: str, **options: bool) -> sofac.Simulation:
    path = tmp_path / "scene.scn"
    path.write_text(text)
    return sofac.load(path, **{"interactive": True, **options})


def test_only_interactive_scenes_carry_point_forces(tmp_path: Path) -> None:
    plain = _load(tmp_path, FREE_PARTICLES, interactive=False)
    assert not [key for key in plain.params() if "pointForce" in key]
    assert "point_force" not in plain.compiled.source
    assert "point_force" in _load(tmp_path, FREE_PARTICLES).compiled.source


def test_a_point_force_pushes_only_its_dof_and_only_while_set(tmp_path: Path) -> None:
    sim = _load(tmp_path, FREE_PARTICLES)
    index, force = sim.param("/cloud/dofs.pointForceIndex"), sim.param("/cloud/dofs.pointForce")
    assert index.tolist() == [-1] and force.tolist() == [0.0, 0.0, 0.0]
    index[0], force[:] = 1, [3.0, 0.0, -1.0]
    sim.step()
    dofs = sim["/cloud/dofs"]
    expected_v = np.array([3.0, 0.0, -1.0]) / 2.0 * 0.01  # a = F / m, one explicit step
    np.testing.assert_allclose(dofs.velocity[1], expected_v, rtol=1e-15)
    np.testing.assert_allclose(dofs.position[1], [1.0, 0.0, 0.0] + 0.01 * expected_v, rtol=1e-15)
    assert not dofs.velocity[[0, 2]].any()
    index[0] = -1  # released: the particle coasts
    sim.step()
    np.testing.assert_allclose(dofs.velocity[1], expected_v, rtol=1e-15)


def test_a_point_index_outside_the_state_does_nothing(tmp_path: Path) -> None:
    sim = _load(tmp_path, FREE_PARTICLES)
    sim.param("/cloud/dofs.pointForce")[:] = [1e3, 1e3, 1e3]
    for outside in (3, 10**9, -5):
        sim.param("/cloud/dofs.pointForceIndex")[0] = outside
        sim.step()
        assert not sim["/cloud/dofs"].velocity.any()


def test_a_point_force_on_a_mapped_state_reaches_its_parent(tmp_path: Path) -> None:
    # prune=False keeps the mapped state in the step although nothing else acts on it; else it is
    # left out (mapped only when read) and has no point force of its own.
    assert "/body/handle/points.pointForce" not in _load(tmp_path, MAPPED).params()
    sim = _load(tmp_path, MAPPED, prune=False)
    sim.param("/body/handle/points.pointForceIndex")[0] = 0
    sim.param("/body/handle/points.pointForce")[:] = [0.0, 8.0, 0.0]
    sim.step()
    # Implicit Euler without stiffness: v = h M^-1 f.
    np.testing.assert_allclose(sim["/body/dofs"].velocity[0], [0.0, 0.05 * 8.0 / 4.0, 0.0], rtol=1e-12)
    sim.reset()  # parameters are kept by reset(), as every tunable parameter is
    assert sim.param("/body/handle/points.pointForceIndex")[0] == 0
    with pytest.raises(KeyError):
        sim.param("/body/dofs.pointForceIndexes")
