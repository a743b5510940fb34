"""Reading any step of a series file (:mod:`.steps`) and coding the steps of a series.

:class:`StepDecoder` decodes a step's point arrays and coordinates (level 0's decode order),
keeping level 0's connectivity refs and positions and the last steps it decoded, so that walking
the steps decodes each one once. :meth:`StepDecoder.reader` gives a :class:`StepReader`: a
:class:`~.tetcfile.TetcReader` whose meshes and batches carry that step's values at every level
(a coarse level gathers them from level 0 through its ``L{i}/vmap``), so the simplifier, the
budget planner and the renderer work on any step unchanged.
"""

from __future__ import annotations

import numpy as np

from ..errors import CorruptFileError, MeshError, OptionError
from ..mesh import TetMesh
from ..mesh.model import scalar_of
from . import _cutborder_kernels as CK
from .arrays import ArrayDecoder, dtype_name, encode_array
from .decoded_connectivity import DecodedConnectivity
from .steps import MAX_ORDER, StepIndex, decode_step_array, encode_step_array, history_steps, step_entry
from .tetcfile import _POINTS, DEFAULT_BATCH_TETS, TetcReader, _finite_range

__all__ = ["StepDecoder", "StepReader", "step_index", "encode_steps", "encode_level_map", "CellCoding",
           "CellStepEncoder", "tet_decode_order"]

_CACHE_STEPS = MAX_ORDER + 2  # the last steps a prediction uses: a walk decodes every step once


def step_index(container) -> StepIndex:
    """The container's :class:`StepIndex`, read once (it registers appended sections)."""
    idx = getattr(container, "_step_index", None)
    if idx is None:
        idx = StepIndex(container)
        container._step_index = idx
    return idx


def _pos4(points) -> np.ndarray:
    p = np.zeros((len(points), 4), np.float32)
    p[:, :3] = np.asarray(points).astype(np.float32)
    return p


