// Surface force fields on triangles (and QuadularBendingSprings on quads), in SOFA's order of
// floating-point operations.
//
// TriangularFEMForceFieldOptim (corotational membrane, "large" only): per triangle (a, b, c) the rest
// frame gives bx, cx, cy (b and c in the frame of edge ab) and ss_factor = 1/2 / (bx cy); each
// force pass recomputes the current frame (x along ab, y in the plane) from the positions and
// stores it for the derivative passes. mu = E / (1 + nu), gamma = E nu / (1 - nu^2) (SOFA's
// computeMuGamma). Element data: bx, cx, cy, ss_factor, frame x (3), frame y (3) = 10 doubles.
// SOFA's getPotentialEnergy returns 0 for it (not implemented), as here.
#pragma once

#include <cmath>

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
        const double E = fem_detail::element_value(young, n_young, i), nu = fem_detail::element_value(poisson, n_poisson, i);
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
        const double E = fem_detail::element_value(young, n_young, i), nu = fem_detail::element_value(poisson, n_poisson, i);
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
    const double E = fem_detail::element_value(young, n_young, e), nu = fem_detail::element_value(poisson, n_poisson, e);
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

// TriangularBendingSprings: a spring (m1, m2) between the vertices opposite each edge shared by two
// triangles, in the topology's edge order: u = x_m2 - x_m1, d = |u|; for d > 1e-4, F = ks (d - L) +
// kd (u/d).(v_m2 - v_m1), f_m1 += F u/d, f_m2 -= it, and the force pass stores df/dx =
// (ks - F/d) u u^T / d^2 + F/d I (zero for d <= 1e-4). springs: (m1, m2) per spring; params: ks, kd,
// L per spring; dfdx: 9 per spring.
inline void triangular_bending_add_force(const Index* springs, const double* params, Index n, const double* x,
                                         const double* v, double* f, double* dfdx) {
    for (Index s = 0; s < n; ++s) {
        const Index a = springs[2 * s], b = springs[2 * s + 1];
        const double ks = params[3 * s], kd = params[3 * s + 1], rest = params[3 * s + 2];
        double* m = dfdx + 9 * s;
        double u[3];
        for (int k = 0; k < 3; ++k) u[k] = x[3 * b + k] - x[3 * a + k];
        const double d = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        if (!(d > 1.0e-4)) {
            for (int k = 0; k < 9; ++k) m[k] = 0.0;
            continue;
        }
        const double inverse = 1.0 / d;
        for (int k = 0; k < 3; ++k) u[k] *= inverse;
        const double elongation = d - rest;
        double rv[3];
        for (int k = 0; k < 3; ++k) rv[k] = v[3 * b + k] - v[3 * a + k];
        const double speed = u[0] * rv[0] + u[1] * rv[1] + u[2] * rv[2];
        const double intensity = ks * elongation + kd * speed;
        for (int k = 0; k < 3; ++k) {
            const double force = u[k] * intensity;
            f[3 * a + k] += force;
            f[3 * b + k] -= force;
        }
        const double tgt = intensity * inverse;
        for (int j = 0; j < 3; ++j) {
            for (int k = 0; k < 3; ++k) m[3 * j + k] = (ks - tgt) * u[j] * u[k];
            m[3 * j + j] += tgt;
        }
    }
}

inline void triangular_bending_add_dforce(const Index* springs, Index n, const double* dfdx, const double* dx,
                                          double* df, double kfactor) {
    for (Index s = 0; s < n; ++s) {
        const Index a = springs[2 * s], b = springs[2 * s + 1];
        const double* m = dfdx + 9 * s;
        double d[3];
        for (int k = 0; k < 3; ++k) d[k] = dx[3 * b + k] - dx[3 * a + k];
        for (int j = 0; j < 3; ++j) {
            const double value = m[3 * j] * d[0] + m[3 * j + 1] * d[1] + m[3 * j + 2] * d[2];
            df[3 * a + j] += value * kfactor;
            df[3 * b + j] -= value * kfactor;
        }
    }
}

