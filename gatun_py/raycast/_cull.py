"""Invisible tets (private): the tets the transfer function makes fully transparent, and the
boundary of the rest.

The walk reads opacity from the transfer function's lookup table, interpolating linearly between
two neighbouring entries (``_walk._lookup``). A sample whose entries are both 0 adds exactly
nothing: ``w = (1 - a) * 0`` front to back, ``0 * c + 1 * a`` back to front, in face mode
``1 - exp(0)``. Every sample inside a tet (and on its faces) has a scalar between the smallest and
the largest of its four vertices' (barycentric weights that sum to one), so a tet is invisible
when every table entry that scalar interval can reach is 0. The interval is widened by one entry
on each side, far more than the rounding of a sample's scalar: the test is on the table the walk
reads, over the whole interval, not only at its ends (a piecewise-linear opacity may rise and fall
back to 0 inside it).

Dropping those tets leaves the visible part, whose boundary (:func:`table_boundary`: the faces
with one tet in the face table) may be non-convex or cut into many pieces; the segment machinery
casts rays into it as into any mesh, and because a face's crossing depth and scalar depend only on
the face, the image is the one the full walk gives.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._facetable import FT_A, FT_B, FT_C, FT_TET0, FT_TET1


def visible_prefix(opacity) -> np.ndarray:
    """Prefix counts of the table entries with opacity > 0: ``p[j] - p[i]`` entries of ``i:j`` are visible.

    Examples
    --------
    >>> visible_prefix(np.array([0.0, 0.0, 0.5, 0.0])).tolist()
    [0, 0, 0, 1, 1]
    """
    p = np.zeros(len(opacity) + 1, dtype=np.int64)
    np.cumsum(np.asarray(opacity) > 0.0, out=p[1:])
    return p


@njit(cache=True, _nrt=False)
def _entry(s, lo, inv, n):
    """The table entry ``_walk._lookup`` starts from at scalar ``s``."""
    x = (s - lo) * inv
    if not x > 0.0:
        return 0
    if x >= n - 1:
        return n - 1
    return int(x)


@njit(cache=True, _nrt=False)
def range_visible(prefix, lo, inv, smin, smax):
    """Whether a scalar interval [smin, smax] can show: some table entry it reaches, widened by one
    entry each way, has opacity > 0 (``prefix``: :func:`visible_prefix` of the table's opacity).
    A tet's interval is that of its four vertices; a brick's, the range its file stores."""
    n = prefix.shape[0] - 1
    i0 = max(_entry(smin, lo, inv, n) - 1, 0)
    i1 = min(_entry(smax, lo, inv, n) + 2, n - 1)
    return prefix[i1 + 1] - prefix[i0] > 0


@njit(cache=True, parallel=True)
def visible_tets(tets, dens, prefix, lo, inv, out):
    """``out[t]`` = 1 if tet t can show (:func:`range_visible` of its vertices' scalar interval),
    else 0. One task per tet, each writing its own entry."""
    for t in prange(tets.shape[0]):
        d0, d1, d2, d3 = dens[tets[t, 0]], dens[tets[t, 1]], dens[tets[t, 2]], dens[tets[t, 3]]
        out[t] = 1 if range_visible(prefix, lo, inv, min(min(d0, d1), min(d2, d3)), max(max(d0, d1), max(d2, d3))) else 0


@njit(cache=True)
def table_boundary(htab):
    """The faces of the face table with one tet, wound outward in it: the boundary of the tets
    entered (the codes' parity says whether the sorted ids are wound outward)."""
    n = 0
    for h in range(htab.shape[0]):
        if htab[h, FT_A] >= 0 and (htab[h, FT_TET0] >= 0) != (htab[h, FT_TET1] >= 0):
            n += 1
    out = np.empty((n, 3), dtype=np.int64)
    k = 0
    for h in range(htab.shape[0]):
        if htab[h, FT_A] >= 0 and (htab[h, FT_TET0] >= 0) != (htab[h, FT_TET1] >= 0):
            code = htab[h, FT_TET0] if htab[h, FT_TET0] >= 0 else htab[h, FT_TET1]
            out[k, 0] = htab[h, FT_A]
            if (code & 1) == 0:
                out[k, 1], out[k, 2] = htab[h, FT_B], htab[h, FT_C]
            else:
                out[k, 1], out[k, 2] = htab[h, FT_C], htab[h, FT_B]
            k += 1
    return out
