"""Numba kernels of the object-space ray caster (private; validated callers in ``raycast.py``).

Geometry conventions
--------------------
All rays start at the camera position; points are stored relative to it (``P = points - eye``,
float64). For a ray with unit direction ``d`` and a directed edge i -> j, the Pluecker side is the
triple product ``d . (P_i x P_j)``. A triangle (i, j, k) is crossed by the ray iff the three sides
of (i, j), (j, k), (k, i) share a sign: all positive = the ray leaves through the face along its
winding normal, all negative = it enters. Each undirected edge is evaluated once in a canonical
order (lower id first), so the two tets sharing a face always agree; exact zeros are broken by a
symbolic perturbation of the ray direction (simulation of simplicity), which keeps the decisions
those of a real, slightly moved ray: it enters and leaves every tet it meets exactly once, also
through vertices, edges and zero-volume tets.

Where a ray crosses a face, its parameter ``t`` (distance from the eye) and the scalar are the
barycentric combination whose weights are the three edge sides; they depend only on the face's
sorted vertex ids, so a face gives bit-identical values from both sides and in every walking
direction. That is what makes the streaming render (front and back subsegments, any tet order)
equal to the in-memory one.

Face table
----------
Faces live in an open-addressing hash keyed by the sorted vertex triple (a < b < c), in ``htab[slot, 0..2]``.
``htab[slot, 3..4]`` describe the (up to) two tets on the face as ``2 * e + p``: ``e`` the tet's
fourth vertex, ``p`` = 0 if (a, b, c) is wound outward in it. That is all a ray needs to step
through the tet: it takes the tet whose fourth vertex is not the one of the tet it came from
(this also works across zero-volume tets, where "which side" is not well defined).
``htab[slot, 5]`` heads a linked list of subsegments parked on the face.

Freeing faces (streaming)
-------------------------
A lean streaming renderer keeps a seventh column, ``htab[slot, 6]``: the number of tet steps rays
still have to take next to the face. When a tet arrives, each of its faces gains the number of
pixel rays crossing that face (:func:`count_crossings`, the same edge-side signs the walk uses,
so the count is exact); a ray stepping through a tet takes one off its entry and one off its exit
face. A face at zero with nobody parked on it will never be looked up again and is dropped when
the table is next rebuilt (:func:`rehash` with ``purge``), so the table holds the tets in flight,
not the whole mesh. Crossings the walk could only resolve by its rounding fallback are neither
counted nor taken off (they keep a face alive, never free it early).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..mesh.model import TET_FACES

MODE_VOLUME = 0
MODE_FACE = 1

NEVER_COUNTS = 2  # seg_clean: this segment's walk does not touch the face counters
FOLD_END = -2  # seg_from: the subsegment left the mesh through a fold face (see _walk) and is over

STATE_ACTIVE = 0
STATE_DONE = 1
STATE_STUCK = 2
# A ray this opaque is finished (the and VTK's early-termination threshold): segments
# behind it can change its colour by at most 1 - OPAQUE.
OPAQUE = 0.99


@intrinsic
def _atomic_sub_i32(typingctx, arr, i, j, v):
    """``arr[i, j] -= v`` as one atomic instruction (2-D int32 array); the parallel walks share
    the face table's counters. Numba has no CPU atomics, so this emits LLVM's ``atomicrmw``."""
    if not (isinstance(arr, types.Array) and arr.ndim == 2 and arr.dtype == types.int32):
        return None
    sig = types.int32(arr, i, j, v)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ii = context.cast(builder, args[1], signature.args[1], types.intp)
        jj = context.cast(builder, args[2], signature.args[2], types.intp)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [ii, jj], wraparound=False)
        val = context.cast(builder, args[3], signature.args[3], types.int32)
        return builder.atomic_rmw("sub", ptr, val, "monotonic")

    return sig, codegen


# ---------------------------------------------------------------------------------------------
# geometry helpers
@njit(cache=True, inline="always")
def _edge_cross(P, i, j):
    """The ray-independent part of the side of i -> j: P_lo x P_hi and the sign of the order."""
    if i < j:
        lo, hi, flip = i, j, 1.0
    else:
        lo, hi, flip = j, i, -1.0
    ax, ay, az = P[lo, 0], P[lo, 1], P[lo, 2]
    bx, by, bz = P[hi, 0], P[hi, 1], P[hi, 2]
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx, flip


@njit(cache=True, inline="always")
def _side_cross(cx, cy, cz, flip, dx, dy, dz):
    """:func:`_side` from the edge's :func:`_edge_cross`."""
    v = dx * cx + dy * cy + dz * cz
    if v > 0.0:
        s = 1.0
    elif v < 0.0:
        s = -1.0
    # symbolic perturbation d + (e, e^2, e^3): the first non-zero cross component decides
    elif cx != 0.0:
        s = 1.0 if cx > 0.0 else -1.0
    elif cy != 0.0:
        s = 1.0 if cy > 0.0 else -1.0
    elif cz != 0.0:
        s = 1.0 if cz > 0.0 else -1.0
    else:  # edge collinear with the eye or of zero length: ids decide
        s = 1.0
    return v * flip, s * flip


@njit(cache=True, inline="always")
def _side(P, dx, dy, dz, i, j):
    """Pluecker side of the directed edge i -> j: (value, sign), sign never 0."""
    cx, cy, cz, flip = _edge_cross(P, i, j)
    return _side_cross(cx, cy, cz, flip, dx, dy, dz)


@njit(cache=True, inline="always")
def _sort3(a, b, c):
    """Sorted triple and the parity (0 even, 1 odd) of the sorting permutation."""
    par = 0
    if a > b:
        a, b = b, a
        par ^= 1
    if b > c:
        b, c = c, b
        par ^= 1
    if a > b:
        a, b = b, a
        par ^= 1
    return a, b, c, par


@njit(cache=True)
def _face_values(P, dens, dx, dy, dz, a, b, c):
    """Ray parameter t and scalar where the ray crosses the face with sorted ids a < b < c.

    The barycentric weights of the crossing are the three edge sides. Rounding can give them
    mixed signs near an edge; the wrong-signed ones are dropped so the point stays on the face.
    When all vanish the ray lies in the face's plane (e.g. along one of its edges): the crossing
    of the slightly moved ray is somewhere on the chord of the ray inside the triangle, and its
    midpoint is taken.
    """
    wa, _ = _side(P, dx, dy, dz, b, c)
    wb, _ = _side(P, dx, dy, dz, c, a)
    wc, _ = _side(P, dx, dy, dz, a, b)
    return _face_values_w(P, dens, dx, dy, dz, a, b, c, wa, wb, wc)


