"""VTKHDF in and out (gatun_py.mesh.vtkhdf): bit-exact round trips, VTK's own vtkHDFReader and
vtkHDFWriter as the peer, temporal and partitioned files, bad files, and the CLI."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="VTKHDF needs h5py (pip install 'gatun_py[vtkhdf]')")

import gatun_py  # noqa: E402
from cli_util import assert_error, run  # noqa: E402
from gatun_py.errors import ReadError  # noqa: E402
from gatun_py.mesh import read_mesh  # noqa: E402
from gatun_py.mesh.vtkhdf import read_vtkhdf, write_vtkhdf  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POST = ROOT / "tests" / "data" / "post_v9.tetc"  # float32, float64, int32 and a 3-vector point array


@pytest.fixture(scope="module")
def post():
    return gatun_py.open(POST).mesh()


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _vtk():
    pytest.importorskip("vtkmodules.vtkIOHDF", reason="VTK's vtkHDFReader (pip install vtk) is the peer")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
    from vtkmodules.vtkIOHDF import vtkHDFReader
    return vtkHDFReader, vtk_to_numpy, vtkStreamingDemandDrivenPipeline


def test_round_trip_bit_exact_every_array(tmp_path, post):
    path = tmp_path / "post.vtkhdf"
    write_vtkhdf(path, post)
    s = read_vtkhdf(path)
    assert s.times == (0.0,) and s.n_steps == 1
    assert _same(s.mesh.points, post.points)
    assert [c.type for c in s.mesh.cells] == ["tetra"]
    assert _same(s.mesh.cells[0].data, post.tets.astype(np.int64))
    assert set(s.mesh.point_data) == set(post.user_point_data)
    for name, a in post.user_point_data.items():
        assert _same(s.mesh.point_data[name], a), name


def test_vtk_reads_ours_bit_exact(tmp_path, post):
    vtkHDFReader, vtk_to_numpy, _ = _vtk()
    path = tmp_path / "post.vtkhdf"
    write_vtkhdf(path, post, deflate=4)
    r = vtkHDFReader()
    r.SetFileName(str(path))
    r.Update()
    g = r.GetOutput()
    assert g.GetNumberOfCells() == post.n_tets and g.GetNumberOfPoints() == post.n_points
    assert _same(vtk_to_numpy(g.GetPoints().GetData()), post.points)
    conn = vtk_to_numpy(g.GetCells().GetConnectivityArray()).reshape(-1, 4)
    assert (conn == post.tets).all() and {g.GetCellType(i) for i in range(post.n_tets)} == {10}
    for name, a in post.user_point_data.items():
        assert _same(vtk_to_numpy(g.GetPointData().GetArray(name)), a), name


def test_temporal_40_steps_open_in_vtk_with_40_steps(tmp_path, post):
    vtkHDFReader, vtk_to_numpy, sddp = _vtk()
    rng = np.random.default_rng(5)
    times = np.cumsum(rng.uniform(0.01, 0.2, 40))
    steps = [(t, {"T": rng.standard_normal(post.n_points), "u": rng.standard_normal((post.n_points, 3)).astype(np.float32)},
              {"q": rng.integers(0, 9, post.n_tets).astype(np.int32)}) for t in times]
    path = tmp_path / "series.vtkhdf"
    write_vtkhdf(path, post, steps=steps)
    ours = read_vtkhdf(path)
    assert ours.times == tuple(float(t) for t in times)
    r = vtkHDFReader()
    r.SetFileName(str(path))
    r.UpdateInformation()
    info = r.GetOutputInformation(0)
    vtk_times = info.Get(sddp.TIME_STEPS())
    assert len(vtk_times) == 40 and np.array_equal(vtk_times, times)
    for k in (0, 17, 39):
        r.UpdateTimeStep(times[k])
        g = r.GetOutput()
        assert g.GetNumberOfCells() == post.n_tets
        assert _same(vtk_to_numpy(g.GetPointData().GetArray("T")), steps[k][1]["T"])
        assert _same(vtk_to_numpy(g.GetPointData().GetArray("u")), steps[k][1]["u"])
        assert _same(vtk_to_numpy(g.GetCellData().GetArray("q")), steps[k][2]["q"])
        # the mesh's own arrays, which no step names, are written once and replayed at every step
        assert _same(vtk_to_numpy(g.GetPointData().GetArray("Pressure")), post.user_point_data["Pressure"])
        m = ours.step_mesh(k)
        assert _same(m.point_data["T"], steps[k][1]["T"]) and _same(m.cell_data["q"][0], steps[k][2]["q"])
    # read_mesh takes a step (the last by default, as for Exodus) with a note
    mesh, report = read_mesh(path, scalar="T")
    assert _same(mesh.user_point_data["T"], steps[-1][1]["T"])
    assert any("40 steps" in n for n in report.notes)
    mesh, _ = read_mesh(path, scalar="T", time_step=3)
    assert _same(mesh.user_point_data["T"], steps[3][1]["T"])


def _vtk_temporal_source(n_steps):
    """A VTK algorithm whose grid (two tets) and arrays change with time: what vtkHDFWriter writes."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkUnstructuredGrid
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as sddp

    class Source(VTKPythonAlgorithmBase):
        def __init__(self):
            super().__init__(nInputPorts=0, nOutputPorts=1, outputType="vtkUnstructuredGrid")

        def RequestInformation(self, request, inInfo, outInfo):
            info = outInfo.GetInformationObject(0)
            for t in range(n_steps):
                info.Append(sddp.TIME_STEPS(), 0.25 * t)
            info.Set(sddp.TIME_RANGE(), [0.0, 0.25 * (n_steps - 1)], 2)
            return 1

        def RequestData(self, request, inInfo, outInfo):
            info = outInfo.GetInformationObject(0)
            t = info.Get(sddp.UPDATE_TIME_STEP()) if info.Has(sddp.UPDATE_TIME_STEP()) else 0.0
            g = vtkUnstructuredGrid.GetData(outInfo)
            pts = vtkPoints()
            pts.SetData(numpy_to_vtk(np.eye(5, 3, k=-1) * (1.0 + t), deep=1))
            g.SetPoints(pts)
            g.Allocate(2)
            g.InsertNextCell(10, 4, [0, 1, 2, 3])
            g.InsertNextCell(10, 4, [1, 2, 3, 4])
            a = numpy_to_vtk(np.arange(5.0) + t, deep=1)
            a.SetName("p")
            g.GetPointData().AddArray(a)
            return 1

    return Source()


