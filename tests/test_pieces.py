"""Partitioned inputs: pieces with their own numbering compressed one by one into a bricked file."""

from __future__ import annotations

import os
import zlib

import numpy as np
import pytest

import gatun_py
from cli_util import assert_error, assert_usage_error, run
from gatun_py.codec import TetcReader
from gatun_py.codec.bricks import decode_bricked
from gatun_py.codec.container import build_container, container_head, record_head, split_container
from gatun_py.codec.tetcfile import file_meta
from gatun_py.errors import MeshError, OptionError, ReadError
from gatun_py.mesh import TetMesh
from gatun_py.mesh.partition import partition_tets, split_bricks
from gatun_py.mesh.pieces import (boundary_part, exodus_pieces, interface_table, piece_paths, read_piece,
                                  refine_midpoints, write_pvtu)
from gatun_py.mesh.synthetic import jittered_grid
from gatun_py.pipeline.compress_pieces import PIECES_KEY, compress_pieces, parse_memory, piece_mesh
from test_bricks import _faces, assert_same_mesh


def rich_mesh(dims=(9, 8, 7), seed=2, f64=False) -> TetMesh:
    """A jittered grid with a float scalar, a vector and an integer array."""
    m = jittered_grid(dims, jitter=0.25, seed=seed)
    rng = np.random.default_rng(seed)
    pts = m.points.astype(np.float64) * 1.001 if f64 else m.points
    data = {"density": m.density, "vel": rng.normal(size=(m.n_points, 3)),
            "ids": np.arange(m.n_points, dtype=np.int32)}
    return TetMesh(pts, None, m.tets, "density", point_data=data)


def solver_pieces(mesh: TetMesh, k: int, seed: int = 0) -> list[TetMesh]:
    """``mesh`` cut into k k-d pieces, each renumbered at random (a solver's local numbering)."""
    rng = np.random.default_rng(seed)
    out = []
    for b in split_bricks(mesh, partition_tets(mesh, k)):
        m = b.mesh
        perm = rng.permutation(m.n_points)  # new id of old vertex perm^-1
        inv = np.empty_like(perm)
        inv[perm] = np.arange(perm.size)
        tets = inv[m.tets][rng.permutation(m.n_tets)]
        out.append(TetMesh(m.points[perm], None, tets.astype(np.int32), m.scalar_name,
                           point_data={n: a[perm] for n, a in m.point_data.items()}))
    return out


@pytest.fixture(scope="module")
def pvtu(tmp_path_factory):
    d = tmp_path_factory.mktemp("pieces")
    mesh = rich_mesh()
    write_pvtu(solver_pieces(mesh, 5), d / "run.pvtu")
    return d / "run.pvtu", mesh


def test_pvtu_round_trip_and_whole_mesh_metadata(pvtu, tmp_path):
    path, mesh = pvtu
    assert [p.name for p in piece_paths(path)] == [f"run_{i}.vtu" for i in range(5)]
    stats = compress_pieces(path, tmp_path / "r.tetc", mesh_only=True)
    r = TetcReader(tmp_path / "r.tetc")
    assert r.n_bricks == 5 and stats["points"] == mesh.n_points and stats["tets"] == mesh.n_tets
    assert_same_mesh(decode_bricked(r, jobs=2), mesh)  # every shared point once, every bit kept
    # the metadata is what the whole mesh would give, though no process held it whole
    ref = file_meta(mesh, len(mesh.boundary_faces()), "run.pvtu")
    assert {k: r.meta[k] for k in ref} == ref
    assert [p["source"] for p in r.meta[PIECES_KEY]] == [f"run_{i}.vtu" for i in range(5)]