// SOFA's potential energy: sum of ks (d - L)^2 / 2 over the springs longer than 1e-4.
inline double triangular_bending_energy(const Index* springs, const double* params, Index n, const double* x) {
    double energy = 0.0;
    for (Index s = 0; s < n; ++s) {
        const Index a = springs[2 * s], b = springs[2 * s + 1];
        double u[3];
        for (int k = 0; k < 3; ++k) u[k] = x[3 * b + k] - x[3 * a + k];
        const double d = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        if (d > 1.0e-4) {
            const double elongation = d - params[3 * s + 2];
            energy += elongation * elongation * params[3 * s] / 2;
        }
    }
    return energy;
}

// Sparse direct solvers: A += kfact K, K = [[m, -m], [-m, m]] on (m1, m2).
template <class Assembler>
inline void assemble_triangular_bending(Assembler& A, Index offset, const Index* springs, Index n, const double* dfdx,
                                        double kfact) {
    for (Index s = 0; s < n; ++s) {
        const Index ends[2] = {springs[2 * s], springs[2 * s + 1]};
        const double* m = dfdx + 9 * s;
        for (int p = 0; p < 2; ++p)
            for (int q = 0; q < 2; ++q) {
                const double sign = p == q ? -1.0 : 1.0;
                for (int j = 0; j < 3; ++j)
                    for (int k = 0; k < 3; ++k)
                        A.add(offset + 3 * ends[p] + j, offset + 3 * ends[q] + k, sign * m[3 * j + k] * kfact);
            }
    }
}

// QuadularBendingSprings: springs (e0, e1) with ks, kd, L each (params), SOFA's computeSpringForce:
// u = x_e1 - x_e0, d = |u|; for d > 1e-4, direction u * (1/d), F = ks (d - L) + kd direction.(v_e1 -
// v_e0), f_e0 += F direction, f_e1 -= it, and the force pass stores df/dx = (u/d)(u/d)^T (ks - F/d)
// + F/d I (zero for d <= 1e-4; note u/d there, a division, where the force multiplies by 1/d).
inline void quadular_bending_add_force(const Index* springs, const double* params, Index n, const double* x,
                                       const double* v, double* f, double* dfdx) {
    for (Index s = 0; s < n; ++s) {
        const Index a = springs[2 * s], b = springs[2 * s + 1];
        const double ks = params[3 * s], kd = params[3 * s + 1], rest = params[3 * s + 2];
        double* m = dfdx + 9 * s;
        for (int k = 0; k < 9; ++k) m[k] = 0.0;
        double u[3];
        for (int k = 0; k < 3; ++k) u[k] = x[3 * b + k] - x[3 * a + k];
        const double d = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        if (!(d > 1.0e-4)) continue;
        const double inverse = 1 / d;
        double direction[3], rv[3], unit[3];
        for (int k = 0; k < 3; ++k) {
            direction[k] = u[k] * inverse;
            rv[k] = v[3 * b + k] - v[3 * a + k];
            unit[k] = u[k] / d;
        }
        const double elongation = d - rest;
        const double speed = direction[0] * rv[0] + direction[1] * rv[1] + direction[2] * rv[2];
        const double intensity = ks * elongation + kd * speed;
        for (int k = 0; k < 3; ++k) {
            const double force = direction[k] * intensity;
            f[3 * a + k] += force;
            f[3 * b + k] -= force;
        }
        const double tgt = intensity * inverse;
        for (int j = 0; j < 3; ++j) {
            for (int k = 0; k < 3; ++k) m[3 * j + k] = unit[j] * unit[k] * (ks - tgt);
            m[3 * j + j] += tgt;
        }
    }
}

// df_e0 += m (kfactor (dx_e1 - dx_e0)), df_e1 -= it (SOFA scales dx before the product).
inline void quadular_bending_add_dforce(const Index* springs, Index n, const double* dfdx, const double* dx,
                                        double* df, double kfactor) {
    for (Index s = 0; s < n; ++s) {
        const Index a = springs[2 * s], b = springs[2 * s + 1];
        const double* m = dfdx + 9 * s;
        double d[3];
        for (int k = 0; k < 3; ++k) d[k] = (dx[3 * b + k] - dx[3 * a + k]) * kfactor;
        for (int j = 0; j < 3; ++j) {
            const double value = m[3 * j] * d[0] + m[3 * j + 1] * d[1] + m[3 * j + 2] * d[2];
            df[3 * a + j] += value;
            df[3 * b + j] -= value;
        }
    }
}