def test_reads_vtk_writers_temporal_file(tmp_path):
    pytest.importorskip("vtkmodules.vtkIOHDF")
    from vtkmodules.vtkIOHDF import vtkHDFWriter
    path = tmp_path / "vtk.vtkhdf"
    source = _vtk_temporal_source(3)  # held: VTK calls back into its Python methods
    w = vtkHDFWriter()
    w.SetInputConnection(source.GetOutputPort())
    w.SetFileName(str(path))
    if hasattr(w, "SetWriteAllTimeSteps"):
        w.SetWriteAllTimeSteps(True)
    w.Write()
    s = read_vtkhdf(path)
    assert s.times == (0.0, 0.25, 0.5)
    for k, t in enumerate(s.times):  # VTK's writer stores the (changing) mesh at every step
        m = s.step_mesh(k)
        assert np.array_equal(m.points, np.eye(5, 3, k=-1) * (1.0 + t))
        assert np.array_equal(m.point_data["p"], np.arange(5.0) + t)
        assert m.cells[0].data.tolist() == [[0, 1, 2, 3], [1, 2, 3, 4]]


def _partitioned_file(path, parts):
    """A VTKHDF unstructured grid of several partitions, laid out as the specification says (one
    per MPI rank: each part's ids local to its points, cells + 1 offsets per part); each part
    ``(points, tets, point arrays by name, or one array named rho)``."""
    with h5py.File(path, "w") as f:
        g = f.create_group("VTKHDF")
        g.attrs["Version"] = np.array([1, 0])
        g.attrs["Type"] = np.bytes_(b"UnstructuredGrid")
        g["NumberOfPoints"] = np.array([len(p) for p, _, _ in parts], np.int64)
        g["NumberOfCells"] = np.array([len(t) for _, t, _ in parts], np.int64)
        g["NumberOfConnectivityIds"] = np.array([t.size for _, t, _ in parts], np.int64)
        g["Points"] = np.concatenate([p for p, _, _ in parts])
        g["Connectivity"] = np.concatenate([t.reshape(-1) for _, t, _ in parts]).astype(np.int64)
        g["Offsets"] = np.concatenate([np.arange(len(t) + 1) * 4 for _, t, _ in parts]).astype(np.int64)
        g["Types"] = np.full(sum(len(t) for _, t, _ in parts), 10, np.uint8)
        pd = g.create_group("PointData")
        data = [d if isinstance(d, dict) else {"rho": d} for _, _, d in parts]  # one array: rho
        for name in data[0]:
            pd[name] = np.concatenate([d[name] for d in data])