@njit(cache=True, inline="always")
def _face_values_w(P, dens, dx, dy, dz, a, b, c, wa, wb, wc):
    """:func:`_face_values` with the sides of (b, c), (c, a), (a, b) already known (up to a
    common sign)."""
    t, sv, ok = _barycentric(_depth(P, a, dx, dy, dz), _depth(P, b, dx, dy, dz), _depth(P, c, dx, dy, dz),
                             dens[a], dens[b], dens[c], wa, wb, wc)
    if ok:
        return t, sv
    return _chord_midpoint(P, dens, dx, dy, dz, a, b, c)


@njit(cache=True, inline="always")
def _depth(P, v, dx, dy, dz):
    """P_v . d: the ray parameter of vertex v's foot on the ray."""
    return P[v, 0] * dx + P[v, 1] * dy + P[v, 2] * dz


@njit(cache=True, inline="always")
def _barycentric(ta, tb, tc, da, db, dc, wa, wb, wc):
    """(t, scalar, ok) of the face point with (unnormalised) weights wa, wb, wc, from the vertices'
    depths t and scalars d; ok False when no weight is left (the ray lies in the face's plane:
    :func:`_chord_midpoint`). Scalars only, no arrays: the walk's hot loop calls it, and arrays
    passed to an inlined function that calls out cost reference-count updates on every step."""
    w = wa + wb + wc
    if w < 0.0:
        wa, wb, wc = -wa, -wb, -wc
    wa = max(wa, 0.0)
    wb = max(wb, 0.0)
    wc = max(wc, 0.0)
    w = wa + wb + wc
    if w > 0.0 and math.isfinite(w):
        wa /= w
        wb /= w
        wc /= w
        return wa * ta + wb * tb + wc * tc, wa * da + wb * db + wc * dc, True
    return 0.0, 0.0, False


@njit(cache=True)
def _chord_midpoint(P, dens, dx, dy, dz, a, b, c):
    """Midpoint (t, scalar) of the part of the ray inside triangle (a, b, c), ray in its plane."""
    tmin = np.inf
    tmax = -np.inf
    smin = 0.0
    smax = 0.0
    for q in range(3):
        if q == 0:
            i, j = a, b
        elif q == 1:
            i, j = b, c
        else:
            i, j = c, a
        ex, ey, ez = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
        cx = dy * ez - dz * ey
        cy = dz * ex - dx * ez
        cz = dx * ey - dy * ex
        n2 = cx * cx + cy * cy + cz * cz
        e2 = ex * ex + ey * ey + ez * ez
        for end in range(2):
            if n2 > 0.0:  # where the ray meets the edge's line
                if end == 1:
                    break
                px = P[i, 1] * ez - P[i, 2] * ey
                py = P[i, 2] * ex - P[i, 0] * ez
                pz = P[i, 0] * ey - P[i, 1] * ex
                t = (px * cx + py * cy + pz * cz) / n2
                u = ((t * dx - P[i, 0]) * ex + (t * dy - P[i, 1]) * ey + (t * dz - P[i, 2]) * ez) / e2
                if not (-1e-9 <= u <= 1.0 + 1e-9):
                    continue
                u = min(max(u, 0.0), 1.0)
                sv = dens[i] + u * (dens[j] - dens[i])
            else:  # edge parallel to the ray (or a point): its ends
                k = i if end == 0 else j
                t = P[k, 0] * dx + P[k, 1] * dy + P[k, 2] * dz
                sv = dens[k]
            if t < tmin:
                tmin, smin = t, sv
            if t > tmax:
                tmax, smax = t, sv
    if tmin > tmax:  # numerically nowhere: the centroid's depth
        ta = P[a, 0] * dx + P[a, 1] * dy + P[a, 2] * dz
        tb = P[b, 0] * dx + P[b, 1] * dy + P[b, 2] * dz
        tc = P[c, 0] * dx + P[c, 1] * dy + P[c, 2] * dz
        return (ta + tb + tc) / 3.0, (dens[a] + dens[b] + dens[c]) / 3.0
    return 0.5 * (tmin + tmax), 0.5 * (smin + smax)


# ---------------------------------------------------------------------------------------------
# face hash
@njit(cache=True, inline="always")
def _hash0(a, b, c, mul, mask):
    # Faces are grouped by their smallest vertex id: meshes number neighbouring vertices close
    # together, so the faces a ray meets in a row sit in nearby slots (far fewer cache misses
    # than a scattering hash). ``mul`` = slots per vertex id in 16-bit fixed point, so the ids
    # spread over the whole table whatever the ratio of slots to vertices; the other two ids
    # pick a slot inside the id's stretch.
    # ``mul`` = 0: a table of the faces in flight (streaming, counting), whose ids cluster in the
    # recently decoded range: grouping would pile them into one stretch, so scatter them (the
    # table is small enough to stay in cache anyway).
    mix = (np.int64(b) * 73856093) ^ (np.int64(c) * 19349663)
    if mul == 0:
        x = (mix ^ (np.int64(a) * 83492791)) * np.int64(-7046029254386353131)  # 0x9E3779B97F4A7C15
        return (x >> 29) & mask
    return (((np.int64(a) * mul) >> 16) + (((mix & 0xFFFF) * mul) >> 32)) & mask


@njit(cache=True)
def _hash_find(htab, mul, a, b, c):
    mask = htab.shape[0] - 1
    h = _hash0(a, b, c, mul, mask)
    while True:
        k0 = htab[h, 0]
        if k0 == -1:
            return -1
        if k0 == a and htab[h, 1] == b and htab[h, 2] == c:
            return h
        h = (h + 1) & mask


@njit(cache=True)
def _hash_insert(htab, mul, hcount, a, b, c):
    mask = htab.shape[0] - 1
    h = _hash0(a, b, c, mul, mask)
    while True:
        k0 = htab[h, 0]
        if k0 == -1:
            htab[h, 0] = a
            htab[h, 1] = b
            htab[h, 2] = c
            htab[h, 3] = -1
            htab[h, 4] = -1
            htab[h, 5] = -1
            if htab.shape[1] > 6:
                htab[h, 6] = 0
            hcount[0] += 1
            return h
        if k0 == a and htab[h, 1] == b and htab[h, 2] == c:
            return h
        h = (h + 1) & mask


