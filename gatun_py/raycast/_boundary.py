"""The ray caster's boundary kernels (private): pixel rays against the boundary surface, cut into
segments.

Every pixel ray is tested against every boundary face it may cross (:func:`_boundary_hits`, the
walk's own crossing rule); each ray's crossings, sorted by depth, pair up into segments (entry,
exit; several per ray on non-convex meshes and cavities), and each segment gets its two
subsegments standing on its two boundary faces (:func:`find_segments`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._geom import NEAR, _edge_cross, _edge_terms, _face_values, _norm, _project, _side_cross, _sort3
from ._segments import FRONT, TS_SCALAR, TS_T, make_segments


@njit(cache=True, _nrt=False)
def _clip_side(lo, hi, b, r, inv_r, tol):
    """Narrow [lo, hi] to (a superset of) the x with b + x r >= -tol (empty: lo > hi).

    ``inv_r`` = 1 / r, or 0 where r is 0 or too small to invert (such a side changes by less than
    1e-290 over the image: it is taken as constant). The bound -(tol + b) / r is rounded by a few
    ulps, far less than the x by which ``tol`` exceeds the sides' own rounding error.
    """
    if inv_r > 0.0:
        lo = max(lo, (-tol - b) * inv_r)
    elif inv_r < 0.0:
        hi = min(hi, (-tol - b) * inv_r)
    elif b < -tol:
        hi = lo - 1.0
    return lo, hi


@njit(cache=True, _nrt=False)
def _inverse(r):
    return 1.0 / r if abs(r) > 1e-300 else 0.0


@njit(cache=True, _nrt=False)
def _row_span(b0, r0, i0, t0, b1, r1, i1, t1, b2, r2, i2, t2, xlo, xhi):
    """The x in [xlo, xhi] where three sides b_k + x r_k can share a sign (within their bounds t_k):
    the hull of the part where all are >= -t_k and the part where all are <= t_k. ``i_k`` = 1 / r_k
    (see :func:`_clip_side`)."""
    lo, hi = _clip_side(xlo, xhi, b0, r0, i0, t0)
    lo, hi = _clip_side(lo, hi, b1, r1, i1, t1)
    lo, hi = _clip_side(lo, hi, b2, r2, i2, t2)
    lo2, hi2 = _clip_side(xlo, xhi, -b0, -r0, -i0, t0)
    lo2, hi2 = _clip_side(lo2, hi2, -b1, -r1, -i1, t1)
    lo2, hi2 = _clip_side(lo2, hi2, -b2, -r2, -i2, t2)
    if not lo <= hi:
        return lo2, hi2
    if lo2 <= hi2:
        return min(lo, lo2), max(hi, hi2)
    return lo, hi


@njit(cache=True, _nrt=False)
def _box_edge(v, n):
    """A pixel box bound ``v`` (a float) clamped to 0..n as an int."""
    if not v > 0.0:  # also NaN
        return 0
    if v >= n:
        return n
    return int(v)


@njit(cache=True, _nrt=False)
def _pixel_box(P, i0, i1, i2, fwd, right, up, tan_half, width, height):
    """Pixel box [col0, col1) x [row0, row1) of triangle (i0, i1, i2) (in front of the eye), one pixel
    to spare on each side."""
    aspect = width / height
    _, c0, r0 = _project(P, i0, fwd, right, up, tan_half, aspect, width, height)
    _, c1, r1 = _project(P, i1, fwd, right, up, tan_half, aspect, width, height)
    _, c2, r2 = _project(P, i2, fwd, right, up, tan_half, aspect, width, height)
    return (_box_edge(np.floor(min(c0, min(c1, c2))) - 1.0, width),
            _box_edge(np.ceil(max(c0, max(c1, c2))) + 2.0, width),
            _box_edge(np.floor(min(r0, min(r1, r2))) - 1.0, height),
            _box_edge(np.ceil(max(r0, max(r1, r2))) + 2.0, height))


@njit(cache=True, parallel=True)
def _boundary_hits(P, dens, dirs, width, height, faces, fwd, right, up, xs, ys, tan_half, counts, offsets, out_ray,
                   out_t, out_face, out_enter, fill):
    """Pixel rays crossing each boundary face (``fill`` False: count them; True: record them).

    A ray crosses face (i0, i1, i2) when the signs of its three edge sides agree (:func:`_side_cross`,
    the walk's own test). Only the pixels of each row's span are tested: an edge side is linear in
    the pixel's offsets ``xs``, ``ys`` along ``right`` and ``up`` (as in :func:`count_crossings`),
    so the columns where the three can share a sign, within a rounding bound far above the
    error of the side itself (``NEAR``), form an interval. Every pixel outside it has two sides of
    certain, opposite signs: skipping it changes no hit, and the hits come out in the same order as
    from testing every pixel of the face's box.
    """
    # One task per face; the face's work is a plain function, compiled once rather than inlined
    # into the parallel loop (inlined, this kernel took 20 s to compile).
    for f in prange(faces.shape[0]):
        # f as a signed int: the parallel loop's own index is unsigned, which would compile _face_hits
        # a second time (for the loop body) beside the signed one the typing pass asks for
        n = _face_hits(P, dens, dirs, width, height, faces, np.int64(f), fwd, right, up, xs, ys, tan_half,
                       offsets[f] if fill else 0, out_ray, out_t, out_face, out_enter, fill)
        if not fill:
            counts[f] = n


@njit(cache=True, _nrt=False)
def _face_hits(P, dens, dirs, width, height, faces, f, fwd, right, up, xs, ys, tan_half, base, out_ray, out_t,
               out_face, out_enter, fill):
    """:func:`_boundary_hits` for face ``f``: records its hits from ``base`` on (if ``fill``); returns their number."""
    i0, i1, i2 = np.int64(faces[f, 0]), np.int64(faces[f, 1]), np.int64(faces[f, 2])
    n = 0
    # the edges' cross products do not depend on the ray: once per face, not per pixel
    ax, ay, az, af = _edge_cross(P, i0, i1)
    bx, by, bz, bf = _edge_cross(P, i1, i2)
    cx, cy, cz, cf = _edge_cross(P, i2, i0)
    c0, c1, row0, row1 = _pixel_box(P, i0, i1, i2, fwd, right, up, tan_half, width, height)
    if c0 >= c1:
        return 0
    # the three directed sides over the image plane: f + x r + y u
    f01, r01, u01 = _edge_terms(P, i0, i1, fwd, right, up)
    f12, r12, u12 = _edge_terms(P, i1, i2, fwd, right, up)
    f20, r20, u20 = _edge_terms(P, i2, i0, fwd, right, up)
    m0, m1, m2 = _norm(P, i0), _norm(P, i1), _norm(P, i2)
    t01, t12, t20 = NEAR * m0 * m1, NEAR * m1 * m2, NEAR * m2 * m0
    i01, i12, i20 = _inverse(r01), _inverse(r12), _inverse(r20)
    half = 0.5 * width
    xscale = tan_half * (width / height)
    for row in range(row0, row1):
        y = ys[row]
        xlo, xhi = _row_span(f01 + y * u01, r01, i01, t01, f12 + y * u12, r12, i12, t12, f20 + y * u20, r20, i20,
                             t20, xs[c0], xs[c1 - 1])
        if not xlo <= xhi:
            continue
        # the columns whose xs lie in [xlo, xhi] (xs[col] = (2 (col + 0.5) / width - 1) xscale),
        # a millionth of a column to spare for the rounding of this mapping
        col_lo = max(c0, int(math.ceil((xlo / xscale + 1.0) * half - 0.5 - 1e-6)))
        col_hi = min(c1, int(math.floor((xhi / xscale + 1.0) * half - 0.5 + 1e-6)) + 1)
        for col in range(col_lo, col_hi):
            r = row * width + col
            dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
            _, s01 = _side_cross(ax, ay, az, af, dx, dy, dz)
            _, s12 = _side_cross(bx, by, bz, bf, dx, dy, dz)
            if s01 != s12:
                continue
            _, s20 = _side_cross(cx, cy, cz, cf, dx, dy, dz)
            if s20 != s01:
                continue
            if fill:
                a, b, c, par = _sort3(i0, i1, i2)
                t, _ = _face_values(P, dens, dx, dy, dz, a, b, c)
                out_ray[base + n] = r
                out_t[base + n] = t
                out_face[base + n] = f
                out_enter[base + n] = s01 < 0
            n += 1
    return n


@njit(cache=True)
def group_by_ray(ray, n_rays):
    """A stable counting sort by ray: ``order`` lists the items ray by ray, ray r's are
    ``order[start[r]:start[r + 1]]`` (boundary crossings here, fragments in ``composite``)."""
    m = ray.shape[0]
    start = np.zeros(n_rays + 1, dtype=np.int64)
    for i in range(m):
        start[ray[i] + 1] += 1
    for r in range(n_rays):
        start[r + 1] += start[r]
    order = np.empty(m, dtype=np.int64)
    pos = start[:-1].copy()
    for i in range(m):
        order[pos[ray[i]]] = i
        pos[ray[i]] += 1
    return start, order


@njit(cache=True)
def sort_run(order, lo, hi, key, tie):
    """Insertion sort of ``order[lo:hi]`` by ``(key[i], tie[i])`` ascending, stable: for the few
    items one ray has (boundary crossings by (t, exits first), fragments by (front, back) depth)."""
    for i in range(lo + 1, hi):
        x = order[i]
        j = i - 1
        while j >= lo:
            y = order[j]
            if key[y] > key[x] or (key[y] == key[x] and tie[y] > tie[x]):
                order[j + 1] = y
                j -= 1
            else:
                break
        order[j + 1] = x


@njit(cache=True)
def _pair_hits(n_rays, hit_ray, hit_t, hit_face, hit_enter):
    """Sort each ray's boundary crossings by t and pair them into (entry, exit) segments."""
    m = hit_ray.shape[0]
    start, order = group_by_ray(hit_ray, n_rays)
    seg_ray = np.empty(m + 1, dtype=np.int64)
    seg_in = np.empty(m + 1, dtype=np.int64)
    seg_out = np.empty(m + 1, dtype=np.int64)
    nseg = 0
    anomalies = 0
    for r in range(n_rays):
        lo, hi = start[r], start[r + 1]
        sort_run(order, lo, hi, hit_t, hit_enter)  # by (t, exits first): rays cross few boundary faces
        # an entry a rounding error ahead of an exit at the same place (seams, touching parts)
        for i in range(lo, hi - 1):
            x, y = order[i], order[i + 1]
            if hit_enter[x] and not hit_enter[y] and hit_t[y] - hit_t[x] <= 1e-9 * (abs(hit_t[x]) + 1e-30):
                order[i], order[i + 1] = y, x
        # Pair each entry with the next exit. A mesh whose boundary overlaps itself (folded
        # curvilinear grids) can give two entries or two exits in a row: the odd one gets a
        # segment with one end only (-1), whose single subsegment walks until the boundary.
        open_ = -1
        for i in range(lo, hi + 1):
            x = order[i] if i < hi else -1
            if i < hi and not hit_enter[x]:  # an exit: closes the open entry, or stands alone
                seg_ray[nseg] = r
                seg_in[nseg] = open_
                seg_out[nseg] = x
                nseg += 1
                if open_ == -1:
                    anomalies += 1
                open_ = -1
            else:  # an entry, or the end of the ray: an entry still open gets a segment of its own
                if open_ != -1:
                    seg_ray[nseg] = r
                    seg_in[nseg] = open_
                    seg_out[nseg] = -1
                    nseg += 1
                    anomalies += 1
                open_ = x
    return seg_ray[:nseg], seg_in[:nseg], seg_out[:nseg], anomalies


@njit(cache=True)
def _init_segments(P, dens, dirs, faces, seg_ray_, hit_face, hit_in, hit_out, seg_ray, seg_face, seg_from,
                   seg_ts):
    """Each segment's two subsegments standing on their boundary faces (``SEG_FACE``, ``SEG_FROM``,
    ``SEG_TS``), not yet moved."""
    for s in range(seg_ray_.shape[0]):
        r = seg_ray_[s]
        seg_ray[s] = r
        dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        for sub in range(2):
            hit = hit_in[s] if sub == FRONT else hit_out[s]
            if hit < 0:  # no such end: a sentinel face that never matches or moves
                seg_face[s, sub, 0] = -1
                seg_face[s, sub, 1] = -1
                seg_face[s, sub, 2] = -1
                seg_from[s, sub] = -1
                seg_ts[s, sub, TS_T] = 0.0
                seg_ts[s, sub, TS_SCALAR] = 0.0
                continue
            f = hit_face[hit]
            a, b, c, par = _sort3(faces[f, 0], faces[f, 1], faces[f, 2])
            seg_face[s, sub, 0] = a
            seg_face[s, sub, 1] = b
            seg_face[s, sub, 2] = c
            seg_from[s, sub] = -1  # from outside the mesh
            t, sv = _face_values(P, dens, dx, dy, dz, a, b, c)
            seg_ts[s, sub, TS_T] = t
            seg_ts[s, sub, TS_SCALAR] = sv


def find_segments(P, dens, dirs, width, height, faces, fwd, right, up, xs, ys, tan_half):
    """All (ray, entry face, exit face) segments of the boundary ``faces`` (outward wound, every
    vertex in front of the eye), as the state of segments about to walk.

    ``fwd``, ``right``, ``up``: the camera basis; ``xs``, ``ys``: the pixel rays' offsets along
    ``right`` and ``up`` (``Camera.ray_offsets``; ``dirs`` are their normalised directions);
    ``tan_half``: tan of half the vertical view angle.

    Returns ``(S, odd_rays, anomalies, hits)``: the segments (:func:`make_segments`), the rays
    whose crossings did not pair up, how many crossings were left unpaired, and the number of
    boundary crossings.
    """
    nf = faces.shape[0]
    counts = np.zeros(nf, dtype=np.int64)
    dummy_i = np.zeros(0, dtype=np.int64)
    dummy_f = np.zeros(0, dtype=np.float64)
    dummy_b = np.zeros(0, dtype=np.bool_)
    _boundary_hits(P, dens, dirs, width, height, faces, fwd, right, up, xs, ys, tan_half, counts, counts, dummy_i,
                   dummy_f, dummy_i, dummy_b, False)
    offsets = np.zeros(nf + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    m = int(offsets[-1])
    hit_ray = np.empty(m, dtype=np.int64)
    hit_t = np.empty(m, dtype=np.float64)
    hit_face = np.empty(m, dtype=np.int64)
    hit_enter = np.empty(m, dtype=np.bool_)
    _boundary_hits(P, dens, dirs, width, height, faces, fwd, right, up, xs, ys, tan_half, counts, offsets, hit_ray,
                   hit_t, hit_face, hit_enter, True)
    seg_ray_, hit_in, hit_out, anomalies = _pair_hits(dirs.shape[0], hit_ray, hit_t, hit_face, hit_enter)
    nseg = seg_ray_.shape[0]
    seg_ray = np.empty(nseg, dtype=np.int32)
    seg_face = np.empty((nseg, 2, 3), dtype=np.int32)
    seg_from = np.empty((nseg, 2), dtype=np.int32)
    seg_ts = np.empty((nseg, 2, 2), dtype=np.float64)
    _init_segments(P, dens, dirs, faces, seg_ray_, hit_face, hit_in, hit_out, seg_ray, seg_face, seg_from, seg_ts)
    S, odd_rays = make_segments(seg_ray, seg_face, seg_from, seg_ts, dirs.shape[0])
    return S, odd_rays, int(anomalies), m
