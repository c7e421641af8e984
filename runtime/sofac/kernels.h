// The per-component kernels the generated step calls. Each is a small inline template over
// DataTypes, works on flat arrays, allocates nothing and reads its parameters through pointers
// into the instance's parameter storage (so they can be changed from Python between steps).
//
// The formulas follow SOFA's components (see docs in compiler/registry/components/*.py).
#pragma once

#include <cmath>
#include <limits>

#include "quaternion.h"
#include "types.h"

// Complete unrolling of the short loops over a point's coordinates (g++ -O2 keeps them as loops).
#define SOFAC_UNROLL _Pragma("GCC unroll 16")

namespace sofac {

// ---- vector operations -------------------------------------------------------------------------

inline void clear(double* a, Index size) {
    for (Index k = 0; k < size; ++k) a[k] = 0.0;
}

inline void copy(double* out, const double* in, Index size) {
    for (Index k = 0; k < size; ++k) out[k] = in[k];
}

// out = a + h * b (derivative-shaped arrays)
inline void add_scaled(double* out, const double* a, const double* b, double h, Index size) {
    for (Index k = 0; k < size; ++k) out[k] = a[k] + h * b[k];
}

// Symplectic Euler on points in one pass: v += h a, then x += h v (the same numbers as add_scaled
// followed by advance).
inline void symplectic_points(double* x, double* v, const double* a, double h, Index size) {
    for (Index k = 0; k < size; ++k) {
        v[k] = v[k] + h * a[k];
        x[k] = x[k] + h * v[k];
    }
}

// out = x "+" h * v on coordinates: a translation for points; for rigid frames the orientation
// turns by the rotation vector h*w, left-multiplied in world axes (SOFA's RigidCoord += Deriv).
template <class DT>
inline void advance(double* out, const double* x, const double* v, double h, Index n) {
    if constexpr (!DT::rigid) {
        add_scaled(out, x, v, h, DT::coord * n);
    } else if constexpr (DT::coord == 7) {
        for (Index i = 0; i < n; ++i) {
            point<DT>(out, i) = point<DT>(x, i) + h * linear<DT>(v, i);
            const Quat turn = quat_from_rotation_vector(h * angular(v, i));
            orientation(out, i) = turn * orientation(x, i);
        }
    } else {
        add_scaled(out, x, v, h, 3 * n);  // Rigid2d: x, y, theta
    }
}

// CentralDifferenceSolver's update, a the acceleration M^-1 f: with rayleighMass r = 0 symplectic
// Euler (SOFA's fused v += a h, x += v h); else v += c1 v, v += c2 a, x += h v with
// c1 = (1/h - r/2) / (1/h + r/2) - 1 and c2 = 1 / (1/h + r/2), in SOFA's order.
template <class DT>
inline void central_difference(double* x, double* v, const double* a, double h, double r, Index n) {
    const Index size = DT::deriv * n;
    if (r == 0) {
        if constexpr (!DT::rigid) {
            symplectic_points(x, v, a, h, size);
            return;
        }
        add_scaled(v, v, a, h, size);
    } else {
        add_scaled(v, v, v, -1.0 + (1 / h - r / 2) / (1 / h + r / 2), size);
        add_scaled(v, v, a, 1 / (1 / h + r / 2), size);
    }
    advance<DT>(x, x, v, h, n);
}

// ---- masses ------------------------------------------------------------------------------------

// Rigid masses are (m, inertia[9]) with the inertia already multiplied by m, applied in world
// axes: SOFA neither rotates the inertia with the body nor adds the gyroscopic term.
template <class DT>
inline void mass_gravity(double* f, Index n, const double* mass, Index mass_stride, const double* g) {
    if (mass_stride == 0) {  // one mass: the weight m g computed once (f may alias nothing then)
        double weight[DT::spatial];
        for (int d = 0; d < DT::spatial; ++d) weight[d] = mass[0] * g[d];
        for (Index i = 0; i < n; ++i) {
            SOFAC_UNROLL
            for (int d = 0; d < DT::spatial; ++d) f[DT::deriv * i + d] += weight[d];
        }
        return;
    }
    for (Index i = 0; i < n; ++i) {
        const double m = mass[i * mass_stride];
        for (int d = 0; d < DT::spatial; ++d) f[DT::deriv * i + d] += m * g[d];
    }
}

// out[i] = in[i] / divisor. Divisions are slow (SSE2 does 2 at a time): the AVX2 and AVX-512
// copies do 4 or 8, with the same quotients.
inline void divide_plain(double* out, const double* in, Index n, double divisor) {
    for (Index i = 0; i < n; ++i) out[i] = in[i] / divisor;
}
#ifdef SOFAC_X86_VARIANTS
__attribute__((target("avx2"))) inline void divide_avx2(double* out, const double* in, Index n, double divisor) {
    for (Index i = 0; i < n; ++i) out[i] = in[i] / divisor;
}
__attribute__((target("avx512f,avx512vl"))) inline void divide_avx512(double* out, const double* in, Index n,
                                                                      double divisor) {
    for (Index i = 0; i < n; ++i) out[i] = in[i] / divisor;
}
#endif
inline void divide(double* out, const double* in, Index n, double divisor) {
#ifdef SOFAC_X86_VARIANTS
    const int level = vector_level();
    if (level == 2) return divide_avx512(out, in, n, divisor);
    if (level == 1) return divide_avx2(out, in, n, divisor);
#endif
    divide_plain(out, in, n, divisor);
}

template <class DT>
inline void mass_acceleration(double* a, const double* f, Index n, const double* mass, Index mass_stride) {
    if constexpr (!DT::rigid) {
        if (mass_stride == 0) {  // one mass for every point: a flat division
            divide(a, f, DT::deriv * n, mass[0]);
            return;
        }
    }
    for (Index i = 0; i < n; ++i) {
        const double* mi = mass + i * mass_stride;
        if constexpr (DT::rigid && DT::coord == 7) {
            linear<DT>(a, i) = linear<DT>(f, i) / mi[0];
            const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> inertia(mi + 1);
            // SOFA multiplies by the inverse of (inertia * m); a closed-form 3x3 inverse also keeps
            // the compile time down (Eigen's LDLT instantiates much more code).
            angular(a, i) = Mat3(inertia).inverse() * Vec3(angular(f, i));
        } else if constexpr (DT::rigid) {
            a[3 * i] = f[3 * i] / mi[0];
            a[3 * i + 1] = f[3 * i + 1] / mi[0];
            a[3 * i + 2] = f[3 * i + 2] / mi[1];
        } else {
            for (int d = 0; d < DT::deriv; ++d) a[DT::deriv * i + d] = f[DT::deriv * i + d] / mi[0];
        }
    }
}

// df += mfact M dx.
template <class DT>
inline void mass_multiply(double* df, const double* dx, Index n, const double* mass, Index mass_stride,
                          double mfact) {
    if constexpr (!DT::rigid) {
        if (mass_stride == 0) {  // one mass: the factor (mfact m) once, then a flat, vectorised pass
            const double factor = mfact * mass[0];
            for (Index k = 0; k < DT::deriv * n; ++k) df[k] += factor * dx[k];
            return;
        }
    }
    for (Index i = 0; i < n; ++i) {
        const double* mi = mass + i * mass_stride;
        if constexpr (DT::rigid && DT::coord == 7) {
            linear<DT>(df, i) += mfact * mi[0] * linear<DT>(dx, i);
            const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> inertia(mi + 1);
            angular(df, i) += mfact * (inertia * angular(dx, i));
        } else if constexpr (DT::rigid) {
            df[3 * i] += mfact * mi[0] * dx[3 * i];
            df[3 * i + 1] += mfact * mi[0] * dx[3 * i + 1];
            df[3 * i + 2] += mfact * mi[1] * dx[3 * i + 2];
        } else {  // one mass per point (DiagonalMass::addMDx): (dx m) mfact, in that order
            for (int d = 0; d < DT::deriv; ++d) df[DT::deriv * i + d] += (dx[DT::deriv * i + d] * mi[0]) * mfact;
        }
    }
}

// The exact rigid-body model (opt-in, not SOFA's): the inertia given in the body frame turns with
// the body, I_w = R I R^T, and Euler's equations keep the gyroscopic term:
// dw/dt = I_w^-1 (tau - w x I_w w). Linear part as mass_acceleration.
inline void rigid_acceleration_exact(double* a, const double* f, const double* x, const double* v, Index n,
                                     const double* mass, Index mass_stride) {
    for (Index i = 0; i < n; ++i) {
        const double* mi = mass + i * mass_stride;
        linear<Rigid3d>(a, i) = linear<Rigid3d>(f, i) / mi[0];
        const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> body(mi + 1);
        const Mat3 rotation = orientation(x, i).toRotationMatrix();
        const Mat3 world = rotation * body * rotation.transpose();
        const Vec3 w = angular(v, i);
        angular(a, i) = world.inverse() * (Vec3(angular(f, i)) - w.cross(world * w));
    }
}

// Kinetic energy 1/2 v.M.v and gravity's potential -m g.x.
template <class DT>
inline void mass_energy(const double* x, const double* v, Index n, const double* mass, Index mass_stride,
                        const double* g, double* kinetic, double* potential) {
    for (Index i = 0; i < n; ++i) {
        const double* mi = mass + i * mass_stride;
        *kinetic += 0.5 * mi[0] * linear<DT>(v, i).squaredNorm();
        if constexpr (DT::rigid && DT::coord == 7) {
            const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> inertia(mi + 1);
            *kinetic += 0.5 * angular(v, i).dot(inertia * angular(v, i));
        } else if constexpr (DT::rigid) {
            *kinetic += 0.5 * mi[1] * v[3 * i + 2] * v[3 * i + 2];
        } else {
            for (int d = DT::spatial; d < DT::deriv; ++d) *kinetic += 0.5 * mi[0] * v[DT::deriv * i + d] * v[DT::deriv * i + d];
        }
        for (int d = 0; d < DT::spatial; ++d) *potential -= mi[0] * g[d] * x[DT::coord * i + d];
    }
}

// Gravity's potential -sum m_i g.x_i of per-point masses (times `factor`).
template <class DT>
inline double gravity_potential(const double* x, Index n, const double* mass, const double* g, double factor) {
    double potential = 0.0;
    for (Index i = 0; i < n; ++i)
        for (int d = 0; d < DT::spatial; ++d) potential -= mass[i] * factor * g[d] * x[DT::coord * i + d];
    return potential;
}

// ---- force fields ------------------------------------------------------------------------------

// Springs between point a of state 1 and point b of state 2 (may be the same state):
// u = x_b - x_a, d = |u|, n = u/d, F = ks (d - L0) + kd (v_b - v_a).n; f_a += F n, f_b -= F n.
struct Springs {
    const Index* a;
    const Index* b;
    const double* stiffness;
    const double* damping;
    const double* rest_length;
    const Index* elongation_only;  // 0/1 per spring
    const Index* enabled;          // 0/1 per spring
    Index count;
};

// VectorSpringForceField (Vec3d): spring k joins a[k] of object1 and b[k] of object2, with rest
// vector rest[k]; one stiffness and one damping for all (SOFA's default springs).
struct VectorSprings {
    const Index* a;
    const Index* b;
    const double* rest;  // count x 3
    const double* stiffness;
    const double* damping;
    Index count;
};

// f = (d - r) ks + (v2 - v1) kd with d = x2[b] - x1[a], in SOFA's order; f1[a] += f, f2[b] -= f.
inline void vector_spring_forces(const VectorSprings& s, const double* x1, const double* v1, double* f1,
                                 const double* x2, const double* v2, double* f2) {
    const double ks = s.stiffness[0], kd = s.damping[0];
    for (Index k = 0; k < s.count; ++k) {
        const Index i = 3 * s.a[k], j = 3 * s.b[k];
        for (int c = 0; c < 3; ++c) {
            const double squash = (x2[j + c] - x1[i + c]) - s.rest[3 * k + c];
            const double force = squash * ks + (v2[j + c] - v1[i + c]) * kd;
            f1[i + c] += force;
            f2[j + c] -= force;
        }
    }
}

// df = (dx2[b] - dx1[a]) (ks kfact): SOFA's addDForce, no damping term.
inline void vector_spring_dforces(const VectorSprings& s, const double* dx1, double* df1, const double* dx2,
                                  double* df2, double kfact) {
    const double factor = s.stiffness[0] * kfact;
    for (Index k = 0; k < s.count; ++k) {
        const Index i = 3 * s.a[k], j = 3 * s.b[k];
        for (int c = 0; c < 3; ++c) {
            const double dforce = (dx2[j + c] - dx1[i + c]) * factor;
            df1[i + c] += dforce;
            df2[j + c] -= dforce;
        }
    }
}

// With `jacobians` (implicit schemes), also stores each spring's dF/dx block for spring_dforces,
// (ks - F/d) n n^T + (F/d) I with F the whole intensity (elastic and damping), as SOFA does, in
// factored form: S + 2 numbers per spring, c = ks - F/d, t = F/d and n (spring_block rebuilds
// entry (i, j) as (c n_i) n_j [+ t], the very numbers a stored S x S block would hold).
// `SpringDamping::Undamped` leaves out the damping term (the plan proves every damping is zero: no
// velocity is read); `SpringFlags::None` skips the per-spring enabled / elongation-only flags (all
// springs enabled, none elongation-only). Plain scalar code: the sums run in the order Eigen's small
// fixed-size expressions use (left to right), so every variant gives the same numbers bit for bit.
enum class SpringDamping { Undamped, Damped };
enum class SpringFlags { None, PerSpring };

template <class D1, class D2, SpringDamping Damping = SpringDamping::Damped, SpringFlags Flags = SpringFlags::PerSpring>
inline void spring_forces(const Springs& s, const double* x1, const double* v1, double* f1, const double* x2,
                          const double* v2, double* f2, double* jacobians) {
    static_assert(D1::spatial == D2::spatial, "springs join points of the same dimension");
    constexpr int S = D1::spatial;
    const Index* const sa = s.a;
    const Index* const sb = s.b;
    const double* const stiffness = s.stiffness;
    const double* const rest = s.rest_length;
    const Index count = s.count;
    for (Index k = 0; k < count; ++k) {
        const Index a = sa[k], b = sb[k];
        const double* const xa = x1 + D1::coord * a;
        const double* const xb = x2 + D2::coord * b;
        double u[S];
        SOFAC_UNROLL
        for (int i = 0; i < S; ++i) u[i] = xb[i] - xa[i];
        double squared = u[0] * u[0];
        SOFAC_UNROLL
        for (int i = 1; i < S; ++i) squared += u[i] * u[i];
        const double d = std::sqrt(squared);
        bool active = d > 1.0e-9;
        if constexpr (Flags == SpringFlags::PerSpring) active = active && s.enabled[k] && !(s.elongation_only[k] && !(d > rest[k]));
        if (!active) {
            if (jacobians) {
                SOFAC_UNROLL
                for (int i = 0; i < S + 2; ++i) jacobians[(S + 2) * k + i] = 0.0;
            }
            continue;
        }
        const double inverse_length = 1.0 / d;
        SOFAC_UNROLL
        for (int i = 0; i < S; ++i) u[i] *= inverse_length;
        const double ks = stiffness[k];
        double intensity = ks * (d - rest[k]);
        if constexpr (Damping == SpringDamping::Damped) {
            const double* const va = v1 + D1::deriv * a;
            const double* const vb = v2 + D2::deriv * b;
            double relative_speed = u[0] * (vb[0] - va[0]);
            SOFAC_UNROLL
            for (int i = 1; i < S; ++i) relative_speed += u[i] * (vb[i] - va[i]);
            intensity += s.damping[k] * relative_speed;
        }
        double* const fa = f1 + D1::deriv * a;
        double* const fb = f2 + D2::deriv * b;
        SOFAC_UNROLL
        for (int i = 0; i < S; ++i) {
            const double force = u[i] * intensity;
            fa[i] += force;
            fb[i] -= force;
        }
        if (jacobians) {
            const double tangent = intensity * inverse_length;
            double* const m = jacobians + (S + 2) * k;
            m[0] = ks - tangent;
            m[1] = tangent;
            SOFAC_UNROLL
            for (int i = 0; i < S; ++i) m[2 + i] = u[i];
        }
    }
}

// Spring k's S x S block (row-major) from the factored form spring_forces stores.
template <int S>
inline void spring_block(const double* jacobians, Index k, double* block) {
    const double* const m = jacobians + (S + 2) * k;
    SOFAC_UNROLL
    for (int i = 0; i < S; ++i) {
        const double cu = m[0] * m[2 + i];
        SOFAC_UNROLL
        for (int j = 0; j < S; ++j) block[S * i + j] = cu * m[2 + j];
        block[S * i + i] += m[1];
    }
}

// df_a += kfact dF/dx (dx_b - dx_a), df_b -= the same, with the blocks of the last force pass
// (row sums left to right, then the factor: as Eigen's (m * w) * kfact).
template <class D1, class D2>
inline void spring_dforces(const Springs& s, const double* jacobians, const double* dx1, double* df1,
                           const double* dx2, double* df2, double kfact) {
    constexpr int S = D1::spatial;
    const Index* const sa = s.a;
    const Index* const sb = s.b;
    const Index count = s.count;
    for (Index k = 0; k < count; ++k) {
        const Index a = sa[k], b = sb[k];
        double m[S * S];
        spring_block<S>(jacobians, k, m);
        const double* const ya = dx1 + D1::deriv * a;
        const double* const yb = dx2 + D2::deriv * b;
        double w[S];
        SOFAC_UNROLL
        for (int j = 0; j < S; ++j) w[j] = yb[j] - ya[j];
        double* const fa = df1 + D1::deriv * a;
        double* const fb = df2 + D2::deriv * b;
        SOFAC_UNROLL
        for (int i = 0; i < S; ++i) {
            double row = m[S * i] * w[0];
            SOFAC_UNROLL
            for (int j = 1; j < S; ++j) row += m[S * i + j] * w[j];
            const double dforce = row * kfact;
            fa[i] += dforce;
            fb[i] -= dforce;
        }
    }
}

template <class D1, class D2>
inline double spring_energy(const Springs& s, const double* x1, const double* x2) {
    double energy = 0.0;
    for (Index k = 0; k < s.count; ++k) {
        if (!s.enabled[k]) continue;
        const double d = (point<D2>(x2, s.b[k]) - point<D1>(x1, s.a[k])).norm();
        if (s.elongation_only[k] && d < s.rest_length[k]) continue;
        const double stretch = d - s.rest_length[k];
        energy += 0.5 * s.stiffness[k] * stretch * stretch;
    }
    return energy;
}

// A force on one DOF, set from Python between steps (sofac view's mouse spring): none while `point`
// is outside [0, size), so an index written from Python can never reach outside the state.
template <class DT>
inline void point_force(double* f, const Index* point, const double* force, Index size) {
    const Index i = point[0];
    if (i < 0 || i >= size) return;
    for (int d = 0; d < DT::deriv; ++d) f[DT::deriv * i + d] += force[d];
}

// A constant force per listed DOF (deriv-shaped rows).
template <class DT>
inline void constant_forces(double* f, const Index* indices, const double* forces, Index count) {
    for (Index k = 0; k < count; ++k)
        for (int d = 0; d < DT::deriv; ++d) f[DT::deriv * indices[k] + d] += forces[DT::deriv * k + d];
}

// RestShapeSpringsForceField on points: f_i -= k_i (x_i - x_rest_i) (translation only); points past the
// end of the stiffness list take its first value, as SOFA does.
template <class DT>
inline void rest_shape_forces(double* f, const double* x, const double* rest, const Index* indices,
                              const double* stiffness, Index stiffness_count, Index count) {
    for (Index k = 0; k < count; ++k) {
        const Index i = indices[k];
        const double ks = stiffness[k < stiffness_count ? k : 0];
        linear<DT>(f, i) -= ks * (point<DT>(x, i) - point<DT>(rest, i));
    }
}

// K = -k I on the listed points: df -= kfact k dx.
template <class DT>
inline void rest_shape_dforces(double* df, const double* dx, const Index* indices, const double* stiffness,
                               Index stiffness_count, Index count, double kfact) {
    for (Index k = 0; k < count; ++k) {
        const Index i = indices[k];
        const double ks = stiffness[k < stiffness_count ? k : 0];
        linear<DT>(df, i) -= (linear<DT>(dx, i) * ks) * kfact;  // SOFA's order: (dx k) kfact
    }
}

template <class DT>
inline double rest_shape_energy(const double* x, const double* rest, const Index* indices, const double* stiffness,
                                Index stiffness_count, Index count) {
    double energy = 0.0;
    for (Index k = 0; k < count; ++k) {
        const Index i = indices[k];
        const double ks = stiffness[k < stiffness_count ? k : 0];
        energy += 0.5 * ks * (point<DT>(x, i) - point<DT>(rest, i)).squaredNorm();
    }
    return energy;
}

// ---- projective constraints ----------------------------------------------------------------------

// Zero the listed DOFs of a derivative-shaped vector (FixedProjectiveConstraint).
template <class DT>
inline void project_fixed(double* dx, const Index* indices, Index count) {
    for (Index k = 0; k < count; ++k)
        for (int d = 0; d < DT::deriv; ++d) dx[DT::deriv * indices[k] + d] = 0.0;
}

// Zero the flagged directions of the listed DOFs (PartialFixedProjectiveConstraint).
template <class DT>
inline void project_partial(double* dx, const Index* indices, Index count, const Index* directions) {
    for (Index k = 0; k < count; ++k)
        for (int d = 0; d < DT::deriv; ++d)
            if (directions[d]) dx[DT::deriv * indices[k] + d] = 0.0;
}

// ---- mappings ----------------------------------------------------------------------------------

// RigidMapping Rigid3d -> Vec3d: p = c + R r, v = v_c + w x (R r), f_c += f, tau_c += (R r) x f.
// `offset` holds the current R r per point, computed by apply and reused by applyJ / applyJT.
inline void rigid_apply(const double* in_x, double* out_x, const double* local, const Index* frame,
                        double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = frame[i];
        const Vec3 r = orientation(in_x, c) * Eigen::Map<const Vec3>(local + 3 * i);
        Eigen::Map<Vec3>(offset + 3 * i) = r;
        Eigen::Map<Vec3>(out_x + 3 * i) = point<Rigid3d>(in_x, c) + r;
    }
}

