"""Collision runtime (runtime/sofac/collision.h, proximity.h, contact.h) tested as C++ on its own:
each proximity test against hand-computed cases (degenerate ones included) and SOFA's quirks, the
bounding tree against its definition, the narrow phase against a brute-force loop over all element
pairs and against an independent Python traversal (order), the broad phase's pair order, and the
penalty force against its formula and finite differences of its energy and of itself."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from collision_shim import (
    KINDS,
    LINE_POINT,
    SAME_LINES,
    SAME_MODEL,
    TRIANGLE_POINT,
    Model,
    Output,
    Shim,
    csr,
    make_shim,
)
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from test_self_collision import grid_triangles


@pytest.fixture(scope="module")
def shim(tmp_path_factory: pytest.TempPathFactory) -> Shim:
    return make_shim(tmp_path_factory)


FLAG_P1, FLAG_P2, FLAG_P3, FLAG_E23, FLAG_E31, FLAG_E12 = 1, 2, 4, 8, 16, 32
ALL_FLAGS = FLAG_P1 | FLAG_P2 | FLAG_P3 | FLAG_E23 | FLAG_E31 | FLAG_E12

UNIT_TRIANGLE = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])


def points(*p: tuple[float, float, float], cd: float = 0.0) -> Model:
    return Model(np.array(p, dtype=float), cd=cd)


def segment(a: tuple, b: tuple, cd: float = 0.0) -> Model:
    return Model(np.array([a, b], dtype=float), elements=np.array([[0, 1]]), cd=cd)


def triangle(x: np.ndarray = UNIT_TRIANGLE, flags: int = ALL_FLAGS, cd: float = 0.0) -> Model:
    normal = np.cross(x[1] - x[0], x[2] - x[0])
    length = np.linalg.norm(normal)
    return Model(
        np.array(x, dtype=float), elements=np.array([[0, 1, 2]]), flags=np.array([flags]),
        normals=normal / length if length > 0 else normal, cd=cd,
    )  # fmt: skip


def spheres(*c: tuple, radius: float = 1.0, radii: list[float] | None = None, cd: float = 0.0) -> Model:
    return Model(
        np.array(c, dtype=float), cd=cd, radius=radius, radii=None if radii is None else np.array(radii)
    )


def rigid_spheres(*c: tuple, radius: float) -> Model:
    x = np.array([[*p, 0, 0, 0, 1] for p in c], dtype=float)
    return Model(x, radius=radius, rigid=True)


def close(a: np.ndarray, b: tuple | np.ndarray, tol: float = 1e-14) -> bool:
    return bool(np.abs(np.asarray(a) - np.asarray(b, dtype=float)).max() <= tol)


# -------------------------------------------------------------------------------------------------
# Element tests, MinProximityIntersection


@pytest.mark.parametrize("method", ["min", "new"])
def test_point_point(shim: Shim, method: str) -> None:
    a, b = points((0, 0, 0), cd=0.05), points((9, 9, 9), (0.3, 0.4, 0.0), cd=0.1)
    (o,), _ = shim.test(method, "PP", a, 0, b, 1, alarm=1.0, contact=0.2)
    assert close(o.p0, (0, 0, 0)) and close(o.p1, (0.3, 0.4, 0))
    assert close(o.normal, (0.6, 0.8, 0))
    assert o.value == pytest.approx(0.5 - (0.2 + 0.05 + 0.1), abs=1e-15)
    assert (o.elem1, o.elem2, o.id) == (0, 1, 1)  # id: the index in the larger model
    # the alarm distance includes both models' contactDistance: 0.5 < 0.3 + 0.15, not < 0.3
    assert shim.test(method, "PP", a, 0, b, 1, alarm=0.36, contact=0.2)[0]
    assert not shim.test(method, "PP", a, 0, b, 1, alarm=0.34, contact=0.2)[0]
    # exactly at the alarm distance: rejected (|pq|^2 >= alarm^2)
    assert not shim.test(method, "PP", points((0, 0, 0)), 0, points((1, 0, 0)), 0, alarm=1.0, contact=0.2)[0]


@pytest.mark.parametrize("method", ["min", "new"])
def test_coincident_points_get_sofas_fallback_normal(shim: Shim, method: str) -> None:
    (o,), (zero, dropped) = shim.test(method, "PP", points((1, 2, 3)), 0, points((1, 2, 3)), 0, 1.0, 0.25)
    assert close(o.normal, (1, 0, 0)) and o.value == -0.25
    assert (zero, dropped) == (1, 0)


@pytest.mark.parametrize("method", ["min", "new"])
def test_line_point(shim: Shim, method: str) -> None:
    line = segment((0, 0, 0), (2, 0, 0), cd=0.01)
    (o,), _ = shim.test(method, "LP", line, 0, points((0.5, 0.3, 0), cd=0.02), 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0.5, 0, 0)) and close(o.p1, (0.5, 0.3, 0)) and close(o.normal, (0, 1, 0))
    assert o.value == pytest.approx(0.3 - 0.13, abs=1e-15) and (o.elem1, o.elem2, o.id) == (0, 0, 0)
    # beyond an end: the projection is clamped to the end point
    (o,), _ = shim.test(method, "LP", line, 0, points((-0.3, 0.4, 0)), 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0, 0, 0)) and close(o.normal, (-0.6, 0.8, 0)) and o.value == pytest.approx(0.5 - 0.11)


@pytest.mark.parametrize("method", ["min", "new"])
def test_zero_length_edge_projects_on_its_point(shim: Shim, method: str) -> None:
    (o,), (zero, dropped) = shim.test(
        method, "LP", segment((1, 1, 1), (1, 1, 1)), 0, points((1, 1.5, 1)), 0, alarm=1.0, contact=0.1
    )
    assert close(o.p0, (1, 1, 1)) and close(o.normal, (0, 1, 0)) and o.value == pytest.approx(0.4)
    assert (zero, dropped) == (0, 0)


@pytest.mark.parametrize("method", ["min", "new"])
def test_line_line(shim: Shim, method: str) -> None:
    a, b = segment((-1, 0, 0), (1, 0, 0)), segment((0, -1, 0.4), (0, 1, 0.4))
    (o,), _ = shim.test(method, "LL", a, 0, b, 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0, 0, 0)) and close(o.p1, (0, 0, 0.4)) and close(o.normal, (0, 0, 1))
    assert o.value == pytest.approx(0.3)
    # closest points beyond an end of either segment: no contact (no clamping for line-line)
    assert not shim.test(method, "LL", a, 0, segment((2, -1, 0.1), (2, 1, 0.1)), 0, 1.0, 0.1)[0]
    assert not shim.test(method, "LL", a, 0, segment((0.5, 0.2, 0.1), (0.5, 1, 0.1)), 0, 1.0, 0.1)[0]


@pytest.mark.parametrize("method", ["min", "new"])
def test_parallel_lines_meet_at_their_middles(shim: Shim, method: str) -> None:
    a, b = segment((0, 0, 0), (1, 0, 0)), segment((0.25, 0.3, 0), (2.25, 0.3, 0))
    (o,), _ = shim.test(method, "LL", a, 0, b, 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0.5, 0, 0)) and close(o.p1, (1.25, 0.3, 0))  # alpha = beta = 0.5
    assert o.value == pytest.approx(math.hypot(0.75, 0.3) - 0.1)


def test_min_triangle_point_interior_only(shim: Shim) -> None:
    tri = triangle(cd=0.01)
    (o,), _ = shim.test("min", "TP", tri, 0, points((0, 0, 0), (0.25, 0.25, 0.3), cd=0.02), 1, 1.0, 0.1)
    assert close(o.p0, (0.25, 0.25, 0)) and close(o.p1, (0.25, 0.25, 0.3)) and close(o.normal, (0, 0, 1))
    assert o.value == pytest.approx(0.3 - 0.13, abs=1e-15) and (o.elem1, o.elem2, o.id) == (0, 1, 1)
    # above an edge, a corner, or on an edge: MinProximity leaves it to the line / point tests
    for p in [(0.5, 0.0, 0.3), (1.1, -0.1, 0.0), (0.5, 0.0, 0.0), (0.5, 0.5, 0.1)]:
        assert not shim.test("min", "TP", tri, 0, points(p), 0, 1.0, 0.1)[0]


def test_min_triangle_point_surface_normals(shim: Shim) -> None:
    tri = triangle(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]))
    (o,), _ = shim.test("min", "TP", tri, 0, points((0.2, 0.2, -0.3)), 0, 1.0, 0.1, option=1)
    assert close(o.normal, (0, 0, 1))  # the triangle's normal, not the direction to the point (0, 0, -1)
    (o,), _ = shim.test("min", "TP", tri, 0, points((0.2, 0.2, -0.3)), 0, 1.0, 0.1, option=0)
    assert close(o.normal, (0, 0, -1))


@pytest.mark.parametrize("method", ["min", "new"])
def test_zero_area_triangle_gives_no_nan(shim: Shim, method: str) -> None:
    flat = triangle(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    found, (_, dropped) = shim.test(method, "TP", flat, 0, points((0.5, 0.2, 0)), 0, 1.0, 0.1)
    assert found == []
    assert dropped == (1 if method == "new" else 0)  # NewProximity's 0/0 is counted, never output


def test_sphere_sphere(shim: Shim) -> None:
    a, b = spheres((0, 0, 0), radius=0.5, cd=0.01), spheres((1.5, 0, 0), radius=0.7, cd=0.02)
    for method in ["min", "new"]:
        (o,), _ = shim.test(method, "SS", a, 0, b, 0, alarm=1.0, contact=0.1)
        assert close(o.p0, (0, 0, 0)) and close(o.p1, (1.5, 0, 0))  # Vec3 spheres: the centres
        assert close(o.normal, (1, 0, 0)) and o.value == pytest.approx(1.5 - 1.2 - 0.13, abs=1e-15)
    # rigid spheres give their surface points
    (o,), _ = shim.test(
        "min",
        "SS",
        rigid_spheres((0, 0, 0), radius=0.5),
        0,
        rigid_spheres((2, 0, 0), radius=0.5),
        0,
        2.0,
        0.1,
    )
    assert close(o.p0, (0.5, 0, 0)) and close(o.p1, (1.5, 0, 0)) and o.value == pytest.approx(0.9)
    # listRadius overrides the radius for the elements it lists
    listed = spheres((0, 0, 0), (0, 3, 0), radius=0.5, radii=[2.0])
    (o,), _ = shim.test("min", "SS", listed, 0, b, 0, alarm=1.0, contact=0.1)
    assert o.value == pytest.approx(1.5 - 2.7 - 0.12)


def test_sphere_sphere_at_the_alarm_distance(shim: Shim) -> None:
    """DiscreteIntersection (MinProximity) keeps a pair exactly at the alarm distance (`>`), the
    point-point kernel of NewProximity drops it (`>=`)."""
    a, b = spheres((0, 0, 0), radius=0.5), spheres((2, 0, 0), radius=0.5)
    assert len(shim.test("min", "SS", a, 0, b, 0, alarm=1.0, contact=0.1)[0]) == 1
    assert shim.test("new", "SS", a, 0, b, 0, alarm=1.0, contact=0.1)[0] == []


@pytest.mark.parametrize("method", ["min", "new"])
def test_coincident_spheres(shim: Shim, method: str) -> None:
    (o,), (zero, dropped) = shim.test(
        method, "SS", spheres((1, 1, 1), radius=0.3), 0, spheres((1, 1, 1), radius=0.2), 0, 1.0, 0.1
    )
    assert close(o.normal, (1, 0, 0)) and o.value == pytest.approx(-0.6) and (zero, dropped) == (1, 0)


@pytest.mark.parametrize("method", ["min", "new"])
def test_sphere_point(shim: Shim, method: str) -> None:
    (o,), _ = shim.test(
        method, "SP", spheres((0, 0, 0), (5, 5, 5), radius=0.5), 1, points((5, 5.8, 5)), 0, 1.0, 0.1
    )
    assert close(o.p0, (5, 5, 5)) and close(o.p1, (5, 5.8, 5)) and close(o.normal, (0, 1, 0))
    assert o.value == pytest.approx(0.8 - 0.5 - 0.1)
    assert o.id == 1  # Min: the sphere; New: the index in the larger model (the spheres here)


@pytest.mark.parametrize("method", ["min", "new"])
def test_triangle_sphere_interior(shim: Shim, method: str) -> None:
    (o,), _ = shim.test(method, "TS", triangle(), 0, spheres((0.25, 0.25, 0.9), radius=0.5), 0, 1.0, 0.1)
    assert close(o.p0, (0.25, 0.25, 0)) and close(o.p1, (0.25, 0.25, 0.9)) and close(o.normal, (0, 0, 1))
    assert o.value == pytest.approx(0.9 - 0.5 - 0.1) and o.id == 0


def test_min_line_sphere_mirrors_the_projection(shim: Shim) -> None:
    """MeshMinProximityIntersection measures alpha from p2 but applies it from p1: the contact point
    is the centre's projection mirrored about the segment's middle (0.8 instead of 0.2 here)."""
    line, ball = segment((0, 0, 0), (1, 0, 0)), spheres((0.2, 0.5, 0), radius=0.1)
    (o,), _ = shim.test("min", "LS", line, 0, ball, 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0.8, 0, 0)) and close(o.p1, (0.2, 0.5, 0))
    assert o.value == pytest.approx(math.hypot(0.6, 0.5) - 0.2)
    (o,), _ = shim.test("new", "LS", line, 0, ball, 0, alarm=1.0, contact=0.1)
    assert close(o.p0, (0.2, 0, 0)) and o.value == pytest.approx(0.5 - 0.2)


# -------------------------------------------------------------------------------------------------
# NewProximityIntersection's features and flags


def test_new_triangle_point_features(shim: Shim) -> None:
    tri = triangle()
    cases = [  # point, closest point on the triangle, the flag the feature needs
        ((0.2, 0.3, 0.4), (0.2, 0.3, 0), 0),
        ((0.5, -0.2, 0.1), (0.5, 0, 0), FLAG_E12),
        ((-0.2, 0.5, 0.1), (0, 0.5, 0), FLAG_E31),
        ((0.7, 0.7, 0.1), (0.5, 0.5, 0), FLAG_E23),
        ((-0.1, -0.2, 0.0), (0, 0, 0), FLAG_P1),
        ((1.1, -0.1, 0.0), (1, 0, 0), FLAG_P2),
        ((-0.1, 1.2, 0.0), (0, 1, 0), FLAG_P3),
    ]
    for p, q, flag in cases:
        (o,), _ = shim.test("new", "TP", triangle(flags=ALL_FLAGS), 0, points(p), 0, 1.0, 0.1)
        assert close(o.p0, q) and close(o.p1, p)
        assert o.value == pytest.approx(np.linalg.norm(np.subtract(p, q)) - 0.1, abs=1e-15)
        if flag:  # a feature the triangle does not own is another triangle's contact
            assert not shim.test("new", "TP", triangle(flags=ALL_FLAGS & ~flag), 0, points(p), 0, 1.0, 0.1)[0]
    del tri


def test_new_point_on_a_triangle_edge(shim: Shim) -> None:
    (o,), (zero, _) = shim.test("new", "TP", triangle(), 0, points((0.5, 0.0, 0.0)), 0, 1.0, 0.1)
    assert close(o.p0, (0.5, 0, 0)) and o.value == -0.1 and close(o.normal, (1, 0, 0)) and zero == 1


def test_new_triangle_sphere_checks_sofas_flags(shim: Shim) -> None:
    """SOFA's Triangle-Sphere copy checks FLAG_E12 for the AC edge and FLAG_E31 for BC."""
    ball_ac, ball_bc = spheres((-0.2, 0.5, 0.1), radius=0.05), spheres((0.7, 0.7, 0.1), radius=0.05)
    only = {
        flag: triangle(flags=ALL_FLAGS & ~(FLAG_E12 | FLAG_E23 | FLAG_E31) | flag)
        for flag in (FLAG_E12, FLAG_E23, FLAG_E31)
    }
    assert shim.test("new", "TS", only[FLAG_E12], 0, ball_ac, 0, 1.0, 0.1)[0]
    assert not shim.test("new", "TS", only[FLAG_E31], 0, ball_ac, 0, 1.0, 0.1)[0]
    assert shim.test("new", "TS", only[FLAG_E31], 0, ball_bc, 0, 1.0, 0.1)[0]
    assert not shim.test("new", "TS", only[FLAG_E23], 0, ball_bc, 0, 1.0, 0.1)[0]
    (o,), _ = shim.test("new", "TS", triangle(), 0, ball_ac, 0, 1.0, 0.1)
    assert close(o.p0, (0, 0.5, 0)) and close(o.p1, (-0.2, 0.5, 0.1))


