"""Tests of the lossless geometry/density coder (gatun_py.codec.geometry)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_sample
from meshgen import cavity_mesh, delaunay_mesh, grid_mesh, two_components, with_unreferenced
from naive_geometry import emulate_decode_order, naive_symbols
from gatun_py.codec import _geometry_kernels as K
from gatun_py.codec.geometry import (
    CODINGS,
    FORMAT_VERSION,
    HEADER_SIZE,
    XY_TABLE_BIT,
    GeometryDecoder,
    _channels,
    _ordered,
    _run_encode,
    decode_geometry,
    encode_geometry,
    geometry_stream_sizes,
    refs_from_predictors,
)
from gatun_py.errors import CorruptFileError

_orders: dict = {}


def _in_decode_order(mesh):
    """Points, density and refs of a mesh in an emulated cut-border decode order (cached)."""
    key = (mesh.n_points, mesh.tets.tobytes(), mesh.points.tobytes())
    if key not in _orders:
        order, refs = emulate_decode_order(mesh.tets, mesh.n_points)
        _orders[key] = (np.ascontiguousarray(mesh.points[order]), np.ascontiguousarray(mesh.density[order]),
                        refs)
    return _orders[key]


def _assert_bit_identical(a, b):
    a = np.ascontiguousarray(a, dtype=np.float32)
    b = np.ascontiguousarray(b, dtype=np.float32)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.int32), b.view(np.int32))


def _round_trip(points, density, refs, **kw):
    blob = encode_geometry(points, density, refs, **kw)
    p2, d2 = decode_geometry(blob, refs, n_points=len(density))
    _assert_bit_identical(p2, points)
    _assert_bit_identical(d2, density)
    return blob


def _random_refs(rng, n, apex=True):
    refs = np.full((n, 4), -1, dtype=np.int32)
    for k in range(n):
        for j in range(4 if apex else 3):
            if k and rng.random() < 0.85:
                refs[k, j] = rng.integers(0, k)
    return refs


# ------------------------------------------------------------------------------ round trips


def test_round_trip_real_samples(sample):
    """In the cut-border coder's own vertex order, with its refs."""
    from gatun_py.codec.cutborder import encode_connectivity

    name, mesh = sample
    ec = encode_connectivity(mesh.n_points, mesh.tets)
    points = np.ascontiguousarray(mesh.points[ec.vertex_order])
    density = np.ascontiguousarray(mesh.density[ec.vertex_order])
    blob = _round_trip(points, density, ec.predictors)
    bits_per_vertex = 8 * len(blob) / mesh.n_points
    # raw float32 is 128 bits per vertex; every sample has structure the coder must find
    assert bits_per_vertex < 80, (name, bits_per_vertex)


def test_round_trip_emulated_order(small_sample):
    """In the emulated decode order of naive_geometry (independent of the connectivity coder)."""
    points, density, refs = _in_decode_order(small_sample)
    blob = _round_trip(points, density, refs)
    assert 8 * len(blob) / small_sample.n_points < 40


def test_repetition_makes_grid_coordinates_cheap():
    """A regular grid reuses few values per axis: coordinates must cost a few bits per vertex."""
    mesh = grid_mesh(12, 12, 12)
    points, density, refs = _in_decode_order(mesh)
    blob = _round_trip(points, density, refs)
    sizes = geometry_stream_sizes(blob)
    coord_bits = 8 * (sizes["x"] + sizes["y"] + sizes["z"]) / mesh.n_points
    assert coord_bits < 5, coord_bits  # (raw: 96; measured 4.2, mostly model warm-up)


@pytest.mark.parametrize("make", [cavity_mesh, two_components, lambda: with_unreferenced(grid_mesh(3, 3, 3), 4)])
def test_round_trip_awkward_meshes(make):
    mesh = make()
    points, density, refs = _in_decode_order(mesh)
    _round_trip(points, density, refs)


@pytest.mark.parametrize("modes", [(0, 0, 0, 0), (1, 1, 1, 1), (1, 0, 1, 0)])
def test_every_mode_round_trips(modes):
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    blob = _round_trip(points, density, refs, modes=modes)
    sizes = geometry_stream_sizes(blob)
    got = [sizes[c + "_mode"] == "table" for c in ("x", "y", "z", "density")]
    assert got == [bool(m) for m in modes]


