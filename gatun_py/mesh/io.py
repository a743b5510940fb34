"""Reading any supported mesh file into a validated :class:`TetMesh`, and writing one out.

Supported inputs: every meshio format that carries volume cells (tets, hexahedra, wedges,
pyramids, and their quadratic variants reduced to their corners), and single-block PLOT3D grids.
``.tetc`` files are read by :mod:`gatun_py.codec`.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import warnings
from pathlib import Path
from urllib.parse import unquote

import meshio
import numpy as np
from meshio import _helpers

from .._atomic import atomic_path
from ..errors import MeshError, OptionError, OutputError, ReadError
from ..read_options import ReadOptions  # noqa: F401  (the readers' record; re-exported where it was)
from . import plot3d
from .cells import Cells, check_cell_type, check_cells
from .model import NO_SCALAR, TetMesh, signed_volumes
from .split import orient_positive, split_hexes_two_colour, split_min_id_star, two_colour
from .validate import MeshReport, validate_tets
from .cells import VOLUME_CELLS  # meshio volume cell type -> (linear type, corners)
from .exodus import EXODUS_SUFFIXES, read_exodus
from .vtk_reader import INSTALL_HINT, VTK_SUFFIXES, read_with_vtk, vtk_available
from .vtkhdf import is_vtkhdf, read_vtkhdf, write_vtkhdf



# meshio formats that hold linear tetrahedra with point data (written by write_mesh)
TET_FORMATS = {"vtu", "vtk", "gmsh", "xdmf", "medit", "exodus", "abaqus", "avsucd", "flac3d", "h5m", "med",
               "nastran", "permas", "su2", "tetgen", "ugrid", "dolfin-xml", "cgns", "netgen", "mdpa", "hmf"}
TET_EXTENSIONS = (".vtu", ".vtk", ".msh", ".xdmf", ".mesh", ".exo", ".inp", ".avs", ".f3grid", ".med", ".bdf",
                  ".su2", ".ugrid", ".xml", ".vol", ".mdpa", ".vtkhdf")


def read_mesh(path, *, scalar: str | None = None, q_file=None, q_var: str = "density",
              cell_to_point: bool = False, refine: int = 1, time_step: int | None = None) -> tuple[TetMesh, MeshReport]:
    """Read, split into tets, validate.

    Parameters
    ----------
    path : path-like
        Any meshio volume format, or a PLOT3D XYZ grid.
    scalar : str, optional
        Point-data array to use as density. Without it: the only scalar array, else an error that
        lists the names.
    q_file : path-like, optional
        PLOT3D Q file (default: the ``...q...`` file beside an ``...xyz...`` grid).
    q_var : str
        Which PLOT3D quantity to use (see :data:`plot3d.Q_VARIABLES`).
    cell_to_point : bool
        Allow a cell-data scalar, averaged to the points weighted by cell volume.
    refine : int
        PLOT3D only: refine the grid trilinearly by this factor per axis before splitting
        (:func:`plot3d.refine_grid`; interpolated scalar, for scale tests). Default 1: as stored.
    time_step : int, optional
        Exodus only: which time step's nodal variables to read (0-based, negative from the end;
        default the last).

    Raises
    ------
    ReadError, MeshError, OptionError
    """
    path = Path(path)
    if not path.exists():
        raise ReadError(f"no such file: {path}")
    if path.is_dir():
        raise ReadError(f"{path} is a directory, not a mesh file")
    if time_step is not None and path.suffix.lower() not in EXODUS_SUFFIXES and not is_vtkhdf(path):
        raise OptionError(f"{path}: a time step applies to Exodus ({', '.join(EXODUS_SUFFIXES)}) and VTKHDF "
                          "(.vtkhdf) files only")
    if is_vtkhdf(path):  # temporal: the last step unless told, as for Exodus
        series = read_vtkhdf(path, step=-1 if time_step is None else time_step)
        mesh, report = mesh_from_meshio(series.mesh, scalar=scalar, cell_to_point=cell_to_point, source=str(path))
        if series.n_steps > 1:
            k = (-1 if time_step is None else time_step) % series.n_steps
            series.notes.append(f"time step {k} of 0..{series.n_steps - 1} read (t = {series.times[k]:g})")
        report.notes[:0] = series.notes
        return mesh, report
    if path.suffix.lower() in EXODUS_SUFFIXES:
        m, notes = read_exodus(path, time_step=time_step)
        mesh, report = mesh_from_meshio(m, scalar=scalar, cell_to_point=cell_to_point, source=str(path))
        report.notes[:0] = notes
        return mesh, report
    if plot3d.is_plot3d_input(path, q_file):
        return _read_plot3d(path, q_file, q_var, refine)
    if refine != 1:
        raise OptionError(f"{path}: refinement needs a PLOT3D grid input (structured), not a {path.suffix or 'mesh'} file")
    if path.suffix.lower() in plot3d.PLOT3D_SUFFIXES:
        raise ReadError(f"{path}: not a PLOT3D grid nor a mesh format known by extension")
    return _read_meshio(path, scalar, cell_to_point)


def _read_plot3d(path: Path, q_file, q_var: str, refine: int = 1) -> tuple[TetMesh, MeshReport]:
    """A PLOT3D grid with everything its Q file holds: the five Q planes as point arrays (``q_var``
    the default scalar, computed and added when it is a derived quantity), the free-stream header
    as field data, the grid's hexahedra as the cells."""
    grid = plot3d.read_xyz(path)
    notes = []
    if q_file is None:
        q_file = plot3d.find_q_file(path)
        if q_file is None:
            raise ReadError(f"{path} is a PLOT3D grid: give its solution file (the Q file; none found beside it)")
        notes.append(f"scalar from {Path(q_file).name}")
    if q_var not in plot3d.Q_VARIABLES:
        raise ReadError(f"unknown Q variable {q_var!r}; choose one of {', '.join(plot3d.Q_VARIABLES)}")
    solution = plot3d.read_q_file(q_file, grid.dims)
    point_data = {k: solution.planes[i] for i, k in enumerate(plot3d.Q_STORED)}
    if q_var not in point_data:
        point_data[q_var] = plot3d.q_variable(solution.planes, q_var)
        notes.append(f"{q_var!r} computed from the Q variables and stored beside them as the default scalar")
    xyz, dims = grid.xyz, grid.dims
    keep = None
    if grid.iblank is not None:
        keep = (grid.iblank[plot3d.grid_hexes(dims)[0]] != 0).all(axis=1)
        if not keep.all():
            notes.append(f"{int((~keep).sum())} cells dropped by IBLANK")
    if refine != 1:
        xyz, dens, fine = plot3d.refine_grid(xyz, point_data[q_var], dims, refine)
        point_data = {q_var: dens}  # interpolated, not data: only the scalar the refinement is for
        if keep is not None:
            keep = plot3d.refine_cell_mask(keep, dims, refine)
        notes.append(f"grid refined {refine}x per axis ({'x'.join(map(str, dims))} -> "
                     f"{'x'.join(map(str, fine))}), scalar trilinearly interpolated, the other Q variables "
                     "not kept")
        dims = fine
    hexes, colour = plot3d.grid_hexes(dims)
    if keep is not None:
        hexes = hexes[keep]
    tets = orient_positive(xyz, split_hexes_two_colour(hexes, colour))
    mesh, report = _validated(str(path), xyz, None, tets, q_var, point_data)
    report.notes += notes
    cells = Cells([("hexahedron", hexes)], np.repeat(np.arange(len(hexes), dtype=np.int64), 5),
                  field_data=dict(solution.free_stream))
    check_cells(cells, len(xyz), str(path))
    report.cells = cells
    return mesh, report


