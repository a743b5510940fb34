"""Time series of meshes: several files in time order, a ParaView ``.pvd`` collection, an XDMF
temporal collection, or every step of an Exodus II or a temporal VTKHDF file.

:func:`read_series` returns a :class:`Series`: the times and, per step, a loader that reads that
step's :class:`~gatun_py.mesh.TetMesh` when it is asked for (a long run is never all in memory).
Every step is read and validated like a single mesh (:func:`~gatun_py.mesh.read_mesh`).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import MeshError, OptionError, ReadError
import meshio

from .cells import VOLUME_CELLS, Cells
from .exodus import EXODUS_SUFFIXES, exodus_times, read_exodus
from .io import _meshio_read, mesh_from_meshio, read_mesh
from .vtkhdf import is_vtkhdf, read_vtkhdf, vtkhdf_partitions

__all__ = ["Series", "read_series", "is_series_source", "SERIES_SUFFIXES", "tet_cell_data", "tet_cells"]

SERIES_SUFFIXES = (".pvd",)


class Series:
    """Steps of a run: ``times`` and the meshes, read on access (``series[k]``).

    Parameters
    ----------
    times : sequence of float
    loaders : sequence of callables
        ``loaders[k]()`` returns ``(TetMesh, MeshReport)`` of step k.
    names : sequence of str
        Where each step comes from (for messages).

    Examples
    --------
    >>> from gatun_py.warmup import tiny_mesh
    >>> s = Series([0.0, 0.5], [lambda: (tiny_mesh(), None)] * 2, ["a", "b"])
    >>> s
    Series(2 steps, times 0 .. 0.5)
    >>> s[1].n_tets
    90
    """

    def __init__(self, times, loaders, names):
        if not (len(times) == len(loaders) == len(names)):
            raise ValueError("times, loaders and names must have one entry per step")
        self.times = [float(t) for t in times]
        self._loaders = list(loaders)
        self.names = [str(n) for n in names]
        self.reports = [None] * len(self._loaders)
        self._last = None

    def __len__(self) -> int:
        return len(self._loaders)

    def __getitem__(self, k: int):
        k = range(len(self))[k]
        if self._last is not None and self._last[0] == k:
            return self._last[1]
        mesh, report = self._loaders[k]()
        self.reports[k] = report
        self._last = (k, mesh)
        return mesh

    def __repr__(self) -> str:
        if not self.times:
            return "Series(0 steps)"
        return f"Series({len(self)} step{'s' if len(self) != 1 else ''}, times {self.times[0]:g} .. {self.times[-1]:g})"


def tet_cell_data(cells, where: str = "") -> dict:
    """A step's volume cell arrays as one row per tet (the mesh's tet order), as a series stores
    them: every volume block must be of tets (a series keeps tets only); arrays of other blocks
    (faces, lines) are not kept. ``{}`` when there are none."""
    if cells is None or not cells.cell_data:
        return {}
    vol = [bi for bi, (t, _) in enumerate(cells.blocks) if t in VOLUME_CELLS]
    other = sorted({t for t, _ in (cells.blocks[bi] for bi in vol)} - {"tetra"})
    if other:
        raise MeshError(f"{where}: cell arrays of {', '.join(other)} cells: a series keeps its cell arrays per tet, "
                        "of tet meshes (average them to the points with cell-to-point, or drop them with "
                        "drop-cell-data)")
    out = {}
    for name, per in cells.cell_data.items():
        parts = [np.asarray(per[bi]) for bi in vol]
        if any(p.dtype == bool for p in parts):
            parts = [p.astype(np.uint8) for p in parts]  # the array coder's dtypes: booleans as 0/1 bytes
        a = parts[0] if len(parts) == 1 else np.concatenate(parts)
        if a.ndim > 2:
            a = a.reshape(len(a), -1)
        out[str(name)] = a[np.asarray(cells.tet_cell)]
    return out


def tet_cells(tets, cell_data: dict) -> Cells:
    """The :class:`Cells` of one block of tets carrying ``cell_data`` (one row per tet), to write."""
    return Cells([("tetra", np.asarray(tets, np.int64))], np.arange(len(tets), dtype=np.int64),
                 {name: [np.asarray(a)] for name, a in cell_data.items()})


def is_series_source(source) -> bool:
    """Whether ``source`` names a series: a list of several inputs, a ``.pvd``, or an XDMF file
    with a temporal collection."""
    if isinstance(source, Series):
        return True
    if isinstance(source, (list, tuple)):
        return len(source) != 1 or is_series_source(source[0])
    if isinstance(source, (str, os.PathLike)):
        p = Path(source)
        if p.suffix.lower() in SERIES_SUFFIXES:
            return True
        if p.suffix.lower() in (".xdmf", ".xmf") and p.is_file():
            return _xdmf_is_temporal(p)
    return False


def _xdmf_is_temporal(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return False
    return b'CollectionType="Temporal"' in head


def read_series(source, *, times=None, scalar: str | None = None, cell_to_point: bool = False) -> Series:
    """The steps of a run.

    Parameters
    ----------
    source : path-like or list of path-likes
        Several mesh files in time order, one ``.pvd`` collection, one XDMF temporal collection,
        one Exodus file or one temporal VTKHDF file (every step).
    times : sequence of float, optional
        The steps' times (several files only; default: each file's own ``TimeValue`` field, else
        0, 1, 2, ...). Must increase.
    scalar, cell_to_point
        How each step is read (see :func:`~gatun_py.mesh.read_mesh`).

    Raises
    ------
    ReadError
        A missing file, a ``.pvd`` entry outside its folder, an unreadable collection.
    OptionError
        Times that do not increase, or as many times as files.
    """
    opts = dict(scalar=scalar, cell_to_point=cell_to_point)
    if isinstance(source, Series):
        return source
    paths = [source] if isinstance(source, (str, os.PathLike)) else list(source)
    if not paths:
        raise OptionError("no input files")
    for p in paths:
        if not Path(p).exists():
            raise ReadError(f"no such file: {p}")
    if len(paths) == 1:
        p = Path(paths[0])
        suffix = p.suffix.lower()
        if suffix == ".pvd":
            return _with_times(_read_pvd(p, opts), times)
        if suffix in (".xdmf", ".xmf") and _xdmf_is_temporal(p):
            return _with_times(_read_xdmf(p, opts), times)
        if suffix in EXODUS_SUFFIXES:
            return _with_times(_read_exodus_series(p, opts), times)
        if is_vtkhdf(p):
            return _with_times(_read_vtkhdf_series(p, opts), times)
    for p in paths:
        if Path(p).suffix.lower() in SERIES_SUFFIXES:
            raise OptionError(f"{p}: a .pvd collection is a series of its own; give it alone")
    own = [None] * len(paths)
    if times is None:
        own = [_time_value(p) for p in paths]
        file_times = own if all(t is not None for t in own) else list(range(len(paths)))
    else:
        file_times = list(times)
        if len(file_times) != len(paths):
            raise OptionError(f"{len(paths)} files but {len(file_times)} times")
    loaders = [(lambda p=p: read_mesh(p, **opts)) for p in paths]
    return Series(_increasing(file_times, [str(p) for p in paths]), loaders, [str(p) for p in paths])


def _with_times(series: Series, times) -> Series:
    if times is None:
        return series
    times = list(times)
    if len(times) != len(series):
        raise OptionError(f"the collection has {len(series)} steps but {len(times)} times were given")
    series.times = _increasing(times, series.names)
    return series


def _increasing(times, names) -> list:
    out = []
    for k, t in enumerate(times):
        try:
            v = float(t)
        except (TypeError, ValueError):
            raise OptionError(f"time of step {k} ({names[k]}) is not a number: {t!r}") from None
        if not math.isfinite(v):
            raise OptionError(f"time of step {k} ({names[k]}) is not finite: {t!r}")
        if out and not v > out[-1]:
            raise OptionError(f"times go backwards: step {k} ({names[k]}) has time {v!r}, "
                              f"step {k - 1} ({names[k - 1]}) {out[-1]!r}")
        out.append(v)
    return out


def _time_value(path) -> float | None:
    """A VTK file's own ``TimeValue`` field (one number), else None."""
    if Path(path).suffix.lower() not in (".vtu", ".vtk"):
        return None
    try:
        m = _meshio_read(Path(path))
    except ReadError:
        return None
    v = m.field_data.get("TimeValue")
    if v is None:
        return None
    v = np.asarray(v).reshape(-1)
    return float(v[0]) if v.size == 1 else None


