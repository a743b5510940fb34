"""The ray caster against the slow reference, streaming against in-memory, and robustness."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshgen import AWKWARD, delaunay_mesh, grid_mesh, mesh_strategy
from naive_render import naive_render

from gatun_py.mesh import TetMesh
from gatun_py.raycast import Camera, FittedCamera, StreamingRaycaster, render_mesh
from gatun_py.raycast.transfer import from_dict

# Semi-transparent everywhere, so that every tet along a ray shows in the pixel.
TF = from_dict({
    "color": [{"x": 0.0, "rgb": [0.1, 0.2, 1.0]}, {"x": 0.5, "rgb": [0.2, 1.0, 0.3]}, {"x": 1.0, "rgb": [1.0, 0.1, 0.0]}],
    "opacity": [{"x": 0.0, "a": 0.05}, {"x": 0.6, "a": 0.3}, {"x": 1.0, "a": 0.15}],
    "unit_distance": 3.0,
})


def fitted(mesh, camera):
    used = np.unique(mesh.boundary_faces())
    return camera.fit(mesh.points[used].min(axis=0), mesh.points[used].max(axis=0))


def seam_mesh() -> TetMesh:
    """Two grid blocks touching along a plane with duplicated (coincident) vertices."""
    a = grid_mesh(3, 3, 3)
    b = grid_mesh(3, 3, 3)
    pts = np.concatenate([a.points, b.points + np.float32([2.0, 0.0, 0.0])])
    return TetMesh(pts, np.concatenate([a.density, b.density + 0.5]), np.concatenate([a.tets, b.tets + a.n_points]))


MESHES = dict(AWKWARD, seam=seam_mesh)


def stream(mesh, camera, mode, order_seed=0, n_batches=5, tf=TF, lean=True):
    return stream_rc(mesh, camera, mode, order_seed, n_batches, tf, lean)[1]


def stream_rc(mesh, camera, mode, order_seed=0, n_batches=5, tf=TF, lean=True):
    """(the StreamingRaycaster, its result) for ``mesh`` fed in pieces, tets in a random order
    (lean by default: the streaming tests hold for both ways of keeping the face table)."""
    rc = StreamingRaycaster(camera, tf, mode=mode, scalar_range=mesh.scalar_range, lean=lean)
    rng = np.random.default_rng(order_seed)
    # vertices arrive in pieces too; the whole boundary comes before the first tet
    cut = mesh.n_points // 2
    rc.add_vertices(mesh.points[:cut], mesh.density[:cut])
    rc.add_vertices(mesh.points[cut:], mesh.density[cut:])
    faces = mesh.boundary_faces()
    rc.set_boundary(faces[: len(faces) // 3])
    rc.set_boundary(faces[len(faces) // 3:])
    tets = mesh.tets[rng.permutation(mesh.n_tets)]
    for chunk in np.array_split(tets, min(n_batches, max(1, len(tets)))):
        rc.add_tets(chunk)
    return rc, rc.finish()


@pytest.mark.parametrize("mode", ["volume", "face"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_matches_reference_and_streaming(name, mode):
    mesh = MESHES[name]()
    cam = Camera(18, 14, azimuth=25.0, elevation=15.0)
    ours = render_mesh(mesh, cam, TF, mode=mode)
    ref = naive_render(mesh, fitted(mesh, cam), TF, mode=mode)
    assert ours.image.shape == (14, 18, 4)
    assert ours.stats["rays_unfinished"] == 0
    assert ours.stats["nan_pixels"] == 0
    assert 0.01 < ref[..., 3].max() < 0.999  # semi-transparent: every tet counts
    np.testing.assert_allclose(ours.image, ref, atol=1e-5, rtol=0)
    streamed = stream(mesh, cam, mode, order_seed=1)
    assert streamed.stats["rays_unfinished"] == 0
    np.testing.assert_allclose(streamed.image, ours.image, atol=1e-5, rtol=0)
    assert streamed.stats["samples"] == ours.stats["samples"]


def test_several_segments_per_ray():
    mesh = MESHES["l_shaped"]()
    centre = np.array([2.5, 2.5, 1.0])
    cam = FittedCamera(24, 24, centre + 20 * np.array([0.7071, -0.7071, 0.0]), centre, np.array([0.0, 0.0, 1.0]), 30.0)
    res = render_mesh(mesh, cam, TF)
    assert res.stats["segments"] > res.stats["rays_hit"]  # rays across the notch leave and re-enter
    np.testing.assert_allclose(res.image, naive_render(mesh, cam, TF), atol=1e-5, rtol=0)
    np.testing.assert_allclose(stream(mesh, cam, "volume", 4).image, res.image, atol=1e-5, rtol=0)
    mesh = MESHES["cavity"]()
    res = render_mesh(mesh, Camera(24, 24), TF)
    assert res.stats["segments"] > res.stats["rays_hit"]


@pytest.mark.parametrize("mode", ["volume", "face"])
@pytest.mark.parametrize("target", [(1.0, 1.0, 1.0), (1.0, 1.0, 0.5), (1.5, 1.0, 1.0), (1.0, 2.0, 0.0)])
def test_rays_exactly_through_vertices_and_edges(target, mode):
    """A 1x1 image looks down its exact centre: along a grid line (through every vertex of the
    column, along edges parallel to the ray) or through edge midpoints: exact zero sides."""
    mesh = grid_mesh(4, 4, 3)
    target = np.asarray(target)
    for offset in ([0.0, 0.0, 10.0], [10.0, 0.0, 0.0], [0.0, -7.0, 0.0]):
        cam = FittedCamera(1, 1, target + np.asarray(offset), target, np.array([0.0, 0.0, 1.0]) if offset[2] == 0
                           else np.array([0.0, 1.0, 0.0]), 30.0)
        ours = render_mesh(mesh, cam, TF, mode=mode)
        ref = naive_render(mesh, cam, TF, mode=mode)
        assert ours.stats["rays_unfinished"] == 0
        assert ref[0, 0, 3] > 0.05
        np.testing.assert_allclose(ours.image, ref, atol=1e-5, rtol=0)
        np.testing.assert_allclose(stream(mesh, cam, mode, 3).image, ours.image, atol=1e-5, rtol=0)


@settings(max_examples=15, deadline=None)
@given(mesh=mesh_strategy(), seed=st.integers(0, 1000), az=st.floats(-180, 180), el=st.floats(-80, 80),
       mode=st.sampled_from(["volume", "face"]), n_batches=st.integers(1, 9))
def test_streaming_equals_in_memory_any_order(mesh, seed, az, el, mode, n_batches):
    cam = Camera(12, 10, azimuth=az, elevation=el)
    whole = render_mesh(mesh, cam, TF, mode=mode)
    streamed = stream(mesh, cam, mode, order_seed=seed, n_batches=n_batches)
    assert whole.stats["rays_unfinished"] == 0 and streamed.stats["rays_unfinished"] == 0
    np.testing.assert_allclose(streamed.image, whole.image, atol=1e-5, rtol=0)


def test_image_independent_of_thread_count():
    mesh = delaunay_mesh(80, 5)
    cam = Camera(40, 30, azimuth=10.0)
    images = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        try:
            images.append(stream(mesh, cam, "volume", order_seed=2).image)
            images.append(render_mesh(mesh, cam, TF).image)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(images[0], images[2])
    assert np.array_equal(images[1], images[3])


def test_real_sample_post_several_views(small_sample):
    mesh = small_sample
    for az, el in [(0, 0), (90, 30), (200, -60)]:
        res = render_mesh(mesh, Camera(48, 40, azimuth=az, elevation=el), "post")
        assert res.stats["rays_unfinished"] == 0
        assert res.stats["boundary_anomalies"] == 0
        assert res.stats["nan_pixels"] == 0
        assert res.stats["rays_hit"] > 0


def test_mesh_out_of_view_gives_black_image():
    mesh = delaunay_mesh(20)
    cam = FittedCamera(8, 8, np.array([5.0, 0.5, 10.0]), np.array([30.0, 0.5, 10.0]), np.array([0.0, 1.0, 0.0]), 10.0)
    res = render_mesh(mesh, cam, TF)
    assert res.stats["rays_hit"] == 0
    assert not res.image.any()


def test_bad_input():
    from gatun_py.errors import MeshError, OptionError

    mesh = delaunay_mesh(20)
    with pytest.raises(OptionError):
        StreamingRaycaster(Camera(8, 8), TF, mode="nope")
    with pytest.raises(OptionError):
        StreamingRaycaster(Camera(8, 8), TF, step=-1.0)
    rc = StreamingRaycaster(Camera(8, 8), TF)
    rc.add_vertices(mesh.points, mesh.density)
    with pytest.raises(MeshError):
        rc.set_boundary([[0, 1, mesh.n_points]])
    rc.set_boundary(mesh.boundary_faces())
    with pytest.raises(MeshError):
        rc.add_tets([[0, 1, 2, -1]])
    with pytest.raises(MeshError):
        rc.add_vertices([[np.nan, 0, 0]], [0.0])
    # the camera inside the mesh: rays would start inside
    cam = FittedCamera(8, 8, np.array([0.5, 0.5, 0.5]), np.array([0.5, 0.5, 0.0]), np.array([0.0, 1.0, 0.0]), 30.0)
    with pytest.raises(OptionError):
        render_mesh(mesh, cam, TF)


# -- lean streaming: faces freed once no ray needs them --------------------------------------------
def _crossings(mesh, cam):
    from gatun_py.raycast import _facetable as K

    fitted_cam = fitted(mesh, cam)
    P = mesh.points.astype(np.float64) - fitted_cam.position
    fwd, right, up = fitted_cam.basis()
    out = np.empty((mesh.n_tets, 4), dtype=np.int32)
    fold_mark = np.zeros(mesh.n_points, dtype=np.uint8)
    K.count_crossings(np.ascontiguousarray(mesh.tets), P, *fitted_cam.ray_offsets(), fitted_cam.width,
                      fitted_cam.height, fwd, right, up, float(np.tan(np.radians(fitted_cam.view_angle) / 2)),
                      np.zeros(0, dtype=np.uint8), fold_mark, out)
    return out, fitted_cam, fold_mark


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_count_crossings_matches_reference(seed):
    from naive_render import naive_face_crossings

    mesh = delaunay_mesh(60, seed)
    cam = Camera(23, 17, azimuth=37.0 * seed + 11.0, elevation=-25.0 + 20 * seed)
    got, fitted_cam, fold_mark = _crossings(mesh, cam)
    want = naive_face_crossings(mesh, fitted_cam)
    assert want.sum() > 100  # the rays do cross faces
    np.testing.assert_array_equal(got, want)
    assert not fold_mark.any()  # no flat tets


def test_count_crossings_keeps_flat_tets():
    mesh = AWKWARD["degenerate_grid"]()
    got, _, fold_mark = _crossings(mesh, Camera(16, 16, azimuth=20.0))
    flat = np.abs(mesh.signed_volumes()) == 0
    assert flat.any()
    assert np.all(got[flat] >= 1)  # never freed: the walk crosses flat tets by its fallback
    assert np.array_equal(np.flatnonzero(fold_mark), np.unique(mesh.tets[flat]))  # nor their surroundings


@pytest.mark.parametrize("lean", [True, False])
def test_lean_streaming_equals_in_memory(lean):
    mesh = delaunay_mesh(300, 7)
    cam = Camera(48, 40, azimuth=25.0, elevation=15.0)
    whole = render_mesh(mesh, cam, TF)
    res = stream(mesh, cam, "volume", order_seed=3, n_batches=40, lean=lean)
    assert res.stats["lean"] is lean and res.stats["rays_unfinished"] == 0
    assert np.array_equal(res.image, whole.image)


def test_lean_frees_every_face_of_a_clean_mesh():
    """Every counted crossing is walked exactly once: with no flat tets and no rays grazing an
    edge, all the counters end at zero."""
    mesh = delaunay_mesh(400, 11)
    assert np.all(np.abs(mesh.signed_volumes()) > 1e-9)
    cam = Camera(40, 40, azimuth=33.0, elevation=21.0)
    rc, res = stream_rc(mesh, cam, "volume", order_seed=5, n_batches=25, lean=True)
    assert res.stats["rays_unfinished"] == 0 and res.stats["rays_hit"] > 500
    from gatun_py.raycast._facetable import FT_A, FT_COUNT, FT_TABLE

    table = rc._ft[FT_TABLE]
    counters = table[table[:, FT_A] >= 0, FT_COUNT]
    assert np.all(counters == 0)


def test_compose_counts_incomplete_segments_only_in_front_of_opacity():
    """A segment left unfinished behind an opaque one (opacity >= 0.99, the early-termination
    threshold) does not leave its ray unfinished; in front of it, it does. Colours combine by
    eq. (3)/(4) either way."""
    from gatun_py.raycast import _segments as K
    from gatun_py.raycast._walk import compose

    # ray 0: done segment of opacity 0.995, then a stuck one; ray 1: 0.5 then stuck;
    # ray 2: stuck first, then a done opaque one; ray 3: a stuck segment whose front
    # subsegment is opaque (the gap lies behind it); ray 4: front 0.5 after 0.97: 0.985 at the gap
    seg_ray = np.array([0, 0, 1, 1, 2, 2, 3, 4, 4], dtype=np.int32)
    seg_acc = np.zeros((9, 2, 4))
    seg_acc[6, 0] = [0.0, 0.995, 0.0, 0.995]
    seg_acc[6, 1] = [0.0, 0.0, 1.0, 1.0]
    seg_acc[7, 0] = [0.97, 0.0, 0.0, 0.97]
    seg_acc[8, 0] = [0.0, 0.5, 0.0, 0.5]
    seg_acc[0, 0] = [0.995, 0.0, 0.0, 0.995]
    seg_acc[1, 1] = [0.0, 0.6, 0.0, 0.6]
    seg_acc[2, 0] = [0.0, 0.0, 0.5, 0.5]
    seg_acc[3, 0] = [0.3, 0.0, 0.0, 0.3]
    seg_acc[4, 0] = [0.1, 0.0, 0.0, 0.1]
    seg_acc[5, 0] = [0.0, 0.999, 0.0, 0.999]
    state = np.array([K.STATE_DONE, K.STATE_STUCK, K.STATE_DONE, K.STATE_ACTIVE, K.STATE_STUCK, K.STATE_DONE,
                      K.STATE_STUCK, K.STATE_DONE, K.STATE_ACTIVE], dtype=np.uint8)
    seg = list(K.make_segments(seg_ray, np.zeros((9, 2, 3), np.int32), np.zeros((9, 2), np.int32),
                               np.zeros((9, 2, 2)), 5)[0])
    seg[K.SEG_ACC], seg[K.SEG_STATE] = seg_acc, state
    image = np.zeros((5, 4))
    unfinished, hidden = compose(tuple(seg), image, False)
    assert (unfinished, hidden) == (3, 2)
    np.testing.assert_allclose(image[3], [0.0, 0.995, 0.005, 1.0])
    np.testing.assert_allclose(image[0], [0.995, 0.005 * 0.6, 0.0, 0.995 + 0.005 * 0.6])
    np.testing.assert_allclose(image[1], [0.5 * 0.3, 0.0, 0.5, 0.5 + 0.5 * 0.3])
    np.testing.assert_allclose(image[2], [0.1, 0.9 * 0.999, 0.0, 0.1 + 0.9 * 0.999])
    # with early termination a segment behind an opaque ray adds nothing (ray 0's second);
    # the counts are the same
    terminated = np.zeros((5, 4))
    assert compose(tuple(seg), terminated, True) == (3, 2)
    np.testing.assert_allclose(terminated[0], [0.995, 0.0, 0.0, 0.995])
    np.testing.assert_array_equal(terminated[1:], image[1:])


@pytest.mark.parametrize("az, el", [(30, 20), (0, 0), (90, 20), (200, -45), (45, 70)])
def test_folded_real_grid_leaves_no_ray_unfinished(az, el):
    """The Combustion chamber grid folds over itself in places (two tets on the same side of a
    face): walks that reach such a face end there, as at the boundary, instead of entering the tet
    backwards and circling an edge (which left 0-3 rays per view unfinished)."""
    from conftest import load_sample

    mesh, _ = load_sample("combustion")
    res = render_mesh(mesh, Camera(256, 256, az, el), "default")
    assert res.stats["rays_unfinished"] == 0
    assert res.stats["segments_stuck"] == 0
    assert res.stats["nan_pixels"] == 0


# -- the face table ---------------------------------------------------------------------------------
@pytest.mark.parametrize("mul", [0, 3 << 16])
def test_face_table_holds_each_face_with_its_two_tets_across_rehash(mul):
    """Every face of a mesh is found after insertion and after rehashing into a larger table
    (grouped or scattered slots), with the fourth vertex of each of its tets; boundary faces have
    one tet, interior faces two; the face count is exact."""
    from gatun_py.mesh.model import TET_FACES
    from gatun_py.raycast import _facetable as FT
    from gatun_py.raycast._segments import make_segments

    mesh = delaunay_mesh(80, 4)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int32)
    S, _ = make_segments(np.zeros(0, np.int32), np.zeros((0, 2, 3), np.int32), np.zeros((0, 2), np.int32),
                         np.zeros((0, 2, 2)), 1)
    F = FT.make_face_table(1 << 12, mul, 0, counting=False)
    n_active, conflicts = FT.insert_tets(tets, np.zeros((0, 4), np.int32), np.zeros(mesh.n_points, np.uint8), F, S,
                                         1, np.zeros(0, np.int64))
    assert (n_active, conflicts) == (0, 0)
    want = {}
    for t, tet in enumerate(tets):
        for k in range(4):
            want.setdefault(tuple(sorted(tet[TET_FACES[k]].tolist())), set()).add(int(tet[k]))
    n_boundary = len(mesh.boundary_faces())
    assert sum(len(v) == 1 for v in want.values()) == n_boundary
    for grown in (False, True):
        if grown:
            F = FT.with_table(F, FT.rehash(F, 1 << 13, mul, False, np.zeros(mesh.n_points, np.uint8)))
        table, info = F[FT.FT_TABLE], F[FT.FT_INFO]
        assert info[FT.INFO_FACES] == len(want) and info[FT.INFO_MUL] == mul
        for (a, b, c), fourth in want.items():
            slot = FT._hash_find(table, mul, a, b, c)
            assert slot >= 0
            codes = table[slot, [FT.FT_TET0, FT.FT_TET1]]
            assert {int(x) >> 1 for x in codes if x >= 0} == fourth
        assert FT._hash_find(table, mul, 0, 0, 0) == -1


@settings(max_examples=10, deadline=None)
@given(mesh=mesh_strategy(), seed=st.integers(0, 1000), mode=st.sampled_from(["volume", "face"]),
       n_batches=st.integers(2, 7))
def test_snapshots_fill_in_toward_the_final_image(mesh, seed, mode, n_batches):
    """Partial images of a streaming render only gain opacity, never exceed the final image's, the
    pixels they call finished already hold their final colour, and taking them changes nothing."""
    from gatun_py.mesh import mesh_batches
    from gatun_py.raycast.stream import render_batches

    cam = Camera(12, 10, azimuth=25.0, elevation=15.0)
    order = np.random.default_rng(seed).permutation(mesh.n_tets)
    batch = max(1, -(-mesh.n_tets // n_batches))
    shots = []
    res = render_batches(mesh_batches(mesh, batch_tets=batch, order=order), cam, TF, mode=mode,
                         scalar_range=mesh.scalar_range, partial=lambda *shot: shots.append(shot),
                         partial_every_s=0.0)
    plain = render_batches(mesh_batches(mesh, batch_tets=batch, order=order), cam, TF, mode=mode,
                           scalar_range=mesh.scalar_range)
    assert np.array_equal(res.image, plain.image)
    assert len(shots) == -(-mesh.n_tets // batch)
    alphas = [image[..., 3] for image, _ in shots] + [res.image[..., 3]]
    for a, b in zip(alphas, alphas[1:]):
        assert np.all(a <= b + 1e-6)
    for image, finished in shots:
        np.testing.assert_array_equal(image[finished], res.image[finished])
    assert shots[-1][1].sum() >= shots[0][1].sum()
    np.testing.assert_allclose(shots[-1][0], res.image, atol=1e-5)
