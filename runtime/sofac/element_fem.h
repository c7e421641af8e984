// SOFA's element-based finite elements (Sofa.Component.SolidMechanics.FEM.Elastic's
// CorotationalFEMForceField and LinearSmallStrainFEMForceField, Sofa.Component.Mass's FEMMass with a
// NodalMassDensity), for Vec3d on linear tetrahedra (4 nodes) and trilinear hexahedra (8 nodes).
//
// Written from a reading of SOFA's sources at the corpus commit (2a278d89): the element helpers
// (sofa::fem::FiniteElement: reference shape functions, their gradients, Gauss points), the
// integration of B^T C B, the corotational frames and the scalar CRS mass matrix. No SOFA code is
// included. Where it matters for bit-level agreement the floating-point operations are done in
// SOFA's order (sums left to right, the same products, the same divisions); compile with
// -ffp-contract=off.
//
// Conventions
// - Positions / forces are flat Vec3d arrays; elements are flat index arrays (N per element) in the
//   topology's order (sofa::geometry::Tetrahedron / Hexahedron node numbering).
// - Element stiffness matrices (SOFA's d_elementStiffness) are stored row-major, (3N)^2 doubles per
//   element, computed once by element_fem_stiffness_init on the rest positions.
// - add_force: f += f(x) (f_node -= (K u)_node, u the element displacement);
//   add_dforce: df_node -= kfactor * (K du)_node, as SOFA's dispatchElementForcesDerivToNodes
//   (kfactor = kFactorIncludingRayleighDamping; the component's own rayleighStiffness must be 0).
// - The "parallel" compute strategies of SOFA compute the same element vectors and dispatch them
//   sequentially; the result does not depend on the strategy.
// - FEMMass: the scalar (per node pair) mass matrix M_ij = sum over elements and Gauss points of
//   w |det J| rho(q) N_i N_j, stored as CSR (row_begin, cols, values) over the node pairs present;
//   the pattern comes from the compiler (sorted node pairs), the values from fem_mass_init.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "fem.h"
#include "types.h"

