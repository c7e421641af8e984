"""Mesh2PointTopologicalMapping evaluated at compile time: the output container's points (which size
and place a MechanicalObject), in SOFA's order: per input point, per edge, per triangle, per
tetrahedron."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import sofac

SCENE = """<Node name="root" dt="0.01" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver/>
  <CGLinearSolver iterations="10" tolerance="1e-9" threshold="1e-9"/>
  <TetrahedronSetTopologyContainer name="tets" position="0 0 0  2 0 0  0 4 0  0 0 8  2 4 8"
      tetrahedra="0 1 2 3  1 2 3 4"/>
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="1"/>
  <Node name="points">
    <PointSetTopologyContainer name="out"/>
    <Mesh2PointTopologicalMapping input="@../tets" output="@out" pointBaryCoords="0 0 0  0 0 1"
        edgeBaryCoords="0.25 0 0" tetraBaryCoords="0.25 0.25 0.25"/>
    <MechanicalObject name="mapped"/>
  </Node>
</Node>
"""


def test_points_edges_and_tetrahedra(tmp_path: Path) -> None:
    scene = tmp_path / "mesh2point.scn"
    scene.write_text(SCENE)
    sim = sofac.load(scene)
    points = np.array([[0, 0, 0], [2, 0, 0], [0, 4, 0], [0, 0, 8], [2, 4, 8]], dtype=float)
    expected = [p + offset for p in points for offset in ([0, 0, 0], [0, 0, 1])]
    # The container's edges: per tetrahedron, local pairs (1,2) (0,1) (0,2) (1,3) (0,3) (2,3), new ones
    # only, stored (min, max); the point at 0.25 from the first end.
    edges = [(1, 2), (0, 1), (0, 2), (1, 3), (0, 3), (2, 3), (2, 4), (1, 4), (3, 4)]
    expected += [points[a] * 0.75 + points[b] * 0.25 for a, b in edges]
    for tetra in ([0, 1, 2, 3], [1, 2, 3, 4]):
        expected.append(points[tetra].mean(axis=0))
    mapped = np.asarray(sim["/points/mapped"].position)
    assert mapped.shape == (len(expected), 3)
    assert np.abs(mapped - np.array(expected)).max() < 1e-15
    sim.step(2)  # no force on them: they stay
    assert np.abs(np.asarray(sim["/points/mapped"].position) - np.array(expected)).max() < 1e-15
