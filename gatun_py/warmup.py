"""Compile (and cache) every numba kernel ahead of the first real run: ``python -m gatun_py.warmup``.

``make install`` runs this, so a user's first ``tetc compress`` / ``tetc render`` starts in seconds
instead of sitting in JIT compilation. The kernels are exercised through the public API on a tiny
mesh, which gives them the same argument types as real data; the work is split over two processes
(numba compiles one function at a time per process) so both cores are used.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import meshio
import numpy as np

from . import api
from .codec import LevelPayload, TetcReader, encode_tetc
from .codec.arrays import ArrayDecoder, encode_array
from .codec.geometry import GeometryDecoder
from .codec.forest import FOREST_CODING, decode_forest_on_geometry, decode_forest_on_mesh, decode_forest_rounds
from .errors import CorruptFileError, TetcError
from .contour.extract import TINY_TETC, isosurface
from .mesh import TetMesh, mesh_batches, write_mesh
from .mesh.plot3d import grid_hexes
from .mesh.synthetic import jittered_grid
from .pipeline.bricks import compress_bricks, read_bricked
from .pipeline.sortlast import render_bricks, split_for_render
from .pipeline.stream import View, render_tetc
from .raycast._facetable import count_live, make_face_table, rehash
from .raycast.camera import Camera
from .raycast.composite import composite
from .raycast.caster import render_mesh
from .raycast.stream import render_batches
from .simplify import ROOT_RANK, ancestors, available_levels, build_levels, decimate
from .pipeline import _importance_kernels as IK
from .simplify.dependencies import closed_cut_order, cut_ancestors, merge_dependencies
from .simplify.filter import SimplifyFilter
from .simplify.levels import Target


def tiny_mesh():
    """A 4×4×3 jittered grid split into tets, with a smooth scalar."""
    return jittered_grid((4, 4, 3), jitter=0.15, scalar=(1.0, 0.3, 0.0))


def _simplify_and_render() -> str:
    mesh = tiny_mesh()
    forest = decimate(mesh)
    # every level the forest reaches: the tiny mesh is below the default's smallest level
    levels = build_levels(mesh, forest, available_levels(forest, min_points=1))
    _selective_kernels(mesh, forest)
    _render_kernels(lean=True)
    return f"decimation, merge dependencies and rendering ({len(levels)} levels)"


def _selective_kernels(mesh, forest) -> None:
    """The merge dependencies (compression) and a selective cut's importance (rendering)."""
    deps = merge_dependencies(mesh, forest)
    cut = np.zeros(deps.n_merges, np.bool_)
    cut[closed_cut_order(deps, np.ones(deps.n_merges))[: deps.n_merges // 2]] = True
    cut_ancestors(forest.parent, forest.rank, cut)
    pts = np.asarray(mesh.points, np.float64)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    grid = IK._extinction_grid(pts, np.ones(len(pts)), lo, hi, 4)
    IK._transmittance(grid, lo, hi, hi + 1.0, pts, 4)
    s = np.asarray(mesh.density, np.float64)
    IK._colour_change(np.ones((8, 4)), 0.0, 1.0, s, s[::-1].copy(), 4, 1.0)
    IK._projected_size(pts, np.ones(len(pts)), hi + 1.0, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                       np.array([0, 0, 1.0]), 0.5, 8.0, 8.0)
    IK._trilinear(np.ones((2, 2, 2)), lo, hi, pts, np.ones(len(pts), np.bool_))
    IK._cell_centres(lo, hi, 2)


def _codec_and_filter() -> str:
    _decode_and_filter(tiny_tetc_bytes())  # encodes first: the encoder's kernels too
    _arrays()
    return "compression, decompression and the run-time filter"


def _arrays() -> None:
    """The point-array coder both ways, for the dtypes meshes carry most (a float32 vector, float64
    and int32 values): a mesh read from .vtu usually has more arrays than its scalar."""
    mesh = tiny_mesh()
    n = mesh.n_points
    rng = np.random.default_rng(0)
    data = {"density": mesh.density, "u": rng.normal(size=(n, 3)).astype(np.float32),
            "p": rng.normal(size=n), "id": np.arange(n, dtype=np.int32)}
    mesh = TetMesh(mesh.points, None, mesh.tets, "density", point_data=data)
    TetcReader(encode_tetc([LevelPayload(0, 0.0, 0, mesh)])).decode_mesh(0)


SHIPPED_TETC = TINY_TETC  # the isosurface driver loads its kernels with it too


def tiny_tetc_bytes() -> bytes:
    """:func:`tiny_mesh` as a .tetc file with one merge in its forest (needs the encoder)."""
    mesh = tiny_mesh()
    parent = np.arange(mesh.n_points, dtype=np.int32)
    rank = np.full(mesh.n_points, ROOT_RANK, np.int32)
    parent[1], rank[1] = 0, 0  # one merge, so the forest coder and the filter do real work
    return encode_tetc([LevelPayload(0, 0.0, 0, mesh, (parent, rank))])


def _tiny_tetc() -> bytes:
    """The small .tetc that exercises the decoder: shipped beside this module (a test keeps it
    equal to :func:`tiny_tetc_bytes`), so a first render does not have to compile the encoder."""
    try:
        data = SHIPPED_TETC.read_bytes()
        TetcReader(data)
        return data
    except (OSError, TetcError):
        return tiny_tetc_bytes()


def _decode_and_filter(data: bytes) -> str:
    """Decode a tiny file, its forest too, and filter it."""
    reader = TetcReader(data)
    reader.decode_mesh(0)
    p, r = reader.read_forest(0)
    list(SimplifyFilter(ancestors(p, r, 1)).filter(reader.iter_decode(0, batch_tets=5)))
    return "decompression and the run-time filter"


# A format-3 forest section over two tets (four merges): the forest decoder compiles from it
# without a mesh's connectivity decoded first (a test keeps it equal to what the encoder writes).
FOREST_TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]], np.int32)
FOREST_PARENT_RANK = ([1, 1, 1, 2, 2], [0, ROOT_RANK, 3, 1, 2])
FOREST_SECTION = b"GFR3\x05\x00\x00\x00\x04\x00\x00\x00\x00\x01\xf8\x1c\x03\x1a\xb7z\x90\x00\x00"


