"""Invisible tets left out before the walk, and early ray termination: both against the full walk
and the slow reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import delaunay_mesh, grid_mesh, mesh_strategy
from naive_render import naive_render

from gatun_py.mesh import TetMesh
from gatun_py.raycast import Camera, StreamingRaycaster, render_mesh
from gatun_py.raycast._cull import visible_prefix, visible_tets
from gatun_py.raycast._walk import OPAQUE
from gatun_py.raycast.image import to_rgb8
from gatun_py.raycast.transfer import from_dict


def tf_above(cut: float, a: float = 0.3, unit: float = 3.0):
    """Transparent below ``cut`` (normalised), a ramp of opacity above it."""
    return from_dict({
        "color": [{"x": 0.0, "rgb": [0.1, 0.2, 1.0]}, {"x": 0.5, "rgb": [0.2, 1.0, 0.3]},
                  {"x": 1.0, "rgb": [1.0, 0.1, 0.0]}],
        "opacity": [{"x": 0.0, "a": 0.0}, {"x": cut, "a": 0.0}, {"x": min(1.0, cut + 0.1), "a": a}, {"x": 1.0, "a": a}],
        "unit_distance": unit,
    })


# a narrow bump of opacity, zero at both ends of the range: tets spanning it must stay
BUMP = from_dict({
    "color": [{"x": 0.0, "rgb": [1.0, 1.0, 1.0]}, {"x": 1.0, "rgb": [1.0, 0.5, 0.0]}],
    "opacity": [{"x": 0.0, "a": 0.0}, {"x": 0.49, "a": 0.0}, {"x": 0.5, "a": 0.6}, {"x": 0.51, "a": 0.0},
                {"x": 1.0, "a": 0.0}],
    "unit_distance": 1.0,
})

NOTHING = from_dict({"color": [{"x": 0.0, "rgb": [1.0, 1.0, 1.0]}, {"x": 1.0, "rgb": [1.0, 1.0, 1.0]}],
                     "opacity": [{"x": 0.0, "a": 0.0}, {"x": 1.0, "a": 0.0}]})


def diff8(a, b) -> int:
    return int(np.abs(to_rgb8(a).astype(int) - to_rgb8(b).astype(int)).max())


def fitted(mesh, camera):
    used = np.unique(mesh.boundary_faces())
    return camera.fit(mesh.points[used].min(axis=0), mesh.points[used].max(axis=0))


def test_visibility_is_over_the_whole_scalar_interval():
    """A tet whose four scalars all sit where the opacity is 0 still shows when the opacity rises
    between them (the bump at 0.5 lies inside [0.1, 0.9]); one wholly on a zero stretch does not."""
    tab, lo, inv = BUMP.table((0.0, 1.0))
    prefix = visible_prefix(tab[:, 3])
    dens = np.array([0.1, 0.9, 0.1, 0.9, 0.0, 0.2, 0.3, 0.45, 0.55, 0.6, 0.7, 1.0, 0.499, 0.499, 0.499, 0.499])
    tets = np.arange(16, dtype=np.int32).reshape(4, 4)
    out = np.empty(4, np.uint8)
    visible_tets(tets, dens, prefix, lo, inv, out)
    assert out.tolist() == [1, 0, 0, 1]
    assert tab[:, 3][np.searchsorted(np.linspace(0, 1, len(tab)), 0.1):].max() > 0
    # every entry the plain test would keep, the kernel keeps (and the reverse)
    rng = np.random.default_rng(0)
    d = rng.random(4000)
    t = rng.integers(0, 4000, (1000, 4)).astype(np.int32)
    out = np.empty(1000, np.uint8)
    visible_tets(t, d, prefix, lo, inv, out)
    n = len(tab)
    i0 = np.clip(np.floor((d[t].min(1) - lo) * inv).astype(int) - 1, 0, n - 1)
    i1 = np.clip(np.floor((d[t].max(1) - lo) * inv).astype(int) + 2, 0, n - 1)
    want = [np.any(tab[a: b + 1, 3] > 0) for a, b in zip(i0, i1)]
    assert out.astype(bool).tolist() == want


@pytest.mark.parametrize("mode", ["volume", "face"])
@pytest.mark.parametrize("make", [lambda: grid_mesh(6, 5, 5, jitter=0.2, seed=3), lambda: delaunay_mesh(120, 2)])
@pytest.mark.parametrize("tf", [tf_above(0.75), tf_above(0.4, a=0.9, unit=0.5), BUMP])
def test_culled_render_equals_full_walk_and_reference(make, tf, mode):
    mesh = make()
    cam = Camera(20, 16, azimuth=25.0, elevation=15.0)
    culled = render_mesh(mesh, cam, tf, mode=mode)
    full = render_mesh(mesh, cam, tf, mode=mode, cull=False)
    assert culled.stats["tets_culled"] > 0 and full.stats["tets_culled"] == 0
    assert culled.stats["tets_rendered"] == full.stats["tets_rendered"] == mesh.n_tets
    assert culled.stats["rays_unfinished"] == full.stats["rays_unfinished"] == 0
    np.testing.assert_allclose(culled.image, full.image, atol=1e-5, rtol=0)
    ref = naive_render(mesh, fitted(mesh, cam), tf, mode=mode)
    np.testing.assert_allclose(culled.image, ref, atol=1e-5, rtol=0)
    np.testing.assert_allclose(naive_render(mesh, fitted(mesh, cam), tf, mode=mode, cull=True), ref, atol=1e-12)
    assert culled.stats["steps"] < full.stats["steps"]


@settings(max_examples=12, deadline=None)
@given(mesh=mesh_strategy(), seed=st.integers(0, 1000), az=st.floats(-180, 180), el=st.floats(-80, 80),
       cut=st.floats(0.1, 0.9), n_batches=st.integers(1, 7))
def test_culled_streaming_equals_in_memory_and_unculled(mesh, seed, az, el, cut, n_batches):
    cam = Camera(12, 10, azimuth=az, elevation=el)
    tf = tf_above(cut)
    whole = render_mesh(mesh, cam, tf, cull=False)
    rc = StreamingRaycaster(cam, tf, scalar_range=mesh.scalar_range)
    rc.add_vertices(mesh.points, mesh.density)
    rc.set_boundary(mesh.boundary_faces())
    for chunk in np.array_split(mesh.tets[np.random.default_rng(seed).permutation(mesh.n_tets)],
                                min(n_batches, mesh.n_tets)):
        rc.add_tets(chunk)
    streamed = rc.finish()
    assert streamed.stats["rays_unfinished"] == 0
    np.testing.assert_allclose(streamed.image, whole.image, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(streamed.image, render_mesh(mesh, cam, tf).image)


def test_thousands_of_visible_pieces():
    """A field of many bumps, shown only near their peaks: the visible part falls apart into
    thousands of pieces (rays enter and leave it many times); the image is the full walk's."""
    n = 37
    mesh = grid_mesh(n, n, n)
    x = mesh.points.astype(np.float64) / (n - 1)
    k = 13.0
    dens = np.sin(np.pi * k * x[:, 0]) * np.sin(np.pi * k * x[:, 1]) * np.sin(np.pi * k * x[:, 2])
    mesh = TetMesh(mesh.points, dens.astype(np.float32), mesh.tets)
    tf = tf_above(0.8, a=0.5, unit=0.5)
    # the visible tets' pieces (face-connected components)
    tab, lo, inv = tf.table(mesh.scalar_range)
    keep = np.empty(mesh.n_tets, np.uint8)
    visible_tets(np.ascontiguousarray(mesh.tets, np.int32), mesh.density.astype(np.float64),
                 visible_prefix(tab[:, 3]), lo, inv, keep)
    assert _pieces(mesh.tets[keep.astype(bool)]) > 1000
    cam = Camera(96, 96, azimuth=20.0, elevation=30.0)
    culled = render_mesh(mesh, cam, tf)
    full = render_mesh(mesh, cam, tf, cull=False)
    assert culled.stats["tets_culled"] > 0.8 * mesh.n_tets
    assert culled.stats["segments"] > 3 * culled.stats["rays_hit"]  # rays cross many pieces
    assert culled.stats["rays_unfinished"] == 0
    assert diff8(culled.image, full.image) <= 1
    np.testing.assert_allclose(culled.image, full.image, atol=1e-5, rtol=0)


