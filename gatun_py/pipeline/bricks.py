"""Bricks end to end: compress a mesh as K bricks on a process pool, read a bricked file back whole.

Compression splits the tets into K bricks (:func:`gatun_py.mesh.partition.partition_tets`), then
decimates and encodes every brick on its own, with its cut vertices locked, so that any level or
ratio of one brick meets its neighbours exactly. The bricks are independent: a pool of ``jobs``
processes (spawned, so a parent's numba threads are never forked) works through them, largest
first, and the file is assembled in brick order, so it is the same bytes whatever ``jobs`` is.

Reading (``gatun_py.open(...).mesh()``, ``tetc decompress``) decodes the bricks on threads (the
decode kernels release the GIL) and stitches them (:mod:`gatun_py.codec.bricks`).
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

import numba
import numpy as np

from .._compile_notice import worker_init, worker_initargs
from ..codec import LevelPayload, TetcReader
from ..codec.bricks import (BrickLevels, brick_jobs, check_jobs, decode_bricked, distinct_points, encode_brick,
                            encode_bricked, map_bricks, read_cut, stitch_bricks)
from ..errors import CorruptFileError, OptionError, TetcError
from ..mesh import TetMesh
from ..mesh.partition import Brick, partition_tets, split_bricks
from ..simplify import build_levels, decimate, level_payloads
from ..simplify.forest import mesh_from_ancestors
from ..simplify.levels import read_simplified, resolve_target, target_ancestors

__all__ = ["compress_bricks", "read_bricked"]


def _brick_payload(mesh: TetMesh, cut_ids: np.ndarray, options: dict) -> BrickLevels:
    """The levels of one brick: its mesh alone, or its forest (cut vertices locked) and levels."""
    if options["mesh_only"]:
        return BrickLevels([LevelPayload(0, 0.0, 0, mesh)], [cut_ids])
    forest = decimate(mesh, w_density=options["w_density"], w_geometry=options["w_geometry"],
                      w_sample=options["w_sample"], locked=cut_ids >= 0)
    lv = build_levels(mesh, forest, options["levels"])
    payloads = level_payloads(lv)
    return BrickLevels(payloads, [cut_ids[x.vertex_ids] for x in lv])


def _with_loose_points(brick: Brick, mesh: TetMesh) -> Brick:
    """``brick`` plus the vertices no tet uses (no brick of the partition holds them), so that the
    file keeps every input vertex."""
    used = np.zeros(mesh.n_points, bool)
    used[mesh.tets.ravel()] = True
    loose = np.flatnonzero(~used)
    if loose.size == 0:
        return brick
    m = brick.mesh
    ids = np.concatenate([brick.vertex_ids, loose])
    sub = TetMesh(mesh.points[ids], None, m.tets, mesh.scalar_name,
                  point_data={name: a[ids] for name, a in mesh.point_data.items()})
    return Brick(brick.index, sub, ids, brick.tet_ids, np.concatenate([brick.cut, np.zeros(loose.size, bool)]))


def _brick_job(mesh: TetMesh, cut_ids: np.ndarray, options: dict, threads: int):
    """One brick, in a worker process: decimate, build the levels, encode (plain data back)."""
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    return encode_brick(_brick_payload(mesh, cut_ids, options))


def compress_bricks(mesh: TetMesh, n_bricks: int, *, jobs: int | None = None, mesh_only: bool = False,
                    levels=None, w_density: float = 1.0, w_geometry: float = 1.0, w_sample: float = 1.0,
                    source: str = "", cut_ids: bool | None = None, progress=None, log=None) -> bytes:
    """The bytes of a bricked ``.tetc`` file of ``mesh`` split into ``n_bricks`` (>= 2) bricks.

    Parameters
    ----------
    jobs : int, optional
        Worker processes (default: all cores); 1 works in this process.
    cut_ids : bool, optional
        Store the file-wide ids of the shared vertices (default: only when two of them have the
        same coordinates; otherwise the coordinates match them up).
    progress : callable, optional
        ``progress(done, total)`` in vertices of finished bricks.
    log : callable, optional
        One line about the split.
    """
    jobs = check_jobs(jobs)
    bricks = split_bricks(mesh, partition_tets(mesh, n_bricks))
    if len(bricks) < 2:
        raise OptionError(f"a mesh of {mesh.n_tets} tets cannot be split into bricks")
    bricks[0] = _with_loose_points(bricks[0], mesh)
    # file-wide id of every cut vertex: its rank among the cut vertices' input ids
    is_cut = np.zeros(mesh.n_points, bool)
    for b in bricks:
        is_cut[b.vertex_ids[b.cut]] = True
    cut_index = np.full(mesh.n_points, -1, np.int64)
    n_cut = int(is_cut.sum())
    cut_index[is_cut] = np.arange(n_cut)
    if log is not None:
        log(f"{len(bricks)} bricks of {min(b.mesh.n_tets for b in bricks)}..{max(b.mesh.n_tets for b in bricks)} "
            f"tets; {n_cut} cut vertices ({100.0 * n_cut / max(mesh.n_points, 1):.2f} % of the points)")
    options = dict(mesh_only=mesh_only, levels=levels, w_density=float(w_density), w_geometry=float(w_geometry),
                   w_sample=float(w_sample))
    total = sum(b.mesh.n_points for b in bricks)
    done = 0
    encoded = [None] * len(bricks)
    jobs = min(jobs, len(bricks))
    if jobs == 1:
        for b in bricks:
            encoded[b.index] = encode_brick(_brick_payload(b.mesh, cut_index[b.vertex_ids], options))
            done += b.mesh.n_points
            if progress is not None:
                progress(done, total)
    else:
        threads = max(1, numba.config.NUMBA_NUM_THREADS // jobs)
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"), initializer=worker_init,
                                 initargs=worker_initargs()) as pool:
            order = sorted(bricks, key=lambda b: -b.mesh.n_tets)  # largest first: the pool drains evenly
            futures = {pool.submit(_brick_job, b.mesh, cut_index[b.vertex_ids], options, threads):
                       (b.index, b.mesh.n_points) for b in order}
            del order, bricks, b  # the workers have their own copies
            for fut in as_completed(futures):
                k, n = futures[fut]
                try:
                    encoded[k] = fut.result()
                except BrokenProcessPool:
                    raise TetcError(f"a worker process died while compressing brick {k} (out of memory?); "
                                    "fewer jobs need less memory") from None
                done += n
                if progress is not None:
                    progress(done, total)
    # shared vertices are matched by their coordinates when these tell them apart (no ids stored)
    if cut_ids is None:
        cut_ids = not distinct_points(mesh.points[is_cut])
    return encode_bricked(mesh, encoded, n_cut, source=source, cut_ids=cut_ids)


def read_bricked(reader: TetcReader, *, ratio: float | None = None, level: int | None = None,
                 jobs: int | None = None, progress=None) -> TetMesh:
    """The whole mesh of a bricked file (any file: one brick is the plain read) at a stored level
    or a ratio, every brick decoded (and simplified) on its own thread, then stitched.

    A ratio R simplifies every brick to R of its own points (cut vertices never merge, so the
    bricks still meet).
    """
    if reader.n_bricks == 1:
        return read_simplified(reader, ratio=ratio, level=level, jobs=jobs)
    if ratio is None:
        return decode_bricked(reader, 0 if level is None else int(level), jobs=jobs, progress=progress)

    def one(k):
        b = reader.brick(k)
        target = resolve_target(b, ratio=ratio, level=level)
        mesh = b.decode_mesh(target.level, jobs=brick_jobs(jobs, reader.n_bricks))
        pos, ids = read_cut(reader, k, target.level)
        anc = target_ancestors(b, target)
        if anc is None:
            return mesh, (pos, ids)
        if (anc[pos] != pos).any():
            raise CorruptFileError(f"corrupt file: brick {k}'s forest merges away one of its cut vertices")
        mesh, kept = mesh_from_ancestors(mesh, anc)
        return mesh, (np.searchsorted(kept, pos), ids)

    parts = map_bricks(one, reader.n_bricks, jobs, progress)
    return stitch_bricks([p[0] for p in parts], [p[1] for p in parts], int(reader.meta["cut_points"]))



