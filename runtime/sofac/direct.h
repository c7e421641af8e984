// Sparse direct solves of the implicit system A dv = b, A = mfact M + kfact K (SOFA's
// SparseLDLSolver and friends), with SuiteSparse's CHOLMOD through Eigen.
//
// The matrix is assembled (assembly.h) from the same blocks the matrix-free product uses, on a
// pattern recorded once at creation, then CHOLMOD's symbolic analysis; every step only adds values
// at the recorded slots (no allocation) before the numeric factorisation. The pattern leaves out the
// couplings of the projected DOFs (their rows and columns are cleared by the projection), so the
// ordering and the factor are those of the free DOFs' graph.
#pragma once

#include <Eigen/CholmodSupport>
#include <Eigen/Sparse>
#include <algorithm>
#include <limits>
#include <vector>

#include "assembly.h"
#include "kernels.h"
#include "types.h"

namespace sofac {

// The factorisation a direct solver runs: L D L^T (SOFA's SparseLDLSolver, and the solvers sofac
// solves the same way), CHOLMOD's simplicial kernel; or L L^T (SOFA's Cholesky solvers), with
// CHOLMOD's supernodal kernel (dense blocks through BLAS and LAPACK) when CHOLMOD would choose it
// (flops / nnz(L) >= 40) and the factorisation is big enough, else its simplicial kernel.
enum class Factorization { LDLT, LLT };

// The supernodal kernel's fixed costs per supernode (BLAS calls, an OpenMP team per parallel
// region) make it slower below ~1e8 flops per factorisation (W3's beam at 6x6x20, 8x8x30 and
// 10x10x50 nodes, the reference BLAS: 24% slower at 2.8e7 flops, 8% faster at 2.5e8, 25% at
// 1.9e9); it also allocates (see factor()).
inline constexpr double kSupernodalFlops = 1e8;

// Eigen's CHOLMOD wrapper (settings, symbolic analysis), with access to the factor.
class Cholmod : public Eigen::CholmodDecomposition<Eigen::SparseMatrix<double>> {
public:
    cholmod_factor* factor() const { return m_cholmodFactor; }
};

struct DirectSolver {
    Eigen::SparseMatrix<double> matrix;
    Cholmod factorization;
    Assembler assembler;
    std::vector<char> fixed;  // per scalar DOF: projected out (row and column cleared, diagonal 1)
    Eigen::VectorXd rhs, solution;
    bool ok = true;
    bool factored = false;  // PrecomputedLinearSolver: factorised once, on the first step

    DirectSolver() { factorization.cholmod().print = 0; }  // failures are reported, not printed
    DirectSolver(const DirectSolver&) = delete;
    DirectSolver& operator=(const DirectSolver&) = delete;
    ~DirectSolver() {
        cholmod_free_dense(&x_, &factorization.cholmod());
        cholmod_free_dense(&y_, &factorization.cholmod());
        cholmod_free_dense(&e_, &factorization.cholmod());
        cholmod_free_sparse(&permuted_, &factorization.cholmod());
    }

    void resize(Index n) {
        fixed.assign(static_cast<std::size_t>(n), 0);
        rhs.resize(n);
        solution.resize(n);
    }

    // Once, on the recorded pattern: CHOLMOD's symbolic analysis (ordering, elimination tree, and
    // for L L^T the choice of the supernodal kernel).
    void analyze(Factorization kind) {
        cholmod_common& common = factorization.cholmod();
        if (kind == Factorization::LDLT) {
            factorization.setMode(Eigen::CholmodLDLt);  // simplicial, L D L^T, the factor kept as is
            factorization.analyzePattern(matrix);
            return;
        }
        factorization.setMode(Eigen::CholmodAuto);  // supernodal or simplicial, kept as is
        common.final_ll = 1;                        // simplicial: L L^T as well
        factorization.analyzePattern(matrix);
        const cholmod_factor* L = factorization.factor();
        if (L != nullptr && L->is_super && common.fl < kSupernodalFlops) {
            common.supernodal = CHOLMOD_SIMPLICIAL;
            factorization.analyzePattern(matrix);
        }
    }

