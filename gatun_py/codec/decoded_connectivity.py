"""A level's connectivity (and geometry) decoded once and replayed: the forest of format 3 to 5
needs the level's tets before the mesh is streamed, the forest of format 6 its tets and float32
positions and values, and the stream then reuses them instead of decoding them again."""

from __future__ import annotations

import numpy as np

from ..errors import CorruptFileError
from .cutborder import ConnectivityDecoder
from .cutborder import _tets_out  # the check of a caller's output array, shared with the decoder


class DecodedConnectivity:
    """The whole output of a :class:`~gatun_py.codec.cutborder.ConnectivityDecoder` (boundary
    faces, tets, geometry predictors, peak border), served through the same interface, in batches
    of any size.

    Parameters
    ----------
    decoder : ConnectivityDecoder
        A fresh decoder; it is run to the end here (raising what it raises on damage).
    """

    def __init__(self, decoder: ConnectivityDecoder):
        self._faces, self._nbv = decoder.boundary()
        decoder.start_tets()
        self.n_tets = decoder.n_tets
        self.tets = decoder.next_tets(decoder.n_tets) if decoder.n_tets else np.zeros((0, 4), np.int32)
        self.predictors = decoder.predictors
        self.last_refs = self.predictors[:self._nbv]
        self.peak_border = decoder.peak_border
        self._known_end = decoder.vertices_known
        self._done = 0
        self._known = self._nbv

    def __repr__(self) -> str:
        return f"DecodedConnectivity(tets={self.n_tets}, boundary_faces={len(self._faces)}, served={self._done})"

    def boundary(self):
        self.last_refs = self.predictors[:self._nbv]  # a replay starts again from the boundary's
        return self._faces, self._nbv

    def start_tets(self):
        self._done = 0
        self._known = self._nbv

    @property
    def tets_done(self) -> int:
        return self._done

    def _copy_to(self, out, max_tets):
        part = self.tets[self._done:self._done + max_tets]
        out = _tets_out(out, len(part))
        out[:] = part
        return out

    @property
    def vertices_known(self) -> int:
        return self._known

    def next_tets(self, max_tets: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """The next up to ``max_tets`` tets; the vertices they introduce are the next ids in order
        (the decoder numbers new vertices as they appear), so the count known is the largest id + 1.
        ``out``: as :meth:`ConnectivityDecoder.next_tets` (they are copied there)."""
        out = self.tets[self._done:self._done + max_tets] if out is None else self._copy_to(out, max_tets)
        first = self._known
        self._done += len(out)
        if len(out):
            self._known = max(self._known, int(out.max()) + 1)
        if self._done == self.n_tets:
            self._known = self._known_end
        self.last_refs = self.predictors[first:self._known]
        return out


class DecodedGeometry:
    """The values of a finished :class:`~gatun_py.codec.geometry.GeometryDecoder` (x, y, z and the
    default scalar of every vertex, in decode order), served through the decoder's interface:
    ``decode(refs)`` gives the next ``len(refs)`` rows, ``finish()`` checks that all were served.

    Parameters
    ----------
    values : (n, 4) float32
        The decoder's :attr:`~gatun_py.codec.geometry.GeometryDecoder.values`, fully decoded.
    """

    def __init__(self, values: np.ndarray):
        self.values = values
        self.n_points = len(values)
        self.n_decoded = 0

    def __repr__(self) -> str:
        return f"DecodedGeometry(points={self.n_points}, served={self.n_decoded})"

    def decode(self, refs) -> tuple[np.ndarray, np.ndarray]:
        start, count = self.n_decoded, len(refs)
        if start + count > self.n_points:
            raise CorruptFileError(
                f"corrupt geometry block: {start + count} vertices requested, the block holds {self.n_points}")
        self.n_decoded = start + count
        return self.values[start:start + count, :3], self.values[start:start + count, 3]

    def finish(self) -> None:
        if self.n_decoded != self.n_points:
            raise CorruptFileError(f"corrupt geometry block: {self.n_decoded} of {self.n_points} vertices decoded")
