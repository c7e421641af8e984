// Penalty contact between the collision models of a DefaultAnimationLoop scene, as SOFA's pipeline
// runs it each step (SubCollisionPipeline: bounding trees, BruteForceBroadPhase, BVHNarrowPhase;
// CollisionResponse with BarycentricPenalityContact + PenalityContactForceField):
//
//   detect():  the trees of the models (static ones once), the broad phase over the compile-time
//              pair table, the narrow phase of each pair it finds (the element test is the caller's:
//              code generation instantiates only the (method, type pair) tests the scene has);
//   respond(): SOFA's two stable-id maps decide the order of the contacts; each pair's outputs are
//              de-duplicated and become penalty contacts on contact points (barycentric points
//              on triangles and lines, points fixed in the frames of Rigid3d spheres, the model's
//              own points on point and Vec3d sphere models); pairs of two simulated models get
//              their force now, once, at the start of the step when no solver integrates the
//              pipeline's node (SOFA evaluates them there, before any solver: explicit coupling);
//   add_force() / add_dforce(): in each force evaluation and each K dx product of the group that
//              integrates a model, the contacts with a static model (placed in that group) are
//              evaluated, and every contact point's force is mapped onto the model's points in the
//              order SOFA creates the contact-point nodes under the model's node;
//   add_group_force() / add_group_dforce(): pairs of two simulated models when a solver integrates
//              the pipeline's node (SOFA places them there: inside that solver's group, implicit),
//              in every force evaluation and K dx product of that group, in SOFA's contact order.
//
// Memory: every buffer is reserved at init for the pair's element counts; a step that needs more
// grows them (counted in growths(), never an overrun) and keeps the larger capacity.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "contact.h"
#include "contact_order.h"

namespace sofac::collide {

// One collision model of the pipeline, in SOFA's order (depth-first below the pipeline's node).
struct PenaltyModel {
    ContactSide kind = ContactSide::kPoint;
    Index points = 0;             // points of its state
    Index elements = 0;           // triangles, edges, points or spheres
    const Index* cells = nullptr; // triangles (3 per) or edges (2 per)
    double contact_distance = 0.0;
    double contact_stiffness = 0.0;
    bool moving = true;  // its boxes follow its points (moving="0": computed once, at the first step)
    bool rigid = false;  // sphere models on Rigid3d frames: contact points mapped rigidly (RigidContactPoints)
    CubeTree tree;
    std::vector<int> flags;       // triangle models: SOFA's vertex / edge ownership flags
    std::vector<double> normals;  // triangle models: the normals of the last tree update
    std::vector<double> external; // point / sphere models: the explicit contact forces of this step
    SphereModel sphere{};         // sphere models: the radii (the response reads them)
    Box root{};                   // this step's root box, from the points (the pre-test)
    Index lazy = -1;              // its points' LazyPoints, if they are mapped only when near
    std::vector<Index> used;      // triangle / line models: the points their elements use, if not all
    Box last_root{};              // the root box of the previous detection
    Box swept{};                  // the union of that box and this step's
    double motion = 0.0;          // how far a side of its root box moved since then
    // Contact-point states under this model's node, in creation order: 2 * pair + side.
    std::vector<Index> children;
    std::vector<double> element_k;  // add_k's blocks, element by element
};

// The points of collision models that nothing but their contacts reads, output of a linear mapping
// (each point a weighted sum of parent points, compiler/plan/contacts.py): the step maps them only
// while one of their models is in contact, the detection only when a pair may meet (skip_unmapped).
struct LazyPoints {
    const double* parent = nullptr;  // the parent's positions
    Index parent_points = 0;
    // Every mapped point lies in the parent's box grown on each axis by spread x its extent (the
    // weights' negative parts) + rounding x its largest |coordinate| (weights summing to 1 only up
    // to rounding, and the sums' own rounding), both from the weights at compile time.
    double spread = 0.0, rounding = 0.0;
    double* saved = nullptr;     // the parent's positions at the last detection that did not map them
    bool unmapped = false;       // that was the last detection: its models' last_root are enclosures
    bool current = false;        // this detection: mapped at the end of the last step (in contact)
    Box enclosure{};             // this detection's enclosure of the points
    std::vector<Index> models;   // the pipeline's models on these points
};

// One model pair the broad phase can produce (the compile-time table), with its response.
struct PenaltyPair {
    Index model[2] = {0, 0};  // in the intersector's order
    // The compiled element test (code generation numbers the (method, kinds) tests the scene
    // has) and the two models' places among the models of their kind.
    Index test = 0;
    Index view[2] = {0, 0};
    bool root = false;     // both simulated, no solver integrates the pipeline's node: once, at the step's start
    bool grouped = false;  // both simulated, in the group of the solver integrating the pipeline's node
    bool respond = true;       // false: the models' contactResponse is "nullptr" (SOFA drops the contact)
    SelfCollisionFilter filter;  // models of one node (the narrow phase's test case applies it)
    bool one_node = false;       // models of one node, one state: the motion watch skips the pair
    OutputList outputs;
    NarrowPhaseStack stack;
    ContactDeduplication dedup;
    BarycentricContactPoints points[2];
    RigidContactPoints rigid[2];
    std::vector<double> x[2], f[2], dx[2], df[2];  // the contact-point states (barycentric sides)
    PenaltyContactForceField ff;
    bool live = false;  // SOFA's contact object exists (from its first outputs to its last)
};

class PenaltyContacts {
public:
    // `n` models, `rule` the broad phase's n x n table (PairRule), `pair_of` the index of each
    // (first, second) ordered pair in `pairs` (n x n, -1: none).
    void resize(Index n, double alarm_distance, double contact_distance, int depth) {
        models.resize(static_cast<std::size_t>(n));
        rule.assign(static_cast<std::size_t>(n * n), static_cast<std::int8_t>(kNever));
        pair_of.assign(static_cast<std::size_t>(n * n), -1);
        alarm_distance_ = alarm_distance;
        contact_distance_ = contact_distance;
        depth_ = depth;
    }

