// FastTetrahedralCorotationalForceField (SOFA's FastTetrahedralCorotationalForceField.inl):
// corotational linear tetrahedra written on edges. Per tetrahedron, from the rest positions: the
// shape vectors sv_j, the rest edge vectors, Lame's lambda and mu times |volume|, the 3x3 stiffness
// blocks of its 6 edges, DfDx_e(m,n) = lambda sv_k[n] sv_l[m] + mu sv_l[n] sv_k[m] (+ mu sv_l.sv_k on
// the diagonal, edge e = (k, l) of SOFA's edgesInTetrahedronArray) and of its 4 vertices (used by
// assembled solvers only), and the rest rotation (qr: frame of edges 0-1 and 0-2; polar2: polar
// factor of the rows p1 - p0, p2 - p0, p3 - p0).
//
// The force pass finds the rotation R (polar: of the deformation gradient sum_j edge_j sv_{j+1}^T;
// qr: S^T R0 with S the frame of the current edges 0-1, 0-2; polar2: polar(S)^T R0 with S the rows of
// the current edges from vertex 0; linear: identity), stores rotation = R^T, and adds per edge
// d = rotation edge - rest edge: force_l += DfDx_e d, force_k -= DfDx_e^T d, then f += R force.
// K dx is written on the topology's edges: after each force pass (SOFA rebuilds them lazily, at the
// first K dx after a force pass: the same numbers) every edge sums, over its tetrahedra,
// rotation^T DfDx_e rotation (or (DfDx_e rotation)^T rotation when the tetrahedron's edge runs against
// the topology's edge); df_b += E (dx_b - dx_a) kFactor, df_a -= E^T (dx_b - dx_a) kFactor. SOFA's
// getPotentialEnergy returns 0.
#pragma once

#include <cmath>

#include "fem.h"
#include "types.h"

namespace sofac {

// SOFA's RotationDecompositionMethod, in its order: the `method` the kernels take.
enum FastTetraMethod : int { FAST_TETRA_POLAR = 0, FAST_TETRA_QR = 1, FAST_TETRA_POLAR2 = 2, FAST_TETRA_LINEAR = 3 };

namespace fast_tetra_detail {
using namespace fem_detail;

// Per-tetrahedron data (offsets in doubles).
constexpr int FT_SHAPE = 0;           // 4 shape vectors (12)
constexpr int FT_REST_EDGE = 12;      // 6 rest edge vectors (18)
constexpr int FT_DIAG = 30;           // 4 vertex blocks (36), row-major
constexpr int FT_EDGE = 66;           // 6 edge blocks (54), row-major
constexpr int FT_ROTATION = 120;      // SOFA's rotation = R^T (9)
constexpr int FT_REST_ROTATION = 129; // qr / polar2 rest rotation (9)
constexpr int FT_ORIENTATION = 138;   // +1 / -1 per edge (6)
constexpr int FT_DATA = 144;

constexpr int kEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

inline V3 scaled_down(const V3& v, double s) { return V3{{v[0] / s, v[1] / s, v[2] / s}}; }

// SOFA's computeQRRotation of the edges e0, e1: rows x = e0 normalised, z = (x cross e1) normalised,
// y = z cross x.
inline M3 qr_rotation(const V3& e0, const V3& e1) { return tetra_frame(V3{{0, 0, 0}}, e0, e1); }

inline M3 add(const M3& a, const M3& b) {
    M3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(i, j) + b(i, j);
    return r;
}
}  // namespace fast_tetra_detail

constexpr int fast_tetra_fem_data_size(int /*method*/ = 0) { return fast_tetra_detail::FT_DATA; }

// SOFA's createTetrahedronRestInformation and updateTopologyInformation, per tetrahedron.
// tet_edges: the topology's index of each of the 6 local edges (getEdgesInTetrahedron).
inline void fast_tetra_fem_init(const Index* tetra, Index n, const double* rest_x, const double* young,
                                Index n_young, const double* poisson, Index n_poisson, int method,
                                const Index* tet_edges, const Index* edges, double* data) {
    using namespace fast_tetra_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tetra + 4 * i;
        double* e = data + FT_DATA * i;
        for (int k = 0; k < FT_DATA; ++k) e[k] = 0.0;
        const double E = element_value(young, n_young, i), nu = element_value(poisson, n_poisson, i);
        double mu = E / (2 * (1 + nu));
        double lambda = E * nu / ((1 + nu) * (1 - 2.0 * nu));
        V3 p[4];
        for (int j = 0; j < 4; ++j) p[j] = load(rest_x + 3 * t[j]);
        const double volume = -(dot3(cross(sub(p[1], p[0]), sub(p[2], p[0])), sub(p[3], p[0])) / 6.0);
        mu *= std::fabs(volume);
        lambda *= std::fabs(volume);
        V3 sv[4];
        for (int j = 0; j < 4; ++j) {
            V3 c = cross(sub(p[(j + 2) % 4], p[(j + 1) % 4]), sub(p[(j + 3) % 4], p[(j + 1) % 4]));
            if (j % 2)
                for (int m = 0; m < 3; ++m) c[m] = -c[m];
            sv[j] = scaled_down(c, volume * 6);
            for (int m = 0; m < 3; ++m) e[FT_SHAPE + 3 * j + m] = sv[j][m];
        }
        for (int j = 0; j < 4; ++j) {
            double* d = e + FT_DIAG + 9 * j;
            const double val = mu * dot3(sv[j], sv[j]);
            for (int m = 0; m < 3; ++m)
                for (int q = m; q < 3; ++q) {
                    d[3 * m + q] = lambda * sv[j][q] * sv[j][m] + mu * sv[j][q] * sv[j][m];
                    if (m == q)
                        d[3 * m + m] += val;
                    else
                        d[3 * q + m] = d[3 * m + q];
                }
        }
        for (int j = 0; j < 6; ++j) {
            const int k = kEdges[j][0], l = kEdges[j][1];
            const V3 rest_edge = sub(p[l], p[k]);
            for (int m = 0; m < 3; ++m) e[FT_REST_EDGE + 3 * j + m] = rest_edge[m];
            double* d = e + FT_EDGE + 9 * j;
            const double val = mu * dot3(sv[l], sv[k]);
            for (int m = 0; m < 3; ++m)
                for (int q = 0; q < 3; ++q) {
                    d[3 * m + q] = lambda * sv[k][q] * sv[l][m] + mu * sv[l][q] * sv[k][m];
                    if (m == q) d[3 * m + m] += val;
                }
            const Index* edge = edges + 2 * tet_edges[6 * i + j];
            e[FT_ORIENTATION + j] = t[k] == edge[0] ? 1.0 : -1.0;
        }
        if (method == FAST_TETRA_QR) {
            store_m(e + FT_REST_ROTATION, qr_rotation(load(e + FT_REST_EDGE), load(e + FT_REST_EDGE + 3)));
        } else if (method == FAST_TETRA_POLAR2) {
            store_m(e + FT_REST_ROTATION, polar_rotation(from_rows(sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0]))));
        }
        store_m(e + FT_ROTATION, identity());
    }
}

