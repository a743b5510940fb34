"""Isosurfaces from a tet stream: exactness (slow reference, VTK), locks, topology, options."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import load_sample
from meshgen import grid_mesh, mesh_strategy
from naive_isosurface import naive_isosurface

from gatun_py.errors import OptionError
from gatun_py.contour import isosurface, load_importance
from gatun_py.contour.marching import CASE_COUNT


def canonical(points, tris):
    """Triangles as position triples, each rotated to start at its smallest point (keeps the winding)."""
    p = np.asarray(points, np.float64)
    out = []
    for t in np.asarray(tris):
        tri = [tuple(p[i]) for i in t]
        k = min(range(3), key=lambda i: tri[i])
        out.append(tuple(tri[k:] + tri[:k]))
    return sorted(out)


def topology(tris):
    """(directed edges used twice, undirected edges used > 2 times, boundary edges, Euler characteristic)."""
    t = np.asarray(tris, np.int64)
    if len(t) == 0:
        return 0, 0, 0, 0
    d = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    _, dcount = np.unique(d, axis=0, return_counts=True)
    u, ucount = np.unique(np.sort(d, axis=1), axis=0, return_counts=True)
    nv = len(np.unique(t))
    return int((dcount > 1).sum()), int((ucount > 2).sum()), int((ucount == 1).sum()), nv - len(u) + len(t)


def iso_values(mesh, fractions=(0.3, 0.55)):
    lo, hi = mesh.scalar_range
    return [lo + f * (hi - lo) for f in fractions]


# -- exactness --------------------------------------------------------------------------------------

def test_case_table_covers_every_case():
    assert CASE_COUNT[0] == CASE_COUNT[15] == 0
    assert sorted(CASE_COUNT[1:15]) == [1] * 8 + [2] * 6


@pytest.mark.parametrize("name", ["post", "bluntfin"])
def test_exact_surface_equals_slow_reference(name):
    mesh = load_sample(name)[0]
    for v in iso_values(mesh):
        s = isosurface(mesh, values=v)
        rp, rt, _ = naive_isosurface(mesh.points, mesh.density, mesh.tets, v)
        assert s.n_triangles == len(rt) > 0
        assert s.n_points == len(rp)
        assert canonical(s.points, s.triangles) == canonical(rp, rt)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=mesh_strategy(), frac=st.floats(0.05, 0.95))
def test_exact_surface_on_random_meshes(mesh, frac):
    lo, hi = mesh.scalar_range
    v = lo + frac * (hi - lo)
    s = isosurface(mesh, values=v)
    rp, rt, _ = naive_isosurface(mesh.points, mesh.density, mesh.tets, v)
    assert canonical(s.points, s.triangles) == canonical(rp, rt)


def test_isovalue_on_mesh_vertices_keys_by_vertex():
    # integer scalars on a grid: the isovalue hits vertices exactly, surface vertices sit on them
    mesh = grid_mesh(5, 5, 5)
    mesh = type(mesh)(mesh.points, np.round(mesh.points[:, 0] * 4).astype(np.float32), mesh.tets)
    v = float(np.median(mesh.density))
    s = isosurface(mesh, values=v)
    rp, rt, _ = naive_isosurface(mesh.points, mesh.density, mesh.tets, v)
    assert canonical(s.points, s.triangles) == canonical(rp, rt)
    assert s.n_triangles > 0 and np.allclose(s.points[:, 0] * 4, v)
    directed_twice, nonmanifold, _, _ = topology(s.triangles)
    assert directed_twice == 0 and nonmanifold == 0


def test_winding_points_toward_lower_scalar():
    mesh = load_sample("bluntfin")[0]
    v = iso_values(mesh)[1]
    s = isosurface(mesh, values=v)
    p, t = s.points, s.triangles
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    c = p[t].mean(axis=1)
    ln = np.linalg.norm(n, axis=1)
    ok = ln > 1e-9 * np.abs(c).max()
    step = 1e-3 * (n[ok] / ln[ok][:, None])
    # the mesh scalar a small step along the normal is lower than the isovalue: sample it by the
    # nearest mesh vertex on each side, on the majority of faces (a linear field is not needed)
    from scipy.spatial import cKDTree

    tree = cKDTree(mesh.points)
    ahead = mesh.density[tree.query(c[ok] + 50 * step)[1]]
    behind = mesh.density[tree.query(c[ok] - 50 * step)[1]]
    assert np.mean(ahead <= behind) > 0.9


def test_exact_surface_equals_vtk():
    vtk = pytest.importorskip("vtk", reason="VTK (the vtk extra) is the peer this test compares with")
    from scipy.spatial import cKDTree
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy

    mesh = load_sample("bluntfin")[0]
    ug = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(mesh.points, deep=True))
    ug.SetPoints(pts)
    offsets = numpy_to_vtkIdTypeArray(4 * np.arange(mesh.n_tets + 1, dtype=np.int64), deep=True)
    conn = numpy_to_vtkIdTypeArray(mesh.tets.astype(np.int64).ravel(), deep=True)
    cells = vtk.vtkCellArray()
    cells.SetData(offsets, conn)
    ug.SetCells(vtk.VTK_TETRA, cells)
    sc = numpy_to_vtk(mesh.density, deep=True)
    sc.SetName("density")
    ug.GetPointData().SetScalars(sc)
    lo, hi = mesh.bbox
    diag = float(np.linalg.norm(hi - lo))
    for v in iso_values(mesh):
        c = vtk.vtkContour3DLinearGrid()
        c.SetInputData(ug)
        c.SetValue(0, v)
        c.Update()
        out = c.GetOutput()
        vp = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
        vt = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
        s = isosurface(mesh, values=v)
        assert s.n_triangles == len(vt) and s.n_points == len(vp)
        d, j = cKDTree(vp).query(s.points)
        assert d.max() <= 1e-6 * diag
        # same triangles, same winding, compared by position: the grid has coincident points, so
        # the triangles with two corners on one spot (no area, no winding) are only counted
        ours, theirs = canonical(vp[j], s.triangles), canonical(vp, vt)
        flat = [t for t in ours if len(set(t)) < 3]
        assert len(flat) == len([t for t in theirs if len(set(t)) < 3]) < 0.01 * len(ours)
        assert [t for t in ours if len(set(t)) == 3] == [t for t in theirs if len(set(t)) == 3]


def test_several_values_and_outside_range():
    mesh = load_sample("post")[0]
    lo, hi = mesh.scalar_range
    a, b = iso_values(mesh)
    s = isosurface(mesh, values=[a, hi + 1.0, b])
    sa, sb = isosurface(mesh, values=a), isosurface(mesh, values=b)
    assert s.n_triangles == sa.n_triangles + sb.n_triangles
    assert set(np.unique(s.point_data["scalar"])) == {np.float32(a), np.float32(b)}
    assert s.stats["values_outside_range"] == [hi + 1.0]
    empty = isosurface(mesh, values=hi + 1.0)
    assert empty.n_triangles == 0 and empty.n_points == 0
    assert "0 triangles" in repr(empty)


@pytest.mark.parametrize("bad", [dict(values=float("nan")), dict(values=1.0, ratio=0.0), dict(values=1.0, ratio=1.5),
                                 dict(values=1.0, faces=0), dict(values=1.0, ratio=0.5, faces=10),
                                 dict(values=[]), dict(values=1.0, batch_faces=0)])
def test_bad_options_raise(bad):
    with pytest.raises(OptionError):
        isosurface(load_sample("post")[0], **bad)


# -- simplification ---------------------------------------------------------------------------------

def _edge_star_last(tets):
    """Sorted keys (a << 32 | b, and v << 32 | v) with the stream position of the last tet around them."""
    t = np.asarray(tets, np.int64)
    idx = np.arange(len(t), dtype=np.int64)
    keys, last = [], []
    for i, j in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]:
        a, b = np.minimum(t[:, i], t[:, j]), np.maximum(t[:, i], t[:, j])
        keys.append((a << 32) | b)
        last.append(idx)
    for i in range(4):
        keys.append((t[:, i] << 32) | t[:, i])
        last.append(idx)
    k = np.concatenate(keys)
    pos = np.concatenate(last)
    order = np.lexsort((pos, k))
    k, pos = k[order], pos[order]
    end = np.r_[np.flatnonzero(np.diff(k)), len(k) - 1]
    return k[end], pos[end]


class LockChecker:
    """The check hook: every vertex a collapse touched had its whole edge star streamed already."""

    def __init__(self, stream_tets):
        self.keys, self.last = _edge_star_last(stream_tets)
        self.n = len(stream_tets)
        self.rounds_mid_stream = 0
        self.touched = 0

    def __call__(self, keys, tets_done):
        i = np.searchsorted(self.keys, keys)
        assert np.all(self.keys[i] == keys)
        assert np.all(self.last[i] < tets_done), "a collapse touched a vertex whose edge still had tets to come"
        self.touched += len(keys)
        if tets_done < self.n:
            self.rounds_mid_stream += 1


@pytest.mark.parametrize("ratio", [0.2, 0.05])
def test_locks_hold_and_topology_is_kept(ratio):
    mesh = load_sample("bluntfin")[0]
    for v in iso_values(mesh):
        full = isosurface(mesh, values=v)
        check = LockChecker(mesh.tets)
        s = isosurface(mesh, values=v, ratio=ratio, batch_faces=500, check=check)
        assert check.rounds_mid_stream >= 3 and check.touched > 0  # the check was not vacuous
        target = int(np.ceil(ratio * full.n_triangles))
        assert s.stats["faces_extracted"] == full.n_triangles
        assert target * 0.9 <= s.n_triangles <= target * 1.5 + 20
        # collapses with the link condition keep the topology: same Euler characteristic, still
        # manifold and consistently wound, the surface boundary kept (never more boundary edges)
        dt, nm, nb, chi = topology(s.triangles)
        dt0, nm0, nb0, chi0 = topology(full.triangles)
        # (Blunt-fin's zero-volume tets can put a wrongly wound pair into the exact surface itself)
        assert dt <= dt0 <= 2 and nm <= nm0 == 0
        assert chi == chi0
        assert 0 < nb <= nb0 or nb0 == 0
        assert s.stats["peak_faces"] < full.n_triangles  # never held the full surface


def test_locks_on_a_tetc_stream(post_tetc):
    from gatun_py.codec import TetcReader

    mesh = TetcReader(post_tetc).decode_mesh(0)  # the stream's own vertex and tet order
    stream_tets = mesh.tets
    v = iso_values(mesh)[0]
    check = LockChecker(stream_tets)
    s = isosurface(post_tetc, values=v, ratio=0.2, batch_faces=200, check=check)
    assert check.rounds_mid_stream >= 1
    full = isosurface(post_tetc, values=v)
    assert canonical(full.points, full.triangles) == canonical(*naive_isosurface(mesh.points, mesh.density,
                                                                                 mesh.tets, v)[:2])
    assert s.n_triangles <= 0.2 * full.n_triangles * 1.5 + 20
    band = s.stats["band"]
    assert band and all(b["locked"] <= b["vertices"] for b in band)
    assert max(b["locked"] for b in band) < full.n_points
    # the timeline: a batch is extracted after it is decoded, in stream order; rounds are counted
    assert all(b["decoded_s"] <= b["t_s"] for b in band)
    assert [b["decoded_s"] for b in band] == sorted(b["decoded_s"] for b in band)
    assert [b["rounds"] for b in band] == sorted(b["rounds"] for b in band)
    assert 1 <= band[-1]["rounds"] == s.stats["rounds"] - 1  # all but the final round ran mid-stream


def test_result_does_not_depend_on_how_far_the_decoder_runs_ahead(post_tetc, monkeypatch):
    import functools

    from gatun_py.codec.prefetch import PrefetchedDecode
    from gatun_py.contour import extract

    v = 0.5 * sum(isosurface(post_tetc, values=0.0).stats["scalar_range"])
    # small batches, so that the queues fill and drain many times over the stream
    monkeypatch.setattr(extract, "PrefetchedDecode", functools.partial(PrefetchedDecode, batch_tets=300))
    runs = []
    for depth, in_flight in ((1, 1), (extract.PREFETCH_DEPTH, extract.MAX_IN_FLIGHT), (64, 64)):
        monkeypatch.setattr(extract, "PREFETCH_DEPTH", depth)
        monkeypatch.setattr(extract, "MAX_IN_FLIGHT", in_flight)
        s = isosurface(post_tetc, values=v, ratio=0.2, batch_faces=200)
        runs.append((s.points, s.triangles, s.stats["rounds"]))
        assert len(s.stats["band"]) > 20  # many batches went through the queues
    assert runs[0][1].shape[0] > 0
    for pts, tris, rounds in runs[1:]:
        assert np.array_equal(pts, runs[0][0]) and np.array_equal(tris, runs[0][1]) and rounds == runs[0][2]


def test_trim_heap_is_safe_to_call_between_batches():
    import platform

    from gatun_py import _runtime

    _runtime.trim_heap()
    _runtime.trim_heap()
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert _runtime._malloc_trim() is not None  # on glibc the trim is real, not silently skipped


def test_faces_target_and_error_small():
    from gatun_py.contour.metrics import surface_distance

    mesh = load_sample("bluntfin")[0]
    v = iso_values(mesh)[1]
    full = isosurface(mesh, values=v)
    s = isosurface(mesh, values=v, faces=1000, batch_faces=2000)
    assert 900 <= s.n_triangles <= 1100
    lo, hi = mesh.bbox
    d = surface_distance(full.points, full.triangles, s.points, s.triangles, diagonal=float(np.linalg.norm(hi - lo)),
                         n_samples=50_000)
    assert d["rms"] < 0.2 and d["hausdorff"] < 3.0  # % of the diagonal


def test_importance_keeps_detail_where_weighted():
    from gatun_py.contour.metrics import one_sided

    mesh = load_sample("bluntfin")[0]
    v = iso_values(mesh)[1]
    full = isosurface(mesh, values=v)
    g = full.point_data["gradient_magnitude"]
    hot = g > np.quantile(g, 0.8)
    lo, hi = mesh.bbox
    scale = float(np.linalg.norm(hi - lo)) / (mesh.scalar_range[1] - mesh.scalar_range[0])
    cut = float(np.quantile(g, 0.8)) * scale
    imp = {"points": [{"x": 0.0, "w": 1.0}, {"x": cut * 0.9, "w": 1.0}, {"x": cut, "w": 50.0}]}
    plain = isosurface(mesh, values=v, ratio=0.05)
    weighted = isosurface(mesh, values=v, ratio=0.05, importance_tf=imp)
    assert abs(weighted.n_triangles - plain.n_triangles) <= 0.1 * plain.n_triangles
    e_plain = one_sided(full.points[hot], plain.points, plain.triangles)
    e_weighted = one_sided(full.points[hot], weighted.points, weighted.triangles)
    assert np.sqrt(np.mean(e_weighted ** 2)) < 0.8 * np.sqrt(np.mean(e_plain ** 2))
    assert "importance" in weighted.point_data


def test_load_importance_rejects_bad_specs(tmp_path):
    with pytest.raises(OptionError):
        load_importance({"points": []})
    with pytest.raises(OptionError):
        load_importance({"points": [{"x": 0, "w": -1}]})
    with pytest.raises(OptionError):
        load_importance({"feature": "curvature", "points": [{"x": 0, "w": 1}]})
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    from gatun_py.errors import ReadError

    with pytest.raises(ReadError):
        load_importance(bad)


# -- simplified start -------------------------------------------------------------------------------

@pytest.mark.parametrize("how", [dict(level=1), dict(ratio_mesh=0.6)])
def test_simplified_start_equals_reference_on_simplified_mesh(post_tetc, how):
    from gatun_py.simplify.levels import read_simplified

    simple = read_simplified(post_tetc, **{("ratio" if k == "ratio_mesh" else k): x for k, x in how.items()})
    v = iso_values(simple)[0]
    s = isosurface(post_tetc, values=v, **how)
    rp, rt, _ = naive_isosurface(simple.points, simple.density, simple.tets, v)
    assert s.n_triangles == len(rt) > 0
    assert canonical(s.points, s.triangles) == canonical(rp, rt)
    dt, nm, _, _ = topology(s.triangles)
    assert dt == 0 and nm == 0  # conforming tet mesh: no cracks, consistently wound


def test_simplified_start_then_qem_respects_locks(post_tetc):
    from gatun_py.codec import TetcReader
    from gatun_py.simplify.filter import SimplifyFilter
    from gatun_py.simplify.levels import resolve_target, target_ancestors

    reader = TetcReader(post_tetc)
    target = resolve_target(reader, ratio=0.6)
    anc = target_ancestors(reader, target)
    stream = [b.tets for b in SimplifyFilter(anc).filter(reader.iter_decode(target.level)) if len(b.tets)]
    check = LockChecker(np.concatenate(stream))
    v = iso_values(load_sample("post")[0])[0]
    s = isosurface(post_tetc, values=v, ratio_mesh=0.6, ratio=0.3, batch_faces=100, check=check)
    assert s.n_triangles > 0 and check.touched > 0
