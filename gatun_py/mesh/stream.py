"""The stream every stage passes along: batches of vertices, boundary faces and tets.

A stream is an iterable of :class:`TetBatch`. The decoder produces one (``TetcReader.iter_decode``),
the simplification filter consumes and produces one, the ray caster and the isosurface extractor
consume one, and :func:`mesh_batches` makes one from a mesh in memory. The rules
(``docs/architecture.md``): vertices arrive in id order (batch ``first`` is the id of its first new
vertex); the whole boundary surface arrives before the first tet; a tet or face only names vertices
that have arrived.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TetBatch", "mesh_batches"]

_NO_FACES = np.zeros((0, 3), np.int32)
_NO_TETS = np.zeros((0, 4), np.int32)


@dataclass
class TetBatch:
    """One step of a tet stream.

    Attributes
    ----------
    first : int
        Id of the first new vertex in this batch.
    points : (k, 3) float array
        New vertices ``first .. first + k - 1``.
    density : (k,) float array
        Their scalar.
    boundary : (b, 3) int32
        Boundary faces (wound outward), vertex ids ``< first + k``.
    tets : (j, 4) int32
        Positively oriented tets, vertex ids ``< first + k``.

    Examples
    --------
    >>> import numpy as np
    >>> TetBatch(0, np.zeros((4, 3), np.float32), np.zeros(4, np.float32),
    ...          np.zeros((4, 3), np.int32), np.zeros((1, 4), np.int32))
    TetBatch(first=0, points=4, boundary=4, tets=1)
    """

    first: int
    points: np.ndarray
    density: np.ndarray
    boundary: np.ndarray
    tets: np.ndarray

    def __repr__(self) -> str:
        return (f"TetBatch(first={self.first}, points={len(self.points)}, boundary={len(self.boundary)}, "
                f"tets={len(self.tets)})")

    @classmethod
    def of_vertices(cls, first: int, points, density, boundary=None) -> "TetBatch":
        """A batch of new vertices (and optionally the boundary), no tets."""
        return cls(first, points, density, _NO_FACES if boundary is None else boundary, _NO_TETS)

    @classmethod
    def of_tets(cls, first: int, tets, points=None, density=None) -> "TetBatch":
        """A batch of tets, with the vertices they introduce (none by default)."""
        if points is None:
            points, density = np.zeros((0, 3), np.float32), np.zeros(0, np.float32)
        return cls(first, points, density, _NO_FACES, tets)


def mesh_batches(mesh, *, batch_tets: int = 65536, order=None):
    """Feed an in-memory mesh as a stream: every vertex and the boundary first, then the tets.

    Parameters
    ----------
    mesh : TetMesh
    batch_tets : int
        Tets per batch.
    order : array of int, optional
        A permutation of the tets (default: the mesh's order).

    Yields
    ------
    TetBatch

    Examples
    --------
    >>> import numpy as np
    >>> from gatun_py.mesh import TetMesh
    >>> m = TetMesh(np.eye(4, 3, k=-1), np.arange(4), np.array([[0, 1, 2, 3]]))
    >>> [b.tets.shape[0] for b in mesh_batches(m)]
    [0, 1]
    """
    yield TetBatch.of_vertices(0, mesh.points, mesh.density, mesh.boundary_faces())
    tets = mesh.tets if order is None else mesh.tets[np.asarray(order)]
    step = max(1, int(batch_tets))
    for i in range(0, len(tets), step):
        yield TetBatch.of_tets(mesh.n_points, tets[i:i + step], mesh.points[:0], mesh.density[:0])
