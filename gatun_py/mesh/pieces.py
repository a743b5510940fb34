"""Partitioned meshes: the pieces a parallel solver writes, and the table that joins them.

A solver running on N ranks writes one piece per rank: a ``.pvtu`` file naming its ``.vtu``
pieces, an Exodus decomposition ``name.e.N.0`` .. ``name.e.N.(N-1)``, a VTKHDF file of N
partitions (named here ``run.vtkhdf#i``: partition i of the file), or simply N files. Each piece
has its own local numbering; the points on the interfaces between pieces are repeated in every
piece that uses them.

:func:`piece_paths` finds the pieces of an input; :func:`read_piece` reads one. The
*interface table* (:func:`interface_table`) joins them without ever holding the whole mesh: it
looks only at each piece's boundary vertices (an interface point is on the boundary of every piece
that holds it), matches them across pieces by the bits of their coordinates, checks that matched
points also carry the same bits in every point array (else the decomposition does not conform),
and gives each shared point one id. From the same boundary data it counts the whole mesh's
boundary faces (a face on the boundary of two pieces is inside the whole mesh).
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._atomic import atomic_path
from ..errors import MeshError, OptionError, ReadError
from .exodus import read_exodus
from .io import mesh_from_meshio, read_mesh, write_mesh
from .vtkhdf import is_vtkhdf, read_vtkhdf_partition, vtkhdf_partitions
from .model import MIN_SAMPLES_PER_DIAGONAL, TetMesh
from .validate import MeshReport

__all__ = ["PVTU_SUFFIX", "BoundaryPart", "InterfaceTable", "boundary_part", "exodus_pieces", "interface_table",
           "is_partitioned", "piece_file", "piece_paths", "pvtu_pieces", "pvtu_scalar", "read_piece",
           "refine_midpoints", "vtkhdf_pieces", "write_pvtu", "write_pvtu_index"]

PVTU_SUFFIX = ".pvtu"
MAX_PIECES = 4096  # the bricked format's limit (a piece is one brick or more)
# name.e.N.i or name.exo.N.i: Exodus's (Nemesis) file-per-rank naming, i zero-padded to N's width
_EXODUS_PIECE = re.compile(r"^(?P<base>.+\.(?:e|exo|ex2))\.(?P<n>\d+)\.(?P<i>\d+)$", re.IGNORECASE)
# run.vtkhdf#i: partition i of a VTKHDF file (no file of that name: a VTKHDF file ends in .vtkhdf)
_VTKHDF_PART = re.compile(r"^(?P<file>.+\.vtkhdf)#(?P<i>\d+)$", re.IGNORECASE | re.DOTALL)


# -- finding the pieces ----------------------------------------------------------------------------

def pvtu_pieces(path) -> list[Path]:
    """The ``.vtu`` pieces a ``.pvtu`` file names (``<Piece Source=...>``, relative to its folder),
    in its order; :class:`ReadError` for a file that is not a parallel unstructured grid or names
    a piece that does not exist."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise ReadError(f"no such file: {path}") from None
    except (ET.ParseError, OSError) as e:
        raise ReadError(f"cannot read {path} as a .pvtu file: {e}") from None
    grid = root.find("PUnstructuredGrid")
    if root.tag != "VTKFile" or grid is None:
        raise ReadError(f"{path}: not a parallel unstructured grid (.pvtu: VTKFile/PUnstructuredGrid)")
    sources = [p.get("Source") for p in grid.findall("Piece")]
    if not sources or any(not s for s in sources):
        raise ReadError(f"{path}: lists no pieces" if not sources else f"{path}: a <Piece> without a Source")
    return _existing(path, [path.parent / s for s in sources])


def pvtu_scalar(path) -> str | None:
    """The default scalar a ``.pvtu`` file names (``<PPointData Scalars=...>``), or None."""
    try:
        grid = ET.parse(path).getroot().find("PUnstructuredGrid")
    except (ET.ParseError, OSError):
        return None
    pd = grid.find("PPointData") if grid is not None else None
    return (pd.get("Scalars") or None) if pd is not None else None


