// Shared by the hand-written W1/W2 loops: reads the cloth written by benchmarks/workloads.py and
// writes the final positions back. Binary, native endianness:
//   int64 points, int64 springs, int64 fixed;
//   double position[3 * points]; int64 a[springs]; int64 b[springs]; double rest[springs];
//   int64 fixed_index[fixed].
// Nothing here is timed.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

struct ClothInput {
    std::int64_t points = 0, springs = 0, fixed = 0;
    std::vector<double> x;
    std::vector<std::int64_t> a, b, fixed_index;
    std::vector<double> rest;
};

template <class T>
inline void read_array(std::FILE* file, std::vector<T>& out, std::int64_t count) {
    out.resize(static_cast<std::size_t>(count));
    if (count && std::fread(out.data(), sizeof(T), out.size(), file) != out.size()) {
        std::fprintf(stderr, "short read\n");
        std::exit(2);
    }
}

inline ClothInput read_cloth(const char* path) {
    std::FILE* file = std::fopen(path, "rb");
    if (!file) {
        std::perror(path);
        std::exit(2);
    }
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

inline void write_positions(const char* path, const std::vector<double>& x) {
    std::FILE* file = std::fopen(path, "wb");
    if (!file || std::fwrite(x.data(), sizeof(double), x.size(), file) != x.size()) {
        std::perror(path);
        std::exit(2);
    }
    std::fclose(file);
}

// Milliseconds on the benchmark's clock: the process's CPU time (default: insensitive to the time
// slices other processes take on a shared machine), or the wall clock with SOFAC_BENCH_CLOCK=wall.
inline double bench_ms() {
    const char* clock_name = std::getenv("SOFAC_BENCH_CLOCK");
    if (clock_name && std::string(clock_name) == "wall")
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch())
            .count();
    return 1000.0 * double(std::clock()) / CLOCKS_PER_SEC;
}
