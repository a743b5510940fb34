"""Isosurfaces straight from a tet stream, simplified while they are extracted (Hou & Chen).

The driver feeds every batch of the stream (a ``.tetc`` file's decoder, optionally through the
on-the-fly mesh simplification filter, or an in-memory mesh cut into batches) to one
:class:`_Extractor` per isovalue: marching tetrahedra with edge-keyed vertices and locks
(:mod:`.marching`), and after every ``batch_faces`` new faces a round of QEM edge collapses over the
whole intermediate surface (:mod:`.qem`), after which dead vertices and faces are compacted away.
The full-resolution surface never exists unless no reduction was asked for.
"""

from __future__ import annotations

import collections
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._atomic import check_output_path
from .._compile_notice import announce as _announce_compiling
from .._compile_notice import watch as _watch_compiles
from .._runtime import peak_rss_mb, release_code_pages, rss_mb, trim_heap
from ..codec import TetcReader
from ..codec.stepreader import StepDecoder
from ..codec.bricks import check_jobs
from ..codec.container import is_tetc
from ..codec.prefetch import PrefetchedDecode
from ..errors import CorruptFileError, OptionError, ReadError, TetcError
from ..mesh import TetMesh, mesh_batches, read_mesh
from ..mesh.synthetic import jittered_grid
from ..simplify.filter import SimplifyFilter
from ..simplify.levels import resolve_target, target_ancestors
from . import _numba_setup  # noqa: F401  (first, before any kernel is loaded: see the module)
from . import marching, qem
from .bricked import BrickedStream
from .io import write_surface

DEFAULT_BATCH_FACES = 100_000
MAX_PREVIEW_PIXELS = 1 << 26
CHUNK_TETS = 8192  # tets per extraction step (rounds start between steps)
MAX_IN_FLIGHT = 16  # decoded batches waiting for the extraction thread
#: tets batches the connectivity decoder may run ahead of the geometry (each ~1.2 MB of tets and
#: refs): the geometry of the boundary's vertices comes first and takes as long as ~10 batches of
#: connectivity (flange-10m: 268 k vertices), so with the decoder's default of 4 the connectivity
#: thread, the critical path, sat idle on a full queue for that long; afterwards the geometry is
#: the faster stage and the queue stays nearly empty, so the depth costs no memory at the peak
PREFETCH_DEPTH = 16
BOUNDARY_CHUNK = 4 * CHUNK_TETS  # boundary faces per extraction step (as many faces as a tet step)
#: keep at least this share of ``batch_faces`` modifiable faces between rounds (Hou & Chen's
#: initial phase: early rounds must not over-decimate what little has been seen)
KEEP_SHARE = 0.5
#: over this last share of the stream (when its length is known) that floor shrinks linearly to
#: zero: late rounds have seen most of the surface, and what they keep is what the final round,
#: after the stream and so on the critical path, must still collapse (flange-10m at three
#: isovalues: final round 0.24-0.36 s -> 0.15-0.19 s of CPU, RMS and Hausdorff equal or lower)
KEEP_TAIL = 0.5
#: hand the C heap's free pages back to the system after every this many batches (see trim_heap)
TRIM_EVERY = 4
#: the worker unmaps LLVM's code pages (``release_code_pages``) after this many batches, by when the
#: decoders' and the marching kernels are loaded (the boundary, then the first batch of tets), and
#: again after the first round of collapses (which loads theirs); LLVM is not used after that
RELEASE_CODE_AFTER = 2
#: the per-vertex columns of an extractor: name -> (shape after the vertex axis, dtype, value of a
#: fresh slot, both when allocated and when freed by a round's compaction, or None where marching
#: writes the value of every vertex it adds); a stale quadric, border flag or importance in a reused
#: slot would pass to the new vertex
VERTEX_COLUMNS = {
    "vpos": ((3,), np.float64, None),
    "vgrad": ((2,), np.float64, 0.0),
    "vkey": ((), np.int64, None),
    "vlock": ((), np.uint8, 0),
    "vq": ((qem.QUADRIC_WIDTH,), np.float64, 0.0),
    "vbnd": ((), np.uint8, 0),
    "vdead": ((), np.uint8, 0),
    "vimp": ((), np.float64, 1.0),
    "vfresh": ((), np.uint8, 1),
}
MIN_DOT = 0.0  # a collapse may not turn a face by more than 90 degrees (0.2, ~78 degrees, measured worse)


