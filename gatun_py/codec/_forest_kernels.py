"""Numba kernels of the format-3 merge-forest coding (see :mod:`.forest` for the layout).

The encoder and the decoder share every model decision through the same helpers: the vertex
adjacency of the level's mesh (:func:`adjacency`), the rank buckets (:func:`bucket_bounds`), the
bucket context of a vertex from its already decoded neighbours (:func:`_bucket_context`) and the
candidate parents of a merge (:func:`_candidates`). ``tests/naive_forest.py`` is the slow
reference that produces the same bytes with Python sets and integers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .rangecoder import dec_below, dec_bit, dec_failed, dec_init, dec_sym, enc_below, enc_bit, enc_finish, enc_sym

ROOT_SYMBOL = 63  # bucket symbol of a vertex that is never merged
BUCKET_BITS = 6
CONTEXT_CAP = 6  # bucket symbols above this (and roots) look alike to the context
DEGREE_CLASSES = 7  # neighbour count // 4, capped: well-connected vertices merge later
N_BUCKET_CONTEXTS = (CONTEXT_CAP + 2) * 2 * DEGREE_CLASSES
SMALL_LIST = 32  # candidate lists up to this long code the index with a model, longer ones uniformly
FLAG_CONTEXTS = 16
# model layout: bucket symbols | "parent is in the list" flags | index symbols, per tier (2)
_FLAG_BASE = N_BUCKET_CONTEXTS << BUCKET_BITS
_INDEX_BASE = _FLAG_BASE + 2 * FLAG_CONTEXTS
MODEL_SIZE = _INDEX_BASE + 2 * (SMALL_LIST + 1) * SMALL_LIST


@njit(cache=True, nogil=True)
def adjacency(tets, n):
    """Vertex neighbours of a tet mesh as CSR ``(start, nbrs)``, each row sorted and unique.

    Ids are not checked here: the callers pass tets that the connectivity coder produced or
    checked (``0 <= id < n``).
    """
    count = np.zeros(n + 1, np.int64)
    for t in range(tets.shape[0]):
        for i in range(4):
            count[tets[t, i] + 1] += 3
    start = np.cumsum(count)
    fill = start[:-1].copy()
    nbrs = np.empty(start[n], np.int32)
    for t in range(tets.shape[0]):
        for i in range(4):
            a = tets[t, i]
            for j in range(4):
                if j != i:
                    nbrs[fill[a]] = tets[t, j]
                    fill[a] += 1
    # deduplicate every row (a vertex is listed once per tet it shares), then sort the short
    # unique row, compacting in place
    out = 0
    row_start = np.zeros(n + 1, np.int64)
    seen_by = np.full(n, -1, np.int64)
    for v in range(n):
        row_start[v] = out
        for i in range(start[v], start[v + 1]):
            x = nbrs[i]
            if seen_by[x] != v:
                seen_by[x] = v
                nbrs[out] = x
                out += 1
        _sort_small(nbrs[row_start[v]:out], out - row_start[v])
    row_start[n] = out
    return row_start, nbrs[:out].copy()


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


@njit(cache=True, nogil=True)
def _bucket_context(start, nbrs, boundary, v, symbol):
    """Context of v's bucket symbol: whether v is on the boundary, its degree class, and the
    smallest bucket symbol among its decoded (smaller-id) neighbours, capped (0: none)."""
    lowest = CONTEXT_CAP + 1
    for i in range(start[v], start[v + 1]):
        u = nbrs[i]
        if u >= v:
            break  # rows are sorted
        if symbol[u] < lowest:
            lowest = symbol[u]
    seen = 0 if start[v] == start[v + 1] or nbrs[start[v]] >= v else 1 + min(lowest, CONTEXT_CAP)
    degree = start[v + 1] - start[v]
    own = (1 if boundary[v] else 0) * DEGREE_CLASSES + min(degree >> 2, DEGREE_CLASSES - 1)
    return own * (CONTEXT_CAP + 2) + seen


@njit(cache=True, nogil=True)
def _fen_add(tree, i, delta):
    i += 1
    while i < tree.shape[0]:
        tree[i] += delta
        i += i & -i


@njit(cache=True, nogil=True)
def _fen_prefix(tree, i):
    """Sum over positions [0, i)."""
    s = 0
    while i > 0:
        s += tree[i]
        i -= i & -i
    return s


@njit(cache=True, nogil=True)
def _fen_select(tree, t, high_bit):
    """Smallest position p with prefix(p + 1) > t (t-th one, 0-based); counts are 0/1."""
    pos = 0
    step = high_bit
    while step > 0:
        nxt = pos + step
        if nxt < tree.shape[0] and tree[nxt] <= t:
            pos = nxt
            t -= tree[nxt]
        step >>= 1
    return pos


@njit(cache=True, nogil=True)
def _free_ranks(k):
    """Fenwick tree of k free ranks (all ones) and its highest power of two."""
    tree = np.zeros(k + 1, np.int64)
    for i in range(1, k + 1):
        tree[i] = i & -i
    high = 1
    while high * 2 <= k:
        high *= 2
    return tree, high


@njit(cache=True, nogil=True)
def _find(uf, x):
    while uf[x] != x:
        uf[x] = uf[uf[x]]
        x = uf[x]
    return x


@njit(cache=True, nogil=True)
def _sort_small(a, m):
    """Sort ``a[:m]`` in place (np.sort would allocate a copy per call)."""
    # Shell sort (gaps 1, 4, 13, ...): insertion sort for the usual rows, and no quadratic blow-up
    # for the long lists of a vertex that absorbed many others (np.sort would cost seconds of
    # compilation on a cold first run)
    gap = 1
    while gap < m // 3:
        gap = 3 * gap + 1
    while gap > 0:
        for i in range(gap, m):
            x = a[i]
            j = i - gap
            while j >= 0 and a[j] > x:
                a[j + gap] = a[j]
                j -= gap
            a[j + gap] = x
        gap //= 3


@njit(cache=True, nogil=True)
def _candidates(start, nbrs, uf, v, tier, first_child, next_sibling, exclude, out, count):
    """Candidate parents of v's merge, written to ``out``; returns their number.

    Tier 0: the live representatives of v's neighbours. Tier 1: those of the neighbours of v's
    children (vertices merged into v before), minus tier 0's (``exclude[:]`` marks tier 0's then).
    v itself is never a candidate. Order: by how many of the listed neighbours lead to the
    candidate (most first: the merge target usually shares the most of v's star), then by id.
    """
    m = 0
    if tier == 0:
        for i in range(start[v], start[v + 1]):
            out[m] = _find(uf, nbrs[i])
            m += 1
    else:
        c = first_child[v]
        while c >= 0:
            for i in range(start[c], start[c + 1]):
                out[m] = _find(uf, nbrs[i])  # out holds every neighbour of every vertex: no overflow
                m += 1
            c = next_sibling[c]
    _sort_small(out, m)
    k = 0
    i = 0
    while i < m:
        x = out[i]
        j = i
        while j < m and out[j] == x:
            j += 1
        if x != v and not (tier == 1 and exclude[x]):
            out[k] = x
            count[k] = j - i
            k += 1
        i = j
    # stable insertion sort by count, descending
    for i in range(1, k):
        x = out[i]
        c = count[i]
        j = i - 1
        while j >= 0 and count[j] < c:
            out[j + 1] = out[j]
            count[j + 1] = count[j]
            j -= 1
        out[j + 1] = x
        count[j + 1] = c
    return k


@njit(cache=True, nogil=True)
def _clear_marks(start, nbrs, uf, v, exclude):
    """Undo tier 0's marks in ``exclude`` (the representatives of v's neighbours)."""
    for i in range(start[v], start[v + 1]):
        exclude[_find(uf, nbrs[i])] = False


@njit(cache=True, nogil=True)
def _flag_context(tier, size):
    return _FLAG_BASE + tier * FLAG_CONTEXTS + (size if size < FLAG_CONTEXTS - 1 else FLAG_CONTEXTS - 1)


@njit(cache=True, nogil=True)
def _index_base(tier, size):
    return _INDEX_BASE + (tier * (SMALL_LIST + 1) + size) * SMALL_LIST


@njit(cache=True, nogil=True)
def _replay_state(n, n_nbrs):
    """Scratch of the rank-order replay: union-find parents, children lists (first child, next
    sibling), tier-0 marks, candidate ids and their counts (room for every adjacency entry)."""
    return (np.arange(n), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, np.bool_),
            np.empty(max(1, n_nbrs), np.int64), np.empty(max(1, n_nbrs), np.int64))


@njit(cache=True)
def encode_forest_kernel(st, out, start, nbrs, boundary, parent, rank, k):
    """Code a forest (decode order; roots have rank >= k) after the level's adjacency."""
    n = parent.shape[0]
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    symbol = np.empty(n, np.int64)
    tree, _ = _free_ranks(k)
    # pass 1, decode order: each vertex's rank bucket, then its place among the bucket's free ranks
    for v in range(n):
        r = rank[v]
        if r >= k:
            s = ROOT_SYMBOL
        else:
            s = 0
            while bounds[s + 1] <= r:
                s += 1
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        enc_sym(st, out, probs, ctx << BUCKET_BITS, BUCKET_BITS, s)
        symbol[v] = s
        if s != ROOT_SYMBOL:
            lo = _fen_prefix(tree, bounds[s])
            free = _fen_prefix(tree, bounds[s + 1]) - lo
            enc_below(st, out, _fen_prefix(tree, r) - lo, free)
            _fen_add(tree, r, -1)
    # pass 2, rank order: each merge's parent among candidates built from the mesh so far
    of_rank = np.empty(k, np.int64)
    for v in range(n):
        if rank[v] < k:
            of_rank[rank[v]] = v
    uf, first_child, next_sibling, exclude, cand, cand_count = _replay_state(n, nbrs.shape[0])
    for r in range(k):
        v = of_rank[r]
        p = parent[v]
        found = False
        for tier in range(2):
            m = _candidates(start, nbrs, uf, v, tier, first_child, next_sibling, exclude, cand, cand_count)
            if tier == 0:
                for i in range(m):
                    exclude[cand[i]] = True
            if m > 0:
                idx = -1
                for i in range(m):
                    if cand[i] == p:
                        idx = i
                        break
                enc_bit(st, out, probs, _flag_context(tier, m), 1 if idx >= 0 else 0)
                if idx >= 0:
                    if m <= SMALL_LIST:
                        enc_sym(st, out, probs, _index_base(tier, m), 5, idx)
                    else:
                        enc_below(st, out, idx, m)
                    found = True
            if found:
                break
        _clear_marks(start, nbrs, uf, v, exclude)
        if not found:
            enc_below(st, out, p, n)
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v
    return enc_finish(st, out)


