// Lagrangian contact under FreeMotionAnimationLoop: SOFA's FrictionContactConstraint response
// (BaseUnilateralContactResponse + FrictionContact) turning each detection output into an
// UnilateralLagrangianConstraint<Vec3d> contact, and the rows those contacts add to the loop's
// constraint problem:
//
//   respond():   (start of the step, on the positions at its start) SOFA's contact order (the two
//                stable-id maps of the penalty pipeline, whose detection this class reuses), the
//                response's de-duplication (outputs closer than 1e-8f to a kept one are dropped),
//                the contact points (barycentric on triangles and lines, the model's own points on
//                point models) and each contact's P, Q, normal and tangents (addContact);
//   begin():     (constraint phase) the rows: static rows first (the scene's own constraints, in the
//                root node), then the contacts, placed as SOFA places the constraint objects
//                (two simulated models: the pipeline's node; a static partner: the simulated
//                model's node; nodes in depth-first order, contacts order within a node);
//   violation(): dfree from the free positions (UnilateralLagrangianConstraint::getPositionViolation);
//   jacobian():  each corrected state's rows: its static rows, then its contact rows carried through
//                BarycentricMapping::applyJT and RigidMapping::applyJT as SOFA accumulates them.
//
// Memory: buffers are reserved at setup for `capacity` rows; a step with more rows doubles it (fit(),
// counted among the growths), never an overrun nor a dropped contact.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "constraints.h"
#include "penalty.h"

namespace sofac::collide {

// Where a collision model's points are corrected: `body` (a constraint correction, in the solver's
// order; -1: none, as a static obstacle) and, for a rigidly mapped model, each point's frame and
// rotated offset (the RigidMapping's last apply); for a model mapped by an IdentityMapping or a
// SubsetMapping with increasing indices, each point's DOF in the corrected state; for a model
// mapped by a BarycentricMapping, each point's `width` parent DOFs and weights in its mapper's
// applyJT order, of which the first element_nodes[point] (all when null) are its element's.
struct LagrangianModel {
    Index body = -1;
    const double* x_free = nullptr;  // the model's free positions (x + dt J v_free when mapped)
    const Index* frames = nullptr;   // rigidly mapped: frame of each point
    const double* offsets = nullptr; // rigidly mapped: rotated offset of each point
    const Index* subset = nullptr;   // identity or subset mapped: the parent DOF of each point
    const Index* nodes = nullptr;    // barycentrically mapped: the parent DOFs of each point
    const double* weights = nullptr; // barycentrically mapped: their weights
    const Index* element_nodes = nullptr;
    int width = 0;
    bool barycentric() const { return nodes != nullptr; }
};

// One contact (BaseContactLagrangianConstraint::Contact) and its contact points.
struct LagrangianContact {
    Index pair = 0;
    Index point[2][3] = {{0, 0, 0}, {0, 0, 0}};  // each side's element points
    double weight[2][3] = {{0, 0, 0}, {0, 0, 0}};
    int count[2] = {1, 1};  // 3 triangle, 2 line, 1 point
    double fx[2] = {0, 0}, fy[2] = {0, 0};
    V3 normal, t, s, P, Q;  // P on side 2 (mstate2), Q on side 1
    double distance = 0.0;
    Index row = 0;
    Index output_id = 0;  // the detection output's id (the persistent id's first half)
};

// A state's constraint rows built each step (SOFA's MatrixDeriv after the mappings' applyJT).
struct DynamicRows {
    std::vector<Index> row_index, start, dof;
    std::vector<double> values;
    int deriv = 3;
    void clear() {
        row_index.clear();
        dof.clear();
        values.clear();
        start.assign(1, 0);
    }
    JacobianRows view() const {
        return JacobianRows{Index(row_index.size()), row_index.data(), start.data(), dof.data(), values.data()};
    }
};

class FrictionContacts : public PenaltyContacts {
public:
    // After resize(): the response's settings, the static rows, the corrections reached; then the
    // models' `lagrangian` entries, then reserve_rows().
    void setup_lagrangian(double mu, Index static_rows, Index bodies) {
        mu_ = mu;
        static_rows_ = static_rows;
        lagrangian.resize(models.size());
        rank.assign(pairs.size(), 0);
        object_.resize(pairs.size());
        kept_.resize(pairs.size());
        for (std::size_t i = 0; i < pairs.size(); ++i) {  // as many as the pair's outputs may be
            const PenaltyPair& p = pairs[i];
            const Index most = std::max(models[p.model[0]].elements, models[p.model[1]].elements);
            kept_[i].reserve(4 * static_cast<std::size_t>(most));
        }
        scratch_points_.reserve(1);
        order_.reserve(pairs.size());
        rows_.resize(static_cast<std::size_t>(bodies));
    }

    // The buffers sized by the rows, reserved for `capacity` rows once the models are known (a
    // row's widest reach on one body: three points of an element on each side, each spread on
    // its barycentric element's nodes).
    void reserve_rows(Index capacity) {
        int width = 1;  // (a point, or a frame, per element point)
        for (const LagrangianModel& m : lagrangian) width = std::max(width, m.width);
        row_width_ = 6 * width;
        reserve(capacity);
    }

