"""Slow plain references for gatun_py.isosurface.qem's cost and placement.

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
