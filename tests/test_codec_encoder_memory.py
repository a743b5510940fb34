"""The encoder's lean face pairing and int32 tables: same neighbours as a plain dict of faces,
the hub-vertex and non-conforming branches, the range checks that refuse ids before any
narrowing to int32, and the render step taken from the encoder's boundary."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

from gatun_py.codec import _cutborder_kernels as K
from gatun_py.codec import write_tetc
from gatun_py.codec.cutborder import encode_connectivity
from gatun_py.codec.tetcfile import TetcReader
from gatun_py.errors import MeshError
from gatun_py.mesh import default_step
from gatun_py.mesh.validate import validate_tets
from meshgen import delaunay_mesh, mesh_strategy
from naive_simplify import face_neighbours


def _neighbours(tets):
    nbr = np.empty((len(tets), 4), np.int32)
    bad = K.tet_neighbours(np.ascontiguousarray(tets, np.int32), nbr)
    return nbr, bad


@settings(max_examples=40, deadline=None)
@given(mesh_strategy())
def test_tet_neighbours_match_a_dict_of_faces(mesh):
    nbr, bad = _neighbours(mesh.tets)
    assert bad == 0
    assert nbr.tolist() == face_neighbours(mesh.tets.tolist())


def test_tet_neighbours_hub_vertex_takes_the_sorting_branch():
    # a fan of tets around vertex 0 (the smallest id of every face through it): one bucket far
    # wider than the insertion sort handles
    k = 4 * K._INSERTION_SORT_MAX
    ring = np.arange(1, k + 1)
    tets = np.stack([np.zeros(k, np.int64), ring, np.roll(ring, -1), np.full(k, k + 1)], axis=1)
    tets = tets[np.random.default_rng(3).permutation(k)]
    nbr, bad = _neighbours(tets)
    assert bad == 0
    assert nbr.tolist() == face_neighbours(tets.tolist())
    assert (nbr >= 0).sum() == 2 * k  # every tet meets its two ring neighbours


def test_tet_neighbours_counts_a_face_of_three_tets():
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]])
    _, bad = _neighbours(tets)
    assert bad == 1
    with pytest.raises(MeshError, match="more than two tets"):
        encode_connectivity(6, tets)


@pytest.mark.parametrize("bad_id", [-1, 7, 2**32 + 1])
def test_encode_connectivity_refuses_ids_out_of_range_before_narrowing(bad_id):
    # 2**32 + 1 would wrap to 1 (a valid id) in int32: it must be refused, not coded as vertex 1
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, bad_id]], np.int64)
    with pytest.raises(MeshError, match=r"ids must lie in 0\.\.4"):
        encode_connectivity(5, tets)


def test_validate_refuses_ids_that_int32_would_wrap():
    pts = np.random.default_rng(0).random((5, 3)).astype(np.float32)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 2**32 + 4]], np.int64)
    with pytest.raises(MeshError, match=f"refers to vertex {2**32 + 4}"):
        validate_tets(pts, np.zeros(5, np.float32), tets)


def test_validated_tets_are_int32_and_not_the_callers_array():
    mesh = delaunay_mesh(40, 1)
    tets = mesh.tets.astype(np.int64)[:, [0, 1, 3, 2]]  # all negative: validation re-orients them
    before = tets.copy()
    out, report = validate_tets(mesh.points, mesh.density, tets)
    assert out.tets.dtype == np.int32 and report.reoriented_tets == len(tets)
    assert np.array_equal(tets, before)  # the caller's array is left alone


@settings(max_examples=15, deadline=None)
@given(mesh_strategy())
def test_render_step_from_the_encoder_boundary_equals_the_mesh_one(tmp_path_factory, mesh):
    path = tmp_path_factory.mktemp("step") / "m.tetc"
    write_tetc(path, mesh)
    assert TetcReader(path).meta["render_step"] == float(default_step(mesh.points32, mesh.boundary_faces()))


@settings(max_examples=40, deadline=None)
@given(mesh_strategy())
def test_packed_boundary_faces_equal_the_triples_reference(mesh):
    from gatun_py.mesh.model import _boundary_faces_packed, _boundary_faces_triples

    got = _boundary_faces_packed(mesh.tets)
    assert got.dtype == np.int32
    assert np.array_equal(got, _boundary_faces_triples(mesh.tets))


def test_boundary_faces_of_ids_beyond_the_packed_keys_take_the_triples_path():
    from gatun_py.mesh.model import _KEY_BITS, boundary_faces

    mesh = delaunay_mesh(30, 2)
    shifted = mesh.tets.astype(np.int64) + (1 << _KEY_BITS)  # same faces, ids too wide to pack
    assert np.array_equal(boundary_faces(shifted) - (1 << _KEY_BITS), boundary_faces(mesh.tets))
