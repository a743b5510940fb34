"""The merge dependencies' bytes: the ``deps`` section of a ``.tetc`` file (format 3).

Merge i (the merge of rank i of the full forest) depends on the merges D(i), all of lower rank
(:mod:`gatun_py.simplify.dependencies` computes them); ``removed[i]`` counts the tets it deletes.
Ranks are those of the full forest, so one section serves every level: level k's remaining
merges are the ranks >= N_k.

Section layout (magic ``GDP1``): ``<4sIIQ`` header (magic, merges k, a reserved 0, entries nnz),
then, when k > 0, one LZMA (xz) stream of ``4 (2k + nnz)`` bytes, three uint32 arrays each
byte-planed (all low bytes, ..., all high bytes): every merge's |D(i)|, every merge's
``removed[i]``, then the dependencies as gaps: per merge, from the highest rank down,
``i - 1 - j`` for the first and ``j_prev - 1 - j`` after it (small numbers: dependencies are
recent merges). Decoding stops at the stated length plus one byte whatever the stream claims, and
checks every rank it rebuilds.
"""

from __future__ import annotations

import lzma
import struct

import numpy as np

from ..errors import CorruptFileError

__all__ = ["encode_dependencies", "decode_dependencies", "dependencies_header", "MAX_ENTRIES_PER_MERGE"]

_MAGIC = b"GDP1"
_HEADER = struct.Struct("<4sIIQ")
# believed at most this many dependencies per merge (the largest seen on the samples is ~150 for
# one merge, the mean ~10): bounds what a header can make the decoder allocate
MAX_ENTRIES_PER_MERGE = 4096


def _planes(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(np.asarray(a, "<u4").view(np.uint8).reshape(-1, 4).T).tobytes()


def _unplanes(b: bytes, k: int) -> np.ndarray:
    return np.frombuffer(b, np.uint8).reshape(4, k).T.copy().view("<u4").reshape(-1).astype(np.int64)


def encode_dependencies(ptr: np.ndarray, idx: np.ndarray, removed: np.ndarray) -> bytes:
    """Code a dependency DAG (CSR ``ptr``, ``idx`` by rank, any order within a merge) and the removal counts."""
    ptr = np.asarray(ptr, np.int64)
    idx = np.asarray(idx, np.int64)
    removed = np.asarray(removed, np.int64)
    k = removed.shape[0]
    if ptr.shape != (k + 1,) or ptr[0] != 0 or ptr[-1] != idx.shape[0] or np.any(np.diff(ptr) < 0):
        raise ValueError("dependencies: bad CSR pointers")
    rows = np.repeat(np.arange(k), np.diff(ptr))
    if idx.size and (idx.min() < 0 or np.any(idx >= rows)):
        raise ValueError("dependencies: a merge depends on itself or a later merge")
    order = np.lexsort((-idx, rows))  # per merge, highest rank first
    j = idx[order]
    prev = np.where(np.arange(idx.size) == ptr[rows], rows, np.concatenate([[0], j[:-1]]))
    gaps = prev - 1 - j
    if gaps.size and gaps.min() < 0:
        raise ValueError("dependencies: a merge lists a dependency twice")
    body = b""
    if k:
        body = lzma.compress(_planes(np.diff(ptr)) + _planes(removed) + _planes(gaps), preset=9 | lzma.PRESET_EXTREME)
    return _HEADER.pack(_MAGIC, k, 0, int(idx.size)) + body


def dependencies_header(data: bytes) -> tuple[int, int]:
    """(merges, entries) from the header only."""
    data = bytes(data[: _HEADER.size])
    if len(data) < _HEADER.size:
        raise CorruptFileError("dependencies: truncated header")
    magic, k, reserved, nnz = _HEADER.unpack(data)
    if magic != _MAGIC or reserved != 0 or nnz > MAX_ENTRIES_PER_MERGE * k:
        raise CorruptFileError("dependencies: bad header")
    return int(k), int(nnz)


def decode_dependencies(data: bytes, n_merges: int, n_tets: int):
    """Inverse of :func:`encode_dependencies`: (ptr (k+1,) int64, idx int32 ascending per merge,
    removed (k,) int32).

    Parameters
    ----------
    n_merges : int
        The merges of the file's full forest (the section must cover exactly these).
    n_tets : int
        Tets of the full mesh: the removal counts cannot add up to more.

    Raises
    ------
    CorruptFileError
        On any inconsistency, before allocating more than the header's (capped) counts allow.
    """
    data = bytes(data)
    k, nnz = dependencies_header(data)
    if k != n_merges:
        raise CorruptFileError(f"dependencies: cover {k} merges, the forest has {n_merges}")
    if k == 0:
        if len(data) != _HEADER.size or nnz:
            raise CorruptFileError("dependencies: trailing bytes")
        return np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32)
    want = 4 * (2 * k + nnz)
    try:
        dec = lzma.LZMADecompressor()
        raw = dec.decompress(data[_HEADER.size:], max_length=want + 1)
    except lzma.LZMAError as e:
        raise CorruptFileError(f"dependencies: {e}") from None
    if len(raw) != want or not dec.eof or dec.unused_data:
        raise CorruptFileError("dependencies: payload has the wrong length")
    deg = _unplanes(raw[: 4 * k], k)
    removed = _unplanes(raw[4 * k: 8 * k], k)
    gaps = _unplanes(raw[8 * k:], nnz)
    if int(deg.sum()) != nnz:
        raise CorruptFileError("dependencies: counts do not add up to the entries")
    if removed.min() < 1 or int(removed.sum()) > n_tets:
        raise CorruptFileError("dependencies: bad removal counts")
    ptr = np.concatenate([[0], np.cumsum(deg)]).astype(np.int64)
    rows = np.repeat(np.arange(k, dtype=np.int64), deg)
    steps = np.cumsum(gaps + 1)
    base = np.concatenate([[0], steps])[ptr[:-1]][rows] if nnz else steps
    j = rows - (steps - base)  # highest first within each merge
    if nnz and j.min() < 0:
        raise CorruptFileError("dependencies: a rank is out of range")
    out = np.empty(nnz, np.int32)
    out[ptr[rows] + ptr[rows + 1] - 1 - np.arange(nnz)] = j  # ascending within each merge
    return ptr, out, removed.astype(np.int32)
