// The element tests of SOFA's proximity intersection methods, MinProximityIntersection and
// NewProximityIntersection, with SOFA's formulas, thresholds, output fields and emission order
// (docs/collision-runtime.md maps each function to its SOFA source). A test appends 0..n detection
// outputs to an OutputList and returns how many.
//
// Element order is the intersector's (SOFA registers e.g. Triangle-Point, never Point-Triangle):
// elem1 / point[0] belong to the first model, elem2 / point[1] to the second, and the normal points
// from point[0] to point[1] unless SOFA says otherwise (noted). value = distance - contact distance.
//
// Where SOFA's arithmetic yields NaN (0/0 on a zero-length edge, coincident points or spheres, a
// triangle of zero area) sofac does not hand a NaN to the response: a zero-length edge projects on
// its first point (the limit SOFA's formula has for a short edge), a zero distance takes SOFA's own
// fallback normal (1, 0, 0), and any other output that is not finite is dropped; both events are
// counted in the OutputList, so the step can report them.
#pragma once

#include <cmath>
#include <limits>
#include <vector>

#include "collision.h"

namespace sofac::collide {

struct DetectionOutput {
    V3 point[2];
    V3 normal;
    double value;
    Index elem1, elem2;
    Index id;
};

// Contact outputs of one model pair. reserve() once; a step that needs more keeps working (the
// vector grows) and counts it in `growths`, which the step reports so the capacity can be raised.
class OutputList {
public:
    void reserve(std::size_t n) { items_.reserve(n); }
    void clear() { items_.clear(); }
    std::size_t size() const { return items_.size(); }
    const DetectionOutput& operator[](std::size_t i) const { return items_[i]; }
    DetectionOutput& operator[](std::size_t i) { return items_[i]; }
    void push(const DetectionOutput& o) {
        if (items_.size() == items_.capacity()) ++growths;
        items_.push_back(o);
    }
    Index growths = 0;
    Index zero_distances = 0;  // outputs given SOFA's fallback normal (1, 0, 0)
    Index dropped = 0;         // outputs SOFA would have made of NaN

private:
    std::vector<DetectionOutput> items_;
};

// ---------------------------------------------------------------------------------------------
// The collision models' element data (Vec3d positions, 3 doubles per point).

struct PointModel {
    const double* x;
    Index size;
    double contact_distance;
    V3 p(Index i) const { return load3(x, 3, i); }
};

struct LineModel {
    const double* x;
    const Index* edges;  // (size, 2)
    Index size;
    double contact_distance;
    V3 p1(Index e) const { return load3(x, 3, edges[2 * e]); }
    V3 p2(Index e) const { return load3(x, 3, edges[2 * e + 1]); }
};

struct TriangleModel {
    const double* x;
    const Index* triangles;  // (size, 3)
    const int* flags;        // triangle_flags()
    const double* normals;   // (size, 3), triangle_normal(); read only with useSurfaceNormals
    Index size;
    double contact_distance;
    V3 p(Index t, int j) const { return load3(x, 3, triangles[3 * t + j]); }
    Index point(Index t, int j) const { return triangles[3 * t + j]; }
};

// SphereCollisionModel<Vec3d> (stride 3) or <Rigid3d> (stride 7, the centre is the translation).
struct SphereModel {
    const double* x;
    Index stride;
    const double* radii;  // listRadius, may be shorter than the model (then `radius` applies)
    Index n_radii;
    double radius;
    Index size;
    double contact_distance;
    V3 center(Index i) const { return load3(x, stride, i); }
    double r(Index i) const { return i < n_radii ? radii[i] : radius; }
    // TSphere::getContactPointByNormal: the centre for Vec3d spheres, the surface point
    // centre - n r for rigid ones.
    V3 contact_point(Index i, const V3& n) const { return stride == 3 ? center(i) : center(i) - n * r(i); }
};

struct Proximity {
    double alarm_distance;
    double contact_distance;
};

namespace detail {

inline bool finite(const DetectionOutput& o) {
    double s = o.value;
    for (int k = 0; k < 3; ++k) s += o.point[0][k] + o.point[1][k] + o.normal[k];
    return std::isfinite(s);
}

// Appends o unless it holds a NaN / infinity (then counts it): the single exit of every test.
inline int emit(OutputList& out, const DetectionOutput& o) {
    if (!finite(o)) {
        ++out.dropped;
        return 0;
    }
    out.push(o);
    return 1;
}

// normal = d / |d| with MeshMinProximityIntersection's guard (|d| <= 1e-15 -> (1, 0, 0)); returns |d|.
inline double guarded_normal(const V3& d, V3& normal, OutputList& out) {
    const double length = std::sqrt(norm2(d));
    if (length > 1e-15) {
        normal = d / length;
    } else {
        normal = V3{{1.0, 0.0, 0.0}};
        ++out.zero_distances;
    }
    return length;
}

// normal = d / |d| where SOFA divides unguarded (NewProximity's kernels, DiscreteIntersection's
// sphere-sphere): the same numbers whenever |d| > 0, SOFA's (1, 0, 0) when it is 0.
inline V3 unit(const V3& d, double length, OutputList& out) {
    if (length > 0) return d / length;
    ++out.zero_distances;
    return V3{{1.0, 0.0, 0.0}};
}

inline Index larger_model_index(Index size1, Index e1, Index size2, Index e2) { return size1 > size2 ? e1 : e2; }

}  // namespace detail

// =============================================================================================
// MinProximityIntersection (MinProximityIntersection.h, MeshMinProximityIntersection.{h,cpp},
// DiscreteIntersection.h for sphere-sphere).
namespace min_proximity {

inline int point_point(const Proximity& m, const PointModel& a, Index e1, const PointModel& b, Index e2,
                       OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const V3 p = a.p(e1), q = b.p(e2), pq = q - p;
    if (norm2(pq) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = e1;
    o.elem2 = e2;
    o.id = detail::larger_model_index(a.size, e1, b.size, e2);
    o.point[0] = p;
    o.point[1] = q;
    const double contact = m.contact_distance + a.contact_distance + b.contact_distance;
    o.value = detail::guarded_normal(pq, o.normal, out) - contact;
    return detail::emit(out, o);
}

// Line (first) - Point: the projection is clamped to the segment.
inline int line_point(const Proximity& m, const LineModel& a, Index line, const PointModel& b, Index point,
                      OutputList& out) {
    const double alarm = m.alarm_distance + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p1(line), p2 = a.p2(line), P = b.p(point);
    const V3 AB = p2 - p1, AP = P - p1;
    const double A = dot(AB, AB), bb = dot(AP, AB);
    const double alpha = A > 0 ? bb / A : 0.0;  // zero-length edge: SOFA's 0/0, its first point here
    V3 Q;
    if (alpha <= 0.0)
        Q = p1;
    else if (alpha >= 1.0)
        Q = p2;
    else
        Q = p1 + AB * alpha;
    const V3 QP = P - Q;
    if (norm2(QP) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = line;
    o.elem2 = point;
    o.id = point;
    o.point[0] = Q;
    o.point[1] = P;
    const double contact = m.contact_distance + b.contact_distance + a.contact_distance;
    o.value = detail::guarded_normal(QP, o.normal, out) - contact;
    return detail::emit(out, o);
}

inline int line_line(const Proximity& m, const LineModel& a, Index e1, const LineModel& b, Index e2, OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const V3 a1 = a.p1(e1), a2 = a.p2(e1), c1 = b.p1(e2), c2 = b.p2(e2);
    const V3 AB = a2 - a1, CD = c2 - c1, AC = c1 - a1;
    const double A00 = dot(AB, AB), A11 = dot(CD, CD), A01 = -dot(CD, AB);
    const double b0 = dot(AB, AC), b1 = -dot(CD, AC);
    const double det = A00 * A11 - A01 * A01;
    double alpha = 0.5, beta = 0.5;
    if (det < -1.0e-15 || det > 1.0e-15) {
        alpha = (b0 * A11 - b1 * A01) / det;
        beta = (b1 * A00 - b0 * A01) / det;
        if (alpha < 0.000001 || alpha > 0.999999 || beta < 0.000001 || beta > 0.999999) return 0;
    }
    const V3 P = a1 + AB * alpha, Q = c1 + CD * beta, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = e1;
    o.elem2 = e2;
    o.id = detail::larger_model_index(a.size, e1, b.size, e2);
    o.point[0] = P;
    o.point[1] = Q;
    const double contact = m.contact_distance + a.contact_distance + b.contact_distance;
    o.value = detail::guarded_normal(PQ, o.normal, out) - contact;
    return detail::emit(out, o);
}

// Triangle (first) - Point: the projection must fall strictly inside (1e-6 margins); with
// use_surface_normals the output normal is the triangle's stored normal.
inline int triangle_point(const Proximity& m, const TriangleModel& a, Index tri, const PointModel& b, Index point,
                          bool use_surface_normals, OutputList& out) {
    const double alarm = m.alarm_distance + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p(tri, 0), p2 = a.p(tri, 1), p3 = a.p(tri, 2), P = b.p(point);
    const V3 AB = p2 - p1, AC = p3 - p1, AP = P - p1;
    const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
    const double b0 = dot(AP, AB), b1 = dot(AP, AC);
    const double det = A00 * A11 - A01 * A01;
    if (det == 0) return 0;  // zero area: SOFA's 0/0 lets only NaN outputs through
    const double alpha = (b0 * A11 - b1 * A01) / det;
    const double beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) return 0;
    const V3 Q = p1 + AB * alpha + AC * beta;
    const V3 QP = P - Q;
    if (norm2(QP) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = tri;
    o.elem2 = point;
    o.id = point;
    o.point[0] = Q;
    o.point[1] = P;
    const double contact = m.contact_distance + b.contact_distance + a.contact_distance;
    o.value = detail::guarded_normal(QP, o.normal, out) - contact;
    if (use_surface_normals) o.normal = load3(a.normals, 3, tri);
    return detail::emit(out, o);
}

// DiscreteIntersection::computeIntersectionSphere (note: rejects only beyond the alarm distance,
// `>`, where the other tests reject at it, `>=`).
inline int sphere_sphere(const Proximity& m, const SphereModel& a, Index e1, const SphereModel& b, Index e2,
                         OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const double contact = m.contact_distance + a.contact_distance + b.contact_distance;
    const double r = a.r(e1) + b.r(e2);
    const double reach = alarm + r;
    const V3 d = b.center(e2) - a.center(e1);
    const double n2 = norm2(d);
    if (n2 > reach * reach) return 0;
    DetectionOutput o;
    const double length = std::sqrt(n2);
    o.normal = detail::unit(d, length, out);
    o.point[0] = a.contact_point(e1, -o.normal);
    o.point[1] = b.contact_point(e2, o.normal);
    o.value = length - r - contact;
    o.elem1 = e1;
    o.elem2 = e2;
    o.id = detail::larger_model_index(a.size, e1, b.size, e2);
    return detail::emit(out, o);
}

inline int sphere_point(const Proximity& m, const SphereModel& a, Index sphere, const PointModel& b, Index point,
                        OutputList& out) {
    const double r = a.r(sphere);
    const double alarm = m.alarm_distance + r + a.contact_distance + b.contact_distance;
    const V3 P = a.center(sphere), Q = b.p(point), PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = sphere;
    o.elem2 = point;
    o.id = sphere;
    const double contact = m.contact_distance + r + a.contact_distance + b.contact_distance;
    o.value = detail::guarded_normal(PQ, o.normal, out) - contact;
    o.point[0] = a.contact_point(sphere, -o.normal);
    o.point[1] = Q;
    return detail::emit(out, o);
}

// Triangle (first) - Sphere, parametrised from p1 with x13 = p1 - p2, x23 = p1 - p3 (SOFA's form).
inline int triangle_sphere(const Proximity& m, const TriangleModel& a, Index tri, const SphereModel& b, Index sphere,
                           OutputList& out) {
    const double r = b.r(sphere);
    const double alarm = m.alarm_distance + r + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p(tri, 0), c = b.center(sphere);
    const V3 x13 = p1 - a.p(tri, 1), x23 = p1 - a.p(tri, 2), x03 = p1 - c;
    const double A00 = dot(x13, x13), A11 = dot(x23, x23), A01 = dot(x13, x23);
    const double b0 = dot(x13, x03), b1 = dot(x23, x03);
    const double det = A00 * A11 - A01 * A01;
    if (det == 0) return 0;  // zero area (see triangle_point)
    const double alpha = (b0 * A11 - b1 * A01) / det;
    const double beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) return 0;
    const V3 Q = p1 - x13 * alpha - x23 * beta;
    const V3 QP = c - Q;
    if (norm2(QP) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = tri;
    o.elem2 = sphere;
    o.id = sphere;
    const double contact = m.contact_distance + r + b.contact_distance + a.contact_distance;
    o.value = detail::guarded_normal(QP, o.normal, out) - contact;
    o.point[0] = Q;
    o.point[1] = b.contact_point(sphere, o.normal);
    return detail::emit(out, o);
}

// Line (first) - Sphere. SOFA measures alpha from p2 (x32 = p1 - p2, x31 = c - p2) but places the
// point from p1 (Q = p1 - x32 alpha): Q is the centre's projection mirrored about the edge's middle.
// Reproduced as is; no clamping, alpha outside [1e-6, 0.999999] gives no contact.
inline int line_sphere(const Proximity& m, const LineModel& a, Index line, const SphereModel& b, Index sphere,
                       OutputList& out) {
    const double r = b.r(sphere);
    const double alarm = m.alarm_distance + r + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p1(line), p2 = a.p2(line), c = b.center(sphere);
    const V3 x32 = p1 - p2, x31 = c - p2;
    const double A = dot(x32, x32), bb = dot(x32, x31);
    const double alpha = bb / A;  // zero-length edge: NaN, rejected by the test below as in SOFA
    if (!(alpha >= 0.000001 && alpha <= 0.999999)) return 0;
    const V3 Q = p1 - x32 * alpha;
    const V3 QP = c - Q;
    if (norm2(QP) >= alarm * alarm) return 0;
    DetectionOutput o;
    o.elem1 = line;
    o.elem2 = sphere;
    o.id = sphere;
    const double contact = m.contact_distance + r + b.contact_distance + a.contact_distance;
    o.value = detail::guarded_normal(QP, o.normal, out) - contact;
    o.point[0] = Q;
    o.point[1] = b.contact_point(sphere, o.normal);
    return detail::emit(out, o);
}

}  // namespace min_proximity

// =============================================================================================
// NewProximityIntersection (NewProximityIntersection.{h,inl}, MeshNewProximityIntersection.{h,inl,cpp}).
// Each kernel writes points, normal, value = |pq| and id; the element test then sets the elements
// and subtracts the contact distance from every output it added.
namespace new_proximity {

namespace kernel {

// doIntersectionPointPoint
inline int point_point(double dist2, const V3& p, const V3& q, Index id, OutputList& out) {
    const V3 pq = q - p;
    const double n2 = norm2(pq);
    if (n2 >= dist2) return 0;
    DetectionOutput o{};
    o.id = id;
    o.point[0] = p;
    o.point[1] = q;
    o.value = std::sqrt(n2);
    o.normal = detail::unit(pq, o.value, out);
    return detail::emit(out, o);
}

// doIntersectionLinePoint: the projection of q on [p1, p2], clamped; with `swap`, point[0] is q
// and the normal points from q to the segment.
inline int line_point(double dist2, const V3& p1, const V3& p2, const V3& q, Index id, bool swap, OutputList& out) {
    const V3 AB = p2 - p1, AQ = q - p1;
    const double A = dot(AB, AB), b = dot(AQ, AB);
    double alpha = A > 0 ? b / A : 0.0;  // zero-length edge: SOFA's 0/0, its first point here
    if (alpha < 0.0)
        alpha = 0.0;
    else if (alpha > 1.0)
        alpha = 1.0;
    const V3 p = p1 + AB * alpha, pq = q - p;
    const double n2 = norm2(pq);
    if (n2 >= dist2) return 0;
    DetectionOutput o{};
    o.id = id;
    o.value = std::sqrt(n2);
    const V3 n = detail::unit(pq, o.value, out);
    if (swap) {
        o.point[0] = q;
        o.point[1] = p;
        o.normal = -n;
    } else {
        o.point[0] = p;
        o.point[1] = q;
        o.normal = n;
    }
    return detail::emit(out, o);
}

// doIntersectionLineLine: interior closest points only (1e-6 margins); parallel (|det| <= 1e-12)
// segments are compared at their middles.
inline int line_line(double dist2, const V3& p1, const V3& p2, const V3& q1, const V3& q2, Index id, OutputList& out) {
    const V3 AB = p2 - p1, CD = q2 - q1, AC = q1 - p1;
    const double A00 = dot(AB, AB), A11 = dot(CD, CD), A01 = -dot(CD, AB);
    const double b0 = dot(AB, AC), b1 = -dot(CD, AC);
    const double det = A00 * A11 - A01 * A01;
    double alpha = 0.5, beta = 0.5;
    if (det < -0.000000000001 || det > 0.000000000001) {
        alpha = (b0 * A11 - b1 * A01) / det;
        beta = (b1 * A00 - b0 * A01) / det;
        if (alpha < 0.000001 || alpha > 0.999999 || beta < 0.000001 || beta > 0.999999) return 0;
    }
    const V3 p = p1 + AB * alpha, q = q1 + CD * beta, pq = q - p;
    const double n2 = norm2(pq);
    if (n2 >= dist2) return 0;
    DetectionOutput o{};
    o.id = id;
    o.point[0] = p;
    o.point[1] = q;
    o.value = std::sqrt(n2);
    o.normal = detail::unit(pq, o.value, out);
    return detail::emit(out, o);
}

// doIntersectionTrianglePoint: the closest point of triangle (p1, p2, p3) to q, interior or on the
// feature (corner, edge) the Voronoi tests pick with DBL_EPSILON margins; a feature the triangle
// does not own (`flags`) gives no contact, another triangle reports it.
inline int triangle_point(double dist2, int flags, const V3& p1, const V3& p2, const V3& p3, const V3& q, Index id,
                          bool swap, OutputList& out) {
    const V3 AB = p2 - p1, AC = p3 - p1, AQ = q - p1;
    const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
    const double b0 = dot(AQ, AB), b1 = dot(AQ, AC);
    const double det = A00 * A11 - A01 * A01;
    const double eps = std::numeric_limits<double>::epsilon();
    double alpha = (b0 * A11 - b1 * A01) / det;
    double beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < eps || beta < eps || alpha + beta > 1 - eps) {
        const double pAB = b0 / A00, pAC = b1 / A11;
        if (pAB < eps && pAC < eps) {
            if (!(flags & FLAG_P1)) return 0;
            alpha = 0.0;
            beta = 0.0;
        } else if (pAB < 1 - eps && pAB >= eps && beta < eps) {
            if (!(flags & FLAG_E12)) return 0;
            alpha = pAB;
            beta = 0.0;
        } else if (pAC < 1 - eps && pAC >= eps && alpha < eps) {
            if (!(flags & FLAG_E31)) return 0;
            alpha = 0.0;
            beta = pAC;
        } else {
            const double pBC = (b1 - b0 + A00 - A01) / (A00 + A11 - 2 * A01);
            if (pBC < eps) {
                if (!(flags & FLAG_P2)) return 0;
                alpha = 1.0;
                beta = 0.0;
            } else if (pBC > 1 - eps) {
                if (!(flags & FLAG_P3)) return 0;
                alpha = 0.0;
                beta = 1.0;
            } else {
                if (!(flags & FLAG_E23)) return 0;
                alpha = 1.0 - pBC;
                beta = pBC;
            }
        }
    }
    const V3 p = p1 + AB * alpha + AC * beta, pq = q - p;
    const double n2 = norm2(pq);
    if (n2 >= dist2) return 0;
    DetectionOutput o{};
    o.id = id;
    o.value = std::sqrt(n2);
    const V3 n = detail::unit(pq, o.value, out);
    if (swap) {
        o.point[0] = q;
        o.point[1] = p;
        o.normal = -n;
    } else {
        o.point[0] = p;
        o.point[1] = q;
        o.normal = n;
    }
    return detail::emit(out, o);
}

}  // namespace kernel

// The element tests' epilogue: elements and value -= contact distance on the last n outputs.
inline int finish(OutputList& out, int n, Index e1, Index e2, double contact) {
    for (std::size_t i = out.size() - static_cast<std::size_t>(n); i < out.size(); ++i) {
        out[i].elem1 = e1;
        out[i].elem2 = e2;
        out[i].value -= contact;
    }
    return n;
}

inline int point_point(const Proximity& m, const PointModel& a, Index e1, const PointModel& b, Index e2,
                       OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const Index id = detail::larger_model_index(a.size, e1, b.size, e2);
    const int n = kernel::point_point(alarm * alarm, a.p(e1), b.p(e2), id, out);
    return finish(out, n, e1, e2, m.contact_distance + a.contact_distance + b.contact_distance);
}

inline int line_point(const Proximity& m, const LineModel& a, Index line, const PointModel& b, Index point,
                      OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const int n = kernel::line_point(alarm * alarm, a.p1(line), a.p2(line), b.p(point), point, false, out);
    return finish(out, n, line, point, m.contact_distance + a.contact_distance + b.contact_distance);
}

inline int line_line(const Proximity& m, const LineModel& a, Index e1, const LineModel& b, Index e2, OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const int n = kernel::line_line(alarm * alarm, a.p1(e1), a.p2(e1), b.p1(e2), b.p2(e2),
                                    detail::larger_model_index(a.size, e1, b.size, e2), out);
    return finish(out, n, e1, e2, m.contact_distance + a.contact_distance + b.contact_distance);
}

inline int triangle_point(const Proximity& m, const TriangleModel& a, Index tri, const PointModel& b, Index point,
                          OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const int n = kernel::triangle_point(alarm * alarm, a.flags[tri], a.p(tri, 0), a.p(tri, 1), a.p(tri, 2),
                                         b.p(point), point, false, out);
    return finish(out, n, tri, point, m.contact_distance + a.contact_distance + b.contact_distance);
}

// Triangle - Line: the line against each vertex the triangle owns, then each end of the line
// against the triangle, then (use_line_line) each owned edge against the line; id = line index.
inline int triangle_line(const Proximity& m, const TriangleModel& a, Index tri, const LineModel& b, Index line,
                         bool use_line_line, OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const double dist2 = alarm * alarm;
    const V3 p1 = a.p(tri, 0), p2 = a.p(tri, 1), p3 = a.p(tri, 2), q1 = b.p1(line), q2 = b.p2(line);
    const int f = a.flags[tri];
    int n = 0;
    if (f & FLAG_P1) n += kernel::line_point(dist2, q1, q2, p1, line, true, out);
    if (f & FLAG_P2) n += kernel::line_point(dist2, q1, q2, p2, line, true, out);
    if (f & FLAG_P3) n += kernel::line_point(dist2, q1, q2, p3, line, true, out);
    n += kernel::triangle_point(dist2, f, p1, p2, p3, q1, line, false, out);
    n += kernel::triangle_point(dist2, f, p1, p2, p3, q2, line, false, out);
    if (use_line_line) {
        if (f & FLAG_E12) n += kernel::line_line(dist2, p1, p2, q1, q2, line, out);
        if (f & FLAG_E23) n += kernel::line_line(dist2, p2, p3, q1, q2, line, out);
        if (f & FLAG_E31) n += kernel::line_line(dist2, p3, p1, q1, q2, line, out);
    }
    return finish(out, n, tri, line, m.contact_distance + a.contact_distance + b.contact_distance);
}

// Triangle - Triangle. Triangles of one model sharing a vertex never meet. e1's vertices against
// e2 (point[0] on e1; SOFA tests e1's first vertex without looking at FLAG_P1, the other two
// only when e1 owns them), then e2's owned vertices against e1, then (use_line_line) owned edge
// pairs. ids: e1.index * 3 + k for e1's vertices, size1 * 3 + e2.index * 12 + k for the rest.
// (bothSide only rewrites stored normals no kernel reads: it has no effect here.)
inline int triangle_triangle(const Proximity& m, const TriangleModel& a, Index e1, const TriangleModel& b, Index e2,
                             bool same_model, bool use_line_line, OutputList& out) {
    if (same_model) {
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                if (a.point(e1, i) == b.point(e2, j)) return 0;
    }
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const double dist2 = alarm * alarm;
    const V3 p1 = a.p(e1, 0), p2 = a.p(e1, 1), p3 = a.p(e1, 2);
    const V3 q1 = b.p(e2, 0), q2 = b.p(e2, 1), q3 = b.p(e2, 2);
    const int f1 = a.flags[e1], f2 = b.flags[e2];
    const Index id1 = e1 * 3;
    const Index id2 = a.size * 3 + e2 * 12;
    int n = 0;
    n += kernel::triangle_point(dist2, f2, q1, q2, q3, p1, id1 + 0, true, out);
    if (f1 & FLAG_P2) n += kernel::triangle_point(dist2, f2, q1, q2, q3, p2, id1 + 1, true, out);
    if (f1 & FLAG_P3) n += kernel::triangle_point(dist2, f2, q1, q2, q3, p3, id1 + 2, true, out);
    if (f2 & FLAG_P1) n += kernel::triangle_point(dist2, f1, p1, p2, p3, q1, id2 + 0, false, out);
    if (f2 & FLAG_P2) n += kernel::triangle_point(dist2, f1, p1, p2, p3, q2, id2 + 1, false, out);
    if (f2 & FLAG_P3) n += kernel::triangle_point(dist2, f1, p1, p2, p3, q3, id2 + 2, false, out);
    if (use_line_line) {
        const V3* pe[3][2] = {{&p1, &p2}, {&p2, &p3}, {&p3, &p1}};
        const V3* qe[3][2] = {{&q1, &q2}, {&q2, &q3}, {&q3, &q1}};
        const int edge_flag[3] = {FLAG_E12, FLAG_E23, FLAG_E31};
        for (int i = 0; i < 3; ++i) {
            if (!(f1 & edge_flag[i])) continue;
            for (int j = 0; j < 3; ++j)
                if (f2 & edge_flag[j])
                    n += kernel::line_line(dist2, *pe[i][0], *pe[i][1], *qe[j][0], *qe[j][1], id2 + 3 + 3 * i + j,
                                           out);
        }
    }
    return finish(out, n, e1, e2, m.contact_distance + a.contact_distance + b.contact_distance);
}

// Sphere - Sphere through the point-point kernel with the radii added to both distances.
inline int sphere_sphere(const Proximity& m, const SphereModel& a, Index e1, const SphereModel& b, Index e2,
                         OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance + a.r(e1) + b.r(e2);
    const int n = kernel::point_point(alarm * alarm, a.center(e1), b.center(e2),
                                      detail::larger_model_index(a.size, e1, b.size, e2), out);
    return finish(out, n, e1, e2, m.contact_distance + a.contact_distance + b.contact_distance + a.r(e1) + b.r(e2));
}

inline int sphere_point(const Proximity& m, const SphereModel& a, Index sphere, const PointModel& b, Index point,
                        OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance + a.r(sphere);
    const int n = kernel::point_point(alarm * alarm, a.center(sphere), b.p(point),
                                      detail::larger_model_index(a.size, sphere, b.size, point), out);
    return finish(out, n, sphere, point, m.contact_distance + a.contact_distance + b.contact_distance + a.r(sphere));
}

inline int line_sphere(const Proximity& m, const LineModel& a, Index line, const SphereModel& b, Index sphere,
                       OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance + b.r(sphere);
    const int n = kernel::line_point(alarm * alarm, a.p1(line), a.p2(line), b.center(sphere), sphere, false, out);
    return finish(out, n, line, sphere, m.contact_distance + a.contact_distance + b.contact_distance + b.r(sphere));
}

// Triangle - Sphere: its own copy of the feature logic, with SOFA's differences kept: 1e-6
// margins, `pAC < 1e-7` in the corner test, FLAG_E12 checked for edge AC and FLAG_E31 for edge BC,
// the guarded normal, and point[1] = the sphere's contact point.
inline int triangle_sphere(const Proximity& m, const TriangleModel& a, Index tri, const SphereModel& b, Index sphere,
                           OutputList& out) {
    const int flags = a.flags[tri];
    const double r = b.r(sphere);
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance + r;
    const double dist2 = alarm * alarm;
    const V3 p1 = a.p(tri, 0), c = b.center(sphere);
    const V3 AB = a.p(tri, 1) - p1, AC = a.p(tri, 2) - p1, AQ = c - p1;
    const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
    const double b0 = dot(AQ, AB), b1 = dot(AQ, AC);
    const double det = A00 * A11 - A01 * A01;
    double alpha = (b0 * A11 - b1 * A01) / det;
    double beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) {
        const double pAB = b0 / A00, pAC = b1 / A11;
        if (pAB < 0.000001 && pAC < 0.0000001) {
            if (!(flags & FLAG_P1)) return 0;
            alpha = 0.0;
            beta = 0.0;
        } else if (pAB < 0.999999 && beta < 0.000001) {
            if (!(flags & FLAG_E12)) return 0;
            alpha = pAB;
            beta = 0.0;
        } else if (pAC < 0.999999 && alpha < 0.000001) {
            if (!(flags & FLAG_E12)) return 0;
            alpha = 0.0;
            beta = pAC;
        } else {
            const double pBC = (b1 - b0 + A00 - A01) / (A00 + A11 - 2 * A01);
            if (pBC < 0.000001) {
                if (!(flags & FLAG_P2)) return 0;
                alpha = 1.0;
                beta = 0.0;
            } else if (pBC > 0.999999) {
                if (!(flags & FLAG_P3)) return 0;
                alpha = 0.0;
                beta = 1.0;
            } else {
                if (!(flags & FLAG_E31)) return 0;
                alpha = 1.0 - pBC;
                beta = pBC;
            }
        }
    }
    const V3 p = p1 + AB * alpha + AC * beta, pq = c - p;
    const double n2 = norm2(pq);
    if (n2 >= dist2) return 0;
    DetectionOutput o;
    o.elem1 = tri;
    o.elem2 = sphere;
    o.id = sphere;
    o.value = std::sqrt(n2);
    if (o.value > 1e-15) {
        o.normal = pq / o.value;
    } else {
        o.normal = V3{{1.0, 0.0, 0.0}};
        ++out.zero_distances;
    }
    o.value -= m.contact_distance + a.contact_distance + b.contact_distance + r;
    o.point[0] = p;
    o.point[1] = b.contact_point(sphere, o.normal);
    return detail::emit(out, o);
}

}  // namespace new_proximity

}  // namespace sofac::collide