@pytest.mark.parametrize("name", ["post", "bluntfin"])
def test_mode_choice_keeps_the_smaller_stream(name):
    """Per channel the smaller of the two modes, also where most values are distinct but repeat
    enough for a table (Blunt-fin's density: 28,025 values on 40,960 vertices). Coding 3: a
    table-mode channel's stream holds its table; coding 4: the tables are apart, and the block is
    no larger than with either mode forced on every channel (a table's bytes are estimated alone:
    a few bytes of slack)."""
    mesh = load_sample(name)[0]
    points, density, refs = _in_decode_order(mesh)
    blobs = {}
    for coding in (3, 4):
        blobs[coding] = [encode_geometry(points, density, refs, modes=modes, coding=coding)
                         for modes in [None, (0, 0, 0, 0), (1, 1, 1, 1)]]
    auto, *forced = map(geometry_stream_sizes, blobs[3])
    for ch in ("x", "y", "z", "density"):
        assert auto[ch] <= min(f[ch] for f in forced), ch
    if name == "bluntfin":
        assert auto["density_mode"] == "table" and auto["density"] < forced[0]["density"]
    auto4, *forced4 = blobs[4]
    assert len(auto4) <= min(map(len, forced4)) + 8
    assert [geometry_stream_sizes(auto4)[c + "_mode"] for c in ("x", "y", "z", "density")] == \
        [auto[c + "_mode"] for c in ("x", "y", "z", "density")]


def test_three_column_refs_and_empty_and_single():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(50, 3)).astype(np.float32)
    den = rng.normal(size=50).astype(np.float32)
    refs = _random_refs(rng, 50, apex=False)[:, :3]
    _round_trip(pts, den, refs)
    _round_trip(np.zeros((0, 3), np.float32), np.zeros(0, np.float32), np.zeros((0, 4), np.int32))
    _round_trip(np.array([[1.5, -2.0, 3.0]], np.float32), np.array([7.0], np.float32), np.full((1, 4), -1, np.int32))


def test_special_floats_round_trip():
    specials = np.array([0.0, -0.0, 1e-45, -1e-45, 1.17549435e-38, -1.17549435e-38, 3.4028235e38,
                         -3.4028235e38, 1e-30, 1e30, 1.0, -1.0, np.nextafter(np.float32(1), np.float32(2)),
                         np.inf, -np.inf, np.nan], dtype=np.float32)
    rng = np.random.default_rng(7)
    n = 400
    pts = rng.choice(specials, size=(n, 3)).astype(np.float32)
    den = rng.choice(specials, size=n).astype(np.float32)
    # a NaN with an unusual payload and a signalling-style pattern
    den[:2] = np.array([0x7FC12345, 0xFF800001], dtype=np.uint32).view(np.float32)
    refs = _random_refs(rng, n)
    _round_trip(pts, den, refs)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 120), seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["bits", "smooth", "few"]),
       batch=st.integers(1, 50), coding=st.sampled_from(CODINGS))
def test_hypothesis_round_trip_streaming_both_codings(n, seed, kind, batch, coding):
    _streaming_round_trip(n, seed, kind, batch, coding)


def _random_values(rng, n, kind):
    """(n, 4) float32: any bit pattern at all (``bits``), random walks (``smooth``) or a few values."""
    if kind == "bits":
        vals = rng.integers(-(2**31), 2**31, size=(n, 4), dtype=np.int64).astype(np.int32).view(np.float32)
    elif kind == "smooth":
        vals = np.cumsum(rng.normal(size=(n, 4)), axis=0).astype(np.float32)
    else:
        vals = rng.choice(np.array([-2.5, 0.0, 1.0, 3.25, 1e-40], np.float32), size=(n, 4))
    return np.ascontiguousarray(vals)


def _decode_in_batches(blob, vals, refs, batch):
    """Decode ``batch`` vertices at a time, each batch checked bit for bit against ``vals``."""
    dec = GeometryDecoder(blob, n_points=len(vals))
    for start in range(0, len(vals), batch):
        p, d = dec.decode(refs[start:start + batch])
        _assert_bit_identical(p, vals[start:start + batch, :3])
        _assert_bit_identical(d, vals[start:start + batch, 3])
    dec.finish()


def _streaming_round_trip(n, seed, kind, batch, coding=FORMAT_VERSION):
    rng = np.random.default_rng(seed)
    vals = _random_values(rng, n, kind)
    refs = _random_refs(rng, n)
    _decode_in_batches(encode_geometry(vals[:, :3], vals[:, 3], refs, coding=coding), vals, refs, batch)


# ------------------------------------------------------------------------------ reference model


def _kernel_trace(points, density, refs, modes, coding=FORMAT_VERSION):
    vf = _channels(points, density)
    ordered = _ordered(vf)
    tables_list = [np.unique(ordered[:, ch]) for ch in range(4)]
    tables = np.concatenate(tables_list)
    offs = np.zeros(5, np.int64)
    offs[1:] = np.cumsum([len(t) for t in tables_list])
    trace = np.zeros((len(vf), 4, 3), np.int64)
    full = np.full((len(vf), 4), -1, np.int32)
    full[:, : refs.shape[1]] = refs
    _run_encode(vf, full, np.asarray(modes, np.int64), tables, offs, K.candidate_table(coding), trace)
    return vf, full, trace


def test_naive_reference_uses_the_kernel_constants():
    import naive_geometry

    assert naive_geometry.ADJ_CAP == K.ADJ_CAP


