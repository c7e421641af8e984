// Collision detection as SOFA's DefaultPipeline runs it: leaf boxes of the collision models, the
// CubeCollisionModel bounding tree (built once, refitted after), BruteForceBroadPhase's model pairs
// and BVHNarrowPhase's traversal, in SOFA's orders (docs/collision-runtime.md names the SOFA file of
// each rule).
//
// Arithmetic goes through V3, whose dot, norm and cross are SOFA's type::Vec (left-to-right sums):
// Eigen's fixed-size reductions pair the terms differently, and contact order and contact values
// must match SOFA bit for bit.
//
// Memory: every buffer is sized by resize()/reserve() at initialisation; a step only writes into
// them. The traversal stack has a capacity that the tree depth bounds (CubeTree::stack_bound), so
// it never grows in a step.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "types.h"

namespace sofac::collide {

struct V3 {
    double v[3];
    double operator[](int i) const { return v[i]; }
    double& operator[](int i) { return v[i]; }
};

inline V3 load3(const double* x, Index stride, Index i) {
    const double* p = x + stride * i;
    return V3{{p[0], p[1], p[2]}};
}
inline V3 operator+(const V3& a, const V3& b) { return V3{{a[0] + b[0], a[1] + b[1], a[2] + b[2]}}; }
inline V3 operator-(const V3& a, const V3& b) { return V3{{a[0] - b[0], a[1] - b[1], a[2] - b[2]}}; }
inline V3 operator-(const V3& a) { return V3{{-a[0], -a[1], -a[2]}}; }
inline V3 operator*(const V3& a, double s) { return V3{{a[0] * s, a[1] * s, a[2] * s}}; }
inline V3 operator/(const V3& a, double s) { return V3{{a[0] / s, a[1] / s, a[2] / s}}; }
inline double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline double norm2(const V3& a) { return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]; }
inline V3 cross(const V3& a, const V3& b) {
    return V3{{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}};
}
// SOFA's Vec::normalize(): divides only when the norm exceeds DBL_EPSILON, else leaves v as is.
inline V3 normalized(const V3& a) {
    const double n = std::sqrt(norm2(a));
    return n > std::numeric_limits<double>::epsilon() ? a / n : a;
}

struct Box {
    V3 min, max;
};

// ---------------------------------------------------------------------------------------------
// Leaf boxes, one per element, grown by the model's contactDistance (the loops of
// Triangle/Line/Point/SphereCollisionModel::computeBoundingTree).

inline void grow_by(const V3& p, Box& box, int c) {
    if (p[c] > box.max[c])
        box.max[c] = p[c];
    else if (p[c] < box.min[c])
        box.min[c] = p[c];
}

inline Box triangle_box(const V3& p1, const V3& p2, const V3& p3, double distance) {
    Box box{p1, p1};
    for (int c = 0; c < 3; ++c) {
        grow_by(p2, box, c);
        grow_by(p3, box, c);
        box.min[c] -= distance;
        box.max[c] += distance;
    }
    return box;
}

inline Box line_box(const V3& p1, const V3& p2, double distance) {
    Box box{p1, p1};
    for (int c = 0; c < 3; ++c) {
        grow_by(p2, box, c);
        box.min[c] -= distance;
        box.max[c] += distance;
    }
    return box;
}

inline Box point_box(const V3& p, double distance) {
    const V3 d{{distance, distance, distance}};
    return Box{p - d, p + d};
}

inline Box sphere_box(const V3& center, double radius, double distance) {
    const double r = radius + distance;
    const V3 d{{r, r, r}};
    return Box{center - d, center + d};
}

// TriangleCollisionModel's stored normal (computeNormals): normalize(cross(p2 - p1, p3 - p1)).
inline V3 triangle_normal(const V3& p1, const V3& p2, const V3& p3) { return normalized(cross(p2 - p1, p3 - p1)); }