namespace sofac::collide {

// ---------------------------------------------------------------------------------------------
// One step of a model's bounding tree: the leaf boxes from the current positions, then
// CubeTree::update() (built at the first call, refitted after). A static model (moving = 0,
// simulated = 0) is updated once: SOFA freezes its boxes and normals after the first build.

inline void update_tree(CubeTree& tree, const PointModel& m) {
    for (Index i = 0; i < m.size; ++i) tree.set_box(i, point_box(m.p(i), m.contact_distance));
    tree.update();
}

inline void update_tree(CubeTree& tree, const LineModel& m) {
    for (Index i = 0; i < m.size; ++i) tree.set_box(i, line_box(m.p1(i), m.p2(i), m.contact_distance));
    tree.update();
}

// `normals` (size x 3) receives the triangles' normals when computeNormals is set (not null).
inline void update_tree(CubeTree& tree, const TriangleModel& m, double* normals) {
    for (Index i = 0; i < m.size; ++i) {
        const V3 p1 = m.p(i, 0), p2 = m.p(i, 1), p3 = m.p(i, 2);
        tree.set_box(i, triangle_box(p1, p2, p3, m.contact_distance));
        if (normals) {
            const V3 n = triangle_normal(p1, p2, p3);
            for (int k = 0; k < 3; ++k) normals[3 * i + k] = n[k];
        }
    }
    tree.update();
}

inline void update_tree(CubeTree& tree, const SphereModel& m) {
    for (Index i = 0; i < m.size; ++i) tree.set_box(i, sphere_box(m.center(i), m.r(i), m.contact_distance));
    tree.update();
}

// ---------------------------------------------------------------------------------------------
// Topology adjacency lists in ascending element order (MeshTopology's), in CSR form:
// the items of entry i are items[offsets[i] .. offsets[i + 1]).
struct Adjacency {
    const Index* offsets;
    const Index* items;
    Index count(Index i) const { return offsets[i + 1] - offsets[i]; }
    Index at(Index i, Index k) const { return items[offsets[i] + k]; }
};

// The element filters of a self-colliding model (canCollideWithElement), asked only when both
// elements belong to models of the same node with selfCollision set. SOFA asks them through
// CollisionElementIterator::canCollideWith, which also wants index < index2 within one model
// (SelfCollisionFilter below combines the two).
//
// PointCollisionModel, both elements in the model: only index > index2, and not when a neighbour
// of one is the other or a neighbour of both (SOFA's loop runs only when both have neighbours).
// With canCollideWith's index < index2 no pair of one point model ever passes.
inline bool points_can_collide(Index index, Index index2, const Adjacency& vertices_around_vertex) {
    if (index <= index2) return false;
    const Index n1 = vertices_around_vertex.count(index), n2 = vertices_around_vertex.count(index2);
    for (Index i1 = 0; i1 < n1; ++i1) {
        const Index v1 = vertices_around_vertex.at(index, i1);
        for (Index i2 = 0; i2 < n2; ++i2) {
            const Index v2 = vertices_around_vertex.at(index2, i2);
            if (v1 == v2 || v1 == index2 || index == v2) return false;
        }
    }
    return true;
}

// LineCollisionModel, both elements in the model: not when they share a point, nor when an edge
// touches an end of each.
inline bool lines_can_collide(Index line, Index line2, const Index* edges, const Adjacency& edges_around_vertex) {
    const Index p11 = edges[2 * line], p12 = edges[2 * line + 1];
    const Index p21 = edges[2 * line2], p22 = edges[2 * line2 + 1];
    if (p11 == p21 || p11 == p22 || p12 == p21 || p12 == p22) return false;
    for (const Index p1 : {p11, p12})
        for (Index i1 = 0; i1 < edges_around_vertex.count(p1); ++i1) {
            const Index e = edges_around_vertex.at(p1, i1);
            for (const Index p2 : {p21, p22})
                for (Index i2 = 0; i2 < edges_around_vertex.count(p2); ++i2)
                    if (e == edges_around_vertex.at(p2, i2)) return false;
        }
    return true;
}

// TriangleCollisionModel against the point model of its own node: not a vertex of the triangle.
// (Against anything else it always answers true.)
inline bool triangle_point_can_collide(const TriangleModel& m, Index tri, Index point) {
    return point != m.point(tri, 0) && point != m.point(tri, 1) && point != m.point(tri, 2);
}

// LineCollisionModel against the point model of its node (its `mpoints`): not an end of the line,
// nor an end of an edge around either end (edges_around_vertex indexes the line model's edges).
inline bool line_point_can_collide(Index line, Index point, const Index* edges, const Adjacency& edges_around_vertex) {
    for (const Index p : {edges[2 * line], edges[2 * line + 1]}) {
        if (point == p) return false;
    }
    for (const Index p : {edges[2 * line], edges[2 * line + 1]})
        for (Index i = 0; i < edges_around_vertex.count(p); ++i) {
            const Index e = edges_around_vertex.at(p, i);
            if (point == edges[2 * e] || point == edges[2 * e + 1]) return false;
        }
    return true;
}

// BVHNarrowPhase's test before each element pair of two models of one node (both selfCollision):
// CollisionElementIterator::canCollideWith, (model1 != model2 || e1 < e2) &&
// model1->canCollideWithElement(e1, model2, e2), e1 on the intersector's first model. The planner
// picks the rule from the models (compiler/plan/contacts.py): the pairs of one point model never
// pass (no filter object: their narrow phase is not run), other pairs of one node pass always.
struct SelfCollisionFilter {
    enum Rule : int {
        kSameModel = 1,      // triangles, spheres: e1 < e2 (their canCollideWithElement says yes)
        kSameLines = 2,      // e1 < e2 and lines_can_collide
        kTrianglePoint = 3,  // triangle_point_can_collide (the point model is the triangle's node's)
        kLinePoint = 4,      // line_point_can_collide (the point model is the line's node's)
    };
    Rule rule = kSameModel;
    const Index* cells = nullptr;     // the first model's triangles or edges
    Adjacency edges_around_vertex{};  // line rules: the line model's topology
    bool operator()(Index e1, Index e2) const {
        switch (rule) {
            case kSameModel:
                return e1 < e2;
            case kSameLines:
                return e1 < e2 && lines_can_collide(e1, e2, cells, edges_around_vertex);
            case kTrianglePoint:
                return e2 != cells[3 * e1] && e2 != cells[3 * e1 + 1] && e2 != cells[3 * e1 + 2];
            case kLinePoint:
                return line_point_can_collide(e1, e2, cells, edges_around_vertex);
        }
        return true;
    }
};

}  // namespace sofac::collide

