"""The tet stream of a bricked ``.tetc`` file for the isosurface extractor: skip, decode apart, renumber.

A bricked file (``tetc compress --bricks K``, :mod:`gatun_py.codec.bricks`) holds K independent
streams, and its index stores every brick's scalar range per level. A brick whose range contains
none of the isovalues has every vertex on one side of each of them: no tet of it is cut by a
surface, and none of its faces touches one, so it is skipped without reading anything but the
index. The other bricks are decoded on up to ``jobs`` threads at a time (the decode kernels release
the GIL); the extractor takes their batches in brick order, so the surface (its vertex order, the
rounds of collapses) is the same whatever the thread count and the schedule.

**Ids.** The stream renumbers every brick's vertices into one id space as
:func:`gatun_py.codec.bricks.plan_stitch` numbers the stitched mesh: the first brick's vertices in
decode order, then every next brick's, a cut vertex only the first time a brick holds it (it is
known by its file-wide cut id, or, in a file whose cut sections list positions only, by its
coordinates' bits). When no brick is skipped, the ids and the tet order are exactly those of
:func:`~gatun_py.codec.bricks.decode_bricked`, so a surface vertex on a cut edge is keyed by the same
edge whichever brick reaches it, and it is one vertex.

**Locks.** The extractor locks a surface vertex until the faces around its edge leave the cut
border of the stream (:mod:`.marching`), and that border must be the one of the whole mesh, not of
each brick: a face on a cut between two bricks is interior to the mesh, open from the first of its
two tets to the second. So the stream passes a brick's boundary faces except those whose three
vertices are cut vertices (a cut face has all three on the cut): those faces are toggled by their
tets alone, and a vertex on a cut edge stays locked until every brick that holds the edge is done.
Every brick that holds a tet around such an edge is decoded (its tets straddle the isovalue), so
the lock is released when the last of them has been streamed. The price: a face of the mesh
boundary whose three vertices all lie on cuts (rare: the corner of a cut at the boundary) is never
closed, and the surface vertices around it wait for the final round of collapses
(``locked_at_end`` in the stats). And a brick's boundary enters the border with the brick, not at
the start: an edge whose star is two fans that meet only along the edge (a non-manifold edge of
the mesh boundary), in two bricks, unlocks when the first fan is done; a later triangle on it
then makes a second vertex at the same place (a seam, never an error). The one-stream extractor
has the whole boundary up front and no such case.

Memory: at most ``jobs`` bricks decode at once, and at most ``jobs + 1`` bricks' batches (decoded,
not yet extracted) are held; the extractor's tables and the shared vertex array (x, y, z, scalar of
the decoded bricks' vertices) are the only state of the whole file.
"""

from __future__ import annotations

import math
import queue
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from ..codec import TetcReader
from ..codec.bricks import check_jobs, read_cut
from ..errors import CorruptFileError, OptionError
from ..mesh import TetBatch
from . import _numba_setup  # noqa: F401  (first, before any kernel is loaded: see the module)

__all__ = ["BrickedStream", "bricks_to_decode"]

_DONE = object()


# -- cut vertices matched by their coordinates: a hash table of their bits --------------------------
# (position-only cut sections; a dict of bytes held ~115 B per cut vertex, 17 MB on flange-10m; this
# table 20 B a slot, 5 MB there)

