"""Numba kernels of the merge dependencies (see :mod:`gatun_py.simplify.dependencies`).

The mesh state while the merges are replayed in rank order is the decimator's
(:mod:`gatun_py.simplify._decimate_kernels`): ``T`` (m, 4) the current image of every input tet,
``alive`` (m,), per-vertex slot lists ``head`` / ``nxt`` (slot = 4*t + corner), spliced on a merge
and tidied lazily. On top of it, ``last[t]`` = the rank of the last merge that changed tet t
(-1: never changed).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _incidence(T, n):
    """(head, nxt): every vertex's list of slots 4*t + c."""
    head = np.full(n, -1, np.int64)
    nxt = np.full(4 * T.shape[0], -1, np.int64)
    for s in range(4 * T.shape[0] - 1, -1, -1):
        v = T[s >> 2, s & 3]
        nxt[s] = head[v]
        head[v] = s
    return head, nxt


@njit(cache=True)
def _tidy(v, head, nxt, T, alive):
    """Unlink from v's list the slots of dead tets and of tets that no longer hold v there."""
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
def _push(buf, n, value):
    """Append ``value`` at ``buf[n]``, doubling ``buf`` when full; returns the (possibly new) buffer."""
    if n >= buf.shape[0]:
        grown = np.empty(2 * buf.shape[0] + 16, buf.dtype)
        grown[:n] = buf[:n]
        buf = grown
    buf[n] = value
    return buf


@njit(cache=True)
def _dependencies(tets, by_rank, parent):
    """Replay the merges in rank order; returns (ptr (k+1,), idx, removed (k,)) or ptr[0] = -1-r
    when merge r is not an edge collapse of the current mesh (a forest that does not belong to
    this mesh).

    ``idx[ptr[i]:ptr[i+1]]`` = D(i), ascending: the last changers of the tets in the stars of
    v_i and t_i just before merge i. ``removed[i]`` = tets with both v_i and t_i (merge i deletes
    them).
    """
    m = tets.shape[0]
    k = by_rank.shape[0]
    n = parent.shape[0]
    T = tets.copy()
    alive = np.ones(m, np.bool_)
    last = np.full(m, -1, np.int64)
    head, nxt = _incidence(T, n)
    seen = np.full(k, -1, np.int64)
    ptr = np.zeros(k + 1, np.int64)
    idx = np.empty(4 * k + 16, np.int32)
    removed = np.zeros(k, np.int32)
    nd = 0
    for i in range(k):
        a = by_rank[i]
        b = parent[a]
        _tidy(a, head, nxt, T, alive)
        _tidy(b, head, nxt, T, alive)
        start = nd
        for end in range(2):
            v = a if end == 0 else b
            s = head[v]
            while s >= 0:
                j = last[s >> 2]
                if j >= 0 and seen[j] != i:
                    seen[j] = i
                    idx = _push(idx, nd, j)
                    nd += 1
                s = nxt[s]
        # apply: tets of edge ab die, the rest of a's star is relabelled
        shared = 0
        s = head[a]
        while s >= 0:
            t = s >> 2
            last[t] = i
            if T[t, 0] == b or T[t, 1] == b or T[t, 2] == b or T[t, 3] == b:
                alive[t] = False
                shared += 1
            else:
                T[t, s & 3] = b
            s = nxt[s]
        if shared == 0:
            ptr[0] = -1 - i
            return ptr, idx[:0], removed
        removed[i] = shared
        s = head[a]
        if s >= 0:
            while nxt[s] >= 0:
                s = nxt[s]
            nxt[s] = head[b]
            head[b] = head[a]
            head[a] = -1
        idx[start:nd] = np.sort(idx[start:nd])
        ptr[i + 1] = nd
    return ptr, idx[:nd], removed


@njit(cache=True)
def _effective_importance(importance, ptr, idx):
    """e(i) = max(importance[i], max of e over D(i)), in rank order (dependencies come first)."""
    k = importance.shape[0]
    e = np.empty(k)
    for i in range(k):
        x = importance[i]
        for p in range(ptr[i], ptr[i + 1]):
            y = e[idx[p]]
            if y > x:
                x = y
        e[i] = x
    return e


@njit(cache=True)
def _is_closed(applied, ptr, idx):
    """-1 when every applied merge has all its dependencies applied, else the first merge that has not."""
    for i in range(applied.shape[0]):
        if applied[i]:
            for p in range(ptr[i], ptr[i + 1]):
                if not applied[idx[p]]:
                    return i
    return -1


@njit(cache=True)
def _cut_ancestors(parent, rank, applied):
    """Ancestor of every vertex for a cut: follow the parent while that vertex's merge is applied.

    Top-down over the ranks (a parent outranks its children), a counting sort by rank: O(n).
    """
    n = parent.shape[0]
    k = applied.shape[0]
    anc = np.empty(n, np.int32)
    by_rank = np.full(k, -1, np.int64)
    for v in range(n):
        anc[v] = v
        r = rank[v]
        if 0 <= r < k:
            by_rank[r] = v
    for r in range(k - 1, -1, -1):
        v = by_rank[r]
        if v >= 0 and applied[r]:
            anc[v] = anc[parent[v]]
    return anc
