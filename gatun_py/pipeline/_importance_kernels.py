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
    """:func:`_transmittance_where` at every target."""
    return _transmittance_where(grid, lo, hi, eye, targets, n_steps, np.ones(targets.shape[0], np.bool_))


@njit(cache=True)
def _transmittance_where(grid, lo, hi, eye, targets, n_steps, need):
    """exp(-integral of the extinction) from the eye to every target point, marched through the
    voxel grid in ``n_steps`` steps over the part of the segment inside the box (1 where ``need``
    is False: a factor that cannot matter there is not computed)."""
    g = grid.shape[0]
    inv = np.empty(3)
    for d in range(3):
        inv[d] = g / (hi[d] - lo[d]) if hi[d] > lo[d] else 0.0
    out = np.empty(targets.shape[0])
    p = np.empty(3)
    for r in range(targets.shape[0]):
        if not need[r]:
            out[r] = 1.0
            continue
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


@njit(cache=True)
def _merge_regions(vertex, target, points, scalars):
    """What merge i changes in its prefix state: v_i and every vertex merged into it before (its
    subtree of the forest) move onto t_i and take its value. Per merge, in rank order: the radius
    of that region about t_i (farthest corner of the subtree's bounding box) and the scalar range
    over the subtree and t_i. O(n): a subtree's box and range are final when its root merges
    (children have lower ranks than their parent), then fold into the parent's."""
    k = vertex.shape[0]
    box_lo = points.copy()
    box_hi = points.copy()
    s_lo = scalars.copy()
    s_hi = scalars.copy()
    radius = np.empty(k)
    lo = np.empty(k)
    hi = np.empty(k)
    for i in range(k):
        v = vertex[i]
        t = target[i]
        r2 = 0.0
        for d in range(3):
            dd = max(abs(box_lo[v, d] - points[t, d]), abs(box_hi[v, d] - points[t, d]))
            r2 += dd * dd
            box_lo[t, d] = min(box_lo[t, d], box_lo[v, d])
            box_hi[t, d] = max(box_hi[t, d], box_hi[v, d])
        radius[i] = math.sqrt(r2)
        lo[i] = min(s_lo[v], scalars[t])
        hi[i] = max(s_hi[v], scalars[t])
        s_lo[t] = min(s_lo[t], s_lo[v])
        s_hi[t] = max(s_hi[t], s_hi[v])
    return radius, lo, hi


@njit(cache=True)
def _region_colour_error(table, t_lo, t_inv, lo, hi, st, radius, boundary, unit, n_samples):
    """Per merge: the largest change of premultiplied (r a, g a, b a, a), mean over the four, between
    the target's value st and any value on [lo, hi], the opacity being that of a path through the
    region (2 x radius: 1 - (1 - a)^(2 r / unit)). A boundary merge moves the boundary by up to the
    radius: there the change is against nothing (what a path of that length showed disappears or
    appears)."""
    k = lo.shape[0]
    out = np.empty(k)
    c0 = np.empty(4)
    c = np.empty(4)
    for i in range(k):
        path = 2.0 * radius[i] / unit
        _lookup(table, t_lo, t_inv, st[i], c0)
        a0 = 1.0 - (1.0 - min(max(c0[3], 0.0), 0.999999)) ** path
        if boundary[i]:
            a0 = 0.0
        best = 0.0
        for j in range(n_samples):
            s = lo[i] + (hi[i] - lo[i]) * j / (n_samples - 1)
            _lookup(table, t_lo, t_inv, s, c)
            a = 1.0 - (1.0 - min(max(c[3], 0.0), 0.999999)) ** path
            d = abs(a - a0)
            for ch in range(3):
                d += abs(c[ch] * a - c0[ch] * a0)
            if d > best:
                best = d
        out[i] = best / 4.0
    return out