    // After respond(): when this step's rows outgrow the capacity, the capacity doubles (as many
    // times as needed) and every buffer sized by it grows with it, this pipeline's and the
    // constraint problem's (W, dfree, f, d, the solvers' scratch), counted as one growth. The
    // problem's old storage goes to `retired` (the instance's: views taken of it before stay
    // readable, with the values before the growth); buffers already large enough (grown before a
    // reset) are kept. A step that does not grow allocates nothing.
    void fit(std::vector<std::vector<double>>& retired, std::vector<double>& W, std::vector<double>& dfree,
             std::vector<double>& f, std::vector<double>& d, std::vector<double>& scratch) {
        if (rows_total_ <= capacity_) return;
        Index capacity = std::max<Index>(capacity_, 1);
        while (capacity < rows_total_) capacity *= 2;
        reserve(capacity);
        const auto grow = [&](std::vector<double>& v, Index size) {
            if (v.size() >= static_cast<std::size_t>(size)) return;
            std::vector<double> bigger(static_cast<std::size_t>(size), 0.0);
            std::copy(v.begin(), v.end(), bigger.begin());
            v.swap(bigger);
            retired.push_back(std::move(bigger));
        };
        grow(W, capacity * capacity);
        grow(dfree, capacity);
        grow(f, capacity);
        grow(d, capacity);
        grow(scratch, 3 * capacity);
        ++row_growths_;
    }
    Index capacity() const { return capacity_; }

    std::vector<LagrangianModel> lagrangian;
    std::vector<Index> rank;  // per pair: the depth-first index of the node its constraint goes to

    // The response at the start of the step: SOFA's contact order, de-duplication, contact points
    // and the contacts' P, Q from the models' positions `x`.
    void respond(const double* const* x) {
        order_contacts(
            [&](Index pair) {  // a new contact object: ContactIdentifier's next id, no history yet
                object_[pair].response_id = next_response_id_++;
                object_[pair].yet_integrated = false;
                object_[pair].previous.clear();
            },
            [](Index) {}, [](Index) {});
        contacts_.clear();
        order_.clear();
        for_each_contact([&](Index pair) { order_.push_back(pair); });
        for (std::size_t i = 1; i < order_.size(); ++i)  // stable, without std::stable_sort's buffer
            for (std::size_t j = i; j > 0 && rank[order_[j]] < rank[order_[j - 1]]; --j) std::swap(order_[j], order_[j - 1]);
        const int lines = mu_ > 0.0 ? 3 : 1;
        Index row = static_rows_;
        for (const Index index : order_) {
            PenaltyPair& p = pairs[index];
            const PenaltyModel& m1 = models[p.model[0]];
            const PenaltyModel& m2 = models[p.model[1]];
            if (m1.contact_stiffness == 0.0 || m2.contact_stiffness == 0.0) continue;  // SOFA: disabled
            auto& kept = kept_[index];
            kept.clear();
            const double min_dist2 = double(0.00000001f);
            for (std::size_t i = 0; i < p.outputs.size(); ++i) {
                const DetectionOutput& o = p.outputs[i];
                bool found = false;
                for (std::size_t k = 0; k < kept.size() && !found; ++k) {
                    const DetectionOutput& q = p.outputs[kept[k]];
                    if (norm2(o.point[0] - q.point[0]) + norm2(o.point[1] - q.point[1]) < min_dist2) found = true;
                }
                if (!found) kept.push_back(i);
            }
            const double d0 = contact_distance() + m1.contact_distance + m2.contact_distance;
            for (const std::size_t i : kept) {
                const DetectionOutput& o = p.outputs[i];
                LagrangianContact c;
                c.pair = index;
                c.output_id = o.id;
                for (int s = 0; s < 2; ++s) place(c, s, p.model[s], s == 0 ? o.elem1 : o.elem2, o.point[s], x);
                // a sphere's contact point is its centre, its radius added to the distance (SOFA's
                // sphere ContactMapper::addPoint; d0 + r1 + r2)
                const double r1 = m1.kind == ContactSide::kSphere ? m1.sphere.r(o.elem1) : 0.0;
                const double r2 = m2.kind == ContactSide::kSphere ? m2.sphere.r(o.elem2) : 0.0;
                c.distance = d0 + r1 + r2;
                c.Q = position(c, 0, x[p.model[0]]);
                c.P = position(c, 1, x[p.model[1]]);
                const V3& n = o.normal;
                c.normal = n;
                c.t = V3{{n[2], n[0], n[1]}};
                c.s = cross(n, c.t);
                c.s = c.s / std::sqrt(norm2(c.s));
                c.t = cross(-n, c.s);
                c.row = row;
                row += lines;
                contacts_.push_back(c);
            }
        }
        rows_total_ = row;
    }

    // The problem's size this step, W (what the last step wrote of it), dfree, f and d zeroed over it
    // (GenericConstraintProblem::clear).
    Index begin(CompliancePattern& P, double* W, double* dfree, double* f, double* d) {
        const Index n = rows_total_;
        n_ = n;
        P.start(W, n);
        for (Index i = 0; i < n; ++i) dfree[i] = f[i] = d[i] = 0.0;
        return n;
    }

