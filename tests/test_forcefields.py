"""Force fields that reach their state through links rather than through their node.

MeshSpringForceField is a pair-interaction force field in SOFA: its ``object1`` and ``object2``
both default to the node's state, so it acts on that one state. (It was once dropped from the step
because the checker gave it no state: ``scenes/cloth.scn`` then fell without its springs.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.pipeline import compile_scene
from sofac.plan.report import format_schedule

DT = 1e-3
MESH_SPRINGS = """\
<Node name="root" gravity="0 0 0" dt="{dt!r}"><DefaultAnimationLoop/>
  <Node name="net"><EulerExplicitSolver symplectic="0"/>
    <MeshTopology name="mesh" position="0 0 0  2 0 0  2 1.5 0" edges="0 1  1 2"/>
    <MechanicalObject name="dofs"/>
    <UniformMass vertexMass="0.5"/>
    <FixedProjectiveConstraint indices="0"/>
    <MeshSpringForceField name="springs" stiffness="30" damping="0"/>
  </Node>
</Node>
"""


def test_mesh_springs_act_on_their_nodes_state(tmp_path: Path) -> None:
    path = tmp_path / "mesh_springs.scn"
    path.write_text(MESH_SPRINGS.format(dt=DT))
    compiled = compile_scene(path)
    assert "MeshSpringForceField '/net/springs'" in format_schedule(compiled.plan)
    sim = compiled.instantiate()
    rest = sim["dofs"].position.copy()
    moved = rest.copy()
    moved[1] = [2.2, 0.1, -0.05]
    sim["dofs"].position[:] = moved
    sim.step(1)  # explicit Euler from rest: v1 = dt f / m
    force = np.zeros(3)
    for other in (0, 2):  # SOFA's per-spring stiffness: stiffness / rest length
        length = np.linalg.norm(rest[other] - rest[1])
        u = moved[other] - moved[1]
        d = np.linalg.norm(u)
        force += 30 / length * (d - length) * u / d
    assert sim["dofs"].velocity[1] == pytest.approx(DT * force / 0.5, rel=1e-12)
    assert sim["dofs"].velocity[0].tolist() == [0.0, 0.0, 0.0]


GRID_SPRINGS = """\
<Node name="root" gravity="0 0 0" dt="1e-3"><DefaultAnimationLoop/>
  <Node name="cube"><EulerExplicitSolver/>
    <RegularGridTopology n="2 2 2" min="0 0 0" max="{size}"/>
    <MechanicalObject name="dofs"/>
    <UniformMass vertexMass="0.25"/>
    <{field} stiffness="40" damping="0.5"/>
  </Node>
</Node>
"""


def test_regular_grid_springs_are_the_grids_edges_and_diagonals(tmp_path: Path) -> None:
    """On one cell, RegularGridSpringForceField springs every vertex pair (12 edges, 12 face
    diagonals, 4 cube diagonals) with ks = stiffness / L0, as MeshSpringForceField does on the
    cell's hexahedron: the two give the same motion (up to the order of the sums)."""
    sims = {}
    for field in ("RegularGridSpringForceField", "MeshSpringForceField"):
        path = tmp_path / f"{field}.scn"
        path.write_text(GRID_SPRINGS.format(field=field, size="1 2 3"))
        compiled = compile_scene(path)
        springs = next(b for b in compiled.plan.buffers if b.key.endswith(".stiffness"))
        assert springs.initial.size == 28
        sim = compiled.instantiate()
        sim["dofs"].position[7] += [0.3, -0.2, 0.1]  # pull one corner
        sim.step(200)
        sims[field] = sim["dofs"].position.copy()
    moved = sims["RegularGridSpringForceField"]
    assert np.abs(moved - sims["MeshSpringForceField"]).max() < 1e-12
    assert np.abs(moved[7] - [1.3, 1.8, 3.1]).max() > 1e-3  # the springs did act
