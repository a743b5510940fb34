"""Numba kernels of the cut-border connectivity coder (see :mod:`gatun_py.codec.cutborder`).

The *border* is a set of live elements with up to three vertices each: oriented triangles (the
current surface T of the tet phase) or directed edges (the border of the boundary-surface phase,
column 2 then holds the apex of the triangle that created the edge, used only as a geometry
predictor). Elements live in slots; every vertex has a doubly linked list of the (slot, corner)
nodes incident to it, so adjacency queries cost the vertex degree in the border. Elements are
processed first-in first-out (a ring buffer of (slot, sequence) pairs with lazy deletion), which is
the breadth-first, iteration-by-iteration growth of the paper.

Encoder and decoder share every rule that shapes the state (candidate lists, additions,
removals); only the symbol I/O differs. Decoders check every index and count they read and stop
with an error code instead of touching memory out of bounds.

Border arrays, passed as a tuple ``B = (E, vhead, Q, bs)`` (few arrays: every array passed to a
kernel costs reference-count updates on each call, which dominated the per-tet cost before):
``E (cap * E_COLS,) int32`` one row of ``E_COLS`` per slot, flat so that a row's offset is a
multiplication by a constant (a 2-D array's row stride is a run-time value: one more multiply on
the list walks' chain of dependent loads): vertices (+ apex data) in columns 0-3, sequence number
(``E_SEQ``, -1: free slot), incidence-list links per corner (``E_NEXT``, ``E_PREV``; a node id is
the offset in E of the node's next link, ``slot * E_COLS + E_NEXT + corner``, stored as an
unsigned 32-bit value in the int32 table (-1, all ones: none), so that a list walk's chain of
dependent loads is ``node = E[np.uint32(node)]`` with no arithmetic between the loads (the slot,
needed beside the chain, is a multiply and a shift: :func:`_node_slot`), free-list link
(``E_FREE``; slots never used are handed out in order past ``BS_BUMP``, so the table needs no
initialisation); ``vhead (nv) int32`` list heads;
``Q (qcap, 2) int64`` (the decoders: int32) FIFO ring of (slot, sequence), ``qcap`` a power of
two; ``bs int64`` scalars (see ``BS_*``).

The tet decoder does not walk the fourth vertex's list for the faces a new tet closes: they are
the faces on an edge of the current face holding that vertex, which its candidate gather has
just visited and notes (:func:`_gather_face`); the encoder walks the list (:func:`_apply_tet`),
so every round trip compares the two.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from . import rangecoder as rc

BS_NFREE, BS_QHEAD, BS_QTAIL, BS_SEQ, BS_LIVE, BS_PEAK, BS_FREE_HEAD, BS_BUMP = 0, 1, 2, 3, 4, 5, 6, 7
# columns of the element table E: vertices/apex 0-3, sequence, list links per corner, free list
E_SEQ, E_NEXT, E_PREV, E_FREE, E_COLS = 4, 5, 8, 11, 12
MAX_SLOTS = 1 << 28  # node ids slot * E_COLS + E_NEXT + corner are below 2**32 - 1 (all ones: none)
E_LINK = E_PREV - E_NEXT  # a node's previous-node link, this far past its next link
# sequence numbers are int32 (E_SEQ, and the decoders' queue): one per element ever added, so a
# stream adds fewer than this many elements (the decoders check it from the header's counts)
MAX_SEQ = (1 << 31) - 1


@njit(cache=True, inline="always")
def _node_slot(node):
    """The slot of node id ``node`` (as stored, int32): ``node // E_COLS`` on its unsigned value,
    as the multiply and shift a compiler makes of an unsigned 32-bit division by 12 (E_COLS)."""
    return np.int64((np.uint64(np.uint32(node)) * np.uint64(0xAAAAAAAB)) >> np.uint64(35))


@njit(cache=True, inline="always")
def _node_corner(node, slot):
    """The corner of node id ``node`` in its slot."""
    return np.int64(np.uint32(node)) - slot * E_COLS - E_NEXT


@intrinsic
def _prefetch(typingctx, arr, i):
    """Hint the CPU to bring ``arr[i]`` (1-D) into cache: LLVM's ``prefetch``, which reads
    nothing architecturally and never faults, so ``i`` need not be checked. Numba has no
    prefetch of its own."""
    if not (isinstance(arr, types.Array) and arr.ndim == 1 and isinstance(i, types.Integer)):
        return None
    sig = types.void(arr, i)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ii = context.cast(builder, args[1], signature.args[1], types.intp)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [ii], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])  # read, keep, data
        return context.get_dummy_value()

    return sig, codegen


# How far ahead in the FIFO the tet decoder prefetches: the row of the face PF_ROW entries on,
# the list heads of the vertices of the face PF_HEAD entries on (whose row is in by then), and
# the first nodes of the lists of the face PF_NODE entries on (whose heads are in by then).
PF_ROW, PF_HEAD, PF_NODE, PF_NODE2 = 32, 16, 8, 4


MAX_C1 = 15  # coded edge-adjacent candidates (symbol 15 = escape)
MAX_C2 = 64  # vertex-adjacent candidates
ESC = 15

# What follows an escape: the codes the encoder writes and the decoder reads (docs/format.md).
# Tet phase, a 2-bit kind symbol: the paper's cases (b), (c) and (d).
KIND_NEW, KIND_VERTEX_ADJACENT, KIND_TABLE = 0, 1, 2
# Boundary phase and seed triangles, one adaptive bit: a new vertex, or a raw vertex-table index.
BIT_NEW, BIT_TABLE = 1, 0
# The encoder's per-tet symbol log (``syms``, for statistics): candidate 0..14, or the escape kind.
SYM_NEW, SYM_VERTEX_ADJACENT, SYM_TABLE = ESC + KIND_NEW, ESC + KIND_VERTEX_ADJACENT, ESC + KIND_TABLE

# model layout of the boundary phase
N_S1_CTX = 5 * 3 * 3 * 2
SM_C1 = 0
SM_NEW = SM_C1 + N_S1_CTX * 16
SM_SEED = SM_NEW + 8
SM_FLIP = SM_SEED + 8
SM_SIZE = SM_FLIP + 4

# status codes of the resumable decoder
ST_DONE, ST_BATCH, ST_GROW, ST_ERROR = 0, 1, 2, 3


def _pow2_at_least(n: int) -> int:
    """The smallest power of two >= n: the queue's capacity, so that a position in the ring is
    a mask of the running count rather than a division (two per tet)."""
    return 1 << max(int(n) - 1, 0).bit_length()


def new_border(n_vertices: int, cap: int, qcap: int, *, queue_dtype=np.int64):
    """Allocate an empty border for ``n_vertices`` vertices (the decoders pass ``queue_dtype``
    int32: slots and sequence numbers fit, see ``MAX_SLOTS`` and ``MAX_SEQ``, and the queue is
    their largest array after E)."""
    cap = max(int(cap), 16)
    qcap = _pow2_at_least(max(int(qcap), 16))
    E = np.empty((cap, E_COLS), np.int32)
    vhead = np.full(max(int(n_vertices), 1), -1, np.int32)
    Q = np.zeros((qcap, 2), queue_dtype)
    bs = np.zeros(8, np.int64)
    bs[BS_NFREE] = cap
    bs[BS_FREE_HEAD] = -1  # freed slots; the never used ones start at BS_BUMP = 0
    return (E.reshape(-1), vhead, Q, bs)


def grow_border(B, need_slots: int, need_queue: int):
    """A copy of border ``B`` with room for at least ``need_slots`` more elements and queue entries."""
    E, vhead, Q, bs = B
    E = E.reshape(-1, E_COLS)
    bs = bs.copy()
    cap = E.shape[0]
    nfree = int(bs[BS_NFREE])
    if nfree < need_slots:
        new_cap = min(max(2 * cap, cap + need_slots), MAX_SLOTS - 1)  # the caller checks cap + need_slots
        grown = np.empty((new_cap, E_COLS), np.int32)  # slots past BS_BUMP are written when handed out
        grown[:cap] = E
        E = grown
        bs[BS_NFREE] = nfree + new_cap - cap
    qcap = Q.shape[0]
    used = int(bs[BS_QTAIL] - bs[BS_QHEAD])
    if qcap - used < need_queue:
        new_qcap = _pow2_at_least(max(2 * qcap, used + need_queue))
        idx = (int(bs[BS_QHEAD]) + np.arange(used)) & (qcap - 1)
        nq = np.zeros((new_qcap, 2), Q.dtype)
        nq[:used] = Q[idx]
        Q = nq
        bs[BS_QHEAD] = 0
        bs[BS_QTAIL] = used
    return (E.reshape(-1), vhead, Q, bs)


# The border helpers below are compiled with ``_nrt=False``: they never allocate, and without the
# runtime's reference counting a call no longer does an atomic increment and decrement of each of
# the border's arrays (most of the per-tet overhead of the decoder, measured with perf).
@njit(cache=True, _nrt=False)
def _room(B, slots, entries):
    E, vhead, Q, bs = B
    return bs[BS_NFREE] >= slots and Q.shape[0] - (bs[BS_QTAIL] - bs[BS_QHEAD]) >= entries


@njit(cache=True, _nrt=False)
def _add(B, k, v0, v1, v2, v3):
    """Add an element with ``k`` listed vertices (the rest of v0..v3 is stored as data: the apex
    of the triangle or tet that created it, for the geometry coder); returns its slot."""
    E, vhead, Q, bs = B
    s = bs[BS_FREE_HEAD]
    if s != -1:
        bs[BS_FREE_HEAD] = E[s * E_COLS + E_FREE]
    else:
        s = bs[BS_BUMP]
        bs[BS_BUMP] = s + 1
    bs[BS_NFREE] -= 1
    E[s * E_COLS + 0] = v0
    E[s * E_COLS + 1] = v1
    E[s * E_COLS + 2] = v2
    E[s * E_COLS + 3] = v3
    seq = bs[BS_SEQ]
    bs[BS_SEQ] = seq + 1
    E[s * E_COLS + E_SEQ] = seq
    for c in range(k):
        v = E[s * E_COLS + c]
        node = s * E_COLS + E_NEXT + c
        h = vhead[v]
        E[node] = h
        E[node + E_LINK] = -1
        if h != -1:
            E[np.int64(np.uint32(h)) + E_LINK] = node
        vhead[v] = node
    t = bs[BS_QTAIL] & (Q.shape[0] - 1)
    Q[t, 0] = s
    Q[t, 1] = seq
    bs[BS_QTAIL] += 1
    bs[BS_LIVE] += 1
    if bs[BS_LIVE] > bs[BS_PEAK]:
        bs[BS_PEAK] = bs[BS_LIVE]
    return s


@njit(cache=True, _nrt=False)
def _remove(B, k, s):
    E, vhead, Q, bs = B
    for c in range(k):
        p = E[s * E_COLS + E_PREV + c]
        n = E[s * E_COLS + E_NEXT + c]
        if p != -1:
            E[np.uint32(p)] = n
        else:
            vhead[E[s * E_COLS + c]] = n
        if n != -1:
            E[np.int64(np.uint32(n)) + E_LINK] = p
    E[s * E_COLS + E_SEQ] = -1
    E[s * E_COLS + E_FREE] = bs[BS_FREE_HEAD]
    bs[BS_FREE_HEAD] = s
    bs[BS_NFREE] += 1
    bs[BS_LIVE] -= 1


@njit(cache=True, _nrt=False)
def _pop(B):
    """The oldest live element's slot (it stays live), or -1 when the border is empty."""
    E, vhead, Q, bs = B
    qcap = Q.shape[0]
    while bs[BS_QHEAD] < bs[BS_QTAIL]:
        h = bs[BS_QHEAD] & (qcap - 1)
        bs[BS_QHEAD] += 1
        s = Q[h, 0]
        if E[s * E_COLS + E_SEQ] == Q[h, 1]:
            return s
    return -1


