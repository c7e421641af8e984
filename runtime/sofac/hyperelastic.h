// SOFA's TetrahedronHyperelasticityFEMForceField (Sofa.Component.SolidMechanics.FEM.HyperElastic)
// for Vec3d on linear tetrahedra, with the materials SOFA registers (materialName):
//   0 ArrudaBoyce (default)  ParameterSet = mu k0
//   1 StVenantKirchhoff      ParameterSet = mu lambda
//   2 NeoHookean             ParameterSet = mu lambda
//   3 MooneyRivlin           ParameterSet = c1 c2 k0
//   4 VerondaWestman         ParameterSet = c1 c2 k0
//   5 Costa                  ParameterSet = a k0 bff bfs bss bfn bsn bnn
//   6 Ogden                  ParameterSet = mu1 alpha1 k0
//   7 StableNeoHookean       ParameterSet = mu lambda
//
// Written from a reading of SOFA's sources at the corpus commit (2a278d89): the force field's
// createTetrahedronRestInformation, addForce, updateTangentMatrix, addDForce and addKToMatrix, and
// each material's deriveSPKTensor and applyElasticityTensor (material/*.h). No SOFA code is
// included. The formulas are SOFA's, term by term:
// - rest: per element the shape vectors sv_j (gradients of the barycentric coordinates, divided by
//   the signed 6-volume) and the rest volume |V6| / 6;
// - addForce: F = sum_j (x_j - x_0) (x) sv_j (j = 1..3), C = F^T F, J = det F from the current
//   edges, S = the material's second Piola-Kirchhoff stress, f_j -= V F S sv_j;
// - the tangent, per element and local edge (k, l): for each direction a, H_a = dC for a unit move
//   of node l along a (H_a,mn = sv_l,m F_a,n + F_a,m sv_l,n), dS_a = the material's elasticity
//   applied to H_a, N(a, u) = (F dS_a sv_k)_u; D = V (N + (sv_k . S sv_l) I). It is computed at the
//   first dforce (or assembly) after a force evaluation, as SOFA's m_updateMatrix;
// - addDForce: per edge d = dx_k - dx_l, df_k += kfactor D^T d, df_l -= kfactor D d (SOFA sums the
//   blocks per global edge first: the same terms, the sum in another order);
// - the assembled matrix: blocks (k,k) += D^T, (k,l) -= D^T, (l,k) -= D, (l,l) += D, times kfactor.
// SOFA reports no potential energy for this force field; hyperelastic_strain_energy (the energy
// whose derivative the stress is, for tests) is not part of a scene's energy.
//
// Symmetric 3x3 tensors are 6 numbers in SOFA's MatSym order: 00 01 11 02 12 22.
#pragma once

#include <cmath>

#include "types.h"

