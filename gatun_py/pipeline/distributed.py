"""Render bricks on a Dask cluster: bricks resident on workers, fragments composited by a tree reduction.

:class:`BrickCluster` connects to a scheduler (``tcp://HOST:PORT``) or starts a ``LocalCluster`` of
worker processes, then :meth:`BrickCluster.load` puts every brick on one worker (balanced by tets)
where it stays, decoded, for every frame that follows. A frame is one task per worker (render the
fragments of the bricks it holds), a binary tree of merge tasks between workers, and one
composite task at the root; the client receives only the image. A series of frames (views of an
orbit, or time steps) is submitted a few frames ahead and each frame is handed back as soon as it
is complete, in order.

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
from ..render.composite import merge_fragments
from .sortlast import (BrickRef, FrameSetup, balance, brick_tets, composite_frame, frame_setup, load_brick_kernels,
                     open_brick, render_brick)

__all__ = ["BrickCluster", "ClusterError", "FrameOutcome"]

CONNECT_TIMEOUT_S = 10.0
FRAMES_AHEAD = 2  # frames submitted beyond the one being waited for


class ClusterError(TetcError, OSError):
    """The cluster cannot be reached, or a frame failed on it."""


def _distributed():
    """``dask.distributed``, imported on first use (an optional dependency)."""
    try:
        import distributed  # optional dependency: only for --workers / --scheduler
    except ImportError:
        raise OptionError("rendering on a cluster needs Dask: pip install 'gatun_py[dask]' "
                          "(dask[distributed])") from None
    return distributed


# -- what runs on the workers (module-level functions: pickled by reference) -------------------------

def _load_brick(source):
    """A brick kept in a worker's memory: a mesh as it is, a file's brick decoded once."""
    if isinstance(source, TetMesh):
        return source
    if isinstance(source, BrickRef):
        return open_brick(source).decode_mesh(source.level)
    return TetcReader(source).decode_mesh(0)


def _render_on_worker(setup: FrameSetup, *meshes):
    """Every brick a worker holds, rendered in turn; their fragments in one (one message to send)."""
    parts = [render_brick(m, setup) for m in meshes]
    return merge_fragments(*[p[0] for p in parts]), [p[1] for p in parts]


def _merge_on_worker(*parts):
    frags = [p[0] for p in parts]
    stats = [s for p in parts for s in (p[1] if isinstance(p[1], list) else [p[1]])]
    return merge_fragments(*frags), stats


def _composite_on_worker(part):
    frags, stats = part
    stats = stats if isinstance(stats, list) else [stats]
    return composite_frame([frags], stats)


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

    Examples
    --------
    The whole round trip (skipped where Dask is not installed):

    >>> from gatun_py.mesh.synthetic import jittered_grid
    >>> from gatun_py.pipeline.sortlast import split_for_render
    >>> from gatun_py.pipeline.stream import View
    >>> from gatun_py.render.camera import Camera
    >>> bricks, extent = split_for_render(jittered_grid((5, 5, 5), jitter=0.2), 4)
    >>> with BrickCluster(workers=2) as cluster:  # doctest: +SKIP
    ...     cluster.load(bricks)
    ...     res = cluster.render(View(Camera(16, 16)), extent)
    >>> res.image.shape  # doctest: +SKIP
    (16, 16, 4)
    """

    def __init__(self, *, scheduler: str | None = None, workers: int | None = None,
                 threads_per_worker: int | None = None, timeout: float = CONNECT_TIMEOUT_S, log=None):
        dd = _distributed()
        self._log = log or (lambda _m: None)
        self._cluster = None
        self._bricks = []  # futures of the resident bricks
        self._brick_worker = []
        self._sources = []
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
    def load(self, sources) -> list[list[int]]:
        """Put every brick on a worker (balanced by tets) and keep it there; returns each worker's bricks.

        ``sources``: TetMeshes, :class:`BrickRef`\\ s or ``.tetc`` paths (one brick each). A path
        must be readable by the workers (a shared folder on a real cluster).
        """
        workers = self.workers
        if not workers:
            raise ClusterError("the cluster has no workers")
        sources = [s if isinstance(s, (TetMesh, BrickRef)) else BrickRef(os.fspath(s)) for s in sources]
        if not sources:
            raise OptionError("no bricks to load")
        bins = balance([brick_tets(s) for s in sources], len(workers))
        where = [None] * len(sources)
        for w, idx in zip(workers, bins):
            for i in idx:
                where[i] = w
        self._sources = sources
        self._brick_worker = where
        # allow_other_workers: when a worker dies, its bricks load again elsewhere
        self._bricks = [self.client.submit(_load_brick, s, workers=[w], allow_other_workers=True, pure=False,
                                           key=f"tetc-brick-{i}-{id(self)}-{time.monotonic_ns()}")
                        for i, (s, w) in enumerate(zip(sources, where))]
        self._wait(self._bricks, "loading the bricks")
        return bins

    # -- frames ------------------------------------------------------------------------------------
    def _submit_frame(self, setup: FrameSetup):
        c = self.client
        # one task per worker over the bricks it holds: a frame is a few large tasks, not one per brick
        by_worker = {}
        for b, w in zip(self._bricks, self._brick_worker):
            by_worker.setdefault(w, []).append(b)
        level = [c.submit(_render_on_worker, setup, *bricks, workers=[w], allow_other_workers=True, pure=False)
                 for w, bricks in by_worker.items()]
        # a binary tree of merges: log2(workers) rounds of fragment traffic between workers
        while len(level) > 1:
            nxt = [c.submit(_merge_on_worker, level[i], level[i + 1], pure=False) for i in range(0, len(level) - 1, 2)]
            if len(level) % 2:
                nxt.append(level[-1])
            level = nxt
        return c.submit(_composite_on_worker, level[0], pure=False)

    def _wait(self, futures, what):
        dd = _distributed()
        try:
            return self.client.gather(futures)
        except dd.KilledWorker as e:
            raise ClusterError(f"{what} failed: workers kept dying ({e})") from None
        except (OSError, TimeoutError) as e:
            raise ClusterError(f"{what} failed: lost the cluster ({e})") from None

    def render(self, view, extent):
        """One frame: every brick's fragments composited. Returns a PipelineResult."""
        return next(iter(self.render_series([view], extent)))

    def render_series(self, views, extent, *, ahead: int = FRAMES_AHEAD):
        """Render ``views`` (View objects) in order, yielding each frame's PipelineResult as it completes.

        A few frames are in flight at once (``ahead``), so workers start the next frame while the
        client writes this one.
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
                pending.append((self._submit_frame(setup), notes, setup, time.perf_counter()))
            if not pending:
                return
            fut, notes, setup, t0 = pending.popleft()
            res = self._wait(fut, "the frame")
            res.stats.update(notes=notes, step=setup.step, mode=setup.mode, frame_s=time.perf_counter() - t0,
                             workers=len(self.workers))
            yield res


def _numba_cache_dir() -> str | None:
    """The numba cache folder workers should share: NUMBA_CACHE_DIR if set (else numba's default,
    beside the installed sources, which local workers find by themselves)."""
    return os.environ.get("NUMBA_CACHE_DIR") or None