    // Where a pair's response goes (the pair table's placement column).
    enum Placement : int { kStaticPartner = 0, kExplicit = 1, kInGroup = 2 };

    // A possible pair; `id_bound` bounds its outputs' ids (the dedup's table).
    Index add_pair(Index first, Index second, Index placement, Index id_bound, Index test, Index view1, Index view2) {
        PenaltyPair& p = pairs.emplace_back();
        p.model[0] = first;
        p.model[1] = second;
        p.root = placement == kExplicit;
        p.grouped = placement == kInGroup;
        p.test = test;
        p.view[0] = view1;
        p.view[1] = view2;
        const Index n = static_cast<Index>(models.size());
        const Index index = static_cast<Index>(pairs.size()) - 1;
        pair_of[first * n + second] = index;
        if (first > second)
            rule[first * n + second] = kKeep;
        else if (first < second)
            rule[second * n + first] = kSwap;
        else
            rule[first * n + first] = kKeep;
        const std::size_t capacity = static_cast<std::size_t>(std::max(models[first].elements, models[second].elements));
        p.outputs.reserve(4 * capacity);
        p.dedup.resize(id_bound, 4 * capacity);
        p.ff.reserve(4 * capacity);
        for (int s = 0; s < 2; ++s) {
            p.points[s].reserve(4 * capacity);
            p.rigid[s].reserve(4 * capacity);
            for (auto* v : {&p.x[s], &p.f[s], &p.dx[s], &p.df[s]}) v->reserve(12 * capacity);
        }
        return index;
    }

    // After the models and pairs: trees sized, maps' pools filled.
    void finish_setup() {
        const Index n = static_cast<Index>(models.size());
        broad_.resize(models.size());
        static_x_.assign(models.size(), nullptr);
        live_pairs_.assign(models.size(), 0);
        broad_pairs_.assign(static_cast<std::size_t>(n * (n + 1)), 0);
        for (std::size_t i = 0; i < models.size(); ++i) {
            PenaltyModel& m = models[i];
            m.tree.resize(m.elements, depth_);
            if (m.kind == ContactSide::kTriangle) m.normals.assign(static_cast<std::size_t>(3 * m.elements), 0.0);
            // point / sphere models of a pair of two simulated models: their explicit contact forces
            // (nothing writes them otherwise, and add_force adds them only when they exist)
            const bool explicit_forces = std::any_of(pairs.begin(), pairs.end(), [&](const PenaltyPair& p) {
                return p.root && (p.model[0] == static_cast<Index>(i) || p.model[1] == static_cast<Index>(i));
            });
            if (explicit_forces && (m.kind == ContactSide::kPoint || (m.kind == ContactSide::kSphere && !m.rigid)))
                m.external.assign(static_cast<std::size_t>(3 * m.points), 0.0);
            m.children.reserve(2 * pairs.size());
            broad_[i] = BroadPhaseModel{&m.tree, m.contact_distance};
            if (m.kind == ContactSide::kTriangle || m.kind == ContactSide::kLine) {
                const int width = element_width(m);
                std::vector<char> seen(static_cast<std::size_t>(m.points), 0);
                for (Index k = 0; k < width * m.elements; ++k) seen[static_cast<std::size_t>(m.cells[k])] = 1;
                for (Index k = 0; k < m.points; ++k)
                    if (seen[static_cast<std::size_t>(k)]) m.used.push_back(k);
                if (static_cast<Index>(m.used.size()) == m.points) m.used.clear();  // all of them
            }
        }
        outputs_map_.reserve(n, pairs.size());
        contacts_map_.reserve(n, pairs.size());
    }

    // Before the trees' updates of a step: whether any pair of the table can meet this step. After
    // the first detection (which builds every tree from its boxes, as SOFA does), each moving
    // model's root box is taken straight from its points `x[m]` (min / max over the points its
    // elements use, grown as its leaf boxes are: the numbers the refitted root would hold, min and
    // max being exact and monotone in the growth), a static model's from its frozen tree. When no
    // pair's boxes meet at the broad phase's reach, the leaf boxes, the refit, the broad and the
    // narrow phases are skipped: detect() then finds nothing, as the broad phase would have. A NaN
    // among the points runs the full detection (the tree's boxes then depend on element order).
    void begin_detection(const double* const* x) {
        skip_ = false;
        if (!stacks_reserved_) return;  // the first detection builds the trees
        bool finite = true;
        for (std::size_t i = 0; i < models.size(); ++i) {
            PenaltyModel& m = models[i];
            if (!m.tree.built() || m.tree.empty()) continue;
            if (!m.moving) {
                m.root = m.tree.root().box;
                continue;
            }
            finite = finite && points_box(m, x[i], m.root);
        }
        if (!finite) return;
        const Index n = static_cast<Index>(models.size());
        for (const PenaltyPair& p : pairs) {
            const Index i = std::max(p.model[0], p.model[1]), j = std::min(p.model[0], p.model[1]);
            const PenaltyModel& a = models[i];
            const PenaltyModel& b = models[j];
            if (a.tree.empty() || b.tree.empty()) continue;  // the broad phase skips empty models
            if (i == j) return;                            // a root box always meets itself
            if (rule[i * n + j] == kNever) continue;
            const double reach = alarm_distance_ + a.contact_distance + b.contact_distance;
            if (boxes_meet(a.root, b.root, reach)) return;
        }
        skip_ = true;
    }

    // Whether the pre-test of this step skipped the detection (no pair can meet).
    bool skipped() const { return skip_; }

    // Lazily mapped points (LazyPoints) from `parent` (`parent_points` points); `saved` holds as
    // many. Their models follow with set_lazy.
    Index add_lazy_points(const double* parent, Index parent_points, double spread, double rounding, double* saved) {
        LazyPoints& l = lazy.emplace_back();
        l.parent = parent;
        l.parent_points = parent_points;
        l.spread = spread;
        l.rounding = rounding;
        l.saved = saved;
        return static_cast<Index>(lazy.size()) - 1;
    }
    void set_lazy(Index model, Index points) {
        models[model].lazy = points;
        lazy[points].models.push_back(model);
    }

