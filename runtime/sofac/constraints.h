// Lagrangian constraints: the solvers of SOFA's constraint framework and what they work on.
//
// A problem has n rows. W (n x n, row-major) is the compliance in constraint space, dfree the
// violations of the free motion, f the constraint forces (impulses: x = x_free + dt C J^T f with
// EulerImplicit's factors). Rows come in blocks, each with its resolution (SOFA's
// ConstraintResolution subclasses, here an enum and a switch: no virtual call):
//   Bilateral3            BilateralConstraintResolution3Dof: exact 3x3 solve, warm started
//   Bilateral1            BilateralConstraintResolution: f -= d / w, warm started
//   Unilateral1           UnilateralConstraintResolution: f -= d / w, then f >= 0
//   UnilateralFriction3   UnilateralConstraintResolutionWithFriction: normal, then tangents in
//                         Coulomb's cone of coefficient `parameter`
//   Stopper1              StopperLagrangianConstraintResolution1Dof: the free displacement kept in
//                         [parameter, upper] (min, max), no warm start
// Solvers, with SOFA's stopping tests, iteration counts and order of operations:
//   block_gauss_seidel    BlockGaussSeidelConstraintSolver::doSolve (built W)
//   nncg                  NNCGConstraintSolver::doSolve
//   unbuilt_gauss_seidel  UnbuiltGaussSeidelConstraintSolver::doSolve (diagonal blocks of W, the
//                         displacements through the corrections)
//   lcp_gauss_seidel      LCPConstraintSolver's nlcp_gaussseidel (built, with friction)
// and the UncoupledConstraintCorrection kernels (W += factor J C J^T, dx = C J^T f).
//
// W is stored dense, but written and read as sparse (CompliancePattern): the corrections add only
// the entries of rows that share a DOF, the step clears only what was written, and the sweeps read
// each row's written entries only, in the dense loops' order (which changes no bit: see
// add_rows_product).
//
// Storage is the caller's (instance buffers sized at compile time), but for CompliancePattern's
// lists, reserved with the rows' capacity: a steady-state step allocates nothing.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

#include "quaternion.h"
#include "types.h"

namespace sofac {

enum class Resolution : int {
    Bilateral3 = 0,
    Bilateral1 = 1,
    Unilateral1 = 2,
    UnilateralFriction3 = 3,
    Stopper1 = 4
};

inline constexpr int resolution_lines(Resolution kind) {
    return kind == Resolution::Bilateral3 || kind == Resolution::UnilateralFriction3 ? 3 : 1;
}

// One block of rows and its resolution's state.
struct RowBlock {
    Index first = 0;  // first row
    Resolution kind = Resolution::Unilateral1;
    double parameter = 1.0;      // Bilateral*: load; UnilateralFriction3: mu; Stopper1: min
    double upper = 0.0;          // Stopper1: max
    double* previous = nullptr;  // Bilateral*: forces kept from the last solve (warm start), or none
    double block[9] = {};        // Bilateral3: inverse of W's block; UnilateralFriction3: W00 W01 W02 W11 W12 W22
    bool singular = false;       // Bilateral3: the block did not invert (SOFA leaves the inverse zero)
};

struct ConstraintProblem {
    Index n = 0;
    double* W = nullptr;      // n x n, row-major
    double* dfree = nullptr;  // n
    double* f = nullptr;      // n
    double* d = nullptr;      // n, scratch
    RowBlock* blocks = nullptr;
    Index block_count = 0;
    double* scratch = nullptr;  // 3 n: NNCG's lambda, deltaF, p; SOR's previous forces (n)
    // W's written entries, row by row (CompliancePattern::finish): row i's columns, ascending, are
    // columns[row_start[i] .. row_start[i + 1]); null: W is read whole.
    const Index* row_start = nullptr;
    const Index* columns = nullptr;
    bool forces_finite = false;  // every f[c] finite (the sweeps keep it; see add_rows_product)

    double w(Index i, Index j) const { return W[n * i + j]; }
};

// Whether the sweeps may read only W's written entries from now on: f all finite (a sweep checks it
// at its start, then after each block it changes).
inline void check_forces(ConstraintProblem& p) {
    p.forces_finite = true;
    if (p.columns == nullptr) return;
    for (Index c = 0; c < p.n; ++c)
        if (!std::isfinite(p.f[c])) p.forces_finite = false;
}

inline void check_forces(ConstraintProblem& p, Index first, int lines) {
    for (int l = 0; l < lines; ++l)
        if (!std::isfinite(p.f[first + l])) p.forces_finite = false;
}

// d[l] + sum over c ascending of W(row + l, c) f[c] for the `lines` (at most 3) rows of a block,
// SOFA's dense loop, bit for bit. A row is summed over its written entries when W's are known, f
// is finite and d[l] is not -0: every entry left out is +0 (never written since W was cleared), so
// its term (+0) f[c] is +0 or -0, and adding a zero gives back any sum but -0 exactly; a sum is -0
// only when it starts at -0 and adds -0 terms only. Otherwise (a non-finite force: 0 inf is NaN)
// over every column, the block's rows side by side (three independent sums: SOFA's loop order).
inline void add_rows_product(const ConstraintProblem& p, Index row, int lines, double* d) {
    const bool sparse = p.columns != nullptr && p.forces_finite;
    if (!sparse) {
        for (Index c = 0; c < p.n; ++c)
            for (int l = 0; l < lines; ++l) d[l] += p.w(row + l, c) * p.f[c];
        return;
    }
    for (int l = 0; l < lines; ++l) {
        const double* w = p.W + p.n * (row + l);
        double sum = d[l];
        if (sum == 0.0 && std::signbit(sum)) {
            for (Index c = 0; c < p.n; ++c) sum += w[c] * p.f[c];
        } else {
            for (Index e = p.row_start[row + l]; e < p.row_start[row + l + 1]; ++e) {
                const Index c = p.columns[e];
                sum += w[c] * p.f[c];
            }
        }
        d[l] = sum;
    }
}

struct ConstraintSettings {
    Index max_iterations = 1000;
    double tolerance = 1e-3;
    double sor = 1.0;
    bool scale_tolerance = true;
    bool all_verified = false;
};

struct ConstraintResult {
    Index iterations = 0;  // SOFA's currentIterations (BGS, NNCG: sweeps + 1, as result_output counts)
    Index sweeps = 0;      // Gauss-Seidel sweeps done
    double error = 0.0;    // the last sweep's error (SOFA's currentError)
    bool converged = false;
    Index singular_blocks = 0;  // Bilateral3 blocks of W that did not invert (redundant rows)
    bool stalled = false;       // NNCG: stopped as the forces stopped changing (SOFA: not converged)
};

// The run report of a solve: report[0] solves, [1] and [2] the last one's iterations and error,
// [3] the unconverged solves and [4..6] the last of those (time, error, iterations). A step with
// no row (`any_row` false) has nothing to converge.
inline void record_solve(double* report, const ConstraintResult& result, double time,
                         bool any_row = true) {
    report[0] += 1.0;
    report[1] = double(result.iterations);
    report[2] = result.error;
    if (any_row && !result.converged) {
        report[3] += 1.0;
        report[4] = time;
        report[5] = result.error;
        report[6] = double(result.iterations);
    }
}

// The constraint step's timer: each lap adds the steady-clock seconds since the previous lap (or
// since construction) to one of the run report's *_seconds fields (plan ir.CONSTRAINT_REPORT_FIELDS).
// Reading the clock changes nothing the step computes and allocates nothing.
struct PhaseClock {
    explicit PhaseClock(double* report) : report_(report), last_(std::chrono::steady_clock::now()) {}

