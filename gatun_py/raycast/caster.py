"""The object-space ray caster: streaming (tets in any order, as they arrive) and in-memory.

Both share one set of kernels (``_boundary``, ``_facetable``, ``_walk``): rays from the eye through every pixel are
intersected with the boundary surface and cut into segments (entry/exit pairs; several for
non-convex meshes and cavities). Each segment has a front subsegment walking from its entry face
along the ray and a back subsegment walking from its exit face toward the eye. A subsegment steps
through every tet that is present and otherwise waits, parked on the face where it stopped, until
the tet behind that face arrives; the face it waits on is its water mark, and the segment is done
when the two marks meet. Front subsegments composite front to back, back subsegments back to
front, and the two are joined with the paper's equations (3)/(4).
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numba
import numpy as np

from ..errors import MeshError, OptionError
from ..limits import MODES  # one home of the render modes (the request records check them)
from ..mesh.model import default_step

from ._boundary import find_segments
from ._cull import range_visible, table_boundary, visible_prefix, visible_tets
from ._facetable import (FT_INFO, FT_NODES, FT_PARKED, FT_TABLE, INFO_FACES, INFO_MUL, INFO_NODES, count_crossings,
                         count_live, insert_tets, make_face_table, park, rehash, with_nodes, with_table)
from ._segments import (ACC_A, FOLD_END, FRONT, SEG_ACC, SEG_FACE, SEG_FROM, SEG_RAY, SEG_SAMPLES,
                        SEG_STATE, SEG_STEPS, SEG_TS, STATE_ACTIVE, STATE_DONE, STATE_STUCK, TS_T, make_segments)
from ._walk import MODE_FACE, MODE_VOLUME, OPAQUE, advance, advance_rays, compose, make_sampling, settle
from .camera import Camera, FittedCamera
from .composite import Fragments, segment_fragments
from .transfer import TransferFunction, load_transfer_function

TILE = 4  # rays walk in square tiles of pixels (see StreamingRaycaster._runs)


@dataclass
class RenderResult:
    """A rendered image and what it took.

    Attributes
    ----------
    image : (H, W, 4) float32
        Premultiplied RGBA (colour already multiplied by opacity), black background.
    stats : dict
        ``rays``, ``rays_hit``, ``segments``, ``rays_unfinished``, ``samples``, ``tets_rendered``,
        ``step``, ``render_s`` and diagnostics. ``rays_unfinished`` counts the rays with a segment
        whose walk could not be completed in front of opacity 0.99 (the early-termination
        threshold); ``segments_behind_opaque`` the incomplete segments behind it, which change
        their pixel by at most 0.01; ``subsegments_folded`` the subsegments that ended where a
        grid folds over itself (the tet behind a face lies on the ray's side of it);
        ``tets_culled`` those of the ``tets_rendered`` the transfer function makes invisible, left
        out before the walk.
    fragments : Fragments or None
        Every segment's composited colour and depth interval (asked for with ``fragments=True``),
        what :func:`~gatun_py.raycast.composite.composite` sorts and blends with other bricks'.
    """

    image: np.ndarray
    stats: dict = field(default_factory=dict)
    fragments: Fragments | None = None


class StreamingRaycaster:
    """Render tets as they arrive (paper section 3.2).

    Parameters
    ----------
    camera : Camera or FittedCamera
        A :class:`Camera` is fitted to the bounding box of the boundary vertices.
    tf : TransferFunction, str or dict
        Anything :func:`load_transfer_function` accepts.
    mode : {"volume", "face"}
        ``volume``: samples every ``step`` along the ray, at t = k * step from the eye;
        ``face``: one sample per tet interval, the average of the two face samples.
    step : float, optional
        Sample spacing for ``volume``; default :func:`~gatun_py.mesh.default_step`.
    scalar_range : (float, float), optional
        Range the transfer function's normalised ``x`` maps to; default the range of the
        vertices received before the first tet.
    expected_tets : int, optional
        Sizes the face table up front (it grows as needed otherwise).
    lean : bool
        Count, for every face, the rays still to cross it and drop the faces nobody needs any
        more, so the table holds the tets in flight rather than the whole mesh (the paper's
        memory saving; the render takes 1.5-2x as long). Off by default: on grids that fold over
        themselves a walk can leave the ray's path, and although the faces around such places are
        kept, one refined Blunt-fin view (1.5 M tets, 512², az 45 el 70) still lost one ray.
    fragments : bool
        Also return every segment as a fragment (``RenderResult.fragments``): a brick of a
        partition rendered this way composites exactly with the other bricks' fragments.
    cull : bool
        Leave out the tets the transfer function makes fully transparent (every table entry their
        scalar interval reaches has opacity 0): rays enter and leave the visible part through its
        own boundary, and the image is the full walk's. The tets are then entered as they arrive
        and walked once all have come (front to back, as :func:`render_mesh`), so snapshots stay
        blank until :meth:`finish`. Only where the transfer function has a transparent range;
        not with ``lean``.
    terminate : bool
        Early ray termination (below); off: every ray is walked to its end.

    Notes
    -----
    Call :meth:`add_vertices` and :meth:`set_boundary` (any number of times, the boundary must be
    complete before the first :meth:`add_tets`), then :meth:`add_tets` for every batch, then
    :meth:`finish`. Tets may come in any order; the image does not depend on it.

    Early ray termination (as VTK's): a ray stops where its opacity reaches ``OPAQUE`` (0.99); what
    lies behind would change it by less than 0.01. A front subsegment stops there; at
    :meth:`finish` the rays that became that opaque without their first front subsegment stopping
    are walked again from the front, so the image equals the in-memory render's whatever the order
    of the tets. Lean renders (whose face counters need every crossing walked) and ``fragments``
    (bricks composited afterwards) walk every ray to its end.
    """

    def __init__(self, camera, tf, *, mode: str = "volume", step: float | None = None, scalar_range=None,
                 expected_tets: int | None = None, lean: bool = False, fragments: bool = False, cull: bool = True,
                 terminate: bool = True):
        if mode not in MODES:
            raise OptionError(f"unknown render mode {mode!r} (choose from {', '.join(MODES)})")
        if step is not None and not (np.isfinite(step) and step > 0):
            raise OptionError(f"the sample step must be a positive number, got {step!r}")
        if not isinstance(camera, (Camera, FittedCamera)):
            raise TypeError("camera must be a Camera or FittedCamera")
        self.camera = camera
        self.tf = load_transfer_function(tf)
        self.mode = mode
        self.step = step
        self.scalar_range = scalar_range
        self.expected_tets = expected_tets
        self._points = np.empty((1024, 3), dtype=np.float64)
        self._dens = np.empty(1024, dtype=np.float64)
        self._fold_mark = np.zeros(1024, dtype=np.uint8)  # vertices by a fold or a flat tet (lean)
        self._nv = 0
        self._faces: list[np.ndarray] = []
        self._started = False
        self._n_tets = 0
        self._conflicts = 0
        self._mark = 0
        self._t_render = 0.0
        # CPU seconds (all threads) of each phase: what the profile and the budget model read
        self._cpu = {"segments": 0.0, "insert": 0.0, "walk": 0.0, "compose": 0.0}
        self.fitted: FittedCamera | None = None
        # lean: count the rays still to cross each face and drop the faces no ray needs any more
        self._counting = bool(lean)
        self._table_peak = 0
        self._want_fragments = bool(fragments)
        self._entry_t = None  # fragments: each segment's boundary depths, before the walks move them
        self._terminate = bool(terminate) and not lean and not fragments
        self._cull = bool(cull) and not lean
        self._deferred = False  # culling: tets entered as they come, walked at the end
        self._n_culled = 0
        self._seg0 = None  # the segments as they start (termination re-walks some rays from there)
        self._redone = 0
        self._notes: list[str] = []

    # -- input ----------------------------------------------------------------------------------
    def add_vertices(self, points, density) -> None:
        """Append vertices (ids continue from the previous ones)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        den = np.asarray(density, dtype=np.float64).reshape(-1)
        if len(pts) != len(den):
            raise MeshError(f"{len(pts)} points but {len(den)} density values")
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(den))):
            raise MeshError("vertices contain NaN or infinite values")
        n = self._nv + len(pts)
        if n > len(self._dens):
            cap = max(n, 2 * len(self._dens))
            p2 = np.empty((cap, 3), dtype=np.float64)
            d2 = np.empty(cap, dtype=np.float64)
            p2[: self._nv] = self._points[: self._nv]
            d2[: self._nv] = self._dens[: self._nv]
            self._points, self._dens = p2, d2
            m2 = np.zeros(cap, dtype=np.uint8)
            m2[: self._nv] = self._fold_mark[: self._nv]
            self._fold_mark = m2
        if self._started:
            pts = pts - self._eye  # stored relative to the eye once it is known
        self._points[self._nv: n] = pts
        self._dens[self._nv: n] = den
        self._nv = n
        if self._started:
            # The face table groups faces by their smallest vertex id, ``mul`` slots per id; sized
            # for fewer vertices, the new ids would wrap around onto the old ones' slots and pile
            # up into long probe chains.
            cap = len(self._ft[FT_TABLE])
            mul = self._slots_per_vertex(cap)
            if mul < self._ft[FT_INFO][INFO_MUL]:
                self._ft = with_table(self._ft, rehash(self._ft, cap, mul, False, self._fold_mark))

    def set_boundary(self, faces) -> None:
        """Add boundary faces (outward wound); all of them must come before the first tet."""
        if self._started:
            raise MeshError("boundary faces arrived after the first tets")
        f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        self._check_ids(f, "boundary face")
        self._faces.append(f)

    def add_tets(self, tets) -> None:
        """Render a batch of tets (positively oriented vertex ids)."""
        t0 = time.perf_counter()
        if not self._started:
            self._start()
        tets = np.ascontiguousarray(tets, dtype=np.int32).reshape(-1, 4)
        if len(tets) == 0:
            return
        self._check_ids(tets, "tet")
        self._n_tets += len(tets)
        if self._deferred:
            keep = np.empty(len(tets), dtype=np.uint8)
            visible_tets(tets, self._dens[: self._nv], self._vis_prefix, self._tab_lo, self._tab_inv, keep)
            vis = tets[keep.view(np.bool_)]
            self._n_culled += len(tets) - len(vis)
            if len(vis):
                self._insert(vis, np.zeros((0, 4), dtype=np.int32), 1)
        elif self._nseg:
            self._mark += 1
            n_active, conflicts = self._insert(tets, self._crossings(tets), self._mark)
            self._conflicts += conflicts
            self._advance(n_active)
            self._park(n_active)
        self._t_render += time.perf_counter() - t0

    def finish(self) -> RenderResult:
        """Composite every ray; segments whose marks never met count as unfinished."""
        t0 = time.perf_counter()
        if not self._started:
            self._start()
        if self._deferred:
            self._walk_visible()
        image = np.zeros((self._n_rays, 4), dtype=np.float64)
        settle(self._seg, self._boundary_keys)
        with self._phase("compose"):
            unfinished, hidden = compose(self._seg, image, self._terminate)
        if self._terminate and not self._deferred and self._nseg:
            redo = self._runs_to_redo(image)
            if len(redo[0]):
                self._rewalk(*redo)
                image[:] = 0.0
                settle(self._seg, self._boundary_keys)
                unfinished, hidden = compose(self._seg, image, self._terminate)
        self._t_render += time.perf_counter() - t0
        return self._take_fragments(self._result(image, unfinished, hidden))

    # -- early termination and culling ----------------------------------------------------------
    def _runs(self):
        """(first, end) segment of each ray's run (segments are stored ray by ray), the rays in
        tiles of ``TILE`` x ``TILE`` pixels: :func:`advance_rays` hands out blocks of 16 runs, and
        the rays of a square tile meet more of the same tets than a row's (fewer cache misses).
        Runs are independent: their order changes no pixel."""
        ray = self._seg[SEG_RAY]
        if len(ray) == 0:
            z = np.zeros(0, dtype=np.int64)
            return z, z
        lo = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]]).astype(np.int64)
        hi = np.r_[lo[1:], len(ray)].astype(np.int64)
        w = self.fitted.width
        r = ray[lo].astype(np.int64)
        row, col = r // w, r % w
        key = ((row // TILE) * (w // TILE + 1) + col // TILE) * (TILE * TILE) + (row % TILE) * TILE + col % TILE
        order = np.argsort(key, kind="stable")
        return lo[order], hi[order]

    @contextmanager
    def _phase(self, name):
        c0 = time.process_time()
        try:
            yield
        finally:
            self._cpu[name] += time.process_time() - c0

    def _walk_runs(self, lo, hi, max_steps):
        with self._phase("walk"):
            self._walk_runs_kernel(lo, hi, max_steps)

    def _walk_runs_kernel(self, lo, hi, max_steps):
        old = numba.set_parallel_chunksize(2)
        try:
            advance_rays(lo, hi, self._points[: self._nv], self._dens[: self._nv], self._dirs, self._seg, self._ft,
                         self._sampling, max_steps, self._terminate)
        finally:
            numba.set_parallel_chunksize(old)

    def _runs_to_redo(self, image):
        """The rays whose streamed colour is not the front-to-back walk's: opaque enough to terminate
        (``OPAQUE``) without their first front subsegment having stopped there (a back subsegment
        met it first, or a later segment stopped on its own threshold)."""
        lo, hi = self._runs()
        ray = self._seg[SEG_RAY][lo]
        first_front = self._seg[SEG_ACC][lo, FRONT, ACC_A]
        redo = (image[ray, ACC_A] >= OPAQUE) & ~(first_front >= OPAQUE)
        return lo[redo], hi[redo]

    def _rewalk(self, lo, hi):
        """Walk the runs ``lo[i]:hi[i]`` again from their boundary faces, front to back (every tet
        has arrived: the table is not lean)."""
        seg = self._seg
        lens = hi - lo
        idx = np.repeat(lo - np.cumsum(lens) + lens, lens) + np.arange(int(lens.sum()), dtype=np.int64)
        face0, from0, ts0 = self._seg0
        seg[SEG_FACE][idx] = face0[idx]
        seg[SEG_FROM][idx] = from0[idx]
        seg[SEG_TS][idx] = ts0[idx]
        seg[SEG_ACC][idx] = 0.0
        seg[SEG_STATE][idx] = STATE_ACTIVE
        seg[SEG_STEPS][idx] = 0
        seg[SEG_SAMPLES][idx] = 0
        self._redone += len(lo)
        self._walk_runs(lo, hi, self._n_tets + 8)

    def _walk_visible(self):
        """Culling: every tet has come; cast the rays into the boundary of the visible ones and walk them."""
        cam = self.fitted
        P = self._points[: self._nv]
        faces = table_boundary(self._ft[FT_TABLE]) if len(self._bfaces) else np.zeros((0, 3), dtype=np.int64)
        self._bfaces, self._bkeys = faces, None
        with self._phase("segments"):
            self._seg, self._odd_pixels, self._anomalies, self._boundary_hits = find_segments(
                P, self._dens, self._dirs, cam.width, cam.height, faces, *_ray_grid(cam))
        self._nseg = len(self._seg[SEG_RAY])
        if self._want_fragments:
            self._entry_t = self._seg[SEG_TS][:, :, TS_T].copy()
        if self._nseg:
            self._walk_runs(*self._runs(), self._n_tets + 8)

    def _take_fragments(self, res: RenderResult) -> RenderResult:
        if self._want_fragments:
            cam = self.fitted
            res.fragments = segment_fragments(self._seg, self._entry_t, cam.width, cam.height)
            res.stats["fragments"] = len(res.fragments)
        return res

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """The image of what has arrived so far, and which of its pixels are final.

        Returns
        -------
        image : (H, W, 4) float32
            Premultiplied RGBA: every segment contributes its two subsegments as far as they have
            walked (the gap between their marks counts as empty), so the picture fills in as the
            stream arrives and its opacity never exceeds the final image's.
        finished : (H, W) bool
            Pixels whose every segment is done (or that hit nothing): they already hold their
            final colour.

        Cheap (one pass over the segments); the render goes on unchanged.
        """
        t0 = time.perf_counter()
        cam = self.fitted if self._started else self.camera  # nothing arrived yet: a blank image
        image = np.zeros((cam.width * cam.height, 4), dtype=np.float64)
        finished = np.zeros(cam.width * cam.height, dtype=np.bool_)
        if self._started:
            finished[:] = not self._deferred  # culling: nothing is walked before finish()
            if self._nseg:
                compose(self._seg, image, self._terminate)
                finished[self._seg[SEG_RAY][self._seg[SEG_STATE] != STATE_DONE]] = False
        self._t_render += time.perf_counter() - t0
        return image.reshape(cam.height, cam.width, 4).astype(np.float32), finished.reshape(cam.height, cam.width)

    # -- internals ------------------------------------------------------------------------------
    def _check_ids(self, ids, what):
        if ids.size and (ids.min() < 0 or ids.max() >= self._nv):
            bad = int(np.argmax(np.any((ids < 0) | (ids >= self._nv), axis=1)))
            raise MeshError(f"{what} {bad} of the batch refers to vertex {ids[bad].tolist()} "
                            f"but only {self._nv} vertices have arrived")

    def _start(self):
        self._started = True
        faces = np.concatenate(self._faces) if self._faces else np.zeros((0, 3), dtype=np.int64)
        self._faces = []
        pts = self._points[: self._nv]
        cam = self.camera
        tf = self.tf
        if isinstance(cam, Camera) or tf.unit_relative:
            # the mesh's extent: its boundary's vertices (known before the first tet)
            used = np.unique(faces) if len(faces) else np.arange(self._nv)
            lo, hi = (pts[used].min(axis=0), pts[used].max(axis=0)) if len(used) else (np.zeros(3), np.zeros(3))
            if isinstance(cam, Camera):
                cam = cam.fit(lo, hi)
            # a relative unit distance is a fraction of the mesh's size, unless the caller resolved
            # it already against the full mesh (levels must agree)
            tf = tf.for_size(float(np.linalg.norm(hi - lo)) if len(used) else 1.0)
        self.fitted = cam
        self._eye = np.asarray(cam.position, dtype=np.float64)
        if self.step is None:
            self.step = default_step(pts, faces)
        if self.scalar_range is None:
            self.scalar_range = (float(self._dens[: self._nv].min()), float(self._dens[: self._nv].max())) \
                if self._nv else (0.0, 1.0)
        tf, tab, lo, inv = sampling_table(tf, self.scalar_range, self.mode, self.step)
        self._sampling = make_sampling(MODE_VOLUME if self.mode == "volume" else MODE_FACE, self.step, tab, lo, inv,
                                       tf.unit_distance)
        visible = tab[:, 3] > 0.0
        if not visible.any():
            self._notes.append("the transfer function is transparent over the whole scalar range "
                               f"[{self.scalar_range[0]:g}, {self.scalar_range[1]:g}]: the image is black")
        if self._cull and not visible.all():
            self._deferred = True
            self._vis_prefix, self._tab_lo, self._tab_inv = visible_prefix(tab[:, 3]), float(lo), float(inv)
        self._points[: self._nv] -= self._eye
        self._n_rays = cam.width * cam.height
        self._dirs = cam.ray_directions()
        P = self._points[: self._nv]
        faces = self._faces_in_front(P, faces, cam)
        self._bfaces, self._bkeys = faces, None
        if self._deferred:
            # segments wait for the visible part's boundary (_walk_visible); the table takes its tets
            self._seg, _ = make_segments(np.zeros(0, np.int32), np.zeros((0, 2, 3), np.int32),
                                         np.zeros((0, 2), np.int32), np.zeros((0, 2, 2)), self._n_rays)
            self._nseg, self._odd_pixels, self._anomalies, self._boundary_hits = 0, np.zeros(0, np.uint8), 0, 0
            self._active = np.zeros(0, dtype=np.int64)
            expected = self.expected_tets or max(len(faces), 1024)
            cap = 1 << int(np.ceil(np.log2(max(16, 2.5 * (2 * expected + len(faces) // 2)))))
            self._ft = make_face_table(cap, self._slots_per_vertex(cap), 0, counting=False)
            self._table_peak = self._ft[FT_TABLE].nbytes
            return
        # the segments; the rays whose boundary crossings did not pair up (count_crossings keeps
        # the tets around them)
        with self._phase("segments"):
            self._seg, self._odd_pixels, self._anomalies, self._boundary_hits = find_segments(
                P, self._dens, self._dirs, cam.width, cam.height, faces, *_ray_grid(cam))
        nseg = self._nseg = len(self._seg[SEG_RAY])
        if self._want_fragments:
            self._entry_t = self._seg[SEG_TS][:, :, TS_T].copy()
        if self._terminate:
            self._seg0 = (self._seg[SEG_FACE].copy(), self._seg[SEG_FROM].copy(), self._seg[SEG_TS].copy())
        self._active = np.arange(nseg, dtype=np.int64)
        if self._counting:  # grows with the tets in flight
            cap = 1 << int(np.ceil(np.log2(max(1024, 4 * len(faces)))))
        else:
            expected = self.expected_tets or max(len(faces), 1024)
            cap = 1 << int(np.ceil(np.log2(max(16, 2.5 * (2 * expected + len(faces) // 2)))))
        self._ft = make_face_table(cap, self._slots_per_vertex(cap), nseg, counting=self._counting)
        self._table_peak = self._ft[FT_TABLE].nbytes
        self._park(nseg, new_faces=min(2 * nseg, len(faces)))

    def _insert(self, tets, crossings, mark):
        with self._phase("insert"):
            return self._insert_kernel(tets, crossings, mark)

    def _insert_kernel(self, tets, crossings, mark):
        """Enter tets into the face table (:func:`_facetable.insert_tets`); returns (segments to advance, conflicts).

        A tet adds at most four faces, but a batch of a whole mesh adds about two per tet: rather
        than doubling a table sized for the expected tets (a full rehash) to fit a worst case that
        never comes, the batch goes in pieces that fit, and the table grows only when even a
        piece does not. Pieces collect the same segments in the same order as one call.
        """
        n_active = conflicts = done = 0
        while done < len(tets):
            left = len(tets) - done
            room = (int(0.6 * len(self._ft[FT_TABLE])) - int(self._ft[FT_INFO][INFO_FACES])) // 4
            if self._counting or room < min(left, 4096):
                self._ensure_capacity(4 * left)  # a counting table purges first; see there
                take = left
            else:
                take = min(left, room)
            part = crossings[done: done + take] if len(crossings) else crossings
            k, c = insert_tets(tets[done: done + take], part, self._fold_mark, self._ft, self._seg, mark,
                               self._active[n_active:])
            n_active += k
            conflicts += c
            done += take
        return n_active, conflicts

    def _park(self, n_active, new_faces=None):
        # Parking adds a face only where a subsegment waits on one the table lacks: at the start
        # the boundary faces (``new_faces``: at most those), later none in a table that keeps every
        # face (a walk stops on the exit face of the last tet it crossed, which is present). The
        # worst case of 2 per subsegment pair may then fill the table further instead of doubling it.
        if new_faces is not None:
            self._ensure_capacity(new_faces)
        else:
            self._ensure_capacity(2 * n_active, load=0.6 if self._counting else 0.9)
        nodes = self._ft[FT_NODES]
        if self._ft[FT_INFO][INFO_NODES] + 2 * n_active > len(nodes):
            live = self._compact_nodes()
            if live + 2 * n_active > len(nodes) // 2:
                grown = np.empty((2 * (live + 2 * n_active) + 16, 3), dtype=np.int32)
                grown[:live] = nodes[:live]
                self._ft = with_nodes(self._ft, grown)
        park(self._active, n_active, self._seg, self._ft)

    def _compact_nodes(self):
        """Drop stale park-list nodes (rebuild the lists from the live items); return the count."""
        htab, info, _, _, in_list, _ = self._ft
        htab[:, FT_PARKED] = -1
        in_list[:] = 0
        info[INFO_NODES] = 0
        live = np.flatnonzero(self._seg[SEG_STATE] == STATE_ACTIVE).astype(np.int64)
        # re-park every live subsegment where it waits
        park(live, len(live), self._seg, self._ft)
        return int(info[INFO_NODES])

    @property
    def _boundary_keys(self):
        """The boundary faces' id triples, each sorted, in lexicographic order (for :func:`_walk.settle`).

        ``settle`` looks a face up only for a segment still active at the end, which most frames
        have none of: the sort waits until one is.
        """
        if self._bkeys is None:
            if not np.any(self._seg[SEG_STATE] == STATE_ACTIVE):
                return np.zeros((0, 3), dtype=np.int32)
            keys = np.sort(self._bfaces, axis=1).astype(np.int32)
            self._bkeys = np.ascontiguousarray(keys[np.lexsort((keys[:, 2], keys[:, 1], keys[:, 0]))])
        return self._bkeys

    @staticmethod
    def _faces_in_front(P, faces, cam):
        """The boundary, or nothing if it is all behind the eye; an error if the eye's plane cuts it."""
        if len(faces) == 0:
            return faces
        fwd, _, _ = cam.basis()
        depth = (P @ fwd)[faces]  # every boundary vertex (each as often as it has faces)
        if np.all(depth <= 0):
            return faces[:0]
        if np.any(depth <= 0):
            raise OptionError("the camera is inside the mesh or too close to it (part of the mesh is behind "
                              "the eye); use a smaller --zoom or move the camera out")
        return faces

    def _crossings(self, tets):
        """Rays crossing each face of each tet (the counting table's increments)."""
        if not self._counting:
            return np.zeros((0, 4), dtype=np.int32)
        cam = self.fitted
        fwd, right, up = cam.basis()
        out = np.empty((len(tets), 4), dtype=np.int32)
        xs, ys = cam.ray_offsets()
        count_crossings(tets, self._points[: self._nv], xs, ys, cam.width, cam.height,
                          np.asarray(fwd, np.float64), np.asarray(right, np.float64), np.asarray(up, np.float64),
                          float(np.tan(np.radians(cam.view_angle) / 2.0)), self._odd_pixels, self._fold_mark, out)
        return out

    def _ensure_capacity(self, extra, load=0.6):
        """Make room for ``extra`` more faces within ``load`` of the table (rehashing to a larger
        table, a counting table purged first, to load 0.6 or 0.25)."""
        cap = len(self._ft[FT_TABLE])
        need = int(self._ft[FT_INFO][INFO_FACES]) + int(extra)
        if need <= load * cap:
            return
        # A counting table first drops the faces no ray needs, then fits the rest. A walk that
        # looped on folded geometry may have taken a face off more than once: keep every face
        # around where it stopped (the loop circles an edge or a vertex of that face).
        purge = self._counting
        if purge:
            stuck = self._seg[SEG_STATE] == STATE_STUCK
            if np.any(stuck):
                ids = np.concatenate([self._seg[SEG_FACE][stuck].ravel(), self._seg[SEG_FROM][stuck].ravel()])
                self._fold_mark[ids[ids >= 0]] = 1
        live = count_live(self._ft, purge, self._fold_mark) if purge else int(self._ft[FT_INFO][INFO_FACES])
        need = live + int(extra)
        new = 1024 if purge else cap
        while need > (0.25 if purge else 0.6) * new:  # room for many batches before the next purge
            new *= 2
        self._ft = with_table(self._ft, rehash(self._ft, new, self._slots_per_vertex(new), purge, self._fold_mark))
        self._table_peak = max(self._table_peak, self._ft[FT_TABLE].nbytes)

    def _slots_per_vertex(self, cap):
        """Table slots per vertex id in 16-bit fixed point (faces are grouped by smallest vertex).

        A stream's vertices keep arriving after the table is made; sizing for a typical vertex
        count of the expected tets (meshes have about 5 tets per vertex) spares rehashing the
        table at every vertex batch.
        """
        if self._counting:  # scattered, see _facetable._hash0
            return 0
        return (int(cap) << 16) // max(self._nv, (self.expected_tets or 0) // 4, 1)

    def _advance(self, n_active):
        with self._phase("walk"):
            self._advance_timed(n_active)

    def _advance_timed(self, n_active):
        old = numba.set_parallel_chunksize(4)
        try:
            self._advance_kernel(n_active)
        finally:
            numba.set_parallel_chunksize(old)

    def _advance_kernel(self, n_active):
        advance(self._active, n_active, self._points[: self._nv], self._dens[: self._nv], self._dirs, self._seg,
                self._ft, self._sampling, self._n_tets + 8, OPAQUE if self._terminate else 2.0)

    def _result(self, image, unfinished, hidden):
        cam = self.fitted
        img = image.reshape(cam.height, cam.width, 4).astype(np.float32)
        seg = self._seg
        hit_rays = int(len(np.unique(seg[SEG_RAY]))) if self._nseg else 0
        stats = {
            "rays": int(self._n_rays),
            "rays_hit": hit_rays,
            "segments": int(self._nseg),
            "rays_unfinished": int(unfinished),
            "segments_stuck": int(np.count_nonzero(seg[SEG_STATE] == STATE_STUCK)),
            "segments_behind_opaque": int(hidden),
            "subsegments_folded": int(np.count_nonzero(seg[SEG_FROM] == FOLD_END)),
            "boundary_anomalies": int(self._anomalies),
            "boundary_hits": int(self._boundary_hits),
            "face_conflicts": int(self._conflicts),
            "samples": int(seg[SEG_SAMPLES].sum()),
            "steps": int(seg[SEG_STEPS].sum()),
            "tets_rendered": int(self._n_tets),
            "tets_culled": int(self._n_culled),
            "early_termination": OPAQUE if self._terminate else None,
            "rays_rewalked": int(self._redone),
            "face_table_peak_mb": round(self._table_peak / 2**20, 2),
            "lean": self._counting,
            "step": float(self.step),
            "mode": self.mode,
            "render_s": self._t_render,
            "cpu_s": {k: round(v, 4) for k, v in self._cpu.items()},
            "nan_pixels": int(np.count_nonzero(~np.isfinite(img).all(axis=2))),
        }
        if self._notes:
            stats["notes"] = list(self._notes)
        return RenderResult(img, stats)


def sampling_table(tf: TransferFunction, scalar_range, mode: str, step: float):
    """The transfer function resolved against ``scalar_range`` and the lookup table the walk reads:
    ``(tf, tab, lo, inv)``, row i of ``tab`` the r, g, b, a at scalar ``lo + i / inv``; in volume
    mode the opacity of a path of one ``step``."""
    tf = tf.resolve(scalar_range)
    tab, lo, inv = tf.table(scalar_range)
    if mode == "volume":  # opacity for a path of one step
        tab[:, 3] = 1.0 - np.power(1.0 - tab[:, 3], step / tf.unit_distance)
    return tf, tab, lo, inv


def range_can_show(tf: TransferFunction, scalar_range, lo: float, hi: float) -> bool:
    """Whether points whose scalar lies in [``lo``, ``hi``] can add anything to an image drawn with
    ``tf`` over ``scalar_range``: False only when every tet among them would be culled (the same
    test, :func:`~._cull.range_visible`). The table's opacity before it is scaled to the step: an
    entry above 0 there may round to 0 after, never the other way, so the answer errs to True.

    Examples
    --------
    >>> x = np.array([0.0, 0.7, 1.0])  # transparent below 70 % of the range
    >>> tf = TransferFunction(x, np.ones((3, 3)), x, np.array([0.0, 0.0, 0.5]))
    >>> range_can_show(tf, (0.0, 1.0), 0.0, 0.5), range_can_show(tf, (0.0, 1.0), 0.5, 0.9)
    (False, True)
    """
    tab, t_lo, inv = tf.resolve(scalar_range).table(scalar_range)
    return bool(range_visible(visible_prefix(tab[:, 3]), float(t_lo), float(inv), float(lo), float(hi)))


def box_in_view(camera: FittedCamera, lo, hi, *, margin: float = 1.0) -> bool:
    """Whether a pixel ray of ``camera`` can meet the box [``lo``, ``hi``]: False only when the whole
    box lies in front of the eye and its projection misses the image's pixel centres by more than
    ``margin`` pixels (a box partly behind the eye, or around it, counts as in view)."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                       dtype=np.float64)
    if not np.all(np.isfinite(corners)):
        return True
    fwd, _, _ = camera.basis()
    if not np.all((corners - camera.position) @ fwd > 0.0):
        return True
    uv = camera.project(corners)
    if not np.all(np.isfinite(uv)):
        return True
    (c0, r0), (c1, r1) = uv.min(axis=0), uv.max(axis=0)
    return bool(c1 >= 0.5 - margin and c0 <= camera.width - 0.5 + margin
                and r1 >= 0.5 - margin and r0 <= camera.height - 0.5 + margin)


def _ray_grid(cam):
    """Camera basis (fwd, right, up), pixel ray offsets (xs, ys) and tan of half the view angle."""
    fwd, right, up = (np.ascontiguousarray(v, dtype=np.float64) for v in cam.basis())
    xs, ys = cam.ray_offsets()
    tan_half = float(np.tan(np.radians(cam.view_angle) / 2.0))
    return fwd, right, up, np.ascontiguousarray(xs, np.float64), np.ascontiguousarray(ys, np.float64), tan_half


def render_mesh(mesh, camera, tf, *, mode: str = "volume", step: float | None = None,
                scalar_range=None, fragments: bool = False, cull: bool = True, terminate: bool = True) -> RenderResult:
    """Render a whole in-memory mesh (the generic decompress-then-render baseline).

    All tets enter the face table first, then every ray walks front to back from its entry
    face in one parallel pass, stopping where it is opaque (``OPAQUE``). Same kernels and sampling as :class:`StreamingRaycaster`, so the
    two give the same image.

    Parameters
    ----------
    mesh : TetMesh
    camera : Camera or FittedCamera
    tf : TransferFunction, str or dict
    mode : {"volume", "face"}
    step : float, optional
        Default :func:`~gatun_py.mesh.default_step`.
    scalar_range : (float, float), optional
        Default the mesh's scalar range.
    fragments : bool
        Also return the segments as fragments (see :class:`StreamingRaycaster`).
    cull, terminate : bool
        Leave out the tets the transfer function makes invisible; stop rays where they are opaque
        (see :class:`StreamingRaycaster`).

    Returns
    -------
    RenderResult
    """
    t0 = time.perf_counter()
    rc = StreamingRaycaster(camera, tf, mode=mode, step=step,
                            scalar_range=mesh.scalar_range if scalar_range is None else scalar_range,
                            expected_tets=mesh.n_tets, lean=False,  # the whole mesh is in the table anyway
                            fragments=fragments, cull=cull, terminate=terminate)
    rc.add_vertices(mesh.points, mesh.density)
    rc.set_boundary(mesh.boundary_faces())
    rc._start()
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int32)
    if rc._deferred:
        rc.add_tets(tets)
        res = rc.finish()
        res.stats["render_s"] = rc._t_render = time.perf_counter() - t0
        return res
    rc._n_tets = len(tets)
    if rc._nseg and len(tets):
        _, rc._conflicts = rc._insert(tets, rc._crossings(tets), 1)
        rc._walk_runs(*rc._runs(), rc._n_tets + 8)
    image = np.zeros((rc._n_rays, 4), dtype=np.float64)
    settle(rc._seg, rc._boundary_keys)
    with rc._phase("compose"):
        unfinished, hidden = compose(rc._seg, image, rc._terminate)
    rc._t_render = time.perf_counter() - t0
    return rc._take_fragments(rc._result(image, unfinished, hidden))


__all__ = ["RenderResult", "StreamingRaycaster", "render_mesh", "MODES", "TransferFunction"]
