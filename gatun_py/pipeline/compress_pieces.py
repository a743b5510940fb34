"""Compress a partitioned mesh piece by piece into one bricked ``.tetc`` file, in bounded memory.

A partitioned mesh (``.pvtu``, an Exodus decomposition, several files: :mod:`gatun_py.mesh.pieces`)
is never held whole. Two passes over the pieces:

1. every piece is read and reduced to its boundary (vertices with their bits, faces) and its
   summary (counts, bounds, value ranges); the interface table joins these: the points repeated
   at the interfaces get one id each and the whole mesh's metadata (boundary faces, render step,
   ranges) follows without the whole mesh;
2. every piece is read again and becomes one brick, or several when it is larger than the memory
   limit allows (a k-d split of the piece), coded exactly as :func:`~gatun_py.pipeline.bricks.compress_bricks`
   codes a brick: decimated with its shared vertices locked (so every level of every brick meets
   its neighbours), its levels encoded, its cut lists written.

A process holds one piece at a time (its decimation: a few hundred bytes per tet) plus the
boundaries of all pieces. Finished bricks are written to a spool file beside the output as they
arrive, in brick order, and the file is assembled from it at the end (the metadata, which indexes
every section, comes first in a ``.tetc`` file): the bricks are never all in memory either.

The pieces are compressed in this process, on a process pool (``jobs``), or as Dask tasks
(``workers`` or ``scheduler``: the workers read their own pieces, so the paths must be readable
there). Each brick depends only on its piece and the table, so the file is the same bytes however
it was made; Dask reruns the tasks of a worker that dies.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import re
import shutil
import tempfile
import zlib
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from .._atomic import atomic_path
from ..codec.bricks import _keys, brick_jobs, encode_brick, encode_cut, map_bricks, read_cut, stitch_bricks
from ..codec.brickindex import BRICKS_KEY, brick_prefix
from ..codec.container import container_head, record_head
from ..codec.tetcfile import FORMAT_NAME, dtype_name
from ..codec.threads import check_jobs
from ..errors import CorruptFileError, MeshError, OptionError, OutputError, TetcError
from ..mesh import TetMesh
from ..mesh.partition import MAX_BRICKS, partition_tets, split_bricks
from ..mesh.pieces import boundary_part, interface_table, piece_file, piece_paths, pvtu_scalar, read_piece
from .bricks import _brick_payload, _with_loose_points
from .distributed import ClusterError, _distributed, _numba_cache_dir
from .requests import ForestOptions, ReadOptions, split_options

__all__ = ["PIECES_KEY", "compress_pieces", "parse_memory", "piece_bricks", "piece_mesh"]

PIECES_KEY = "pieces"  # metadata: per piece its source name and its first brick and brick count
# Peak bytes per tet of compressing one brick with its forest and levels (decimation, levels,
# encoding), and of its mesh alone: what --memory divides by to size the bricks.
BYTES_PER_TET = 400
BYTES_PER_TET_MESH_ONLY = 150
MIN_BRICK_TETS = 1000  # a memory limit never cuts bricks smaller (their cut points would dominate)


def parse_memory(text) -> int:
    """Bytes of a size such as ``8G``, ``500M``, ``2.5GB`` or a plain number of bytes, at least 64M.

    Examples
    --------
    >>> parse_memory("8G"), parse_memory("500M"), parse_memory(1 << 30)
    (8589934592, 524288000, 1073741824)
    >>> parse_memory(1024)
    Traceback (most recent call last):
    ...
    gatun_py.errors.OptionError: memory limit 1024: at least 64M
    """
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool):
        value = int(text)
    else:
        m = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*([kKmMgGtT]?)[iI]?[bB]?\s*", str(text))
        if m is None:
            raise OptionError(f"memory limit {text!r}: give a size such as 8G, 500M or 2.5GB")
        value = int(float(m.group(1)) * 1024 ** " KMGT".index(m.group(2).upper() or " "))
    if value < 64 << 20:
        raise OptionError(f"memory limit {text!r}: at least 64M")
    return value


# -- pass 1: the summary of a piece ------------------------------------------------------------------

@dataclass
class PieceSummary:
    """Pass 1's result for one piece (plain data: it travels back from a worker)."""

    name: str
    n_points: int
    n_tets: int
    units: list  # per brick of the piece: (points, tets)
    points_dtype: str
    scalar: str
    arrays: list  # (name, dtype name, components)
    lo: np.ndarray
    hi: np.ndarray
    ranges: list  # per array: [range or None, component ranges or None]
    scalar_range: tuple
    parts: list  # BoundaryPart per brick
    notes: list


