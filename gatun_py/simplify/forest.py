"""The merge forest: parents and ranks of the decimation, ancestors after N merges.

Conventions (``docs/architecture.md``): ``parent[v]`` is v itself for a root, ``rank[v]`` the
0-based execution order of v's merge (``ROOT_RANK`` for roots; inside a round of independent
merges any order executes the same, and the ranks follow
:func:`gatun_py.simplify.decimation.canonical_key`). The first N merges are those with rank < N; a
parent always has a larger rank than its children (it was still alive when they were merged into
it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..codec.forest import ROOT_RANK, check_forest
from ..errors import OptionError
from ..mesh import TetMesh
from ._forest_kernels import ancestors_kernel

__all__ = ["ROOT_RANK", "MergeForest", "ancestors", "simplified_mesh", "mesh_from_ancestors", "check_forest",
           "forest_prefix"]


@dataclass(frozen=True, eq=False)
class MergeForest:
    """The result of the decimation.

    Parameters
    ----------
    parent : (n,) int32
        The vertex each vertex is merged into (itself for a root).
    rank : (n,) int32
        Execution order of the vertex's merge, ``ROOT_RANK`` for a root.
    n_merges : int
        Number of merges (vertices with a rank below ``ROOT_RANK``); ranks are exactly
        ``0 .. n_merges - 1``.
    """

    parent: np.ndarray
    rank: np.ndarray
    n_merges: int

    @property
    def n_points(self) -> int:
        return int(self.parent.shape[0])

    @property
    def max_ratio(self) -> float:
        """Simplification ratio after every merge (merged vertices / all vertices)."""
        return self.n_merges / self.n_points if self.n_points else 0.0

    def merges_for_ratio(self, ratio: float) -> int:
        """Number of merges N = floor(ratio * points), checked against what the forest reaches."""
        if not 0.0 <= ratio <= 1.0:
            raise OptionError(f"ratio {ratio} is outside [0, 1]; this forest reaches {self.max_ratio:.6f}")
        n = int(np.floor(ratio * self.n_points))
        if n > self.n_merges:
            raise OptionError(f"ratio {ratio} needs {n} merges but the forest holds {self.n_merges} "
                              f"(maximum ratio {self.max_ratio:.6f})")
        return n


def forest_prefix(forest: MergeForest, n_merges: int) -> MergeForest:
    """The forest of only the first ``n_merges`` merges (later-merged vertices become roots).

    Any N <= ``n_merges`` gives the same ancestors as with the whole forest.
    """
    n_merges = max(0, min(int(n_merges), forest.n_merges))
    later = forest.rank >= n_merges
    parent = np.where(later, np.arange(forest.n_points), forest.parent).astype(np.int32)
    rank = np.where(later, ROOT_RANK, forest.rank).astype(np.int32)
    return MergeForest(parent, rank, n_merges)


def ancestors(parent: np.ndarray, rank: np.ndarray, n_merges: int) -> np.ndarray:
    """Every vertex's ancestor after the first ``n_merges`` merges (paper section 4.2).

    Parameters
    ----------
    parent, rank : (n,) int
        The merge forest.
    n_merges : int
        How many merges to apply (merges with rank < n_merges); 0 gives the identity.

    Returns
    -------
    (n,) int32
        ``anc[v]`` = the vertex v ends in; ``anc[v] == v`` exactly for the surviving vertices.
    """
    parent = np.ascontiguousarray(parent, dtype=np.int32)
    rank = np.ascontiguousarray(rank, dtype=np.int32)
    if n_merges < 0:
        raise OptionError(f"n_merges must be >= 0, got {n_merges}")
    if parent.shape[0] == 0:
        return np.zeros(0, np.int32)
    return ancestors_kernel(parent, rank, np.int64(n_merges))


def simplified_mesh(mesh: TetMesh, forest: MergeForest, n_merges: int, *, return_ids: bool = False):
    """The mesh after the first ``n_merges`` merges.

    Tets whose four ancestors are distinct, rewritten to the ancestors; surviving vertices
    compacted in their original order (so their ids keep the input's relative order).

    Parameters
    ----------
    mesh : TetMesh
        The mesh the forest was computed on.
    forest : MergeForest
    n_merges : int
        0 .. ``forest.n_merges``.
    return_ids : bool
        Also return the input id of every vertex of the result.

    Returns
    -------
    TetMesh, or (TetMesh, (k,) int64 vertex ids) with ``return_ids``.
    """
    if forest.n_points != mesh.n_points:
        raise OptionError(f"the forest has {forest.n_points} vertices, the mesh {mesh.n_points}")
    if not 0 <= n_merges <= forest.n_merges:
        raise OptionError(f"n_merges {n_merges} is outside 0..{forest.n_merges}")
    anc = ancestors(forest.parent, forest.rank, n_merges)
    out, ids = mesh_from_ancestors(mesh, anc)
    return (out, ids) if return_ids else out


def mesh_from_ancestors(mesh: TetMesh, anc: np.ndarray):
    """(simplified TetMesh, input id of each of its vertices) for an ancestor table.

    Tets whose four ancestors are distinct, rewritten to the ancestors; the surviving vertices
    (``anc[v] == v``) compacted in their input order, each keeping its exact coordinates and the
    values of every point array.
    """
    t = anc[mesh.tets]
    s = np.sort(t, axis=1)
    keep = np.all(s[:, 1:] != s[:, :-1], axis=1)
    ids = np.flatnonzero(anc == np.arange(mesh.n_points))
    new_id = np.full(mesh.n_points, -1, np.int64)
    new_id[ids] = np.arange(ids.size)
    out = TetMesh(mesh.points[ids], None, new_id[t[keep]].astype(np.int32), mesh.scalar_name,
                  point_data={name: a[ids] for name, a in mesh.point_data.items()})
    return out, ids
