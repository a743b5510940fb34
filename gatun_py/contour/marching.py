"""Marching tetrahedra over a stream of tet batches, with edge-keyed vertices and locks.

A surface vertex lives on a mesh edge (a, b) whose scalars straddle the isovalue, or on a mesh
vertex whose scalar equals it exactly (key (v, v)). Every tet around that edge adds its triangles
to the same vertex, so the streamed surface is indexed (shared vertices) without a position hash.

**Locks** (Hou & Chen's modifiability, on tets). A surface vertex may be changed only once every
tet around its edge has been decoded: before that, more triangles will arrive on it. We track the
*cut border* of the stream ourselves: the multiset of mesh boundary faces and faces of decoded tets,
kept modulo 2 in a hash table, is exactly the set of faces between the decoded and the undecoded
part (a boundary face whose tet is still to come, or an interior face with one decoded tet). Only
faces that touch the isosurface matter (a face with a straddling edge or an iso-valued vertex), so
the table holds the border's intersection with the surface, a band, not the mesh. Per surface
vertex we count the open faces around its edge (around its vertex for key (v, v)); the vertex
unlocks when that count falls to zero at the end of a batch. Why that is safe: once a tet around
edge e has been decoded, if some other tet around e has not, then either they are face-connected
around e, and some face around e between a decoded and an undecoded tet is open, or the undecoded
tets form another fan around e, which in a mesh whose tets do not overlap ends in mesh boundary
faces, and those are open until their tets arrive. So a zero count means the edge's star is
complete. The count is read only at the end of a batch, because within one tet a face may leave
the border before its sibling enters it. (The decoder's own cut border holds the same information,
but it lives in the codec kernel; counting here keeps the codec untouched and also works for plain
mesh files fed as batches.)

Classification follows VTK: a vertex is *above* when s >= iso. The point on a straddling edge is
p_below + t (p_above - p_below) with t = (iso - s_below) / (s_above - s_below).
"""

from __future__ import annotations

import numpy as np
from numba import njit

EMPTY = -1
#: the six edges of a tet, as local vertex pairs (i < j)
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], np.int64)
#: the four faces of a tet, by local vertex ids (orientation does not matter here: keys are sorted)
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], np.int64)


def _edge_index(i: int, j: int) -> int:
    i, j = min(i, j), max(i, j)
    return int(np.flatnonzero((TET_EDGES[:, 0] == i) & (TET_EDGES[:, 1] == j))[0])


#: the diagonal (two tet edges) that splits the quad of each two-above case: VTK's choice
#: (vtkTetra's case table), so that the triangles equal vtkContour3DLinearGrid's one for one
_QUAD_DIAGONAL = {3: (1, 4), 5: (2, 3), 6: (0, 5), 9: (0, 5), 10: (0, 5), 12: (2, 3)}


