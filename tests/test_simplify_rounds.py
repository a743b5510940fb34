"""Rounds of independent merges: the merges of a round commute (any order, every prefix legal, the
same mesh at the round's end), ranks inside a round follow the canonical key, levels stay rounds'
boundaries."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy
from naive_simplify import collapse, evaluate_merge
from test_simplify_decimate import _check_forest_prefixes, _naive_kw

from gatun_py.errors import OptionError
from gatun_py.simplify import decimate
from gatun_py.simplify.decimation import DecimationState, _canonical_ranks, canonical_key
from gatun_py.simplify.levels import level_merges


def _by_rank(forest):
    order = np.argsort(forest.rank, kind="stable")[: forest.n_merges]
    return [(int(a), int(forest.parent[a])) for a in order]


def _replay_rounds_in_random_orders(mesh, rounds, seed, orders=3):
    """Apply every round's merges in ``orders`` random orders with the slow reference: each merge
    is legal when it comes (positive tets, boundary rules, link condition) and every order ends
    in the same mesh."""
    forest, starts = decimate(mesh, rounds=rounds, return_rounds=True)
    kw = _naive_kw(DecimationState(mesh, 1.0, 1.0, order="input"), None)
    pts, dens = mesh.points.astype(np.float64), mesh.density.astype(np.float64)
    tets = [tuple(int(x) for x in t) for t in mesh.tets]
    merges = _by_rank(forest)
    rng = np.random.default_rng(seed)
    bounds = list(starts) + [forest.n_merges]
    multi = 0
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        batch = merges[lo:hi]
        multi += len(batch) > 1
        ends = set()
        for k in range(orders):
            perm = np.arange(len(batch)) if k == 0 else rng.permutation(len(batch))
            cur = tets
            for i in perm:
                a, b = batch[i]
                ok, _ = evaluate_merge(cur, pts, dens, a, b, **kw)
                assert ok, f"round [{lo}, {hi}): merge {a}->{b} not legal after {[batch[j] for j in perm]}"
                cur = collapse(cur, a, b)
            ends.add(tuple(sorted(cur)))
        assert len(ends) == 1, f"round [{lo}, {hi}): orders end in different meshes"
        tets = collapse_all(tets, batch)
    return forest, starts, multi


def collapse_all(tets, batch):
    for a, b in batch:
        tets = collapse(tets, a, b)
    return tets


@pytest.mark.parametrize("mesh,rounds", [(delaunay_mesh(120, 5), 2), (grid_mesh(6, 5, 4, jitter=0.2, seed=3), 3),
                                         (delaunay_mesh(200, 9), 4)], ids=["delaunay-2", "grid-3", "delaunay-4"])
def test_merges_of_a_round_commute(mesh, rounds):
    forest, starts, multi = _replay_rounds_in_random_orders(mesh, rounds, seed=1)
    assert multi >= 3, "too few rounds with more than one merge to test anything"
    assert forest.max_ratio > 0.7


@settings(max_examples=15, deadline=None)
@given(mesh_strategy(), st.integers(1, 4), st.integers(0, 100))
def test_merges_of_a_round_commute_on_random_meshes(mesh, rounds, seed):
    _replay_rounds_in_random_orders(mesh, rounds, seed, orders=2)


@settings(max_examples=20, deadline=None)
@given(mesh_strategy(), st.integers(1, 8))
def test_every_prefix_is_valid_with_rounds(mesh, rounds):
    """Prefixes that end inside a round too (a render at any ratio)."""
    forest = decimate(mesh, rounds=rounds)
    _check_forest_prefixes(mesh, forest, range(forest.n_merges + 1))


@pytest.mark.parametrize("rounds", [1, 3, 32])
def test_ranks_ascend_in_the_key_inside_rounds_and_levels_end_rounds(rounds):
    mesh = delaunay_mesh(300, 2)
    forest, starts = decimate(mesh, rounds=rounds, return_rounds=True)
    key = canonical_key(mesh)
    by_rank = np.array([a for a, _ in _by_rank(forest)])
    bounds = list(starts) + [forest.n_merges]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        assert hi > lo
        assert np.all(np.diff(key[by_rank[lo:hi]]) > 0)
    for i in range(1, 20):
        n_i = level_merges(mesh.n_points, i)
        if n_i < forest.n_merges:
            assert n_i in starts, f"level {i} starts inside a round"
    # at most `rounds` rounds per level when no round ends early
    assert len(starts) >= min(rounds, 2)
    # a parent is merged in a later round than its child
    child = np.flatnonzero(forest.rank < forest.n_merges)
    child = child[forest.rank[forest.parent[child]] < forest.n_merges]  # parents merged too
    rid = np.searchsorted(starts, forest.rank[child], side="right")
    prid = np.searchsorted(starts, forest.rank[forest.parent[child]], side="right")
    assert child.size and np.all(prid > rid)


def test_canonical_key_orders_float_bits_then_value():
    from gatun_py.mesh import TetMesh

    pts = np.array([[1, 0, 0], [0, 2, 0], [0, 0, 0], [0, 2, 0], [-1, 0, 0]], np.float32)
    dens = np.array([0, 1, 0, 0.5, 0], np.float32)
    mesh = TetMesh(pts, dens, np.zeros((0, 4), np.int32))
    key = canonical_key(mesh)
    # x bits: 0 < 1.0 < -1.0 (sign bit set); then y, then the value's bits
    assert key.tolist() == [3, 2, 0, 1, 4]
    pts[3] = pts[1]
    dens[3] = dens[1]
    assert canonical_key(TetMesh(pts, dens, np.zeros((0, 4), np.int32))).tolist() == [2, 1, 0, 1, 3]


def test_a_round_with_equal_keys_is_split_between_them():
    # execution order: vertices 0..5, one round; vertices 1 and 4 have the same key
    rank = np.arange(6, dtype=np.int32)
    key = np.array([5, 3, 0, 4, 3, 1])
    out, starts = _canonical_ranks(rank, 6, [0], key)
    assert starts == [0, 4]
    # round [0, 4) = vertices 0..3 by key: 2, 1, 3, 0; round [4, 6) = vertices 4, 5: 5, 4
    assert out.tolist() == [3, 1, 0, 2, 5, 4]


def test_greedy_order_is_rounds_zero_and_rounds_are_checked():
    mesh = grid_mesh(4, 4, 3, jitter=0.2, seed=4)
    greedy = decimate(mesh, rounds=0)
    state = DecimationState(mesh, 1.0, 1.0)
    state.run(mesh.n_points)
    run = state.prefix()
    assert np.array_equal(greedy.rank, run.rank) and np.array_equal(greedy.parent, run.parent)
    for bad in (-1, 1.5, True, "4"):
        with pytest.raises(OptionError):
            decimate(mesh, rounds=bad)


def test_max_merges_at_a_round_start_gives_the_same_prefix():
    mesh = delaunay_mesh(150, 8)
    full, starts = decimate(mesh, rounds=4, return_rounds=True)
    cut = starts[len(starts) // 2]
    seen = []
    part = decimate(mesh, rounds=4, max_merges=cut, progress=seen.append)
    assert part.n_merges == cut and sum(seen) == cut
    assert np.array_equal(full.rank < cut, part.rank < cut)
    first = full.rank < cut
    assert np.array_equal(full.parent[first], part.parent[first]) and np.array_equal(full.rank[first],
                                                                                     part.rank[first])
