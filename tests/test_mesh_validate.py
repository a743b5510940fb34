"""Validation rules: each bad mesh gets one MeshError naming the first offender and the count."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatun_py.errors import MeshError
from gatun_py.mesh import validate_tets
from gatun_py.mesh.validate import coincident_points, duplicate_rows
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy


def _raw(mesh):
    return np.array(mesh.points), np.array(mesh.density), np.array(mesh.tets, dtype=np.int64)


def _err(points, density, tets):
    with pytest.raises(MeshError) as ei:
        validate_tets(points, density, tets)
    return str(ei.value)


def test_nan_coordinate():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    p[5, 1] = np.nan
    p[9, 0] = np.inf
    msg = _err(p, d, t)
    assert "point 5" in msg and "2 points" in msg


def test_nan_scalar():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    d[7] = np.nan
    msg = _err(p, d, t)
    assert "point 7" in msg and "1 point affected" in msg


def test_id_out_of_range():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    t[4, 2] = len(p) + 3
    t[6, 0] = -1
    msg = _err(p, d, t)
    assert "tet 4" in msg and str(len(p) + 3) in msg and "2 tets" in msg


def test_repeated_vertex():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    t[2, 3] = t[2, 0]
    msg = _err(p, d, t)
    assert "tet 2 repeats" in msg and "1 tet" in msg


def test_duplicate_tet():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    t = np.concatenate([t, t[[3]][:, [1, 0, 2, 3]]])
    msg = _err(p, d, t)
    assert f"tet {len(t) - 1}" in msg and "duplicates tet 3" in msg


def test_non_conforming_face():
    p, d, t = _raw(grid_mesh(3, 3, 3))
    # A third tet on an interior face: apex at a new point.
    shared = None
    faces = {}
    for i, tet in enumerate(t):
        for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]):
            key = tuple(int(x) for x in sorted(tet[f]))
            faces.setdefault(key, []).append(i)
    shared = next(k for k, v in faces.items() if len(v) == 2)
    p = np.concatenate([p, [[10, 10, 10]]]).astype(np.float32)
    d = np.concatenate([d, [0]]).astype(np.float32)
    t = np.concatenate([t, [[*shared, len(p) - 1]]])
    msg = _err(p, d, t)
    assert "non-conforming" in msg and str(list(shared)) in msg and "1 such triangle" in msg


def test_no_tets():
    msg = _err(np.zeros((3, 3)), np.zeros(3), np.zeros((0, 4), np.int64))
    assert "no tetrahedra" in msg


def test_wrong_shapes():
    assert "(n, 3)" in _err(np.zeros((3, 2)), np.zeros(3), np.zeros((1, 4), np.int64))
    assert "scalar has 2 values" in _err(np.zeros((3, 3)), np.zeros(2), np.zeros((1, 4), np.int64))


def test_zero_volume_coincident_unreferenced_are_kept_and_counted():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 0], [7, 7, 7]], np.float32)
    d = np.arange(7, dtype=np.float32)
    t = np.array([[0, 1, 2, 3], [0, 1, 2, 4]])  # second tet is flat (z = 0 plane)
    mesh, rep = validate_tets(p, d, t)
    assert rep.zero_volume_tets == 1
    assert rep.coincident_points == 1  # point 5 repeats point 1
    assert rep.unreferenced_points == 2  # points 5 and 6
    assert mesh.n_points == 7 and mesh.n_tets == 2
    assert np.array_equal(mesh.points, p)


@settings(max_examples=80, deadline=None)
@given(mesh_strategy(), st.integers(0, 2**32 - 1))
def test_reorientation_keeps_the_simplices(mesh, seed):
    """Flipping random tets: validation re-orients exactly those, the simplex set is unchanged."""
    rng = np.random.default_rng(seed)
    p, d, t = _raw(mesh)
    flip = rng.random(len(t)) < 0.5
    flip &= mesh.signed_volumes() > 0  # a flat tet has no orientation to flip
    t2 = t.copy()
    t2[flip] = t2[flip][:, [1, 0, 2, 3]]
    out, rep = validate_tets(p, d, t2)
    assert rep.reoriented_tets == int(flip.sum())
    assert (out.signed_volumes() >= 0).all()
    assert np.array_equal(np.sort(out.tets, axis=1), np.sort(t, axis=1))
    assert out.points.tobytes() == p.tobytes() and out.density.tobytes() == d.tobytes()


def test_orient_false_rejects_negative():
    p, d, t = _raw(delaunay_mesh(10, 1))
    t[0] = t[0][[1, 0, 2, 3]]
    with pytest.raises(MeshError, match="negatively oriented"):
        validate_tets(p, d, t, orient=False)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**32 - 1), st.booleans())
def test_packed_face_multiplicity_equals_the_triples(m, seed, high_ids):
    """The packed-key face count (one int64 per face) against the lexsort of (4m, 3) triples:
    the same counts and the same over-shared faces in the same order, including ids at the top of
    the packed range and faces shared by three or more tets."""
    from gatun_py.mesh.model import _KEY_BITS, _face_multiplicity_triples, face_multiplicity

    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 12))  # few vertices: faces repeat, some in three or more tets
    tets = np.stack([rng.choice(n, 4, replace=False) for _ in range(m)])
    if high_ids:
        tets = tets + ((1 << _KEY_BITS) - n)  # the largest ids that still pack
    counts, over = face_multiplicity(tets)
    ref_counts, ref_over = _face_multiplicity_triples(tets)
    np.testing.assert_array_equal(counts, ref_counts)
    np.testing.assert_array_equal(over.reshape(-1, 3), ref_over.reshape(-1, 3))
    assert counts.sum() == 4 * m


def test_face_multiplicity_beyond_the_packed_range_uses_the_triples():
    from gatun_py.mesh.model import _KEY_BITS, face_multiplicity

    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]]) + (1 << _KEY_BITS)
    counts, over = face_multiplicity(tets)
    assert counts.sum() == 12 and over.tolist() == [[tets[0, 0], tets[0, 1], tets[0, 2]]]


def _plain_duplicates(s):
    """The reference: every row that repeats an earlier one, with the last earlier copy as its twin."""
    last, rows, twins = {}, [], []
    for i, row in enumerate(map(tuple, s.tolist())):
        if row in last:
            rows.append(i)
            twins.append(last[row])
        last[row] = i
    return np.array(rows, np.int64), np.array(twins, np.int64)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.integers(0, 12), min_size=4, max_size=4, unique=True), min_size=0, max_size=60),
       st.booleans())
def test_duplicate_rows_match_the_plain_lexsort(rows, wide):
    """Packed keys (and the lexsort fallback for ids of 21 bits or more) find the same repeats,
    with the same twins, as a lexsort of all four columns: many rows share three ids here."""
    s = np.sort(np.array(rows, np.int64).reshape(-1, 4), axis=1)
    if wide:
        s = s + (1 << 21)
    got, ref = duplicate_rows(s), _plain_duplicates(s)
    assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(*[st.sampled_from([0.0, -0.0, 1.0, 2.5, -1.0]) for _ in range(3)]), min_size=0, max_size=40),
       st.sampled_from([np.float32, np.float64]))
def test_coincident_points_match_unique(points, dtype):
    p = np.array(points, dtype).reshape(-1, 3)
    expect = p.shape[0] - np.unique(p, axis=0).shape[0] if p.shape[0] else 0
    assert coincident_points(p) == expect
