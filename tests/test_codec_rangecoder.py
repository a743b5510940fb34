"""The range coder kernels against the plain-Python reference, round trips and damaged input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from gatun_py.codec import rangecoder as rc
from gatun_py.errors import CorruptFileError
from naive_codec import NaiveRangeDecoder, NaiveRangeEncoder

N_CTX = 4


@njit(cache=True)
def _encode_ops(st_, out, kinds, values, ctxs):
    """kinds: 0 bit, 1 raw (16 bits), 2 3-bit symbol, 3 signed integer, 4 unsigned integer."""
    probs = np.full(64 + N_CTX * rc.INT_MODEL_SIZE, rc.PROB_INIT, np.uint16)
    for i in range(kinds.shape[0]):
        k = kinds[i]
        if k == 0:
            rc.enc_bit(st_, out, probs, ctxs[i], values[i])
        elif k == 1:
            rc.enc_raw(st_, out, values[i], 16)
        elif k == 2:
            rc.enc_sym(st_, out, probs, 8 + 8 * ctxs[i], 3, values[i])
        elif k == 3:
            rc.enc_sint(st_, out, probs, 64 + ctxs[i] * rc.INT_MODEL_SIZE, values[i])
        else:
            rc.enc_uint(st_, out, probs, 64 + ctxs[i] * rc.INT_MODEL_SIZE, values[i])
    rc.enc_finish(st_, out)


@njit(cache=True)
def _decode_ops(st_, data, kinds, ctxs, values):
    probs = np.full(64 + N_CTX * rc.INT_MODEL_SIZE, rc.PROB_INIT, np.uint16)
    rc.dec_init(st_, data)
    for i in range(kinds.shape[0]):
        if rc.dec_failed(st_):
            return i
        k = kinds[i]
        if k == 0:
            values[i] = rc.dec_bit(st_, data, probs, ctxs[i])
        elif k == 1:
            values[i] = rc.dec_raw(st_, data, 16)
        elif k == 2:
            values[i] = rc.dec_sym(st_, data, probs, 8 + 8 * ctxs[i], 3)
        elif k == 3:
            values[i] = rc.dec_sint(st_, data, probs, 64 + ctxs[i] * rc.INT_MODEL_SIZE)
        else:
            values[i] = rc.dec_uint(st_, data, probs, 64 + ctxs[i] * rc.INT_MODEL_SIZE)
    return kinds.shape[0]


def _random_ops(rng, n):
    kinds = rng.integers(0, 5, n)
    ctxs = rng.integers(0, N_CTX, n)
    values = np.zeros(n, np.int64)
    skewed = rng.random(n) < 0.8
    values[kinds == 0] = (rng.random((kinds == 0).sum()) < np.where(skewed[kinds == 0], 0.05, 0.5))
    values[kinds == 1] = rng.integers(0, 1 << 16, (kinds == 1).sum())
    values[kinds == 2] = np.minimum(rng.geometric(0.5, (kinds == 2).sum()) - 1, 7)
    mags = rng.integers(0, 1 << 40, n) >> rng.integers(0, 41, n)
    values[kinds == 3] = (mags * rng.choice([-1, 1], n))[kinds == 3]
    values[kinds == 4] = mags[kinds == 4]
    return kinds, values, ctxs


def _encode(kinds, values, ctxs, capacity=16):
    return rc.run_encoder(_encode_ops, kinds, values, ctxs, capacity=capacity)


def _decode(data, kinds, ctxs):
    st_ = rc.dec_state()
    buf = np.frombuffer(data, np.uint8)
    values = np.zeros(len(kinds), np.int64)
    _decode_ops(st_, buf, kinds, ctxs, values)
    rc.check_decoder(st_, buf)
    return values


@pytest.mark.parametrize("seed", range(5))
def test_round_trip_mixed_operations(seed):
    rng = np.random.default_rng(seed)
    kinds, values, ctxs = _random_ops(rng, int(rng.integers(0, 3000)))
    data = _encode(kinds, values, ctxs)
    assert np.array_equal(_decode(data, kinds, ctxs), values)


def test_matches_plain_python_reference_bytes():
    rng = np.random.default_rng(11)
    n = 4000
    kinds = rng.integers(0, 3, n)
    ctxs = rng.integers(0, N_CTX, n)
    values = np.where(kinds == 0, rng.random(n) < 0.1, np.where(kinds == 1, rng.integers(0, 1 << 16, n),
                                                                 rng.integers(0, 8, n))).astype(np.int64)
    data = _encode(kinds, values, ctxs)
    enc = NaiveRangeEncoder()
    probs = [rc.PROB_INIT] * (64 + N_CTX * rc.INT_MODEL_SIZE)
    for k, v, c in zip(kinds.tolist(), values.tolist(), ctxs.tolist()):
        if k == 0:
            enc.bit(probs, c, v)
        elif k == 1:
            enc.raw(v, 16)
        else:
            enc.sym(probs, 8 + 8 * c, 3, v)
    ref = enc.finish()
    assert data == ref
    dec = NaiveRangeDecoder(ref)
    probs = [rc.PROB_INIT] * (64 + N_CTX * rc.INT_MODEL_SIZE)
    out = []
    for k, c in zip(kinds.tolist(), ctxs.tolist()):
        out.append(dec.bit(probs, c) if k == 0 else dec.raw(16) if k == 1 else dec.sym(probs, 8 + 8 * c, 3))
    assert out == values.tolist() and not dec.overrun and dec.pos == len(ref)


@njit(cache=True)
def _encode_mixed_rates(st, bits, ctxs, fast, out):
    probs = np.full(16, rc.PROB_INIT, dtype=np.uint16)
    for j in range(bits.shape[0]):
        if fast[j]:
            rc.enc_bit_fast(st, out, probs, ctxs[j], bits[j])
        else:
            rc.enc_bit(st, out, probs, ctxs[j], bits[j])
    return rc.enc_finish(st, out)


@njit(cache=True)
def _decode_mixed_rates(st, data, ctxs, fast):
    rc.dec_init(st, data)
    probs = np.full(16, rc.PROB_INIT, dtype=np.uint16)
    got = np.zeros(ctxs.shape[0], dtype=np.int64)
    for j in range(ctxs.shape[0]):
        got[j] = rc.dec_bit_fast(st, data, probs, ctxs[j]) if fast[j] else rc.dec_bit(st, data, probs, ctxs[j])
    return got, st[rc.DEC_POS]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fast_adapting_bits_match_the_plain_reference(seed):
    """enc_bit_fast / dec_bit_fast (shift FAST_ADAPT_SHIFT) mixed with the usual rate on shared
    models: the bytes of the plain Python coder, decoded back."""
    rng = np.random.default_rng(seed)
    n = 3000
    bits = (rng.random(n) < rng.choice([0.02, 0.3, 0.9], n)).astype(np.int64)
    ctxs = rng.integers(0, 16, n)
    fast = rng.random(n) < 0.5
    out = np.empty(2 * n + 64, np.uint8)
    data = out[:_encode_mixed_rates(rc.enc_state(), bits, ctxs, fast, out)].copy()
    enc = NaiveRangeEncoder()
    probs = [rc.PROB_INIT] * 16
    for b, c, f in zip(bits.tolist(), ctxs.tolist(), fast.tolist()):
        enc.bit(probs, c, b, rc.FAST_ADAPT_SHIFT if f else rc.ADAPT_SHIFT)
    assert data.tobytes() == enc.finish()
    got, pos = _decode_mixed_rates(rc.dec_state(), data, ctxs, fast)
    assert got.tolist() == bits.tolist() and pos == len(data)


def test_skewed_bits_cost_little():
    kinds = np.zeros(20000, np.int64)
    values = np.zeros(20000, np.int64)
    ctxs = np.zeros(20000, np.int64)
    data = _encode(kinds, values, ctxs)
    assert len(data) * 8 / 20000 < 0.01  # adaptive probability reaches the 15-bit precision


def test_buffer_growth_gives_identical_bytes():
    rng = np.random.default_rng(3)
    kinds, values, ctxs = _random_ops(rng, 500)
    assert _encode(kinds, values, ctxs, capacity=16) == _encode(kinds, values, ctxs, capacity=1 << 20)


def test_truncation_is_detected():
    rng = np.random.default_rng(5)
    kinds, values, ctxs = _random_ops(rng, 400)
    data = _encode(kinds, values, ctxs)
    for cut in range(0, len(data), max(1, len(data) // 50)):
        with pytest.raises(CorruptFileError):
            _decode(data[:cut], kinds, ctxs)


def test_trailing_bytes_are_detected():
    rng = np.random.default_rng(6)
    kinds, values, ctxs = _random_ops(rng, 100)
    with pytest.raises(CorruptFileError):
        _decode(_encode(kinds, values, ctxs) + b"\x00", kinds, ctxs)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200), st.integers(0, 2**32 - 1))
def test_garbage_never_crashes(data, seed):
    rng = np.random.default_rng(seed)
    kinds, _, ctxs = _random_ops(rng, 300)
    try:
        _decode(data, kinds, ctxs)
    except CorruptFileError:
        pass
