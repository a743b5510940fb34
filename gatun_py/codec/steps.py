"""Time series in a ``.tetc`` file: the steps after the first, each step's point arrays and moving
coordinates, coded against an earlier step, and steps appended to a written file.

A series file is an ordinary ``.tetc`` file of its first step (step 0: connectivity, boundary,
geometry, point arrays, forest and levels, all built on step 0; the forest on step 0's default
scalar) plus, under the metadata key ``"steps"``:

* ``times``: the time of every step of the base file; ``entries``: per step ``{"ref", "points"}``,
  the step it is predicted from (-1: none) and whether it stores its own coordinates;
* ``keyframe_interval`` K: the steps ``k`` with ``k % K == 0`` are coded on their own (spatial
  prediction only), every other step from the steps before it back to its keyframe (at most
  ``MAX_ORDER + 1`` of them), so that any step decodes from at most K coded steps (random access);
* ``mesh`` and ``points``: digests of step 0's tets and coordinates (input order), which an append
  checks a new step against without decoding anything;
* ``maps``: the levels that hold an ``L{i}/vmap`` section, each vertex's level-0 decode id: a
  coarse level gets a step's values by gathering them from level 0.

Sections of step ``k >= 1``: ``S{k}/array/{j}`` for every point array j of the metadata's
``arrays``, ``S{k}/points`` when the step's coordinates differ from step 0's; and, when the
metadata's ``cells`` lists cell arrays (``{"name", "dtype", "components"}``, one row per tet),
``S{k}/cell/{j}`` for every step, step 0 included, in level 0's tet decode order, each tet
predicted from its earlier face neighbours at the tets' centres
(:class:`~.stepreader.CellCoding`) after the same temporal prediction as a point array (a reader
without cell arrays decodes every other section of such a file as before); every one in level
0's decode order, each a byte (the mode) and an array block of :mod:`.arrays`: mode 0 codes the
values (spatial predictors), mode ``1 + p`` the difference of their ordered integers
(:func:`ordered`) to those of :func:`extrapolate` of degree p from the previous steps, modulo
2**64, as an int64 array (spatial predictors on the temporal difference). The encoder picks p by
the residuals' mean bit length and keeps the smaller mode. The arrays of a step with its own coordinates are
predicted with those coordinates (float32); its coordinates with the reference step's.

Appended steps (:func:`append_block`) follow the last section of the base file, each a block::

    8s  magic b"TETCSTEP"
    u32 J, u32 CRC32 of the next 8 + J bytes, u64 B (bytes after this 24-byte header)
    J   bytes of JSON {"time", "ref", "points", "sections": [{"name", "offset", "length", "crc32"}]}
        (offsets from the file start)
    ... the step's sections, as records of the container

A reader takes blocks while they are whole and their header checks; an incomplete last block (an
append that was interrupted) is ignored, and the next append cuts it off first.
"""

from __future__ import annotations

import hashlib
import json
import math
import struct
import zlib

import numpy as np

from ..errors import CorruptFileError, MeshError, OptionError
from .arrays import MAX_COMPONENTS, ArrayDecoder, check_dtype, dtype_name, encode_array
from .container import _record

__all__ = ["STEP_MAGIC", "encode_step_array", "decode_step_array", "ordered", "mesh_digest", "points_digest",
           "StepIndex", "append_block", "step_entry", "history_steps", "extrapolate"]

STEP_MAGIC = b"TETCSTEP"
_BLOCK = struct.Struct("<8sIIQ")
MODE_VALUES, MODE_TEMPORAL = 0, 1
DEFAULT_KEYFRAME_INTERVAL = 16
MAX_STEPS = 1 << 20
MAX_BLOCK_JSON = 1 << 20


MAX_ORDER = 6  # heat conduction gains up to order 6 (bench/sections/series.md)


def step_entry(k: int, interval: int) -> dict:
    """How step ``k`` is predicted: ``ref`` the previous step (-1: a keyframe, coded alone) and
    ``order``: the steps ``ref, ..., ref - order`` its sections may be predicted from (each
    section's mode says the degree it uses), never reaching before its keyframe ``k - k % interval``."""
    back = k % interval
    return {"ref": -1 if back == 0 else k - 1, "order": max(0, min(MAX_ORDER, back - 1))}


def history_steps(entry: dict) -> list:
    """The steps a step's prediction uses, latest first."""
    return [] if entry["ref"] < 0 else [entry["ref"] - i for i in range(entry["order"] + 1)]