def _read_meshio(path: Path, scalar: str | None, cell_to_point: bool) -> tuple[TetMesh, MeshReport]:
    m = _meshio_read(path)
    if path.suffix.lower() == ".vtk":
        _unescape_names(m)
    return mesh_from_meshio(m, scalar=scalar, cell_to_point=cell_to_point, source=str(path))


def _unescape_names(m) -> None:
    """VTK's legacy writer percent-escapes array names (``Nodal Stress`` -> ``Nodal%20Stress``) and
    meshio keeps them escaped: give them back their own names (unless two would then collide)."""
    for data in (m.point_data, m.cell_data):
        names = {k: unquote(k) for k in data}
        if len(set(names.values())) == len(names) and any(k != v for k, v in names.items()):
            for k in list(data):
                data[names[k]] = data.pop(k)


def _prefer_gmsh(formats):
    """``.msh`` is both ANSYS and Gmsh; Gmsh is by far the more common, and what we write."""
    return sorted(formats, key=lambda f: f != "gmsh")


def _meshio_read(path: Path):
    """meshio.read without its habit of printing and calling sys.exit on unreadable files."""
    try:
        formats = _helpers._filetypes_from_path(path)
    except (KeyError, ValueError, meshio.ReadError):
        if path.suffix.lower() in VTK_SUFFIXES:  # .vts, .vtr, .pvtu: VTK's own formats, meshio has no reader
            if vtk_available():
                return read_with_vtk(path)
            raise ReadError(f"cannot read {path}: {INSTALL_HINT}") from None
        raise ReadError(f"cannot read {path}: unknown file extension {path.suffix!r} "
                        f"(mesh formats: .vtu .vtk .msh .mesh .xdmf .exo .med .inp ...; PLOT3D: .bin .xyz)") from None
    reasons = []
    for fmt in _prefer_gmsh(formats):
        reader = _helpers.reader_map.get(fmt)
        if reader is None:
            continue
        try:
            with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
                warnings.simplefilter("ignore")
                return reader(str(path))
        except MemoryError:
            raise
        except Exception as e:  # meshio readers raise many unrelated types on malformed input
            reasons.append(f"{type(e).__name__}: {e}" if str(e) else "malformed file")
        except SystemExit:
            reasons.append("reader gave up")
    why = reasons[0] if reasons else "no reader for this extension"
    if path.suffix.lower() in VTK_SUFFIXES:
        if vtk_available():
            try:
                return read_with_vtk(path)
            except ReadError:
                raise ReadError(f"cannot read {path} as {'/'.join(formats)}: {why}; "
                                "VTK's reader could not read it either") from None
        raise ReadError(f"cannot read {path} as {'/'.join(formats)}: {why}; {INSTALL_HINT}")
    raise ReadError(f"cannot read {path} as {'/'.join(formats)}: {why}")


