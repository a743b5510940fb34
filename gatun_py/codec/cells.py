"""The cells as given, coded against the decoded tets: the ``C/...`` sections and ``cells`` metadata.

The tets a file decodes are the split of the input's volume cells (:mod:`gatun_py.mesh.split`). So
the cells are not stored as a second connectivity; what is stored is what the tets do not say:

* **groups**: which cell each decoded tet belongs to. Cells are numbered in *traversal order*, the
  order of their first tet in decode order. Per tet one symbol: 0 the first tet of a new cell,
  ``j`` (1-5) the cell of the ``j``-th candidate (the previous tet, then the earlier face
  neighbours, most recent first), 6 an escape followed by the cell's rank counted back from the
  newest (``C/escapes``). With several volume blocks, each new cell's block (``C/blocks``).
* **vertex order**: the corners of a cell are the vertices of its tets; listed in order of first
  appearance over its tets in decode order they give ``U``, and the cell's own order is a
  permutation of ``U``. Per block a palette of the permutations that occur (``C/palettes``), per
  cell its index (``C/perms``): coherent meshes use a handful.
* **higher-order nodes** (quadratic cells, points no tet refers to): each node sits on an edge or
  face of its cell (:data:`gatun_py.mesh.cells.NODE_SUPPORTS`); a node already placed on that edge
  or face by an earlier cell is predicted (a flag, ``C/node_flags``), any other is coded as its
  decode id against the last new one (``C/node_ids``).
* **other blocks** (triangles, quads, lines, vertices): their ids in decode numbering as given
  (``C/other/{b}``).
* **cell arrays**, every component in its dtype, coded per block in the block's output order,
  each cell predicted from its earlier face-neighbouring cells (Courbet & Isenburg's prediction
  across faces, with :mod:`.arrays`' predictors and coders): ``C/data/{j}/{b}``.
* **field data** (in the metadata, exact bytes), **point sets** and **cell sets**
  (``C/pset/{j}``, ``C/cset/{j}/{b}``).

Every integer stream is coded by :func:`~.arrays.encode_array` (range coder or xz planes,
whichever is smaller). A decoded volume block lists its cells in traversal order; the blocks keep
their file order, each cell its vertex order.
"""

from __future__ import annotations

import base64
import lzma

import numpy as np

from ..errors import CorruptFileError, MeshError
from ..mesh.model import TetMesh
from ..mesh.cells import NODE_SUPPORTS, OTHER_CELLS, VOLUME_CELLS, Cells, cell_size, is_raw_set
from . import _cutborder_kernels as CK
from .arrays import MAX_COMPONENTS, ArrayDecoder, check_dtype, dtype_name, encode_array

NEW, ESCAPE = 0, 6
_CANDIDATES = 5


# -- shared by both sides -------------------------------------------------------------------------

def _neighbours(tets: np.ndarray) -> np.ndarray:
    t = np.ascontiguousarray(tets, dtype=np.int32)
    nbr = np.empty((len(t), 4), np.int32)
    if len(t) and CK.tet_neighbours(t, nbr):
        raise CorruptFileError("corrupt file: a face is shared by more than two tets")
    return nbr


def _candidates(nbr: np.ndarray) -> np.ndarray:
    """(m, 5) earlier tets whose cell a tet may share: the previous tet, then the earlier face
    neighbours, most recent first (-1: none)."""
    m = len(nbr)
    idx = np.arange(m)
    nb = np.where(nbr.astype(np.int64) < idx[:, None], nbr, -1).astype(np.int64)
    nb = -np.sort(-nb, axis=1)
    return np.column_stack([idx - 1, nb])


