"""Pre-simplified levels (paper section 5): level i = the mesh after N_i = floor((1 - 1/2^i) * points) merges."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..codec import LevelPayload, TetcReader
from ..codec.levelmeta import LevelMeta
from ..errors import CorruptFileError, OptionError
from ..mesh import TetMesh
from .forest import ROOT_RANK, MergeForest, ancestors, forest_prefix, mesh_from_ancestors, simplified_mesh

__all__ = ["MAX_LEVEL", "MIN_LEVEL_POINTS", "LevelMesh", "max_stored_level", "level_merges", "level_ends", "available_levels", "build_levels", "next_level", "level_forest",
           "read_simplified", "forest_merges", "storage_forests", "level_payloads", "Target", "resolve_target",
           "stored_levels",
           "target_ancestors"]

MAX_LEVEL = 13
# A level of fewer points is not stored: the level before it (under 256 points, about a thousand
# tets) decodes in a fraction of a millisecond, and its forest then keeps all the remaining merges
# (any ratio stays reachable), while every level costs section records, headers and metadata of its
# own besides its data: Blunt-fin's levels 9 to 13 (80 to 5 points) took 5.2 kB of its 337 kB file.
MIN_LEVEL_POINTS = 128


def level_merges(n_points: int, i: int) -> int:
    """N_i = floor((1 - 1/2^i) * n_points), computed exactly in integers."""
    if i < 0:
        raise OptionError(f"level must be >= 0, got {i}")
    return n_points - -(-n_points // (1 << i)) if i < 63 else n_points - (1 if n_points else 0)


def level_ends(n_points: int, max_level: int = 62) -> dict[int, int]:
    """{N_i: i} for the levels 1..max_level of a mesh of ``n_points`` whose N_i is more than the
    level before's (of equal N_i the first i; no level i >= 1 with N_i = 0)."""
    out = {}
    prev = 0
    for i in range(1, max_level + 1):
        n = level_merges(n_points, i)
        if n > prev:
            out[n] = i
            prev = n
    return out


def max_stored_level(n_points: int, max_level: int = MAX_LEVEL, min_points: int = MIN_LEVEL_POINTS) -> int:
    """The last level i <= ``max_level`` whose n_points - N_i points (:func:`level_merges`) are at
    least ``min_points`` (0 if none is): the last level a file stores by default.

    >>> max_stored_level(40960), max_stored_level(2288), max_stored_level(100)
    (8, 4, 0)
    """
    i = 0
    while i < max_level and n_points - level_merges(n_points, i + 1) >= min_points:
        i += 1
    return i


