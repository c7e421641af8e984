"""PCGLinearSolver preconditioned by a sparse direct solver (SparseLDLSolver...), as
Demos/fallingBeamLagrangianCollision.scn uses it: SOFA's PreconditionedMatrixFreeSystem assembles
the preconditioner's matrix when its counter reaches assemblingRate (every solve by default), the
direct solver factorises it at its next use and applies it as a solve. With the factorisation of
the step's own matrix, one PCG iteration is the direct solve; with an older one it is not.

Tested as C++ (the PCG of runtime/sofac/solvers.h with an exact preconditioner; the refresh
counter) and through small scenes against SparseLDLSolver solving the same step directly.
"""

from __future__ import annotations

import ctypes
import hashlib
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import D, build_shim
from kernel_shim import doubles as _d
from sofac.pipeline import plan_file

SHIM = r"""
#include "sofac/solvers.h"
#include <Eigen/Dense>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

using Space = sofac::StateSpace<sofac::Vec3d, sofac::Vec1d>;
constexpr Space space({2, 1});
constexpr int N = 7;
Space::Vector split(double* a) { return {a, a + 6}; }
using Dense = Eigen::Map<const Eigen::Matrix<double, N, N, Eigen::RowMajor>>;
using Column = Eigen::Map<Eigen::Matrix<double, N, 1>>;
using ConstColumn = Eigen::Map<const Eigen::Matrix<double, N, 1>>;

// PCG on A preconditioned by the exact L D L^T of P (P = A: the exact preconditioner).
API Index pcg_ldl(const double* A, const double* P, const double* b, double* x, Index iterations,
                  double tolerance) {
    const Eigen::LDLT<Eigen::Matrix<double, N, N>> ldl(Dense(P).eval());
    double z[N], p[N], dx[N], df[N], rhs[N];
    for (int i = 0; i < N; ++i) rhs[i] = b[i];
    return sofac::preconditioned_conjugate_gradient(
        space, iterations, tolerance, split(x), split(rhs), split(z), split(p), split(dx), split(df),
        [&] { Column{df} = Dense(A) * ConstColumn{dx}; },
        [&] { Column{df} = ldl.solve(ConstColumn{z}); });
}

// Which of `solves` successive solves refresh the preconditioner (1) at assembling rate `rate`.
API void refreshes(Index rate, Index solves, double* out) {
    std::int64_t counter = rate;
    for (Index i = 0; i < solves; ++i) out[i] = sofac::refresh_due(counter, rate) ? 1.0 : 0.0;
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "pcg_ldl", SHIM)
    library.pcg_ldl.argtypes = [D, D, D, D, ctypes.c_int64, ctypes.c_double]
    library.pcg_ldl.restype = ctypes.c_int64
    library.refreshes.argtypes = [ctypes.c_int64, ctypes.c_int64, D]
    library.refreshes.restype = None
    return library


def _spd(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((7, 7)))
    return (q * np.geomspace(1.0, 1e4, 7)) @ q.T


def _pcg(
    lib: ctypes.CDLL, a: np.ndarray, p: np.ndarray, b: np.ndarray, iterations: int
) -> tuple[np.ndarray, int]:
    x = np.zeros(7)
    a, p, b = (np.ascontiguousarray(m, dtype=np.float64) for m in (a, p, b))
    done = lib.pcg_ldl(_d(a), _d(p), _d(b), _d(x), iterations, 1e-20)
    return x, int(done)


def test_an_exact_preconditioner_converges_in_one_iteration(lib: ctypes.CDLL) -> None:
    a = _spd(1)
    b = np.random.default_rng(2).standard_normal(7)
    x, done = _pcg(lib, a, a, b, 25)
    exact = np.linalg.solve(a, b)
    assert done == 1
    assert np.abs(x - exact).max() <= 1e-12 * np.abs(exact).max()


def test_a_stale_preconditioner_needs_more_iterations(lib: ctypes.CDLL) -> None:
    """The factorisation of an older matrix (what assemblingRate > 1 leaves between refreshes)."""
    a = _spd(3)
    older = a + 0.3 * np.diag(np.diag(a))
    b = np.random.default_rng(4).standard_normal(7)
    x, done = _pcg(lib, a, older, b, 50)
    exact = np.linalg.solve(a, b)
    assert done > 1
    assert np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
    one, _ = _pcg(lib, a, older, b, 1)
    assert np.abs(one - exact).max() > 1e-4 * np.abs(exact).max()


@pytest.mark.parametrize(("rate", "expected"), [(1, [1] * 7), (3, [1, 0, 0, 1, 0, 0, 1])])
def test_the_refresh_counter_is_sofas(lib: ctypes.CDLL, rate: int, expected: list[int]) -> None:
    """PreconditionedMatrixFreeSystem: m_assemblyCounter starts at assemblingRate, `++counter >=
    rate` assembles and resets it: solves 1, 1 + rate, 1 + 2 rate... refresh."""
    out = np.zeros(7)
    lib.refreshes(rate, 7, _d(out))
    assert out.tolist() == expected


# ---- through scenes ---------------------------------------------------------------------------

SCENE = """<Node name="root" dt="0.02" gravity="0 -10 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
  {solver}
  <RegularGridTopology name="grid" n="6 2 2" min="0 0 0" max="5 1 1"/>
  <MechanicalObject name="dofs"/>
  <TetrahedronSetTopologyContainer name="tetras"/>
  <Hexa2TetraTopologicalMapping input="@grid" output="@tetras"/>
  <UniformMass totalMass="5"/>
  <FixedProjectiveConstraint indices="0 6 12 18"/>
  <TetrahedronFEMForceField topology="@tetras" youngModulus="400" poissonRatio="0.3" method="large"/>
