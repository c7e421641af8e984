// Beams between rigid frames: BeamFEMForceField (Rigid3d), BeamLinearMapping (Rigid3d -> Vec3d)
// and BTDLinearSolver's block-tridiagonal solve (6x6 blocks), as SOFA computes them.
//
// Quaternions are stored (x y z w), as in Rigid3d coordinates. The helpers below follow SOFA's
// type::Quat operation by operation (rotate, inverse, product, normalize, quatToRotationVector),
// so that the forces come out with SOFA's rounding, not Eigen's.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "assembly.h"
#include "types.h"

namespace sofac {
namespace beamq {

struct Q {
    double x, y, z, w;
};
struct V3 {
    double x, y, z;
};

inline Q load(const double* q) { return {q[0], q[1], q[2], q[3]}; }
inline V3 cross(const V3& a, const V3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline V3 add(const V3& a, const V3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 sub(const V3& a, const V3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 scale(const V3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }

// Quat::rotate: v + w t + q_xyz x t, t = 2 q_xyz x v (the quaternion used as stored).
inline V3 rotate(const Q& q, const V3& v) {
    const V3 u{q.x, q.y, q.z};
    const V3 t = scale(cross(u, v), 2.0);
    return add(add(v, scale(t, q.w)), cross(u, t));
}
// Quat::inverseRotate: the same with -q_xyz.
inline V3 inverse_rotate(const Q& q, const V3& v) {
    const V3 u{-q.x, -q.y, -q.z};
    const V3 t = scale(cross(u, v), 2.0);
    return add(add(v, scale(t, q.w)), cross(u, t));
}
// Quat::operator* (Hamilton product a b).
inline Q product(const Q& a, const Q& b) {
    Q r;
    r.w = a.w * b.w - (a.x * b.x + a.y * b.y + a.z * b.z);
    r.x = a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y;
    r.y = a.w * b.y + a.y * b.w + a.z * b.x - a.x * b.z;
    r.z = a.w * b.z + a.z * b.w + a.x * b.y - a.y * b.x;
    return r;
}
// Quat::inverse: the conjugate divided by the norm.
inline Q inverse(const Q& q) {
    double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    if (norm == 0.0) return {0.0, 0.0, 0.0, 0.0};
    norm = 1.0 / norm;
    return {-q.x * norm, -q.y * norm, -q.z * norm, q.w * norm};
}
// Quat::normalize: only when the squared norm is more than 1e-10 away from 1.
inline Q normalized(Q q) {
    const double mag = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
    if (std::abs(mag - 1.0) > 1.0e-10) {
        if (mag != 0.0) {
            const double s = 1.0 / std::sqrt(mag);
            q.x *= s;
            q.y *= s;
            q.z *= s;
            q.w *= s;
        } else {
            q.w = 1.0;
        }
    }
    return q;
}
// BeamFEMForceField's qDiff(a, b): b^-1 a, with a negated first when a.b < 0.
inline Q qdiff(Q a, const Q& b) {
    if (a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w < 0) a = {-a.x, -a.y, -a.z, -a.w};
    return product(inverse(b), a);
}
// Quat::quatToRotationVector: axis times angle, the angle in [0, 2 pi].
inline V3 rotation_vector(Q q) {
    q = normalized(q);
    if (q.w < 0) q = {-q.x, -q.y, -q.z, -q.w};
    double sin_half, angle;
    if (q.w > 0.999) {  // small angles: asin, not acos (SOFA's guard)
        sin_half = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
        angle = 2.0 * std::asin(sin_half);
    } else {
        const double half = std::acos(q.w);
        sin_half = std::sin(half);
        angle = 2 * half;
    }
    if (sin_half < std::numeric_limits<double>::epsilon()) return {0.0, 0.0, 0.0};
    return {q.x / sin_half * angle, q.y / sin_half * angle, q.z / sin_half * angle};
}
// Quat::toMatrix (row-major 3x3).
inline void to_matrix(const Q& q, double* m) {
    m[0] = 1 - 2 * (q.y * q.y + q.z * q.z);
    m[1] = 2 * (q.x * q.y - q.z * q.w);
    m[2] = 2 * (q.z * q.x + q.y * q.w);
    m[3] = 2 * (q.x * q.y + q.z * q.w);
    m[4] = 1 - 2 * (q.z * q.z + q.x * q.x);
    m[5] = 2 * (q.y * q.z - q.x * q.w);
    m[6] = 2 * (q.z * q.x - q.y * q.w);
    m[7] = 2 * (q.y * q.z + q.x * q.w);
    m[8] = 1 - 2 * (q.y * q.y + q.x * q.x);
}
inline V3 center_of(const double* x, Index i) { return {x[7 * i], x[7 * i + 1], x[7 * i + 2]}; }
inline Q quat_of(const double* x, Index i) { return load(x + 7 * i + 3); }

}  // namespace beamq

// Per beam: the 12x12 local stiffness (row-major) and its frame (the quaternion of node a, x y z w).
constexpr int BEAM_STIFFNESS_SIZE = 144;
constexpr int BEAM_FRAME_SIZE = 4;

// BeamFEMForceField::BeamInfo::init and computeStiffness: a circular (hollow) section of radius r
// (inner radius r_in), E and nu of the element, length L = |c_b - c_a| at rest. SOFA sets the shear
// areas As_y = As_z = 0, so phi_y = phi_z = 0 (Euler-Bernoulli); the Timoshenko terms are kept,
// written as SOFA writes them. edges: (a, b) per beam; young, poisson: one value per beam, or one
// for all (SOFA's getYoungModulusInElement: element e's if there are more than e, else the first).
inline void beam_fem_init(const Index* edges, Index n, const double* x0, const double* young, Index n_young,
                          const double* poisson, Index n_poisson, double r, double r_inner, double* kloc,
                          double* frames) {
    const double pi = M_PI;
    for (Index e = 0; e < n; ++e) {
        const Index a = edges[2 * e], b = edges[2 * e + 1];
        const beamq::V3 d = beamq::sub(beamq::center_of(x0, a), beamq::center_of(x0, b));
        const double L = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
        const double E = young[n_young > e ? e : 0], nu = poisson[n_poisson > e ? e : 0];
        const double G = E / (2.0 * (1.0 + nu));
        const double Iz = pi * (r * r * r * r - r_inner * r_inner * r_inner * r_inner) / 4.0;
        const double Iy = Iz, J = Iz + Iy;
        const double A = pi * (r * r - r_inner * r_inner);
        const double Asy = 0.0, Asz = 0.0;
        const double L2 = L * L, L3 = L2 * L, EIy = E * Iy, EIz = E * Iz;
        const double phiy = Asy == 0 ? 0.0 : 24.0 * (1.0 + nu) * Iz / (Asy * L2);
        const double phiz = Asz == 0 ? 0.0 : 24.0 * (1.0 + nu) * Iy / (Asz * L2);
        double* k = kloc + BEAM_STIFFNESS_SIZE * e;
        auto K = [k](int i, int j) -> double& { return k[12 * i + j]; };
        for (int i = 0; i < BEAM_STIFFNESS_SIZE; ++i) k[i] = 0.0;
        K(6, 6) = K(0, 0) = E * A / L;
        K(7, 7) = K(1, 1) = 12.0 * EIz / (L3 * (1.0 + phiy));
        K(8, 8) = K(2, 2) = 12.0 * EIy / (L3 * (1.0 + phiz));
        K(9, 9) = K(3, 3) = G * J / L;
        K(10, 10) = K(4, 4) = (4.0 + phiz) * EIy / (L * (1.0 + phiz));
        K(11, 11) = K(5, 5) = (4.0 + phiy) * EIz / (L * (1.0 + phiy));
        K(4, 2) = -6.0 * EIy / (L2 * (1.0 + phiz));
        K(5, 1) = 6.0 * EIz / (L2 * (1.0 + phiy));
        K(6, 0) = -K(0, 0);
        K(7, 1) = -K(1, 1);
        K(7, 5) = -K(5, 1);
        K(8, 2) = -K(2, 2);
        K(8, 4) = -K(4, 2);
        K(9, 3) = -K(3, 3);
        K(10, 2) = K(4, 2);
        K(10, 4) = (2.0 - phiz) * EIy / (L * (1.0 + phiz));
        K(10, 8) = -K(4, 2);
        K(11, 1) = K(5, 1);
        K(11, 5) = (2.0 - phiy) * EIz / (L * (1.0 + phiy));
        K(11, 7) = -K(5, 1);
        for (int i = 0; i <= 10; ++i)
            for (int j = i + 1; j < 12; ++j) K(i, j) = K(j, i);
        // Before the first force pass the frame is node a's (initLarge at rest for aligned frames).
        const beamq::Q q = beamq::normalized(beamq::quat_of(x0, a));
        double* frame = frames + BEAM_FRAME_SIZE * e;
        frame[0] = q.x, frame[1] = q.y, frame[2] = q.z, frame[3] = q.w;
    }
}

// BeamFEMForceField::addForce (accumulateForceLarge per beam, in element order): in node a's frame,
// the displacement of b's centre from rest and the rotation vector of (q0_a^-1 q0_b)^-1 (q_a^-1 q_b);
// f = K_loc d (a's own displacement is zero), rotated back by q_a and subtracted. The beam's frame,
// normalised q_a, is kept for the K dx products and the assembled matrix of this step.
inline void beam_fem_add_force(const Index* edges, const Index* elements, Index n, const double* kloc,
                               const double* x0, const double* x, double* f, double* frames) {
    using namespace beamq;
    for (Index k = 0; k < n; ++k) {
        const Index e = elements[k];
        const Index a = edges[2 * e], b = edges[2 * e + 1];
        const Q qa = quat_of(x, a), qb = quat_of(x, b);
        const Q q = normalized(qa);
        double* frame = frames + BEAM_FRAME_SIZE * e;
        frame[0] = q.x, frame[1] = q.y, frame[2] = q.z, frame[3] = q.w;
        const Q q0a = quat_of(x0, a), q0b = quat_of(x0, b);
        const V3 rest = inverse_rotate(q0a, sub(center_of(x0, b), center_of(x0, a)));
        const V3 now = inverse_rotate(qa, sub(center_of(x, b), center_of(x, a)));
        const V3 u = sub(now, rest);
        const Q dq0 = normalized(qdiff(q0b, q0a));
        const Q dq = normalized(qdiff(qb, qa));
        const V3 w = rotation_vector(normalized(qdiff(dq, dq0)));
        const double depl[12] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, u.x, u.y, u.z, w.x, w.y, w.z};
        const double* K = kloc + BEAM_STIFFNESS_SIZE * e;
        double force[12];
        for (int i = 0; i < 12; ++i) {
            double sum = 0.0;
            for (int j = 0; j < 12; ++j) sum += K[12 * i + j] * depl[j];
            force[i] = sum;
        }
        for (int part = 0; part < 4; ++part) {
            const V3 g = rotate(qa, V3{force[3 * part], force[3 * part + 1], force[3 * part + 2]});
            double* out = f + 6 * (part < 2 ? a : b) + 3 * (part % 2);
            out[0] += -g.x;
            out[1] += -g.y;
            out[2] += -g.z;
        }
    }
}

// BeamFEMForceField::addDForce (applyStiffnessLarge): df += -R K_loc R^T dx kfact per beam, R the
// beam's frame of the last force pass.
inline void beam_fem_add_dforce(const Index* edges, const Index* elements, Index n, const double* kloc,
                                const double* frames, const double* dx, double* df, double kfact) {
    using namespace beamq;
    for (Index k = 0; k < n; ++k) {
        const Index e = elements[k];
        const Index a = edges[2 * e], b = edges[2 * e + 1];
        const Q q = normalized(load(frames + BEAM_FRAME_SIZE * e));
        double local[12];
        for (int part = 0; part < 4; ++part) {
            const double* in = dx + 6 * (part < 2 ? a : b) + 3 * (part % 2);
            const V3 u = inverse_rotate(q, V3{in[0], in[1], in[2]});
            local[3 * part] = u.x, local[3 * part + 1] = u.y, local[3 * part + 2] = u.z;
        }
        const double* K = kloc + BEAM_STIFFNESS_SIZE * e;
        double force[12];
        for (int i = 0; i < 12; ++i) {
            double sum = 0.0;
            for (int j = 0; j < 12; ++j) sum += K[12 * i + j] * local[j];
            force[i] = sum;
        }
        for (int part = 0; part < 4; ++part) {
            const V3 g = rotate(q, V3{force[3 * part], force[3 * part + 1], force[3 * part + 2]});
            double* out = df + 6 * (part < 2 ? a : b) + 3 * (part % 2);
            out[0] += -g.x * kfact;
            out[1] += -g.y * kfact;
            out[2] += -g.z * kfact;
        }
    }
}

// The 12x12 world stiffness R K_loc R^T of a beam, block by 3x3 block as SOFA's addKToMatrix /
// buildStiffnessMatrix (with useSymmetricAssembly, the upper blocks mirrored and the diagonal
// blocks halved after their double addition).
inline void beam_fem_world_stiffness(const double* K0, const double* frame, bool symmetric, double* K) {
    double R[9];
    beamq::to_matrix(beamq::normalized(beamq::load(frame)), R);
    for (int i = 0; i < 144; ++i) K[i] = 0.0;
    auto rotated = [&](int x1, int y1, double* m) {
        double t[9];  // R m
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                t[3 * i + j] = R[3 * i] * K0[12 * (x1) + y1 + j] + R[3 * i + 1] * K0[12 * (x1 + 1) + y1 + j] +
                               R[3 * i + 2] * K0[12 * (x1 + 2) + y1 + j];
        for (int i = 0; i < 3; ++i)  // (R m) R^T
            for (int j = 0; j < 3; ++j)
                m[3 * i + j] = t[3 * i] * R[3 * j] + t[3 * i + 1] * R[3 * j + 1] + t[3 * i + 2] * R[3 * j + 2];
    };
    for (int x1 = 0; x1 < 12; x1 += 3)
        for (int y1 = symmetric ? x1 : 0; y1 < 12; y1 += 3) {
            double m[9];
            rotated(x1, y1, m);
            if (!symmetric) {
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) K[12 * (x1 + i) + y1 + j] = m[3 * i + j];
                continue;
            }
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) {
                    K[12 * (x1 + i) + y1 + j] += m[3 * i + j];
                    K[12 * (y1 + j) + x1 + i] += m[3 * i + j];
                }
            if (x1 == y1)
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) K[12 * (x1 + i) + y1 + j] *= 0.5;
        }
}

