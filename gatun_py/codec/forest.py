"""The merge forest's bytes: the ``L{i}/forest`` section of a ``.tetc`` file.

A forest is two arrays over the vertices of a level, in decode order: ``parent[v]`` (v itself for
a root) and ``rank[v]``, the 0-based execution order of v's merge (``ROOT_RANK`` for roots). The
first N merges are those with rank < N; a parent always outranks its children (it was still alive
when they were merged into it). The simplify stage builds forests; this module only stores them.

Section layout in files of format 1 and 2 (magic ``GFR1``): ``<4sII`` header (magic, vertices n, merges k), then,
when k > 0, one LZMA (xz) stream of 8n bytes: every vertex's rank (roots as k) as uint32, then its
parent as a zigzagged delta from the vertex, each array byte-planed (all low bytes, ..., all high
bytes). Decoding stops at 8n + 1 bytes of output whatever the stream claims.

Files of format 3 code the forest after the level's mesh (magic ``GFR3``,
:func:`encode_forest_on_mesh`): the decoder knows the level's tets when it reads the forest, so a
merge's parent is coded as an index among the live neighbours of the merged vertex, and its rank
as a bucket (the 1 - 1/2^i level it falls in, context-modelled from the neighbours' buckets) plus
its place among the bucket's free ranks. ``<4sII`` header (magic, vertices n, merges k), then,
when k > 0, one range-coded stream (:mod:`._forest_kernels`, ``docs/format.md``).

Files of format 6 code the forest after the level's mesh *and geometry* (magic ``GFR6``,
forest coding 2, :func:`encode_forest_rounds`): the decimator merges in rounds of independent
merges and numbers the merges of a round by the merged vertices' :func:`canonical_key` (their
float32 position bits, then value), so a rank is coded as its bucket plus its round inside the
bucket (``log2`` of the bucket's rounds instead of ``log2`` of its free ranks); the decoder
rebuilds the ranks by sorting (bucket, round, key). Parents as in format 3. Any valid forest
codes this way (a round is a maximal run of ranks whose keys ascend; a greedy forest just has
many short runs).

Files of format 7 (magic ``GFR7``, forest coding 3, :func:`encode_forest_on_geometry`) code the
same rounds and parents with what the level's geometry says about the decimator's errors: every
vertex's quadric over its tets (as the decimator's, from the level's mesh) ranks a merge's
candidate parents (least error first: the decimator's choice is usually first), and the quantile
of a vertex's cheapest merge is the context of its round's phase (cheap merges come early). The
quadrics are independent of the order of the tets and of their corners (the encoder has the input's,
the decoder the connectivity decoder's).
"""

from __future__ import annotations

import lzma
import struct

import numpy as np

from ..errors import CorruptFileError
from . import _forest_kernels as FK
from .formats import CURRENT, codings
from .rangecoder import capacity_hint, check_decoder, dec_state, run_encoder

__all__ = ["ROOT_RANK", "check_forest", "encode_forest", "decode_forest", "forest_header",
           "encode_forest_on_mesh", "decode_forest_on_mesh", "encode_forest_rounds", "decode_forest_rounds",
           "encode_forest_on_geometry", "decode_forest_on_geometry", "canonical_key", "rank_rounds",
           "coding_for_format", "FOREST_CODING"]

ROOT_RANK = 2**31 - 1  # the rank of a vertex that is never merged


def coding_for_format(major: int) -> int:
    """The forest coding of a file of format ``major`` (:mod:`gatun_py.codec.formats`)."""
    return codings(major).forest


# what this version of tetc writes
FOREST_CODING = CURRENT.forest


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


_MAGIC = b"GFR1"
_MAGIC_ON_MESH = b"GFR3"
_MAGIC_ROUNDS = b"GFR6"
_MAGIC_GEOMETRY = b"GFR7"
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


