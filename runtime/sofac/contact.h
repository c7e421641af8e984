// Penalty contact response as SOFA builds it from one model pair's detection outputs
// (BarycentricPenalityContact::setDetectionOutputs) and the force field it feeds
// (PenalityContactForceField<Vec3d>): de-duplication by output id, the contact points on each side
// (the barycentric contact mapper on triangles and lines, the model's own points on point and
// sphere models), and the force, its derivative and its stiffness matrix. docs/collision-runtime.md
// names the SOFA source of each rule.
//
// Memory: reserve() every buffer once for the largest output count the pair may produce (the
// planner knows it, or takes the output list's capacity); clear() keeps the capacity, so a step
// allocates nothing. Past the capacity, vectors grow and `growths` counts it (reported by the step).
#pragma once

#include <vector>

#include "proximity.h"
#include "quaternion.h"

namespace sofac::collide {

// ---------------------------------------------------------------------------------------------
// SOFA's de-duplication by DetectionOutput::id: of the outputs sharing an id, the first is kept
// unless a later one has a strictly smaller value, which then takes its place -- at the later
// position. `survivors` lists the kept outputs' positions in output order.
class ContactDeduplication {
public:
    // ids run over [0, id_bound): the element count of the model that gives ids (or, for
    // NewProximity's triangle-triangle, 3 size1 + 12 size2).
    void resize(Index id_bound, std::size_t max_outputs) {
        champion_.assign(static_cast<std::size_t>(id_bound), 0);
        stamp_.assign(static_cast<std::size_t>(id_bound), 0);
        keep_.reserve(max_outputs);
        survivors.reserve(max_outputs);
    }

    void run(const OutputList& outputs) {
        ++step_;
        const std::size_t n = outputs.size();
        if (n > keep_.capacity()) ++growths;
        keep_.assign(n, 1);
        for (std::size_t i = 0; i < n; ++i) {
            const auto id = static_cast<std::size_t>(outputs[i].id);
            if (id >= stamp_.size()) {  // an id bound set too small: grow (counted) rather than overrun
                ++growths;
                stamp_.resize(id + 1, 0);
                champion_.resize(id + 1, 0);
            }
            if (stamp_[id] == step_) {
                const std::size_t earlier = champion_[id];
                if (outputs[earlier].value <= outputs[i].value) {
                    keep_[i] = 0;
                    continue;
                }
                keep_[earlier] = 0;
            }
            stamp_[id] = step_;
            champion_[id] = i;
        }
        survivors.clear();
        for (std::size_t i = 0; i < n; ++i)
            if (keep_[i]) survivors.push_back(i);
    }

    std::vector<std::size_t> survivors;
    Index growths = 0;

private:
    std::vector<std::size_t> champion_;
    std::vector<Index> stamp_;
    std::vector<char> keep_;
    Index step_ = 0;
};

// ---------------------------------------------------------------------------------------------
// The barycentric contact mapper's points (BarycentricMapperMeshTopology createPointInTriangle /
// createPointInLine, apply, applyJT): point i lies in element[i] at coordinates (fx, fy).
class BarycentricContactPoints {
public:
    void reserve(std::size_t n) { points_.reserve(n); }
    void clear() { points_.clear(); }
    std::size_t size() const { return points_.size(); }

    // createPointInTriangle: the projection's coordinates, or those of the closest edge / corner.
    Index add_in_triangle(const V3& P, Index tri, const double* x, const Index* triangles) {
        const V3 p1 = load3(x, 3, triangles[3 * tri]);
        const V3 AB = load3(x, 3, triangles[3 * tri + 1]) - p1, AC = load3(x, 3, triangles[3 * tri + 2]) - p1;
        const V3 AQ = P - p1;
        const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
        const double b0 = dot(AQ, AB), b1 = dot(AQ, AC);
        const double det = A00 * A11 - A01 * A01;
        double fx = (b0 * A11 - b1 * A01) / det;
        double fy = (b1 * A00 - b0 * A01) / det;
        if (fx < 0 || fy < 0 || fx + fy > 1) {
            const double pAB = b0 / A00, pAC = b1 / A11;
            if (pAB < 0 && pAC < 0) {
                fx = 0.0;
                fy = 0.0;
            } else if (pAB < 1 && fy < 0) {
                fx = pAB;
                fy = 0.0;
            } else if (pAC < 1 && fx < 0) {
                fx = 0.0;
                fy = pAC;
            } else {
                const double pBC = (b1 - b0 + A00 - A01) / (A00 + A11 - 2 * A01);
                if (pBC < 0) {
                    fx = 1.0;
                    fy = 0.0;
                } else if (pBC > 1) {
                    fx = 0.0;
                    fy = 1.0;
                } else {
                    fx = 1.0 - pBC;
                    fy = pBC;
                }
            }
        }
        return push(Point{{triangles[3 * tri], triangles[3 * tri + 1], triangles[3 * tri + 2]}, fx, fy, 3});
    }