</Node>
"""
DIRECT = '<SparseLDLSolver template="CompressedRowSparseMatrixMat3x3"/>'
PCG = (
    '<PCGLinearSolver iterations="{iterations}" tolerance="1e-30" preconditioner="@ldl" {extra}/>\n'
    '  <SparseLDLSolver name="ldl" template="CompressedRowSparseMatrixMat3x3"/>'
)
PLAIN = '<PCGLinearSolver iterations="1" tolerance="1e-30"/>'
RATED = (
    '<PreconditionedMatrixFreeSystem name="free" assemblingRate="{rate}"/>\n'
    '  <PCGLinearSolver iterations="1" tolerance="1e-30" linearSystem="@free" preconditioner="@ldl"/>\n'
    '  <SparseLDLSolver name="ldl" template="CompressedRowSparseMatrixMat3x3"/>'
)


def _load(tmp_path: Path, solver: str) -> sofac.Simulation:
    """The scene with ``solver``, in a file named after it: the generated code names its file, so
    the same scene loaded by two tests is compiled once."""
    scene = tmp_path / f"pcg_{hashlib.sha1(solver.encode()).hexdigest()[:12]}.scn"
    scene.write_text(SCENE.format(solver=solver))
    return sofac.load(scene)


def _trajectory(sim: sofac.Simulation, steps: int) -> list[np.ndarray]:
    out = []
    for _ in range(steps):
        sim.step(1)
        out.append(np.asarray(sim["/dofs"].position).copy())
    return out


def test_one_iteration_is_the_direct_solve(tmp_path: Path) -> None:
    direct = _trajectory(_load(tmp_path, DIRECT), 8)
    one = _trajectory(_load(tmp_path, PCG.format(iterations=1, extra="")), 8)
    plain = _trajectory(_load(tmp_path, PLAIN), 8)
    moved = np.abs(direct[-1] - direct[0]).max()
    assert moved > 1e-2  # the beam swings: the matrix changes from step to step
    for a, b in zip(direct, one, strict=True):
        assert np.abs(b - a).max() < 1e-10
    assert np.abs(plain[-1] - direct[-1]).max() > 1e-4  # unpreconditioned, one iteration is far off


def test_use_precond_false_is_plain_cg(tmp_path: Path) -> None:
    off = _trajectory(_load(tmp_path, PCG.format(iterations=1, extra='use_precond="false"')), 3)
    plain = _trajectory(_load(tmp_path, PLAIN), 3)
    assert all(np.array_equal(a, b) for a, b in zip(off, plain, strict=True))


def test_update_step_is_ignored_as_sofa_ignores_it(tmp_path: Path) -> None:
    """PCGLinearSolver's update_step is a DeprecatedData (SOFA warns, the preconditioner is still
    refreshed by its PreconditionedMatrixFreeSystem, every step by default)."""
    with pytest.warns(sofac.SceneWarning, match=r"W225.*update_step"):
        sim = _load(tmp_path, PCG.format(iterations=1, extra='update_step="4"'))
    updated = _trajectory(sim, 5)
    every = _trajectory(_load(tmp_path, PCG.format(iterations=1, extra="")), 5)
    assert all(np.array_equal(a, b) for a, b in zip(updated, every, strict=True))


def test_assembling_rate_refreshes_every_rate_solves(tmp_path: Path) -> None:
    """assemblingRate 3: the factorisation of steps 1, 4, 7 serves the steps after them. Each step
    of that run, restarted from the same state, is compared with a direct solve of its matrix: equal
    (to round-off) where the preconditioner was refreshed, not in between (one PCG iteration with a
    factorisation of an older matrix)."""
    rated = _load(tmp_path, RATED.format(rate=3))
    direct = _load(tmp_path, DIRECT)
    refreshed = []
    for _ in range(7):
        x, v = (np.asarray(a).copy() for a in (rated["/dofs"].position, rated["/dofs"].velocity))
        direct["/dofs"].position[:] = x
        direct["/dofs"].velocity[:] = v
        rated.step(1)
        direct.step(1)
        gap = np.abs(np.asarray(rated["/dofs"].position) - np.asarray(direct["/dofs"].position)).max()
        refreshed.append(bool(gap < 1e-10))
    assert refreshed == [True, False, False, True, False, False, True]


def test_a_dense_svd_preconditioner_is_refused(tmp_path: Path) -> None:
    solver = '<PCGLinearSolver iterations="5" preconditioner="@svd"/>\n  <SVDLinearSolver name="svd"/>'
    with pytest.raises(sofac.SceneError, match=r"E222.*SVDLinearSolver as a PCG preconditioner"):
        _load(tmp_path, solver)


def test_the_preconditioner_is_part_of_the_step(tmp_path: Path) -> None:
    """`sofac inspect --effects`: the direct solver preconditions the PCG (it is not kept out), on the
    matrix its PreconditionedMatrixFreeSystem assembles every assemblingRate solves."""
    scene = tmp_path / "effects.scn"
    scene.write_text(SCENE.format(solver=RATED.format(rate=3)))
    effects = plan_file(scene).effects
    (line,) = [(e, why) for e, origin, why in effects if origin.startswith("SparseLDLSolver")]
    assert line[0] == "linear_solve"
    assert line[1].startswith("preconditions PCGLinearSolver") and line[1].endswith("every 3 solves")