    // Before begin_detection, with lazily mapped points: whether this step's detection is skipped
    // without mapping them. Each model gets its root box as begin_detection makes it, except the
    // models on lazy points not mapped since their parent last moved (none of their models in
    // contact), which get an enclosure: the parent's box grown by the points' spread and rounding,
    // then by the model's contact distance, holding every box the mapped points would give. When
    // no pair of the table meets at the broad phase's reach, nor (after a first detection) any
    // pair's swept boxes (this box and the last detection's, as the motion watch makes them), the
    // exact pre-test would have skipped the detection and counted no fast motion: it is skipped the
    // same way, and the parents' positions kept (`saved`) for the next detection's motion watch.
    // Otherwise nothing is decided: the caller maps the points (after restore_roots when the last
    // detection left them unmapped) and runs begin_detection, the same detection as without laziness.
    bool skip_unmapped(const double* const* x) {
        if (!stacks_reserved_) return false;  // the first detection builds the trees
        for (std::size_t k = 0; k < lazy.size(); ++k) {
            LazyPoints& l = lazy[k];
            l.current = lazy_current(static_cast<Index>(k));
            if (!l.current && !enclose(l)) return false;
        }
        for (std::size_t i = 0; i < models.size(); ++i) {
            PenaltyModel& m = models[i];
            if (!m.tree.built() || m.tree.empty()) continue;
            if (!m.moving) {
                m.root = m.tree.root().box;
            } else if (m.lazy >= 0 && !lazy[static_cast<std::size_t>(m.lazy)].current) {
                const Box& e = lazy[static_cast<std::size_t>(m.lazy)].enclosure;
                for (int c = 0; c < 3; ++c) {
                    m.root.min[c] = e.min[c] - m.contact_distance;
                    m.root.max[c] = e.max[c] + m.contact_distance;
                }
            } else if (!points_box(m, x[i], m.root)) {
                return false;
            }
        }
        const Index n = static_cast<Index>(models.size());
        for (const PenaltyPair& p : pairs) {
            const Index i = std::max(p.model[0], p.model[1]), j = std::min(p.model[0], p.model[1]);
            const PenaltyModel& a = models[i];
            const PenaltyModel& b = models[j];
            if (a.tree.empty() || b.tree.empty()) continue;
            if (i == j) return false;  // a root box always meets itself
            const double reach = alarm_distance_ + a.contact_distance + b.contact_distance;
            if (rule[i * n + j] != kNever && boxes_meet(a.root, b.root, reach)) return false;
            if (watching_ && boxes_meet(union_of(a.root, a.last_root), union_of(b.root, b.last_root), reach))
                return false;
        }
        for (LazyPoints& l : lazy) {
            if (l.current) continue;
            std::copy(l.parent, l.parent + 3 * l.parent_points, l.saved);
            l.unmapped = true;
        }
        skip_ = true;
        ++unmapped_detections_;
        return true;
    }

    // Whether lazy points are mapped already: at the end of the last step, as the step maps them
    // while one of their models is in contact.
    bool lazy_current(Index points) const {
        for (const Index model : lazy[static_cast<std::size_t>(points)].models)
            if (in_contact(model)) return true;
        return false;
    }

    // Whether the last detection left lazy points unmapped; restore_roots then gives their models
    // the root boxes that detection would have made, from the points mapped from `saved` (`x`).
    bool unmapped_before(Index points) const { return lazy[static_cast<std::size_t>(points)].unmapped; }
    void restore_roots(Index points, const double* const* x) {
        LazyPoints& l = lazy[static_cast<std::size_t>(points)];
        for (const Index i : l.models) {
            PenaltyModel& m = models[static_cast<std::size_t>(i)];
            if (m.tree.built() && !m.tree.empty() && m.moving) points_box(m, x[i], m.last_root);
        }
        l.unmapped = false;
    }

    // A model's tree on its current points (`update` builds it from the view the caller made).
    bool needs_update(Index model) const {
        return !skip_ && (models[model].moving || !models[model].tree.built());
    }

    // BVHNarrowPhase on one pair: `test(e1, e2, outputs)` is its element test.
    template <class Test>
    void narrow_phase(PenaltyPair& p, Test&& test) {
        const PenaltyModel& a = models[p.model[0]];
        const PenaltyModel& b = models[p.model[1]];
        bvh_narrow_phase(a.tree, a.contact_distance, b.tree, b.contact_distance, alarm_distance_, p.stack,
                         [&](Index e1, Index e2) { test(e1, e2, p.outputs); });
    }

    // Broad phase, then the narrow phase of every pair found, in SOFA's order. `narrow(pair)` runs
    // the pair's BVH traversal with its element test into pairs[pair].outputs.
    template <class Narrow>
    void detect(Narrow&& narrow) {
        const Index n = static_cast<Index>(models.size());
        watch_fast_motion(skip_);
        if (!stacks_reserved_) {  // every pair's traversal stack, once the trees exist (first detection)
            for (PenaltyPair& p : pairs) p.stack.reserve_for(models[p.model[0]].tree, models[p.model[1]].tree);
            stacks_reserved_ = true;
        }
        const Index found =
            skip_ ? 0 : brute_force_broad_phase(broad_.data(), n, rule.data(), alarm_distance_, broad_pairs_.data());
        auto& outputs = outputs_map_.map();
        for (auto& entry : outputs) pairs[entry.second].outputs.clear();  // beginNarrowPhase
        for (Index k = 0; k < found; ++k) {
            const Index first = broad_pairs_[2 * k], second = broad_pairs_[2 * k + 1];
            const Index index = pair_of[first * n + second];
            auto slot = output_slot(outputs, first, second);
            slot->second = index;
            PenaltyPair& p = pairs[index];
            p.outputs.clear();
            p.stack.reserve_for(models[p.model[0]].tree, models[p.model[1]].tree);  // once the trees exist
            narrow(index);
        }
        erase_empty(outputs, [&](Index index) { return pairs[index].outputs.size() == 0; });
    }