def exodus_pieces(path) -> list[Path] | None:
    """Every file of the Exodus decomposition ``path`` belongs to (``name.e.N.i``: rank i of N), in
    rank order; None when ``path`` is not named so."""
    path = Path(path)
    m = _EXODUS_PIECE.match(path.name)
    if m is None:
        return None
    n, width = int(m.group("n")), len(m.group("i"))
    if not 1 <= n <= MAX_PIECES:
        raise ReadError(f"{path}: a decomposition into {n} pieces (1..{MAX_PIECES})")
    if int(m.group("i")) >= n:
        raise ReadError(f"{path}: rank {int(m.group('i'))} of a decomposition into {n}")
    return _existing(path, [path.with_name(f"{m.group('base')}.{m.group('n')}.{i:0{width}d}") for i in range(n)])


def _existing(source: Path, paths: list[Path]) -> list[Path]:
    missing = [p for p in paths if not p.is_file()]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ReadError(f"{source}: piece {missing[0]} is missing{more}")
    if len(paths) > MAX_PIECES:
        raise ReadError(f"{source}: {len(paths)} pieces; at most {MAX_PIECES}")
    return paths


def is_partitioned(path, *, step: int | None = None) -> bool:
    """``path`` names a partitioned mesh (a ``.pvtu`` file, a piece of an Exodus decomposition, or
    a VTKHDF file whose ``step``, default the last, has several partitions)."""
    p = Path(path)
    if is_vtkhdf(p) and p.is_file():
        try:
            return vtkhdf_partitions(p, step=step)[0] > 1
        except (ReadError, OptionError):
            return False  # the single-mesh reader says what is wrong with it
    return p.suffix.lower() == PVTU_SUFFIX or _EXODUS_PIECE.match(p.name) is not None


def vtkhdf_pieces(path, *, step: int | None = None) -> list[Path] | None:
    """The partitions of ``step`` (default the last) of a VTKHDF file, as pieces ``path#i``; None
    when the file has one partition there."""
    path = Path(path)
    n, _, _ = vtkhdf_partitions(path, step=step)
    if n < 2:
        return None
    if n > MAX_PIECES:
        raise ReadError(f"{path}: {n} partitions; at most {MAX_PIECES}")
    return [Path(f"{path}#{i}") for i in range(n)]


def piece_file(piece) -> Path:
    """The file a piece is read from (a VTKHDF partition's file; else the piece itself)."""
    m = _VTKHDF_PART.match(os.fspath(piece))
    return Path(m.group("file")) if m and not Path(piece).exists() else Path(piece)


def piece_paths(inputs, *, single: bool = False, step: int | None = None) -> list[Path]:
    """The pieces of ``inputs``: a ``.pvtu`` file's pieces, an Exodus decomposition's files (any
    one of them named), a VTKHDF file's partitions (of ``step``, default the last), or several
    mesh files, each one piece; with ``single``, also one plain mesh file (a piece on its own).

    Examples
    --------
    >>> piece_paths(["a.vtu", "b.vtu"])  # doctest: +SKIP
    [PosixPath('a.vtu'), PosixPath('b.vtu')]
    """
    inputs = [Path(p) for p in ([inputs] if isinstance(inputs, (str, os.PathLike)) else inputs)]
    if not inputs:
        raise OptionError("no pieces given")
    if len(inputs) == 1:
        p = inputs[0]
        if p.suffix.lower() == PVTU_SUFFIX:
            return pvtu_pieces(p)
        ex = exodus_pieces(p)
        if ex is not None:
            return ex
        if is_vtkhdf(p) and p.is_file():
            parts = vtkhdf_pieces(p, step=step)
            if parts is not None:
                return parts
        if single:
            return _existing(p, [p])
        raise OptionError(f"{p} is one mesh, not pieces of one: give a .pvtu file, an Exodus decomposition "
                          "(name.e.N.i) or several files")
    nested = [p for p in inputs if is_partitioned(p)]
    if nested:
        raise OptionError(f"{nested[0]} is itself partitioned: give it alone, or its pieces")
    if len({os.path.realpath(p) for p in inputs}) != len(inputs):
        raise OptionError("a piece is given twice")
    return _existing(inputs[0], inputs)