namespace sofac {

namespace hyper_detail {

// Element data offsets (doubles per element: HYPERELASTIC_DATA_SIZE); one more number after the
// elements says whether the tangent blocks are stale (SOFA's m_updateMatrix).
constexpr int SHAPE = 0;      // 4 shape vectors
constexpr int VOLUME = 12;    // rest volume
constexpr int GRADIENT = 13;  // F, row-major
constexpr int STRESS = 22;    // S (symmetric)
constexpr int JACOBIAN = 28;  // J = det F
constexpr int BLOCKS = 29;    // 6 edge blocks D, row-major
constexpr int VOLUME_SCALE = 83;  // 1 / (signed 6-volume), SOFA's m_volScale
constexpr int SIZE = 84;

// SOFA's local edges of a tetrahedron (core::topology edgesInTetrahedronArray).
constexpr int EDGES[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

struct Sym {
    double s[6];
    double& operator[](int i) { return s[i]; }
    double operator[](int i) const { return s[i]; }
    double operator()(int i, int j) const { return s[index(i, j)]; }
    static constexpr int index(int i, int j) { return i >= j ? i * (i + 1) / 2 + j : j * (j + 1) / 2 + i; }
};

inline Sym identity() { return Sym{{1, 0, 1, 0, 0, 1}}; }
inline Sym operator+(const Sym& a, const Sym& b) {
    Sym r;
    for (int i = 0; i < 6; ++i) r[i] = a[i] + b[i];
    return r;
}
inline Sym operator-(const Sym& a, const Sym& b) {
    Sym r;
    for (int i = 0; i < 6; ++i) r[i] = a[i] - b[i];
    return r;
}
inline Sym operator*(const Sym& a, double k) {
    Sym r;
    for (int i = 0; i < 6; ++i) r[i] = a[i] * k;
    return r;
}
inline Sym operator*(double k, const Sym& a) { return a * k; }
inline Sym operator/(const Sym& a, double k) {
    Sym r;
    for (int i = 0; i < 6; ++i) r[i] = a[i] / k;
    return r;
}

// Full contraction A:B of two symmetric tensors (SOFA's "trHC" sums).
inline double contract(const Sym& a, const Sym& b) {
    return a[0] * b[0] + a[2] * b[2] + a[5] * b[5] + 2 * a[1] * b[1] + 2 * a[3] * b[3] + 2 * a[4] * b[4];
}
inline double trace(const Sym& a) { return a[0] + a[2] + a[5]; }

// SOFA's invertMatrix on a MatSym<3>: the cofactors over the determinant.
inline Sym inverse(const Sym& m) {
    const double det = m(0, 0) * m(1, 1) * m(2, 2) + m(1, 0) * m(2, 1) * m(0, 2) + m(2, 0) * m(0, 1) * m(1, 2) -
                       m(0, 0) * m(2, 1) * m(1, 2) - m(1, 0) * m(0, 1) * m(2, 2) - m(2, 0) * m(1, 1) * m(0, 2);
    Sym r;
    r[0] = (m(1, 1) * m(2, 2) - m(2, 1) * m(1, 2)) / det;
    r[1] = (m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2)) / det;
    r[2] = (m(2, 2) * m(0, 0) - m(2, 0) * m(0, 2)) / det;
    r[3] = (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0)) / det;
    r[4] = (m(2, 0) * m(0, 1) - m(2, 1) * m(0, 0)) / det;
    r[5] = (m(0, 0) * m(1, 1) - m(1, 0) * m(0, 1)) / det;
    return r;
}

// a b a for symmetric a, b (SOFA's Cinv H Cinv, symmetrised as Mat2Sym does).
inline Sym sandwich(const Sym& a, const Sym& b) {
    double ab[3][3], full[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) ab[i][j] = b(i, 0) * a(0, j) + b(i, 1) * a(1, j) + b(i, 2) * a(2, j);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) full[i][j] = a(i, 0) * ab[0][j] + a(i, 1) * ab[1][j] + a(i, 2) * ab[2][j];
    Sym r;
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i <= j; ++i) r[Sym::index(i, j)] = (full[i][j] + full[j][i]) / 2;
    return r;
}

inline void sym_times(const Sym& a, const double v[3], double out[3]) {
    for (int i = 0; i < 3; ++i) out[i] = a(i, 0) * v[0] + a(i, 1) * v[1] + a(i, 2) * v[2];
}

// What the materials read of a deformation.
struct Strain {
    Sym C;       // right Cauchy-Green tensor
    Sym Cinv;    // its inverse
    double I1;   // tr C
    double J;    // det F
};

inline Strain strain_of(const double* F, double J) {
    Strain s;
    for (int k = 0; k < 3; ++k)
        for (int l = k; l < 3; ++l)
            s.C[Sym::index(k, l)] = F[0 * 3 + k] * F[0 * 3 + l] + F[1 * 3 + k] * F[1 * 3 + l] + F[2 * 3 + k] * F[2 * 3 + l];
    s.I1 = s.C[0] + s.C[2] + s.C[5];
    s.J = J;
    s.Cinv = inverse(s.C);
    return s;
}

// tr(C^2) (SOFA's I1square) and the second invariant.
inline double trace_of_square(const Sym& C) {
    return C[0] * C[0] + C[2] * C[2] + C[5] * C[5] + 2 * (C[1] * C[1] + C[3] * C[3] + C[4] * C[4]);
}

// ---- Arruda-Boyce: the five-term series of SOFA's BoyceAndArruda -------------------------------
constexpr double AB1 = 1.0 / 2.0, AB2 = 1.0 / 160.0, AB3 = 11.0 / (1050.0 * 8 * 8);
constexpr double AB4 = 19.0 / (7000.0 * 8.0 * 8.0 * 8.0), AB5 = 519.0 / (673750.0 * 8.0 * 8.0 * 8.0 * 8.0);

// Ogden's spectral quantities of C (SOFA's precomputeVariables, with Eigen's self-adjoint solver).
struct Spectral {
    double value[3];
    double vector[3][3];  // vector[i][n]: component i of eigenvector n
    double trace_power;   // sum lambda_n^(alpha/2)
    Sym power_minus_one;  // C^(alpha/2 - 1)
    double FJ;            // J^(-alpha/3)
};