@pytest.mark.parametrize("coding", K.CODINGS)  # the kernels' (coding 4 runs coding 3's model)
@pytest.mark.parametrize("modes", [(0, 0, 0, 0), (1, 1, 1, 1)])
def test_kernel_model_matches_naive_reference_on_post(modes, coding):
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    vf, full, trace = _kernel_trace(points, density, refs, modes, coding)
    np.testing.assert_array_equal(trace, naive_symbols(vf, full, modes, coding))


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")  # inf - inf in the reference's numpy
@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 60), seed=st.integers(0, 2**32 - 1), modes=st.tuples(*[st.integers(0, 1)] * 4),
       hub=st.booleans(), coding=st.sampled_from(K.CODINGS))
def test_kernel_model_matches_naive_reference_random(n, seed, modes, hub, coding):
    rng = np.random.default_rng(seed)
    few = rng.choice(np.array([0.0, -0.0, 1.0, 2.0, -3.5, 1e-42, 7e20, np.nan, np.inf], np.float32), size=(n, 4))
    vals = np.where(rng.random((n, 4)) < 0.3, rng.normal(size=(n, 4)), few).astype(np.float32)
    refs = _random_refs(rng, n)
    if hub and n > 2:  # one vertex in every face: its neighbour list overflows ADJ_CAP
        refs[2:, 0] = 0
    vf, full, trace = _kernel_trace(vals[:, :3], vals[:, 3], refs, modes, coding)
    np.testing.assert_array_equal(trace, naive_symbols(vf, full, modes, coding))


@settings(max_examples=20, deadline=None)
@given(n=st.integers(4, 60), seed=st.integers(0, 2**32 - 1))
def test_tet_geometry_predictors_match_naive_reference_on_smooth_meshes(n, seed):
    """Version 2's predictors on a smooth field over jittered points (where they are chosen)."""
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(n, 3)) * 10.0
    vals = np.empty((n, 4), np.float32)
    vals[:, :3] = xyz
    vals[:, 3] = 2.0 * xyz[:, 0] - xyz[:, 1] + 0.5 * xyz[:, 2] + 0.01 * rng.normal(size=n)
    refs = _random_refs(rng, n)
    vf, full, trace = _kernel_trace(vals[:, :3], vals[:, 3], refs, (0, 0, 0, 0), 2)
    np.testing.assert_array_equal(trace, naive_symbols(vf, full, (0, 0, 0, 0), 2))
    # the linear field is predicted exactly up to its noise: the tet candidate wins on density
    used = trace[:, 3, 2]
    if n > 30:
        assert (used >= K.N_CANDS_V1[K.PAT_FACE_APEX]).any()


def test_geometry_predictors_fall_back_on_flat_and_broken_tets():
    import naive_geometry as N

    vals = np.zeros((5, 4), np.float32)
    vals[1, 0] = vals[2, 1] = 1.0  # 0, 1, 2 in the plane z = 0; 3 on the same plane: a flat tet
    vals[3, :2] = 0.5
    vals[4] = (0.2, 0.2, 1.0, 7.0)
    vf = np.ascontiguousarray(vals)
    assert K._tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0) == N.naive_tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0) == 42.0
    vals[3, 2] = np.nan  # a broken apex
    assert K._tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0) == 42.0
    vals[3] = (0.0, 0.0, 1.0, 1.0)  # a proper tet; vertex 4 inside it: an interpolation
    got = K._tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0)
    assert got == N.naive_tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0) and got != 42.0
    vals[4, :3] = (1e6, 0.0, 0.0)  # far outside: not an extrapolation the coder trusts
    assert K._tet_linear(vf, 4, 0, 1, 2, 3, 3, 42.0) == 42.0
    assert K._tri_linear(vf, 4, 0, 1, 1, 3, -1.0) == -1.0  # a degenerate triangle


@pytest.mark.parametrize("coding", CODINGS)
def test_both_codings_round_trip_and_say_which_they_are(coding):
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    blob = _round_trip(points, density, refs, coding=coding)
    assert blob[0] == coding
    assert GeometryDecoder(blob).coding == coding


def test_each_coding_is_no_larger_on_the_samples_than_the_one_before():
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    v1 = encode_geometry(points, density, refs, coding=1)
    v2 = encode_geometry(points, density, refs, coding=2)
    v3 = encode_geometry(points, density, refs, coding=3)
    v4 = encode_geometry(points, density, refs, coding=4)
    v5 = encode_geometry(points, density, refs, coding=5)
    assert len(v3) <= len(v2) < len(v1)
    # coding 4 alone (no coarser level to chain to) is coding 3 with the tables moved: its longer
    # header (21 bytes more) and a few bytes per table stream's end more at most
    assert len(v4) <= len(v3) + 21 + 4 * 4
    # coding 5 takes rank steps only where smaller: at most its header's one byte more (post's z
    # gains by them)
    assert len(v5) < len(v4)
    with pytest.raises(ValueError, match="coding"):
        encode_geometry(points, density, refs, coding=6)


