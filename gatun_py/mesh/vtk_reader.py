"""Reading VTK files with VTK itself, for the files meshio cannot parse.

meshio reads most ``.vtk`` and ``.vtu`` files, but not all that VTK writes (legacy files of VTK 9
with 64-bit ``vtkidtype`` offsets, some appended/compressed XML layouts, structured grids in XML).
When meshio fails on such a file and the optional ``vtk`` package is installed
(``pip install 'gatun_py[vtk]'``), the file is read by VTK's own reader and turned into a
``meshio.Mesh`` with the same cells, point data and cell data.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from ..errors import MeshError, ReadError

# VTK cell type id -> meshio cell type, for the cells a volume mesh holds (and its surface cells,
# which the reader then reports as ignored)
VTK_TO_MESHIO = {1: "vertex", 3: "line", 5: "triangle", 9: "quad", 10: "tetra", 12: "hexahedron", 13: "wedge",
                 14: "pyramid", 21: "line3", 22: "triangle6", 23: "quad8", 24: "tetra10", 25: "hexahedron20",
                 26: "wedge15", 27: "pyramid13", 28: "quad9", 29: "hexahedron27", 32: "wedge18", 33: "hexahedron24",
                 34: "triangle7", 35: "line4"}
# VTK's axis-aligned cells, renumbered into the cell they are (voxel -> hexahedron, pixel -> quad)
VTK_REORDERED = {11: ("hexahedron", [0, 1, 3, 2, 4, 5, 7, 6]), 8: ("quad", [0, 1, 3, 2])}

VTK_SUFFIXES = (".vtk", ".vtu", ".vts", ".vtr", ".pvtu", ".pvts")
INSTALL_HINT = "VTK can read more of these files: pip install vtk (or the extra: pip install 'gatun_py[vtk]')"


def vtk_available() -> bool:
    try:
        import vtkmodules.vtkIOLegacy  # noqa: F401  (optional dependency)
    except ImportError:
        return False
    return True


def read_with_vtk(path) -> meshio.Mesh:
    """Read ``path`` with VTK's reader for its suffix and return it as a ``meshio.Mesh``.

    Raises
    ------
    ReadError
        VTK is not installed, or it could not read the file either.
    """
    path = Path(path)
    try:  # optional dependency
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkCommonCore import vtkObject, vtkVersion
        from vtkmodules.vtkFiltersCore import vtkAppendFilter
        from vtkmodules.vtkIOLegacy import vtkGenericDataObjectReader
        from vtkmodules.vtkIOXML import vtkXMLGenericDataObjectReader
    except ImportError:
        raise ReadError(f"{path}: {INSTALL_HINT}") from None
    vtkObject.GlobalWarningDisplayOff()  # VTK prints its complaints; we raise one error instead
    legacy = path.suffix.lower() == ".vtk"
    reader = vtkGenericDataObjectReader() if legacy else vtkXMLGenericDataObjectReader()
    reader.SetFileName(str(path))
    if legacy:  # every array, not only the first SCALARS and VECTORS
        for flag in ("ReadAllScalarsOn", "ReadAllVectorsOn", "ReadAllNormalsOn", "ReadAllTensorsOn",
                     "ReadAllColorScalarsOn", "ReadAllTCoordsOn", "ReadAllFieldsOn"):
            getattr(reader, flag)()
    reader.Update()
    data = reader.GetOutput()
    if data is None or not hasattr(data, "GetNumberOfPoints") or data.GetNumberOfPoints() == 0:
        raise ReadError(f"{path}: VTK's reader could not read it either")
    merge = vtkAppendFilter()  # any data set (structured grids too) as an unstructured grid
    merge.AddInputData(data)
    merge.Update()
    grid = merge.GetOutput()
    points = vtk_to_numpy(grid.GetPoints().GetData()).copy()
    cells_obj = grid.GetCells()
    offsets = vtk_to_numpy(cells_obj.GetOffsetsArray()).astype(np.int64)
    conn = vtk_to_numpy(cells_obj.GetConnectivityArray()).astype(np.int64)
    # VTK 9.6 renamed GetCellTypesArray() to GetCellTypes() (which took an argument before)
    get_types = grid.GetCellTypesArray if _vtk_version(vtkVersion) < (9, 6) else grid.GetCellTypes
    types = vtk_to_numpy(get_types()).astype(np.int64)
    blocks, block_rows = [], []
    # one block per run of equal types, in file order (the cells' own order, block by block)
    starts = np.flatnonzero(np.r_[True, types[1:] != types[:-1]]) if len(types) else np.zeros(0, np.int64)
    for a, b in zip(starts, np.r_[starts[1:], len(types)].astype(np.int64)):
        t = int(types[a])
        if t not in VTK_TO_MESHIO and t not in VTK_REORDERED:
            from vtkmodules.vtkCommonDataModel import vtkCellTypes

            name = vtkCellTypes.GetClassNameFromTypeId(t) or f"VTK cell type {t}"
            raise MeshError(f"{path}: cell type {name} (VTK type {t}) cannot be stored: only tets, hexahedra, "
                            "wedges, pyramids, their quadratic forms and fixed-size surface cells")
        rows = np.arange(a, b)
        sizes = offsets[rows + 1] - offsets[rows]
        idx = offsets[rows][:, None] + np.arange(int(sizes[0]))
        ids = conn[idx]
        if t in VTK_REORDERED:
            typ, order = VTK_REORDERED[t]
            ids = ids[:, order]
        else:
            typ = VTK_TO_MESHIO[t]
        blocks.append(meshio.CellBlock(typ, ids))
        block_rows.append(rows)
    point_data = _arrays(grid.GetPointData(), vtk_to_numpy)
    cell_data = {name: [a[rows] for rows in block_rows] for name, a in _arrays(grid.GetCellData(), vtk_to_numpy).items()}
    field_data = _arrays(data_obj_fields(data), vtk_to_numpy) if data_obj_fields(data) is not None else {}
    return meshio.Mesh(points, blocks, point_data=point_data, cell_data=cell_data, field_data=field_data)


def data_obj_fields(data):
    """A data set's field data (arrays that belong to neither points nor cells), or None."""
    get = getattr(data, "GetFieldData", None)
    return get() if get is not None else None


def _vtk_version(vtkVersion) -> tuple[int, int]:
    return vtkVersion.GetVTKMajorVersion(), vtkVersion.GetVTKMinorVersion()


def _arrays(field_data, vtk_to_numpy) -> dict:
    out = {}
    for i in range(field_data.GetNumberOfArrays()):
        arr = field_data.GetArray(i)  # None for string arrays: those are not numbers to store
        if arr is None:
            continue
        name = arr.GetName() or f"array {i}"
        out[name] = vtk_to_numpy(arr).copy()
    return out
