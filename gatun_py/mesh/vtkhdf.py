"""VTKHDF (``.vtkhdf``): VTK's one-file HDF5 format, read and written with h5py.

VTK and ParaView read it natively, with time steps; it compresses only with deflate, so it is the
interchange format beside ``.tetc``. An unstructured grid is written as one partition: the
points, the cells (every linear and quadratic type meshio names, mixed: VTK's types, offsets and
connectivity), every point and cell array in its own dtype, meshio's field data. Consecutive
blocks of one cell type read back as one block (VTKHDF has no blocks); point and cell sets are
not written. A series is written temporal (VTKHDF 2.0): the mesh once (every step's offsets 0),
each step's arrays one after the other, the time values in ``Steps/Values``; arrays that do not
change are written once and replayed by their offsets. Files of other writers may be partitioned
(one partition per MPI rank) and temporal with a changing mesh: reading a step concatenates its
partitions, as VTK's own reader does (points on partition seams stay duplicated).

Examples
--------
>>> import os, tempfile, numpy as np
>>> from gatun_py.warmup import tiny_mesh
>>> path = os.path.join(tempfile.mkdtemp(), "tiny.vtkhdf")
>>> m = tiny_mesh()
>>> steps = [(t, {"p": m.density + t}, {}) for t in (0.0, 0.5)]
>>> write_vtkhdf(path, m, steps=steps)
>>> s = read_vtkhdf(path)
>>> s.times, len(s.mesh.cells[0].data) == m.n_tets
((0.0, 0.5), True)
>>> bool((s.step_mesh(1).point_data["p"] == m.density + 0.5).all())
True
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import meshio
import numpy as np
from meshio._vtk_common import meshio_to_vtk_type, vtk_to_meshio_type

from .._atomic import atomic_path
from ..errors import OutputError, ReadError

SUFFIXES = (".vtkhdf",)
# the newest VTKHDF major version read here (2.x: temporal, partitioned, PolyData...)
MAX_MAJOR = 2
INSTALL_HINT = "VTKHDF files need h5py: pip install h5py (or pip install 'gatun_py[vtkhdf]')"

# corner count of every fixed-size VTK cell type meshio names (polygons and polyhedra vary)
_CELL_NODES = {
    "vertex": 1, "line": 2, "triangle": 3, "quad": 4, "pixel": 4, "tetra": 4, "hexahedron": 8, "wedge": 6,
    "pyramid": 5, "penta_prism": 10, "hexa_prism": 12, "line3": 3, "triangle6": 6, "quad8": 8, "tetra10": 10,
    "hexahedron20": 20, "wedge15": 15, "pyramid13": 13, "quad9": 9, "hexahedron27": 27, "quad6": 6,
    "wedge12": 12, "wedge18": 18, "hexahedron24": 24, "triangle7": 7, "line4": 4,
}


def _h5py(reading: bool):
    try:
        import h5py  # optional dependency
    except ImportError:
        raise (ReadError if reading else OutputError)(INSTALL_HINT) from None
    return h5py


def is_vtkhdf(path) -> bool:
    """Whether ``path`` names a VTKHDF file by its extension."""
    return os.fspath(path).lower().endswith(SUFFIXES)


# -- writing -------------------------------------------------------------------------------------

def _parts(mesh):
    """(points, [(meshio type, (n, k) ids)], point_data, cell_data {name: [per block]}) of a
    TetMesh or a meshio.Mesh."""
    if hasattr(mesh, "tets") and hasattr(mesh, "user_point_data"):  # a TetMesh: its tets, its arrays
        return (np.asarray(mesh.points), [("tetra", np.asarray(mesh.tets))],
                {k: np.asarray(v) for k, v in mesh.user_point_data.items()}, {})
    if hasattr(mesh, "cells") and hasattr(mesh, "points"):
        cells = [(c.type, np.asarray(c.data)) for c in mesh.cells]
        return (np.asarray(mesh.points), cells, {k: np.asarray(v) for k, v in mesh.point_data.items()},
                {k: [np.asarray(b) for b in v] for k, v in mesh.cell_data.items()})
    raise OutputError(f"cannot write a {type(mesh).__name__} as VTKHDF: give a TetMesh or a meshio.Mesh")


def _topology(cells):
    """VTK's (types uint8, offsets int64, connectivity int64) of meshio-like cell blocks."""
    types, counts, conn = [], [], []
    for name, data in cells:
        if name not in meshio_to_vtk_type or name not in _CELL_NODES:
            raise OutputError(f"cannot write {name!r} cells as VTKHDF (fixed-size VTK cell types only)")
        data = data.reshape(len(data), -1)
        types.append(np.full(len(data), meshio_to_vtk_type[name], np.uint8))
        counts.append(np.full(len(data), data.shape[1], np.int64))
        conn.append(data.astype(np.int64, copy=False).reshape(-1))
    types = np.concatenate(types) if types else np.zeros(0, np.uint8)
    offsets = np.zeros(len(types) + 1, np.int64)
    if counts:
        np.cumsum(np.concatenate(counts), out=offsets[1:])
    return types, offsets, (np.concatenate(conn) if conn else np.zeros(0, np.int64))


