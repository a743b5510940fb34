"""gatun_py: the tetc pipeline for compressed tetrahedral volume data.

The stages, in pipeline order:

* :mod:`gatun_py.mesh`      mesh model, input formats, validation
* :mod:`gatun_py.codec`     lossless cut-border compression and the streaming decoder, ``.tetc`` files
* :mod:`gatun_py.simplify`  offline decimation (merge forest, levels) and the on-the-fly filter
* :mod:`gatun_py.render`    object-space ray casting, camera, transfer functions
* :mod:`gatun_py.pipeline`  decompress -> simplify -> render in one pass, time budgets, quality
"""

__version__ = "0.1.0"

from .errors import CorruptFileError, MeshError, OptionError, OutputError, ReadError, TetcError  # noqa: E402
from .mesh import TetMesh, read_mesh, write_mesh  # noqa: E402

__all__ = ["TetMesh", "read_mesh", "write_mesh", "TetcError", "ReadError", "MeshError", "CorruptFileError",
           "OptionError", "OutputError", "__version__"]
