"""Cell arrays of every step of a series: stored per tet, lossless in their dtype, read back by
TetcFile.cell_data(step=), decompress --step and -o .pvd (meshio and VTK), appended with a step.

Real solver output: tests/data/series_heat.npz's ``heat_flux`` (scikit-fem, the magnitude of
-k grad T per tet, float64) beside an integer band per tet; random series of random dtypes
(hypothesis). The oracle: each decoded tet's values equal the input tet's with the same vertices.
"""

import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gatun_py
from gatun_py.errors import MeshError
from gatun_py.mesh.validate import validate_tets
from gatun_py.pipeline.series import append_step, encode_series, write_series

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
from series_data import load, write_pvd  # noqa: E402

DATA = Path(__file__).parent / "data"
N = 8


@pytest.fixture(scope="module")
def run():
    return load(DATA / "series_heat.npz")


def steps(run, n=N, *, moving=False):
    meshes = [validate_tets(run["moved"][k] if moving else run["points"], None, run["tets"],
                            scalar_name="temperature", point_data={"temperature": run["temperature"][k]})[0]
              for k in range(n)]
    for m in meshes:  # the solver's tets are positively oriented: validation keeps their order
        assert np.array_equal(m.tets, run["tets"])
    cells = [{"heat_flux": run["heat_flux"][k], "band": np.floor(run["heat_flux"][k] * 4).astype(np.int32)}
             for k in range(n)]
    return meshes, cells


def input_rows(decoded_points, decoded_tets, points, tets):
    """Input tet index of every decoded tet (matched by the coordinates of its vertices)."""
    where = {p.tobytes(): i for i, p in enumerate(np.ascontiguousarray(points))}
    perm = np.array([where[p.tobytes()] for p in np.ascontiguousarray(decoded_points)])
    key = {tuple(sorted(t)): i for i, t in enumerate(np.asarray(tets).tolist())}
    return np.array([key[tuple(sorted(t))] for t in perm[np.asarray(decoded_tets)].tolist()])


def assert_cells(got: dict, want: dict, rows):
    assert set(got) == set(want)
    for name, a in want.items():
        b = got[name]
        assert b.dtype == a.dtype and b.shape == a.shape, name
        np.testing.assert_array_equal(b.view(np.uint8), a[rows].view(np.uint8))


@pytest.mark.parametrize("moving", [False, True], ids=["static", "deforming"])
def test_solver_cell_arrays_bit_exact_at_every_step(run, tmp_path, moving):
    meshes, cells = steps(run, moving=moving)
    path = tmp_path / "run.tetc"
    write_series(path, meshes, list(run["times"][:N]), mesh_only=True, keyframe_interval=3,
                 cell_data=lambda k: cells[k])
    f = gatun_py.open(path)
    m0 = f.mesh(step=0)
    rows = input_rows(m0.points, m0.tets, meshes[0].points, meshes[0].tets)
    for k in [5, 0, 7, 2, 6, 1, 3, 4]:  # random access
        assert_cells(f.cell_data(step=k), cells[k], rows)
    c = f.reader.container
    cell_bytes = sum(c.section_size(f"S{k}/cell/0") for k in range(1, N))
    assert cell_bytes < sum(cells[k]["heat_flux"].nbytes for k in range(1, N))  # 0.82x raw here