def mesh_from_meshio(m, *, scalar: str | None = None, cell_to_point: bool = False,
                     source: str = "mesh") -> tuple[TetMesh, MeshReport]:
    """Turn a ``meshio.Mesh`` into a validated :class:`TetMesh` (see :func:`read_mesh`)."""
    points = np.asarray(m.points)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise ReadError(f"{source}: points have shape {points.shape}")
    if points.shape[1] == 2:
        raise ReadError(f"{source}: a 2-D mesh has no volume cells")
    notes = []
    pts = _coordinates(points, notes)

    blocks = []  # (linear type, corner ids, block index)
    other = set()
    for cb in m.cells:
        check_cell_type(cb.type, source)  # polyhedra, polygons, unknown types: by name
    for bi, cb in enumerate(m.cells):
        if cb.type in VOLUME_CELLS:
            lin, k = VOLUME_CELLS[cb.type]
            data = np.asarray(cb.data)[:, :k].astype(np.int64, copy=False)  # meshio's own array when int64
            blocks.append((lin, data, bi))
        else:
            other.add(cb.type)
    if not blocks:
        kinds = ", ".join(sorted(other)) or "none"
        raise MeshError(f"{source}: no volume cells (cell types present: {kinds})")
    if other:
        notes.append(f"non-volume cells kept as given (not rendered): {', '.join(sorted(other))}")

    n = len(points)
    for lin, data, _ in blocks:
        bad = (data < 0) | (data >= n)
        if bad.any():
            i = int(np.flatnonzero(bad.any(axis=1))[0])
            nbad = int(bad.any(axis=1).sum())
            raise MeshError(f"{source}: {lin} cell {i} refers to vertex {int(data[i][bad[i]][0])} but the mesh has "
                            f"{n} points; {nbad} cell{'s' if nbad > 1 else ''} affected")

    types = {b[0] for b in blocks}
    tet_chunks, cell_of_tet = [], []
    colour = None
    if types <= {"hexahedron", "tetra"} and "hexahedron" in types:
        colour = two_colour(np.concatenate([d for t, d, _ in blocks if t == "hexahedron"]), n)
        if colour is None:
            notes.append("hex graph not two-colourable: min-id 6-tet split")
    offset = 0
    for lin, data, bi in blocks:
        if lin == "tetra":
            tt = data
            per = 1
        elif lin == "hexahedron" and colour is not None:
            tt = split_hexes_two_colour(data, colour)
            per = 5
        else:
            tt = split_min_id_star(data, lin)
            per = len(tt) // max(len(data), 1)
        if lin != "tetra":  # our own split: orient it; only the file's own tets count as re-oriented
            tt = orient_positive(pts, tt)
        tet_chunks.append(tt)
        cell_of_tet.append((bi, offset, per, len(data)))
        offset += len(data)
    tets = tet_chunks[0] if len(tet_chunks) == 1 else np.concatenate(tet_chunks)  # no copy of one block

    point_data = _point_arrays(m.point_data, n, notes)
    cell_names = sorted(m.cell_data)
    if cell_to_point:  # every cell array is carried, averaged to the points
        for cname in cell_names:
            key = cname if cname not in point_data else f"{cname} (cell)"
            point_data[key] = _cell_to_point(m, cname, pts, tet_chunks, cell_of_tet, n)
            if key != cname:
                notes.append(f"cell array {cname!r} averaged to the points as {key!r}")
    density, name = _choose_scalar(m, n, scalar, cell_to_point, point_data, source)
    others = [k for k, v in point_data.items() if v.ndim == 1 and k != name]
    if scalar is None and name != NO_SCALAR and others and not cell_to_point:
        notes.append(f"default scalar {name!r}, the first of {len(others) + 1} point scalars "
                     f"(scalar= chooses another: {', '.join(map(repr, others))})")
    if name == NO_SCALAR:
        hint = (f"; its cell data ({', '.join(cell_names)}) can be averaged to the points (cell-to-point)"
                if cell_names and not cell_to_point else "")
        notes.append(f"no point scalar: the mesh is kept without one (renders show its shape as a uniform "
                     f"medium){hint}")
    mesh, report = _validated(source, pts, density, tets, name, point_data)
    report.notes += notes
    if not cell_to_point:
        report.cell_arrays = cell_names
    report.cells = _cells_as_given(m, cell_of_tet, len(tets), n, source)
    return mesh, report