def read_piece(path, read_options: dict | None = None) -> tuple[TetMesh, MeshReport]:
    """One piece as a validated mesh (``read_options`` as for :func:`~gatun_py.mesh.read_mesh`)."""

    opts = dict(read_options or {})
    path = Path(path)
    part = _VTKHDF_PART.match(os.fspath(path))
    if part and not path.exists():
        file = Path(part.group("file"))
        m = read_vtkhdf_partition(file, int(part.group("i")), step=opts.get("time_step"))
        mesh, report = mesh_from_meshio(m, scalar=opts.get("scalar"), cell_to_point=opts.get("cell_to_point", False),
                                        source=str(path))
        _, k, n = vtkhdf_partitions(file, step=opts.get("time_step"))
        if n > 1:  # pieces are one step: the file's other steps are not stored
            report.notes.insert(0, f"time step {k} of 0..{n - 1} read (the partitions of one step)")
        return mesh, report
    if _EXODUS_PIECE.match(path.name):
        if not path.is_file():
            raise ReadError(f"no such file: {path}")
        m, notes = read_exodus(path, time_step=opts.get("time_step"))
        mesh, report = mesh_from_meshio(m, scalar=opts.get("scalar"), cell_to_point=opts.get("cell_to_point", False),
                                        source=str(path))
        report.notes[:0] = notes
        return mesh, report
    return read_mesh(path, **opts)


# -- the interface table -----------------------------------------------------------------------------

def _bits(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.uint8).reshape(a.shape[0], -1)


def _void(rows: np.ndarray) -> np.ndarray:
    rows = np.ascontiguousarray(rows)
    return rows.view(f"V{rows.shape[1]}").ravel()


@dataclass
class BoundaryPart:
    """What the interface table needs of one part (a piece, or a brick cut from one).

    Attributes
    ----------
    vertices : (b,) int64
        The part's boundary vertices (its own ids), sorted.
    coords : (b,) void
        Their coordinates' bits, one scalar each.
    values : (b, w) uint8
        Their bits in every point array, side by side.
    faces : (f, 3) int32
        The part's boundary faces, as positions in ``vertices``.
    points32 : (b, 3) float32
        The boundary vertices' coordinates in float32 (for the sample step, as the whole mesh's).
    """

    vertices: np.ndarray
    coords: np.ndarray
    values: np.ndarray
    faces: np.ndarray
    points32: np.ndarray


def boundary_part(mesh: TetMesh, array_names: list[str] | None = None) -> BoundaryPart:
    """The boundary vertices and faces of ``mesh`` with their bits (see :class:`BoundaryPart`)."""
    bf = mesh.boundary_faces()
    verts = np.unique(bf)
    names = list(mesh.point_data) if array_names is None else array_names
    cols = [_bits(mesh.point_data[n][verts]) for n in names]
    values = np.concatenate(cols, axis=1) if cols else np.zeros((verts.size, 0), np.uint8)
    return BoundaryPart(verts.astype(np.int64), _void(_bits(mesh.points[verts])), values,
                        np.searchsorted(verts, bf).astype(np.int32), np.asarray(mesh.points32[verts], np.float32))


