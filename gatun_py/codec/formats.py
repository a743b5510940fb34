"""The one table from a ``.tetc`` format version to the coding of each of its sections.

A file's container header holds its major format version; every section of the file is coded as
that version's row says. The writer writes :data:`CURRENT` (the row of
:data:`~gatun_py.codec.container.VERSION_MAJOR`); readers take every row. The codings of earlier
versions that today's writer no longer uses are frozen decoders in :mod:`gatun_py.codec.legacy`
(tet coding 1) or kept beside today's in the section's module; ``docs/format.md`` tells what each
version changed.

Examples
--------
>>> from gatun_py.codec.formats import codings
>>> codings(4).geometry, codings(9).geometry, codings(10).steps
(2, 5, True)
>>> codings(2).arrays, codings(1).arrays
(True, False)
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import FormatVersionError
from .container import VERSION_MAJOR


@dataclass(frozen=True)
class Codings:
    """How the sections of a file of one format version are coded.

    Attributes
    ----------
    tets : int
        The coding of the ``L{i}/tets`` stream (:mod:`gatun_py.codec.cutborder`); the boundary
        stream is the same in all versions.
    geometry : int
        The coding of the ``L{i}/geometry`` block (:mod:`gatun_py.codec.geometry`); a block's first
        byte repeats it, and a reader refuses a block coded later than its file's version.
    forest : int
        The coding of the ``L{i}/forest`` sections (:mod:`gatun_py.codec.forest`): 0 LZMA, 1 after
        the level's mesh, 2 in rounds after its mesh and geometry, 3 with the level's quadrics.
    arrays : bool
        Whether the metadata lists the point arrays and the file has ``points64`` and ``array/j``
        sections (array blocks, :mod:`gatun_py.codec.arrays`); else one float32 scalar.
    array_copies : bool
        Whether an array may list components that are ``copies`` of another array's.
    steps : bool
        Whether the file may be a time series (metadata ``steps``, :mod:`gatun_py.codec.steps`).
    cells : bool
        Whether the file may store its cells as given (metadata ``cells``, :mod:`gatun_py.codec.cells`).
    """

    tets: int
    geometry: int
    forest: int
    arrays: bool = True
    array_copies: bool = False
    steps: bool = False
    cells: bool = False


FORMATS = {
    1: Codings(tets=1, geometry=1, forest=0, arrays=False),
    2: Codings(tets=1, geometry=1, forest=0),
    3: Codings(tets=1, geometry=1, forest=1),
    4: Codings(tets=1, geometry=2, forest=1),
    5: Codings(tets=2, geometry=3, forest=1),
    6: Codings(tets=2, geometry=3, forest=2),
    7: Codings(tets=2, geometry=3, forest=3),
    8: Codings(tets=2, geometry=4, forest=3, array_copies=True),
    9: Codings(tets=2, geometry=5, forest=3, array_copies=True),
    10: Codings(tets=2, geometry=5, forest=3, array_copies=True, steps=True, cells=True),
    11: Codings(tets=2, geometry=5, forest=3, array_copies=True, steps=True, cells=True),
}


def codings(major: int) -> Codings:
    """The codings of a file of format version ``major``.

    Raises
    ------
    FormatVersionError
        If no version of that number exists (the container refuses it before this is asked).
    """
    try:
        return FORMATS[int(major)]
    except (KeyError, TypeError, ValueError):
        raise FormatVersionError(f"unknown .tetc format version {major!r}") from None


CURRENT = codings(VERSION_MAJOR)  # what this version of tetc writes
