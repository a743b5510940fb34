"""A round-trip checker that compares cell blocks, not just tets: every block's type, its cells'
vertex order, point arrays, cell arrays, dtypes, field data and sets, bit for bit.

A decoded file lists its points in decode order and each volume block's cells in traversal order;
``vertex_order`` (decoded point -> original point) undoes the first, and the cells of a block are
matched to the originals by their ordered vertex tuples (a tuple that appears once matches one
original cell; the vertex order inside a cell must then be the original's exactly)."""

from __future__ import annotations

import numpy as np

from gatun_py.codec.cutborder import encode_connectivity
from gatun_py.mesh.cells import VOLUME_CELLS


def same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    return np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()


def vertex_order_of(tet_mesh) -> np.ndarray:
    return encode_connectivity(tet_mesh.n_points, tet_mesh.tets).vertex_order


def _native(a):
    a = np.asarray(a)
    return a.astype(a.dtype.newbyteorder("=")) if a.dtype.kind in "fiu" else a


def check_round_trip(orig, dec, vo, *, point_data=True) -> None:
    """Assert that meshio mesh ``dec`` (decoded) is ``orig`` up to the point order ``vo`` (decoded
    -> original) and the order of the cells inside each volume block."""
    assert same_bits(np.asarray(dec.points), _native(orig.points)[vo]) or same_bits(
        np.asarray(dec.points), _native(orig.points).astype(np.asarray(dec.points).dtype)[vo])
    if point_data:
        assert set(dec.point_data) == set(orig.point_data), (set(dec.point_data), set(orig.point_data))
        for k, v in orig.point_data.items():
            exp = _native(v)
            got = np.asarray(dec.point_data[k])
            if exp.dtype == bool:
                exp = exp.astype(np.uint8)
            if exp.ndim == 2 and exp.shape[1] == 1:
                exp = exp.reshape(-1)
            assert same_bits(got, exp[vo]), k
    assert [c.type for c in dec.cells] == [c.type for c in orig.cells]
    perms = []
    for co, cd in zip(orig.cells, dec.cells):
        a = np.asarray(co.data).astype(np.int64)
        b = vo[np.asarray(cd.data).astype(np.int64)]
        assert a.shape == b.shape, (co.type, a.shape, b.shape)
        if co.type not in VOLUME_CELLS:
            assert np.array_equal(a, b), co.type
            perms.append(np.arange(len(a)))
            continue
        oa, ob = np.lexsort(a.T[::-1]), np.lexsort(b.T[::-1])
        assert np.array_equal(a[oa], b[ob]), f"{co.type}: cells or their vertex order differ"
        p = np.empty(len(a), np.int64)
        p[ob] = oa  # decoded cell i is original cell p[i]
        perms.append(p)
    assert set(dec.cell_data) == set(orig.cell_data)
    for k, per in orig.cell_data.items():
        for bi, (v, p) in enumerate(zip(per, perms)):
            got = np.asarray(dec.cell_data[k][bi])
            exp = _native(v)[p]
            assert same_bits(got, exp), (k, bi, got.dtype, exp.dtype, got.shape, exp.shape)
    assert set(dec.field_data) == set(orig.field_data or {})
    for k, v in (orig.field_data or {}).items():
        assert same_bits(dec.field_data[k], np.asarray(v)), k
    assert set(dec.point_sets) == set(orig.point_sets or {})
    for k, v in (orig.point_sets or {}).items():
        got, v = vo[np.asarray(dec.point_sets[k])], np.asarray(v)
        if np.all(v[1:] > v[:-1]):  # a set (increasing ids): the same points, increasing in the decoded ids
            assert np.all(np.diff(np.asarray(dec.point_sets[k]).astype(np.int64)) > 0), k
            got = np.sort(got)
        assert np.array_equal(got, v) and np.asarray(dec.point_sets[k]).dtype == v.dtype, k
    assert set(dec.cell_sets) == set(orig.cell_sets or {})
    for k, per in (orig.cell_sets or {}).items():
        for bi, (ids, p) in enumerate(zip(per, perms)):
            got = dec.cell_sets[k][bi]
            if ids is None:
                assert got is None
                continue
            if k.startswith("gmsh:"):  # entity tags, not cell ids
                assert same_bits(np.asarray(got), np.asarray(ids)), (k, bi)
                continue
            ids, back = np.asarray(ids), p[np.asarray(got, np.int64)]
            if np.all(ids[1:] > ids[:-1]):
                assert np.all(np.diff(np.asarray(got).astype(np.int64)) > 0), (k, bi)
                back = np.sort(back)
            assert np.array_equal(back, ids), (k, bi)
            assert np.asarray(got).dtype == np.asarray(ids).dtype, (k, bi)