    // The contacts of this step from the outputs, in SOFA's contact order, and the explicit forces
    // of the pairs of two simulated models. `x[m]`: model m's points.
    void respond(const double* const* x) {
        count_crossings(x);
        auto& contacts = contacts_map_.map();
        for (const auto& entry : outputs_map_.map()) {
            auto [it, fresh] = contact_slot(contacts, entry.first);
            if (fresh) {
                if (!pairs[entry.second].respond) {  // response "nullptr": SOFA erases the new entry
                    contacts.erase(it);
                    continue;
                }
                it->second = entry.second;
                create(entry.second);
            }
            set_outputs(pairs[entry.second], x);
        }
        remove_inactive(contacts, outputs_map_.map(), [&](Index index) { destroy(index); });
        for (PenaltyModel& m : models) std::fill(m.external.begin(), m.external.end(), 0.0);
        for (const auto& entry : contacts) {  // SolveVisitor at the pipeline's node, `contacts` order
            PenaltyPair& p = pairs[entry.second];
            if (!p.root) continue;
            for (int s = 0; s < 2; ++s) std::fill(p.f[s].begin(), p.f[s].end(), 0.0);
            p.ff.add_force(force(p, 0), force(p, 1), position(p, 0, x), position(p, 1, x));
        }
    }

    // SOFA's contact map after a detection (CollisionResponse::createContacts): `created(pair)` for
    // the pairs that start touching, `updated(pair)` for every pair with outputs in map order,
    // `removed(pair)` for those that stopped.
    template <class Created, class Updated, class Removed>
    void order_contacts(Created&& created, Updated&& updated, Removed&& removed) {
        auto& contacts = contacts_map_.map();
        for (const auto& entry : outputs_map_.map()) {
            auto [it, fresh] = contact_slot(contacts, entry.first);
            if (fresh) {
                it->second = entry.second;
                created(entry.second);
            }
            updated(entry.second);
        }
        remove_inactive(contacts, outputs_map_.map(), removed);
    }

    // f(pair) for the live contacts, in SOFA's `contacts` order.
    template <class F>
    void for_each_contact(F&& f) const {
        for (const auto& entry : contacts_map_.map()) f(entry.second);
    }

    double contact_distance() const { return contact_distance_; }

    // f(model) += its contact forces (a force evaluation of the group integrating `model`).
    void add_force(Index model, double* f, const double* x) {
        PenaltyModel& m = models[model];
        if (!m.external.empty())
            for (std::size_t i = 0; i < m.external.size(); ++i) f[i] += m.external[i];
        for (const auto& entry : contacts_map_.map()) {  // the contacts with a static model, in this group
            PenaltyPair& p = pairs[entry.second];
            if (p.root || p.grouped) continue;
            const int s = side_of(p, model);
            if (s < 0) continue;
            if (has_points(p, s)) {
                map_positions(p, s, x, p.x[s].data());
                std::fill(p.f[s].begin(), p.f[s].end(), 0.0);
            }
            if (has_points(p, 1 - s)) std::fill(p.f[1 - s].begin(), p.f[1 - s].end(), 0.0);
            double* fs = has_points(p, s) ? p.f[s].data() : f;
            double* fo = has_points(p, 1 - s) ? p.f[1 - s].data() : scratch(p, 1 - s);
            const double* xs = has_points(p, s) ? p.x[s].data() : x;
            const double* xo = other_position(p, 1 - s);
            if (s == 0)
                p.ff.add_force(fs, fo, xs, xo);
            else
                p.ff.add_force(fo, fs, xo, xs);
        }
        for (const Index child : m.children) {  // contact points up to the model, creation order
            const PenaltyPair& p = pairs[child / 2];
            points_jt(p, child % 2, p.f[child % 2].data(), f);
        }
    }

    // df(model) += kfact K dx (a product of the group integrating `model`): the contacts with a
    // static model (the static side does not move: its dx is zero).
    void add_dforce(Index model, double* df, const double* dx, double kfact) {
        PenaltyModel& m = models[model];
        for (const auto& entry : contacts_map_.map()) {
            PenaltyPair& p = pairs[entry.second];
            if (p.root || p.grouped) continue;
            const int s = side_of(p, model);
            if (s < 0) continue;
            const int o = 1 - s;
            if (has_points(p, s)) {
                map_dx(p, s, dx, p.dx[s].data());
                std::fill(p.df[s].begin(), p.df[s].end(), 0.0);
            }
            zero_other(p, o);
            double* dfs = has_points(p, s) ? p.df[s].data() : df;
            const double* dxs = has_points(p, s) ? p.dx[s].data() : dx;
            if (s == 0)
                p.ff.add_dforce(dfs, p.df[o].data(), dxs, p.dx[o].data(), kfact);
            else
                p.ff.add_dforce(p.df[o].data(), dfs, p.dx[o].data(), dxs, kfact);
        }
        for (const Index child : m.children) {
            const PenaltyPair& p = pairs[child / 2];
            if (!p.root) points_jt(p, child % 2, p.df[child % 2].data(), df);
        }
    }