@dataclass
class Surface:
    """A triangle surface with per-point data.

    Attributes
    ----------
    points : (n, 3) float64
    triangles : (m, 3) int32, wound so that normals point toward lower scalar values
    point_data : dict of name -> (n,) array (``scalar``: the isovalue; ``gradient_magnitude``;
        ``importance`` when an importance function was given)
    stats : dict
        Timings, counts and the locked band over time (``band``: list of per-batch records).
    """

    points: np.ndarray
    triangles: np.ndarray
    point_data: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    def __repr__(self) -> str:
        vals = self.stats.get("values")
        v = f", values={vals}" if vals is not None else ""
        return (f"<Surface: {self.n_points} points, {self.n_triangles} triangles{v}, "
                f"point data {sorted(self.point_data)}>")

    @property
    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        if self.n_points == 0:
            return np.zeros(3), np.zeros(3)
        return self.points.min(axis=0), self.points.max(axis=0)

    def save(self, path, *, force: bool = False) -> None:
        """Write the surface; the format follows the extension (``.vtp``, ``.ply``, ``.obj``, ``.stl``, ...)."""
        write_surface(self, path, force=force)

    def preview(self, *, size=512, azimuth: float = 0.0, elevation: float = 0.0, zoom: float = 1.0,
                frame: str = "surface") -> np.ndarray:
        """A shaded picture of the surface: (H, W, 3) uint8, Lambert with a headlight.

        The camera follows ``tetc render``'s conventions, fitted to the surface's own bounding box
        (``frame="surface"``: a small surface fills the picture) or to the box of the mesh it was
        extracted from (``frame="volume"``, ``stats["bbox"]``: the preview lines up with a volume
        render of the same view). Several isovalues are coloured by value.

        Examples
        --------
        >>> from gatun_py.mesh.synthetic import jittered_grid
        >>> s = isosurface(jittered_grid((5, 5, 5), jitter=0.1), values=1.5)
        >>> s.preview(size=(48, 32)).shape
        (32, 48, 3)
        """
        # the renderer (and PIL, for images) load only for a preview: start-up and memory of a plain extraction
        from ..raycast.camera import Camera
        from ..raycast.image import to_rgb8
        from ..raycast.surface import render_surface

        w, h = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
        if w <= 0 or h <= 0 or w * h > MAX_PREVIEW_PIXELS:
            raise OptionError(f"preview size {w}x{h}: each side must be >= 1 and the image at most "
                              f"{MAX_PREVIEW_PIXELS} pixels")
        for name, v in (("azimuth", azimuth), ("elevation", elevation), ("zoom", zoom)):
            if not math.isfinite(v):
                raise OptionError(f"{name} must be a finite number, got {v}")
        if zoom <= 0:
            raise OptionError(f"zoom must be > 0, got {zoom}")
        if frame not in ("surface", "volume"):
            raise OptionError(f"frame must be 'surface' or 'volume', got {frame!r}")
        box = self.stats.get("bbox")
        if frame == "surface" and self.n_triangles:
            bbox = self.bbox  # an empty surface keeps the volume's frame: a black picture of the right view
        else:
            bbox = (np.asarray(box[0], float), np.asarray(box[1], float)) if box is not None else None
        scal = self.point_data.get("scalar") if len(self.stats.get("values", ())) > 1 else None
        rgba = render_surface(self.points, self.triangles, Camera(w, h, azimuth, elevation, zoom), scalar=scal,
                              bbox=bbox)
        return to_rgb8(rgba)

    def save_preview(self, path, *, size=512, azimuth: float = 0.0, elevation: float = 0.0, zoom: float = 1.0,
                     frame: str = "surface", force: bool = False) -> None:
        """Write :meth:`preview` as an image (PNG, JPEG, WebP, TIFF or BMP from the extension), atomically."""
        from ..raycast.image import write_image  # PIL only for a preview (see preview)

        check_output_path(path, force=force)
        write_image(path, self.preview(size=size, azimuth=azimuth, elevation=elevation, zoom=zoom, frame=frame),
                    force=force)

    def _repr_png_(self) -> bytes:
        from ..raycast.image import png_bytes  # PIL only for a preview (see preview)

        return png_bytes(self.preview(size=384, azimuth=30, elevation=20))


# -- importance ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ImportanceFunction:
    """Importance of a surface vertex as a piecewise-linear function of a feature (Peng et al.).

    The feature is the scalar's gradient magnitude at the surface; ``x`` is in units of the scalar
    range per bounding-box diagonal (a linear ramp across the whole box has x = 1) unless
    ``absolute``. Importance multiplies the quadric error of the faces, so a region with importance
    10 keeps its detail until its error is ten times what it would otherwise be.
    """

    x: np.ndarray
    w: np.ndarray
    absolute: bool = False

    def __call__(self, gradient, scale: float) -> np.ndarray:
        g = np.asarray(gradient, np.float64) * (1.0 if self.absolute else scale)
        return np.interp(g, self.x, self.w)