@pytest.mark.parametrize("sample, steps", [("fire", "xyz"), ("bluntfin", "z"), ("post", "z"), ("combustion", "")])
def test_coding_5_takes_rank_steps_on_the_grid_axes_where_they_pay(sample, steps):
    """Room fire's grid lines run along every axis of the decode order, Blunt-fin's curvilinear
    grid and LOX post's at least along z (in the real decode order their x and y steps escape too
    often to be tried: STEP_ESCAPE_SHARE); Combustion's channels have no tables."""
    mesh = load_sample(sample)[0]
    points, density, refs = _in_decode_order(mesh)
    v4 = encode_geometry(points, density, refs, coding=4)
    v5 = _round_trip(points, density, refs, coding=5)
    sizes4, sizes5 = geometry_stream_sizes(v4), geometry_stream_sizes(v5)
    got = "".join(c for c in "xyz" if sizes5[c + "_steps"])
    assert set(steps) <= set(got) and (got == "") == (steps == "")
    assert not sizes5["density_steps"]
    for c in ("x", "y", "z", "density"):
        assert sizes5[c] <= sizes4[c], c
        assert sizes5[c + "_mode"] == sizes4[c + "_mode"]
    if steps:
        assert sum(sizes4[c] - sizes5[c] for c in steps) > 0.5 * sum(sizes4[c] for c in steps)
    else:
        assert len(v5) == len(v4) + 1


def _steps_forced(parts):
    """The parts with the plain rank streams dropped: every table-mode channel takes rank steps."""
    from gatun_py.codec.geometry import STEPS

    for key in list(parts.streams):
        if key[0] is True:
            del parts.streams[key]
        elif key[0] == STEPS:
            parts.streams[True, key[1]] = [None] * 4  # what assemble_geometry looks up for ranks
    return parts


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 150), seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["bits", "smooth", "few"]),
       batch=st.integers(1, 50))
def test_hypothesis_rank_steps_on_every_channel_round_trip(n, seed, kind, batch):
    """Rank steps forced on every channel (with random refs most vertices escape): the escapes,
    the repeated values' ranks and the step decisions all round-trip, batch by batch."""
    from unittest import mock

    from gatun_py.codec import geometry
    from gatun_py.codec.geometry import assemble_geometry, geometry_parts

    rng = np.random.default_rng(seed)
    vals = _random_values(rng, n, kind)
    refs = _random_refs(rng, n)
    with mock.patch.object(geometry, "STEP_ESCAPE_SHARE", 1.0):  # steps tried whatever the escapes
        parts = geometry_parts(vals[:, :3], vals[:, 3], refs, force_ranks=True, steps=True)
    parts = _steps_forced(parts)
    blob = assemble_geometry([parts], modes=[(1, 1, 1, 1)], coding=5)[0]
    sizes = geometry_stream_sizes(blob)
    assert all(sizes[c + "_steps"] for c in ("x", "y", "z", "density"))
    _decode_in_batches(blob, vals, refs, batch)


def test_step_context_matches_the_naive_reference():
    from naive_geometry import naive_step_context

    rng = np.random.default_rng(5)
    rk = rng.integers(0, 6, size=(20, 4)).astype(np.int32)
    for _ in range(500):
        ch = int(rng.integers(0, 4))
        r1, r2, r3 = (int(x) for x in rng.integers(-1, 20, size=3))
        base = int(rng.integers(0, 6))
        flag = int(rng.integers(0, 8))
        assert K._step_context(rk, ch, base, r1, r2, r3, flag) == \
            K.STEP_BASE + 8 * naive_step_context(rk[:, ch], base, (r1, r2, r3), flag if ch else None)


def test_rank_steps_on_a_channel_without_a_table_are_refused():
    mesh = load_sample("fire")[0]
    points, density, refs = _in_decode_order(mesh)
    blob = bytearray(encode_geometry(points, density, refs, coding=5))
    assert blob[0] == 5 and blob[39] == 0b0111  # x, y, z take steps; the density has no table
    blob[39] |= 0b1000
    with pytest.raises(CorruptFileError, match="rank steps"):
        GeometryDecoder(bytes(blob))
    blob[39] = 0x10
    with pytest.raises(CorruptFileError, match="rank steps"):
        GeometryDecoder(bytes(blob))


@pytest.mark.parametrize("sample, xy_table", [("bluntfin", True), ("fire", False)])
def test_coding_3_is_no_larger_than_coding_2_and_keeps_the_x_y_table_where_it_pays(sample, xy_table):
    mesh = load_sample(sample)[0]
    points, density, refs = _in_decode_order(mesh)
    v2 = encode_geometry(points, density, refs, coding=2)
    v3 = _round_trip(points, density, refs, coding=3)
    assert len(v3) <= len(v2)
    # Blunt-fin's curvilinear grid repeats (x, y) columns; the fire's 41 x 18 values are cheap anyway
    assert bool(v3[1] & XY_TABLE_BIT) == xy_table


