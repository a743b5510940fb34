"""Cells as given: blocks, vertex order, quadratic nodes, cell arrays, field data and sets come back
bit for bit (tests/cells_check.py compares the blocks, not just the tets)."""

from __future__ import annotations

import os
from pathlib import Path

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import gatun_py
from gatun_py.codec import TetcReader
from gatun_py.codec.container import VERSION_MAJOR
from gatun_py.errors import MeshError
from gatun_py.mesh import mesh_from_meshio, read_mesh

from cells_check import check_round_trip, vertex_order_of
from cli_util import assert_error, run
from mixedgen import mixed_mesh, tetra10_mesh

ROOT = Path(__file__).resolve().parents[1]
ROOM_FIRE = ROOT / "sample_meshes" / "room_fire" / "fire_ug.vtu"
POST = ROOT / "sample_meshes" / "lox_post_tets" / "post.vtk"


def _round_trip(orig, tmp_path, **kw):
    tm, _ = mesh_from_meshio(orig)
    out = tmp_path / "a.tetc"
    gatun_py.compress(orig, out, force=True, **kw)
    dec = meshio.read(out)
    check_round_trip(orig, dec, vertex_order_of(tm))
    return out, dec


def test_room_fire_hexes_come_back_and_cost_little(tmp_path):
    orig = meshio.read(ROOM_FIRE)
    tm, _ = read_mesh(ROOM_FIRE)
    hexes = tmp_path / "hex.tetc"
    gatun_py.compress(ROOM_FIRE, hexes, mesh_only=True)
    tets = tmp_path / "tets.tetc"
    gatun_py.compress(tm, tets, mesh_only=True)  # the same mesh, already split: no cells
    assert "cells" not in TetcReader(tets).meta
    # the target: the file with the original hexes at most 1.1x the file of the split
    assert os.path.getsize(hexes) <= 1.1 * os.path.getsize(tets)
    out = tmp_path / "back.vtu"
    res = run("decompress", hexes, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    back = meshio.read(out)
    assert [c.type for c in back.cells] == ["hexahedron"]
    check_round_trip(orig, back, vertex_order_of(tm))
    split = tmp_path / "split.vtu"
    assert run("decompress", hexes, "-o", split, "-q", "--as-tets").exit_code == 0
    s = meshio.read(split)
    assert [c.type for c in s.cells] == ["tetra"] and len(s.cells[0].data) == tm.n_tets


def test_plain_tet_mesh_stores_no_cells(tmp_path):
    out = tmp_path / "p.tetc"
    gatun_py.compress(POST, out, mesh_only=True)
    r = TetcReader(out)
    assert "cells" not in r.meta and not any(s.startswith("C/") for s in r.container.section_names())
    assert r.container.major == VERSION_MAJOR


@pytest.mark.parametrize("seed,dims,kinds", [(0, (3, 3, 2), (0, 1, 2)), (1, (4, 3, 3), (0, 1, 2)),
                                             (2, (2, 2, 2), (0,)), (3, (3, 2, 2), (1, 2))])
def test_mixed_meshes_round_trip(tmp_path, seed, dims, kinds):
    orig = mixed_mesh(*dims, seed, kinds=kinds)
    _, dec = _round_trip(orig, tmp_path, mesh_only=True)
    assert dec.cell_data["flag"][0].dtype == bool
    assert all(a.flags.writeable for a in [dec.points, *dec.point_data.values(), *(c.data for c in dec.cells)])


def test_mixed_mesh_with_levels_round_trips(tmp_path):
    orig = mixed_mesh(4, 4, 3, 7)
    out, _ = _round_trip(orig, tmp_path)
    assert len(TetcReader(out).levels) >= 1


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), nx=st.integers(1, 4), ny=st.integers(1, 3), nz=st.integers(1, 3),
       kinds=st.sampled_from([(0,), (1,), (2,), (0, 1), (0, 2), (0, 1, 2)]))
def test_random_mixed_meshes_round_trip(tmp_path, seed, nx, ny, nz, kinds):
    _round_trip(mixed_mesh(nx, ny, nz, seed, kinds=kinds), tmp_path, mesh_only=True)


