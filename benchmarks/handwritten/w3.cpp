// W3 by hand: corotational ("large") linear tetrahedral FEM cantilever, implicit Euler with Rayleigh
// damping, solved by (a) a conjugate gradient of exactly `iterations` iterations or (b) CHOLMOD.
//   usage: w3 INPUT OUTPUT dt vertex_mass young poisson gravity_y rayleigh_stiffness rayleigh_mass
//             SOLVER iterations warmup steps batches
//   SOLVER: cg            CG, matrix-free element products (per step: world shape gradients)
//           cg-assembled  CG on K assembled each step (3x3 block rows)
//           cholmod       K assembled, CHOLMOD's default factorisation (supernodal LL^T when worth it)
//           cholmod-simplicial  the same with a simplicial LDL^T (what SOFA's SparseLDLSolver does)
//
// Element (corotational, SOFA's "large" frame): R has the rows x = edge 0->1 (normalised),
// z = x cross edge 0->2 (normalised), y = z cross x, from the current positions (world -> local).
// At rest, r_k = R0 (X_k - X_0) and the shape function gradients g_k (rows of [r1 r2 r3]^-1,
// g_0 = -(g_1 + g_2 + g_3)) are computed once, with the volume V. Each step, the local displacement
// d_k = R (x_k - x_0) - r_k gives H = sum_k d_k g_k^T, the stress (times V) S = V (lambda tr(H) I +
// mu (H + H^T)) and the force f_k = -R^T S g_k. The stiffness is that of the rest element rotated
// by R, K_ab = V (lambda G_a G_b^T + mu G_b G_a^T + mu (G_a . G_b) I) with the world gradients
// G = R^T g (isotropic material: the same as R^T (B^T D B) R).
// Step (SOFA's EulerImplicitSolver): f = m g + elastic forces; b = h (f - rm M v - (h + rk) K v);
// solve ((1 + h rm) M + h (h + rk) K) dv = b without the z = 0 nodes' DOFs (CG zeroes their rows,
// CHOLMOD's matrix leaves them out);
// v += dv, x += h v.
// Prints one JSON line: ms per step of each timed batch, the time of the step's phases, and for
// CHOLMOD the factor's kind and size.
#include <cholmod.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench_io.h"
#include "cg.h"