def test_partitioned_file_read_as_vtk_reads_it(tmp_path, post):
    vtkHDFReader, vtk_to_numpy, _ = _vtk()
    # two partitions of the post mesh, each with its own copy of the points it uses
    half = post.n_tets // 2
    parts = []
    for tets in (post.tets[:half], post.tets[half:]):
        used, local = np.unique(tets, return_inverse=True)
        parts.append((post.points[used], local.reshape(-1, 4), post.user_point_data["wave64"][used]))
    path = tmp_path / "parts.vtkhdf"
    _partitioned_file(path, parts)
    s = read_vtkhdf(path)
    assert any("2 partitions" in n for n in s.notes)
    r = vtkHDFReader()
    r.SetFileName(str(path))
    r.Update()
    g = r.GetOutputDataObject(0)
    if g.IsA("vtkPartitionedDataSet") or g.IsA("vtkMultiBlockDataSet"):
        from vtkmodules.vtkFiltersCore import vtkAppendFilter  # VTK >= 9.3 keeps the parts apart
        app = vtkAppendFilter()
        app.AddInputData(g.GetPartition(0) if g.IsA("vtkPartitionedDataSet") else g.GetBlock(0))
        app.AddInputData(g.GetPartition(1) if g.IsA("vtkPartitionedDataSet") else g.GetBlock(1))
        app.Update()
        g = app.GetOutput()
    assert g.GetNumberOfCells() == post.n_tets == len(s.mesh.cells[0].data)
    assert _same(vtk_to_numpy(g.GetPoints().GetData()), s.mesh.points)
    assert _same(vtk_to_numpy(g.GetPointData().GetArray("rho")), s.mesh.point_data["rho"])
    assert np.array_equal(vtk_to_numpy(g.GetCells().GetConnectivityArray()).reshape(-1, 4), s.mesh.cells[0].data)
    # compressing it keeps every value: the stored mesh's points carry the same (point, rho) pairs
    out = tmp_path / "parts.tetc"
    gatun_py.compress(path, out, levels=1)
    back = gatun_py.open(out).mesh()
    want = {(p.tobytes(), r.tobytes()) for p, r in zip(s.mesh.points, s.mesh.point_data["rho"])}
    got = {(p.tobytes(), r.tobytes()) for p, r in zip(back.points, back.user_point_data["rho"])}
    assert got == want and back.n_tets == post.n_tets


def _records(mesh):
    """Each point's coordinates and array values as bytes, and each tet as the set of its points'
    records: what survives the compressor's renumbering."""
    names = sorted(mesh.user_point_data)
    rec = [mesh.points[i].tobytes() + b"".join(np.asarray(mesh.user_point_data[n][i]).tobytes() for n in names)
           for i in range(mesh.n_points)]
    return sorted(rec), sorted(tuple(sorted(rec[i] for i in t)) for t in mesh.tets.tolist())


def test_cli_decompress_compress_round_trip(tmp_path, post):
    out = tmp_path / "post.vtkhdf"
    res = run("decompress", POST, "-o", out)
    assert res.exit_code == 0, res.output
    assert read_vtkhdf(out).mesh.points.shape == post.points.shape
    res = run("compress", out, "-o", tmp_path / "again.tetc", "--scalar", "Pressure", "--levels", "1", "-q")
    assert res.exit_code == 0, res.output
    again = gatun_py.open(tmp_path / "again.tetc").mesh()
    assert _records(again) == _records(post)
    assert_error(run("decompress", POST, "-o", out), "--force")