    // Projective constraints: rows and columns of constrained DOFs cleared, diagonal 1.
    void project() {
        for (int col = 0; col < matrix.outerSize(); ++col)
            for (Eigen::SparseMatrix<double>::InnerIterator it(matrix, col); it; ++it)
                if (fixed[it.row()] || fixed[it.col()]) it.valueRef() = it.row() == it.col() ? 1.0 : 0.0;
    }

    // After the values are assembled: the projection, then the numeric factorisation. What
    // cholmod_factorize does, step by step, so that the permuted triangle it factors is allocated
    // once and then refilled in place (cholmod_factorize allocates and frees it on every call).
    // Simplicial: S = triu(A(p,p)') of the lower triangle, factored by cholmod_rowfac (no
    // allocation). Supernodal: S = tril(A(p,p)') of the upper triangle (what SOFA's CSparse
    // Cholesky reads, and one transpose instead of cholmod_factorize's two for a lower one),
    // factored by cholmod_super_numeric, which still allocates in every call: its update
    // workspace, and one OpenMP team per parallel region (Debian's CHOLMOD is built with OpenMP;
    // a region whose `if` clause is false still gets a team), ~9 per supernode: 8,700 per step
    // on W3's beam (negligible next to its 1.9 GFlop, but not allocation-free).
    void factor() {
        project();
        cholmod_common& common = factorization.cholmod();
        cholmod_factor* L = factorization.factor();
        if (L == nullptr) {  // no analysis: Eigen's path, which reports the failure
            factorization.factorize(matrix);
            ok = factorization.info() == Eigen::Success;
            return;
        }
        const Eigen::SparseMatrix<double>& values = matrix;
        const bool super = L->is_super;
        cholmod_sparse a = super ? Eigen::viewAsCholmod(values.selfadjointView<Eigen::Upper>())
                                 : Eigen::viewAsCholmod(values.selfadjointView<Eigen::Lower>());
        common.status = CHOLMOD_OK;
        // Kept in `common` after the first call: transposes need 2n, the supernodal kernel 2n + 5 nsuper.
        cholmod_allocate_work(a.nrow, 2 * a.nrow + (super ? 5 * L->nsuper : 0), 0, &common);
        int* perm = L->ordering == CHOLMOD_NATURAL ? nullptr : static_cast<int*>(L->Perm);
        if (permuted_ == nullptr) permuted_ = cholmod_ptranspose(&a, 2, perm, nullptr, 0, &common);
        else cholmod_transpose_sym(&a, 2, perm, permuted_, &common);
        if (permuted_ == nullptr || common.status < CHOLMOD_OK) {
            ok = false;
            return;
        }
        double beta[2] = {0.0, 0.0};
        if (super) {
            cholmod_super_numeric(permuted_, nullptr, beta, L, &common);
        } else {
            L->is_ll = common.final_ll ? 1 : 0;
            cholmod_rowfac(permuted_, nullptr, beta, 0, a.nrow, L, &common);
            if (common.status >= CHOLMOD_OK && !common.final_asis)
                cholmod_change_factor(L->xtype, L->is_ll, 0, common.final_pack, common.final_monotonic, L,
                                      &common);
        }
        ok = common.status >= CHOLMOD_OK && L->minor == L->n;
    }