inline void rigid_apply_j(const double* in_v, double* out_v, const Index* frame, const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = frame[i];
        Eigen::Map<Vec3>(out_v + 3 * i) =
            linear<Rigid3d>(in_v, c) + angular(in_v, c).cross(Eigen::Map<const Vec3>(offset + 3 * i));
    }
}

inline void rigid_apply_jt(double* in_f, const double* out_f, const Index* frame, const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = frame[i];
        const Eigen::Map<const Vec3> f(out_f + 3 * i);
        linear<Rigid3d>(in_f, c) += f;
        angular(in_f, c) += Eigen::Map<const Vec3>(offset + 3 * i).cross(f);
    }
}

// RigidMapping Rigid3d -> Rigid3d (child frames), SOFA's apply / applyJ / applyJT with its
// Rigid3 specialisation of updateOmega: r = q.rotate(local centre) (SOFA's quaternion arithmetic),
// x = (c + r, q * q_local); v = (v_c + w x r, w); f_c += f, tau_c += tau + r x f.
inline void rigid_frame_apply(const double* in_x, double* out_x, const double* local, const Index* frame,
                              double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const double* parent = in_x + 7 * frame[i];
        const double* child = local + 7 * i;
        const SofaQuat q = SofaQuat::load(parent + 3);
        double* r = offset + 3 * i;
        q.rotate(child, r);
        const SofaQuat turned = q * SofaQuat::load(child + 3);
        double* out = out_x + 7 * i;
        for (int c = 0; c < 3; ++c) out[c] = parent[c] + r[c];
        for (int c = 0; c < 4; ++c) out[3 + c] = turned.q[c];
    }
}