class StepDecoder:
    """Decoder of the steps of a series file (a snapshot is a series of one step).

    Parameters
    ----------
    reader : TetcReader
    cache_steps : int
        Decoded steps kept (least recently used out first; step 0 stays): at least the steps a
        prediction reaches back to, so that a walk through the steps decodes each step once.
    """

    def __init__(self, reader: TetcReader, *, cache_steps: int = _CACHE_STEPS):
        self.base = reader
        self.index = step_index(reader.container)
        self.cache_steps = max(int(cache_steps), _CACHE_STEPS)
        self._level0 = None
        self._cache = {}
        self._maps = {}
        self._points0 = None

    @property
    def n_steps(self) -> int:
        return self.index.n_steps

    @property
    def times(self) -> tuple:
        return tuple(self.index.times)

    def check_step(self, step) -> int:
        """``step`` as an index (negative from the end); :class:`OptionError` when out of range."""
        n = self.n_steps
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or not -n <= step < n:
            raise OptionError(f"step {step!r} does not exist: the file has {n} step{'s' if n > 1 else ''} "
                              f"(0..{n - 1})")
        return int(step) % n

    def step_at(self, time: float) -> int:
        """The step whose time is ``time`` (the nearest one within 1e-9 relative); OptionError otherwise."""
        t = np.asarray(self.index.times)
        k = int(np.argmin(np.abs(t - float(time))))
        if abs(t[k] - float(time)) > 1e-9 * max(1.0, abs(float(time))):
            raise OptionError(f"no step at time {time!r}: the times are {_times_text(self.index.times)}")
        return k

    def _base(self):
        """(refs, positions, n) of level 0: its connectivity refs and the geometry's coordinates."""
        if self._level0 is None:
            r = self.base
            r._one_stream()
            n = r._checked_points(0)
            conn = DecodedConnectivity(r._connectivity_decoder(0))
            geo = r._geometry_decoder(0, n)
            r._decoded = (0, conn)
            for _ in r._batches(0, max(1, conn.n_tets), {}, geometry=geo):
                pass
            refs = np.full((n, 4), -1, np.int32)
            p = np.asarray(conn.predictors)[:n]
            refs[:len(p)] = p
            self._level0 = (refs, geo.values, n)
            self._conn = conn  # replayed by every step's level-0 decode: the mesh is decoded once
            r._decoded, r._decoded_geometry = (0, conn), (0, geo.values)  # for step 0's full decode
        return self._level0

    def kept_level0(self):
        """(decoded connectivity, geometry values) of level 0, decoded once for every step."""
        self._base()
        return self._conn, self._level0[1]

    def pending(self, step: int) -> list:
        """The steps that decoding ``step`` would decode (none when it is cached), in order."""
        need, todo = [self.check_step(step)], []
        while need:  # the steps the prediction reaches back to, as far as the cache or a keyframe
            s = need.pop()
            if s in self._cache or s in todo:
                continue
            todo.append(s)
            need.extend(history_steps(self.index.entries[s]))
        return sorted(todo)

    def is_cached(self, step: int) -> bool:
        return self.check_step(step) in self._cache

    def values(self, step: int) -> dict:
        """{array name: values, ``_POINTS``: coordinates} of ``step`` in level 0's decode order."""
        k = self.check_step(step)
        if k in self._cache:
            self._cache[k] = self._cache.pop(k)  # most recently used last
            return self._cache[k]
        have = dict(self._cache)
        for s in self.pending(k):
            have[s] = self._decode(s, have)
            self._cache.pop(s, None)
            self._cache[s] = have[s]
        self._cache[k] = self._cache.pop(k)
        # least recently used out first; step 0 (a whole mesh decode) and the steps a walk from
        # ``k`` predicts from stay
        keep = {0, *range(k - MAX_ORDER - 1, k + 1)}
        for s in list(self._cache):
            if len(self._cache) <= self.cache_steps:
                break
            if s not in keep:
                del self._cache[s]
        return have[k]

    def _decode(self, k: int, have: dict) -> dict:
        refs, pos0, n = self._base()
        if k == 0:
            m = self.base.decode_mesh(0, jobs=1)
            out = dict(m.point_data)
            out[_POINTS] = m.points
            return out
        entry = self.index.entries[k]
        hist = [have[s] for s in history_steps(entry)]
        out = {}
        pos = _pos4(hist[0][_POINTS]) if hist and self._moves(entry["ref"]) else pos0
        if entry["points"]:
            out[_POINTS] = decode_step_array(
                self.base.read_section(f"S{k}/points"), refs, n_points=n, dtype=self.base.points_dtype.name,
                components=3, history=[h[_POINTS] for h in hist], positions=pos)
            pos = _pos4(out[_POINTS])
        else:
            out[_POINTS] = self.base_points()
            pos = pos0
        for j, (name, dt, c) in enumerate(self.base.arrays):
            out[name] = decode_step_array(self.base.read_section(f"S{k}/array/{j}"), refs, n_points=n,
                                          dtype=dt.name, components=c, history=[h[name] for h in hist],
                                          positions=pos)
        return out

    def base_points(self) -> np.ndarray:
        """Step 0's coordinates in level 0's decode order, without decoding its point arrays."""
        if 0 in self._cache:
            return self._cache[0][_POINTS]
        if getattr(self, "_points0", None) is None:
            refs, pos0, n = self._base()
            r = self.base
            dec = r._points_decoder(0, n)
            if dec is None:
                self._points0 = pos0[:, :3].astype(r.points_dtype)
            else:
                dec.decode(refs, np.ascontiguousarray(pos0[:, :3]), positions=pos0)
                self._points0 = dec.finish()
        return self._points0

    def _moves(self, k: int) -> bool:
        return bool(self.index.entries[k]["points"])

    def level_map(self, level: int) -> np.ndarray | None:
        """Level-0 decode id of every vertex of ``level`` (None for level 0)."""
        if level == 0:
            return None
        if level not in self._maps:
            lv = self.base.level_meta(level)
            name = f"L{level}/vmap"
            if level not in self.index.maps or not self.base.container.has_section(name):
                raise CorruptFileError(f"missing section {name!r}: a coarse level of a series maps its vertices "
                                       "to level 0's")
            n = lv.points
            dec = ArrayDecoder(self.base.read_section(name), n_points=n, dtype="int64", components=1)
            dec.decode(np.full((n, 4), -1, np.int32))  # coded without refs: no connectivity to decode
            m = dec.finish()
            n0 = self.base.level_meta(0).points
            if m.size and (int(m.min()) < 0 or int(m.max()) >= n0):
                raise CorruptFileError(f"corrupt section {name!r}: a vertex maps outside level 0")
            self._maps[level] = m
        return self._maps[level]

    # -- cell arrays -------------------------------------------------------------------------------

    @property
    def cell_arrays(self) -> list:
        """``(name, dtype, components)`` of the cell arrays every step stores (one value per tet)."""
        return list(self.index.cells)

    def cell_values(self, step) -> dict:
        """{name: values} of ``step``'s cell arrays, one row per tet of level 0 in decode order
        (the rows of :meth:`~.tetcfile.TetcReader.decode_mesh`'s tets), bit for bit."""
        k = self.check_step(step)
        if not self.index.cells:
            return {}
        cache = self.__dict__.setdefault("_cell_cache", {})
        if k in cache:
            return cache[k]
        need, todo = [k], []
        while need:
            s = need.pop()
            if s in cache or s in todo:
                continue
            todo.append(s)
            need.extend(history_steps(self.index.entries[s]))
        coding = self._cell_coding()
        for s in sorted(todo):
            hist = [cache[h] for h in history_steps(self.index.entries[s])]
            cache[s] = {name: coding.decode(self.base.read_section(f"S{s}/cell/{j}"), dt, c,
                                            history=[h[name] for h in hist])
                        for j, (name, dt, c) in enumerate(self.index.cells)}
        keep = {*range(k - MAX_ORDER - 1, k + 1)}
        for s in [s for s in cache if s not in keep]:
            if len(cache) <= self.cache_steps:
                break
            del cache[s]
        return cache[k]

    def _cell_coding(self) -> "CellCoding":
        if getattr(self, "_cells_coding", None) is None:
            conn, _ = self.kept_level0()
            self._cells_coding = CellCoding(conn.tets, self._level0[1])
        return self._cells_coding

    def reader(self, step) -> TetcReader:
        """A reader of ``step`` (the base reader itself for step 0)."""
        k = self.check_step(step)
        return self.base if k == 0 else StepReader(self, k)


