"""Input formats: the real samples (paper's Table 1), PLOT3D variants, hex/wedge/pyramid splits,
quadratic cells, scalar choice, and bit-exact round trips through meshio formats."""

import hashlib

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import SAMPLES, load_sample
from gatun_py.errors import MeshError, ReadError
from gatun_py.mesh import read_mesh, write_mesh
from gatun_py.mesh.model import face_multiplicity
from gatun_py.mesh.plot3d import grid_hexes
from gatun_py.mesh.split import orient_positive, split_min_id_star
from meshgen import mesh_strategy


def test_sample_checksums():
    for line in (SAMPLES / "SHA256SUMS").read_text().splitlines():
        digest, name = line.split()
        assert hashlib.sha256((SAMPLES / name).read_bytes()).hexdigest() == digest, name


@pytest.mark.parametrize("name, points, tets, boundary, zero", [
    ("bluntfin", 40960, 187395, 13516, 77),
    ("combustion", 47025, 215040, 15616, 0),
])
def test_paper_table1(name, points, tets, boundary, zero):
    mesh, rep = load_sample(name)
    assert (mesh.n_points, mesh.n_tets, len(mesh.boundary_faces()), rep.zero_volume_tets) == (points, tets, boundary, zero)
    assert (mesh.signed_volumes() >= 0).all()
    assert rep.reoriented_tets == 0  # our own split is oriented before validation


def test_post_vtk_native_tets():
    mesh, rep = load_sample("post")
    assert (mesh.n_points, mesh.n_tets, rep.coincident_points) == (2288, 8750, 88)
    assert mesh.scalar_name == "Pressure"


def test_fire_hexes_split_conformingly():
    mesh, rep = load_sample("fire")
    assert mesh.n_tets == 52310 == 5 * 10462
    counts, over = face_multiplicity(mesh.tets)
    assert len(over) == 0 and counts.max() <= 2
    assert (mesh.signed_volumes() > 0).all()
    assert mesh.scalar_name == "t"


def test_fire_takes_its_first_scalar_and_says_so():
    mesh, rep = read_mesh(SAMPLES / "room_fire" / "fire_ug.vtu")
    assert mesh.scalar_name == "t"
    assert any("default scalar 't', the first of 5 point scalars" in n for n in rep.notes), rep.notes
    with pytest.raises(ReadError, match="no point scalar named 'nope'"):
        read_mesh(SAMPLES / "room_fire" / "fire_ug.vtu", scalar="nope")


# -- PLOT3D ---------------------------------------------------------------------------------

def _write_plot3d(tmp_path, dims, *, bo=">", iblank=None, pad=0, seed=0):
    rng = np.random.default_rng(seed)
    ni, nj, nk = dims
    n = ni * nj * nk
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    xyz = np.stack([i.ravel() + 0.1 * rng.random(n), j.ravel() * 1.0, k.ravel() * 2.0]).astype(f"{bo}f4")
    head = np.array(dims, f"{bo}i4").tobytes()
    raw = head + xyz.tobytes()
    if iblank is not None:
        raw += np.asarray(iblank, f"{bo}i4").tobytes()
    (tmp_path / "gxyz.bin").write_bytes(raw + b"\0" * pad)
    q = (rng.random((5, n)) + 0.5).astype(f"{bo}f4")
    (tmp_path / "gq.bin").write_bytes(head + np.zeros(4, f"{bo}f4").tobytes() + q.tobytes() + b"\0" * pad)
    return xyz.astype(np.float32).T, q.astype(np.float32)


@pytest.mark.parametrize("bo", [">", "<"])
@pytest.mark.parametrize("pad", [0, 484])
def test_plot3d_byte_orders_and_padding(tmp_path, bo, pad):
    xyz, q = _write_plot3d(tmp_path, (4, 3, 3), bo=bo, pad=pad)
    mesh, rep = read_mesh(tmp_path / "gxyz.bin")
    assert mesh.n_points == 36 and mesh.n_tets == 5 * 3 * 2 * 2
    assert mesh.points.tobytes() == np.ascontiguousarray(xyz).tobytes()
    assert mesh.density.tobytes() == q[0].tobytes()
    counts, over = face_multiplicity(mesh.tets)
    assert len(over) == 0


def test_plot3d_q_variables(tmp_path):
    xyz, q = _write_plot3d(tmp_path, (3, 3, 2))
    q64 = q.astype(np.float64)
    m, _ = read_mesh(tmp_path / "gxyz.bin", q_file=tmp_path / "gq.bin", q_var="energy")
    assert m.density.tobytes() == q[4].tobytes()
    m, _ = read_mesh(tmp_path / "gxyz.bin", q_var="velocity-magnitude")
    expect = (np.sqrt((q64[1:4] ** 2).sum(0)) / q64[0]).astype(np.float32)
    assert np.array_equal(m.density, expect)
    with pytest.raises(ReadError, match="unknown Q variable"):
        read_mesh(tmp_path / "gxyz.bin", q_var="vorticity")