@njit(cache=True, _nrt=False)
def _find_edge(B, p, r):
    """Slot of a live border edge {p, r} (either direction; the oldest one), or -1."""
    E, vhead, Q, bs = B
    node = vhead[p]
    best = -1
    best_seq = np.int64(-1)
    while node != -1:
        s = _node_slot(node)
        c = _node_corner(node, s)
        if c < 2 and E[s * E_COLS + 1 - c] == r:
            if best == -1 or E[s * E_COLS + E_SEQ] < best_seq:
                best = s
                best_seq = E[s * E_COLS + E_SEQ]
        node = E[np.uint32(node)]  # an unsigned index: no wrap-around arithmetic on the chain
    return best


@njit(cache=True, _nrt=False)
def _insert_candidate(cand, cscore, cseq, n, x, seq):
    """Add vertex x (seen on an adjacent element with sequence ``seq``) to the candidate list."""
    for i in range(n):
        if cand[i] == x:
            cscore[i] += 1
            if seq < cseq[i]:
                cseq[i] = seq
            return n
    if n < cand.shape[0]:
        cand[n] = x
        cscore[n] = 1
        cseq[n] = seq
        return n + 1
    return n


@njit(cache=True, _nrt=False)
def _sort_candidates(cand, cscore, cseq, n):
    """Order by score (descending), then by first-seen sequence (ascending): insertion sort."""
    for i in range(1, n):
        x, sc, sq = cand[i], cscore[i], cseq[i]
        j = i - 1
        while j >= 0 and (cscore[j] < sc or (cscore[j] == sc and cseq[j] > sq)):
            cand[j + 1] = cand[j]
            cscore[j + 1] = cscore[j]
            cseq[j + 1] = cseq[j]
            j -= 1
        cand[j + 1] = x
        cscore[j + 1] = sc
        cseq[j + 1] = sq


# The case (c) gather's table of the vertices it has met (open addressing, linear probing): row 0
# the vertex (-1: free), row 1 its position in the list (-1: an edge candidate, left out). At most
# MAX_C1 + MAX_C2 keys, so it stays under a third full and a lookup is a probe or two, where
# scanning both lists for every vertex met cost the decoder 7 % of its time on the gmsh flange.
SEEN_SLOTS = 256


@njit(cache=True, inline="always")
def _seen_slot(seen, w):
    """Slot of vertex ``w`` in the table, or the free slot where it goes."""
    h = ((w * -7046029254386353131) >> 40) & (SEEN_SLOTS - 1)  # multiplicative hash, high bits
    while seen[0, h] != -1 and seen[0, h] != w:
        h = (h + 1) & (SEEN_SLOTS - 1)
    return h


@njit(cache=True, _nrt=False)
def _gather_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen):
    """The paper's case (c) list: vertices of faces of T sharing exactly one vertex with the
    current face (a, b, c) (already removed from T), except the edge candidates, in traversal
    order (oldest face first). Only needed after an escape, so computed lazily. ``seen``
    ``(2, SEEN_SLOTS)`` int64 is scratch."""
    n2 = _walk_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen)
    # stable insertion sort by sequence
    for i in range(1, n2):
        x, sq = c2[i], c2seq[i]
        j = i - 1
        while j >= 0 and c2seq[j] > sq:
            c2[j + 1] = c2[j]
            c2seq[j + 1] = c2seq[j]
            j -= 1
        c2[j + 1] = x
        c2seq[j + 1] = sq
    return n2


@njit(cache=True, _nrt=False)
def _walk_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen):
    """:func:`_gather_vertex_adjacent`'s list unsorted: in the order first met, each vertex with
    the oldest sequence number of a face it was met on."""
    E, vhead, Q, bs = B
    for h in range(SEEN_SLOTS):
        seen[0, h] = -1
    for i in range(n1):
        h = _seen_slot(seen, cand[i])
        seen[0, h] = cand[i]
        seen[1, h] = -1
    n2 = 0
    for k in range(3):
        u = a if k == 0 else (b if k == 1 else c)
        node = vhead[u]
        while node != -1:
            g = _node_slot(node)
            node = E[np.uint32(node)]  # an unsigned index: no wrap-around arithmetic on the chain
            shared = 0
            for cj in range(3):
                w = E[g * E_COLS + cj]
                if w == a or w == b or w == c:
                    shared += 1
            if shared != 1:
                continue
            seq = np.int64(E[g * E_COLS + E_SEQ])
            for cj in range(3):
                w = np.int64(E[g * E_COLS + cj])
                if w == a or w == b or w == c:
                    continue
                h = _seen_slot(seen, w)
                if seen[0, h] == w:
                    i = seen[1, h]
                    if i >= 0 and seq < c2seq[i]:
                        c2seq[i] = seq
                elif n2 < c2.shape[0]:
                    seen[0, h] = w
                    seen[1, h] = n2
                    c2[n2] = w
                    c2seq[n2] = seq
                    n2 += 1
    return n2


@njit(cache=True, _nrt=False)
def _score_context(n1, cscore, prev, cap):
    """Context of a candidate-index symbol: how many candidates (capped at 4), the scores of the
    best two (capped at ``cap``) and whether the previous symbol escaped."""
    s1 = cscore[0] if n1 > 0 else 0
    s2 = cscore[1] if n1 > 1 else 0
    if s1 > cap:
        s1 = cap
    if s2 > cap:
        s2 = cap
    nn = n1 if n1 < 4 else 4
    return ((nn * (cap + 1) + s1) * (cap + 1) + s2) * 2 + prev


