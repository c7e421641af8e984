"""Every linear solver sofac compiles gives the same implicit Euler step.

One block (corotational tetrahedra on a grid, a consistent MeshMatrixMass so that the mass matrix
is not diagonal, Rayleigh damping, a clamped face) per linear solver, each in its own node of one
scene with its own EulerImplicitSolver, all stepped from the same deformed, moving state: the
system ((1 + h rm) M - h (h + rk) K) dv = b then involves every term of SOFA's EulerImplicitSolver.
Conjugate gradient run to a tight tolerance (matrix-free, assembled, and PCGLinearSolver with each
preconditioner) and every sparse direct solver must agree on dv, hence on the new velocities and
positions, to round-off relative to the step (measured: 1e-14 for CG and PCG; the L D L^T direct
solvers share one sparse factorisation and agree exactly, the L L^T ones, SparseCholeskySolver and
EigenSimplicialLLT, factor L L^T instead). PrecomputedLinearSolver factorises the first step's
matrix, so it agrees on that first step; later, its frozen matrix makes it differ, by much more
than round-off. (tests/test_compile.py checks a few of them over 15 steps of another scene.)
"""

from __future__ import annotations

import numpy as np
import pytest
import sofac

BLOCK = """\
  <Node name="{name}">
    <EulerImplicitSolver rayleighStiffness="0.05" rayleighMass="0.2"/>
    {solver}
    <RegularGridTopology name="grid" n="3 4 3" min="0 0 0" max="0.4 0.9 0.3"/>
    <MechanicalObject template="Vec3d" name="dofs"/>
    <MeshMatrixMass massDensity="800"/>
    <BoxROI name="clamp" box="-1 -0.001 -1  1 0.001 1"/>
    <FixedProjectiveConstraint indices="@clamp.indices"/>
    <TetrahedronFEMForceField method="large" youngModulus="2e4" poissonRatio="0.35"/>
  </Node>
"""

TIGHT_CG = 'iterations="5000" tolerance="1e-16" threshold="1e-40"'
SOLVERS = {
    "CGLinearSolver": f"<CGLinearSolver {TIGHT_CG}/>",
    "CGLinearSolver assembled": f'<CGLinearSolver template="CompressedRowSparseMatrixd" {TIGHT_CG}/>',
    "PCGLinearSolver": '<PCGLinearSolver iterations="5000" tolerance="1e-32"/>',
    "PCG Jacobi": '<PCGLinearSolver iterations="5000" tolerance="1e-32" preconditioner="@p"/>'
    '<JacobiPreconditioner name="p"/>',
    "PCG block Jacobi": '<PCGLinearSolver iterations="5000" tolerance="1e-32" preconditioner="@p"/>'
    '<BlockJacobiPreconditioner name="p"/>',
    "PCG SSOR": '<PCGLinearSolver iterations="5000" tolerance="1e-32" preconditioner="@p"/>'
    '<SSORPreconditioner name="p"/>',
    "SparseLDLSolver": "<SparseLDLSolver/>",
    "SparseCholeskySolver": "<SparseCholeskySolver/>",
    "SparseLUSolver": "<SparseLUSolver/>",
    "EigenSimplicialLDLT": "<EigenSimplicialLDLT/>",
    "EigenSimplicialLLT": "<EigenSimplicialLLT/>",
    "EigenSparseLU": "<EigenSparseLU/>",
    "EigenSparseQR": "<EigenSparseQR/>",
    "PrecomputedLinearSolver": "<PrecomputedLinearSolver/>",
}


def start_state(rest: np.ndarray, fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(12)
    x = rest + 0.03 * rng.standard_normal(rest.shape)
    v = 0.5 * rng.standard_normal(rest.shape)
    x[fixed], v[fixed] = rest[fixed], 0.0
    return x, v


def node(index: int) -> str:
    return f"block{index}"


def scene_text() -> str:
    blocks = "".join(BLOCK.format(name=node(i), solver=solver) for i, solver in enumerate(SOLVERS.values()))
    return f'<Node name="root" gravity="0 -9.81 0" dt="0.05"><DefaultAnimationLoop/>\n{blocks}</Node>\n'


@pytest.fixture(scope="module")
def steps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Per solver: (x, v) after each of three steps from the same start."""
    path = tmp_path_factory.mktemp("solvers") / "solvers.scn"
    path.write_text(scene_text())
    sim = sofac.load(path)
    results: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {name: [] for name in SOLVERS}
    for index in range(len(SOLVERS)):
        dofs = sim[f"{node(index)}/dofs"]
        rest = dofs.position.copy()
        x, v = start_state(rest, np.abs(rest[:, 1]) < 1e-9)
        dofs.position[:] = x
        dofs.velocity[:] = v
    results["start"] = [(x, v)]
    for _ in range(3):
        sim.step(1)
        for index, name in enumerate(SOLVERS):
            dofs = sim[f"{node(index)}/dofs"]
            results[name].append((dofs.position.copy(), dofs.velocity.copy()))
    return results


def test_every_solver_gives_the_same_implicit_step(steps: dict) -> None:
    x_ref, v_ref = steps["SparseLDLSolver"][0]
    dv_scale = np.abs(v_ref).max()
    assert dv_scale > 0.1
    for name in SOLVERS:
        x, v = steps[name][0]
        assert np.abs(v - v_ref).max() < 1e-12 * dv_scale, name
        assert np.abs(x - x_ref).max() < 1e-13, name  # x += h v: h times the velocity gap


def test_solvers_stay_together_except_the_precomputed_one(steps: dict) -> None:
    x_ref, v_ref = steps["SparseLDLSolver"][2]
    scale = np.abs(v_ref).max()
    for name in SOLVERS:
        states = steps[name]
        gap = np.abs(states[2][1] - v_ref).max()
        if name == "PrecomputedLinearSolver":
            assert gap > 1e-6 * scale  # the first step's matrix, no longer the current one
        else:
            assert gap < 1e-12 * scale, name
            assert np.abs(states[2][0] - x_ref).max() < 1e-12 * scale, name


def test_the_step_moves_the_block(steps: dict) -> None:
    """The step is not trivial: the velocities change by much more than the agreement asked above."""
    _, v0 = steps["start"][0]
    _, v1 = steps["SparseLDLSolver"][0]
    assert np.abs(v1 - v0).max() > 0.05
