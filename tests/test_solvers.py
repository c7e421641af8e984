"""The solver algorithms of runtime/sofac/solvers.h, tested as C++ on their own.

A small shim (plain C wrappers, loaded with ctypes) runs them on dense systems given from NumPy,
over a space of two states of different widths (a Vec3d state of two points and a Vec1d state of
one: seven numbers), so that every vector operation walks more than one array. Checked against:
direct solves (CG, PCG, MINRES), a NumPy copy of SOFA's CG with its stopping rules (iterations,
tolerance, threshold, and the first solve that never stops at iteration 1), the exact one-step
minimiser of MINRES, Newton's method on small nonlinear systems (with and without the line
search), and the closed-form one-step formulas of implicit Euler, Newmark and the variational
symplectic scheme on a 1-DOF spring.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import D, build_shim
from kernel_shim import doubles as _d

SHIM = r"""
#include "sofac/direct.h"
#include "sofac/solvers.h"
#include <Eigen/Dense>
#include <vector>
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))

// Two states: 2 points of Vec3d, then 1 of Vec1d, stored one after the other in a 7-number array.
using Space = sofac::StateSpace<sofac::Vec3d, sofac::Vec1d>;
constexpr Space space({2, 1});
constexpr int N = 7;
Space::Vector split(double* a) { return {a, a + 6}; }

using Dense = Eigen::Map<const Eigen::Matrix<double, N, N, Eigen::RowMajor>>;
void multiply(const double* A, const double* in, double* out) {  // out = A in, A row-major
    for (int i = 0; i < N; ++i) {
        out[i] = 0.0;
        for (int j = 0; j < N; ++j) out[i] += A[N * i + j] * in[j];
    }
}

API Index cg(const double* A, double* b, double* x, Index iterations, double tolerance, double threshold,
             int first_solve, int fused) {
    double p[N], q[N];
    const sofac::CgControls controls{iterations, tolerance, threshold, first_solve != 0};
    if (fused) {  // a product that returns p.q itself, summed in one sequence (the assembled CG)
        return sofac::conjugate_gradient(space, controls, split(x), split(b), split(p), split(q), [&] {
            multiply(A, p, q);
            double dot = 0.0;
            for (int i = 0; i < N; ++i) dot += p[i] * q[i];
            return dot;
        });
    }
    return sofac::conjugate_gradient(space, controls, split(x), split(b), split(p), split(q),
                                     [&] { multiply(A, p, q); });
}

// PCG preconditioned by sofac::JacobiPreconditioner (block 1 or 3) built from A, or by nothing (0).
API Index pcg(const double* A, const double* b, double* x, Index iterations, double tolerance, int jacobi) {
    Eigen::SparseMatrix<double> sparse = Dense(A).sparseView();
    sofac::JacobiPreconditioner P;
    P.block = jacobi == 0 ? 1 : jacobi;
    P.update(sparse);
    double z[N], p[N], dx[N], df[N], rhs[N];
    for (int i = 0; i < N; ++i) rhs[i] = b[i];
    return sofac::preconditioned_conjugate_gradient(
        space, iterations, tolerance, split(x), split(rhs), split(z), split(p), split(dx), split(df),
        [&] { multiply(A, dx, df); },
        [&] {
            if (jacobi) P.apply(z, df, N);
            else space.copy(split(df), split(z));
        });
}

API Index minres(const double* A, const double* b, double* x, Index iterations, double tolerance) {
    double work[6][N], dx[N], df[N], rhs[N];
    for (int i = 0; i < N; ++i) rhs[i] = b[i];
    const sofac::MinresVectors<Space> vectors{split(work[0]), split(work[1]), split(work[2]),
                                              split(work[3]), split(work[4]), split(work[5])};
    return sofac::minres(space, iterations, tolerance, split(x), split(rhs), vectors, split(dx), split(df),
                         [&] { multiply(A, dx, df); });
}

// ---- one degree of freedom, for the ODE solvers and Newton -----------------------------------

using Line = sofac::StateSpace<sofac::Vec1d>;
constexpr Line line({1});

// A point of mass m on the line, force f(x) = -k x - c x^3 (c = 0: a linear spring), no mapping,
// no projection. The linear solve is exact: acc = r / (mfact m - kfact f'(x)).
struct Point {
    double m, k, c;
    double x, v, f = 0, acc = 0, dx = 0, df = 0, r = 0;
    double a = 0, x0 = 0, xi = 0, momentum = 0, new_momentum = 0;
    Index solves = 0;

    double stiffness() const { return -k - 3.0 * c * x * x; }  // df/dx
    sofac::SchemeVectors<Line> vectors() { return {{&x}, {&v}, {&f}, {&acc}, {&dx}, {&df}, {&r}}; }
};

