"""Cut-border connectivity coding (paper section 3.1).

Two range-coded streams:

* **boundary**: the boundary surface, coded first with a breadth-first triangle cut-border (as in
  [MC98]): a FIFO of directed border edges; the unvisited triangle across each edge is given by
  its apex, coded as an index into the candidate apexes that would close adjacent border edges,
  or as a new vertex, or as a vertex-table index. A new connected piece of the surface starts
  with a seed triangle (three vertices, each new or a table index).
* **tets**: the current surface T starts as the boundary; each face of T, first in first out,
  pairs with its unvisited tet, whose fourth vertex is coded as one of the paper's four cases:
  (a) one of the apexes of faces of T adjacent to an edge of the current face, (b) a new vertex,
  (c) an index into the ordered list of vertices of faces that share only a vertex with the
  current face, (d) a vertex-table index. The three other faces of the tet close faces of T or
  join it.

The paper orders the edge-adjacent faces by edge and then traversal order; we rank the distinct
apexes instead by a learnt probability of their *class* (how many faces of T they would close,
how many decoded tets hold them and the ends of their gate edge, whether they are on the
boundary), which makes index 0 far more likely, and code the index with adaptive models whose
context is the two best candidates' probabilities (:mod:`gatun_py.codec._cutborder_kernels`).
The case (c) list is ordered by decoded tets, fewest first. This is tet coding 2, what files of
format 5 on hold; :mod:`gatun_py.codec.formats` says which coding a file has, and files of
formats 1 to 4 decode with the frozen coding 1 (:mod:`gatun_py.codec.legacy.tets1`).

Vertex numbering (decode order): boundary vertices in the order the boundary code meets them,
then interior vertices in the order the tet code meets them, then unreferenced vertices.
Every new vertex gets up to three *predictor* vertices (decode ids, -1 if none) for the
geometry coder: the current face for interior vertices, the border edge and the apex of the
triangle it came from for boundary vertices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CorruptFileError, MeshError
from . import _cutborder_kernels as K
from . import rangecoder as rc
from .formats import CURRENT, codings

CODINGS = (1, 2)


def coding_for_format(major: int) -> int:
    """The tet-stream coding of a file of format ``major`` (:mod:`gatun_py.codec.formats`)."""
    return codings(major).tets


# what this version of tetc writes
FORMAT_CODING = CURRENT.tets


def _tets1():
    """The frozen tet coding 1 (formats 1 to 4), imported when a file of those versions is read:
    today's files never compile its kernels."""
    from .legacy import tets1

    return tets1


@dataclass
class EncodedConnectivity:
    """The output of :func:`encode_connectivity`.

    Attributes
    ----------
    boundary_code, tet_code : bytes
        The two range-coded streams.
    n_points, n_tets, n_boundary_faces, n_boundary_vertices, n_referenced : int
        Counts the decoder needs (stored in the container's section header).
    vertex_order : (n_points,) int64
        ``vertex_order[k]`` = original id of the k-th decoded vertex.
    predictors : (n_points, 4) int32
        Geometry refs of every vertex in decode order (decode ids, -1 for none): the face
        (a, b, c) it closes and the apex behind it (interior), or (p, r, -1, apex) for a boundary
        vertex attached across edge (p, r); see :mod:`gatun_py.codec.geometry`.
    boundary : (n_boundary_faces, 3) int32
        Boundary faces in decode order and decode ids (what the decoder will produce).
    tets : (n_tets, 4) int32
        Tets in decode order and decode ids.
    peak_border : int
        Largest number of faces on the cut border during the tet phase.
    symbols : (n_tets,) int16
        Each tet's case, for statistics and tests: the index of its fourth vertex among the
        edge-adjacent candidates (paper case a), or 15 + 0 / 1 / 2 for a new vertex (b), an index
        into the vertex-adjacent list (c), a vertex-table index (d); coding 2 ranks the candidates
        its own way (:mod:`gatun_py.codec._cutborder_kernels`).
    coding : int
        The tet stream's coding (1 or 2).
    """

    boundary_code: bytes
    tet_code: bytes
    n_points: int
    n_tets: int
    n_boundary_faces: int
    n_boundary_vertices: int
    n_referenced: int
    vertex_order: np.ndarray
    predictors: np.ndarray
    boundary: np.ndarray
    tets: np.ndarray
    peak_border: int
    symbols: np.ndarray
    coding: int = 1


