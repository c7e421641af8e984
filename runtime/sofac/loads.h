// Mechanical loads (Sofa.Component.MechanicalLoad) and the projective constraints with a geometric
// target (Line / Plane / Point), in SOFA's order of operations (results must match SOFA's).
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

#include <cfloat>
#include <cmath>

#include "kernels.h"
#include "quaternion.h"
#include "types.h"

namespace sofac {

// contacts: per point 10 doubles (flag, m row-major); frame_q: 4 doubles (the quaternion used).
inline void ellipsoid_add_force(const double* x1, const double* v1, double* f1, Index n, const double* x2,
                                Index frame, const double* ellipsoids, Index n_ellipsoids, double stiffness,
                                double damping, double* contacts, double* frame_q) {
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

// ---- PlaneForceField ---------------------------------------------------------------------------

// Penalty against the plane x.n = d for the points in [begin, end): for a point at signed distance
// delta = x.n - d < 0 (or any delta when bilateral), f += -stiffness delta n + damping delta v,
// clamped to |f| <= maxForce when maxForce > 0. `contact[i]` records which points were pushed, for
// the stiffness of the implicit solve (SOFA's m_contacts). Parameters: stiffness, damping, maxForce.
template <class DT>
inline void plane_forces(double* f, const double* x, const double* v, Index* contact, const double* normal,
                         const double* offset, const double* stiffness, const double* damping,
                         const double* max_force, bool bilateral, Index begin, Index end) {
    constexpr int S = DT::spatial;
    const double limit = max_force[0] * max_force[0];
    for (Index i = begin; i < end; ++i) {
        const double* p = x + DT::coord * i;
        double delta = p[0] * normal[0];
        for (int k = 1; k < S; ++k) delta += p[k] * normal[k];
        delta -= offset[0];
        contact[i] = bilateral || delta < 0.0;
        if (!contact[i]) continue;
        const double force_intensity = -stiffness[0] * delta;
        const double damping_intensity = -damping[0] * delta;
        double force[S];
        double amplitude = 0.0;
        for (int k = 0; k < S; ++k) {
            force[k] = normal[k] * force_intensity - v[DT::deriv * i + k] * damping_intensity;
            amplitude += force[k] * force[k];
        }
        if (limit > 0.0 && amplitude > limit) {
            const double scale = std::sqrt(limit / amplitude);
            for (int k = 0; k < S; ++k) force[k] *= scale;
        }
        for (int k = 0; k < S; ++k) f[DT::deriv * i + k] += force[k];
    }
}

// df += kfact * (-stiffness) (dx.n) n on the points in contact.
template <class DT>
inline void plane_dforces(double* df, const double* dx, const Index* contact, const double* normal,
                          const double* stiffness, double kfact, Index begin, Index end) {
    constexpr int S = DT::spatial;
    const double factor = -stiffness[0] * kfact;
    for (Index i = begin; i < end; ++i) {
        if (!contact[i]) continue;
        const double* d = dx + DT::deriv * i;
        double along = d[0] * normal[0];
        for (int k = 1; k < S; ++k) along += d[k] * normal[k];
        for (int k = 0; k < S; ++k) df[DT::deriv * i + k] += normal[k] * (factor * along);
    }
}

// The penalty's energy, 1/2 stiffness delta^2 per point it pushes (SOFA reports none).
template <class DT>
inline double plane_energy(const double* x, const double* normal, const double* offset, const double* stiffness,
                           bool bilateral, Index begin, Index end) {
    constexpr int S = DT::spatial;
    double energy = 0.0;
    for (Index i = begin; i < end; ++i) {
        const double* p = x + DT::coord * i;
        double delta = p[0] * normal[0];
        for (int k = 1; k < S; ++k) delta += p[k] * normal[k];
        delta -= offset[0];
        if (bilateral || delta < 0.0) energy += 0.5 * stiffness[0] * delta * delta;
    }
    return energy;
}

// ---- TrianglePressureForceField ------------------------------------------------------------------

// useConstantForce: each listed triangle pushes its three corners with (pressure * its rest area) / 3.
template <class DT>
inline void triangle_pressure(double* f, const Index* corners, const double* area, Index count,
                              const double* pressure) {
    constexpr int S = DT::spatial;
    for (Index t = 0; t < count; ++t) {
        double share[S];
        for (int k = 0; k < S; ++k) share[k] = pressure[k] * area[t] / 3.0;
        for (int c = 0; c < 3; ++c)
            for (int k = 0; k < S; ++k) f[DT::deriv * corners[3 * t + c] + k] += share[k];
    }
}

// ---- EdgePressureForceField ---------------------------------------------------------------------

// Each selected edge (ends edges[2i], edges[2i+1]) adds its stored force / 2 to both ends (Vec3d).
inline void edge_pressure_forces(double* f, const Index* edges, Index count, const double* forces) {
    for (Index i = 0; i < count; ++i) {
        const double half[3] = {forces[3 * i] / 2, forces[3 * i + 1] / 2, forces[3 * i + 2] / 2};
        for (int end = 0; end < 2; ++end)
            for (int k = 0; k < 3; ++k) f[3 * edges[2 * i + end] + k] += half[k];
    }
}

// SOFA's initEdgeInformation with a binormal, run at init and at the end of every addForce: the
// stored force of selected edge i becomes (n intensity[i]) length[i], n = normalize(binormal x
// normalize(x[e1] - x[e0])), each normalize Vec::normalize's (divided by the norm when it exceeds
// the machine epsilon).
inline void edge_pressure_update(double* forces, const double* x, const Index* edges, Index count,
                                 const double* binormal, const double* intensity, const double* length) {
    const auto normalize = [](double* v) {
        const double norm = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if (norm > DBL_EPSILON)
            for (int k = 0; k < 3; ++k) v[k] /= norm;
    };
    const double* b = binormal;
    for (Index i = 0; i < count; ++i) {
        const double* p0 = x + 3 * edges[2 * i];
        const double* p1 = x + 3 * edges[2 * i + 1];
        double t[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
        normalize(t);
        double n[3] = {b[1] * t[2] - b[2] * t[1], b[2] * t[0] - b[0] * t[2], b[0] * t[1] - b[1] * t[0]};
        normalize(n);
        for (int k = 0; k < 3; ++k) forces[3 * i + k] = n[k] * intensity[i] * length[i];
    }
}

// ---- Line / Plane / Point projective constraints -----------------------------------------------

// dx_i = P dx_i for the listed DOFs, P a spatial x spatial block: n n^T onto a line, I - n n^T onto
// a plane (SOFA's projection Jacobian, applied to responses and velocities).
template <class DT>
inline void project_block(double* dx, const Index* indices, Index count, const double* block) {
    constexpr int S = DT::spatial;
    for (Index k = 0; k < count; ++k) {
        double* d = dx + DT::deriv * indices[k];
        double projected[S];
        for (int r = 0; r < S; ++r) {
            projected[r] = block[S * r] * d[0];
            for (int c = 1; c < S; ++c) projected[r] += block[S * r + c] * d[c];
        }
        for (int r = 0; r < S; ++r) d[r] = projected[r];
    }
}

// x_i = o + n ((x_i - o).n): the listed points onto the line through o along the unit n.
template <class DT>
inline void project_onto_line(double* x, const Index* indices, Index count, const double* origin,
                              const double* direction) {
    constexpr int S = DT::spatial;
    for (Index k = 0; k < count; ++k) {
        double* p = x + DT::coord * indices[k];
        double along = (p[0] - origin[0]) * direction[0];
        for (int c = 1; c < S; ++c) along += (p[c] - origin[c]) * direction[c];
        for (int c = 0; c < S; ++c) p[c] = origin[c] + direction[c] * along;
    }
}

// x_i = x_i - n ((x_i - o).n): the listed points onto the plane through o of unit normal n.
template <class DT>
inline void project_onto_plane(double* x, const Index* indices, Index count, const double* origin,
                               const double* normal) {
    constexpr int S = DT::spatial;
    for (Index k = 0; k < count; ++k) {
        double* p = x + DT::coord * indices[k];
        double across = (p[0] - origin[0]) * normal[0];
        for (int c = 1; c < S; ++c) across += (p[c] - origin[c]) * normal[c];
        for (int c = 0; c < S; ++c) p[c] = p[c] - normal[c] * across;
    }
}

// x_i = target for the listed DOFs (PointProjectiveConstraint).
template <class DT>
inline void project_onto_point(double* x, const Index* indices, Index count, const double* target) {
    for (Index k = 0; k < count; ++k)
        for (int c = 0; c < DT::coord; ++c) x[DT::coord * indices[k] + c] = target[c];
}

// ---- FixedPlane, FixedTranslation, Direction, FixedRotation, LinearMovement -----------------------

// The part of a derivative FixedPlane acts on: a rigid's translation, a vector's every coordinate.
template <class DT>
constexpr int translation_width() {
    return DT::rigid ? DT::spatial : DT::deriv;
}

// FixedPlaneProjectiveConstraint's projectResponse: d = d - dir (d . dir) on the listed DOFs, with
// `direction` as given (SOFA does not normalise it).
template <class DT>
inline void project_out_direction(double* dx, const Index* indices, Index count, const double* direction) {
    constexpr int W = translation_width<DT>();
    for (Index k = 0; k < count; ++k) {
        double* d = dx + DT::deriv * indices[k];
        double along = d[0] * direction[0];
        for (int c = 1; c < W; ++c) along += d[c] * direction[c];
        for (int c = 0; c < W; ++c) d[c] = d[c] - direction[c] * along;
    }
}

// DirectionProjectiveConstraint's projectPosition: x_i = o_i + n ((x_i - o_i) . n), o_i the point's
// initial position (SOFA's m_origin), n the unit direction.
template <class DT>
inline void project_onto_lines(double* x, const Index* indices, Index count, const double* origins,
                               const double* direction) {
    constexpr int S = DT::spatial;
    for (Index k = 0; k < count; ++k) {
        double* p = x + DT::coord * indices[k];
        const double* o = origins + S * k;
        double along = (p[0] - o[0]) * direction[0];
        for (int c = 1; c < S; ++c) along += (p[c] - o[c]) * direction[c];
        for (int c = 0; c < S; ++c) p[c] = o[c] + direction[c] * along;
    }
}

// FixedRotationProjectiveConstraint's projectPosition on every rigid: for each fixed axis (x, y, z
// in that order), the twist about it is removed from the orientation (swing-twist decomposition)
// and the initial orientation's twist about it is kept instead; q = remaining * kept.
inline void fixed_rotation_position(double* x, Index count, const double* initial_orientations,
                                    const Index* fixed_axes) {
    // q = twist * swing with twist about `axis`; returns the twist, leaves the swing in q.
    auto split = [](SofaQuat& q, int axis) {
        SofaQuat twist{{0.0, 0.0, 0.0, q.q[3]}};
        twist.q[axis] = q.q[axis];  // (v . e) e for a coordinate axis e
        if (twist.q[0] == 0.0 && twist.q[1] == 0.0 && twist.q[2] == 0.0 && twist.q[3] == 0.0)
            twist = SofaQuat{{0.0, 0.0, 0.0, 1.0}};
        twist.normalize();
        q = q * twist.inverse();
        q.normalize();
        return twist;
    };
    for (Index i = 0; i < count; ++i) {
        double* o = x + 7 * i + 3;
        SofaQuat remaining{{o[0], o[1], o[2], o[3]}};
        const double* p = initial_orientations + 4 * i;
        SofaQuat previous{{p[0], p[1], p[2], p[3]}};
        SofaQuat kept{{0.0, 0.0, 0.0, 1.0}};
        for (int axis = 0; axis < 3; ++axis) {
            if (!fixed_axes[axis]) continue;
            split(remaining, axis);
            kept = split(previous, axis) * kept;
        }
        const SofaQuat result = remaining * kept;
        for (int c = 0; c < 4; ++c) o[c] = result.q[c];
    }
}

// LinearMovementProjectiveConstraint: SOFA's findKeyTimes at `time`. Active (true) when a key time
// follows `time` and `time` is not before the first key; then the surrounding keys' times and
// movements.
template <class DT>
struct KeyedMovement {
    double* memory;  // [captured, x0 (count x coord)]: the listed DOFs at the first projectPosition
    const double* key_times;
    const double* key_movements;  // keys x deriv
    Index keys;
    bool relative;

    bool find(double time, double& previous_time, double& next_time, const double*& previous,
              const double*& next) const {
        if (keys == 0 || time < key_times[0] || time > key_times[keys - 1]) return false;
        previous_time = next_time = key_times[0];
        previous = next = key_movements;
        for (Index k = 0; k < keys; ++k) {
            if (key_times[k] <= time) {
                previous_time = key_times[k];
                previous = key_movements + DT::deriv * k;
            } else {
                next_time = key_times[k];
                next = key_movements + DT::deriv * k;
                return next_time != previous_time;
            }
        }
        return false;  // `time` is the last key: SOFA's loop ends without finding the next one
    }
};

// projectResponse: the listed DOFs' derivatives zeroed while a movement is under way.
template <class DT>
inline void keyed_movement_response(const KeyedMovement<DT>& k, double* dx, const Index* indices, Index count,
                                    double time) {
    double t0, t1;
    const double *m0, *m1;
    if (k.find(time, t0, t1, m0, m1)) project_fixed<DT>(dx, indices, count);
}

// projectVelocity: v = (m1 - m0) / (t1 - t0) on the listed DOFs.
template <class DT>
inline void keyed_movement_velocity(const KeyedMovement<DT>& k, double* v, const Index* indices, Index count,
                                    double time) {
    double t0, t1;
    const double *m0, *m1;
    if (!k.find(time, t0, t1, m0, m1)) return;
    const double inverse = 1.0 / (t1 - t0);
    for (Index i = 0; i < count; ++i)
        for (int c = 0; c < DT::deriv; ++c) v[DT::deriv * indices[i] + c] = (m1[c] - m0[c]) * inverse;
}

// projectPosition: x = x0 + m (relative) or m, m = m0 + (m1 - m0) (t - t0) / (t1 - t0); a rigid's
// orientation is x0's times the slerp of the keys' Euler rotations (ZYX), or that slerp alone.
template <class DT>
inline void keyed_movement_position(const KeyedMovement<DT>& k, double* x, const Index* indices, Index count,
                                    double time) {
    double* initial = k.memory + 1;
    if (k.memory[0] == 0.0) {
        for (Index i = 0; i < count; ++i)
            for (int c = 0; c < DT::coord; ++c) initial[DT::coord * i + c] = x[DT::coord * indices[i] + c];
        k.memory[0] = 1.0;
    }
    double t0, t1;
    const double *m0, *m1;
    if (!k.find(time, t0, t1, m0, m1)) return;
    const double ratio = (time - t0) / (t1 - t0);
    double m[DT::deriv];
    for (int c = 0; c < DT::deriv; ++c) m[c] = m0[c] + (m1[c] - m0[c]) * ratio;
    if constexpr (DT::rigid) {
        static_assert(DT::coord == 7, "LinearMovementProjectiveConstraint: Rigid3d only among rigids");
        const SofaQuat turn = SofaQuat::from_euler(m0 + 3).slerp2(SofaQuat::from_euler(m1 + 3), ratio);
        for (Index i = 0; i < count; ++i) {
            double* p = x + 7 * indices[i];
            const double* p0 = initial + 7 * i;
            for (int c = 0; c < 3; ++c) p[c] = k.relative ? p0[c] + m[c] : m[c];
            const SofaQuat q = k.relative ? SofaQuat{{p0[3], p0[4], p0[5], p0[6]}} * turn : turn;
            for (int c = 0; c < 4; ++c) p[3 + c] = q.q[c];
        }
    } else {
        for (Index i = 0; i < count; ++i)
            for (int c = 0; c < DT::coord; ++c)
                x[DT::coord * indices[i] + c] = k.relative ? initial[DT::coord * i + c] + m[c] : m[c];
    }
}

// ---- LinearVelocityProjectiveConstraint ------------------------------------------------------------

// The constraint's memory (SOFA's members), one array: [prevT, nextT, finished, captured,
// prevV (deriv), nextV (deriv), xP (count x coord: the constrained DOFs' last projected positions)].
// Every projection first runs SOFA's findKeyTimes at the step's start time while not finished.
template <class DT>
struct KeyedVelocity {
    double* memory;
    const double* key_times;
    const double* key_velocities;  // keys x deriv
    Index keys;
    bool continue_after_end;

    double& previous_time() const { return memory[0]; }
    double& next_time() const { return memory[1]; }
    double* previous_velocity() const { return memory + 4; }
    double* next_velocity() const { return memory + 4 + DT::deriv; }
    double* last_positions() const { return memory + 4 + 2 * DT::deriv; }

    void find_key_times(double time) const {
        if (memory[2] != 0.0 || keys == 0) return;
        if (time > key_times[keys - 1]) {
            for (int c = 0; c < DT::deriv; ++c) previous_velocity()[c] = next_velocity()[c];
            next_time() = INFINITY;
            memory[2] = 1.0;
            return;
        }
        if (time < key_times[0]) return;
        next_time() = key_times[0];
        previous_time() = next_time();
        for (Index k = 0; k < keys; ++k) {
            const bool passed = key_times[k] <= time;
            (passed ? previous_time() : next_time()) = key_times[k];
            double* velocity = passed ? previous_velocity() : next_velocity();
            for (int c = 0; c < DT::deriv; ++c) velocity[c] = key_velocities[DT::deriv * k + c];
            if (!passed) return;  // the first key after `time`
        }
    }

    bool active() const {
        return (memory[2] == 0.0 || continue_after_end) && next_time() != previous_time();
    }

    // The velocity at `time`: interpolated between the keys, the last one once finished.
    void velocity(double time, double* out) const {
        const double ratio = (time - previous_time()) / (next_time() - previous_time());
        for (int c = 0; c < DT::deriv; ++c)
            out[c] = memory[2] != 0.0 ? previous_velocity()[c]
                                      : (next_velocity()[c] - previous_velocity()[c]) * ratio + previous_velocity()[c];
    }
};

// projectResponse: zero the whole derivative of the listed DOFs while the constraint is active.
template <class DT>
inline void keyed_velocity_response(const KeyedVelocity<DT>& k, double* dx, const Index* indices, Index count,
                                    double time) {
    k.find_key_times(time);
    if (k.active()) project_fixed<DT>(dx, indices, count);
}

// projectVelocity: the listed DOFs (their `coordinates`, or all) at the key-interpolated velocity.
template <class DT>
inline void keyed_velocity_velocity(const KeyedVelocity<DT>& k, double* v, const Index* indices, Index count,
                                    const Index* coordinates, Index n_coordinates, double time) {
    k.find_key_times(time);
    if (!k.active()) return;
    double velocity[DT::deriv];
    k.velocity(time, velocity);
    for (Index i = 0; i < count; ++i)
        for (Index c = 0; c < (n_coordinates ? n_coordinates : DT::deriv); ++c) {
            const Index j = n_coordinates ? coordinates[c] : c;
            v[DT::deriv * indices[i] + j] = velocity[j];
        }
}

// projectPosition: x = xP + v dt for the listed DOFs, then xP = x (xP captured at the first call).
template <class DT>
inline void keyed_velocity_position(const KeyedVelocity<DT>& k, double* x, const Index* indices, Index count,
                                    const Index* coordinates, Index n_coordinates, double time, double dt) {
    double* last = k.last_positions();
    if (k.memory[3] == 0.0) {
        for (Index i = 0; i < count; ++i)
            for (int c = 0; c < DT::coord; ++c) last[DT::coord * i + c] = x[DT::coord * indices[i] + c];
        k.memory[3] = 1.0;
    }
    k.find_key_times(time);
    if (!k.active()) return;
    double velocity[DT::deriv];
    k.velocity(time, velocity);
    if constexpr (DT::rigid) {
        // x = xP + v dt with SOFA's RigidCoord + Deriv (the planner refuses `coordinates` on rigids).
        (void)coordinates, (void)n_coordinates;
        for (Index i = 0; i < count; ++i) {
            double* p = x + DT::coord * indices[i];
            advance<DT>(p, last + DT::coord * i, velocity, dt, 1);
            for (int c = 0; c < DT::coord; ++c) last[DT::coord * i + c] = p[c];
        }
        return;
    }
    for (Index i = 0; i < count; ++i) {
        double* p = x + DT::coord * indices[i];
        for (Index c = 0; c < (n_coordinates ? n_coordinates : DT::coord); ++c) {
            const Index j = n_coordinates ? coordinates[c] : c;
            p[j] = last[DT::coord * i + j] + velocity[j] * dt;
        }
        for (int c = 0; c < DT::coord; ++c) last[DT::coord * i + c] = p[c];
    }
}

}  // namespace sofac