@njit(cache=True)
def _live(htab, h, purge, fold_mark):
    """Whether slot ``h`` holds a face worth keeping (with ``purge``: still needed, or next to a
    fold, see :func:`count_crossings`)."""
    if htab[h, 0] == -1:
        return False
    if not purge or htab.shape[1] <= 6:
        return True
    if htab[h, 6] > 0 or htab[h, 5] != -1:
        return True
    return fold_mark[htab[h, 0]] != 0 or fold_mark[htab[h, 1]] != 0 or fold_mark[htab[h, 2]] != 0


@njit(cache=True)
def count_live(htab, purge, fold_mark):
    """The faces :func:`rehash` would keep."""
    n = 0
    for h in range(htab.shape[0]):
        if _live(htab, h, purge, fold_mark):
            n += 1
    return n


@njit(cache=True)
def rehash(htab, new_cap, new_mul, purge, fold_mark):
    """Copy the face table into one of ``new_cap`` (a power of two) slots; with ``purge``, drop
    the faces no ray will look up again (count zero, nobody parked, no vertex by a fold).
    Returns (table, faces)."""
    ntab = np.full((new_cap, htab.shape[1]), -1, dtype=np.int32)
    cnt = np.zeros(1, dtype=np.int64)
    for h in range(htab.shape[0]):
        if _live(htab, h, purge, fold_mark):
            g = _hash_insert(ntab, new_mul, cnt, htab[h, 0], htab[h, 1], htab[h, 2])
            for col in range(3, htab.shape[1]):
                ntab[g, col] = htab[h, col]
    return ntab, cnt[0]


@njit(cache=True)
def insert_tets(tets, crossings, fold_mark, htab, mul, hcount, nodes, park_ver, in_list, seg_mark, mark, active):
    """Enter a batch of tets into the face table; collect the segments parked on their faces.

    ``crossings`` (n, 4): rays crossing each tet's faces (:func:`count_crossings`), added to the
    faces' counters; an empty array when the table does not count (in-memory rendering). A face
    whose two tets lie on the same side of it (a grid folded over itself) marks its five vertices
    in ``fold_mark``.

    ``nodes`` (k, 3) = (item, version, next) is the pool of park-list nodes; a node is live
    while its version is the item's current one (an item that moves on is simply re-parked with a
    new version, its old node goes stale). Returns (number of segments written to ``active``,
    number of face conflicts).
    """
    n_active = 0
    conflicts = 0
    for t in range(tets.shape[0]):
        for k in range(4):
            a, b, c, par = _sort3(tets[t, TET_FACES[k, 0]], tets[t, TET_FACES[k, 1]], tets[t, TET_FACES[k, 2]])
            slot = _hash_insert(htab, mul, hcount, a, b, c)
            code = 2 * tets[t, k] + par  # fourth vertex, and whether (a, b, c) is wound outward in it
            if htab[slot, 3] == -1:
                htab[slot, 3] = code
            elif htab[slot, 4] == -1:
                htab[slot, 4] = code
                if crossings.shape[0] > 0 and (htab[slot, 3] & 1) == par:  # both wind it outward
                    fold_mark[a] = 1
                    fold_mark[b] = 1
                    fold_mark[c] = 1
                    fold_mark[htab[slot, 3] >> 1] = 1
                    fold_mark[tets[t, k]] = 1
            else:
                conflicts += 1  # a third tet on one face: not a conforming mesh
            if crossings.shape[0] > 0:
                htab[slot, 6] += crossings[t, k]
            node = htab[slot, 5]
            while node != -1:
                item = nodes[node, 0]
                if nodes[node, 1] == park_ver[item] and in_list[item]:
                    in_list[item] = 0
                    s = item >> 1
                    if seg_mark[s] != mark:
                        seg_mark[s] = mark
                        active[n_active] = s
                        n_active += 1
                node = nodes[node, 2]
            htab[slot, 5] = -1
    return n_active, conflicts


@njit(cache=True, inline="always")
def _pixel_span(u0, u1, u2, u3, n):
    """Pixels k (centres at k + 0.5) within [min u, max u], a thousandth of a pixel to spare:
    the span must hold every pixel whose ray can cross the tet, or a face would be freed early."""
    lo = min(min(u0, u1), min(u2, u3)) - 0.5 - 1e-3
    hi = max(max(u0, u1), max(u2, u3)) - 0.5 + 1e-3
    if not (lo < n and hi >= 0.0):  # also NaN
        return 0, 0
    return max(int(math.ceil(lo)), 0), min(int(math.floor(hi)), n - 1) + 1


@njit(cache=True, inline="always")
def _project(P, v, fwd, right, up, tan_half, aspect, width, height):
    """Depth and continuous pixel (column, row from the top) of vertex v, as Camera.project."""
    z = P[v, 0] * fwd[0] + P[v, 1] * fwd[1] + P[v, 2] * fwd[2]
    x = (P[v, 0] * right[0] + P[v, 1] * right[1] + P[v, 2] * right[2]) / (z * tan_half * aspect)
    y = (P[v, 0] * up[0] + P[v, 1] * up[1] + P[v, 2] * up[2]) / (z * tan_half)
    return z, (x + 1.0) * (width / 2.0), (1.0 - y) * (height / 2.0)


NEAR = 1e-12  # relative rounding bound of an edge side (float64 error is ~1e-16 of |P_lo| |P_hi|)


@njit(cache=True, inline="always")
def _edge_terms(P, i, j, fwd, right, up):
    """The directed edge i -> j's side as fwd . c + x right . c + y up . c, c its canonical cross."""
    cx, cy, cz, flip = _edge_cross(P, i, j)
    return ((fwd[0] * cx + fwd[1] * cy + fwd[2] * cz) * flip, (right[0] * cx + right[1] * cy + right[2] * cz) * flip,
            (up[0] * cx + up[1] * cy + up[2] * cz) * flip)


@njit(cache=True, inline="always")
def _norm(P, v):
    return math.sqrt(P[v, 0] * P[v, 0] + P[v, 1] * P[v, 1] + P[v, 2] * P[v, 2])


@njit(cache=True, inline="always")
def _flat(P, a, b, c, d):
    """Whether tet (a, b, c, d) has (nearly) zero volume: |6 V| <= 1e-9 of its longest edge cubed."""
    ux, uy, uz = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
    vx, vy, vz = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
    wx, wy, wz = P[d, 0] - P[a, 0], P[d, 1] - P[a, 1], P[d, 2] - P[a, 2]
    vol6 = ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz) + uz * (vx * wy - vy * wx)
    e = max(ux * ux + uy * uy + uz * uz, max(vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz))
    return abs(vol6) <= 1e-9 * e * math.sqrt(e)