def _pieces(tets) -> int:
    """Face-connected components of ``tets`` (union-find over shared sorted faces)."""
    faces = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]], axis=2).reshape(-1, 3)
    owner = np.repeat(np.arange(len(tets)), 4)
    order = np.lexsort(faces.T[::-1])
    f, o = faces[order], owner[order]
    same = np.all(f[1:] == f[:-1], axis=1)
    parent = np.arange(len(tets))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in zip(o[:-1][same], o[1:][same]):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    return len({find(a) for a in range(len(tets))})


def test_transparent_everywhere_gives_black_image_and_one_note():
    mesh = delaunay_mesh(40, 1)
    res = render_mesh(mesh, Camera(16, 16), NOTHING)
    assert not res.image.any()
    assert res.stats["tets_culled"] == mesh.n_tets and res.stats["steps"] == 0
    assert len(res.stats["notes"]) == 1 and "transparent" in res.stats["notes"][0]


def test_api_render_says_the_image_is_black(tmp_path):
    import gatun_py

    lines = []
    frame = gatun_py.render(delaunay_mesh(40, 1), size=16, tf=NOTHING, log=lines.append)
    assert not frame.rgb.any()
    assert sum("transparent over the whole scalar range" in line for line in lines) == 1
    assert sum("black" in line for line in lines) == 1  # one line, not a second "no ray hits"