namespace sofac {

namespace element_fem_detail {

using fem_detail::M3;
using fem_detail::V3;

// ---- reference elements (sofa::fem::FiniteElement) ------------------------------------------

template <int N>
struct Element;

// Linear tetrahedron: reference nodes (0,0,0) (1,0,0) (0,1,0) (0,0,1), one Gauss point at the
// centroid with weight 1/6.
template <>
struct Element<4> {
    static constexpr int quadrature_points = 1;
    static void quadrature(int, double q[3], double& weight) {
        q[0] = q[1] = q[2] = 1. / 4.;
        weight = 1. / 6.;
    }
    static void gradients(const double*, double g[4][3]) {
        const double values[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        for (int i = 0; i < 4; ++i)
            for (int c = 0; c < 3; ++c) g[i][c] = values[i][c];
    }
    static void shape(const double* q, double n[4]) {
        n[0] = 1.0 - q[0] - q[1] - q[2];
        n[1] = q[0];
        n[2] = q[1];
        n[3] = q[2];
    }
};

// Trilinear hexahedron on [-1, 1]^3, nodes in sofa::geometry::Hexahedron's order; 2x2x2 Gauss
// points at +-1/sqrt(3) (SOFA's constant 1.73205080757), weight 1.
template <>
struct Element<8> {
    static constexpr int quadrature_points = 8;
    static constexpr double reference[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                               {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
    static void quadrature(int k, double q[3], double& weight) {
        constexpr double sqrt3 = 1.73205080757;
        const double inverse = 1.0 / sqrt3;
        for (int c = 0; c < 3; ++c) q[c] = reference[k][c] * inverse;
        weight = 1.0;
    }
    static void gradients(const double* q, double g[8][3]) {
        const double x = q[0], y = q[1], z = q[2];
        for (int i = 0; i < 8; ++i) {
            const double xr = reference[i][0], yr = reference[i][1], zr = reference[i][2];
            g[i][0] = xr * (1 + y * yr) * (1 + z * zr) * (1. / 8.);
            g[i][1] = yr * (1 + x * xr) * (1 + z * zr) * (1. / 8.);
            g[i][2] = zr * (1 + x * xr) * (1 + y * yr) * (1. / 8.);
        }
    }
    static void shape(const double* q, double n[8]) {
        const double a = 0.125;
        n[0] = -a * (q[0] - 1) * (q[1] - 1) * (q[2] - 1);
        n[1] = a * (q[0] + 1) * (q[1] - 1) * (q[2] - 1);
        n[2] = -a * (q[0] + 1) * (q[1] + 1) * (q[2] - 1);
        n[3] = a * (q[0] - 1) * (q[1] + 1) * (q[2] - 1);
        n[4] = a * (q[0] - 1) * (q[1] - 1) * (q[2] + 1);
        n[5] = -a * (q[0] + 1) * (q[1] - 1) * (q[2] + 1);
        n[6] = a * (q[0] + 1) * (q[1] + 1) * (q[2] + 1);
        n[7] = -a * (q[0] - 1) * (q[1] + 1) * (q[2] + 1);
    }
};

// Jacobian of the reference-to-physical map: J = sum_i x_i (dN_i/dq)^T, accumulated node by node.
template <int N>
inline M3 jacobian(const V3* nodes, const double g[N][3]) {
    M3 J{{{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}};
    for (int i = 0; i < N; ++i)
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) J(r, c) += nodes[i][r] * g[i][c];
    return J;
}

// Voigt indices of SOFA's VoigtNotation (3D): xx yy zz yz xz xy.
constexpr int voigt[6][2] = {{0, 0}, {1, 1}, {2, 2}, {1, 2}, {0, 2}, {0, 1}};

// Isotropic elasticity tensor in Voigt form (makeIsotropicElasticityTensor with the Lame
// parameters of toLameParameters<3>), engineering shear strains.
inline void isotropic_tensor(double young, double poisson, double C[6][6]) {
    const double mu = young / (2 * (1 + poisson));
    const double lambda = young * poisson / ((1 + poisson) * (1 - 2.0 * poisson));
    auto delta = [](int i, int j) { return i == j ? 1.0 : 0.0; };
    for (int a = 0; a < 6; ++a)
        for (int b = a; b < 6; ++b) {
            const int i = voigt[a][0], j = voigt[a][1], k = voigt[b][0], l = voigt[b][1];
            C[a][b] = mu * (delta(i, k) * delta(j, l) + delta(i, l) * delta(j, k)) + lambda * delta(i, j) * delta(k, l);
            C[b][a] = C[a][b];
        }
}

// Ke = sum over Gauss points of (w |det J|) B^T (C B), SOFA's `integrate` with its generic matrix
// products (C B accumulated over the Voigt index from 0; B^T (C B) from the first product).
template <int N>
inline void element_stiffness(const V3* nodes, const double C[6][6], double* K) {
    constexpr int D = 3 * N;
    for (int k = 0; k < D * D; ++k) K[k] = 0.0;
    for (int p = 0; p < Element<N>::quadrature_points; ++p) {
        double q[3], weight;
        Element<N>::quadrature(p, q, weight);
        double g[N][3];
        Element<N>::gradients(q, g);
        const M3 J = jacobian<N>(nodes, g);
        const double detJ = std::fabs(fem_detail::determinant(J));
        M3 Jinv = J;  // SOFA's Mat::inverted() returns the matrix unchanged when it is singular
        fem_detail::invert(Jinv, J);
        double dN[N][3];  // physical gradients: J^-T dN/dq
        for (int i = 0; i < N; ++i)
            for (int a = 0; a < 3; ++a) dN[i][a] = Jinv(0, a) * g[i][0] + Jinv(1, a) * g[i][1] + Jinv(2, a) * g[i][2];
        double B[6][D] = {};
        for (int v = 0; v < 6; ++v) {
            const int i = voigt[v][0], j = voigt[v][1];
            for (int n = 0; n < N; ++n) {
                B[v][3 * n + i] = dN[n][j];
                if (i != j) B[v][3 * n + j] = dN[n][i];
            }
        }
        double CB[6][D];
        for (int r = 0; r < 6; ++r)
            for (int c = 0; c < D; ++c) {
                double s = 0.0;
                for (int k = 0; k < 6; ++k) s += C[r][k] * B[k][c];
                CB[r][c] = s;
            }
        const double factor = weight * detJ;
        for (int r = 0; r < D; ++r)
            for (int c = 0; c < D; ++c) {
                double s = B[0][r] * CB[0][c];
                for (int k = 1; k < 6; ++k) s += B[k][r] * CB[k][c];
                K[D * r + c] += s * factor;
            }
    }
}

// r = K v for a (3N)x(3N) row-major matrix (SOFA's Mat * Vec: each row summed left to right).
template <int N>
inline void mat_vec(const double* K, const double* v, double* r) {
    constexpr int D = 3 * N;
    for (int i = 0; i < D; ++i) {
        double s = K[D * i] * v[0];
        for (int j = 1; j < D; ++j) s += K[D * i + j] * v[j];
        r[i] = s;
    }
}

// Centroid: zero, plus each node in turn, divided by N.
template <int N>
inline V3 centroid(const V3* nodes) {
    V3 c{{0.0, 0.0, 0.0}};
    for (int i = 0; i < N; ++i)
        for (int d = 0; d < 3; ++d) c[d] += nodes[i][d];
    for (int d = 0; d < 3; ++d) c[d] /= static_cast<double>(N);
    return c;
}

// Rotation methods of CorotationalFEMForceField (rotationMethod): 0 = the element's frame
// ("triangle" for tetrahedra, "hexahedron" for hexahedra), 1 = "identity", 2 = "polar",
// 3 = "stable_polar".
//
// The frame (rows x, y, z) of the current nodes: tetrahedra from the first three nodes (Gram-Schmidt
// of edges 0->1, 0->2), hexahedra from two mean edges.
template <int N>
inline M3 element_frame(const V3* n) {
    V3 x, y;
    if constexpr (N == 4) {
        x = fem_detail::sub(n[1], n[0]);
        fem_detail::normalize(x);
        y = fem_detail::sub(n[2], n[0]);
    } else {
        for (int d = 0; d < 3; ++d) {
            x[d] = (n[1][d] - n[0][d] + n[2][d] - n[3][d] + n[5][d] - n[4][d] + n[6][d] - n[7][d]) * 0.25;
            y[d] = (n[3][d] - n[0][d] + n[2][d] - n[1][d] + n[7][d] - n[4][d] + n[6][d] - n[5][d]) * 0.25;
        }
        fem_detail::normalize(x);
    }
    V3 z = fem_detail::cross(x, y);
    fem_detail::normalize(z);
    y = fem_detail::cross(z, x);
    return fem_detail::from_rows(x, y, z);
}

// SOFA's RotationMethodsContainer::computeRotation(R, R_initial, nodes, rest nodes).
template <int N>
inline M3 element_rotation(int method, const M3& initial, const V3* nodes, const V3* rest) {
    using namespace fem_detail;
    if (method == 0) return mul_tn(element_frame<N>(nodes), initial);
    if (method == 1) return identity();
    const V3 t = centroid<N>(nodes), t0 = centroid<N>(rest);
    M3 H;  // P^T Q, P and Q the centred current and rest nodes (rows)
    V3 P[N], Q[N];
    for (int j = 0; j < N; ++j) {
        P[j] = sub(nodes[j], t);
        Q[j] = sub(rest[j], t0);
    }
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double s = P[0][i] * Q[0][j];
            for (int k = 1; k < N; ++k) s += P[k][i] * Q[k][j];
            H(i, j) = s;
        }
    return method == 2 ? polar_rotation(H) : svd_stable_rotation(H);
}

template <int N>
inline void gather(const Index* element, const double* x, V3* out) {
    for (int j = 0; j < N; ++j) out[j] = fem_detail::load(x + 3 * element[j]);
}

}  // namespace element_fem_detail

// ---- BaseElementLinearFEMForceField: element stiffness matrices ------------------------------

// SOFA's precomputeElementStiffness: Ke of each element on the rest positions, with its Young's
// modulus and Poisson's ratio (per-element lists, SOFA's fallbacks and range checks).
template <int N>
inline void element_fem_stiffness_init(const Index* elements, Index count, const double* rest, const double* young,
                                       Index n_young, const double* poisson, Index n_poisson, double* stiffness) {
    using namespace element_fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        double C[6][6];
        isotropic_tensor(fem_detail::element_value(young, n_young, e), fem_detail::element_value(poisson, n_poisson, e), C);
        V3 nodes[N];
        gather<N>(elements + N * e, rest, nodes);
        element_stiffness<N>(nodes, C, stiffness + static_cast<Index>(D) * D * e);
    }
}

// ---- LinearSmallStrainFEMForceField ---------------------------------------------------------

// f_node -= (Ke (x - x0))_node
template <int N>
inline void element_linear_add_force(const Index* elements, Index count, const double* x, const double* rest,
                                     const double* stiffness, double* f) {
    using namespace element_fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        double u[D], F[D];
        for (int j = 0; j < N; ++j)
            for (int d = 0; d < 3; ++d) u[3 * j + d] = x[3 * element[j] + d] - rest[3 * element[j] + d];
        mat_vec<N>(stiffness + static_cast<Index>(D) * D * e, u, F);
        for (int j = 0; j < N; ++j)
            for (int d = 0; d < 3; ++d) f[3 * element[j] + d] -= F[3 * j + d];
    }
}

// df_node -= kfactor * (Ke dx)_node
template <int N>
inline void element_linear_add_dforce(const Index* elements, Index count, const double* dx, double* df,
                                      double kfactor, const double* stiffness) {
    using namespace element_fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        double u[D], F[D];
        for (int j = 0; j < N; ++j)
            for (int d = 0; d < 3; ++d) u[3 * j + d] = dx[3 * element[j] + d];
        mat_vec<N>(stiffness + static_cast<Index>(D) * D * e, u, F);
        for (int j = 0; j < N; ++j)
            for (int d = 0; d < 3; ++d) df[3 * element[j] + d] -= kfactor * F[3 * j + d];
    }
}

