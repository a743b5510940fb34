"""The per-frame importance kernels against plain numpy / Python references: the projected size
(the camera's own projection), transmittance only where it is needed, the merge regions (subtree
radius and scalar range, by walking the forest), children-first keys; a TF change or a new view
reuses the cached state and gives the same importance as a fresh source."""

from __future__ import annotations

import numpy as np
import pytest

from gatun_py.codec import TetcReader
from gatun_py.pipeline import _importance_kernels as K
from gatun_py.pipeline.selective import (REGION_FACTORS, merge_importance, merge_regions, region_error,
                                         selective_source)
from gatun_py.pipeline.stream import file_render_defaults
from gatun_py.raycast.camera import Camera
from gatun_py.raycast.transfer import load_transfer_function

TFS = ["post", {"color": [{"x": 0, "rgb": [0, 0, 1]}, {"x": 1, "rgb": [1, 0, 0]}],
                "opacity": [{"x": 0, "a": 0}, {"x": 0.4, "a": 0}, {"x": 1, "a": 0.8}]}]


@pytest.fixture(scope="module")
def setup(post_deps_tetc):
    reader = TetcReader(post_deps_tetc)
    lo, hi, rng, _ = file_render_defaults(reader)
    return reader, selective_source(reader), lo, hi, rng


def _tf(spec, lo, hi):
    return load_transfer_function(spec).for_size(float(np.linalg.norm(hi - lo)))


@pytest.mark.parametrize("az, el, zoom", [(30, 20, 1.0), (200, 60, 3.0), (120, -30, 8.0)])
def test_projected_size_matches_the_camera(setup, az, el, zoom):
    _, src, lo, hi, _ = setup
    cam = Camera(64, 48, az, el, zoom=zoom).fit(lo, hi)
    pv = np.ascontiguousarray(src.points[src.vertex])
    length = np.linalg.norm(src.points[src.target] - pv, axis=1)
    fwd, right, up = cam.basis()
    got = K._projected_size(pv, length, np.asarray(cam.position, np.float64), fwd, right, up,
                            float(np.tan(np.radians(cam.view_angle) / 2)), 64.0, 48.0)
    depth = (pv - cam.position) @ fwd
    pixel = 2.0 * np.tan(np.radians(cam.view_angle) / 2.0) / cam.height
    px = np.where(depth > 0, length / (np.maximum(depth, 1e-300) * pixel), 0.0)
    xy = cam.project(pv)
    on = (depth > 0) & (xy[:, 0] >= -px) & (xy[:, 0] <= 64 + px) & (xy[:, 1] >= -px) & (xy[:, 1] <= 48 + px)
    want = np.where(on, px, 0.0)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    if zoom > 1:
        assert (got == 0).any()  # zoomed in: some merges are off the image


def test_transmittance_only_where_needed(setup):
    _, src, lo, hi, rng = setup
    tf = _tf("post", lo, hi)
    _, a = tf.resolve(rng).evaluate(src.scalars)
    grid = K._extinction_grid(src.points, -np.log1p(-np.clip(a, 0, 0.999)) / tf.unit_distance, lo, hi, 8)
    eye = np.asarray(hi, np.float64) * 3.0
    pv = np.ascontiguousarray(src.points[src.vertex])
    every = K._transmittance(grid, lo, hi, eye, pv, 8)
    need = np.random.default_rng(0).random(pv.shape[0]) < 0.3
    some = K._transmittance_where(grid, lo, hi, eye, pv, 8, need)
    assert np.array_equal(some[need], every[need]) and np.all(some[~need] == 1.0)
    assert np.all((every > 0) & (every <= 1)) and every.min() < 1


def _regions_naive(src):
    """Walk every merge's subtree (the vertices whose chain of parents reaches v_i through merges
    of lower rank)."""
    children = {}
    for i in range(src.n_merges):
        children.setdefault(int(src.target[i]), []).append(int(src.vertex[i]))
    rank = {int(src.vertex[i]): i for i in range(src.n_merges)}
    out = []
    for i in range(src.n_merges):
        stack, sub = [int(src.vertex[i])], []
        while stack:
            v = stack.pop()
            sub.append(v)
            stack += [c for c in children.get(v, []) if rank[c] < i]
        p = src.points[sub]
        t = src.points[src.target[i]]
        corner = np.maximum(np.abs(p.min(axis=0) - t), np.abs(p.max(axis=0) - t))
        s = np.append(src.scalars[sub], src.scalars[src.target[i]])
        out.append((np.sqrt((corner ** 2).sum()), s.min(), s.max()))
    return np.array(out)


