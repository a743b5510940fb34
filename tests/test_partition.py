"""Bricks: the k-d partition covers every tet once, is balanced, and each brick is a faithful sub-mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatun_py.errors import OptionError
from gatun_py.mesh.partition import partition_tets, split_bricks
from gatun_py.mesh.synthetic import jittered_grid


@settings(max_examples=25, deadline=None)
@given(dims=st.tuples(st.integers(2, 7), st.integers(2, 7), st.integers(2, 7)), k=st.integers(1, 40),
       seed=st.integers(0, 10))
def test_partition_is_balanced_and_bricks_rebuild_the_mesh(dims, k, seed):
    m = jittered_grid(dims, jitter=0.3, seed=seed)
    k = min(k, m.n_tets)
    ids = partition_tets(m, k)
    counts = np.bincount(ids, minlength=k)
    assert len(counts) == k and counts.sum() == m.n_tets
    # each split rounds by at most one tet: spread bounded by the depth of the k-d tree
    assert counts.max() - counts.min() <= int(np.ceil(np.log2(k))) + 1
    assert np.array_equal(ids, partition_tets(m, k))  # deterministic
    bricks = split_bricks(m, ids)
    seen = np.zeros(m.n_tets, np.int64)
    users = np.zeros(m.n_points, np.int64)
    for b in bricks:
        seen[b.tet_ids] += 1
        np.testing.assert_array_equal(b.vertex_ids[b.mesh.tets], m.tets[b.tet_ids])
        np.testing.assert_array_equal(b.mesh.points, m.points[b.vertex_ids])
        np.testing.assert_array_equal(b.mesh.density, m.density[b.vertex_ids])
        users[b.vertex_ids] += 1
    assert np.all(seen == 1)
    for b in bricks:
        np.testing.assert_array_equal(b.cut, users[b.vertex_ids] > 1)


def test_bricks_are_spatially_compact():
    """A k-d split separates the centroids: the bricks of a 2-way split do not interleave on the split axis."""
    m = jittered_grid((12, 5, 5), jitter=0.1)
    ids = partition_tets(m, 2)
    cx = np.asarray(m.points, np.float64)[m.tets].mean(axis=1)[:, 0]
    assert cx[ids == 0].max() <= cx[ids == 1].min()


@pytest.mark.parametrize("k", [0, -1, 10**6])
def test_absurd_brick_counts_are_refused(k):
    with pytest.raises(OptionError, match="bricks"):
        partition_tets(jittered_grid((3, 3, 3), jitter=0.1), k)


def test_more_bricks_than_tets_is_refused():
    m = jittered_grid((2, 2, 2), jitter=0.1)
    with pytest.raises(OptionError, match="one brick per tet"):
        partition_tets(m, m.n_tets + 1)
