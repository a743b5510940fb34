"""`tetc compress`, `tetc decompress`, `tetc info` on .tetc files: exit codes and messages."""

from __future__ import annotations

import json
import os

import numpy as np

from cli_util import assert_error, run
from conftest import SAMPLES
from gatun_py.codec import TetcReader
from gatun_py.codec.container import VERSION_MAJOR
from gatun_py.codec.cutborder import encode_connectivity
from gatun_py.codec.geometry import geometry_stream_sizes
from gatun_py.mesh import read_mesh
from naive_codec import canonical_tets

POST = str(SAMPLES / "lox_post_tets" / "post.vtk")
FIRE = str(SAMPLES / "room_fire" / "fire_ug.vtu")




def _same_mesh(a, b):
    """b equals a up to the codec's vertex permutation, every float bit-identical."""
    vo = encode_connectivity(a.n_points, a.tets).vertex_order
    assert np.array_equal(b.points.view(np.uint32), a.points[vo].view(np.uint32))
    assert np.array_equal(b.density.view(np.uint32), a.density[vo].view(np.uint32))
    assert canonical_tets(vo[b.tets]) == canonical_tets(a.tets)


def test_compress_info_decompress_round_trip(tmp_path):
    out = tmp_path / "post.tetc"
    res = run("compress", POST, "-o", out, "--mesh-only")
    assert res.exit_code == 0, res.output
    assert "wrote" in res.output and "bits/tet" in res.output
    res = run("info", out, "--json")
    assert res.exit_code == 0
    info = json.loads(res.output)
    mesh = read_mesh(POST)[0]
    assert info["points"] == mesh.n_points and info["tets"] == mesh.n_tets
    assert info["bytes_total"] == os.path.getsize(out)
    assert 0 < info["bits_per_tet_connectivity"] < 2.3
    assert 0 < info["bits_per_vertex_geometry"] < 96
    assert set(info["sections"]) == {"L0/boundary", "L0/tets", "L0/geometry"}
    assert info["levels"][0]["tets"] == mesh.n_tets
    assert info["boundary_faces"] == len(mesh.boundary_faces())
    vtu = tmp_path / "back.vtu"
    res = run("decompress", out, "-o", vtu, "--quiet")
    assert res.exit_code == 0 and res.output == ""
    _same_mesh(mesh, read_mesh(vtu)[0])


def test_info_parts_add_up_to_the_sections(tmp_path):
    """`parts` groups every section once (all levels, and level 0 alone); the text output shows
    them instead of the raw section list."""
    out = tmp_path / "fire.tetc"
    assert run("compress", FIRE, "--scalar", "t", "-o", out, "-q", "--levels", "2").exit_code == 0
    info = json.loads(run("info", out, "--json").output)
    parts = {row["part"]: row for row in info["parts"]}
    assert sum(row["bytes"] for row in info["parts"]) == sum(info["sections"].values())
    # level 0's bytes: its sections, and the value tables of the coarser levels its geometry chains to
    reader = TetcReader(out)
    chained, level = 0, 0
    need = ("x", "y", "z", "density")
    while True:  # the chained channels' table streams, level after level as far as each chain goes
        sizes = geometry_stream_sizes(reader.read_section(f"L{level}/geometry"))
        need = [c for c in need if sizes[c + "_mode"] == "chained"]
        if not need:
            break
        level += 1
        coarser = geometry_stream_sizes(reader.read_section(f"L{level}/geometry"))
        chained += sum(coarser[c + "_table"] for c in need)
    assert level > 0  # fire's levels chain
    assert sum(row["level0_bytes"] for row in info["parts"]) == sum(
        v for k, v in info["sections"].items() if k.startswith("L0/")) + chained
    assert parts["geometry value tables"]["level0_bytes"] == chained + geometry_stream_sizes(
        reader.read_section("L0/geometry"))["tables"]
    assert {"connectivity", "geometry", "geometry value tables", "merge forests", "array 'uvw'"} <= set(parts)
    assert parts["connectivity"]["level0_bytes"] == info["sections"]["L0/boundary"] + info["sections"]["L0/tets"]
    assert [row["bytes"] for row in info["parts"]] == sorted((row["bytes"] for row in info["parts"]), reverse=True)
    text = run("info", out).output
    assert "parts (all levels / level 0, bytes):" in text and "array 'uvw'" in text
    assert "L0/geometry" not in text  # the raw list is --json's


