"""Writing and reading ``.tetc`` files: levels of compressed meshes and the streaming decoder.

A file holds one or more *levels* (level 0 is the full mesh; the simplify stage adds
pre-simplified levels). Level ``i`` has the sections ``L{i}/boundary`` and ``L{i}/tets``
(connectivity, :mod:`.cutborder`), ``L{i}/geometry`` (coordinates and default scalar as float32 in
decode order, :mod:`.geometry`: the stream the renderer needs), ``L{i}/points64`` (float64
coordinates, exact, when they are not all float32 values) and ``L{i}/array/{j}`` (point array j of
the metadata's ``arrays``, exact in its dtype, :mod:`.arrays`; absent for a float32 default scalar,
which the geometry holds exactly; format 8: without the components the array's ``copies`` entry
lists as copies of another array's, :func:`find_copies`, and absent when that is all of them),
and optionally ``L{i}/forest`` (the remaining merge forest in
decode order, :mod:`.forest`). The metadata lists the levels with the counts the decoder needs, so
a reader seeks straight to one level.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from .._atomic import write_bytes_atomic
from ..errors import CorruptFileError, MeshError, OptionError
from ..mesh import TetBatch, TetMesh, default_step
from ..mesh.model import NO_SCALAR, scalar_of
from ..mesh.validate import check_tet_ids
from ..mesh.cells import VOLUME_CELLS
from .cells import decode_cells, encode_cells, node_refs
from .brickindex import BrickView, brick_levels_summary, parse_brick_index
from .arrays import MAX_COMPONENTS, ArrayDecoder, check_dtype, dtype_name, encode_array
from .container import Container, build_container
from .levelmeta import LevelMeta
from .cutborder import ConnectivityDecoder, encode_connectivity
from .decoded_connectivity import DecodedConnectivity, DecodedGeometry
from .dependencies import decode_dependencies, dependencies_header, encode_dependencies
from .forest import (FOREST_CODING, ROOT_RANK, decode_forest,
                     decode_forest_on_geometry, decode_forest_on_mesh, decode_forest_rounds, encode_forest_on_geometry,
                     encode_forest_on_mesh, encode_forest_rounds, forest_header)
from .geometry import (MAX_HEADER_SIZE, GeometryDecoder, assemble_geometry, chained_channels, check_geometry_header,
                       decode_value_tables, encode_geometry,
                       geometry_parts)
from .formats import CURRENT, codings
from .threads import RunAhead, check_jobs

FORMAT_NAME = "tetc"
DEFAULT_BATCH_TETS = 65536
# decode_mesh on two threads cuts a level into batches of at least this many tets (smaller ones
# cost more hand-overs than they gain: flange-1m was slower in batches of 16,384 than of 65,536)
_MIN_RUN_AHEAD_BATCH_TETS = 16384
# counts beyond these bounds are not believed from a stream of the given size (rejected before
# allocating): a regular 40^3 grid, the most compressible mesh we know, codes 8.3 tets per byte of
# its tet section and 5 boundary faces per byte; 512 leaves 60x headroom
_MAX_TETS_PER_BYTE = 512
_MAX_FACES_PER_BYTE = 512
GEOMETRY_CODING = CURRENT.geometry  # what this version writes
_POINTS = ("points",)  # key of the float64 coordinates among the exact arrays (no array name is a tuple)


@dataclass
class LevelPayload:
    """A mesh to store as one level of a ``.tetc`` file.

    Attributes
    ----------
    level : int
        i (0 = the full mesh).
    ratio : float
        Simplification ratio of this level (merged vertices / all vertices of level 0).
    merges_before : int
        N_i, merges of the full forest already applied.
    mesh : TetMesh
    forest : (parent, rank) or None
        The remaining merge forest in this level mesh's own numbering.
    copies : tuple of (j, c, k, kc)
        Components stored as references, :func:`find_copies` of level 0 (the file's ``copies``):
        component c of array j is component kc of array k. Empty: every component is coded.
    node_blocks : tuple of (str, (n, k) array)
        Level 0 only: the quadratic volume blocks of the cells as given (point ids of ``mesh``),
        whose higher-order nodes, points no tet holds, are then coded against the corners of
        their edge or face (:func:`.cells.node_refs`) instead of the previous point.
    """

    level: int
    ratio: float
    merges_before: int
    mesh: object
    forest: tuple | None = None
    copies: tuple = ()
    node_blocks: tuple = ()


@dataclass
class EncodedLevel:
    """Sections and figures of one encoded level."""

    level: int
    sections: dict
    meta: dict
    vertex_order: np.ndarray
    peak_border: int
    render_step: float  # default_step of this level's mesh, from the boundary the encoder found
    # geometry coding 4: the level's channels coded every way, until the file's levels are chained
    # (:func:`_chain_geometry` rewrites the geometry section and drops them)
    geometry_parts: object = None
    copies: tuple = ()  # the payload's: what the array sections leave out
    tets: np.ndarray = None  # the tets in decode order and ids, as the decoder gives them (for the cells)
    node_refs: bool = False  # the points no tet holds were coded against their cells' edges and faces


def encode_level(payload: LevelPayload, *, chainable: bool = True) -> EncodedLevel:
    """Compress one level: connectivity, geometry (in decode order) and the optional forest.

    The geometry section is a block of its own; ``chainable``: the level is one of several, and
    keeps what :func:`_chain_geometry` needs to chain its value tables to the next coarser level's
    once every level is coded."""
    return _with_forest(_encode_level_mesh(payload, chainable=chainable), payload)


def _encode_level_mesh(payload: LevelPayload, *, chainable: bool = True) -> EncodedLevel:
    """One level's mesh sections (connectivity, geometry, point arrays) and metadata, without the
    forest: :func:`_with_forest` adds it (at once in :func:`encode_level`, or later for a level
    whose mesh was coded while its forest was being built)."""
    mesh = payload.mesh
    check_mesh(mesh)
    conn = encode_connectivity(mesh.n_points, mesh.tets)
    vo = conn.vertex_order
    refs = np.ascontiguousarray(conn.predictors, dtype=np.int32)
    use_nodes = bool(payload.node_blocks) and conn.n_referenced < mesh.n_points
    if use_nodes:
        dec_of = np.empty(mesh.n_points, np.int64)
        dec_of[vo] = np.arange(mesh.n_points)
        refs = refs.copy()
        refs[conn.n_referenced:] = node_refs([(t, dec_of[d]) for t, d in payload.node_blocks],
                                             conn.n_referenced, mesh.n_points)
    p32, d32 = mesh.points32[vo], mesh.density[vo]
    # The boundary in decode ids and order has the same edges as mesh.boundary_faces(), so the same
    # median; deriving it again from the tets would sort all 4m faces (4 GB at 7.8 M tets).
    render_step = float(default_step(p32, conn.boundary))
    parts = None
    if GEOMETRY_CODING >= 4:
        parts = geometry_parts(p32, d32, refs, chainable=chainable)
        geometry = assemble_geometry([parts])[0]
    else:
        geometry = encode_geometry(p32, d32, refs)
    i = int(payload.level)
    sections = {f"L{i}/boundary": conn.boundary_code, f"L{i}/tets": conn.tet_code, f"L{i}/geometry": geometry}
    if mesh.points.dtype == np.float64:
        p64 = mesh.points[vo]
        if not np.array_equal(p64.view(np.int64), p32.astype(np.float64).view(np.int64)):
            sections[f"L{i}/points64"] = encode_array(p64, refs, external=p32)
    copied = {}
    for j, c, _, _ in payload.copies:
        copied.setdefault(j, set()).add(c)
    for j, (name, values) in enumerate(mesh.point_data.items()):
        if name == mesh.scalar_name and values.dtype == np.float32:
            continue  # the geometry section holds it exactly
        if j in copied:  # only the components that copy nothing; none: no section
            stored = [c for c in range(values.shape[1] if values.ndim == 2 else 1) if c not in copied[j]]
            if not stored:
                continue
            values = values[:, stored[0]] if len(stored) == 1 else values[:, stored]
        sections[f"L{i}/array/{j}"] = encode_array(values[vo], refs, external=d32 if name == mesh.scalar_name else None,
                                                   positions=p32)
    lo, hi = mesh.bbox
    meta = {
        "level": i,
        "ratio": float(payload.ratio),
        "merges_before": int(payload.merges_before),
        "points": int(mesh.n_points),
        "tets": int(mesh.n_tets),
        "boundary_faces": int(conn.n_boundary_faces),
        "boundary_vertices": int(conn.n_boundary_vertices),
        "referenced_points": int(conn.n_referenced),
        "bbox": [lo.tolist(), hi.tolist()],
        "scalar_range": [float(x) for x in mesh.scalar_range],
        "has_forest": False,
    }
    return EncodedLevel(i, sections, meta, vo, conn.peak_border, render_step, parts if chainable else None,
                        tuple(payload.copies), conn.tets, use_nodes)


def _chain_geometry(encoded: list) -> None:
    """Recode the geometry sections of a file's (or a brick's) levels, in file order, with their
    value tables chained each to the next level's (:func:`~.geometry.assemble_geometry`), and drop
    the levels' geometry parts. Levels without parts keep their sections (a file of one level)."""
    if len(encoded) > 1 and all(e.geometry_parts is not None for e in encoded):
        blocks = assemble_geometry([e.geometry_parts for e in encoded])
        for e, block in zip(encoded, blocks):
            e.sections[f"L{e.level}/geometry"] = block
    for e in encoded:
        e.geometry_parts = None


