"""LinearSolverConstraintCorrection (runtime/sofac/linear_correction.h): the compliance of a state
through its ODE solver's factorisation, W += dt J A⁻¹ Jᵀ, and the correction dx = A⁻¹ Jᵀ f,
x = x_free + dt dx, v = v_free + dx (SOFA's LinearSolverConstraintCorrection.inl with
EulerImplicitSolver's integration factors).

Checked against: W and dx computed by NumPy from the same sparse matrix (the kernels as C++), a
particle resting on a floor (impulse m g dt, at the contact distance; A = M, so the same run as
UncoupledConstraintCorrection with compliance 1/m), and SOFA's fallingBeamLagrangianCollision.scn
run past its first contacts (step 46) to rest on the floor.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from lagrangian_scenes import CONTACT, DT, G, contact_root, static_floor
from sofac.check.checker import check_file
from sofac.diagnostics import SceneError
from sofac.plan.planner import plan_scene

MASS = 2.0

SHIM = r"""
#include "sofac/linear_correction.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

// A (n x n, dense input, its non-zeros assembled) factorised L D L^T, DOF i fixed when fixed[i];
// J: `rows` rows of Vec3d entries (row_index, start, dof, values). Out: W (rows x rows, factor dt,
// regularization reg) and, for the forces f, lambda = J^T f and dx = A^-1 lambda, x and v moved
// from x_free, v_free by dt dx and dx.
API void run(Index n, const double* A, const Index* fixed, Index rows, const Index* row_index,
             const Index* start, const Index* dof, const double* values, double dt, double reg, double* W,
             const double* f, double* x, double* v, double* lambda, double* dx) {
    sofac::DirectSolver D;
    D.resize(n);
    for (Index i = 0; i < n; ++i) D.fixed[i] = fixed[i] != 0;
    D.assembler.start_pattern();
    for (Index i = 0; i < n; ++i)
        for (Index j = 0; j < n; ++j)
            if (A[n * i + j] != 0.0) D.assembler.add(i, j, 0.0);
    D.assembler.finish_pattern(D.matrix, n, D.fixed);
    D.analyze(sofac::Factorization::LDLT);
    D.assembler.start_values(D.matrix);
    for (Index i = 0; i < n; ++i)
        for (Index j = 0; j < n; ++j)
            if (A[n * i + j] != 0.0) D.assembler.add(i, j, A[n * i + j]);
    D.factor();
    const sofac::JacobianRows J{rows, row_index, start, dof, values};
    const Index m = row_index[rows - 1] + 1;
    sofac::CompliancePattern P;
    P.start(W, m);  // (a fresh pattern clears all of W)
    sofac::linear_add_compliance<sofac::Vec3d>(P, W, J, D, 0, dt, reg);
    sofac::linear_correct<sofac::Vec3d>(x, v, lambda, dx, J, f, n / 3, D, 0, dt, 1.0);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    return build_shim(tmp_path_factory, "linear_correction", SHIM, optimize="-O1", cholmod=True)


def _spd(points: int, seed: int) -> np.ndarray:
    """A symmetric positive definite system of `points` Vec3d DOFs, sparse (a chain of couplings)."""
    rng = np.random.default_rng(seed)
    n = 3 * points
    A = np.zeros((n, n))
    for p in range(points - 1):
        block = rng.normal(size=(6, 6))
        A[3 * p : 3 * p + 6, 3 * p : 3 * p + 6] += block @ block.T
    return A + n * np.eye(n)


@pytest.mark.parametrize("fixed_point", [None, 1])
def test_compliance_and_correction_match_numpy(lib: ctypes.CDLL, fixed_point: int | None) -> None:
    points, dt, reg = 5, DT, 1e-3
    n = 3 * points
    A = _spd(points, seed=7)
    fixed = np.zeros(n, dtype=np.int64)
    if fixed_point is not None:
        fixed[3 * fixed_point : 3 * fixed_point + 3] = 1
    # three rows (ids 0, 2, 3): row 1 of W is nobody's; row 3 touches the fixed point
    row_index = np.array([0, 2, 3], dtype=np.int64)
    start = np.array([0, 2, 3, 5], dtype=np.int64)
    dof = np.array([0, 3, 2, 1, 4], dtype=np.int64)
    rng = np.random.default_rng(3)
    values = rng.normal(size=(5, 3))
    m = 4
    J = np.zeros((m, n))
    for r, row in enumerate(row_index):
        for e in range(start[r], start[r + 1]):
            J[row, 3 * dof[e] : 3 * dof[e] + 3] += values[e]
    W = np.zeros(m * m)
    f = np.array([0.5, 0.0, -1.25, 2.0])
    x_free, v_free = rng.normal(size=n), rng.normal(size=n)
    x, v, lam, dx = x_free.copy(), v_free.copy(), np.zeros(n), np.zeros(n)
    lib.run(
        n, _d(A.ravel().copy()), _i(fixed), 3, _i(row_index), _i(start), _i(dof), _d(values.ravel().copy()),
        ctypes.c_double(dt), ctypes.c_double(reg), _d(W), _d(f), _d(x), _d(v), _d(lam), _d(dx),
    )  # fmt: skip
    # the projected system (fixed rows and columns cleared, unit diagonal): the free DOFs see the
    # inverse of A's free block; fixed DOFs get no right-hand side, so no response
    free = fixed == 0
    Ainv = np.zeros((n, n))
    Ainv[np.ix_(free, free)] = np.linalg.inv(A[np.ix_(free, free)])
    expected = dt * J @ Ainv @ J.T + reg * np.diag([1.0, 0.0, 1.0, 1.0])
    assert np.allclose(W.reshape(m, m), expected, rtol=1e-12, atol=1e-15)
    assert np.array_equal(W.reshape(m, m), W.reshape(m, m).T)
    assert np.allclose(lam, J.T @ f, rtol=1e-14, atol=1e-15)
    correction = Ainv @ (J.T @ f)
    assert np.allclose(dx, dt * correction, rtol=1e-12, atol=1e-15)
    assert np.allclose(x, x_free + dt * correction, rtol=1e-12, atol=1e-14)
    assert np.allclose(v, v_free + correction, rtol=1e-12, atol=1e-14)
    if fixed_point is not None:
        assert np.all(dx[3 * fixed_point : 3 * fixed_point + 3] == 0.0)


def particle_scene(tmp_path: Path, correction: str, *, linear: str = "<SparseLDLSolver/>") -> Path:
    """A particle (mass 2) above a static floor of two triangles, no damping, its correction given."""
    text = (
        contact_root('<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="100"/>')
        + f"""    <Node name="Particle">
        <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0" />
        {linear}
        <MechanicalObject name="dofs" position="0.3 0.1 0.2" />
        <UniformMass totalMass="{MASS}" />
        {correction}
        <PointCollisionModel />
    </Node>
"""
        + static_floor("-1 0 -1  1 0 -1  1 0 1  -1 0 1")
        + "</Node>\n"
    )
    path = tmp_path / f"particle_{abs(hash(correction + linear))}.scn"
    path.write_text(text)
    return path


def _run(path: Path, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sim = sofac.load(path)
    heights, velocities, impulses = [], [], []
    for _ in range(steps):
        sim.step(1)
        heights.append(sim["/Particle/dofs"].position[0, 1])
        velocities.append(sim["/Particle/dofs"].velocity[0, 1])
        impulses.append(sim.output("/.constraint_f")[0])
    return np.array(heights), np.array(velocities), np.array(impulses)


def test_a_particle_rests_on_the_floor_with_the_weight_as_impulse(tmp_path: Path) -> None:
    heights, velocities, impulses = _run(particle_scene(tmp_path, "<LinearSolverConstraintCorrection/>"), 120)
    # lands within 20 steps, then rests at the contact distance (a plastic impact), no drift
    assert np.abs(heights[20:] - CONTACT).max() < 1e-12
    assert np.abs(velocities[20:]).max() < 1e-12
    # A = M: W = dt / m, and the normal impulse carries the weight over the step, m g dt
    assert np.allclose(impulses[20:], MASS * G * DT, rtol=1e-12, atol=0)


def test_it_agrees_with_the_uncoupled_correction_where_a_is_the_mass(tmp_path: Path) -> None:
    # one point mass and no stiffness: A = M, so A^-1 = 1/m = the uncoupled compliance
    linear = _run(particle_scene(tmp_path, "<LinearSolverConstraintCorrection/>"), 60)
    uncoupled_scene = particle_scene(tmp_path, f'<UncoupledConstraintCorrection compliance="{1 / MASS}"/>')
    uncoupled = _run(uncoupled_scene, 60)
    for a, b in zip(linear, uncoupled, strict=True):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-15)
    assert linear[2][-1] > 0  # in contact at the end


def _plan_error(path: Path, code: str) -> tuple[int, str | None, str]:
    checked, _ = check_file(path)
    assert checked is not None
    with pytest.raises(SceneError) as error:
        plan_scene(checked)
    (diagnostic,) = [d for d in error.value.diagnostics if d.code == code]
    return diagnostic.loc.line, diagnostic.loc.attribute, diagnostic.message


def test_wire_optimization_is_refused_at_its_attribute(tmp_path: Path) -> None:
    path = particle_scene(tmp_path, '<LinearSolverConstraintCorrection wire_optimization="1"/>')
    line, attribute, message = _plan_error(path, "E222")
    assert (line, attribute) == (15, "wire_optimization") and "wire_optimization=1" in message


def test_an_iterative_linear_solver_is_refused_with_contacts(tmp_path: Path) -> None:
    path = particle_scene(
        tmp_path,
        "<LinearSolverConstraintCorrection/>",
        linear='<CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-20"/>',
    )
    line, _, message = _plan_error(path, "E222")
    assert line == 15 and "its linear solver (CGLinearSolver) must be the sparse direct solver" in message


@pytest.mark.long
def test_falling_beam_lands_and_comes_to_rest_on_the_floor(shared_dir: Path) -> None:
    # SOFA's Demos/fallingBeamLagrangianCollision.scn: an FEM beam (EulerImplicit, PCG with a
    # SparseLDL preconditioner, LinearSolverConstraintCorrection on it) falls 1.0 onto a box; its
    # first contacts come at step 46, where the contact guard used to stop it.
    sim = sofac.load(shared_dir / "corpus/sofa/Demos/fallingBeamLagrangianCollision.scn")
    beam = sim["/FEM/mstate"]
    x0 = beam.position.copy()
    above = (x0[:, 2] == 0.0) & (x0[:, 0] >= 0.1) & (x0[:, 0] <= 0.4)  # the underside over the box
    contacts = []
    with pytest.warns(RuntimeWarning, match="iteration limit"):  # BGS at 200 iterations, as SOFA
        for _ in range(200):
            sim.step(1)
            contacts.append(sim.output("/Pipeline.contactReport")[0])
    x, v = beam.position, beam.velocity
    assert np.isfinite(x).all() and np.isfinite(v).all()
    contacts_arr = np.array(contacts)
    assert contacts_arr[:45].max() == 0 and contacts_arr[60:].min() > 0  # contact from ~step 46 on
    # at rest on the box top (z = -1): the underside over it at the contact distance (0.003:
    # the intersection's 0.001 and each model's 0.001), never through it
    gap = x[above, 2] - (-1.0)
    assert gap.min() > 0.0 and np.abs(gap - 0.003).max() < 2e-5  # measured: 0.0030003 on average
    assert np.abs(v).max() < 1e-4
    # at rest the normal impulses carry the beam's weight over the step: m g dt (m = 1)
    normals = sim.output("/.constraint_f")[: 3 * int(contacts[-1]) : 3]
    assert normals.min() >= 0.0 and normals.sum() == pytest.approx(1.0 * 9.81 * 0.01, rel=1e-3)


SPRING = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop name="loop"/>
    <BlockGaussSeidelConstraintSolver maxIterations="200" tolerance="1e-14"/>
    <Node name="A">
        <EulerImplicitSolver rayleighMass="0.5" rayleighStiffness="0"/>
        <SparseLDLSolver/>
        <MechanicalObject name="dofs" position="0 1 0  0 0 0"/>
        <UniformMass vertexMass="0.5"/>
        <SpringForceField spring="0 1 100 0 1"/>
        <LinearSolverConstraintCorrection/>
    </Node>
    <Node name="B">
        <MechanicalObject name="anchor" position="0 1 0"/>
    </Node>
    <BilateralLagrangianConstraint object1="@B/anchor" object2="@A/dofs" first_point="0" second_point="0"/>
</Node>
"""


def test_a_spring_pair_hangs_from_its_anchor_through_the_coupled_compliance(tmp_path: Path) -> None:
    """Two points joined by a spring (k 100, length 1), the upper one held by a bilateral row: A
    couples them, so the row's correction moves both. At rest the upper point is at the anchor, the
    lower one 1 + m g / k below, and the row's impulse per step carries both weights, 2 m g dt."""
    path = tmp_path / "spring.scn"
    path.write_text(SPRING)
    sim = sofac.load(path)
    sim.step(1500)
    dofs = sim["/A/dofs"]
    m, g, k = 0.5, 9.81, 100.0
    np.testing.assert_allclose(dofs.position[0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(dofs.position[1], [0.0, -m * g / k, 0.0], atol=1e-9)
    np.testing.assert_allclose(dofs.velocity, 0.0, atol=1e-8)  # (the swing decays: 2e-9 left)
    impulse = sim.output("/.constraint_kept_forces")
    np.testing.assert_allclose(impulse / 0.01, [0.0, 2 * m * g, 0.0], rtol=1e-7, atol=1e-9)
