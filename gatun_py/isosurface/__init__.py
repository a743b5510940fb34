"""Isosurfaces straight from a tet stream, simplified on the fly (Hou & Chen; Peng et al.).

* :mod:`.marching` marching tetrahedra over a batch, edge-keyed vertices, locks from the cut border
* :mod:`.qem`      QEM edge collapse with a global heap, link condition, flip test, locks
* :mod:`.extract`  the streaming driver and the public verb :func:`isosurface`
* :mod:`.io`       writing a :class:`Surface` (any meshio surface format, and ``.vtp``)
"""

from .extract import ImportanceFunction, Surface, isosurface, load_importance

__all__ = ["isosurface", "Surface", "ImportanceFunction", "load_importance"]
