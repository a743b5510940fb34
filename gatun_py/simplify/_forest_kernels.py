"""Numba kernels of the merge forest (see :mod:`gatun_py.simplify.forest`): plain arrays in, plain
arrays out; ``parent`` and ``rank`` as the forest holds them (a root's rank is ``ROOT_RANK``)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def ancestors_kernel(parent, rank, n_merges):
    """Ancestor of every vertex after the first ``n_merges`` merges.

    One top-down pass, as in the paper's section 4.2: merges are visited from the latest to the
    earliest (a parent always outranks its children), so a parent's ancestor is final before any
    child copies it. Ranks below ``n_merges`` are distinct, so the order is a counting sort, O(n).
    """
    n = parent.shape[0]
    anc = np.empty(n, np.int32)
    by_rank = np.full(n, -1, np.int64)
    for v in range(n):
        anc[v] = v
        r = rank[v]
        if 0 <= r < n_merges and r < n:
            by_rank[r] = v
    for r in range(min(n_merges, n) - 1, -1, -1):
        v = by_rank[r]
        if v >= 0:
            anc[v] = anc[parent[v]]
    return anc
