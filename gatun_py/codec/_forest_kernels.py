"""Numba kernels of the format-3 merge-forest coding (see :mod:`.forest` for the layout).

The encoder and the decoder share every model decision through the same helpers: the vertex
adjacency of the level's mesh (:func:`adjacency`), the rank buckets (:func:`bucket_bounds`), the
bucket context of a vertex from its already decoded neighbours (:func:`_bucket_context`) and the
candidate parents of a merge (:func:`_tier0`, :func:`_tier1`, ordered by :func:`_precedes`).
``tests/naive_forest.py`` is the slow reference that produces the same bytes with Python sets and
integers.

Decode speed (the same bytes as the first kernels of format 3, about 1.3-1.5 times faster): the
replay of the merges in rank order is memory-bound, so the kernels keep its working set small and
its work proportional to what a merge needs: a candidate list is counted unordered (searching the
short list itself, or with per-list stamps that need no reset) and only the decoded index is
selected from it; tier 1 is built only after a tier-0 miss; the free ranks are one Fenwick tree
per bucket; the adjacency comes from the vertex-to-tet incidence, rows unsorted. The small helpers
are compiled without NRT (``_nrt=False``): they never allocate, and a call then skips the atomic
reference counting of each array argument.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..mesh._quadric_kernels import sorted4, spatial_volume, tet_quadric_terms
from .rangecoder import DEC_ERROR, dec_below, dec_bit, dec_failed, dec_init, dec_sym, enc_below, enc_bit, enc_finish, enc_sym

ROOT_SYMBOL = 63  # bucket symbol of a vertex that is never merged
BUCKET_BITS = 6
CONTEXT_CAP = 6  # bucket symbols above this (and roots) look alike to the context
DEGREE_CLASSES = 7  # neighbour count // 4, capped: well-connected vertices merge later
N_BUCKET_CONTEXTS = (CONTEXT_CAP + 2) * 2 * DEGREE_CLASSES
SMALL_LIST = 32  # candidate lists up to this long code the index with a model, longer ones uniformly
FLAG_CONTEXTS = 16
_SHORT_ROW = 32  # tier 0 of a vertex with at most this many neighbours is counted without a table
# model layout: bucket symbols | "parent is in the list" flags | index symbols, per tier (2)
_FLAG_BASE = N_BUCKET_CONTEXTS << BUCKET_BITS
_INDEX_BASE = _FLAG_BASE + 2 * FLAG_CONTEXTS
MODEL_SIZE = _INDEX_BASE + 2 * (SMALL_LIST + 1) * SMALL_LIST


@njit(cache=True, nogil=True)
def adjacency(tets, n):
    """Vertex neighbours of a tet mesh as CSR ``(start, nbrs)``, each row unique (in no set order:
    every model decision of the coding is independent of the order inside a row).

    Ids are not checked here: the callers pass tets that the connectivity coder produced or
    checked (``0 <= id < n``).
    """
    # vertex -> incident tets first (4 scattered writes per tet instead of 12 neighbour entries),
    # then each vertex's row straight from its tets, a neighbour listed once (the tag says which
    # vertex saw it last)
    m = tets.shape[0]
    inc_start = np.zeros(n + 1, np.int64)
    for t in range(m):
        for i in range(4):
            inc_start[tets[t, i] + 1] += 1
    for v in range(n):
        inc_start[v + 1] += inc_start[v]
    fill = inc_start[:-1].copy()
    inc = np.empty(4 * m, np.int32)
    for t in range(m):
        for i in range(4):
            a = tets[t, i]
            inc[fill[a]] = t
            fill[a] += 1
    start = np.empty(n + 1, np.int64)
    # every incidence lists 3 neighbours, and a row also writes (without counting) the vertex
    # itself one slot past the last counted entry: 12m + 1 slots
    nbrs = np.empty(12 * m + 1, np.int32)
    seen_by = np.full(n, -1, np.int32)
    out = 0
    for v in range(n):
        start[v] = out
        seen_by[v] = v
        for j in range(inc_start[v], inc_start[v + 1]):
            t = inc[j]
            for i in range(4):
                x = tets[t, i]
                # without a branch: a neighbour is new about one time in five, unpredictably
                nbrs[out] = x
                out += seen_by[x] != v
                seen_by[x] = v
    start[n] = out
    # a view, not a copy: the untouched tail of the buffer is never paged in, and a copy would
    # page in and write the rows a second time
    return start, nbrs[:out]


@njit(cache=True, nogil=True)
def bucket_bounds(n, k):
    """Rank buckets ``[b[j], b[j+1])``: each takes half of the vertices still unmerged (the
    1 - 1/2^i levels), the last ends at k. Returns the bounds (length = buckets + 1)."""
    b = np.zeros(64, np.int64)
    nb = 0
    while b[nb] < k:
        step = (n - b[nb]) // 2
        b[nb + 1] = min(b[nb] + (step if step > 1 else 1), k)
        nb += 1
    return b[:nb + 1].copy()


@njit(cache=True, nogil=True, _nrt=False)
def _bucket_context(start, nbrs, boundary, v, symbol):
    """Context of v's bucket symbol: whether v is on the boundary, its degree class, and the
    smallest bucket symbol among its decoded (smaller-id) neighbours, capped (0: none)."""
    lowest = CONTEXT_CAP + 1
    seen = False
    for i in range(start[v], start[v + 1]):
        u = nbrs[i]
        if u < v:
            seen = True
            if symbol[u] < lowest:
                lowest = symbol[u]
    degree = start[v + 1] - start[v]
    own = (1 if boundary[v] else 0) * DEGREE_CLASSES + min(degree >> 2, DEGREE_CLASSES - 1)
    return own * (CONTEXT_CAP + 2) + (1 + min(lowest, CONTEXT_CAP) if seen else 0)


# Free ranks: one Fenwick tree of 0/1 counts per rank bucket, all in one array (bucket s's tree is
# ``tree[bounds[s] + s : bounds[s + 1] + s + 1]``, 1-based inside), plus the free count of every
# bucket. A rank's position among its bucket's free ranks then costs two walks over a tree of the
# bucket's size, instead of four over the tree of all ranks.


@njit(cache=True, nogil=True)
def _free_ranks(bounds):
    """(tree, free count per bucket) with every rank of every bucket free."""
    nb = bounds.shape[0] - 1
    tree = np.empty(bounds[nb] + nb, np.int32)
    free = np.empty(nb, np.int64)
    for s in range(nb):
        off = bounds[s] + s
        size = bounds[s + 1] - bounds[s]
        tree[off] = 0
        for i in range(1, size + 1):
            tree[off + i] = i & -i
        free[s] = size
    return tree, free


@njit(cache=True, nogil=True, _nrt=False)
def _fen_take(tree, off, size, i):
    """Mark position ``i`` (0-based) of the tree at ``off`` of ``size`` positions as taken."""
    i += 1
    while i <= size:
        tree[off + i] -= 1
        i += i & -i


@njit(cache=True, nogil=True, _nrt=False)
def _fen_prefix(tree, off, i):
    """Free positions in [0, i) of the tree at ``off``."""
    s = 0
    while i > 0:
        s += tree[off + i]
        i -= i & -i
    return s


@njit(cache=True, nogil=True, _nrt=False)
def _fen_select(tree, off, size, t):
    """Position of the ``t``-th free position (0-based) of the tree at ``off`` of ``size`` positions."""
    pos = 0
    step = 1
    while step * 2 <= size:
        step *= 2
    while step > 0:
        nxt = pos + step
        if nxt <= size and tree[off + nxt] <= t:
            pos = nxt
            t -= tree[off + nxt]
        step >>= 1
    return pos


@njit(cache=True, nogil=True, _nrt=False)
def _find(uf, x):
    """Live representative of x (union-find with path halving)."""
    while uf[x] != x:
        uf[x] = uf[uf[x]]
        x = uf[x]
    return x


@njit(cache=True, nogil=True, _nrt=False)
def _sort_candidates(cand, count, m):
    """Sort ``cand[:m]`` (distinct ids) by ``count`` descending, then by id, in place."""
    # Shell sort (gaps 1, 4, 13, ...): insertion sort for the usual short lists, and no quadratic
    # blow-up for the long lists of a vertex that absorbed many others (np.argsort would allocate
    # per call and cost seconds of compilation on a cold first run)
    gap = 1
    while gap < m // 3:
        gap = 3 * gap + 1
    while gap > 0:
        for i in range(gap, m):
            x = cand[i]
            c = count[i]
            j = i - gap
            while j >= 0 and (count[j] < c or (count[j] == c and cand[j] > x)):  # x precedes j
                cand[j + gap] = cand[j]
                count[j + gap] = count[j]
                j -= gap
            cand[j + gap] = x
            count[j + gap] = c
        gap //= 3


@njit(cache=True, nogil=True, _nrt=False)
def _tally_row(start, nbrs, uf, u, v, stamp, mark, cand, count, m):
    """Count the live representatives of u's neighbours into the candidates ``cand[:m]`` (distinct,
    in order of appearance) and their ``count``, leaving out v and the vertices of an earlier list.
    Returns the new m. ``mark[2x]`` is the stamp of the list x was last counted in (a list has a
    stamp of its own: no reset between lists), ``mark[2x + 1]`` its position there."""
    for i in range(start[u], start[u + 1]):
        x = _find(uf, nbrs[i])
        if x == v:
            continue
        seen = mark[2 * x]
        if seen == stamp:
            count[mark[2 * x + 1]] += 1
        elif seen < stamp - 1 or (stamp & 1) == 1:  # tier 1 (even stamps) skips tier 0's (stamp - 1)
            mark[2 * x] = stamp
            mark[2 * x + 1] = m
            cand[m] = x
            count[m] = 1
            m += 1
    return m


@njit(cache=True, nogil=True, _nrt=False)
def _tier0(start, nbrs, uf, v, r, mark, cand, count):
    """Tier 0 of the merge of rank ``r`` (of v): the live representatives of v's neighbours, minus
    v, in ``cand``, with in ``count`` how many of the neighbours lead to each; unordered (see
    :func:`_candidate_at` for the order). Returns their number."""
    if start[v + 1] - start[v] > _SHORT_ROW:
        return _tally_row(start, nbrs, uf, v, v, 2 * r + 1, mark, cand, count, 0)
    # a short row: the list itself is searched, which stays in the first-level cache (the
    # per-vertex table would cost a cache miss per neighbour)
    m = 0
    for i in range(start[v], start[v + 1]):
        x = _find(uf, nbrs[i])
        if x == v:
            continue
        j = 0
        while j < m and cand[j] != x:
            j += 1
        if j == m:
            cand[m] = x
            count[m] = 0
            m += 1
        count[j] += 1
    return m


@njit(cache=True, nogil=True, _nrt=False)
def _tier1(start, nbrs, uf, v, r, first_child, next_sibling, mark, cand0, m0, cand, count):
    """Tier 1 of the merge of rank ``r`` (of v) after tier 0's ``cand0[:m0]``: the live
    representatives of the neighbours of v's children (vertices merged into v before), minus v and
    tier 0's, counted and unordered as :func:`_tier0`'s. Returns their number."""
    for i in range(m0):  # tier 0's stamp, in case the short search counted it
        mark[2 * cand0[i]] = 2 * r + 1
    m = 0
    c = first_child[v]
    while c >= 0:
        m = _tally_row(start, nbrs, uf, c, v, 2 * r + 2, mark, cand, count, m)
        c = next_sibling[c]
    return m


@njit(cache=True, nogil=True, _nrt=False)
def _precedes(cand, count, i, j):
    """Whether candidate i comes before candidate j: a larger ``count``, or an equal one and a
    smaller id. Codings 1 and 2 count the listed neighbours that lead to it (the merge target
    usually shares the most of v's star); coding 3 passes minus its score
    (:func:`_score_candidates`)."""
    return count[i] > count[j] or (count[i] == count[j] and cand[i] < cand[j])


@njit(cache=True, nogil=True, _nrt=False)
def _index_of(cand, count, m, p):
    """Position of ``p`` in the ordered list ``cand[:m]``, or -1 when it is not listed."""
    at = -1
    for i in range(m):
        if cand[i] == p:
            at = i
            break
    if at < 0:
        return -1
    before = 0
    for i in range(m):
        if _precedes(cand, count, i, at):
            before += 1
    return before


@njit(cache=True, nogil=True, _nrt=False)
def _candidate_at(cand, count, m, idx):
    """The candidate at position ``idx < m`` of the ordered list (reorders ``cand[:m]``)."""
    if idx >= 8:
        _sort_candidates(cand, count, m)
        return cand[idx]
    for j in range(idx + 1):  # a partial selection sort: the usual index is 0 or 1
        best = j
        for i in range(j + 1, m):
            if _precedes(cand, count, i, best):
                best = i
        cand[j], cand[best] = cand[best], cand[j]
        count[j], count[best] = count[best], count[j]
    return cand[idx]


@njit(cache=True, nogil=True, _nrt=False)
def _flag_context(tier, size):
    return _FLAG_BASE + tier * FLAG_CONTEXTS + (size if size < FLAG_CONTEXTS - 1 else FLAG_CONTEXTS - 1)


@njit(cache=True, nogil=True, _nrt=False)
def _index_base(tier, size):
    return _INDEX_BASE + (tier * (SMALL_LIST + 1) + size) * SMALL_LIST


@njit(cache=True, nogil=True)
def _replay_state(n):
    """Scratch of the rank-order replay: union-find parents, children lists (first child, next
    sibling), the candidate lists' stamps and positions (:func:`_tally_row`: 0 = never listed),
    tier 0's and tier 1's candidates and counts (a tier lists distinct vertices: at most n)."""
    uf = np.empty(n, np.int32)
    for v in range(n):
        uf[v] = v
    size = max(1, n)
    return (uf, np.full(n, -1, np.int32), np.full(n, -1, np.int32), np.zeros(2 * n, np.int32),
            np.empty(size, np.int32), np.empty(size, np.int32), np.empty(size, np.int32), np.empty(size, np.int32))


@njit(cache=True, nogil=True, _nrt=False)
def _bucket_of(bounds, r):
    s = 0
    while bounds[s + 1] <= r:
        s += 1
    return s


@njit(cache=True, nogil=True)
def encode_forest_kernel(st, out, start, nbrs, boundary, parent, rank, k):
    """Code a forest (decode order; roots have rank >= k) after the level's adjacency."""
    n = parent.shape[0]
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    symbol = np.empty(n, np.int8)  # bucket symbols are < 64
    tree, free = _free_ranks(bounds)
    # pass 1, decode order: each vertex's rank bucket, then its place among the bucket's free ranks
    for v in range(n):
        r = rank[v]
        s = ROOT_SYMBOL if r >= k else _bucket_of(bounds, r)
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        enc_sym(st, out, probs, ctx << BUCKET_BITS, BUCKET_BITS, s)
        symbol[v] = s
        if s != ROOT_SYMBOL:
            off = bounds[s] + s
            enc_below(st, out, _fen_prefix(tree, off, r - bounds[s]), free[s])
            _fen_take(tree, off, bounds[s + 1] - bounds[s], r - bounds[s])
            free[s] -= 1
    _enc_parents(st, out, probs, start, nbrs, parent, rank, k)
    return enc_finish(st, out)


@njit(cache=True)
def _enc_parents(st, out, probs, start, nbrs, parent, rank, k):
    """Pass 2 of both codings, merges in rank order: each merge's parent among candidates built
    from the mesh so far."""
    n = parent.shape[0]
    of_rank = np.empty(k, np.int64)
    for v in range(n):
        if rank[v] < k:
            of_rank[rank[v]] = v
    uf, first_child, next_sibling, mark, cand0, count0, cand1, count1 = _replay_state(n)
    for r in range(k):
        v = of_rank[r]
        p = parent[v]
        m0 = _tier0(start, nbrs, uf, v, r, mark, cand0, count0)
        found = _enc_parent(st, out, probs, 0, cand0, count0, m0, p)
        if not found:
            m1 = _tier1(start, nbrs, uf, v, r, first_child, next_sibling, mark, cand0, m0, cand1, count1)
            found = _enc_parent(st, out, probs, 1, cand1, count1, m1, p)
        if not found:
            enc_below(st, out, p, n)
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v


@njit(cache=True)
def _enc_parent(st, out, probs, tier, cand, count, m, p):
    """Code whether parent ``p`` is in a tier's list ``cand[:m]`` and, if so, its index there
    (nothing for an empty list). Returns whether it was."""
    if m == 0:
        return False
    idx = _index_of(cand, count, m, p)
    enc_bit(st, out, probs, _flag_context(tier, m), 1 if idx >= 0 else 0)
    if idx < 0:
        return False
    if m <= SMALL_LIST:
        enc_sym(st, out, probs, _index_base(tier, m), 5, idx)
    else:
        enc_below(st, out, idx, m)
    return True


@njit(cache=True, nogil=True, _nrt=False)
def _dec_parent(st, data, probs, tier, cand, count, m):
    """The parent a tier's list codes, or -1 (not in the list, or an index past its end)."""
    if m == 0 or dec_bit(st, data, probs, _flag_context(tier, m)) == 0:
        return -1
    if m <= SMALL_LIST:
        idx = dec_sym(st, data, probs, _index_base(tier, m), 5)
    else:
        idx = dec_below(st, data, m)
    if idx >= m:
        st[DEC_ERROR] = 1  # a damaged stream: only 5-bit symbols can point past a short list
        return -1
    return _candidate_at(cand, count, m, idx)


@njit(cache=True, nogil=True)
def decode_forest_kernel(st, data, start, nbrs, boundary, k, parent, rank):
    """Inverse of :func:`encode_forest_kernel`: fills ``parent`` and ``rank`` (int32; roots:
    ``rank = k``).

    Returns False on a damaged stream (then the arrays are garbage but every index stayed in
    bounds); the caller also checks the decoder state and the forest itself.
    """
    n = parent.shape[0]
    dec_init(st, data)
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    n_buckets = bounds.shape[0] - 1
    symbol = np.empty(n, np.int8)  # bucket symbols are < 64
    tree, free = _free_ranks(bounds)
    of_rank = np.full(max(k, 1), -1, np.int32)
    for v in range(n):
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        s = dec_sym(st, data, probs, ctx << BUCKET_BITS, BUCKET_BITS)
        symbol[v] = s
        if s == ROOT_SYMBOL:
            rank[v] = k
            parent[v] = v
            continue
        if s >= n_buckets or free[s] <= 0:
            return False
        size = bounds[s + 1] - bounds[s]
        off = bounds[s] + s
        pos = _fen_select(tree, off, size, dec_below(st, data, free[s]))
        if dec_failed(st) or pos >= size:
            return False
        _fen_take(tree, off, size, pos)
        free[s] -= 1
        r = bounds[s] + pos
        rank[v] = r
        of_rank[r] = v
    for s in range(n_buckets):
        if free[s] != 0:
            return False  # fewer merges than the header says
    return decode_parents_kernel(st, data, probs, start, nbrs, k, parent, rank, of_rank)


@njit(cache=True, nogil=True)
def decode_parents_kernel(st, data, probs, start, nbrs, k, parent, rank, of_rank):
    """Pass 2 of both codings: every merge's parent, in rank order (``of_rank``: the vertex of
    every rank, all of them set; ``rank``: k for the roots, whose ``parent`` is already set).
    False on a damaged stream."""
    n = parent.shape[0]
    uf, first_child, next_sibling, mark, cand0, count0, cand1, count1 = _replay_state(n)
    for r in range(k):
        v = of_rank[r]
        m0 = _tier0(start, nbrs, uf, v, r, mark, cand0, count0)
        p = _dec_parent(st, data, probs, 0, cand0, count0, m0)
        if p < 0:
            m1 = _tier1(start, nbrs, uf, v, r, first_child, next_sibling, mark, cand0, m0, cand1, count1)
            p = _dec_parent(st, data, probs, 1, cand1, count1, m1)
            if p < 0:
                p = dec_below(st, data, n)
        if dec_failed(st) or p == v or rank[p] <= r:
            return False  # the parent must still be alive when v merges into it
        parent[v] = p
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v
    return True


# -- forest coding 2 (format 6): rounds instead of places -------------------------------------------
# Pass 1 codes, per merged vertex, its bucket (as coding 1) and its round inside the bucket; the
# ranks inside a round follow the vertices' canonical key (:func:`gatun_py.codec.forest.canonical_key`),
# which the decoder computes from the level's geometry between the two passes.


def new_model():
    """The adaptive bit probabilities of both passes, all at 1/2 (shared by the pass kernels)."""
    return np.full(MODEL_SIZE, 1 << 14, np.uint16)


@njit(cache=True, nogil=True)
def encode_rounds_kernel(st, out, start, nbrs, boundary, parent, rank, k, rid, n_rounds):
    """Code a forest (decode order; roots have rank >= k) as bucket + round per vertex (``rid``,
    ``n_rounds`` per bucket, see :func:`gatun_py.codec.forest.rank_rounds`), then the parents."""
    n = parent.shape[0]
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    for s in range(bounds.shape[0] - 1):
        enc_below(st, out, n_rounds[s] - 1, bounds[s + 1] - bounds[s])
    symbol = np.empty(n, np.int8)
    for v in range(n):
        r = rank[v]
        s = ROOT_SYMBOL if r >= k else _bucket_of(bounds, r)
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        enc_sym(st, out, probs, ctx << BUCKET_BITS, BUCKET_BITS, s)
        symbol[v] = s
        if s != ROOT_SYMBOL and n_rounds[s] > 1:
            enc_below(st, out, rid[v], n_rounds[s])
    _enc_parents(st, out, probs, start, nbrs, parent, rank, k)
    return enc_finish(st, out)


@njit(cache=True, nogil=True)
def decode_rounds_kernel(st, data, probs, start, nbrs, boundary, k, symbol, rid):
    """Pass 1 of coding 2: every vertex's bucket symbol (``ROOT_SYMBOL`` for a root) and round
    (-1 for a root). False on a damaged stream (a symbol past the last bucket, a round past the
    bucket's count); the caller checks the counts and builds the ranks."""
    n = symbol.shape[0]
    dec_init(st, data)
    bounds = bucket_bounds(n, k)
    n_buckets = bounds.shape[0] - 1
    n_rounds = np.empty(n_buckets, np.int64)
    for s in range(n_buckets):
        n_rounds[s] = dec_below(st, data, bounds[s + 1] - bounds[s]) + 1
    for v in range(n):
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        s = dec_sym(st, data, probs, ctx << BUCKET_BITS, BUCKET_BITS)
        symbol[v] = s
        if s == ROOT_SYMBOL:
            rid[v] = -1
            continue
        if s >= n_buckets:
            return False
        rid[v] = dec_below(st, data, n_rounds[s]) if n_rounds[s] > 1 else 0
        if dec_failed(st) or rid[v] >= n_rounds[s]:
            return False
    return not dec_failed(st)


# -- forest coding 3 (format 7): the level's geometry ranks the parents and gives every vertex a context
# Both passes read an error proxy of the decimator's that the decoder computes from the level's
# mesh and geometry: every vertex's quadric (the volume-weighted squared distances of a point in
# (x, y, z, value) to the hyperplanes of the vertex's tets, positions over the bounding-box diagonal,
# values over their range times QUADRIC_SCALAR_SCALE, as the decimator's quadric). Pass 1 codes
# a vertex's bucket as coding 2 does and its round's phase in a context of the quantile of its
# cheapest merge's quadric error (early merges are cheap; the quantiles in the bucket symbol's
# context too measured worse: too many contexts for the small meshes); pass 2 orders the candidate parents by the merged vertex's
# quadric (accumulated over the vertices merged into it, as the decimator does) at the candidate:
# the decimator picked the target of least error, so the parent is usually first. Every float is
# computed by the same sequence of IEEE double operations in the encoder and the decoder (no
# fastmath: no reassociation, no fused multiply-add), and candidates compare by (score, id), a
# total order (a NaN score counts as the largest).

QUADRIC_SCALAR_SCALE = 0.01
QUADRIC_TERMS = 15  # A's upper triangle (00 01 02 03 11 12 13 22 23 33), b (4), c: about the vertex itself
QUADRIC_A_TERMS = 10
PROXY_BINS = 16  # quantiles of the cheapest merge's quadric error: the context of a round's phase
PHASES = 16  # a round is coded as its phase (which sixteenth of the bucket's rounds) and its place in it
BUCKET_CLASSES3 = 8  # buckets above 7 share the round phases' context
_PHASE_BASE3 = N_BUCKET_CONTEXTS << BUCKET_BITS
PASS1_MODEL_SIZE3 = _PHASE_BASE3 + BUCKET_CLASSES3 * PROXY_BINS * PHASES
_BOUNDARY_MISMATCH = 1e300  # added to the score of an interior candidate of a boundary vertex


FIXED_ONE = 2.0**36  # a vertex's largest tet weight in the integer sums (terms <= 4 weights: room for 2^20 tets)


@njit(cache=True, nogil=True)
def level_quadrics(tets, points, density, start, nbrs, boundary):
    """(q, u, best): the (n, 15) quadric of every vertex over its tets (see the section comment),
    the (n, 4) normalised (x, y, z, value) of every vertex and every vertex's cheapest merge, float64.

    ``points`` (n, 3) and ``density`` (n,) float32, ``(start, nbrs)`` the adjacency; tet ids are in
    range (checked by the caller). One kernel for all three: one compilation on a cold start."""
    n = points.shape[0]
    q = np.zeros((n, QUADRIC_TERMS))
    u = np.zeros((n, 4))
    best = np.full(n, np.inf)
    if n == 0:
        return q, u, best
    lo = np.empty(3)
    hi = np.empty(3)
    for c in range(3):
        lo[c] = points[0, c]
        hi[c] = points[0, c]
    s_lo = np.float64(density[0])
    s_hi = s_lo
    for v in range(n):
        for c in range(3):
            x = np.float64(points[v, c])
            if x < lo[c]:
                lo[c] = x
            if x > hi[c]:
                hi[c] = x
        s = np.float64(density[v])
        if s < s_lo:
            s_lo = s
        if s > s_hi:
            s_hi = s
    dx, dy, dz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    diag = np.sqrt(dx * dx + dy * dy + dz * dz)
    if not diag > 0 or not np.isfinite(diag):
        diag = 1.0
    srange = s_hi - s_lo
    if not srange > 0 or not np.isfinite(srange):
        srange = 1.0
    for v in range(n):
        for c in range(3):
            u[v, c] = (np.float64(points[v, c]) - lo[c]) / diag
        u[v, 3] = QUADRIC_SCALAR_SCALE * ((np.float64(density[v]) - s_lo) / srange)
    # Sums over a vertex's tets, independent of the tets' order and orientation (the encoder has
    # the input's, the decoder the connectivity decoder's): every tet's terms from its corners in
    # id order, summed as integers (exact, so in any order) in units of 2^-FIXED_BITS of the
    # vertex's largest tet weight (the first pass), then back to floats.
    m = tets.shape[0]
    weight = np.empty(m)
    wmax = np.zeros(n)
    for t in range(m):
        a, b, c, d = sorted4(tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3])
        w = spatial_volume(u, a, b, c, d)
        weight[t] = w
        for x in (a, b, c, d):
            if w > wmax[x]:
                wmax[x] = w
    unit = np.empty(n)
    for v in range(n):
        unit[v] = FIXED_ONE / wmax[v] if wmax[v] > 0 else 0.0
        if not unit[v] < np.inf:
            unit[v] = 0.0
    fixed = np.zeros((n, QUADRIC_A_TERMS), np.int64)
    terms = np.empty(QUADRIC_A_TERMS)
    for t in range(m):
        a, b, c, d = sorted4(tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3])
        if not tet_quadric_terms(u, a, b, c, d, weight[t], terms):
            continue
        for x in (a, b, c, d):
            f = unit[x]
            for j in range(QUADRIC_A_TERMS):
                fixed[x, j] += np.int64(terms[j] * f)
    for v in range(n):
        back = wmax[v] / FIXED_ONE
        for j in range(QUADRIC_A_TERMS):
            q[v, j] = np.float64(fixed[v, j]) * back
    # every vertex's cheapest merge: the least quadric error over the neighbours it may merge into
    # (a boundary vertex only into boundary ones), inf when there is none
    best = np.full(n, np.inf)
    for v in range(n):
        for i in range(start[v], start[v + 1]):
            x = nbrs[i]
            if boundary[v] and not boundary[x]:
                continue
            e = _quadric_at(q, v, u, x)
            if e < best[v]:
                best[v] = e
    return q, u, best


