// W1 by hand: explicit (symplectic Euler) mass-spring cloth, the practical limit for sofac.
//   usage: w1 INPUT OUTPUT dt vertex_mass stiffness gravity_y warmup steps batches
// Each step: f = m g + spring forces (k (d - L0) along the spring, no damping: W1 has none);
// v += dt f / m on the free particles; x += dt v. Prints one JSON line with the ms per step of
// each timed batch (bench_ms() around the batch only: CPU time by default).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "cloth_io.h"

int main(int argc, char** argv) {
    if (argc != 10) {
        std::fprintf(stderr, "usage: w1 INPUT OUTPUT dt mass stiffness gravity_y warmup steps batches\n");
        return 2;
    }
    ClothInput c = read_cloth(argv[1]);
    const double dt = std::atof(argv[3]), mass = std::atof(argv[4]), k = std::atof(argv[5]);
    const double gy = std::atof(argv[6]);
    const long warmup = std::atol(argv[7]), steps = std::atol(argv[8]), batches = std::atol(argv[9]);

    const std::int64_t n = c.points, ns = c.springs;
    std::vector<double>& x = c.x;
    std::vector<double> v(3 * n, 0.0), f(3 * n, 0.0);
    std::vector<double> dt_over_m(n, dt / mass);  // 0 on fixed particles: they never move
    for (std::int64_t i : c.fixed_index) dt_over_m[i] = 0.0;
    const std::int64_t* sa = c.a.data();
    const std::int64_t* sb = c.b.data();
    const double* rest = c.rest.data();
    const double weight = mass * gy;

    auto step = [&]() {
        double* fp = f.data();
        const double* xp = x.data();
        for (std::int64_t i = 0; i < n; ++i) {
            fp[3 * i] = 0.0;
            fp[3 * i + 1] = weight;
            fp[3 * i + 2] = 0.0;
        }
        for (std::int64_t s = 0; s < ns; ++s) {
            const std::int64_t ia = 3 * sa[s], ib = 3 * sb[s];
            const double ux = xp[ib] - xp[ia], uy = xp[ib + 1] - xp[ia + 1], uz = xp[ib + 2] - xp[ia + 2];
            const double d = std::sqrt(ux * ux + uy * uy + uz * uz);
            const double scale = k * (d - rest[s]) / d;  // intensity / length
            const double fx = ux * scale, fy = uy * scale, fz = uz * scale;
            fp[ia] += fx;
            fp[ia + 1] += fy;
            fp[ia + 2] += fz;
            fp[ib] -= fx;
            fp[ib + 1] -= fy;
            fp[ib + 2] -= fz;
        }
        double* vp = v.data();
        double* xw = x.data();
        for (std::int64_t i = 0; i < n; ++i) {
            const double h = dt_over_m[i];
            for (int d = 0; d < 3; ++d) {
                vp[3 * i + d] += h * fp[3 * i + d];
                xw[3 * i + d] += dt * vp[3 * i + d];
            }
        }
    };

    run_batches(step, warmup, steps, batches);
    std::printf("}\n");
    write_positions(argv[2], x);
    return 0;
}
