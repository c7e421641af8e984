// Finite-element force fields of SOFA's Sofa.Component.SolidMechanics.FEM.Elastic, Vec3d only:
// TetrahedronFEMForceField, TetrahedralCorotationalFEMForceField, HexahedronFEMForceField.
//
// The formulas and, where it matters for bit-level agreement, the order of the floating-point
// operations follow SOFA (commit 2a278d89, the corpus commit). Written from a reading of SOFA's
// sources; no SOFA code is included. Notes on the conventions: see the comments of each section.
//
// Conventions shared by all kernels
// - Positions and forces are flat Vec3d arrays (3 doubles per point).
// - Elements are flat index arrays (4 per tetrahedron, 8 per hexahedron), in the topology's order.
// - `method`: 0 = small, 1 = large, 2 = polar, 3 = svd (tetrahedra only). SOFA maps an unknown
//   method string to "large".
// - Everything an element needs is precomputed by *_init into `element_data`, a caller-owned array:
//   hexahedra: n_elements * hexa_fem_data_size(method) doubles (element e at offset e * size);
//   tetrahedra: tetra_fem_data_count(method, n_elements) doubles, in blocks of TETRA_LANES elements
//   (see tetra_fem_data_count).
//   *_add_force also writes the element's current rotation there (SOFA's `rotations[i]`), which
//   *_add_dforce reads; so add_dforce linearizes around the positions of the last add_force, as SOFA.
// - add_force: f += f(x) (internal elastic force, f = -K (x - x0) for small displacements).
//   add_dforce: df += kfactor * (df/dx) dx, with SOFA's df/dx (see below); kfactor is SOFA's
//   kFactorIncludingRayleighDamping = mparams.kFactor + mparams.bFactor * rayleighStiffness, where
//   rayleighStiffness is the force field's own data (default 0), not the solver's.
// - No allocation, no exceptions; functions are inline and not thread-safe per element_data.
//
// Material parameters (BaseLinearElasticityFEMForceField): youngModulus / poissonRatio are lists;
// element i uses list[i] if the list has more than i values, else list[0]; an empty list uses the
// default (5000 / 0.45). SOFA's init replaces a negative Young's modulus by 5000 and a Poisson ratio
// outside [0, 0.5) by 0.45 (with a warning); these kernels do the same.
//
// Plasticity (plasticMaxThreshold > 0) and updateStiffnessMatrix: tetra_fem_add_force_options. Not
// reproduced: computeGlobalMatrix=true (assembled-in-addForce path), von Mises stress, topological changes.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>

#include "parallel.h"
#include "types.h"

namespace sofac {

// Tetrahedra processed at once by the vectorised kernels (see tetra_fem_data_count).
constexpr int TETRA_LANES = 4;

// The FEM force fields' `method`, as the kernels take it (an int: SOFA's order of the names).
enum FemMethod : int { FEM_SMALL = 0, FEM_LARGE = 1, FEM_POLAR = 2, FEM_SVD = 3 };

namespace fem_detail {

// Row-major 3x3 matrix and 3-vector with SOFA's evaluation order (no Eigen: Eigen is free to
// reorder sums and products, which would change the last bits).
struct M3 {
    double a[3][3];
    double& operator()(int i, int j) { return a[i][j]; }
    double operator()(int i, int j) const { return a[i][j]; }
};
struct V3 {
    double v[3];
    double& operator[](int i) { return v[i]; }
    double operator[](int i) const { return v[i]; }
};

inline V3 load(const double* p) { return V3{{p[0], p[1], p[2]}}; }
inline V3 sub(const V3& a, const V3& b) { return V3{{a[0] - b[0], a[1] - b[1], a[2] - b[2]}}; }
inline V3 cross(const V3& a, const V3& b) {
    return V3{{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}};
}
inline double dot3(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline double norm(const V3& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }
inline void sqrt_lanes(double& v) { v = std::sqrt(v); }
// TETRA_LANES doubles in one vector (GCC's vector extension, also in Clang): one lane per element.
typedef double Lanes __attribute__((vector_size(8 * TETRA_LANES)));
inline void sqrt_lanes(Lanes& v) {
    for (int l = 0; l < TETRA_LANES; ++l) v[l] = std::sqrt(v[l]);
}
// SOFA's Vec::normalize: divides by the norm unless it is <= machine epsilon (then unchanged).
inline void normalize(V3& a) {
    const double n = norm(a);
    if (n > DBL_EPSILON) {
        a[0] /= n;
        a[1] /= n;
        a[2] /= n;
    }
}
// SOFA's Mat * Vec: r_i = ((m_i0 v0 + m_i1 v1) + m_i2 v2).
inline V3 mul(const M3& m, const V3& v) {
    V3 r;
    for (int i = 0; i < 3; ++i) r[i] = m(i, 0) * v[0] + m(i, 1) * v[1] + m(i, 2) * v[2];
    return r;
}
// SOFA's Mat::multTranspose(Vec): r_i = sum_j m_ji v_j.
inline V3 mul_t(const M3& m, const V3& v) {
    V3 r;
    for (int i = 0; i < 3; ++i) r[i] = m(0, i) * v[0] + m(1, i) * v[1] + m(2, i) * v[2];
    return r;
}
// SOFA's 3x3 Mat * Mat.
inline M3 mul(const M3& a, const M3& b) {
    M3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(i, 0) * b(0, j) + a(i, 1) * b(1, j) + a(i, 2) * b(2, j);
    return r;
}
// a^T b (SOFA's 3x3 multTranspose(Mat, Mat)).
inline M3 mul_tn(const M3& a, const M3& b) {
    M3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(0, i) * b(0, j) + a(1, i) * b(1, j) + a(2, i) * b(2, j);
    return r;
}
// a b^T (SOFA's Mat::multTransposed).
inline M3 mul_nt(const M3& a, const M3& b) {
    M3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(i, 0) * b(j, 0) + a(i, 1) * b(j, 1) + a(i, 2) * b(j, 2);
    return r;
}
inline M3 transposed(const M3& m) {
    M3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = m(j, i);
    return r;
}
inline M3 identity() { return M3{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}; }
inline M3 from_rows(const V3& x, const V3& y, const V3& z) {
    return M3{{{x[0], x[1], x[2]}, {y[0], y[1], y[2]}, {z[0], z[1], z[2]}}};
}
inline M3 load_m(const double* p) {
    return M3{{{p[0], p[1], p[2]}, {p[3], p[4], p[5]}, {p[6], p[7], p[8]}}};
}
inline void store_m(double* p, const M3& m) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) p[3 * i + j] = m(i, j);
}
inline double determinant(const M3& m) {
    return m(0, 0) * m(1, 1) * m(2, 2) + m(1, 0) * m(2, 1) * m(0, 2) + m(2, 0) * m(0, 1) * m(1, 2) -
           m(0, 0) * m(2, 1) * m(1, 2) - m(1, 0) * m(0, 1) * m(2, 2) - m(2, 0) * m(1, 1) * m(0, 2);
}
// SOFA's invertMatrix (3x3): cofactors divided by the determinant. Returns false if det == 0.
inline bool invert(M3& r, const M3& m) {
    const double det = determinant(m);
    if (det == 0.0) return false;
    r(0, 0) = (m(1, 1) * m(2, 2) - m(2, 1) * m(1, 2)) / det;
    r(1, 0) = (m(1, 2) * m(2, 0) - m(2, 2) * m(1, 0)) / det;
    r(2, 0) = (m(1, 0) * m(2, 1) - m(2, 0) * m(1, 1)) / det;
    r(0, 1) = (m(2, 1) * m(0, 2) - m(0, 1) * m(2, 2)) / det;
    r(1, 1) = (m(2, 2) * m(0, 0) - m(0, 2) * m(2, 0)) / det;
    r(2, 1) = (m(2, 0) * m(0, 1) - m(0, 0) * m(2, 1)) / det;
    r(0, 2) = (m(0, 1) * m(1, 2) - m(1, 1) * m(0, 2)) / det;
    r(1, 2) = (m(0, 2) * m(1, 0) - m(1, 2) * m(0, 0)) / det;
    r(2, 2) = (m(0, 0) * m(1, 1) - m(1, 0) * m(0, 1)) / det;
    return true;
}
inline double one_norm(const M3& m) {  // max column sum of |m_ij|
    double best = 0.0;
    for (int j = 0; j < 3; ++j) {
        const double s = std::fabs(m(0, j)) + std::fabs(m(1, j)) + std::fabs(m(2, j));
        if (s > best) best = s;
    }
    return best;
}
inline double inf_norm(const M3& m) {  // max row sum of |m_ij|
    double best = 0.0;
    for (int i = 0; i < 3; ++i) {
        const double s = std::fabs(m(i, 0)) + std::fabs(m(i, 1)) + std::fabs(m(i, 2));
        if (s > best) best = s;
    }
    return best;
}

// Orthogonal factor Q of the polar decomposition M = Q S, by SOFA's helper::Decompose::
// polarDecomposition (Shoemake/Higham scaled Newton iteration on M^T, Barbic's variant):
// Mk <- gamma/2 Mk + 1/(2 gamma det) adj(Mk)^T with gamma = ((|adj|_1 |adj|_inf)/(|Mk|_1 |Mk|_inf))^(1/4)
// / sqrt|det|, until |Mk - Mk_prev|_1 <= 1e-8 |Mk|_1; Q = Mk^T. For det(M) < 0 the result is an
// improper orthogonal matrix (a reflection), as in SOFA. Stops (keeping Mk) on a zero determinant.
inline M3 polar_rotation(const M3& m) {
    M3 mk = transposed(m);
    double m_one = one_norm(mk);
    double m_inf = inf_norm(mk);
    double e_one = 0.0;
    do {
        M3 adj;
        const V3 r0{{mk(0, 0), mk(0, 1), mk(0, 2)}};
        const V3 r1{{mk(1, 0), mk(1, 1), mk(1, 2)}};
        const V3 r2{{mk(2, 0), mk(2, 1), mk(2, 2)}};
        adj = from_rows(cross(r1, r2), cross(r2, r0), cross(r0, r1));
        const double det = mk(0, 0) * adj(0, 0) + mk(0, 1) * adj(0, 1) + mk(0, 2) * adj(0, 2);
        if (det == 0.0) break;
        const double adj_one = one_norm(adj);
        const double adj_inf = inf_norm(adj);
        const double gamma = std::sqrt(std::sqrt((adj_one * adj_inf) / (m_one * m_inf)) / std::fabs(det));
        const double g1 = gamma * 0.5;
        const double g2 = 0.5 / (gamma * det);
        M3 ek = mk;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) mk(i, j) = mk(i, j) * g1 + adj(i, j) * g2;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) ek(i, j) -= mk(i, j);
        e_one = one_norm(ek);
        m_one = one_norm(mk);
        m_inf = inf_norm(mk);
    } while (e_one > m_one * 1e-8);
    return transposed(mk);
}

