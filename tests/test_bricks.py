"""Bricked files: lossless round trips, one-brick layout, parallel decode, crack-free levels, hostile indexes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gatun_py
from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
from gatun_py.codec.bricks import decode_bricked, decode_cut, encode_cut, read_cut
from gatun_py.codec.container import build_container, split_container
from gatun_py.errors import CorruptFileError, OptionError
from gatun_py.mesh import TetMesh
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.pipeline.bricks import compress_bricks
from gatun_py.simplify import decimate
from meshgen import delaunay_mesh, with_unreferenced


def canonical(mesh: TetMesh):
    """The mesh up to a permutation of vertices and tets: every tet as its four vertices' bits
    (coordinates and every point array) in a sorted order, the tets sorted."""
    cols = [mesh.points.view(np.uint8).reshape(mesh.n_points, -1)]
    for name in sorted(mesh.point_data):
        a = np.ascontiguousarray(mesh.point_data[name])
        cols.append(a.view(np.uint8).reshape(mesh.n_points, -1))
    rows = np.concatenate(cols, axis=1)
    vkey = np.unique(rows, axis=0, return_inverse=True)[1].ravel()
    t = np.sort(vkey[mesh.tets], axis=1)
    return np.unique(rows, axis=0), t[np.lexsort(t.T[::-1])]


def assert_same_mesh(a: TetMesh, b: TetMesh):
    assert (a.n_points, a.n_tets) == (b.n_points, b.n_tets)
    assert a.points.dtype == b.points.dtype and sorted(a.point_data) == sorted(b.point_data)
    ra, ta = canonical(a)
    rb, tb = canonical(b)
    np.testing.assert_array_equal(ra, rb)
    np.testing.assert_array_equal(ta, tb)


def bricked_bytes(mesh, k, **kw):
    kw.setdefault("mesh_only", True)
    return compress_bricks(mesh, k, jobs=1, **kw)


# -- round trips ----------------------------------------------------------------------------------

@pytest.mark.parametrize("cut_ids", [None, True])
@pytest.mark.parametrize("k", [2, 3, 8])
def test_bricked_file_decodes_to_the_input_up_to_permutation(k, cut_ids):
    m = jittered_grid((7, 6, 5), jitter=0.25, seed=3)
    data = bricked_bytes(m, k, cut_ids=cut_ids)
    r = TetcReader(data)
    magic = {r.brick(i).read_section("L0/cut")[:4] for i in range(k)}
    assert magic == ({b"CUT1"} if cut_ids else {b"CUTP"})  # distinct coordinates: no ids unless asked
    assert r.n_bricks == k and r.container.major >= 3
    assert sum(r.brick(i).meta["tets"] for i in range(k)) == m.n_tets
    assert_same_mesh(decode_bricked(r, jobs=1), m)


@pytest.mark.slow  # the real samples at full size, decimated brick by brick
def test_samples_round_trip_with_bricks(sample):
    name, m = sample
    data = bricked_bytes(m, 8)
    out = decode_bricked(TetcReader(data), jobs=2)
    assert_same_mesh(out, m)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(12, 60), seed=st.integers(0, 1000), k=st.integers(2, 9), f64=st.booleans())
def test_random_meshes_round_trip(n, seed, k, f64):
    m = delaunay_mesh(n, seed)
    extra = {"ids": np.arange(m.n_points, dtype=np.int32), "vec": np.random.default_rng(seed).normal(size=(m.n_points, 3))}
    pts = m.points.astype(np.float64) + (1e-9 if f64 else 0.0)
    m = TetMesh(pts if f64 else m.points, m.density, m.tets, point_data={"density": m.density, **extra})
    k = min(k, m.n_tets)
    if k < 2:
        return
    assert_same_mesh(decode_bricked(TetcReader(bricked_bytes(m, k)), jobs=2), m)


@pytest.mark.parametrize("mesh_only", [True, False])
def test_unreferenced_points_are_kept(mesh_only):
    # a vertex no tet uses belongs to no brick of the partition: brick 0 keeps it
    m = with_unreferenced(jittered_grid((4, 4, 4), jitter=0.2), extra=3)
    assert_same_mesh(decode_bricked(TetcReader(bricked_bytes(m, 3, mesh_only=mesh_only)), jobs=1), m)


def test_output_does_not_depend_on_jobs():
    m = jittered_grid((8, 7, 6), jitter=0.25, seed=1)
    data = bricked_bytes(m, 5)
    a, b = decode_bricked(TetcReader(data), jobs=1), decode_bricked(TetcReader(data), jobs=3)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.tets, b.tets)
    np.testing.assert_array_equal(a.density, b.density)


def test_compress_is_the_same_bytes_with_any_job_count():
    m = jittered_grid((6, 5, 5), jitter=0.25, seed=2)
    assert bricked_bytes(m, 4, mesh_only=False) == compress_bricks(m, 4, jobs=2, mesh_only=False)


def test_one_brick_is_todays_layout(tmp_path):
    m = jittered_grid((5, 5, 4), jitter=0.2)
    gatun_py.compress(m, tmp_path / "a.tetc", mesh_only=True)
    b = gatun_py.compress(m, tmp_path / "b.tetc", mesh_only=True, bricks=1)
    assert (tmp_path / "a.tetc").read_bytes() == (tmp_path / "b.tetc").read_bytes()
    r = b.reader
    assert r.n_bricks == 1 and "bricks" not in r.meta and r.brick(0) is r
    assert not any(n.startswith("B") for n in r.container.section_names())
    assert (tmp_path / "a.tetc").read_bytes() == encode_tetc([LevelPayload(0, 0.0, 0, m)])
    with pytest.raises(OptionError):
        r.brick(1)


# -- a brick reads as a file ----------------------------------------------------------------------

def test_brick_reader_is_a_one_brick_file(tmp_path):
    m = jittered_grid((7, 7, 6), jitter=0.25, seed=4)
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=4, jobs=1)
    r = f.reader
    for k in range(4):
        b = r.brick(k)
        lo, hi = r.brick_bounds(k)
        mk = b.decode_mesh(0)
        np.testing.assert_array_equal(mk.bbox[0], lo.astype(mk.points.dtype))
        np.testing.assert_array_equal(mk.bbox[1], hi.astype(mk.points.dtype))
        assert mk.n_tets == b.meta["tets"] and b.n_bricks == 1
        assert sum(len(x.tets) for x in b.iter_decode(0)) == mk.n_tets
        # its levels and forest, as the one-brick pipeline reads them
        fb = f.brick(k)
        assert fb.levels == [lv["level"] for lv in b.levels] and fb.max_ratio > 0
        assert sum(len(x.tets) for x in fb.batches(ratio=fb.max_ratio / 2)) == fb.mesh(ratio=fb.max_ratio / 2).n_tets
    with pytest.raises(OptionError, match="bricks"):
        r.decode_mesh(0)
    with pytest.raises(OptionError, match="bricks"):
        next(iter(f))


def _faces(tets):
    f = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    return np.sort(f, axis=1)


def test_simplified_bricks_never_crack(tmp_path):
    m = jittered_grid((9, 8, 7), jitter=0.25, seed=5)
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=6, jobs=1)
    whole = f.mesh()
    outer = {tuple(x) for x in _faces(whole.tets)[np.unique(_faces(whole.tets), axis=0, return_counts=True)[1][
        np.unique(_faces(whole.tets), axis=0, return_inverse=True)[1].ravel()] == 1]}
    outer_pts = {tuple(p) for p in whole.points[np.array(sorted(outer)).ravel()].tolist()}
    for ratio in (None, 0.2, f.max_ratio / 2, f.max_ratio):
        s = f.mesh(ratio=ratio, jobs=2)
        faces, counts = np.unique(_faces(s.tets), axis=0, return_counts=True)
        assert counts.max() <= 2  # conforming
        # every boundary face of the stitched mesh lies on the input's boundary: a crack between
        # two bricks would leave faces inside the volume open
        bnd = faces[counts == 1]
        assert all(tuple(p) in outer_pts for p in s.points[bnd.ravel()].tolist())
        assert (s.signed_volumes() >= 0).all()
    for lv in f.levels:
        assert f.mesh(level=lv).n_tets == sum(f.brick(k).reader.level_meta(lv)["tets"] for k in range(6))


def _boundary_triangles(mesh: TetMesh) -> set:
    """The mesh's boundary faces as triangles of coordinates (what a neighbour brick can match)."""
    pts = [tuple(p) for p in mesh.points.tolist()]
    return {tuple(sorted(pts[v] for v in f)) for f in mesh.boundary_faces().tolist()}