    // A failed factorisation yields NaN, which the step's divergence guard reports. The same
    // solve as Eigen's (cholmod_solve), through cholmod_solve2 with CHOLMOD's result and workspace
    // vectors kept from one step to the next: no allocation after the first solve.
    void solve() {
        if (!ok) {
            solution.setConstant(std::numeric_limits<double>::quiet_NaN());
            return;
        }
        cholmod_dense b{};
        b.nrow = b.nzmax = b.d = static_cast<std::size_t>(rhs.size());
        b.ncol = 1;
        b.x = rhs.data();
        b.xtype = CHOLMOD_REAL;
        b.dtype = CHOLMOD_DOUBLE;
        // The simplicial solve leaves its workspace Y (4 x n, leading dimension 4) marked as 1 x n,
        // which would make the next call reallocate it: restore the shape it was allocated with.
        // (The supernodal solve's Y, n x 1, keeps its shape.)
        if (y_ && !factorization.factor()->is_super && y_->nzmax >= 4 * y_->ncol) y_->nrow = y_->d = 4;
        if (!cholmod_solve2(CHOLMOD_A, factorization.factor(), &b, nullptr, &x_, nullptr, &y_, &e_,
                            &factorization.cholmod())) {
            solution.setConstant(std::numeric_limits<double>::quiet_NaN());
            return;
        }
        std::copy_n(static_cast<const double*>(x_->x), rhs.size(), solution.data());
    }

private:
    cholmod_dense* x_ = nullptr;  // cholmod_solve2's solution and workspaces, reused
    cholmod_dense* y_ = nullptr;
    cholmod_dense* e_ = nullptr;
    cholmod_sparse* permuted_ = nullptr;  // triu(A(p,p)'), the matrix the numeric factorisation reads
};

// (Block) Jacobi preconditioner of PCGLinearSolver: z = D^-1 r with D the diagonal (block size 1)
// or the 3x3 diagonal blocks (block size 3) of the assembled, projected system matrix.
struct JacobiPreconditioner {
    int block = 1;
    std::vector<double> inverse;  // n values (block 1) or n/3 row-major 3x3 inverses (block 3)

    void update(const Eigen::SparseMatrix<double>& matrix) {
        const Index n = matrix.rows();
        if (block == 1) {
            inverse.resize(static_cast<std::size_t>(n));
            for (Index i = 0; i < n; ++i) inverse[i] = 1.0 / matrix.coeff(i, i);
            return;
        }
        inverse.resize(static_cast<std::size_t>(3 * n));
        for (Index b = 0; b < n / 3; ++b) {
            Mat3 m;
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) m(i, j) = matrix.coeff(3 * b + i, 3 * b + j);
            Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(inverse.data() + 9 * b) = m.inverse();
        }
    }

    void apply(const double* r, double* z, Index n) const {
        if (block == 1) {
            for (Index i = 0; i < n; ++i) z[i] = inverse[i] * r[i];
            return;
        }
        for (Index b = 0; b < n / 3; ++b) {
            const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> m(inverse.data() + 9 * b);
            Eigen::Map<Vec3>(z + 3 * b) = m * Eigen::Map<const Vec3>(r + 3 * b);
        }
    }
};

// SSOR preconditioner of PCGLinearSolver (SOFA's scalar CRS version): with A = D + L + L^T,
// z = (2 - w) ((D/w + L^T)^-1 ... ): a backward sweep over the upper part, then a forward sweep over
// the lower part, each entry taken in increasing column order (A is symmetric: column j = row j).
struct SsorPreconditioner {
    double omega = 1.0;
    std::vector<double> inverse_diagonal;
    const Eigen::SparseMatrix<double>* matrix = nullptr;

    void update(const Eigen::SparseMatrix<double>& a) {
        matrix = &a;
        inverse_diagonal.resize(static_cast<std::size_t>(a.rows()));
        for (Index j = 0; j < a.rows(); ++j) inverse_diagonal[j] = 1.0 / a.coeff(j, j);
    }

    void apply(const double* r, double* z, Index n) const {
        const auto& a = *matrix;
        const double w = omega;
        for (Index j = n - 1; j >= 0; --j) {
            double sum = 0.0;
            for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
                if (it.row() > j) sum += z[it.row()] * it.value();
            z[j] = (r[j] - sum) * w * inverse_diagonal[j];
        }
        for (Index j = 0; j < n; ++j) {
            double sum = 0.0;
            for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it && it.row() < j; ++it)
                sum += z[it.row()] * it.value();
            z[j] -= sum * w * inverse_diagonal[j];
        }
        if (w != 1.0)
            for (Index j = 0; j < n; ++j) z[j] *= 2 - w;
    }
};

}  // namespace sofac
