"""How a file becomes a mesh, as one record the verbs, the CLI and the readers share.

A base module (the standard library only), so that the CLI can check its options before it loads
numpy, meshio or numba.
"""

from __future__ import annotations

import dataclasses
import numbers
import os
from dataclasses import dataclass

from .errors import OptionError


@dataclass(frozen=True)
class ReadOptions:
    """How to turn a file into a mesh: the keywords of :func:`read_mesh`, as one record.

    The verbs take it as ``read=`` (and their flat ``scalar=``, ``q_file=``... as shorthand for it);
    ``read_mesh(path, **options.kwargs())`` reads with it.

    Parameters
    ----------
    scalar, q_file, q_var, cell_to_point, time_step, refine
        As for :func:`read_mesh`. For a ``.tetc`` file, ``scalar`` names the stored point array to
        use and ``time_step`` the step of a time series.

    Examples
    --------
    >>> ReadOptions(scalar="rho").kwargs()["scalar"]
    'rho'
    """

    scalar: str | None = None
    q_file: str | os.PathLike | None = None
    q_var: str = "density"
    cell_to_point: bool = False
    time_step: int | None = None
    refine: int = 1

    def __post_init__(self):
        if self.time_step is not None and (isinstance(self.time_step, bool) or not isinstance(self.time_step, numbers.Integral)):
            raise OptionError(f"time_step must be a whole number, got {self.time_step!r}")
        object.__setattr__(self, "cell_to_point", bool(self.cell_to_point))

    def kwargs(self) -> dict:
        """The keywords of :func:`read_mesh`."""
        return dataclasses.asdict(self)
