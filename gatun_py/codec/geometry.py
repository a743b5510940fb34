"""Lossless coding of vertex coordinates and density in decode order.

The connectivity coder introduces vertices one at a time and, for each new vertex ``k``, knows a
few already decoded vertices close to it: ``refs[k] = (a, b, c, d)``, decode ids ``< k`` or ``-1``.

* ``(a, b, c)`` is the face the new vertex closes (an interior vertex is the fourth vertex of
  the tet behind a cut-border face); a boundary vertex is attached across an edge: ``(u, v, -1)``.
* ``d`` is the *apex* behind that face: the fourth vertex of the already decoded tet that owns
  the face, or the third vertex of the boundary triangle across the edge; ``-1`` if there is none.

Refs of shape ``(n, 3)`` are accepted too (no apex), at some cost in compression.

Every float comes back bit for bit (``-0.0``, denormals, any magnitude; even NaN/inf bit patterns,
although validation keeps those out of meshes). The model, per vertex and per channel (x, y, z,
density), is described in :mod:`gatun_py.codec._geometry_kernels`: a cheap symbol for "equal to a
ref's value" (y also "equal to the y last seen with this x"), otherwise a backward-adaptively
chosen linear prediction from the refs and from grid-line partners the coder finds in its own edge
graph (coding 2 adds predictions from the tet's geometry: the density as the linear field through
the ref tet at the vertex's decoded position, the coordinates beyond the face or edge), with an exact integer residual, either on the order-preserving integer of the float bits or
on the rank in a table of the channel's distinct values (chosen per channel, whichever is smaller).

The decoder keeps, besides the vertex table (16 bytes per vertex), its edge graph (36 bytes per
vertex), the x -> y table (codings 1-2: 18 to 36 bytes per vertex; coding 3: a 72 KB cache,
or nothing where the block does without it) and, coding 5 with rank steps, every vertex's ranks
(16 bytes per vertex).

Byte layout of the geometry block (little endian)::

    u8  coding      1 (format <= 3), 2 (format 4: adds the tet-geometry predictors), 3
                    (formats 5-7: the same model, decoded with fewer range-coder steps), 4
                    (format 8: coding 3's model, the value tables apart and chained across levels)
                    or 5 (format 9: coding 4 with rank steps)
    u8  modes       bit ch set (ch < 4): channel ch uses the value table; bit 4 (codings 3
                    to 5): y uses the x -> y table (codings 1-2 always do)
    u32 n_points
    u32 length[4]   byte length of each channel's range-coded stream
    -- codings 4 and 5:
    u8  chained     bit ch set (only for a table-mode channel): channel ch's table is chained
    u32 table_length[4]  byte length of each channel's table stream (0: the channel has no table)
    -- coding 5 only:
    u8  steps       bit ch set (only for a table-mode channel): channel ch codes rank steps
    ...             the table streams (codings 4 and 5), channel 0 to 3
    ...             the four streams, channel 0 (x) to 3 (density)

In codings 1-3 a table-mode channel's stream starts with its table (size, first value, gaps). In
coding 4 each table-mode channel's table is a stream of its own ahead of the channel streams
(:func:`gatun_py.codec._geometry_kernels.encode_table_set`), so that a reader takes a block's
tables, or some channels' tables, without decoding its vertices. A *chained* channel's table
stream holds only the values it adds to the table of the same channel in the next coarser level of
the file (the next entry of the file's level list, which must code that channel with a table too):
a coarser level's vertices are a subset of the finer one's, values bit for bit, so its table is a
subset. Decoding level k then takes the table streams of the chained channels in the levels k+1,
k+2, ... as far as their chains go, about one whole table's worth of values, as a block of its own
tables would. The channel streams of coding 4 are coding 3's (a table-mode channel's without the
table). The encoder of a file with levels chooses per level and channel among prediction, own
table and chained table, coarsest level first (:func:`assemble_geometry`).

Coding 5 is coding 4 with *rank steps* (``K.MODE_STEPS``) on the table-mode channels where they
make the stream smaller: a vertex's rank is coded as a step of -2 .. 2 from its first ref's rank,
or an escape followed by the value as a table-mode channel of coding 4 codes it (see
:mod:`gatun_py.codec._geometry_kernels`).
"""

from __future__ import annotations

import itertools
import struct
import threading
from dataclasses import dataclass

import numpy as np

from ..errors import CorruptFileError
from . import _geometry_kernels as K
from .formats import CURRENT, codings
from .rangecoder import (ADAPT_SHIFT, DEC_ERROR, DEC_OVERRUN, DEC_POS, FAST_ADAPT_SHIFT, INT_BUCKET_BITS, PROB_INIT,
                         PROB_ONE, dec_state, enc_state, new_model)

# codings 4 and 5 run the kernels of coding 3: 4 moves the tables, 5 adds rank steps (K.MODE_STEPS)
CODINGS = K.CODINGS + (4, 5)


def coding_for_format(major: int) -> int:
    """The geometry block coding of a file of format ``major`` (:mod:`gatun_py.codec.formats`)."""
    return codings(major).geometry


def _kernel_coding(coding: int) -> int:
    return min(int(coding), 3)


# what this version of tetc writes
FORMAT_VERSION = CURRENT.geometry
MAX_POINTS = 1 << 29  # the decoder's scratch tags (3 per vertex) are int32
_HEADER = struct.Struct("<BBI4I")
HEADER_SIZE = _HEADER.size  # codings 1-3
_HEADER4 = struct.Struct("<BBI4IB4I")
_HEADER5 = struct.Struct("<BBI4IB4IB")  # coding 4's, then the channels coded with rank steps
MAX_HEADER_SIZE = _HEADER5.size  # enough of a block's start to check any coding's header
XY_TABLE_BIT = 1 << K.N_CHANNELS  # coding 3's modes: y uses the x -> y table (always, before)
# The encoder tries a channel's value table (MODE_TABLE) when it has at most this share of distinct
# values among the vertices, and keeps it where its stream is smaller. Blunt-fin's density has
# 28,025 values on 40,960 vertices (0.68): 78,507 bytes as ranks in its table against 92,456 as
# prediction residuals, and its coarser levels (0.74-0.76) gain 3-9 %; at 0.97 (Combustion's,
# LOX post's density) and 0.99 (the gmsh flange) the table loses, so the trial is skipped there.
TABLE_TRIAL_SHARE = 0.8
# A level of a file with levels tries ranks on every channel, whatever its share of distinct values,
# when it has at most this many vertices (coding 4): chained, its table costs a fraction of a whole
# one and ranks then win on nearly every level even where nearly all values are distinct
# (Combustion's every level; all its levels chained so: 808 KB against 961 KB). But ranks of a
# nearly all-distinct channel decode slower than prediction residuals: its table (about 60 ns per
# value) and a table look-up per vertex (about 70 ns: Combustion's level 0 decoded in 1.48 x the
# time), so above this size only channels with at most TABLE_TRIAL_SHARE distinct values try them
# (Combustion 933 KB, its levels 0-3 decode as fast as before; Blunt-fin and LOX post lose nothing).
CHAIN_ANY_SHARE_POINTS = 4096

