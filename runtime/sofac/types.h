// DataTypes: how a degree of freedom is stored, as in SOFA.
//
// A state is a flat array of doubles: n coordinates of `coord` numbers (positions) and n
// derivatives of `deriv` numbers (velocities, forces). Rigid3d coordinates are
// (x y z qx qy qz qw), derivatives (vx vy vz wx wy wz) with the angular velocity in world axes.
// Rigid2d coordinates are (x y theta), derivatives (vx vy omega).
#pragma once

#include <Eigen/Dense>
#include <cstdint>

namespace sofac {

using Index = std::int64_t;

#if defined(__GNUC__) && defined(__x86_64__)
// Kernels with copies compiled for AVX2 and AVX-512 (GCC's target attribute), chosen by
// vector_level(): wider vectors, the same IEEE operations per lane (no fused multiply-add), so
// the same numbers as the baseline copy.
#define SOFAC_X86_VARIANTS 1
// 2: AVX-512 F+VL, 1: AVX2, 0: neither. A scene library is built for the processor it runs on
// (sofac.build defines SOFAC_VECTOR_LEVEL from it, and the flag is part of the cache key), so only
// that copy is compiled: the others would triple the kernels' compile time. Without the define
// (tests, other builds), the processor is asked at run time.
inline int vector_level() {
#ifdef SOFAC_VECTOR_LEVEL
    return SOFAC_VECTOR_LEVEL;
#else
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl")) return 2;
    return __builtin_cpu_supports("avx2") ? 1 : 0;
#endif
}
#endif

template <int N>
struct VecTypes {
    static constexpr int coord = N;
    static constexpr int deriv = N;
    static constexpr int spatial = N < 3 ? N : 3;  // Vec6d: the first three numbers are a position
    static constexpr bool rigid = false;
};

struct Rigid3Types {
    static constexpr int coord = 7;
    static constexpr int deriv = 6;
    static constexpr int spatial = 3;
    static constexpr bool rigid = true;
};

struct Rigid2Types {
    static constexpr int coord = 3;
    static constexpr int deriv = 3;
    static constexpr int spatial = 2;
    static constexpr bool rigid = true;
};

using Vec1d = VecTypes<1>;
using Vec2d = VecTypes<2>;
using Vec3d = VecTypes<3>;
using Vec6d = VecTypes<6>;
using Rigid3d = Rigid3Types;
using Rigid2d = Rigid2Types;

template <int N>
using VecN = Eigen::Matrix<double, N, 1>;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;

// The spatial (translational) part of coordinate / derivative i.
template <class DT>
inline Eigen::Map<VecN<DT::spatial>> point(double* x, Index i) {
    return Eigen::Map<VecN<DT::spatial>>(x + DT::coord * i);
}
template <class DT>
inline Eigen::Map<const VecN<DT::spatial>> point(const double* x, Index i) {
    return Eigen::Map<const VecN<DT::spatial>>(x + DT::coord * i);
}
template <class DT>
inline Eigen::Map<VecN<DT::spatial>> linear(double* v, Index i) {
    return Eigen::Map<VecN<DT::spatial>>(v + DT::deriv * i);
}
template <class DT>
inline Eigen::Map<const VecN<DT::spatial>> linear(const double* v, Index i) {
    return Eigen::Map<const VecN<DT::spatial>>(v + DT::deriv * i);
}

// Rigid3d orientation i, stored (x y z w) like SOFA; Eigen's Quaterniond stores the same order.
inline Eigen::Map<Quat> orientation(double* x, Index i) { return Eigen::Map<Quat>(x + 7 * i + 3); }
inline Eigen::Map<const Quat> orientation(const double* x, Index i) {
    return Eigen::Map<const Quat>(x + 7 * i + 3);
}
inline Eigen::Map<Vec3> angular(double* v, Index i) { return Eigen::Map<Vec3>(v + 6 * i + 3); }
inline Eigen::Map<const Vec3> angular(const double* v, Index i) {
    return Eigen::Map<const Vec3>(v + 6 * i + 3);
}

// The unit quaternion of the rotation vector w (angle |w| about w / |w|).
inline Quat quat_from_rotation_vector(const Vec3& w) {
    const double angle = w.norm();
    if (angle < 1e-300) return Quat::Identity();
    const double half = 0.5 * angle;
    const Vec3 axis = w * (std::sin(half) / angle);
    return Quat(std::cos(half), axis.x(), axis.y(), axis.z());
}

}  // namespace sofac
