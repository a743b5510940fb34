"""The merge forest: parents and ranks of the decimation, ancestors after N merges, compact coding.

Conventions (``docs/architecture.md``): ``parent[v]`` is v itself for a root, ``rank[v]`` the
0-based execution order of v's merge (``ROOT_RANK`` for roots). The first N merges are those with
rank < N; a parent always has a larger rank than its children (it was still alive when they were
merged into it).
"""

from __future__ import annotations

import lzma
import struct
from dataclasses import dataclass

import numpy as np

from ..errors import CorruptFileError, OptionError
from ..mesh import TetMesh
from ._decimate_kernels import ROOT_RANK, _ancestors

__all__ = ["ROOT_RANK", "MergeForest", "ancestors", "simplified_mesh", "mesh_from_ancestors", "encode_forest", "decode_forest",
           "check_forest", "forest_header", "forest_prefix"]


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


def check_forest(parent: np.ndarray, rank: np.ndarray) -> int:
    """Validate a forest; return its number of merges or raise :class:`CorruptFileError`.

    Ranks of merged vertices must be exactly 0..k-1, roots must be their own parent with
    ``ROOT_RANK``, and every parent must outrank its child (which also rules out cycles).
    """
    parent = np.asarray(parent)
    rank = np.asarray(rank)
    n = parent.shape[0]
    if parent.shape != (n,) or rank.shape != (n,):
        raise CorruptFileError("merge forest: parent and rank arrays differ in length")
    if n == 0:
        return 0
    if parent.min() < 0 or parent.max() >= n:
        raise CorruptFileError("merge forest: a parent id is out of range")
    idx = np.arange(n)
    root = parent == idx
    if np.any(rank[root] != ROOT_RANK):
        raise CorruptFileError("merge forest: a root has a merge rank")
    merged = ~root
    k = int(merged.sum())
    r = np.sort(rank[merged].astype(np.int64))
    if not np.array_equal(r, np.arange(k)):
        raise CorruptFileError("merge forest: merge ranks are not 0..k-1")
    if np.any(rank[parent[merged]].astype(np.int64) <= rank[merged]):
        raise CorruptFileError("merge forest: a vertex is merged into one that was merged before it")
    return k


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
    return _ancestors(parent, rank, np.int64(n_merges))


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
    (``anc[v] == v``) compacted in their input order.
    """
    t = anc[mesh.tets]
    s = np.sort(t, axis=1)
    keep = np.all(s[:, 1:] != s[:, :-1], axis=1)
    ids = np.flatnonzero(anc == np.arange(mesh.n_points))
    new_id = np.full(mesh.n_points, -1, np.int64)
    new_id[ids] = np.arange(ids.size)
    out = TetMesh(mesh.points[ids], mesh.density[ids], new_id[t[keep]].astype(np.int32), mesh.scalar_name)
    return out, ids


# -- coding -----------------------------------------------------------------------------------
_MAGIC = b"GFR1"
_HEADER = struct.Struct("<4sII")


def _zigzag(x: np.ndarray) -> np.ndarray:
    x = x.astype(np.int64)
    return ((x << 1) ^ (x >> 63)).astype(np.uint32)


def _unzigzag(z: np.ndarray) -> np.ndarray:
    z = z.astype(np.int64)
    return (z >> 1) ^ -(z & 1)


def _shuffle(a: np.ndarray) -> bytes:
    """uint32 array -> its bytes grouped by significance (low bytes, then ..., high bytes)."""
    return np.ascontiguousarray(a.astype("<u4").view(np.uint8).reshape(-1, 4).T).tobytes()


def _unshuffle(b: bytes, k: int) -> np.ndarray:
    return np.frombuffer(b, np.uint8).reshape(4, k).T.copy().view("<u4").reshape(-1)


def encode_forest(parent: np.ndarray, rank: np.ndarray) -> bytes:
    """Code a merge forest compactly.

    In vertex order: every vertex's rank (roots as k = the number of merges) and its parent as
    a delta from the vertex (0 for roots), both zigzagged/byte-planed and LZMA-coded. Ranks cost
    close to the log2(n!)/n bits of an arbitrary permutation; parents are mesh neighbours, so in a
    locality-preserving vertex order (the codec's decode order) their deltas are small.

    Parameters
    ----------
    parent, rank : (n,) int
        A valid forest (see :func:`check_forest`).

    Returns
    -------
    bytes
    """
    parent = np.asarray(parent, np.int64)
    rank = np.asarray(rank, np.int64)
    k = check_forest(parent, rank)
    n = parent.shape[0]
    ranks = np.where(rank == ROOT_RANK, k, rank).astype(np.uint32)
    d_parent = _zigzag(parent - np.arange(n))
    body = lzma.compress(_shuffle(ranks) + _shuffle(d_parent), preset=9 | lzma.PRESET_EXTREME) if k else b""
    return _HEADER.pack(_MAGIC, n, k) + body


def forest_header(data: bytes) -> tuple[int, int]:
    """(vertices, merges) of a coded forest, read from its header only."""
    data = bytes(data[: _HEADER.size])
    if len(data) < _HEADER.size:
        raise CorruptFileError("merge forest: truncated header")
    magic, n, k = _HEADER.unpack(data)
    if magic != _MAGIC or k > n:
        raise CorruptFileError("merge forest: bad header")
    return int(n), int(k)


def decode_forest(data: bytes, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_forest`.

    Parameters
    ----------
    data : bytes
    n : int
        The number of vertices the forest must cover (from the mesh it belongs to).

    Returns
    -------
    parent, rank : (n,) int32

    Raises
    ------
    CorruptFileError
        On any inconsistency (wrong size, bad ids, a cycle, ...).
    """
    data = bytes(data)
    if len(data) < _HEADER.size:
        raise CorruptFileError("merge forest: truncated header")
    magic, n_stored, k = _HEADER.unpack_from(data)
    if magic != _MAGIC:
        raise CorruptFileError("merge forest: bad magic")
    if n_stored != n:
        raise CorruptFileError(f"merge forest: covers {n_stored} vertices, the mesh has {n}")
    if k > n:
        raise CorruptFileError("merge forest: more merges than vertices")
    parent = np.arange(n, dtype=np.int64)
    rank = np.full(n, ROOT_RANK, np.int64)
    if k:
        try:
            dec = lzma.LZMADecompressor()
            raw = dec.decompress(data[_HEADER.size:], max_length=8 * n + 1)
        except lzma.LZMAError as e:
            raise CorruptFileError(f"merge forest: {e}") from None
        if len(raw) != 8 * n or not dec.eof or dec.unused_data:
            raise CorruptFileError("merge forest: payload has the wrong length")
        ranks = _unshuffle(raw[: 4 * n], n).astype(np.int64)
        if ranks.max() > k:
            raise CorruptFileError("merge forest: a rank is out of range")
        parent = np.arange(n) + _unzigzag(_unshuffle(raw[4 * n:], n))
        if parent.min() < 0 or parent.max() >= n:
            raise CorruptFileError("merge forest: a parent id is out of range")
        rank = np.where(ranks == k, ROOT_RANK, ranks)
    elif len(data) != _HEADER.size:
        raise CorruptFileError("merge forest: trailing bytes")
    parent = parent.astype(np.int32)
    rank = rank.astype(np.int32)
    check_forest(parent, rank)
    return parent, rank