@njit(cache=True, nogil=True)
def decode_forest_kernel(st, data, start, nbrs, boundary, k, parent, rank):
    """Inverse of :func:`encode_forest_kernel`: fills ``parent`` and ``rank`` (roots: ``rank = k``).

    Returns False on a damaged stream (then the arrays are garbage but every index stayed in
    bounds); the caller also checks the decoder state and the forest itself.
    """
    n = parent.shape[0]
    dec_init(st, data)
    probs = np.full(MODEL_SIZE, 1 << 14, np.uint16)
    bounds = bucket_bounds(n, k)
    n_buckets = bounds.shape[0] - 1
    symbol = np.empty(n, np.int64)
    tree, high = _free_ranks(k)
    of_rank = np.full(max(k, 1), -1, np.int64)
    for v in range(n):
        ctx = _bucket_context(start, nbrs, boundary, v, symbol)
        s = dec_sym(st, data, probs, ctx << BUCKET_BITS, BUCKET_BITS)
        if dec_failed(st):
            return False
        symbol[v] = s
        if s == ROOT_SYMBOL:
            rank[v] = k
            parent[v] = v
            continue
        if s >= n_buckets:
            return False
        lo = _fen_prefix(tree, bounds[s])
        free = _fen_prefix(tree, bounds[s + 1]) - lo
        if free <= 0:
            return False
        r = _fen_select(tree, lo + dec_below(st, data, free), high)
        if r >= k or of_rank[r] >= 0:
            return False
        _fen_add(tree, r, -1)
        rank[v] = r
        of_rank[r] = v
    for r in range(k):
        if of_rank[r] < 0:
            return False  # fewer merges than the header says
    uf, first_child, next_sibling, exclude, cand, cand_count = _replay_state(n, nbrs.shape[0])
    for r in range(k):
        v = of_rank[r]
        p = -1
        for tier in range(2):
            m = _candidates(start, nbrs, uf, v, tier, first_child, next_sibling, exclude, cand, cand_count)
            if tier == 0:
                for i in range(m):
                    exclude[cand[i]] = True
            if m > 0 and dec_bit(st, data, probs, _flag_context(tier, m)) == 1:
                if m <= SMALL_LIST:
                    idx = dec_sym(st, data, probs, _index_base(tier, m), 5)
                else:
                    idx = dec_below(st, data, m)
                if idx >= m:
                    return False
                p = cand[idx]
            if p >= 0:
                break
        _clear_marks(start, nbrs, uf, v, exclude)
        if p < 0:
            p = dec_below(st, data, n)
        if dec_failed(st) or p == v or rank[p] <= r:
            return False  # the parent must still be alive when v merges into it
        parent[v] = p
        uf[v] = p
        next_sibling[v] = first_child[p]
        first_child[p] = v
    return True
