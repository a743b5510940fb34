"""Selective refinement end to end: the stored dependencies, closed cuts from the file, streaming
selective render == in-memory render of the written mesh, the TF-change cache, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_util import assert_usage_error, run
from naive_simplify import check_valid

import gatun_py
from gatun_py.codec import TetcReader
from gatun_py.codec.dependencies import decode_dependencies, encode_dependencies
from gatun_py.errors import CorruptFileError, OptionError
from gatun_py.mesh import read_mesh
from gatun_py.pipeline.selective import (EPS, FACTORS, choose_cut, merge_importance, plan_cut, render_selective,
                                         selective_mesh, selective_source, uniform_cut)
from gatun_py.pipeline.stream import View, file_render_defaults
from gatun_py.raycast.camera import Camera
from gatun_py.raycast.caster import render_mesh
from gatun_py.raycast.transfer import load_transfer_function
from gatun_py.simplify.dependencies import merge_dependencies

TOL = 1e-5
VIEW = View(Camera(48, 40, 30, 20), tf="post")


def _tet_key(m):
    """The mesh's tets as sorted coordinate tuples: equal for the same tets in any order."""
    return sorted(map(tuple, np.sort(m.points[m.tets].reshape(-1, 12), axis=1).tolist()))


@pytest.fixture(scope="module")
def reader(post_deps_tetc):
    return TetcReader(post_deps_tetc)


def test_stored_dependencies_are_those_of_the_decoded_mesh(reader):
    """Round trip: the deps section equals the dependencies recomputed from level 0 and its forest."""
    deps = reader.read_dependencies()
    assert reader.container.major >= 3 and reader.meta["dependencies"]["merges"] == reader.forest_merges()
    again = merge_dependencies(reader.decode_mesh(0), reader.read_forest(0))
    for a, b in zip(deps, (again.ptr, again.idx, again.removed)):
        assert np.array_equal(a, b)


def test_dependency_coding_round_trip_and_errors():
    rng = np.random.default_rng(3)
    k = 500
    rows = [np.unique(rng.integers(0, max(i, 1), rng.integers(0, 6))) if i else np.zeros(0, int) for i in range(k)]
    ptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
    idx = np.concatenate(rows).astype(np.int32)
    removed = rng.integers(1, 5, k).astype(np.int32)
    data = encode_dependencies(ptr, idx, removed)
    p, i, r = decode_dependencies(data, k, int(removed.sum()))
    assert np.array_equal(p, ptr) and np.array_equal(i, idx) and np.array_equal(r, removed)
    with pytest.raises(CorruptFileError):
        decode_dependencies(data, k + 1, int(removed.sum()))
    with pytest.raises(CorruptFileError):
        decode_dependencies(data, k, int(removed.sum()) - 1)  # removes more tets than the mesh has
    with pytest.raises(CorruptFileError):
        decode_dependencies(data[:-3], k, int(removed.sum()))
    with pytest.raises(ValueError):
        encode_dependencies(ptr, np.where(idx >= 0, k, idx), removed)  # a merge depending on a later one


@pytest.mark.parametrize("tets", [300, 1200, 4000])
def test_streaming_selective_equals_render_of_the_written_mesh(reader, post_deps_tetc, tmp_path, tets):
    res = render_selective(reader, VIEW, tets=tets)
    st = res.stats
    assert st["selective"] and st["cut_tets"] <= tets and st["tets_rendered"] == st["cut_tets"]
    assert st["flipped_tets"] == 0 and st["rays_unfinished"] == 0
    # the written mesh (tetc decompress --selective, same view), read back and rendered whole
    out = tmp_path / "cut.vtu"
    res_cli = run("decompress", post_deps_tetc, "-o", out, "--selective", "--tets", tets, "--tf", "post", "--size", "48x40",
                  "--azimuth", 30, "--elevation", 20, "--quiet")
    assert res_cli.exit_code == 0, res_cli.output
    mesh = read_mesh(out)[0]
    assert mesh.n_tets == st["cut_tets"]
    check_valid(mesh, 0, "selective cut")
    lo, hi, rng, step = file_render_defaults(reader)
    ref = render_mesh(mesh, VIEW.camera.fit(lo, hi), "post", step=step, scalar_range=rng)
    assert np.abs(res.image - ref.image).max() <= TOL
    # generic pipeline, same cut
    gen = render_selective(reader, VIEW, tets=tets, pipeline="generic")
    assert np.abs(gen.image - res.image).max() <= TOL


