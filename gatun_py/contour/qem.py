"""QEM edge collapse (Garland & Heckbert) over a growing surface with locked vertices.

One call of :func:`decimate` runs the global priority queue over the current intermediate surface
until it holds ``target`` faces or no legal collapse is left. An edge is a candidate only when both
its vertices are unlocked (their mesh edges' stars are complete, see ``marching``): nothing that is
still to arrive can then reference a vertex that a collapse removes or moves. Legality:

* the link condition (the common neighbours of u and v are exactly the apexes of the faces on uv);
* no face around u or v turns over (its normal keeps a positive dot product with the old one);
* the surface boundary stays: a boundary vertex only merges with a boundary neighbour along a
  boundary edge, the boundary vertex survives a merge with an interior one, and Garland's
  perpendicular constraint planes in its quadric keep the new position on the border.

Error: each vertex carries two quadrics (``QUADRIC_WIDTH`` = 20 numbers, see :data:`CURRENT` and
:data:`HISTORY`). The *current* one is the area-weighted plane quadric of the faces around the
vertex as they are now, plus the border's constraint planes (Lindstrom & Turk's memoryless
simplification: rebuilt for the ring of every collapse, so a cost measures the change against the
surface as it is); the *history* one accumulates the original faces' quadrics over the collapses
(Garland & Heckbert). An edge's cost is current + ``HISTORY_WEIGHT`` x history: the history term
keeps many small memoryless steps from drifting away from the original surface. Measured on
Blunt-fin, Combustion and the gmsh flange at R = 0.2 / 0.05 / 0.01 (bench/bench_isosurface.py),
against the best cascade this took the geometric mean RMS ratio from 0.98 (accumulated quadric
alone) to 0.80 and the cells with both RMS and Hausdorff ratios <= 1 from 5 of 18 to 13.

The heap key divides that cost by the square root of the quadric's total weight
(:data:`COST_WEIGHT_POWER`): between Garland's area-weighted sum, which lets a small feature (a thin
lip, little area) go for next to nothing, and meshoptimizer's weighted mean squared distance, which
gave up RMS. The original border's constraint planes enter the history ten times heavier than the
current quadric's (:data:`BOUNDARY_HISTORY_WEIGHT`), so the border's shape survives the memoryless
rebuilds. At the extreme reductions these two took the worst Hausdorff ratio from 1.87 (Blunt-fin
1.193 at 161 faces, where the curl of the surface along the plate was planed off) to 1.34.

One-sided distance (Hausdorff-aware, as Klein et al. and Cignoni's Metro measure it): within a
call every live vertex stands for a chain of points (the positions, at the call's start, of itself
and of the vertices it absorbed since), and a collapse's key is the larger of the quadric's and
``HAUSDORFF_WEIGHT`` x (the farthest of u's and v's points from the new fan)^2 x the same
sqrt(weight) x importance (:data:`HAUSDORFF_WEIGHT`). Planes are infinite, so a quadric does not see
a feature that is removed sideways: the curl of Blunt-fin's surface along the plate (its border
pulled off the plate, 1.7 % of the diagonal away at 161 faces) or a small closed piece of Combustion's
(the last collapse of a piece leaves no face: its points are measured to the new vertex). The term is
computed only when a collapse surfaces, after the legality tests, and the collapse goes back to the
heap when it is no longer the cheapest (its key only grows, so the order is still the exact keys').
Measured (bench/bench_isosurface.py, 18 cells): cells with both ratios <= the best cascade's 16 -> 18,
the geometric mean Hausdorff ratio 0.673 -> 0.417 and RMS ratio 0.784 -> 0.750. Its price on
flange-10m at R = 0.05 (243,238 faces -> 12,162, 165 k distance searches, 2.4 M point-triangle
tests): the collapse kernel's CPU +20 to 25 %, the whole ``tetc isosurface`` process's CPU +5 %.
The search is cut short both ways: points nearer the new vertex than the floor (the distance at
which the term equals the quadric's key) are skipped, a face whose plane is no nearer than the best
so far is not tested, and past the next entry's key the search stops.

Placement: the quadric's minimum, solved as an offset from the edge's midpoint with a tiny ridge
(so a flat or cylindrical quadric does not throw the vertex along its free directions) and kept
within two edge lengths of the midpoint; else, or when cheaper, the cheapest point of the segment
(the quadric restricted to the edge is a parabola).

Each face's quadric is weighted by its area and by the importance of its vertices (Peng et al.),
and an edge's cost by the larger importance of its ends (the current quadric alone, rebuilt from
the simplified faces, dilutes a face weight: the importance test's hot region lost its margin).

After a collapse only the survivor's edges are re-costed at once; an edge of the ring whose end's
current quadric was rebuilt is re-costed when it surfaces (lazy update: pushing every ring edge at
every collapse costs far more; ``bench/sections/isosurface.md``).

State is plain arrays (the driver owns and grows them); the heap is local to a call: a 4-ary heap
of 24-byte records (cost, edge, collapse count when costed), each edge pushed once (from its lower
end, then heapified), stale entries dropped when they surface. Faces' planes are cached for the
call and rewritten for the faces a collapse changes, so rebuilding a ring vertex's current quadric
only sums them (flange-10m's three rounds: 1.31 s -> 0.80 s of kernel CPU, same collapses).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Garland's constraint planes along the border, weighted by edge length squared like a face's area
#: (VTK's default since 9.3; 10 and 100 measured worse RMS and Hausdorff with the current quadric)
BOUNDARY_WEIGHT = 1.0
#: the same planes of the original border in the history quadric: the border's shape outlives the
#: memoryless rebuilds there (Blunt-fin 1.193 at 161 faces: the curl where the surface meets the
#: plate was planed off, Hausdorff 2.37 % -> 1.70 %; 3 in both quadrics kept it too, 1.18 %, but cost
#: Hausdorff at R = 0.05 on both isovalues)
BOUNDARY_HISTORY_WEIGHT = 10.0
#: columns of a vertex's quadrics: the current faces' (memoryless) and the accumulated history
CURRENT = slice(0, 10)
HISTORY_BASE = 10  # the history's first column (a kernel's ``base`` argument)
HISTORY = slice(HISTORY_BASE, 20)
QUADRIC_WIDTH = 20
#: weight of the history quadric in a collapse's cost (0.1 / 0.3 / 1 measured; 0.3 met the most cells)
HISTORY_WEIGHT = 0.3
#: an edge's cost is its quadric's error divided by the quadric's total weight (its trace: the sum of
#: its planes' weights) to this power: 0 is Garland's area-weighted sum, 1 the weighted mean squared
#: distance meshoptimizer ranks by; in between, a small feature (a thin lip, a narrow tip: little
#: area, so a cheap sum) is not planed off for free, which is what the Hausdorff distance sees
#: (measured 0 / 0.5 / 1: 1 cost RMS everywhere, 0.5 kept RMS and lowered the worst Hausdorff ratios)
COST_WEIGHT_POWER = 0.5
PLACE_RIDGE = 1e-6  # ridge on the placement solve, relative to the trace of the quadric
PLACE_REACH = 4.0  # the optimum may lie within 2 edge lengths of the midpoint (squared ratio)
#: weight of the one-sided distance term in a collapse's key: key = max(quadric key, HAUSDORFF_WEIGHT x
#: d_max^2 x sqrt(weight) x importance), the quadric key being about sqrt(weight) x the mean squared
#: distance, so the term decides once the farthest point is ~1.8 x the mean distance away (0 turns
#: it off: the quadric alone)
HAUSDORFF_WEIGHT = 0.3


@njit(cache=True)
def _add_plane(q, v, nx, ny, nz, d, w, base):
    """Add w (n . x + d)^2 to the quadric in columns base..base+9 of row v."""
    q[v, base + 0] += w * nx * nx
    q[v, base + 1] += w * nx * ny
    q[v, base + 2] += w * nx * nz
    q[v, base + 3] += w * nx * d
    q[v, base + 4] += w * ny * ny
    q[v, base + 5] += w * ny * nz
    q[v, base + 6] += w * ny * d
    q[v, base + 7] += w * nz * nz
    q[v, base + 8] += w * nz * d
    q[v, base + 9] += w * d * d


@njit(cache=True, inline="always")
def _normal(vpos, a, b, c):
    """Unnormalised normal (b - a) x (c - a) of face (a, b, c)."""
    return _cross(vpos[a, 0], vpos[a, 1], vpos[a, 2], vpos[b, 0], vpos[b, 1], vpos[b, 2],
                  vpos[c, 0], vpos[c, 1], vpos[c, 2])


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz, cx, cy, cz):
    ux, uy, uz = bx - ax, by - ay, bz - az
    wx, wy, wz = cx - ax, cy - ay, cz - az
    return uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx


@njit(cache=True, inline="always")
def _face_plane(vpos, vimp, a, b, c):
    """(nx, ny, nz, d, weight) of face (a, b, c): unit normal, offset, area x mean importance;
    weight 0 for a degenerate face."""
    nx, ny, nz = _normal(vpos, a, b, c)
    ln = np.sqrt(nx * nx + ny * ny + nz * nz)
    if ln == 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    nx /= ln
    ny /= ln
    nz /= ln
    d = -(nx * vpos[a, 0] + ny * vpos[a, 1] + nz * vpos[a, 2])
    return nx, ny, nz, d, 0.5 * ln * (vimp[a] + vimp[b] + vimp[c]) / 3.0


@njit(cache=True, nogil=True)
def add_face_quadrics(vpos, vq, vimp, tris, f0, f1):
    """Add the area-weighted plane quadric of faces f0..f1-1 to both quadrics of their vertices."""
    for f in range(f0, f1):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if a < 0:
            continue
        nx, ny, nz, d, w = _face_plane(vpos, vimp, a, b, c)
        if w == 0.0:
            continue
        for base in (0, 10):
            _add_plane(vq, a, nx, ny, nz, d, w, base)
            _add_plane(vq, b, nx, ny, nz, d, w, base)
            _add_plane(vq, c, nx, ny, nz, d, w, base)


@njit(cache=True)
def _qcost(q, x, y, z):
    return (q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x
            + q[4] * y * y + 2 * q[5] * y * z + 2 * q[6] * y
            + q[7] * z * z + 2 * q[8] * z + q[9])


@njit(cache=True)
def _placement(vq, vpos, vbnd, u, v, qs):
    """Best position and cost for collapsing edge (u, v): (cost, x, y, z), under the quadric
    current + HISTORY_WEIGHT x history of both ends (left in ``qs``).

    The same rule for every edge, on the border or not: a boundary vertex carries Garland's
    perpendicular constraint planes in its quadric, which keep the result on the border (snapping an
    interior vertex onto the boundary vertex instead measured worse RMS on all three data sets).
    """
    for k in range(10):
        qs[k] = vq[u, k] + vq[v, k] + HISTORY_WEIGHT * (vq[u, 10 + k] + vq[v, 10 + k])
    ux, uy, uz = vpos[u, 0], vpos[u, 1], vpos[u, 2]
    ex, ey, ez = vpos[v, 0] - ux, vpos[v, 1] - uy, vpos[v, 2] - uz
    mx, my, mz = ux + 0.5 * ex, uy + 0.5 * ey, uz + 0.5 * ez
    a00, a01, a02, a11, a12, a22 = qs[0], qs[1], qs[2], qs[4], qs[5], qs[7]
    # gradient of the quadric at the midpoint / 2: A m - b with b = -(q3, q6, q8)
    gx = a00 * mx + a01 * my + a02 * mz + qs[3]
    gy = a01 * mx + a11 * my + a12 * mz + qs[6]
    gz = a02 * mx + a12 * my + a22 * mz + qs[8]
    best = np.inf
    bx = by = bz = 0.0
    scale = a00 + a11 + a22
    if scale > 0.0:
        # the optimum as an offset from the midpoint, (A + eps I) d = -(A m - b): a small ridge
        # keeps a nearly flat or cylindrical quadric from throwing the vertex along its flat
        # directions (Lindstrom's SVD placement, without the SVD), a full-rank one is barely moved
        eps = PLACE_RIDGE * scale
        r00, r11, r22 = a00 + eps, a11 + eps, a22 + eps
        c00 = r11 * r22 - a12 * a12
        c01 = a02 * a12 - a01 * r22
        c02 = a01 * a12 - a02 * r11
        det = r00 * c00 + a01 * c01 + a02 * c02
        if abs(det) > 1e-12 * scale * scale * scale:
            c11 = r00 * r22 - a02 * a02
            c12 = a01 * a02 - r00 * a12
            c22 = r00 * r11 - a01 * a01
            dx = -(c00 * gx + c01 * gy + c02 * gz) / det
            dy = -(c01 * gx + c11 * gy + c12 * gz) / det
            dz = -(c02 * gx + c12 * gy + c22 * gz) / det
            # keep the optimum near the edge: a far-off solve of a nearly flat quadric is no good
            if dx * dx + dy * dy + dz * dz <= PLACE_REACH * (ex * ex + ey * ey + ez * ez):
                x, y, z = mx + dx, my + dy, mz + dz
                best, bx, by, bz = _qcost(qs, x, y, z), x, y, z
    # the cheapest point of the segment (the quadric restricted to the edge is a parabola)
    aee = ex * (a00 * ex + a01 * ey + a02 * ez) + ey * (a01 * ex + a11 * ey + a12 * ez) \
        + ez * (a02 * ex + a12 * ey + a22 * ez)
    ge = gx * ex + gy * ey + gz * ez  # d/dt at the midpoint is 2 (g . e)
    t = 0.5
    if aee > 0.0:
        t = 0.5 - ge / aee
        t = min(max(t, 0.0), 1.0)
    elif ge > 0.0:
        t = 0.0
    elif ge < 0.0:
        t = 1.0
    x, y, z = ux + t * ex, uy + t * ey, uz + t * ez
    c = _qcost(qs, x, y, z)
    if c < best:
        best, bx, by, bz = c, x, y, z
    return max(best, 0.0), bx, by, bz


@njit(cache=True, inline="always")
def _point_triangle2(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Squared distance from point p to triangle abc (Ericson, Real-Time Collision Detection 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        qx, qy, qz = ax + t * abx, ay + t * aby, az + t * abz
        return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        qx, qy, qz = ax + t * acx, ay + t * acy, az + t * acz
        return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        qx, qy, qz = bx + t * (cx - bx), by + t * (cy - by), bz + t * (cz - bz)
        return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2
    den = va + vb + vc
    if den <= 0.0:  # a flat triangle: its corners were tried above
        return min(apx * apx + apy * apy + apz * apz, min(bpx * bpx + bpy * bpy + bpz * bpz,
                                                          cpx * cpx + cpy * cpy + cpz * cpz))
    v = vb / den
    w = vc / den
    qx, qy, qz = ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w
    return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2


FAN_WIDTH = 13


@njit(cache=True)
def _fan_distance(x, y, z, u, v, start, cnt, refs, tris, vpos, opos, nxt, fan, floor, ceiling):
    """The largest squared distance from the points that u and v stand for (their chains in ``nxt``,
    positions in ``opos``) to the fan of faces around them after u and v merge at (x, y, z), or
    ``floor`` if that is larger; the search stops as soon as it passes ``ceiling`` (the caller only
    needs to know that). ``fan`` (rows of ``FAN_WIDTH``: 9 coordinates, unit normal, offset) is scratch space, grown when too small.
    Returns (distance squared, fan)."""
    nf = 0
    for side in (u, v):
        for i in range(cnt[side]):
            f = refs[start[side] + i]
            a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
            if a < 0:
                continue
            hu = a == u or b == u or c == u
            hv = a == v or b == v or c == v
            if (hu and hv) or (side == u and hv):
                continue  # on the edge (it dies), or already taken from v's list
            if nf == fan.shape[0]:
                grown = np.empty((2 * nf, FAN_WIDTH))
                grown[:nf] = fan
                fan = grown
            for k in range(3):
                w = tris[f, k]
                if w == u or w == v:
                    fan[nf, 3 * k], fan[nf, 3 * k + 1], fan[nf, 3 * k + 2] = x, y, z
                else:
                    fan[nf, 3 * k], fan[nf, 3 * k + 1], fan[nf, 3 * k + 2] = vpos[w, 0], vpos[w, 1], vpos[w, 2]
            # its plane (unit normal, offset; zero for a flat face): a point whose distance to the
            # plane is already no nearer than the best face so far skips the exact test
            nx, ny, nz = _cross(fan[nf, 0], fan[nf, 1], fan[nf, 2], fan[nf, 3], fan[nf, 4], fan[nf, 5],
                                fan[nf, 6], fan[nf, 7], fan[nf, 8])
            ln = np.sqrt(nx * nx + ny * ny + nz * nz)
            if ln > 0.0:
                nx, ny, nz = nx / ln, ny / ln, nz / ln
            fan[nf, 9], fan[nf, 10], fan[nf, 11] = nx, ny, nz
            fan[nf, 12] = -(nx * fan[nf, 0] + ny * fan[nf, 1] + nz * fan[nf, 2])
            nf += 1
    worst = floor
    near = 0  # the face that was near enough for the last point: a chain's points are neighbours
    for end in (u, v):
        p = end
        while p >= 0:
            px, py, pz = opos[p, 0], opos[p, 1], opos[p, 2]
            p = nxt[p]
            # the new vertex is on the fan: a point this close to it cannot raise the maximum
            best = (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2
            if best <= worst:
                continue
            for i in range(nf):  # none left (a small closed piece collapsing): the new vertex
                g = near + i
                if g >= nf:
                    g -= nf
                h = fan[g, 9] * px + fan[g, 10] * py + fan[g, 11] * pz + fan[g, 12]
                if h * h >= best:
                    continue
                d = _point_triangle2(px, py, pz, fan[g, 0], fan[g, 1], fan[g, 2], fan[g, 3], fan[g, 4], fan[g, 5],
                                     fan[g, 6], fan[g, 7], fan[g, 8])
                if d < best:
                    best = d
                    if best <= worst:
                        near = g
                        break
            if best > worst:
                worst = best
                if worst > ceiling:
                    return worst, fan
    return worst, fan


# -- 4-ary min-heap of collapse candidates ---------------------------------------------------------
#: one heap entry: the cost first (the key), then the edge and the collapse count when it was
#: costed: an entry is stale when an end moved (``moved``) or died since, and is re-costed when an
#: end's current quadric was rebuilt since (``changed``). 24 bytes, and four children per node:
#: a pop from a heap of a few hundred thousand entries runs half the levels of a binary heap, each
#: level's children in about one cache line (the pops, most of them of stale entries, were the
#: collapse loop's largest cost)
HEAP_ENTRY = np.dtype([("cost", np.float64), ("u", np.int32), ("v", np.int32), ("t", np.int32), ("pad", np.int32)])


@njit(cache=True)
def _heap_push(heap, n, cost, u, v, t, sift=True):
    """Add an entry (at the end only, when not ``sift``: :func:`_heapify` orders them later)."""
    if n == heap.shape[0]:
        grown = np.empty(2 * n + 16, HEAP_ENTRY)
        grown[:n] = heap[:n]
        heap = grown
    i = n
    while sift and i > 0:
        p = (i - 1) >> 2
        if heap[p].cost <= cost:
            break
        heap[i] = heap[p]
        i = p
    e = heap[i]
    e.cost = cost
    e.u = u
    e.v = v
    e.t = t
    return heap, n + 1


@njit(cache=True)
def _sift_down(heap, i, n):
    """Move entry i down to its place in heap[:n]."""
    c = heap[i].cost
    u, v, t = heap[i].u, heap[i].v, heap[i].t
    while True:
        first = 4 * i + 1
        if first >= n:
            break
        m = first
        mc = heap[first].cost
        last = min(first + 4, n)
        for j in range(first + 1, last):
            cj = heap[j].cost
            if cj < mc:
                m, mc = j, cj
        if mc >= c:
            break
        heap[i] = heap[m]
        i = m
    e = heap[i]
    e.cost = c
    e.u = u
    e.v = v
    e.t = t


@njit(cache=True)
def _heap_pop(heap, n):
    """Remove the top (the caller read it at index 0); returns the new size."""
    n -= 1
    if n > 0:
        heap[0] = heap[n]
        _sift_down(heap, 0, n)
    return n


@njit(cache=True)
def _heapify(heap, n):
    for i in range((n - 2) // 4, -1, -1):
        _sift_down(heap, i, n)


# -- adjacency: per-vertex face lists in one array, rewritten at the end on change ----------------

@njit(cache=True)
def _build_adjacency(nv, tris, nt, extra):
    cnt = np.zeros(nv, np.int64)
    for f in range(nt):
        if tris[f, 0] >= 0:
            for k in range(3):
                cnt[tris[f, k]] += 1
    start = np.zeros(nv, np.int64)
    s = 0
    for v in range(nv):
        start[v] = s
        s += cnt[v]
    refs = np.empty(s + extra, np.int32)
    fill = np.zeros(nv, np.int64)
    for f in range(nt):
        if tris[f, 0] >= 0:
            for k in range(3):
                v = tris[f, k]
                refs[start[v] + fill[v]] = f
                fill[v] += 1
    return start, fill, refs, s


@njit(cache=True)
def _mark_boundary(u, start, cnt, refs, tris, vpos, vq, vbnd, nbr, nbr_n, base):
    """Find u's boundary edges (edges of one live face) and add their constraint planes to u's
    quadric in columns base..base+9."""
    m = 0
    for i in range(cnt[u]):
        f = refs[start[u] + i]
        if tris[f, 0] < 0:  # dead faces stay in the lists until they are rewritten
            continue
        for k in range(3):
            w = tris[f, k]
            if w != u:
                found = False
                for j in range(m):
                    if nbr[j] == w:
                        nbr_n[j] += 1
                        found = True
                        break
                if not found and m < nbr.shape[0]:
                    nbr[m] = w
                    nbr_n[m] = 1
                    m += 1
    for j in range(m):
        if nbr_n[j] != 1:
            continue
        w = nbr[j]
        vbnd[u] = 1
        # the face on edge (u, w): its normal and the plane through the edge perpendicular to it
        for i in range(cnt[u]):
            f = refs[start[u] + i]
            if tris[f, 0] >= 0 and (tris[f, 0] == w or tris[f, 1] == w or tris[f, 2] == w):
                nx, ny, nz = _normal(vpos, tris[f, 0], tris[f, 1], tris[f, 2])
                ex = vpos[w, 0] - vpos[u, 0]
                ey = vpos[w, 1] - vpos[u, 1]
                ez = vpos[w, 2] - vpos[u, 2]
                px = ey * nz - ez * ny
                py = ez * nx - ex * nz
                pz = ex * ny - ey * nx
                lp = np.sqrt(px * px + py * py + pz * pz)
                if lp > 0:
                    px /= lp
                    py /= lp
                    pz /= lp
                    d = -(px * vpos[u, 0] + py * vpos[u, 1] + pz * vpos[u, 2])
                    el2 = ex * ex + ey * ey + ez * ez
                    w_border = BOUNDARY_HISTORY_WEIGHT if base == HISTORY_BASE else BOUNDARY_WEIGHT
                    _add_plane(vq, u, px, py, pz, d, w_border * el2, base)
                break


@njit(cache=True)
def _flips(x, y, z, moving, other, start, cnt, refs, tris, vpos, min_dot):
    """Whether moving vertex ``moving`` to (x, y, z) turns over one of its faces not on the edge."""
    for i in range(cnt[moving]):
        f = refs[start[moving] + i]
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if a < 0 or a == other or b == other or c == other:
            continue
        n0x, n0y, n0z = _normal(vpos, a, b, c)
        # the same face with the moving vertex at (x, y, z)
        ax, ay, az = (x, y, z) if a == moving else (vpos[a, 0], vpos[a, 1], vpos[a, 2])
        bx, by, bz = (x, y, z) if b == moving else (vpos[b, 0], vpos[b, 1], vpos[b, 2])
        cx, cy, cz = (x, y, z) if c == moving else (vpos[c, 0], vpos[c, 1], vpos[c, 2])
        n1x, n1y, n1z = _cross(ax, ay, az, bx, by, bz, cx, cy, cz)
        l0 = np.sqrt(n0x * n0x + n0y * n0y + n0z * n0z)
        l1 = np.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
        if l1 == 0.0:
            return True
        if l0 > 0.0 and n0x * n1x + n0y * n1y + n0z * n1z < min_dot * l0 * l1:
            return True
    return False


@njit(cache=True)
def _edge_cost(vq, vpos, vbnd, vimp, u, v, qs):
    """The heap key of edge (u, v): its collapse's quadric cost over the quadric's total weight to the
    ``COST_WEIGHT_POWER``, times the larger importance of its ends (one definition for the first
    costing and the lazy re-costing, so the heap stays ordered)."""
    cost, _, _, _ = _placement(vq, vpos, vbnd, u, v, qs)
    weight = qs[0] + qs[4] + qs[7]  # the trace: each plane adds its weight x |unit normal|^2
    if weight > 0.0:
        # a square root where the power is 1/2 (a global: numba folds the test away), not a pow
        cost /= np.sqrt(weight) if COST_WEIGHT_POWER == 0.5 else weight ** COST_WEIGHT_POWER
    return cost * max(vimp[u], vimp[v])


@njit(cache=True)
def _push_edges(v, higher, start, cnt, refs, tris, vpos, vq, vbnd, vlock, vimp, mark, tag, qs, heap, hn, t):
    """Cost and push every edge of v to an unlocked neighbour once (only to neighbours w > v when
    ``higher``: the first costing of a round pushes each edge from its lower end, unordered, and
    heapifies once at the end)."""
    for i in range(cnt[v]):
        f = refs[start[v] + i]
        if tris[f, 0] < 0:
            continue
        for k in range(3):
            w = tris[f, k]
            if w == v or vlock[w] or mark[w] == tag or (higher and w < v):
                continue
            mark[w] = tag
            cost = _edge_cost(vq, vpos, vbnd, vimp, v, w, qs)
            heap, hn = _heap_push(heap, hn, cost, v, w, t, not higher)
    return heap, hn


@njit(cache=True)
def _set_plane(fpl, f, vpos, vimp, tris):
    """Cache face f's plane (unit normal, offset, weight; weight 0 for a dead or degenerate face)."""
    a = tris[f, 0]
    if a < 0:
        fpl[f, 4] = 0.0
        return
    fpl[f, 0], fpl[f, 1], fpl[f, 2], fpl[f, 3], fpl[f, 4] = _face_plane(vpos, vimp, a, tris[f, 1], tris[f, 2])