@njit(cache=True, inline="always")
def _near_crossing(x0, t0, x1, t1, x2, t2):
    """1 if the ray crosses the face with directed edge sides x0, x1, x2, or misses it by no more
    than rounding (each side within its bound t of agreeing with the others), else 0."""
    if x0 >= -t0 and x1 >= -t1 and x2 >= -t2:
        return 1
    if x0 <= t0 and x1 <= t1 and x2 <= t2:
        return 1
    return 0


ODD_MARGIN = 3.0  # pixels around a ray with unpaired boundary crossings whose tets are all kept


@njit(cache=True, inline="always")
def _near_odd_ray(c0, c1, c2, c3, r0, r1, r2, r3, width, height, odd_pixels):
    """Whether a pixel of ``odd_pixels`` lies within ODD_MARGIN of the tet's pixel box."""
    lo_c = max(int(math.floor(min(min(c0, c1), min(c2, c3)) - ODD_MARGIN)), 0)
    hi_c = min(int(math.ceil(max(max(c0, c1), max(c2, c3)) + ODD_MARGIN)), width)
    lo_r = max(int(math.floor(min(min(r0, r1), min(r2, r3)) - ODD_MARGIN)), 0)
    hi_r = min(int(math.ceil(max(max(r0, r1), max(r2, r3)) + ODD_MARGIN)), height)
    for row in range(lo_r, hi_r):
        for col in range(lo_c, hi_c):
            if odd_pixels[row * width + col]:
                return True
    return False


@njit(cache=True, parallel=True)
def count_crossings(tets, P, xs, ys, width, height, fwd, right, up, tan_half, odd_pixels, fold_mark, out):
    """``out[t, k]`` = pixel rays that may cross face k of tet t: an upper bound on the walk's uses.

    ``xs``, ``ys``: the pixel rays' offsets along ``right`` and ``up`` (``Camera.ray_offsets``).
    A ray crosses face (i, j, k) cleanly when the signs of its three directed edge sides agree,
    the same :func:`_side_cross` values of the same canonical edges as in :func:`_walk` and
    :func:`_boundary_hits`; the walk takes one off for each such crossing. Rays that miss the face
    by no more than rounding are counted too: where rounding leaves a tet without a clean exit,
    the walk's fallback goes through such a face, never takes it off, and so the face is kept
    (a few faces along rays grazing edges; never one freed early). Each tet is one task writing
    its own row: the result cannot depend on the thread count.
    """
    aspect = width / height
    for t in prange(tets.shape[0]):
        v0, v1, v2, v3 = tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3]
        for k in range(4):
            out[t, k] = 0
        z0, c0, r0 = _project(P, v0, fwd, right, up, tan_half, aspect, width, height)
        z1, c1, r1 = _project(P, v1, fwd, right, up, tan_half, aspect, width, height)
        z2, c2, r2 = _project(P, v2, fwd, right, up, tan_half, aspect, width, height)
        z3, c3, r3 = _project(P, v3, fwd, right, up, tan_half, aspect, width, height)
        if _flat(P, v0, v1, v2, v3):
            # a (nearly) zero-volume tet: the walk passes it through whichever faces its
            # fallback picks, not the ones the ray crosses; one extra on each face keeps them,
            # and its vertices keep every face around them (a walk that left the ray's path here
            # can wander a few tets off it). Threads may mark the same vertex: all write 1.
            for k in range(4):
                out[t, k] = 1
                fold_mark[tets[t, k]] = 1
        if not (z0 > 0.0 and z1 > 0.0 and z2 > 0.0 and z3 > 0.0):
            continue  # behind the eye: rays cannot be cast at it
        if odd_pixels.shape[0] > 0 and _near_odd_ray(c0, c1, c2, c3, r0, r1, r2, r3, width, height, odd_pixels):
            # rays whose boundary crossings did not pair up walk a grid folded over itself, off
            # the path the counts foresee: keep everything around them
            for k in range(4):
                out[t, k] += 1
                fold_mark[tets[t, k]] = 1
        col0, col1 = _pixel_span(c0, c1, c2, c3, width)
        row0, row1 = _pixel_span(r0, r1, r2, r3, height)
        if col0 >= col1 or row0 >= row1:
            continue
        # An edge's side for the pixel ray d = fwd + xs[col] right + ys[row] up (unnormalised,
        # |d| <= 1.1) is linear in xs and ys: 6 multiply-adds per pixel.
        f01, r01, u01 = _edge_terms(P, v0, v1, fwd, right, up)
        f02, r02, u02 = _edge_terms(P, v0, v2, fwd, right, up)
        f03, r03, u03 = _edge_terms(P, v0, v3, fwd, right, up)
        f12, r12, u12 = _edge_terms(P, v1, v2, fwd, right, up)
        f13, r13, u13 = _edge_terms(P, v1, v3, fwd, right, up)
        f23, r23, u23 = _edge_terms(P, v2, v3, fwd, right, up)
        # rounding bound on a side value: far above the error of d . (P_lo x P_hi)
        m0, m1, m2, m3 = _norm(P, v0), _norm(P, v1), _norm(P, v2), _norm(P, v3)
        t01, t02, t03 = NEAR * m0 * m1, NEAR * m0 * m2, NEAR * m0 * m3
        t12, t13, t23 = NEAR * m1 * m2, NEAR * m1 * m3, NEAR * m2 * m3
        n0 = n1 = n2 = n3 = 0
        for row in range(row0, row1):
            y = ys[row]
            b01, b02, b03 = f01 + y * u01, f02 + y * u02, f03 + y * u03
            b12, b13, b23 = f12 + y * u12, f13 + y * u13, f23 + y * u23
            for col in range(col0, col1):
                x = xs[col]
                x01 = b01 + x * r01
                x02 = b02 + x * r02
                x03 = b03 + x * r03
                x12 = b12 + x * r12
                x13 = b13 + x * r13
                x23 = b23 + x * r23
                # outward faces (TET_FACES): (1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)
                n0 += _near_crossing(x12, t12, x23, t23, -x13, t13)
                n1 += _near_crossing(x03, t03, -x23, t23, -x02, t02)
                n2 += _near_crossing(x01, t01, x13, t13, -x03, t03)
                n3 += _near_crossing(x02, t02, -x12, t12, -x01, t01)
        out[t, 0] += n0
        out[t, 1] += n1
        out[t, 2] += n2
        out[t, 3] += n3