def _read_pvd(path: Path, opts: dict) -> Series:
    """The DataSets of a ParaView collection, in file order, with their ``timestep`` exactly as
    written; a file outside the collection's folder is refused."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise ReadError(f"cannot read {path} as a ParaView collection: {e}") from None
    sets = root.findall("./Collection/DataSet")
    if root.tag != "VTKFile" or not sets:
        raise ReadError(f"{path}: not a ParaView collection (no Collection of DataSets)")
    folder = path.resolve().parent
    times, files = [], []
    for i, ds in enumerate(sets):
        name = ds.get("file")
        if not name:
            raise ReadError(f"{path}: DataSet {i} names no file")
        if ds.get("part", "0") not in ("0", ""):
            raise ReadError(f"{path}: DataSet {i} is part {ds.get('part')} of a multi-part step; "
                            "only one part per step is read")
        f = (folder / name).resolve()
        if os.path.isabs(name) or not f.is_relative_to(folder):
            raise ReadError(f"{path}: DataSet {i} points outside the collection's folder ({name!r}); refused")
        if not f.is_file():
            raise ReadError(f"{path}: DataSet {i}: no such file {name!r}")
        t = ds.get("timestep", ds.get("time"))
        times.append(i if t is None else t)
        files.append(f)
    loaders = [(lambda f=f: read_mesh(f, **opts)) for f in files]
    return Series(_increasing(times, [str(f) for f in files]), loaders, [str(f) for f in files])


def _read_xdmf(path: Path, opts: dict) -> Series:
    """An XDMF temporal collection through meshio's TimeSeriesReader (one mesh, data per step)."""
    try:
        with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
            points, cells = reader.read_points_cells()
            steps = []
            for k in range(reader.num_steps):
                t, pd, cd = reader.read_data(k)
                steps.append((t, pd, cd))
    except Exception as e:  # meshio raises many types on malformed XDMF/HDF5
        raise ReadError(f"cannot read {path} as an XDMF temporal collection: {type(e).__name__}: {e}") from None
    if not steps:
        raise ReadError(f"{path}: the temporal collection holds no steps")

    def load(k):
        _, pd, cd = steps[k]
        m = meshio.Mesh(points, cells, point_data=pd, cell_data=cd)
        return mesh_from_meshio(m, source=f"{path} step {k}", **opts)

    names = [f"{path} step {k}" for k in range(len(steps))]
    return Series(_increasing([s[0] for s in steps], names), [(lambda k=k: load(k)) for k in range(len(steps))],
                  names)