// ---- CorotationalFEMForceField --------------------------------------------------------------
// `rotations`: 18 doubles per element, row-major: SOFA's m_initialRotationsTransposed[e] (the rest
// frame) then m_rotations[e] (the current rotation, set by add_force, read by add_dforce and the
// assembly).

constexpr int ELEMENT_ROTATION_SIZE = 18;

// computeInitialRotations: the rotation of the rest nodes relative to the identity, transposed;
// current rotations start as the identity.
template <int N>
inline void element_corot_init(const Index* elements, Index count, const double* rest, int method,
                               double* rotations) {
    using namespace element_fem_detail;
    for (Index e = 0; e < count; ++e) {
        V3 nodes[N];
        gather<N>(elements + N * e, rest, nodes);
        const M3 initial = element_rotation<N>(method, fem_detail::identity(), nodes, nodes);
        fem_detail::store_m(rotations + ELEMENT_ROTATION_SIZE * e, fem_detail::transposed(initial));
        fem_detail::store_m(rotations + ELEMENT_ROTATION_SIZE * e + 9, fem_detail::identity());
    }
}

// u_j = R^T (x_j - t) - (x0_j - t0) (t, t0 the centroids); f_node -= R (Ke u)_node.
template <int N>
inline void element_corot_add_force(const Index* elements, Index count, const double* x, const double* rest,
                                    const double* stiffness, int method, double* rotations, double* f) {
    using namespace element_fem_detail;
    using namespace fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        double* rot = rotations + ELEMENT_ROTATION_SIZE * e;
        V3 nodes[N], rest_nodes[N];
        gather<N>(element, x, nodes);
        gather<N>(element, rest, rest_nodes);
        const M3 R = element_rotation<N>(method, load_m(rot), nodes, rest_nodes);
        store_m(rot + 9, R);
        const V3 t = centroid<N>(nodes), t0 = centroid<N>(rest_nodes);
        double u[D], F[D];
        for (int j = 0; j < N; ++j) {
            const V3 local = mul_t(R, sub(nodes[j], t));
            const V3 initial = sub(rest_nodes[j], t0);
            for (int d = 0; d < 3; ++d) u[3 * j + d] = local[d] - initial[d];
        }
        mat_vec<N>(stiffness + static_cast<Index>(D) * D * e, u, F);
        for (int j = 0; j < N; ++j) {
            const V3 world = mul(R, V3{{F[3 * j], F[3 * j + 1], F[3 * j + 2]}});
            for (int d = 0; d < 3; ++d) f[3 * element[j] + d] -= world[d];
        }
    }
}