@njit(cache=True)
def park(active, n_active, seg_face, seg_state, htab, mul, hcount, nodes, n_nodes, park_ver, in_list,
         park_face):
    """Hang the unfinished subsegments of ``active`` on the faces where they stopped.

    A subsegment still live on the face it waits on is left alone. Returns the new node count.
    """
    for i in range(n_active):
        s = active[i]
        if seg_state[s] != STATE_ACTIVE:
            continue
        for sub in range(2):
            item = 2 * s + sub
            a, b, c = seg_face[s, sub, 0], seg_face[s, sub, 1], seg_face[s, sub, 2]
            if a < 0:
                continue
            if in_list[item] and park_face[item, 0] == a and park_face[item, 1] == b and park_face[item, 2] == c:
                continue
            slot = _hash_insert(htab, mul, hcount, a, b, c)
            park_ver[item] += 1
            in_list[item] = 1
            park_face[item, 0] = a
            park_face[item, 1] = b
            park_face[item, 2] = c
            nodes[n_nodes, 0] = item
            nodes[n_nodes, 1] = park_ver[item]
            nodes[n_nodes, 2] = htab[slot, 5]
            htab[slot, 5] = n_nodes
            n_nodes += 1
    return n_nodes


# ---------------------------------------------------------------------------------------------
# sampling and compositing
@njit(cache=True, inline="always")
def _lookup(tab, lo, inv, s):
    """(r, g, b, a) of the table at scalar ``s`` (a tuple: no buffer to allocate in the walk)."""
    n = tab.shape[0]
    x = (s - lo) * inv
    if not x > 0.0:  # also NaN
        x = 0.0
    if x > n - 1:
        x = float(n - 1)
    i = int(x)
    if i >= n - 1:
        i = n - 2
    f = x - i
    return (tab[i, 0] * (1.0 - f) + tab[i + 1, 0] * f, tab[i, 1] * (1.0 - f) + tab[i + 1, 1] * f,
            tab[i, 2] * (1.0 - f) + tab[i + 1, 2] * f, tab[i, 3] * (1.0 - f) + tab[i + 1, 3] * f)


@njit(cache=True)
def _first_sample(t0, step):
    k = math.ceil(t0 / step)
    if (k - 1) * step >= t0:
        k -= 1
    if k * step < t0:
        k += 1
    return k


@njit(cache=True, inline="always")
def _composite(a0, a1, a2, a3, t0, s0, t1, s1, k0, k1, forward, mode, step, tab, lo, inv, unit):
    """Composite the tet interval [t0, t1) (scalar s0 -> s1) into the running colour (a0, a1, a2, a3);
    return (samples taken, new colour). The colour stays in registers for the whole walk.

    forward: the colour is a front subsegment's (new samples go behind it); otherwise a back
    subsegment's, walking toward the eye (new samples go in front of it). Volume mode: ``k0``,
    ``k1`` are ``_first_sample(t0)``, ``_first_sample(t1)`` (the walk computes each face's once).
    """
    if not t1 > t0:
        return 0, a0, a1, a2, a3
    if mode == MODE_VOLUME:
        if k1 <= k0:
            return 0, a0, a1, a2, a3
        scale = (s1 - s0) / (t1 - t0)
        for q in range(k1 - k0):
            k = k0 + q if forward else k1 - 1 - q
            c0, c1, c2, al = _lookup(tab, lo, inv, s0 + (k * step - t0) * scale)
            a0, a1, a2, a3 = _blend(a0, a1, a2, a3, c0, c1, c2, al, forward)
        return k1 - k0, a0, a1, a2, a3
    # face mode: the interval takes the average of the samples at its two faces
    p0, p1, p2, p3 = _lookup(tab, lo, inv, s0)
    q0, q1, q2, q3 = _lookup(tab, lo, inv, s1)
    a = 0.5 * (p3 + q3)
    if a >= 1.0:
        al = 1.0
    else:
        al = 1.0 - math.exp((t1 - t0) / unit * math.log1p(-a))
    a0, a1, a2, a3 = _blend(a0, a1, a2, a3, 0.5 * (p0 + q0), 0.5 * (p1 + q1), 0.5 * (p2 + q2), al, forward)
    return 1, a0, a1, a2, a3


@njit(cache=True, inline="always")
def _blend(a0, a1, a2, a3, c0, c1, c2, al, forward):
    """The running colour with a sample (colour c, opacity al) added behind it (``forward``: a
    front subsegment) or in front of it (a back subsegment walking toward the eye)."""
    if forward:
        w = (1.0 - a3) * al
        return a0 + w * c0, a1 + w * c1, a2 + w * c2, a3 + w
    r = 1.0 - al
    return al * c0 + r * a0, al * c1 + r * a1, al * c2 + r * a2, al + r * a3


@njit(cache=True, inline="always")
def _first_sample_at(t, step, mode):
    """``_first_sample(t)`` in volume mode for a finite ``t``; 0 where it is not needed."""
    if mode == MODE_VOLUME and math.isfinite(t):
        return _first_sample(t, step)
    return 0


# ---------------------------------------------------------------------------------------------
# walking
@njit(cache=True, inline="always")
def _sort3w(a, b, c, wa, wb, wc):
    """Sort three ids, carrying a weight with each."""
    if a > b:
        a, b, wa, wb = b, a, wb, wa
    if b > c:
        b, c, wb, wc = c, b, wc, wb
    if a > b:
        a, b, wa, wb = b, a, wb, wa
    return a, b, c, wa, wb, wc


@njit(cache=True, inline="always")
def _canon(i, j, x, g):
    """An edge side known for the directed edge i -> j, as (lo, hi, value, sign) of lo -> hi.

    ``_side`` evaluates every edge lo -> hi and negates for hi -> lo, so negating back gives the
    canonical value bit for bit."""
    if i < j:
        return i, j, x, g
    return j, i, -x, -g


@njit(cache=True, inline="always")
def _by_edge(na, nb, e, vab, sab, vbc, sbc, vac, sac):
    """File the canonical edge side ``e`` under its edge of the face (na, nb, nc)."""
    if e[0] == na:
        if e[1] == nb:
            return e[2], e[3], vbc, sbc, vac, sac
        return vab, sab, vbc, sbc, e[2], e[3]
    return vab, sab, e[2], e[3], vac, sac


