"""The public verbs: :func:`compress`, :func:`open`, :func:`render`, and what they return.

Each verb validates its arguments, then calls down the pipeline's stages. The command line
(``tetc compress``, ``tetc render``, ...) is a thin layer over these, so a script gets exactly what
the command does::

    import gatun_py
    gatun_py.compress("mesh.vtu", "mesh.tetc")
    f = gatun_py.open("mesh.tetc")
    frame = gatun_py.render(f, size=512, tf="bluntfin", azimuth=30, elevation=20, ratio=0.9)
    frame.save("mesh.png")
"""

from __future__ import annotations

import contextlib
import dataclasses
import glob
import importlib.util

import math
import os
import tempfile
import time
from time import perf_counter as _perf_counter  # render's own argument `time` hides the module
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import meshio
import numpy as np

from ._atomic import check_output_path, write_bytes_atomic
from ._runtime import peak_rss_mb
from .codec import LevelPayload, TetcReader, write_tetc
from .codec.bricks import check_jobs
from .codec.cells import read_cells, restore_order
from .codec.info import tetc_info
from .codec.stepreader import StepDecoder
from .codec.tetcfile import encode_level, find_copies, node_blocks
from ._compile_notice import announce as _announce_compiling
from ._compile_notice import watch as _watch_compiles
from .errors import OptionError, OutputError, ReadError
from .mesh import TetMesh, mesh_from_meshio, read_mesh, write_mesh
from .mesh.cells import Cells
from .mesh.exodus import exodus_times
from .mesh.io import mesh_output_format
from .mesh.series import is_series_source, read_series, tet_cell_data, tet_cells, vtkhdf_steps
from .mesh.pyvista_grid import to_pyvista
from .mesh.vtkhdf import is_vtkhdf, write_vtkhdf
from .pipeline.bricks import compress_bricks, read_bricked
from .pipeline.compress_pieces import compress_pieces, piece_mesh
from .mesh.pieces import is_partitioned
from .pipeline.sortlast import BrickRef, MeshExtent, render_bricks, split_for_render
from .pipeline.series import append_step, write_series
from .pipeline.budget import load_costs, plan_file_budget, remember_frame
from .pipeline.distributed import BrickCluster
from .pipeline.selective import SELECTION_ALLOWANCE_S, budget_tets, render_selective, selective_mesh
from .limits import PIPELINES
from .pipeline.requests import Detail, ForestOptions, Frame, ReadOptions, View, split_options
from .pipeline.requests import check_number as _check_number
from .pipeline.stream import View as _StreamView  # the fitted view the stages draw with
from .pipeline.stream import file_render_defaults, is_tetc, render_cell_array, render_mesh_file, render_tetc
from .raycast.image import add_colorbar, image_format, to_rgb8, upscale_rgb8, write_image
from .simplify import build_levels, decimate, level_payloads
from .simplify.dependencies import merge_dependencies
from .simplify.filter import SimplifyFilter
from .simplify.levels import MAX_LEVEL, max_stored_level, next_level, resolve_target, target_ancestors

__all__ = ["compress", "decompress", "convert", "info", "open", "render", "render_frames", "render_steps", "append", "TetcFile", "Frame",
           "View", "Detail", "ReadOptions", "ForestOptions"]

_watch_compiles()  # a verb (or method) whose first run compiles says so on stderr, once per process


# -- reading the source --------------------------------------------------------------------------

def _as_mesh(source, read: ReadOptions, log, *, storing: bool = False, drop_cell_data: bool = False) -> TetMesh:
    """A TetMesh from a path, a TetMesh or a meshio.Mesh (notes of the reader go to ``log``).

    ``storing``: the mesh is about to be compressed with its cells (:func:`_as_mesh_and_cells`),
    so ``drop_cell_data`` leaves its cell arrays out, with a note.
    """
    return _as_mesh_and_cells(source, read, log, storing=storing, drop_cell_data=drop_cell_data)[0]


def _as_mesh_and_cells(source, read: ReadOptions, log, *, storing: bool = False, drop_cell_data: bool = False):
    """(TetMesh, the cells as given or None) from a path, a TetMesh or a meshio.Mesh."""
    if isinstance(source, TetMesh):
        return source, None
    if type(source).__name__ == "Mesh" and hasattr(source, "cells") and hasattr(source, "points"):
        mesh, report = mesh_from_meshio(source, scalar=read.scalar, cell_to_point=read.cell_to_point,
                                        source="<meshio.Mesh>")
    elif isinstance(source, (str, os.PathLike)):
        mesh, report = read_mesh(source, **read.kwargs())
    else:
        raise OptionError(f"cannot read a mesh from a {type(source).__name__}: give a path, a TetMesh or a meshio.Mesh")
    for note in report.notes:
        log(f"note: {note}")
    cells = report.cells
    if storing and drop_cell_data and cells is not None and cells.cell_data:
        log(f"note: cell data dropped on request: {', '.join(map(repr, cells.cell_data))}")
        cells.cell_data = {}
    return mesh, cells


def _quiet(_msg: str) -> None:
    pass


def _names_cell_array(reader, name: str | None) -> bool:
    """Whether ``name`` is one of the file's cell arrays and none of its point arrays."""
    if name is None or name in {a[0] for a in reader.arrays}:
        return False
    cells = reader.meta.get("cells")
    return isinstance(cells, dict) and any(isinstance(e, dict) and e.get("name") == name
                                           for e in cells.get("cell_data") or [])


# -- compress ------------------------------------------------------------------------------------

