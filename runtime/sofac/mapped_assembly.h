// The Jacobians of mappings as rows of the assembler's J (see Assembler::kMapped): a force field or
// mass on a mapped state then assembles J^T K J onto the independent DOFs. `child` is the first
// index of the mapped state's DOFs (from kMapped on), `parent` that of its input (an independent
// offset, or a mapped one for a chain). Rows are given in order, one per scalar DOF of the child.
#pragma once

#include "assembly.h"

namespace sofac {

// RigidMapping Rigid3d -> Vec3d: v = v_c + w_c x r, r the rotated offset of the last apply
// (current rotation: refilled every step).
inline void rigid_jacobian(Assembler& A, Index child, Index parent, const Index* frame, const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = parent + 6 * frame[i];
        const double* r = offset + 3 * i;
        const Index rows[3][3] = {{c, c + 4, c + 5}, {c + 1, c + 3, c + 5}, {c + 2, c + 3, c + 4}};
        const double weights[3][3] = {{1.0, r[2], -r[1]}, {1.0, -r[2], r[0]}, {1.0, r[1], -r[0]}};
        for (int d = 0; d < 3; ++d) A.jacobian_row(child + 3 * i + d, 3, rows[d], weights[d]);
    }
}

// RigidMapping Rigid3d -> Rigid3d: the linear rows as above, the angular rows the parent's w.
inline void rigid_frame_jacobian(Assembler& A, Index child, Index parent, const Index* frame,
                                 const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = parent + 6 * frame[i];
        const double* r = offset + 3 * i;
        const Index rows[3][3] = {{c, c + 4, c + 5}, {c + 1, c + 3, c + 5}, {c + 2, c + 3, c + 4}};
        const double weights[3][3] = {{1.0, r[2], -r[1]}, {1.0, -r[2], r[0]}, {1.0, r[1], -r[0]}};
        for (int d = 0; d < 3; ++d) A.jacobian_row(child + 6 * i + d, 3, rows[d], weights[d]);
        const double one = 1.0;
        for (int d = 0; d < 3; ++d) {
            const Index column = c + 3 + d;
            A.jacobian_row(child + 6 * i + 3 + d, 1, &column, &one);
        }
    }
}

// RigidMapping Rigid2d -> Vec2d: v = v_c + w_c (-r_y, r_x).
inline void rigid2_jacobian(Assembler& A, Index child, Index parent, const Index* frame, const double* offset,
                            Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = parent + 3 * frame[i];
        const double* r = offset + 2 * i;
        const Index rows[2][2] = {{c, c + 2}, {c + 1, c + 2}};
        const double weights[2][2] = {{1.0, -r[1]}, {1.0, r[0]}};
        for (int d = 0; d < 2; ++d) A.jacobian_row(child + 2 * i + d, 2, rows[d], weights[d]);
    }
}

// A constant linear map (BarycentricMapping: k weighted parent points per child point, `width`
// numbers per point on both sides): recorded once, with the pattern.
inline void linear_jacobian(Assembler& A, Index child, Index parent, const Index* idx, const double* w, Index n,
                            int k, int width) {
    std::vector<Index> columns(static_cast<std::size_t>(k));
    for (Index i = 0; i < n; ++i)
        for (int d = 0; d < width; ++d) {
            for (int j = 0; j < k; ++j) columns[j] = parent + width * idx[i * k + j] + d;
            A.jacobian_row(child + width * i + d, k, columns.data(), w + i * k);
        }
}

// SubsetMapping / IdentityMapping: child DOF k is parent DOF indices[k] (recorded once).
template <class DT>
inline void subset_jacobian(Assembler& A, Index child, Index parent, const Index* indices, Index n) {
    const double one = 1.0;
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < DT::deriv; ++d) {
            const Index column = parent + DT::deriv * indices[k] + d;
            A.jacobian_row(child + DT::deriv * k + d, 1, &column, &one);
        }
}

// IdentityMapping between types of different sizes: child number d of DOF k is the parent's number
// d of DOF k (recorded once).
inline void leading_jacobian(Assembler& A, Index child, Index parent, Index n, int in_width, int out_width) {
    const double one = 1.0;
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < out_width; ++d) {
            const Index column = parent + in_width * k + d;
            A.jacobian_row(child + out_width * k + d, 1, &column, &one);
        }
}

}  // namespace sofac
