"""Direct-send compositing: a frame cut into row bands, each band composited on its own from every
brick's fragments, stacks up to the frame composited whole (pixels are independent)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_sample
from gatun_py.pipeline.sortlast import (composite_frame, composite_rows, frame_setup, join_rows, render_brick,
                                        split_for_render)
from gatun_py.pipeline.stream import View
from gatun_py.raycast import Camera
from gatun_py.raycast.composite import Fragments, composite, merge_fragments, row_bands, split_rows


def _fragments(rng, width, height, n):
    ray = rng.integers(0, width * height, n).astype(np.int32)
    a = rng.uniform(0, 1, n)
    rgb = rng.uniform(0, 1, (n, 3)) * a[:, None]
    t0 = rng.integers(0, 4, n).astype(np.float64)  # overlaps and ties too
    depth = np.stack([t0, t0 + rng.integers(0, 3, n)], axis=1)
    return Fragments(ray, np.concatenate([rgb, a[:, None]], axis=1), depth, width, height)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7), st.integers(1, 9), st.integers(0, 80), st.integers(1, 12))
def test_bands_composite_to_the_whole_frame(seed, width, height, n, n_bands):
    rng = np.random.default_rng(seed)
    frags = merge_fragments(*[_fragments(rng, width, height, n) for _ in range(3)])
    bands = row_bands(height, n_bands)
    assert bands[0][0] == 0 and bands[-1][1] == height and len(bands) == min(n_bands, height)
    assert all(b[0] < b[1] and b[1] == c[0] for b, c in zip(bands, bands[1:]))
    parts = split_rows(frags, bands)
    assert sum(len(p) for p in parts) == len(frags)
    whole_stats, band_overlaps = {}, 0
    whole = composite(frags, stats=whole_stats)
    rows = []
    for p in parts:
        st_band = {}
        rows.append(composite(p, stats=st_band))
        band_overlaps += st_band["fragments_overlapping_pixels"]
    assert np.array_equal(np.concatenate(rows, axis=0), whole)  # bit for bit, ties kept in input order
    assert band_overlaps == whole_stats["fragments_overlapping_pixels"]


def test_row_bands_of_bricks_join_to_the_composited_frame():
    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 5)
    setup, _ = frame_setup(View(Camera(40, 33, 30, 20), "post"), extent)
    rendered = [render_brick(b, setup) for b in bricks]
    stats = [dict(s, brick=i) for i, (_, s) in enumerate(rendered)]
    ref = composite_frame([f for f, _ in rendered], stats)
    bands = row_bands(33, 3)
    cut = [split_rows(f, bands) for f, _ in rendered]
    got = join_rows([composite_rows(band, [c[j] for c in cut], stats if j == 0 else None)
                     for j, band in enumerate(bands)], 40)
    assert np.array_equal(got.image, ref.image)
    for key in ("rays_hit", "fragments_overlapping_pixels", "tets_rendered", "bricks", "rays"):
        assert got.stats[key] == ref.stats[key], key
    assert got.stats["bands"] == 3 and len(got.stats["brick_s"]) == 5