    // A += kfact K for the contacts on `model` with static partners (the group's assembled system):
    // -ks kfact w_a w_b n n^T between the points a, b of each contact point's element, w the contact
    // point's weights. Every element's blocks are added at every call, zeros included, so that
    // the assembler's recorded pattern (all couplings within an element) never changes.
    template <class Assembler>
    void add_k(Index model, Assembler& A, Index offset, double kfact) {
        PenaltyModel& m = models[model];
        if (m.rigid) {
            add_rigid_k(model, A, offset, kfact);
            return;
        }
        const int width = element_width(m);
        const std::size_t per = static_cast<std::size_t>(9 * width * width);
        m.element_k.assign(per * static_cast<std::size_t>(m.elements), 0.0);
        for_each_static_contact(model, [&](const PenaltyContact& c, Index element, const double* w, Index) {
            double* block = m.element_k.data() + per * static_cast<std::size_t>(element);
            const double k = c.ks * kfact;
            for (int a = 0; a < width; ++a)
                for (int b = 0; b < width; ++b)
                    for (int i = 0; i < 3; ++i)
                        for (int j = 0; j < 3; ++j)
                            block[9 * (width * a + b) + 3 * i + j] -= k * w[a] * w[b] * c.normal[i] * c.normal[j];
        });
        for (Index e = 0; e < m.elements; ++e) {
            const double* block = m.element_k.data() + per * static_cast<std::size_t>(e);
            for (int a = 0; a < width; ++a) {
                const Index pa = width == 1 ? e : m.cells[width * e + a];
                for (int b = 0; b < width; ++b) {
                    const Index pb = width == 1 ? e : m.cells[width * e + b];
                    for (int i = 0; i < 3; ++i)
                        for (int j = 0; j < 3; ++j)
                            A.add(offset + 3 * pa + i, offset + 3 * pb + j, block[9 * (width * a + b) + 3 * i + j]);
                }
            }
        }
    }

    // add_k for a model of Rigid3d spheres: J^T (-ks kfact n n^T) J on each frame, J = [I, -[r]x]
    // the contact point's RigidMapping row (r its rotated offset): -ks kfact g g^T, g = (n, r x n).
    // Every frame's 6x6 block is added at every call, zeros included (a fixed pattern).
    template <class Assembler>
    void add_rigid_k(Index model, Assembler& A, Index offset, double kfact) {
        PenaltyModel& m = models[model];
        m.element_k.assign(36 * static_cast<std::size_t>(m.elements), 0.0);
        for (const auto& entry : contacts_map_.map()) {
            const PenaltyPair& p = pairs[entry.second];
            if (p.root || p.grouped) continue;
            const int s = side_of(p, model);
            if (s < 0) continue;
            for (const PenaltyContact& c : p.ff.contacts) {
                if (!(c.pen > 0)) continue;
                const Index point = s == 0 ? c.m1 : c.m2;
                double g[6];
                rigid_gradient(p.rigid[s], point, c.normal, g);
                double* block = m.element_k.data() + 36 * static_cast<std::size_t>(p.rigid[s].frame(point));
                const double k = c.ks * kfact;
                for (int i = 0; i < 6; ++i)
                    for (int j = 0; j < 6; ++j) block[6 * i + j] -= k * g[i] * g[j];
            }
        }
        for (Index e = 0; e < m.elements; ++e) {
            const double* block = m.element_k.data() + 36 * static_cast<std::size_t>(e);
            for (int i = 0; i < 6; ++i)
                for (int j = 0; j < 6; ++j) A.add(offset + 6 * e + i, offset + 6 * e + j, block[6 * i + j]);
        }
    }

    // f += the forces of the contacts placed in the group integrating the pipeline's node (pairs
    // of two simulated models), in SOFA's contact order: each pair's contact points from the
    // models' positions x[model], its force field, its points' forces mapped onto the models.
    // x[m] and f[m] are the state vectors of model m (null for models in no such pair); two models
    // of one state share them.
    void add_group_force(double* const* f, const double* const* x) {
        for_each_group_pair(f, x, false, [](PenaltyPair& p, double* const* out, const double* const* in) {
            p.ff.add_force(out[0], out[1], in[0], in[1]);
        });
    }

    // df += kfact K dx for the same contacts (both sides move: dx of both models).
    void add_group_dforce(double* const* df, const double* const* dx, double kfact) {
        for_each_group_pair(df, dx, true, [kfact](PenaltyPair& p, double* const* out, const double* const* in) {
            p.ff.add_dforce(out[0], out[1], in[0], in[1], kfact);
        });
    }

    // The coupling blocks of the contacts on `model` with static partners, as SOFA's
    // MatrixLinearSystem adds them although the static side is no state of the system: that
    // state is unknown to its mapping graph, so the blocks df_model/dx_static = ks n n^T (J^T K,
    // on the model's side) and df_static/dx_model (K J) go to the global matrix at the static
    // contact point's own scalar index 3 m + i, read as a column (resp. a row) of the system.
    // `A` holds the mappings' current Jacobians; `matrix.add(row, col, value)` receives kfact
    // times each entry on the system's DOFs.
    template <class Assembler, class Matrix>
    void add_k_static_coupling(Index model, const Assembler& A, Index offset, double kfact, Matrix& matrix) {
        const PenaltyModel& m = models[model];
        const int width = element_width(m);
        const auto add = [&matrix](Index row, Index col, double value) { matrix.add(row, col, value); };
        for_each_static_contact(model, [&](const PenaltyContact& c, Index element, const double* w, Index other) {
            const double k = c.ks * kfact;
            for (int a = 0; a < width; ++a) {
                const Index pa = offset + 3 * (width == 1 ? element : m.cells[width * element + a]);
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) {
                        const double value = k * w[a] * c.normal[i] * c.normal[j];
                        A.expand(pa + i, 3 * other + j, value, add);
                        A.expand(3 * other + i, pa + j, value, add);
                    }
            }
        });
    }

    // Whether a contact of this step involves the model (else its contact forces are zero).
    bool in_contact(Index model) const { return live_pairs_[static_cast<std::size_t>(model)] > 0; }

    // Potential energy of the active contacts (sum of ks pen^2 / 2).
    double energy() const {
        double e = 0.0;
        for (const auto& entry : contacts_map_.map()) e += pairs[entry.second].ff.energy();
        return e;
    }