def test_new_triangle_line_order_and_swap(shim: Shim) -> None:
    line = segment((0.2, 0.2, 0.3), (0.2, 0.2, 2.0))
    (o,), _ = shim.test("new", "TL", triangle(), 0, line, 0, alarm=0.35, contact=0.1)
    assert close(o.p0, (0.2, 0.2, 0)) and close(o.p1, (0.2, 0.2, 0.3)) and o.id == 0
    # a wider alarm adds the first vertex against the line, first: point[0] on the triangle
    vertex, interior = shim.test("new", "TL", triangle(), 0, line, 0, alarm=0.45, contact=0.1)[0]
    assert close(vertex.p0, (0, 0, 0)) and close(vertex.p1, (0.2, 0.2, 0.3))
    assert close(vertex.normal, np.array([0.2, 0.2, 0.3]) / math.sqrt(0.17))
    assert close(interior.p0, (0.2, 0.2, 0))
    assert not shim.test("new", "TL", triangle(flags=ALL_FLAGS & ~FLAG_P1), 0, line, 0, 0.45, 0.1)[0][1:]


def closest_on_triangle(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Brute closest point: a fine barycentric grid refined by the exact edge / interior projections."""
    candidates = [x[0], x[1], x[2]]
    for a, b in [(0, 1), (1, 2), (2, 0)]:
        t = np.clip(np.dot(p - x[a], x[b] - x[a]) / np.dot(x[b] - x[a], x[b] - x[a]), 0, 1)
        candidates.append(x[a] + t * (x[b] - x[a]))
    n = np.cross(x[1] - x[0], x[2] - x[0])
    q = p - np.dot(p - x[0], n) / np.dot(n, n) * n
    m = np.array([x[1] - x[0], x[2] - x[0]]).T
    ab = np.linalg.lstsq(m, q - x[0], rcond=None)[0]
    if ab.min() > 0 and ab.sum() < 1:
        candidates.append(q)
    return min(candidates, key=lambda c: float(np.linalg.norm(c - p)))


def test_new_triangle_triangle(shim: Shim) -> None:
    t1 = UNIT_TRIANGLE
    t2 = np.array([[0.1, 0.1, 0.2], [0.6, 0.1, 0.2], [0.1, 0.6, 0.2]])
    both = Model(
        np.vstack([t1, t2]), elements=np.array([[0, 1, 2], [3, 4, 5]]), flags=np.array([ALL_FLAGS] * 2)
    )
    a, b = triangle(t1), triangle(t2)
    alarm = 0.5
    found, _ = shim.test("new", "TT", a, 0, b, 0, alarm=alarm, contact=0.1)
    expected = []
    for k, p in enumerate(t1):  # e1's vertices against e2, point[0] on e1
        q = closest_on_triangle(t2, p)
        if np.linalg.norm(q - p) < alarm:
            expected.append((p, q, k))
    for k, q in enumerate(t2):  # then e2's vertices against e1
        p = closest_on_triangle(t1, q)
        if np.linalg.norm(q - p) < alarm:
            expected.append((p, q, 1 * 3 + 0 * 12 + k))
    assert len(found) == len(expected) == 6
    for o, (p, q, ident) in zip(found, expected, strict=True):
        assert close(o.p0, p, 1e-12) and close(o.p1, q, 1e-12) and o.id == ident
        assert close(o.normal, (q - p) / np.linalg.norm(q - p), 1e-12)
        assert o.value == pytest.approx(np.linalg.norm(q - p) - 0.1, abs=1e-12)
    # SOFA tests e1's first vertex whatever its flags say, the others only when e1 owns them
    no_points = triangle(t1, flags=ALL_FLAGS & ~(FLAG_P1 | FLAG_P2 | FLAG_P3))
    first = shim.test("new", "TT", no_points, 0, b, 0, alarm=alarm, contact=0.1)[0]
    assert [o.id for o in first] == [0, 3, 4, 5]
    # two triangles of one model that share no vertex meet; sharing one, they never do
    assert len(shim.test("new", "TT", both, 0, both, 1, alarm=alarm, contact=0.1)[0]) == 6
    shared = Model(
        np.vstack([t1, t2]), elements=np.array([[0, 1, 2], [3, 4, 0]]), flags=np.array([ALL_FLAGS] * 2)
    )
    assert shim.test("new", "TT", shared, 0, shared, 1, alarm=alarm, contact=0.1)[0] == []


def test_triangle_flags(shim: Shim) -> None:
    """Two triangles sharing edge 1-2: the first owns the shared edge and vertices, the second only
    its own vertex 3 and its two other edges; edges with one triangle are boundary edges."""
    tris = np.array([[0, 1, 2], [2, 1, 3]], dtype=np.int64)
    out = (ctypes.c_int * 2)()
    shim.lib.flags(_i(tris), 2, 4, out)
    be23, be31, be12 = 64, 128, 256
    assert out[0] == FLAG_P1 | FLAG_P2 | FLAG_P3 | FLAG_E23 | FLAG_E31 | FLAG_E12 | be31 | be12
    # second triangle (2, 1, 3): edge opposite vertex 0 is (1, 3), opposite 1 is (3, 2), opposite 2 is (2, 1)
    assert out[1] == FLAG_P3 | FLAG_E23 | FLAG_E31 | be23 | be31


def test_self_collision_element_filters(shim: Shim) -> None:
    """A chain 0-1-2-3-4: PointCollisionModel::canCollideWithElement lets points collide only as
    (later, earlier) and not within two links; lines not when they share a point or an edge
    touches both. canCollideWith adds e1 < e2 within one model, so no pair of one point model
    ever passes (the planner gives it no narrow phase), and a line model keeps (0, 3) only."""
    around = [[1], [0, 2], [1, 3], [2, 4], [3]]
    offsets, items = csr(around)
    allowed = {
        (i, j) for i in range(5) for j in range(5) if shim.lib.self_points(i, j, _i(offsets), _i(items))
    }
    assert allowed == {(3, 0), (4, 0), (4, 1)}
    assert not {(i, j) for i, j in allowed if i < j}  # SOFA's canCollideWith: index < index2 too
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4]], dtype=np.int64)
    edges_around = [[0], [0, 1], [1, 2], [2, 3], [3]]
    e_offsets, e_items = csr(edges_around)
    pairs = {
        (i, j)
        for i in range(4)
        for j in range(4)
        if shim.lib.self_lines(i, j, _i(edges), _i(e_offsets), _i(e_items))
    }
    assert pairs == {(0, 3), (3, 0)}
    mask = shim.self_filter(SAME_LINES, 4, 4, edges, edges_around)
    assert set(zip(*np.nonzero(mask), strict=True)) == {(0, 3)}
    # LineCollisionModel against its node's points: not an end of the line, nor of an edge around its ends
    mask = shim.self_filter(LINE_POINT, 4, 5, edges, edges_around)
    assert {int(p) for p in np.flatnonzero(mask[0])} == {3, 4}  # line 0-1: 0, 1 and 2 (edge 1-2) excluded
    assert {int(p) for p in np.flatnonzero(mask[1])} == {4}  # line 1-2: edges 0-1 and 2-3 around it
    assert {int(p) for p in np.flatnonzero(mask[3])} == {0, 1}
    # TriangleCollisionModel against its node's points: not a vertex of the triangle
    tris = np.array([[0, 1, 2], [2, 1, 3]], dtype=np.int64)
    mask = shim.self_filter(TRIANGLE_POINT, 2, 5, tris)
    assert [set(np.flatnonzero(row).tolist()) for row in mask] == [{3, 4}, {0, 4}]
    # one triangle (or sphere) model: e1 < e2, whatever they share (the intersector skips neighbours)
    mask = shim.self_filter(SAME_MODEL, 3, 3, tris)
    assert set(zip(*np.nonzero(mask), strict=True)) == {(0, 1), (0, 2), (1, 2)}


def folded_sheet(cells: int = 12, width: int = 4, gap: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """A strip of cells x width quads folded back over itself `gap` above (points, triangles), its
    upper layer shifted by a fraction of a cell so that its points lie inside lower triangles."""
    us = np.linspace(0.0, 2.0, 2 * cells + 1)
    vs = np.linspace(0.0, 0.4, width + 1)
    du, dv = 1.0 / cells, 0.4 / width
    x = np.array([(u, 0.0, v) if u <= 1.0 else (2.0 - u + du / 2, gap, v + dv / 4) for u in us for v in vs])
    return x, np.array(grid_triangles(2 * cells, width), dtype=np.int64)


def test_self_collision_through_the_narrow_phase(shim: Shim) -> None:
    """Models of one node through BVHNarrowPhase with SOFA's element filter (canCollideWith before
    each element pair): a random-walk rope (one line model) and a sheet folded over itself (one
    triangle model with NewProximity, and its triangles against the points of its own state). The
    traversal of a model against itself finds exactly what every element pair through the filter
    finds, and never a pair the filter refuses: neighbouring elements never touch."""
    rng = np.random.default_rng(9)
    n = 300
    x = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    edges = np.array([(i, i + 1) for i in range(n - 1)], dtype=np.int64)
    around = [[0]] + [[i - 1, i] for i in range(1, n - 1)] + [[n - 2]]
    rope = Model(x, elements=edges, cd=0.01)
    reach = {"alarm": 0.04, "contact": 0.01}
    runs = [
        sorted(map(key, shim.self_detect("min", "LL", rope, rope, SAME_LINES, around, **reach, brute=brute)))
        for brute in (False, True)
    ]  # fmt: skip
    assert len(runs[1]) > 10 and runs[0] == runs[1]
    assert all(o[0] + 1 < o[1] for o in runs[0])  # e1 < e2, never two links of one joint

    x, tris = folded_sheet()
    flags = np.zeros(len(tris), dtype=np.int32)
    shim.lib.flags(_i(tris), len(tris), len(x), flags.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
    sheet = Model(x, elements=tris, flags=flags, normals=np.zeros((len(tris), 3)), cd=0.005)
    found = shim.self_detect("new", "TT", sheet, sheet, SAME_MODEL, alarm=0.04, contact=0.01)
    every = shim.self_detect("new", "TT", sheet, sheet, SAME_MODEL, alarm=0.04, contact=0.01, brute=True)
    assert len(found) > 50 and sorted(map(key, found)) == sorted(map(key, every))
    for o in found:
        assert o.elem1 < o.elem2 and not set(tris[o.elem1]) & set(tris[o.elem2])
        assert abs(o.p0[1] - o.p1[1]) > 0.02  # across the fold, one layer to the other
    vertices = Model(x, cd=0.005)
    found = shim.self_detect("min", "TP", sheet, vertices, TRIANGLE_POINT, alarm=0.04, contact=0.01)
    every = shim.self_detect(
        "min", "TP", sheet, vertices, TRIANGLE_POINT, alarm=0.04, contact=0.01, brute=True
    )
    assert len(found) > 20 and sorted(map(key, found)) == sorted(map(key, every))
    assert all(o.elem2 not in tris[o.elem1] for o in found)
    assert all(abs(o.value - (0.03 - 0.02)) < 1e-12 for o in found)  # the gap less both contact distances


def test_update_tree_writes_triangle_normals(shim: Shim) -> None:
    x = np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0], [0, 0, 1]])
    m = Model(x, elements=np.array([[0, 1, 2], [0, 3, 1]]), flags=np.zeros(2))
    normals = np.zeros((2, 3))
    shim.lib.triangle_normals(ctypes.byref(m.struct), _d(normals))
    assert close(normals, [(0, 0, 1), (0, 1, 0)])


# -------------------------------------------------------------------------------------------------
# Bounding tree, narrow phase, broad phase


def test_tree_splits_as_sofa(shim: Shim) -> None:
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.permutation(10) * 1.0, rng.uniform(0, 0.1, 10), rng.uniform(0, 0.1, 10)])
    depth = 6
    leaf = np.zeros(10, dtype=np.int64)
    sizes = np.zeros(depth + 1, dtype=np.int64)
    rows = np.zeros((64, 9))
    shim.lib.point_tree(_d(x), 10, depth, 0.05, _i(leaf), _i(sizes), _d(rows))
    # root (10 leaves) -> 5 + 5 along x -> 3 + 2 and 3 + 2; cubes of 4 leaves or fewer stay whole
    assert list(sizes) == [1, 2, 4, 0, 0, 0, 0]
    assert list(leaf) == list(np.argsort(x[:, 0], kind="stable"))
    root, left, right = rows[0], rows[1], rows[2]
    assert close(root[:3], x.min(axis=0) - 0.05) and close(root[3:6], x.max(axis=0) + 0.05)
    assert tuple(root[6:]) == (1, 0, 2) and tuple(left[6:]) == (2, 0, 2) and tuple(right[6:]) == (2, 2, 4)
    assert [tuple(r[6:]) for r in rows[3:7]] == [(-1, 0, 3), (-1, 3, 5), (-1, 5, 8), (-1, 8, 10)]
    # equal keys keep their order (std::stable_sort)
    ties = np.array([[1.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0], [0.0, 0, 0], [2.0, 0, 0], [1.0, 0, 0]])
    shim.lib.point_tree(_d(ties), 6, 1, 0.0, _i(leaf), _i(sizes), _d(rows))
    assert list(leaf[:6]) == [1, 3, 0, 2, 5, 4]


def test_tree_structure_is_fixed_by_the_first_update(shim: Shim) -> None:
    rng = np.random.default_rng(6)
    x0 = rng.uniform(-1, 1, (40, 3))
    x1 = x0[::-1].copy()  # the same points, element i now where element 39 - i was
    refit, fresh = np.zeros(40, dtype=np.int64), np.zeros(40, dtype=np.int64)
    root = np.zeros(6)
    assert shim.lib.tree_structure(_d(x0), _d(x1), 40, 6, _i(refit), _i(fresh), _d(root)) == 1
    assert list(fresh) == [39 - e for e in refit]  # a fresh build would sort the moved points anew
    assert close(root, np.concatenate([x1.min(axis=0), x1.max(axis=0)]))  # the refit boxes follow x1


def random_models(kind: str, rng: np.random.Generator, n: int) -> tuple[Model, Model]:
    def cloud(m: int, center: float) -> np.ndarray:
        return rng.uniform(-1, 1, (m, 3)) + center

    def soup(m: int, shape: int, center: float) -> Model:
        x = cloud(m * shape, center)
        for e in range(m):  # small elements around random centres
            base = x[e * shape]
            x[e * shape : (e + 1) * shape] = base + rng.uniform(-0.15, 0.15, (shape, 3))
        elements = np.arange(m * shape).reshape(m, shape)
        if shape == 2:
            return Model(x, elements=elements, cd=0.01)
        normals = np.cross(x[elements[:, 1]] - x[elements[:, 0]], x[elements[:, 2]] - x[elements[:, 0]])
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        return Model(x, elements=elements, flags=rng.integers(0, 64, m), normals=normals, cd=0.01)

    def side(code: str, center: float) -> Model:
        if code == "P":
            return Model(cloud(n, center), cd=0.02)
        if code == "S":
            return Model(cloud(n, center), radius=0.05, radii=rng.uniform(0.02, 0.1, n // 2), cd=0.01)
        return soup(n, 2 if code == "L" else 3, center)

    return side(kind[0], 0.0), side(kind[1], 0.4)


def key(o: Output) -> tuple:
    return (o.elem1, o.elem2, o.id, o.value, *o.p0, *o.p1, *o.normal)


PAIRS = [("min", k) for k in ["PP", "LP", "LL", "TP", "SS", "SP", "TS", "LS"]] + [
    ("new", k) for k in ["PP", "LP", "LL", "TP", "SS", "SP", "TS", "LS", "TL", "TT"]
]


@pytest.mark.parametrize(("method", "kind"), PAIRS)
def test_narrow_phase_finds_what_brute_force_finds(shim: Shim, method: str, kind: str) -> None:
    rng = np.random.default_rng(KINDS[kind] + 17 * (method == "new"))
    a, b = random_models(kind, rng, 150)
    found, _ = shim.detect(method, kind, a, b, depth=6, alarm=0.15, contact=0.05, option=1)
    boxed = shim.brute_force(method, kind, a, b, alarm=0.15, contact=0.05, option=1, boxes=True)
    every = shim.brute_force(method, kind, a, b, alarm=0.15, contact=0.05, option=1)
    assert len(boxed) >= 5  # the geometry does produce contacts
    assert sorted(map(key, found)) == sorted(map(key, boxed))
    if (method, kind) != ("new", "TS"):
        assert sorted(map(key, every)) == sorted(map(key, boxed))  # no contact lies beyond the boxes
    else:
        # SOFA's Triangle-Sphere edge branch takes pAB < 0 as a point of edge AB: some contact points
        # lie off the triangle, where the leaf boxes (and so SOFA's narrow phase) never look
        assert len(every) > len(boxed)


def python_narrow_phase(
    boxes1: np.ndarray, boxes2: np.ndarray, depth: int, reach: float
) -> list[tuple[int, int]]:
    """SOFA's CubeCollisionModel tree and BVHNarrowPhase traversal, written again from their
    description, for point models: the (e1, e2) order in which element tests are called."""

    def build(boxes: np.ndarray) -> tuple[list[list[list]], list[int]]:
        leaves = list(range(len(boxes)))  # element at each leaf position
        levels: list[list[list]] = [[[-1, 0, len(boxes)]] for _ in range(1)] + [[] for _ in range(depth)]

        def union(lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
            sel = boxes[leaves[lo:hi]]
            return sel[:, 0].min(axis=0), sel[:, 1].max(axis=0)

        for lvl in range(depth):
            for cube in levels[lvl]:
                lo, hi = cube[1], cube[2]
                if hi - lo <= 4:
                    continue
                mn, mx = union(lo, hi)
                ext = mx - mn
                axis = (0 if ext[0] > ext[2] else 2) if ext[0] > ext[1] else (1 if ext[1] > ext[2] else 2)
                part = sorted(leaves[lo:hi], key=lambda e: boxes[e, 0, axis] + boxes[e, 1, axis])
                leaves[lo:hi] = part
                mid = lo + (hi - lo + 1) // 2
                levels[lvl + 1] += [[-1, lo, mid], [-1, mid, hi]]
                cube[:] = [lvl + 1, len(levels[lvl + 1]) - 2, len(levels[lvl + 1])]
        return levels, leaves

    def cube_box(tree: tuple, boxes: np.ndarray, level: int, i: int) -> tuple[np.ndarray, np.ndarray]:
        levels, leaves = tree
        if level == -1:
            return boxes[leaves[i], 0], boxes[leaves[i], 1]
        sub = levels[level][i]
        parts = [cube_box(tree, boxes, sub[0], j) for j in range(sub[1], sub[2])]
        return np.min([p[0] for p in parts], axis=0), np.max([p[1] for p in parts], axis=0)

    t1, t2 = build(boxes1), build(boxes2)
    r1, r2 = t1[0][0][0], t2[0][0][0]
    stack = [((r1[0], r1[1], r1[2]), (r2[0], r2[1], r2[2]))]
    calls = []
    while stack:
        (l1, b1, e1), (l2, b2, e2) = stack.pop()
        for c1 in range(b1, e1):
            lo1, hi1 = cube_box(t1, boxes1, l1, c1)
            for c2 in range(b2, e2):
                lo2, hi2 = cube_box(t2, boxes2, l2, c2)
                if np.any(lo1 > hi2 + reach) or np.any(lo2 > hi1 + reach):
                    continue
                s1 = tuple(t1[0][l1][c1]) if l1 != -1 else (-1, c1, c1 + 1)
                s2 = tuple(t2[0][l2][c2]) if l2 != -1 else (-1, c2, c2 + 1)
                if l1 != -1 or l2 != -1:
                    stack.append((s1 if l1 != -1 else (-1, c1, c1 + 1), s2 if l2 != -1 else (-1, c2, c2 + 1)))
                else:
                    calls.append((t1[1][c1], t2[1][c2]))
    return calls


# (points of each model, tree depth): small deepest cubes, and large ones (blocks of ~70 leaves,
# where the runtime first drops the leaves that miss the other block)
@pytest.mark.parametrize(("sizes", "depth"), [((120, 90), 6), ((600, 500), 3)])
def test_narrow_phase_order_matches_the_traversal(shim: Shim, sizes: tuple[int, int], depth: int) -> None:
    rng = np.random.default_rng(11)
    x1, x2 = rng.uniform(-1, 1, (sizes[0], 3)), rng.uniform(-0.6, 1.4, (sizes[1], 3))
    cd1, cd2, alarm = 0.02, 0.03, 0.2
    a, b = Model(x1, cd=cd1), Model(x2, cd=cd2)
    found, _ = shim.detect("min", "PP", a, b, depth=depth, alarm=alarm, contact=0.05)
    boxes1 = np.stack([x1 - cd1, x1 + cd1], axis=1)
    boxes2 = np.stack([x2 - cd2, x2 + cd2], axis=1)
    calls = python_narrow_phase(boxes1, boxes2, depth, alarm + cd1 + cd2)
    hits = {(o.elem1, o.elem2) for o in found}
    expected = [c for c in calls if c in hits]
    assert len(found) > 10
    assert [(o.elem1, o.elem2) for o in found] == expected


def test_a_later_step_refits_without_allocating(shim: Shim) -> None:
    rng = np.random.default_rng(5)
    a, b = random_models("TP", rng, 200)
    first, counters = shim.detect("new", "TP", a, b, depth=6, alarm=0.15, contact=0.05, first=True)
    b.x[:] += np.array([0.03, -0.02, 0.01])  # the points move; same arrays, so the trees refit
    moved, counters = shim.detect("new", "TP", a, b, depth=6, alarm=0.15, contact=0.05, first=False)
    assert counters[1] == 0 and counters[2] == 0 and counters[3] == 0  # refit, traversal, outputs
    reference = shim.brute_force("new", "TP", a, b, alarm=0.15, contact=0.05)
    assert sorted(map(key, moved)) == sorted(map(key, reference)) != sorted(map(key, first))


def python_broad_phase(
    boxes: np.ndarray, cds: np.ndarray, rule: np.ndarray, alarm: float
) -> list[tuple[int, int]]:
    n, pairs = len(boxes), []

    def meet(i: int, j: int) -> bool:
        reach = alarm + cds[i] + cds[j]
        return not (
            np.any(boxes[i, :3] > boxes[j, 3:] + reach) or np.any(boxes[j, :3] > boxes[i, 3:] + reach)
        )

    for i in range(n):
        if rule[i, i]:
            pairs.append((i, i))
        for j in range(i):
            if rule[i, j] and meet(i, j):
                pairs.append((j, i) if rule[i, j] == 2 else (i, j))
    return pairs


def test_broad_phase_pairs_in_sofas_order(shim: Shim) -> None:
    def run(boxes: np.ndarray, cds: np.ndarray, rule: np.ndarray, alarm: float) -> list[tuple[int, int]]:
        n = len(boxes)
        out = np.zeros(n * (n + 1), dtype=np.int64)
        rule8 = np.ascontiguousarray(rule, dtype=np.int8)
        count = shim.lib.broad_phase(
            _d(np.ascontiguousarray(boxes)),
            _d(cds),
            n,
            rule8.ctypes.data_as(ctypes.POINTER(ctypes.c_int8)),
            alarm,
            _i(out),
        )
        return [tuple(p) for p in out[: 2 * count].reshape(-1, 2).tolist()]

    overlap = np.array([[0, 0, 0, 1, 1, 1]] * 3, dtype=float)
    keep = np.tril(np.ones((3, 3)), -1)
    assert run(overlap, np.zeros(3), keep, 0.1) == [(1, 0), (2, 0), (2, 1)]  # (later, earlier)
    self1 = keep.copy()
    self1[1, 1] = 1
    assert run(overlap, np.zeros(3), self1, 0.1) == [(1, 1), (1, 0), (2, 0), (2, 1)]
    swapped = keep.copy()
    swapped[2, 0] = 2
    assert run(overlap, np.zeros(3), swapped, 0.1) == [(1, 0), (0, 2), (2, 1)]
    # the root boxes meet within alarm + both contactDistances
    apart = np.array([[0, 0, 0, 1, 1, 1], [1.5, 0, 0, 2, 1, 1]], dtype=float)
    assert run(apart, np.array([0.1, 0.15]), np.tril(np.ones((2, 2)), -1), 0.26) == [(1, 0)]
    assert run(apart, np.array([0.1, 0.15]), np.tril(np.ones((2, 2)), -1), 0.24) == []
    rng = np.random.default_rng(2)
    lo = rng.uniform(0, 10, (25, 3))
    boxes = np.hstack([lo, lo + rng.uniform(0.1, 2, (25, 3))])
    cds = rng.uniform(0, 0.3, 25)
    rule = np.tril(rng.integers(0, 3, (25, 25)), -1) + np.diag(rng.integers(0, 2, 25))
    assert run(boxes, cds, rule, 0.5) == python_broad_phase(boxes, cds, rule, 0.5)


# -------------------------------------------------------------------------------------------------
# Penalty contact


class Penalty:
    def __init__(
        self,
        shim: Shim,
        m: np.ndarray,
        normals: np.ndarray,
        dist: np.ndarray,
        ks: np.ndarray,
        n1: int,
        n2: int,
    ) -> None:
        self.shim, self.m, self.normals, self.dist, self.ks, self.n1, self.n2 = (
            shim,
            m,
            normals,
            dist,
            ks,
            n1,
            n2,
        )

    def run(
        self, x1: np.ndarray, x2: np.ndarray, dx1: np.ndarray | None = None, dx2: np.ndarray | None = None,
        k_factor: float = 1.0,
    ) -> dict:  # fmt: skip
        n = len(self.dist)
        f1, f2 = np.zeros(3 * self.n1), np.zeros(3 * self.n2)
        df1, df2 = np.zeros(3 * self.n1), np.zeros(3 * self.n2)
        dx1 = np.zeros(3 * self.n1) if dx1 is None else np.ascontiguousarray(dx1)
        dx2 = np.zeros(3 * self.n2) if dx2 is None else np.ascontiguousarray(dx2)
        pen = np.zeros(n)
        size = 3 * (self.n1 + self.n2)
        matrix = np.zeros((size, size))
        energy = self.shim.lib.penalty(
            n, _i(self.m), _d(self.normals), _d(self.dist), _d(self.ks), _d(np.ascontiguousarray(x1)),
            _d(np.ascontiguousarray(x2)), _d(f1), _d(f2), _d(dx1), _d(dx2), _d(df1), _d(df2), k_factor,
            _d(pen), _d(matrix), self.n1, self.n2,
        )  # fmt: skip
        return {
            "f": np.concatenate([f1, f2]),
            "df": np.concatenate([df1, df2]),
            "pen": pen,
            "energy": energy,
            "K": matrix,
        }


def test_penalty_force_by_hand(shim: Shim) -> None:
    p = Penalty(
        shim,
        np.array([[0, 0]], dtype=np.int64),
        np.array([[0.0, 0, 1]]),
        np.array([0.5]),
        np.array([10.0]),
        1,
        1,
    )
    r = p.run(np.zeros(3), np.array([0, 0, 0.2]))
    assert r["pen"][0] == pytest.approx(0.3)
    assert close(r["f"], (0, 0, -3, 0, 0, 3), 1e-14) and r["energy"] == pytest.approx(0.45)
    r = p.run(np.zeros(3), np.array([0, 0, 0.2]), dx2=np.array([0, 0, 0.1]), k_factor=-0.5)
    assert close(r["df"], (0, 0, 10 * 0.1 * -0.5, 0, 0, -10 * 0.1 * -0.5), 1e-14)
    r = p.run(np.zeros(3), np.array([0, 0, 0.6]), dx2=np.array([0, 0, 0.1]))  # apart: no force, no stiffness
    assert not r["f"].any() and not r["df"].any() and not r["K"].any() and r["energy"] == 0


def test_penalty_against_finite_differences(shim: Shim) -> None:
    rng = np.random.default_rng(8)
    n1, n2, n = 5, 4, 9
    m = np.column_stack([rng.integers(0, n1, n), rng.integers(0, n2, n)]).astype(np.int64)
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    x1, x2 = rng.uniform(-0.2, 0.2, 3 * n1), rng.uniform(-0.2, 0.2, 3 * n2)
    dist = np.array(
        [
            np.dot(x2[3 * b : 3 * b + 3] - x1[3 * a : 3 * a + 3], nn)
            for (a, b), nn in zip(m, normals, strict=True)
        ]
    )
    dist += np.where(np.arange(n) % 3 == 0, -0.05, 0.1)  # every third contact apart, the rest pressed
    p = Penalty(shim, m, normals, dist, rng.uniform(5, 50, n), n1, n2)
    base = p.run(x1, x2)
    active = base["pen"] > 0
    assert 0 < active.sum() < n
    x = np.concatenate([x1, x2])
    h = 1e-6

    def at(y: np.ndarray) -> dict:
        return p.run(y[: 3 * n1], y[3 * n1 :])

    grad = np.array([(at(x + h * e)["energy"] - at(x - h * e)["energy"]) / (2 * h) for e in np.eye(x.size)])
    assert np.abs(base["f"] + grad).max() < 1e-7  # f = -dE/dx
    jac = np.column_stack([(at(x + h * e)["f"] - at(x - h * e)["f"]) / (2 * h) for e in np.eye(x.size)])
    for k_factor in (1.0, -0.3):
        dx = rng.normal(size=x.size)
        df = p.run(x1, x2, dx[: 3 * n1], dx[3 * n1 :], k_factor)["df"]
        assert np.abs(df - k_factor * jac @ dx).max() < 1e-6 * np.abs(jac).max()
        assert np.abs(p.run(x1, x2, k_factor=k_factor)["K"] - k_factor * jac).max() < 1e-6 * np.abs(jac).max()


def test_points_come_to_rest_on_a_floor(shim: Shim) -> None:
    """The whole chain in a loop: points dropped on a static floor settle where the penalty force
    carries their weight, ks (dist - h) = m g with dist = contactDistance and ks = k1 k2 / dist, one
    contact each (the point on the shared diagonal is reported once, by the triangle owning that
    edge), and the steps after the first allocate nothing."""
    x = np.array([[0.3, -0.4, 0.3], [-0.5, 0.2, 0.25], [0.2, 0.2, 0.35], [0.9, 0.9, 0.2], [-2.0, 0.0, 0.3]])
    steps = 4000
    counts = np.zeros(steps, dtype=np.int64)
    mass, k1, k2, contact = 1.0, 100.0, 10.0, 0.05
    allocations = shim.lib.drop_points(_d(x), 5, steps, 1e-3, mass, 120.0, k1, k2, 0.2, contact, _i(counts))
    assert allocations == 0
    ks = k1 * k2 / contact
    rest = contact - mass * 9.81 / ks
    assert np.abs(x[:4, 2] - rest).max() < 1e-9
    assert close(x[:4, :2], [(0.3, -0.4), (-0.5, 0.2), (0.2, 0.2), (0.9, 0.9)], 1e-12)  # pushed straight up
    assert x[4, 2] < 0  # off the floor: it falls past the floor plane
    assert counts[-1] == 4 and counts[0] == 0


def test_penalty_contacts_from_outputs(shim: Shim) -> None:
    """De-duplication by id (a later duplicate replaces the first only with a strictly smaller
    value, at its own position), barycentric contact points on the triangle side, identity on
    the point side, ks = k1 k2 / (contactDistance + both models' contactDistance)."""
    tri_x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    triangles = np.array([[0, 1, 2], [1, 3, 2]], dtype=np.int64)
    point_x = np.zeros((8, 3))
    rows = []
    for p0, tri, point, ident, value in [
        ((0.2, 0.2, 0), 0, 3, 3, 0.1),
        ((0.7, 0.6, 0), 1, 5, 5, 0.2),
        ((0.3, 0.1, 0), 0, 3, 3, 0.05),
        ((0.1, 0.1, 0), 0, 3, 3, 0.05),
    ]:
        rows.append([*p0, 0, 0, 1, 0, 0, 1, value, tri, point, ident])
    rows_a = np.ascontiguousarray(rows, dtype=float)
    contact_rows = np.zeros((4, 4), dtype=np.int64)
    values = np.zeros((4, 2))
    mapped = np.zeros((4, 3))
    count = shim.lib.penalty_from_outputs(
        _d(rows_a), 4, 8, _d(tri_x), _i(triangles), 0.01, 20.0, _d(point_x), 0.02, 3.0, 0.1, _i(contact_rows),
        _d(values), _d(mapped),
    )  # fmt: skip
    assert count == 2
    assert contact_rows[:2].tolist() == [[0, 5, 1, 5], [1, 3, 0, 3]]
    assert close(mapped[:2], [(0.7, 0.6, 0), (0.3, 0.1, 0)], 1e-15)
    assert close(values[:2], [(0.13, 60 / 0.13), (0.13, 60 / 0.13)], 1e-12)


def test_barycentric_contact_points(shim: Shim) -> None:
    x = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 3]])
    triangles = np.array([[0, 1, 2]], dtype=np.int64)
    edges = np.array([[0, 3]], dtype=np.int64)
    P = np.array([[0.5, 0.5, 0.7], [3.0, -1, 0], [-1, -1, 0], [2, 2, 0], [0, 0, 4], [0, 0, 1.5]])
    element = np.zeros(6, dtype=np.int64)
    in_line = np.array([0, 0, 0, 0, 1, 1], dtype=np.int32)
    f = np.random.default_rng(1).normal(size=(6, 3))
    mapped, jt = np.zeros((6, 3)), np.zeros((4, 3))
    flags = in_line.ctypes.data_as(ctypes.POINTER(ctypes.c_int))
    shim.lib.barycentric(
        _d(x), _i(triangles), _i(edges), _d(P), _i(element), flags, 6, _d(mapped), _d(f), _d(jt)
    )
    # in the triangle: the projection; outside: the closest corner or edge point; lines: unclamped
    assert close(mapped, [(0.5, 0.5, 0), (2, 0, 0), (0, 0, 0), (1, 1, 0), (0, 0, 4), (0, 0, 1.5)], 1e-15)
    weights = np.zeros((6, 4))  # each point's weights on the four vertices, from the mapped points
    weights[:4, 1], weights[:4, 2] = mapped[:4, 0] / 2, mapped[:4, 1] / 2
    weights[:4, 0] = 1 - weights[:4, 1] - weights[:4, 2]
    weights[4:, 3] = mapped[4:, 2] / 3
    weights[4:, 0] = 1 - weights[4:, 3]
    assert close(jt, weights.T @ f, 1e-14)