# The same forest in coding 2 (format 6), over these points and zero values, and in coding 3
# (format 7, what tetc writes).
FOREST_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float32)
FOREST_SECTION_ROUNDS = b"GFR6\x05\x00\x00\x00\x04\x00\x00\x00\x00\x01\xf7\xfe\x03\x1a\xb7z\x90\x00\x00"
FOREST_SECTION_GEOMETRY = b"GFR7\x05\x00\x00\x00\x04\x00\x00\x00\x00\x01\xf7\xfe\x03\x1a\xb8\x0f\x10\x00\x00"


def _forest_decoder() -> str:
    # the coding tetc writes today only: a file of an older format compiles its own forest coding
    # when a render first needs it, instead of every first render paying for both
    if FOREST_CODING >= 2:
        decode, data = ((decode_forest_on_geometry, FOREST_SECTION_GEOMETRY) if FOREST_CODING == 3
                        else (decode_forest_rounds, FOREST_SECTION_ROUNDS))
        decode(data, FOREST_TETS, 5, boundary=np.ones(5, bool), points=FOREST_POINTS, density=np.zeros(5, np.float32))
    else:
        decode_forest_on_mesh(FOREST_SECTION, FOREST_TETS, 5, boundary=np.ones(5, bool))
    return "the merge-forest decoder"


