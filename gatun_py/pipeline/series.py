"""Compressing a time series into one ``.tetc`` file, and appending steps to one.

Step 0 is compressed as a snapshot (its forest and levels built on its default scalar); every
later step stores only its point arrays and, when they move, its coordinates, each coded against
its keyframe (:mod:`gatun_py.codec.steps`). Coarse levels store a map to level 0's vertices, so a
step at any ratio gathers its values from level 0.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from .._atomic import check_output_path, write_bytes_atomic
from ..codec import LevelPayload
from ..codec.container import build_container, split_container
from ..codec.cutborder import encode_connectivity
from ..codec.stepreader import (CellCoding, CellStepEncoder, StepDecoder, encode_level_map, encode_steps,
                                step_index, tet_decode_order)
from ..codec.steps import (append_block, keyframe_interval_for, check_step_mesh, check_times, mesh_digest,
                           points_digest)
from ..codec.arrays import dtype_name
from ..codec.tetcfile import _POINTS, TetcReader, encode_level, encode_tetc, find_copies
from ..errors import MeshError, OptionError
from ..simplify import build_levels, decimate, level_payloads

__all__ = ["encode_series", "write_series", "append_step"]


def _level0_order(mesh):
    """(vertex order, refs) of level 0's connectivity: what every step is coded in."""
    conn = encode_connectivity(mesh.n_points, mesh.tets)
    return conn.vertex_order, np.ascontiguousarray(conn.predictors, np.int32)


def encode_series(meshes, times, *, levels: int | None = None, mesh_only: bool = False, source: str = "",
                  keyframe_interval: int | None = None, w_density: float = 1.0,
                  w_geometry: float = 1.0, w_sample: float = 1.0, threads: int = 1, cell_data=None,
                  log=None) -> bytes:
    """A whole series file: step 0 as a snapshot with its levels, then every other step.

    Parameters
    ----------
    meshes : sequence of TetMesh
        The steps (``len(meshes) == len(times)``); meshes may also be loaded lazily by a sequence
        whose items are read on access (each is read once, in order).
    times : sequence of float
        Strictly increasing.
    keyframe_interval : int, optional
        Steps ``k`` with ``k % K == 0`` are coded alone, the others from the steps before them back
        to their keyframe. Default: :func:`~gatun_py.codec.steps.keyframe_interval_for` (any step
        decodes in about 1.5x the time of step 0).
    cell_data : callable, optional
        ``cell_data(k)``: step ``k``'s cell arrays, ``{name: (m,) or (m, c) array}`` with one row
        per tet in the mesh's tet order (called once per step, right after ``meshes[k]``); every
        step the same names, dtypes and components. Stored per step, lossless, predicted from
        the previous steps in the tets' decode order (``S{k}/cell/{j}``).
    """
    log = log or (lambda _m: None)
    times = check_times(times)
    if len(meshes) != len(times):
        raise OptionError(f"{len(meshes)} steps but {len(times)} times")
    if keyframe_interval is not None and (isinstance(keyframe_interval, bool) or keyframe_interval < 1
                                          or not isinstance(keyframe_interval, (int, np.integer))):
        raise OptionError(f"keyframe interval must be a whole number >= 1, got {keyframe_interval!r}")
    mesh0 = meshes[0]
    if keyframe_interval is None:
        moves = len(meshes) > 1 and not np.array_equal(meshes[1].points, mesh0.points)
        per_step = sum(c for _, _, c in mesh0.arrays) + (3 if moves else 0)
        keyframe_interval = keyframe_interval_for(mesh0.n_points, mesh0.n_tets, per_step * mesh0.n_points)
    copies = find_copies(mesh0)
    if mesh_only:
        lvs = None
        payloads = [LevelPayload(0, 0.0, 0, mesh0, copies=copies)]
    else:
        forest = decimate(mesh0, w_density=w_density, w_geometry=w_geometry, w_sample=w_sample)
        lvs = build_levels(mesh0, forest, levels)
        payloads = [dataclasses.replace(p, copies=copies) for p in level_payloads(lvs)]
        log(f"merge forest on step 0: {forest.n_merges} merges; levels {', '.join(str(x.level) for x in lvs)}")
    chainable = len(payloads) > 1
    codes = {p.level: encode_level(dataclasses.replace(p, forest=None), chainable=chainable) for p in payloads}
    vo = codes[0].vertex_order
    data = encode_tetc(payloads, source=source, mesh_codes=codes, threads=threads, copies=copies)
    meta, sections = split_container(data)
    dec0_of = np.empty(mesh0.n_points, np.int64)
    dec0_of[vo] = np.arange(mesh0.n_points)
    maps = []
    if lvs is not None:
        for lv in lvs[1:]:
            ids = dec0_of[np.asarray(lv.vertex_ids)[codes[lv.level].vertex_order]]
            sections.append((f"L{lv.level}/vmap", encode_level_map(ids)))
            maps.append(int(lv.level))
    conn0 = _level0_conn(mesh0, vo)
    refs = np.ascontiguousarray(conn0.predictors, np.int32)
    base_points = np.ascontiguousarray(mesh0.points[vo])
    cells = None
    first_cells = cell_data(0) if cell_data is not None else {}
    if first_cells:
        cells = CellStepEncoder(CellCoding(conn0.tets, _pos4(base_points)), tet_decode_order(mesh0.tets, vo, conn0.tets),
                                interval=int(keyframe_interval))
        sections.extend(cells.step(0, first_cells))
    step0 = {name: np.ascontiguousarray(a[vo]) for name, a in mesh0.point_data.items()}
    step0[_POINTS] = base_points
    entries = [{"ref": -1, "order": 0, "points": False}]

    def later():
        for k in range(1, len(times)):
            m = meshes[k]
            check_step_mesh(mesh0, m, k)
            yield m

    for k, (entry, secs) in enumerate(encode_steps(later(), vo, refs, base_points, first=1,
                                                   interval=int(keyframe_interval),
                                                   previous=lambda k: step0 if k == 0 else None), 1):
        entries.append(entry)
        sections.extend(secs)
        if cells is not None:
            sections.extend(cells.step(k, cell_data(k)))
        elif cell_data is not None and cell_data(k):
            raise MeshError(f"step {k} has cell arrays ({', '.join(map(repr, cell_data(k)))}), step 0 none")
    meta["steps"] = {"times": times, "entries": entries, "keyframe_interval": int(keyframe_interval),
                     "mesh": mesh_digest(mesh0.n_points, mesh0.tets), "points": points_digest(mesh0.points),
                     "maps": maps}
    if cells is not None:
        meta["steps"]["cells"] = [{"name": n, "dtype": d, "components": c} for n, d, c in cells.arrays]
    return build_container(meta, sections)


