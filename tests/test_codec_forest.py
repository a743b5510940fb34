"""Format-3 merge-forest coding (parents among live neighbours, bucketed ranks): bytes equal to
the slow reference, round trips, escapes, bad input, and the file level (format 3 writes it,
format 1 and 2 files keep the old decoder: ``test_format_stability.py``)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy, with_unreferenced
from naive_forest import naive_encode_forest_on_mesh

from gatun_py.codec import container
from gatun_py.codec.forest import (ROOT_RANK, check_forest, coding_for_format, decode_forest_on_mesh, encode_forest,
                                   encode_forest_on_mesh, forest_header)
from gatun_py.codec.tetcfile import LevelPayload, TetcReader, encode_tetc
from gatun_py.errors import CorruptFileError
from gatun_py.simplify import build_levels, decimate, storage_forests


def _random_forest(n: int, seed: int, roots: int = 1):
    """A valid forest whose parents are arbitrary (mostly not mesh neighbours): exercises the
    second candidate list and the explicit-id escape."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)  # order[i] merges at rank i; the last `roots` never merge
    k = max(0, n - roots)
    rank = np.full(n, ROOT_RANK, np.int64)
    parent = np.arange(n)
    for i in range(k):
        v = order[i]
        rank[v] = i
        parent[v] = order[rng.integers(i + 1, n)]
    return parent, rank


def _boundary(tets, n):
    """Boundary-vertex mask (faces used by one tet)."""
    faces = np.sort(np.asarray(tets).reshape(-1, 4)[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3), axis=1)
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    mask = np.zeros(n, bool)
    mask[uniq[count == 1].ravel()] = True
    return mask


def _round_trip(parent, rank, tets, n):
    b = _boundary(tets, n)
    data = encode_forest_on_mesh(parent, rank, tets, boundary=b)
    assert data == naive_encode_forest_on_mesh(parent, rank, tets, b)
    p, r = decode_forest_on_mesh(data, tets, n, boundary=b)
    assert np.array_equal(p, parent) and np.array_equal(r, rank)
    assert p.dtype == np.int32 and r.dtype == np.int32
    return data


@settings(max_examples=30, deadline=None)
@given(mesh_strategy())
def test_decimated_forest_matches_reference_and_round_trips(mesh):
    f = decimate(mesh)
    _round_trip(f.parent, f.rank, mesh.tets, mesh.n_points)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**31), st.integers(1, 4))
def test_arbitrary_forest_on_a_mesh_round_trips(n_points, seed, roots):
    mesh = delaunay_mesh(max(n_points, 5), seed % 1000)
    n = mesh.n_points
    parent, rank = _random_forest(n, seed, min(roots, n))
    _round_trip(parent, rank, mesh.tets, n)


def test_unreferenced_vertices_and_no_tets():
    mesh = with_unreferenced(grid_mesh(3, 3, 3, jitter=0.1, seed=2), 5, seed=1)
    f = decimate(mesh)
    _round_trip(f.parent, f.rank, mesh.tets, mesh.n_points)
    parent, rank = _random_forest(9, 4)
    _round_trip(parent, rank, np.zeros((0, 4), np.int32), 9)  # every parent by its plain id


def test_roots_only_and_empty():
    tets = np.array([[0, 1, 2, 3]])
    data = _round_trip(np.arange(4), np.full(4, ROOT_RANK), tets, 4)
    assert len(data) == 12 and forest_header(data) == (4, 0)
    _round_trip(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4), int), 0)


def test_fewer_bits_than_the_old_coding_on_a_real_level():
    mesh = grid_mesh(12, 12, 10, jitter=0.2, seed=3)
    f = decimate(mesh)
    new = encode_forest_on_mesh(f.parent, f.rank, mesh.tets, boundary=_boundary(mesh.tets, mesh.n_points))
    old = encode_forest(f.parent, f.rank)
    assert len(new) < 0.8 * len(old)
    rank_bound = np.log2(np.arange(1, f.n_merges + 1)).sum() / 8  # log2(k!) bits: an arbitrary order
    # above an arbitrary order's log2(k!), a bucket and a parent cost under 5 bits a vertex together,
    # models still learning (the samples: about 4)
    assert len(new) < rank_bound + 5 * mesh.n_points / 8