def _sorted_halfedges(faces: np.ndarray):
    he = np.sort(np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    fid = np.repeat(np.arange(len(faces), dtype=np.int64), 3)
    order = np.lexsort((he[:, 1], he[:, 0]))
    return np.ascontiguousarray(he[order], dtype=np.int64), fid[order]


# border slots, list nodes (3 per slot) and sequence numbers are int32 in the kernels
MAX_TETS = 1 << 29

_ENCODER_ERRORS = {
    1: "the cut border emptied before every tet was visited",
    2: "a border face has no unvisited tet behind it",
    3: "a tet face is shared inconsistently",
    4: "internal capacity exceeded",
    5: "faces left on the cut border after the last tet",
}


def encode_connectivity(points_count: int, tets: np.ndarray, boundary=None, *,
                        coding: int = FORMAT_CODING) -> EncodedConnectivity:
    """Code the connectivity of a valid tet mesh.

    Parameters
    ----------
    points_count : int
        Number of vertices (ids in ``tets`` are below it; unreferenced ones are allowed).
    tets : (m, 4) int array
        Positively oriented tets (as in :class:`~gatun_py.mesh.TetMesh`); the boundary surface
        is the set of faces used by one tet, as ``TetMesh.boundary_faces``.
    boundary : ignored
        Accepted for compatibility; the boundary is always derived from ``tets``.
    coding : {1, 2}
        The tet stream's coding (:func:`coding_for_format`); the default is what this version
        writes.

    Returns
    -------
    EncodedConnectivity

    Raises
    ------
    MeshError
        If a face is shared by more than two tets (validation rejects such meshes earlier).
    """
    if coding not in CODINGS:
        raise ValueError(f"coding must be one of {CODINGS}, got {coding!r}")
    n = int(points_count)
    tets = np.asarray(tets).reshape(-1, 4)
    m = len(tets)
    if m >= MAX_TETS or n >= MAX_TETS:
        raise MeshError(f"mesh too large for the .tetc format ({m} tets, {n} points; limit {MAX_TETS - 1})")
    if m and (int(tets.min()) < 0 or int(tets.max()) >= n):
        raise MeshError(f"tet vertex ids must lie in 0..{n - 1}, got {int(tets.min())}..{int(tets.max())}")
    # ids < n < 2**29 and tet ids < m < 2**29: the kernels' tables are int32 (16 bytes per tet each)
    tets = np.ascontiguousarray(tets, dtype=np.int32)
    nbr = np.empty((m, 4), np.int32)
    if K.tet_neighbours(tets, nbr):
        raise MeshError("a face is shared by more than two tets: the mesh is not conforming")
    faces = np.empty((int(np.count_nonzero(nbr == -1)), 3), np.int64)
    owner = np.empty(len(faces), np.int64)
    nf = K.boundary_from_neighbours(tets, nbr, faces, owner)
    if nf + 2 * m + 8 >= K.MAX_SLOTS:  # the cut border of the tet phase holds up to nf + 2 m faces
        raise MeshError(f"mesh too large for one .tetc stream ({m} tets, {nf} boundary faces): split it into bricks")

    dec_of = np.full(max(n, 1), -1, np.int64)
    order = np.full(max(n, 1), -1, np.int64)
    pred = np.full((max(n, 1), 4), -1, np.int32)
    out_faces = np.zeros((nf, 3), np.int32)
    face_src = np.zeros(nf, np.int64)
    hkey, hface = _sorted_halfedges(faces) if nf else (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))

    def run_boundary(st, out):
        dec_of[:] = -1
        order[:] = -1
        pred[:] = -1
        B = K.new_border(n, 3 * nf + 8, 3 * nf + 8)
        res = K.encode_boundary(st, out, faces, hkey, hface, n, B, dec_of, order, pred, out_faces, face_src)
        run_boundary.result = res

    boundary_code = rc.run_encoder(run_boundary, capacity=rc.capacity_hint(nf * 4))
    nbv, code = run_boundary.result
    if code:
        raise MeshError(f"boundary surface cannot be coded (code {code}): is the mesh valid?")

    out_tets = np.zeros((m, 4), np.int32)
    symbols = np.zeros(m, np.int16)
    # boundary face i (original order) is out_faces[j] for the j-th decoded face: map owners over
    bowner = owner[face_src]
    dec_b, order_b, pred_b = dec_of.copy(), order.copy(), pred.copy()

    def run_tets(st, out):
        dec_of[:] = dec_b
        order[:] = order_b
        pred[:] = pred_b
        # each tet takes its face off the border and adds at most three: at most nf + 2 m live
        B = K.new_border(n, nf + 2 * m + 8, nf + 3 * m + 8)
        tgt = np.full(nf + 3 * m + 8, -1, np.int32)
        tgt[K.add_faces(B, out_faces, -1)] = bowner
        if coding == 1:  # the frozen coding, kept for the tests' round trips
            res = _tets1().encode_tets(st, out, tets, nbr, tgt, B, dec_of, order, pred, nbv, out_tets, symbols)
        else:
            res = K.encode_tets(st, out, tets, nbr, tgt, B, dec_of, order, pred, nbv, out_tets, symbols,
                                K.new_rank_model(), np.zeros(max(n, 1), np.uint8))
        run_tets.result = res
        run_tets.peak = int(B[3][K.BS_PEAK])

    tet_code = rc.run_encoder(run_tets, capacity=rc.capacity_hint(m * 2))
    nref, code = run_tets.result
    if code:
        raise MeshError(f"tet connectivity cannot be coded: {_ENCODER_ERRORS.get(code, code)}; is the mesh valid?")
    # unreferenced vertices: last, in their original order
    if m == 0:  # nothing coded: empty streams (the decoder insists on it)
        boundary_code, tet_code = b"", b""
    rest = np.flatnonzero(dec_of[:n] == -1)
    order[nref:n] = rest
    return EncodedConnectivity(
        boundary_code=boundary_code, tet_code=tet_code, n_points=n, n_tets=m, n_boundary_faces=nf,
        n_boundary_vertices=int(nbv), n_referenced=int(nref), vertex_order=order[:n].copy(),
        predictors=pred[:n].copy(), boundary=out_faces, tets=out_tets, peak_border=run_tets.peak,
        symbols=symbols, coding=coding,
    )