def compress(source, output, *, forest: ForestOptions | None = None, read: ReadOptions | None = None,
             force: bool = False, drop_cell_data: bool = False, bricks: int = 1, jobs: int | None = None,
             keep_order: bool = False, progress=None, log=None, times=None, keyframe_interval: int | None = None,
             **options) -> "TetcFile":
    """Compress a mesh losslessly into a ``.tetc`` file, with its merge forest and levels.

    Parameters
    ----------
    source : path-like, TetMesh or meshio.Mesh
        Any meshio volume format or a PLOT3D grid (see :func:`gatun_py.read_mesh`).
    output : path-like
        The ``.tetc`` file, written atomically.
    forest : ForestOptions, optional
        How the merge forest and levels are built: ``levels``, ``mesh_only``, ``w_density``,
        ``w_geometry``, ``w_sample``, ``dependencies`` (see :class:`ForestOptions`).
    read : ReadOptions, optional
        How to read ``source`` (see :func:`gatun_py.read_mesh`). Every point array is stored, in its
        dtype; ``scalar`` is the default one (rendered and decimated).
    drop_cell_data : bool
        Leave the cell arrays out (an explicit opt-out: by default they are stored exactly, beside
        the cells as given).
    bricks : int
        Split the tets into this many bricks (k-d tree over the tet centroids, balanced by tet
        count), each coded on its own with its own forest and levels (its vertices shared with other
        bricks locked), so that they decode in parallel and render apart. 1: one plain stream.
    jobs : int, optional
        Processes that decimate and encode bricks; without bricks, threads that encode the levels
        (and level 0 beside the decimation). Default: all cores. The bytes do not depend on it.
    keep_order : bool
        Also store the original point order, cell order and every cell's vertex order (tets
        included), coded against the decoder's order: decompressing gives the input's numbering
        back exactly (``tetc info`` reports what it cost).
    progress : callable, optional
        ``progress(done, total)``: vertices the decimation has processed so far, of ``total``.
    log : callable, optional
        Called with one-line status messages (notes about the input, the forest, the sizes).
    times : sequence of float, optional
        A time series (``source`` a list of files, a ``.pvd``, an XDMF temporal collection, an
        Exodus or a VTKHDF file with several steps, or a :class:`~gatun_py.mesh.series.Series`): the steps'
        times (default: the source's own, else 0, 1, ...). Every step must have step 0's points and
        tets; the forest and levels are built on step 0 (see :mod:`gatun_py.codec.steps`).
    keyframe_interval : int, optional
        A series: steps coded alone every this many (default: chosen so that any step decodes in
        about 1.5x the time of step 0).
    force : bool
        Overwrite ``output`` if it exists.
    **options
        Shorthand: the fields of ``forest`` and ``read`` by name (``levels=3, scalar="rho"``).

    Returns
    -------
    TetcFile
        The written file, open.

    Examples
    --------
    >>> import gatun_py, tempfile, os
    >>> from gatun_py.warmup import tiny_mesh
    >>> out = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
    >>> f = gatun_py.compress(tiny_mesh(), out)
    >>> f.n_points, f.n_tets, f.mesh().n_tets
    (48, 90, 90)
    """
    log = log or _quiet
    forest, read = split_options("compress", options, forest=forest, read=read)
    levels, mesh_only, dependencies = forest.levels, forest.mesh_only, forest.dependencies
    w_density, w_geometry, w_sample = forest.w_density, forest.w_geometry, forest.w_sample
    scalar, cell_to_point, time_step = read.scalar, read.cell_to_point, read.time_step
    # a list of files is a time series (compress_pieces takes a list of pieces); a .pvtu, an
    # Exodus decomposition or a VTKHDF file of several partitions names its pieces
    if isinstance(source, (str, os.PathLike)) and is_partitioned(source, step=time_step):
        if bricks != 1 or dependencies:  # a partitioned mesh is bricked by its pieces
            raise OptionError("a partitioned mesh is compressed one brick per piece: no bricks or dependencies")
        compress_pieces(source, output, forest=forest, read=read, force=force, jobs=jobs,
                        drop_cell_data=drop_cell_data, progress=progress, log=log)
        return TetcFile(output)
    if times is not None or keyframe_interval is not None or is_series_source(source) \
            or (isinstance(source, (str, os.PathLike)) and time_step is None
                and ((Path(source).suffix.lower() in (".e", ".exo", ".ex2") and _exodus_steps(source) > 1)
                     or (is_vtkhdf(source) and vtkhdf_steps(source) > 1))):
        return _compress_series(source, output, times=times, levels=levels, mesh_only=mesh_only, force=force,
                                w_density=w_density, w_geometry=w_geometry, w_sample=w_sample, scalar=scalar,
                                cell_to_point=cell_to_point, drop_cell_data=drop_cell_data, bricks=bricks,
                                dependencies=dependencies, jobs=jobs, keyframe_interval=keyframe_interval, log=log)
    if isinstance(bricks, bool) or not isinstance(bricks, (int, np.integer)) or bricks < 1:
        raise OptionError(f"bricks must be a positive integer, got {bricks!r}")
    threads = check_jobs(jobs)
    _check_output(source, output, force=force)  # fail before the (long) work
    _announce_compiling(["encoder"] + ([] if mesh_only else ["decimation"]) + (["dependencies"] if dependencies else []))
    t0 = time.perf_counter()
    mesh, cells = _as_mesh_and_cells(source, read, log, storing=True, drop_cell_data=drop_cell_data)
    if keep_order:
        if bricks > 1:
            raise OptionError("keep_order needs one plain stream: not with bricks")
        if cells is None:  # a TetMesh: its tets are its cells

            cells = Cells([("tetra", np.asarray(mesh.tets, np.int64))], np.arange(mesh.n_tets, dtype=np.int64))
        cells.keep_order = True
    if cells is not None and cells.needed() and bricks > 1:
        log("note: a bricked file keeps the tets only: the cells as given are not stored (compress without "
            "bricks to keep them)")
        cells = None
    name = Path(source).name if isinstance(source, (str, os.PathLike)) else ""
    log(f"read {name or 'mesh'}: {mesh.n_points} points, {mesh.n_tets} tets")
    if dependencies and (mesh_only or bricks > 1):
        raise OptionError("merge dependencies need a merge forest of one plain stream: not with mesh_only or bricks")
    deps = None
    mesh_codes = {}
    copies = None  # find_copies(mesh), once it is known
    if bricks > 1 and mesh.n_tets == 0:
        log("note: a mesh without tets is stored as one brick")
    if bricks > 1 and mesh.n_tets > 0:
        data = compress_bricks(mesh, int(bricks), jobs=jobs, mesh_only=mesh_only, levels=levels,
                               w_density=w_density, w_geometry=w_geometry, w_sample=w_sample, source=name,
                               progress=progress, log=log)
        write_bytes_atomic(output, data, force=force)
        payload = None
    elif mesh_only:
        payload = mesh
    else:
        with ThreadPoolExecutor(1, thread_name_prefix="tetc-level") as pool:
            # With a second core the levels' meshes are encoded beside the decimation (whose merge
            # loop releases the GIL), each as soon as the merges before it are done; their forests
            # are added afterwards.
            beside = _LevelsBeside(mesh, pool, max_stored_level(mesh.n_points) if levels is None
                                   else min(int(levels), MAX_LEVEL), node_blocks(cells))
            forest = decimate(mesh, w_density=w_density, w_geometry=w_geometry, w_sample=w_sample,
                              progress=_counter(progress, mesh.n_points),
                              on_level=beside.submit if threads > 1 else None)
            if progress is not None:  # done: the last vertices of every component are never merged
                progress(mesh.n_points, mesh.n_points)
            lv = build_levels(mesh, forest, levels)
            mesh_codes, copies = beside.codes(lv), beside.copies
            log(f"merge forest: {forest.n_merges} merges (max ratio {forest.max_ratio:.5f}); "
                f"levels {', '.join(str(x.level) for x in lv)}")
            payload = level_payloads(lv)
            if dependencies:
                deps = merge_dependencies(mesh, forest)
                log(f"merge dependencies: {deps.idx.size} ({deps.idx.size / max(deps.n_merges, 1):.1f} per merge)")
                deps = (deps.ptr, deps.idx, deps.removed)
    n = (len(data) if payload is None else
         write_tetc(output, payload, source=name, force=force, dependencies=deps, mesh_codes=mesh_codes,
                    threads=threads, copies=copies, cells=cells))
    out = TetcFile(output)
    info = out.info
    log(f"wrote {output}: {n} bytes ({8.0 * n / max(mesh.n_tets, 1):.2f} bits/tet overall, "
        f"connectivity {info['bits_per_tet_connectivity']:.2f} bits/tet, "
        f"geometry {info['bits_per_vertex_geometry']:.1f} bits/vertex) in {time.perf_counter() - t0:.1f} s")
    return out


class _LevelsBeside:
    """Levels built and their meshes encoded in ``pool`` (one worker: in level order, each from
    the one before) while the decimation goes on: :meth:`submit` is its ``on_level``.

    Level 0's mesh does not depend on the forest, but it is encoded only once level 1's merges
    are done: before them the decimation's set-up and first evaluation of every vertex use both
    cores, and an encoder beside them made that phase half as long again (flange-10m, from the
    validated mesh to the first merge: 45-47 s with level 0 encoded beside, 29-30 s without, on a
    machine loaded by another job); the merge loop leaves the second core idle."""

    def __init__(self, mesh: TetMesh, pool: ThreadPoolExecutor, max_level: int, nodes: tuple = ()):
        self.mesh, self.pool, self.max_level, self.nodes = mesh, pool, max_level, nodes
        self.copies = find_copies(mesh)  # what encode_tetc will ask every level for
        self.prev = None  # the last level built (the worker's chain)
        self.jobs = {}

    def submit(self, i: int, prefix) -> None:
        if 0 not in self.jobs:
            self.jobs[0] = self.pool.submit(encode_level, LevelPayload(0, 0.0, 0, self.mesh, copies=self.copies,
                                                                       node_blocks=self.nodes))
        if i <= self.max_level:
            self.jobs[i] = self.pool.submit(self._encode, i, prefix)

    def _encode(self, i: int, prefix):
        lv = next_level(self.mesh, prefix, i, self.prev)
        self.prev = lv
        return lv.mesh, encode_level(LevelPayload(i, lv.ratio, lv.n_merges, lv.mesh, copies=self.copies))

    def codes(self, levels) -> dict:
        """{level: its encoded mesh} for the levels of ``levels`` coded beside the decimation. Each
        was built from a prefix of the forest and is checked against the level's mesh made from
        the whole forest (the same by construction: a level's mesh depends only on the set of
        merges before it); a level that differed would be coded again from ``levels``."""
        out = {0: self.jobs[0].result()} if 0 in self.jobs else {}
        for lv in levels[1:]:
            job = self.jobs.get(lv.level)
            if job is None:
                continue
            m, code = job.result()
            same = (_same_bits(m.tets, lv.mesh.tets) and _same_bits(m.points, lv.mesh.points)
                    and m.point_data.keys() == lv.mesh.point_data.keys()
                    and all(_same_bits(a, lv.mesh.point_data[k]) for k, a in m.point_data.items()))
            if same:
                out[lv.level] = code
        return out


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal dtype, shape and bytes (NaNs included)."""
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _counter(progress, total: int):
    """Adapt ``progress(done, total)`` to the stages' ``update(increment)`` callbacks."""
    if progress is None:
        return None
    done = [0]

    def update(n: int = 1) -> None:
        done[0] += int(n)
        progress(done[0], total)

    return update


