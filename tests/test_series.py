"""Time series in one .tetc file: real solver output (scikit-fem heat conduction and thermo-elastic
deformation, ``tests/data/series_heat.npz``) round-trips bit for bit at every step, read back
through meshio and VTK; random series (hypothesis) too; every bad input gets one clear error; an
interrupted append leaves the earlier steps readable."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gatun_py
from gatun_py.cli.main import tetc
from gatun_py.codec.steps import decode_step_array, encode_step_array, extrapolate
from gatun_py.errors import CorruptFileError, MeshError, OptionError, ReadError
from gatun_py.mesh.validate import validate_tets
from gatun_py.pipeline import series as series_mod
from gatun_py.pipeline.series import append_step, encode_series, write_series

DATA = Path(__file__).parent / "data"
sys.path.insert(0, str(Path(__file__).parent.parent / "bench"))
from series_data import load, write_pvd  # noqa: E402

N_STEPS = 12


@pytest.fixture(scope="module")
def run():
    return load(DATA / "series_heat.npz")


def steps_of(run, n=N_STEPS, *, moving=False, extra=True):
    out = []
    for k in range(n):
        data = {"temperature": run["temperature"][k]}
        if extra:
            data["t32"] = run["temperature"][k].astype(np.float32)
            data["band"] = np.floor(run["temperature"][k] / 10).astype(np.int16)
        pts = run["moved"][k] if moving else run["points"]
        out.append(validate_tets(pts, None, run["tets"], scalar_name="temperature", point_data=data)[0])
    return out


def by_position(points):
    """Row index of every point's coordinate bits (the solver's points are distinct)."""
    keys = [p.tobytes() for p in np.ascontiguousarray(points)]
    assert len(set(keys)) == len(keys)
    return {k: i for i, k in enumerate(keys)}


def assert_same_step(decoded, source):
    """``decoded`` (decode order) holds ``source``'s points and arrays bit for bit, and its tets."""
    where = by_position(source.points)
    perm = np.array([where[p.tobytes()] for p in np.ascontiguousarray(decoded.points)])
    np.testing.assert_array_equal(decoded.points.view(np.uint8), source.points[perm].view(np.uint8))
    for name, a in source.point_data.items():
        b = decoded.point_data[name]
        assert b.dtype == a.dtype and b.shape == a.shape
        np.testing.assert_array_equal(b.view(np.uint8), a[perm].view(np.uint8))
    t_dec = np.sort(np.sort(perm[decoded.tets], axis=1), axis=0)
    assert {tuple(r) for r in np.sort(perm[decoded.tets], axis=1)} == {tuple(r) for r in np.sort(source.tets, axis=1)}
    assert len(t_dec) == source.n_tets


@pytest.fixture(scope="module", params=[False, True], ids=["static", "deforming"])
def series_file(request, run, tmp_path_factory):
    meshes = steps_of(run, moving=request.param)
    path = tmp_path_factory.mktemp("series") / "run.tetc"
    write_series(path, meshes, list(run["times"][:N_STEPS]), levels=2, keyframe_interval=5)
    return path, meshes


def test_every_step_bit_exact(series_file):
    path, meshes = series_file
    f = gatun_py.open(path)
    assert f.n_steps == N_STEPS and len(f.times) == N_STEPS
    for k in [7, 3, 11, 0, 5, 10, 1]:  # random access: each from its keyframe
        assert_same_step(f.mesh(step=k), meshes[k])
    for k, (t, m) in enumerate(f.steps()):
        assert t == f.times[k]
        assert_same_step(m, meshes[k])


def test_times_kept_exactly(series_file, run):
    path, _ = series_file
    assert gatun_py.open(path).times == tuple(float(t) for t in run["times"][:N_STEPS])
    assert gatun_py.info(str(path))["times"] == [float(t) for t in run["times"][:N_STEPS]]


