"""Conforming mixed meshes for the cell tests: a hex grid whose cells are kept as hexahedra, cut
into six pyramids around a centre point, or cut into pyramids some of which are split again into
two tets along the base diagonal the min-id rule would choose (so the faces still match); cells
shuffled inside their blocks and re-labelled by a symmetry, with cell arrays of every kind."""

from __future__ import annotations

import meshio
import numpy as np

# hex faces as pyramid bases, wound so the pyramid (base, centre) is positive for an outward base
_HEX_FACES = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
# orientation-keeping relabellings of a hex: rotations about the vertical axis, and the flip
_HEX_ROT = [[0, 1, 2, 3, 4, 5, 6, 7], [1, 2, 3, 0, 5, 6, 7, 4], [2, 3, 0, 1, 6, 7, 4, 5], [3, 0, 1, 2, 7, 4, 5, 6],
            [4, 7, 6, 5, 0, 3, 2, 1]]


def mixed_mesh(nx=3, ny=3, nz=2, seed=0, *, kinds=(0, 1, 2), quadratic=False) -> meshio.Mesh:
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij"), -1)
    pts = list((g.reshape(-1, 3) + rng.uniform(-0.15, 0.15, ((nx + 1) * (ny + 1) * (nz + 1), 3))).astype(np.float64))
    pid = np.arange(len(pts)).reshape(nx + 1, ny + 1, nz + 1)
    hexes, pyrs, tets = [], [], []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                h = [pid[i, j, k], pid[i + 1, j, k], pid[i + 1, j + 1, k], pid[i, j + 1, k],
                     pid[i, j, k + 1], pid[i + 1, j, k + 1], pid[i + 1, j + 1, k + 1], pid[i, j + 1, k + 1]]
                kind = kinds[int(rng.integers(len(kinds)))]
                if kind == 0:
                    hexes.append([h[x] for x in _HEX_ROT[int(rng.integers(len(_HEX_ROT)))]])
                    continue
                c = len(pts)
                pts.append(np.mean([pts[v] for v in h], axis=0))
                for f in _HEX_FACES:
                    base = [h[x] for x in f]
                    if kind == 2 and rng.random() < 0.5:
                        m = int(np.argmin(base))  # the diagonal through the base's smallest id
                        q = base[m:] + base[:m]
                        for tri in ([q[0], q[1], q[2]], [q[0], q[2], q[3]]):
                            tets.append(list(np.roll(tri + [c], -int(rng.integers(1)))))
                    else:
                        r = int(rng.integers(4))
                        pyrs.append(base[r:] + base[:r] + [c])
    pts = np.array(pts)
    # outward bases give positive pyramids with apex last in VTK's order? VTK wants the base
    # counter-clockwise seen from the apex: flip the ones that come out negative
    cells = []
    for typ, rows in (("hexahedron", hexes), ("pyramid", pyrs), ("tetra", tets)):
        if not rows:
            continue
        a = np.array(rows, np.int64)
        a = a[rng.permutation(len(a))]
        cells.append((typ, a))
    if quadratic:
        cells = [(t, _add_mid_nodes(t, a, [])) for t, a in cells]
    m = meshio.Mesh(pts, cells)
    n = len(pts)
    m.point_data["p"] = rng.normal(size=n)
    m.point_data["id"] = np.arange(n, dtype=np.int32)
    m.cell_data["mat"] = [rng.integers(0, 3, len(c.data)).astype(np.int32) for c in m.cells]
    m.cell_data["stress"] = [rng.normal(size=(len(c.data), 3)) for c in m.cells]
    m.cell_data["flag"] = [rng.random(len(c.data)) < 0.3 for c in m.cells]
    m.cell_data["t32"] = [np.repeat(rng.normal(size=1).astype(np.float32), len(c.data)) for c in m.cells]
    m.field_data["steel"] = np.array([1, 3])
    m.point_sets["corner"] = np.array([0, n - 1], np.int64)
    m.cell_sets["first"] = [np.array([0]) for _ in m.cells]
    return m


def _add_mid_nodes(t, a, _):
    return a


def tetra10_mesh(seed=0, n=4) -> meshio.Mesh:
    """A tetra10 mesh: a jittered grid's Kuhn tets (conforming) with a node on every edge."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*[np.arange(n + 1)] * 3, indexing="ij"), -1).reshape(-1, 3).astype(np.float64)
    g += rng.uniform(-0.1, 0.1, g.shape)
    pid = np.arange(len(g)).reshape(n + 1, n + 1, n + 1)
    kuhn = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    tets = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [pid[i + (b & 1), j + (b >> 1 & 1), k + (b >> 2 & 1)] for b in range(8)]
                for q in kuhn:
                    tets.append([c[x] for x in q])
    tets = np.array(tets, np.int64)
    vol = np.einsum("ij,ij->i", g[tets[:, 1]] - g[tets[:, 0]],
                    np.cross(g[tets[:, 2]] - g[tets[:, 0]], g[tets[:, 3]] - g[tets[:, 0]]))
    tets[vol < 0] = tets[vol < 0][:, [0, 1, 3, 2]]
    edges = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    mid = {}
    pts = list(g)
    out = []
    for t in tets[rng.permutation(len(tets))]:
        row = list(t)
        for a, b in edges:
            key = (min(t[a], t[b]), max(t[a], t[b]))
            if key not in mid:
                mid[key] = len(pts)
                pts.append((g[t[a]] + g[t[b]]) / 2)
            row.append(mid[key])
        out.append(row)
    pts = np.array(pts)
    m = meshio.Mesh(pts, [("tetra10", np.array(out, np.int64))])
    m.point_data["u"] = rng.normal(size=(len(pts), 3))
    m.cell_data["E"] = [rng.normal(size=len(out))]
    return m