def test_refuses_to_overwrite_without_force(tmp_path):
    out = tmp_path / "f.tetc"
    out.write_bytes(b"keep")
    assert_error(run("compress", POST, "-o", out, "-q"), "already exists", "--force")
    assert out.read_bytes() == b"keep"
    assert run("compress", POST, "-o", out, "-q", "--force").exit_code == 0
    vtu = tmp_path / "x.vtu"
    vtu.write_bytes(b"keep")
    assert_error(run("decompress", out, "-o", vtu), "already exists")


def test_bad_inputs(tmp_path):
    assert_error(run("decompress", tmp_path / "missing.tetc", "-o", tmp_path / "a.vtu"), "no such file")
    notetc = tmp_path / "x.tetc"
    notetc.write_bytes(b"hello world, not a mesh" * 3)
    assert_error(run("decompress", notetc, "-o", tmp_path / "a.vtu"), "not a .tetc file")
    assert_error(run("info", notetc), "not a .tetc file")
    good = tmp_path / "g.tetc"
    run("compress", POST, "-o", good, "-q", "--mesh-only")
    data = good.read_bytes()
    cut = tmp_path / "cut.tetc"
    cut.write_bytes(data[: len(data) // 2])
    assert_error(run("decompress", cut, "-o", tmp_path / "a.vtu"), "corrupt")
    newer = bytearray(data)
    newer[8] = VERSION_MAJOR + 1  # a version this reader does not know
    (tmp_path / "new.tetc").write_bytes(bytes(newer))
    assert_error(run("decompress", tmp_path / "new.tetc", "-o", tmp_path / "a.vtu"), "newer")
    assert not (tmp_path / "a.vtu").exists()
    assert_error(run("decompress", good, "-o", tmp_path / "a.vtu", "--level", "3"), "level 3")
    assert_error(run("compress", POST, "-o", tmp_path / "nodir" / "x.tetc"), "does not exist")


def test_usage_errors_exit_2(tmp_path):
    assert run("compress", POST).exit_code == 2  # missing -o
    assert run("decompress").exit_code == 2
    assert run("decompress", "a.tetc", "-o", "b.vtu", "--level", "-1").exit_code == 2


def test_every_array_through_the_cli_and_cell_data_never_dropped_silently(tmp_path):
    """A float64 .vtu with several point arrays and a cell array: compress refuses until the cell data
    is dropped on request; info lists the arrays; decompress writes them all back, bit for bit."""
    import meshio

    from gatun_py.mesh.validate import validate_tets
    from meshgen import AWKWARD

    base = AWKWARD["jittered_grid"]()
    rng = np.random.default_rng(4)
    n = base.n_points
    pts = base.points.astype(np.float64) + rng.normal(size=(n, 3)) * 1e-10
    tets = validate_tets(pts, base.density, base.tets)[0].tets
    pd = {"p": rng.normal(size=n), "T": rng.normal(size=n).astype(np.float32), "u": rng.normal(size=(n, 3))}
    src = tmp_path / "in.vtu"
    meshio.write(src, meshio.Mesh(pts, [("tetra", tets)], point_data=pd, cell_data={"mat": [np.ones(len(tets))]}))
    out = tmp_path / "a.tetc"
    res = run("compress", src, "--scalar", "p", "-o", out, "--mesh-only")  # the cell array is kept
    assert res.exit_code == 0 and meshio.read(out).cell_data["mat"][0].tolist() == [1.0] * len(tets), res.output
    res = run("compress", src, "--scalar", "p", "-o", out, "--mesh-only", "--drop-cell-data", "--force")
    assert res.exit_code == 0 and "cell data dropped" in res.output, res.output
    info = json.loads(run("info", out, "--json").output)
    assert info["points_dtype"] == "float64" and info["format_version"] == VERSION_MAJOR
    assert [(a["name"], a["dtype"], a["components"]) for a in info["arrays"]] == [
        ("p", "float64", 1), ("T", "float32", 1), ("u", "float64", 3)]
    back_path = tmp_path / "back.vtu"
    assert run("decompress", out, "-o", back_path).exit_code == 0
    back = meshio.read(back_path)
    order = np.lexsort(pts.T[::-1])
    border = np.lexsort(back.points.T[::-1])
    assert back.points.dtype == np.float64 and back.points[border].tobytes() == pts[order].tobytes()
    for name, a in pd.items():
        b = np.asarray(back.point_data[name])
        assert b.dtype == a.dtype and b.reshape(a.shape)[border].tobytes() == a[order].tobytes(), name
