"""Bricks: a k-d partition of a mesh's tets, balanced by tet count, and the sub-mesh of each brick.

Bricks are what a file is split into to be decoded on several cores and rendered on several
machines (``tetc compress --bricks K``). Every tet belongs to exactly one brick; a vertex used by
tets of several bricks (a *cut vertex*) is stored once in each of them, so a brick is a complete
mesh on its own, whose boundary includes the cut faces.

The partition splits the tets' centroids at the median of the longest axis of their bounding box,
recursively, giving ``floor(K/2)`` bricks to the lower side with a proportional share of tets, so
any ``K >= 1`` is balanced to within one tet per split. It depends only on the coordinates and the
tet order, never on thread count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OptionError
from .model import TetMesh

MAX_BRICKS = 4096

__all__ = ["MAX_BRICKS", "Brick", "partition_tets", "split_bricks"]


def partition_tets(mesh: TetMesh, n_bricks: int) -> np.ndarray:
    """The brick of every tet: a k-d partition of the tet centroids balanced by tet count.

    Parameters
    ----------
    mesh : TetMesh
    n_bricks : int
        K, 1 .. ``min(MAX_BRICKS, mesh.n_tets)`` (a mesh without tets has one, empty, brick).

    Returns
    -------
    (n_tets,) int32
        Brick ids 0 .. K-1; brick k's tets are ``np.flatnonzero(ids == k)``.

    Examples
    --------
    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> m = jittered_grid((5, 5, 5), jitter=0.2)
    >>> ids = partition_tets(m, 3)
    >>> np.bincount(ids).tolist(), m.n_tets
    ([106, 107, 107], 320)
    """
    k = int(n_bricks)
    if k < 1 or k > MAX_BRICKS:
        raise OptionError(f"the number of bricks must be 1..{MAX_BRICKS}, got {n_bricks}")
    if mesh.n_tets and k > mesh.n_tets:
        raise OptionError(f"{k} bricks for a mesh of {mesh.n_tets} tets: at most one brick per tet")
    ids = np.zeros(mesh.n_tets, np.int32)
    if k == 1 or mesh.n_tets == 0:
        return ids
    centroids = np.asarray(mesh.points, np.float64)[mesh.tets].mean(axis=1)
    stack = [(np.arange(mesh.n_tets), 0, k)]  # (tets, first brick id, brick count)
    while stack:
        tets, first, count = stack.pop()
        if count == 1:
            ids[tets] = first
            continue
        c = centroids[tets]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        k_low = count // 2
        n_low = (len(tets) * k_low) // count
        # a stable order (ties by tet id) keeps the partition deterministic
        order = np.lexsort((tets, c[:, axis]))
        stack.append((tets[order[n_low:]], first + k_low, count - k_low))
        stack.append((tets[order[:n_low]], first, k_low))
    return ids


@dataclass(frozen=True, eq=False)
class Brick:
    """One brick of a partitioned mesh.

    Attributes
    ----------
    index : int
        k, its position in the partition.
    mesh : TetMesh
        The brick's tets over its own vertices (numbered in the order of their global ids), with
        every point array.
    vertex_ids : (n,) int64
        Global id of every vertex of ``mesh``.
    tet_ids : (m,) int64
        Global id of every tet of ``mesh``, in the brick's tet order.
    cut : (n,) bool
        The vertex is shared with another brick (it must not move when the brick is simplified).
    """

    index: int
    mesh: TetMesh
    vertex_ids: np.ndarray
    tet_ids: np.ndarray
    cut: np.ndarray

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the brick's points."""
        return self.mesh.bbox

    def __repr__(self) -> str:
        return (f"Brick({self.index}: {self.mesh.n_tets} tets, {self.mesh.n_points} points, "
                f"{int(self.cut.sum())} cut vertices)")


def split_bricks(mesh: TetMesh, brick_of_tet: np.ndarray) -> list[Brick]:
    """The sub-mesh of every brick of a partition (see :func:`partition_tets`).

    Examples
    --------
    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> m = jittered_grid((5, 5, 5), jitter=0.2)
    >>> bricks = split_bricks(m, partition_tets(m, 2))
    >>> bricks[0]
    Brick(0: 160 tets, 75 points, 25 cut vertices)
    >>> sum(b.mesh.n_tets for b in bricks) == m.n_tets
    True
    """
    brick_of_tet = np.asarray(brick_of_tet)
    if brick_of_tet.shape != (mesh.n_tets,):
        raise OptionError(f"brick ids: expected one per tet ({mesh.n_tets}), got shape {brick_of_tet.shape}")
    k = int(brick_of_tet.max()) + 1 if brick_of_tet.size else 1
    if brick_of_tet.size and brick_of_tet.min() < 0:
        raise OptionError("brick ids must be >= 0")
    order = np.argsort(brick_of_tet, kind="stable")
    starts = np.searchsorted(brick_of_tet[order], np.arange(k + 1))
    # each brick's vertices (sorted) with a mark array, O(points + its tets) per brick instead of a
    # sort of every (brick, vertex) pair (15 s of a 1 M-tet split); a vertex is cut when more than
    # one brick uses it
    mark = np.zeros(mesh.n_points, bool)
    bricks_per_vertex = np.zeros(mesh.n_points, np.int32)
    parts = []
    for b in range(k):
        tet_ids = order[starts[b]:starts[b + 1]].astype(np.int64)
        tets = mesh.tets[tet_ids]
        mark[tets.ravel()] = True
        vertex_ids = np.flatnonzero(mark)
        mark[vertex_ids] = False
        bricks_per_vertex[vertex_ids] += 1
        parts.append((tet_ids, tets, vertex_ids))
    local_id = np.empty(mesh.n_points, np.int32)
    out = []
    for b, (tet_ids, tets, vertex_ids) in enumerate(parts):
        local_id[vertex_ids] = np.arange(vertex_ids.size, dtype=np.int32)
        sub = TetMesh(mesh.points[vertex_ids], None, local_id[tets], mesh.scalar_name,
                      point_data={name: a[vertex_ids] for name, a in mesh.point_data.items()})
        out.append(Brick(b, sub, vertex_ids.astype(np.int64), tet_ids, bricks_per_vertex[vertex_ids] > 1))
    return out