def _dataset_name(name: str, kind: str) -> str:
    if not name or "/" in name or name in (".", ".."):
        raise OutputError(f"cannot write the {kind} array {name!r} as VTKHDF: HDF5 names hold no '/' "
                          "and cannot be empty")
    return name


def _check_rows(a: np.ndarray, n: int, what: str) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim == 0 or a.shape[0] != n:
        raise OutputError(f"cannot write {what} as VTKHDF: {a.shape[0] if a.ndim else 0} values for {n} rows")
    if a.dtype.kind not in "fiub":
        raise OutputError(f"cannot write {what} as VTKHDF: dtype {a.dtype} (numbers only)")
    return a.reshape(n, -1) if a.ndim > 2 else a


def write_vtkhdf(path, mesh, *, steps=None, force: bool = False, deflate: int = 0) -> None:
    """Write a mesh, or a series over one mesh, as a VTKHDF unstructured grid, atomically.

    Parameters
    ----------
    path : path-like
        The ``.vtkhdf`` file.
    mesh : TetMesh or meshio.Mesh
        The points and cells (a meshio.Mesh keeps its cell blocks and cell data), and the arrays
        of a file without ``steps``.
    steps : sequence of (float, dict, dict) or (float, dict, dict, array), optional
        ``(time, point_data, cell_data)`` of every step, over ``mesh``'s points and cells: written
        temporal (VTKHDF 2.0), the mesh once; a 4th item gives the step's own coordinates (a
        moving mesh: every step's points are written, the cells once). The mesh's own arrays that no step names are written
        once and shared by every step. Cell data: one array over all cells (blocks in order), or a
        list per block as in meshio.
    force : bool
        Overwrite ``path`` if it exists.
    deflate : int
        HDF5 deflate level 1-9 of the arrays (0: none, the fastest to write and read).
    """
    h5py = _h5py(reading=False)
    if not (isinstance(deflate, (int, np.integer)) and 0 <= deflate <= 9):
        raise OutputError(f"deflate must be a level in 0..9, got {deflate!r}")
    points, cells, point_data, cell_data = _parts(mesh)
    types, offsets, conn = _topology(cells)
    n_points, n_cells = len(points), len(types)
    block_rows = [len(d) for _, d in cells]

    def cells_array(v, name):
        v = np.concatenate([np.asarray(b) for b in v]) if isinstance(v, (list, tuple)) else np.asarray(v)
        return _check_rows(v, n_cells, f"cell array {name!r}")

    static_pd = {_dataset_name(k, "point"): _check_rows(v, n_points, f"point array {k!r}") for k, v in point_data.items()}
    static_cd = {_dataset_name(k, "cell"): cells_array(v, k) for k, v in cell_data.items()}
    steps = None if steps is None else list(steps)
    if steps is not None and not steps:
        raise OutputError("a VTKHDF series needs at least one step")
    kw = {"compression": "gzip", "compression_opts": int(deflate)} if deflate else {}

    def put(group, name, a):
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("="))
        if a.dtype == np.bool_:
            a = a.view(np.uint8)
        group.create_dataset(name, data=a, **(kw if a.size >= 1024 else {}))

    with atomic_path(path, force=force) as tmp, h5py.File(tmp, "w") as f:
        g = f.create_group("VTKHDF")
        g.attrs["Version"] = np.array([2 if steps is not None else 1, 0], np.int64)
        g.attrs["Type"] = np.bytes_(b"UnstructuredGrid")
        for name, v in (("NumberOfPoints", n_points), ("NumberOfCells", n_cells),
                        ("NumberOfConnectivityIds", len(conn))):
            g.create_dataset(name, data=np.array([v], np.int64))
        moved = _moved_points(steps, points) if steps is not None else None
        if moved is None:
            put(g, "Points", points.reshape(n_points, 3) if points.size else np.zeros((0, 3)))
        else:  # every step's coordinates, one after the other (Steps/PointOffsets); the cells once
            put(g, "Points", np.concatenate(moved))
        put(g, "Types", types)
        put(g, "Offsets", offsets)
        put(g, "Connectivity", conn)
        pg, cg = g.create_group("PointData"), g.create_group("CellData")
        field = {_dataset_name(k, "field"): np.asarray(v) for k, v in (getattr(mesh, "field_data", None) or {}).items()}
        if field:  # meshio's field data (gmsh's physical names: [tag, dimension]), numbers only
            fg = g.create_group("FieldData")
            for name, a in field.items():
                if a.dtype.kind not in "fiub":
                    raise OutputError(f"cannot write the field array {name!r} as VTKHDF: dtype {a.dtype} (numbers only)")
                fg.create_dataset(name, data=a)
        if steps is None:
            for name, a in static_pd.items():
                put(pg, name, a)
            for name, a in static_cd.items():
                put(cg, name, a)
            return
        _write_steps(g, put, steps, static_pd, static_cd, n_points, n_cells, cells_array, block_rows)
        if moved is not None:
            del g["Steps/PointOffsets"]
            g["Steps"].create_dataset("PointOffsets", data=np.arange(len(steps), dtype=np.int64) * n_points)