inline Spectral spectral_of(const Strain& s, double alpha) {
    Eigen::Matrix3d c;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) c(i, j) = s.C(i, j);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(c, Eigen::ComputeEigenvectors);
    Spectral sp;
    for (int n = 0; n < 3; ++n) {
        sp.value[n] = solver.eigenvalues()[n];
        for (int i = 0; i < 3; ++i) sp.vector[i][n] = solver.eigenvectors()(i, n);
    }
    const double half = alpha / 2;
    sp.trace_power = 0;
    for (int n = 0; n < 3; ++n) sp.trace_power += std::pow(sp.value[n], half);
    double d[3];
    for (int n = 0; n < 3; ++n) d[n] = std::pow(sp.value[n], half - 1);
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i <= j; ++i) {
            double full_ij = 0, full_ji = 0;  // E D E^T, symmetrised as Mat2Sym
            for (int n = 0; n < 3; ++n) {
                full_ij += sp.vector[i][n] * d[n] * sp.vector[j][n];
                full_ji += sp.vector[j][n] * d[n] * sp.vector[i][n];
            }
            sp.power_minus_one[Sym::index(i, j)] = (full_ij + full_ji) / 2;
        }
    sp.FJ = std::pow(s.J, -alpha / 3);
    return sp;
}

// Ogden's elasticity dS/dC as the 3x3x3x3 tensor of SOFA's Ogden::ElasticityTensor (before its
// factor 2 and the doubled off-diagonal columns, which its applyElasticityTensor undoes).
inline void ogden_tensor(const Strain& s, const Spectral& sp, const double* p, double T[6][3][3]) {
    const double mu = p[0], alpha = p[1], k0 = p[2];
    const double half = alpha / 2, m1 = half - 1, m2 = half - 2;
    const double logJ = std::log(s.J);
    const Sym& Ca = sp.power_minus_one;
    const Sym& Ci = s.Cinv;
    for (int m = 0; m < 6; ++m) {
        const int i = m == 0 ? 0 : m == 1 ? 0 : m == 2 ? 1 : m == 3 ? 0 : m == 4 ? 1 : 2;
        const int j = m == 0 ? 0 : m == 1 ? 1 : m == 2 ? 1 : m == 3 ? 2 : m == 4 ? 2 : 2;
        for (int k = 0; k < 3; ++k)
            for (int l = 0; l < 3; ++l) {
                double t = 0;
                for (int a = 0; a < 3; ++a) {
                    const double power2 = std::pow(sp.value[a], m2);
                    t += sp.FJ * mu / alpha * m1 * power2 * sp.vector[i][a] * sp.vector[j][a] * sp.vector[k][a] *
                         sp.vector[l][a];
                    const double power1 = std::pow(sp.value[a], m1);
                    for (int b = 0; b < 3; ++b) {
                        if (b == a) continue;
                        const double largest = std::fmax(std::fabs(sp.value[a]), std::fabs(sp.value[b]));
                        const bool degenerate = std::fabs(sp.value[a] - sp.value[b]) < largest * 1e-8;
                        const double rotation = degenerate ? m1 * power2
                                                           : (power1 - std::pow(sp.value[b], m1)) /
                                                                 (sp.value[a] - sp.value[b]);
                        t += 0.5 * sp.FJ * mu / alpha * rotation *
                             (sp.vector[i][a] * sp.vector[j][b] * sp.vector[k][b] * sp.vector[l][a] +
                              sp.vector[i][a] * sp.vector[j][b] * sp.vector[k][a] * sp.vector[l][b]);
                    }
                }
                t += -sp.FJ * mu / 6 * (Ca(i, j) * Ci(l, k) + Ca(k, l) * Ci(j, i)) +
                     sp.FJ * mu * sp.trace_power / 18 * Ci(j, i) * Ci(l, k) +
                     sp.FJ * mu / (6 * alpha) * sp.trace_power * (Ci(k, i) * Ci(l, j) + Ci(l, i) * Ci(k, j));
                t += 0.5 * k0 * Ci(j, i) * Ci(l, k) - 0.5 * k0 * logJ * (Ci(j, k) * Ci(l, i) + Ci(j, l) * Ci(k, i));
                T[m][k][l] = t;
            }
    }
}

// Costa's Fung-type quantities: E = (C - I) / 2, Q = sum b_ij E_ij^2 (the b of each stored entry,
// off-diagonal ones twice), and U E (each entry of E times its b).
struct Costa {
    Sym UE;
    double Q;
    double Qbar;  // J^(-4/3) Q
};

inline Sym costa_weighted(const double* p, const Sym& a) {
    return Sym{{p[2] * a[0], p[3] * a[1], p[4] * a[2], p[5] * a[3], p[6] * a[4], p[7] * a[5]}};
}

inline Costa costa_of(const double* p, const Strain& s) {
    const Sym E = (s.C - identity()) / 2.0;
    Costa c;
    c.Q = p[2] * E[0] * E[0] + 2 * p[3] * E[1] * E[1] + p[4] * E[2] * E[2] + 2 * p[5] * E[3] * E[3] +
          2 * p[6] * E[4] * E[4] + p[7] * E[5] * E[5];
    c.Qbar = std::pow(s.J, -4.0 / 3.0) * c.Q;
    c.UE = costa_weighted(p, E);
    return c;
}

