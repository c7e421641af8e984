// The assembled system matrix A = mfact M + kfact K of an implicit step, for the linear solvers
// that work on it: the sparse direct solvers (direct.h, on an Eigen matrix) and CGLinearSolver on
// a CompressedRowSparseMatrix (AssembledCg below, on rows of 3x3 or 1x1 blocks).
//
// Components add their entries through an Assembler. The sparsity never changes, so assembly runs
// once at creation recording where each contribution goes (the pattern), and then, every step,
// only adds values at the recorded slots, in the same order: no allocation, no search.
#pragma once

#include <Eigen/Sparse>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "kernels.h"
#include "solvers.h"
#include "types.h"

namespace sofac {

// A square matrix stored by rows of B x B blocks (B = 1: scalar CSR), as SOFA's
// CompressedRowSparseMatrix: block row I holds the blocks (I, col[k]) for k in [start[I],
// start[I + 1]), columns increasing, each block's values row-major at values[B * B * k].
template <int B>
struct BlockRows {
    Index n = 0;  // scalar rows (a multiple of B)
    std::vector<Index> start, col;
    std::vector<double> values;

    // y = A x; returns x.y, summed in index order (as a FullVector dot product, while the product
    // runs). Each scalar row is summed over increasing scalar columns, one product at a time, from
    // 0: SOFA's CompressedRowSparseMatrix product (tmul), whose numbers are then the same for every
    // block size (and for its FullMatrix and SparseMatrix, whose extra terms are exact zeros).
    double multiply(const double* x, double* y) const {
        const Index rows = n / B;
        double dot = 0.0;
        for (Index I = 0; I < rows; ++I) {
            double sum[B] = {};
            for (Index k = start[I]; k < start[I + 1]; ++k) {
                const double* m = values.data() + B * B * k;
                const double* xj = x + B * col[k];
                SOFAC_UNROLL
                for (int i = 0; i < B; ++i)
                    SOFAC_UNROLL
                    for (int j = 0; j < B; ++j) sum[i] += m[B * i + j] * xj[j];
            }
            for (int i = 0; i < B; ++i) {
                y[B * I + i] = sum[i];
                dot += x[B * I + i] * sum[i];
            }
        }
        return dot;
    }
};

class Assembler {
public:
    // Mapped states' scalar DOFs are numbered from kMapped on. Each is a row of the mapping's
    // Jacobian J, over independent or (chained mappings) other mapped indices, so an entry on
    // such a row or column lands, weighted, on the rows and columns J maps it to: what a mapped
    // state's K or M contributes is J^T K J (SOFA's MatrixLinearSystem does the same).
    static constexpr Index kMapped = Index(1) << 40;

    // The block size of the matrix it fills: with 3 (BlockRows<3>), add_block3 finds a whole 3x3
    // block with one slot. Set before start_pattern.
    int block = 1;

    // Record (first pass) or add (later passes) one entry of A.
    void add(Index row, Index col, double value) {
        expand(row, col, value, [this](Index r, Index c, double v) {
            if (recording_) {
                rows_.push_back(r);
                cols_.push_back(c);
                whole_.push_back(0);
            } else {
                values_[slots_[cursor_++]] += v;
            }
        });
    }

    // The entries of the independent DOFs that one entry (row, col) becomes through the mappings'
    // current Jacobians: `sink(row, col, value)` for each, in the order add() visits them.
    template <class Sink>
    void expand(Index row, Index col, double value, Sink&& sink) const {
        if (row >= kMapped) {
            const auto r = static_cast<std::size_t>(row - kMapped);
            for (Index k = jstart_[r]; k < jstart_[r + 1]; ++k) expand(jcols_[k], col, jweights_[k] * value, sink);
        } else if (col >= kMapped) {
            const auto c = static_cast<std::size_t>(col - kMapped);
            for (Index k = jstart_[c]; k < jstart_[c + 1]; ++k) expand(row, jcols_[k], value * jweights_[k], sink);
        } else {
            sink(row, col, value);
        }
    }

    // A block of a derivative pair: rows of DOF a (width wa) against columns of DOF b.
    template <class Block>
    void add_block(Index row0, Index col0, const Block& block, double factor) {
        for (int i = 0; i < block.rows(); ++i)
            for (int j = 0; j < block.cols(); ++j) add(row0 + i, col0 + j, factor * block(i, j));
    }