def decompress(source, output, *, detail: Detail | None = None, view: View | None = None, force: bool = False,
               jobs: int | None = None, as_tets: bool = False, log=None, step: int | None = None,
               time: float | None = None, piece: int | None = None, **options) -> TetMesh:
    """Decode a ``.tetc`` file (optionally simplified) and write it in any meshio format.

    The full mesh of a file that stores its cells as given (hexahedra, wedges, quadratic cells,
    several blocks, cell arrays, sets) is written as those cells; ``as_tets`` writes the tets they
    were split into instead (as does any simplified mesh).

    A time series: ``step`` (index, negative from the end) or ``time`` picks the step written
    (default step 0); an output ending in ``.pvd`` or ``.xdmf`` without either gets every step.

    ``detail``: a :class:`Detail` with a ``ratio`` or ``level`` (default: the full mesh), or
    ``selective`` with a ``ratio`` or ``tets``: the mesh a selective render with ``view`` (a
    :class:`View`: size, camera, transfer function, scalar range) would draw, so it can be checked
    and used elsewhere. A file without merge dependencies gives the uniform mesh, with a note
    through ``log``. Their fields may be given as flat keywords (``ratio=0.5``, ``azimuth=30``).

    ``jobs``: threads decoding (default: all cores): the connectivity ahead of the geometry, the
    bricks of a bricked file in parallel (:meth:`TetcFile.mesh`). With ``piece`` (a file
    compressed from pieces), only that piece's bricks, at ``level``.

    Returns the mesh written.
    """
    log = log or _quiet
    detail, view = split_options("decompress", options, detail=detail, view=view)
    if detail.budget is not None:
        raise OptionError("decompress takes a ratio, a level or selective tets, not a budget")
    ratio, level, selective, tets = detail.ratio, detail.level, detail.selective, detail.tets
    if step is not None and time is not None:
        raise OptionError("give a step or a time, not both")
    kind = _series_output(output)
    if kind is not None and step is None and time is None:
        if selective:
            raise OptionError("selective refinement writes one step: give a step or a time")
        if isinstance(source, (str, os.PathLike)) and _same_file(source, output):
            raise OptionError(f"the output {output} is the input file")
        f = source if isinstance(source, TetcFile) else TetcFile(source)
        if kind == "xdmf" or f.n_steps > 1:
            _write_steps(f, output, kind, ratio=ratio, level=level, jobs=jobs, force=force)
            log(f"wrote {f.n_steps} step{'s' if f.n_steps > 1 else ''} to {output}")
            return f.mesh(ratio, level=level, jobs=jobs, step=f.n_steps - 1)
    _check_output(source, output, force=force, mesh_file=True)  # before decoding
    f = source if isinstance(source, TetcFile) else TetcFile(source)
    _announce_compiling(["decoder"] + (["forest decoder"] if ratio is not None or selective else []))
    if step is not None or time is not None:
        k = f.step_index(step=step, time=time)
        if selective and k != 0:
            raise OptionError("selective refinement is for step 0 of a series (its merge dependencies)")
        if k != 0 or f.n_steps > 1:
            mesh = f.mesh(ratio, level=level, jobs=jobs, step=k)
            write_mesh(mesh, output, force=force, cells=f._step_cells(mesh, k, ratio=ratio, level=level, log=log))
            return mesh
    mesh = None
    if piece is not None:
        if selective or ratio is not None:
            raise OptionError("a piece is decoded at a stored level: not with a ratio or selective")
        mesh = piece_mesh(f.reader, piece, level=0 if level is None else int(level), jobs=jobs)
    if selective:
        sview = _StreamView(view.camera, view.tf, scalar_range=view.scalar_range)
        if ratio is None and tets is None:
            ratio = 0.5
        mesh, cut = selective_mesh(f.reader, sview, ratio=ratio, tets=tets)
        if mesh is None:
            log("note: this file stores no merge dependencies (it was compressed without them): decoding uniformly")
            ratio = ratio if tets is None else None
        else:
            log(f"selective cut: {cut.n_merges} merges, {cut.n_tets} tets, chosen in {cut.select_s:.3f} s")
    if mesh is None:
        mesh = f.mesh(ratio=ratio, level=level, jobs=jobs)
    n_steps = int(getattr(f, "n_steps", 1))
    if is_vtkhdf(output) and n_steps > 1 and not selective:
        _write_vtkhdf_series(f, mesh, output, ratio=ratio, level=level, jobs=jobs, force=force)
        return mesh
    cells = None
    if "cells" in f.reader.meta and not as_tets:
        if selective or ratio is not None or level not in (None, 0):
            log("note: the cells as given are those of the full mesh: writing the simplified mesh's tets")
        else:
            cells = read_cells(f.reader, mesh.tets, mesh.n_points, mesh.points)
            mesh, cells = restore_order(mesh, cells)
    write_mesh(mesh, output, force=force, cells=cells)
    return mesh


def _write_vtkhdf_series(f, mesh, output, *, ratio, level, jobs, force) -> None:
    """Every step of ``f`` into one temporal VTKHDF file: ``mesh`` (step 0's) once, each step's arrays
    (and its coordinates, where the mesh moves)."""
    steps = []
    for k, t in enumerate(f.times):
        m = mesh if k == 0 else f.mesh(ratio=ratio, level=level, jobs=jobs, step=k)
        if not _same_bits(m.tets, mesh.tets):  # a series keeps one topology: a decoder's bug otherwise
            raise OptionError(f"step {k} has other tets than step 0: write the steps one by one (--step)")
        steps.append((float(t), dict(m.user_point_data), {}, m.points))
    write_vtkhdf(output, mesh, steps=steps, force=force)


def convert(source, output, *, refine: int = 1, force: bool = False, scalar: str | None = None, q_file=None,
            q_var: str = "density", cell_to_point: bool = False, time_step: int | None = None, log=None) -> TetMesh:
    """Read any mesh (or PLOT3D grid), split it into tets and write it in any meshio format.

    ``refine`` (PLOT3D only) cuts every grid cell into refine³ cells on its trilinear map first
    (interpolated scalar: larger meshes for scale tests, not new data). Returns the mesh written.
    """
    log = log or _quiet
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or not 1 <= refine <= 16:
        raise OptionError(f"refine must be an integer in 1..16, got {refine!r}")
    _check_output(source, output, force=force, mesh_file=True)
    if isinstance(source, (str, os.PathLike)):
        mesh, report = read_mesh(source, refine=int(refine), scalar=scalar, q_file=q_file, q_var=q_var,
                                 cell_to_point=cell_to_point, time_step=time_step)
        for note in report.notes:
            log(f"note: {note}")
        if report.cell_arrays:
            log(f"note: cell data not written ({', '.join(map(repr, report.cell_arrays))}): only point data "
                "follows the split into tets; average it to the points with cell-to-point")
    else:
        mesh = _as_mesh(source, ReadOptions(scalar=scalar, cell_to_point=cell_to_point), log)
    write_mesh(mesh, output, force=force)
    return mesh