# Absurd counts are rejected before allocating: a binary decision costs at least
# -log2(p_max) bits, p_max being the most skewed probability the range coder's adaptation reaches
# (the fast-adapting decisions of coding 5's rank steps reach a more skewed one); a vertex takes at
# least one decision in each channel's stream, a table entry at least INT_BUCKET_BITS decisions. So
# a stream of L bytes holds at most ~8 L / cost of them.
_MIN_DECISION_BITS = -np.log2(1.0 - ((1 << ADAPT_SHIFT) - 1) / PROB_ONE)
_MIN_VERTEX_BITS = -np.log2(1.0 - ((1 << FAST_ADAPT_SHIFT) - 1) / PROB_ONE)
_MAX_VERTICES_PER_BYTE = int(8.0 / _MIN_VERTEX_BITS) + 1
# What real blocks reach: a regular 40^3 grid with a constant scalar, the most compressible mesh we
# know, codes 3.5 vertices per byte of its four streams together; 256 leaves 70x headroom and keeps
# a crafted count (and the decoder's ~120 bytes of state per vertex) within a bound of the file size.
MAX_VERTICES_PER_STREAM_BYTE = 256


def max_vertices(lengths) -> int:
    """The most vertices a block with these four stream lengths is accepted to hold."""
    return min(MAX_VERTICES_PER_STREAM_BYTE * (sum(int(x) for x in lengths) + 16),
               _MAX_VERTICES_PER_BYTE * (min(int(x) for x in lengths) + 8), MAX_POINTS - 1)
_MAX_TABLE_PER_BYTE = int(8.0 / (INT_BUCKET_BITS * _MIN_DECISION_BITS)) + 1


def _as_refs(refs, n: int) -> np.ndarray:
    refs = np.asarray(refs)
    if refs.ndim != 2 or refs.shape[0] != n or refs.shape[1] not in (3, 4):
        raise ValueError(f"refs must have shape ({n}, 3) or ({n}, 4), got {refs.shape}")
    if refs.dtype.kind not in "iu":
        raise ValueError(f"refs must be integers, got {refs.dtype}")
    if n and (refs.min() < -1 or (refs >= np.arange(n, dtype=np.int64)[:, None]).any()):
        raise ValueError("refs[k] must hold decode ids in [-1, k)")
    out = np.full((n, 4), -1, dtype=np.int32)
    out[:, : refs.shape[1]] = refs
    return out


def _channels(points, density) -> np.ndarray:
    points = np.asarray(points)
    density = np.asarray(density)
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype != np.float32:
        raise ValueError(f"points must be a (n, 3) float32 array, got {points.shape} {points.dtype}")
    if density.shape != (points.shape[0],) or density.dtype != np.float32:
        raise ValueError(f"density must be a ({points.shape[0]},) float32 array, got {density.shape} {density.dtype}")
    vf = np.empty((points.shape[0], 4), dtype=np.float32)
    vf[:, :3] = points
    vf[:, 3] = density
    return vf


def _ordered(vf: np.ndarray) -> np.ndarray:
    """Order-preserving int64 image of float32 bit patterns (the kernels' ``ordered_int``)."""
    b = vf.view(np.int32).astype(np.int64)
    return np.where(b < 0, b ^ 0x7FFFFFFF, b)


_NO_TRACE = np.zeros((0, 4, 3), dtype=np.int64)


def _block_tables(vf: np.ndarray, refs) -> tuple:
    """A block's checked refs and each channel's table of distinct ordered integers: ``(refs,
    tables_list, tables, tab_offs)``, the tables also concatenated with their offsets as the
    kernels take them."""
    n = vf.shape[0]
    if n >= MAX_POINTS:
        raise ValueError(f"at most {MAX_POINTS - 1} vertices per geometry block, got {n}")
    refs = _as_refs(refs, n)
    ordered = _ordered(vf)
    tables_list = [np.unique(ordered[:, ch]) for ch in range(K.N_CHANNELS)]
    tables = np.concatenate(tables_list) if n else np.zeros(0, dtype=np.int64)
    tab_offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
    tab_offs[1:] = np.cumsum([len(t) for t in tables_list])
    return refs, tables_list, tables, tab_offs


def _run_encode(vf, refs, modes, tables, tab_offs, cands, trace=_NO_TRACE, wpar=None) -> list:
    n = vf.shape[0]
    if wpar is None:
        wpar = K.link_all(refs, vf)
    cap = 256 + 8 * n
    while True:
        st = np.stack([enc_state() for _ in range(K.N_CHANNELS)])
        out = np.empty((K.N_CHANNELS, cap), dtype=np.uint8)
        nbytes = K.encode_kernel(st, out, vf, refs, wpar, modes, tables, tab_offs, cands, trace)
        if int(nbytes.max()) <= cap:
            return [out[ch, : nbytes[ch]].tobytes() for ch in range(K.N_CHANNELS)]
        cap = int(nbytes.max()) + 64