struct PointOperations {
    Point& p;
    void propagate() const {}
    void forces() const { p.f = -p.k * p.x - p.c * p.x * p.x * p.x; }
    void add_product(double mfact, double kfact, double bfact) const {
        (void)bfact;
        p.df += mfact * p.m * p.dx + kfact * p.stiffness() * p.dx;
    }
    void mass() const { p.df = p.m * p.dx; }
    void project_rhs() const {}
    void project_forces() const {}
    void solve(double mfact, double kfact, double bfact) const {
        (void)bfact;
        p.acc = p.r / (mfact * p.m + kfact * p.stiffness());
        ++p.solves;
    }
    void energy(double& kinetic, double& potential) const {
        kinetic += 0.5 * p.m * p.v * p.v;
        potential += 0.5 * p.k * p.x * p.x + 0.25 * p.c * p.x * p.x * p.x * p.x;
    }
};

// state = {x, v}; out = {x, v} after one step
API void implicit_euler(double m, double k, double h, double* state) {
    Point p{m, k, 0.0, state[0], state[1]};
    sofac::implicit_euler_step(line, p.vectors(), {h, 1.0, 0.0, 0.0, 0.0, false}, PointOperations{p});
    state[0] = p.x;
    state[1] = p.v;
}

// state = {x, v, a}; started: a holds the previous step's acceleration
API void newmark(double m, double k, double h, double gamma, double beta, Index started, double* state) {
    Point p{m, k, 0.0, state[0], state[1]};
    p.a = state[2];
    const sofac::NewmarkControls controls{h, gamma, beta, 0.0, 0.0, 0.0};
    sofac::newmark_step(line, p.vectors(), {&p.a}, controls, started, PointOperations{p});
    state[0] = p.x;
    state[1] = p.v;
    state[2] = p.a;
}

// state = {x, v, momentum}; out = {x, v, momentum, kinetic, potential, hamiltonian, Newton solves}
API void variational(double m, double k, double c, double h, Index newton_steps, double newton_error,
                     Index started, double* state, double* out) {
    Point p{m, k, c, state[0], state[1]};
    p.momentum = state[2];
    double incremental = 0.0, energies[2] = {0.0, 0.0}, hamiltonian = 0.0;
    const sofac::VariationalVectors<Line> own{{&p.x0}, {&p.xi}, {&p.momentum}, {&p.new_momentum}};
    const sofac::VariationalControls controls{h, 0.0, 0.0, newton_steps, newton_error, 1.0, true, false};
    sofac::variational_symplectic_step(line, p.vectors(), own, controls, started,
                                       {&incremental, energies, &hamiltonian}, PointOperations{p});
    const double result[] = {p.x, p.v, p.momentum, energies[0], energies[1], hamiltonian, double(p.solves)};
    for (int i = 0; i < 7; ++i) out[i] = result[i];
}

// Newton on f(x) = -k x - c x^3 + load (the load in c's place: f = load - k x - c x^3), from x.
// out = {x, Newton solves}
API void newton(double k, double c, double load, double x, Index iterations, Index line_searches,
                double coefficient, double absolute, double relative_successive, double* out) {
    struct Loaded : PointOperations {
        double load;
        void forces() const { PointOperations::forces(); p.f += load; }
    };
    Point p{1.0, k, c, x, 0.0};
    const sofac::NewtonControls controls{iterations, line_searches, coefficient, absolute, 0.0,
                                         relative_successive, 0.0, 0.0};
    sofac::newton_raphson(line, p.vectors(), controls, Loaded{{p}, load});
    out[0] = p.x;
    out[1] = double(p.solves);
}

// BDFOdeSolver on the spring (exact linear solves, one Newton iteration, no Rayleigh damping):
// from out = {x, v} at time 0, `steps` steps; out[2 j], out[2 j + 1] = x, v after step j.
API void bdf(double m, double k, double h, Index order, Index steps, double* out) {
    struct Operations : PointOperations {
        void project_position_velocity() const {}
    };
    Point p{m, k, 0.0, out[0], out[1]};
    double x_previous = 0, v_previous = 0, r1 = 0, r2 = 0;
    std::vector<double> times(order + 2, 0.0), a(order + 1), b(order + 1);
    Index count = 1, solves = 0;
    const sofac::BdfVectors<Line> own{{&x_previous}, {&v_previous}, {&r1}, {&r2}};
    const sofac::NewtonControls newton{1, 1, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0};
    double time = 0.0;
    for (Index j = 1; j <= steps; ++j) {
        const sofac::BdfControls controls{h, time, order, 0.0, 0.0, newton};
        sofac::bdf_step(line, p.vectors(), own, controls, {times.data(), count, solves, a.data(), b.data()},
                        Operations{{p}});
        time += h;
        out[2 * j] = p.x;
        out[2 * j + 1] = p.v;
    }
}

// BDFOdeSolver::computeLinearMultiStepCoefficients on times t[0..k]: a[0..k], b[0..k]
API void bdf_coefficients(const double* t, Index k, double* a, double* b) {
    sofac::bdf_coefficients(t, k, a, b);
}

