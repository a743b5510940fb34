"""gatun_py: the tetc pipeline for compressed tetrahedral volume data.

The public verbs (``gatun_py.api``)::

    gatun_py.compress(source, "mesh.tetc")      # lossless, with the merge forest and levels
    f = gatun_py.open("mesh.tetc")              # .info, .levels, .mesh(ratio), iteration over batches
    frame = gatun_py.render(f, size=512, ratio=0.9)   # .rgb, .stats, .save(path), shown in Jupyter

The stages, in pipeline order (each imports only the ones before it):

* :mod:`gatun_py.mesh`      mesh model, input formats, validation, the tet stream
* :mod:`gatun_py.codec`     lossless cut-border compression and the streaming decoder, ``.tetc`` files
* :mod:`gatun_py.simplify`  offline decimation (merge forest, levels) and the on-the-fly filter
* :mod:`gatun_py.render`    object-space ray casting, camera, transfer functions (imports only mesh)
* :mod:`gatun_py.pipeline`  decompress -> simplify -> render in one pass, time budgets, quality

``import gatun_py`` also registers ``.tetc`` with meshio.
"""

from ._version import __version__  # noqa: E402
from .api import Frame, TetcFile, compress, convert, decompress, info, open, render  # noqa: E402,A004
from .errors import (CorruptFileError, FormatVersionError, MeshError, OptionError, OutputError,  # noqa: E402
                     OutputExistsError, ReadError, TetcError)
from .mesh import TetBatch, TetMesh, read_mesh, write_mesh  # noqa: E402
from .meshio_format import register as _register_meshio  # noqa: E402

_register_meshio()

__all__ = ["compress", "decompress", "convert", "info", "open", "render", "TetcFile", "Frame", "TetMesh",
           "TetBatch", "read_mesh", "write_mesh", "TetcError", "ReadError", "MeshError", "CorruptFileError",
           "FormatVersionError", "OptionError", "OutputError", "OutputExistsError", "__version__"]
