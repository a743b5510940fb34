"""A mesh as a ``pyvista.UnstructuredGrid`` (PyVista is optional: ``pip install pyvista``)."""

from __future__ import annotations

import numpy as np

from ..errors import OptionError

INSTALL_HINT = "to_pyvista needs PyVista: pip install pyvista"


def to_pyvista(mesh):
    """A TetMesh (its tets and point arrays) or a meshio.Mesh (its cell blocks, point and cell
    arrays) as a ``pyvista.UnstructuredGrid``; the arrays keep their dtypes and values."""
    try:
        import pyvista  # optional dependency
    except ImportError:
        raise OptionError(INSTALL_HINT) from None
    if hasattr(mesh, "tets") and hasattr(mesh, "user_point_data"):
        grid = pyvista.UnstructuredGrid({pyvista.CellType.TETRA: np.asarray(mesh.tets)}, np.asarray(mesh.points))
        for name, a in mesh.user_point_data.items():
            grid.point_data[name] = np.asarray(a)
        return grid
    return pyvista.from_meshio(mesh)