# -------------------------------------------------------------------------------------------------
# LocalMinDistance

# A flat unit square of two triangles (normals +z) with MeshTopology's edges: (1,2), (2,0) the
# shared diagonal, (0,1), (2,3), (3,0).
SQUARE = (
    np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
    np.array([[0, 1, 2], [0, 2, 3]]),
    np.array([[1, 2], [2, 0], [0, 1], [2, 3], [3, 0]]),
)


def test_lmd_triangle_point_and_the_triangle_side(shim: Shim) -> None:
    (o,), _ = shim.lmd("TP", triangle(), 0, points((0.25, 0.25, 0.3)), 0, 1.0, 0.1)
    assert close(o.p0, (0.25, 0.25, 0)) and close(o.p1, (0.25, 0.25, 0.3)) and close(o.normal, (0, 0, 1))
    assert o.value == pytest.approx(0.2) and o.id == 0
    below = points((0.25, 0.25, -0.3))
    assert not shim.lmd("TP", triangle(), 0, below, 0, 1.0, 0.1)[0]  # behind the triangle
    assert shim.lmd("TP", triangle(), 0, below, 0, 1.0, 0.1, both_side=True)[0]
    assert shim.lmd("TP", triangle(), 0, below, 0, 1.0, 0.1, filter=False)[0]
    assert not shim.lmd("TP", triangle(), 0, points((0.5, 0.0, 0.3)), 0, 1.0, 0.1)[0]  # interior only