# -- early ray termination --------------------------------------------------------------------------
OPAQUE_TF = from_dict({
    "color": [{"x": 0.0, "rgb": [0.1, 0.2, 1.0]}, {"x": 1.0, "rgb": [1.0, 0.1, 0.0]}],
    "opacity": [{"x": 0.0, "a": 0.4}, {"x": 1.0, "a": 0.9}],
    "unit_distance": 0.3,
})


@pytest.mark.parametrize("mode", ["volume", "face"])
def test_termination_matches_reference_and_bounds_the_change(mode):
    mesh = grid_mesh(6, 6, 5, jitter=0.2, seed=1)
    cam = Camera(20, 16, azimuth=30.0, elevation=20.0)
    ours = render_mesh(mesh, cam, OPAQUE_TF, mode=mode)
    full = render_mesh(mesh, cam, OPAQUE_TF, mode=mode, terminate=False)
    ref = naive_render(mesh, fitted(mesh, cam), OPAQUE_TF, mode=mode)
    ref_full = naive_render(mesh, fitted(mesh, cam), OPAQUE_TF, mode=mode, terminate=False)
    np.testing.assert_allclose(ours.image, ref, atol=1e-5, rtol=0)
    np.testing.assert_allclose(full.image, ref_full, atol=1e-5, rtol=0)
    assert ours.stats["steps"] < 0.8 * full.stats["steps"]
    d = np.abs(ours.image - full.image).max()
    assert 0 < d <= 1.0 - OPAQUE + 1e-6  # what lies behind weighs at most 1 - OPAQUE
    assert ours.stats["early_termination"] == OPAQUE and full.stats["early_termination"] is None


@settings(max_examples=12, deadline=None)
@given(mesh=mesh_strategy(), seed=st.integers(0, 1000), az=st.floats(-180, 180), el=st.floats(-80, 80),
       mode=st.sampled_from(["volume", "face"]), n_batches=st.integers(1, 9))
def test_terminated_streaming_equals_in_memory_any_order(mesh, seed, az, el, mode, n_batches):
    """Rays that turn opaque while streamed (a back subsegment met the front, or a later segment
    stopped first) are walked again from the front: the image is the in-memory one, bit for bit."""
    cam = Camera(12, 10, azimuth=az, elevation=el)
    whole = render_mesh(mesh, cam, OPAQUE_TF, mode=mode)
    rc = StreamingRaycaster(cam, OPAQUE_TF, mode=mode, scalar_range=mesh.scalar_range)
    rc.add_vertices(mesh.points, mesh.density)
    rc.set_boundary(mesh.boundary_faces())
    for chunk in np.array_split(mesh.tets[np.random.default_rng(seed).permutation(mesh.n_tets)],
                                min(n_batches, mesh.n_tets)):
        rc.add_tets(chunk)
    streamed = rc.finish()
    assert streamed.stats["rays_unfinished"] == whole.stats["rays_unfinished"] == 0
    np.testing.assert_array_equal(streamed.image, whole.image)


@pytest.mark.parametrize("name", ["bluntfin", "combustion"])
def test_culling_real_grids_equals_the_full_walk(name):
    """Curvilinear grids that fold over themselves (Combustion) and collapse a grid line
    (Blunt-fin): the visible part's boundary meets folds and flat tets; the image is the full walk's."""
    from conftest import load_sample
    from samples import SAMPLES

    mesh, _ = load_sample(name)
    preset = SAMPLES[name][2]
    for tf in (preset, tf_above(0.6, a=0.4, unit=2.0)):
        for az, el in ((30, 20), (200, -45)):
            cam = Camera(96, 96, az, el)
            culled = render_mesh(mesh, cam, tf)
            full = render_mesh(mesh, cam, tf, cull=False)
            assert culled.stats["tets_culled"] > 0
            assert culled.stats["rays_unfinished"] == full.stats["rays_unfinished"] == 0
            assert culled.stats["nan_pixels"] == 0
            assert diff8(culled.image, full.image) <= 1, (tf, az, el)
            assert np.abs(culled.image - full.image).max() < 1e-4


def test_culled_stream_snapshots_claim_nothing_before_the_end():
    """Culling walks once every tet has come: a snapshot before that is blank and calls no pixel final."""
    mesh = delaunay_mesh(60, 3)
    rc = StreamingRaycaster(Camera(12, 10), tf_above(0.5), scalar_range=mesh.scalar_range)
    rc.add_vertices(mesh.points, mesh.density)
    rc.set_boundary(mesh.boundary_faces())
    rc.add_tets(mesh.tets[: mesh.n_tets // 2])
    image, finished = rc.snapshot()
    assert not image.any() and not finished.any()
    rc.add_tets(mesh.tets[mesh.n_tets // 2:])
    assert rc.finish().image.any()
