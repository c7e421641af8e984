// The C interface every generated scene library exports, read by sofac's Python host module.
// Plain C symbols keep the scene libraries free of pybind11: only the host, built once per
// installation, includes it, so compiling a scene compiles Eigen and the kernels only.
#pragma once

#include <cstdint>
#include <cstring>
#include <tuple>
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

// An instance's buffers, in the order Python numbers them: `Instance::buffers()` returns them as
// a std::tie, so the generated code lists them once for sofac_create and sofac_buffer.
template <class... Buffers>
inline void fill_all(const std::tuple<Buffers&...>& buffers, const void* const* data, const std::int64_t* sizes) {
    std::size_t index = 0;
    std::apply([&](auto&... buffer) { ((fill(buffer, data[index], sizes[index]), ++index), ...); }, buffers);
}

// Buffer `index`'s first element and its size; nullptr and 0 for an index out of range.
template <class... Buffers>
inline void* buffer_at(const std::tuple<Buffers&...>& buffers, int index, std::int64_t* size) {
    void* found = nullptr;
    *size = 0;
    int position = 0;
    const auto visit = [&](auto& buffer) {
        if (position++ != index) return;
        found = buffer.data();
        *size = std::int64_t(buffer.size());
    };
    std::apply([&](auto&... buffer) { (visit(buffer), ...); }, buffers);
    return found;
}

}  // namespace sofac