def test_lmd_point_cone(shim: Shim) -> None:
    """Vertex 2 of the square against a triangle above it (facing down): inside its cone; below
    it: outside; a triangle tilted so that PQ leans 17 degrees towards the mesh: outside the
    edge cone unless angleCone widens it."""
    vertex = Model(SQUARE[0])
    above = triangle(np.array([[0.5, 0.5, 0.2], [0.5, 2, 0.2], [2, 0.5, 0.2]]))
    below = triangle(np.array([[0.5, 0.5, -0.2], [2, 0.5, -0.2], [0.5, 2, -0.2]]))
    (o,), _ = shim.lmd("TP", above, 0, vertex, 2, 1.0, 0.1, mesh=SQUARE, cones=1)
    assert close(o.p1, (1, 1, 0)) and close(o.p0, (1, 1, 0.2))
    assert not shim.lmd("TP", below, 0, vertex, 2, 1.0, 0.1, mesh=SQUARE, cones=1)[0]
    assert shim.lmd("TP", below, 0, vertex, 2, 1.0, 0.1)[0]  # no cone without the point's topology
    tilted = triangle(np.array([[0.5, 0.5, 0.05], [0.5, 2, 0.05], [2, 0.5, 0.5]]))
    assert not shim.lmd("TP", tilted, 0, vertex, 2, 1.0, 0.1, mesh=SQUARE, cones=1)[0]
    (o,), _ = shim.lmd("TP", tilted, 0, vertex, 2, 1.0, 0.1, mesh=SQUARE, cones=1, angle_cone=0.3)
    assert close(o.normal, -np.array([-0.3, 0, 1]) / math.sqrt(1.09), 1e-12)


