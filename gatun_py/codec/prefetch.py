"""Decoding a level with the connectivity running ahead of the geometry, in a thread of its own.

:meth:`TetcReader.iter_decode` decodes each batch's tets and then the vertices they introduce, one
after the other. The two stages depend on each other only through the new vertices' refs (the
connectivity decoder writes them, the geometry decoder reads them), and both kernels release the
GIL, so here the connectivity decoder runs in a producer thread up to ``depth`` batches ahead and
hands over each batch's tets with a copy of its refs; the caller's thread decodes the geometry
(the same path as :meth:`TetcReader.decode_mesh` with ``jobs`` > 1: :class:`~.threads.RunAhead`).
On two cores the stream then costs about the slower of the two decoders instead of their sum
(``bench/sections/codec.md``). The batches are the same, in the same order, as
the default scalar's :meth:`~TetcReader.iter_decode`.
"""

from __future__ import annotations

from typing import Iterator

from ..mesh import TetBatch
from .tetcfile import DEFAULT_BATCH_TETS, TetcReader


class PrefetchedDecode:
    """The stream of one level, the connectivity decoded in a background thread at most ``depth``
    batches ahead: iterate it once for the same :class:`~gatun_py.mesh.TetBatch`es as
    :meth:`TetcReader.iter_decode` (default scalar).

    Errors of the background thread (a damaged stream) are raised in the iterating thread. Closing
    the iteration early stops the thread.

    Attributes
    ----------
    values : (n, 4) float32 or None
        The geometry decoder's own array x, y, z, scalar, set once the first batch is out: the
        batches' points and density are views of its rows, and the rows of every batch already
        yielded keep their values, so a consumer can index vertices there instead of copying them.

    Examples
    --------
    >>> from gatun_py.codec import TetcReader
    >>> from gatun_py.warmup import SHIPPED_TETC
    >>> r = TetcReader(SHIPPED_TETC)
    >>> stream = PrefetchedDecode(r, batch_tets=40)
    >>> a = [(b.first, len(b.points), len(b.tets)) for b in stream]
    >>> a == [(b.first, len(b.points), len(b.tets)) for b in r.iter_decode(batch_tets=40)]
    True
    >>> stream.values.shape == (r.level_meta(0).points, 4)
    True
    """

    def __init__(self, reader: TetcReader, level: int = 0, *, batch_tets: int = DEFAULT_BATCH_TETS, depth: int = 4):
        self.values = None
        self._batches = self._stream(reader, level, batch_tets, depth)

    def __iter__(self) -> Iterator[TetBatch]:
        return self._batches

    def __repr__(self) -> str:
        return f"<PrefetchedDecode: values {'not yet' if self.values is None else self.values.shape}>"

    def _stream(self, reader, level, batch_tets, depth):
        n = reader._checked_points(level)
        geo = reader._geometry(level, n)
        self.values = geo.values
        for batch, _ in reader._batches(level, batch_tets, {}, geometry=geo, jobs=2, depth=depth):
            yield batch


def iter_decode_prefetched(reader: TetcReader, level: int = 0, *, batch_tets: int = DEFAULT_BATCH_TETS,
                           depth: int = 4) -> Iterator[TetBatch]:
    """The batches of :class:`PrefetchedDecode` (same as ``reader.iter_decode(level)``)."""
    return iter(PrefetchedDecode(reader, level, batch_tets=batch_tets, depth=depth))
