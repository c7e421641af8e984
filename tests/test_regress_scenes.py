"""SOFA regression scenes that pass with the components added for issue #4, run for real with
SOFA's criterion (each scene compiles and runs its full length: a few seconds each)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.regress.suite import Status, run_regression

SCENES = [
    "Component/SolidMechanics/FEM/HexahedronFEMForceFieldAndMass.scn",
    "Component/SolidMechanics/Spring/FastTriangularBendingSprings.scn",  # with TriangularFEMForceFieldOptim
    "Component/Mapping/NonLinear/DistanceMapping.scn",
    "Component/Topology/Mapping/Mesh2PointTopologicalMapping.scn",
    "Component/LinearSolver/Iterative/FEMBAR_MinResLinearSolver.scn",
    "Component/MechanicalLoad/InteractionEllipsoidForceField.scn",  # with QuadBendingSprings
    "Component/Mapping/NonLinear/DistanceMultiMapping.scn",  # with TransformEngine, UniformVelocityDamping
    "Component/LinearSolver/Preconditioner/FEMBAR_PCG_WarpPreconditioner.scn",
    # PrecomputedMatrixSystem: SOFA's run, and its reference, never move from the initial state
    "Component/LinearSolver/Preconditioner/FEMBAR_PCG_PrecomputedWarpPreconditioner.scn",
    "Demos/TriangleSurfaceCutting.scn",  # TriangularFEMForceField + TriangularBendingSprings, loader scale
    # Chaotic scenes (one ulp on an initial coordinate moves the final state by up to 1e-3): they pass
    # only when every operation is SOFA's, here DiagonalMass's (dx m) mfact and, for the second,
    # RestShapeSpringsForceField's (dx k) kfact.
    "Component/SolidMechanics/FEM/TriangularFEMForceFieldOptim.scn",
    "Component/Mapping/NonLinear/SquareDistanceMapping.scn",
    # Two collision models (sphere surfaces of two livers that never come within reach): the contact
    # guard tests their boxes before each of the 10,000 steps and never stops the run.
    "Component/Topology/Container/Grid/RegularGridTopology.scn",
    # Three dragons voxelised by SparseGridTopology (SOFA's points, in SOFA's order), MeshSpringForceField
    # on its hexahedra, barycentric sphere surfaces that never touch.
    "Component/Topology/Container/Grid/SparseGridTopology.scn",
    # FreeMotionAnimationLoop with no contact in the compared steps: EulerImplicit + PCG preconditioned
    # by SparseLDLSolver, Tetra2Triangle surface (the guard stops it only at step 46, not compared).
    "Demos/fallingBeamLagrangianCollision.scn",
]


@pytest.mark.parametrize("scene", SCENES)
def test_regression_scene_passes(shared_dir: Path, scene: str) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[scene]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon


def test_liver_matches_sofa_bit_for_bit(shared_dir: Path) -> None:
    """Demos/liver.scn (DiagonalMass on tetrahedra, corotational FEM, implicit Euler + CG) against the
    17-digit run of SOFA in reference/sofa/data: positions and velocities equal after 99 and 100
    steps, which needs DiagonalMass::addMDx's operation order, (dx m) mfact."""
    data = shared_dir / "reference" / "sofa" / "data" / "real_Demos_liver.liver_dofs.csv"
    if not data.exists():
        pytest.skip("SOFA's liver reference is not available")
    rows = np.genfromtxt(data, delimiter=",", names=True)
    sim = sofac.load(shared_dir / "corpus" / "sofa" / "Demos" / "liver.scn")
    (path,) = [state.path for state in sim.states() if state.path.endswith("/dofs")]
    done = 0
    for step in (99, 100):
        sim.step(step - done)
        done = step
        block = rows[rows["step"] == step]
        block = block[np.argsort(block["dof"])]
        position = np.stack([block["x"], block["y"], block["z"]], axis=1)
        velocity = np.stack([block["vx"], block["vy"], block["vz"]], axis=1)
        assert np.array_equal(sim[path].position, position), step
        assert np.array_equal(sim[path].velocity, velocity), step


def test_falling_beam_meets_the_floor_at_step_46(shared_dir: Path) -> None:
    """fallingBeamLagrangianCollision.scn: its 45 compared steps are free motion (no contact can be
    detected), then step 46, whose start has the beam's surface within NewProximityIntersection's
    alarm distance of the floor, runs with contacts (LinearSolverConstraintCorrection on the PCG's
    SparseLDL preconditioner; the run to rest: tests/test_linear_solver_correction.py)."""
    sim = sofac.load(shared_dir / "corpus" / "sofa" / "Demos" / "fallingBeamLagrangianCollision.scn")
    sim.step(45)
    bottom = float(np.asarray(sim["/FEM/mstate"].position)[:, 2].min())
    assert -1.0 < bottom < -0.999  # 0.4 mm above the floor's top (z = -1)
    assert sim.output("/Pipeline.contactReport")[0] == 0
    with pytest.warns(sofac.ContactWarning, match="step 46"):  # it moves 4 cm a step, alarm 2 cm
        sim.step(1)
    assert sim.output("/Pipeline.contactReport")[0] > 0
    assert np.isfinite(sim["/FEM/mstate"].position).all()
