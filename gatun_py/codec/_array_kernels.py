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
PRED_LINEAR = 6  # the linear field through the tet (a, b, c, apex) at the vertex's float32 position
N_PREDICTORS = 7

# value kinds of ``vinfo[0]`` (linear prediction works on values, not on their integer images)
VALUE_INT, VALUE_F32, VALUE_F64 = 0, 1, 2

OK = 0
BAD_REF = 1
BAD_STREAM = 2


@njit(cache=True, inline="always")
def _mean_floor(s_q, s_r, f):
    # floor((sum of f values) / f) from per-value quotients and remainders by f (no overflow)
    return s_q + s_r // f


@njit(cache=True)
def to_value(o, lin):
    """The value (as float64) of a reduced ordered integer; ``lin`` as in :func:`_predict`."""
    vinfo, i64, f64, i32, f32 = lin[2], lin[3], lin[4], lin[5], lin[6]
    shift = vinfo[1]
    if vinfo[0] == VALUE_INT:
        return np.float64(o << shift)
    m = o if o >= 0 else ~o
    mag = m << shift
    if vinfo[0] == VALUE_F64:
        i64[0] = mag | (np.int64(1) << 63) if o < 0 else mag
        return f64[0]
    bits = mag | ((np.int64(1) << 31) if o < 0 else np.int64(0))
    i32[0] = np.int32(bits - (np.int64(1) << 32)) if bits >= (np.int64(1) << 31) else np.int32(bits)
    return np.float64(f32[0])


@njit(cache=True)
def _from_value(v, lin, lo, hi):
    """(ok, reduced ordered integer) of a predicted value; not ok for NaN or inf."""
    vinfo, i64, f64, i32, f32 = lin[2], lin[3], lin[4], lin[5], lin[6]
    shift = vinfo[1]
    if not np.isfinite(v):
        return False, np.int64(0)
    if vinfo[0] == VALUE_INT:
        if v > 9.2e18:
            v = 9.2e18
        elif v < -9.2e18:
            v = -9.2e18
        p = np.int64(np.floor(v + 0.5)) >> shift
    else:
        if vinfo[0] == VALUE_F64:
            f64[0] = v
            bits = i64[0]
            mag = bits & np.int64(0x7FFFFFFFFFFFFFFF)
        else:
            f32[0] = np.float32(v)
            bits = np.int64(i32[0])
            mag = bits & np.int64(0x7FFFFFFF)
        m = mag >> shift
        p = ~m if bits < 0 else m
    if p < lo:
        p = lo
    elif p > hi:
        p = hi
    return True, p


@njit(cache=True)
def _linear(refs, row, k, lin):
    """(ok, value) of the linear field through the ref tet at vertex k's position (float64, no fastmath)."""
    pos, fv = lin[0], lin[1]
    a, b, c, d = refs[row, 0], refs[row, 1], refs[row, 2], refs[row, 3]
    if a < 0 or b < 0 or c < 0 or d < 0:
        return False, 0.0
    ax = np.float64(pos[a, 0]) - pos[d, 0]
    ay = np.float64(pos[a, 1]) - pos[d, 1]
    az = np.float64(pos[a, 2]) - pos[d, 2]
    bx = np.float64(pos[b, 0]) - pos[d, 0]
    by = np.float64(pos[b, 1]) - pos[d, 1]
    bz = np.float64(pos[b, 2]) - pos[d, 2]
    cx = np.float64(pos[c, 0]) - pos[d, 0]
    cy = np.float64(pos[c, 1]) - pos[d, 1]
    cz = np.float64(pos[c, 2]) - pos[d, 2]
    px = np.float64(pos[k, 0]) - pos[d, 0]
    py = np.float64(pos[k, 1]) - pos[d, 1]
    pz = np.float64(pos[k, 2]) - pos[d, 2]
    # Cramer's rule for p = la * a + lb * b + lc * c (all relative to d)
    kx, ky, kz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
    det = ax * kx + ay * ky + az * kz
    if det == 0.0:
        return False, 0.0
    la = (px * kx + py * ky + pz * kz) / det
    lb = (ax * (py * cz - pz * cy) + ay * (pz * cx - px * cz) + az * (px * cy - py * cx)) / det
    lc = (ax * (by * pz - bz * py) + ay * (bz * px - bx * pz) + az * (bx * py - by * px)) / det
    if not (abs(la) + abs(lb) + abs(lc) <= 8.0):  # ill-conditioned (or NaN): not worth trusting
        return False, 0.0
    fd = fv[d]
    return True, fd + la * (fv[a] - fd) + lb * (fv[b] - fd) + lc * (fv[c] - fd)


@njit(cache=True)
def _predict(o, refs, row, k, kind, ext, lo, hi, lin):
    """Prediction of ``o[k]`` (int64) from earlier entries of ``o``; ``ext`` for PRED_EXTERNAL.

    ``refs[row]`` and ``ext[row]`` belong to vertex k (a decoder passes one batch at a time).
    ``lin = (positions (n, >=3) float32, values fv (n,) float64, vinfo (kind, shift), and four
    one-element scratch views for bit casts)`` serves PRED_LINEAR; it falls back to PRED_REFLECT.
    """
    if kind == PRED_LINEAR:
        ok, v = _linear(refs, row, k, lin)
        if ok:
            ok, p = _from_value(v, lin, lo, hi)
            if ok:
                return p
        kind = PRED_REFLECT
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


@njit(cache=True, nogil=True)
def residuals(o, refs, kind, ext, lo, hi, lin):
    """Zigzagged residuals (as int64 bit patterns of uint64) of every vertex for one predictor."""
    n = o.shape[0]
    if kind == PRED_LINEAR:  # the values the decoder will have, from the same function
        for k in range(n):
            lin[1][k] = to_value(o[k], lin)
    out = np.empty(n, np.int64)
    for k in range(n):
        r = o[k] - _predict(o, refs, k, k, kind, ext, lo, hi, lin)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True, _nrt=False)
def decode_component(st, data, probs, lens, o, refs, start, stop, kind, ext, lo, hi, lin):
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
        o[k] = _predict(o, refs, row, k, kind, ext, lo, hi, lin) + r
        if kind == PRED_LINEAR:
            lin[1][k] = to_value(o[k], lin)
    return OK


@njit(cache=True, nogil=True)
def reconstruct(o, zz, refs, start, stop, kind, ext, lo, hi, lin):
    """Rebuild ``o[start:stop]`` from already decoded residuals ``zz`` (the LZMA coder); refs checked."""
    if not _refs_valid(refs, start, stop):
        return BAD_REF
    for k in range(start, stop):
        z = zz[k]
        r = ((z >> 1) & np.int64(0x7FFFFFFFFFFFFFFF)) ^ -(z & 1)
        o[k] = _predict(o, refs, k - start, k, kind, ext, lo, hi, lin) + r
        if kind == PRED_LINEAR:
            lin[1][k] = to_value(o[k], lin)
    return OK