// The beams' share of the assembled matrix: -K kfact at the rows and columns of a and b.
inline void assemble_beam_fem(Assembler& A, Index offset, const Index* edges, const Index* elements, Index n,
                              const double* kloc, const double* frames, Index symmetric, double kfact) {
    for (Index k = 0; k < n; ++k) {
        const Index e = elements[k];
        double K[144];
        beam_fem_world_stiffness(kloc + BEAM_STIFFNESS_SIZE * e, frames + BEAM_FRAME_SIZE * e, symmetric != 0, K);
        Index index[12];
        for (int i = 0; i < 6; ++i) {
            index[i] = offset + 6 * edges[2 * e] + i;
            index[6 + i] = offset + 6 * edges[2 * e + 1] + i;
        }
        for (int i = 0; i < 12; ++i)
            for (int j = 0; j < 12; ++j) A.add(index[i], index[j], -K[12 * i + j] * kfact);
    }
}

// BeamLinearMapping (Rigid3d -> Vec3d). Per point, from compile time: the first frame in0 of its
// beam, its coordinates p (p_x reduced to [0, 1] along the beam, p_y, p_z as given) and the beam's
// length L. apply: r0 = R_in0 p L, r1 = R_in1 (p - e_x) L, x = (c0 + r0)(1 - s) + (c1 + r1) s with
// s = 3 p_x^2 - 2 p_x^3; r0 and r1 are kept for J and J^T (rotated: 6 per point).
inline void beam_linear_apply(const double* in_x, double* out_x, const Index* frame, const double* local,
                              const double* length, double* rotated, Index n) {
    using namespace beamq;
    for (Index i = 0; i < n; ++i) {
        const Index a = frame[i];
        const V3 p{local[3 * i], local[3 * i + 1], local[3 * i + 2]};
        const V3 r0 = scale(rotate(quat_of(in_x, a), p), length[i]);
        const V3 r1 = scale(rotate(quat_of(in_x, a + 1), V3{p.x - 1, p.y, p.z}), length[i]);
        const V3 out0 = add(center_of(in_x, a), r0), out1 = add(center_of(in_x, a + 1), r1);
        double s = p.x;
        s = 3 * (s * s) - 2 * (s * s * s);
        const V3 out = add(scale(out0, 1 - s), scale(out1, s));
        out_x[3 * i] = out.x, out_x[3 * i + 1] = out.y, out_x[3 * i + 2] = out.z;
        double* r = rotated + 6 * i;
        r[0] = r0.x, r[1] = r0.y, r[2] = r0.z, r[3] = r1.x, r[4] = r1.y, r[5] = r1.z;
    }
}