// TriangularFEMForceField, method "large" (SOFA's TriangleFEMUtils, non-anisotropic path): per
// triangle the frame R (x along ab, z the normal) of the current positions, the displacement of b and
// c in it against the rotated rest shape, J from the current local b and c, stress = K J^T D with
// K = E/(1-nu^2) area [[1, nu, 0], [nu, 1, 0], [0, 0, (1-nu)/2]], F = J stress rotated back. The
// force pass stores R^T and J for the derivative passes. Element data (35 doubles): R^T (9), rest
// b_x, c_x, c_y (3), J (6x3), K00 K01 K10 K11 K22 (5).
namespace shell_detail {
constexpr int TRI_FEM_DATA = 35;

// SOFA's computeRotationLarge: rows x = normalized(b - a), z = normalized(x cross (c - a)), y = z cross x.
inline void triangle_rotation(const V3& pa, const V3& pb, const V3& pc, double r[9]) {
    V3 ex = sub(pb, pa);
    normalize(ex);
    V3 ey = sub(pc, pa);
    V3 ez = cross(ex, ey);
    normalize(ez);
    ey = cross(ez, ex);
    for (int k = 0; k < 3; ++k) {
        r[k] = ex[k];
        r[3 + k] = ey[k];
        r[6 + k] = ez[k];
    }
}

inline V3 mat_vec(const double r[9], const V3& v) {
    return V3{{r[0] * v[0] + r[1] * v[1] + r[2] * v[2], r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
               r[6] * v[0] + r[7] * v[1] + r[8] * v[2]}};
}

// SOFA's computeStrainDisplacementLocal (J is 6x3, row-major).
inline void strain_displacement(const V3& b, const V3& c, double J[18]) {
    const double inv = 1 / (b[0] * c[1]);
    for (int k = 0; k < 18; ++k) J[k] = 0.0;
    J[0 * 3 + 0] = J[1 * 3 + 2] = -c[1] * inv;
    J[0 * 3 + 2] = J[1 * 3 + 1] = (c[0] - b[0]) * inv;
    J[2 * 3 + 0] = J[3 * 3 + 2] = c[1] * inv;
    J[2 * 3 + 2] = J[3 * 3 + 1] = -c[0] * inv;
    J[4 * 3 + 2] = J[5 * 3 + 1] = b[0] * inv;
}

// Local forces F (6) of displacements D (6): strain = J^T D (sparse), stress = K strain, F = J stress.
inline void local_forces(const double J[18], const double* K, const double D[6], double F[6]) {
    auto j = [&](int row, int col) { return J[row * 3 + col]; };
    const double s0 = j(0, 0) * D[0] + j(2, 0) * D[2];
    const double s1 = j(1, 1) * D[1] + j(3, 1) * D[3] + j(5, 1) * D[5];
    const double s2 = j(0, 2) * D[0] + j(1, 2) * D[1] + j(2, 2) * D[2] + j(3, 2) * D[3] + j(4, 2) * D[4];
    const double t0 = K[0] * s0 + K[1] * s1, t1 = K[2] * s0 + K[3] * s1, t2 = K[4] * s2;
    F[0] = j(0, 0) * t0 + j(0, 2) * t2;
    F[1] = j(1, 1) * t1 + j(1, 2) * t2;
    F[2] = j(2, 0) * t0 + j(2, 2) * t2;
    F[3] = j(3, 1) * t1 + j(3, 2) * t2;
    F[4] = j(4, 2) * t2;
    F[5] = j(5, 1) * t1;
}

// The large method on one triangle (SOFA's accumulateForceLarge): the frame R of the current
// positions, the displacement of b and c in it against the rest b_x, c_x, c_y, J from the current
// local b and c; f += R^T F. Stores R^T in `rotation` and J for the derivative passes.
inline void large_triangle_force(const Index* t, const double* x, double* f, double rest_bx, double rest_cx,
                                 double rest_cy, const double* K, double* rotation, double* J) {
    const V3 pa = load(x + 3 * t[0]), pb = load(x + 3 * t[1]), pc = load(x + 3 * t[2]);
    double r[9];
    triangle_rotation(pa, pb, pc, r);
    const V3 b = mat_vec(r, sub(pb, pa)), c = mat_vec(r, sub(pc, pa));
    const double D[6] = {0, 0, rest_bx - b[0], 0, rest_cx - c[0], rest_cy - c[1]};
    double F[6];
    strain_displacement(b, c, J);
    local_forces(J, K, D, F);
    for (int a = 0; a < 3; ++a)
        for (int k = 0; k < 3; ++k) rotation[3 * a + k] = r[3 * k + a];
    for (int node = 0; node < 3; ++node) {
        const V3 fw = mat_vec(rotation, V3{{F[2 * node], F[2 * node + 1], 0}});
        for (int k = 0; k < 3; ++k) f[3 * t[node] + k] += fw[k];
    }
}

// df += kfactor (df/dx) dx on one triangle with the stored R^T and J (SOFA's applyStiffnessLarge, h = 1).
inline void large_triangle_dforce(const Index* t, const double* dx, double* df, double kfactor,
                                  const double* rotation, const double* J, const double* K) {
    double r[9];  // R_0_2 = transpose(rotation)
    for (int a = 0; a < 3; ++a)
        for (int k = 0; k < 3; ++k) r[3 * a + k] = rotation[3 * k + a];
    double D[6], F[6];
    for (int node = 0; node < 3; ++node) {
        const V3 local = mat_vec(r, load(dx + 3 * t[node]));
        D[2 * node] = local[0];
        D[2 * node + 1] = local[1];
    }
    local_forces(J, K, D, F);
    const double h = 1;
    for (int node = 0; node < 3; ++node) {
        const V3 fw = mat_vec(rotation, V3{{-h * F[2 * node], -h * F[2 * node + 1], 0}});
        for (int k = 0; k < 3; ++k) df[3 * t[node] + k] += fw[k] * kfactor;
    }
}
// SOFA's computeElementStiffnessMatrix (TriangleFEMForceField and TriangularFEMForceField): the
// positive stiffness (9x9, row-major, node-major) Ke = J K J^T on the in-plane x, y of each node, then
// RR Ke RR^T with RR the block-diagonal rotation (R^T, local to world); products in SOFA's Mat order.
inline void corotational_triangle_matrix(const double* rotation, const double* J, const double* k, double* out) {
    const double K[3][3] = {{k[0], k[1], 0}, {k[2], k[3], 0}, {0, 0, k[4]}};
    double JK[6][3] = {}, JKJt[6][6] = {};
    for (int i = 0; i < 6; ++i)
        for (int m = 0; m < 3; ++m)
            for (int j = 0; j < 3; ++j) JK[i][j] += J[3 * i + m] * K[m][j];
    for (int i = 0; i < 6; ++i)
        for (int m = 0; m < 3; ++m)
            for (int j = 0; j < 6; ++j) JKJt[i][j] += JK[i][m] * J[3 * j + m];
    double Ke[9][9] = {}, RR[9][9] = {}, S[9][9] = {};
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int m = 0; m < 2; ++m)
                for (int l = 0; l < 2; ++l) Ke[3 * a + m][3 * b + l] = JKJt[2 * a + m][2 * b + l];
    for (int a = 0; a < 3; ++a)
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) RR[3 * a + i][3 * a + j] = rotation[3 * i + j];
    for (int i = 0; i < 9; ++i)
        for (int m = 0; m < 9; ++m)
            for (int j = 0; j < 9; ++j) S[i][j] += RR[i][m] * Ke[m][j];
    for (int i = 0; i < 9; ++i)
        for (int j = 0; j < 9; ++j) out[9 * i + j] = 0.0;
    for (int i = 0; i < 9; ++i)
        for (int m = 0; m < 9; ++m)
            for (int j = 0; j < 9; ++j) out[9 * i + j] += S[i][m] * RR[j][m];
}
}  // namespace shell_detail

