// The C++ side of tests/collision_shim.py (see there).
#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <new>
#include "sofac/contact.h"
#include "sofac/penalty.h"
using sofac::Index;
using namespace sofac::collide;
#define API extern "C" __attribute__((visibility("default")))

// Heap allocations made by this library, to check that a step allocates nothing.
static std::atomic<long> g_allocations{0};
void* operator new(std::size_t n) {
    ++g_allocations;
    if (void* p = std::malloc(n ? n : 1)) return p;
    throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
API long allocations() { return g_allocations.load(); }

enum Kind { PP, LP, LL, TP, SS, SP, TS, LS, TL, TT };
enum Method { MIN, NEW };

struct Model {
    const double* x; const Index* elements; const int* flags; const double* normals; Index size;
    double cd; const double* radii; Index n_radii; double radius; Index stride;
    PointModel point() const { return PointModel{x, size, cd}; }
    LineModel line() const { return LineModel{x, elements, size, cd}; }
    TriangleModel triangle() const { return TriangleModel{x, elements, flags, normals, size, cd}; }
    SphereModel sphere() const { return SphereModel{x, stride, radii, n_radii, radius, size, cd}; }
};

static int test(int method, int kind, const Model& a, Index e1, const Model& b, Index e2, const Proximity& m,
                int option, OutputList& out) {
    if (method == MIN) {
        switch (kind) {
            case PP: return min_proximity::point_point(m, a.point(), e1, b.point(), e2, out);
            case LP: return min_proximity::line_point(m, a.line(), e1, b.point(), e2, out);
            case LL: return min_proximity::line_line(m, a.line(), e1, b.line(), e2, out);
            case TP: return min_proximity::triangle_point(m, a.triangle(), e1, b.point(), e2, option != 0, out);
            case SS: return min_proximity::sphere_sphere(m, a.sphere(), e1, b.sphere(), e2, out);
            case SP: return min_proximity::sphere_point(m, a.sphere(), e1, b.point(), e2, out);
            case TS: return min_proximity::triangle_sphere(m, a.triangle(), e1, b.sphere(), e2, out);
            case LS: return min_proximity::line_sphere(m, a.line(), e1, b.sphere(), e2, out);
        }
        return -1;
    }
    switch (kind) {
        case PP: return new_proximity::point_point(m, a.point(), e1, b.point(), e2, out);
        case LP: return new_proximity::line_point(m, a.line(), e1, b.point(), e2, out);
        case LL: return new_proximity::line_line(m, a.line(), e1, b.line(), e2, out);
        case TP: return new_proximity::triangle_point(m, a.triangle(), e1, b.point(), e2, out);
        case SS: return new_proximity::sphere_sphere(m, a.sphere(), e1, b.sphere(), e2, out);
        case SP: return new_proximity::sphere_point(m, a.sphere(), e1, b.point(), e2, out);
        case TS: return new_proximity::triangle_sphere(m, a.triangle(), e1, b.sphere(), e2, out);
        case LS: return new_proximity::line_sphere(m, a.line(), e1, b.sphere(), e2, out);
        case TL: return new_proximity::triangle_line(m, a.triangle(), e1, b.line(), e2, option != 0, out);
        case TT: return new_proximity::triangle_triangle(m, a.triangle(), e1, b.triangle(), e2, a.x == b.x, option != 0, out);
    }
    return -1;
}

static Index write(const OutputList& out, double* rows, Index capacity) {
    const Index n = static_cast<Index>(out.size());
    for (Index i = 0; i < n && i < capacity; ++i) {
        const DetectionOutput& o = out[i];
        double* r = rows + 13 * i;
        for (int k = 0; k < 3; ++k) { r[k] = o.point[0][k]; r[3 + k] = o.point[1][k]; r[6 + k] = o.normal[k]; }
        r[9] = o.value; r[10] = double(o.elem1); r[11] = double(o.elem2); r[12] = double(o.id);
    }
    return n;
}

API Index element_test(int method, int kind, const Model* a, Index e1, const Model* b, Index e2, double alarm,
                       double contact, int option, double* rows, Index* counters) {
    OutputList out;
    out.reserve(16);
    test(method, kind, *a, e1, *b, e2, Proximity{alarm, contact}, option, out);
    counters[0] = out.zero_distances;
    counters[1] = out.dropped;
    return write(out, rows, 16);
}

// The model type of either side of a kind: 0 points, 1 lines, 2 triangles, 3 spheres.
static int shape(int kind, int side) {
    if (side == 0) return kind == PP ? 0 : (kind == LP || kind == LL || kind == LS) ? 1 : (kind == SS || kind == SP) ? 3 : 2;
    return (kind == PP || kind == LP || kind == TP || kind == SP) ? 0 : (kind == LL || kind == TL) ? 1 : kind == TT ? 2 : 3;
}

// The tree of one side through the runtime's update_tree (the triangle normals into a scratch array).
static void update(int kind, int side, const Model& m, CubeTree& tree) {
    static std::vector<double> normals(3 * 100000);
    switch (shape(kind, side)) {
        case 0: update_tree(tree, m.point()); break;
        case 1: update_tree(tree, m.line()); break;
        case 2: update_tree(tree, m.triangle(), normals.data()); break;
        default: update_tree(tree, m.sphere()); break;
    }
}

API void triangle_normals(const Model* m, double* normals) {
    CubeTree tree;
    tree.resize(m->size, 2);
    update_tree(tree, m->triangle(), normals);
}

API int self_points(Index index, Index index2, const Index* offsets, const Index* items) {
    return points_can_collide(index, index2, Adjacency{offsets, items});
}

API int self_lines(Index line, Index line2, const Index* edges, const Index* offsets, const Index* items) {
    return lines_can_collide(line, line2, edges, Adjacency{offsets, items});
}

static Box element_box(int kind, int side, const Model& m, Index i) {
    switch (shape(kind, side)) {
        case 0: return point_box(load3(m.x, 3, i), m.cd);
        case 1: return line_box(load3(m.x, 3, m.elements[2 * i]), load3(m.x, 3, m.elements[2 * i + 1]), m.cd);
        case 2: return triangle_box(load3(m.x, 3, m.elements[3 * i]), load3(m.x, 3, m.elements[3 * i + 1]), load3(m.x, 3, m.elements[3 * i + 2]), m.cd);
        default: return sphere_box(load3(m.x, m.stride, i), m.sphere().r(i), m.cd);
    }
}

// One model pair through trees and the narrow phase, `steps` times (the positions scaled by
// `moves[s]` about the origin at step s, to refit a built tree); returns the last step's outputs.
struct Pair {
    CubeTree tree1, tree2;
    NarrowPhaseStack stack;
    OutputList out;
};

API Index detect(int method, int kind, const Model* a, const Model* b, int depth, double alarm, double contact,
                 int option, double* rows, Index capacity, Index* counters) {
    static Pair pair;  // kept across calls, so a second call runs as a later step (refit)
    const bool same = a->x == b->x && a->elements == b->elements;
    if (counters[0] == 0) {  // first call for these models: size everything
        pair.tree1.resize(a->size, depth);
        pair.tree2.resize(b->size, depth);
        pair.out.reserve(static_cast<std::size_t>(capacity));
    }
    const long before = g_allocations.load();
    update(kind, 0, *a, pair.tree1);
    update(kind, 1, *b, pair.tree2);
    if (counters[0] == 0) pair.stack.reserve_for(pair.tree1, pair.tree2);
    const long after_trees = g_allocations.load();
    pair.out.clear();
    const Proximity m{alarm, contact};
    bvh_narrow_phase(pair.tree1, a->cd, pair.tree2, b->cd, alarm, pair.stack, [&](Index e1, Index e2) {
        if (same && kind == TT && e1 == e2) return;
        test(method, kind, *a, e1, *b, e2, m, option, pair.out);
    });
    counters[1] = after_trees - before;
    counters[2] = g_allocations.load() - after_trees;
    counters[3] = pair.out.growths;
    return write(pair.out, rows, capacity);
}

// Every element pair, or (boxes) only those whose leaf boxes meet as the narrow phase tests them.
API Index brute_force(int method, int kind, const Model* a, const Model* b, double alarm, double contact, int option,
                      int boxes, double* rows, Index capacity) {
    OutputList out;
    out.reserve(static_cast<std::size_t>(capacity));
    const bool same = a->x == b->x && a->elements == b->elements;
    for (Index e1 = 0; e1 < a->size; ++e1)
        for (Index e2 = 0; e2 < b->size; ++e2) {
            if (same && kind == TT && e1 == e2) continue;
            if (boxes && !boxes_meet(element_box(kind, 0, *a, e1), element_box(kind, 1, *b, e2), alarm + a->cd + b->cd)) continue;
            test(method, kind, *a, e1, *b, e2, Proximity{alarm, contact}, option, out);
        }
    return write(out, rows, capacity);
}

// The leaf order of a point model's tree and its cubes: level sizes, and per cube its box and range.
API Index point_tree(const double* x, Index n, int depth, double cd, Index* leaf_elements, Index* level_sizes,
                     double* cube_rows) {
    CubeTree tree;
    tree.resize(n, depth);
    for (Index i = 0; i < n; ++i) tree.set_box(i, point_box(load3(x, 3, i), cd));
    tree.update();
    for (Index i = 0; i < n; ++i) leaf_elements[i] = tree.leaf(i).element;
    Index row = 0;
    for (int l = 0; l <= depth; ++l) {
        level_sizes[l] = static_cast<Index>(tree.level(l).size());
        for (const auto& c : tree.level(l)) {
            double* r = cube_rows + 9 * row++;
            for (int k = 0; k < 3; ++k) { r[k] = c.box.min[k]; r[3 + k] = c.box.max[k]; }
            r[6] = c.sub_level; r[7] = double(c.sub_begin); r[8] = double(c.sub_end);
        }
    }
    return row;
}

API void flags(const Index* triangles, Index n, Index n_points, int* out) { triangle_flags(triangles, n, n_points, out); }

// Point models with one box each (`boxes`: n x 6), broad phase with the rule table.
API Index broad_phase(const double* boxes, const double* cds, Index n, const std::int8_t* rule, double alarm,
                      Index* pairs) {
    std::vector<CubeTree> trees(static_cast<std::size_t>(n));
    std::vector<BroadPhaseModel> models;
    for (Index i = 0; i < n; ++i) {
        const double* b = boxes + 6 * i;
        trees[i].resize(1, 0);
        trees[i].set_box(0, Box{V3{{b[0], b[1], b[2]}}, V3{{b[3], b[4], b[5]}}});
        trees[i].update();
        models.push_back(BroadPhaseModel{&trees[i], cds[i]});
    }
    return brute_force_broad_phase(models.data(), n, rule, alarm, pairs);
}

// Penalty contacts: n contacts on states of n1 / n2 points; then forces, energy, df for dx.
API double penalty(Index n, const Index* m, const double* normals, const double* dist, const double* ks,
                   const double* x1, const double* x2, double* f1, double* f2, const double* dx1, const double* dx2,
                   double* df1, double* df2, double k_factor, double* pen, double* matrix, Index n1, Index n2) {
    PenaltyContactForceField ff;
    ff.reserve(static_cast<std::size_t>(n));
    for (Index c = 0; c < n; ++c)
        ff.add_contact(m[2 * c], m[2 * c + 1], 0, 0, load3(normals, 3, c), dist[c], ks[c]);
    ff.add_force(f1, f2, x1, x2);
    ff.add_dforce(df1, df2, dx1, dx2, k_factor);
    const Index size = 3 * (n1 + n2);
    ff.add_k(k_factor, [&](int s1, Index r, int s2, Index col, double v) {
        matrix[(s1 * 3 * n1 + r) * size + s2 * 3 * n1 + col] += v;
    });
    for (Index c = 0; c < n; ++c) pen[c] = ff.contacts[c].pen;
    return ff.energy();
}

// De-duplication then contacts of a Triangle (side 1) / Point (side 2) pair from given outputs.
API Index penalty_from_outputs(const double* rows, Index n, Index id_bound, const double* tri_x,
                               const Index* triangles, double cd1, double k1, const double* point_x, double cd2,
                               double k2, double contact_distance, Index* contact_rows, double* contact_values,
                               double* mapped) {
    OutputList out;
    out.reserve(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) {
        const double* r = rows + 13 * i;
        DetectionOutput o;
        for (int k = 0; k < 3; ++k) { o.point[0][k] = r[k]; o.point[1][k] = r[3 + k]; o.normal[k] = r[6 + k]; }
        o.value = r[9]; o.elem1 = Index(r[10]); o.elem2 = Index(r[11]); o.id = Index(r[12]);
        out.push(o);
    }
    ContactDeduplication dedup;
    dedup.resize(id_bound, static_cast<std::size_t>(n));
    dedup.run(out);
    BarycentricContactPoints points;
    points.reserve(static_cast<std::size_t>(n));
    PenaltyContactForceField ff;
    ff.reserve(static_cast<std::size_t>(n));
    const ContactSideModel side1{ContactSide::kTriangle, tri_x, triangles, nullptr, cd1, k1, &points};
    const ContactSideModel side2{ContactSide::kPoint, point_x, nullptr, nullptr, cd2, k2, nullptr};
    set_penalty_contacts(out, dedup, contact_distance, side1, side2, ff);
    points.apply(tri_x, mapped);
    for (std::size_t c = 0; c < ff.contacts.size(); ++c) {
        const PenaltyContact& p = ff.contacts[c];
        contact_rows[4 * c] = p.m1; contact_rows[4 * c + 1] = p.m2;
        contact_rows[4 * c + 2] = p.element1; contact_rows[4 * c + 3] = p.element2;
        contact_values[2 * c] = p.dist; contact_values[2 * c + 1] = p.ks;
    }
    return static_cast<Index>(ff.contacts.size());
}

// Barycentric contact points: coordinates by apply, and apply_jt of unit forces (J^T).
API void barycentric(const double* x, const Index* triangles, const Index* edges, const double* P, const Index* element,
                     const int* in_line, Index n, double* mapped, const double* f, double* jt) {
    BarycentricContactPoints points;
    for (Index i = 0; i < n; ++i) {
        if (in_line[i]) points.add_in_line(load3(P, 3, i), element[i], x, edges);
        else points.add_in_triangle(load3(P, 3, i), element[i], x, triangles);
    }
    points.apply(x, mapped);
    points.apply_jt(f, jt);
}

// Adjacency lists (ascending) of a mesh, built here for the LocalMinDistance cones.
struct Lists {
    std::vector<Index> offsets, items;
    Adjacency view() const { return Adjacency{offsets.data(), items.data()}; }
};

static Lists group(Index n, const std::vector<std::pair<Index, Index>>& pairs) {  // (owner, item) sorted
    Lists l;
    l.offsets.assign(static_cast<std::size_t>(n + 1), 0);
    for (const auto& p : pairs) ++l.offsets[p.first + 1];
    for (Index i = 0; i < n; ++i) l.offsets[i + 1] += l.offsets[i];
    for (const auto& p : pairs) l.items.push_back(p.second);
    return l;
}

static Lists around_vertices(Index n_points, const Index* elements, Index n, int per) {
    std::vector<std::pair<Index, Index>> pairs;
    for (Index e = 0; e < n; ++e)
        for (int k = 0; k < per; ++k) pairs.emplace_back(elements[per * e + k], e);
    std::sort(pairs.begin(), pairs.end());
    return group(n_points, pairs);
}

static Lists around_edges(const Index* edges, Index n_edges, const Index* triangles, Index n_triangles) {
    std::vector<std::pair<Index, Index>> pairs;
    for (Index e = 0; e < n_edges; ++e)
        for (Index t = 0; t < n_triangles; ++t) {
            int shared = 0;
            for (int k = 0; k < 3; ++k) shared += triangles[3 * t + k] == edges[2 * e] || triangles[3 * t + k] == edges[2 * e + 1];
            if (shared == 2) pairs.emplace_back(e, t);
        }
    return group(n_edges, pairs);
}

// One LocalMinDistance element test; the cones asked for (use_cones: 1 points, 2 lines) read the
// mesh given, as the point model's and the line model's topology.
API Index lmd_test(int kind, const Model* a, Index e1, const Model* b, Index e2, double alarm, double contact,
                   int filter, double angle_cone, double cone_factor, int both_side, const double* mesh_x,
                   const Index* mesh_triangles, Index n_triangles, const Index* mesh_edges, Index n_edges,
                   Index n_points, int use_cones, double* rows, Index* counters) {
    namespace lmd = local_min_distance;
    const lmd::Options o{filter != 0, angle_cone, cone_factor, false};
    const Lists tav = around_vertices(n_points, mesh_triangles, n_triangles, 3);
    const Lists eav = around_vertices(n_points, mesh_edges, n_edges, 2);
    const Lists tae = around_edges(mesh_edges, n_edges, mesh_triangles, n_triangles);
    const lmd::PointCone point_cone{mesh_x, mesh_triangles, mesh_edges, tav.view(), eav.view(), both_side != 0};
    const lmd::LineCone line_cone{mesh_x, mesh_triangles, tae.view(), both_side != 0};
    const lmd::PointCone* pc = (use_cones & 1) ? &point_cone : nullptr;
    const lmd::LineCone* lc = (use_cones & 2) ? &line_cone : nullptr;
    const Proximity m{alarm, contact};
    OutputList out;
    out.reserve(4);
    switch (kind) {
        case PP: lmd::point_point(m, o, a->point(), e1, pc, b->point(), e2, pc, out); break;
        case LP: lmd::line_point(m, o, a->line(), e1, lc, b->point(), e2, pc, out); break;
        case LL: lmd::line_line(m, o, a->line(), e1, lc, b->line(), e2, lc, out); break;
        case TP: lmd::triangle_point(m, o, a->triangle(), e1, both_side != 0, b->point(), e2, pc, out); break;
        case SS: lmd::sphere_sphere(m, a->sphere(), e1, b->sphere(), e2, out); break;
        case SP: lmd::sphere_point(m, o, a->sphere(), e1, b->point(), e2, pc, out); break;
        case TS: lmd::triangle_sphere(m, o, a->triangle(), e1, both_side != 0, b->sphere(), e2, out); break;
        case LS: lmd::line_sphere(m, o, a->line(), e1, lc, b->sphere(), e2, out); break;
        default: return -1;
    }
    counters[0] = out.zero_distances;
    counters[1] = out.dropped;
    return write(out, rows, 4);
}

// ---------------------------------------------------------------------------------------------
// Contact order: SOFA's map operations over a scripted sequence of steps, with the runtime's
// StablePairMap or with a std::map whose comparator is SOFA's expression as written (operand
// order left to g++). Each step lists its broad-phase pairs and whether each found contacts;
// the output map's and the contact map's orders after each step are written out.
#include "sofac/contact_order.h"

struct SofaExpressionCompare {
    StableIds* ids;
    bool operator()(const ModelPair& a, const ModelPair& b) const {
        return std::make_pair(ids->id(b.first), ids->id(b.second)) > std::make_pair(ids->id(a.first), ids->id(a.second));
    }
};

template <class OutputMap, class ContactMap>
static Index run_order(OutputMap& outputs, ContactMap& contacts, const Index* pairs, const int* found,
                       const Index* step_sizes, Index n_steps, Index* orders) {
    Index written = 0, at = 0;
    for (Index s = 0; s < n_steps; ++s) {
        for (auto& entry : outputs) entry.second = 0;  // beginNarrowPhase: outputs cleared, entries kept
        for (Index k = 0; k < step_sizes[s]; ++k, ++at) {
            auto slot = output_slot(outputs, pairs[2 * at], pairs[2 * at + 1]);
            slot->second = found[at];
        }
        erase_empty(outputs, [](int n) { return n == 0; });
        for (const auto& entry : outputs) contact_slot(contacts, entry.first);
        remove_inactive(contacts, outputs, [](int) {});
        for (const auto& entry : outputs) { orders[written++] = entry.first.first; orders[written++] = entry.first.second; }
        orders[written++] = -1;
        for (const auto& entry : contacts) { orders[written++] = entry.first.first; orders[written++] = entry.first.second; }
        orders[written++] = -2;
    }
    return written;
}

API Index contact_order(int sofa_expression, Index n_models, const Index* pairs, const int* found,
                        const Index* step_sizes, Index n_steps, Index* orders, Index* allocations) {
    if (sofa_expression) {
        StableIds ids1, ids2;
        ids1.resize(n_models);
        ids2.resize(n_models);
        std::map<ModelPair, int, SofaExpressionCompare> outputs(SofaExpressionCompare{&ids1});
        std::map<ModelPair, int, SofaExpressionCompare> contacts(SofaExpressionCompare{&ids2});
        return run_order(outputs, contacts, pairs, found, step_sizes, n_steps, orders);
    }
    StablePairMap<int> outputs, contacts;
    outputs.reserve(n_models, static_cast<std::size_t>(n_models * n_models));
    contacts.reserve(n_models, static_cast<std::size_t>(n_models * n_models));
    const long before = g_allocations.load();
    const Index n = run_order(outputs.map(), contacts.map(), pairs, found, step_sizes, n_steps, orders);
    allocations[0] = g_allocations.load() - before;
    allocations[1] = outputs.growths() + contacts.growths();
    return n;
}

// SelfCollisionFilter `rule` on every element pair (e1 < n1, e2 < n2): mask[e1 * n2 + e2].
API void self_filter(int rule, Index n1, Index n2, const Index* cells, const Index* offsets, const Index* items,
                     char* mask) {
    const SelfCollisionFilter filter{static_cast<SelfCollisionFilter::Rule>(rule), cells, Adjacency{offsets, items}};
    for (Index e1 = 0; e1 < n1; ++e1)
        for (Index e2 = 0; e2 < n2; ++e2) mask[e1 * n2 + e2] = filter(e1, e2) ? 1 : 0;
}

// Two models of one node (b may be a itself: kind LL or TT on one model; TP, LP on the points of
// a's state) through their trees and the narrow phase, each element pair first through
// SelfCollisionFilter `rule` (a's cells, its edgesAroundVertex for the line rules), as BVHNarrowPhase
// asks canCollideWith; or (brute) every element pair through the same filter.
API Index self_detect(int method, int kind, const Model* a, const Model* b, int rule, const Index* offsets,
                      const Index* items, int depth, double alarm, double contact, int option, int brute,
                      double* rows, Index capacity) {
    const SelfCollisionFilter filter{static_cast<SelfCollisionFilter::Rule>(rule), a->elements, Adjacency{offsets, items}};
    CubeTree tree1, tree2;
    tree1.resize(a->size, depth);
    tree2.resize(b->size, depth);
    update(kind, 0, *a, tree1);
    update(kind, 1, *b, tree2);
    NarrowPhaseStack stack;
    stack.reserve_for(tree1, tree2);
    OutputList out;
    out.reserve(static_cast<std::size_t>(capacity));
    const Proximity prox{alarm, contact};
    auto elements = [&](Index e1, Index e2) {
        if (filter(e1, e2)) test(method, kind, *a, e1, *b, e2, prox, option, out);
    };
    if (brute) {
        for (Index e1 = 0; e1 < a->size; ++e1)
            for (Index e2 = 0; e2 < b->size; ++e2) elements(e1, e2);
    } else {
        bvh_narrow_phase(tree1, a->cd, tree2, b->cd, alarm, stack, elements);
    }
    return write(out, rows, capacity);
}

// The tree's structure is that of its first update: refit with other positions keeps the leaf
// order (leaf_refit), a fresh tree on those positions sorts them anew (leaf_fresh).
API int tree_structure(const double* x0, const double* x1, Index n, int depth, Index* leaf_refit, Index* leaf_fresh,
                       double* root_refit) {
    CubeTree kept, fresh;
    kept.resize(n, depth);
    fresh.resize(n, depth);
    const int before = kept.built();
    update_tree(kept, PointModel{x0, n, 0.0});
    update_tree(kept, PointModel{x1, n, 0.0});
    update_tree(fresh, PointModel{x1, n, 0.0});
    for (Index i = 0; i < n; ++i) {
        leaf_refit[i] = kept.leaf(i).element;
        leaf_fresh[i] = fresh.leaf(i).element;
    }
    for (int k = 0; k < 3; ++k) {
        root_refit[k] = kept.root().box.min[k];
        root_refit[3 + k] = kept.root().box.max[k];
    }
    return before == 0 && kept.built() ? 1 : 0;
}

// Points dropped on a static two-triangle floor (NewProximity triangle-point, penalty response), a
// damped symplectic Euler loop written here: detection, de-duplication, contact points, force. The
// points' final heights, and the heap allocations of the steps after the first.
API long drop_points(double* x, Index n, Index steps, double dt, double mass, double damping, double k_floor,
                     double k_points, double alarm, double contact, Index* contact_counts) {
    static const double floor_x[] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
    static const Index floor_triangles[] = {0, 1, 2, 0, 2, 3};
    int flags[2];
    triangle_flags(floor_triangles, 2, 4, flags);
    const TriangleModel floor{floor_x, floor_triangles, flags, nullptr, 2, 0.0};
    const PointModel cloud{x, n, 0.0};
    CubeTree floor_tree, cloud_tree;
    floor_tree.resize(2, 6);
    cloud_tree.resize(n, 6);
    update_tree(floor_tree, floor, nullptr);  // static: once
    update_tree(cloud_tree, cloud);
    NarrowPhaseStack stack;
    stack.reserve_for(floor_tree, cloud_tree);
    OutputList outputs;
    outputs.reserve(static_cast<std::size_t>(4 * n));
    ContactDeduplication dedup;
    dedup.resize(n, static_cast<std::size_t>(4 * n));
    BarycentricContactPoints floor_points;
    floor_points.reserve(static_cast<std::size_t>(4 * n));
    PenaltyContactForceField ff;
    ff.reserve(static_cast<std::size_t>(4 * n));
    std::vector<double> v(static_cast<std::size_t>(3 * n), 0.0), f(static_cast<std::size_t>(3 * n));
    std::vector<double> x1(static_cast<std::size_t>(12 * n)), f1(static_cast<std::size_t>(12 * n));
    const ContactSideModel side1{ContactSide::kTriangle, floor_x, floor_triangles, nullptr, 0.0, k_floor, &floor_points};
    const ContactSideModel side2{ContactSide::kPoint, x, nullptr, nullptr, 0.0, k_points, nullptr};
    const Proximity prox{alarm, contact};
    long allocations = 0;
    for (Index s = 0; s < steps; ++s) {
        const long before = g_allocations.load();
        update_tree(cloud_tree, cloud);
        outputs.clear();
        bvh_narrow_phase(floor_tree, 0.0, cloud_tree, 0.0, alarm, stack, [&](Index t, Index p) {
            new_proximity::triangle_point(prox, floor, t, cloud, p, outputs);
        });
        dedup.run(outputs);
        set_penalty_contacts(outputs, dedup, contact, side1, side2, ff);
        floor_points.apply(floor_x, x1.data());
        std::fill(f.begin(), f.end(), 0.0);
        ff.add_force(f1.data(), f.data(), x1.data(), x);
        for (Index i = 0; i < n; ++i) {
            f[3 * i + 2] -= mass * 9.81;
            for (int k = 0; k < 3; ++k) {
                v[3 * i + k] += dt * (f[3 * i + k] - damping * v[3 * i + k]) / mass;
                x[3 * i + k] += dt * v[3 * i + k];
            }
        }
        contact_counts[s] = static_cast<Index>(ff.contacts.size());
        if (s > 0) allocations += g_allocations.load() - before;
    }
    return allocations;
}

// PenaltyContacts (penalty.h) on a static two-triangle floor at y = 0 (model 0) and one moving model
// `b` of `kind`'s second side (model 1) over `steps` positions (xs: steps x n_points x 3), as the
// generated step runs it: with (pretest = 1) or without the per-step pre-test. Per step: whether
// the detection was skipped, the pair's outputs, the contacts and their energy; with the pre-test,
// `mismatches` counts the steps whose root box from the points differs (bit for bit) from that of
// the moving model's tree refitted on the same points. Returns the fast motions counted.
API Index pretest_run(int kind, const Model* b, Index n_points, const double* xs, Index steps, int pretest,
                      double alarm, double contact, double floor_cd, Index* skipped, Index* outputs,
                      Index* contacts, double* energy, Index* mismatches) {
    static const double floor_x[] = {-1, 0, -1, 1, 0, -1, 1, 0, 1, -1, 0, 1};
    static const Index floor_triangles[] = {0, 2, 1, 0, 3, 2};
    static int floor_flags[2];
    triangle_flags(floor_triangles, 2, 4, floor_flags);
    const Model floor{floor_x, floor_triangles, floor_flags, nullptr, 2, floor_cd, nullptr, 0, 1.0, 3};
    std::vector<double> x(xs, xs + 3 * n_points);
    Model moving = *b;
    moving.x = x.data();
    const int side = shape(kind, 1);
    PenaltyContacts C;
    C.resize(2, alarm, contact, 6);
    C.models[0].kind = ContactSide::kTriangle;
    C.models[0].points = 4;
    C.models[0].elements = 2;
    C.models[0].cells = floor_triangles;
    C.models[0].contact_distance = floor_cd;
    C.models[0].contact_stiffness = 10.0;
    C.models[0].moving = false;
    C.models[0].flags.assign(floor_flags, floor_flags + 2);
    const ContactSide kinds[] = {ContactSide::kPoint, ContactSide::kLine, ContactSide::kTriangle, ContactSide::kSphere};
    PenaltyModel& m = C.models[1];
    m.kind = kinds[side];
    m.points = n_points;
    m.elements = b->size;
    m.cells = side == 1 || side == 2 ? b->elements : nullptr;
    m.contact_distance = b->cd;
    m.contact_stiffness = 10.0;
    if (side == 3) m.sphere = SphereModel{nullptr, 3, b->radii, b->n_radii, b->radius, b->size, b->cd};
    if (side == 2) {
        m.flags.resize(static_cast<std::size_t>(b->size));
        triangle_flags(b->elements, b->size, n_points, m.flags.data());
    }
    C.add_pair(0, 1, false, std::max<Index>(n_points, 4), 0, 0, 0);
    C.finish_setup();
    const Proximity method{alarm, contact};
    *mismatches = 0;
    for (Index s = 0; s < steps; ++s) {
        std::copy(xs + 3 * n_points * s, xs + 3 * n_points * (s + 1), x.begin());
        const double* const positions[] = {floor_x, x.data()};
        if (pretest) C.begin_detection(positions);
        if (C.needs_update(0)) update(TP, 0, floor, C.models[0].tree);
        if (C.needs_update(1)) update(kind, 1, moving, C.models[1].tree);
        C.detect([&](Index pair) {
            C.narrow_phase(C.pairs[pair], [&](Index e1, Index e2, OutputList& out) {
                test(NEW, kind, floor, e1, moving, e2, method, 0, out);
            });
        });
        C.respond(positions);
        skipped[s] = C.skipped() ? 1 : 0;
        outputs[s] = static_cast<Index>(C.pairs[0].outputs.size());
        contacts[s] = C.contact_count();
        energy[s] = C.energy();
        if (pretest && s > 0) {  // the tree refitted on these points (a copy: the run keeps its own)
            CubeTree refitted = C.models[1].tree;
            update(kind, 1, moving, refitted);
            if (std::memcmp(&refitted.root().box, &m.root, sizeof(Box)) != 0) ++*mismatches;
        }
    }
    return C.fast_motions();
}