def _moved_points(steps, points):
    """Every step's coordinates when some step gives its own (a 4th item) other than ``points``,
    else None."""
    own = [st[3] if isinstance(st, (tuple, list)) and len(st) == 4 and st[3] is not None else None for st in steps]
    if all(p is None or _same_bits(p, points) for p in own):
        return None
    out = []
    for i, p in enumerate(own):
        p = points if p is None else np.asarray(p)
        if p.shape != points.shape or p.dtype != points.dtype:
            raise OutputError(f"step {i}'s points are {p.dtype} {p.shape}, the mesh's {points.dtype} {points.shape}")
        out.append(p.reshape(len(points), 3))
    return out


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _write_steps(g, put, steps, static_pd, static_cd, n_points, n_cells, cells_array, block_rows):
    n = len(steps)
    times = []
    per_pd, per_cd = {}, {}
    for i, step in enumerate(steps):
        try:
            t, pd, cd = step[:3] if isinstance(step, (tuple, list)) and len(step) == 4 else step
            t = float(t)
        except (TypeError, ValueError):
            raise OutputError(f"step {i}: give (time, point_data, cell_data[, points])") from None
        times.append(t)
        for store, data, kind in ((per_pd, pd or {}, "point"), (per_cd, cd or {}, "cell")):
            if i and set(data) != set(store):
                raise OutputError(f"step {i} has other {kind} arrays than step 0: {sorted(data)} vs {sorted(store)}")
            for k, v in data.items():
                a = (_check_rows(v, n_points, f"point array {k!r} of step {i}") if kind == "point"
                     else cells_array(v, k))
                if i and (a.dtype != store[k][0].dtype or a.shape[1:] != store[k][0].shape[1:]):
                    raise OutputError(f"{kind} array {k!r} changes dtype or components at step {i}")
                store.setdefault(_dataset_name(k, kind), []).append(a)
    s = g.create_group("Steps")
    s.attrs["NSteps"] = np.int64(n)
    s.create_dataset("Values", data=np.asarray(times, np.float64))
    zeros = np.zeros(n, np.int64)
    for name in ("PartOffsets", "PointOffsets", "CellOffsets", "ConnectivityIdOffsets"):
        s.create_dataset(name, data=zeros)  # the mesh once: every step reads partition 0
    s.create_dataset("NumberOfParts", data=np.ones(n, np.int64))
    for group, offs_name, per, static, rows in ((g["PointData"], "PointDataOffsets", per_pd, static_pd, n_points),
                                                (g["CellData"], "CellDataOffsets", per_cd, static_cd, n_cells)):
        offs = s.create_group(offs_name)
        for name, arrays in per.items():
            put(group, name, np.concatenate(arrays))
            offs.create_dataset(name, data=np.arange(n, dtype=np.int64) * rows)
        for name, a in static.items():
            if name not in per:
                put(group, name, a)
                offs.create_dataset(name, data=zeros)