// Symmetric 3x3 eigen decomposition as SOFA's Decompose::eigenDecomposition_iterative: one
// Householder step to tridiagonal form, then the implicit QL iteration (at most 32 sweeps per
// eigenvalue). Eigenvectors are the columns of v, eigenvalues in diag (unsorted).
inline void eigen_symmetric(const M3& m, M3& v, V3& diag) {
    V3 sub{{0.0, 0.0, 0.0}};
    double m01 = m(0, 1);
    double m02 = m(0, 2);
    const double m00 = m(0, 0), m11 = m(1, 1), m12 = m(1, 2), m22 = m(2, 2);
    diag[0] = m00;
    sub[2] = 0.0;
    if (m02 != 0.0) {
        const double length = std::sqrt(m01 * m01 + m02 * m02);
        const double inv_length = 1.0 / length;
        m01 *= inv_length;
        m02 *= inv_length;
        const double q = 2.0 * m01 * m12 + m02 * (m22 - m11);
        diag[1] = m11 + m02 * q;
        diag[2] = m22 - m02 * q;
        sub[0] = length;
        sub[1] = m12 - m01 * q;
        v = M3{{{1.0, 0.0, 0.0}, {0.0, m01, m02}, {0.0, m02, -m01}}};
    } else {
        diag[1] = m11;
        diag[2] = m22;
        sub[0] = m01;
        sub[1] = m12;
        v = identity();
    }
    constexpr int max_sweeps = 32;
    for (int i0 = 0; i0 < 3; ++i0) {
        int sweep = 0;
        for (; sweep < max_sweeps; ++sweep) {
            int i2 = i0;
            for (; i2 <= 1; ++i2) {  // find a negligible off-diagonal entry
                const double t = std::fabs(diag[i2]) + std::fabs(diag[i2 + 1]);
                if (std::fabs(sub[i2]) + t == t) break;
            }
            if (i2 == i0) break;
            double g = (diag[i0 + 1] - diag[i0]) / (2.0 * sub[i0]);
            double r = std::sqrt(g * g + 1.0);
            if (g < 0.0)
                g = diag[i2] - diag[i0] + sub[i0] / (g - r);
            else
                g = diag[i2] - diag[i0] + sub[i0] / (g + r);
            double s = 1.0, c = 1.0, p = 0.0;
            for (int i3 = i2 - 1; i3 >= i0; --i3) {
                double f = s * sub[i3];
                const double b = c * sub[i3];
                if (std::fabs(f) >= std::fabs(g)) {
                    c = g / f;
                    r = std::sqrt(c * c + 1.0);
                    sub[i3 + 1] = f * r;
                    s = 1.0 / r;
                    c *= s;
                } else {
                    s = f / g;
                    r = std::sqrt(s * s + 1.0);
                    sub[i3 + 1] = g * r;
                    c = 1.0 / r;
                    s *= c;
                }
                g = diag[i3 + 1] - p;
                r = (diag[i3] - g) * s + 2.0 * b * c;
                p = s * r;
                diag[i3 + 1] = g + p;
                g = c * r - b;
                for (int k = 0; k < 3; ++k) {
                    f = v(k, i3 + 1);
                    v(k, i3 + 1) = s * v(k, i3) + c * f;
                    v(k, i3) = c * v(k, i3) - s * f;
                }
            }
            diag[i0] -= p;
            sub[i0] = g;
            sub[i2] = 0.0;
        }
        if (sweep == max_sweeps) return;
    }
}

// Rotation of SOFA's Decompose::polarDecomposition_stable: Q = U V^T from SVD_stable (F^T F = V S^2
// V^T, U = F V S^-1), made a proper rotation for inverted elements (the column of the smallest
// singular value flipped) and completed for flat (1 null value), linear (2) or collapsed (3) ones.
inline M3 svd_stable_rotation(const M3& f) {
    const M3 ftf = mul_tn(f, f);
    M3 v;
    V3 s;
    eigen_symmetric(ftf, v, s);
    if (determinant(v) < 0.0)
        for (int i = 0; i < 3; ++i) v(i, 0) = -v(i, 0);
    int degenerated = 0;
    V3 s_inv;
    for (int i = 0; i < 3; ++i) {
        if (s[i] < 1e-8) {
            ++degenerated;
            s[i] = 0.0;
            s_inv[i] = 1.0;
        } else {
            s[i] = std::sqrt(s[i]);
            s_inv[i] = 1.0 / s[i];
        }
    }
    int order[3];  // indices of the singular values, ascending (SOFA's decision tree)
    if (s[0] < s[1]) {
        if (s[0] < s[2]) {
            order[0] = 0;
            if (s[1] < s[2]) {
                order[1] = 1;
                order[2] = 2;
            } else {
                order[1] = 2;
                order[2] = 1;
            }
        } else {
            order[0] = 2;
            order[1] = 0;
            order[2] = 1;
        }
    } else {
        if (s[1] < s[2]) {
            order[0] = 1;
            if (s[0] < s[2]) {
                order[1] = 0;
                order[2] = 2;
            } else {
                order[1] = 2;
                order[2] = 0;
            }
        } else {
            order[0] = 2;
            order[1] = 1;
            order[2] = 0;
        }
    }
    M3 vs;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) vs(i, j) = v(i, j) * s_inv[j];
    M3 u = mul(f, vs);
    if (degenerated == 1) {
        const V3 c = cross(V3{{u(0, order[1]), u(1, order[1]), u(2, order[1])}},
                           V3{{u(0, order[2]), u(1, order[2]), u(2, order[2])}});
        for (int i = 0; i < 3; ++i) u(i, order[0]) = c[i];
    } else if (degenerated == 2) {
        // SOFA builds the kept edge from mixed columns (row 0 of the largest, rows 1-2 of the
        // smallest singular vector); reproduced as is.
        const V3 edge2{{u(0, order[2]), u(1, order[0]), u(2, order[0])}};
        const double a0 = std::fabs(edge2[0]), a1 = std::fabs(edge2[1]), a2 = std::fabs(edge2[2]);
        V3 edge0;
        if (a0 > a1)
            edge0 = a0 > a2 ? V3{{0, 1, 0}} : V3{{1, 0, 0}};
        else
            edge0 = a1 > a2 ? V3{{0, 0, 1}} : V3{{1, 0, 0}};
        V3 edge1 = cross(edge2, edge0);
        normalize(edge1);
        edge0 = cross(edge1, edge2);
        for (int i = 0; i < 3; ++i) {
            u(i, order[0]) = edge0[i];
            u(i, order[1]) = edge1[i];
        }
    } else if (degenerated == 3) {
        u = identity();
    }
    if (determinant(u) < 0.0)
        for (int i = 0; i < 3; ++i) u(i, order[0]) *= -1.0;
    return mul_nt(u, v);
}

// Material parameter of element i (BaseLinearElasticityFEMForceField::getVecRealInElement): its
// own value, else the first. n >= 1: the plan gives an empty list the registry's default.
inline double element_value(const double* list, Index n, Index i) { return n > i ? list[i] : list[0]; }

// ---- tetrahedra: SOFA's element quantities --------------------------------------------------

// SOFA's 2x3 "pseudo determinant" of rows (p, q): the cofactor of the 3 points' coordinates.
inline double pseudo_det(double p0, double p1, double p2, double q0, double q1, double q2) {
    return p1 * q2 - q1 * p2 - p0 * q2 + q0 * p2 + p0 * q1 - q0 * p1;
}

// Strain-displacement cofactors (SOFA's computeStrainDisplacement), compacted: SOFA's 12x6 matrix J
// has for node n (rows 3n..3n+2) three distinct values alpha_n, beta_n, gamma_n (6 V times the
// shape function gradient dN_n/dx, dN_n/dy, dN_n/dz, up to the orientation sign):
//   J(3n,0)=J(3n+1,3)=J(3n+2,5)=alpha_n  J(3n,3)=J(3n+1,1)=J(3n+2,4)=beta_n
//   J(3n,5)=J(3n+1,4)=J(3n+2,2)=gamma_n, all other entries 0; Voigt order xx yy zz xy yz zx.
// Stored as j[3n + {0,1,2}] = {alpha_n, beta_n, gamma_n}.
inline void strain_displacement(double* j, const V3& a, const V3& b, const V3& c, const V3& d) {
    const V3* pts[4] = {&a, &b, &c, &d};
    for (int n = 0; n < 4; ++n) {
        const V3& p = *pts[(n + 1) % 4];
        const V3& q = *pts[(n + 2) % 4];
        const V3& r = *pts[(n + 3) % 4];
        const double sign = (n % 2 == 0) ? -1.0 : 1.0;  // -,+,- for nodes 0 and 2; +,-,+ for 1 and 3
        const double yz = pseudo_det(p[1], q[1], r[1], p[2], q[2], r[2]);
        const double xz = pseudo_det(p[0], q[0], r[0], p[2], q[2], r[2]);
        const double xy = pseudo_det(p[0], q[0], r[0], p[1], q[1], r[1]);
        j[3 * n + 0] = sign < 0 ? -yz : yz;
        j[3 * n + 1] = sign < 0 ? xz : -xz;
        j[3 * n + 2] = sign < 0 ? -xy : xy;
    }
}