constexpr int trifem_data_size(int /*method*/ = 1) { return shell_detail::TRI_FEM_DATA; }

inline void trifem_init(const Index* tri, Index n, const double* rest_x, const double* young, Index n_young,
                        const double* poisson, Index n_poisson, int /*method*/, double* data) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        double* e = data + TRI_FEM_DATA * i;
        const V3 pa = load(rest_x + 3 * t[0]), pb = load(rest_x + 3 * t[1]), pc = load(rest_x + 3 * t[2]);
        double r[9];
        triangle_rotation(pa, pb, pc, r);
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) e[3 * a + b] = r[3 * b + a];  // R^T
        const V3 b = mat_vec(r, sub(pb, pa)), c = mat_vec(r, sub(pc, pa));
        e[9] = b[0];
        e[10] = c[0];
        e[11] = c[1];
        strain_displacement(b, c, e + 12);
        const double area = b[0] * c[1] * 0.5;
        const double y = fem_detail::element_value(young, n_young, i), p = fem_detail::element_value(poisson, n_poisson, i);
        const double scale = (y / (1.0 - p * p)) * area;
        e[30] = 1 * scale;
        e[31] = p * scale;
        e[32] = p * scale;
        e[33] = 1 * scale;
        e[34] = ((1.0 - p) * 0.5) * scale;
    }
}