def test_cut_faces_stay_the_same_triangles_at_every_level_and_ratio(tmp_path):
    """Locked cut vertices are merge targets for interior vertices, never merged away themselves:
    at every stored level and ratio each brick's cut faces (its boundary triangles that another
    brick's boundary also has) are exactly its level-0 cut faces, so the bricks still meet."""
    m = jittered_grid((12, 12, 12), jitter=0.25, seed=11)
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=3, jobs=1)
    bricks = [f.brick(k) for k in range(3)]

    def cut_faces(meshes):
        tri = [_boundary_triangles(x) for x in meshes]
        return [t & set().union(*(tri[:k] + tri[k + 1:])) for k, t in enumerate(tri)]

    ref = cut_faces([b.mesh() for b in bricks])
    assert all(ref) and sum(map(len, ref)) > 100
    assert len(f.levels) >= 2 and f.max_ratio > 0.5  # simplified levels to check
    for how in [{"level": lv} for lv in f.levels] + [{"ratio": r} for r in (0.3, f.max_ratio)]:
        meshes = [b.mesh(**how) for b in bricks]
        assert cut_faces(meshes) == ref, how
        for b, x in zip(ref, meshes):
            assert b <= _boundary_triangles(x)
        whole = f.mesh(**how)
        faces, counts = np.unique(_faces(whole.tets), axis=0, return_counts=True)
        assert counts.max() <= 2 and (whole.signed_volumes() >= 0).all()  # conforming, nothing inverted