// SOFA's computeForce for tetrahedra: F = J (K (J^T D)) exploiting the zeros, with an optional
// factor applied to K J^T D (the addDForce variant). mat = {K00, K01, K33} (K11 = K22 = K00,
// off-diagonal normal terms = K01, shear terms = K33), already divided by 36 V.
// T is double, or a vector of doubles holding that many elements (one per lane) for the
// vectorised kernels: each lane then does exactly the scalar operations, in the same order.
// In two halves, so that plasticity (tetra_plastic_strain) can act on the strain between them.
// The strain J^T D (Voigt xx yy zz xy yz zx) of the 12 displacements D. jn: the cofactors in J's
// normal-strain columns 0-2 (J(3n, 0), J(3n+1, 1), J(3n+2, 2)), js: those in its shear columns 3-5;
// the same array except after SOFA's updateStiffnessMatrix with method large, which rewrites the
// normal ones only.
template <class T>
inline void tetra_strain(T* e, const T* D, const T* jn, const T* js) {
    e[0] = jn[0] * D[0] + jn[3] * D[3] + jn[6] * D[6] + jn[9] * D[9];
    e[1] = jn[1] * D[1] + jn[4] * D[4] + jn[7] * D[7] + jn[10] * D[10];
    e[2] = jn[2] * D[2] + jn[5] * D[5] + jn[8] * D[8] + jn[11] * D[11];
    const T a0 = js[0], b0 = js[1], g0 = js[2];
    const T a1 = js[3], b1 = js[4], g1 = js[5];
    const T a2 = js[6], b2 = js[7], g2 = js[8];
    const T a3 = js[9], b3 = js[10], g3 = js[11];
    e[3] = b0 * D[0] + a0 * D[1] + b1 * D[3] + a1 * D[4] + b2 * D[6] + a2 * D[7] + b3 * D[9] + a3 * D[10];
    e[4] = g0 * D[1] + b0 * D[2] + g1 * D[4] + b1 * D[5] + g2 * D[7] + b2 * D[8] + g3 * D[10] + b3 * D[11];
    e[5] = g0 * D[0] + a0 * D[2] + g1 * D[3] + a1 * D[5] + g2 * D[6] + a2 * D[8] + g3 * D[9] + a3 * D[11];
}
// F = J (fact K e) of a strain e.
template <class T>
inline void tetra_strain_force(T* F, const T* e, const T* jn, const T* js, const T* mat, const T& fact,
                               bool scale) {
    const T kd = mat[0], ko = mat[1], ks = mat[2];
    T s[6];
    s[0] = kd * e[0] + ko * e[1] + ko * e[2];
    s[1] = ko * e[0] + kd * e[1] + ko * e[2];
    s[2] = ko * e[0] + ko * e[1] + kd * e[2];
    s[3] = ks * e[3];
    s[4] = ks * e[4];
    s[5] = ks * e[5];
    if (scale)
        for (T& v : s) v *= fact;
    for (int n = 0; n < 4; ++n) {
        const T a = js[3 * n], b = js[3 * n + 1], g = js[3 * n + 2];
        F[3 * n + 0] = jn[3 * n] * s[0] + b * s[3] + g * s[5];
        F[3 * n + 1] = jn[3 * n + 1] * s[1] + a * s[3] + g * s[4];
        F[3 * n + 2] = jn[3 * n + 2] * s[2] + b * s[4] + a * s[5];
    }
}
template <class T>
inline void tetra_compute_force(T* F, const T* D, const T* jn, const T* js, const T* mat, const T& fact,
                                bool scale) {
    T e[6];
    tetra_strain(e, D, jn, js);
    tetra_strain_force(F, e, jn, js, mat, fact, scale);
}
template <class T>
inline void tetra_compute_force(T* F, const T* D, const T* j, const T* mat, const T& fact, bool scale) {
    tetra_compute_force(F, D, j, j, mat, fact, scale);
}

// SOFA's squared norm of a Voigt vector (r = v0^2, then += vi^2 in order).
inline double voigt_norm2(const double* v) {
    double r = v[0] * v[0];
    for (int i = 1; i < 6; ++i) r += v[i] * v[i];
    return r;
}

// SOFA's plasticity of computeForce (plasticMaxThreshold > 0), applied to the total strain e of an
// element with plastic strain p (6 numbers, carried from step to step): the elastic strain e - p,
// when its 2-norm exceeds the yield threshold, moves the fraction `creep` of itself into p; p is
// then scaled back onto the sphere of radius max_threshold if it left it; e becomes e - p.
inline void tetra_plastic_strain(double* e, double* p, double max_threshold, double yield_threshold, double creep) {
    double elastic[6];
    for (int i = 0; i < 6; ++i) elastic[i] = e[i] - p[i];
    if (voigt_norm2(elastic) > yield_threshold * yield_threshold)
        for (int i = 0; i < 6; ++i) p[i] += creep * elastic[i];
    const double p_norm2 = voigt_norm2(p);
    if (p_norm2 > max_threshold * max_threshold) {
        const double ratio = max_threshold / std::sqrt(p_norm2);
        for (int i = 0; i < 6; ++i) p[i] *= ratio;
    }
    for (int i = 0; i < 6; ++i) e[i] -= p[i];
}

// R^T v and R v for a row-major 3x3 R (9 numbers), as mul_t and mul (SOFA's order), on T.
template <class T>
inline void rotate_t(const T* R, const T* v, T* r) {
    for (int i = 0; i < 3; ++i) r[i] = R[i] * v[0] + R[3 + i] * v[1] + R[6 + i] * v[2];
}
template <class T>
inline void rotate(const T* R, const T* v, T* r) {
    for (int i = 0; i < 3; ++i) r[i] = R[3 * i] * v[0] + R[3 * i + 1] * v[1] + R[3 * i + 2] * v[2];
}

// SOFA's addDForce of one element on T: the 12 numbers R (J K J^T) (kfactor R^T dx) (R = the
// element's rotation, local -> world; none for small) that SOFA subtracts from df. X: the 12
// numbers of dx at the element's nodes.
template <class T, bool Rotated>
inline void tetra_dforce_element(const T* R, const T* jn, const T* js, const T* mat, const T& kfactor, const T* X,
                                 T* out) {
    T L[12];
    if (Rotated) {
        for (int k = 0; k < 4; ++k) rotate_t(R, X + 3 * k, L + 3 * k);
    } else {
        for (int k = 0; k < 12; ++k) L[k] = X[k];
    }
    T F[12];
    tetra_compute_force(F, L, jn, js, mat, kfactor, true);
    if (Rotated) {
        for (int k = 0; k < 4; ++k) rotate(R, F + 3 * k, out + 3 * k);
    } else {
        for (int k = 0; k < 12; ++k) out[k] = F[k];
    }
}

// Gram-Schmidt frame of SOFA's computeRotationLarge: x along edge a->b, z normal to (a->b, a->c),
// y = z x x. Rows of the result are the frame axes (a world -> local rotation).
// On T (double or a vector of lanes): the frame's rows as 9 numbers, a, b, c 3 numbers each; the
// operations of normalize, sub and cross in their order (a vector divides every lane and keeps
// the quotient where the norm is above epsilon: the same numbers).
template <class T>
inline void normalize_lanes(T* a) {
    const T squared = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    T n = squared;
    sqrt_lanes(n);
    const auto above = n > DBL_EPSILON;
    for (int i = 0; i < 3; ++i) a[i] = above ? a[i] / n : a[i];
}
template <class T>
inline void cross_lanes(const T* a, const T* b, T* r) {
    r[0] = a[1] * b[2] - a[2] * b[1];
    r[1] = a[2] * b[0] - a[0] * b[2];
    r[2] = a[0] * b[1] - a[1] * b[0];
}
template <class T>
inline void tetra_frame_rows(const T* a, const T* b, const T* c, T* rows) {
    T* ex = rows;
    T* ey = rows + 3;
    T* ez = rows + 6;
    T ac[3];
    for (int m = 0; m < 3; ++m) ex[m] = b[m] - a[m];
    normalize_lanes(ex);
    for (int m = 0; m < 3; ++m) ac[m] = c[m] - a[m];
    cross_lanes(ex, ac, ez);
    normalize_lanes(ez);
    cross_lanes(ez, ex, ey);
}

inline M3 tetra_frame(const V3& a, const V3& b, const V3& c) {
    M3 r;
    tetra_frame_rows(a.v, b.v, c.v, &r.a[0][0]);
    return r;
}

inline M3 edge_rows(const V3& a, const V3& b, const V3& c, const V3& d) {
    return from_rows(sub(b, a), sub(c, a), sub(d, a));
}

// Per-element layout (offsets in doubles).
constexpr int TJ = 0;     // 12 strain-displacement cofactors
constexpr int TMAT = 12;  // 3 material values {K00, K01, K33} / (36 V)
constexpr int TSMALL_REST = 15;  // small: 9 = rest edges X0[b]-X0[a], X0[c]-X0[a], X0[d]-X0[a]
constexpr int TROT = 15;  // large/polar/svd: 9 = SOFA's rotations[i] (local -> world), row-major
constexpr int TREST = 24;  // large: 6 = rotated rest (r1x, r2x, r2y, r3x, r3y, r3z); polar/svd: 12
constexpr int TINITROT = 36;  // svd: 9 = SOFA's _initialRotations[i] (R_0_1^T)
constexpr int TINITINV = 45;  // svd: 9 = SOFA's _initialTransformation[i] (inverse rest edge rows)

}  // namespace fem_detail

// ================================================================================================
// TetrahedronFEMForceField (Vec3d)
// ================================================================================================
//
// Element data, doubles per element (see fem_detail offsets):
//   small 24 = J cofactors 12 + material 3 + rest edges 9
//   large 30 = J 12 + material 3 + rotation 9 + rotated rest edges 6
//   polar 36 = J 12 + material 3 + rotation 9 + rotated rest points 12
//   svd   54 = polar 36 + initial rotation 9 + inverse rest edge matrix 9
constexpr int tetra_fem_data_size(int method) {
    return method == 0 ? 24 : method == 1 ? 30 : method == 2 ? 36 : 54;
}

// Tetrahedron element data is stored in blocks of TETRA_LANES consecutive elements, field-major
// inside a block (a structure of arrays per block): number f (a fem_detail offset) of element e
// is at data[(e / TETRA_LANES) * TETRA_LANES * size + f * TETRA_LANES + e % TETRA_LANES], so the
// vectorised kernels load one number of TETRA_LANES elements with one load. The array holds whole
// blocks (the lanes past the last element stay unused): tetra_fem_data_count doubles.
constexpr Index tetra_fem_data_count(int method, Index n) {
    return (n + TETRA_LANES - 1) / TETRA_LANES * TETRA_LANES * tetra_fem_data_size(method);
}

namespace fem_detail {

// Element e's numbers [first, first + count) between the blocked data and a flat record (the
// per-element layout of the offsets above), for the scalar kernels.
inline void tetra_unpack(const double* data, Index e, int stride, int first, int count, double* record) {
    const double* p = data + e / TETRA_LANES * TETRA_LANES * stride + e % TETRA_LANES;
    for (int f = first; f < first + count; ++f) record[f] = p[f * TETRA_LANES];
}
inline void tetra_pack(double* data, Index e, int stride, int first, int count, const double* record) {
    double* p = data + e / TETRA_LANES * TETRA_LANES * stride + e % TETRA_LANES;
    for (int f = first; f < first + count; ++f) p[f * TETRA_LANES] = record[f];
}

}  // namespace fem_detail

