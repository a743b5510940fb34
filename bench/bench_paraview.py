"""The ParaView reader plugin's first output against ParaView opening the same mesh as a zlib .vtu.

    python bench/bench_paraview.py [--quick] [--repeat N] [--tetc FILE]

Default mesh: Blunt-fin refined 2x per axis (1.5 M tets; ``bench/common.refined_tetc``), or FILE.
Writes the peer, the same mesh as ``.vtu`` with VTK's XML writer and zlib (what ParaView's *Save
Data* writes), then times in Debian's pvbatch (under xvfb-run), each run a fresh process and the
two interleaved: from ``OpenDataFile`` to the end of the first ``UpdatePipeline``. The plugin's time
includes the decoder process (started by LoadPlugin: gatun_py and numba imported, kernels from the
cache), decoding, the .npy files and loading them into VTK; a second column opens a small file first
(the decoder already up, as in a GUI session); a fresh decoder process is timed apart. Medians of the
runs; the machine's load is recorded. Writes bench/sections/paraview.md.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, WORK, code_state, refined_tetc, table, write_section

PVBATCH, XVFB = shutil.which("pvbatch"), shutil.which("xvfb-run")
PLUGIN = ROOT / "gatun_py" / "paraview" / "tetc_reader.py"

PV_SCRIPT = r'''
import inspect, json, sys, time
inspect.getargspec = getattr(inspect, "getargspec", inspect.getfullargspec)
from paraview.simple import LoadPlugin, OpenDataFile
path, plugin, warm = sys.argv[1], sys.argv[2], sys.argv[3]
if plugin != "-":
    LoadPlugin(plugin, ns=globals())
if warm != "-":  # a session whose decoder is already up: another .tetc file opened first
    OpenDataFile(warm).UpdatePipeline()
t0 = time.perf_counter()
reader = OpenDataFile(path)
reader.UpdatePipeline()
sec = time.perf_counter() - t0
cells = reader.GetDataInformation().GetNumberOfCells()
print(json.dumps({"s": sec, "cells": cells}))
'''


def write_vtu(mesh, path: Path) -> None:
    """The mesh as ParaView saves it: VTK XML, binary appended, zlib."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import VTK_TETRA, vtkCellArray, vtkUnstructuredGrid
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter
    import numpy as np

    g = vtkUnstructuredGrid()
    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(mesh.points, deep=1))
    g.SetPoints(pts)
    cells = vtkCellArray()
    offsets = np.arange(0, 4 * mesh.n_tets + 1, 4, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=1),
                  numpy_to_vtkIdTypeArray(mesh.tets.astype(np.int64).reshape(-1), deep=1))
    g.SetCells(VTK_TETRA, cells)
    for name, a in mesh.user_point_data.items():
        arr = numpy_to_vtk(np.ascontiguousarray(a), deep=1)
        arr.SetName(name)
        g.GetPointData().AddArray(arr)
    w = vtkXMLUnstructuredGridWriter()
    w.SetInputData(g)
    w.SetFileName(str(path))
    w.SetCompressorTypeToZLib()
    w.Write()