// df_node -= kfactor * R (Ke R^T dx)_node with the rotations of the last add_force.
template <int N>
inline void element_corot_add_dforce(const Index* elements, Index count, const double* dx, double* df,
                                     double kfactor, const double* stiffness, const double* rotations) {
    using namespace element_fem_detail;
    using namespace fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        const M3 R = load_m(rotations + ELEMENT_ROTATION_SIZE * e + 9);
        double u[D], F[D];
        for (int j = 0; j < N; ++j) {
            const V3 local = mul_t(R, load(dx + 3 * element[j]));
            for (int d = 0; d < 3; ++d) u[3 * j + d] = local[d];
        }
        mat_vec<N>(stiffness + static_cast<Index>(D) * D * e, u, F);
        for (int j = 0; j < N; ++j) {
            const V3 world = mul(R, V3{{F[3 * j], F[3 * j + 1], F[3 * j + 2]}});
            for (int d = 0; d < 3; ++d) df[3 * element[j] + d] -= kfactor * world[d];
        }
    }
}

// Sparse direct solvers: kfact times the force Jacobian, node block (a, b) = -R Ke_ab R^T
// (rotations == nullptr: -Ke_ab, the small-strain form). `Assembler` is sofac::Assembler.
template <int N, class Assembler>
inline void element_fem_assemble(Assembler& A, const Index* elements, Index count, const double* stiffness,
                                 const double* rotations, Index offset, double kfactor) {
    using namespace fem_detail;
    constexpr int D = 3 * N;
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        const double* K = stiffness + static_cast<Index>(D) * D * e;
        const M3 R = rotations ? load_m(rotations + ELEMENT_ROTATION_SIZE * e + 9) : identity();
        for (int a = 0; a < N; ++a)
            for (int b = 0; b < N; ++b) {
                M3 block;
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) block(i, j) = K[D * (3 * a + i) + 3 * b + j];
                if (rotations) block = mul_nt(mul(R, block), R);
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j)
                        A.add(offset + 3 * element[a] + i, offset + 3 * element[b] + j, -kfactor * block(i, j));
            }
    }
}