def _encode_level_forest(mesh, vertex_order, parent, rank, n_boundary_vertices) -> bytes:
    """The ``L{i}/forest`` section: the forest renumbered to decode order, coded after the level's
    mesh (format 3 to 5) or mesh and geometry (format 6: forest coding 2; format 7: coding 3); in
    decode order the boundary vertices come first."""
    dec_of = np.empty(mesh.n_points, np.int64)
    dec_of[vertex_order] = np.arange(mesh.n_points)
    args = (dec_of[parent[vertex_order]], rank[vertex_order], dec_of[mesh.tets])
    boundary = np.arange(mesh.n_points) < n_boundary_vertices
    if FOREST_CODING == 1:
        return encode_forest_on_mesh(*args, boundary=boundary)
    encode = encode_forest_on_geometry if FOREST_CODING == 3 else encode_forest_rounds
    return encode(*args, boundary=boundary, points=mesh.points[vertex_order], density=mesh.density[vertex_order])


def check_mesh(mesh) -> None:
    """What the encoder's kernels assume, checked before any of them runs (from every entry point).

    Raises :class:`~gatun_py.errors.MeshError` on ids out of range (-1 included), a tet that
    repeats a vertex, a negatively oriented tet, unsupported dtypes, or arrays of the wrong length.
    """
    if not isinstance(mesh, TetMesh):
        raise MeshError(f"expected a TetMesh, got {type(mesh).__name__}")
    n, t = mesh.n_points, mesh.tets
    if n >= 2**31 - 1:
        raise MeshError(f"mesh too large for 32-bit ids ({n} points)")
    if t.size:
        check_tet_ids(t, n)
        neg = mesh.signed_volumes() < 0
        if neg.any():
            i = int(np.flatnonzero(neg)[0])
            raise MeshError(f"tet {i} is negatively oriented; {int(neg.sum())} tets affected "
                            "(validate_tets re-orients them)")
    if mesh.points.dtype not in (np.float32, np.float64):
        raise MeshError(f"coordinates must be float32 or float64, not {mesh.points.dtype}")
    for name, a in mesh.point_data.items():
        try:
            dtype_name(a.dtype)
        except ValueError as e:
            raise MeshError(f"point array {name!r}: {e}") from None
        if a.shape[0] != n or a.ndim not in (1, 2) or (a.ndim == 2 and not 1 <= a.shape[1] <= MAX_COMPONENTS):
            raise MeshError(f"point array {name!r} has shape {a.shape} for {n} points")


def _finite_range(values) -> list:
    """[lo, hi] of the finite values (JSON holds no NaN or inf); [0, 0] when there are none."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return [float(v.min()), float(v.max())] if v.size else [0.0, 0.0]


def find_copies(mesh) -> tuple:
    """The components of ``mesh``'s point arrays that repeat another's bit for bit, in the same
    dtype: ((j, c, k, kc), ...), component c of array j equals component kc of array k, where k is
    an earlier array (not j itself) or the default scalar and (k, kc) is not itself a copy (so no
    chains, no cycles). The default scalar is never a copy (a float32 one costs nothing beside the geometry).
    Decided on level 0: a coarser level's vertices are a subset, so its columns stay equal."""
    arrays = list(mesh.arrays)
    names = [a[0] for a in arrays]
    s = names.index(mesh.scalar_name) if mesh.scalar_name in names else -1
    seen = {}  # (dtype, digest) -> (k, kc): the first, coded, column with those bits

    def columns(j):
        a = np.asarray(mesh.point_data[names[j]])
        return [a] if a.ndim == 1 else [a[:, c] for c in range(a.shape[1])]

    def key(j, col):  # a digest, not the bytes: one column of a 10 M-point float64 array is 80 MB
        return dtype_name(arrays[j][1]), hashlib.blake2b(np.ascontiguousarray(col).view(np.uint8)).digest()

    def same(j, c, k, kc):  # bit for bit (-0.0 is not 0.0, NaN payloads count)
        a, b = np.ascontiguousarray(columns(j)[c]), np.ascontiguousarray(columns(k)[kc])
        return a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))

    if s >= 0:
        seen[key(s, columns(s)[0])] = (s, 0)
    out = []
    for j in range(len(arrays)):
        if j == s:
            continue
        own = {}  # sources from earlier arrays only: a component repeating its own array's is coded
        for c, col in enumerate(columns(j)):
            kk = key(j, col)
            if kk in seen and same(j, c, *seen[kk]):
                out.append((j, c) + seen[kk])
            else:
                own.setdefault(kk, (j, c))
        for kk, src in own.items():
            seen.setdefault(kk, src)
    return tuple(out)


