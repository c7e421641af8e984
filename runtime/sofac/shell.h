// Surface force fields on triangles, in SOFA's order of floating-point operations.
//
// TriangularFEMForceFieldOptim (corotational membrane, "large" only): per triangle (a, b, c) the rest
// frame gives bx, cx, cy (b and c in the frame of edge ab) and ss_factor = 1/2 / (bx cy); each
// force pass recomputes the current frame (x along ab, y in the plane) from the positions and
// stores it for the derivative passes. mu = E / (1 + nu), gamma = E nu / (1 - nu^2) (SOFA's
// computeMuGamma). Element data: bx, cx, cy, ss_factor, frame x (3), frame y (3) = 10 doubles.
// SOFA's getPotentialEnergy returns 0 for it (not implemented), as here.
#pragma once

#include "fem.h"
#include "types.h"

namespace sofac {

namespace shell_detail {
using fem_detail::cross;
using fem_detail::dot3;
using fem_detail::load;
using fem_detail::normalize;
using fem_detail::sub;
using fem_detail::V3;

constexpr int TRI_OPTIM_DATA = 10;

// SOFA's computeTriangleRotation: x = ab, y = (ab x ac) x ab, both normalised.
inline void triangle_frame(const V3& ab, const V3& ac, V3& fx, V3& fy) {
    fx = ab;
    const V3 n = cross(ab, ac);
    fy = cross(n, ab);
    normalize(fx);
    normalize(fy);
}

inline V3 combine(const V3& a, double s, const V3& b, double t) {
    return V3{{a[0] * s + b[0] * t, a[1] * s + b[1] * t, a[2] * s + b[2] * t}};
}

}  // namespace shell_detail

constexpr int trifem_optim_data_size(int /*method*/ = 1) { return shell_detail::TRI_OPTIM_DATA; }

// SOFA's reinit (initTriangleInfo, initTriangleState).
inline void trifem_optim_init(const Index* tri, Index n, const double* rest_x, const double* young, Index n_young,
                              const double* poisson, Index n_poisson, int /*method*/, double* data) {
    using namespace shell_detail;
    (void)young, (void)n_young, (void)poisson, (void)n_poisson;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        double* e = data + TRI_OPTIM_DATA * i;
        const V3 a = load(rest_x + 3 * t[0]);
        const V3 ab = sub(load(rest_x + 3 * t[1]), a);
        const V3 ac = sub(load(rest_x + 3 * t[2]), a);
        V3 fx, fy;
        triangle_frame(ab, ac, fx, fy);
        const double bx = dot3(fx, ab), cx = dot3(fx, ac), cy = dot3(fy, ac);
        e[0] = bx;
        e[1] = cx;
        e[2] = cy;
        e[3] = 0.5 / (bx * cy);
        for (int d = 0; d < 3; ++d) {
            e[4 + d] = fx[d];
            e[7 + d] = fy[d];
        }
    }
}

inline void trifem_optim_add_force(const Index* tri, Index n, const double* x, double* f, double* data,
                                   const double* young, Index n_young, const double* poisson, Index n_poisson) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        double* e = data + TRI_OPTIM_DATA * i;
        const double bx = e[0], cx = e[1], cy = e[2], ss = e[3];
        const V3 a = load(x + 3 * t[0]);
        const V3 ab = sub(load(x + 3 * t[1]), a);
        const V3 ac = sub(load(x + 3 * t[2]), a);
        const double E = fem_detail::young_in(young, n_young, i), nu = fem_detail::poisson_in(poisson, n_poisson, i);
        const double mu = E / (1 + nu);
        const double gamma = (E * nu) / (1 - nu * nu);
        V3 fx, fy;
        triangle_frame(ab, ac, fx, fy);
        const double dbx = bx - dot3(fx, ab);
        const double dcx = cx - dot3(fx, ac);
        const double dcy = cy - dot3(fy, ac);
        const double s0 = cy * dbx, s1 = bx * dcy, s2 = bx * dcx - cx * dbx;
        const double gxy = gamma * (s0 + s1);
        const double t0 = (mu * s0 + gxy) * ss, t1 = (mu * s1 + gxy) * ss, t2 = (0.5 * mu * s2) * ss;
        const V3 fb = combine(fx, cy * t0 - cx * t2, fy, cy * t2 - cx * t1);
        const V3 fc = combine(fx, bx * t2, fy, bx * t1);
        for (int d = 0; d < 3; ++d) {
            const double fa = -fb[d] - fc[d];
            f[3 * t[0] + d] += fa;
            f[3 * t[1] + d] += fb[d];
            f[3 * t[2] + d] += fc[d];
            e[4 + d] = fx[d];
            e[7 + d] = fy[d];
        }
    }
}

