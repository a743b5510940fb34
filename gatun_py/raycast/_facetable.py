"""The ray caster's face table (private): a hash table of the faces of the tets that have arrived,
the lists of subsegments parked on them, and (lean rendering) their ray counters.

Faces live in an open-addressing hash keyed by the sorted vertex triple (a < b < c), in columns
``FT_A``, ``FT_B``, ``FT_C`` of ``htab``. ``FT_TET0`` and ``FT_TET1`` describe the (up to) two tets on
the face as ``2 * e + p``: ``e`` the tet's fourth vertex, ``p`` = 0 if (a, b, c) is wound outward in
it. That is all a ray needs to step through the tet: it takes the tet whose fourth vertex is not
the one of the tet it came from (this also works across zero-volume tets, where "which side" is
not well defined). ``FT_PARKED`` heads a linked list of subsegments parked on the face.

Freeing faces (streaming)
-------------------------
A lean streaming renderer keeps one more column, ``FT_COUNT``: the number of tet steps rays
still have to take next to the face. When a tet arrives, each of its faces gains the number of
pixel rays crossing that face (:func:`count_crossings`, the same edge-side signs the walk uses,
so the count is exact); a ray stepping through a tet takes one off its entry and one off its exit
face. A face at zero with nobody parked on it will never be looked up again and is dropped when
the table is next rebuilt (:func:`rehash` with ``purge``), so the table holds the tets in flight,
not the whole mesh. Crossings the walk could only resolve by its rounding fallback are neither
counted nor taken off (they keep a face alive, never free it early).

The table is one tuple ``F`` built by :func:`make_face_table`, passed whole to the kernels:

=============== ====================== ===============================================================
field           array                  meaning
=============== ====================== ===============================================================
``FT_TABLE``    (cap, 6 or 7) int32    the hash table (cap a power of two; 7 columns: counting)
``FT_INFO``     (3,) int64             scalars: ``INFO_FACES`` faces stored, ``INFO_MUL`` slots per
                                       vertex id (see :func:`_hash0`), ``INFO_NODES`` nodes used
``FT_NODES``    (k, 3) int32           pool of park-list nodes: ``NODE_ITEM``, ``NODE_VER``,
                                       ``NODE_NEXT``
``FT_PARK_VER`` (2 n_seg,) int32       per subsegment (item 2 s + sub): its park version; a node is
                                       live while its version is the item's current one (an item
                                       that moves on is re-parked with a new version, its old node
                                       goes stale)
``FT_IN_LIST``  (2 n_seg,) uint8       per item: parked on a list now
``FT_PARKED_ON`` (2 n_seg, 3) int32    per item: the face it is parked on
=============== ====================== ===============================================================

A table that grows or is purged gets a new ``FT_TABLE`` (:func:`with_table`), the node pool a new
``FT_NODES`` (:func:`with_nodes`); the rest stays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..mesh.model import TET_FACES
from ._geom import NEAR, _edge_terms, _flat, _norm, _project, _sort3
from ._segments import SEG_FACE, SEG_MARK, SEG_STATE, STATE_ACTIVE

FT_TABLE, FT_INFO, FT_NODES, FT_PARK_VER, FT_IN_LIST, FT_PARKED_ON = range(6)
FT_A, FT_B, FT_C, FT_TET0, FT_TET1, FT_PARKED, FT_COUNT = range(7)  # columns of the table
INFO_FACES, INFO_MUL, INFO_NODES = range(3)
NODE_ITEM, NODE_VER, NODE_NEXT = range(3)


def make_face_table(cap: int, mul: int, n_seg: int, *, counting: bool):
    """An empty face table ``F`` of ``cap`` slots (a power of two) for ``n_seg`` segments.

    ``mul``: slots per vertex id in 16-bit fixed point, 0 to scatter (see :func:`_hash0`);
    ``counting``: keep the ``FT_COUNT`` column (lean rendering).
    """
    info = np.zeros(3, dtype=np.int64)
    info[INFO_MUL] = mul
    return (np.full((cap, FT_COUNT + 1 if counting else FT_COUNT), -1, dtype=np.int32), info,
            np.empty((2 * n_seg + 16, 3), dtype=np.int32), np.zeros(2 * n_seg, dtype=np.int32),
            np.zeros(2 * n_seg, dtype=np.uint8), np.full((2 * n_seg, 3), -1, dtype=np.int32))


def with_table(F, table):
    """``F`` with a new hash table (after :func:`rehash`)."""
    return (table,) + F[FT_INFO:]


def with_nodes(F, nodes):
    """``F`` with a new node pool."""
    return F[:FT_NODES] + (nodes,) + F[FT_PARK_VER:]


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
# face hash
@njit(cache=True, _nrt=False)
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


@njit(cache=True, _nrt=False)
def _hash_find(htab, mul, a, b, c):
    """The slot of face (a, b, c) (sorted ids), or -1."""
    mask = htab.shape[0] - 1
    h = _hash0(a, b, c, mul, mask)
    while True:
        k0 = htab[h, FT_A]
        if k0 == -1:
            return -1
        if k0 == a and htab[h, FT_B] == b and htab[h, FT_C] == c:
            return h
        h = (h + 1) & mask


@njit(cache=True, _nrt=False)
def _hash_insert(htab, mul, info, a, b, c):
    """The slot of face (a, b, c) (sorted ids), added with no tets if new (counted in ``info``)."""
    mask = htab.shape[0] - 1
    h = _hash0(a, b, c, mul, mask)
    while True:
        k0 = htab[h, FT_A]
        if k0 == -1:
            htab[h, FT_A] = a
            htab[h, FT_B] = b
            htab[h, FT_C] = c
            htab[h, FT_TET0] = -1
            htab[h, FT_TET1] = -1
            htab[h, FT_PARKED] = -1
            if htab.shape[1] > FT_COUNT:
                htab[h, FT_COUNT] = 0
            info[INFO_FACES] += 1
            return h
        if k0 == a and htab[h, FT_B] == b and htab[h, FT_C] == c:
            return h
        h = (h + 1) & mask


@njit(cache=True, _nrt=False)
def _live(htab, h, purge, fold_mark):
    """Whether slot ``h`` holds a face worth keeping (with ``purge``: still needed, or next to a
    fold, see :func:`count_crossings`)."""
    if htab[h, FT_A] == -1:
        return False
    if not purge or htab.shape[1] <= FT_COUNT:
        return True
    if htab[h, FT_COUNT] > 0 or htab[h, FT_PARKED] != -1:
        return True
    return fold_mark[htab[h, FT_A]] != 0 or fold_mark[htab[h, FT_B]] != 0 or fold_mark[htab[h, FT_C]] != 0


@njit(cache=True)
def count_live(F, purge, fold_mark):
    """The faces :func:`rehash` would keep."""
    htab = F[FT_TABLE]
    n = 0
    for h in range(htab.shape[0]):
        if _live(htab, h, purge, fold_mark):
            n += 1
    return n


@njit(cache=True)
def rehash(F, new_cap, new_mul, purge, fold_mark):
    """The face table copied into a new one of ``new_cap`` (a power of two) slots, ``new_mul``
    slots per vertex id; with ``purge``, without the faces no ray will look up again (count zero,
    nobody parked, no vertex by a fold). Updates ``F``'s face count and ``mul``; returns the new
    table (for :func:`with_table`)."""
    htab, info = F[FT_TABLE], F[FT_INFO]
    ntab = np.full((new_cap, htab.shape[1]), -1, dtype=np.int32)
    info[INFO_FACES] = 0
    info[INFO_MUL] = new_mul
    for h in range(htab.shape[0]):
        if _live(htab, h, purge, fold_mark):
            g = _hash_insert(ntab, new_mul, info, htab[h, FT_A], htab[h, FT_B], htab[h, FT_C])
            for col in range(FT_TET0, htab.shape[1]):
                ntab[g, col] = htab[h, col]
    return ntab


@njit(cache=True)
def insert_tets(tets, crossings, fold_mark, F, S, mark, active):
    """Enter a batch of tets into the face table ``F``; collect the segments parked on their faces.

    ``crossings`` (n, 4): rays crossing each tet's faces (:func:`count_crossings`), added to the
    faces' counters; an empty array when the table does not count (in-memory rendering). A face
    whose two tets lie on the same side of it (a grid folded over itself) marks its five vertices
    in ``fold_mark``. The segments of ``S`` whose subsegments were parked on a face of the batch
    are written to ``active`` once each (``SEG_MARK`` = ``mark``: listed in this batch).

    Returns (number of segments written to ``active``, number of face conflicts).
    """
    htab, info, nodes, park_ver, in_list = F[FT_TABLE], F[FT_INFO], F[FT_NODES], F[FT_PARK_VER], F[FT_IN_LIST]
    seg_mark = S[SEG_MARK]
    mul = info[INFO_MUL]
    n_active = 0
    conflicts = 0
    for t in range(tets.shape[0]):
        for k in range(4):
            a, b, c, par = _sort3(tets[t, TET_FACES[k, 0]], tets[t, TET_FACES[k, 1]], tets[t, TET_FACES[k, 2]])
            slot = _hash_insert(htab, mul, info, a, b, c)
            code = 2 * tets[t, k] + par  # fourth vertex, and whether (a, b, c) is wound outward in it
            if htab[slot, FT_TET0] == -1:
                htab[slot, FT_TET0] = code
            elif htab[slot, FT_TET1] == -1:
                htab[slot, FT_TET1] = code
                if crossings.shape[0] > 0 and (htab[slot, FT_TET0] & 1) == par:  # both wind it outward
                    fold_mark[a] = 1
                    fold_mark[b] = 1
                    fold_mark[c] = 1
                    fold_mark[htab[slot, FT_TET0] >> 1] = 1
                    fold_mark[tets[t, k]] = 1
            else:
                conflicts += 1  # a third tet on one face: not a conforming mesh
            if crossings.shape[0] > 0:
                htab[slot, FT_COUNT] += crossings[t, k]
            node = htab[slot, FT_PARKED]
            while node != -1:
                item = nodes[node, NODE_ITEM]
                if nodes[node, NODE_VER] == park_ver[item] and in_list[item]:
                    in_list[item] = 0
                    s = item >> 1
                    if seg_mark[s] != mark:
                        seg_mark[s] = mark
                        active[n_active] = s
                        n_active += 1
                node = nodes[node, NODE_NEXT]
            htab[slot, FT_PARKED] = -1
    return n_active, conflicts


# ---------------------------------------------------------------------------------------------
# counting (lean rendering)
@njit(cache=True, _nrt=False)
def _pixel_span(u0, u1, u2, u3, n):
    """Pixels k (centres at k + 0.5) within [min u, max u], a thousandth of a pixel to spare:
    the span must hold every pixel whose ray can cross the tet, or a face would be freed early."""
    lo = min(min(u0, u1), min(u2, u3)) - 0.5 - 1e-3
    hi = max(max(u0, u1), max(u2, u3)) - 0.5 + 1e-3
    if not (lo < n and hi >= 0.0):  # also NaN
        return 0, 0
    return max(int(math.ceil(lo)), 0), min(int(math.floor(hi)), n - 1) + 1

@njit(cache=True, _nrt=False)
def _near_crossing(x0, t0, x1, t1, x2, t2):
    """1 if the ray crosses the face with directed edge sides x0, x1, x2, or misses it by no more
    than rounding (each side within its bound t of agreeing with the others), else 0."""
    if x0 >= -t0 and x1 >= -t1 and x2 >= -t2:
        return 1
    if x0 <= t0 and x1 <= t1 and x2 <= t2:
        return 1
    return 0


ODD_MARGIN = 3.0  # pixels around a ray with unpaired boundary crossings whose tets are all kept


@njit(cache=True, _nrt=False)
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
        v0, v1, v2, v3 = np.int64(tets[t, 0]), np.int64(tets[t, 1]), np.int64(tets[t, 2]), np.int64(tets[t, 3])
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


# ---------------------------------------------------------------------------------------------
# parking
@njit(cache=True)
def park(active, n_active, S, F):
    """Hang the unfinished subsegments of the segments ``active[:n_active]`` on the faces where
    they stopped (a subsegment still listed on the face it waits on is left alone)."""
    seg_face, seg_state = S[SEG_FACE], S[SEG_STATE]
    htab, info, nodes, park_ver, in_list, parked_on = F
    mul = info[INFO_MUL]
    n_nodes = info[INFO_NODES]
    for i in range(n_active):
        s = active[i]
        if seg_state[s] != STATE_ACTIVE:
            continue
        for sub in range(2):
            item = 2 * s + sub
            a, b, c = seg_face[s, sub, 0], seg_face[s, sub, 1], seg_face[s, sub, 2]
            if a < 0:
                continue
            if in_list[item] and parked_on[item, 0] == a and parked_on[item, 1] == b and parked_on[item, 2] == c:
                continue
            slot = _hash_insert(htab, mul, info, a, b, c)
            park_ver[item] += 1
            in_list[item] = 1
            parked_on[item, 0] = a
            parked_on[item, 1] = b
            parked_on[item, 2] = c
            nodes[n_nodes, NODE_ITEM] = item
            nodes[n_nodes, NODE_VER] = park_ver[item]
            nodes[n_nodes, NODE_NEXT] = htab[slot, FT_PARKED]
            htab[slot, FT_PARKED] = n_nodes
            n_nodes += 1
    info[INFO_NODES] = n_nodes
