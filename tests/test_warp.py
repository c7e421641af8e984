"""WarpPreconditioner with its RotationMatrixSystem reassembled every step: the PCG preconditioned by
the exact factorisation of the step's matrix reaches the direct solution in one iteration."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

SCENE = """<Node name="root" dt="0.02" gravity="0 -10 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="50"/>
  <RegularGridTopology nx="2" ny="2" nz="5" xmin="0" xmax="1" ymin="0" ymax="1" zmin="0" zmax="6"/>
  <FixedProjectiveConstraint indices="0 1 2 3"/>
  {solver}
  <HexahedronFEMForceField youngModulus="3000" poissonRatio="0.3" method="large"/>
</Node>
"""
WARP = """<PreconditionedMatrixFreeSystem name="free" assemblingRate="1"/>
  <PCGLinearSolver iterations="{iterations}" tolerance="1e-30" linearSystem="@free" preconditioner="@warp"/>
  <RotationMatrixSystem name="rotations" assemblingRate="{rate}"/>
  <WarpPreconditioner name="warp" linearSystem="@rotations" linearSolver="@ldl"/>
  <MatrixLinearSystem template="CompressedRowSparseMatrixMat3x3" name="system"/>
  <SparseLDLSolver name="ldl" template="CompressedRowSparseMatrixMat3x3" linearSystem="@system"/>"""


def _run(tmp_path: Path, name: str, solver: str) -> np.ndarray:
    scene = tmp_path / f"{name}.scn"
    scene.write_text(SCENE.format(solver=solver))
    sim = sofac.load(scene)
    sim.step(5)
    return np.asarray(sim["/dofs"].position).copy()


def test_one_warped_iteration_is_the_direct_solve(tmp_path: Path) -> None:
    direct = _run(tmp_path, "ldl", '<SparseLDLSolver template="CompressedRowSparseMatrixMat3x3"/>')
    warped = _run(tmp_path, "warp", WARP.format(iterations=1, rate=1))
    plain = _run(tmp_path, "plain", '<PCGLinearSolver iterations="1" tolerance="1e-30"/>')
    assert np.abs(warped - direct).max() < 1e-10
    assert np.abs(plain - direct).max() > 1e-4  # one unpreconditioned iteration is far from it


def test_rotated_factorisations_are_refused(tmp_path: Path) -> None:
    scene = tmp_path / "rate.scn"
    scene.write_text(SCENE.format(solver=WARP.format(iterations=10, rate=3)))
    with pytest.raises(sofac.SceneError, match=r"E222.*assemblingRate > 1"):
        sofac.load(scene)
