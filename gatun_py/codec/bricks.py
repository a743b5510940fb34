"""Bricked ``.tetc`` files: K bricks coded independently in one file, decoded in parallel, stitched.

A brick is a complete mesh (see :func:`gatun_py.mesh.partition.split_bricks`): it holds every
vertex its tets use, so a vertex on a cut between bricks (a *cut vertex*) is stored once in every
brick that uses it. Brick k is coded exactly as a one-brick file's content (every level with its
connectivity, geometry, point arrays and forest) under the section prefix ``B{k}/``, plus per level
a section ``B{k}/L{i}/cut`` listing which of the level's vertices (decode ids) are cut vertices and
the file-wide id of each (0 .. ``cut_points`` - 1), so that the bricks stitch back into one mesh
with each shared vertex once. File-wide ids are numbered in the order cut vertices first appear in
level 0's decode order, brick after brick: a brick's level-0 list then mostly counts up by one
(its new cut vertices) and codes in a few bits per vertex. Cut vertices are locked in every brick's decimation, so they survive
in every level and at every ratio, and bricks never crack.

The cut section::

    4 bytes  b"CUT1"
    u32      vertices of the level (must match the level's "points")
    u32      c, cut vertices listed
    u32      cut vertices of the whole file (the ids' bound)
    u32      s, the id the list's deltas start from
    rest     raw LZMA2 of 2c little-endian u32: the gaps between the sorted decode ids (first id,
             then next - previous - 1), then per vertex in that order the zigzag-coded difference
             of its file-wide id and (the previous one's, or s - 1 for the first) + 1

or, when no two cut vertices of the file have the same coordinates (the usual case), ``b"CUTP"``,
the same header with s = 0, and only the c gaps: the stitcher then matches a brick's cut vertices
to the other bricks' by their coordinates' bits (file-wide id = rank of the coordinates among the
distinct ones), which costs nothing in the file.

Decoding uses threads: the decode kernels release the GIL (``nogil=True``), so K bricks decode
on all cores in one process, and the result does not depend on the number of threads.
"""

from __future__ import annotations

import lzma
import os  # noqa: F401  (the doctests use it)
import struct
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import CorruptFileError, OptionError
from ..mesh import TetMesh
from .brickindex import BRICKS_KEY, brick_prefix
from .container import build_container
from .tetcfile import TetcReader, _chain_geometry, check_mesh, encode_level, file_meta
from .threads import check_jobs, default_jobs

__all__ = ["BrickLevels", "EncodedBrick", "encode_brick", "encode_bricked", "read_cut", "stitch_bricks",
           "decode_bricked", "map_bricks", "default_jobs"]

_CUT_HEAD = struct.Struct("<4sIIII")
_CUT_MAGIC = b"CUT1"  # positions and file-wide ids
_CUT_POINTS_MAGIC = b"CUTP"  # positions only: shared vertices are matched by their coordinates
_LZMA_FILTERS = [{"id": lzma.FILTER_LZMA2, "preset": 6}]


# -- the cut section ------------------------------------------------------------------------------

def encode_cut(cut_ids_decode_order: np.ndarray, n_cut_total: int, start: int = 0, *, ids: bool = True) -> bytes:
    """The cut section of one level of a brick: ``cut_ids_decode_order[v]`` is the file-wide cut id
    of decode vertex v, or -1 when v belongs to this brick alone; ``start``: the id the brick's new
    cut vertices are numbered from (its first listed id is coded against it). Without ``ids``,
    only which vertices are cut (the file's cut vertices have distinct coordinates: the
    coordinates say which is which)."""
    cut = np.asarray(cut_ids_decode_order, np.int64)
    pos = np.flatnonzero(cut >= 0)
    gaps = np.diff(pos, prepend=-1) - 1
    parts = [gaps]
    if ids:
        d = np.diff(cut[pos], prepend=int(start) - 1) - 1
        parts.append(np.where(d >= 0, 2 * d, -2 * d - 1))
    body = np.concatenate(parts).astype("<u4").tobytes()
    magic = _CUT_MAGIC if ids else _CUT_POINTS_MAGIC
    return _CUT_HEAD.pack(magic, cut.size, pos.size, int(n_cut_total), int(start) if ids else 0) + lzma.compress(
        body, format=lzma.FORMAT_RAW, filters=_LZMA_FILTERS)


