"""Compile-time side of FastTriangularBendingSprings: one spring per edge shared by exactly two
triangles, with SOFA's weights and stiffness (``EdgeSpring::setEdgeSpring``), from the rest
positions, in SOFA's order of floating-point operations (plain float arithmetic, no numpy
reductions, so that every value has the bits SOFA computes).

SOFA builds the springs triangle by triangle (``applyTriangleCreation``); an edge shared by two
triangles is set twice and keeps the second setting: A is the vertex opposite the edge in the
triangle of lower index, B the one in the other triangle, C and D the edge's two vertices as the
topology stores them. Springs are listed in the topology's edge order.
"""

from __future__ import annotations

import math

import numpy as np

_EPSILON = 2.220446049250313e-16  # std::numeric_limits<double>::epsilon(): SOFA's Vec::normalize


def _sub(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _norm(a: tuple[float, ...]) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def _spring(p: list[tuple[float, float, float]], stiffness: float) -> tuple[list[float], float]:
    """SOFA's setEdgeSpring for the points A, B, C, D: the weights alpha and the stiffness lambda."""
    a, b, c, d = p
    na = _norm(_cross(_sub(a, c), _sub(a, d)))
    nb = _norm(_cross(_sub(b, d), _sub(b, c)))
    nc = _norm(_cross(_sub(c, b), _sub(c, a)))
    nd = _norm(_cross(_sub(d, a), _sub(d, b)))
    alpha = [nb / (na + nb), na / (na + nb), -nd / (nc + nd), -nc / (nc + nd)]
    edge = _sub(c, d)
    length = _norm(edge)
    if length > _EPSILON:
        edge = (edge[0] / length, edge[1] / length, edge[2] / length)
    ac, bc = _sub(c, a), _sub(c, b)
    dot_a = ac[0] * edge[0] + ac[1] * edge[1] + ac[2] * edge[2]
    dot_b = bc[0] * edge[0] + bc[1] * edge[1] + bc[2] * edge[2]
    ha = _norm(_sub(ac, (edge[0] * dot_a, edge[1] * dot_a, edge[2] * dot_a)))
    hb = _norm(_sub(bc, (edge[0] * dot_b, edge[1] * dot_b, edge[2] * dot_b)))
    l_cd = _norm(_sub(c, d))
    lam = (2.0 / 3.0) * (ha + hb) / (ha * ha * hb * hb) * l_cd * stiffness
    return alpha, lam


def bending_springs(
    rest: np.ndarray, triangles: np.ndarray, edges: np.ndarray, stiffness: float, min_dist: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vid (k, 4) int64, alpha (k, 4), lambda (k,)) of the springs, in edge order."""
    points = [tuple(float(v) for v in row) for row in np.asarray(rest, dtype=float).reshape(-1, 3)]
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    around: dict[tuple[int, int], list[int]] = {}
    for index, tri in enumerate(tris.tolist()):
        for j in range(3):
            u, v = tri[(j + 1) % 3], tri[(j + 2) % 3]
            around.setdefault((min(u, v), max(u, v)), []).append(index)
    epsilon_sq = min_dist * min_dist
    vids: list[list[int]] = []
    alphas: list[list[float]] = []
    lambdas: list[float] = []
    for e1, e2 in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist():
        shell = around.get((min(e1, e2), max(e1, e2)), [])
        if len(shell) != 2:
            continue
        first, second = sorted(shell)
        v1 = next(v for v in tris[first].tolist() if v not in (e1, e2))
        v2 = next(v for v in tris[second].tolist() if v not in (e1, e2))
        vp, ve = _sub(points[v2], points[v1]), _sub(points[e2], points[e1])
        if not (_dot(vp) > epsilon_sq and _dot(ve) > epsilon_sq):
            continue
        alpha, lam = _spring([points[v1], points[v2], points[e1], points[e2]], stiffness)
        vids.append([v1, v2, e1, e2])
        alphas.append(alpha)
        lambdas.append(lam)
    return (
        np.asarray(vids, dtype=np.int64).reshape(-1, 4),
        np.asarray(alphas, dtype=float).reshape(-1, 4),
        np.asarray(lambdas, dtype=float),
    )


def _dot(a: tuple[float, float, float]) -> float:
    return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