    // createPointInLine: not clamped; 0 on an edge shorter than sqrt(DBL_EPSILON).
    Index add_in_line(const V3& P, Index edge, const double* x, const Index* edges) {
        const V3 p0 = load3(x, 3, edges[2 * edge]);
        const V3 pA = load3(x, 3, edges[2 * edge + 1]) - p0, pos = P - p0;
        const double L2 = norm2(pA);
        const double fx = L2 < std::numeric_limits<double>::epsilon() ? 0.0 : dot(pos, pA) / L2;
        return push(Point{{edges[2 * edge], edges[2 * edge + 1], 0}, fx, 0.0, 2});
    }

    // out_i = in[a] (1 - fx - fy) + in[b] fx + in[c] fy   (positions, velocities or dx)
    void apply(const double* in, double* out) const {
        for (std::size_t i = 0; i < points_.size(); ++i) {
            const Point& p = points_[i];
            const V3 r = p.count == 3 ? load3(in, 3, p.v[0]) * (1 - p.fx - p.fy) + load3(in, 3, p.v[1]) * p.fx +
                                            load3(in, 3, p.v[2]) * p.fy
                                      : load3(in, 3, p.v[0]) * (1 - p.fx) + load3(in, 3, p.v[1]) * p.fx;
            for (int k = 0; k < 3; ++k) out[3 * i + k] = r[k];
        }
    }

    // in[a] += f_i (1 - fx - fy), in[b] += f_i fx, in[c] += f_i fy, point after point
    void apply_jt(const double* f, double* in_f) const {
        for (std::size_t i = 0; i < points_.size(); ++i) {
            const Point& p = points_[i];
            const V3 v = load3(f, 3, static_cast<Index>(i));
            if (p.count == 3) {
                add(in_f, p.v[0], v * (1 - p.fx - p.fy));
                add(in_f, p.v[1], v * p.fx);
                add(in_f, p.v[2], v * p.fy);
            } else {
                add(in_f, p.v[0], v * (1 - p.fx));
                add(in_f, p.v[1], v * p.fx);
            }
        }
    }

    // Point i's weights on its element's points (3 on a triangle, 2 on an edge).
    void weights(Index i, double* w) const {
        const Point& p = points_[static_cast<std::size_t>(i)];
        if (p.count == 3) {
            w[0] = 1 - p.fx - p.fy;
            w[1] = p.fx;
            w[2] = p.fy;
        } else {
            w[0] = 1 - p.fx;
            w[1] = p.fx;
        }
    }

    Index growths = 0;

private:
    struct Point {
        Index v[3];
        double fx, fy;
        int count;
    };
    static void add(double* a, Index i, const V3& v) {
        for (int k = 0; k < 3; ++k) a[3 * i + k] += v[k];
    }
    Index push(const Point& p) {
        if (points_.size() == points_.capacity()) ++growths;
        points_.push_back(p);
        return static_cast<Index>(points_.size()) - 1;
    }
    std::vector<Point> points_;
};

// ---------------------------------------------------------------------------------------------
// The rigid contact mapper of SphereCollisionModel<Rigid3d> (RigidContactMapper.{h,inl}: a
// RigidMapping from the spheres' frames onto the contact points): point i is fixed in frame
// frame[i] at local = q.inverseRotate(P - c), SOFA's quaternion arithmetic (quaternion.h).
// apply (RigidMapping::apply): rotated = q.rotate(local), x = rotated + c; apply_j (applyJ, with
// the rotated offsets of the last apply): v = v_c + w x rotated; apply_jt (applyJT): f_c += f,
// tau_c += rotated x f. Frames are Rigid3d: 7 numbers per coordinate, 6 per derivative.
class RigidContactPoints {
public:
    void reserve(std::size_t n) {
        points_.reserve(n);
    }
    void clear() { points_.clear(); }
    std::size_t size() const { return points_.size(); }

