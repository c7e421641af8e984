// Mechanical loads (Sofa.Component.MechanicalLoad) in SOFA's order of operations.
//
// UniformVelocityDampingForceField: f -= v c; implicit: df -= dx (bfact c) (B = -c I).
//
// InteractionEllipsoidForceField (Vec3d points, Rigid3d frame): the
// points are brought into the frame of rigid DOF `frame` of object2 (q^-1 (p - c)), the nearest of
// the ellipsoids (smallest sum dp_j^2 / r_j^2) pushes a point that is inside it (for stiffness > 0)
// along the gradient g_j = dp_j / r_j^2 with intensity -|k| (|dp|_r - 1) / |g|, damped by
// damping |(|dp|_r - 1)| v; the force is rotated back. Each force pass stores, per point, whether it
// is in contact and the 3x3 local df/dx (SOFA's Contact::m), and the frame's quaternion, for the
// derivative passes. Only object1 receives forces (object2_forces = false).
// ellipsoids: per ellipsoid, centre (3) and 1/r^2 (3).
#pragma once

#include <cmath>

#include "types.h"

namespace sofac {

namespace ellipsoid_detail {
// SOFA's Quat::rotate / inverseRotate: t = 2 (q x v); v + w t + q x t (q negated for the inverse).
inline void quat_rotate(const double* q, bool inverse, const double* v, double* out) {
    const double s = inverse ? -1.0 : 1.0;
    const double qx = q[0] * s, qy = q[1] * s, qz = q[2] * s, w = q[3];
    const double t0 = (qy * v[2] - qz * v[1]) * 2, t1 = (qz * v[0] - qx * v[2]) * 2, t2 = (qx * v[1] - qy * v[0]) * 2;
    out[0] = v[0] + w * t0 + (qy * t2 - qz * t1);
    out[1] = v[1] + w * t1 + (qz * t0 - qx * t2);
    out[2] = v[2] + w * t2 + (qx * t1 - qy * t0);
}
}  // namespace ellipsoid_detail

// contacts: per point 10 doubles (flag, m row-major); frame_q: 4 doubles (the quaternion used).
inline void ellipsoid_add_force(const double* x1, const double* v1, double* f1, Index n, const double* x2,
                                Index frame, const double* ellipsoids, Index n_ellipsoids, double stiffness,
                                double damping, double* contacts, double* frame_q) {
    using ellipsoid_detail::quat_rotate;
    const double* c = x2 + 7 * frame;
    const double q[4] = {c[3], c[4], c[5], c[6]};
    for (int k = 0; k < 4; ++k) frame_q[k] = q[k];
    const double stiffabs = std::fabs(stiffness);
    for (Index i = 0; i < n; ++i) {
        double* contact = contacts + 10 * i;
        contact[0] = 0.0;
        double rel[3], p[3], v[3];
        for (int d = 0; d < 3; ++d) rel[d] = x1[3 * i + d] - c[d];
        quat_rotate(q, true, rel, p);
        quat_rotate(q, true, v1 + 3 * i, v);
        double best_dp[3] = {0.0, 0.0, 0.0}, best = -1.0;
        Index be = -1;
        for (Index e = 0; e < n_ellipsoids; ++e) {
            const double* ell = ellipsoids + 6 * e;
            double dp[3];
            for (int d = 0; d < 3; ++d) dp[d] = p[d] - ell[d];
            double norm2 = 0.0;
            for (int d = 0; d < 3; ++d) norm2 += (dp[d] * dp[d]) * ell[3 + d];
            if (be == -1 || norm2 < best) {
                best = norm2;
                be = e;
                for (int d = 0; d < 3; ++d) best_dp[d] = dp[d];
            }
        }
        if (!((best - 1) * stiffness < 0)) continue;
        const double* inv_r2 = ellipsoids + 6 * be + 3;
        const double norm = std::sqrt(best);
        const double value = norm - 1;
        double grad[3];
        for (int d = 0; d < 3; ++d) grad[d] = best_dp[d] * inv_r2[d];
        const double gnorm2 = grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2];
        const double gnorm = std::sqrt(gnorm2);
        const double force_intensity = -stiffabs * value / gnorm;
        const double damping_intensity = damping * std::fabs(value);
        double local[3];
        for (int d = 0; d < 3; ++d) local[d] = grad[d] * force_intensity - v[d] * damping_intensity;
        const double fact1 = -stiffabs / (norm * gnorm);
        const double fact2 = -stiffabs * value / gnorm;
        const double fact3 = -stiffabs * value / gnorm2;
        contact[0] = 1.0;
        for (int a = 0; a < 3; ++a) {
            for (int b = 0; b < 3; ++b) contact[1 + 3 * a + b] = grad[a] * grad[b] * (fact1 + fact3 * inv_r2[b]);
            contact[1 + 4 * a] += fact2 * inv_r2[a];
        }
        double world[3];
        quat_rotate(q, false, local, world);
        for (int d = 0; d < 3; ++d) f1[3 * i + d] += world[d];
    }
}

// df1 += kfactor R m R^-1 dx1 for the points in contact at the last force pass.
inline void ellipsoid_add_dforce(const double* dx1, double* df1, Index n, const double* contacts,
                                 const double* frame_q, double kfactor) {
    using ellipsoid_detail::quat_rotate;
    for (Index i = 0; i < n; ++i) {
        const double* contact = contacts + 10 * i;
        if (contact[0] == 0.0) continue;
        double local[3], force[3], world[3];
        quat_rotate(frame_q, true, dx1 + 3 * i, local);
        for (int a = 0; a < 3; ++a) {
            const double* m = contact + 1 + 3 * a;
            force[a] = (m[0] * local[0] + m[1] * local[1] + m[2] * local[2]) * kfactor;
        }
        quat_rotate(frame_q, false, force, world);
        for (int d = 0; d < 3; ++d) df1[3 * i + d] += world[d];
    }
}

inline void velocity_damping_force(double* f, const double* v, Index n_scalars, double c) {
    for (Index i = 0; i < n_scalars; ++i) f[i] -= v[i] * c;
}

inline void velocity_damping_dforce(double* df, const double* dx, Index n_scalars, double c, double bfact) {
    if (bfact == 0.0) return;
    const double b = bfact * c;
    for (Index i = 0; i < n_scalars; ++i) df[i] -= dx[i] * b;
}

}  // namespace sofac
