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
    "CGLinearSolver assembled 3x3": '<CGLinearSolver template="CompressedRowSparseMatrixMat3x3d" '
    f"{TIGHT_CG}/>",
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


def test_assembled_and_matrix_free_cg_agree_on_the_step(steps: dict) -> None:
    """CGLinearSolver on the assembled matrix (scalar and 3x3-block CRS templates: SOFA assembles
    mfact M + kfact K, clears the fixed rows and columns and runs CG on it) against the matrix-free
    one, both converged tightly: the same dv to round-off (measured: 1e-15 of the step's largest
    velocity change after the first step, 7e-15 after the third)."""
    _, v0 = steps["start"][0]
    for step in range(3):
        previous = v0 if step == 0 else steps["CGLinearSolver"][step - 1][1]
        x_free, v_free = steps["CGLinearSolver"][step]
        dv = np.abs(v_free - previous).max()
        for name in ("CGLinearSolver assembled", "CGLinearSolver assembled 3x3"):
            x, v = steps[name][step]
            assert np.abs(v - v_free).max() < 1e-12 * dv, (name, step)
            assert np.abs(x - x_free).max() < 1e-12 * dv, (name, step)


# ---- through mappings: a direct solver assembles J^T K J ---------------------------------------
# Each body once with a tight CG (matrix-free: K and M act through J and J^T) and once with a sparse
# direct solver (K and M of the mapped state assembled as J^T K J, J built at init and, for
# RigidMapping, refilled from the current rotations each step). From the same rotated, moving
# start, both must give the same implicit step.
RIGID_BODY = """\
  <Node name="{name}">
    <EulerImplicitSolver rayleighStiffness="0.05" rayleighMass="0.1"/>
    {solver}
    <RegularGridTopology name="frames" n="1 1 4" min="0 0 0" max="0 0 0.9"/>
    <MechanicalObject template="Rigid3d" name="dofs" position="@frames.position"/>
    <FixedProjectiveConstraint indices="0"/>
    <Node name="body">
      <RegularGridTopology name="grid" n="3 3 4" min="-0.2 -0.2 0" max="0.2 0.2 0.9"/>
      <MechanicalObject template="Vec3d" name="points" position="@grid.position"/>
      <UniformMass vertexMass="0.3"/>
      <TetrahedronFEMForceField method="large" youngModulus="3e3" poissonRatio="0.3"/>
      <RigidMapping globalToLocalCoords="true"
          rigidIndexPerPoint="0 0 0 0 0 0 0 0 0 1 1 1 1 1 1 1 1 1 2 2 2 2 2 2 2 2 2 3 3 3 3 3 3 3 3 3"/>
      <Node name="tip">
        <MechanicalObject template="Vec3d" name="corners" size="4"/>
        <SubsetMapping indices="27 29 33 35"/>
        <RestShapeSpringsForceField stiffness="40"/>
        <UniformMass vertexMass="0.2"/>
      </Node>
    </Node>
  </Node>
"""

EMBEDDED_BODY = """\
  <Node name="{name}">
    <EulerImplicitSolver rayleighStiffness="0.05" rayleighMass="0.1"/>
    {solver}
    <RegularGridTopology name="cage" n="2 3 2" min="-0.1 0 -0.1" max="0.5 1.0 0.5"/>
    <MechanicalObject template="Vec3d" name="dofs"/>
    <UniformMass vertexMass="0.1"/>
    <BoxROI name="clamp" box="-1 -0.001 -1  1 0.001 1"/>
    <FixedProjectiveConstraint indices="@clamp.indices"/>
    <Node name="body">
      <RegularGridTopology name="grid" n="3 4 3" min="0 0 0" max="0.4 0.9 0.3"/>
      <MechanicalObject template="Vec3d" name="points"/>
      <UniformMass vertexMass="0.05"/>
      <TetrahedronFEMForceField method="large" youngModulus="2e3" poissonRatio="0.35"/>
      <MeshSpringForceField stiffness="50" damping="0.5"/>
      <BarycentricMapping/>
    </Node>
  </Node>
"""

MAPPED_SOLVERS = {
    "CGLinearSolver": f"<CGLinearSolver {TIGHT_CG}/>",
    "SparseLDLSolver": "<SparseLDLSolver/>",
    "PCG block Jacobi": '<PCGLinearSolver iterations="5000" tolerance="1e-32" preconditioner="@p"/>'
    '<BlockJacobiPreconditioner name="p"/>',
}


def rotated_start(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames turned about random axes (frame 0 kept: it is fixed) and moving."""
    rng = np.random.default_rng(5)
    x, v = rest.copy(), 0.3 * rng.standard_normal((len(rest), 6))
    axes = rng.standard_normal((len(rest), 3))
    angles = 0.4 * rng.random(len(rest))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    x[:, 3:6] = np.sin(angles / 2)[:, None] * axes
    x[:, 6] = np.cos(angles / 2)
    x[:, :3] += 0.05 * rng.standard_normal((len(rest), 3))
    x[0], v[0] = rest[0], 0.0
    return x, v


@pytest.fixture(scope="module")
def mapped_steps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[np.ndarray]]:
    """Per body and solver: the independent velocities after each of two steps from the same start."""
    blocks = []
    for body, template in (("rigid", RIGID_BODY), ("embedded", EMBEDDED_BODY)):
        for index, solver in enumerate(MAPPED_SOLVERS.values()):
            blocks.append(template.format(name=f"{body}{index}", solver=solver))
    path = tmp_path_factory.mktemp("mapped") / "mapped.scn"
    root = '<Node name="root" gravity="0 -9.81 0" dt="0.04"><DefaultAnimationLoop/>'
    path.write_text(f"{root}\n{''.join(blocks)}</Node>\n")
    sim = sofac.load(path)
    results: dict[str, list[np.ndarray]] = {}
    for body in ("rigid", "embedded"):
        for index in range(len(MAPPED_SOLVERS)):
            dofs = sim[f"{body}{index}/dofs"]
            rest = dofs.position.copy()
            if body == "rigid":
                x, v = rotated_start(rest)
            else:
                x, v = start_state(rest, np.abs(rest[:, 1]) < 1e-9)
            dofs.position[:] = x
            dofs.velocity[:] = v
            results[f"{body} start"] = [v.copy()]
    for _ in range(2):
        sim.step(1)
        for body in ("rigid", "embedded"):
            for index, name in enumerate(MAPPED_SOLVERS):
                dofs = sim[f"{body}{index}/dofs"]
                results.setdefault(f"{body} {name}", []).append(dofs.velocity.copy())
    return results


@pytest.mark.parametrize("body", ["rigid", "embedded"])
def test_direct_solves_through_mappings_agree_with_cg(mapped_steps: dict, body: str) -> None:
    cg = mapped_steps[f"{body} CGLinearSolver"]
    change = np.abs(cg[0] - mapped_steps[f"{body} start"][0]).max()
    assert change > 0.05  # the step is far from trivial
    scale = np.abs(cg[1]).max()
    for name in ("SparseLDLSolver", "PCG block Jacobi"):
        for step in range(2):
            gap = np.abs(mapped_steps[f"{body} {name}"][step] - cg[step]).max()
            assert gap < 1e-11 * scale, (name, step, gap)
