"""PLOT3D keeps its whole Q file (five variables, free-stream header), and a cell array renders as a
constant per cell (against tests/naive_render.py's per-tet reference)."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

import gatun_py
from gatun_py.codec import TetcReader
from gatun_py.codec.cells import read_cells
from gatun_py.mesh import mesh_from_meshio, read_mesh
from gatun_py.mesh.cells import constant_per_cell, tet_values
from gatun_py.mesh.plot3d import FREE_STREAM, Q_STORED, grid_hexes, read_q_file, read_xyz
from gatun_py.raycast.camera import Camera
from gatun_py.raycast.transfer import load_transfer_function

from mixedgen import mixed_mesh
from naive_render import naive_render

ROOT = Path(__file__).resolve().parents[1]
BLUNT = ROOT.parent / "shared" / "data" / "bluntfin"
if not BLUNT.exists():
    BLUNT = ROOT / "sample_meshes" / "bluntfin"


# -- PLOT3D: every Q variable and the free-stream header --------------------------------------------

def test_bluntfin_keeps_its_whole_q_file_bit_exactly(tmp_path):
    xyz = BLUNT / "bluntfinxyz.bin"
    grid = read_xyz(xyz)
    sol = read_q_file(BLUNT / "bluntfinq.bin", grid.dims)
    raw = (BLUNT / "bluntfinq.bin").read_bytes()
    bo = ">" if np.frombuffer(raw[:4], ">i4")[0] == grid.dims[0] else "<"
    n = int(np.prod(grid.dims))
    planes = np.frombuffer(raw, f"{bo}f4", count=5 * n, offset=28).reshape(5, n).astype(np.float32)
    head = np.frombuffer(raw, f"{bo}f4", count=4, offset=12).astype(np.float32)
    out = tmp_path / "bf.tetc"
    gatun_py.compress(xyz, out, mesh_only=True, keep_order=True)
    r = TetcReader(out)
    mesh = gatun_py.TetcFile(out).mesh()
    assert mesh.scalar_name == "density"
    cells = read_cells(r, mesh.tets, mesh.n_points, mesh.points)
    assert list(cells.field_data) == list(FREE_STREAM)
    for i, k in enumerate(FREE_STREAM):
        assert cells.field_data[k].tobytes() == head[i:i + 1].tobytes() == sol.free_stream[k].tobytes()
    # decompressed in the grid's own numbering: points, the five Q planes, the hexahedra, bit for bit
    vtu = tmp_path / "bf.vtu"
    gatun_py.decompress(out, vtu)
    m = meshio.read(vtu)
    assert np.asarray(m.points).astype(np.float32).tobytes() == grid.xyz.tobytes()
    for i, name in enumerate(Q_STORED):
        a = np.asarray(m.point_data[name])
        assert a.dtype == np.float32 and a.tobytes() == planes[i].tobytes(), name
    assert [c.type for c in m.cells] == ["hexahedron"]
    assert np.array_equal(m.cells[0].data, grid_hexes(grid.dims)[0])
    # (meshio's .vtu writer leaves field data out: the header was checked in the file above)


def test_derived_q_variable_is_the_default_scalar_beside_the_five(tmp_path):
    from test_mesh_readers import _write_plot3d

    _, q = _write_plot3d(tmp_path, (3, 3, 2))
    m, rep = read_mesh(tmp_path / "gxyz.bin", q_var="pressure")
    assert m.scalar_name == "pressure" and set(m.point_data) == set(Q_STORED) | {"pressure"}
    assert m.point_data["momentum-y"].tobytes() == q[2].tobytes()
    assert [t for t, _ in rep.cells.blocks] == ["hexahedron"] and len(rep.cells.tet_cell) == m.n_tets
    assert set(rep.cells.field_data) == set(FREE_STREAM)


# -- a cell array rendered as a constant per cell ---------------------------------------------------

def _mesh_with_cell_values(seed=3):
    m = mixed_mesh(3, 3, 2, seed)
    del m.cell_data["flag"]  # what .vtu cannot hold
    m.point_sets.clear()
    m.cell_sets.clear()
    m.field_data.clear()
    rng = np.random.default_rng(seed)
    m.cell_data["w"] = [rng.random(len(c.data)) for c in m.cells]  # a value per cell, changing at every face
    tm, rep = mesh_from_meshio(m, scalar="p")
    return m, tm, rep.cells


def test_constant_per_cell_is_constant_in_every_tet():
    _, tm, cells = _mesh_with_cell_values()
    vals = tet_values(cells, "w")
    pc = constant_per_cell(tm, vals, "w")
    assert pc.n_tets == tm.n_tets
    d = pc.density[pc.tets]
    assert np.array_equal(d, np.repeat(vals.astype(np.float32)[:, None], 4, axis=1))
    assert np.array_equal(pc.points[pc.tets], tm.points[tm.tets])  # the same tets, in place


@pytest.mark.parametrize("mode", ["volume", "face"])
def test_cell_array_render_matches_the_per_tet_reference(tmp_path, mode):
    m, tm, cells = _mesh_with_cell_values()
    src = tmp_path / "m.vtu"
    m.write(src)
    frame = gatun_py.render(src, size=24, azimuth=30, elevation=20, scalar="w", mode=mode, terminate=False,
                            tf="default", scalar_range=(0.0, 1.0))
    vals = tet_values(cells, "w")
    step = gatun_py.mesh.default_step(tm.points, tm.boundary_faces())
    lo, hi = tm.bbox
    cam = Camera(24, 24, 30.0, 20.0).fit(lo, hi)
    tf = load_transfer_function("default").for_size(float(np.linalg.norm(hi - lo)))  # as the caster sizes it
    ref = naive_render(tm, cam, tf, mode=mode, step=step, terminate=False, tet_values=vals,
                       scalar_range=(0.0, 1.0))
    assert frame.image.any()
    np.testing.assert_allclose(frame.image, ref, atol=2e-4)


def test_a_cell_array_equal_on_every_cell_renders_as_that_constant_everywhere(tmp_path):
    m, tm, _ = _mesh_with_cell_values()
    n = [len(c.data) for c in m.cells]
    m.cell_data["c"] = [np.full(k, 0.7) for k in n]
    m.point_data["c7"] = np.full(len(m.points), 0.7)
    src = tmp_path / "m.vtu"
    m.write(src)
    rng = (0.0, 1.0)
    a = gatun_py.render(src, size=32, azimuth=20, elevation=10, scalar="c", scalar_range=rng)
    b = gatun_py.render(src, size=32, azimuth=20, elevation=10, scalar="c7", scalar_range=rng)
    assert a.image.any() and np.array_equal(a.image, b.image)
    # from a .tetc file too, where the cell array is stored
    out = tmp_path / "m.tetc"
    gatun_py.compress(src, out, mesh_only=True, scalar="p")
    c = gatun_py.render(out, size=32, azimuth=20, elevation=10, scalar="c", scalar_range=rng)
    assert np.array_equal(c.image, b.image)


def test_cell_array_render_from_a_file_and_the_command_line(tmp_path):
    from cli_util import assert_error, run

    m, tm, cells = _mesh_with_cell_values()
    src = tmp_path / "m.vtu"
    m.write(src)
    out = tmp_path / "m.tetc"
    gatun_py.compress(src, out, scalar="p")
    a = gatun_py.render(src, size=24, scalar="w", scalar_range=(0, 1))
    b = gatun_py.render(out, size=24, scalar="w", scalar_range=(0, 1))
    np.testing.assert_allclose(a.image, b.image, atol=1e-6)
    assert b.stats["scalar"] == "w"
    png = tmp_path / "w.png"
    res = run("render", out, "-o", png, "--scalar", "w", "--size", "24")
    assert res.exit_code == 0, res.output
    assert png.exists()
    res = run("render", out, "-o", tmp_path / "x.png", "--scalar", "w", "--ratio", "0.5")
    assert_error(res, "cell array")


# -- quadratic nodes predicted from their edges; constant and counter cell arrays -------------------

def test_quadratic_nodes_are_coded_on_their_edges(tmp_path):
    from cells_check import check_round_trip, vertex_order_of
    from gatun_py.codec.tetcfile import LevelPayload, encode_level
    from mixedgen import tetra10_mesh

    orig = tetra10_mesh(n=4)
    tm, rep = mesh_from_meshio(orig)
    out = tmp_path / "t10.tetc"
    gatun_py.compress(orig, out, mesh_only=True)
    r = TetcReader(out)
    assert r.meta["cells"].get("node_refs") is True
    check_round_trip(orig, meshio.read(out), vertex_order_of(tm))
    # the nodes sit at their edges' midpoints: their coordinates cost far less than coded as loose points
    plain = encode_level(LevelPayload(0, 0.0, 0, tm))
    quad = tuple((t, d) for t, d in rep.cells.blocks)
    on_edges = encode_level(LevelPayload(0, 0.0, 0, tm, node_blocks=quad))
    assert on_edges.node_refs and not plain.node_refs
    assert len(on_edges.sections["L0/geometry"]) < 0.8 * len(plain.sections["L0/geometry"])


def test_quadratic_nodes_off_their_midpoints_and_streaming_decode(tmp_path):
    from cells_check import check_round_trip, vertex_order_of
    from mixedgen import tetra10_mesh

    orig = tetra10_mesh(seed=2, n=3)
    pts = np.asarray(orig.points).copy()
    nodes = np.unique(orig.cells[0].data[:, 4:])
    pts[nodes] += np.random.default_rng(1).normal(scale=0.01, size=(len(nodes), 3))  # curved edges
    orig = meshio.Mesh(pts, [("tetra10", orig.cells[0].data)], point_data={"u": pts[:, 0] ** 2})
    tm, _ = mesh_from_meshio(orig)
    out = tmp_path / "c.tetc"
    gatun_py.compress(orig, out)  # with levels
    check_round_trip(orig, meshio.read(out), vertex_order_of(tm))
    whole = TetcReader(out).decode_mesh(0, jobs=1)
    streamed = np.concatenate([b.points for b in TetcReader(out).iter_decode(0, batch_tets=50)])
    assert np.array_equal(streamed, whole.points.astype(np.float32))


def test_constant_and_counter_cell_arrays_cost_a_few_bytes(tmp_path):
    from cells_check import check_round_trip, vertex_order_of
    from test_cells import _exact

    m = mixed_mesh(4, 4, 3, 5)
    m.cell_data = {"tag": [np.full(len(c.data), 7 + i, np.int32) for i, c in enumerate(m.cells)],
                   "zero": [np.full((len(c.data), 3), -0.0) for c in m.cells],
                   "CellId": [np.arange(len(c.data), dtype=np.int64) * 2 + 5 for c in m.cells]}
    tm, _ = mesh_from_meshio(m)
    for keep in (False, True):
        out = tmp_path / f"k{keep}.tetc"
        gatun_py.compress(m, out, mesh_only=True, keep_order=keep)
        back = meshio.read(out)
        if keep:
            _exact(m, back)
        else:
            check_round_trip(m, back, vertex_order_of(tm))
        r = TetcReader(out)
        sizes = {n: r.container.section_size(n) for n in r.container.section_names() if n.startswith("C/data")}
        j = [e["name"] for e in r.meta["cells"]["cell_data"]]
        for name in ("tag", "zero"):
            assert all(v < 40 for k, v in sizes.items() if k.startswith(f"C/data/{j.index(name)}/")), sizes
        if keep:  # in the order given, a counter is two numbers
            assert all(v < 40 for k, v in sizes.items() if k.startswith(f"C/data/{j.index('CellId')}/")), sizes