def test_bad_bytes_raise_typed_errors_never_out_of_bounds():
    mesh = grid_mesh(5, 5, 4, jitter=0.1, seed=5)
    f = decimate(mesh)
    n, tets = mesh.n_points, mesh.tets
    bnd = _boundary(tets, n)
    data = encode_forest_on_mesh(f.parent, f.rank, tets, boundary=bnd)
    try:  # another boundary than the encoder's: an error or some other valid forest, never a crash
        check_forest(*decode_forest_on_mesh(data, tets, n, boundary=~bnd))
    except CorruptFileError:
        pass
    with pytest.raises(CorruptFileError):
        decode_forest_on_mesh(data, tets, n + 1, boundary=np.zeros(n + 1, bool))
    for cut in (0, 5, 11, 12, 13, len(data) // 2, len(data) - 1):
        with pytest.raises(CorruptFileError):
            decode_forest_on_mesh(data[:cut], tets, n, boundary=bnd)
    with pytest.raises(CorruptFileError):
        decode_forest_on_mesh(data + b"x", tets, n, boundary=bnd)
    with pytest.raises(CorruptFileError):
        decode_forest_on_mesh(encode_forest(f.parent, f.rank), tets, n, boundary=bnd)  # the old coding's magic
    for k in (n, n + 1, 2**32 - 1):  # absurd merge counts
        with pytest.raises(CorruptFileError):
            decode_forest_on_mesh(struct.pack("<4sII", b"GFR3", n, k) + data[12:], tets, n, boundary=bnd)
    with pytest.raises(CorruptFileError):
        decode_forest_on_mesh(data, np.full((2, 4), n, np.int32), n, boundary=bnd)  # tets beyond the vertices
    rng = np.random.default_rng(0)
    for _ in range(300):
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(12, len(b)))
            b[i] ^= 1 << int(rng.integers(0, 8))
        try:
            p, r = decode_forest_on_mesh(bytes(b), tets, n, boundary=bnd)
        except CorruptFileError:
            continue
        check_forest(p, r)  # whatever decodes is a valid forest (the file's CRC catches the rest)
    for _ in range(100):  # random garbage after a valid header
        body = rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8).tobytes()
        try:
            check_forest(*decode_forest_on_mesh(data[:12] + body, tets, n, boundary=bnd))
        except CorruptFileError:
            pass


def test_files_are_format_3_and_store_the_new_coding():
    mesh = grid_mesh(8, 7, 6, jitter=0.15, seed=7)
    f = decimate(mesh)
    lv = build_levels(mesh, f)
    r = TetcReader(encode_tetc([LevelPayload(x.level, x.ratio, x.n_merges, x.mesh, (g.parent, g.rank))
                                for x, g in zip(lv, storage_forests(lv))]))
    assert r.container.major == container.VERSION_MAJOR >= 3
    magic = {1: b"GFR3", 2: b"GFR6", 3: b"GFR7"}[coding_for_format(r.container.major)]
    for lv in r.levels:
        if lv["has_forest"]:
            assert r.read_section(f"L{lv['level']}/forest")[:4] == magic
    p, rank = r.read_forest(0)
    mesh0 = r.decode_mesh(0)
    # same forest as the decimator's, in decode order: compare (merged vertex, parent) by position
    key = {tuple(x): i for i, x in enumerate(mesh.points.tolist())}
    orig = np.array([key[tuple(x)] for x in mesh0.points.tolist()])
    assert np.array_equal(rank, f.rank[orig])
    assert np.array_equal(orig[p], f.parent[orig])


def test_the_stream_after_the_forest_reuses_its_connectivity_and_equals_a_fresh_decode():
    mesh = grid_mesh(9, 8, 7, jitter=0.15, seed=11)
    f = decimate(mesh)
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh, (f.parent, f.rank))])
    fresh = list(TetcReader(data).iter_decode(0, batch_tets=97))
    r = TetcReader(data)
    r.read_forest(0)
    # every coding keeps the connectivity it decoded; codings 2 and 3 decode (and keep) the geometry too
    assert r._decoded is not None
    assert (getattr(r, "_decoded_geometry", None) is not None) == (coding_for_format(r.container.major) >= 2)
    replayed = list(r.iter_decode(0, batch_tets=97))
    assert r._decoded is None and getattr(r, "_decoded_geometry", None) is None  # handed over once
    assert len(fresh) == len(replayed)
    for a, b in zip(fresh, replayed):
        assert a.first == b.first
        assert np.array_equal(a.tets, b.tets) and np.array_equal(a.points, b.points)
        assert np.array_equal(a.density, b.density)
    r.read_forest(0)
    m1, m2 = r.decode_mesh(0), TetcReader(data).decode_mesh(0)
    assert np.array_equal(m1.tets, m2.tets) and np.array_equal(m1.points, m2.points)