def info(source, *, scalar: str | None = None, q_file=None, q_var: str = "density",
         cell_to_point: bool = False, time_step: int | None = None) -> dict:
    """Describe a ``.tetc`` file (sizes, bits per tet, levels, forest) or any mesh file (sizes,
    boundary, degenerate tets, the reader's notes): what ``tetc info --json`` prints."""
    if isinstance(source, TetcFile) or (isinstance(source, (str, os.PathLike)) and is_tetc(source)):
        return (source if isinstance(source, TetcFile) else TetcFile(source)).info
    mesh, report = read_mesh(source, scalar=scalar, q_file=q_file, q_var=q_var, cell_to_point=cell_to_point,
                             time_step=time_step)
    lo, hi = mesh.bbox
    return {
        "points": mesh.n_points,
        "tets": mesh.n_tets,
        "boundary_faces": int(len(mesh.boundary_faces())),
        "zero_volume_tets": report.zero_volume_tets,
        "reoriented_tets": report.reoriented_tets,
        "coincident_points": report.coincident_points,
        "unreferenced_points": report.unreferenced_points,
        "bbox": [lo.tolist(), hi.tolist()],
        "scalar": mesh.scalar_name if mesh.has_scalar else None,
        "scalar_range": list(mesh.scalar_range) if mesh.has_scalar else None,
        "point_arrays": [_array_row(name, a) for name, a in mesh.user_point_data.items()],
        **({"cells": [f"{t} {len(d)}" for t, d in report.cells.blocks],
            "cell_arrays": [_array_row(name, np.concatenate([np.asarray(a).reshape(len(a), -1) for a in per]))
                            for name, per in report.cells.cell_data.items()]}
           if report.cells is not None else {}),
        "notes": list(report.notes),
    }


def _array_row(name: str, a) -> dict:
    """name, dtype, components and the finite range of an array (of its magnitude for vectors)."""
    a = np.asarray(a)
    k = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
    v = a.reshape(len(a), -1).astype(np.float64) if a.size else np.zeros((0, 1))
    with np.errstate(over="ignore", invalid="ignore"):
        v = v[:, 0] if k == 1 else np.sqrt(np.sum(v * v, axis=1))
    v = v[np.isfinite(v)]
    rng = [float(v.min()), float(v.max())] if v.size else None
    return {"name": name, "dtype": str(a.dtype.newbyteorder("=") if a.dtype.byteorder == ">" else a.dtype),
            "components": k, "range": rng}


def _check_output(source, output, *, force: bool, mesh_file: bool = False) -> None:
    """Refuse an output before any work: one that exists (unless ``force``), that is not a regular
    file, that is the input itself (even with ``force``), or, for a ``mesh_file``, whose format
    cannot hold tetrahedra."""
    if mesh_file:
        mesh_output_format(output)
    check_output_path(output, force=force)
    if isinstance(source, (str, os.PathLike)) and _same_file(source, output):
        raise OptionError(f"the output {output} is the input file")


def _same_file(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


# -- time series ---------------------------------------------------------------------------------

def _exodus_steps(path) -> int:
    """Steps of an Exodus file (0 when it cannot tell: the single-mesh path reports the error)."""
    try:
        return len(exodus_times(path))
    except Exception:
        return 0


def _compress_series(source, output, *, times, levels, mesh_only, force, w_density, w_geometry, w_sample, scalar,
                     cell_to_point, drop_cell_data, bricks, dependencies, jobs, keyframe_interval, log) -> "TetcFile":
    """:func:`compress` of a time series (one file: step 0 with its forest and levels, every step's
    arrays; :mod:`gatun_py.pipeline.series`)."""
    if bricks != 1 or dependencies:
        raise OptionError("a time series is stored as one plain stream: not with bricks or dependencies")
    for name, w in (("w_density", w_density), ("w_geometry", w_geometry), ("w_sample", w_sample)):
        if not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0):
            raise OptionError(f"{name} must be a finite number >= 0, got {w!r}")
    srcs = [source] if isinstance(source, (str, os.PathLike)) else source
    for src in (srcs if isinstance(srcs, (list, tuple)) else []):
        _check_output(src, output, force=force)
    check_output_path(output, force=force)
    t0 = time.perf_counter()
    series = read_series(source, times=times, scalar=scalar, cell_to_point=cell_to_point)
    noted = set()

    class _Steps:  # the series' meshes, each step's reader notes logged once; cell data per tet
        def __len__(self):
            return len(series)

        def __getitem__(self, k):
            mesh = series[k]
            report = series.reports[k]
            if report is not None and k not in noted:
                noted.add(k)
                for note in report.notes:
                    if k == 0 or not note.startswith("ignored non-volume"):
                        log(f"note: step {k}: {note}")
                if report.cell_arrays and drop_cell_data and k == 0:
                    log(f"note: cell data dropped on request: {', '.join(map(repr, report.cell_arrays))}")
            return mesh

        def cells(self, k):
            report = series.reports[k]
            if drop_cell_data or report is None or not report.cell_arrays:
                return {}
            return tet_cell_data(report.cells, f"step {k} ({series.names[k]})")

    meshes = _Steps()
    m0 = meshes[0]
    log(f"read {len(series)} steps ({series.times[0]:g} .. {series.times[-1]:g}): {m0.n_points} points, "
        f"{m0.n_tets} tets")
    n = write_series(output, meshes, series.times, force=force, levels=levels, mesh_only=mesh_only,
                     w_density=w_density, w_geometry=w_geometry, w_sample=w_sample, threads=check_jobs(jobs),
                     keyframe_interval=keyframe_interval, source=Path(series.names[0]).name,
                     cell_data=meshes.cells, log=log)
    log(f"wrote {output}: {n} bytes, {len(series)} steps, in {time.perf_counter() - t0:.1f} s")
    return TetcFile(output)


def append(path, source, *, time: float | None = None, scalar: str | None = None, cell_to_point: bool = False,
           drop_cell_data: bool = False, log=None) -> int:
    """Append a step to a series file without re-encoding the others; returns its step number.

    ``source``: a mesh file (or TetMesh) with the file's points and tets, and its cell arrays
    when the file's steps store them; ``time``: default the last time + 1. The step is written after the last whole step: an append interrupted midway
    leaves the earlier steps readable, and the next append cuts its bytes off first.
    """
    log = log or _quiet
    mesh, cells = _as_mesh_and_cells(source, ReadOptions(scalar=scalar, cell_to_point=cell_to_point), log,
                                     storing=True, drop_cell_data=drop_cell_data)
    if time is not None:
        time = _check_number("time", time, allow_none=False)
    cell_data = {} if cell_to_point else tet_cell_data(cells, str(source) if isinstance(source, (str, os.PathLike))
                                                       else "the step")
    return append_step(path, mesh, time, cell_data=cell_data)


def _series_output(output) -> str | None:
    """"pvd" or "xdmf" when ``output`` is a collection every step is written to."""
    suffix = Path(output).suffix.lower()
    return {".pvd": "pvd", ".xdmf": "xdmf", ".xmf": "xdmf"}.get(suffix)


def _write_steps(f: "TetcFile", output, kind: str, *, ratio, level, jobs, force) -> list:
    """Every step of ``f`` as a ``.pvd`` (one ``.vtu`` per step in ``<stem>_steps/``) or an XDMF
    temporal collection (one mesh, each step's point data; the coordinates must not move)."""
    output = Path(output)
    check_output_path(output, force=force)
    steps = range(f.n_steps)
    if kind == "pvd":
        folder = output.with_name(output.stem + "_steps")
        names = [f"step_{k:05d}.vtu" for k in steps]
        if folder.exists() and not force:
            for name in names:
                check_output_path(folder / name, force=force)
        folder.mkdir(exist_ok=True)
        rows = []
        for k, name in zip(steps, names):
            m = f.mesh(ratio, level=level, jobs=jobs, step=k)
            write_mesh(m, folder / name, force=force, cells=f._step_cells(m, k, ratio=ratio, level=level))
            rows.append(f'    <DataSet timestep="{f.times[k]!r}" part="0" file="{folder.name}/{name}"/>')
        text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                + "\n".join(rows) + "\n  </Collection>\n</VTKFile>\n")
        write_bytes_atomic(output, text.encode(), force=force)
        return [folder / n for n in names]
    if importlib.util.find_spec("h5py") is None:
        raise OutputError("writing an XDMF collection needs h5py (pip install h5py); a .pvd needs nothing extra")
    h5 = output.with_suffix(".h5")
    check_output_path(h5, force=force)
    if isinstance(f.reader.container.name, str) and os.path.isfile(f.reader.container.name):
        f = TetcFile(os.path.abspath(f.reader.container.name))  # read from inside the temporary directory
    first = f.mesh(ratio, level=level, jobs=jobs, step=0)
    with tempfile.TemporaryDirectory(dir=output.parent) as tmp:
        tx = Path(tmp) / output.name
        # meshio's writer puts the .h5 in the working directory: the temporary one for its duration
        with contextlib.chdir(tmp), meshio.xdmf.TimeSeriesWriter(tx.name) as w:
            w.write_points_cells(np.asarray(first.points), [("tetra", np.asarray(first.tets))])
            for k in steps:
                m = first if k == 0 else f.mesh(ratio, level=level, jobs=jobs, step=k)
                if k and not np.array_equal(m.points, first.points):
                    raise OptionError(f"step {k} moves the points, which an XDMF temporal collection of one "
                                      "mesh cannot hold: write a .pvd")
                w.write_data(f.times[k], point_data={n: np.asarray(a) for n, a in m.user_point_data.items()})
        os.replace(Path(tmp) / h5.name, h5)
        os.replace(tx, output)
    return [output, h5]