def keyframe_interval_for(n_points: int, n_tets: int, values_per_step: int) -> int:
    """A keyframe interval that keeps decoding any step within about 1.5x decoding step 0: a step
    decodes its keyframe and the steps after it, each about as costly per value as step 0's arrays,
    while step 0 also decodes the mesh (connectivity and geometry, about as costly as 2.5 values per
    tet: bench/sections/series.md)."""
    mesh = 2.5 * n_tets
    v = max(1, int(values_per_step))
    return int(min(16, max(1, (0.5 * mesh + 1.5 * v) // v)))


def mesh_digest(n_points: int, tets: np.ndarray) -> str:
    """A digest of a topology (point count and tets as int32, in input order)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(struct.pack("<Q", int(n_points)))
    h.update(np.ascontiguousarray(tets, np.int32).tobytes())
    return h.hexdigest()


def points_digest(points: np.ndarray) -> str:
    """A digest of the coordinates' bits (input order)."""
    a = np.ascontiguousarray(points)
    return hashlib.blake2b(a.dtype.str.encode() + a.tobytes(), digest_size=16).hexdigest()


def ordered(values: np.ndarray) -> np.ndarray:
    """Ordered integers of an array's values as int64 (n, k): a float's sign and magnitude bits
    folded so that integer order is float order, an integer its value (uint64 its bits)."""
    v = np.asarray(values)
    n = v.shape[0]
    v = v.reshape(n, -1)
    if v.dtype.kind == "f":
        bits = 64 if v.dtype.itemsize == 8 else 32
        raw = v.view(np.int64 if bits == 64 else np.int32).astype(np.int64)
        m = raw & ((1 << (bits - 1)) - 1)
        return np.where(raw < 0, ~m, m)
    if v.dtype == np.uint64:
        return v.view(np.int64).astype(np.int64)
    return v.astype(np.int64)


def _unordered(o: np.ndarray, dt: np.dtype, shape: tuple) -> np.ndarray:
    """Inverse of :func:`ordered` into an array of dtype ``dt`` and ``shape``."""
    if dt.kind == "f":
        neg = o < 0
        m = np.where(neg, ~o, o)
        if dt.itemsize == 8:
            u = m.astype(np.uint64) | (neg.astype(np.uint64) << np.uint64(63))
            out = u.view(np.float64)
        else:
            u = (m | (neg.astype(np.int64) << 31)).astype(np.uint32)
            out = u.view(np.float32)
    elif dt == np.uint64:
        out = o.view(np.uint64)
    else:
        out = o.astype(dt)
    return out.astype(dt, copy=False).reshape(shape)


def extrapolate(history, order: int | None = None) -> np.ndarray:
    """The temporal prediction of a step from the steps before it (``history``: the previous
    step's array first): the polynomial of degree ``order`` (default: ``len(history) - 1``)
    through the last ``order + 1`` steps at equal time spacing, at the next step,
    ``sum_i (-1)^i C(order + 1, i + 1) h_i`` (``h_0``; ``2 h_0 - h_1``; ``3 h_0 - 3 h_1 + h_2``; ...).
    Floats are extrapolated in float64, term by term in that order, and rounded to their dtype;
    integers modulo 2**64. Any result (inf, NaN) is a valid prediction.

    Examples
    --------
    >>> import numpy as np
    >>> h = [np.array([16.0]), np.array([9.0]), np.array([4.0]), np.array([1.0])]  # t^2 at t = 4, 3, 2, 1
    >>> [float(extrapolate(h, p)[0]) for p in range(4)]
    [16.0, 23.0, 25.0, 25.0]
    """
    h = [np.asarray(a) for a in history]
    p = len(h) - 1 if order is None else int(order)
    if not 0 <= p < len(h):
        raise ValueError(f"order {p} needs {p + 1} previous steps, {len(h)} given")
    dt = h[0].dtype
    if p == 0:
        return h[0]
    coef = [(-1) ** i * math.comb(p + 1, i + 1) for i in range(p + 1)]
    with np.errstate(over="ignore", invalid="ignore"):
        if dt.kind == "f":
            acc = coef[0] * h[0].astype(np.float64)
            for c, a in zip(coef[1:], h[1:]):
                acc = acc + c * a.astype(np.float64)
            return acc.astype(dt)
        ints = [a.view(np.int64) if dt == np.uint64 else a.astype(np.int64) for a in h[:p + 1]]
        acc = np.int64(coef[0]) * ints[0]
        for c, a in zip(coef[1:], ints[1:]):
            acc = acc + np.int64(c) * a
        return acc.view(np.uint64) if dt == np.uint64 else acc.astype(dt)


def _zigzag_bits(d: np.ndarray) -> float:
    """Mean bit length of zigzagged residuals: a cheap estimate of what they code to."""
    u = (d.view(np.uint64) << np.uint64(1)) ^ (d >> 63).view(np.uint64)
    return float(np.mean(np.log2(u.astype(np.float64) + 1.0))) if u.size else 0.0


def encode_step_array(values, refs, *, history=(), positions=None) -> bytes:
    """One step's array (decode order) as a step section: the values on their own (spatial
    predictors), or their difference to :func:`extrapolate` of ``history`` (the same array of the
    previous steps, latest first) at the order whose differences are smallest, whichever codes
    smaller.

    Examples
    --------
    >>> import numpy as np
    >>> refs = np.array([[-1] * 4, [0, -1, -1, -1], [0, 1, -1, -1]], np.int32)
    >>> a, b = np.array([1.5, 2.5, -0.0]), np.array([1.25, 2.75, np.nan])
    >>> data = encode_step_array(b, refs, history=[a])
    >>> out = decode_step_array(data, refs, n_points=3, dtype="float64", components=1, history=[a])
    >>> out.view(np.int64).tolist() == b.view(np.int64).tolist()
    True
    """
    values = np.asarray(values)
    best = bytes([MODE_VALUES]) + encode_array(values, refs, positions=positions)
    if len(history):
        for a in history:
            if np.asarray(a).dtype != values.dtype or np.asarray(a).shape != values.shape:
                raise ValueError("a previous step's array has another dtype or shape")
        ov = ordered(values)
        cands = []
        with np.errstate(over="ignore"):
            for p in range(min(len(history), MAX_ORDER + 1)):
                d = ov - ordered(extrapolate(history, p))  # modulo 2**64
                cands.append((_zigzag_bits(d), p, d))
        _, p, delta = min(cands, key=lambda c: c[:2])
        delta = delta.reshape(-1) if values.ndim == 1 else delta
        tmp = bytes([MODE_TEMPORAL + p]) + encode_array(delta, refs, positions=positions)
        if len(tmp) < len(best):
            best = tmp
    return best


def decode_step_array(data, refs, *, n_points: int, dtype: str, components: int, history=(),
                      positions=None) -> np.ndarray:
    """Inverse of :func:`encode_step_array`: the step's array in decode order, bit for bit.

    ``refs``: the level-0 refs of every vertex; ``positions``: (n, 4) float32 when the coder's
    linear predictor may need them; ``history``: the previous steps' arrays, as coded (mode 1)."""
    data = bytes(data)
    if len(data) < 1 or data[0] > MODE_TEMPORAL + MAX_ORDER:
        raise CorruptFileError("corrupt step section: unknown mode")
    dt = check_dtype(dtype)
    refs = np.ascontiguousarray(refs, np.int32)
    temporal = data[0] >= MODE_TEMPORAL
    order = data[0] - MODE_TEMPORAL
    if temporal and order >= len(history):
        raise CorruptFileError(f"corrupt step section: predicted from {order + 1} earlier steps, the step has "
                               f"{len(history)}")
    dec = ArrayDecoder(data[1:], n_points=n_points, dtype="int64" if temporal else dtype, components=components)
    if dec.needs_external():
        raise CorruptFileError("corrupt step section: external prediction in a step section")
    pos = None if positions is None else np.ascontiguousarray(positions, np.float32)
    dec.decode(refs, None, positions=pos)
    out = dec.finish()
    shape = (n_points,) if components == 1 else (n_points, components)
    if not temporal:
        return out.astype(dt, copy=False).reshape(shape)
    if any(np.asarray(a).shape != shape or np.asarray(a).dtype != dt for a in history):
        raise CorruptFileError("corrupt step section: the previous steps' arrays do not match")
    with np.errstate(over="ignore"):
        o = ordered(extrapolate(history, order)) + out.reshape(n_points, components).astype(np.int64)
    return _unordered(o, dt, shape)


# -- the step index: the base file's steps and the appended ones ------------------------------------

def _number(v, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise CorruptFileError(f"corrupt metadata: bad {what}")
    return float(v)


def _entry(e, k: int) -> dict:
    if not isinstance(e, dict):
        raise CorruptFileError(f"corrupt metadata: bad entry of step {k}")
    ref, order, pts = e.get("ref"), e.get("order", 0), e.get("points")
    ints = all(isinstance(x, int) and not isinstance(x, bool) for x in (ref, order))
    if not ints or not -1 <= ref < k or not 0 <= order <= MAX_ORDER or ref - order < -1 or ref == -1 and order \
            or not isinstance(pts, bool):
        raise CorruptFileError(f"corrupt metadata: bad reference of step {k}")
    return {"ref": ref, "order": order, "points": pts}


def _cell_arrays(entries) -> list:
    """``(name, dtype, components)`` of the metadata's per-step cell arrays."""
    if not isinstance(entries, list):
        raise CorruptFileError("corrupt metadata: bad step cell arrays")
    out = []
    for e in entries:
        try:
            name, dt, c = e["name"], check_dtype(e["dtype"]), e["components"]
        except (TypeError, KeyError, ValueError, OptionError):
            raise CorruptFileError("corrupt metadata: bad step cell array") from None
        if not isinstance(name, str) or isinstance(c, bool) or not isinstance(c, int) or not 1 <= c <= MAX_COMPONENTS:
            raise CorruptFileError("corrupt metadata: bad step cell array")
        out.append((name, dt, c))
    return out


class StepIndex:
    """The steps of a file: times, references, which ones store coordinates, and the sections of
    appended steps (registered in the container's index, so they read like any section).

    Attributes
    ----------
    times : list of float
    entries : list of dict
        ``{"ref", "points"}`` per step (step 0: ``{"ref": -1, "points": False}``).
    cells : list of (name, dtype, components)
        The cell arrays every step stores (``S{k}/cell/{j}``, step 0 included; one row per tet).
    end : int
        The file offset after the last whole step (where the next append goes).
    """

    def __init__(self, container):
        meta = container.meta
        info = meta.get("steps")
        self.series = info is not None
        if info is None:
            self.times, self.entries, self.interval = [0.0], [{"ref": -1, "order": 0, "points": False}], 1
            self.mesh_digest = self.points_digest = None
            self.maps = []
            self.cells = []
        else:
            if container.major < 10:
                raise CorruptFileError("corrupt metadata: steps in a file of format 9 or older")
            if not isinstance(info, dict):
                raise CorruptFileError("corrupt metadata: bad 'steps' entry")
            times, entries = info.get("times"), info.get("entries")
            if not isinstance(times, list) or not isinstance(entries, list) or not 1 <= len(times) <= MAX_STEPS \
                    or len(entries) != len(times):
                raise CorruptFileError("corrupt metadata: bad step list")
            self.times = [_number(t, "step time") for t in times]
            self.entries = [_entry(e, k) for k, e in enumerate(entries)]
            if self.entries[0] != {"ref": -1, "order": 0, "points": False}:
                raise CorruptFileError("corrupt metadata: step 0 is the base mesh")
            iv = info.get("keyframe_interval")
            if isinstance(iv, bool) or not isinstance(iv, int) or not 1 <= iv <= MAX_STEPS:
                raise CorruptFileError("corrupt metadata: bad keyframe interval")
            self.interval = iv
            self.mesh_digest, self.points_digest = info.get("mesh"), info.get("points")
            maps = info.get("maps", [])
            if not isinstance(maps, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in maps):
                raise CorruptFileError("corrupt metadata: bad level maps")
            self.maps = maps
            self.cells = _cell_arrays(info.get("cells", []))
        # a brick's view of a bricked file has no index of its own (and no steps: a series is one stream)
        index = getattr(container, "index", None) or {}
        self.end = max([off + length for off, length, _ in index.values()]
                       + [container.base_end if hasattr(container, "base_end") else 0])
        if self.series:
            self._read_appended(container)
        for k in range(1, len(self.times)):
            if not self.times[k] > self.times[k - 1]:
                raise CorruptFileError(f"corrupt metadata: the time of step {k} does not follow step {k - 1}'s")

    @property
    def n_steps(self) -> int:
        return len(self.times)

    def _read_appended(self, container) -> None:
        pos = self.end
        while pos + _BLOCK.size <= container.size and len(self.times) < MAX_STEPS:
            head = container._read(pos, _BLOCK.size)
            magic, jlen, crc, blen = _BLOCK.unpack(head)
            if magic != STEP_MAGIC or jlen > MAX_BLOCK_JSON or jlen > blen or pos + _BLOCK.size + blen > container.size:
                break  # an interrupted append (or nothing): the steps so far are the file's
            blob = container._read(pos + _BLOCK.size, jlen)
            if zlib.crc32(head[8:12] + head[16:24] + blob) != crc:
                break
            try:
                e = json.loads(blob.decode("utf-8"))
            except (UnicodeDecodeError, ValueError, RecursionError):
                break
            k = len(self.times)
            start, stop = pos + _BLOCK.size + jlen, pos + _BLOCK.size + blen
            if not isinstance(e, dict) or not isinstance(e.get("sections"), list):
                raise CorruptFileError(f"{container.name}: corrupt appended step {k}")
            entry = _entry(e, k)
            t = _number(e.get("time"), f"time of step {k}")
            found = {}
            for s in e["sections"]:
                try:
                    name, off, length, c = s["name"], s["offset"], s["length"], s["crc32"]
                except (TypeError, KeyError):
                    raise CorruptFileError(f"{container.name}: corrupt appended step {k}") from None
                ints = all(isinstance(x, int) and not isinstance(x, bool) for x in (off, length, c))
                if not (isinstance(name, str) and name.startswith(f"S{k}/") and ints) or name in found \
                        or off < start or length < 0 or off + length > stop or not 0 <= c < 2 ** 32:
                    raise CorruptFileError(f"{container.name}: corrupt section index of appended step {k}")
                found[name] = (off, length, c)
            if not t > self.times[-1]:
                raise CorruptFileError(f"{container.name}: appended step {k} goes back in time")
            container.index.update(found)
            self.times.append(t)
            self.entries.append(entry)
            pos = stop
        self.end = pos


def append_block(k: int, time: float, entry: dict, sections: list, offset: int) -> bytes:
    """The bytes of appended step ``k`` at file ``offset``: header, JSON index, section records."""
    records = [(name, _record(name, bytes(p))) for name, p in sections]
    jlen = 0
    for _ in range(8):  # the offsets in the JSON depend on its length
        off = offset + _BLOCK.size + jlen
        index = []
        for (name, payload), (_, rec) in zip(sections, records):
            index.append({"name": name, "offset": off + len(rec) - len(payload), "length": len(payload),
                          "crc32": zlib.crc32(payload)})
            off += len(rec)
        blob = json.dumps({"time": float(time), "ref": int(entry["ref"]), "order": int(entry["order"]),
                           "points": bool(entry["points"]),
                           "sections": index}, separators=(",", ":")).encode()
        if len(blob) == jlen:
            break
        jlen = len(blob)
    body = blob + b"".join(rec for _, rec in records)
    lens = struct.pack("<I", len(blob)), struct.pack("<Q", len(body))
    crc = zlib.crc32(lens[0] + lens[1] + blob)
    return _BLOCK.pack(STEP_MAGIC, len(blob), crc, len(body)) + body


def check_step_mesh(mesh0, mesh, k: int, source: str = "") -> None:
    """Raise :class:`MeshError` naming step ``k`` unless ``mesh`` has step 0's points, tets and
    point arrays (names, dtypes, components); its coordinates and values may differ."""
    where = f"step {k}" + (f" ({source})" if source else "")
    if mesh.n_points != mesh0.n_points or mesh.n_tets != mesh0.n_tets \
            or not np.array_equal(mesh.tets, mesh0.tets):
        raise MeshError(f"{where}: the mesh differs from step 0's ({mesh.n_points} points, {mesh.n_tets} tets "
                        f"against {mesh0.n_points} and {mesh0.n_tets}, or other tets): a series keeps one topology (the pieces of one mesh are compressed "
                        "with --pieces, gatun_py.compress_pieces)")
    if mesh.points.dtype != mesh0.points.dtype:
        raise MeshError(f"{where}: coordinates are {mesh.points.dtype}, step 0's {mesh0.points.dtype}")
    a0 = [(n, dtype_name(d), c) for n, d, c in mesh0.arrays]
    a1 = [(n, dtype_name(d), c) for n, d, c in mesh.arrays]
    if a0 != a1 or mesh.scalar_name != mesh0.scalar_name:
        raise MeshError(f"{where}: point arrays {a1} differ from step 0's {a0}")


def check_times(times) -> list:
    """Times as floats, strictly increasing; :class:`OptionError` naming the first one that is not."""
    out = []
    for k, t in enumerate(times):
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not np.isfinite(t):
            raise OptionError(f"time of step {k} must be a finite number, got {t!r}")
        out.append(float(t))
        if k and not out[k] > out[k - 1]:
            raise OptionError(f"times go backwards: step {k} has time {out[k]!r}, step {k - 1} {out[k - 1]!r}")
    return out