inline void rigid_frame_apply_j(const double* in_v, double* out_v, const Index* frame, const double* offset,
                                Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = frame[i];
        Eigen::Map<Vec3>(out_v + 6 * i) =
            linear<Rigid3d>(in_v, c) + angular(in_v, c).cross(Eigen::Map<const Vec3>(offset + 3 * i));
        angular(out_v, i) = angular(in_v, c);
    }
}

inline void rigid_frame_apply_jt(double* in_f, const double* out_f, const Index* frame, const double* offset,
                                 Index n) {
    for (Index i = 0; i < n; ++i) {
        const Index c = frame[i];
        const Eigen::Map<const Vec3> f(out_f + 6 * i);
        linear<Rigid3d>(in_f, c) += f;
        const Vec3 torque = angular(out_f, i) + Eigen::Map<const Vec3>(offset + 3 * i).cross(f);
        angular(in_f, c) += torque;
    }
}

// RigidMapping Rigid2d -> Vec2d (rotation by theta in the plane).
inline void rigid2_apply(const double* in_x, double* out_x, const double* local, const Index* frame,
                         double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const double* c = in_x + 3 * frame[i];
        const double cs = std::cos(c[2]), sn = std::sin(c[2]);
        const double rx = cs * local[2 * i] - sn * local[2 * i + 1];
        const double ry = sn * local[2 * i] + cs * local[2 * i + 1];
        offset[2 * i] = rx;
        offset[2 * i + 1] = ry;
        out_x[2 * i] = c[0] + rx;
        out_x[2 * i + 1] = c[1] + ry;
    }
}

