"""Render a stream of :class:`~gatun_py.mesh.TetBatch`es: the loop the pipeline shares."""

from __future__ import annotations

import time

from .caster import RenderResult, StreamingRaycaster


def render_batches(batches, camera, tf, *, mode: str = "volume", step: float | None = None, scalar_range=None,
                   expected_tets: int | None = None, lean: bool = False, fragments: bool = False,
                   progress=None, partial=None, partial_every_s: float = 0.25, cull: bool = True,
                   terminate: bool = True) -> RenderResult:
    """Stream-render ``batches`` (objects with ``points``, ``density``, ``boundary``, ``tets``).

    Parameters
    ----------
    batches : iterable of TetBatch
        Vertices in id order; the whole boundary before the first tet.
    camera, tf, mode, step, scalar_range, expected_tets, lean, fragments, cull, terminate
        As for :class:`StreamingRaycaster`.
    progress : callable, optional
        Called with the number of tets of every batch once it is rendered.
    partial : callable, optional
        Called as ``partial(image, finished)`` with :meth:`StreamingRaycaster.snapshot` (the image so
        far and its pixels that are final) between batches, at most
        every ``partial_every_s`` seconds: a viewer shows the frame
        filling in while a long render streams.

    Returns
    -------
    RenderResult
        ``stats`` also holds ``decode_s`` (time spent waiting for batches) and ``batches``.
    """
    rc = StreamingRaycaster(camera, tf, mode=mode, step=step, scalar_range=scalar_range,
                            expected_tets=expected_tets, lean=lean, fragments=fragments, cull=cull,
                            terminate=terminate)
    decode_s = 0.0
    n_batches = 0
    last_partial = time.perf_counter()
    it = iter(batches)
    while True:
        t0 = time.perf_counter()
        try:
            b = next(it)
        except StopIteration:
            decode_s += time.perf_counter() - t0
            break
        decode_s += time.perf_counter() - t0
        n_batches += 1
        if len(b.points):
            rc.add_vertices(b.points, b.density)
        if len(b.boundary):
            rc.set_boundary(b.boundary)
        if len(b.tets):
            rc.add_tets(b.tets)
            if progress is not None:
                progress(len(b.tets))
            if partial is not None and time.perf_counter() - last_partial >= partial_every_s:
                partial(*rc.snapshot())
                last_partial = time.perf_counter()
    res = rc.finish()
    res.stats["decode_s"] = decode_s
    res.stats["batches"] = n_batches
    return res