// ---- the materials ------------------------------------------------------------------------------

// Second Piola-Kirchhoff stress (each material's deriveSPKTensor).
inline Sym stress(int material, const double* p, const Strain& s) {
    const Sym I = identity();
    const Sym& Ci = s.Cinv;
    const double I1 = s.I1, J = s.J;
    switch (material) {
        case 1: {  // StVenantKirchhoff
            const double mu = p[0], lambda = p[1];
            return (lambda * (0.5 * (I1 - 3)) - mu) * I + mu * s.C;
        }
        case 2: {  // NeoHookean
            const double mu = p[0], lambda = p[1];
            return mu * I + (lambda * std::log(J) - mu) * Ci;
        }
        case 3: {  // MooneyRivlin
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (std::pow(I1, 2.0) - trace_of_square(s.C)) / 2;
            return (I - Ci * I1 / 3) * (2 * c1 * std::pow(J, -2.0 / 3.0)) +
                   (Ci * -2.0 * I2 / 3 + I * I1 - s.C) * (2 * c2 * std::pow(J, -4.0 / 3.0)) + Ci * k0 * std::log(J);
        }
        case 4: {  // VerondaWestman
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (std::pow(I1, 2.0) - trace_of_square(s.C)) / 2;
            const double J23 = std::pow(J, -2.0 / 3.0);
            return (I - Ci * I1 / 3) * 2 * c1 * c2 * J23 * std::exp(c2 * (J23 * I1 - 3)) +
                   (I * I1 - s.C - Ci * I2 * 2 / 3) * (-c1 * c2 * std::pow(J, -4.0 / 3.0)) + Ci * k0 * std::log(J);
        }
        case 5: {  // Costa
            const double a = p[0], k0 = p[1];
            const Costa c = costa_of(p, s);
            return (c.UE - Ci * (2.0 / 3.0) * c.Q) * (a * std::exp(c.Qbar) * std::pow(J, -4.0 / 3.0)) +
                   Ci * k0 * J * std::log(J);
        }
        case 6: {  // Ogden
            const double mu = p[0], alpha = p[1], k0 = p[2];
            const Spectral sp = spectral_of(s, alpha);
            return sp.power_minus_one * sp.FJ * mu / alpha - Ci * sp.FJ * mu / (3 * alpha) * sp.trace_power +
                   Ci * k0 * std::log(J);
        }
        case 7: {  // StableNeoHookean
            const double mu = p[0], lambda = p[1];
            const double alpha = 1 + mu / (lambda + mu);
            return mu * I + ((lambda + mu) * J * (J - alpha)) * Ci;
        }
        default: {  // ArrudaBoyce
            const double mu = p[0], k0 = p[1];
            const Sym series = (Ci * (-1.0 / 3.0) * I1 + I) * AB1 * std::pow(J, -2.0 / 3.0) +
                               (Ci * (-2.0 / 3.0) * I1 * I1 + I * 2.0 * I1) * AB2 * std::pow(J, -4.0 / 3.0) +
                               (I * 3.0 * I1 * I1 - Ci * I1 * I1 * I1) * AB3 * std::pow(J, -2.0) +
                               (Ci * (-4.0 / 3.0) * std::pow(I1, 4.0) + I * 4.0 * std::pow(I1, 3.0)) * AB4 *
                                   std::pow(J, -8.0 / 3.0) +
                               (Ci * (-5.0 / 3.0) * std::pow(I1, 5.0) + I * 5.0 * std::pow(I1, 4.0)) * AB5 *
                                   std::pow(J, -10.0 / 3.0);
            return series * 2.0 * mu + Ci * k0 * std::log(J);
        }
    }
}