def test_interior_vertices_merge_into_locked_ones():
    """Locked vertices take merges from interior vertices (not from boundary ones), so a brick's
    forest goes on past the vertices around its cut; without locks nothing changes."""
    m = jittered_grid((7, 7, 7), jitter=0.2, seed=2)
    # lock one side of the grid, as a cut would
    locked = m.points[:, 0] <= np.quantile(m.points[:, 0], 0.2)
    forest = decimate(m, locked=locked)
    assert np.all(forest.parent[locked] == np.flatnonzero(locked))
    merged = np.flatnonzero(forest.parent != np.arange(m.n_points))
    into_locked = merged[locked[forest.parent[merged]]]
    assert into_locked.size > 0
    on_boundary = np.zeros(m.n_points, bool)
    on_boundary[m.boundary_faces().ravel()] = True
    assert not on_boundary[into_locked].any()
    free = decimate(m)
    assert np.array_equal(free.parent, decimate(m, locked=np.zeros(m.n_points, bool)).parent)


def test_decimate_keeps_locked_vertices():
    m = jittered_grid((6, 6, 6), jitter=0.2, seed=0)
    locked = np.zeros(m.n_points, bool)
    locked[::3] = True
    forest = decimate(m, locked=locked)
    assert forest.n_merges > 0
    assert np.all(forest.parent[locked] == np.flatnonzero(locked))  # never merged away
    with pytest.raises(OptionError):
        decimate(m, locked=locked[:-1])


# -- the API and the command line -----------------------------------------------------------------

@pytest.mark.slow  # the whole pipeline through the CLI, a process per command
def test_api_and_cli(tmp_path):
    from cli_util import run

    m = jittered_grid((6, 6, 5), jitter=0.2, seed=7)
    src = tmp_path / "m.vtu"
    gatun_py.write_mesh(m, src)
    out = tmp_path / "m.tetc"
    res = run("compress", src, "-o", out, "--bricks", "3", "--jobs", "2", "--mesh-only")
    assert res.exit_code == 0, res.output
    f = gatun_py.open(out)
    assert f.n_bricks == 3 and len(f.info["bricks"]) == 3
    assert_same_mesh(f.mesh(jobs=2), m)
    res = run("decompress", out, "-o", tmp_path / "d.vtu", "--jobs", "2")
    assert res.exit_code == 0, res.output
    back, _ = gatun_py.read_mesh(tmp_path / "d.vtu")
    assert back.n_tets == m.n_tets and back.n_points == m.n_points
    assert run("compress", src, "-o", tmp_path / "x.tetc", "--bricks", "0").exit_code == 2
    assert run("compress", src, "-o", tmp_path / "x.tetc", "--bricks", "100000").exit_code == 2
    res = run("compress", src, "-o", tmp_path / "x.tetc", "--bricks", str(m.n_tets + 1), "--mesh-only")
    assert res.exit_code == 1 and "at most one brick per tet" in res.output
    res = run("info", out, "--json")
    assert res.exit_code == 0 and len(json.loads(res.output)["bricks"]) == 3