    // ContactMapper<RigidSphereModel>::addPoint: P in frame `frame` of the positions `x`.
    Index add(const V3& P, Index frame, const double* x) {
        const double* c = x + 7 * frame;
        const double d[3] = {P[0] - c[0], P[1] - c[1], P[2] - c[2]};
        Point p{frame, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};
        quat_rotate(c + 3, true, d, p.local);
        if (points_.size() == points_.capacity()) ++growths;
        points_.push_back(p);
        return static_cast<Index>(points_.size()) - 1;
    }

    void apply(const double* x, double* out) {
        for (std::size_t i = 0; i < points_.size(); ++i) {
            Point& p = points_[i];
            const double* c = x + 7 * p.frame;
            quat_rotate(c + 3, false, p.local, p.rotated);
            for (int k = 0; k < 3; ++k) out[3 * i + k] = p.rotated[k] + c[k];
        }
    }

    void apply_j(const double* v, double* out) const {
        for (std::size_t i = 0; i < points_.size(); ++i) {
            const Point& p = points_[i];
            const V3 w = load3(v + 6 * p.frame + 3, 3, 0), r = load3(p.rotated, 3, 0);
            const V3 u = load3(v + 6 * p.frame, 3, 0) + cross(w, r);
            for (int k = 0; k < 3; ++k) out[3 * i + k] = u[k];
        }
    }

    void apply_jt(const double* f, double* in_f) const {
        for (std::size_t i = 0; i < points_.size(); ++i) {
            const Point& p = points_[i];
            const V3 force = load3(f, 3, static_cast<Index>(i));
            double* frame = in_f + 6 * p.frame;
            for (int k = 0; k < 3; ++k) frame[k] += force[k];
            const V3 torque = cross(load3(p.rotated, 3, 0), force);
            for (int k = 0; k < 3; ++k) frame[3 + k] += torque[k];
        }
    }

    // Point i's frame and its offset from the frame's centre at the last apply.
    Index frame(Index i) const { return points_[static_cast<std::size_t>(i)].frame; }
    V3 rotated(Index i) const { return load3(points_[static_cast<std::size_t>(i)].rotated, 3, 0); }

    Index growths = 0;

private:
    struct Point {
        Index frame;
        double local[3];
        double rotated[3];
    };
    std::vector<Point> points_;
};

// ---------------------------------------------------------------------------------------------
// PenalityContactForceField<Vec3d> between two Vec3d states (the contact-point states; the same
// state twice is allowed). Contact c pushes x1[m1] and x2[m2] apart along `normal` while
// pen = dist - (x2[m2] - x1[m1]) . normal > 0: energy ks pen^2 / 2, f1 = -ks pen n, f2 = +ks pen n.
struct PenaltyContact {
    Index m1, m2;              // contact points in state 1 / state 2
    Index element1, element2;  // the detection output's elements
    V3 normal;
    double dist, ks, pen;
};

class PenaltyContactForceField {
public:
    void reserve(std::size_t n) { contacts.reserve(n); }
    void clear() { contacts.clear(); }

    void add_contact(Index m1, Index m2, Index element1, Index element2, const V3& normal, double dist, double ks) {
        if (contacts.size() == contacts.capacity()) ++growths;
        contacts.push_back(PenaltyContact{m1, m2, element1, element2, normal, dist, ks, 0.0});
    }

    // addForce: stores each contact's pen (addDForce and the matrix use it: a contact is active
    // for the whole step if it was at the last addForce).
    void add_force(double* f1, double* f2, const double* x1, const double* x2) {
        for (PenaltyContact& c : contacts) {
            const V3 u = load3(x2, 3, c.m2) - load3(x1, 3, c.m1);
            c.pen = c.dist - dot(u, c.normal);
            if (c.pen > 0) {
                const double fN = c.ks * c.pen;
                const V3 force = -c.normal * fN;
                for (int k = 0; k < 3; ++k) {
                    f1[3 * c.m1 + k] += force[k];
                    f2[3 * c.m2 + k] -= force[k];
                }
            }
        }
    }

    // addDForce: df += k_factor * K dx, with k_factor SOFA's kFactorIncludingRayleighDamping.
    void add_dforce(double* df1, double* df2, const double* dx1, const double* dx2, double k_factor) const {
        for (const PenaltyContact& c : contacts) {
            if (!(c.pen > 0)) continue;
            const V3 du = load3(dx2, 3, c.m2) - load3(dx1, 3, c.m1);
            const double dpen = -dot(du, c.normal);
            const double dfN = c.ks * dpen * k_factor;
            const V3 dforce = -c.normal * dfN;
            for (int k = 0; k < 3; ++k) {
                df1[3 * c.m1 + k] += dforce[k];
                df2[3 * c.m2 + k] -= dforce[k];
            }
        }
    }

