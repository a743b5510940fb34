"""Render bricks on a Dask cluster: bricks resident on workers, fragments composited by direct send.

:class:`BrickCluster` connects to a scheduler (``tcp://HOST:PORT``) or starts a ``LocalCluster`` of
worker processes, then :meth:`BrickCluster.load` puts every brick on one worker (interleaved in k-d
order, or balanced by tets) where it stays, decoded, for every frame that follows. A frame is one
task per worker (render the fragments of the bricks it holds, cut into one row band per worker)
and one task per band on its worker (composite the band from every worker's fragments, in brick
order); the client receives only the bands' rows. There is no root: compositing is split like the
rendering. Between frames a brick may move to another worker, when the render times measured so
far say that evens out the workers (the image does not change: it does not depend on where a
brick was drawn). A series of frames (views of an orbit, or time steps) is submitted a few frames
ahead and each frame is handed back as soon as it is complete, in order.

With a budget (bricks loaded with ``budget=True``) the workers keep each brick's compressed
reader, and every frame each brick renders at the level and ratio the client planned for it
(:class:`~gatun_py.pipeline.sortlast.BrickBudget`).

Resilience is Dask's: a brick is loaded by a task (from its file, or from the mesh the task
carries), so when a worker dies the scheduler loads its bricks again on the others and reruns the
frame's tasks there; a task that keeps failing fails the frame with :class:`ClusterError`, and no
image is returned for it.

Workers compile nothing they can load: a ``LocalCluster``'s workers get this process's
``NUMBA_CACHE_DIR`` (numba's cache is keyed by source file and CPU, so workers of the same install
share it); on a real cluster, start the workers with ``NUMBA_CACHE_DIR`` on a shared folder.

``dask[distributed]`` is optional (``pip install gatun_py[dask]``) and imported only here, only
when a cluster is made.
"""

from __future__ import annotations

import os
import time
from collections import deque
from dataclasses import dataclass

from ..codec import TetcReader
from ..errors import OptionError, TetcError
from ..mesh import TetMesh
from ..raycast.composite import row_bands, split_rows
from .sortlast import (BrickBudget, BrickRef, FrameSetup, brick_tets, composite_rows, frame_setup, join_rows,
                       load_brick_kernels, open_brick, place, render_brick, shared_rays)

__all__ = ["BrickCluster", "ClusterError", "FrameOutcome"]

CONNECT_TIMEOUT_S = 10.0
FRAMES_AHEAD = 2  # frames submitted beyond the one being waited for
# a brick moves to another worker when that shortens the slowest worker's frame by this share of the
# mean (a move costs its transfer; smaller gains are noise)
REBALANCE_GAIN = 0.05
# weight of the newest frame in each brick's smoothed render time (the rest: the frames before), so
# that one noisy frame does not move bricks back and forth
TIME_SMOOTHING = 0.5


class ClusterError(TetcError, OSError):
    """The cluster cannot be reached, or a frame failed on it."""


def _distributed():
    """``dask.distributed``, imported on first use (an optional dependency)."""
    try:
        import distributed  # optional dependency: only for --workers / --scheduler
    except ImportError:
        raise OptionError("rendering on a cluster needs Dask: pip install 'dask[distributed]' (or pip install "
                          "'gatun_py[dask]'; in a checkout: pip install '.[dask]')") from None
    return distributed


# -- what runs on the workers (module-level functions: pickled by reference) -------------------------

def _load_brick(source, keep_reader: bool = False):
    """A brick kept in a worker's memory: a mesh as it is, a file's brick decoded once (or, with
    ``keep_reader``, its reader: a budget picks the level and ratio frame by frame)."""
    if isinstance(source, TetMesh):
        return source
    if isinstance(source, BrickRef):
        reader = open_brick(source)
        return reader if keep_reader else reader.decode_mesh(source.level)
    reader = TetcReader(source)
    return reader if keep_reader else reader.decode_mesh(0)


def _keep(brick):
    """The brick itself: a task that moves a resident brick to the worker it runs on."""
    return brick


