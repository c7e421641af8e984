// Kernels of constant linear mappings (BarycentricMapping and any mapping given as k weighted input
// points per output point) and of SOFA's MeshMatrixMass.
//
// A linear map is stored as two (n, k) row-major arrays computed at compile time
// (compiler/barycentric.py): output point i = sum_j w[i*k+j] * input point idx[i*k+j]. Columns are in
// SOFA's summation order and zero-weight padding is harmless, so apply reproduces SOFA's mapped
// positions bit for bit. `width` is the number of doubles per point, the same on both sides (3 for
// Vec3d); the same kernel maps positions (apply), velocities and dx (J).
//
// MeshMatrixMass (compiler/masses.py, MeshMatrixMassData): per vertex `vertex_mass`, per edge
// (a, b) `edge_mass`; the matrix is M[i][i] = vertex_mass[i], M[a][b] = M[b][a] = edge_mass[e]
// (identical for every spatial component), or, lumped, diag(vertex_mass * lumping).
#pragma once

#include "types.h"

namespace sofac {

// out_i = sum_j w_ij in[idx_ij]   (out is overwritten; in and out must not overlap)
inline void linear_map_apply(const double* in, double* out, const Index* idx, const double* w, Index n, int k,
                             int width) {
    for (Index i = 0; i < n; ++i) {
        double* o = out + i * width;
        for (int d = 0; d < width; ++d) o[d] = 0.0;
        const Index* row_idx = idx + i * k;
        const double* row_w = w + i * k;
        for (int j = 0; j < k; ++j) {
            const double* src = in + row_idx[j] * width;
            const double wj = row_w[j];
            for (int d = 0; d < width; ++d) o[d] += src[d] * wj;
        }
    }
}

// in_f[idx_ij] += w_ij out_f_i   (J^T: forces or df of the mapped points accumulated on the input)
inline void linear_map_apply_jt(double* in_f, const double* out_f, const Index* idx, const double* w, Index n,
                                int k, int width) {
    for (Index i = 0; i < n; ++i) {
        const double* f = out_f + i * width;
        const Index* row_idx = idx + i * k;
        const double* row_w = w + i * k;
        for (int j = 0; j < k; ++j) {
            double* dst = in_f + row_idx[j] * width;
            const double wj = row_w[j];
            for (int d = 0; d < width; ++d) dst[d] += f[d] * wj;
        }
    }
}

// df += factor * M dx, consistent MeshMatrixMass (SOFA's addMDx, same operation order): first every
// vertex term dx_i * m_i * factor, then for each edge e = (a, b): df_a += dx_b * (m_e * factor) and
// df_b += dx_a * (m_e * factor). `edges` is (n_edges, 2) row-major.
inline void mesh_matrix_mass_multiply(double* df, const double* dx, const double* vertex_mass, Index n,
                                      const Index* edges, const double* edge_mass, Index n_edges, double factor,
                                      int width) {
    for (Index i = 0; i < n; ++i) {
        const double m = vertex_mass[i];
        for (int d = 0; d < width; ++d) df[i * width + d] += dx[i * width + d] * m * factor;
    }
    for (Index e = 0; e < n_edges; ++e) {
        const Index a = edges[2 * e];
        const Index b = edges[2 * e + 1];
        const double m = edge_mass[e] * factor;
        for (int d = 0; d < width; ++d) df[a * width + d] += dx[b * width + d] * m;
        for (int d = 0; d < width; ++d) df[b * width + d] += dx[a * width + d] * m;
    }
}

// df += factor * M dx, lumped MeshMatrixMass: df_i += dx_i * m_i * lumping * factor.
inline void mesh_matrix_mass_multiply_lumped(double* df, const double* dx, const double* vertex_mass, Index n,
                                             double lumping, double factor, int width) {
    for (Index i = 0; i < n; ++i) {
        const double m = vertex_mass[i];
        for (int d = 0; d < width; ++d) df[i * width + d] += dx[i * width + d] * m * lumping * factor;
    }
}

// Gravity, consistent or lumped alike (SOFA's MeshMatrixMass::addForce): f_i += g * m_i * lumping,
// g with `width` components (the first `width` of the node's gravity).
inline void mesh_matrix_mass_gravity(double* f, const double* vertex_mass, Index n, double lumping, const double* g,
                                     int width) {
    for (Index i = 0; i < n; ++i) {
        const double m = vertex_mass[i];
        for (int d = 0; d < width; ++d) f[i * width + d] += g[d] * m * lumping;
    }
}

// a_i = f_i / (m_i * lumping): explicit solvers, lumped matrix only (SOFA refuses accFromF otherwise).
inline void mesh_matrix_mass_acceleration_lumped(double* a, const double* f, const double* vertex_mass, Index n,
                                                 double lumping, int width) {
    for (Index i = 0; i < n; ++i) {
        const double m = vertex_mass[i] * lumping;
        for (int d = 0; d < width; ++d) a[i * width + d] = f[i * width + d] / m;
    }
}

// 1/2 v.M.v (SOFA's getKineticEnergy); lumped when `lumped` (then the edges are ignored).
inline double mesh_matrix_mass_kinetic_energy(const double* v, const double* vertex_mass, Index n, const Index* edges,
                                              const double* edge_mass, Index n_edges, bool lumped, double lumping,
                                              int width) {
    double e = 0.0;
    const double coefficient = lumped ? lumping : 1.0;
    for (Index i = 0; i < n; ++i) {
        double vv = 0.0;
        for (int d = 0; d < width; ++d) vv += v[i * width + d] * v[i * width + d];
        e += vv * vertex_mass[i] * coefficient;
    }
    if (!lumped) {
        for (Index k = 0; k < n_edges; ++k) {
            const Index a = edges[2 * k];
            const Index b = edges[2 * k + 1];
            double ab = 0.0;
            for (int d = 0; d < width; ++d) ab += v[a * width + d] * v[b * width + d];
            e += 2 * ab * edge_mass[k];
        }
    }
    return e / 2;
}

}  // namespace sofac