    void lap(int field) {
        const auto now = std::chrono::steady_clock::now();
        report_[field] += std::chrono::duration<double>(now - last_).count();
        last_ = now;
    }

  private:
    double* report_;
    std::chrono::steady_clock::time_point last_;
};

// SOFA's type::invertMatrix for 3x3 (cofactors over the determinant; false when |det| <= eps).
inline bool invert3(const double m[9], double out[9]) {
    const double det = m[0] * m[4] * m[8] + m[3] * m[7] * m[2] + m[6] * m[1] * m[5] - m[0] * m[7] * m[5] -
                       m[3] * m[1] * m[8] - m[6] * m[4] * m[2];
    if (std::fabs(det) <= std::numeric_limits<double>::epsilon()) return false;
    out[0] = (m[4] * m[8] - m[7] * m[5]) / det;
    out[3] = (m[5] * m[6] - m[8] * m[3]) / det;
    out[6] = (m[3] * m[7] - m[6] * m[4]) / det;
    out[1] = (m[7] * m[2] - m[1] * m[8]) / det;
    out[4] = (m[8] * m[0] - m[2] * m[6]) / det;
    out[7] = (m[6] * m[1] - m[0] * m[7]) / det;
    out[2] = (m[1] * m[5] - m[4] * m[2]) / det;
    out[5] = (m[2] * m[3] - m[5] * m[0]) / det;
    out[8] = (m[0] * m[4] - m[3] * m[1]) / det;
    return true;
}

// ConstraintResolution::init: block data from W, warm start from the kept forces.
inline void resolution_init(RowBlock& b, const ConstraintProblem& p) {
    const Index l = b.first;
    switch (b.kind) {
        case Resolution::Bilateral3: {
            double m[9];
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) m[3 * i + j] = p.w(l + i, l + j);
            b.singular = !invert3(m, b.block);
            if (b.singular)
                for (double& value : b.block) value = 0.0;
            if (b.previous)
                for (int i = 0; i < 3; ++i) p.f[l + i] = b.previous[i];
            break;
        }
        case Resolution::Bilateral1:
            if (b.previous) p.f[l] = b.previous[0];
            break;
        case Resolution::UnilateralFriction3:
            b.block[0] = p.w(l, l);
            b.block[1] = p.w(l, l + 1);
            b.block[2] = p.w(l, l + 2);
            b.block[3] = p.w(l + 1, l + 1);
            b.block[4] = p.w(l + 1, l + 2);
            b.block[5] = p.w(l + 2, l + 2);
            break;
        case Resolution::Stopper1:
            p.f[l] = 0.0;
            break;
        case Resolution::Unilateral1:
            break;
    }
}

// ConstraintResolution::resolution: the block's new forces from its displacement d (W f + dfree).
inline void resolution_solve(const RowBlock& b, const ConstraintProblem& p, double* d, double* f) {
    const Index l = b.first;
    switch (b.kind) {
        case Resolution::Bilateral3:
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) f[l + i] -= d[l + j] * b.block[3 * i + j] * b.parameter;
            break;
        case Resolution::Bilateral1:
            f[l] -= d[l] / p.w(l, l);
            break;
        case Resolution::Unilateral1:
            f[l] -= d[l] / p.w(l, l);
            if (f[l] < 0) f[l] = 0.0;
            break;
        case Resolution::Stopper1: {
            const double w = p.w(l, l);
            const double free = d[l] - w * f[l];
            if (free > b.upper)
                f[l] = (b.upper - free) * (1.0 / w);
            else if (free < b.parameter)
                f[l] = (b.parameter - free) * (1.0 / w);
            else
                f[l] = 0;
            break;
        }
        case Resolution::UnilateralFriction3: {
            const double* w = b.block;
            const double f0 = f[l];
            f[l] -= d[l] / w[0];
            if (f[l] < 0) {
                f[l] = 0;
                f[l + 1] = 0;
                f[l + 2] = 0;
                return;
            }
            d[l + 1] += w[1] * (f[l] - f0);
            d[l + 2] += w[2] * (f[l] - f0);
            f[l + 1] -= 2 * d[l + 1] / (w[3] + w[5]);
            f[l + 2] -= 2 * d[l + 2] / (w[3] + w[5]);
            const double tangential = std::sqrt(f[l + 1] * f[l + 1] + f[l + 2] * f[l + 2]);
            const double limit = b.parameter * f[l];
            if (tangential > limit) {
                const double factor = limit / tangential;
                f[l + 1] *= factor;
                f[l + 2] *= factor;
            }
            break;
        }
    }
}

// ConstraintResolution::store: the forces kept for the next solve's warm start.
inline void resolution_store(const RowBlock& b, const double* f) {
    if (!b.previous) return;
    for (int i = 0; i < resolution_lines(b.kind); ++i) b.previous[i] = f[b.first + i];
}

inline void init_blocks(ConstraintProblem& p, ConstraintResult& result) {
    for (Index k = 0; k < p.block_count; ++k) {
        resolution_init(p.blocks[k], p);
        result.singular_blocks += p.blocks[k].singular ? 1 : 0;
    }
}

// The error of one block after its resolution (errF: its forces before), SOFA's measure.
inline double block_error(const ConstraintProblem& p, const RowBlock& b, const double* before, double tol,
                          bool& verified) {
    const int nb = resolution_lines(b.kind);
    const Index j = b.first;
    if (nb > 1) {
        double error = 0.0;
        for (int l = 0; l < nb; ++l) {
            double line = 0.0;
            for (int m = 0; m < nb; ++m) {
                const double dof = p.w(j + l, j + m) * (p.f[j + m] - before[m]);
                line += dof * dof;
            }
            line = std::sqrt(line);
            if (line > tol) verified = false;
            error += line;
        }
        return error;
    }
    const double error = std::fabs(p.w(j, j) * (p.f[j] - before[0]));
    if (error > tol) verified = false;
    return error;
}