def _checked_header(data: bytes, magic: bytes, n: int) -> int:
    """The merge count of a section that must start with ``magic`` and cover ``n`` vertices."""
    if len(data) < _HEADER.size:
        raise CorruptFileError("merge forest: truncated header")
    found, n_stored, k = _HEADER.unpack_from(data)
    if found != magic:
        raise CorruptFileError("merge forest: bad magic")
    if n_stored != n:
        raise CorruptFileError(f"merge forest: covers {n_stored} vertices, the mesh has {n}")
    return k


def forest_header(data: bytes) -> tuple[int, int]:
    """(vertices, merges) of a coded forest, read from its header only."""
    data = bytes(data[: _HEADER.size])
    if len(data) < _HEADER.size:
        raise CorruptFileError("merge forest: truncated header")
    magic, n, k = _HEADER.unpack(data)
    if magic not in (_MAGIC, _MAGIC_ON_MESH, _MAGIC_ROUNDS, _MAGIC_GEOMETRY) or k > n:
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
    k = _checked_header(data, _MAGIC, n)
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


MAX_VERTICES = 1 << 30  # the replay's int32 list stamps reach 2n


def _mesh_adjacency(tets, n: int):
    if n >= MAX_VERTICES:
        raise ValueError(f"a forest of {n} vertices: at most {MAX_VERTICES - 1}")
    tets = np.ascontiguousarray(tets, dtype=np.int32).reshape(-1, 4)
    if tets.size and (tets.min() < 0 or tets.max() >= n):
        raise ValueError("tet ids out of range")
    return FK.adjacency(tets, n)


def _boundary_mask(boundary, n: int) -> np.ndarray:
    mask = np.ascontiguousarray(boundary, dtype=np.bool_)
    if mask.shape != (n,):
        raise ValueError(f"boundary mask of shape {mask.shape} for {n} vertices")
    return mask


def _encode_prelude(parent, rank, magic: bytes, tets):
    """(header, parent, ranks with roots at k, k, start, nbrs) of a forest coded after its
    level's mesh (no adjacency when k = 0: the header is the whole section)."""
    parent = np.asarray(parent, np.int64)
    rank = np.asarray(rank, np.int64)
    k = check_forest(parent, rank)
    n = parent.shape[0]
    head = _HEADER.pack(magic, n, k)
    if k == 0:
        return head, parent, rank, 0, None, None
    start, nbrs = _mesh_adjacency(tets, n)
    return head, parent, np.where(rank == ROOT_RANK, k, rank), k, start, nbrs


def _prelude(data: bytes, magic: bytes, tets, n: int):
    """(k, start, nbrs) of a section coded after its level's mesh: header and counts checked,
    the adjacency built; ``start`` None for a forest without merges (nothing else may follow)."""
    k = _checked_header(data, magic, n)
    if n and k >= n:
        raise CorruptFileError("merge forest: as many merges as vertices")
    if k == 0:
        if len(data) != _HEADER.size:
            raise CorruptFileError("merge forest: trailing bytes")
        return 0, None, None
    if n >= MAX_VERTICES:
        raise CorruptFileError(f"merge forest: {n} vertices, at most {MAX_VERTICES - 1}")
    try:
        start, nbrs = _mesh_adjacency(tets, n)
    except ValueError:
        raise CorruptFileError("merge forest: the mesh's tet ids are out of range") from None
    return k, start, nbrs