// applyJ: v = (v0 - r0 x w0)(1 - s) + (v1 - r1 x w1) s.
inline void beam_linear_apply_j(const double* in_v, double* out_v, const Index* frame, const double* local,
                                const double* rotated, Index n) {
    using namespace beamq;
    for (Index i = 0; i < n; ++i) {
        const Index a = frame[i];
        const double* r = rotated + 6 * i;
        const double* v0 = in_v + 6 * a;
        const double* v1 = in_v + 6 * (a + 1);
        const V3 out0 = sub(V3{v0[0], v0[1], v0[2]}, cross(V3{r[0], r[1], r[2]}, V3{v0[3], v0[4], v0[5]}));
        const V3 out1 = sub(V3{v1[0], v1[1], v1[2]}, cross(V3{r[3], r[4], r[5]}, V3{v1[3], v1[4], v1[5]}));
        double s = local[3 * i];
        s = 3 * (s * s) - 2 * (s * s * s);
        const V3 out = add(scale(out0, 1 - s), scale(out1, s));
        out_v[3 * i] = out.x, out_v[3 * i + 1] = out.y, out_v[3 * i + 2] = out.z;
    }
}

// applyJT: f_0 += f (1 - s), tau_0 += (r0 x f)(1 - s); f_1 += f s, tau_1 += (r1 x f) s.
inline void beam_linear_apply_jt(double* in_f, const double* out_f, const Index* frame, const double* local,
                                 const double* rotated, Index n) {
    using namespace beamq;
    for (Index i = 0; i < n; ++i) {
        const Index a = frame[i];
        const double* r = rotated + 6 * i;
        const V3 f{out_f[3 * i], out_f[3 * i + 1], out_f[3 * i + 2]};
        double s = local[3 * i];
        s = 3 * (s * s) - 2 * (s * s * s);
        const V3 parts[4] = {scale(f, 1 - s), scale(cross(V3{r[0], r[1], r[2]}, f), 1 - s), scale(f, s),
                             scale(cross(V3{r[3], r[4], r[5]}, f), s)};
        for (int k = 0; k < 4; ++k) {
            double* out = in_f + 6 * (a + k / 2) + 3 * (k % 2);
            out[0] += parts[k].x;
            out[1] += parts[k].y;
            out[2] += parts[k].z;
        }
    }
}