def _times_text(times) -> str:
    t = list(times)
    shown = ", ".join(f"{x:g}" for x in (t if len(t) <= 8 else t[:4] + t[-2:]))
    return shown if len(t) <= 8 else shown.replace(f"{t[3]:g}, ", f"{t[3]:g}, ..., ", 1)


class StepReader(TetcReader):
    """A :class:`TetcReader` of one step of a series: meshes, batches and ranges carry the step's
    coordinates and point arrays; the connectivity, forests and levels are step 0's."""

    def __init__(self, steps: StepDecoder, step: int):
        self.__dict__.update({k: v for k, v in steps.base.__dict__.items()
                              if k not in ("_decoded", "_decoded_geometry")})
        self.steps, self.step = steps, step
        vals = steps.values(step)
        meta = dict(steps.base.meta)
        pts = vals[_POINTS]
        meta["bbox"] = [pts.min(axis=0).tolist(), pts.max(axis=0).tolist()] if len(pts) else meta["bbox"]
        s = vals[self.scalar_name]
        meta["scalar_range"] = _finite_range(s)
        arrays = []
        for e in meta.get("arrays", []):
            e = dict(e)
            a = vals.get(e.get("name"))
            if a is not None:
                if a.ndim == 1:
                    e["range"] = _finite_range(a)
                else:
                    e["range"] = _finite_range(np.sqrt((a.astype(np.float64) ** 2).sum(axis=1)))
                    e["component_ranges"] = [_finite_range(a[:, c]) for c in range(a.shape[1])]
            arrays.append(e)
        meta["arrays"] = arrays
        self.meta = meta

    def _keep(self, level: int) -> None:
        """Level 0's batches replay the connectivity and geometry the steps were decoded with."""
        if level == 0:
            conn, geo = self.steps.kept_level0()
            self._decoded, self._decoded_geometry = (0, conn), (0, geo)

    def _gather(self, level: int, first: int, count: int) -> dict:
        vals = self.steps.values(self.step)
        m = self.steps.level_map(level)
        ids = slice(first, first + count) if m is None else m[first:first + count]
        return {key: a[ids] for key, a in vals.items()}

    def iter_decode(self, level: int = 0, *, scalar: str | None = None, component=None,
                    batch_tets: int = DEFAULT_BATCH_TETS, jobs: int = 1, depth: int = 4):
        names = [a[0] for a in self.arrays]
        name = self.scalar_name if scalar is None else scalar
        if name not in names:
            raise OptionError(f"no point array named {scalar!r}; arrays: {', '.join(map(repr, names))}")
        self._keep(level)
        for batch, _ in TetcReader._batches(self, level, batch_tets, {}, jobs=1):
            k = len(batch.points)
            got = self._gather(level, batch.first, k)
            batch.points = got[_POINTS].astype(np.float32)
            with np.errstate(over="ignore"):
                batch.density = scalar_of(got, name, component).astype(np.float32)
            yield batch

    def decode_mesh(self, level: int = 0, *, jobs: int | None = None):
        lv = self.level_meta(level)
        if level == 0:  # the connectivity the steps were decoded with
            self._one_stream()
            tets = self.steps.kept_level0()[0].tets
        else:
            tets = np.empty((lv.tets, 4), np.int32)
            for _ in TetcReader._batches(self, level, DEFAULT_BATCH_TETS, {}, tets_out=tets):
                pass
        got = self._gather(level, 0, lv.points)
        points = got.pop(_POINTS)
        data = {name: got[name] for name, _, _ in self.arrays}
        try:
            return TetMesh(points, data[self.scalar_name].astype(np.float32), tets, self.scalar_name, point_data=data)
        except Exception as e:
            raise CorruptFileError(f"corrupt file: decoded mesh of step {self.step} is invalid ({e})") from None


