// HexahedralFEMForceField (SOFA's HexahedralFEMForceField.inl): corotational trilinear hexahedra on a
// HexahedronSetTopology, methods large (mean-edge Gram-Schmidt frame) and polar.
//
// It shares HexahedronFEMForceField's element data (fem.h, 609 doubles: Ke, rest positions in the
// rest frame, current rotation) and its force pass (D = R0 X0 - R x, f += R^T Ke D), but not its
// element stiffness nor its derivative:
//   - Ke comes from SOFA's closed-form integrateStiffness (valid for axis-aligned boxes only: J^-1 is
//     diag(2 / l) with l = node 6 - node 0 of the *unrotated* rest element, the volume the product of
//     the edges 0-1, 0-3, 0-4 over 8), each 3x3 entry rounded to float as SOFA casts it, the upper
//     node blocks computed and mirrored;
//   - K dx scales the rotated dx by kFactor before Ke (SOFA's x_2 = R dx * kFactor);
//   - the assembled matrix (addKToMatrix and buildStiffnessMatrix) has node blocks R Ke_ab R^T, the
//     rotation taken the other way round from the force's R^T Ke_ab R: SOFA's quirk, kept (it only
//     agrees with K dx where the element is not rotated).
// SOFA's getPotentialEnergy returns 0 for it.
#pragma once

#include "fem.h"
#include "parallel.h"
#include "types.h"