// ---- FEMMass ----------------------------------------------------------------------------------

// SOFA's calculateElementMassMatrix and initializeGlobalMassMatrix: per element and Gauss point,
// (w rho(q) |det J|) N N^T with rho interpolated from the nodal densities (NodalMassDensity's
// getNodeProperty: property[i], else its last value, else 1); the element entries are collected in
// element order, sorted by (row, column) with std::sort (as CompressedRowSparseMatrix::compress)
// and duplicates summed in that order. Writes `values` of the CSR pattern (row_begin, cols), which
// must hold exactly the node pairs of the elements, sorted.
template <int N>
inline void fem_mass_init(const Index* elements, Index count, const double* rest, const double* density,
                          Index n_density, const Index* row_begin, const Index* cols, Index n_rows, double* values) {
    using namespace element_fem_detail;
    struct Entry {
        int l, c;
        double value;
        bool operator<(const Entry& b) const { return (l < b.l) || (l == b.l && c < b.c); }
    };
    std::vector<Entry> entries;
    entries.reserve(static_cast<std::size_t>(count) * N * N);
    for (Index e = 0; e < count; ++e) {
        const Index* element = elements + N * e;
        double rho[N];
        for (int i = 0; i < N; ++i)
            rho[i] = element[i] < n_density ? density[element[i]] : (n_density > 0 ? density[n_density - 1] : 1.0);
        V3 nodes[N];
        gather<N>(element, rest, nodes);
        double M[N][N] = {};
        for (int p = 0; p < Element<N>::quadrature_points; ++p) {
            double q[3], weight;
            Element<N>::quadrature(p, q, weight);
            double g[N][3];
            Element<N>::gradients(q, g);
            const double detJ = std::fabs(fem_detail::determinant(jacobian<N>(nodes, g)));
            double shape[N];
            Element<N>::shape(q, shape);
            double rho_q = 0.0;
            for (int i = 0; i < N; ++i) rho_q = rho_q + rho[i] * shape[i];
            const double factor = weight * rho_q * detJ;
            for (int i = 0; i < N; ++i)
                for (int j = 0; j < N; ++j) M[i][j] += (shape[i] * shape[j]) * factor;
        }
        for (int i = 0; i < N; ++i)
            for (int j = 0; j < N; ++j) {
                const int l = static_cast<int>(element[i]), c = static_cast<int>(element[j]);
                if (!entries.empty() && entries.back().l == l && entries.back().c == c)
                    entries.back().value += M[i][j];
                else
                    entries.push_back(Entry{l, c, 0.0 + M[i][j]});
            }
    }
    std::sort(entries.begin(), entries.end());
    const Index nnz = row_begin[n_rows];
    for (Index k = 0; k < nnz; ++k) values[k] = 0.0;
    Index slot = -1, row = 0;
    int last_l = -1, last_c = -1;
    for (const Entry& entry : entries) {
        if (entry.l != last_l || entry.c != last_c) {
            ++slot;
            while (row < n_rows && row_begin[row + 1] <= slot) ++row;
            if (slot >= nnz || row != entry.l || cols[slot] != entry.c) return;  // pattern mismatch
            values[slot] = entry.value;
            last_l = entry.l;
            last_c = entry.c;
        } else {
            values[slot] += entry.value;
        }
    }
}