def _bad(path, make):
    with h5py.File(path, "w") as f:
        make(f)
    return path


@pytest.mark.parametrize("make, words", [
    (lambda f: f.create_group("other"), "without a VTKHDF group"),
    (lambda f: f.create_group("VTKHDF").attrs.update({"Version": [3, 0], "Type": np.bytes_(b"UnstructuredGrid")}),
     "newer"),
    (lambda f: f.create_group("VTKHDF").attrs.update({"Version": [2, 0], "Type": np.bytes_(b"ImageData")}),
     "not an UnstructuredGrid"),
    (lambda f: f.create_group("VTKHDF").attrs.update({"Version": [2, 0], "Type": np.bytes_(b"UnstructuredGrid")}),
     "inconsistent"),
])
def test_bad_files_raise_one_clear_error(tmp_path, make, words):
    path = _bad(tmp_path / "bad.vtkhdf", make)
    with pytest.raises(ReadError, match=words):
        read_vtkhdf(path)
    assert_error(run("info", path), words)


def test_not_hdf5_and_truncated(tmp_path, post):
    junk = tmp_path / "junk.vtkhdf"
    junk.write_bytes(b"not an hdf5 file at all" * 10)
    with pytest.raises(ReadError, match="not an HDF5 file"):
        read_vtkhdf(junk)
    path = tmp_path / "cut.vtkhdf"
    write_vtkhdf(path, post)
    with h5py.File(path, "r+") as f:  # the connectivity shorter than its count says
        del f["VTKHDF/Connectivity"]
        f["VTKHDF/Connectivity"] = np.zeros(10, np.int64)
    with pytest.raises(ReadError, match="shorter"):
        read_vtkhdf(path)


def test_series_decompress_to_temporal_vtkhdf(tmp_path):
    from test_paraview_plugin import make_series  # the same 40-step series the ParaView test opens
    src = make_series(tmp_path)
    f = gatun_py.open(src)
    out = tmp_path / "series.vtkhdf"
    gatun_py.decompress(src, out)
    s = read_vtkhdf(out)
    assert s.n_steps == f.n_steps == 40 and s.times == tuple(f.times)
    for k in (0, 39):
        want = f.mesh(step=k)
        for name, a in want.user_point_data.items():
            assert _same(s.step_mesh(k).point_data[name], a)


# -- a temporal VTKHDF compressed: every step -------------------------------------------------------

HEAT = ROOT / "tests" / "data" / "series_heat.npz"  # scikit-fem heat conduction: 40 steps, float64


def _heat_vtkhdf(path, moving=False):
    """The solver's 40 steps as one temporal VTKHDF (the cells once; the points once, or every
    step's deformed ones), three arrays of three dtypes."""
    d = np.load(HEAT)
    mesh = meshio.Mesh(d["points"], [("tetra", d["tets"].astype(np.int64))])
    steps = [(t, {"temperature": d["temperature"][k], "t32": d["temperature"][k].astype(np.float32),
                  "band": np.floor(d["temperature"][k] / 10).astype(np.int16)}, {},
              d["moved"][k] if moving else d["points"])
             for k, t in enumerate(d["times"])]
    write_vtkhdf(path, mesh, steps=steps)
    return d, steps


def _step_arrays(path):
    """(times, points, tets, [point arrays of every step]) of a VTKHDF file through VTK's own reader."""
    vtkHDFReader, vtk_to_numpy, sddp = _vtk()
    r = vtkHDFReader()
    r.SetFileName(str(path))
    r.UpdateInformation()
    times = list(r.GetOutputInformation(0).Get(sddp.TIME_STEPS()))
    per_step, points, tets = [], [], None
    for t in times:
        r.UpdateTimeStep(t)
        g = r.GetOutput()
        pd = g.GetPointData()
        per_step.append({pd.GetArrayName(i): vtk_to_numpy(pd.GetArray(i)).copy() for i in range(pd.GetNumberOfArrays())})
        points.append(vtk_to_numpy(g.GetPoints().GetData()).copy())
        tets = vtk_to_numpy(g.GetCells().GetConnectivityArray()).reshape(-1, 4).copy()
    return times, points, tets, per_step