@njit(cache=True, _nrt=False)
def _apply_tet(B, t0, t1, t2, t3):
    """Attach the new tet (t0, t1, t2, t3) (as output; its face opposite t3 was the current face,
    already removed): each other face closes a face of the border or joins it, wound as the
    consistently oriented tet on its other side would see it from outside. Returns the slots of
    the faces opposite t0, t1, t2 that joined the border (-1 where a face was closed)."""
    f0, f1, f2 = _closing_faces(B, t0, t1, t2, t3)
    return _attach_tet(B, t0, t1, t2, t3, f0, f1, f2)


@njit(cache=True, _nrt=False)
def _closing_faces(B, t0, t1, t2, t3):
    """The border faces (slots, -1: none) that the faces opposite t0, t1, t2 of the new tet close."""
    E, vhead, Q, bs = B
    # all three faces hold t3 (the apex just attached, often new with an empty list): one walk
    # of its list finds those already on the border
    f0 = -1
    f1 = -1
    f2 = -1
    node = vhead[t3]
    while node != -1:
        g = _node_slot(node)
        c0 = _node_corner(node, g)
        node = E[np.uint32(node)]  # an unsigned index: no wrap-around arithmetic on the chain
        x = E[g * E_COLS + (0 if c0 == 2 else c0 + 1)]
        y = E[g * E_COLS + (2 if c0 == 0 else c0 - 1)]
        if (x == t1 and y == t2) or (x == t2 and y == t1):
            f0 = g
        elif (x == t2 and y == t0) or (x == t0 and y == t2):
            f1 = g
        elif (x == t0 and y == t1) or (x == t1 and y == t0):
            f2 = g
    return f0, f1, f2


@njit(cache=True, _nrt=False)
def _attach_tet(B, t0, t1, t2, t3, f0, f1, f2):
    """The second half of :func:`_apply_tet`, given the border faces ``f0``, ``f1``, ``f2`` (-1:
    none) that the faces opposite t0, t1, t2 close."""
    # outward faces opposite t0, t1, t2 (TET_FACES), stored reversed when they join the border
    if f0 != -1:
        _remove(B, 3, f0)
        added0 = -1
    else:
        added0 = _add(B, 3, t1, t3, t2, t0)
    if f1 != -1:
        _remove(B, 3, f1)
        added1 = -1
    else:
        added1 = _add(B, 3, t0, t2, t3, t1)
    if f2 != -1:
        _remove(B, 3, f2)
        added2 = -1
    else:
        added2 = _add(B, 3, t0, t3, t1, t2)
    return added0, added1, added2


# The tet decoders' copies of the per-tet helpers, inlined into them by numba: called, each call
# passed the border's arrays and the candidate lists as some forty words on the stack.
_apply_tet_inlined = njit(cache=True, _nrt=False, inline="always")(_apply_tet.py_func)
_attach_tet_inlined = njit(cache=True, _nrt=False, inline="always")(_attach_tet.py_func)
# Coding 2's decoder writes the attachment out with these (a loop over the tet's three faces, so
# that each is compiled once: numba's inlining costs compile time per call site).
_add_inlined = njit(cache=True, _nrt=False, inline="always")(_add.py_func)
_remove_inlined = njit(cache=True, _nrt=False, inline="always")(_remove.py_func)


# edges of the current face (a, b, c) in the tet decoder's record of the faces on them
EDGE_BC, EDGE_AB, EDGE_AC = 0, 1, 2


@njit(cache=True, _nrt=False)
def _gather_face(B, s, cand, cscore, cseq, cface, cface_full):
    """Candidates for the fourth vertex of the tet behind border face ``s`` = (a, b, c): the
    apexes of faces of T adjacent to an edge of ``s``, unsorted (:func:`_sort_candidates` orders
    them by score, how many of the face's edges they are adjacent across, and then by traversal
    order). Returns their number.

    Also notes, for the candidate at each position (``cand`` before the sort: the decoder keeps
    a copy), the oldest face on each edge of ``s`` holding it (``cface[i, EDGE_*]``, -1 none). A
    tet on candidate x closes exactly those faces: they are the border faces holding x and an
    edge of ``s`` (the faces :func:`_apply_tet` finds on x's list, the oldest first), so the
    decoder need not walk x's list for them. A vertex that is no candidate holds no such face,
    unless the list was full: ``cface_full[0]`` is then set (the caller clears it)."""
    E, vhead, Q, bs = B
    a = np.int64(E[s * E_COLS + 0])
    b = np.int64(E[s * E_COLS + 1])
    c = np.int64(E[s * E_COLS + 2])
    n1 = np.int64(0)
    # faces on edges (a, b) and (a, c) are all in a's list; those on (b, c) in b's list
    for k in range(2):
        u = a if k == 0 else b
        node = vhead[u]
        while node != -1:
            g = _node_slot(node)
            node = E[np.uint32(node)]  # an unsigned index: no wrap-around arithmetic on the chain
            if g == s:
                continue
            g0 = np.int64(E[g * E_COLS + 0])
            g1 = np.int64(E[g * E_COLS + 1])
            g2 = np.int64(E[g * E_COLS + 2])
            has_a = g0 == a or g1 == a or g2 == a
            has_b = g0 == b or g1 == b or g2 == b
            has_c = g0 == c or g1 == c or g2 == c
            if k == 0:
                if has_b == has_c:  # neither: vertex-adjacent only; both: corrupt duplicate
                    continue
                edge = EDGE_AB if has_b else EDGE_AC
            elif has_a or not has_c:
                continue
            else:
                edge = EDGE_BC
            if g0 != a and g0 != b and g0 != c:
                x = g0
            elif g1 != a and g1 != b and g1 != c:
                x = g1
            else:
                x = g2
            seq = E[g * E_COLS + E_SEQ]
            i = 0
            while i < n1 and cand[i] != x:
                i += 1
            if i < n1:
                cscore[i] += 1
                if seq < cseq[i]:
                    cseq[i] = seq
                f = cface[i, edge]
                if f == -1 or seq < E[f * E_COLS + E_SEQ]:
                    cface[i, edge] = g
            elif n1 < cand.shape[0]:  # as _insert_candidate
                cand[n1] = x
                cscore[n1] = 1
                cseq[n1] = seq
                cface[n1, 0] = -1
                cface[n1, 1] = -1
                cface[n1, 2] = -1
                cface[n1, edge] = g
                n1 += 1
            else:
                cface_full[0] = 1
    return n1


_gather_face_inlined = njit(cache=True, _nrt=False, inline="always")(_gather_face.py_func)


@njit(cache=True, _nrt=False)
def _bitlen(n):
    k = 0
    while n > 0:
        k += 1
        n >>= 1
    return k


# ------------------------------------------------------------------ boundary surface phase


@njit(cache=True, _nrt=False)
def _gather_edge(B, s, cand, cscore, cseq):
    """Candidates for the apex of the unvisited triangle on border edge s = {p, r}: apexes x
    that would close border edges {r, x} or {x, p}. Returns n1 (sorted like the tet phase)."""
    E, vhead, Q, bs = B
    p = np.int64(E[s * E_COLS + 0])
    r = np.int64(E[s * E_COLS + 1])
    n1 = np.int64(0)
    for k in range(2):
        u = r if k == 0 else p
        other = p if k == 0 else r
        node = vhead[u]
        while node != -1:
            g = _node_slot(node)
            c = _node_corner(node, g)
            if c < 2 and g != s:
                x = np.int64(E[g * E_COLS + 1 - c])
                if x != other:
                    n1 = _insert_candidate(cand, cscore, cseq, n1, x, E[g * E_COLS + E_SEQ])
            node = E[np.uint32(node)]  # an unsigned index: no wrap-around arithmetic on the chain
    _sort_candidates(cand, cscore, cseq, n1)
    return n1


@njit(cache=True, _nrt=False)
def _apply_triangle(B, u0, u1, u2, p, r):
    """Visit triangle (u0, u1, u2) (as wound in the output) whose edge {p, r} was the border edge
    just removed (p = r = -1 for a seed): each other edge closes a border edge or joins the
    border, directed as a consistently wound neighbour would hold it."""
    for k in range(3):
        h0 = u0 if k == 0 else (u1 if k == 1 else u2)
        h1 = u1 if k == 0 else (u2 if k == 1 else u0)
        apex = u2 if k == 0 else (u0 if k == 1 else u1)
        if (h0 == p and h1 == r) or (h0 == r and h1 == p):
            continue
        s = _find_edge(B, h0, h1)
        if s != -1:
            _remove(B, np.int64(2), s)
        else:
            _add(B, np.int64(2), h1, h0, apex, np.int64(-1))




