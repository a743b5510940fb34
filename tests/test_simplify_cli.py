"""`tetc compress` with levels and forest, `tetc decompress --ratio/--level`, `tetc info` levels/forest."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_util import assert_error, assert_usage_error, run
from conftest import SAMPLES, load_sample
from meshgen import single_tet

from gatun_py.codec import TetcReader
from gatun_py.mesh import read_mesh, write_mesh
from gatun_py.simplify import build_levels, decimate, level_merges, simplified_mesh

POST = str(SAMPLES / "lox_post_tets" / "post.vtk")




def _canonical(mesh):
    """A vertex-order-free description of a mesh: tets as sorted tuples of float bit patterns."""
    key = np.concatenate([mesh.points.view(np.uint32), mesh.density.view(np.uint32)[:, None]], axis=1)
    return sorted(tuple(sorted(map(tuple, key[t]))) for t in mesh.tets)




def test_info_lists_levels_and_forest(post_tetc):
    res = run("info", post_tetc, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    mesh = load_sample("post")[0]
    forest = decimate(mesh)
    levels = build_levels(mesh, forest)
    assert [lv["level"] for lv in d["levels"]] == [lv.level for lv in levels]
    for got, lv in zip(d["levels"], levels):
        assert got["points"] == lv.mesh.n_points and got["tets"] == lv.mesh.n_tets
        assert got["ratio"] == pytest.approx(lv.ratio) and got["bytes"] > 0
    assert d["forest"]["merges"] == forest.n_merges
    # levels in between store only the merges up to the next level
    from gatun_py.codec import TetcReader
    from gatun_py.simplify import ROOT_RANK

    reader = TetcReader(post_tetc)
    for j, lv in enumerate(levels):
        _, rank = reader.read_forest(lv.level)
        stored = int((rank != ROOT_RANK).sum())
        want = (forest.n_merges - lv.n_merges if j in (0, len(levels) - 1)
                else levels[j + 1].n_merges - lv.n_merges)
        assert stored == want
    assert d["forest"]["max_ratio"] == pytest.approx(forest.max_ratio)
    assert d["forest"]["bytes"] > 0


@pytest.mark.parametrize("ratio", [0.0, 0.3, 0.5, 0.9, 0.97])
def test_decompress_ratio_equals_simplified_mesh(post_tetc, tmp_path, ratio):
    mesh = load_sample("post")[0]
    forest = decimate(mesh)
    want = simplified_mesh(mesh, forest, int(np.floor(ratio * mesh.n_points)))
    out = tmp_path / "s.vtu"
    res = run("decompress", post_tetc, "-o", out, "--ratio", ratio, "--quiet")
    assert res.exit_code == 0, res.output
    got, _ = read_mesh(out, scalar="Pressure")
    assert got.n_points == want.n_points and got.n_tets == want.n_tets
    assert _canonical(got) == _canonical(want)


def test_decompress_level(post_tetc, tmp_path):
    mesh = load_sample("post")[0]
    want = simplified_mesh(mesh, decimate(mesh), level_merges(mesh.n_points, 3))
    out = tmp_path / "l3.vtu"
    assert run("decompress", post_tetc, "-o", out, "--level", 3, "--quiet").exit_code == 0
    got, _ = read_mesh(out, scalar="Pressure")
    assert _canonical(got) == _canonical(want)


def test_impossible_requests(post_tetc, tmp_path):
    out = tmp_path / "x.vtu"
    assert_usage_error(run("decompress", post_tetc, "-o", out, "--ratio", 1.5), "--ratio", "<= 1")
    assert_usage_error(run("decompress", post_tetc, "-o", out, "--ratio", -0.1), "--ratio", ">= 0")
    assert_error(run("decompress", post_tetc, "-o", out, "--level", 40), "level 40 is not stored", "4 (ratio")
    assert_error(run("decompress", post_tetc, "-o", out, "--ratio", 0.9999), "maximum ratio", "stored levels")
    assert_usage_error(run("decompress", post_tetc, "-o", out, "--ratio", 0.5, "--level", 1), "exclusive")
    assert not out.exists()


def test_levels_option_and_mesh_only(tmp_path):
    two = tmp_path / "two.tetc"
    assert run("compress", POST, "-o", two, "--levels", 2, "--quiet").exit_code == 0
    d = json.loads(run("info", two, "--json").output)
    assert [lv["level"] for lv in d["levels"]] == [0, 1, 2]
    # beyond the stored levels the forest still reaches further
    out = tmp_path / "s.vtu"
    assert run("decompress", two, "-o", out, "--ratio", 0.95, "--quiet").exit_code == 0

    bare = tmp_path / "bare.tetc"
    assert run("compress", POST, "-o", bare, "--mesh-only", "--quiet").exit_code == 0
    d = json.loads(run("info", bare, "--json").output)
    assert [lv["level"] for lv in d["levels"]] == [0]
    assert d["forest"] == {"merges": 0, "max_ratio": 0.0, "bytes": 0}
    assert_error(run("decompress", bare, "-o", out, "--ratio", 0.5, "--force"), "no merge forest")
    assert run("decompress", bare, "-o", out, "--ratio", 0.0, "--force", "--quiet").exit_code == 0


def test_weights_are_options(tmp_path):
    out = tmp_path / "w.tetc"
    assert run("compress", POST, "-o", out, "--w-density", 2, "--w-geometry", 0, "--levels", 1,
               "--quiet").exit_code == 0
    assert run("compress", POST, "-o", out, "--w-density", -1, "--force").exit_code == 2  # click range
    assert run("compress", POST, "-o", out, "--w-sample", -1, "--force").exit_code == 2
    # without the sampled error: another forest, the same lossless mesh
    fast = tmp_path / "fast.tetc"
    assert run("compress", POST, "-o", out, "--levels", 1, "--force", "--quiet").exit_code == 0
    assert run("compress", POST, "-o", fast, "--levels", 1, "--w-sample", 0, "--quiet").exit_code == 0
    a, b = TetcReader(out), TetcReader(fast)
    assert a.read_section("L0/forest") != b.read_section("L0/forest")
    ma, mb = a.decode_mesh(), b.decode_mesh()
    assert np.array_equal(ma.tets, mb.tets) and np.array_equal(ma.points, mb.points)
    assert np.array_equal(ma.density, mb.density)


def test_single_tet_compresses_with_a_forest_of_roots(tmp_path):
    src = tmp_path / "one.vtu"
    write_mesh(single_tet(), src)
    out = tmp_path / "one.tetc"
    res = run("compress", src, "-o", out, "--quiet")
    assert res.exit_code == 0, res.output
    d = json.loads(run("info", out, "--json").output)
    assert [lv["level"] for lv in d["levels"]] == [0]
    assert d["forest"]["merges"] == 0
    assert_error(run("decompress", out, "-o", tmp_path / "x.vtu", "--ratio", 0.5), "maximum ratio 0.000000")