    // Contacts of the last step, and how often a buffer outgrew its reserved capacity.
    Index contact_count() const {
        Index n = 0;
        for (const auto& entry : contacts_map_.map()) n += static_cast<Index>(pairs[entry.second].ff.contacts.size());
        return n;
    }
    Index growths() const {
        Index n = outputs_map_.growths() + contacts_map_.growths();
        for (const PenaltyPair& p : pairs)
            n += p.outputs.growths + p.dedup.growths + p.ff.growths + p.points[0].growths + p.points[1].growths +
                 p.rigid[0].growths + p.rigid[1].growths;
        return n;
    }
    // Steps x pairs where a model moved farther than the detection's reach near its partner: the
    // detection at the start of each step may have missed a contact in between (tunnelling).
    Index fast_motions() const { return fast_motions_; }
    // Detections skipped without mapping the lazy points (skip_unmapped).
    Index unmapped_detections() const { return unmapped_detections_; }
    // Contacts pushed through in a step (count_crossings): a point through a thin sheet, say.
    Index crossings() const { return crossings_; }

    // Outputs SOFA would have made of NaN (dropped) or of a zero distance (normal (1, 0, 0)).
    Index degenerate_outputs() const {
        Index n = 0;
        for (const PenaltyPair& p : pairs) n += p.outputs.dropped + p.outputs.zero_distances;
        return n;
    }

    std::vector<PenaltyModel> models;
    std::vector<PenaltyPair> pairs;
    std::vector<std::int8_t> rule;  // n x n PairRule
    std::vector<Index> pair_of;  // n x n index into pairs, -1: none
    std::vector<LazyPoints> lazy;

private:
    // Points per element of a model: 3 (triangles), 2 (lines), 1 (points, spheres).
    static int element_width(const PenaltyModel& m) {
        return m.kind == ContactSide::kTriangle ? 3 : (m.kind == ContactSide::kLine ? 2 : 1);
    }

    // Each active contact (pen > 0) of `model` with a static partner, in contact order:
    // f(contact, the model's element, its contact point's weights on the element's points, the
    // partner's contact point).
    template <class F>
    void for_each_static_contact(Index model, F&& f) const {
        for (const auto& entry : contacts_map_.map()) {
            const PenaltyPair& p = pairs[entry.second];
            if (p.root || p.grouped) continue;
            const int s = side_of(p, model);
            if (s < 0) continue;
            for (const PenaltyContact& c : p.ff.contacts) {
                if (!(c.pen > 0)) continue;
                double w[3] = {1.0, 0.0, 0.0};
                if (has_points(p, s)) p.points[s].weights(s == 0 ? c.m1 : c.m2, w);
                f(c, s == 0 ? c.element1 : c.element2, w, s == 0 ? c.m2 : c.m1);
            }
        }
    }

    // The live pairs placed in the group of the pipeline's node, in SOFA's contact order: each
    // side's contact points from its model's vector `in` (positions; dx when `derivative`, through
    // J), `evaluate(pair, sides' outputs, sides' inputs)`, the points' outputs mapped onto `out`.
    template <class Evaluate>
    void for_each_group_pair(double* const* out, const double* const* in, bool derivative, Evaluate&& evaluate) {
        for (const auto& entry : contacts_map_.map()) {
            PenaltyPair& p = pairs[entry.second];
            if (!p.grouped) continue;
            double* outs[2];
            const double* ins[2];
            for (int s = 0; s < 2; ++s) {
                const Index model = p.model[s];
                outs[s] = out[model];
                ins[s] = in[model];
                if (!has_points(p, s)) continue;
                std::vector<double>& point_in = derivative ? p.dx[s] : p.x[s];
                std::vector<double>& point_out = derivative ? p.df[s] : p.f[s];
                if (derivative)
                    map_dx(p, s, in[model], point_in.data());
                else
                    map_positions(p, s, in[model], point_in.data());
                std::fill(point_out.begin(), point_out.end(), 0.0);
                outs[s] = point_out.data();
                ins[s] = point_in.data();
            }
            evaluate(p, outs, ins);
            for (int s = 0; s < 2; ++s)
                if (has_points(p, s)) points_jt(p, s, outs[s], out[p.model[s]]);
        }
    }

    // g = J^T n for a rigidly mapped contact point: (n, r x n), r its rotated offset.
    static void rigid_gradient(const RigidContactPoints& points, Index point, const V3& n, double* g) {
        const V3 t = cross(points.rotated(point), n);
        for (int k = 0; k < 3; ++k) {
            g[k] = n[k];
            g[3 + k] = t[k];
        }
    }

    // Which side of a pair a model is (0 or 1), or -1.
    static int side_of(const PenaltyPair& p, Index model) {
        return p.model[0] == model ? 0 : (p.model[1] == model ? 1 : -1);
    }

    // The root box of a moving model from its points `x` (see begin_detection), as its leaf boxes
    // and the refit would make it; false if a coordinate is NaN.
    static bool points_box(const PenaltyModel& m, const double* x, Box& box) {
        bool finite = true;
        const double d = m.contact_distance;
        if (m.kind == ContactSide::kSphere) {  // per-sphere radii: the leaf boxes' own numbers
            SphereModel s = m.sphere;
            s.x = x;
            for (Index e = 0; e < m.elements; ++e) {
                const Box b = sphere_box(s.center(e), s.r(e), d);
                for (int c = 0; c < 3; ++c) {
                    finite = finite && b.min[c] == b.min[c] && b.max[c] == b.max[c];
                    if (e == 0 || b.min[c] < box.min[c]) box.min[c] = b.min[c];
                    if (e == 0 || b.max[c] > box.max[c]) box.max[c] = b.max[c];
                }
            }
            return finite;
        }
        const bool all = m.used.empty();  // point models: element i is point i
        const Index count = !all ? static_cast<Index>(m.used.size()) : (m.kind == ContactSide::kPoint ? m.elements : m.points);
        if (count == 0) return true;
        V3 lo, hi;
        finite = min_max(x, all ? nullptr : m.used.data(), count, lo, hi);
        for (int c = 0; c < 3; ++c) {
            box.min[c] = lo[c] - d;
            box.max[c] = hi[c] + d;
        }
        return finite;
    }

