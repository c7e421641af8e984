// JointSpringForceField (Rigid3d): six-degree-of-freedom springs between rigid frames, as SOFA's
// JointSpringForceField.inl at the corpus commit, term by term.
//
// Spring k joins DOF a[k] of object1 and b[k] of object2. Each force pass, in SOFA's order:
//   ref = q1; d = c2 - c1 - initTrans; r = (q1^-1 q2) initRot, normalised; torsion = axis angle of r
//   (quatToAxis, angle in [-pi, pi]); KT_i = hard or soft translation stiffness (axis i free or not);
//   fT = ref (KT .* ref^-1 d) + kd (v2 - v1)_linear;
//   KR_i = hard or soft rotation stiffness, and the torque fR0 by SOFA's cases: all rotations
//   blocked (KR .* torsion), a pivot about x, y or z inside its limits (the swing read from r's
//   matrix), else the general case (torsion beyond a free axis's limits pulled back by the bloc
//   stiffness, which then replaces KR_i);
//   fR = ref fR0 + kd (v2 - v1)_angular; f1[a] += (fT, fR), f2[b] -= (fT, fR).
// The pass stores ref, KT and KR per spring; K dx is SOFA's addDForce with them:
//   df = ref (KT .* ref^-1 (dx2 - dx1)_linear), dR likewise with KR; f1 += kfact (df, dR), f2 -= ...
// (no damping term and no dependence on the rotation of ref: SOFA's approximation). The rest offset
// of a spring that gave REST_T is taken from the positions at the first force pass (SOFA's bwdInit:
// initTrans = c2 - c1, initRot = q2 q1^-1, in that order), REST_R then being overwritten.
#pragma once

#include <cmath>

#include "quaternion.h"
#include "types.h"