def test_lmd_line_cone(shim: Shim) -> None:
    """The square's diagonal (two triangles around it) accepts only PQ along the mean normal; a
    boundary edge any PQ orthogonal to it."""
    lines = Model(SQUARE[0], elements=SQUARE[2])
    (o,), _ = shim.lmd("LP", lines, 1, points((0.5, 0.5, 0.3)), 0, 1.0, 0.1, mesh=SQUARE, cones=2)
    assert close(o.p0, (0.5, 0.5, 0)) and close(o.p1, (0.5, 0.5, 0.3)) and o.value == pytest.approx(0.2)
    assert not shim.lmd("LP", lines, 1, points((0.5, 0.5, -0.3)), 0, 1.0, 0.1, mesh=SQUARE, cones=2)[0]
    assert shim.lmd(
        "LP", lines, 1, points((0.5, 0.5, -0.3)), 0, 1.0, 0.1, mesh=SQUARE, cones=2, both_side=True
    )[0]
    assert shim.lmd("LP", lines, 2, points((0.5, -0.3, 0.3)), 0, 1.0, 0.1, mesh=SQUARE, cones=2)[0]
    # no clamping: beyond an end there is no contact (MinProximity would take the end point)
    assert not shim.lmd("LP", lines, 2, points((1.2, 0.0, 0.1)), 0, 1.0, 0.1)[0]
    assert shim.test("min", "LP", lines, 2, points((1.2, 0.0, 0.1)), 0, 1.0, 0.1)[0]


