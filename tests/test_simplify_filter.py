"""The run-time filter against the plain reference and against the simplified mesh."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatun_py.errors import CorruptFileError
from gatun_py.mesh import TetBatch as Batch
from gatun_py.simplify import ancestors, decimate
from gatun_py.simplify.filter import SimplifyFilter
from meshgen import AWKWARD, grid_mesh, mesh_strategy
from naive_filter import naive_filter


def emulated_stream(mesh, seed, batch_vertices=7):
    """A decode-like stream: vertices in a random order, boundary first, each tet as soon as its
    last vertex has arrived; returns (batches, new id of every original vertex)."""
    rng = np.random.default_rng(seed)
    n = mesh.n_points
    bnd = mesh.boundary_faces()
    bverts = np.unique(bnd)
    rest = np.setdiff1d(np.arange(n), bverts)
    order = np.concatenate([rng.permutation(bverts), rng.permutation(rest)])
    new = np.empty(n, np.int64)
    new[order] = np.arange(n)
    tets = new[mesh.tets]
    faces = new[bnd]
    ready = tets.max(axis=1)
    tets = tets[rng.permutation(len(tets))]
    ready = tets.max(axis=1)
    batches = []
    nb = len(bverts)
    cuts = [0] + list(range(max(nb, 1), n, batch_vertices)) + [n]
    cuts = sorted(set(cuts))
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        sel = (ready >= lo) & (ready < hi)
        fsel = (faces.max(axis=1) >= lo) & (faces.max(axis=1) < hi) if lo < nb else np.zeros(len(faces), bool)
        if lo == 0:
            fsel = np.ones(len(faces), bool)
        batches.append(Batch(lo, mesh.points[order[lo:hi]], mesh.density[order[lo:hi]],
                             faces[fsel].astype(np.int32), tets[sel].astype(np.int32)))
    return batches, new


def _forest_in_stream_order(forest, new):
    parent = np.empty_like(forest.parent)
    rank = np.empty_like(forest.rank)
    parent[new] = new[forest.parent]
    rank[new] = forest.rank
    return parent, rank


def _run(mesh, seed, frac):
    forest = decimate(mesh)
    batches, new = emulated_stream(mesh, seed)
    parent, rank = _forest_in_stream_order(forest, new)
    N = int(frac * forest.n_merges)
    anc = ancestors(parent, rank, N)
    f = SimplifyFilter(anc)
    got = list(f.filter(batches))
    ref = list(naive_filter(batches, anc))
    return mesh, forest, new, anc, N, f, got, ref


def _rows(a):
    return sorted(map(tuple, np.asarray(a).tolist()))


@settings(max_examples=40, deadline=None)
@given(mesh_strategy(), st.integers(0, 1000), st.floats(0, 1))
def test_filter_matches_reference(mesh, seed, frac):
    mesh, forest, new, anc, N, f, got, ref = _run(mesh, seed, frac)
    for g, (rf, rt) in zip(got, ref):
        # Same items, batch by batch (the order inside a batch is free).
        assert _rows(g.boundary) == sorted(rf)
        assert _rows(g.tets) == sorted(rt)
    assert f.stats["tets_in"] == mesh.n_tets
    assert f.stats["tets_out"] + f.stats["tets_dropped"] == mesh.n_tets


@pytest.mark.parametrize("name", ["cavity", "l_shaped", "jittered_grid", "delaunay", "two_components"])
@pytest.mark.parametrize("frac", [0.0, 0.3, 1.0])
def test_filter_gives_the_simplified_mesh(name, frac):
    mesh = AWKWARD[name]()
    mesh, forest, new, anc, N, f, got, ref = _run(mesh, 5, frac)
    tets = np.concatenate([g.tets for g in got])
    faces = np.concatenate([g.boundary for g in got])
    # Oracle: the tets of the simplified mesh, with ancestors as vertices, oriented as stored.
    expect = anc[new[mesh.tets]]
    s = np.sort(expect, axis=1)
    expect = expect[np.all(s[:, 1:] != s[:, :-1], axis=1)]
    assert _rows(tets) == _rows(expect)
    # Boundary faces: exactly the boundary of the simplified tets.
    from gatun_py.mesh.model import boundary_faces
    assert _rows(np.sort(faces, axis=1)) == _rows(np.sort(boundary_faces(tets), axis=1))
    # Every tet is forwarded only after all its vertices arrived.
    seen = -1
    for g in got:
        seen = g.first + len(g.points) - 1
        if len(g.tets):
            assert g.tets.max() <= seen


def test_identity_forwards_everything_unchanged():
    mesh = grid_mesh(4, 4, 4)
    batches, new = emulated_stream(mesh, 0)
    f = SimplifyFilter(np.arange(mesh.n_points))
    for b, g in zip(batches, f.filter(batches)):
        assert np.array_equal(b.tets, g.tets) and np.array_equal(b.boundary, g.boundary)
    assert f.stats["tets_dropped"] == 0 and f.stats["tets_parked"] == 0


def test_corrupt_streams_raise():
    mesh = grid_mesh(3, 3, 3)
    batches, new = emulated_stream(mesh, 0)
    with pytest.raises(CorruptFileError):
        SimplifyFilter(np.full(mesh.n_points, mesh.n_points))
    bad = Batch(0, mesh.points, mesh.density, np.zeros((0, 3), np.int32), np.array([[0, 1, 2, 99]], np.int32))
    with pytest.raises(CorruptFileError, match="outside the mesh"):
        SimplifyFilter(np.arange(mesh.n_points)).process(bad)
    # A tet waiting on a vertex that never comes.
    anc = np.arange(mesh.n_points)
    anc[0] = mesh.n_points - 1
    short = [Batch(0, mesh.points[:-1], mesh.density[:-1], np.zeros((0, 3), np.int32),
                   np.array([[0, 1, 3, 9]], np.int32))]
    with pytest.raises(CorruptFileError, match="never delivered"):
        list(SimplifyFilter(anc).filter(short))