// J's rows for the assembled matrix: per point and axis, (1 - s) [e_d, (r0 x .)_d] on frame in0 and
// s [e_d, (r1 x .)_d] on frame in0 + 1 (v_d = ... + (w x r)_d).
inline void beam_linear_jacobian(Assembler& A, Index child, Index parent, const Index* frame, const double* local,
                                 const double* rotated, Index n) {
    for (Index i = 0; i < n; ++i) {
        double s = local[3 * i];
        s = 3 * (s * s) - 2 * (s * s * s);
        const double* r = rotated + 6 * i;
        for (int d = 0; d < 3; ++d) {
            Index columns[6];
            double weights[6];
            for (int side = 0; side < 2; ++side) {
                const Index c = parent + 6 * (frame[i] + side);
                const double* rr = r + 3 * side;
                const double w = side == 0 ? 1 - s : s;
                // (w x r)_d = w_{d+1} r_{d+2} - w_{d+2} r_{d+1}
                const int d1 = (d + 1) % 3, d2 = (d + 2) % 3;
                columns[3 * side] = c + d;
                weights[3 * side] = w;
                columns[3 * side + 1] = c + 3 + d1;
                weights[3 * side + 1] = rr[d2] * w;
                columns[3 * side + 2] = c + 3 + d2;
                weights[3 * side + 2] = -rr[d1] * w;
            }
            A.jacobian_row(child + 3 * i + d, 6, columns, weights);
        }
    }
}

