"""`tetc render` with --ratio / --level / --budget / --pipeline: exit codes, messages, stats."""

import json

import numpy as np
import pytest

from cli_util import run
from conftest import SAMPLES
from gatun_py.codec import TetcReader
from gatun_py.pipeline.quality import read_rgb

POST = str(SAMPLES / "lox_post_tets" / "post.vtk")





def _render(post_tetc, out, *extra):
    res = run("render", post_tetc, "-o", out, "--tf", "post", "--size", "40x32", "--stats", "-q", *extra)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def test_ratio_streaming_equals_generic(post_tetc, tmp_path):
    s = _render(post_tetc, tmp_path / "s.png", "--ratio", "0.8")
    g = _render(post_tetc, tmp_path / "g.png", "--ratio", "0.8", "--pipeline", "generic")
    assert np.array_equal(read_rgb(tmp_path / "s.png"), read_rgb(tmp_path / "g.png"))
    for key in ("startup_s", "decode_s", "filter_s", "render_s", "total_s", "level", "ratio", "tets_rendered", "rays",
                "rays_unfinished", "samples", "peak_rss_mb"):
        assert key in s
    assert s["ratio"] == pytest.approx(0.8, abs=1e-3) and s["level"] >= 2
    assert s["tets_rendered"] == g["tets_rendered"] < 8750
    assert s["rays_unfinished"] == 0


def test_lean_render_is_the_same_image(post_tetc, tmp_path):
    lean = _render(post_tetc, tmp_path / "lean.png", "--ratio", "0.5", "--lean", "--size", "96x80")
    full = _render(post_tetc, tmp_path / "full.png", "--ratio", "0.5", "--no-lean", "--size", "96x80")
    assert lean["lean"] is True and full["lean"] is False
    assert lean["rays_unfinished"] == full["rays_unfinished"] == 0
    assert np.array_equal(read_rgb(tmp_path / "lean.png"), read_rgb(tmp_path / "full.png"))


def test_level_and_budget(post_tetc, tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path / "cache"))
    lv = _render(post_tetc, tmp_path / "l.png", "--level", "2")
    assert lv["level"] == 2
    b = _render(post_tetc, tmp_path / "b.png", "--budget", "5")
    assert b["budget_s"] == 5 and "predicted_s" in b
    assert (tmp_path / "cache" / "costs.json").exists()  # the machine's costs, kept for next time (not per file)
    assert b["level"] == 0  # a generous budget renders the full mesh
    res = run("render", post_tetc, "-o", tmp_path / "z.png", "--tf", "post", "--size", "40x32", "--budget", "1e-9",
              "--stats")
    assert res.exit_code == 0
    assert "cannot be met" in res.stderr and "scaling it up" in res.stderr
    coarsest = max(int(lv["level"]) for lv in TetcReader(post_tetc).levels)
    st = json.loads(res.stdout)
    assert st["level"] == coarsest and st["image_scale"] < 1
    assert read_rgb(tmp_path / "z.png").shape == (32, 40, 3)  # the size asked for, scaled up


def test_bad_combinations(post_tetc, tmp_path):
    res = run("render", post_tetc, "-o", tmp_path / "x.png", "--ratio", "0.5", "--budget", "0.1")
    assert res.exit_code == 2
    res = run("render", post_tetc, "-o", tmp_path / "x.png", "--ratio", "1.5")
    assert res.exit_code == 2 and "--ratio" in res.output
    res = run("render", post_tetc, "-o", tmp_path / "x.png", "--ratio", "0.9999")
    assert res.exit_code == 1 and "maximum ratio" in res.output and "stored levels: 0 (ratio 0" in res.output
    res = run("render", post_tetc, "-o", tmp_path / "x.png", "--level", "40")
    assert res.exit_code == 1 and "level 40 is not stored" in res.output
    res = run("render", POST, "-o", tmp_path / "x.png", "--ratio", "0.5")
    assert res.exit_code == 1 and "need a .tetc file" in res.output
    assert not (tmp_path / "x.png").exists()
