"""The decimator's local numbering (DecimationState's ``order``): the set-up renumbered bit for
bit, and the same forest (parents, ranks, rounds, level prefixes) whatever the local numbering,
on samples, a gmsh mesh, meshes full of equal errors and random meshes."""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from conftest import load_sample
from hypothesis import given, settings
from meshgen import AWKWARD, delaunay_mesh, grid_mesh, mesh_strategy
from test_simplify_decimate import _gmsh_mesh

from gatun_py.errors import OptionError
from gatun_py.mesh import TetMesh
from gatun_py.simplify import _decimate_kernels as K
from gatun_py.simplify import decimate
from gatun_py.simplify.decimation import DecimationState, local_order

from gatun_py.simplify import decimation as decimate_module


def _random_order(seed):
    rng = np.random.default_rng(seed)
    return lambda mesh: (rng.permutation(mesh.n_points), rng.permutation(mesh.n_tets))


def _reversed_order(mesh):
    return np.arange(mesh.n_points)[::-1], np.arange(mesh.n_tets)[::-1]


def _input_order(mesh):
    return np.arange(mesh.n_points), np.arange(mesh.n_tets)


def _decimate_in(order, mesh, **kw):
    """decimate() with the state's local numbering chosen by ``order(mesh)``; the level prefixes too."""
    levels = []
    with mock.patch.object(decimate_module, "local_order", order):
        forest, starts = decimate(mesh, return_rounds=True, on_level=lambda i, f: levels.append((i, f)), **kw)
    return forest, starts, levels


def _assert_same(a, b):
    (fa, sa, la), (fb, sb, lb) = a, b
    assert fa.n_merges == fb.n_merges
    assert np.array_equal(fa.parent, fb.parent) and np.array_equal(fa.rank, fb.rank)
    assert sa == sb
    assert [i for i, _ in la] == [i for i, _ in lb]
    for (_, pa), (_, pb) in zip(la, lb):
        assert pa.n_merges == pb.n_merges
        assert np.array_equal(pa.parent, pb.parent) and np.array_equal(pa.rank, pb.rank)


def _check_independent_of_numbering(mesh, seeds=(0, 1), **kw):
    """The same forest in the input, Morton, reversed and random local numberings, and without
    dropping the dead tets on the way (:meth:`DecimationState.compact`)."""
    ref = _decimate_in(_input_order, mesh, **kw)
    for order in [local_order, _reversed_order] + [_random_order(s) for s in seeds]:
        _assert_same(_decimate_in(order, mesh, **kw), ref)
    with mock.patch.object(DecimationState, "compact_if_sparse", lambda self: None):
        _assert_same(_decimate_in(local_order, mesh, **kw), ref)
    return ref[0]


@pytest.mark.parametrize("name", ["post", "fire"])
def test_forest_does_not_depend_on_the_local_numbering_samples(name):
    forest = _check_independent_of_numbering(load_sample(name)[0], seeds=(3,))
    assert forest.n_merges > 1000


def test_forest_does_not_depend_on_the_local_numbering_gmsh():
    mesh = _gmsh_mesh("block-50k")
    forest = _check_independent_of_numbering(mesh, seeds=(4,))
    assert forest.max_ratio > 0.99


@pytest.mark.parametrize("rounds", [0, 4])
def test_equal_errors_are_broken_by_the_callers_ids(rounds):
    """A regular grid with a linear field: many candidates and heap entries of equal error, which
    only the caller's ids order (a tie broken by local ids would change the forest)."""
    mesh = grid_mesh(5, 5, 4)
    mesh = TetMesh(mesh.points, (mesh.points[:, 0] + 2 * mesh.points[:, 1]).astype(np.float32), mesh.tets)
    forest = _check_independent_of_numbering(mesh, seeds=(5, 6, 7), rounds=rounds)
    assert forest.n_merges > mesh.n_points // 2


def test_locked_vertices_and_max_merges_in_the_callers_numbering():
    mesh = delaunay_mesh(80, 9)
    locked = np.zeros(mesh.n_points, bool)
    locked[::3] = True
    forest = _check_independent_of_numbering(mesh, locked=locked, max_merges=40)
    assert forest.n_merges == 40 and np.all(forest.rank[locked] == K.ROOT_RANK)


