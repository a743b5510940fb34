"""Exodus II input with a choice of time step (netCDF4 is the optional ``exodus`` extra)."""

from __future__ import annotations

import numpy as np
import pytest

from cli_util import assert_error, run
from gatun_py.errors import OptionError, ReadError
from gatun_py.mesh import read_mesh
from gatun_py.mesh import exodus as exodus_mod
from samples import SAMPLES

netCDF4 = pytest.importorskip("netCDF4", reason="netCDF4 (the exodus extra) writes and reads Exodus files")


def _write_exodus(path, mesh, steps):
    """A minimal Exodus II file: one tet block, nodal variables 'p' and 'vel_x' over len(steps) steps."""
    with netCDF4.Dataset(path, "w") as nc:
        n, m = mesh.n_points, mesh.n_tets
        nc.createDimension("len_string", 33)
        nc.createDimension("num_dim", 3)
        nc.createDimension("num_nodes", n)
        nc.createDimension("num_elem", m)
        nc.createDimension("num_el_blk", 1)
        nc.createDimension("num_el_in_blk1", m)
        nc.createDimension("num_nod_per_el1", 4)
        nc.createDimension("num_nod_var", 2)
        nc.createDimension("time_step", None)
        for k, a in enumerate("xyz"):
            nc.createVariable(f"coord{a}", "f8", ("num_nodes",))[:] = np.asarray(mesh.points[:, k], np.float64)
        conn = nc.createVariable("connect1", "i4", ("num_el_in_blk1", "num_nod_per_el1"))
        conn.elem_type = "TETRA"
        conn[:] = mesh.tets + 1
        names = nc.createVariable("name_nod_var", "S1", ("num_nod_var", "len_string"))
        names[:] = netCDF4.stringtochar(np.array(["p", "vel_x"], dtype="S33"))
        nc.createVariable("time_whole", "f8", ("time_step",))[:] = np.asarray(steps, float)
        p = nc.createVariable("vals_nod_var1", "f8", ("time_step", "num_nodes"))
        v = nc.createVariable("vals_nod_var2", "f8", ("time_step", "num_nodes"))
        for t, time in enumerate(steps):
            p[t, :] = np.asarray(mesh.density, np.float64) * (1 + t)
            v[t, :] = time


@pytest.fixture(scope="module")
def exo(tmp_path_factory):
    mesh = read_mesh(SAMPLES["post"][0])[0]
    path = tmp_path_factory.mktemp("exo") / "run.exo"
    _write_exodus(path, mesh, [0.0, 0.5, 1.5])
    return path, mesh


def test_the_last_step_by_default_and_any_step_on_request(exo):
    path, src = exo
    last, report = read_mesh(path, scalar="p")
    assert any("time step 2 of 0..2 (time 1.5)" in n for n in report.notes)
    assert (last.n_points, last.n_tets) == (src.n_points, src.n_tets)
    np.testing.assert_allclose(last.density, src.density.astype(np.float64) * 3, rtol=1e-6)
    first, _ = read_mesh(path, scalar="p", time_step=0)
    np.testing.assert_allclose(first.density, src.density, rtol=1e-6)
    same, _ = read_mesh(path, scalar="vel_x", time_step=-2)
    assert np.all(same.density == 0.5)


def test_bad_time_steps(exo, tmp_path):
    path, _ = exo
    with pytest.raises(OptionError, match="time step 3 does not exist .*0..2"):
        read_mesh(path, scalar="p", time_step=3)
    with pytest.raises(OptionError, match="applies to Exodus"):
        read_mesh(SAMPLES["post"][0], time_step=1)
    assert_error(run("info", path, "--scalar", "p", "--time-step", 9), "does not exist")
    res = run("info", path, "--scalar", "p", "--time-step", 1, "--json")
    assert res.exit_code == 0 and "time step 1 of 0..2" in res.output


def test_without_netcdf4_the_message_says_how_to_get_it(exo, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_netcdf(name, *args, **kwargs):
        if name == "netCDF4":
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_netcdf)
    with pytest.raises(ReadError, match=r"pip install 'gatun_py\[exodus\]'"):
        exodus_mod.read_exodus(exo[0])