// Precomputes per element what SOFA's reinit does: material stiffness (isotropic Hooke, divided by
// 36 |V0|), strain-displacement cofactors in the element's rest frame (world frame for small; the
// Gram-Schmidt frame of edges 0->1, 0->2 for large; the polar rotation of the rest edge rows for
// polar/svd), the rotated rest positions, and the initial rotation (current rotation = initial).
// young/poisson: per-element lists (see the header comment). local_stiffness_factor (optional,
// SOFA's `localStiffnessFactor`, M values): element i uses factor[i * M / n_tetra] * E_i.
inline void tetra_fem_init(const Index* tetra, Index n_tetra, const double* rest_x, const double* young,
                           Index n_young, const double* poisson, Index n_poisson, int method,
                           double* element_data, const double* local_stiffness_factor = nullptr,
                           Index n_factor = 0) {
    using namespace fem_detail;
    const int stride = tetra_fem_data_size(method);
    for (Index i = 0; i < n_tetra; ++i) {
        double e[54];
        const Index* t = tetra + 4 * i;
        const V3 a = load(rest_x + 3 * t[0]), b = load(rest_x + 3 * t[1]);
        const V3 c = load(rest_x + 3 * t[2]), d = load(rest_x + 3 * t[3]);

        // computeMaterialStiffness
        const double factor = n_factor > 0 ? local_stiffness_factor[i * n_factor / n_tetra] : 1.0;
        const double E = factor * element_value(young, n_young, i);
        const double nu = element_value(poisson, n_poisson, i);
        const double scale = (E * (1 - nu)) / ((1 + nu) * (1 - 2 * nu));
        const double volume = std::fabs(dot3(cross(sub(b, a), sub(c, a)), sub(d, a)) / 6.0);
        const double div = volume * 36;
        e[TMAT + 0] = (1.0 * scale) / div;
        e[TMAT + 1] = ((nu / (1 - nu)) * scale) / div;
        e[TMAT + 2] = (((1 - 2 * nu) / (2 * (1 - nu))) * scale) / div;

        if (method == 0) {
            strain_displacement(e + TJ, a, b, c, d);
            const V3 edges[3] = {sub(b, a), sub(c, a), sub(d, a)};
            for (int k = 0; k < 3; ++k)
                for (int m = 0; m < 3; ++m) e[TSMALL_REST + 3 * k + m] = edges[k][m];
        } else if (method == 1) {
            const M3 r01 = tetra_frame(a, b, c);
            store_m(e + TROT, transposed(r01));
            const V3 r0 = mul(r01, a);
            const V3 r1 = sub(mul(r01, b), r0), r2 = sub(mul(r01, c), r0), r3 = sub(mul(r01, d), r0);
            strain_displacement(e + TJ, V3{{0.0, 0.0, 0.0}}, r1, r2, r3);
            e[TREST + 0] = r1[0];
            e[TREST + 1] = r2[0];
            e[TREST + 2] = r2[1];
            e[TREST + 3] = r3[0];
            e[TREST + 4] = r3[1];
            e[TREST + 5] = r3[2];
        } else {
            const M3 A = edge_rows(a, b, c, d);
            const M3 r01 = polar_rotation(A);
            store_m(e + TROT, transposed(r01));
            const V3 r[4] = {mul(r01, a), mul(r01, b), mul(r01, c), mul(r01, d)};
            strain_displacement(e + TJ, r[0], r[1], r[2], r[3]);
            for (int k = 0; k < 4; ++k)
                for (int m = 0; m < 3; ++m) e[TREST + 3 * k + m] = r[k][m];
            if (method == 3) {
                store_m(e + TINITROT, transposed(r01));
                M3 inv = identity();
                invert(inv, A);  // SOFA asserts invertibility; a flat rest element keeps identity here
                store_m(e + TINITINV, inv);
            }
        }
        tetra_pack(element_data, i, stride, 0, stride, e);
    }
}

// TetrahedronFEMForceField's plasticity (plasticMaxThreshold > 0): `strain` holds 6 numbers per
// element (SOFA's _plasticStrains, Voigt order, zero at creation), updated by every add_force;
// a null `strain`: no plasticity.
struct TetraPlasticity {
    double* strain;
    double max_threshold;
    double yield_threshold;
    double creep;
};

// SOFA's updateStiffnessMatrix: every add_force rewrites the strain-displacement cofactors from the
// element's current local coordinates (then add_dforce and the element matrices use them).
// polar/svd: SOFA's computeStrainDisplacement of the rotated current points, into the element
// data. large: SOFA rewrites 9 entries of J's normal-strain columns only (the shear columns keep
// their rest values), so those live apart: `normals`, 12 per element (see tetra_strain), which
// tetra_fem_copy_normals fills with the rest values at init.
struct TetraStiffnessUpdate {
    bool enabled;
    double* normals;
};

// The rest normal-column cofactors of each element (large with updateStiffnessMatrix).
inline void tetra_fem_copy_normals(Index n, const double* element_data, int method, double* normals) {
    static_assert(fem_detail::TJ == 0, "the cofactors open an element's record");
    for (Index i = 0; i < n; ++i)
        fem_detail::tetra_unpack(element_data, i, tetra_fem_data_size(method), fem_detail::TJ, 12, normals + 12 * i);
}

namespace fem_detail {
// computeForce of element i with its displacements D and cofactors jn (normal columns) and js
// (shear columns), with plasticity when given.
inline void tetra_element_force(double* F, const double* D, const double* jn, const double* js, const double* mat,
                                Index i, const TetraPlasticity* plasticity) {
    if (plasticity == nullptr || plasticity->strain == nullptr)
        return tetra_compute_force(F, D, jn, js, mat, 1.0, false);
    double strain[6];
    tetra_strain(strain, D, jn, js);
    tetra_plastic_strain(strain, plasticity->strain + 6 * i, plasticity->max_threshold,
                         plasticity->yield_threshold, plasticity->creep);
    tetra_strain_force(F, strain, jn, js, mat, 1.0, false);
}
}  // namespace fem_detail

// The internal force of element i at positions x, F (12 numbers) to add to its nodes; stores the
// element's current rotation (large/polar/svd); updates its plastic strain and its cofactors when
// asked (SOFA's order: displacements, then the cofactors, then the force).
inline void tetra_fem_force_of(const Index* tetra, Index i, const double* x, double* element_data, int method,
                               double* out, const TetraPlasticity* plasticity = nullptr,
                               const TetraStiffnessUpdate* update = nullptr) {
    using namespace fem_detail;
    const int stride = tetra_fem_data_size(method);
    double e[54];
    tetra_unpack(element_data, i, stride, 0, stride, e);
    const Index* t = tetra + 4 * i;
    double D[12];
    double F[12];
    if (method == 0) {  // SOFA's small method never updates its cofactors
        const double* p0 = x + 3 * t[0];
        D[0] = D[1] = D[2] = 0.0;
        for (int k = 1; k < 4; ++k) {
            const double* pk = x + 3 * t[k];
            for (int m = 0; m < 3; ++m) D[3 * k + m] = e[TSMALL_REST + 3 * (k - 1) + m] - pk[m] + p0[m];
        }
        tetra_element_force(out, D, e + TJ, e + TJ, e + TMAT, i, plasticity);
        return;
    }
    const V3 p[4] = {load(x + 3 * t[0]), load(x + 3 * t[1]), load(x + 3 * t[2]), load(x + 3 * t[3])};
    M3 r02;  // world -> local
    if (method == 1) {
        r02 = tetra_frame(p[0], p[1], p[2]);
    } else if (method == 2) {
        r02 = polar_rotation(edge_rows(p[0], p[1], p[2], p[3]));
    } else {
        const M3 A = edge_rows(p[0], p[1], p[2], p[3]);
        const M3 defo = mul(A, load_m(e + TINITINV));
        if (determinant(defo) < 1e-6)  // inverted or flat element: SVD with degenerate handling
            r02 = mul_nt(svd_stable_rotation(defo), load_m(e + TINITROT));
        else
            r02 = polar_rotation(A);
    }
    const M3 rot = transposed(r02);
    store_m(e + TROT, rot);
    tetra_pack(element_data, i, stride, TROT, 9, e);
    V3 q[4];
    for (int k = 0; k < 4; ++k) q[k] = mul(r02, p[k]);
    const bool updating = update != nullptr && update->enabled;
    const double* jn = e + TJ;
    if (method == 1) {
        // SOFA subtracts node 0 only where the local coordinates are not zero by construction
        // and sets the displacement of those to exactly 0.
        q[1][0] -= q[0][0];
        q[2][0] -= q[0][0];
        q[2][1] -= q[0][1];
        q[3] = sub(q[3], q[0]);
        const double* r = e + TREST;
        D[0] = D[1] = D[2] = 0.0;
        D[3] = r[0] - q[1][0];
        D[4] = 0.0;
        D[5] = 0.0;
        D[6] = r[1] - q[2][0];
        D[7] = r[2] - q[2][1];
        D[8] = 0.0;
        D[9] = r[3] - q[3][0];
        D[10] = r[4] - q[3][1];
        D[11] = r[5] - q[3][2];
        if (updating) {  // SOFA's 9 entries, from the current local coordinates
            double* n = update->normals + 12 * i;
            const double d10 = q[1][0], d20 = q[2][0], d21 = q[2][1];
            const double d30 = q[3][0], d31 = q[3][1], d32 = q[3][2];
            n[0] = -d21 * d32;                                      // J(0,0)
            n[1] = d20 * d32 - d10 * d32;                           // J(1,1)
            n[2] = d21 * d30 - d20 * d31 + d10 * d31 - d10 * d21;   // J(2,2)
            n[3] = d21 * d32;                                       // J(3,0)
            n[4] = -d20 * d32;                                      // J(4,1)
            n[5] = -d21 * d30 + d20 * d31;                          // J(5,2)
            n[7] = d10 * d32;                                       // J(7,1)
            n[8] = -d10 * d31;                                      // J(8,2)
            n[11] = d10 * d21;                                      // J(11,2)
            jn = n;
        }
    } else {
        for (int k = 0; k < 4; ++k)
            for (int m = 0; m < 3; ++m) D[3 * k + m] = e[TREST + 3 * k + m] - q[k][m];
        if (updating) {
            strain_displacement(e + TJ, q[0], q[1], q[2], q[3]);
            tetra_pack(element_data, i, stride, TJ, 12, e);
        }
    }
    tetra_element_force(F, D, jn, e + TJ, e + TMAT, i, plasticity);
    for (int k = 0; k < 4; ++k) {
        const V3 fk = mul(rot, V3{{F[3 * k], F[3 * k + 1], F[3 * k + 2]}});
        for (int m = 0; m < 3; ++m) out[3 * k + m] = fk[m];
    }
}

// -kfactor * (df/dx) dx of element i (12 numbers to add), with SOFA's df/dx = -R (J K J^T) R^T, R
// the rotation of the last add_force (the initial rotation before any add_force); small:
// -J K J^T. The derivative of the rotation is neglected, as in SOFA (exact at zero strain, an
// approximation elsewhere). SOFA subtracts R F from df; adding -(R F) rounds the same.
// normals: the updated normal-column cofactors of large with updateStiffnessMatrix, or null.
inline void tetra_fem_dforce_of(const Index* tetra, Index i, const double* dx, double kfactor,
                                const double* element_data, int method, double* out,
                                const double* normals = nullptr) {
    using namespace fem_detail;
    double e[TROT + 9];
    tetra_unpack(element_data, i, tetra_fem_data_size(method), 0, method == 0 ? TROT : TROT + 9, e);
    const Index* t = tetra + 4 * i;
    double X[12];
    for (int k = 0; k < 4; ++k)
        for (int m = 0; m < 3; ++m) X[3 * k + m] = dx[3 * t[k] + m];
    double F[12];
    if (method == 0)
        tetra_dforce_element<double, false>(nullptr, e + TJ, e + TJ, e + TMAT, kfactor, X, F);
    else
        tetra_dforce_element<double, true>(e + TROT, normals ? normals + 12 * i : e + TJ, e + TJ, e + TMAT, kfactor, X, F);
    for (int j = 0; j < 12; ++j) out[j] = -F[j];
}