def _finite(values) -> tuple | None:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return (float(v.min()), float(v.max())) if v.size else None


def _units(mesh: TetMesh, unit_tets: int | None) -> list[TetMesh]:
    """The bricks a piece is coded as: itself, or a k-d split of it into bricks of at most
    ``unit_tets`` tets (the vertices no tet uses go with the first)."""
    k = 1 if not unit_tets else min(max(1, math.ceil(mesh.n_tets / unit_tets)), mesh.n_tets, MAX_BRICKS)
    if k <= 1:
        return [mesh]
    bricks = split_bricks(mesh, partition_tets(mesh, k))
    bricks[0] = _with_loose_points(bricks[0], mesh)
    return [b.mesh for b in bricks]


def _read(path, read_options: dict, drop_cell_data: bool) -> tuple[TetMesh, list]:
    mesh, report = read_piece(path, read_options)
    notes = list(report.notes)
    if report.cell_arrays:
        names = ", ".join(map(repr, report.cell_arrays))
        if not drop_cell_data:
            raise OptionError(f"{path}: the piece has cell data ({names}), which a .tetc file does not store: "
                              "average it to the points (cell-to-point) or drop it explicitly (drop-cell-data)")
        notes.append(f"cell data dropped on request: {names}")
    return mesh, notes


def summarise_piece(path, read_options: dict, unit_tets: int | None, drop_cell_data: bool = False) -> PieceSummary:
    """Pass 1 for one piece: read it, cut it into its bricks, keep their boundaries and its summary."""
    mesh, notes = _read(path, read_options, drop_cell_data)
    ranges = []
    for name, _, k in mesh.arrays:
        a = mesh.point_data[name]
        if k == 1:
            ranges.append([_finite(a), None])
        else:
            ranges.append([_finite(mesh.scalar(name, "magnitude")), [_finite(a[:, c]) for c in range(k)]])
    lo, hi = mesh.bbox
    names = list(mesh.point_data)
    units = _units(mesh, unit_tets)
    return PieceSummary(Path(path).name, mesh.n_points, mesh.n_tets, [(u.n_points, u.n_tets) for u in units],
                        dtype_name(mesh.points.dtype), str(mesh.scalar_name),
                        [(n, dtype_name(dt), k) for n, dt, k in mesh.arrays], np.array(lo), np.array(hi), ranges,
                        mesh.scalar_range, [boundary_part(u, names) for u in units], notes)


# -- pass 2: the bricks of a piece -------------------------------------------------------------------