// BlockGaussSeidelConstraintSolver::gaussSeidel_increment: one sweep over the blocks in row order,
// d = dfree + W f (k ascending over the rows, the block's own included; add_rows_product).
inline double gauss_seidel_sweep(ConstraintProblem& p, bool measure, double tol, bool& verified) {
    double error = 0.0;
    check_forces(p);
    for (Index k = 0; k < p.block_count; ++k) {
        const RowBlock& b = p.blocks[k];
        const int nb = resolution_lines(b.kind);
        const Index j = b.first;
        double before[3];
        for (int l = 0; l < nb; ++l) {
            before[l] = p.f[j + l];
            p.d[j + l] = p.dfree[j + l];
        }
        add_rows_product(p, j, nb, p.d + j);
        resolution_solve(b, p, p.d, p.f);
        check_forces(p, j, nb);
        if (measure)
            error += block_error(p, b, before, tol, verified);
        else
            verified = true;
    }
    return error;
}

inline double scaled_tolerance(const ConstraintProblem& p, const ConstraintSettings& s) {
    return s.scale_tolerance && !s.all_verified ? s.tolerance * double(p.n) : s.tolerance;
}

inline void store_blocks(const ConstraintProblem& p) {
    for (Index k = 0; k < p.block_count; ++k) resolution_store(p.blocks[k], p.f);
}

// BlockGaussSeidelConstraintSolver::doSolve. scratch: n numbers when sor != 1.
inline ConstraintResult block_gauss_seidel(ConstraintProblem& p, const ConstraintSettings& s) {
    ConstraintResult result;
    if (p.n == 0) return result;  // error 0, iterations 0
    const double tol = scaled_tolerance(p, s);
    init_blocks(p, result);
    double error = 0.0;
    Index sweeps = 0;
    for (Index it = 0; it < s.max_iterations; ++it) {
        ++sweeps;
        bool verified = true;
        if (s.sor != 1.0)
            for (Index j = 0; j < p.n; ++j) p.scratch[j] = p.f[j];
        error = gauss_seidel_sweep(p, true, tol, verified);
        if (s.sor != 1.0)
            for (Index j = 0; j < p.n; ++j) p.f[j] = s.sor * p.f[j] + (1 - s.sor) * p.scratch[j];
        if (s.all_verified ? verified : error < tol) {
            result.converged = true;
            break;
        }
    }
    result.sweeps = sweeps;
    result.iterations = sweeps + 1;  // GenericConstraintProblem::result_output
    result.error = error;
    store_blocks(p);
    return result;
}

inline double dot(const double* a, const double* b, Index n) {
    double sum = 0.0;
    for (Index i = 0; i < n; ++i) sum += a[i] * b[i];
    return sum;
}

// NNCGConstraintSolver::doSolve: a Gauss-Seidel sweep as the first direction, then sweeps
// accelerated by a Fletcher-Reeves step (restarted when beta > 1). scratch: 3 n numbers.
inline ConstraintResult nncg(ConstraintProblem& p, const ConstraintSettings& s) {
    ConstraintResult result;
    if (p.n == 0) return result;
    const Index n = p.n;
    double* lambda = p.scratch;
    double* delta = p.scratch + n;
    double* direction = p.scratch + 2 * n;
    for (Index j = 0; j < 3 * n; ++j) p.scratch[j] = 0.0;
    const double tol = scaled_tolerance(p, s);
    init_blocks(p, result);
    bool verified = true;
    for (Index j = 0; j < n; ++j) lambda[j] = p.f[j];
    double error = gauss_seidel_sweep(p, false, tol, verified);
    for (Index j = 0; j < n; ++j) {
        delta[j] = -(p.f[j] - lambda[j]);
        direction[j] = -delta[j];
    }
    Index count = 0;
    for (Index it = 1; it < s.max_iterations; ++it) {
        ++count;
        verified = true;
        for (Index j = 0; j < n; ++j) lambda[j] = p.f[j];
        error = gauss_seidel_sweep(p, true, tol, verified);
        if (s.all_verified ? verified : error < tol) {
            result.converged = true;
            break;
        }
        // deltaF_new (kept in lambda, which is not read again this iteration)
        for (Index j = 0; j < n; ++j) lambda[j] = -(p.f[j] - lambda[j]);
        const double beta = dot(lambda, lambda, n) / dot(delta, delta, n);
        for (Index j = 0; j < n; ++j) delta[j] = lambda[j] * 1;
        if (beta > 1) {
            for (Index j = 0; j < n; ++j) direction[j] = 0.0;
        } else {
            for (Index j = 0; j < n; ++j) {
                p.f[j] += beta * direction[j];
                direction[j] = beta * direction[j] - delta[j];
            }
        }
        if (std::sqrt(dot(lambda, lambda, n)) < tol) {
            result.stalled = true;
            break;
        }
    }
    result.sweeps = count + 1;
    result.iterations = count + 1;
    result.error = error;
    store_blocks(p);
    return result;
}

// The built solvers of the loop's constraint rows (BlockGaussSeidelConstraintSolver, NNCGConstraintSolver).
enum class BuiltSolver { BlockGaussSeidel, Nncg };

// One solve by a built solver of the loop (its solver's component decides which).
inline ConstraintResult solve_built(BuiltSolver solver, ConstraintProblem& p, const ConstraintSettings& settings) {
    return solver == BuiltSolver::Nncg ? nncg(p, settings) : block_gauss_seidel(p, settings);
}

// UnbuiltGaussSeidelConstraintSolver::doSolve. W holds only the blocks' diagonal blocks;
// `corrections` gives each block's displacement from the forces so far and takes force changes:
//   corrections.add_displacement(d, first, last)   d[first..last] += J C (J^T f) of those rows
//   corrections.set_force_change(df, first, last)  J^T df of those rows into the corrections
// Forces start from zero (SOFA erases them after the warm start of `init`).
template <class Corrections>
inline ConstraintResult unbuilt_gauss_seidel(ConstraintProblem& p, const ConstraintSettings& s,
                                             Corrections& corrections) {
    ConstraintResult result;
    if (p.n == 0) return result;
    const double tol = scaled_tolerance(p, s);
    init_blocks(p, result);
    for (Index j = 0; j < p.n; ++j) p.f[j] = 0.0;
    double error = 0.0;
    Index iteration = 0;
    for (iteration = 0; iteration < s.max_iterations; ++iteration) {
        bool verified = true;
        if (s.sor != 1.0)
            for (Index j = 0; j < p.n; ++j) p.scratch[j] = p.f[j];
        error = 0.0;
        for (Index k = 0; k < p.block_count; ++k) {
            const RowBlock& b = p.blocks[k];
            const int nb = resolution_lines(b.kind);
            const Index j = b.first;
            double before[3];
            for (int l = 0; l < nb; ++l) {
                before[l] = p.f[j + l];
                p.d[j + l] = p.dfree[j + l];
            }
            corrections.add_displacement(p.d, j, j + nb - 1);
            resolution_solve(b, p, p.d, p.f);
            error += block_error(p, b, before, tol, verified);
            bool update = false;
            for (int l = 0; l < nb; ++l) update |= (p.f[j + l] != 0.0 || before[l] != 0.0);
            if (update) {
                double kept[3];
                for (int l = 0; l < nb; ++l) {
                    kept[l] = p.f[j + l];
                    p.f[j + l] -= before[l];
                }
                corrections.set_force_change(p.f, j, j + nb - 1);
                for (int l = 0; l < nb; ++l) p.f[j + l] = kept[l];
            }
        }
        if (s.sor != 1.0)
            for (Index j = 0; j < p.n; ++j) p.f[j] = s.sor * p.f[j] + (1 - s.sor) * p.scratch[j];
        if (s.all_verified ? verified : error < tol) {
            result.converged = true;
            break;
        }
    }
    // result_output(iter): iter is the loop index at exit (sweeps - 1 when converged), plus one
    result.sweeps = result.converged ? iteration + 1 : iteration;
    result.iterations = iteration + 1;
    result.error = error;
    store_blocks(p);
    return result;
}