def test_tetra10_round_trip(tmp_path):
    orig = tetra10_mesh()
    out, dec = _round_trip(orig, tmp_path, mesh_only=True)
    assert [c.type for c in dec.cells] == ["tetra10"]


def _gmsh_box(path, order=1):
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("b")
        b1 = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        b2 = gmsh.model.occ.addBox(1, 0, 0, 1, 1, 1)
        gmsh.model.occ.fragment([(3, b1)], [(3, b2)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [b1], 11, "left")
        gmsh.model.addPhysicalGroup(3, [b2], 12, "right")
        gmsh.model.addPhysicalGroup(2, [s for _, s in gmsh.model.getEntities(2)][:3], 21, "walls")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.35)
        gmsh.model.mesh.generate(3)
        if order > 1:
            gmsh.model.mesh.setOrder(order)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.mark.parametrize("order", [1, 2])
def test_gmsh_physical_groups_round_trip(tmp_path, order):
    src = tmp_path / "box.msh"
    _gmsh_box(src, order)
    orig = meshio.read(src)
    tm, _ = read_mesh(src)
    out = tmp_path / "box.tetc"
    gatun_py.compress(src, out, mesh_only=True)
    check_round_trip(orig, meshio.read(out), vertex_order_of(tm))
    back = tmp_path / "back.msh"
    assert run("decompress", out, "-o", back, "-q").exit_code == 0
    m = meshio.read(back)
    assert [c.type for c in m.cells] == [c.type for c in orig.cells]
    for k in ("gmsh:physical", "gmsh:geometrical"):
        for a, b in zip(orig.cell_data[k], m.cell_data[k]):
            assert np.array_equal(np.sort(a), np.sort(b))
    assert set(m.field_data) == set(orig.field_data)


def test_vtu_round_trip_through_files(tmp_path):
    orig = mixed_mesh(3, 2, 2, 4)
    del orig.cell_data["flag"]  # VTU holds no booleans, nor sets
    orig.point_sets.clear()
    orig.cell_sets.clear()
    orig.field_data.clear()
    src = tmp_path / "in.vtu"
    orig.write(src)
    orig = meshio.read(src)
    tm, _ = read_mesh(src)
    out = tmp_path / "a.tetc"
    assert run("compress", src, "-o", out, "-q", "--mesh-only").exit_code == 0
    back = tmp_path / "back.vtu"
    assert run("decompress", out, "-o", back, "-q").exit_code == 0
    check_round_trip(orig, meshio.read(back), vertex_order_of(tm))


# -- bad input -----------------------------------------------------------------------------------

def _write_vtu(m, path):
    m.write(path)
    return path


def test_polyhedra_are_refused_by_name(tmp_path):
    m = meshio.Mesh(np.eye(4, 3, k=-1), [("tetra", np.array([[0, 1, 2, 3]]))])
    m.cells.append(meshio.CellBlock("polyhedron4", [[np.array([0, 1, 2]), np.array([0, 1, 3]),
                                                     np.array([0, 2, 3]), np.array([1, 2, 3])]]))
    with pytest.raises(MeshError, match="polyhedron4"):
        mesh_from_meshio(m)


def test_polygons_refused_by_name_on_the_command_line(tmp_path):
    m = meshio.Mesh(np.eye(4, 3, k=-1), [("tetra", np.array([[0, 1, 2, 3]])),
                                         ("polygon", np.array([[0, 1, 2, 3, 0]]))])
    src = _write_vtu(m, tmp_path / "poly.vtu")
    out = tmp_path / "o.tetc"
    assert_error(run("compress", src, "-o", out, "--mesh-only"), "polygon")
    assert not out.exists()


def test_cell_array_of_wrong_length_is_refused(tmp_path):
    m = mixed_mesh(2, 2, 1, 0, kinds=(0,))
    m.cell_data = {"bad": [np.zeros(len(m.cells[0].data) + 1)]}
    with pytest.raises(MeshError, match="'bad' has 5 values for 4 hexahedron cells"):
        mesh_from_meshio(m)
    with pytest.raises(MeshError):
        gatun_py.compress(m, tmp_path / "x.tetc")
    assert not (tmp_path / "x.tetc").exists()


