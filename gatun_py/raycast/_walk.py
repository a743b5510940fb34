"""The ray caster's walk (private): subsegments step through the tets that have arrived,
sampling and compositing as they go; at the end, segments are settled and composed into pixels.

A subsegment stands on a face (``SEG_FACE``) and knows the tet it came through (``SEG_FROM``). A
step looks the face up in the face table (``_facetable``), takes the tet on it that it did not
come from, finds the face where the ray leaves that tet from the signs of the six edge sides
(``_geom``), and composites the interval between the two faces: front subsegments front to
back, back subsegments back to front. Segments whose subsegments meet are done; :func:`compose`
joins each segment's two colours (the paper's equation 3) and the segments of a ray in depth
order (equation 4).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._facetable import FT_COUNT, FT_INFO, FT_TABLE, FT_TET0, FT_TET1, INFO_MUL, _atomic_sub_i32, _hash_find
from ._geom import _barycentric, _chord_midpoint, _depth, _flat, _side
from ._segments import (ACC_A, ACC_B, ACC_G, ACC_R, BACK, FOLD_END, FRONT, NEVER_COUNTS, SEG_ACC, SEG_FACE,
                        SEG_FROM, SEG_RAY, SEG_STATE, STATE_ACTIVE, STATE_DONE, STATE_STUCK, TS_SCALAR, TS_T)

MODE_VOLUME = 0
MODE_FACE = 1

# A ray this opaque is finished (the and VTK's early-termination threshold): segments
# behind it can change its colour by at most 1 - OPAQUE.
OPAQUE = 0.99


def make_sampling(mode: int, step: float, tab, lo: float, inv: float, unit: float):
    """The sampling ``V`` the walk takes: ``mode`` (``MODE_VOLUME`` or ``MODE_FACE``), the volume
    sample ``step``, the transfer function's lookup table ``tab`` (row i: r, g, b, a at scalar
    ``lo + i / inv``; in volume mode the opacity of one step) and its ``unit_distance``."""
    return (int(mode), float(step), tab, float(lo), float(inv), float(unit))


# ---------------------------------------------------------------------------------------------
# sampling and compositing
@njit(cache=True, _nrt=False)
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


@njit(cache=True, _nrt=False)
def _first_sample(t0, step):
    k = math.ceil(t0 / step)
    if (k - 1) * step >= t0:
        k -= 1
    if k * step < t0:
        k += 1
    return k


# Inlined by numba: LLVM leaves a function with a loop as a call, which cost 4 % at 512² here.
@njit(cache=True, _nrt=False, inline="always")
def _composite(a0, a1, a2, a3, t0, s0, t1, s1, k0, k1, forward, mode, step, tab, lo, inv, unit, thr):
    """Composite the tet interval [t0, t1) (scalar s0 -> s1) into the running colour (a0, a1, a2, a3);
    return (samples taken, new colour). The colour stays in registers for the whole walk.

    forward: the colour is a front subsegment's (new samples go behind it); otherwise a back
    subsegment's, walking toward the eye (new samples go in front of it). Volume mode: ``k0``,
    ``k1`` are ``_first_sample(t0)``, ``_first_sample(t1)`` (the walk computes each face's once).
    A front subsegment stops at the first sample that brings its opacity to ``thr`` (early ray
    termination; ``thr`` > 1: never).
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
            if forward and a3 >= thr:
                return q + 1, a0, a1, a2, a3
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


@njit(cache=True, _nrt=False)
def _blend(a0, a1, a2, a3, c0, c1, c2, al, forward):
    """The running colour with a sample (colour c, opacity al) added behind it (``forward``: a
    front subsegment) or in front of it (a back subsegment walking toward the eye)."""
    if forward:
        w = (1.0 - a3) * al
        return a0 + w * c0, a1 + w * c1, a2 + w * c2, a3 + w
    r = 1.0 - al
    return al * c0 + r * a0, al * c1 + r * a1, al * c2 + r * a2, al + r * a3


@njit(cache=True, _nrt=False)
def _first_sample_at(t, step, mode):
    """``_first_sample(t)`` in volume mode for a finite ``t``; 0 where it is not needed."""
    if mode == MODE_VOLUME and math.isfinite(t):
        return _first_sample(t, step)
    return 0


# ---------------------------------------------------------------------------------------------
# walking
@njit(cache=True, _nrt=False)
def _sort3p(a, b, c, wa, wb, wc, ta, tb, tc, da, db, dc):
    """Sort three ids, carrying a weight, a depth and a scalar with each."""
    if a > b:
        a, b, wa, wb, ta, tb, da, db = b, a, wb, wa, tb, ta, db, da
    if b > c:
        b, c, wb, wc, tb, tc, db, dc = c, b, wc, wb, tc, tb, dc, db
    if a > b:
        a, b, wa, wb, ta, tb, da, db = b, a, wb, wa, tb, ta, db, da
    return a, b, c, wa, wb, wc, ta, tb, tc, da, db, dc


@njit(cache=True, _nrt=False)
def _canon(i, j, x, g):
    """An edge side known for the directed edge i -> j, as (lo, hi, value, sign) of lo -> hi.

    ``_side`` evaluates every edge lo -> hi and negates for hi -> lo, so negating back gives the
    canonical value bit for bit."""
    if i < j:
        return i, j, x, g
    return j, i, -x, -g


@njit(cache=True, _nrt=False)
def _by_edge(na, nb, e, vab, sab, vbc, sbc, vac, sac):
    """File the canonical edge side ``e`` under its edge of the face (na, nb, nc)."""
    if e[0] == na:
        if e[1] == nb:
            return e[2], e[3], vbc, sbc, vac, sac
        return vab, sab, vbc, sbc, e[2], e[3]
    return vab, sab, e[2], e[3], vac, sac


@njit(cache=True, _nrt=False)
def _walk(s, sub, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state, seg_steps,
          seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps, thr):
    """Advance subsegment ``sub`` (``FRONT`` or ``BACK``) of segment ``s`` through every present tet.

    Stops when the next tet is missing (the subsegment stays parked on that face), when it
    reaches the other subsegment's face (segment done), or after ``max_steps`` steps in total
    for the segment (stuck: it can only be looping on inconsistent geometry), or, for a front
    subsegment, at the sample where its opacity reaches ``thr`` (early ray termination: the segment
    is done and the back subsegment's partial colour is dropped, so the result does not depend on
    how far the back walked; ``thr`` > 1: never). Returns the segment's state.

    A counting table (``FT_COUNT`` column) loses one from the entry and the exit face of every
    tet stepped through, where the crossing was a clean one (``SEG_CLEAN`` 1: all three edge sides agreed;
    ``NEVER_COUNTS`` for the segments of rays whose boundary crossings did not pair up: on a grid
    that overlaps itself such a ray can walk the same tets in two segments).
    """
    if seg_from[s, sub] == FOLD_END:
        return STATE_ACTIVE
    counting = htab.shape[1] > FT_COUNT and seg_clean[s, sub] != NEVER_COUNTS
    clean = seg_clean[s, sub] == 1
    r = seg_ray[s]
    dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
    forward = sub == FRONT
    want = 1.0 if forward else -1.0
    # int64 like the faces the walk moves on to: one compiled version of each helper, not two
    a, b, c = np.int64(seg_face[s, sub, 0]), np.int64(seg_face[s, sub, 1]), np.int64(seg_face[s, sub, 2])
    oa, ob, oc = seg_face[s, 1 - sub, 0], seg_face[s, 1 - sub, 1], seg_face[s, 1 - sub, 2]
    came_from = seg_from[s, sub]
    t_here, s_here = seg_ts[s, sub, TS_T], seg_ts[s, sub, TS_SCALAR]
    # the running colour, in registers
    a0, a1, a2, a3 = seg_acc[s, sub, ACC_R], seg_acc[s, sub, ACC_G], seg_acc[s, sub, ACC_B], seg_acc[s, sub, ACC_A]
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
    # the face's vertices' depths along the ray and scalars, carried like its sides: a step
    # computes only its new vertex's
    ta, tb, tc = _depth(P, a, dx, dy, dz), _depth(P, b, dx, dy, dz), _depth(P, c, dx, dy, dz)
    da, db, dc = dens[a], dens[b], dens[c]
    slot = _hash_find(htab, mul, a, b, c)
    while True:
        if slot < 0:
            break
        code = -1
        h0 = htab[slot, FT_TET0]
        h1 = htab[slot, FT_TET1]
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
            t0, t1, t2, d0, d1, d2 = ta, tc, tb, da, dc, db
        else:
            v0, v1, v2 = a, b, c
            t0, t1, t2, d0, d1, d2 = ta, tb, tc, da, db, dc
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
            _atomic_sub_i32(htab, slot, FT_COUNT, 1)
        x03, g03 = _side(P, dx, dy, dz, v0, v3)
        x13, g13 = _side(P, dx, dy, dz, v1, v3)
        x23, g23 = _side(P, dx, dy, dz, v2, v3)
        t3, d3 = _depth(P, v3, dx, dy, dz), dens[v3]
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
            na, nb, nc, wa, wb, wc, ta, tb, tc, da, db, dc = _sort3p(v1, v2, v3, x23, -x13, x12, t1, t2, t3, d1, d2, d3)
            came_from = v0
            e0 = _canon(v1, v2, x12, g12)
            e1 = _canon(v2, v3, x23, g23)
            e2 = _canon(v1, v3, x13, g13)
        elif best_k == 1:
            na, nb, nc, wa, wb, wc, ta, tb, tc, da, db, dc = _sort3p(v0, v3, v2, -x23, x20, x03, t0, t3, t2, d0, d3, d2)
            came_from = v1
            e0 = _canon(v0, v3, x03, g03)
            e1 = _canon(v2, v3, x23, g23)
            e2 = _canon(v2, v0, x20, g20)
        else:
            na, nb, nc, wa, wb, wc, ta, tb, tc, da, db, dc = _sort3p(v0, v1, v3, x13, -x03, x01, t0, t1, t3, d0, d1, d3)
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
            _atomic_sub_i32(htab, slot, FT_COUNT, 1)
        t_next, s_next, ok = _barycentric(ta, tb, tc, da, db, dc, wa, wb, wc)
        if not ok:  # the ray lies in the exit face's plane
            t_next, s_next = _chord_midpoint(P, dens, dx, dy, dz, na, nb, nc)
        k_next = _first_sample_at(t_next, step, mode)
        # one call site: the compositing is inlined, once
        if forward:
            i_t0, i_s0, i_k0, i_t1, i_s1, i_k1 = t_here, s_here, k_here, t_next, s_next, k_next
        else:
            i_t0, i_s0, i_k0, i_t1, i_s1, i_k1 = t_next, s_next, k_next, t_here, s_here, k_here
        n_new, a0, a1, a2, a3 = _composite(a0, a1, a2, a3, i_t0, i_s0, i_t1, i_s1, i_k0, i_k1, forward, mode,
                                           step, tab, lo, inv, unit, thr)
        samples += n_new
        a, b, c = na, nb, nc
        t_here, s_here, k_here = t_next, s_next, k_next
        if forward and a3 >= thr:
            state = STATE_DONE
            for ch in range(4):
                seg_acc[s, BACK, ch] = 0.0
            break
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
    seg_acc[s, sub, ACC_R], seg_acc[s, sub, ACC_G], seg_acc[s, sub, ACC_B], seg_acc[s, sub, ACC_A] = a0, a1, a2, a3
    seg_face[s, sub, 0] = a
    seg_face[s, sub, 1] = b
    seg_face[s, sub, 2] = c
    seg_from[s, sub] = came_from
    if counting:
        seg_clean[s, sub] = 1 if clean else 0
    seg_ts[s, sub, TS_T] = t_here
    seg_ts[s, sub, TS_SCALAR] = s_here
    seg_steps[s] = steps
    seg_samples[s] += samples
    if state != STATE_ACTIVE:
        seg_state[s] = state
    return state


@njit(cache=True, parallel=True)
def advance(active, n_active, P, dens, dirs, S, F, V, max_steps, thr):
    """Advance the segments ``active[:n_active]`` of ``S`` as far as the tets in the face table ``F``
    allow (one bulk-synchronous phase). ``V``: the sampling (:func:`make_sampling`).

    Each segment is handled by one task that only writes its own state, and reads the face table,
    whose keys and tets nobody writes during the phase: the result cannot depend on the thread
    count. (The counters of a counting table are taken off atomically; only their totals matter.)
    """
    # The walk takes the arrays one by one: a tuple of arrays passed on every call cost ~2 %.
    seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state, seg_steps, seg_samples, _ = S
    htab = F[FT_TABLE]
    mul = F[FT_INFO][INFO_MUL]
    mode, step, tab, lo, inv, unit = V
    # Blocks of neighbouring rays (they meet the same tets: cache reuse); the caller hands
    # them out dynamically (numba.set_parallel_chunksize) so both threads stay busy.
    block = 16
    n_blocks = (n_active + block - 1) // block
    for blk in prange(n_blocks):
        for i in range(blk * block, min(n_active, (blk + 1) * block)):
            s = active[i]
            if seg_state[s] != STATE_ACTIVE:
                continue
            # front, then back if the front did not finish the segment; ``sub`` is a variable, not
            # a literal 0 / 1, so numba compiles _walk once (two literal calls compiled it twice)
            for sub in range(2):
                # the state comes back from the walk rather than from seg_state: a parallel loop's
                # arrays are compiled as not aliasing the walk's, and a re-read of seg_state[s]
                # after the walk may be folded into the read above
                if _walk(s, sub, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state,
                         seg_steps, seg_samples, htab, mul, mode, step, tab, lo, inv, unit, max_steps,
                         thr if sub == FRONT else 2.0) != STATE_ACTIVE:
                    break


@njit(cache=True, parallel=True)
def advance_rays(run_lo, run_hi, P, dens, dirs, S, F, V, max_steps, terminate):
    """Walk whole rays, front to back: the segments ``run_lo[i]:run_hi[i]`` (one ray's, nearest
    first) for every i, each from its entry face as far as the tets in ``F`` allow (every tet
    present: to its exit face), the back subsegment only where the front could not finish.

    With ``terminate`` a ray stops where its opacity (of its segments so far, combined as
    :func:`compose` does) reaches ``OPAQUE``: the front subsegment's threshold is the opacity that
    takes the ray there, and segments behind an opaque ray are not walked (``compose`` leaves
    them out). One task per block of rays, each writing only its rays' segments: the result cannot
    depend on the thread count.
    """
    seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc, seg_state, seg_steps, seg_samples, _ = S
    htab = F[FT_TABLE]
    mul = F[FT_INFO][INFO_MUL]
    mode, step, tab, lo, inv, unit = V
    n_runs = run_lo.shape[0]
    block = 16  # neighbouring rays meet the same tets (the caller hands blocks out dynamically)
    n_blocks = (n_runs + block - 1) // block
    for blk in prange(n_blocks):
        for i in range(blk * block, min(n_runs, (blk + 1) * block)):
            alpha = 0.0
            for s in range(run_lo[i], run_hi[i]):
                if terminate and alpha >= OPAQUE:
                    seg_state[s] = STATE_DONE
                    continue
                thr = (OPAQUE - alpha) / (1.0 - alpha) if terminate else 2.0
                if seg_state[s] == STATE_ACTIVE:
                    for sub in range(2):
                        if _walk(s, sub, P, dens, dirs, seg_ray, seg_face, seg_from, seg_clean, seg_ts, seg_acc,
                                 seg_state, seg_steps, seg_samples, htab, mul, mode, step, tab, lo, inv, unit,
                                 max_steps, thr if sub == FRONT else 2.0) != STATE_ACTIVE:
                            break
                of = seg_acc[s, FRONT, ACC_A]
                alpha += (1.0 - alpha) * (of + (1.0 - of) * seg_acc[s, BACK, ACC_A])


@njit(cache=True, _nrt=False)
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
def settle(S, boundary_keys):
    """At the end of the stream: a segment whose marks never met is still complete when both its
    subsegments stopped on boundary faces after moving, or on a fold face (``FOLD_END``), or
    have no end: the mesh's own boundary disagreed with the pairing of its crossings
    (overlapping, folded grids), and nothing on the ray was skipped. Everything else that is
    not done is unfinished."""
    seg_face, seg_from, seg_state = S[SEG_FACE], S[SEG_FROM], S[SEG_STATE]
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
def compose(S, image, terminate):
    """Combine subsegments (eq. 3/4) and segments (in ray order) into premultiplied RGBA.

    Segments are stored ray by ray, nearest first. Returns ``(unfinished, hidden)``: the number
    of rays with an unfinished segment whose gap (the part between its front and back marks that
    was never walked) lies in front of opacity ``OPAQUE``, and the number of unfinished segments
    whose gap lies behind it. A ray that is already opaque there has the spec's (and VTK's) early
    termination: what lies behind weighs at most 1 - ``OPAQUE`` and may be skipped, so such a
    segment does not leave its ray unfinished (its partial colour is still added). The ray's
    opacity in front of the gap is that of the segments before it plus this segment's front
    subsegment. With ``terminate`` a segment behind a ray already as opaque as ``OPAQUE`` adds
    nothing (early ray termination, as :func:`advance_rays` walks it).
    """
    seg_ray, seg_acc, seg_state = S[SEG_RAY], S[SEG_ACC], S[SEG_STATE]
    unfinished = 0
    hidden = 0
    last_bad = -1
    for s in range(seg_ray.shape[0]):
        r = seg_ray[s]
        front, back = seg_acc[s, FRONT], seg_acc[s, BACK]
        of = front[ACC_A]
        wb = 1.0 - of
        seg_c0 = front[ACC_R] + wb * back[ACC_R]
        seg_c1 = front[ACC_G] + wb * back[ACC_G]
        seg_c2 = front[ACC_B] + wb * back[ACC_B]
        seg_o = of + wb * back[ACC_A]
        w = 1.0 - image[r, ACC_A]
        alpha_at_gap = image[r, ACC_A] + w * of
        if terminate and image[r, ACC_A] >= OPAQUE:
            w = 0.0  # behind the termination point: skipped (a walk may have been cut short there)
        image[r, ACC_R] += w * seg_c0
        image[r, ACC_G] += w * seg_c1
        image[r, ACC_B] += w * seg_c2
        image[r, ACC_A] += w * seg_o
        if seg_state[s] != STATE_DONE:
            if alpha_at_gap >= OPAQUE:
                hidden += 1
            elif r != last_bad:
                unfinished += 1
                last_bad = r
    return unfinished, hidden