// The elasticity applied to H = dC: dS (each material's applyElasticityTensor). Ogden reads its
// tensor `ogden` (ogden_tensor of the same strain).
inline Sym elasticity(int material, const double* p, const Strain& s, const Sym& H, const double ogden[6][3][3]) {
    const Sym I = identity();
    const Sym& Ci = s.Cinv;
    const double I1 = s.I1, J = s.J;
    const double trHC = contract(H, Ci);  // Cinv : H
    const Sym first = sandwich(Ci, H);    // Cinv H Cinv
    const double trH = trace(H);
    switch (material) {
        case 1: {  // StVenantKirchhoff
            const double mu = p[0], lambda = p[1];
            return I * (trH * lambda / 2.0) + H * mu;
        }
        case 2: {  // NeoHookean
            const double mu = p[0], lambda = p[1];
            return first * (mu - lambda * std::log(J)) + Ci * (lambda * trHC / 2);
        }
        case 3: {  // MooneyRivlin
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (std::pow(I1, 2.0) - trace_of_square(s.C)) / 2;
            const double trHCc = contract(H, s.C);
            return ((I - Ci * I1 / 3.0) * (-trHC) / 3.0 + first * I1 / 3.0 - Ci * trH / 3.0) * 2.0 * c1 *
                       std::pow(J, -2.0 / 3.0) +
                   ((Ci * (-2.0) * I2 / 3.0 + I * I1 - s.C) * (-2.0) * trHC / 3.0 + first * 2.0 * I2 / 3.0 -
                    Ci * 2.0 * (I1 * trH - trHCc) / 3.0 + I * trH - H) *
                       2.0 * c2 * std::pow(J, -4.0 / 3.0) +
                   Ci * trHC * k0 / 2.0 - first * k0 * std::log(J);
        }
        case 4: {  // VerondaWestman
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (std::pow(I1, 2.0) - trace_of_square(s.C)) / 2;
            const double trHCc = contract(H, s.C);
            const double J23 = std::pow(J, -2.0 / 3.0), J43 = std::pow(J, -4.0 / 3.0);
            const double e = std::exp(c2 * (I1 * J23 - 3.0));
            return (Ci * I1 * trHC / 9.0 - Ci * trH / 3.0 + first / 3.0 * I1 - I * trHC / 3.0) * 2.0 * c1 * c2 * J23 * e +
                   (I - Ci * I1 / 3.0) * e * 2 * c1 * c2 * c2 * J43 * (-I1 * trHC / 3.0 + trH) +
                   (Ci * (-4.0) * trHC * I2 / 9.0 + Ci * 2.0 * I1 * trH / 3.0 - Ci * 2.0 * trHCc / 3.0 -
                    first * 2.0 * I2 / 3.0 + I * trHC * I1 * (2.0 / 3.0) - I * trH - s.C * trHC * (2.0 / 3.0) + H) *
                       c1 * c2 * J43 +
                   first * (-k0) * std::log(J) + Ci * k0 * trHC / 2.0;
        }
        case 5: {  // Costa; its volumetric term -Cinv H Cinv J ln J lacks k0 in SOFA, kept (exact for k0 = 1)
            const double a = p[0], k0 = p[1];
            const Costa c = costa_of(p, s);
            const Sym UH = costa_weighted(p, H);
            const double trHUE = contract(H, c.UE);
            const Sym deviation = c.UE - Ci * (2.0 / 3.0) * c.Q;
            return (deviation * ((-2.0 / 3.0) * trHC) + UH / 2.0 + first * (2.0 / 3.0) * c.Q -
                    Ci * (2.0 / 3.0) * trHUE) *
                       (a * std::pow(J, -4.0 / 3.0) * std::exp(c.Qbar)) +
                   deviation * (a * std::pow(J, -8.0 / 3.0) * (trHUE - (2.0 / 3.0) * c.Q * trHC) * std::exp(c.Qbar)) +
                   Ci * k0 / 2.0 * J * (std::log(J) + 1) * trHC - first * J * std::log(J);
        }
        case 6: {  // Ogden: sum over k, l of dS_ij/dC_kl H_kl
            Sym r;
            for (int m = 0; m < 6; ++m) {
                double t = 0;
                for (int k = 0; k < 3; ++k)
                    for (int l = 0; l < 3; ++l) t += ogden[m][k][l] * H(k, l);
                r[m] = t;
            }
            return r;
        }
        case 7: {  // StableNeoHookean
            const double mu = p[0], lambda = p[1];
            const double alpha = 1 + mu / (lambda + mu);
            return 0.5 * (lambda + mu) * (first * (-2 * J * (J - alpha)) + Ci * (J * (2 * J - alpha) * trHC));
        }
        default: {  // ArrudaBoyce
            const double mu = p[0], k0 = p[1];
            const Sym series =
                ((Ci * (-1.0 / 3.0) * I1 + I) * (-1.0 / 3.0) * trHC - Ci * (1.0 / 3.0) * trH + first * (1.0 / 3.0) * I1) *
                    AB1 * std::pow(J, -2.0 / 3.0) +
                ((Ci * (-2.0 / 3.0) * I1 * I1 + I * 2.0 * I1) * (-2.0 / 3.0) * trHC - Ci * (4.0 / 3.0) * I1 * trH +
                 first * (2.0 / 3.0) * I1 * I1 + I * 2.0 * trH) *
                    AB2 * std::pow(J, -4.0 / 3.0) +
                ((Ci * (-I1) * I1 * I1 + I * 3.0 * I1 * I1) * (-trHC) - Ci * 3.0 * I1 * I1 * trH + first * I1 * I1 * I1 +
                 I * 6.0 * I1 * trH) *
                    AB3 * std::pow(J, -2.0) +
                ((Ci * (-4.0 / 3.0) * std::pow(I1, 4.0) + I * 4.0 * std::pow(I1, 3.0)) * (-4.0 / 3.0) * trHC -
                 Ci * (16.0 / 3.0) * std::pow(I1, 3.0) * trH + first * (4.0 / 3.0) * std::pow(I1, 4.0) +
                 I * 12.0 * I1 * I1 * trH) *
                    AB4 * std::pow(J, -8.0 / 3.0) +
                ((Ci * (-5.0 / 3.0) * std::pow(I1, 5.0) + I * 5.0 * std::pow(I1, 4.0)) * (-5.0 / 3.0) * trHC -
                 Ci * (25.0 / 3.0) * std::pow(I1, 4.0) * trH + first * (5.0 / 3.0) * std::pow(I1, 5.0) +
                 I * 20.0 * std::pow(I1, 3.0) * trH) *
                    AB5 * std::pow(J, -10.0 / 3.0);
            return series * 2.0 * mu + Ci * (k0 / 2.0) * trHC - first * (k0 * std::log(J));
        }
    }
}

