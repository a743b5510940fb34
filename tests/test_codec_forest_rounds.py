"""Forest codings 2 (format 6: bucket + round per vertex, ranks inside a round by the canonical key of
the level's geometry) and 3 (format 7: the same rounds, the round's phase in a context of the
level's quadrics, parents ordered by them): bytes equal to the slow reference, round trips of
decimated and arbitrary forests, ties, and bad input (truncations, flips, absurd counts, geometry
that does not match)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy, with_unreferenced
from naive_forest import naive_encode_forest_on_geometry, naive_encode_forest_rounds
from test_codec_forest import _boundary, _random_forest

from gatun_py.codec._forest_kernels import bucket_bounds
from gatun_py.codec.forest import (ROOT_RANK, canonical_key, check_forest, decode_forest_on_geometry, decode_forest_rounds,
                                   encode_forest_on_geometry, encode_forest_on_mesh, encode_forest_rounds, forest_header,
                                   rank_rounds)
from gatun_py.errors import CorruptFileError
from gatun_py.simplify import decimate


# coding -> (encoder, decoder, slow reference, magic)
CODINGS = {2: (encode_forest_rounds, decode_forest_rounds, naive_encode_forest_rounds, b"GFR6"),
           3: (encode_forest_on_geometry, decode_forest_on_geometry, naive_encode_forest_on_geometry, b"GFR7")}


def _round_trip(parent, rank, tets, n, points, density, coding=2):
    encode, decode, naive, _ = CODINGS[coding]
    b = _boundary(tets, n)
    data = encode(parent, rank, tets, boundary=b, points=points, density=density)
    assert data == naive(parent, rank, tets, b, points, density)
    p, r = decode(data, tets, n, boundary=b, points=points, density=density)
    assert np.array_equal(p, parent) and np.array_equal(r, rank)
    assert p.dtype == np.int32 and r.dtype == np.int32
    return data


@pytest.mark.parametrize("coding", sorted(CODINGS))
@settings(max_examples=30, deadline=None)
@given(mesh=mesh_strategy(), rounds=st.integers(0, 8))
def test_decimated_forest_matches_reference_and_round_trips(coding, mesh, rounds):
    f = decimate(mesh, rounds=rounds)
    _round_trip(f.parent, f.rank, mesh.tets, mesh.n_points, mesh.points, mesh.density, coding)


@pytest.mark.parametrize("coding", sorted(CODINGS))
@settings(max_examples=30, deadline=None)
@given(n_points=st.integers(1, 60), seed=st.integers(0, 2**31), roots=st.integers(1, 4))
def test_arbitrary_forest_round_trips(coding, n_points, seed, roots):
    """Any valid forest codes (a greedy order just has many short rounds), duplicate points too."""
    mesh = delaunay_mesh(max(n_points, 5), seed % 1000)
    n = mesh.n_points
    parent, rank = _random_forest(n, seed, min(roots, n))
    _round_trip(parent, rank, mesh.tets, n, mesh.points, mesh.density, coding)
    pts = mesh.points.copy()
    pts[n // 2] = pts[0]  # two vertices of equal key (a tie splits a round)
    _round_trip(parent, rank, mesh.tets, n, pts, np.zeros(n, np.float32), coding)


@pytest.mark.parametrize("coding", sorted(CODINGS))
def test_unreferenced_vertices_no_tets_and_empty(coding):
    mesh = with_unreferenced(grid_mesh(3, 3, 3, jitter=0.1, seed=2), 5, seed=1)
    f = decimate(mesh)
    _round_trip(f.parent, f.rank, mesh.tets, mesh.n_points, mesh.points, mesh.density, coding)
    parent, rank = _random_forest(9, 4)
    rng = np.random.default_rng(0)
    _round_trip(parent, rank, np.zeros((0, 4), np.int32), 9, rng.random((9, 3)).astype(np.float32), np.zeros(9), coding)
    data = _round_trip(np.arange(4), np.full(4, ROOT_RANK), np.array([[0, 1, 2, 3]]), 4, np.eye(4, 3), np.zeros(4),
                       coding)
    assert len(data) == 12 and forest_header(data) == (4, 0)
    _round_trip(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4), int), 0, np.zeros((0, 3)), np.zeros(0), coding)


def test_rounds_of_a_forest_give_back_its_ranks():
    mesh = delaunay_mesh(200, 3)
    f = decimate(mesh, rounds=4)
    key = canonical_key(mesh.points, mesh.density)
    k = f.n_merges
    ranks = np.where(f.rank == ROOT_RANK, k, f.rank)
    rid, n_rounds = rank_rounds(ranks, k, key)
    bounds = bucket_bounds(mesh.n_points, k)
    assert len(n_rounds) == len(bounds) - 1 and np.all(n_rounds >= 1) and np.all(n_rounds <= np.diff(bounds))
    merged = np.flatnonzero(ranks < k)
    bucket = np.searchsorted(bounds, ranks[merged], side="right") - 1
    order = merged[np.lexsort((key[merged], rid[merged], bucket))]
    assert np.array_equal(ranks[order], np.arange(k))
    for s in range(len(n_rounds)):  # rounds numbered 0 .. n_rounds - 1, none empty
        assert np.array_equal(np.unique(rid[merged[bucket == s]]), np.arange(n_rounds[s]))
    assert np.all(rid[ranks >= k] == -1)
    # the decimator's rounds (4 a level) are what the coder finds, or fewer (runs may join)
    assert n_rounds.sum() <= len(decimate(mesh, rounds=4, return_rounds=True)[1])


def test_fewer_bits_than_coding_1_with_rounds_and_than_coding_2_with_quadrics():
    mesh = grid_mesh(14, 13, 12, jitter=0.2, seed=3)
    f = decimate(mesh)
    b = _boundary(mesh.tets, mesh.n_points)
    geo = dict(boundary=b, points=mesh.points, density=mesh.density)
    new = encode_forest_rounds(f.parent, f.rank, mesh.tets, **geo)
    old = encode_forest_on_mesh(f.parent, f.rank, mesh.tets, boundary=b)
    assert len(new) < 0.95 * len(old)  # 64 rounds a level on 2,184 vertices: rounds of a few merges
    # the quadrics put the decimator's choice of parent first most of the time
    assert len(encode_forest_on_geometry(f.parent, f.rank, mesh.tets, **geo)) < 0.95 * len(new)


@pytest.mark.parametrize("coding", sorted(CODINGS))
def test_bad_bytes_raise_typed_errors_never_out_of_bounds(coding):
    encode, decode_forest, _, magic = CODINGS[coding]
    mesh = grid_mesh(6, 5, 4, jitter=0.1, seed=5)
    f = decimate(mesh, rounds=4)
    n, tets = mesh.n_points, mesh.tets
    bnd = _boundary(tets, n)
    geo = dict(points=mesh.points, density=mesh.density)
    data = encode(f.parent, f.rank, tets, boundary=bnd, **geo)

    def decode(d, **kw):
        args = dict(boundary=bnd, **geo)
        args.update(kw)
        return decode_forest(d, tets, n, **args)

    for other in (dict(boundary=~bnd), dict(points=mesh.points[::-1].copy()), dict(density=-mesh.density)):
        try:  # other inputs than the encoder's: an error or some other valid forest, never a crash
            check_forest(*decode(data, **other))
        except CorruptFileError:
            pass
    with pytest.raises(CorruptFileError):  # every vertex at one point: ties inside rounds
        decode(data, points=np.zeros((n, 3), np.float32), density=np.zeros(n, np.float32))
    with pytest.raises(CorruptFileError):
        decode_forest(data, tets, n + 1, boundary=np.zeros(n + 1, bool), points=np.zeros((n + 1, 3)),
                             density=np.zeros(n + 1))
    for cut in (0, 5, 11, 12, 13, len(data) // 2, len(data) - 1):
        with pytest.raises(CorruptFileError):
            decode(data[:cut])
    with pytest.raises(CorruptFileError):
        decode(data + b"x")
    with pytest.raises(CorruptFileError):  # coding 1's magic
        decode(encode_forest_on_mesh(f.parent, f.rank, tets, boundary=bnd))
    with pytest.raises(CorruptFileError):  # the other coding's magic
        decode(CODINGS[5 - coding][0](f.parent, f.rank, tets, boundary=bnd, **geo))
    for k in (n, n + 1, 2**32 - 1):  # absurd merge counts
        with pytest.raises(CorruptFileError):
            decode(struct.pack("<4sII", magic, n, k) + data[12:])
    with pytest.raises(CorruptFileError):
        decode_forest(data, np.full((2, 4), n, np.int32), n, boundary=bnd, **geo)
    rng = np.random.default_rng(0)
    for _ in range(300):
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(12, len(b)))
            b[i] ^= 1 << int(rng.integers(0, 8))
        try:
            p, r = decode(bytes(b))
        except CorruptFileError:
            continue
        check_forest(p, r)
    for _ in range(100):  # random garbage after a valid header
        body = rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8).tobytes()
        try:
            check_forest(*decode(data[:12] + body))
        except CorruptFileError:
            pass


@pytest.mark.parametrize("coding", sorted(CODINGS))
def test_warmup_section_is_what_the_encoder_writes(coding):
    from gatun_py.warmup import (FOREST_PARENT_RANK, FOREST_POINTS, FOREST_SECTION_GEOMETRY, FOREST_SECTION_ROUNDS,
                                 FOREST_TETS)

    encode, decode, _, _ = CODINGS[coding]
    section = FOREST_SECTION_ROUNDS if coding == 2 else FOREST_SECTION_GEOMETRY
    parent, rank = (np.array(x) for x in FOREST_PARENT_RANK)
    geo = dict(points=FOREST_POINTS, density=np.zeros(5, np.float32))
    assert encode(parent, rank, FOREST_TETS, boundary=np.ones(5, bool), **geo) == section
    p, r = decode(section, FOREST_TETS, 5, boundary=np.ones(5, bool), **geo)
    assert p.tolist() == parent.tolist() and r.tolist() == rank.tolist()


def test_a_decode_after_read_forest_reuses_the_geometry_it_decoded():
    """Forest coding 2 is decoded after the level's connectivity and geometry; the next decode of
    that level (a render at a ratio) takes both over instead of decoding them again, with the
    same batches as a fresh reader's."""
    from gatun_py.codec import TetcReader
    from gatun_py.codec.decoded_connectivity import DecodedGeometry
    from gatun_py.warmup import SHIPPED_TETC

    data = SHIPPED_TETC.read_bytes()
    fresh = list(TetcReader(data).iter_decode(batch_tets=40))
    r = TetcReader(data)
    assert r.read_forest(0) is not None
    assert r._decoded_geometry is not None and r._decoded_geometry[0] == 0
    geo = r._geometry(0, r.level_meta(0)["points"])
    assert isinstance(geo, DecodedGeometry) and r._decoded_geometry is None
    r._decoded_geometry = (0, geo.values)
    again = list(r.iter_decode(batch_tets=40))
    assert r._decoded_geometry is None
    assert len(again) == len(fresh)
    for a, b in zip(again, fresh):
        assert a.first == b.first
        assert np.array_equal(a.tets, b.tets) and np.array_equal(a.points, b.points)
        assert np.array_equal(a.density, b.density)


@settings(max_examples=20, deadline=None)
@given(mesh=mesh_strategy(), seed=st.integers(0, 2**31))
def test_coding_3_ignores_the_tets_order_and_orientation(mesh, seed):
    """The decoder sees the level's tets in the connectivity decoder's order and corner order, the
    encoder in the input's: the quadrics (float sums) must not depend on either."""
    f = decimate(mesh, rounds=4)
    b = _boundary(mesh.tets, mesh.n_points)
    geo = dict(boundary=b, points=mesh.points, density=mesh.density)
    data = encode_forest_on_geometry(f.parent, f.rank, mesh.tets, **geo)
    rng = np.random.default_rng(seed)
    shuffled = mesh.tets[rng.permutation(mesh.n_tets)]
    shuffled = np.take_along_axis(shuffled, np.argsort(rng.random(shuffled.shape), axis=1), axis=1)
    assert encode_forest_on_geometry(f.parent, f.rank, shuffled, **geo) == data
    p, r = decode_forest_on_geometry(data, shuffled, mesh.n_points, **geo)
    assert np.array_equal(p, f.parent) and np.array_equal(r, f.rank)
