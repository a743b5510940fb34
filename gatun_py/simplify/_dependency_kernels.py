"""Numba kernels of the merge dependencies (see :mod:`gatun_py.simplify.dependencies`).

The mesh state while the merges are replayed in rank order is the decimator's
(:mod:`gatun_py.simplify._decimate_kernels`): ``T`` (m, 4) the current image of every input tet,
``alive`` (m,), per-vertex slot lists ``head`` / ``nxt`` (slot = 4*t + corner), spliced on a merge.
Unlike the decimator's, the lists keep dead tets. On top of it, ``last[t]`` = the rank of the last merge that changed tet t
(-1: never changed).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._decimate_kernels import _incidence  # the decimator's slot lists, built the same way


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

    Every vertex's list holds every input tet whose image contains it, dead ones included (their
    images keep following the merges): a tet killed by a merge r that a cut leaves out is alive in
    that cut, so a merge near it must depend on r. ``idx[ptr[i]:ptr[i+1]]`` = D(i), ascending:
    the last changers of the images of the tets whose image contains v_i or t_i just before merge
    i (the killer of a dead tet is reached through the merges that moved it since). ``removed[i]`` = live tets with both v_i and t_i (merge i deletes them).
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
        # apply: live tets of edge ab die, every tet holding a now holds b
        shared = 0
        s = head[a]
        while s >= 0:
            t = s >> 2
            last[t] = i
            if alive[t] and (T[t, 0] == b or T[t, 1] == b or T[t, 2] == b or T[t, 3] == b):
                alive[t] = False
                shared += 1
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


@njit(cache=True)
def _reduce(ptr, idx, budget):
    """Close to the transitive reduction of the dependency DAG: per merge, only the dependencies
    that no other dependency of it reaches. The closure (hence every closed cut) is unchanged.

    Merge by merge in rank order, its dependencies from the highest rank down: one already reached
    is dropped, one kept marks what it reaches (a depth-first search over the reduced lists of
    earlier merges, pruned below the merge's lowest dependency, which nothing below can cover, and
    stopped after ``budget`` marks: what it did not reach is kept, which is redundant but correct).
    """
    k = ptr.shape[0] - 1
    rptr = np.zeros(k + 1, np.int64)
    ridx = np.empty(idx.shape[0], np.int32)
    mark = np.full(k, -1, np.int64)
    stack = np.empty(16, np.int64)
    nr = 0
    for i in range(k):
        lo = ptr[i]
        hi = ptr[i + 1]
        start = nr
        if hi > lo:
            floor = idx[lo]  # ascending: the lowest dependency
            for p in range(hi - 1, lo - 1, -1):
                x = idx[p]
                if mark[x] == i:
                    continue
                ridx[nr] = x
                nr += 1
                mark[x] = i
                top = 0
                stack = _push(stack, top, x)
                top += 1
                work = 0
                while top > 0 and work < budget:
                    top -= 1
                    y = stack[top]
                    for q in range(rptr[y], rptr[y + 1]):
                        z = ridx[q]
                        if z >= floor and mark[z] != i:
                            mark[z] = i
                            work += 1
                            stack = _push(stack, top, z)
                            top += 1
            ridx[start:nr] = np.sort(ridx[start:nr])
        rptr[i + 1] = nr
    return rptr, ridx[:nr].copy()