    // UnilateralLagrangianConstraint::getPositionViolation on the free positions.
    void violation(double* dfree) const {
        for (const LagrangianContact& c : contacts_) {
            const PenaltyPair& p = pairs[c.pair];
            const V3 Qfree = position(c, 0, lagrangian[p.model[0]].x_free);
            const V3 Pfree = position(c, 1, lagrangian[p.model[1]].x_free);
            const V3 PPfree = Pfree - c.P, QQfree = Qfree - c.Q;
            const double ref_dist = std::sqrt(norm2(PPfree)) + std::sqrt(norm2(QQfree));
            const double dfree_n = dot(Pfree - Qfree, c.normal) - c.distance;
            const double delta = dot(c.P - c.Q, c.normal) - c.distance;
            double dfree_t = 0.0, dfree_s = 0.0;
            const auto direct = [&] {
                dfree_t = dot(PPfree, c.t) - dot(QQfree, c.t);
                dfree_s = dot(PPfree, c.s) - dot(QQfree, c.s);
            };
            if (std::fabs(delta) < 0.00001 * ref_dist && std::fabs(dfree_n) < 0.00001 * ref_dist) {
                direct();
            } else if (std::fabs(delta - dfree_n) > 0.001 * delta) {
                const double dt = delta / (delta - dfree_n);
                if (dt > 0.0 && dt < 1.0) {
                    const V3 Pt = c.P * (1 - dt) + Pfree * dt;
                    const V3 Qt = c.Q * (1 - dt) + Qfree * dt;
                    const V3 PtPfree = Pfree - Pt, QtQfree = Qfree - Qt;
                    dfree_t = dot(PtPfree, c.t) - dot(QtQfree, c.t);
                    dfree_s = dot(PtPfree, c.s) - dot(QtQfree, c.s);
                } else if (dfree_n < 0.0) {
                    direct();
                }
            } else {
                direct();
            }
            dfree[c.row] = dfree_n;
            if (mu_ > 0.0) {
                dfree[c.row + 1] = dfree_t;
                dfree[c.row + 2] = dfree_s;
            }
        }
    }

    // Body `body`'s rows: the static ones (`fixed`), then its contact rows, carried to its DOFs.
    template <class DT>
    const DynamicRows& jacobian(Index body, const JacobianRows& fixed) {
        DynamicRows& r = rows_[static_cast<std::size_t>(body)];
        r.deriv = DT::deriv;
        r.clear();
        if constexpr (DT::deriv == 3 && !DT::rigid) {
            for (const LagrangianModel& m : lagrangian)
                if (m.body == body && m.barycentric()) {
                    barycentric_rows(r, body, fixed);
                    return r;
                }
        }
        for (Index k = 0; k < fixed.rows; ++k) {
            r.row_index.push_back(fixed.row_index[k]);
            for (Index e = fixed.start[k]; e < fixed.start[k + 1]; ++e) {
                r.dof.push_back(fixed.dof[e]);
                for (int c = 0; c < DT::deriv; ++c) r.values.push_back(fixed.values[DT::deriv * e + c]);
            }
            r.start.push_back(Index(r.dof.size()));
        }
        const int lines = mu_ > 0.0 ? 3 : 1;
        for (const LagrangianContact& c : contacts_) {
            const PenaltyPair& p = pairs[c.pair];
            for (int s = 0; s < 2; ++s) {
                const LagrangianModel& m = lagrangian[p.model[s]];
                if (m.body != body) continue;
                for (int l = 0; l < lines; ++l) {
                    const V3& dir = l == 0 ? c.normal : (l == 1 ? c.t : c.s);
                    const V3 data = s == 0 ? -dir : dir;
                    r.row_index.push_back(c.row + l);
                    add_row_entries<DT>(r, m, c, s, data);
                    r.start.push_back(Index(r.dof.size()));
                }
            }
        }
        return r;
    }

    // The problem's blocks: the K static ones, then one per contact.
    RowBlock* blocks(const Index* first, const Index* kind, const double* parameter, const Index* kept,
                     double* previous, Index K) {
        blocks_.clear();
        for (Index k = 0; k < K; ++k) {
            RowBlock b;
            b.first = first[k];
            b.kind = Resolution(kind[k]);
            b.parameter = parameter[2 * k];
            b.upper = parameter[2 * k + 1];
            b.previous = kept[k] >= 0 ? previous + kept[k] : nullptr;
            blocks_.push_back(b);
        }
        for (const LagrangianContact& c : contacts_) {
            RowBlock b;
            b.first = c.row;
            b.kind = mu_ > 0.0 ? Resolution::UnilateralFriction3 : Resolution::Unilateral1;
            b.parameter = mu_;
            blocks_.push_back(b);
        }
        return blocks_.data();
    }
    // LCPConstraintSolver::getConstraintInfo + computeInitialGuess: each contact's persistent id
    // (cantor(output id, response id), negated until its constraint object's first solve is
    // over: BaseContactLagrangianConstraint's yetIntegrated), and the previous forces of the
    // contacts found by it in their object's history (the last entry of an id wins).
    void initial_guess(double* f) {
        const Index n = rows_total_;
        for (Index i = 0; i < n; ++i) f[i] = 0.0;
        ids_.clear();
        const Index lines = mu_ > 0.0 ? 3 : 1;
        for (const LagrangianContact& c : contacts_) {
            const Object& o = object_[static_cast<std::size_t>(c.pair)];
            const std::int64_t x = c.output_id, y = o.response_id;
            const long id = long(((x + y) * (x + y) + 3 * x + y) / 2);
            ids_.push_back(o.yet_integrated ? id : -id);
        }
        for (std::size_t k = 0; k < contacts_.size(); ++k) {
            const LagrangianContact& c = contacts_[k];
            const Object& o = object_[static_cast<std::size_t>(c.pair)];
            if (o.previous.empty()) continue;
            const Index nbl = std::min(lines, o.lines);
            Index previous = -1;
            for (const auto& entry : o.previous)
                if (entry.first == ids_[k]) previous = entry.second;
            if (previous >= 0 && previous + nbl <= Index(previous_forces_.size()))
                for (Index l = 0; l < nbl; ++l) f[c.row + l] = previous_forces_[static_cast<std::size_t>(previous + l)];
        }
        for (const LagrangianContact& c : contacts_) object_[static_cast<std::size_t>(c.pair)].yet_integrated = true;
    }