// df += kfactor (df/dx) dx with the frames of the last force pass (SOFA's addDForce).
inline void trifem_optim_add_dforce(const Index* tri, Index n, const double* dx, double* df, double kfactor,
                                    const double* data, const double* young, Index n_young, const double* poisson,
                                    Index n_poisson) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        const double* e = data + TRI_OPTIM_DATA * i;
        const double bx = e[0], cx = e[1], cy = e[2], ss = e[3];
        const V3 fx = load(e + 4), fy = load(e + 7);
        const double E = fem_detail::young_in(young, n_young, i), nu = fem_detail::poisson_in(poisson, n_poisson, i);
        const double mu = E / (1 + nu);
        const double gamma = (E * nu) / (1 - nu * nu);
        const V3 da = load(dx + 3 * t[0]);
        const V3 dab = sub(load(dx + 3 * t[1]), da);
        const V3 dac = sub(load(dx + 3 * t[2]), da);
        const double dbx = dot3(fx, dab), dby = dot3(fy, dab), dcx = dot3(fx, dac), dcy = dot3(fy, dac);
        const double s0 = cy * dbx, s1 = bx * dcy - cx * dby, s2 = bx * dcx - cx * dbx + cy * dby;
        const double gxy = gamma * (s0 + s1);
        const double k = ss * kfactor;
        const double t0 = (mu * s0 + gxy) * k, t1 = (mu * s1 + gxy) * k, t2 = (0.5 * mu * s2) * k;
        const V3 fb = combine(fx, cy * t0 - cx * t2, fy, cy * t2 - cx * t1);
        const V3 fc = combine(fx, bx * t2, fy, bx * t1);
        for (int d = 0; d < 3; ++d) {
            const double fa = -fb[d] - fc[d];
            df[3 * t[0] + d] -= fa;
            df[3 * t[1] + d] -= fb[d];
            df[3 * t[2] + d] -= fc[d];
        }
    }
}

// The positive stiffness of triangle e (3x3 blocks of 3x3, row-major 9x9) with the stored frame, as
// SOFA's addKToMatrix builds it: blocks F^T (J K J^T)_ab F, F the 2x3 frame.
inline void trifem_optim_element_matrix(const double* data, Index e, const double* young, Index n_young,
                                        const double* poisson, Index n_poisson, double* out) {
    const double* d = data + shell_detail::TRI_OPTIM_DATA * e;
    const double bx = d[0], cx = d[1], cy = d[2], ss = d[3];
    const double E = fem_detail::young_in(young, n_young, e), nu = fem_detail::poisson_in(poisson, n_poisson, e);
    const double mu = E / (1 + nu);
    const double gamma = (E * nu) / (1 - nu * nu);
    const double fG = ss * gamma, fGM = ss * (gamma + mu), fM2 = ss * (0.5 * mu);
    double K[3][4] = {{fGM * cy, fG * -cx, 0, fG * bx}, {fG * cy, fGM * -cx, 0, fGM * bx},
                      {fM2 * -cx, fM2 * cy, fM2 * bx, 0}};
    double B[3][3][2][2];  // node blocks in the frame
    double k11[2][2] = {{cy * K[0][0] - cx * K[2][0], cy * K[0][1] - cx * K[2][1]}, {0, cy * K[2][1] - cx * K[1][1]}};
    k11[1][0] = k11[0][1];
    const double k12[2][2] = {{-cx * K[2][2], cy * K[0][3]}, {cy * K[2][2], -cx * K[1][3]}};
    const double k22[2][2] = {{bx * K[2][2], 0}, {0, bx * K[1][3]}};
    for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) {
            B[1][1][i][j] = k11[i][j];
            B[1][2][i][j] = k12[i][j];
            B[2][1][i][j] = k12[j][i];
            B[2][2][i][j] = k22[i][j];
            B[0][0][i][j] = k11[i][j] + k12[i][j] + k22[i][j] + k12[j][i];
            B[0][1][i][j] = -k11[i][j] - k12[j][i];
            B[1][0][i][j] = -k11[j][i] - k12[i][j];
            B[0][2][i][j] = -k12[i][j] - k22[i][j];
            B[2][0][i][j] = -k12[j][i] - k22[j][i];
        }
    const double* F[2] = {d + 4, d + 7};
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c) {
                    double v = 0.0;
                    for (int i = 0; i < 2; ++i)
                        for (int j = 0; j < 2; ++j) v += F[i][r] * B[a][b][i][j] * F[j][c];
                    out[9 * (3 * a + r) + 3 * b + c] = v;
                }
}