// Strain energy density W (the potential of `stress`: S = 2 dW/dC). For MooneyRivlin this is the
// textbook energy, not SOFA's getStrainEnergy (whose exponents -2/3 and -4/3 are integer divisions,
// 0); SOFA never uses these in a step.
inline double energy_density(int material, const double* p, const Strain& s) {
    const double I1 = s.I1, J = s.J, logJ = std::log(J);
    switch (material) {
        case 1: {
            const double mu = p[0], lambda = p[1];
            const double trE = 0.5 * (I1 - 3), trE2 = 0.25 * (trace_of_square(s.C) - 2 * I1 + 3);
            return 0.5 * lambda * trE * trE + mu * trE2;
        }
        case 2: {
            const double mu = p[0], lambda = p[1];
            return 0.5 * mu * (I1 - 3) - mu * logJ + 0.5 * lambda * logJ * logJ;
        }
        case 3: {
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (I1 * I1 - trace_of_square(s.C)) / 2;
            return c1 * (I1 * std::pow(J, -2.0 / 3.0) - 3) + c2 * (I2 * std::pow(J, -4.0 / 3.0) - 3) +
                   k0 * logJ * logJ / 2;
        }
        case 4: {
            const double c1 = p[0], c2 = p[1], k0 = p[2];
            const double I2 = (I1 * I1 - trace_of_square(s.C)) / 2;
            return c1 * (std::exp(c2 * (std::pow(J, -2.0 / 3.0) * I1 - 3)) - 1) -
                   c1 * c2 * (std::pow(J, -4.0 / 3.0) * I2 - 3) / 2 + k0 * logJ * logJ / 2;
        }
        case 5: {
            const Costa c = costa_of(p, s);
            return p[0] * (std::exp(c.Qbar) - 1) / 2 + p[1] * (J * logJ - J - 1);
        }
        case 6: {
            const double mu = p[0], alpha = p[1], k0 = p[2];
            const Spectral sp = spectral_of(s, alpha);
            const double scale = mu / (alpha * alpha);
            return sp.FJ * scale * sp.trace_power - 3 * scale + k0 * logJ * logJ / 2;
        }
        case 7: {
            const double mu = p[0], lambda = p[1];
            const double alpha = 1 + mu / (lambda + mu);
            return 0.5 * (mu * (I1 - 3) + (lambda + mu) * (J - alpha) * (J - alpha));
        }
        default: {
            const double mu = p[0], k0 = p[1];
            return mu * (AB1 * (std::pow(J, -2.0 / 3.0) * I1 - 3) + AB2 * (std::pow(J, -4.0 / 3.0) * I1 * I1 - 9) +
                         AB3 * (std::pow(J, -2.0) * I1 * I1 * I1 - 27) +
                         AB4 * (std::pow(J, -8.0 / 3.0) * std::pow(I1, 4.0) - std::pow(3.0, 4.0)) +
                         AB5 * (std::pow(J, -10.0 / 3.0) * std::pow(I1, 5.0) - std::pow(3.0, 5.0))) +
                   k0 * logJ * logJ / 2;
        }
    }
}

