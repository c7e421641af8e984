// Shared by the hand-written loops (w1.cpp, w2.cpp, w3.cpp): binary input arrays written by
// benchmarks/workloads.py (native endianness), the final positions written back, the batch clock
// and the JSON report. Nothing here is timed.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

template <class T>
inline void read_array(std::FILE* file, std::vector<T>& out, std::int64_t count) {
    out.resize(static_cast<std::size_t>(count));
    if (count && std::fread(out.data(), sizeof(T), out.size(), file) != out.size()) {
        std::fprintf(stderr, "short read\n");
        std::exit(2);
    }
}

inline std::FILE* open_input(const char* path) {
    std::FILE* file = std::fopen(path, "rb");
    if (!file) {
        std::perror(path);
        std::exit(2);
    }
    return file;
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

// Runs `warmup` untimed steps, then `batches` timed batches of `steps` steps, and prints the start
// of the JSON report: {"ms_per_step": [...] (the caller adds its own fields and the closing brace).
template <class Step>
inline void run_batches(Step&& step, long warmup, long steps, long batches) {
    for (long s = 0; s < warmup; ++s) step();
    std::printf("{\"ms_per_step\": [");
    for (long batch = 0; batch < batches; ++batch) {
        const double start = bench_ms();
        for (long s = 0; s < steps; ++s) step();
        std::printf("%s%.17g", batch ? ", " : "", (bench_ms() - start) / double(steps));
    }
    std::printf("]");
}
