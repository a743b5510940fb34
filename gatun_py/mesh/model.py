"""The thin mesh data model shared by every stage of the pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Faces of a positively oriented tet (a, b, c, d), each wound so its normal points out of the tet.
# Face k is the face opposite vertex k.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)

# The default scalar's name for a mesh that came without any: its density is all zeros, stored
# under this name, and left out wherever the user's arrays are listed or written (a bare gmsh mesh
# compresses and decompresses to itself, and renders as a uniform medium that shows its shape).
NO_SCALAR = ""


@dataclass(frozen=True, eq=False, repr=False)
class TetMesh:
    """A linear tetrahedral mesh with its point arrays.

    Immutable by convention: the arrays are marked read-only, stages that change a mesh build a
    new one.

    Parameters
    ----------
    points : (n, 3) float32 or float64
        Vertex coordinates, kept in their dtype (float64 stays float64; any other dtype becomes
        float32).
    density : (n,) array or None
        The scalar rendered and decimated by default (the paper's "density"), as float32. ``None``
        when ``point_data`` holds ``scalar_name``: then it is that array rounded to float32.
    tets : (m, 4) int32
        Vertex ids of every tetrahedron, positively oriented (signed volume >= 0).
    scalar_name : str
        Name of the default scalar, kept for output; :data:`NO_SCALAR` (``""``) for a mesh without
        one (``density`` all zeros, see :attr:`user_point_data`).
    point_data : dict, optional
        Every point array, ``name -> (n,) or (n, k)`` array in its own dtype (floats and integers),
        bit for bit what the user gave. The default scalar is ``point_data[scalar_name]``; when it
        is absent, ``density`` is stored under that name.

    Examples
    --------
    >>> import numpy as np
    >>> m = TetMesh(np.eye(4, 3, k=-1, dtype=np.float32), np.arange(4, dtype=np.float32),
    ...             np.array([[0, 1, 2, 3]], dtype=np.int32))
    >>> m
    TetMesh(points=4, tets=1, scalar='density' in [0, 3])
    >>> float(m.signed_volumes()[0])
    0.16666666666666666
    >>> v = TetMesh(np.eye(4, 3, k=-1), None, [[0, 1, 2, 3]], "p",
    ...             point_data={"p": np.arange(4.0), "u": np.ones((4, 3))})
    >>> v
    TetMesh(points=4 float64, tets=1, scalar='p' in [0, 3], arrays=['p' float64, 'u' float64 x3])
    >>> v.scalar("u", "magnitude")[:2]
    array([1.73205081, 1.73205081])
    """

    points: np.ndarray
    density: np.ndarray | None
    tets: np.ndarray
    scalar_name: str = "density"
    point_data: dict | None = None
    _cache: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        raw = np.asarray(self.points)
        pdtype = np.float64 if raw.dtype.kind == "f" and raw.dtype.itemsize == 8 else np.float32
        pts = np.ascontiguousarray(raw, dtype=pdtype).reshape(-1, 3)
        n = pts.shape[0]
        data = {}
        for name, arr in (self.point_data or {}).items():
            data[str(name)] = _point_array(name, arr, n)
        name = str(self.scalar_name)
        if name in data:
            if data[name].ndim != 1:
                raise ValueError(f"the default scalar {name!r} must be one value per point, "
                                 f"got shape {data[name].shape}")
            den = np.ascontiguousarray(data[name], dtype=np.float32)
            if self.density is not None:
                given = np.asarray(self.density, dtype=np.float32).reshape(-1)
                if given.shape != den.shape or not np.array_equal(given.view(np.int32), den.view(np.int32)):
                    raise ValueError(f"density differs from point_data[{name!r}] rounded to float32")
        else:
            if self.density is None:
                raise ValueError(f"no density given and no point array named {name!r}")
            den = np.ascontiguousarray(self.density, dtype=np.float32).reshape(-1)
            if den.shape[0] != n:
                raise ValueError(f"density has {den.shape[0]} values for {n} points")
            data = {name: den, **data}
        raw_tets = np.asarray(self.tets)
        if raw_tets.size and raw_tets.dtype.kind not in "iu":
            raise ValueError(f"tet vertex ids must be integers, got {raw_tets.dtype}")
        if raw_tets.size and raw_tets.dtype.itemsize > 4 and (raw_tets.min() < -1 or raw_tets.max() >= 2**31 - 1):
            raise ValueError("tet vertex ids do not fit in 32 bits")
        tets = np.ascontiguousarray(raw_tets, dtype=np.int32).reshape(-1, 4)
        for a in (pts, den, tets, *data.values()):
            a.flags.writeable = False
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "density", den)
        object.__setattr__(self, "tets", tets)
        object.__setattr__(self, "scalar_name", name)
        object.__setattr__(self, "point_data", data)

    # -- sizes -------------------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    def __repr__(self) -> str:
        if self.n_points and self.has_scalar:
            lo, hi = self.scalar_range
            rng = f" in [{lo:.6g}, {hi:.6g}]"
        else:
            rng = ""
        pdt = "" if self.points.dtype == np.float32 else f" {self.points.dtype}"
        arrays = ""
        listed = [a for a in self.arrays if a[0] in self.user_point_data]
        if len(listed) > 1 or (listed and (listed[0][1] != np.float32 or not self.has_scalar)):
            arrays = ", arrays=[" + ", ".join(
                f"{name!r} {dt}" + (f" x{k}" if k > 1 else "") for name, dt, k in listed) + "]"
        scalar = repr(self.scalar_name) if self.has_scalar else "none"
        return (f"TetMesh(points={self.n_points}{pdt}, tets={self.n_tets}, "
                f"scalar={scalar}{rng}{arrays})")

    # -- point arrays ------------------------------------------------------------------------
    @property
    def has_scalar(self) -> bool:
        """False for a mesh that came without a scalar (``scalar_name`` is :data:`NO_SCALAR`)."""
        return self.scalar_name != NO_SCALAR

    @property
    def user_point_data(self) -> dict:
        """The point arrays the user gave: ``point_data`` without the zeros of a mesh that had no
        scalar (what a writer writes)."""
        if self.has_scalar:
            return self.point_data
        return {k: v for k, v in self.point_data.items() if k != NO_SCALAR}

    @property
    def arrays(self) -> list[tuple[str, np.dtype, int]]:
        """``(name, dtype, components)`` of every point array, the default scalar first."""
        return [(name, a.dtype, 1 if a.ndim == 1 else int(a.shape[1])) for name, a in self.point_data.items()]

    def scalar(self, name: str | None = None, component=None) -> np.ndarray:
        """One value per point from a point array, as float64.

        Parameters
        ----------
        name : str, optional
            The array (default: the default scalar).
        component : None, int or "magnitude"
            For a vector array: which component, or the Euclidean norm. Required for vectors.

        Raises
        ------
        KeyError
            No such array (the message lists the names).
        ValueError
            A vector without ``component``, or a component out of range.
        """
        return scalar_of(self.point_data, self.scalar_name if name is None else name, component)

    def with_scalar(self, name: str, component=None) -> "TetMesh":
        """The same mesh with ``name`` (a component or the magnitude of a vector) as default scalar.

        For a vector, the derived scalar is added as ``"name[i]"`` or ``"name[magnitude]"``.
        """
        if component is None and name in self.point_data and self.point_data[name].ndim == 1:
            return TetMesh(self.points, None, self.tets, name, point_data=self.point_data)
        label = f"{name}[{component}]"
        data = dict(self.point_data)
        data[label] = self.scalar(name, component)
        return TetMesh(self.points, None, self.tets, label, point_data=data)

    @property
    def points32(self) -> np.ndarray:
        """The coordinates rounded to float32 (the array itself when already float32)."""
        if self.points.dtype == np.float32:
            return self.points
        if "p32" not in self._cache:
            p = self.points.astype(np.float32)
            p.flags.writeable = False
            self._cache["p32"] = p
        return self._cache["p32"]

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


def _point_array(name, arr, n: int) -> np.ndarray:
    """A point array in its own dtype as a contiguous (n,) or (n, k) array."""
    a = np.asarray(arr)
    if a.dtype.kind not in "fiub" or a.dtype.itemsize > 8:
        raise ValueError(f"point array {name!r}: unsupported dtype {a.dtype} (floats and integers only)")
    if a.dtype.kind == "b":
        a = a.astype(np.uint8)
    if not a.dtype.isnative:  # legacy VTK is big endian: same values, native bytes
        a = a.astype(a.dtype.newbyteorder("="))
    if a.ndim == 2 and a.shape[1] == 1:
        a = a.reshape(-1)
    if a.ndim not in (1, 2) or a.shape[0] != n or (a.ndim == 2 and a.shape[1] == 0):
        raise ValueError(f"point array {name!r}: shape {a.shape} is not ({n},) or ({n}, k)")
    # a read-only contiguous array is shared; anything else is copied (the mesh marks its arrays
    # read-only, which must not change the caller's array)
    if a.flags.c_contiguous and not a.flags.writeable:
        return a
    return np.array(a, order="C")


def scalar_of(point_data: dict, name: str, component=None) -> np.ndarray:
    """One float64 value per point from ``point_data[name]`` (see :meth:`TetMesh.scalar`)."""
    if name not in point_data:
        raise KeyError(f"no point array named {name!r}; arrays: {', '.join(map(repr, point_data)) or 'none'}")
    a = point_data[name]
    if a.ndim == 1:
        if component not in (None, 0):
            raise ValueError(f"{name!r} is a scalar array: it has no component {component!r}")
        return a.astype(np.float64)
    k = a.shape[1]
    if component is None:
        raise ValueError(f"{name!r} has {k} components: choose one (0..{k - 1}) or 'magnitude'")
    if component == "magnitude":
        with np.errstate(over="ignore", invalid="ignore"):  # huge components: inf, as the values say
            return np.sqrt(np.sum(np.square(a.astype(np.float64)), axis=1))
    if isinstance(component, (int, np.integer)) and not isinstance(component, bool) and 0 <= component < k:
        return a[:, int(component)].astype(np.float64)
    raise ValueError(f"{name!r} has components 0..{k - 1} and 'magnitude', not {component!r}")


# The default step samples the bounding-box diagonal at least this often. Half a boundary edge alone
# is too coarse on meshes of few or large cells (hex grids, quadratic FEM meshes, coarse CFD grids):
# their volume renders showed wood-grain bands, whose contrast grows with the opacity a sample
# takes, a fraction of the diagonal (the transfer functions' unit distance); bench/sections/banding.md.
MIN_SAMPLES_PER_DIAGONAL = 512


def default_step(points, boundary_faces) -> float:
    """The volume-mode sample spacing: half the median edge length of the boundary surface, and at
    most 1/512 of the bounding-box diagonal.

    Boundary edges are used because they are known before the first tet arrives, so a streaming
    renderer and an in-memory one agree on the step, and the codec can record it in the file. The
    bound on the diagonal keeps meshes of few or large cells from banding.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]], np.float32)
    >>> default_step(pts, np.array([[0, 2, 1]])) == float(np.sqrt(8) / 512)
    True
    """
    faces = np.asarray(boundary_faces)
    if len(faces) == 0:
        return 1.0
    p = np.asarray(points, dtype=np.float64)
    e = np.concatenate([p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 1]],
                        p[faces[:, 0]] - p[faces[:, 2]]])
    lengths = np.linalg.norm(e, axis=1)
    lengths = lengths[lengths > 0]
    if not len(lengths):
        return 1.0
    step = float(np.median(lengths)) * 0.5
    used = p[np.unique(faces)]  # the boundary's box is the mesh's (unreferenced points aside)
    diag = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    if diag > 0 and np.isfinite(diag):
        step = min(step, diag / MIN_SAMPLES_PER_DIAGONAL)
    return step


# Tets per chunk of signed_volumes.
_VOLUME_CHUNK = 1 << 16


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The signed volume of each tet, computed in float64.

    Differences of float32 coordinates are exact in float64, so a tet whose vertices are exactly
    coplanar on a grid line reports exactly 0.
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets)
    out = np.empty(t.shape[0])
    for lo in range(0, t.shape[0], _VOLUME_CHUNK):  # bounded temporaries (150 bytes per tet at once)
        c = t[lo:lo + _VOLUME_CHUNK].astype(np.int64)
        a = p[c[:, 0]]
        u = p[c[:, 1]] - a
        v = p[c[:, 2]] - a
        w = p[c[:, 3]] - a
        out[lo:lo + c.shape[0]] = np.einsum("ij,ij->i", u, np.cross(v, w)) / 6.0
    return out


def face_keys(tets: np.ndarray):
    """All 4m faces of the tets as sorted vertex triples, plus their owning tet and local index."""
    t = np.asarray(tets, dtype=np.int64)
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
    t = np.asarray(tets)
    if t.shape[0] and int(t.max()) < (1 << _KEY_BITS) and int(t.min()) >= 0:
        return _boundary_faces_packed(t)
    return _boundary_faces_triples(t)


def _boundary_faces_packed(tets: np.ndarray) -> np.ndarray:
    """:func:`boundary_faces` by one packed int64 key per face (about 30 bytes per face at the
    peak, where the (4m, 3) int64 triples and their lexsort take 130: 4 GB at 7.8 M tets)."""
    m = tets.shape[0]
    keys = _packed_face_keys(tets)  # face k of tet i at k * m + i
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    single = np.ones(4 * m, bool)  # in key order: no equal key before or after
    same = keys[1:] == keys[:-1]
    del keys
    single[1:] &= ~same
    single[:-1] &= ~same
    del same
    once = np.empty(4 * m, bool)
    once[order] = single
    del order, single
    tet, k = np.nonzero(once.reshape(4, m).T)  # by tet, then face position: the documented order
    return np.ascontiguousarray(np.asarray(tets)[tet[:, None], TET_FACES[k]], dtype=np.int32)


def _boundary_faces_triples(tets: np.ndarray) -> np.ndarray:
    """:func:`boundary_faces` for any ids, by lexsorting the (4m, 3) sorted triples."""
    sorted_faces, faces = face_keys(tets)
    order, gid, counts = _unique_face_counts(sorted_faces)
    once = np.zeros(sorted_faces.shape[0], bool)
    once[order] = counts[gid] == 1
    return np.ascontiguousarray(faces[once], dtype=np.int32)


# Vertex ids below this fit three to an int64 key (21 bits each): face_multiplicity packs them.
_KEY_BITS = 21


def _packed_face_keys(tets: np.ndarray) -> np.ndarray:
    """Every face of every tet as one int64 key a << 42 | b << 21 | c of its sorted ids (a < b < c),
    built face by face: ordering the keys orders the triples lexicographically. 8 bytes per face
    and (m,)-sized temporaries, where (4m, 3) int64 triples and their lexsort take 40 + 24."""
    t = np.asarray(tets)
    m = t.shape[0]
    keys = np.empty((4, m), np.int64)
    for k in range(4):
        x, y, z = (t[:, TET_FACES[k, j]].astype(np.int64) for j in range(3))
        lo = np.minimum(np.minimum(x, y), z)
        hi = np.maximum(np.maximum(x, y), z)
        mid = x + y + z - lo - hi
        np.left_shift(lo, 2 * _KEY_BITS, out=keys[k])
        keys[k] |= mid << _KEY_BITS
        keys[k] |= hi
    return keys.reshape(-1)


def face_multiplicity(tets: np.ndarray):
    """For validation: (how many tets share each distinct face, in the lexicographic order of its
    sorted ids; rows of the faces shared by > 2 tets as sorted triples, in that order)."""
    t = np.asarray(tets)
    if t.shape[0] and int(t.max()) < (1 << _KEY_BITS) and int(t.min()) >= 0:
        # bounded memory (a 10 M-tet mesh: 0.5 GB instead of 3.9 GB): one sorted int64 key per face
        keys = _packed_face_keys(t)
        keys.sort()
        new = np.empty(keys.shape[0], bool)
        new[0] = True
        np.not_equal(keys[1:], keys[:-1], out=new[1:])
        starts = np.flatnonzero(new)
        del new
        counts = np.empty_like(starts)  # written in place: no concatenated copies of 8 bytes per face
        np.subtract(starts[1:], starts[:-1], out=counts[:-1])
        counts[-1] = keys.shape[0] - starts[-1]
        bad = keys[starts[counts > 2]]
        mask = (1 << _KEY_BITS) - 1
        over = np.stack([bad >> (2 * _KEY_BITS), (bad >> _KEY_BITS) & mask, bad & mask], axis=1)
        return counts, over
    return _face_multiplicity_triples(t)


def _face_multiplicity_triples(tets: np.ndarray):
    """:func:`face_multiplicity` for any ids, by lexsorting the (4m, 3) sorted triples."""
    sorted_faces, _ = face_keys(tets)
    order, gid, counts = _unique_face_counts(sorted_faces)
    bad = counts > 2
    first_rows = order[np.r_[0, np.flatnonzero(np.diff(gid)) + 1]] if len(order) else order
    return counts, sorted_faces[first_rows[bad]] if bad.any() else np.zeros((0, 3), np.int64)
