"""Ray geometry shared by the ray caster's kernels (private): edge sides, face crossings, projection.

All rays start at the camera position; points are stored relative to it (``P = points - eye``,
float64). For a ray with unit direction ``d`` and a directed edge i -> j, the Pluecker side is the
triple product ``d . (P_i x P_j)``. A triangle (i, j, k) is crossed by the ray iff the three sides
of (i, j), (j, k), (k, i) share a sign: all positive = the ray leaves through the face along its
winding normal, all negative = it enters. Each undirected edge is evaluated once in a canonical
order (lower id first), so the two tets sharing a face always agree; exact zeros are broken by a
symbolic perturbation of the ray direction (simulation of simplicity), which keeps the decisions
those of a real, slightly moved ray: it enters and leaves every tet it meets exactly once, also
through vertices, edges and zero-volume tets.

Where a ray crosses a face, its parameter ``t`` (distance from the eye) and the scalar are the
barycentric combination whose weights are the three edge sides; they depend only on the face's
sorted vertex ids, so a face gives bit-identical values from both sides and in every walking
direction. That is what makes the streaming render (front and back subsegments, any tet order)
equal to the in-memory one.

The helpers here, as those of the other kernel modules, are compiled with ``_nrt=False``: they
never allocate, and without numba's reference counting a call passing arrays costs no atomic
increments and decrements; LLVM then inlines the small ones into their callers. (Numba-level
inlining, ``inline="always"``, gave the same code at twice the compile time: the walk alone took
10 s to compile.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

NEAR = 1e-12  # relative rounding bound of an edge side (float64 error is ~1e-16 of |P_lo| |P_hi|)


@njit(cache=True, _nrt=False)
def _edge_cross(P, i, j):
    """The ray-independent part of the side of i -> j: P_lo x P_hi and the sign of the order."""
    if i < j:
        lo, hi, flip = i, j, 1.0
    else:
        lo, hi, flip = j, i, -1.0
    ax, ay, az = P[lo, 0], P[lo, 1], P[lo, 2]
    bx, by, bz = P[hi, 0], P[hi, 1], P[hi, 2]
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx, flip


@njit(cache=True, _nrt=False)
def _side_cross(cx, cy, cz, flip, dx, dy, dz):
    """:func:`_side` from the edge's :func:`_edge_cross`."""
    v = dx * cx + dy * cy + dz * cz
    if v > 0.0:
        s = 1.0
    elif v < 0.0:
        s = -1.0
    # symbolic perturbation d + (e, e^2, e^3): the first non-zero cross component decides
    elif cx != 0.0:
        s = 1.0 if cx > 0.0 else -1.0
    elif cy != 0.0:
        s = 1.0 if cy > 0.0 else -1.0
    elif cz != 0.0:
        s = 1.0 if cz > 0.0 else -1.0
    else:  # edge collinear with the eye or of zero length: ids decide
        s = 1.0
    return v * flip, s * flip


@njit(cache=True, _nrt=False)
def _side(P, dx, dy, dz, i, j):
    """Pluecker side of the directed edge i -> j: (value, sign), sign never 0."""
    cx, cy, cz, flip = _edge_cross(P, i, j)
    return _side_cross(cx, cy, cz, flip, dx, dy, dz)


@njit(cache=True, _nrt=False)
def _sort3(a, b, c):
    """Sorted triple and the parity (0 even, 1 odd) of the sorting permutation."""
    par = 0
    if a > b:
        a, b = b, a
        par ^= 1
    if b > c:
        b, c = c, b
        par ^= 1
    if a > b:
        a, b = b, a
        par ^= 1
    return a, b, c, par


@njit(cache=True, _nrt=False)
def _face_values(P, dens, dx, dy, dz, a, b, c):
    """Ray parameter t and scalar where the ray crosses the face with sorted ids a < b < c.

    The barycentric weights of the crossing are the three edge sides. Rounding can give them
    mixed signs near an edge; the wrong-signed ones are dropped so the point stays on the face.
    When all vanish the ray lies in the face's plane (e.g. along one of its edges): the crossing
    of the slightly moved ray is somewhere on the chord of the ray inside the triangle, and its
    midpoint is taken.
    """
    wa, _ = _side(P, dx, dy, dz, b, c)
    wb, _ = _side(P, dx, dy, dz, c, a)
    wc, _ = _side(P, dx, dy, dz, a, b)
    return _face_values_w(P, dens, dx, dy, dz, a, b, c, wa, wb, wc)


@njit(cache=True, _nrt=False)
def _face_values_w(P, dens, dx, dy, dz, a, b, c, wa, wb, wc):
    """:func:`_face_values` with the sides of (b, c), (c, a), (a, b) already known (up to a
    common sign)."""
    t, sv, ok = _barycentric(_depth(P, a, dx, dy, dz), _depth(P, b, dx, dy, dz), _depth(P, c, dx, dy, dz),
                             dens[a], dens[b], dens[c], wa, wb, wc)
    if ok:
        return t, sv
    return _chord_midpoint(P, dens, dx, dy, dz, a, b, c)


@njit(cache=True, _nrt=False)
def _depth(P, v, dx, dy, dz):
    """P_v . d: the ray parameter of vertex v's foot on the ray."""
    return P[v, 0] * dx + P[v, 1] * dy + P[v, 2] * dz