namespace fem_detail {

// Numbers [first, first + count) of a block's TETRA_LANES elements into out[first, first + count)
// (the data need not be aligned).
inline void load_lanes(const double* block, int first, int count, Lanes* out) {
    _Pragma("GCC unroll 32") for (int f = first; f < first + count; ++f)
        std::memcpy(&out[f], block + f * TETRA_LANES, sizeof(Lanes));
}

// The block kernels below run TETRA_LANES elements at once, one element per lane: each lane does
// the scalar operations of the per-element kernel, in the same order (the same numbers), and the
// elements' results go to the nodes one element after the other, in element order, as the serial
// loop adds them. A short last block repeats the last element in its unused lanes and drops their
// results. They are always inlined into the instruction-set variants below, which compile them for
// their vector width.

// node[k][l] = 3 * node k of element first + l; X[3k + m][l] = in[node[k][l] + m].
__attribute__((always_inline)) inline void gather_nodes(const Index* tetra, Index n, Index first,
                                                        const double* in, Index (&node)[4][TETRA_LANES],
                                                        Lanes* X) {
    for (int l = 0; l < TETRA_LANES; ++l) {
        const Index* t = tetra + 4 * std::min<Index>(first + l, n - 1);
        for (int k = 0; k < 4; ++k) node[k][l] = 3 * t[k];
    }
    for (int k = 0; k < 4; ++k)
        for (int m = 0; m < 3; ++m)
            for (int l = 0; l < TETRA_LANES; ++l) X[3 * k + m][l] = in[node[k][l] + m];
}

// out[node k of element first + l] += F[3k + m][l] (or -=), element after element. Under a thread
// split (slots non-null: per element corner, -1 or its deferred slot), a deferred corner's
// contribution goes to its slot instead, signed, for parallel.h's for_chunks to add in order.
template <bool Subtract>
__attribute__((always_inline)) inline void scatter_nodes(Index n, Index first,
                                                         const Index (&node)[4][TETRA_LANES], const Lanes* F,
                                                         double* out, const Index* slots, double* deferred) {
    typedef double Pair __attribute__((vector_size(16)));
    const auto element = [&](int l) {
        for (int k = 0; k < 4; ++k) {
            if (slots && slots[4 * (first + l) + k] >= 0) {
                double* d = deferred + 3 * slots[4 * (first + l) + k];
                for (int m = 0; m < 3; ++m) d[m] = Subtract ? -F[3 * k + m][l] : F[3 * k + m][l];
                continue;
            }
            double* o = out + node[k][l];
            // x and y in one operation, then z: the same sums, fewer instructions
            const Pair xy = {F[3 * k][l], F[3 * k + 1][l]};
            Pair sum;
            std::memcpy(&sum, o, sizeof(Pair));
            if (Subtract) {
                sum -= xy;
                o[2] -= F[3 * k + 2][l];
            } else {
                sum += xy;
                o[2] += F[3 * k + 2][l];
            }
            std::memcpy(o, &sum, sizeof(Pair));
        }
    };
    if (n - first >= TETRA_LANES) {
        _Pragma("GCC unroll 16") for (int l = 0; l < TETRA_LANES; ++l) element(l);
    } else {
        for (int l = 0; l < n - first; ++l) element(l);
    }
}

// add_dforce (tetra_fem_dforce_of): SOFA subtracts R F from df (a - b and a + (-b) round the same).
template <bool Rotated>
__attribute__((always_inline)) inline void tetra_dforce_blocks(const Index* tetra, Index n, const double* dx,
                                                               double* df, double kfactor, const double* data,
                                                               int stride, const Index* slots, double* deferred) {
    Lanes factor;
    for (int l = 0; l < TETRA_LANES; ++l) factor[l] = kfactor;
    for (Index first = 0; first < n; first += TETRA_LANES) {
        Lanes f[TROT + 9];
        load_lanes(data + first * stride, 0, Rotated ? TROT + 9 : TROT, f);
        Index node[4][TETRA_LANES];
        Lanes X[12] = {};
        gather_nodes(tetra, n, first, dx, node, X);
        Lanes F[12];
        tetra_dforce_element<Lanes, Rotated>(f + TROT, f + TJ, f + TJ, f + TMAT, factor, X, F);
        scatter_nodes<true>(n, first, node, F, df, slots, deferred);
    }
}

// add_force of the large method (tetra_fem_force_of, method 1); stores the rotations.
__attribute__((always_inline)) inline void tetra_force_large_blocks(const Index* tetra, Index n, const double* x,
                                                                    double* f, double* data, const Index* slots,
                                                                    double* deferred) {
    constexpr int stride = 30;
    Lanes one;
    for (int l = 0; l < TETRA_LANES; ++l) one[l] = 1.0;
    for (Index first = 0; first < n; first += TETRA_LANES) {
        double* block = data + first * stride;
        Index node[4][TETRA_LANES];
        Lanes p[12] = {};
        gather_nodes(tetra, n, first, x, node, p);
        Lanes r02[9];  // world -> local
        tetra_frame_rows(p, p + 3, p + 6, r02);
        Lanes rot[9];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) rot[3 * i + j] = r02[3 * j + i];
        for (int i = 0; i < 9; ++i) std::memcpy(block + (TROT + i) * TETRA_LANES, &rot[i], sizeof(Lanes));
        Lanes q[12];
        for (int k = 0; k < 4; ++k) rotate(r02, p + 3 * k, q + 3 * k);
        // as tetra_fem_force_of: node 0 subtracted only where the local coordinates are not 0
        q[3] -= q[0];
        q[6] -= q[0];
        q[7] -= q[1];
        for (int m = 0; m < 3; ++m) q[9 + m] -= q[m];
        Lanes e[TREST + 6];
        load_lanes(block, 0, TROT, e);
        load_lanes(block, TREST, 6, e);
        const Lanes* r = e + TREST;
        const Lanes zero = Lanes{};
        Lanes D[12] = {zero, zero, zero, r[0] - q[3], zero, zero, r[1] - q[6], r[2] - q[7], zero,
                       r[3] - q[9], r[4] - q[10], r[5] - q[11]};
        Lanes F[12];
        tetra_compute_force(F, D, e + TJ, e + TMAT, one, false);
        Lanes out[12];
        for (int k = 0; k < 4; ++k) rotate(rot, F + 3 * k, out + 3 * k);
        scatter_nodes<false>(n, first, node, out, f, slots, deferred);
    }
}

__attribute__((always_inline)) inline void tetra_dforce_method(const Index* tetra, Index n, const double* dx,
                                                               double* df, double kfactor, const double* data,
                                                               int method, const Index* slots, double* deferred) {
    if (method == 0)
        tetra_dforce_blocks<false>(tetra, n, dx, df, kfactor, data, tetra_fem_data_size(method), slots, deferred);
    else
        tetra_dforce_blocks<true>(tetra, n, dx, df, kfactor, data, tetra_fem_data_size(method), slots, deferred);
}

// R J K J^T R^T of one element (T = double) or of TETRA_LANES elements (T = Lanes, one per lane):
// the positive stiffness, 12x12 row-major, from a record's TJ, TMAT and (rotated) TROT fields.
// SOFA's order of operations (TetrahedronFEMForceField's assembled matrix, structural zeros of J
// and K skipped); without rotation R is the identity, multiplied all the same.
template <class T>
__attribute__((always_inline)) inline void tetra_element_matrix(const T* d, bool rotated, T* out) {
    // Row 3n + c of J has its non-zeros in the columns column[c][0..2] (increasing): the cofactors
    // (a, b, g) of node n in the order cofactor[c][0..2]. Column c < 3 is the only one below 3.
    constexpr int column[3][3] = {{0, 3, 5}, {1, 3, 4}, {2, 4, 5}};
    constexpr int cofactor[3][3] = {{0, 1, 2}, {1, 0, 2}, {2, 1, 0}};
    T Jv[12][3];
    for (int n = 0; n < 4; ++n)
        for (int c = 0; c < 3; ++c)
            for (int t = 0; t < 3; ++t) Jv[3 * n + c][t] = d[TJ + 3 * n + cofactor[c][t]];
    // K: K00 on the diagonal and K01 off it in the upper-left 3x3 block, K33 on the lower diagonal.
    const T K00 = d[TMAT], K01 = d[TMAT + 1], K33 = d[TMAT + 2];
    const T zero = T{}, one = zero + 1.0;
    T JK[12][6];  // one term each: J[i][c] K[c][j] (j < 3), J[i][j] K33 (j >= 3)
    for (int i = 0; i < 12; ++i) {
        const int c = i % 3;
        for (int j = 0; j < 3; ++j) JK[i][j] = Jv[i][0] * (j == c ? K00 : K01);
        for (int j = 3; j < 6; ++j) JK[i][j] = zero;
        JK[i][column[c][1]] = Jv[i][1] * K33;
        JK[i][column[c][2]] = Jv[i][2] * K33;
    }
    T JKJt[12][12];
    for (int i = 0; i < 12; ++i)
        for (int j = 0; j < 12; ++j) {
            const int* k = column[j % 3];
            JKJt[i][j] = JK[i][k[0]] * Jv[j][0] + JK[i][k[1]] * Jv[j][1] + JK[i][k[2]] * Jv[j][2];
        }
    T R[9];
    for (int k = 0; k < 9; ++k) R[k] = rotated ? d[TROT + k] : (k % 4 == 0 ? one : zero);
    T S[12][12];  // RR JKJt, RR = diag(R, R, R, R)
    for (int i = 0; i < 12; ++i) {
        const int b = i - i % 3;
        const T r0 = R[3 * (i % 3)], r1 = R[3 * (i % 3) + 1], r2 = R[3 * (i % 3) + 2];
        for (int j = 0; j < 12; ++j) S[i][j] = r0 * JKJt[b][j] + r1 * JKJt[b + 1][j] + r2 * JKJt[b + 2][j];
    }
    for (int i = 0; i < 12; ++i)
        for (int b = 0; b < 12; b += 3)
            for (int j = 0; j < 3; ++j)
                out[12 * i + b + j] = S[i][b] * R[3 * j] + S[i][b + 1] * R[3 * j + 1] + S[i][b + 2] * R[3 * j + 2];
}