namespace sofac::collide {

// =============================================================================================
// LocalMinDistance (LocalMinDistance.{h,cpp}): interior-only projections (no clamping), and,
// unless useLMDFilters, the "angle cones" (testValidity) of both elements after the distance
// test. Only Vec3d spheres (SOFA registers no rigid sphere pair for it); a sphere is always valid.
namespace local_min_distance {

struct Options {
    bool filter_intersection = true;
    double angle_cone = 0.0;
    double cone_factor = 0.5;
    bool use_lmd_filters = false;
};

// What a point's cone reads: its model's positions and topology. Pass null instead when SOFA
// accepts before reading the topology (filterIntersection off, or no LineCollisionModel in the
// point model's node).
struct PointCone {
    const double* x;
    const Index* triangles;
    const Index* edges;
    Adjacency triangles_around_vertex;
    Adjacency edges_around_vertex;
    bool both_side;
};

// A line's cone: positions, triangles and trianglesAroundEdge of the line model's topology (the
// line model's element i is topology edge i).
struct LineCone {
    const double* x;
    const Index* triangles;
    Adjacency triangles_around_edge;
    bool both_side;
};

inline bool valid(const Options& o, const PointCone* cone, Index point, const V3& PQ) {
    if (!o.filter_intersection || cone == nullptr) return true;
    const V3 pt = load3(cone->x, 3, point);
    V3 mean{{0.0, 0.0, 0.0}};
    const Index n_triangles = cone->triangles_around_vertex.count(point);
    const Index n_edges = cone->edges_around_vertex.count(point);
    for (Index k = 0; k < n_triangles; ++k) {
        const Index* t = cone->triangles + 3 * cone->triangles_around_vertex.at(point, k);
        const V3 p0 = load3(cone->x, 3, t[0]);
        mean = mean + normalized(cross(load3(cone->x, 3, t[1]) - p0, load3(cone->x, 3, t[2]) - p0));
    }
    auto edge_direction = [&](Index k) {
        const Index* e = cone->edges + 2 * cone->edges_around_vertex.at(point, k);
        return normalized((pt - load3(cone->x, 3, e[0])) + (pt - load3(cone->x, 3, e[1])));
    };
    if (n_triangles == 0)
        for (Index k = 0; k < n_edges; ++k) mean = mean + edge_direction(k);
    const double pq = std::sqrt(norm2(PQ));
    if (std::sqrt(norm2(mean)) > 0.0000000001) {
        mean = normalized(mean);
        if (dot(mean, PQ) < -o.angle_cone * pq && !cone->both_side) return false;
    }
    for (Index k = 0; k < n_edges; ++k) {
        const V3 l = edge_direction(k);
        double angle = dot(mean, l) * o.cone_factor;
        if (angle < 0) angle = 0.0;
        angle += o.angle_cone;
        if (dot(l, PQ) < -angle * pq) return false;
    }
    return true;
}

inline bool valid(const Options& o, const LineModel& m, const LineCone* cone, Index line, const V3& PQ) {
    if (!o.filter_intersection) return true;
    const V3 AB = normalized(m.p2(line) - m.p1(line));
    const double pq = std::sqrt(norm2(PQ));
    if (cone != nullptr && cone->triangles_around_edge.count(line) == 2) {
        const Index i1 = m.edges[2 * line], i2 = m.edges[2 * line + 1];
        const Index* t0 = cone->triangles + 3 * cone->triangles_around_edge.at(line, 0);
        const Index* t1 = cone->triangles + 3 * cone->triangles_around_edge.at(line, 1);
        const bool t0_left =
            (i1 == t0[0] && i2 == t0[1]) || (i1 == t0[1] && i2 == t0[2]) || (i1 == t0[2] && i2 == t0[0]);
        const Index* right = t0_left ? t1 : t0;
        const Index* left = t0_left ? t0 : t1;
        auto normal = [&](const Index* t) {
            const V3 p0 = load3(cone->x, 3, t[0]);
            return normalized(cross(load3(cone->x, 3, t[1]) - p0, load3(cone->x, 3, t[2]) - p0));
        };
        const V3 n1 = normal(right);
        const V3 tangent1 = normalized(cross(n1, AB));
        const V3 n2 = normal(left);
        const V3 tangent2 = normalized(cross(AB, n2));
        const V3 mean = normalized(n1 + n2);
        if (dot(mean, PQ) < 0 && !cone->both_side) return false;
        for (const V3& t : {tangent1, tangent2}) {
            double angle = dot(mean, t) * o.cone_factor;
            if (angle < 0) angle = 0.0;
            angle += o.angle_cone;
            if (dot(t, PQ) < -angle * pq) return false;
        }
        return true;
    }
    // a boundary (or free) edge: PQ must be nearly orthogonal to it
    return !(std::fabs(dot(AB, normalized(PQ))) > o.angle_cone + 0.0001);
}

inline bool valid(const Options& o, const TriangleModel& m, bool both_side, Index tri, const V3& PQ) {
    if (!o.filter_intersection || both_side) return true;
    const V3 p1 = m.p(tri, 0);
    return dot(cross(m.p(tri, 1) - p1, m.p(tri, 2) - p1), PQ) >= 0.0;
}

namespace detail {
inline int emit(OutputList& out, Index e1, Index e2, Index id, const V3& p0, const V3& p1, double contact) {
    DetectionOutput o;
    o.elem1 = e1;
    o.elem2 = e2;
    o.id = id;
    o.point[0] = p0;
    o.point[1] = p1;
    const V3 d = p1 - p0;
    const double length = std::sqrt(norm2(d));
    o.normal = collide::detail::unit(d, length, out);
    o.value = length - contact;
    return collide::detail::emit(out, o);
}
}  // namespace detail

inline int line_line(const Proximity& m, const Options& o, const LineModel& a, Index e1, const LineCone* cone1,
                     const LineModel& b, Index e2, const LineCone* cone2, OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const V3 AB = a.p2(e1) - a.p1(e1), CD = b.p2(e2) - b.p1(e2), AC = b.p1(e2) - a.p1(e1);
    const double A00 = dot(AB, AB), A11 = dot(CD, CD), A01 = -dot(CD, AB);
    const double b0 = dot(AB, AC), b1 = -dot(CD, AC);
    const double det = A00 * A11 - A01 * A01;
    double alpha = 0.5, beta = 0.5;
    if (det < -1.0e-30 || det > 1.0e-30) {
        alpha = (b0 * A11 - b1 * A01) / det;
        beta = (b1 * A00 - b0 * A01) / det;
        if (alpha < 1e-15 || alpha > (1.0 - 1e-15) || beta < 1e-15 || beta > (1.0 - 1e-15)) return 0;
    }
    const V3 P = a.p1(e1) + AB * alpha, Q = b.p1(e2) + CD * beta, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && (!valid(o, a, cone1, e1, PQ) || !valid(o, b, cone2, e2, -PQ))) return 0;
    const Index id = collide::detail::larger_model_index(a.size, e1, b.size, e2);
    return detail::emit(out, e1, e2, id, P, Q, m.contact_distance + a.contact_distance + b.contact_distance);
}

// Triangle (first) - Point, interior only; the point's cone sees PQ (towards the triangle), the
// triangle's its reverse.
inline int triangle_point(const Proximity& m, const Options& o, const TriangleModel& a, Index tri, bool both_side,
                          const PointModel& b, Index point, const PointCone* cone, OutputList& out) {
    const double alarm = m.alarm_distance + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p(tri, 0), AB = a.p(tri, 1) - p1, AC = a.p(tri, 2) - p1, P = b.p(point), AP = P - p1;
    const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
    const double b0 = dot(AP, AB), b1 = dot(AP, AC);
    const double det = A00 * A11 - A01 * A01;
    if (det == 0) return 0;  // zero area (see min_proximity::triangle_point)
    const double alpha = (b0 * A11 - b1 * A01) / det, beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) return 0;
    const V3 Q = p1 + AB * alpha + AC * beta, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && (!valid(o, cone, point, PQ) || !valid(o, a, both_side, tri, -PQ))) return 0;
    return detail::emit(out, tri, point, point, Q, P, m.contact_distance + b.contact_distance + a.contact_distance);
}