def encode_forest_on_mesh(parent: np.ndarray, rank: np.ndarray, tets: np.ndarray, *, boundary) -> bytes:
    """Code a merge forest knowing the mesh it belongs to (the format-3 ``L{i}/forest`` section).

    Each merge's parent is almost always a live neighbour of the merged vertex at the time of the
    merge (the representative of one of its mesh neighbours, or of a neighbour of a vertex merged
    into it earlier): it is coded as an index into that short list, with an escape to the plain id.
    Ranks are coded per vertex as their 1 - 1/2^i bucket, context-modelled on the vertex's degree,
    whether it lies on the boundary and the buckets of the neighbours decoded before, then as the
    position among the ranks of the bucket still free (uniform: the order inside a bucket follows
    the decimator's error, which the decoder cannot predict).

    Parameters
    ----------
    parent, rank : (n,) int
        A valid forest (see :func:`check_forest`), in the numbering of ``tets``.
    tets : (m, 4) int
        The mesh the forest applies to (its vertex adjacency is all the coder uses, so the tets'
        order and orientation do not matter).
    boundary : (n,) bool
        Which vertices lie on the mesh's boundary surface (in decode order: the first
        ``boundary_vertices`` ones).

    Returns
    -------
    bytes

    Examples
    --------
    >>> import numpy as np
    >>> tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    >>> parent, rank = np.array([1, 2, 2, 2, 3]), np.array([0, 2, ROOT_RANK, 3, 1])
    >>> on_boundary = np.ones(5, bool)
    >>> data = encode_forest_on_mesh(parent, rank, tets, boundary=on_boundary)
    >>> p, r = decode_forest_on_mesh(data, tets, 5, boundary=on_boundary)
    >>> p.tolist(), r.tolist() == rank.tolist()
    ([1, 2, 2, 2, 3], True)
    """
    head, parent, ranks, k, start, nbrs = _encode_prelude(parent, rank, _MAGIC_ON_MESH, tets)
    if k == 0:
        return head
    n = len(parent)
    return head + run_encoder(FK.encode_forest_kernel, start, nbrs, _boundary_mask(boundary, n), parent, ranks, k,
                              capacity=capacity_hint(16 * n))