// F (row-major) and J of element e at positions x, in SOFA's order of operations.
inline void deformation(const Index* t, const double* x, const double* d, double* F, double& J) {
    const double* x0 = x + 3 * t[0];
    double dp[3][3];
    for (int j = 0; j < 3; ++j)
        for (int c = 0; c < 3; ++c) dp[j][c] = x[3 * t[j + 1] + c] - x0[c];
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l) F[3 * k + l] = dp[0][k] * d[SHAPE + 3 + l];
    for (int j = 1; j < 3; ++j)
        for (int k = 0; k < 3; ++k)
            for (int l = 0; l < 3; ++l) F[3 * k + l] += dp[j][k] * d[SHAPE + 3 * (j + 1) + l];
    const double area[3] = {dp[1][1] * dp[2][2] - dp[1][2] * dp[2][1], dp[1][2] * dp[2][0] - dp[1][0] * dp[2][2],
                            dp[1][0] * dp[2][1] - dp[1][1] * dp[2][0]};
    J = (area[0] * dp[0][0] + area[1] * dp[0][1] + area[2] * dp[0][2]) * d[VOLUME_SCALE];
}

}  // namespace hyper_detail

// One element's data: hyper_detail::SIZE doubles (tests/test_layout.py reads it).
constexpr int hyperelastic_data_size() { return hyper_detail::SIZE; }

// SOFA's createTetrahedronRestInformation for every element; marks the tangent stale.
inline void hyperelastic_init(const Index* tetra, Index count, const double* rest, double* data) {
    using namespace hyper_detail;
    for (Index e = 0; e < count; ++e) {
        const Index* t = tetra + 4 * e;
        double* d = data + SIZE * e;
        double p[4][3];
        for (int j = 0; j < 4; ++j)
            for (int c = 0; c < 3; ++c) p[j][c] = rest[3 * t[j] + c];
        auto cross_of = [&](int a, int b, int o, double out[3]) {
            const double u[3] = {p[a][0] - p[o][0], p[a][1] - p[o][1], p[a][2] - p[o][2]};
            const double v[3] = {p[b][0] - p[o][0], p[b][1] - p[o][1], p[b][2] - p[o][2]};
            out[0] = u[1] * v[2] - u[2] * v[1];
            out[1] = u[2] * v[0] - u[0] * v[2];
            out[2] = u[0] * v[1] - u[1] * v[0];
        };
        double n[3];
        cross_of(2, 3, 0, n);
        const double volume = n[0] * (p[1][0] - p[0][0]) + n[1] * (p[1][1] - p[0][1]) + n[2] * (p[1][2] - p[0][2]);
        d[VOLUME_SCALE] = 1.0 / volume;
        d[VOLUME] = std::fabs(volume / 6);
        for (int j = 0; j < 4; ++j) {
            const double sign = j % 2 ? 1 : -1;
            double c[3];
            cross_of((j + 2) % 4, (j + 3) % 4, (j + 1) % 4, c);
            for (int k = 0; k < 3; ++k) d[SHAPE + 3 * j + k] = sign * c[k] / volume;
        }
        // the rest state (F = I, J = 1, S = 0: every material is stress-free there) until a force
        // is evaluated, so that a tangent asked for first (an assembly's pattern) is finite
        for (int k = GRADIENT; k < VOLUME_SCALE; ++k) d[k] = 0.0;
        d[GRADIENT] = d[GRADIENT + 4] = d[GRADIENT + 8] = 1.0;
        d[JACOBIAN] = 1.0;
    }
    data[SIZE * count] = 1.0;
}

// f += f(x) (SOFA's addForce); keeps F, S and J per element for the tangent.
inline void hyperelastic_add_force(const Index* tetra, Index count, const double* x, double* f, double* data,
                                   int material, const double* parameters) {
    using namespace hyper_detail;
    for (Index e = 0; e < count; ++e) {
        const Index* t = tetra + 4 * e;
        double* d = data + SIZE * e;
        double* F = d + GRADIENT;
        deformation(t, x, d, F, d[JACOBIAN]);
        const Strain s = strain_of(F, d[JACOBIAN]);
        const Sym S = stress(material, parameters, s);
        for (int i = 0; i < 6; ++i) d[STRESS + i] = S[i];
        for (int l = 0; l < 4; ++l) {
            double Ssv[3];
            sym_times(S, d + SHAPE + 3 * l, Ssv);
            for (int r = 0; r < 3; ++r)
                f[3 * t[l] + r] -= (F[3 * r] * Ssv[0] + F[3 * r + 1] * Ssv[1] + F[3 * r + 2] * Ssv[2]) * d[VOLUME];
        }
    }
    data[SIZE * count] = 1.0;
}

