"""``pyvista.read("x.tetc")``: PyVista finds this reader through the ``pyvista.readers`` entry point
(PyVista >= 0.48); older PyVista reads ``.tetc`` through meshio once ``gatun_py`` is imported, with
the arrays widened to float64."""

from __future__ import annotations


def read(path, *, ratio: float | None = None, level: int | None = None, step: int | None = None, **_options):
    """A ``.tetc`` file as a ``pyvista.UnstructuredGrid``, every array in its dtype
    (:meth:`gatun_py.TetcFile.to_pyvista`); ``pyvista.read(path, ratio=0.5)`` passes the options."""
    from .api import open as open_tetc  # start-up time: the verbs load numba only when a file is read

    return open_tetc(path).to_pyvista(ratio, level=level, step=step)
