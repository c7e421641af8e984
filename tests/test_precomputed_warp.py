"""PrecomputedWarpPreconditioner as SOFA runs it: its PrecomputedMatrixSystem assembles nothing, so the
precomputed inverse is 0x0 and applying it leaves the PCG's output vector (a fresh zero one) as it
was; r.z = 0 then stops the PCG before its first iteration, every step: dv stays 0, velocities keep
their initial values and positions move with them (SOFA's regression reference of
FEMBAR_PCG_PrecomputedWarpPreconditioner.scn is exactly its initial state)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

SCENE = """<Node name="root" dt="0.02" gravity="0 -10 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
  <MechanicalObject name="dofs" velocity="{velocity}"/>
  <UniformMass totalMass="50"/>
  <RegularGridTopology nx="2" ny="2" nz="4" xmin="0" xmax="1" ymin="0" ymax="1" zmin="0" zmax="6"/>
  <PreconditionedMatrixFreeSystem name="free" assemblingRate="1"/>
  <PCGLinearSolver iterations="100" linearSystem="@free" preconditioner="@warp" use_precond="{use}"/>
  <{system} name="precomputed"/>
  <PrecomputedWarpPreconditioner name="warp" linearSystem="@precomputed" linearSolver="@ldl"{extra}/>
  <MatrixLinearSystem template="CompressedRowSparseMatrixMat3x3" name="system"/>
  <SparseLDLSolver name="ldl" template="CompressedRowSparseMatrixMat3x3" linearSystem="@system"/>
  <TetrahedronFEMForceField youngModulus="3000" poissonRatio="0.3" method="large"/>
</Node>
"""
V0 = np.array([0.5, -0.25, 1.0])  # one initial velocity for the 16 nodes


def _scene(
    tmp_path: Path, use: str = "true", system: str = "PrecomputedMatrixSystem", extra: str = ""
) -> Path:
    scene = tmp_path / "pwarp.scn"
    velocity = " ".join(f"{c:g}" for c in np.tile(V0, 16))
    scene.write_text(SCENE.format(velocity=velocity, use=use, system=system, extra=extra))
    return scene


def test_the_pcg_keeps_dv_zero_and_states_move_with_their_initial_velocity(tmp_path: Path) -> None:
    sim = sofac.load(_scene(tmp_path))
    x0 = np.asarray(sim["/dofs"].position).copy()
    sim.step(25)
    expected = x0.copy()
    for _ in range(25):  # x += h v, as the step does
        expected += 0.02 * V0
    np.testing.assert_array_equal(np.asarray(sim["/dofs"].velocity), np.tile(V0, (16, 1)))
    assert np.abs(np.asarray(sim["/dofs"].position) - expected).max() < 1e-12


def test_without_the_preconditioner_the_pcg_moves_the_body(tmp_path: Path) -> None:
    sim = sofac.load(_scene(tmp_path, use="false"))
    sim.step(25)
    velocity = np.asarray(sim["/dofs"].velocity)
    assert np.abs(velocity - V0).max() > 1.0  # gravity alone adds 5 in y over 0.5 s, free fall


@pytest.mark.parametrize(
    ("system", "extra", "message"),
    [
        ("MatrixLinearSystem", "", "its linearSystem must link a PrecomputedMatrixSystem"),
        ("PrecomputedMatrixSystem", ' use_rotations="false"', "use_rotations false"),
        ("PrecomputedMatrixSystem", ' share_matrix="false"', "share_matrix false"),
    ],
)
def test_configurations_where_sofa_differs_are_refused(
    tmp_path: Path, system: str, extra: str, message: str
) -> None:
    with pytest.raises(sofac.SceneError, match=rf"E222.*PrecomputedWarpPreconditioner.*{message}"):
        sofac.load(_scene(tmp_path, system=system, extra=extra))
