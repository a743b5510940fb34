"""Merge forest: ancestors, forest coding, levels (continuing from a level is exact), real samples."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_sample
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy, single_tet
from naive_simplify import ancestors_naive
from test_simplify_decimate import _check_forest_prefixes

from gatun_py.codec.forest import decode_forest, encode_forest
from gatun_py.errors import CorruptFileError, OptionError
from gatun_py.simplify import (ROOT_RANK, MergeForest, ancestors, available_levels, build_levels, decimate,
                               level_merges, simplified_mesh)
from gatun_py.simplify.levels import MAX_LEVEL, level_forest

_FORESTS: dict = {}


def _forest(name):
    if name not in _FORESTS:
        _FORESTS[name] = decimate(load_sample(name)[0])
    return _FORESTS[name]


def test_level_merges_formula():
    for n in (1, 4, 5, 1000, 40960, 47025):
        for i in range(14):
            assert level_merges(n, i) == int(np.floor((1 - 1 / 2**i) * n + 1e-9))


@settings(max_examples=25, deadline=None)
@given(mesh_strategy(), st.data())
def test_ancestors_match_naive(mesh, data):
    f = decimate(mesh)
    n = data.draw(st.integers(0, f.n_merges))
    assert np.array_equal(ancestors(f.parent, f.rank, n), ancestors_naive(f.parent, f.rank, n))


def _same_state(mesh, forest, level, n):
    """The mesh after n merges reached from a level equals the one reached from level 0, bit for bit."""
    ref, ref_ids = simplified_mesh(mesh, forest, n, return_ids=True)
    got, got_ids = simplified_mesh(level.mesh, level.forest, n - level.n_merges, return_ids=True)
    assert np.array_equal(level.vertex_ids[got_ids], ref_ids)
    assert np.array_equal(got.points.view(np.uint32), ref.points.view(np.uint32))
    assert np.array_equal(got.density.view(np.uint32), ref.density.view(np.uint32))
    assert np.array_equal(got.tets, ref.tets)


@settings(max_examples=25, deadline=None)
@given(mesh_strategy(), st.data())
def test_continuing_from_a_level_is_exact(mesh, data):
    forest = decimate(mesh)
    levels = build_levels(mesh, forest)
    assert levels[0].n_merges == 0 and levels[0].mesh.n_tets == mesh.n_tets
    for lv in levels:
        assert lv.forest.n_merges == forest.n_merges - lv.n_merges
        assert lv.mesh.n_points == mesh.n_points - lv.n_merges
        n = data.draw(st.integers(lv.n_merges, forest.n_merges))
        _same_state(mesh, forest, lv, n)
        _same_state(mesh, forest, lv, forest.n_merges)


def _assert_levels_equal_direct(mesh, forest, levels):
    """Each level (built from the previous one) equals the level built from the input directly."""
    for lv in levels:
        m, ids = simplified_mesh(mesh, forest, lv.n_merges, return_ids=True)
        assert np.array_equal(lv.vertex_ids, ids)
        assert np.array_equal(lv.mesh.tets, m.tets)
        assert lv.mesh.points.tobytes() == m.points.tobytes()
        assert lv.mesh.density.tobytes() == m.density.tobytes()
        direct = level_forest(forest, lv.n_merges, ids)
        assert np.array_equal(lv.forest.parent, direct.parent) and np.array_equal(lv.forest.rank, direct.rank)
        assert lv.forest.n_merges == direct.n_merges


@settings(max_examples=25, deadline=None)
@given(mesh_strategy())
def test_levels_built_in_a_chain_equal_levels_from_the_input(mesh):
    forest = decimate(mesh)
    _assert_levels_equal_direct(mesh, forest, build_levels(mesh, forest))


def test_sample_levels_built_in_a_chain_equal_levels_from_the_input():
    mesh = load_sample("bluntfin")[0]
    forest = decimate(mesh)
    levels = build_levels(mesh, forest, MAX_LEVEL)  # every level, down to a few points
    assert len(levels) >= 10
    _assert_levels_equal_direct(mesh, forest, levels)


@settings(max_examples=40, deadline=None)
@given(mesh_strategy())
def test_forest_coding_round_trip(mesh):
    f = decimate(mesh)
    data = encode_forest(f.parent, f.rank)
    p, r = decode_forest(data, mesh.n_points)
    assert np.array_equal(p, f.parent) and np.array_equal(r, f.rank)
    assert p.dtype == np.int32 and r.dtype == np.int32


def test_forest_of_roots_round_trip():
    p, r = decode_forest(encode_forest(np.arange(4), np.full(4, ROOT_RANK)), 4)
    assert np.array_equal(p, np.arange(4)) and np.all(r == ROOT_RANK)
    p, r = decode_forest(encode_forest(np.zeros(0, int), np.zeros(0, int)), 0)
    assert p.size == 0


def test_corrupt_forest_bytes_raise_typed_errors():
    mesh = grid_mesh(4, 4, 3, jitter=0.1, seed=5)
    f = decimate(mesh)
    data = encode_forest(f.parent, f.rank)
    with pytest.raises(CorruptFileError):
        decode_forest(data, mesh.n_points + 1)
    for cut in (0, 5, 12, len(data) // 2, len(data) - 1):
        with pytest.raises(CorruptFileError):
            decode_forest(data[:cut], mesh.n_points)
    with pytest.raises(CorruptFileError):
        decode_forest(data + b"x", mesh.n_points)
    rng = np.random.default_rng(0)
    for _ in range(200):
        b = bytearray(data)
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
        try:
            p, r = decode_forest(bytes(b), mesh.n_points)
        except CorruptFileError:
            continue
        MergeForest(p, r, int((r != ROOT_RANK).sum()))  # decoded: it passed check_forest


def test_check_forest_rejects_cycles_and_bad_ranks():
    from gatun_py.simplify import check_forest

    with pytest.raises(CorruptFileError):
        check_forest(np.array([1, 0]), np.array([0, 1]))  # a cycle
    with pytest.raises(CorruptFileError):
        check_forest(np.array([1, 1, 1]), np.array([0, ROOT_RANK, 0]))  # rank 0 twice
    with pytest.raises(CorruptFileError):
        check_forest(np.array([0, 5]), np.array([ROOT_RANK, 0]))


def test_ratio_requests():
    f = decimate(delaunay_mesh(40, 4))
    assert f.merges_for_ratio(0.0) == 0
    with pytest.raises(OptionError, match="outside"):
        f.merges_for_ratio(1.5)
    with pytest.raises(OptionError, match="maximum ratio"):
        MergeForest(np.arange(10), np.full(10, ROOT_RANK), 0).merges_for_ratio(0.5)


def test_levels_of_a_single_tet():
    m = single_tet()
    f = decimate(m)
    levels = build_levels(m, f)
    assert [lv.level for lv in levels] == [0]
    with pytest.raises(OptionError, match="available levels: 0"):
        build_levels(m, f, [3])


def test_build_levels_selection():
    m = delaunay_mesh(80, 9)
    f = decimate(m)
    reach = available_levels(f, min_points=1)
    assert [lv.level for lv in build_levels(m, f, 2)] == [i for i in reach if i <= 2]
    assert len(reach) > 2 and [lv.level for lv in build_levels(m, f)] == [0]  # 40 points at level 1: none by default
    with pytest.raises(OptionError):
        build_levels(m, f, -1)


# -- real samples: one decimation each, cached across the tests below ---------------------------
@pytest.mark.parametrize("name", ["post", "fire", "bluntfin", "combustion"])
def test_samples_valid_at_levels_and_random_prefixes(name):
    mesh = load_sample(name)[0]
    f = _forest(name)
    rng = np.random.default_rng(1)
    ns = [level_merges(mesh.n_points, i) for i in available_levels(f)] + list(rng.integers(0, f.n_merges, 3))
    ns += [f.n_merges]
    _check_forest_prefixes(mesh, f, ns, name)
    if name in ("bluntfin", "combustion"):
        assert f.max_ratio >= 0.995
        vol0 = mesh.signed_volumes().sum()
        vol = simplified_mesh(mesh, f, int(0.9 * mesh.n_points)).signed_volumes().sum()
        assert abs(vol / vol0 - 1) < 0.01


def test_sample_level_continuation_is_exact():
    mesh = load_sample("post")[0]
    f = _forest("post")
    levels = build_levels(mesh, f, available_levels(f, min_points=1))  # down to a few points
    assert len(levels) >= 8
    rng = np.random.default_rng(3)
    for lv in levels:
        for n in rng.integers(lv.n_merges, f.n_merges + 1, 2):
            _same_state(mesh, f, lv, int(n))


def test_default_levels_stop_at_min_points():
    from gatun_py.simplify import MIN_LEVEL_POINTS, level_merges, storage_forests

    mesh = load_sample("post")[0]
    f = _forest("post")
    levels = build_levels(mesh, f)
    assert all(lv.mesh.n_points >= MIN_LEVEL_POINTS for lv in levels)
    big_enough = [i for i in available_levels(f, min_points=1)
                  if mesh.n_points - level_merges(mesh.n_points, i) >= MIN_LEVEL_POINTS]
    assert [lv.level for lv in levels] == big_enough
    assert len(big_enough) < len(available_levels(f, min_points=1))  # post's forest goes further
    # the last stored level keeps every remaining merge: any ratio stays reachable
    assert storage_forests(levels)[-1].n_merges == f.n_merges - levels[-1].n_merges
    # levels asked for by number are stored however small
    assert [lv.level for lv in build_levels(mesh, f, 7)] == [i for i in available_levels(f, min_points=1) if i <= 7]
    assert max(big_enough) < 7


@settings(max_examples=20, deadline=None)
@given(mesh_strategy(), st.data())
def test_forest_prefix_and_storage_forests(mesh, data):
    from gatun_py.simplify import check_forest, forest_prefix, storage_forests

    f = decimate(mesh)
    k = data.draw(st.integers(0, f.n_merges))
    p = forest_prefix(f, k)
    assert check_forest(p.parent, p.rank) == k
    for n in {0, k // 2, k}:
        assert np.array_equal(ancestors(p.parent, p.rank, n), ancestors(f.parent, f.rank, n))
    levels = build_levels(mesh, f)
    stored = storage_forests(levels)
    assert stored[0] is levels[0].forest and stored[-1] is levels[-1].forest
    for j in range(1, len(levels) - 1):
        assert stored[j].n_merges == levels[j + 1].n_merges - levels[j].n_merges
        n = data.draw(st.integers(levels[j].n_merges, levels[j + 1].n_merges))
        got = simplified_mesh(levels[j].mesh, stored[j], n - levels[j].n_merges)
        assert np.array_equal(got.tets, simplified_mesh(levels[j].mesh, levels[j].forest, n - levels[j].n_merges).tets)