// LCPConstraintSolver, built, mu > 0: helper::nlcp_gaussseidel on contacts of 3 rows (normal and
// two tangents), Coulomb's cone of coefficient mu (the solver's own). f starts from zero unless
// `initial_force`. Converged when the sum over contacts of |d - d_before| < tol (numContacts + 1);
// then contacts whose normal force reaches maxF (when set) are released.
struct LcpSettings {
    Index max_iterations = 1000;
    double tolerance = 1e-3;
    double mu = 0.6;
    double min_w = 0.0;
    double max_f = 0.0;
    bool initial_force = false;
};

inline double abs_error(const double a[3], const double b[3]) {
    return std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
}

// LocalBlock33::GS_State: one contact's forces from its displacement d (own forces excluded);
// d then includes them, unless the contact separates (f = 0, d unchanged).
inline void lcp_contact(const double w[6], double mu, double d[3], double f[3]) {
    double fn = f[0], ft = f[1], fs = f[2];
    const double d0 = w[0] * fn + w[1] * ft + w[2] * fs + d[0];
    fn -= d0 / w[0];
    if (fn < 0) {
        f[0] = f[1] = f[2] = 0;
        return;
    }
    const double d1 = w[1] * fn + w[3] * ft + w[4] * fs + d[1];
    const double d2 = w[2] * fn + w[4] * ft + w[5] * fs + d[2];
    ft -= 2 * d1 / (w[3] + w[5]);
    fs -= 2 * d2 / (w[3] + w[5]);
    const double tangential = std::sqrt(ft * ft + fs * fs);
    if (tangential > mu * fn) {
        ft *= mu * fn / tangential;
        fs *= mu * fn / tangential;
    }
    d[0] += w[0] * fn + w[1] * ft + w[2] * fs;
    d[1] += w[1] * fn + w[3] * ft + w[4] * fs;
    d[2] += w[2] * fn + w[4] * ft + w[5] * fs;
    f[0] = fn, f[1] = ft, f[2] = fs;
}

inline ConstraintResult lcp_gauss_seidel(ConstraintProblem& p, const LcpSettings& s) {
    ConstraintResult result;
    const Index n = p.n;
    const Index contacts = n / 3;
    if (n == 0 || n % 3) return result;
    if (!s.initial_force)
        for (Index j = 0; j < n; ++j) p.f[j] = 0.0;
    double error = 0.0;
    Index it = 0;
    for (it = 0; it < s.max_iterations; ++it) {
        error = 0.0;
        check_forces(p);
        for (Index c = 0; c < contacts; ++c) {
            const Index r = 3 * c;
            double* fc = p.f + r;
            double f1[3] = {fc[0], fc[1], fc[2]};
            fc[0] = fc[1] = fc[2] = 0.0;
            double d[3] = {p.dfree[r], p.dfree[r + 1], p.dfree[r + 2]};
            add_rows_product(p, r, 3, d);
            double before[3];
            for (int l = 0; l < 3; ++l)
                before[l] = d[l] + p.w(r + l, r) * f1[0] + p.w(r + l, r + 1) * f1[1] + p.w(r + l, r + 2) * f1[2];
            if (s.min_w != 0.0 && std::fabs(p.w(r, r)) <= s.min_w) {
                f1[0] = f1[1] = f1[2] = 0.0;  // compliance too small: no force
            } else {
                const double w[6] = {p.w(r, r),         p.w(r, r + 1),     p.w(r, r + 2),
                                     p.w(r + 1, r + 1), p.w(r + 1, r + 2), p.w(r + 2, r + 2)};
                lcp_contact(w, s.mu, d, f1);
            }
            error += abs_error(d, before);
            fc[0] = f1[0], fc[1] = f1[1], fc[2] = f1[2];
            check_forces(p, r, 3);
        }
        if (error < s.tolerance * double(contacts + 1)) {
            result.converged = true;
            if (s.max_f != 0.0)
                for (Index c = 0; c < contacts; ++c)
                    if (std::fabs(p.f[3 * c]) >= s.max_f) p.f[3 * c] = p.f[3 * c + 1] = p.f[3 * c + 2] = 0.0;
            break;
        }
    }
    result.sweeps = result.converged ? it + 1 : it;
    result.iterations = result.sweeps;
    result.error = error;
    return result;
}

// ---- UncoupledConstraintCorrection -------------------------------------------------------------
//
// A state's constraint Jacobian, rows in ascending order, each a run of (dof, derivative)
// entries with ascending dofs (SOFA's MatrixDeriv): row r's entries are entries[start[r] ..
// start[r + 1]), its constraint index row_index[r]; values hold DT::deriv numbers per entry.
struct JacobianRows {
    Index rows = 0;
    const Index* row_index = nullptr;
    const Index* start = nullptr;  // rows + 1
    const Index* dof = nullptr;
    const double* values = nullptr;
};

// W's entries written this step. W is stored dense (n x n, row-major: the resolutions read its
// diagonal blocks in place), but with UncoupledConstraintCorrection two rows couple only when they
// share a DOF, so most of W stays zero: the corrections write through add(), which notes each entry
// it makes non-zero; start() clears only the entries the last step wrote (and the diagonal, where
// the regularization goes); finish() hands the built solvers each row's written columns,
// ascending, the diagonal included, for add_rows_product. Once more than a quarter of W is written
// (LinearSolverConstraintCorrection: A^-1 couples all of its state's rows) nothing more is noted:
// the solvers read W whole and the next start() clears it whole, as before.
// Memory: the lists reserved for `capacity` rows at reset() (a quarter of W's size for the entries
// noted), and again when a step has more rows: a step with no more rows allocates nothing.
class CompliancePattern {
public:
    // The instance's init: W's values unknown (each start() clears the rows no step had before:
    // all of them at the first); the lists reserved.
    void reset(Index capacity) {
        cleared_ = 0;
        stride_ = 0;
        written_.clear();
        whole_ = false;
        rows_ = 0;
        reserve(capacity);
    }

