"""ParaView reader plugin for ``.tetc`` files (compressed tetrahedral meshes).

Load it in ParaView with Tools > Manage Plugins > Load New (this file; ``tetc paraview-plugin``
prints its path) or ``LoadPlugin(path, ns=globals())`` in pvbatch/pvpython; then File > Open (or
``OpenDataFile``) reads ``.tetc`` files.

ParaView's own Python cannot import gatun_py: gatun_py needs numba and a numpy that ParaView's
build may not match, and loading both into one process breaks one of them. So this file imports
only the standard library and ParaView's VTK, and runs the decoder in the Python gatun_py is
installed in (``python -m gatun_py.paraview.decode --serve``, started when the plugin loads and kept):
it writes the requested time step, at the requested ratio or stored level, as ``.npy`` files in a
temporary folder, which ParaView's own numpy loads straight into VTK arrays (ParaView 5.11's
VTKHDF and XML readers take longer than the decode; where ParaView has no numpy the decoder writes
a VTKHDF file for ParaView's reader).
That Python is found, in this order, in the ``TETC_PYTHON`` environment variable, in
``tetc_python.txt`` beside this file (written by ``tetc paraview-plugin``), as the virtual
environment this file is installed in, or from the ``tetc`` command on ``PATH``.

The output is the cells as given (hexahedra, wedges, quadratic cells... with their cell arrays)
where the file stores them, else its tets. Properties: Ratio (simplify on the fly: merged / all
vertices, 0 = the full mesh), Level (a stored level, -1 = none; a simplified mesh is tets), Output
Tets (the tets the cells were split into), the point and cell arrays to load, and the time steps of
a series (``TimestepValues``). A file that cannot be read shows one message in the output window and gives
an empty output.
"""

import atexit
import json
import os
import shutil
import subprocess
import tempfile

try:
    from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
    from vtkmodules.vtkCommonCore import vtkDataArraySelection, vtkOutputWindow
    from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkUnstructuredGrid
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
except ImportError:  # imported without VTK (a doctest run): the helpers below still work
    VTKPythonAlgorithmBase = object
try:  # ParaView's own numpy: the decoded arrays are loaded with it (the fastest route)
    import numpy as np
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkTypeInt32Array, vtkTypeInt64Array, vtkUnsignedCharArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray
except ImportError:  # a ParaView without numpy: the decoder writes VTKHDF for ParaView's reader
    np = None
try:
    from vtkmodules.vtkIOHDF import vtkHDFReader
except ImportError:  # VTK before 9.1: the decoder is asked for .vtu files instead
    vtkHDFReader = None
try:
    from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy
    IN_PARAVIEW = True
except ImportError:  # plain VTK (pip's vtk, tests): the reader runs as an ordinary algorithm
    IN_PARAVIEW = False

    class _Ignore:
        """ParaView's decorator modules as no-ops."""

        def __getattr__(self, name):
            return lambda *args, **kwargs: (lambda f: f)

    smdomain = smhint = smproperty = smproxy = _Ignore()

PYTHON_ENV = "TETC_PYTHON"
# how the decoded mesh reaches ParaView: npy (default where ParaView has numpy), vtkhdf or vtu (the
# fallbacks, read by ParaView's own readers; set to test them)
TRANSFER_ENV = "TETC_PARAVIEW_TRANSFER"
HERE = os.path.dirname(os.path.abspath(__file__))
PYTHON_FILE = os.path.join(HERE, "tetc_python.txt")
# decoded steps kept on disk per reader (stepping back and forth does not decode again)
KEEP_DECODED = 3


def find_python():
    """``(path, how found)`` of the Python that has gatun_py, or ``(None, what was tried)``."""
    env = os.environ.get(PYTHON_ENV, "").strip()
    if env:
        return env, f"${PYTHON_ENV}"
    try:
        with open(PYTHON_FILE, encoding="utf-8") as fh:
            recorded = fh.read().strip()
        if recorded and os.path.exists(recorded):
            return recorded, PYTHON_FILE
    except OSError:
        pass
    # <prefix>/lib/pythonX.Y/site-packages/gatun_py/paraview/tetc_reader.py: <prefix>/bin/python
    parts = HERE.split(os.sep)
    if len(parts) > 5 and parts[-3] == "site-packages" and parts[-5] == "lib":
        for name in ("python3", "python"):
            cand = os.path.join(os.sep.join(parts[:-5]) or os.sep, "bin", name)
            if os.path.exists(cand):
                return cand, "the environment this plugin is installed in"
    tetc = shutil.which("tetc")
    if tetc:
        try:
            with open(tetc, "rb") as fh:
                first = fh.readline(4096).decode("utf-8", "replace").strip()
        except OSError:
            first = ""
        if first.startswith("#!") and " " not in first[2:].strip():
            return first[2:].strip(), tetc
    return None, (f"${PYTHON_ENV}, {PYTHON_FILE}, the environment of {HERE} and `tetc` on PATH")