// f += internal force at x (SOFA's addForce); stores each tetrahedron's rotation.
inline void fast_tetra_fem_add_force(const Index* tetra, Index n, const double* x, double* f, double* data,
                                     int method) {
    using namespace fast_tetra_detail;
    for (Index i = 0; i < n; ++i) {
        const Index* t = tetra + 4 * i;
        double* e = data + FT_DATA * i;
        V3 v[4], displ[6];
        for (int j = 0; j < 4; ++j) v[j] = load(x + 3 * t[j]);
        for (int j = 0; j < 6; ++j) displ[j] = sub(v[kEdges[j][1]], v[kEdges[j][0]]);
        M3 R = identity();
        if (method == FAST_TETRA_POLAR) {
            M3 gradient;
            const double* sv = e + FT_SHAPE + 3;
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < 3; ++l) gradient(k, l) = displ[0][k] * sv[l];
            for (int j = 1; j < 3; ++j) {
                sv = e + FT_SHAPE + 3 * (j + 1);
                for (int k = 0; k < 3; ++k)
                    for (int l = 0; l < 3; ++l) gradient(k, l) += displ[j][k] * sv[l];
            }
            R = polar_rotation(gradient);
        } else if (method == FAST_TETRA_QR) {
            R = mul_tn(qr_rotation(displ[0], displ[1]), load_m(e + FT_REST_ROTATION));
        } else if (method == FAST_TETRA_POLAR2) {
            const M3 S = polar_rotation(from_rows(displ[0], displ[1], displ[2]));
            R = mul(transposed(S), load_m(e + FT_REST_ROTATION));
        }
        const M3 rotation = transposed(R);
        store_m(e + FT_ROTATION, rotation);
        V3 force[4] = {};
        for (int j = 0; j < 6; ++j) {
            const V3 rotated = mul(rotation, displ[j]);
            const V3 d = sub(rotated, load(e + FT_REST_EDGE + 3 * j));
            const M3 block = load_m(e + FT_EDGE + 9 * j);
            const V3 on_l = mul(block, d), on_k = mul_t(block, d);
            V3& fl = force[kEdges[j][1]];
            V3& fk = force[kEdges[j][0]];
            for (int m = 0; m < 3; ++m) {
                fl[m] += on_l[m];
                fk[m] -= on_k[m];
            }
        }
        for (int j = 0; j < 4; ++j) {
            const V3 world = mul(R, force[j]);
            for (int m = 0; m < 3; ++m) f[3 * t[j] + m] += world[m];
        }
    }
}

