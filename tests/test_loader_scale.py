"""MeshLoader's legacy ``scale`` attribute multiplies ``scale3d`` (SOFA's MeshLoader::parse)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

OBJ = "v 0 0 0\nv 1 0 0\nv 0 2 0\nf 1 2 3\n"
SCENE = """<Node name="root" dt="0.01" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver/>
  <CGLinearSolver iterations="10" tolerance="1e-9" threshold="1e-9"/>
  <MeshOBJLoader name="loader" filename="tri.obj" {attributes}/>
  <MeshTopology src="@loader"/>
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="1"/>
</Node>
"""


@pytest.mark.parametrize(
    ("attributes", "factor"),
    [("", [1, 1, 1]), ('scale="10"', [10, 10, 10]), ('scale3d="1 2 3" scale="10"', [10, 20, 30])],
)
def test_legacy_scale(tmp_path: Path, attributes: str, factor: list[float]) -> None:
    (tmp_path / "tri.obj").write_text(OBJ)
    scene = tmp_path / "scaled.scn"
    scene.write_text(SCENE.format(attributes=attributes))
    sim = sofac.load(scene)
    expected = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], dtype=float) * factor
    assert np.asarray(sim["/dofs"].position).tolist() == expected.tolist()