def test_levels_of_pieces_stay_conforming(pvtu, tmp_path):
    path, mesh = pvtu
    big = rich_mesh((12, 12, 12), seed=4)
    write_pvtu(solver_pieces(big, 3, seed=1), tmp_path / "big.pvtu")
    f = gatun_py.compress(tmp_path / "big.pvtu", tmp_path / "b.tetc", jobs=1)
    assert f.n_bricks == 3 and len(f.levels) >= 2
    whole = f.mesh()
    assert_same_mesh(whole, big)
    outer = {tuple(p) for p in whole.points[whole.boundary_faces().ravel()].tolist()}
    for how in [{"level": lv} for lv in f.levels] + [{"ratio": f.max_ratio}]:
        s = f.mesh(**how)
        faces, counts = np.unique(_faces(s.tets), axis=0, return_counts=True)
        assert counts.max() <= 2 and (s.signed_volumes() >= 0).all()
        # no crack: every boundary face of the stitched level lies on the input's boundary
        assert all(tuple(p) in outer for p in s.points[faces[counts == 1].ravel()].tolist()), how


def test_several_files_and_jobs_give_the_same_bytes(pvtu, tmp_path):
    path, _ = pvtu
    files = [str(p) for p in piece_paths(path)]
    opts = {"scalar": "density"}  # no .pvtu to name the default one: the first array would be
    a = compress_pieces(files, tmp_path / "a.tetc", mesh_only=True, jobs=1, **opts)
    b = compress_pieces(files, tmp_path / "b.tetc", mesh_only=True, jobs=2, **opts)
    assert a == b and (tmp_path / "a.tetc").read_bytes() == (tmp_path / "b.tetc").read_bytes()