    // A step of n rows begins: W zeroed over them, as GenericConstraintProblem::clear does, by
    // zeroing what the last step wrote (W's first cleared_ rows hold nothing else) and, when the
    // rows outgrow every earlier step's, the entries beyond.
    void start(double* W, Index n) {
        if (n > capacity_) reserve(std::max(n, 2 * capacity_));
        if (whole_) {
            std::fill_n(W, stride_ * stride_, 0.0);
        } else {
            for (const Entry& e : written_) W[stride_ * e.row + e.column] = 0.0;
            for (Index i = 0; i < stride_; ++i) W[stride_ * i + i] = 0.0;
        }
        if (n > cleared_) {
            std::fill(W + cleared_ * cleared_, W + n * n, 0.0);
            cleared_ = n;
        }
        written_.clear();
        whole_ = false;
        stride_ = n;
        limit_ = std::max<Index>(n * n / 4 - n, 0);
        rows_ = 0;
    }

    // W(row, column) += value.
    void add(double* W, Index row, Index column, double value) {
        double& entry = W[stride_ * row + column];
        if (entry == 0.0 && !whole_) {
            if (Index(written_.size()) < limit_)
                written_.push_back(Entry{row, column});
            else
                whole_ = true;
        }
        entry += value;
    }

    // After the corrections: each row's written columns, for the solvers (none when W is read whole).
    void finish() {
        const Index n = stride_;
        rows_ = 0;
        if (n == 0 || whole_) return;
        start_.assign(static_cast<std::size_t>(n + 1), 0);
        for (Index i = 0; i < n; ++i) start_[i + 1] = 1;  // the diagonal
        for (const Entry& e : written_) ++start_[e.row + 1];
        for (Index i = 0; i < n; ++i) start_[i + 1] += start_[i];
        columns_.resize(static_cast<std::size_t>(start_[n]));
        for (Index i = 0; i < n; ++i) columns_[start_[i]++] = i;  // start_[i] as row i's cursor
        for (const Entry& e : written_) columns_[start_[e.row]++] = e.column;
        for (Index i = n; i > 0; --i) start_[i] = start_[i - 1];  // the cursors back to the starts
        start_[0] = 0;
        Index kept = 0;  // each row sorted, repeats dropped (an entry zeroed then written again)
        for (Index i = 0; i < n; ++i) {
            const Index begin = start_[i], end = start_[i + 1];
            start_[i] = kept;
            std::sort(columns_.begin() + begin, columns_.begin() + end);
            for (Index e = begin; e < end; ++e)
                if (kept == start_[i] || columns_[kept - 1] != columns_[e]) columns_[kept++] = columns_[e];
        }
        start_[n] = kept;
        rows_ = n;
    }

    // The built solvers' view of W (finish()): sparse rows or, when W is read whole, none.
    void view(ConstraintProblem& p) const {
        p.row_start = rows_ > 0 ? start_.data() : nullptr;
        p.columns = rows_ > 0 ? columns_.data() : nullptr;
    }

    // A correction's rows by DOF (its J, DOFs below `dofs`), for rows_sharing().
    void index_rows(const JacobianRows& J, Index dofs) {
        const Index entries = J.rows > 0 ? J.start[J.rows] : 0;
        grow(by_dof_start_, dofs + 1);
        grow(by_dof_, entries);
        grow(mark_, J.rows);
        grow(sharing_, J.rows);
        std::fill_n(by_dof_start_.begin(), dofs + 1, 0);
        for (Index e = 0; e < entries; ++e) ++by_dof_start_[J.dof[e] + 1];
        for (Index g = 0; g < dofs; ++g) by_dof_start_[g + 1] += by_dof_start_[g];
        for (Index r = 0; r < J.rows; ++r)  // rows ascending within each DOF
            for (Index e = J.start[r]; e < J.start[r + 1]; ++e) by_dof_[by_dof_start_[J.dof[e]]++] = r;
        for (Index g = dofs; g > 0; --g) by_dof_start_[g] = by_dof_start_[g - 1];
        by_dof_start_[0] = 0;
        std::fill_n(mark_.begin(), J.rows, Index(-1));
    }

    // The rows after row r of the indexed J that share a DOF with it, ascending: `count` of them at
    // the returned pointer.
    const Index* rows_sharing(const JacobianRows& J, Index r, Index& count) {
        count = 0;
        for (Index e = J.start[r]; e < J.start[r + 1]; ++e) {
            const Index dof = J.dof[e];
            for (Index k = by_dof_start_[dof]; k < by_dof_start_[dof + 1]; ++k) {
                const Index s = by_dof_[k];
                if (s <= r || mark_[s] == r) continue;
                mark_[s] = r;
                sharing_[count++] = s;
            }
        }
        std::sort(sharing_.begin(), sharing_.begin() + count);
        return sharing_.data();
    }

private:
    struct Entry {
        Index row, column;
    };
    static void grow(std::vector<Index>& v, Index size) {
        if (Index(v.size()) < size) v.resize(static_cast<std::size_t>(size));
    }
    // Lists for `rows` rows: W's entries noted, at most a quarter of them (limit_); J's entries, up
    // to 8 DOFs a row on each of a contact's two sides.
    void reserve(Index rows) {
        capacity_ = rows;
        const auto n = static_cast<std::size_t>(rows);
        written_.reserve(std::max<std::size_t>(n * n / 4, n) - n);
        start_.reserve(n + 1);
        columns_.reserve(std::max<std::size_t>(n * n / 4, n));
        by_dof_.reserve(16 * n);
        mark_.reserve(2 * n);
        sharing_.reserve(2 * n);
    }

    std::vector<Entry> written_;
    std::vector<Index> start_, columns_;  // finish(): the rows' columns
    std::vector<Index> by_dof_start_, by_dof_, mark_, sharing_;  // index_rows(), rows_sharing()
    Index capacity_ = 0, cleared_ = 0, stride_ = 0, limit_ = 0, rows_ = 0;
    bool whole_ = false;  // more than limit_ entries written: W read and cleared whole
};

// c(n1, n2) of one DOF: (n1 . n2) comp (Vec, comp[dof] or the default) or SOFA's rigid formula on
// the 7 compliance numbers (translation comp[0], rotation the symmetric 3x3 comp[1..6]).
template <class DT>
inline double uncoupled_pair(Index dof, const double* n1, const double* n2, double comp0, const double* comp,
                             Index comp_size) {
    if constexpr (DT::rigid && DT::deriv == 6) {
        (void)dof, (void)comp0, (void)comp_size;
        double w = (n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]) * comp[0];
        const double* a = n1 + 3;
        const double* b = n2 + 3;
        w += (a[0] * comp[1] + a[1] * comp[2] + a[2] * comp[3]) * b[0];
        w += (a[0] * comp[2] + a[1] * comp[4] + a[2] * comp[5]) * b[1];
        w += (a[0] * comp[3] + a[1] * comp[5] + a[2] * comp[6]) * b[2];
        return w;
    } else {
        double product = 0.0;
        for (int c = 0; c < DT::deriv; ++c) product += n1[c] * n2[c];
        return product * (dof < comp_size ? comp[dof] : comp0);
    }
}