def refs_from_predictors(predictors, n_boundary_vertices: int, interior_apex=None) -> np.ndarray:
    """Geometry refs from the cut-border coder's predictor vertices.

    Parameters
    ----------
    predictors : (n, 3) or (n, 4) int array
        Four columns are taken as refs already. Three: ``(p, r, apex)`` for boundary vertices
        (the border edge and the third vertex of the triangle it came from), the current face
        ``(a, b, c)`` for interior ones; ``-1`` for none.
    n_boundary_vertices : int
        The first ``n_boundary_vertices`` vertices come from the boundary-surface phase.
    interior_apex : (n,) int array, optional
        The apex behind the face of every interior vertex (ignored for boundary vertices).

    Returns
    -------
    (n, 4) int32
        Refs as :func:`encode_geometry` wants them.
    """
    predictors = np.asarray(predictors)
    n = predictors.shape[0]
    if predictors.ndim == 2 and predictors.shape[1] == 4:  # already (face, apex)
        return np.ascontiguousarray(predictors, dtype=np.int32)
    nb = min(max(int(n_boundary_vertices), 0), n)
    refs = np.full((n, 4), -1, dtype=np.int32)
    refs[:, :3] = predictors
    # a boundary vertex hangs off the edge (p, r); the triangle's apex is behind that edge. Seed
    # triangle vertices have only earlier seed vertices as predictors (no apex): leave them.
    hanging = np.flatnonzero(predictors[:nb, 1] >= 0)
    hanging = hanging[predictors[hanging, 2] >= 0]
    refs[hanging, 3] = predictors[hanging, 2]
    refs[hanging, 2] = -1
    if interior_apex is not None:
        refs[nb:, 3] = np.asarray(interior_apex)[nb:]
    return refs


def encode_geometry(points, density, refs, *, modes=None, coding: int = FORMAT_VERSION) -> bytes:
    """Losslessly encode vertex coordinates and density given in decode order.

    Parameters
    ----------
    points : (n, 3) float32 array
        Coordinates in decode order.
    density : (n,) float32 array
        The scalar of every vertex, in decode order.
    refs : (n, 4) or (n, 3) int array
        For vertex k, the face ``(a, b, c)`` it closes and the apex ``d`` behind it, as decode
        ids ``< k`` or ``-1`` (see the module docstring).
    modes : sequence of 4 ints, optional
        Force the residual mode per channel (0 prediction, 1 value table); by default both are
        tried and the smaller stream is kept, channel by channel.
    coding : {1, 2, 3, 4, 5}
        The block's coding version: 5 (the default, format 9: coding 4 with rank steps), 4 what
        format 8 wrote (coding 3's model, its value tables in streams of their own; alone, a block
        chains to nothing: :func:`assemble_geometry` codes the levels of a file), 3 what formats 5 to 7 wrote, 2 what format 4 wrote (the tet-geometry
        predictors), 1 what format 3 and older wrote.

    Returns
    -------
    bytes
        The geometry block, decoded by :func:`decode_geometry` or :class:`GeometryDecoder`.

    Raises
    ------
    ValueError
        On arrays of the wrong shape or dtype, or refs outside ``[-1, k)``.
    """
    vf = _channels(points, density)
    n = vf.shape[0]
    if coding not in CODINGS:
        raise ValueError(f"coding must be one of {CODINGS}, got {coding!r}")
    if modes is not None:
        modes = np.asarray(modes, dtype=np.int64)
        if modes.shape != (K.N_CHANNELS,) or not np.isin(modes, (0, 1)).all():
            raise ValueError("modes must be 4 values, each 0 (prediction) or 1 (table)")
    if coding >= 4:
        parts = geometry_parts(points, density, refs, chainable=False, steps=coding >= 5,
                               force_ranks=modes is not None and bool(modes.any()))
        return assemble_geometry([parts], modes=None if modes is None else [modes], coding=coding)[0]
    cands = K.candidate_table(coding)
    refs, tables_list, tables, tab_offs = _block_tables(vf, refs)
    if modes is not None:
        streams = _run_encode(vf, refs, modes, tables, tab_offs, cands)
    else:
        wpar = K.link_all(refs, vf)
        pred = _run_encode(vf, refs, np.zeros(4, np.int64), tables, tab_offs, cands, wpar=wpar)
        # a table pays off only when values repeat: skip the trial when nearly all are distinct
        use_table = np.array([len(t) <= TABLE_TRIAL_SHARE * n for t in tables_list], dtype=np.int64)
        if use_table.any():
            # second pass: only the channels worth a table (channels are independent streams)
            trial = np.where(use_table == 1, K.MODE_TABLE, K.MODE_SKIP).astype(np.int64)
            tab = _run_encode(vf, refs, trial, tables, tab_offs, cands, wpar=wpar)
            modes = np.zeros(K.N_CHANNELS, dtype=np.int64)
            streams = []
            for ch in range(K.N_CHANNELS):
                if use_table[ch] and len(tab[ch]) < len(pred[ch]):
                    modes[ch] = 1
                    streams.append(tab[ch])
                else:
                    streams.append(pred[ch])
        else:
            modes = np.zeros(K.N_CHANNELS, dtype=np.int64)
            streams = pred
    mode_bits = sum(int(m) << ch for ch, m in enumerate(modes))
    if coding >= 3:
        # coding 3 says per block whether y gets the x -> y table's repetition candidate: it pays on
        # grids, and costs the decoder a random table access per vertex and 16-24 bytes per vertex
        # where nothing repeats. It changes y's stream, and z's (whose contexts are y's repetitions):
        # code both again without, keep the smaller pair.
        trial = np.full(K.N_CHANNELS, K.MODE_SKIP, dtype=np.int64)
        trial[1:3] = modes[1:3]
        plain = _run_encode(vf, refs, trial, tables, tab_offs, K.candidate_table(coding, xy_table=False),
                            wpar=K.link_all(refs, vf))
        if len(plain[1]) + len(plain[2]) <= len(streams[1]) + len(streams[2]):
            streams[1:3] = plain[1:3]
        else:
            mode_bits |= XY_TABLE_BIT
    header = _HEADER.pack(coding, mode_bits, n, *(len(s) for s in streams))
    return header + b"".join(streams)


# ------------------------------------------------------------------------------ coding 4


@dataclass
class GeometryParts:
    """What the coding-4 encoder knows of one block before choosing its modes: the channels'
    distinct values and their streams coded every way that may be chosen.

    Attributes
    ----------
    n : int
    tables : list of 4 int32 arrays
        Per channel, its sorted distinct ordered integers (the table a table-mode channel needs).
    streams : dict
        ``(ranks, xy)`` -> 4 channel streams (bytes, or None where not coded): ``ranks`` False for
        prediction residuals, True for ranks in the channel's table (without the table), ``STEPS``
        for ranks with coding 5's rank steps; ``xy`` whether y had the x -> y table (only y's and
        z's streams depend on it).
    """

    n: int
    tables: list
    streams: dict


STEPS = "steps"  # the GeometryParts.streams key of ranks coded with rank steps
# Rank steps are tried on a channel only where at most this share of the vertices escape (a step
# beyond -2 .. 2 from the first ref's rank). An escape decodes as a step decision, the value as
# without steps and a table look-up for its rank, so a channel with many escapes is smaller in steps
# but decodes slower (bench/sections/levels.md holds the measurements).
STEP_ESCAPE_SHARE = 0.1