def _arrays_meta(mesh, *, ranges: bool = False, copies: tuple = ()) -> list:
    """The metadata's ``arrays``; with ``ranges`` also each one's value range (the magnitude's for a
    vector, plus ``component_ranges``) so a renderer can normalise any of them before decoding;
    ``copies`` (:func:`find_copies`) as each copying array's ``copies``: [[c, k, kc], ...]."""
    out = []
    for j, (name, dt, k) in enumerate(mesh.arrays):
        e = {"name": name, "dtype": dtype_name(dt), "components": k}
        own = [[c, kk, kc] for jj, c, kk, kc in copies if jj == j]
        if own:
            e["copies"] = own
        if ranges:
            a = mesh.point_data[name]
            if k == 1:
                e["range"] = _finite_range(a)
            else:
                e["range"] = _finite_range(mesh.scalar(name, "magnitude"))
                e["component_ranges"] = [_finite_range(a[:, c]) for c in range(k)]
        out.append(e)
    return out


def file_meta(mesh0, n_boundary_faces: int, source: str = "", *, render_step: float | None = None,
              copies: tuple = ()) -> dict:
    """The metadata that describes the whole mesh (counts, bounds, arrays and their ranges, render
    step), before the levels or the bricks that hold it. ``render_step``: the mesh's
    :func:`~gatun_py.mesh.default_step` when the caller has it (computed here otherwise);
    ``copies``: the components every level stores as references (:func:`find_copies`)."""
    lo, hi = mesh0.bbox
    if render_step is None:
        render_step = default_step(mesh0.points32, mesh0.boundary_faces())
    return {
        "format": FORMAT_NAME,
        "points": int(mesh0.n_points),
        "tets": int(mesh0.n_tets),
        "boundary_faces": int(n_boundary_faces),
        "bbox": [lo.tolist(), hi.tolist()],
        "scalar": str(mesh0.scalar_name),
        "points_dtype": dtype_name(mesh0.points.dtype),
        "arrays": _arrays_meta(mesh0, ranges=True, copies=copies),
        "scalar_range": [float(x) for x in mesh0.scalar_range],
        "source": os.path.basename(str(source)),
        # The full mesh's volume-mode sample step, so that every level and ratio samples alike.
        "render_step": float(render_step),
    }


def node_blocks(cells) -> tuple:
    """The blocks of ``cells`` whose higher-order nodes level 0 codes on their edges and faces
    (:attr:`LevelPayload.node_blocks`): the quadratic volume blocks of cells a file stores."""
    if cells is None or not cells.needed():
        return ()
    return tuple((t, d) for t, d in cells.blocks if t in VOLUME_CELLS and d.shape[1] > VOLUME_CELLS[t][1])


def encode_tetc(levels: list[LevelPayload], *, source: str = "", progress=None, dependencies=None,
                mesh_codes: dict | None = None, threads: int = 1, copies: tuple | None = None,
                cells=None) -> bytes:
    """Build a whole ``.tetc`` file from levels (level 0 first).

    Parameters
    ----------
    levels : list of LevelPayload
    source : str
        Source file name, recorded in the metadata.
    progress : callable, optional
        Called with each finished level number, in level order.
    dependencies : (ptr, idx, removed), optional
        The full forest's merge dependencies (:mod:`gatun_py.simplify.dependencies`), stored as
        the section ``deps`` for selective refinement.
    mesh_codes : dict, optional
        Level number -> :class:`EncodedLevel` of that level's mesh alone, already encoded by
        ``encode_level(LevelPayload(level, ratio, merges_before, mesh))`` (no forest), e.g. level 0
        beside the decimation; only its forest section is added here.
    threads : int
        Levels encoded at once in threads (the connectivity kernels release the GIL); every level
        is coded on its own and the sections are assembled in level order, so the bytes do not
        depend on it.
    copies : tuple, optional
        :func:`find_copies` of level 0's mesh when the caller has it already (it hashes every
        point array: two passes over a large mesh's arrays otherwise); computed here when omitted.
    cells : Cells, optional
        The cell blocks level 0's tets were split from (:class:`gatun_py.mesh.cells.Cells`), stored
        against the decoded tets (:mod:`.cells`) when they hold more than one block of tets.
    """
    if not levels:
        raise OptionError("nothing to write: no levels")
    mesh0 = levels[0].mesh
    for lv in levels:
        if not isinstance(lv.mesh, TetMesh):
            raise MeshError(f"expected a TetMesh, got {type(lv.mesh).__name__}")
        if _arrays_meta(lv.mesh) != _arrays_meta(mesh0) or lv.mesh.points.dtype != mesh0.points.dtype:
            raise OptionError(f"level {lv.level} does not carry the arrays of level 0")
    # every level's mesh is checked (check_mesh) by encode_level; a mesh encoded beforehand was
    # checked there, and _with_forest holds it to the level's counts
    mesh_codes = mesh_codes or {}
    copies = find_copies(mesh0) if copies is None else tuple(copies)
    levels = [dataclasses.replace(lv, copies=copies) for lv in levels]
    levels[0] = dataclasses.replace(levels[0], node_blocks=node_blocks(cells))

    chainable = len(levels) > 1

    def encode(lv):
        done = mesh_codes.get(lv.level)
        if done is None or done.copies != copies or bool(lv.node_blocks) != done.node_refs:
            # coded beforehand with other copies, or without the nodes' refs: again
            return encode_level(lv, chainable=chainable)
        return _with_forest(done, lv)

    if threads > 1 and len(levels) > 1:
        with ThreadPoolExecutor(min(int(threads), len(levels)), thread_name_prefix="tetc-level") as pool:
            futures = [pool.submit(encode, lv) for lv in levels]
            encoded = []
            try:
                for lv, fut in zip(levels, futures):  # in level order, whichever finishes first
                    encoded.append(fut.result())
                    if progress is not None:
                        progress(lv.level)
            except BaseException:
                for fut in futures:  # a level failed (or an interrupt): the levels not started are not coded
                    fut.cancel()
                raise
    else:
        encoded = []
        for lv in levels:
            encoded.append(encode(lv))
            if progress is not None:
                progress(lv.level)
    _chain_geometry(encoded)
    meta = file_meta(mesh0, encoded[0].meta["boundary_faces"], source, render_step=encoded[0].render_step,
                     copies=copies)
    meta["levels"] = [e.meta for e in encoded]
    sections = [(name, data) for e in encoded for name, data in e.sections.items()]
    if dependencies is not None:
        meta["dependencies"], deps = _dependency_section(dependencies, levels[0])
        sections.append(("deps", deps))
    if cells is not None and cells.needed():

        meta["cells"], cell_sections = encode_cells(cells, mesh0.tets, encoded[0].vertex_order, encoded[0].tets,
                                                    mesh0.points32[encoded[0].vertex_order])
        if encoded[0].node_refs:
            meta["cells"]["node_refs"] = True
        sections += cell_sections
    return build_container(meta, sections)


