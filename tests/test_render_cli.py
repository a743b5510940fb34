"""``tetc render`` end to end on small files: output, --stats, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from cli_util import run
from meshgen import delaunay_mesh, grid_mesh

from gatun_py.cli.main import tetc
from gatun_py.mesh import write_mesh
from gatun_py.raycast import Camera, render_mesh, to_rgb8
from gatun_py.raycast.image import read_png_rgb


@pytest.fixture
def mesh_file(tmp_path):
    mesh = grid_mesh(4, 4, 3, jitter=0.1, seed=2)
    path = tmp_path / "m.vtu"
    write_mesh(mesh, path)
    return mesh, path



def test_render_mesh_file_with_stats(mesh_file, tmp_path):
    mesh, path = mesh_file
    out = tmp_path / "o.png"
    res = run("render", path, "-o", out, "--size", "40x30", "--azimuth", "20", "--tf", "post", "--stats", "--quiet")
    assert res.exit_code == 0, res.output
    st = json.loads(res.stdout)
    for key in ("decode_s", "render_s", "total_s", "tets_rendered", "rays", "rays_unfinished", "samples", "peak_rss_mb"):
        assert key in st
    assert st["rays"] == 1200 and st["tets_rendered"] == mesh.n_tets and st["rays_unfinished"] == 0
    img = read_png_rgb(out)
    assert img.shape == (30, 40, 3)
    expect = to_rgb8(render_mesh(mesh, Camera(40, 30, azimuth=20.0), "post").image)
    assert np.abs(img.astype(int) - expect.astype(int)).max() <= 1
    # refuses to overwrite without --force
    res = CliRunner().invoke(tetc, ["render", str(path), "-o", str(out)])
    assert res.exit_code == 1 and "already exists" in res.output


def test_render_tetc_file(tmp_path):
    from gatun_py.codec import tetcfile as codec

    mesh = delaunay_mesh(60, 3)
    tetc_path = tmp_path / "m.tetc"
    codec.write_tetc(tetc_path, mesh)
    out = tmp_path / "t.png"
    res = run("render", tetc_path, "-o", out, "--size", "32", "--mode", "face", "--stats", "--quiet")
    assert res.exit_code == 0, res.output
    st = json.loads(res.stdout)
    assert st["tets_rendered"] == mesh.n_tets and st["rays_unfinished"] == 0
    expect = to_rgb8(render_mesh(mesh, Camera(32, 32), "default", mode="face").image)
    assert np.abs(read_png_rgb(out).astype(int) - expect.astype(int)).max() <= 1


@pytest.mark.parametrize("args, message", [
    (["--size", "0"], "1..8192"),
    (["--size", "-5x3"], "W or WxH"),
    (["--size", "abc"], "W or WxH"),
    (["--size", "100000"], "1..8192"),
    (["--zoom", "0"], "--zoom"),
    (["--zoom", "1e9"], "--zoom"),
    (["--zoom", "nan"], "finite"),
    (["--step", "-1"], "--step"),
    (["--step", "inf"], "finite"),
    (["--azimuth", "nan"], "finite"),
    (["--budget", "-1"], "--budget"),
    (["--ratio", "1.5"], "--ratio"),
    (["--range", "2", "1"], "MIN must be below MAX"),
    (["--background", "no-such-colour"], "unknown colour"),
])
def test_bad_option_values_are_usage_errors(mesh_file, tmp_path, args, message):
    _, path = mesh_file
    res = CliRunner().invoke(tetc, ["render", str(path), "-o", str(tmp_path / "x.png"), *args])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and message in res.output
    assert not (tmp_path / "x.png").exists()


def test_unknown_transfer_function(mesh_file, tmp_path):
    _, path = mesh_file
    res = CliRunner().invoke(tetc, ["render", str(path), "-o", str(tmp_path / "x.png"), "--tf", "nope-not-a-map"])
    assert res.exit_code == 1 and "tetc: error:" in res.output and "unknown name" in res.output
    assert not (tmp_path / "x.png").exists()


def test_malformed_tf_json(mesh_file, tmp_path):
    _, path = mesh_file
    tf = tmp_path / "tf.json"
    tf.write_text('{"color": [}')
    res = CliRunner().invoke(tetc, ["render", str(path), "-o", str(tmp_path / "x.png"), "--tf", str(tf)])
    assert res.exit_code == 1 and "malformed JSON" in res.output


def test_missing_input_fails_before_any_compiling(tmp_path, monkeypatch):
    """With an empty numba cache a missing input must not first cost a minute of compiling."""
    import gatun_py.warmup as warmup

    def refuse(**_):
        raise AssertionError("compiled or loaded kernels for a missing input")

    import gatun_py._compile_notice as notice

    monkeypatch.setattr(notice, "uncached", lambda parts: list(parts))
    monkeypatch.setattr(warmup, "compile_for_render", refuse)
    monkeypatch.setattr(warmup, "load_kernels", refuse)
    res = run("render", tmp_path / "none.tetc", "-o", tmp_path / "o.png")
    assert res.exit_code == 1
    assert "no such file" in res.output
    assert not (tmp_path / "o.png").exists()