def encode_piece(path, read_options: dict, unit_tets: int | None, drop_cell_data: bool, expect: list,
                 shared: list, n_shared: int, first_brick: int, options: dict, threads: int = 0) -> list:
    """Pass 2 for one piece: its bricks, each as ``(records, index rows, brick entry)``: the
    container records of its sections (named ``B{k}/...``), their ``(name, head length, payload
    length, crc32)``, and its entry in the brick index."""
    if threads:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    mesh, _ = _read(path, read_options, drop_cell_data)
    units = _units(mesh, unit_tets)
    del mesh
    if [(u.n_points, u.n_tets) for u in units] != [tuple(x) for x in expect]:
        raise TetcError(f"{path} changed while it was being compressed (other counts than in the first pass)")
    out = []
    for j, (unit, (verts, ids)) in enumerate(zip(units, shared)):
        cut = np.full(unit.n_points, -1, np.int64)
        cut[verts] = ids
        enc = encode_brick(_brick_payload(unit, cut, options))
        units[j] = None
        sections = list(enc.sections.items())
        sections += [(f"L{lv['level']}/cut", encode_cut(cd, n_shared, 0, ids=False))
                     for lv, cd in zip(enc.entry["levels"], enc.cut_decode)]
        prefix = brick_prefix(first_brick + j)
        recs, rows = [], []
        for name, data in sections:
            head = record_head(prefix + name, data)
            recs += [head, bytes(data)]
            rows.append((prefix + name, len(head), len(data), zlib.crc32(data)))
        out.append((b"".join(recs), rows, enc.entry))
    return out


# -- the file ----------------------------------------------------------------------------------------

def whole_meta(summaries: list[PieceSummary], table, source: str) -> dict:
    """The metadata of the whole mesh (what :func:`~gatun_py.codec.tetcfile.file_meta` gives for
    it, before the brick index) from the pieces' summaries and the interface table."""
    first = summaries[0]
    check_alike(summaries)
    lo = np.min(np.stack([s.lo for s in summaries]), axis=0)
    hi = np.max(np.stack([s.hi for s in summaries]), axis=0)
    arrays = []
    for j, (name, dt, k) in enumerate(first.arrays):
        e = {"name": name, "dtype": dt, "components": k}
        e["range"] = _join([s.ranges[j][0] for s in summaries])
        if k > 1:
            e["component_ranges"] = [_join([s.ranges[j][1][c] for s in summaries]) for c in range(k)]
        arrays.append(e)
    n_points = sum(u[0] for s in summaries for u in s.units) - table.occurrences + table.n_shared
    srange = [float(np.min([s.scalar_range[0] for s in summaries])),
              float(np.max([s.scalar_range[1] for s in summaries]))]
    return {"format": FORMAT_NAME, "points": int(n_points), "tets": int(sum(s.n_tets for s in summaries)),
            "boundary_faces": int(table.boundary_faces), "bbox": [lo.tolist(), hi.tolist()], "scalar": first.scalar,
            "points_dtype": first.points_dtype, "arrays": arrays, "scalar_range": srange,
            "source": os.path.basename(str(source)), "render_step": float(table.render_step)}


def check_alike(summaries: list[PieceSummary]) -> None:
    """Every piece has the first one's coordinate type, point arrays and default scalar."""
    first = summaries[0]
    for s in summaries[1:]:
        if s.arrays != first.arrays or s.points_dtype != first.points_dtype or s.scalar != first.scalar:
            what = ("coordinates" if s.points_dtype != first.points_dtype else "point arrays"
                    if s.arrays != first.arrays else "default scalar")
            raise MeshError(f"piece {s.name} has other {what} than piece {first.name}: "
                            f"{_describe(s)} against {_describe(first)}")


def _describe(s: PieceSummary) -> str:
    return f"{s.points_dtype} points, arrays " + (", ".join(f"{n} ({d}x{k})" for n, d, k in s.arrays) or "none")


def _join(ranges) -> list:
    have = [r for r in ranges if r is not None]
    return [min(r[0] for r in have), max(r[1] for r in have)] if have else [0.0, 0.0]