    // addKToMatrix: `add(state_row, row, state_col, col, value)` with states 0 / 1 and scalar rows
    // 3 m + i: -k n n^T on (1,1) and (2,2), +k n n^T on (1,2) and (2,1), k = ks k_factor, in
    // SOFA's order (contact, then i, then j, then the four blocks).
    template <class Add>
    void add_k(double k_factor, Add&& add) const {
        for (const PenaltyContact& c : contacts) {
            if (!(c.pen > 0)) continue;
            const double k = c.ks * k_factor;
            for (int i = 0; i < 3; ++i) {
                for (int j = 0; j < 3; ++j) {
                    const double stiffness = k * c.normal[i] * c.normal[j];
                    add(0, 3 * c.m1 + i, 0, 3 * c.m1 + j, -stiffness);
                    add(0, 3 * c.m1 + i, 1, 3 * c.m2 + j, stiffness);
                    add(1, 3 * c.m2 + i, 0, 3 * c.m1 + j, stiffness);
                    add(1, 3 * c.m2 + i, 1, 3 * c.m2 + j, -stiffness);
                }
            }
        }
    }

    double energy() const {
        double e = 0;
        for (const PenaltyContact& c : contacts)
            if (c.pen > 0) e += 0.5 * c.ks * c.pen * c.pen;
        return e;
    }

    std::vector<PenaltyContact> contacts;
    Index growths = 0;
};

// How a model places its contact points (ContactMapper): on triangles and lines a barycentric
// point per contact; on points and Vec3d spheres the element itself, on Rigid3d spheres a point
// fixed in the sphere's frame (r = the sphere's radius for both sphere kinds).
enum class ContactSide { kTriangle, kLine, kPoint, kSphere };

struct ContactSideModel {
    ContactSide kind;
    const double* x;            // the collision model's positions (Vec3d; Rigid3d spheres: stride 7)
    const Index* elements;      // triangles (3 per) or edges (2 per); unused otherwise
    const SphereModel* sphere;  // kSphere only
    double contact_distance;
    double contact_stiffness;
    BarycentricContactPoints* points;  // kTriangle / kLine: the contact-point state's mapping
    RigidContactPoints* rigid = nullptr;  // kSphere on Rigid3d frames: the contact-point state's mapping
};

namespace detail {
inline Index add_contact_point(const ContactSideModel& side, const V3& P, Index element, double& r) {
    switch (side.kind) {
        case ContactSide::kTriangle:
            return side.points->add_in_triangle(P, element, side.x, side.elements);
        case ContactSide::kLine:
            return side.points->add_in_line(P, element, side.x, side.elements);
        case ContactSide::kSphere:
            r = side.sphere->r(element);
            return side.rigid ? side.rigid->add(P, element, side.x) : element;
        case ContactSide::kPoint:
            break;
    }
    return element;
}
}  // namespace detail

// BarycentricPenalityContact::setDetectionOutputs, after the de-duplication: the contact-point
// lists are rebuilt and one contact per survivor added, with dist = intersection contactDistance
// + both models' contactDistance + the radii, and ks = k1 k2 / dist (k1 k2 when dist is 0).
// The caller then maps positions (BarycentricContactPoints::apply) before add_force.
inline void set_penalty_contacts(const OutputList& outputs, const ContactDeduplication& dedup,
                                 double intersection_contact_distance, const ContactSideModel& side1,
                                 const ContactSideModel& side2, PenaltyContactForceField& ff) {
    ff.clear();
    for (const ContactSideModel* side : {&side1, &side2}) {
        if (side->points) side->points->clear();
        if (side->rigid) side->rigid->clear();
    }
    const double d0 = intersection_contact_distance + side1.contact_distance + side2.contact_distance;
    for (const std::size_t i : dedup.survivors) {
        const DetectionOutput& o = outputs[i];
        double r1 = 0.0, r2 = 0.0;
        const Index m1 = detail::add_contact_point(side1, o.point[0], o.elem1, r1);
        const Index m2 = detail::add_contact_point(side2, o.point[1], o.elem2, r2);
        const double distance = d0 + r1 + r2;
        double stiffness = side1.contact_stiffness * side2.contact_stiffness;
        if (distance != 0.0) stiffness /= distance;
        ff.add_contact(m1, m2, o.elem1, o.elem2, o.normal, distance, stiffness);
    }
}

}  // namespace sofac::collide
