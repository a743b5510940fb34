"""Isosurfaces straight from a tet stream, simplified on the fly (Hou & Chen; Peng et al.).

* :mod:`.marching` marching tetrahedra over a batch, edge-keyed vertices, locks from the cut border
* :mod:`.qem`      QEM edge collapse with a global heap, link condition, flip test, locks
* :mod:`.extract`  the streaming driver and the public verb :func:`isosurface`
* :mod:`.io`       writing a :class:`Surface` (any meshio surface format, and ``.vtp``)

The names below load on first use (PEP 562): ``gatun_py.isosurface`` is also the name of the public
verb, and importing this package must not load numba.
"""

from .._lazy import attach

_LAZY = {"isosurface": "extract", "Surface": "extract", "ImportanceFunction": "extract", "load_importance": "extract"}


__getattr__, __dir__, __all__ = attach(__name__, _LAZY)