@njit(cache=True, _nrt=False)
def _lookup_halfedge(hkey, hface, fvisited, p, r):
    """An unvisited face holding the directed edge p -> r (hkey sorted lexicographically), or -1."""
    lo = 0
    hi = hkey.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if hkey[mid, 0] < p or (hkey[mid, 0] == p and hkey[mid, 1] < r):
            lo = mid + 1
        else:
            hi = mid
    i = lo
    while i < hkey.shape[0] and hkey[i, 0] == p and hkey[i, 1] == r:
        if not fvisited[hface[i]]:
            return hface[i]
        i += 1
    return -1


@njit(cache=True, nogil=True)
def encode_boundary(st, out, faces, hkey, hface, n_points, B, dec_of, order, pred, out_faces, face_src):
    """Code the boundary surface ``faces`` (original ids). Fills ``dec_of`` (original -> decode id),
    ``order`` (decode -> original), ``pred`` (geometry predictors, decode ids) and ``out_faces``
    (faces in decode order and decode ids; ``face_src`` their rows in ``faces``). Returns
    (number of vertices, 0), or (-1, code) on error."""
    nf = faces.shape[0]
    probs = np.full(SM_SIZE, rc.PROB_INIT, np.uint16)
    fvisited = np.zeros(nf, np.bool_)
    cand = np.empty(MAX_C1, np.int64)
    cscore = np.empty(MAX_C1, np.int64)
    cseq = np.empty(MAX_C1, np.int64)
    nv = 0
    done = 0
    seed_ptr = 0
    prev_new = np.int64(0)
    prev_flip = 0
    while done < nf:
        s = _pop(B)
        if s == -1:
            while fvisited[seed_ptr]:
                seed_ptr += 1
            f = seed_ptr
            tri = np.empty(3, np.int64)
            for k in range(3):
                v = faces[f, k]
                if dec_of[v] == -1:
                    rc.enc_bit(st, out, probs, SM_SEED + k, BIT_NEW)
                    dec_of[v] = nv
                    order[nv] = v
                    for j in range(2):
                        pred[nv, j] = tri[j] if j < k else -1
                    nv += 1
                else:
                    rc.enc_bit(st, out, probs, SM_SEED + k, BIT_TABLE)
                    rc.enc_raw(st, out, dec_of[v], _bitlen(nv - 1))
                tri[k] = dec_of[v]
            fvisited[f] = True
            face_src[done] = f
            out_faces[done, 0] = tri[0]
            out_faces[done, 1] = tri[1]
            out_faces[done, 2] = tri[2]
            done += 1
            _apply_triangle(B, tri[0], tri[1], tri[2], np.int64(-1), np.int64(-1))
            continue
        E = B[0]
        p = np.int64(E[s * E_COLS + 0])
        r = np.int64(E[s * E_COLS + 1])
        n1 = _gather_edge(B, s, cand, cscore, cseq)
        _remove(B, np.int64(2), s)
        po = order[p]
        ro = order[r]
        f = _lookup_halfedge(hkey, hface, fvisited, min(po, ro), max(po, ro))
        if f == -1:
            return -1, 1
        xo = -1
        flip = 0
        for k in range(3):
            f0 = faces[f, k]
            f1 = faces[f, (k + 1) % 3]
            if (f0 == po and f1 == ro) or (f0 == ro and f1 == po):
                xo = faces[f, (k + 2) % 3]
                flip = 1 if f0 == ro else 0
        ctx = _score_context(n1, cscore, prev_new, np.int64(2))
        x = dec_of[xo]
        sym = ESC
        if x != -1:
            for i in range(n1):
                if cand[i] == x:
                    sym = i
                    break
        rc.enc_sym(st, out, probs, SM_C1 + ctx * 16, 4, sym)
        prev_new = np.int64(0)
        if sym == ESC:
            if x == -1:
                rc.enc_bit(st, out, probs, SM_NEW + (1 if n1 > 0 else 0), BIT_NEW)
                x = nv
                dec_of[xo] = nv
                order[nv] = xo
                pred[nv, 0] = p
                pred[nv, 1] = r
                pred[nv, 3] = E[s * E_COLS + 2]
                nv += 1
                prev_new = 1
            else:
                rc.enc_bit(st, out, probs, SM_NEW + (1 if n1 > 0 else 0), BIT_TABLE)
                rc.enc_raw(st, out, x, _bitlen(nv - 1))
        fvisited[f] = True
        face_src[done] = f
        rc.enc_bit(st, out, probs, SM_FLIP + prev_flip, flip)
        prev_flip = flip
        u0 = r if flip else p
        u1 = p if flip else r
        out_faces[done, 0] = u0
        out_faces[done, 1] = u1
        out_faces[done, 2] = x
        done += 1
        _apply_triangle(B, u0, u1, x, p, r)
        if not _room(B, np.int64(4), np.int64(4)):
            return -1, 2
    if B[3][BS_LIVE] != 0:
        return -1, 3
    rc.enc_finish(st, out)
    return nv, 0


@njit(cache=True, nogil=True)
def decode_boundary(st, data, nf, n_points, B, pred, out_faces):
    """Inverse of :func:`encode_boundary`; returns (number of vertices, status)."""
    probs = np.full(SM_SIZE, rc.PROB_INIT, np.uint16)
    cand = np.empty(MAX_C1, np.int64)
    cscore = np.empty(MAX_C1, np.int64)
    cseq = np.empty(MAX_C1, np.int64)
    rc.dec_init(st, data)
    nv = 0
    done = 0
    prev_new = np.int64(0)
    prev_flip = 0
    tri = np.empty(3, np.int64)
    while done < nf:
        if rc.dec_failed(st):
            return nv, ST_ERROR
        if not _room(B, np.int64(4), np.int64(4)):
            return nv, ST_GROW
        s = _pop(B)
        if s == -1:
            for k in range(3):
                if rc.dec_bit(st, data, probs, SM_SEED + k) == BIT_NEW:
                    if nv >= n_points:
                        return nv, ST_ERROR
                    for j in range(2):
                        pred[nv, j] = tri[j] if j < k else -1
                    tri[k] = nv
                    nv += 1
                else:
                    v = rc.dec_raw(st, data, _bitlen(nv - 1))
                    if v >= nv:
                        return nv, ST_ERROR
                    tri[k] = v
            if tri[0] == tri[1] or tri[1] == tri[2] or tri[0] == tri[2]:
                return nv, ST_ERROR
            out_faces[done, 0] = tri[0]
            out_faces[done, 1] = tri[1]
            out_faces[done, 2] = tri[2]
            done += 1
            _apply_triangle(B, tri[0], tri[1], tri[2], np.int64(-1), np.int64(-1))
            continue
        E = B[0]
        p = np.int64(E[s * E_COLS + 0])
        r = np.int64(E[s * E_COLS + 1])
        apex = np.int64(E[s * E_COLS + 2])
        n1 = _gather_edge(B, s, cand, cscore, cseq)
        _remove(B, np.int64(2), s)
        ctx = _score_context(n1, cscore, prev_new, np.int64(2))
        sym = rc.dec_sym(st, data, probs, SM_C1 + ctx * 16, np.int64(4))
        prev_new = np.int64(0)
        if sym < ESC:
            if sym >= n1:
                return nv, ST_ERROR
            x = cand[sym]
        elif rc.dec_bit(st, data, probs, SM_NEW + (1 if n1 > 0 else 0)) == BIT_NEW:
            if nv >= n_points:
                return nv, ST_ERROR
            x = nv
            pred[nv, 0] = p
            pred[nv, 1] = r
            pred[nv, 3] = apex
            nv += 1
            prev_new = 1
        else:
            x = rc.dec_raw(st, data, _bitlen(nv - 1))
            if x >= nv:
                return nv, ST_ERROR
        if x == p or x == r:
            return nv, ST_ERROR
        flip = rc.dec_bit(st, data, probs, SM_FLIP + prev_flip)
        prev_flip = flip
        u0 = r if flip else p
        u1 = p if flip else r
        out_faces[done, 0] = u0
        out_faces[done, 1] = u1
        out_faces[done, 2] = x
        done += 1
        _apply_triangle(B, u0, u1, x, p, r)
    if B[3][BS_LIVE] != 0 or rc.dec_failed(st):
        return nv, ST_ERROR
    return nv, ST_DONE


# ------------------------------------------------------------------ tet phase


_INSERTION_SORT_MAX = 48  # tet_neighbours' buckets up to this size are insertion-sorted


