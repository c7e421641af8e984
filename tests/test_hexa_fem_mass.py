"""HexahedronFEMForceFieldAndMass: SOFA's element mass matrix (every node pair of an element holds
vol * density * 8/27 on its 3 diagonal DOF pairs, SOFA's integrateMass), its weight from the
particle masses vol * density / 8, and the stiffness of HexahedronFEMForceField."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

SCENE = """<Node name="root" dt="{dt}" gravity="0 -9.81 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="200" tolerance="1e-30" threshold="1e-30"/>
  <MechanicalObject name="state"/>
  <RegularGridTopology nx="3" ny="2" nz="2" xmin="0" xmax="4" ymin="0" ymax="1.5" zmin="0" zmax="0.5"/>
  <HexahedronFEMForceFieldAndMass youngModulus="{young}" poissonRatio="0.3" density="{rho}"
    lumpedMass="{lumped}"/>
</Node>
"""
VOLUME = 2.0 * 1.5 * 0.5  # each of the 2 cells


def _load(
    tmp_path: Path, lumped: bool, dt: float = 0.01, young: float = 1000.0, rho: float = 3.0
) -> sofac.Simulation:
    scene = tmp_path / f"hexa_mass_{int(lumped)}.scn"
    scene.write_text(SCENE.format(dt=dt, young=young, rho=rho, lumped=str(lumped).lower()))
    return sofac.load(scene)


@pytest.mark.parametrize("lumped", [False, True])
def test_free_fall_follows_sofas_mass(tmp_path: Path, lumped: bool) -> None:
    """A free body: the weight per node is (cells of the node) * vol rho / 8 and M 1 per node is
    (cells of the node) * 8 * vol rho 8/27 (consistent and lumped alike), and K of a translation
    is 0: one implicit step gives every node dv = h g 27/512 (SOFA's mass is not the body's)."""
    sim = _load(tmp_path, lumped)
    sim.step(1)
    velocity = np.asarray(sim["/state"].velocity)
    expected = 0.01 * -9.81 * 27.0 / 512.0
    assert np.abs(velocity[:, 1] - expected).max() < 1e-13
    assert np.abs(velocity[:, [0, 2]]).max() < 1e-13
    # 1/2 v^T M v with M 1 = 8 * 8/27 vol rho per cell of a node: 12 nodes, 16 node-cells.
    node_cells = 16
    kinetic = 0.5 * node_cells * 8 * (8.0 / 27.0) * VOLUME * 3.0 * expected**2
    assert sim.energy().kinetic == pytest.approx(kinetic, rel=1e-12)


def _mass_matrix(lumped: bool, rho: float) -> np.ndarray:
    """SOFA's scalar mass matrix of the two cells, by hand."""
    m = VOLUME * rho * 8.0 / 27.0
    matrix = np.zeros((12, 12))
    for first in (0, 1):  # cell x in [first, first + 1]; node index x + 3 (y + 2 z)
        nodes = [x + 3 * (y + 2 * z) for z in (0, 1) for y in (0, 1) for x in (first, first + 1)]
        matrix[np.ix_(nodes, nodes)] += m
    return np.diag(matrix.sum(axis=1)) if lumped else matrix


@pytest.mark.parametrize("lumped", [False, True])
def test_held_body_solves_with_sofas_matrix(tmp_path: Path, lumped: bool) -> None:
    """Nodes 0, 3, 6, 9 (x = 0) fixed, a negligible stiffness: one implicit step solves
    M_free dv = h weight_free, the weight being vol rho / 8 g per cell of the node. SOFA's
    consistent matrix has rank 1 per cell: CG from 0 finds its least-norm solution."""
    rho, h = 3.0, 0.01
    scene = tmp_path / f"held_{int(lumped)}.scn"
    text = SCENE.format(dt=h, young=1e-9, rho=rho, lumped=str(lumped).lower())
    text = text.replace(
        '<MechanicalObject name="state"/>',
        '<MechanicalObject name="state"/>\n  <FixedProjectiveConstraint indices="0 3 6 9"/>',
    )
    scene.write_text(text)
    sim = sofac.load(scene)
    sim.step(1)
    velocity = np.asarray(sim["/state"].velocity)
    cells = np.array([1, 2, 1] * 4)
    weight = cells * VOLUME * rho / 8.0 * -9.81
    free = [i for i in range(12) if i % 3 != 0]
    matrix = _mass_matrix(lumped, rho)
    expected = np.zeros(12)
    expected[free] = np.linalg.lstsq(matrix[np.ix_(free, free)], h * weight[free], rcond=None)[0]
    assert np.abs(velocity[:, 1] - expected).max() < 1e-9 * np.abs(expected).max()
    assert np.abs(velocity[:, [0, 2]]).max() < 1e-12
    assert np.abs(velocity[[0, 3, 6, 9]]).max() == 0.0
    kinetic = 0.5 * expected @ matrix @ expected
    assert sim.energy().kinetic == pytest.approx(kinetic, rel=1e-8)