def _pos4(points) -> np.ndarray:
    p = np.zeros((len(points), 4), np.float32)
    p[:, :3] = np.asarray(points).astype(np.float32)
    return p


def _level0_conn(mesh0, vo):
    conn = encode_connectivity(mesh0.n_points, mesh0.tets)
    if not np.array_equal(conn.vertex_order, vo):  # deterministic: the same tets, the same order
        raise RuntimeError("the connectivity coder gave two vertex orders for one mesh")
    return conn


def write_series(path, meshes, times, *, force: bool = False, **kw) -> int:
    """:func:`encode_series` into ``path`` atomically; returns the bytes written."""
    check_output_path(path, force=force)
    data = encode_series(meshes, times, **kw)
    write_bytes_atomic(path, data, force=force)
    return len(data)


# -- appending ---------------------------------------------------------------------------------------

_CRASH_HOOK = None  # tests: called with the bytes written so far of an append, may raise to simulate a kill


def append_step(path, mesh, time: float | None = None, *, cell_data: dict | None = None) -> int:
    """Append ``mesh`` as the next step of the series file ``path``; returns the new step's number.

    The earlier steps are not re-encoded: the step's sections are coded against its keyframe and
    written after the last whole step (an interrupted append before it is cut off first). The
    mesh must have step 0's points and tets. ``time``: default the last time + 1. ``cell_data``:
    the step's cell arrays (one row per tet), when the file stores cell arrays per step.
    """
    path = os.fspath(path)
    reader = TetcReader(path)
    c = reader.container
    idx = step_index(c)
    if not idx.series:
        raise OptionError(f"{path} is a snapshot, not a series: compress the steps together "
                          "(tetc compress a.vtu b.vtu ... -o run.tetc) to append to it later")
    k = idx.n_steps
    t = idx.times[-1] + 1.0 if time is None else check_times([time])[0]
    if not t > idx.times[-1]:
        raise OptionError(f"times go backwards: the new step's time {t!r} is not after the last step's "
                          f"{idx.times[-1]!r}")
    if mesh_digest(mesh.n_points, mesh.tets) != idx.mesh_digest:
        raise MeshError(f"step {k}: the mesh differs from step 0's ({mesh.n_points} points, {mesh.n_tets} tets; "
                        f"the file's: {reader.meta['points']} and {reader.meta['tets']}, or other tets): "
                        "a series keeps one topology")
    arrays = [(n, dt.name, c_) for n, dt, c_ in reader.arrays]
    mine = [(n, dtype_name(d), c_) for n, d, c_ in mesh.arrays]
    if mine != arrays:
        raise MeshError(f"step {k}: point arrays {mine} differ from the file's {arrays}")
    if mesh.points.dtype != reader.points_dtype:
        raise MeshError(f"step {k}: coordinates are {mesh.points.dtype}, the file's {reader.points_dtype}")
    steps = StepDecoder(reader)
    vo, refs = _level0_order(mesh)
    if points_digest(mesh.points) == idx.points_digest:
        base_points = np.ascontiguousarray(mesh.points[vo])  # the same bits as step 0's
    else:
        base_points = steps.base_points()
    cell_data = dict(cell_data or {})
    if bool(cell_data) != bool(idx.cells):
        have = ", ".join(repr(n) for n, _, _ in idx.cells) or "none"
        raise MeshError(f"step {k}: cell arrays {', '.join(map(repr, cell_data)) or 'none'}; the file's steps have "
                        f"{have}")
    (entry, sections), = encode_steps([mesh], vo, refs, base_points, first=k, interval=idx.interval,
                                      previous=steps.values)
    if idx.cells:
        conn, pos0 = steps.kept_level0()
        enc = CellStepEncoder(CellCoding(conn.tets, pos0), tet_decode_order(mesh.tets, vo, conn.tets),
                              interval=idx.interval, arrays=[(n, dtype_name(d), c_) for n, d, c_ in idx.cells],
                              previous=steps.cell_values)
        sections = sections + enc.step(k, cell_data)
    block = append_block(k, t, entry, sections, idx.end)
    fd = os.open(path, os.O_RDWR)
    try:
        os.ftruncate(fd, idx.end)  # an interrupted append's bytes
        os.lseek(fd, idx.end, os.SEEK_SET)
        if _CRASH_HOOK is not None:
            _CRASH_HOOK(fd, block)
        view = memoryview(block)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)
    return k
