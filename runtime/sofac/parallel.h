// Element loops split over threads (OpenMP, optional) with the same numbers as the serial loop.
//
// A serial element loop adds each element's contributions to its nodes in element order, so a
// node's sum is rounded in that order. Threads writing to shared nodes in any other order would
// change the last bits, so the split keeps the order:
// - the elements are cut into `chunks` consecutive ranges, one per thread (whole blocks of 4 for
//   the kernels that run 4 elements at once);
// - a node belongs to the first chunk that touches it; that chunk adds to it directly (no other
//   chunk before it touches the node, so its additions come first, as in the serial loop);
// - a later chunk writes its contributions to such a node into its own slots instead (`deferred`),
//   and the slots are added after all chunks are done, in (chunk, element, corner) order: exactly
//   the serial order.
// The split is static (computed by the compiler from the topology, sofac.plan.element_split), so
// the step allocates nothing. Elements ordered along the mesh (grids, banded meshes) share few
// nodes between chunks: only the interface is deferred.
//
// Without -fopenmp the pragma is compiled out and the chunks run one after another: still the
// serial numbers.
#pragma once

#include "types.h"

namespace sofac {

// Flat arrays of a split, all owned by the instance (see sofac.plan.element_split). Kernels take
// one as their last argument; the default, no chunks, runs the serial loop.
struct ElementSplit {
    const Index* bounds = nullptr;     // chunks + 1 element indices: chunk c holds [bounds[c], bounds[c+1])
    int chunks = 0;
    const Index* slot_of = nullptr;    // per element corner: its deferred slot, or -1 to add directly
    const Index* slot_node = nullptr;  // per slot: the node it adds to
    Index slots = 0;
    double* deferred = nullptr;        // 3 numbers per slot, written by the chunks, added at the end
};

// Runs chunk(begin, end) for each chunk's element range on the split's threads, then adds the
// deferred slots in serial order. A chunk writes a deferred corner's contribution, already signed
// (a kernel that subtracts stores -value: a - b and a + (-b) round the same), to its slot.
template <class Chunk>
inline void for_chunks(const ElementSplit& split, double* out, Chunk chunk) {
#ifdef _OPENMP
#pragma omp parallel for schedule(static, 1) num_threads(split.chunks)
#endif
    for (int c = 0; c < split.chunks; ++c) chunk(split.bounds[c], split.bounds[c + 1]);
    for (Index s = 0; s < split.slots; ++s)
        for (int m = 0; m < 3; ++m) out[3 * split.slot_node[s] + m] += split.deferred[3 * s + m];
}

// out[node] += contribution for every element corner, element(e, F) giving the element's
// 3 * Corners contributions (already signed). The element function must only write per-element
// data of its own element.
template <int Corners, class Element>
inline void split_elements(const ElementSplit& split, const Index* cells, double* out, Element element) {
    for_chunks(split, out, [&](Index begin, Index end) {
        double F[3 * Corners];
        for (Index e = begin; e < end; ++e) {
            element(e, F);
            for (int k = 0; k < Corners; ++k) {
                const Index slot = split.slot_of[Corners * e + k];
                if (slot < 0) {
                    double* node = out + 3 * cells[Corners * e + k];
                    for (int m = 0; m < 3; ++m) node[m] += F[3 * k + m];
                } else {
                    for (int m = 0; m < 3; ++m) split.deferred[3 * slot + m] = F[3 * k + m];
                }
            }
        }
    });
}

// The serial loop over the same element function (no split: the default build).
template <int Corners, class Element>
inline void serial_elements(Index n, const Index* cells, double* out, Element element) {
    double F[3 * Corners];
    for (Index e = 0; e < n; ++e) {
        element(e, F);
        for (int k = 0; k < Corners; ++k) {
            double* node = out + 3 * cells[Corners * e + k];
            for (int m = 0; m < 3; ++m) node[m] += F[3 * k + m];
        }
    }
}

}  // namespace sofac