def test_render_of_a_bricked_file_equals_the_plain_file(tmp_path):
    m = jittered_grid((7, 6, 6), jitter=0.2, seed=8)
    plain = gatun_py.compress(m, tmp_path / "p.tetc", mesh_only=True)
    bricked = gatun_py.compress(m, tmp_path / "b.tetc", mesh_only=True, bricks=4, jobs=1)
    for mode in ("volume", "face"):
        # bricks walk every ray to its end (sort-last compositing needs whole segments); the plain
        # file's early termination changes a pixel by at most 255 * (1 - 0.99)
        a = gatun_py.render(plain, size=64, azimuth=30, elevation=20, mode=mode, terminate=False)
        b = gatun_py.render(bricked, size=64, azimuth=30, elevation=20, mode=mode)
        assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max() <= 1
        t = gatun_py.render(plain, size=64, azimuth=30, elevation=20, mode=mode)
        assert np.abs(t.rgb.astype(int) - b.rgb.astype(int)).max() <= 3
    # a budget splits the frame among the bricks (sort-last compositor): mesh-only bricks draw whole
    c = gatun_py.render(bricked, size=64, azimuth=30, elevation=20, budget=100.0)
    assert c.stats["budget_s"] == 100.0 and c.stats["bricks"] == 4
    whole = gatun_py.render(plain, size=64, azimuth=30, elevation=20, terminate=False)
    assert np.abs(c.rgb.astype(int) - whole.rgb.astype(int)).max() <= 1


# -- hostile brick indexes ------------------------------------------------------------------------

@pytest.fixture(scope="module", params=[None, True], ids=["matched-by-points", "cut-ids"])
def bricked(request):
    m = jittered_grid((6, 5, 5), jitter=0.25, seed=9)
    return bricked_bytes(m, 3, cut_ids=request.param)


def test_distinct_points():
    from gatun_py.codec.bricks import distinct_points

    p = np.array([[0, 0, 0], [1, 0, 0], [0.0, 0, 0]], np.float32)
    assert not distinct_points(p) and distinct_points(p[:2])
    assert distinct_points(np.array([[0.0, 0, 0], [-0.0, 0, 0]]))  # bits, not values


def _rebuild(data, edit_meta=None, edit_sections=None):
    meta, sections = split_container(data)
    if edit_meta:
        edit_meta(meta)
    if edit_sections:
        sections = edit_sections(sections)
    return build_container(meta, sections)


def _read_all(data):
    r = TetcReader(data)
    return decode_bricked(r, jobs=2)


def _set(path, value):
    def edit(meta):
        node = meta
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value(node[path[-1]]) if callable(value) else value
    return edit


HOSTILE_META = {
    "tets of a brick": _set(["bricks", 1, "tets"], lambda v: v + 1),
    "points of a brick": _set(["bricks", 0, "points"], lambda v: v + 5),
    "cut points of the file": _set(["cut_points"], lambda v: v + 1),
    "cut points of a brick": _set(["bricks", 2, "cut_points"], -1),
    "bounds": _set(["bricks", 0, "bounds"], [[1, 1, 1], [0, 0, 0]]),
    "bounds not numbers": _set(["bricks", 0, "bounds"], [["a", 1, 1], [0, 0, 0]]),
    "one brick": _set(["bricks"], lambda v: v[:1]),
    "not a list": _set(["bricks"], {"0": 1}),
    "brick not an object": _set(["bricks", 1], 7),
    "no levels": _set(["bricks", 1, "levels"], []),
    "level of a brick claims more tets": _set(["bricks", 1, "levels", 0, "tets"], lambda v: v + 3),
    "levels at the top too": _set(["levels"], [{"level": 0}]),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_META))
def test_hostile_brick_index(bricked, case):
    with pytest.raises(CorruptFileError):
        _read_all(_rebuild(bricked, edit_meta=HOSTILE_META[case]))


def test_missing_and_stray_brick_sections(bricked):
    with pytest.raises(CorruptFileError, match="missing"):
        TetcReader(_rebuild(bricked, edit_sections=lambda s: [x for x in s if x[0] != "B1/L0/tets"]))
    with pytest.raises(CorruptFileError, match="missing"):
        TetcReader(_rebuild(bricked, edit_sections=lambda s: [x for x in s if x[0] != "B2/L0/cut"]))
    with pytest.raises(CorruptFileError, match="no brick"):
        TetcReader(_rebuild(bricked, edit_sections=lambda s: s + [("B3/L0/tets", b"x")]))
    with pytest.raises(CorruptFileError, match="no brick"):
        TetcReader(_rebuild(bricked, edit_sections=lambda s: s + [("L0/tets", b"x")]))