class _Spool:
    """Finished bricks written in brick order to a temporary file beside the output (results that
    arrive early wait in memory for the ones before them)."""

    def __init__(self, output: Path):
        fd, self.path = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".bricks", dir=output.parent or ".")
        self.f = os.fdopen(fd, "wb")
        self.rows, self.entries, self.waiting, self.next = [], [], {}, 0

    def add(self, piece: int, bricks: list) -> None:
        self.waiting[piece] = bricks
        while self.next in self.waiting:
            for recs, rows, entry in self.waiting.pop(self.next):
                self.f.write(recs)
                self.rows += rows
                self.entries.append(entry)
            self.next += 1

    def finish(self, meta: dict, target: Path) -> None:
        self.f.close()
        meta = dict(meta)
        meta[BRICKS_KEY] = self.entries
        with open(target, "wb") as out, open(self.path, "rb") as spool:
            out.write(container_head(meta, self.rows))
            shutil.copyfileobj(spool, out, 16 << 20)

    def close(self) -> None:
        if not self.f.closed:
            self.f.close()
        try:
            os.unlink(self.path)
        except OSError:
            pass


# -- the verb ------------------------------------------------------------------------------------------

def piece_bricks(meta: dict, piece: int) -> range:
    """The bricks of piece ``piece`` of a file written from pieces."""
    pieces = meta.get(PIECES_KEY)
    if not isinstance(pieces, list) or not pieces:
        raise OptionError("this file was not compressed from pieces (it has no piece list)")
    if not 0 <= piece < len(pieces):
        raise OptionError(f"piece {piece} does not exist: the file has pieces 0..{len(pieces) - 1}")
    e = pieces[piece]
    first, n = e.get("first_brick"), e.get("bricks")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (first, n)) or n < 1:
        raise CorruptFileError(f"corrupt piece list: piece {piece}")
    return range(first, first + n)


