// Non-linear mappings Vec3d -> Vec1d over the edges (l0, l1) of a topology, in SOFA's order of
// floating-point operations (Sofa.Component.Mapping.NonLinear).
//
// DistanceMapping: child_i = |p_l1 - p_l0| - rest_i; J_i = (-u, u) on (l0, l1), u the unit direction
// (or (1,1,1)/sqrt(3) for a zero length), stored with 1/length by apply. Geometric stiffness (SOFA's
// matrixFreeApplyDJT): df_l0 -= b, df_l1 += b, b = ((I - u u^T) * (f_i / length * kfact)) (dx_l1 - dx_l0),
// for f_i < 0 (Stabilized) or always (Exact).
// SquareDistanceMapping: child_i = |p_l1 - p_l0|^2; J_i = (-2 g, 2 g), g = p_l1 - p_l0 (stored in dir);
// geometric stiffness df_l0 += 2 f_i kfact (dx_l0 - dx_l1), df_l1 -= the same.
// `kind`: 0 distance, 1 square distance. `gs`: 0 none, 1 exact, 2 stabilized.
// J's two blocks are summed in increasing vertex order, as SOFA's sorted Jacobian rows.
#pragma once

#include <cfloat>
#include <cmath>

#include "types.h"

namespace sofac {

// An edge's length minus its rest length, its unit direction g / |g| and 1 / |g|, as SOFA's
// distance mappings compute them (a zero-length edge: the direction (1, 1, 1) / sqrt(3), 1/|g| = 0).
inline void edge_direction(const double* g, double distance, double rest, double& cx, double& invlen, double* d) {
    cx = distance - rest;
    if (distance > DBL_EPSILON) {
        invlen = 1 / distance;
        for (int k = 0; k < 3; ++k) d[k] = g[k] * invlen;
    } else {
        invlen = 0;
        const double p = 1.0 / std::sqrt(3.0);
        for (int k = 0; k < 3; ++k) d[k] = p;
    }
}

inline void distance_mapping_apply(const double* px, double* cx, const Index* edges, Index n, const double* rest,
                                   int kind, double* dir, double* invlen) {
    for (Index i = 0; i < n; ++i) {
        const Index a = edges[2 * i], b = edges[2 * i + 1];
        double g[3];
        for (int k = 0; k < 3; ++k) g[k] = px[3 * b + k] - px[3 * a + k];
        const double norm2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
        double* d = dir + 3 * i;
        if (kind == 1) {
            cx[i] = norm2;
            for (int k = 0; k < 3; ++k) d[k] = g[k] * 2;
            continue;
        }
        const double distance = std::sqrt(norm2);
        edge_direction(g, distance, rest[i], cx[i], invlen[i], d);
    }
}

// child_i = J_i parent (velocities, dx).
inline void distance_mapping_j(const double* pv, double* cv, const Index* edges, Index n, const double* dir) {
    for (Index i = 0; i < n; ++i) {
        const Index a = edges[2 * i], b = edges[2 * i + 1];
        const double* d = dir + 3 * i;
        double sum = 0.0;
        if (a < b) {
            for (int k = 0; k < 3; ++k) sum += -d[k] * pv[3 * a + k];
            for (int k = 0; k < 3; ++k) sum += d[k] * pv[3 * b + k];
        } else {
            for (int k = 0; k < 3; ++k) sum += d[k] * pv[3 * b + k];
            for (int k = 0; k < 3; ++k) sum += -d[k] * pv[3 * a + k];
        }
        cv[i] = sum;
    }
}

// parent += J^T child (forces, df), row by row.
inline void distance_mapping_jt(double* pf, const double* cf, const Index* edges, Index n, const double* dir) {
    for (Index i = 0; i < n; ++i) {
        const Index a = edges[2 * i], b = edges[2 * i + 1];
        const double* d = dir + 3 * i;
        for (int k = 0; k < 3; ++k) {
            pf[3 * a + k] += -d[k] * cf[i];
            pf[3 * b + k] += d[k] * cf[i];
        }
    }
}

// parent df += kfact dJ^T/dx (child force) dx: the geometric stiffness.
inline void distance_mapping_djt(double* pdf, const double* pdx, const double* cf, const Index* edges, Index n,
                                 const double* dir, const double* invlen, int kind, int gs, double kfact) {
    if (gs == 0) return;
    for (Index i = 0; i < n; ++i) {
        if (!(cf[i] < 0 || gs == 1)) continue;
        const Index a = edges[2 * i], b = edges[2 * i + 1];
        if (kind == 1) {
            const double t = 2 * cf[i] * kfact;
            for (int k = 0; k < 3; ++k) {
                const double df = t * (pdx[3 * a + k] - pdx[3 * b + k]);
                pdf[3 * a + k] = pdf[3 * a + k] + df;
                pdf[3 * b + k] = pdf[3 * b + k] - df;
            }
            continue;
        }
        const double* u = dir + 3 * i;
        const double s = cf[i] * invlen[i] * kfact;
        double m[3][3];
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) m[j][k] = (1.0 * (j == k) - u[j] * u[k]) * s;
        double dx[3], df[3] = {0.0, 0.0, 0.0};
        for (int k = 0; k < 3; ++k) dx[k] = pdx[3 * b + k] - pdx[3 * a + k];
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) df[j] += m[j][k] * dx[k];
        for (int k = 0; k < 3; ++k) {
            pdf[3 * a + k] -= df[k];
            pdf[3 * b + k] += df[k];
        }
    }
}

// DistanceMultiMapping with each edge from a point a_i of parent 0 to a point b_i of parent 1:
// child_i = |x1_b - x0_a| - rest_i, J = (-u on parent 0, u on parent 1), one matrix per parent
// (SOFA's applyJ: parent 0's product, then parent 1's added).
inline void distance_multi_apply(const double* x0, const double* x1, double* cx, const Index* a, const Index* b,
                                 Index n, const double* rest, double* dir, double* invlen) {
    for (Index i = 0; i < n; ++i) {
        double g[3];
        for (int k = 0; k < 3; ++k) g[k] = x1[3 * b[i] + k] - x0[3 * a[i] + k];
        const double distance = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        double* d = dir + 3 * i;
        edge_direction(g, distance, rest[i], cx[i], invlen[i], d);
    }
}

inline void distance_multi_j(const double* v0, const double* v1, double* cv, const Index* a, const Index* b, Index n,
                             const double* dir) {
    for (Index i = 0; i < n; ++i) {
        const double* d = dir + 3 * i;
        double first = 0.0, second = 0.0;
        for (int k = 0; k < 3; ++k) first += -d[k] * v0[3 * a[i] + k];
        for (int k = 0; k < 3; ++k) second += d[k] * v1[3 * b[i] + k];
        cv[i] = first + second;
    }
}

inline void distance_multi_jt(double* f0, double* f1, const double* cf, const Index* a, const Index* b, Index n,
                              const double* dir) {
    for (Index i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) f0[3 * a[i] + k] += -dir[3 * i + k] * cf[i];
    for (Index i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) f1[3 * b[i] + k] += dir[3 * i + k] * cf[i];
}

}  // namespace sofac
