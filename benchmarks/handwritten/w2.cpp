// W2 by hand: implicit (backward Euler) mass-spring cloth with a matrix-free conjugate gradient of
// exactly `iterations` iterations, the practical limit for sofac.
//   usage: w2 INPUT OUTPUT dt vertex_mass stiffness gravity_y iterations warmup steps batches
// Each step, as SOFA's EulerImplicitSolver with rayleighStiffness = rayleighMass = 0:
//   f = m g + spring forces; per spring the 3x3 block J = (k - F/d) u u^T + (F/d) I (symmetric,
//   6 numbers kept); b = h (f + h K v), projected (fixed particles' rows zeroed);
//   solve (M - h^2 K) dv = b by CG from dv = 0 (same stopping rules as SOFA's CGLinearSolver with
//   tolerance = threshold = 0: stop only when |b| = 0 or p.Ap = 0), then v += dv, x += h v.
// Prints one JSON line: ms per step of each timed batch, and the fewest CG iterations any step ran.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "cg.h"
#include "cloth_io.h"

int main(int argc, char** argv) {
    if (argc != 11) {
        std::fprintf(stderr, "usage: w2 INPUT OUTPUT dt mass stiffness gravity_y iterations warmup steps batches\n");
        return 2;
    }
    ClothInput c = read_cloth(argv[1]);
    const double h = std::atof(argv[3]), mass = std::atof(argv[4]), k = std::atof(argv[5]);
    const double gy = std::atof(argv[6]);
    const long iterations = std::atol(argv[7]);
    const long warmup = std::atol(argv[8]), steps = std::atol(argv[9]), batches = std::atol(argv[10]);

    const std::int64_t n = c.points, ns = c.springs, size = 3 * c.points;
    std::vector<double>& x = c.x;
    std::vector<double> v(size, 0.0), f(size), r(size), p(size), q(size), dv(size), J(6 * ns);
    std::vector<unsigned char> free_dof(size, 1);
    for (std::int64_t i : c.fixed_index) free_dof[3 * i] = free_dof[3 * i + 1] = free_dof[3 * i + 2] = 0;
    const std::int64_t* sa = c.a.data();
    const std::int64_t* sb = c.b.data();
    const double* rest = c.rest.data();
    const double weight = mass * gy;
    long fewest_iterations = iterations;

    // out += factor * K y (K: the spring blocks of the last force pass), then out's fixed rows = 0.
    auto add_k = [&](double* out, const double* y, double factor) {
        const double* jp = J.data();
        for (std::int64_t s = 0; s < ns; ++s, jp += 6) {
            const std::int64_t ia = 3 * sa[s], ib = 3 * sb[s];
            const double dx = y[ib] - y[ia], dy = y[ib + 1] - y[ia + 1], dz = y[ib + 2] - y[ia + 2];
            const double gx = factor * (jp[0] * dx + jp[1] * dy + jp[2] * dz);
            const double gy2 = factor * (jp[1] * dx + jp[3] * dy + jp[4] * dz);
            const double gz = factor * (jp[2] * dx + jp[4] * dy + jp[5] * dz);
            out[ia] += gx;
            out[ia + 1] += gy2;
            out[ia + 2] += gz;
            out[ib] -= gx;
            out[ib + 1] -= gy2;
            out[ib + 2] -= gz;
        }
    };

    auto step = [&]() {
        const double* xp = x.data();
        for (std::int64_t i = 0; i < n; ++i) {
            f[3 * i] = 0.0;
            f[3 * i + 1] = weight;
            f[3 * i + 2] = 0.0;
        }
        double* jp = J.data();
        for (std::int64_t s = 0; s < ns; ++s, jp += 6) {
            const std::int64_t ia = 3 * sa[s], ib = 3 * sb[s];
            double ux = xp[ib] - xp[ia], uy = xp[ib + 1] - xp[ia + 1], uz = xp[ib + 2] - xp[ia + 2];
            const double d = std::sqrt(ux * ux + uy * uy + uz * uz);
            const double inv = 1.0 / d;
            ux *= inv;
            uy *= inv;
            uz *= inv;
            const double F = k * (d - rest[s]);
            f[ia] += F * ux;
            f[ia + 1] += F * uy;
            f[ia + 2] += F * uz;
            f[ib] -= F * ux;
            f[ib + 1] -= F * uy;
            f[ib + 2] -= F * uz;
            const double t = F * inv, c2 = k - t;
            jp[0] = c2 * ux * ux + t;
            jp[1] = c2 * ux * uy;
            jp[2] = c2 * ux * uz;
            jp[3] = c2 * uy * uy + t;
            jp[4] = c2 * uy * uz;
            jp[5] = c2 * uz * uz + t;
        }
        // b = h (f + h K v), projected
        add_k(f.data(), v.data(), h);
        for (std::int64_t j = 0; j < size; ++j) r[j] = free_dof[j] ? h * f[j] : 0.0;
        const long done = conjugate_gradient(size, iterations, free_dof.data(), r.data(), p.data(), q.data(),
                                             dv.data(), [&](const double* y, double* out) {
                                                 for (std::int64_t j = 0; j < size; ++j) out[j] = mass * y[j];
                                                 add_k(out, y, -h * h);
                                             });
        fewest_iterations = std::min(fewest_iterations, done);
        for (std::int64_t j = 0; j < size; ++j) {
            v[j] += dv[j];
            x[j] += h * v[j];
        }
    };

    run_batches(step, warmup, steps, batches);
    std::printf(", \"fewest_cg_iterations\": %ld}\n", fewest_iterations);
    write_positions(argv[2], x);
    return 0;
}