# -- open ----------------------------------------------------------------------------------------

class TetcFile:
    """An open ``.tetc`` file: what it holds, its meshes and its stream.

    Parameters
    ----------
    path : path-like or bytes

    Attributes
    ----------
    reader : TetcReader
        The low-level reader (sections, levels, the decoder).

    Examples
    --------
    >>> import gatun_py, tempfile, os
    >>> from gatun_py.warmup import tiny_mesh
    >>> out = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
    >>> f = gatun_py.open(gatun_py.compress(tiny_mesh(), out, levels=3).path)
    >>> f.levels
    [0, 1, 2, 3]
    >>> sum(len(b.tets) for b in f)   # the decoded stream of level 0
    90
    """

    def __init__(self, path):
        self.reader = (path.reader if isinstance(path, TetcFile) else path if isinstance(path, TetcReader)
                       else TetcReader(path))
        self.path = self.reader.container.name
        self._steps = None

    def __repr__(self) -> str:
        steps = f", steps={self.n_steps}" if self.n_steps > 1 else ""
        return (f"TetcFile({self.path!r}, points={self.n_points}, tets={self.n_tets}, "
                f"scalar={self.scalar_name if self.reader.has_scalar else None!r}, levels={self.levels}, "
                f"max_ratio={self.max_ratio:.4f}{steps})")

    @property
    def _series(self):
        if self._steps is None:
            self._steps = StepDecoder(self.reader)
        return self._steps

    @property
    def n_steps(self) -> int:
        """Time steps the file holds (1 for a snapshot)."""
        return self._series.n_steps

    @property
    def times(self) -> tuple:
        """The time of every step (a snapshot: ``(0.0,)``)."""
        return self._series.times

    def step_index(self, *, step: int | None = None, time: float | None = None) -> int:
        """The step at index ``step`` (negative from the end) or at ``time``; :class:`OptionError`
        when there is none."""
        if step is not None and time is not None:
            raise OptionError("give a step or a time, not both")
        if time is not None:
            return self._series.step_at(_check_number("time", time, allow_none=False))
        return self._series.check_step(0 if step is None else step)

    def at(self, step: int | None = None, *, time: float | None = None) -> "TetcFile":
        """Step ``step`` (or the one at ``time``) as a file of its own: its meshes, batches and
        renders carry that step's coordinates and arrays (step 0: this file)."""
        k = self.step_index(step=step, time=time)
        return self if k == 0 else TetcFile(self._series.reader(k))

    def cell_data(self, step: int = 0) -> dict:
        """A series' cell arrays of ``step`` (negative from the end): ``{name: array}`` with one row
        per tet of the full mesh, in the order of :meth:`mesh`'s tets, bit for bit in its dtype
        (a snapshot or a series without cell arrays: ``{}``)."""
        return dict(self._series.cell_values(self.step_index(step=step)))

    def _step_cells(self, mesh, k: int, *, ratio=None, level=None, log=None):
        """The cells to write with ``mesh`` (step ``k``): its tets with the step's cell arrays, or
        None (no cell arrays, or a simplified mesh, whose tets are not the stored ones)."""
        if not self._series.index.cells:
            return None
        if ratio is not None or level not in (None, 0):
            if log is not None:
                log("note: the cell arrays are those of the full mesh's tets: not written with a simplified mesh")
            return None
        return tet_cells(mesh.tets, self._series.cell_values(k))

    def steps(self, ratio: float | None = None, *, level: int | None = None, jobs: int | None = None):
        """Iterate over the steps: yields ``(time, mesh)`` (see :meth:`mesh`), each step decoded once."""
        for k in range(self.n_steps):
            yield self.times[k], self.mesh(ratio, level=level, jobs=jobs, step=k)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def __iter__(self):
        return self.batches()

    @property
    def info(self) -> dict:
        """What ``tetc info --json`` prints: sizes, bits per tet, sections, levels, forest; a series
        also its ``steps`` and ``times``."""
        n, times = self.n_steps, list(self.times)  # first: an appended step's sections join the index
        out = tetc_info(self.reader)
        if self._series.index.series:
            out["steps"], out["times"] = n, times
        return out

    @property
    def levels(self) -> list[int]:
        """The stored levels (0 = the full mesh)."""
        return sorted(int(lv["level"]) for lv in self.reader.levels)

    @property
    def n_points(self) -> int:
        return int(self.reader.meta.get("points", 0))

    @property
    def n_tets(self) -> int:
        return int(self.reader.meta.get("tets", 0))

    @property
    def scalar_name(self) -> str:
        return self.reader.scalar_name

    @property
    def arrays(self) -> list[tuple[str, str, int]]:
        """``(name, dtype, components)`` of every stored point array (the default scalar among them)."""
        return [(name, dt.name, k) for name, dt, k in self.reader.arrays]

    @property
    def max_ratio(self) -> float:
        """The largest simplification ratio the stored forest reaches (0 without one); of a bricked
        file, the largest every brick reaches."""
        if self.n_bricks > 1:
            return min(self.brick(k).max_ratio for k in range(self.n_bricks))
        return self.reader.forest_merges() / self.n_points if self.n_points else 0.0

    @property
    def n_bricks(self) -> int:
        """Bricks the file is split into (1: one plain stream)."""
        return self.reader.n_bricks

    def brick(self, k: int) -> "TetcFile":
        """Brick ``k`` as a file of its own (its levels, forest, stream); bounds in ``.info["bbox"]``."""
        return TetcFile(self.reader.brick(k))

    def mesh(self, ratio: float | None = None, *, level: int | None = None, jobs: int | None = None,
             step: int = 0) -> TetMesh:
        """The mesh at a simplification ratio (merged / all vertices) or a stored level; default the full mesh.

        ``step``: of a time series, the step (negative from the end); its coordinates and point
        arrays on the connectivity, forest and levels of step 0.

        Decodes on ``jobs`` threads (default: all cores): the connectivity in a thread of its own
        ahead of the geometry (:meth:`TetcReader.decode_mesh`), and a bricked file's bricks in
        parallel, stitched (every brick at ``ratio`` of its own vertices); the result does not
        depend on ``jobs``.
        """
        if ratio is not None and level is not None:
            raise OptionError("give a ratio or a level, not both")
        k = self.step_index(step=step)
        reader = self.reader if k == 0 else self._series.reader(k)
        return read_bricked(reader, ratio=ratio, level=level, jobs=jobs)

    def to_pyvista(self, ratio: float | None = None, *, level: int | None = None, step: int | None = None):
        """The mesh (:meth:`mesh`: at ``ratio`` or ``level``; of time step ``step`` in a series) as a
        ``pyvista.UnstructuredGrid`` with every array (needs PyVista).

        ``pyvista.read("x.tetc")`` also works once gatun_py is imported (meshio's registration): the full
        mesh of the first step.
        """
        n_steps = int(getattr(self, "n_steps", 1))
        if step is not None and not (isinstance(step, (int, np.integer)) and -n_steps <= step < n_steps):
            raise OptionError(f"no time step {step!r}: the file has {n_steps}")
        if step is None or n_steps == 1:
            return to_pyvista(self.mesh(ratio, level=level))
        return to_pyvista(self.mesh(ratio, level=level, step=int(step) % n_steps))

    def batches(self, *, ratio: float | None = None, level: int | None = None, batch_tets: int = 65536):
        """The decoded stream (:class:`~gatun_py.mesh.TetBatch`), simplified on the fly to ``ratio``."""
        if not (isinstance(batch_tets, (int, np.integer)) and batch_tets > 0):
            raise OptionError(f"batch_tets must be a positive integer, got {batch_tets!r}")
        if self.n_bricks > 1:
            raise OptionError(f"{self.path} is split into {self.n_bricks} bricks: stream one with "
                              ".brick(k).batches(), or decode the whole mesh with .mesh()")
        target = resolve_target(self.reader, ratio=ratio, level=level)
        stream = self.reader.iter_decode(target.level, batch_tets=int(batch_tets))
        anc = target_ancestors(self.reader, target)
        return stream if anc is None else SimplifyFilter(anc).filter(stream)

    def render(self, **options) -> "Frame":
        """:func:`render` this file (same keyword options)."""
        return render(self, **options)


