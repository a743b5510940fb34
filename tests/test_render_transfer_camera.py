"""Transfer functions (formats, presets, errors), the VTK-style camera maths, PNG output."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gatun_py.errors import OptionError
from gatun_py.raycast import Camera, load_transfer_function, preset_names, to_rgb8, write_png
from gatun_py.raycast.image import png_bytes, read_png_rgb
from gatun_py.raycast.transfer import TABLE_SIZE, from_dict

PROJECT_TF = {
    "color": [{"x": 0.0, "rgb": [0, 0, 1]}, {"x": 1.0, "rgb": [1, 0, 0]}],
    "opacity": [{"x": 0.0, "a": 0.0}, {"x": 0.5, "a": 0.2}, {"x": 1.0, "a": 1.0}],
    "unit_distance": 0.5,
}


def test_project_format_resolve_and_evaluate():
    tf = from_dict(PROJECT_TF).resolve((10.0, 20.0))
    rgb, a = tf.evaluate([10.0, 12.5, 15.0, 20.0, 25.0])
    np.testing.assert_allclose(rgb[:, 0], [0, 0.25, 0.5, 1, 1])
    np.testing.assert_allclose(a, [0, 0.1, 0.2, 1, 1])
    assert tf.unit_distance == 0.5
    absolute = from_dict(dict(PROJECT_TF, absolute=True))
    assert absolute.resolve((10.0, 20.0)) is absolute


def test_table_matches_exact_evaluation():
    tf = from_dict(PROJECT_TF)
    tab, lo, inv = tf.table((2.0, 4.0))
    assert tab.shape == (TABLE_SIZE, 4) and lo == 2.0
    xs = np.linspace(2.0, 4.0, 777)
    idx = (xs - lo) * inv
    interp = np.array([np.interp(idx, np.arange(TABLE_SIZE), tab[:, c]) for c in range(4)]).T
    rgb, a = tf.resolve((2.0, 4.0)).evaluate(xs)
    np.testing.assert_allclose(interp[:, :3], rgb, atol=1e-3)
    np.testing.assert_allclose(interp[:, 3], a, atol=1e-3)


def test_paraview_format(tmp_path):
    pv = [{"Name": "x", "RGBPoints": [100, 0, 0, 0, 200, 1, 1, 1], "Points": [100, 0, 0.5, 0, 200, 0.8, 0.5, 0]}]
    p = tmp_path / "pv.json"
    p.write_text(json.dumps(pv))
    tf = load_transfer_function(p).resolve((0.0, 1.0))
    rgb, a = tf.evaluate([0.0, 0.5, 1.0])
    np.testing.assert_allclose(rgb[:, 1], [0, 0.5, 1])
    np.testing.assert_allclose(a, [0, 0.4, 0.8])


def test_presets_and_matplotlib():
    names = preset_names()
    assert {"default", "bluntfin", "combustion", "post", "fire"} <= set(names)
    for n in names:
        tf = load_transfer_function(n)
        assert tf.unit_distance > 0
    tf = load_transfer_function("viridis").resolve((0, 1))
    rgb, _ = tf.evaluate([0.0, 1.0])
    assert rgb[0, 2] > rgb[0, 1]  # viridis starts dark blue-purple


@pytest.mark.parametrize("bad", [
    {"color": [], "opacity": [{"x": 0, "a": 0}]},
    {"color": [{"x": 0, "rgb": [0, 0]}], "opacity": [{"x": 0, "a": 0}]},
    {"color": [{"x": 1, "rgb": [0, 0, 0]}, {"x": 0, "rgb": [0, 0, 0]}], "opacity": [{"x": 0, "a": 0}]},
    {"color": [{"x": 0, "rgb": [0, 0, 2]}], "opacity": [{"x": 0, "a": 0}]},
    {"color": [{"x": 0, "rgb": [0, 0, 0]}], "opacity": [{"x": 0, "a": "high"}]},
    dict(PROJECT_TF, unit_distance=0),
    {"RGBPoints": [0, 1, 1]},
    [1, 2],
])
def test_malformed_transfer_functions(bad):
    with pytest.raises(OptionError):
        from_dict(bad)


def test_bad_names_and_files(tmp_path):
    with pytest.raises(OptionError, match="unknown name"):
        load_transfer_function("no-such-colormap-or-preset")
    with pytest.raises(OptionError, match="not found"):
        load_transfer_function(tmp_path / "missing.json")
    p = tmp_path / "broken.json"
    p.write_text("{ not json")
    with pytest.raises(OptionError, match="malformed JSON"):
        load_transfer_function(p)


def test_camera_reset_formula():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([2.0, 4.0, 6.0])
    cam = Camera(100, 100).fit(lo, hi)
    radius = 0.5 * math.sqrt(4 + 16 + 36)
    np.testing.assert_allclose(cam.focal_point, [1, 2, 3])
    np.testing.assert_allclose(cam.position, [1, 2, 3 + radius / math.sin(math.radians(15))])
    np.testing.assert_allclose(cam.view_up, [0, 1, 0])
    # azimuth 90: the camera swings to +x about the view-up
    cam = Camera(100, 100, azimuth=90).fit(lo, hi)
    d = cam.position - cam.focal_point
    np.testing.assert_allclose(d / np.linalg.norm(d), [1, 0, 0], atol=1e-12)
    # elevation 90 looks straight down; view-up is re-orthogonalised
    cam = Camera(100, 100, elevation=45).fit(lo, hi)
    d = cam.position - cam.focal_point
    np.testing.assert_allclose(d / np.linalg.norm(d), [0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
    assert abs(np.dot(cam.view_up, d)) < 1e-9
    # zoom narrows the view angle; a tall window fits the sphere horizontally
    assert Camera(100, 100, zoom=2).fit(lo, hi).view_angle == 15.0
    tall = Camera(50, 100).fit(lo, hi)
    assert np.linalg.norm(tall.position - tall.focal_point) > np.linalg.norm(cam.position - cam.focal_point)


def test_rays_and_projection_agree():
    cam = Camera(31, 21, azimuth=30, elevation=10).fit([0, 0, 0], [1, 2, 3])
    dirs = cam.ray_directions().reshape(21, 31, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=2), 1.0)
    fwd, _, _ = cam.basis()
    np.testing.assert_allclose(dirs[10, 15], fwd, atol=1e-12)  # centre pixel looks at the focal point
    for row, col in [(0, 0), (20, 30), (5, 17)]:
        p = cam.position + 7.0 * dirs[row, col]
        np.testing.assert_allclose(cam.project(p[None])[0], [col + 0.5, row + 0.5], atol=1e-9)


@pytest.mark.parametrize("kw", [dict(width=0), dict(height=-3), dict(zoom=0.0), dict(zoom=1e9), dict(azimuth=math.nan)])
def test_camera_rejects_bad_values(kw):
    with pytest.raises(OptionError):
        Camera(**kw)


def test_png_round_trip(tmp_path):
    img = np.zeros((5, 7, 4), np.float32)
    img[1, 2] = [0.5, 0.25, 1.0, 1.0]
    img[3, 4] = [2.0, -1.0, np.nan, 1.0]
    rgb = to_rgb8(img)
    assert rgb[1, 2].tolist() == [128, 64, 255] and rgb[3, 4].tolist() == [255, 0, 0]
    path = tmp_path / "x.png"
    write_png(path, img)
    np.testing.assert_array_equal(read_png_rgb(path), rgb)
    with pytest.raises(Exception):
        write_png(path, img)  # exists, no force
    assert png_bytes(rgb)[:8] == b"\x89PNG\r\n\x1a\n"
