"""The renderer's robustness on the real samples, judged here (the bench only reports it):
every sample from four views, no unfinished ray, no NaN pixel, no stuck walk, and the render
streamed in 20 shuffled batches equals the in-memory render."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import load_sample
from gatun_py.mesh import mesh_batches
from gatun_py.raycast import Camera, render_mesh
from gatun_py.raycast.stream import render_batches
from samples import SAMPLES

pytestmark = pytest.mark.slow
VIEWS = [(0.0, 0.0), (90.0, 20.0), (200.0, -45.0), (45.0, 70.0)]


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_every_sample_from_every_view(name):
    mesh = load_sample(name)[0]
    tf = SAMPLES[name][2]
    perm = np.random.default_rng(0).permutation(mesh.n_tets)
    for az, el in VIEWS:
        cam = Camera(96, 96, az, el)
        mem = render_mesh(mesh, cam, tf)
        streamed = render_batches(mesh_batches(mesh, batch_tets=-(-mesh.n_tets // 20), order=perm), cam, tf,
                                  scalar_range=mesh.scalar_range, expected_tets=mesh.n_tets)
        for res in (mem, streamed):
            s = res.stats
            assert s["rays_unfinished"] == 0 and s["segments_stuck"] == 0 and s["nan_pixels"] == 0, (az, el, s)
            assert s["rays_hit"] > 0
        assert float(np.abs(streamed.image - mem.image).max()) <= 1e-5, (az, el)