# -- reading -------------------------------------------------------------------------------------

@dataclass
class VtkHdfSeries:
    """A VTKHDF unstructured grid as read: the mesh of its first step and every step's arrays.

    Attributes
    ----------
    mesh : meshio.Mesh
        Points, cell blocks and arrays of step 0 (of the only step of a file without time).
    times : tuple of float
        The time values (``(0.0,)`` for a file without steps).
    notes : list of str
        What the reader did (partitions concatenated, a changing mesh...).
    """

    mesh: meshio.Mesh
    times: tuple
    notes: list = field(default_factory=list)
    path: str = ""
    static_mesh: bool = True

    @property
    def n_steps(self) -> int:
        return len(self.times)

    def step_mesh(self, step: int) -> meshio.Mesh:
        """The mesh and arrays of ``step`` (0-based, negative from the end)."""
        if not -self.n_steps <= step < self.n_steps:
            raise ReadError(f"{self.path}: no time step {step}; the file has {self.n_steps} (0..{self.n_steps - 1})")
        return _read_step(self.path, step % self.n_steps)[0]

    def step_arrays(self, step: int) -> tuple[dict, dict]:
        """``(point_data, cell_data)`` of ``step`` (cell data as meshio's per-block lists)."""
        m = self.step_mesh(step)
        return m.point_data, m.cell_data


def read_vtkhdf(path, *, step: int | None = 0) -> VtkHdfSeries:
    """Read a VTKHDF unstructured grid (temporal and partitioned ones too).

    ``step``: the step whose mesh and arrays are in ``.mesh`` (0-based, negative from the end).

    Raises
    ------
    ReadError
        Missing h5py, not an HDF5 file, not a VTKHDF unstructured grid, a newer VTKHDF version,
        or inconsistent offsets.
    """
    path = os.fspath(path)
    times, notes, static = _read_times(path)
    n = len(times)
    step = 0 if step is None else int(step)
    if not -n <= step < n:
        raise ReadError(f"{path}: no time step {step}; the file has {n} (0..{n - 1})")
    mesh, more = _read_step(path, step % n)
    return VtkHdfSeries(mesh, times, notes + more, path, static)


def vtkhdf_partitions(path, *, step: int | None = None) -> tuple[int, int, int]:
    """``(partitions of the step, the step, steps)`` of a VTKHDF unstructured grid: the step is
    ``step`` (0-based, negative from the end), by default the last, as :func:`read_vtkhdf` reads it
    through :func:`~gatun_py.mesh.read_mesh`."""
    path = os.fspath(path)
    times, _, _ = _read_times(path)
    n = len(times)
    k = -1 if step is None else int(step)
    if not -n <= k < n:
        raise ReadError(f"{path}: no time step {k}; the file has {n} (0..{n - 1})")
    k %= n
    f, g = _open(path)
    with f:
        try:
            s = g["Steps"] if "Steps" in g else None
            n_parts = _step_index(s, "NumberOfParts", k, len(np.asarray(g["NumberOfPoints"]).reshape(-1))
                                  if s is None else 1)
        except (KeyError, IndexError, ValueError, TypeError) as e:
            raise ReadError(f"{path}: inconsistent VTKHDF unstructured grid ({type(e).__name__}: {e})") from None
    return int(n_parts), k, n


def read_vtkhdf_partition(path, part: int, *, step: int | None = None) -> meshio.Mesh:
    """Partition ``part`` of a step (default the last) alone, with its own point numbering, as a
    solver's rank wrote it: points on its seams with other partitions are its own copies. Only that
    partition's slices of the file are read."""
    path = os.fspath(path)
    _, k, _ = vtkhdf_partitions(path, step=step)
    return _read_step(path, k, int(part))[0]


