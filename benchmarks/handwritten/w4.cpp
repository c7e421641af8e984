// W4 by hand: particles bouncing on a static triangulated floor with penalty contact, symplectic
// Euler, the algorithm of the sofac scene (SOFA's MinProximity triangle-point test and
// PenalityContactForceField) with what a hand-written loop can know: the floor never moves, so its
// triangles are binned once into a uniform grid over (x, z), and each particle tests only its cell.
//   usage: w4 INPUT OUTPUT dt mass k1 k2 alarm contact gravity_y warmup steps batches
// INPUT (native endianness): int64 particles, floor points, triangles; double x[3 particles];
// double floor[3 floor points]; int64 triangles[3 triangles].
// Each step: f = m g; for every particle, of the triangles of its cell whose interior holds the
// particle's projection Q within the alarm distance, the closest (SOFA keeps one contact per point:
// the smallest distance), pen = contact - |P - Q| and, when pen > 0, f += ks pen n
// (n = (P - Q) / |P - Q|, ks = k1 k2 / contact); then a = f / m; v += dt a; x += dt v.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench_io.h"
#include "floor_grid.h"

int main(int argc, char** argv) {
    if (argc != 13) {
        std::fprintf(stderr, "usage: w4 INPUT OUTPUT dt mass k1 k2 alarm contact gravity_y warmup steps batches\n");
        return 2;
    }
    std::FILE* file = open_input(argv[1]);
    std::vector<std::int64_t> header, tri;
    std::vector<double> x, floor;
    read_array(file, header, 3);
    const std::int64_t n = header[0], nt = header[2];
    read_array(file, x, 3 * n);
    read_array(file, floor, 3 * header[1]);
    read_array(file, tri, 3 * nt);
    std::fclose(file);
    const double dt = std::atof(argv[3]), mass = std::atof(argv[4]);
    const double ks = std::atof(argv[5]) * std::atof(argv[6]) / std::atof(argv[8]);
    const double alarm = std::atof(argv[7]), contact = std::atof(argv[8]), gy = std::atof(argv[9]);
    const long warmup = std::atol(argv[10]), steps = std::atol(argv[11]), batches = std::atol(argv[12]);

    const FloorGrid grid(floor, tri, alarm);  // the triangles within the alarm distance of each cell

    std::vector<double> v(3 * n, 0.0), f(3 * n, 0.0);
    const double weight = mass * gy;
    auto step = [&]() {
        for (std::int64_t p = 0; p < n; ++p) {
            double* fp = &f[3 * p];
            const double* P = &x[3 * p];
            fp[0] = 0.0;
            fp[1] = weight;
            fp[2] = 0.0;
            if (grid.outside(P[0], P[2], alarm)) continue;
            double best_d2 = alarm * alarm, best[3] = {0.0, 0.0, 0.0};  // the closest projection
            for (const std::int64_t t : grid.triangles(P[0], P[2])) {
                const double* p1 = &floor[3 * tri[3 * t]];
                const double* p2 = &floor[3 * tri[3 * t + 1]];
                const double* p3 = &floor[3 * tri[3 * t + 2]];
                double AB[3], AC[3], AP[3];
                for (int k = 0; k < 3; ++k) {
                    AB[k] = p2[k] - p1[k];
                    AC[k] = p3[k] - p1[k];
                    AP[k] = P[k] - p1[k];
                }
                const double A00 = AB[0] * AB[0] + AB[1] * AB[1] + AB[2] * AB[2];
                const double A11 = AC[0] * AC[0] + AC[1] * AC[1] + AC[2] * AC[2];
                const double A01 = AB[0] * AC[0] + AB[1] * AC[1] + AB[2] * AC[2];
                const double b0 = AP[0] * AB[0] + AP[1] * AB[1] + AP[2] * AB[2];
                const double b1 = AP[0] * AC[0] + AP[1] * AC[1] + AP[2] * AC[2];
                const double det = A00 * A11 - A01 * A01;
                const double alpha = (b0 * A11 - b1 * A01) / det, beta = (b1 * A00 - b0 * A01) / det;
                if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) continue;
                double QP[3];
                for (int k = 0; k < 3; ++k) QP[k] = P[k] - (p1[k] + AB[k] * alpha + AC[k] * beta);
                const double d2 = QP[0] * QP[0] + QP[1] * QP[1] + QP[2] * QP[2];
                if (d2 < best_d2) {
                    best_d2 = d2;
                    for (int k = 0; k < 3; ++k) best[k] = QP[k];
                }
            }
            const double d = std::sqrt(best_d2), pen = contact - d;
            if (pen > 0 && d > 1e-15)
                for (int k = 0; k < 3; ++k) fp[k] += ks * pen * (best[k] / d);
        }
        for (std::int64_t i = 0; i < 3 * n; ++i) {
            v[i] += dt * (f[i] / mass);
            x[i] += dt * v[i];
        }
    };
    run_batches(step, warmup, steps, batches);
    std::printf("}\n");
    write_positions(argv[2], x);
    return 0;
}