@dataclass
class InterfaceTable:
    """The points shared between parts, each with one id, and the whole mesh's boundary.

    Attributes
    ----------
    n_shared : int
        Shared points (each counted once).
    shared : list of ((s,) int64, (s,) int64)
        Per part: its shared vertices (its own ids) and their ids (0 .. n_shared - 1).
    boundary_faces : int
        Faces on the boundary of the whole mesh (a face on the boundary of two parts is inside).
    render_step : float
        Half the median edge length of those faces (:func:`~gatun_py.mesh.default_step`).
    occurrences : int
        Copies of the shared points over all parts (the whole mesh has
        ``sum(points) - occurrences + n_shared`` points).
    """

    n_shared: int
    shared: list = field(default_factory=list)
    boundary_faces: int = 0
    render_step: float = 1.0
    occurrences: int = 0


def interface_table(parts: list[BoundaryPart], names: list[str] | None = None) -> InterfaceTable:
    """Join parts by their boundary vertices' coordinate bits (see the module's description).

    ``names``: what to call each part in messages.

    Raises
    ------
    MeshError
        Points at the same coordinates with other values in some point array (a non-conforming
        decomposition, or pieces of different results), a part with two boundary points at one
        position that another part shares (ambiguous), or a face on the boundary of three parts.
    """
    names = names or [f"piece {i}" for i in range(len(parts))]
    sizes = [p.vertices.size for p in parts]
    owner = np.repeat(np.arange(len(parts), dtype=np.int64), sizes)
    local = np.concatenate([np.arange(n, dtype=np.int64) for n in sizes]) if parts else np.zeros(0, np.int64)
    keys = np.concatenate([p.coords for p in parts]) if parts else np.zeros(0, "V1")
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    start = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]])) if ks.size else np.zeros(0, np.int64)
    count = np.diff(np.append(start, ks.size))
    group = np.repeat(np.arange(start.size), count)  # group of every sorted occurrence
    own = owner[order]
    # a group is shared when more than one part holds it
    first_owner = own[start]
    multi = np.zeros(start.size, bool)
    np.logical_or.at(multi, group, own != first_owner[group])
    occ = multi[group]
    # a part holding one shared position twice: which of its points is the other parts' is unknown
    pairs = own[occ] * (start.size + 1) + group[occ]
    if np.unique(pairs).size != pairs.size:
        dup = np.flatnonzero(np.diff(np.sort(pairs)) == 0)[0]
        pk = np.sort(pairs)[dup]
        p, g = int(pk // (start.size + 1)), int(pk % (start.size + 1))
        raise MeshError(f"{names[p]} has two boundary points at {_where(parts, own, local, order, start[g])}, a "
                        "position other pieces share: cannot tell which one they share")
    # every copy of a shared point must carry the same bits as the group's first copy
    idx = np.flatnonzero(occ)
    if idx.size:
        first = start[group[idx]]
        widths = {p.values.shape[1] for p in parts}
        if len(widths) != 1:
            raise MeshError("the pieces hold point arrays of different sizes")
        vals = np.concatenate([p.values for p in parts])
        rows = order[idx]
        ref = order[first]
        bad = (vals[rows] != vals[ref]).any(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            a, b = int(owner[ref[i]]), int(owner[rows[i]])
            raise MeshError(f"the pieces do not conform: the point at {_where(parts, own, local, order, first[i])} "
                            f"has other array values in {names[b]} than in {names[a]} "
                            f"({int(bad.sum())} interface points differ)")
    gid = np.cumsum(multi) - 1  # id of every shared group
    shared = []
    sorted_part = own[idx] if idx.size else np.zeros(0, np.int64)
    by_part = np.argsort(sorted_part, kind="stable")
    bounds = np.searchsorted(sorted_part[by_part], np.arange(len(parts) + 1))
    for k, part in enumerate(parts):
        sel = idx[by_part[bounds[k]:bounds[k + 1]]]
        loc = local[order[sel]]
        ids = gid[group[sel]].astype(np.int64)
        o = np.argsort(loc)
        shared.append((part.vertices[loc[o]], ids[o]))
    n_shared = int(multi.sum())
    _near_misses(parts, own, local, order, occ, names)
    bf, step = _outer_faces(parts, shared, n_shared, names)
    return InterfaceTable(n_shared, shared, bf, step, int(occ.sum()))


# Boundary points of two parts closer than this share of the boundary's extent and of their own
# shortest boundary edges, yet not the same bits, are an interface that does not match (rounded
# differently by two ranks, say): two distinct surface points of a mesh are an edge apart.
NEAR_MISS = 1e-6
NEAR_MISS_EDGE = 1e-3


def _shortest_edges(part: BoundaryPart) -> np.ndarray:
    """Every boundary vertex's shortest boundary edge."""
    p = part.points32.astype(np.float64)
    out = np.full(part.vertices.size, np.inf)
    f = part.faces
    for a, b in ((0, 1), (1, 2), (2, 0)):
        ln = np.linalg.norm(p[f[:, a]] - p[f[:, b]], axis=1)
        np.minimum.at(out, f[:, a], ln)
        np.minimum.at(out, f[:, b], ln)
    return out


def _near_misses(parts, own, local, order, occ, names) -> None:
    """Refuse parts whose unmatched boundary points nearly coincide with another part's."""
    from scipy.spatial import cKDTree  # scipy comes with scikit-image

    rows = order[~occ]
    if rows.size < 2:
        return
    p_own = own[~occ]
    pts = np.concatenate([p.points32 for p in parts]).astype(np.float64)
    offsets = np.cumsum([0] + [p.vertices.size for p in parts])
    xyz = pts[offsets[p_own] + local[rows]]
    diag = float(np.linalg.norm(xyz.max(axis=0) - xyz.min(axis=0)))
    if diag == 0:
        return
    pairs = cKDTree(xyz).query_pairs(NEAR_MISS * diag, output_type="ndarray")
    pairs = pairs[p_own[pairs[:, 0]] != p_own[pairs[:, 1]]]
    if pairs.size:  # only points much closer than their own edges are the same point rounded otherwise
        edge = np.concatenate([_shortest_edges(p) for p in parts])[offsets[p_own] + local[rows]]
        dist = np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1)
        pairs = pairs[dist < NEAR_MISS_EDGE * np.minimum(edge[pairs[:, 0]], edge[pairs[:, 1]])]
    if pairs.size:
        i, j = pairs[0]
        at = "(" + ", ".join(f"{float(x):.9g}" for x in xyz[i]) + ")"
        raise MeshError(f"the pieces do not conform: {names[int(p_own[i])]} and {names[int(p_own[j])]} have "
                        f"interface points at {at} that differ in their last bits ({len(pairs)} such pairs)")


def _where(parts, own, local, order, pos) -> str:
    p = parts[int(own[pos])]
    return "(" + ", ".join(f"{float(x):.9g}" for x in p.points32[int(local[order[pos]])]) + ")"


def _outer_faces(parts, shared, n_shared: int, names) -> tuple[int, float]:
    """Faces on the boundary of the whole mesh, and :func:`~gatun_py.mesh.default_step` of them (half
    their edges' median length, at most 1/512 of their bounding box's diagonal)."""
    face_keys, face_part = [], []
    cut_of = []
    for k, (part, (verts, ids)) in enumerate(zip(parts, shared)):
        cid = np.full(part.vertices.size, -1, np.int64)
        cid[np.searchsorted(part.vertices, verts)] = ids
        cut_of.append(cid)
        f = cid[part.faces]
        inner = (f >= 0).all(axis=1)
        s = np.sort(f[inner], axis=1)
        face_keys.append((s[:, 0] * n_shared + s[:, 1]) * n_shared + s[:, 2] if n_shared < (1 << 21)
                         else _void(_bits(s)))
        face_part.append(np.full(s.shape[0], k, np.int64))
    if face_keys and sum(len(x) for x in face_keys):
        keys = np.concatenate(face_keys)
        uniq, inv, cnt = np.unique(keys, return_inverse=True, return_counts=True)
        if (cnt > 2).any():
            g = int(np.flatnonzero(cnt > 2)[0])
            parts_of = np.concatenate(face_part)[inv.ravel() == g]
            raise MeshError("the pieces overlap: a face is on the boundary of "
                            + ", ".join(names[int(p)] for p in parts_of))
        interior = (cnt == 2)[inv.ravel()]
        b = np.cumsum([0] + [len(x) for x in face_keys])
        interior_of = [interior[b[k]:b[k + 1]] for k in range(len(parts))]
    else:
        interior_of = [np.zeros(0, bool) for _ in parts]
    n_faces, lengths = 0, []
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for part, cid, inner_int in zip(parts, cut_of, interior_of):
        inner = (cid[part.faces] >= 0).all(axis=1)
        keep = np.ones(part.faces.shape[0], bool)
        keep[np.flatnonzero(inner)[inner_int]] = False
        faces = part.faces[keep]
        n_faces += faces.shape[0]
        p = part.points32.astype(np.float64)
        e = np.concatenate([p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 1]],
                            p[faces[:, 0]] - p[faces[:, 2]]])
        ln = np.linalg.norm(e, axis=1)
        lengths.append(ln[ln > 0])
        if faces.size:
            used = p[np.unique(faces)]
            lo, hi = np.minimum(lo, used.min(axis=0)), np.maximum(hi, used.max(axis=0))
    ln = np.concatenate(lengths) if lengths else np.zeros(0)
    if not ln.size:
        return n_faces, 1.0
    step = float(np.median(ln)) * 0.5
    diag = float(np.linalg.norm(hi - lo))
    if diag > 0 and np.isfinite(diag):
        step = min(step, diag / MIN_SAMPLES_PER_DIAGONAL)
    return n_faces, step