def _first_appearance(cellrank: np.ndarray, tets: np.ndarray, n_cells: int, n_points: int):
    """(U vertices, start of each cell's run, its length): every cell's distinct tet vertices in the
    order they first appear over its tets in decode order."""
    order = np.argsort(cellrank, kind="stable")
    verts = np.asarray(tets, np.int64)[order].reshape(-1)
    owner = np.repeat(cellrank[order], 4)
    _, first = np.unique(owner * max(n_points, 1) + verts, return_index=True)
    first.sort()
    u, uo = verts[first], owner[first]
    counts = np.bincount(uo, minlength=n_cells)
    starts = np.zeros(n_cells, np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    return u, starts, counts


def _prev_refs(n: int) -> np.ndarray:
    refs = np.full((n, 4), -1, np.int32)
    refs[1:, 0] = np.arange(n - 1)
    return refs


def _code(values, refs=None, positions=None) -> bytes:
    values = np.ascontiguousarray(values)
    if values.shape[0] == 0:
        return b""
    return encode_array(values, _prev_refs(len(values)) if refs is None else refs, positions=positions)


def _decode(data: bytes, n: int, dtype: str, k: int = 1, refs=None, positions=None) -> np.ndarray:
    if n == 0:
        if data:
            raise CorruptFileError("corrupt cells section: data for no values")
        return np.zeros((0,) if k == 1 else (0, k), check_dtype(dtype))
    dec = ArrayDecoder(data, n_points=n, dtype=dtype, components=k)
    pos4 = None
    if positions is not None:
        pos4 = np.zeros((n, 4), np.float32)
        pos4[:, :3] = positions
    dec.decode(_prev_refs(n) if refs is None else refs, positions=pos4)
    return dec.finish()


_TAG_PREDICTED, _TAG_XZ, _TAG_CONSTANT, _TAG_ARITHMETIC = 0, 1, 2, 3


def _arithmetic(values: np.ndarray):
    """(first, step) when the integer values are ``first + i * step`` (a counter such as VTK's
    CellId in the order given), else None."""
    if values.ndim != 1 or values.dtype.kind not in "iu" or len(values) < 2:
        return None
    if values.dtype == np.uint64 and int(values.max()) >= 1 << 63:
        return None
    v = values.astype(np.int64)
    first, step = int(v[0]), int(v[1]) - int(v[0])
    if not -(1 << 62) < step < 1 << 62:
        return None
    with np.errstate(over="ignore"):
        again = np.int64(first) + np.arange(len(v), dtype=np.int64) * np.int64(step)
    return (first, step) if np.array_equal(again, v) else None


def _code_values(values, refs, positions) -> bytes:
    """A cell array's stream: a tag byte, then one row when every row has the same bytes (a tag
    per block, a constant), the first value and step of an integer counter, the predicted coding
    (:func:`_code`) or, when smaller, ``xz -9`` of the raw little-endian values in this order
    (long repeats, as in arrays that cycle, are what xz finds and a predictor does not)."""
    values = np.ascontiguousarray(values)
    le = values.astype(values.dtype.newbyteorder("<"))
    rows = np.ascontiguousarray(le.reshape(len(le), -1)).view(np.uint8)
    if len(rows) and np.all(rows == rows[:1]):  # bit for bit: -0.0 is not 0.0, NaN payloads count
        return bytes([_TAG_CONSTANT]) + rows[0].tobytes()
    ar = _arithmetic(values)
    if ar is not None:
        return bytes([_TAG_ARITHMETIC]) + np.array(ar, "<i8").tobytes()
    predicted = _code(values, refs, positions)
    raw = lzma.compress(le.tobytes(), preset=9 | lzma.PRESET_EXTREME)
    if len(raw) < len(predicted):
        return bytes([_TAG_XZ]) + raw
    return bytes([_TAG_PREDICTED]) + predicted


def _decode_values(data: bytes, n: int, dtype: str, k: int, refs, positions) -> np.ndarray:
    if not data or data[0] not in (_TAG_PREDICTED, _TAG_XZ, _TAG_CONSTANT, _TAG_ARITHMETIC):
        raise CorruptFileError("corrupt cells section: bad cell array stream")
    if data[0] == _TAG_PREDICTED:
        return _decode(data[1:], n, dtype, k, refs, positions)
    dt = check_dtype(dtype)
    if data[0] == _TAG_CONSTANT:
        if len(data) != 1 + k * dt.itemsize:
            raise CorruptFileError("corrupt cells section: a constant cell array has the wrong length")
        row = np.frombuffer(data[1:], dt)
        out = np.repeat(row[None, :], n, axis=0)
        return out.reshape(n) if k == 1 else out
    if data[0] == _TAG_ARITHMETIC:
        if len(data) != 17 or k != 1 or dt.kind not in "iu":
            raise CorruptFileError("corrupt cells section: bad counter cell array")
        first, step = (int(x) for x in np.frombuffer(data[1:], "<i8"))
        with np.errstate(over="ignore"):
            return (np.int64(first) + np.arange(n, dtype=np.int64) * np.int64(step)).astype(dt)
    size = n * k * dt.itemsize
    try:
        dec = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)
        body = dec.decompress(data[1:], max_length=size + 1)
    except lzma.LZMAError as e:
        raise CorruptFileError(f"corrupt cells section: {e}") from None
    if len(body) != size or not dec.eof or dec.unused_data:
        raise CorruptFileError("corrupt cells section: a cell array has the wrong length")
    a = np.frombuffer(body, dt).copy()
    return a if k == 1 else a.reshape(n, k)


