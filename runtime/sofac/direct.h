// Sparse direct solves of the implicit system A dv = b, A = mfact M + kfact K (SOFA's
// SparseLDLSolver and friends), with SuiteSparse's CHOLMOD through Eigen (ordering, symbolic
// analysis, simplicial factorisations, solves) and sofac's own supernodal L L^T numeric kernel.
//
// The matrix is assembled (assembly.h) from the same blocks the matrix-free product uses, on a
// pattern recorded once at creation, then CHOLMOD's symbolic analysis; every step only adds values
// at the recorded slots (no allocation) before the numeric factorisation. The pattern leaves out the
// couplings of the projected DOFs (their rows and columns are cleared by the projection), so the
// ordering and the factor are those of the free DOFs' graph.
#pragma once

#include <Eigen/CholmodSupport>
#include <Eigen/Dense>
#include <Eigen/Sparse>
#include <algorithm>
#include <cstddef>
#include <limits>
#include <vector>

#include "assembly.h"
#include "kernels.h"
#include "types.h"

namespace sofac {

// The factorisation a direct solver runs: L D L^T (SOFA's SparseLDLSolver, and the solvers sofac
// solves the same way), CHOLMOD's simplicial kernel; or L L^T (SOFA's Cholesky solvers), with a
// supernodal kernel (SupernodalCholesky: dense blocks through BLAS and LAPACK) when CHOLMOD's
// analysis chooses one (flops / nnz(L) >= 40), else CHOLMOD's simplicial kernel. (sofac's
// supernodal kernel has no per-supernode thread teams: unlike CHOLMOD's, it is faster than the
// simplicial one on small factors too, e.g. W3's beam at 6x6x20 nodes, 2.8e7 flops: 6.8 against
// 9.3 ms per step.)
//
// SVD (SOFA's SVDLinearSolver): the matrix copied dense and decomposed by Eigen's JacobiSVD (thin U
// and V, as SOFA's), then x = V S^+ U^T b where S^+ inverts the singular values above
// `min_singular_value` and zeroes the others. Everything is sized once by analyze().
enum class Factorization { LDLT, LLT, SVD };

// The Fortran BLAS and LAPACK routines CHOLMOD's supernodal kernel calls (Debian links CHOLMOD with
// the reference libraries, which allocate nothing). gfortran passes each CHARACTER argument's
// length after the others.
extern "C" {
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha, const double* a,
            const int* lda, const double* beta, double* c, const int* ldc, std::size_t, std::size_t);
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* b, const int* ldb, const double* beta, double* c,
            const int* ldc, std::size_t, std::size_t);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m, const int* n,
            const double* alpha, const double* a, const int* lda, double* b, const int* ldb, std::size_t,
            std::size_t, std::size_t, std::size_t);
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info, std::size_t);
}

// The numeric L L^T factorisation of A(p,p) over CHOLMOD's supernodal symbolic factor, left-looking
// as cholmod_super_numeric (the same BLAS calls in the same order), written into L->x in CHOLMOD's
// layout so that cholmod_solve2 solves with it. What cholmod_super_numeric allocates in every call
// (its update block C, and with OpenMP a thread team per parallel region) is allocated once here, by
// setup(), together with the slot in L->x of every entry of A: no transpose of A per step.
class SupernodalCholesky {
public:
    bool ready() const { return L_ != nullptr; }