# -- writing pieces (test data, and what a solver writes) ---------------------------------------------

_VTK_TYPES = {"f4": "Float32", "f8": "Float64", "i1": "Int8", "i2": "Int16", "i4": "Int32", "i8": "Int64",
              "u1": "UInt8", "u2": "UInt16", "u4": "UInt32", "u8": "UInt64"}


def _vtk_type(dtype) -> str:
    dt = np.dtype(dtype)
    return _VTK_TYPES.get(f"{dt.kind}{dt.itemsize}", "Float64")


def write_pvtu(pieces: list[TetMesh], path, *, force: bool = False) -> list[Path]:
    """Write ``pieces`` as ``path`` (a ``.pvtu`` file) and its ``.vtu`` pieces beside it
    (``<stem>_<i>.vtu``), each with its own numbering and every point array. Returns the pieces' paths.

    Examples
    --------
    >>> import tempfile, os
    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> from gatun_py.mesh.partition import partition_tets, split_bricks
    >>> m = jittered_grid((5, 5, 5), jitter=0.2)
    >>> out = os.path.join(tempfile.mkdtemp(), "m.pvtu")
    >>> [p.name for p in write_pvtu([b.mesh for b in split_bricks(m, partition_tets(m, 2))], out)]
    ['m_0.vtu', 'm_1.vtu']
    >>> len(pvtu_pieces(out))
    2
    """

    path = Path(path)
    if path.suffix.lower() != PVTU_SUFFIX:
        raise OptionError(f"{path}: a partitioned mesh is written as a .pvtu file")
    if not pieces:
        raise OptionError("no pieces to write")
    out = [path.with_name(f"{path.stem}_{i}.vtu") for i in range(len(pieces))]
    for p, m in zip(out, pieces):
        write_mesh(m, p, force=force)
    write_pvtu_index(path, out, pieces[0], force=force)
    return out