@njit(cache=True)
def _walk(s, sub, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state, seg_steps,
          seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps):
    """Advance subsegment ``sub`` (0 front, 1 back) of segment ``s`` through every present tet.

    Stops when the next tet is missing (the subsegment stays parked on that face), when it
    reaches the other subsegment's face (segment done), or after ``max_steps`` steps in total
    for the segment (stuck: it can only be looping on inconsistent geometry).

    A counting table (7 columns) loses one from the entry and the exit face of every tet stepped
    through, where the crossing was a clean one (``seg_clean`` 1: all three edge sides agreed;
    ``NEVER_COUNTS`` for the segments of rays whose boundary crossings did not pair up: on a grid
    that overlaps itself such a ray can walk the same tets in two segments).
    """
    if seg_from[s, sub] == FOLD_END:
        return
    counting = htab.shape[1] > 6 and seg_clean[s, sub] != NEVER_COUNTS
    clean = seg_clean[s, sub] == 1
    r = seg_ray[s]
    dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
    forward = sub == 0
    want = 1.0 if forward else -1.0
    a, b, c = seg_face[s, sub, 0], seg_face[s, sub, 1], seg_face[s, sub, 2]
    oa, ob, oc = seg_face[s, 1 - sub, 0], seg_face[s, 1 - sub, 1], seg_face[s, 1 - sub, 2]
    came_from = seg_from[s, sub]
    t_here, s_here = seg_ts[s, sub, 0], seg_ts[s, sub, 1]
    acc = seg_acc[s, sub]
    a0, a1, a2, a3 = acc[0], acc[1], acc[2], acc[3]  # the running colour, in registers
    samples = 0
    steps = seg_steps[s]
    state = STATE_ACTIVE
    # Brent's cycle detection: on a mesh that folds over itself a walk can come back to a face it
    # crossed in the same direction; stop there instead of burning ``max_steps``.
    ma, mb, mc, mfrom = a, b, c, came_from
    power = 1
    lam = 0
    have_face_sides = False
    k_here = _first_sample_at(t_here, step, mode)
    vab = sab = vbc = sbc = vac = sac = 0.0
    slot = _hash_find(htab, mul, a, b, c)
    while True:
        if slot < 0:
            break
        code = -1
        h0 = htab[slot, 3]
        h1 = htab[slot, 4]
        if h0 >= 0 and (h0 >> 1) != came_from:
            code = h0
        elif h1 >= 0 and (h1 >> 1) != came_from:
            code = h1
        if code < 0:
            break
        if steps >= max_steps:
            state = STATE_STUCK
            break
        # the tet behind the face, positively oriented as (v0, v1, v2, v3) with the face opposite v3
        v3 = code >> 1
        if (code & 1) == 0:
            v0, v1, v2 = a, c, b
        else:
            v0, v1, v2 = a, b, c
        # the six edge sides; face 0 = (v1, v2, v3), 1 = (v0, v3, v2), 2 = (v0, v1, v3).
        # The entry face's three were computed at the previous step (as its exit face).
        if have_face_sides:
            if (code & 1) == 0:  # (v0, v1, v2) = (a, c, b)
                x12, g12 = -vbc, -sbc
                x20, g20 = -vab, -sab
                x01, g01 = vac, sac
            else:  # (a, b, c)
                x12, g12 = vbc, sbc
                x20, g20 = -vac, -sac
                x01, g01 = vab, sab
        else:
            x12, g12 = _side(P, dx, dy, dz, v1, v2)
            x20, g20 = _side(P, dx, dy, dz, v2, v0)
            x01, g01 = _side(P, dx, dy, dz, v0, v1)
        if g01 * want < 0 and g12 * want < 0 and g20 * want < 0 and not _flat(P, v0, v1, v2, v3):
            # The tet lies on the side of the face the ray comes from: the grid folds over itself
            # here, and the ray leaves this sheet of the mesh as if through its boundary (walking
            # on would enter the tet backwards and can circle an edge for ever). A flat tet has no
            # side: the walk passes it as usual.
            came_from = FOLD_END
            if oa < 0 or seg_from[s, 1 - sub] == FOLD_END:
                state = STATE_DONE
            break
        steps += 1
        if counting and clean:
            _atomic_sub_i32(htab, slot, 6, 1)
        x03, g03 = _side(P, dx, dy, dz, v0, v3)
        x13, g13 = _side(P, dx, dy, dz, v1, v3)
        x23, g23 = _side(P, dx, dy, dz, v2, v3)
        best_k = -1
        best_score = -1
        best_min = -np.inf
        reversed_k = -1  # the first face whose three sides all oppose ``want`` (see below)
        clean = False
        for k in range(3):
            if k == 0:
                e0, e1, e2, q0, q1, q2 = x12, x23, -x13, g12, g23, -g13
            elif k == 1:
                e0, e1, e2, q0, q1, q2 = x03, -x23, x20, g03, -g23, g20
            else:
                e0, e1, e2, q0, q1, q2 = x01, x13, -x03, g01, g13, -g03
            score = (q0 * want > 0) + (q1 * want > 0) + (q2 * want > 0)
            if score == 3:
                best_k = k
                clean = True
                break
            if score == 0 and reversed_k < 0:
                reversed_k = k
            # inconsistent rounding can leave no clean exit: take the closest one
            m = min(e0 * want, e1 * want, e2 * want)
            if score > best_score or (score == best_score and m > best_min):
                best_score = score
                best_min = m
                best_k = k
        if not clean and reversed_k >= 0 and _flat(P, v0, v1, v2, v3):
            # A flat tet has no inside: its four faces lie in one plane and the ray crosses that
            # plane in one point, inside the entry face and one other face, whose three sides then
            # agree with each other but, that face's winding being reversed, against ``want``.
            # Leave through that one: any other choice leaves the ray's path (Blunt-fin's
            # collapsed grid line, 512²: walks that wandered off and looped).
            best_k = reversed_k
        # exit face (f0, f1, f2) outward, barycentric weight of f_i = side of the opposite edge
        if best_k == 0:
            na, nb, nc, wa, wb, wc = _sort3w(v1, v2, v3, x23, -x13, x12)
            came_from = v0
            e0 = _canon(v1, v2, x12, g12)
            e1 = _canon(v2, v3, x23, g23)
            e2 = _canon(v1, v3, x13, g13)
        elif best_k == 1:
            na, nb, nc, wa, wb, wc = _sort3w(v0, v3, v2, -x23, x20, x03)
            came_from = v1
            e0 = _canon(v0, v3, x03, g03)
            e1 = _canon(v2, v3, x23, g23)
            e2 = _canon(v2, v0, x20, g20)
        else:
            na, nb, nc, wa, wb, wc = _sort3w(v0, v1, v3, x13, -x03, x01)
            came_from = v2
            e0 = _canon(v0, v1, x01, g01)
            e1 = _canon(v1, v3, x13, g13)
            e2 = _canon(v0, v3, x03, g03)
        # keep the exit face's sides for the next step, by edge (na, nb), (nb, nc), (na, nc)
        have_face_sides = na < nb and nb < nc
        vab, sab, vbc, sbc, vac, sac = _by_edge(na, nb, e0, vab, sab, vbc, sbc, vac, sac)
        vab, sab, vbc, sbc, vac, sac = _by_edge(na, nb, e1, vab, sab, vbc, sbc, vac, sac)
        vab, sab, vbc, sbc, vac, sac = _by_edge(na, nb, e2, vab, sab, vbc, sbc, vac, sac)
        slot = _hash_find(htab, mul, na, nb, nc)
        if counting and clean and slot >= 0:
            _atomic_sub_i32(htab, slot, 6, 1)
        t_next, s_next, ok = _barycentric(_depth(P, na, dx, dy, dz), _depth(P, nb, dx, dy, dz),
                                          _depth(P, nc, dx, dy, dz), dens[na], dens[nb], dens[nc], wa, wb, wc)
        if not ok:  # the ray lies in the exit face's plane
            t_next, s_next = _chord_midpoint(P, dens, dx, dy, dz, na, nb, nc)
        k_next = _first_sample_at(t_next, step, mode)
        # one call site: the compositing is inlined, once
        if forward:
            i_t0, i_s0, i_k0, i_t1, i_s1, i_k1 = t_here, s_here, k_here, t_next, s_next, k_next
        else:
            i_t0, i_s0, i_k0, i_t1, i_s1, i_k1 = t_next, s_next, k_next, t_here, s_here, k_here
        n_new, a0, a1, a2, a3 = _composite(a0, a1, a2, a3, i_t0, i_s0, i_t1, i_s1, i_k0, i_k1, forward, mode,
                                           step, tab, lo, inv, unit)
        samples += n_new
        a, b, c = na, nb, nc
        t_here, s_here, k_here = t_next, s_next, k_next
        if a == oa and b == ob and c == oc:
            state = STATE_DONE
            break
        if a == ma and b == mb and c == mc and came_from == mfrom:
            state = STATE_STUCK
            break
        lam += 1
        if lam == power:
            ma, mb, mc, mfrom = a, b, c, came_from
            power *= 2
            lam = 0
    acc[0], acc[1], acc[2], acc[3] = a0, a1, a2, a3
    seg_face[s, sub, 0] = a
    seg_face[s, sub, 1] = b
    seg_face[s, sub, 2] = c
    seg_from[s, sub] = came_from
    if counting:
        seg_clean[s, sub] = 1 if clean else 0
    seg_ts[s, sub, 0] = t_here
    seg_ts[s, sub, 1] = s_here
    seg_steps[s] = steps
    seg_samples[s] += samples
    if state != STATE_ACTIVE:
        seg_state[s] = state