def test_pvd_in_decompress_step_and_pvd_out(run, tmp_path):
    """A .pvd of zlib .vtu files with cell data in; --step and -o .pvd out, read by meshio and VTK."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    sub = {k: (v[:5] if k in ("times", "temperature", "heat_flux", "moved") else v) for k, v in run.items()}
    pvd = write_pvd(sub, tmp_path / "in", cell_data=True)
    f = gatun_py.compress(str(pvd), tmp_path / "run.tetc", levels=1)
    assert f.reader.meta["steps"]["cells"] == [{"name": "heat_flux", "dtype": "float64", "components": 1}]
    gatun_py.decompress(f.path, tmp_path / "s3.vtu", step=3)
    gatun_py.decompress(f.path, tmp_path / "out.pvd")
    for k, out in [(3, tmp_path / "s3.vtu")] + [(k, tmp_path / "out_steps" / f"step_{k:05d}.vtu") for k in range(5)]:
        got = meshio.read(out)
        rows = input_rows(got.points, got.cells_dict["tetra"], sub["points"], sub["tets"])
        a = np.asarray(got.cell_data["heat_flux"][0])
        np.testing.assert_array_equal(a.view(np.uint8), sub["heat_flux"][k][rows].view(np.uint8))
        r = vtk.vtkXMLUnstructuredGridReader()
        r.SetFileName(str(out))
        r.Update()
        v = vtk_to_numpy(r.GetOutput().GetCellData().GetArray("heat_flux"))
        np.testing.assert_array_equal(v.view(np.uint8), a.view(np.uint8))
    # a simplified step has other tets: written without the cell arrays, and says so
    notes = []
    gatun_py.decompress(f.path, tmp_path / "coarse.vtu", step=2, level=1, log=notes.append)
    assert not meshio.read(tmp_path / "coarse.vtu").cell_data and any("cell arrays" in n for n in notes)


def test_append_keeps_cell_arrays(run, tmp_path):
    meshes, cells = steps(run)
    path = tmp_path / "run.tetc"
    write_series(path, meshes[:4], list(run["times"][:4]), mesh_only=True, keyframe_interval=3,
                 cell_data=lambda k: cells[k])
    for k in range(4, N):
        assert append_step(path, meshes[k], float(run["times"][k]), cell_data=cells[k]) == k
    with pytest.raises(MeshError, match="cell arrays"):
        append_step(path, meshes[0], 99.0)
    with pytest.raises(MeshError, match="step 8: cell arrays"):
        append_step(path, meshes[0], 99.0, cell_data={"heat_flux": cells[0]["heat_flux"]})
    f = gatun_py.open(path)
    assert f.n_steps == N
    m0 = f.mesh()
    rows = input_rows(m0.points, m0.tets, meshes[0].points, meshes[0].tets)
    for k in range(N):
        assert_cells(f.cell_data(step=k), cells[k], rows)


def test_other_cell_arrays_at_a_later_step_name_it(run):
    meshes, cells = steps(run, 3)
    bad = [cells[0], cells[1], {"heat_flux": cells[2]["heat_flux"].astype(np.float32), "band": cells[2]["band"]}]
    with pytest.raises(MeshError, match="step 2: cell arrays"):
        encode_series(meshes, list(run["times"][:3]), mesh_only=True, cell_data=lambda k: bad[k])
    short = [cells[0], {"heat_flux": cells[1]["heat_flux"][:-1], "band": cells[1]["band"]}]
    with pytest.raises(MeshError, match="step 1: cell array 'heat_flux'"):
        encode_series(meshes[:2], list(run["times"][:2]), mesh_only=True, cell_data=lambda k: short[k])


@st.composite
def random_cells(draw):
    from meshgen import delaunay_mesh

    base = delaunay_mesh(draw(st.integers(8, 40)), draw(st.integers(0, 1000)))
    m = base.n_tets
    n_steps = draw(st.integers(1, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    kinds = draw(st.lists(st.sampled_from(["float64", "float32", "int8", "uint64", "vec"]), min_size=1, max_size=3,
                          unique=True))
    trend = rng.normal(size=m)
    cells = []
    for k in range(n_steps):
        cd = {}
        for kind in kinds:
            if kind == "float64":
                a = trend * (1 + 0.1 * k) + rng.normal(size=m) * 1e-3
                a[rng.random(m) < 0.1] = np.nan
                a[rng.random(m) < 0.1] = -0.0
                cd[kind] = a
            elif kind == "float32":
                cd[kind] = (trend * k).astype(np.float32)
            elif kind == "int8":
                cd[kind] = rng.integers(-128, 128, m).astype(np.int8)
            elif kind == "uint64":
                cd[kind] = rng.integers(0, 2**63, m, dtype=np.uint64) * np.uint64(2) + np.uint64(k)
            else:
                cd[kind] = rng.normal(size=(m, 3)) + k
        cells.append(cd)
    return base, cells, draw(st.integers(1, 4))


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_cells())
def test_random_cell_arrays_round_trip(case):
    base, cells, interval = case
    meshes = [base] * len(cells)
    f = gatun_py.open(encode_series(meshes, [float(k) for k in range(len(cells))], mesh_only=True,
                                    keyframe_interval=interval, cell_data=lambda k: cells[k]))
    m0 = f.mesh()
    rows = input_rows(m0.points, m0.tets, base.points, base.tets)
    for k in reversed(range(len(cells))):
        assert_cells(f.cell_data(step=k), cells[k], rows)
