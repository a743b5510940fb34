"""Isosurfaces of bricked files: bricks skipped by range, the rest decoded on threads, one surface."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cli_util import run
from conftest import load_sample
from test_isosurface import LockChecker, canonical, iso_values, topology

from gatun_py.codec import TetcReader
from gatun_py.codec.bricks import decode_bricked
from gatun_py.codec.container import build_container, split_container
from gatun_py.errors import CorruptFileError, OptionError
from gatun_py.contour import isosurface
from gatun_py.contour.bricked import BrickedStream, bricks_to_decode
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.pipeline.bricks import compress_bricks

_FILES: dict = {}


def bricked(name: str, k: int, cut_ids=None) -> bytes:
    """A sample (or "grid": a small jittered grid) as a bricked file, made once per session."""
    key = (name, k, cut_ids)
    if key not in _FILES:
        mesh = jittered_grid((9, 8, 7), jitter=0.25, seed=5) if name == "grid" else load_sample(name)[0]
        _FILES[key] = compress_bricks(mesh, k, jobs=1, mesh_only=True, cut_ids=cut_ids)
    return _FILES[key]


def mesh_of(name):
    return jittered_grid((9, 8, 7), jitter=0.25, seed=5) if name == "grid" else load_sample(name)[0]


def _edit_brick_level(data, k, fn):
    meta, sections = split_container(data)
    fn(meta["bricks"][k]["levels"][0])
    return build_container(meta, sections)


# -- exactness ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("cut_ids", [None, True], ids=["matched-by-points", "cut-ids"])
def test_exact_surface_is_the_stitched_meshs_one_for_one(cut_ids):
    """Every brick decoded: the stream's ids and tet order are the stitched mesh's, so the surface is
    the same arrays as the in-memory extraction of the stitched mesh, and the same triangles (by
    position) as the unbricked mesh's (which test_isosurface checks against VTK)."""
    data = bricked("bluntfin", 4, cut_ids)
    mesh = load_sample("bluntfin")[0]
    stitched = decode_bricked(TetcReader(data), jobs=1)
    all_decoded = 0
    for v in iso_values(mesh):
        s = isosurface(TetcReader(data), values=v, jobs=2)
        ref = isosurface(stitched, values=v)
        if s.stats["bricks"]["bricks_skipped"] == 0:
            all_decoded += 1
            np.testing.assert_array_equal(s.points, ref.points)
            np.testing.assert_array_equal(s.triangles, ref.triangles)
        else:  # fewer ids: the same triangles, numbered otherwise
            assert canonical(s.points, s.triangles) == canonical(ref.points, ref.triangles)
        plain = isosurface(mesh, values=v)
        assert same_surface(s, plain)
    assert all_decoded >= 1


def same_surface(a, b) -> bool:
    """The same vertices (one per cut edge), as many triangles, the same topology (watertight across
    the cuts where the input is). Not the same triangles: the codec stores a tet's corners in
    another order, and the diagonal that splits a quad follows the corner order (as VTK's)."""
    return (a.n_triangles == b.n_triangles and np.array_equal(np.unique(a.points, axis=0), np.unique(b.points, axis=0))
            and a.n_points == b.n_points and topology(a.triangles) == topology(b.triangles))


def test_bricks_outside_the_isovalue_are_skipped_and_the_surface_is_whole():
    data = bricked("bluntfin", 8)
    mesh = load_sample("bluntfin")[0]
    reader = TetcReader(data)
    ranges = [reader.brick(k).level_meta(0)["scalar_range"] for k in range(8)]
    lo, hi = mesh.scalar_range
    # an isovalue some bricks' ranges miss
    v = next(lo + f * (hi - lo) for f in np.linspace(0.05, 0.95, 19)
             if 0 < sum(r[0] <= lo + f * (hi - lo) <= r[1] for r in ranges) < 8)
    hit = [k for k, r in enumerate(ranges) if r[0] <= v <= r[1]]
    assert bricks_to_decode(reader, [v]) == hit
    s = isosurface(reader, values=v, jobs=2)
    st = s.stats["bricks"]
    assert st["bricks_skipped"] == 8 - len(hit) and st["bricks_decoded"] == len(hit)
    assert st["tets"] == s.stats["tets"] == sum(reader.brick(k).level_meta(0)["tets"] for k in hit)
    assert 1 <= st["peak_bricks_decoding"] <= 2 and st["peak_bricks_held"] <= 3
    whole = isosurface(decode_bricked(reader, jobs=1), values=v)
    assert canonical(s.points, s.triangles) == canonical(whole.points, whole.triangles)
    assert same_surface(s, isosurface(mesh, values=v))
    # two values: the union of the bricks either cuts
    w = lo + 0.9 * (hi - lo)
    assert bricks_to_decode(reader, [v, w]) == sorted(set(hit) | set(bricks_to_decode(reader, [w])))
    # a value outside every range decodes nothing
    empty = isosurface(reader, values=hi + 1.0)
    assert empty.n_triangles == 0 and empty.stats["bricks"]["bricks_decoded"] == 0