def compress_pieces(inputs, output, *, forest: ForestOptions | None = None, read: ReadOptions | None = None,
                    memory=None, jobs: int | None = 1, workers: int | None = None, scheduler: str | None = None,
                    drop_cell_data: bool = False, force: bool = False, timeout: float = 10.0,
                    progress=None, log=None, **options) -> dict:
    """Compress the pieces of a partitioned mesh into one bricked ``.tetc`` file.

    Parameters
    ----------
    inputs : path-like or list of path-like
        A ``.pvtu`` file, one file of an Exodus decomposition (``name.e.N.i``), a VTKHDF file of
        several partitions (those of ``read_options``' ``time_step``, default the last), or several mesh
        files, each one piece (:func:`~gatun_py.mesh.pieces.piece_paths`); with ``memory``, also
        one plain mesh file, split into bricks before any forest is built.
    output : path-like
        The ``.tetc`` file, written atomically.
    memory : int or str, optional
        A process's memory for one brick (``"4G"``): larger pieces are split into several bricks.
    jobs : int
        Processes compressing pieces side by side on this machine (each holds one piece).
    workers, scheduler
        Compress on a local Dask cluster of ``workers`` processes, or on a running one.
    forest, read, drop_cell_data, force, options
        As for :func:`gatun_py.compress` (``options``: the records' fields by name).

    Returns
    -------
    dict
        ``pieces``, ``bricks``, ``points``, ``tets``, ``shared_points``, ``bytes``.
    """
    log = log or (lambda _m: None)
    forest, read = split_options("compress_pieces", options, forest=forest, read=read)
    mesh_only, levels = forest.mesh_only, forest.levels
    paths = piece_paths(inputs, single=memory is not None, step=read.time_step)
    output = Path(output)
    if any(os.path.exists(output) and os.path.samefile(piece_file(p), output) for p in paths):
        raise OptionError(f"the output {output} is one of the pieces")
    if workers is not None and scheduler is not None:
        raise OptionError("give either a number of local workers or a scheduler address, not both")
    jobs = min(check_jobs(jobs), len(paths))
    unit_tets = None
    if memory is not None:
        per_tet = BYTES_PER_TET_MESH_ONLY if mesh_only else BYTES_PER_TET
        unit_tets = max(MIN_BRICK_TETS, parse_memory(memory) // per_tet)
    build = dict(mesh_only=bool(mesh_only), levels=levels, w_density=float(forest.w_density),
                   w_geometry=float(forest.w_geometry), w_sample=float(forest.w_sample))
    ropts = read.kwargs()
    single = inputs[0] if isinstance(inputs, (list, tuple)) and len(inputs) == 1 else inputs
    if ropts.get("scalar") is None and isinstance(single, (str, os.PathLike)) and pvtu_scalar(single):
        ropts["scalar"] = pvtu_scalar(single)  # the solver's choice of default scalar
    with atomic_path(output, force=force) as tmp, _Runner(jobs, workers, scheduler, timeout, log) as run:
        summaries = run.map(summarise_piece, [(str(p), ropts, unit_tets, drop_cell_data) for p in paths])
        check_alike(summaries)
        for s in summaries:
            for note in s.notes:
                log(f"note: {s.name}: {note}")
        parts = [part for s in summaries for part in s.parts]
        names = [s.name if len(s.parts) == 1 else f"{s.name} (brick {j})"
                 for s in summaries for j in range(len(s.parts))]
        if len(parts) < 2:
            raise OptionError("one piece, which fits the memory limit in one brick: compress it as a plain file"
                              if memory is not None else "a partitioned mesh of one piece: compress the file itself")
        if len(parts) > MAX_BRICKS:
            raise OptionError(f"{len(parts)} bricks: at most {MAX_BRICKS} (a larger memory limit makes fewer)")
        table = interface_table(parts, names)
        meta = whole_meta(summaries, table, inputs[0] if isinstance(inputs, (list, tuple)) else inputs)
        firsts = np.concatenate([[0], np.cumsum([len(s.parts) for s in summaries])]).astype(int)
        meta["cut_points"] = table.n_shared
        meta[PIECES_KEY] = [{"source": s.name, "first_brick": int(firsts[i]), "bricks": len(s.parts)}
                            for i, s in enumerate(summaries)]
        log(f"{len(paths)} piece{'s' if len(paths) > 1 else ''}, {meta['tets']} tets in {len(parts)} bricks; {table.n_shared} points shared "
            "between them "
            f"({100.0 * table.n_shared / max(meta['points'], 1):.2f} % of the {meta['points']} points)")
        del parts
        for s in summaries:
            s.parts = None  # the table has what pass 2 needs
        spool = _Spool(output)
        try:
            args = [(str(p), ropts, unit_tets, drop_cell_data, s.units,
                     table.shared[firsts[i]:firsts[i + 1]], table.n_shared, int(firsts[i]), build)
                    for i, (p, s) in enumerate(zip(paths, summaries))]
            total, done = meta["tets"], 0
            for i, bricks in run.each(encode_piece, args, sizes=[s.n_tets for s in summaries]):
                spool.add(i, bricks)
                done += summaries[i].n_tets
                if progress is not None:
                    progress(done, total)
            try:
                spool.finish(meta, tmp)
            except OSError as e:
                raise OutputError(f"cannot write {output}: {e.strerror or e}") from None
        finally:
            spool.close()
    size = os.path.getsize(output)
    log(f"wrote {output}: {size} bytes ({8.0 * size / max(meta['tets'], 1):.2f} bits/tet overall)")
    return {"pieces": len(paths), "bricks": int(firsts[-1]), "points": meta["points"], "tets": meta["tets"],
            "shared_points": table.n_shared, "bytes": size}


# -- where the work runs ---------------------------------------------------------------------------------

class _Runner:
    """Runs the passes' tasks: in this process, on a pool of processes, or on Dask."""

    def __init__(self, jobs: int, workers, scheduler, timeout: float, log):
        self.jobs, self.client, self.cluster, self.pool = jobs, None, None, None
        self.threads = 0
        if workers is not None or scheduler is not None:
            dd = _distributed()
            try:
                if scheduler is not None:
                    self.client = dd.Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
                else:
                    n = int(workers)
                    if n < 1:
                        raise OptionError(f"the number of workers must be >= 1, got {workers!r}")
                    env = {"NUMBA_NUM_THREADS": str(max(1, (os.cpu_count() or 1) // n))}
                    if _numba_cache_dir():
                        env["NUMBA_CACHE_DIR"] = _numba_cache_dir()
                    self.cluster = dd.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                   dashboard_address=None, host="127.0.0.1", env=env, silence_logs=40)
                    self.client = dd.Client(self.cluster, timeout=f"{timeout}s", set_as_default=False)
            except (OSError, TimeoutError) as e:
                self.close()
                raise ClusterError(f"cannot reach {scheduler or 'a local cluster'} within {timeout:g} s: {e}") from None
            log(f"compressing on {len(self.client.scheduler_info()['workers'])} Dask workers")
        elif jobs > 1:
            self.pool = ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"))
            self.threads = max(1, numba.config.NUMBA_NUM_THREADS // jobs)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)
            self.pool = None

    def map(self, fn, args: list) -> list:
        out = [None] * len(args)
        for i, r in self.each(fn, args):
            out[i] = r
        return out

    def each(self, fn, args: list, sizes=None):
        """``(i, fn(*args[i]))`` as each finishes (largest first when ``sizes`` are given)."""
        order = sorted(range(len(args)), key=lambda i: -sizes[i]) if sizes else list(range(len(args)))
        if self.client is not None:
            yield from self._dask(fn, args, order)
        elif self.pool is not None:
            extra = (self.threads,) if fn is encode_piece else ()
            futs = {self.pool.submit(fn, *args[i], *extra): i for i in order}
            for fut in as_completed(futs):
                try:
                    yield futs[fut], fut.result()
                except BrokenProcessPool:
                    raise TetcError(f"a worker process died on piece {futs[fut]} (out of memory?); fewer jobs or "
                                    "a smaller memory limit need less memory") from None
        else:
            for i in order:
                yield i, fn(*args[i])

    def _dask(self, fn, args, order):
        dd = _distributed()
        futs = [self.client.submit(fn, *args[i], pure=False, key=f"tetc-{fn.__name__}-{i}-{os.getpid()}-{id(self)}")
                for i in order]
        index = {f.key: i for f, i in zip(futs, order)}
        try:
            for fut in futs:  # in submission order (largest first); the spool writes them in piece order
                try:
                    result = fut.result()
                except (TetcError, dd.KilledWorker, OSError, TimeoutError):
                    raise
                except Exception as e:  # anything else a task raised: name the piece
                    raise ClusterError(f"piece {index[fut.key]} failed on the cluster: "
                                       f"{type(e).__name__}: {e}") from None
                yield index[fut.key], result
                fut.release()
        except dd.KilledWorker as e:
            raise ClusterError(f"compressing failed: workers kept dying ({e})") from None
        except (OSError, TimeoutError) as e:
            if isinstance(e, TetcError):
                raise
            raise ClusterError(f"compressing failed: lost the cluster ({e})") from None


def piece_mesh(reader, piece: int, *, level: int = 0, jobs: int | None = None) -> TetMesh:
    """Piece ``piece`` of a file compressed from pieces, at a stored level: its bricks decoded and
    stitched (their shared points once; vertices and tets in decode order, not the piece's own)."""

    ks = list(piece_bricks(reader.meta, int(piece)))
    if reader.n_bricks <= 1:
        raise OptionError("this file has no bricks")
    for k in ks:
        if level not in {lv.level for lv in reader.brick(k).levels}:
            raise OptionError(f"level {level} is not stored in brick {k} of piece {piece}")
    meshes = map_bricks(lambda i: reader.brick(ks[i]).decode_mesh(level, jobs=brick_jobs(jobs, len(ks))), len(ks), jobs)
    if len(ks) == 1:
        return meshes[0]
    cuts = [read_cut(reader, k, level) for k in ks]
    n = np.unique(np.concatenate([_keys(m.points[pos]) for m, (pos, _) in zip(meshes, cuts)])).size
    return stitch_bricks(meshes, cuts, int(n), jobs=jobs)
