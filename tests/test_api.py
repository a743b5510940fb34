"""The public verbs: gatun_py.compress / open / render / decompress, Frame, TetcFile, meshio."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

import gatun_py
from cli_util import run
from gatun_py.raycast.image import read_png_rgb
from samples import SAMPLES

POST = SAMPLES["post"][0]


@pytest.fixture(scope="module")
def post_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "post.tetc"
    return gatun_py.compress(POST, out, levels=3)


def test_compress_accepts_paths_meshes_and_meshio(tmp_path, small_sample):
    m = small_sample
    from_mesh = gatun_py.compress(m, tmp_path / "a.tetc", mesh_only=True)
    mio = meshio.Mesh(m.points, [("tetra", m.tets)], point_data={"Pressure": m.density})
    from_meshio = gatun_py.compress(mio, tmp_path / "b.tetc", mesh_only=True)
    for f in (from_mesh, from_meshio):
        assert isinstance(f, gatun_py.TetcFile)
        back = f.mesh()
        assert (back.n_points, back.n_tets) == (m.n_points, m.n_tets)
        assert sorted(back.density.tobytes()) == sorted(m.density.tobytes())
    assert from_meshio.scalar_name == "Pressure"


def test_open_info_levels_mesh_and_stream(post_file, tmp_path):
    f = gatun_py.open(post_file.path)
    assert f.levels == [0, 1, 2, 3]
    assert f.info == json.loads(run("info", f.path, "--json").output)
    assert "TetcFile(" in repr(f) and "levels=[0, 1, 2, 3]" in repr(f)
    assert sum(len(b.tets) for b in f) == f.n_tets
    m90 = f.mesh(0.9)
    out = tmp_path / "d.vtu"
    assert run("decompress", f.path, "-o", out, "--ratio", 0.9, "--quiet").exit_code == 0
    back, _ = gatun_py.read_mesh(out)
    assert back.n_tets == m90.n_tets and back.points.tobytes() == m90.points.tobytes()
    # the simplified stream carries exactly the simplified mesh's tets
    assert sum(len(b.tets) for b in f.batches(ratio=0.9)) == m90.n_tets


def test_render_frame_equals_the_command(post_file, tmp_path):
    frame = gatun_py.render(post_file.path, size=(48, 40), tf="post", azimuth=30, elevation=20, ratio=0.5)
    assert frame.rgb.shape == (40, 48, 3) and frame.rgb.dtype == np.uint8
    assert frame.stats["ratio"] == pytest.approx(0.5, abs=1e-3) and frame.stats["rays_unfinished"] == 0
    out = tmp_path / "c.png"
    res = run("render", post_file.path, "-o", out, "--size", "48x40", "--tf", "post", "--azimuth", 30,
              "--elevation", 20, "--ratio", 0.5, "--quiet")
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_png_rgb(out), frame.rgb)
    assert frame._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"
    same = post_file.render(size=(48, 40), tf="post", azimuth=30, elevation=20, ratio=0.5)
    np.testing.assert_array_equal(same.rgb, frame.rgb)


def test_render_a_mesh_in_memory_equals_the_file(small_sample, post_file):
    a = gatun_py.render(small_sample, size=32, tf="post")
    b = gatun_py.render(post_file, size=32, tf="post")
    assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max() <= 1


def test_background_range_and_colorbar(post_file):
    plain = gatun_py.render(post_file, size=32, tf="post")
    white = gatun_py.render(post_file, size=32, tf="post", background="white")
    empty = plain.image[..., 3] == 0
    assert empty.any() and (white.rgb[empty] == 255).all() and (plain.rgb[empty] == 0).all()
    lo, hi = plain.stats["scalar_range"]
    wide = gatun_py.render(post_file, size=32, tf="post", scalar_range=(lo - (hi - lo), hi))
    assert wide.stats["scalar_range"] == [lo - (hi - lo), hi]
    assert not np.array_equal(wide.rgb, plain.rgb)
    bar = gatun_py.render(post_file, size=64, tf="post", colorbar=True)
    assert bar.rgb.shape[0] == 64 and bar.rgb.shape[1] > 64
    np.testing.assert_array_equal(bar.rgb[:, :64], gatun_py.render(post_file, size=64, tf="post").rgb)


def test_image_formats_follow_the_extension(post_file, tmp_path):
    frame = gatun_py.render(post_file, size=16, tf="post")
    frame.save(tmp_path / "x.jpg")
    assert (tmp_path / "x.jpg").read_bytes()[:3] == b"\xff\xd8\xff"
    frame.save(tmp_path / "x.webp")
    assert (tmp_path / "x.webp").read_bytes()[8:12] == b"WEBP"
    with pytest.raises(gatun_py.OutputError, match="choose one of"):
        frame.save(tmp_path / "x.gif")
    with pytest.raises(gatun_py.OutputExistsError):
        frame.save(tmp_path / "x.jpg")


@pytest.mark.parametrize("kwargs, message", [
    (dict(size=0), "image size"),
    (dict(size=(10, 10**6)), "image size"),
    (dict(step=1e-300 * 0), "step"),
    (dict(zoom=float("nan")), "zoom"),
    (dict(ratio=1.5), "ratio"),
    (dict(budget=-1), "budget"),
    (dict(ratio=0.5, level=1), "at most one"),
    (dict(scalar_range=(2, 1)), "scalar_range"),
    (dict(mode="x-ray"), "mode"),
    (dict(background="nope"), "colour"),
])
def test_render_validates_its_arguments(post_file, kwargs, message):
    with pytest.raises(gatun_py.OptionError, match=message) as e:
        gatun_py.render(post_file, **kwargs)
    assert isinstance(e.value, ValueError)


def test_typed_errors_are_builtin_errors_too(tmp_path):
    with pytest.raises(OSError):
        gatun_py.open(tmp_path / "missing.tetc")
    (tmp_path / "bad.tetc").write_bytes(b"not a tetc file at all")
    with pytest.raises(ValueError):
        gatun_py.open(tmp_path / "bad.tetc")
    with pytest.raises(gatun_py.OptionError, match="input file"):
        gatun_py.compress(POST, POST, force=True)


def test_meshio_reads_and_writes_tetc(post_file, tmp_path, small_sample):
    m = meshio.read(post_file.path)
    ref = post_file.mesh()
    assert m.cells[0].type == "tetra" and len(m.cells[0].data) == ref.n_tets
    np.testing.assert_array_equal(m.point_data[ref.scalar_name], ref.density)
    out = tmp_path / "w.tetc"
    meshio.write(out, meshio.Mesh(small_sample.points, [("tetra", small_sample.tets)],
                                  point_data={"p": small_sample.density}), mesh_only=True)
    assert gatun_py.open(out).mesh().n_tets == small_sample.n_tets


def test_import_is_light_and_the_verbs_document_themselves():
    import pydoc
    import subprocess
    import sys

    code = "import sys, gatun_py; print('numba' in sys.modules, 'gatun_py.api' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["False", "False"], out
    # the verbs and the cluster code load Dask only when a cluster is made
    code = ("import sys, gatun_py.api, gatun_py.pipeline.distributed; "
            "print('dask' in sys.modules, 'distributed' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["False", "False"], out
    text = pydoc.render_doc(gatun_py.render, renderer=pydoc.plaintext)
    assert "Volume-render a mesh" in text and "render(source, *, view:" in text
    assert callable(gatun_py.open) and gatun_py.TetcFile.__name__ == "TetcFile"