def _swap_cut(data, k, fn):
    r = TetcReader(data)
    n = r.brick(k).level_meta(0)["points"]
    total = r.meta["cut_points"]
    pos, ids = read_cut(r, k, 0)
    with_ids = ids is not None
    full = np.full(n, -1, np.int64)
    new_pos, new_ids = fn(pos.copy(), ids.copy() if with_ids else np.arange(pos.size))
    full[new_pos] = new_ids
    return _rebuild(data, edit_sections=lambda s: [(name, encode_cut(full, total, ids=with_ids)
                                                    if name == f"B{k}/L0/cut" else p) for name, p in s])


def test_overlapping_and_inconsistent_cut_ids(bricked):
    if TetcReader(bricked).brick(1).read_section("L0/cut")[:4] == b"CUT1":
        # two cut vertices of brick 1 swap ids: the shared vertices no longer agree between bricks
        def swap(pos, ids):
            ids[[0, 1]] = ids[[1, 0]]
            return pos, ids
        with pytest.raises(CorruptFileError, match="differs"):
            _read_all(_swap_cut(bricked, 1, swap))

    # a vertex of brick 1 alone is listed as a cut vertex: its position matches no other brick's
    def extra(pos, ids):
        v = np.setdiff1d(np.arange(pos.max() + 2), pos)[0]
        return np.append(pos, v), np.append(ids, (ids.max() + 1) % TetcReader(bricked).meta["cut_points"])
    with pytest.raises(CorruptFileError):
        _read_all(_swap_cut(bricked, 1, extra))

    if TetcReader(bricked).brick(0).read_section("L0/cut")[:4] == b"CUT1":
        # a cut vertex claims the id of another brick's vertex that it does not share
        def steal(pos, ids):
            ids[0] = (ids.max() + 1) % TetcReader(bricked).meta["cut_points"]
            return pos, ids
        with pytest.raises(CorruptFileError):
            _read_all(_swap_cut(bricked, 0, steal))

    # a brick drops one of its cut vertices: the counts no longer add up
    with pytest.raises(CorruptFileError):
        _read_all(_swap_cut(bricked, 2, lambda pos, ids: (pos[1:], ids[1:])))


def test_cut_section_checks():
    ids = np.array([-1, 3, -1, 0, 7, -1])
    data = encode_cut(ids, 8)
    pos, got = decode_cut(data, 6, 8)
    np.testing.assert_array_equal(pos, [1, 3, 4])
    np.testing.assert_array_equal(got, [3, 0, 7])
    for bad in (data[:10], data[:-2], data + b"\0", data[:4] + b"\x07" + data[5:]):
        with pytest.raises(CorruptFileError):
            decode_cut(bad, 6, 8)
    with pytest.raises(CorruptFileError):
        decode_cut(data, 6, 7)  # the file's cut count disagrees
    with pytest.raises(CorruptFileError, match="twice"):
        decode_cut(encode_cut(np.array([1, 1, -1]), 4), 3, 4)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(k=st.integers(0, 2), key=st.sampled_from(["points", "tets", "cut_points", "boundary_faces"]),
       level_key=st.sampled_from([None, "points", "tets", "boundary_faces", "boundary_vertices", "referenced_points"]),
       value=st.one_of(st.integers(-3, 3), st.integers(0, 2**40), st.just(None), st.just("7"), st.just(1.5)))
def test_any_edited_brick_count_is_read_or_rejected(bricked, k, key, level_key, value):
    def edit(meta):
        entry = meta["bricks"][k]
        if level_key is None:
            entry[key] = value if not isinstance(value, int) or value > 3 else entry[key] + value
        else:
            lv = entry["levels"][0]
            lv[level_key] = value if not isinstance(value, int) or value > 3 else lv[level_key] + value
    data = _rebuild(bricked, edit_meta=edit)
    try:
        out = _read_all(data)
    except CorruptFileError:
        return
    assert out.n_tets == TetcReader(bricked).meta["tets"]