def _open(path):
    h5py = _h5py(reading=True)
    if not os.path.exists(path):
        raise ReadError(f"no such file: {path}")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise ReadError(f"{path}: not an HDF5 file ({e})") from None
    if "VTKHDF" not in f:
        f.close()
        raise ReadError(f"{path}: an HDF5 file without a VTKHDF group (not written as VTKHDF)")
    g = f["VTKHDF"]
    try:
        version = [int(v) for v in np.ravel(g.attrs.get("Version", [1, 0]))]
        kind = g.attrs.get("Type", b"")
        kind = kind.decode("ascii", "replace") if isinstance(kind, bytes) else str(kind)
    except (TypeError, ValueError):
        f.close()
        raise ReadError(f"{path}: malformed VTKHDF attributes") from None
    if version and version[0] > MAX_MAJOR:
        f.close()
        raise ReadError(f"{path}: VTKHDF version {'.'.join(map(str, version))} is newer than this reader "
                        f"knows ({MAX_MAJOR}.x)")
    if kind.strip("\x00 ") != "UnstructuredGrid":
        f.close()
        raise ReadError(f"{path}: a VTKHDF {kind.strip() or 'dataset without a Type'}, not an UnstructuredGrid "
                        "(volume meshes only)")
    return f, g


def _read_times(path):
    f, g = _open(path)
    with f:
        if "Steps" not in g:
            return (0.0,), [], True
        s = g["Steps"]
        try:
            n = int(s.attrs.get("NSteps", len(s["Values"])))
            times = tuple(float(t) for t in np.asarray(s["Values"][:n], np.float64))
            static = all(not np.any(np.asarray(s[k][:n])) for k in ("PointOffsets", "CellOffsets",
                                                                    "ConnectivityIdOffsets") if k in s)
        except (KeyError, ValueError, TypeError) as e:
            raise ReadError(f"{path}: malformed Steps group ({e})") from None
        if n < 1 or len(times) != n:
            raise ReadError(f"{path}: Steps holds {len(times)} time values for NSteps = {n}")
        notes = [f"temporal VTKHDF: {n} steps" + ("" if static else " (the mesh changes between steps)")]
        return times, notes, static


def _step_index(s, name, step, default=0):
    if s is None or name not in s:
        return default
    a = np.asarray(s[name][step])
    return int(a.reshape(-1)[0])


def _read_step(path, step, part=None):
    f, g = _open(path)
    with f:
        try:
            return _read_step_open(path, g, step, part)
        except (KeyError, IndexError, ValueError, TypeError) as e:
            raise ReadError(f"{path}: inconsistent VTKHDF unstructured grid ({type(e).__name__}: {e})") from None


