// SOFA's quaternion arithmetic (sofa::type::Quat, stored x y z w), written out so that the
// operations and their order are SOFA's (Quat.h / Quat.inl at the corpus commit): products,
// inverse, normalize, rotate / inverseRotate, quatToAxis, toMatrix, createQuaterFromEuler, slerp2.
// Kernels that must reproduce SOFA's digits use these rather than Eigen's quaternions.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

namespace sofac {

// Quat::rotate / inverseRotate on raw arrays: t = 2 (q x v); v + w t + q x t (q's vector part
// negated for the inverse).
inline void quat_rotate(const double* q, bool inverse, const double* v, double* out) {
    const double s = inverse ? -1.0 : 1.0;
    const double qx = q[0] * s, qy = q[1] * s, qz = q[2] * s, w = q[3];
    const double t0 = (qy * v[2] - qz * v[1]) * 2, t1 = (qz * v[0] - qx * v[2]) * 2, t2 = (qx * v[1] - qy * v[0]) * 2;
    out[0] = v[0] + w * t0 + (qy * t2 - qz * t1);
    out[1] = v[1] + w * t1 + (qz * t0 - qx * t2);
    out[2] = v[2] + w * t2 + (qx * t1 - qy * t0);
}

struct SofaQuat {
    double q[4];

    static SofaQuat load(const double* p) { return {{p[0], p[1], p[2], p[3]}}; }

    SofaQuat operator*(const SofaQuat& b) const {
        return {{q[3] * b.q[0] + q[0] * b.q[3] + q[1] * b.q[2] - q[2] * b.q[1],
                 q[3] * b.q[1] + q[1] * b.q[3] + q[2] * b.q[0] - q[0] * b.q[2],
                 q[3] * b.q[2] + q[2] * b.q[3] + q[0] * b.q[1] - q[1] * b.q[0],
                 q[3] * b.q[3] - (q[0] * b.q[0] + q[1] * b.q[1] + q[2] * b.q[2])}};
    }
    // Quat::inverse: the conjugate divided by the norm (not its square, as SOFA's).
    SofaQuat inverse() const {
        double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (norm == 0.0) return {{0.0, 0.0, 0.0, 0.0}};
        norm = 1.0 / norm;
        return {{-q[0] * norm, -q[1] * norm, -q[2] * norm, q[3] * norm}};
    }
    // Quat::normalize: only when the squared norm differs from 1 by more than 1e-10.
    void normalize() {
        const double magnitude = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
        if (std::abs(magnitude - 1.0) <= 1e-10) return;
        if (magnitude == 0.0) {
            q[3] = 1.0;
            return;
        }
        const double scale = 1.0 / std::sqrt(magnitude);
        for (double& c : q) c *= scale;
    }
    // Quat::toEulerVector: roll, pitch, yaw of the normalized quaternion (pitch's sine clamped).
    void to_euler_vector(double* out) const {
        SofaQuat p = *this;
        p.normalize();
        const double* a = p.q;
        const double y = std::max(-1.0, std::min(1.0, 2. * (a[3] * a[1] - a[2] * a[0])));
        out[0] = std::atan2(2 * (a[3] * a[0] + a[1] * a[2]), (1 - 2 * (a[0] * a[0] + a[1] * a[1])));
        out[1] = std::asin(y);
        out[2] = std::atan2(2 * (a[3] * a[2] + a[0] * a[1]), (1 - 2 * (a[1] * a[1] + a[2] * a[2])));
    }
    void rotate(const double* v, double* out) const { quat_rotate(q, false, v, out); }
    void inverse_rotate(const double* v, double* out) const { quat_rotate(q, true, v, out); }
    // Quat::quatToAxis: the angle in [0, pi] (q negated when w < 0), asin of the vector part's norm
    // below 5 degrees (w > 0.999), else acos; the axis (0, 1, 0) when sin(angle / 2) < epsilon.
    void to_axis(double* axis, double& angle) const {
        SofaQuat p = *this;
        if (p.q[3] < 0)
            for (double& c : p.q) c *= -1;
        double sin_half;
        if (p.q[3] > 0.999) {
            sin_half = std::sqrt(p.q[0] * p.q[0] + p.q[1] * p.q[1] + p.q[2] * p.q[2]);
            angle = 2.0 * std::asin(sin_half);
        } else {
            const double half = std::acos(p.q[3]);
            sin_half = std::sin(half);
            angle = 2 * half;
        }
        if (sin_half < std::numeric_limits<double>::epsilon()) {
            axis[0] = 0.0;
            axis[1] = 1.0;
            axis[2] = 0.0;
        } else {
            for (int c = 0; c < 3; ++c) axis[c] = p.q[c] / sin_half;
        }
    }
    // Quat::toMatrix (computeRotationMatrix), row-major m[3 * row + column].
    void to_matrix(double* m) const {
        m[0] = 1 - 2 * (q[1] * q[1] + q[2] * q[2]);
        m[1] = 2 * (q[0] * q[1] - q[2] * q[3]);
        m[2] = 2 * (q[2] * q[0] + q[1] * q[3]);
        m[3] = 2 * (q[0] * q[1] + q[2] * q[3]);
        m[4] = 1 - 2 * (q[2] * q[2] + q[0] * q[0]);
        m[5] = 2 * (q[1] * q[2] - q[0] * q[3]);
        m[6] = 2 * (q[2] * q[0] - q[1] * q[3]);
        m[7] = 2 * (q[1] * q[2] + q[0] * q[3]);
        m[8] = 1 - 2 * (q[1] * q[1] + q[0] * q[0]);
    }
    // Quat::createQuaterFromEuler, SOFA's default order (ZYX).
    static SofaQuat from_euler(const double* angles) {
        const double c1 = std::cos(angles[0] / 2), c2 = std::cos(angles[1] / 2), c3 = std::cos(angles[2] / 2);
        const double s1 = std::sin(angles[0] / 2), s2 = std::sin(angles[1] / 2), s3 = std::sin(angles[2] / 2);
        return {{s1 * c2 * c3 - c1 * s2 * s3, c1 * s2 * c3 + s1 * c2 * s3, c1 * c2 * s3 - s1 * s2 * c3,
                 c1 * c2 * c3 + s1 * s2 * s3}};
    }
    // Quat::slerp2: spherical interpolation from this (t = 0) to b (t = 1).
    SofaQuat slerp2(const SofaQuat& b, double t) const {
        const double cos_half = q[3] * b.q[3] + q[0] * b.q[0] + q[1] * b.q[1] + q[2] * b.q[2];
        if (std::abs(cos_half) >= 1.0) return *this;
        const double half = std::acos(cos_half);
        const double sin_half = std::sqrt(1.0 - cos_half * cos_half);
        if (std::abs(sin_half) < 0.001)
            return {{q[0] * 0.5 + b.q[0] * 0.5, q[1] * 0.5 + b.q[1] * 0.5, q[2] * 0.5 + b.q[2] * 0.5,
                     q[3] * 0.5 + b.q[3] * 0.5}};
        const double ra = std::sin((1 - t) * half) / sin_half, rb = std::sin(t * half) / sin_half;
        return {{q[0] * ra + b.q[0] * rb, q[1] * ra + b.q[1] * rb, q[2] * ra + b.q[2] * rb, q[3] * ra + b.q[3] * rb}};
    }
};

}  // namespace sofac
