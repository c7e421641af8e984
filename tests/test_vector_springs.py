"""VectorSpringForceField: SOFA's default springs (point i of object1 to point i of object2, rest
vector 0) and, with useTopology, one spring per edge with the rest positions' edge vector."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.pipeline import compile_scene
from sofac.simulation.loader import Simulation

DT = 0.01
SCENE = """\
<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
  <Node name="pair"><EulerExplicitSolver symplectic="0"/>
    <Node name="a"><MechanicalObject name="a_dofs" position="0 0 0  1 0 0"/>
      <UniformMass vertexMass="2"/></Node>
    <Node name="b"><MechanicalObject name="b_dofs" position="0.5 1 0  1 0 2" velocity="1 0 0  0 0 0"/>
      <UniformMass vertexMass="1"/></Node>
    <VectorSpringForceField object1="@a/a_dofs" object2="@b/b_dofs" stiffness="10" viscosity="0.5"/>
  </Node>
  <Node name="mesh"><EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/><SparseLDLSolver/>
    <MeshTopology name="topo" position="0 0 0  1 0 0  1 1 0" edges="0 1  1 2"/>
    <MechanicalObject name="mesh_dofs"/>
    <UniformMass vertexMass="1"/>
    <FixedProjectiveConstraint indices="0"/>
    <VectorSpringForceField useTopology="1" stiffness="30" viscosity="0"/>
  </Node>
</Node>
"""


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Simulation:
    path = tmp_path_factory.mktemp("vector_springs") / "vector_springs.scn"
    path.write_text(SCENE)
    simulation = compile_scene(path).instantiate()
    simulation["mesh_dofs"].position[2] += [0.1, -0.2, 0.3]
    simulation.step(1)
    return simulation


def test_point_to_point_springs_couple_two_states(sim: Simulation) -> None:
    """f = ks (x2 - x1) + kd (v2 - v1) on object1, its opposite on object2 (explicit Euler)."""
    force = 10 * np.array([[0.5, 1.0, 0.0], [0.0, 0.0, 2.0]]) + 0.5 * np.array([[1.0, 0, 0], [0, 0, 0]])
    assert sim["a_dofs"].velocity == pytest.approx(DT * force / 2, abs=1e-15)
    assert sim["b_dofs"].velocity == pytest.approx(np.array([[1.0, 0, 0], [0, 0, 0]]) - DT * force, abs=1e-15)


def test_topology_springs_solve_as_a_linear_system(sim: Simulation) -> None:
    """Implicit Euler from rest: (M - dt^2 K) dv = dt f, K = ks [[-I, I], [I, -I]] per edge, the
    fixed point 0 projected out: exactly linear, so one solve gives the velocity."""
    ks = 30.0
    stiffness = np.zeros((9, 9))
    for a, b in ((0, 1), (1, 2)):
        for c in range(3):
            i, j = 3 * a + c, 3 * b + c
            stiffness[i, i] -= ks
            stiffness[j, j] -= ks
            stiffness[i, j] += ks
            stiffness[j, i] += ks
    displacement = np.zeros(9)
    displacement[6:] = [0.1, -0.2, 0.3]  # from the rest shape, whose edge vectors are the rest vectors
    force = stiffness @ displacement
    free = slice(3, 9)
    system = np.eye(6) - DT * DT * stiffness[free, free]
    dv = np.linalg.solve(system, DT * force[free])
    assert sim["mesh_dofs"].velocity[1:].ravel() == pytest.approx(dv, rel=1e-12, abs=1e-15)
    assert sim["mesh_dofs"].velocity[0].tolist() == [0.0, 0.0, 0.0]


def test_a_springs_list_applies_no_force(tmp_path: Path) -> None:
    """With `springs` given, SOFA's bwdInit builds no edge for them, so addForce loops over no spring:
    a warning on the attribute, and the displaced mesh (no gravity) stays at rest."""
    path = tmp_path / "listed.scn"
    path.write_text(SCENE.replace('useTopology="1"', 'useTopology="1" springs="30 0 1 0 0"'))
    with pytest.warns(UserWarning, match="SOFA applies no spring when `springs` is given"):
        compiled = compile_scene(path)
    assert [(d.code, d.loc.line, d.loc.attribute) for d in compiled.warnings] == [("W225", 14, "springs")]
    simulation = compiled.instantiate()
    simulation["mesh_dofs"].position[2] += [0.1, -0.2, 0.3]
    simulation.step(1)
    assert not simulation["mesh_dofs"].velocity.any()
