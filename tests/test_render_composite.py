"""Sort-last compositing: a mesh rendered as bricks, their fragments sorted by depth and
composited, equals the mesh rendered whole; the compositor kernel equals its slow reference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_sample
from gatun_py.errors import OptionError
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.pipeline.sortlast import MeshExtent, frame_setup, render_bricks, split_for_render
from gatun_py.pipeline.stream import View, render_mesh_file
from gatun_py.raycast import Camera, render_mesh
from gatun_py.raycast.composite import Fragments, composite, merge_fragments
from gatun_py.raycast._walk import OPAQUE
from gatun_py.raycast.image import to_rgb8
from naive_composite import naive_composite
from samples import SAMPLES


def _random_fragments(rng, width, height, n, *, disjoint=True, part=0, parts=1):
    ray = rng.integers(0, width * height, n).astype(np.int32)
    a = rng.uniform(0, 1, n)
    rgb = rng.uniform(0, 1, (n, 3)) * a[:, None]
    if disjoint:  # a partition's fragments: disjoint depth intervals per pixel
        t0 = (rng.permutation(n) * parts + part).astype(np.float64) * 2.0
        depth = np.stack([t0, t0 + 1.0], axis=1)
    else:
        t0 = rng.integers(0, 3, n).astype(np.float64)
        depth = np.stack([t0, t0 + rng.integers(0, 3, n)], axis=1)
    return Fragments(ray, np.concatenate([rgb, a[:, None]], axis=1), depth, width, height)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(1, 5), st.integers(0, 60), st.booleans())
def test_composite_kernel_equals_naive_reference(seed, width, height, n, disjoint):
    rng = np.random.default_rng(seed)
    parts = [_random_fragments(rng, width, height, n, disjoint=disjoint, part=k, parts=3) for k in range(3)]
    stats = {}
    fast = composite(merge_fragments(*parts), stats=stats)
    slow = naive_composite(parts)
    # the same operations in the same order: equal up to the final float32 rounding
    assert np.array_equal(fast, slow.astype(np.float32))
    if disjoint:
        assert stats["fragments_overlapping_pixels"] == 0


def test_merge_order_does_not_matter():
    rng = np.random.default_rng(3)
    parts = [_random_fragments(rng, 7, 5, 40, part=k, parts=4) for k in range(4)]
    a = composite(merge_fragments(*parts))
    b = composite(merge_fragments(merge_fragments(parts[3], parts[1]), merge_fragments(parts[2], parts[0])))
    assert np.array_equal(a, b)


def test_bad_fragments_are_refused():
    f = Fragments(np.array([6], np.int32), np.zeros((1, 4)), np.zeros((1, 2)), 2, 3)
    with pytest.raises(ValueError, match="pixels"):
        composite(f)
    with pytest.raises(ValueError, match="cannot merge"):
        merge_fragments(f, Fragments.empty(3, 3))


def test_fragments_of_a_whole_mesh_composite_to_its_image():
    """One brick: the fragments are the render's own segments, so compositing them gives its image."""
    mesh = jittered_grid((7, 7, 7), jitter=0.25, seed=1)
    for mode in ("volume", "face"):
        res = render_mesh(mesh, Camera(48, 40, 30, 20), "default", mode=mode, fragments=True)
        assert np.array_equal(composite(res.fragments), res.image)
        assert len(res.fragments) <= res.stats["segments"]


def _diff(a, b):
    """(max difference on 0..255, pixels that differ at all) of two premultiplied images."""
    a8, b8 = to_rgb8(a).astype(int), to_rgb8(b).astype(int)
    return int(np.abs(a8 - b8).max()), int(np.count_nonzero(np.any(a != b, axis=2)))


def _bricked_vs_whole(mesh, n_bricks, mode, tf, size=64, views=((30.0, 20.0),)):
    bricks, extent = split_for_render(mesh, n_bricks)
    out = []
    for az, el in views:
        # bricks walk every ray to its end (sort-last compositing needs whole segments): the
        # whole render to compare with does too; with early termination it differs by < 1 - OPAQUE
        view = View(Camera(size, size, az, el), tf, mode, terminate=False)
        whole = render_mesh_file(mesh, view)
        bricked = render_bricks(bricks, view, extent)
        terminated = render_mesh_file(mesh, replace(view, terminate=True))
        assert np.abs(terminated.image - whole.image).max() <= 1.0 - OPAQUE + 1e-6
        if bricked.stats["boundary_anomalies"] == 0:  # a folded grid's one-ended segments may overlap
            assert bricked.stats["fragments_overlapping_pixels"] == 0
        assert bricked.stats["rays_unfinished"] == whole.stats["rays_unfinished"] == 0
        out.append(_diff(bricked.image, whole.image) + (float(np.abs(bricked.image - whole.image).max()),))
    return out


@pytest.mark.parametrize("mode", ["volume", "face"])
@pytest.mark.parametrize("n_bricks", [2, 8, 64])
def test_bricked_render_equals_whole_render_on_a_grid(mode, n_bricks):
    mesh = jittered_grid((9, 9, 9), jitter=0.3, seed=2)
    for max8, _, max_abs in _bricked_vs_whole(mesh, n_bricks, mode, "default", views=((30, 20), (200, -45))):
        assert max8 <= 1 and max_abs < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["volume", "face"])