def write_pvtu_index(path, pieces: list, like: TetMesh, *, force: bool = False) -> None:
    """Write the ``.pvtu`` file naming ``pieces`` (``.vtu`` files beside it, already written),
    whose point arrays are those of ``like``."""

    path = Path(path)
    arrays = "".join(f'      <PDataArray type="{_vtk_type(a.dtype)}" Name="{n}" '
                     f'NumberOfComponents="{1 if a.ndim == 1 else a.shape[1]}"/>\n'
                     for n, a in like.user_point_data.items())
    scalars = f' Scalars="{like.scalar_name}"' if like.scalar_name in like.user_point_data else ""
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="PUnstructuredGrid" version="0.1" byte_order="LittleEndian">\n'
            '  <PUnstructuredGrid GhostLevel="0">\n'
            f'    <PPointData{scalars}>\n{arrays}    </PPointData>\n'
            f'    <PPoints>\n      <PDataArray type="{_vtk_type(like.points.dtype)}" NumberOfComponents="3"/>\n'
            '    </PPoints>\n'
            + "".join(f'    <Piece Source="{Path(p).name}"/>\n' for p in pieces)
            + '  </PUnstructuredGrid>\n</VTKFile>\n')
    with atomic_path(path, force=force) as tmp:
        tmp.write_text(text)