@pytest.mark.parametrize("moving", [False, True], ids=["static", "deforming"])
def test_temporal_vtkhdf_compresses_every_step_bit_exact(tmp_path, moving):
    """run.vtkhdf -> .tetc -> run.vtkhdf: one series file with every step and its exact time; back
    in VTKHDF every step's every array (and its coordinates, where the mesh moves) holds the input's
    bits (the points in the decoder's order, matched by their coordinate bits), as VTK's own
    vtkHDFReader reads it."""
    src = tmp_path / "run.vtkhdf"
    d, steps = _heat_vtkhdf(src, moving)
    res = run("compress", src, "-o", tmp_path / "run.tetc", "--scalar", "temperature", "--mesh-only", "-q")
    assert res.exit_code == 0, res.output
    f = gatun_py.open(tmp_path / "run.tetc")
    assert f.n_steps == 40 and f.times == tuple(float(t) for t in d["times"])  # exact, not rounded
    res = run("decompress", tmp_path / "run.tetc", "-o", tmp_path / "back.vtkhdf")
    assert res.exit_code == 0, res.output
    times, points, tets, per_step = _step_arrays(tmp_path / "back.vtkhdf")
    assert times == list(f.times)
    where = {p.tobytes(): i for i, p in enumerate(np.ascontiguousarray(steps[0][3]))}
    perm = np.array([where[p.tobytes()] for p in np.ascontiguousarray(points[0])])
    assert {tuple(r) for r in np.sort(perm[tets], axis=1)} == {tuple(r) for r in np.sort(d["tets"], axis=1)}
    for k, (_, want, _, pts) in enumerate(steps):
        assert _same(points[k], pts[perm]), k
        assert set(per_step[k]) == set(want), k
        for name, a in want.items():
            assert _same(per_step[k][name], a[perm]), (k, name)
    # once in the decoder's order, the round trip gives the same file content back, bit for bit
    res = run("compress", tmp_path / "back.vtkhdf", "-o", tmp_path / "again.tetc", "--scalar", "temperature",
              "--mesh-only", "-q")
    assert res.exit_code == 0, res.output
    gatun_py.decompress(tmp_path / "again.tetc", tmp_path / "again.vtkhdf")
    t2, p2, c2, s2 = _step_arrays(tmp_path / "again.vtkhdf")
    assert t2 == times and _same(c2, tets) and all(_same(a, b) for a, b in zip(p2, points))
    assert all(_same(s2[k][n], per_step[k][n]) for k in range(40) for n in per_step[k])


def test_temporal_vtkhdf_step_options(tmp_path):
    src = tmp_path / "run.vtkhdf"
    d, steps = _heat_vtkhdf(src)
    # --time-step picks one step, compressed as a snapshot
    res = run("compress", src, "-o", tmp_path / "one.tetc", "--time-step", "7", "--scalar", "temperature",
              "--mesh-only", "-q")
    assert res.exit_code == 0, res.output
    one = gatun_py.open(tmp_path / "one.tetc")
    assert one.n_steps == 1
    got = one.mesh().user_point_data["temperature"]
    assert sorted(got.tobytes()[i:i + 8] for i in range(0, got.nbytes, 8)) == \
        sorted(steps[7][1]["temperature"].tobytes()[i:i + 8] for i in range(0, got.nbytes, 8))
    # cell data per step is kept, step by step, bit for bit (as a multiset: the tets are reordered)
    mesh = meshio.Mesh(d["points"], [("tetra", d["tets"].astype(np.int64))])
    write_vtkhdf(tmp_path / "cd.vtkhdf", mesh, steps=[(t, {"T": d["temperature"][k]},
                                                         {"q": d["heat_flux"][k]}) for k, t in
                                                        enumerate(d["times"][:3])])
    res = run("compress", tmp_path / "cd.vtkhdf", "-o", tmp_path / "cd.tetc", "--mesh-only", "-q")
    assert res.exit_code == 0, res.output
    f = gatun_py.open(tmp_path / "cd.tetc")
    assert f.n_steps == 3
    for k in range(3):
        got, want = f.cell_data(step=k)["q"], np.asarray(d["heat_flux"][k])
        assert got.dtype == want.dtype and sorted(map(bytes, got.reshape(len(got), -1))) == \
            sorted(map(bytes, want.reshape(len(want), -1)))