def test_snapshot_has_one_step(tmp_path, run):
    m = steps_of(run, 1)[0]
    f = gatun_py.compress(m, tmp_path / "one.tetc", mesh_only=True)
    assert f.n_steps == 1 and f.times == (0.0,) and "times" not in f.info
    with pytest.raises(OptionError, match="does not exist"):
        f.mesh(step=1)


@pytest.mark.parametrize("ratio", [None, 0.5, 0.9])
def test_coarse_steps_gather_from_level_0(series_file, ratio):
    """A step at a ratio or a stored level is step 0's simplified mesh with that step's values at
    the vertices that survive (each vertex's values are its own, gathered from level 0)."""
    path, meshes = series_file
    f = gatun_py.open(path)
    for level in ([None] if ratio is not None else [1, 2]):
        m0 = f.mesh(ratio, level=level, step=0)
        full0 = f.mesh(step=0)
        pos = by_position(full0.points)
        for k in (4, 9):
            mk, fullk = f.mesh(ratio, level=level, step=k), f.mesh(step=k)
            np.testing.assert_array_equal(mk.tets, m0.tets)
            ids = np.array([pos[p.tobytes()] for p in np.ascontiguousarray(m0.points)])
            np.testing.assert_array_equal(mk.points.view(np.uint8), fullk.points[ids].view(np.uint8))
            for name in fullk.point_data:
                np.testing.assert_array_equal(mk.point_data[name].view(np.uint8),
                                              fullk.point_data[name][ids].view(np.uint8))


def test_render_any_step(series_file):
    path, meshes = series_file
    f = gatun_py.open(path)
    # the sample spacing given: a series samples every step with step 0's (frames compare), a mesh its own
    a = gatun_py.render(f, size=24, time_step=9, scalar_range=(0, 300), step=0.05)
    b = gatun_py.render(meshes[9], size=24, scalar_range=(0, 300), step=0.05)  # the same step from memory
    assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max() <= 1
    assert np.abs(a.rgb.astype(int) - gatun_py.render(f, size=24, step=0.05, scalar_range=(0, 300)).rgb).max() > 10
    c = gatun_py.render(f, size=24, time=f.times[9], scalar_range=(0, 300), ratio=0.5)
    assert c.stats["tets_rendered"] < meshes[0].n_tets