    // Once, on the analysed pattern of `a` (both triangles stored; the upper one is read, as SOFA's
    // CSparse Cholesky does): L->x allocated, the workspaces sized, the slots of A's entries found.
    // False if CHOLMOD cannot allocate L->x or A has an entry outside L's pattern (a changed pattern).
    bool setup(const Eigen::SparseMatrix<double>& a, cholmod_factor* L, cholmod_common& common) {
        if (!a.isCompressed() || L->n != static_cast<std::size_t>(a.rows())) return false;
        // Symbolic -> numeric supernodal L L^T: allocates L->x, as cholmod_super_numeric does.
        if (!cholmod_change_factor(CHOLMOD_REAL, 1, 1, 1, 1, L, &common) || L->x == nullptr) return false;
        const int n = static_cast<int>(L->n), nsuper = static_cast<int>(L->nsuper);
        const int* super = static_cast<const int*>(L->super);
        const int* pi = static_cast<const int*>(L->pi);
        const int* px = static_cast<const int*>(L->px);
        const int* rows = static_cast<const int*>(L->s);
        const int* perm = static_cast<const int*>(L->Perm);
        supernode_of_.resize(static_cast<std::size_t>(n));
        for (int s = 0; s < nsuper; ++s) std::fill(&supernode_of_[super[s]], &supernode_of_[super[s + 1]], s);
        std::vector<int> position(static_cast<std::size_t>(n));  // original index -> permuted
        for (int k = 0; k < n; ++k) position[perm[k]] = k;

        // The upper-triangle entries (r <= c) as (column j, row i >= j) of A(p,p)'s lower triangle,
        // grouped by supernode to place each with the supernode's row map.
        struct Entry {
            int column, row, source;
        };
        std::vector<Entry> entries;
        for (int c = 0; c < a.outerSize(); ++c)
            for (int k = a.outerIndexPtr()[c]; k < a.outerIndexPtr()[c + 1]; ++k) {
                const int r = a.innerIndexPtr()[k];
                if (r > c) continue;
                const int i = position[r], j = position[c];
                entries.push_back({std::min(i, j), std::max(i, j), k});
            }
        std::sort(entries.begin(), entries.end(), [](const Entry& x, const Entry& y) { return x.column < y.column; });
        source_.clear();
        slot_.clear();
        map_.assign(static_cast<std::size_t>(n), -1);
        std::size_t e = 0;
        for (int s = 0; s < nsuper; ++s) {
            const int nsrow = pi[s + 1] - pi[s];
            for (int k = 0; k < nsrow; ++k) map_[rows[pi[s] + k]] = k;
            for (; e < entries.size() && entries[e].column < super[s + 1]; ++e) {
                const int local = map_[entries[e].row];
                if (local < 0 || local >= nsrow || rows[pi[s] + local] != entries[e].row) return false;
                source_.push_back(entries[e].source);
                slot_.push_back(px[s] + (entries[e].column - super[s]) * nsrow + local);
            }
        }
        relative_.resize(static_cast<std::size_t>(n));
        head_.resize(static_cast<std::size_t>(nsuper));
        next_.resize(static_cast<std::size_t>(nsuper));
        first_row_.resize(static_cast<std::size_t>(nsuper));
        update_.resize(L->maxcsize);
        L_ = L;
        return true;
    }