def child_env():
    """The decoder's environment: ParaView's own Python paths removed, so that the other Python
    sees only its own packages (ParaView's numpy first on its path would break its numba)."""
    env = dict(os.environ)
    for key in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTHONNOUSERSITE"):
        env.pop(key, None)
    return env


def explain_failure(returncode, stderr, python):
    """One line for ParaView's output window from a failed decoder run."""
    lines = [ln.strip() for ln in (stderr or "").splitlines() if ln.strip()]
    for ln in lines:
        if ln.startswith("tetc: error: "):
            return ln[len("tetc: error: "):]
    text = " ".join(lines)
    if "No module named" in text and "gatun_py" in text:
        return (f"gatun_py is not installed for {python}: install it there (pip install gatun_py), "
                f"or point {PYTHON_ENV} at the Python that has it")
    if returncode is not None and returncode < 0:
        return f"the decoder was killed by signal {-returncode} (out of memory?)"
    last = lines[-1] if lines else f"exit status {returncode}"
    return f"the decoder failed ({python}): {last}"


class Decoder:
    """The decoder process (``python -m gatun_py.paraview.decode --serve``), one per ParaView process:
    started when the plugin loads, so that gatun_py and its kernels are loaded before the first file
    is opened, and kept for every later request (another ratio, another time step). A decoder that
    died (killed, out of memory) is started again at the next request."""

    def __init__(self):
        self.proc = self.python = self.log = None
        self.ready = False

    def start(self):
        """``(process, None)`` or ``(None, message)``."""
        python, how = find_python()
        if python is None:
            return None, (f"cannot find the Python that has gatun_py (tried {how}): run `tetc paraview-plugin` "
                          f"in the environment gatun_py is installed in, or set {PYTHON_ENV}")
        if self.proc is not None and self.proc.poll() is None and self.python == python:
            return self.proc, None
        self.stop()
        self.log = tempfile.TemporaryFile(mode="w+")  # its stderr: a file, so a chatty decoder never blocks
        try:
            self.proc = subprocess.Popen([python, "-m", "gatun_py.paraview.decode", "--serve"], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, stderr=self.log, text=True, env=child_env())
        except OSError as e:
            self.proc = None
            return None, (f"cannot run {python} ({e.strerror or e}): point {PYTHON_ENV} at the Python that has "
                          "gatun_py, or run `tetc paraview-plugin` in its environment")
        self.python, self.ready = python, False
        return self.proc, None

    def request(self, **req):
        """One request: ``(answer dict, None)`` or ``(None, message)``."""
        proc, err = self.start()
        if err:
            return None, err
        try:
            if not self.ready:
                if not proc.stdout.readline():  # {"ready": true} once gatun_py is loaded
                    raise EOFError
                self.ready = True
            proc.stdin.write(json.dumps(req) + "\n")
            proc.stdin.flush()
            line = proc.stdout.readline()
            if not line:
                raise EOFError
            answer = json.loads(line)
        except (OSError, EOFError, ValueError):
            try:
                code = proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                code = proc.wait()
            self.log.seek(0)
            message = explain_failure(code, self.log.read(), self.python)
            self.stop()
            return None, message
        if "error" in answer:
            return None, answer["error"]
        return answer, None

    def stop(self):
        if self.proc is not None:
            try:
                self.proc.stdin.close()
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
            self.proc = None
        if self.log is not None:
            self.log.close()
            self.log = None


DECODER = Decoder()
atexit.register(DECODER.stop)
if IN_PARAVIEW:  # start loading gatun_py now, while ParaView and its user do something else
    DECODER.start()


def _unlink(path):
    try:
        os.unlink(path)
    except OSError:
        pass


def _vtk_array(cls, a):
    """A VTK array of class ``cls`` holding a copy of the 1-D numpy array ``a``."""
    out = cls()
    out.SetNumberOfValues(len(a))
    vtk_to_numpy(out)[:] = a
    return out


def grid_from_arrays(folder, manifest):
    """A vtkUnstructuredGrid from the decoder's ``.npy`` files (ParaView's numpy reads them; the
    connectivity goes into VTK's cell array in the width it was written, 32 or 64 bits)."""
    def load(name):
        return np.load(os.path.join(folder, name), allow_pickle=False)

    grid = vtkUnstructuredGrid()
    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(load(manifest["points"]), deep=1))
    grid.SetPoints(pts)
    conn, offsets = load(manifest["connectivity"]), load(manifest["offsets"])
    cls = vtkTypeInt32Array if conn.dtype == np.int32 else vtkTypeInt64Array
    cells = vtkCellArray()
    cells.SetData(_vtk_array(cls, offsets.astype(conn.dtype, copy=False)), _vtk_array(cls, conn))
    if manifest.get("cell_type") is not None:
        grid.SetCells(int(manifest["cell_type"]), cells)
    else:
        grid.SetCells(_vtk_array(vtkUnsignedCharArray, load(manifest["types"])), cells)
    for attrs, entries in ((grid.GetPointData(), manifest["point_data"]), (grid.GetCellData(), manifest["cell_data"])):
        for name, file in entries:
            a = numpy_to_vtk(np.ascontiguousarray(load(file)), deep=1)
            a.SetName(name)
            attrs.AddArray(a)
    return grid