@njit(cache=True, nogil=True, _nrt=False)
def _quadric_at(q, v, u, x):
    """Vertex v's quadric at vertex x: d^T A d + 2 b.d + c with d = u[x] - u[v] (quadrics are kept
    about their own vertex: no cancellation of large terms); NaN -> the largest."""
    a0, a1, a2, a3 = u[x, 0] - u[v, 0], u[x, 1] - u[v, 1], u[x, 2] - u[v, 2], u[x, 3] - u[v, 3]
    s = (q[v, 0] * a0 * a0 + q[v, 4] * a1 * a1 + q[v, 7] * a2 * a2 + q[v, 9] * a3 * a3
         + 2.0 * (q[v, 1] * a0 * a1 + q[v, 2] * a0 * a2 + q[v, 3] * a0 * a3
                  + q[v, 5] * a1 * a2 + q[v, 6] * a1 * a3 + q[v, 8] * a2 * a3)
         + 2.0 * (q[v, 10] * a0 + q[v, 11] * a1 + q[v, 12] * a2 + q[v, 13] * a3) + q[v, 14])
    if s != s:
        return np.inf
    return s


@njit(cache=True, nogil=True, _nrt=False)
def _phase_range(phase, n_rounds):
    """The rounds [lo, hi) of ``phase`` out of min(PHASES, n_rounds): those with round * P // R = phase."""
    p = PHASES if n_rounds > PHASES else n_rounds
    return (phase * n_rounds + p - 1) // p, ((phase + 1) * n_rounds + p - 1) // p


