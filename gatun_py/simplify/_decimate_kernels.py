"""Numba kernels of the Van Gelder decimation (see :mod:`gatun_py.simplify.decimation`).

Everything here works on plain arrays; :func:`gatun_py.simplify.decimation.decimate` builds them,
validates the input and drives the loop. Vertex and tet ids here are the state's local
numbering (see :class:`gatun_py.simplify.decimation.DecimationState`); ``vkey`` maps a vertex to
the caller's id, which breaks every tie between equal errors. The mesh state during decimation:

``T`` (m, 4) int32
    current vertex ids of every tet (a merged vertex is replaced by its target in place);
``alive`` (m,) bool
    False once a tet has collapsed (it contained both ends of a merged edge);
``nbr`` (m, 4) int32
    the tet across face k (the face opposite corner k), -1 on the boundary;
``head`` (n,), ``nxt`` (4m,) int32
    per-vertex singly linked lists of "slots" 4*t + c (tet t has this vertex at corner c).
    Merging a into b splices a's list onto b's; slots of dead tets are unlinked lazily.
``quad`` (n, 15) float64, ``u4`` (n, 4) float64
    every vertex's error quadric (A's upper triangle, b, c; see :func:`_quadric_at`) and its
    (x, y, z, s) point; merging a into b adds a's quadric to b's.
``pdat`` (r, 6) float64, ``prow`` (r, 2) int32, ``tp_head``, ``tp_count`` (m,) int32
    sample points of the original field, one row (x, y, z, value, weight, error) each (error: the
    weighted squared error against the interpolant of the tet holding it, see
    :func:`_star_samples`): the centroid of every input tet from the start, every vertex once
    merged away (its row made then, from ``pts``, ``dens`` and its weight ``vw``); ``prow[r, 0]``
    names the point (a vertex id, or n + t for tet t's centroid), ``prow[r, 1]`` the tet the run
    holding row r was written for. Every one is listed in the live
    tet that holds it, with its weight (its share of the original volume): tet t's list is the run
    of rows ``tp_head[t]`` .. ``tp_head[t] + tp_count[t] - 1`` (the evaluations read these runs
    in order: the order within a list fixes the sums). Rows ``counters[C_PTOP]`` on are free
    (r = n + m + ``POINT_SLACK`` x (n + m) rows: room beyond the n + m points); a merge writes
    the new lists of its star there, and when the rows run out they are rewritten tet by tet
    from row 0 (:func:`_compact_points`, every list in its order). A merge a -> b hands
    a and the points of a's star to the tets of the new star.

A merge a -> b is legal when every surviving tet of a's star stays positive, every boundary face
around a keeps its orientation, a boundary vertex only goes into a boundary vertex, and the link
condition holds (Dey et al.; the boundary is handled with a virtual vertex joined to every boundary
simplex), which guarantees that the collapse keeps the mesh a manifold with a closed boundary
(no face shared by three tets, no duplicate tets, no pinched boundary).
"""

from __future__ import annotations

import numpy as np
from numba import get_thread_id, njit, prange

from ..mesh._quadric_kernels import hyperplane_normal
from ..codec.forest import ROOT_RANK  # noqa: F401 (decimate.py reads it as K.ROOT_RANK)
from ..mesh.model import TET_FACES as _TET_FACES

# A surviving tet must keep at least this fraction of (longest edge)^3 as 6x its volume, or not
# shrink below its current volume: far above float64 rounding of the triple product, so "positive
# here" means "positive" for any other evaluation of the same determinant.
VOLUME_EPS = 1e-10
# A boundary face may not turn by 90 degrees or more (that is the paper's "negative area").
NORMAL_EPS = 1e-6

# Indices into the float parameter array.
P_WD, P_WG, P_WV, P_WI, P_WQ, P_WS, P_NCP, P_MAXS = 0, 1, 2, 3, 4, 5, 6, 7
# Indices into the int64 counter array.
C_MERGES, C_HEAP, C_STAMP, C_SWEEPS, C_EVALS, C_STARTED, C_EXACT, C_PTOP = 0, 1, 2, 3, 4, 5, 6, 7
# what the search does (bench/forest_identity.py --counters prints them): link tests, exact
# evaluations stopped by their bound, sample points summed by exact evaluations, heap pops and the
# stale ones, evaluations of one vertex on its pop, sample points moved by merges, rewrites of the
# point rows (:func:`_compact_points`)
C_LINK, C_PRUNED, C_POINTS, C_POPS, C_STALE, C_LAZY, C_MOVED, C_REWRITES = 8, 9, 10, 11, 12, 13, 14, 15
N_COUNTERS = 16
# bits of a vertex's ``pinned`` flags: PIN_KEEP never merged away, PIN_NO_TARGET nothing merges into
# it. A non-manifold vertex has both (PIN_ALL); a locked vertex (a brick's cut vertex) only
# PIN_KEEP, and only interior vertices merge into it: an interior vertex's merge keeps every
# boundary triangle (its star is a ball whose surface, the link, is unchanged), so a brick's cut
# faces stay exactly the triangles its neighbours have.
PIN_KEEP, PIN_NO_TARGET = 1, 2
PIN_ALL = PIN_KEEP | PIN_NO_TARGET

# Reference counting: the helpers below that never allocate are compiled with ``_nrt=False`` (no
# numba runtime, so no atomic incref / decref of every array argument, view and tuple item on
# every call; their caller owns every array for the whole call). Profiled on Blunt-fin (perf on the
# kernels' code), those two atomic instructions were ~19 % of the decimation's CPU time: the
# per-tet helpers (_tet_planes, _contains, ...) run millions of times. The arithmetic is the
# same, so the forest is bit-identical (bench/forest_identity.py). Functions that allocate
# (stars, contexts, the evaluation, the merge, the driver) keep the runtime.


@njit(cache=True, _nrt=False)
def _orient6(p, a, b, c, d):
    """6 x signed volume of (a, b, c, d), evaluated like ``TetMesh.signed_volumes`` (same order)."""
    ax = p[a, 0]
    ay = p[a, 1]
    az = p[a, 2]
    ux = p[b, 0] - ax
    uy = p[b, 1] - ay
    uz = p[b, 2] - az
    vx = p[c, 0] - ax
    vy = p[c, 1] - ay
    vz = p[c, 2] - az
    wx = p[d, 0] - ax
    wy = p[d, 1] - ay
    wz = p[d, 2] - az
    cx = vy * wz - vz * wy
    cy = vz * wx - vx * wz
    cz = vx * wy - vy * wx
    return (ux * cx + uy * cy) + uz * cz


@njit(cache=True, _nrt=False)
def _det6(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """6 x signed volume of four explicit points (same formula as :func:`_orient6`)."""
    ux = bx - ax
    uy = by - ay
    uz = bz - az
    vx = cx - ax
    vy = cy - ay
    vz = cz - az
    wx = dx - ax
    wy = dy - ay
    wz = dz - az
    return (ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz)) + uz * (vx * wy - vy * wx)


@njit(cache=True, _nrt=False)
def _value_at(pts, dens, q, v6, x, y, z, out):
    """Barycentric interpolation of the density at (x, y, z) in tet q (6 vol v6 > 0).

    Writes (smallest barycentric coordinate, interpolated value) into ``out``.
    """
    lo = 1e300
    val = 0.0
    ax, ay, az = pts[q[0], 0], pts[q[0], 1], pts[q[0], 2]
    bx, by, bz = pts[q[1], 0], pts[q[1], 1], pts[q[1], 2]
    cx, cy, cz = pts[q[2], 0], pts[q[2], 1], pts[q[2], 2]
    dx, dy, dz = pts[q[3], 0], pts[q[3], 1], pts[q[3], 2]
    for j in range(4):
        if j == 0:
            d = _det6(x, y, z, bx, by, bz, cx, cy, cz, dx, dy, dz)
        elif j == 1:
            d = _det6(ax, ay, az, x, y, z, cx, cy, cz, dx, dy, dz)
        elif j == 2:
            d = _det6(ax, ay, az, bx, by, bz, x, y, z, dx, dy, dz)
        else:
            d = _det6(ax, ay, az, bx, by, bz, cx, cy, cz, x, y, z)
        lam = d / v6
        if lam < lo:
            lo = lam
        val += lam * dens[q[j]]
    out[0] = lo
    out[1] = val


@njit(cache=True, _nrt=False)
def _max_edge2(p, q):
    best = 0.0
    for i in range(4):
        for j in range(i + 1, 4):
            dx = p[q[i], 0] - p[q[j], 0]
            dy = p[q[i], 1] - p[q[j], 1]
            dz = p[q[i], 2] - p[q[j], 2]
            d = dx * dx + dy * dy + dz * dz
            if d > best:
                best = d
    return best


@njit(cache=True, _nrt=False)
def _tri_normal(p, a, b, c, out):
    ux = p[b, 0] - p[a, 0]
    uy = p[b, 1] - p[a, 1]
    uz = p[b, 2] - p[a, 2]
    vx = p[c, 0] - p[a, 0]
    vy = p[c, 1] - p[a, 1]
    vz = p[c, 2] - p[a, 2]
    out[0] = uy * vz - uz * vy
    out[1] = uz * vx - ux * vz
    out[2] = ux * vy - uy * vx


@njit(cache=True, _nrt=False)
def _tidy(v, head, nxt, T, alive):
    """Unlink the slots of dead tets (and of tets that no longer hold v) from v's list."""
    prev = -1
    s = head[v]
    while s >= 0:
        ns = nxt[s]
        t = s >> 2
        if alive[t] and T[t, s & 3] == v:
            prev = s
        elif prev < 0:
            head[v] = ns
        else:
            nxt[prev] = ns
        s = ns


@njit(cache=True)
def _star_view(v, head, nxt, T, alive):
    """Slots (4*t + corner) of the live tets around v, in list order, without touching the lists
    (so that evaluations can run in parallel)."""
    cnt = 0
    s = head[v]
    while s >= 0:
        if alive[s >> 2] and T[s >> 2, s & 3] == v:
            cnt += 1
        s = nxt[s]
    out = np.empty(cnt, np.int64)
    i = 0
    s = head[v]
    while s >= 0:
        if alive[s >> 2] and T[s >> 2, s & 3] == v:
            out[i] = s
            i += 1
        s = nxt[s]
    return out


# Scratch: an evaluation takes its ~30 arrays as views of one float and one int buffer per thread
# (``_SCRATCH_F``, ``_SCRATCH_I`` elements; a star too large for them gets new arrays), instead of
# allocating each: an evaluation runs ~4 times per merge.
_SCRATCH_F = 1 << 15
_SCRATCH_I = 1 << 14