    // lo, hi: the smallest and largest coordinates of `count` points of `x` (those of `subset`, or
    // the first ones), in their order; false if one is NaN.
    static bool min_max(const double* x, const Index* subset, Index count, V3& lo, V3& hi) {
        const Index first = subset ? subset[0] : 0;
        lo = V3{{x[3 * first], x[3 * first + 1], x[3 * first + 2]}};
        hi = lo;
        int nan = 0;
        const auto fold = [&](const double* p) {  // branch-free: min / max and a NaN flag per point
            for (int c = 0; c < 3; ++c) {
                nan |= p[c] != p[c];
                lo[c] = p[c] < lo[c] ? p[c] : lo[c];
                hi[c] = p[c] > hi[c] ? p[c] : hi[c];
            }
        };
        if (subset)
            for (Index k = 1; k < count; ++k) fold(x + 3 * subset[k]);
        else
            for (Index k = 1; k < count; ++k) fold(x + 3 * k);
        return nan == 0 && lo[0] == lo[0] && lo[1] == lo[1] && lo[2] == lo[2];
    }

    // Lazy points' enclosure from their parent's positions (see LazyPoints); false if it is not
    // finite (a NaN or an overflow: the caller then maps the points and the exact path decides).
    static bool enclose(LazyPoints& l) {
        if (l.parent_points == 0) return false;
        V3 lo, hi;
        if (!min_max(l.parent, nullptr, l.parent_points, lo, hi)) return false;
        for (int c = 0; c < 3; ++c) {
            const double grow = l.spread * (hi[c] - lo[c]) + l.rounding * std::max(std::abs(lo[c]), std::abs(hi[c]));
            l.enclosure.min[c] = lo[c] - grow;
            l.enclosure.max[c] = hi[c] + grow;
            if (!std::isfinite(l.enclosure.min[c]) || !std::isfinite(l.enclosure.max[c])) return false;
        }
        return true;
    }

    // Before a response: the contacts of the last step that were active (pen > 0) and whose points
    // now lie on the wrong side of each other along the contact's normal ((x2 - x1) . n < 0, pen >
    // dist): a point pushed through a triangle, two edges across each other. The detection finds
    // them again with the normal reversed and the penalty then pushes them on through: counted for
    // the report (ContactWarning), not undone.
    void count_crossings(const double* const* x) {
        for (const auto& entry : contacts_map_.map()) {
            PenaltyPair& p = pairs[entry.second];
            if (p.ff.contacts.empty()) continue;
            const double* xs[2];
            for (int s = 0; s < 2; ++s) {
                xs[s] = x[p.model[s]];
                if (has_points(p, s)) {  // (set_outputs maps them again for the new contacts)
                    map_positions(p, s, xs[s], p.x[s].data());
                    xs[s] = p.x[s].data();
                }
            }
            for (const PenaltyContact& c : p.ff.contacts)
                if (c.pen > 0 && dot(load3(xs[1], 3, c.m2) - load3(xs[0], 3, c.m1), c.normal) < 0) ++crossings_;
        }
    }

    // The box of a model swept from its last root box to this one (watch_fast_motion).
    static Box union_of(const Box& now, const Box& last) {
        Box swept = now;
        for (int c = 0; c < 3; ++c) {
            swept.min[c] = std::min(now.min[c], last.min[c]);
            swept.max[c] = std::max(now.max[c], last.max[c]);
        }
        return swept;
    }

    // Before each detection: how far each model's root box moved since the previous one, and the
    // pairs whose swept boxes meet while one of them moved farther than the pair's reach. A step
    // the pre-test skipped (`from_points`) reads the root boxes it computed: the same numbers.
    void watch_fast_motion(bool from_points) {
        for (PenaltyModel& m : models) {
            if (!m.tree.built() || m.tree.empty()) continue;
            const Box& now = from_points ? m.root : m.tree.root().box;
            m.swept = watching_ ? union_of(now, m.last_root) : now;
            m.motion = 0.0;
            if (watching_)
                for (int c = 0; c < 3; ++c)
                    m.motion = std::max({m.motion, std::abs(now.min[c] - m.last_root.min[c]),
                                         std::abs(now.max[c] - m.last_root.max[c])});
            m.last_root = now;
        }
        if (watching_) {
            for (const PenaltyPair& p : pairs) {
                const PenaltyModel& a = models[p.model[0]];
                const PenaltyModel& b = models[p.model[1]];
                // one state moving as a whole moves both sides alike: its box says nothing here
                if (a.tree.empty() || b.tree.empty() || p.one_node) continue;
                const double reach = alarm_distance_ + a.contact_distance + b.contact_distance;
                if ((a.motion > reach || b.motion > reach) && boxes_meet(a.swept, b.swept, reach)) ++fast_motions_;
            }
        }
        watching_ = true;
    }

    // Whether a side's contact points are a state of their own (a mapping from the model's state):
    // barycentric on triangles and lines, rigid on Rigid3d spheres; else the model's own points.
    bool has_points(const PenaltyPair& p, int side) const {
        const PenaltyModel& m = models[p.model[side]];
        return m.kind == ContactSide::kTriangle || m.kind == ContactSide::kLine || m.rigid;
    }
    bool rigid_side(const PenaltyPair& p, int side) const { return models[p.model[side]].rigid; }
    // The contact points' mapping of a side with points: positions (RigidMapping::apply keeps the
    // rotated offsets), derivatives (J) and J^T.
    void map_positions(PenaltyPair& p, int side, const double* x, double* out) {
        if (rigid_side(p, side))
            p.rigid[side].apply(x, out);
        else
            p.points[side].apply(x, out);
    }
    void map_dx(const PenaltyPair& p, int side, const double* dx, double* out) const {
        if (rigid_side(p, side))
            p.rigid[side].apply_j(dx, out);
        else
            p.points[side].apply(dx, out);
    }
    void points_jt(const PenaltyPair& p, int side, const double* f, double* in_f) const {
        if (rigid_side(p, side))
            p.rigid[side].apply_jt(f, in_f);
        else
            p.points[side].apply_jt(f, in_f);
    }
    std::size_t point_count(const PenaltyPair& p, int side) const {
        return rigid_side(p, side) ? p.rigid[side].size() : p.points[side].size();
    }
    double* force(PenaltyPair& p, int side) {
        return has_points(p, side) ? p.f[side].data() : models[p.model[side]].external.data();
    }
    const double* position(const PenaltyPair& p, int side, const double* const* x) const {
        return has_points(p, side) ? p.x[side].data() : x[p.model[side]];
    }
    // The static side of a contact in a group: its contact points as the response placed them.
    const double* other_position(const PenaltyPair& p, int side) const {
        return has_points(p, side) ? p.x[side].data() : static_x_[p.model[side]];
    }
    double* scratch(PenaltyPair& p, int side) {
        p.f[side].assign(static_cast<std::size_t>(3 * models[p.model[side]].points), 0.0);
        return p.f[side].data();
    }
    void zero_other(PenaltyPair& p, int side) {
        const std::size_t n = has_points(p, side) ? p.x[side].size() : static_cast<std::size_t>(3 * models[p.model[side]].points);
        p.dx[side].assign(n, 0.0);
        p.df[side].assign(n, 0.0);
    }

