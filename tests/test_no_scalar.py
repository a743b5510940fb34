"""Meshes without any point scalar (a bare gmsh or FEM mesh): kept without one, stored and given
back losslessly without an invented array, rendered as a uniform medium that shows the shape, and
refused where a field is needed (isosurfaces) with one clear message."""

import json

import meshio
import numpy as np
import pytest

import gatun_py
from cli_util import run
from gatun_py.errors import OptionError
from gatun_py.mesh import read_mesh
from gatun_py.mesh.model import NO_SCALAR
from gatun_py.mesh.synthetic import jittered_grid


def _bare(tmp_path, *, point_data=None, cell_data=None, name="bare.vtu"):
    grid = jittered_grid((4, 3, 3), jitter=0.2, seed=5)
    path = tmp_path / name
    meshio.Mesh(np.asarray(grid.points, np.float64), [("tetra", np.asarray(grid.tets))],
                point_data=point_data or {}, cell_data=cell_data or {}).write(path)
    return path, grid


def test_a_bare_mesh_reads_without_a_scalar(tmp_path):
    path, grid = _bare(tmp_path)
    mesh, report = read_mesh(path)
    assert not mesh.has_scalar and mesh.scalar_name == NO_SCALAR
    assert mesh.user_point_data == {} and not mesh.density.any()
    assert "scalar=none" in repr(mesh)
    assert any("no point scalar" in note for note in report.notes)


def test_a_bare_mesh_round_trips_without_an_invented_array(tmp_path):
    ids = np.arange(72, dtype=np.int32).reshape(36, 2)  # two components: no scalar candidate
    path, _ = _bare(tmp_path, point_data={"node_id": ids})
    mesh, _ = read_mesh(path)
    f = gatun_py.compress(path, tmp_path / "b.tetc")
    assert f.info["scalar"] is None and [a["name"] for a in f.info["arrays"]] == ["node_id"]
    back = gatun_py.open(tmp_path / "b.tetc").mesh()
    assert not back.has_scalar and list(back.user_point_data) == ["node_id"]
    order = np.lexsort(mesh.points.T[::-1])
    order_back = np.lexsort(back.points.T[::-1])
    np.testing.assert_array_equal(back.points[order_back], mesh.points[order])
    np.testing.assert_array_equal(back.user_point_data["node_id"][order_back], ids[order])
    gatun_py.decompress(tmp_path / "b.tetc", tmp_path / "out.vtu")
    out = meshio.read(tmp_path / "out.vtu")
    assert sorted(out.point_data) == ["node_id"]  # nothing under the empty name
    assert len(out.cells_dict["tetra"]) == mesh.n_tets


def test_a_bare_mesh_renders_its_shape(tmp_path):
    path, _ = _bare(tmp_path)
    gatun_py.compress(path, tmp_path / "b.tetc", mesh_only=True)
    img = gatun_py.render(tmp_path / "b.tetc", size=48, azimuth=30, elevation=20)
    lit = (img.rgb > 0).any(axis=-1)
    # a constant field sits in the middle of the transfer function: the mesh shows, the corners stay empty
    assert lit.mean() > 0.1 and not lit[0, 0] and not lit[-1, -1]


def test_no_isosurface_without_a_scalar(tmp_path):
    path, _ = _bare(tmp_path)
    gatun_py.compress(path, tmp_path / "b.tetc", mesh_only=True)
    for source in (path, tmp_path / "b.tetc"):
        with pytest.raises(OptionError, match="no scalar"):
            gatun_py.isosurface(source, values=[0.0])
    res = run("isosurface", tmp_path / "b.tetc", "-o", tmp_path / "s.vtu", "--value", "0")
    assert res.exit_code != 0 and "no scalar" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "s.vtu").exists()


def test_cli_gmsh_mesh_with_cell_tags(tmp_path):
    """A .msh file as gmsh writes it: entity tags as point and cell data, no field."""
    grid = jittered_grid((4, 3, 3), jitter=0.2, seed=5)
    n, m = grid.n_points, grid.n_tets
    path = tmp_path / "part.msh"
    meshio.Mesh(np.asarray(grid.points, np.float64), [("tetra", np.asarray(grid.tets))],
                point_data={"gmsh:dim_tags": np.tile([3, 1], (n, 1))},
                cell_data={"gmsh:geometrical": [np.ones(m, np.int32)], "gmsh:physical": [np.ones(m, np.int32)]},
                ).write(path, file_format="gmsh")
    kept = run("compress", path, "-o", tmp_path / "k.tetc", "-q")  # the tags are kept as cell data
    assert kept.exit_code == 0, kept.output
    assert meshio.read(tmp_path / "k.tetc").cell_data["gmsh:physical"][0].tolist() == [1] * m
    ok = run("compress", path, "-o", tmp_path / "p.tetc", "-q", "--drop-cell-data")
    assert ok.exit_code == 0, ok.output
    info = json.loads(run("info", tmp_path / "p.tetc", "--json").output)
    assert info["scalar"] is None and info["scalar_range"] is None
    assert run("decompress", tmp_path / "p.tetc", "-o", tmp_path / "back.msh").exit_code == 0
    back = meshio.read(tmp_path / "back.msh")
    assert len(back.cells_dict["tetra"]) == m and len(back.points) == n
    assert run("render", tmp_path / "p.tetc", "-o", tmp_path / "p.png", "--size", "32").exit_code == 0