def test_decode_kernels_release_the_gil():
    """Bricks decode on threads: every kernel the decoder calls from Python runs without the GIL."""
    from gatun_py.codec import _array_kernels, _cutborder_kernels, _forest_kernels, _geometry_kernels
    from gatun_py.codec.legacy import tets1

    kernels = [_cutborder_kernels.decode_boundary, _cutborder_kernels._decode_tets_run, tets1._decode_tets_run,
               _cutborder_kernels.add_faces,
               _geometry_kernels.decode_tables_kernel, _geometry_kernels.decode_vertices, _geometry_kernels._decode_vertices_run,
               _array_kernels.decode_component, _array_kernels.reconstruct,
               _forest_kernels.adjacency, _forest_kernels.decode_forest_kernel, _forest_kernels.decode_rounds_kernel,
               _forest_kernels.decode_parents_kernel, _forest_kernels.level_quadrics,
               _forest_kernels.decode_rounds3_kernel, _forest_kernels.decode_parents3_kernel]
    assert all(k.targetoptions.get("nogil") for k in kernels), [k.__name__ for k in kernels
                                                               if not k.targetoptions.get("nogil")]


def test_adjacency_rows_are_the_distinct_neighbours():
    """The CSR adjacency (rows in no set order) against Python sets, on a mesh, on tets that list
    a pair in many tets (a fan around one vertex) and on disjoint tets (run the tests with
    NUMBA_BOUNDSCHECK=1 and a fresh NUMBA_CACHE_DIR to check the kernels' indexing too)."""
    from gatun_py.codec._forest_kernels import adjacency

    fan = np.array([[0, i, i + 1, i + 2] for i in range(1, 60)], np.int32)
    disjoint = np.arange(8, dtype=np.int32).reshape(2, 4)  # every slot of the row buffer used (12 per tet)
    for tets, n in ((np.asarray(delaunay_mesh(80, 3).tets, np.int32), 80), (fan, 62), (disjoint, 8),
                    (np.zeros((0, 4), np.int32), 5)):
        start, nbrs = adjacency(tets, n)
        expect = [set() for _ in range(n)]
        for t in tets.tolist():
            for a in t:
                expect[a].update(b for b in t if b != a)
        assert start.shape == (n + 1,) and start[0] == 0 and start[-1] == len(nbrs)
        for v in range(n):
            row = nbrs[start[v]:start[v + 1]].tolist()
            assert len(row) == len(set(row)) and set(row) == expect[v]


def test_candidate_order_kernels_match_a_sort():
    """The replay's selection of the idx-th candidate (a partial selection sort, or a full sort from
    index 8) and the encoder's index of a parent agree with sorting by (count descending, id)."""
    from gatun_py.codec._forest_kernels import _candidate_at, _index_of

    rng = np.random.default_rng(1)
    for m in (1, 2, 5, 9, 31, 33, 200):
        cand0 = rng.permutation(10 * m)[:m].astype(np.int32)
        count0 = rng.integers(1, 4, m).astype(np.int32)
        order = sorted(range(m), key=lambda i: (-count0[i], cand0[i]))
        for idx in range(m):
            assert _index_of(cand0, count0, m, cand0[order[idx]]) == idx
            cand, count = cand0.copy(), count0.copy()
            assert _candidate_at(cand, count, m, idx) == cand0[order[idx]]
            assert sorted(zip(cand.tolist(), count.tolist())) == sorted(zip(cand0.tolist(), count0.tolist()))
        assert _index_of(cand0, count0, m, 10 * m) == -1


@pytest.mark.parametrize("seed", range(4))
def test_long_candidate_lists_match_reference(seed):
    """A fan (one vertex with 70 neighbours: tier 0 counted with the per-vertex table, not the
    short search) and an arbitrary forest on a larger mesh (tier-1 lists past 32 entries: uniform
    indices, and indices from 8 on: the full sort) give the reference's bytes and round-trip."""
    fan = np.array([[0, i, i + 1, i + 2] for i in range(1, 71)], np.int32)
    parent, rank = _random_forest(73, seed)
    _round_trip(parent, rank, fan, 73)
    # the fan's centre merged last, into a ring vertex: its whole star is tier 0
    order = np.r_[np.arange(1, 72), 0]
    rank = np.full(73, ROOT_RANK, np.int64)
    rank[order] = np.arange(72)
    parent = np.full(73, 72)
    parent[72] = 72
    _round_trip(parent, rank, fan, 73)
    mesh = delaunay_mesh(300, seed)
    parent, rank = _random_forest(mesh.n_points, seed + 10, 2)
    _round_trip(parent, rank, mesh.tets, mesh.n_points)
