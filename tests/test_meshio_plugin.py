"""The meshio plugin keeps meshio's contract: ``meshio.write`` of any mesh with volume cells (every
point and cell array included) and ``meshio.read`` give the mesh back, numbering included, with
writable arrays. ``write_read`` follows meshio's own test helper of that name (written here: the
mesh written, read back, and compared array by array), exact instead of within a tolerance.

Not representable, by design: meshes without volume cells (2-D, surfaces: a ``.tetc`` file holds a
volume mesh), polyhedra and polygons (no fixed size), non-conforming or duplicated volume cells (the
tets must form a valid mesh), and arrays that are not numbers (strings, objects); each is refused
with one clear error."""

from __future__ import annotations

import copy

import meshio
import numpy as np
import pytest

import gatun_py  # noqa: F401  (registers the format)
from gatun_py.errors import TetcError

from cells_check import _native, same_bits

_TET = meshio.Mesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.5]]),
                   [("tetra", np.array([[0, 1, 2, 4], [0, 2, 3, 4]]))])
_HEX = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                             [2, 0, 0], [2, 1, 0], [2, 0, 1], [2, 1, 1]], dtype=float),
                   [("hexahedron", np.array([[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 10, 11, 6]]))])
_WEDGE = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], dtype=float),
                     [("wedge", np.array([[0, 1, 2, 3, 4, 5]]))])
_PYRAMID = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]]),
                       [("pyramid", np.array([[0, 1, 2, 3, 4]]))])


def _quadratic(m, typ, edges):
    pts = list(np.asarray(m.points, float))
    rows = []
    for c in m.cells[0].data:
        row = list(c)
        for a, b in edges:
            row.append(len(pts))
            pts.append((pts[c[a]] + pts[c[b]]) / 2)
        rows.append(row)
    return meshio.Mesh(np.array(pts), [(typ, np.array(rows))])


_TET10 = _quadratic(meshio.Mesh(_TET.points, [("tetra", _TET.cells[0].data[:1])]), "tetra10",
                    [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)])
_HEX20 = _quadratic(meshio.Mesh(_HEX.points, [("hexahedron", _HEX.cells[0].data[:1])]), "hexahedron20",
                    [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)])
_WEDGE15 = _quadratic(_WEDGE, "wedge15", [(0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)])
_PYRAMID13 = _quadratic(_PYRAMID, "pyramid13", [(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)])
_TET_AND_SURFACE = meshio.Mesh(_TET.points, [("triangle", np.array([[0, 1, 2], [0, 2, 3]])),
                                             ("tetra", _TET.cells[0].data)])


def add_point_data(mesh, dim, num_tags=2, seed=0, dtype=float):
    """As meshio's helper: ``num_tags`` random point arrays of ``dim`` components (1: a scalar)."""
    rng = np.random.default_rng(seed)
    m = copy.deepcopy(mesh)
    shape = (len(m.points),) if dim == 1 else (len(m.points), dim)
    m.point_data = {str(k): (rng.random(shape) * 100).astype(dtype) for k in range(num_tags)}
    return m


def add_cell_data(mesh, specs, seed=1):
    """As meshio's helper: per (name, shape, dtype) a random cell array on every block."""
    rng = np.random.default_rng(seed)
    m = copy.deepcopy(mesh)
    m.cell_data = {name: [(rng.random((len(c.data), *shape)) * 100).astype(dtype) for c in m.cells]
                   for name, shape, dtype in specs}
    return m


def write_read(tmp_path, mesh) -> meshio.Mesh:
    """Write ``mesh`` as .tetc with meshio, read it back, check every array exactly."""
    path = tmp_path / "m.tetc"
    meshio.write(path, mesh)
    back = meshio.read(path)
    assert same_bits(back.points, _native(mesh.points).astype(np.float64))
    assert [c.type for c in back.cells] == [c.type for c in mesh.cells]
    for a, b in zip(mesh.cells, back.cells):
        assert np.array_equal(a.data, b.data), a.type
    assert set(back.point_data) == set(mesh.point_data)
    for k, v in mesh.point_data.items():
        assert same_bits(back.point_data[k], _native(v)), k
    assert set(back.cell_data) == set(mesh.cell_data)
    for k, v in mesh.cell_data.items():
        for a, b in zip(v, back.cell_data[k]):
            assert same_bits(b, _native(a)), k
    for a in [back.points, *back.point_data.values(), *(c.data for c in back.cells),
              *(a for v in back.cell_data.values() for a in v)]:
        assert a.flags.writeable
    return back


MESHES = {"tet": _TET, "hex": _HEX, "wedge": _WEDGE, "pyramid": _PYRAMID, "tetra10": _TET10, "hexahedron20": _HEX20,
          "wedge15": _WEDGE15, "pyramid13": _PYRAMID13, "tet+triangles": _TET_AND_SURFACE}


@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("data", ["none", "point1", "point2", "point3", "point-int", "cell", "both"])
def test_write_read(tmp_path, name, data):
    m = MESHES[name]
    if data == "point1":
        m = add_point_data(m, 1)
    elif data == "point2":
        m = add_point_data(m, 2)
    elif data == "point3":
        m = add_point_data(m, 3)
    elif data == "point-int":
        m = add_point_data(m, 1, dtype=np.int32)
    elif data == "cell":
        m = add_cell_data(m, [("a", (), np.float64), ("b", (3,), np.float32), ("c", (), np.int32)])
    elif data == "both":
        m = add_cell_data(add_point_data(m, 3), [("a", (), np.float64), ("flag", (), bool)])
    write_read(tmp_path, m)


@pytest.mark.parametrize("mesh,what", [
    (meshio.Mesh(np.zeros((3, 2)), [("triangle", np.array([[0, 1, 2]]))]), "2-D"),
    (meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]), "no volume cells"),
    (meshio.Mesh(_TET.points, [("tetra", np.array([[0, 1, 2, 4], [0, 1, 2, 4]]))]), "duplicates"),
])
def test_what_cannot_be_represented_is_refused(tmp_path, mesh, what):
    with pytest.raises(TetcError, match=what):
        meshio.write(tmp_path / "x.tetc", mesh)
    assert not (tmp_path / "x.tetc").exists()
