"""One open file in the viewer: frame requests in, images and stats out (no web code here).

A :class:`FrameRequest` is what a browser, a script or a test asks for: a camera, a transfer function,
a frame-time budget (or none: full quality) and an image format. :meth:`ViewerSession.render` plans the
frame with the shared time model (:mod:`gatun_py.pipeline.budget`), renders it through the streaming
pipeline on the file kept open, encodes it, and corrects the model from the frame's measured stats.
"""

from __future__ import annotations

import collections
import io
import math
import os
import time
from dataclasses import dataclass, replace

import numpy as np
from PIL import Image

from ..codec import TetcReader
from ..errors import OptionError, TetcError
from ..pipeline.budget import FramePlanner, TimeModel, machine_costs
from ..pipeline.requests import Frame, View
from ..pipeline.stream import View as _StreamView  # the fitted view the stages draw with
from ..pipeline.stream import file_render_defaults, render_tetc
from ..raycast.camera import MAX_ZOOM, Camera
from ..raycast.image import image_bytes, to_rgb8
from ..raycast.transfer import from_dict, load_transfer_function, preset_names
from ..simplify.levels import resolve_target
from .series import SeriesFrames, parse_step

FORMATS = {"jpeg": "image/jpeg", "png": "image/png", "webp": "image/webp"}
MAX_VIEW_SIZE = 2048  # pixels per side the viewer renders
DEFAULT_BUDGET_S = 0.1
PARTIAL_QUALITY = 80  # WebP quality of the images a still frame shows while it streams
# Frames are planned to a share of the budget: the model predicts a typical frame, and the same work
# takes longer now and then (other programs, the cache). The share starts at PLAN_SHARE and then
# follows the spread of this session's frames: the target is 90 % of frames within 1.2 x the
# budget, so frames are planned to 1.2 x budget / (the 90th percentile of measured / predicted),
# never above PLAN_SHARE, so that the typical frame also leaves room for sending it (frames per
# second = 1 / (frame + transfer)).
PLAN_SHARE = 0.85
PLAN_SHARE_RANGE = (0.3, PLAN_SHARE)
SPREAD_FRAMES = 40  # measured / predicted of the last frames this many
HISTOGRAM_POINTS = 20_000
COLORMAPS = ("viridis", "plasma", "inferno", "magma", "cividis", "coolwarm", "jet", "gray")


class FrameCancelled(Exception):
    """A newer request superseded the frame being rendered."""


@dataclass(frozen=True)
class FrameRequest:
    """A validated frame request (see :func:`parse_request` for the JSON it comes from): the view
    (the same record :func:`gatun_py.render` takes, which checks it), the viewer's pan, and how
    the frame is planned and sent."""

    view: View
    budget_s: float | None  # None: full quality (the file's level 0, or ``level``)
    level: int | None = None
    fmt: str = "jpeg"
    quality: int = 85
    interacting: bool = False
    pan: tuple = (0.0, 0.0)  # the focal point's shift, in radii of the bounding sphere (Camera.pan_x, pan_y)
    time_step: int = 0  # a time step of a series file (negative: from the end)

    @property
    def camera(self) -> Camera:
        return replace(self.view.camera, pan_x=self.pan[0], pan_y=self.pan[1])

    @property
    def tf(self):
        return self.view.tf

    @property
    def mode(self) -> str:
        return self.view.mode


def _number(obj: dict, key: str, default, lo=-math.inf, hi=math.inf, integer=False):
    v = obj.get(key, default)
    if v is None and default is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise OptionError(f"{key!r} must be a finite number, got {v!r}")
    if integer:
        if int(v) != v:
            raise OptionError(f"{key!r} must be an integer, got {v!r}")
        v = int(v)
    if not lo <= v <= hi:
        raise OptionError(f"{key!r} must lie in [{lo:g}, {hi:g}], got {v!r}")
    return v