def _read_exodus_series(path: Path, opts: dict) -> Series:
    """Every step of an Exodus file (its ``time_whole`` values)."""
    times = exodus_times(path)
    if not times:
        raise ReadError(f"{path}: the Exodus file holds no time steps")

    def load(k):
        m, notes = read_exodus(path, time_step=k)
        mesh, report = mesh_from_meshio(m, source=f"{path} step {k}", **opts)
        report.notes[:0] = [n for n in notes if not n.startswith("nodal variables of time step")]
        return mesh, report

    names = [f"{path} step {k}" for k in range(len(times))]
    return Series(_increasing(times, names), [(lambda k=k: load(k)) for k in range(len(times))], names)


def vtkhdf_steps(path) -> int:
    """Steps of a VTKHDF file (0 when it cannot tell: the single-mesh path reports the error)."""
    try:
        return vtkhdf_partitions(path)[2]
    except Exception:
        return 0


def _read_vtkhdf_series(path: Path, opts: dict) -> Series:
    """Every step of a temporal VTKHDF file, its ``Steps/Values`` exactly (each step's partitions
    concatenated, as :func:`~gatun_py.mesh.read_mesh` reads one step)."""
    times = read_vtkhdf(path, step=0).times
    names = [f"{path} step {k}" for k in range(len(times))]

    def load(k):  # the step's own notes, without the reader's "temporal, step k read" ones
        mesh, report = read_mesh(path, time_step=k, **opts)
        said = ("temporal VTKHDF", "time step ") + (("default scalar",) if k else ())  # step 0 says it
        report.notes[:] = [n for n in report.notes if not n.startswith(said)]
        return mesh, report

    return Series(_increasing(times, names), [(lambda k=k: load(k)) for k in range(len(times))], names)