// BTDLinearSolver on BTDMatrix6d: the Thomas algorithm on 6x6 blocks, as SOFA's invert and solve.
// Block row i holds B_i = A(i, i-1), the diagonal D_i and C_i = A(i, i+1):
//   alpha_0^-1 = D_0^-1, lambda_0 = alpha_0^-1 C_0,
//   alpha_i^-1 = (D_i - B_i lambda_{i-1})^-1, lambda_i = alpha_i^-1 C_i;
//   x_0 = alpha_0^-1 b_0, x_i = alpha_i^-1 (b_i - B_i x_{i-1}); x_i -= lambda_i x_{i+1} backwards.
struct Block6 {
    double m[36];
    double& operator()(int i, int j) { return m[6 * i + j]; }
    double operator()(int i, int j) const { return m[6 * i + j]; }
};

inline Block6 btd_product(const Block6& a, const Block6& b) {
    Block6 r{};
    for (int i = 0; i < 6; ++i)
        for (int k = 0; k < 6; ++k) {
            const double aik = a(i, k);
            for (int j = 0; j < 6; ++j) r(i, j) += aik * b(k, j);
        }
    return r;
}

inline void btd_multiply(const Block6& a, const double* v, double* out) {
    for (int i = 0; i < 6; ++i) {
        double sum = a(i, 0) * v[0];
        for (int j = 1; j < 6; ++j) sum += a(i, j) * v[j];
        out[i] = sum;
    }
}