def test_lmd_line_line_and_spheres(shim: Shim) -> None:
    a, b = segment((-1, 0, 0), (1, 0, 0)), segment((0, -1, 0.4), (0, 1, 0.4))
    (o,), _ = shim.lmd("LL", a, 0, b, 0, 1.0, 0.1)
    assert close(o.p0, (0, 0, 0)) and close(o.p1, (0, 0, 0.4)) and o.value == pytest.approx(0.3)
    (o,), (zero, _) = shim.lmd("LL", a, 0, segment((0, -1, 0), (0, 1, 0)), 0, 1.0, 0.1)  # crossing
    assert close(o.normal, (1, 0, 0)) and o.value == -0.1 and zero == 1
    (o,), _ = shim.lmd("SS", spheres((0, 0, 0), radius=0.5), 0, spheres((1.5, 0, 0), radius=0.7), 0, 1.0, 0.1)
    assert close(o.p0, (0, 0, 0)) and close(o.p1, (1.5, 0, 0)) and o.value == pytest.approx(1.5 - 1.2 - 0.1)
    (o,), _ = shim.lmd("TS", triangle(), 0, spheres((0.25, 0.25, 0.9), radius=0.5), 0, 1.0, 0.1)
    assert close(o.p0, (0.25, 0.25, 0)) and close(o.p1, (0.25, 0.25, 0.9)) and o.value == pytest.approx(0.3)
    (o,), _ = shim.lmd("LS", a, 0, spheres((0.2, 0.5, 0), radius=0.1), 0, 1.0, 0.1)
    assert close(o.p0, (0.2, 0, 0)) and o.value == pytest.approx(0.3)  # no mirror, unlike MinProximity
    (o,), _ = shim.lmd("SP", spheres((0, 0, 0), radius=0.5), 0, points((0, 0.8, 0)), 0, 1.0, 0.1)
    assert close(o.normal, (0, 1, 0)) and o.value == pytest.approx(0.2)


