// The solvers of an implicit step: SOFA's linear solvers (CGLinearSolver, PCGLinearSolver,
// MinResLinearSolver) and its ODE solvers (EulerImplicitSolver, NewmarkImplicitSolver,
// StaticSolver with NewtonRaphsonSolver, VariationalSymplecticSolver), each written once here.
//
// A generated step only arranges calls: it hands the algorithm the group's vectors and its
// scene-specific operations (the matrix-free product built from the masses, force fields,
// mappings and projections; the force evaluation; the linear solve), as callables or as one
// "operations" object whose members are plain functions. Templates, not std::function or virtual
// calls: everything inlines, and a step allocates nothing.
//
// The numbers are SOFA's: every vector operation is the one SOFA's MechanicalObject performs, in
// its order (dot products summed per state, states in order, each derivative's numbers first).
#pragma once

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <type_traits>
#include <utility>

#include "kernels.h"

namespace sofac {

// ---- the group's vectors ------------------------------------------------------------------------

// The independent states of one ODE solver as one vector space: a vector is one flat array per
// state (StateSpace::Vector), state k holding points[k] derivatives of DataTypes k.
template <class... DataTypes>
class StateSpace {
public:
    static constexpr std::size_t count = sizeof...(DataTypes);
    using Vector = std::array<double*, count>;

    constexpr explicit StateSpace(const std::array<Index, count>& points) : points_(points) {}

    // a.b on derivatives, summed state after state (sofac::dot within a state).
    double dot(const Vector& a, const Vector& b) const {
        double sum = 0.0;
        each([&](auto k, auto type) { sum += sofac::dot(a[k], b[k], points_[k], decltype(type)::deriv); });
        return sum;
    }

    // a.b on coordinates (positions): |x| for the Newton and variational stopping tests.
    double dot_coordinates(const Vector& a, const Vector& b) const {
        double sum = 0.0;
        each([&](auto k, auto type) { sum += sofac::dot(a[k], b[k], points_[k], decltype(type)::coord); });
        return sum;
    }

    void clear(const Vector& a) const {
        each([&](auto k, auto type) { sofac::clear(a[k], deriv_size(k, type)); });
    }

    void copy(const Vector& out, const Vector& in) const {
        each([&](auto k, auto type) { sofac::copy(out[k], in[k], deriv_size(k, type)); });
    }

    void copy_coordinates(const Vector& out, const Vector& in) const {
        each([&](auto k, auto type) { sofac::copy(out[k], in[k], coord_size(k, type)); });
    }

    void scale(const Vector& a, double factor) const {
        each([&](auto k, auto type) { sofac::scale(a[k], factor, deriv_size(k, type)); });
    }

    // out = a + h b
    void add_scaled(const Vector& out, const Vector& a, const Vector& b, double h) const {
        each([&](auto k, auto type) { sofac::add_scaled(out[k], a[k], b[k], h, deriv_size(k, type)); });
    }

    // out = a + h b on coordinate-shaped arrays (point states only: there x and v share a layout).
    void add_scaled_coordinates(const Vector& out, const Vector& a, const Vector& b, double h) const {
        each([&](auto k, auto type) { sofac::add_scaled(out[k], a[k], b[k], h, coord_size(k, type)); });
    }

    // out = x "+" h v: a translation for points, a turn for rigid frames (sofac::advance).
    void advance(const Vector& out, const Vector& x, const Vector& v, double h) const {
        each([&](auto k, auto type) { sofac::advance<decltype(type)>(out[k], x[k], v[k], h, points_[k]); });
    }

    // x += alpha p, r -= alpha q; the new r.r (the conjugate gradient's update, one pass per state).
    double cg_update(const Vector& x, const Vector& r, const Vector& p, const Vector& q, double alpha) const {
        double sum = 0.0;
        each([&](auto k, auto type) {
            sum += sofac::cg_update<decltype(type)::deriv>(x[k], r[k], p[k], q[k], alpha, points_[k]);
        });
        return sum;
    }

    // No rigid frame: coordinates and derivatives share a layout (what the variational solver needs).
    static constexpr bool all_points = (!DataTypes::rigid && ...);

private:
    template <std::size_t K>
    using TypeAt = std::tuple_element_t<K, std::tuple<DataTypes...>>;

    template <class K, class DT>
    Index deriv_size(K k, DT) const { return points_[k] * DT::deriv; }
    template <class K, class DT>
    Index coord_size(K k, DT) const { return points_[k] * DT::coord; }

