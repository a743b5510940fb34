"""Merge dependencies: kernel == slow reference; every closed cut is a valid, flip-free mesh with
T0 - sum(removed) tets and the input's enclosed volume."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_sample
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy
from naive_dependencies import closure_naive, cut_ancestors_naive, dependencies_naive, merge_volume_changes
from naive_simplify import check_valid, max_coverage

from gatun_py.errors import OptionError
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.simplify import decimate
from gatun_py.simplify.dependencies import (closed_cut_order, cut_ancestors, first_unclosed, merge_dependencies,
                                            prefix_cut)
from gatun_py.simplify.forest import ancestors, mesh_from_ancestors


def _manifold(mesh) -> bool:
    bf = mesh.boundary_faces().astype(np.int64)
    if not bf.shape[0]:
        return True
    e = np.sort(bf[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return bool(np.all(np.unique(e, axis=0, return_counts=True)[1] == 2))


def _random_cuts(deps, rng, n_cuts):
    """Closed cuts: prefixes of the importance order for random importances, and closures of
    random subsets."""
    k = deps.n_merges
    out = []
    for _ in range(n_cuts):
        order = closed_cut_order(deps, rng.random(k) ** 3)
        cut = np.zeros(k, bool)
        cut[order[: int(rng.integers(0, k + 1))]] = True
        out.append(cut)
        sub = rng.random(k) < rng.random()
        out.append(closure_naive([deps.of(i) for i in range(k)], sub))
    return out


def _check_cuts(mesh, forest, deps, cuts, label, *, changes):
    """Every cut: a valid mesh, T0 - sum(removed) tets, and its enclosed volume = the input's plus
    the changes of its merges (each merge sees the star it was validated in, so it changes the
    volume by exactly what it did in its prefix state: interior merges by nothing)."""
    n_flat = int((mesh.signed_volumes() == 0).sum())
    vol0 = float(mesh.signed_volumes().sum())
    manifold = _manifold(mesh)
    # a conforming mesh's tet volumes always sum to what its boundary encloses, so the volume
    # check below cannot see overlapping tets: point coverage can (small meshes: it is O(P m))
    coverage = mesh.n_tets <= 2000 and max_coverage(mesh) == 1
    for c, cut in enumerate(cuts):
        assert deps.is_closed(cut)
        anc = cut_ancestors(forest.parent, forest.rank, cut)
        out = mesh_from_ancestors(mesh, anc)[0]
        check_valid(out, n_flat, f"{label} cut {c}", manifold=manifold)
        assert out.n_tets == deps.cut_tets(mesh.n_tets, cut), f"{label} cut {c}: tet count"
        vol = float(out.signed_volumes().sum())
        want = vol0 + float(changes[cut].sum())
        assert abs(vol - want) <= 1e-9 * abs(vol0), f"{label} cut {c}: volume {vol} vs {want}"
        if coverage:
            assert max_coverage(out) == 1, f"{label} cut {c}: overlapping tets"


@settings(max_examples=40, deadline=None)
@given(mesh_strategy())
def test_kernel_matches_naive(mesh):
    forest = decimate(mesh)
    deps = merge_dependencies(mesh, forest, reduce=False)
    ref, removed = dependencies_naive(mesh.tets, forest.parent, forest.rank)
    assert deps.n_merges == forest.n_merges
    for i in range(forest.n_merges):
        assert deps.of(i).tolist() == ref[i], f"merge {i}"
        assert all(j < i for j in ref[i])
    assert deps.removed.tolist() == removed
    # the reduction keeps the closure of every merge (and of random sets of merges)
    red = merge_dependencies(mesh, forest)
    assert np.array_equal(red.removed, deps.removed)
    assert red.idx.size <= deps.idx.size
    rng = np.random.default_rng(0)
    k = deps.n_merges
    for cut in [np.eye(k, dtype=bool)[i] for i in range(k)] + [rng.random(k) < 0.2 for _ in range(5)]:
        assert np.array_equal(closure_naive(ref, cut), closure_naive([red.of(i) for i in range(k)], cut))


@settings(max_examples=30, deadline=None)
@given(mesh_strategy(), st.integers(0, 2**32 - 1))
def test_random_closed_cuts_are_valid(mesh, seed):
    forest = decimate(mesh)
    deps = merge_dependencies(mesh, forest)
    _check_cuts(mesh, forest, deps, _random_cuts(deps, np.random.default_rng(seed), 4), "random",
                changes=merge_volume_changes(mesh, forest.parent, forest.rank))


@settings(max_examples=10, deadline=None)
@given(st.integers(3, 7), st.integers(3, 6), st.integers(3, 5), st.integers(0, 10_000))
def test_closed_cuts_on_jittered_grids(a, b, c, seed):
    mesh = jittered_grid((a, b, c), jitter=0.3, seed=seed)
    forest = decimate(mesh)
    deps = merge_dependencies(mesh, forest)
    _check_cuts(mesh, forest, deps, _random_cuts(deps, np.random.default_rng(seed), 4), "grid",
                changes=merge_volume_changes(mesh, forest.parent, forest.rank))


@settings(max_examples=20, deadline=None)
@given(mesh_strategy(), st.data())
def test_cut_ancestors(mesh, data):
    forest = decimate(mesh)
    k = forest.n_merges
    cut = np.array(data.draw(st.lists(st.booleans(), min_size=k, max_size=k)), bool)
    assert np.array_equal(cut_ancestors(forest.parent, forest.rank, cut),
                          cut_ancestors_naive(forest.parent, forest.rank, cut))
    n = data.draw(st.integers(0, k))
    assert np.array_equal(cut_ancestors(forest.parent, forest.rank, prefix_cut(k, n)),
                          ancestors(forest.parent, forest.rank, n))


def test_prefixes_are_closed_and_order_respects_dependencies():
    mesh = delaunay_mesh(60, 3)
    forest = decimate(mesh)
    deps = merge_dependencies(mesh, forest)
    for n in range(deps.n_merges + 1):
        assert deps.is_closed(prefix_cut(deps.n_merges, n))
    order = closed_cut_order(deps, np.random.default_rng(0).random(deps.n_merges))
    pos = np.empty_like(order)
    pos[order] = np.arange(order.size)
    for i in range(deps.n_merges):
        assert np.all(pos[deps.of(i)] < pos[i])
    # a cut missing a dependency is reported
    i = next(i for i in range(deps.n_merges) if deps.of(i).size)
    cut = prefix_cut(deps.n_merges, i + 1)
    cut[deps.of(i)[0]] = False
    assert first_unclosed(deps, cut) >= 0


def test_unclosed_cuts_can_flip_so_the_dependencies_matter():
    """Over random meshes, some cut that leaves out a dependency is invalid: the DAG is not vacuous."""
    bad = 0
    for seed in range(6):
        mesh = grid_mesh(5, 5, 4, jitter=0.2, seed=seed)
        forest = decimate(mesh)
        deps = merge_dependencies(mesh, forest)
        rng = np.random.default_rng(seed)
        for _ in range(30):
            cut = rng.random(deps.n_merges) < 0.5
            if deps.is_closed(cut):
                continue
            out = mesh_from_ancestors(mesh, cut_ancestors(forest.parent, forest.rank, cut))[0]
            try:
                check_valid(out, 0, "unclosed")
            except AssertionError:
                bad += 1
    assert bad > 0


def test_wrong_forest_is_refused():
    mesh = grid_mesh(4, 4, 4, jitter=0.1, seed=1)
    forest = decimate(mesh)
    other = decimate(grid_mesh(4, 4, 4, jitter=0.1, seed=2))
    perm = np.random.default_rng(0).permutation(mesh.n_points)
    inv = np.argsort(perm)
    # a valid forest over the same vertex count that does not follow the mesh's edges
    with pytest.raises(OptionError):
        merge_dependencies(mesh, (inv[other.parent[perm]], other.rank[perm]))
    with pytest.raises(OptionError):
        merge_dependencies(mesh, (forest.parent[:-1], forest.rank[:-1]))


@pytest.mark.parametrize("name", ["post", "fire", "bluntfin", "combustion"])
def test_samples_random_closed_cuts(name):
    from test_simplify_forest import _forest

    mesh = load_sample(name)[0]
    forest = _forest(name)
    deps = merge_dependencies(mesh, forest)
    assert deps.cut_tets(mesh.n_tets, prefix_cut(deps.n_merges, deps.n_merges)) == \
        mesh_from_ancestors(mesh, ancestors(forest.parent, forest.rank, deps.n_merges))[0].n_tets
    _check_cuts(mesh, forest, deps, _random_cuts(deps, np.random.default_rng(7), 2), name,
                changes=merge_volume_changes(mesh, forest.parent, forest.rank))