namespace sofac {

namespace hexahedral_detail {
using fem_detail::M3;

// SOFA's integrateStiffness(signx0, signy0, signz0, signx1, signy1, signz1, u, v, w, J_1): the node
// block (a, b) of the element stiffness for nodes of reference signs (x0, y0, z0) and (x1, y1, z1),
// u, v, w = M00, M01, M33 of the Hooke matrix, J_1 the diagonal inverse Jacobian; products and
// sums in SOFA's order, each entry rounded to float.
inline M3 integrate_stiffness(int signx0, int signy0, int signz0, int signx1, int signy1, int signz1, double u,
                              double v, double w, const M3& J_1) {
    const double t1 = J_1(0, 0) * J_1(0, 0);
    const double t2 = t1 * signx0;
    const double t3 = (double)(signy0 * signz0);
    const double t4 = t2 * t3;
    const double t5 = w * signx1;
    const double t6 = (double)(signy1 * signz1);
    const double t7 = t5 * t6;
    const double t10 = t1 * signy0;
    const double t12 = w * signy1;
    const double t13 = t12 * signz1;
    const double t16 = t2 * signz0;
    const double t17 = u * signx1;
    const double t18 = t17 * signz1;
    const double t21 = t17 * t6;
    const double t24 = t2 * signy0;
    const double t25 = t17 * signy1;
    const double t28 = t5 * signy1;
    const double t32 = w * signz1;
    const double t37 = t5 * signz1;
    const double t43 = J_1(0, 0) * signx0;
    const double t45 = v * J_1(1, 1);
    const double t49 = J_1(0, 0) * signy0;
    const double t50 = t49 * signz0;
    const double t51 = w * J_1(1, 1);
    const double t52 = (double)(signx1 * signz1);
    const double t53 = t51 * t52;
    const double t56 = t45 * signy1;
    const double t64 = v * J_1(2, 2);
    const double t68 = w * J_1(2, 2);
    const double t69 = (double)(signx1 * signy1);
    const double t70 = t68 * t69;
    const double t73 = t64 * signz1;
    const double t81 = J_1(1, 1) * signy0;
    const double t83 = v * J_1(0, 0);
    const double t87 = J_1(1, 1) * signx0;
    const double t88 = t87 * signz0;
    const double t89 = w * J_1(0, 0);
    const double t90 = t89 * t6;
    const double t93 = t83 * signx1;
    const double t100 = J_1(1, 1) * J_1(1, 1);
    const double t101 = t100 * signx0;
    const double t102 = t101 * t3;
    const double t110 = t100 * signy0;
    const double t111 = t110 * signz0;
    const double t112 = u * signy1;
    const double t113 = t112 * signz1;
    const double t116 = t101 * signy0;
    const double t144 = J_1(2, 2) * signy0;
    const double t149 = J_1(2, 2) * signx0;
    const double t150 = t149 * signy0;
    const double t153 = J_1(2, 2) * signz0;
    const double t172 = J_1(2, 2) * J_1(2, 2);
    const double t173 = t172 * signx0;
    const double t174 = t173 * t3;
    const double t177 = t173 * signz0;
    const double t180 = t172 * signy0;
    const double t181 = t180 * signz0;
    M3 K;
    K(0, 0) = (float)(t4 * t7 / 36.0 + t10 * signz0 * t13 / 12.0 + t16 * t18 / 24.0 + t4 * t21 / 72.0 +
                      t24 * t25 / 24.0 + t24 * t28 / 24.0 + t1 * signz0 * t32 / 8.0 + t10 * t12 / 8.0 +
                      t16 * t37 / 24.0 + t2 * t17 / 8.0);
    K(0, 1) = (float)(t43 * signz0 * t45 * t6 / 24.0 + t50 * t53 / 24.0 + t43 * t56 / 8.0 +
                      t49 * t51 * signx1 / 8.0);
    K(0, 2) = (float)(t43 * signy0 * t64 * t6 / 24.0 + t50 * t70 / 24.0 + t43 * t73 / 8.0 +
                      J_1(0, 0) * signz0 * t68 * signx1 / 8.0);
    K(1, 0) = (float)(t81 * signz0 * t83 * t52 / 24.0 + t88 * t90 / 24.0 + t81 * t93 / 8.0 +
                      t87 * t89 * signy1 / 8.0);
    K(1, 1) = (float)(t102 * t7 / 36.0 + t102 * t21 / 72.0 + t101 * signz0 * t37 / 12.0 + t111 * t113 / 24.0 +
                      t116 * t28 / 24.0 + t100 * signz0 * t32 / 8.0 + t111 * t13 / 24.0 + t116 * t25 / 24.0 +
                      t110 * t112 / 8.0 + t101 * t5 / 8.0);
    K(1, 2) = (float)(t87 * signy0 * t64 * t52 / 24.0 + t88 * t70 / 24.0 + t81 * t73 / 8.0 +
                      J_1(1, 1) * signz0 * t68 * signy1 / 8.0);
    K(2, 0) = (float)(t144 * signz0 * t83 * t69 / 24.0 + t150 * t90 / 24.0 + t153 * t93 / 8.0 +
                      t149 * t89 * signz1 / 8.0);
    K(2, 1) = (float)(t149 * signz0 * t45 * t69 / 24.0 + t150 * t53 / 24.0 + t153 * t56 / 8.0 +
                      t144 * t51 * signz1 / 8.0);
    K(2, 2) = (float)(t174 * t7 / 36.0 + t177 * t37 / 24.0 + t181 * t13 / 24.0 + t174 * t21 / 72.0 +
                      t173 * signy0 * t28 / 12.0 + t180 * t12 / 8.0 + t181 * t113 / 24.0 + t177 * t18 / 24.0 +
                      t172 * signz0 * u * signz1 / 8.0 + t173 * t5 / 8.0);
    return K;
}

// SOFA's computeElementStiffness: the upper node blocks vol * integrate_stiffness (vol = product of
// the edges 0-1, 0-3, 0-4, over 8), the lower triangle mirrored from the upper one.
inline void element_stiffness(double* K, const fem_detail::V3* nodes, double u, double v, double w) {
    using namespace fem_detail;
    M3 J_1{};
    const V3 l = sub(nodes[6], nodes[0]);
    for (int k = 0; k < 3; ++k) J_1(k, k) = 2.0 / l[k];
    double vol = norm(sub(nodes[1], nodes[0])) * norm(sub(nodes[3], nodes[0])) * norm(sub(nodes[4], nodes[0]));
    vol /= 8.0;
    for (int k = 0; k < 576; ++k) K[k] = 0.0;
    for (int i = 0; i < 8; ++i)
        for (int j = i; j < 8; ++j) {
            const M3 k = integrate_stiffness(hexa_coef[i][0], hexa_coef[i][1], hexa_coef[i][2], hexa_coef[j][0],
                                             hexa_coef[j][1], hexa_coef[j][2], u, v, w, J_1);
            for (int m = 0; m < 3; ++m)
                for (int l2 = 0; l2 < 3; ++l2) K[24 * (3 * i + m) + 3 * j + l2] += k(m, l2) * vol;
        }
    for (int i = 0; i < 24; ++i)
        for (int j = i + 1; j < 24; ++j) K[24 * j + i] = K[24 * i + j];
}

}  // namespace hexahedral_detail

constexpr int hexahedral_fem_data_size(int method = 1) { return hexa_fem_data_size(method); }

// SOFA's reinit (initLarge / initPolar per element): the rest rotation R0 of the element's rest
// positions, the rest positions in its frame, and Ke from the Hooke matrix of (E_i, nu_i) and the
// unrotated rest positions. The stored rotation starts as R0 (SOFA's starts at zero; every K pass
// follows a force pass that sets it).
inline void hexahedral_fem_init(const Index* hexa, Index n_hexa, const double* rest_x, const double* young,
                                Index n_young, const double* poisson, Index n_poisson, int method,
                                double* element_data) {
    using namespace fem_detail;
    const int stride = hexahedral_fem_data_size(method);
    for (Index i = 0; i < n_hexa; ++i) {
        double* e = element_data + i * stride;
        const Index* h = hexa + 8 * i;
        const double nu = element_value(poisson, n_poisson, i);
        const double E = element_value(young, n_young, i);
        const double scale = (E * (1 - nu)) / ((1 + nu) * (1 - 2 * nu));
        const double u = 1.0 * scale;
        const double v = (nu / (1 - nu)) * scale;
        const double w = ((1 - 2 * nu) / (2 * (1 - nu))) * scale;
        V3 nodes[8];
        for (int k = 0; k < 8; ++k) nodes[k] = load(rest_x + 3 * h[k]);
        const M3 R = method == FEM_POLAR ? hexa_rotation_polar(nodes) : hexa_rotation_large(nodes);
        store_m(e + HROT, R);
        for (int k = 0; k < 8; ++k) {
            const V3 rotated = mul(R, nodes[k]);
            for (int m = 0; m < 3; ++m) e[HREST + 3 * k + m] = rotated[m];
        }
        hexahedral_detail::element_stiffness(e + HK, nodes, u, v, w);
    }
}

// f += internal force at x (HexahedronFEMForceField's force pass, which is SOFA's here too); stores R.
inline void hexahedral_fem_add_force(const Index* hexa, Index n, const double* x, double* f, double* element_data,
                                     int method, const ElementSplit& split = {}) {
    hexa_fem_add_force(hexa, n, x, f, element_data, method, split);
}

// df -= R^T (Ke ((R dx) kfactor)) per element (SOFA's addDForce, with the rotation of the last force pass).
inline void hexahedral_fem_add_dforce(const Index* hexa, Index n, const double* dx, double* df, double kfactor,
                                      const double* element_data, int method, const ElementSplit& split = {}) {
    using namespace fem_detail;
    const int stride = hexahedral_fem_data_size(method);
    const auto element = [&](Index i, double* out) {
        const double* e = element_data + i * stride;
        const Index* h = hexa + 8 * i;
        const M3 R = load_m(e + HROT);
        double X[24], F[24];
        for (int k = 0; k < 8; ++k) {
            const V3 l = mul(R, load(dx + 3 * h[k]));
            for (int m = 0; m < 3; ++m) X[3 * k + m] = l[m] * kfactor;
        }
        hexa_mul(F, e + HK, X);
        for (int k = 0; k < 8; ++k) {
            const V3 fw = mul_t(R, V3{{F[3 * k], F[3 * k + 1], F[3 * k + 2]}});
            for (int m = 0; m < 3; ++m) out[3 * k + m] = -fw[m];
        }
    };
    if (split.chunks > 1)
        split_elements<8>(split, hexa, df, element);
    else
        serial_elements<8>(n, hexa, df, element);
}

// The positive stiffness SOFA assembles for element e (24x24, row-major): node blocks
// rotation^T Ke_ab rotation with rotation = R^T, i.e. R Ke_ab R^T (see the header comment).
inline void hexahedral_fem_element_matrix(const double* element_data, Index e, int method, double* out) {
    using namespace fem_detail;
    const double* d = element_data + e * hexahedral_fem_data_size(method);
    const M3 R = load_m(d + HROT);
    for (int a = 0; a < 8; ++a)
        for (int b = 0; b < 8; ++b) {
            M3 kb;
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) kb(i, j) = d[HK + 24 * (3 * a + i) + 3 * b + j];
            const M3 r = mul_nt(mul(R, kb), R);
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) out[24 * (3 * a + i) + 3 * b + j] = r(i, j);
        }
}

}  // namespace sofac