def _tets_out(out: np.ndarray, k: int) -> np.ndarray:
    """The first ``k`` rows of a caller's output array, checked (the kernels write it unchecked)."""
    if (not isinstance(out, np.ndarray) or out.dtype != np.int32 or out.ndim != 2 or out.shape[1] != 4
            or len(out) < k or not out.flags.c_contiguous or not out.flags.writeable):
        raise ValueError(f"out must be a writeable C-contiguous (>= {k}, 4) int32 array")
    return out[:k]


class ConnectivityDecoder:
    """Streaming decoder of the two connectivity streams.

    Parameters
    ----------
    boundary_code, tet_code : bytes
        The streams written by :func:`encode_connectivity`.
    n_points, n_tets, n_boundary_faces, n_referenced : int
        Counts from the section header (checked against what the streams produce).
    coding : {1, 2}, default 1
        The tet stream's coding (:func:`coding_for_format` of the file's format).
    keep_predictors : bool, default True
        Keep the geometry refs of every vertex in :attr:`predictors`. A streaming reader that
        takes each batch's refs from :attr:`last_refs` passes False: the tet phase then holds
        only the refs of the last batch (16 bytes per vertex less at the end of a level).

    Attributes
    ----------
    predictors : (n_points, 4) int32 or None
        Geometry refs by decode id (rows of vertices not decoded yet are -1); None in the tet
        phase without ``keep_predictors``.
    last_refs : (k, 4) int32
        Refs of the vertices introduced by the last :meth:`boundary` or :meth:`next_tets` call
        (valid until the next call).
    """

    def __init__(self, boundary_code, tet_code, *, n_points, n_tets, n_boundary_faces, n_referenced,
                 coding: int = 1, keep_predictors: bool = True):
        if coding not in CODINGS:
            raise CorruptFileError(f"unknown connectivity coding {coding!r}")
        self.coding = int(coding)
        self.n_points = int(n_points)
        self.n_tets = int(n_tets)
        self.n_boundary_faces = int(n_boundary_faces)
        self.n_referenced = int(n_referenced)
        if self.n_tets >= MAX_TETS or self.n_points >= MAX_TETS:
            raise CorruptFileError("corrupt connectivity header: counts beyond the format's limits")
        if not (0 <= self.n_referenced <= self.n_points):
            raise CorruptFileError("corrupt connectivity header: inconsistent vertex counts")
        # every element added to a border gets an int32 sequence number (and the queue holds them):
        # the boundary adds fewer than 3 per face, the tets fewer than 3 per tet
        if 3 * self.n_boundary_faces + 3 * self.n_tets + 64 >= K.MAX_SEQ or self.n_boundary_faces < 0:
            raise CorruptFileError("corrupt connectivity header: counts beyond the format's limits")
        self._bdata = np.frombuffer(boundary_code, dtype=np.uint8)
        self._tdata = np.frombuffer(tet_code, dtype=np.uint8)
        self.predictors = np.full((max(self.n_points, 1), 4), -1, np.int32)
        self.keep_predictors = bool(keep_predictors)
        self.last_refs = self.predictors[:0]
        self.peak_border = 0
        self._tstate = None

    def boundary(self):
        """Decode the boundary surface: returns (faces (b, 3) int32, number of boundary vertices)."""
        nf = self.n_boundary_faces
        faces = np.zeros((nf, 3), np.int32)
        B = K.new_border(self.n_points, 3 * nf + 8, 3 * nf + 8, queue_dtype=np.int32)
        st = rc.dec_state()
        if nf:
            nv, status = K.decode_boundary(st, self._bdata, nf, self.n_points, B, self.predictors, faces)
            if status != K.ST_DONE:
                raise CorruptFileError("corrupt boundary section: the surface code is inconsistent")
            rc.check_decoder(st, self._bdata, "boundary section")
        else:
            nv = 0
            if len(self._bdata):
                raise CorruptFileError("corrupt boundary section: unexpected data")
        if self.n_tets and nv > self.n_referenced:
            raise CorruptFileError("corrupt boundary section: too many vertices")
        self._nbv = int(nv)
        self._faces = faces
        self.last_refs = self.predictors[:nv]
        return faces, int(nv)

    def start_tets(self):
        """Prepare the tet phase (after :meth:`boundary`)."""
        nf = self.n_boundary_faces
        cap = max(64, 2 * nf)
        self._B = K.new_border(self.n_points, cap, cap, queue_dtype=np.int32)
        K.add_faces(self._B, self._faces, -1)
        self._faces = None  # the caller has them; the border holds what the tets need
        self._tst = rc.dec_state()
        # [vertices known, tets done, prev_esc, prev_flip, decode id of the predictors' row 0]
        self._tstate = np.array([self._nbv, 0, 0, 0, 0], np.int64)
        if not self.keep_predictors:  # from here on, a window of the newest vertices' refs
            self.predictors = None
            self._window = np.empty((0, 4), np.int32)
        self.last_refs = np.empty((0, 4), np.int32)
        if self.coding == 1:
            self._probs = np.full(_tets1().TM_SIZE, rc.PROB_INIT, np.uint16)
        else:  # the class probabilities and decoded-tet counts persist between batches too
            self._probs = np.full(K.TM_SIZE, rc.PROB_INIT, np.uint16)
            self._rankp = K.new_rank_model()
            self._vdec = np.zeros(max(self.n_points, 1), np.uint8)
        if self.n_tets:
            rc.dec_init(self._tst, self._tdata)
        elif len(self._tdata):
            raise CorruptFileError("corrupt tet section: unexpected data")
        elif self._nbv != self.n_referenced or nf:
            raise CorruptFileError("corrupt connectivity: counts do not match")

    @property
    def vertices_known(self) -> int:
        return int(self._tstate[0])

    @property
    def tets_done(self) -> int:
        return int(self._tstate[1])

    def next_tets(self, max_tets: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """Decode up to ``max_tets`` more tets (fewer only at the end); (j, 4) int32 decode ids.

        ``out``, a C-contiguous (k, 4) int32 array with k >= j, receives them (its first j rows are
        returned): a caller assembling the whole level decodes into its own array, uncopied."""
        k = min(max_tets, self.n_tets - self.tets_done)
        if out is None:
            out = np.zeros((k, 4), np.int32)
        else:
            out = _tets_out(out, k)
        first = self.vertices_known
        if self.keep_predictors:
            pred = self.predictors
        else:  # each tet introduces at most one vertex: len(out) rows, reused across batches
            if len(self._window) < len(out):
                self._window = np.empty((len(out), 4), np.int32)
            pred = self._window[:len(out)]
            pred.fill(-1)
            self._tstate[4] = first
        filled = 0
        while filled < len(out):
            if self.coding == 1:
                n, status = _tets1().decode_tets(self._tst, self._tdata, self._probs, self.n_tets, self.n_referenced,
                                                 self._B, pred, self._tstate, out[filled:])
            else:
                n, status = K.decode_tets(self._tst, self._tdata, self._probs, self._rankp, self._vdec, self._nbv,
                                          self.n_tets, self.n_referenced, self._B, pred, self._tstate, out[filled:])
            filled += n
            if status == K.ST_GROW:
                if len(self._B[0]) // K.E_COLS + 64 >= K.MAX_SLOTS:
                    raise CorruptFileError("corrupt tet section: the cut border grows beyond any mesh's")
                self._B = K.grow_border(self._B, 64, 64)
            elif status == K.ST_ERROR:
                raise CorruptFileError("corrupt tet section: the connectivity code is inconsistent")
            elif status == K.ST_DONE:
                break
        self.peak_border = max(self.peak_border, int(self._B[3][K.BS_PEAK]))
        known = self.vertices_known
        self.last_refs = self.predictors[first:known] if self.keep_predictors else pred[:known - first]
        if self.tets_done == self.n_tets:
            self._B = None  # empty now: the decoder may outlive its level (a consumer's reference)
            rc.check_decoder(self._tst, self._tdata, "tet section")
            if self.vertices_known != self.n_referenced:
                raise CorruptFileError("corrupt tet section: vertex count does not match the header")
        return out[:filled]
