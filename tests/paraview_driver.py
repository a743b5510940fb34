"""Run by pvbatch (ParaView's own Python, not the test's): load the plugin, open a .tetc file, report.

    xvfb-run -a pvbatch tests/paraview_driver.py PLUGIN FILE OUTDIR '{"props": {...}, "render": true}'

Writes OUTDIR/result.json (cells, cell types, points, arrays, time steps, per-step checksums, timings)
and OUTDIR/arrays.npz (points, connectivity, offsets, cell types and every point and cell array of
the first output), and with
"render" a volume rendering OUTDIR/volume.png.
"""

import inspect
import json
import os
import sys
import time

# Debian 12's ParaView 5.11 runs on Python 3.11, whose inspect lost getargspec, which ParaView's
# Python-plugin loader imports: put it back before loading any Python plugin.
inspect.getargspec = getattr(inspect, "getargspec", inspect.getfullargspec)

import numpy as np  # noqa: E402  (ParaView's numpy)
from paraview import servermanager  # noqa: E402
from paraview.simple import (ColorBy, GetActiveViewOrCreate, LoadPlugin, OpenDataFile, Render,  # noqa: E402
                             ResetCamera, SaveScreenshot, Show)
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402

plugin, path, outdir = sys.argv[1:4]
opts = json.loads(sys.argv[4]) if len(sys.argv) > 4 else {}
res = {}
t0 = time.perf_counter()
LoadPlugin(plugin, ns=globals())
res["load_s"] = time.perf_counter() - t0
t0 = time.perf_counter()
reader = OpenDataFile(path)
res["proxy"] = reader.GetXMLName()
for k, v in opts.get("props", {}).items():
    setattr(reader, k, v)
reader.UpdatePipelineInformation()
times = list(reader.TimestepValues) if reader.TimestepValues else []
res["times"] = times
reader.UpdatePipeline(times[0] if times else 0.0)
res["first_output_s"] = time.perf_counter() - t0


def describe(data):
    pd, cd = data.GetPointData(), data.GetCellData()
    return {
        "cells": data.GetNumberOfCells(),
        "points": data.GetNumberOfPoints(),
        "point_arrays": {pd.GetArrayName(i): [pd.GetArray(i).GetDataTypeAsString(), pd.GetArray(i).GetNumberOfComponents()]
                         for i in range(pd.GetNumberOfArrays())},
        "cell_arrays": [cd.GetArrayName(i) for i in range(cd.GetNumberOfArrays())],
        "cell_types": {str(t): int(n) for t, n in zip(*np.unique(cell_types(data), return_counts=True))},
    }


def cell_types(data):
    if not data.GetNumberOfCells():
        return np.zeros(0, np.uint8)
    return vtk_to_numpy(data.GetCellTypesArray()).astype(np.uint8)


data = servermanager.Fetch(reader)
res.update(describe(data))
if data.GetNumberOfPoints():
    arrays = {"points": vtk_to_numpy(data.GetPoints().GetData()),
              "connectivity": vtk_to_numpy(data.GetCells().GetConnectivityArray())}
    arrays["offsets"] = vtk_to_numpy(data.GetCells().GetOffsetsArray())
    arrays["types"] = cell_types(data)
    for name in res["point_arrays"]:
        arrays["point:" + name] = vtk_to_numpy(data.GetPointData().GetArray(name))
    for name in res["cell_arrays"]:
        arrays["cell:" + name] = vtk_to_numpy(data.GetCellData().GetArray(name))
    np.savez(os.path.join(outdir, "arrays.npz"), **arrays)
# stepping through a series: every step's checksum of its first point array
res["step_sums"] = []
for t in opts.get("step_times", []):
    reader.UpdatePipeline(t)
    d = servermanager.Fetch(reader)
    a = d.GetPointData().GetArray(0)
    res["step_sums"].append(float(np.asarray(vtk_to_numpy(a), np.float64).sum()) if a is not None else None)
if opts.get("render"):
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [200, 200]
    view.Background = [0.0, 0.0, 0.0]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 0
    display = Show(reader, view)
    display.Representation = "Volume"
    ColorBy(display, ("POINTS", opts["render"]))
    ResetCamera(view)
    Render(view)
    SaveScreenshot(os.path.join(outdir, "volume.png"), view, ImageResolution=[200, 200])
with open(os.path.join(outdir, "result.json"), "w") as fh:
    json.dump(res, fh)