def _render_kernels(*, lean: bool) -> None:
    """Render the tiny mesh in memory and streamed, in both modes (``lean``: counting faces)."""
    mesh = tiny_mesh()
    cam = Camera(16, 16, 30, 20)
    for mode in ("volume", "face"):
        composite(render_mesh(mesh, cam, "default", mode=mode, fragments=True).fragments)
        render_batches(mesh_batches(mesh, batch_tets=7), cam, "default", mode=mode, scalar_range=mesh.scalar_range,
                       lean=lean)
    if lean:
        _purge_kernels()


def _purge_kernels() -> None:
    """A lean face table fills up (and is purged) only on real meshes: call those kernels here."""
    table = make_face_table(8, 0, 0, counting=True)
    mark = np.zeros(1, dtype=np.uint8)
    rehash(table, 8, 0, count_live(table, True, mark) >= 0, mark)


def _isosurface() -> str:
    """Extract and simplify an isosurface of the tiny file (streamed: the prefetching decoder, the
    marching kernel, QEM), so a first ``tetc isosurface`` does not sit in compilation."""
    reader = TetcReader(_tiny_tetc())
    lo, hi = reader.meta["scalar_range"]
    isosurface(reader, values=[lo + 0.4 * (hi - lo), lo + 0.6 * (hi - lo)], ratio=0.5, batch_faces=4)
    return "isosurfaces"


def _connectivity_decoder() -> str:
    """The connectivity decoder as a streamed decode drives it (batches of a few tets)."""
    reader = TetcReader(_tiny_tetc())
    for _ in reader._connectivity_batches(reader._connectivity(0), reader.level_meta(0), 5, None, copy_refs=False):
        pass
    return "the connectivity decoder"


def _geometry_decoder() -> str:
    """The geometry decoder, without the connectivity's: numba compiles a kernel from its arguments'
    types, so refs of the right type do (all -1: whether the stream then decodes cleanly does not
    matter, and a corrupt-file error is expected)."""
    reader = TetcReader(_tiny_tetc())
    n = reader.level_meta(0).points
    geometry = GeometryDecoder(reader.read_section("L0/geometry"), n_points=n)
    try:
        geometry.decode(np.full((n, 4), -1, np.int32))
    except CorruptFileError:
        pass
    return "the geometry decoder"


def _filter_on_mesh() -> str:
    """The run-time filter's kernels, on the tiny mesh's batches (no decoder needed)."""
    mesh = tiny_mesh()
    p, r = np.arange(mesh.n_points, dtype=np.int32), np.full(mesh.n_points, ROOT_RANK, np.int32)
    p[1], r[1] = 0, 0
    list(SimplifyFilter(ancestors(p, r, 1)).filter(mesh_batches(mesh, batch_tets=5)))
    return "the run-time filter"


def _render_streamed(*, mode: str = "volume", lean: bool = False) -> str:
    """The ray caster as ``tetc render`` drives it: batches as a decoder hands them over (writable
    tets), and with ``lean`` the counting face table's purge."""
    mesh = tiny_mesh()
    batches = [dataclasses.replace(b, tets=b.tets.copy()) for b in mesh_batches(mesh, batch_tets=7)]
    render_batches(batches, Camera(16, 16, 30, 20), "default", mode=mode, scalar_range=mesh.scalar_range, lean=lean)
    if lean:
        _purge_kernels()
    return "rendering"


def compile_for_render(*, decoder: bool = True, simplify: bool = False, lean: bool = False,
                       mode: str = "volume") -> float:
    """Compile what ``tetc render`` needs into numba's cache (the first run on a fresh install);
    returns the seconds it took.

    numba compiles one function at a time per process, so the work is split: this process compiles
    the renderer while worker processes compile the decoder's connectivity and geometry halves
    and, with ``simplify`` (a render at a ratio, level or budget), the merge-forest decoder and the
    run-time filter. Three compilations at once keep two cores busy whatever their lengths (on a
    2-core EPYC about 11, 8.5 and 8.7 s of CPU for the renderer, the connectivity and the geometry). A mesh file (``decoder=False``) needs the renderer
    alone; what a render does not use compiles when first used (or ahead, by ``make install``).
    """
    t0 = time.perf_counter()
    jobs = ([_connectivity_decoder, _geometry_decoder] if decoder else []) + \
        ([_forest_decoder, _filter_on_mesh] if decoder and simplify else [])
    if not jobs:
        _render_streamed(mode=mode, lean=lean)
        return time.perf_counter() - t0
    with ProcessPoolExecutor(max_workers=2) as pool:
        futures = [pool.submit(job) for job in jobs]
        _render_streamed(mode=mode, lean=lean)
        for future in futures:
            future.result()
    return time.perf_counter() - t0


