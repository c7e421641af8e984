// The order in which SOFA hands model pairs from the narrow phase to the response: two maps keyed by
// (model 1, model 2) with sofa::helper::map_ptr_stable_compare (F/Helper/.../map_ptr_stable_compare.h),
// the narrow phase's DetectionOutputMap (core/collision/NarrowPhaseDetection.cpp) and
// CollisionResponse's ContactMap (CR/Contact/.../CollisionResponse.{h,cpp}).
//
// Such a map orders keys by (id(first), id(second)), where a model's id is the number of models the
// comparator had seen before it: ids are handed out inside the comparisons libstdc++'s red-black tree
// makes, so the order depends on the exact sequence of map operations and on the order in which the
// comparator evaluates its four id() calls. SOFA writes
//     make_pair(id(b.first), id(b.second)) > make_pair(id(a.first), id(a.second))
// whose operands GCC evaluates right to left (a.second, a.first, b.second, b.first); the comparator
// below makes that sequence explicit, so the order no longer depends on the compiler's choice
// (tests/test_collision_kernels.py checks it against SOFA's expression as g++ compiles it). Use it
// with libstdc++ and the same operations as SOFA (the functions at the end).
//
// Memory: map nodes come from a pool that reserve() fills once (a throwaway map of the same type
// allocates and frees the nodes, so no id is handed out); past it, the pool allocates and counts it.
#pragma once

#include <cstddef>
#include <map>
#include <new>
#include <utility>
#include <vector>

#include "types.h"

namespace sofac::collide {

using ModelPair = std::pair<Index, Index>;

// ptr_stable_id over model handles 0 .. n-1: an id at first presentation, kept for ever.
class StableIds {
public:
    void resize(Index n_models) { ids_.assign(static_cast<std::size_t>(n_models), -1); }
    unsigned id(Index model) {
        long& slot = ids_[static_cast<std::size_t>(model)];
        if (slot < 0) slot = static_cast<long>(counter_++);
        return static_cast<unsigned>(slot);
    }

private:
    std::vector<long> ids_;
    unsigned counter_ = 0;
};

struct StablePairCompare {
    StableIds* ids;
    bool operator()(const ModelPair& a, const ModelPair& b) const {
        const unsigned a2 = ids->id(a.second);
        const unsigned a1 = ids->id(a.first);
        const unsigned b2 = ids->id(b.second);
        const unsigned b1 = ids->id(b.first);
        return std::make_pair(b1, b2) > std::make_pair(a1, a2);
    }
};

// Fixed-size blocks on a free list (a std::map allocates one node at a time, all of one size).
class NodePool {
public:
    NodePool() = default;
    NodePool(const NodePool&) = delete;
    NodePool& operator=(const NodePool&) = delete;
    ~NodePool() {
        for (void* p : owned_) ::operator delete(p);
    }
    void* take(std::size_t bytes) {
        if (!free_.empty() && bytes == block_) {
            void* p = free_.back();
            free_.pop_back();
            return p;
        }
        ++growths;
        block_ = bytes;
        void* p = ::operator new(bytes);
        owned_.push_back(p);
        free_.reserve(owned_.capacity());
        return p;
    }
    void give(void* p) { free_.push_back(p); }
    void reserve_blocks(std::size_t n) {
        owned_.reserve(n);
        free_.reserve(n);
    }
    Index growths = 0;

private:
    std::size_t block_ = 0;
    std::vector<void*> owned_;
    std::vector<void*> free_;
};

template <class T>
struct PoolAllocator {
    using value_type = T;
    NodePool* pool;
    explicit PoolAllocator(NodePool* p) : pool(p) {}
    template <class U>
    PoolAllocator(const PoolAllocator<U>& other) : pool(other.pool) {}  // NOLINT: rebinding
    T* allocate(std::size_t n) { return static_cast<T*>(pool->take(n * sizeof(T))); }
    void deallocate(T* p, std::size_t) { pool->give(p); }
    template <class U>
    bool operator==(const PoolAllocator<U>& other) const {
        return pool == other.pool;
    }
    template <class U>
    bool operator!=(const PoolAllocator<U>& other) const {
        return pool != other.pool;
    }
};

// A map_ptr_stable_compare<pair<model, model>, T> over model handles.
template <class T>
class StablePairMap {
public:
    using Map = std::map<ModelPair, T, StablePairCompare, PoolAllocator<std::pair<const ModelPair, T>>>;

    StablePairMap() : map_(StablePairCompare{&ids_}, PoolAllocator<std::pair<const ModelPair, T>>(&pool_)) {}
    StablePairMap(const StablePairMap&) = delete;
    StablePairMap& operator=(const StablePairMap&) = delete;

    // `n_models` handles; `capacity` nodes (the number of pairs the broad phase can produce).
    void reserve(Index n_models, std::size_t capacity) {
        ids_.resize(n_models);
        pool_.reserve_blocks(capacity);
        StableIds scratch;
        scratch.resize(static_cast<Index>(capacity) + 1);
        Map warm(StablePairCompare{&scratch}, map_.get_allocator());
        for (std::size_t i = 0; i < capacity; ++i) warm.emplace(ModelPair{static_cast<Index>(i), 0}, T{});
        pool_.growths = 0;
    }

    Map& map() { return map_; }
    const Map& map() const { return map_; }
    Index growths() const { return pool_.growths; }

private:
    StableIds ids_;
    NodePool pool_;
    Map map_;
};

// ---------------------------------------------------------------------------------------------
// SOFA's operations on the two maps, in the order the pipeline makes them each step:
// narrow phase: output_slot() for every pair it tests (NarrowPhaseDetection::getDetectionOutputs:
// insert with the hint end()), then erase_empty() (endNarrowPhase); response: for each entry of the
// output map in order, contact_slot() (CollisionResponse::createNewContacts: plain insert), then
// remove_inactive() (removeInactiveContacts: a find in the output map per contact); the contact
// map's order is then the order of SOFA's `contacts` (createResponse, placement).

// (They take the std::map itself, StablePairMap::map(), so the same code drives any comparator.)

template <class Map>
typename Map::iterator output_slot(Map& outputs, Index model1, Index model2) {
    return outputs.insert(outputs.end(), {ModelPair{model1, model2}, typename Map::mapped_type{}});
}

// Erases the entries `empty(value)` says are empty, in map order.
template <class Map, class Empty>
void erase_empty(Map& outputs, Empty&& empty) {
    for (auto it = outputs.begin(); it != outputs.end();) {
        if (empty(it->second))
            it = outputs.erase(it);
        else
            ++it;
    }
}

// Inserts key (the output map's entry) into the contact map; `second` is true when it is new.
template <class Map>
std::pair<typename Map::iterator, bool> contact_slot(Map& contacts, const ModelPair& key) {
    return contacts.insert({key, typename Map::mapped_type{}});
}

// Erases the contacts whose key the output map no longer holds (`removed(value)` is told first).
template <class Map, class OutputMap, class Removed>
void remove_inactive(Map& contacts, const OutputMap& outputs, Removed&& removed) {
    for (auto it = contacts.begin(); it != contacts.end();) {
        if (outputs.find(it->first) == outputs.end()) {
            removed(it->second);
            it = contacts.erase(it);
        } else {
            ++it;
        }
    }
}

}  // namespace sofac::collide