// Triangle (first) - Sphere: as triangle_point with the centre and the radius in both distances.
inline int triangle_sphere(const Proximity& m, const Options& o, const TriangleModel& a, Index tri, bool both_side,
                           const SphereModel& b, Index sphere, OutputList& out) {
    const double r = b.r(sphere);
    const double alarm = m.alarm_distance + r + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p(tri, 0), AB = a.p(tri, 1) - p1, AC = a.p(tri, 2) - p1, P = b.center(sphere), AP = P - p1;
    const double A00 = dot(AB, AB), A11 = dot(AC, AC), A01 = dot(AB, AC);
    const double b0 = dot(AP, AB), b1 = dot(AP, AC);
    const double det = A00 * A11 - A01 * A01;
    if (det == 0) return 0;
    const double alpha = (b0 * A11 - b1 * A01) / det, beta = (b1 * A00 - b0 * A01) / det;
    if (alpha < 0.000001 || beta < 0.000001 || alpha + beta > 0.999999) return 0;
    const V3 Q = p1 + AB * alpha + AC * beta, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && !valid(o, a, both_side, tri, -PQ)) return 0;
    return detail::emit(out, tri, sphere, sphere, Q, P, m.contact_distance + r + b.contact_distance + a.contact_distance);
}

// Line (first) - Point: no clamping, alpha outside [1e-6, 0.999999] gives no contact, nor does an
// edge shorter than 1e-12 |AP|.
inline int line_point(const Proximity& m, const Options& o, const LineModel& a, Index line, const LineCone* line_cone,
                      const PointModel& b, Index point, const PointCone* point_cone, OutputList& out) {
    const double alarm = m.alarm_distance + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p1(line), AB = a.p2(line) - p1, P = b.p(point), AP = P - p1;
    if (std::sqrt(norm2(AB)) < 0.000000000001 * std::sqrt(norm2(AP))) return 0;
    const double alpha = dot(AP, AB) / dot(AB, AB);
    if (!(alpha >= 0.000001 && alpha <= 0.999999)) return 0;  // (0/0 on a point on a null edge: none)
    const V3 Q = p1 + AB * alpha, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && (!valid(o, point_cone, point, PQ) || !valid(o, a, line_cone, line, -PQ))) return 0;
    return detail::emit(out, line, point, point, Q, P, m.contact_distance + b.contact_distance + a.contact_distance);
}