def load_importance(spec) -> ImportanceFunction:
    """Read an importance function: a JSON file or dict ``{"points": [{"x": .., "w": ..}, ...],
    "absolute": false}`` (``feature``, if present, must be ``"gradient_magnitude"``).

    Examples
    --------
    >>> f = load_importance({"points": [{"x": 0, "w": 1}, {"x": 2, "w": 10}]})
    >>> float(f(np.array([1.0]), 1.0)[0])
    5.5
    """
    if isinstance(spec, ImportanceFunction):
        return spec
    if not isinstance(spec, dict):
        try:
            spec = json.loads(Path(spec).read_text())
        except OSError as e:
            raise ReadError(f"cannot read importance function {spec}: {e.strerror or e}") from None
        except ValueError as e:
            raise ReadError(f"importance function {spec} is not valid JSON: {e}") from None
    try:
        feature = spec.get("feature", "gradient_magnitude")
        if feature != "gradient_magnitude":
            raise OptionError(f"importance feature {feature!r} is not supported (only 'gradient_magnitude')")
        pts = spec["points"]
        x = np.array([float(p["x"]) for p in pts])
        w = np.array([float(p["w"]) for p in pts])
    except OptionError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError):
        raise OptionError('importance function must be {"points": [{"x": X, "w": W}, ...]}') from None
    if len(x) == 0 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(w))):
        raise OptionError("importance function needs at least one point with finite x and w")
    if np.any(w <= 0):
        raise OptionError("importance weights must be positive")
    if np.any(np.diff(x) < 0):
        raise OptionError("importance points must be sorted by x")
    return ImportanceFunction(x, w, bool(spec.get("absolute", False)))


# -- one isovalue ------------------------------------------------------------------------------------

def _pow2(n: int) -> int:
    return 1 << max(4, int(n - 1).bit_length())