def test_cut_from_a_coarser_level_equals_level_zero(reader):
    """A cut that applies everything below a stored level starts there, with the same tets."""
    cut = plan_cut(reader, VIEW, ratio=0.9, uniform=True)
    assert cut.level > 0
    mesh = selective_mesh(reader, VIEW, ratio=0.9, uniform=True)[0]
    base = reader.decode_mesh(0)
    from gatun_py.simplify.dependencies import cut_ancestors
    from gatun_py.simplify.forest import mesh_from_ancestors
    parent, rank = reader.read_forest(0)
    ref = mesh_from_ancestors(base, cut_ancestors(parent, rank, cut.applied))[0]
    assert mesh.n_tets == ref.n_tets == cut.n_tets
    assert _tet_key(mesh) == _tet_key(ref)


def test_tf_change_needs_no_reading(reader, monkeypatch):
    plan_cut(reader, VIEW, tets=800)
    reads = []
    orig = reader.container.read_section
    monkeypatch.setattr(reader.container, "read_section", lambda name: reads.append(name) or orig(name))
    a = plan_cut(reader, VIEW, tets=800)
    tf = {"color": [{"x": 0, "rgb": [0, 0, 1]}, {"x": 1, "rgb": [1, 0, 0]}],
          "opacity": [{"x": 0, "a": 0}, {"x": 0.3, "a": 0}, {"x": 1, "a": 1}]}
    b = plan_cut(reader, View(Camera(48, 40, 30, 20), tf=tf), tets=800)
    c = plan_cut(reader, View(Camera(48, 40, 200, 60), tf=tf), tets=800)
    assert reads == []
    assert not np.array_equal(a.applied, b.applied) and not np.array_equal(b.applied, c.applied)


def test_importance_factors(reader):
    src = selective_source(reader)
    lo, hi, rng, _ = file_render_defaults(reader)
    cam = VIEW.camera.fit(lo, hi)
    tf = load_transfer_function({"color": [{"x": 0, "rgb": [1, 1, 1]}, {"x": 1, "rgb": [1, 1, 1]}],
                                 "opacity": [{"x": 0, "a": 0}, {"x": 0.5, "a": 0}, {"x": 1, "a": 0.5}]})
    tf = tf.for_size(float(np.linalg.norm(hi - lo)))
    imp = merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng, factors=("colour",))
    # transparent over the whole merged range: only EPS is left (Peng); opaque somewhere: more
    top = np.maximum(src.scalars[src.vertex], src.scalars[src.target])
    x = (top - rng[0]) / (rng[1] - rng[0])
    assert np.all(imp[x < 0.49] == EPS) and np.all(imp[x > 0.51] > EPS)
    # the forest factor alone is the rank order: the uniform cut
    rank_only = merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng, factors=("forest",))
    assert np.all(np.diff(rank_only) > 0)
    assert np.array_equal(choose_cut(src, rank_only, tets=900), uniform_cut(src, tets=900))
    assert np.all(merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng, factors=()) == 1)
    full = merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng)
    assert full.shape == (src.n_merges,) and np.all(np.isfinite(full)) and np.all(full >= 0)
    with pytest.raises(OptionError):
        merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng, factors=("colour", "bogus"))
    assert set(FACTORS) == {"colour", "light", "size", "forest"}


def test_api_and_bad_input(post_deps_tetc, tmp_path):
    f = gatun_py.open(post_deps_tetc)
    fr = gatun_py.render(f, size=32, selective=True, tets=500)
    assert fr.stats["cut_tets"] <= 500 and fr.stats["flipped_tets"] == 0 and fr.stats["selection_s"] >= 0
    full = gatun_py.render(f, size=32, selective=True, tets=10**9)
    assert full.stats["tets_rendered"] == f.n_tets
    for kw in ({"tets": 0}, {"tets": -3}, {"tets": 2.5}, {"tets": 10, "ratio": 0.5}):
        with pytest.raises(OptionError):
            gatun_py.render(f, size=32, selective=True, **kw)
    with pytest.raises(OptionError):
        gatun_py.render(f, size=32, tets=10)  # tets without selective
    with pytest.raises(OptionError):
        gatun_py.render(f, size=32, selective=True, level=1)


