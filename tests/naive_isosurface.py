"""Slow plain-Python marching tetrahedra: the reference for gatun_py.isosurface's kernel.

Written from the definition, tet by tet, with no tables shared with the kernel except the quad
diagonal (VTK's choice, a convention, not a computation): a vertex is above when s >= iso; the
point on edge (below b, above a) is p_b + t (p_a - p_b), t = (iso - s_b) / (s_a - s_b), or the
mesh vertex itself when s_a == iso; triangles are wound so that their normal points against the
tet's scalar gradient (toward lower values).
"""

from __future__ import annotations

import numpy as np

EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
QUAD_DIAGONAL = {3: (1, 4), 5: (2, 3), 6: (0, 5), 9: (0, 5), 10: (0, 5), 12: (2, 3)}


def naive_isosurface(points, density, tets, iso):
    """Returns (points (n, 3) float64, triangles (m, 3), keys): keys[i] = (a, b) with a <= b the mesh
    edge (or (v, v) the mesh vertex) of surface vertex i."""
    p = np.asarray(points, np.float64)
    s = np.asarray(density, np.float64)
    index = {}
    out_pts = []
    keys = []
    tris = []

    def vertex(a, b):  # a above, b below
        key = (a, a) if s[a] == iso else (min(a, b), max(a, b))
        if key not in index:
            index[key] = len(out_pts)
            keys.append(key)
            if s[a] == iso:
                out_pts.append(p[a].copy())
            else:
                t = (iso - s[b]) / (s[a] - s[b])
                out_pts.append(p[b] + t * (p[a] - p[b]))
        return index[key]

    ref = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    for tet in np.asarray(tets):
        above = [i for i in range(4) if s[tet[i]] >= iso]
        if len(above) in (0, 4):
            continue
        case = sum(1 << i for i in above)
        crossing = [e for e, (i, j) in enumerate(EDGES) if (i in above) != (j in above)]
        # the crossing edges in cyclic order around the section polygon (adjacent = share a face)
        def adjacent(e, f):
            return len(set(EDGES[e]) | set(EDGES[f])) == 3
        cyc = [crossing[0]]
        while len(cyc) < len(crossing):
            nxt = [e for e in crossing if e not in cyc and adjacent(cyc[-1], e)]
            cyc.append(nxt[0])
        if len(cyc) == 3:
            polys = [cyc]
        else:
            d0, d1 = QUAD_DIAGONAL[case]
            k = cyc.index(d0)
            cyc = cyc[k:] + cyc[:k]
            assert cyc[2] == d1
            polys = [cyc[:3], [cyc[0], cyc[2], cyc[3]]]
        # orientation on the reference tet (positive tets map to it by a positive affine map)
        sref = np.array([1.0 if i in above else 0.0 for i in range(4)])
        grad = np.linalg.solve(ref[1:] - ref[0], sref[1:] - sref[0])
        for poly in polys:
            mid = [(ref[EDGES[e][0]] + ref[EDGES[e][1]]) / 2 for e in poly]
            if np.dot(np.cross(mid[1] - mid[0], mid[2] - mid[0]), grad) > 0:
                poly = [poly[0], poly[2], poly[1]]
            ids = []
            for e in poly:
                i, j = EDGES[e]
                a, b = (tet[i], tet[j]) if i in above else (tet[j], tet[i])
                ids.append(vertex(a, b))
            if len(set(ids)) == 3:
                tris.append(ids)
    return np.array(out_pts).reshape(-1, 3), np.array(tris, np.int64).reshape(-1, 3), keys