def open(path) -> TetcFile:  # noqa: A001 (the verb users look for, as gzip.open, tarfile.open)
    """Open a ``.tetc`` file.

    Parameters
    ----------
    path : path-like or bytes

    Returns
    -------
    TetcFile

    Raises
    ------
    ReadError
        Missing or unreadable file.
    CorruptFileError
        Not a ``.tetc`` file, or damaged.
    """
    return TetcFile(path)


# -- render --------------------------------------------------------------------------------------

def render(source, *, view: View | None = None, detail: Detail | None = None, read: ReadOptions | None = None,
           pipeline: str = "streaming", time: float | None = None, progress=None, log=None, **options) -> Frame:
    """Volume-render a mesh: decode, simplify and ray-cast in one streaming pass.

    Parameters
    ----------
    source : path-like, TetcFile, TetMesh or meshio.Mesh
        A ``.tetc`` file (opened once), any mesh file, or a mesh in memory.
    view, detail, read : View, Detail, ReadOptions, optional
        How to draw (size, camera, transfer function, mode, step, background...), how much of the
        mesh (``.tetc``: a ratio, level, budget or selective cut; default all) and how to read it
        (for a ``.tetc`` file ``scalar`` is the stored array to draw, ``time_step`` a series' step).
        ``scalar`` may name a cell array: each cell is drawn in its value, constant inside it (the
        full mesh only).
    pipeline : {"streaming", "generic"}
        One pass, or decode-all-then-render (the paper's baseline).
    time : float, optional
        ``.tetc`` time series: render the step at this time (instead of ``time_step``).
    progress, log : callable, optional
        ``progress(done, total)`` of the tets rendered; ``log(line)`` for notes.
    **options
        Shorthand: the records' fields by name (``size=512, tf="bluntfin", ratio=0.9``).

    Examples
    --------
    >>> import gatun_py
    >>> from gatun_py.warmup import tiny_mesh
    >>> frame = gatun_py.render(tiny_mesh(), view=gatun_py.View(size=32, azimuth=30), elevation=20)
    >>> frame.rgb.shape, frame.stats["rays_unfinished"]
    ((32, 32, 3), 0)
    """
    log = log or _quiet
    view, detail, read = split_options("render", options, view=view, detail=detail, read=read)
    if pipeline not in PIPELINES:
        raise OptionError(f"pipeline must be one of {', '.join(PIPELINES)}, got {pipeline!r}")
    tetc_input = isinstance(source, TetcFile) or (isinstance(source, (str, os.PathLike)) and is_tetc(source))
    _announce_compiling((["decoder"] if tetc_input else []) + ["renderer"]
                        + (["forest decoder", "filter"] if tetc_input and detail.simplifies else []))
    t0 = _perf_counter()
    sview = _StreamView(view.camera, view.tf, view.mode, view.step, view.lean, view.scalar_range,
                        terminate=view.terminate)
    if not tetc_input:
        result, name, rng = _render_mesh_source(source, sview, detail, read, time=time, progress=progress, log=log)
        return _finish_frame(result, {}, view, name, rng, t0, log)
    f = source if isinstance(source, TetcFile) else TetcFile(source)
    if read.time_step is not None or time is not None:  # a step of a series
        f = f.at(read.time_step, time=time)
    if detail.budget is not None:
        _note_if_unsimplifiable(f.reader, os.path.basename(os.fspath(f.reader.container.name)), log)
    if f.n_bricks == 1 and _names_cell_array(f.reader, read.scalar):
        result, rng = _render_cell_array_file(f, read.scalar, sview, detail, view.component, progress)
        return _finish_frame(result, {}, view, _label(read.scalar, view.component), rng, t0, log)
    if read.scalar is not None or view.component is not None:
        sview = dataclasses.replace(sview, scalar=read.scalar or f.scalar_name, component=view.component)
    planner = _render_bricked if f.n_bricks > 1 else _render_selective if detail.selective else _render_uniform
    result, planned = planner(f.reader, sview, detail, pipeline=pipeline, progress=progress, log=log)
    name = f.scalar_name if sview.scalar is None else _label(sview.scalar, sview.component)
    return _finish_frame(result, planned, view, name, f.reader.array_range(sview.scalar, sview.component) or (0.0, 1.0),
                         t0, log)


def _render_mesh_source(source, sview, detail: Detail, read: ReadOptions, *, time, progress, log):
    """(PipelineResult, scalar name, scalar range) of a mesh file or a mesh in memory."""
    if time is not None:
        raise OptionError("time picks a step of a .tetc time series")
    if detail.simplifies:
        raise OptionError("ratio, level, budget and selective need a .tetc file with a merge forest "
                          "(make one with gatun_py.compress or `tetc compress`)")
    try:
        mesh = _as_mesh(source, read, log)
    except ReadError:
        # a cell array is no point scalar to read the mesh with: read it with its default one and
        # render the cell array as a constant per cell
        if read.scalar is None or read.cell_to_point:
            raise
        mesh, cells = _as_mesh_and_cells(source, dataclasses.replace(read, scalar=None), _quiet)
        if cells is None or read.scalar not in cells.cell_data:
            raise
        result, rng = render_cell_array(mesh, cells, read.scalar, sview,
                                        progress=_counter(progress, mesh.n_tets))
        return result, _label(read.scalar, sview.component), rng
    result = render_mesh_file(mesh, sview, progress=_counter(progress, mesh.n_tets))
    return result, mesh.scalar_name, mesh.scalar_range


def _label(scalar: str, component) -> str:
    """The colour bar's name of an array, or of one component of it."""
    return scalar + ("" if component is None else f"[{component}]")


def _render_cell_array_file(f, scalar: str, sview, detail: Detail, component, progress):
    """(PipelineResult, scalar range) of a ``.tetc`` file drawn by one of its cell arrays,
    constant inside each cell: the full mesh and its cells, decoded whole."""
    if detail.selective or detail.budget is not None or detail.tets is not None or detail.ratio not in (None, 0.0) \
            or detail.level not in (None, 0):
        raise OptionError(f"{scalar!r} is a cell array: it renders on the full mesh's cells only (no ratio, "
                          "level, budget or selective refinement)")
    mesh = f.mesh()
    cells = read_cells(f.reader, mesh.tets, mesh.n_points, mesh.points)
    return render_cell_array(mesh, cells, scalar, dataclasses.replace(sview, component=component),
                             step=file_render_defaults(f.reader)[3], progress=_counter(progress, mesh.n_tets))


def _render_bricked(reader, sview, detail: Detail, *, pipeline, progress, log):
    """(PipelineResult, planned stats) of a bricked file: each brick streams on its own into
    fragments, composited by depth; nothing is stitched, and under a budget each brick picks its
    own level."""
    if detail.selective:
        raise OptionError("selective refinement needs a file of one plain stream, not a bricked one")
    total = int(reader.meta.get("tets", 0))
    result = render_bricks([reader.brick(k) for k in range(reader.n_bricks)], sview, MeshExtent.of_reader(reader),
                           ratio=detail.ratio, level=detail.level, budget=detail.budget,
                           progress=_counter(progress, total))
    return result, ({"budget_s": detail.budget} if detail.budget is not None else {})


