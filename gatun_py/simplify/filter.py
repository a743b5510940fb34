"""The on-the-fly simplification filter between the decoder and the renderer (paper 4.2).

Given the number of merges N, one top-down pass over the merge forest gives every vertex its
ancestor (:func:`gatun_py.simplify.forest.ancestors`). For every decoded tet (and boundary face):
rewrite it to ancestors; if they are not distinct it has collapsed and is dropped; if all ancestors
have been decoded it is forwarded; otherwise it is parked on each missing ancestor with a waitCount
and released the moment the count reaches zero, when the decoder emits the last of them.

Neither the decoder nor the renderer knows about the filter: it consumes and yields
``gatun_py.mesh.TetBatch``es (``docs/architecture.md``). Vertices pass through unchanged (merged-away vertices
are simply never referenced again).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Iterable, Iterator

import numpy as np

from ..errors import CorruptFileError
from . import _filter_kernels as K


class _WaitQueues:
    """Parked items of one arity (4 for tets, 3 for faces) and their wait lists."""

    def __init__(self, n_vertices: int, arity: int):
        self.arity = arity
        self.head = np.full(n_vertices, -1, np.int64)
        self.counts = np.zeros(3, np.int64)  # ever parked, wait-list entries, waiting now
        self.parked = np.empty((0, arity), np.int32)
        self.wait = np.empty(0, np.int32)
        self.nxt = np.empty(0, np.int64)
        self.item_of = np.empty(0, np.int64)

    def grow(self) -> None:
        """Double the room for parked items and wait-list entries (slots are not reused)."""
        cap = max(2 * len(self.wait), 1024)
        self.parked = _grow(self.parked, cap)
        self.wait = _grow(self.wait, cap)
        self.nxt = _grow(self.nxt, self.arity * cap)
        self.item_of = _grow(self.item_of, self.arity * cap)

    @property
    def waiting(self) -> int:
        return int(self.counts[2])


def _grow(a: np.ndarray, cap: int) -> np.ndarray:
    out = np.empty((cap,) + a.shape[1:], a.dtype)
    out[: len(a)] = a
    return out


class SimplifyFilter:
    """Paper 4.2's filter for one target: ``SimplifyFilter(anc).filter(batches)``.

    Parameters
    ----------
    ancestor : (n,) int array
        Ancestor of every vertex in decode numbering, e.g. ``ancestors(parent, rank, N)``.

    Attributes
    ----------
    stats : dict
        ``tets_in``, ``tets_out``, ``tets_dropped``, ``tets_parked``, ``faces_in``, ``faces_out``,
        ``filter_s`` (seconds spent inside the filter).

    Examples
    --------
    >>> import numpy as np
    >>> from gatun_py.simplify.filter import SimplifyFilter
    >>> f = SimplifyFilter(np.array([0, 1, 2, 3, 3]))     # vertex 4 merged into 3
    >>> f.stats["tets_in"]
    0
    """

    def __init__(self, ancestor: np.ndarray):
        self.anc = np.ascontiguousarray(ancestor, dtype=np.int64)
        n = len(self.anc)
        if n and (self.anc.min() < 0 or self.anc.max() >= n):
            raise CorruptFileError("ancestor table refers to vertices outside the mesh")
        self.arrived = np.zeros(n, np.bool_)
        self.tets = _WaitQueues(n, 4)
        self.faces = _WaitQueues(n, 3)
        self.stats = dict(tets_in=0, tets_out=0, tets_dropped=0, tets_parked=0, faces_in=0, faces_out=0,
                          filter_s=0.0)

    def filter(self, batches: Iterable) -> Iterator:
        """Yield the simplified stream of ``batches`` (same batch type, rewritten faces and tets)."""
        for batch in batches:
            yield self.process(batch)
        if self.tets.waiting or self.faces.waiting:
            raise CorruptFileError(f"{self.tets.waiting} tets and {self.faces.waiting} boundary faces still wait "
                                   f"for vertices the stream never delivered")

    def process(self, batch):
        t0 = time.perf_counter()
        first, k = int(batch.first), int(len(batch.points))
        n = len(self.anc)
        if first < 0 or first + k > n:
            raise CorruptFileError(f"batch vertices {first}..{first + k - 1} outside the forest's {n} vertices")
        self.arrived[first:first + k] = True
        faces = self._run(self.faces, first, k, np.asarray(batch.boundary))
        tets = self._run(self.tets, first, k, np.asarray(batch.tets))
        self.stats["faces_in"] += len(batch.boundary)
        self.stats["faces_out"] += len(faces)
        self.stats["tets_in"] += len(batch.tets)
        self.stats["tets_out"] += len(tets)
        self.stats["tets_parked"] = int(self.tets.counts[0])
        self.stats["tets_dropped"] = self.stats["tets_in"] - self.stats["tets_out"] - self.tets.waiting
        out = dataclasses.replace(batch, boundary=faces, tets=tets)
        self.stats["filter_s"] += time.perf_counter() - t0
        return out

    def _run(self, q: _WaitQueues, first: int, k: int, items: np.ndarray) -> np.ndarray:
        """Release what the batch's new vertices complete, then filter the batch's own items."""
        items = np.ascontiguousarray(items, dtype=np.int32).reshape(-1, q.arity)
        out = np.empty((len(items) + q.waiting, q.arity), np.int32)
        n_out = K.release(first, k, q.head, q.nxt, q.item_of, q.parked, q.wait, q.counts, out, 0) if k else 0
        i = 0
        while True:
            n_out, i = K.filter_items(items, i, self.anc, self.arrived, q.head, q.nxt, q.item_of, q.parked, q.wait,
                                      q.counts, out, n_out)
            if n_out < 0 or i >= len(items):
                break
            q.grow()
        if n_out < 0:
            raise CorruptFileError("a decoded tet or face refers to a vertex outside the mesh")
        return out[:n_out]