// sofa::type::invertMatrix: Gauss-Jordan with full pivoting (false on a zero pivot).
inline bool btd_gauss_jordan(Block6& dest, const Block6& from) {
    Block6 m1 = from, m2{};
    for (int i = 0; i < 6; ++i) m2(i, i) = 1.0;
    int r[6] = {}, c[6] = {}, row[6] = {}, col[6] = {};
    for (int k = 0; k < 6; ++k) {
        double pivot = 0;
        for (int i = 0; i < 6; ++i) {
            if (row[i]) continue;
            for (int j = 0; j < 6; ++j) {
                if (col[j]) continue;
                double t = m1(i, j);
                if (t < 0) t = -t;
                if (t > pivot) {
                    pivot = t;
                    r[k] = i;
                    c[k] = j;
                }
            }
        }
        if (std::abs(pivot) < std::numeric_limits<double>::epsilon()) return false;  // equalsZero
        row[r[k]] = col[c[k]] = 1;
        pivot = m1(r[k], c[k]);
        for (int j = 0; j < 6; ++j) m1(r[k], j) /= pivot;
        m1(r[k], c[k]) = 1;
        for (int j = 0; j < 6; ++j) m2(r[k], j) /= pivot;
        for (int i = 0; i < 6; ++i) {
            if (i == r[k]) continue;
            const double f = m1(i, c[k]);
            for (int j = 0; j < 6; ++j) m1(i, j) -= m1(r[k], j) * f;
            m1(i, c[k]) = 0;
            for (int j = 0; j < 6; ++j) m2(i, j) -= m2(r[k], j) * f;
        }
    }
    for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 6; ++j)
            if (c[j] == i) row[i] = r[j];
    for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 6; ++j) dest(i, j) = m2(row[i], j);
    return true;
}

// BTDLinearSolver::invert(SubMatrix&, const BlocType&): the leading rows whose entries right of
// the diagonal are below 1e-10 times it are inverted as a diagonal; if every row is, the inverse is
// that diagonal; otherwise the whole block goes through Gauss-Jordan.
inline bool btd_invert(Block6& inv, const Block6& m) {
    inv = Block6{};
    int i0 = 0;
    while (i0 < 6) {
        int j0 = i0 + 1;
        const double eps = m(i0, i0) * 1.0e-10;
        while (j0 < 6)
            if (std::fabs(m(i0, j0)) > eps) break;
            else ++j0;
        if (j0 != 6) break;
        inv(i0, i0) = 1.0 / m(i0, i0);
        ++i0;
    }
    if (i0 < 6) return btd_gauss_jordan(inv, m);
    return true;
}

struct BlockTridiagonal {
    Index blocks = 0;
    // BTDMatrix's storage: block row i holds B_i, D_i and C_i at band[3 i], band[3 i + 1] and
    // band[3 i + 2].
    std::vector<Block6> band;
    std::vector<Block6> alpha_inv, lambda;
    // Entries of the last assembly on a row past the matrix: SOFA writes them past its blocks
    // (undefined behaviour, nothing to reproduce), so the solve fails (NaN) rather than guess.
    Index overflows = 0;
    bool ok = true;

