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

from ._decimate_kernels import (  # the decimator's state and legality tests, reused as they are
    VOLUME_EPS,
    _apply_merge,
    _boundary_faces_of,
    _boundary_ok,
    _contains,
    _face_neighbours,  # noqa: F401  (dependencies.py calls it through this module)
    _incidence,
    _link_ok,
    _max_edge2,
    _orient6,
    _star,
    _splice_incidence,
    _star_boundary,
    _vertex_topology,  # noqa: F401  (likewise)
)


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
        _splice_incidence(a, b, head, nxt)
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


# -- legal cuts: a runtime check instead of the stored closure ------------------------------------
# The state is the decimator's (T, alive, nbr, head, nxt over the start mesh); merges are tried in
# any order and each is applied only when the decimator's own legality tests pass on the *current*
# cut mesh: an edge of it, the link condition, every surviving tet of the star positive, no
# boundary face turned by 90 degrees or more. Every intermediate mesh is then a valid mesh, so the
# final one is, whatever the order.


@njit(cache=True)
def _find(jump, v):
    """Current representative of v (follow applied merges; path halving)."""
    while jump[v] != v:
        jump[v] = jump[jump[v]]
        v = jump[v]
    return v


@njit(cache=True)
def _volumes_ok(a, b, st, T, pts, q):
    """Every tet of a's star without b stays positive with a moved onto b (the decimator's rule:
    above VOLUME_EPS of its longest edge cubed, or not shrinking). Returns the tets that collapse,
    -1 when one would flatten or invert."""
    n_col = 0
    for k in range(st.shape[0]):
        t = st[k] >> 2
        if _contains(T, t, b):
            n_col += 1
            continue
        for j in range(4):
            q[j] = T[t, j]
        old = _orient6(pts, q[0], q[1], q[2], q[3])
        q[st[k] & 3] = b
        v6 = _orient6(pts, q[0], q[1], q[2], q[3])
        if not (v6 > VOLUME_EPS * _max_edge2(pts, q) ** 1.5 or (v6 >= old and v6 > 0.0)):
            return -1
    return n_col


@njit(cache=True)
def _legal_greedy(order, vertex, target, T, nbr, isb, pts, n_tets, goal, max_passes, children_first):
    """Apply merges ``order[0], order[1], ...`` (merge i: vertex[i] into target[i], only while
    target[i]'s own merge is not applied, so every applied merge is an edge of the forest and the
    ancestors are the cut's) when legal on the current mesh, until it has at most ``goal`` tets; merges found
    illegal are tried again in later passes (up to ``max_passes``) as the mesh around them changes.

    ``children_first``: a merge waits (to a later pass) until every merge into its vertex is
    applied, so the cut is a union of whole subtrees of the forest (each applied merge moves the
    region it moved in its prefix state).

    ``T`` and ``nbr`` are consumed (the start mesh's tets and face neighbours, copies). Returns
    (applied (k,) bool by merge, tets left, merges rejected at least once).
    """
    n = pts.shape[0]
    m = T.shape[0]
    k = vertex.shape[0]
    alive = np.ones(m, np.bool_)
    head, nxt = _incidence(T, n)
    jump = np.arange(n)
    mark_b = np.zeros(n, np.int64)
    mark_ab = np.zeros(n, np.int64)
    counters = np.zeros(8, np.int64)
    applied = np.zeros(k, np.bool_)
    q = np.empty(4, np.int64)
    n_new = np.empty(3)
    tets = n_tets
    pending = np.zeros(n, np.int64)  # merges into each vertex not applied yet
    if children_first:
        for i in range(k):
            pending[target[i]] += 1
    todo = order.copy()
    n_todo = todo.shape[0]
    rejected = 0
    for p in range(max_passes):
        if tets <= goal or n_todo == 0:
            break
        left = 0
        for j in range(n_todo):
            if tets <= goal:
                todo[left] = todo[j]
                left += 1
                continue
            i = todo[j]
            a = vertex[i]
            b = target[i]
            if pending[a] > 0:  # a child still to come (children_first)
                todo[left] = i
                left += 1
                continue
            ok = jump[b] == b and (isb[b] or not isb[a])
            st = _star(a, head, nxt, T, alive)
            n_col = -1
            if ok:
                n_col = _volumes_ok(a, b, st, T, pts, q)
                ok = n_col > 0
            if ok and isb[a]:
                bf = _boundary_faces_of(st, T, nbr)
                n_old = np.empty((bf.shape[0], 3))
                area_old = np.empty(bf.shape[0])
                area_new = np.empty(bf.shape[0])
                _star_boundary(bf, pts, n_old, area_old)
                ok = _boundary_ok(a, b, bf, n_old, area_old, pts, area_new, n_new)
            if ok:
                ok = _link_ok(a, b, st, T, alive, nbr, head, nxt, isb, mark_b, mark_ab, counters)
            if ok:
                _apply_merge(a, b, st, T, alive, nbr, head, nxt)
                jump[a] = b
                applied[i] = True
                if children_first:
                    pending[b] -= 1
                tets -= n_col
            else:
                if p == 0:
                    rejected += 1
                todo[left] = i
                left += 1
        if left == n_todo:
            break
        n_todo = left
    return applied, tets, rejected