def _centroids(points32: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(n, 3) float32 centre of each cell's corners: what the linear predictor of a cell array
    evaluates its neighbours' field at (the same bits on both sides: float32 points, the cell's
    own vertex order, float64 sums)."""
    c = np.asarray(corners, np.int64)
    return (points32[c].astype(np.float64).sum(axis=1) / c.shape[1]).astype(np.float32)


def _zigzag(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, np.int64)
    return (v << 1) ^ (v >> 63)


def _unzigzag(z: np.ndarray) -> np.ndarray:
    z = np.asarray(z, np.int64)
    return (z >> 1) ^ -(z & 1)


def _cell_refs(pairs: np.ndarray, pos: np.ndarray, n: int) -> np.ndarray:
    """(n, 4) refs of a block's cells in its output order: up to four earlier face-neighbouring
    cells of the block, most recent first. ``pairs``: (c, d) rank pairs of face neighbours;
    ``pos``: position of a rank in the block (-1: not in it)."""
    refs = np.full((n, 4), -1, np.int32)
    if not len(pairs):
        return refs
    pc, pd = pos[pairs[:, 0]], pos[pairs[:, 1]]
    keep = (pc >= 0) & (pd >= 0) & (pd < pc)
    pc, pd = pc[keep], pd[keep]
    if not len(pc):
        return refs
    order = np.lexsort((-pd, pc))
    pc, pd = pc[order], pd[order]
    first = np.r_[0, np.flatnonzero(np.diff(pc)) + 1]
    run = np.arange(len(pc)) - np.repeat(first, np.diff(np.r_[first, len(pc)]))
    sel = run < 4
    refs[pc[sel], run[sel]] = pd[sel]
    return refs


def _point_refs(tets: np.ndarray, n: int) -> np.ndarray:
    """(n, 4) refs of every decoded vertex for coding its original id: the other vertices of the
    first tet that holds it, those decoded before it, latest first; the previous vertex for
    vertices no tet holds."""
    refs = np.full((n, 4), -1, np.int32)
    t = np.asarray(tets, np.int64)
    if len(t):
        flat = t.reshape(-1)
        _, first = np.unique(flat, return_index=True)
        v = flat[first]
        rows = t[first // 4]
        others = np.where(rows < v[:, None], rows, -1)
        others = -np.sort(-others, axis=1)
        refs[v, :] = others.astype(np.int32)
    none = np.flatnonzero(np.all(refs == -1, axis=1))
    refs[none[none > 0], 0] = none[none > 0] - 1
    return refs


def restore_order(mesh, cells: Cells):
    """(mesh, cells) in the original numbering, for cells decoded from a file written with
    ``keep_order``: points, point arrays and tets renumbered, every block's cells, cell arrays and
    cell sets back in their original order; (mesh, cells) unchanged otherwise."""

    if cells is None or cells.order is None:
        return mesh, cells
    orig, per_block = cells.order
    n = mesh.n_points
    if orig is None:  # the cell order alone
        orig, out = np.arange(n), mesh
    else:
        inv = np.empty(n, np.int64)
        inv[orig] = np.arange(n)
        data = {k: np.asarray(v)[inv] for k, v in mesh.point_data.items()}
        out = TetMesh(np.asarray(mesh.points)[inv], None, orig[mesh.tets], mesh.scalar_name, point_data=data)
    back = {bi: np.argsort(o, kind="stable") for bi, o in per_block.items()}
    blocks = []
    for bi, (t, d) in enumerate(cells.blocks):
        d = orig[d]
        blocks.append((t, d[back[bi]] if bi in back else d))
    cell_data = {k: [a[back[bi]] if bi in back else a for bi, a in enumerate(v)] for k, v in cells.cell_data.items()}
    point_sets = {k: _resorted(orig[v], v) for k, v in cells.point_sets.items()}
    cell_sets = {}
    for k, v in cells.cell_sets.items():
        per = []
        for bi, ids in enumerate(v):
            if ids is None or bi not in per_block or is_raw_set(k):
                per.append(ids)
            else:
                per.append(_resorted(per_block[bi][ids.astype(np.int64)].astype(ids.dtype), ids))
        cell_sets[k] = per
    tet_cell = cells.tet_cell
    return out, Cells(blocks, tet_cell, cell_data, cells.field_data, point_sets, cell_sets)


def _resorted(mapped: np.ndarray, decoded: np.ndarray) -> np.ndarray:
    """A set decoded as increasing ids stays increasing in the original numbering."""
    d = decoded.astype(np.int64)
    return np.sort(mapped) if len(d) < 2 or np.all(d[1:] > d[:-1]) else mapped


def _neighbour_pairs(nbr: np.ndarray, cellrank: np.ndarray) -> np.ndarray:
    t, k = np.nonzero(nbr >= 0)
    a, b = cellrank[t], cellrank[nbr[t, k]]
    diff = a != b
    if not diff.any():
        return np.zeros((0, 2), np.int64)
    return np.unique(np.stack([a[diff], b[diff]], axis=1), axis=0)


def _increasing(ids: np.ndarray) -> bool:
    """Strictly increasing ids: a set, stored as a set (sorted in the decoded numbering), since
    the decoded cells and points come in another order; other ids keep their order."""
    return bool(np.all(ids[1:] > ids[:-1]))


def _id_dtype(ids: np.ndarray) -> str:
    return dtype_name(ids.dtype) if ids.dtype.kind in "iu" else "int64"


def _array_entry(a: np.ndarray) -> dict:
    return {"dtype": "bool" if a.dtype.kind == "b" else dtype_name(a.dtype), "shape": list(a.shape[1:])}


def _as_columns(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind == "b":
        a = a.astype(np.uint8)
    a = a.astype(a.dtype.newbyteorder("<"), copy=False)
    cols = a.reshape(len(a), -1)
    if cols.shape[1] > MAX_COMPONENTS:
        raise MeshError(f"cell array {name!r} has {cols.shape[1]} components (at most {MAX_COMPONENTS})")
    return cols[:, 0] if cols.shape[1] == 1 else cols


def _field_entry(name, v) -> dict:
    a = np.asarray(v)
    if a.dtype.kind not in "fiubUS":
        raise MeshError(f"field data {name!r} has dtype {a.dtype}: only numbers and strings can be stored")
    a = np.ascontiguousarray(a)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


def _field_value(e) -> np.ndarray:
    try:
        dt = np.dtype(e["dtype"])
        if dt.kind not in "fiubUS":
            raise ValueError
        raw = base64.b64decode(e["data"].encode("ascii"), validate=True)
        return np.frombuffer(raw, dt).reshape(e["shape"]).copy()
    except (KeyError, TypeError, ValueError, AttributeError):
        raise CorruptFileError("corrupt metadata: bad field data entry") from None


def node_refs(blocks, n_referenced: int, n_points: int) -> np.ndarray:
    """(n_points - n_referenced, 4) int32 geometry refs of the points no tet holds (decoded last, in
    that order), from the volume blocks ``blocks`` [(type, (n, k) decode ids)]: a higher-order node
    gets the corners of its edge (the geometry and array coders then predict it at their midpoint),
    of its triangle, or two opposite corners of its quadrilateral or hexahedron (their midpoint is
    the centre of a parallelogram face or a parallelepiped); -1 rows for the rest (the previous
    point, as before). A node on several supports takes the smallest, so neither the order of
    the cells nor of the blocks matters: encoder and decoder see the same blocks in other orders."""
    tail = n_points - n_referenced
    out = np.full((max(tail, 0), 4), -1, np.int32)
    if tail <= 0:
        return out
    nodes, rows = [], []
    for t, data in blocks:
        sup = _node_keys(t) if t in VOLUME_CELLS else None
        if sup is None or not len(data):
            continue
        data = np.asarray(data, np.int64)
        k = VOLUME_CELLS[t][1]
        for j, corners in enumerate(sup):
            c = list(corners)
            if len(c) == 4:
                c = [c[0], c[2]]
            elif len(c) == 8:
                c = [c[0], c[6]]
            r = np.full((len(data), 4), -1, np.int64)
            r[:, :len(c)] = np.sort(data[:, c], axis=1)
            nodes.append(data[:, k + j])
            rows.append(r)
    if not nodes:
        return out
    node = np.concatenate(nodes)
    r = np.concatenate(rows)
    keep = node >= n_referenced
    node, r = node[keep], r[keep]
    order = np.lexsort((r[:, 3], r[:, 2], r[:, 1], r[:, 0], node))
    node, r = node[order], r[order]
    first = np.r_[True, node[1:] != node[:-1]] if len(node) else np.zeros(0, bool)
    out[node[first] - n_referenced] = r[first].astype(np.int32)
    return out


# -- encoder ---------------------------------------------------------------------------------------

def encode_cells(cells: Cells, mesh_tets: np.ndarray, vertex_order: np.ndarray,
                 dec_tets: np.ndarray, points32: np.ndarray | None = None) -> tuple[dict, list]:
    """The ``cells`` metadata and the ``C/...`` sections of a level-0 mesh.

    Parameters
    ----------
    cells : Cells
        The blocks as given, ``tet_cell`` over ``mesh_tets``.
    mesh_tets : (m, 4) int
        The mesh's tets (original ids), in the order ``cells.tet_cell`` refers to.
    vertex_order : (n,) int
        Original id of every decoded vertex.
    dec_tets : (m, 4) int
        The tets in decode order and decode ids, as the decoder produces them.
    points32 : (n, 3) float32, optional
        The coordinates in decode order as the geometry section holds them: cell arrays are then
        also predicted linearly at the cells' centres.
    """
    n = len(vertex_order)
    m = len(dec_tets)
    dec_of = np.empty(n, np.int64)
    dec_of[np.asarray(vertex_order)] = np.arange(n)
    a = np.sort(dec_of[np.asarray(mesh_tets, np.int64)], axis=1)
    b = np.sort(np.asarray(dec_tets, np.int64), axis=1)
    oa, ob = np.lexsort(a.T[::-1]), np.lexsort(b.T[::-1])
    if not np.array_equal(a[oa], b[ob]):
        raise MeshError("internal error: the decoded tets are not the mesh's tets")
    src = np.empty(m, np.int64)
    src[ob] = oa
    cell = np.asarray(cells.tet_cell, np.int64)[src]

    vol_blocks = [i for i, (t, _) in enumerate(cells.blocks) if t in VOLUME_CELLS]
    counts = [len(cells.blocks[i][1]) for i in vol_blocks]
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    nc = int(offsets[-1])
    uc, fi = np.unique(cell, return_index=True)
    if len(uc) != nc:
        raise MeshError(f"{nc - len(uc)} volume cells have no tets (degenerate cells cannot be stored as given)")
    trav = uc[np.argsort(fi, kind="stable")]
    rank = np.empty(nc, np.int64)
    rank[trav] = np.arange(nc)
    cellrank = rank[cell]
    first_tet = np.sort(fi)

    sections = []
    # groups
    new = np.zeros(m, bool)
    new[first_tet] = True
    nbr = _neighbours(dec_tets)
    cand = _candidates(nbr)
    cc = np.where(cand >= 0, cellrank[np.maximum(cand, 0)], -1)
    match = cc == cellrank[:, None]
    has = match.any(axis=1)
    sym = np.where(new, NEW, np.where(has, match.argmax(axis=1) + 1, ESCAPE)).astype(np.uint8)
    newcount = np.cumsum(new)
    esc = np.flatnonzero(sym == ESCAPE)
    sections.append(("C/groups", _code(sym)))
    escapes = (newcount[esc] - 1 - cellrank[esc]).astype(np.int64)
    sections.append(("C/escapes", _code(escapes)))
    # block of each cell in traversal order
    block_of = np.repeat(np.arange(len(vol_blocks)), counts)  # global cell -> volume block position
    if len(vol_blocks) > 1:
        sections.append(("C/blocks", _code(block_of[trav].astype(np.uint16))))

    # vertex order
    u, starts, ucount = _first_appearance(cellrank, dec_tets, nc, n)
    perms = np.zeros(nc, np.int64)
    palettes = []
    node_cells = []  # (ranks, decode ids of the nodes, type) per quadratic block
    for p, bi in enumerate(vol_blocks):
        t, data = cells.blocks[bi]
        k = VOLUME_CELLS[t][1]
        ranks = rank[offsets[p]:offsets[p + 1]]  # the block's cells, local order
        if len(ranks) == 0:
            palettes.append(np.zeros((0, k), np.uint8))
            continue
        if np.any(ucount[ranks] != k):
            raise MeshError(f"a {t} cell's tets do not have its {k} corners (degenerate cell)")
        ub = u[starts[ranks][:, None] + np.arange(k)]
        corners = dec_of[data[:, :k]]
        eq = ub[:, None, :] == corners[:, :, None]
        if not eq.any(axis=2).all():
            raise MeshError(f"a {t} cell's corners differ from its tets' vertices (repeated corner?)")
        pos = eq.argmax(axis=2)
        pal, inv = np.unique(pos, axis=0, return_inverse=True)
        palettes.append(pal.astype(np.uint8))
        perms[ranks] = inv.reshape(-1)
        if data.shape[1] > k:
            node_cells.append((ranks, dec_of[data[:, k:]], t))
    sections.append(("C/palettes", _code(np.concatenate([p.reshape(-1) for p in palettes]) if palettes
                                         else np.zeros(0, np.uint8))))
    all_pairs = _neighbour_pairs(nbr, cellrank)
    sections.append(("C/perms", _code(perms, _cell_refs(all_pairs, np.arange(nc), nc))))
    pal_sizes = [int(len(p)) for p in palettes]

    # higher-order nodes, in traversal order
    if node_cells:
        flags, ids = _encode_nodes(node_cells, cells, vol_blocks, offsets, rank, dec_of, nc)
        sections.append(("C/node_flags", _code(flags)))
        sections.append(("C/node_ids", _code(ids)))

    # output order of every block: volume blocks in traversal order, the others as given
    out_pos = np.full(nc, -1, np.int64)  # rank -> position in its block's output
    block_entries = []
    out_local = {}  # block index -> local cell ids in output order
    for p, bi in enumerate(vol_blocks):
        ranks = rank[offsets[p]:offsets[p + 1]]
        order = np.argsort(ranks, kind="stable")
        out_local[bi] = order
        out_pos[ranks[order]] = np.arange(len(order))
    for bi, (t, data) in enumerate(cells.blocks):
        block_entries.append({"type": t, "cells": int(len(data))})
        if t not in VOLUME_CELLS:
            out_local[bi] = np.arange(len(data))
            if len(data):
                sections.append((f"C/other/{bi}", _code(dec_of[data].reshape(len(data), -1))))

    # cell arrays: each volume block's in traversal order, predicted from the earlier face-neighbouring
    # cells; or, when the block's cell order is stored (keep_order, or because it costs less than
    # what coding the arrays in their file order saves), in file order with the same prediction
    pairs = (_neighbour_pairs(nbr, cellrank) if cells.cell_data or cells.keep_order
             else np.zeros((0, 2), np.int64))
    order_sections = {}
    for p, bi in enumerate(vol_blocks):
        ranks = rank[offsets[p]:offsets[p + 1]]
        if len(ranks):
            pos = np.full(nc, -1, np.int64)
            pos[ranks] = out_pos[ranks]
            order_sections[bi] = _code(out_local[bi].astype(np.int64), _cell_refs(pairs, pos, len(ranks)))
    data_meta, coded = [], {}  # coded[(j, bi)] = {"traversal": bytes, "file": bytes}
    for j, (name, arrays) in enumerate(cells.cell_data.items()):
        entries = []
        for bi, arr in enumerate(arrays):
            arr = np.asarray(arr)
            entries.append(_array_entry(arr))
            cols = _as_columns(arr, name)
            if cols.size == 0:
                continue
            t, data = cells.blocks[bi]
            k = VOLUME_CELLS[t][1] if t in VOLUME_CELLS else data.shape[1]
            ways = {}
            for way in ("traversal", "file") if t in VOLUME_CELLS else ("file",):
                local = out_local[bi] if way == "traversal" else np.arange(len(data))
                refs = None
                if t in VOLUME_CELLS:
                    p = vol_blocks.index(bi)
                    ranks = rank[offsets[p]:offsets[p + 1]]
                    pos = np.full(nc, -1, np.int64)
                    pos[ranks] = out_pos[ranks] if way == "traversal" else np.arange(len(ranks))
                    refs = _cell_refs(pairs, pos, len(data))
                centres = None if points32 is None else _centroids(points32, dec_of[data[local, :k]])
                ways[way] = _code_values(cols[local], refs, centres)
            coded[j, bi] = ways
        data_meta.append({"name": str(name), "blocks": entries})
    trav_total = sum(len(w.get("traversal", w["file"])) for w in coded.values())
    file_total = sum(min(len(x) for x in w.values()) for w in coded.values())
    cell_order = cells.keep_order or (file_total + sum(map(len, order_sections.values())) < trav_total)
    for (j, bi), ways in coded.items():
        if cells.blocks[bi][0] not in VOLUME_CELLS:
            way = "file"
        elif cell_order:
            way = min(ways, key=lambda w: len(ways[w]))
        else:
            way = "traversal"
        data_meta[j]["blocks"][bi]["order"] = way
        sections.append((f"C/data/{j}/{bi}", ways[way]))
    if cell_order:
        sections += [(f"C/order/{bi}", code) for bi, code in order_sections.items()]

    # sets
    pset_meta = []
    for j, (name, ids) in enumerate(cells.point_sets.items()):
        ids = np.asarray(ids)
        flat = ids.reshape(-1).astype(np.int64)
        inc = _increasing(flat)
        pset_meta.append({"name": str(name), "dtype": _id_dtype(ids), "n": int(ids.size), "sorted": inc})
        if ids.size:
            mapped = dec_of[flat]
            sections.append((f"C/pset/{j}", _code(np.sort(mapped) if inc else mapped)))
    cset_meta = []
    for j, (name, per_block) in enumerate(cells.cell_sets.items()):
        entries = []
        for bi, ids in enumerate(per_block):
            if ids is None:
                entries.append(None)
                continue
            ids = np.asarray(ids)
            flat = ids.reshape(-1).astype(np.int64)
            inc = _increasing(flat) and not is_raw_set(name)
            entries.append({"dtype": _id_dtype(ids), "n": int(ids.size), "sorted": inc})
            if ids.size and is_raw_set(name):
                sections.append((f"C/cset/{j}/{bi}", _code(flat)))
            elif ids.size:
                inv = np.empty(len(out_local[bi]), np.int64)
                inv[out_local[bi]] = np.arange(len(out_local[bi]))
                mapped = inv[flat]
                sections.append((f"C/cset/{j}/{bi}", _code(np.sort(mapped) if inc else mapped)))
        cset_meta.append({"name": str(name), "blocks": entries})

    if cells.keep_order:
        sections.append(("C/order/points", _code(np.asarray(vertex_order, np.int64), _point_refs(dec_tets, n))))
    meta = {
        "keep_order": bool(cells.keep_order),
        "cell_order": bool(cell_order),
        "blocks": block_entries,
        "palettes": pal_sizes,
        "escapes": int(len(esc)),
        "nodes": int(sum(nc_[1].size for nc_ in node_cells)),
        "cell_data": data_meta,
        "field_data": {str(k): _field_entry(k, v) for k, v in cells.field_data.items()},
        "point_sets": pset_meta,
        "cell_sets": cset_meta,
    }
    return meta, [(name, data) for name, data in sections if data or name in ("C/groups",)]


def _node_keys(t: str):
    sup = NODE_SUPPORTS.get(t)
    if sup is None or len(sup) != cell_size(t) - VOLUME_CELLS[t][1]:
        return None
    return sup


def _encode_nodes(node_cells, cells, vol_blocks, offsets, rank, dec_of, nc):
    """(flags, ids): per node whose edge or face was seen before, 0 when it is the node seen there;
    per other node its decode id against the last coded one (zigzag)."""
    by_rank = {}
    for ranks, nodes, t in node_cells:
        for r, row, corners in zip(ranks.tolist(), nodes.tolist(), [None] * len(ranks)):
            by_rank[r] = (row, t)
    # corners in decode ids by rank, for the keys
    corners_of = {}
    for p, bi in enumerate(vol_blocks):
        t, data = cells.blocks[bi]
        if t in NODE_SUPPORTS or data.shape[1] > VOLUME_CELLS[t][1]:
            k = VOLUME_CELLS[t][1]
            for r, row in zip(rank[offsets[p]:offsets[p + 1]].tolist(), dec_of[data[:, :k]].tolist()):
                corners_of[r] = row
    flags, ids = [], []
    seen = {}
    last = -1
    for r in sorted(by_rank):
        row, t = by_rank[r]
        sup = _node_keys(t)
        c = corners_of[r]
        for j, node in enumerate(row):
            key = None if sup is None else tuple(sorted(c[x] for x in sup[j]))
            if key is not None and key in seen:
                if seen[key] == node:
                    flags.append(0)
                    continue
                flags.append(1)
            ids.append(node - last - 1)
            last = node
            if key is not None:
                seen[key] = node
    return np.array(flags, np.uint8), _zigzag(np.array(ids, np.int64))


# -- decoder ---------------------------------------------------------------------------------------

def _int(v, lo=0, hi=2**62):
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise CorruptFileError("corrupt metadata: bad cells entry")
    return v


def decode_cells(meta, read_section, has_section, dec_tets: np.ndarray, n_points: int,
                 points32: np.ndarray | None = None) -> Cells:
    """The cells of a file's ``cells`` metadata and ``C/...`` sections, in decode ids, against the
    decoded tets of level 0 (``tet_cell``: each decoded tet's cell in traversal order).

    ``read_section(name)`` and ``has_section(name)`` read the file's sections."""
    if not isinstance(meta, dict) or not isinstance(meta.get("blocks"), list):
        raise CorruptFileError("corrupt metadata: bad cells entry")
    m = len(dec_tets)
    blocks = []
    for e in meta["blocks"]:
        if not isinstance(e, dict) or not isinstance(e.get("type"), str):
            raise CorruptFileError("corrupt metadata: bad cell block")
        t = e["type"]
        if t not in VOLUME_CELLS and t not in OTHER_CELLS:
            raise CorruptFileError(f"corrupt metadata: unknown cell type {t!r}")
        blocks.append((t, _int(e.get("cells"), 0, 2**31)))
    vol_blocks = [i for i, (t, _) in enumerate(blocks) if t in VOLUME_CELLS]
    counts = [blocks[i][1] for i in vol_blocks]
    nc = int(sum(counts))
    if nc > m:
        raise CorruptFileError("corrupt metadata: more volume cells than tets")

    def section(name):
        return read_section(name) if has_section(name) else b""

    sym = _decode(read_section("C/groups"), m, "uint8")
    if np.any(sym > ESCAPE):
        raise CorruptFileError("corrupt cells section: bad group symbol")
    new = sym == NEW
    newcount = np.cumsum(new)
    if int(newcount[-1] if m else 0) != nc:
        raise CorruptFileError("corrupt cells section: the tets start a wrong number of cells")
    nbr = _neighbours(dec_tets)
    cand = _candidates(nbr)
    idx = np.arange(m)
    parent = idx.copy()
    pick = (sym >= 1) & (sym <= _CANDIDATES)
    parent[pick] = cand[pick, sym[pick].astype(np.int64) - 1]
    esc = np.flatnonzero(sym == ESCAPE)
    if len(esc) != _int(meta.get("escapes"), 0, m):
        raise CorruptFileError("corrupt metadata: escape count")
    back = _decode(section("C/escapes"), len(esc), "int64")
    first_tet = np.flatnonzero(new)
    target = newcount[esc] - 1 - back
    if np.any((target < 0) | (target >= newcount[esc])):
        raise CorruptFileError("corrupt cells section: an escape names a cell not yet started")
    parent[esc] = first_tet[target]
    if np.any(parent[~new] < 0) or np.any(parent[~new] >= idx[~new]):
        raise CorruptFileError("corrupt cells section: a tet joins a cell that does not precede it")
    root = parent
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    rank_of_new = np.zeros(m, np.int64)
    rank_of_new[first_tet] = np.arange(nc)
    cellrank = rank_of_new[root]

    if len(vol_blocks) > 1:
        block_of = _decode(read_section("C/blocks"), nc, "uint16").astype(np.int64)
        if np.any(block_of >= len(vol_blocks)) or np.any(np.bincount(block_of, minlength=len(vol_blocks)) != counts):
            raise CorruptFileError("corrupt cells section: block counts do not match the metadata")
    else:
        block_of = np.zeros(nc, np.int64)

    u, starts, ucount = _first_appearance(cellrank, dec_tets, nc, n_points)
    pal_sizes = meta.get("palettes")
    if not isinstance(pal_sizes, list) or len(pal_sizes) != len(vol_blocks):
        raise CorruptFileError("corrupt metadata: bad palettes")
    ks = [VOLUME_CELLS[blocks[i][0]][1] for i in vol_blocks]
    total = sum(_int(s, 0, 40320) * k for s, k in zip(pal_sizes, ks))
    flat = _decode(section("C/palettes"), total, "uint8").astype(np.int64)
    perms = (_decode(read_section("C/perms"), nc, "int64", 1, _cell_refs(_neighbour_pairs(nbr, cellrank), np.arange(nc), nc))
             if nc else np.zeros(0, np.int64))
    out_blocks = [None] * len(blocks)
    ranks_of_block = {}
    at = 0
    for p, bi in enumerate(vol_blocks):
        t = blocks[bi][0]
        k = ks[p]
        pal = flat[at:at + pal_sizes[p] * k].reshape(-1, k)
        at += pal_sizes[p] * k
        ranks = np.flatnonzero(block_of == p)
        ranks_of_block[bi] = ranks
        if np.any(ucount[ranks] != k):
            raise CorruptFileError(f"corrupt cells section: a {t} cell's tets do not have {k} corners")
        pi = perms[ranks]
        if len(ranks) and (np.any(pi < 0) or np.any(pi >= len(pal)) or np.any(pal >= k)):
            raise CorruptFileError("corrupt cells section: bad vertex order")
        ub = u[starts[ranks][:, None] + np.arange(k)]
        corners = np.take_along_axis(ub, pal[pi], axis=1) if len(ranks) else np.zeros((0, k), np.int64)
        out_blocks[bi] = np.zeros((len(ranks), cell_size(t)), np.int64)
        out_blocks[bi][:, :k] = corners
    quad = [bi for bi in vol_blocks if cell_size(blocks[bi][0]) > VOLUME_CELLS[blocks[bi][0]][1]]
    if quad:
        _decode_nodes(meta, read_section, has_section, out_blocks, blocks, quad, ranks_of_block, nc, n_points)
    for bi, (t, count) in enumerate(blocks):
        if t not in VOLUME_CELLS:
            k = cell_size(t)
            ids = _decode(section(f"C/other/{bi}"), count, "int64", k) if count else np.zeros((0, k), np.int64)
            ids = ids.reshape(count, k)
            if ids.size and (ids.min() < 0 or ids.max() >= n_points):
                raise CorruptFileError("corrupt cells section: a cell refers to a missing point")
            out_blocks[bi] = ids

    pairs = None
    order = None
    per_block = {}
    if meta.get("keep_order") or meta.get("cell_order"):
        pairs = _neighbour_pairs(nbr, cellrank)
        for bi in vol_blocks:
            ranks = ranks_of_block[bi]
            if not len(ranks):
                per_block[bi] = np.zeros(0, np.int64)
                continue
            pos = np.full(nc, -1, np.int64)
            pos[ranks] = np.arange(len(ranks))
            o = _decode(read_section(f"C/order/{bi}"), len(ranks), "int64", 1, _cell_refs(pairs, pos, len(ranks)))
            if not np.array_equal(np.sort(o), np.arange(len(ranks))):
                raise CorruptFileError("corrupt cells section: a cell order is not a permutation")
            per_block[bi] = o
        orig = None
        if meta.get("keep_order"):
            orig = _decode(read_section("C/order/points"), n_points, "int64", 1, _point_refs(dec_tets, n_points))
            if not np.array_equal(np.sort(orig), np.arange(n_points)):
                raise CorruptFileError("corrupt cells section: the point order is not a permutation")
        order = (orig, per_block)

    # cell arrays
    cell_data = {}
    for j, e in enumerate(meta.get("cell_data") or []):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str) or len(e.get("blocks") or []) != len(blocks):
            raise CorruptFileError("corrupt metadata: bad cell array entry")
        arrays = []
        for bi, be in enumerate(e["blocks"]):
            try:
                dt_name, shape = be["dtype"], [int(x) for x in be["shape"]]
            except (TypeError, KeyError, ValueError):
                raise CorruptFileError("corrupt metadata: bad cell array entry") from None
            is_bool = dt_name == "bool"
            dt = check_dtype("uint8" if is_bool else dt_name)
            count = blocks[bi][1]
            comps = int(np.prod(shape)) if shape else 1
            if comps > MAX_COMPONENTS or any(s < 0 for s in shape):
                raise CorruptFileError("corrupt metadata: bad cell array shape")
            if count == 0 or comps == 0:
                values = np.zeros((count, *shape), dt)
            else:
                t = blocks[bi][0]
                way = be.get("order", "traversal" if t in VOLUME_CELLS else "file")
                if way not in ("traversal", "file") or (way == "traversal" and t not in VOLUME_CELLS) or (
                        way == "file" and t in VOLUME_CELLS and bi not in per_block):
                    raise CorruptFileError("corrupt metadata: bad cell array order")
                local = np.arange(count)
                refs = None
                if t in VOLUME_CELLS:
                    if pairs is None:
                        pairs = _neighbour_pairs(nbr, cellrank)
                    pos = np.full(nc, -1, np.int64)
                    ranks = ranks_of_block[bi]
                    if way == "traversal":
                        pos[ranks] = np.arange(len(ranks))
                    else:
                        pos[ranks] = per_block[bi]
                        local = np.argsort(per_block[bi])  # file position -> decoded position
                    refs = _cell_refs(pairs, pos, count)
                centres = None
                if points32 is not None:
                    k = VOLUME_CELLS[t][1] if t in VOLUME_CELLS else cell_size(t)
                    centres = _centroids(points32, out_blocks[bi][local, :k])
                values = _decode_values(read_section(f"C/data/{j}/{bi}"), count, dt.name, comps, refs, centres)
                if t in VOLUME_CELLS and way == "file":
                    values = values[per_block[bi]]
                values = values.reshape((count, *shape))
            arrays.append(values.astype(bool) if is_bool else values.astype(values.dtype.newbyteorder("=")))
        cell_data[e["name"]] = arrays

    field_data = {}
    fd = meta.get("field_data") or {}
    if not isinstance(fd, dict):
        raise CorruptFileError("corrupt metadata: bad field data")
    for k, e in fd.items():
        field_data[k] = _field_value(e)
    point_sets = {}
    for j, e in enumerate(meta.get("point_sets") or []):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str):
            raise CorruptFileError("corrupt metadata: bad point set")
        count = _int(e.get("n"), 0, 2**31)
        ids = _decode(section(f"C/pset/{j}"), count, "int64")
        if count and (ids.min() < 0 or ids.max() >= n_points):
            raise CorruptFileError("corrupt cells section: a point set names a missing point")
        point_sets[e["name"]] = ids.astype(check_dtype(e.get("dtype")).newbyteorder("="))
    cell_sets = {}
    for j, e in enumerate(meta.get("cell_sets") or []):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str) or len(e.get("blocks") or []) != len(blocks):
            raise CorruptFileError("corrupt metadata: bad cell set")
        per = []
        for bi, be in enumerate(e["blocks"]):
            if be is None:
                per.append(None)
                continue
            if not isinstance(be, dict):
                raise CorruptFileError("corrupt metadata: bad cell set")
            count = _int(be.get("n"), 0, 2**31)
            ids = _decode(section(f"C/cset/{j}/{bi}"), count, "int64")
            if count and not is_raw_set(e["name"]) and (ids.min() < 0 or ids.max() >= blocks[bi][1]):
                raise CorruptFileError("corrupt cells section: a cell set names a missing cell")
            per.append(ids.astype(check_dtype(be.get("dtype")).newbyteorder("=")))
        cell_sets[e["name"]] = per

    tet_cell = np.zeros(m, np.int64)  # each decoded tet's volume cell, numbered as the output blocks
    vol_pos = np.zeros(nc, np.int64)
    base = 0
    for bi in vol_blocks:
        ranks = ranks_of_block[bi]
        vol_pos[ranks] = base + np.arange(len(ranks))
        base += len(ranks)
    tet_cell[:] = vol_pos[cellrank] if m else tet_cell
    return Cells([(t, out_blocks[bi]) for bi, (t, _) in enumerate(blocks)], tet_cell, cell_data, field_data,
                 point_sets, cell_sets, keep_order=bool(meta.get("keep_order")), order=order)


