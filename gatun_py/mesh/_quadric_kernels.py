"""The quadric math of the merge forest, frozen with the format: the forest coder's quadrics
(:mod:`gatun_py.codec._forest_kernels`; format 7 on decodes its ranks from them) and the decimator's
(:mod:`gatun_py.simplify._decimate_kernels`) are formed here, every operation spelled out in one
order so the results are the same bits on every machine. A change here changes the bytes of files
that exist: the golden files and the forest hashes guard it.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, _nrt=False)
def sorted4(a, b, c, d):
    """The four ids in ascending order (a sorting network)."""
    if a > b:
        a, b = b, a
    if c > d:
        c, d = d, c
    if a > c:
        a, c = c, a
    if b > d:
        b, d = d, b
    if b > c:
        b, c = c, b
    return a, b, c, d


@njit(cache=True, nogil=True, _nrt=False)
def spatial_volume(u, a, b, c, d):
    """|det| of the tet's spatial edges from corner a (6 x its volume, in normalised units)."""
    p0, p1, p2 = u[b, 0] - u[a, 0], u[b, 1] - u[a, 1], u[b, 2] - u[a, 2]
    q0, q1, q2 = u[c, 0] - u[a, 0], u[c, 1] - u[a, 1], u[c, 2] - u[a, 2]
    r0, r1, r2 = u[d, 0] - u[a, 0], u[d, 1] - u[a, 1], u[d, 2] - u[a, 2]
    w = abs(p0 * (q1 * r2 - q2 * r1) - p1 * (q0 * r2 - q2 * r0) + p2 * (q0 * r1 - q1 * r0))
    return w if w < np.inf else 0.0  # NaN and inf: no weight


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def hyperplane_normal(u, a, b, c, d):
    """(length, n0, n1, n2, n3): the unit normal of the hyperplane through rows a, b, c, d of
    ``u`` (points in 4-D, e.g. (x, y, z, value)) and the length it had before normalising; n = 0
    when that length is 0 or not finite (a flat tet: no unique hyperplane).

    The normal is the generalised cross product of the three edges from a: n_j = (-1)^j det of
    the edges without column j, from the 2 x 2 minors of the last two edges. Every operation is
    spelled out in this order, so the result is the same bits on every machine: the forest
    coder's quadrics (format 7 decodes from them) and the decimator's both come from here."""
    # the three edges from corner a in (x, y, z, value)
    p0, p1, p2, p3 = u[b, 0] - u[a, 0], u[b, 1] - u[a, 1], u[b, 2] - u[a, 2], u[b, 3] - u[a, 3]
    q0, q1, q2, q3 = u[c, 0] - u[a, 0], u[c, 1] - u[a, 1], u[c, 2] - u[a, 2], u[c, 3] - u[a, 3]
    r0, r1, r2, r3 = u[d, 0] - u[a, 0], u[d, 1] - u[a, 1], u[d, 2] - u[a, 2], u[d, 3] - u[a, 3]
    m01 = q0 * r1 - q1 * r0
    m02 = q0 * r2 - q2 * r0
    m03 = q0 * r3 - q3 * r0
    m12 = q1 * r2 - q2 * r1
    m13 = q1 * r3 - q3 * r1
    m23 = q2 * r3 - q3 * r2
    n0 = p1 * m23 - p2 * m13 + p3 * m12
    n1 = -(p0 * m23 - p2 * m03 + p3 * m02)
    n2 = p0 * m13 - p1 * m03 + p3 * m01
    n3 = -(p0 * m12 - p1 * m02 + p2 * m01)
    length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
    if not (length > 0 and length < np.inf):
        return length, 0.0, 0.0, 0.0, 0.0
    return length, n0 / length, n1 / length, n2 / length, n3 / length


@njit(cache=True, nogil=True, _nrt=False)
def tet_quadric_terms(u, a, b, c, d, w, terms):
    """The 10 terms of A of one tet's quadric (corners in id order, ``w`` its
    :func:`spatial_volume`): its volume times the squared
    distance to the hyperplane through its corners in (x, y, z, value), about any of its corners
    (the plane passes through them: no b, no c). False for a flat tet."""
    length, n0, n1, n2, n3 = hyperplane_normal(u, a, b, c, d)
    if not (length > 0 and w > 0 and length < np.inf):
        return False
    w0, w1, w2, w3 = w * n0, w * n1, w * n2, w * n3
    terms[0] = w0 * n0
    terms[1] = w0 * n1
    terms[2] = w0 * n2
    terms[3] = w0 * n3
    terms[4] = w1 * n1
    terms[5] = w1 * n2
    terms[6] = w1 * n3
    terms[7] = w2 * n2
    terms[8] = w2 * n3
    terms[9] = w3 * n3
    return True