// SOFA's updateTangentMatrix: the six edge blocks D of every element from its last F and S.
inline void hyperelastic_update_tangent(Index count, double* data, int material, const double* parameters) {
    using namespace hyper_detail;
    if (data[SIZE * count] == 0.0) return;
    double ogden[6][3][3] = {};
    for (Index e = 0; e < count; ++e) {
        double* d = data + SIZE * e;
        const double* F = d + GRADIENT;
        const Strain s = strain_of(F, d[JACOBIAN]);
        Sym S;
        for (int i = 0; i < 6; ++i) S[i] = d[STRESS + i];
        if (material == 6) ogden_tensor(s, spectral_of(s, parameters[1]), parameters, ogden);
        for (int j = 0; j < 6; ++j) {
            const double* svk = d + SHAPE + 3 * EDGES[j][0];
            const double* svl = d + SHAPE + 3 * EDGES[j][1];
            double N[3][3];
            for (int a = 0; a < 3; ++a) {
                Sym H;
                for (int m = 0; m < 3; ++m)
                    for (int n = m; n < 3; ++n) H[Sym::index(m, n)] = svl[m] * F[3 * a + n] + F[3 * a + m] * svl[n];
                const Sym dS = elasticity(material, parameters, s, H, ogden);
                double w[3];
                sym_times(dS, svk, w);
                for (int u = 0; u < 3; ++u) N[a][u] = F[3 * u] * w[0] + F[3 * u + 1] * w[1] + F[3 * u + 2] * w[2];
            }
            double Ssv[3];
            sym_times(S, svk, Ssv);
            const double product = Ssv[0] * svl[0] + Ssv[1] * svl[1] + Ssv[2] * svl[2];
            double* D = d + BLOCKS + 9 * j;
            for (int a = 0; a < 3; ++a)
                for (int u = 0; u < 3; ++u) D[3 * a + u] = (N[a][u] + (a == u ? product : 0.0)) * d[VOLUME];
        }
    }
    data[SIZE * count] = 0.0;
}

// df += kfactor K dx (SOFA's addDForce; kfactor includes the component's Rayleigh stiffness).
inline void hyperelastic_add_dforce(const Index* tetra, Index count, const double* dx, double* df, double kfactor,
                                    double* data, int material, const double* parameters) {
    using namespace hyper_detail;
    hyperelastic_update_tangent(count, data, material, parameters);
    for (Index e = 0; e < count; ++e) {
        const Index* t = tetra + 4 * e;
        const double* d = data + SIZE * e;
        for (int j = 0; j < 6; ++j) {
            const Index v0 = t[EDGES[j][0]], v1 = t[EDGES[j][1]];
            const double* D = d + BLOCKS + 9 * j;
            const double delta[3] = {dx[3 * v0] - dx[3 * v1], dx[3 * v0 + 1] - dx[3 * v1 + 1],
                                     dx[3 * v0 + 2] - dx[3 * v1 + 2]};
            for (int i = 0; i < 3; ++i) {
                const double along = D[3 * i] * delta[0] + D[3 * i + 1] * delta[1] + D[3 * i + 2] * delta[2];
                const double transposed = delta[0] * D[i] + delta[1] * D[3 + i] + delta[2] * D[6 + i];
                df[3 * v0 + i] += transposed * kfactor;
                df[3 * v1 + i] -= along * kfactor;
            }
        }
    }
}

// An assembled solver's share: kfactor times the force Jacobian (SOFA's addKToMatrix).
// `Assembler` is sofac::Assembler.
template <class Assembler>
inline void hyperelastic_assemble(Assembler& A, const Index* tetra, Index count, double* data, int material,
                                  const double* parameters, Index offset, double kfactor) {
    using namespace hyper_detail;
    hyperelastic_update_tangent(count, data, material, parameters);
    for (Index e = 0; e < count; ++e) {
        const Index* t = tetra + 4 * e;
        const double* d = data + SIZE * e;
        for (int j = 0; j < 6; ++j) {
            const Index n0 = offset + 3 * t[EDGES[j][0]], n1 = offset + 3 * t[EDGES[j][1]];
            const double* D = d + BLOCKS + 9 * j;
            for (int i = 0; i < 3; ++i)
                for (int c = 0; c < 3; ++c) {
                    A.add(n0 + i, n0 + c, D[3 * c + i] * kfactor);
                    A.add(n0 + i, n1 + c, -D[3 * c + i] * kfactor);
                    A.add(n1 + i, n0 + c, -D[3 * i + c] * kfactor);
                    A.add(n1 + i, n1 + c, D[3 * i + c] * kfactor);
                }
        }
    }
}

// Sum of W V over the elements at positions x (not SOFA's getPotentialEnergy, which is 0).
inline double hyperelastic_strain_energy(const Index* tetra, Index count, const double* x, const double* data,
                                         int material, const double* parameters) {
    using namespace hyper_detail;
    double total = 0;
    for (Index e = 0; e < count; ++e) {
        const double* d = data + SIZE * e;
        double F[9], J;
        deformation(tetra + 4 * e, x, d, F, J);
        total += energy_density(material, parameters, strain_of(F, J)) * d[VOLUME];
    }
    return total;
}

}  // namespace sofac