def parse_request(obj) -> FrameRequest:
    """Validate a frame request given as parsed JSON.

    The request (every key optional)::

        {"camera": {"width": 512, "height": 512, "azimuth": 0, "elevation": 0, "zoom": 1,
                    "pan_x": 0, "pan_y": 0},
         "tf": "bluntfin" | {project transfer-function JSON},
         "budget": 0.1 | null,        # seconds; null = full quality
         "level": null | 3,           # a stored level instead of a budget
         "mode": "volume" | "face",
         "format": "jpeg" | "png" | "webp", "quality": 85,
         "interacting": false,
         "step": 0}                   # a time step of a series file

    Raises
    ------
    OptionError
        Anything malformed, with a message naming the key. A ``tf`` string must be a preset name:
        file paths are never read on a client's behalf.

    Examples
    --------
    >>> r = parse_request({"camera": {"width": 64, "height": 48, "azimuth": 30}, "budget": 0.2})
    >>> (r.camera.width, r.camera.height, r.camera.azimuth, r.budget_s, r.fmt)
    (64, 48, 30.0, 0.2, 'jpeg')
    """
    if not isinstance(obj, dict):
        raise OptionError("a frame request must be a JSON object")
    cam = obj.get("camera", {})
    if not isinstance(cam, dict):
        raise OptionError("'camera' must be an object")
    size = (_number(cam, "width", 512, 1, MAX_VIEW_SIZE, integer=True),
            _number(cam, "height", 512, 1, MAX_VIEW_SIZE, integer=True))
    angles = {k: float(_number(cam, k, 0.0, -1e6, 1e6)) for k in ("azimuth", "elevation")}
    zoom = float(_number(cam, "zoom", 1.0, 1 / MAX_ZOOM, MAX_ZOOM))
    pan = (float(_number(cam, "pan_x", 0.0, -100, 100)), float(_number(cam, "pan_y", 0.0, -100, 100)))
    spec = obj.get("tf", "default")
    if isinstance(spec, str):
        if spec not in preset_names():
            raise OptionError(f"unknown transfer-function preset {spec!r} (presets: {', '.join(preset_names())})")
        tf = load_transfer_function(spec)
    elif isinstance(spec, dict):
        tf = from_dict(spec, "the request's transfer function")
    else:
        raise OptionError("'tf' must be a preset name or a transfer-function object")
    budget = _number(obj, "budget", DEFAULT_BUDGET_S, 1e-3, 3600.0) if obj.get("budget", 0) is not None else None
    level = _number(obj, "level", None, 0, 64, integer=True)
    fmt = obj.get("format", "jpeg")
    if fmt not in FORMATS:
        raise OptionError(f"'format' must be one of {', '.join(FORMATS)}, got {fmt!r}")
    view = View(size=size, tf=tf, zoom=zoom, mode=obj.get("mode", "volume"), **angles)
    return FrameRequest(view, budget, level, fmt, _number(obj, "quality", 85, 1, 100, integer=True),
                        bool(obj.get("interacting", False)), pan, parse_step(obj))


class CachingReader(TetcReader):
    """A :class:`TetcReader` that keeps the decoded batches of levels up to ``max_tets`` in total.

    Every interactive frame would otherwise decode its level again; a viewer redraws the same few
    coarse levels many times. Levels too large for the cache (a 10 M-tet level 0) stream from the
    file each time, as ``tetc render`` does. A level enters the cache only once decoded whole (a
    cancelled frame leaves nothing half-cached).
    """

    def __init__(self, source, *, max_tets: int = 3_000_000):
        super().__init__(source)
        self.max_tets = max_tets
        self._decoded_levels: dict[int, list] = {}
        self._forests: dict[int, tuple] = {}

    def is_decoded(self, level: int) -> bool:
        return level in self._decoded_levels

    def cached_tets(self) -> int:
        return sum(int(self.level_meta(lv)["tets"]) for lv in self._decoded_levels)

    def iter_decode(self, level: int = 0, **kw):
        if level in self._decoded_levels:
            yield from self._decoded_levels[level]
            return
        keep = self.cached_tets() + int(self.level_meta(level)["tets"]) <= self.max_tets
        out = []
        for batch in super().iter_decode(level, **kw):
            if keep:
                out.append(batch)
            yield batch
        if keep:
            self._decoded_levels[level] = out

    def read_forest(self, level: int = 0):
        if level not in self._forests:
            self._forests[level] = super().read_forest(level)
        return self._forests[level]