def _case_table() -> tuple[np.ndarray, np.ndarray]:
    """Triangles per case (bit i set: vertex i above), as tet edge indices, wound so that the normal
    points from above toward below (out of the region s >= iso) for a positively oriented tet.

    Built by construction on the reference tet (0,0,0), (1,0,0), (0,1,0), (0,0,1), whose signed
    volume is positive; orientation is preserved by every positive affine map and does not depend
    on where the points sit on their edges, so the table holds for every positive tet.
    """
    ref = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    count = np.zeros(16, np.int64)
    tris = np.full((16, 2, 3), -1, np.int64)
    for case in range(1, 15):
        above = [i for i in range(4) if case >> i & 1]
        below = [i for i in range(4) if not case >> i & 1]
        if len(above) == 1 or len(below) == 1:
            lone, others = (above[0], below) if len(above) == 1 else (below[0], above)
            polys = [[_edge_index(lone, o) for o in others]]
        else:
            a0, a1 = above
            b0, b1 = below
            quad = [_edge_index(a0, b0), _edge_index(a0, b1), _edge_index(a1, b1), _edge_index(a1, b0)]
            k = quad.index(_QUAD_DIAGONAL[case][0])
            quad = quad[k:] + quad[:k]  # start the cycle at one end of the diagonal
            polys = [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
        # gradient direction of a scalar that is 1 above and 0 below, and the midpoint positions
        s = np.array([1.0 if case >> i & 1 else 0.0 for i in range(4)])
        grad = np.linalg.solve(ref[1:] - ref[0], s[1:] - s[0])
        for k, poly in enumerate(polys):
            p = np.array([(ref[TET_EDGES[e, 0]] + ref[TET_EDGES[e, 1]]) / 2 for e in poly])
            n = np.cross(p[1] - p[0], p[2] - p[0])
            if np.dot(n, grad) > 0:  # normal toward above: flip to point toward below
                poly = [poly[0], poly[2], poly[1]]
            tris[case, k] = poly
        count[case] = len(polys)
    return count, tris


CASE_COUNT, CASE_TRIS = _case_table()


# -- hash tables (linear probing, backward-shift deletion, power-of-two capacity) ----------------
# Each table is one array of rows (a face: its three sorted vertex ids; an edge: key, vertex id and
# open-face count in one 16-byte record), so a probe touches one cache line, not one per column:
# the tables outgrow the caches on a large mesh, and their probes were most of the extraction's time.

#: one slot of the edge table: the key (a << 32 | b, a <= b; EMPTY when free), the surface vertex on
#: that edge (EMPTY until a tet creates it) and the count of open border faces around the edge
EDGE_SLOT = np.dtype([("key", np.int64), ("vid", np.int32), ("count", np.int32)])


def new_face_table(cap: int) -> np.ndarray:
    """An empty face table of ``cap`` (a power of two) rows."""
    return np.full((cap, 3), EMPTY, np.int32)


def new_edge_table(cap: int) -> np.ndarray:
    """An empty edge table of ``cap`` (a power of two) slots."""
    t = np.empty(cap, EDGE_SLOT)
    t["key"] = EMPTY
    t["vid"] = EMPTY
    t["count"] = 0
    return t


@njit(cache=True, inline="always")
def _mix(x):
    x = (x ^ (x >> 31)) * 0x7FB5D329728EA185
    x = (x ^ (x >> 27)) * 0x81DADEF4BC2DD44D
    return x ^ (x >> 33)


@njit(cache=True, inline="always")
def _face_home(a, b, c, mask):
    return _mix(np.int64(a) * 0x9E3779B1 + np.int64(b) * 0x85EBCA77 + np.int64(c) * 0xC2B2AE3D) & mask


@njit(cache=True)
def _face_toggle(ft, a, b, c):
    """Insert face (a < b < c) if absent (returns +1), remove it if present (returns -1)."""
    mask = ft.shape[0] - 1
    i = _face_home(a, b, c, mask)
    while ft[i, 0] != EMPTY:
        if ft[i, 0] == a and ft[i, 1] == b and ft[i, 2] == c:
            # backward-shift deletion keeps every probe chain unbroken, no tombstones
            j = i
            while True:
                j = (j + 1) & mask
                if ft[j, 0] == EMPTY:
                    break
                h = _face_home(ft[j, 0], ft[j, 1], ft[j, 2], mask)
                if (j > i and (h <= i or h > j)) or (j < i and (h <= i and h > j)):
                    ft[i, 0] = ft[j, 0]
                    ft[i, 1] = ft[j, 1]
                    ft[i, 2] = ft[j, 2]
                    i = j
            ft[i, 0] = EMPTY
            return -1
        i = (i + 1) & mask
    ft[i, 0] = a
    ft[i, 1] = b
    ft[i, 2] = c
    return 1


@njit(cache=True)
def _edge_find(et, key):
    """Slot of ``key`` in the edge table, or the empty slot where it would go."""
    mask = et.shape[0] - 1
    i = _mix(key) & mask
    while et[i].key != EMPTY and et[i].key != key:
        i = (i + 1) & mask
    return i


@njit(cache=True)
def _edge_slot(et, key, sizes):
    """Slot of ``key``, inserted (no vertex yet, count 0) if absent."""
    i = _edge_find(et, key)
    if et[i].key == EMPTY:
        et[i].key = key
        et[i].vid = EMPTY
        et[i].count = 0
        sizes[1] += 1
    return i


@njit(cache=True)
def _edge_delete(et, i):
    mask = et.shape[0] - 1
    j = i
    while True:
        j = (j + 1) & mask
        if et[j].key == EMPTY:
            break
        h = _mix(et[j].key) & mask
        if (j > i and (h <= i or h > j)) or (j < i and (h <= i and h > j)):
            et[i] = et[j]
            i = j
    et[i].key = EMPTY


@njit(cache=True, nogil=True)
def rehash_faces(ft, cap):
    new = np.full((cap, 3), EMPTY, np.int32)
    for i in range(ft.shape[0]):
        if ft[i, 0] != EMPTY:
            _face_toggle(new, ft[i, 0], ft[i, 1], ft[i, 2])
    return new


@njit(cache=True, nogil=True)
def rehash_edges(et, cap):
    new = np.empty(cap, EDGE_SLOT)
    for i in range(cap):
        new[i].key = EMPTY
    for i in range(et.shape[0]):
        if et[i].key != EMPTY:
            new[_edge_find(new, et[i].key)] = et[i]
    return new


# -- the kernel ------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _edge_key(a, b):
    if a > b:
        a, b = b, a
    return (np.int64(a) << 32) | np.int64(b)


@njit(cache=True, inline="always")
def _sorted3(a, b, c):
    """A face's vertex ids in increasing order (its key in the face table)."""
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return a, b, c


@njit(cache=True)
def _touch_face(ft, et, zero, nzero, vals, iso, a, b, c, sizes):
    """Toggle face (a, b, c) in the border if it touches the surface; update its edges' counts.
    Returns the new number of recorded count-hits-zero keys."""
    a, b, c = _sorted3(a, b, c)
    sa = vals[a, 3] >= iso
    sb = vals[b, 3] >= iso
    sc = vals[c, 3] >= iso
    ea = vals[a, 3] == iso
    eb = vals[b, 3] == iso
    ec = vals[c, 3] == iso
    if sa == sb and sb == sc and not (ea or eb or ec):
        return nzero
    d = _face_toggle(ft, a, b, c)
    sizes[0] += d
    for k in range(6):
        # three straddling-edge keys, then three vertex keys
        if k == 0:
            if sa == sb:
                continue
            key = _edge_key(a, b)
        elif k == 1:
            if sa == sc:
                continue
            key = _edge_key(a, c)
        elif k == 2:
            if sb == sc:
                continue
            key = _edge_key(b, c)
        elif k == 3:
            if not ea:
                continue
            key = _edge_key(a, a)
        elif k == 4:
            if not eb:
                continue
            key = _edge_key(b, b)
        else:
            if not ec:
                continue
            key = _edge_key(c, c)
        i = _edge_slot(et, key, sizes)
        et[i].count += d
        if et[i].count == 0:
            zero[nzero] = key
            nzero += 1
    return nzero


@njit(cache=True)
def _surface_vertex(et, vals, iso, a, b, vpos, vgrad, vkey, nv, gmag, sizes):
    """(slot of its key, id) of the surface vertex on edge (a, b) (a above, b below), created if new."""
    if vals[a, 3] == iso:
        key = _edge_key(a, a)
    else:
        key = _edge_key(a, b)
    i = _edge_slot(et, key, sizes)
    if et[i].vid == EMPTY:
        et[i].vid = nv
        vkey[nv] = key
        if vals[a, 3] == iso:
            for k in range(3):
                vpos[nv, k] = vals[a, k]
        else:
            sa = np.float64(vals[a, 3])
            sb = np.float64(vals[b, 3])
            t = (iso - sb) / (sa - sb)
            for k in range(3):
                pb = np.float64(vals[b, k])
                vpos[nv, k] = pb + t * (np.float64(vals[a, k]) - pb)
        vgrad[nv, 0] = 0.0
        vgrad[nv, 1] = 0.0
        nv += 1
    v = et[i].vid
    vgrad[v, 0] += gmag
    vgrad[v, 1] += 1.0
    return i, v, nv


#: for each tet edge, the two local vertices off it: the edge lies in the faces opposite them
_OFF_EDGE = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]], np.int64)


