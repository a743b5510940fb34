"""The ``vtk`` opacity model (VTK's unstructured-grid ray caster) against closed forms; no vtk needed.

VTK's ``vtkUnstructuredGridPartialPreIntegration`` reads the opacity ``a`` as an attenuation
coefficient ``a / unit_distance`` (a path of length L has opacity ``1 - exp(-a L / u)``), and reads the
opacity function only at the colour function's points, the first opacity point and the data-range
ends. Measured with VTK 9.7 on the same slabs (bench/bench_render.py, "What VTK computes").
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_util import run
from meshgen import grid_mesh
from naive_render import naive_render

from gatun_py.errors import OptionError
from gatun_py.mesh import TetMesh, write_mesh
from gatun_py.raycast import FittedCamera, render_mesh
from gatun_py.raycast.image import read_png_rgb
from gatun_py.raycast.transfer import from_dict, load_transfer_function, vtk_opacity_points

COLOUR = [0.2, 0.6, 1.0]
THICK = 2.0  # the slab is grid_mesh(4, 4, 3): [0, 3] x [0, 3] x [0, 2]


def slab(value: float) -> TetMesh:
    """A box of constant scalar, seen face on by ``CAMERA``."""
    g = grid_mesh(4, 4, 3)
    return TetMesh(g.points, np.full(g.n_points, value, np.float32), g.tets)


CAMERA = FittedCamera(9, 9, np.array([1.5, 1.5, 10.0]), np.array([1.5, 1.5, 1.0]), np.array([0.0, 1.0, 0.0]), 30.0)


def path_lengths():
    """Length of the slab along the rays of the central 3 x 3 pixels (they cross both big faces)."""
    d = CAMERA.ray_directions().reshape(9, 9, 3)[3:6, 3:6]
    return THICK / np.abs(d[..., 2])


def tf(opacity, colour_x=(0.0, 1.0), model="vtk", unit=0.7, absolute=False):
    return from_dict({"color": [{"x": x, "rgb": COLOUR} for x in colour_x],
                      "opacity": [{"x": x, "a": a} for x, a in opacity], "unit_distance": unit,
                      "opacity_model": model, "absolute": absolute})


def centre(res):
    return res.image[3:6, 3:6]


def check_premultiplied(px, alpha, atol):
    np.testing.assert_allclose(px[..., 3], alpha, atol=atol, rtol=0)
    np.testing.assert_allclose(px[..., :3], alpha[..., None] * np.array(COLOUR), atol=atol, rtol=0)


@pytest.mark.parametrize("mode", ["face", "volume"])
@pytest.mark.parametrize("a", [0.1, 0.45, 1.0])
def test_constant_slab_is_exponential_attenuation(mode, a):
    unit, step = 0.7, 0.004
    L = path_lengths()
    res = render_mesh(slab(0.5), CAMERA, tf([(0.0, a), (1.0, a)], unit=unit), mode=mode, step=step,
                      scalar_range=(0.0, 1.0))
    # volume mode: each sample stands for one step, so the path is counted to within a step
    atol = 1e-5 if mode == "face" else a / unit * step
    check_premultiplied(centre(res), 1.0 - np.exp(-a * L / unit), atol)
    gatun = render_mesh(slab(0.5), CAMERA, tf([(0.0, a), (1.0, a)], model="gatun", unit=unit), mode=mode,
                        step=step, scalar_range=(0.0, 1.0))
    check_premultiplied(centre(gatun), 1.0 - (1.0 - a) ** (L / unit), atol)


@pytest.mark.parametrize("mode", ["face", "volume"])
def test_opacity_read_only_at_colour_points(mode):
    # a tent of opacity peaking at 0.5; colour points only at the ends, data range [0, 1]
    tent = [(0.0, 0.0), (0.5, 0.6), (1.0, 0.0)]
    L, unit, step = path_lengths(), 0.7, 0.004
    atol = 1e-5 if mode == "face" else 0.48 / unit * step
    kw = dict(mode=mode, step=step, scalar_range=(0.0, 1.0))
    # VTK sees the opacity at 0 and 1 only (both 0): the slab at 0.4 is invisible
    res = render_mesh(slab(0.4), CAMERA, tf(tent), **kw)
    assert np.abs(res.image).max() == 0.0
    # ... while our model shows the opacity there, 0.48
    res = render_mesh(slab(0.4), CAMERA, tf(tent, model="gatun"), **kw)
    check_premultiplied(centre(res), 1.0 - (1.0 - 0.48) ** (L / unit), atol)
    # a colour point at 0.5 puts the peak back into VTK's control points
    res = render_mesh(slab(0.4), CAMERA, tf(tent, colour_x=(0.0, 0.5, 1.0)), **kw)
    check_premultiplied(centre(res), 1.0 - np.exp(-0.48 * L / unit), atol)
    # the data range ends are control points too: with the range [0.4, 1] (function in absolute
    # units) 0.4 is one, and the opacity there is exact again
    res = render_mesh(slab(0.4), CAMERA, tf(tent, absolute=True), mode=mode, step=step, scalar_range=(0.4, 1.0))
    check_premultiplied(centre(res), 1.0 - np.exp(-0.48 * L / unit), atol)


def test_vtk_opacity_points():
    # Blunt-fin's function (normalised x): opacity points at 0.12, 0.25, 0.5 are not colour points
    x, a = vtk_opacity_points([0.0, 0.15, 0.35, 0.6, 1.0], [0.0, 0.12, 0.25, 0.5, 1.0],
                              [0.0, 0.0, 0.05, 0.3, 0.8], (0.0, 1.0))
    np.testing.assert_allclose(x, [0.0, 0.15, 0.35, 0.6, 1.0])
    np.testing.assert_allclose(a, [0.0, 0.03 / 0.13 * 0.05, 0.15, 0.4, 0.8])
    # the first opacity point and the range ends are kept, the rest dropped
    x, _ = vtk_opacity_points([0.2, 0.8], [0.1, 0.5, 0.9], [0.0, 1.0, 0.0], (-1.0, 2.0))
    np.testing.assert_allclose(x, [-1.0, 0.1, 0.2, 0.8, 2.0])


def test_resolve_and_table_follow_the_model():
    base = load_transfer_function("bluntfin")
    assert base.opacity_model == "gatun"
    v = base.with_opacity_model("vtk")
    r1 = v.resolve((1.0, 3.0))
    r2 = r1.resolve((1.0, 3.0))  # idempotent for the same range
    assert np.array_equal(r2.opacity_x, r1.opacity_x) and np.array_equal(r2.opacity_a, r1.opacity_a)
    s = np.linspace(1.0, 3.0, 101)
    _, a_gatun = base.resolve((1.0, 3.0)).evaluate(s)
    _, a_vtk = r1.evaluate(s)
    x, a = vtk_opacity_points(base.resolve((1.0, 3.0)).color_x, base.resolve((1.0, 3.0)).opacity_x,
                              base.opacity_a, (1.0, 3.0))
    np.testing.assert_allclose(a_vtk, 1.0 - np.exp(-np.interp(s, x, a)))
    assert not np.allclose(a_vtk, a_gatun)
    tab, lo, inv = v.table((1.0, 3.0))
    np.testing.assert_allclose(tab[:, 3], 1.0 - np.exp(-np.interp(np.linspace(1.0, 3.0, len(tab)), x, a)))


def test_vtk_model_matches_reference():
    mesh = grid_mesh(4, 3, 3, jitter=0.15, seed=4)
    used = np.unique(mesh.boundary_faces())
    from gatun_py.raycast import Camera

    cam = Camera(12, 10, azimuth=25.0, elevation=10.0).fit(mesh.points[used].min(axis=0),
                                                            mesh.points[used].max(axis=0))
    t = load_transfer_function("post").with_opacity_model("vtk")
    for mode in ("volume", "face"):
        ours = render_mesh(mesh, cam, t, mode=mode).image
        ref = naive_render(mesh, cam, t, mode=mode)
        assert np.abs(ours.reshape(ref.shape) - ref).max() <= 1e-5


def test_bad_model():
    with pytest.raises(OptionError, match="opacity_model"):
        from_dict({"color": [{"x": 0, "rgb": [1, 1, 1]}], "opacity": [{"x": 0, "a": 0.5}], "opacity_model": "x"})
    with pytest.raises(OptionError, match="opacity model"):
        load_transfer_function("default").with_opacity_model("linear")


def test_cli_opacity_model(tmp_path):
    path = tmp_path / "m.vtu"
    write_mesh(slab(0.5), path)
    spec = tmp_path / "tf.json"
    spec.write_text(json.dumps({"color": [{"x": 0, "rgb": [1, 1, 1]}, {"x": 1, "rgb": [1, 1, 1]}],
                                "opacity": [{"x": 0, "a": 0.6}, {"x": 1, "a": 0.6}], "unit_distance": 1.0}))
    px = {}
    for model in ("gatun", "vtk"):
        out = tmp_path / f"{model}.png"
        res = run("render", path, "-o", out, "--size", "9", "--tf", spec, "--opacity-model", model, "--quiet")
        assert res.exit_code == 0, res.output
        px[model] = read_png_rgb(out)[4, 4, 0] / 255.0
    # the default camera looks down the slab's thinnest side (2 units) along the view axis
    assert abs(px["gatun"] - (1 - 0.4 ** 2)) < 0.01 and abs(px["vtk"] - (1 - np.exp(-1.2))) < 0.01
    res = run("render", path, "-o", tmp_path / "x.png", "--opacity-model", "linear")
    assert res.exit_code != 0 and "opacity-model" in res.output