namespace sofac {

// Per spring: params (JOINT_PARAMS numbers), rest (initTrans 3, initRot 4), pending (1: rest still
// to take from the positions), memory (ref 4, KT 3, KR 3: the last force pass's, for K dx).
constexpr int JOINT_PARAMS = 18;  // free[6] (0/1), ksT, khT, ksR, khR, kBloc, kd, limits[6]
constexpr int JOINT_MEMORY = 10;

struct JointSprings {
    const Index* a;
    const Index* b;
    const double* params;
    double* rest;
    Index* pending;
    double* memory;
    Index count;
};

namespace joint_detail {
// SOFA's JointSpringForceField::projectTorsion: per rotation axis, the part of the torsion inside
// the limits (0 on a blocked axis, the nearer limit, counted across +-2 pi, outside them).
inline void project_torsion(const double* p, const double* torsion, double* lawful) {
    const double* free_axis = p;
    const double* limits = p + 12;
    for (int i = 0; i < 3; ++i) {
        if (free_axis[3 + i] == 0.0) {
            lawful[i] = 0;
        } else if (torsion[i] > limits[i * 2] && torsion[i] < limits[i * 2 + 1]) {
            lawful[i] = torsion[i];
        } else {
            double d1, d2;
            if (torsion[i] > 0) {
                d1 = torsion[i] - limits[i * 2 + 1];
                d2 = limits[i * 2] + 2 * M_PI - torsion[i];
            } else {
                d1 = torsion[i] - limits[i * 2 + 1] + 2 * M_PI;
                d2 = limits[i * 2] - torsion[i];
            }
            lawful[i] = d1 < d2 ? limits[i * 2 + 1] : limits[i * 2];
        }
    }
}
}  // namespace joint_detail

inline void joint_spring_forces(const JointSprings& s, const double* x1, const double* v1, double* f1,
                                const double* x2, const double* v2, double* f2) {
    for (Index k = 0; k < s.count; ++k) {
        const double* p = s.params + JOINT_PARAMS * k;
        const double* free_axis = p;
        const double soft_t = p[6], hard_t = p[7], soft_r = p[8], hard_r = p[9], bloc = p[10], kd = p[11];
        const double* limits = p + 12;
        double* rest = s.rest + 7 * k;
        double* memory = s.memory + JOINT_MEMORY * k;
        const Index a = s.a[k], b = s.b[k];
        const double* c1 = x1 + 7 * a;
        const double* c2 = x2 + 7 * b;
        const SofaQuat q1 = SofaQuat::load(c1 + 3), q2 = SofaQuat::load(c2 + 3);
        if (s.pending[k]) {  // SOFA's bwdInit
            for (int c = 0; c < 3; ++c) rest[c] = c2[c] - c1[c];
            const SofaQuat initial = q2 * q1.inverse();
            for (int c = 0; c < 4; ++c) rest[3 + c] = initial.q[c];
            s.pending[k] = 0;
        }
        const SofaQuat& ref = q1;
        // Mp1p2 = p2 - p1 (RigidCoord's difference), then the offsets.
        double d[3];
        for (int c = 0; c < 3; ++c) d[c] = c2[c] - c1[c];
        SofaQuat r = q1.inverse() * q2;
        for (int c = 0; c < 3; ++c) d[c] -= rest[c];
        r = r * SofaQuat::load(rest + 3);
        r.normalize();
        const double* w1 = v1 + 6 * a;
        const double* w2 = v2 + 6 * b;
        double dv[6];
        for (int c = 0; c < 6; ++c) dv[c] = w2[c] - w1[c];
        double torsion[3], phi;
        r.to_axis(torsion, phi);
        while (phi < -M_PI) phi += 2 * M_PI;
        while (phi > M_PI) phi -= 2 * M_PI;
        for (double& t : torsion) t *= phi;
        // translation
        double kt[3], kr[3], local[3], scaled[3], ft[3];
        for (int i = 0; i < 3; ++i) kt[i] = free_axis[i] == 0.0 ? hard_t : soft_t;
        ref.inverse_rotate(d, local);
        for (int i = 0; i < 3; ++i) scaled[i] = 0.0 + kt[i] * local[i];  // constantForce (no infile) + KT.*
        ref.rotate(scaled, ft);
        for (int i = 0; i < 3; ++i) ft[i] += dv[i] * kd;
        // rotation
        for (int i = 0; i < 3; ++i) kr[i] = free_axis[3 + i] == 0.0 ? hard_r : soft_r;
        const bool fx = free_axis[3] != 0.0, fy = free_axis[4] != 0.0, fz = free_axis[5] != 0.0;
        double fr0[3];
        if (!fx && !fy && !fz) {  // encastrement
            for (int i = 0; i < 3; ++i) fr0[i] = torsion[i] * kr[i];
        } else if (fx && !fy && !fz && torsion[0] > limits[0] && torsion[0] < limits[1]) {  // pivot about x
            double m[9];
            r.to_matrix(m);
            const double cross = std::sqrt(m[3] * m[3] + m[6] * m[6]);
            const double theta = std::atan2(cross, m[0]);
            fr0[0] = torsion[0] * kr[0];
            fr0[1] = -m[6] * theta * kr[1];
            fr0[2] = m[3] * theta * kr[2];
        } else if (!fx && fy && !fz && torsion[1] > limits[2] && torsion[1] < limits[3]) {  // pivot about y
            double m[9];
            r.to_matrix(m);
            const double cross = std::sqrt(m[1] * m[1] + m[7] * m[7]);
            const double theta = std::atan2(cross, m[4]);
            fr0[0] = m[7] * theta * kr[0];
            fr0[1] = torsion[1] * kr[1];
            fr0[2] = -m[1] * theta * kr[2];
        } else if (!fx && !fy && fz && torsion[2] > limits[4] && torsion[2] < limits[5]) {  // pivot about z
            double m[9];
            r.to_matrix(m);
            const double cross = std::sqrt(m[5] * m[5] + m[2] * m[2]);
            const double theta = std::atan2(cross, m[8]);
            fr0[0] = -m[5] * theta * kr[0];
            fr0[1] = m[2] * theta * kr[1];
            fr0[2] = torsion[2] * kr[2];
        } else {  // general case
            double lawful[3], extra[3];
            joint_detail::project_torsion(p, torsion, lawful);
            for (int i = 0; i < 3; ++i) extra[i] = torsion[i] - lawful[i];
            double psi = std::sqrt(extra[0] * extra[0] + extra[1] * extra[1] + extra[2] * extra[2]);
            // (SOFA divides by psi even when it is 0; the quotients are then never used.)
            if (psi != 0.0)
                for (double& e : extra) e /= psi;
            while (psi < -M_PI) psi += 2 * M_PI;
            while (psi > M_PI) psi -= 2 * M_PI;
            for (double& e : extra) e *= psi;
            for (int i = 0; i < 3; ++i) {
                if (free_axis[3 + i] != 0.0 && torsion[i] != lawful[i]) {  // outside the limits
                    kr[i] = bloc;
                    fr0[i] = extra[i] * kr[i];
                } else {
                    fr0[i] = torsion[i] * kr[i];
                }
            }
        }
        double fr[3];
        for (double& t : fr0) t = 0.0 + t;  // constantForce (no infile) + fR0
        ref.rotate(fr0, fr);
        for (int i = 0; i < 3; ++i) fr[i] += dv[3 + i] * kd;
        double* g1 = f1 + 6 * a;
        double* g2 = f2 + 6 * b;
        for (int i = 0; i < 3; ++i) {
            g1[i] += ft[i];
            g1[3 + i] += fr[i];
        }
        for (int i = 0; i < 3; ++i) {
            g2[i] -= ft[i];
            g2[3 + i] -= fr[i];
        }
        for (int c = 0; c < 4; ++c) memory[c] = ref.q[c];
        for (int i = 0; i < 3; ++i) {
            memory[4 + i] = kt[i];
            memory[7 + i] = kr[i];
        }
    }
}

inline void joint_spring_dforces(const JointSprings& s, const double* dx1, double* df1, const double* dx2,
                                 double* df2, double kfact) {
    for (Index k = 0; k < s.count; ++k) {
        const double* memory = s.memory + JOINT_MEMORY * k;
        const SofaQuat ref = SofaQuat::load(memory);
        const Index a = s.a[k], b = s.b[k];
        double delta[6];
        for (int c = 0; c < 6; ++c) delta[c] = dx2[6 * b + c] - dx1[6 * a + c];
        double dforce[6];
        for (int part = 0; part < 2; ++part) {
            const double* stiffness = memory + 4 + 3 * part;
            double local[3];
            ref.inverse_rotate(delta + 3 * part, local);
            for (int i = 0; i < 3; ++i) local[i] = stiffness[i] * local[i];
            ref.rotate(local, dforce + 3 * part);
        }
        for (int c = 0; c < 6; ++c) df1[6 * a + c] += dforce[c] * kfact;
        for (int c = 0; c < 6; ++c) df2[6 * b + c] -= dforce[c] * kfact;
    }
}

// The blocks addDForce applies: per spring and part (translation, rotation) B = R diag(K) R^T with
// R ref's matrix; A += kfact [[-B, B], [B, -B]] over (a, b). Every entry is added, zeros included,
// so that the pattern (assembled with zero memory at init) holds the later values.
template <class Assembler>
inline void assemble_joint_springs(Assembler& A, const JointSprings& s, Index offset1, Index offset2,
                                   double kfact) {
    for (Index k = 0; k < s.count; ++k) {
        const double* memory = s.memory + JOINT_MEMORY * k;
        const SofaQuat ref = SofaQuat::load(memory);
        const Index a = offset1 + 6 * s.a[k], b = offset2 + 6 * s.b[k];
        for (int part = 0; part < 2; ++part) {
            const double* stiffness = memory + 4 + 3 * part;
            double block[9];
            for (int column = 0; column < 3; ++column) {  // B e_column, as K dx computes it
                double unit[3] = {0.0, 0.0, 0.0}, local[3], out[3];
                unit[column] = 1.0;
                ref.inverse_rotate(unit, local);
                for (int i = 0; i < 3; ++i) local[i] = stiffness[i] * local[i];
                ref.rotate(local, out);
                for (int row = 0; row < 3; ++row) block[3 * row + column] = out[row];
            }
            const Index base = 3 * part;
            for (int row = 0; row < 3; ++row)
                for (int column = 0; column < 3; ++column) {
                    const double value = kfact * block[3 * row + column];
                    const Index i = base + row, j = base + column;
                    A.add(a + i, a + j, -value);
                    A.add(a + i, b + j, value);
                    A.add(b + i, a + j, value);
                    A.add(b + i, b + j, -value);
                }
        }
    }
}

}  // namespace sofac