def _few_escapes(vf, refs, tables_list) -> np.ndarray:
    """Per channel, whether at most STEP_ESCAPE_SHARE of the vertices with a first ref would
    escape in rank steps."""
    ordered = _ordered(vf)
    has = refs[:, 0] >= 0
    out = np.zeros(K.N_CHANNELS, dtype=bool)
    for ch, table in enumerate(tables_list):
        rank = np.searchsorted(table, ordered[:, ch])
        steps = rank[has] - rank[refs[has, 0]]
        out[ch] = np.count_nonzero(np.abs(steps) > 2) <= STEP_ESCAPE_SHARE * len(steps)
    return out


def geometry_parts(points, density, refs, *, chainable: bool = True, force_ranks: bool = False,
                   steps: bool = FORMAT_VERSION >= 5) -> GeometryParts:
    """Code a block's channels every way :func:`assemble_geometry` may choose (arguments as
    :func:`encode_geometry`). The ranks are coded on the channels where at most
    :data:`TABLE_TRIAL_SHARE` of the values are distinct, on all with ``force_ranks``, and on all
    of a block of at most :data:`CHAIN_ANY_SHARE_POINTS` vertices with ``chainable`` (a level of a
    file with levels, whose tables may chain to the next coarser level's); with ``steps`` (coding
    5) also as rank steps, wherever ranks are."""
    vf = _channels(points, density)
    n = vf.shape[0]
    refs, tables_list, tables, tab_offs = _block_tables(vf, refs)
    wpar = K.link_all(refs, vf)
    xy_on, xy_off = K.candidate_table(3, True), K.candidate_table(3, False)
    skip = K.MODE_SKIP
    streams = {}
    streams[False, True] = _run_encode(vf, refs, np.zeros(K.N_CHANNELS, np.int64), tables, tab_offs, xy_on, wpar=wpar)
    streams[False, False] = [None] + _run_encode(vf, refs, np.array([skip, 0, 0, skip]), tables, tab_offs, xy_off,
                                                 wpar=wpar)[1:3] + [None]
    tried = np.array([n > 0 and (force_ranks or len(t) <= TABLE_TRIAL_SHARE * n
                                 or (chainable and n <= CHAIN_ANY_SHARE_POINTS)) for t in tables_list])
    stepped = tried & _few_escapes(vf, refs, tables_list) if steps else np.zeros(K.N_CHANNELS, bool)
    for key, mode, chans in ((True, K.MODE_RANKS, tried), (STEPS, K.MODE_STEPS, stepped)):
        if not chans.any():
            continue
        trial = np.where(chans, mode, skip).astype(np.int64)
        on = _run_encode(vf, refs, trial, tables, tab_offs, xy_on, wpar=wpar)
        streams[key, True] = [on[ch] if chans[ch] else None for ch in range(K.N_CHANNELS)]
        if chans[1:3].any():
            trial[0] = trial[3] = skip
            off = _run_encode(vf, refs, trial, tables, tab_offs, xy_off, wpar=wpar)
            streams[key, False] = [None] + [off[ch] if chans[ch] else None for ch in (1, 2)] + [None]
    # kept until the file's levels are chained: as int32 (ordered integers of float32 fit), half the memory
    return GeometryParts(int(n), [t.astype(np.int32) for t in tables_list], streams)


_PREDICT, _OWN, _CHAINED = 0, 1, 2


def _table_stream(values) -> bytes:
    """A table's (or a chained table's additions') stream: :func:`K.encode_table_set`."""
    values = np.ascontiguousarray(values, dtype=np.int64)
    cap = 64 + 8 * len(values)
    while True:
        out = np.empty(cap, np.uint8)
        nbytes = int(K.encode_table_set(enc_state(), out, values))
        if nbytes <= cap:
            return out[:nbytes].tobytes()
        cap = nbytes + 64


def _is_subset(coarse, fine) -> bool:
    """Whether the sorted distinct values ``coarse`` all occur in the sorted ``fine``."""
    if len(coarse) > len(fine):
        return False
    at = np.searchsorted(fine, coarse)
    return bool((at < len(fine)).all() and (fine[np.minimum(at, len(fine) - 1)] == coarse).all())


def _rank_stream(p: GeometryParts, ch: int, key_xy: bool, coding: int):
    """The smaller of channel ch's rank streams (plain, or with rank steps in coding 5) and
    whether it has steps; ``(None, False)`` where the ranks were not coded."""
    s = p.streams.get((True, key_xy))
    best = (None, False) if s is None or s[ch] is None else (s[ch], False)
    t = p.streams.get((STEPS, key_xy)) if coding >= 5 else None
    if t is not None and t[ch] is not None and (best[0] is None or len(t[ch]) < len(best[0])):
        best = (t[ch], True)
    return best


