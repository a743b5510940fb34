"""ParaView support: the reader plugin file and the decoder it runs.

``tetc_reader.py`` is a ParaView Python plugin (load it with Tools > Manage Plugins, or
``LoadPlugin`` in pvbatch; ``tetc paraview-plugin`` prints its path). ParaView's own Python cannot
import gatun_py and numba (other packages, another numpy), so the plugin imports neither: it runs
:mod:`gatun_py.paraview.decode` with the Python gatun_py is installed in, which decodes the
requested step, ratio or level into a VTKHDF file that ParaView's own reader opens.
"""

from __future__ import annotations

from pathlib import Path

from .._atomic import write_bytes_atomic
from ..errors import TetcError

PLUGIN = Path(__file__).with_name("tetc_reader.py")
# the Python that runs the decoder, recorded beside the plugin by `tetc paraview-plugin`
PYTHON_FILE = PLUGIN.with_name("tetc_python.txt")

__all__ = ["PLUGIN", "PYTHON_FILE", "plugin_path"]


def plugin_path(*, record_python: str | None = None) -> Path:
    """The plugin file's path; with ``record_python``, that interpreter is first recorded beside
    it (where the package is writable) so that the plugin finds gatun_py's Python without
    ``TETC_PYTHON`` or ``tetc`` on ParaView's ``PATH``."""
    if record_python:
        try:
            if not PYTHON_FILE.exists() or PYTHON_FILE.read_text().strip() != record_python:
                write_bytes_atomic(PYTHON_FILE, (record_python + "\n").encode(), force=True)
        except (OSError, TetcError):  # a read-only install: the plugin falls back to TETC_PYTHON and PATH
            pass
    return PLUGIN
