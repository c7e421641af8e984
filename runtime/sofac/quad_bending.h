// QuadBendingFEMForceField (Vec3d, method "small", the only one SOFA implements), in SOFA's order
// of floating-point operations (commit 2a278d89). Written from a reading of SOFA's sources.
//
// SOFA's element, as it is (no frame: it works in world coordinates whatever the quad's plane):
// - Each quad (0, 1, 2, 3) carries 5 unknowns per node (u, v, w, theta_x, theta_y); the rotations
//   are taken to be zero, so only u, v, w act. The displacement is measured from the quad's
//   centroid (p0 + p2) / 2: D_k = (X0_k - C0) - (x_k - C), so a translation gives no force.
// - Every force (and derivative) pass recomputes the element stiffness from the *current*
//   positions: half-lengths l = |x1 - x0| / 2, h = |x3 - x0| / 2.
// - u, v: a bilinear membrane, 2x2 Gauss points (+-sqrt(3)/3, weight 1), plane-stress matrix
//   Cb = E t / (1 - nu^2) [1 nu 0; nu 1 0; 0 0 (1 - nu) / 2], dN/dx, dN/dy of the isoparametric
//   rectangle of half sides l, h.
// - w: only the transverse-shear term with zero rotations, one Gauss point (weight 2 x 2):
//   K_ww(i, j) = 4 l h Cs (dNi/dx dNj/dx + dNi/dy dNj/dy), Cs = (5/6) E t / (2 (1 + nu)). The
//   bending terms (E t^3 / 12 ...) multiply the rotations only, hence never act.
// - add_dforce: df += kfactor * (-K dx), with K from the positions x at that time (SOFA reads the
//   state's positions); dK/dx is neglected, as in SOFA.
// - SOFA's getPotentialEnergy is not implemented (returns 0), and neither is it here.
// Element data: the rest positions minus the rest centroid (12), then Cb00, Cb01, Cb22, Cs (4).
#pragma once

#include <cmath>

#include "fem.h"
#include "types.h"

namespace sofac {

constexpr int QUAD_BENDING_DATA = 16;

namespace quad_bending_detail {

// The corner signs (m, n) of SOFA's nodes 0..3 in the element's (xi, eta) square.
constexpr double kM[4] = {-1.0, 1.0, 1.0, -1.0};
constexpr double kN[4] = {-1.0, -1.0, 1.0, 1.0};

// The translational rows of SOFA's element stiffness K (20x20, 5 unknowns per node): kuv[i][c][j][d]
// = K(5i + c, 5j + d) for c, d in {u, v}, kw[i][j] = K(5i + 2, 5j + 2).
struct QuadStiffness {
    double kuv[4][2][4][2];
    double kw[4][4];
};

inline double half_length(const double* a, const double* b) {
    const double d0 = b[0] - a[0], d1 = b[1] - a[1], d2 = b[2] - a[2];
    return std::sqrt(d0 * d0 + d1 * d1 + d2 * d2) / 2;
}

// SOFA's computeElementStiffness (the entries its computeForce reads) at positions x.
inline void element_stiffness(const Index* q, const double* x, const double* data, QuadStiffness& k) {
    const double l = half_length(x + 3 * q[0], x + 3 * q[1]);
    const double h = half_length(x + 3 * q[0], x + 3 * q[3]);
    const double c00 = data[12], c01 = data[13], c22 = data[14], cs = data[15];
    const double lh = l * h;
    const double g = std::sqrt(3.0) / 3;
    const double gauss[4][2] = {{g, g}, {-g, g}, {g, -g}, {-g, -g}};  // (gauss1, gauss2)
    for (int i = 0; i < 4; ++i)
        for (int c = 0; c < 2; ++c)
            for (int j = 0; j < 4; ++j)
                for (int d = 0; d < 2; ++d) k.kuv[i][c][j][d] = 0.0;
    for (const auto& point : gauss) {
        double ax[4], ay[4];  // dN/dx, dN/dy at the point (SOFA's Jb entries)
        for (int i = 0; i < 4; ++i) {
            ax[i] = kM[i] * (1 + kN[i] * point[1]) / (4 * l);
            ay[i] = kN[i] * (1 + kM[i] * point[0]) / (4 * h);
        }
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) {
                // wb = 1: SOFA's final "* wb" changes nothing.
                const double uu = lh * (ax[i] * c00 * ax[j] + ay[i] * c22 * ay[j]);
                const double uv = lh * (ax[i] * c01 * ay[j] + ay[i] * c22 * ax[j]);
                const double vu = lh * (ay[i] * c01 * ax[j] + ax[i] * c22 * ay[j]);
                const double vv = lh * (ay[i] * c00 * ay[j] + ax[i] * c22 * ax[j]);
                // Kb = Kb0 + Kb1 + Kb2 + Kb3, left to right (0 + Kb0 is Kb0)
                k.kuv[i][0][j][0] += uu;
                k.kuv[i][0][j][1] += uv;
                k.kuv[i][1][j][0] += vu;
                k.kuv[i][1][j][1] += vv;
            }
    }
    const double ws = 2;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            const double bxi = kM[i] / (4 * l), byi = kN[i] / (4 * h);
            const double bxj = kM[j] / (4 * l), byj = kN[j] / (4 * h);
            k.kw[i][j] = lh * (bxi * cs * bxj + byi * cs * byj) * ws * ws;
        }
}