// FastTriangularBendingSprings (Volino's linear bending): per spring across an edge CD between the
// triangles ACD and BCD, R = sum_k alpha_k p_k (alpha and lambda precomputed at compile time from
// the rest positions, as SOFA's setEdgeSpring); f_k -= R lambda alpha_k; energy R.R lambda / 2.
// vid: 4 indices (A, B, C, D) per spring, alpha: 4 weights, lambda: 1 stiffness.
inline void bending_springs_add_force(const Index* vid, const double* alpha, const double* lambda, Index n,
                                      const double* x, double* f) {
    for (Index s = 0; s < n; ++s) {
        const Index* v = vid + 4 * s;
        const double* a = alpha + 4 * s;
        const double l = lambda[s];
        double R[3];
        for (int d = 0; d < 3; ++d)
            R[d] = x[3 * v[0] + d] * a[0] + x[3 * v[1] + d] * a[1] + x[3 * v[2] + d] * a[2] + x[3 * v[3] + d] * a[3];
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d) f[3 * v[k] + d] -= R[d] * l * a[k];
    }
}

inline double bending_springs_energy(const Index* vid, const double* alpha, const double* lambda, Index n,
                                     const double* x) {
    double energy = 0.0;
    for (Index s = 0; s < n; ++s) {
        const Index* v = vid + 4 * s;
        const double* a = alpha + 4 * s;
        double R[3];
        for (int d = 0; d < 3; ++d)
            R[d] = x[3 * v[0] + d] * a[0] + x[3 * v[1] + d] * a[1] + x[3 * v[2] + d] * a[2] + x[3 * v[3] + d] * a[3];
        energy += (R[0] * R[0] + R[1] * R[1] + R[2] * R[2]) * lambda[s] * 0.5;
    }
    return energy;
}

// df += kfactor K dx, K = -lambda alpha alpha^T (x) I3 (SOFA's LOCAL_OPTIM addDForce order).
inline void bending_springs_add_dforce(const Index* vid, const double* alpha, const double* lambda, Index n,
                                       const double* dx, double* df, double kfactor) {
    for (Index s = 0; s < n; ++s) {
        const Index* v = vid + 4 * s;
        const double* a = alpha + 4 * s;
        double p[4][3];
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d) p[k][d] = dx[3 * v[k] + d] * lambda[s] * kfactor * a[k];
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k)
                for (int d = 0; d < 3; ++d) df[3 * v[j] + d] -= p[k][d] * a[j];
    }
}

// Sparse direct solvers: A += kfact K.
template <class Assembler>
inline void assemble_bending_springs(Assembler& A, Index offset, const Index* vid, const double* alpha,
                                     const double* lambda, Index n, double kfact) {
    for (Index s = 0; s < n; ++s) {
        const Index* v = vid + 4 * s;
        const double* a = alpha + 4 * s;
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) {
                const double value = -lambda[s] * a[j] * a[k] * kfact;
                for (int d = 0; d < 3; ++d) A.add(offset + 3 * v[j] + d, offset + 3 * v[k] + d, value);
            }
    }
}

}  // namespace sofac
