"""Render a stream of :class:`DecodeBatch`es: the loop the CLI and the pipeline share."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .raycast import RenderResult, StreamingRaycaster


@dataclass
class MeshBatch:
    """A DecodeBatch-shaped piece of an in-memory mesh (see ``docs/architecture.md``)."""

    first: int
    points: np.ndarray
    density: np.ndarray
    boundary: np.ndarray
    tets: np.ndarray


def mesh_batches(mesh, *, batch_tets: int = 65536, order=None):
    """Feed an in-memory mesh as batches: all vertices and the boundary first, then the tets.

    Parameters
    ----------
    mesh : TetMesh
    batch_tets : int
        Tets per batch.
    order : array of int, optional
        A permutation of the tets (default: file order).
    """
    no_tets = np.zeros((0, 4), np.int32)
    yield MeshBatch(0, mesh.points, mesh.density, mesh.boundary_faces(), no_tets)
    tets = mesh.tets if order is None else mesh.tets[np.asarray(order)]
    for i in range(0, len(tets), max(1, int(batch_tets))):
        yield MeshBatch(mesh.n_points, mesh.points[:0], mesh.density[:0], np.zeros((0, 3), np.int32),
                        tets[i:i + batch_tets])


def render_batches(batches, camera, tf, *, mode: str = "volume", step: float | None = None, scalar_range=None,
                   expected_tets: int | None = None, lean: bool = False, progress=None) -> RenderResult:
    """Stream-render ``batches`` (objects with ``points``, ``density``, ``boundary``, ``tets``).

    Parameters
    ----------
    batches : iterable of DecodeBatch
        Vertices in id order; the whole boundary before the first tet.
    camera, tf, mode, step, scalar_range, expected_tets, lean
        As for :class:`StreamingRaycaster`.
    progress : callable, optional
        Called with the number of tets of every batch once it is rendered.

    Returns
    -------
    RenderResult
        ``stats`` also holds ``decode_s`` (time spent waiting for batches) and ``batches``.
    """
    rc = StreamingRaycaster(camera, tf, mode=mode, step=step, scalar_range=scalar_range,
                            expected_tets=expected_tets, lean=lean)
    decode_s = 0.0
    n_batches = 0
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
    res = rc.finish()
    res.stats["decode_s"] = decode_s
    res.stats["batches"] = n_batches
    return res
