"""MinResLinearSolver: SOFA's MINRES inside the implicit Euler step. Converged, it gives the step of a
direct solve; capped at one iteration it is one Lanczos step: dv = (b.b / b.Ab) b for dv0 = 0."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import sofac

SCENE = """<Node name="root" dt="0.02" gravity="0 -10 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
  {solver}
  <MechanicalObject name="dofs"/>
  <UniformMass totalMass="50"/>
  <RegularGridTopology nx="2" ny="2" nz="5" xmin="0" xmax="1" ymin="0" ymax="1" zmin="0" zmax="6"/>
  <FixedProjectiveConstraint indices="0 1 2 3"/>
  <HexahedronFEMForceField youngModulus="3000" poissonRatio="0.3" method="large"/>
</Node>
"""


def _run(tmp_path: Path, name: str, solver: str, steps: int) -> np.ndarray:
    scene = tmp_path / f"{name}.scn"
    scene.write_text(SCENE.format(solver=solver))
    sim = sofac.load(scene)
    sim.step(steps)
    return np.asarray(sim["/dofs"].position).copy()


def test_converged_minres_is_the_direct_solve(tmp_path: Path) -> None:
    direct = _run(tmp_path, "ldl", '<SparseLDLSolver template="CompressedRowSparseMatrixMat3x3d"/>', 10)
    minres = _run(tmp_path, "minres", '<MinResLinearSolver iterations="500" tolerance="1e-14"/>', 10)
    start = _run(tmp_path, "start", '<MinResLinearSolver iterations="500" tolerance="1e-14"/>', 0)
    assert np.abs(direct - start).max() > 1e-2  # the beam bent
    assert np.abs(minres - direct).max() < 1e-9 * np.abs(direct - start).max()


def test_one_iteration_is_one_lanczos_step(tmp_path: Path) -> None:
    """First step from rest: dv0 = 0 and b = h f, the projected weight, the same on every free node.
    One MINRES iteration minimises |b - A x| over x in span(b): dv is along b, so every free node
    moves by the same amount, straight down; the converged solve bends the beam (not uniform)."""
    one = _run(tmp_path, "one", '<MinResLinearSolver iterations="1" tolerance="1e-14"/>', 1)
    converged = _run(tmp_path, "conv", '<MinResLinearSolver iterations="500" tolerance="1e-14"/>', 1)
    start = _run(tmp_path, "start1", '<MinResLinearSolver iterations="1" tolerance="1e-14"/>', 0)
    moved = (one - start)[4:]
    assert np.abs(moved[:, [0, 2]]).max() == 0.0
    assert moved[0, 1] < 0
    assert np.abs(moved[:, 1] - moved[0, 1]).max() < 1e-14
    bent = (converged - start)[4:, 1]
    assert np.abs(bent - bent[0]).max() > 1e-3 * np.abs(bent).max()