namespace {

// Input (binary, native endianness): int64 points, tetrahedra, fixed; double position[3 points];
// int64 tetrahedron[4 tetrahedra]; int64 fixed_index[fixed].
struct Mesh {
    std::int64_t points = 0, tetrahedra = 0, fixed = 0;
    std::vector<double> x;
    std::vector<std::int64_t> tetra, fixed_index;
};

Mesh read_mesh(const char* path) {
    std::FILE* file = open_input(path);
    Mesh m;
    std::vector<std::int64_t> header;
    read_array(file, header, 3);
    m.points = header[0];
    m.tetrahedra = header[1];
    m.fixed = header[2];
    read_array(file, m.x, 3 * m.points);
    read_array(file, m.tetra, 4 * m.tetrahedra);
    read_array(file, m.fixed_index, m.fixed);
    std::fclose(file);
    return m;
}

// Rows of the element frame (world -> local) from three points.
void frame(const double* a, const double* b, const double* c, double R[9]) {
    double ex[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double nx = 1.0 / std::sqrt(ex[0] * ex[0] + ex[1] * ex[1] + ex[2] * ex[2]);
    for (double& v : ex) v *= nx;
    double ez[3] = {ex[1] * e2[2] - ex[2] * e2[1], ex[2] * e2[0] - ex[0] * e2[2], ex[0] * e2[1] - ex[1] * e2[0]};
    const double nz = 1.0 / std::sqrt(ez[0] * ez[0] + ez[1] * ez[1] + ez[2] * ez[2]);
    for (double& v : ez) v *= nz;
    const double ey[3] = {ez[1] * ex[2] - ez[2] * ex[1], ez[2] * ex[0] - ez[0] * ex[2], ez[0] * ex[1] - ez[1] * ex[0]};
    for (int i = 0; i < 3; ++i) {
        R[i] = ex[i];
        R[3 + i] = ey[i];
        R[6 + i] = ez[i];
    }
}

struct Phases {  // ms accumulated over the timed steps
    double forces = 0, rhs = 0, factor = 0, solve = 0;
};

}  // namespace

int main(int argc, char** argv) {
    if (argc != 15) {
        std::fprintf(stderr,
                     "usage: w3 INPUT OUTPUT dt vertex_mass young poisson gravity_y rayleigh_stiffness "
                     "rayleigh_mass cg|cg-assembled|cholmod|cholmod-simplicial iterations warmup steps batches\n");
        return 2;
    }
    Mesh mesh = read_mesh(argv[1]);
    const double h = std::atof(argv[3]), mass = std::atof(argv[4]), young = std::atof(argv[5]);
    const double nu = std::atof(argv[6]), gy = std::atof(argv[7]);
    const double rk = std::atof(argv[8]), rm = std::atof(argv[9]);
    const std::string solver = argv[10];
    const long iterations = std::atol(argv[11]);
    const long warmup = std::atol(argv[12]), steps = std::atol(argv[13]), batches = std::atol(argv[14]);
    const bool matrix_free = solver == "cg";
    const bool direct = solver == "cholmod" || solver == "cholmod-simplicial";
    if (!matrix_free && !direct && solver != "cg-assembled") {
        std::fprintf(stderr, "w3: unknown solver %s\n", solver.c_str());
        return 2;
    }

    const std::int64_t n = mesh.points, ne = mesh.tetrahedra, size = 3 * n;
    const std::int64_t* tet = mesh.tetra.data();
    std::vector<double>& x = mesh.x;
    std::vector<unsigned char> free_dof(size, 1);
    for (std::int64_t i : mesh.fixed_index) free_dof[3 * i] = free_dof[3 * i + 1] = free_dof[3 * i + 2] = 0;

    // ---- rest state: local rest edges r_1..r_3 (9), gradients g_0..g_3 (12), V lambda, V mu ----
    const double lambda = young * nu / ((1 + nu) * (1 - 2 * nu)), mu = young / (2 * (1 + nu));
    std::vector<double> rest(9 * ne), grad(12 * ne), vlambda(ne), vmu(ne), world_grad(12 * ne);
    for (std::int64_t e = 0; e < ne; ++e) {
        const std::int64_t* t = tet + 4 * e;
        const double* p0 = &x[3 * t[0]];
        double R[9];
        frame(p0, &x[3 * t[1]], &x[3 * t[2]], R);
        double* r = &rest[9 * e];  // r[3 (k-1) + i]: local rest coordinate i of node k
        for (int k = 1; k < 4; ++k) {
            const double* pk = &x[3 * t[k]];
            const double d[3] = {pk[0] - p0[0], pk[1] - p0[1], pk[2] - p0[2]};
            for (int i = 0; i < 3; ++i) r[3 * (k - 1) + i] = R[3 * i] * d[0] + R[3 * i + 1] * d[1] + R[3 * i + 2] * d[2];
        }
        // columns r_1, r_2, r_3: the inverse's rows are g_1, g_2, g_3
        const double a = r[0], b = r[3], c = r[6], d = r[1], f = r[4], g = r[7], p = r[2], q = r[5], s = r[8];
        const double det = a * (f * s - g * q) - b * (d * s - g * p) + c * (d * q - f * p);
        double* gr = &grad[12 * e];
        const double inv[9] = {(f * s - g * q) / det, (c * q - b * s) / det, (b * g - c * f) / det,
                               (g * p - d * s) / det, (a * s - c * p) / det, (c * d - a * g) / det,
                               (d * q - f * p) / det, (b * p - a * q) / det, (a * f - b * d) / det};
        for (int i = 0; i < 9; ++i) gr[3 + i] = inv[i];
        for (int i = 0; i < 3; ++i) gr[i] = -(gr[3 + i] + gr[6 + i] + gr[9 + i]);
        const double volume = std::fabs(det) / 6.0;
        vlambda[e] = volume * lambda;
        vmu[e] = volume * mu;
    }

    // ---- assembled K (cg-assembled, cholmod): 3x3 block rows over all nodes, the pattern once ----
    std::vector<std::int64_t> row_start, block_col, slot;  // slot[16 e + 4 a + b]: block (a, b) of e
    std::vector<double> kval;
    if (!matrix_free) {
        std::vector<std::vector<std::int64_t>> neighbours(n);
        for (std::int64_t e = 0; e < ne; ++e)
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b) neighbours[tet[4 * e + a]].push_back(tet[4 * e + b]);
        row_start.assign(n + 1, 0);
        for (std::int64_t i = 0; i < n; ++i) {
            auto& list = neighbours[i];
            std::sort(list.begin(), list.end());
            list.erase(std::unique(list.begin(), list.end()), list.end());
            row_start[i + 1] = row_start[i] + static_cast<std::int64_t>(list.size());
            block_col.insert(block_col.end(), list.begin(), list.end());
        }
        kval.assign(9 * block_col.size(), 0.0);
        slot.resize(16 * ne);
        for (std::int64_t e = 0; e < ne; ++e)
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b) {
                    const std::int64_t i = tet[4 * e + a], j = tet[4 * e + b];
                    slot[16 * e + 4 * a + b] =
                        std::lower_bound(block_col.begin() + row_start[i], block_col.begin() + row_start[i + 1], j) -
                        block_col.begin();
                }
    }

    // ---- per step: forces, world gradients, K ----
    std::vector<double> f(size), v(size, 0.0), r(size), p(size), q(size), dv(size, 0.0);
    const double weight = mass * gy;
    auto forces = [&]() {
        for (std::int64_t i = 0; i < n; ++i) {
            f[3 * i] = 0.0;
            f[3 * i + 1] = weight;
            f[3 * i + 2] = 0.0;
        }
        if (!matrix_free) std::fill(kval.begin(), kval.end(), 0.0);
        for (std::int64_t e = 0; e < ne; ++e) {
            const std::int64_t* t = tet + 4 * e;
            const double* p0 = &x[3 * t[0]];
            double R[9];
            frame(p0, &x[3 * t[1]], &x[3 * t[2]], R);
            const double* r0 = &rest[9 * e];
            const double* g = &grad[12 * e];
            double H[9] = {};  // local displacement gradient
            for (int k = 1; k < 4; ++k) {
                const double* pk = &x[3 * t[k]];
                const double u[3] = {pk[0] - p0[0], pk[1] - p0[1], pk[2] - p0[2]};
                for (int i = 0; i < 3; ++i) {
                    const double di = R[3 * i] * u[0] + R[3 * i + 1] * u[1] + R[3 * i + 2] * u[2] - r0[3 * (k - 1) + i];
                    for (int j = 0; j < 3; ++j) H[3 * i + j] += di * g[3 * k + j];
                }
            }
            const double vl = vlambda[e] * (H[0] + H[4] + H[8]), vm = vmu[e];
            double S[9];
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) S[3 * i + j] = vm * (H[3 * i + j] + H[3 * j + i]) + (i == j ? vl : 0.0);
            double* G = &world_grad[12 * e];
            for (int a = 0; a < 4; ++a) {
                const double* ga = g + 3 * a;
                double fl[3];
                for (int i = 0; i < 3; ++i) fl[i] = -(S[3 * i] * ga[0] + S[3 * i + 1] * ga[1] + S[3 * i + 2] * ga[2]);
                double* fa = &f[3 * t[a]];
                for (int i = 0; i < 3; ++i) {
                    fa[i] += R[i] * fl[0] + R[3 + i] * fl[1] + R[6 + i] * fl[2];
                    G[3 * a + i] = R[i] * ga[0] + R[3 + i] * ga[1] + R[6 + i] * ga[2];
                }
            }
            if (matrix_free) continue;
            const double vl0 = vlambda[e];
            for (int a = 0; a < 4; ++a)
                for (int b = a; b < 4; ++b) {
                    const double* Ga = G + 3 * a;
                    const double* Gb = G + 3 * b;
                    const double dot = vm * (Ga[0] * Gb[0] + Ga[1] * Gb[1] + Ga[2] * Gb[2]);
                    double blk[9];
                    for (int i = 0; i < 3; ++i)
                        for (int j = 0; j < 3; ++j)
                            blk[3 * i + j] = vl0 * Ga[i] * Gb[j] + vm * Gb[i] * Ga[j] + (i == j ? dot : 0.0);
                    double* ab = &kval[9 * slot[16 * e + 4 * a + b]];
                    for (int k = 0; k < 9; ++k) ab[k] += blk[k];
                    if (a == b) continue;
                    double* ba = &kval[9 * slot[16 * e + 4 * b + a]];
                    for (int i = 0; i < 3; ++i)
                        for (int j = 0; j < 3; ++j) ba[3 * j + i] += blk[3 * i + j];
                }
        }
    };

    // out += c K y
    auto k_product = [&](const double* y, double* out, double c) {
        if (!matrix_free) {
            for (std::int64_t i = 0; i < n; ++i) {
                double s0 = 0.0, s1 = 0.0, s2 = 0.0;
                for (std::int64_t k = row_start[i]; k < row_start[i + 1]; ++k) {
                    const double* m = &kval[9 * k];
                    const double* yj = y + 3 * block_col[k];
                    s0 += m[0] * yj[0] + m[1] * yj[1] + m[2] * yj[2];
                    s1 += m[3] * yj[0] + m[4] * yj[1] + m[5] * yj[2];
                    s2 += m[6] * yj[0] + m[7] * yj[1] + m[8] * yj[2];
                }
                out[3 * i] += c * s0;
                out[3 * i + 1] += c * s1;
                out[3 * i + 2] += c * s2;
            }
            return;
        }
        for (std::int64_t e = 0; e < ne; ++e) {
            const std::int64_t* t = tet + 4 * e;
            const double* G = &world_grad[12 * e];
            double H[9] = {};
            for (int a = 0; a < 4; ++a) {
                const double* ya = y + 3 * t[a];
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) H[3 * i + j] += ya[i] * G[3 * a + j];
            }
            const double vl = c * vlambda[e] * (H[0] + H[4] + H[8]), vm = c * vmu[e];
            double S[9];
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) S[3 * i + j] = vm * (H[3 * i + j] + H[3 * j + i]) + (i == j ? vl : 0.0);
            for (int a = 0; a < 4; ++a) {
                const double* Ga = G + 3 * a;
                double* oa = out + 3 * t[a];
                for (int i = 0; i < 3; ++i) oa[i] += S[3 * i] * Ga[0] + S[3 * i + 1] * Ga[1] + S[3 * i + 2] * Ga[2];
            }
        }
    };

    const double mfact = 1.0 + h * rm, kfact = h * (h + rk);

    // ---- CHOLMOD: the free DOFs' upper triangle (compressed columns), analysed once ----
    cholmod_common common;
    cholmod_sparse* A = nullptr;
    cholmod_factor* L = nullptr;
    cholmod_dense *X = nullptr, *Y = nullptr, *E = nullptr;
    std::vector<std::int64_t> source;  // per entry of A: index into kval (-1 - index: a diagonal entry)
    std::vector<std::int64_t> dof_of;  // per free DOF: its index among all DOFs
    std::vector<double> rhs;
    if (direct) {
        cholmod_start(&common);
        if (solver == "cholmod-simplicial") {
            common.supernodal = CHOLMOD_SIMPLICIAL;
            common.final_ll = 0;
        }
        std::vector<std::int64_t> reduced(n, -1);
        std::int64_t free_nodes = 0;
        for (std::int64_t i = 0; i < n; ++i)
            if (free_dof[3 * i]) reduced[i] = free_nodes++;
        const std::int64_t m = 3 * free_nodes;
        std::vector<int> col_start(1, 0), rows;
        for (std::int64_t J = 0; J < n; ++J) {
            if (reduced[J] < 0) continue;
            for (int b = 0; b < 3; ++b) {
                const std::int64_t col = 3 * reduced[J] + b;
                dof_of.push_back(3 * J + b);
                // column col's rows above the diagonal: block (I, J) = block (J, I)^T, I <= J
                for (std::int64_t k = row_start[J]; k < row_start[J + 1] && block_col[k] <= J; ++k) {
                    const std::int64_t I = block_col[k];
                    if (reduced[I] < 0) continue;
                    for (int a = 0; a < 3; ++a) {
                        const std::int64_t row = 3 * reduced[I] + a;
                        if (row > col) break;
                        rows.push_back(static_cast<int>(row));
                        source.push_back(row == col ? -1 - (9 * k + 3 * b + a) : 9 * k + 3 * b + a);
                    }
                }
                col_start.push_back(static_cast<int>(rows.size()));
            }
        }
        A = cholmod_allocate_sparse(m, m, rows.size(), 1, 1, 1, CHOLMOD_REAL, &common);
        std::memcpy(A->p, col_start.data(), col_start.size() * sizeof(int));
        std::memcpy(A->i, rows.data(), rows.size() * sizeof(int));
        L = cholmod_analyze(A, &common);
        rhs.resize(m);
    }
    Phases phases;
    bool timing = false;
    bool failed = false;
    long fewest_iterations = iterations;

    auto step = [&]() {
        double t0 = timing ? bench_ms() : 0.0;
        forces();
        double t1 = timing ? bench_ms() : 0.0;
        phases.forces += t1 - t0;
        for (std::int64_t j = 0; j < size; ++j) r[j] = f[j] - rm * mass * v[j];
        k_product(v.data(), r.data(), -(h + rk));
        for (std::int64_t j = 0; j < size; ++j) r[j] = free_dof[j] ? h * r[j] : 0.0;
        t0 = timing ? bench_ms() : 0.0;
        phases.rhs += t0 - t1;
        if (direct) {
            double* ax = static_cast<double*>(A->x);
            for (std::size_t s = 0; s < source.size(); ++s)
                ax[s] = source[s] >= 0 ? kfact * kval[source[s]] : kfact * kval[-1 - source[s]] + mfact * mass;
            cholmod_factorize(A, L, &common);
            failed = failed || common.status != CHOLMOD_OK;
            t1 = timing ? bench_ms() : 0.0;
            phases.factor += t1 - t0;
            for (std::size_t s = 0; s < dof_of.size(); ++s) rhs[s] = r[dof_of[s]];
            cholmod_dense b{};
            b.nrow = b.nzmax = b.d = rhs.size();
            b.ncol = 1;
            b.x = rhs.data();
            b.xtype = CHOLMOD_REAL;
            b.dtype = CHOLMOD_DOUBLE;
            cholmod_solve2(CHOLMOD_A, L, &b, nullptr, &X, nullptr, &Y, &E, &common);
            const double* sol = static_cast<const double*>(X->x);
            for (std::size_t s = 0; s < dof_of.size(); ++s) dv[dof_of[s]] = sol[s];
            t0 = timing ? bench_ms() : 0.0;
            phases.solve += t0 - t1;
        } else {
            const long done = conjugate_gradient(size, iterations, free_dof.data(), r.data(), p.data(), q.data(),
                                                 dv.data(), [&](const double* y, double* out) {
                                                     for (std::int64_t j = 0; j < size; ++j) out[j] = mfact * mass * y[j];
                                                     k_product(y, out, kfact);
                                                 });
            fewest_iterations = std::min(fewest_iterations, done);
            t1 = timing ? bench_ms() : 0.0;
            phases.solve += t1 - t0;
        }
        for (std::int64_t j = 0; j < size; ++j) {
            v[j] += dv[j];
            x[j] += h * v[j];
        }
    };

    for (long s = 0; s < warmup; ++s) step();
    timing = true;  // the phases of the timed steps (the clock's calls cost ~0.1% of a step)
    run_batches(step, 0, steps, batches);
    const double timed = double(steps * batches);
    std::printf(", \"phase_ms\": {\"forces\": %.6g, \"rhs\": %.6g, \"factor\": %.6g, \"solve\": %.6g}",
                phases.forces / timed, phases.rhs / timed, phases.factor / timed, phases.solve / timed);
    if (direct) {
        std::printf(", \"factor\": \"%s\", \"nnz_L\": %.0f, \"flops\": %.0f, \"failed\": %s",
                    L->is_super ? "supernodal LL^T" : (L->is_ll ? "simplicial LL^T" : "simplicial LDL^T"),
                    common.lnz, common.fl, failed ? "true" : "false");
        cholmod_free_dense(&X, &common);
        cholmod_free_dense(&Y, &common);
        cholmod_free_dense(&E, &common);
        cholmod_free_factor(&L, &common);
        cholmod_free_sparse(&A, &common);
        cholmod_finish(&common);
    } else {
        std::printf(", \"fewest_cg_iterations\": %ld", fewest_iterations);
    }
    std::printf("}\n");
    write_positions(argv[2], x);
    return 0;
}
