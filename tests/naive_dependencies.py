"""Slow, obviously correct reference of the merge dependencies (and of a cut's ancestors).

Recomputes every tet's image from scratch at every prefix state with :func:`ancestors_naive`:
``last[T]`` is the last merge after which T's image differed from before it (dead or alive).
"""

from __future__ import annotations

import numpy as np
from naive_simplify import ancestors_naive


def dependencies_naive(tets, parent, rank):
    """(list of sorted dependency lists, list of removal counts), by rank."""
    tets = np.asarray(tets, np.int64)
    k = int(sum(1 for r in rank if r < 2**31 - 1))
    by_rank = {int(r): v for v, r in enumerate(rank) if r < 2**31 - 1}
    last = [-1] * len(tets)
    image = ancestors_naive(parent, rank, 0)[tets]
    deps, removed = [], []
    for i in range(k):
        a, b = by_rank[i], int(parent[by_rank[i]])
        live = [len(set(q.tolist())) == 4 for q in image]
        # dead tets too: one left alive by a cut that skips its killer is around a and b there
        near = [t for t in range(len(tets)) if a in image[t] or b in image[t]]
        deps.append(sorted({last[t] for t in near if last[t] >= 0}))
        removed.append(sum(1 for t in near if live[t] and a in image[t] and b in image[t]))
        nxt = ancestors_naive(parent, rank, i + 1)[tets]
        for t in range(len(tets)):
            if not np.array_equal(nxt[t], image[t]):
                last[t] = i
        image = nxt
    return deps, removed


def cut_ancestors_naive(parent, rank, applied):
    """Follow the parent while that vertex's merge is applied."""
    out = []
    for v in range(len(parent)):
        while rank[v] < len(applied) and applied[rank[v]]:
            v = parent[v]
        out.append(v)
    return np.array(out, np.int64)


def closure_naive(deps, applied):
    """The smallest closed cut containing ``applied``."""
    out = np.array(applied, bool)
    for i in range(len(out) - 1, -1, -1):  # dependencies have lower ranks: one backward pass
        if out[i]:
            for j in deps[i]:
                out[j] = True
    return out


def merge_volume_changes(mesh, parent, rank):
    """Enclosed-volume change of every merge in its prefix state, by replaying the merges with
    Python sets (each merge: volume of its star after minus before)."""
    pts = np.asarray(mesh.points, np.float64)
    T = np.array(mesh.tets, np.int64)
    alive = np.ones(len(T), bool)
    around = [set() for _ in range(len(pts))]
    for t, q in enumerate(T.tolist()):
        for v in q:
            around[v].add(t)

    def vol(ts):
        q = T[ts]
        a = pts[q[:, 0]]
        return float(np.einsum("ij,ij->i", pts[q[:, 1]] - a, np.cross(pts[q[:, 2]] - a, pts[q[:, 3]] - a)).sum()) / 6

    by_rank = sorted((int(r), v) for v, r in enumerate(rank) if r < 2**31 - 1)
    out = []
    for _, a in by_rank:
        b = int(parent[a])
        star = np.array(sorted(t for t in around[a] if alive[t]), np.int64)
        before = vol(star)
        for t in around[a]:
            T[t][T[t] == a] = b
        around[b] |= around[a]
        around[a] = set()
        star_alive = np.array([t for t in star if len(set(T[t].tolist())) == 4], np.int64)
        alive[star[~np.isin(star, star_alive)]] = False
        out.append(vol(star_alive) - before)
    return np.array(out)