def _render_on_worker(setup: FrameSetup, bands, indices, targets, *bricks):
    """Every brick a worker holds, rendered in turn, their fragments cut into the frame's row bands.

    Returns ``(per band: [(brick index, Fragments)], per brick: stats)``; the stats carry each
    brick's render time, which places the bricks for the frames that follow.
    """
    out = [[] for _ in bands]
    stats = []
    setup = shared_rays(setup)
    for i, target, brick in zip(indices, targets, bricks):
        frags, st = render_brick(brick, setup, target=target)
        st["brick"] = i
        stats.append(st)
        for j, part in enumerate(split_rows(frags, bands)):
            out[j].append((i, part))
    return out, stats


def _composite_on_worker(band: int, rows, with_stats: bool, *parts):
    """One row band of the frame from every worker's fragments, blended in brick order (the same
    order whichever worker rendered which brick): ``(image rows, stats or None)``."""
    pieces = sorted((p for part in parts for p in part[0][band]), key=lambda p: p[0])
    stats = sorted((s for part in parts for s in part[1]), key=lambda s: s["brick"]) if with_stats else None
    return composite_rows(rows, [f for _, f in pieces], stats)


@dataclass
class FrameOutcome:
    """One frame of a series: its index, and the result (a PipelineResult) or the error."""

    index: int
    result: object = None
    error: BaseException | None = None


