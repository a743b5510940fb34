"""Writing and reading ``.tetc`` files: levels of compressed meshes and the streaming decoder.

A file holds one or more *levels* (level 0 is the full mesh; the simplify stage adds
pre-simplified levels). Level ``i`` has the sections ``L{i}/boundary`` and ``L{i}/tets``
(connectivity, :mod:`.cutborder`), ``L{i}/geometry`` (coordinates and density in decode order,
:mod:`.geometry`) and optionally ``L{i}/forest`` (the remaining merge forest in decode order,
:mod:`.forest`). The metadata lists the levels with the counts
the decoder needs, so a reader seeks straight to one level.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from .._atomic import write_bytes_atomic
from ..errors import CorruptFileError, OptionError
from ..mesh import TetBatch, TetMesh, default_step
from .container import Container, build_container
from .cutborder import ConnectivityDecoder, encode_connectivity
from .forest import decode_forest, encode_forest, forest_header
from .geometry import GeometryDecoder, encode_geometry

FORMAT_NAME = "tetc"
DEFAULT_BATCH_TETS = 65536
# a coded tet costs at least a few hundredths of a bit, a vertex at least a fraction of a byte:
# counts beyond these bounds cannot come from a stream of the given size (rejected before allocating)
_MAX_TETS_PER_BYTE = 2000
_MAX_FACES_PER_BYTE = 2000


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
    """

    level: int
    ratio: float
    merges_before: int
    mesh: object
    forest: tuple | None = None


@dataclass
class EncodedLevel:
    """Sections and figures of one encoded level."""

    level: int
    sections: dict
    meta: dict
    vertex_order: np.ndarray
    peak_border: int


def encode_level(payload: LevelPayload) -> EncodedLevel:
    """Compress one level: connectivity, geometry (in decode order) and the optional forest."""
    mesh = payload.mesh
    conn = encode_connectivity(mesh.n_points, mesh.tets)
    vo = conn.vertex_order
    geometry = encode_geometry(np.asarray(mesh.points)[vo], np.asarray(mesh.density)[vo], conn.predictors)
    i = int(payload.level)
    sections = {f"L{i}/boundary": conn.boundary_code, f"L{i}/tets": conn.tet_code, f"L{i}/geometry": geometry}
    if payload.forest is not None:
        parent, rank = (np.asarray(a) for a in payload.forest)
        if parent.shape != (mesh.n_points,) or rank.shape != (mesh.n_points,):
            raise OptionError(f"level {i}: forest does not match the mesh ({mesh.n_points} points)")
        dec_of = np.empty(mesh.n_points, np.int64)
        dec_of[vo] = np.arange(mesh.n_points)
        sections[f"L{i}/forest"] = encode_forest(dec_of[parent[vo]].astype(np.int32), rank[vo])
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
        "has_forest": payload.forest is not None,
    }
    return EncodedLevel(i, sections, meta, vo, conn.peak_border)


def encode_tetc(levels: list[LevelPayload], *, source: str = "", progress=None) -> bytes:
    """Build a whole ``.tetc`` file from levels (level 0 first).

    Parameters
    ----------
    levels : list of LevelPayload
    source : str
        Source file name, recorded in the metadata.
    progress : callable, optional
        Called with each finished level number.
    """
    if not levels:
        raise OptionError("nothing to write: no levels")
    mesh0 = levels[0].mesh
    encoded = []
    for lv in levels:
        encoded.append(encode_level(lv))
        if progress is not None:
            progress(lv.level)
    lo, hi = mesh0.bbox
    meta = {
        "format": FORMAT_NAME,
        "points": int(mesh0.n_points),
        "tets": int(mesh0.n_tets),
        "boundary_faces": encoded[0].meta["boundary_faces"],
        "bbox": [lo.tolist(), hi.tolist()],
        "scalar": str(mesh0.scalar_name),
        "scalar_range": [float(x) for x in mesh0.scalar_range],
        "source": os.path.basename(str(source)),
        # The full mesh's volume-mode sample step, so that every level and ratio samples alike.
        "render_step": float(default_step(mesh0.points, mesh0.boundary_faces())),
        "levels": [e.meta for e in encoded],
    }
    sections = [(name, data) for e in encoded for name, data in e.sections.items()]
    return build_container(meta, sections)