def test_coding_3_drops_the_x_y_table_where_nothing_repeats():
    mesh = delaunay_mesh(600, seed=3)  # random points: no x repeats
    points, density, refs = _in_decode_order(mesh)
    blob = _round_trip(points, density, refs, coding=3)
    assert not blob[1] & XY_TABLE_BIT
    dec = GeometryDecoder(blob)
    assert len(dec.hkeys) == 1  # no table allocated


def test_x_y_table_bit_only_in_coding_3(post_blob):
    blob, refs = post_blob
    bad = bytearray(blob)
    bad[1] |= XY_TABLE_BIT << (1 if blob[0] >= 3 else 0)  # coding 3: the bit above it; 1-2: the bit itself
    with pytest.raises(CorruptFileError, match="modes"):
        GeometryDecoder(bytes(bad))


def test_coding_3_cache_of_x_y_pairs_matches_the_naive_reference_with_collisions():
    # more distinct x than the cache has slots: pairs get evicted the same way in both
    rng = np.random.default_rng(7)
    n = 3 * K.XY_CACHE_SLOTS
    xs = rng.integers(0, 2 * K.XY_CACHE_SLOTS, n).astype(np.float32)
    ys = (xs * 0.5).astype(np.float32)  # y repeats with its x
    vals = np.stack([xs, ys, rng.normal(size=n).astype(np.float32), rng.normal(size=n).astype(np.float32)], 1)
    refs = np.full((n, 4), -1, np.int32)
    refs[1:, 0] = np.arange(n - 1)
    vf, full, trace = _kernel_trace(vals[:, :3], vals[:, 3], refs, (0, 0, 0, 0), coding=3)
    np.testing.assert_array_equal(trace[:, 1], naive_symbols(vf, full, (0, 0, 0, 0), 3)[:, 1])
    assert (trace[:, 1, 0] == 1).sum() > n // 4  # the cache's candidate is used


def test_a_block_in_one_coding_read_as_the_other_is_caught_or_differs():
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    blob = bytearray(encode_geometry(points, density, refs, coding=2))
    blob[0] = 1  # the header says coding 1: the predictions differ, so must the values (or corrupt)
    try:
        p, d = decode_geometry(bytes(blob), refs)
    except CorruptFileError:
        return
    assert not (np.array_equal(p.view(np.int32), points.view(np.int32))
                and np.array_equal(d.view(np.int32), density.view(np.int32)))


def test_emulated_order_is_a_valid_decode_order():
    mesh = cavity_mesh()
    order, refs = emulate_decode_order(mesh.tets, mesh.n_points)
    assert sorted(order.tolist()) == list(range(mesh.n_points))
    k = np.arange(mesh.n_points)[:, None]
    assert ((refs >= -1) & (refs < k)).all()


# ------------------------------------------------------------------------------ bad input


@pytest.fixture(scope="module", params=CODINGS, ids=lambda c: f"coding{c}")
def post_blob(request):
    mesh = load_sample("post")[0]
    points, density, refs = _in_decode_order(mesh)
    return encode_geometry(points, density, refs, coding=request.param), refs


@pytest.fixture(scope="module", params=[2, 3, 4, 5], ids=lambda c: f"coding{c}")
def smooth_blob(request):
    """Codings 2 and 3 on an unstructured mesh with a smooth field: the tet-geometry predictors,
    and coding 3's wide raw bits, at work."""
    from meshgen import delaunay_mesh

    mesh = delaunay_mesh(400, seed=5)
    points, _, refs = _in_decode_order(mesh)
    x, y, z = points.astype(np.float64).T
    density = (np.sin(3 * x) * np.cos(2 * y) + z).astype(np.float32)
    blob = encode_geometry(points, density, refs, coding=request.param)
    assert len(blob) < len(encode_geometry(points, density, refs, coding=1))
    return blob, refs


def test_truncation_and_flips_on_a_smooth_mesh(smooth_blob):
    blob, refs = smooth_blob
    for cut in np.linspace(0, len(blob) - 1, 60).astype(int):
        with pytest.raises(CorruptFileError):
            decode_geometry(blob[:cut], refs)
    rng = np.random.default_rng(11)
    detected = 0
    for _ in range(200):
        data = bytearray(blob)
        pos = int(rng.integers(HEADER_SIZE, len(data)))
        data[pos] ^= int(rng.integers(1, 256))
        detected += not _decode_or_corrupt(bytes(data), refs)
    assert detected > 60


def _decode_or_corrupt(data, refs):
    """Decode; the only acceptable failure is CorruptFileError."""
    try:
        decode_geometry(data, refs)
    except CorruptFileError:
        return False
    return True


def test_truncation_is_detected(post_blob):
    blob, refs = post_blob
    for cut in np.linspace(0, len(blob) - 1, 100).astype(int):
        with pytest.raises(CorruptFileError):
            decode_geometry(blob[:cut], refs)


