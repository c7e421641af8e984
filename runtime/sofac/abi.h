// The C interface every generated scene library exports, read by sofac's Python host module.
// Plain C symbols keep the scene libraries free of pybind11: only the host, built once per
// installation, includes it, so compiling a scene compiles Eigen and the kernels only.
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

#define SOFAC_ABI_VERSION 2  // 2: sofac_update_mapped
#define SOFAC_EXPORT __attribute__((visibility("default")))

namespace sofac {

// Copy `size` elements handed over by Python into an instance buffer (sized once, at creation).
template <class T>
inline void fill(std::vector<T>& buffer, const void* data, std::int64_t size) {
    buffer.resize(static_cast<std::size_t>(size));
    if (size > 0) std::memcpy(buffer.data(), data, static_cast<std::size_t>(size) * sizeof(T));
}

}  // namespace sofac