    // keepContactForcesValue: this solve's forces and, per constraint object, id -> first row.
    void keep_forces(const double* f) {
        previous_forces_.assign(f, f + rows_total_);
        for (Object& o : object_) o.previous.clear();
        const Index lines = mu_ > 0.0 ? 3 : 1;
        for (std::size_t k = 0; k < contacts_.size() && k < ids_.size(); ++k) {
            Object& o = object_[static_cast<std::size_t>(contacts_[k].pair)];
            o.previous.emplace_back(ids_[k], contacts_[k].row);
            o.lines = lines;
        }
    }

    Index block_count() const { return Index(blocks_.size()); }
    Index rows() const { return n_; }
    Index contact_count() const { return Index(contacts_.size()); }
    // The detection's growths, and the times the rows outgrew their capacity (fit()).
    Index growths() const { return PenaltyContacts::growths() + row_growths_; }
    const std::vector<LagrangianContact>& contacts() const { return contacts_; }
    double mu() const { return mu_; }

private:
    // The buffers sized by the rows: reserved for `capacity` rows (contacts of one row or more).
    void reserve(Index capacity) {
        capacity_ = capacity;
        const auto rows = static_cast<std::size_t>(capacity);
        const auto width = static_cast<std::size_t>(row_width_);
        for (auto& o : object_) o.previous.reserve(rows);
        previous_forces_.reserve(rows);
        ids_.reserve(rows);
        contacts_.reserve(rows);
        blocks_.reserve(rows);
        for (auto& r : rows_) {
            r.row_index.reserve(rows);
            r.start.reserve(rows + 1);
            r.dof.reserve(width * rows);
            r.values.reserve(6 * width * rows);
        }
        if (row_width_ > 6) triplets_.reserve(width * rows + static_entries_);
    }

    // A block of a body's constraint matrix as CompressedRowSparseMatrixConstraint inserts it
    // (its btemp: unsorted, a repeat of the last (row, DOF) added to it).
    struct Triplet {
        Index row, dof;
        V3 value;
        bool operator<(const Triplet& b) const { return row < b.row || (row == b.row && dof < b.dof); }
    };
    void insert(Index row, Index dof, const V3& value) {
        if (triplets_.empty() || triplets_.back().row != row || triplets_.back().dof != dof)
            triplets_.push_back(Triplet{row, dof, V3{{0.0, 0.0, 0.0}}});
        triplets_.back().value = triplets_.back().value + value;
    }

    // The rows of a body whose contact models are barycentrically mapped onto it, as SOFA's
    // MatrixDeriv holds them when the correction reads it: the static rows (the body's own
    // constraints wrote them first), then, per collision state (in the models' order), its rows
    // ascending, each DOF of a row ascending spread on its element's nodes in the mapper's order
    // (BarycentricMapper::applyJT); then compress(): std::sort of the blocks by (row, DOF), the
    // blocks of one (row, DOF) summed in the sorted order. The same std::sort on the same
    // sequence, so the same sums to the last bit.
    void barycentric_rows(DynamicRows& r, Index body, const JacobianRows& fixed) {
        const auto entries = static_cast<std::size_t>(fixed.rows > 0 ? fixed.start[fixed.rows] : 0);
        if (entries > static_entries_) {  // (the first step: the static rows are known now)
            static_entries_ = entries;
            triplets_.reserve(static_cast<std::size_t>(row_width_ * capacity_) + entries);
        }
        triplets_.clear();
        for (Index k = 0; k < fixed.rows; ++k)
            for (Index e = fixed.start[k]; e < fixed.start[k + 1]; ++e)
                insert(fixed.row_index[k], fixed.dof[e], load3(fixed.values, 3, e));
        const int lines = mu_ > 0.0 ? 3 : 1;
        for (std::size_t i = 0; i < lagrangian.size(); ++i) {
            const LagrangianModel& state = lagrangian[i];
            bool first = state.body == body && state.barycentric();
            for (std::size_t j = 0; j < i && first; ++j) first = lagrangian[j].x_free != state.x_free;
            if (!first) continue;  // (a collision state's models share its free positions)
            for (const LagrangianContact& c : contacts_) {
                const PenaltyPair& p = pairs[c.pair];
                for (int s = 0; s < 2; ++s) {
                    const LagrangianModel& m = lagrangian[p.model[s]];
                    if (m.body != body || m.x_free != state.x_free) continue;
                    for (int l = 0; l < lines; ++l) {
                        const V3& dir = l == 0 ? c.normal : (l == 1 ? c.t : c.s);
                        Index vertex[3];
                        V3 value[3];
                        const int n = collision_row(c, s, s == 0 ? -dir : dir, vertex, value);
                        for (int k = 0; k < n; ++k) {
                            const Index v = vertex[k];
                            const Index count = m.element_nodes != nullptr ? m.element_nodes[v] : m.width;
                            for (Index a = 0; a < count; ++a) {
                                const Index column = Index(m.width) * v + a;
                                insert(c.row + l, m.nodes[column], value[k] * m.weights[column]);
                            }
                        }
                    }
                }
            }
        }
        std::sort(triplets_.begin(), triplets_.end());
        for (std::size_t i = 0; i < triplets_.size();) {
            const Index row = triplets_[i].row;
            r.row_index.push_back(row);
            while (i < triplets_.size() && triplets_[i].row == row) {
                const Index dof = triplets_[i].dof;
                V3 sum = triplets_[i].value;
                for (++i; i < triplets_.size() && triplets_[i].row == row && triplets_[i].dof == dof; ++i)
                    sum = sum + triplets_[i].value;
                r.dof.push_back(dof);
                for (int k = 0; k < 3; ++k) r.values.push_back(sum[k]);
            }
            r.start.push_back(Index(r.dof.size()));
        }
    }