    void create(Index index) {  // createMapping on side 1, then side 2: the contact-point nodes
        PenaltyPair& p = pairs[index];
        p.live = true;
        ++live_pairs_[static_cast<std::size_t>(p.model[0])];
        ++live_pairs_[static_cast<std::size_t>(p.model[1])];
        if (p.grouped) return;  // add_group_force maps its points' forces itself
        for (int s = 0; s < 2; ++s)
            if (has_points(p, s)) models[p.model[s]].children.push_back(2 * index + s);
    }
    void destroy(Index index) {
        PenaltyPair& p = pairs[index];
        p.live = false;
        --live_pairs_[static_cast<std::size_t>(p.model[0])];
        --live_pairs_[static_cast<std::size_t>(p.model[1])];
        p.ff.clear();
        for (int s = 0; s < 2; ++s) {
            auto& children = models[p.model[s]].children;
            children.erase(std::remove(children.begin(), children.end(), 2 * index + s), children.end());
        }
    }

    ContactSideModel side_model(PenaltyPair& p, int s, const double* x) {
        PenaltyModel& m = models[p.model[s]];
        m.sphere.x = x;
        const bool barycentric = has_points(p, s) && !m.rigid;
        return ContactSideModel{m.kind,
                                x,
                                m.cells,
                                m.kind == ContactSide::kSphere ? &m.sphere : nullptr,
                                m.contact_distance,
                                m.contact_stiffness,
                                barycentric ? &p.points[s] : nullptr,
                                m.rigid ? &p.rigid[s] : nullptr};
    }

    // BarycentricPenalityContact::setDetectionOutputs, then the mappers' update() on positions.
    void set_outputs(PenaltyPair& p, const double* const* x) {
        p.dedup.run(p.outputs);
        set_penalty_contacts(p.outputs, p.dedup, contact_distance_, side_model(p, 0, x[p.model[0]]),
                             side_model(p, 1, x[p.model[1]]), p.ff);
        for (int s = 0; s < 2; ++s) {
            static_x_[p.model[s]] = x[p.model[s]];
            if (!has_points(p, s)) continue;
            const std::size_t n = 3 * point_count(p, s);
            for (auto* v : {&p.x[s], &p.f[s], &p.dx[s], &p.df[s]}) v->resize(n);
            map_positions(p, s, x[p.model[s]], p.x[s].data());
        }
    }

    double alarm_distance_ = 0.0, contact_distance_ = 0.0;
    bool watching_ = false;  // a detection ran before: root boxes to compare with
    bool stacks_reserved_ = false;
    bool skip_ = false;  // this step's pre-test found no pair that can meet
    Index fast_motions_ = 0;
    Index unmapped_detections_ = 0;
    Index crossings_ = 0;
    int depth_ = 0;
    std::vector<BroadPhaseModel> broad_;
    std::vector<Index> broad_pairs_;
    std::vector<const double*> static_x_;
    std::vector<Index> live_pairs_;  // per model: its live pairs
    StablePairMap<Index> outputs_map_, contacts_map_;
};

}  // namespace sofac::collide

namespace sofac {

// The scene's pipelines, in SOFA's order (a CompositeCollisionPipeline's sub-pipelines).
using ContactPipelines = std::vector<std::unique_ptr<collide::PenaltyContacts>>;

inline void contact_add_force(ContactPipelines& pipelines, Index pipeline, Index model, double* f, const double* x) {
    pipelines[pipeline]->add_force(model, f, x);
}

template <class Assembler>
inline void contact_assemble(ContactPipelines& pipelines, Index pipeline, Index model, Assembler& A, Index offset,
                             double kfact) {
    pipelines[pipeline]->add_k(model, A, offset, kfact);
}

template <class Assembler, class Matrix>
inline void contact_assemble_static_coupling(ContactPipelines& pipelines, Index pipeline, Index model,
                                             const Assembler& A, Index offset, double kfact, Matrix& matrix) {
    pipelines[pipeline]->add_k_static_coupling(model, A, offset, kfact, matrix);
}

inline void contact_add_dforce(ContactPipelines& pipelines, Index pipeline, Index model, double* df,
                               const double* dx, double kfact) {
    pipelines[pipeline]->add_dforce(model, df, dx, kfact);
}

// One state vector per model of a pipeline (null for the models it does not concern).
template <int N>
struct ModelVectors {
    double* at[N];
};

template <int N>
inline void contact_group_add_force(ContactPipelines& pipelines, Index pipeline, const ModelVectors<N>& f,
                                    const ModelVectors<N>& x) {
    pipelines[pipeline]->add_group_force(f.at, x.at);
}

template <int N>
inline void contact_group_add_dforce(ContactPipelines& pipelines, Index pipeline, const ModelVectors<N>& df,
                                     const ModelVectors<N>& dx, double kfact) {
    pipelines[pipeline]->add_group_dforce(df.at, dx.at, kfact);
}

}  // namespace sofac