def pv_open(script: Path, path: Path, plugin: str, warm: str = "-") -> dict:
    env = dict(os.environ, TETC_PYTHON=sys.executable)
    p = subprocess.run([XVFB, "-a", PVBATCH, str(script), str(path), plugin, warm], capture_output=True, text=True,
                       env=env, timeout=1200)
    if p.returncode != 0:
        raise RuntimeError(f"pvbatch failed: {p.stderr[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def decoder_s(path: Path, tmp: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gatun_py.paraview.decode", str(path), str(tmp / "d.vtkhdf")],
                   check=True, capture_output=True)
    return time.perf_counter() - t0


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    repeat = int(argv[argv.index("--repeat") + 1]) if "--repeat" in argv else (2 if quick else 5)
    if PVBATCH is None or XVFB is None:
        print("bench_paraview: skipped, no pvbatch/xvfb-run (install Debian's paraview and xvfb: make paraview)",
              file=sys.stderr)
        return 0
    if "--tetc" in argv:
        tetc = Path(argv[argv.index("--tetc") + 1])
        label = tetc.name
    else:
        rec = refined_tetc("bluntfin", 2)
        tetc, label = ROOT / rec["tetc"], "Blunt-fin refined 2x (mesh only)"
    import gatun_py

    mesh = gatun_py.open(tetc).mesh()
    WORK.mkdir(parents=True, exist_ok=True)
    vtu = WORK / f"{tetc.stem}_zlib.vtu"
    if not vtu.exists() or vtu.stat().st_mtime < tetc.stat().st_mtime:
        write_vtu(mesh, vtu)
    load_before = os.getloadavg()
    ours, warm, peer, dec = [], [], [], []
    tiny = ROOT / "tests" / "data" / "post_v9.tetc"
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        script = tmp / "open.py"
        script.write_text(PV_SCRIPT)
        for i in range(repeat):  # interleaved, so that both see the same load
            r = pv_open(script, tetc, str(PLUGIN))
            assert r["cells"] == mesh.n_tets, r
            ours.append(r["s"])
            r = pv_open(script, tetc, str(PLUGIN), str(tiny))
            assert r["cells"] == mesh.n_tets, r
            warm.append(r["s"])
            r = pv_open(script, vtu, "-")
            assert r["cells"] == mesh.n_tets, r
            peer.append(r["s"])
            dec.append(decoder_s(tetc, tmp))
            print(f"run {i}: plugin {ours[-1]:.2f} s (decoder up: {warm[-1]:.2f} s), zlib .vtu {peer[-1]:.2f} s, "
                  f"decoder alone {dec[-1]:.2f} s",
                  flush=True)
    load_after = os.getloadavg()
    m_ours, m_warm, m_peer, m_dec = (statistics.median(x) for x in (ours, warm, peer, dec))
    rows = [[label, f"{mesh.n_tets:,}", f"{tetc.stat().st_size / 2**20:.1f}", f"{vtu.stat().st_size / 2**20:.1f}",
             f"{m_ours:.2f}", f"{m_warm:.2f}", f"{m_peer:.2f}", f"{m_ours / m_peer:.2f}x", f"{m_warm / m_peer:.2f}x",
             f"{m_dec:.2f}"]]
    text = f"""## ParaView reader plugin: first output

`python bench/bench_paraview.py{' --quick' if quick else ''}` ({code_state()}). Debian's ParaView
(pvbatch under xvfb-run), each open a fresh pvbatch process, the two interleaved, median of {repeat}:
from `OpenDataFile` to the end of the first `UpdatePipeline`. The plugin (gatun_py/paraview/tetc_reader.py)
asks its decoder process (gatun_py's Python, started when the plugin loads) for the full mesh, which
it writes as `.npy` files that the plugin loads with ParaView's numpy into VTK arrays; the peer is
ParaView's XML reader on the same mesh saved as a zlib `.vtu` (VTK's XML writer, appended binary, as
ParaView's *Save Data* writes it). "decoder alone": a fresh `python -m gatun_py.paraview.decode FILE
OUT.vtkhdf` process (start-up, numba, decode, VTKHDF write) timed by itself, for scale. Target: plugin <= 1.5x
the `.vtu`. Load average {load_before[0]:.1f} before, {load_after[0]:.1f} after, on {os.cpu_count()} cores.

{table(["mesh", "tets", ".tetc MB", ".vtu MB", "plugin s", "plugin, decoder up s", ".vtu s", "plugin / .vtu",
        "decoder up / .vtu", "decoder alone s"], rows)}

"plugin": `LoadPlugin` then at once `OpenDataFile` (the decoder process starts with the plugin and is
still loading gatun_py). "decoder up": a small `.tetc` opened first, as in a GUI session where the
plugin auto-loaded at start-up. Runs (plugin / decoder up / .vtu, s):
{', '.join(f'{a:.2f}/{w:.2f}/{b:.2f}' for a, w, b in zip(ours, warm, peer))}.
"""
    write_section("paraview", text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
