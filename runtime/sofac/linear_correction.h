// LinearSolverConstraintCorrection: the compliance of a state seen through the factorisation its
// ODE solver's linear system holds this step (A = mfact M + bfact B + kfact K, as EulerImplicitSolver
// assembles it), SOFA's LinearSolverConstraintCorrection.inl:
//
//   addComplianceInConstraintSpace:  W += factor J A^-1 J^T (addJMInvJt, factor = the ODE solver's
//                                    position integration factor, dt), then regularizationTerm on the
//                                    diagonal of the state's non-empty rows (addRegularization);
//   computeMotionCorrection:         dx = A^-1 lambda, lambda = J^T f (the same factorisation);
//   applyMotionCorrection:           x = x_free + dt dx, v = v_free + dx, dx = dt dx.
//
// J A^-1 J^T is built one row at a time: A y = J_a^T by the direct solver, then W(a, b) = J_b . y for
// the rows b >= a, mirrored (the lower triangle, as SparseLDLSolver's addJMInvJtLocal fills it).
// DOFs the projective constraints fix have a unit row and column in A: their right-hand side is
// cleared, so they receive no correction. Memory: the solver's own right-hand side and solution
// vectors, nothing allocated per step.
#pragma once

#include <algorithm>
#include <limits>

#include "constraints.h"
#include "direct.h"
#include "lagrangian_contact.h"

namespace sofac {

// J_row^T into a right-hand side of the solver's size (the state's DOFs start at `offset`), fixed
// DOFs cleared.
template <class DT>
inline void linear_scatter_row(double* rhs, const DirectSolver& D, const JacobianRows& J, Index r, Index offset) {
    std::fill_n(rhs, D.rhs.size(), 0.0);
    for (Index e = J.start[r]; e < J.start[r + 1]; ++e)
        for (int c = 0; c < DT::deriv; ++c) rhs[offset + DT::deriv * J.dof[e] + c] += J.values[DT::deriv * e + c];
    for (Index i = 0; i < Index(D.fixed.size()); ++i)
        if (D.fixed[static_cast<std::size_t>(i)]) rhs[i] = 0.0;
}

// W(a, b) += factor J_b . y for the rows b >= a, mirrored; y = A^-1 J_a^T.
template <class DT>
inline void linear_add_row(CompliancePattern& P, double* W, const JacobianRows& J, Index a, const double* y,
                           Index offset, double factor) {
    const Index row = J.row_index[a];
    for (Index b = a; b < J.rows; ++b) {
        double w = 0.0;
        for (Index e = J.start[b]; e < J.start[b + 1]; ++e)
            for (int c = 0; c < DT::deriv; ++c) w += J.values[DT::deriv * e + c] * y[offset + DT::deriv * J.dof[e] + c];
        const Index column = J.row_index[b];
        P.add(W, column, row, factor * w);
        if (column != row) P.add(W, row, column, factor * w);
    }
}

// W += factor J A^-1 J^T over the state's rows, then the regularization. The solves go
// DirectSolver::kSolveColumns rows at a time when the factor allows (the same solutions, W filled in
// the same order), else one row at a time. Every pair of the state's rows is written: W's part of
// it is dense.
template <class DT>
inline void linear_add_compliance(CompliancePattern& P, double* W, const JacobianRows& J, DirectSolver& D,
                                  Index offset, double factor, double regularization) {
    constexpr int C = DirectSolver::kSolveColumns;
    const auto empty = [&](Index a) { return J.start[a] == J.start[a + 1]; };
    if (D.can_solve_columns()) {
        for (Index a = 0; a < J.rows;) {
            Index batch[C];
            int count = 0;
            for (; a < J.rows && count < C; ++a)
                if (!empty(a)) batch[count++] = a;
            for (int c = 0; c < C; ++c) {
                if (c < count) linear_scatter_row<DT>(D.rhs_columns.col(c).data(), D, J, batch[c], offset);
                else D.rhs_columns.col(c).setZero();
            }
            D.solve_columns();
            for (int c = 0; c < count; ++c) linear_add_row<DT>(P, W, J, batch[c], D.column_solution(c), offset, factor);
        }
    } else {
        for (Index a = 0; a < J.rows; ++a) {
            if (empty(a)) continue;
            linear_scatter_row<DT>(D.rhs.data(), D, J, a, offset);
            D.solve();
            linear_add_row<DT>(P, W, J, a, D.solution.data(), offset, factor);
        }
    }
    if (regularization > std::numeric_limits<double>::epsilon())
        for (Index a = 0; a < J.rows; ++a)
            if (!empty(a)) P.add(W, J.row_index[a], J.row_index[a], regularization);
}

// lambda = J^T f, dx = A^-1 lambda, then x = x_free + position_factor dx, v = v_free + velocity_factor dx
// (x, v hold the free motion), dx = position_factor dx.
template <class DT>
inline void linear_correct(double* x, double* v, double* lambda, double* dx, const JacobianRows& J, const double* f,
                           Index dofs, DirectSolver& D, Index offset, double position_factor, double velocity_factor) {
    const Index size = DT::deriv * dofs;
    for (Index i = 0; i < size; ++i) lambda[i] = 0.0;
    add_jacobian_transpose<DT>(lambda, J, f);
    D.rhs.setZero();
    for (Index i = 0; i < size; ++i) D.rhs[offset + i] = lambda[i];
    for (Index i = 0; i < Index(D.fixed.size()); ++i)
        if (D.fixed[static_cast<std::size_t>(i)]) D.rhs[i] = 0.0;
    D.solve();
    for (Index i = 0; i < size; ++i) dx[i] = D.solution[offset + i];
    apply_motion_correction<DT>(x, x, v, v, dx, dofs, position_factor, velocity_factor);
}

// The same on a body of the Lagrangian contacts: its rows this step (static, then contact rows).
template <class DT>
inline void lagrangian_linear_add_compliance(LagrangianPipeline& L, Index body, CompliancePattern& P, double* W,
                                             const JacobianRows& fixed, DirectSolver& D, Index offset, double factor,
                                             double regularization) {
    const collide::DynamicRows& rows = L->template jacobian<DT>(body, fixed);
    linear_add_compliance<DT>(P, W, rows.view(), D, offset, factor, regularization);
}

template <class DT>
inline void lagrangian_linear_correct(LagrangianPipeline& L, Index body, double* x, double* v, double* lambda,
                                      double* dx, const JacobianRows& fixed, const double* f, Index dofs,
                                      DirectSolver& D, Index offset, double position_factor, double velocity_factor) {
    const collide::DynamicRows& rows = L->template jacobian<DT>(body, fixed);
    linear_correct<DT>(x, v, lambda, dx, rows.view(), f, dofs, D, offset, position_factor, velocity_factor);
}

}  // namespace sofac