inline int line_sphere(const Proximity& m, const Options& o, const LineModel& a, Index line, const LineCone* cone,
                       const SphereModel& b, Index sphere, OutputList& out) {
    const double r = b.r(sphere);
    const double alarm = m.alarm_distance + r + b.contact_distance + a.contact_distance;
    const V3 p1 = a.p1(line), AB = a.p2(line) - p1, P = b.center(sphere), AP = P - p1;
    if (std::sqrt(norm2(AB)) < 0.000000000001 * std::sqrt(norm2(AP))) return 0;
    const double alpha = dot(AP, AB) / dot(AB, AB);
    if (!(alpha >= 0.000001 && alpha <= 0.999999)) return 0;
    const V3 Q = p1 + AB * alpha, PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && !valid(o, a, cone, line, -PQ)) return 0;
    return detail::emit(out, line, sphere, sphere, Q, P, m.contact_distance + r + b.contact_distance + a.contact_distance);
}

inline int point_point(const Proximity& m, const Options& o, const PointModel& a, Index e1, const PointCone* cone1,
                       const PointModel& b, Index e2, const PointCone* cone2, OutputList& out) {
    const double alarm = m.alarm_distance + a.contact_distance + b.contact_distance;
    const V3 P = a.p(e1), Q = b.p(e2), PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && (!valid(o, cone1, e1, PQ) || !valid(o, cone2, e2, -PQ))) return 0;
    const Index id = collide::detail::larger_model_index(a.size, e1, b.size, e2);
    return detail::emit(out, e1, e2, id, P, Q, m.contact_distance + a.contact_distance + b.contact_distance);
}