def assemble_geometry(levels: list, modes: list | None = None, coding: int = FORMAT_VERSION) -> list:
    """Coding-4 or -5 geometry blocks of the levels of one file (or of one brick) from their
    :class:`GeometryParts`, finest first: block i may chain its tables to block i + 1's.

    Per channel and level the modes are prediction, own table or chained table (only where the
    next coarser block codes the channel with a table and its table is a subset of this one's),
    and per level whether y uses the x -> y table; chosen for the fewest bytes over all levels by a
    dynamic programme from the coarsest level on (the state: which channels the coarser level codes
    with a table; every table is a stream of its own, so a choice's bytes are exact). ``modes``:
    per level, 4 forced modes (0 prediction, 1 table: own or chained). In coding 5 a table-mode
    channel's ranks are coded with rank steps where that stream is smaller. Returns the blocks, in
    the same order."""
    if coding not in (4, 5):
        raise ValueError(f"assemble_geometry writes codings 4 and 5, not {coding!r}")
    nl = len(levels)
    inf = float("inf")
    # per level: cost[ch][mode][xy] of the channel's stream plus its table, inf where impossible
    costs = []
    for k, p in enumerate(levels):
        coarse = levels[k + 1] if k + 1 < nl else None
        c = np.full((K.N_CHANNELS, 3, 2), inf)
        for ch in range(K.N_CHANNELS):
            own_table = None  # bytes of the table stream (exact: every channel's is a stream of its own)
            for xy in (0, 1):
                key_xy = bool(xy) if ch in (1, 2) else True  # only y's and z's streams depend on xy
                s = p.streams.get((False, key_xy))
                if s is not None and s[ch] is not None:
                    c[ch, _PREDICT, xy] = len(s[ch])
                ranks, _ = _rank_stream(p, ch, key_xy, coding)
                if ranks is not None:
                    if own_table is None:
                        own_table = len(_table_stream(p.tables[ch]))
                    c[ch, _OWN, xy] = len(ranks) + own_table
            if own_table is not None:
                if coarse is not None and _is_subset(coarse.tables[ch], p.tables[ch]):
                    adds = np.setdiff1d(p.tables[ch], coarse.tables[ch], assume_unique=True)
                    c[ch, _CHAINED] = c[ch, _OWN] - own_table + len(_table_stream(adds))
            if modes is not None:
                forced = int(modes[k][ch])
                c[ch, _OWN if forced == 0 else _PREDICT] = inf
                if forced == 0:
                    c[ch, _CHAINED] = inf
        costs.append(c)
    choices = [(m, xy) for xy in (1, 0) for m in itertools.product((_PREDICT, _OWN, _CHAINED), repeat=K.N_CHANNELS)]
    # best[k][mask]: the fewest bytes of levels k.. when level k codes the channels of mask with a table
    nm = 1 << K.N_CHANNELS
    best = [[inf] * nm for _ in range(nl + 1)]
    pick = [[None] * nm for _ in range(nl)]
    best[nl][0] = 0.0
    for k in range(nl - 1, -1, -1):
        # the least cost of levels k+1.. whose table mask covers a given set of channels
        sup = [min(best[k + 1][m] for m in range(nm) if m & s == s) for s in range(nm)]
        c = costs[k]
        for m4, xy in choices:
            need = sum(1 << ch for ch in range(K.N_CHANNELS) if m4[ch] == _CHAINED)
            if k + 1 == nl and need:
                continue
            total = sup[need] + sum(c[ch, m4[ch], xy] for ch in range(K.N_CHANNELS))
            mask = sum(1 << ch for ch in range(K.N_CHANNELS) if m4[ch] != _PREDICT)
            if total < best[k][mask]:
                best[k][mask] = total
                pick[k][mask] = (m4, xy)
    blocks = []
    mask = min(range(nm), key=lambda m: best[0][m])
    for k, p in enumerate(levels):
        m4, xy = pick[k][mask]
        need = sum(1 << ch for ch in range(K.N_CHANNELS) if m4[ch] == _CHAINED)
        blocks.append(_block4(p, levels[k + 1] if k + 1 < nl else None, m4, xy, coding))
        if k + 1 < nl:
            mask = min((m for m in range(nm) if m & need == need), key=lambda m: best[k + 1][m])
    return blocks


def _block4(p: GeometryParts, coarse, m4, xy: int, coding: int) -> bytes:
    streams, tables, steps = [], [], 0
    for ch in range(K.N_CHANNELS):
        key_xy = bool(xy) if ch in (1, 2) else True
        if m4[ch] == _PREDICT:
            streams.append(p.streams[False, key_xy][ch])
        else:
            ranks, stepped = _rank_stream(p, ch, key_xy, coding)
            streams.append(ranks)
            steps |= int(stepped) << ch
        if m4[ch] == _CHAINED:
            tables.append(_table_stream(np.setdiff1d(p.tables[ch], coarse.tables[ch], assume_unique=True)))
        elif m4[ch] == _OWN:
            tables.append(_table_stream(p.tables[ch]))
        else:
            tables.append(b"")
    mode_bits = sum(int(m4[ch] != _PREDICT) << ch for ch in range(K.N_CHANNELS)) | (XY_TABLE_BIT if xy else 0)
    chained = sum(1 << ch for ch in range(K.N_CHANNELS) if m4[ch] == _CHAINED)
    lengths = [len(s) for s in streams] + [chained] + [len(t) for t in tables]
    header = _HEADER5.pack(5, mode_bits, p.n, *lengths, steps) if coding >= 5 else _HEADER4.pack(4, mode_bits, p.n, *lengths)
    return header + b"".join(tables) + b"".join(streams)


# ------------------------------------------------------------------------------ headers


@dataclass
class GeometryHeader:
    """A geometry block's header (any coding), checked by :func:`parse_geometry_header`."""

    coding: int
    mode_bits: int
    n: int
    lengths: list
    chained: int = 0  # coding 4: bit ch, channel ch's table is chained to the next coarser level's
    table_lengths: tuple = (0, 0, 0, 0)  # coding 4: bytes of each channel's table stream
    size: int = HEADER_SIZE  # bytes of the header
    steps: int = 0  # coding 5: bit ch, channel ch's ranks are coded with rank steps

    @property
    def table_length(self) -> int:
        return sum(self.table_lengths)

    @property
    def modes(self) -> np.ndarray:
        """The kernels' mode of each channel: K.MODE_PREDICT, K.MODE_TABLE or K.MODE_STEPS."""
        return np.array([K.MODE_STEPS if self.steps >> ch & 1 else (self.mode_bits >> ch) & 1
                         for ch in range(K.N_CHANNELS)], dtype=np.int64)