inline void rigid2_apply_j(const double* in_v, double* out_v, const Index* frame, const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        const double* c = in_v + 3 * frame[i];
        out_v[2 * i] = c[0] - c[2] * offset[2 * i + 1];
        out_v[2 * i + 1] = c[1] + c[2] * offset[2 * i];
    }
}

inline void rigid2_apply_jt(double* in_f, const double* out_f, const Index* frame, const double* offset, Index n) {
    for (Index i = 0; i < n; ++i) {
        double* c = in_f + 3 * frame[i];
        c[0] += out_f[2 * i];
        c[1] += out_f[2 * i + 1];
        c[2] += offset[2 * i] * out_f[2 * i + 1] - offset[2 * i + 1] * out_f[2 * i];
    }
}

// SubsetMapping (and IdentityMapping with indices 0..n-1): out_k = in[index_k]; J^T adds back.
template <class DT>
inline void subset_apply(const double* in, double* out, const Index* indices, Index n, int width) {
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < width; ++d) out[width * k + d] = in[width * indices[k] + d];
}

template <class DT>
inline void subset_apply_jt(double* in_f, const double* out_f, const Index* indices, Index n) {
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < DT::deriv; ++d) in_f[DT::deriv * indices[k] + d] += out_f[DT::deriv * k + d];
}