def available_levels(forest: MergeForest, max_level: int = MAX_LEVEL, *,
                     min_points: int = MIN_LEVEL_POINTS) -> list[int]:
    """Levels 0..max_level whose N_i the forest reaches and which keep at least ``min_points``
    points (level 0 always; of equal N_i the first i). ``min_points=1``: every reachable level."""
    top = max_stored_level(forest.n_points, max_level, min_points)
    return [0] + [i for n, i in level_ends(forest.n_points, top).items() if n <= forest.n_merges]


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
        An int K means levels 0..K (those the forest reaches, however small, see
        :func:`available_levels`); a sequence picks levels explicitly (each must be reached by the
        forest). Default: every level up to 13 of at least :data:`MIN_LEVEL_POINTS` points.

    Returns
    -------
    list of LevelMesh, level 0 first.
    """
    reach = available_levels(forest, MAX_LEVEL, min_points=1)  # what an explicit request may ask
    if levels is None:
        wanted = available_levels(forest, MAX_LEVEL)
    elif isinstance(levels, (int, np.integer)):
        if levels < 0:
            raise OptionError(f"levels must be >= 0, got {levels}")
        wanted = [i for i in reach if i <= levels]
    else:
        wanted = sorted({int(i) for i in levels} | {0})
        bad = [i for i in wanted if i not in reach]
        if bad:
            raise OptionError(f"level {bad[0]} is not reached by this forest; available levels: "
                              f"{', '.join(map(str, reach))}")
    out = []
    for i in wanted:
        out.append(next_level(mesh, forest, i, out[-1] if out else None))
    return out


def next_level(mesh: TetMesh, forest: MergeForest, level: int, prev: LevelMesh | None = None) -> LevelMesh:
    """Level ``level`` of ``mesh``, from the previous level ``prev`` when given.

    Parameters
    ----------
    mesh : TetMesh
        The input (level 0).
    forest : MergeForest
        Its decimation, or any prefix of it holding at least the level's N_i merges (what
        :func:`~gatun_py.simplify.decimate` hands its ``on_level`` callback): the level's mesh
        depends only on those. The level's ``forest`` is this one restricted (a prefix's
        restriction is a prefix too).
    level : int
        i >= 0.
    prev : LevelMesh, optional
        A coarser-numbered level of the same mesh and forest (or of a shorter prefix of it).

    Returns
    -------
    LevelMesh

    Examples
    --------
    >>> from gatun_py.mesh import TetMesh
    >>> from gatun_py.simplify import decimate
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float32)
    >>> mesh = TetMesh(pts, np.arange(5, dtype=np.float32), np.array([[0, 1, 2, 3], [1, 2, 3, 4]], np.int32))
    >>> next_level(mesh, decimate(mesh), 0).mesh.n_tets
    2
    """
    n = level_merges(mesh.n_points, level)
    if prev is None:
        m, ids = simplified_mesh(mesh, forest, n, return_ids=True)
        rest = level_forest(forest, n, ids)
    else:
        # from the previous level (half its size), not from the input: its remaining forest
        # continues the same merges, so the tets, their order and the vertices are the same
        sub = level_forest(forest, prev.n_merges, prev.vertex_ids)
        m, local = simplified_mesh(prev.mesh, sub, n - prev.n_merges, return_ids=True)
        ids = prev.vertex_ids[local]
        rest = level_forest(sub, n - prev.n_merges, local)
    return LevelMesh(level, n, n / mesh.n_points if mesh.n_points else 0.0, m, rest, ids)


def storage_forests(levels: list[LevelMesh]) -> list[MergeForest]:
    """The forest to store with each level of a file.

    Level 0 keeps the whole forest (any ratio from the full mesh); the last level keeps all its
    remaining merges; every level in between keeps only the merges up to the next stored level,
    because a reader always starts from the most simplified level still finer than its target
    (paper section 5). Storing every level's whole remaining forest would repeat the same merges
    in every level (about a fifth of the file on Blunt-fin).
    """
    out = []
    for j, lv in enumerate(levels):
        if j == 0 or j == len(levels) - 1:
            out.append(lv.forest)
        else:
            out.append(forest_prefix(lv.forest, levels[j + 1].n_merges - lv.n_merges))
    return out


def level_payloads(levels: list[LevelMesh]) -> list[LevelPayload]:
    """What a file stores of these levels: each level's mesh with its :func:`storage_forests` forest,
    as the codec's payloads (``write_tetc``, ``encode_level``)."""
    return [LevelPayload(x.level, x.ratio, x.n_merges, x.mesh, (f.parent, f.rank))
            for x, f in zip(levels, storage_forests(levels))]


# -- reading levels back from a .tetc file ------------------------------------------------------
def _describe_levels(levels_meta) -> str:
    return ", ".join(f"{lv.level} (ratio {float(lv.ratio):.6f})" for lv in levels_meta)


def forest_merges(reader: TetcReader) -> int:
    """Merges the file's full forest holds (0 when it stores no forest)."""
    return reader.forest_merges()


@dataclass(frozen=True)
class Target:
    """Where to start and how far to go: stored ``level`` (its N_i is ``level_merges``) and the
    number of merges of the full forest to reach, ``merges`` (ratio = merges / points)."""

    level: int
    merges: int
    ratio: float
    level_merges: int


def stored_levels(reader) -> list[LevelMeta]:
    """The file's level metadata, finest first."""
    return sorted(reader.levels, key=lambda lv: lv.merges_before)