# -- coding ------------------------------------------------------------------------------------------

class CellCoding:
    """How a step's cell arrays (one value per tet) are coded: in level 0's tet decode order, each
    tet predicted from its earlier face neighbours (up to four, latest first; the previous tet
    when it has none), the linear predictor evaluated at the tets' centres in step 0's float32
    coordinates, after the temporal prediction of :func:`~.steps.encode_step_array`.

    Parameters
    ----------
    tets : (m, 4) int
        Level 0's tets in decode order and decode ids.
    positions : (n, 4) float32
        Step 0's coordinates in decode order (the geometry's float32 values).
    """

    def __init__(self, tets, positions):
        t = np.ascontiguousarray(tets, np.int32)
        m = len(t)
        self.n = m
        nbr = np.full((m, 4), -1, np.int32)
        if m and CK.tet_neighbours(t, nbr):
            raise CorruptFileError("corrupt file: a face is shared by more than two tets")
        i = np.arange(m, dtype=np.int64)[:, None]
        earlier = np.where((nbr >= 0) & (nbr < i), nbr, -1)
        refs = -np.sort(-earlier, axis=1)  # latest first, none (-1) last
        lone = np.flatnonzero(refs[:, 0] < 0)
        lone = lone[lone > 0]
        refs[lone, 0] = lone - 1
        self.refs = np.ascontiguousarray(refs, np.int32)
        pos = np.asarray(positions, np.float32)[:, :3]
        cent = np.zeros((m, 4), np.float32)
        if m:
            # summed in vertex id order: the same bits whichever way round a tet's rows hold them
            cent[:, :3] = (pos[np.sort(t, axis=1)].astype(np.float64).sum(axis=1) / 4).astype(np.float32)
        self.centres = cent

    def encode(self, values, history=()) -> bytes:
        return encode_step_array(values, self.refs, history=history, positions=self.centres[:, :3])

    def decode(self, data, dtype, components: int, history=()) -> np.ndarray:
        return decode_step_array(data, self.refs, n_points=self.n, dtype=dtype.name, components=components,
                                 history=history, positions=self.centres)


def tet_decode_order(mesh_tets, vertex_order, decoded_tets) -> np.ndarray:
    """Input index of every decoded tet: the decoded tets (decode ids) matched to the input's
    tets (input ids, mapped through ``vertex_order``) by their vertex sets."""
    vo = np.asarray(vertex_order, np.int64)
    a = np.sort(vo[np.asarray(decoded_tets, np.int64)], axis=1)
    b = np.sort(np.asarray(mesh_tets, np.int64), axis=1)
    ka, kb = np.lexsort(a.T[::-1]), np.lexsort(b.T[::-1])
    if len(a) != len(b) or not np.array_equal(a[ka], b[kb]):
        raise RuntimeError("the connectivity coder's tets are not the mesh's")
    out = np.empty(len(a), np.int64)
    out[ka] = kb
    return out


def cell_arrays_meta(cell_data: dict, n_tets: int, k: int = 0) -> list:
    """``[(name, dtype, components)]`` of one step's cell arrays (one row per tet), checked."""
    out = []
    for name, a in cell_data.items():
        a = np.asarray(a)
        if a.ndim not in (1, 2) or a.shape[0] != n_tets:
            raise MeshError(f"step {k}: cell array {name!r} has shape {a.shape}, not one row per tet ({n_tets})")
        out.append((str(name), dtype_name(a.dtype), 1 if a.ndim == 1 else int(a.shape[1])))
    return out