def test_byte_flips_never_crash(post_blob):
    blob, refs = post_blob
    rng = np.random.default_rng(3)
    detected = 0
    for _ in range(300):
        data = bytearray(blob)
        pos = int(rng.integers(0, len(data)))
        data[pos] ^= int(rng.integers(1, 256))
        detected += not _decode_or_corrupt(bytes(data), refs)
    # the container's CRC catches the rest; the coder itself must notice a good share
    assert detected > 100


def test_absurd_header_counts_rejected_before_allocation(post_blob):
    blob, refs = post_blob
    version, modes, n, *lengths = struct.unpack_from("<BBI4I", blob)
    for bad in [
        struct.pack("<BBI4I", version, modes, 2**32 - 1, *lengths),
        struct.pack("<BBI4I", 9, modes, n, *lengths),
        struct.pack("<BBI4I", version, 0xF0, n, *lengths),
        struct.pack("<BBI4I", version, modes, n, 2**32 - 1, *lengths[1:]),
    ]:
        with pytest.raises(CorruptFileError):
            GeometryDecoder(bad + blob[HEADER_SIZE:])
    with pytest.raises(CorruptFileError):
        GeometryDecoder(blob, n_points=n + 1)


@settings(max_examples=60, deadline=None)
@given(header=st.binary(min_size=HEADER_SIZE, max_size=HEADER_SIZE), tail=st.binary(max_size=64))
def test_fuzzed_headers(header, tail):
    try:
        dec = GeometryDecoder(header + tail)
        n = dec.n_points
        dec.decode(np.full((min(n, 50), 4), -1, np.int32))
    except CorruptFileError:
        pass


def test_bad_refs_in_decoder(post_blob):
    blob, refs = post_blob
    for bad_value, row in [(5, 3), (-7, 10), (10**12, 20)]:
        bad = refs.astype(np.int64).copy()
        bad[row, 1] = bad_value
        with pytest.raises(CorruptFileError):
            decode_geometry(blob, bad)
    dec = GeometryDecoder(blob)
    with pytest.raises(CorruptFileError):
        dec.decode(np.full((dec.n_points + 1, 4), -1, np.int32))
    with pytest.raises(CorruptFileError):
        dec.finish()


def test_encoder_rejects_bad_arguments():
    pts = np.zeros((4, 3), np.float32)
    den = np.zeros(4, np.float32)
    refs = np.full((4, 4), -1, np.int32)
    with pytest.raises(ValueError):
        encode_geometry(pts.astype(np.float64), den, refs)
    with pytest.raises(ValueError):
        encode_geometry(pts, den[:3], refs)
    with pytest.raises(ValueError):
        encode_geometry(pts, den, refs[:, :2])
    bad = refs.copy()
    bad[2, 0] = 2  # not an earlier vertex
    with pytest.raises(ValueError):
        encode_geometry(pts, den, bad)
    wraps = refs.astype(np.int64)
    wraps[3, 0] = 2**32  # would wrap to 0 in int32
    with pytest.raises(ValueError):
        encode_geometry(pts, den, wraps)
    with pytest.raises(ValueError):
        encode_geometry(pts, den, refs, modes=(0, 2, 0, 0))


def test_refs_from_predictors():
    pred = np.array([[-1, -1, -1], [0, -1, -1], [0, 1, -1], [1, 2, 0], [0, 1, 2], [3, 4, 1]], np.int32)
    refs = refs_from_predictors(pred, n_boundary_vertices=4, interior_apex=np.array([-1, -1, -1, -1, 3, 2]))
    np.testing.assert_array_equal(refs, [[-1, -1, -1, -1], [0, -1, -1, -1], [0, 1, -1, -1], [1, 2, -1, 0],
                                         [0, 1, 2, 3], [3, 4, 1, 2]])
    assert K.MODE_TABLE == 1


def test_kernel_callable_from_another_numba_kernel():
    """The codec may interleave geometry with connectivity inside its own njit decode loop."""
    from numba import njit

    @njit
    def decode_in_batches(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes, tables,
                          tab_offs, ranks, cands, refs, values, batch):
        n = values.shape[0]
        start = 0
        while start < n:
            count = min(batch, n - start)
            status = K.decode_vertices(st, buf, offs, probs, scores, flags, adj, deg, mark, hkeys, hvals, modes,
                                       tables, tab_offs, ranks, cands, refs[start:start + count], values, start,
                                       count)
            if status != K.OK:
                return status
            start += count
        return K.OK

    mesh = grid_mesh(5, 4, 3)
    points, density, refs = _in_decode_order(mesh)
    blob = encode_geometry(points, density, refs)
    dec = GeometryDecoder(blob, n_points=len(density))
    assert decode_in_batches(*dec.kernel_args, refs, dec.values, 7) == K.OK
    dec.n_decoded = dec.n_points
    dec.finish()
    _assert_bit_identical(dec.points, points)
    _assert_bit_identical(dec.density, density)


