"""The ParaView reader plugin in a real ParaView: Debian's pvbatch under xvfb-run.

tests/paraview_driver.py runs inside pvbatch (ParaView's own Python, which cannot import gatun_py):
it loads gatun_py/paraview/tetc_reader.py, opens a .tetc file and reports what ParaView got, which
is checked here against gatun_py's own decode, bit for bit. Needs Debian's ``paraview`` and
``xvfb`` (``make test`` installs them); skips, saying which is missing, where they cannot be had.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gatun_py
from gatun_py.paraview import PLUGIN

ROOT = Path(__file__).resolve().parents[1]
DRIVER = ROOT / "tests" / "paraview_driver.py"
POST = ROOT / "tests" / "data" / "post_v9.tetc"
PVBATCH, XVFB = shutil.which("pvbatch"), shutil.which("xvfb-run")

needs_paraview = pytest.mark.skipif(
    PVBATCH is None or XVFB is None,
    reason=f"no {'pvbatch' if PVBATCH is None else 'xvfb-run'} here: install Debian's paraview and xvfb "
           "(make test does)")


def pvbatch(path, tmp_path, *, python=sys.executable, transfer="", **opts):
    """Run the driver on ``path``: (result dict, arrays npz or None, stderr)."""
    out = tmp_path / f"pv{len(list(tmp_path.glob('pv*')))}"
    out.mkdir()
    env = dict(os.environ, TETC_PYTHON=str(python), TETC_PARAVIEW_TRANSFER=transfer)
    proc = subprocess.run([XVFB, "-a", PVBATCH, str(DRIVER), str(PLUGIN), str(path), str(out), json.dumps(opts)],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    res = json.loads((out / "result.json").read_text())
    arrays = np.load(out / "arrays.npz") if (out / "arrays.npz").exists() else None
    return res, arrays, proc.stderr, out


@pytest.fixture(scope="module")
def snapshot(tmp_path_factory):
    return pvbatch(POST, tmp_path_factory.mktemp("pv"), render="Pressure")


@pytest.fixture(scope="module", params=["npy", "vtkhdf"])
def opened(request, snapshot, tmp_path_factory):
    """The snapshot through the plugin's default transfer (.npy files loaded with ParaView's numpy)
    and through its fallback (a VTKHDF file read by ParaView's vtkHDFReader)."""
    return snapshot if request.param == "npy" else pvbatch(POST, tmp_path_factory.mktemp("pv"), transfer="vtkhdf")


@needs_paraview
def test_snapshot_cells_and_arrays_bit_exact(opened):
    res, arrays, _, _ = opened
    f = gatun_py.open(POST)
    mesh = f.mesh()
    assert res["proxy"] == "TetcReader"
    assert res["cells"] == f.n_tets == 8750 and res["points"] == f.n_points
    assert res["times"] == []  # a snapshot has no time steps
    assert {k: v[1] for k, v in res["point_arrays"].items()} == {name: k for name, _, k in f.arrays}
    assert np.asarray(arrays["points"]).tobytes() == mesh.points.tobytes()
    assert np.array_equal(arrays["connectivity"].reshape(-1, 4), mesh.tets)
    for name, a in mesh.user_point_data.items():
        got = arrays["point:" + name]
        assert got.dtype == a.dtype and got.tobytes() == np.ascontiguousarray(a).tobytes(), name


def _lit_fraction(png: Path) -> float:
    from PIL import Image
    rgb = np.asarray(Image.open(png).convert("RGB")).astype(int)
    return float((rgb.max(axis=2) > 24).mean())


@needs_paraview
def test_volume_render_shows_the_object(snapshot):
    *_, out = snapshot
    lit = _lit_fraction(out / "volume.png")
    assert 0.1 < lit < 0.95, lit  # the object covers part of the black background, not none or all


@needs_paraview
def test_ratio_and_array_selection(tmp_path):
    f = gatun_py.open(POST)
    res, arrays, _, _ = pvbatch(POST, tmp_path, props={"Ratio": 0.5, "PointArrays": ["Pressure"]})
    want = f.mesh(0.5)
    assert res["cells"] == want.n_tets < f.n_tets
    assert list(res["point_arrays"]) == ["Pressure"]
    assert arrays["point:Pressure"].tobytes() == want.user_point_data["Pressure"].tobytes()


@needs_paraview
def test_stored_level(tmp_path):
    f = gatun_py.open(POST)
    res, _, _, _ = pvbatch(POST, tmp_path, props={"Level": 3})
    assert res["cells"] == f.mesh(level=3).n_tets < f.n_tets


def _newer(tmp_path):
    data = bytearray(POST.read_bytes())
    data[8:10] = (99).to_bytes(2, "little")  # the format version in the preamble
    path = tmp_path / "newer.tetc"
    path.write_bytes(bytes(data))
    return path


def _corrupt(tmp_path):
    path = tmp_path / "corrupt.tetc"
    path.write_bytes(b"this is not a tetc file" * 50)
    return path


@needs_paraview
@pytest.mark.parametrize("make, python, words", [
    (_newer, sys.executable, "written by a newer tetc"),
    (_corrupt, sys.executable, "not a .tetc file"),
    (lambda tmp: POST, "/usr/bin/python3", "gatun_py is not installed"),
    (lambda tmp: POST, "/nonexistent/python", "cannot run /nonexistent/python"),
])
def test_bad_input_one_clear_message(tmp_path, make, python, words):
    if python == "/usr/bin/python3" and subprocess.run([python, "-c", "import gatun_py"],
                                                       capture_output=True, env={}).returncode == 0:
        pytest.skip("the system Python has gatun_py: no Python without it to point the plugin at")
    res, _, stderr, _ = pvbatch(make(tmp_path), tmp_path, python=python)
    assert res["cells"] == 0  # an empty output, ParaView alive
    messages = [ln for ln in stderr.splitlines() if "tetc reader:" in ln]
    assert len(messages) == 1 and words in messages[0], stderr


def make_series(tmp_path, n_steps: int = 40, *, mesh_only: bool = False) -> Path:
    """A 40-step series over the post mesh (its Pressure scaled per step), compressed from .vtu files
    given in time order."""
    import meshio
    mesh = gatun_py.open(POST).mesh()
    files = []
    for k in range(n_steps):
        p = tmp_path / f"step{k:02d}.vtu"
        pd = {"Pressure": (mesh.user_point_data["Pressure"] * np.float32(1 + 0.05 * k)).astype(np.float32)}
        meshio.write(p, meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data=pd))
        files.append(str(p))
    out = tmp_path / "series.tetc"
    tetc = Path(sys.executable).parent / "tetc"
    proc = subprocess.run([str(tetc), "compress", *files, "-o", str(out), "-q"] + (["--mesh-only"] if mesh_only else []),
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


@needs_paraview
def test_series_time_steps(tmp_path):
    path = make_series(tmp_path)
    f = gatun_py.open(path)
    times = list(f.times)
    res, _, _, _ = pvbatch(path, tmp_path, step_times=[times[0], times[1], times[39]])
    assert res["times"] == times and len(times) == 40  # 40 TimestepValues
    sums = res["step_sums"]
    want = [float(np.asarray(f.mesh(step=k).user_point_data["Pressure"], np.float64).sum()) for k in (0, 1, 39)]
    assert sums == pytest.approx(want, rel=1e-12) and len(set(sums)) == 3  # stepping changes the data


def _readme_block(after: str, lang: str) -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(rf"```{lang}\n(.*?)```", text[text.index(after):], re.S)
    assert m, f"no ```{lang} block after {after!r}"
    return m.group(1)


@needs_paraview
@pytest.mark.slow
def test_readme_pvbatch_steps_as_written(tmp_path):
    """The README's ParaView steps, in a fresh directory, with only the venv's bin on PATH before the
    system's (as after `source .venv/bin/activate`) and no TETC_PYTHON."""
    (tmp_path / "sample_meshes").symlink_to(ROOT / "sample_meshes")
    (tmp_path / "open_tetc.py").write_text(_readme_block("### ParaView", "python"))
    env = {k: v for k, v in os.environ.items() if k != "TETC_PYTHON"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    script = _readme_block("### ParaView", "sh")
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert _lit_fraction(tmp_path / "post_paraview.png") > 0.05


def test_cli_prints_the_plugin_path_and_records_python():
    from cli_util import run
    res = run("paraview-plugin")
    assert res.exit_code == 0 and res.output.splitlines() == [str(PLUGIN)]
    assert PLUGIN.is_file() and "smproxy.reader" in PLUGIN.read_text()
    from gatun_py.paraview import PYTHON_FILE
    if os.access(PYTHON_FILE.parent, os.W_OK):  # recorded where the install is writable
        assert PYTHON_FILE.read_text().strip() == sys.executable


def test_decoder_serves_requests_one_line_each(tmp_path):
    """The resident decoder's protocol, without ParaView: an answer per request line, errors as
    {"error": ...} (the process goes on), the decoded .npy files equal to gatun_py's decode."""
    import io
    from gatun_py.paraview.decode import serve
    reqs = [{"file": str(POST), "output": str(tmp_path / "a.npydir"), "ratio": 0.5},
            {"file": str(tmp_path / "missing.tetc"), "output": str(tmp_path / "b.npydir")}, "not json"]
    stdin = io.StringIO("".join((json.dumps(r) if isinstance(r, dict) else r) + "\n" for r in reqs))
    stdout = io.StringIO()
    assert serve(stdin, stdout) == 0
    lines = [json.loads(ln) for ln in stdout.getvalue().splitlines()]
    assert lines[0] == {"ready": True} and len(lines) == 4
    want = gatun_py.open(POST).mesh(0.5)
    ans = lines[1]
    assert ans["cells"] == want.n_tets and ans["written_points"] == want.n_points
    folder = Path(ans["output"])
    assert np.array_equal(np.load(folder / ans["arrays"]["connectivity"]).reshape(-1, 4), want.tets)
    assert np.load(folder / ans["arrays"]["points"]).tobytes() == want.points.tobytes()
    for name, file in ans["arrays"]["point_data"]:
        assert np.load(folder / file).tobytes() == want.user_point_data[name].tobytes(), name
    assert "no such file" in lines[2]["error"] and "bad request" in lines[3]["error"]


def test_plugin_finds_python_and_explains_failures(monkeypatch, tmp_path):
    """The plugin's helpers, imported as plain Python (outside ParaView its decorators are no-ops)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("tetc_reader_under_test", PLUGIN)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setenv("TETC_PYTHON", "/some/python")
    assert mod.find_python() == ("/some/python", "$TETC_PYTHON")
    monkeypatch.delenv("TETC_PYTHON")
    monkeypatch.setenv("PYTHONPATH", "/usr/lib/python3/dist-packages")
    assert "PYTHONPATH" not in mod.child_env()
    assert "not installed" in mod.explain_failure(1, "/x/python: Error while finding module specification for "
                                                     "'gatun_py.paraview.decode' (ModuleNotFoundError: No module "
                                                     "named 'gatun_py')", "/x/python")
    assert mod.explain_failure(-9, "", "p").startswith("the decoder was killed by signal 9")
    assert mod.step_for_time([0.0, 0.5, 1.0], 0.7) == 1 and mod.step_for_time([0.0, 0.5], -1.0) == 0


def test_plugin_as_a_vtk_algorithm_keeps_few_decodes(monkeypatch):
    """The reader class in pip's VTK (no ParaView): every ratio asked for gives gatun_py's mesh at that
    ratio, a ratio asked for again is not decoded again, and at most KEEP_DECODED decodes stay on disk."""
    pytest.importorskip("vtkmodules.util.vtkAlgorithm", reason="pip install vtk")
    import importlib.util
    from vtkmodules.util.numpy_support import vtk_to_numpy
    monkeypatch.setenv("TETC_PYTHON", sys.executable)
    spec = importlib.util.spec_from_file_location("tetc_reader_as_vtk", PLUGIN)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    f = gatun_py.open(POST)
    reader = mod.TetcReader()
    reader.SetFileName(str(POST))
    try:
        for ratio in (0.0, 0.2, 0.4, 0.6, 0.8, 0.2):
            reader.SetRatio(ratio)
            reader.Update()
            want = f.mesh(ratio or None)
            out = reader.GetOutputDataObject(0)
            assert out.GetNumberOfCells() == want.n_tets, ratio
            got = vtk_to_numpy(out.GetPointData().GetArray("Pressure"))
            assert got.tobytes() == want.user_point_data["Pressure"].tobytes()
            assert len(os.listdir(reader._tmp)) <= mod.KEEP_DECODED
    finally:
        mod.DECODER.stop()


FAKE_SERIES = '''
import sys
import numpy as np
import gatun_py.api as api
from gatun_py.mesh import TetMesh
from gatun_py.paraview.decode import serve

_mesh = api.TetcFile.mesh


def mesh(self, ratio=None, *, level=None, jobs=None, step=0):
    m = _mesh(self, ratio, level=level, jobs=jobs)
    data = dict(m.user_point_data)
    if "Pressure" not in data:  # the decoder's warm-up file
        return m
    data["Pressure"] = (data["Pressure"] * np.float32(1 + 0.05 * step)).astype(np.float32)
    return TetMesh(m.points, None, m.tets, "Pressure", point_data=data)


api.TetcFile.n_steps = 40
api.TetcFile.times = tuple(0.5 * k for k in range(40))
api.TetcFile.mesh = mesh
sys.exit(serve())
'''


@needs_paraview
def test_plugin_time_steps_with_a_stand_in_series(tmp_path):
    """The plugin's side of a series, before .tetc files hold one: its decoder is given a TetcFile with
    40 steps (each step's Pressure scaled), as the time-series API has them (n_steps, times,
    mesh(step=)). ParaView shows 40 TimestepValues and stepping changes the data."""
    script = tmp_path / "fake_series.py"
    script.write_text(FAKE_SERIES)
    python = tmp_path / "python"
    python.write_text(f"#!/bin/sh\nexec {sys.executable} {script}\n")  # ignores the plugin's -m arguments
    python.chmod(0o755)
    times = [0.5 * k for k in range(40)]
    res, _, _, _ = pvbatch(POST, tmp_path, python=python, step_times=[times[0], times[1], times[39], 7.3])
    assert res["times"] == times
    base = float(np.asarray(gatun_py.open(POST).mesh().user_point_data["Pressure"], np.float64).sum())
    want = [base * (1 + 0.05 * k) for k in (0, 1, 39, 14)]  # t = 7.3 shows step 14 (t = 7.0)
    assert res["step_sums"] == pytest.approx(want, rel=1e-5) and len(set(res["step_sums"])) == 4


CELLS = ROOT / "tests" / "data" / "cells_v10.tetc"  # hexahedra, pyramids, tets, tetra10, wedges; cell arrays


@needs_paraview
def test_original_cells_by_default_tets_on_request(tmp_path):
    """A file that stores its cells as given opens in ParaView as those cells (VTK types and counts,
    the connectivity, every point and cell array bit for bit); Output Tets gives the tets."""
    from meshio._vtk_common import meshio_to_vtk_type
    from test_vtkhdf import _cells_as_given
    f = gatun_py.open(CELLS)
    want = _cells_as_given(CELLS)  # the cells as given, as the decompress verb writes them
    res, arrays, _, _ = pvbatch(CELLS, tmp_path)
    counts = {}
    for c in want.cells:
        key = str(meshio_to_vtk_type[c.type])
        counts[key] = counts.get(key, 0) + len(c.data)
    assert res["cell_types"] == counts and len(counts) == 5
    assert res["cells"] == sum(len(c.data) for c in want.cells) and res["points"] == len(want.points)
    assert arrays["connectivity"].tolist() == np.concatenate([c.data.reshape(-1) for c in want.cells]).tolist()
    assert sorted(res["cell_arrays"]) == sorted(want.cell_data) and want.cell_data
    for name, blocks in want.cell_data.items():
        a = np.concatenate([np.asarray(b) for b in blocks])
        got = arrays["cell:" + name]
        assert got.dtype == a.dtype and got.tobytes() == np.ascontiguousarray(a).tobytes(), name
    for name, a in want.point_data.items():
        assert arrays["point:" + name].tobytes() == np.ascontiguousarray(a).tobytes(), name
    res, _, _, _ = pvbatch(CELLS, tmp_path, props={"OutputTets": 1})
    assert res["cell_types"] == {"10": f.n_tets} and res["cell_arrays"] == []


PARAVIEW_GUI = shutil.which("paraview")

GUI_SCRIPT = '''
import json, os, sys
out = {OUT!r}
open(out + ".started", "w").close()  # the GUI came up and runs its Python
try:
    {SHELL_LINE}                      # the README's line for View > Python Shell
    from paraview.simple import *
    LoadPlugin({PLUGIN!r}, remote=False, ns=globals())   # Tools > Manage Plugins > Load New...
    reader = OpenDataFile({FILE!r})                       # File > Open
    Show(reader)
    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()              # what the GUI does when data with time is opened
    keeper = GetTimeKeeper()
    res = {{"proxy": reader.GetXMLName(), "reader_times": list(reader.TimestepValues),
           "gui_times": list(keeper.TimestepValues), "sums": []}}
    from paraview import servermanager
    from vtkmodules.util.numpy_support import vtk_to_numpy
    for t in (res["gui_times"][0], res["gui_times"][-1]):
        scene.AnimationTime = t                            # the time controls: first and last step
        data = servermanager.Fetch(reader)
        res["sums"].append(float(vtk_to_numpy(data.GetPointData().GetArray("Pressure")).astype("float64").sum()))
except Exception as e:
    res = {{"error": repr(e)}}
with open(out, "w") as fh:
    json.dump(res, fh)
os._exit(0)
'''


def _readme_shell_line() -> str:
    """The Python line the README's GUI steps type into View > Python Shell before loading the plugin."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(r"`([^`]*getargspec[^`]*)` in \*View › Python Shell\*", text)
    assert m, "the README's GUI steps no longer name the View > Python Shell line"
    return m.group(1)


@pytest.mark.slow
@pytest.mark.skipif(PARAVIEW_GUI is None or XVFB is None,
                    reason="no paraview GUI or xvfb-run here: install Debian's paraview and xvfb (make test does)")
def test_gui_steps_as_written(tmp_path):
    """The README's GUI steps in the real ParaView GUI (under xvfb-run, its --script run at start-up):
    `tetc paraview-plugin` gives the file, the Python Shell line, Tools > Manage Plugins > Load New
    (LoadPlugin, what that dialog calls), File > Open of a 40-step series: the GUI's time keeper shows
    its 40 TimestepValues and the time controls change the data."""
    series = make_series(tmp_path, mesh_only=True)  # the GUI's side is under test, not the levels
    env = {k: v for k, v in os.environ.items() if k != "TETC_PYTHON"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    plugin = subprocess.run(["tetc", "paraview-plugin"], env=env, capture_output=True, text=True, check=True)
    assert len(plugin.stdout.splitlines()) == 1
    out = tmp_path / "gui.json"
    script = tmp_path / "gui_steps.py"
    script.write_text(GUI_SCRIPT.format(OUT=str(out), SHELL_LINE=_readme_shell_line(),
                                        PLUGIN=plugin.stdout.strip(), FILE=str(series)))
    try:
        proc = subprocess.run([XVFB, "-a", PARAVIEW_GUI, "--dr", f"--script={script}"], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=900)
        log = proc.stdout + proc.stderr
    except subprocess.TimeoutExpired as e:
        log = f"timed out after {e.timeout} s"
    if not Path(str(out) + ".started").exists():
        pytest.skip(f"the ParaView GUI did not start headless under xvfb-run: {log[-400:]}")
    assert out.exists(), log
    res = json.loads(out.read_text())
    assert "error" not in res, (res, log)
    times = list(gatun_py.open(series).times)
    assert res["proxy"] == "TetcReader" and res["reader_times"] == times and len(times) == 40
    assert res["gui_times"] == times  # the GUI's time controls step through the 40 steps
    f = gatun_py.open(series)
    want = [float(np.asarray(f.mesh(step=k).user_point_data["Pressure"], np.float64).sum()) for k in (0, 39)]
    assert res["sums"] == pytest.approx(want, rel=1e-12) and res["sums"][0] != res["sums"][1]
    assert "Traceback" not in log, log