# -------------------------------------------------------------------------------------------------
# Contact order (contact_order.h)


def test_contact_order_reproduces_the_briefs_harness(shim: Shim) -> None:
    """The design brief's six pairs of models 10 < 20 < 30 < 40 in broad-phase order: the output
    map keeps that order, the contact map fed from it iterates in another (g++ 12.2 harness)."""
    step = [(20, 10, 1), (30, 10, 1), (30, 20, 1), (40, 10, 1), (40, 20, 1), (40, 30, 1)]
    ((outputs, contacts),), (allocations, growths) = shim.contact_order([step], 41, sofa_expression=False)
    assert outputs == [(20, 10), (30, 10), (30, 20), (40, 10), (40, 20), (40, 30)]
    assert contacts == [(30, 10), (30, 20), (20, 10), (40, 10), (40, 30), (40, 20)]
    assert allocations == 0 and growths == 0  # nodes come from the reserved pool


def test_contact_order_matches_sofas_expression_under_gxx(shim: Shim) -> None:
    """Random steps (pairs appearing and disappearing, broad-phase order): the explicit sequence
    a.second, a.first, b.second, b.first gives the orders of SOFA's comparator as g++ compiles it."""
    rng = np.random.default_rng(4)
    n_models = 7
    candidates = [(i, j) for i in range(n_models) for j in range(i)]
    steps = []
    for _ in range(40):
        chosen = [p for p in candidates if rng.random() < 0.4]
        steps.append([(a, b, int(rng.random() < 0.7)) for a, b in chosen])
    explicit, _ = shim.contact_order(steps, n_models, sofa_expression=False)
    literal, _ = shim.contact_order(steps, n_models, sofa_expression=True)
    assert explicit == literal
    assert any(out != con for out, con in explicit)  # the two maps do disagree at times


