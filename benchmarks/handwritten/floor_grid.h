// Shared by the hand-written contact loops (w4.cpp, w5.cpp): a static triangulated floor binned
// once, before any step, into a uniform grid over (x, z). Each cell lists, in increasing order, the
// triangles whose (x, z) box grown by `reach` overlaps it (CSR arrays: no allocation in a step).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

struct FloorGrid {
    double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};  // the floor points' (x, z) box
    double cell[2] = {1.0, 1.0};
    int side = 1;                      // cells per side: the triangles' mean size
    std::vector<std::int64_t> start;   // cell c's triangles: tris[start[c] .. start[c + 1])
    std::vector<std::int64_t> tris;

    int cell_of(double v, int a) const { return std::clamp(int(std::floor((v - lo[a]) / cell[a])), 0, side - 1); }

    // Whether (x, z) lies outside the floor's box grown by `reach` (no triangle within reach).
    bool outside(double x, double z, double reach) const {
        return x < lo[0] - reach || x > hi[0] + reach || z < lo[1] - reach || z > hi[1] + reach;
    }

    // The triangles of the cell holding (x, z): [first, last).
    struct Range {
        const std::int64_t *first, *last;
        const std::int64_t* begin() const { return first; }
        const std::int64_t* end() const { return last; }
    };
    Range triangles(double x, double z) const {
        const std::size_t c = std::size_t(cell_of(z, 1)) * side + cell_of(x, 0);
        return {tris.data() + start[c], tris.data() + start[c + 1]};
    }

    FloorGrid(const std::vector<double>& floor, const std::vector<std::int64_t>& tri, double reach) {
        const std::int64_t nt = std::int64_t(tri.size() / 3);
        for (std::size_t p = 0; p < floor.size(); p += 3)
            for (int a = 0; a < 2; ++a) {
                lo[a] = std::min(lo[a], floor[p + 2 * a]);
                hi[a] = std::max(hi[a], floor[p + 2 * a]);
            }
        side = std::max(1, int(std::sqrt(double(nt) / 2.0)));
        cell[0] = (hi[0] - lo[0]) / side;
        cell[1] = (hi[1] - lo[1]) / side;
        std::vector<std::vector<std::int64_t>> bins(std::size_t(side) * side);
        for (std::int64_t t = 0; t < nt; ++t) {
            double tlo[2] = {1e300, 1e300}, thi[2] = {-1e300, -1e300};
            for (int c = 0; c < 3; ++c)
                for (int a = 0; a < 2; ++a) {
                    tlo[a] = std::min(tlo[a], floor[3 * tri[3 * t + c] + 2 * a]);
                    thi[a] = std::max(thi[a], floor[3 * tri[3 * t + c] + 2 * a]);
                }
            for (int j = cell_of(tlo[1] - reach, 1); j <= cell_of(thi[1] + reach, 1); ++j)
                for (int i = cell_of(tlo[0] - reach, 0); i <= cell_of(thi[0] + reach, 0); ++i)
                    bins[std::size_t(j) * side + i].push_back(t);
        }
        start.assign(1, 0);
        for (const auto& bin : bins) {
            tris.insert(tris.end(), bin.begin(), bin.end());
            start.push_back(std::int64_t(tris.size()));
        }
    }
};