def _new_point_table(n: int) -> tuple[np.ndarray, np.ndarray]:
    """An empty table for ``n`` points: (bits (cap, 3) uint32, id (cap,) int64, -1 when free)."""
    cap = 1 << max(4, int(4 * n // 3).bit_length())  # more than 4 n / 3: at most 3/4 full
    return np.zeros((cap, 3), np.uint32), np.full(cap, -1, np.int64)


#: the id of a slot taken by a point of the batch being placed (its id is not known yet)
_TAKEN = -2


@njit(cache=True, nogil=True)
def _point_slots(bits, ids, keys, out, room):
    """``out[i]``: the slot of point ``keys[i]`` (coordinate bits) in the table; a point not there
    yet takes a free slot (``out[i]`` = -1 - slot), marked ``_TAKEN`` until the caller writes its id
    (so a point twice in ``keys`` finds ``_TAKEN`` the second time). Returns the points added, or
    -1 as soon as more than ``room`` would be (then the table is left as it is: the file is
    damaged). Linear probing; the table never fills: it has more slots than the file's cut
    vertices, and no more than those enter (``room``)."""
    mask = bits.shape[0] - 1
    added = 0
    for i in range(keys.shape[0]):
        h = np.uint64(keys[i, 0]) * np.uint64(0x9E3779B97F4A7C15)
        h = (h ^ np.uint64(keys[i, 1])) * np.uint64(0xC2B2AE3D27D4EB4F)
        h = (h ^ np.uint64(keys[i, 2])) * np.uint64(0x165667B19E3779F9)
        j = np.int64((h ^ (h >> np.uint64(29))) & np.uint64(mask))
        while ids[j] != -1 and not (bits[j, 0] == keys[i, 0] and bits[j, 1] == keys[i, 1] and bits[j, 2] == keys[i, 2]):
            j = (j + 1) & mask
        out[i] = j
        if ids[j] == -1:
            if added == room:
                return -1
            added += 1
            bits[j, 0] = keys[i, 0]
            bits[j, 1] = keys[i, 1]
            bits[j, 2] = keys[i, 2]
            ids[j] = _TAKEN
            out[i] = -1 - j  # a new point: its slot, marked
    return added


def _brick_range(lv: dict):
    """(lo, hi) of a brick level's stored scalar range, or None when it is absent or malformed."""
    rng = lv.get("scalar_range")
    try:
        lo, hi = (float(x) for x in rng)
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        return None
    return lo, hi


def _level_of_brick(reader: TetcReader, k: int, level: int) -> dict:
    try:
        return reader.brick(k).level_meta(level)
    except OptionError:
        stored = [lv.level for lv in reader.levels]
        raise OptionError(f"level {level} is not stored in every brick (missing in brick {k}); "
                          f"stored in all: {stored}") from None


def bricks_to_decode(reader: TetcReader, values, level: int = 0) -> list[int]:
    """The bricks of ``reader`` whose stored scalar range at ``level`` contains one of ``values``
    (a brick whose range is unknown is included), in brick order; nothing is decoded.

    Examples
    --------
    >>> import gatun_py, tempfile, os
    >>> from gatun_py.warmup import tiny_mesh
    >>> mesh = tiny_mesh()
    >>> out = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
    >>> f = gatun_py.compress(mesh, out, bricks=2, mesh_only=True, jobs=1)
    >>> lo, hi = mesh.scalar_range
    >>> bricks_to_decode(TetcReader(out), [lo - 1.0])
    []
    >>> len(bricks_to_decode(TetcReader(out), [(lo + hi) / 2])) >= 1
    True
    """
    values = [float(v) for v in values]
    out = []
    for k in range(reader.n_bricks):
        rng = _brick_range(_level_of_brick(reader, k, level))
        if rng is None or any(rng[0] <= v <= rng[1] for v in values):
            out.append(k)
    return out


class BrickedStream:
    """The batches of the bricks of ``reader`` that the isovalues cut, in one id space (see the module).

    Iterate it once; each item is a :class:`~gatun_py.mesh.TetBatch` whose tets and boundary faces
    (the mesh boundary, cut faces left out) name ids of :attr:`values`, and whose points and
    density are its new vertices ``first .. first + k - 1``.

    Attributes
    ----------
    values : (n, 4) float32
        x, y, z and the scalar of every vertex streamed so far (rows of later batches are not yet
        written; rows already written never change).
    bricks : list of int
        The bricks decoded, in stream order.
    stats : dict
        ``bricks``, ``bricks_skipped``, ``bricks_decoded``, ``jobs``, ``peak_bricks_decoding`` (at
        once), ``peak_bricks_held`` (decoded or decoding, not yet extracted), ``cut_faces_left_out``,
        ``tets``, ``points``; filled as the stream runs.

    Examples
    --------
    >>> import gatun_py, tempfile, os
    >>> from gatun_py.warmup import tiny_mesh
    >>> out = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
    >>> f = gatun_py.compress(tiny_mesh(), out, bricks=2, mesh_only=True, jobs=1)
    >>> s = BrickedStream(TetcReader(out), values=[float(np.mean(tiny_mesh().scalar_range))], jobs=2)
    >>> sum(len(b.tets) for b in s) == s.stats["tets"]
    True
    """

    def __init__(self, reader: TetcReader, *, values, level: int = 0, jobs: int | None = None):
        if reader.n_bricks < 2:
            raise OptionError("BrickedStream needs a file of two bricks or more")
        self.reader = reader
        self.level = int(level)
        self.jobs = check_jobs(jobs)
        self.bricks = bricks_to_decode(reader, values, self.level)
        self._levels = {k: _level_of_brick(reader, k, self.level) for k in self.bricks}
        self._ranges = {k: _brick_range(self._levels[k]) for k in self.bricks}
        # an upper bound of the ids (a cut vertex counts in every brick that holds it); pages of
        # np.empty are committed only when written, so the slack costs no memory
        self.values = np.empty((sum(int(lv["points"]) for lv in self._levels.values()), 4), np.float32)
        self.n = 0
        self._n_cut_total = int(reader.meta.get("cut_points", 0))
        self._cut_gid = np.full(self._n_cut_total, -1, np.int64)  # id of each file-wide cut id, once placed
        self._cut_bits, self._cut_ids = _new_point_table(self._n_cut_total)  # position-only cut sections
        self._n_placed = 0  # cut vertices in the table
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._decoding = 0
        self._iterated = False
        self.stats = {"bricks": reader.n_bricks, "bricks_skipped": reader.n_bricks - len(self.bricks),
                      "bricks_decoded": 0, "jobs": self.jobs, "peak_bricks_decoding": 0, "peak_bricks_held": 0,
                      "cut_faces_left_out": 0, "tets": sum(int(lv["tets"]) for lv in self._levels.values()),
                      "points": 0}

    def __repr__(self) -> str:
        return (f"<BrickedStream: {len(self.bricks)} of {self.reader.n_bricks} bricks, level {self.level}, "
                f"{self.jobs} jobs>")

    def __iter__(self):
        if self._iterated:
            raise RuntimeError("a BrickedStream is iterated once")
        self._iterated = True
        self._gen = self._stream()
        return self._gen

    def close(self) -> None:
        """End the iteration early: the decoding threads stop after their current batch, and are
        joined."""
        self._stop.set()
        gen = getattr(self, "_gen", None)
        if gen is not None:
            gen.close()

    # -- decoding threads --------------------------------------------------------------------------

    def _decode(self, k: int, q: queue.SimpleQueue) -> None:
        """Decode brick k into ``q``: its cut list, then (first, x y z scalar, tets, boundary) per batch."""
        with self._lock:
            self._decoding += 1
            self.stats["peak_bricks_decoding"] = max(self.stats["peak_bricks_decoding"], self._decoding)
        try:
            if self._stop.is_set():
                return
            q.put(read_cut(self.reader, k, self.level))
            for b in self.reader.brick(k).iter_decode(self.level):
                if self._stop.is_set():
                    return
                vals = np.empty((len(b.points), 4), np.float32)
                vals[:, :3] = b.points
                vals[:, 3] = b.density
                # copies: the decoder reuses its windows, and a held brick must not keep its decoder alive
                q.put((b.first, vals, np.array(b.tets, np.int32, copy=True), np.array(b.boundary, np.int32,
                                                                                      copy=True)))
            q.put(_DONE)
        except BaseException as e:  # handed to the extracting thread, which raises it
            q.put(e)
        finally:
            with self._lock:
                self._decoding -= 1

    # -- the extracting thread ---------------------------------------------------------------------

    def _stream(self):
        window = self.jobs + 1
        pending = iter(self.bricks)
        held = []  # (k, queue) of bricks submitted and not yet streamed, in brick order
        pool = ThreadPoolExecutor(self.jobs, thread_name_prefix="tetc-iso-brick")

        def submit() -> None:
            k = next(pending, None)
            if k is not None:
                q = queue.SimpleQueue()
                pool.submit(self._decode, k, q)
                held.append((k, q))
                self.stats["peak_bricks_held"] = max(self.stats["peak_bricks_held"], len(held))

        try:
            for _ in range(window):
                submit()
            while held:
                k, q = held[0]
                yield from self._brick(k, q)
                held.pop(0)
                self.stats["bricks_decoded"] += 1
                submit()
        finally:
            self._stop.set()
            pool.shutdown(wait=True, cancel_futures=True)
        self.stats["points"] = self.n

    @staticmethod
    def _get(q: queue.SimpleQueue):
        item = q.get()
        if isinstance(item, BaseException):
            raise item
        return item

    def _brick(self, k: int, q: queue.SimpleQueue):
        """Brick k's batches in the stream's ids."""
        n_k = int(self._levels[k]["points"])
        pos, cut_ids = self._get(q)
        is_cut = np.zeros(n_k, bool)
        is_cut[pos] = True
        file_id = None
        if cut_ids is not None:
            file_id = np.full(n_k, -1, np.int64)
            file_id[pos] = cut_ids
        gid = np.full(n_k, -1, np.int64)
        brick_start = self.n
        rng = self._ranges[k]
        while True:
            item = self._get(q)
            if item is _DONE:
                return
            first, vals, tets, boundary = item
            m = len(vals)
            if not 0 <= first <= n_k - m:
                raise CorruptFileError(f"corrupt file: brick {k} decodes more vertices than its index says")
            if m and rng is not None and not (rng[0] <= vals[:, 3].min() and vals[:, 3].max() <= rng[1]):
                raise CorruptFileError(f"corrupt file: brick {k} holds scalars outside the range its index "
                                       f"gives ({rng[0]:g} .. {rng[1]:g})")
            start = self.n
            gid[first:first + m] = self._place(k, vals, is_cut[first:first + m],
                                               None if file_id is None else file_id[first:first + m], brick_start)
            tets = gid[tets]
            keep = ~is_cut[boundary].all(axis=1) if len(boundary) else np.zeros(0, bool)
            self.stats["cut_faces_left_out"] += int(len(boundary) - keep.sum())
            boundary = gid[boundary[keep]]
            if (tets.size and tets.min() < 0) or (boundary.size and boundary.min() < 0):
                raise CorruptFileError(f"corrupt file: brick {k} names a vertex before it is decoded")
            yield TetBatch(start, self.values[start:self.n, :3], self.values[start:self.n, 3],
                           boundary.astype(np.int32), tets.astype(np.int32))

    def _place(self, k: int, vals: np.ndarray, cut: np.ndarray, file_id, brick_start: int) -> np.ndarray:
        """Ids of a batch's vertices: a cut vertex an earlier brick placed keeps its id (its values
        must be bit-identical), every other one takes the next id, in order; their rows written."""
        m = len(vals)
        ids = np.empty(m, np.int64)
        fresh = ~cut
        ci = np.flatnonzero(cut)
        if ci.size:
            if file_id is not None:
                g = self._cut_gid[file_id[ci]]
            else:
                keys = np.ascontiguousarray(vals[ci, :3]).view(np.uint32)
                slots = np.empty(ci.size, np.int64)
                added = _point_slots(self._cut_bits, self._cut_ids, keys, slots, self._n_cut_total - self._n_placed)
                if added < 0:
                    raise CorruptFileError("corrupt file: the bricks hold more cut vertices than the file says")
                self._n_placed += added
                fresh_slot = slots < 0
                slots[fresh_slot] = -1 - slots[fresh_slot]
                g = np.where(fresh_slot, -1, self._cut_ids[slots])
                if (g == _TAKEN).any():
                    raise CorruptFileError(f"corrupt file: two cut vertices of brick {k} have the same position")
            seen = g >= 0
            if (g[seen] >= brick_start).any():
                raise CorruptFileError(f"corrupt file: two cut vertices of brick {k} are the same vertex")
            if seen.any() and not np.array_equal(self.values[g[seen]].view(np.uint32), vals[ci[seen]].view(np.uint32)):
                raise CorruptFileError(f"corrupt file: a cut vertex differs between brick {k} and an earlier brick")
            ids[ci[seen]] = g[seen]
            fresh[ci[~seen]] = True
        n_new = int(fresh.sum())
        if self.n + n_new > len(self.values):
            raise CorruptFileError("corrupt file: the bricks decode more vertices than their index says")
        ids[fresh] = self.n + np.arange(n_new)
        self.values[self.n:self.n + n_new] = vals[fresh]
        self.n += n_new
        if ci.size:
            new_cut = ci[~seen]
            if file_id is not None:
                self._cut_gid[file_id[new_cut]] = ids[new_cut]
            else:
                self._cut_ids[slots[~seen]] = ids[new_cut]
        return ids