@njit(cache=True)
def _subtree_max(key, vertex, target, rank):
    """key(i) raised to the largest key of the merges into v_i (its children), in rank order: a
    merge never sorts before one of its children (ties: by rank)."""
    k = key.shape[0]
    best = np.full(rank.shape[0], -np.inf)
    out = np.empty(k)
    for i in range(k):
        v = vertex[i]
        x = max(key[i], best[v])
        out[i] = x
        t = target[i]
        if x > best[t]:
            best[t] = x
    return out


@njit(cache=True)
def _projected_size(pv, length, eye, fwd, right, up, tan_half, width, height):
    """Per merge: |v t| seen from the camera in pixels (0 behind the camera or off the image, the
    merge's own extent as margin), as :meth:`FittedCamera.project` places points."""
    k = pv.shape[0]
    out = np.empty(k)
    pixel = 2.0 * tan_half / height
    for i in range(k):
        rx = pv[i, 0] - eye[0]
        ry = pv[i, 1] - eye[1]
        rz = pv[i, 2] - eye[2]
        z = rx * fwd[0] + ry * fwd[1] + rz * fwd[2]
        if not z > 0.0:
            out[i] = 0.0
            continue
        px = length[i] / (z * pixel)
        x = (rx * right[0] + ry * right[1] + rz * right[2]) / (z * tan_half * (width / height))
        y = (rx * up[0] + ry * up[1] + rz * up[2]) / (z * tan_half)
        col = (x + 1.0) * width / 2.0
        row = (1.0 - y) * height / 2.0
        if col >= -px and col <= width + px and row >= -px and row <= height + px:
            out[i] = px
        else:
            out[i] = 0.0
    return out


@njit(cache=True)
def _cell_centres(lo, hi, g):
    """Centres of the g^3 cells over [lo, hi], x slowest."""
    out = np.empty((g * g * g, 3))
    r = 0
    for i in range(g):
        for j in range(g):
            for k in range(g):
                out[r, 0] = lo[0] + (i + 0.5) * (hi[0] - lo[0]) / g
                out[r, 1] = lo[1] + (j + 0.5) * (hi[1] - lo[1]) / g
                out[r, 2] = lo[2] + (k + 0.5) * (hi[2] - lo[2]) / g
                r += 1
    return out


@njit(cache=True)
def _trilinear(values, lo, hi, pts, need):
    """``values`` (g, g, g) given at the cell centres over [lo, hi], interpolated at every point
    (clamped to the outer centres; 1 where ``need`` is False). g >= 2."""
    g = values.shape[0]
    out = np.empty(pts.shape[0])
    scale = np.empty(3)
    for d in range(3):
        scale[d] = g / (hi[d] - lo[d]) if hi[d] > lo[d] else 0.0
    for r in range(pts.shape[0]):
        if not need[r]:
            out[r] = 1.0
            continue
        x = min(max((pts[r, 0] - lo[0]) * scale[0] - 0.5, 0.0), g - 1.0)
        y = min(max((pts[r, 1] - lo[1]) * scale[1] - 0.5, 0.0), g - 1.0)
        z = min(max((pts[r, 2] - lo[2]) * scale[2] - 0.5, 0.0), g - 1.0)
        i = min(int(x), g - 2)
        j = min(int(y), g - 2)
        k = min(int(z), g - 2)
        fx = x - i
        fy = y - j
        fz = z - k
        c00 = values[i, j, k] * (1.0 - fx) + values[i + 1, j, k] * fx
        c10 = values[i, j + 1, k] * (1.0 - fx) + values[i + 1, j + 1, k] * fx
        c01 = values[i, j, k + 1] * (1.0 - fx) + values[i + 1, j, k + 1] * fx
        c11 = values[i, j + 1, k + 1] * (1.0 - fx) + values[i + 1, j + 1, k + 1] * fx
        c0 = c00 * (1.0 - fy) + c10 * fy
        c1 = c01 * (1.0 - fy) + c11 * fy
        out[r] = c0 * (1.0 - fz) + c1 * fz
    return out
