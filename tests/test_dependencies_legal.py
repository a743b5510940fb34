"""Legal cuts (a runtime legality check instead of the stored closure): whatever the order of the
merges, the cut mesh is valid (conforming, no flat or inverted tet, a closed manifold boundary) and
has the tet count the kernel reports. In rank order (the decimator's own prefixes), on small meshes
whose input does not overlap itself, no two of its tets overlap either (no point strictly inside
two tets, over every centroid and random points). In other orders that is not guaranteed: the
checks are the decimator's local ones, and a boundary can fold onto a part of itself that no
local check sees (:func:`test_a_random_order_can_fold_the_boundary`)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_sample
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import grid_mesh, mesh_strategy
from naive_simplify import check_valid, max_coverage
from test_simplify_dependencies import _manifold

from gatun_py.errors import OptionError
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.simplify import decimate
from gatun_py.simplify.dependencies import cut_ancestors, legal_cut, legal_cut_base
from gatun_py.simplify.forest import ancestors, mesh_from_ancestors


def _check_legal_cuts(mesh, forest, orders, goals, label, *, children_first=False, overlap_free=()):
    """Every cut valid; the cuts of the orders listed in ``overlap_free`` (indices) also without
    overlapping tets, on small meshes."""
    base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
    n_flat = int((mesh.signed_volumes() == 0).sum())
    manifold = _manifold(mesh)
    coverage = mesh.n_tets <= 2000 and max_coverage(mesh) == 1  # the input itself does not overlap
    for c, (order, goal) in enumerate(zip(orders, goals)):
        applied, n_tets, _ = legal_cut(base, order, tets=goal, children_first=children_first)
        if children_first:  # a union of whole subtrees: every merge into an applied merge's vertex is applied
            into = np.zeros(mesh.n_points, bool)
            np.logical_or.at(into, base.target[~applied], True)
            assert not (applied & into[base.vertex]).any(), f"{label} cut {c}: a merge before its children"
        out = mesh_from_ancestors(mesh, cut_ancestors(forest.parent, forest.rank, applied))[0]
        check_valid(out, n_flat, f"{label} cut {c}", manifold=manifold)
        assert out.n_tets == n_tets, f"{label} cut {c}: tet count {out.n_tets} vs {n_tets}"
        if coverage and c in overlap_free:
            assert max_coverage(out) == 1, f"{label} cut {c}: overlapping tets"


def _orders(k, rng, n):
    """Random orders, the reversed rank order (late merges first: the hardest for legality) and
    the rank order itself; random goals."""
    orders = [rng.permutation(k) for _ in range(n)] + [np.arange(k)[::-1], np.arange(k)]
    return orders


@settings(max_examples=40, deadline=None)
@given(mesh_strategy(), st.integers(0, 2**32 - 1))
def test_random_legal_cuts_are_valid(mesh, seed):
    forest = decimate(mesh)
    rng = np.random.default_rng(seed)
    orders = _orders(forest.n_merges, rng, 3)
    goals = [int(rng.integers(1, mesh.n_tets + 1)) for _ in orders]
    rank_order = [len(orders) - 1]
    _check_legal_cuts(mesh, forest, orders, goals, "random", overlap_free=rank_order)
    _check_legal_cuts(mesh, forest, orders, goals, "children first", children_first=True, overlap_free=rank_order)


@settings(max_examples=10, deadline=None)
@given(st.integers(3, 7), st.integers(3, 6), st.integers(3, 5), st.integers(0, 10_000))
def test_legal_cuts_on_jittered_grids(a, b, c, seed):
    mesh = jittered_grid((a, b, c), jitter=0.3, seed=seed)
    forest = decimate(mesh)
    rng = np.random.default_rng(seed)
    orders = _orders(forest.n_merges, rng, 2)
    _check_legal_cuts(mesh, forest, orders, [1] * len(orders), "grid", overlap_free=[len(orders) - 1])


def test_a_random_order_can_fold_the_boundary():
    """The known limit of a legal cut in an order other than the decimator's (found by hypothesis):
    on this jittered grid a random order applies 85 of 116 merges, every one legal by the local
    checks, and two tets made of boundary vertices, sharing one vertex, overlap. The cut is still
    conforming, positive and manifold. When a check that sees such folds is added, this test
    fails and goes: the overlap assertion then holds for every order."""
    a, b, c, seed = 6, 4, 5, 8225
    mesh = jittered_grid((a, b, c), jitter=0.3, seed=seed)
    forest = decimate(mesh)
    order = _orders(forest.n_merges, np.random.default_rng(seed), 2)[0]
    _check_legal_cuts(mesh, forest, [order], [1], "folded")  # valid
    base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
    applied, _, _ = legal_cut(base, order, tets=1)
    out = mesh_from_ancestors(mesh, cut_ancestors(forest.parent, forest.rank, applied))[0]
    assert max_coverage(mesh) == 1 and max_coverage(out) == 2


def test_rank_order_gives_the_prefix():
    """In rank order every merge sees its prefix state, which the decimator validated: the legal
    cut is the uniform one for every goal."""
    mesh = grid_mesh(6, 5, 4, jitter=0.2, seed=3)
    forest = decimate(mesh)
    base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
    for n in (0, 1, forest.n_merges // 3, forest.n_merges - 1, forest.n_merges):
        goal = mesh_from_ancestors(mesh, ancestors(forest.parent, forest.rank, n))[0].n_tets
        applied, n_tets, rejected = legal_cut(base, np.arange(forest.n_merges), tets=goal)
        assert rejected == 0
        first = int(np.argmin(applied)) if not applied.all() else forest.n_merges
        assert not applied[first:].any() and n_tets == goal
        # the fewest merges that reach the goal (the prefix may reach it before merge n)
        assert first <= n


def test_late_merges_first_are_refused_where_illegal():
    """Applying the last merges first is what a closed cut forbids; the legal cut applies what is
    legal and refuses the rest, and some are refused on the first pass (the check is not vacuous)."""
    refused = 0
    for seed in range(4):
        mesh = grid_mesh(5, 5, 4, jitter=0.2, seed=seed)
        forest = decimate(mesh)
        base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
        refused += legal_cut(base, np.arange(forest.n_merges)[::-1], tets=1)[2]
    assert refused > 0


def test_bad_order_is_refused():
    mesh = grid_mesh(4, 4, 4, jitter=0.1, seed=1)
    forest = decimate(mesh)
    base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
    with pytest.raises(OptionError):
        legal_cut(base, [forest.n_merges], tets=1)
    with pytest.raises(OptionError):
        legal_cut_base(mesh.tets, mesh.points, forest.parent[:-1], forest.rank[:-1])


@pytest.mark.parametrize("name", ["post", "fire", "bluntfin", "combustion"])
def test_samples_random_legal_cuts(name):
    from test_simplify_forest import _forest

    mesh = load_sample(name)[0]
    forest = _forest(name)
    rng = np.random.default_rng(11)
    k = forest.n_merges
    # importance-like orders: random, and late-first (the cuts furthest from any prefix)
    orders = [rng.permutation(k), np.argsort(-np.arange(k) + rng.normal(0, k / 10, k))]
    _check_legal_cuts(mesh, forest, orders, [mesh.n_tets // 20, mesh.n_tets // 100], name)
    _check_legal_cuts(mesh, forest, orders[:1], [mesh.n_tets // 20], name, children_first=True)


def test_coverage_oracle_sees_overlaps():
    """The overlap check is not vacuous: two tets sharing a face on the same side overlap, a
    Delaunay mesh does not, and some cut that ignores both the closure and the legality check does."""
    from gatun_py.mesh.model import TetMesh
    from meshgen import delaunay_mesh

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1], [0.3, 0.3, 0.5]], np.float32)
    two = TetMesh(pts, np.zeros(5, np.float32), np.array([[0, 1, 2, 3], [0, 1, 2, 4]], np.int32))
    assert max_coverage(two) == 2
    assert max_coverage(delaunay_mesh(40, 1)) == 1
    worst = 1
    for seed in range(4):
        mesh = delaunay_mesh(60, seed)
        forest = decimate(mesh)
        cut = np.random.default_rng(seed).random(forest.n_merges) < 0.5
        worst = max(worst, max_coverage(mesh_from_ancestors(mesh, cut_ancestors(forest.parent, forest.rank, cut))[0]))
    assert worst > 1