    // f(k, DataTypes k{}) for every state, in order (k a compile-time index).
    template <class F>
    void each(F&& f) const {
        each(f, std::index_sequence_for<DataTypes...>{});
    }
    template <class F, std::size_t... K>
    void each(F& f, std::index_sequence<K...>) const {
        (f(std::integral_constant<std::size_t, K>{}, TypeAt<K>{}), ...);
    }

    std::array<Index, count> points_;
};

// A vector of that space (in signatures where Space is deduced from another argument).
template <class Space>
using VectorOf = typename Space::Vector;

// The vectors every implicit scheme works on, one array per independent state.
template <class Space>
struct SchemeVectors {
    using Vector = typename Space::Vector;
    Vector x, v, f;  // the state and its forces
    Vector acc;      // the linear solve's solution (dv, a' or dx) and, for PCG and MINRES, its start
    Vector dx, df;   // what the matrix-free product reads and writes
    Vector r;        // the linear solve's right-hand side
};

// ---- linear solvers: A acc = r -----------------------------------------------------------------

// CGLinearSolver's controls: its `iterations`, `tolerance` and `threshold`, and whether this is the
// solver's very first solve (where SOFA's CG never stops at iteration 1).
struct CgControls {
    std::int64_t max_iterations;
    double tolerance;
    double threshold;
    bool first_solve;
};

// SOFA's CGLinearSolver: x0 = 0; before each iteration, stop when |r| / |b| <= tolerance; after
// the product, stop when p.Ap = 0 or |p.Ap| <= threshold; on the very first solve, neither test
// stops iteration 1. On entry r holds b (it ends as the residual). product() leaves q = A p; it
// may return p.q when it computes it on the way (the assembled matrix does), else it is summed here.
// Returns the number of iterations that updated x.
template <class Space, class Product>
std::int64_t conjugate_gradient(const Space& space, const CgControls& controls, const VectorOf<Space>& x,
                                const VectorOf<Space>& r, const VectorOf<Space>& p,
                                const VectorOf<Space>& q, Product&& product) {
    space.clear(x);
    const double normb2 = space.dot(r, r);
    const double normb = std::sqrt(normb2);
    double rho = normb2, rho_previous = 0.0;  // r.r, computed by the previous iteration's update
    std::int64_t iteration = 1;
    for (; normb != 0.0 && iteration <= controls.max_iterations; ++iteration) {
        const bool may_stop = !(iteration == 1 && controls.first_solve);
        if (std::sqrt(rho) / normb <= controls.tolerance && may_stop) break;
        if (iteration == 1) space.copy(p, r);
        else space.add_scaled(p, r, p, rho / rho_previous);  // p = r + beta p
        double den;
        if constexpr (std::is_same_v<decltype(product()), double>) {
            den = product();
        } else {
            product();
            den = space.dot(p, q);
        }
        if (den == 0.0 || (std::fabs(den) <= controls.threshold && may_stop)) break;
        const double alpha = rho / den;
        rho_previous = rho;
        rho = space.cg_update(x, r, p, q, alpha);
    }
    return iteration - 1;
}

// PreconditionedMatrixFreeSystem::buildSystemMatrix's counter: it starts at the assembling rate
// (the first solve refreshes the preconditioner), each solve increments it, and a solve that
// brings it to the rate refreshes the preconditioner's matrix and resets it to 0.
inline bool refresh_due(std::int64_t& counter, std::int64_t rate) {
    if (++counter < rate) return false;
    counter = 0;
    return true;
}

// SOFA's PCGLinearSolver, from the start x holds (the previous solution): stops when r.z <=
// tolerance |b|^2 (z the preconditioned residual) or after max_iterations. product() leaves
// df = A dx; precondition() leaves df = P^-1 z (both vectors are the product's, as in SOFA, which
// reuses them). z and p are work vectors. Returns the number of iterations.
template <class Space, class Product, class Precondition>
std::int64_t preconditioned_conjugate_gradient(const Space& space, std::int64_t max_iterations, double tolerance,
                                               const VectorOf<Space>& x, const VectorOf<Space>& b,
                                               const VectorOf<Space>& z, const VectorOf<Space>& p,
                                               const VectorOf<Space>& dx, const VectorOf<Space>& df,
                                               Product&& product, Precondition&& precondition) {
    const double stop = tolerance * space.dot(b, b);
    space.copy(dx, x);
    product();
    space.add_scaled(z, b, df, -1.0);  // z holds the residual b - A x; df its preconditioned copy
    precondition();
    space.copy(p, df);
    double r_norm = space.dot(z, p);
    std::int64_t iteration = 1;
    for (; iteration <= max_iterations && r_norm > stop; ++iteration) {
        space.copy(dx, p);
        product();
        const double alpha = r_norm / space.dot(p, df);
        space.add_scaled(x, x, p, alpha);
        space.add_scaled(z, z, df, -alpha);
        precondition();
        const double previous = r_norm;
        r_norm = space.dot(z, df);
        space.add_scaled(p, df, p, r_norm / previous);
    }
    return iteration - 1;
}

// MINRES's work vectors.
template <class Space>
struct MinresVectors {
    typename Space::Vector r1, r2, y, v, w, w2;
};

// SOFA's MinResLinearSolver: MINRES (Paige & Saunders), unpreconditioned, from the start x holds;
// its stopping tests in SOFA's order. product() leaves df = A dx. Returns the number of iterations
// that updated x.
template <class Space, class Product>
std::int64_t minres(const Space& space, std::int64_t max_iterations, double tolerance, const VectorOf<Space>& x,
                    const VectorOf<Space>& b, MinresVectors<Space> work, const VectorOf<Space>& dx,
                    const VectorOf<Space>& df, Product&& product) {
    auto& [r1, r2, y, v, w, w2] = work;
    space.copy(dx, x);
    space.clear(w);
    space.clear(w2);
    product();
    space.add_scaled(r1, b, df, -1.0);
    double beta1 = space.dot(r1, r1);
    if (!(beta1 > 0)) return 0;
    beta1 = std::sqrt(beta1);
    space.copy(y, r1);
    double oldb = 0.0, beta = beta1, dbar = 0.0, epsln = 0.0, oldeps = 0.0;
    double phibar = beta1, tnorm2 = 0.0, cs = -1.0, sn = 0.0, gmax = 0.0, gmin = DBL_MAX;
    const double eps = DBL_EPSILON;
    std::int64_t itn = 0;
    for (; itn < max_iterations; ++itn) {
        // The Lanczos step: v = y / beta, y = A v - (beta / oldb) r1 - (alpha / beta) r2.
        space.copy(r2, y);
        space.copy(v, y);
        space.scale(v, 1. / beta);
        space.copy(dx, v);
        product();
        space.copy(y, df);
        if (itn) space.add_scaled(y, y, r1, -beta / oldb);
        const double alpha = space.dot(v, y);
        space.add_scaled(y, y, r2, -alpha / beta);
        std::swap(r1, r2);
        oldb = beta;
        beta = space.dot(y, y);
        if (beta < 0) return itn;
        beta = std::sqrt(beta);
        tnorm2 += alpha * alpha + oldb * oldb + beta * beta;
        // The plane rotation that keeps the tridiagonal system upper triangular.
        oldeps = epsln;
        const double delta = cs * dbar + sn * alpha;
        const double gbar = sn * dbar - cs * alpha;
        epsln = sn * beta;
        dbar = -cs * beta;
        const double root = std::sqrt(gbar * gbar + dbar * dbar);
        const double gamma = std::max(std::sqrt(gbar * gbar + beta * beta), eps);
        const double denom = 1. / gamma;
        cs = gbar * denom;
        sn = beta * denom;
        const double phi = cs * phibar;
        phibar = sn * phibar;
        // w = (v - oldeps w_old_old - delta w_old) / gamma; x += phi w
        std::swap(w, w2);
        space.scale(w, -oldeps);
        space.add_scaled(w, w, w2, -delta);
        space.add_scaled(w, w, v, 1.0);
        space.scale(w, denom);
        space.add_scaled(x, x, w, phi);
        if (itn == 0 && beta / beta1 < 10.0 * eps) return 1;
        const double a_norm = std::sqrt(tnorm2);
        const double y_norm = std::sqrt(space.dot(x, x));
        const double test1 = phibar / (a_norm * y_norm);
        gmax = std::max(gmax, gamma);
        gmin = std::min(gmin, gamma);
        const double test2 = root / a_norm;
        if (test1 <= 0. || test2 <= 0. || itn >= max_iterations - 1 || gmax / gmin >= .1 / eps ||
            a_norm * eps * y_norm >= beta1 || test2 <= tolerance || test1 <= tolerance)
            return itn + 1;
    }
    return itn;
}

// ---- ODE solvers -------------------------------------------------------------------------------
//
// Each takes the group's operations as one object `ops` with (those it uses):
//   ops.propagate()                 positions and velocities down the mappings
//   ops.forces()                    f(x, v) on every state, mapped forces up (J^T)
//   ops.add_product(mf, kf, bf)     df += (mf M + bf B + kf K) dx through the mappings, unprojected
//   ops.mass()                      df = M dx on the independent states alone (SOFA's addMdx)
//   ops.project_rhs()               the projective constraints on r
//   ops.project_forces()            the projective constraints on f
//   ops.solve(mf, kf, bf)           acc = A^-1 r, A = mf M + bf B + kf K (the linear solver)
//   ops.energy(kinetic, potential)  the group's energies, added to the two totals
// The projections of x and v that end every step, and the last propagation, stay with the caller.

// EulerImplicitSolver's parameters for one step.
struct ImplicitEulerControls {
    double h;
    double trapezoidal;  // 0.5 with trapezoidalScheme, else 1
    double rayleigh_stiffness, rayleigh_mass;
    double vdamping;
    bool first_order;
};

// SOFA's EulerImplicitSolver: solve ((1 + tr h rm) M - tr h (tr h + rk) K) dv = h (f - rm M v +
// (tr h + rk) K v), then v += dv, x += h v. firstOrder: solve (M - tr h K) v' = f, then v = v',
// x += h v (no Rayleigh damping).
template <class Space, class Operations>
void implicit_euler_step(const Space& space, const SchemeVectors<Space>& s, const ImplicitEulerControls& c,
                         const Operations& ops) {
    const double h = c.h, tr = c.trapezoidal, rk = c.rayleigh_stiffness, rm = c.rayleigh_mass;
    ops.propagate();
    ops.forces();
    if (c.first_order) {
        space.copy(s.r, s.f);
        ops.project_rhs();
        ops.solve(1.0, -h * tr, 0.0);
        space.copy(s.v, s.acc);
    } else {
        // b = f, then b += (-rm M + (h + rk) K) v (accumulated in SOFA's order), then b *= h
        space.copy(s.dx, s.v);
        space.copy(s.df, s.f);
        ops.add_product(-rm, h * tr + rk, 0.0);
        space.copy(s.r, s.df);
        space.scale(s.r, h);
        ops.project_rhs();
        ops.solve(1.0 + tr * h * rm, -tr * h * (tr * h + rk), -tr * h);
        space.add_scaled(s.v, s.v, s.acc, 1.0);
    }
    space.advance(s.x, s.x, s.v, h);
    const double velocity_damping = std::exp(-h * c.vdamping);
    if (velocity_damping != 1.0) space.scale(s.v, velocity_damping);
}

// NewmarkImplicitSolver's parameters for one step.
struct NewmarkControls {
    double h;
    double gamma, beta;
    double rayleigh_stiffness, rayleigh_mass;
    double vdamping;
};

// SOFA's NewmarkImplicitSolver, on the acceleration a' of the end of the step:
//   ((1 + h gamma rm) M - (h^2 beta + h gamma rk) K) a' = f + (-rm M + (rk + h) K) v
//     + (-h (1 - gamma) rm M + (h (1 - gamma) rk + h^2 (1 - 2 beta) / 2) K) a  (when rm, rk or beta - 1/2 is not 0),
// then x += h v + h^2 (1/2 - beta) a + h^2 beta a', v += h (1 - gamma) a + h gamma a', a = a'.
// The first step (started == 0: the first, or the first after a reset) starts with a = M^-1 f.
template <class Space, class Operations>
void newmark_step(const Space& space, const SchemeVectors<Space>& s, const VectorOf<Space>& a,
                  const NewmarkControls& c, Index& started, const Operations& ops) {
    const double h = c.h, gamma = c.gamma, beta = c.beta, rk = c.rayleigh_stiffness, rm = c.rayleigh_mass;
    ops.propagate();
    ops.forces();
    for (int pass = started != 0 ? 1 : 0; pass < 2; ++pass) {
        if (pass == 0) {  // the initial acceleration, with the mass alone
            space.copy(s.r, s.f);
            ops.project_rhs();
            ops.solve(1.0, 0.0, 0.0);
            space.copy(a, s.acc);
            started = 1;
            continue;
        }
        space.copy(s.df, s.f);
        if (rm != 0.0 || rk != 0.0 || beta != 0.5) {
            space.copy(s.dx, a);
            ops.add_product(-h * (1 - gamma) * rm, h * (1 - gamma) * rk + h * h * (1 - 2 * beta) / 2.0,
                            h * (1 - gamma));
        }
        space.copy(s.dx, s.v);
        ops.add_product(-rm, rk + h, 1.0);
        space.copy(s.r, s.df);
        ops.project_rhs();
        ops.solve(1.0 + h * gamma * rm, -h * h * beta - h * rk * gamma, -h * gamma);
    }
    const double velocity_damping = std::exp(-h * c.vdamping);
    space.advance(s.x, s.x, s.v, h);
    space.advance(s.x, s.x, a, h * h * (0.5 - beta));
    space.advance(s.x, s.x, s.acc, h * h * beta);
    space.add_scaled(s.v, s.v, a, h * (1 - gamma));
    space.add_scaled(s.v, s.v, s.acc, h * gamma);
    if (velocity_damping != 1.0) space.scale(s.v, velocity_damping);
    space.copy(a, s.acc);
}

// NewtonRaphsonSolver's parameters (StaticSolver).
struct NewtonControls {
    std::int64_t max_iterations;             // maxNbIterationsNewton
    std::int64_t line_searches;              // maxNbIterationsLineSearch
    double line_search_coefficient;          // lineSearchCoefficient
    double absolute_residual;                // absoluteResidualStoppingThreshold
    double relative_initial;                 // relativeInitialStoppingThreshold
    double relative_successive;              // relativeSuccessiveStoppingThreshold
    double absolute_estimate;                // absoluteEstimateDifferenceThreshold
    double relative_estimate;                // relativeEstimateDifferenceThreshold
};

// SOFA's NewtonRaphsonSolver::solve on a non-linear function `fn`, its stopping rules in SOFA's
// order (each measured when its threshold is > 0). `fn` provides (BaseNonLinearFunction's):
//   fn.evaluate()           r(x) at the current guess; returns |r|^2
//   fn.solve_linearised()   J_r(x) dx = -r(x) (computeGradientFromCurrentGuess, solveLinearEquation)
//   fn.update(alpha)        x += alpha dx (updateGuessFromLinearSolution)
//   fn.squared_guess()      |x|^2 (squaredLastEvaluation, for the relative estimate test)
//   fn.squared_correction() |dx|^2 (squaredNormDx)
// The line search multiplies alpha by lineSearchCoefficient while |r| does not decrease, up to
// maxNbIterationsLineSearch tries; with no decrease (and more than one try) the full step is taken.
template <class Function>
void newton_solve(const NewtonControls& c, Function& fn) {
    double r2 = fn.evaluate();
    if (c.absolute_residual > 0.0 && r2 <= c.absolute_residual * c.absolute_residual) return;
    const double first_r2 = r2;
    const std::int64_t line_searches = std::max<std::int64_t>(c.line_searches, 1);
    for (std::int64_t newton = 0; newton < c.max_iterations; ++newton) {
        const double previous_r2 = r2;
        const double previous_x2 = c.relative_estimate > 0.0 ? fn.squared_guess() : 0.0;
        fn.solve_linearised();
        double alpha = 1.0, previous_alpha = 0.0;
        bool decreased = false;
        for (std::int64_t search = 0; search < line_searches; ++search) {
            fn.update(alpha - previous_alpha);
            r2 = fn.evaluate();
            if (r2 < previous_r2) {
                decreased = true;
                break;
            }
            previous_alpha = alpha;
            alpha *= c.line_search_coefficient;
        }
        if (!decreased && line_searches > 1) {  // no decrease: the full step after all
            fn.update(1.0 - previous_alpha);
            r2 = fn.evaluate();
        }
        if (c.relative_successive > 0.0 && r2 < c.relative_successive * c.relative_successive * previous_r2) break;
        if (c.relative_initial > 0.0 && r2 < c.relative_initial * c.relative_initial * first_r2) break;
        if (c.absolute_residual > 0.0 && r2 < c.absolute_residual * c.absolute_residual) break;
        if (c.absolute_estimate > 0.0 || c.relative_estimate > 0.0) {
            const double dx2 = fn.squared_correction();
            if (c.relative_estimate > 0.0 && previous_x2 > 0.0 &&
                dx2 < previous_x2 * (c.relative_estimate * c.relative_estimate))
                break;
            if (c.absolute_estimate > 0.0 && dx2 < c.absolute_estimate * c.absolute_estimate) break;
        }
    }
}

// SOFA's StaticSolver with its NewtonRaphsonSolver: x such that f(x) = 0 (projected). The residual
// is f after ops.propagate(), ops.forces() and ops.project_forces(); each Newton iteration solves
// -K dx = f (mass and damping factors 0); x moves by alpha dx. Velocities are left as they are.
template <class Space, class Operations>
void newton_raphson(const Space& space, const SchemeVectors<Space>& s, const NewtonControls& c,
                    const Operations& ops) {
    struct Equilibrium {
        const Space& space;
        const SchemeVectors<Space>& s;
        const Operations& ops;
        double evaluate() const {
            ops.propagate();
            ops.forces();
            ops.project_forces();
            return space.dot(s.f, s.f);
        }
        void solve_linearised() const {
            space.copy(s.r, s.f);
            ops.solve(0.0, -1.0, 0.0);
        }
        void update(double alpha) const { space.advance(s.x, s.x, s.acc, alpha); }
        double squared_guess() const { return space.dot_coordinates(s.x, s.x); }
        double squared_correction() const { return space.dot(s.acc, s.acc); }
    } equilibrium{space, s, ops};
    newton_solve(c, equilibrium);
}

// BDFOdeSolver's parameters for one step (and its NewtonRaphsonSolver's).
struct BdfControls {
    double h;
    double time;  // the scene's time at the start of the step
    std::int64_t order;  // d_order (at least 1)
    double rayleigh_stiffness, rayleigh_mass;
    NewtonControls newton;
};

// The solver's vectors: x and v of the step's start, the residuals r1 (positions) and r2
// (momenta). Point states only: SOFA adds coordinates and derivatives as vectors.
template <class Space>
struct BdfVectors {
    typename Space::Vector x_previous, v_previous, r1, r2;
};

// What BDFOdeSolver keeps between steps (reset restores it): its time list (capacity order + 2),
// the list's length and the number of solves done; and room for the coefficients a, b (order + 1
// each).
struct BdfHistory {
    double* times;
    Index& count;
    Index& solves;
    double* a;
    double* b;
};

// BDFOdeSolver::computeLinearMultiStepCoefficients on the times t_0..t_k: a_j the derivative at t_k
// of the j-th Lagrange polynomial, times t_k - t_k-1, divided by a_k (then 1); b_k = 1 / a_k, the
// other b_j 0. In SOFA's order of operations.
inline void bdf_coefficients(const double* t, Index k, double* a, double* b) {
    for (Index j = 0; j <= k; ++j) {
        a[j] = 0.0;
        for (Index i = 0; i <= k; ++i) {
            if (i == j) continue;
            double product = 1.0;
            for (Index m = 0; m <= k; ++m)
                if (m != i && m != j) product *= (t[k] - t[m]) / (t[j] - t[m]);
            a[j] += product / (t[j] - t[i]);
        }
    }
    const double dt = t[k] - t[k - 1];
    for (Index j = 0; j <= k; ++j) a[j] *= dt;
    for (Index j = 0; j < k; ++j) a[j] /= a[k];
    b[k] = 1 / a[k];
    a[k] = 1;
    for (Index j = 0; j < k; ++j) b[j] = 0;
}

// SOFA's BDFOdeSolver (BaseLinearMultiStepMethod::solve), order k = min(order, solves + 1): the
// Newton-Raphson solver on r = (r1, r2),
//   r1 = sum_j a_j x_j - h sum_j b_j v_j,   r2 = M sum_j a_j v_j - h sum_j b_j f_j,
// f_j = f(x_j, v_j) - rm M v_j + rk K v_j (projected), the guess (x_k, v_k) starting at
// (x + h v, v); each iteration solves (a_k + h b_k rm) M - h b_k B - h b_k (rk + h b_k / a_k) K) dv =
// -r2 - (h b_k / a_k) K r1, then v_k += alpha dv, x_k += (h b_k / a_k) dv - r1 / a_k, projected
// and mapped. SOFA keeps its vector ids from step to step: the slots below k still name the
// state's own x, v, f (each was xResult when the order was lower), so every x_j, v_j with j < k is
// the step's start: x_previous, v_previous here (and f_j is never read: b_j = 0). The guess lives
// in x, v, f, which SOFA copies them into at the end.
template <class Space, class Operations>
void bdf_step(const Space& space, const SchemeVectors<Space>& s, const BdfVectors<Space>& w, const BdfControls& c,
              BdfHistory history, const Operations& ops) {
    static_assert(Space::all_points, "rigid frames: x and dx do not share a layout");
    const double h = c.h, rk = c.rayleigh_stiffness, rm = c.rayleigh_mass;
    const Index k = std::max<Index>(std::min<Index>(c.order, history.solves + 1), 1);
    history.times[history.count++] = c.time + h;
    while (history.count > k + 1) {  // pop_front
        for (Index j = 1; j < history.count; ++j) history.times[j - 1] = history.times[j];
        --history.count;
    }
    const double* a = history.a;
    const double* b = history.b;
    bdf_coefficients(history.times, k, history.a, history.b);

    space.copy_coordinates(w.x_previous, s.x);
    space.copy(w.v_previous, s.v);
    space.add_scaled_coordinates(s.x, s.x, s.v, h);  // the prediction x + h v
    ops.propagate();

    struct Residual {
        const Space& space;
        const SchemeVectors<Space>& s;
        const BdfVectors<Space>& w;
        const Operations& ops;
        const double* a;
        const double* b;
        Index k;
        double h, rk, rm;
        double evaluate() const {
            ops.forces();
            space.copy(s.dx, s.v);  // Rayleigh damping: f += -rm M v + rk K v
            space.copy(s.df, s.f);
            ops.add_product(-rm, rk, 0.0);
            space.copy(s.f, s.df);
            ops.project_forces();
            space.clear(w.r1);  // r1 = sum a_j x_j - h sum b_j v_j
            for (Index j = 0; j <= k; ++j)
                if (a[j] != 0) space.add_scaled_coordinates(w.r1, w.r1, j < k ? w.x_previous : s.x, a[j]);
            for (Index j = 0; j <= k; ++j)
                if (b[j] != 0) space.add_scaled(w.r1, w.r1, j < k ? w.v_previous : s.v, -h * b[j]);
            space.clear(s.dx);  // r2 = M (sum a_j v_j) - h b_k f_k
            for (Index j = 0; j <= k; ++j)
                if (a[j] != 0) space.add_scaled(s.dx, s.dx, j < k ? w.v_previous : s.v, a[j]);
            ops.mass();
            space.copy(w.r2, s.df);
            if (b[k] != 0) space.add_scaled(w.r2, w.r2, s.f, -h * b[k]);
            space.copy(s.r, w.r1);
            ops.project_rhs();
            space.copy(w.r1, s.r);
            space.copy(s.r, w.r2);
            ops.project_rhs();
            space.copy(w.r2, s.r);
            return space.dot(w.r2, w.r2);
        }
        void solve_linearised() const {
            space.copy(s.r, w.r2);  // rhs = -r2 - (h b_k / a_k) K r1
            space.scale(s.r, -1.0);
            space.copy(s.dx, w.r1);
            space.copy(s.df, s.r);
            ops.add_product(0.0, -h * b[k] / a[k], 0.0);
            space.copy(s.r, s.df);
            ops.project_rhs();
            space.clear(s.acc);
            ops.solve(a[k] + h * b[k] * rm, -h * b[k] * (rk + h * b[k] / a[k]), -h * b[k]);
        }
        void update(double alpha) const {
            space.add_scaled(s.v, s.v, s.acc, alpha);
            space.copy(s.dx, s.acc);  // dx = (h b_k / a_k) dv - r1 / a_k
            space.scale(s.dx, h * b[k] / a[k]);
            space.add_scaled(s.dx, s.dx, w.r1, -1 / a[k]);
            space.add_scaled_coordinates(s.x, s.x, s.dx, 1.0);
            ops.project_position_velocity();
            ops.propagate();
        }
        double squared_guess() const { return space.dot(s.v, s.v); }
        double squared_correction() const { return space.dot(s.acc, s.acc); }
    } residual{space, s, w, ops, a, b, k, h, rk, rm};
    newton_solve(c.newton, residual);
    ++history.solves;
}

// VariationalSymplecticSolver's parameters for one step.
struct VariationalControls {
    double h;
    double rayleigh_stiffness, rayleigh_mass;
    std::int64_t max_newton;  // steps
    double newton_error;      // newtonError
    double time;              // the scene's time: at 0 (after a reset) the momentum starts again
    bool hamiltonian;         // computeHamiltonian
    bool incremental_potential;  // useIncrementalPotentialEnergy (with computeHamiltonian)
};

// The solver's own vectors: x_k, the previous Newton iterate, the momenta p_k and p_k+1.
template <class Space>
struct VariationalVectors {
    typename Space::Vector x0, xi, momentum, new_momentum;
};

// Where computeHamiltonian writes (null when it is not computed).
struct VariationalOutputs {
    double* incremental = nullptr;  // the incremental potential energy
    double* energies = nullptr;     // kinetic, potential
    double* hamiltonian = nullptr;  // their sum
};

// SOFA's VariationalSymplecticSolver (implicit, alpha = 1/2): Newton iterations on the
// displacement res from x_k to the midpoint, from res = 0:
//   ((4/h^2 + 4 rm/h) M - (1 + 4 rk/h) K) res' = f(x_k + res) - K res + (2/h) p   (b projected)
// until |res' - res| <= newtonError |x_k| or max_newton iterations; then v = (2/h) res,
// p = (h/2) f(x_k + (h/2) v) (projected) + M v, x = x_k + h v. The momentum p starts as M v, at the
// first step (started == 0) or at time 0. computeHamiltonian: a last solve M b = p gives the
// kinetic energy p.b / 2.
template <class Space, class Operations>
void variational_symplectic_step(const Space& space, const SchemeVectors<Space>& s,
                                 const VariationalVectors<Space>& w, const VariationalControls& c,
                                 Index& started, const VariationalOutputs& out, const Operations& ops) {
    static_assert(Space::all_points, "rigid frames: x and dx do not share a layout");
    const double h = c.h, rk = c.rayleigh_stiffness, rm = c.rayleigh_mass;
    if (started == 0 || c.time == 0.0) {
        space.copy(s.dx, s.v);
        ops.mass();
        space.copy(w.momentum, s.df);
        if (c.hamiltonian && c.incremental_potential) {
            double kinetic = 0.0, potential = 0.0;
            ops.energy(kinetic, potential);
            *out.incremental = potential;
        }
        started = 1;
    }
    space.copy_coordinates(w.x0, s.x);
    space.copy_coordinates(w.xi, s.x);
    space.clear(s.acc);
    const double position_norm = std::sqrt(space.dot_coordinates(s.x, s.x));
    std::int64_t newton = 0;
    for (;;) {
        // b = f(x_k + res) + (2/h) p - K res, projected
        ops.forces();
        space.add_scaled(s.df, s.f, w.momentum, 2.0 / h);
        if (newton > 0) {  // res = 0 at the first iteration
            space.copy(s.dx, s.acc);
            ops.add_product(0.0, -1.0, 0.0);
        }
        space.copy(s.r, s.df);
        ops.project_rhs();
        ops.solve(4.0 / (h * h) + 4 * rm / h, -1.0 - 4 * rk / h, 0.0);
        // x = x_k + res; |res - previous res| / |x_k| decides whether Newton goes on
        space.add_scaled_coordinates(s.x, w.x0, s.acc, 1.0);
        space.add_scaled_coordinates(w.xi, s.x, w.xi, -1.0);
        const double change2 = space.dot_coordinates(w.xi, w.xi);
        space.copy_coordinates(w.xi, s.x);
        ops.propagate();
        ++newton;
        if (newton < c.max_newton && std::sqrt(change2) / position_norm > c.newton_error) continue;
        break;
    }
    if (c.hamiltonian && c.incremental_potential)  // the potential energy changes by -2 f.res (f unprojected)
        *out.incremental += -2.0 * space.dot(s.f, s.acc);
    // v = (2/h) res; p_k+1 = (h/2) f(x_k + (h/2) v), projected, + M v; x = x_k + (h/2) v + (h/2) v
    space.copy(s.v, s.acc);
    space.scale(s.v, 2.0 / h);
    space.add_scaled_coordinates(s.x, w.x0, s.v, h / 2);
    ops.forces();  // the mapped states keep the last iterate's positions, as in SOFA
    ops.project_forces();
    space.copy(s.dx, s.v);
    ops.mass();
    space.add_scaled(w.new_momentum, s.df, s.f, h / 2.0);
    space.add_scaled_coordinates(s.x, s.x, s.v, h / 2);
    if (c.hamiltonian) {  // b = p_k+1, from 0: M b = p_k+1, kinetic energy p_k+1.b / 2
        space.copy(s.r, w.new_momentum);
        space.clear(s.acc);
        ops.solve(1.0, 0.0, 0.0);
        const double kinetic = 0.5 * space.dot(w.new_momentum, s.acc);
        double potential = 0.0;
        if (c.incremental_potential) {
            potential = *out.incremental;
        } else {
            double ignored_kinetic = 0.0;  // the force fields' own potential energy
            ops.energy(ignored_kinetic, potential);
        }
        out.energies[0] = kinetic;
        out.energies[1] = potential;
        *out.hamiltonian = kinetic + potential;
    }
    space.copy(w.momentum, w.new_momentum);
}

}  // namespace sofac
