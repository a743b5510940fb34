"""`tetc isosurface`: outputs, exit codes and messages."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from cli_util import assert_error, assert_usage_error, run
from conftest import SAMPLE_FILES, load_sample

from gatun_py.raycast.image import read_png_rgb

POST = SAMPLE_FILES["post"][0]


def _mid(frac=0.5):
    lo, hi = load_sample("post")[0].scalar_range
    return lo + frac * (hi - lo)


@pytest.mark.parametrize("ext", [".ply", ".vtp", ".obj", ".stl", ".vtk"])
def test_writes_every_format(tmp_path, post_tetc, ext):
    out = tmp_path / f"iso{ext}"
    res = run("isosurface", post_tetc, "--value", _mid(), "-o", out, "--quiet")
    assert res.exit_code == 0, res.output
    assert res.output == ""
    if ext == ".vtp":
        vtk = pytest.importorskip("vtk", reason="reading .vtp back needs VTK (the vtk extra)")
        r = vtk.vtkXMLPolyDataReader()
        r.SetFileName(str(out))
        r.Update()
        n_tri = r.GetOutput().GetNumberOfPolys()
        assert r.GetOutput().GetPointData().GetArray("gradient_magnitude") is not None
    else:
        m = meshio.read(out)
        n_tri = sum(len(c.data) for c in m.cells if c.type == "triangle")
    from gatun_py.contour import isosurface

    assert n_tri == isosurface(post_tetc, values=_mid()).n_triangles > 0


def test_ratio_png_and_stats(tmp_path, post_tetc):
    out, png = tmp_path / "iso.ply", tmp_path / "iso.png"
    res = run("isosurface", post_tetc, "--value", _mid(0.3), "--value", _mid(0.6), "--ratio", 0.2, "-o", out,
              "--png", png, "--size", "96x64", "--azimuth", 30, "--stats", "--quiet")
    assert res.exit_code == 0, res.output
    st = json.loads(res.output)
    assert st["faces"] <= 0.2 * st["faces_extracted"] * 1.5 + 20
    assert st["band"] and {"tets", "locked", "faces", "rss_mb"} <= set(st["band"][0])
    img = read_png_rgb(png)
    assert img.shape == (64, 96, 3) and img.any()


def test_mesh_file_input_and_simplified_start(tmp_path, post_tetc):
    res = run("isosurface", POST, "--value", _mid(), "-o", tmp_path / "a.ply", "--quiet")
    assert res.exit_code == 0, res.output
    res = run("isosurface", post_tetc, "--value", _mid(), "--level", 1, "-o", tmp_path / "b.ply", "--quiet")
    assert res.exit_code == 0, res.output
    res = run("isosurface", POST, "--value", _mid(), "--level", 1, "-o", tmp_path / "c.ply")
    assert_error(res, ".tetc")


def test_value_outside_range_is_an_empty_surface(tmp_path, post_tetc):
    out = tmp_path / "e.ply"
    res = run("isosurface", post_tetc, "--value", 1e9, "-o", out)
    assert res.exit_code == 0, res.output
    assert "outside the scalar range" in res.output and out.exists()


@pytest.mark.parametrize("args", [["--value", "nan"], ["--value", 1, "--ratio", 0], ["--value", 1, "--ratio", 1.5],
                                  ["--value", 1, "--ratio", 0.5, "--faces", 10], []])
def test_usage_errors(tmp_path, post_tetc, args):
    res = run("isosurface", post_tetc, *args, "-o", tmp_path / "x.ply")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output


def test_errors(tmp_path, post_tetc):
    res = run("isosurface", post_tetc, "--value", 1, "-o", tmp_path / "x.xyz")
    assert_error(res, ".vtp", ".ply", ".stl")
    out = tmp_path / "x.ply"
    out.write_text("keep")
    res = run("isosurface", post_tetc, "--value", 1, "-o", out)
    assert_error(res, "--force")
    assert out.read_text() == "keep"
    res = run("isosurface", tmp_path / "missing.tetc", "--value", 1, "-o", tmp_path / "y.ply")
    assert res.exit_code == 1 and "tetc: error:" in res.output
    bad = tmp_path / "imp.json"
    bad.write_text('{"points": []}')
    res = run("isosurface", post_tetc, "--value", 1, "--ratio", 0.5, "--importance-tf", bad, "-o", tmp_path / "z.ply")
    assert_error(res, "importance")
    assert not (tmp_path / "z.ply").exists()


def test_help_mentions_the_essentials():
    res = run("isosurface", "--help")
    assert res.exit_code == 0
    for word in ("--value", "--ratio", "--faces", "--batch-faces", "--importance-tf", "--png", "--stats"):
        assert word in res.output
    assert np.isfinite(_mid())


def test_preview_options_are_checked_before_the_work(tmp_path, post_tetc):
    """A preview nobody can write fails at once, and no surface is left behind."""
    out = tmp_path / "iso.ply"
    res = run("isosurface", post_tetc, "--value", _mid(), "-o", out, "--png", tmp_path / "iso.xyz")
    assert_error(res, "choose one of")
    res = run("isosurface", post_tetc, "--value", _mid(), "-o", out, "--png", tmp_path / "iso.png",
              "--size", "100000x100000")
    assert_usage_error(res, "pixels")
    assert not out.exists()


def test_surface_preview_matches_the_cli_png(tmp_path, post_tetc):
    """The library's Surface.preview is what the CLI writes (one code path)."""
    from gatun_py.contour import isosurface

    png = tmp_path / "iso.png"
    res = run("isosurface", post_tetc, "--value", _mid(), "-o", tmp_path / "iso.ply", "--png", png, "--size", "80x60",
              "--elevation", 25, "--quiet")
    assert res.exit_code == 0, res.output
    want = isosurface(post_tetc, values=_mid()).preview(size=(80, 60), elevation=25)
    np.testing.assert_array_equal(read_png_rgb(png), want)


def test_the_preview_frames_the_surface_unless_asked_for_the_volume(tmp_path, post_tetc):
    """A surface in a corner of the mesh fills the default preview (its lit pixels span most of the
    picture), and --frame-volume shows it where tetc render would, smaller."""
    from gatun_py.contour import isosurface

    lo, hi = json.loads(run("info", post_tetc, "--json").output)["scalar_range"]
    surf = isosurface(post_tetc, values=lo + 0.7 * (hi - lo))
    assert surf.n_triangles > 0
    spans = {}
    for frame in ("surface", "volume"):
        lit = surf.preview(size=96, frame=frame).sum(axis=2) > 0
        rows, cols = np.nonzero(lit)
        spans[frame] = max(rows.max() - rows.min(), cols.max() - cols.min()) + 1
    assert spans["surface"] >= 0.5 * 96 and spans["surface"] > 4 * spans["volume"], spans
    png = tmp_path / "v.png"
    res = run("isosurface", post_tetc, "--value", lo + 0.7 * (hi - lo), "-o", tmp_path / "v.ply", "--png", png,
              "--size", 96, "--frame-volume", "--quiet")
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_png_rgb(png), surf.preview(size=96, frame="volume"))
