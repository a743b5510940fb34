"""Decimation kernels against the slow reference, and validity of every prefix of the merge forest."""

from __future__ import annotations

import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst
from meshgen import AWKWARD, delaunay_mesh, degenerate_grid, grid_mesh, mesh_strategy, single_tet
from naive_simplify import (check_valid, collapse, evaluate_merge, face_neighbours, interpolate, legal_merges,
                            pinned_vertices, quadric_value, reassign_samples, tet_quadrics)

from gatun_py.errors import OptionError
from gatun_py.simplify import ROOT_RANK, check_forest, decimate, simplified_mesh
from gatun_py.simplify import _decimate_kernels as K
from gatun_py.simplify.decimation import CENTROID_WEIGHT, QUADRIC_WEIGHT, SCALAR_SCALE, DecimationState

import gatun_py.simplify.decimation as D  # noqa: E402

MANIFOLD = {k for k in AWKWARD if k not in ("edge_touching", "vertex_touching")}


def _naive_kw(state, tets):
    return dict(is_boundary=set(np.flatnonzero(state.isb).tolist()),
                pinned=set(np.flatnonzero(state.pinned).tolist()),
                wd=state.params[0], wg=state.params[1], wv=state.params[2], wi=state.params[3],
                wq=state.params[4], quad=state.quad, u4=state.u4, ws=state.params[5], n_power=state.params[6],
                max_samples=state.params[7])


def _sample_weights(mesh):
    """A vertex's share of the volume (a quarter of the volume of its tets, over the total), then
    every tet's centroid: its volume over the total, times CENTROID_WEIGHT."""
    vol = np.abs(mesh.signed_volumes())
    pw = np.zeros(mesh.n_points)
    for t, v in zip(mesh.tets, vol):
        pw[t] += v / 4.0
    return np.concatenate([pw, vol * CENTROID_WEIGHT]) / vol.sum()


def _sample_points(mesh):
    """Positions and values of the vertices, then of the tet centroids (the sample point ids)."""
    p = mesh.points.astype(np.float64)
    d = mesh.density.astype(np.float64)
    cen = np.array([p[list(t)].sum(axis=0) / 4 for t in mesh.tets]).reshape(-1, 3)
    val = np.array([d[list(t)].sum() / 4 for t in mesh.tets])
    return np.concatenate([p, cen]), np.concatenate([d, val])


def _rows(state, t):
    """The point rows of tet t's list, in order."""
    return range(state.tp_head[t], state.tp_head[t] + state.tp_count[t])


def _kernel_samples(state):
    """point -> tet (4-tuple) from the kernel's per-tet lists."""
    out = {}
    for t in np.flatnonzero(state.alive):
        for p in _rows(state, t):
            assert state.p_orig[p] not in out, "a sample point listed twice"
            out[int(state.p_orig[p])] = tuple(int(x) for x in state.T[t])
    return out


def _star_samples(state, a):
    """The sample points of a's tets in the kernel's order (star order, then list order)."""
    out = {}
    for s in K._star(a, state.head, state.nxt, state.T, state.alive):
        for p in _rows(state, s >> 2):
            out[int(state.p_orig[p])] = tuple(int(x) for x in state.T[s >> 2])
    return out


def _compare_all_edges(state, pts, dens, pw=None):
    tets = [tuple(int(x) for x in t) for t in state.current_tets()]
    kw = _naive_kw(state, tets)
    kw.update(pw=pw)
    edges = sorted({(x, y) for t in tets for x in t for y in t if x != y})
    n_legal = 0
    for a, b in edges:
        ok_k, e_k = state.evaluate(a, b)
        ok_n, e_n = evaluate_merge(tets, pts, dens, a, b, samples=_star_samples(state, a), **kw)
        assert ok_k == ok_n, (a, b, ok_k, ok_n)
        if ok_k:
            n_legal += 1
            # the quadric sums terms far larger than its value: compare within its rounding
            q_scale = kw["wq"] * float(np.abs(state.quad[a]).sum()) * (1.0 + float(state.u4[b] @ state.u4[b]))
            assert e_k == pytest.approx(e_n, rel=1e-9, abs=1e-15 + 1e-12 * q_scale), (a, b)
    return n_legal