inline void trifem_add_force(const Index* tri, Index n, const double* x, double* f, double* data, int /*method*/) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        double* e = data + TRI_FEM_DATA * i;
        large_triangle_force(tri + 3 * i, x, f, e[9], e[10], e[11], e + 30, e, e + 12);
    }
}

// df += kfactor (df/dx) dx with the frames and J of the last force pass (SOFA's applyStiffnessLarge, h = 1).
inline void trifem_add_dforce(const Index* tri, Index n, const double* dx, double* df, double kfactor,
                              const double* data, int /*method*/) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const double* e = data + TRI_FEM_DATA * i;
        large_triangle_dforce(tri + 3 * i, dx, df, kfactor, e, e + 12, e + 30);
    }
}

// The positive stiffness of triangle e of TriangularFEMForceField, for assembled solvers.
inline void trifem_element_matrix(const double* data, Index e, int /*method*/, double* out) {
    const double* d = data + shell_detail::TRI_FEM_DATA * e;
    shell_detail::corotational_triangle_matrix(d, d + 12, d + 30, out);
}

// TriangleFEMForceField (SOFA's TriangleFEMForceField.inl with TriangleFEMUtils). Element data, 36
// doubles: rotation R^T (9), rest b_x, b_y, c_x, c_y (4), J (6x3), K00 K01 K10 K11 K22 (5).
// K = E/(1-nu^2) t A [[1, nu, 0], [nu, 1, 0], [0, 0, (1-nu)/2]] (plane stress) or
// E/((1+nu)(1-2nu)) t A [[1-nu, nu, 0], [nu, 1-nu, 0], [0, 0, 1/2-nu]] (plane strain), A the 3D
// area of the initial triangle. Large: as TriangularFEMForceField's, but the rest shape is
// R pB - R pA (SOFA rotates the points, then subtracts). Small (SOFA warns it is unvalidated): no
// rotation; the displacement and J are those of the in-plane x, y of the world frame, J from the
// current edges, forces along x and y only; J is zero until the first force pass (SOFA's init does not
// compute it). SOFA's getPotentialEnergy returns 0.
namespace shell_detail {
constexpr int TRIANGLE_FEM_DATA = 36;
constexpr int TF_ROT = 0, TF_REST = 9, TF_J = 13, TF_K = 31;
}  // namespace shell_detail

constexpr int triangle_fem_data_size(int /*method*/ = 1) { return shell_detail::TRIANGLE_FEM_DATA; }

inline void triangle_fem_init(const Index* tri, Index n, const double* initial_x, const double* young,
                              Index n_young, const double* poisson, Index n_poisson, double thickness,
                              bool plane_strain, int method, double* data) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        double* e = data + TRIANGLE_FEM_DATA * i;
        for (int k = 0; k < TRIANGLE_FEM_DATA; ++k) e[k] = 0.0;
        const V3 pa = load(initial_x + 3 * t[0]), pb = load(initial_x + 3 * t[1]), pc = load(initial_x + 3 * t[2]);
        if (method == FEM_SMALL) {  // initSmall
            for (int k = 0; k < 3; ++k) e[TF_ROT + 4 * k] = 1.0;
            const V3 b = sub(pb, pa), c = sub(pc, pa);
            e[TF_REST] = b[0];
            e[TF_REST + 1] = b[1];
            e[TF_REST + 2] = c[0];
            e[TF_REST + 3] = c[1];
        } else {  // initLarge
            double r[9];
            triangle_rotation(pa, pb, pc, r);
            for (int a = 0; a < 3; ++a)
                for (int k = 0; k < 3; ++k) e[TF_ROT + 3 * a + k] = r[3 * k + a];
            const V3 ra = mat_vec(r, pa);
            const V3 b = sub(mat_vec(r, pb), ra), c = sub(mat_vec(r, pc), ra);
            e[TF_REST] = b[0];
            e[TF_REST + 1] = b[1];
            e[TF_REST + 2] = c[0];
            e[TF_REST + 3] = c[1];
            strain_displacement(b, c, e + TF_J);
        }
        // computeMaterialStiffnesses
        const double p = fem_detail::element_value(poisson, n_poisson, i);
        const double E = fem_detail::element_value(young, n_young, i);
        const double one_minus_p = 1 - p;
        const double area = 0.5 * fem_detail::norm(cross(sub(pb, pa), sub(pc, pa)));
        const double volume = thickness * area;
        double* K = e + TF_K;
        if (plane_strain) {
            const double scale = E / ((1 + p) * (1 - 2 * p)) * volume;
            K[0] = one_minus_p * scale;
            K[1] = p * scale;
            K[2] = p * scale;
            K[3] = one_minus_p * scale;
            K[4] = (0.5 - p) * scale;
        } else {
            const double scale = E / (1 - p * p) * volume;
            K[0] = 1 * scale;
            K[1] = p * scale;
            K[2] = p * scale;
            K[3] = 1 * scale;
            K[4] = (0.5 * one_minus_p) * scale;
        }
    }
}

