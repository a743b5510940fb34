"""Numba kernels of the point-array coder (:mod:`gatun_py.codec.arrays`).

Values arrive as *reduced ordered integers* (int64): the order-preserving integer image of a float's
bit pattern (or an integer's value), shifted right by the component's common trailing zero bits.
Vertex ``k`` is predicted from already known vertices: its refs ``(a, b, c, apex)`` (decode ids
``< k`` or -1) or the vertex before it, or an external prediction (the float32 rounding the geometry
section already holds). The residual ``value - prediction`` is taken modulo 2**64 and zigzagged, so
any prediction, even a wrapped one, gives back the value exactly. Encoder and decoder compute
predictions with the same function, in integers only (no floating point anywhere).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .rangecoder import dec_bit, dec_failed, dec_raw, dec_sym, enc_bit, enc_finish, enc_raw, enc_sym

PRED_ZERO = 0  # raw values
PRED_PREV = 1  # the vertex before in decode order
PRED_FIRST = 2  # the first ref (a), else the previous vertex
PRED_MEAN = 3  # mean of the face refs (a, b, c) that exist
PRED_REFLECT = 4  # 2 * mean(face) - apex: the apex reflected through the face (linear field)
PRED_EXTERNAL = 5  # a given prediction (the float32 rounding of the value)
N_PREDICTORS = 6

OK = 0
BAD_REF = 1
BAD_STREAM = 2


@njit(cache=True, inline="always")
def _mean_floor(s_q, s_r, f):
    # floor((sum of f values) / f) from per-value quotients and remainders by f (no overflow)
    return s_q + s_r // f


@njit(cache=True)
def _predict(o, refs, row, k, kind, ext, lo, hi):
    """Prediction of ``o[k]`` (int64) from earlier entries of ``o``; ``ext`` for PRED_EXTERNAL.

    ``refs[row]`` and ``ext[row]`` belong to vertex k (a decoder passes one batch at a time).
    """
    if kind == PRED_ZERO:
        return np.int64(0)
    if kind == PRED_EXTERNAL:
        return ext[row]
    prev = o[k - 1] if k > 0 else np.int64(0)
    if kind == PRED_PREV:
        return prev
    a = refs[row, 0]
    if kind == PRED_FIRST:
        return o[a] if a >= 0 else prev
    f = 0
    s_q = np.int64(0)
    s_r = np.int64(0)
    for j in range(3):
        if refs[row, j] >= 0:
            f += 1
    if f == 0:
        return prev
    for j in range(3):
        r = refs[row, j]
        if r >= 0:
            v = o[r]
            # Python-style floor division and modulo: q * f + m == v exactly
            s_q += v // f
            s_r += v % f
    mean = _mean_floor(s_q, s_r, f)
    d = refs[row, 3]
    if kind == PRED_MEAN or d < 0 or f < 2:
        return mean
    p = mean + mean - o[d]  # may wrap: only a worse prediction, still exact after the residual
    if p < lo:
        p = lo
    elif p > hi:
        p = hi
    return p


@njit(cache=True)
def residuals(o, refs, kind, ext, lo, hi):
    """Zigzagged residuals (as int64 bit patterns of uint64) of every vertex for one predictor."""
    n = o.shape[0]
    out = np.empty(n, np.int64)
    for k in range(n):
        r = o[k] - _predict(o, refs, k, k, kind, ext, lo, hi)
        out[k] = (r << 1) ^ (r >> 63)
    return out


# -- entropy coding of the residuals: adaptive range coding ------------------------------------
# A zigzagged residual z is coded as its bit length L (0..64, a 7-bit tree in a context: the bit
# length of the residual of the vertex's first ref, else of the previous vertex), then the MANT
# bits below its leading one modelled (context L), then the rest raw.
LEN_BITS = 7
N_LEN_CONTEXTS = 65
MANT_BITS = 3
_MANT_BASE = N_LEN_CONTEXTS * (1 << LEN_BITS)
MODEL_SIZE = _MANT_BASE + 65 * (1 << MANT_BITS)


@njit(cache=True, _nrt=False)
def _refs_valid(refs, start, stop):
    """Every ref of vertices ``start:stop`` (rows of ``refs``) is -1 or an earlier vertex."""
    for k in range(start, stop):
        for j in range(4):
            r = refs[k - start, j]
            if r < -1 or r >= k:
                return False
    return True


@njit(cache=True, inline="always")
def _bit_length(z):
    u = np.uint64(z)
    b = 0
    while u:
        u >>= np.uint64(1)
        b += 1
    return b


@njit(cache=True, inline="always")
def _context(lens, refs, row, k):
    a = refs[row, 0]
    if a >= 0:
        return np.int64(lens[a])
    return np.int64(lens[k - 1]) if k > 0 else np.int64(0)


@njit(cache=True)
def encode_residuals(st, out, zz, refs, probs, lens):
    """Range-code the zigzagged residuals ``zz`` of one component (refs give the contexts)."""
    for k in range(zz.shape[0]):
        z = zz[k]
        nb = _bit_length(z)
        lens[k] = nb
        enc_sym(st, out, probs, _context(lens, refs, k, k) * (1 << LEN_BITS), LEN_BITS, nb)
        if nb > 1:
            mbits = nb - 1
            nmod = mbits if mbits < MANT_BITS else MANT_BITS
            base = _MANT_BASE + nb * (1 << MANT_BITS)
            node = 1
            for j in range(nmod):
                b = (z >> (mbits - 1 - j)) & 1
                enc_bit(st, out, probs, base + node, b)
                node = (node << 1) | b
            rest = mbits - nmod
            if rest > 32:  # raw bits go 32 at a time
                enc_raw(st, out, z >> 32, rest - 32)
                enc_raw(st, out, z & 0xFFFFFFFF, 32)
            elif rest > 0:
                enc_raw(st, out, z, rest)
    return enc_finish(st, out)


@njit(cache=True, _nrt=False)
def decode_component(st, data, probs, lens, o, refs, start, stop, kind, ext, lo, hi):
    """Decode the residuals of vertices ``start:stop`` and rebuild their values ``o`` (refs checked)."""
    if not _refs_valid(refs, start, stop):
        return BAD_REF
    for k in range(start, stop):
        row = k - start
        nb = dec_sym(st, data, probs, _context(lens, refs, row, k) * (1 << LEN_BITS), LEN_BITS)
        if nb > 64 or dec_failed(st):
            return BAD_STREAM
        lens[k] = nb
        z = np.int64(0)
        if nb >= 1:
            z = np.int64(1)
            mbits = nb - 1
            nmod = mbits if mbits < MANT_BITS else MANT_BITS
            base = _MANT_BASE + nb * (1 << MANT_BITS)
            node = 1
            for j in range(nmod):
                b = dec_bit(st, data, probs, base + node)
                node = (node << 1) | b
                z = (z << 1) | b
            rest = mbits - nmod
            if rest > 32:
                high = dec_raw(st, data, rest - 32)
                z = (z << rest) | (np.int64(high) << 32) | dec_raw(st, data, 32)
            elif rest > 0:
                z = (z << rest) | dec_raw(st, data, rest)
        r = ((z >> 1) & np.int64(0x7FFFFFFFFFFFFFFF)) ^ -(z & 1)
        o[k] = _predict(o, refs, row, k, kind, ext, lo, hi) + r
    return OK


@njit(cache=True)
def reconstruct(o, zz, refs, start, stop, kind, ext, lo, hi):
    """Rebuild ``o[start:stop]`` from already decoded residuals ``zz`` (the LZMA coder); refs checked."""
    if not _refs_valid(refs, start, stop):
        return BAD_REF
    for k in range(start, stop):
        z = zz[k]
        r = ((z >> 1) & np.int64(0x7FFFFFFFFFFFFFFF)) ^ -(z & 1)
        o[k] = _predict(o, refs, k - start, k, kind, ext, lo, hi) + r
    return OK