    // The contact point of side s: SOFA's mappers' addPoint.
    void place(LagrangianContact& c, int s, Index model, Index element, const V3& at, const double* const* x) {
        const PenaltyModel& m = models[model];
        const double* xm = x[model];
        if (m.kind == ContactSide::kTriangle) {
            BarycentricContactPoints& points = scratch_points_;
            points.clear();
            points.add_in_triangle(at, element, xm, m.cells);
            double w[3] = {0.0, 0.0, 0.0};
            points.weights(0, w);
            c.count[s] = 3;
            for (int a = 0; a < 3; ++a) c.point[s][a] = m.cells[3 * element + a];
            c.fx[s] = w[1];
            c.fy[s] = w[2];
        } else if (m.kind == ContactSide::kLine) {
            BarycentricContactPoints& points = scratch_points_;
            points.clear();
            points.add_in_line(at, element, xm, m.cells);
            double w[3] = {0.0, 0.0, 0.0};
            points.weights(0, w);
            c.count[s] = 2;
            for (int a = 0; a < 2; ++a) c.point[s][a] = m.cells[2 * element + a];
            c.fx[s] = w[1];
            c.fy[s] = 0.0;
        } else {
            c.count[s] = 1;
            c.point[s][0] = element;
        }
    }

    // The contact point of side s on positions x (the barycentric mapper's apply).
    static V3 position(const LagrangianContact& c, int s, const double* x) {
        const Index* v = c.point[s];
        const double fx = c.fx[s], fy = c.fy[s];
        if (c.count[s] == 3) return load3(x, 3, v[0]) * (1 - fx - fy) + load3(x, 3, v[1]) * fx + load3(x, 3, v[2]) * fy;
        if (c.count[s] == 2) return load3(x, 3, v[0]) * (1 - fx) + load3(x, 3, v[1]) * fx;
        return load3(x, 3, v[0]);
    }

    // A contact row of the collision state, side s: the contact point's `data` spread on its
    // element's points (the contact mapper's BarycentricMapping::applyJT), as the state's
    // compressed row holds it: points ascending, a repeated point summed. Returns the entries.
    static int collision_row(const LagrangianContact& c, int s, const V3& data, Index* merged_vertex, V3* merged) {
        Index vertex[3] = {0, 0, 0};
        V3 f[3] = {};
        const int count = c.count[s];
        const double fx = c.fx[s], fy = c.fy[s];
        for (int a = 0; a < count; ++a) vertex[a] = c.point[s][a];
        if (count == 3) {
            f[0] = data * (1 - fx - fy);
            f[1] = data * fx;
            f[2] = data * fy;
        } else if (count == 2) {
            f[0] = data * (1 - fx);
            f[1] = data * fx;
        } else {
            f[0] = data;
        }
        // sort by vertex (the collision state's row is a std::map); equal vertices add up
        int order[3] = {0, 1, 2};
        for (int i = 1; i < count; ++i)  // insertion sort of (at most) three
            for (int j = i; j > 0 && vertex[order[j]] < vertex[order[j - 1]]; --j) std::swap(order[j], order[j - 1]);
        int n = 0;
        for (int k = 0; k < count; ++k) {
            const int a = order[k];
            if (n > 0 && merged_vertex[n - 1] == vertex[a]) {
                merged[n - 1] = merged[n - 1] + f[a];
            } else {
                merged_vertex[n] = vertex[a];
                merged[n] = f[a];
                ++n;
            }
        }
        return n;
    }