// CentralDifferenceSolver's update on the spring (a = -k x / m, rayleighMass r): out = {x, v}, in place
API void central_difference(double m, double k, double r, double h, Index steps, double* out) {
    for (Index j = 0; j < steps; ++j) {
        const double a = -k * out[0] / m;
        sofac::central_difference<sofac::Vec1d>(&out[0], &out[1], &a, h, r, 1);
    }
}

// Newton on f(x) = -atan(x) (the line search's textbook case): out = {x, solves}
API void newton_atan(double x, Index iterations, Index line_searches, double coefficient, double* out) {
    struct Atan {
        Point& p;
        void propagate() const {}
        void forces() const { p.f = -std::atan(p.x); }
        void project_forces() const {}
        void solve(double, double kfact, double) const {  // (kfact K) acc = r, K = df/dx
            p.acc = p.r / (kfact * (-1.0 / (1.0 + p.x * p.x)));
            ++p.solves;
        }
    };
    Point p{1.0, 0.0, 0.0, x, 0.0};
    const sofac::NewtonControls controls{iterations, line_searches, coefficient, 1e-14, 0.0, 0.0, 0.0, 0.0};
    sofac::newton_raphson(line, p.vectors(), controls, Atan{p});
    out[0] = p.x;
    out[1] = double(p.solves);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    lib = build_shim(tmp_path_factory, "solvers", SHIM, cholmod=True)  # JacobiPreconditioner: direct.h
    lib.cg.argtypes = [D, D, D, ctypes.c_int64, ctypes.c_double, ctypes.c_double, ctypes.c_int, ctypes.c_int]
    lib.cg.restype = ctypes.c_int64
    lib.pcg.argtypes = [D, D, D, ctypes.c_int64, ctypes.c_double, ctypes.c_int]
    lib.pcg.restype = ctypes.c_int64
    lib.minres.argtypes = [D, D, D, ctypes.c_int64, ctypes.c_double]
    lib.minres.restype = ctypes.c_int64
    lib.implicit_euler.argtypes = [ctypes.c_double] * 3 + [D]
    lib.newmark.argtypes = [ctypes.c_double] * 5 + [ctypes.c_int64, D]
    lib.variational.argtypes = [ctypes.c_double] * 4 + [ctypes.c_int64, ctypes.c_double, ctypes.c_int64, D, D]
    lib.newton.argtypes = [*[ctypes.c_double] * 4, ctypes.c_int64, ctypes.c_int64, *[ctypes.c_double] * 3, D]
    lib.newton_atan.argtypes = [ctypes.c_double, ctypes.c_int64, ctypes.c_int64, ctypes.c_double, D]
    lib.bdf.argtypes = [*[ctypes.c_double] * 3, ctypes.c_int64, ctypes.c_int64, D]
    lib.bdf_coefficients.argtypes = [D, ctypes.c_int64, D, D]
    lib.central_difference.argtypes = [*[ctypes.c_double] * 4, ctypes.c_int64, D]
    return lib


def spd(seed: int, condition: float = 1e3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((7, 7)))
    return (q * np.geomspace(1.0, condition, 7)) @ q.T


def rhs(seed: int) -> np.ndarray:
    return np.random.default_rng(seed + 100).standard_normal(7)


def run_cg(
    lib: ctypes.CDLL,
    a: np.ndarray,
    b: np.ndarray,
    iterations: int = 100,
    tolerance: float = 1e-15,
    threshold: float = 1e-30,
    first: bool = False,
    fused: bool = False,
) -> tuple[np.ndarray, int]:
    a, r, x = np.ascontiguousarray(a), b.copy(), np.full(7, np.nan)  # CG clears x itself
    done = lib.cg(_d(a), _d(r), _d(x), iterations, tolerance, threshold, int(first), int(fused))
    return x, done


def _dot(a: list[float], b: list[float]) -> float:
    """The shim space's dot product, in its order: per point of the Vec3d state, then the Vec1d one."""
    states = []
    for first, last, width in ((0, 6, 3), (6, 7, 1)):
        total = 0.0
        for point in range(first, last, width):
            block = a[point] * b[point]
            for d in range(1, width):
                block += a[point + d] * b[point + d]
            total += block
        states.append(total)
    return (0.0 + states[0]) + states[1]


def sofa_cg(
    a: np.ndarray, b: np.ndarray, iterations: int, tolerance: float, threshold: float, first: bool
) -> tuple[np.ndarray, int]:
    """SOFA's CGLinearSolver in plain Python floats, every operation in the shim's order: the
    reference for the stopping rules, equal to the last bit."""
    rows = a.tolist()
    x, r, p = [0.0] * 7, b.tolist(), [0.0] * 7
    rho = _dot(r, r)
    normb, rho_previous, done = np.sqrt(rho), 0.0, 0
    for iteration in range(1, iterations + 1):
        if normb == 0.0:
            break
        may_stop = not (iteration == 1 and first)
        if np.sqrt(rho) / normb <= tolerance and may_stop:
            break
        beta = rho / rho_previous if iteration > 1 else 0.0
        p = list(r) if iteration == 1 else [ri + beta * pi for ri, pi in zip(r, p, strict=True)]
        q = []
        for row in rows:
            qi = 0.0
            for aij, pj in zip(row, p, strict=True):
                qi += aij * pj
            q.append(qi)
        den = _dot(p, q)
        if den == 0.0 or (abs(den) <= threshold and may_stop):
            break
        alpha = rho / den
        x = [xi + alpha * pi for xi, pi in zip(x, p, strict=True)]
        r = [ri + -alpha * qi for ri, qi in zip(r, q, strict=True)]
        rho_previous, rho = rho, _dot(r, r)
        done += 1
    return np.array(x), done


def test_cg_solves_an_spd_system(lib: ctypes.CDLL) -> None:
    a, b = spd(1), rhs(1)
    x, done = run_cg(lib, a, b)
    assert np.abs(x - np.linalg.solve(a, b)).max() < 1e-12 * np.abs(x).max()
    assert 7 <= done <= 30  # n iterations in exact arithmetic; a few more to reach 1e-15


@pytest.mark.parametrize("first", [False, True])
@pytest.mark.parametrize(
    ("iterations", "tolerance", "threshold"),
    [
        (2, 1e-15, 1e-30),
        (5, 1e-15, 1e-30),
        (100, 1e-3, 1e-30),
        (100, 1e-8, 1e-30),
        (100, 10.0, 1e-30),
        (100, 1e-15, 1e30),
    ],
    ids=["2 iterations", "5 iterations", "tolerance 1e-3", "tolerance 1e-8", "tolerance 10", "threshold"],
)
def test_cg_stops_as_sofa(
    lib: ctypes.CDLL, iterations: int, tolerance: float, threshold: float, first: bool
) -> None:
    """Each rule against SOFA's CG in Python: the same number of iterations, the same x to the bit.
    A tolerance of 10 and a threshold of 1e30 stop at once, except on the first solve (x0 = 0 is
    never its answer), which runs iteration 1 and stops at the next test."""
    a, b = spd(2), rhs(2)
    x, done = run_cg(lib, a, b, iterations, tolerance, threshold, first)
    x_ref, done_ref = sofa_cg(a, b, iterations, tolerance, threshold, first)
    assert done == done_ref
    assert np.array_equal(x, x_ref)
    if iterations < 100:
        assert done == iterations
    if tolerance == 10.0 or threshold == 1e30:
        assert done == (1 if first else 0)
        assert np.any(x != 0.0) == first  # x0 = 0 unless iteration 1 ran
    if tolerance in (1e-3, 1e-8):  # stopped by |r| / |b| <= tolerance, not before
        residual = np.linalg.norm(b - a @ x) / np.linalg.norm(b)
        assert residual <= tolerance * (1 + 1e-6)
        x_short, _ = run_cg(lib, a, b, done - 1, tolerance, threshold, first)
        assert np.linalg.norm(b - a @ x_short) / np.linalg.norm(b) > tolerance * (1 - 1e-6)


def test_cg_of_a_zero_right_hand_side_is_zero(lib: ctypes.CDLL) -> None:
    x, done = run_cg(lib, spd(3), np.zeros(7), first=True)
    assert done == 0 and np.array_equal(x, np.zeros(7))


def test_a_product_that_returns_its_dot_gives_the_same_numbers(lib: ctypes.CDLL) -> None:
    """The assembled CG's fused product (p.q summed in one sequence) against p.q summed per state
    and per derivative: different sums in general, so the numbers may differ in the last bits,
    never in the iterations' count or beyond round-off."""
    a, b = spd(4), rhs(4)
    x_fused, done_fused = run_cg(lib, a, b, tolerance=1e-10, fused=True)
    x, done = run_cg(lib, a, b, tolerance=1e-10)
    assert done_fused == done
    # Round-off of two summation orders carried through the CG's iterations (the SIMD width the
    # runtime picks for this processor changes the last bits): well below 1e-12 of the solution.
    assert np.abs(x_fused - x).max() <= 1e-12 * np.abs(x).max()


def run_pcg(
    lib: ctypes.CDLL,
    a: np.ndarray,
    b: np.ndarray,
    x0: np.ndarray,
    iterations: int,
    tolerance: float,
    jacobi: int,
) -> tuple[np.ndarray, int]:
    a, x = np.ascontiguousarray(a), x0.copy()
    return x, lib.pcg(_d(a), _d(b.copy()), _d(x), iterations, tolerance, jacobi)


def badly_scaled(seed: int) -> np.ndarray:
    """An SPD matrix whose diagonal spans six decades: Jacobi's case."""
    scale = np.geomspace(1.0, 1e3, 7)
    return spd(seed, condition=10.0) * np.outer(scale, scale)


@pytest.mark.parametrize("jacobi", [0, 1])
def test_pcg_solves_an_spd_system(lib: ctypes.CDLL, jacobi: int) -> None:
    a, b = badly_scaled(5), rhs(5)
    x, done = run_pcg(lib, a, b, np.zeros(7), 200, 1e-30, jacobi)
    exact = np.linalg.solve(a, b)
    assert np.abs(x - exact).max() <= 1e-10 * np.abs(exact).max()
    assert done >= 7


def test_jacobi_needs_fewer_iterations_on_a_badly_scaled_system(lib: ctypes.CDLL) -> None:
    a, b = badly_scaled(6), rhs(6)
    _, plain = run_pcg(lib, a, b, np.zeros(7), 1000, 1e-20, 0)
    _, jacobi = run_pcg(lib, a, b, np.zeros(7), 1000, 1e-20, 1)
    assert jacobi < plain


def test_jacobi_pcg_on_a_diagonal_system_takes_one_iteration(lib: ctypes.CDLL) -> None:
    a, b = np.diag(np.geomspace(1.0, 1e4, 7)), rhs(7)
    x, done = run_pcg(lib, a, b, np.zeros(7), 50, 1e-30, 1)
    assert done == 1
    assert np.abs(x - b / np.diag(a)).max() <= 1e-15 * np.abs(b / np.diag(a)).max()


def test_pcg_stops_on_its_rules(lib: ctypes.CDLL) -> None:
    """r.z <= tolerance |b|^2 (from the start x holds), and the iteration limit."""
    a, b = spd(8), rhs(8)
    exact = np.linalg.solve(a, b)
    x, done = run_pcg(lib, a, b, exact, 50, 1e-20, 0)  # starts at the answer: r.z = round-off
    assert done == 0 and np.array_equal(x, exact)
    _, done = run_pcg(lib, a, b, np.zeros(7), 3, 1e-30, 1)
    assert done == 3
    x, done = run_pcg(lib, a, b, np.zeros(7), 100, 1e-6, 0)
    r = b - a @ x
    assert r @ r <= 1e-6 * (b @ b) * (1 + 1e-6)
    x_short, _ = run_pcg(lib, a, b, np.zeros(7), done - 1, 1e-6, 0)
    r = b - a @ x_short
    assert r @ r > 1e-6 * (b @ b) * (1 - 1e-6)


def indefinite(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((7, 7)))
    return (q * np.array([-5.0, -2.0, -0.5, 0.7, 1.0, 3.0, 8.0])) @ q.T


def test_minres_solves_a_symmetric_indefinite_system(lib: ctypes.CDLL) -> None:
    a, b = indefinite(9), rhs(9)
    x = np.zeros(7)
    done = lib.minres(_d(np.ascontiguousarray(a)), _d(b.copy()), _d(x), 100, 1e-14)
    exact = np.linalg.solve(a, b)
    assert np.abs(x - exact).max() <= 1e-10 * np.abs(exact).max()
    assert 7 <= done < 100


def test_one_minres_iteration_minimises_the_residual_along_b(lib: ctypes.CDLL) -> None:
    a, b = indefinite(10), rhs(10)
    x = np.zeros(7)
    done = lib.minres(_d(np.ascontiguousarray(a)), _d(b.copy()), _d(x), 1, 1e-14)
    ab = a @ b
    assert done == 1
    assert np.abs(x - (b @ ab) / (ab @ ab) * b).max() <= 1e-14 * np.abs(x).max()


def test_minres_from_a_start_corrects_it(lib: ctypes.CDLL) -> None:
    a, b = indefinite(11), rhs(11)
    exact = np.linalg.solve(a, b)
    x = exact + 1e-3 * rhs(12)
    lib.minres(_d(np.ascontiguousarray(a)), _d(b.copy()), _d(x), 100, 1e-14)
    assert np.abs(x - exact).max() <= 1e-10 * np.abs(exact).max()


def newton_run(lib: ctypes.CDLL, *args: float) -> tuple[float, int]:
    out = np.zeros(2)
    lib.newton(*args, _d(out))
    return out[0], int(out[1])


def test_newton_solves_a_cubic_spring_quadratically(lib: ctypes.CDLL) -> None:
    """f(x) = load - k x - c x^3 = 0, from x = 0: Newton's iterates in NumPy, one per solve."""
    k, c, load = 2.0, 0.5, 3.0
    x, solves = newton_run(lib, k, c, load, 0.0, 50, 1, 0.5, 1e-13, 0.0)
    assert abs(load - k * x - c * x**3) <= 1e-13
    ref, n = 0.0, 0
    while abs(load - k * ref - c * ref**3) >= 1e-13:
        ref -= (load - k * ref - c * ref**3) / (-k - 3 * c * ref**2)
        n += 1
    assert solves == n and x == pytest.approx(ref, abs=1e-15)


def test_newton_stops_on_its_rules(lib: ctypes.CDLL) -> None:
    k, c, load = 2.0, 0.5, 3.0
    _, solves = newton_run(lib, k, c, load, 0.0, 2, 1, 0.5, 0.0, 0.0)  # the iteration limit alone
    assert solves == 2
    x, solves = newton_run(lib, k, c, load, 1.0, 50, 1, 0.5, 1e30, 0.0)  # |f| small enough at the start
    assert solves == 0 and x == 1.0
    # relativeSuccessiveStoppingThreshold: stop once |f| drops by that factor in one iteration
    _, loose = newton_run(lib, k, c, load, 0.0, 50, 1, 0.5, 0.0, 0.5)
    _, tight = newton_run(lib, k, c, load, 0.0, 50, 1, 0.5, 0.0, 1e-6)
    assert 1 <= loose < tight < 50


def test_newton_line_search_rescues_the_arctangent(lib: ctypes.CDLL) -> None:
    """f(x) = -atan(x) from x = 2: plain Newton overshoots further each time (|x| grows); halving the
    step while |f| does not decrease brings it to the root."""
    out = np.zeros(2)
    lib.newton_atan(2.0, 5, 1, 0.5, _d(out))
    assert abs(out[0]) > 100.0
    lib.newton_atan(2.0, 50, 10, 0.5, _d(out))
    assert abs(out[0]) < 1e-14


M, K, H = 0.5, 50.0, 0.05


def test_implicit_euler_step_of_a_spring(lib: ctypes.CDLL) -> None:
    """(m + h^2 k) dv = h (-k x - h k v): the backward Euler step, v += dv, x += h v."""
    x0, v0 = 0.2, -0.3
    state = np.array([x0, v0])
    lib.implicit_euler(M, K, H, _d(state))
    v1 = v0 + H * (-K * x0 - H * K * v0) / (M + H * H * K)
    assert state == pytest.approx([x0 + H * v1, v1], rel=1e-15)


@pytest.mark.parametrize(("gamma", "beta"), [(0.5, 0.25), (0.6, 0.3025)])
def test_newmark_step_of_a_spring(lib: ctypes.CDLL, gamma: float, beta: float) -> None:
    """m a' = -k x1 with x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a'): solved for a' in closed form;
    the first step (started = 0) takes a0 = -k x0 / m, a later one the a it is given."""
    x0, v0 = 0.2, -0.3
    for started, a0 in [(0, -K * x0 / M), (1, 1.7)]:
        state = np.array([x0, v0, a0 if started else 123.0])
        lib.newmark(M, K, H, gamma, beta, started, _d(state))
        a1 = -K * (x0 + H * v0 + H * H * (0.5 - beta) * a0) / (M + K * H * H * beta)
        x1 = x0 + H * v0 + H * H * ((0.5 - beta) * a0 + beta * a1)
        v1 = v0 + H * ((1 - gamma) * a0 + gamma * a1)
        assert state == pytest.approx([x1, v1, a1], rel=1e-14), started


def test_variational_symplectic_step_of_a_spring(lib: ctypes.CDLL) -> None:
    """Linear spring: one Newton iteration is exact. The step is the implicit midpoint rule:
    v = v0 - (h/2) w^2 (x0 + (h/2) v) (the mean velocity), x1 = x0 + h v, p1 = m v0 - h k (x0 + (h/2) v);
    the Hamiltonian is p1^2 / 2m + k x1^2 / 2. From started = 0, p0 = m v0."""
    x0, v0 = 0.2, -0.3
    w2 = K / M
    v = (v0 - H / 2 * w2 * x0) / (1 + H * H * w2 / 4)
    x1, p1 = x0 + H * v, M * v0 - H * K * (x0 + H / 2 * v)
    for steps in (1, 3):
        out = np.zeros(7)
        lib.variational(M, K, 0.0, H, steps, 1e-12, 0, _d(np.array([x0, v0, 999.0])), _d(out))
        assert out[:3] == pytest.approx([x1, v, p1], rel=1e-14)
        kinetic, potential = p1**2 / (2 * M), K * x1**2 / 2
        assert out[3:6] == pytest.approx([kinetic, potential, kinetic + potential], rel=1e-14)
        # the Newton solves (a second one finds no change, and newtonError stops it), then M b = p
        assert out[6] == min(steps, 2) + 1
    started = np.zeros(7)  # started: the momentum it is given, not m v
    lib.variational(M, K, 0.0, H, 1, 0.0, 1, _d(np.array([x0, v0, 2.0 * M * v0])), _d(started))
    assert started[0] != pytest.approx(x1, rel=1e-6)


def test_variational_newton_iterations_on_a_nonlinear_spring(lib: ctypes.CDLL) -> None:
    """f = -k x - c x^3: the midpoint equation m (v - v0) = (h/2) f(x0 + (h/2) v) is nonlinear; more
    Newton iterations solve it better, and newtonError stops them early."""
    x0, v0, c = 0.4, 0.8, 4000.0

    def residual(v: float) -> float:
        mid = x0 + H / 2 * v
        return M * (v - v0) - H / 2 * (-K * mid - c * mid**3)

    errors = []
    for steps in (1, 2, 4, 8):
        out = np.zeros(7)
        lib.variational(M, K, c, H, steps, 0.0, 0, _d(np.array([x0, v0, 0.0])), _d(out))
        errors.append(abs(residual(out[1])))
    assert errors[-1] < 1e-12 < errors[1] < errors[0]
    out = np.zeros(7)
    lib.variational(M, K, c, H, 50, 1e-6, 0, _d(np.array([x0, v0, 0.0])), _d(out))
    assert 2 <= out[6] - 1 < 50


GROUP = """\
  <Node name="{name}">
    {solver}
    <MechanicalObject template="Vec3d" name="dofs" position="0 0 0  1.2 0 0"/>
    <UniformMass vertexMass="1"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="0 1 100 0 1"/>
  </Node>
"""
GROUPS = {
    "conjugate_gradient": '<EulerImplicitSolver/><CGLinearSolver iterations="10" tolerance="1e-9"/>',
    "preconditioned_conjugate_gradient": '<EulerImplicitSolver/><PCGLinearSolver iterations="10"/>',
    "minres": '<EulerImplicitSolver/><MinResLinearSolver iterations="10"/>',
    "newmark_step": "<NewmarkImplicitSolver/><SparseLDLSolver/>",
    "newton_raphson": "<StaticSolver/><SparseLDLSolver/>",
    "variational_symplectic_step": '<VariationalSymplecticSolver steps="2"/><SparseLDLSolver/>',
    "bdf_step": '<BDFOdeSolver order="2"/><NewtonRaphsonSolver/><SparseLDLSolver/>',
}


def test_generated_steps_call_the_runtime_solvers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The generated C++ only arranges calls: each implicit group hands its vectors and operations
    to an algorithm of solvers.h, and none of the algorithms' own arithmetic is written out."""
    from sofac.cli.main import main

    nodes = "".join(GROUP.format(name=f"g{i}", solver=solver) for i, solver in enumerate(GROUPS.values()))
    scene = tmp_path / "groups.scn"
    scene.write_text(
        f'<Node name="root" gravity="0 -9.81 0" dt="0.01"><DefaultAnimationLoop/>\n{nodes}</Node>\n'
    )
    assert main(["emit", str(scene)]) == 0
    source = capsys.readouterr().out
    for algorithm in GROUPS:
        assert f"sofac::{algorithm}(" in source, algorithm
    assert source.count("sofac::implicit_euler_step(") == 3
    internals = (
        "cg_update",
        "rho_previous",
        "tnorm2",
        "line_search",
        "momentum_dot",
        "beta1",
        "bdf_coefficients",
    )
    for internal in internals:
        assert internal not in source, internal


def bdf_coefficients(lib: ctypes.CDLL, times: list[float]) -> tuple[np.ndarray, np.ndarray]:
    k = len(times) - 1
    a, b = np.zeros(k + 1), np.zeros(k + 1)
    lib.bdf_coefficients(_d(np.array(times)), k, _d(a), _d(b))
    return a, b


@pytest.mark.parametrize("start", [0.0, 12.0, 900.0])
def test_bdf_coefficients_are_sofas(lib: ctypes.CDLL, start: float) -> None:
    """SOFA's BDFOdeSolver_test values on evenly spaced times (1, 2, 3 steps back), and on uneven
    ones the derivative at t_k of the Lagrange interpolant through (t_j, y_j), times t_k - t_k-1,
    normalised by a_k: exact on quadratics."""
    for times, a_ref, b_ref in (
        ([start, start + 1], [-1, 1], [0, 1]),
        ([start, start + 1, start + 2], [1 / 3, -4 / 3, 1], [0, 0, 2 / 3]),
        ([start, start + 1, start + 2, start + 3], [-2 / 11, 9 / 11, -18 / 11, 1], [0, 0, 0, 6 / 11]),
    ):
        a, b = bdf_coefficients(lib, times)
        assert a == pytest.approx(a_ref, abs=1e-12) and b == pytest.approx(b_ref, abs=1e-12)
    times = [start, start + 0.1, start + 0.35]
    a, b = bdf_coefficients(lib, times)
    y = [(t - start) ** 2 + 3 * (t - start) for t in times]  # y' at t_2 = 2 (0.35) + 3
    derivative = sum(a[j] * y[j] for j in range(3)) / (b[2] * (times[2] - times[1]))
    assert derivative == pytest.approx(2 * 0.35 + 3, rel=1e-12)


def bdf_run(lib: ctypes.CDLL, h: float, order: int, steps: int, x0: float = 1.0) -> np.ndarray:
    out = np.zeros(2 * steps + 2)
    out[0] = x0
    lib.bdf(M, K, h, order, steps, _d(out))
    return out.reshape(-1, 2)


def bdf_reference(h: float, order: int, steps: int, x0: float = 1.0) -> np.ndarray:
    """SOFA's BDF step solved in closed form: r1 = sum_j a_j x_j - h b_k v_k = 0 and
    r2 = m sum_j a_j v_j - h b_k f(x_k) = 0 with, as SOFA's vector ids make them, x_j = x_n and
    v_j = v_n for every j < k (the step's start), k = min(order, step + 1)."""
    x, v, times, rows = x0, 0.0, [0.0], [(x0, 0.0)]
    for step in range(steps):
        k = min(order, step + 1)
        times = ([*times, step * h + h])[-(k + 1) :]
        a = np.zeros(k + 1)
        for j in range(k + 1):
            for i in range(k + 1):
                if i != j:
                    product = 1.0
                    for m in range(k + 1):
                        if m not in (i, j):
                            product *= (times[k] - times[m]) / (times[j] - times[m])
                    a[j] += product / (times[j] - times[i])
        a *= times[k] - times[k - 1]
        hb, before = h / a[k], a[:k].sum() / a[k]  # a_k x_k + (sum a_j) x_n = h b_k a_k v_k, ...
        # x_k = -before x + hb v_k; m (v_k + before v) = hb (-K x_k)
        v_next = (-M * before * v + hb * K * before * x) / (M + hb * hb * K)
        x, v = -before * x + hb * v_next, v_next
        rows.append((x, v))
    return np.array(rows)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_bdf_steps_of_a_spring_are_sofas(lib: ctypes.CDLL, order: int) -> None:
    """One Newton iteration solves the linear spring's step exactly: the trajectory is the closed
    form of SOFA's residual, start-up steps (order 1, then 2, ...) included."""
    h, steps = 0.01, 40
    assert bdf_run(lib, h, order, steps) == pytest.approx(bdf_reference(h, order, steps), rel=1e-9, abs=1e-12)


def test_bdf_accuracy_on_the_harmonic_oscillator(lib: ctypes.CDLL) -> None:
    """x(t) = cos(w t) from x = 1, v = 0. Order 1 is backward Euler: first order in h. At higher
    orders SOFA's solver reuses the state's x and v for every earlier slot, so after the start-up a
    step is backward Euler with the step b_k h (b_2 = 2/3, b_3 = 6/11): first order again, towards
    cos(w b_k t) instead of cos(w t)."""
    w, t = np.sqrt(K / M), 1.0
    for order, speed in ((1, 1.0), (2, 2 / 3), (3, 6 / 11)):
        errors, wrong = [], []
        for steps in (400, 800, 1600):
            h = t / steps
            x = bdf_run(lib, h, order, steps)[-1, 0]
            # the start-up steps: a first step of h, then order-2 steps (b = 2/3) up to order k
            elapsed = h + sum({2: 2 / 3, 3: 6 / 11}.get(min(order, j + 1), 1.0) * h for j in range(1, steps))
            errors.append(abs(x - np.cos(w * elapsed)))
            wrong.append(abs(x - np.cos(w * t)))
        rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
        assert np.all(np.abs(rates - 1.0) < 0.1), (order, rates)  # first order
        assert elapsed == pytest.approx(speed * t, abs=2 * h)
        if order > 1:
            assert min(wrong) > 0.1  # not converging to cos(w t)


def test_central_difference_steps(lib: ctypes.CDLL) -> None:
    """rayleighMass 0: v += h a, then x += h v (symplectic Euler). r > 0: v += c1 v, v += c2 a with
    c1 = (1/h - r/2) / (1/h + r/2) - 1, c2 = 1 / (1/h + r/2), then x += h v."""
    h, r = 0.01, 0.7
    for damping in (0.0, r):
        state = np.array([0.2, -0.3])
        lib.central_difference(M, K, damping, h, 1, _d(state))
        a = -K * 0.2 / M
        if damping == 0.0:
            v = -0.3 + h * a
        else:
            v = -0.3 + (-1.0 + (1 / h - r / 2) / (1 / h + r / 2)) * -0.3
            v = v + 1 / (1 / h + r / 2) * a
        assert state.tolist() == [0.2 + h * v, v]


@pytest.mark.parametrize("damping", [0.0, 0.8])
def test_central_difference_accuracy_on_the_oscillator(lib: ctypes.CDLL, damping: float) -> None:
    """m x'' + r m x' + k x = 0 from x = 1: the velocity SOFA's solver updates is the one of the
    half step before (leapfrog). Started with v(-h/2) the error in x at t = 1 is second order in h;
    started with v(0), as a scene gives it, the first step is off by O(h^2) and x only first order."""
    w0 = np.sqrt(K / M)
    wd = np.sqrt(w0**2 - damping**2 / 4)

    def exact(t: float) -> tuple[float, float]:  # x(0) = 1, x'(0) = 0
        decay, c, s = np.exp(-damping * t / 2), np.cos(wd * t), np.sin(wd * t)
        return decay * (c + damping / (2 * wd) * s), -decay * s * w0**2 / wd

    for start, order in (("half step", 2.0), ("step", 1.0)):
        errors = []
        for steps in (400, 800, 1600):
            h = 1.0 / steps
            state = np.array([1.0, exact(-h / 2)[1] if start == "half step" else 0.0])
            lib.central_difference(M, K, damping, h, steps, _d(state))
            errors.append(abs(state[0] - exact(1.0)[0]))
        rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
        assert np.all(np.abs(rates - order) < 0.1), (start, rates)