    void resize(Index n) {
        blocks = n;
        const auto size = static_cast<std::size_t>(n);
        band.assign(3 * size, Block6{});
        alpha_inv.assign(size, Block6{});
        lambda.assign(size, Block6{});
    }

    // BTDMatrix::add: an entry right of the band is dropped; one left of it lands at the block
    // index 3 bi + (bj - bi + 1), which is then another block of the band (SOFA checks only the
    // right side). Entries inside the band (all that sofac's planner lets beams make) add in place.
    void add(Index row, Index col, double value) {
        const Index bi = row / 6, offset = col / 6 - bi + 1;
        if (offset >= 3) return;
        if (bi >= blocks) {
            ++overflows;
            return;
        }
        band[static_cast<std::size_t>(3 * bi + offset)](static_cast<int>(row % 6), static_cast<int>(col % 6)) += value;
    }

    void clear() {
        std::fill(band.begin(), band.end(), Block6{});
        overflows = 0;
    }

    // A sparse matrix of the same size added, entry by entry through add().
    void add_matrix(const Eigen::SparseMatrix<double>& matrix) {
        for (int col = 0; col < matrix.outerSize(); ++col)
            for (Eigen::SparseMatrix<double>::InnerIterator it(matrix, col); it; ++it) add(it.row(), it.col(), it.value());
    }

    // MatrixLinearSystem's projection of each constrained scalar DOF r (Dirichlet::discardRowCol):
    // BTDMatrix::clearRowCol(r), which clears row r and column r inside the band only, then 1 at (r, r).
    void project(const std::vector<char>& fixed) {
        for (Index r = 0; r < 6 * blocks; ++r) {
            if (!fixed[static_cast<std::size_t>(r)]) continue;
            const Index b = r / 6;
            const int i = static_cast<int>(r % 6);
            for (Index k = 3 * b; k < 3 * b + 3; ++k)
                for (int j = 0; j < 6; ++j) band[static_cast<std::size_t>(k)](i, j) = 0.0;
            for (const Index k : {3 * (b - 1) + 2, 3 * b + 1, 3 * (b + 1)})
                if (k >= 0 && k < 3 * blocks)
                    for (int j = 0; j < 6; ++j) band[static_cast<std::size_t>(k)](j, i) = 0.0;
            band[static_cast<std::size_t>(3 * b + 1)](i, i) = 1.0;
        }
    }

    void factor() {
        ok = overflows == 0;
        if (blocks == 0) return;
        ok = btd_invert(alpha_inv[0], diagonal(0)) && ok;
        if (blocks > 1) lambda[0] = btd_product(alpha_inv[0], upper(0));
        for (Index i = 1; i < blocks; ++i) {
            const Block6 t1 = btd_product(lower(i), lambda[i - 1]);
            Block6 t2;
            for (int k = 0; k < 36; ++k) t2.m[k] = diagonal(i).m[k] - t1.m[k];
            ok = btd_invert(alpha_inv[i], t2) && ok;
            if (i < blocks - 1) lambda[i] = btd_product(alpha_inv[i], upper(i));
        }
    }

    void solve(const double* b, double* x) {
        if (!ok) {
            for (Index k = 0; k < 6 * blocks; ++k) x[k] = std::numeric_limits<double>::quiet_NaN();
            return;
        }
        if (blocks == 0) return;
        btd_multiply(alpha_inv[0], b, x);
        double t[6], u[6];
        for (Index i = 1; i < blocks; ++i) {
            btd_multiply(lower(i), x + 6 * (i - 1), t);
            for (int k = 0; k < 6; ++k) u[k] = b[6 * i + k] - t[k];
            btd_multiply(alpha_inv[i], u, x + 6 * i);
        }
        for (Index i = blocks - 2; i >= 0; --i) {
            btd_multiply(lambda[i], x + 6 * (i + 1), t);
            for (int k = 0; k < 6; ++k) x[6 * i + k] -= t[k];
        }
    }

    const Block6& lower(Index i) const { return band[static_cast<std::size_t>(3 * i)]; }
    const Block6& diagonal(Index i) const { return band[static_cast<std::size_t>(3 * i + 1)]; }
    const Block6& upper(Index i) const { return band[static_cast<std::size_t>(3 * i + 2)]; }
};

}  // namespace sofac