    // One row's entries on a body: the collision state's row (collision_row) on the body's DOFs:
    // as they are, through an identity or subset mapping, or, when the model is rigidly mapped,
    // summed per frame as RigidMapping::applyJT does (v += f, w += r x f, points ascending).
    template <class DT>
    void add_row_entries(DynamicRows& r, const LagrangianModel& m, const LagrangianContact& c, int s, const V3& data) {
        Index merged_vertex[3] = {0, 0, 0};
        V3 merged[3] = {};
        const int n = collision_row(c, s, data, merged_vertex, merged);
        if constexpr (DT::rigid && DT::deriv == 6) {
            // frames ascending; within a frame, points ascending
            Index frame_list[3] = {0, 0, 0};
            int frames = 0;
            for (int k = 0; k < n; ++k) {
                const Index fr = m.frames[merged_vertex[k]];
                if (std::find(frame_list, frame_list + frames, fr) == frame_list + frames) frame_list[frames++] = fr;
            }
            for (int i = 1; i < frames; ++i)
                for (int j = i; j > 0 && frame_list[j] < frame_list[j - 1]; --j) std::swap(frame_list[j], frame_list[j - 1]);
            for (int q = 0; q < frames; ++q) {
                V3 v{{0.0, 0.0, 0.0}}, w{{0.0, 0.0, 0.0}};
                for (int k = 0; k < n; ++k) {
                    if (m.frames[merged_vertex[k]] != frame_list[q]) continue;
                    v = v + merged[k];
                    w = w + cross(load3(m.offsets, 3, merged_vertex[k]), merged[k]);
                }
                r.dof.push_back(frame_list[q]);
                for (int k = 0; k < 3; ++k) r.values.push_back(v[k]);
                for (int k = 0; k < 3; ++k) r.values.push_back(w[k]);
            }
        } else {
            for (int k = 0; k < n; ++k) {  // (a subset's indices increase: the order is kept)
                r.dof.push_back(m.subset != nullptr ? m.subset[merged_vertex[k]] : merged_vertex[k]);
                for (int c3 = 0; c3 < DT::deriv; ++c3) r.values.push_back(c3 < 3 ? merged[k][c3] : 0.0);
            }
        }
    }

    struct Object {  // a pair's constraint object (alive while the pair has outputs)
        std::int64_t response_id = 0;
        bool yet_integrated = false;
        Index lines = 1;
        std::vector<std::pair<long, Index>> previous;  // persistent id -> first row, last solve
    };
    std::vector<Object> object_;
    std::int64_t next_response_id_ = 0;
    std::vector<double> previous_forces_;
    std::vector<long> ids_;
    double mu_ = 0.8;
    Index capacity_ = 0, static_rows_ = 0, rows_total_ = 0, n_ = 0, row_growths_ = 0;
    std::vector<std::vector<std::size_t>> kept_;
    std::vector<LagrangianContact> contacts_;
    std::vector<Index> order_;
    std::vector<RowBlock> blocks_;
    std::vector<DynamicRows> rows_;
    std::vector<Triplet> triplets_;  // a barycentric body's blocks before compress()
    Index row_width_ = 6;           // the most DOFs a row reaches on one body
    std::size_t static_entries_ = 0;  // the most static blocks a barycentric body has
    BarycentricContactPoints scratch_points_;
};

}  // namespace sofac::collide