def _with_forest(done: EncodedLevel, payload: LevelPayload) -> EncodedLevel:
    """A level whose mesh was coded without a forest (``encode_level`` of a payload without one),
    with the payload's forest and its metadata (ratio, merges before, has_forest) added; the one
    place a level's forest section is made."""
    mesh, i = payload.mesh, int(payload.level)
    meta = dict(done.meta)
    if (done.level != i or meta["points"] != mesh.n_points or meta["tets"] != mesh.n_tets
            or meta["has_forest"] or len(done.vertex_order) != mesh.n_points):
        raise OptionError(f"level {i}: the encoded mesh given does not match the level's mesh")
    sections = dict(done.sections)
    if payload.forest is not None:
        parent, rank = (np.asarray(a) for a in payload.forest)
        if parent.shape != (mesh.n_points,) or rank.shape != (mesh.n_points,):
            raise OptionError(f"level {i}: forest does not match the mesh ({mesh.n_points} points)")
        sections[f"L{i}/forest"] = _encode_level_forest(mesh, done.vertex_order, parent, rank,
                                                        meta["boundary_vertices"])
    meta.update(ratio=float(payload.ratio), merges_before=int(payload.merges_before),
                has_forest=payload.forest is not None)
    return dataclasses.replace(done, sections=sections, meta=meta)


def _dependency_section(dependencies, level0: LevelPayload) -> tuple[dict, bytes]:
    """(metadata entry, ``deps`` section) of the full forest's merge dependencies."""
    ptr, idx, removed = dependencies
    k = 0 if level0.forest is None else int((np.asarray(level0.forest[1]) != ROOT_RANK).sum())
    if len(removed) != k:
        raise OptionError(f"the dependencies cover {len(removed)} merges, the forest {k}")
    data = encode_dependencies(ptr, idx, removed)
    return {"merges": k, "entries": int(len(idx))}, data


def write_tetc(path, mesh_or_levels, *, source: str = "", force: bool = False, progress=None,
               dependencies=None, mesh_codes: dict | None = None, threads: int = 1,
               copies: tuple | None = None, cells=None) -> int:
    """Compress a mesh (or a list of :class:`LevelPayload`) into ``path`` atomically; returns bytes
    written. ``mesh_codes``, ``threads``, ``copies``, ``cells``: as :func:`encode_tetc`."""
    levels = mesh_or_levels if isinstance(mesh_or_levels, list) else [LevelPayload(0, 0.0, 0, mesh_or_levels)]
    data = encode_tetc(levels, source=source, progress=progress, dependencies=dependencies,
                       mesh_codes=mesh_codes, threads=threads, copies=copies, cells=cells)
    write_bytes_atomic(path, data, force=force)
    return len(data)


def _int(meta: dict, key: str, lo: int = 0, hi: int = 2**31 - 1) -> int:
    v = meta.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise CorruptFileError(f"corrupt metadata: bad {key!r}")
    return v