def test_hash_table_without_a_free_slot_is_refused(post_blob):
    """The x -> y table is right-sized (at most 2/3 full): a table the n vertices could fill would
    let a lookup probe forever, so the kernel refuses it instead of running."""
    blob, refs = post_blob
    dec = GeometryDecoder(blob)
    n = dec.n_points
    if dec.coding >= 3:
        # coding 3's table is a direct-mapped cache (no probing): any power of two will do, others not
        if len(dec.hkeys) > 1:
            assert len(dec.hkeys) == K.XY_CACHE_SLOTS
            dec.hkeys, dec.hvals = np.zeros(3 * 16, np.int64), np.zeros(3 * 16, np.uint8)
            with pytest.raises(CorruptFileError):
                dec.decode(refs[:10])
        return
    assert 1.5 * n < len(dec.hkeys) <= K.hash_capacity(n)  # at most 2/3 full, never above the encoder's
    full = 1 << (n.bit_length() - 1)  # the largest power of two <= n
    dec.hkeys, dec.hvals = np.zeros(full, np.int64), np.zeros(full, np.uint8)
    with pytest.raises(CorruptFileError):
        dec.decode(refs[:10])
    dec.hkeys, dec.hvals = np.zeros(3 * full, np.int64), np.zeros(3 * full, np.uint8)  # not a power of two
    with pytest.raises(CorruptFileError):
        dec.decode(refs[:10])


# ------------------------------------------------------------------------------ format versions


def test_files_of_format_9_carry_geometry_coding_5_format_8_coding_4_older_3_2_1(post_tetc):
    from gatun_py.codec.container import VERSION_MAJOR
    from gatun_py.codec.geometry import coding_for_format
    from gatun_py.codec.tetcfile import TetcReader

    assert [coding_for_format(v) for v in (1, 2, 3, 4, 5, 6, 7, 8, 9)] == [1, 1, 1, 2, 3, 3, 3, 4, 5]
    assert FORMAT_VERSION == coding_for_format(VERSION_MAJOR) == 5
    r = TetcReader(post_tetc)
    assert r.container.major == VERSION_MAJOR >= 9
    for lv in range(len(r.levels)):
        assert r.read_section(f"L{lv}/geometry")[0] == 5


# ------------------------------------------------------------------------------ coding 4: chained tables