inline void triangle_fem_add_force(const Index* tri, Index n, const double* x, double* f, double* data, int method) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        double* e = data + TRIANGLE_FEM_DATA * i;
        if (method != FEM_SMALL) {
            large_triangle_force(t, x, f, e[TF_REST], e[TF_REST + 2], e[TF_REST + 3], e + TF_K, e + TF_ROT, e + TF_J);
            continue;
        }
        // accumulateForceSmall: world x, y; J from the current edges
        const V3 pa = load(x + 3 * t[0]);
        const V3 b = sub(load(x + 3 * t[1]), pa), c = sub(load(x + 3 * t[2]), pa);
        const double D[6] = {0, 0, e[TF_REST] - b[0], e[TF_REST + 1] - b[1], e[TF_REST + 2] - c[0],
                             e[TF_REST + 3] - c[1]};
        double F[6];
        strain_displacement(b, c, e + TF_J);
        local_forces(e + TF_J, e + TF_K, D, F);
        for (int node = 0; node < 3; ++node) {
            f[3 * t[node]] += F[2 * node];
            f[3 * t[node] + 1] += F[2 * node + 1];
            f[3 * t[node] + 2] += 0;
        }
    }
}

inline void triangle_fem_add_dforce(const Index* tri, Index n, const double* dx, double* df, double kfactor,
                                    const double* data, int method) {
    using namespace shell_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tri + 3 * i;
        const double* e = data + TRIANGLE_FEM_DATA * i;
        if (method != FEM_SMALL) {
            large_triangle_dforce(t, dx, df, kfactor, e + TF_ROT, e + TF_J, e + TF_K);
            continue;
        }
        // applyStiffnessSmall: the x, y of dx, h = 1
        double D[6], F[6];
        for (int node = 0; node < 3; ++node) {
            D[2 * node] = dx[3 * t[node]];
            D[2 * node + 1] = dx[3 * t[node] + 1];
        }
        local_forces(e + TF_J, e + TF_K, D, F);
        const double h = 1;
        for (int node = 0; node < 3; ++node) {
            df[3 * t[node]] += -h * F[2 * node] * kfactor;
            df[3 * t[node] + 1] += -h * F[2 * node + 1] * kfactor;
            df[3 * t[node] + 2] += 0 * kfactor;
        }
    }
}

// The positive stiffness of triangle e of TriangleFEMForceField (9x9, row-major, node-major).
inline void triangle_fem_element_matrix(const double* data, Index e, int /*method*/, double* out) {
    using namespace shell_detail;
    const double* d = data + TRIANGLE_FEM_DATA * e;
    corotational_triangle_matrix(d + TF_ROT, d + TF_J, d + TF_K, out);
}

// trifem_optim_element_matrix as assemble_elements calls it: the materials bound, per element.
struct TrifemOptimElementMatrix {
    const double* young;
    Index n_young;
    const double* poisson;
    Index n_poisson;

    void operator()(const double* data, Index e, int /*method*/, double* out) const {
        trifem_optim_element_matrix(data, e, young, n_young, poisson, n_poisson, out);
    }
};

}  // namespace sofac