    // factor times the 3x3 block m (rows `stride` apart) at (row0, col0), both multiples of 3 on a
    // 3x3-block matrix. Each entry receives the same number as from add, in the same order.
    void add_block3(Index row0, Index col0, const double* m, Index stride, double factor) {
        if (block != 3 || row0 >= kMapped || col0 >= kMapped) {
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) add(row0 + i, col0 + j, factor * m[stride * i + j]);
            return;
        }
        if (recording_) {
            rows_.push_back(row0);
            cols_.push_back(col0);
            whole_.push_back(1);
            return;
        }
        double* values = values_ + slots_[cursor_++];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) values[3 * i + j] += factor * m[stride * i + j];
    }

    // Row kMapped + r of J: its columns (the first pass appends the rows in order) and weights
    // (refilled in place on later passes: the mapping's current values).
    void jacobian_row(Index row, int count, const Index* columns, const double* weights) {
        if (recording_) {
            jcols_.insert(jcols_.end(), columns, columns + count);
            jweights_.insert(jweights_.end(), weights, weights + count);
            jstart_.push_back(static_cast<Index>(jcols_.size()));
        } else {
            std::copy_n(weights, count, jweights_.data() + jstart_[static_cast<std::size_t>(row - kMapped)]);
        }
    }

    bool recording() const { return recording_; }

    void start_pattern() {
        recording_ = true;
        rows_.clear();
        cols_.clear();
        whole_.clear();
        jstart_.assign(1, 0);
        jcols_.clear();
        jweights_.clear();
    }

    // Build the pattern of an n x n matrix from the recorded entries (plus the whole diagonal),
    // without the off-diagonal entries in a row or column of a `fixed` DOF: those contributions
    // go to that DOF's diagonal, which the projection overwrites (so a direct solver orders and
    // factors the free DOFs' graph).
    void finish_pattern(Eigen::SparseMatrix<double>& matrix, Index n, const std::vector<char>& fixed) {
        const auto target = [&](std::size_t k, Index& row, Index& col) {
            row = rows_[k];
            col = cols_[k];
            if (fixed[static_cast<std::size_t>(row)]) col = row;
            else if (fixed[static_cast<std::size_t>(col)]) row = col;
        };
        std::vector<Eigen::Triplet<double>> triplets;
        triplets.reserve(rows_.size() + static_cast<std::size_t>(n));
        Index row = 0, col = 0;
        for (std::size_t k = 0; k < rows_.size(); ++k) {
            target(k, row, col);
            if (row != col) triplets.emplace_back(row, col, 0.0);
        }
        for (Index i = 0; i < n; ++i) triplets.emplace_back(i, i, 0.0);
        matrix.resize(n, n);
        matrix.setFromTriplets(triplets.begin(), triplets.end());
        matrix.makeCompressed();
        slots_.resize(rows_.size());
        for (std::size_t k = 0; k < rows_.size(); ++k) {
            target(k, row, col);
            slots_[k] = static_cast<Index>(&matrix.coeffRef(row, col) - matrix.valuePtr());
        }
        recording_ = false;
    }

    // The same with no projected DOF: every recorded entry in the pattern.
    void finish_pattern(Eigen::SparseMatrix<double>& matrix, Index n) {
        finish_pattern(matrix, n, std::vector<char>(static_cast<std::size_t>(n), 0));
    }

    // The same for block rows (B must be `block`): the blocks touched, plus the diagonal ones.
    template <int B>
    void finish_pattern(BlockRows<B>& matrix, Index n) {
        const Index blocks = n / B;
        std::vector<Index> keys;  // I * blocks + J, sorted: row-major block order
        keys.reserve(rows_.size() + static_cast<std::size_t>(blocks));
        for (std::size_t k = 0; k < rows_.size(); ++k) keys.push_back(rows_[k] / B * blocks + cols_[k] / B);
        for (Index I = 0; I < blocks; ++I) keys.push_back(I * blocks + I);
        std::sort(keys.begin(), keys.end());
        keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
        matrix.n = n;
        matrix.start.assign(static_cast<std::size_t>(blocks) + 1, 0);
        matrix.col.resize(keys.size());
        for (std::size_t k = 0; k < keys.size(); ++k) {
            ++matrix.start[keys[k] / blocks + 1];
            matrix.col[k] = keys[k] % blocks;
        }
        for (Index I = 0; I < blocks; ++I) matrix.start[I + 1] += matrix.start[I];
        matrix.values.assign(static_cast<std::size_t>(B * B) * keys.size(), 0.0);
        slots_.resize(rows_.size());
        for (std::size_t k = 0; k < rows_.size(); ++k) {
            const Index I = rows_[k] / B, J = cols_[k] / B;
            const auto first = matrix.col.begin() + matrix.start[I], last = matrix.col.begin() + matrix.start[I + 1];
            const Index position = std::lower_bound(first, last, J) - matrix.col.begin();
            const Index within = whole_[k] ? 0 : B * (rows_[k] % B) + cols_[k] % B;
            slots_[k] = B * B * position + within;
        }
        recording_ = false;
    }

    void start_values(Eigen::SparseMatrix<double>& matrix) { start_values(matrix.valuePtr(), matrix.nonZeros()); }

    template <int B>
    void start_values(BlockRows<B>& matrix) {
        start_values(matrix.values.data(), static_cast<Index>(matrix.values.size()));
    }