    // The factorisation of the current values of `a`: true if A is positive definite. Else
    // L->minor is the column whose pivot is not positive (CHOLMOD's convention) and L->x is partly
    // computed: the caller must not solve with it.
    bool factor(const Eigen::SparseMatrix<double>& a) {
        cholmod_factor* L = L_;
        const int n = static_cast<int>(L->n), nsuper = static_cast<int>(L->nsuper);
        const int* super = static_cast<const int*>(L->super);
        const int* pi = static_cast<const int*>(L->pi);
        const int* px = static_cast<const int*>(L->px);
        const int* rows = static_cast<const int*>(L->s);
        double* x = static_cast<double*>(L->x);
        double* C = update_.data();
        const double one = 1.0, zero = 0.0;

        // Every supernode starts as A's values (the rest of the block, and the unused triangle
        // above each diagonal block, zero); the descendants' updates are then subtracted.
        std::fill(x, x + L->xsize, 0.0);
        const double* values = a.valuePtr();
        for (std::size_t k = 0; k < slot_.size(); ++k) x[slot_[k]] = values[source_[k]];
        // head_[s]: the supernodes whose next update goes to s, linked by next_; first_row_[d]:
        // the offset in d's rows of the first row that d's next update touches.
        std::fill(head_.begin(), head_.end(), -1);

        for (int s = 0; s < nsuper; ++s) {
            const int k1 = super[s], k2 = super[s + 1], nscol = k2 - k1;
            const int psi = pi[s], nsrow = pi[s + 1] - psi;
            double* block = x + px[s];  // nsrow x nscol, column-major
            for (int k = 0; k < nsrow; ++k) map_[rows[psi + k]] = k;

            for (int d = head_[s], after = 0; d != -1; d = after) {
                const int ndcol = super[d + 1] - super[d];
                const int pdi = pi[d], ndrow = pi[d + 1] - pdi;
                const int pdi1 = pdi + first_row_[d];
                int pdi2 = pdi1;  // d's rows in s's columns: [pdi1, pdi2); the rest below them
                while (pdi2 < pi[d + 1] && rows[pdi2] < k2) ++pdi2;
                const int ndrow1 = pdi2 - pdi1, ndrow2 = pi[d + 1] - pdi1, ndrow3 = ndrow2 - ndrow1;
                const double* l1 = x + px[d] + first_row_[d];  // L(rows pdi1.., columns of d)

                // C = L(rows pdi1.., d) L(rows pdi1..pdi2, d)': lower triangle of the square top,
                // then the rectangle below it.
                dsyrk_("L", "N", &ndrow1, &ndcol, &one, l1, &ndrow, &zero, C, &ndrow2, 1, 1);
                if (ndrow3 > 0)
                    dgemm_("N", "T", &ndrow3, &ndrow1, &ndcol, &one, l1 + ndrow1, &ndrow, l1, &ndrow, &zero,
                           C + ndrow1, &ndrow2, 1, 1);
                // s -= C, each row of C at its row in s.
                for (int i = 0; i < ndrow2; ++i) relative_[i] = map_[rows[pdi1 + i]];
                for (int j = 0; j < ndrow1; ++j) {
                    double* column = block + static_cast<std::ptrdiff_t>(relative_[j]) * nsrow;
                    const double* c = C + static_cast<std::ptrdiff_t>(j) * ndrow2;
                    for (int i = j; i < ndrow2; ++i) column[relative_[i]] -= c[i];
                }

                // d's next update goes to the supernode of its first row below s's columns.
                after = next_[d];
                first_row_[d] = pdi2 - pdi;
                if (first_row_[d] < ndrow) {
                    const int ancestor = supernode_of_[rows[pdi2]];
                    next_[d] = head_[ancestor];
                    head_[ancestor] = d;
                }
            }

            int info = 0;
            dpotrf_("L", &nscol, block, &nsrow, &info, 1);
            if (info != 0) {
                L->minor = static_cast<std::size_t>(k1 + info - 1);
                return false;
            }
            const int below = nsrow - nscol;
            if (below > 0) {
                // L2 = S2 L1^-T, then s's first update goes to its parent.
                dtrsm_("R", "L", "T", "N", &below, &nscol, &one, block, &nsrow, block + nscol, &nsrow, 1, 1, 1, 1);
                first_row_[s] = nscol;
                const int parent = supernode_of_[rows[psi + nscol]];
                next_[s] = head_[parent];
                head_[parent] = s;
            }
        }
        L->minor = static_cast<std::size_t>(n);
        return true;
    }

private:
    cholmod_factor* L_ = nullptr;
    std::vector<int> source_, slot_;  // x[slot_[k]] = A's value source_[k]
    std::vector<int> supernode_of_;   // per column of L
    std::vector<int> map_;            // row of L -> its offset in the current supernode's rows
    std::vector<int> relative_;       // a descendant's rows -> their offsets in the current supernode
    std::vector<int> head_, next_, first_row_;
    std::vector<double> update_;  // C, L->maxcsize doubles
};

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
    double min_singular_value = 1e-6;  // SVD: singular values at or below it are treated as 0
    double condition_number = 0.0;     // SVD: largest / smallest singular value of the last matrix

    DirectSolver() { factorization.cholmod().print = 0; }  // failures are reported, not printed
    DirectSolver(const DirectSolver&) = delete;
    DirectSolver& operator=(const DirectSolver&) = delete;
    ~DirectSolver() {
        cholmod_free_dense(&x_, &factorization.cholmod());
        cholmod_free_dense(&y_, &factorization.cholmod());
        cholmod_free_dense(&e_, &factorization.cholmod());
        cholmod_free_dense(&x_columns_, &factorization.cholmod());
        cholmod_free_dense(&y_columns_, &factorization.cholmod());
        cholmod_free_sparse(&permuted_, &factorization.cholmod());
    }

    void resize(Index n) {
        fixed.assign(static_cast<std::size_t>(n), 0);
        rhs.resize(n);
        solution.resize(n);
    }

    // Once, on the recorded pattern: CHOLMOD's symbolic analysis (ordering, elimination tree, and
    // for L L^T the choice of the supernodal or the simplicial kernel).
    void analyze(Factorization kind) {
        if (kind == Factorization::SVD) {
            const Index n = matrix.rows();
            svd_ = true;
            dense_.setZero(n, n);
            svd_decomposition_ = Eigen::JacobiSVD<Eigen::MatrixXd>(n, n, Eigen::ComputeThinU | Eigen::ComputeThinV);
            projected_rhs_.setZero(n);
            return;
        }
        cholmod_common& common = factorization.cholmod();
        if (kind == Factorization::LDLT) {
            factorization.setMode(Eigen::CholmodLDLt);  // simplicial, L D L^T, the factor kept as is
        } else {
            factorization.setMode(Eigen::CholmodAuto);  // supernodal or simplicial, kept as is
            common.final_ll = 1;                        // simplicial: L L^T as well
        }
        factorization.analyzePattern(matrix);
        const cholmod_factor* L = factorization.factor();
        if (L != nullptr && !L->is_super) {  // solve_columns' right-hand sides and CHOLMOD's X and Y
            const std::size_t n = L->n;
            rhs_columns.setZero(Index(n), kSolveColumns);
            cholmod_ensure_dense(&x_columns_, n, kSolveColumns, n, CHOLMOD_REAL, &common);
            cholmod_ensure_dense(&y_columns_, 4, n, 4, CHOLMOD_REAL, &common);  // (4 columns' room)
        }
    }

    // Projective constraints: rows and columns of constrained DOFs cleared, diagonal 1.
    void project() {
        for (int col = 0; col < matrix.outerSize(); ++col)
            for (Eigen::SparseMatrix<double>::InnerIterator it(matrix, col); it; ++it)
                if (fixed[it.row()] || fixed[it.col()]) it.valueRef() = it.row() == it.col() ? 1.0 : 0.0;
    }

    // After the values are assembled: the projection, then the numeric factorisation.
    // Supernodal: sofac's SupernodalCholesky, which reads A's upper triangle in place (set up on
    // the first call). Simplicial: what cholmod_factorize does, step by step, so that the permuted
    // triangle it factors is allocated once and then refilled in place (cholmod_factorize
    // allocates and frees it on every call): S = triu(A(p,p)') of the lower triangle, factored by
    // cholmod_rowfac (no allocation).
    void factor() {
        project();
        if (svd_) {
            dense_ = matrix;  // same size: no allocation
            svd_decomposition_.compute(dense_);
            const auto& sigma = svd_decomposition_.singularValues();
            condition_number = sigma.size() ? sigma(0) / sigma(sigma.size() - 1) : 0.0;
            ok = true;
            return;
        }
        cholmod_common& common = factorization.cholmod();
        cholmod_factor* L = factorization.factor();
        if (L == nullptr) {  // no analysis: Eigen's path, which reports the failure
            factorization.factorize(matrix);
            ok = factorization.info() == Eigen::Success;
            return;
        }
        if (L->is_super) {
            ok = (supernodal_.ready() || supernodal_.setup(matrix, L, common)) && supernodal_.factor(matrix);
            return;
        }
        const Eigen::SparseMatrix<double>& values = matrix;
        cholmod_sparse a = Eigen::viewAsCholmod(values.selfadjointView<Eigen::Lower>());
        common.status = CHOLMOD_OK;
        cholmod_allocate_work(a.nrow, 2 * a.nrow, 0, &common);  // the transpose's, kept in `common`
        int* perm = L->ordering == CHOLMOD_NATURAL ? nullptr : static_cast<int*>(L->Perm);
        if (permuted_ == nullptr) permuted_ = cholmod_ptranspose(&a, 2, perm, nullptr, 0, &common);
        else cholmod_transpose_sym(&a, 2, perm, permuted_, &common);
        if (permuted_ == nullptr || common.status < CHOLMOD_OK) {
            ok = false;
            return;
        }
        double beta[2] = {0.0, 0.0};
        L->is_ll = common.final_ll ? 1 : 0;
        cholmod_rowfac(permuted_, nullptr, beta, 0, a.nrow, L, &common);
        if (common.status >= CHOLMOD_OK && !common.final_asis)
            cholmod_change_factor(L->xtype, L->is_ll, 0, common.final_pack, common.final_monotonic, L, &common);
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
        if (svd_) {
            // SOFA's order: U^T b, divided by each singular value above the threshold, then V times it.
            const auto& sigma = svd_decomposition_.singularValues();
            projected_rhs_.noalias() = svd_decomposition_.matrixU().transpose() * rhs;
            for (Index i = 0; i < projected_rhs_.size(); ++i)
                projected_rhs_(i) = sigma(i) > min_singular_value ? projected_rhs_(i) / sigma(i) : 0.0;
            solution.noalias() = svd_decomposition_.matrixV() * projected_rhs_;
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

    // kSolveColumns right-hand sides at once, rhs_columns -> column_solution(c), when
    // can_solve_columns() (a simplicial factor, factorised; else solve one column at a time); a
    // failed solve yields NaN, as solve()'s. CHOLMOD's simplicial solve runs up to four columns per
    // pass over L; with three, each column gets the operations of a one-column solve in the same
    // order (its four-column L^T solve rounds differently), so every column's solution is solve()'s
    // bit for bit (tests/test_direct_solver.py), for a third of the passes over L.
    static constexpr int kSolveColumns = 3;
    Eigen::Matrix<double, Eigen::Dynamic, kSolveColumns> rhs_columns;  // sized by analyze()

    bool can_solve_columns() const { return ok && !svd_ && x_columns_ != nullptr && !factorization.factor()->is_super; }

    void solve_columns() {
        y_columns_->nrow = y_columns_->d = 4;  // the shape CHOLMOD allocates Y with (see solve())
        cholmod_dense b{};
        b.nrow = b.d = static_cast<std::size_t>(rhs_columns.rows());
        b.ncol = kSolveColumns;
        b.nzmax = b.nrow * b.ncol;
        b.x = rhs_columns.data();
        b.xtype = CHOLMOD_REAL;
        b.dtype = CHOLMOD_DOUBLE;
        if (!cholmod_solve2(CHOLMOD_A, factorization.factor(), &b, nullptr, &x_columns_, nullptr, &y_columns_,
                            &e_columns_unused_, &factorization.cholmod()))
            std::fill_n(static_cast<double*>(x_columns_->x), x_columns_->nzmax, std::numeric_limits<double>::quiet_NaN());
    }

    const double* column_solution(int column) const {
        return static_cast<const double*>(x_columns_->x) + x_columns_->d * static_cast<std::size_t>(column);
    }

private:
    cholmod_dense* x_columns_ = nullptr;  // solve_columns' solution and workspace, allocated by analyze()
    cholmod_dense* y_columns_ = nullptr;
    cholmod_dense* e_columns_unused_ = nullptr;  // (the supernodal solve's: stays null)
    cholmod_dense* x_ = nullptr;  // cholmod_solve2's solution and workspaces, reused
    cholmod_dense* y_ = nullptr;
    cholmod_dense* e_ = nullptr;
    cholmod_sparse* permuted_ = nullptr;  // triu(A(p,p)'), the matrix the simplicial factorisation reads
    SupernodalCholesky supernodal_;
    bool svd_ = false;  // Factorization::SVD: the dense members below replace CHOLMOD
    Eigen::MatrixXd dense_;
    Eigen::JacobiSVD<Eigen::MatrixXd> svd_decomposition_;
    Eigen::VectorXd projected_rhs_;  // U^T b, then S^+ U^T b
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
