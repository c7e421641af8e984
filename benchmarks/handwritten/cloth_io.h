// Shared by the hand-written W1/W2 loops: reads the cloth written by benchmarks/workloads.py.
// Binary, native endianness:
//   int64 points, int64 springs, int64 fixed;
//   double position[3 * points]; int64 a[springs]; int64 b[springs]; double rest[springs];
//   int64 fixed_index[fixed].
#pragma once

#include <cstdint>
#include <cstdio>
#include <vector>

#include "bench_io.h"

struct ClothInput {
    std::int64_t points = 0, springs = 0, fixed = 0;
    std::vector<double> x;
    std::vector<std::int64_t> a, b, fixed_index;
    std::vector<double> rest;
};

inline ClothInput read_cloth(const char* path) {
    std::FILE* file = open_input(path);
    ClothInput c;
    std::vector<std::int64_t> header;
    read_array(file, header, 3);
    c.points = header[0];
    c.springs = header[1];
    c.fixed = header[2];
    read_array(file, c.x, 3 * c.points);
    read_array(file, c.a, c.springs);
    read_array(file, c.b, c.springs);
    read_array(file, c.rest, c.springs);
    read_array(file, c.fixed_index, c.fixed);
    std::fclose(file);
    return c;
}