def test_cli_render_selective(post_deps_tetc, tmp_path):
    out = tmp_path / "a.png"
    res = run("render", post_deps_tetc, "-o", out, "--selective", "--tets", 700, "--stats", "--size", 32)
    assert res.exit_code == 0, res.output
    st = json.loads(res.stdout)
    assert st["cut_tets"] <= 700 and st["flipped_tets"] == 0 and "selection_s" in st
    res = run("render", post_deps_tetc, "-o", tmp_path / "b.png", "--selective", "--ratio", 0.9, "--size", 32, "--quiet")
    assert res.exit_code == 0, res.output
    res = run("render", post_deps_tetc, "-o", tmp_path / "c.png", "--selective", "--tets", 10**9, "--stats", "--size", 32)
    assert json.loads(res.stdout)["tets_rendered"] == TetcReader(post_deps_tetc).meta["tets"]
    for bad in ("0", "-5"):
        assert_usage_error(run("render", post_deps_tetc, "-o", tmp_path / "d.png", "--selective", "--tets", bad), "--tets")
    assert_usage_error(run("render", post_deps_tetc, "-o", tmp_path / "d.png", "--tets", 50), "--selective")
    assert_usage_error(run("render", post_deps_tetc, "-o", tmp_path / "d.png", "--selective", "--level", 1), "--level")
    assert_usage_error(run("render", post_deps_tetc, "-o", tmp_path / "d.png", "--selective", "--tets", 5, "--ratio", 0.5))
    assert_usage_error(run("decompress", post_deps_tetc, "-o", tmp_path / "d.vtu", "--tets", 50), "--selective")


def test_cli_file_without_dependencies_renders_uniformly(tmp_path):
    """A format-2 file (written before the dependencies): uniform, and one note saying so."""
    from pathlib import Path

    old = Path(__file__).parent / "data" / "post_v2.tetc"
    res = run("render", old, "-o", tmp_path / "a.png", "--selective", "--ratio", 0.5, "--size", 32, "--stats")
    assert res.exit_code == 0, res.output
    assert res.stderr.count("no merge dependencies") == 1
    st = json.loads(res.stdout)
    assert st["selective"] is False and st["merges"] == int(0.5 * TetcReader(old).meta["points"])
    res = run("decompress", old, "-o", tmp_path / "a.vtu", "--selective", "--ratio", 0.5)
    assert res.exit_code == 0 and res.stderr.count("no merge dependencies") == 1


def test_first_frame_from_the_kept_stream_equals_a_decoded_one(post_deps_tetc):
    """The first selective frame renders level 0 from the stream decoded for the geometry; the
    next decodes it again: the same image, bit for bit."""
    r = TetcReader(post_deps_tetc)
    first = render_selective(r, VIEW, tets=1500)
    assert "_selective_batches" in r.__dict__ and not r.__dict__["_selective_batches"]  # used up
    second = render_selective(r, VIEW, tets=1500)
    assert np.array_equal(first.image, second.image) and first.stats["cut_tets"] == second.stats["cut_tets"]


@pytest.mark.parametrize("level", [1, 3])
def test_cut_within_a_stored_level(reader, level):
    """A cut chosen among a stored level's merges (as --budget does) is a closed cut of the whole
    forest: the same mesh as from level 0, valid, with the counted tets."""
    from gatun_py.simplify.dependencies import MergeDependencies, cut_ancestors
    from gatun_py.simplify.forest import mesh_from_ancestors

    src = selective_source(reader, level=level)
    tets = int(0.6 * src.n_tets)
    mesh, cut = selective_mesh(reader, VIEW, tets=tets, level=level)
    assert cut.level == level and mesh.n_tets == cut.n_tets <= tets
    check_valid(mesh, 0, f"level {level} cut")
    full = np.zeros(reader.forest_merges(), bool)
    full[:src.first] = True
    full[src.first:src.first + src.n_merges] = cut.applied
    deps = MergeDependencies(*reader.read_dependencies())
    assert deps.is_closed(full)
    parent, rank = reader.read_forest(0)
    ref = mesh_from_ancestors(reader.decode_mesh(0), cut_ancestors(parent, rank, full))[0]
    assert _tet_key(mesh) == _tet_key(ref)
    res = render_selective(reader, VIEW, tets=tets, level=level)
    assert res.stats["cut_tets"] == cut.n_tets and res.stats["flipped_tets"] == 0 and res.stats["level"] == level


def test_selective_budget(post_deps_tetc):
    f = gatun_py.open(post_deps_tetc)
    fr = gatun_py.render(f, size=48, selective=True, budget=0.3)
    assert fr.stats["flipped_tets"] == 0 and fr.stats["budget_s"] == 0.3 and fr.stats["selective"]


def test_dependencies_are_stored_only_when_asked_for(post_tetc, post_deps_tetc):
    """They cost a fifth of the file or more: a plain compress leaves them out."""
    plain, deps = TetcReader(post_tetc), TetcReader(post_deps_tetc)
    assert not plain.has_dependencies() and plain.read_dependencies() is None
    assert deps.has_dependencies() and deps.read_dependencies() is not None
    assert deps.meta["dependencies"]["merges"] == deps.forest_merges()