@njit(cache=True)
def _take(buf, o, k):
    """(``buf[o:o + k]``, o + k) when it fits in ``buf``, else (a new array of k, o + k)."""
    if o + k <= buf.shape[0]:
        return buf[o:o + k], o + k
    return np.empty(k, buf.dtype), o + k


@njit(cache=True)
def _star_into(v, head, nxt, T, alive, buf):
    """:func:`_star_view` in one walk of the list, as a view of ``buf`` when the star fits."""
    cnt = 0
    cap = buf.shape[0]
    s = head[v]
    while s >= 0:
        if alive[s >> 2] and T[s >> 2, s & 3] == v:
            if cnt >= cap:
                return _star_view(v, head, nxt, T, alive)
            buf[cnt] = s
            cnt += 1
        s = nxt[s]
    return buf[:cnt]


@njit(cache=True)
def _star(v, head, nxt, T, alive):
    """Slots (4*t + corner) of the live tets around v; unlinks dead slots on the way."""
    _tidy(v, head, nxt, T, alive)
    return _star_view(v, head, nxt, T, alive)


@njit(cache=True, _nrt=False)
def _contains(T, t, v):
    return T[t, 0] == v or T[t, 1] == v or T[t, 2] == v or T[t, 3] == v


@njit(cache=True, _nrt=False)
def _next_stamp(counters):
    counters[C_STAMP] += 1
    return counters[C_STAMP]


@njit(cache=True)
def _boundary_faces_of(st, T, nbr):
    """Boundary faces (k, 3) (outward) incident to the star's centre vertex."""
    out, _ = _boundary_faces_into(st, T, nbr, np.empty(0, np.int64), 0)
    return out


@njit(cache=True)
def _boundary_faces_into(st, T, nbr, buf, o):
    """(:func:`_boundary_faces_of` in ``buf`` from o on when they fit, the offset after them)."""
    k = 0
    for i in range(st.shape[0]):
        t = st[i] >> 2
        c = st[i] & 3
        for f in range(4):
            if f != c and nbr[t, f] < 0:
                k += 1
    flat, o = _take(buf, o, 3 * k)
    out = flat.reshape((k, 3))
    k = 0
    for i in range(st.shape[0]):
        t = st[i] >> 2
        c = st[i] & 3
        for f in range(4):
            if f != c and nbr[t, f] < 0:
                for j in range(3):
                    out[k, j] = T[t, _TET_FACES[f, j]]
                k += 1
    return out, o


@njit(cache=True)
def _link_ok(a, b, st_a, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, counters):
    """The link condition Lk(a) ∩ Lk(b) = Lk(ab) for collapsing edge ab (with a virtual vertex ω)."""
    return _link_ok_buf(a, b, st_a, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, counters, np.empty(0, np.int64))


@njit(cache=True)
def _link_ok_buf(a, b, st_a, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, counters, buf):
    """:func:`_link_ok` with b's star and the edges of Lk(ab) in the scratch ``buf`` (when they fit)."""
    st_b = _star_into(b, head, nxt, T, alive, buf)
    s_b = _next_stamp(counters)
    for i in range(st_b.shape[0]):
        t = st_b[i] >> 2
        for j in range(4):
            mark_b[T[t, j]] = s_b
    s_ab = _next_stamp(counters)
    n_shared = 0
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        if _contains(T, t, b):
            n_shared += 1
            for j in range(4):
                mark_ab[T[t, j]] = s_ab
    if n_shared == 0:
        return False  # not an edge of the current mesh
    # Lk(ab) edges: the opposite edge of every tet around ab.
    ab_flat, _ = _take(buf, st_b.shape[0], 2 * n_shared)
    ab_edges = ab_flat.reshape((n_shared, 2))
    k = 0
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        if _contains(T, t, b):
            q = 0
            for j in range(4):
                w = T[t, j]
                if w != a and w != b:
                    ab_edges[k, q] = w
                    q += 1
            k += 1
    # vertices: every common neighbour must be in Lk(ab)
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        for j in range(4):
            w = T[t, j]
            if w != a and w != b and mark_b[w] == s_b and mark_ab[w] != s_ab:
                return False
    # edges and triangles of the link of a (tets of a without b) also in the link of b
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        c = st_a[i] & 3
        if _contains(T, t, b):
            continue
        o0 = T[t, (c + 1) & 3]
        o1 = T[t, (c + 2) & 3]
        o2 = T[t, (c + 3) & 3]
        in0 = mark_b[o0] == s_b
        in1 = mark_b[o1] == s_b
        in2 = mark_b[o2] == s_b
        n_in_ab = 0
        for e in range(3):
            if e == 0:
                p, q, ok = o0, o1, in0 and in1
            elif e == 1:
                p, q, ok = o1, o2, in1 and in2
            else:
                p, q, ok = o0, o2, in0 and in2
            if not ok:
                continue
            in_lk_ab = False
            for r in range(n_shared):
                if (ab_edges[r, 0] == p and ab_edges[r, 1] == q) or (ab_edges[r, 0] == q and ab_edges[r, 1] == p):
                    in_lk_ab = True
                    break
            if in_lk_ab:
                n_in_ab += 1
                continue
            # pq is not in Lk(ab): it must not be in Lk(b) either
            for r in range(st_b.shape[0]):
                tb = st_b[r] >> 2
                if _contains(T, tb, p) and _contains(T, tb, q):
                    return False
        if n_in_ab == 3:
            # a triangle pqr with all edges in Lk(ab): it must not be in Lk(b) (two tets apqr, bpqr)
            for r in range(st_b.shape[0]):
                tb = st_b[r] >> 2
                if _contains(T, tb, o0) and _contains(T, tb, o1) and _contains(T, tb, o2):
                    return False
    # the virtual vertex ω (joined to the boundary): only matters when both ends are on it
    if isb[a] and isb[b]:
        bf_a = _boundary_faces_of(st_a, T, nbr)
        bf_b = _boundary_faces_of(st_b, T, nbr)
        # ω in both links -> ab must be a boundary edge
        ab_faces = 0
        for i in range(bf_a.shape[0]):
            if bf_a[i, 0] == b or bf_a[i, 1] == b or bf_a[i, 2] == b:
                ab_faces += 1
        if ab_faces == 0:
            return False
        # edge wω in both links (aw and bw boundary edges) -> abw must be a boundary face
        for i in range(bf_a.shape[0]):
            for j in range(3):
                w = bf_a[i, j]
                if w == a or w == b:
                    continue
                in_b = False
                for r in range(bf_b.shape[0]):
                    if bf_b[r, 0] == w or bf_b[r, 1] == w or bf_b[r, 2] == w:
                        in_b = True
                        break
                if not in_b:
                    continue
                found = False
                for r in range(bf_a.shape[0]):
                    has_b = bf_a[r, 0] == b or bf_a[r, 1] == b or bf_a[r, 2] == b
                    has_w = bf_a[r, 0] == w or bf_a[r, 1] == w or bf_a[r, 2] == w
                    if has_b and has_w:
                        found = True
                        break
                if not found:
                    return False
        # triangle wxω in both links: boundary faces awx and bwx both exist
        for i in range(bf_a.shape[0]):
            if bf_a[i, 0] == b or bf_a[i, 1] == b or bf_a[i, 2] == b:
                continue
            w = -1
            x = -1
            for j in range(3):
                if bf_a[i, j] != a:
                    if w < 0:
                        w = bf_a[i, j]
                    else:
                        x = bf_a[i, j]
            for r in range(bf_b.shape[0]):
                hw = bf_b[r, 0] == w or bf_b[r, 1] == w or bf_b[r, 2] == w
                hx = bf_b[r, 0] == x or bf_b[r, 1] == x or bf_b[r, 2] == x
                if hw and hx:
                    return False
    return True


@njit(cache=True, _nrt=False)
def _quadric_at(quad, u4, v, w):
    """Quadric of vertex v at vertex w's point u = u4[w] = (x, y, z, s): u^T A u + 2 b.u + c.

    ``quad[v]`` holds A's upper triangle row by row (00 01 02 03 11 12 13 22 23 33), then b, then c.
    A sum of squares, so negative values are rounding and read as 0.
    """
    x0 = u4[w, 0]
    x1 = u4[w, 1]
    x2 = u4[w, 2]
    x3 = u4[w, 3]
    q = quad[v]
    e = (q[0] * x0 * x0 + q[4] * x1 * x1 + q[7] * x2 * x2 + q[9] * x3 * x3
         + 2.0 * (q[1] * x0 * x1 + q[2] * x0 * x2 + q[3] * x0 * x3 + q[5] * x1 * x2 + q[6] * x1 * x3
                  + q[8] * x2 * x3)
         + 2.0 * (q[10] * x0 + q[11] * x1 + q[12] * x2 + q[13] * x3) + q[14])
    return e if e > 0.0 else 0.0


@njit(cache=True, _nrt=False)
def _tet_planes(pts, dens, q, lam, val):
    """Tet q's barycentric coordinates and interpolant as affine functions of the point.

    ``lam[j, :3] . x + lam[j, 3]`` is coordinate j at x, ``val[:3] . x + val[3]`` the value (the
    rows of the inverse of the edge matrix: four dot products per point instead of four
    determinants). Returns False for a tet that is not positive (``_orient6`` <= 0).
    """
    det = _orient6(pts, q[0], q[1], q[2], q[3])
    if not det > 0.0:
        return False
    x0 = pts[q[0], 0]
    y0 = pts[q[0], 1]
    z0 = pts[q[0], 2]
    e1x, e1y, e1z = pts[q[1], 0] - x0, pts[q[1], 1] - y0, pts[q[1], 2] - z0
    e2x, e2y, e2z = pts[q[2], 0] - x0, pts[q[2], 1] - y0, pts[q[2], 2] - z0
    e3x, e3y, e3z = pts[q[3], 0] - x0, pts[q[3], 1] - y0, pts[q[3], 2] - z0
    inv = 1.0 / det
    lam[1, 0] = (e2y * e3z - e2z * e3y) * inv
    lam[1, 1] = (e2z * e3x - e2x * e3z) * inv
    lam[1, 2] = (e2x * e3y - e2y * e3x) * inv
    lam[2, 0] = (e3y * e1z - e3z * e1y) * inv
    lam[2, 1] = (e3z * e1x - e3x * e1z) * inv
    lam[2, 2] = (e3x * e1y - e3y * e1x) * inv
    lam[3, 0] = (e1y * e2z - e1z * e2y) * inv
    lam[3, 1] = (e1z * e2x - e1x * e2z) * inv
    lam[3, 2] = (e1x * e2y - e1y * e2x) * inv
    for r in range(1, 4):
        lam[r, 3] = -(lam[r, 0] * x0 + lam[r, 1] * y0 + lam[r, 2] * z0)
    for c in range(4):
        lam[0, c] = -(lam[1, c] + lam[2, c] + lam[3, c])
    lam[0, 3] += 1.0
    for c in range(4):
        val[c] = dens[q[0]] * lam[0, c] + dens[q[1]] * lam[1, c] + dens[q[2]] * lam[2, c] + dens[q[3]] * lam[3, c]
    return True


