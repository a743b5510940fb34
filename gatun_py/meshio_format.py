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
    """The full mesh of a ``.tetc`` file as a ``meshio.Mesh`` (tetra cells, every point array)."""
    from .api import open as open_tetc  # start-up time: the verbs load numba; registering must not

    mesh = open_tetc(filename).mesh()
    return meshio.Mesh(np.asarray(mesh.points), [("tetra", np.asarray(mesh.tets))],
                       point_data={name: np.asarray(a) for name, a in mesh.user_point_data.items()})


def write(filename, mesh: meshio.Mesh, **options) -> None:
    """Compress a ``meshio.Mesh`` into ``filename`` (with its merge forest and levels; like
    meshio's other writers it overwrites). Options go to :func:`gatun_py.compress`."""
    from .api import compress  # start-up time: as in read

    options.setdefault("force", True)
    compress(mesh, filename, **options)


def register() -> None:
    meshio.register_format(FORMAT_NAME, [".tetc"], read, {FORMAT_NAME: write})
