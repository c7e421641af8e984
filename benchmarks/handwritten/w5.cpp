// W5 by hand: damped spheres dropped onto a flat static triangulated floor with penalty contact,
// symplectic Euler: the algorithm of the sofac scene (SOFA's MinProximity triangle-sphere test,
// BarycentricPenalityContact's stiffness and PenalityContactForceField, UniformVelocityDamping)
// with what a hand-written loop can know: the floor never moves, so its triangles are binned once
// into a uniform grid over (x, z) (floor_grid.h), and each sphere tests only its cell.
//   usage: w5 INPUT OUTPUT dt mass radius k1 k2 alarm contact damping gravity_y warmup steps batches
// INPUT (native endianness): int64 spheres, floor points, triangles; double x[3 spheres];
// double floor[3 floor points]; int64 triangles[3 triangles] (the file of w4.cpp).
// Each step: f = m g - c v; for every sphere centre P, of the triangles of its cell whose interior
// (1e-6 margins) holds P's projection Q within alarm + r, the closest (SOFA keeps one contact per
// sphere: the smallest distance), pen = contact + r - |P - Q| and, when pen > 0, f += ks pen n
// (n = (P - Q) / |P - Q|, ks = k1 k2 / (contact + r)); then a = f / m; v += dt a; x += dt v.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench_io.h"
#include "floor_grid.h"

int main(int argc, char** argv) {
    if (argc != 15) {
        std::fprintf(stderr,
                     "usage: w5 INPUT OUTPUT dt mass radius k1 k2 alarm contact damping gravity_y warmup steps "
                     "batches\n");
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
    const double dt = std::atof(argv[3]), mass = std::atof(argv[4]), r = std::atof(argv[5]);
    const double alarm = std::atof(argv[8]) + r, contact = std::atof(argv[9]) + r;
    const double ks = std::atof(argv[6]) * std::atof(argv[7]) / contact;
    const double c = std::atof(argv[10]), gy = std::atof(argv[11]);
    const long warmup = std::atol(argv[12]), steps = std::atol(argv[13]), batches = std::atol(argv[14]);

    const FloorGrid grid(floor, tri, alarm);  // the triangles within alarm + r of each cell

    std::vector<double> v(3 * n, 0.0), f(3 * n, 0.0);
    const double weight = mass * gy;
    auto step = [&]() {
        for (std::int64_t p = 0; p < n; ++p) {
            double* fp = &f[3 * p];
            const double* P = &x[3 * p];
            const double* vp = &v[3 * p];
            fp[0] = 0.0;
            fp[1] = weight;
            fp[2] = 0.0;
            for (int k = 0; k < 3; ++k) fp[k] += -c * vp[k];
            if (grid.outside(P[0], P[2], alarm)) continue;
            double best_d2 = alarm * alarm, best[3] = {0.0, 0.0, 0.0};  // the closest projection
            for (const std::int64_t t : grid.triangles(P[0], P[2])) {
                // SOFA's parametrisation from p1: x13 = p1 - p2, x23 = p1 - p3, x03 = p1 - P
                const double* p1 = &floor[3 * tri[3 * t]];
                const double* p2 = &floor[3 * tri[3 * t + 1]];
                const double* p3 = &floor[3 * tri[3 * t + 2]];
                double x13[3], x23[3], x03[3];
                for (int k = 0; k < 3; ++k) {
                    x13[k] = p1[k] - p2[k];
                    x23[k] = p1[k] - p3[k];
                    x03[k] = p1[k] - P[k];
                }
                const double A00 = x13[0] * x13[0] + x13[1] * x13[1] + x13[2] * x13[2];
                const double A11 = x23[0] * x23[0] + x23[1] * x23[1] + x23[2] * x23[2];
                const double A01 = x13[0] * x23[0] + x13[1] * x23[1] + x13[2] * x23[2];
                const double b0 = x13[0] * x03[0] + x13[1] * x03[1] + x13[2] * x03[2];
                const double b1 = x23[0] * x03[0] + x23[1] * x03[1] + x23[2] * x03[2];
                const double det = A00 * A11 - A01 * A01;
                const double alpha = (b0 * A11 - b1 * A01) / det, beta = (b1 * A00 - b0 * A01) / det;
                if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) continue;
                double QP[3];
                for (int k = 0; k < 3; ++k) QP[k] = P[k] - (p1[k] - x13[k] * alpha - x23[k] * beta);
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
