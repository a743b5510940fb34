"""Small meshes for tests: random Delaunay blobs, grids, and the awkward cases the pipeline must handle.

Every generator returns a validated :class:`gatun_py.mesh.TetMesh` (positively oriented tets).
"""

from __future__ import annotations

import numpy as np

from gatun_py.mesh import TetMesh, validate_tets
from gatun_py.mesh.plot3d import grid_hexes
from gatun_py.mesh.split import orient_positive, split_hexes_two_colour


def _finish(points, density, tets, name="density") -> TetMesh:
    pts = np.asarray(points, np.float32)
    tets = orient_positive(pts, np.asarray(tets, np.int64))
    mesh, _ = validate_tets(pts, np.asarray(density, np.float32), tets, scalar_name=name)
    return mesh


def delaunay_mesh(n_points: int = 30, seed: int = 0, *, offset=(0.0, 0.0, 0.0)) -> TetMesh:
    """Delaunay tets of random points in the unit cube (convex), random densities."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    pts = rng.random((max(n_points, 5), 3)).astype(np.float32) + np.asarray(offset, np.float32)
    tri = Delaunay(pts.astype(np.float64))
    simp = tri.simplices
    vol = np.abs(TetMesh(pts, np.zeros(len(pts)), orient_positive(pts, simp)).signed_volumes())
    simp = simp[vol > 1e-9]  # drop Qhull slivers so generated meshes are non-degenerate
    dens = rng.random(len(pts)).astype(np.float32)
    return _finish(pts, dens, simp)


def grid_mesh(ni: int = 4, nj: int = 4, nk: int = 4, *, jitter: float = 0.0, seed: int = 0,
              keep_cell=None) -> TetMesh:
    """A structured grid split 5 tets per hex (optionally jittered, optionally with cells removed)."""
    rng = np.random.default_rng(seed)
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    pts = np.stack([i, j, k], axis=-1).reshape(-1, 3).astype(np.float64)
    if jitter:
        pts += rng.uniform(-jitter, jitter, pts.shape)
    pts = pts.astype(np.float32)
    hexes, colour = grid_hexes((ni, nj, nk))
    if keep_cell is not None:
        kk, jj, ii = np.meshgrid(np.arange(nk - 1), np.arange(nj - 1), np.arange(ni - 1), indexing="ij")
        keep = np.array([keep_cell(a, b, c) for a, b, c in zip(ii.ravel(), jj.ravel(), kk.ravel())])
        hexes = hexes[keep]
    tets = split_hexes_two_colour(hexes, colour)
    dens = (np.sin(pts[:, 0]) + pts[:, 1] * 0.3 + pts[:, 2] ** 2 * 0.1 + rng.random(len(pts)) * 0.01).astype(np.float32)
    return _finish(pts, dens, tets)


def cavity_mesh(n: int = 5) -> TetMesh:
    """A grid block with the central cell removed: an internal boundary (a cavity)."""
    c = (n - 1) // 2
    return grid_mesh(n, n, n, keep_cell=lambda i, j, k: not (i == c and j == c and k == c))


def l_shaped_mesh() -> TetMesh:
    """A non-convex L-shaped block: rays leave and re-enter the volume (several segments)."""
    return grid_mesh(6, 6, 3, keep_cell=lambda i, j, k: not (i >= 2 and j >= 2))


def two_components() -> TetMesh:
    """Two disjoint Delaunay blobs in one mesh."""
    a = delaunay_mesh(20, 1)
    b = delaunay_mesh(20, 2, offset=(2.0, 0.0, 0.0))
    pts = np.concatenate([a.points, b.points])
    return _finish(pts, np.concatenate([a.density, b.density]), np.concatenate([a.tets, b.tets + a.n_points]))


def single_tet() -> TetMesh:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    return _finish(pts, [0.0, 1.0, 2.0, 3.0], [[0, 1, 2, 3]])


def edge_touching() -> TetMesh:
    """Two tets sharing only an edge (a non-manifold boundary)."""
    pts = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], np.float32)
    return _finish(pts, np.arange(6), [[0, 1, 2, 3], [0, 1, 4, 5]])


def vertex_touching() -> TetMesh:
    """Two tets sharing only a vertex."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], np.float32)
    return _finish(pts, np.arange(7), [[0, 1, 2, 3], [0, 4, 5, 6]])


def degenerate_grid() -> TetMesh:
    """A grid whose first grid line is collapsed onto one point: zero-volume tets and coincident points."""
    m = grid_mesh(4, 3, 3)
    pts = np.array(m.points)
    line = (pts[:, 1] == 0) & (pts[:, 2] == 0)
    pts[line, 0] = 0.0  # collapse the line: coincident vertices, exactly-zero-volume tets
    return _finish(pts, m.density, m.tets)


def with_unreferenced(mesh: TetMesh, extra: int = 3, seed: int = 0) -> TetMesh:
    """The same mesh plus points no tet uses."""
    rng = np.random.default_rng(seed)
    pts = np.concatenate([mesh.points, rng.random((extra, 3)).astype(np.float32) + 5])
    dens = np.concatenate([mesh.density, rng.random(extra).astype(np.float32)])
    return _finish(pts, dens, mesh.tets)


AWKWARD = {
    "single_tet": single_tet,
    "edge_touching": edge_touching,
    "vertex_touching": vertex_touching,
    "two_components": two_components,
    "cavity": cavity_mesh,
    "l_shaped": l_shaped_mesh,
    "degenerate_grid": degenerate_grid,
    "unreferenced": lambda: with_unreferenced(grid_mesh(3, 3, 3)),
    "jittered_grid": lambda: grid_mesh(5, 4, 3, jitter=0.2, seed=3),
    "delaunay": lambda: delaunay_mesh(60, 7),
}


def mesh_strategy():
    """Hypothesis strategy over random Delaunay meshes, jittered grids and the awkward cases."""
    from hypothesis import strategies as st

    return st.one_of(
        st.builds(delaunay_mesh, st.integers(5, 80), st.integers(0, 10_000)),
        st.builds(lambda a, b, c, s: grid_mesh(a, b, c, jitter=0.15, seed=s),
                  st.integers(2, 5), st.integers(2, 5), st.integers(2, 4), st.integers(0, 1000)),
        st.sampled_from(sorted(AWKWARD)).map(lambda k: AWKWARD[k]()),
    )
