"""The thin mesh data model shared by every stage of the pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Faces of a positively oriented tet (a, b, c, d), each wound so its normal points out of the tet.
# Face k is the face opposite vertex k.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


@dataclass(frozen=True, eq=False, repr=False)
class TetMesh:
    """A linear tetrahedral mesh with one scalar per point.

    Immutable by convention: the arrays are marked read-only, stages that change a mesh build a
    new one.

    Parameters
    ----------
    points : (n, 3) float32
        Vertex coordinates.
    density : (n,) float32
        The scalar sampled at every vertex (the paper's "density").
    tets : (m, 4) int32
        Vertex ids of every tetrahedron, positively oriented (signed volume >= 0).
    scalar_name : str
        Name of the scalar in the source file, kept for output.

    Examples
    --------
    >>> import numpy as np
    >>> m = TetMesh(np.eye(4, 3, k=-1, dtype=np.float32), np.arange(4, dtype=np.float32),
    ...             np.array([[0, 1, 2, 3]], dtype=np.int32))
    >>> m
    TetMesh(points=4, tets=1, scalar='density' in [0, 3])
    >>> float(m.signed_volumes()[0])
    0.16666666666666666
    """

    points: np.ndarray
    density: np.ndarray
    tets: np.ndarray
    scalar_name: str = "density"
    _cache: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        pts = np.ascontiguousarray(self.points, dtype=np.float32).reshape(-1, 3)
        den = np.ascontiguousarray(self.density, dtype=np.float32).reshape(-1)
        tets = np.ascontiguousarray(self.tets, dtype=np.int32).reshape(-1, 4)
        for a in (pts, den, tets):
            a.flags.writeable = False
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "density", den)
        object.__setattr__(self, "tets", tets)

    # -- sizes -------------------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    def __repr__(self) -> str:
        if self.n_points:
            lo, hi = self.scalar_range
            rng = f" in [{lo:.6g}, {hi:.6g}]"
        else:
            rng = ""
        return f"TetMesh(points={self.n_points}, tets={self.n_tets}, scalar={self.scalar_name!r}{rng})"

    # -- geometry ----------------------------------------------------------------------------
    def signed_volumes(self) -> np.ndarray:
        """Signed volume of every tet in float64 (positive for the stored orientation)."""
        if "vol" not in self._cache:
            self._cache["vol"] = signed_volumes(self.points, self.tets)
        return self._cache["vol"]

    @property
    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """(min xyz, max xyz) as float32 arrays."""
        if self.n_points == 0:
            z = np.zeros(3, np.float32)
            return z, z
        return self.points.min(axis=0), self.points.max(axis=0)

    @property
    def scalar_range(self) -> tuple[float, float]:
        if self.n_points == 0:
            return 0.0, 0.0
        return float(self.density.min()), float(self.density.max())

    def boundary_faces(self) -> np.ndarray:
        """Triangles that belong to exactly one tet, wound outward, as (k, 3) int32.

        Sorted by the tet that owns them and then by the face's position in that tet, so the
        result is deterministic for a given tet array.
        """
        if "bnd" not in self._cache:
            self._cache["bnd"] = boundary_faces(self.tets)
        return self._cache["bnd"]

    def edge_length_median(self) -> float:
        """Median tet edge length: a natural sampling step for the renderer."""
        if self.n_tets == 0:
            return 0.0
        t = self.tets[: min(self.n_tets, 200_000)]
        p = self.points.astype(np.float64)
        e = np.linalg.norm(p[t[:, 0]] - p[t[:, 1]], axis=1)
        return float(np.median(e))


def default_step(points, boundary_faces) -> float:
    """Half the median edge length of the boundary surface: the volume-mode sample spacing.

    Boundary edges are used because they are known before the first tet arrives, so a streaming
    renderer and an in-memory one agree on the step, and the codec can record it in the file.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]], np.float32)
    >>> default_step(pts, np.array([[0, 2, 1]]))
    1.0
    """
    faces = np.asarray(boundary_faces)
    if len(faces) == 0:
        return 1.0
    p = np.asarray(points, dtype=np.float64)
    e = np.concatenate([p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 1]],
                        p[faces[:, 0]] - p[faces[:, 2]]])
    lengths = np.linalg.norm(e, axis=1)
    lengths = lengths[lengths > 0]
    return float(np.median(lengths)) * 0.5 if len(lengths) else 1.0


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The signed volume of each tet, computed in float64.

    Differences of float32 coordinates are exact in float64, so a tet whose vertices are exactly
    coplanar on a grid line reports exactly 0.
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    if t.shape[0] == 0:
        return np.zeros(0)
    a = p[t[:, 0]]
    u = p[t[:, 1]] - a
    v = p[t[:, 2]] - a
    w = p[t[:, 3]] - a
    return np.einsum("ij,ij->i", u, np.cross(v, w)) / 6.0


def face_keys(tets: np.ndarray):
    """All 4m faces of the tets as sorted vertex triples, plus their owning tet and local index."""
    t = np.asarray(tets, dtype=np.int64)
    m = t.shape[0]
    faces = t[:, TET_FACES].reshape(-1, 3)  # (4m, 3), face k of tet i at row 4i+k
    return np.sort(faces, axis=1), faces


def _unique_face_counts(sorted_faces: np.ndarray):
    """Group identical sorted triples: returns (order, group id per row in that order, counts)."""
    n = sorted_faces.shape[0]
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort((sorted_faces[:, 2], sorted_faces[:, 1], sorted_faces[:, 0]))
    s = sorted_faces[order]
    new = np.ones(n, bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    gid = np.cumsum(new) - 1
    counts = np.bincount(gid)
    return order, gid, counts


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Faces used by exactly one tet, wound outward, in tet order (see TetMesh.boundary_faces)."""
    sorted_faces, faces = face_keys(tets)
    order, gid, counts = _unique_face_counts(sorted_faces)
    once = np.zeros(sorted_faces.shape[0], bool)
    once[order] = counts[gid] == 1
    return np.ascontiguousarray(faces[once], dtype=np.int32)


def face_multiplicity(tets: np.ndarray):
    """For validation: (number of distinct faces, rows of faces shared by > 2 tets as sorted triples)."""
    sorted_faces, _ = face_keys(tets)
    order, gid, counts = _unique_face_counts(sorted_faces)
    bad = counts > 2
    first_rows = order[np.r_[0, np.flatnonzero(np.diff(gid)) + 1]] if len(order) else order
    return counts, sorted_faces[first_rows[bad]] if bad.any() else np.zeros((0, 3), np.int64)