def load_kernels(*, lean: bool = False, decoder: bool = True, simplify: bool = True) -> float:
    """Load the decode, filter and render kernels into this process (from numba's cache, or by
    compiling them) with a 4x4-pixel render of a tiny file; returns the seconds it took.
    ``lean``: the face-counting kernels of a lean render too (otherwise they load when first used).
    ``decoder=False``: the render kernels only (a mesh file is rendered without the decoder).
    ``simplify=False``: without the merge-forest decoder and the filter (a full-resolution render).

    The CLI does this before it opens the user's file, so ``total_s`` measures the work on the
    file, not the one-off loading of compiled code (as VTK's timing excludes ``import vtk``).
    """
    t0 = time.perf_counter()
    if decoder:
        render_tetc(_tiny_tetc(), View(Camera(4, 4), tf="default", lean=lean),
                    target=Target(0, 1 if simplify else 0, 0.0, 0))
    else:
        mesh = tiny_mesh()
        render_batches(mesh_batches(mesh), Camera(4, 4), "default", scalar_range=mesh.scalar_range, lean=lean)
    if lean:
        _purge_kernels()
    return time.perf_counter() - t0


def _bricks() -> str:
    """A bricked file (`tetc compress --bricks`): each brick decimated with its shared vertices
    locked and coded, then decoded and stitched, whole and simplified."""
    reader = TetcReader(compress_bricks(tiny_mesh(), 2, jobs=1))
    read_bricked(reader, jobs=1)
    read_bricked(reader, ratio=0.2, jobs=1)
    return "bricks"


def _readme() -> str:
    """The README's Usage lines through the verbs the commands call, on a tiny mesh file with the
    arrays real files carry (a float32 vector too): numba compiles a kernel per argument types, and
    the paths above reach some kernels with other types (or not at all) than a real run does:
    compress --dependencies from a file, bricks without levels and their decode on worker
    processes, render at a ratio, under a budget, selective, lean, VTK's opacity, a vector's
    magnitude, a bricked render (as on Dask workers), isosurfaces with a preview and of bricks."""
    mesh = tiny_mesh()
    n = mesh.n_points
    uvw = np.random.default_rng(0).normal(size=(n, 3)).astype(np.float32)
    mesh = TetMesh(mesh.points, None, mesh.tets, "density", point_data={"density": mesh.density, "uvw": uvw})
    with tempfile.TemporaryDirectory(prefix="tetc_warmup_") as tmp:
        d = Path(tmp)
        write_mesh(mesh, d / "tiny.vtu")
        whole = api.compress(d / "tiny.vtu", d / "tiny.tetc", dependencies=True, levels=2)
        bricked = api.compress(d / "tiny.vtu", d / "tiny8.tetc", bricks=2, mesh_only=True, jobs=2)
        api.decompress(d / "tiny.tetc", d / "back.vtu")
        api.decompress(d / "tiny.tetc", d / "back90.vtu", ratio=0.9)
        api.decompress(d / "tiny8.tetc", d / "back8.vtu", jobs=2)
        views = [{}, {"ratio": 0.9}, {"budget": 0.1}, {"selective": True, "tets": 100}, {"lean": True},
                 {"opacity_model": "vtk", "background": "white", "colorbar": True},
                 {"scalar": "uvw", "component": "magnitude"}, {"scalar_range": (0.2, 0.8), "colorbar": True}]
        for view in views:
            api.render(whole, size=16, tf="default", azimuth=30, elevation=20, **view)
        api.render(bricked, size=16)
        bricks, extent = split_for_render(whole.reader.decode_mesh(0), 2)
        render_bricks(bricks, View(Camera(16, 16, 30, 20), tf="default"), extent)
        lo, hi = whole.reader.meta["scalar_range"]
        mid = lo + 0.5 * (hi - lo)
        isosurface(whole, values=[mid], ratio=0.1).preview(size=16, azimuth=30, elevation=20)
        isosurface(bricked, values=[mid], ratio=0.1)
        _hex_grid(d)
    _planes_coder()
    return "the README's commands"


