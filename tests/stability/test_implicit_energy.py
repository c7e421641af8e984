"""Implicit Euler on a stiff elastic body at a large step: bounded, and its total energy never grows.

A clamped cantilever of linear tetrahedra (E = 1e9, nu = 0.45, 5 kg) at dt = 0.05, far beyond the
explicit limit of its stiffest modes, starts with random velocities. For a linear elastic system
backward Euler is unconditionally dissipative: kinetic + elastic + gravitational energy must fall
at every step (to rounding), whichever linear solver solves the step exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

SCENE = """\
<Node name="root" gravity="0 -9.81 0" dt="0.05"><DefaultAnimationLoop/>
  <Node name="beam">
    <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
    {linear}
    <RegularGridTopology name="grid" n="6 3 3" min="0 0 0" max="1 0.2 0.2"/>
    <MechanicalObject name="dofs"/>
    <UniformMass totalMass="5"/>
    <BoxROI name="clamp" box="-0.01 -0.01 -0.01 0.01 0.21 0.21"/>
    <FixedProjectiveConstraint indices="@clamp.indices"/>
    <TetrahedronFEMForceField youngModulus="1e9" poissonRatio="0.45" method="small"/>
  </Node>
</Node>
"""
LINEAR = {
    "sparse-ldl": "<SparseLDLSolver/>",
    "cg": '<CGLinearSolver iterations="300" tolerance="1e-24" threshold="1e-40"/>',
}


@pytest.mark.parametrize("linear", list(LINEAR))
def test_stiff_linear_fem_at_large_dt_loses_energy_every_step(tmp_path: Path, linear: str) -> None:
    path = tmp_path / "stiff.scn"
    path.write_text(SCENE.format(linear=LINEAR[linear]))
    sim = sofac.load(path)
    dofs = sim["dofs"]
    dofs.velocity[:] = np.random.default_rng(7).normal(size=dofs.velocity.shape)
    dofs.velocity[dofs.position[:, 0] < 0.01] = 0.0  # the clamped face
    energies = [sim.energy().total]
    for _ in range(40):
        sim.step(1)
        energies.append(sim.energy().total)
    energies = np.array(energies)
    assert np.all(np.diff(energies) <= 1e-12 * np.abs(energies[:-1])), np.diff(energies).max()
    assert energies[-1] < 0.6 * energies[0]  # most of the initial kinetic energy is gone
    assert np.isfinite(dofs.position).all() and np.abs(dofs.position).max() < 1.01
