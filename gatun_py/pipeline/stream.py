"""Decompress → simplify → render in one streaming pass (paper 3-5), and the generic baseline.

* **streaming**: the decoder's batches go through the run-time filter (only when the target
  ratio lies beyond the stored level it starts from) into the streaming ray caster; every tet is
  rendered as soon as it and its ancestors have arrived, and nothing is held beyond that.
* **generic** (the paper's baseline): decode the whole level into memory, simplify it, then
  render the whole mesh.

Both give the same image: the camera is fitted to the full mesh's bounding box, the transfer
function maps the full mesh's scalar range, and the volume-mode sample step is the full mesh's,
whatever level or ratio is drawn.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numba
import numpy as np

from .._runtime import peak_rss_mb
from ..codec import TetcReader
from ..codec.container import is_tetc  # noqa: F401  (the api and the CLI take it from here)
from ..errors import CorruptFileError, OptionError
from ..limits import PIPELINES
from ..mesh import TetMesh, default_step, mesh_batches, read_mesh
from ..mesh.cells import constant_per_cell, tet_values
from ..raycast.camera import Camera
from ..raycast.caster import render_mesh
from ..raycast.stream import render_batches
from ..raycast.transfer import load_transfer_function
from ..simplify.filter import SimplifyFilter
from ..simplify.forest import mesh_from_ancestors
from ..simplify.levels import Target, resolve_target, stored_levels, target_ancestors  # noqa: F401 (re-exported)

# The finest volume-mode step: this many samples along the bounding-box diagonal (the default step
# gives a few hundred to a few thousand). A step from the user or from a file below it is raised to
# it with a note, so no render can sample for ever (a 1e-9 step would take years).
MAX_SAMPLES_PER_DIAGONAL = 20_000
LEAN_BATCH_TETS = 16384  # decode batch of a lean streaming render
PREFETCH_BATCHES = 2  # batches the connectivity decoder may run ahead of a (not lean) streaming render


def decode_jobs() -> int:
    """Threads for a streaming render's decode: 2 (the connectivity ahead in a thread of its own)
    when numba may use two or more, else 1 (a Dask worker given one core keeps to it)."""
    return 2 if numba.get_num_threads() >= 2 else 1


@dataclass(frozen=True)
class View:
    """How to draw: the camera (image size and angles), transfer function and sampling."""

    camera: Camera = None  # default 256x256, VTK's default view
    tf: object = "default"
    mode: str = "volume"
    step: float | None = None
    lean: bool = False  # StreamingRaycaster's: free the faces no ray needs any more
    scalar_range: tuple | None = None  # what the transfer function is normalised to (default: the mesh's)
    scalar: str | None = None  # .tetc: the point array to render (default: the file's default scalar)
    component: object = None  # for a vector array: its component (int) or "magnitude"
    terminate: bool = True  # early ray termination at opacity 0.99 (off: every ray walked to its end)

    def __post_init__(self):
        if self.camera is None:
            object.__setattr__(self, "camera", Camera())


@dataclass
class PipelineResult:
    image: np.ndarray  # (H, W, 4) float32 premultiplied RGBA
    stats: dict = field(default_factory=dict)


def bounded_step(step: float, lo, hi, what: str = "step") -> tuple[float, list[str]]:
    """``step`` raised to the finest step the mesh allows, and a note when that changed it.

    Examples
    --------
    >>> bounded_step(1e-9, [0, 0, 0], [3, 4, 0])
    (0.00025, ['step 1e-09 is below the finest this mesh allows (0.00025: 20000 samples along the bounding-box diagonal); using 0.00025'])
    """
    diag = float(np.linalg.norm(np.asarray(hi, np.float64) - np.asarray(lo, np.float64)))
    finest = diag / MAX_SAMPLES_PER_DIAGONAL if diag > 0 and math.isfinite(diag) else 0.0
    if finest > 0 and not step >= finest:
        return finest, [f"{what} {step:g} is below the finest this mesh allows ({finest:g}: "
                        f"{MAX_SAMPLES_PER_DIAGONAL} samples along the bounding-box diagonal); using {finest:g}"]
    return step, []


def file_render_defaults(reader) -> tuple[np.ndarray, np.ndarray, tuple[float, float], float]:
    """bbox lo, hi, scalar range and volume-mode step of the full mesh (level 0).

    The step is the one the full mesh renders with (:func:`~gatun_py.mesh.default_step`): recorded at
    compression as ``render_step``, else computed from level 0's boundary, which is the first
    thing its stream holds. Every level and ratio then samples the same positions.
    """
    try:
        lo, hi = (np.asarray(x, np.float64).reshape(3) for x in reader.meta["bbox"])
        rng = tuple(float(x) for x in reader.meta["scalar_range"])
        if len(rng) != 2 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and all(map(math.isfinite, rng))):
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise CorruptFileError("corrupt metadata: bad bounding box or scalar range") from None
    step = reader.meta.get("render_step")
    if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
        stream = reader.iter_decode(0)
        first = next(stream)
        stream.close()
        step = default_step(first.points, first.boundary)
    return lo, hi, rng, float(step)


def file_view(reader, view: View):
    """(view, camera, scalar range, step, notes) of a frame of a ``.tetc`` file: everything fitted
    to the full mesh (its bounds, its scalar's range, its step), whatever level or brick is drawn."""
    lo, hi, rng, step = file_render_defaults(reader)
    if view.scalar is not None:  # another point array: its range is in the metadata (format 2)
        rng = reader.array_range(view.scalar, view.component) or rng
    rng = view.scalar_range if view.scalar_range is not None else rng
    # a relative opacity unit is a fraction of the full mesh's size, whatever level is drawn
    view = replace(view, tf=load_transfer_function(view.tf).for_size(float(np.linalg.norm(hi - lo))))
    camera = view.camera.fit(lo, hi)
    if view.step is not None:
        step, notes = bounded_step(view.step, lo, hi)
    else:
        step, notes = bounded_step(step, lo, hi, "the file's step")
    return view, camera, rng, step, notes


# -- running ------------------------------------------------------------------------------------

def render_tetc(source, view: View, *, ratio: float | None = None, level: int | None = None,
                pipeline: str = "streaming", target: Target | None = None, progress=None, ancestors=None,
                watch=None, decoded=None, partial=None, partial_every_s: float = 0.25) -> PipelineResult:
    """Render a ``.tetc`` file at a ratio or stored level.

    Parameters
    ----------
    source : path-like, bytes or TetcReader
        The file; an open reader is reused (a viewer renders many frames from one).
    view : View
    ratio, level : optional
        Simplification target (see :func:`gatun_py.simplify.levels.resolve_target`); default the full mesh.
    pipeline : {"streaming", "generic"}
    target : Target, optional
        A target already resolved (e.g. by the time-budget planner).
    progress : callable, optional
        Called with the number of tets decoded so far.
    ancestors : (n,) int array, optional
        With ``target``: the ancestors of the target level's vertices to filter with, instead of
        the first ``target.merges`` merges' (a selective cut, :mod:`gatun_py.pipeline.selective`).
    watch : callable, optional
        Wraps the filtered stream of batches (e.g. to count what goes to the renderer).
    decoded : iterable of TetBatch, optional
        The target level's stream, already decoded (streaming pipeline): used instead of decoding.
    partial, partial_every_s : optional
        Streaming pipeline: ``partial(image, finished)`` is called with the image so far at most every
        ``partial_every_s`` seconds (see :func:`gatun_py.raycast.stream.render_batches`).

    Returns
    -------
    PipelineResult
        ``stats`` has ``decode_s``, ``filter_s``, ``render_s``, ``level``, ``ratio``, ``merges``,
        ``tets_decoded``, ``tets_rendered``, ``rays``, ``rays_unfinished``, ``samples``, ``peak_rss_mb``.
    """
    if pipeline not in PIPELINES:
        raise OptionError(f"unknown pipeline {pipeline!r} (choose from {', '.join(PIPELINES)})")
    reader = source if isinstance(source, TetcReader) else TetcReader(source)
    if target is None:
        target = resolve_target(reader, ratio=ratio, level=level)
    view, camera, rng, step, notes = file_view(reader, view)
    times = {"decode_s": 0.0, "filter_s": 0.0}
    # Decoding the forest section is decompression; the top-down pass is part of the filter.
    forest_times = {"forest_decode_s": 0.0, "ancestors_s": 0.0}
    anc = target_ancestors(reader, target, times=forest_times) if ancestors is None else ancestors
    lv = reader.level_meta(target.level)
    if pipeline == "streaming":
        res, fstats = _run_streaming(reader, target, anc, camera, view, rng, step, times, progress, watch, decoded,
                                     partial=partial, partial_every_s=partial_every_s)
    else:
        res, fstats = _run_generic(reader, target, anc, camera, view, rng, step, times, watch)
    times["decode_s"] += forest_times["forest_decode_s"]
    times["filter_s"] += forest_times["ancestors_s"]
    stats = dict(res.stats)
    stats.update(times)
    stats.update(forest_times)
    stats.update(
        pipeline=pipeline, level=target.level, ratio=target.ratio, merges=target.merges,
        tets_decoded=lv.tets, filter=fstats, notes=notes + res.stats.get("notes", []),
        peak_rss_mb=peak_rss_mb(),
    )
    return PipelineResult(res.image, stats)


def _run_streaming(reader, target, anc, camera, view, rng, step, times, progress, watch=None, decoded=None, *,
                   partial=None, partial_every_s=0.25, fragments=False):
    lv = reader.level_meta(target.level)
    # A lean render holds about one batch of tets in flight: smaller batches, less memory. Otherwise,
    # with a second core, the connectivity decodes ahead in a thread of its own while this one
    # decodes the geometry and renders (the same batches, so the same image).
    batches = iter(decoded) if decoded is not None else reader.iter_decode(
        target.level, scalar=view.scalar, component=view.component,
        **({"batch_tets": LEAN_BATCH_TETS} if view.lean else {"jobs": decode_jobs(), "depth": PREFETCH_BATCHES}))
    filt = None
    if anc is not None:
        filt = SimplifyFilter(anc)
        batches = filt.filter(batches)
    if watch is not None:
        batches = watch(batches)
    res = render_batches(batches, camera, view.tf, mode=view.mode, step=step, scalar_range=rng,
                         expected_tets=lv.tets, lean=view.lean, fragments=fragments, progress=progress,
                         terminate=view.terminate,
                         partial=partial, partial_every_s=partial_every_s)
    # render_batches times the wait for each batch: the decoder, plus the filter when there is one.
    times["decode_s"] = res.stats["decode_s"]
    if filt is not None:
        times["filter_s"] = filt.stats["filter_s"]
        times["decode_s"] -= filt.stats["filter_s"]
    return res, (filt.stats if filt is not None else None)


def _run_generic(reader, target, anc, camera, view, rng, step, times, watch=None):
    t0 = time.perf_counter()
    mesh = reader.decode_mesh(target.level)
    if view.scalar is not None:
        try:
            mesh = mesh.with_scalar(view.scalar, view.component)
        except (KeyError, ValueError) as e:
            raise OptionError(str(e).strip("'\"")) from None
    times["decode_s"] = time.perf_counter() - t0
    fstats = None
    if anc is not None:
        t0 = time.perf_counter()
        mesh = mesh_from_ancestors(mesh, anc)[0]
        times["filter_s"] = time.perf_counter() - t0
        fstats = {"tets_out": mesh.n_tets}
    if watch is not None:
        for _ in watch(mesh_batches(mesh)):
            pass
    res = render_mesh(mesh, camera, view.tf, mode=view.mode, step=step, scalar_range=rng, terminate=view.terminate)
    return res, fstats


def render_mesh_file(source, view: View, *, read_kwargs: dict | None = None, progress=None) -> PipelineResult:
    """Render a mesh file (not ``.tetc``) or a :class:`TetMesh` whole, fed batch-wise like a decoded stream."""
    t0 = time.perf_counter()
    if isinstance(source, TetMesh):
        mesh, notes = source, []
    else:
        mesh, report = read_mesh(source, **(read_kwargs or {}))
        notes = list(report.notes)
    read_s = time.perf_counter() - t0
    lo, hi = mesh.bbox
    rng = view.scalar_range if view.scalar_range is not None else mesh.scalar_range
    step = view.step
    if step is not None:
        step, step_notes = bounded_step(step, lo, hi)
        notes += step_notes
    res = render_batches(mesh_batches(mesh), view.camera.fit(lo, hi), view.tf, mode=view.mode, step=step,
                         scalar_range=rng, expected_tets=mesh.n_tets, lean=False, progress=progress,
                         terminate=view.terminate)
    stats = dict(res.stats)
    stats.update(decode_s=read_s + stats.get("decode_s", 0.0), filter_s=0.0, pipeline="streaming", level=0,
                 ratio=0.0, merges=0, tets_decoded=mesh.n_tets, notes=notes + stats.get("notes", []),
                 peak_rss_mb=peak_rss_mb())
    return PipelineResult(res.image, stats)


def render_cell_array(mesh: TetMesh, cells, name: str, view: View, *, step: float | None = None,
                      progress=None) -> tuple[PipelineResult, tuple[float, float]]:
    """Render the cell array ``name`` of ``cells`` (the cells of ``mesh``) as a constant per cell.

    Every tet takes its cell's value (``view.component`` of a vector), so the scalar is constant
    inside a cell and jumps at its faces (:func:`~gatun_py.mesh.cells.constant_per_cell`); the
    renderer's kernels are the point-scalar ones. The sample step is ``view.step``, else ``step``
    (a file's recorded step), else the full mesh's default, so the samples fall where a point
    scalar's would. Returns the result and the values' range.
    """
    values = tet_values(cells, name, view.component)
    if view.step is None:
        view = replace(view, step=step if step is not None else default_step(mesh.points, mesh.boundary_faces()))
    label = name if view.component is None else f"{name}[{view.component}]"
    per_cell = constant_per_cell(mesh, values, label)
    res = render_mesh_file(per_cell, view, progress=progress)
    res.stats["notes"] = res.stats.get("notes", []) + [f"cell array {label!r} rendered as a constant per cell"]
    return res, per_cell.scalar_range