// IdentityMapping between types of different sizes (Rigid3d -> Vec3d, Rigid2d -> Vec2d, Vec6d -> Vec3d):
// the child takes the first `out_width` numbers of each parent value (a rigid body's centre, its
// linear velocity); J^T adds a child force to the parent's first numbers only (no torque).
inline void leading_apply(const double* in, double* out, Index n, int in_width, int out_width) {
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < out_width; ++d) out[out_width * k + d] = in[in_width * k + d];
}

inline void leading_apply_jt(double* in_f, const double* out_f, Index n, int in_width, int out_width) {
    for (Index k = 0; k < n; ++k)
        for (int d = 0; d < out_width; ++d) in_f[in_width * k + d] += out_f[out_width * k + d];
}

// ---- linear algebra on flat vectors (conjugate gradient) ---------------------------------------

// a.b over n derivatives of `width` numbers, summed per derivative first, as SOFA's vector dot.
inline double dot(const double* a, const double* b, Index n, int width) {
    double sum = 0.0;
    for (Index i = 0; i < n; ++i) {
        double block = a[width * i] * b[width * i];
        for (int d = 1; d < width; ++d) block += a[width * i + d] * b[width * i + d];
        sum += block;
    }
    return sum;
}

// The conjugate gradient's update in one pass: x += alpha p, r -= alpha q; returns the new r.r
// (summed as dot(r, r, n, width): the same number as the separate passes).
template <int Width>
inline double cg_update(double* x, double* r, const double* p, const double* q, double alpha, Index n) {
    double sum = 0.0;
    for (Index i = 0; i < n; ++i) {
        double block = 0.0;
        SOFAC_UNROLL
        for (int d = 0; d < Width; ++d) {
            const Index k = Width * i + d;
            x[k] = x[k] + alpha * p[k];
            const double rk = r[k] + -alpha * q[k];
            r[k] = rk;
            block = d == 0 ? rk * rk : block + rk * rk;
        }
        sum += block;
    }
    return sum;
}