// UncoupledConstraintCorrection::addComplianceInConstraintSpace: W += factor-scaled J C J^T
// (comp and comp0 multiplied by `factor` first, as SOFA does) on a state of `dofs` DOFs. SOFA tries
// every pair of rows (r, s > r) and writes the non-zero sums over their common DOFs; only the
// pairs that share a DOF can have one, so those alone are tried, in the same order.
template <class DT>
inline void uncoupled_add_compliance(CompliancePattern& P, double* W, const JacobianRows& J, Index dofs, double comp0,
                                     const double* comp, Index comp_size, double factor, double* scaled_comp) {
    comp0 *= factor;
    for (Index i = 0; i < comp_size; ++i) scaled_comp[i] = comp[i] * factor;
    P.index_rows(J, dofs);
    for (Index r = 0; r < J.rows; ++r) {
        if (J.start[r] == J.start[r + 1]) continue;
        const Index row = J.row_index[r];
        double w = 0.0;
        for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
            w += uncoupled_pair<DT>(J.dof[e], J.values + DT::deriv * e, J.values + DT::deriv * e, comp0, scaled_comp,
                                    comp_size);
        P.add(W, row, row, w);
        Index count = 0;
        const Index* sharing = P.rows_sharing(J, r, count);
        for (Index k = 0; k < count; ++k) {
            const Index s = sharing[k];
            const Index column = J.row_index[s];
            double v = 0.0;
            Index a = J.start[r], b = J.start[s];
            while (a < J.start[r + 1] && b < J.start[s + 1]) {
                if (J.dof[a] < J.dof[b]) {
                    ++a;
                } else if (J.dof[b] < J.dof[a]) {
                    ++b;
                } else {
                    v += uncoupled_pair<DT>(J.dof[a], J.values + DT::deriv * a, J.values + DT::deriv * b, comp0,
                                            scaled_comp, comp_size);
                    ++a, ++b;
                }
            }
            if (v != 0.0) {
                P.add(W, row, column, v);
                P.add(W, column, row, v);
            }
        }
    }
}

// lambda += J^T f over the state's rows (MapMapSparseMatrix::multTransposeBaseVector).
template <class DT>
inline void add_jacobian_transpose(double* lambda, const JacobianRows& J, const double* f) {
    for (Index r = 0; r < J.rows; ++r) {
        const double force = f[J.row_index[r]];
        for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
            for (int c = 0; c < DT::deriv; ++c) lambda[DT::deriv * J.dof[e] + c] += J.values[DT::deriv * e + c] * force;
    }
}

// computeDx: dx = C lambda per DOF (Vec: comp[dof] or comp0; rigid: comp[0] and the 3x3 block).
template <class DT>
inline void uncoupled_dx(double* dx, const double* lambda, Index dofs, double comp0, const double* comp,
                         Index comp_size) {
    for (Index i = 0; i < dofs; ++i) {
        const double* f = lambda + DT::deriv * i;
        double* out = dx + DT::deriv * i;
        if constexpr (DT::rigid && DT::deriv == 6) {
            for (int c = 0; c < 3; ++c) out[c] = f[c] * comp[0];
            out[3] = f[3] * comp[1] + f[4] * comp[2] + f[5] * comp[3];
            out[4] = f[3] * comp[2] + f[4] * comp[4] + f[5] * comp[5];
            out[5] = f[3] * comp[3] + f[4] * comp[5] + f[5] * comp[6];
        } else {
            const double c = i < comp_size ? comp[i] : comp0;
            for (int k = 0; k < DT::deriv; ++k) out[k] = f[k] * c;
        }
    }
}

// applyMotionCorrection: x = x_free + position_factor dx, v = v_free + velocity_factor dx, and
// dx scaled by position_factor (rigid frames: SOFA's RigidCoord += Deriv).
template <class DT>
inline void apply_motion_correction(double* x, const double* x_free, double* v, const double* v_free, double* dx,
                                    Index dofs, double position_factor, double velocity_factor) {
    for (Index i = 0; i < dofs; ++i) {
        double* step = dx + DT::deriv * i;
        double scaled[DT::deriv];
        for (int c = 0; c < DT::deriv; ++c) scaled[c] = step[c] * position_factor;
        if constexpr (DT::rigid && DT::coord == 7) {
            const Vec3 turn_vector(scaled[3], scaled[4], scaled[5]);
            for (int c = 0; c < 3; ++c) x[7 * i + c] = x_free[7 * i + c] + scaled[c];
            const Quat turn = quat_from_rotation_vector(turn_vector);
            orientation(x, i) = turn * orientation(x_free, i);
        } else {
            for (int c = 0; c < DT::coord; ++c) x[DT::coord * i + c] = x_free[DT::coord * i + c] + scaled[c];
        }
        for (int c = 0; c < DT::deriv; ++c) {
            v[DT::deriv * i + c] = v_free[DT::deriv * i + c] + step[c] * velocity_factor;
            step[c] = scaled[c];
        }
    }
}

// ---- the compiled constraint phase (FreeMotionAnimationLoop) ----------------------------------

// GenericConstraintProblem::clear(n): W (what the last step wrote of it), dfree, f and d zeroed.
inline void constraint_clear(CompliancePattern& P, double* W, double* dfree, double* f, double* d, Index n) {
    P.start(W, n);
    for (Index i = 0; i < n; ++i) dfree[i] = f[i] = d[i] = 0.0;
}

// BilateralLagrangianConstraint<Vec3d>::getPositionViolation: rows first + 3 p + k get
// x2_free[m2[p]] - x1_free[m1[p]] (- rest[p] when given).
inline void bilateral_violation(double* dfree, Index first, const double* x1, const double* x2, const Index* m1,
                                const Index* m2, Index pairs, const double* rest, Index rest_count) {
    for (Index p = 0; p < pairs; ++p)
        for (int k = 0; k < 3; ++k) {
            double value = x2[3 * m2[p] + k] - x1[3 * m1[p] + k];
            if (p < rest_count) value -= rest[3 * p + k];
            dfree[first + 3 * p + k] = value;
        }
}

