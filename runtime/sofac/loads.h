// Loads and projective constraints with a geometric target: PlaneForceField,
// UniformVelocityDampingForceField, and the Line / Plane / Point projective constraints.
// Operation order follows SOFA's components (the scenes' results must match SOFA's).
#pragma once

#include <cmath>

#include "types.h"

namespace sofac {

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

// ---- UniformVelocityDampingForceField ------------------------------------------------------------

// f -= c v on every scalar of every DOF (explicit: no df/dv in implicit solves).
inline void velocity_damping(double* f, const double* v, const double* coefficient, Index size) {
    const double c = coefficient[0];
    for (Index k = 0; k < size; ++k) f[k] -= v[k] * c;
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

}  // namespace sofac