class ViewerSession:
    """A ``.tetc`` file kept open for a viewer: file info, frame planning and rendering.

    Every frame checks that the file on disk is still the one opened (size and modification time):
    a changed file is reopened, a vanished or corrupt one raises :class:`~gatun_py.errors.TetcError`
    with a clear message (the server shows it and keeps serving).
    """

    #: seconds between the images of a still frame filling in (see :meth:`render`)
    partial_every_s = 0.25

    def __init__(self, path, *, costs=None):
        self.path = os.fspath(path)
        self.costs = costs if costs is not None else machine_costs()[0]
        self._open()
        for fmt in FORMATS:  # Pillow loads each encoder on first use (~50 ms): not in the first frame
            image_bytes(np.zeros((8, 8, 3), np.uint8), fmt)

    def _signature(self):
        try:
            st = os.stat(self.path)
        except OSError as e:
            raise TetcError(f"{self.path}: the file is gone ({e.strerror or e})") from None
        return st.st_size, st.st_mtime_ns

    def _open(self):
        self.signature = None  # until the file has been read whole: a failed open is retried next frame
        signature = self._signature()
        try:
            with open(self.path, "rb") as fh:  # read whole: the file may change under a long session
                data = fh.read()
        except OSError as e:
            raise TetcError(f"{self.path}: cannot read ({e.strerror or e})") from None
        reader = CachingReader(data)
        for name in reader.container.section_names():  # every checksum, before the page is served:
            reader.container.read_section(name)  # a damaged file fails here, not in every frame
        self.reader = reader
        self.bbox_lo, self.bbox_hi, self.scalar_range, self.step = file_render_defaults(self.reader)
        self.series = SeriesFrames(reader)  # one step for a snapshot
        self.planners = {}  # by mode: each keeps its own view statistics, the costs are shared
        self.spread = collections.deque(maxlen=SPREAD_FRAMES)  # measured / predicted of budget frames
        self.model = TimeModel(self.costs)
        self._histogram = None
        self.signature = signature

    def check_file(self) -> None:
        """Reopen the file if it changed on disk; raise TetcError if it vanished or is corrupt."""
        if self._signature() != self.signature:
            self._open()

    def plan_share(self) -> float:
        """Share of the budget to plan frames to (see PLAN_SHARE)."""
        if len(self.spread) < 5:
            return PLAN_SHARE
        lo, hi = PLAN_SHARE_RANGE
        return min(max(1.2 / float(np.percentile(self.spread, 90)), lo), hi)

    @staticmethod
    def series_budget(budget_s: float, step_s: float) -> float:
        """The budget left for the frame once the time step's predicted decode is taken off (at
        least a fifth of it: a step that alone overruns gets the coarsest frames, not none)."""
        return max(budget_s - step_s, 0.2 * budget_s)

    def planner(self, mode: str) -> FramePlanner:
        if mode not in self.planners:
            self.planners[mode] = FramePlanner(self.reader, self.model, step=self.step, mode=mode,
                                               decoded=self.reader.is_decoded)
        return self.planners[mode]

    # -- what the page shows before the first frame ---------------------------------------------

    def histogram(self, bins: int = 64, *, points: int = HISTOGRAM_POINTS) -> list[int]:
        """Counts of the scalar over the vertices of the coarsest stored level that still has
        ``points`` of them (or level 0): the shape of the distribution, without decoding it all."""
        if self._histogram is None:
            big_enough = [lv for lv in self.reader.levels if int(lv["points"]) >= points] or self.reader.levels[:1]
            lv = max(big_enough, key=lambda x: int(x.get("merges_before", 0)))
            mesh = self.reader.decode_mesh(int(lv["level"]))
            lo, hi = self.scalar_range
            counts, _ = np.histogram(mesh.density, bins=bins, range=(lo, hi if hi > lo else lo + 1))
            self._histogram = [int(c) for c in counts]
        return self._histogram

    def info(self) -> dict:
        meta = self.reader.meta
        return {
            "file": os.path.basename(self.path),
            "points": int(meta["points"]), "tets": int(meta["tets"]),
            "scalar": self.reader.scalar_name,
            "scalar_range": list(self.scalar_range),
            "bbox": [list(map(float, self.bbox_lo)), list(map(float, self.bbox_hi))],
            "levels": [{k: lv.get(k) for k in ("level", "ratio", "merges_before", "points", "tets", "has_forest")}
                       for lv in self.reader.levels],
            "histogram": self.histogram(),
            "presets": {name: _tf_json(load_transfer_function(name)) for name in preset_names()},
            "colormaps": colormap_tables(),
            "selective_refinement": False,
            "default_budget": DEFAULT_BUDGET_S,
            "steps": self.series.info(),
        }

    # -- frames ---------------------------------------------------------------------------------

    def render(self, req: FrameRequest, *, cancelled=None, partial=None) -> Frame:
        """Plan, render, encode one frame; ``cancelled()`` returning True aborts it between batches.

        ``partial(data, mime, stats)``, when given, receives the frame as it fills in while a long
        frame streams (at most every ``partial_every_s`` seconds, between batches): a WebP whose
        opaque pixels are final and the rest transparent.

        With a budget, the planner picks the level and merges (and, when levels alone cannot make it,
        a coarser sample step and a smaller image, which the page scales up) predicted to fit;
        without, the file's full mesh at the file's step, as ``tetc render`` draws it.
        """
        t0 = time.perf_counter()
        self.check_file()
        time_step = self.series.check(req.time_step)
        step_s = self.series.predict_decode_s(time_step)
        planner = self.planner(req.mode)
        fitted = req.camera.fit(self.bbox_lo, self.bbox_hi)
        plan = None
        if req.level is not None:
            target = resolve_target(self.reader, level=req.level)
        elif req.budget_s is None:
            target = resolve_target(self.reader)
        else:
            # Before the first frame of a view the work is guessed from the bounding box (an
            # overestimate: the first frame comes out coarse and fast); each frame then teaches it.
            plan = planner.plan(self.series_budget(self.plan_share() * req.budget_s, step_s), fitted, drag=True)
            target = planner.target(plan)
        scale = plan.scale if plan is not None else 1.0
        step_factor = plan.step_factor if plan is not None else 1.0
        camera = req.camera
        if scale != 1.0:
            camera = replace(camera, width=max(1, round(camera.width * scale)),
                             height=max(1, round(camera.height * scale)))
        view = _StreamView(camera, req.tf, req.mode, self.step * step_factor if step_factor != 1.0 else None, False)
        decoded = self.reader.is_decoded(target.level)
        work = planner.estimate(target.level, target.merges, camera.width * camera.height,
                                planner.estimator.coverage(fitted), step_factor)
        predicted = planner.model.predict(work, key=target.level)
        # the step's arrays are decoded before the frame, so the model learns the frame alone
        step_decode_s, stream = 0.0, None
        if time_step:  # step 0 is the file's own stream
            _, step_decode_s = self.series.values(time_step)
            stream = self.series.batches(target.level, time_step)

        def progress(_n):
            if cancelled is not None and cancelled():
                raise FrameCancelled()

        on_image = None
        if partial is not None:
            def on_image(image, finished):
                if cancelled is not None and cancelled():
                    raise FrameCancelled()
                # only the pixels that are final: drawn over the preview on the page, the frame
                # fills in with its full-quality pixels instead of flashing the unwalked ones black
                rgba8 = np.concatenate([to_rgb8(image), (finished * np.uint8(255))[..., None]], axis=2)
                buf = io.BytesIO()
                Image.fromarray(rgba8, "RGBA").save(buf, format="WEBP", quality=PARTIAL_QUALITY)
                partial(buf.getvalue(), FORMATS["webp"], {"partial": True, "server_s": time.perf_counter() - t0,
                                                          "finished_share": float(finished.mean()),
                                                          "width": camera.width, "height": camera.height})

        t_plan = time.perf_counter()
        res = render_tetc(self.reader, view, target=target, progress=progress, partial=on_image,
                          partial_every_s=self.partial_every_s, decoded=stream)
        t_render = time.perf_counter()
        rgb8 = to_rgb8(res.image)
        data = image_bytes(rgb8, req.fmt, quality=req.quality)
        t_end = time.perf_counter()
        st = res.stats
        encode_s = t_end - t_render
        planner.observe(st, total_s=t_end - t_plan, extra_s=encode_s, step_factor=step_factor, decoded=decoded)
        if plan is not None and predicted > 0:
            self.spread.append((t_end - t0) / (predicted + step_s))
        stats = {
            "level": int(target.level), "merges": int(target.merges), "ratio": float(target.ratio),
            "cut": "uniform",
            "tets_decoded": 0 if decoded else int(st["tets_decoded"]), "tets_rendered": int(st["tets_rendered"]),
            "rays": int(st["rays"]), "rays_hit": int(st["rays_hit"]), "steps": int(st["steps"]),
            "samples": int(st["samples"]), "scale": scale, "step_factor": step_factor,
            "plan_s": t_plan - t0,
            "decode_s": float(st["decode_s"]), "filter_s": float(st["filter_s"]), "render_s": float(st["render_s"]),
            "encode_s": encode_s, "server_s": t_end - t0,
            "budget_s": req.budget_s, "predicted_s": predicted,
            "feasible": True if plan is None else plan.feasible,
            "full_quality": plan is None and req.level is None,
            "format": req.fmt, "bytes": len(data), "width": camera.width, "height": camera.height,
            "time_step": time_step, "time": float(self.series.steps.times[time_step]),
            "step_decode_s": step_decode_s, "step_predicted_s": step_s,
        }
        return Frame(rgb8, res.image, stats, data, FORMATS[req.fmt])


def _tf_json(tf) -> dict:
    return {"absolute": bool(tf.absolute), "unit_distance": float(tf.unit_distance),
            "color": [{"x": float(x), "rgb": [float(c) for c in rgb]} for x, rgb in zip(tf.color_x, tf.color_rgb)],
            "opacity": [{"x": float(x), "a": float(a)} for x, a in zip(tf.opacity_x, tf.opacity_a)]}


def colormap_tables(n: int = 17) -> dict:
    """Colour tables the page offers: matplotlib's common maps (when installed), ``n`` points each."""
    try:  # optional: matplotlib only widens the colormap choice
        import matplotlib
    except ImportError:
        return {}
    xs = np.linspace(0.0, 1.0, n)
    out = {}
    for name in COLORMAPS:
        try:
            rgb = np.asarray(matplotlib.colormaps[name](xs))[:, :3]
        except KeyError:
            continue
        out[name] = [{"x": float(x), "rgb": [round(float(c), 4) for c in row]} for x, row in zip(xs, rgb)]
    return out