def _nested_levels(rng, n0, n_levels, kind):
    """Values of levels whose vertices are nested subsets (each coarser level a random subset of the
    one before, in an order of its own), with random refs: what a file's levels look like to the
    geometry coder."""
    if kind == "few":
        pool = rng.normal(size=(max(2, n0 // 3), 4)).astype(np.float32)
        vals = pool[rng.integers(0, len(pool), (n0, 4)), np.arange(4)]
    elif kind == "grid":
        vals = rng.integers(0, 12, (n0, 4)).astype(np.float32) * np.float32(0.25)
    else:
        vals = rng.integers(-(2**31), 2**31, size=(n0, 4), dtype=np.int64).astype(np.int32).view(np.float32)
    levels = [np.ascontiguousarray(vals)]
    for _ in range(n_levels - 1):
        prev = levels[-1]
        keep = rng.permutation(len(prev))[: max(1, len(prev) // 2)]
        levels.append(np.ascontiguousarray(prev[keep]))
    return [(v, _random_refs(rng, len(v))) for v in levels]


def _assemble(levels):
    from gatun_py.codec.geometry import assemble_geometry, geometry_parts

    return assemble_geometry([geometry_parts(v[:, :3], v[:, 3], refs) for v, refs in levels])


def _decode_chain(blocks, levels):
    """Decode every block coarsest first, each with the next coarser one's tables; check bits."""
    from gatun_py.codec.geometry import decode_value_tables

    base = None
    for block, (vals, refs) in zip(reversed(blocks), reversed(levels)):
        dec = GeometryDecoder(block, n_points=len(vals), base=base)
        dec.decode(refs)
        dec.finish()
        _assert_bit_identical(dec.values, vals)
        tables = decode_value_tables(block, len(vals), base)
        ordered = _ordered(vals)
        for ch in range(4):  # a table is the channel's distinct values, whether chained or not
            assert (tables[ch] is None) == (dec.value_tables[ch] is None)
            if tables[ch] is not None:
                np.testing.assert_array_equal(tables[ch], dec.value_tables[ch])
                np.testing.assert_array_equal(tables[ch], np.unique(ordered[:, ch]))
        base = tables


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 150), n_levels=st.integers(1, 5), seed=st.integers(0, 2**32 - 1),
       kind=st.sampled_from(["few", "grid", "bits"]))
def test_hypothesis_chained_levels_round_trip(n, n_levels, seed, kind):
    levels = _nested_levels(np.random.default_rng(seed), n, n_levels, kind)
    blocks = _assemble(levels)
    assert all(b[0] == FORMAT_VERSION for b in blocks) and blocks[-1][HEADER_SIZE] == 0  # the coarsest chains to nothing
    _decode_chain(blocks, levels)


def test_chained_tables_shrink_the_levels_of_a_real_sample():
    """LOX post's levels (the file's decimation, each level in its own decode order): the chained
    blocks are smaller than the same levels coded alone, and finer levels chain."""
    import gatun_py
    from gatun_py.codec.cutborder import encode_connectivity
    from gatun_py.simplify import build_levels, decimate

    mesh = load_sample("post")[0]
    levels = []
    for lv in build_levels(mesh, decimate(mesh), 4):
        conn = encode_connectivity(lv.mesh.n_points, lv.mesh.tets)
        vo = conn.vertex_order
        vals = np.ascontiguousarray(np.column_stack([lv.mesh.points32[vo], lv.mesh.density[vo]]))
        levels.append((vals, np.ascontiguousarray(conn.predictors, np.int32)))
    blocks = _assemble(levels)
    _decode_chain(blocks, levels)
    alone = [encode_geometry(v[:, :3], v[:, 3], refs, coding=4) for v, refs in levels]
    assert sum(map(len, blocks)) < 0.85 * sum(map(len, alone))
    assert all(geometry_stream_sizes(b)["density_mode"] == "chained" for b in blocks[:-1])
    assert gatun_py  # the package the levels come from


def test_a_channel_whose_coarser_table_is_not_a_subset_does_not_chain():
    rng = np.random.default_rng(4)
    levels = _nested_levels(rng, 120, 2, "grid")
    coarse_vals, coarse_refs = levels[1]
    coarse_vals = coarse_vals.copy()
    coarse_vals[0, 3] = np.float32(1000.5)  # a density the finer level does not have
    levels[1] = (coarse_vals, coarse_refs)
    blocks = _assemble(levels)
    sizes = geometry_stream_sizes(blocks[0])
    assert sizes["density_mode"] != "chained" and "chained" in (sizes["x_mode"], sizes["y_mode"], sizes["z_mode"])
    _decode_chain(blocks, levels)


@pytest.fixture(scope="module")
def chained_pair():
    levels = _nested_levels(np.random.default_rng(9), 400, 2, "few")
    blocks = _assemble(levels)
    assert blocks[0][HEADER_SIZE] != 0  # the finer block chains
    from gatun_py.codec.geometry import decode_value_tables

    return blocks, levels, decode_value_tables(blocks[1], len(levels[1][0]))


def test_a_chained_block_needs_its_coarser_tables(chained_pair):
    from gatun_py.codec.geometry import decode_value_tables

    blocks, levels, base = chained_pair
    with pytest.raises(CorruptFileError, match="coarser"):
        GeometryDecoder(blocks[0])
    with pytest.raises(CorruptFileError, match="coarser"):
        decode_value_tables(blocks[0])
    with pytest.raises(CorruptFileError, match="coarser"):  # the coarser level codes no table
        GeometryDecoder(blocks[0], base=[None] * 4)
    # a finer level's decode asks only for the chained channels of the coarser one
    chained = blocks[0][HEADER_SIZE] & 15
    some = decode_value_tables(blocks[1], len(levels[1][0]), channels=chained)
    assert [t is not None for t in some] == [bool(chained >> ch & 1) for ch in range(4)]
    GeometryDecoder(blocks[0], base=some)


def test_a_coarser_table_that_holds_an_addition_is_refused(chained_pair):
    """The additions and the coarser table are disjoint: a coarser table that already holds an
    addition (another level's tables, or damage) is corruption, not a table with a repeat."""
    blocks, levels, base = chained_pair
    fine = GeometryDecoder(blocks[0], base=base).value_tables
    ch = next(c for c in range(4) if (blocks[0][HEADER_SIZE] >> c) & 1)
    extra = np.setdiff1d(fine[ch], base[ch])[0]  # an addition (the finer level has values of its own)
    bad = list(base)
    bad[ch] = np.union1d(base[ch], [extra])
    with pytest.raises(CorruptFileError, match="table"):
        GeometryDecoder(blocks[0], base=bad)


def test_damaged_chained_blocks_are_refused_or_decode_right(chained_pair):
    """Truncations and byte flips of a chained block (mostly its header and table stream): a
    CorruptFileError or some values, never another exception."""
    blocks, levels, base = chained_pair
    refs = levels[0][1]
    block = blocks[0]
    for cut in np.linspace(0, len(block) - 1, 80).astype(int):
        with pytest.raises(CorruptFileError):
            dec = GeometryDecoder(block[:cut], base=base)
            dec.decode(refs)
            dec.finish()
    rng = np.random.default_rng(12)
    detected = 0
    for _ in range(300):
        data = bytearray(block)
        pos = int(rng.integers(0, min(len(data), 39 + 64)))  # mostly the header and the table streams
        data[pos] ^= int(rng.integers(1, 256))
        try:
            dec = GeometryDecoder(bytes(data), base=base)
            dec.decode(refs)
            dec.finish()
        except CorruptFileError:
            detected += 1
    # the container's CRC catches the rest; the coder itself must notice a good share
    assert detected > 150