@njit(cache=True)
def _current_quadric(w, start, cnt, refs, tris, fpl, vpos, vq, vbnd, nbr, nbr_n):
    """Rebuild w's current quadric from the faces around it now (their cached planes) and its
    border's planes (``vbnd[w]`` must be known: a vertex that is not on the border has none)."""
    for k in range(10):
        vq[w, k] = 0.0
    for i in range(cnt[w]):
        f = refs[start[w] + i]
        if tris[f, 0] < 0:
            continue
        wt = fpl[f, 4]
        if wt > 0.0:
            _add_plane(vq, w, fpl[f, 0], fpl[f, 1], fpl[f, 2], fpl[f, 3], wt, 0)
    if vbnd[w]:
        _mark_boundary(w, start, cnt, refs, tris, vpos, vq, vbnd, nbr, nbr_n, 0)


@njit(cache=True, nogil=True)
def decimate(vpos, vq, vbnd, vlock, vdead, vimp, vfresh, tris, nv, nt, target, min_dot, touched):
    """Collapse edges, cheapest first, until ``target`` faces remain or nothing legal is left.

    Dead faces get ``tris[f, 0] = -1``, dead vertices ``vdead[v] = 1``. ``vfresh[v]`` marks unlocked
    vertices whose boundary planes were not added yet. ``touched`` (len >= 2 * collapses, or 0 to
    skip) receives the vertices each collapse removed or moved (the lock check of the tests).

    Returns (faces alive, collapses done).
    """
    alive = 0
    for f in range(nt):
        if tris[f, 0] >= 0:
            alive += 1
    start, cnt, refs, used = _build_adjacency(nv, tris, nt, 4 * nt + 64)
    nbr = np.empty(256, np.int32)
    nbr_n = np.empty(256, np.int32)
    fpl = np.empty((nt, 5))  # every face's plane, rewritten for the faces a collapse changes
    for f in range(nt):
        _set_plane(fpl, f, vpos, vimp, tris)
    for v in range(nv):
        if vlock[v] or vdead[v]:
            continue
        if vfresh[v]:  # the border's planes enter the history once, when the vertex is final
            _mark_boundary(v, start, cnt, refs, tris, vpos, vq, vbnd, nbr, nbr_n, 10)
            vfresh[v] = 0
        # the current quadric from the faces as they are (a vertex unlocked since the last
        # round has all its faces now; add_face_quadrics only added the new ones)
        _current_quadric(v, start, cnt, refs, tris, fpl, vpos, vq, vbnd, nbr, nbr_n)
    if alive <= target:
        return alive, 0
    qs = np.empty(10)
    heap = np.empty(2 * alive + 16, HEAP_ENTRY)
    hn = 0
    mark = np.zeros(nv, np.int64)
    tag = 0
    for v in range(nv):
        if not vlock[v] and not vdead[v]:
            tag += 1
            heap, hn = _push_edges(v, True, start, cnt, refs, tris, vpos, vq, vbnd, vlock, vimp, mark, tag, qs,
                                   heap, hn, 0)
    _heapify(heap, hn)
    moved = np.zeros(nv, np.int32)  # collapse count when a vertex last moved (its entries went stale)
    changed = np.zeros(nv, np.int32)  # collapse count when a vertex's current quadric last changed
    ring = np.empty(64, np.int64)
    done = 0
    # the points each live vertex stands for (itself and the vertices it absorbed this call), as
    # chains: the one-sided distance of a collapse is the farthest of them from the new fan
    opos = vpos[:nv].copy()
    nxt = np.full(nv, -1, np.int64)
    tail = np.arange(nv)
    fan = np.empty((32, FAN_WIDTH))
    while alive > target and hn > 0:
        top = heap[0]
        u, v, t, key0 = top.u, top.v, top.t, top.cost
        hn = _heap_pop(heap, hn)
        if vdead[u] or vdead[v] or moved[u] > t or moved[v] > t:
            continue
        if changed[u] > t or changed[v] > t:
            # a collapse next to it rebuilt an end's current quadric: re-cost it now (lazily, instead
            # of re-pushing every edge of the ring at each collapse) and go on with it only if it
            # is still the cheapest
            cost = _edge_cost(vq, vpos, vbnd, vimp, u, v, qs)
            if hn > 0 and cost > heap[0].cost:
                heap, hn = _heap_push(heap, hn, cost, u, v, done)
                continue
            key0 = cost
        # keep the boundary vertex when there is one
        if vbnd[u] and not vbnd[v]:
            u, v = v, u
        # faces on the edge and the link condition
        tag += 1
        for i in range(cnt[u]):
            f = refs[start[u] + i]
            if tris[f, 0] < 0:  # dead faces stay in the apexes' lists until rewritten
                continue
            for k in range(3):
                mark[tris[f, k]] = tag
        on_edge = 0
        apex0 = -1
        for i in range(cnt[v]):
            f = refs[start[v] + i]
            a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
            if a < 0:
                continue
            if a == u or b == u or c == u:
                on_edge += 1
                apex = a if (a != u and a != v) else (b if (b != u and b != v) else c)
                if apex0 < 0:
                    apex0 = apex
        if on_edge == 0 or on_edge > 2:
            continue
        if vbnd[u] and vbnd[v] and on_edge != 1:
            continue  # two boundary vertices across the inside: the collapse would pinch
        common = 0
        tag += 1  # count each common neighbour once
        for i in range(cnt[v]):
            f = refs[start[v] + i]
            if tris[f, 0] < 0:
                continue
            for k in range(3):
                w = tris[f, k]
                if w != u and w != v and mark[w] == tag - 1:
                    mark[w] = tag
                    common += 1
        if common != on_edge:
            continue
        cost, x, y, z = _placement(vq, vpos, vbnd, u, v, qs)
        if _flips(x, y, z, u, v, start, cnt, refs, tris, vpos, min_dot):
            continue
        if _flips(x, y, z, v, u, start, cnt, refs, tris, vpos, min_dot):
            continue
        if HAUSDORFF_WEIGHT > 0.0:
            # the one-sided distance term of the key: HAUSDORFF_WEIGHT x (farthest point)^2 x the same
            # sqrt(weight) x importance as the quadric's. Points within the distance where it is below
            # the quadric's key change nothing (the floor), and past the next entry's key the
            # collapse goes back to the heap: its key there is a lower bound, recomputed when it
            # surfaces again, so the order is the exact keys'.
            scale = HAUSDORFF_WEIGHT * np.sqrt(max(qs[0] + qs[4] + qs[7], 0.0)) * max(vimp[u], vimp[v])
            if scale > 0.0 and hn > 0:
                # (a relative margin, so that an entry pushed back here is taken when it surfaces
                # with the same distance, whatever the rounding of key / scale x scale)
                ceiling = max(key0, heap[0].cost) * (1.0 + 1e-9)
                d2, fan = _fan_distance(x, y, z, u, v, start, cnt, refs, tris, vpos, opos, nxt, fan, key0 / scale,
                                        ceiling / scale)
                if scale * d2 > ceiling:
                    heap, hn = _heap_push(heap, hn, scale * d2, u, v, done)
                    continue
        # collapse u into v
        if touched.shape[0] > 0:
            touched[2 * done] = u
            touched[2 * done + 1] = v
        done += 1
        vpos[v, 0], vpos[v, 1], vpos[v, 2] = x, y, z
        for k in range(10, 20):
            vq[v, k] += vq[u, k]
        vdead[u] = 1
        moved[v] = done
        nxt[tail[v]] = u
        tail[v] = tail[u]
        need = cnt[u] + cnt[v]
        if used + need > refs.shape[0]:
            start, cnt, refs, used = _build_adjacency(nv, tris, nt, 4 * nt + 64)
        s0 = used
        m = 0
        for i in range(cnt[v]):
            f = refs[start[v] + i]
            if tris[f, 0] < 0:
                continue
            a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
            if a == u or b == u or c == u:
                tris[f, 0] = -1
                alive -= 1
                continue
            refs[s0 + m] = f
            m += 1
        for i in range(cnt[u]):
            f = refs[start[u] + i]
            if tris[f, 0] < 0:
                continue
            for k in range(3):
                if tris[f, k] == u:
                    tris[f, k] = v
            refs[s0 + m] = f
            m += 1
        start[v] = s0
        cnt[v] = m
        used = s0 + m
        cnt[u] = 0
        # every face that changed had u in it, so its vertices are v's ring now: rebuild their
        # current quadrics (their other edges are re-costed when they surface), then re-cost v's
        tag += 1
        nr = 0
        for i in range(cnt[v]):
            f = refs[start[v] + i]
            for k in range(3):
                w = tris[f, k]
                if mark[w] != tag:
                    mark[w] = tag
                    if nr == ring.shape[0]:
                        grown = np.empty(2 * nr, np.int64)
                        grown[:nr] = ring
                        ring = grown
                    ring[nr] = w
                    nr += 1
        for i in range(cnt[v]):  # v moved: all its faces have new planes (the dead ones weight 0)
            _set_plane(fpl, refs[start[v] + i], vpos, vimp, tris)
        for i in range(nr):
            w = ring[i]
            if not vlock[w]:
                _current_quadric(w, start, cnt, refs, tris, fpl, vpos, vq, vbnd, nbr, nbr_n)
                changed[w] = done
        tag += 1
        heap, hn = _push_edges(v, False, start, cnt, refs, tris, vpos, vq, vbnd, vlock, vimp, mark, tag, qs,
                               heap, hn, done)
    return alive, done


@njit(cache=True, nogil=True)
def compact(vdead, tris, nv, nt):
    """Renumber the live vertices and faces in order: returns (vertex map old -> new or -1,
    new vertex count, new face count); ``tris`` is rewritten in place."""
    remap = np.full(nv, -1, np.int64)
    k = 0
    for v in range(nv):
        if not vdead[v]:
            remap[v] = k
            k += 1
    m = 0
    for f in range(nt):
        if tris[f, 0] >= 0:
            for c in range(3):
                tris[m, c] = remap[tris[f, c]]
            m += 1
    return remap, k, m
