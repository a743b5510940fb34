"""Slow plain references for gatun_py.contour.qem: quadrics, cost and placement.

A quadric is the 10 numbers (a00, a01, a02, b0, a11, a12, b1, a22, b2, c) of
Q(x) = x^T A x + 2 b^T x + c. The placement of an edge collapse is the cheapest point the kernel may
choose: the quadric's own minimum (with the same small ridge toward the edge's midpoint) when it lies
near the edge, else the cheapest point of the segment, found here by brute-force sampling.
"""

from __future__ import annotations

import numpy as np

DET_FLOOR = 1e-12  # below it (relative to trace^3) the system counts as singular


def quadric_matrix(q):
    """(A (3, 3), b (3,), c) of a 10-number quadric."""
    q = np.asarray(q, np.float64)
    a = np.array([[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]])
    return a, np.array([q[3], q[6], q[8]]), q[9]


def quadric_cost(q, x):
    a, b, c = quadric_matrix(q)
    x = np.asarray(x, np.float64)
    return float(x @ a @ x + 2 * b @ x + c)


def plane_quadric(n, d, w=1.0):
    """The quadric w (n . x + d)^2 of a plane (n unit)."""
    n = np.asarray(n, np.float64)
    return w * np.array([n[0] * n[0], n[0] * n[1], n[0] * n[2], n[0] * d, n[1] * n[1], n[1] * n[2], n[1] * d,
                         n[2] * n[2], n[2] * d, d * d])


def naive_segment_min(q, pu, pv, steps: int = 20001):
    """The cheapest of ``steps`` evenly spaced points of segment pu-pv: (cost, point)."""
    t = np.linspace(0.0, 1.0, steps)[:, None]
    pts = np.asarray(pu, np.float64) + t * (np.asarray(pv, np.float64) - np.asarray(pu, np.float64))
    a, b, c = quadric_matrix(q)
    costs = np.einsum("ij,jk,ik->i", pts, a, pts) + 2 * pts @ b + c
    i = int(np.argmin(costs))
    return float(costs[i]), pts[i]


def naive_placement(q, pu, pv, *, ridge: float, reach: float):
    """(cost, point) the kernel should pick for collapsing u-v (up to the segment's sampling); the
    surface boundary needs no rule of its own (its constraint planes are in the quadric)."""
    pu, pv = np.asarray(pu, np.float64), np.asarray(pv, np.float64)
    a, b, _ = quadric_matrix(q)
    m = 0.5 * (pu + pv)
    best = (np.inf, None)
    tr = np.trace(a)
    # the kernel solves only a well-conditioned system: |det(A + eps I)| > 1e-12 trace^3
    if tr > 0 and abs(np.linalg.det(a + ridge * tr * np.eye(3))) > DET_FLOOR * tr ** 3:
        eps = ridge * tr
        x = np.linalg.solve(a + eps * np.eye(3), -b + eps * m)
        if np.sum((x - m) ** 2) <= reach * np.sum((pv - pu) ** 2):
            best = (quadric_cost(q, x), x)
    seg = naive_segment_min(q, pu, pv)
    if seg[0] < best[0]:
        best = seg
    return max(best[0], 0.0), best[1]


def naive_edge_cost(q, pu, pv, imp_u, imp_v, *, ridge: float, reach: float, weight_power: float):
    """The heap key of collapsing u-v under the edge's quadric ``q``: the placement's cost over the
    quadric's total weight (the sum of its planes' weights, its trace) to ``weight_power``, times the
    larger importance of the two ends."""
    cost, _ = naive_placement(q, pu, pv, ridge=ridge, reach=reach)
    weight = float(np.trace(quadric_matrix(q)[0]))
    if weight > 0:
        cost /= weight ** weight_power
    return cost * max(imp_u, imp_v)


def naive_face_quadrics(points, triangles, importance=None):
    """Per face (unit normal n, offset d, weight): the plane n . x + d = 0 and the face's area times
    the mean importance of its corners (weight 0 for a degenerate face)."""
    p = np.asarray(points, np.float64)
    out = []
    for a, b, c in np.asarray(triangles):
        n = np.cross(p[b] - p[a], p[c] - p[a])
        ln = np.linalg.norm(n)
        if ln == 0:
            out.append((np.zeros(3), 0.0, 0.0))
            continue
        n = n / ln
        imp = 1.0 if importance is None else (importance[a] + importance[b] + importance[c]) / 3
        out.append((n, -float(n @ p[a]), 0.5 * ln * imp))
    return out


def naive_border_planes(points, triangles, v, weight):
    """The constraint planes of vertex v's border edges (edges of one face): through the edge,
    perpendicular to that face, weighted ``weight`` x the edge's length squared (Garland)."""
    p = np.asarray(points, np.float64)
    t = np.asarray(triangles)
    q = np.zeros(10)
    faces = [f for f in t if v in f]
    nbrs = {}
    for f in faces:
        for w in f:
            if w != v:
                nbrs.setdefault(int(w), []).append(f)
    for w, fs in nbrs.items():
        if len(fs) != 1:
            continue
        a, b, c = fs[0]
        n = np.cross(p[b] - p[a], p[c] - p[a])
        e = p[w] - p[v]
        perp = np.cross(e, n)
        if np.linalg.norm(perp) == 0:
            continue
        perp = perp / np.linalg.norm(perp)
        q += plane_quadric(perp, -float(perp @ p[v]), w=weight * float(e @ e))
    return q


def naive_current_quadric(points, triangles, v, *, border_weight, importance=None):
    """The memoryless quadric of vertex v: the weighted planes of the faces around it as they are,
    plus its border's constraint planes."""
    t = np.asarray(triangles)
    around = np.flatnonzero((t == v).any(axis=1))
    q = np.zeros(10)
    for (n, d, w) in naive_face_quadrics(points, t[around], importance):
        if w > 0:
            q += plane_quadric(n, d, w)
    return q + naive_border_planes(points, t, v, border_weight)


def naive_fan_distance(points, triangles, u, v, new_pos, samples):
    """The largest squared distance from ``samples`` to the faces around u and v once u and v merge
    at ``new_pos`` (the faces on edge uv gone), or to ``new_pos`` when no face is left. Exact
    point-to-triangle distances from the metric module's own routine (a separate implementation)."""
    from gatun_py.contour.metrics import _point_triangle

    p = np.asarray(points, np.float64).copy()
    p[u] = p[v] = new_pos
    fan = [f for f in np.asarray(triangles) if (u in f) != (v in f)]
    worst = 0.0
    for s in np.asarray(samples, np.float64):
        d = [float(_point_triangle(s[0], s[1], s[2], p[a], p[b], p[c])) for a, b, c in fan]
        d = [x for x in d if np.isfinite(x)]  # a flat face: its edges belong to the others
        worst = max(worst, min(d) if d else float(np.sum((s - new_pos) ** 2)))
    return worst
