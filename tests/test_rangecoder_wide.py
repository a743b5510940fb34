"""The range coder's wide raw steps (``enc_raw_wide`` and the integers on them): round trips mixed
with adaptive bits, equivalence of the decoded values with the narrow coder's, damaged input."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from gatun_py.codec import rangecoder as rc


@njit(cache=True)
def _encode_wide(st_, out, kinds, values, nbits):
    """kinds: 0 adaptive bit, 1 wide raw bits (nbits), 2 signed integer (sign context nbits & 1)."""
    probs = np.full(8 + rc.INT_MODEL_SIZE, rc.PROB_INIT, np.uint16)
    for i in range(kinds.shape[0]):
        if kinds[i] == 0:
            rc.enc_bit(st_, out, probs, 1, values[i])
        elif kinds[i] == 1:
            rc.enc_raw_wide(st_, out, values[i], nbits[i])
        else:
            rc.enc_sint_wide(st_, out, probs, 8, values[i], nbits[i] & 1)
    return rc.enc_finish(st_, out)


@njit(cache=True)
def _decode_wide(st_, data, kinds, nbits, values):
    probs = np.full(8 + rc.INT_MODEL_SIZE, rc.PROB_INIT, np.uint16)
    rc.dec_init(st_, data)
    for i in range(kinds.shape[0]):
        if kinds[i] == 0:
            values[i] = rc.dec_bit(st_, data, probs, 1)
        elif kinds[i] == 1:
            values[i] = rc.dec_raw_wide(st_, data, nbits[i])
        else:
            values[i] = rc.dec_sint_wide(st_, data, probs, 8, nbits[i] & 1)


def _ops(seed, n):
    rng = np.random.default_rng(seed)
    kinds = rng.integers(0, 3, n)
    nbits = rng.integers(0, 41, n)
    values = np.where(kinds == 0, rng.integers(0, 2, n),
                      np.where(kinds == 1, rng.integers(0, 1 << 62, n) & ((1 << nbits) - 1),
                               rng.integers(-(1 << 39), 1 << 39, n) >> rng.integers(0, 40, n)))
    return kinds, values.astype(np.int64), nbits


def _encode(kinds, values, nbits):
    st_ = rc.enc_state()
    out = np.empty(64 + 8 * len(kinds), np.uint8)
    n = _encode_wide(st_, out, kinds, values, nbits)
    assert not st_[rc.ENC_OVERFLOW]
    return out[:n].copy()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 400))
def test_wide_steps_round_trip_mixed_with_adaptive_bits(seed, n):
    kinds, values, nbits = _ops(seed, n)
    data = _encode(kinds, values, nbits)
    got = np.zeros(n, np.int64)
    st_ = rc.dec_state()
    _decode_wide(st_, data, kinds, nbits, got)
    np.testing.assert_array_equal(got, values)
    rc.check_decoder(st_, data)


def test_wide_raw_bits_cost_what_they_carry():
    # 40 000 raw bits in 16-bit steps: within a fraction of a percent of 5 000 bytes
    kinds = np.ones(2500, np.int64)
    nbits = np.full(2500, 16, np.int64)
    values = np.random.default_rng(1).integers(0, 1 << 16, 2500)
    assert len(_encode(kinds, values, nbits)) <= 5000 * 1.003 + 8


def test_damaged_wide_streams_are_flagged_never_read_past_the_end():
    kinds, values, nbits = _ops(5, 300)
    data = _encode(kinds, values, nbits)
    rng = np.random.default_rng(3)
    flagged = 0
    for trial in range(200):
        bad = data.copy()
        if trial % 2:
            bad = bad[: int(rng.integers(0, len(bad)))]
        else:
            bad[int(rng.integers(0, len(bad)))] ^= int(rng.integers(1, 256))
        st_ = rc.dec_state()
        got = np.zeros(len(kinds), np.int64)
        _decode_wide(st_, bad, kinds, nbits, got)
        ok = rc.dec_ok(st_, bad) and int(st_[rc.DEC_POS]) == len(bad)
        flagged += not ok or not np.array_equal(got, values)
    assert flagged >= 190  # a flip in the last flushed bytes may leave every value intact