def _cells_as_given(m, cell_of_tet, n_tets: int, n_points: int, source: str) -> Cells:
    """The mesh's blocks, cell data, field data and sets as given, with each tet's cell."""
    tet_cell = np.empty(n_tets, np.int64)
    at = 0
    for _, first, per, ncell in cell_of_tet:
        tet_cell[at:at + per * ncell] = np.repeat(np.arange(first, first + ncell, dtype=np.int64), per)
        at += per * ncell
    blocks = [(cb.type, np.asarray(cb.data).astype(np.int64, copy=False)) for cb in m.cells]
    cell_data = {str(k): [np.asarray(a) for a in v] for k, v in m.cell_data.items()}
    cell_sets = {str(k): [None if a is None else np.asarray(a) for a in v]
                 for k, v in (getattr(m, "cell_sets", None) or {}).items()}
    point_sets = {str(k): np.asarray(v) for k, v in (getattr(m, "point_sets", None) or {}).items()}
    cells = Cells(blocks, tet_cell, cell_data, dict(getattr(m, "field_data", None) or {}), point_sets, cell_sets)
    check_cells(cells, n_points, source)
    return cells


def _coordinates(points: np.ndarray, notes: list) -> np.ndarray:
    """float32 and float64 coordinates as they are; other dtypes in the float that holds them."""
    if points.dtype.kind == "f" and points.dtype.itemsize in (4, 8):
        return points.astype(points.dtype.newbyteorder("="))  # legacy VTK is big endian
    if points.dtype == np.float16:
        return points.astype(np.float32)
    out = points.astype(np.float64)
    with np.errstate(invalid="ignore"):
        changed = int((out.astype(points.dtype) != points)[np.isfinite(out)].sum())
    if changed:
        notes.append(f"{changed} coordinates rounded from {points.dtype} to float64")
    return out