def _render_uniform(reader, sview, detail: Detail, *, pipeline, progress, log):
    """(PipelineResult, planned stats) of a stored level, simplified on the fly to a ratio, or
    planned to a budget (drawn smaller and scaled up when no level fits)."""
    planned = {}
    target = resolve_target(reader, ratio=detail.ratio, level=detail.level)
    budget = detail.budget
    if budget is not None:
        if load_costs() is None:
            log("measuring this machine's rendering costs for the budget (once, under a second)...")
        target, plan, planner, _ = plan_file_budget(reader, sview, budget)
        planned.update(predicted_s=plan.predicted_s, budget_s=budget, image_scale=plan.scale)
        if plan.scale != 1.0:
            width, height = sview.camera.width, sview.camera.height
            sview = dataclasses.replace(sview, camera=dataclasses.replace(
                sview.camera, width=max(1, round(width * plan.scale)), height=max(1, round(height * plan.scale))))
            log(f"note: no level renders {width}x{height} within {budget:g} s: rendering "
                f"{sview.camera.width}x{sview.camera.height} and scaling it up")
        if not plan.feasible:
            log(f"note: the budget of {budget:g} s cannot be met: rendering the coarsest level "
                f"(predicted {plan.predicted_s:.3f} s)")
    total = int(reader.level_meta(target.level)["tets"])
    t_frame = _perf_counter()
    result = render_tetc(reader, sview, pipeline=pipeline, target=target, progress=_counter(progress, total))
    if budget is not None:  # the machine's costs learn from every budget render
        remember_frame(planner, result.stats, total_s=_perf_counter() - t_frame)
    return result, planned


def _render_selective(reader, sview, detail: Detail, *, pipeline, progress, log):
    """(PipelineResult, planned stats) of a selective render of a file with merge dependencies;
    without ratio, tets or budget: ratio 0.5 (half the vertices merged where they matter least).
    A file without them renders uniformly, with a note."""
    if not reader.has_dependencies():
        log("note: this file stores no merge dependencies (it was compressed without them): rendering uniformly")
        level = detail.level
        if detail.tets is not None:  # the stored level with the fewest tets still at least that many
            lvs = [lv for lv in reader.levels if int(lv["tets"]) >= detail.tets] or reader.levels[:1]
            level = int(min(lvs, key=lambda lv: int(lv["tets"]))["level"])
        result, planned = _render_uniform(reader, sview, detail.replace(selective=False, tets=None, level=level),
                                          pipeline=pipeline, progress=progress, log=log)
        return result, {"selective": False, **planned}
    planned = {}
    level, ratio, tets = 0, detail.ratio, detail.tets
    if detail.budget is not None:
        if load_costs() is None:
            log("measuring this machine's rendering costs for the budget (once, under a second)...")
        # the uniform plan's level and tets, chosen selectively within that level's forest
        target, plan, _, _ = plan_file_budget(reader, sview, max(detail.budget - SELECTION_ALLOWANCE_S, 1e-3))
        level, tets = target.level, budget_tets(reader, sview, target)
        planned = {"predicted_s": plan.predicted_s, "budget_s": detail.budget}
    elif ratio is None and tets is None:
        ratio = 0.5
    total = int(reader.level_meta(0)["tets"])
    result = render_selective(reader, sview, ratio=ratio, tets=tets, pipeline=pipeline, level=level,
                              progress=_counter(progress, total), log=log)
    return result, planned


def _finish_frame(result, planned: dict, view: View, name: str, rng, t0: float, log) -> Frame:
    """The Frame of a render: over the background, at the size asked for, with the colour bar, and
    its stats (the notes of the stages go to ``log``)."""
    st = result.stats
    st.pop("filter", None)
    for note in st.pop("notes", []):
        log(f"note: {note}")
    st.update(planned)
    rng = view.scalar_range if view.scalar_range is not None else tuple(float(v) for v in rng)
    width, height = view.size
    rgb = to_rgb8(result.image, view.background)
    if rgb.shape[:2] != (height, width):  # a budget render drawn smaller
        rgb = upscale_rgb8(rgb, width, height)
    if view.colorbar:
        rgb = add_colorbar(rgb, view.tf.table(rng)[0], rng, name, view.background)
    st["render_total_s"] = _perf_counter() - t0
    st["peak_rss_mb"] = peak_rss_mb()
    st["size"] = [width, height]
    st["scalar"] = name
    st["scalar_range"] = list(rng)
    culled = st.get("tets_culled", 0)
    if st.get("rays_hit", 1) == 0 and not (culled and culled >= st.get("tets_rendered", 0)):
        # (all tets invisible: the ray caster's own note said so)
        log("note: no ray hits the " + ("visible part of the mesh" if culled else "mesh") + "; the image is black")
    if st.get("rays_unfinished"):
        log(f"warning: {st['rays_unfinished']} rays could not be completed")
    return Frame(rgb, result.image, st)


def _note_if_unsimplifiable(reader, name, log) -> None:
    """Say once that a budget cannot simplify a file stored without levels or a forest
    (``--mesh-only``): the render then meets the budget only by drawing fewer pixels, or not at all."""
    parts = [reader.brick(k) for k in range(reader.n_bricks)] if reader.n_bricks > 1 else [reader]
    if not any(len(r.levels) > 1 or any(lv.get("has_forest") for lv in r.levels) for r in parts):
        log(f"note: {name} stores no simplified levels and no merge forest (compressed with --mesh-only): "
            "a budget cannot simplify its mesh; compress it without --mesh-only to let a budget pick "
            "a coarser level")


def render_steps(source, output, *, steps=(None, None, None), force: bool = False, view: View | None = None,
                 detail: Detail | None = None, read: ReadOptions | None = None, pipeline: str = "streaming",
                 progress=None, log=None, **options) -> list[dict]:
    """Render steps of a ``.tetc`` time series, one image each: an animation.

    Parameters
    ----------
    source : path-like or TetcFile
    output : path-like
        The images: ``{frame}`` (0, 1, ...) and ``{step}`` (the step's index) in the name are
        formatted (e.g. ``run_{step:04d}.png``); without either, ``_0000``, ``_0001``, ... is added
        before the extension.
    steps : (start, stop, stride)
        As a Python slice of the steps (stop excluded; None: the ends).
    view, detail, read, pipeline, options
        As for :func:`render` (size, tf, azimuth, ratio, budget, scalar, ...). The view's
        ``scalar_range`` defaults to the range of the rendered array over every rendered step, so
        that the frames compare.

    Returns
    -------
    list of dict
        Every frame's stats, with its ``output``, ``step`` and ``time``.
    """
    log = log or _quiet
    view, detail, read = split_options("render_steps", options, view=view, detail=detail, read=read)
    f = source if isinstance(source, TetcFile) else TetcFile(source)
    start, stop, stride = steps
    if stride == 0:
        raise OptionError("the step stride must not be 0")
    for name, v in (("start", start), ("stop", stop), ("stride", stride)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))):
            raise OptionError(f"steps {name} must be a whole number, got {v!r}")
    ks = list(range(f.n_steps))[slice(start, stop, stride)]
    if not ks:
        raise OptionError(f"no step in {start}:{stop}:{stride} (the file has {f.n_steps} steps, 0..{f.n_steps - 1})")
    out = Path(output)
    if "{frame" in out.name or "{step" in out.name:
        try:
            paths = [out.with_name(out.name.format(frame=i, step=k)) for i, k in enumerate(ks)]
        except (KeyError, IndexError, ValueError) as e:
            raise OptionError(f"bad frame pattern {out.name!r}: use {{frame}}, {{step}} or {{step:04d}} ({e})") from None
    else:
        paths = frame_paths(out, len(ks))
    for p in paths:
        image_format(p)
        check_output_path(p, force=force)
    if view.scalar_range is None:
        lo, hi = math.inf, -math.inf
        for k in ks:
            r = f.at(k).reader.array_range(read.scalar, view.component)
            if r is not None:
                lo, hi = min(lo, r[0]), max(hi, r[1])
        if hi > lo:
            view = view.replace(scalar_range=(lo, hi))
    stats = []
    for i, (k, p) in enumerate(zip(ks, paths)):
        frame = render(f, view=view, detail=detail, read=dataclasses.replace(read, time_step=k), pipeline=pipeline,
                       log=log)
        frame.save(p, force=force)
        st = dict(frame.stats, output=str(p), step=k, time=f.times[k])
        stats.append(st)
        if progress is not None:
            progress(i + 1, len(ks))
    return stats