@njit(cache=True, nogil=True)
def extract_batch(vals, tets, boundary, iso, case_count, case_tris, tet_edges,
                  ft, et, vpos, vgrad, vkey, vlock, nv, tris, nt, zero, sizes):
    """Marching tetrahedra on one batch; border bookkeeping; unlock complete edges.

    ``vals`` (n, 4) float32 holds x, y, z and the scalar of every vertex streamed so far (one
    array, so a ``.tetc`` stream can lend the decoder's own instead of a copy). ``ft`` and ``et``
    are the face and edge tables (:func:`new_face_table`, :func:`new_edge_table`).
    Capacities (checked by the caller): the tables hold at least twice their entries after the
    batch, ``vpos``/``vgrad``/``vlock`` room for 4 new vertices per tet, ``tris`` 2 per tet,
    ``zero`` 12 per tet + 3 per boundary face.

    ``sizes`` = [faces in the border table, entries in the edge table], updated. ``vkey`` gets the
    edge key of every new vertex (a << 32 | b, a <= b).

    Returns (nv, nt, unlocked): the new vertex and triangle counts and how many vertices unlocked.
    """
    nzero = 0
    for f in range(boundary.shape[0]):
        nzero = _touch_face(ft, et, zero, nzero, vals, iso, boundary[f, 0], boundary[f, 1], boundary[f, 2], sizes)
    g = np.empty(3)
    m = np.empty((3, 3))
    vid = np.empty(6, np.int64)
    slot = np.empty(6, np.int64)
    toggled = np.zeros(4, np.int64)
    for t in range(tets.shape[0]):
        case = 0
        on_iso = False
        for i in range(4):
            s = vals[tets[t, i], 3]
            if s >= iso:
                case |= 1 << i
            if s == iso:
                on_iso = True
        if case_count[case] == 0 and not on_iso:
            continue  # none of its faces touches the surface: nothing to extract or to track
        if case_count[case] > 0:
            # gradient magnitude of the tet's linear scalar (0 for a flat tet)
            p0 = tets[t, 0]
            for r in range(3):
                q = tets[t, r + 1]
                for k in range(3):
                    m[r, k] = np.float64(vals[q, k]) - np.float64(vals[p0, k])
                g[r] = np.float64(vals[q, 3]) - np.float64(vals[p0, 3])
            det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
                   - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
                   + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
            gmag = 0.0
            if det != 0.0:
                # grad = M^-1 g via Cramer's rule
                gx = (g[0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
                      - m[0, 1] * (g[1] * m[2, 2] - m[1, 2] * g[2])
                      + m[0, 2] * (g[1] * m[2, 1] - m[1, 1] * g[2])) / det
                gy = (m[0, 0] * (g[1] * m[2, 2] - m[1, 2] * g[2])
                      - g[0] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
                      + m[0, 2] * (m[1, 0] * g[2] - g[1] * m[2, 0])) / det
                gz = (m[0, 0] * (m[1, 1] * g[2] - g[1] * m[2, 1])
                      - m[0, 1] * (m[1, 0] * g[2] - g[1] * m[2, 0])
                      + g[0] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])) / det
                gmag = np.sqrt(gx * gx + gy * gy + gz * gz)
            for e in range(6):
                vid[e] = EMPTY
                slot[e] = EMPTY
            for k in range(case_count[case]):
                tri0 = EMPTY
                tri1 = EMPTY
                tri2 = EMPTY
                for c in range(3):
                    e = case_tris[case, k, c]
                    if vid[e] == EMPTY:
                        a = tets[t, tet_edges[e, 0]]
                        b = tets[t, tet_edges[e, 1]]
                        if vals[b, 3] >= iso:
                            a, b = b, a
                        nv0 = nv
                        slot[e], vid[e], nv = _surface_vertex(et, vals, iso, a, b, vpos, vgrad, vkey, nv, gmag,
                                                              sizes)
                        if nv > nv0:
                            vlock[nv0] = 1
                    if c == 0:
                        tri0 = vid[e]
                    elif c == 1:
                        tri1 = vid[e]
                    else:
                        tri2 = vid[e]
                # iso-valued mesh vertices can merge two corners: such a triangle has no area
                if tri0 != tri1 and tri1 != tri2 and tri0 != tri2:
                    tris[nt, 0] = tri0
                    tris[nt, 1] = tri1
                    tris[nt, 2] = tri2
                    nt += 1
        if on_iso:
            # an iso-valued corner keys its vertex by the mesh vertex: the general path, face by face
            for f in range(4):
                nzero = _touch_face(ft, et, zero, nzero, vals, iso, tets[t, _FACES[f, 0]], tets[t, _FACES[f, 1]],
                                    tets[t, _FACES[f, 2]], sizes)
            continue
        # No corner on the isovalue: a face touches the surface when its corners are not all on
        # one side, and each straddling edge (it has a vertex: slot[e]) lies in two of the faces,
        # so its count changes by the sum of their toggles: one look-up per edge, not per face
        for f in range(4):
            rest = case & (15 ^ (1 << f))  # the side bits of face f's corners (face f is opposite f)
            if rest == 0 or rest == (15 ^ (1 << f)):
                toggled[f] = 0
                continue
            a, b, c = _sorted3(tets[t, _FACES[f, 0]], tets[t, _FACES[f, 1]], tets[t, _FACES[f, 2]])
            toggled[f] = _face_toggle(ft, a, b, c)
            sizes[0] += toggled[f]
        for e in range(6):
            i = slot[e]
            if i == EMPTY:
                continue
            d = toggled[_OFF_EDGE[e, 0]] + toggled[_OFF_EDGE[e, 1]]
            if d != 0:
                et[i].count += d
                if et[i].count == 0:
                    zero[nzero] = et[i].key
                    nzero += 1
    unlocked = 0
    for z in range(nzero):
        i = _edge_find(et, zero[z])
        if et[i].key != EMPTY and et[i].count == 0:
            if et[i].vid != EMPTY:
                vlock[et[i].vid] = 0
                unlocked += 1
            _edge_delete(et, i)
            sizes[1] -= 1
    return nv, nt, unlocked