// The edge stiffness blocks of the last force pass (SOFA's updateMatrix pass of addDForce): each
// topology edge sums rotation^T (DfDx rotation), or (DfDx rotation)^T rotation against its orientation.
inline void fast_tetra_fem_edge_matrices(const Index* tet_edges, Index n, Index n_edges, const double* data,
                                         double* edge_matrices) {
    using namespace fast_tetra_detail;
    for (Index k = 0; k < 9 * n_edges; ++k) edge_matrices[k] = 0.0;
    for (Index i = 0; i < n; ++i) {
        const double* e = data + FT_DATA * i;
        const M3 rotation = load_m(e + FT_ROTATION);
        for (int j = 0; j < 6; ++j) {
            const M3 tmp = mul(load_m(e + FT_EDGE + 9 * j), rotation);
            double* out = edge_matrices + 9 * tet_edges[6 * i + j];
            const M3 term = e[FT_ORIENTATION + j] == 1.0 ? mul_tn(rotation, tmp) : mul_tn(tmp, rotation);
            store_m(out, add(load_m(out), term));
        }
    }
}

// df += kfactor (df/dx) dx on the topology's edges (SOFA's addDForce).
inline void fast_tetra_fem_add_dforce(const Index* edges, Index n_edges, const double* edge_matrices,
                                      const double* dx, double* df, double kfactor) {
    using namespace fast_tetra_detail;
    for (Index k = 0; k < n_edges; ++k) {
        const Index a = edges[2 * k], b = edges[2 * k + 1];
        V3 delta = sub(load(dx + 3 * b), load(dx + 3 * a));
        for (int m = 0; m < 3; ++m) delta[m] *= kfactor;
        const M3 block = load_m(edge_matrices + 9 * k);
        const V3 on_b = mul(block, delta), on_a = mul_t(block, delta);
        for (int m = 0; m < 3; ++m) {
            df[3 * b + m] += on_b[m];
            df[3 * a + m] -= on_a[m];
        }
    }
}

// Assembled solvers (SOFA's buildStiffnessMatrix): A += kfact df/dx, the vertex blocks
// -sum rotation^T Diag rotation over each vertex's tetrahedra (point_matrices: 9 per point, scratch),
// then the edge blocks -E^T at (a, b) and -E at (b, a).
template <class Assembler>
inline void assemble_fast_tetra_fem(Assembler& A, Index offset, const Index* tetra, Index n, Index n_points,
                                    const Index* edges, Index n_edges, const double* edge_matrices,
                                    const double* data, double* point_matrices, double kfact) {
    using namespace fast_tetra_detail;
    for (Index k = 0; k < 9 * n_points; ++k) point_matrices[k] = 0.0;
    for (Index i = 0; i < n; ++i) {
        const double* e = data + FT_DATA * i;
        const M3 rotation = load_m(e + FT_ROTATION);
        for (int j = 0; j < 4; ++j) {
            const M3 tmp = mul(mul(transposed(rotation), load_m(e + FT_DIAG + 9 * j)), rotation);
            double* out = point_matrices + 9 * tetra[4 * i + j];
            store_m(out, add(load_m(out), tmp));
        }
    }
    for (Index p = 0; p < n_points; ++p)
        A.add_block3(offset + 3 * p, offset + 3 * p, point_matrices + 9 * p, 3, -kfact);
    for (Index k = 0; k < n_edges; ++k) {
        const M3 block = load_m(edge_matrices + 9 * k);
        double transposed_block[9];
        store_m(transposed_block, transposed(block));
        A.add_block3(offset + 3 * edges[2 * k], offset + 3 * edges[2 * k + 1], transposed_block, 3, -kfact);
        A.add_block3(offset + 3 * edges[2 * k + 1], offset + 3 * edges[2 * k], edge_matrices + 9 * k, 3, -kfact);
    }
}

}  // namespace sofac