# -- rendering on a cluster ----------------------------------------------------------------------

def frame_paths(output, n_frames: int) -> list[Path]:
    """The file of every frame: ``output`` itself for one frame; else ``{frame}`` in it formatted, or
    ``_0000``, ``_0001``, ... before its extension.

    Examples
    --------
    >>> [p.name for p in frame_paths("orbit.png", 2)], [p.name for p in frame_paths("f{frame:02d}.png", 2)]
    (['orbit_0000.png', 'orbit_0001.png'], ['f00.png', 'f01.png'])
    """
    output = Path(output)
    if n_frames == 1 and "{frame" not in output.name:
        return [output]
    if "{frame" in output.name:
        try:
            return [output.with_name(output.name.format(frame=i)) for i in range(n_frames)]
        except (KeyError, IndexError, ValueError) as e:
            raise OptionError(f"bad frame pattern {output.name!r}: use {{frame}} or {{frame:04d}} ({e})") from None
    return [output.with_name(f"{output.stem}_{i:04d}{output.suffix}") for i in range(n_frames)]


def render_frames(source, output, *, workers: int | None = None, scheduler: str | None = None,
                  bricks: int | None = None, orbit: int = 1, view: View | None = None, detail: Detail | None = None,
                  read: ReadOptions | None = None, force: bool = False, timeout: float = 10.0, progress=None, log=None,
                  **options) -> list[dict]:
    """Render ``source`` as bricks on a Dask cluster, frame by frame, each frame written as it completes.

    The bricks go to the workers once and stay there for every frame. Each frame's fragments are
    composited in row bands on the workers (:mod:`gatun_py.pipeline.distributed`); the
    image equals the one :func:`render` gives (max difference 1 on 0-255).

    Parameters
    ----------
    source : path-like, TetMesh, or a list of them
        A ``.tetc`` file (a bricked file's own bricks; otherwise its level is decoded once and cut
        into ``bricks``) or any mesh file. A list (time steps) renders file after file, each with
        every view; a path with ``*``, ``?`` or ``[`` is a glob, expanded in sorted order.
    output : path-like
        The image; with several frames ``{frame}`` in the name is the frame number, else
        ``_0000``... is added before the extension.
    workers : int, optional
        Start a local cluster of this many worker processes (default 2 when no ``scheduler``).
    scheduler : str, optional
        Address of a running Dask scheduler, ``tcp://HOST:PORT``.
    bricks : int, optional
        Bricks to cut an unbricked source into (default 4 per worker).
    orbit : int
        Frames at azimuths ``azimuth + 360 k / orbit``.
    view : View, optional
        As for :func:`render` (size, tf, azimuth, elevation, zoom, mode, step, scalar_range,
        opacity_model, background); the orbit turns from its azimuth.
    detail : Detail, optional
        A stored ``level``, or a ``budget``: seconds per frame (a bricked ``.tetc`` file): every
        frame, each brick picks the level and ratio it can render in its share of the budget (the
        bricks of one worker share it; workers run side by side).
    read : ReadOptions, optional
        How to read a mesh file (see :func:`read_mesh`).
    force : bool
        Overwrite existing frames.
    timeout : float
        Seconds to wait for the scheduler.
    progress : callable, optional
        ``progress(frames_done, frames)``.
    log : callable, optional
        One-line notes.
    **options
        Shorthand: fields of ``view``, ``detail`` and ``read`` by name, as for :func:`render`.

    Returns
    -------
    list of dict
        Every frame's stats (``output``, ``frame_s``, ``tets_rendered``, ``fragment_mb``, ...).
    """
    log = log or _quiet
    view, detail, read = split_options("render_frames", options, view=view, detail=detail, read=read)
    orbit = int(orbit)
    if orbit < 1:
        raise OptionError(f"orbit must be a number of frames >= 1, got {orbit}")
    if bricks is not None and not (isinstance(bricks, (int, np.integer)) and bricks >= 1):
        raise OptionError(f"bricks must be a whole number >= 1, got {bricks!r}")
    if detail.ratio is not None or detail.selective:
        raise OptionError("a cluster renders a stored level or a budget: a ratio or a selective cut renders on "
                          "one machine (gatun_py.render)")
    level, budget = detail.level, detail.budget
    inputs = _frame_inputs(source)
    if budget is not None:
        for src in inputs:
            reader = TetcReader(src) if isinstance(src, (str, os.PathLike)) and is_tetc(src) else None
            if reader is None or reader.n_bricks <= 1:
                raise OptionError(f"a frame-time budget on a cluster needs a bricked .tetc file (tetc compress "
                                  f"--bricks K), not {src if isinstance(src, (str, os.PathLike)) else 'a mesh'}")
            _note_if_unsimplifiable(reader, os.path.basename(os.fspath(src)), log)
    paths = frame_paths(output, orbit * len(inputs))
    for p in paths:
        image_format(p)  # refuse what cannot be written before the work, not after
        check_output_path(p, force=force)
    views = [_StreamView(dataclasses.replace(view.camera, azimuth=view.azimuth + 360.0 * k / orbit), view.tf,
                         view.mode, view.step, False, view.scalar_range) for k in range(orbit)]
    with BrickCluster(scheduler=scheduler, workers=workers if scheduler is None else None, timeout=timeout,
                      log=log) as cluster:
        n_workers = len(cluster.workers)
        k = bricks or 4 * n_workers
        out = []
        for src in inputs:  # time steps: one file's bricks on the workers at a time
            sources, extent = _cluster_bricks(src, k, level, read, log)
            log(f"placing {len(sources)} bricks on {n_workers} workers...")
            cluster.load(sources, budget=budget is not None)
            for res, frame_view in zip(cluster.render_series(views, extent, budget=budget), views):
                i = len(out)
                for note in res.stats.pop("notes", []):
                    log(f"note: {note}")
                write_image(paths[i], to_rgb8(res.image, view.background), force=force)
                st = res.stats
                st.update(output=str(paths[i]), azimuth=frame_view.camera.azimuth,
                          input=str(src) if isinstance(src, (str, os.PathLike)) else "<mesh>")
                out.append(st)
                if progress is not None:
                    progress(i + 1, len(paths))
    return out


def _frame_inputs(source) -> list:
    """The inputs of a series: a list as it is, a glob pattern expanded (sorted), else the one source."""
    if isinstance(source, (list, tuple)):
        if not source:
            raise OptionError("no input files")
        return list(source)
    if isinstance(source, (str, os.PathLike)) and any(c in os.fspath(source) for c in "*?[") \
            and not os.path.exists(source):
        found = sorted(glob.glob(os.fspath(source)))
        if not found:
            raise OptionError(f"no file matches {os.fspath(source)!r}")
        return found
    return [source]


def _cluster_bricks(source, n_bricks: int, level, read: ReadOptions, log):
    """(brick sources, whole-mesh extent) of one input: a bricked file's own bricks, else its mesh
    (a .tetc level, a mesh file or a TetMesh) cut into ``n_bricks``."""
    if isinstance(source, (str, os.PathLike)) and is_tetc(source):
        reader = TetcReader(source)
        extent = MeshExtent.of_reader(reader)
        lv = resolve_target(reader, level=level).level
        if reader.n_bricks > 1:
            return [BrickRef(os.fspath(source), b, lv) for b in range(reader.n_bricks)], extent
        log(f"decoding level {lv} and cutting it into {n_bricks} bricks...")
        return split_for_render(reader.decode_mesh(lv), n_bricks)[0], extent
    if level is not None:
        raise OptionError("level needs a .tetc file")
    return split_for_render(_as_mesh(source, read, log), n_bricks)
