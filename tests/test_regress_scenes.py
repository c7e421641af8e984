"""SOFA regression scenes that pass with the components added for issue #4, run for real with
SOFA's criterion (each scene compiles and runs its full length: a few seconds each)."""

from __future__ import annotations

from pathlib import Path

import pytest
from sofac.regress import Status, run_regression

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
]


@pytest.mark.parametrize("scene", SCENES)
def test_regression_scene_passes(shared_dir: Path, scene: str) -> None:
    root = shared_dir / "reference" / "sofa-regression"
    (result,) = run_regression(
        root / "scenes.regression-tests", shared_dir / "corpus" / "sofa", root, only=[scene]
    )
    assert result.status is Status.PASS, (result.status, result.message, result.error)
    assert result.error is not None and result.error <= result.epsilon