def test_a_brick_whose_range_is_unknown_is_decoded():
    data = bricked("grid", 3)
    mesh = mesh_of("grid")
    v = iso_values(mesh)[0]
    edited = _edit_brick_level(data, 1, lambda lv: lv.pop("scalar_range"))
    assert 1 in bricks_to_decode(TetcReader(edited), [mesh.scalar_range[1] + 5.0])
    s = isosurface(TetcReader(edited), values=v)
    assert same_surface(s, isosurface(mesh, values=v))


@pytest.mark.parametrize("jobs", [1, 3])
def test_result_does_not_depend_on_the_thread_count(jobs):
    data = bricked("bluntfin", 8)
    v = iso_values(load_sample("bluntfin")[0])[1]
    ref = isosurface(TetcReader(data), values=v, ratio=0.1, batch_faces=400, jobs=2)
    s = isosurface(TetcReader(data), values=v, ratio=0.1, batch_faces=400, jobs=jobs)
    np.testing.assert_array_equal(s.points, ref.points)
    np.testing.assert_array_equal(s.triangles, ref.triangles)
    assert s.stats["bricks"]["peak_bricks_decoding"] <= jobs


# -- locks across cuts --------------------------------------------------------------------------------

@pytest.mark.parametrize("ratio", [0.2, 0.05])
def test_locks_hold_across_cuts_and_topology_is_kept(ratio):
    """A vertex on a cut edge is collapsed only once every brick around its edge is streamed: the
    check hook sees the keys in the stream's ids (the stitched mesh's when no brick is skipped, and
    a skipped brick has no tet around a surface edge: test_bricks_outside_...), in its tet order."""
    data = bricked("bluntfin", 4)
    mesh = load_sample("bluntfin")[0]
    stitched = decode_bricked(TetcReader(data), jobs=1)
    for v in iso_values(mesh):
        full = isosurface(mesh, values=v)
        stream = BrickedStream(TetcReader(data), values=[v], jobs=1)
        tets = np.concatenate([b.tets for b in stream])
        if stream.stats["bricks_skipped"] == 0:
            np.testing.assert_array_equal(tets, stitched.tets)
        check = LockChecker(tets)
        s = isosurface(TetcReader(data), values=v, ratio=ratio, batch_faces=500, check=check, jobs=2)
        assert check.rounds_mid_stream >= 3 and check.touched > 0
        assert s.stats["faces_extracted"] == full.n_triangles
        target = int(np.ceil(ratio * full.n_triangles))
        assert target * 0.9 <= s.n_triangles <= target * 1.5 + 20
        dt, nm, nb, chi = topology(s.triangles)
        dt0, nm0, nb0, chi0 = topology(full.triangles)
        assert dt <= dt0 <= 2 and nm <= nm0 == 0 and chi == chi0
        assert 0 < nb <= nb0 or nb0 == 0
        assert s.stats["peak_faces"] < full.n_triangles
        band = s.stats["band"]
        assert max(b["locked"] for b in band) < full.n_points


def test_cut_faces_are_left_out_of_the_border():
    data = bricked("grid", 3)
    reader = TetcReader(data)
    v = iso_values(mesh_of("grid"))[0]
    stream = BrickedStream(reader, values=[v], jobs=2)
    batches = list(stream)
    assert stream.stats["cut_faces_left_out"] > 0
    # what is passed is the mesh's own boundary, each face once, but for the boundary faces whose
    # three corners are all on cuts (they cannot be told from cut faces: left open, on the safe side)
    passed = np.concatenate([b.boundary for b in batches])
    stitched = decode_bricked(reader, jobs=1)
    key = lambda f: {tuple(sorted(t)) for t in f.tolist()}  # noqa: E731
    true = key(stitched.boundary_faces())
    assert len(key(passed)) == len(passed) and key(passed) <= true
    start = np.cumsum([0] + [reader.brick(k).level_meta(0)["tets"] for k in range(3)])
    bricks_of = {}
    for k in range(3):
        for p in np.unique(stitched.tets[start[k]:start[k + 1]]).tolist():
            bricks_of.setdefault(p, set()).add(k)
    assert all(all(len(bricks_of[p]) > 1 for p in f) for f in true - key(passed))
    assert len(true - key(passed)) < 0.05 * len(true)
    np.testing.assert_array_equal(np.concatenate([b.tets for b in batches]), stitched.tets)
    np.testing.assert_array_equal(stream.values[:stream.n, :3], stitched.points)
    assert stream.n == stitched.n_points == stream.stats["points"]