class CellStepEncoder:
    """Codes the ``S{k}/cell/{j}`` sections of the steps given to :meth:`step`, in step order.

    Parameters
    ----------
    coding : CellCoding
    tet_order : (m,) int
        Input index of every decoded tet (:func:`tet_decode_order`).
    interval : int
        The file's keyframe interval.
    arrays : list of (name, dtype name, components), optional
        The cell arrays every step must have (default: the first step's).
    previous : callable, optional
        ``previous(k)``: the cell values (decode order) of a step before the first one given.
    """

    def __init__(self, coding: CellCoding, tet_order, *, interval: int, arrays=None, previous=None):
        self.coding, self.order, self.interval = coding, np.asarray(tet_order), int(interval)
        self.arrays = None if arrays is None else list(arrays)
        self.previous = previous
        self.held = {}

    def step(self, k: int, cell_data: dict) -> list:
        """The sections of step ``k`` from ``{name: (m,) or (m, c) array}`` in the input's tet order."""
        meta = cell_arrays_meta(cell_data, self.coding.n, k)
        if self.arrays is None:
            self.arrays = meta
        if meta != self.arrays:
            raise MeshError(f"step {k}: cell arrays {meta} differ from step 0's {self.arrays}")
        vals = {name: np.ascontiguousarray(np.asarray(cell_data[name])[self.order]) for name, _, _ in self.arrays}
        hist = [self.held[s] if s in self.held else self.previous(s)
                for s in history_steps(step_entry(k, self.interval))]
        out = [(f"S{k}/cell/{j}", self.coding.encode(vals[name], history=[h[name] for h in hist]))
               for j, (name, _, _) in enumerate(self.arrays)]
        self.held[k] = vals
        for s in [s for s in self.held if s <= k - MAX_ORDER - 1]:
            del self.held[s]
        return out


def encode_level_map(ids: np.ndarray) -> bytes:
    """The ``L{i}/vmap`` section: every level vertex's level-0 decode id (level decode order),
    predicted from the previous vertex's (both orders follow the connectivity's traversal)."""
    ids = np.asarray(ids, np.int64)
    return encode_array(ids, np.full((len(ids), 4), -1, np.int32))


def encode_steps(meshes, vertex_order, refs, base_points, *, first: int = 1, interval: int, previous=None):
    """The entries and sections of steps ``first, first + 1, ...`` (``meshes``, already checked
    against step 0).

    Parameters
    ----------
    meshes : iterable of TetMesh
        The steps to code, in order (input vertex order, step 0's topology).
    vertex_order : (n,) array
        Level 0's decode order (decode id -> input id).
    refs : (n, 4) int32
        Level 0's refs.
    base_points : (n, 3) array
        Step 0's coordinates in decode order.
    first : int
        The step number of the first mesh.
    interval : int
        Keyframe interval.
    previous : callable
        ``previous(k)``: the values dict (decode order, with ``_POINTS``) of an earlier step ``k``
        that comes before ``meshes`` (step 0, or the keyframe of an appended step).

    Yields
    ------
    (entry, sections) per step
    """
    vo = np.asarray(vertex_order)
    held = {}
    base_pos = _pos4(base_points)[:, :3]
    base_bits = np.ascontiguousarray(base_points).view(np.uint8)
    for i, mesh in enumerate(meshes):
        k = first + i
        pts = np.ascontiguousarray(mesh.points[vo])
        vals = {name: np.ascontiguousarray(mesh.point_data[name][vo]) for name in mesh.point_data}
        vals[_POINTS] = pts
        entry = step_entry(k, interval)
        hist = [held[s] if s in held else previous(s) for s in history_steps(entry)]
        moves = not np.array_equal(pts.view(np.uint8), base_bits)
        ref_moves = bool(hist) and not np.array_equal(hist[0][_POINTS].view(np.uint8), base_bits)
        pos = _pos4(hist[0][_POINTS])[:, :3] if ref_moves else base_pos
        sections = []
        if moves:
            sections.append((f"S{k}/points", encode_step_array(pts, refs, positions=pos,
                                                               history=[h[_POINTS] for h in hist])))
            pos = _pos4(pts)[:, :3]
        else:
            pos = base_pos
        for j, name in enumerate(mesh.point_data):
            sections.append((f"S{k}/array/{j}", encode_step_array(vals[name], refs, positions=pos,
                                                                  history=[h[name] for h in hist])))
        held[k] = vals
        for s in [s for s in held if s <= k - MAX_ORDER - 1]:
            del held[s]
        entry["points"] = bool(moves)
        yield entry, sections