// f_row += M_rc g for each stored entry, in CSR order (FEMMass::addForce).
inline void fem_mass_gravity(double* f, const Index* row_begin, const Index* cols, const double* values,
                             Index n_rows, const double* g) {
    (void)cols;
    for (Index r = 0; r < n_rows; ++r)
        for (Index k = row_begin[r]; k < row_begin[r + 1]; ++k)
            for (int d = 0; d < 3; ++d) f[3 * r + d] += values[k] * g[d];
}

// df_row += (factor M_rc) dx_c (FEMMass::addMDx).
inline void fem_mass_multiply(double* df, const double* dx, const Index* row_begin, const Index* cols,
                              const double* values, Index n_rows, double factor) {
    for (Index r = 0; r < n_rows; ++r)
        for (Index k = row_begin[r]; k < row_begin[r + 1]; ++k) {
            const double m = factor * values[k];
            for (int d = 0; d < 3; ++d) df[3 * r + d] += m * dx[3 * cols[k] + d];
        }
}

// 1/2 v^T M v (FEMMass::getKineticEnergy).
inline double fem_mass_kinetic_energy(const double* v, const Index* row_begin, const Index* cols,
                                      const double* values, Index n_rows) {
    double energy = 0.0;
    for (Index r = 0; r < n_rows; ++r)
        for (Index k = row_begin[r]; k < row_begin[r + 1]; ++k) {
            const double* a = v + 3 * r;
            const double* b = v + 3 * cols[k];
            energy += a[0] * (b[0] * values[k]) + a[1] * (b[1] * values[k]) + a[2] * (b[2] * values[k]);
        }
    return energy / 2.0;
}

// -x^T M g (FEMMass::getPotentialEnergy).
inline double fem_mass_potential_energy(const double* x, const Index* row_begin, const Index* cols,
                                        const double* values, Index n_rows, const double* g) {
    (void)cols;
    double energy = 0.0;
    for (Index r = 0; r < n_rows; ++r)
        for (Index k = row_begin[r]; k < row_begin[r + 1]; ++k) {
            const double* a = x + 3 * r;
            energy -= a[0] * (g[0] * values[k]) + a[1] * (g[1] * values[k]) + a[2] * (g[2] * values[k]);
        }
    return energy;
}

// Sparse direct solvers: mfact M, the scalar entry on each of the 3 diagonal DOF pairs.
template <class Assembler>
inline void assemble_fem_mass(Assembler& A, Index offset, const Index* row_begin, const Index* cols,
                              const double* values, Index n_rows, double mfact) {
    for (Index r = 0; r < n_rows; ++r)
        for (Index k = row_begin[r]; k < row_begin[r + 1]; ++k)
            for (int d = 0; d < 3; ++d) A.add(offset + 3 * r + d, offset + 3 * cols[k] + d, mfact * values[k]);
}

}  // namespace sofac