def test_memory_limit_splits_pieces_and_piece_k_decodes_alone(pvtu, tmp_path, monkeypatch):
    path, mesh = pvtu
    stats = compress_pieces(path, tmp_path / "m.tetc", mesh_only=True, memory=parse_memory("64M"))
    assert stats["bricks"] == 5  # 64 MB holds these small pieces whole
    import gatun_py.pipeline.compress_pieces as cp
    monkeypatch.setattr(cp, "BYTES_PER_TET_MESH_ONLY", (64 << 20) // 150)  # bricks of 150 tets at most
    monkeypatch.setattr(cp, "MIN_BRICK_TETS", 1)
    stats = compress_pieces(path, tmp_path / "s.tetc", mesh_only=True, memory="64M")
    r = TetcReader(tmp_path / "s.tetc")
    assert stats["bricks"] > 5 and r.n_bricks == stats["bricks"]
    assert_same_mesh(decode_bricked(r), mesh)
    # one plain mesh file under a memory limit: split into bricks before any forest is built
    write_pvtu([mesh], tmp_path / "one.pvtu")
    stats = compress_pieces(tmp_path / "one_0.vtu", tmp_path / "one.tetc", mesh_only=True, memory="64M",
                            scalar="density")
    assert stats["bricks"] >= 10
    assert_same_mesh(decode_bricked(TetcReader(tmp_path / "one.tetc")), mesh)
    pieces = read_piece_meshes(path)
    for k in (0, 3):
        assert_same_mesh(piece_mesh(r, k), pieces[k])
    out = tmp_path / "p3.vtu"
    res = run("decompress", tmp_path / "s.tetc", "--piece", 3, "-o", out)
    assert res.exit_code == 0, res.output
    assert_same_mesh(gatun_py.read_mesh(out, scalar="density")[0], pieces[3])
    assert_error(run("decompress", tmp_path / "s.tetc", "--piece", 9, "-o", tmp_path / "p9.vtu"), "piece 9")
    assert not (tmp_path / "p9.vtu").exists()


def read_piece_meshes(pvtu_path):
    return [read_piece(p, {"scalar": "density"})[0] for p in piece_paths(pvtu_path)]


def test_streamed_container_is_build_container():
    meta = {"format": "x", "n": 3}
    sections = [("a", b"12"), ("B0/L0/tets", b"x" * 300), ("c", b"")]
    rows = [(n, len(record_head(n, p)), len(p), zlib.crc32(p)) for n, p in sections]
    body = b"".join(record_head(n, p) + p for n, p in sections)
    assert container_head(meta, rows) + body == build_container(meta, sections)
    assert split_container(container_head(meta, rows) + body)[1] == sections


def test_refined_pieces_meet_as_the_refined_whole():
    mesh = rich_mesh((6, 5, 5), seed=7, f64=True)
    pieces = [refine_midpoints(p) for p in solver_pieces(mesh, 4, seed=3)]
    whole = refine_midpoints(mesh)
    assert whole.n_tets == 8 * mesh.n_tets and (whole.signed_volumes() > 0).all()
    assert np.isclose(whole.signed_volumes().sum(), mesh.signed_volumes().sum())
    table = interface_table([boundary_part(p) for p in pieces])
    assert sum(p.n_points for p in pieces) - table.occurrences + table.n_shared == whole.n_points
    assert table.boundary_faces == len(whole.boundary_faces())


# -- bad input ---------------------------------------------------------------------------------------

def test_missing_piece_is_one_line_and_nothing_written(pvtu, tmp_path):
    path, _ = pvtu
    text = path.read_text().replace("run_4.vtu", "gone_4.vtu")
    bad = path.parent / "missing.pvtu"
    bad.write_text(text)
    out = tmp_path / "x.tetc"
    assert_error(run("compress", bad, "-o", out), "gone_4.vtu", "missing")
    assert not out.exists() and not list(tmp_path.iterdir())


def test_other_arrays_and_nonconforming_interfaces_are_refused(tmp_path):
    mesh = rich_mesh()
    pieces = solver_pieces(mesh, 3)
    p = pieces[1]
    other = TetMesh(p.points, None, p.tets, "density", point_data={"density": p.density})
    write_pvtu([pieces[0], other, pieces[2]], tmp_path / "arrays.pvtu")
    assert_error(run("compress", tmp_path / "arrays.pvtu", "-o", tmp_path / "a.tetc"), "arrays_1.vtu",
                 "other point arrays")
    # one interface point with another value in one piece: the pieces do not conform
    shared = interface_table([boundary_part(x) for x in pieces]).shared[1][0]
    dens = p.density.copy()
    dens[shared[0]] += 1.0
    moved = TetMesh(p.points, None, p.tets, "density", point_data={**p.point_data, "density": dens})
    write_pvtu([pieces[0], moved, pieces[2]], tmp_path / "nc.pvtu")
    assert_error(run("compress", tmp_path / "nc.pvtu", "-o", tmp_path / "n.tetc"), "do not conform")
    # one interface point moved by one float32 step in one piece: a near miss, not two points
    pts = p.points.copy()
    pts[shared[0]] = np.nextafter(pts[shared[0]], np.float32(np.inf))
    bumped = TetMesh(pts, None, p.tets, "density", point_data=p.point_data)
    write_pvtu([pieces[0], bumped, pieces[2]], tmp_path / "ulp.pvtu")
    assert_error(run("compress", tmp_path / "ulp.pvtu", "-o", tmp_path / "u.tetc"), "do not conform", "last bits")
    with pytest.raises(MeshError, match="overlap"):
        interface_table([boundary_part(x) for x in [pieces[0], pieces[0], pieces[1]]])
    assert not list(tmp_path.glob("*.tetc")) and not list(tmp_path.glob(".*"))


def test_cli_usage(pvtu, tmp_path):
    path, _ = pvtu
    files = [str(p) for p in piece_paths(path)]
    # several files without --pieces are the steps of a time series: pieces' topologies differ
    assert_error(run("compress", *files[:2], "-q", "--scalar", "density", "-o", tmp_path / "x.tetc"), "--pieces")
    assert_usage_error(run("compress", path, "--bricks", 3, "-o", tmp_path / "x.tetc"), "--bricks")
    assert_usage_error(run("compress", files[0], "--workers", "2", "-o", tmp_path / "x.tetc"), "--workers")
    assert_error(run("compress", files[0], "--memory", "1G", "--scalar", "density", "-o", tmp_path / "x.tetc"),
                 "fits the memory limit")
    assert_error(run("compress", path, "--memory", "lots", "-o", tmp_path / "x.tetc"), "memory limit")
    res = run("compress", "--pieces", *files, "--mesh-only", "--scalar", "density", "-o", tmp_path / "x.tetc")
    assert res.exit_code == 0, res.output
    assert_error(run("compress", "--pieces", *files, "--scalar", "density", "-o", tmp_path / "x.tetc"),
                 "already exists")
    with pytest.raises(OptionError, match="one mesh"):
        piece_paths([files[0]])


# -- Exodus decompositions ---------------------------------------------------------------------------------

def test_exodus_decomposition(tmp_path):
    pytest.importorskip("netCDF4", reason="netCDF4 (the exodus extra) writes and reads Exodus files")
    from test_mesh_exodus import _write_exodus
    mesh = rich_mesh()
    pieces = solver_pieces(mesh, 3)
    for i, p in enumerate(pieces):
        _write_exodus(tmp_path / f"run.e.3.{i}", p, [0.0, 1.0])
    assert [p.name for p in exodus_pieces(tmp_path / "run.e.3.1")] == ["run.e.3.0", "run.e.3.1", "run.e.3.2"]
    res = run("compress", tmp_path / "run.e.3.0", "--mesh-only", "--scalar", "p", "-o", tmp_path / "e.tetc")
    assert res.exit_code == 0, res.output
    out = gatun_py.open(tmp_path / "e.tetc").mesh()
    assert out.n_points == mesh.n_points and out.n_tets == mesh.n_tets
    os.unlink(tmp_path / "run.e.3.2")
    with pytest.raises(ReadError, match="missing"):
        exodus_pieces(tmp_path / "run.e.3.0")


# -- everything else works from the pieced file --------------------------------------------------------

def test_render_budget_and_isosurface_of_a_pieced_file(pvtu, tmp_path):
    from gatun_py.contour import isosurface
    from test_isosurface_bricks import same_surface

    path, mesh = pvtu
    pieced = gatun_py.compress(path, tmp_path / "p.tetc", mesh_only=True, jobs=1)
    plain = gatun_py.compress(mesh, tmp_path / "w.tetc", mesh_only=True)
    assert pieced.n_bricks == 5
    for mode in ("volume", "face"):
        # bricks composite whole segments: they equal the render without early ray termination
        a = gatun_py.render(plain, size=64, azimuth=30, elevation=20, mode=mode, terminate=False)
        b = gatun_py.render(pieced, size=64, azimuth=30, elevation=20, mode=mode)
        assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max() <= 1
    c = gatun_py.render(pieced, size=64, azimuth=30, elevation=20, budget=100.0)
    assert c.stats["bricks"] == 5
    ref = gatun_py.render(plain, size=64, azimuth=30, elevation=20, terminate=False)
    assert np.abs(c.rgb.astype(int) - ref.rgb.astype(int)).max() <= 1
    lo, hi = mesh.scalar_range
    for v in (lo + 0.3 * (hi - lo), lo + 0.6 * (hi - lo)):
        s = isosurface(pieced.reader, values=v, jobs=2)
        assert s.n_triangles > 0 and same_surface(s, isosurface(mesh, values=v))


def test_close_points_an_edge_apart_are_not_a_near_miss():
    """Two pieces' boundary points far closer than the mesh's extent but as far apart as their own
    edges (a fine boundary layer) are distinct points, not an interface rounded otherwise."""
    unit = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    tet = np.array([[0, 1, 2, 3]], np.int32)

    def piece(origin, scale):
        pts = origin + scale * unit
        return TetMesh(pts, None, tet, point_data={"density": np.zeros(4, np.float32)})

    big, a = piece(np.array([100.0, 0, 0]), 10.0), piece(np.zeros(3), 1e-7)
    near = piece(np.array([0, 0, 2e-7]), 1e-7)  # 1e-7 above a: one edge away
    table = interface_table([boundary_part(m) for m in (big, a, near)])
    assert table.n_shared == 0 and table.boundary_faces == 12
    rounded = piece(np.array([0, 0, 1e-7 + 1e-13]), 1e-7)  # a's apex, rounded otherwise
    with pytest.raises(MeshError, match="last bits"):
        interface_table([boundary_part(m) for m in (big, a, rounded)])
