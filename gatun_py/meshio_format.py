"""``.tetc`` as a meshio format: ``meshio.read("x.tetc")`` and ``meshio.write("x.tetc", mesh)``.

Registered by ``import gatun_py``, so that in the same Python process PyVista (``pyvista.read`` goes
through meshio for formats VTK does not know) and any meshio user can open compressed files.
meshio's command line (``meshio convert``) cannot load plugins and does not know ``.tetc``.
"""

from __future__ import annotations

import meshio
import numpy as np

FORMAT_NAME = "tetc"


def read(filename) -> meshio.Mesh:
    """The full mesh of a ``.tetc`` file as a ``meshio.Mesh``: the cells as given (every block,
    cell array, field data and set) when the file stores them, else its tets; every point array.
    Every array is the caller's own (writable), as meshio's readers return them."""
    from .api import open as open_tetc  # start-up time: the verbs load numba; registering must not
    from .codec.cells import read_cells, restore_order
    from .mesh.io import to_meshio

    f = open_tetc(filename)
    mesh = f.mesh()
    cells = read_cells(f.reader, mesh.tets, mesh.n_points, mesh.points) if f.n_bricks == 1 else None
    mesh, cells = restore_order(mesh, cells)
    m = to_meshio(mesh, cells)
    m.points = np.array(m.points)
    m.point_data = {k: np.array(v) for k, v in m.point_data.items()}
    for cb in m.cells:
        cb.data = np.array(cb.data)
    return m


def write(filename, mesh: meshio.Mesh, **options) -> None:
    """Compress a ``meshio.Mesh`` into ``filename`` (with its merge forest and levels, its cells as
    given and its numbering, ``keep_order``; like meshio's other writers it overwrites). Options go
    to :func:`gatun_py.compress`."""
    from .api import compress  # start-up time: as in read

    options.setdefault("force", True)
    options.setdefault("keep_order", True)  # meshio's readers give the numbering back: so does this one
    compress(mesh, filename, **options)


def register() -> None:
    meshio.register_format(FORMAT_NAME, [".tetc"], read, {FORMAT_NAME: write})
