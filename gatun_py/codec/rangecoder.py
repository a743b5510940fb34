"""Adaptive binary range coder usable from inside numba kernels.

This is an LZMA-style binary range coder (a carry-propagating range encoder with 32-bit range,
adaptive probabilities of the bit being 0). Multi-symbol alphabets are binarised with a bit tree
of adaptive bits (one probability per tree node), integers with an Elias-gamma style bucket (the
bit length, itself a bit-tree symbol) followed by the mantissa, whose top bits are modelled and the
rest sent as raw (equiprobable) bits.

Everything is plain arrays so that the kernels can be ``@njit(cache=True)`` and called from other
``@njit`` kernels (no jitclass, which cannot be cached).

Kernel-level API
----------------
Encoder state: ``st = enc_state()`` (int64 array) and an output buffer ``out`` (uint8 array whose
capacity the caller chooses, e.g. :func:`capacity_hint`). If the buffer fills up the encoder sets
``st[ENC_OVERFLOW]`` and drops further bytes: the Python caller then retries with a bigger buffer
(:func:`run_encoder` does this).

Decoder state: ``st = dec_state()`` then ``dec_init(st, data)`` (``data`` uint8 array). Reading
past the end of ``data`` yields zero bytes and counts them in ``st[DEC_OVERRUN]``; any overrun
or an impossible code value marks the stream corrupt: check ``dec_ok(st, data)`` after decoding
(or :func:`check_decoder`, which raises :class:`~gatun_py.errors.CorruptFileError`). Kernels
that loop on decoded values should also test ``st[DEC_ERROR]`` / ``st[DEC_OVERRUN]`` to stop early.

Models are ``uint16`` probability arrays (``new_model(n)`` gives n probabilities at 1/2); the
caller selects a context simply by choosing the offset ``base`` into a model array.

=====================================================  ==================================================
encoder (all ``@njit``)                                decoder (all ``@njit``)
=====================================================  ==================================================
``enc_bit(st, out, probs, i, bit)``                    ``dec_bit(st, data, probs, i) -> int``
``enc_raw(st, out, value, nbits)``   (nbits <= 32)     ``dec_raw(st, data, nbits) -> int``
``enc_sym(st, out, probs, base, nbits, sym)``          ``dec_sym(st, data, probs, base, nbits) -> int``
``enc_uint(st, out, probs, base, value)``  (< 2**40)   ``dec_uint(st, data, probs, base) -> int``
``enc_sint(st, out, probs, base, value)``  (|v|<2**40) ``dec_sint(st, data, probs, base) -> int``
``enc_below(st, out, value, m)``  (m <= 2**32)        ``dec_below(st, data, m) -> int``
``enc_finish(st, out) -> n_bytes``                     ``dec_init(st, data)``, ``dec_ok(st, data)``
=====================================================  ==================================================

``enc_below`` codes ``0 <= value < m`` at probability 1/m each (no model: for an index that is
equally likely anywhere, such as the position of a rank among the ranks still free).

``enc_sym`` codes ``sym`` in ``[0, 2**nbits)`` and uses ``probs[base : base + 2**nbits]``.
``enc_uint``/``enc_sint`` use ``probs[base : base + INT_MODEL_SIZE]`` (``new_int_model(k)`` makes
k such contexts; context c starts at ``c * INT_MODEL_SIZE``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import CorruptFileError

PROB_BITS = 15
PROB_ONE = 1 << PROB_BITS
PROB_INIT = PROB_ONE // 2
ADAPT_SHIFT = 5
TOP = 1 << 24
MASK32 = (1 << 32) - 1

# encoder state slots
ENC_LOW, ENC_RANGE, ENC_CACHE, ENC_CACHE_SIZE, ENC_POS, ENC_OVERFLOW = 0, 1, 2, 3, 4, 5
# decoder state slots
DEC_CODE, DEC_RANGE, DEC_POS, DEC_OVERRUN, DEC_ERROR = 0, 1, 2, 3, 4

# integer model layout: bucket bit tree (64) + 3 modelled mantissa bits per bucket (8 each) + sign (4)
INT_BUCKET_BITS = 6
INT_MODELLED_BITS = 3
_INT_MANT_BASE = 1 << INT_BUCKET_BITS
_INT_MAX_BUCKET = 41
_INT_SIGN_BASE = _INT_MANT_BASE + _INT_MAX_BUCKET * (1 << INT_MODELLED_BITS)
INT_MODEL_SIZE = _INT_SIGN_BASE + 2
INT_MAX = (1 << 40) - 1


def new_model(n: int) -> np.ndarray:
    """``n`` adaptive binary probabilities, all starting at 1/2."""
    return np.full(int(n), PROB_INIT, dtype=np.uint16)


def new_int_model(n_contexts: int = 1) -> np.ndarray:
    """Model array for ``n_contexts`` integer contexts (context c at offset ``c * INT_MODEL_SIZE``)."""
    return new_model(int(n_contexts) * INT_MODEL_SIZE)


def enc_state() -> np.ndarray:
    """A fresh encoder state."""
    st = np.zeros(8, dtype=np.int64)
    st[ENC_RANGE] = MASK32
    st[ENC_CACHE_SIZE] = 1
    return st


def dec_state() -> np.ndarray:
    """A fresh decoder state (call :func:`dec_init` before decoding)."""
    return np.zeros(8, dtype=np.int64)


def capacity_hint(n_symbols: int) -> int:
    """A first guess of the output size for ``n_symbols`` coded bits/symbols."""
    return 64 + int(n_symbols) // 2


# ---------------------------------------------------------------- encoder


@njit(cache=True, _nrt=False)
def _put_byte(st, out, b):
    pos = st[ENC_POS]
    if pos < out.shape[0]:
        out[pos] = b
    else:
        st[ENC_OVERFLOW] = 1
    st[ENC_POS] = pos + 1


@njit(cache=True)
def _shift_low(st, out):
    low = st[ENC_LOW]
    if low < 0xFF000000 or low > MASK32:
        carry = low >> 32
        temp = st[ENC_CACHE]
        while True:
            _put_byte(st, out, (temp + carry) & 0xFF)
            temp = 0xFF
            st[ENC_CACHE_SIZE] -= 1
            if st[ENC_CACHE_SIZE] == 0:
                break
        st[ENC_CACHE] = (low >> 24) & 0xFF
    st[ENC_CACHE_SIZE] += 1
    st[ENC_LOW] = (low & 0x00FFFFFF) << 8


@njit(cache=True, inline="always")
def _enc_bit_at(st, out, probs, i, bit, shift):
    p = np.int64(probs[i])
    rng = st[ENC_RANGE]
    bound = (rng >> PROB_BITS) * p
    if bit == 0:
        st[ENC_RANGE] = bound
        probs[i] = p + ((PROB_ONE - p) >> shift)
    else:
        st[ENC_LOW] += bound
        st[ENC_RANGE] = rng - bound
        probs[i] = p - (p >> shift)
    while st[ENC_RANGE] < TOP:
        st[ENC_RANGE] <<= 8
        _shift_low(st, out)


@njit(cache=True)
def enc_bit(st, out, probs, i, bit):
    """Code one bit with the adaptive probability ``probs[i]``."""
    _enc_bit_at(st, out, probs, i, bit, ADAPT_SHIFT)


@njit(cache=True)
def enc_raw(st, out, value, nbits):
    """Code the low ``nbits`` bits of ``value`` (most significant first) at probability 1/2."""
    for k in range(nbits - 1, -1, -1):
        st[ENC_RANGE] >>= 1
        if (value >> k) & 1:
            st[ENC_LOW] += st[ENC_RANGE]
        while st[ENC_RANGE] < TOP:
            st[ENC_RANGE] <<= 8
            _shift_low(st, out)


RAW_STEP_BITS = 16  # raw bits coded per range-coder step by enc_raw_wide / dec_raw_wide


@njit(cache=True)
def enc_raw_wide(st, out, value, nbits):
    """Code the low ``nbits`` bits of ``value`` at probability 1/2 each, up to RAW_STEP_BITS of them
    in one range-coder step (one multiply here, one division in the decoder, instead of a step
    per bit). Not the bit stream of :func:`enc_raw`: decode with :func:`dec_raw_wide`."""
    while nbits > 0:
        k = nbits if nbits < RAW_STEP_BITS else RAW_STEP_BITS
        nbits -= k
        # the range is >= TOP = 2**24 here, so the share of each of the 2**k values stays >= 2**8
        r = st[ENC_RANGE] >> k
        st[ENC_LOW] += ((value >> nbits) & ((1 << k) - 1)) * r
        st[ENC_RANGE] = r
        while st[ENC_RANGE] < TOP:
            st[ENC_RANGE] <<= 8
            _shift_low(st, out)


@njit(cache=True)
def enc_sym(st, out, probs, base, nbits, sym):
    """Code ``sym`` in ``[0, 2**nbits)`` with the bit tree ``probs[base : base + 2**nbits]``."""
    # enc_bit written out: the hottest call of the connectivity encoder
    node = 1
    for k in range(nbits - 1, -1, -1):
        b = (sym >> k) & 1
        i = base + node
        p = np.int64(probs[i])
        rng = st[ENC_RANGE]
        bound = (rng >> PROB_BITS) * p
        if b == 0:
            st[ENC_RANGE] = bound
            probs[i] = p + ((PROB_ONE - p) >> ADAPT_SHIFT)
        else:
            st[ENC_LOW] += bound
            st[ENC_RANGE] = rng - bound
            probs[i] = p - (p >> ADAPT_SHIFT)
        while st[ENC_RANGE] < TOP:
            st[ENC_RANGE] <<= 8
            _shift_low(st, out)
        node = (node << 1) | b


@njit(cache=True, _nrt=False)
def _enc_uint(st, out, probs, base, value, wide):
    nb = 0
    v = value
    while v > 0:
        nb += 1
        v >>= 1
    enc_sym(st, out, probs, base, INT_BUCKET_BITS, nb)
    if nb <= 1:
        return
    mbits = nb - 1  # bits below the leading one
    nmod = mbits if mbits < INT_MODELLED_BITS else INT_MODELLED_BITS
    mbase = base + _INT_MANT_BASE + nb * (1 << INT_MODELLED_BITS)
    node = 1
    for k in range(nmod):
        b = (value >> (mbits - 1 - k)) & 1
        enc_bit(st, out, probs, mbase + node, b)
        node = (node << 1) | b
    rest = mbits - nmod
    if rest > 0:
        if wide:
            enc_raw_wide(st, out, value, rest)
        else:
            enc_raw(st, out, value, rest)


@njit(cache=True)
def enc_uint(st, out, probs, base, value):
    """Code an integer ``0 <= value < 2**40`` (bucket = bit length, then the mantissa)."""
    _enc_uint(st, out, probs, base, value, False)


@njit(cache=True)
def enc_uint_wide(st, out, probs, base, value):
    """:func:`enc_uint` with the unmodelled mantissa bits in wide steps (:func:`enc_raw_wide`);
    the same model layout. Decode with :func:`dec_uint_wide`."""
    _enc_uint(st, out, probs, base, value, True)


@njit(cache=True)
def enc_sint(st, out, probs, base, value):
    """Code a signed integer ``|value| < 2**40``: magnitude, then an adaptive sign bit."""
    mag = value if value >= 0 else -value
    enc_uint(st, out, probs, base, mag)
    if mag != 0:
        enc_bit(st, out, probs, base + _INT_SIGN_BASE, 1 if value < 0 else 0)


@njit(cache=True)
def enc_sint_wide(st, out, probs, base, value, sign_context):
    """:func:`enc_sint` on :func:`enc_uint_wide`, the sign in one of two contexts (0 or 1, the
    caller's guess of it). Decode with :func:`dec_sint_wide`."""
    mag = value if value >= 0 else -value
    enc_uint_wide(st, out, probs, base, mag)
    if mag != 0:
        enc_bit(st, out, probs, base + _INT_SIGN_BASE + sign_context, 1 if value < 0 else 0)


@njit(cache=True)
def _enc_below16(st, out, value, m):
    r = st[ENC_RANGE] // m
    st[ENC_LOW] += value * r
    st[ENC_RANGE] = r
    while st[ENC_RANGE] < TOP:
        st[ENC_RANGE] <<= 8
        _shift_low(st, out)


@njit(cache=True)
def enc_below(st, out, value, m):
    """Code ``0 <= value < m`` uniformly (``m <= 2**32``; above 2**16 as a high and a low part)."""
    if m <= 65536:
        _enc_below16(st, out, value, m)
    else:
        hi = value >> 16
        _enc_below16(st, out, hi, ((m - 1) >> 16) + 1)
        rest = m - (hi << 16)
        _enc_below16(st, out, value & 0xFFFF, rest if rest < 65536 else 65536)


@njit(cache=True)
def enc_finish(st, out):
    """Flush the encoder; returns the number of bytes written (may exceed ``len(out)`` on overflow)."""
    for _ in range(5):
        _shift_low(st, out)
    return st[ENC_POS]


# ---------------------------------------------------------------- decoder
# The decoding primitives are compiled with ``_nrt=False``: they never allocate, and without the
# runtime's reference counting a call no longer does an atomic increment and decrement of every
# array argument, which cost about a quarter of the decoders' time (measured with perf).


@njit(cache=True, _nrt=False)
def _get_byte(st, data):
    pos = st[DEC_POS]
    st[DEC_POS] = pos + 1
    if pos < data.shape[0]:
        return np.int64(data[pos])
    st[DEC_OVERRUN] += 1
    return np.int64(0)


@njit(cache=True)
def dec_init(st, data):
    """Start decoding ``data`` (uint8 array)."""
    st[DEC_POS] = 0
    st[DEC_OVERRUN] = 0
    st[DEC_ERROR] = 0
    st[DEC_RANGE] = MASK32
    first = _get_byte(st, data)
    if first != 0:
        st[DEC_ERROR] = 1
    code = 0
    for _ in range(4):
        code = (code << 8) | _get_byte(st, data)
    st[DEC_CODE] = code


# The decoding steps on the range and code held by the caller (in registers), inlined: a caller
# that decodes several symbols in a row loads and stores the decoder state once.
@njit(cache=True, _nrt=False, inline="always")
def _decide_at(st, data, probs, i, rng, code, shift):
    p = np.int64(probs[i])
    bound = (rng >> PROB_BITS) * p
    if code < bound:
        rng = bound
        probs[i] = p + ((PROB_ONE - p) >> shift)
        bit = 0
    else:
        code -= bound
        rng -= bound
        probs[i] = p - (p >> shift)
        bit = 1
    while rng < TOP:
        rng <<= 8
        code = ((code << 8) | _get_byte(st, data)) & MASK32
    return bit, rng, code


@njit(cache=True, _nrt=False)
def _decide(st, data, probs, i, rng, code):
    """One adaptive binary decision with ``probs[i]``: (bit, range, code)."""
    return _decide_at(st, data, probs, i, rng, code, ADAPT_SHIFT)


@njit(cache=True, _nrt=False, error_model="numpy")
def _raw_wide(st, data, nbits, rng, code):
    """``nbits`` raw bits coded by :func:`enc_raw_wide`: (value, range, code); a damaged stream
    sets the error flag."""
    value = np.int64(0)
    while nbits > 0:
        k = nbits if nbits < RAW_STEP_BITS else RAW_STEP_BITS
        nbits -= k
        rng >>= k
        if rng <= 0:  # only a damaged state gets here (a valid range is >= TOP before the shift)
            st[DEC_ERROR] = 1
            rng = 1
        q = code // rng
        if q >> k:  # only a damaged stream gets here
            st[DEC_ERROR] = 1
            q = (1 << k) - 1
        code -= q * rng
        value = (value << k) | q
        while rng < TOP:
            rng <<= 8
            code = ((code << 8) | _get_byte(st, data)) & MASK32
    return value, rng, code


@njit(cache=True, _nrt=False)
def dec_bit(st, data, probs, i):
    """Decode one bit with the adaptive probability ``probs[i]``."""
    bit, rng, code = _decide(st, data, probs, i, st[DEC_RANGE], st[DEC_CODE])
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return bit


@njit(cache=True, _nrt=False)
def dec_raw(st, data, nbits):
    """Decode ``nbits`` raw bits (most significant first)."""
    value = 0
    rng = st[DEC_RANGE]
    code = st[DEC_CODE]
    for _ in range(nbits):
        rng >>= 1
        b = 0
        if code >= rng:
            code -= rng
            b = 1
        value = (value << 1) | b
        while rng < TOP:
            rng <<= 8
            code = ((code << 8) | _get_byte(st, data)) & MASK32
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return value


@njit(cache=True, _nrt=False, error_model="numpy")
def dec_raw_wide(st, data, nbits):
    """Decode ``nbits`` raw bits coded by :func:`enc_raw_wide` (a damaged stream sets the error flag)."""
    value, rng, code = _raw_wide(st, data, nbits, st[DEC_RANGE], st[DEC_CODE])
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return value


@njit(cache=True, _nrt=False)
def dec_sym(st, data, probs, base, nbits):
    """Decode a symbol in ``[0, 2**nbits)`` coded by :func:`enc_sym`."""
    # the decisions on the range and code in registers: this is the hottest call of the
    # connectivity decoder
    rng = st[DEC_RANGE]
    code = st[DEC_CODE]
    node = 1
    for _ in range(nbits):
        bit, rng, code = _decide(st, data, probs, base + node, rng, code)
        node = (node << 1) | bit
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return node - (1 << nbits)


@njit(cache=True, _nrt=False, inline="always")
def _dec_uint(st, data, probs, base, wide):
    nb = dec_sym(st, data, probs, base, INT_BUCKET_BITS)  # a literal: a dec_sym of its own, its bit loop unrolled
    if nb == 0:
        return np.int64(0)
    if nb > _INT_MAX_BUCKET - 1:
        st[DEC_ERROR] = 1
        return np.int64(0)
    mbits = nb - 1
    nmod = mbits if mbits < INT_MODELLED_BITS else INT_MODELLED_BITS
    mbase = base + _INT_MANT_BASE + nb * (1 << INT_MODELLED_BITS)
    value = np.int64(1)
    node = 1
    for _ in range(nmod):
        b = dec_bit(st, data, probs, mbase + node)
        node = (node << 1) | b
        value = (value << 1) | b
    rest = mbits - nmod
    if rest > 0:
        value = (value << rest) | (dec_raw_wide(st, data, rest) if wide else dec_raw(st, data, rest))
    return value


@njit(cache=True, _nrt=False)
def dec_uint(st, data, probs, base):
    """Decode an integer coded by :func:`enc_uint` (a corrupt bucket sets the error flag, returns 0)."""
    return _dec_uint(st, data, probs, base, False)


@njit(cache=True, _nrt=False)
def dec_uint_wide(st, data, probs, base):
    """Decode an integer coded by :func:`enc_uint_wide` (a corrupt bucket sets the error flag, returns 0)."""
    return _dec_uint(st, data, probs, base, True)


@njit(cache=True, _nrt=False)
def dec_sint(st, data, probs, base):
    """Decode a signed integer coded by :func:`enc_sint`."""
    mag = dec_uint(st, data, probs, base)
    if mag != 0 and dec_bit(st, data, probs, base + _INT_SIGN_BASE) == 1:
        return -mag
    return mag


@njit(cache=True, _nrt=False, error_model="numpy")
def dec_sint_wide(st, data, probs, base, sign_context):
    """Decode a signed integer coded by :func:`enc_sint_wide` with the same sign context.

    :func:`dec_uint_wide` and the sign's :func:`dec_bit` in one function, the range and code in
    registers throughout: one call per residual instead of six (the geometry decoder's hottest)."""
    rng = st[DEC_RANGE]
    code = st[DEC_CODE]
    node = 1
    for _ in range(INT_BUCKET_BITS):  # the bucket (bit length), as dec_sym
        bit, rng, code = _decide(st, data, probs, base + node, rng, code)
        node = (node << 1) | bit
    nb = node - (1 << INT_BUCKET_BITS)
    value = np.int64(0)
    if nb > _INT_MAX_BUCKET - 1:  # a corrupt bucket
        st[DEC_ERROR] = 1
    elif nb > 0:
        mbits = nb - 1
        nmod = mbits if mbits < INT_MODELLED_BITS else INT_MODELLED_BITS
        mbase = base + _INT_MANT_BASE + nb * (1 << INT_MODELLED_BITS)
        value = np.int64(1)
        node = 1
        for _ in range(nmod):  # the top mantissa bits, adaptive
            bit, rng, code = _decide(st, data, probs, mbase + node, rng, code)
            node = (node << 1) | bit
            value = (value << 1) | bit
        rest = mbits - nmod
        if rest > 0:
            raw, rng, code = _raw_wide(st, data, rest, rng, code)
            value = (value << rest) | raw
        bit, rng, code = _decide(st, data, probs, base + _INT_SIGN_BASE + sign_context, rng, code)
        if bit == 1:
            value = -value
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return value


@njit(cache=True, _nrt=False)
def _dec_below16(st, data, m):
    rng = st[DEC_RANGE] // m
    code = st[DEC_CODE]
    q = code // rng
    if q >= m:  # only a damaged stream gets here
        st[DEC_ERROR] = 1
        q = m - 1
    code -= q * rng
    while rng < TOP:
        rng <<= 8
        code = ((code << 8) | _get_byte(st, data)) & MASK32
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return q


@njit(cache=True, _nrt=False)
def dec_below(st, data, m):
    """Decode a value coded by :func:`enc_below` with the same ``m``."""
    if m <= 65536:
        return _dec_below16(st, data, m)
    hi = _dec_below16(st, data, ((m - 1) >> 16) + 1)
    rest = m - (hi << 16)
    return (hi << 16) | _dec_below16(st, data, rest if rest < 65536 else 65536)


@njit(cache=True)
def dec_ok(st, data):
    """True when the decoder saw no error and did not read past the end of ``data``.

    A finished encoder emits exactly the bytes the decoder consumes, so after decoding the whole
    stream ``st[DEC_POS]`` also equals ``len(data)`` (:func:`check_decoder` tests that too).
    """
    return st[DEC_ERROR] == 0 and st[DEC_OVERRUN] == 0


@njit(cache=True, _nrt=False)
def dec_failed(st):
    """Cheap test for kernels' loops: an error or overrun has happened."""
    return st[DEC_ERROR] != 0 or st[DEC_OVERRUN] != 0


# ---------------------------------------------------------------- Python helpers


def check_decoder(st: np.ndarray, data: np.ndarray, what: str = "stream", *, complete: bool = True) -> None:
    """Raise :class:`CorruptFileError` if the decoder reports an error or an overrun.

    With ``complete`` (after the last symbol) it also requires that every byte was consumed: the
    decoder reads exactly the bytes the encoder wrote, so leftover bytes mean a damaged stream.
    """
    if st[DEC_ERROR] != 0 or st[DEC_OVERRUN] != 0:
        raise CorruptFileError(f"corrupt {what}: the coded data is damaged or truncated")
    if complete and int(st[DEC_POS]) != len(data):
        raise CorruptFileError(f"corrupt {what}: {len(data) - int(st[DEC_POS])} unexpected trailing bytes")


def run_encoder(kernel, *args, capacity: int = 1 << 16):
    """Call ``kernel(st, out, *args)`` (which must end with :func:`enc_finish`) with a growing buffer.

    The kernel is re-run from scratch with a buffer twice as large whenever it overflowed, so it
    must not mutate its other arguments (copy models inside it). Returns ``bytes``.
    """
    capacity = max(int(capacity), 64)
    while True:
        st = enc_state()
        out = np.empty(capacity, dtype=np.uint8)
        kernel(st, out, *args)
        n = int(st[ENC_POS])
        if not st[ENC_OVERFLOW]:
            return out[:n].tobytes()
        capacity = max(2 * capacity, n + 64)


# Decisions that adapt faster (each update moves the probability 1/8 of the way instead of 1/32):
# for models with many sparse contexts, such as geometry coding 5's rank steps (648 contexts: Room
# fire's x, y, z steps take 645 bytes at this rate; a model of the usual rate estimates 1,070).
FAST_ADAPT_SHIFT = 3


@njit(cache=True)
def enc_bit_fast(st, out, probs, i, bit):
    """:func:`enc_bit` adapting at FAST_ADAPT_SHIFT (decode with :func:`dec_bit_fast`)."""
    _enc_bit_at(st, out, probs, i, bit, FAST_ADAPT_SHIFT)


@njit(cache=True, _nrt=False)
def dec_bit_fast(st, data, probs, i):
    """Decode one bit coded by :func:`enc_bit_fast`."""
    bit, rng, code = _decide_at(st, data, probs, i, st[DEC_RANGE], st[DEC_CODE], FAST_ADAPT_SHIFT)
    st[DEC_RANGE] = rng
    st[DEC_CODE] = code
    return bit