def _decode_nodes(meta, read_section, has_section, out_blocks, blocks, quad, ranks_of_block, nc, n_points):
    n_nodes = _int(meta.get("nodes"), 0, 2**40)
    expect = sum(len(ranks_of_block[bi]) * (cell_size(blocks[bi][0]) - VOLUME_CELLS[blocks[bi][0]][1])
                 for bi in quad)
    if n_nodes != expect:
        raise CorruptFileError("corrupt metadata: node count")
    where = {}  # rank -> (block, row)
    for bi in quad:
        for row, r in enumerate(ranks_of_block[bi].tolist()):
            where[r] = (bi, row)
    # the flags' count is known only as they are used: decode generously from the section header
    flags_data = read_section("C/node_flags") if has_section("C/node_flags") else b""
    ids_data = read_section("C/node_ids") if has_section("C/node_ids") else b""
    flags = _decode_any(flags_data, "uint8")
    ids = _unzigzag(_decode_any(ids_data, "int64"))
    fi = ii = 0
    seen = {}
    last = -1
    for r in sorted(where):
        bi, row = where[r]
        t = blocks[bi][0]
        k = VOLUME_CELLS[t][1]
        sup = _node_keys(t)
        c = out_blocks[bi][row, :k].tolist()
        for j in range(cell_size(t) - k):
            key = None if sup is None else tuple(sorted(c[x] for x in sup[j]))
            if key is not None and key in seen:
                if fi >= len(flags):
                    raise CorruptFileError("corrupt cells section: node flags end early")
                f = flags[fi]
                fi += 1
                if f == 0:
                    out_blocks[bi][row, k + j] = seen[key]
                    continue
            if ii >= len(ids):
                raise CorruptFileError("corrupt cells section: node ids end early")
            node = last + 1 + int(ids[ii])
            ii += 1
            if not 0 <= node < n_points:
                raise CorruptFileError("corrupt cells section: a node refers to a missing point")
            out_blocks[bi][row, k + j] = node
            last = node
            if key is not None:
                seen[key] = node
    if fi != len(flags) or ii != len(ids):
        raise CorruptFileError("corrupt cells section: node streams have values left over")


def _decode_any(data: bytes, dtype: str) -> np.ndarray:
    """A one-component stream whose count its own header gives (checked by the decoder)."""
    if not data:
        return np.zeros(0, check_dtype(dtype))
    if len(data) < 8:
        raise CorruptFileError("corrupt cells section: truncated header")
    n = int.from_bytes(data[4:8], "little")
    return _decode(data, n, dtype)


def read_cells(reader, dec_tets: np.ndarray, n_points: int, points=None) -> Cells | None:
    """The cells stored in a :class:`~.tetcfile.TetcReader`'s file (None when it stores none), against
    its level 0's decoded tets and points (``points``: needed by the cell arrays)."""
    meta = reader.meta.get("cells")
    if meta is None:
        return None
    if reader.container.major < 10:
        raise CorruptFileError("corrupt metadata: cells in a file of format 9 or older")
    return decode_cells(meta, reader.read_section, reader.container.has_section, dec_tets, n_points,
                        None if points is None else np.asarray(points).astype(np.float32))