@njit(cache=True, _nrt=False)
def _new_value(p, k0, pdat, ok, lam, val, fallback):
    """Value at sample point p after the merge, from the new star's tet planes (``ok[k]``: tet k of
    the star survives positive; ``lam``, ``val`` from :func:`_tet_planes`).

    From the new tet containing p: first the new version of p's own tet k0, then the others in
    star order; if none does (the boundary moved), the one p is nearest to (largest smallest
    barycentric coordinate, the first of equals).
    """
    x = pdat[p, 0]
    y = pdat[p, 1]
    z = pdat[p, 2]
    best_lo = -1e300
    v = fallback
    for kk in range(-1, ok.shape[0]):
        k = k0 if kk < 0 else kk
        if kk == k0 or not ok[k]:
            continue
        lo = 1e300
        for j in range(4):
            lj = lam[k, j, 0] * x + lam[k, j, 1] * y + lam[k, j, 2] * z + lam[k, j, 3]
            if lj < lo:
                lo = lj
        if lo >= 0.0:
            return val[k, 0] * x + val[k, 1] * y + val[k, 2] * z + val[k, 3]
        if lo > best_lo:
            best_lo = lo
            v = val[k, 0] * x + val[k, 1] * y + val[k, 2] * z + val[k, 3]
    return v


# -- the error of a merge a -> b, one term per function ------------------------------------------
# Per vertex a, the star's quantities every candidate b shares are computed once (``_star_*``);
# per candidate, the legality tests (``_new_volumes``, ``_boundary_ok``) and then each error term.
# The whole error is combined by :func:`_total_error`, always in the same order, so that the
# bound of :func:`_evaluate` (the terms that cannot be negative left out) rounds below it.


@njit(cache=True, _nrt=False)
def _star_volumes(a, st, T, pts, dens, vol_old, mass_old, dsum, nrm, off, fn):
    """Per star tet: 6 x volume, mass, density sum without a, and the plane of the face opposite a
    (so that the volume with a moved onto b is one dot product: 6 vol = off - nrm . p_b, linear in
    the moved corner). Returns (volume of the star, squared distance from a to its farthest vertex)."""
    vol_star = 0.0
    reach2 = 0.0
    for i in range(st.shape[0]):
        t = st[i] >> 2
        c = st[i] & 3
        v6 = _orient6(pts, T[t, 0], T[t, 1], T[t, 2], T[t, 3])
        vol_old[i] = v6
        ds = dens[T[t, 0]] + dens[T[t, 1]] + dens[T[t, 2]] + dens[T[t, 3]]
        mass_old[i] = v6 / 6.0 * ds * 0.25
        dsum[i] = ds - dens[a]
        vol_star += abs(v6) / 6.0
        f0 = T[t, _TET_FACES[c, 0]]
        _tri_normal(pts, f0, T[t, _TET_FACES[c, 1]], T[t, _TET_FACES[c, 2]], fn)
        nrm[i, 0] = fn[0]
        nrm[i, 1] = fn[1]
        nrm[i, 2] = fn[2]
        off[i] = fn[0] * pts[f0, 0] + fn[1] * pts[f0, 1] + fn[2] * pts[f0, 2]
        for j in range(4):
            w = T[t, j]
            d2 = (pts[w, 0] - pts[a, 0]) ** 2 + (pts[w, 1] - pts[a, 1]) ** 2 + (pts[w, 2] - pts[a, 2]) ** 2
            if d2 > reach2:
                reach2 = d2
    return vol_star, reach2


@njit(cache=True, _nrt=False)
def _star_boundary(bf, pts, n_old, area_old):
    """Outward normals (2 x area) and areas of a's boundary faces; returns their total area."""
    area_sum = 0.0
    for f in range(bf.shape[0]):
        _tri_normal(pts, bf[f, 0], bf[f, 1], bf[f, 2], n_old[f])
        area_old[f] = 0.5 * np.sqrt(n_old[f, 0] ** 2 + n_old[f, 1] ** 2 + n_old[f, 2] ** 2)
        area_sum += area_old[f]
    return area_sum


@njit(cache=True, _nrt=False)
def _star_sample_count(st, tp_count):
    """Number of sample points listed in the star's tets."""
    npt = 0
    for i in range(st.shape[0]):
        npt += tp_count[st[i] >> 2]
    return npt


@njit(cache=True, _nrt=False)
def _point_error(pdat, p, val):
    """Sample point p's weighted squared error against the interpolant ``val`` of a positive tet
    (from :func:`_tet_planes`; ``pdat[p]``: the point's row)."""
    f = val[0] * pdat[p, 0] + val[1] * pdat[p, 1] + val[2] * pdat[p, 2] + val[3]
    return pdat[p, 4] * (pdat[p, 3] - f) ** 2


@njit(cache=True, nogil=True)
def _set_point_errors(T, pts, dens, pdat, tp_head, tp_count):
    """``pdat[p, 5]`` of every listed point: its error in its tet (:func:`_point_error`; 0.0 in a
    flat tet), the cache :func:`_star_samples` sums."""
    lam = np.empty((4, 4))
    val = np.empty(4)
    q = np.empty(4, np.int64)
    for t in range(tp_head.shape[0]):
        if tp_count[t] == 0:
            continue
        for j in range(4):
            q[j] = T[t, j]
        ok = _tet_planes(pts, dens, q, lam, val)
        for p in range(tp_head[t], tp_head[t] + tp_count[t]):
            pdat[p, 5] = _point_error(pdat, p, val) if ok else 0.0


@njit(cache=True, _nrt=False)
def _star_samples(st, pdat, tp_head, tp_count, stride, p_id, p_k):
    """Every stride-th sample point of the star (``p_id``) with its star tet (``p_k``); returns the
    sum of their weighted squared errors against the current interpolant, in list order.

    The errors are the ones cached in ``pdat[:, 5]`` where each point got its tet (set-up,
    :func:`_reassign_points`): a point's tet only changes (its vertices relabelled) in a merge
    that moves every point of it, so the cache is always the error in the tet as it is now,
    computed by the same expression from the same planes. A flat tet's points hold 0.0, which
    adds nothing to ``e_old`` (>= +0.0) bit for bit, as skipping them did."""
    e_old = 0.0
    npt = 0
    skip = 0  # the points of the next tets to pass before the next one taken
    for i in range(st.shape[0]):
        t = st[i] >> 2
        c = tp_count[t]
        j = skip
        while j < c:  # a tet's points are rows tp_head[t] .. + c - 1, in list order
            p = tp_head[t] + j
            p_id[npt] = p
            p_k[npt] = i
            e_old += pdat[p, 5]
            npt += 1
            j += stride
        skip = j - c
    return e_old


@njit(cache=True, _nrt=False)
def _new_volumes(b, st, T, pts, vol_old, nrm, off, fast_ok, v6n, q):
    """Legality of the volumes after a -> b: every tet of a's star without b stays positive (or
    the input's flat tets stay flat). Fills ``v6n`` (6 x new volume) of the surviving tets and
    returns the number of tets the merge collapses, or -1 when a tet would flatten or invert."""
    n_col = 0
    pbx = pts[b, 0]
    pby = pts[b, 1]
    pbz = pts[b, 2]
    for k in range(st.shape[0]):
        t = st[k] >> 2
        if _contains(T, t, b):
            n_col += 1
            continue
        v6 = off[k] - (nrm[k, 0] * pbx + nrm[k, 1] * pby + nrm[k, 2] * pbz)
        if not v6 > fast_ok:
            # near the limit: decide with the exact evaluation order of signed_volumes
            c = st[k] & 3
            for j in range(4):
                q[j] = T[t, j]
            q[c] = b
            v6 = _orient6(pts, q[0], q[1], q[2], q[3])
            old = vol_old[k]
            if old == 0.0:
                good = v6 == 0.0 or v6 > VOLUME_EPS * _max_edge2(pts, q) ** 1.5
            else:
                good = v6 > VOLUME_EPS * _max_edge2(pts, q) ** 1.5 or (v6 >= old and v6 > 0.0)
            if not good:
                return -1
        v6n[k] = v6
    return n_col


@njit(cache=True, _nrt=False)
def _mass_error(b, st, T, dens, mass_old, dsum, v6n):
    """The paper's density error: sum over a's tets of |mass after - mass before| (a collapsed tet
    loses all its mass)."""
    dm = 0.0
    for k in range(st.shape[0]):
        if _contains(T, st[k] >> 2, b):
            dm += abs(mass_old[k])
        else:
            dm += abs(v6n[k] / 6.0 * (dsum[k] + dens[b]) * 0.25 - mass_old[k])
    return dm


@njit(cache=True, _nrt=False)
def _interp_deviation(a, b, st, T, pts, dens, v6n, q, vout):
    """|value of a - the new mesh's interpolant at a's position|: in the new tet containing it (the
    smallest deviation if several do, which only happens on shared faces or at coincident points),
    else in the one it is nearest outside of."""
    best_lo = -1e300
    dev_out = abs(dens[a] - dens[b])
    dev_in = -1.0
    for k in range(st.shape[0]):
        t = st[k] >> 2
        if _contains(T, t, b) or v6n[k] <= 0.0:
            continue
        for j in range(4):
            q[j] = T[t, j]
        q[st[k] & 3] = b
        _value_at(pts, dens, q, v6n[k], pts[a, 0], pts[a, 1], pts[a, 2], vout)
        if vout[0] >= 0.0:
            dev = abs(dens[a] - vout[1])
            if dev_in < 0.0 or dev < dev_in:
                dev_in = dev
        else:
            dev = abs(dens[a] - vout[1])
            if vout[0] > best_lo or (vout[0] == best_lo and dev < dev_out):
                best_lo = vout[0]
                dev_out = dev
    return dev_in if dev_in >= 0.0 else dev_out