@pytest.mark.parametrize("name", ["delaunay", "jittered_grid", "degenerate_grid", "cavity", "edge_touching",
                                  "two_components", "single_tet"])
def test_candidates_match_reference(name):
    mesh = AWKWARD[name]()
    state = DecimationState(mesh, 1.0, 3.0, order="input")
    tets = [tuple(int(x) for x in t) for t in mesh.tets]
    assert set(np.flatnonzero(state.pinned).tolist()) == pinned_vertices(tets, mesh.n_points)
    n0 = _compare_all_edges(state, *_sample_points(mesh), _sample_weights(mesh))
    # isolated tets (single, edge-touching) cannot lose a vertex; everything else can
    assert (n0 > 0) == (name not in ("single_tet", "edge_touching"))
    # and again in a decimated state, half way through
    forest = decimate(mesh, w_geometry=3.0)
    order = np.argsort(forest.rank)[: forest.n_merges // 2]
    for a in order:
        state.apply(int(a), int(forest.parent[a]))
    # (points of a region that left the mesh with a boundary merge are dropped)
    assert len(_kernel_samples(state)) > 0.9 * mesh.n_tets
    spts, sdens = _sample_points(mesh)
    _compare_all_edges(state, spts, sdens, _sample_weights(mesh))
    # with a sample budget small enough to thin out the points of most stars
    state.params[K.P_MAXS] = 2
    _compare_all_edges(state, spts, sdens, _sample_weights(mesh))


@settings(max_examples=40, deadline=None)
@given(mesh_strategy())
def test_tet_hyperplanes_against_svd(mesh):
    """Each tet's plane: unit normal orthogonal to its edges in (x, y, z, s) (the SVD's null vector,
    up to sign), through its corners; flat tets and tets of weight 0 get a zero plane and weight."""
    rng = np.random.default_rng(mesh.n_points)
    u4 = np.column_stack([mesh.points.astype(np.float64), rng.random(mesh.n_points)])
    T = np.ascontiguousarray(mesh.tets, np.int32)
    weight = rng.random(mesh.n_tets)
    weight[::5] = 0.0
    planes = np.empty((mesh.n_tets, 6))
    K._tet_hyperplanes(u4, T, weight, planes)
    for t in range(mesh.n_tets):
        e = u4[T[t, 1:]] - u4[T[t, 0]]
        sv = np.linalg.svd(e, compute_uv=False)
        n, d, w = planes[t, :4], planes[t, 4], planes[t, 5]
        if weight[t] == 0.0 or sv[-1] <= 1e-9 * max(sv[0], 1e-300):  # weight 0 or (nearly) flat in 4-D
            if weight[t] == 0.0:
                assert w == 0.0 and not n.any()
            continue
        ref = np.linalg.svd(e)[2][-1]
        assert w == weight[t] and abs(np.linalg.norm(n) - 1.0) < 1e-12
        assert min(np.abs(n - ref).max(), np.abs(n + ref).max()) < 1e-6
        assert np.abs(u4[T[t]] @ n + d).max() < 1e-9 * (1.0 + np.abs(u4[T[t]]).max())


@pytest.mark.parametrize("name", ["delaunay", "jittered_grid", "degenerate_grid"])
def test_quadrics_match_reference_and_accumulate(name):
    mesh = AWKWARD[name]()
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    w = np.abs(mesh.signed_volumes()) / np.abs(mesh.signed_volumes()).sum() * QUADRIC_WEIGHT / SCALAR_SCALE**2
    ref = tet_quadrics(state.u4, mesh.tets.tolist(), w)
    assert np.allclose(state.quad, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    # every tet's hyperplane passes through its corners: a vertex's own quadric vanishes at its point
    scale = np.abs(ref).sum(axis=1) * (1 + (state.u4**2).sum(axis=1))
    own = np.array([quadric_value(state.quad[v], state.u4[v]) for v in range(mesh.n_points)])
    assert np.all(own <= 1e-12 * scale)
    # a merge hands its quadric on: after any prefix, a root holds the sum of its subtree's quadrics
    forest = decimate(mesh)
    k = forest.n_merges // 2
    for a in np.argsort(forest.rank)[:k]:
        state.apply(int(a), int(forest.parent[a]))
    from gatun_py.simplify import ancestors
    anc = ancestors(forest.parent, forest.rank, k)
    expect = np.zeros_like(ref)
    np.add.at(expect, anc, ref)
    roots = anc == np.arange(mesh.n_points)
    assert np.allclose(state.quad[roots], expect[roots], rtol=1e-9, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("name", ["delaunay", "jittered_grid", "degenerate_grid", "cavity", "two_components"])
def test_sample_points_follow_the_merges(name):
    """Every tet centroid and merged-away vertex is listed once, in the tet the reference assigns it
    to (or, on a face shared by two tets, in another tet that also contains it)."""
    mesh = AWKWARD[name]()
    pts, dens = _sample_points(mesh)
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    n, m = mesh.n_points, mesh.n_tets
    # the centroids' rows first (named n + t), the vertices' weights beside
    assert np.array_equal(state.p_orig[:m], np.arange(n, n + m))
    assert np.allclose(state.vw, _sample_weights(mesh)[:n], rtol=1e-12, atol=0)
    assert np.allclose(state.pdat[:m, 4], _sample_weights(mesh)[n:], rtol=1e-12, atol=0)
    assert np.allclose(state.pdat[:m, :3], pts[n:], rtol=1e-12, atol=1e-12)
    assert np.allclose(state.pdat[:m, 3], dens[n:], rtol=1e-12)
    forest = decimate(mesh)
    tets = [tuple(int(x) for x in t) for t in mesh.tets]
    ref = {mesh.n_points + i: t for i, t in enumerate(tets)}
    assert _kernel_samples(state) == ref
    order = np.argsort(forest.rank)[: forest.n_merges * 2 // 3]
    assert len(order) > 3
    for i, a in enumerate(order):
        a, b = int(a), int(forest.parent[a])
        ref = reassign_samples(tets, pts, dens, ref, a, b)
        state.apply(a, b)
        tets = collapse(tets, a, b)
        if i % 5 and i != len(order) - 1:
            continue
        got = _kernel_samples(state)
        assert set(got) == set(ref)
        assert set(got.values()) <= set(tets)
        for x, t in got.items():
            if t != ref[x]:
                assert min(interpolate(pts, dens, t, pts[x])[0], interpolate(pts, dens, ref[x], pts[x])[0]) >= -1e-9


@pytest.mark.parametrize("mesh", [delaunay_mesh(18, 3), grid_mesh(3, 3, 3, jitter=0.2, seed=1), degenerate_grid()],
                         ids=["delaunay", "grid", "degenerate"])
def test_replay_every_merge_is_legal_and_final_state_is_stuck(mesh):
    forest = decimate(mesh)
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    kw = _naive_kw(state, None)
    pts, dens = mesh.points.astype(np.float64), mesh.density.astype(np.float64)
    tets = [tuple(int(x) for x in t) for t in mesh.tets]
    for a in np.argsort(forest.rank)[: forest.n_merges]:
        a, b = int(a), int(forest.parent[a])
        ok, _ = evaluate_merge(tets, pts, dens, a, b, **kw)
        assert ok, f"merge {a}->{b} is not legal in the reference"
        tets = collapse(tets, a, b)
    assert legal_merges(tets, pts, dens, **kw) == []


def _check_forest_prefixes(mesh, forest, ns, label=""):
    n_flat = int((mesh.signed_volumes() == 0).sum())
    check_forest(forest.parent, forest.rank)
    isb = np.zeros(mesh.n_points, bool)
    isb[mesh.boundary_faces().ravel()] = True
    merged = forest.rank != ROOT_RANK
    assert not np.any(isb[merged] & ~isb[forest.parent[merged]]), "a boundary vertex went into an interior one"
    manifold = True
    bf = mesh.boundary_faces().astype(np.int64)
    if bf.shape[0]:
        e = np.sort(bf[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        manifold = bool(np.all(np.unique(e, axis=0, return_counts=True)[1] == 2))
    for n in ns:
        check_valid(simplified_mesh(mesh, forest, int(n)), n_flat, f"{label} N={n}", manifold=manifold)


@settings(max_examples=30, deadline=None)
@given(mesh_strategy())
def test_every_prefix_is_valid(mesh):
    forest = decimate(mesh)
    _check_forest_prefixes(mesh, forest, range(forest.n_merges + 1))


def test_reaches_far_on_random_meshes():
    mesh = delaunay_mesh(60, 11)
    forest = decimate(mesh)
    assert forest.max_ratio > 0.8


def test_single_tet_is_a_forest_of_roots():
    forest = decimate(single_tet())
    assert forest.n_merges == 0
    assert np.array_equal(forest.parent, np.arange(4))
    assert np.all(forest.rank == ROOT_RANK)


def test_bad_weights():
    for kw in ({"w_density": -1.0}, {"w_geometry": float("nan")}, {"w_sample": -0.5}, {"w_sample": float("inf")}):
        with pytest.raises(OptionError):
            decimate(single_tet(), **kw)


@pytest.mark.parametrize("name", ["delaunay", "jittered_grid", "cavity"])
def test_without_the_sampled_error(name):
    """w_sample=0 drops the sampled term only: the kernels still match the reference (with ws = 0),
    every prefix of the forest is valid, and the forest is another one than the default's."""
    mesh = AWKWARD[name]()
    state = DecimationState(mesh, 1.0, 3.0, order="input", w_sample=0.0)
    assert state.params[K.P_WS] == 0.0
    assert state.params[K.P_WD] == DecimationState(mesh, 1.0, 3.0, order="input").params[K.P_WD]
    assert _compare_all_edges(state, *_sample_points(mesh), _sample_weights(mesh)) > 0
    forest = decimate(mesh, w_sample=0.0)
    _check_forest_prefixes(mesh, forest, range(forest.n_merges + 1), f"{name} w_sample=0")
    full = decimate(mesh)
    assert forest.n_merges > 0.5 * mesh.n_points
    assert not (np.array_equal(forest.parent, full.parent) and np.array_equal(forest.rank, full.rank))


def test_max_merges_and_progress_give_the_same_prefix():
    mesh = grid_mesh(5, 4, 4, jitter=0.1, seed=2)
    full = decimate(mesh, rounds=0)  # with rounds: test_simplify_rounds
    seen = []
    part = decimate(mesh, max_merges=20, progress=seen.append, rounds=0)
    assert part.n_merges == 20 and sum(seen) == 20
    first = full.rank < 20
    assert np.array_equal(first, part.rank < 20)
    assert np.array_equal(full.parent[first], part.parent[first])


def test_meshes_without_tets():
    from gatun_py.mesh import TetMesh

    for n in (0, 3):
        mesh = TetMesh(np.zeros((n, 3), np.float32), np.zeros(n, np.float32), np.zeros((0, 4), np.int32))
        forest = decimate(mesh)
        assert forest.n_merges == 0 and np.array_equal(forest.parent, np.arange(n))


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_set_up_matches_reference(name):
    """Face neighbours, boundary and pinned vertices and incidence lists of the set-up kernels."""
    mesh = AWKWARD[name]()
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    tets = [tuple(int(x) for x in t) for t in mesh.tets]
    assert state.nbr.tolist() == face_neighbours(tets)
    assert set(np.flatnonzero(state.pinned).tolist()) == pinned_vertices(tets, mesh.n_points)
    assert set(np.flatnonzero(state.isb).tolist()) == {w for t, k in zip(*np.nonzero(state.nbr < 0))
                                                       for j, w in enumerate(tets[t]) if j != k}
    for v in range(mesh.n_points):
        slots = K._star(v, state.head, state.nxt, state.T, state.alive).tolist()
        assert slots == [4 * t + c for t, q in enumerate(tets) for c, w in enumerate(q) if w == v]


def _best_by_every_error(state, a):
    """The best legal merge of a with every candidate's error computed (the rule the bound keeps)."""
    st = K._star(a, state.head, state.nxt, state.T, state.alive)
    if st.shape[0] == 0 or state.pinned[a]:
        return -1, 0.0
    cand = np.empty(3 * st.shape[0] + 1, np.int64)
    err = np.empty(cand.shape[0])
    nc = K._candidate_errors(a, st, state.T, state.nbr, state.pts, state.dens, state.isb, state.pinned,
                             state.params, state.quad, state.u4, state.marks[0], state.tcount[0], cand, err,
                             *state._sample_args())
    for i in sorted(range(nc), key=lambda i: (err[i], cand[i])):
        if K._link_ok(a, int(cand[i]), st, state.T, state.alive, state.nbr, state.head, state.nxt, state.isb,
                      state.marks_b[0], state.marks_ab[0], state.tcount[0]):
            return int(cand[i]), float(err[i])
    return -1, 0.0


@pytest.mark.parametrize("mesh", [delaunay_mesh(25, 4), grid_mesh(4, 4, 3, jitter=0.2, seed=3), degenerate_grid()],
                         ids=["delaunay", "grid", "degenerate"])
def test_branch_and_bound_picks_the_best_merge(mesh):
    """The bounded search of _evaluate picks what computing every candidate's error would, bit for bit,
    at the start and part way through (where the sample points make the bound loose)."""
    forest = decimate(mesh)
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    order = np.argsort(forest.rank)[: forest.n_merges]
    done = 0
    for stop in (0, len(order) // 3, 2 * len(order) // 3):
        for a in order[done:stop]:
            state.apply(int(a), int(forest.parent[a]))
        done = stop
        for a in np.flatnonzero(state.parent == np.arange(mesh.n_points)):
            want = _best_by_every_error(state, int(a))
            # with the scratch buffers of a thread, and with none (every array allocated)
            for fbuf, ibuf in ((np.empty(K._SCRATCH_F), np.empty(K._SCRATCH_I, np.int64)),
                               (np.empty(0), np.empty(0, np.int64))):
                got = K._evaluate(int(a), *state._mesh_args(), state.marks[0], state.marks_b[0], state.marks_ab[0],
                                  state.tcount[0], *state._sample_args(), fbuf, ibuf)
                assert (int(got[0]), float(got[1])) == want, (stop, a, fbuf.size)


def test_forest_does_not_depend_on_the_thread_count():
    mesh = delaunay_mesh(50, 7)
    saved = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = decimate(mesh)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = decimate(mesh)
    finally:
        numba.set_num_threads(saved)
    assert np.array_equal(one.parent, many.parent) and np.array_equal(one.rank, many.rank)


def _gmsh_mesh(name):
    """A small unstructured gmsh mesh (bench/gmsh_meshes.py), skipped when gmsh is not installed."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import gmsh_meshes

    if not (gmsh_meshes.CACHE / f"{name}.vtu").exists():
        pytest.importorskip("gmsh", reason="the gmsh test meshes need the gmsh package (test extra)")
    from gatun_py.mesh import read_mesh

    return read_mesh(gmsh_meshes.mesh_path(name))[0]


def test_unstructured_gmsh_mesh():
    """A graded Delaunay mesh of a CAD-like shape: reaches far, every checked prefix is valid."""
    mesh = _gmsh_mesh("block-50k")
    assert 30_000 < mesh.n_tets <= 50_000
    forest = decimate(mesh)
    assert forest.max_ratio > 0.99
    n = forest.n_merges
    _check_forest_prefixes(mesh, forest, [0, 1, n // 4, n // 2, 9 * n // 10, n - 1, n], "block-50k")


@pytest.mark.parametrize("name", ["delaunay", "cavity"])
def test_compacting_the_points_keeps_every_list_and_its_order(name):
    """The point rows are rewritten when they run out: the same points (by name and row content)
    in the same order in every tet's list, side by side from row 0."""
    mesh = AWKWARD[name]()
    state = DecimationState(mesh, 1.0, 1.0, order="input")
    forest = decimate(mesh)
    for a in np.argsort(forest.rank)[: forest.n_merges // 2]:
        state.apply(int(a), int(forest.parent[a]))

    def lists():
        return {int(t): [(int(state.p_orig[p]), tuple(state.pdat[p])) for p in _rows(state, t)]
                for t in np.flatnonzero(state.alive)}

    before = lists()
    K._compact_points(state.alive, state.pdat, state.prow, state.tp_head, state.tp_count, state.counters)
    assert lists() == before
    k = int(state.counters[K.C_PTOP])
    assert k == sum(len(v) for v in before.values())
    # side by side from row 0, no row left between them
    live = [t for t in np.flatnonzero(state.alive) if state.tp_count[t] > 0]
    runs = sorted((int(state.tp_head[t]), int(state.tp_count[t])) for t in live)
    assert runs[0][0] == 0 and runs[-1][0] + runs[-1][1] == k
    assert all(h + c == h2 for (h, c), (h2, _) in zip(runs, runs[1:]))
    assert all(state.prow[h, 1] == t for t in live for h in _rows(state, t))


@pytest.mark.parametrize("name", ["delaunay", "cavity", "two_components"])
def test_running_out_of_point_rows_changes_no_merge(name, monkeypatch):
    """Without room beyond the n + m points the rows are rewritten by many merges (every list
    kept in order): the forest stays the same, bit for bit."""
    mesh = AWKWARD[name]()
    want = decimate(mesh, rounds=0)
    monkeypatch.setattr(D, "POINT_SLACK", 0.0)
    state = DecimationState(mesh, 1.0, 1.0)
    assert state.pdat.shape[0] == mesh.n_points + mesh.n_tets
    state.run(mesh.n_points)
    assert state.counters[K.C_REWRITES] > 0
    got = state.prefix()
    assert got.n_merges == want.n_merges
    assert np.array_equal(got.parent, want.parent) and np.array_equal(got.rank, want.rank)


@settings(max_examples=60, deadline=None)
@given(hst.lists(hst.tuples(hst.integers(0, 2), hst.integers(0, 11),
                            hst.sampled_from([0.0, -0.0, 1.0, 2.5, 1e-300, 7.0])), max_size=80),
       hst.randoms(use_true_random=False))
def test_heap_pops_the_smallest_current_entry(ops, rnd):
    """The heap keeps one entry per vertex (a push replaces it, a removal drops it) and pops the
    smallest (error, vkey) among them: against a dict of the current entries."""
    n = 12
    vkey = np.array(rnd.sample(range(100), n), np.int32)
    h_err, h_v, h_b, h_ver = np.zeros(n + 1), np.zeros(n + 1, np.int32), np.zeros(n + 1, np.int32), \
        np.zeros(n + 1, np.int32)
    h_pos = np.full(n, -1, np.int32)
    counters = np.zeros(K.N_COUNTERS, np.int64)
    ref = {}
    for step, (op, v, e) in enumerate(ops):
        if op == 0:
            K._heap_push(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, e, v, v + 1, step)
            ref[v] = (e, v + 1, step)
        elif op == 1:
            K._heap_remove(h_err, h_v, h_b, h_ver, h_pos, vkey, counters, v)
            ref.pop(v, None)
        elif ref:
            want = min(ref, key=lambda u: (ref[u][0], vkey[u]))
            e_got, v_got, b_got, ver_got = K._heap_pop(h_err, h_v, h_b, h_ver, h_pos, vkey, counters)
            assert (v_got, (e_got, b_got, ver_got)) == (want, ref.pop(want))
        assert counters[K.C_HEAP] == len(ref)
        assert all(h_v[h_pos[u]] == u for u in ref) and all(h_pos[u] == -1 for u in range(n) if u not in ref)