def test_plot3d_iblank_drops_blanked_cells(tmp_path):
    dims = (3, 3, 3)
    ib = np.ones(27, np.int32)
    ib[0] = 0  # corner point blanked: the one cell using it goes
    _write_plot3d(tmp_path, dims, iblank=ib)
    mesh, rep = read_mesh(tmp_path / "gxyz.bin")
    assert mesh.n_tets == 5 * 7
    assert any("IBLANK" in n for n in rep.notes)


def test_plot3d_errors(tmp_path):
    _write_plot3d(tmp_path, (3, 3, 3))
    (tmp_path / "gq.bin").unlink()
    with pytest.raises(ReadError, match="give its solution file"):
        read_mesh(tmp_path / "gxyz.bin")
    _write_plot3d(tmp_path, (3, 3, 3))
    other = tmp_path / "o"
    other.mkdir()
    _write_plot3d(other, (3, 3, 2))
    with pytest.raises(ReadError, match="Q file is 3x3x2, grid is 3x3x3"):
        read_mesh(tmp_path / "gxyz.bin", q_file=other / "gq.bin")
    raw = (tmp_path / "gxyz.bin").read_bytes()
    (tmp_path / "cut.bin").write_bytes(raw[:100])
    with pytest.raises(ReadError):
        read_mesh(tmp_path / "cut.bin", q_file=tmp_path / "gq.bin")


# -- cell splitting -------------------------------------------------------------------------

def _hex_grid(ni, nj, nk, seed=0, shuffle=False):
    hexes, _ = grid_hexes((ni, nj, nk))
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    pts = np.stack([i, j, k], -1).reshape(-1, 3).astype(np.float32)
    if shuffle:  # random global ids: the min-id rule must still be conforming
        perm = np.random.default_rng(seed).permutation(len(pts))
        inv = np.argsort(perm)
        pts = pts[perm]
        hexes = inv[hexes]
    return pts, hexes


@pytest.mark.parametrize("seed", range(5))
def test_min_id_star_split_is_conforming(seed):
    pts, hexes = _hex_grid(4, 4, 3, seed, shuffle=True)
    tets = orient_positive(pts, split_min_id_star(hexes, "hexahedron"))
    assert len(tets) == 6 * len(hexes)
    counts, over = face_multiplicity(tets)
    assert len(over) == 0
    vol = np.abs(np.linalg.det(np.stack([pts[tets[:, c]] - pts[tets[:, 0]] for c in (1, 2, 3)], 1).astype(np.float64))) / 6
    assert (vol > 0).all() and vol.sum() == pytest.approx(3 * 3 * 2)
    # Boundary triangles: two per boundary quad, i.e. conforming inside.
    n_bq = 2 * (3 * 3 + 3 * 2 + 3 * 2)
    assert int((counts == 1).sum()) == 2 * n_bq