def _point_arrays(data: dict, n: int, notes: list) -> dict:
    """Every numeric point array as (n,) or (n, k) in its own dtype; a note for anything skipped."""
    out = {}
    for k, v in data.items():
        a = np.asarray(v)
        if a.ndim == 0 or a.shape[0] != n:
            notes.append(f"point array {k!r} skipped: shape {a.shape} does not match {n} points")
            continue
        if a.dtype.kind not in "fiub" or a.dtype.itemsize > 8:
            notes.append(f"point array {k!r} skipped: dtype {a.dtype} cannot be stored (floats and integers only)")
            continue
        if a.ndim > 2:
            notes.append(f"point array {k!r} of shape {a.shape} stored as {a.shape[0]} x {a[0].size} components")
            a = a.reshape(n, -1)
        out[str(k)] = a.reshape(-1) if a.ndim == 2 and a.shape[1] == 1 else a
    return out


def _validated(source, points, density, tets, name, point_data=None):
    try:
        return validate_tets(points, density, tets, scalar_name=name, point_data=point_data)
    except MeshError as e:
        raise MeshError(f"{source}: {e}") from None


def _choose_scalar(m, n, scalar, cell_to_point, point_data, source):
    """(None, name) of the default scalar among the point arrays (cell arrays already averaged in)."""
    cell_names = set(m.cell_data) if cell_to_point else set()
    point_scalars = {k: v for k, v in point_data.items() if v.ndim == 1 and k not in cell_names}
    if scalar is not None:
        if scalar in point_data and point_data[scalar].ndim == 1:
            return None, scalar
        if scalar in point_data:
            raise ReadError(f"{source}: {scalar!r} has {point_data[scalar].shape[1]} components; the default "
                            "scalar must be one value per point (a vector's component is chosen at render time)")
        if scalar in m.cell_data:
            raise ReadError(f"{source}: {scalar!r} is cell data; it can be used only averaged to the points "
                            "(cell-to-point)")
        names = sorted(point_scalars) + [f"{k} (cell data)" for k in sorted(m.cell_data) if k not in point_data]
        raise ReadError(f"{source}: no point scalar named {scalar!r}; available: {', '.join(names) or 'none'}")
    if cell_to_point:
        cell_names = sorted(m.cell_data)
        if len(cell_names) == 1 and point_data[cell_names[0]].ndim == 1:
            return None, cell_names[0]
        if len(cell_names) > 1:
            raise ReadError(f"{source}: several cell arrays, choose the scalar by name: {', '.join(cell_names)}")
    if len(point_scalars) == 1:
        (name, _), = point_scalars.items()
        return None, name
    if len(point_scalars) > 1:  # the first, as written; the reader's notes say so
        return None, next(iter(point_scalars))
    # no scalar at all: the mesh is kept without one (zeros under NO_SCALAR, never written back)
    return np.zeros(n, np.float32), NO_SCALAR


