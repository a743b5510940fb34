"""Numba kernels of the on-the-fly simplification filter (paper 4.2): waitCount queues.

State, all plain arrays owned by :class:`gatun_py.simplify.filter.SimplifyFilter`:

* ``anc[v]``       ancestor of vertex v (decode numbering) for the target number of merges
* ``arrived[v]``   the decoder has emitted v
* ``head[v]``      first wait-list entry of ancestor v (-1: none)
* ``nxt[e]``, ``item_of[e]``   singly linked wait lists: entry e parks item ``item_of[e]``
* ``parked[p]``    an item (tet or boundary face, rewritten to ancestors) waiting on ancestors
* ``wait[p]``      its waitCount: how many of its distinct ancestors have not arrived yet
* ``counts``       [items ever parked, wait-list entries used, items waiting now]
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def release(first, count, head, nxt, item_of, parked, wait, counts, out, n_out):
    """Vertices first..first+count-1 have arrived: move items whose waitCount drops to 0 to out."""
    for v in range(first, first + count):
        e = head[v]
        while e >= 0:
            p = item_of[e]
            wait[p] -= 1
            if wait[p] == 0:
                counts[2] -= 1
                for c in range(parked.shape[1]):
                    out[n_out, c] = parked[p, c]
                n_out += 1
            e = nxt[e]
        head[v] = -1
    return n_out


@njit(cache=True)
def filter_items(items, start, anc, arrived, head, nxt, item_of, parked, wait, counts, out, n_out):
    """Rewrite items[start:] (tets or faces) to ancestors; drop degenerate ones, forward or park the rest.

    Returns (n_out, next item): stops early when the parking arrays are full, so that the caller
    grows them and resumes. n_out is -1 if a vertex id is out of range (corrupt input).
    """
    n = anc.shape[0]
    k = items.shape[1]
    mapped = np.empty(4, np.int64)
    for i in range(start, items.shape[0]):
        for c in range(k):
            v = items[i, c]
            if v < 0 or v >= n:
                return -1, i
            mapped[c] = anc[v]
        bad = False
        for c in range(k):
            for d in range(c + 1, k):
                if mapped[c] == mapped[d]:
                    bad = True
        if bad:
            continue  # collapsed by a merge: not part of the simplified mesh
        missing = 0
        for c in range(k):
            if not arrived[mapped[c]]:
                missing += 1
        if missing == 0:
            for c in range(k):
                out[n_out, c] = mapped[c]
            n_out += 1
            continue
        if counts[0] >= parked.shape[0] or counts[1] + missing > nxt.shape[0]:
            return n_out, i  # full: the caller grows the arrays and calls again from item i
        p = counts[0]
        counts[0] += 1
        counts[2] += 1
        for c in range(k):
            parked[p, c] = mapped[c]
        wait[p] = missing
        for c in range(k):
            a = mapped[c]
            if not arrived[a]:
                e = counts[1]
                counts[1] += 1
                item_of[e] = p
                nxt[e] = head[a]
                head[a] = e
    return n_out, items.shape[0]