def parse_geometry_header(data, n_points: int | None = None, *, total: int | None = None) -> GeometryHeader:
    """Check a geometry block's header against its size (and the expected vertex count).

    ``data`` is the block, or only its start (:data:`MAX_HEADER_SIZE` bytes are enough) with the
    block's size in ``total``. Raises :class:`CorruptFileError` before anything is allocated when
    the counts cannot come from a block of this size.
    """
    total = len(data) if total is None else int(total)
    if len(data) < HEADER_SIZE:
        raise CorruptFileError("corrupt geometry block: truncated header")
    version, mode_bits, n, *lengths = _HEADER.unpack_from(data)
    if version not in CODINGS:
        raise CorruptFileError(f"corrupt geometry block: unknown geometry format version {version}")
    if mode_bits >> K.N_CHANNELS != 0 and (version < 3 or mode_bits >= 2 * XY_TABLE_BIT):
        raise CorruptFileError("corrupt geometry block: invalid channel modes")
    hdr = GeometryHeader(version, mode_bits, n, lengths)
    if version >= 4:
        if len(data) < _HEADER4.size:
            raise CorruptFileError("corrupt geometry block: truncated header")
        hdr.chained, *hdr.table_lengths = _HEADER4.unpack_from(data)[-1 - K.N_CHANNELS:]
        hdr.size = _HEADER4.size
        if version >= 5:
            if len(data) < _HEADER5.size:
                raise CorruptFileError("corrupt geometry block: truncated header")
            hdr.steps = _HEADER5.unpack_from(data)[-1]
            hdr.size = _HEADER5.size
            if hdr.steps & ~mode_bits & ((1 << K.N_CHANNELS) - 1) or hdr.steps >> K.N_CHANNELS:
                raise CorruptFileError("corrupt geometry block: rank steps on a channel without a table")
        if hdr.chained & ~mode_bits & ((1 << K.N_CHANNELS) - 1) or hdr.chained >> K.N_CHANNELS:
            raise CorruptFileError("corrupt geometry block: a chained table on a channel without a table")
        if any((hdr.table_lengths[ch] == 0) != (mode_bits >> ch & 1 == 0) for ch in range(K.N_CHANNELS)):
            raise CorruptFileError("corrupt geometry block: table streams do not match the channel modes")
    if n_points is not None and n != n_points:
        raise CorruptFileError(f"corrupt geometry block: {n} vertices, expected {n_points}")
    if hdr.size + hdr.table_length + sum(lengths) != total:
        raise CorruptFileError("corrupt geometry block: stream lengths do not match the block size")
    if n > max_vertices(lengths):
        raise CorruptFileError(f"corrupt geometry block: {n} vertices cannot fit in {total} bytes")
    return hdr


def geometry_stream_sizes(data: bytes) -> dict:
    """Byte sizes of the parts of a geometry block (header, the x, y, z, density streams and, in
    coding 4, the table streams: ``tables`` and per channel ``x_table`` ...), each channel's
    mode (``predict``, ``table`` or, coding 4, ``chained``) and, coding 5, whether its ranks are
    coded with rank steps (``x_steps`` ...)."""
    if len(data) < HEADER_SIZE:
        raise CorruptFileError("corrupt geometry block: truncated header")
    version, mode_bits, n, *lengths = _HEADER.unpack_from(data)
    chained, table_lengths, size, steps = 0, None, HEADER_SIZE, 0
    if version >= 4:
        head = _HEADER5 if version >= 5 else _HEADER4
        if len(data) < head.size:
            raise CorruptFileError("corrupt geometry block: truncated header")
        chained, *table_lengths = _HEADER4.unpack_from(data)[-1 - K.N_CHANNELS:]
        size = head.size
        steps = head.unpack_from(data)[-1] if version >= 5 else 0
    sizes = {"header": size}
    if table_lengths is not None:
        sizes["tables"] = sum(table_lengths)
    for name, ch_len, ch in zip(("x", "y", "z", "density"), lengths, range(4)):
        sizes[name] = ch_len
        sizes[name + "_mode"] = ("chained" if chained >> ch & 1 else "table") if mode_bits >> ch & 1 else "predict"
        if table_lengths is not None:
            sizes[name + "_table"] = table_lengths[ch]
        sizes[name + "_steps"] = bool(steps >> ch & 1)
    return sizes


def check_geometry_header(data, n_points: int | None = None, *, total: int | None = None) -> tuple[int, int, list]:
    """Check a geometry block's header against its size (and the expected vertex count).

    ``data`` is the block, or only its start with the block's size in ``total``. Returns
    ``(coding, mode bits, vertices, stream lengths)`` (:func:`parse_geometry_header` has the rest of
    a coding-4 header); raises :class:`CorruptFileError` before anything is allocated when the
    counts cannot come from a block of this size.
    """
    hdr = parse_geometry_header(data, n_points, total=total)
    return hdr.coding, hdr.mode_bits, hdr.n, hdr.lengths


def _channels_of(mask: int) -> list:
    return [ch for ch in range(K.N_CHANNELS) if mask >> ch & 1]


_MODELS = threading.local()


def _table_models() -> np.ndarray:
    """The models decode_tables_kernel needs for tables alone, reset: the kernel indexes a channel's
    table model at TABLE_BASE of a whole channel model (760 KB for four, filled anew for every level
    of a chain was a third of its time), so one per thread is kept and only the table part reset."""
    probs = getattr(_MODELS, "probs", None)
    if probs is None:
        probs = _MODELS.probs = np.full((K.N_CHANNELS, K.TABLE_BASE + K.TABLE_SET_MODEL), PROB_INIT, dtype=np.uint16)
    probs[:, K.TABLE_BASE:] = PROB_INIT
    return probs


# A stream that dec_init accepts and nothing reads: the place of a channel whose table is not read
_NO_STREAM = np.zeros(5, np.uint8)
_MASK_MODES = [np.array([m >> ch & 1 for ch in range(K.N_CHANNELS)], dtype=np.int64) for m in range(1 << K.N_CHANNELS)]


def _decode_tables4(buf, hdr: GeometryHeader, base, channels: int = (1 << K.N_CHANNELS) - 1) -> list:
    """Tables of a coding-4 block's table-mode channels among ``channels`` (a bit mask): per channel
    its sorted distinct ordered integers (int64), None for a channel without a table or not asked
    for. ``base``: per channel the next coarser level's table (needed where this block chains).

    A table stream is coded as the table prefix of a channel stream of codings 1-3, so
    :func:`K.decode_tables_kernel` reads the asked ones in one call (with the argument types of a
    block's own decode: nothing more to compile); a chained channel's additions are then merged
    into the coarser table."""
    want = hdr.mode_bits & channels & ((1 << K.N_CHANNELS) - 1)
    out = [None] * K.N_CHANNELS
    if not want:
        return out
    lengths = [int(x) for x in hdr.table_lengths]
    for ch in range(K.N_CHANNELS):
        if want >> ch & 1 and hdr.chained >> ch & 1 and (base is None or base[ch] is None):
            raise CorruptFileError("corrupt geometry block: a chained value table without the coarser level's")
    offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
    if want == (1 << K.N_CHANNELS) - 1:  # every channel's table, one after the other in the block
        data = buf[hdr.size:hdr.size + sum(lengths)]
        offs[1:] = np.cumsum(lengths)
    else:  # the others' places hold an empty stream
        streams, start = [], hdr.size
        for ch in range(K.N_CHANNELS):
            streams.append(buf[start:start + lengths[ch]] if want >> ch & 1 else _NO_STREAM)
            start += lengths[ch]
        data = np.concatenate(streams)
        data.flags.writeable = False  # the type of a block read from a file
        offs[1:] = np.cumsum([len(x) for x in streams])
    # each set's room before allocating: at most n values, and what its stream can code
    room = sum(min(hdr.n, _MAX_TABLE_PER_BYTE * (lengths[ch] + 8)) for ch in range(K.N_CHANNELS) if want >> ch & 1)
    sets = np.empty(room, dtype=np.int64)
    set_offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
    st = np.zeros((K.N_CHANNELS, 8), dtype=np.int64)
    probs = _table_models()
    if K.decode_tables_kernel(st, data, offs, probs, _MASK_MODES[want], hdr.n, sets, set_offs) != K.OK:
        raise CorruptFileError("corrupt geometry block: damaged value table")
    for ch in range(K.N_CHANNELS):
        if not want >> ch & 1:
            continue
        if st[ch, DEC_ERROR] != 0 or st[ch, DEC_OVERRUN] != 0 or int(st[ch, DEC_POS]) != lengths[ch]:
            raise CorruptFileError("corrupt geometry block: damaged value table")
        table = sets[set_offs[ch]:set_offs[ch + 1]]
        if hdr.chained >> ch & 1:
            # the additions and the coarser table, both sorted: a stable sort merges the two runs
            table = np.concatenate([base[ch], table])
            table.sort(kind="stable")
            if len(table) > hdr.n or (table[1:] == table[:-1]).any():
                raise CorruptFileError("corrupt geometry block: damaged value table (an addition the coarser "
                                       "table holds, or more values than vertices)")
        out[ch] = table
    return out