// tetra_element_matrix of the TETRA_LANES elements of one data block, element after element in out.
__attribute__((always_inline)) inline void tetra_element_matrices_block(const double* block, int method,
                                                                        double* out) {
    Lanes d[TROT + 9];
    load_lanes(block, 0, method == 0 ? TROT : TROT + 9, d);
    Lanes m[144];
    tetra_element_matrix<Lanes>(d, method != 0, m);
    for (int l = 0; l < TETRA_LANES; ++l)
        for (int k = 0; k < 144; ++k) out[144 * l + k] = m[k][l];
}

// The block kernels compiled for baseline x86-64 (the library's own target) and, chosen at run time
// by what the processor has, for AVX2 and for AVX-512 F+VL (the same 4-wide vectors, with 32
// registers instead of 16: fewer spills, about 10% faster). No fused multiply-add: the targets do
// not change the operations (and scenes are built with -ffp-contract=off), so every lane rounds as
// the scalar code.
inline void tetra_dforce_default(const Index* tetra, Index n, const double* dx, double* df, double kfactor,
                                 const double* data, int method, const Index* slots, double* deferred) {
    tetra_dforce_method(tetra, n, dx, df, kfactor, data, method, slots, deferred);
}
inline void tetra_force_large_default(const Index* tetra, Index n, const double* x, double* f, double* data,
                                      const Index* slots, double* deferred) {
    tetra_force_large_blocks(tetra, n, x, f, data, slots, deferred);
}
inline void tetra_element_matrices_default(const double* block, int method, double* out) {
    tetra_element_matrices_block(block, method, out);
}

#ifdef SOFAC_X86_VARIANTS
__attribute__((target("avx2"))) inline void tetra_dforce_avx2(const Index* tetra, Index n, const double* dx,
                                                              double* df, double kfactor, const double* data,
                                                              int method, const Index* slots, double* deferred) {
    tetra_dforce_method(tetra, n, dx, df, kfactor, data, method, slots, deferred);
}
__attribute__((target("avx2"))) inline void tetra_force_large_avx2(const Index* tetra, Index n, const double* x,
                                                                  double* f, double* data, const Index* slots,
                                                                  double* deferred) {
    tetra_force_large_blocks(tetra, n, x, f, data, slots, deferred);
}
__attribute__((target("avx512f,avx512vl"))) inline void tetra_dforce_avx512(
    const Index* tetra, Index n, const double* dx, double* df, double kfactor, const double* data, int method,
    const Index* slots, double* deferred) {
    tetra_dforce_method(tetra, n, dx, df, kfactor, data, method, slots, deferred);
}
__attribute__((target("avx512f,avx512vl"))) inline void tetra_force_large_avx512(
    const Index* tetra, Index n, const double* x, double* f, double* data, const Index* slots, double* deferred) {
    tetra_force_large_blocks(tetra, n, x, f, data, slots, deferred);
}
__attribute__((target("avx2"))) inline void tetra_element_matrices_avx2(const double* block, int method,
                                                                        double* out) {
    tetra_element_matrices_block(block, method, out);
}
__attribute__((target("avx512f,avx512vl"))) inline void tetra_element_matrices_avx512(const double* block,
                                                                                      int method, double* out) {
    tetra_element_matrices_block(block, method, out);
}
#endif

// The variant for this processor. `slots`/`deferred`: a thread split's (see scatter_nodes), or null.
inline void tetra_dforce_dispatch(const Index* tetra, Index n, const double* dx, double* df, double kfactor,
                                  const double* data, int method, const Index* slots, double* deferred) {
#ifdef SOFAC_X86_VARIANTS
    const int level = vector_level();
    if (level == 2) return tetra_dforce_avx512(tetra, n, dx, df, kfactor, data, method, slots, deferred);
    if (level == 1) return tetra_dforce_avx2(tetra, n, dx, df, kfactor, data, method, slots, deferred);
#endif
    tetra_dforce_default(tetra, n, dx, df, kfactor, data, method, slots, deferred);
}
inline void tetra_force_large_dispatch(const Index* tetra, Index n, const double* x, double* f, double* data,
                                       const Index* slots, double* deferred) {
#ifdef SOFAC_X86_VARIANTS
    const int level = vector_level();
    if (level == 2) return tetra_force_large_avx512(tetra, n, x, f, data, slots, deferred);
    if (level == 1) return tetra_force_large_avx2(tetra, n, x, f, data, slots, deferred);
#endif
    tetra_force_large_default(tetra, n, x, f, data, slots, deferred);
}
inline void tetra_element_matrices_dispatch(const double* block, int method, double* out) {
#ifdef SOFAC_X86_VARIANTS
    const int level = vector_level();
    if (level == 2) return tetra_element_matrices_avx512(block, method, out);
    if (level == 1) return tetra_element_matrices_avx2(block, method, out);
#endif
    tetra_element_matrices_default(block, method, out);
}

}  // namespace fem_detail

// f += internal force at positions x; stores each element's current rotation (large/polar/svd).
// The large method runs TETRA_LANES elements at once (the same numbers). With a split, the
// elements run on its threads (same numbers, see parallel.h; its chunks start at whole blocks).
inline void tetra_fem_add_force(const Index* tetra, Index n, const double* x, double* f, double* element_data,
                                int method, const ElementSplit& split = {}) {
    const int stride = tetra_fem_data_size(method);
    if (method == 1 && split.chunks > 1) {
        for_chunks(split, f, [&](Index begin, Index end) {
            fem_detail::tetra_force_large_dispatch(tetra + 4 * begin, end - begin, x, f, element_data + begin * stride,
                                                   split.slot_of + 4 * begin, split.deferred);
        });
    } else if (method == 1) {
        fem_detail::tetra_force_large_dispatch(tetra, n, x, f, element_data, nullptr, nullptr);
    } else {
        const auto element = [&](Index i, double* out) {
            tetra_fem_force_of(tetra, i, x, element_data, method, out);
        };
        if (split.chunks > 1)
            split_elements<4>(split, tetra, f, element);
        else
            serial_elements<4>(n, tetra, f, element);
    }
}

// tetra_fem_add_force with SOFA's plasticity and/or updateStiffnessMatrix (any method; the scalar
// path, one element after the other as SOFA: each element's updates depend on its own nodes only).
inline void tetra_fem_add_force_options(const Index* tetra, Index n, const double* x, double* f,
                                        double* element_data, int method, const TetraPlasticity& plasticity,
                                        const TetraStiffnessUpdate& update, const ElementSplit& split = {}) {
    const auto element = [&](Index i, double* out) {
        tetra_fem_force_of(tetra, i, x, element_data, method, out, &plasticity, &update);
    };
    if (split.chunks > 1)
        split_elements<4>(split, tetra, f, element);
    else
        serial_elements<4>(n, tetra, f, element);
}

// tetra_fem_add_dforce with the updated normal-column cofactors of large with updateStiffnessMatrix
// (the scalar path).
inline void tetra_fem_add_dforce_normals(const Index* tetra, Index n, const double* dx, double* df, double kfactor,
                                         const double* element_data, int method, const double* normals,
                                         const ElementSplit& split = {}) {
    const auto element = [&](Index i, double* out) {
        tetra_fem_dforce_of(tetra, i, dx, kfactor, element_data, method, out, normals);
    };
    if (split.chunks > 1)
        split_elements<4>(split, tetra, df, element);
    else
        serial_elements<4>(n, tetra, df, element);
}

// df += kfactor * (df/dx) dx (see tetra_fem_dforce_of), TETRA_LANES elements at once.
inline void tetra_fem_add_dforce(const Index* tetra, Index n, const double* dx, double* df, double kfactor,
                                 const double* element_data, int method, const ElementSplit& split = {}) {
    const int stride = tetra_fem_data_size(method);
    if (split.chunks > 1) {
        for_chunks(split, df, [&](Index begin, Index end) {
            fem_detail::tetra_dforce_dispatch(tetra + 4 * begin, end - begin, dx, df, kfactor,
                                              element_data + begin * stride, method, split.slot_of + 4 * begin,
                                              split.deferred);
        });
        return;
    }
    fem_detail::tetra_dforce_dispatch(tetra, n, dx, df, kfactor, element_data, method, nullptr, nullptr);
}

// SOFA's getPotentialEnergy: 1/2 sum_e D_e . (J K J^T D_e) for the small method; SOFA returns 0 for
// large, polar and svd (not implemented there), and so does this function.
inline double tetra_fem_energy(const Index* tetra, Index n, const double* x, const double* element_data,
                               int method) {
    using namespace fem_detail;
    if (method != 0) return 0.0;
    const int stride = tetra_fem_data_size(method);
    double energy = 0.0;
    for (Index i = 0; i < n; ++i) {
        double e[TSMALL_REST + 9];
        tetra_unpack(element_data, i, stride, 0, TSMALL_REST + 9, e);
        const Index* t = tetra + 4 * i;
        double D[12];
        double F[12];
        const double* p0 = x + 3 * t[0];
        D[0] = D[1] = D[2] = 0.0;
        for (int k = 1; k < 4; ++k) {
            const double* pk = x + 3 * t[k];
            for (int m = 0; m < 3; ++m) D[3 * k + m] = e[TSMALL_REST + 3 * (k - 1) + m] - pk[m] + p0[m];
        }
        tetra_compute_force(F, D, e + TJ, e + TMAT, 1.0, false);
        for (int k = 0; k < 4; ++k)
            energy += F[3 * k] * -D[3 * k] + F[3 * k + 1] * -D[3 * k + 1] + F[3 * k + 2] * -D[3 * k + 2];
    }
    return energy / -2.0;
}

// Element stiffness of element e as SOFA assembles it (computeStiffnessMatrix / buildStiffnessMatrix):
// out (12x12, row-major, node-major blocks) = R (J K J^T) R^T with R the stored rotation (identity
// for small); the force Jacobian block of nodes (a, b) is -out[3a.., 3b..], and addKToMatrix adds
// -k * out. SOFA evaluates these as generic Mat products over all 12/6 entries, each sum from 0;
// the sums below keep only the terms that are not zero by construction (J's 3 non-zeros per row,
// K's zero blocks, R's block diagonal), in SOFA's order. Adding an exact zero never changes a sum,
// so every entry is SOFA's number (a zero entry may come out as -0, which adds nothing when it is
// assembled), at less than half the operations.
inline void tetra_fem_element_matrix(const double* element_data, Index e, int method, double* out) {
    using namespace fem_detail;
    double d[TROT + 9];
    tetra_unpack(element_data, e, tetra_fem_data_size(method), 0, method == 0 ? TROT : TROT + 9, d);
    tetra_element_matrix<double>(d, method != 0, out);
}

// The matrices of elements first .. first + TETRA_LANES - 1 (one block of the element data; past the
// last element, unused), 144 numbers each, one after the other: each the same numbers as
// tetra_fem_element_matrix's, computed TETRA_LANES at once with this processor's vector copy.
inline void tetra_fem_element_matrices(const double* element_data, Index first, int method, double* out) {
    fem_detail::tetra_element_matrices_dispatch(element_data + first * tetra_fem_data_size(method), method, out);
}