def resolve_target(reader, *, ratio: float | None = None, level: int | None = None) -> Target:
    """The stored level to start from for ``--ratio R`` or ``--level i`` (paper section 5).

    Ratio R means N = floor(R * points) merges, started from the most simplified stored level
    whose N_i <= N (the levels between the first and the last store only the merges up to the
    next level, so that is also the only level that can get there). Neither: the full mesh.

    Raises
    ------
    OptionError
        Impossible ratio or level; the message lists what the file holds.
    """
    if ratio is not None and level is not None:
        raise OptionError("give either a ratio or a level, not both")
    stored = stored_levels(reader)
    n0 = stored[0].points
    if ratio is None:
        level = 0 if level is None else int(level)
        for lv in stored:
            if lv.level == level:
                n = lv.merges_before
                return Target(level, n, n / n0 if n0 else 0.0, n)
        raise OptionError(f"level {level} is not stored in this file; stored levels: {_describe_levels(stored)}")
    total = forest_merges(reader)
    max_ratio = total / n0 if n0 else 0.0
    if not (isinstance(ratio, (int, float)) and 0.0 <= ratio <= 1.0):
        raise OptionError(f"ratio {ratio} is outside [0, 1]; this file reaches ratios up to {max_ratio:.6f} "
                          f"(stored levels: {_describe_levels(stored)})")
    n = int(np.floor(ratio * n0))
    if n > total:
        why = ("it stores no merge forest (compressed with --mesh-only)" if not stored[0].has_forest
               else f"its forest holds {total} merges (maximum ratio {max_ratio:.6f})")
        raise OptionError(f"ratio {ratio} needs {n} merges but {why}; stored levels: {_describe_levels(stored)}")
    usable = [lv for lv in stored if lv.merges_before <= n and (lv.has_forest or lv.merges_before == n)]
    if not usable:
        raise OptionError(f"no stored level can reach ratio {ratio}; stored levels: {_describe_levels(stored)}")
    lv = max(usable, key=lambda x: x.merges_before)
    return Target(lv.level, n, n / n0 if n0 else 0.0, lv.merges_before)


def target_ancestors(reader, target: Target, *, times: dict | None = None) -> np.ndarray | None:
    """Ancestor of every vertex of the target's stored level (decode order), None if no merge is left.

    ``times``, if given, receives ``forest_decode_s`` (reading and decoding the forest section)
    and ``ancestors_s`` (the top-down pass).
    """
    rest = target.merges - target.level_merges
    if rest == 0:
        return None
    t0 = time.perf_counter()
    parent, rank = reader.read_forest(target.level)
    t1 = time.perf_counter()
    if rest > int((rank != ROOT_RANK).sum()):
        raise CorruptFileError(f"level {target.level}: its forest holds fewer merges than the metadata says")
    anc = ancestors(parent, rank, rest)
    if times is not None:
        times["forest_decode_s"] = t1 - t0
        times["ancestors_s"] = time.perf_counter() - t1
    return anc


def read_simplified(source, *, ratio: float | None = None, level: int | None = None, jobs: int | None = None):
    """The mesh at a simplification ratio (or a stored level) of a ``.tetc`` file.

    The level chosen by :func:`resolve_target` is decoded and its forest applied for the
    remaining N - N_i merges, which gives exactly the mesh after N merges of the full forest.

    Parameters
    ----------
    source : path, bytes or TetcReader
    ratio : float, optional
        0 <= ratio <= the file's maximum ratio.
    level : int, optional
        A stored level (exclusive with ``ratio``).
    jobs : int, optional
        Threads decoding the level (:meth:`TetcReader.decode_mesh`; default: all cores).

    Returns
    -------
    TetMesh
        Vertices in the decode order of the level it came from (merged ones dropped).

    Raises
    ------
    OptionError
        Impossible ratio or level; the message lists what the file holds.
    """
    reader = source if isinstance(source, TetcReader) else TetcReader(source)
    target = resolve_target(reader, ratio=ratio, level=level)
    anc = target_ancestors(reader, target)  # first: the level's decode then reuses the forest's connectivity
    mesh = reader.decode_mesh(target.level, jobs=jobs)
    return mesh if anc is None else mesh_from_ancestors(mesh, anc)[0]