// ---------------------------------------------------------------------------------------------
// Triangle feature flags (TriangleCollisionModel::getTriangleFlags): a triangle owns its vertex j
// (FLAG_P1 << j) if it is the first triangle around that vertex, its edge opposite vertex j
// (FLAG_E23 << j) if it is the first triangle around that edge, and FLAG_BE23 << j marks a boundary
// edge. With a MeshTopology the "first" triangle is the one of lowest index. Computed once, at
// initialisation (it allocates).
enum TriangleFlag : int {
    FLAG_P1 = 1 << 0,
    FLAG_P2 = 1 << 1,
    FLAG_P3 = 1 << 2,
    FLAG_E23 = 1 << 3,
    FLAG_E31 = 1 << 4,
    FLAG_E12 = 1 << 5,
    FLAG_BE23 = 1 << 6,
    FLAG_BE31 = 1 << 7,
    FLAG_BE12 = 1 << 8,
};

inline void triangle_flags(const Index* triangles, Index n_triangles, Index n_points, int* flags) {
    std::vector<Index> first_at_vertex(static_cast<std::size_t>(n_points), -1);
    struct EdgeUse {
        Index a, b, first, count;
    };
    std::vector<EdgeUse> edges;
    edges.reserve(static_cast<std::size_t>(3 * n_triangles));
    for (Index t = 0; t < n_triangles; ++t) {
        for (int j = 0; j < 3; ++j) {
            const Index v = triangles[3 * t + j];
            if (first_at_vertex[v] < 0) first_at_vertex[v] = t;
            edges.push_back({std::min(triangles[3 * t + (j + 1) % 3], triangles[3 * t + (j + 2) % 3]),
                             std::max(triangles[3 * t + (j + 1) % 3], triangles[3 * t + (j + 2) % 3]), t, 1});
        }
    }
    // Group equal edges: sort (edge, triangle) records, the first of a run is the lowest triangle.
    std::vector<Index> order(edges.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<Index>(i);
    std::stable_sort(order.begin(), order.end(), [&](Index l, Index r) {
        return edges[l].a != edges[r].a ? edges[l].a < edges[r].a : edges[l].b < edges[r].b;
    });
    for (std::size_t s = 0; s < order.size();) {
        std::size_t e = s;
        while (e < order.size() && edges[order[e]].a == edges[order[s]].a && edges[order[e]].b == edges[order[s]].b)
            ++e;
        for (std::size_t k = s; k < e; ++k) {
            edges[order[k]].first = edges[order[s]].first;
            edges[order[k]].count = static_cast<Index>(e - s);
        }
        s = e;
    }
    for (Index t = 0; t < n_triangles; ++t) {
        int f = 0;
        for (int j = 0; j < 3; ++j) {
            if (first_at_vertex[triangles[3 * t + j]] == t) f |= FLAG_P1 << j;
            const EdgeUse& edge = edges[static_cast<std::size_t>(3 * t + j)];
            if (edge.first == t) f |= FLAG_E23 << j;
            if (edge.count == 1) f |= FLAG_BE23 << j;
        }
        flags[t] = f;
    }
}

// ---------------------------------------------------------------------------------------------
// CubeCollisionModel's bounding tree. levels[0] holds the root cube; levels[1..depth] the cubes a
// split created; the leaf cubes (one per element, SOFA's last CubeCollisionModel) are `leaves`.
// A cube's subcells are a range of the next level, or of the leaves (sub_level == kLeaves) when
// it was never split (4 leaves or fewer, or the deepest level).
class CubeTree {
public:
    static constexpr int kLeaves = -1;
    struct Cube {
        Box box;
        int sub_level;
        Index sub_begin, sub_end;
    };
    struct Leaf {
        Box box;
        Index element;
    };

    // Sizes the tree for `n_elements` elements and `max_depth` splits (the pipeline's depth);
    // the structure is built by the first update().
    void resize(Index n_elements, int max_depth) {
        depth_ = max_depth;
        leaves_.assign(static_cast<std::size_t>(n_elements), Leaf{Box{}, 0});
        parent_of_.resize(static_cast<std::size_t>(n_elements));
        for (Index i = 0; i < n_elements; ++i) {
            leaves_[i].element = i;
            parent_of_[i] = i;
        }
        levels_.assign(static_cast<std::size_t>(max_depth + 1), {});
        // Level l holds at most 2^l cubes, and fewer than n (a split cube has 5 leaves or more).
        for (int l = 0; l <= max_depth; ++l) {
            const Index by_split = l < 62 ? (Index{1} << l) : n_elements;
            levels_[l].reserve(static_cast<std::size_t>(std::max<Index>(1, std::min(by_split, n_elements))));
        }
        built_ = false;
    }

    // CubeCollisionModel::setParentOf: element i's box goes to the leaf cube that holds it.
    void set_box(Index element, const Box& box) { leaves_[parent_of_[element]].box = box; }

    // CubeCollisionModel::computeBoundingTree: the first call splits (the structure depends on the
    // boxes of that call only), later calls refit every level from the deepest up.
    void update() {
        if (leaves_.empty()) return;
        if (!built_) {
            build();
            built_ = true;
        } else {
            for (int l = depth_; l >= 0; --l)
                for (Cube& cube : levels_[l]) refit(cube);
        }
    }

    bool built() const { return built_; }
    bool empty() const { return leaves_.empty(); }
    int depth() const { return depth_; }
    Index size() const { return static_cast<Index>(leaves_.size()); }
    const Cube& root() const { return levels_[0][0]; }
    const std::vector<Cube>& level(int l) const { return levels_[l]; }
    const Leaf& leaf(Index i) const { return leaves_[i]; }
    const Box& box(int level, Index i) const { return level == kLeaves ? leaves_[i].box : levels_[level][i].box; }
    // The most leaf cubes under one cube (4 at most above the deepest level, any number at it).
    Index widest_leaf_range() const { return widest_leaf_range_; }

private:
    Box range_box(int level, Index begin, Index end) const {
        Box result = box(level, begin);
        for (Index i = begin + 1; i < end; ++i) {
            const Box& b = box(level, i);
            for (int c = 0; c < 3; ++c) {
                if (b.max[c] > result.max[c]) result.max[c] = b.max[c];
                if (b.min[c] < result.min[c]) result.min[c] = b.min[c];
            }
        }
        return result;
    }
    void refit(Cube& cube) const { cube.box = range_box(cube.sub_level, cube.sub_begin, cube.sub_end); }
    Index add_cube(int level, Index begin, Index end) {
        levels_[level].push_back(Cube{range_box(kLeaves, begin, end), kLeaves, begin, end});
        return static_cast<Index>(levels_[level].size()) - 1;
    }

    void build() {
        for (auto& level : levels_) level.clear();
        add_cube(0, 0, size());
        for (int l = 0; l < depth_; ++l) {
            for (std::size_t c = 0; c < levels_[l].size(); ++c) {
                Cube& cube = levels_[l][c];
                const Index begin = cube.sub_begin, end = cube.sub_end, count = end - begin;
                if (count <= 4) continue;
                const V3 extent = cube.box.max - cube.box.min;
                const int axis =
                    extent[0] > extent[1] ? (extent[0] > extent[2] ? 0 : 2) : (extent[1] > extent[2] ? 1 : 2);
                const Index middle = begin + (count + 1) / 2;
                std::stable_sort(leaves_.begin() + begin, leaves_.begin() + end, [axis](const Leaf& a, const Leaf& b) {
                    return a.box.min[axis] + a.box.max[axis] < b.box.min[axis] + b.box.max[axis];
                });
                const Index first = add_cube(l + 1, begin, middle);  // (another level: `cube` stays valid)
                const Index second = add_cube(l + 1, middle, end);
                cube.sub_level = l + 1;
                cube.sub_begin = first;
                cube.sub_end = second + 1;
            }
        }
        for (Index i = 0; i < size(); ++i) parent_of_[leaves_[i].element] = i;
        widest_leaf_range_ = 0;
        for (const auto& level : levels_)
            for (const Cube& cube : level)
                if (cube.sub_level == kLeaves)
                    widest_leaf_range_ = std::max(widest_leaf_range_, cube.sub_end - cube.sub_begin);
    }

    int depth_ = 0;
    Index widest_leaf_range_ = 0;
    bool built_ = false;
    std::vector<std::vector<Cube>> levels_;
    std::vector<Leaf> leaves_;
    std::vector<Index> parent_of_;
};

// BaseProximityIntersection::testIntersection(Cube, Cube): a = alarmDistance + the two models'
// contactDistance (a model's cubes carry its contactDistance).
inline bool boxes_meet(const Box& a, const Box& b, double reach) {
    for (int c = 0; c < 3; ++c)
        if (a.min[c] > b.max[c] + reach || b.min[c] > a.max[c] + reach) return false;
    return true;
}

// ---------------------------------------------------------------------------------------------
// BruteForceBroadPhase::addCollisionModel over the pipeline's models in order. What SOFA decides
// from types, nodes and groups is a compile-time table `rule` (n x n, row-major):
//   rule[i*n+i]: 1 if model i may self-collide (simulated, canCollideWith itself, an intersector
//                for its own type);
//   rule[i*n+j], j < i: kNever, kKeep (pair (i, j)) or kSwap (pair (j, i): the intersector is
//                registered for the other type order). Both-static pairs and canCollideWith
//                refusals are kNever.
// At run time only the root boxes decide. `pairs` receives (first, second) model indices, capacity
// n (n + 1) / 2 pairs; the count is returned. Models with no element are skipped, as SOFA skips
// empty models before recording them.
enum PairRule : std::int8_t { kNever = 0, kKeep = 1, kSwap = 2 };

struct BroadPhaseModel {
    const CubeTree* tree;
    double contact_distance;
};

inline Index brute_force_broad_phase(const BroadPhaseModel* models, Index n, const std::int8_t* rule,
                                     double alarm_distance, Index* pairs) {
    Index count = 0;
    for (Index i = 0; i < n; ++i) {
        const CubeTree& tree = *models[i].tree;
        if (tree.empty()) continue;
        const Box& root = tree.root().box;
        const double self_reach = alarm_distance + 2 * models[i].contact_distance;
        if (rule[i * n + i] && boxes_meet(root, root, self_reach)) {
            pairs[2 * count] = i;
            pairs[2 * count + 1] = i;
            ++count;
        }
        for (Index j = 0; j < i; ++j) {
            if (models[j].tree->empty() || rule[i * n + j] == kNever) continue;
            const double reach = alarm_distance + models[i].contact_distance + models[j].contact_distance;
            if (!boxes_meet(root, models[j].tree->root().box, reach)) continue;
            const bool swap = rule[i * n + j] == kSwap;
            pairs[2 * count] = swap ? j : i;
            pairs[2 * count + 1] = swap ? i : j;
            ++count;
        }
    }
    return count;
}

// ---------------------------------------------------------------------------------------------
// BVHNarrowPhase::addCollisionPair for one model pair, models already in the intersector's order.
// The traversal starts from the roots' subcells; for a pair of cube ranges it tests every
// (c1, c2), c1 outer, in index order: a pair of leaf cubes calls `elements(e1, e2)` at once; any
// other meeting pair is pushed, to be popped (LIFO) after the loop. The caller's `elements` applies
// the self-collision element filter and the intersector. (SOFA's queue of external cells only
// ever holds the first cell when both models have cube trees, so it is not reproduced.)
struct NarrowPhaseStack {
    struct Entry {
        int level1, level2;
        Index begin1, end1, begin2, end2;
    };
    std::vector<Entry> entries;
    std::vector<Index> near1, near2;  // a leaf block's leaves that can meet the other side (in order)
    // The capacity a pair of built trees can need, reserved once after their first update(). A
    // popped pair pushes at most 2 w + 4 pairs (a split cube has 2 subcells, an unsplit one at most
    // w leaves; two leaves are never pushed), and each push goes one level deeper on at least one
    // side (depth + 2 levels per tree, root and leaves included).
    void reserve_for(const CubeTree& tree1, const CubeTree& tree2) {
        const Index widest = std::max(tree1.widest_leaf_range(), tree2.widest_leaf_range());
        const Index path = tree1.depth() + tree2.depth() + 4;
        const Index bound = (2 * widest + 4) * path;
        if (static_cast<std::size_t>(bound) > entries.capacity()) entries.reserve(static_cast<std::size_t>(bound));
        near1.reserve(static_cast<std::size_t>(tree1.widest_leaf_range()));
        near2.reserve(static_cast<std::size_t>(tree2.widest_leaf_range()));
    }
};

namespace detail {
inline Box union_of(const CubeTree& tree, const std::vector<Index>& leaves) {
    Box box = tree.leaf(leaves.front()).box;
    for (const Index i : leaves)
        for (int c = 0; c < 3; ++c) {
            box.min[c] = std::min(box.min[c], tree.leaf(i).box.min[c]);
            box.max[c] = std::max(box.max[c], tree.leaf(i).box.max[c]);
        }
    return box;
}

// The leaves of [begin, end) whose box meets `other` (grown by `reach`), in order.
inline void leaves_near(const CubeTree& tree, Index begin, Index end, const Box& other, double reach,
                        std::vector<Index>& out) {
    out.clear();
    for (Index i = begin; i < end; ++i)
        if (boxes_meet(tree.leaf(i).box, other, reach)) out.push_back(i);
}

// Two blocks of leaves (the deepest cubes' elements: up to hundreds each at SOFA's depth 6): every
// pair whose boxes meet, in the order of the double loop over both blocks. A leaf that misses the
// union of the other block's boxes misses each of them, so the pairs of the leaves left are the
// same pairs in the same order, for far fewer box tests when the blocks only partly overlap.
template <class Elements>
inline void leaf_blocks(const CubeTree& tree1, Index begin1, Index end1, const CubeTree& tree2, Index begin2,
                        Index end2, double reach, NarrowPhaseStack& stack, Elements&& elements) {
    std::vector<Index>& near2 = stack.near2;
    std::vector<Index>& near1 = stack.near1;
    near2.clear();
    for (Index i = begin2; i < end2; ++i) near2.push_back(i);
    leaves_near(tree1, begin1, end1, union_of(tree2, near2), reach, near1);
    if (near1.empty()) return;
    leaves_near(tree2, begin2, end2, union_of(tree1, near1), reach, near2);
    for (const Index c1 : near1) {
        const Box& box1 = tree1.leaf(c1).box;
        for (const Index c2 : near2)
            if (boxes_meet(box1, tree2.leaf(c2).box, reach)) elements(tree1.leaf(c1).element, tree2.leaf(c2).element);
    }
}
}  // namespace detail

template <class Elements>
inline void bvh_narrow_phase(const CubeTree& tree1, double contact_distance1, const CubeTree& tree2,
                             double contact_distance2, double alarm_distance, NarrowPhaseStack& stack,
                             Elements&& elements) {
    if (tree1.empty() || tree2.empty()) return;
    const double reach = alarm_distance + contact_distance1 + contact_distance2;
    using Entry = NarrowPhaseStack::Entry;
    auto& s = stack.entries;
    s.clear();
    const CubeTree::Cube& root1 = tree1.root();
    const CubeTree::Cube& root2 = tree2.root();
    s.push_back(
        Entry{root1.sub_level, root2.sub_level, root1.sub_begin, root1.sub_end, root2.sub_begin, root2.sub_end});
    while (!s.empty()) {
        const Entry cell = s.back();
        s.pop_back();
        if (cell.level1 == CubeTree::kLeaves && cell.level2 == CubeTree::kLeaves) {
            detail::leaf_blocks(tree1, cell.begin1, cell.end1, tree2, cell.begin2, cell.end2, reach, stack, elements);
            continue;
        }
        for (Index c1 = cell.begin1; c1 < cell.end1; ++c1) {
            const Box& box1 = tree1.box(cell.level1, c1);
            for (Index c2 = cell.begin2; c2 < cell.end2; ++c2) {
                if (!boxes_meet(box1, tree2.box(cell.level2, c2), reach)) continue;
                const bool inner1 = cell.level1 != CubeTree::kLeaves;
                const bool inner2 = cell.level2 != CubeTree::kLeaves;
                if (inner1 && inner2) {
                    const auto& a = tree1.level(cell.level1)[c1];
                    const auto& b = tree2.level(cell.level2)[c2];
                    s.push_back(Entry{a.sub_level, b.sub_level, a.sub_begin, a.sub_end, b.sub_begin, b.sub_end});
                } else if (inner1) {
                    const auto& a = tree1.level(cell.level1)[c1];
                    s.push_back(Entry{a.sub_level, CubeTree::kLeaves, a.sub_begin, a.sub_end, c2, c2 + 1});
                } else if (inner2) {
                    const auto& b = tree2.level(cell.level2)[c2];
                    s.push_back(Entry{CubeTree::kLeaves, b.sub_level, c1, c1 + 1, b.sub_begin, b.sub_end});
                } else {
                    elements(tree1.leaf(c1).element, tree2.leaf(c2).element);
                }
            }
        }
    }
}

}  // namespace sofac::collide