@njit(cache=True, parallel=True)
def advance(active, n_active, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc,
            seg_state, seg_steps, seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps):
    """Advance every listed segment as far as the present tets allow (one bulk-synchronous phase).

    Each segment is handled by one task that only writes its own state, and reads the face table,
    whose keys and tets nobody writes during the phase: the result cannot depend on the thread
    count. (The counters of a counting table are taken off atomically; only their totals matter.)
    """
    # Blocks of neighbouring rays (they meet the same tets: cache reuse); the caller hands
    # them out dynamically (numba.set_parallel_chunksize) so both threads stay busy.
    block = 16
    n_blocks = (n_active + block - 1) // block
    for blk in prange(n_blocks):
        for i in range(blk * block, min(n_active, (blk + 1) * block)):
            s = active[i]
            if seg_state[s] != STATE_ACTIVE:
                continue
            # The literals 0 and 1 make numba compile _walk twice (10 s more on a fresh cache), each
            # with its direction folded into the hot loop: 3 % faster at 512² than one compile.
            _walk(s, 0, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state,
                  seg_steps, seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps)
            if seg_state[s] == STATE_ACTIVE:
                _walk(s, 1, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state,
                      seg_steps, seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps)


# ---------------------------------------------------------------------------------------------
# boundary: rays -> segments
@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _inverse(r):
    return 1.0 / r if abs(r) > 1e-300 else 0.0


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _box_edge(v, n):
    """A pixel box bound ``v`` (a float) clamped to 0..n as an int."""
    if not v > 0.0:  # also NaN
        return 0
    if v >= n:
        return n
    return int(v)


@njit(cache=True, inline="always")
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
        n = _face_hits(P, dens, dirs, width, height, faces, f, fwd, right, up, xs, ys, tan_half,
                       offsets[f] if fill else 0, out_ray, out_t, out_face, out_enter, fill)
        if not fill:
            counts[f] = n


@njit(cache=True)
def _face_hits(P, dens, dirs, width, height, faces, f, fwd, right, up, xs, ys, tan_half, base, out_ray, out_t,
               out_face, out_enter, fill):
    """:func:`_boundary_hits` for face ``f``: records its hits from ``base`` on (if ``fill``); returns their number."""
    i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
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
def _pair_hits(n_rays, hit_ray, hit_t, hit_face, hit_enter):
    """Sort each ray's boundary crossings by t and pair them into (entry, exit) segments."""
    m = hit_ray.shape[0]
    start = np.zeros(n_rays + 1, dtype=np.int64)
    for i in range(m):
        start[hit_ray[i] + 1] += 1
    for r in range(n_rays):
        start[r + 1] += start[r]
    order = np.empty(m, dtype=np.int64)
    pos = start[:-1].copy()
    for i in range(m):
        order[pos[hit_ray[i]]] = i
        pos[hit_ray[i]] += 1
    seg_ray = np.empty(m + 1, dtype=np.int64)
    seg_in = np.empty(m + 1, dtype=np.int64)
    seg_out = np.empty(m + 1, dtype=np.int64)
    nseg = 0
    anomalies = 0
    for r in range(n_rays):
        lo, hi = start[r], start[r + 1]
        # insertion sort by (t, exits first): rays cross few boundary faces
        for i in range(lo + 1, hi):
            x = order[i]
            j = i - 1
            while j >= lo:
                y = order[j]
                if hit_t[y] > hit_t[x] or (hit_t[y] == hit_t[x] and hit_enter[y] and not hit_enter[x]):
                    order[j + 1] = y
                    j -= 1
                else:
                    break
            order[j + 1] = x
        # an entry a rounding error ahead of an exit at the same place (seams, touching parts)
        for i in range(lo, hi - 1):
            x, y = order[i], order[i + 1]
            if hit_enter[x] and not hit_enter[y] and hit_t[y] - hit_t[x] <= 1e-9 * (abs(hit_t[x]) + 1e-30):
                order[i], order[i + 1] = y, x
        # Pair each entry with the next exit. A mesh whose boundary overlaps itself (folded
        # curvilinear grids) can give two entries or two exits in a row: the odd one gets a
        # segment with one end only (-1), whose single subsegment walks until the boundary.
        open_ = -1
        for i in range(lo, hi):
            x = order[i]
            if hit_enter[x]:
                if open_ != -1:
                    seg_ray[nseg] = r
                    seg_in[nseg] = open_
                    seg_out[nseg] = -1
                    nseg += 1
                    anomalies += 1
                open_ = x
            else:
                seg_ray[nseg] = r
                seg_in[nseg] = open_
                seg_out[nseg] = x
                nseg += 1
                if open_ == -1:
                    anomalies += 1
                open_ = -1
        if open_ != -1:
            seg_ray[nseg] = r
            seg_in[nseg] = open_
            seg_out[nseg] = -1
            nseg += 1
            anomalies += 1
    return seg_ray[:nseg], seg_in[:nseg], seg_out[:nseg], anomalies


