"""PyVista: ``pyvista.read`` of a .tetc file after ``import gatun_py``, and ``TetcFile.to_pyvista``."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pyvista = pytest.importorskip("pyvista", reason="pip install pyvista")

import gatun_py  # noqa: E402
from gatun_py.errors import OptionError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POST = ROOT / "tests" / "data" / "post_v9.tetc"


def _check(grid, mesh):
    assert grid.n_cells == mesh.n_tets and grid.n_points == mesh.n_points
    assert np.asarray(grid.points).tobytes() == mesh.points.tobytes()
    assert set(grid.celltypes.tolist()) == {pyvista.CellType.TETRA}
    assert np.array_equal(grid.cell_connectivity.reshape(-1, 4), mesh.tets)
    assert set(grid.point_data.keys()) == set(mesh.user_point_data)
    for name, a in mesh.user_point_data.items():
        got = np.asarray(grid.point_data[name])
        assert got.dtype == a.dtype and got.tobytes() == np.ascontiguousarray(a).tobytes(), name


def test_pyvista_read_through_meshio():
    _check(pyvista.read(POST), gatun_py.open(POST).mesh())


def test_pyvista_read_entry_point_without_import(tmp_path):
    """A fresh interpreter that never imports gatun_py itself: PyVista finds the reader by entry point."""
    code = ("import sys, pyvista; g = pyvista.read(sys.argv[1], ratio=0.5); "
            "print(g.n_cells, g.point_data['Pressure'].dtype, 'gatun_py' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code, str(POST)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == [str(gatun_py.open(POST).mesh(0.5).n_tets), "float32", "True"]


def test_to_pyvista_ratio_level_step():
    f = gatun_py.open(POST)
    _check(f.to_pyvista(0.5), f.mesh(0.5))
    _check(f.to_pyvista(level=2), f.mesh(level=2))
    _check(f.to_pyvista(step=0), f.mesh())
    with pytest.raises(OptionError, match="time step"):
        f.to_pyvista(step=int(getattr(f, "n_steps", 1)))


def test_readme_pyvista_block(tmp_path):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"```python\n(.*?)```", text[text.index("**PyVista.**"):], re.S).group(1)
    shutil.copy(POST, tmp_path / "post.tetc")
    res = subprocess.run([sys.executable, "-c", block + "\nprint(grid.n_cells)"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.split()[-1]) == gatun_py.open(POST).mesh(0.5).n_tets