# -- bad input ----------------------------------------------------------------------------------------

def test_a_brick_range_that_lies_is_a_corrupt_file():
    data = bricked("grid", 3)
    mesh = mesh_of("grid")
    lo, hi = mesh.scalar_range
    v = iso_values(mesh)[0]
    k = bricks_to_decode(TetcReader(data), [v])[0]
    edited = _edit_brick_level(data, k, lambda lv: lv.update(scalar_range=[v, v]))
    with pytest.raises(CorruptFileError, match="range"):
        isosurface(TetcReader(edited), values=v)


def test_a_cut_vertex_that_differs_between_bricks_is_a_corrupt_file():
    from gatun_py.codec.bricks import read_cut

    data = bricked("grid", 3, True)
    reader = TetcReader(data)
    pos1, ids1 = read_cut(reader, 1)
    # brick 1 says its first cut vertex is another file-wide cut vertex, one that brick 0 also holds
    _, ids0 = read_cut(reader, 0)
    other = next(i for i in ids0.tolist() if i not in set(ids1.tolist()))
    from gatun_py.codec.bricks import encode_cut

    cut = np.full(reader.brick(1).level_meta(0)["points"], -1, np.int64)
    cut[pos1] = ids1
    cut[pos1[0]] = other
    meta, sections = split_container(data)
    sections = [(n, encode_cut(cut, int(meta["cut_points"]), 0) if n == "B1/L0/cut" else d) for n, d in sections]
    bad = build_container(meta, sections)
    v = iso_values(mesh_of("grid"))[0]
    with pytest.raises(CorruptFileError):
        isosurface(TetcReader(bad), values=v, jobs=2)


def test_a_stored_level_of_a_bricked_file():
    mesh = mesh_of("grid")
    data = compress_bricks(mesh, 3, jobs=1, levels=2)
    reader = TetcReader(data)
    v = iso_values(mesh)[1]
    for level in (0, 1):
        s = isosurface(reader, values=v, level=level)
        whole = isosurface(decode_bricked(reader, level, jobs=1), values=v)
        assert s.stats["level"] == level and s.n_triangles == whole.n_triangles > 0
        assert canonical(s.points, s.triangles) == canonical(whole.points, whole.triangles)


def test_options_of_a_bricked_file():
    data = bricked("grid", 3)
    v = iso_values(mesh_of("grid"))[0]
    with pytest.raises(OptionError, match="bricked"):
        isosurface(TetcReader(data), values=v, ratio_mesh=0.5)
    with pytest.raises(OptionError, match="level 3"):
        isosurface(TetcReader(data), values=v, level=3)
    with pytest.raises(OptionError, match="jobs"):
        isosurface(TetcReader(data), values=v, jobs=0)


def test_cli_on_a_bricked_file(tmp_path):
    src = tmp_path / "b.tetc"
    src.write_bytes(bricked("grid", 3))
    out = tmp_path / "iso.ply"
    v = iso_values(mesh_of("grid"))[0]
    res = run("isosurface", src, "--value", str(v), "--ratio", "0.5", "-o", out, "--stats", "--jobs", "2", "--quiet")
    assert res.exit_code == 0, res.output
    st = json.loads(res.stdout)
    assert st["bricks"]["bricks"] == 3 and st["bricks"]["bricks_decoded"] + st["bricks"]["bricks_skipped"] == 3
    assert st["bricks"]["jobs"] == 2 and out.exists()
    res = run("isosurface", src, "--value", str(v), "-o", tmp_path / "x.ply", "--jobs", "0")
    assert res.exit_code == 2


def test_point_table_finds_adds_and_bounds():
    from gatun_py.contour.bricked import _TAKEN, _new_point_table, _point_slots

    bits, ids = _new_point_table(5)
    keys = np.array([[1, 2, 3], [3, 2, 1], [1, 2, 3], [0, 0, 0]], np.uint32)
    out = np.empty(4, np.int64)
    assert _point_slots(bits, ids, keys, out, 5) == 3
    assert out[0] < 0 and out[1] < 0 and out[3] < 0 and out[2] == -1 - out[0]  # the repeat finds its slot taken
    assert ids[out[2]] == _TAKEN
    ids[-1 - out[[0, 1, 3]]] = [7, 8, 9]
    again = np.empty(3, np.int64)
    assert _point_slots(bits, ids, keys[[3, 1, 0]], again, 2) == 0
    assert ids[again].tolist() == [9, 8, 7]
    more = np.array([[5, 5, 5], [6, 6, 6], [7, 7, 7]], np.uint32)
    assert _point_slots(bits, ids, more, np.empty(3, np.int64), 2) == -1  # more than the room: damage
    assert (ids != -1).sum() <= 5 < len(ids)