@settings(max_examples=25, deadline=None)
@given(mesh_strategy())
def test_forest_does_not_depend_on_the_local_numbering_random_meshes(mesh):
    _check_independent_of_numbering(mesh, seeds=(8,))


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_set_up_is_renumbered_bit_for_bit(name):
    """Every array of a random local numbering is the caller-numbered one's, renumbered: the same
    floats (sums taken in the caller's order), adjacency, flags and incidence lists (same tet order)."""
    mesh = AWKWARD[name]()
    ref = DecimationState(mesh, 1.0, 1.0, order="input")
    st = DecimationState(mesh, 1.0, 1.0, order=_random_order(11)(mesh))
    vo, to = st.v_orig, st.t_orig
    assert np.array_equal(st.v_local[vo], np.arange(mesh.n_points))
    assert np.array_equal(vo[st.T], ref.T[to])
    assert np.array_equal(np.where(st.nbr >= 0, to[st.nbr], -1), ref.nbr[to])
    for attr in ("pts", "dens", "isb", "pinned", "u4", "quad", "vw"):
        assert np.array_equal(getattr(st, attr), getattr(ref, attr)[vo]), attr
    m = mesh.n_tets
    assert np.array_equal(st.pdat[:m], ref.pdat[:m][to])
    assert np.array_equal(st.params, ref.params)
    assert np.array_equal(st.current_tets(), ref.current_tets())
    for v in range(mesh.n_points):
        slots = K._star(v, st.head, st.nxt, st.T, st.alive)
        assert (4 * to[slots >> 2] + (slots & 3)).tolist() == K._star(int(vo[v]), ref.head, ref.nxt, ref.T,
                                                                      ref.alive).tolist()


@pytest.mark.parametrize("name", ["delaunay", "cavity", "two_components"])
def test_evaluate_apply_and_current_tets_speak_the_callers_ids(name):
    mesh = AWKWARD[name]()
    ref = DecimationState(mesh, 1.0, 1.0, order="input")
    st = DecimationState(mesh, 1.0, 1.0, order=_random_order(12)(mesh))
    forest = decimate(mesh)
    for stage in ("start", "half way"):
        if stage == "half way":
            for a in np.argsort(forest.rank)[: forest.n_merges // 2]:
                ref.apply(int(a), int(forest.parent[a]))
                st.apply(int(a), int(forest.parent[a]))
        tets = st.current_tets()
        assert np.array_equal(tets, ref.current_tets())
        n_legal = 0
        for a, b in {(int(x), int(y)) for t in tets for x in t for y in t if x != y}:
            got = st.evaluate(a, b)
            assert got == ref.evaluate(a, b), (stage, a, b)
            n_legal += got[0]
        assert n_legal > 0
        pa, pb = st.prefix(), ref.prefix()
        assert np.array_equal(pa.parent, pb.parent) and np.array_equal(pa.rank, pb.rank)
        # dropping the dead tets keeps every list (as the caller's tets, in order) and every error
        n_live = int(st.alive.sum())
        st.compact()
        assert st.T.shape[0] == n_live and st.alive.all() and np.array_equal(st.current_tets(), tets)
        for v in range(mesh.n_points):
            slots = K._star(v, st.head, st.nxt, st.T, st.alive)
            got = (4 * st.t_orig[slots >> 2] + (slots & 3)).tolist()
            assert got == K._star(int(st.v_orig[v]), ref.head, ref.nxt, ref.T, ref.alive).tolist()
        assert all(st.evaluate(a, b) == ref.evaluate(a, b) for t in tets for a in t for b in t if a != b)


def test_local_order_is_a_permutation_with_locality():
    mesh = load_sample("fire")[0]
    v_order, t_order = local_order(mesh)
    assert np.array_equal(np.sort(v_order), np.arange(mesh.n_points))
    assert np.array_equal(np.sort(t_order), np.arange(mesh.n_tets))
    # the vertices of a tet lie closer together in the local numbering than in a random one
    v_new = np.empty(mesh.n_points, np.int64)
    v_new[v_order] = np.arange(mesh.n_points)
    span = np.ptp(v_new[mesh.tets], axis=1)
    shuffled = np.ptp(np.random.default_rng(0).permutation(mesh.n_points)[mesh.tets], axis=1)
    assert np.median(span) < np.median(shuffled) / 10
    for bad in ((v_order[:-1], t_order), (v_order, np.zeros_like(t_order))):
        with pytest.raises(OptionError):
            DecimationState(mesh, 1.0, 1.0, order=bad)
