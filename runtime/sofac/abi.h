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

// One buffer of a scene's instance, as Python numbers them: the member holding it (numbers or
// indices; the other pointer is null). A scene lists its buffers in a constant array of these, so
// creating an instance and handing a buffer to Python are loops over data, not generated code.
template <class Instance>
struct BufferMember {
    std::vector<double> Instance::*numbers;
    std::vector<std::int64_t> Instance::*indices;
};

// Fills every buffer of a new instance from the arrays Python hands over, in the table's order.
template <class Instance, std::size_t N>
inline void fill_buffers(Instance& S, const BufferMember<Instance> (&table)[N], const void* const* data,
                         const std::int64_t* sizes) {
    for (std::size_t i = 0; i < N; ++i) {
        if (table[i].numbers != nullptr)
            fill(S.*table[i].numbers, data[i], sizes[i]);
        else
            fill(S.*table[i].indices, data[i], sizes[i]);
    }
}

// Buffer `index` of an instance and its current size (buffers may grow: contact capacities), or
// null past the table.
template <class Instance, std::size_t N>
inline void* buffer_at(Instance& S, const BufferMember<Instance> (&table)[N], int index, std::int64_t* size) {
    if (index < 0 || static_cast<std::size_t>(index) >= N) {
        *size = 0;
        return nullptr;
    }
    const BufferMember<Instance>& member = table[index];
    if (member.numbers != nullptr) {
        auto& buffer = S.*member.numbers;
        *size = static_cast<std::int64_t>(buffer.size());
        return buffer.data();
    }
    auto& buffer = S.*member.indices;
    *size = static_cast<std::int64_t>(buffer.size());
    return buffer.data();
}

}  // namespace sofac
