"""Bricks of a bricked file that cannot show are not decoded: those whose stored scalar range the
transfer function makes invisible, and those whose stored box lies off the image. The image is
the one every brick decoded gives, bit for bit, and the whole file's."""

from __future__ import annotations

import numpy as np
import pytest

import gatun_py
from gatun_py.codec import TetcReader
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.pipeline import sortlast
from gatun_py.pipeline.sortlast import BrickRef, MeshExtent, frame_setup, render_bricks
from gatun_py.pipeline.stream import View, render_tetc
from gatun_py.raycast import Camera
from gatun_py.raycast._cull import visible_prefix, visible_tets
from gatun_py.raycast.caster import box_in_view, range_can_show
from gatun_py.raycast.image import to_rgb8
from gatun_py.raycast.transfer import from_dict

N_BRICKS = 8


def tf_above(cut: float):
    """Transparent below ``cut`` of the scalar range, a ramp of opacity above it."""
    return from_dict({
        "color": [{"x": 0.0, "rgb": [0.1, 0.2, 1.0]}, {"x": 1.0, "rgb": [1.0, 0.1, 0.0]}],
        "opacity": [{"x": 0.0, "a": 0.0}, {"x": cut, "a": 0.0}, {"x": min(1.0, cut + 0.1), "a": 0.4},
                    {"x": 1.0, "a": 0.4}],
        "unit_distance": 3.0,
    })


NOTHING = from_dict({"color": [{"x": 0.0, "rgb": [1.0, 1.0, 1.0]}, {"x": 1.0, "rgb": [1.0, 1.0, 1.0]}],
                     "opacity": [{"x": 0.0, "a": 0.0}, {"x": 1.0, "a": 0.0}]})


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A grid whose scalar grows along y, as one plain stream and as 8 bricks."""
    d = tmp_path_factory.mktemp("skip")
    mesh = jittered_grid((9, 9, 9), jitter=0.2, scalar=(0.0, 1.0, 0.0))
    plain, bricked = d / "plain.tetc", d / "bricked.tetc"
    gatun_py.compress(mesh, plain, mesh_only=True)
    gatun_py.compress(mesh, bricked, mesh_only=True, bricks=N_BRICKS, jobs=1)
    return mesh, plain, bricked


def _render_counting(bricked, view, monkeypatch, *, skip=True):
    """The bricks' render, and how many bricks were decoded (calls of the streaming decoder)."""
    reader = TetcReader(bricked)
    decoded = []
    run = sortlast._run_streaming

    def counting(reader, *args, **kwargs):
        decoded.append(reader)
        return run(reader, *args, **kwargs)

    monkeypatch.setattr(sortlast, "_run_streaming", counting)
    if not skip:
        monkeypatch.setattr(sortlast, "brick_hidden", lambda *a: None)
    refs = [BrickRef(str(bricked), k) for k in range(reader.n_bricks)]
    res = render_bricks(refs, view, MeshExtent.of_reader(reader))
    monkeypatch.undo()
    return res, len(decoded)


@pytest.mark.parametrize("mode", ["volume", "face"])
def test_invisible_bricks_are_not_decoded(files, monkeypatch, mode):
    mesh, plain, bricked = files
    view = View(Camera(48, 48, 30, 20), tf_above(0.7), mode, terminate=False)
    res, n_decoded = _render_counting(bricked, view, monkeypatch)
    full, n_all = _render_counting(bricked, view, monkeypatch, skip=False)
    assert n_all == N_BRICKS
    assert 1 <= n_decoded < N_BRICKS  # the bricks below 70 % of the range hold nothing visible
    assert res.stats["bricks_decoded"] == n_decoded
    assert res.stats["bricks_skipped"] == N_BRICKS - n_decoded
    assert np.array_equal(res.image, full.image)
    assert float(res.image[..., 3].max()) > 0.05  # something shows
    whole = render_tetc(str(plain), view)
    assert int(np.abs(to_rgb8(res.image).astype(int) - to_rgb8(whole.image).astype(int)).max()) <= 1
    assert float(np.abs(res.image - whole.image).max()) < 1e-6