def _hex_grid(d: Path) -> None:
    """What a PLOT3D grid (Blunt-fin) becomes: hexahedra on float32 points with five float32
    arrays, compressed with its dependencies and decompressed to its cells: kernels typed by
    float32 coordinates and reached by cells that the tet meshes above do not reach, and enough
    tets (over 1024) for the decimation to compact its tet table as on real files."""
    dims = (10, 8, 6)
    hexes, _ = grid_hexes(dims)
    k, j, i = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in dims[::-1]), indexing="ij")
    rng = np.random.default_rng(1)
    pts = np.stack([i, j, k], axis=-1).reshape(-1, 3) + rng.uniform(-0.1, 0.1, (i.size, 3)).astype(np.float32)
    arrays = {name: rng.normal(size=len(pts)).astype(np.float32)
              for name in ("density", "momentum-x", "momentum-y", "momentum-z", "energy")}
    grid = meshio.Mesh(pts.astype(np.float32), [("hexahedron", hexes)], point_data=arrays)
    api.compress(grid, d / "hex.tetc", dependencies=True, scalar="density")
    api.decompress(d / "hex.tetc", d / "hex.vtu")


def _planes_coder() -> None:
    """An array coded by the planes coder (xz of the residuals' bytes), which wins only on long,
    repetitive arrays: real files (Blunt-fin's Q variables) reach its decoder, a tiny mesh never."""
    n = 4096
    values = np.tile(np.arange(8, dtype=np.float32), n // 8)
    refs = np.full((n, 4), -1, np.int32)
    refs[1:, 0] = np.arange(n - 1)
    ArrayDecoder(encode_array(values, refs), n_points=n, dtype="float32", components=1).decode(refs)


# What `tetc warmup` (and `make install`) compiles, in two processes (numba compiles one function
# at a time per process): each job with the seconds it takes on two cores, for the progress line.
JOBS = ((_simplify_and_render, 60), (_codec_and_filter, 50), (_isosurface, 30), (_bricks, 20), (_readme, 40))


def warm_up(log=None) -> float:
    """Compile every kernel the commands run into numba's cache, in two processes, with a line on
    ``log`` as each part is ready; returns the seconds it took. Nothing compiles twice: a second
    call loads the kernels from the cache in seconds."""
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    os.environ["TETC_COMPILE_NOTICE"] = "0"  # the workers compile on purpose: no first-run notices
    t0 = time.perf_counter()
    total = max(sum(s for _, s in JOBS) / 2, max(s for _, s in JOBS))
    log(f"compiling tetc's kernels into numba's cache (once per install; about {total / 60:.0f} min on two "
        "cores, seconds when they are cached already)...")
    with ProcessPoolExecutor(max_workers=2) as pool:
        jobs = [pool.submit(job) for job, _ in JOBS]
        for i, job in enumerate(jobs, 1):
            log(f"  [{i}/{len(jobs)}] ready: {job.result()} ({time.perf_counter() - t0:.0f} s)")
    return time.perf_counter() - t0


def main() -> int:
    seconds = warm_up()
    print(f"kernels compiled and cached in {seconds:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
