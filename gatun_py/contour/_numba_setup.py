"""Loading numba's array library without its BLAS probe (time and memory of a streaming run).

The first compiled call of a process makes numba import ``numba.np.arraymath``, and that module,
at import, imports ``scipy.linalg.cython_blas`` only to decide whether ``np.correlate`` and
``np.convolve`` in jitted code may call BLAS (``numba.np.arraymath._HAVE_BLAS``). scipy comes with
scikit-image, so the probe succeeds and loads all of ``scipy.linalg`` and its own OpenBLAS: 0.1 to
0.2 s on the critical path of every ``tetc isosurface`` (before any batch is decoded) and ~16 MB
of its peak, for functions none of our kernels use.

Importing this module imports that module once with ``scipy.linalg`` hidden, then unhides it.
Nothing else changes: scipy stays importable as before, and ``np.dot`` / ``np.linalg`` in jitted
code still find BLAS (numba looks for it again when it compiles them); only numba's
``np.correlate`` / ``np.convolve`` use their plain loop for the rest of the process. When numba's
array library or ``scipy.linalg`` is already loaded there is nothing to save and nothing is done
(:data:`SKIPPED_BLAS_PROBE` says which). The driver imports it before its first kernel call.
"""

from __future__ import annotations

import importlib
import sys

_HIDDEN = "scipy.linalg"

#: whether this import loaded numba's array library without the probe
SKIPPED_BLAS_PROBE = "numba.np.arraymath" not in sys.modules and _HIDDEN not in sys.modules
if SKIPPED_BLAS_PROBE:
    sys.modules[_HIDDEN] = None  # an import of it (or of a submodule) raises ImportError meanwhile
try:  # numba's array library: the point of this module
    importlib.import_module("numba.np.arraymath")
except ImportError:  # a numba that lays its modules out otherwise: nothing saved, nothing broken
    SKIPPED_BLAS_PROBE = False
finally:
    if sys.modules.get(_HIDDEN, 0) is None:
        del sys.modules[_HIDDEN]