def test_pvd_and_vtk_round_trip(tmp_path, run):
    """A .pvd of zlib .vtu files in, every step out to a .pvd, each .vtu read back by meshio and VTK."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    sub = {k: (v[:6] if k in ("times", "temperature", "heat_flux", "moved") else v) for k, v in run.items()}
    pvd = write_pvd(sub, tmp_path / "in", deforming=True, cell_data=False)
    f = gatun_py.compress(str(pvd), tmp_path / "run.tetc", levels=1)
    assert f.times == tuple(float(t) for t in sub["times"])
    gatun_py.decompress(f.path, tmp_path / "out.pvd")
    back = gatun_py.read_series(str(tmp_path / "out.pvd"))
    assert back.times == list(f.times)
    for k in range(6):
        src = meshio.read(tmp_path / "in" / f"step_{k:04d}.vtu")
        out_file = tmp_path / "out_steps" / f"step_{k:05d}.vtu"
        got = meshio.read(out_file)
        ref = validate_tets(src.points, None, src.cells_dict["tetra"], scalar_name="temperature",
                            point_data={"temperature": src.point_data["temperature"]})[0]
        dec = validate_tets(got.points, None, got.cells_dict["tetra"], scalar_name="temperature",
                            point_data={"temperature": got.point_data["temperature"]})[0]
        assert_same_step(dec, ref)
        r = vtk.vtkXMLUnstructuredGridReader()
        r.SetFileName(str(out_file))
        r.Update()
        grid = r.GetOutput()
        np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()).view(np.uint8),
                                      np.asarray(got.points).view(np.uint8))
        np.testing.assert_array_equal(vtk_to_numpy(grid.GetPointData().GetArray("temperature")).view(np.uint8),
                                      np.asarray(got.point_data["temperature"]).view(np.uint8))


def test_xdmf_round_trip(tmp_path, run):
    pytest.importorskip("h5py")
    meshes = steps_of(run, 4, extra=False)
    f = gatun_py.compress(gatun_py.Series(list(run["times"][:4]), [(lambda m=m: (m, None)) for m in meshes],
                                          ["s"] * 4), tmp_path / "run.tetc", mesh_only=True)
    gatun_py.decompress(f, tmp_path / "out.xdmf")
    g = gatun_py.compress(str(tmp_path / "out.xdmf"), tmp_path / "again.tetc", mesh_only=True)
    assert g.times == f.times
    for k in range(4):
        assert_same_step(g.mesh(step=k), meshes[k])


def test_exodus_every_step(tmp_path, run):
    netCDF4 = pytest.importorskip("netCDF4")
    meshes = steps_of(run, 3, extra=False)
    path = tmp_path / "run.exo"
    with netCDF4.Dataset(path, "w") as nc:
        n, m = meshes[0].n_points, meshes[0].n_tets
        nc.createDimension("num_nodes", n)
        nc.createDimension("num_dim", 3)
        nc.createDimension("num_el_in_blk1", m)
        nc.createDimension("num_nod_per_el1", 4)
        nc.createDimension("time_step", None)
        nc.createDimension("num_nod_var", 1)
        nc.createDimension("len_name", 33)
        for a, name in enumerate("xyz"):
            nc.createVariable(f"coord{name}", "f8", ("num_nodes",))[:] = meshes[0].points[:, a]
        c = nc.createVariable("connect1", "i4", ("num_el_in_blk1", "num_nod_per_el1"))
        c[:] = meshes[0].tets + 1
        c.elem_type = "TETRA"
        nc.createVariable("time_whole", "f8", ("time_step",))[:] = run["times"][:3]
        names = nc.createVariable("name_nod_var", "S1", ("num_nod_var", "len_name"))
        names[0, :] = netCDF4.stringtochar(np.array(["temperature"], "S33"))
        v = nc.createVariable("vals_nod_var1", "f8", ("time_step", "num_nodes"))
        v[:] = np.stack([m.point_data["temperature"] for m in meshes])
    f = gatun_py.compress(str(path), tmp_path / "run.tetc", mesh_only=True)
    assert f.times == tuple(float(t) for t in run["times"][:3])
    for k in range(3):
        assert_same_step(f.mesh(step=k), meshes[k])


# -- random series ----------------------------------------------------------------------------------

@st.composite
def random_series(draw):
    from meshgen import delaunay_mesh

    base = delaunay_mesh(draw(st.integers(8, 40)), draw(st.integers(0, 1000)))
    n = base.n_points
    steps = draw(st.integers(1, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    moving = draw(st.booleans())
    kinds = draw(st.lists(st.sampled_from(["float64", "float32", "int16", "uint64", "vec"]), min_size=0,
                          max_size=3, unique=True))
    drift = rng.normal(size=(n,))
    meshes = []
    for k in range(steps):
        data = {"s": (np.sin(base.points[:, 0] * 3 + 0.3 * k) + 0.01 * k * drift).astype(np.float64)}
        for kind in kinds:
            if kind == "float64":
                a = rng.normal(size=n) * 10.0 ** rng.integers(-5, 5)
                a[rng.random(n) < 0.1] = np.nan
                a[rng.random(n) < 0.1] = -0.0
                data[kind] = a
            elif kind == "float32":
                data[kind] = (np.cos(base.points[:, 1] + k) * 1e3).astype(np.float32)
            elif kind == "int16":
                data[kind] = rng.integers(-2**15, 2**15, n).astype(np.int16)
            elif kind == "uint64":
                data[kind] = rng.integers(0, 2**63, n, dtype=np.uint64) * np.uint64(2) + np.uint64(k)
            else:
                data[kind] = rng.normal(size=(n, 3)) + k
        pts = base.points + (0.001 * k * rng.normal(size=(n, 3)) if moving else 0.0)
        meshes.append(validate_tets(pts, None, base.tets, scalar_name="s", point_data=data, orient=False)[0]
                      if not moving else
                      validate_tets(base.points + 1e-4 * k * np.sin(base.points), None, base.tets, scalar_name="s",
                                    point_data=data)[0])
    interval = draw(st.integers(1, 5))
    return meshes, [0.5 * k for k in range(steps)], interval


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_series(), st.randoms(use_true_random=False))
def test_random_series_round_trip(case, rnd):
    meshes, times, interval = case
    if any(not np.array_equal(m.tets, meshes[0].tets) for m in meshes):
        return  # a moved point flipped a tet: another topology (the encoder refuses it, tested below)
    data = encode_series(meshes, times, mesh_only=True, keyframe_interval=interval)
    f = gatun_py.open(data)
    order = list(range(len(meshes)))
    rnd.shuffle(order)
    for k in order:
        m = f.mesh(step=k)
        ref = meshes[k]
        # decode order -> input order from step 0's decode (the same at every step)
        assert m.n_points == ref.n_points
        for name, a in ref.point_data.items():
            b = m.point_data[name]
            assert b.dtype == a.dtype and b.shape == a.shape
    vo = series_mod._level0_order(meshes[0])[0]
    for k in order:
        m = f.mesh(step=k)
        np.testing.assert_array_equal(m.points.view(np.uint8), meshes[k].points[vo].view(np.uint8))
        for name, a in meshes[k].point_data.items():
            np.testing.assert_array_equal(m.point_data[name].view(np.uint8), a[vo].view(np.uint8))


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=1, max_size=30),
       st.integers(0, 3))
@settings(max_examples=60, deadline=None)
def test_step_array_any_float64(values, order):
    """Any float64 bits, predicted from any history (NaN, inf, -0.0 on either side), come back."""
    v = np.array(values, np.float64)
    rng = np.random.default_rng(len(values))
    hist = [v[::-1].copy() * rng.normal() for _ in range(order)]
    for h in hist:
        h[rng.random(len(h)) < 0.2] = np.inf
    refs = np.full((len(v), 4), -1, np.int32)
    data = encode_step_array(v, refs, history=hist)
    out = decode_step_array(data, refs, n_points=len(v), dtype="float64", components=1, history=hist)
    np.testing.assert_array_equal(out.view(np.int64), v.view(np.int64))


def test_extrapolation_is_a_parabola():
    h = [np.array([9.0]), np.array([4.0]), np.array([1.0])]  # t^2 at t = 3, 2, 1
    assert extrapolate(h)[0] == 16.0 and extrapolate(h[:2])[0] == 14.0 and extrapolate(h[:1])[0] == 9.0


# -- bad inputs -------------------------------------------------------------------------------------

def test_topology_change_names_the_step(run):
    meshes = steps_of(run, 4, extra=False)
    other = validate_tets(run["points"], None, run["tets"][:-1], scalar_name="temperature",
                          point_data={"temperature": run["temperature"][2]})[0]
    with pytest.raises(MeshError, match="step 2"):
        encode_series(meshes[:2] + [other] + meshes[3:], list(run["times"][:4]), mesh_only=True)


def test_times_must_increase(run):
    meshes = steps_of(run, 3, extra=False)
    with pytest.raises(OptionError, match="times go backwards: step 2"):
        encode_series(meshes, [0.0, 1.0, 1.0], mesh_only=True)


def test_pvd_bad_entries(tmp_path, run):
    sub = {k: (v[:2] if k in ("times", "temperature", "heat_flux", "moved") else v) for k, v in run.items()}
    pvd = write_pvd(sub, tmp_path / "a", cell_data=False)
    text = pvd.read_text()
    out = tmp_path / "o.tetc"
    (tmp_path / "a" / "missing.pvd").write_text(text.replace("step_0001.vtu", "nope.vtu"))
    with pytest.raises(ReadError, match="no such file 'nope.vtu'"):
        gatun_py.compress(str(tmp_path / "a" / "missing.pvd"), out)
    (tmp_path / "secret.vtu").write_bytes((tmp_path / "a" / "step_0001.vtu").read_bytes())
    (tmp_path / "a" / "outside.pvd").write_text(text.replace("step_0001.vtu", "../secret.vtu"))
    with pytest.raises(ReadError, match="outside the collection's folder"):
        gatun_py.compress(str(tmp_path / "a" / "outside.pvd"), out)
    (tmp_path / "a" / "back.pvd").write_text(text.replace(f'timestep="{float(sub["times"][1])!r}"', 'timestep="-1"'))
    with pytest.raises(OptionError, match="times go backwards"):
        gatun_py.compress(str(tmp_path / "a" / "back.pvd"), out)
    assert not out.exists()


def test_cell_data_kept_dropped_on_request_or_averaged(tmp_path, run):
    sub = {k: (v[:2] if k in ("times", "temperature", "heat_flux", "moved") else v) for k, v in run.items()}
    pvd = write_pvd(sub, tmp_path / "a", cell_data=True)
    kept = gatun_py.compress(str(pvd), tmp_path / "k.tetc", mesh_only=True)
    assert sorted(kept.cell_data(step=1)) == ["heat_flux"]  # bit for bit: tests/test_series_cells.py
    f = gatun_py.compress(str(pvd), tmp_path / "o.tetc", drop_cell_data=True, mesh_only=True)
    assert f.n_steps == 2 and f.cell_data(step=1) == {}
    g = gatun_py.compress(str(pvd), tmp_path / "p.tetc", cell_to_point=True, scalar="temperature", mesh_only=True)
    assert [a[0] for a in g.arrays] == ["temperature", "heat_flux"]


def test_nan_kept_in_a_field(run):
    meshes = []
    for k in range(3):
        extra = run["temperature"][k].copy()
        extra[::7] = np.nan
        meshes.append(validate_tets(run["points"], None, run["tets"], scalar_name="temperature",
                                    point_data={"temperature": run["temperature"][k], "extra": extra})[0])
    f = gatun_py.open(encode_series(meshes, [0.0, 1.0, 2.0], mesh_only=True))
    vo = series_mod._level0_order(meshes[0])[0]
    for k in range(3):
        np.testing.assert_array_equal(f.mesh(step=k).point_data["extra"].view(np.int64),
                                      meshes[k].point_data["extra"][vo].view(np.int64))


# -- appending --------------------------------------------------------------------------------------

def test_append_matches_compressing_together(tmp_path, run):
    meshes = steps_of(run, 9, moving=True)
    times = list(run["times"][:9])
    whole = tmp_path / "whole.tetc"
    write_series(whole, meshes, times, levels=1, keyframe_interval=4)
    grown = tmp_path / "grown.tetc"
    write_series(grown, meshes[:3], times[:3], levels=1, keyframe_interval=4)
    for k in range(3, 9):
        assert append_step(grown, meshes[k], times[k]) == k
    a, b = gatun_py.open(whole), gatun_py.open(grown)
    assert a.times == b.times
    for k in range(9):
        ma, mb = a.mesh(step=k), b.mesh(step=k)
        np.testing.assert_array_equal(ma.points.view(np.uint8), mb.points.view(np.uint8))
        for name in ma.point_data:
            np.testing.assert_array_equal(ma.point_data[name].view(np.uint8), mb.point_data[name].view(np.uint8))
        assert_same_step(mb, meshes[k])
    # the steps' sections are the same bytes either way
    for k in range(3, 9):
        for j in range(3):
            assert a.reader.read_section(f"S{k}/array/{j}") == b.reader.read_section(f"S{k}/array/{j}")


def test_append_refuses_other_meshes_and_times(tmp_path, run):
    meshes = steps_of(run, 3, extra=False)
    path = tmp_path / "run.tetc"
    write_series(path, meshes[:2], [0.0, 1.0], mesh_only=True)
    before = path.read_bytes()
    other = validate_tets(run["points"], None, run["tets"][1:], scalar_name="temperature",
                          point_data={"temperature": run["temperature"][2]})[0]
    with pytest.raises(MeshError, match="step 2: the mesh differs"):
        append_step(path, other, 2.0)
    with pytest.raises(OptionError, match="times go backwards"):
        append_step(path, meshes[2], 1.0)
    more = validate_tets(run["points"], None, run["tets"], scalar_name="temperature",
                         point_data={"temperature": run["temperature"][2], "x": run["temperature"][2]})[0]
    with pytest.raises(MeshError, match="point arrays"):
        append_step(path, more, 2.0)
    assert path.read_bytes() == before
    snap = tmp_path / "snap.tetc"
    gatun_py.compress(meshes[0], snap, mesh_only=True)
    with pytest.raises(OptionError, match="snapshot"):
        append_step(snap, meshes[1], 1.0)


def test_interrupted_append_keeps_earlier_steps(tmp_path, run):
    """Cut the file at every byte of an appended step (what kill -9 midway leaves): it opens with
    the steps before it; the next append cuts the partial step off and succeeds."""
    meshes = steps_of(run, 4, extra=False)
    path = tmp_path / "run.tetc"
    write_series(path, meshes[:2], [0.0, 1.0], mesh_only=True, keyframe_interval=8)
    append_step(path, meshes[2], 2.0)
    base = path.read_bytes()
    append_step(path, meshes[3], 3.0)
    full = path.read_bytes()
    assert len(full) > len(base) and full.startswith(base)
    want2 = gatun_py.open(base).mesh(step=2)
    for cut in range(len(base), len(full)):
        f = gatun_py.open(full[:cut])
        assert f.n_steps == 3, cut
    for cut in (len(base) + 1, len(base) + 40, len(full) - 1):
        f = gatun_py.open(full[:cut])
        m = f.mesh(step=2)
        np.testing.assert_array_equal(m.point_data["temperature"], want2.point_data["temperature"])
    path.write_bytes(full[:len(full) - 7])  # a kill -9 leaves a partial step: the next append cuts it off
    assert append_step(path, meshes[3], 3.5) == 3
    f = gatun_py.open(path)
    assert f.times == (0.0, 1.0, 2.0, 3.5)
    assert_same_step(f.mesh(step=3), meshes[3])


def test_crash_during_append_write(tmp_path, run, monkeypatch):
    meshes = steps_of(run, 3, extra=False)
    path = tmp_path / "run.tetc"
    write_series(path, meshes[:2], [0.0, 1.0], mesh_only=True)

    def crash(fd, block):
        os.write(fd, block[:len(block) // 2])
        raise KeyboardInterrupt  # the process dies halfway through its write

    monkeypatch.setattr(series_mod, "_CRASH_HOOK", crash)
    with pytest.raises(KeyboardInterrupt):
        append_step(path, meshes[2], 2.0)
    assert gatun_py.open(path).n_steps == 2
    monkeypatch.setattr(series_mod, "_CRASH_HOOK", None)
    assert append_step(path, meshes[2], 2.0) == 2
    assert_same_step(gatun_py.open(path).mesh(step=2), meshes[2])


def test_corrupt_appended_section_is_an_error(tmp_path, run):
    meshes = steps_of(run, 3, extra=False)
    path = tmp_path / "run.tetc"
    write_series(path, meshes[:2], [0.0, 1.0], mesh_only=True)
    append_step(path, meshes[2], 2.0)
    data = bytearray(path.read_bytes())
    data[-5] ^= 0xFF  # inside the step's last section: the step is listed, its data damaged
    f = gatun_py.open(bytes(data))
    assert f.n_steps == 3
    with pytest.raises(CorruptFileError):
        f.mesh(step=2)
    f.mesh(step=1)  # the others still decode


# -- command line -----------------------------------------------------------------------------------

def test_cli_series(tmp_path, run):
    sub = {k: (v[:5] if k in ("times", "temperature", "heat_flux", "moved") else v) for k, v in run.items()}
    write_pvd(sub, tmp_path / "a", cell_data=False)
    files = [str(tmp_path / "a" / f"step_{k:04d}.vtu") for k in range(5)]
    out = str(tmp_path / "run.tetc")
    r = CliRunner().invoke(tetc, ["compress", *files[:4], "--times", "0,0.5,1,2", "--mesh-only", "-o", out, "-q"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(tetc, ["append", out, files[4], "--time", "3", "-q"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(tetc, ["info", out, "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["times"] == [0.0, 0.5, 1.0, 2.0, 3.0] and json.loads(r.output)["steps"] == 5
    r = CliRunner().invoke(tetc, ["decompress", out, "--step", "4", "-o", str(tmp_path / "s4.vtu")])
    assert r.exit_code == 0, r.output
    got = meshio.read(tmp_path / "s4.vtu").point_data["temperature"]
    assert sorted(got.tolist()) == sorted(sub["temperature"][4].tolist())
    r = CliRunner().invoke(tetc, ["decompress", out, "--time", "0.5", "-o", str(tmp_path / "s1.vtu")])
    assert r.exit_code == 0, r.output
    for args, code, msg in [(["decompress", out, "--step", "5", "-o", str(tmp_path / "x.vtu")], 2, "step 5 does not exist"),
                            (["decompress", out, "--time", "0.7", "-o", str(tmp_path / "x.vtu")], 2, "no step at time"),
                            (["render", out, "--time-step", "-9", "-o", str(tmp_path / "x.png")], 2, "does not exist"),
                            (["compress", files[0], files[1], "--times", "1,0", "-o", str(tmp_path / "y.tetc")], 1,
                             "times go backwards"),
                            (["compress", files[0], str(tmp_path / "nope.vtu"), "-o", str(tmp_path / "y.tetc")], 1,
                             "no such file"),
                            (["append", out, files[0], "--time", "1"], 1, "times go backwards")]:
        r = CliRunner().invoke(tetc, args)
        assert r.exit_code == code and msg in r.output, (args, r.output)
    assert not (tmp_path / "x.vtu").exists() and not (tmp_path / "y.tetc").exists()
    r = CliRunner().invoke(tetc, ["render", out, "--steps", "1::2", "--size", "16", "-o",
                                  str(tmp_path / "f{frame}_s{step:02d}.png"), "-q"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob("f*.png")) == ["f0_s01.png", "f1_s03.png"]
    r = CliRunner().invoke(tetc, ["isosurface", out, "--value", "100", "--time-step", "4", "-o",
                                  str(tmp_path / "iso.ply"), "-q"])
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("change", [
    lambda st: st["entries"][1].update(ref=3),            # predicted from a later step
    lambda st: st["entries"][2].update(order=5),          # reaching before step 0
    lambda st: st.update(times=st["times"][::-1]),        # times going backwards
    lambda st: st.update(keyframe_interval=0),
    lambda st: st["entries"].pop(),                       # fewer entries than times
    lambda st: st.update(maps=["1"]),
])
def test_bad_step_metadata_is_a_corrupt_file(run, change):
    from gatun_py.codec.container import build_container, split_container

    meshes = steps_of(run, 3, extra=False)
    meta, sections = split_container(encode_series(meshes, [0.0, 1.0, 2.0], mesh_only=True))
    change(meta["steps"])
    f = gatun_py.open(build_container(meta, sections))
    with pytest.raises(CorruptFileError):
        f.mesh(step=2)