// ================================================================================================
// TetrahedralCorotationalFEMForceField (Vec3d), methods small (0), large (1), polar (2)
// ================================================================================================
// Numerically identical to TetrahedronFEMForceField for these methods (same material matrix,
// strain-displacement, Gram-Schmidt / polar rotations, computeForce and addDForce; its addDForce
// writes f += R (-F) where TetrahedronFEMForceField writes f -= R F, the same IEEE result). The
// differences are elsewhere: no svd method, no hexahedron->tetrahedron split (it needs tetrahedra
// in the topology), no plasticity, getPotentialEnergy returns 0 for every method, and its
// rotation is left zero until the first addForce (irrelevant: solvers call addForce first).
constexpr int tetracorot_fem_data_size(int method) { return tetra_fem_data_size(method); }

inline void tetracorot_fem_init(const Index* tetra, Index n_tetra, const double* rest_x, const double* young,
                                Index n_young, const double* poisson, Index n_poisson, int method,
                                double* element_data, const double* local_stiffness_factor = nullptr,
                                Index n_factor = 0) {
    tetra_fem_init(tetra, n_tetra, rest_x, young, n_young, poisson, n_poisson, method, element_data,
                   local_stiffness_factor, n_factor);
}
inline void tetracorot_fem_add_force(const Index* tetra, Index n, const double* x, double* f,
                                     double* element_data, int method, const ElementSplit& split = {}) {
    tetra_fem_add_force(tetra, n, x, f, element_data, method, split);
}
inline void tetracorot_fem_add_dforce(const Index* tetra, Index n, const double* dx, double* df,
                                      double kfactor, const double* element_data, int method,
                                      const ElementSplit& split = {}) {
    tetra_fem_add_dforce(tetra, n, dx, df, kfactor, element_data, method, split);
}
inline void tetracorot_fem_element_matrix(const double* element_data, Index e, int method, double* out) {
    tetra_fem_element_matrix(element_data, e, method, out);
}
inline void tetracorot_fem_element_matrices(const double* element_data, Index first, int method, double* out) {
    tetra_fem_element_matrices(element_data, first, method, out);
}

// ================================================================================================
// HexahedronFEMForceField (Vec3d), methods small (0), large (1), polar (2)
// ================================================================================================
//
// Node order (SOFA's topologies and the force field alike): 0 (0,0,0) 1 (1,0,0) 2 (1,1,0)
// 3 (0,1,0) 4 (0,0,1) 5 (1,0,1) 6 (1,1,1) 7 (0,1,1) in the element's reference coordinates.
//
// Element data, 609 doubles per element for every method:
//   [0, 576)   element stiffness Ke (24x24, row-major, node-major, symmetric), times the optional
//              per-element stiffness coefficient (SparseGridTopology::getStiffnessCoef; 1 otherwise)
//   [576, 600) rest positions of the 8 nodes in the rest frame (R0 X0, not translated)
//   [600, 609) current rotation R (world -> local, rows = local axes; SOFA's _rotations[i])
constexpr int hexa_fem_data_size(int /*method*/ = 1) { return 609; }