def refine_midpoints(mesh: TetMesh) -> TetMesh:
    """Every tet cut into 8 at its edge midpoints (Bey's red refinement), every point array
    interpolated at the midpoints (the mean of the two ends; integer arrays: the smaller end).

    A midpoint depends only on its edge's two ends (``(a + b) / 2`` is symmetric bit for bit), so
    pieces of a mesh refined one by one meet exactly where the whole mesh refined at once would.

    Examples
    --------
    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> m = jittered_grid((3, 3, 3), jitter=0.1)
    >>> r = refine_midpoints(m)
    >>> r.n_tets == 8 * m.n_tets, bool(np.isclose(r.signed_volumes().sum(), m.signed_volumes().sum()))
    (True, True)
    """
    t = mesh.tets.astype(np.int64)
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    e = np.concatenate([np.sort(t[:, [a, b]], axis=1) for a, b in pairs])
    n = mesh.n_points
    key = e[:, 0] * n + e[:, 1]
    uniq, inv = np.unique(key, return_inverse=True)
    a, b = uniq // n, uniq % n
    mid = (np.arange(uniq.size) + n).astype(np.int64)[inv.ravel()].reshape(6, -1).T  # (m, 6) midpoint ids

    def interp(x):
        x = np.asarray(x)
        if x.dtype.kind == "f":
            return np.concatenate([x, ((x[a] + x[b]) / x.dtype.type(2)).astype(x.dtype)])
        return np.concatenate([x, np.minimum(x[a], x[b])])

    pts = interp(mesh.points)
    v0, v1, v2, v3 = t.T
    m01, m02, m03, m12, m13, m23 = mid.T
    kids = np.concatenate([
        np.stack([v0, m01, m02, m03], 1), np.stack([m01, v1, m12, m13], 1),
        np.stack([m02, m12, v2, m23], 1), np.stack([m03, m13, m23, v3], 1),
        np.stack([m01, m02, m03, m13], 1), np.stack([m01, m02, m12, m13], 1),
        np.stack([m02, m03, m13, m23], 1), np.stack([m02, m12, m13, m23], 1)])
    # orient every child positively (the octahedron's four by their volume's sign)
    p = pts.astype(np.float64)
    d = p[kids[:, 1:]] - p[kids[:, :1]]
    neg = np.einsum("ij,ij->i", d[:, 0], np.cross(d[:, 1], d[:, 2])) < 0
    kids[neg] = kids[neg][:, [0, 2, 1, 3]]
    data = {name: interp(x) for name, x in mesh.point_data.items()}
    return TetMesh(pts, None, kids.astype(np.int32), mesh.scalar_name, point_data=data)