# -- VTKHDF partitions are pieces ----------------------------------------------------------------------

def _write_partitions(path, pieces):
    """``pieces`` (TetMeshes with their own numbering) as the partitions of one VTKHDF file, every
    point array in its dtype."""
    _partitioned_file(path, [(p.points, p.tets, p.user_point_data) for p in pieces])


def test_partitions_compress_as_pieces_like_the_same_pvtu(tmp_path):
    """A VTKHDF file of 5 partitions goes through the pieces path (each partition a brick, the
    points repeated on the seams stored once) and gives the same bricks, byte for byte, and the same
    decode as the same pieces written as a .pvtu file."""
    from gatun_py.codec import TetcReader
    from gatun_py.codec.bricks import decode_bricked
    from gatun_py.codec.container import split_container
    from gatun_py.mesh.pieces import is_partitioned, piece_paths, read_piece, write_pvtu
    from gatun_py.pipeline.compress_pieces import PIECES_KEY
    from test_bricks import assert_same_mesh
    from test_pieces import rich_mesh, solver_pieces
    mesh = rich_mesh()
    pieces = solver_pieces(mesh, 5)
    write_pvtu(pieces, tmp_path / "run.pvtu")
    _write_partitions(tmp_path / "run.vtkhdf", pieces)
    write_vtkhdf(tmp_path / "whole.vtkhdf", mesh)
    assert is_partitioned(tmp_path / "run.vtkhdf") and not is_partitioned(tmp_path / "whole.vtkhdf")
    parts = piece_paths(tmp_path / "run.vtkhdf")
    assert [p.name for p in parts] == [f"run.vtkhdf#{i}" for i in range(5)]
    for p, want in zip(parts, pieces):  # each partition alone, in its own numbering
        got, _ = read_piece(p, {"scalar": "density"})
        assert _same(got.points, want.points) and np.array_equal(got.tets, want.tets)
        assert all(_same(got.user_point_data[n], a) for n, a in want.user_point_data.items())
    outs = {}
    for src in ("run.pvtu", "run.vtkhdf"):
        res = run("compress", tmp_path / src, "-o", tmp_path / f"{src}.tetc", "--scalar", "density",
                  "--mesh-only", "-q")
        assert res.exit_code == 0, res.output
        outs[src] = tmp_path / f"{src}.tetc"
    r = TetcReader(outs["run.vtkhdf"])
    assert r.n_bricks == 5 and [p["source"] for p in r.meta[PIECES_KEY]] == [p.name for p in parts]
    assert_same_mesh(decode_bricked(r, jobs=1), mesh)  # every shared point once, every bit kept
    (_, sa), (_, sb) = (split_container(outs[k].read_bytes()) for k in ("run.pvtu", "run.vtkhdf"))
    # the same bricks' meshes, byte for byte (HDF5 lists a file's arrays by name, the .pvtu in its
    # order: the arrays' sections are numbered in that order), and the same decode
    assert [x for x in sa if "/array/" not in x[0]] == [x for x in sb if "/array/" not in x[0]]
    a, b = (decode_bricked(TetcReader(outs[k]), jobs=1) for k in ("run.pvtu", "run.vtkhdf"))
    assert _same(a.points, b.points) and np.array_equal(a.tets, b.tets)
    assert set(a.point_data) == set(b.point_data)
    assert all(_same(a.point_data[n], b.point_data[n]) for n in a.point_data)


def test_partition_bad_input(tmp_path):
    from gatun_py.mesh.vtkhdf import read_vtkhdf_partition
    from test_pieces import rich_mesh, solver_pieces
    pieces = solver_pieces(rich_mesh(), 3)
    _write_partitions(tmp_path / "run.vtkhdf", pieces)
    with pytest.raises(ReadError, match="no partition 3"):
        read_vtkhdf_partition(tmp_path / "run.vtkhdf", 3)