class TetcReader:
    """Reader of a ``.tetc`` file.

    Parameters
    ----------
    source : path or bytes

    Attributes
    ----------
    meta : dict
        The file's metadata.
    levels : list of LevelMeta
        Per-level metadata (level, ratio, merges_before, points, tets, ...), in file order.
    """

    def __init__(self, source):
        self.container = source if isinstance(source, BrickView) else Container(source)
        self.meta = self.container.meta
        if self.meta.get("format") != FORMAT_NAME:
            raise CorruptFileError(f"{self.container.name}: metadata does not describe a tetc mesh")
        self._brick_metas = parse_brick_index(self.meta, self.container)  # [] for a file of one brick
        levels = brick_levels_summary(self._brick_metas) if self._brick_metas else self.meta.get("levels")
        if not isinstance(levels, list) or not levels:
            raise CorruptFileError(f"{self.container.name}: no levels in the metadata")
        self.levels = [LevelMeta.from_json(lv) for lv in levels]
        _int(self.meta, "points")
        _int(self.meta, "tets")
        if not isinstance(self.meta.get("scalar", ""), str):
            raise CorruptFileError("corrupt metadata: bad scalar name")
        self.points_dtype, self.arrays = self._parse_arrays()
        self.copies = self._parse_copies()  # {j: [(c, k, kc), ...]}: see find_copies
        self._value_tables = {}  # (level, channel) -> its geometry's value table, for finer levels chained to it

    def _parse_arrays(self):
        """(points dtype, [(name, dtype, components)]) from the metadata; format 1 has one float32 scalar."""
        if ("arrays" in self.meta) != codings(self.container.major).arrays:
            raise CorruptFileError("corrupt metadata: the array list does not match the format version")
        if "arrays" not in self.meta:  # format 1: float32 coordinates and one float32 scalar
            return np.dtype("<f4"), [(self.scalar_name, np.dtype("<f4"), 1)]
        pdt = check_dtype(self.meta.get("points_dtype"))
        if pdt.kind != "f":
            raise CorruptFileError("corrupt metadata: bad points_dtype")
        entries = self.meta["arrays"]
        if not isinstance(entries, list) or not 1 <= len(entries) <= 4096:
            raise CorruptFileError("corrupt metadata: bad array list")
        arrays = []
        for e in entries:
            if not isinstance(e, dict) or not isinstance(e.get("name"), str):
                raise CorruptFileError("corrupt metadata: bad array entry")
            arrays.append((e["name"], check_dtype(e.get("dtype")), _int(e, "components", 1, MAX_COMPONENTS)))
        names = [a[0] for a in arrays]
        if len(set(names)) != len(names) or self.scalar_name not in names:
            raise CorruptFileError("corrupt metadata: array names repeat or miss the default scalar")
        if arrays[names.index(self.scalar_name)][2] != 1:
            raise CorruptFileError("corrupt metadata: the default scalar has several components")
        return pdt, arrays

    def _parse_copies(self) -> dict:
        """{j: [(c, k, kc), ...]} from the ``arrays`` entries' ``copies`` (format 8): component c of
        array j is component kc of array k, an earlier array or the default scalar, in the same
        dtype, and not a copy itself (which leaves no room for a cycle)."""
        entries = self.meta.get("arrays") or []
        listed = {j: e["copies"] for j, e in enumerate(entries) if "copies" in e}
        if not listed:
            return {}
        if not codings(self.container.major).array_copies:
            raise CorruptFileError("corrupt metadata: array copies in a file of format 7 or older")
        names = [a[0] for a in self.arrays]
        s = names.index(self.scalar_name)
        out = {}
        for j, rows in listed.items():
            if not isinstance(rows, list) or not rows or j == s:
                raise CorruptFileError(f"corrupt metadata: bad copies of array {j}")
            for row in rows:
                if (not isinstance(row, list) or len(row) != 3
                        or not all(isinstance(x, int) and not isinstance(x, bool) for x in row)):
                    raise CorruptFileError(f"corrupt metadata: bad copy entry of array {j}")
                c, k, kc = row
                if not 0 <= c < self.arrays[j][2] or any(c == r[0] for r in out.get(j, [])):
                    raise CorruptFileError(f"corrupt metadata: array {j} copies a bad or repeated component")
                if k == j:
                    raise CorruptFileError(f"corrupt metadata: array {j} copies itself")
                if not (0 <= k < j or k == s) or not 0 <= kc < self.arrays[k][2]:
                    raise CorruptFileError(f"corrupt metadata: array {j} copies a missing array or component")
                if self.arrays[k][1] != self.arrays[j][1]:
                    raise CorruptFileError(f"corrupt metadata: array {j} copies an array of another dtype")
                out.setdefault(j, []).append((c, k, kc))
        for j, rows in out.items():
            for c, k, kc in rows:
                if any(r[0] == kc for r in out.get(k, [])):
                    raise CorruptFileError(f"corrupt metadata: array {j} copies a copy (a chain or a cycle)")
        return out

    @property
    def scalar_name(self) -> str:
        name = self.meta.get("scalar", "density")
        return name if isinstance(name, str) else "density"

    @property
    def has_scalar(self) -> bool:
        """False for a mesh stored without a scalar (see :attr:`gatun_py.mesh.TetMesh.has_scalar`)."""
        return self.scalar_name != NO_SCALAR

    @property
    def n_bricks(self) -> int:
        """K, the bricks the file is split into (1 for a file written without ``bricks``)."""
        return max(1, len(self._brick_metas))

    def brick(self, k: int) -> "TetcReader":
        """A reader of brick ``k`` alone, as of a one-brick file (levels, forest, decoders); the
        reader itself for a file of one brick."""
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < self.n_bricks:
            raise OptionError(f"brick {k!r} does not exist: the file has {self.n_bricks} brick(s)")
        if not self._brick_metas:
            return self
        return TetcReader(BrickView(self.container, int(k), self._brick_metas[int(k)]))

    def brick_bounds(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of brick ``k``'s points, from the index (nothing decoded)."""
        lo, hi = self.brick(k).meta["bbox"]
        return np.array(lo, np.float64), np.array(hi, np.float64)

    def _one_stream(self) -> None:
        if self._brick_metas:
            raise OptionError(f"{self.container.name} is split into {self.n_bricks} bricks: decode them with "
                              "reader.brick(k) or the whole mesh with gatun_py.codec.bricks.decode_bricked")

    def level_meta(self, level: int = 0) -> LevelMeta:
        for lv in self.levels:
            if lv.level == level:
                return lv
        raise OptionError(f"level {level} is not stored in this file (stored: {[lv.level for lv in self.levels]})")

    def read_section(self, name: str) -> bytes:
        """The CRC-checked payload of section ``name``."""
        return self.container.read_section(name)

    def array_range(self, name: str | None = None, component=None) -> tuple[float, float] | None:
        """(lo, hi) of a point array (a vector's component or magnitude) from the metadata, without
        decoding; None when the file does not record it (format 1 records only the default scalar's)."""
        name = self.scalar_name if name is None else name
        entry = next((e for e in self.meta.get("arrays", []) if isinstance(e, dict) and e.get("name") == name), None)
        if entry is None:
            rng = self.meta.get("scalar_range") if name == self.scalar_name else None
        elif isinstance(component, (int, np.integer)) and not isinstance(component, bool) and entry.get("components", 1) > 1:
            ranges = entry.get("component_ranges")
            rng = ranges[component] if isinstance(ranges, list) and 0 <= component < len(ranges) else None
        else:
            rng = entry.get("range")
        if (isinstance(rng, list) and len(rng) == 2 and all(isinstance(x, (int, float)) and np.isfinite(x) for x in rng)
                and rng[0] <= rng[1]):
            return float(rng[0]), float(rng[1])
        return None

    def _size(self, name: str) -> int:
        if not self.container.has_section(name):
            raise CorruptFileError(f"{self.container.name}: missing section {name!r}")
        return self.container.section_size(name)

    def _checked_points(self, level: int) -> int:
        """The level's vertex count, checked with its tet and face counts against the sizes of the
        sections that code them, before anything is allocated."""
        self._one_stream()
        lv = self.level_meta(level)
        name = f"L{level}/geometry"
        head = self.container.read_section_head(name, MAX_HEADER_SIZE)
        coding, _, _, _ = check_geometry_header(head, lv.points, total=self._size(name))
        if coding > codings(self.container.major).geometry:
            raise CorruptFileError(f"corrupt geometry section of level {level}: coding {coding} "
                                   f"in a file of format {self.container.major}")
        m, nf = lv.tets, lv.boundary_faces
        tlen, blen = (self._size(f"L{level}/{part}") for part in ("tets", "boundary"))
        if m > _MAX_TETS_PER_BYTE * (tlen + 8) or nf > _MAX_FACES_PER_BYTE * (blen + 8):
            raise CorruptFileError("corrupt metadata: counts cannot fit in the stored sections")
        if (m == 0) != (nf == 0):
            raise CorruptFileError("corrupt metadata: inconsistent tet and face counts")
        return lv.points

    def read_forest(self, level: int = 0):
        """The merge forest of ``level`` in decode order as (parent, rank), or None if not stored."""
        lv = self.level_meta(level)
        name = f"L{level}/forest"
        if not self.container.has_section(name):
            if lv.has_forest:
                raise CorruptFileError(f"missing section {name!r}")
            return None
        data = self.read_section(name)
        n, _ = forest_header(data)
        if n != lv.points:
            raise CorruptFileError(f"{name}: covers {n} vertices, the level has {lv.points}")
        n = self._checked_points(level)
        coding = codings(self.container.major).forest
        if coding == 0:
            return decode_forest(data, n)
        boundary = np.arange(n) < lv.boundary_vertices
        if coding == 1:
            return decode_forest_on_mesh(data, self._level_tets(level), n, boundary=boundary)
        tets, points, density = self._level_geometry(level)
        decode = decode_forest_rounds if coding == 2 else decode_forest_on_geometry
        return decode(data, tets, n, boundary=boundary, points=points, density=density)

    def _level_geometry(self, level: int):
        """(tets, float32 points, density) of ``level`` in decode order: what forest codings 2 and 3 are
        coded after (connectivity and geometry sections, no other point array). Both decodes are
        kept for the next decode of the level (:meth:`_connectivity`, :meth:`_geometry`), which a
        render at a ratio runs right after."""
        n = self._checked_points(level)
        conn = DecodedConnectivity(self._connectivity_decoder(level))
        geo = self._geometry_decoder(level, n)
        self._decoded = (level, conn)
        for _ in self._batches(level, max(1, conn.n_tets), {}, geometry=geo):  # with every decode's checks
            pass
        self._decoded = (level, conn)  # served once here, kept for the next decode
        self._decoded_geometry = (level, geo.values)
        return conn.tets, geo.values[:, :3], geo.values[:, 3]

    def _geometry(self, level: int, n: int):
        """The level's geometry for one decode: the values :meth:`_level_geometry` kept (handed
        over once, then dropped), else a fresh decoder of the section."""
        kept = getattr(self, "_decoded_geometry", None)
        self._decoded_geometry = None
        if kept is not None and kept[0] == level:
            return DecodedGeometry(kept[1])
        return self._geometry_decoder(level, n)

    def _geometry_decoder(self, level: int, n: int) -> GeometryDecoder:
        data = self.read_section(f"L{level}/geometry")
        return GeometryDecoder(data, n_points=n, base=self._coarser_tables(level, data))

    def _coarser_tables(self, level: int, data=None):
        """Per channel the value table of the level after ``level`` in the file that ``level``'s
        geometry (``data``, or read here) chains to, None for the others; None when nothing chains.
        Decoded from the chain's table streams alone, channel by channel as far as each chain goes,
        and kept for the reader's next decodes (a viewer decodes many levels)."""
        if data is None:
            data = self.container.read_section_head(f"L{level}/geometry", MAX_HEADER_SIZE)
        mask = chained_channels(data)
        if not mask:
            return None
        order = [lv.level for lv in self.levels]
        first = order.index(level) + 1
        cache = self._value_tables  # (level, channel) -> table
        # the tables missing, level by level from the next one: a level's chained channels among
        # them are missing in the level after it too (the walk only goes on in the list: at most
        # every level once)
        plan, need, at = [], mask, first
        while need:
            if at >= len(order):
                raise CorruptFileError(f"corrupt geometry section of level {order[at - 1]}: its value tables are "
                                       "chained to a coarser level the file does not hold")
            need &= sum(1 << ch for ch in range(4) if (order[at], ch) not in cache)
            if not need:
                break
            chains = chained_channels(self.container.read_section_head(f"L{order[at]}/geometry", MAX_HEADER_SIZE))
            plan.append((at, need, chains & need))
            need &= chains
            at += 1
        for at, need, chains in reversed(plan):
            base = [cache.get((order[at + 1], ch)) if chains >> ch & 1 else None for ch in range(4)]
            # the block's header is checked against the level's vertex count (the metadata's, checked
            # when the reader opened) before its tables are allocated: n caps their sizes
            tables = decode_value_tables(self.read_section(f"L{order[at]}/geometry"),
                                         self.level_meta(order[at]).points, base, channels=need)
            for ch in range(4):
                if need >> ch & 1:
                    if tables[ch] is None:
                        raise CorruptFileError(f"corrupt geometry section of level {order[at - 1]}: a value table "
                                               f"chained to level {order[at]}, which codes that channel without one")
                    cache[order[at], ch] = tables[ch]
        return [cache[order[first], ch] if mask >> ch & 1 else None for ch in range(4)]

    def _level_tets(self, level: int) -> np.ndarray:
        """The tets of ``level`` in decode order, from its connectivity sections alone (what the
        format-3 forest is coded after). The decoded connectivity is kept for the next decode of
        the level (:meth:`_connectivity`), which a render at a ratio runs right after."""
        self._decoded = (level, DecodedConnectivity(self._connectivity_decoder(level)))
        return self._decoded[1].tets

    def _connectivity_decoder(self, level: int, *, keep_predictors: bool = True) -> ConnectivityDecoder:
        lv = self.level_meta(level)
        return ConnectivityDecoder(self.read_section(f"L{level}/boundary"), self.read_section(f"L{level}/tets"),
                                   n_points=lv.points, n_tets=lv.tets, n_boundary_faces=lv.boundary_faces,
                                   n_referenced=lv.referenced_points, keep_predictors=keep_predictors,
                                   coding=codings(self.container.major).tets)

    def _connectivity(self, level: int):
        """The level's connectivity for one decode: the one :meth:`_level_tets` kept (handed over
        once, then dropped), else a fresh decoder. Either way, a batch's refs are in ``last_refs``."""
        kept = getattr(self, "_decoded", None)
        self._decoded = None
        if kept is not None and kept[0] == level:
            return kept[1]
        return self._connectivity_decoder(level, keep_predictors=False)

    def forest_merges(self) -> int:
        """Merges the file's full forest holds (0 when it stores none), from the section header only."""
        if self._brick_metas:  # the bricks' forests together
            return sum(self.brick(k).forest_merges() for k in range(self.n_bricks))
        lv0 = min(self.levels, key=lambda lv: lv.level)
        name = f"L{lv0.level}/forest"
        if not self.container.has_section(name):
            return 0
        n, k = forest_header(self.read_section(name))
        if n != lv0.points:
            raise CorruptFileError(f"{name}: covers {n} vertices, the level has {lv0.points}")
        return k

    def has_dependencies(self) -> bool:
        """Whether the file stores merge dependencies (format 3 with a forest): selective refinement."""
        return self.container.has_section("deps")

    def read_dependencies(self):
        """The full forest's merge dependencies as (ptr, idx, removed) by rank, or None when the
        file stores none (written before format 3, or without a forest)."""
        if not self.container.has_section("deps"):
            if "dependencies" in self.meta:
                raise CorruptFileError("missing section 'deps'")
            return None
        data = self.read_section("deps")
        k, _ = dependencies_header(data)
        entry = self.meta.get("dependencies")
        if not isinstance(entry, dict) or entry.get("merges") != k:
            raise CorruptFileError("corrupt metadata: bad 'dependencies' entry")
        return decode_dependencies(data, self.forest_merges(), int(self.meta["tets"]))

    def _array_decoder(self, level: int, j: int, n: int):
        """Decoder of array j of ``level`` (None for a float32 default scalar: the geometry holds it);
        a :class:`_CopyingDecoder` for an array with copied components, whose sources
        (:meth:`_array_decoders`) must be decoded before it."""
        name, dt, k = self.arrays[j]
        section = f"L{level}/array/{j}"
        copies = self.copies.get(j)
        if copies:
            stored = [c for c in range(k) if all(c != r[0] for r in copies)]
            if self.container.has_section(section) != bool(stored):
                raise CorruptFileError(f"{'missing' if stored else 'unexpected'} section {section!r}")
            dec = ArrayDecoder(self.read_section(section), n_points=n, dtype=dt.name,
                               components=len(stored)) if stored else None
            return _CopyingDecoder(dec, dt, k, n, stored, [(c, self.arrays[kk][0], kc) for c, kk, kc in copies])
        if not self.container.has_section(section):
            if name == self.scalar_name and dt == np.float32:
                return None
            raise CorruptFileError(f"missing section {section!r}")
        return ArrayDecoder(self.read_section(section), n_points=n, dtype=dt.name, components=k)

    def _array_decoders(self, level: int, js, n: int) -> dict:
        """{name: decoder} of the arrays ``js`` of ``level`` and of the arrays their copies come from,
        in the order :meth:`_batches` must decode them (the default scalar, then by index: a copy's
        source comes first)."""
        need = set(js)
        need.update(k for j in js for _, k, _ in self.copies.get(j, ()))
        s = [a[0] for a in self.arrays].index(self.scalar_name)
        out = {}
        for j in sorted(need, key=lambda j: (j != s, j)):
            dec = self._array_decoder(level, j, n)
            if dec is not None:
                out[self.arrays[j][0]] = dec
        return out

    def _points_decoder(self, level: int, n: int):
        section = f"L{level}/points64"
        if self.points_dtype != np.float64 or not self.container.has_section(section):
            return None
        return ArrayDecoder(self.read_section(section), n_points=n, dtype="float64", components=3)

    def _connectivity_batches(self, conn, lv: LevelMeta, batch_tets: int, tets_out, copy_refs: bool):
        """The connectivity stage of a decode: yields (first new vertex, tets or None, new vertices'
        refs, boundary faces or None), the boundary surface first, then batches of tets (into
        ``tets_out`` when given, see :meth:`_batches`). ``copy_refs``: hand over copies of the
        refs (the decoder rewrites its window of them on the next call)."""
        faces, nbv = conn.boundary()
        if nbv != lv.boundary_vertices:
            raise CorruptFileError("corrupt boundary section: vertex count does not match the metadata")
        refs = conn.last_refs
        yield 0, None, refs.copy() if copy_refs else refs, faces
        conn.start_tets()
        known = nbv
        while conn.tets_done < lv.tets:
            out = None if tets_out is None else tets_out[conn.tets_done:]
            tets = conn.next_tets(batch_tets, out=out)
            refs = conn.last_refs  # the batch's new vertices
            yield known, tets, refs.copy() if copy_refs else refs, None
            known = conn.vertices_known
        if known != lv.referenced_points:
            raise CorruptFileError("corrupt tet section: vertex count does not match the metadata")
        self.last_peak_border = conn.peak_border

    def _batches(self, level: int, batch_tets: int, extra: dict, tets_out: np.ndarray | None = None,
                 geometry=None, *, jobs: int = 1, depth: int = 4):
        """Decode ``level``: yields (TetBatch, {key: exact values of the batch's new vertices}).

        ``extra`` maps keys to :class:`ArrayDecoder`s fed alongside the geometry; a decoder under the
        key ``_POINTS`` is predicted from the float32 coordinates, the default scalar's from the
        float32 density. ``tets_out``, an (m, 4) int32 array for all the level's tets, receives
        them in order (the batches' tets are views of it). ``geometry``: a fresh geometry decoder
        of the level to use (default: :meth:`_geometry`'s). ``jobs`` > 1: the connectivity decodes
        in a thread of its own, up to ``depth`` batches ahead of the geometry and the point arrays
        (:class:`~.threads.RunAhead`; the same batches, its errors raised here).
        """
        lv = self.level_meta(level)
        n = self._checked_points(level)
        conn = self._connectivity(level)
        stages = self._connectivity_batches(conn, lv, batch_tets, tets_out, copy_refs=jobs > 1)
        with RunAhead(stages, depth=depth, name="tetc-connectivity") if jobs > 1 else nullcontext(stages) as source:
            geo = self._geometry(level, n) if geometry is None else geometry  # set up while the boundary decodes

            def exact(refs, pts, dens):
                out = {}
                for key, dec in extra.items():
                    if isinstance(dec, _CopyingDecoder):  # its sources are before it in extra
                        out[key] = dec.decode(refs, out, dens, positions=geo.values)
                        continue
                    ext = pts if key == _POINTS else dens if key == self.scalar_name else None
                    out[key] = dec.decode(refs, ext, positions=geo.values)
                return out

            known = 0
            node_tets = [] if level == 0 and self._nodes_coded_on_cells() else None
            for first, tets, refs, faces in source:
                pts, dens = geo.decode(refs)
                batch = TetBatch.of_vertices(0, pts, dens, faces) if faces is not None else \
                    TetBatch.of_tets(first, tets, pts, dens)
                if node_tets is not None and faces is None:
                    node_tets.append(np.array(tets, np.int32))
                yield batch, exact(refs, pts, dens)
                known = first + len(refs)
        if known < n:  # vertices no tet references: no refs, or their cells' edges and faces
            none = (np.full((n - known, 4), -1, np.int32) if node_tets is None else
                    self._node_refs(np.concatenate(node_tets) if node_tets else np.zeros((0, 4), np.int32), known, n))
            pts, dens = geo.decode(none)
            yield TetBatch.of_vertices(known, pts, dens), exact(none, pts, dens)
        geo.finish()
        for dec in extra.values():
            dec.finish()

    def _nodes_coded_on_cells(self) -> bool:
        cells = self.meta.get("cells")
        return isinstance(cells, dict) and cells.get("node_refs") is True

    def _node_refs(self, tets: np.ndarray, known: int, n: int) -> np.ndarray:
        """The geometry refs of level 0's points no tet holds, from the cells' higher-order nodes
        (the blocks alone are decoded here: no cell arrays, sets or order)."""
        meta = dict(self.meta["cells"], cell_data=[], point_sets=[], cell_sets=[], keep_order=False,
                    cell_order=False)
        cells = decode_cells(meta, self.read_section, self.container.has_section, tets, n)
        return node_refs(cells.blocks, known, n)

    def iter_decode(self, level: int = 0, *, scalar: str | None = None, component=None,
                    batch_tets: int = DEFAULT_BATCH_TETS, jobs: int = 1, depth: int = 4) -> Iterator[TetBatch]:
        """Stream the mesh of ``level`` as :class:`~gatun_py.mesh.TetBatch`es.

        The first batch holds the boundary surface and its vertices, then batches of up to
        ``batch_tets`` tets with the vertices they introduce, and a last batch with the
        unreferenced vertices (if any). Raises :class:`CorruptFileError` on damaged data, at the
        latest when the last batch is produced.

        Parameters
        ----------
        scalar : str, optional
            The point array to put in the batches' ``density`` (float32; default: the file's
            default scalar, straight from the geometry section).
        component : None, int or "magnitude"
            For a vector array: the component, or the Euclidean norm.
        jobs : int
            1: one thread. 2 or more: the connectivity decodes in a thread of its own, up to
            ``depth`` batches ahead (:class:`~gatun_py.codec.prefetch.PrefetchedDecode`); the same
            batches, while the caller works on the previous ones.
        """
        jobs = check_jobs(jobs)
        n = self._checked_points(level)
        names = [a[0] for a in self.arrays]
        if scalar is None or (scalar == self.scalar_name and component in (None, 0)):
            for batch, _ in self._batches(level, batch_tets, {}, jobs=jobs, depth=depth):
                yield batch
            return
        if scalar not in names:
            raise OptionError(f"no point array named {scalar!r}; arrays: {', '.join(map(repr, names))}")
        j = names.index(scalar)
        try:  # check the component before decoding anything
            scalar_of({scalar: np.zeros((0,) if self.arrays[j][2] == 1 else (0, self.arrays[j][2]))}, scalar, component)
        except ValueError as e:
            raise OptionError(str(e)) from None
        extra = self._array_decoders(level, [j], n)
        for batch, exact in self._batches(level, batch_tets, extra, jobs=jobs, depth=depth):
            with np.errstate(over="ignore"):  # beyond float32: inf, like any float32 rounding
                batch.density = scalar_of(exact, scalar, component).astype(np.float32)
            yield batch

    def decode_mesh(self, level: int = 0, *, jobs: int | None = None):
        """The whole mesh of ``level`` as a :class:`~gatun_py.mesh.TetMesh` (vertices in decode order).

        Coordinates in their stored dtype and every point array in its own, bit for bit.

        Parameters
        ----------
        level : int
            A stored level (0: the full mesh).
        jobs : int, optional
            Threads (default: all cores). With two or more, the connectivity decodes in a thread
            of its own ahead of the geometry and the point arrays (both decoders release the GIL);
            the mesh is the same whatever ``jobs`` is.

        Examples
        --------
        >>> from gatun_py.warmup import SHIPPED_TETC
        >>> r = TetcReader(SHIPPED_TETC)
        >>> m = r.decode_mesh(jobs=2)
        >>> m.n_tets == r.level_meta(0).tets
        True
        >>> bool((m.tets == r.decode_mesh(jobs=1).tets).all())
        True
        """
        jobs = check_jobs(jobs)
        lv = self.level_meta(level)
        n = self._checked_points(level)
        extra = {}
        pdec = self._points_decoder(level, n)
        if pdec is not None:
            extra[_POINTS] = pdec
        extra.update(self._array_decoders(level, range(len(self.arrays)), n))
        points = np.empty((n, 3), np.float32)
        density = np.empty(n, np.float32)
        tets = np.empty((lv.tets, 4), np.int32)  # decoded into in place, batch by batch
        batch_tets = DEFAULT_BATCH_TETS
        if jobs > 1:  # the last batch's geometry waits for nothing to overlap: a dozen batches or more
            batch_tets = min(DEFAULT_BATCH_TETS, max(_MIN_RUN_AHEAD_BATCH_TETS, lv.tets // 12))
        for b, _ in self._batches(level, batch_tets, extra, tets_out=tets, jobs=jobs):
            k = len(b.points)
            points[b.first:b.first + k] = b.points
            density[b.first:b.first + k] = b.density
        point_data = {}
        for name, dt, _ in self.arrays:
            point_data[name] = extra[name].values if name in extra else density
        if pdec is not None:
            if not np.array_equal(pdec.values.astype(np.float32), points):
                raise CorruptFileError("corrupt file: float64 coordinates disagree with the geometry section")
            points = pdec.values
        elif self.points_dtype == np.float64:
            points = points.astype(np.float64)
        try:
            return TetMesh(points, density, tets, self.scalar_name, point_data=point_data)
        except Exception as e:  # a mesh that fails its own invariants can only come from damage
            raise CorruptFileError(f"corrupt file: decoded mesh is invalid ({e})") from None


class _CopyingDecoder:
    """Streaming decoder of a point array some of whose components are copies of other arrays'
    (the file's ``copies``): the coded components from ``dec`` (None when every one is a copy),
    the others from the batch's values of their sources. Same interface as :class:`ArrayDecoder`
    but for :meth:`decode`, which takes the batch's decoded arrays."""

    def __init__(self, dec, dtype, k: int, n: int, stored: list, copies: list):
        self.dec, self.stored, self.copies = dec, stored, copies  # copies: [(c, source name, kc)]
        self.values = np.empty((n,) if k == 1 else (n, k), dtype)
        self._cols = self.values.reshape(n, k)
        self.n_points, self.n_decoded = n, 0

    def decode(self, refs, out: dict, dens, positions=None) -> np.ndarray:
        """The next ``len(refs)`` vertices; ``out``: the batch's values of the sources by name
        (a float32 default scalar, held by the geometry, is ``dens``)."""
        a, m = self.n_decoded, len(refs)
        cols = self._cols[a:a + m]
        if self.dec is not None:
            part = self.dec.decode(refs, None, positions=positions)
            cols[:, self.stored] = part.reshape(m, len(self.stored))
        for c, src, kc in self.copies:
            v = out.get(src, dens)
            cols[:, c] = v if v.ndim == 1 else v[:, kc]
        self.n_decoded = a + m
        return self.values[a:a + m]

    def finish(self) -> np.ndarray:
        if self.dec is not None:
            self.dec.finish()
        if self.n_decoded != self.n_points:
            raise CorruptFileError("corrupt array section: fewer vertices decoded than announced")
        return self.values


def iter_decode(source, level: int = 0, **kw) -> Iterator[TetBatch]:
    """Stream a ``.tetc`` file's level as :class:`~gatun_py.mesh.TetBatch`es (see :meth:`TetcReader.iter_decode`)."""
    return TetcReader(source).iter_decode(level, **kw)


def decode_mesh(source, level: int = 0, *, jobs: int | None = None):
    """Decode a whole level of a ``.tetc`` file into a :class:`~gatun_py.mesh.TetMesh` (see
    :meth:`TetcReader.decode_mesh`)."""
    return TetcReader(source).decode_mesh(level, jobs=jobs)