def decode_forest_on_mesh(data: bytes, tets: np.ndarray, n: int, *, boundary) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_forest_on_mesh`, given the same mesh's tets (decode order).

    Parameters
    ----------
    data : bytes
    tets : (m, 4) int
        The level's tets, ids in ``[0, n)`` (as the connectivity decoder returns them).
    n : int
        The level's vertex count.
    boundary : (n,) bool
        The boundary vertices, as given to the encoder.

    Returns
    -------
    parent, rank : (n,) int32

    Raises
    ------
    CorruptFileError
        On any inconsistency: wrong header, a damaged or truncated stream, trailing bytes, an
        invalid forest. Every index the kernel computes is checked before use.
    """
    data = bytes(data)
    k, start, nbrs = _prelude(data, _MAGIC_ON_MESH, tets, n)
    if start is None:
        return np.arange(n, dtype=np.int32), np.full(n, ROOT_RANK, np.int32)
    body = np.frombuffer(data, np.uint8, offset=_HEADER.size)
    parent = np.empty(n, np.int32)
    rank = np.empty(n, np.int32)
    st = dec_state()
    ok = FK.decode_forest_kernel(st, body, start, nbrs, _boundary_mask(boundary, n), k, parent, rank)
    if not ok:
        raise CorruptFileError("merge forest: the coded data is damaged or truncated")
    check_decoder(st, body, "merge forest")
    rank[rank == k] = ROOT_RANK
    check_forest(parent, rank)
    return parent, rank


def canonical_key(points: np.ndarray, density: np.ndarray) -> np.ndarray:
    """Every vertex's place in the order of the ranks inside a round (forest coding 2): the
    float32 bit patterns of x, y, z and the value, compared in that order as unsigned integers.

    Returns an (n,) int64 array of dense key ranks (equal points and values share one): what a
    decoder computes from the geometry it has decoded, in any numbering of the vertices.

    Examples
    --------
    >>> canonical_key(np.array([[1, 0, 0], [0, 0, 0], [-1, 0, 0]], np.float32), np.zeros(3, np.float32)).tolist()
    [1, 0, 2]
    """
    n = points.shape[0]
    # (x, y) and (z, value) as two uint64 keys: a sort on two keys instead of four
    bits = np.ascontiguousarray(points, np.float32).reshape(n, 3).view(np.uint32).astype(np.uint64)
    value = np.ascontiguousarray(density, np.float32).reshape(n).view(np.uint32).astype(np.uint64)
    hi = (bits[:, 0] << np.uint64(32)) | bits[:, 1]
    lo = (bits[:, 2] << np.uint64(32)) | value
    order = np.lexsort((lo, hi))
    dense = np.zeros(n, np.int64)
    if n:
        h, low = hi[order], lo[order]
        step = np.zeros(n, np.int64)
        step[1:] = (h[1:] != h[:-1]) | (low[1:] != low[:-1])
        dense[order] = np.cumsum(step)
    return dense


def rank_rounds(rank: np.ndarray, k: int, key: np.ndarray):
    """(round of every vertex, rounds per bucket) of a forest's ranks (roots: rank >= k): inside
    each rank bucket, a round is a maximal run of consecutive ranks whose vertices' keys strictly
    ascend, numbered from 0. Sorting a bucket's vertices by (round, key) gives back their ranks."""
    n = rank.shape[0]
    bounds = FK.bucket_bounds(n, k)
    by_rank = np.empty(k, np.int64)
    merged = np.flatnonzero(rank < k)
    by_rank[rank[merged]] = merged
    kk = key[by_rank]
    new = np.ones(k, bool)
    new[1:] = kk[1:] <= kk[:-1]
    new[bounds[:-1]] = True
    run = np.cumsum(new) - 1  # global run index
    first_run = run[bounds[:-1]]
    bucket = np.searchsorted(bounds, np.arange(k), side="right") - 1
    rid = np.full(n, -1, np.int64)
    rid[by_rank] = run - first_run[bucket]
    n_rounds = np.diff(np.append(first_run, run[-1] + 1)) if k else np.zeros(0, np.int64)
    return rid, n_rounds.astype(np.int64)



def _ranks_of_rounds(symbol, rid, k: int, points, density):
    """(rank with roots at k, vertex of every rank) from pass 1 of codings 2 and 3: every merged
    vertex's bucket symbol and round; the ranks follow (bucket, round, canonical key)."""
    n = symbol.shape[0]
    merged = np.flatnonzero(symbol != FK.ROOT_SYMBOL)
    bounds = FK.bucket_bounds(n, k)
    sizes = np.bincount(symbol[merged].astype(np.int64), minlength=len(bounds) - 1)
    if merged.size != k or not np.array_equal(sizes, np.diff(bounds)):
        raise CorruptFileError("merge forest: the buckets do not hold the merges the header says")
    key = canonical_key(points, density)
    s, r, kk = symbol[merged].astype(np.int64), rid[merged], key[merged]
    span_r, span_k = int(r.max()) + 1, int(kk.max()) + 1  # r >= 0 and kk >= 0: checked by the kernels
    if (int(s.max()) + 1) * span_r * span_k < 2**62:  # one int64 key sorts faster than three
        order = np.argsort((s * span_r + r) * span_k + kk, kind="stable")
    else:
        order = np.lexsort((kk, r, s))
    s, r, kk = s[order], r[order], kk[order]
    same_round = (s[1:] == s[:-1]) & (r[1:] == r[:-1])
    if np.any(same_round & (kk[1:] == kk[:-1])):
        raise CorruptFileError("merge forest: two vertices of one round have the same position and value")
    # rounds numbered 0, 1, ... without gaps in every bucket
    first = np.ones(k, bool)
    first[1:] = s[1:] != s[:-1]
    if np.any(r[first] != 0) or np.any(~first[1:] & (r[1:] != r[:-1]) & (r[1:] != r[:-1] + 1)):
        raise CorruptFileError("merge forest: a bucket has an empty round")
    of_rank = merged[order].astype(np.int32)
    rank = np.full(n, k, np.int32)
    rank[of_rank] = np.arange(k, dtype=np.int32)
    return rank, of_rank

def encode_forest_rounds(parent: np.ndarray, rank: np.ndarray, tets: np.ndarray, *, boundary, points,
                         density) -> bytes:
    """Code a merge forest knowing its level's mesh and geometry (the format-6 ``L{i}/forest``
    section, forest coding 2).

    As :func:`encode_forest_on_mesh`, but a rank is coded as its bucket and its round inside the
    bucket (:func:`rank_rounds`), uniformly among the bucket's rounds; the ranks inside a round
    follow :func:`canonical_key` of ``points`` and ``density`` (the level's float32 geometry in
    the numbering of ``tets``).

    Examples
    --------
    >>> import numpy as np
    >>> tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float32)
    >>> parent, rank = np.array([1, 2, 2, 2, 3]), np.array([0, 2, ROOT_RANK, 3, 1])
    >>> on_boundary = np.ones(5, bool)
    >>> data = encode_forest_rounds(parent, rank, tets, boundary=on_boundary, points=pts, density=np.zeros(5))
    >>> p, r = decode_forest_rounds(data, tets, 5, boundary=on_boundary, points=pts, density=np.zeros(5))
    >>> p.tolist(), r.tolist() == rank.tolist()
    ([1, 2, 2, 2, 3], True)
    """
    head, parent, ranks, k, start, nbrs = _encode_prelude(parent, rank, _MAGIC_ROUNDS, tets)
    if k == 0:
        return head
    rid, n_rounds = rank_rounds(ranks, k, canonical_key(np.asarray(points), np.asarray(density)))
    n = len(parent)
    return head + run_encoder(FK.encode_rounds_kernel, start, nbrs, _boundary_mask(boundary, n), parent, ranks, k,
                              rid, n_rounds, capacity=capacity_hint(16 * n))


def decode_forest_rounds(data: bytes, tets: np.ndarray, n: int, *, boundary, points,
                         density) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_forest_rounds`, given the level's tets, boundary vertices and
    geometry in decode order.

    Returns
    -------
    parent, rank : (n,) int32

    Raises
    ------
    CorruptFileError
        On any inconsistency: wrong header, a damaged or truncated stream, a bucket with more or
        fewer vertices than its ranks, an empty round, two vertices of equal key in one round,
        trailing bytes, an invalid forest.
    """
    data = bytes(data)
    k, start, nbrs = _prelude(data, _MAGIC_ROUNDS, tets, n)
    if start is None:
        return np.arange(n, dtype=np.int32), np.full(n, ROOT_RANK, np.int32)
    points = np.asarray(points)
    density = np.asarray(density)
    if points.shape != (n, 3) or density.shape != (n,):
        raise ValueError(f"geometry of shapes {points.shape}, {density.shape} for {n} vertices")
    body = np.frombuffer(data, np.uint8, offset=_HEADER.size)
    st = dec_state()
    probs = FK.new_model()
    mask = _boundary_mask(boundary, n)
    return _decode_rounds_then_parents(
        st, body, n, k, points, density,
        lambda symbol, rid: FK.decode_rounds_kernel(st, body, probs, start, nbrs, mask, k, symbol, rid),
        lambda parent, rank, of_rank: FK.decode_parents_kernel(st, body, probs, start, nbrs, k, parent, rank,
                                                               of_rank))


def _decode_rounds_then_parents(st, body, n: int, k: int, points, density, decode_rounds, decode_parents):
    """The part forest codings 2 and 3 share after their set-up: every vertex's bucket and round
    (``decode_rounds(symbol, rid)``), the ranks inside the rounds by :func:`canonical_key`, then
    the parents (``decode_parents(parent, rank, of_rank)``); both kernels return False on damage.
    Checks the stream's end and the forest; returns (parent, rank) with roots at ROOT_RANK."""
    symbol = np.empty(n, np.int8)
    rid = np.empty(n, np.int64)
    damaged = CorruptFileError("merge forest: the coded data is damaged or truncated")
    if not decode_rounds(symbol, rid):
        raise damaged
    rank, of_rank = _ranks_of_rounds(symbol, rid, k, points, density)
    parent = np.arange(n, dtype=np.int32)
    if not decode_parents(parent, rank, of_rank):
        raise damaged
    check_decoder(st, body, "merge forest")
    rank[rank == k] = ROOT_RANK
    check_forest(parent, rank)
    return parent, rank