@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_bricked_render_equals_whole_render_on_every_sample(name, mode):
    mesh = load_sample(name)[0]
    for n_bricks in (8, 64):
        for max8, _, max_abs in _bricked_vs_whole(mesh, n_bricks, mode, SAMPLES[name][2], size=96,
                                                  views=((0, 0), (90, 20), (45, 70))):
            assert max8 <= 1, (n_bricks, max8)
            assert max_abs < 1e-4, (n_bricks, max_abs)


def test_bricks_share_the_whole_mesh_frame():
    """Bricks sample the whole mesh's positions: its camera, step and scalar range, not their own."""
    mesh = jittered_grid((6, 6, 6), jitter=0.2, seed=4)
    bricks, extent = split_for_render(mesh, 4)
    assert extent == MeshExtent.of_mesh(mesh)
    setup, _ = frame_setup(View(Camera(32, 32)), extent)
    lo, hi = mesh.bbox
    assert np.allclose(setup.camera.position, Camera(32, 32).fit(lo, hi).position)
    assert setup.scalar_range == tuple(map(float, mesh.scalar_range))
    assert setup.step == extent.step
    # a brick's own boundary (with its cut faces) would give another step: it must not be used
    assert any(MeshExtent.of_mesh(b).step != extent.step for b in bricks)
    assert render_bricks(bricks, View(Camera(16, 16)), extent).stats["step"] == extent.step


@pytest.fixture(scope="module")
def post_brick_files(tmp_path_factory):
    """post.vtk cut into 4 bricks, each compressed to its own .tetc (with its forest and levels)."""
    import gatun_py

    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 4)
    folder = tmp_path_factory.mktemp("post_bricks")
    paths = []
    for k, b in enumerate(bricks):
        paths.append(folder / f"b{k}.tetc")
        gatun_py.compress(b, paths[-1])
    return mesh, paths, extent


def test_tetc_bricks_render_the_whole_mesh(post_brick_files):
    """Bricks decoded from their own files (the cut-border coder renumbers their vertices) still
    composite to the whole mesh's image."""
    mesh, paths, extent = post_brick_files
    for mode in ("volume", "face"):
        view = View(Camera(64, 64, 30, 20), "post", mode)
        whole = render_mesh_file(mesh, view)
        bricked = render_bricks([str(p) for p in paths], view, extent)
        max8, _ = _diff(bricked.image, whole.image)
        assert max8 <= 1 and float(np.abs(bricked.image - whole.image).max()) < 1e-6
        assert bricked.stats["brick_levels"] == [0, 0, 0, 0]


def test_budget_with_bricks_picks_a_level_per_brick(post_brick_files, tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    mesh, paths, extent = post_brick_files
    view = View(Camera(48, 48, 30, 20), "post")
    srcs = [str(p) for p in paths]
    generous = render_bricks(srcs, view, extent, budget=60.0)
    assert generous.stats["brick_levels"] == [0, 0, 0, 0]  # a minute: the full mesh everywhere
    tight = render_bricks(srcs, view, extent, budget=1e-4)
    assert all(lv > 0 for lv in tight.stats["brick_levels"])  # nothing fits: every brick coarsens
    assert tight.stats["tets_rendered"] < generous.stats["tets_rendered"] == mesh.n_tets
    with pytest.raises(OptionError, match="at most one"):
        render_bricks(srcs, view, extent, budget=1.0, level=1)


def test_cluster_without_dask_says_how_to_install_it(monkeypatch):
    import sys

    from gatun_py.pipeline.distributed import BrickCluster

    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed: import raises ImportError
    with pytest.raises(OptionError, match=r"gatun_py\[dask\]"):
        BrickCluster(workers=1)


def test_a_bricked_file_renders_brick_by_brick_like_the_whole_file(tmp_path):
    """A format-3 bricked file: each brick's reader rendered on its own into fragments, composited,
    equals the plain file's render (the path `tetc render --workers` takes)."""
    import gatun_py
    from gatun_py.codec import TetcReader
    from gatun_py.pipeline.sortlast import BrickRef
    from gatun_py.pipeline.stream import render_tetc

    mesh = load_sample("post")[0]
    plain, bricked = tmp_path / "plain.tetc", tmp_path / "bricked.tetc"
    gatun_py.compress(mesh, plain, mesh_only=True)
    gatun_py.compress(mesh, bricked, mesh_only=True, bricks=8)
    reader = TetcReader(bricked)
    assert reader.n_bricks == 8
    extent = MeshExtent.of_reader(reader)
    refs = [BrickRef(str(bricked), k) for k in range(reader.n_bricks)]
    for mode in ("volume", "face"):
        view = View(Camera(64, 64, 30, 20), "post", mode)
        whole = render_tetc(str(plain), view)
        res = render_bricks(refs, view, extent)
        max8, _ = _diff(res.image, whole.image)
        assert max8 <= 1 and float(np.abs(res.image - whole.image).max()) < 1e-6, mode
        assert res.stats["tets_rendered"] == mesh.n_tets