def _read_step_open(path, g, step, part=None):
    """The mesh of ``step``: all its partitions concatenated, or only partition ``part`` (0-based
    within the step) with its own numbering, read without the others."""
    s = g["Steps"] if "Steps" in g else None
    n_pts_all = np.asarray(g["NumberOfPoints"], np.int64).reshape(-1)
    n_cells_all = np.asarray(g["NumberOfCells"], np.int64).reshape(-1)
    n_conn_all = np.asarray(g["NumberOfConnectivityIds"], np.int64).reshape(-1)
    part0 = _step_index(s, "PartOffsets", step)
    n_parts = _step_index(s, "NumberOfParts", step, len(n_pts_all) if s is None else 1)
    pt0 = _step_index(s, "PointOffsets", step)
    cell0 = _step_index(s, "CellOffsets", step)
    conn0 = _step_index(s, "ConnectivityIdOffsets", step)
    if n_parts < 1 or part0 < 0 or part0 + n_parts > len(n_pts_all):
        raise ReadError(f"{path}: step {step} names partitions {part0}..{part0 + n_parts - 1} of {len(n_pts_all)}")
    pshift = cshift = 0  # the points and cells of the step's partitions before ``part``
    if part is not None:
        if not 0 <= part < n_parts:
            raise ReadError(f"{path}: no partition {part} at step {step}; it has {n_parts} (0..{n_parts - 1})")
        before = slice(part0, part0 + part)
        pshift, cshift = int(n_pts_all[before].sum()), int(n_cells_all[before].sum())
        pt0, cell0, conn0 = pt0 + pshift, cell0 + cshift, conn0 + int(n_conn_all[before].sum())
        part0, n_parts = part0 + part, 1
    off_start = cell0 + part0  # every partition has its cells + 1 offsets
    parts = range(part0, part0 + n_parts)
    npts, ncells, nconn = (int(a[parts.start:parts.stop].sum()) for a in (n_pts_all, n_cells_all, n_conn_all))
    points = np.asarray(g["Points"][pt0:pt0 + npts])
    types = np.asarray(g["Types"][cell0:cell0 + ncells])
    conn_raw = np.asarray(g["Connectivity"][conn0:conn0 + nconn]).astype(np.int64, copy=False)
    offs_raw = np.asarray(g["Offsets"][off_start:off_start + ncells + n_parts]).astype(np.int64, copy=False)
    if len(points) != npts or len(types) != ncells or len(conn_raw) != nconn or len(offs_raw) != ncells + n_parts:
        raise ReadError(f"{path}: step {step}'s arrays are shorter than its sizes say (truncated file?)")
    # one connectivity over all partitions: each partition's ids shifted by the points before it
    counts = np.empty(ncells, np.int64)
    conn = np.empty(nconn, np.int64)
    c = o = p = k = 0
    for part in parts:
        nc, nk, npp = int(n_cells_all[part]), int(n_conn_all[part]), int(n_pts_all[part])
        po = offs_raw[o:o + nc + 1]
        if po[0] != 0 or po[-1] != nk or np.any(np.diff(po) < 0):
            raise ReadError(f"{path}: partition {part}'s cell offsets do not match its connectivity")
        counts[c:c + nc] = np.diff(po)
        ids = conn_raw[k:k + nk]
        if nk and (ids.min() < 0 or ids.max() >= npp):
            raise ReadError(f"{path}: partition {part} refers to a point it does not hold")
        conn[k:k + nk] = ids + p
        c, o, k, p = c + nc, o + nc + 1, k + nk, p + npp
    notes = [f"{n_parts} partitions concatenated (points on their seams stay duplicated)"] if n_parts > 1 else []
    blocks, runs = _cell_blocks(path, types, counts, conn)
    point_data = {}
    cell_data = {}
    for group, store, base, rows, kind in (("PointData", point_data, pt0, npts, "point"),
                                           ("CellData", cell_data, cell0, ncells, "cell")):
        if group not in g:
            continue
        offs = s.get(f"{group}Offsets") if s is not None else None
        for name, ds in g[group].items():
            if not hasattr(ds, "shape"):
                continue
            start = base if offs is None or name not in offs else \
                int(np.asarray(offs[name][step]).reshape(-1)[0]) + (pshift if kind == "point" else cshift)
            a = np.asarray(ds[start:start + rows])
            if len(a) != rows:
                raise ReadError(f"{path}: {kind} array {name!r} has {len(a)} values at step {step}, not {rows}")
            store[name] = a if kind == "point" else [a[i:j] for i, j in runs]
    field_data = {name: np.asarray(ds) for name, ds in g["FieldData"].items() if hasattr(ds, "shape")} \
        if "FieldData" in g else {}
    return meshio.Mesh(points, blocks, point_data=point_data, cell_data=cell_data, field_data=field_data), notes


def _cell_blocks(path, types, counts, conn):
    """meshio cell blocks of runs of one VTK type, and each run's (start, stop) in cell order."""
    blocks, runs = [], []
    if not len(types):
        return blocks, runs
    cut = np.flatnonzero(np.diff(types.astype(np.int64))) + 1
    starts = np.concatenate([[0], cut])
    stops = np.concatenate([cut, [len(types)]])
    first = np.concatenate([[0], np.cumsum(counts)])
    for a, b in zip(starts.tolist(), stops.tolist()):
        name = vtk_to_meshio_type.get(int(types[a]))
        k = _CELL_NODES.get(name)
        if k is None:
            raise ReadError(f"{path}: VTK cell type {int(types[a])} ({name or 'unknown'}) cannot be read "
                            "(fixed-size cell types only)")
        if np.any(counts[a:b] != k):
            raise ReadError(f"{path}: {name} cells with other than {k} points")
        blocks.append(meshio.CellBlock(name, conn[first[a]:first[b]].reshape(b - a, k)))
        runs.append((a, b))
    return blocks, runs