_NO_TABLE = np.zeros(0, np.int64)


def decode_value_tables(data, n_points: int | None = None, base=None, channels: int = (1 << K.N_CHANNELS) - 1) -> list:
    """The value tables of a geometry block without decoding its vertices: per channel its sorted
    distinct ordered integers (int64), None for a channel without a table or not among
    ``channels`` (a bit mask). What a finer level's chained block needs of this one; ``base``: per
    channel the tables of this block's own coarser level, needed where it chains too. Raises
    :class:`CorruptFileError` on a damaged block."""
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    hdr = parse_geometry_header(buf, n_points)
    if hdr.coding >= 4:
        return _decode_tables4(buf, hdr, base, channels)
    offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
    offs[0] = HEADER_SIZE
    offs[1:] = HEADER_SIZE + np.cumsum(hdr.lengths)
    modes = hdr.modes
    room = sum(min(hdr.n, _MAX_TABLE_PER_BYTE * (int(hdr.lengths[ch]) + 8)) for ch in range(K.N_CHANNELS) if modes[ch])
    tables = np.zeros(room, dtype=np.int64)
    tab_offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
    st = np.stack([dec_state() for _ in range(K.N_CHANNELS)])
    probs = np.stack([new_model(K.MODEL_SIZE) for _ in range(K.N_CHANNELS)])
    if K.decode_tables_kernel(st, buf, offs, probs, modes, hdr.n, tables, tab_offs) != K.OK:
        raise CorruptFileError("corrupt geometry block: damaged value table")
    return [tables[tab_offs[ch]:tab_offs[ch + 1]] if modes[ch] and channels >> ch & 1 else None
            for ch in range(K.N_CHANNELS)]


def chained_channels(data) -> int:
    """The channels (bit mask) whose tables a geometry block (or its first :data:`MAX_HEADER_SIZE`
    bytes) chains to the next coarser level's; 0 before coding 4."""
    data = bytes(data[:MAX_HEADER_SIZE])
    if len(data) < _HEADER4.size or data[0] < 4:
        return 0
    return _HEADER4.unpack_from(data)[-1 - K.N_CHANNELS] & ((1 << K.N_CHANNELS) - 1)