class _Extractor:
    """Streaming extraction + locked QEM for one isovalue (state: the arrays below)."""

    def __init__(self, iso: float, *, ratio, faces, batch_faces, importance, grad_scale, check=None,
                 expected_tets=None):
        self.iso = float(iso)
        self.expected_tets = expected_tets
        self.ratio = ratio
        self.faces_target = faces
        self.batch_faces = int(batch_faces)
        self.importance = importance
        self.grad_scale = grad_scale
        self.check = check
        self.tets_done = 0
        self.ftab = marching.new_face_table(16)
        self.etab = marching.new_edge_table(16)
        self.sizes = np.zeros(2, np.int64)
        self.nv = 0
        self.nt = 0
        self._alloc_vertices(1024)
        self.tris = np.empty((2048, 3), np.int32)
        self.nq = 0  # faces whose quadrics are added
        self.extracted = 0  # faces extracted in total
        self.since = 0  # faces extracted since the last round
        self.rounds = 0
        self.collapses = 0
        self.peak_faces = 0
        self.qem_s = 0.0
        self.extract_s = 0.0

    def _alloc_vertices(self, cap):
        old = getattr(self, "vpos", None)
        n = self.nv
        new = {name: np.empty((cap, *shape), dtype) if fresh is None else np.full((cap, *shape), fresh, dtype)
               for name, (shape, dtype, fresh) in VERTEX_COLUMNS.items()}
        if old is not None:
            for name, arr in new.items():
                arr[:n] = getattr(self, name)[:n]
        for name, arr in new.items():
            setattr(self, name, arr)

    def _reserve(self, n_tets: int, n_faces: int):
        need_f = int(self.sizes[0]) + 4 * n_tets + n_faces
        if 2 * need_f > self.ftab.shape[0]:
            self.ftab = marching.rehash_faces(self.ftab, _pow2(4 * need_f))
        need_e = int(self.sizes[1]) + 6 * n_tets + 3 * n_faces
        if 2 * need_e > self.etab.shape[0]:
            self.etab = marching.rehash_edges(self.etab, _pow2(4 * need_e))
        if self.nv + 4 * n_tets > self.vpos.shape[0]:
            self._alloc_vertices(max(2 * self.vpos.shape[0], self.nv + 4 * n_tets))
        if self.nt + 2 * n_tets > self.tris.shape[0]:
            t = np.empty((max(2 * self.tris.shape[0], self.nt + 2 * n_tets), 3), np.int32)
            t[:self.nt] = self.tris[:self.nt]
            self.tris = t

    def add(self, vals, tets, boundary, tets_before: int, *, batch_len=None, chunk_ends=None):
        """Feed one batch, in chunks small enough that a round runs close to every B faces.

        Boundary faces go first, in chunks of their own: the tables are reserved for the worst
        case of one call, and a ``.tetc`` file's first batch carries the whole mesh boundary
        (535,922 faces on the 7.8 M-tet flange, which reserved ~190 MB of hash slots in one
        call). The result is the same as in one call: a boundary face only enters the border,
        so no count falls to zero between the chunks that would not at the end of the batch.

        ``batch_len``, ``chunk_ends``: ``tets`` are the surface's tets (:class:`_SurfaceTets`) of a
        batch of ``batch_len`` tets, and ``chunk_ends[i]`` is how many of them lie in its first
        i + 1 chunks of ``CHUNK_TETS`` tets; the chunks, the unlocks at their ends and the rounds
        between them are then those of the whole batch. None: ``tets`` is the whole batch.
        """
        step = CHUNK_TETS
        if len(boundary) > BOUNDARY_CHUNK:
            for i in range(0, len(boundary), BOUNDARY_CHUNK):
                self._add(vals, tets[:0], boundary[i:i + BOUNDARY_CHUNK], tets_before)
            boundary = boundary[:0]
        n_tets = len(tets) if batch_len is None else int(batch_len)
        if chunk_ends is None:
            chunk_ends = np.minimum(np.arange(1, -(-n_tets // step) + 1) * step, n_tets)
        if n_tets <= step:
            self._add(vals, tets, boundary, tets_before + n_tets)
            return
        start = 0
        for i, end in enumerate(chunk_ends.tolist()):
            self._add(vals, tets[start:end], boundary if i == 0 else boundary[:0],
                      tets_before + min((i + 1) * step, n_tets))
            start = end

    def _add(self, vals, tets, boundary, tets_done):
        self.tets_done = tets_done
        t0 = time.perf_counter()
        self._reserve(len(tets), len(boundary))
        zero = np.empty(12 * len(tets) + 3 * len(boundary) + 1, np.int64)
        nt0 = self.nt
        self.nv, self.nt, _ = marching.extract_batch(
            vals, tets, boundary, self.iso, marching.CASE_COUNT, marching.CASE_TRIS, marching.TET_EDGES,
            self.ftab, self.etab, self.vpos, self.vgrad, self.vkey,
            self.vlock, self.nv, self.tris, self.nt, zero, self.sizes)
        new = self.nt - nt0
        self.extracted += new
        self.since += new
        self.peak_faces = max(self.peak_faces, self.nt)
        self.extract_s += time.perf_counter() - t0
        if self.since >= self.batch_faces and (self.ratio is not None or self.faces_target is not None):
            self.decimate(final=False)

    @property
    def locked(self) -> int:
        return int(self.vlock[:self.nv].sum())

    def _target(self, final: bool) -> int:
        if final:
            if self.faces_target is not None:
                return int(self.faces_target)
            return int(math.ceil(self.ratio * self.extracted))
        tris = self.tris[:self.nt]
        faces_locked = int(self.vlock[tris].any(axis=1).sum()) if self.nt else 0
        keep = KEEP_SHARE * self.batch_faces
        if self.expected_tets:
            left = max(0.0, 1.0 - self.tets_done / self.expected_tets)
            keep *= min(1.0, left / KEEP_TAIL)
        if self.faces_target is not None:
            mod = max(self.faces_target, keep)
        else:
            mod = max(self.ratio * (self.extracted - faces_locked), keep)
        return faces_locked + int(mod)

    def decimate(self, *, final: bool):
        t0 = time.perf_counter()
        n = self.nv
        if self.importance is not None:
            g = self.vgrad[:n, 0] / np.maximum(self.vgrad[:n, 1], 1.0)
            self.vimp[:n] = self.importance(g, self.grad_scale)
        qem.add_face_quadrics(self.vpos, self.vq, self.vimp, self.tris, self.nq, self.nt)
        target = self._target(final)
        touched = np.empty(2 * self.nt if self.check is not None else 0, np.int64)
        alive, done = qem.decimate(self.vpos, self.vq, self.vbnd, self.vlock, self.vdead, self.vimp, self.vfresh,
                                   self.tris, n, self.nt, target, MIN_DOT, touched)
        if self.check is not None and done:
            self.check(self.vkey[touched[:2 * done]], self.tets_done)
        self.collapses += done
        self.rounds += 1
        remap, self.nv, self.nt = qem.compact(self.vdead, self.tris, n, self.nt)
        live = remap >= 0  # the vertices not dead: their vdead moves as 0
        for name, (_, _, fresh) in VERTEX_COLUMNS.items():
            arr = getattr(self, name)
            arr[:self.nv] = arr[:n][live]
            if fresh is not None:  # the freed slots are reused by the next batch's new vertices
                arr[self.nv:n] = fresh
        vid = self.etab["vid"]
        used = (self.etab["key"] != marching.EMPTY) & (vid >= 0)
        vid[used] = remap[vid[used]].astype(np.int32)
        self.nq = self.nt
        self.since = 0
        self.qem_s += time.perf_counter() - t0

    def finish(self):
        self.locked_at_end = self.locked
        if self.locked_at_end:  # only a mesh whose tets overlap can leave a star open at the end
            self.vlock[:self.nv] = 0
        if self.ratio is not None or self.faces_target is not None:
            self.decimate(final=True)
        points = self.vpos[:self.nv].copy()
        tris = self.tris[:self.nt].copy()
        grad = self.vgrad[:self.nv, 0] / np.maximum(self.vgrad[:self.nv, 1], 1.0)
        data = {"scalar": np.full(self.nv, self.iso, np.float32), "gradient_magnitude": grad.astype(np.float32)}
        if self.importance is not None:
            data["importance"] = self.vimp[:self.nv].astype(np.float32)
        return points, tris, data


# -- loading the kernels ahead of the data --------------------------------------------------------

#: a tiny ``.tetc`` file shipped with the package (:mod:`gatun_py.warmup` writes and tests it)
TINY_TETC = Path(__file__).resolve().parent.parent / "warmup.tetc"

_watch_compiles()  # a first extraction that compiles says so on stderr, once per process


def load_kernels(source=None, *, simplify: bool = True) -> float:
    """Load the kernels an extraction of ``source`` runs into this process, then hand back the
    LLVM code pages that loading touched; returns the seconds it took.

    The kernels load (from numba's cache, or compile) with an isosurface of the tiny shipped file:
    the streaming decoder unless ``source`` is a mesh file or an in-memory mesh (a tiny mesh is
    then extracted in memory), marching tetrahedra, and QEM unless ``simplify=False``. The CLI
    calls this before it opens the user's file, so that the peak memory of a large extraction is
    its arrays over a floor without LLVM's linker pages (see
    :func:`gatun_py._runtime.release_code_pages`; 90 MB of the 7.8 M-tet flange's peak), and
    no kernel loads in the middle of the stream. Nothing is done (0.0) when the tiny file is not
    there or not readable: the kernels then load when first used.

    Examples
    --------
    >>> load_kernels() >= 0.0
    True
    """
    t0 = time.perf_counter()
    decoder = source is None or isinstance(source, TetcReader) or (not isinstance(source, TetMesh) and is_tetc(source))
    if decoder:
        try:
            tiny = TetcReader(TINY_TETC)
            lo, hi = (float(x) for x in tiny.meta["scalar_range"])
        except (OSError, TetcError, KeyError, TypeError, ValueError):
            return 0.0
    else:
        tiny = jittered_grid((4, 4, 3), jitter=0.15)
        lo, hi = tiny.scalar_range
    release_code_pages()  # those our imports touched: the loading below then peaks lower
    # two isovalues and tiny rounds: the driver's every path (several extractors, rounds mid-stream)
    isosurface(tiny, values=[lo + 0.4 * (hi - lo), lo + 0.6 * (hi - lo)], ratio=0.5 if simplify else None,
               batch_faces=4)
    release_code_pages()
    return time.perf_counter() - t0


# -- the public verb -------------------------------------------------------------------------------

def _check_options(values, ratio, faces, batch_faces):
    vals = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if vals.size == 0:
        raise OptionError("give at least one isovalue")
    if not np.all(np.isfinite(vals)):
        raise OptionError("isovalues must be finite numbers (got NaN or infinity)")
    if ratio is not None and faces is not None:
        raise OptionError("give either ratio or faces, not both")
    if ratio is not None and not (isinstance(ratio, (int, float)) and 0.0 < ratio <= 1.0):
        raise OptionError(f"ratio must lie in (0, 1] (faces kept / faces extracted), got {ratio}")
    if faces is not None and not (isinstance(faces, (int, np.integer)) and faces >= 1):
        raise OptionError(f"faces must be a positive integer, got {faces}")
    if not (isinstance(batch_faces, (int, np.integer)) and batch_faces >= 1):
        raise OptionError(f"batch_faces must be a positive integer, got {batch_faces}")
    if ratio == 1.0:
        ratio = None
    return [float(v) for v in vals], ratio


def isosurface(source, *, values, ratio: float | None = None, faces: int | None = None,
               batch_faces: int = DEFAULT_BATCH_FACES, level: int | None = None, ratio_mesh: float | None = None,
               importance_tf=None, read_kwargs: dict | None = None, jobs: int | None = None, progress=None,
               check=None) -> Surface:
    """Extract (and simplify on the fly) the isosurfaces of a tet mesh, streaming.

    Parameters
    ----------
    source : path, TetcReader or TetMesh
        A ``.tetc`` file (decoded in a stream), any mesh file :func:`gatun_py.mesh.read_mesh` reads,
        or an in-memory mesh. Of a bricked ``.tetc`` file, only the bricks whose stored scalar
        range contains an isovalue are decoded, on ``jobs`` threads (:mod:`.bricked`); the surface
        is the one of the whole mesh.
    values : float or sequence of float
        Isovalues (finite).
    ratio : float in (0, 1], optional
        Faces kept / faces extracted. 1 or None (and no ``faces``): the exact surface.
    faces : int, optional
        Target face count instead of ``ratio`` (per isovalue).
    batch_faces : int
        Run a round of QEM collapses after every this many new faces (Hou & Chen's B).
    level, ratio_mesh : optional, ``.tetc`` only
        Extract from a stored level, or from the mesh simplified on the fly to this ratio (merged /
        all vertices, as ``tetc render --ratio``); the tet mesh stays conforming, so the surface
        has no cracks.
    importance_tf : path, dict or ImportanceFunction, optional
        Importance over the gradient magnitude at the surface (:func:`load_importance`).
    read_kwargs : dict, optional
        Passed to :func:`gatun_py.mesh.read_mesh` for a mesh file.
    jobs : int, optional
        Bricks decoded at once, for a bricked file (default: all cores). The surface does not
        depend on it.
    progress : callable, optional
        Called with the number of tets processed so far.
    check : callable, optional
        Test hook: called after every round with the edge keys (a << 32 | b) of the surface
        vertices its collapses removed or moved, and the number of tets streamed so far.

    Returns
    -------
    Surface
        All isovalues in one surface; ``point_data["scalar"]`` tells them apart.

    Examples
    --------
    >>> from gatun_py.mesh import TetMesh
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    >>> mesh = TetMesh(pts, np.array([0, 1, 0, 0], np.float32), np.array([[0, 1, 2, 3]], np.int32))
    >>> s = isosurface(mesh, values=0.5)
    >>> s.n_triangles, s.points[:, 0].tolist()
    (1, [0.5, 0.5, 0.5])
    """
    vals, ratio = _check_options(values, ratio, faces, batch_faces)
    jobs = check_jobs(jobs)
    imp = load_importance(importance_tf) if importance_tf is not None else None
    decoder = isinstance(source, TetcReader) or (not isinstance(source, TetMesh) and is_tetc(source))
    _announce_compiling((["decoder"] if decoder else []) + ["isosurface"])
    t_start = time.perf_counter()
    stream, info = _open_stream(source, level=level, ratio_mesh=ratio_mesh, read_kwargs=read_kwargs, values=vals,
                                jobs=jobs)
    try:
        return _extract(stream, info, vals, ratio=ratio, faces=faces, batch_faces=batch_faces, imp=imp, check=check,
                        progress=progress, t_start=t_start)
    finally:
        if isinstance(stream, BrickedStream):
            stream.close()  # its decoding threads stop if the extraction failed


def _extract(stream, info, vals, *, ratio, faces, batch_faces, imp, check, progress, t_start) -> Surface:
    """The driver of :func:`isosurface` over an opened stream (``imp``: the importance function or None)."""
    lo, hi, (smin, smax) = info["bbox_lo"], info["bbox_hi"], info["scalar_range"]
    diag = float(np.linalg.norm(np.asarray(hi, float) - np.asarray(lo, float)))
    grad_scale = diag / (smax - smin) if smax > smin else 1.0
    inside = [v for v in vals if smin <= v <= smax]
    extractors = [_Extractor(v, ratio=ratio, faces=faces, batch_faces=batch_faces, importance=imp,
                             grad_scale=grad_scale, check=check, expected_tets=info.get("tets")) for v in inside]
    n = int(info["points"])
    isos = [np.float64(e.iso) for e in extractors]
    sieve = None  # _SurfaceTets, made with the first batch (the vertex array's length is known then)
    # x, y, z, scalar of every vertex streamed so far: the decoder's own array when it offers one
    # (a .tetc stream: no copy of O(vertices)), else ours, filled batch by batch
    shared = info.get("shared_values")
    vdata = None
    boundary_override = info.get("boundary")
    band = []
    first_batch = True
    tets_done = 0
    n_batches = 0
    wait_s = 0.0

    def work(vdata, tets, chunk_ends, batch_len, bnd, before, decoded_s, batch_no):
        rounds = sum(e.rounds for e in extractors)
        for ex in extractors:
            ex.add(vdata, tets, bnd, before, batch_len=batch_len, chunk_ends=chunk_ends)
        if batch_no == RELEASE_CODE_AFTER or (rounds == 0 and any(e.rounds for e in extractors)):
            release_code_pages()
        done = before + batch_len
        if extractors and (batch_len or len(bnd)):
            band.append({"tets": done, "decoded_s": round(decoded_s, 4),
                         "t_s": round(time.perf_counter() - t_start, 4), "rounds": sum(e.rounds for e in extractors),
                         "faces_extracted": sum(e.extracted for e in extractors),
                         "faces": sum(e.nt for e in extractors),
                         "locked": sum(e.locked for e in extractors),
                         "vertices": sum(e.nv for e in extractors),
                         "border_faces": sum(int(e.sizes[0]) for e in extractors),
                         "rss_mb": round(rss_mb(), 1), "peak_rss_mb": round(peak_rss_mb(), 1)})
        return done

    # Extraction and collapses run in a worker thread (their kernels release the GIL) while the
    # decoder produces the next batches: the stages overlap on two cores. At most MAX_IN_FLIGHT
    # batches wait for the worker (a round of collapses takes as long as decoding ~10 batches,
    # and the decoder should not stall on it), so memory stays bounded (~1 MB of tets each); the
    # worker reads only vertices of batches already stored, the main thread writes only the new
    # batch's.
    in_flight = collections.deque()
    with ThreadPoolExecutor(max_workers=1) as pool:
        t_wait = time.perf_counter()
        for batch in stream:
            decoded_s = time.perf_counter() - t_start
            wait_s += time.perf_counter() - t_wait
            if shared is not None:
                vdata = shared.values  # the batch's vertices are already there
            else:
                if vdata is None:
                    vdata = np.empty((n, 4), np.float32)
                k = len(batch.points)
                vdata[batch.first:batch.first + k, :3] = batch.points
                vdata[batch.first:batch.first + k, 3] = batch.density
            if boundary_override is not None:  # simplified start: the whole boundary with the first batch
                bnd = boundary_override if first_batch else np.zeros((0, 3), np.int32)
            else:
                bnd = batch.boundary
            first_batch = False
            # only the tets the surfaces cut wait for the worker (a few per cent of them; a new
            # array, so the worker owns its input even if a producer reuses its buffers)
            batch_len = len(batch.tets)
            if sieve is None:
                sieve = _SurfaceTets(len(vdata), isos)
            tets, chunk_ends = sieve(vdata[:, 3], batch.tets)
            bnd = np.array(bnd, dtype=np.int32, order="C", copy=True)
            n_batches += 1
            in_flight.append(pool.submit(work, vdata, tets, chunk_ends, batch_len, bnd, tets_done, decoded_s,
                                         n_batches))
            tets_done += batch_len
            if n_batches % TRIM_EVERY == 0:
                trim_heap()
            while len(in_flight) > MAX_IN_FLIGHT:
                done = in_flight.popleft().result()  # re-raises the worker's exception here
                if progress is not None:
                    progress(done)
            t_wait = time.perf_counter()
        while in_flight:
            done = in_flight.popleft().result()
            if progress is not None:
                progress(done)
    parts = [ex.finish() for ex in extractors]
    off = 0
    pts_all, tris_all, data_all = [], [], {}
    for p, t, d in parts:
        pts_all.append(p)
        tris_all.append(t + off)
        off += len(p)
        for name, arr in d.items():
            data_all.setdefault(name, []).append(arr)
    if parts:
        surf_pts = np.concatenate(pts_all)
        surf_tris = np.concatenate(tris_all).astype(np.int32)
        point_data = {name: np.concatenate(a) for name, a in data_all.items()}
    else:
        surf_pts, surf_tris = np.zeros((0, 3)), np.zeros((0, 3), np.int32)
        point_data = {"scalar": np.zeros(0, np.float32), "gradient_magnitude": np.zeros(0, np.float32)}
    stats = {
        "values": vals, "values_outside_range": [v for v in vals if v not in inside],
        "scalar_range": [float(smin), float(smax)], "tets": tets_done,
        "bbox": [np.asarray(lo, float).tolist(), np.asarray(hi, float).tolist()],
        "faces_extracted": sum(e.extracted for e in extractors), "faces": int(len(surf_tris)),
        "peak_faces": sum(e.peak_faces for e in extractors),
        "peak_locked": max((b["locked"] for b in band), default=0),
        "locked_at_end": sum(e.locked_at_end for e in extractors),
        "rounds": sum(e.rounds for e in extractors), "collapses": sum(e.collapses for e in extractors),
        "decode_s": wait_s, "extract_s": sum(e.extract_s for e in extractors),
        "qem_s": sum(e.qem_s for e in extractors), "total_s": time.perf_counter() - t_start,
        "level": info.get("level", 0), "mesh_ratio": info.get("mesh_ratio", 0.0),
        "peak_rss_mb": peak_rss_mb(), "band": band,
    }
    if isinstance(stream, BrickedStream):
        stats["bricks"] = stream.stats
    return Surface(surf_pts, surf_tris, point_data, stats)


class _SurfaceTets:
    """Picks the tets of a batch that an isosurface cuts, and counts them per chunk (``_Extractor.add``).

    A tet is cut by the surface at ``iso`` when its corners are not all on one side (above: s >=
    iso, as :func:`.marching.extract_batch` classifies them) or a corner lies on it. Every other
    tet is one ``extract_batch`` passes over (it adds no triangle and none of its faces touches the
    surface, so it changes no lock): it is left out here, in the decoding thread, instead of
    waiting with its batch for the extraction thread (~97 % of the tets on the flange, and of the
    memory of the batches waiting while a round of collapses runs).

    Each vertex gets a byte per four isovalues, two bits each (above, on), once, when a tet first
    names it (vertex ids follow the stream, so every id below a named one has its values); a tet's
    four bytes are then one uint32, read in one gather instead of four scalars from the strided
    (n, 4) array.
    """

    _ABOVE = np.uint32(0x01010101)

    def __init__(self, n_points: int, isos):
        self.groups = [list(isos[i:i + 4]) for i in range(0, len(isos), 4)]
        self.codes = np.zeros((len(self.groups), n_points), np.uint8)
        self.coded = 0  # vertices 0 .. coded - 1 have their bytes

    def __call__(self, scalar, tets) -> tuple[np.ndarray, np.ndarray]:
        """(the cut tets, ``chunk_ends``: how many of them lie in the first i + 1 chunks of
        ``CHUNK_TETS`` tets of the batch)."""
        tets = np.ascontiguousarray(tets, dtype=np.int32)
        n = len(tets)
        keep = np.zeros(n, np.bool_)
        if n and self.groups:
            top = int(tets.max()) + 1
            if top > self.coded:
                s = scalar[self.coded:top]
                for code, group in zip(self.codes, self.groups):
                    for j, iso in enumerate(group):  # float64 isovalue: compared in float64, as the kernel
                        code[self.coded:top] |= ((s >= iso).view(np.uint8) << (2 * j)) | ((s == iso).view(np.uint8)
                                                                                        << (2 * j + 1))
                self.coded = top
            for code, group in zip(self.codes, self.groups):
                word = code[tets].view(np.uint32).ravel()  # the tet's four corners' bytes
                for j in range(len(group)):
                    above = word & (self._ABOVE << np.uint32(2 * j))
                    keep |= ((word & (self._ABOVE << np.uint32(2 * j + 1))) != 0) | (
                        (above != 0) & (above != (self._ABOVE << np.uint32(2 * j))))
        kept = tets[keep]
        last = np.minimum(np.arange(1, -(-n // CHUNK_TETS) + 1) * CHUNK_TETS, n) - 1
        return kept, np.cumsum(keep)[last] if n else np.zeros(0, np.int64)


_NO_SCALAR_MESSAGE = "the mesh has no scalar (it came without point data): there is no field to extract an isosurface of"


def _open_stream(source, *, level, ratio_mesh, read_kwargs, values=(), jobs=1):
    """(batches, info) for any source; info has points, bbox_lo/hi, scalar_range and, for a
    simplified start, the boundary of the simplified mesh (see below). ``values`` and ``jobs``
    choose and decode the bricks of a bricked file."""
    if isinstance(getattr(source, "reader", None), TetcReader):  # an open gatun_py.TetcFile
        source = source.reader
    if isinstance(source, TetMesh) or (not isinstance(source, TetcReader) and not is_tetc(source)):
        if level is not None or ratio_mesh is not None:
            raise OptionError("level and ratio_mesh need a .tetc file (a mesh file has no merge forest)")
        mesh = source if isinstance(source, TetMesh) else read_mesh(source, **(read_kwargs or {}))[0]
        if not mesh.has_scalar:
            raise OptionError(_NO_SCALAR_MESSAGE)
        lo, hi = mesh.bbox
        info = {"points": mesh.n_points, "bbox_lo": lo, "bbox_hi": hi, "scalar_range": mesh.scalar_range,
                "tets": mesh.n_tets}
        return mesh_batches(mesh), info
    reader = source if isinstance(source, TetcReader) else TetcReader(source)
    if (read_kwargs or {}).get("time_step") is not None:  # a step of a time series
        reader = StepDecoder(reader).reader(read_kwargs["time_step"])
    if not reader.has_scalar:
        raise OptionError(_NO_SCALAR_MESSAGE)
    if reader.n_bricks > 1:
        return _open_bricked(reader, level=level, ratio_mesh=ratio_mesh, values=values, jobs=jobs)
    target = resolve_target(reader, ratio=ratio_mesh, level=level)
    lv = reader.level_meta(target.level)
    lo, hi, rng = _file_box_and_range(reader)
    info = {"points": int(lv["points"]), "bbox_lo": lo, "bbox_hi": hi, "scalar_range": rng,
            "level": target.level, "mesh_ratio": target.ratio}
    batches = PrefetchedDecode(reader, target.level, depth=PREFETCH_DEPTH)
    anc = target_ancestors(reader, target)
    if anc is None:
        info["shared_values"] = batches
        info["tets"] = int(lv["tets"])  # (a simplified start streams fewer, not known beforehand)
        return batches, info
    # The filter parks boundary faces until their ancestors arrive, but the lock test needs the
    # whole boundary up front. Boundary vertices merge only into boundary vertices, so the first
    # batch (all boundary vertices) already has every ancestor: map its faces ourselves.
    stream = iter(batches)
    first = next(stream)
    f = anc[first.boundary]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    info["boundary"] = np.ascontiguousarray(f[keep], dtype=np.int32)

    def chained():
        yield first
        yield from stream

    return SimplifyFilter(anc).filter(chained()), info


def _file_box_and_range(reader: TetcReader):
    try:
        lo, hi = (np.asarray(x, np.float64).reshape(3) for x in reader.meta["bbox"])
        rng = tuple(float(x) for x in np.asarray(reader.meta["scalar_range"], np.float64).reshape(2))
    except (KeyError, TypeError, ValueError):
        raise CorruptFileError("corrupt metadata: bad bounding box or scalar range") from None
    return lo, hi, rng


def _open_bricked(reader: TetcReader, *, level, ratio_mesh, values, jobs):
    """(stream, info) of a bricked file: the bricks an isovalue inside the file's range cuts."""
    if ratio_mesh is not None:
        raise OptionError("simplifying the tet mesh on the fly (ratio_mesh, --mesh-ratio) is not supported on a "
                          "bricked file; start from a stored level instead (level, --level)")
    lo, hi, rng = _file_box_and_range(reader)
    inside = [v for v in values if rng[0] <= v <= rng[1]]
    stream = BrickedStream(reader, values=inside, level=0 if level is None else level, jobs=jobs)
    info = {"points": len(stream.values), "bbox_lo": lo, "bbox_hi": hi, "scalar_range": rng,
            "level": stream.level, "mesh_ratio": 0.0, "shared_values": stream, "tets": stream.stats["tets"]}
    return stream, info


