"""Numba kernels of the per-merge importance (see :mod:`gatun_py.pipeline.selective`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _voxel(p, lo, inv, g, d):
    i = int((p[d] - lo[d]) * inv[d])
    return min(max(i, 0), g - 1)


@njit(cache=True)
def _extinction_grid(points, sigma, lo, hi, g):
    """Mean extinction of the vertices in each of g^3 voxels over [lo, hi] (0 where none falls)."""
    inv = np.empty(3)
    for d in range(3):
        inv[d] = g / (hi[d] - lo[d]) if hi[d] > lo[d] else 0.0
    acc = np.zeros((g, g, g))
    cnt = np.zeros((g, g, g))
    for v in range(points.shape[0]):
        i = _voxel(points[v], lo, inv, g, 0)
        j = _voxel(points[v], lo, inv, g, 1)
        k = _voxel(points[v], lo, inv, g, 2)
        acc[i, j, k] += sigma[v]
        cnt[i, j, k] += 1.0
    for i in range(g):
        for j in range(g):
            for k in range(g):
                if cnt[i, j, k] > 0:
                    acc[i, j, k] /= cnt[i, j, k]
    return acc


@njit(cache=True)
def _transmittance(grid, lo, hi, eye, targets, n_steps):
    """exp(-integral of the extinction) from the eye to every target point, marched through the
    voxel grid in ``n_steps`` steps over the part of the segment inside the box."""
    g = grid.shape[0]
    inv = np.empty(3)
    for d in range(3):
        inv[d] = g / (hi[d] - lo[d]) if hi[d] > lo[d] else 0.0
    out = np.empty(targets.shape[0])
    p = np.empty(3)
    for r in range(targets.shape[0]):
        # clip the segment eye -> target (t in [0, 1]) to the box (slabs)
        t0 = 0.0
        t1 = 1.0
        for d in range(3):
            dv = targets[r, d] - eye[d]
            if dv != 0.0:
                a = (lo[d] - eye[d]) / dv
                b = (hi[d] - eye[d]) / dv
                if a > b:
                    a, b = b, a
                t0 = max(t0, a)
                t1 = min(t1, b)
        length = 0.0
        for d in range(3):
            length += (targets[r, d] - eye[d]) ** 2
        length = math.sqrt(length)
        tau = 0.0
        if t1 > t0:
            dt = (t1 - t0) / n_steps
            for s in range(n_steps):
                t = t0 + (s + 0.5) * dt
                for d in range(3):
                    p[d] = eye[d] + t * (targets[r, d] - eye[d])
                tau += grid[_voxel(p, lo, inv, g, 0), _voxel(p, lo, inv, g, 1), _voxel(p, lo, inv, g, 2)]
            tau *= dt * length
        out[r] = math.exp(-tau)
    return out


@njit(cache=True)
def _lookup(table, lo, inv, s, out):
    """(r, g, b, a) at scalar s, linear between the table's entries, clamped at its ends."""
    x = (s - lo) * inv
    n = table.shape[0]
    if not x > 0.0:
        x = 0.0
    if x > n - 1:
        x = n - 1.0
    i = min(int(x), n - 2)
    f = x - i
    for c in range(4):
        out[c] = table[i, c] + f * (table[i + 1, c] - table[i, c])


@njit(cache=True)
def _colour_change(table, lo, inv, sv, st, n_samples, opaque_share):
    """Per merge: the largest change of premultiplied (r a, g a, b a, a) between s(v) and the
    values on [s(v), s(t)] (mean over the four channels), plus ``opaque_share`` x the largest
    opacity there."""
    k = sv.shape[0]
    out = np.empty(k)
    c0 = np.empty(4)
    c = np.empty(4)
    for i in range(k):
        _lookup(table, lo, inv, sv[i], c0)
        a0 = min(max(c0[3], 0.0), 1.0)
        best = 0.0
        amax = a0
        for j in range(1, n_samples):
            s = sv[i] + (st[i] - sv[i]) * j / (n_samples - 1)
            _lookup(table, lo, inv, s, c)
            a = min(max(c[3], 0.0), 1.0)
            d = abs(a - a0)
            for ch in range(3):
                d += abs(c[ch] * a - c0[ch] * a0)
            if d > best:
                best = d
            if a > amax:
                amax = a
        out[i] = best / 4.0 + opaque_share * amax
    return out