// FixedLagrangianConstraint<Rigid3d>::getConstraintViolation: six rows first + 6 p + k per fixed
// frame dofs[p]: its centre's move from the rest position, then the Euler vector of
// q_free * q_rest.inverse() (doGetSingleConstraintViolation).
inline void rigid_fixed_violation(double* dfree, Index first, const double* x, const double* rest, const Index* dofs,
                                  Index count) {
    for (Index p = 0; p < count; ++p) {
        const double* free = x + 7 * dofs[p];
        const double* home = rest + 7 * dofs[p];
        double* out = dfree + first + 6 * p;
        for (int k = 0; k < 3; ++k) out[k] = free[k] - home[k];
        (SofaQuat::load(free + 3) * SofaQuat::load(home + 3).inverse()).to_euler_vector(out + 3);
    }
}

// UniformLagrangianConstraint::getConstraintViolation (position order): rows first + i get
// x_free[i] - rest[i] (rest: constrainToRestPos) or x_free[i], over every coordinate.
inline void coordinate_violation(double* dfree, Index first, const double* x, const double* rest, Index count) {
    for (Index i = 0; i < count; ++i) dfree[first + i] = rest ? x[i] - rest[i] : x[i];
}

// SlidingLagrangianConstraint<Vec3d>::buildConstraintMatrix and getConstraintViolation on the free
// positions: point m1 of x1 on the segment a-b of x2. Rows first.. first+3: dirProj, dirOrtho
// (bilateral, on P and on the projection's barycentre of A and B), dirAxe on P - A, -dirAxe on
// P - B (unilateral). values1: one entry a row (P); values2: rows 0, 1 with A and B in ascending
// DOF order, row 2 on A, row 3 on B. A segment of zero length (SOFA then adds three bilateral rows
// on P - A) keeps the last directions and is counted in degenerate[0].
inline void sliding_rows(double* values1, double* values2, double* dfree, Index first, const double* x1,
                         const double* x2, Index m1, Index a, Index b, double* degenerate) {
    const double eps = std::numeric_limits<double>::epsilon();
    const Vec3 P(x1[3 * m1], x1[3 * m1 + 1], x1[3 * m1 + 2]);
    const Vec3 A(x2[3 * a], x2[3 * a + 1], x2[3 * a + 2]);
    const Vec3 B(x2[3 * b], x2[3 * b + 1], x2[3 * b + 2]);
    Vec3 axis = B - A;
    const double ab = axis.norm();
    if (ab < eps) {
        degenerate[0] += 1.0;
    } else {
        axis = axis.normalized();
        const double r = (P - A).dot(axis);
        double bary = r / ab < 0 ? 0 : r / ab;
        bary = bary > 1.0 ? 1.0 : bary;
        const Vec3 projection = A + axis * r;
        Vec3 normal = P - projection;
        if (normal.norm() < eps) {
            Vec3 x_vec(1, 0, 0);
            if (x_vec.cross(axis).norm() < eps) x_vec[1] = 1;
            normal = x_vec.cross(axis);
        }
        normal = normal.normalized();
        const Vec3 ortho = normal.cross(axis).normalized();
        const Vec3 directions[4] = {normal, ortho, axis, -axis};
        for (int row = 0; row < 4; ++row)
            for (int c = 0; c < 3; ++c) values1[3 * row + c] = directions[row][c];
        const bool a_first = a < b;
        for (int row = 0; row < 2; ++row)
            for (int c = 0; c < 3; ++c) {
                const double on_a = -directions[row][c] * (1 - bary), on_b = -directions[row][c] * bary;
                values2[6 * row + c] = a_first ? on_a : on_b;
                values2[6 * row + 3 + c] = a_first ? on_b : on_a;
            }
        for (int c = 0; c < 3; ++c) {
            values2[12 + c] = -axis[c];
            values2[15 + c] = axis[c];
        }
        values1[12] = bary;  // (kept for the violation: the last barycentric coordinate)
    }
    const double bary = values1[12];
    const Vec3 to_projection = P - (B * bary + A * (1 - bary));
    for (int row = 0; row < 2; ++row) {
        const Vec3 direction(values1[3 * row], values1[3 * row + 1], values1[3 * row + 2]);
        dfree[first + row] = to_projection.dot(direction);
    }
    const Vec3 axis_kept(values1[6], values1[7], values1[8]);
    dfree[first + 2] = (P - A).dot(axis_kept);
    dfree[first + 3] = (P - B).dot(-axis_kept);
}

// StopperLagrangianConstraint<Vec1d>::getConstraintViolation: its row gets x_free[index].
inline void stopper_violation(double* dfree, Index row, const double* x, Index index) { dfree[row] = x[index]; }

// The loop's constraint solve, on blocks given as arrays (first row, Resolution, parameters (two a
// block: parameter, upper), offset
// of its kept forces in `previous` or -1); K blocks, on the stack. report: solves, iterations and
// error of the last solve, solves that hit the iteration limit, and the time, error and iterations
// of the last such solve.
template <int K>
inline void solve_constraints(BuiltSolver solver, CompliancePattern& P, double* W, double* dfree, double* f, double* d,
                              double* scratch, Index n, const Index* first, const Index* kind, const double* parameter,
                              const Index* kept, double* previous, double max_iterations, double tolerance, double sor,
                              double scale_tolerance, double all_verified, double regularization, double* report,
                              double time) {
    RowBlock blocks[K];
    for (int k = 0; k < K; ++k) {
        blocks[k].first = first[k];
        blocks[k].kind = Resolution(kind[k]);
        blocks[k].parameter = parameter[2 * k];
        blocks[k].upper = parameter[2 * k + 1];
        blocks[k].previous = kept[k] >= 0 ? previous + kept[k] : nullptr;
    }
    if (regularization > std::numeric_limits<double>::epsilon())
        for (Index i = 0; i < n; ++i) W[n * i + i] += regularization;
    ConstraintProblem p{n, W, dfree, f, d, blocks, K, scratch};
    P.finish();
    P.view(p);
    const ConstraintSettings settings{Index(max_iterations), tolerance, sor, scale_tolerance != 0.0,
                                      all_verified != 0.0};
    record_solve(report, solve_built(solver, p, settings), time);
}

// RigidMapping::applyJT on constraint rows: entry e of the frame's rows gets (n, r x n), n the
// mapped point's direction and r its rotated offset (the mapping's last apply).
inline void rigid_constraint_jacobian(double* values, const Index* points, const double* directions,
                                      const double* offsets, Index count) {
    for (Index e = 0; e < count; ++e) {
        const double* n = directions + 3 * e;
        const double* r = offsets + 3 * points[e];
        double* out = values + 6 * e;
        out[0] = n[0], out[1] = n[1], out[2] = n[2];
        out[3] = r[1] * n[2] - r[2] * n[1];
        out[4] = r[2] * n[0] - r[0] * n[2];
        out[5] = r[0] * n[1] - r[1] * n[0];
    }
}

