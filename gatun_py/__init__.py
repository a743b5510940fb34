"""gatun_py: the tetc pipeline for compressed tetrahedral volume data.

The public verbs (``gatun_py.api``)::

    gatun_py.compress(source, "mesh.tetc")      # lossless, with the merge forest and levels
    f = gatun_py.open("mesh.tetc")              # .info, .levels, .mesh(ratio), iteration over batches
    frame = gatun_py.render(f, size=512, ratio=0.9)   # .rgb, .stats, .save(path), shown in Jupyter
    surf = gatun_py.isosurface(f, values=[2.5], ratio=0.1)   # simplified while it is extracted

The stages, in pipeline order (each imports only the ones before it):

* :mod:`gatun_py.mesh`      mesh model, input formats, validation, the tet stream
* :mod:`gatun_py.codec`     lossless cut-border compression and the streaming decoder, ``.tetc`` files
* :mod:`gatun_py.simplify`  offline decimation (merge forest, levels) and the on-the-fly filter
* :mod:`gatun_py.raycast`   object-space ray casting, camera, transfer functions (imports only mesh)
* :mod:`gatun_py.contour`   isosurfaces from the tet stream, simplified while extracted
* :mod:`gatun_py.pipeline`  decompress -> simplify -> render in one pass, time budgets, quality

The verbs load ``gatun_py.api`` (and with it numba and the kernels) on first use, as scikit-image
loads its submodules, so ``import gatun_py``, a command's ``--help`` and its usage errors are quick.
``import gatun_py`` registers ``.tetc`` with meshio (when meshio is imported, before or after).
"""

import importlib
import inspect

from ._compile_notice import share_installed_cache as _share_installed_cache
from ._after_import import after_import as _when_imported
from ._lazy import attach
from ._version import __version__
from .errors import (CorruptFileError, FormatVersionError, MeshError, OptionError, OutputError,
                     OutputExistsError, ReadError, TetcError)


class _Verb:
    """A public verb of :mod:`gatun_py.api`, imported when first called (or its help is read)."""

    def __init__(self, name: str, module: str = ".api"):
        self.__name__ = self.__qualname__ = name
        self._module = module
        self.__module__ = __name__ + module  # where it is defined (doctests run there, not here)

    @property
    def _target(self):
        return getattr(importlib.import_module(self._module, __name__), self.__name__)

    def __call__(self, *args, **kwargs):
        return self._target(*args, **kwargs)

    @property
    def __doc__(self):
        return self._target.__doc__

    @property
    def __signature__(self):
        return inspect.signature(self._target)

    @property
    def __wrapped__(self):
        return self._target

    def __get__(self, obj, objtype=None):
        # a descriptor is a routine to inspect and pydoc: help(gatun_py.render) shows the verb's own help
        return self

    def __repr__(self) -> str:
        return f"<gatun_py verb {self.__name__}>"


compress = _Verb("compress")
decompress = _Verb("decompress")
convert = _Verb("convert")
info = _Verb("info")
open = _Verb("open")  # noqa: A001 (the verb users look for, as gzip.open)
render = _Verb("render")
isosurface = _Verb("isosurface", ".contour.extract")
append = _Verb("append")
render_steps = _Verb("render_steps")
compress_pieces = _Verb("compress_pieces", ".pipeline.compress_pieces")

# classes load with their module on first access
_LAZY = {"TetcFile": "api", "Frame": "pipeline.requests", "View": "pipeline.requests", "Detail": "pipeline.requests",
         "ReadOptions": "read_options", "ForestOptions": "pipeline.requests", "Surface": "contour.extract", "TetMesh": "mesh", "TetBatch": "mesh", "read_mesh": "mesh",
         "read_series": "mesh.series", "Series": "mesh.series",
         "write_mesh": "mesh"}


__getattr__, __dir__, _ = attach(__name__, _LAZY)




def _register_meshio():
    from .meshio_format import register  # start-up time: meshio loads in a second or more, numba after it

    register()


# .tetc for meshio once meshio is imported (now, if it is): importing it here would delay every command
_when_imported("meshio", _register_meshio)
# before any kernel module is imported: a checkout shadowing an installed copy of the same kernels
# uses that copy's numba cache (no numba import otherwise)
_share_installed_cache()

__all__ = ["compress", "decompress", "convert", "info", "open", "render", "isosurface", "append", "render_steps",
           "compress_pieces", "TetcFile", "Frame", "View", "Detail", "ReadOptions", "ForestOptions",
           "Surface", "TetMesh",
           "TetBatch", "read_mesh", "write_mesh", "read_series", "Series", "TetcError", "ReadError", "MeshError", "CorruptFileError",
           "FormatVersionError", "OptionError", "OutputError", "OutputExistsError", "__version__"]
