"""Numba kernels of the lossless geometry/density coder (see :mod:`gatun_py.codec.geometry`).

Every vertex carries four channels, x, y, z and density, each a float32 coded exactly through its
*ordered integer* (the bit pattern with negative numbers flipped so integer order is float order,
:func:`ordered_int`). Each channel has its own range-coded stream so that the encoder can pick, per
channel, between two residual modes and keep whichever stream is smaller.

Per vertex k, with the refs ``(a, b, c, d)`` (face, apex) handed over by the connectivity coder:

0. **Partners** (:func:`link_vertex`, once per vertex, before any of its channels): the coder
   keeps its own graph of the edges new vertex - face refs. For each pair of face vertices it picks
   a common neighbour w whose parallelogram ``x + y - w`` lands nearest (in 3-D) to a first
   estimate of the new vertex, and for each face vertex a neighbour w whose extrapolation
   ``2 x - w`` lands nearest. On a curvilinear grid these find the grid lines through the face,
   which the face alone cannot give (Combustion: 64.6 -> 59.2 bits per vertex).

Then per channel:

1. **Repetition**: the distinct values of the valid refs on this channel form a list of at most
   four candidates; a symbol says "equal to candidate i" or "none of them", in a context of what
   the previous channel of the same vertex did. Real grids reuse a few values per axis, so this
   codes most of their coordinates in well under a bit.
2. Otherwise the value is predicted (the predictor is chosen backward-adaptively among linear
   combinations of the refs and partners, per ref pattern, by their recent residual sizes, so
   encoder and decoder pick the same one without side information) and coded as

   * ``MODE_PREDICT``: the integer difference of the ordered integers, or
   * ``MODE_TABLE``: the difference of ranks in the channel's sorted table of distinct values, which
     is sent once up front (worth it when a channel has few distinct values),

   in a context of ref pattern, size of the previous residual and local activity (spread of the
   refs' values).

Coding 2 (format 4) appends candidates built from the geometry of the tet being added
(:func:`_geometric_cands`): for the density, which is coded after the vertex's x, y, z, the linear
field through the ref tet (or the face's plane, or the boundary triangle) evaluated at the vertex's
decoded position; for the coordinates, the apex reflected through the face centroid and the
centroid moved along the face normal by the apex's height or a regular tet's height (across the
edge for boundary vertices). It also codes a coordinate's repetition symbol (when there are at
least two candidates) in a context of which candidate the pattern's first prediction lands
nearest: on a grid that is usually the repeated value (Blunt-fin 22.1 -> 21.3 bits per vertex,
fire 17.1 -> 16.1). The kernels learn the coding from the ``cands`` array of :func:`candidate_table`
(candidate counts per pattern, then the version).

Coding 3 (format 5) codes the same symbols with fewer range-coder steps: a residual's unmodelled
mantissa bits in steps of up to 16 (:func:`gatun_py.codec.rangecoder.enc_raw_wide`), its sign in
a context (:func:`_sign_context`), the repetition symbol as a flag "none" then an index
(:func:`_enc_repeat`), and the x -> y table per block (``cands[CAND_XY]``) as a small
direct-mapped cache (:data:`XY_CACHE_SLOTS`) instead of an exact table of the vertex count.

Coding 5 (format 9) adds *rank steps* on a channel coded with a table (``MODE_STEPS``): a vertex
whose first face ref r0 exists codes the difference of its rank and r0's rank in the table, -2 to 2
or "escape", in fast-adapting decisions (:func:`_enc_step`) in a context of where the other refs'
ranks lie around r0's (:func:`_step_context`) and whether the previous channel repeated r0's
value; an escape codes the value as coding 3 codes a table-mode channel's. On a curvilinear grid
the next vertex along a grid line is mostly one rank away on that axis (Room fire's x: 1,344 -> 187 bytes). The
repetition flags the next channel sees are the ones coding 3 would leave (the index of the first
candidate equal to the value), so every channel's stream still depends only on the values.

All prediction arithmetic is float64 on float32 inputs, rounded to float32 once, without
``fastmath``; partners are chosen from vertices < k only. Encoder and decoder run the same
kernels on the same bits, so they agree exactly. The decoder checks every ref, table index and
decoded value and returns a status instead of touching memory out of bounds.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.cpython.unsafe.numbers import leading_zeros

from .rangecoder import (
    PROB_INIT,
    INT_MODEL_SIZE,
    dec_bit,
    dec_bit_fast,
    dec_failed,
    dec_init,
    dec_sint,
    dec_sint_wide,
    dec_sym,
    dec_uint,
    enc_bit,
    enc_bit_fast,
    enc_finish,
    enc_sint,
    enc_sint_wide,
    enc_sym,
    enc_uint,
)

N_CHANNELS = 4
MODE_PREDICT = 0
MODE_TABLE = 1
MODE_SKIP = -1  # encoder only: leave the channel out of this pass
# encoder only: ranks in the channel's table like MODE_TABLE, without the table at the stream's
# start (geometry coding 4 sends each table in a stream of its own, :func:`encode_table_set`)
MODE_RANKS = 2
# geometry coding 5: ranks as MODE_RANKS, most vertices coded as a rank step from a ref
# (:func:`_step_context`); the decoder takes it for a table-mode channel so coded
MODE_STEPS = 3

# ref patterns (which of the face refs and the apex are present) and their predictor candidates
PAT_NONE, PAT_ONE, PAT_EDGE, PAT_EDGE_APEX, PAT_FACE, PAT_FACE_APEX = 0, 1, 2, 3, 4, 5
N_PATTERNS = 6
MAX_CANDS = 15
# candidates per pattern, by coding version: version 2 appends the tet-geometry predictors
# (:func:`_geometric_cands`) after version 1's, so the version-1 candidates keep their indices
N_CANDS_V1 = (1, 1, 6, 6, 10, 12)
N_CANDS_V2 = (1, 1, 6, 8, 11, 15)
CODINGS = (1, 2, 3)  # the geometry block versions these kernels decode
CAND_VERSION = N_PATTERNS  # where candidate_table keeps the coding version
CAND_XY = N_PATTERNS + 1  # and whether channel 1 uses the x -> y table


def candidate_table(version: int, xy_table: bool = True) -> np.ndarray:
    """The ``cands`` array the kernels take: the candidate count of each ref pattern, then the
    coding version (the one place the kernels learn which version they code), then whether y
    gets the repetition candidate of the x -> y table (always in codings 1 and 2; coding 3
    says per block)."""
    if version not in CODINGS:
        raise ValueError(f"unknown geometry coding version {version}")
    xy = 1 if (version < 3 or xy_table) else 0
    return np.array((N_CANDS_V1 if version == 1 else N_CANDS_V2) + (version, xy), dtype=np.int64)


# the coder's own view of the mesh: the edges from every vertex to its face refs (at most
# ADJ_CAP per vertex, the rest ignored alike by encoder and decoder)
ADJ_CAP = 8
NW = 2  # extra predictor vertices per face pair / face ref

# model layout of one channel (uint16 probabilities)
# repetition contexts: (number of distinct candidates - 1) x what the previous channel of this
# vertex did (repeat of candidate 0..4, or FLAG_PREDICTED); channel 0 uses 6 + whether the
# previous vertex's channel 0 was a repeat
EQ_FLAGS = 8
EQ_CONTEXTS = 5 * EQ_FLAGS
FLAG_PREDICTED = 5  # flag of a channel that was predicted, not repeated
EQ_BASE = 0
RES_BASE = EQ_BASE + EQ_CONTEXTS * 8
N_ACTIVITY = 10
N_RES_CONTEXTS = N_PATTERNS * 2 * N_ACTIVITY
RANK_BASE = RES_BASE + N_RES_CONTEXTS * INT_MODEL_SIZE
TABLE_BASE = RANK_BASE + N_RES_CONTEXTS * INT_MODEL_SIZE
# coding 2's repetition contexts: coding 1's times which candidate the prediction lands nearest
EQ2_BASE = TABLE_BASE + 2 * INT_MODEL_SIZE
# coding 5's rank steps: the classes of three refs' rank offsets x the previous channel's outcome
STEP_CLASSES = 6
N_STEP_CONTEXTS = STEP_CLASSES ** 3 * 3
STEP_BASE = EQ2_BASE + EQ_CONTEXTS * 5 * 8
STEP_ESCAPE = 3  # a step beyond -2 .. 2 (what _dec_step returns for it): the value is predicted instead
MODEL_SIZE = STEP_BASE + N_STEP_CONTEXTS * 8

# what _gather fills
WANT_REPEATS, WANT_BOTH, WANT_PREDICTIONS = 0, 1, 2

SCORE_SHIFT = 4  # predictor scores: exponentially decayed bit lengths, window ~16 vertices

# decoder status codes
OK = 0
ERR_STREAM = 1
ERR_REF = 2
ERR_RANK = 3


@njit(cache=True, inline="always")
def ordered_int(bits):
    """Map an int32 float bit pattern to an integer with the same order as the float."""
    b = np.int64(bits)
    if b < 0:
        b = b ^ 0x7FFFFFFF
    return b


@njit(cache=True, inline="always")
def ordered_to_bits(o):
    """Inverse of :func:`ordered_int` (``o`` must lie in the int32 range)."""
    if o < 0:
        o = o ^ 0x7FFFFFFF
    return np.int32(o)


@njit(cache=True, _nrt=False)
def _bit_length(v):
    """Number of bits of ``|v|`` (``|v| < 2**63``): one count-leading-zeros instruction."""
    if v < 0:
        v = -v
    return 64 - leading_zeros(np.int64(v))


@njit(cache=True, _nrt=False)
def _add_edge(adj, deg, x, y):
    for i in range(deg[x]):
        if adj[x, i] == y:
            return
    if deg[x] < ADJ_CAP:
        adj[x, deg[x]] = y
        deg[x] += 1


@njit(cache=True, _nrt=False)
def _link(adj, deg, x, y):
    if x >= 0 and y >= 0:
        _add_edge(adj, deg, x, y)
        _add_edge(adj, deg, y, x)


@njit(cache=True, _nrt=False)
def _dist2(vf, e0, e1, e2, x0, x1, x2):
    return (x0 - e0) ** 2 + (x1 - e1) ** 2 + (x2 - e2) ** 2


# Helpers called per vertex are compiled with ``_nrt=False`` (they never allocate): without the
# runtime's reference counting a call does not atomically increment and decrement every array
# argument, which was about a quarter of the decoder's time.
@njit(cache=True, _nrt=False)
def _pick_par(adj, deg, mark, tag, vf, x, y, ex0, ex1, e0, e1, e2):
    """The common neighbour w of x and y (not ex0/ex1) whose parallelogram x + y - w lands
    closest to the estimate e (3-D coordinates); -1 if none. ``mark`` (n,) is scratch: the
    neighbours of y are tagged with ``tag`` (unique per call) so the intersection costs O(degree)."""
    for q in range(deg[y]):
        mark[adj[y, q]] = tag
    best = -1
    bd = np.inf
    for i in range(deg[x]):
        w = adj[x, i]
        if w == ex0 or w == ex1 or mark[w] != tag:
            continue
        d = _dist2(vf, e0, e1, e2,
                   np.float64(vf[x, 0]) + np.float64(vf[y, 0]) - np.float64(vf[w, 0]),
                   np.float64(vf[x, 1]) + np.float64(vf[y, 1]) - np.float64(vf[w, 1]),
                   np.float64(vf[x, 2]) + np.float64(vf[y, 2]) - np.float64(vf[w, 2]))
        if d < bd:
            bd = d
            best = w
    return best


@njit(cache=True, _nrt=False)
def _pick_ext(adj, deg, vf, x, e0, e1, e2):
    """The neighbour w of x whose extrapolation 2 x - w lands closest to the estimate e."""
    best = -1
    bd = np.inf
    for i in range(deg[x]):
        w = adj[x, i]
        d = _dist2(vf, e0, e1, e2,
                   2.0 * np.float64(vf[x, 0]) - np.float64(vf[w, 0]),
                   2.0 * np.float64(vf[x, 1]) - np.float64(vf[w, 1]),
                   2.0 * np.float64(vf[x, 2]) - np.float64(vf[w, 2]))
        if d < bd:
            bd = d
            best = w
    return best


_pick_par_inlined = njit(cache=True, _nrt=False, inline="always")(_pick_par.py_func)
_pick_ext_inlined = njit(cache=True, _nrt=False, inline="always")(_pick_ext.py_func)


@njit(cache=True, _nrt=False)
def link_vertex(k, r0, r1, r2, r3, adj, deg, mark, w, vf):
    """Choose the extra predictor vertices of vertex ``k`` (refs checked) and record its edges.

    ``w[p, 0]``: for the pairs p = (f0, f1), (f0, f2), (f1, f2) of face refs, a common neighbour
    completing a parallelogram; ``w[q, 1]``: for face ref q, a neighbour to extrapolate from
    (2 f_q - w). Both are picked by 3-D closeness to a first estimate of the new vertex (the
    parallelepiped corner through the apex, or the face centroid), using only vertices < k, so
    the decoder can do the same before decoding vertex k. ``mark`` (n,) int32 scratch, zero
    at the start.
    """
    f0 = np.int64(-1)
    f1 = np.int64(-1)
    f2 = np.int64(-1)
    nf = 0
    for q in range(3):
        r = r0 if q == 0 else (r1 if q == 1 else r2)
        if r >= 0:
            if nf == 0:
                f0 = r
            elif nf == 1:
                f1 = r
            else:
                f2 = r
            nf += 1
    apex = r3
    for p in range(3):
        w[p, 0] = -1
        w[p, 1] = -1
    if nf >= 2:
        e0 = 0.0
        e1 = 0.0
        e2 = 0.0
        for c in range(3):
            a = np.float64(vf[f0, c])
            b = np.float64(vf[f1, c])
            if nf == 3:
                cc = np.float64(vf[f2, c])
                if apex >= 0:
                    est = (a + b + cc - np.float64(vf[apex, c])) * 0.5
                else:
                    est = (a + b + cc) / 3.0
            elif apex >= 0:
                est = a + b - np.float64(vf[apex, c])
            else:
                est = (a + b) * 0.5
            if c == 0:
                e0 = est
            elif c == 1:
                e1 = est
            else:
                e2 = est
        # pairs (f0, f1), (f0, f2), (f1, f2) and face refs f0, f1, f2 in loops around one inlined
        # copy of each pick (called, each passed four arrays: a fifth of the geometry decode);
        # the picks are independent (each pair's tag is its own), so their order is free
        for p in range(1 if nf == 2 else 3):
            x = f0 if p < 2 else f1
            y = f1 if p == 0 else f2
            other = f2 if p == 0 else (f1 if p == 1 else f0)
            w[p, 0] = _pick_par_inlined(adj, deg, mark, 3 * k + 1 + p, vf, x, y, other, apex, e0, e1, e2)
        for q in range(nf):
            x = f0 if q == 0 else (f1 if q == 1 else f2)
            w[q, 1] = _pick_ext_inlined(adj, deg, vf, x, e0, e1, e2)
    # every pair among the new vertex, its face and the apex is a mesh edge, except
    # new vertex - apex (they sit on either side of the face)
    _link(adj, deg, k, f0)
    _link(adj, deg, k, f1)
    _link(adj, deg, k, f2)



@njit(cache=True, _nrt=False)
def _par(vf, ch, x, y, w, fallback):
    if w < 0:
        return fallback
    return np.float64(vf[x, ch]) + np.float64(vf[y, ch]) - np.float64(vf[w, ch])


@njit(cache=True, _nrt=False)
def _ext(vf, ch, x, w, fallback):
    if w < 0:
        return fallback
    return 2.0 * np.float64(vf[x, ch]) - np.float64(vf[w, ch])


@njit(cache=True)
def hash_capacity(n):
    """Slots of the x -> y table for n vertices (a power of two, at most half full)."""
    cap = 16
    while cap < 2 * n + 2:
        cap *= 2
    return cap


# Coding 3's x -> y table is a direct-mapped cache of this many slots (a new x evicts whatever
# shared its slot): a grid has few distinct x (Blunt-fin 876, fire 41), and 64 KB stay in cache
# where the exact table, 16-24 bytes per vertex, cost a cache miss per vertex on large meshes.
XY_CACHE_SLOTS = 1 << 13


def xy_table_slots(n: int, version: int) -> int:
    """Slots of the decoder's x -> y table for n vertices in this coding."""
    return XY_CACHE_SLOTS if version >= 3 else hash_capacity((3 * n) // 4 + 1)


@njit(cache=True, inline="always")
def _hash_slot(slots, used, x, version):
    """Slot of key x (an ordered int) in the open-addressing table: its slot or a free one
    (coding 3: the one slot of x in the direct-mapped cache, whatever it holds)."""
    mask = slots.shape[0] - 1
    # multiplicative hashing, high bits: float bit patterns often end in runs of zero bits
    h = ((x * -7046029254386353131) >> 32) & mask
    if version >= 3:
        return h
    while used[h] != 0 and (slots[h] >> 32) != x:
        h = (h + 1) & mask
    return h


@njit(cache=True, inline="always")
def _add_conditional(ch, k, vi, slots, used, eq_o, m, cands):
    """Channel 1 (y) gets one more repetition candidate: the y last seen with this vertex's x
    (curvilinear grids repeat whole (x, y) columns). Returns the new candidate count."""
    if ch != 1 or cands[CAND_XY] == 0:
        return m
    x = ordered_int(vi[k, 0])
    h = _hash_slot(slots, used, x, cands[CAND_VERSION])
    if used[h] == 0 or (slots[h] >> 32) != x:
        return m
    v = ((slots[h] & 0xFFFFFFFF) ^ 0x80000000) - 0x80000000  # low half, sign-extended
    for q in range(m):
        if eq_o[q] == v:
            return m
    eq_o[m] = v
    return m + 1


@njit(cache=True, inline="always")
def _remember_conditional(ch, k, vi, slots, used, cands):
    if ch == 1 and cands[CAND_XY] != 0:
        x = ordered_int(vi[k, 0])
        h = _hash_slot(slots, used, x, cands[CAND_VERSION])
        slots[h] = (x << 32) | (ordered_int(vi[k, 1]) & 0xFFFFFFFF)  # key and value in one word
        used[h] = 1

# Version 2's tet-geometry predictors. All float64 on float32 inputs, no fastmath, the same
# kernels in encoder and decoder: the predictions agree bit for bit. A prediction that leaves the
# tet's neighbourhood (barycentric weight beyond MAX_WEIGHT, as on the flat tets of collapsed grid
# cells) falls back to a value the decoder knows anyway.
MAX_WEIGHT = 4.0
# height of a regular tet over the square root of its face area: sqrt(8 / (3 sqrt(3)))
REGULAR_HEIGHT = 1.2408064788027995


@njit(cache=True, _nrt=False)
def _tri_linear(vf, k, p0, p1, p2, ch, fallback):
    """The linear field through triangle (p0, p1, p2) on channel ``ch``, at the orthogonal
    projection of vertex k's position into the triangle's plane (least squares in the plane)."""
    e11 = 0.0
    e12 = 0.0
    e22 = 0.0
    r1 = 0.0
    r2 = 0.0
    for c in range(3):
        a = np.float64(vf[p1, c]) - np.float64(vf[p0, c])
        b = np.float64(vf[p2, c]) - np.float64(vf[p0, c])
        r = np.float64(vf[k, c]) - np.float64(vf[p0, c])
        e11 += a * a
        e12 += a * b
        e22 += b * b
        r1 += r * a
        r2 += r * b
    det = e11 * e22 - e12 * e12
    if not det > 1e-12 * e11 * e22:  # also NaN and inf: a flat or broken triangle
        return fallback
    u = (r1 * e22 - r2 * e12) / det
    v = (r2 * e11 - r1 * e12) / det
    if not (abs(u) <= MAX_WEIGHT and abs(v) <= MAX_WEIGHT):
        return fallback
    s0 = np.float64(vf[p0, ch])
    return s0 + u * (np.float64(vf[p1, ch]) - s0) + v * (np.float64(vf[p2, ch]) - s0)


@njit(cache=True, _nrt=False)
def _tet_linear(vf, k, p0, p1, p2, p3, ch, fallback):
    """The linear field through tet (p0, p1, p2, p3) on channel ``ch`` at vertex k's position
    (its barycentric coordinates by Cramer's rule)."""
    ax = np.float64(vf[p1, 0]) - np.float64(vf[p0, 0])
    ay = np.float64(vf[p1, 1]) - np.float64(vf[p0, 1])
    az = np.float64(vf[p1, 2]) - np.float64(vf[p0, 2])
    bx = np.float64(vf[p2, 0]) - np.float64(vf[p0, 0])
    by = np.float64(vf[p2, 1]) - np.float64(vf[p0, 1])
    bz = np.float64(vf[p2, 2]) - np.float64(vf[p0, 2])
    cx = np.float64(vf[p3, 0]) - np.float64(vf[p0, 0])
    cy = np.float64(vf[p3, 1]) - np.float64(vf[p0, 1])
    cz = np.float64(vf[p3, 2]) - np.float64(vf[p0, 2])
    rx = np.float64(vf[k, 0]) - np.float64(vf[p0, 0])
    ry = np.float64(vf[k, 1]) - np.float64(vf[p0, 1])
    rz = np.float64(vf[k, 2]) - np.float64(vf[p0, 2])
    # b x c, c x a, a x b: the rows of the inverse (times det)
    bcx = by * cz - bz * cy
    bcy = bz * cx - bx * cz
    bcz = bx * cy - by * cx
    cax = cy * az - cz * ay
    cay = cz * ax - cx * az
    caz = cx * ay - cy * ax
    abx = ay * bz - az * by
    aby = az * bx - ax * bz
    abz = ax * by - ay * bx
    det = ax * bcx + ay * bcy + az * bcz
    scale = np.sqrt((ax * ax + ay * ay + az * az) * (bx * bx + by * by + bz * bz) * (cx * cx + cy * cy + cz * cz))
    if not abs(det) > 1e-9 * scale:  # also NaN and inf: a flat or broken tet
        return fallback
    l1 = (rx * bcx + ry * bcy + rz * bcz) / det
    l2 = (rx * cax + ry * cay + rz * caz) / det
    l3 = (rx * abx + ry * aby + rz * abz) / det
    if not (abs(l1) <= MAX_WEIGHT and abs(l2) <= MAX_WEIGHT and abs(l3) <= MAX_WEIGHT):
        return fallback
    s0 = np.float64(vf[p0, ch])
    return (s0 + l1 * (np.float64(vf[p1, ch]) - s0) + l2 * (np.float64(vf[p2, ch]) - s0)
            + l3 * (np.float64(vf[p3, ch]) - s0))


@njit(cache=True, _nrt=False)
def _beyond_face(vf, f0, f1, f2, apex, ch, scratch_f, at, fallback):
    """Coordinate ``ch`` of three predictions of the vertex that closes face (f0, f1, f2) on the
    side away from the apex, into ``scratch_f[at:at + 3]``: the apex reflected through the face
    centroid g (2 g - d), and g plus the unit normal times the apex's height over the face or
    times a regular tet's height for the face's area."""
    g0 = (np.float64(vf[f0, 0]) + np.float64(vf[f1, 0]) + np.float64(vf[f2, 0])) / 3.0
    g1 = (np.float64(vf[f0, 1]) + np.float64(vf[f1, 1]) + np.float64(vf[f2, 1])) / 3.0
    g2 = (np.float64(vf[f0, 2]) + np.float64(vf[f1, 2]) + np.float64(vf[f2, 2])) / 3.0
    ax = np.float64(vf[f1, 0]) - np.float64(vf[f0, 0])
    ay = np.float64(vf[f1, 1]) - np.float64(vf[f0, 1])
    az = np.float64(vf[f1, 2]) - np.float64(vf[f0, 2])
    bx = np.float64(vf[f2, 0]) - np.float64(vf[f0, 0])
    by = np.float64(vf[f2, 1]) - np.float64(vf[f0, 1])
    bz = np.float64(vf[f2, 2]) - np.float64(vf[f0, 2])
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    gc = g0 if ch == 0 else (g1 if ch == 1 else g2)
    scratch_f[at] = 2.0 * gc - np.float64(vf[apex, ch])
    if not (norm > 0.0 and norm < np.inf):
        scratch_f[at + 1] = fallback
        scratch_f[at + 2] = fallback
        return
    h = ((np.float64(vf[apex, 0]) - g0) * nx + (np.float64(vf[apex, 1]) - g1) * ny
         + (np.float64(vf[apex, 2]) - g2) * nz) / norm
    n_c = (nx if ch == 0 else (ny if ch == 1 else nz)) / norm
    if h > 0.0:  # the normal towards the side away from the apex
        n_c = -n_c
        h = -h
    scratch_f[at + 1] = gc - n_c * h
    scratch_f[at + 2] = gc + n_c * (REGULAR_HEIGHT * np.sqrt(0.5 * norm))


EQUILATERAL_HEIGHT = 0.8660254037844386  # sqrt(3) / 2


@njit(cache=True, _nrt=False)
def _beyond_edge(vf, f0, f1, apex, ch, scratch_f, at, fallback):
    """Coordinate ``ch`` of two predictions of the vertex across edge (f0, f1) from the apex (a
    boundary triangle strip), into ``scratch_f[at:at + 2]``: the edge midpoint m minus the apex's
    offset perpendicular to the edge, and m minus the unit perpendicular times an equilateral
    triangle's height on the edge."""
    ex = np.float64(vf[f1, 0]) - np.float64(vf[f0, 0])
    ey = np.float64(vf[f1, 1]) - np.float64(vf[f0, 1])
    ez = np.float64(vf[f1, 2]) - np.float64(vf[f0, 2])
    mx = (np.float64(vf[f0, 0]) + np.float64(vf[f1, 0])) * 0.5
    my = (np.float64(vf[f0, 1]) + np.float64(vf[f1, 1])) * 0.5
    mz = (np.float64(vf[f0, 2]) + np.float64(vf[f1, 2])) * 0.5
    e2 = ex * ex + ey * ey + ez * ez
    if not (e2 > 0.0 and e2 < np.inf):
        scratch_f[at] = fallback
        scratch_f[at + 1] = fallback
        return
    dx = np.float64(vf[apex, 0]) - mx
    dy = np.float64(vf[apex, 1]) - my
    dz = np.float64(vf[apex, 2]) - mz
    t = (dx * ex + dy * ey + dz * ez) / e2
    px = dx - t * ex  # the apex's offset from the edge's line, perpendicular to it
    py = dy - t * ey
    pz = dz - t * ez
    m_c = mx if ch == 0 else (my if ch == 1 else mz)
    p_c = px if ch == 0 else (py if ch == 1 else pz)
    scratch_f[at] = m_c - p_c
    plen = np.sqrt(px * px + py * py + pz * pz)
    if not (plen > 0.0 and plen < np.inf):
        scratch_f[at + 1] = fallback
        return
    scratch_f[at + 1] = m_c - p_c / plen * (EQUILATERAL_HEIGHT * np.sqrt(e2))


@njit(cache=True, _nrt=False, inline="always")  # its one call site, in _gather (a call passed two arrays)
def _geometric_cands(k, face0, face1, face2, apex, nf, vf, ch, scratch_f, nc):
    """Version 2's candidates, appended at ``scratch_f[nc:]``; returns the new count.

    Density (channel 3, coded after the vertex's x, y, z): the linear field through the ref tet
    (face + apex) at the vertex, through the face's plane, and between them and the face centroid;
    through the boundary triangle (edge + apex) for a boundary vertex. Coordinates: the reflections
    of :func:`_beyond_face` (interior vertices); the parallelogram again elsewhere (a place holder
    that keeps the candidate count fixed per pattern).
    """
    if nf == 3 and apex >= 0:
        if ch == 3:
            centroid = scratch_f[1]
            plane = _tri_linear(vf, k, face0, face1, face2, ch, centroid)
            scratch_f[nc] = _tet_linear(vf, k, face0, face1, face2, apex, ch, plane)
            scratch_f[nc + 1] = plane
            scratch_f[nc + 2] = 0.5 * (np.float64(scratch_f[nc]) + np.float64(centroid))
        else:
            _beyond_face(vf, face0, face1, face2, apex, ch, scratch_f, nc, scratch_f[0])
        return nc + 3
    if nf == 3:
        scratch_f[nc] = _tri_linear(vf, k, face0, face1, face2, ch, scratch_f[0]) if ch == 3 else scratch_f[0]
        return nc + 1
    if nf == 2 and apex >= 0:
        if ch == 3:
            tri = _tri_linear(vf, k, face0, face1, apex, ch, scratch_f[0])
            scratch_f[nc] = tri
            scratch_f[nc + 1] = 0.5 * (np.float64(scratch_f[nc]) + np.float64(scratch_f[0]))
        else:
            _beyond_edge(vf, face0, face1, apex, ch, scratch_f, nc, scratch_f[0])
        return nc + 2
    return nc


@njit(cache=True, inline="always")
def _repeat_candidates(a, b, c, d, vi, ch, eq_o):
    """The distinct values of vertices a, b, c, d (those not -1) on channel ch, in that order,
    into ``eq_o``; returns their count."""
    m = 0
    for j in range(4):
        r = a if j == 0 else (b if j == 1 else (c if j == 2 else d))
        if r < 0:
            continue
        o = ordered_int(vi[r, ch])
        dup = False
        for q in range(m):
            if eq_o[q] == o:
                dup = True
        if not dup:
            eq_o[m] = o
            m += 1
    return m


@njit(cache=True, _nrt=False)
def _gather(k, r0, r1, r2, r3, ws, vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i, need_cands, version):
    """Predictor candidates and distinct repetition candidates of vertex ``k`` on channel ``ch``.

    ``r0, r1, r2`` are the face refs and ``r3`` the apex (each ``-1`` or a checked id ``< k``).
    Fills ``cand_o[:n]`` (n: the pattern's entry of :func:`candidate_table`; ordered ints of the predictions) and ``eq_o[:m]`` (the
    distinct ordered ints of the refs' values, in ref order); returns ``(pattern, m)``. ``need_cands``:
    ``WANT_REPEATS`` fills only the repetition candidates (a repeated value needs no prediction),
    ``WANT_BOTH`` both, ``WANT_PREDICTIONS`` only the predictions (m is then 0: the caller kept the
    repetition candidates of its first call, which are the same).
    """
    face0 = np.int64(-1)
    face1 = np.int64(-1)
    face2 = np.int64(-1)
    nf = 0
    for j in range(3):
        r = r0 if j == 0 else (r1 if j == 1 else r2)
        if r >= 0:
            if nf == 0:
                face0 = r
            elif nf == 1:
                face1 = r
            else:
                face2 = r
            nf += 1
    apex = r3
    if nf == 0:
        # no face: predict from the apex, else from the previous vertex (unreferenced vertices)
        if apex >= 0:
            face0 = apex
            apex = -1
            nf = 1
        elif k > 0:
            face0 = k - 1
            nf = 1
    m = 0
    if need_cands != WANT_PREDICTIONS:
        m = _repeat_candidates(face0, face1, face2, apex, vi, ch, eq_o)
    if nf == 0:
        cand_o[0] = 0
        return PAT_NONE, m
    if nf == 1:
        cand_o[0] = ordered_int(vi[face0, ch])
        return PAT_ONE, m
    if need_cands == WANT_REPEATS:
        if nf == 2:
            return (PAT_EDGE_APEX if apex >= 0 else PAT_EDGE), m
        return (PAT_FACE_APEX if apex >= 0 else PAT_FACE), m
    a = np.float64(vf[face0, ch])
    b = np.float64(vf[face1, ch])
    if nf == 2:
        nc = 6
        if apex >= 0:
            d = np.float64(vf[apex, ch])
            scratch_f[0] = a + b - d  # parallelogram across the edge
            scratch_f[1] = (a + b) * 0.5
            scratch_f[2] = a
            scratch_f[3] = _par(vf, ch, face0, face1, ws[0, 0], a + b - d)
            scratch_f[4] = _ext(vf, ch, face0, ws[0, 1], a + b - d)
            scratch_f[5] = _ext(vf, ch, face1, ws[1, 1], a + b - d)
            pat = PAT_EDGE_APEX
        else:
            scratch_f[0] = (a + b) * 0.5
            scratch_f[1] = a
            scratch_f[2] = b
            scratch_f[3] = _par(vf, ch, face0, face1, ws[0, 0], (a + b) * 0.5)
            scratch_f[4] = _ext(vf, ch, face0, ws[0, 1], (a + b) * 0.5)
            scratch_f[5] = _ext(vf, ch, face1, ws[1, 1], (a + b) * 0.5)
            pat = PAT_EDGE
    else:
        c = np.float64(vf[face2, ch])
        if apex >= 0:
            d = np.float64(vf[apex, ch])
            # the far corner of the parallelepiped spanned by the apex and the face (exact on the
            # 5-tet split of a uniform hexahedral grid), then the face centroid and parallelograms
            scratch_f[0] = (a + b + c - d) * 0.5
            scratch_f[1] = (a + b + c) / 3.0
            scratch_f[2] = a + b - d
            scratch_f[3] = a + c - d
            scratch_f[4] = b + c - d
            scratch_f[5] = a
            h = scratch_f[0]
            scratch_f[6] = _par(vf, ch, face0, face1, ws[0, 0], h)
            scratch_f[7] = _par(vf, ch, face0, face2, ws[1, 0], h)
            scratch_f[8] = _par(vf, ch, face1, face2, ws[2, 0], h)
            scratch_f[9] = _ext(vf, ch, face0, ws[0, 1], h)
            scratch_f[10] = _ext(vf, ch, face1, ws[1, 1], h)
            scratch_f[11] = _ext(vf, ch, face2, ws[2, 1], h)
            pat = PAT_FACE_APEX
            nc = 12
        else:
            scratch_f[0] = (a + b + c) / 3.0
            scratch_f[1] = a
            scratch_f[2] = b
            scratch_f[3] = c
            h = scratch_f[0]
            scratch_f[4] = _par(vf, ch, face0, face1, ws[0, 0], h)
            scratch_f[5] = _par(vf, ch, face0, face2, ws[1, 0], h)
            scratch_f[6] = _par(vf, ch, face1, face2, ws[2, 0], h)
            scratch_f[7] = _ext(vf, ch, face0, ws[0, 1], h)
            scratch_f[8] = _ext(vf, ch, face1, ws[1, 1], h)
            scratch_f[9] = _ext(vf, ch, face2, ws[2, 1], h)
            pat = PAT_FACE
            nc = 10
    if version >= 2:
        # int64 casts: numba would otherwise compile a copy per call site that sees a literal -1
        nc = _geometric_cands(k, np.int64(face0), np.int64(face1), np.int64(face2), np.int64(apex), nf, vf, ch,
                              scratch_f, nc)
    for q in range(nc):
        if scratch_f[q] != scratch_f[q]:  # NaN: payload bits are not portable, predict 0
            scratch_f[q] = 0.0
        cand_o[q] = ordered_int(scratch_i[q])
    return pat, m


@njit(cache=True, _nrt=False)
def _first_prediction(k, r0, r1, r2, r3, vf, vi, ch, scratch_f, scratch_i):
    """Coding 2's repetition context: the ordered integer of the first candidate of the vertex's
    pattern, as :func:`_gather` computes it (the parallelepiped corner, the parallelogram, the
    centroid, or the one ref's value): a cheap prediction. Uses ``scratch_f[0]``."""
    a = 0.0
    b = 0.0
    c = 0.0
    one = -1
    nf = 0
    for j in range(3):
        r = r0 if j == 0 else (r1 if j == 1 else r2)
        if r >= 0:
            v = np.float64(vf[r, ch])
            if nf == 0:
                a = v
                one = r
            elif nf == 1:
                b = v
            else:
                c = v
            nf += 1
    if nf == 0:
        one = r3 if r3 >= 0 else k - 1
    if nf <= 1:
        return ordered_int(vi[one, ch]) if one >= 0 else np.int64(0)
    if nf == 2:
        scratch_f[0] = a + b - np.float64(vf[r3, ch]) if r3 >= 0 else (a + b) * 0.5
    else:
        scratch_f[0] = (a + b + c - np.float64(vf[r3, ch])) * 0.5 if r3 >= 0 else (a + b + c) / 3.0
    if scratch_f[0] != scratch_f[0]:  # NaN: as _gather, predict 0
        scratch_f[0] = 0.0
    return ordered_int(scratch_i[0])


@njit(cache=True, _nrt=False)
def _nearest(eq_o, m, pred):
    """Index of the repetition candidate nearest to the prediction (the first of equals)."""
    near = 0
    d = abs(eq_o[0] - pred)
    for q in range(1, m):
        dq = abs(eq_o[q] - pred)
        if dq < d:
            d = dq
            near = q
    return near


@njit(cache=True, inline="always")
def _eq_context(m, flag, near, version):
    """Model offset of the repetition symbol: (candidates, what the previous channel did) and,
    in coding 2, which candidate the prediction lands nearest (``near``)."""
    if version < 2:
        return EQ_BASE + ((m - 1) * EQ_FLAGS + flag) * 8
    return EQ2_BASE + (((m - 1) * EQ_FLAGS + flag) * 5 + near) * 8


@njit(cache=True, inline="always")
def _best_cand(scores, ch, pat, cands):
    """The candidate with the lowest score (the first of equals)."""
    row = scores[ch, pat]
    best = 0
    lowest = row[0]
    for q in range(1, cands[pat]):
        if row[q] < lowest:
            lowest = row[q]
            best = q
    return best


@njit(cache=True, inline="always")  # once per coded value in the decoder loop, where LLVM left a call
def _update_scores(scores, ch, pat, cand_o, o, cands):
    row = scores[ch, pat]
    for q in range(cands[pat]):
        s = row[q]
        row[q] = s - (s >> SCORE_SHIFT) + (_bit_length(o - cand_o[q]) << 4)


@njit(cache=True, _nrt=False)
def _enc_residual(st, out, probs, base, res, version, sign_context):
    """Code a residual: coding 3 sends its unmodelled mantissa bits in wide range-coder steps and
    codes the sign in a context (:func:`_sign_context`)."""
    if version >= 3:
        enc_sint_wide(st, out, probs, base, res, sign_context)
    else:
        enc_sint(st, out, probs, base, res)


@njit(cache=True, inline="always")
def _dec_residual(st, data, probs, base, version, sign_context):
    if version >= 3:
        return dec_sint_wide(st, data, probs, base, sign_context)
    return dec_sint(st, data, probs, base)


@njit(cache=True, inline="always")
def _sign_context(cand_o, best):
    """Coding 3's guess of a prediction residual's sign: whether the pattern's first candidate (a
    plain combination of the refs, always computed) lies above the chosen prediction."""
    return 1 if cand_o[0] > cand_o[best] else 0


@njit(cache=True, inline="always")
def _search(table, lo, hi, o):
    """First index i in [lo, hi) with table[i] >= o (``hi`` if none)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if table[mid] < o:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _res_context(pat, big, eq_o, m):
    """Residual context: ref pattern, size of the previous residual, and the local activity
    (bit length of the spread of the refs' distinct values, in 10 classes): where the refs differ
    a lot, the residual tends to be large too."""
    lo = eq_o[0]
    hi = eq_o[0]
    for q in range(1, m):
        if eq_o[q] < lo:
            lo = eq_o[q]
        if eq_o[q] > hi:
            hi = eq_o[q]
    act = 0
    if m > 1:
        act = (_bit_length(hi - lo) + 3) // 4
        if act > N_ACTIVITY - 1:
            act = N_ACTIVITY - 1
    return (pat * 2 + big) * N_ACTIVITY + act


@njit(cache=True, _nrt=False)
def _eq_bits(m):
    """Bits of the repetition symbol, which takes the m + 1 values 0 .. m (m = "none")."""
    return 1 if m == 1 else (2 if m <= 3 else 3)


@njit(cache=True, _nrt=False)
def _index_bits(m):
    """Coding 3: bits of the index of the repeated candidate among m."""
    return 0 if m == 1 else (1 if m == 2 else (2 if m <= 4 else 3))


@njit(cache=True)
def _enc_repeat(st, out, probs, ctx, m, sym, version):
    """Code the repetition symbol at ``probs[ctx:ctx + 8]``: codings 1-2 as one bit tree of the
    m + 1 values; coding 3 as a flag "none of them" (slot 0, unused by the tree), then the index
    of the repeated one (a tree of :func:`_index_bits` bits): a vertex that repeats nothing, as
    every vertex of an unstructured mesh, costs one binary decision per channel instead of three."""
    if version < 3:
        enc_sym(st, out, probs, ctx, _eq_bits(m), sym)
        return
    enc_bit(st, out, probs, ctx, 1 if sym == m else 0)
    nb = _index_bits(m)
    if sym < m and nb > 0:
        enc_sym(st, out, probs, ctx, nb, sym)


@njit(cache=True, _nrt=False)
def _dec_repeat(st, data, probs, ctx, m, version):
    """Decode a symbol of :func:`_enc_repeat` (``m + 1`` for an index out of range: corruption)."""
    if version < 3:
        return dec_sym(st, data, probs, ctx, _eq_bits(m))
    if dec_bit(st, data, probs, ctx) == 1:
        return m
    nb = _index_bits(m)
    if nb == 0:
        return 0
    q = dec_sym(st, data, probs, ctx, nb)
    return q if q < m else m + 1


@njit(cache=True, inline="always")
def _is_big(mode, res):
    if mode == MODE_TABLE:
        return 1 if (res > 2 or res < -2) else 0
    return 1 if _bit_length(res) > 12 else 0


@njit(cache=True, inline="always")
def _step_class(rk, ch, r, base):
    """Class of ref r's rank offset from ``base`` on channel ch: 0 no ref, 1 at most -2, 2 -1,
    3 0, 4 +1, 5 at least +2."""
    if r < 0:
        return 0
    d = np.int64(rk[r, ch]) - base
    if d <= -2:
        return 1
    if d >= 2:
        return 5
    return 3 + d


@njit(cache=True, inline="always")
def _step_context(rk, ch, base, r1, r2, r3, flag):
    """Model offset of coding 5's step symbol of a vertex whose first ref has rank ``base``: the
    classes of the other refs' rank offsets (on a grid they say which way the grid line runs) and
    whether the previous channel of the vertex repeated its first ref's value (``flag`` 0)."""
    prev = 0 if ch == 0 else (1 if flag == 0 else 2)
    c = (_step_class(rk, ch, r1, base) * STEP_CLASSES + _step_class(rk, ch, r2, base)) * STEP_CLASSES
    return STEP_BASE + ((c + _step_class(rk, ch, r3, base)) * 3 + prev) * 8


@njit(cache=True, _nrt=False)
def _enc_step(st, out, probs, ctx, step):
    """Code a rank step at ``probs[ctx:ctx + 5]`` (fast-adapting decisions): zero or not, then one
    or not and its sign, then two or not (an escape: beyond -2 .. 2) and its sign."""
    enc_bit_fast(st, out, probs, ctx, 0 if step == 0 else 1)
    if step == 0:
        return
    a = abs(step)
    enc_bit_fast(st, out, probs, ctx + 1, 0 if a == 1 else 1)
    if a == 1:
        enc_bit_fast(st, out, probs, ctx + 2, 1 if step > 0 else 0)
        return
    enc_bit_fast(st, out, probs, ctx + 3, 0 if a == 2 else 1)
    if a == 2:
        enc_bit_fast(st, out, probs, ctx + 4, 1 if step > 0 else 0)


@njit(cache=True, _nrt=False)
def _dec_step(st, data, probs, ctx):
    """Decode a step of :func:`_enc_step`: -2 .. 2, or STEP_ESCAPE."""
    if dec_bit_fast(st, data, probs, ctx) == 0:
        return 0
    if dec_bit_fast(st, data, probs, ctx + 1) == 0:
        return 1 if dec_bit_fast(st, data, probs, ctx + 2) == 1 else -1
    if dec_bit_fast(st, data, probs, ctx + 3) == 1:
        return STEP_ESCAPE
    return 2 if dec_bit_fast(st, data, probs, ctx + 4) == 1 else -2


@njit(cache=True, _nrt=False)
def _store_rank(rk, k, ch, tables, lo, hi, o):
    """Store the rank of vertex k's value ``o`` (coded without a step) in the table
    ``tables[lo:hi]``; False if the value is not in the table (damage)."""
    rank = _search(tables, lo, hi, o) - lo
    if rank >= hi - lo or tables[lo + rank] != o:
        return False
    rk[k, ch] = rank
    return True


@njit(cache=True, inline="always")
def _match(eq_o, m, o):
    """The repetition flag a value leaves for the next channel: the index of the first candidate
    equal to it, else FLAG_PREDICTED."""
    for q in range(m):
        if eq_o[q] == o:
            return q
    return FLAG_PREDICTED


# ------------------------------------------------------------------------------------ encoder


@njit(cache=True, nogil=True)
def link_all(refs, vf):
    """:func:`link_vertex` for every vertex in turn (the encoder knows all values up front)."""
    n = vf.shape[0]
    adj = np.zeros((n, ADJ_CAP), dtype=np.int32)
    deg = np.zeros(n, dtype=np.int32)
    mark = np.zeros(n, dtype=np.int32)
    wpar = np.zeros((n, 3, NW), dtype=np.int32)
    for k in range(n):
        link_vertex(k, refs[k, 0], refs[k, 1], refs[k, 2], refs[k, 3], adj, deg, mark, wpar[k], vf)
    return wpar


@njit(cache=True, nogil=True)
def encode_kernel(st, out, vf, refs, wpar, modes, tables, tab_offs, cands, trace):
    """Encode every vertex into four channel streams.

    ``st`` (4, 8) encoder states, ``out`` (4, cap) uint8 buffers, ``vf`` (n, 4) float32 values,
    ``refs`` (n, 4) checked refs, ``wpar`` (n, 3, NW) from :func:`link_all`, ``modes`` (4,)
    per-channel mode (``MODE_SKIP``: only the repeat flags; ``MODE_RANKS``: as ``MODE_TABLE``
    without coding the table itself), ``tables`` the sorted distinct ordered
    ints of the table-mode channels (channel ch at ``tables[tab_offs[ch]:tab_offs[ch+1]]``).
    Returns the byte count of each stream (larger than ``out.shape[1]`` on overflow). If
    ``trace`` has n rows, ``trace[k, ch]`` records the coded (repetition symbol or -1, residual,
    predictor index) for the tests.

    The channels are coded one after the other (a channel predicts from its own values; the
    context of channel ch > 0 is what channel ch - 1 of the same vertex did, and channel 1 also
    looks channel 0 up in an x -> y table), which the decoder reproduces vertex by vertex.
    """
    n = vf.shape[0]
    vi = vf.view(np.int32)
    version = cands[CAND_VERSION]
    scores = np.zeros((N_CHANNELS, N_PATTERNS, MAX_CANDS), dtype=np.int64)
    cand_o = np.zeros(MAX_CANDS, dtype=np.int64)
    eq_o = np.zeros(5, dtype=np.int64)
    scratch_f = np.zeros(MAX_CANDS, dtype=np.float32)
    scratch_i = scratch_f.view(np.int32)
    was_eq = np.zeros(n, dtype=np.int8)
    nbytes = np.zeros(N_CHANNELS, dtype=np.int64)
    any_steps = False
    for ch in range(N_CHANNELS):
        any_steps = any_steps or modes[ch] == MODE_STEPS
    rk = np.zeros((n if any_steps else 1, N_CHANNELS), dtype=np.int32)  # coding 5: every vertex's ranks

    tracing = trace.shape[0] == n
    hcap = (XY_CACHE_SLOTS if version >= 3 else hash_capacity(n)) if cands[CAND_XY] != 0 else 1
    for ch in range(N_CHANNELS):
        hkeys = np.zeros(hcap if ch == 1 else 1, dtype=np.int64)
        hvals = np.zeros(hcap if ch == 1 else 1, dtype=np.uint8)
        stc = st[ch]
        outc = out[ch]
        probs = np.full(MODEL_SIZE, PROB_INIT, dtype=np.uint16)
        mode = modes[ch]
        lo = tab_offs[ch]
        hi = tab_offs[ch + 1]
        if mode == MODE_SKIP:
            # not coded in this pass, but the next channel's contexts need its repeat symbols
            for k in range(n):
                pat, m = _gather(k, refs[k, 0], refs[k, 1], refs[k, 2], refs[k, 3], wpar[k],
                                 vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i, WANT_REPEATS, version)
                m = _add_conditional(ch, k, vi, hkeys, hvals, eq_o, m, cands)
                was_eq[k] = _match(eq_o, m, ordered_int(vi[k, ch]))
                _remember_conditional(ch, k, vi, hkeys, hvals, cands)
            continue
        steps = mode == MODE_STEPS
        if mode == MODE_RANKS or mode == MODE_STEPS:
            mode = MODE_TABLE
        elif mode == MODE_TABLE:
            enc_uint(stc, outc, probs, TABLE_BASE, hi - lo)
            if hi > lo:
                enc_sint(stc, outc, probs, TABLE_BASE + INT_MODEL_SIZE, tables[lo])
                for i in range(lo + 1, hi):
                    enc_uint(stc, outc, probs, TABLE_BASE, tables[i] - tables[i - 1] - 1)
        if steps:
            for k in range(n):
                rk[k, ch] = _search(tables, lo, hi, ordered_int(vi[k, ch])) - lo
        last_eq = 0
        big = 0
        for k in range(n):
            pat, m = _gather(k, refs[k, 0], refs[k, 1], refs[k, 2], refs[k, 3], wpar[k],
                             vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i, WANT_REPEATS, version)
            m = _add_conditional(ch, k, vi, hkeys, hvals, eq_o, m, cands)
            o = ordered_int(vi[k, ch])
            is_eq = 0
            sym = -1
            res = np.int64(0)
            best = -1
            stepped = False
            if steps and refs[k, 0] >= 0:
                base = np.int64(rk[refs[k, 0], ch])
                step = np.int64(rk[k, ch]) - base
                ctx = _step_context(rk, ch, base, refs[k, 1], refs[k, 2], refs[k, 3], was_eq[k] if ch > 0 else 0)
                _enc_step(stc, outc, probs, ctx, step)
                stepped = step >= -2 and step <= 2  # else an escape: coded as without steps
            if stepped:
                # the next channel's context as if the value were coded without steps
                sym = _match(eq_o, m, o)
                is_eq = 1 if sym != FLAG_PREDICTED else 0
                predict = False
            elif m > 0:
                flag = was_eq[k] if ch > 0 else 6 + last_eq
                sym = m
                for q in range(m):
                    if eq_o[q] == o:
                        sym = q
                        break
                near = 0
                if version >= 2 and m >= 2 and ch < 3:
                    near = _nearest(eq_o, m, _first_prediction(k, refs[k, 0], refs[k, 1], refs[k, 2], refs[k, 3],
                                                               vf, vi, ch, scratch_f, scratch_i))
                _enc_repeat(stc, outc, probs, _eq_context(m, flag, near, version), m, sym, version)
                is_eq = 1 if sym < m else 0
                predict = is_eq == 0
            else:
                predict = True
            if predict:
                pat, m = _gather(k, refs[k, 0], refs[k, 1], refs[k, 2], refs[k, 3], wpar[k],
                                 vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i, WANT_BOTH, version)
                best = _best_cand(scores, ch, pat, cands)
                ctx = _res_context(pat, big, eq_o, m)
                if mode == MODE_TABLE:
                    rp = _search(tables, lo, hi, cand_o[best])
                    if rp >= hi:
                        rp = hi - 1
                    res = _search(tables, lo, hi, o) - rp
                    _enc_residual(stc, outc, probs, RANK_BASE + ctx * INT_MODEL_SIZE, res, version, _sign_context(cand_o, best))
                else:
                    res = o - cand_o[best]
                    _enc_residual(stc, outc, probs, RES_BASE + ctx * INT_MODEL_SIZE, res, version, _sign_context(cand_o, best))
                big = _is_big(mode, res)
                # only predicted values train the predictor choice: repeats need no prediction
                _update_scores(scores, ch, pat, cand_o, o, cands)
            if tracing:
                trace[k, ch, 0] = sym
                trace[k, ch, 1] = res
                trace[k, ch, 2] = best
            last_eq = is_eq
            was_eq[k] = sym if is_eq else FLAG_PREDICTED
            _remember_conditional(ch, k, vi, hkeys, hvals, cands)
        nbytes[ch] = enc_finish(stc, outc)
    return nbytes


# ------------------------------------------------------------------------------------ decoder


@njit(cache=True, nogil=True)
def decode_tables_kernel(st, buf, offs, probs, modes, n_points, tables, tab_offs):
    """Start the four channel decoders and read the value tables of the table-mode channels.

    ``tables`` receives the tables one after the other (a count beyond its room is corruption);
    fills ``tab_offs`` (5,). Returns a status (``OK`` or ``ERR_STREAM``).
    """
    pos = 0
    for ch in range(N_CHANNELS):
        data = buf[offs[ch]:offs[ch + 1]]
        stc = st[ch]
        pc = probs[ch]
        dec_init(stc, data)
        tab_offs[ch] = pos
        if modes[ch] == MODE_TABLE:
            count = dec_uint(stc, data, pc, np.int64(TABLE_BASE))
            if count > n_points or pos + count > tables.shape[0] or dec_failed(stc):
                return ERR_STREAM
            if count > 0:
                v = dec_sint(stc, data, pc, TABLE_BASE + INT_MODEL_SIZE)
                if v < -(1 << 31) or v >= (1 << 31):
                    return ERR_STREAM
                tables[pos] = v
                pos += 1
                for _ in range(1, count):
                    v = v + dec_uint(stc, data, pc, np.int64(TABLE_BASE)) + 1
                    if v >= (1 << 31) or dec_failed(stc):
                        return ERR_STREAM
                    tables[pos] = v
                    pos += 1
        if dec_failed(stc):
            return ERR_STREAM
    tab_offs[N_CHANNELS] = pos
    return OK


# Geometry coding 4 sends the value table of each table-mode channel in a stream of its own, ahead
# of the channel streams, so that a reader takes a level's tables (or only some channels' tables)
# without decoding its vertices. A channel's table is either the whole table or, *chained*, only
# the values it adds to the table of the same channel in the next coarser level of the file (a
# coarser level's vertices are a subset of the finer level's, values kept bit for bit). Either way
# the set is coded exactly as the table prefix of a channel stream of codings 1-3 (its size, its
# first value, the gaps between consecutive values less one, in a fresh model at TABLE_BASE), so
# that decode_tables_kernel reads it: a kernel of its own cost a first decode of a format-8 file
# 2-3.5 s of compilation (its wide-bits variant more), for no speed.
TABLE_SET_MODEL = 2 * INT_MODEL_SIZE  # the part of a channel's model from TABLE_BASE on


@njit(cache=True, nogil=True)
def encode_table_set(st, out, values):
    """Code the sorted distinct ``values`` into one stream (see above: what decode_tables_kernel
    reads as a table-mode channel's table); returns its byte count (larger than ``out`` on
    overflow)."""
    probs = np.full(TABLE_SET_MODEL, PROB_INIT, dtype=np.uint16)
    n = values.shape[0]
    enc_uint(st, out, probs, 0, n)
    if n > 0:
        enc_sint(st, out, probs, INT_MODEL_SIZE, values[0])
        for i in range(1, n):
            enc_uint(st, out, probs, 0, values[i] - values[i - 1] - 1)
    return enc_finish(st, out)


@njit(cache=True, _nrt=False)
def _decode_channel(ch, k, r0, r1, r2, r3, w, stc, data, pc, scores, flags, flag, hkeys, hvals, modes, tables,
                    tab_offs, cands, vf, vi, cand_o, eq_o, scratch_f, scratch_i):
    """Decode channel ``ch`` of vertex ``k`` (see :func:`decode_vertices`); ``flag`` is the
    repetition context left by the previous channel. Returns the context for the next channel,
    or minus an error status."""
    # the two requests as run-time values (int64 casts): as literals they compiled _gather twice,
    # some 1.5 s of a cold start, for no measurable speed. Where this channel of the previous vertex
    # was predicted (every channel of an unstructured mesh's vertices), the predictions come with
    # the repetition candidates in one call: a call passes seven arrays, some fifty words, and two
    # a channel were a tenth of the geometry decode (flange-1m); where it repeated (grids), the
    # predictions wait for a value that repeats nothing. The values are the same either way.
    spec = flags[ch] == 0
    pat, m_refs = _gather(k, r0, r1, r2, r3, w, vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i,
                          np.int64(WANT_BOTH if spec else WANT_REPEATS), cands[CAND_VERSION])
    m = _add_conditional(ch, k, vi, hkeys, hvals, eq_o, m_refs, cands)
    is_eq = 0
    o = np.int64(0)
    sym = 0
    if m > 0:
        near = 0
        if cands[CAND_VERSION] >= 2 and m >= 2 and ch < 3:
            near = _nearest(eq_o, m, _first_prediction(k, r0, r1, r2, r3, vf, vi, ch, scratch_f, scratch_i))
        sym = _dec_repeat(stc, data, pc, _eq_context(m, flag, near, cands[CAND_VERSION]), m, cands[CAND_VERSION])
        if sym < m:
            o = eq_o[sym]
            is_eq = 1
        elif sym > m:
            return -ERR_STREAM
    if is_eq == 0:
        # the repetition candidates of the refs (eq_o[:m_refs]) are still those of the first call
        if not spec:
            pat, _ = _gather(k, r0, r1, r2, r3, w, vf, vi, ch, cand_o, eq_o, scratch_f, scratch_i,
                             np.int64(WANT_PREDICTIONS), cands[CAND_VERSION])
        mode = modes[ch]
        best = _best_cand(scores, ch, pat, cands)
        ctx = _res_context(pat, flags[N_CHANNELS + ch], eq_o, m_refs)
        if mode == MODE_TABLE:
            lo = tab_offs[ch]
            hi = tab_offs[ch + 1]
            if hi <= lo:
                return -ERR_RANK
            rp = _search(tables, lo, hi, cand_o[best])
            if rp >= hi:
                rp = hi - 1
            res = _dec_residual(stc, data, pc, RANK_BASE + ctx * INT_MODEL_SIZE, cands[CAND_VERSION],
                                _sign_context(cand_o, best))
            r = rp + res
            if r < lo or r >= hi:
                return -ERR_RANK
            o = tables[r]
        else:
            res = _dec_residual(stc, data, pc, RES_BASE + ctx * INT_MODEL_SIZE, cands[CAND_VERSION],
                                _sign_context(cand_o, best))
            o = cand_o[best] + res
            if o < -(1 << 31) or o >= (1 << 31):
                return -ERR_STREAM
        flags[N_CHANNELS + ch] = _is_big(mode, res)
        _update_scores(scores, ch, pat, cand_o, o, cands)
    if dec_failed(stc):
        return -ERR_STREAM
    vi[k, ch] = ordered_to_bits(o)
    _remember_conditional(ch, k, vi, hkeys, hvals, cands)
    flags[ch] = is_eq
    return sym if is_eq else FLAG_PREDICTED


STEP_ESCAPED = 1 << 20  # what _decode_step returns for an escape


@njit(cache=True, _nrt=False)
def _decode_step(ch, k, r0, r1, r2, r3, stc, data, pc, flags, flag, hkeys, hvals, tables, tab_offs, rk, cands, vi,
                 eq_o):
    """Decode the rank step of vertex k (first ref r0 >= 0) on a channel coded with steps (coding
    5): its value, rank and the context for the next channel (as :func:`_decode_channel` returns
    it), ``STEP_ESCAPED`` for an escape (the value then follows as in a table-mode channel of
    coding 3), or minus an error status. A call of its own: inlined into the vertex loop, the step
    path cost blocks without steps 20-40 % of their geometry decode time."""
    lo = tab_offs[ch]
    hi = tab_offs[ch + 1]
    base = np.int64(rk[r0, ch])
    step = _dec_step(stc, data, pc, _step_context(rk, ch, base, r1, r2, r3, flag))
    if step == STEP_ESCAPE:
        return STEP_ESCAPED
    rank = base + step
    if rank < 0 or rank >= hi - lo:
        return -ERR_RANK
    if dec_failed(stc):
        return -ERR_STREAM
    o = tables[lo + rank]
    vi[k, ch] = ordered_to_bits(o)
    rk[k, ch] = rank
    # the next channel's context as if the value were coded without steps (the repetition
    # candidates of _gather: r0 is the first face ref)
    m = _repeat_candidates(r0, r1, r2, r3, vi, ch, eq_o)
    m = _add_conditional(ch, k, vi, hkeys, hvals, eq_o, m, cands)
    sym = _match(eq_o, m, o)
    _remember_conditional(ch, k, vi, hkeys, hvals, cands)
    flags[ch] = 1 if sym != FLAG_PREDICTED else 0
    return sym


@njit(cache=True, nogil=True)
def decode_vertices(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes, tables, tab_offs, rk,
                    cands, refs, vf, start, count):
    """Decode vertices ``start .. start+count-1`` into ``vf`` (n, 4) float32 (callable from Python
    and from other numba kernels; Python callers take :data:`decode_vertices_py`).

    ``refs`` (count, 4) int32 are the refs of those vertices. ``st`` (4, 8) decoder states,
    ``probs`` (4, MODEL_SIZE) models, ``scores`` (4, N_PATTERNS, MAX_CANDS) predictor scores,
    ``cands`` the block's :func:`candidate_table`, ``flags`` (8,) context flags, ``adj`` (n, ADJ_CAP) int32 and ``deg`` (n,) uint8 or int32 (the edges seen
    so far), ``mark`` (n,) int32 scratch and ``hkeys`` int64 / ``hvals`` uint8 (a power of two above n,)
    (the x -> y table: packed key and value, slot used) and ``rk`` (n, 4) int32 (coding 5: each decoded
    vertex's rank on the ``MODE_STEPS`` channels; (1, 4) when there are none) carry the decoder's state
    from one call to the next. Every index is checked: returns
    ``OK``, ``ERR_REF`` (a ref not in ``[-1, k)``), ``ERR_RANK`` (a table index out of range) or
    ``ERR_STREAM`` (the range decoder failed).
    """
    n = vf.shape[0]
    if start < 0 or count < 0 or start + count > n or refs.shape[0] < count or refs.shape[1] != 4:
        return ERR_REF
    if cands.shape[0] != N_PATTERNS + 2 or scores.shape[2] < MAX_CANDS:
        return ERR_REF
    if (adj.shape[0] < n or deg.shape[0] < n or mark.shape[0] < n or adj.shape[1] != ADJ_CAP
            or (cands[CAND_XY] != 0 and (hkeys.shape[0] <= (n if cands[CAND_VERSION] < 3 else 1)
                                         or (hkeys.shape[0] & (hkeys.shape[0] - 1)) != 0))
            or hvals.shape[0] != hkeys.shape[0]):  # a power of two with a free slot after n keys
        return ERR_REF
    for pat in range(N_PATTERNS):
        if cands[pat] < 1 or cands[pat] > MAX_CANDS:
            return ERR_REF
    if modes.shape[0] != N_CHANNELS or tab_offs.shape[0] != N_CHANNELS + 1 or rk.ndim != 2 or rk.shape[1] != N_CHANNELS:
        return ERR_REF
    for ch in range(N_CHANNELS):
        if modes[ch] == MODE_STEPS and rk.shape[0] < n:
            return ERR_REF
    cand_o = np.zeros(MAX_CANDS, dtype=np.int64)
    eq_o = np.zeros(5, dtype=np.int64)
    scratch_f = np.zeros(MAX_CANDS, dtype=np.float32)
    w = np.zeros((3, NW), dtype=np.int32)
    # the channel decoder's modes: a step channel's escapes are a table-mode channel's values
    table_modes = np.where(modes == MODE_STEPS, MODE_TABLE, modes)
    return _decode_vertices_run(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes, tables,
                                tab_offs, rk, cands, refs, vf, int(start), int(count),
                                (cand_o, eq_o, scratch_f, w, table_modes))


# The same checks and scratch run as Python, the loop compiled (and releasing the GIL): what the
# decoder calls once per batch. Compiled, this wrapper cost a second of a first render's compiling.
decode_vertices_py = decode_vertices.py_func

_decode_channel_inlined = njit(cache=True, _nrt=False, inline="always")(_decode_channel.py_func)


# Compiled without the runtime's reference counting (it allocates nothing): the channel's decoder
# state, stream and model are views picked per channel in a loop around the one (inlined) copy of
# the channel decoder, where four calls passing them as arguments, some hundred words each, were
# a third of the geometry kernels' own time.
@njit(cache=True, nogil=True, _nrt=False)
def _decode_vertices_run(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes, tables, tab_offs,
                         rk, cands, refs, vf, start, count, scratch):
    """The loop of :func:`decode_vertices` (arguments checked), its scratch arrays in ``scratch``."""
    cand_o, eq_o, scratch_f, w, table_modes = scratch
    vi = vf.view(np.int32)
    scratch_i = scratch_f.view(np.int32)
    for j in range(count):
        k = start + j
        r0 = refs[j, 0]
        r1 = refs[j, 1]
        r2 = refs[j, 2]
        r3 = refs[j, 3]
        if (r0 < -1 or r0 >= k or r1 < -1 or r1 >= k or r2 < -1 or r2 >= k or r3 < -1 or r3 >= k):
            return ERR_REF
        link_vertex(k, r0, r1, r2, r3, adj, deg, mark, w, vf)
        flag = 6 + flags[0]
        for ch in range(N_CHANNELS):
            steps = modes[ch] == MODE_STEPS
            if steps and r0 >= 0:
                stepped = _decode_step(ch, k, r0, r1, r2, r3, st[ch], buf[offs[ch]:offs[ch + 1]], probs[ch], flags,
                                       flag, hkeys, hvals, tables, tab_offs, rk, cands, vi, eq_o)
                if stepped != STEP_ESCAPED:
                    if stepped < 0:
                        return -stepped
                    flag = stepped
                    continue
            flag = _decode_channel_inlined(ch, k, r0, r1, r2, r3, w, st[ch], buf[offs[ch]:offs[ch + 1]], probs[ch],
                                           scores, flags, flag, hkeys, hvals, table_modes, tables, tab_offs, cands, vf,
                                           vi, cand_o, eq_o, scratch_f, scratch_i)
            if flag < 0:
                return -flag
            if steps and not _store_rank(rk, k, ch, tables, tab_offs[ch], tab_offs[ch + 1], ordered_int(vi[k, ch])):
                return ERR_RANK
    return OK