// UncoupledConstraintCorrection on a Vec state after the solve: lambda = J^T f, dx = C lambda,
// x = x_free + position_factor dx, v = v_free + velocity_factor dx (x, v hold the free motion).
template <class DT>
inline void uncoupled_correct(double* x, double* v, double* lambda, double* dx, const JacobianRows& J, const double* f,
                              Index dofs, double comp0, const double* comp, Index comp_size, double position_factor,
                              double velocity_factor) {
    for (Index i = 0; i < DT::deriv * dofs; ++i) lambda[i] = 0.0;
    add_jacobian_transpose<DT>(lambda, J, f);
    uncoupled_dx<DT>(dx, lambda, dofs, comp0, comp, comp_size);
    apply_motion_correction<DT>(x, x, v, v, dx, dofs, position_factor, velocity_factor);
}

// ---- UnbuiltGaussSeidel with uncoupled corrections ---------------------------------------------

// SOFA's Deriv products: Vec: one dot; RigidDeriv: linear dot + angular dot.
template <class DT>
inline double deriv_dot(const double* a, const double* b) {
    if constexpr (DT::rigid && DT::deriv == 6) {
        return (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) + (a[3] * b[3] + a[4] * b[4] + a[5] * b[5]);
    } else {
        double sum = 0.0;
        for (int c = 0; c < DT::deriv; ++c) sum += a[c] * b[c];
        return sum;
    }
}

// UncoupledConstraintCorrection's unbuilt interface: constraint_force and constraint_disp per DOF
// (resetForUnbuiltResolution, addConstraintDisplacement, setConstraintDForce,
// getBlockDiagonalCompliance: the raw compliance, without the ODE factor, as SOFA).
template <class DT>
struct UnbuiltUncoupled {
    JacobianRows J;
    Index dofs;
    double comp0;
    const double* comp;
    Index comp_size;
    double* force;  // dofs x deriv
    double* disp;   // dofs x deriv

    Index row_of(Index id) const {  // the position of constraint `id` among the rows, or -1
        Index low = 0, high = J.rows;
        while (low < high) {
            const Index middle = (low + high) / 2;
            if (J.row_index[middle] < id)
                low = middle + 1;
            else
                high = middle;
        }
        return low < J.rows && J.row_index[low] == id && J.start[low] != J.start[low + 1] ? low : -1;
    }
    void reset() const {
        for (Index i = 0; i < DT::deriv * dofs; ++i) force[i] = disp[i] = 0.0;
    }
    void add_displacement(double* d, Index first, Index last) const {
        for (Index id = first; id <= last; ++id) {
            const Index r = row_of(id);
            if (r < 0) continue;
            for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
                d[id] += deriv_dot<DT>(J.values + DT::deriv * e, disp + DT::deriv * J.dof[e]);
        }
    }
    void set_force_change(const double* df, Index first, Index last) const {
        for (Index id = first; id <= last; ++id) {
            const Index r = row_of(id);
            if (r < 0) continue;
            for (Index e = J.start[r]; e < J.start[r + 1]; ++e) {
                const Index dof = J.dof[e];
                for (int c = 0; c < DT::deriv; ++c) force[DT::deriv * dof + c] += J.values[DT::deriv * e + c] * df[id];
                uncoupled_dx<DT>(disp + DT::deriv * dof, force + DT::deriv * dof, 1, dof < comp_size ? comp[dof] : comp0,
                                 comp, DT::rigid ? comp_size : 0);
            }
        }
    }
    void block_compliance(CompliancePattern& P, double* W, Index first, Index last) const {
        for (Index id1 = first; id1 <= last; ++id1) {
            const Index r = row_of(id1);
            if (r < 0) continue;
            double w = 0.0;
            for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
                w += uncoupled_pair<DT>(J.dof[e], J.values + DT::deriv * e, J.values + DT::deriv * e, comp0, comp,
                                        comp_size);
            P.add(W, id1, id1, w);
            for (Index id2 = id1 + 1; id2 <= last; ++id2) {
                const Index s = row_of(id2);
                if (s < 0) continue;
                double v = 0.0;
                Index a = J.start[r], b = J.start[s];
                while (a < J.start[r + 1] && b < J.start[s + 1]) {
                    if (J.dof[a] < J.dof[b]) {
                        ++a;
                    } else if (J.dof[b] < J.dof[a]) {
                        ++b;
                    } else {
                        v += uncoupled_pair<DT>(J.dof[a], J.values + DT::deriv * a, J.values + DT::deriv * b, comp0,
                                                comp, comp_size);
                        ++a, ++b;
                    }
                }
                if (v != 0.0) {
                    P.add(W, id1, id2, v);
                    P.add(W, id2, id1, v);
                }
            }
        }
    }
};

// The corrections of a UGS solve, in the solver's list order: each block's displacements and force
// changes go to the corrections holding its first row (SOFA's cclist).
template <class DT, int C>
struct UnbuiltSet {
    UnbuiltUncoupled<DT> items[C];
    void add_displacement(double* d, Index first, Index last) const {
        for (const auto& item : items)
            if (item.row_of(first) >= 0) item.add_displacement(d, first, last);
    }
    void set_force_change(const double* df, Index first, Index last) const {
        for (const auto& item : items)
            if (item.row_of(first) >= 0) item.set_force_change(df, first, last);
    }
};

// UnbuiltGaussSeidelConstraintSolver on K blocks with C uncoupled corrections of one DataType:
// W holds only the blocks' diagonal blocks (raw compliance), forces start from zero.
template <class DT, int K, class... Items>
inline void solve_unbuilt(CompliancePattern& P, double* W, double* dfree, double* f, double* d, double* scratch,
                          Index n, const Index* first, const Index* kind, const double* parameter, const Index* kept,
                          double* previous, double max_iterations, double tolerance, double sor,
                          double scale_tolerance, double all_verified, double* report, double time,
                          const Items&... items) {
    UnbuiltSet<DT, int(sizeof...(Items))> set{{items...}};
    RowBlock blocks[K];
    for (int k = 0; k < K; ++k) {
        blocks[k].first = first[k];
        blocks[k].kind = Resolution(kind[k]);
        blocks[k].parameter = parameter[2 * k];
        blocks[k].upper = parameter[2 * k + 1];
        blocks[k].previous = kept[k] >= 0 ? previous + kept[k] : nullptr;
    }
    for (const auto& item : set.items) item.reset();
    for (int k = 0; k < K; ++k) {
        const Index last = first[k] + resolution_lines(blocks[k].kind) - 1;
        for (const auto& item : set.items)
            if (item.row_of(first[k]) >= 0) item.block_compliance(P, W, first[k], last);
    }
    ConstraintProblem p{n, W, dfree, f, d, blocks, K, scratch};
    const ConstraintSettings settings{Index(max_iterations), tolerance, sor, scale_tolerance != 0.0,
                                      all_verified != 0.0};
    const ConstraintResult result = unbuilt_gauss_seidel(p, settings, set);
    record_solve(report, result, time);
}

}  // namespace sofac