def write_tetc(path, mesh_or_levels, *, source: str = "", force: bool = False, progress=None) -> int:
    """Compress a mesh (or a list of :class:`LevelPayload`) into ``path`` atomically; returns bytes written."""
    levels = mesh_or_levels if isinstance(mesh_or_levels, list) else [LevelPayload(0, 0.0, 0, mesh_or_levels)]
    data = encode_tetc(levels, source=source, progress=progress)
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
    levels : list of dict
        Per-level metadata (level, ratio, merges_before, points, tets, ...), in file order.
    """

    def __init__(self, source):
        self.container = Container(source)
        self.meta = self.container.meta
        if self.meta.get("format") != FORMAT_NAME:
            raise CorruptFileError(f"{self.container.name}: metadata does not describe a tetc mesh")
        levels = self.meta.get("levels")
        if not isinstance(levels, list) or not levels:
            raise CorruptFileError(f"{self.container.name}: no levels in the metadata")
        self.levels = []
        for lv in levels:
            if not isinstance(lv, dict):
                raise CorruptFileError("corrupt metadata: bad level entry")
            _int(lv, "level", 0, 64)
            n = _int(lv, "points")
            _int(lv, "tets")
            _int(lv, "boundary_faces")
            _int(lv, "boundary_vertices", 0, n)
            _int(lv, "referenced_points", 0, n)
            self.levels.append(lv)

    @property
    def scalar_name(self) -> str:
        name = self.meta.get("scalar", "density")
        return name if isinstance(name, str) else "density"

    def level_meta(self, level: int = 0) -> dict:
        for lv in self.levels:
            if lv["level"] == level:
                return lv
        raise OptionError(f"level {level} is not stored in this file (stored: {[lv['level'] for lv in self.levels]})")

    def read_section(self, name: str) -> bytes:
        """The CRC-checked payload of section ``name``."""
        return self.container.read_section(name)

    def read_forest(self, level: int = 0):
        """The merge forest of ``level`` in decode order as (parent, rank), or None if not stored."""
        lv = self.level_meta(level)
        name = f"L{level}/forest"
        if not self.container.has_section(name):
            if lv.get("has_forest"):
                raise CorruptFileError(f"missing section {name!r}")
            return None
        return decode_forest(self.read_section(name), lv["points"])

    def forest_merges(self) -> int:
        """Merges the file's full forest holds (0 when it stores none), from the section header only."""
        lv0 = min(self.levels, key=lambda lv: lv["level"])
        name = f"L{lv0['level']}/forest"
        if not self.container.has_section(name):
            return 0
        n, k = forest_header(self.read_section(name))
        if n != lv0["points"]:
            raise CorruptFileError(f"{name}: covers {n} vertices, the level has {lv0['points']}")
        return k

    def iter_decode(self, level: int = 0, *, batch_tets: int = DEFAULT_BATCH_TETS) -> Iterator[TetBatch]:
        """Stream the mesh of ``level`` as :class:`~gatun_py.mesh.TetBatch`es.

        The first batch holds the boundary surface and its vertices, then batches of up to
        ``batch_tets`` tets with the vertices they introduce, and a last batch with the
        unreferenced vertices (if any). Raises :class:`CorruptFileError` on damaged data, at the
        latest when the last batch is produced.
        """
        lv = self.level_meta(level)
        n, m, nf = lv["points"], lv["tets"], lv["boundary_faces"]
        bcode = self.read_section(f"L{level}/boundary")
        tcode = self.read_section(f"L{level}/tets")
        if m > _MAX_TETS_PER_BYTE * (len(tcode) + 8) or nf > _MAX_FACES_PER_BYTE * (len(bcode) + 8):
            raise CorruptFileError("corrupt metadata: counts cannot fit in the stored sections")
        if (m == 0) != (nf == 0):
            raise CorruptFileError("corrupt metadata: inconsistent tet and face counts")
        geo = GeometryDecoder(self.read_section(f"L{level}/geometry"), n_points=n)
        conn = ConnectivityDecoder(bcode, tcode, n_points=n, n_tets=m, n_boundary_faces=nf,
                                   n_referenced=lv["referenced_points"])
        faces, nbv = conn.boundary()
        if nbv != lv["boundary_vertices"]:
            raise CorruptFileError("corrupt boundary section: vertex count does not match the metadata")
        refs = conn.predictors
        pts, dens = geo.decode(refs[:nbv])
        yield TetBatch.of_vertices(0, pts, dens, faces)
        conn.start_tets()
        known = nbv
        while conn.tets_done < m:
            tets = conn.next_tets(batch_tets)
            nv = conn.vertices_known
            pts, dens = geo.decode(refs[known:nv])
            yield TetBatch.of_tets(known, tets, pts, dens)
            known = nv
        if known != lv["referenced_points"]:
            raise CorruptFileError("corrupt tet section: vertex count does not match the metadata")
        if known < n:
            pts, dens = geo.decode(np.full((n - known, 4), -1, np.int32))
            yield TetBatch.of_vertices(known, pts, dens)
        geo.finish()
        self.last_peak_border = conn.peak_border

    def decode_mesh(self, level: int = 0):
        """The whole mesh of ``level`` as a :class:`~gatun_py.mesh.TetMesh` (vertices in decode order)."""
        lv = self.level_meta(level)
        n = lv["points"]
        points = np.empty((n, 3), np.float32)
        density = np.empty(n, np.float32)
        tets = np.empty((lv["tets"], 4), np.int32)
        faces = None
        t = 0
        for b in self.iter_decode(level):
            k = len(b.points)
            points[b.first:b.first + k] = b.points
            density[b.first:b.first + k] = b.density
            tets[t:t + len(b.tets)] = b.tets
            t += len(b.tets)
            if faces is None:
                faces = b.boundary
        try:
            return TetMesh(points, density, tets, self.scalar_name)
        except Exception as e:  # a mesh that fails its own invariants can only come from damage
            raise CorruptFileError(f"corrupt file: decoded mesh is invalid ({e})") from None


def iter_decode(source, level: int = 0, **kw) -> Iterator[TetBatch]:
    """Stream a ``.tetc`` file's level as :class:`~gatun_py.mesh.TetBatch`es (see :meth:`TetcReader.iter_decode`)."""
    return TetcReader(source).iter_decode(level, **kw)


def decode_mesh(source, level: int = 0):
    """Decode a whole level of a ``.tetc`` file into a :class:`~gatun_py.mesh.TetMesh`."""
    return TetcReader(source).decode_mesh(level)