@njit(cache=True, _nrt=False)
def _boundary_ok(a, b, bf, n_old, area_old, pts, area_new, n_new):
    """Legality on the boundary: no face of a's that survives turns by 90 degrees or more (the
    paper's negative area). Fills ``area_new`` (-1 for the faces that collapse)."""
    for f in range(bf.shape[0]):
        if bf[f, 0] == b or bf[f, 1] == b or bf[f, 2] == b:
            area_new[f] = -1.0  # collapses
            continue
        x0 = b if bf[f, 0] == a else bf[f, 0]
        x1 = b if bf[f, 1] == a else bf[f, 1]
        x2 = b if bf[f, 2] == a else bf[f, 2]
        _tri_normal(pts, x0, x1, x2, n_new)
        ln = np.sqrt(n_new[0] ** 2 + n_new[1] ** 2 + n_new[2] ** 2)
        dot = n_new[0] * n_old[f, 0] + n_new[1] * n_old[f, 1] + n_new[2] * n_old[f, 2]
        if not (dot > NORMAL_EPS * ln * 2.0 * area_old[f]):
            return False
        area_new[f] = 0.5 * ln
    return True


@njit(cache=True, _nrt=False)
def _swept_volume(b, bf, n_old, pts):
    """Volume swept by a's boundary faces moving a onto b (the tet between each old face and b)."""
    swept = 0.0
    for f in range(bf.shape[0]):
        if bf[f, 0] == b or bf[f, 1] == b or bf[f, 2] == b:
            continue
        swept += abs(n_old[f, 0] * (pts[b, 0] - pts[bf[f, 0], 0]) + n_old[f, 1] * (pts[b, 1] - pts[bf[f, 0], 1])
                     + n_old[f, 2] * (pts[b, 2] - pts[bf[f, 0], 2])) / 6.0
    return swept


@njit(cache=True, _nrt=False)
def _area_error(a, b, bf, area_old, area_new, area_sum):
    """The paper's geometry error: each new face against every old face sharing an edge with it,
    weighted by the old face's share of the affected area."""
    ge = 0.0
    nf = bf.shape[0]
    for f in range(nf):
        if area_new[f] < 0.0:
            continue
        for g in range(nf):
            shared = 0
            for j in range(3):
                w = b if bf[f, j] == a else bf[f, j]
                if w == bf[g, 0] or w == bf[g, 1] or w == bf[g, 2]:
                    shared += 1
            if shared >= 2 and area_sum > 0.0:
                ge += abs(area_new[f] - area_old[g]) * area_old[g] / area_sum
    return ge


@njit(cache=True, _nrt=False)
def _new_star_planes(b, st, T, pts, dens, s_ok, s_lam, s_val, q):
    """Tet planes (:func:`_tet_planes`) of the new star after a -> b; ``s_ok[k]``: tet k survives positive."""
    for k in range(st.shape[0]):
        t = st[k] >> 2
        s_ok[k] = False
        if not _contains(T, t, b):
            for j in range(4):
                q[j] = T[t, j]
            q[st[k] & 3] = b
            s_ok[k] = _tet_planes(pts, dens, q, s_lam[k], s_val[k])


@njit(cache=True, _nrt=False)
def _sample_sum(se, lo, hi, b, pts, dens, pdat, p_id, p_k, s_ok, s_lam, s_val):
    """``se`` plus the weighted squared errors after a -> b at sample points ``lo:hi``, added one
    by one in order (so a sum taken in pieces is the sum taken at once, bit for bit)."""
    for ip in range(lo, hi):
        p = p_id[ip]
        f = _new_value(p, p_k[ip], pdat, s_ok, s_lam, s_val, dens[b])
        se += pdat[p, 4] * (pdat[p, 3] - f) ** 2
    return se


@njit(cache=True, _nrt=False)
def _sample_error(b, st, T, pts, dens, pdat, p_id, p_k, s_ok, s_lam, s_val, q):
    """Sum of the weighted squared errors at the sample points after a -> b (``p_id``, ``p_k``
    from :func:`_star_samples`; the other arrays are scratch)."""
    _new_star_planes(b, st, T, pts, dens, s_ok, s_lam, s_val, q)
    return _sample_sum(0.0, 0, p_id.shape[0], b, pts, dens, pdat, p_id, p_k, s_ok, s_lam, s_val)


@njit(cache=True, _nrt=False)
def _total_error(dm_w, di, ge_w, swept_w, qe_w, se, n_col, power):
    """The merge error from its weighted terms, per collapsed tet (to a power): the comparison
    that matters is at equal tet counts."""
    return (dm_w + di + ge_w + swept_w + qe_w + se) / float(n_col) ** power