@pytest.mark.parametrize("kind", ["point", "cell"])
def test_sets_naming_missing_ids_are_refused(tmp_path, kind):
    m = mixed_mesh(2, 2, 1, 0, kinds=(0,))
    if kind == "point":
        m.point_sets = {"far": np.array([0, len(m.points)])}
    else:
        m.cell_sets = {"far": [np.array([0, 99])]}
    with pytest.raises(MeshError, match="'far' names a"):
        gatun_py.compress(m, tmp_path / "x.tetc")
    assert not (tmp_path / "x.tetc").exists()


def test_damaged_cells_sections_raise_corrupt_file_error(tmp_path):
    from gatun_py.codec.container import build_container, split_container
    from gatun_py.errors import CorruptFileError

    out, _ = _round_trip(mixed_mesh(3, 2, 2, 3), tmp_path, mesh_only=True)
    meta, sections = split_container(out.read_bytes())
    for victim in ("C/groups", "C/perms"):
        bad = [(n, d[: len(d) // 2] if n == victim else d) for n, d in sections]
        p = tmp_path / "bad.tetc"
        p.write_bytes(build_container(meta, bad))
        with pytest.raises(CorruptFileError):
            meshio.read(p)
        res = run("decompress", p, "-o", tmp_path / "bad.vtu")
        assert_error(res, "corrupt")
        assert not (tmp_path / "bad.vtu").exists()


# -- keep-order ----------------------------------------------------------------------------------

def _exact(orig, dec):
    from cells_check import _native, same_bits

    assert same_bits(np.asarray(dec.points), _native(orig.points))
    assert set(dec.point_data) == set(orig.point_data)
    for k, v in orig.point_data.items():
        assert same_bits(dec.point_data[k], _native(v)), k
    assert [c.type for c in dec.cells] == [c.type for c in orig.cells]
    for a, b in zip(orig.cells, dec.cells):
        assert np.array_equal(np.asarray(a.data), np.asarray(b.data)), a.type
    for k, v in orig.cell_data.items():
        for a, b in zip(v, dec.cell_data[k]):
            assert same_bits(np.asarray(b), _native(a)), k
    for k, v in (orig.point_sets or {}).items():
        assert np.array_equal(dec.point_sets[k], v)
    for k, per in (orig.cell_sets or {}).items():
        for a, b in zip(per, dec.cell_sets[k]):
            assert (a is None and b is None) or np.array_equal(a, b), k


@pytest.mark.parametrize("make", [lambda: mixed_mesh(3, 3, 2, 0), tetra10_mesh,
                                  lambda: meshio.read(POST), lambda: meshio.read(ROOM_FIRE)])
def test_keep_order_gives_the_numbering_back(tmp_path, make):
    orig = make()
    out = tmp_path / "k.tetc"
    gatun_py.compress(orig, out, mesh_only=True, keep_order=True)
    _exact(orig, meshio.read(out))
    info = gatun_py.info(out)
    assert info["keep_order"]["bytes"] > 0 and info["keep_order"]["bits_per_point"] > 0


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), nx=st.integers(1, 3), ny=st.integers(1, 3), nz=st.integers(1, 2))
def test_keep_order_random_mixed_meshes(tmp_path, seed, nx, ny, nz):
    orig = mixed_mesh(nx, ny, nz, seed)
    out = tmp_path / "k.tetc"
    gatun_py.compress(orig, out, mesh_only=True, keep_order=True, force=True)
    _exact(orig, meshio.read(out))


def test_keep_order_on_the_command_line_and_cut_short(tmp_path):
    src = tmp_path / "in.vtu"
    m = mixed_mesh(3, 2, 2, 1)
    del m.cell_data["flag"]
    m.point_sets.clear()
    m.cell_sets.clear()
    m.field_data.clear()
    m.write(src)
    orig = meshio.read(src)
    out = tmp_path / "k.tetc"
    assert run("compress", src, "-o", out, "-q", "--mesh-only", "--keep-order").exit_code == 0
    back = tmp_path / "back.vtu"
    assert run("decompress", out, "-o", back, "-q").exit_code == 0
    _exact(orig, meshio.read(back))
    data = out.read_bytes()
    cut = tmp_path / "cut.tetc"
    cut.write_bytes(data[: len(data) - 40])
    res = run("decompress", cut, "-o", tmp_path / "cut.vtu")
    assert_error(res, "cut.tetc")
    assert not (tmp_path / "cut.vtu").exists()


def test_a_mixed_mesh_renders_as_its_tet_split(tmp_path):
    src = tmp_path / "mixed.vtu"
    m = mixed_mesh(4, 3, 3, 11)
    del m.cell_data["flag"]
    m.point_sets.clear()
    m.cell_sets.clear()
    m.field_data.clear()
    m.write(src)
    cells = tmp_path / "cells.tetc"
    gatun_py.compress(src, cells, mesh_only=True, scalar="p")
    split = tmp_path / "split.vtu"
    gatun_py.decompress(cells, split, as_tets=True)
    tets = tmp_path / "tets.tetc"
    gatun_py.compress(split, tets, mesh_only=True, scalar="p")
    assert "cells" in TetcReader(cells).meta and "cells" not in TetcReader(tets).meta
    a = gatun_py.render(cells, size=64, azimuth=30, elevation=20)
    b = gatun_py.render(tets, size=64, azimuth=30, elevation=20)
    assert a.image.any() and np.array_equal(a.rgb, b.rgb)
    np.testing.assert_allclose(a.image, b.image, rtol=0, atol=1e-6)


def test_exodus_round_trip(tmp_path):
    pytest.importorskip("netCDF4")
    from gatun_py.mesh.exodus import read_exodus

    m = mixed_mesh(3, 3, 2, 2, kinds=(0,))
    src = tmp_path / "hex.exo"
    meshio.Mesh(m.points, [("hexahedron", m.cells[0].data)], point_data={"p": m.point_data["p"]},
                point_sets={"left": np.array([0, 1, 2])}).write(src)
    orig, _ = read_exodus(src)
    assert set(orig.point_sets) == {"left"}
    tm, _ = read_mesh(src)
    out = tmp_path / "hex.tetc"
    gatun_py.compress(src, out, mesh_only=True)
    check_round_trip(orig, meshio.read(out), vertex_order_of(tm))


# -- golden files: formats 10 and 11 with cells -------------------------------------------------

CELLS_GOLDEN_VERSIONS = (10, 11)  # one per format version since cells came


@pytest.mark.parametrize("version", CELLS_GOLDEN_VERSIONS)
def test_cells_golden_file_decodes_bit_exactly(version):
    import json
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "data"))
    from make_cells_golden import digest, golden_mesh

    data = ROOT / "tests" / "data"
    golden = data / f"cells_v{version}.tetc"
    assert TetcReader(golden).container.major == version
    assert digest(meshio.read(golden)) == json.loads((data / f"cells_v{version}.json").read_text())["decoded"]
    orig = golden_mesh()
    tm, _ = mesh_from_meshio(orig, scalar="p")
    check_round_trip(orig, meshio.read(golden), vertex_order_of(tm))


def test_cells_golden_file_is_rewritten_the_same(tmp_path):
    """Today's golden file's mesh, compressed again: the same bytes (the format did not drift)."""
    import hashlib
    import json
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "data"))
    from make_cells_golden import digest, golden_mesh

    expected = json.loads((ROOT / "tests" / "data" / f"cells_v{VERSION_MAJOR}.json").read_text())
    out = tmp_path / "again.tetc"
    gatun_py.compress(golden_mesh(), out, scalar="p")
    assert digest(meshio.read(out)) == expected["decoded"]
    assert hashlib.sha256(out.read_bytes()).hexdigest() == expected["file_sha256"]