@njit(cache=True)
def _face_min_key(tets, t, k):
    """(smallest id, the other two as one key ``mid << 32 | largest``) of face k (opposite vertex k)
    of tet t; ids are below 2**31, so the key orders (mid, largest) lexicographically."""
    i0 = 1 if k == 0 else 0
    i1 = 2 if k <= 1 else 1
    i2 = 3 if k <= 2 else 2
    x = np.int64(tets[t, i0])
    y = np.int64(tets[t, i1])
    z = np.int64(tets[t, i2])
    if x > y:
        x, y = y, x
    if y > z:
        y, z = z, y
    if x > y:
        x, y = y, x
    return x, (y << 32) | z


@njit(cache=True, nogil=True)
def tet_neighbours(tets, nbr):
    """Fill ``nbr[t, k]`` with the tet across face k (opposite vertex k) of tet t, -1 on the
    boundary. Returns the number of faces shared by more than two tets (0 for a valid mesh).

    The faces are bucketed by their smallest vertex id (a CSR of face ids ``4 t + k``, int32: 16
    bytes per tet, where a hash of sorted triples took 280), and each bucket is sorted by the other
    two ids: twins end up side by side. Ids must lie in ``0 .. 2**31 - 1`` and ``4 m < 2**31``."""
    m = tets.shape[0]
    n = 0
    for t in range(m):
        for j in range(4):
            if tets[t, j] >= n:
                n = np.int64(tets[t, j]) + 1
    ptr = np.zeros(n + 1, np.int64)
    for t in range(m):
        for k in range(4):
            nbr[t, k] = -1
            x, _ = _face_min_key(tets, t, k)
            ptr[x + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:n].copy()
    faces = np.empty(4 * m, np.int32)
    for t in range(m):
        for k in range(4):
            x, _ = _face_min_key(tets, t, k)
            faces[fill[x]] = 4 * t + k
            fill[x] += 1
    widest = 0
    for v in range(n):
        widest = max(widest, ptr[v + 1] - ptr[v])
    keys = np.empty(widest, np.int64)
    ids = np.empty(widest, np.int32)
    bad = 0
    for v in range(n):
        lo = ptr[v]
        c = ptr[v + 1] - lo
        if c < 2:
            continue
        for i in range(c):
            f = faces[lo + i]
            _, key = _face_min_key(tets, f >> 2, f & 3)
            keys[i] = key
            ids[i] = f
        if c <= _INSERTION_SORT_MAX:  # a vertex's star: tens of faces
            for i in range(1, c):
                key, f = keys[i], ids[i]
                j = i
                while j > 0 and keys[j - 1] > key:
                    keys[j] = keys[j - 1]
                    ids[j] = ids[j - 1]
                    j -= 1
                keys[j] = key
                ids[j] = f
        else:  # a hub vertex (a fan around one id): no quadratic sort
            o = np.argsort(keys[:c], kind="mergesort")
            sk = keys[:c][o]
            si = ids[:c][o]
            keys[:c] = sk
            ids[:c] = si
        i = 0
        while i < c:
            j = i + 1
            while j < c and keys[j] == keys[i]:
                j += 1
            if j - i == 2:
                t0, k0, t1, k1 = ids[i] >> 2, ids[i] & 3, ids[i + 1] >> 2, ids[i + 1] & 3
                nbr[t0, k0] = t1
                nbr[t1, k1] = t0
            elif j - i > 2:
                bad += j - i - 2
            i = j
    return bad


@njit(cache=True, nogil=True)
def boundary_from_neighbours(tets, nbr, faces, owner):
    """Boundary faces (outward, in tet order: the order of ``TetMesh.boundary_faces``) and the
    tet owning each; returns their number."""
    n = 0
    for t in range(tets.shape[0]):
        for k in range(4):
            if nbr[t, k] == -1:
                if k == 0:
                    faces[n, 0], faces[n, 1], faces[n, 2] = tets[t, 1], tets[t, 2], tets[t, 3]
                elif k == 1:
                    faces[n, 0], faces[n, 1], faces[n, 2] = tets[t, 0], tets[t, 3], tets[t, 2]
                elif k == 2:
                    faces[n, 0], faces[n, 1], faces[n, 2] = tets[t, 0], tets[t, 1], tets[t, 3]
                else:
                    faces[n, 0], faces[n, 1], faces[n, 2] = tets[t, 0], tets[t, 2], tets[t, 1]
                owner[n] = t
                n += 1
    return n


@njit(cache=True, nogil=True)
def add_faces(B, faces, apex):
    """Put faces on the border in order (apex -1: the original boundary); returns the slots."""
    slots = np.empty(faces.shape[0], np.int64)
    for i in range(faces.shape[0]):
        slots[i] = _add(B, np.int64(3), faces[i, 0], faces[i, 1], faces[i, 2], apex)
    return slots


# ------------------------------------------------------------------ tet phase: the steps every coding shares
#
# The tet coder below and the frozen coding 1 (:mod:`gatun_py.codec.legacy.tets1`) walk the border
# the same way and differ only in how they rank the candidates and order the case (c) list. The
# steps they share are these helpers, inlined by numba into each coder's loop (a call would pass
# the border's arrays and the candidate lists as some forty words on the stack).

_pop_inlined = njit(cache=True, _nrt=False, inline="always")(_pop.py_func)


def candidate_lists():
    """A tet coder's scratch for one tet's candidates, allocated once per call of its loop:
    (cand, cscore, cseq, ckey, ccls, c2, c2seq, seen, cface, cface_full), the edge candidates with
    their scores, ages, ranking keys and classes (coding 1 keeps the gather order in ``ckey``),
    the vertex-adjacent list with its ages and the table of vertices met, the faces on each gate
    edge of every candidate and whether that record overflowed."""
    return (np.empty(MAX_C1, np.int64), np.empty(MAX_C1, np.int64), np.empty(MAX_C1, np.int64),
            np.empty(MAX_C1, np.int64), np.empty(MAX_C1, np.int64), np.empty(MAX_C2, np.int64),
            np.empty(MAX_C2, np.int64), np.empty((2, SEEN_SLOTS), np.int64), np.empty((MAX_C1, 3), np.int64),
            np.zeros(1, np.int64))


@njit(cache=True, _nrt=False, inline="always")
def _face(E, s):
    """The vertices (a, b, c) of border face ``s`` and the apex behind it, as int64."""
    return (np.int64(E[s * E_COLS + 0]), np.int64(E[s * E_COLS + 1]), np.int64(E[s * E_COLS + 2]),
            np.int64(E[s * E_COLS + 3]))


@njit(cache=True, _nrt=False, inline="always")
def _no_room(bs, qcap):
    """Whether the border lacks the room one more tet may need (4 slots, 4 queue entries)."""
    return bs[BS_NFREE] < 4 or qcap - (bs[BS_QTAIL] - bs[BS_QHEAD]) < 4


@njit(cache=True, _nrt=False, inline="always")
def _set_refs(pred, row, a, b, c, behind):
    """A new interior vertex's geometry refs: the face it closes and the apex behind it."""
    pred[row, 0] = a
    pred[row, 1] = b
    pred[row, 2] = c
    pred[row, 3] = behind


@njit(cache=True, _nrt=False, inline="always")
def _kind_context(n1, prev_esc):
    """Context of the escape's kind symbol: any candidates, whether the previous tet escaped."""
    return 4 * ((1 if n1 > 0 else 0) + 2 * prev_esc)


@njit(cache=True, _nrt=False, inline="always")
def _emit_tet(out_tets, row, a, b, c, d, flip):
    """Write the tet of face (a, b, c) and fourth vertex d, (a, c, b, d) unless ``flip``; returns
    its second and third vertices (t1, t2)."""
    t1 = b if flip else c
    t2 = c if flip else b
    out_tets[row, 0] = a
    out_tets[row, 1] = t1
    out_tets[row, 2] = t2
    out_tets[row, 3] = d
    return t1, t2


# ---- encoders

@njit(cache=True, _nrt=False, inline="always")
def _target(tets, tgt, tvisited, order, s, a, b, c):
    """The unvisited tet behind border face ``s`` (decode ids a, b, c), marked visited, and its
    fourth vertex (original id): (t, do), t = -1 when there is none."""
    ao = order[a]
    bo = order[b]
    co = order[c]
    t = tgt[s]
    if t < 0 or tvisited[t]:
        return -1, -1
    tvisited[t] = True
    do = -1
    for k in range(4):
        w = tets[t, k]
        if w != ao and w != bo and w != co:
            do = w
    return t, do