private:
    void start_values(double* values, Index count) {
        values_ = values;
        std::fill(values_, values_ + count, 0.0);
        cursor_ = 0;
    }

    bool recording_ = false;
    std::vector<Index> rows_, cols_, slots_;
    std::vector<char> whole_;  // per recorded entry: a whole 3x3 block (add_block3 on 3x3 blocks)
    std::vector<Index> jstart_{0}, jcols_;  // J of the mapped DOFs, by rows (CSR)
    std::vector<double> jweights_;
    double* values_ = nullptr;
    std::size_t cursor_ = 0;
};

// SOFA's CGLinearSolver on an assembled matrix (its CompressedRowSparseMatrix*, SparseMatrix and
// FullMatrix templates): A = mfact M + kfact K assembled, projected as SOFA's MatrixLinearSystem
// does (rows and columns of constrained DOFs cleared, diagonal 1), then CG on the global vectors
// with the arithmetic of SOFA's FullVector (dot products summed in one sequence) and
// CGLinearSolver's rules (sofac::conjugate_gradient). Sized at creation: a solve allocates nothing.
template <int B>
struct AssembledCg {
    BlockRows<B> matrix;
    Assembler assembler;
    std::vector<char> fixed;  // per scalar DOF: projected out
    std::vector<double> rhs, solution;

    void resize(Index n) {
        assembler.block = B;
        fixed.assign(static_cast<std::size_t>(n), 0);
        for (auto* v : {&rhs, &solution, &r_, &p_, &q_}) v->assign(static_cast<std::size_t>(n), 0.0);
    }

    // Once, after the pattern and the marks: the value slots the projection writes.
    void find_projected() {
        cleared_.clear();
        unit_.clear();
        for (Index I = 0; I < matrix.n / B; ++I)
            for (Index k = matrix.start[I]; k < matrix.start[I + 1]; ++k)
                for (int i = 0; i < B; ++i)
                    for (int j = 0; j < B; ++j) {
                        const Index row = B * I + i, col = B * matrix.col[k] + j, slot = B * B * k + B * i + j;
                        if (row == col && fixed[row]) unit_.push_back(slot);
                        else if (fixed[row] || fixed[col]) cleared_.push_back(slot);
                    }
    }

    void project() {
        for (Index slot : cleared_) matrix.values[slot] = 0.0;
        for (Index slot : unit_) matrix.values[slot] = 1.0;
    }

    // Solves A solution = rhs: sofac::conjugate_gradient on the global vector (one state of n
    // scalars: dot products summed in one sequence, as SOFA's FullVector), the product fused with p.q.
    void solve(std::int64_t max_iterations, double tolerance, double threshold, bool first_solve) {
        const StateSpace<Vec1d> space({matrix.n});
        std::copy(rhs.begin(), rhs.end(), r_.begin());
        const StateSpace<Vec1d>::Vector x{solution.data()}, r{r_.data()}, p{p_.data()}, q{q_.data()};
        conjugate_gradient(space, {max_iterations, tolerance, threshold, first_solve}, x, r, p, q,
                           [&] { return matrix.multiply(p_.data(), q_.data()); });
    }

private:
    std::vector<double> r_, p_, q_;
    std::vector<Index> cleared_, unit_;  // value slots set to 0 and 1 by the projection
};

// ---- contributions --------------------------------------------------------------------------

// Mass blocks (uniform / diagonal / rigid, as mass_multiply), times mfact.
template <class DT>
inline void assemble_mass(Assembler& A, Index offset, Index n, const double* mass, Index mass_stride, double mfact) {
    for (Index i = 0; i < n; ++i) {
        const double* mi = mass + i * mass_stride;
        const Index row = offset + DT::deriv * i;
        if constexpr (DT::rigid && DT::coord == 7) {
            for (int d = 0; d < 3; ++d) A.add(row + d, row + d, mfact * mi[0]);
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c) A.add(row + 3 + r, row + 3 + c, mfact * mi[1 + 3 * r + c]);
        } else if constexpr (DT::rigid) {
            A.add(row, row, mfact * mi[0]);
            A.add(row + 1, row + 1, mfact * mi[0]);
            A.add(row + 2, row + 2, mfact * mi[1]);
        } else {
            for (int d = 0; d < DT::deriv; ++d) A.add(row + d, row + d, mfact * mi[0]);
        }
    }
}