def step_for_time(times, t):
    """The step shown at time ``t``: the last whose time is <= t (the first before them all)."""
    best = 0
    for i, ti in enumerate(times):
        if ti <= t:
            best = i
    return best


@smproxy.reader(name="TetcReader", label="tetc compressed tetrahedral mesh", extensions="tetc",
                file_description="tetc compressed tetrahedral mesh")
class TetcReader(VTKPythonAlgorithmBase):
    """Reads a ``.tetc`` file: its cells as given (or its tets) with every point and cell array, a
    time step of a series, simplified on the fly to a ratio or a stored level."""

    def __init__(self):
        VTKPythonAlgorithmBase.__init__(self, nInputPorts=0, nOutputPorts=1, outputType="vtkUnstructuredGrid")
        self._filename = None
        self._ratio = 0.0
        self._level = -1
        self._tets = False
        self._info = None  # the decoder's description of the file, for its (name, mtime, size)
        self._info_key = None
        self._decoded = {}  # (file key, step, ratio, level, tets) -> (path, points), in decoding order
        self._manifests = {}  # path -> the decoder's list of its .npy files
        self._count = 0
        self._tmp = None
        self._shown = set()  # messages already shown (ParaView asks several times per update)
        self._point_sel = vtkDataArraySelection()
        self._cell_sel = vtkDataArraySelection()
        for sel in (self._point_sel, self._cell_sel):
            sel.AddObserver("ModifiedEvent", lambda *_: self.Modified())

    def __del__(self):
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)

    # -- properties --------------------------------------------------------------------------------

    @smproperty.stringvector(name="FileName")
    @smdomain.filelist()
    @smhint.filechooser(extensions="tetc", file_description="tetc compressed tetrahedral mesh")
    def SetFileName(self, name):
        if name != self._filename:
            self._filename = name
            self._shown.clear()
            self.Modified()

    @smproperty.doublevector(name="Ratio", default_values=0.0)
    @smdomain.doublerange(min=0.0, max=1.0)
    def SetRatio(self, ratio):
        """Simplify on the fly: merged / all vertices (0: the full mesh)."""
        if ratio != self._ratio:
            self._ratio = float(ratio)
            self.Modified()

    @smproperty.intvector(name="Level", default_values=-1)
    @smdomain.intrange(min=-1, max=13)
    def SetLevel(self, level):
        """A stored level as it is (-1: none, use Ratio)."""
        if level != self._level:
            self._level = int(level)
            self.Modified()

    @smproperty.intvector(name="OutputTets", label="Output Tets", default_values=0)
    @smdomain.xml('<BooleanDomain name="bool"/>')
    def SetOutputTets(self, tets):
        """Output the tets the cells were split into (0: the cells as given, where the file stores them)."""
        if bool(tets) != self._tets:
            self._tets = bool(tets)
            self.Modified()

    @smproperty.dataarrayselection(name="Point Arrays")
    def GetPointDataArraySelection(self):
        return self._point_sel

    @smproperty.dataarrayselection(name="Cell Arrays")
    def GetCellDataArraySelection(self):
        return self._cell_sel

    @smproperty.doublevector(name="TimestepValues", information_only="1", si_class="vtkSITimeStepsProperty")
    def GetTimestepValues(self):
        info = self._info
        return info["times"] if info and info.get("n_steps", 1) > 1 else None

    # -- the pipeline ------------------------------------------------------------------------------

    def _show(self, message):
        """One message in ParaView's output window (once per file and message)."""
        if message not in self._shown:
            self._shown.add(message)
            vtkOutputWindow.GetInstance().DisplayErrorText(f"tetc reader: {message}\n")

    def _file_key(self):
        st = os.stat(self._filename)
        return (os.path.abspath(self._filename), st.st_mtime_ns, st.st_size)

    def _settings(self):
        level = self._level if self._level >= 0 else None
        ratio = self._ratio if level is None and self._ratio > 0 else None
        return ratio, level

    def _decode(self, key, step):
        """Decode ``step`` at the current settings (once; kept for KEEP_DECODED requests):
        ``((path, points written), None)`` or ``(None, message)``."""
        ratio, level = self._settings()
        want = (key, step, ratio, level, self._tets)
        if want in self._decoded and os.path.exists(self._decoded[want][0]):
            return self._decoded[want], None
        if self._tmp is None:
            self._tmp = tempfile.mkdtemp(prefix="tetc-paraview-")
        ext = ".npydir" if np is not None else ".vtkhdf" if vtkHDFReader is not None else ".vtu"
        ext = {"npy": ".npydir", "vtkhdf": ".vtkhdf", "vtu": ".vtu"}.get(os.environ.get(TRANSFER_ENV, ""), ext)
        self._count += 1  # a new name every time: a kept decode is never overwritten
        out = os.path.join(self._tmp, f"decoded{self._count}_step{step}{ext}")
        info, err = DECODER.request(file=self._filename, output=out, step=step, ratio=ratio, level=level,
                                    tets=self._tets)
        if err:
            return None, err
        self._remember(key, info)
        self._decoded[want] = (info["output"], int(info["written_points"]))
        self._manifests[info["output"]] = info.get("arrays")
        while len(self._decoded) > KEEP_DECODED:
            path, _ = self._decoded.pop(next(iter(self._decoded)))
            self._manifests.pop(path, None)
            if os.path.isdir(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                _unlink(path)
        return self._decoded[want], None

    def _remember(self, key, info):
        self._info, self._info_key = info, key
        for sel, names in ((self._point_sel, info.get("point_arrays", [])),
                           (self._cell_sel, info.get("cell_arrays", []))):
            for name, _ in names:
                if not sel.ArrayExists(name):
                    sel.AddArray(name)

    def RequestInformation(self, request, inInfoVec, outInfoVec):
        out = outInfoVec.GetInformationObject(0)
        out.Remove(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
        out.Remove(vtkStreamingDemandDrivenPipeline.TIME_RANGE())
        if not self._filename:
            return 1
        try:
            key = self._file_key()
        except OSError as e:
            self._show(f"cannot read {self._filename}: {e.strerror or e}")
            return 1
        if self._info_key != key:
            # the first step is decoded now: the description comes with it, and the first output
            # costs one start of the other Python, not two
            _, err = self._decode(key, 0)
            if err:
                self._show(f"{os.path.basename(self._filename)}: {err}")
                self._info, self._info_key = None, None
                return 1
        times = self._info.get("times", [])
        if self._info.get("n_steps", 1) > 1:
            for t in times:
                out.Append(vtkStreamingDemandDrivenPipeline.TIME_STEPS(), t)
            out.Set(vtkStreamingDemandDrivenPipeline.TIME_RANGE(), [times[0], times[-1]], 2)
        return 1

    def RequestData(self, request, inInfoVec, outInfoVec):
        out_info = outInfoVec.GetInformationObject(0)
        output = vtkUnstructuredGrid.GetData(outInfoVec, 0)
        if not self._filename or self._info is None:
            return 1  # the reason was shown by RequestInformation; the output stays empty
        try:
            key = self._file_key()
        except OSError as e:
            self._show(f"cannot read {self._filename}: {e.strerror or e}")
            return 1
        times = self._info.get("times", [0.0])
        step = 0
        if self._info.get("n_steps", 1) > 1 and out_info.Has(vtkStreamingDemandDrivenPipeline.UPDATE_TIME_STEP()):
            step = step_for_time(times, out_info.Get(vtkStreamingDemandDrivenPipeline.UPDATE_TIME_STEP()))
        decoded, err = self._decode(key, step)
        if err:
            self._show(f"{os.path.basename(self._filename)}: {err}")
            return 1
        path, n_points = decoded
        if self._manifests.get(path):
            try:
                data = grid_from_arrays(path, self._manifests[path])
            except (OSError, ValueError, KeyError) as e:
                self._show(f"{os.path.basename(self._filename)}: cannot load the decoded arrays in {path}: {e}")
                return 1
        else:
            reader = vtkHDFReader() if path.endswith(".vtkhdf") else vtkXMLUnstructuredGridReader()
            reader.SetFileName(path)
            reader.Update()
            data = reader.GetOutputDataObject(0)
        if not isinstance(data, vtkUnstructuredGrid) or data.GetNumberOfPoints() != n_points:
            self._show(f"{os.path.basename(self._filename)}: ParaView could not read the decoded mesh {path}")
            return 1
        output.ShallowCopy(data)
        for attrs, sel in ((output.GetPointData(), self._point_sel), (output.GetCellData(), self._cell_sel)):
            for name in [attrs.GetArrayName(i) for i in range(attrs.GetNumberOfArrays())]:
                if name and sel.ArrayExists(name) and not sel.ArrayIsEnabled(name):
                    attrs.RemoveArray(name)
        if self._info.get("n_steps", 1) > 1:
            output.GetInformation().Set(vtkDataObject.DATA_TIME_STEP(), times[step])
        return 1
