"""The TetMesh model: volumes, boundary, ranges, repr."""

import numpy as np
import pytest
from hypothesis import given, settings

from gatun_py.mesh import TetMesh
from gatun_py.mesh.model import TET_FACES
from meshgen import AWKWARD, grid_mesh, mesh_strategy, single_tet


def _edges_of_faces(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return e


def test_repr_and_sizes():
    m = single_tet()
    assert repr(m) == "TetMesh(points=4, tets=1, scalar='density' in [0, 3])"
    assert (m.n_points, m.n_tets) == (4, 1)


def test_arrays_are_read_only():
    m = single_tet()
    with pytest.raises(ValueError):
        m.points[0, 0] = 1.0
    with pytest.raises(ValueError):
        m.tets[0, 0] = 1


def test_faces_point_outward():
    m = single_tet()
    p = m.points.astype(np.float64)
    centre = p.mean(axis=0)
    for f in m.boundary_faces():
        a, b, c = p[f]
        n = np.cross(b - a, c - a)
        assert np.dot(n, a - centre) > 0


def test_tet_faces_cover_each_pair_of_vertices_twice():
    # Every edge of a tet lies on exactly two of its faces, traversed in opposite directions.
    e = _edges_of_faces(TET_FACES)
    assert len({tuple(x) for x in e}) == 12
    assert {tuple(x) for x in e} == {tuple(x[::-1]) for x in e}


@settings(max_examples=60, deadline=None)
@given(mesh_strategy())
def test_boundary_is_closed_and_consistently_wound(mesh):
    """Every directed boundary edge is matched by its reverse: a closed, consistently oriented surface."""
    f = mesh.boundary_faces()
    e = _edges_of_faces(f)
    fwd = {}
    for a, b in e:
        fwd[(a, b)] = fwd.get((a, b), 0) + 1
    for (a, b), k in fwd.items():
        assert fwd.get((b, a), 0) == k


@settings(max_examples=60, deadline=None)
@given(mesh_strategy())
def test_divergence_theorem_volume(mesh):
    """Volume from the boundary (divergence theorem) equals the sum of tet volumes."""
    p = mesh.points.astype(np.float64)
    f = mesh.boundary_faces()
    a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    v_surface = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    v_tets = mesh.signed_volumes().sum()
    assert v_surface == pytest.approx(v_tets, rel=1e-6, abs=1e-9)
    assert (mesh.signed_volumes() >= 0).all()


def test_bbox_and_range():
    m = grid_mesh(3, 4, 5)
    lo, hi = m.bbox
    assert lo.tolist() == [0, 0, 0] and hi.tolist() == [2, 3, 4]
    assert m.scalar_range == (float(m.density.min()), float(m.density.max()))


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_awkward_meshes_are_valid(name):
    m = AWKWARD[name]()
    assert isinstance(m, TetMesh) and m.n_tets >= 1