def test_rigid_spheres_through_the_narrow_phase(shim: Shim) -> None:
    rng = np.random.default_rng(12)

    def rigid(centers: np.ndarray, radii: np.ndarray) -> Model:
        x = np.hstack([centers, np.tile([0.0, 0, 0, 1], (len(centers), 1))])
        return Model(x, radius=0.05, radii=radii, rigid=True, cd=0.01)

    a = rigid(rng.uniform(-1, 1, (120, 3)), rng.uniform(0.02, 0.08, 60))
    b = rigid(rng.uniform(-0.6, 1.4, (100, 3)), rng.uniform(0.02, 0.08, 100))
    for method in ("min", "new"):
        found, _ = shim.detect(method, "SS", a, b, depth=6, alarm=0.1, contact=0.02)
        every = shim.brute_force(method, "SS", a, b, alarm=0.1, contact=0.02)
        assert len(every) > 10 and sorted(map(key, found)) == sorted(map(key, every))
        for o in found:
            c1, c2 = a.x[o.elem1, :3], b.x[o.elem2, :3]
            r1 = a.radii[o.elem1] if o.elem1 < len(a.radii) else 0.05
            r2 = b.radii[o.elem2] if o.elem2 < len(b.radii) else 0.05
            distance = np.linalg.norm(c2 - c1)
            assert o.value == pytest.approx(distance - r1 - r2 - 0.04, abs=1e-12)
            if method == "min":  # DiscreteIntersection: the points on the rigid spheres' surfaces
                assert close(o.p0, c1 + o.normal * r1, 1e-12) and close(o.p1, c2 - o.normal * r2, 1e-12)
            else:  # NewProximity's point-point kernel keeps the centres, whatever the sphere type
                assert close(o.p0, c1) and close(o.p1, c2)


# -------------------------------------------------------------------------------------------------
# The per-step pre-test of PenaltyContacts (penalty.h begin_detection): models whose root boxes
# cannot meet skip the trees, the broad and the narrow phase.


def falling(kind: str, rng: np.random.Generator) -> tuple[Model, np.ndarray]:
    """A small model of `kind`'s second side and its positions over 60 steps: it falls from
    y = 3 onto the floor (outputs, contacts), is lifted away (contacts removed), jumps through the
    floor in one step (a fast motion while apart) and stays below. Line and triangle models have an
    extra point no element uses, far below the floor: it must not count in the root box."""
    code = kind[1]
    n = 12
    x = rng.uniform(-0.3, 0.3, (n, 3))
    if code == "P":
        model = Model(x, cd=0.02)
    elif code == "S":
        model = Model(x, radius=0.05, radii=rng.uniform(0.02, 0.1, n // 2), cd=0.01)
    else:
        shape = 2 if code == "L" else 3
        elements = np.array([rng.permutation(n)[:shape] for _ in range(8)])
        x = np.vstack([x, [[0.0, -50.0, 0.0]]])
        first, second = x[elements[:, 1]] - x[elements[:, 0]], x[elements[:, 2 % shape]] - x[elements[:, 0]]
        normals = np.cross(first, second)
        flags = rng.integers(0, 64, len(elements)) if shape == 3 else None
        model = Model(x, elements=elements, flags=flags, normals=normals if shape == 3 else None, cd=0.01)
    heights = [*np.linspace(3.0, -0.25, 40), 2.0, 2.0, 2.0, -3.0, *[-3.0 - 0.01 * k for k in range(16)]]
    xs = np.array([x + np.array([0.0, h, 0.0]) for h in heights])
    if code in "LT":
        xs[:, -1] = [0.0, -50.0, 0.0]
    return model, xs


@pytest.mark.parametrize("kind", ["TP", "TL", "TT", "TS"])
def test_pretest_changes_nothing_but_the_work(shim: Shim, kind: str) -> None:
    model, xs = falling(kind, np.random.default_rng(KINDS[kind]))
    full = shim.pretest_run(kind, model, xs, False, 0.2, 0.05, 0.01)
    fast = shim.pretest_run(kind, model, xs, True, 0.2, 0.05, 0.01)
    assert not full["skipped"].any()
    for name in ("outputs", "contacts", "energy", "fast_motions"):
        assert np.array_equal(full[name], fast[name]), name  # bit for bit
    assert fast["mismatches"] == 0  # the root box from the points is the refitted tree's
    skipped, touching = fast["skipped"].astype(bool), full["outputs"] > 0
    assert not skipped[0]  # the first detection builds the trees
    assert not (skipped & touching).any()
    assert skipped[1:20].all() and skipped[-16:].all()  # far above, then far below the floor
    first = int(np.argmax(touching))  # the first contact: at the same step either way
    assert 20 < first < 40 and not skipped[first]
    assert full["contacts"][first:40].any() and not full["contacts"][40:].any()  # lifted: removed
    assert full["fast_motions"] >= 1  # the jump through the floor, seen while skipped