def _cell_to_point(m, name, points, tet_chunks, cell_of_tet, n):
    """Volume-weighted average of a cell array (scalar or vector) onto the points, as float64."""
    acc = None
    w = np.zeros(n)
    for (bi, _, per, ncell), tt in zip(cell_of_tet, tet_chunks):
        vals = np.asarray(m.cell_data[name][bi])
        if vals.dtype.kind not in "fiub" or vals.shape[:1] != (ncell,):
            raise ReadError(f"cell data {name!r} cannot be averaged (dtype {vals.dtype}, shape {vals.shape})")
        vals = vals.reshape(ncell, -1).astype(np.float64)
        if acc is None:
            acc = np.zeros((n, vals.shape[1]))
        elif vals.shape[1] != acc.shape[1]:
            raise ReadError(f"cell data {name!r} has a different number of components per block")
        vol = np.abs(signed_volumes(points, tt))
        per_tet = np.repeat(vals, per, axis=0)[: len(tt)]
        for c in range(4):
            np.add.at(acc, tt[:, c], vol[:, None] * per_tet)
            np.add.at(w, tt[:, c], vol)
    if acc is None:
        acc = np.zeros((n, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(w[:, None] > 0, acc / np.where(w > 0, w, 1)[:, None], 0.0)
    return out[:, 0] if out.shape[1] == 1 else out


def mesh_output_format(path) -> str:
    """The meshio format a tet mesh is written in for this file name; :class:`OutputError` listing the
    choices when the extension is unknown or names a format that holds no tetrahedra (STL, PLY, OBJ)."""
    path = Path(path)
    if is_vtkhdf(path):
        return "vtkhdf"
    try:
        fmt = _prefer_gmsh(_helpers._filetypes_from_path(path))[0]
    except Exception:
        fmt = None
    if path.suffix.lower() == ".tetc":
        raise OutputError(f"{path.name}: decompress and convert write a mesh file, not a .tetc file (tetc compress "
                          "makes those); "
                          f"name it with a mesh format's extension: {', '.join(TET_EXTENSIONS)}")
    if fmt not in TET_FORMATS:
        raise OutputError(f"cannot write a tet mesh as {path.name!r}: "
                          f"{'that format holds no tetrahedra' if fmt else 'unknown extension'}; "
                          f"use one of {', '.join(TET_EXTENSIONS)}")
    return fmt


def to_meshio(mesh: TetMesh, cells: Cells | None = None) -> meshio.Mesh:
    """A ``meshio.Mesh`` of ``mesh``'s points and point arrays, with the cells as given (blocks,
    cell arrays, field data, sets, in ``mesh``'s point ids) or else its tets as one block."""
    point_data = {name: np.asarray(a) for name, a in mesh.user_point_data.items()}
    if cells is None:
        return meshio.Mesh(np.asarray(mesh.points), [("tetra", np.asarray(mesh.tets))], point_data=point_data)
    return meshio.Mesh(np.asarray(mesh.points), [(t, d) for t, d in cells.blocks], point_data=point_data,
                       cell_data={k: list(v) for k, v in cells.cell_data.items()},
                       field_data=dict(cells.field_data), point_sets=dict(cells.point_sets),
                       cell_sets={k: list(v) for k, v in cells.cell_sets.items()})


def write_mesh(mesh: TetMesh, path, *, force: bool = False, cells: Cells | None = None) -> None:
    """Write a mesh with every point array, format from the extension, atomically: its tets as one
    block of linear tets, or ``cells`` (the cells as given, in ``mesh``'s point ids)."""
    path = Path(path)
    fmt = mesh_output_format(path)
    if fmt == "vtkhdf":  # VTK's cell types and offsets: the cells as given are native there
        write_vtkhdf(path, mesh if cells is None else to_meshio(mesh, cells), force=force)
        return
    if fmt in ("xdmf", "h5m", "med") and importlib.util.find_spec("h5py") is None:
        raise OutputError(f"writing {fmt} files needs h5py (pip install h5py); .vtu needs nothing extra")
    m = to_meshio(mesh, cells)
    if fmt == "gmsh" and "gmsh:geometrical" not in m.cell_data:
        # gmsh's vertex entity tags only make sense with the element tags: meshio's writer refuses
        # them alone and writes its own
        m.point_data.pop("gmsh:dim_tags", None)
    with atomic_path(path, force=force) as tmp:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                meshio.write(str(tmp), m, file_format=fmt)
        except (OSError, ValueError, TypeError, KeyError) as e:
            raise ReadError(f"cannot write {path}: {e}") from None