inline int sphere_point(const Proximity& m, const Options& o, const SphereModel& a, Index sphere, const PointModel& b,
                        Index point, const PointCone* cone, OutputList& out) {
    const double r = a.r(sphere);
    const double alarm = m.alarm_distance + r + a.contact_distance + b.contact_distance;
    const V3 P = a.center(sphere), Q = b.p(point), PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    if (!o.use_lmd_filters && !valid(o, cone, point, -PQ)) return 0;
    const Index id = collide::detail::larger_model_index(a.size, sphere, b.size, point);
    return detail::emit(out, sphere, point, id, P, Q, m.contact_distance + r + a.contact_distance + b.contact_distance);
}

inline int sphere_sphere(const Proximity& m, const SphereModel& a, Index e1, const SphereModel& b, Index e2,
                         OutputList& out) {
    const double alarm = m.alarm_distance + a.r(e1) + a.contact_distance + b.r(e2) + b.contact_distance;
    const V3 P = a.center(e1), Q = b.center(e2), PQ = Q - P;
    if (norm2(PQ) >= alarm * alarm) return 0;
    const Index id = collide::detail::larger_model_index(a.size, e1, b.size, e2);
    const double contact = m.contact_distance + a.r(e1) + a.contact_distance + b.r(e2) + b.contact_distance;
    return detail::emit(out, e1, e2, id, P, Q, contact);
}

}  // namespace local_min_distance

}  // namespace sofac::collide
