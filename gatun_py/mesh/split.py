"""Conforming splits of hexahedra, wedges and pyramids into tetrahedra.

Two rules, both conforming (a quad face shared by two cells gets the same diagonal on both sides):

* **Two-colour 5-tet split** (hexahedra only). The vertices are two-coloured so that every hex edge
  joins different colours (structured grids: the parity of i+j+k). Each hex keeps the tet spanned
  by its four vertices of colour 0 and cuts off the four corners of colour 1. Every face diagonal
  then joins the two colour-0 vertices of that face, on both sides of the face. 5 tets per hex,
  as in the paper's data sets.
* **Minimum-id star split** (any mix, used when the hex graph is not two-colourable or other cell
  types are present). Every quad face is cut by the diagonal through its smallest global vertex
  id; each cell is then coned from its smallest-id vertex to the triangles of the faces that do
  not contain it. Faces containing the apex are cut through the apex, which is their minimum id,
  so both rules agree on every face. 6 tets per hex, 3 per wedge, 2 per pyramid.
"""

from __future__ import annotations

import numpy as np

from .model import signed_volumes

# VTK local numbering. Hex: 0-3 bottom quad, 4-7 top quad above 0-3.
HEX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)
# 5-tet split when local vertex 0 has colour 0 (central tet on {0,2,5,7}) and the mirror image.
_HEX5_EVEN = np.array([[0, 2, 5, 7], [1, 0, 2, 5], [3, 0, 2, 7], [4, 0, 5, 7], [6, 2, 5, 7]])
_HEX5_ODD = np.array([[1, 3, 4, 6], [0, 1, 3, 4], [2, 1, 3, 6], [5, 1, 4, 6], [7, 3, 4, 6]])

# Faces of each cell type (any winding; the tets are oriented afterwards).
CELL_FACES = {
    "hexahedron": [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)],
    "wedge": [(0, 1, 2), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)],
    "pyramid": [(0, 1, 2, 3), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)],
    "tetra": [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)],
}


def two_colour(hexes: np.ndarray, n_points: int) -> np.ndarray | None:
    """Colour vertices 0/1 so every hex edge joins different colours; None if impossible."""
    # scipy.sparse.csgraph costs 1.1 s to import; only hexahedral inputs need it
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    h = np.asarray(hexes, dtype=np.int64)
    e = h[:, HEX_EDGES].reshape(-1, 2)
    g = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n_points, n_points)).tocsr()
    g = g + g.T
    colour = np.full(n_points, -1, np.int8)
    ncomp, labels = connected_components(g, directed=False)
    firsts = np.unique(labels, return_index=True)[1]
    for root in firsts:
        order, pred = breadth_first_order(g, int(root), directed=False, return_predecessors=True)
        colour[root] = 0
        # BFS order guarantees a predecessor is coloured before its children.
        for v in order[1:]:
            colour[v] = 1 - colour[pred[v]]
    colour[colour < 0] = 0
    if np.any(colour[e[:, 0]] == colour[e[:, 1]]):
        return None
    return colour


def split_hexes_two_colour(hexes: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """5 tets per hex, central tet on the colour-0 vertices (see module docstring)."""
    h = np.asarray(hexes, dtype=np.int64)
    even = colour[h[:, 0]] == 0
    local = np.where(even[:, None, None], _HEX5_EVEN[None], _HEX5_ODD[None])  # (k, 5, 4)
    return np.take_along_axis(h[:, None, :], local.reshape(len(h), 1, 20), axis=2).reshape(-1, 4)


def split_min_id_star(cells: np.ndarray, cell_type: str) -> np.ndarray:
    """Cone each cell from its smallest-id vertex over the min-id triangulation of its far faces."""
    c = np.asarray(cells, dtype=np.int64)
    if cell_type == "tetra":
        return c.copy()
    faces = CELL_FACES[cell_type]
    k = len(c)
    apex_local = np.argmin(c, axis=1)
    apex = c[np.arange(k), apex_local]
    out = []
    for f in faces:
        f = np.array(f)
        contains = np.any(f[None, :] == apex_local[:, None], axis=1)
        keep = ~contains
        if not keep.any():
            continue
        fv = c[keep][:, f]
        a = apex[keep]
        if len(f) == 3:
            out.append(np.column_stack([a, fv]))
        else:
            m = np.argmin(fv, axis=1)
            # Diagonal through the face's minimum vertex: rotate so it sits at position 0.
            idx = (m[:, None] + np.arange(4)[None, :]) % 4
            q = np.take_along_axis(fv, idx, axis=1)
            out.append(np.column_stack([a, q[:, 0], q[:, 1], q[:, 2]]))
            out.append(np.column_stack([a, q[:, 0], q[:, 2], q[:, 3]]))
    if not out:
        return np.zeros((0, 4), np.int64)
    # Keep the tets of one cell together (stable order: cell, then face).
    tets = np.stack([o for o in out], axis=0) if all(len(o) == k for o in out) else None
    if tets is not None:
        return tets.transpose(1, 0, 2).reshape(-1, 4)
    owner = np.concatenate([np.flatnonzero(~np.any(np.array(f)[None, :] == apex_local[:, None], axis=1))
                            for f in faces for _ in range(1 if len(f) == 3 else 2)])
    allt = np.concatenate(out)
    return allt[np.argsort(owner, kind="stable")]


def orient_positive(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Swap the last two ids of every tet with negative signed volume (our own splits' winding)."""
    t = np.array(tets, dtype=np.int64, copy=True)
    neg = signed_volumes(points, t) < 0
    t[neg] = t[neg][:, [0, 1, 3, 2]]
    return t