inline void scale(double* a, double factor, Index size) {
    for (Index k = 0; k < size; ++k) a[k] *= factor;
}

// ---- guards ------------------------------------------------------------------------------------

// Whether every number is finite: a vectorised sum of a * 0, which is NaN as soon as one number is
// infinite or NaN (the order of the sum does not matter: it is 0 or NaN).
inline bool all_finite(const double* a, Index size) {
    return !std::isnan((Eigen::Map<const Eigen::ArrayXd>(a, size) * 0.0).sum());
}

// The axis-aligned box of n points (their first three coordinates, `stride` numbers apart), grown
// by `margin` on every side: box = {min x, min y, min z, max x, max y, max z}.
inline void bounding_box(const double* x, Index n, int stride, double margin, double* box) {
    for (int d = 0; d < 3; ++d) {
        box[d] = std::numeric_limits<double>::infinity();
        box[3 + d] = -std::numeric_limits<double>::infinity();
    }
    for (Index i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) {
            box[d] = std::min(box[d], x[stride * i + d]);
            box[3 + d] = std::max(box[3 + d], x[stride * i + d]);
        }
    for (int d = 0; d < 3; ++d) {
        box[d] -= margin;
        box[3 + d] += margin;
    }
}

// The first of n pairs (rows of two box indices) whose boxes overlap, or -1.
inline Index first_touching_pair(const double* boxes, const Index* pairs, Index n) {
    for (Index k = 0; k < n; ++k) {
        const double* a = boxes + 6 * pairs[2 * k];
        const double* b = boxes + 6 * pairs[2 * k + 1];
        if (a[0] <= b[3] && b[0] <= a[3] && a[1] <= b[4] && b[1] <= a[4] && a[2] <= b[5] && b[2] <= a[5]) return k;
    }
    return -1;
}

// Index of the first non-finite number, or -1.
inline Index first_non_finite(const double* a, Index size) {
    for (Index k = 0; k < size; ++k)
        if (!std::isfinite(a[k])) return k;
    return -1;
}

}  // namespace sofac