def test_a_transfer_function_showing_nothing_decodes_no_brick(files, monkeypatch):
    _, _, bricked = files
    view = View(Camera(32, 32, 30, 20), NOTHING)
    res, n_decoded = _render_counting(bricked, view, monkeypatch)
    assert n_decoded == 0 and res.stats["bricks_skipped"] == N_BRICKS
    assert not res.image.any()


def test_off_screen_bricks_are_not_decoded(files, monkeypatch):
    """Zoomed on the middle, panned: bricks outside the image are skipped, the image unchanged."""
    _, _, bricked = files
    view = View(Camera(40, 40, 0, 0, zoom=4.0, pan_x=0.5, pan_y=0.5), "default", terminate=False)
    res, n_decoded = _render_counting(bricked, view, monkeypatch)
    full, _ = _render_counting(bricked, view, monkeypatch, skip=False)
    assert n_decoded < N_BRICKS
    assert np.array_equal(res.image, full.image)
    assert float(res.image[..., 3].max()) > 0.05


def test_a_ratio_between_levels_skips_nothing_by_its_stored_range(files):
    """The stored range and box bound a stored level's points only."""
    _, _, bricked = files
    reader = TetcReader(bricked).brick(0)
    setup, _ = frame_setup(View(Camera(16, 16), NOTHING), MeshExtent.of_reader(TetcReader(bricked)))
    target = sortlast.resolve_target(reader, level=0)
    assert sortlast.brick_hidden(reader, target, setup) == "tf"
    between = sortlast.Target(target.level, target.merges + 1, target.ratio, target.level_merges)
    assert sortlast.brick_hidden(reader, between, setup) is None


@pytest.mark.parametrize("cut", [0.0, 0.3, 0.5, 0.97, 1.0])
def test_range_test_is_the_tet_test(cut):
    """A brick's range is invisible exactly when a tet spanning that range would be culled."""
    tf = tf_above(cut)
    rng = (-2.0, 5.0)
    tab, lo, inv = tf.resolve(rng).table(rng)
    prefix = visible_prefix(tab[:, 3])
    rs = np.random.default_rng(7)
    for _ in range(200):
        a, b = np.sort(rs.uniform(-3.0, 6.0, 2))
        dens = np.array([a, b, a, b])
        out = np.empty(1, np.uint8)
        visible_tets(np.arange(4, dtype=np.int32).reshape(1, 4), dens, prefix, lo, inv, out)
        assert range_can_show(tf, rng, a, b) == bool(out[0])


def test_box_in_view():
    cam = Camera(20, 20).fit(np.zeros(3), np.ones(3))
    assert box_in_view(cam, np.zeros(3), np.ones(3))
    assert not box_in_view(cam, np.array([50.0, 0, 0]), np.array([51.0, 1, 1]))  # far to one side
    behind = cam.position - 5.0 * (cam.focal_point - cam.position)
    assert box_in_view(cam, behind - 1.0, behind + 1.0) is True  # behind the eye: not decided, kept


def test_a_budget_gives_hidden_bricks_no_time(files):
    """Under a budget, the bricks that will not be decoded take no share of the frame's time."""
    _, _, bricked = files
    whole = TetcReader(bricked)
    readers = [whole.brick(k) for k in range(whole.n_bricks)]
    setup, _ = frame_setup(View(Camera(32, 32, 30, 20), tf_above(0.7)), MeshExtent.of_reader(whole))
    hidden = [sortlast.brick_hidden(r, sortlast.resolve_target(r, level=0), setup) is not None for r in readers]
    assert any(hidden) and not all(hidden)
    share = sortlast._budget_shares(readers, 2.0, None, setup)
    assert all(s == 0.0 for s, h in zip(share, hidden) if h)
    assert all(s > 0.0 for s, h in zip(share, hidden) if not h)
    assert sum(share) == pytest.approx(2.0)
    assert sum(sortlast._budget_shares(readers, 2.0, None, None)) == pytest.approx(2.0)
