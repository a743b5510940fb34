"""The boundary hit kernel (rays -> boundary crossings) against the every-pixel reference."""

from __future__ import annotations

import numpy as np
import pytest
from meshgen import AWKWARD, grid_mesh
from naive_render import naive_boundary_hits

from gatun_py.raycast import Camera, FittedCamera
from gatun_py.raycast import _boundary as K
from gatun_py.raycast.caster import _ray_grid


def kernel_hits(mesh, fitted):
    """(face, ray, entering) of ``_boundary_hits`` (count pass, then fill pass, as find_segments)."""
    P = mesh.points.astype(np.float64) - np.asarray(fitted.position, dtype=np.float64)
    dens = mesh.density.astype(np.float64)
    faces = np.ascontiguousarray(mesh.boundary_faces(), dtype=np.int64)
    dirs = fitted.ray_directions()
    grid = _ray_grid(fitted)
    counts = np.zeros(len(faces), dtype=np.int64)
    none_i, none_f, none_b = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.bool_)
    K._boundary_hits(P, dens, dirs, fitted.width, fitted.height, faces, *grid, counts, counts, none_i, none_f,
                     none_i, none_b, False)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    m = int(offsets[-1])
    ray, t, face, enter = np.empty(m, np.int64), np.empty(m), np.empty(m, np.int64), np.empty(m, np.bool_)
    K._boundary_hits(P, dens, dirs, fitted.width, fitted.height, faces, *grid, counts, offsets, ray, t, face, enter,
                     True)
    assert np.array_equal(np.repeat(np.arange(len(faces)), counts), face)  # grouped by face, as counted
    got = set(zip(face.tolist(), ray.tolist(), enter.tolist()))
    assert len(got) == m  # no pixel twice
    return got


def fit(mesh, camera):
    used = np.unique(mesh.boundary_faces())
    return camera.fit(mesh.points[used].min(axis=0), mesh.points[used].max(axis=0))


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_boundary_hits_match_every_pixel_reference(name):
    """Each face tests only the pixels of its rows' spans: none of the skipped pixels is a hit."""
    mesh = AWKWARD[name]()
    for az, el, w, h in [(30.0, 20.0, 21, 17), (0.0, 0.0, 16, 16), (90.0, 0.0, 9, 9), (-120.0, 60.0, 24, 13)]:
        cam = fit(mesh, Camera(w, h, az, el))
        want = naive_boundary_hits(mesh, cam)
        assert kernel_hits(mesh, cam) == want
        assert want or name == "unreferenced"  # the rays do hit the boundary


def test_boundary_hits_rays_exactly_through_vertices_and_edges():
    """Axis-aligned grids seen along their axes: pixel rays run exactly through boundary
    vertices and edges and along faces (every edge side exactly zero on some rays)."""
    mesh = grid_mesh(4, 4, 3)
    for target in [(1.0, 1.0, 1.0), (1.5, 1.0, 1.0), (1.0, 2.0, 0.0)]:
        target = np.asarray(target)
        for offset in ([0.0, 0.0, 10.0], [10.0, 0.0, 0.0], [0.0, -7.0, 0.0]):
            for size in (1, 5, 8):
                up = np.array([0.0, 0.0, 1.0]) if offset[2] == 0 else np.array([0.0, 1.0, 0.0])
                cam = FittedCamera(size, size, target + np.asarray(offset), target, up, 30.0)
                assert kernel_hits(mesh, cam) == naive_boundary_hits(mesh, cam)


def test_boundary_hits_real_sample(small_sample):
    cam = fit(small_sample, Camera(40, 32, 50.0, 30.0))
    want = naive_boundary_hits(small_sample, cam)
    assert len(want) > 500
    assert kernel_hits(small_sample, cam) == want