@njit(cache=True)
def _star_context(a, st, T, nbr, pts, dens, isb, params, pdat, tp_head, tp_count, fbuf, ibuf, fo, io):
    """Everything about a's star that every candidate merge of a shares, and the scratch arrays of
    one evaluation, as one tuple (see the names unpacked in :func:`_candidate_terms`), all taken
    from ``fbuf`` (from offset ``fo`` on) and ``ibuf`` (from ``io``) where they fit (see
    :func:`_take`). Returns (the tuple, the offset in ``ibuf`` after it)."""
    ns = st.shape[0]
    vol_old, fo = _take(fbuf, fo, ns)
    mass_old, fo = _take(fbuf, fo, ns)
    dsum, fo = _take(fbuf, fo, ns)
    nrm_flat, fo = _take(fbuf, fo, 3 * ns)
    nrm = nrm_flat.reshape((ns, 3))
    off, fo = _take(fbuf, fo, ns)
    fn, fo = _take(fbuf, fo, 3)
    vol_star, reach2 = _star_volumes(a, st, T, pts, dens, vol_old, mass_old, dsum, nrm, off, fn)
    # every new tet's vertices lie within sqrt(reach2) of a, so its edges are <= 2 sqrt(reach2):
    # a value above twice this bound is safely positive whatever the rounding
    fast_ok = 2.0 * VOLUME_EPS * (4.0 * reach2) ** 1.5
    if isb[a]:
        bf, io = _boundary_faces_into(st, T, nbr, ibuf, io)
    else:
        bf_flat, io = _take(ibuf, io, 0)
        bf = bf_flat.reshape((0, 3))
    nbf = bf.shape[0]
    n_old_flat, fo = _take(fbuf, fo, 3 * nbf)
    n_old = n_old_flat.reshape((nbf, 3))
    area_old, fo = _take(fbuf, fo, nbf)
    area_sum = _star_boundary(bf, pts, n_old, area_old)
    # the sample points in a's star (only they see the interpolant change) and their squared error
    # now; late on, stars hold many points: every stride-th one stands for stride points
    npt = _star_sample_count(st, tp_count) if params[P_WS] > 0.0 else 0
    max_s = max(1, int(params[P_MAXS]))
    stride = (npt + max_s - 1) // max_s if npt > max_s else 1
    p_id, io = _take(ibuf, io, (npt + stride - 1) // stride)
    p_k, io = _take(ibuf, io, p_id.shape[0])
    s_ok, io = _take(ibuf, io, ns)  # 0 / 1: new tet k survives positive (set by _new_star_planes)
    q, io = _take(ibuf, io, 4)
    s_lam_flat, fo = _take(fbuf, fo, 16 * ns)
    s_lam = s_lam_flat.reshape((ns, 4, 4))
    s_val_flat, fo = _take(fbuf, fo, 4 * ns)
    s_val = s_val_flat.reshape((ns, 4))
    v6n, fo = _take(fbuf, fo, ns)
    vout, fo = _take(fbuf, fo, 2)
    n_new, fo = _take(fbuf, fo, 3)
    area_new, fo = _take(fbuf, fo, nbf)
    e_old = 0.0
    if npt > 0:
        e_old = _star_samples(st, pdat, tp_head, tp_count, stride, p_id, p_k)
    return (vol_old, mass_old, dsum, nrm, off, vol_star, fast_ok, bf, n_old, area_old, area_sum, p_id, p_k,
            stride, e_old, v6n, vout, q, n_new, area_new, s_ok, s_lam, s_val), io


@njit(cache=True, _nrt=False)
def _exact_terms(a, b, st, T, pts, dens, params, pdat, ctx):
    """The two terms left out of the bound: (interpolation term, sampled error term), weighted."""
    (vol_old, mass_old, dsum, nrm, off, vol_star, fast_ok, bf, n_old, area_old, area_sum, p_id, p_k,
     stride, e_old, v6n, vout, q, n_new, area_new, s_ok, s_lam, s_val) = ctx
    di = 0.0
    if params[P_WI] > 0.0:
        f_dev = _interp_deviation(a, b, st, T, pts, dens, v6n, q, vout)
        di = params[P_WI] * f_dev * f_dev * vol_star
    se = 0.0
    if p_id.shape[0] > 0:
        se = _sample_error(b, st, T, pts, dens, pdat, p_id, p_k, s_ok, s_lam, s_val, q)
        se = params[P_WS] * stride * (se - e_old)
    return di, se


@njit(cache=True, _nrt=False)
def _candidate_terms(a, st, T, pts, dens, isb, pinned, params, quad, u4, pdat, mark, counters, ctx, cand_out,
                     err_out, terms_out, exact):
    """Every geometrically legal merge a -> b (b a neighbour of a): its target in ``cand_out``,
    its weighted mass, area, swept volume and quadric terms and collapsed-tet count in
    ``terms_out``, and in ``err_out`` its error (``exact``) or a lower bound of it (the
    interpolation term, >= 0, left out; the sampled error at its most negative, every point's
    new error 0). Returns the number of candidates. Legality here covers volumes, boundary
    orientation and the boundary-into-interior rule; the link condition is the caller's."""
    (vol_old, mass_old, dsum, nrm, off, vol_star, fast_ok, bf, n_old, area_old, area_sum, p_id, p_k,
     stride, e_old, v6n, vout, q, n_new, area_new, s_ok, s_lam, s_val) = ctx
    se_low = params[P_WS] * stride * (0.0 - e_old) if p_id.shape[0] > 0 else 0.0
    a_bnd = isb[a]
    stamp = _next_stamp(counters)
    mark[a] = stamp
    nc = 0
    for i in range(st.shape[0]):
        t0 = st[i] >> 2
        for j0 in range(4):
            b = T[t0, j0]
            if mark[b] == stamp:
                continue
            mark[b] = stamp
            if (pinned[b] != 0 and ((pinned[b] & PIN_NO_TARGET) != 0 or a_bnd)) or (a_bnd and not isb[b]):
                continue
            counters[C_EVALS] += 1
            n_col = _new_volumes(b, st, T, pts, vol_old, nrm, off, fast_ok, v6n, q)
            if n_col < 0:
                continue
            if not _boundary_ok(a, b, bf, n_old, area_old, pts, area_new, n_new):
                continue
            terms_out[nc, 0] = params[P_WD] * _mass_error(b, st, T, dens, mass_old, dsum, v6n)
            terms_out[nc, 1] = params[P_WG] * _area_error(a, b, bf, area_old, area_new, area_sum)
            terms_out[nc, 2] = params[P_WV] * _swept_volume(b, bf, n_old, pts)
            terms_out[nc, 3] = params[P_WQ] * (_quadric_at(quad, u4, a, b) if params[P_WQ] > 0.0 else 0.0)
            terms_out[nc, 4] = n_col
            di, se = _exact_terms(a, b, st, T, pts, dens, params, pdat, ctx) if exact else (0.0, se_low)
            err_out[nc] = _total_error(terms_out[nc, 0], di, terms_out[nc, 1], terms_out[nc, 2], terms_out[nc, 3],
                                       se, n_col, params[P_NCP])
            cand_out[nc] = b
            nc += 1
    return nc


@njit(cache=True, _nrt=False)
def _loses(e, b, best_e, best_b, vkey):
    """True when (e, b) cannot be the best against the best so far (``best_b`` < 0: none yet);
    equal errors go to the smaller ``vkey`` (the caller's vertex id, see :func:`_run`)."""
    return best_b >= 0 and (e > best_e or (e == best_e and vkey[b] > vkey[best_b]))


# Sample points summed between two checks of the running lower bound in _candidate_exact.
_BOUND_EVERY = 32


@njit(cache=True, _nrt=False)
def _candidate_exact(a, b, terms, st, T, pts, dens, params, pdat, ctx, best_b, best_e, counters, vkey):
    """(exact error, True) of candidate b of :func:`_candidate_terms` (``terms`` its row), or
    (0, False) as soon as a lower bound of it loses against (``best_e``, ``best_b``).

    The bound is the error with the sample points not yet summed at a new error of 0: the
    sampled sum only grows point by point, and every step after it (subtracting the old sum,
    the positive weights, the fixed order of :func:`_total_error`) is monotone in it under
    rounding, so the bound never exceeds the exact error and the choice is the one of computing
    every error in full, bit for bit.
    """
    (vol_old, mass_old, dsum, nrm, off, vol_star, fast_ok, bf, n_old, area_old, area_sum, p_id, p_k,
     stride, e_old, v6n, vout, q, n_new, area_new, s_ok, s_lam, s_val) = ctx
    n_col = int(terms[4])
    counters[C_EXACT] += 1
    power = params[P_NCP]
    _new_volumes(b, st, T, pts, vol_old, nrm, off, fast_ok, v6n, q)  # v6n, for the interpolant
    di = 0.0
    if params[P_WI] > 0.0:
        f_dev = _interp_deviation(a, b, st, T, pts, dens, v6n, q, vout)
        di = params[P_WI] * f_dev * f_dev * vol_star
    se = 0.0
    npt = p_id.shape[0]
    if npt > 0:
        w = params[P_WS] * stride
        if _loses(_total_error(terms[0], di, terms[1], terms[2], terms[3], w * (0.0 - e_old), n_col, power),
                  b, best_e, best_b, vkey):
            counters[C_PRUNED] += 1
            return 0.0, False
        _new_star_planes(b, st, T, pts, dens, s_ok, s_lam, s_val, q)
        acc = 0.0
        for lo in range(0, npt, _BOUND_EVERY):
            hi = min(npt, lo + _BOUND_EVERY)
            acc = _sample_sum(acc, lo, hi, b, pts, dens, pdat, p_id, p_k, s_ok, s_lam, s_val)
            counters[C_POINTS] += hi - lo
            if hi < npt and _loses(_total_error(terms[0], di, terms[1], terms[2], terms[3], w * (acc - e_old), n_col,
                                                power), b, best_e, best_b, vkey):
                counters[C_PRUNED] += 1
                return 0.0, False
        se = w * (acc - e_old)
    return _total_error(terms[0], di, terms[1], terms[2], terms[3], se, n_col, power), True


@njit(cache=True)
def _candidate_errors(a, st, T, nbr, pts, dens, isb, pinned, params, quad, u4, mark, counters, cand_out, err_out,
                      pdat, tp_head, tp_count):
    """Error of every geometrically legal merge a -> b (b a neighbour of a): fills the outputs.

    Returns the number of candidates. Legality here covers volumes, boundary orientation and the
    boundary-into-interior rule; the link condition is checked by the caller, best first.
    """
    ctx, _ = _star_context(a, st, T, nbr, pts, dens, isb, params, pdat, tp_head, tp_count, np.empty(0),
                           np.empty(0, np.int64), 0, 0)
    terms = np.empty((cand_out.shape[0], 5))
    return _candidate_terms(a, st, T, pts, dens, isb, pinned, params, quad, u4, pdat, mark, counters, ctx, cand_out,
                            err_out, terms, True)


@njit(cache=True)
def _evaluate(a, T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4, vkey, mark, mark_b, mark_ab,
              counters, pdat, tp_head, tp_count, fbuf, ibuf):
    """Best legal merge of a: (target, error), or (-1, 0) when a has none.

    The best is the smallest (error, ``vkey`` of the target) among the candidates that pass the link
    condition. Branch and bound: candidates are visited by their lower bound (the cheap terms),
    and the expensive ones (interpolation, sample points) are computed only while the bound can
    still beat the best found so far: the same choice as computing every error, for a fraction
    of the cost. ``fbuf``, ``ibuf``: this thread's scratch (see :func:`_take`).
    """
    st = _star_into(a, head, nxt, T, alive, ibuf)
    if st.shape[0] == 0 or pinned[a]:
        return -1, 0.0
    cap = 3 * st.shape[0] + 1
    cand, io = _take(ibuf, st.shape[0], cap)
    order, io = _take(ibuf, io, cap)
    low, fo = _take(fbuf, 0, cap)
    terms_flat, fo = _take(fbuf, fo, 5 * cap)
    terms = terms_flat.reshape((cap, 5))
    ctx, io = _star_context(a, st, T, nbr, pts, dens, isb, params, pdat, tp_head, tp_count, fbuf, ibuf, fo,
                            io)
    link_buf = ibuf[min(io, ibuf.shape[0]):]
    nc = _candidate_terms(a, st, T, pts, dens, isb, pinned, params, quad, u4, pdat, mark, counters, ctx, cand, low,
                          terms, False)
    if nc == 0:
        return -1, 0.0
    # by bound, ties by target (caller's id), so the result does not depend on list order or on
    # the internal numbering: an insertion sort on (bound, key) (a dozen candidates: np.argsort's
    # allocation costs more than the sort)
    for x in range(nc):
        y = x
        while y > 0 and (low[order[y - 1]] > low[x]
                         or (low[order[y - 1]] == low[x] and vkey[cand[order[y - 1]]] > vkey[cand[x]])):
            order[y] = order[y - 1]
            y -= 1
        order[y] = x
    best_b = -1
    best_e = 0.0
    for x in range(nc):
        k = order[x]
        b = cand[k]
        if _loses(low[k], b, best_e, best_b, vkey):
            return best_b, best_e
        e, whole = _candidate_exact(a, b, terms[k], st, T, pts, dens, params, pdat, ctx, best_b, best_e, counters,
                                    vkey)
        if not whole or _loses(e, b, best_e, best_b, vkey):
            continue
        counters[C_LINK] += 1
        if _link_ok_buf(a, b, st, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, counters, link_buf):
            best_b = b
            best_e = e
    return best_b, best_e


# -- a binary min-heap over (error, vertex), at most one entry per vertex ---------------------------
# ``h_pos[v]``: the index of v's entry, -1 if none. A vertex's new entry replaces its old one, and a
# vertex re-evaluated without a legal merge loses it: every entry is current (``h_ver``, the
# vertex's version when it was made, stays for the callers' checks). The keys (error, ``vkey``)
# of distinct vertices are distinct and the errors are never NaN, so the entries come out in
# one order whatever the heap's shape: the order of a heap that kept the superseded entries
# and skipped them on their way out (the one before), with no such entries to pop.
@njit(cache=True, _nrt=False)
def _heap_less(h_err, h_v, vkey, i, j):
    """(error, ``vkey`` of the vertex) of entry i below entry j's (the key only read on equal errors)."""
    return h_err[i] < h_err[j] or (h_err[i] == h_err[j] and vkey[h_v[i]] < vkey[h_v[j]])


@njit(cache=True, _nrt=False)
def _heap_swap(h_err, h_v, h_b, h_ver, h_pos, i, j):
    h_err[i], h_err[j] = h_err[j], h_err[i]
    h_v[i], h_v[j] = h_v[j], h_v[i]
    h_b[i], h_b[j] = h_b[j], h_b[i]
    h_ver[i], h_ver[j] = h_ver[j], h_ver[i]
    h_pos[h_v[i]] = i
    h_pos[h_v[j]] = j


@njit(cache=True, _nrt=False)
def _sift_up(h_err, h_v, h_b, h_ver, h_pos, vkey, i):
    while i > 0:
        p = (i - 1) >> 1
        if _heap_less(h_err, h_v, vkey, i, p):
            _heap_swap(h_err, h_v, h_b, h_ver, h_pos, i, p)
            i = p
        else:
            break
    return i


@njit(cache=True, _nrt=False)
def _heap_push(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, e, v, b, ver):
    """v's entry (error e, target b, version ver), replacing the one v has."""
    i = h_pos[v]
    if i < 0:
        i = counters[C_HEAP]
        counters[C_HEAP] = i + 1
        h_pos[v] = i
    h_err[i] = e
    h_v[i] = v
    h_b[i] = b
    h_ver[i] = ver
    i = _sift_up(h_err, h_v, h_b, h_ver, h_pos, vkey, i)
    _sift_down(h_err, h_v, h_b, h_ver, h_pos, vkey, i, counters[C_HEAP])


@njit(cache=True, _nrt=False)
def _heap_remove(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, v):
    """Drop v's entry, if it has one."""
    i = h_pos[v]
    if i < 0:
        return
    n = counters[C_HEAP] - 1
    _heap_swap(h_err, h_v, h_b, h_ver, h_pos, i, n)
    h_pos[v] = -1
    counters[C_HEAP] = n
    if i < n:
        i = _sift_up(h_err, h_v, h_b, h_ver, h_pos, vkey, i)
        _sift_down(h_err, h_v, h_b, h_ver, h_pos, vkey, i, n)


@njit(cache=True, _nrt=False)
def _sift_down(h_err, h_v, h_b, h_ver, h_pos, vkey, i, n):
    while True:
        l = 2 * i + 1
        if l >= n:
            break
        m = l
        if l + 1 < n and _heap_less(h_err, h_v, vkey, l + 1, l):
            m = l + 1
        if _heap_less(h_err, h_v, vkey, m, i):
            _heap_swap(h_err, h_v, h_b, h_ver, h_pos, i, m)
            i = m
        else:
            break


@njit(cache=True, _nrt=False)
def _heap_pop(h_err, h_v, h_b, h_ver, h_pos, vkey, counters):
    n = counters[C_HEAP] - 1
    e, v, b, ver = h_err[0], h_v[0], h_b[0], h_ver[0]
    _heap_swap(h_err, h_v, h_b, h_ver, h_pos, 0, n)
    h_pos[v] = -1
    counters[C_HEAP] = n
    _sift_down(h_err, h_v, h_b, h_ver, h_pos, vkey, 0, n)
    return e, v, b, ver


@njit(cache=True, _nrt=False)
def _apply_merge(a, b, st_a, T, alive, nbr, head, nxt):
    """Merge a into b: collapse the tets of edge ab (gluing their outer neighbours), relabel the rest."""
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        c = st_a[i] & 3
        cb = -1
        for j in range(4):
            if T[t, j] == b:
                cb = j
        if cb < 0:
            continue
        n_a = nbr[t, c]  # across the face without a (contains b): survives
        n_b = nbr[t, cb]  # across the face without b (contains a): survives, becomes that face
        if n_a >= 0:
            for j in range(4):
                if nbr[n_a, j] == t:
                    nbr[n_a, j] = n_b
        if n_b >= 0:
            for j in range(4):
                if nbr[n_b, j] == t:
                    nbr[n_b, j] = n_a
        alive[t] = False
    for i in range(st_a.shape[0]):
        t = st_a[i] >> 2
        if alive[t]:
            T[t, st_a[i] & 3] = b
    _splice_incidence(a, b, head, nxt)


@njit(cache=True, _nrt=False)
def _splice_incidence(a, b, head, nxt):
    """Vertex a's incidence list put in front of b's (a's left empty): a merged into b."""
    s = head[a]
    if s >= 0:
        while nxt[s] >= 0:
            s = nxt[s]
        nxt[s] = head[b]
        head[b] = head[a]
        head[a] = -1


@njit(cache=True)
def _reassign_points(a, st_a, T, alive, pts, dens, pdat, vw, prow, tp_head, tp_count, counters):
    """After merging a: a and every point listed in a's former star go to the first live tet of
    the new star (star order) that contains them, else the one they are nearest to (largest
    smallest barycentric coordinate of :func:`_value_at`, the first of equals; as :func:`_new_value`).

    Containment is decided by :func:`_value_at`'s determinants; the tet planes (four dot products
    per point) settle it first wherever they are farther from 0 than any rounding of either could
    reach, so the determinants only run for points within rounding of a face (or in slivers).

    Every tet of the new star gets its points as a new run of rows at the top (in the order a list
    that each point was pushed on in turn would have: the last first), with their errors in it
    (``pdat[:, 5]``); the old rows of the star's tets are left behind (:func:`_compact_points`
    drops them when the rows run out).
    """
    ns = st_a.shape[0]
    cnt = 1
    for i in range(ns):
        cnt += tp_count[st_a[i] >> 2]
    counters[C_MOVED] += cnt
    # the points in turn: a first (it becomes a sample point), then every star tet's in list order
    rows = np.empty((cnt, pdat.shape[1]))
    orig = np.empty(cnt, np.int32)
    rows[0, 0] = pts[a, 0]
    rows[0, 1] = pts[a, 1]
    rows[0, 2] = pts[a, 2]
    rows[0, 3] = dens[a]
    rows[0, 4] = vw[a]
    rows[0, 5] = 0.0
    orig[0] = a
    cnt = 1
    for i in range(ns):
        t = st_a[i] >> 2
        for p in range(tp_head[t], tp_head[t] + tp_count[t]):
            for j in range(pdat.shape[1]):
                rows[cnt, j] = pdat[p, j]
            orig[cnt] = prow[p, 0]
            cnt += 1
        tp_head[t] = -1
        tp_count[t] = 0
    # the extent of every coordinate involved (star vertices and points): bounds the rounding
    lo3 = np.full(3, 1e300)
    hi3 = np.full(3, -1e300)
    for i in range(ns):
        t = st_a[i] >> 2
        for j in range(4):
            for d in range(3):
                lo3[d] = min(lo3[d], pts[T[t, j], d])
                hi3[d] = max(hi3[d], pts[T[t, j], d])
    for ip in range(cnt):
        for d in range(3):
            lo3[d] = min(lo3[d], rows[ip, d])
            hi3[d] = max(hi3[d], rows[ip, d])
    ext3 = ((hi3[0] - lo3[0]) ** 2 + (hi3[1] - lo3[1]) ** 2 + (hi3[2] - lo3[2]) ** 2) ** 1.5
    v6s = np.zeros(ns)
    usable = np.zeros(ns, np.bool_)
    margin = np.empty(ns)
    lam = np.empty((ns, 4, 4))
    val = np.empty((ns, 4))
    q = np.empty(4, np.int64)
    for i in range(ns):
        t = st_a[i] >> 2
        if not alive[t]:
            continue
        for j in range(4):
            q[j] = T[t, j]
        v6 = _orient6(pts, q[0], q[1], q[2], q[3])
        v6s[i] = v6
        if v6 > 0.0:
            usable[i] = _tet_planes(pts, dens, q, lam[i], val[i])
            c = ext3 / v6
            margin[i] = 1e-10 * c * (1.0 + c)
    vout = np.empty(2)
    where = np.empty(cnt, np.int64)  # the star tet (index) each point goes to, -1: dropped
    per = np.zeros(ns, np.int64)
    n_keep = 0
    for ip in range(cnt):
        x = rows[ip, 0]
        y = rows[ip, 1]
        z = rows[ip, 2]
        best = -1
        for i in range(ns):
            if not usable[i]:
                continue
            low = 1e300
            for j in range(4):
                lj = lam[i, j, 0] * x + lam[i, j, 1] * y + lam[i, j, 2] * z + lam[i, j, 3]
                if lj < low:
                    low = lj
            if low < -margin[i]:
                continue
            t = st_a[i] >> 2
            if low > margin[i]:
                best = i
                break
            for j in range(4):
                q[j] = T[t, j]
            _value_at(pts, dens, q, v6s[i], x, y, z, vout)
            if vout[0] >= 0.0:
                best = i
                break
        if best < 0:
            # outside every tet: the nearest, by the determinants
            best_lo = -1e300
            for i in range(ns):
                t = st_a[i] >> 2
                if not alive[t] or not v6s[i] > 0.0:
                    continue
                for j in range(4):
                    q[j] = T[t, j]
                _value_at(pts, dens, q, v6s[i], x, y, z, vout)
                if vout[0] > best_lo:
                    best_lo = vout[0]
                    best = i
        where[ip] = best
        if best >= 0:  # else no tet of a's star is left (or all are flat): the point is dropped
            # its error in the new tet, for _star_samples (usable[best]: alive with v6 > 0)
            rows[ip, 5] = _point_error(rows, ip, val[best])
            per[best] += 1
            n_keep += 1
    if counters[C_PTOP] + n_keep > pdat.shape[0]:
        _compact_points(alive, pdat, prow, tp_head, tp_count, counters)
    top = counters[C_PTOP]
    for i in range(ns):
        if per[i] > 0:
            t = st_a[i] >> 2
            tp_head[t] = top
            tp_count[t] = per[i]
            top += per[i]
            per[i] = top  # filled from its end down: the last point to arrive comes first
    for ip in range(cnt):
        i = where[ip]
        if i >= 0:
            per[i] -= 1
            r = per[i]
            for j in range(pdat.shape[1]):
                pdat[r, j] = rows[ip, j]
            prow[r, 0] = orig[ip]
            prow[r, 1] = st_a[i] >> 2
    counters[C_PTOP] = top


@njit(cache=True)
def _compact_tets(T, alive, nbr, head, nxt, tp_head, tp_count, t_orig, prow, counters):
    """The live tets renumbered 0.. in their order (the dead ones dropped), as new arrays
    (T, nbr, nxt, tp_head, tp_count, t_orig); ``head`` and the point rows' tets (``prow[:, 1]``,
    -1 for a dead tet's) are rewritten in place. Every vertex's list
    keeps its live slots in their order (the dead ones are unlinked, as :func:`_tidy` would), so
    the merges that follow are the same; they walk fewer cache lines."""
    m = T.shape[0]
    new_id = np.full(m, -1, np.int32)
    k = 0
    for t in range(m):
        if alive[t]:
            new_id[t] = k
            k += 1
    T2 = np.empty((k, 4), np.int32)
    nbr2 = np.empty((k, 4), np.int32)
    tp_head2 = np.empty(k, np.int32)
    tp_count2 = np.empty(k, np.int32)
    t_orig2 = np.empty(k, t_orig.dtype)
    for t in range(m):
        u = new_id[t]
        if u < 0:
            continue
        for j in range(4):
            T2[u, j] = T[t, j]
            x = nbr[t, j]
            nbr2[u, j] = new_id[x] if x >= 0 else -1
        tp_head2[u] = tp_head[t]
        tp_count2[u] = tp_count[t]
        t_orig2[u] = t_orig[t]
    for r in range(counters[C_PTOP]):
        t = prow[r, 1]
        prow[r, 1] = new_id[t] if t >= 0 else -1
    nxt2 = np.full(4 * k, -1, np.int32)
    for v in range(head.shape[0]):
        last = -1
        s = head[v]
        head[v] = -1
        while s >= 0:
            t = s >> 2
            if alive[t] and T[t, s & 3] == v:
                s2 = 4 * new_id[t] + (s & 3)
                if last < 0:
                    head[v] = s2
                else:
                    nxt2[last] = s2
                last = s2
            s = nxt[s]
    return T2, nbr2, nxt2, tp_head2, tp_count2, t_orig2


@njit(cache=True)
def _compact_points(alive, pdat, prow, tp_head, tp_count, counters):
    """Slide the live runs of rows down from row 0, in row order (the rows left behind by the
    merges go; every list keeps its rows in order). Ids change, lists and their order do not.

    A row r is the start of a live run when its tet t = ``prow[r, 1]`` is alive and
    ``tp_head[t] == r``: the rows below the top are written once between two rewrites, so that run
    is the one written for t at r."""
    top = counters[C_PTOP]
    k = 0
    r = 0
    while r < top:
        t = prow[r, 1]
        if t < 0 or not alive[t] or tp_head[t] != r or tp_count[t] == 0:
            r += 1
            continue
        c = tp_count[t]
        if k != r:  # k < r: an ascending copy never overwrites a row it still has to read
            for i in range(c):
                for j in range(pdat.shape[1]):
                    pdat[k + i, j] = pdat[r + i, j]
                prow[k + i, 0] = prow[r + i, 0]
                prow[k + i, 1] = t
        tp_head[t] = k
        k += c
        r += c
    counters[C_PTOP] = k
    counters[C_REWRITES] += 1


@njit(cache=True, parallel=True)
def _evaluate_many(todo, n_todo, out_b, out_e, T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4,
                   vkey, marks, marks_b, marks_ab, tcount, pdat, tp_head, tp_count):
    """:func:`_evaluate` of ``todo[:n_todo]`` in parallel: every evaluation only reads the mesh
    (each thread stamps its own mark rows and uses its own scratch), so the results cannot depend on
    the scheduling."""
    fbufs = np.empty((marks.shape[0], _SCRATCH_F))
    ibufs = np.empty((marks.shape[0], _SCRATCH_I), np.int64)
    for i in prange(n_todo):
        tid = get_thread_id()
        b, e = _evaluate(todo[i], T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4, vkey, marks[tid],
                         marks_b[tid], marks_ab[tid], tcount[tid], pdat, tp_head, tp_count, fbufs[tid],
                         ibufs[tid])
        out_b[i] = b
        out_e[i] = e


@njit(cache=True, _nrt=False)
def _touches_target(st, T, lock_b, stamp):
    """Whether a vertex of the star ``st`` is the target of a merge of the current round."""
    for i in range(st.shape[0]):
        t = st[i] >> 2
        for j in range(4):
            if lock_b[T[t, j]] == stamp:
                return True
    return False


@njit(cache=True, _nrt=False)
def _set_aside(d_err, d_v, d_b, d_ver, n_def, e, a, b, v_a, ver):
    """Keep a blocked heap entry for the next round; returns the new count. Full: the stale
    entries are dropped first (the live ones, one per vertex at most, always fit)."""
    if n_def >= d_err.shape[0]:
        k = 0
        for i in range(n_def):
            if d_ver[i] == ver[d_v[i]]:
                d_err[k] = d_err[i]
                d_v[k] = d_v[i]
                d_b[k] = d_b[i]
                d_ver[k] = d_ver[i]
                k += 1
        n_def = k
    d_err[n_def] = e
    d_v[n_def] = a
    d_b[n_def] = b
    d_ver[n_def] = v_a
    return n_def + 1


@njit(cache=True, nogil=True)  # compress encodes the levels' meshes in a thread meanwhile
def _run(T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4, vkey, marks, marks_b, marks_ab, tcount,
         counters, ver, h_err, h_v, h_b, h_ver, h_pos, last_err, parent, rank, max_merges, pdat, tp_head, tp_count,
         vw, prow, lock, lock_b, round_stamp, max_blocked):
    """Greedy decimation until ``max_merges`` merges are done in total; True when no legal merge is left.

    ``marks*`` and ``tcount`` have one row per thread (stamps, evaluation counts); the sequential
    steps use row 0. ``vkey[v]`` is vertex v's id in the caller's numbering (the kernels work in a
    local one, see :class:`gatun_py.simplify.decimation.DecimationState`): every tie between equal
    errors (the heap, the best candidate) goes to the smaller key, so the merges do not depend on
    the local numbering.

    With ``round_stamp > 0`` the call is one round of independent merges (see
    :mod:`gatun_py.simplify.decimation`): a merge a -> b sets ``lock`` to ``round_stamp`` on every vertex
    of a's star (a and b included) and ``lock_b[b]``; a popped candidate a' -> b' is accepted only
    when neither a' nor b' is locked and no vertex of a''s star is a target of the round (checked
    with the star walk the link test makes anyway); otherwise the entry is set aside unchanged and
    goes back into the heap when the round ends: at ``max_merges``, when every candidate left
    is blocked, or when more than ``max_blocked`` entries were set aside (False either way). ``round_stamp == 0`` is the plain greedy order.
    """
    n = head.shape[0]
    # entries set aside in this round (at most one live entry per vertex, see _heap_push)
    d_err = np.empty(h_err.shape[0] if round_stamp > 0 else 0)
    d_v = np.empty(d_err.shape[0], np.int32)
    d_b = np.empty(d_err.shape[0], np.int32)
    d_ver = np.empty(d_err.shape[0], np.int32)
    n_def = 0
    mark = marks[0]
    mark_b = marks_b[0]
    mark_ab = marks_ab[0]
    tc = tcount[0]
    fbuf = np.empty(_SCRATCH_F)
    ibuf = np.empty(_SCRATCH_I, np.int64)
    # vertices to (re-)evaluate now: all of them at the start and in a sweep (in parallel), one
    # when a lazy re-evaluation comes up
    todo = np.empty(n, np.int64)
    out_b = np.empty(n, np.int64)
    out_e = np.empty(n)
    n_todo = 0
    sweeping = False
    if counters[C_STARTED] == 0:
        counters[C_STARTED] = 1
        for v in range(n):
            todo[v] = v
        n_todo = n
    while True:
        found = False
        if n_todo == 1:
            out_b[0], out_e[0] = _evaluate(todo[0], T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad,
                                           u4, vkey, mark, mark_b, mark_ab, tc, pdat, tp_head, tp_count, fbuf,
                                           ibuf)
        elif n_todo > 1:
            _evaluate_many(todo, n_todo, out_b, out_e, T, alive, nbr, head, nxt, pts, dens, isb, pinned, params,
                           quad, u4, vkey, marks, marks_b, marks_ab, tcount, pdat, tp_head, tp_count)
        # pushed in todo order, as evaluated one by one
        for i in range(n_todo):
            v = todo[i]
            ver[v] += 1
            if out_b[i] >= 0:
                last_err[v] = out_e[i]
                _heap_push(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, out_e[i], v, out_b[i], ver[v])
                found = True
            else:
                last_err[v] = -1.0
                _heap_remove(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, v)
        n_todo = 0
        if sweeping and not found:
            return True
        sweeping = False
        if counters[C_MERGES] >= max_merges or (n_def > 0 and (counters[C_HEAP] == 0 or n_def > max_blocked)):
            # the round is over: what it set aside goes back with its error unchanged
            for i in range(n_def):
                if d_ver[i] == ver[d_v[i]]:
                    _heap_push(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, d_err[i], d_v[i], d_b[i], d_ver[i])
            return False
        if counters[C_HEAP] == 0:
            # neighbourhoods two rings away from a merge may have become legal: look again
            counters[C_SWEEPS] += 1
            for v in range(n):
                if parent[v] == v:
                    todo[n_todo] = v
                    n_todo += 1
            sweeping = True
            continue
        e, a, b, v_a = _heap_pop(h_err, h_v, h_b, h_ver, h_pos, vkey, counters)
        tc[C_POPS] += 1
        if v_a != ver[a] or parent[a] != a:
            tc[C_STALE] += 1
            continue
        if round_stamp > 0 and (lock[a] == round_stamp or (b >= 0 and lock[b] == round_stamp)):
            n_def = _set_aside(d_err, d_v, d_b, d_ver, n_def, e, a, b, v_a, ver)
            continue
        if b < 0:
            tc[C_LAZY] += 1
            # a's neighbourhood changed since its last evaluation: evaluate now (lazily, so a vertex
            # touched by several merges before its turn is evaluated once)
            todo[0] = a
            n_todo = 1
            continue
        if parent[b] != b:
            continue
        st_a = _star(a, head, nxt, T, alive)
        if round_stamp > 0 and _touches_target(st_a, T, lock_b, round_stamp):
            n_def = _set_aside(d_err, d_v, d_b, d_ver, n_def, e, a, b, v_a, ver)
            continue
        tc[C_LINK] += 1
        # a's star is unchanged since the entry was made (that would have bumped its version),
        # but b's may have changed: check the link condition again
        if not _link_ok_buf(a, b, st_a, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, tc, ibuf):
            todo[0] = a
            n_todo = 1
            continue
        # the neighbourhood whose stars change: b and every vertex of a's star
        stamp = _next_stamp(tc)
        nb = np.empty(3 * st_a.shape[0] + 1, np.int64)
        k = 0
        for i in range(st_a.shape[0]):
            t = st_a[i] >> 2
            for j in range(4):
                w = T[t, j]
                if w != a and mark[w] != stamp:
                    mark[w] = stamp
                    nb[k] = w
                    k += 1
        _merge(a, b, st_a, nb[:k], T, alive, nbr, head, nxt, pts, dens, params, quad, pdat, vw, prow, tp_head,
               tp_count, counters)
        parent[a] = b
        rank[a] = counters[C_MERGES]
        counters[C_MERGES] += 1
        ver[a] += 1
        if round_stamp > 0:
            lock[a] = round_stamp
            lock_b[b] = round_stamp
            for i in range(k):
                lock[nb[i]] = round_stamp
        for i in range(k):
            w = nb[i]
            if parent[w] == w and not pinned[w]:
                ver[w] += 1
                _heap_push(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, max(e, last_err[w]), w, -1, ver[w])


@njit(cache=True, nogil=True)
def _run_rounds(T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4, vkey, marks, marks_b, marks_ab,
                tcount, counters, ver, h_err, h_v, h_b, h_ver, h_pos, last_err, parent, rank, pdat, tp_head, tp_count,
                vw, prow, lock, lock_b, ends, max_blocked, round_no, starts):
    """Rounds of :func:`_run` up to every ``ends[r]`` in turn (its ``max_blocked[r]``), in one call
    without the GIL: the round loop of :func:`gatun_py.simplify.decimation.decimate` (a return to
    Python between rounds waits for the GIL, which a numba encoder in another thread may hold for
    seconds). ``round_no[0]``: the last round's stamp (updated); the first merge count of every
    round goes to ``starts``. Returns (rounds started, True when no legal merge is left, the last
    index of ``ends`` worked on)."""
    k = 0
    for r in range(ends.shape[0]):
        while counters[C_MERGES] < ends[r]:
            starts[k] = counters[C_MERGES]
            k += 1
            round_no[0] += 1
            if _run(T, alive, nbr, head, nxt, pts, dens, isb, pinned, params, quad, u4, vkey, marks, marks_b, marks_ab,
                    tcount, counters, ver, h_err, h_v, h_b, h_ver, h_pos, last_err, parent, rank, ends[r], pdat,
                    tp_head, tp_count, vw, prow, lock, lock_b, round_no[0], max_blocked[r]):
                return k, True, r
    return k, False, ends.shape[0] - 1


@njit(cache=True)
def _merge(a, b, st_a, nb, T, alive, nbr, head, nxt, pts, dens, params, quad, pdat, vw, prow, tp_head, tp_count,
           counters):
    """Everything a merge a -> b changes: the tets, the lists of the vertices around it (``nb``:
    the vertices of a's star but a), the sample points and b's quadric."""
    _apply_merge(a, b, st_a, T, alive, nbr, head, nxt)
    # only the tets of edge ab died (the others keep their slots, relabelled a -> b), so only
    # the lists of their vertices hold dead slots: tidy those (a's is b's now). The dead tets are
    # listed first (a few of a's star), so the test per vertex looks at them only.
    dead = np.empty(st_a.shape[0], np.int64)
    n_dead = 0
    for k in range(st_a.shape[0]):
        t = st_a[k] >> 2
        if not alive[t]:
            dead[n_dead] = t
            n_dead += 1
    for i in range(nb.shape[0]):
        w = nb[i]
        for k in range(n_dead):
            if _contains(T, dead[k], w):
                _tidy(w, head, nxt, T, alive)
                break
    if params[P_WS] > 0.0:
        _reassign_points(a, st_a, T, alive, pts, dens, pdat, vw, prow, tp_head, tp_count, counters)
    for j in range(quad.shape[1]):
        quad[b, j] += quad[a, j]


# -- set-up: incidence, adjacency, vertex topology, sample points, quadrics (O(1) memory per tet
# beyond the state itself) -------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _incidence(T, n):
    """(head, nxt): every vertex's list of slots 4*t + c in increasing order."""
    return _incidence_in_order(T, n, np.arange(T.shape[0]))


@njit(cache=True, nogil=True)
def _incidence_in_order(T, n, t_order):
    """(head, nxt): every vertex's list of slots 4*t + c, the tets in the order ``t_order`` (a
    permutation of the tet ids) and a tet's corners in increasing order."""
    head = np.full(n, -1, np.int32)
    nxt = np.full(4 * T.shape[0], -1, np.int32)
    for i in range(t_order.shape[0] - 1, -1, -1):
        t = t_order[i]
        for c in range(3, -1, -1):
            s = 4 * t + c
            v = T[t, c]
            nxt[s] = head[v]
            head[v] = s
    return head, nxt


@njit(cache=True)
def _relabel_rows(src, rows, new_id):
    """``new_id[src[rows[i], j]]`` for every i, j (int32; -1 stays -1): a (k, 4) array of ids
    (tets' vertices, tets' neighbours) renumbered, its rows reordered."""
    out = np.empty((rows.shape[0], src.shape[1]), np.int32)
    for i in range(rows.shape[0]):
        r = rows[i]
        for j in range(src.shape[1]):
            x = src[r, j]
            out[i, j] = new_id[x] if x >= 0 else -1
    return out


@njit(cache=True, nogil=True)
def _face_neighbours(T, head, nxt):
    """nbr[t, k] = the tet across face k of t (the face opposite corner k), -1 on the boundary
    (found in the incidence list of the face's smallest vertex)."""
    m = T.shape[0]
    nbr = np.full((m, 4), -1, np.int32)
    for t in range(m):
        for k in range(4):
            if nbr[t, k] >= 0:
                continue
            x = T[t, _TET_FACES[k, 0]]
            y = T[t, _TET_FACES[k, 1]]
            z = T[t, _TET_FACES[k, 2]]
            s = head[min(x, min(y, z))]
            while s >= 0:
                u = s >> 2
                if u != t and _contains(T, u, x) and _contains(T, u, y) and _contains(T, u, z):
                    nbr[t, k] = u
                    for j in range(4):
                        w = T[u, j]
                        if w != x and w != y and w != z:
                            nbr[u, j] = t
                    break
                s = nxt[s]
    return nbr


@njit(cache=True, nogil=True)
def _vertex_topology(T, nbr, head, nxt, n):
    """(is_boundary, pinned): boundary vertices, and vertices whose neighbourhood is not a manifold
    (``PIN_ALL`` in ``pinned``, a uint8 array of ``PIN_*`` flags).

    A vertex is left alone when its link is not a sphere (interior) or a disk (boundary), judged by
    the link's Euler characteristic, or when it lies on a boundary edge not shared by exactly two
    boundary faces (edge- or vertex-touching parts). The link condition keeps every other vertex
    manifold, so this is decided once.
    """
    isb = np.zeros(n, np.bool_)
    pinned = np.zeros(n, np.uint8)
    for t in range(T.shape[0]):
        for k in range(4):
            if nbr[t, k] < 0:
                for j in range(3):
                    isb[T[t, _TET_FACES[k, j]]] = True
    seen = np.full(n, -1, np.int64)
    n_bf = np.zeros(n, np.int32)  # boundary faces at v containing the neighbour
    for v in range(n):
        if head[v] < 0:
            continue
        n_tets = 0
        n_faces = 0
        n_edges = 0
        s = head[v]
        while s >= 0:
            t = s >> 2
            c = s & 3
            n_tets += 1
            for j in range(4):
                w = T[t, j]
                if w != v and seen[w] != v:
                    seen[w] = v
                    n_bf[w] = 0
                    n_edges += 1
            for f in range(4):
                if f != c and nbr[t, f] < 0:
                    n_faces += 1
                    for j in range(3):
                        w = T[t, _TET_FACES[f, j]]
                        if w != v:
                            n_bf[w] += 1
            s = nxt[s]
        # Euler characteristic of the link: vertices - edges + triangles (every face at v is in two
        # of its tets, or in one when it is a boundary face)
        chi = n_edges - (3 * n_tets + n_faces) // 2 + n_tets
        if chi != (1 if isb[v] else 2):
            pinned[v] = PIN_ALL
        if isb[v]:
            # boundary edges not shared by exactly two boundary faces
            s = head[v]
            while s >= 0:
                t = s >> 2
                for j in range(4):
                    w = T[t, j]
                    if w != v and n_bf[w] != 0 and n_bf[w] != 2:
                        pinned[v] = PIN_ALL
                        pinned[w] = PIN_ALL
                s = nxt[s]
    return isb, pinned


@njit(cache=True)
def _vertex_weights(T, tet_w, n):
    """Every vertex's weight as a sample point: a quarter of its tets' volume fractions ``tet_w``
    (summed tet by tet, corner by corner: the order fixes the bits)."""
    vw = np.zeros(n)
    for t in range(T.shape[0]):
        for c in range(4):
            vw[T[t, c]] += tet_w[t] / 4.0
    return vw


@njit(cache=True)
def _centroid_points(pts, dens, T, tet_w, centroid_weight, rows):
    """(pdat, prow): the rows (x, y, z, value, weight, 0) and (name, tet) of every tet's
    centroid (weight its volume fraction x ``centroid_weight``; row t, named n + t) and room for the rest of ``rows``
    (at least the n vertices) after them (each row is computed from its own tet alone: the same
    bits in any tet order)."""
    n = pts.shape[0]
    m = T.shape[0]
    pdat = np.zeros((max(rows, n + m), 6))
    prow = np.full((pdat.shape[0], 2), -1, np.int32)
    for t in range(m):
        pdat[t, 4] = tet_w[t] * centroid_weight
        for k in range(3):
            pdat[t, k] = (((pts[T[t, 0], k] + pts[T[t, 1], k]) + pts[T[t, 2], k]) + pts[T[t, 3], k]) / 4.0
        pdat[t, 3] = (((dens[T[t, 0]] + dens[T[t, 1]]) + dens[T[t, 2]]) + dens[T[t, 3]]) / 4.0
        prow[t, 0] = n + t
        prow[t, 1] = t
    return pdat, prow


@njit(cache=True, nogil=True)
def _tet_hyperplanes(u4, T, weight, planes):
    """``planes[t]`` = (unit normal n (4), offset d, weight w) of tet t's hyperplane through its
    corners' (x, y, z, s): n . u + d = 0 there, n from
    :func:`gatun_py.mesh._quadric_kernels.hyperplane_normal` (edges from corner 0, every operation
    spelled out: the quadrics, and with them the forest, are the same bits on every machine); a
    flat tet (n = 0) or one of weight <= 0 gets n = 0 and w = 0."""
    for t in range(T.shape[0]):
        p = T[t, 0]
        length, n0, n1, n2, n3 = hyperplane_normal(u4, p, T[t, 1], T[t, 2], T[t, 3])
        w = weight[t]
        if not (length > 0.0 and length < np.inf and w > 0.0):
            n0 = n1 = n2 = n3 = 0.0
            w = 0.0
        planes[t, 0] = n0
        planes[t, 1] = n1
        planes[t, 2] = n2
        planes[t, 3] = n3
        planes[t, 4] = -(((n0 * u4[p, 0] + n1 * u4[p, 1]) + n2 * u4[p, 2]) + n3 * u4[p, 3])
        planes[t, 5] = w


@njit(cache=True)
def _accumulate_quadrics(T, planes, out):
    """out[v] += the weighted quadric of tet t for every corner v of every tet t, corner by corner
    (the order of a bincount over the corner-major index list). ``planes[t]`` = (unit normal n (4),
    offset d, weight w) from :func:`_tet_hyperplanes`; the terms are formed as ``(n_i * n_j) * w``
    (i <= j, row by row), ``(n_i * d) * w`` and ``(d * d) * w``."""
    q = np.empty(15)
    for c in range(4):
        for t in range(T.shape[0]):
            v = T[t, c]
            w = planes[t, 5]
            d = planes[t, 4]
            k = 0
            for i in range(4):
                for j in range(i, 4):
                    q[k] = (planes[t, i] * planes[t, j]) * w
                    k += 1
            for i in range(4):
                q[10 + i] = (planes[t, i] * d) * w
            q[14] = (d * d) * w
            for j in range(15):
                out[v, j] += q[j]