@njit(cache=True, _nrt=False, inline="always")
def _enc_next(B, tets, tgt, tvisited, order, dec_of):
    """The encoder's next face: (0, its slot, the tet behind it, the tet's fourth vertex as
    original and decode id (-1: new), the face's vertices a, b, c and the apex behind it), or an
    error status first (1: the border emptied, 2: no unvisited tet behind the face)."""
    s = _pop_inlined(B)
    if s == -1:
        return 1, s, -1, -1, -1, -1, -1, -1, -1
    a, b, c, behind = _face(B[0], s)
    t, do = _target(tets, tgt, tvisited, order, s, a, b, c)
    if t < 0:
        return 2, s, t, -1, -1, a, b, c, behind
    return 0, s, t, do, dec_of[do], a, b, c, behind


@njit(cache=True, _nrt=False, inline="always")
def _enc_attach(st, out, probs, flip_model, prev_flip, flip, out_tets, done, a, b, c, d, B, tets, nbr, tgt, order, t):
    """Code the orientation bit, write the tet, attach it to the border and note the tets behind
    its new border faces; 4 when the border has no room left for the next tet, else 0."""
    rc.enc_bit(st, out, probs, flip_model + prev_flip, flip)
    t1, t2 = _emit_tet(out_tets, done, a, b, c, d, flip)
    s0, s1, s2 = _apply_tet(B, a, t1, t2, d)
    _set_targets(tets, nbr, tgt, order, t, a, t1, t2, s0, s1, s2)
    return 4 if _no_room(B[3], B[2].shape[0]) else 0


@njit(cache=True, _nrt=False, inline="always")
def _enc_end(st, out, B):
    """Finish the tet stream: 0, or 5 with faces left on the border after the last tet."""
    if B[3][BS_LIVE] != 0:
        return 5
    rc.enc_finish(st, out)
    return 0


@njit(cache=True, _nrt=False, inline="always")
def _enc_new_vertex(st, out, probs, kctx, dec_of, order, pred, nv, do, a, b, c, behind):
    """Code case (b), a new vertex: it gets decode id ``nv`` and its refs."""
    rc.enc_sym(st, out, probs, kctx, 2, KIND_NEW)
    dec_of[do] = nv
    order[nv] = do
    _set_refs(pred, nv, a, b, c, behind)


@njit(cache=True, _nrt=False, inline="always")
def _enc_known_vertex(st, out, probs, kctx, c2_model, c2, n2, d, nv, syms, done):
    """Code a known vertex d that is no candidate: case (c), its index in the vertex-adjacent list
    ``c2[:n2]``, else case (d), its decode id."""
    j = -1
    for i in range(n2):
        if c2[i] == d:
            j = i
            break
    if j >= 0:
        rc.enc_sym(st, out, probs, kctx, 2, KIND_VERTEX_ADJACENT)
        syms[done] = SYM_VERTEX_ADJACENT
        rc.enc_uint(st, out, probs, c2_model + (rc.INT_MODEL_SIZE if n2 > 8 else 0), j)
    else:
        rc.enc_sym(st, out, probs, kctx, 2, KIND_TABLE)
        syms[done] = SYM_TABLE
        rc.enc_raw(st, out, d, _bitlen(nv - 1))


@njit(cache=True, _nrt=False, inline="always")
def _set_targets(tets, nbr, tgt, order, t, a, t1, t2, s0, s1, s2):
    """The tets behind the faces of tet t that joined the border (slots s0, s1, s2 opposite a, t1,
    t2; -1 where a face closed one): t's neighbours across them."""
    for k in range(3):
        slot = s0 if k == 0 else (s1 if k == 1 else s2)
        if slot >= 0:
            wo = order[a] if k == 0 else (order[t1] if k == 1 else order[t2])
            kk = 0 if tets[t, 0] == wo else (1 if tets[t, 1] == wo else (2 if tets[t, 2] == wo else 3))
            tgt[slot] = nbr[t, kk]


@njit(cache=True, _nrt=False)
def _tet_flip(tets, t, ao, bo, co, do):
    """Parity of tet t's vertex order against (a, c, b, d) (original ids): 1 where the mesh is
    folded (zero-volume tets), else 0."""
    w0 = tets[t, 0]
    w1 = tets[t, 1]
    w2 = tets[t, 2]
    inv = 0
    for i in range(4):
        wi = ao if i == 0 else (co if i == 1 else (bo if i == 2 else do))
        pi = 0 if wi == w0 else (1 if wi == w1 else (2 if wi == w2 else 3))
        for j in range(i + 1, 4):
            wj = ao if j == 0 else (co if j == 1 else (bo if j == 2 else do))
            pj = 0 if wj == w0 else (1 if wj == w1 else (2 if wj == w2 else 3))
            if pi > pj:
                inv += 1
    return inv & 1


# ---- resumable decoders: ``tstate`` int64 [vertices known, tets done, prev_esc, prev_flip, pred_base]

@njit(cache=True, _nrt=False, inline="always")
def _stop(st, n_out, out_tets, bs, qcap):
    """Why a decoder stops before its next tet: ST_ERROR (the range decoder failed), ST_BATCH
    (``out_tets`` is full) or ST_GROW (the border needs room); -1 to go on."""
    if st[rc.DEC_ERROR] != 0 or st[rc.DEC_OVERRUN] != 0:
        return ST_ERROR
    if n_out >= out_tets.shape[0]:
        return ST_BATCH
    if _no_room(bs, qcap):
        return ST_GROW
    return -1


@njit(cache=True, _nrt=False, inline="always")
def _next_face(st, n_out, out_tets, B):
    """A decoder's next face: (slot, -1), or (-1, the status it stops with)."""
    stop = _stop(st, n_out, out_tets, B[3], B[2].shape[0])
    if stop >= 0:
        return -1, stop
    s = _pop_inlined(B)
    return s, (ST_ERROR if s == -1 else -1)


@njit(cache=True, _nrt=False, inline="always")
def _dec_escape(st, data, probs, kind_model, n1, prev_esc, pred, pred_base, nv, limit, a, b, c, behind):
    """Decode what follows an escape: (kind, d, vertices known). Case (b) gives the new vertex its
    decode id and refs, case (d) reads a decode id; d is -1 for case (c), which the caller
    decodes, and on an error (a vertex id past ``limit`` or not yet known, an unknown kind)."""
    kind = rc.dec_sym(st, data, probs, kind_model + _kind_context(n1, prev_esc), 2)
    d = -1
    if kind == KIND_NEW:
        if nv < limit:
            d = nv
            _set_refs(pred, nv - pred_base, a, b, c, behind)
            nv += 1
    elif kind == KIND_TABLE:
        x = rc.dec_raw(st, data, _bitlen(nv - 1))
        if x < nv:
            d = x
    return kind, d, nv


@njit(cache=True, _nrt=False, inline="always")
def _dec_index(st, data, probs, c2_model, n2):
    """Case (c)'s index into a vertex-adjacent list of ``n2``, or -1 past its end."""
    j = rc.dec_uint(st, data, probs, c2_model + (rc.INT_MODEL_SIZE if n2 > 8 else 0))
    return j if j < n2 else -1


@njit(cache=True, _nrt=False, inline="always")
def _end_run(st, status, B, tstate, nv, done, prev_esc, prev_flip):
    """Keep a decoder's state for its next call; the final status (a finished stream must leave
    the border empty and the range decoder sound)."""
    if status == ST_DONE and (B[3][BS_LIVE] != 0 or rc.dec_failed(st)):
        status = ST_ERROR
    tstate[0] = nv
    tstate[1] = done
    tstate[2] = prev_esc
    tstate[3] = prev_flip
    return status


# ------------------------------------------------------------------ tet phase (tet coding 2)
#
# Each candidate gets a *class* from what the decoder knows: its score (faces of T the tet would
# close), how many decoded tets already hold it, whether it is a boundary vertex, and how many
# decoded tets hold the ends of the gate edges it is adjacent across (the fuller the edge's star,
# the likelier the tet closes it). The score alone does not see how full the stars already are
# (bench/sections/codec.md). Each class has an adaptive probability of being the fourth vertex
# (updated after every tet, the same way in encoder and decoder); candidates are ranked by it, and
# the index is coded in a context of the two best candidates' probabilities. An escape's
# vertex-adjacent list (case c) is ordered by decoded tets, fewest first, then by age.