@njit(cache=True, _nrt=False)
def _barycentric(ta, tb, tc, da, db, dc, wa, wb, wc):
    """(t, scalar, ok) of the face point with (unnormalised) weights wa, wb, wc, from the vertices'
    depths t and scalars d; ok False when no weight is left (the ray lies in the face's plane:
    :func:`_chord_midpoint`)."""
    w = wa + wb + wc
    if w < 0.0:
        wa, wb, wc = -wa, -wb, -wc
    wa = max(wa, 0.0)
    wb = max(wb, 0.0)
    wc = max(wc, 0.0)
    w = wa + wb + wc
    if w > 0.0 and math.isfinite(w):
        wa /= w
        wb /= w
        wc /= w
        return wa * ta + wb * tb + wc * tc, wa * da + wb * db + wc * dc, True
    return 0.0, 0.0, False


@njit(cache=True, _nrt=False)
def _chord_midpoint(P, dens, dx, dy, dz, a, b, c):
    """Midpoint (t, scalar) of the part of the ray inside triangle (a, b, c), ray in its plane."""
    tmin = np.inf
    tmax = -np.inf
    smin = 0.0
    smax = 0.0
    for q in range(3):
        if q == 0:
            i, j = a, b
        elif q == 1:
            i, j = b, c
        else:
            i, j = c, a
        ex, ey, ez = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
        cx = dy * ez - dz * ey
        cy = dz * ex - dx * ez
        cz = dx * ey - dy * ex
        n2 = cx * cx + cy * cy + cz * cz
        e2 = ex * ex + ey * ey + ez * ez
        for end in range(2):
            if n2 > 0.0:  # where the ray meets the edge's line
                if end == 1:
                    break
                px = P[i, 1] * ez - P[i, 2] * ey
                py = P[i, 2] * ex - P[i, 0] * ez
                pz = P[i, 0] * ey - P[i, 1] * ex
                t = (px * cx + py * cy + pz * cz) / n2
                u = ((t * dx - P[i, 0]) * ex + (t * dy - P[i, 1]) * ey + (t * dz - P[i, 2]) * ez) / e2
                if not (-1e-9 <= u <= 1.0 + 1e-9):
                    continue
                u = min(max(u, 0.0), 1.0)
                sv = dens[i] + u * (dens[j] - dens[i])
            else:  # edge parallel to the ray (or a point): its ends
                k = i if end == 0 else j
                t = P[k, 0] * dx + P[k, 1] * dy + P[k, 2] * dz
                sv = dens[k]
            if t < tmin:
                tmin, smin = t, sv
            if t > tmax:
                tmax, smax = t, sv
    if tmin > tmax:  # numerically nowhere: the centroid's depth
        ta = P[a, 0] * dx + P[a, 1] * dy + P[a, 2] * dz
        tb = P[b, 0] * dx + P[b, 1] * dy + P[b, 2] * dz
        tc = P[c, 0] * dx + P[c, 1] * dy + P[c, 2] * dz
        return (ta + tb + tc) / 3.0, (dens[a] + dens[b] + dens[c]) / 3.0
    return 0.5 * (tmin + tmax), 0.5 * (smin + smax)



@njit(cache=True, _nrt=False)
def _project(P, v, fwd, right, up, tan_half, aspect, width, height):
    """Depth and continuous pixel (column, row from the top) of vertex v, as Camera.project."""
    z = P[v, 0] * fwd[0] + P[v, 1] * fwd[1] + P[v, 2] * fwd[2]
    x = (P[v, 0] * right[0] + P[v, 1] * right[1] + P[v, 2] * right[2]) / (z * tan_half * aspect)
    y = (P[v, 0] * up[0] + P[v, 1] * up[1] + P[v, 2] * up[2]) / (z * tan_half)
    return z, (x + 1.0) * (width / 2.0), (1.0 - y) * (height / 2.0)




@njit(cache=True, _nrt=False)
def _edge_terms(P, i, j, fwd, right, up):
    """The directed edge i -> j's side as fwd . c + x right . c + y up . c, c its canonical cross."""
    cx, cy, cz, flip = _edge_cross(P, i, j)
    return ((fwd[0] * cx + fwd[1] * cy + fwd[2] * cz) * flip, (right[0] * cx + right[1] * cy + right[2] * cz) * flip,
            (up[0] * cx + up[1] * cy + up[2] * cz) * flip)


@njit(cache=True, _nrt=False)
def _norm(P, v):
    return math.sqrt(P[v, 0] * P[v, 0] + P[v, 1] * P[v, 1] + P[v, 2] * P[v, 2])


@njit(cache=True, _nrt=False)
def _flat(P, a, b, c, d):
    """Whether tet (a, b, c, d) has (nearly) zero volume: |6 V| <= 1e-9 of its longest edge cubed."""
    ux, uy, uz = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
    vx, vy, vz = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
    wx, wy, wz = P[d, 0] - P[a, 0], P[d, 1] - P[a, 1], P[d, 2] - P[a, 2]
    vol6 = ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz) + uz * (vx * wy - vy * wx)
    e = max(ux * ux + uy * uy + uz * uz, max(vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz))
    return abs(vol6) <= 1e-9 * e * math.sqrt(e)