def test_mixed_cells_split_conformingly(tmp_path):
    """A hex, a wedge and a pyramid glued face to face (min-id rule across types)."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                    [2, 0, 0], [2, 0, 1], [0.5, 0.5, 2]], np.float64)
    cells = [("hexahedron", np.array([[0, 1, 2, 3, 4, 5, 6, 7]])),
             ("wedge", np.array([[1, 8, 2, 5, 9, 6]])),
             ("pyramid", np.array([[4, 5, 6, 7, 10]]))]
    meshio.Mesh(pts, cells, point_data={"s": np.arange(11.0)}).write(tmp_path / "mixed.vtu")
    mesh, _ = read_mesh(tmp_path / "mixed.vtu")
    counts, over = face_multiplicity(mesh.tets)
    assert len(over) == 0
    assert mesh.n_tets == 6 + 3 + 2
    assert mesh.signed_volumes().sum() == pytest.approx(1 + 0.5 + 1 / 3)
    # The shared quads are cut the same way from both sides, so only the outer surface is boundary:
    # hex 4 quads (8 triangles) + wedge 2 triangles and 2 quads (6) + pyramid 4 triangles.
    assert int((counts == 1).sum()) == 8 + 6 + 4


def test_structured_vtk_grid(tmp_path):
    (tmp_path / "sg.vtk").write_text(
        "# vtk DataFile Version 3.0\nsg\nASCII\nDATASET STRUCTURED_GRID\nDIMENSIONS 3 2 2\nPOINTS 12 float\n"
        "0 0 0 1 0 0 2 0 0 0 1 0 1 1 0 2 1 0\n0 0 1 1 0 1 2 0 1 0 1 1 1 1 1 2 1 1\n"
        "POINT_DATA 12\nSCALARS temp float 1\nLOOKUP_TABLE default\n0 1 2 3 4 5 6 7 8 9 10 11\n")
    mesh, _ = read_mesh(tmp_path / "sg.vtk")
    assert mesh.n_tets == 10 and mesh.scalar_name == "temp"
    assert len(face_multiplicity(mesh.tets)[1]) == 0
    assert mesh.signed_volumes().sum() == pytest.approx(2.0)


def test_quadratic_tets_reduced_to_corners(tmp_path):
    pts = np.random.default_rng(0).random((10, 3))
    pts[:4] = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    meshio.Mesh(pts, [("tetra10", np.arange(10)[None])], point_data={"s": np.arange(10.0)}).write(tmp_path / "q.vtu")
    mesh, rep = read_mesh(tmp_path / "q.vtu")
    assert mesh.tets.tolist() == [[0, 1, 2, 3]]
    assert rep.unreferenced_points == 6


def test_no_volume_cells_and_cell_data(tmp_path):
    pts = np.random.default_rng(0).random((4, 3))
    meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2]]))], point_data={"s": np.zeros(4)}).write(tmp_path / "t.vtu")
    with pytest.raises(MeshError, match="no volume cells.*triangle"):
        read_mesh(tmp_path / "t.vtu")
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
    meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))],
                cell_data={"c": [np.array([1.0, 3.0])]}).write(tmp_path / "c.vtu")
    bare, rep = read_mesh(tmp_path / "c.vtu")  # no point scalar: kept without one, the note says how to get one
    assert not bare.has_scalar and not bare.user_point_data
    assert any("cell data (c) can be averaged" in note and "cell-to-point" in note for note in rep.notes)
    with pytest.raises(ReadError, match="is cell data; it can be used only averaged"):
        read_mesh(tmp_path / "c.vtu", scalar="c")
    mesh, _ = read_mesh(tmp_path / "c.vtu", scalar="c", cell_to_point=True)
    assert mesh.density[0] == 1.0 and mesh.density[4] == 3.0
    alone, _ = read_mesh(tmp_path / "c.vtu", cell_to_point=True)  # the only cell array: no name needed
    np.testing.assert_array_equal(alone.density, mesh.density)
    meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))],
                cell_data={"c": [np.array([1.0, 3.0])], "d": [np.array([0.0, 1.0])]}).write(tmp_path / "cd.vtu")
    with pytest.raises(ReadError, match="several cell arrays.*: c, d"):
        read_mesh(tmp_path / "cd.vtu", cell_to_point=True)
    assert 1.0 < mesh.density[1] < 3.0  # volume-weighted mix on shared points


def test_missing_unreadable_and_unknown(tmp_path):
    with pytest.raises(ReadError, match="no such file"):
        read_mesh(tmp_path / "nope.vtu")
    (tmp_path / "bad.vtu").write_text("not xml")
    with pytest.raises(ReadError, match="cannot read"):
        read_mesh(tmp_path / "bad.vtu")
    (tmp_path / "x.weird").write_text("?")
    with pytest.raises(ReadError, match="unknown file extension"):
        read_mesh(tmp_path / "x.weird")


# -- round trips ------------------------------------------------------------------------------

@settings(max_examples=25, deadline=None)
@given(mesh_strategy(), st.sampled_from([".vtu", ".vtk", ".msh"]))
def test_write_read_round_trip_is_bit_exact(tmp_path_factory, mesh, ext):
    path = tmp_path_factory.mktemp("rt") / f"m{ext}"
    write_mesh(mesh, path)
    back, rep = read_mesh(path)
    # Gmsh stores coordinates as doubles: the same values come back as float64
    assert back.points.dtype == (np.float64 if ext == ".msh" else mesh.points.dtype)
    assert back.points.astype(mesh.points.dtype).tobytes() == mesh.points.tobytes()
    assert back.density.tobytes() == mesh.density.tobytes()
    assert np.array_equal(back.tets, mesh.tets)
    assert rep.reoriented_tets == 0


def test_sample_round_trip_bit_exact(tmp_path):
    mesh, _ = load_sample("fire")
    write_mesh(mesh, tmp_path / "fire.vtu")
    back, _ = read_mesh(tmp_path / "fire.vtu", scalar=mesh.scalar_name)  # every point array is written
    assert back.points.tobytes() == mesh.points.tobytes() and back.density.tobytes() == mesh.density.tobytes()
    assert np.array_equal(back.tets, mesh.tets)