def decode_cut(data: bytes, n_points: int, n_cut_total: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(decode ids, file-wide cut ids or None for a positions-only section) of a cut section,
    checked: ids inside the level and the file's cut count, decode ids strictly increasing, no cut
    id twice."""
    if len(data) < _CUT_HEAD.size:
        raise CorruptFileError("corrupt cut section: truncated header")
    magic, n, c, total, start = _CUT_HEAD.unpack_from(data)
    if magic not in (_CUT_MAGIC, _CUT_POINTS_MAGIC) or n != n_points or total != n_cut_total or c > n or start > total:
        raise CorruptFileError("corrupt cut section: its header disagrees with the brick index")
    width = 8 if magic == _CUT_MAGIC else 4
    try:
        dec = lzma.LZMADecompressor(format=lzma.FORMAT_RAW, filters=_LZMA_FILTERS)
        body = dec.decompress(data[_CUT_HEAD.size:], max_length=width * c + 1)
    except lzma.LZMAError:
        raise CorruptFileError("corrupt cut section: bad compressed data") from None
    if len(body) != width * c or not dec.eof or dec.unused_data:
        raise CorruptFileError("corrupt cut section: wrong length")
    v = np.frombuffer(body, "<u4").astype(np.int64)
    pos = np.cumsum(v[:c] + 1) - 1
    if c and pos[-1] >= n:
        raise CorruptFileError("corrupt cut section: a vertex out of range")
    if magic == _CUT_POINTS_MAGIC:
        return pos, None
    zz = v[c:]
    ids = start + np.cumsum(np.where(zz & 1, -(zz + 1) // 2, zz // 2) + 1) - 1
    if c and (pos[-1] >= n or ids.min() < 0 or ids.max() >= total):
        raise CorruptFileError("corrupt cut section: a vertex or cut id out of range")
    if np.unique(ids).size != c:
        raise CorruptFileError("corrupt cut section: a cut vertex is listed twice in one brick")
    return pos, ids


# -- writing --------------------------------------------------------------------------------------

@dataclass
class BrickLevels:
    """What to store for one brick.

    Attributes
    ----------
    levels : list of LevelPayload
        The brick's levels (level 0 first), as for a one-brick file.
    cut_ids : list of (n_i,) int64 arrays
        Per level, an id of every vertex of that level's mesh (its own numbering) that is shared
        with other bricks, the same in every brick that holds it (any numbering: the file's is
        assigned by :func:`encode_bricked`), -1 for a vertex of this brick alone.
    """

    levels: list
    cut_ids: list


@dataclass
class EncodedBrick:
    """Sections (names without the brick prefix), index entry and per level the cut ids of the
    vertices in decode order (the cut sections are written with the whole file) of one brick."""

    sections: dict
    entry: dict
    cut_decode: list


def encode_brick(brick: BrickLevels) -> EncodedBrick:
    """Compress one brick: every level as :func:`~gatun_py.codec.tetcfile.encode_level` does.
    Runs in a worker process (only plain data in and out)."""
    if len(brick.levels) != len(brick.cut_ids) or not brick.levels:
        raise OptionError("a brick needs one cut-id array per level")
    sections, metas, cut_decode, encoded = {}, [], [], []
    for lv, cut in zip(brick.levels, brick.cut_ids):
        cut = np.asarray(cut, np.int64)
        if cut.shape != (lv.mesh.n_points,):
            raise OptionError(f"level {lv.level}: cut ids do not match the mesh ({lv.mesh.n_points} points)")
        enc = encode_level(lv, chainable=len(brick.levels) > 1)
        encoded.append(enc)
        cut_decode.append(cut[enc.vertex_order])
        metas.append(enc.meta)
    _chain_geometry(encoded)  # within the brick: what one decode of it reads
    for enc in encoded:
        sections.update(enc.sections)
    m0 = brick.levels[0].mesh
    lo, hi = m0.bbox
    entry = {"bounds": [lo.tolist(), hi.tolist()], "points": int(m0.n_points), "tets": int(m0.n_tets),
             "boundary_faces": metas[0]["boundary_faces"], "cut_points": int((np.asarray(brick.cut_ids[0]) >= 0).sum()),
             "levels": metas}
    return EncodedBrick(sections, entry, cut_decode)


def _cut_sections(bricks: list[EncodedBrick], n_cut_total: int, ids: bool) -> list[dict]:
    """Per brick, its cut sections: cut vertices renumbered in order of first appearance in level
    0's decode order, brick after brick (so each brick's new ones count up from its ``start``)."""
    file_id = np.full(n_cut_total, -1, np.int64)
    nxt = 0
    out = []
    for b in bricks:
        seq = b.cut_decode[0]
        seq = seq[seq >= 0]
        new = seq[file_id[seq] < 0]
        start = nxt
        file_id[new] = nxt + np.arange(new.size)
        nxt += new.size
        sec = {}
        for lv, cd in zip(b.entry["levels"], b.cut_decode):
            if (file_id[cd[cd >= 0]] < 0).any():
                raise OptionError(f"level {lv['level']} of a brick has cut vertices its level 0 does not")
            first = lv["level"] == b.entry["levels"][0]["level"]
            sec[f"L{lv['level']}/cut"] = encode_cut(np.where(cd >= 0, file_id[np.maximum(cd, 0)], -1), n_cut_total,
                                                     start if first else 0, ids=ids)
        out.append(sec)
    if nxt != n_cut_total:
        raise OptionError(f"{n_cut_total} cut vertices announced, the bricks hold {nxt}")
    return out


def encode_bricked(mesh: TetMesh, bricks: list[EncodedBrick], n_cut_total: int, *, source: str = "",
                   cut_ids: bool = True) -> bytes:
    """A whole bricked file: the metadata of ``mesh`` (the unsplit mesh: counts, bounds, arrays,
    ranges, render step) with the brick index, then every brick's sections under ``B{k}/``.

    ``cut_ids``: store the cut vertices' file-wide ids; False only when no two cut vertices have
    the same coordinates (:func:`distinct_points`): then the coordinates match them up.
    """
    if len(bricks) < 2:
        raise OptionError("a bricked file has two bricks or more (one brick is a plain file)")
    check_mesh(mesh)
    meta = file_meta(mesh, len(mesh.boundary_faces()), source)
    meta["cut_points"] = int(n_cut_total)
    meta[BRICKS_KEY] = [b.entry for b in bricks]
    cuts = _cut_sections(bricks, int(n_cut_total), bool(cut_ids))
    sections = [(brick_prefix(k) + name, data) for k, b in enumerate(bricks)
                for name, data in list(b.sections.items()) + list(cuts[k].items())]
    return build_container(meta, sections)


def distinct_points(points: np.ndarray) -> bool:
    """No two rows have the same bits."""
    return np.unique(_keys(points)).size == points.shape[0]


def _keys(rows: np.ndarray) -> np.ndarray:
    """Every row's bits as one void scalar (sortable, comparable)."""
    b = _bits(rows)
    return np.ascontiguousarray(b).view(f"V{max(1, b.shape[1])}").ravel() if b.shape[1] else np.zeros(len(b), "V1")