def test_decode_kernels_release_the_gil():
    # bricks decode on threads: every kernel the decoder spends its time in must run without the GIL
    from gatun_py.codec import _array_kernels, _cutborder_kernels, _geometry_kernels
    from gatun_py.codec.legacy import tets1

    for kernel in (_cutborder_kernels.decode_boundary, _cutborder_kernels._decode_tets_run, tets1._decode_tets_run,
                   _geometry_kernels.decode_tables_kernel, _geometry_kernels.decode_vertices,
                   _array_kernels.decode_component, _array_kernels.reconstruct):
        assert kernel.targetoptions.get("nogil") is True, kernel.__name__


def test_one_brick_renders_through_the_plain_pipeline(tmp_path):
    # what the compositor builds on: a brick's reader goes through render_tetc unchanged (its
    # stream, levels and forest), with the file's scalar range and step in its metadata
    from gatun_py.pipeline.stream import View, file_view, render_tetc
    from gatun_py.raycast.camera import Camera
    from gatun_py.raycast.caster import render_mesh

    m = jittered_grid((6, 6, 5), jitter=0.2, seed=11)
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=3, jobs=1)
    view = View(Camera(48, 48, 30.0, 20.0, 1.0), "default", "volume", None, False, None)
    b = f.reader.brick(1)
    res = render_tetc(b, view, ratio=0.3)
    assert res.stats["tets_decoded"] == b.level_meta(res.stats["level"])["tets"] and res.image.shape[:2] == (48, 48)
    streamed = render_tetc(b, view, level=0).image
    v, camera, rng, step, _ = file_view(b, view)
    ref = render_mesh(b.decode_mesh(0), camera, v.tf, mode="volume", step=step, scalar_range=rng).image
    assert np.abs(streamed - ref).max() < 1e-5 and ref.max() > 0
    assert rng == tuple(f.reader.meta["scalar_range"]) and step == f.reader.meta["render_step"]


def test_brick_budget_probes_once_and_follows_the_budget(tmp_path, monkeypatch):
    """A series plans every frame from planners probed on the first: coarser bricks for smaller
    budgets, the finest for a generous one, and no probe after the first frame."""
    from gatun_py.pipeline import budget as budget_module
    from gatun_py.pipeline.sortlast import BrickBudget, MeshExtent, frame_setup
    from gatun_py.pipeline.stream import View
    from gatun_py.raycast import Camera

    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    m = jittered_grid((12, 12, 12), jitter=0.25, seed=4)
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=3, jobs=1)
    probes = []
    real_probe = budget_module.FramePlanner.probe
    monkeypatch.setattr(budget_module.FramePlanner, "probe", lambda self, *a, **k: probes.append(1) or real_probe(
        self, *a, **k))
    plan = BrickBudget([f.reader.brick(k) for k in range(3)])
    extent = MeshExtent.of_reader(f.reader)
    ratios = []
    for k, budget in enumerate((1e-4, 0.05, 60.0)):
        view = View(Camera(64, 64, 20.0 * k, 10))
        setup, _ = frame_setup(view, extent)
        targets = plan.targets(setup, view, budget, groups=[[0, 1], [2]])
        ratios.append([t.ratio for t in targets])
    assert len(probes) == 3  # one per brick, on the first frame only
    assert all(r > 0 for r in ratios[0]) and ratios[2] == [0.0, 0.0, 0.0]
    assert all(a >= b >= c for a, b, c in zip(*ratios))
    with pytest.raises(OptionError):
        plan.targets(setup, view, 0.0)


# -- a budget on a file that cannot be simplified says so ---------------------------------------

@pytest.mark.parametrize("bricks", [1, 4])
def test_budget_on_a_mesh_only_file_says_it_cannot_simplify(tmp_path, bricks):
    m = jittered_grid((6, 6, 5), jitter=0.2, seed=3)
    gatun_py.compress(m, tmp_path / "mo.tetc", mesh_only=True, bricks=bricks)
    notes = []
    gatun_py.render(tmp_path / "mo.tetc", budget=0.01, size=32, log=notes.append)
    said = [n for n in notes if "no simplified levels" in n]
    assert len(said) == 1 and "--mesh-only" in said[0]
    gatun_py.compress(m, tmp_path / "lv.tetc", bricks=bricks, jobs=1)
    notes = []
    gatun_py.render(tmp_path / "lv.tetc", budget=0.01, size=32, log=notes.append)
    assert not any("no simplified levels" in n for n in notes)