namespace fem_detail {

constexpr int HK = 0;
constexpr int HREST = 576;
constexpr int HROT = 600;

// SOFA's _coef: the reference coordinates (+-1) of the 8 nodes.
constexpr int hexa_coef[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                 {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

// Mean edge directions, summed left to right as SOFA writes them.
inline V3 hexa_sum(const V3* n, int a0, int b0, int a1, int b1, int a2, int b2, int a3, int b3) {
    V3 r;
    for (int m = 0; m < 3; ++m)
        r[m] = (n[a0][m] - n[b0][m] + n[a1][m] - n[b1][m] + n[a2][m] - n[b2][m] + n[a3][m] - n[b3][m]) * .25;
    return r;
}
inline V3 hexa_x(const V3* n) { return hexa_sum(n, 1, 0, 2, 3, 5, 4, 6, 7); }
inline V3 hexa_y(const V3* n) { return hexa_sum(n, 3, 0, 2, 1, 7, 4, 6, 5); }
inline V3 hexa_z(const V3* n) { return hexa_sum(n, 4, 0, 5, 1, 7, 3, 6, 2); }

// large: x = mean x-edge (normalized), z = x cross mean y-edge (normalized), y = z cross x.
inline M3 hexa_rotation_large(const V3* n) {
    V3 ex = hexa_x(n);
    const V3 ey0 = hexa_y(n);
    normalize(ex);
    V3 ez = cross(ex, ey0);
    normalize(ez);
    const V3 ey = cross(ez, ex);
    return from_rows(ex, ey, ez);
}
// polar: orthogonal factor of the matrix whose rows are the three mean edges.
inline M3 hexa_rotation_polar(const V3* n) { return polar_rotation(from_rows(hexa_x(n), hexa_y(n), hexa_z(n))); }

// SOFA's computeElementStiffness (the GENERIC_STIFFNESS_MATRIX path that SOFA keeps): 2x2x2 Gauss
// quadrature (points +-1/sqrt(3), weight 1) of Bi^T M Bj det(J), with a constant Jacobian when the
// nodes form a parallelepiped (tolerance 1e-3 relative on the edges), else J per Gauss point.
// U = M00, V = M01, W = M33 of the (undivided) Hooke matrix.
inline void hexa_element_stiffness(double* K, const V3* nodes, double U, double V, double W, double factor) {
    for (int i = 0; i < 576; ++i) K[i] = 0.0;
    M3 J{}, Jinv{};
    double detJ = 1.0;
    const V3 lx = sub(nodes[1], nodes[0]);
    const V3 ly = sub(nodes[3], nodes[0]);
    const V3 lz = sub(nodes[4], nodes[0]);
    auto off = [](const V3& a, const V3& l, const V3& b) {  // |a + l - b|
        V3 r;
        for (int m = 0; m < 3; ++m) r[m] = a[m] + l[m] - b[m];
        return norm(r);
    };
    const bool parallel = off(nodes[3], lx, nodes[2]) < norm(lx) * 0.001 &&
                          off(nodes[0], lz, nodes[4]) < norm(lz) * 0.001 &&
                          off(nodes[1], lz, nodes[5]) < norm(lz) * 0.001 &&
                          off(nodes[2], lz, nodes[6]) < norm(lz) * 0.001 &&
                          off(nodes[3], lz, nodes[7]) < norm(lz) * 0.001;
    if (parallel) {
        for (int c = 0; c < 3; ++c) {
            J(c, 0) = lx[c] / 2;
            J(c, 1) = ly[c] / 2;
            J(c, 2) = lz[c] / 2;
        }
        detJ = determinant(J);
        invert(Jinv, J);
    }
    const double g = 1.0 / std::sqrt(3.0);
    for (int gx1 = -1; gx1 <= 1; gx1 += 2)
        for (int gx2 = -1; gx2 <= 1; gx2 += 2)
            for (int gx3 = -1; gx3 <= 1; gx3 += 2) {
                const double x1 = gx1 * g, x2 = gx2 * g, x3 = gx3 * g;
                if (!parallel) {
                    for (int c = 0; c < 3; ++c) {
                        const auto d = [&](int a, int b) { return nodes[a][c] - nodes[b][c]; };
                        J(c, 0) = d(1, 0) * (1 - x2) * (1 - x3) / 8 + d(2, 3) * (1 + x2) * (1 - x3) / 8 +
                                  d(5, 4) * (1 - x2) * (1 + x3) / 8 + d(6, 7) * (1 + x2) * (1 + x3) / 8;
                        J(c, 1) = d(3, 0) * (1 - x1) * (1 - x3) / 8 + d(2, 1) * (1 + x1) * (1 - x3) / 8 +
                                  d(7, 4) * (1 - x1) * (1 + x3) / 8 + d(6, 5) * (1 + x1) * (1 + x3) / 8;
                        J(c, 2) = d(4, 0) * (1 - x1) * (1 - x2) / 8 + d(5, 1) * (1 + x1) * (1 - x2) / 8 +
                                  d(6, 2) * (1 + x1) * (1 + x2) / 8 + d(7, 3) * (1 - x1) * (1 + x2) / 8;
                    }
                    detJ = determinant(J);
                    invert(Jinv, J);
                }
                double qx[8], qy[8], qz[8];
                for (int i = 0; i < 8; ++i) {
                    const int c0 = hexa_coef[i][0], c1 = hexa_coef[i][1], c2 = hexa_coef[i][2];
                    const double d1 = c0 * (1 + c1 * x2) * (1 + c2 * x3) / 8.0;
                    const double d2 = (1 + c0 * x1) * c1 * (1 + c2 * x3) / 8.0;
                    const double d3 = (1 + c0 * x1) * (1 + c1 * x2) * c2 / 8.0;
                    qx[i] = d1 * Jinv(0, 0) + d2 * Jinv(1, 0) + d3 * Jinv(2, 0);
                    qy[i] = d1 * Jinv(0, 1) + d2 * Jinv(1, 1) + d3 * Jinv(2, 1);
                    qz[i] = d1 * Jinv(0, 2) + d2 * Jinv(1, 2) + d3 * Jinv(2, 2);
                }
                for (int i = 0; i < 8; ++i) {
                    // M Bi (6x3); zero entries omitted
                    const double m00 = U * qx[i], m01 = V * qy[i], m02 = V * qz[i];
                    const double m10 = V * qx[i], m11 = U * qy[i], m12 = V * qz[i];
                    const double m20 = V * qx[i], m21 = V * qy[i], m22 = U * qz[i];
                    const double m30 = W * qy[i], m31 = W * qx[i];
                    const double m41 = W * qz[i], m42 = W * qy[i];
                    const double m50 = W * qz[i], m52 = W * qx[i];
                    for (int j = i; j < 8; ++j) {
                        double k[3][3];  // Bj^T M Bi
                        k[0][0] = qx[j] * m00 + qy[j] * m30 + qz[j] * m50;
                        k[0][1] = qx[j] * m01 + qy[j] * m31;
                        k[0][2] = qx[j] * m02 + qz[j] * m52;
                        k[1][0] = qy[j] * m10 + qx[j] * m30;
                        k[1][1] = qy[j] * m11 + qx[j] * m31 + qz[j] * m41;
                        k[1][2] = qy[j] * m12 + qz[j] * m42;
                        k[2][0] = qz[j] * m20 + qx[j] * m50;
                        k[2][1] = qz[j] * m21 + qy[j] * m41;
                        k[2][2] = qz[j] * m22 + qy[j] * m42 + qx[j] * m52;
                        for (auto& row : k)
                            for (double& v : row) v *= detJ;
                        for (int m = 0; m < 3; ++m)
                            for (int l = 0; l < 3; ++l) K[24 * (3 * i + m) + 3 * j + l] += k[l][m];
                    }
                }
            }
    for (int i = 0; i < 24; ++i)
        for (int j = i + 1; j < 24; ++j) K[24 * j + i] = K[24 * i + j];
    for (int i = 0; i < 576; ++i) K[i] *= factor;
}

// F = Ke D (SOFA's Mat<24,24> * Vec<24>, summed left to right).
inline void hexa_mul(double* F, const double* K, const double* D) {
    for (int i = 0; i < 24; ++i) {
        double s = K[24 * i] * D[0];
        for (int j = 1; j < 24; ++j) s += K[24 * i + j] * D[j];
        F[i] = s;
    }
}

// Local displacement D = R0 X0 - R x and local force F = Ke D of an element at positions x;
// returns the rotation (computed from x for large/polar, identity for small).
inline M3 hexa_local(const Index* h, const double* x, const double* e, int method, double* D, double* F) {
    V3 nodes[8];
    for (int w = 0; w < 8; ++w) nodes[w] = load(x + 3 * h[w]);
    const M3 R = method == 1 ? hexa_rotation_large(nodes) : method == 2 ? hexa_rotation_polar(nodes) : identity();
    for (int w = 0; w < 8; ++w) {
        const V3 q = method == 0 ? nodes[w] : mul(R, nodes[w]);
        for (int m = 0; m < 3; ++m) D[3 * w + m] = e[HREST + 3 * w + m] - q[m];
    }
    hexa_mul(F, e + HK, D);
    return R;
}

}  // namespace fem_detail

// Precomputes per element (SOFA's reinit): the rest rotation R0 (large: mean-edge Gram-Schmidt;
// polar: polar factor of the mean-edge matrix; small: identity), the rest positions in that frame,
// and Ke integrated on them with the element's Hooke matrix (Young E_i, Poisson nu_i; no division by
// the volume) times stiffness_coef[i] (optional; SparseGridTopology's per-cell coefficient).
inline void hexa_fem_init(const Index* hexa, Index n_hexa, const double* rest_x, const double* young,
                          Index n_young, const double* poisson, Index n_poisson, int method, double* element_data,
                          const double* stiffness_coef = nullptr) {
    using namespace fem_detail;
    const int stride = hexa_fem_data_size(method);
    for (Index i = 0; i < n_hexa; ++i) {
        double* e = element_data + i * stride;
        const Index* h = hexa + 8 * i;
        const double nu = element_value(poisson, n_poisson, i);
        const double scale = (element_value(young, n_young, i) * (1 - nu)) / ((1 + nu) * (1 - 2 * nu));
        const double U = 1.0 * scale;
        const double V = (nu / (1 - nu)) * scale;
        const double W = ((1 - 2 * nu) / (2 * (1 - nu))) * scale;
        V3 nodes[8];
        for (int w = 0; w < 8; ++w) nodes[w] = load(rest_x + 3 * h[w]);
        const M3 R = method == 1 ? hexa_rotation_large(nodes) : method == 2 ? hexa_rotation_polar(nodes) : identity();
        store_m(e + HROT, R);
        V3 rotated[8];
        for (int w = 0; w < 8; ++w) {
            rotated[w] = mul(R, nodes[w]);
            for (int m = 0; m < 3; ++m) e[HREST + 3 * w + m] = rotated[w][m];
        }
        hexa_element_stiffness(e + HK, rotated, U, V, W, stiffness_coef ? stiffness_coef[i] : 1.0);
    }
}

// HexahedronFEMForceFieldAndMass's masses (SOFA's computeElementMass and init), after hexa_fem_init.
// SOFA's element mass matrix has one value on every node pair of the element, on the 3 diagonal
// DOF pairs: vol * integrateMass(...) = vol * (8/27 in SOFA's sum) * density, vol the product of the
// edges 0-1, 0-3, 0-4 of the rotated rest element. It is accumulated into the scalar CSR matrix
// (row_begin, cols, values: the element node pairs; lumped: the diagonal, holding the row sums).
// particle[i] (SOFA's _particleMasses, used for the weight) sums vol * density / 8 over the
// elements of node i, vol from the rest positions. mass_coef[i] (optional; SparseGridTopology's
// getMassCoef, 1 otherwise) scales both of element i's masses, where SOFA applies it.
inline void hexa_fem_mass_init(const Index* hexa, Index n_hexa, const double* rest_x, const double* element_data,
                               int method, const double* density, const Index* row_begin, const Index* cols,
                               Index n_rows, bool lumped, double* values, double* particle,
                               const double* mass_coef = nullptr) {
    using namespace fem_detail;
    const int stride = hexa_fem_data_size(method);
    const double rho = density[0];
    for (Index r = 0; r < row_begin[n_rows]; ++r) values[r] = 0.0;
    for (Index r = 0; r < n_rows; ++r) particle[r] = 0.0;
    auto entry = [&](Index a, Index b) -> double& {
        const Index* first = cols + row_begin[a];
        const Index* last = cols + row_begin[a + 1];
        return values[std::lower_bound(first, last, b) - cols];
    };
    const double t = 1.0;
    const double integrated = (t * t / 72.0 + t * t / 72.0 + (t * t) * t / 216.0 + t / 24.0 + 1.0 / 8.0 +
                               (t * t) / 72.0 + t / 24.0 + t / 24.0) *
                              rho;
    for (Index i = 0; i < n_hexa; ++i) {
        const Index* h = hexa + 8 * i;
        V3 nodes[8];
        for (int w = 0; w < 8; ++w) nodes[w] = load(rest_x + 3 * h[w]);
        const double coef = mass_coef ? mass_coef[i] : 1.0;
        const double volume = norm(sub(nodes[1], nodes[0])) * norm(sub(nodes[3], nodes[0])) *
                              norm(sub(nodes[4], nodes[0])) * coef;
        const double mass = (volume * rho) / 8.0;
        for (int w = 0; w < 8; ++w) particle[h[w]] += mass;
        const double* e = element_data + i * stride + HREST;
        V3 q[8];
        for (int w = 0; w < 8; ++w) q[w] = load(e + 3 * w);
        const double vol = norm(sub(q[1], q[0])) * norm(sub(q[3], q[0])) * norm(sub(q[4], q[0]));
        const double m = (vol * integrated) * coef;  // SOFA scales the finished element matrix
        for (int a = 0; a < 8; ++a)
            for (int b = 0; b < 8; ++b) {
                if (lumped)
                    entry(h[a], h[a]) += m;
                else
                    entry(h[a], h[b]) += m;
            }
    }
}

// f += internal force at x (f_node += R^T (Ke (R0 X0 - R x))_node); stores R. With a split, the
// elements run on its threads (same numbers, see parallel.h).
inline void hexa_fem_add_force(const Index* hexa, Index n, const double* x, double* f, double* element_data,
                               int method, const ElementSplit& split = {}) {
    using namespace fem_detail;
    const int stride = hexa_fem_data_size(method);
    const auto element = [&](Index i, double* out) {
        double* e = element_data + i * stride;
        double D[24], F[24];
        const M3 R = hexa_local(hexa + 8 * i, x, e, method, D, F);
        store_m(e + HROT, R);
        for (int w = 0; w < 8; ++w) {
            const V3 fw = method == 0 ? V3{{F[3 * w], F[3 * w + 1], F[3 * w + 2]}}
                                      : mul_t(R, V3{{F[3 * w], F[3 * w + 1], F[3 * w + 2]}});
            for (int m = 0; m < 3; ++m) out[3 * w + m] = fw[m];
        }
    };
    if (split.chunks > 1)
        split_elements<8>(split, hexa, f, element);
    else
        serial_elements<8>(n, hexa, f, element);
}

// df += kfactor * (df/dx) dx with SOFA's df/dx = -R^T Ke R (rotation of the last add_force;
// SOFA multiplies by kfactor after rotating back: df_node -= (R^T (Ke R dx)_node) * kfactor,
// which rounds as adding -((R^T Ke R dx)_node * kfactor)).
inline void hexa_fem_add_dforce(const Index* hexa, Index n, const double* dx, double* df, double kfactor,
                                const double* element_data, int method, const ElementSplit& split = {}) {
    using namespace fem_detail;
    const int stride = hexa_fem_data_size(method);
    const auto element = [&](Index i, double* out) {
        const double* e = element_data + i * stride;
        const Index* h = hexa + 8 * i;
        const M3 R = load_m(e + HROT);
        double X[24], F[24];
        for (int w = 0; w < 8; ++w) {
            const V3 l = mul(R, load(dx + 3 * h[w]));
            for (int m = 0; m < 3; ++m) X[3 * w + m] = l[m];
        }
        hexa_mul(F, e + HK, X);
        for (int w = 0; w < 8; ++w) {
            const V3 fw = mul_t(R, V3{{F[3 * w], F[3 * w + 1], F[3 * w + 2]}});
            for (int m = 0; m < 3; ++m) out[3 * w + m] = -(fw[m] * kfactor);
        }
    };
    if (split.chunks > 1)
        split_elements<8>(split, hexa, df, element);
    else
        serial_elements<8>(n, hexa, df, element);
}

// SOFA's getPotentialEnergy returns the value accumulated by the last addForce:
// 1/2 sum_e D_e . (Ke D_e) with D_e the local displacement. This recomputes it at x (the rotation
// from x), without touching element_data; call it with the positions of the last add_force to get
// SOFA's number.
inline double hexa_fem_energy(const Index* hexa, Index n, const double* x, const double* element_data,
                              int method) {
    using namespace fem_detail;
    const int stride = hexa_fem_data_size(method);
    double energy = 0.0;
    for (Index i = 0; i < n; ++i) {
        double D[24], F[24];
        hexa_local(hexa + 8 * i, x, element_data + i * stride, method, D, F);
        for (int w = 0; w < 8; ++w)
            energy += F[3 * w] * -D[3 * w] + F[3 * w + 1] * -D[3 * w + 1] + F[3 * w + 2] * -D[3 * w + 2];
    }
    return energy / -2.0;
}

// Element stiffness as SOFA assembles it (addKToMatrix / buildStiffnessMatrix): node block (a, b) of
// out (24x24, row-major) = R^T Ke_ab R with the stored rotation; the force Jacobian block is -out_ab.
inline void hexa_fem_element_matrix(const double* element_data, Index e, int method, double* out) {
    using namespace fem_detail;
    const double* d = element_data + e * hexa_fem_data_size(method);
    const M3 R = load_m(d + HROT);
    for (int a = 0; a < 8; ++a)
        for (int b = 0; b < 8; ++b) {
            M3 kb;
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) kb(i, j) = d[HK + 24 * (3 * a + i) + 3 * b + j];
            const M3 r = mul(mul_tn(R, kb), R);
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) out[24 * (3 * a + i) + 3 * b + j] = r(i, j);
        }
}

}  // namespace sofac