# -- reading --------------------------------------------------------------------------------------

def read_cut(reader: TetcReader, k: int, level: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(decode ids, file-wide cut ids) of the cut vertices of brick ``k`` at ``level``."""
    b = reader.brick(k)
    n = b.level_meta(level).points
    return decode_cut(b.read_section(f"L{level}/cut"), n, int(reader.meta.get("cut_points", 0)))


def brick_jobs(jobs: int | None, n_bricks: int) -> int:
    """Threads each brick's own decode may use while :func:`map_bricks` decodes ``n_bricks`` bricks
    on ``jobs`` threads (their share of the cores: 1 once every thread has a brick)."""
    return max(1, check_jobs(jobs) // max(1, int(n_bricks)))


def map_bricks(fn, n_bricks: int, jobs: int | None = None, progress=None) -> list:
    """``[fn(k) for k in range(n_bricks)]`` on ``jobs`` threads (results in brick order, whatever
    the thread count); ``progress(1)`` after each brick."""
    jobs = min(check_jobs(jobs), n_bricks)

    def one(k):
        out = fn(k)
        if progress is not None:
            progress(1)
        return out

    if jobs <= 1:
        return [one(k) for k in range(n_bricks)]
    with ThreadPoolExecutor(jobs, thread_name_prefix="tetc-brick") as pool:
        return list(pool.map(one, range(n_bricks)))


@dataclass
class StitchPlan:
    """Where every vertex and tet of every brick goes in the stitched mesh.

    Attributes
    ----------
    out_id : list of (n_k,) int32
        Output id of every vertex of brick k.
    placed : list of (n_k,) bool
        The vertices brick k writes (its own, and the cut vertices no earlier brick holds).
    shared : list of ((s,) int64, (s,) int64)
        Brick k's cut vertices an earlier brick placed, and their output ids (must be equal there).
    tet_start : (K + 1,) int64
        First output tet of every brick.
    n_points : int
    """

    out_id: list
    placed: list
    shared: list
    tet_start: np.ndarray
    n_points: int


def plan_stitch(n_points: list[int], n_tets: list[int], cuts: list[tuple[np.ndarray, np.ndarray]],
                n_cut_total: int) -> StitchPlan:
    """The stitch of bricks of these sizes and cut lists: the vertices of brick 0 in order, then each
    next brick's vertices but the cut vertices already placed; tets in brick order. Raises
    :class:`CorruptFileError` when a cut id of the file is in no brick."""
    first = np.full(n_cut_total, -1, np.int64)  # output id of every cut vertex, once placed
    out_ids, placed, shared, total = [], [], [], 0
    for n, (pos, ids) in zip(n_points, cuts):
        seen = first[ids] >= 0
        new = np.ones(n, bool)
        new[pos[seen]] = False
        out_id = np.empty(n, np.int32)
        n_new = int(new.sum())
        out_id[new] = total + np.arange(n_new)
        out_id[pos[seen]] = first[ids[seen]]
        first[ids[~seen]] = out_id[pos[~seen]]
        out_ids.append(out_id)
        placed.append(new)
        shared.append((pos[seen], first[ids[seen]]))
        total += n_new
    if (first < 0).any():
        raise CorruptFileError("corrupt file: a cut vertex of the index belongs to no brick")
    return StitchPlan(out_ids, placed, shared, np.concatenate([[0], np.cumsum(n_tets)]).astype(np.int64), total)


class _Stitched:
    """The output arrays of a stitch, filled brick by brick (from any thread: bricks write disjoint rows)."""

    def __init__(self, plan: StitchPlan, points_dtype, arrays: list, scalar_name: str):
        self.plan = plan
        self.scalar_name = scalar_name
        self.points = np.empty((plan.n_points, 3), points_dtype)
        self.data = {name: np.empty((plan.n_points,) if k == 1 else (plan.n_points, k), dt) for name, dt, k in arrays}
        self.tets = np.empty((int(plan.tet_start[-1]), 4), np.int32)
        self.checks = [None] * len(plan.out_id)

    def put(self, k: int, mesh: TetMesh) -> None:
        """Write brick k; keep its shared vertices' values to check once every brick is in."""
        p = self.plan
        if mesh.n_points != p.out_id[k].shape[0] or mesh.n_tets != p.tet_start[k + 1] - p.tet_start[k]:
            raise CorruptFileError(f"corrupt file: brick {k} decodes to other counts than its index says")
        if sorted(mesh.point_data) != sorted(self.data) or mesh.points.dtype != self.points.dtype:
            raise CorruptFileError(f"corrupt file: brick {k} holds other arrays than the file")
        new, (pos, _) = p.placed[k], p.shared[k]
        dest = p.out_id[k][new]
        pairs = [(self.points, mesh.points)] + [(self.data[name], mesh.point_data[name]) for name in self.data]
        for out, a in pairs:
            out[dest] = a[new]
        self.tets[p.tet_start[k]:p.tet_start[k + 1]] = p.out_id[k][mesh.tets]
        self.checks[k] = [_bits(a[pos]) for _, a in pairs]

    def mesh(self) -> TetMesh:
        """The stitched mesh, after checking that every shared vertex is the same in every brick."""
        for k, (_, dest) in enumerate(self.plan.shared):
            outs = [self.points] + list(self.data.values())
            if any(not np.array_equal(_bits(out[dest]), got) for out, got in zip(outs, self.checks[k])):
                raise CorruptFileError(f"corrupt file: a cut vertex differs between brick {k} and an earlier brick")
        try:
            return TetMesh(self.points, None, self.tets, self.scalar_name, point_data=self.data)
        except Exception as e:  # a stitched mesh that fails its invariants can only come from damage
            raise CorruptFileError(f"corrupt file: the stitched mesh is invalid ({e})") from None


def stitch_bricks(meshes: list[TetMesh], cuts: list[tuple[np.ndarray, np.ndarray | None]], n_cut_total: int,
                  *, n_points: int | None = None, jobs: int | None = 1) -> TetMesh:
    """One mesh from its bricks (see :func:`plan_stitch`), written by ``jobs`` threads.

    Parameters
    ----------
    meshes : list of TetMesh
        The bricks, in order (the list is emptied as they are written).
    cuts : list of (vertex ids, cut ids or None)
        Per brick, its cut vertices (ids in its mesh) and their file-wide ids; None (every brick
        alike): the cut vertices are told apart by their coordinates.
    n_cut_total : int
    n_points : int, optional
        The expected vertex count of the result (checked).

    Raises
    ------
    CorruptFileError
        A cut vertex whose coordinates or values differ between two bricks, or counts that do
        not add up.
    """
    cuts = _ids_from_points(meshes, cuts, n_cut_total)
    plan = plan_stitch([m.n_points for m in meshes], [m.n_tets for m in meshes], cuts, n_cut_total)
    if n_points is not None and plan.n_points != n_points:
        raise CorruptFileError(f"corrupt file: the bricks stitch into {plan.n_points} vertices, "
                               f"the metadata says {n_points}")
    m0 = meshes[0]
    out = _Stitched(plan, m0.points.dtype, m0.arrays, m0.scalar_name)

    def put(k):
        out.put(k, meshes[k])
        meshes[k] = None  # its memory goes as soon as it is written

    map_bricks(put, len(meshes), jobs)
    return out.mesh()


def _ids_from_points(meshes, cuts, n_cut_total: int) -> list:
    """``cuts`` with file-wide ids: as stored, or (positions-only sections) the rank of each cut
    vertex's coordinates among the distinct ones of all bricks."""
    kinds = {ids is None for _, ids in cuts}
    if kinds == {False}:
        return cuts
    if kinds != {True}:
        raise CorruptFileError("corrupt file: some cut sections list ids, others do not")
    keys = [_keys(m.points[pos]) for m, (pos, _) in zip(meshes, cuts)]
    uniq, inverse = np.unique(np.concatenate(keys), return_inverse=True)
    if uniq.size != n_cut_total:
        raise CorruptFileError(f"corrupt file: the bricks' cut vertices have {uniq.size} distinct positions, "
                               f"the file has {n_cut_total} cut vertices")
    bounds = np.cumsum([0] + [len(k) for k in keys])
    out = []
    for k, (pos, _) in enumerate(cuts):
        ids = inverse.ravel()[bounds[k]:bounds[k + 1]].astype(np.int64)
        if np.unique(ids).size != ids.size:
            raise CorruptFileError(f"corrupt file: two cut vertices of brick {k} have the same position")
        out.append((pos, ids))
    return out


def _bits(a: np.ndarray) -> np.ndarray:
    """The raw bytes of every row (so that NaN payloads and -0.0 compare bit for bit)."""
    a = np.ascontiguousarray(a)
    return a.view(np.uint8).reshape(a.shape[0], a.itemsize * int(np.prod(a.shape[1:])))


def decode_bricked(source, level: int = 0, *, jobs: int | None = None, progress=None) -> TetMesh:
    """Decode ``level`` of every brick on ``jobs`` threads (default: all cores) and stitch them.

    Bricks decode on threads, then (on threads too) each writes its rows of the stitched mesh;
    the result is the same whatever ``jobs`` is:
    vertices of brick 0 in its decode order, then each next brick's vertices that no earlier brick
    holds; tets in brick order. For a file of one brick, the plain :meth:`TetcReader.decode_mesh`.

    Examples
    --------
    >>> import gatun_py, tempfile, os
    >>> from gatun_py.warmup import tiny_mesh
    >>> out = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
    >>> f = gatun_py.compress(tiny_mesh(), out, bricks=2, mesh_only=True, jobs=1)
    >>> decode_bricked(out, jobs=2).n_tets
    90
    """
    reader = source if isinstance(source, TetcReader) else TetcReader(source)
    if reader.n_bricks == 1:
        return reader.decode_mesh(level, jobs=jobs)
    bricks = [reader.brick(k) for k in range(reader.n_bricks)]
    missing = [k for k, b in enumerate(bricks) if level not in {lv.level for lv in b.levels}]
    if missing:
        raise OptionError(f"level {level} is not stored in every brick (missing in brick {missing[0]}); "
                          f"stored in all: {[lv.level for lv in reader.levels]}")
    cuts = [read_cut(reader, k, level) for k in range(len(bricks))]  # checked before the long work
    per_brick = brick_jobs(jobs, len(bricks))
    meshes = map_bricks(lambda k: bricks[k].decode_mesh(level, jobs=per_brick), len(bricks), jobs, progress)
    return stitch_bricks(meshes, cuts, int(reader.meta["cut_points"]), jobs=jobs,
                         n_points=int(reader.meta["points"]) if level == 0 else None)
