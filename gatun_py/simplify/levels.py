"""Pre-simplified levels (paper section 5): level i = the mesh after N_i = floor((1 - 1/2^i) * points) merges."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OptionError
from ..mesh import TetMesh
from .forest import ROOT_RANK, MergeForest, simplified_mesh

__all__ = ["MAX_LEVEL", "LevelMesh", "level_merges", "available_levels", "build_levels", "level_forest"]

MAX_LEVEL = 13


def level_merges(n_points: int, i: int) -> int:
    """N_i = floor((1 - 1/2^i) * n_points), computed exactly in integers."""
    if i < 0:
        raise OptionError(f"level must be >= 0, got {i}")
    return n_points - -(-n_points // (1 << i)) if i < 63 else n_points - (1 if n_points else 0)


def available_levels(forest: MergeForest, max_level: int = MAX_LEVEL) -> list[int]:
    """Levels 0..max_level whose N_i the forest reaches (level 0 always; duplicates of N dropped)."""
    out = [0]
    for i in range(1, max_level + 1):
        n = level_merges(forest.n_points, i)
        if n > forest.n_merges:
            break
        if n > level_merges(forest.n_points, out[-1]):
            out.append(i)
    return out


@dataclass(frozen=True, eq=False)
class LevelMesh:
    """One pre-simplified level.

    Attributes
    ----------
    level : int
        i (0 = the input).
    n_merges : int
        N_i, the merges of the full forest already applied.
    ratio : float
        N_i / input points.
    mesh : TetMesh
        The mesh after N_i merges (vertices in input order, tets in input order).
    forest : MergeForest
        The rest of the forest in this mesh's numbering: ranks >= N_i shifted down by N_i.
    vertex_ids : (k,) int64
        Input id of every vertex of ``mesh``.
    """

    level: int
    n_merges: int
    ratio: float
    mesh: TetMesh
    forest: MergeForest
    vertex_ids: np.ndarray


def level_forest(forest: MergeForest, n_merges: int, vertex_ids: np.ndarray) -> MergeForest:
    """The forest restricted to the vertices alive after ``n_merges`` merges, renumbered.

    A surviving vertex's parent survives too (a parent outranks its child), so the restriction
    is closed; ranks drop by ``n_merges``.
    """
    new_id = np.full(forest.n_points, -1, np.int64)
    new_id[vertex_ids] = np.arange(vertex_ids.size)
    par = new_id[forest.parent[vertex_ids]]
    rank = forest.rank[vertex_ids].astype(np.int64)
    rank = np.where(rank == ROOT_RANK, ROOT_RANK, rank - n_merges)
    assert par.min(initial=0) >= 0
    return MergeForest(par.astype(np.int32), rank.astype(np.int32), forest.n_merges - n_merges)


def build_levels(mesh: TetMesh, forest: MergeForest, levels=None) -> list[LevelMesh]:
    """The pre-simplified levels of a mesh.

    Parameters
    ----------
    mesh : TetMesh
        The input (level 0).
    forest : MergeForest
        Its decimation.
    levels : int or sequence of int, optional
        An int K means levels 0..K (only those the forest reaches, see :func:`available_levels`);
        a sequence picks levels explicitly (each must be reachable). Default: every reachable
        level up to 13.

    Returns
    -------
    list of LevelMesh, level 0 first.
    """
    reach = available_levels(forest, MAX_LEVEL)
    if levels is None:
        wanted = reach
    elif isinstance(levels, (int, np.integer)):
        if levels < 0:
            raise OptionError(f"--levels must be >= 0, got {levels}")
        wanted = [i for i in reach if i <= levels]
    else:
        wanted = sorted({int(i) for i in levels} | {0})
        bad = [i for i in wanted if i not in reach]
        if bad:
            raise OptionError(f"level {bad[0]} is not reached by this forest; available levels: "
                              f"{', '.join(map(str, reach))}")
    out = []
    for i in wanted:
        n = level_merges(mesh.n_points, i)
        m, ids = simplified_mesh(mesh, forest, n, return_ids=True)
        out.append(LevelMesh(i, n, n / mesh.n_points if mesh.n_points else 0.0, m,
                             level_forest(forest, n, ids), ids))
    return out