CLS_VD_DIV, CLS_VD_LEVELS = 3, 16  # decoded tets on the candidate, /3, capped
CLS_EV_DIV, CLS_EV_LEVELS = 6, 16  # decoded tets on the ends of its fullest gate edge, /6, capped
N_CLASS = 3 * CLS_VD_LEVELS * 2 * CLS_EV_LEVELS
VDEC_MAX = 255
# the class's levels of a count (division by a constant, as tables: one load instead)
VD_LEVEL = np.minimum(np.arange(VDEC_MAX + 1) // CLS_VD_DIV, CLS_VD_LEVELS - 1).astype(np.int64)
EV_LEVEL = np.minimum(np.arange(CLS_EV_DIV * CLS_EV_LEVELS) // CLS_EV_DIV, CLS_EV_LEVELS - 1).astype(np.int64)
RANK_SHIFT = 5  # adaptation rate of a class's probability (as the range coder's models)
RANK_INIT = (rc.PROB_ONE // 4, (rc.PROB_ONE * 15) // 16, rc.PROB_ONE - 64)  # by score 1, 2, 3
P_LEVELS = 8  # a candidate probability's quantisation in the index context (+1: no candidate)
N_C1_CTX = 5 * (P_LEVELS + 1) * (P_LEVELS + 1) * 2
TM_C1 = 0
TM_KIND = TM_C1 + N_C1_CTX * 16
TM_C2 = TM_KIND + 8 * 4
TM_FLIP = TM_C2 + 2 * rc.INT_MODEL_SIZE
TM_SIZE = TM_FLIP + 4


def new_rank_model() -> np.ndarray:
    """The class probabilities at the start of a tet stream."""
    p = np.empty(N_CLASS, np.uint16)
    per_score = N_CLASS // 3
    for k in range(3):
        p[k * per_score:(k + 1) * per_score] = RANK_INIT[k]
    return p


@njit(cache=True, _nrt=False)
def _rank_candidates(cand, cscore, cseq, cface, n1, vdec, nbv, a, b, c, rankp, ckey, ccls, prev_esc):
    """Class (``ccls``) and ranking key (``ckey``: the class probability, then the score, then the
    age; distinct, higher = better) of each gathered candidate. Returns (the index symbol's context,
    gather position of the best candidate, of the second best; -1 where there is none). The
    decoder needs the full order only for an index past 1 (:func:`_nth_candidate`)."""
    va = np.int64(vdec[a])
    vb = np.int64(vdec[b])
    vc = np.int64(vdec[c])
    best = -1
    second = -1
    kbest = np.int64(-1)
    ksecond = np.int64(-1)
    ev_bc = vb + vc
    ev_ab = va + vb
    ev_ac = va + vc
    for i in range(n1):
        # branch-free: which gate edges hold the candidate is data, not a predictable pattern
        e0 = ev_bc if cface[i, EDGE_BC] != -1 else 0
        e1 = ev_ab if cface[i, EDGE_AB] != -1 else 0
        e2 = ev_ac if cface[i, EDGE_AC] != -1 else 0
        ev = max(e0, max(e1, e2))
        sc = min(cscore[i], 3)
        x = cand[i]
        cls = (((sc - 1) * CLS_VD_LEVELS + VD_LEVEL[vdec[x]]) * 2 + (1 if x < nbv else 0)) * CLS_EV_LEVELS \
            + (EV_LEVEL[ev] if ev < EV_LEVEL.shape[0] else CLS_EV_LEVELS - 1)
        ccls[i] = cls
        # sequence numbers are below 2**31 and distinct per face, hence per candidate
        key = (np.int64(rankp[cls]) << 40) | (sc << 32) | (MAX_SEQ - cseq[i])
        ckey[i] = key
        gt1 = key > kbest
        gt2 = key > ksecond
        second = best if gt1 else (i if gt2 else second)
        ksecond = kbest if gt1 else (key if gt2 else ksecond)
        best = i if gt1 else best
        kbest = key if gt1 else kbest
    q0 = 0
    q1 = 0
    if best >= 0:
        q0 = 1 + (np.int64(rankp[ccls[best]]) * P_LEVELS >> rc.PROB_BITS)
    if second >= 0:
        q1 = 1 + (np.int64(rankp[ccls[second]]) * P_LEVELS >> rc.PROB_BITS)
    nn = n1 if n1 < 4 else 4
    return ((nn * (P_LEVELS + 1) + q0) * (P_LEVELS + 1) + q1) * 2 + prev_esc, best, second


@njit(cache=True, _nrt=False)
def _rank_of(ckey, n1, i):
    """Rank (0 = best) of gather position ``i`` among the candidates' keys."""
    r = 0
    for j in range(n1):
        if ckey[j] > ckey[i]:
            r += 1
    return r


@njit(cache=True, _nrt=False)
def _nth_candidate(ckey, n1, r):
    """Gather position of the candidate of rank ``r`` (< n1)."""
    for i in range(n1):
        if _rank_of(ckey, n1, i) == r:
            return i
    return -1


@njit(cache=True, _nrt=False)
def _learn_ranks(rankp, ckey, ccls, n1, hit):
    """After a tet: the class of gather position ``hit`` (-1: none) was the fourth vertex, the
    others were not. Each update starts from the probability the ranking read (in ``ckey``), and
    the hit's is written last: a class held by several candidates ends the same in any order."""
    for i in range(n1):  # the hit's miss update too: overwritten below
        p = ckey[i] >> 40
        rankp[ccls[i]] = p - (p >> RANK_SHIFT)
    if hit >= 0:
        p = ckey[hit] >> 40
        rankp[ccls[hit]] = p + ((rc.PROB_ONE - p) >> RANK_SHIFT)


@njit(cache=True, _nrt=False)
def _order_by_decoded(c2, n2, vdec):
    """Stable re-order of the vertex-adjacent list (by age) by decoded tets, fewest first."""
    for i in range(1, n2):
        x = c2[i]
        vx = vdec[x]
        j = i - 1
        while j >= 0 and vdec[c2[j]] > vx:
            c2[j + 1] = c2[j]
            j -= 1
        c2[j + 1] = x


@njit(cache=True, _nrt=False)
def _select_vertex_adjacent(c2, c2seq, n2, vdec, j):
    """Entry ``j`` (< n2) of the case (c) order without sorting the list: the list as
    :func:`_walk_vertex_adjacent` leaves it, sorted stably by sequence (:func:`_gather_vertex_adjacent`)
    and then by decoded tets (:func:`_order_by_decoded`), is the order of the distinct keys
    (decoded tets, sequence, position met), so entry j is the (j+1)-th smallest key. The decoder
    reads one entry, mostly one of the first few: j + 1 passes over the list instead of two
    insertion sorts of an input that comes newest first."""
    prev = np.int64(-1)
    for _ in range(j + 1):
        cur = np.int64(1) << 62
        for i in range(n2):
            # decoded tets < 2**8, sequence numbers < 2**31, positions < 2**6 (MAX_C2)
            key = (np.int64(vdec[c2[i]]) << 37) | (c2seq[i] << 6) | i
            if key > prev and key < cur:
                cur = key
        prev = cur
    return c2[prev & 63]


@njit(cache=True, _nrt=False)
def _count_decoded(vdec, a, b, c, d):
    """One more decoded tet on each of its vertices (uint8 counts, saturating: the classes look
    no further than 47, and a byte per vertex keeps the counts in cache)."""
    vdec[a] += vdec[a] < VDEC_MAX
    vdec[b] += vdec[b] < VDEC_MAX
    vdec[c] += vdec[c] < VDEC_MAX
    vdec[d] += vdec[d] < VDEC_MAX


def encode_tets(st, out, tets, nbr, tgt, B, dec_of, order, pred, nv0, out_tets, syms, rankp, vdec):
    """Code the tets growing inward from the border ``B`` (the boundary, in decode ids).

    ``tets`` and ``nbr`` (:func:`tet_neighbours`) use original ids, ``tgt[slot]`` is the
    unvisited tet behind each border face; ``dec_of``/``order`` map between original and decode
    ids and are extended for the new (interior) vertices, numbered from ``nv0`` on, with their
    predictors in ``pred``. ``rankp`` holds the class probabilities (:func:`new_rank_model`),
    ``vdec`` (uint8, zeros) the decoded-tet counts by decode id. ``out_tets`` receives the tets
    in decode order and decode ids, ``syms`` each tet's case: the candidate's rank (paper case
    a), or ESC + 0 / 1 / 2 for cases b / c / d. Returns (vertices, status)."""
    return _encode_tets_run(st, out, tets, nbr, tgt, B, dec_of, order, pred, int(nv0), out_tets, syms, rankp, vdec,
                            candidate_lists())


@njit(cache=True, nogil=True)
def _encode_tets_run(st, out, tets, nbr, tgt, B, dec_of, order, pred, nv0, out_tets, syms, rankp, vdec, scratch):
    """The loop of :func:`encode_tets`, with its candidate lists in ``scratch``."""
    cand, cscore, cseq, ckey, ccls, c2, c2seq, seen, cface, cface_full = scratch
    probs = np.full(TM_SIZE, rc.PROB_INIT, np.uint16)
    tvisited = np.zeros(tets.shape[0], np.bool_)
    nv, prev_esc, prev_flip = nv0, 0, 0
    for done in range(tets.shape[0]):
        err, s, t, do, d, a, b, c, behind = _enc_next(B, tets, tgt, tvisited, order, dec_of)
        if err:
            return nv, err
        n1 = _gather_face(B, s, cand, cscore, cseq, cface, cface_full)
        _remove(B, np.int64(3), s)
        ctx, best, second = _rank_candidates(cand, cscore, cseq, cface, n1, vdec, nv0, a, b, c, rankp, ckey, ccls,
                                             prev_esc)
        sym = ESC
        hit = -1
        if d != -1:
            for i in range(n1):
                if cand[i] == d:
                    hit = i
                    sym = _rank_of(ckey, n1, i)
                    break
        flip = _tet_flip(tets, t, order[a], order[b], order[c], do)
        rc.enc_sym(st, out, probs, TM_C1 + ctx * 16, 4, sym)
        syms[done] = sym
        if sym == ESC:
            kctx = TM_KIND + _kind_context(n1, prev_esc)
            if d == -1:
                _enc_new_vertex(st, out, probs, kctx, dec_of, order, pred, nv, do, a, b, c, behind)
                d = nv
                nv += 1
            else:
                n2 = _gather_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen)
                _order_by_decoded(c2, n2, vdec)
                _enc_known_vertex(st, out, probs, kctx, TM_C2, c2, n2, d, nv, syms, done)
            prev_esc = 1
        else:
            prev_esc = 0
        _learn_ranks(rankp, ckey, ccls, n1, hit)
        _count_decoded(vdec, a, b, c, d)
        err = _enc_attach(st, out, probs, TM_FLIP, prev_flip, flip, out_tets, done, a, b, c, d, B, tets, nbr, tgt,
                          order, t)
        if err:
            return nv, err
        prev_flip = flip
    return nv, _enc_end(st, out, B)


def decode_tets(st, data, probs, rankp, vdec, nbv, m, n_limit, B, pred, tstate, out_tets):
    """Resumable inverse of :func:`encode_tets`.

    ``tstate`` int64 array: [vertices known, tets done, prev_esc, prev_flip, pred_base];
    ``probs``, the class probabilities ``rankp`` (:func:`new_rank_model`) and the decoded-tet
    counts ``vdec`` (uint8 per vertex, zeros at the start) persist between calls, ``nbv`` is the
    number of boundary vertices. Decodes until ``out_tets`` is full (status ST_BATCH), the border
    needs more room (ST_GROW: enlarge it and call again), all ``m`` tets are done (ST_DONE) or
    the data is inconsistent (ST_ERROR). New vertices (ids < ``n_limit``) get their predictors in
    ``pred``, row ``decode id - pred_base`` (a window of the newest vertices, or the whole table
    with ``pred_base`` 0); a vertex past the window is an error, never a write out of bounds.
    Returns (number of tets written to ``out_tets``, status)."""
    # scratch in Python, the loop in the compiled kernel (which releases the GIL): a compiled
    # wrapper here cost most of a second of a first run's compiling, and a call is per batch
    return _decode_tets_run(st, data, probs, rankp, vdec, int(nbv), int(m), int(n_limit), B, pred, tstate, out_tets,
                            candidate_lists())


_rank_candidates_inlined = njit(cache=True, _nrt=False, inline="always")(_rank_candidates.py_func)


# compiled without the runtime's reference counting (it allocates nothing): the helpers inlined
# into its loop would otherwise increment and decrement the border arrays' counts on every tet
@njit(cache=True, nogil=True, _nrt=False)
def _decode_tets_run(st, data, probs, rankp, vdec, nbv, m, n_limit, B, pred, tstate, out_tets, scratch):
    """The loop of :func:`decode_tets`, with its candidate lists in ``scratch``."""
    cand, cscore, cseq, ckey, ccls, c2, c2seq, seen, cface, cface_full = scratch
    nv, done, prev_esc, prev_flip, pred_base = tstate[0], tstate[1], tstate[2], tstate[3], tstate[4]
    # new vertices get ids below this (the header's count, the end of the refs window, of vdec)
    limit = min(n_limit, pred_base + pred.shape[0], vdec.shape[0])
    if pred_base > nv:
        return 0, ST_ERROR
    n_out = 0
    status = ST_DONE
    E, vhead, Q, bs = B
    qcap = Q.shape[0]
    while done < m:
        s, stop = _next_face(st, n_out, out_tets, B)
        if stop >= 0:
            status = stop
            break
        # the faces to come are known (FIFO): fetch their rows and list heads ahead of the walks
        hq = bs[BS_QHEAD]
        _prefetch(E, Q[(hq + PF_ROW) & (qcap - 1), 0] * E_COLS)
        s_next = Q[(hq + PF_HEAD) & (qcap - 1), 0]  # a handed-out slot (or 0): a row within E
        _prefetch(vhead, E[s_next * E_COLS + 0])
        _prefetch(vhead, E[s_next * E_COLS + 1])
        s_next = Q[(hq + PF_NODE) & (qcap - 1), 0]
        for corner in range(2):
            v = E[s_next * E_COLS + corner]
            if v >= 0 and v < vhead.shape[0]:
                _prefetch(E, np.uint32(vhead[v]))  # a node id is an offset in E
        s_next = Q[(hq + PF_NODE2) & (qcap - 1), 0]
        for corner in range(2):
            v = E[s_next * E_COLS + corner]
            if v >= 0 and v < vhead.shape[0]:
                node = vhead[v]
                if node != -1 and np.uint32(node) < E.shape[0]:
                    _prefetch(E, np.uint32(E[np.uint32(node)]))
        a, b, c, behind = _face(E, s)
        cface_full[0] = 0
        n1 = _gather_face_inlined(B, s, cand, cscore, cseq, cface, cface_full)
        _remove(B, 3, s)
        ctx, best, second = _rank_candidates_inlined(cand, cscore, cseq, cface, n1, vdec, nbv, a, b, c, rankp,
                                                     ckey, ccls, prev_esc)
        sym = rc.dec_sym(st, data, probs, TM_C1 + ctx * 16, 4)
        d = -1
        hit = -1
        if sym < ESC:
            if sym >= n1:
                status = ST_ERROR
                break
            hit = best if sym == 0 else (second if sym == 1 else _nth_candidate(ckey, n1, sym))
            if hit < 0:  # no candidate of that rank (keys are distinct in any border: never)
                status = ST_ERROR
                break
            d = cand[hit]
            prev_esc = 0
        else:
            kind, d, nv = _dec_escape(st, data, probs, TM_KIND, n1, prev_esc, pred, pred_base, nv, limit,
                                      a, b, c, behind)
            if kind == KIND_VERTEX_ADJACENT:
                n2 = _walk_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen)
                j = _dec_index(st, data, probs, TM_C2, n2)
                if j >= 0:
                    d = _select_vertex_adjacent(c2, c2seq, n2, vdec, j)
            if d < 0:
                status = ST_ERROR
                break
            prev_esc = 1
            # a corrupt stream may escape to a candidate: attach it by its gathered faces
            for i in range(n1):
                if cand[i] == d:
                    hit = i
                    break
        if d == a or d == b or d == c:
            status = ST_ERROR
            break
        _learn_ranks(rankp, ckey, ccls, n1, hit if sym < ESC else -1)
        flip = rc.dec_bit(st, data, probs, TM_FLIP + prev_flip)
        prev_flip = flip
        t1, t2 = _emit_tet(out_tets, n_out, a, b, c, d, flip)
        n_out += 1
        done += 1
        _count_decoded(vdec, a, b, c, d)
        if hit >= 0:  # faces opposite a, t1, t2: on edges (t1, t2) = (b, c), (a, t2) and (a, t1)
            f0 = cface[hit, EDGE_BC]
            f1 = cface[hit, EDGE_AC if flip else EDGE_AB]
            f2 = cface[hit, EDGE_AB if flip else EDGE_AC]
        elif cface_full[0] == 0:
            f0 = f1 = f2 = -1
        else:
            f0, f1, f2 = _closing_faces(B, a, t1, t2, d)  # rare: a call
        # as _attach_tet, the additions and removals written out (once each: a loop over the
        # three faces, so that the inlined code compiles once)
        for j in range(3):
            f = f0 if j == 0 else (f1 if j == 1 else f2)
            if f != -1:
                _remove_inlined(B, 3, f)
            else:  # (t1, t3, t2, t0), (t0, t2, t3, t1), (t0, t3, t1, t2): reversed outward faces
                _add_inlined(B, 3, t1 if j == 0 else a, d if j != 1 else t2, t2 if j == 0 else (d if j == 1 else t1),
                             a if j == 0 else (t1 if j == 1 else t2))
    status = _end_run(st, status, B, tstate, nv, done, prev_esc, prev_flip)
    return n_out, status