class GeometryDecoder:
    """Streaming decoder of a geometry block, batch by batch in decode order.

    Parameters
    ----------
    data : bytes-like
        The block written by :func:`encode_geometry`.
    n_points : int, optional
        The vertex count the container expects; a different count in the block is corruption.
    base : list of 4 int64 arrays or None, optional
        Coding 4: per channel the value table of the next coarser level (None for a channel
        without one), where the block chains its tables to it (:func:`decode_value_tables`);
        a chained block without it is corruption.

    Attributes
    ----------
    value_tables : list of 4
        Per channel the block's value table (sorted distinct ordered integers), None for a
        channel without one: what a finer level chained to this one needs.
    values : (n, 4) float32
        x, y, z, density of every vertex decoded so far (the rest is uninitialised);
        ``points`` and ``density`` are views of it.
    n_decoded : int
        Vertices decoded so far.

    Notes
    -----
    The kernel :func:`gatun_py.codec._geometry_kernels.decode_vertices` can also be called
    directly from another numba kernel with the arrays in :attr:`kernel_args`, to interleave
    geometry with connectivity decoding.
    """

    def __init__(self, data, n_points: int | None = None, base=None):
        buf = np.frombuffer(bytes(data), dtype=np.uint8)
        hdr = parse_geometry_header(buf, n_points)
        coding, mode_bits, n, lengths = hdr.coding, hdr.mode_bits, hdr.n, hdr.lengths
        self.coding = int(coding)
        xy_table = self.coding < 3 or bool(mode_bits & XY_TABLE_BIT)
        self.cands = K.candidate_table(_kernel_coding(self.coding), xy_table)
        self.n_points = int(n)
        self.modes = hdr.modes
        self.offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
        self.offs[0] = hdr.size + hdr.table_length
        self.offs[1:] = self.offs[0] + np.cumsum(lengths)
        self.buf = buf
        self.st = np.stack([dec_state() for _ in range(K.N_CHANNELS)])
        self.probs = np.stack([new_model(K.MODEL_SIZE) for _ in range(K.N_CHANNELS)])
        self.scores = np.zeros((K.N_CHANNELS, K.N_PATTERNS, K.MAX_CANDS), dtype=np.int64)
        self.flags = np.zeros(2 * K.N_CHANNELS, dtype=np.int64)
        self.adj = np.zeros((self.n_points, K.ADJ_CAP), dtype=np.int32)
        self.deg = np.zeros(self.n_points, dtype=np.uint8)  # at most K.ADJ_CAP
        self.mark = np.zeros(self.n_points, dtype=np.int32)
        # the x -> y table holds at most one key per vertex: at most 2/3 full (the encoder's, at most
        # half, is twice this size at 1.4 M vertices); lookups do not depend on the capacity
        self.hkeys = np.zeros(K.xy_table_slots(self.n_points, self.coding) if xy_table else 1, dtype=np.int64)
        self.hvals = np.zeros(len(self.hkeys), dtype=np.uint8)
        if self.coding >= 4:
            # the tables come from their own stream; the channel streams start with the vertices
            self.value_tables = vt = _decode_tables4(buf, hdr, base)
            # the kernels' tables, one after the other
            self.tab_offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
            self.tab_offs[1:] = np.cumsum([0 if t is None else len(t) for t in vt])
            self.tables = np.concatenate([t for t in vt if t is not None] or [_NO_TABLE])
            if K.decode_tables_kernel(self.st, buf, self.offs, self.probs, np.zeros(K.N_CHANNELS, np.int64),
                                      self.n_points, self.tables, np.zeros(K.N_CHANNELS + 1, np.int64)) != K.OK:
                raise CorruptFileError("corrupt geometry block: the coded data is damaged")
            self.values = np.empty((self.n_points, 4), dtype=np.float32)
            self.n_decoded = 0
            # coding 5: the ranks of the decoded vertices on the rank-step channels
            self.ranks = np.zeros((self.n_points if hdr.steps else 1, K.N_CHANNELS), dtype=np.int32)
            return
        stream_bytes = [int(length) for length in lengths]
        table_room = sum(min(self.n_points, _MAX_TABLE_PER_BYTE * (stream_bytes[ch] + 8))
                         for ch in range(K.N_CHANNELS) if self.modes[ch])
        self.tables = np.zeros(table_room, dtype=np.int64)
        self.tab_offs = np.zeros(K.N_CHANNELS + 1, dtype=np.int64)
        status = K.decode_tables_kernel(self.st, buf, self.offs, self.probs, self.modes, self.n_points,
                                        self.tables, self.tab_offs)
        if status != K.OK:
            raise CorruptFileError("corrupt geometry block: damaged value table")
        self.value_tables = [self.tables[self.tab_offs[ch]:self.tab_offs[ch + 1]] if self.modes[ch] else None
                             for ch in range(K.N_CHANNELS)]
        self.values = np.empty((self.n_points, 4), dtype=np.float32)
        self.n_decoded = 0
        self.ranks = np.zeros((1, K.N_CHANNELS), dtype=np.int32)

    @property
    def points(self) -> np.ndarray:
        """(n, 3) view of the coordinates (valid for the first ``n_decoded`` rows)."""
        return self.values[:, :3]

    @property
    def density(self) -> np.ndarray:
        """(n,) view of the density (valid for the first ``n_decoded`` entries)."""
        return self.values[:, 3]

    @property
    def kernel_args(self) -> tuple:
        """``(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes, tables,
        tab_offs, ranks, cands)``, the leading arguments of ``decode_vertices``."""
        return (self.st, self.buf, self.offs, self.probs, self.scores, self.flags, self.adj, self.deg,
                self.mark, self.hkeys, self.hvals, self.modes, self.tables, self.tab_offs, self.ranks, self.cands)

    def decode(self, refs) -> tuple[np.ndarray, np.ndarray]:
        """Decode the next ``len(refs)`` vertices.

        Parameters
        ----------
        refs : (k, 4) or (k, 3) int array
            Refs of vertices ``n_decoded .. n_decoded + k - 1`` (decode ids, see the module).

        Returns
        -------
        points : (k, 3) float32
        density : (k,) float32
            Views into :attr:`values` for the new vertices.

        Raises
        ------
        CorruptFileError
            When the stream is damaged, a ref is out of range, or more vertices are asked for
            than the block holds.
        """
        refs = np.asarray(refs)
        count = int(refs.shape[0]) if refs.ndim == 2 else -1
        if count < 0 or refs.shape[1] not in (3, 4) or refs.dtype.kind not in "iu":
            raise CorruptFileError("corrupt geometry refs: expected a (k, 4) integer array")
        if refs.shape[1] == 3 or refs.dtype != np.int32:
            # out-of-range values are clipped to values the kernel still rejects
            full = np.full((count, 4), -1, dtype=np.int32)
            full[:, : refs.shape[1]] = np.clip(refs, -2, np.iinfo(np.int32).max)
            refs = full
        refs = np.ascontiguousarray(refs)
        start = self.n_decoded
        if start + count > self.n_points:
            raise CorruptFileError(
                f"corrupt geometry block: {start + count} vertices requested, the block holds {self.n_points}")
        status = K.decode_vertices_py(*self.kernel_args, refs, self.values, start, count)
        if status != K.OK:
            what = {K.ERR_REF: "a vertex reference is out of range",
                    K.ERR_RANK: "a value-table index is out of range"}.get(status, "the coded data is damaged")
            raise CorruptFileError(f"corrupt geometry block: {what}")
        self.n_decoded = start + count
        return self.values[start:start + count, :3], self.values[start:start + count, 3]

    def finish(self) -> None:
        """Check that every vertex was decoded and every byte of the block consumed."""
        if self.n_decoded != self.n_points:
            raise CorruptFileError(
                f"corrupt geometry block: {self.n_decoded} of {self.n_points} vertices decoded")
        for ch in range(K.N_CHANNELS):
            st = self.st[ch]
            length = int(self.offs[ch + 1] - self.offs[ch])
            if st[DEC_ERROR] != 0 or st[DEC_OVERRUN] != 0 or int(st[DEC_POS]) != length:
                raise CorruptFileError("corrupt geometry block: the coded data is damaged or truncated")


def decode_geometry(data, refs, n_points: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Decode a whole geometry block.

    Parameters
    ----------
    data : bytes-like
        The block written by :func:`encode_geometry`.
    refs : (n, 4) or (n, 3) int array
        The same refs the encoder was given.
    n_points : int, optional
        Expected vertex count.

    Returns
    -------
    points : (n, 3) float32
    density : (n,) float32

    Raises
    ------
    CorruptFileError
        When the block is damaged or does not match ``refs``.
    """
    dec = GeometryDecoder(data, n_points)
    refs = np.asarray(refs)
    if refs.ndim != 2 or refs.shape[0] != dec.n_points:
        raise CorruptFileError(f"corrupt geometry block: {dec.n_points} vertices, {len(refs)} refs given")
    dec.decode(refs)
    dec.finish()
    return np.ascontiguousarray(dec.points), np.ascontiguousarray(dec.density)
