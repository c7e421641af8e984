// Detection cost of the collision runtime (runtime/sofac/collision.h, proximity.h) against model size:
// a wavy triangulated sheet against as many random points in a slab just above it, NewProximity
// triangle-point, for SOFA's default tree depth (6) and deeper ones. The sheet's side grows as
// sqrt(n), so elements keep their size and each point meets the same number of triangles. Each step refits both trees,
// traverses and runs the element tests; built by benchmarks/collision_detection.py.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include "sofac/proximity.h"
using namespace sofac::collide;
using sofac::Index;
int main() {
    for (int n : {100, 1000, 10000, 100000}) for (int depth : {6, 12, 17}) {
        const int m = int(std::sqrt(n / 2.0)) + 1;
        const double side = 10.0 * std::sqrt(n / 100.0);
        std::vector<double> x; std::vector<Index> tris;
        for (int i = 0; i < m; ++i) for (int j = 0; j < m; ++j) {
            double X = side * j / (m - 1), Y = side * i / (m - 1);
            x.insert(x.end(), {X, Y, 0.2 * std::sin(X) * std::cos(Y)});
        }
        for (int i = 0; i + 1 < m; ++i) for (int j = 0; j + 1 < m; ++j) {
            Index a = i * m + j, b = a + 1, c = a + m + 1, d = a + m;
            tris.insert(tris.end(), {a, b, c, a, c, d});
        }
        Index nt = Index(tris.size() / 3);
        std::vector<int> flags(nt, 63);
        std::mt19937 rng(1); std::uniform_real_distribution<double> u(0, 1);
        std::vector<double> p; for (int i = 0; i < n; ++i) p.insert(p.end(), {side * u(rng), side * u(rng), 0.5 * u(rng)});
        TriangleModel tm{x.data(), tris.data(), flags.data(), nullptr, nt, 0.0};
        PointModel pm{p.data(), n, 0.0};
        CubeTree t1, t2; t1.resize(nt, depth); t2.resize(n, depth);
        update_tree(t1, tm, nullptr); update_tree(t2, pm);
        NarrowPhaseStack s; s.reserve_for(t1, t2);
        OutputList out; out.reserve(4 * n);
        const Proximity prox{0.1, 0.05};
        const int reps = std::max(1, 200000 / n);
        auto t0 = std::chrono::steady_clock::now();
        long tests = 0;
        for (int r = 0; r < reps; ++r) {
            update_tree(t1, tm, nullptr); update_tree(t2, pm);
            out.clear();
            bvh_narrow_phase(t1, 0.0, t2, 0.0, 0.1, s, [&](Index a, Index b) {
                ++tests;
                new_proximity::triangle_point(prox, tm, a, pm, b, out);
            });
        }
        double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / reps;
        std::printf("depth %2d: %6ld triangles vs %6d points: %9.3f ms/step, %8ld element tests, %7zu contacts\n",
                    depth, (long)nt, n, dt * 1e3, tests / reps, out.size());
    }
}