// Springs: kfact times the blocks of spring_dforces (df_a += m (dx_b - dx_a), df_b -= the same).
template <class D1, class D2>
inline void assemble_springs(Assembler& A, const Springs& s, const double* jacobians, Index offset1, Index offset2,
                             double kfact) {
    constexpr int S = D1::spatial;
    using Block = Eigen::Matrix<double, S, S, Eigen::RowMajor>;
    for (Index k = 0; k < s.count; ++k) {
        double values[S * S];
        spring_block<S>(jacobians, k, values);
        const Eigen::Map<const Block> m(values);
        const Index a = offset1 + D1::deriv * s.a[k], b = offset2 + D2::deriv * s.b[k];
        A.add_block(a, a, m, -kfact);
        A.add_block(a, b, m, kfact);
        A.add_block(b, a, m, kfact);
        A.add_block(b, b, m, -kfact);
    }
}

// VectorSpringForceField: K = ks [[-I, I], [I, -I]] per spring, A += kfact K.
inline void assemble_vector_springs(Assembler& A, const VectorSprings& s, Index offset1, Index offset2,
                                    double kfact) {
    const double value = kfact * s.stiffness[0];
    for (Index k = 0; k < s.count; ++k)
        for (int c = 0; c < 3; ++c) {
            const Index a = offset1 + 3 * s.a[k] + c, b = offset2 + 3 * s.b[k] + c;
            A.add(a, a, -value);
            A.add(a, b, value);
            A.add(b, a, value);
            A.add(b, b, -value);
        }
}

// Elements (FEM): `matrix(element_data, e, method, out)` gives the positive stiffness of element e
// (corners x corners blocks of 3x3, row-major); the force Jacobian is its negative.
// With Block > 1, `matrix(element_data, first, method, out)` gives the matrices of elements first ..
// first + Block - 1 at once, one after the other (tetrahedra: one vector lane per element); they
// are added element after element all the same.
template <int Corners, int Block = 1, class ElementMatrix>
inline void assemble_elements(Assembler& A, const Index* elements, Index count, const double* element_data,
                              int method, Index offset, double kfact, ElementMatrix matrix) {
    constexpr int N = 3 * Corners;
    double out[Block * N * N];
    for (Index first = 0; first < count; first += Block) {
        matrix(element_data, first, method, out);
        for (Index e = first; e < std::min<Index>(first + Block, count); ++e) {
            const double* m = out + (e - first) * N * N;
            const Index* nodes = elements + Corners * e;
            for (int a = 0; a < Corners; ++a)
                for (int b = 0; b < Corners; ++b)
                    A.add_block3(offset + 3 * nodes[a], offset + 3 * nodes[b], m + 3 * a * N + 3 * b, N, -kfact);
        }
    }
}

// RestShapeSpringsForceField: K = -k I on the listed points.
template <class DT>
inline void assemble_rest_shape(Assembler& A, Index offset, const Index* indices, const double* stiffness,
                                Index stiffness_count, Index count, double kfact) {
    for (Index k = 0; k < count; ++k) {
        const double ks = stiffness[k < stiffness_count ? k : 0];
        for (int d = 0; d < DT::spatial; ++d) {
            const Index row = offset + DT::deriv * indices[k] + d;
            A.add(row, row, -kfact * ks);
        }
    }
}

// MeshMatrixMass (consistent: vertex diagonal and edge off-diagonal terms; lumped: diagonal).
inline void assemble_mesh_matrix_mass(Assembler& A, Index offset, const double* vertex_mass, Index n,
                                      const Index* edges, const double* edge_mass, Index n_edges, double lumping,
                                      double mfact, int width) {
    for (Index i = 0; i < n; ++i)
        for (int d = 0; d < width; ++d) A.add(offset + width * i + d, offset + width * i + d, mfact * vertex_mass[i] * lumping);
    for (Index e = 0; e < n_edges; ++e)
        for (int d = 0; d < width; ++d) {
            const Index a = offset + width * edges[2 * e] + d, b = offset + width * edges[2 * e + 1] + d;
            A.add(a, b, mfact * edge_mass[e]);
            A.add(b, a, mfact * edge_mass[e]);
        }
}

// Projective constraints: mark the scalar DOFs whose rows and columns are cleared.
template <class DT>
inline void mark_fixed(std::vector<char>& fixed, Index offset, const Index* indices, Index count,
                       const Index* directions = nullptr) {
    for (Index k = 0; k < count; ++k)
        for (int d = 0; d < DT::deriv; ++d)
            if (!directions || directions[d]) fixed[static_cast<std::size_t>(offset + DT::deriv * indices[k] + d)] = 1;
}

}  // namespace sofac