class BrickCluster:
    """A Dask cluster holding bricks, rendering frames from them.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler, ``tcp://HOST:PORT``.
    workers : int, optional
        Start a ``LocalCluster`` of this many worker processes (when no ``scheduler`` is given;
        default 2).
    threads_per_worker : int, optional
        Numba threads in each local worker; default the cores shared out among the workers.
    timeout : float
        Seconds to wait for the scheduler (and for local workers to start).
    log : callable, optional
        Receives one-line notes.
    bands : int, optional
        Row bands a frame is composited in, each on its own worker (default one per worker holding
        bricks: direct send; 1: all fragments to one worker, as a root would).
    move_bricks : bool
        Move bricks between frames to even out the workers' measured render times (default).

    Examples
    --------
    The whole round trip (skipped where Dask is not installed):

    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> from gatun_py.pipeline.sortlast import split_for_render
    >>> from gatun_py.pipeline.stream import View
    >>> from gatun_py.raycast.camera import Camera
    >>> bricks, extent = split_for_render(jittered_grid((5, 5, 5), jitter=0.2), 4)
    >>> with BrickCluster(workers=2) as cluster:  # doctest: +SKIP
    ...     cluster.load(bricks)
    ...     res = cluster.render(View(Camera(16, 16)), extent)
    >>> res.image.shape  # doctest: +SKIP
    (16, 16, 4)
    """

    def __init__(self, *, scheduler: str | None = None, workers: int | None = None,
                 threads_per_worker: int | None = None, timeout: float = CONNECT_TIMEOUT_S, log=None,
                 bands: int | None = None, move_bricks: bool = True):
        dd = _distributed()
        self._log = log or (lambda _m: None)
        if bands is not None and not (isinstance(bands, int) and bands >= 1):
            raise OptionError(f"bands must be a whole number >= 1, got {bands!r}")
        self.bands = bands
        self.move_bricks = bool(move_bricks)
        self._cluster = None
        self._bricks = []  # futures of the resident bricks
        self._brick_worker = []
        self._sources = []
        self._planner = None
        self._budget_ready = False
        self._brick_s = None
        self.moves = 0
        if scheduler is not None and workers is not None:
            raise OptionError("give either a scheduler address or a number of local workers, not both")
        if workers is not None and not (isinstance(workers, int) and workers >= 1):
            raise OptionError(f"the number of workers must be a whole number >= 1, got {workers!r}")
        try:
            if scheduler is not None:
                self.client = dd.Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
            else:
                n = workers or 2
                cores = os.cpu_count() or 1
                threads = threads_per_worker or max(1, cores // n)
                env = {"NUMBA_NUM_THREADS": str(threads)}
                cache = _numba_cache_dir()
                if cache:
                    env["NUMBA_CACHE_DIR"] = cache
                self._cluster = dd.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                dashboard_address=None, host="127.0.0.1", env=env,
                                                silence_logs=40)
                self.client = dd.Client(self._cluster, timeout=f"{timeout}s", set_as_default=False)
        except (OSError, TimeoutError) as e:
            self.close()
            where = scheduler or "a local cluster"
            raise ClusterError(f"cannot reach {where} within {timeout:g} s: {e}") from None
        self.timeout = float(timeout)
        # every worker loads the kernels from numba's cache now, not in the first frame (and a
        # worker joining later loads them with its first brick)
        self.client.run(load_brick_kernels)

    # -- lifetime ----------------------------------------------------------------------------------
    def close(self) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        n = len(self.workers) if getattr(self, "client", None) is not None else 0
        return f"BrickCluster({n} workers, {len(self._bricks)} bricks)"

    @property
    def workers(self) -> list[str]:
        return sorted(self.client.scheduler_info()["workers"])

    # -- bricks ------------------------------------------------------------------------------------
    def load(self, sources, *, budget: bool = False) -> list[list[int]]:
        """Put every brick on a worker (interleaved in k-d order, or balanced by tets: :func:`place`)
        and keep it there; returns each worker's bricks.

        ``sources``: TetMeshes, :class:`BrickRef`\\ s or ``.tetc`` paths (one brick each). A path
        must be readable by the workers (a shared folder on a real cluster), and by this process
        with ``budget``: then the workers keep each brick's reader rather than its decoded mesh,
        and every frame each brick picks its own level and ratio (``render(..., budget=)``).
        """
        workers = self.workers
        if not workers:
            raise ClusterError("the cluster has no workers")
        sources = [s if isinstance(s, (TetMesh, BrickRef)) else BrickRef(os.fspath(s)) for s in sources]
        if not sources:
            raise OptionError("no bricks to load")
        if budget and any(isinstance(s, TetMesh) for s in sources):
            raise OptionError("a frame-time budget needs .tetc bricks (tetc compress --bricks K): each brick "
                              "picks one of its stored levels")
        bins = place([brick_tets(s) for s in sources], len(workers))
        where = [None] * len(sources)
        for w, idx in zip(workers, bins):
            for i in idx:
                where[i] = w
        self._sources = sources
        self._brick_worker = where
        self._budget_ready = bool(budget)
        self._planner = BrickBudget([open_brick(s) for s in sources]) if budget else None
        self._brick_s = None  # each brick's last measured render time (places the bricks)
        # allow_other_workers: when a worker dies, its bricks load again elsewhere
        self._bricks = [self.client.submit(_load_brick, s, bool(budget), workers=[w], allow_other_workers=True,
                                           pure=False, key=f"tetc-brick-{i}-{id(self)}-{time.monotonic_ns()}")
                        for i, (s, w) in enumerate(zip(sources, where))]
        self._wait(self._bricks, "loading the bricks")
        return bins

    def placement(self) -> list[list[int]]:
        """Each worker's bricks now (they move between frames to even out the measured render times)."""
        return [[i for i, x in enumerate(self._brick_worker) if x == w] for w in self.workers]

    def _observe(self, brick_s) -> None:
        """Fold one frame's per-brick render times into the smoothed ones."""
        if not brick_s or len(brick_s) != len(self._bricks):
            return
        if self._brick_s is None:
            self._brick_s = [float(t) for t in brick_s]
        else:
            self._brick_s = [TIME_SMOOTHING * float(t) + (1.0 - TIME_SMOOTHING) * old if old > 0 else float(t)
                             for t, old in zip(brick_s, self._brick_s)]

    def _rebalance(self) -> None:
        """Move at most one brick, from the worker whose bricks took longest (smoothed render times of
        the frames so far) to the quickest, when that shortens the longest by more than
        ``REBALANCE_GAIN`` of the mean.

        Deterministic (it depends only on the measured times) and without effect on the image: the
        bands composite the fragments in brick order, whichever worker made them. The brick moves
        as Dask data (its boundary faces with it); the old copy is freed, so a worker's memory
        stays that of the bricks it holds.
        """
        times = self._brick_s
        if times is None or not self.move_bricks:
            return
        workers = self.workers
        load = {w: 0.0 for w in workers}
        for i, w in enumerate(self._brick_worker):
            load[w] = load.get(w, 0.0) + times[i]
        hi = max(load, key=lambda w: (load[w], w))
        lo = min(load, key=lambda w: (load[w], w))
        if hi == lo:
            return
        best, best_max = None, load[hi]
        for i, w in enumerate(self._brick_worker):
            if w != hi:
                continue
            new_max = max(load[hi] - times[i], load[lo] + times[i])
            if new_max < best_max - 1e-12:
                best, best_max = i, new_max
        total = sum(load.values())
        if best is None or load[hi] - best_max < REBALANCE_GAIN * max(total / len(workers), 1e-9):
            return
        old = self._bricks[best]
        self._bricks[best] = self.client.submit(_keep, old, workers=[lo], allow_other_workers=True, pure=False,
                                                key=f"tetc-brick-{best}-{id(self)}-{time.monotonic_ns()}")
        self._brick_worker[best] = lo
        self.moves += 1
        self._log(f"brick {best} moved to {lo} (last frame: {load[hi]:.3f} s against {load[lo]:.3f} s)")

    # -- frames ------------------------------------------------------------------------------------
    def _submit_frame(self, setup: FrameSetup, targets=None):
        """One frame's tasks: a render task per worker over the bricks it holds (their fragments cut
        into one row band per worker), then on every worker the compositing of its band from all
        the workers' fragments (direct send: no root composites the whole frame)."""
        c = self.client
        by_worker = {}
        for i, w in enumerate(self._brick_worker):
            by_worker.setdefault(w, []).append(i)
        owners = sorted(by_worker)
        bands = row_bands(setup.camera.height, min(self.bands or len(owners), len(owners)))
        targets = targets or [None] * len(self._bricks)
        parts = [c.submit(_render_on_worker, setup, bands, idx, [targets[i] for i in idx],
                          *[self._bricks[i] for i in idx], workers=[w], allow_other_workers=True, pure=False)
                 for w, idx in ((w, by_worker[w]) for w in owners)]
        return [c.submit(_composite_on_worker, j, band, j == 0, *parts, workers=[owners[j]], allow_other_workers=True,
                         pure=False) for j, band in enumerate(bands)]

    def _wait(self, futures, what):
        dd = _distributed()
        try:
            return self.client.gather(futures)
        except dd.KilledWorker as e:
            raise ClusterError(f"{what} failed: workers kept dying ({e})") from None
        except (OSError, TimeoutError) as e:
            raise ClusterError(f"{what} failed: lost the cluster ({e})") from None

    def render(self, view, extent, *, budget: float | None = None):
        """One frame: every brick's fragments composited. Returns a PipelineResult."""
        return next(iter(self.render_series([view], extent, budget=budget)))

    def _targets(self, setup, view, budget):
        """Each brick's level and ratio for a frame of ``budget`` seconds: the budget is shared out
        among the bricks a worker renders one after another (workers run side by side)."""
        if budget is None:
            return None
        if not self._budget_ready:
            raise OptionError("a frame-time budget needs the bricks loaded with load(..., budget=True)")
        return self._planner.targets(setup, view, budget, groups=[g for g in self.placement() if g])

    def render_series(self, views, extent, *, ahead: int = FRAMES_AHEAD, budget: float | None = None):
        """Render ``views`` (View objects) in order, yielding each frame's PipelineResult as it completes.

        A few frames are in flight at once (``ahead``), so workers start the next frame while the
        client writes this one. Between frames, bricks move between workers to even out the
        render times measured in the last frame that came back. ``budget``: seconds per frame,
        each brick at the level and ratio it can afford (bricks loaded with ``budget=True``).
        """
        if not self._bricks:
            raise OptionError("no bricks loaded: call load() first")
        pending = deque()
        views = iter(views)
        exhausted = False
        while True:
            while not exhausted and len(pending) <= ahead:
                try:
                    view = next(views)
                except StopIteration:
                    exhausted = True
                    break
                setup, notes = frame_setup(view, extent)
                self._rebalance()
                targets = self._targets(setup, view, budget)
                pending.append((self._submit_frame(setup, targets), notes, setup, time.perf_counter()))
            if not pending:
                return
            futs, notes, setup, t0 = pending.popleft()
            res = join_rows(self._wait(futs, "the frame"), setup.camera.width)
            self._observe(res.stats.pop("brick_s", None))
            per_brick = res.stats.pop("per_brick", None)
            if self._planner is not None and budget is not None and per_brick:
                self._planner.observe(per_brick)
            res.stats.update(notes=notes, step=setup.step, mode=setup.mode, frame_s=time.perf_counter() - t0,
                             workers=len(self.workers), brick_moves=self.moves)
            yield res


def _numba_cache_dir() -> str | None:
    """The numba cache folder workers should share: NUMBA_CACHE_DIR if set (else numba's default,
    beside the installed sources, which local workers find by themselves)."""
    return os.environ.get("NUMBA_CACHE_DIR") or None
