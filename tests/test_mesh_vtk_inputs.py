"""Files people have: legacy VTK with escaped names, files only VTK itself reads (optional extra)."""

from __future__ import annotations

import numpy as np
import pytest

from gatun_py.errors import ReadError
from gatun_py.mesh import read_mesh
from gatun_py.mesh import io as mesh_io
from samples import SAMPLES

vtk = pytest.importorskip("vtk", reason="VTK (the vtk extra) writes the files these tests read")
from vtkmodules.util.numpy_support import numpy_to_vtk  # noqa: E402


def _write_vtk9(path, mesh, name, *, xml=False):
    """The mesh as VTK 9 writes it (legacy 5.1 with 64-bit offsets, or XML), one named point array."""
    ug = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.asarray(mesh.points, np.float64), deep=True))
    ug.SetPoints(pts)
    cells = vtk.vtkCellArray()
    cells.SetData(numpy_to_vtk(np.arange(0, 4 * mesh.n_tets + 1, 4, dtype=np.int64), deep=True,
                               array_type=vtk.VTK_ID_TYPE),
                  numpy_to_vtk(mesh.tets.reshape(-1).astype(np.int64), deep=True, array_type=vtk.VTK_ID_TYPE))
    ug.SetCells(vtk.VTK_TETRA, cells)
    arr = numpy_to_vtk(np.asarray(mesh.density, np.float64), deep=True)
    arr.SetName(name)
    ug.GetPointData().AddArray(arr)
    w = vtk.vtkXMLUnstructuredGridWriter() if xml else vtk.vtkUnstructuredGridWriter()
    if not xml:
        w.SetFileTypeToBinary()  # VTK's ASCII writes 10 significant digits: not the mesh's floats
    w.SetFileName(str(path))
    w.SetInputData(ug)
    w.Write()


@pytest.fixture(scope="module")
def post():
    return read_mesh(SAMPLES["post"][0])[0]


def test_escaped_array_names_come_back_as_written(tmp_path, post):
    path = tmp_path / "stress.vtk"
    _write_vtk9(path, post, "Nodal Stress-0")
    assert "Nodal%20Stress-0" in open(path, "rb").read().decode("latin-1")  # what VTK puts in the file
    mesh, _ = read_mesh(path, scalar="Nodal Stress-0")
    assert mesh.scalar_name == "Nodal Stress-0"
    np.testing.assert_array_equal(np.sort(mesh.density.astype(np.float64)), np.sort(post.density.astype(np.float64)))


@pytest.mark.parametrize("xml", [False, True])
def test_vtk_reads_what_meshio_cannot(tmp_path, post, monkeypatch, xml):
    path = tmp_path / ("v.vtu" if xml else "v.vtk")
    _write_vtk9(path, post, "p", xml=xml)

    def refuse(filename):
        raise ValueError("malformed file")

    monkeypatch.setitem(mesh_io._helpers.reader_map, "vtu" if xml else "vtk", refuse)
    mesh, _ = read_mesh(path)
    assert (mesh.n_points, mesh.n_tets) == (post.n_points, post.n_tets)
    np.testing.assert_array_equal(mesh.tets, post.tets)
    np.testing.assert_array_equal(mesh.points.astype(np.float64), post.points.astype(np.float64))


def test_without_vtk_the_message_says_how_to_get_it(tmp_path, post, monkeypatch):
    path = tmp_path / "v.vtk"
    _write_vtk9(path, post, "p")
    monkeypatch.setitem(mesh_io._helpers.reader_map, "vtk", lambda f: (_ for _ in ()).throw(ValueError("bad")))
    monkeypatch.setattr(mesh_io, "vtk_available", lambda: False)
    with pytest.raises(ReadError, match=r"pip install 'gatun_py\[vtk\]'"):
        read_mesh(path)
    garbage = tmp_path / "g.vtk"
    garbage.write_bytes(b"# vtk DataFile Version 5.1\nnonsense\n")
    monkeypatch.setattr(mesh_io, "vtk_available", lambda: True)
    with pytest.raises(ReadError, match="could not read it either"):
        read_mesh(garbage)