@njit(cache=True, nogil=True, _nrt=False)
def _phase_base(s, bin_):
    return _PHASE_BASE3 + ((s if s < BUCKET_CLASSES3 else BUCKET_CLASSES3 - 1) * PROXY_BINS + bin_) * PHASES


@njit(cache=True, nogil=True)
def encode_rounds3_kernel(st, out, start, nbrs, boundary, parent, rank, k, rid, n_rounds, proxy_bin, q, u):
    """Coding 3: the round counts, then per vertex its bucket and round in the context of its proxy
    bin, then the parents ordered by the quadric."""
    n = parent.shape[0]
    probs = np.full(PASS1_MODEL_SIZE3, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    for s in range(bounds.shape[0] - 1):
        enc_below(st, out, n_rounds[s] - 1, bounds[s + 1] - bounds[s])
    symbol = np.empty(n, np.int8)
    for v in range(n):
        r = rank[v]
        s = ROOT_SYMBOL if r >= k else _bucket_of(bounds, r)
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        enc_sym(st, out, probs, ctx << BUCKET_BITS, BUCKET_BITS, s)
        symbol[v] = s
        if s != ROOT_SYMBOL and n_rounds[s] > 1:
            p = PHASES if n_rounds[s] > PHASES else n_rounds[s]
            phase = rid[v] * p // n_rounds[s]
            enc_sym(st, out, probs, _phase_base(s, proxy_bin[v]), 4, phase)
            lo, hi = _phase_range(phase, n_rounds[s])
            if hi - lo > 1:
                enc_below(st, out, rid[v] - lo, hi - lo)
    _enc_parents3(st, out, start, nbrs, boundary, parent, rank, k, q, u)
    return enc_finish(st, out)


@njit(cache=True, nogil=True)
def decode_rounds3_kernel(st, data, start, nbrs, boundary, k, proxy_bin, symbol, rid):
    """Pass 1 of coding 3 (see :func:`decode_rounds_kernel`)."""
    n = symbol.shape[0]
    dec_init(st, data)
    probs = np.full(PASS1_MODEL_SIZE3, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    n_buckets = bounds.shape[0] - 1
    n_rounds = np.empty(n_buckets, np.int64)
    for s in range(n_buckets):
        n_rounds[s] = dec_below(st, data, bounds[s + 1] - bounds[s]) + 1
    for v in range(n):
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        s = dec_sym(st, data, probs, ctx << BUCKET_BITS, BUCKET_BITS)
        symbol[v] = s
        if s == ROOT_SYMBOL:
            rid[v] = -1
            continue
        if s >= n_buckets:
            return False
        rid[v] = 0
        if n_rounds[s] > 1:
            phase = dec_sym(st, data, probs, _phase_base(s, proxy_bin[v]), 4)
            if phase >= (PHASES if n_rounds[s] > PHASES else n_rounds[s]):
                return False
            lo, hi = _phase_range(phase, n_rounds[s])
            rid[v] = lo + (dec_below(st, data, hi - lo) if hi - lo > 1 else 0)
        if dec_failed(st):
            return False
    return not dec_failed(st)


@njit(cache=True, nogil=True, _nrt=False)
def _score_candidates(q, u, boundary, v, cand, m, priority):
    """priority[i] of candidate cand[i] for v's merge: minus its score, v's quadric at it plus a
    penalty that puts an interior candidate of a boundary vertex after every boundary one (nothing
    to order in a list of one). Negated so that coding 1's order (:func:`_precedes`: larger first,
    then smaller id) is coding 3's (smaller score first, then smaller id) and its list helpers serve
    both: scores are never NaN (:func:`_quadric_at`), so the order is total and the candidate at an
    index is the same however it is found."""
    if m < 2:
        priority[0] = 0.0
        return
    for i in range(m):
        x = cand[i]
        s = _quadric_at(q, v, u, x)
        if boundary[v] and not boundary[x]:
            s += _BOUNDARY_MISMATCH
        priority[i] = -s


@njit(cache=True, nogil=True, _nrt=False)
def _absorb(q, u, p, v):
    """p's quadric += v's (the decimator's quadric of a merge target), v's moved from about v to
    about p: with e = u[p] - u[v], A stays, b += A e, c += e^T A e + 2 b.e."""
    e0, e1, e2, e3 = u[p, 0] - u[v, 0], u[p, 1] - u[v, 1], u[p, 2] - u[v, 2], u[p, 3] - u[v, 3]
    ae0 = q[v, 0] * e0 + q[v, 1] * e1 + q[v, 2] * e2 + q[v, 3] * e3
    ae1 = q[v, 1] * e0 + q[v, 4] * e1 + q[v, 5] * e2 + q[v, 6] * e3
    ae2 = q[v, 2] * e0 + q[v, 5] * e1 + q[v, 7] * e2 + q[v, 8] * e3
    ae3 = q[v, 3] * e0 + q[v, 6] * e1 + q[v, 8] * e2 + q[v, 9] * e3
    for j in range(QUADRIC_A_TERMS):
        q[p, j] += q[v, j]
    c = (q[v, 14] + (ae0 * e0 + ae1 * e1 + ae2 * e2 + ae3 * e3)
         + 2.0 * (q[v, 10] * e0 + q[v, 11] * e1 + q[v, 12] * e2 + q[v, 13] * e3))
    q[p, 10] += q[v, 10] + ae0
    q[p, 11] += q[v, 11] + ae1
    q[p, 12] += q[v, 12] + ae2
    q[p, 13] += q[v, 13] + ae3
    q[p, 14] += c


@njit(cache=True)
def _enc_parents3(st, out, start, nbrs, boundary, parent, rank, k, q, u):
    """Pass 2 of coding 3: as :func:`_enc_parents`, the lists ordered by the quadric (``q`` is
    updated in place as the merges are replayed)."""
    n = parent.shape[0]
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    of_rank = np.empty(k, np.int64)
    for v in range(n):
        if rank[v] < k:
            of_rank[rank[v]] = v
    uf, first_child, next_sibling, mark, cand0, count0, cand1, count1 = _replay_state(n)
    priority = np.empty(max(1, n))
    for r in range(k):
        v = of_rank[r]
        p = parent[v]
        m0 = _tier0(start, nbrs, uf, v, r, mark, cand0, count0)
        _score_candidates(q, u, boundary, v, cand0, m0, priority)
        found = _enc_parent(st, out, probs, 0, cand0, priority, m0, p)
        if not found:
            m1 = _tier1(start, nbrs, uf, v, r, first_child, next_sibling, mark, cand0, m0, cand1, count1)
            _score_candidates(q, u, boundary, v, cand1, m1, priority)
            found = _enc_parent(st, out, probs, 1, cand1, priority, m1, p)
        if not found:
            enc_below(st, out, p, n)
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v
        _absorb(q, u, p, v)


@njit(cache=True, nogil=True)
def decode_parents3_kernel(st, data, start, nbrs, boundary, k, parent, rank, of_rank, q, u):
    """Pass 2 of coding 3 (see :func:`decode_parents_kernel`); ``q`` is updated in place."""
    n = parent.shape[0]
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    uf, first_child, next_sibling, mark, cand0, count0, cand1, count1 = _replay_state(n)
    priority = np.empty(max(1, n))
    for r in range(k):
        v = of_rank[r]
        m0 = _tier0(start, nbrs, uf, v, r, mark, cand0, count0)
        _score_candidates(q, u, boundary, v, cand0, m0, priority)
        p = _dec_parent(st, data, probs, 0, cand0, priority, m0)
        if p < 0:
            m1 = _tier1(start, nbrs, uf, v, r, first_child, next_sibling, mark, cand0, m0, cand1, count1)
            _score_candidates(q, u, boundary, v, cand1, m1, priority)
            p = _dec_parent(st, data, probs, 1, cand1, priority, m1)
            if p < 0:
                p = dec_below(st, data, n)
        if dec_failed(st) or p == v or rank[p] <= r:
            return False
        parent[v] = p
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v
        _absorb(q, u, p, v)
    return True