// SOFA's computeForce: F = K D on the translations (D: 3 numbers per node), 12 numbers.
inline void stiffness_times(const QuadStiffness& k, const double* D, double* F) {
    for (int i = 0; i < 4; ++i) {
        for (int c = 0; c < 2; ++c) {
            double s = k.kuv[i][c][0][0] * D[0] + k.kuv[i][c][0][1] * D[1];
            for (int j = 1; j < 4; ++j) {
                s += k.kuv[i][c][j][0] * D[3 * j];
                s += k.kuv[i][c][j][1] * D[3 * j + 1];
            }
            F[3 * i + c] = s;
        }
        double w = k.kw[i][0] * D[2];
        for (int j = 1; j < 4; ++j) w += k.kw[i][j] * D[3 * j + 2];
        F[3 * i + 2] = w;
    }
}

}  // namespace quad_bending_detail

// SOFA's initSmall and material matrices of each quad. young / poisson: one value, or one per
// element (element i takes list[i] when the list is longer than i, else list[0]).
inline void quad_bending_init(const Index* quads, Index n, const double* rest_x, const double* young,
                              Index n_young, const double* poisson, Index n_poisson, double thickness,
                              double* data) {
    for (Index e = 0; e < n; ++e) {
        const Index* q = quads + 4 * e;
        double* d = data + QUAD_BENDING_DATA * e;
        const double* a = rest_x + 3 * q[0];
        const double* c = rest_x + 3 * q[2];
        double centroid[3];
        for (int m = 0; m < 3; ++m) centroid[m] = (a[m] + c[m]) / 2;
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) d[3 * k + m] = rest_x[3 * q[k] + m] - centroid[m];
        const double y = fem_detail::element_value(young, n_young, e);
        const double p = fem_detail::element_value(poisson, n_poisson, e);
        const double t = thickness;
        const double k = 5.0 / 6.0;
        d[12] = y * t / (1 - p * p);
        d[13] = p * y * t / (1 - p * p);
        d[14] = y * t * (1 - p) / (2 - 2 * p * p);
        d[15] = k * y * t / (2 + 2 * p);
    }
}

// f += the elastic force at positions x (SOFA's addForce / accumulateForceSmall).
inline void quad_bending_add_force(const Index* quads, Index n, const double* x, double* f, const double* data) {
    using namespace quad_bending_detail;
    for (Index e = 0; e < n; ++e) {
        const Index* q = quads + 4 * e;
        const double* d = data + QUAD_BENDING_DATA * e;
        double centroid[3];
        for (int m = 0; m < 3; ++m) centroid[m] = (x[3 * q[0] + m] + x[3 * q[2] + m]) / 2;
        double D[12];
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) D[3 * k + m] = d[3 * k + m] - (x[3 * q[k] + m] - centroid[m]);
        QuadStiffness K;
        element_stiffness(q, x, d, K);
        double F[12];
        stiffness_times(K, D, F);
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) f[3 * q[k] + m] += F[3 * k + m];
    }
}

// df += kfactor * (-K dx), K at positions x (SOFA's addDForce / applyStiffnessSmall with h = 1).
inline void quad_bending_add_dforce(const Index* quads, Index n, const double* x, const double* dx, double* df,
                                    double kfactor, const double* data) {
    using namespace quad_bending_detail;
    for (Index e = 0; e < n; ++e) {
        const Index* q = quads + 4 * e;
        double D[12];
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) D[3 * k + m] = dx[3 * q[k] + m];
        QuadStiffness K;
        element_stiffness(q, x, data + QUAD_BENDING_DATA * e, K);
        double F[12];
        stiffness_times(K, D, F);
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) df[3 * q[k] + m] += -F[3 * k + m] * kfactor;
    }
}

}  // namespace sofac