# -- the cells as given through VTKHDF --------------------------------------------------------------

CELLS = ROOT / "tests" / "data" / "cells_v10.tetc"  # hexahedra, pyramids, tets, tetra10, wedges; cell arrays


def _cells_as_given(path):
    """The cells as given of a .tetc file, as the decompress verb writes them (a meshio.Mesh); bool
    arrays as uint8, as VTK (and so VTKHDF) holds them."""
    from gatun_py.codec.cells import read_cells, restore_order
    from gatun_py.mesh.io import to_meshio
    f = gatun_py.open(path)
    m = f.mesh()
    want = to_meshio(*restore_order(m, read_cells(f.reader, m.tets, m.n_points, m.points)))
    for name, blocks in want.cell_data.items():
        want.cell_data[name] = [b.view(np.uint8) if b.dtype == np.bool_ else b for b in blocks]
    return want


def test_original_cells_and_cell_data_through_vtkhdf(tmp_path):
    """decompress -o x.vtkhdf writes the cells as given (VTK's types and offsets) with every point and
    cell array, as the .vtu the verb writes; VTK reads them so; compressing the VTKHDF keeps them."""
    vtkHDFReader, vtk_to_numpy, _ = _vtk()
    want = _cells_as_given(CELLS)
    res = run("decompress", CELLS, "-o", tmp_path / "x.vtkhdf")
    assert res.exit_code == 0, res.output
    got = read_vtkhdf(tmp_path / "x.vtkhdf").mesh
    assert [(c.type, len(c.data)) for c in got.cells] == [(c.type, len(c.data)) for c in want.cells]
    assert len({c.type for c in got.cells}) == 5
    assert all(np.array_equal(a.data, b.data) for a, b in zip(got.cells, want.cells))
    assert _same(got.points, want.points)
    assert set(got.point_data) == set(want.point_data) and set(got.cell_data) == set(want.cell_data)
    assert sorted(got.field_data) == ["air", "steel"]  # gmsh's physical names: [tag, dimension]
    for name, a in want.point_data.items():
        assert _same(got.point_data[name], a), name
    for name, blocks in want.cell_data.items():
        assert all(_same(x, y) for x, y in zip(got.cell_data[name], blocks)), name
    r = vtkHDFReader()
    r.SetFileName(str(tmp_path / "x.vtkhdf"))
    r.Update()
    g = r.GetOutput()
    assert g.GetNumberOfCells() == sum(len(c.data) for c in want.cells)
    types = vtk_to_numpy(g.GetCellTypesArray())
    assert sorted(set(types.tolist())) == [10, 12, 13, 14, 24]
    for name, blocks in want.cell_data.items():
        assert _same(vtk_to_numpy(g.GetCellData().GetArray(name)), np.concatenate(blocks)), name
    # a mixed VTKHDF compresses with its cells kept: decompressing gives them back
    res = run("compress", tmp_path / "x.vtkhdf", "-o", tmp_path / "again.tetc", "--mesh-only", "-q")
    assert res.exit_code == 0, res.output
    gatun_py.decompress(tmp_path / "again.tetc", tmp_path / "again.vtkhdf")
    back = read_vtkhdf(tmp_path / "again.vtkhdf").mesh
    assert sorted((c.type, len(c.data)) for c in back.cells) == sorted((c.type, len(c.data)) for c in want.cells)
    assert set(back.cell_data) == set(want.cell_data)
    for name in want.cell_data:  # the same values per cell type (the cells in the decoder's order)
        for t in {c.type for c in want.cells}:
            x = np.concatenate([v for c, v in zip(want.cells, want.cell_data[name]) if c.type == t])
            y = np.concatenate([v for c, v in zip(back.cells, back.cell_data[name]) if c.type == t])
            assert sorted(x.reshape(len(x), -1).tolist()) == sorted(y.reshape(len(y), -1).tolist()), (name, t)
    # --as-tets writes the split
    res = run("decompress", CELLS, "-o", tmp_path / "tets.vtkhdf", "--as-tets")
    assert res.exit_code == 0, res.output
    assert [c.type for c in read_vtkhdf(tmp_path / "tets.vtkhdf").mesh.cells] == ["tetra"]
