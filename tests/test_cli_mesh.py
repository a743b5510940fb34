"""`tetc` frame, `convert` and `info`: exit codes 0/1/2 and one-line messages."""

import json

import meshio
import numpy as np
import pytest

from cli_util import assert_error, run
from conftest import SAMPLES
from gatun_py import __version__
from gatun_py.mesh import read_mesh

BLUNT = str(SAMPLES / "bluntfin" / "bluntfinxyz.bin")
POST = str(SAMPLES / "lox_post_tets" / "post.vtk")
FIRE = str(SAMPLES / "room_fire" / "fire_ug.vtu")




def test_version_and_help():
    assert run("--version").output.strip() == f"tetc, version {__version__}"
    res = run("--help")
    assert res.exit_code == 0 and "convert" in res.output and "info" in res.output


def test_info_json_bluntfin():
    res = run("info", BLUNT, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    assert (d["points"], d["tets"], d["boundary_faces"], d["zero_volume_tets"]) == (40960, 187395, 13516, 77)
    for key in ("reoriented_tets", "coincident_points", "unreferenced_points", "bbox", "scalar_range"):
        assert key in d
    assert d["scalar_range"][0] == pytest.approx(0.1926, abs=1e-4)


def test_info_text_post():
    res = run("info", POST)
    assert res.exit_code == 0 and "coincident_points: 88" in res.output


def test_convert_fire_and_read_back(tmp_path):
    out = tmp_path / "fire_tets.vtu"
    res = run("convert", FIRE, "--scalar", "t", "-o", out, "--quiet")
    assert res.exit_code == 0, res.output
    m = meshio.read(out)
    assert m.cells[0].type == "tetra" and len(m.cells[0].data) == 52310
    assert {"mfrac", "t", "u", "v", "w"} <= set(m.point_data)  # every point array is kept
    back, rep = read_mesh(out, scalar="t")
    assert rep.reoriented_tets == 0 and (back.signed_volumes() > 0).all()


def test_convert_refuses_to_overwrite(tmp_path):
    out = tmp_path / "p.vtu"
    out.write_text("keep me")
    assert_error(run("convert", POST, "-o", out), "already exists", "--force")
    assert out.read_text() == "keep me"
    assert run("convert", POST, "-o", out, "--force", "-q").exit_code == 0
    assert meshio.read(out).points.shape == (2288, 3)


def test_convert_unwritable_and_bad_extension(tmp_path):
    assert_error(run("convert", POST, "-o", tmp_path / "nodir" / "x.vtu"), "does not exist")
    assert_error(run("convert", POST, "-o", tmp_path / "x.what"), "unknown extension", ".vtu")


@pytest.mark.parametrize("case", ["missing", "unreadable", "no_volume", "unknown_scalar", "nan", "out_of_range",
                                  "repeated", "duplicate"])
def test_bad_inputs_exit_1_with_one_line(tmp_path, case):
    p = tmp_path / "m.vtu"
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    pd = {"s": np.arange(5.0)}
    args = ["info", p]
    expect = []
    if case == "missing":
        p = tmp_path / "none.vtu"
        args = ["info", p]
        expect = ["no such file"]
    elif case == "unreadable":
        p.write_text("garbage")
        expect = ["cannot read"]
    elif case == "no_volume":
        meshio.Mesh(pts, [("line", np.array([[0, 1]]))], point_data=pd).write(p)
        expect = ["no volume cells"]
    elif case == "unknown_scalar":
        meshio.Mesh(pts, [("tetra", tets)], point_data=pd).write(p)
        args += ["--scalar", "rho"]
        expect = ["rho", "available: s"]
    elif case == "nan":
        pts[2, 0] = np.nan
        meshio.Mesh(pts, [("tetra", tets)], point_data=pd).write(p)
        expect = ["point 2", "non-finite"]
    elif case == "out_of_range":
        meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 7]]))], point_data=pd).write(p)
        expect = ["cell 1", "vertex 7"]
    elif case == "repeated":
        meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 2, 4]]))], point_data=pd).write(p)
        expect = ["tet 1 repeats"]
    elif case == "duplicate":
        meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [3, 2, 1, 0]]))], point_data=pd).write(p)
        expect = ["duplicates tet 0"]
    assert_error(run(*args), *expect)


def test_usage_errors_exit_2():
    assert run("convert", POST).exit_code == 2  # missing -o
    assert run("info").exit_code == 2
    assert run("info", POST, "--q-var", "nonsense").exit_code == 2
    assert run("frobnicate").exit_code == 2


def test_outputs_get_normal_permissions(tmp_path):
    import os
    import stat

    out = tmp_path / "p.vtu"
    assert run("convert", POST, "-o", out, "-q").exit_code == 0
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~mask
    assert [p.name for p in tmp_path.iterdir()] == ["p.vtu"]  # no temporary left behind