@njit(cache=True)
def _init_segments(P, dens, dirs, faces, seg_ray_, hit_face, hit_in, hit_out, seg_ray, seg_face, seg_from,
                   seg_ts):
    for s in range(seg_ray_.shape[0]):
        r = seg_ray_[s]
        seg_ray[s] = r
        dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        for sub in range(2):
            hit = hit_in[s] if sub == 0 else hit_out[s]
            if hit < 0:  # no such end: a sentinel face that never matches or moves
                seg_face[s, sub, 0] = -1
                seg_face[s, sub, 1] = -1
                seg_face[s, sub, 2] = -1
                seg_from[s, sub] = -1
                seg_ts[s, sub, 0] = 0.0
                seg_ts[s, sub, 1] = 0.0
                continue
            f = hit_face[hit]
            a, b, c, par = _sort3(faces[f, 0], faces[f, 1], faces[f, 2])
            seg_face[s, sub, 0] = a
            seg_face[s, sub, 1] = b
            seg_face[s, sub, 2] = c
            seg_from[s, sub] = -1  # from outside the mesh
            t, sv = _face_values(P, dens, dx, dy, dz, a, b, c)
            seg_ts[s, sub, 0] = t
            seg_ts[s, sub, 1] = sv


def find_segments(P, dens, dirs, width, height, faces, fwd, right, up, xs, ys, tan_half):
    """All (ray, entry face, exit face) segments of the boundary ``faces`` (outward wound, every
    vertex in front of the eye).

    ``fwd``, ``right``, ``up``: the camera basis; ``xs``, ``ys``: the pixel rays' offsets along
    ``right`` and ``up`` (``Camera.ray_offsets``; ``dirs`` are their normalised directions);
    ``tan_half``: tan of half the vertical view angle.
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
    return seg_ray, seg_face, seg_from, seg_ts, int(anomalies), m


@njit(cache=True)
def _in_sorted(keys, a, b, c):
    lo, hi = 0, keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        k0, k1, k2 = keys[mid, 0], keys[mid, 1], keys[mid, 2]
        if k0 < a or (k0 == a and (k1 < b or (k1 == b and k2 < c))):
            lo = mid + 1
        else:
            hi = mid
    return lo < keys.shape[0] and keys[lo, 0] == a and keys[lo, 1] == b and keys[lo, 2] == c


@njit(cache=True)
def settle(seg_face, seg_from, seg_state, boundary_keys):
    """At the end of the stream: a segment whose marks never met is still complete when both its
    subsegments stopped on boundary faces after moving, or on a fold face (``FOLD_END``), or
    have no end: the mesh's own boundary disagreed with the pairing of its crossings
    (overlapping, folded grids), and nothing on the ray was skipped. Everything else that is
    not done is unfinished."""
    for s in range(seg_state.shape[0]):
        if seg_state[s] != STATE_ACTIVE:
            continue
        ok = True
        for sub in range(2):
            a = seg_face[s, sub, 0]
            if a < 0:
                continue
            if seg_from[s, sub] == FOLD_END:
                continue
            if seg_from[s, sub] < 0 or not _in_sorted(boundary_keys, a, seg_face[s, sub, 1], seg_face[s, sub, 2]):
                ok = False
        if ok:
            seg_state[s] = STATE_DONE


@njit(cache=True)
def compose(n_rays, seg_ray, seg_acc, seg_state, image):
    """Combine subsegments (eq. 3/4) and segments (in ray order) into premultiplied RGBA.

    Segments are stored ray by ray, nearest first. Returns ``(unfinished, hidden)``: the number
    of rays with an unfinished segment whose gap (the part between its front and back marks that
    was never walked) lies in front of opacity ``OPAQUE``, and the number of unfinished segments
    whose gap lies behind it. A ray that is already opaque there has the spec's (and VTK's) early
    termination: what lies behind weighs at most 1 - ``OPAQUE`` and may be skipped, so such a
    segment does not leave its ray unfinished (its partial colour is still added). The ray's
    opacity in front of the gap is that of the segments before it plus this segment's front
    subsegment.
    """
    unfinished = 0
    hidden = 0
    last_bad = -1
    for s in range(seg_ray.shape[0]):
        r = seg_ray[s]
        of = seg_acc[s, 0, 3]
        wb = 1.0 - of
        seg_c0 = seg_acc[s, 0, 0] + wb * seg_acc[s, 1, 0]
        seg_c1 = seg_acc[s, 0, 1] + wb * seg_acc[s, 1, 1]
        seg_c2 = seg_acc[s, 0, 2] + wb * seg_acc[s, 1, 2]
        seg_o = of + wb * seg_acc[s, 1, 3]
        w = 1.0 - image[r, 3]
        alpha_at_gap = image[r, 3] + w * of
        image[r, 0] += w * seg_c0
        image[r, 1] += w * seg_c1
        image[r, 2] += w * seg_c2
        image[r, 3] += w * seg_o
        if seg_state[s] != STATE_DONE:
            if alpha_at_gap >= OPAQUE:
                hidden += 1
            elif r != last_bad:
                unfinished += 1
                last_bad = r
    return unfinished, hidden