def test_merge_regions_match_a_walk_of_the_forest(setup):
    _, src, *_ = setup
    radius, s_lo, s_hi = merge_regions(src)
    ref = _regions_naive(src)
    np.testing.assert_allclose(radius, ref[:, 0], rtol=1e-12)
    assert np.array_equal(s_lo, ref[:, 1]) and np.array_equal(s_hi, ref[:, 2])


def test_subtree_max_puts_children_first(setup):
    _, src, *_ = setup
    key = np.random.default_rng(3).random(src.n_merges)
    out = K._subtree_max(key, src.vertex, src.target, src.rank)
    pos = np.empty(src.n_merges, np.int64)
    pos[np.argsort(out, kind="stable")] = np.arange(src.n_merges)
    merge_of = np.full(src.points.shape[0], -1)
    merge_of[src.vertex] = np.arange(src.n_merges)
    child = np.arange(src.n_merges)
    parent_merge = merge_of[src.target]
    has = parent_merge >= 0
    assert np.all(pos[child[has]] < pos[parent_merge[has]])
    assert np.all(out >= key)


@pytest.mark.parametrize("spec", TFS)
def test_cached_state_gives_what_a_fresh_source_gives(setup, post_deps_tetc, spec):
    reader, src, lo, hi, rng = setup
    cams = [Camera(48, 40, 30, 20).fit(lo, hi), Camera(48, 40, 200, 60).fit(lo, hi)]
    for other in TFS:  # leave the cache holding another TF first
        merge_importance(src, cams[0], _tf(other, lo, hi), lo=lo, hi=hi, scalar_range=rng)
    fresh = selective_source(TetcReader(post_deps_tetc))
    for cam in cams:
        a = merge_importance(src, cam, _tf(spec, lo, hi), lo=lo, hi=hi, scalar_range=rng)
        b = merge_importance(fresh, cam, _tf(spec, lo, hi), lo=lo, hi=hi, scalar_range=rng)
        assert np.array_equal(a, b)
        e = region_error(src, cam, _tf(spec, lo, hi), lo=lo, hi=hi, scalar_range=rng)
        assert e.shape == (src.n_merges,) and np.all(np.isfinite(e)) and np.all(e >= 0)
    assert set(REGION_FACTORS) == {"colour", "light", "area"}


def test_trilinear_reproduces_linear_functions_and_lattice_values(setup):
    _, src, lo, hi, _ = setup
    g = 6
    c = K._cell_centres(np.asarray(lo, np.float64), np.asarray(hi, np.float64), g)
    f = lambda p: 0.3 + p @ np.array([0.5, -0.25, 0.125])  # noqa: E731
    vals = f(c).reshape(g, g, g)
    pts = np.ascontiguousarray(src.points)
    inside = np.all((pts >= c.min(axis=0)) & (pts <= c.max(axis=0)), axis=1)
    got = K._trilinear(vals, np.asarray(lo, np.float64), np.asarray(hi, np.float64), pts, np.ones(len(pts), bool))
    np.testing.assert_allclose(got[inside], f(pts[inside]), rtol=1e-12, atol=1e-12)
    at = K._trilinear(vals, np.asarray(lo, np.float64), np.asarray(hi, np.float64), c, np.ones(len(c), bool))
    np.testing.assert_allclose(at, vals.ravel(), rtol=1e-12, atol=1e-12)
    assert inside.sum() > 0.3 * len(pts)


def test_light_lattice_follows_the_per_point_march(setup):
    """The lattice transmittance stays close to marching to every point (it is smooth at that scale)."""
    from gatun_py.pipeline.selective import _light, _tf_state

    _, src, lo, hi, rng = setup
    cam = Camera(48, 40, 30, 20).fit(lo, hi)
    state = _tf_state(src, _tf("post", lo, hi), rng, lo, hi)
    eye = np.asarray(cam.position, np.float64)
    pv = np.ascontiguousarray(src.points[src.vertex])
    exact = K._transmittance(state["grid"], state["lo"], state["hi"], eye, pv, 32)
    approx = _light(state, eye, pv, np.ones(len(pv), bool))
    assert np.median(np.abs(approx - exact)) < 0.05 and np.corrcoef(approx, exact)[0, 1] > 0.75