namespace sofac {

using LagrangianPipeline = std::unique_ptr<collide::FrictionContacts>;

// The constraint problem's rows this step (static, then contacts); W, dfree, f, d zeroed.
// After the response: the rows' capacity grown to this step's rows if they outgrew it (see fit()).
inline void lagrangian_fit(LagrangianPipeline& L, std::vector<std::vector<double>>& retired, std::vector<double>& W,
                           std::vector<double>& dfree, std::vector<double>& f, std::vector<double>& d,
                           std::vector<double>& scratch) {
    L->fit(retired, W, dfree, f, d, scratch);
}

inline void lagrangian_begin(LagrangianPipeline& L, CompliancePattern& P, double* W, double* dfree, double* f,
                             double* d) {
    L->begin(P, W, dfree, f, d);
}

inline void lagrangian_violation(LagrangianPipeline& L, double* dfree) { L->violation(dfree); }

// UncoupledConstraintCorrection::addComplianceInConstraintSpace on the body's rows of this step.
template <class DT>
inline void lagrangian_add_compliance(LagrangianPipeline& L, Index body, CompliancePattern& P, double* W,
                                      const JacobianRows& fixed, Index dofs, double comp0, const double* comp,
                                      Index comp_size, double factor, double* scaled_comp) {
    const collide::DynamicRows& rows = L->template jacobian<DT>(body, fixed);
    uncoupled_add_compliance<DT>(P, W, rows.view(), dofs, comp0, comp, comp_size, factor, scaled_comp);
}

// The correction of a body after the solve (its rows as jacobian() last built them).
template <class DT>
inline void lagrangian_correct(LagrangianPipeline& L, Index body, double* x, double* v, double* lambda, double* dx,
                               const JacobianRows& fixed, const double* f, Index dofs, double comp0,
                               const double* comp, Index comp_size, double position_factor, double velocity_factor) {
    const collide::DynamicRows& rows = L->template jacobian<DT>(body, fixed);
    uncoupled_correct<DT>(x, v, lambda, dx, rows.view(), f, dofs, comp0, comp, comp_size, position_factor,
                          velocity_factor);
}

// The loop's solve on the static blocks and this step's contact blocks (see solve_constraints).
template <int K>
inline void lagrangian_solve(LagrangianPipeline& L, BuiltSolver solver, CompliancePattern& P, double* W, double* dfree,
                             double* f, double* d, double* scratch, Index /*capacity*/, const Index* first,
                             const Index* kind, const double* parameter, const Index* kept, double* previous,
                             double max_iterations, double tolerance, double sor, double scale_tolerance,
                             double all_verified, double regularization, double* report, double time) {
    const Index n = L->rows();
    RowBlock* blocks = L->blocks(first, kind, parameter, kept, previous, K);
    if (regularization > std::numeric_limits<double>::epsilon())
        for (Index i = 0; i < n; ++i) W[n * i + i] += regularization;
    ConstraintProblem p{n, W, dfree, f, d, blocks, L->block_count(), scratch};
    P.finish();
    P.view(p);
    const ConstraintSettings settings{Index(max_iterations), tolerance, sor, scale_tolerance != 0.0,
                                      all_verified != 0.0};
    record_solve(report, solve_built(solver, p, settings), time, n > 0);
}

// An unbuilt correction and the body its contact rows go to.
template <class DT>
struct LagrangianUnbuilt {
    Index body;
    UnbuiltUncoupled<DT> item;
};

// UnbuiltGaussSeidelConstraintSolver on the static blocks and this step's contact blocks, the
// corrections' rows those of this step (see solve_unbuilt).
template <class DT, int K, class... Items>
inline void lagrangian_solve_unbuilt(LagrangianPipeline& L, CompliancePattern& P, double* W, double* dfree, double* f,
                                     double* d, double* scratch, Index /*capacity*/, const Index* first,
                                     const Index* kind, const double* parameter, const Index* kept, double* previous,
                                     double max_iterations, double tolerance, double sor, double scale_tolerance,
                                     double all_verified, double* report, double time, const Items&... items) {
    UnbuiltSet<DT, int(sizeof...(Items))> set{{items.item...}};
    const Index bodies[] = {items.body...};
    for (int c = 0; c < int(sizeof...(Items)); ++c)
        set.items[c].J = L->template jacobian<DT>(bodies[c], set.items[c].J).view();
    const Index n = L->rows();
    RowBlock* blocks = L->blocks(first, kind, parameter, kept, previous, K);
    const Index count = L->block_count();
    for (const auto& item : set.items) item.reset();
    for (Index k = 0; k < count; ++k) {
        const Index last = blocks[k].first + resolution_lines(blocks[k].kind) - 1;
        for (const auto& item : set.items)
            if (item.row_of(blocks[k].first) >= 0) item.block_compliance(P, W, blocks[k].first, last);
    }
    ConstraintProblem p{n, W, dfree, f, d, blocks, count, scratch};
    const ConstraintSettings settings{Index(max_iterations), tolerance, sor, scale_tolerance != 0.0,
                                      all_verified != 0.0};
    const ConstraintResult result = unbuilt_gauss_seidel(p, settings, set);
    record_solve(report, result, time, n > 0);
}

// LCPConstraintSolver, built, on this step's contact rows (3 per contact): nlcp_gaussseidel with
// the solver's own mu (see lcp_gauss_seidel); W already holds the corrections' compliance.
inline void lagrangian_solve_lcp(LagrangianPipeline& L, CompliancePattern& P, double* W, double* dfree, double* f,
                                 double* d, double* scratch, Index /*capacity*/, double max_iterations,
                                 double tolerance, double mu, double min_w, double max_f, double regularization,
                                 double initial_guess, double* report, double time) {
    const Index n = L->rows();
    if (regularization > std::numeric_limits<double>::epsilon())
        for (Index i = 0; i < n; ++i) W[n * i + i] += regularization;
    if (initial_guess != 0.0 && n != 0) L->initial_guess(f);
    ConstraintProblem p{n, W, dfree, f, d, nullptr, 0, scratch};
    P.finish();
    P.view(p);
    const LcpSettings settings{Index(max_iterations), tolerance, mu, min_w, max_f, initial_guess != 0.0};
    const ConstraintResult result = lcp_gauss_seidel(p, settings);
    if (initial_guess != 0.0) L->keep_forces(f);
    record_solve(report, result, time, n > 0);
}

// LCPConstraintSolver, unbuilt, frictionless (lcp_gaussseidel_unbuilt): one row per contact, each
// row's 1x1 compliance from the (at most two) corrections holding it, the displacements through the
// corrections; the initial guess from the previous solve by persistent id; then the forces kept.
template <class DT, class... Items>
inline void lagrangian_solve_lcp_unbuilt(LagrangianPipeline& L, CompliancePattern& P, double* W, double* dfree,
                                         double* f, double* d, double* /*scratch*/, Index /*capacity*/,
                                         double max_iterations, double tolerance, double mu, double /*min_w*/,
                                         double /*max_f*/, double regularization, double initial_guess,
                                         double* report, double time, const Items&... items) {
    UnbuiltSet<DT, int(sizeof...(Items))> set{{items.item...}};
    const Index bodies[] = {items.body...};
    constexpr int C = int(sizeof...(Items));
    for (int c = 0; c < C; ++c) set.items[c].J = L->template jacobian<DT>(bodies[c], set.items[c].J).view();
    const Index n = L->rows();
    if (initial_guess != 0.0 && n != 0) L->initial_guess(f);
    report[0] += 1.0;
    if (n == 0) {
        report[1] = 0.0;
        report[2] = 0.0;
        if (initial_guess != 0.0) L->keep_forces(f);
        return;
    }
    // resetForUnbuiltResolution: constraint_force = J^T f over the rows with a force, disp = 0
    for (auto& item : set.items) {
        item.reset();
        for (Index r = 0; r < item.J.rows; ++r) {
            const double fc = f[item.J.row_index[r]];
            if (fc == 0.0) continue;
            for (Index e = item.J.start[r]; e < item.J.start[r + 1]; ++e)
                for (int k = 0; k < DT::deriv; ++k)
                    item.force[DT::deriv * item.J.dof[e] + k] += item.J.values[DT::deriv * e + k] * fc;
        }
    }
    // the contacts' corrections (first and second holding the row) and their 1x1 compliances
    const Index lines = mu > 0.0 ? 3 : 1;
    for (Index c = 0; c + lines <= n; c += lines)
        for (int k = 0; k < C; ++k)
            if (set.items[k].row_of(c) >= 0) set.items[k].block_compliance(P, W, c, c + lines - 1);
    if (regularization > std::numeric_limits<double>::epsilon())
        for (Index c = 0; c < n; ++c) W[n * c + c] += regularization;
    const auto holders = [&](Index c, int which) {  // _cclist_elem1 / _cclist_elem2
        int seen = 0;
        for (int k = 0; k < C; ++k)
            if (set.items[k].row_of(c) >= 0 && seen++ == which) return k;
        return -1;
    };
    double error = 0.0;
    Index it = 0;
    bool converged = false;
    if (mu > 0.0) {  // nlcp_gaussseidel_unbuilt: 3 rows per contact, LocalBlock33::New_GS_State
        const Index contacts = n / 3;
        for (it = 0; it < Index(max_iterations); ++it) {
            error = 0.0;
            for (Index c = 0; c < contacts; ++c) {
                const Index r = 3 * c;
                for (int l = 0; l < 3; ++l) d[r + l] = dfree[r + l];
                const double fn0 = f[r];
                double fn = f[r], ft = f[r + 1], fs = f[r + 2];
                const int e1 = holders(r, 0), e2 = holders(r, 1);
                if (e1 >= 0) set.items[e1].add_displacement(d, r, r + 2);
                if (e2 >= 0) set.items[e2].add_displacement(d, r, r + 2);
                double dn = d[r], dt = d[r + 1], ds = d[r + 2];
                const double w[6] = {W[n * r + r],           W[n * r + r + 1],       W[n * r + r + 2],
                                     W[n * (r + 1) + r + 1], W[n * (r + 1) + r + 2], W[n * (r + 2) + r + 2]};
                const double f1[3] = {fn, ft, fs};
                fn -= dn / w[0];
                bool moved = true;
                if (fn <= 0) {
                    fn = ft = fs = 0.0;
                    moved = f1[0] > 0;
                } else {
                    const double d1 = w[1] * (fn - f1[0]) + dt;
                    const double d2 = w[2] * (fn - f1[0]) + ds;
                    ft -= 2 * d1 / (w[3] + w[5]);
                    fs -= 2 * d2 / (w[3] + w[5]);
                    const double norm = std::sqrt(ft * ft + fs * fs);
                    if (norm > mu * fn) {
                        ft *= mu * fn / norm;
                        fs *= mu * fn / norm;
                    }
                }
                if (moved) {
                    const double df[3] = {fn - f1[0], ft - f1[1], fs - f1[2]};
                    dn += w[0] * df[0] + w[1] * df[1] + w[2] * df[2];
                    dt += w[1] * df[0] + w[3] * df[1] + w[4] * df[2];
                    ds += w[2] * df[0] + w[4] * df[1] + w[5] * df[2];
                }
                error += std::sqrt((d[r] - dn) * (d[r] - dn) + (d[r + 1] - dt) * (d[r + 1] - dt) +
                                   (d[r + 2] - ds) * (d[r + 2] - ds));
                const bool update = !(fn0 == 0.0 && fn == 0.0);
                f[r] = fn - f[r];
                f[r + 1] = ft - f[r + 1];
                f[r + 2] = fs - f[r + 2];
                if (update) {
                    if (e1 >= 0) set.items[e1].set_force_change(f, r, r + 2);
                    if (e2 >= 0) set.items[e2].set_force_change(f, r, r + 2);
                }
                f[r] = fn, f[r + 1] = ft, f[r + 2] = fs;
            }
            if (error < tolerance * double(contacts + 1)) {
                converged = true;
                break;
            }
        }
    }
    for (; mu <= 0.0 && it < Index(max_iterations); ++it) {  // lcp_gaussseidel_unbuilt (it is 0 here)
        error = 0.0;
        for (Index c = 0; c < n; ++c) {
            d[c] = dfree[c];
            const double fn0 = f[c];
            double fn = fn0;
            const int e1 = holders(c, 0), e2 = holders(c, 1);
            if (e1 >= 0) set.items[e1].add_displacement(d, c, c);
            if (e2 >= 0) set.items[e2].add_displacement(d, c, c);
            const double dn = d[c];
            const double w11 = W[n * c + c];
            fn -= dn / w11;
            if (fn < 0) fn = 0;
            error += std::fabs(w11 * (fn - fn0));
            if (fn0 != 0.0 || fn != 0.0) {
                f[c] = fn - fn0;
                if (e1 >= 0) set.items[e1].set_force_change(f, c, c);
                if (e2 >= 0) set.items[e2].set_force_change(f, c, c);
            }
            f[c] = fn;
        }
        if (error < tolerance * double(n + 1)) {
            converged = true;
            break;
        }
    }
    report[1] = double(converged ? it + 1 : it);
    report[2] = error;
    if (!converged) {
        report[3] += 1.0;
        report[4] = time;
        report[5] = error;
        report[6] = double(it);
    }
    if (initial_guess != 0.0) L->keep_forces(f);
}

}  // namespace sofac