def _geometry_terms(tets, points, density, start, nbrs, boundary):
    """(quadrics, normalised (x, y, z, value), proxy bins) of the level's vertices: coding 3's error
    proxy; the bins are every vertex's quantile (of ``FK.PROXY_BINS``) of its cheapest merge's
    quadric error, ties by vertex id."""
    n = boundary.shape[0]
    points = np.ascontiguousarray(points, dtype=np.float32)
    density = np.ascontiguousarray(density, dtype=np.float32)
    if points.shape != (n, 3) or density.shape != (n,):
        raise ValueError(f"geometry of shapes {points.shape}, {density.shape} for {n} vertices")
    q, u, best = FK.level_quadrics(np.ascontiguousarray(tets, dtype=np.int32).reshape(-1, 4), points, density,
                                   start, nbrs, boundary)
    bins = np.empty(n, np.int64)
    bins[np.argsort(best, kind="stable")] = np.arange(n, dtype=np.int64) * FK.PROXY_BINS // max(n, 1)
    return q, u, bins


def encode_forest_on_geometry(parent: np.ndarray, rank: np.ndarray, tets: np.ndarray, *, boundary, points,
                              density) -> bytes:
    """Code a merge forest knowing its level's mesh and geometry (the format-7 ``L{i}/forest``
    section, forest coding 3).

    As :func:`encode_forest_rounds` (bucket and round per vertex, ranks inside a round by
    :func:`canonical_key`, parents among the live neighbours), with the decimator's error proxy
    the decoder computes from the level: a vertex's round is coded as its phase (which sixteenth of
    its bucket's rounds) in the context of the quantile of its cheapest merge's quadric error, then
    its place in the phase, and a merge's candidate parents are ordered by the merged vertex's
    quadric at them (``docs/format.md``). The tets' order and orientation do not matter.

    Examples
    --------
    >>> import numpy as np
    >>> tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float32)
    >>> parent, rank = np.array([1, 2, 2, 2, 3]), np.array([0, 2, ROOT_RANK, 3, 1])
    >>> on_boundary = np.ones(5, bool)
    >>> data = encode_forest_on_geometry(parent, rank, tets, boundary=on_boundary, points=pts, density=np.zeros(5))
    >>> p, r = decode_forest_on_geometry(data, tets, 5, boundary=on_boundary, points=pts, density=np.zeros(5))
    >>> p.tolist(), r.tolist() == rank.tolist()
    ([1, 2, 2, 2, 3], True)
    """
    head, parent, ranks, k, start, nbrs = _encode_prelude(parent, rank, _MAGIC_GEOMETRY, tets)
    if k == 0:
        return head
    n = len(parent)
    mask = _boundary_mask(boundary, n)
    q, u, bins = _geometry_terms(tets, points, density, start, nbrs, mask)
    rid, n_rounds = rank_rounds(ranks, k, canonical_key(np.asarray(points), np.asarray(density)))
    return head + run_encoder(FK.encode_rounds3_kernel, start, nbrs, mask, parent, ranks, k, rid, n_rounds, bins,
                              q, u, capacity=capacity_hint(16 * n))


def decode_forest_on_geometry(data: bytes, tets: np.ndarray, n: int, *, boundary, points,
                              density) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_forest_on_geometry`, given the level's tets, boundary vertices and
    geometry in decode order.

    Returns
    -------
    parent, rank : (n,) int32

    Raises
    ------
    CorruptFileError
        As :func:`decode_forest_rounds`.
    """
    data = bytes(data)
    k, start, nbrs = _prelude(data, _MAGIC_GEOMETRY, tets, n)
    if start is None:
        return np.arange(n, dtype=np.int32), np.full(n, ROOT_RANK, np.int32)
    mask = _boundary_mask(boundary, n)
    q, u, bins = _geometry_terms(tets, points, density, start, nbrs, mask)
    body = np.frombuffer(data, np.uint8, offset=_HEADER.size)
    st = dec_state()
    return _decode_rounds_then_parents(
        st, body, n, k, points, density,
        lambda symbol, rid: FK.decode_rounds3_kernel(st, body, start, nbrs, mask, k, bins, symbol, rid),
        lambda parent, rank, of_rank: FK.decode_parents3_kernel(st, body, start, nbrs, mask, k, parent, rank,
                                                                of_rank, q, u))
