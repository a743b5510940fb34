"""Time-critical rendering (paper 5, 6.3): plan every frame against a time budget, no calibration pause.

A frame's time is modelled as the sum of its work, each kind at a cost per unit (Farias et al. adapt
such costs per frame):

* **decode**: per tet of the stored level decoded (0 when the level is already in memory), per
  vertex whose ancestor the run-time filter computes (the forest section and the top-down pass);
* **render**: per frame, per tet rendered, per ray-tet step, per sample, per boundary face, per
  pixel (ray set-up, boundary hits, image);
* **other**: a fixed part per frame and, for the viewer, the image encoding per pixel.

The costs are *seeded once per machine* (:func:`seed_costs`, about 0.2 s, cached in the user's cache
directory, :func:`machine_costs`): the reference machine's costs scaled by how fast this machine
decodes and renders a synthetic grid. They are then *corrected from every frame's measured stats*
(:meth:`TimeModel.observe`: one multiplicative correction per stage, smoothed, and for rendering one
per stored level). The work of a frame that has not been rendered yet is estimated from the file's
metadata and the view (:class:`WorkEstimator`): tets and boundary faces per stored level are in the
file; rays that hit, steps and samples per hit ray are learnt from the frames drawn (or from a tiny
probe render, :meth:`FramePlanner.probe`), and guessed from the bounding box before that.

Given a budget B, :func:`plan_for_budget` walks the stored levels from the finest: the first level
whose own predicted time fits is taken as is; if it does not fit but can be simplified on the fly far
enough before the next level starts, the finest such ratio is taken (starting from that level).
``tetc render --budget`` and the viewer (``tetc view``) use the same model; the viewer may also
coarsen the sample step and the image while the user drags (:data:`DRAG_SETTINGS`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numba
import numpy as np

from .._version import __version__
from ..codec import LevelPayload, TetcReader, encode_tetc
from ..codec.levelmeta import LevelMeta
from ..errors import OptionError
from ..mesh import mesh_batches
from ..mesh.synthetic import jittered_grid
from ..raycast.camera import Camera
from ..raycast.stream import render_batches
from ..simplify import ROOT_RANK, ancestors
from ..simplify.levels import Target, forest_merges, stored_levels
from .stream import file_render_defaults, render_tetc

MIN_LEARN_S = 2e-3  # a stage predicted below this (its variable part) does not correct the model
SEED_VERSION = 2  # bump when the seeding procedure changes: cached costs of older versions are re-seeded


@dataclass(frozen=True)
class LevelSize:
    """What the file says about one stored level."""

    level: int
    merges: int  # N_i: merges of the full forest applied in this stored level
    tets: int
    points: int = 0
    boundary_faces: int = 0
    has_forest: bool = True


@dataclass(frozen=True)
class Work:
    """Units of work of one frame (what the costs multiply)."""

    tets_decoded: float = 0.0  # tets the decoder produces (0 when the level is already in memory)
    forest_points: float = 0.0  # vertices whose ancestor the run-time filter computes (0: no filter)
    tets_rendered: float = 0.0  # tets inserted into the ray caster's face table (the visible ones)
    steps: float = 0.0  # ray-tet steps
    samples: float = 0.0
    boundary_faces: float = 0.0
    pixels: float = 0.0


@dataclass(frozen=True)
class Costs:
    """Seconds per unit of work (see the module docstring); ``render_fixed_s`` is per frame.

    The defaults are the reference machine's (2 cores, no GPU, where the project's figures are
    measured): a non-negative least-squares fit, on relative error, of 126 renders of the four
    samples (five levels each, 96² to 512², two sample steps) and of the seeding grid (the fit's
    quality is in ``bench/sections/pipeline.md``). Boundary faces and the fixed part come out near
    zero in the fit (their cost hides in the per-tet and per-step terms): both are given a small
    non-zero value here; the forest pass is the seeding grid's measured figure.
    """

    fixed_s: float = 2e-3
    per_tet_decoded: float = 5.0e-7
    per_forest_point: float = 1.5e-7
    render_fixed_s: float = 1e-3
    per_tet_rendered: float = 2.4e-7
    per_step: float = 3.4e-8
    per_sample: float = 1.4e-8
    per_boundary_face: float = 2e-8
    per_pixel: float = 3.8e-8
    decode_fixed_s: float = 2.3e-4  # opening the level's sections, the first batch

    def decode_s(self, w: Work) -> float:
        return self.decode_fixed_s + self.decode_variable_s(w)

    def decode_variable_s(self, w: Work) -> float:
        return self.per_tet_decoded * w.tets_decoded + self.per_forest_point * w.forest_points

    def render_s(self, w: Work) -> float:
        return self.render_fixed_s + self.render_variable_s(w)

    def render_variable_s(self, w: Work) -> float:
        return (self.per_tet_rendered * w.tets_rendered + self.per_step * w.steps + self.per_sample * w.samples
                + self.per_boundary_face * w.boundary_faces + self.per_pixel * w.pixels)

    def scaled(self, decode: float, render: float) -> "Costs":
        """These costs on a machine ``decode`` / ``render`` times as slow in each stage."""
        return Costs(self.fixed_s * render, self.per_tet_decoded * decode, self.per_forest_point * decode,
                     self.render_fixed_s * render, self.per_tet_rendered * render, self.per_step * render,
                     self.per_sample * render, self.per_boundary_face * render, self.per_pixel * render,
                     self.decode_fixed_s * decode)


@dataclass
class TimeModel:
    """Machine costs and this session's corrections: predicts a frame, learns from each one.

    Each stage (decode, render, fixed) has a multiplicative correction, updated after every frame
    from measured over predicted time (an exponential average of the logarithm, so one slow frame
    moves it part way and a change of regime takes a few frames); ``extra`` adds per-frame work
    that is not the pipeline's (the viewer's image encoding and transfer).

    Examples
    --------
    >>> m = TimeModel(replace(Costs(*[0.0] * 10), per_tet_decoded=1e-6))
    >>> w = Work(tets_decoded=1e5)
    >>> round(m.predict(w), 3)
    0.1
    >>> for _ in range(20):
    ...     m.observe(w, decode_s=0.2, render_s=0.0, other_s=0.0)
    >>> round(m.predict(w), 2)          # the machine turned out twice as slow: the model follows
    0.2
    """

    costs: Costs = field(default_factory=Costs)
    decode_scale: float = 1.0
    render_scale: float = 1.0
    fixed_s: float | None = None  # measured per-frame overhead (None: the seed's)
    per_pixel_extra: float = 0.0  # seconds per pixel outside the pipeline (encode, transfer)
    alpha: float = 0.35
    frames: int = 0
    # Render corrections per kind of frame (the viewer keys them by stored level): on a busy
    # machine a long frame loses more than a short one, so one factor for all would swing between
    # them. A kind never observed uses the overall factor.
    keyed_render_scale: dict = field(default_factory=dict)

    def predict_stages(self, w: Work, key=None) -> dict:
        fixed = self.costs.fixed_s if self.fixed_s is None else self.fixed_s
        return {"decode_s": self.decode_scale * self.costs.decode_s(w),
                "render_s": self.render_scale_for(key) * self.costs.render_s(w),
                "other_s": fixed + self.per_pixel_extra * w.pixels}

    def predict(self, w: Work, key=None) -> float:
        return sum(self.predict_stages(w, key).values())

    def corrected_costs(self) -> Costs:
        """The costs with this session's overall corrections applied (to cache for the next one)."""
        c = self.costs.scaled(self.decode_scale, self.render_scale)
        return replace(c, fixed_s=self.costs.fixed_s if self.fixed_s is None else self.fixed_s)

    def render_scale_for(self, key=None) -> float:
        """The render correction of ``key``; for a key never observed, that of the nearest observed
        key below it (keys order kinds of frames from costly to cheap: a stored level is costlier than
        the next one, and a costly frame's factor is the cautious guess), else above it, else the
        overall factor."""
        if key is None or not self.keyed_render_scale:
            return self.render_scale
        if key in self.keyed_render_scale:
            return self.keyed_render_scale[key]
        below = [k for k in self.keyed_render_scale if k < key]
        near = max(below) if below else min(self.keyed_render_scale)
        return max(self.keyed_render_scale[near], self.render_scale)

    def observe(self, w: Work, *, decode_s: float, render_s: float, other_s: float, extra_s: float = 0.0,
                key=None) -> None:
        """Correct the model with one frame's measured stage times (seconds)."""

        def update(scale, measured, predicted, variable):
            # A stage whose work is tiny measures mostly its fixed part and noise: nothing to learn.
            if variable * scale < MIN_LEARN_S or not math.isfinite(measured) or measured <= 0:
                return scale
            target = min(max(measured / predicted * scale, 1e-3), 1e3)
            return math.exp((1 - self.alpha) * math.log(scale) + self.alpha * math.log(target))

        c = self.costs
        self.decode_scale = update(self.decode_scale, decode_s, self.decode_scale * c.decode_s(w),
                                   c.decode_variable_s(w))
        if key is not None:
            k = self.render_scale_for(key)
            self.keyed_render_scale[key] = update(k, render_s, k * c.render_s(w), c.render_variable_s(w))
        self.render_scale = update(self.render_scale, render_s, self.render_scale * c.render_s(w),
                                   c.render_variable_s(w))
        fixed = self.costs.fixed_s if self.fixed_s is None else self.fixed_s
        if math.isfinite(other_s) and other_s >= 0:
            self.fixed_s = (1 - self.alpha) * fixed + self.alpha * other_s
        if w.pixels > 0 and math.isfinite(extra_s) and extra_s >= 0:
            self.per_pixel_extra = (1 - self.alpha) * self.per_pixel_extra + self.alpha * extra_s / w.pixels
        self.frames += 1


# -- estimating a frame's work before it is rendered ------------------------------------------------

def estimated_tets(levels: list[LevelSize], merges: int, attr: str = "tets") -> float:
    """Tets (or another per-level count) left after ``merges`` merges, interpolated between stored levels."""
    ls = sorted(levels, key=lambda x: x.merges)
    if merges <= ls[0].merges:
        return float(getattr(ls[0], attr))
    for lo, hi in zip(ls[:-1], ls[1:]):
        if merges <= hi.merges:
            f = (merges - lo.merges) / max(hi.merges - lo.merges, 1)
            return getattr(lo, attr) + f * (getattr(hi, attr) - getattr(lo, attr))
    return float(getattr(ls[-1], attr))


class WorkEstimator:
    """The work of a frame at a level and merge count, for one file and view.

    Before any frame of the view: rays that hit = the projected bounding box's share of the image
    (a rectangle, an overestimate); steps per hit ray = 1.5 * tets^(1/3) (a grid of n tets is about
    (n/6)^(1/3) cubes deep, 2-3 tets per cube); samples per hit ray = half the bounding-box diagonal
    over the sample step (volume mode) or the steps (face mode).

    :meth:`observe` keeps, per stored level, the last frame's share of rays that hit, steps per hit
    ray and samples per hit ray (at the file's step). A level observed is estimated from its own
    figures (steps scaled as tets^(1/3) for merges on the fly); one not observed from the observed
    levels on either side, interpolated in log(tets) - the cube-root rule alone is far off between
    a 6-tet and a 4,000-tet level, and a planner fed such guesses swings between them.

    The ray caster leaves out the tets the transfer function makes invisible (``tets_culled`` of
    the ``tets_rendered`` it received): the share that reaches the face table (the view's transfer
    function's, per level, latest frame) scales the tets of the estimate.
    """

    STEPS_PER_CUBE_ROOT = 1.5

    def __init__(self, levels: list[LevelSize], *, bbox, step: float, mode: str = "volume"):
        self.levels = sorted(levels, key=lambda x: x.merges)
        lo, hi = (np.asarray(x, np.float64) for x in bbox)
        self.bbox = (lo, hi)
        self.diagonal = float(np.linalg.norm(hi - lo)) or 1.0
        self.step = float(step) if step and step > 0 else self.diagonal / 100
        self.mode = mode
        self.seen: dict[int, tuple] = {}  # level -> (tets, hit fraction, steps per hit, samples per hit)
        self.visible: dict[int, float] = {}  # level -> share of its tets the transfer function leaves visible

    _latest_visible = 1.0

    @property
    def hit_fraction(self) -> float | None:
        """Share of rays that hit in the latest observed frame (None before any)."""
        return self._latest[1] if self.seen else None

    def coverage(self, fitted_camera) -> float:
        """Share of the image the bounding box covers (its projected rectangle, clipped)."""
        lo, hi = self.bbox
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        fwd = fitted_camera.basis()[0]
        if np.any((corners - fitted_camera.position) @ fwd <= 0):
            return 1.0  # the camera is inside the box
        px = fitted_camera.project(corners)
        w, h = fitted_camera.width, fitted_camera.height
        x0, x1 = np.clip([px[:, 0].min(), px[:, 0].max()], 0, w)
        y0, y1 = np.clip([px[:, 1].min(), px[:, 1].max()], 0, h)
        return float(max(x1 - x0, 0) * max(y1 - y0, 0) / (w * h))

    def _per_hit(self, level: int, tets: float):
        """(hit fraction, steps per hit ray, samples per hit ray) for ``tets`` tets from ``level``, or None."""
        if not self.seen:
            return None
        if level in self.seen:
            t0, hit, steps, samples = self.seen[level]
            return hit, steps * (tets / t0) ** (1 / 3), samples
        obs = sorted(self.seen.values())  # by tets
        below = [o for o in obs if o[0] <= tets]
        above = [o for o in obs if o[0] > tets]
        if below and above:
            (ta, ha, sa, ma), (tb, hb, sb, mb) = below[-1], above[0]
            f = math.log(tets / ta) / math.log(tb / ta) if tb > ta else 0.0
            lerp = lambda a, b: math.exp((1 - f) * math.log(max(a, 1e-9)) + f * math.log(max(b, 1e-9)))  # noqa: E731
            return lerp(ha, hb), lerp(sa, sb), lerp(ma, mb)
        t0, hit, steps, samples = below[-1] if below else above[0]
        return hit, steps * (tets / t0) ** (1 / 3), samples

    def estimate(self, start: LevelSize, merges: int, pixels: int, coverage: float = 1.0, *,
                 step_factor: float = 1.0, decoded: bool = False) -> Work:
        """Work of a frame from stored level ``start`` simplified to ``merges``, ``pixels`` rays, the
        sample step ``step_factor`` times the file's; ``decoded``: the level is already in memory."""
        tets = max(estimated_tets(self.levels, merges), 1.0)
        known = self._per_hit(start.level, tets)
        if known is None:
            hit = pixels * min(max(coverage, 0.0), 1.0)
            steps = hit * self.STEPS_PER_CUBE_ROOT * tets ** (1 / 3)
            samples = steps if self.mode == "face" else hit * 0.5 * self.diagonal / (self.step * step_factor)
        else:
            fraction, steps_per_hit, samples_per_hit = known
            hit = pixels * fraction
            steps = hit * steps_per_hit
            samples = steps if self.mode == "face" else hit * samples_per_hit / step_factor
        filtering = merges > start.merges
        shown = self.visible.get(start.level, self._latest_visible)
        return Work(0.0 if decoded else float(start.tets), float(start.points) if filtering else 0.0, tets * shown, steps,
                    samples, estimated_tets(self.levels, merges, "boundary_faces"), float(pixels))

    def observe(self, stats: dict, *, step_factor: float = 1.0) -> None:
        """Learn this view's rays hit, steps and samples at the frame's level from its stats."""
        rays, hit = int(stats.get("rays", 0)), int(stats.get("rays_hit", 0))
        if rays <= 0:
            return
        tets = max(int(stats.get("tets_rendered", 0)), 1)
        level = int(stats.get("level", 0))
        shown = tets - int(stats.get("tets_culled", 0))
        self.visible[level] = self._latest_visible = min(max(shown / tets, 0.0), 1.0)
        if hit > 0:
            entry = (float(tets), hit / rays, max(float(stats.get("steps", 0)), 1.0) / hit,
                     max(float(stats.get("samples", 0)), 1.0) * step_factor / hit)
        else:  # nothing in view: keep the counts per hit from before, if any
            prev = self.seen.get(level, (float(tets), 0.0, self.STEPS_PER_CUBE_ROOT * tets ** (1 / 3), 1.0))
            entry = (float(tets), 0.0, prev[2], prev[3])
        self.seen[level] = entry
        self._latest = entry


# -- planning ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class BudgetPlan:
    level: int  # stored level to start from
    merges: int  # target number of merges N (>= that level's N_i)
    predicted_s: float
    feasible: bool  # False: even the coarsest level is predicted to exceed the budget
    scale: float = 1.0  # image rendered at scale * the requested size (the viewer upscales)
    step_factor: float = 1.0  # sample step = step_factor * the file's


def plan_for_budget(levels: list[LevelSize], predict, budget_s: float, max_merges: int) -> BudgetPlan:
    """The finest simplification whose predicted frame time is within ``budget_s``.

    ``predict(i, merges)`` is the predicted frame time starting from stored level ``i`` (finest
    first) and simplifying on the fly to ``merges``; it is taken to shrink as ``merges`` grows.

    Examples
    --------
    >>> lv = [LevelSize(0, 0, 1000), LevelSize(1, 50, 500), LevelSize(2, 75, 250)]
    >>> def predict(i, n):                    # decode the start level, render what is left
    ...     return 1e-4 * lv[i].tets + 1e-4 * estimated_tets(lv, n)
    >>> plan_for_budget(lv, predict, 0.14, 80).level     # level 0 needs 0.15 s even at N = 50
    1
    >>> plan_for_budget(lv, predict, 0.19, 80).merges    # level 0 simplified on the fly, 900 tets
    10
    """
    ls = sorted(levels, key=lambda x: x.merges)
    for i, lv in enumerate(ls):
        t_own = predict(i, lv.merges)
        if t_own <= budget_s:
            return BudgetPlan(lv.level, lv.merges, t_own, True)
        end = ls[i + 1].merges if i + 1 < len(ls) else max_merges
        if not lv.has_forest or end <= lv.merges or predict(i, end) > budget_s:
            continue
        lo, hi = lv.merges, end  # t(lo) > budget >= t(hi): bisect for the smallest fitting N
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if predict(i, mid) <= budget_s:
                hi = mid
            else:
                lo = mid
        return BudgetPlan(lv.level, hi, predict(i, hi), True)
    last = len(ls) - 1
    end = max(max_merges if ls[last].has_forest else ls[last].merges, ls[last].merges)
    return BudgetPlan(ls[last].level, end, predict(last, end), False)


# While the user drags, levels alone cannot always reach the budget: samples and rays do not shrink
# with the mesh. The viewer then also coarsens the sample step and the image (upscaled on screen),
# in this order, taking the first setting whose plan fits without simplifying past MAX_DRAG_RATIO.
PROBE_PIXELS = 64 * 64
PROBE_TETS = 2000

DRAG_SETTINGS = ((1.0, 1.0), (1.0, 2.0), (1.0, 4.0), (0.75, 4.0), (0.5, 4.0), (0.35, 4.0), (0.25, 4.0))
MAX_DRAG_RATIO = 1 - 1 / 2 ** 9
# A still render with a budget (``tetc render --budget``) keeps the file's step and takes the
# finest level that fits at full size; only when even the coarsest level cannot, it renders a
# smaller image and scales it up, as the viewer does while dragging.
STILL_SETTINGS = ((1.0, 1.0), (0.75, 1.0), (0.5, 1.0), (0.35, 1.0), (0.25, 1.0))


class FramePlanner:
    """Plans the frames of one open file: levels from its metadata, a :class:`TimeModel` and a
    :class:`WorkEstimator` for its view. The viewer keeps one per session and render mode; ``tetc
    render --budget`` builds one for its single frame.

    Parameters
    ----------
    reader : TetcReader
    model : TimeModel
    step : float
        The file's volume-mode sample step.
    mode : {"volume", "face"}
    decoded : callable, optional
        ``decoded(level)`` is True when that level is already in memory (no decoding cost).
    """

    def __init__(self, reader, model: TimeModel, *, step: float, mode: str = "volume", decoded=None):
        self.model = model
        self.levels = levels_of(stored_levels(reader))
        self.max_merges = int(forest_merges(reader))
        self.points = int(reader.meta["points"])
        self.estimator = WorkEstimator(self.levels, bbox=reader.meta["bbox"], step=step, mode=mode)
        self.decoded = decoded or (lambda level: False)

    def level_size(self, level: int) -> LevelSize:
        return next(lv for lv in self.levels if lv.level == level)

    def probe(self, reader, view, *, pixels: int = PROBE_PIXELS) -> list[dict]:
        """Learn the view's rays hit, steps and samples from tiny renders (a few milliseconds).

        Two levels, the coarsest and the coarsest with at least :data:`PROBE_TETS` tets, at about
        ``pixels`` rays with the image's aspect: their counts, scaled, stand in for the frame's until
        frames of this view have been drawn (in between and beyond, :class:`WorkEstimator`
        interpolates). Returns the probes' stats.
        """
        fine = next((x for x in reversed(self.levels) if x.tets >= PROBE_TETS), self.levels[0])
        cam = view.camera
        scale = min(1.0, math.sqrt(pixels / (cam.width * cam.height)))
        small = replace(cam, width=max(1, round(cam.width * scale)), height=max(1, round(cam.height * scale)))
        out = []
        threads = numba.get_num_threads()
        # One thread: starting a parallel region costs more than these renders' work, and far more
        # when the machine is busy (a 32² render: 1.5 ms on one thread, 40-60 ms on two under load).
        numba.set_num_threads(1)
        try:
            for lv in sorted({fine.level, self.levels[-1].level}):
                stats = render_tetc(reader, replace(view, camera=small, lean=False), level=lv).stats
                self.estimator.observe(stats, step_factor=1.0)
                out.append(stats)
        finally:
            numba.set_num_threads(threads)
        return out

    def estimate(self, level: int, merges: int, pixels: int, coverage: float, step_factor: float = 1.0) -> Work:
        return self.estimator.estimate(self.level_size(level), merges, pixels, coverage, step_factor=step_factor,
                                       decoded=self.decoded(level))

    def plan(self, budget_s: float, fitted_camera, *, drag: bool = False, rescale: bool = False) -> BudgetPlan:
        """The finest frame predicted to fit ``budget_s``; ``drag``: also coarsen step and image
        (:data:`DRAG_SETTINGS`); ``rescale``: also shrink the image when no level fits at full size
        (:data:`STILL_SETTINGS`)."""
        if not (isinstance(budget_s, (int, float)) and math.isfinite(budget_s) and budget_s > 0):
            raise OptionError(f"the budget must be a positive number of seconds, got {budget_s!r}")
        coverage = self.estimator.coverage(fitted_camera)
        first = None
        for scale, step_factor in (DRAG_SETTINGS if drag else STILL_SETTINGS if rescale else DRAG_SETTINGS[:1]):
            px = max(int(round(fitted_camera.width * scale)), 1) * max(int(round(fitted_camera.height * scale)), 1)
            plan = plan_for_budget(
                self.levels, lambda i, n: self.model.predict(self.estimate(self.levels[i].level, n, px, coverage,
                                                                           step_factor), key=self.levels[i].level),
                float(budget_s), self.max_merges)
            plan = BudgetPlan(plan.level, plan.merges, plan.predicted_s, plan.feasible, scale, step_factor)
            if plan.feasible and (not drag or plan.merges <= MAX_DRAG_RATIO * self.points):
                return plan
            if first is None or (plan.feasible and not first.feasible):
                first = plan
            elif not first.feasible and not plan.feasible and plan.predicted_s < first.predicted_s:
                first = plan
        return first

    def target(self, plan: BudgetPlan):
        start = self.level_size(plan.level)
        merges = plan.merges if start.has_forest else start.merges
        return Target(plan.level, merges, merges / max(self.points, 1), start.merges)

    def work_of(self, stats: dict, *, decoded: bool = False) -> Work:
        """The work a rendered frame did (``decoded``: its level came from memory)."""
        start = self.level_size(int(stats["level"]))
        filtering = int(stats["merges"]) > start.merges
        return Work(0.0 if decoded else float(stats["tets_decoded"]), float(start.points) if filtering else 0.0,
                    float(stats["tets_rendered"]) - float(stats.get("tets_culled", 0)), float(stats["steps"]),
                    float(stats["samples"]),
                    estimated_tets(self.levels, int(stats["merges"]), "boundary_faces"), float(stats["rays"]))

    def observe(self, stats: dict, *, total_s: float, extra_s: float = 0.0, step_factor: float = 1.0,
                decoded: bool = False) -> Work:
        """Correct the model and the view's work estimate from a rendered frame's stats.

        ``total_s`` is the whole frame; ``extra_s`` the part outside the pipeline that grows with
        the pixels (the viewer's image encoding).
        """
        w = self.work_of(stats, decoded=decoded)
        decode_s = stats.get("decode_s", 0.0) + stats.get("filter_s", 0.0)
        render_s = stats.get("render_s", 0.0)
        other = max(total_s - decode_s - render_s - extra_s, 0.0)
        self.model.observe(w, decode_s=decode_s, render_s=render_s, other_s=other, extra_s=extra_s,
                           key=int(stats["level"]))
        self.estimator.observe(stats, step_factor=step_factor)
        return w


def levels_of(stored: list[LevelMeta]) -> list[LevelSize]:
    return sorted((LevelSize(lv.level, lv.merges_before, lv.tets, lv.points, lv.boundary_faces, lv.has_forest)
                   for lv in stored), key=lambda x: x.merges)


# -- seeding the costs once per machine ----------------------------------------------------------------

def cache_dir() -> Path:
    """Where the machine's costs live: $TETC_CACHE_DIR, else $XDG_CACHE_HOME/tetc, else ~/.cache/tetc."""
    if os.environ.get("TETC_CACHE_DIR"):
        return Path(os.environ["TETC_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "tetc"


def machine_key() -> str:
    text = (f"{platform.node()}|{platform.machine()}|{platform.processor()}|{os.cpu_count()}|"
            f"{os.environ.get('NUMBA_NUM_THREADS', '')}|{__version__}|{SEED_VERSION}")
    return hashlib.sha1(text.encode()).hexdigest()[:20]


def load_costs(key: str | None = None) -> Costs | None:
    """The cached costs of this machine (None if absent or damaged)."""
    key = key or machine_key()
    try:
        data = json.loads((cache_dir() / "costs.json").read_text())
        entry = data[key]
        costs = Costs(**{f.name: float(entry[f.name]) for f in fields(Costs)})
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not all(math.isfinite(v) and v >= 0 for v in asdict(costs).values()):
        return None
    return costs


def save_costs(costs: Costs, key: str | None = None) -> None:
    key = key or machine_key()
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
        path = d / "costs.json"
        try:
            data = json.loads(path.read_text())
            if not isinstance(data, dict):
                data = {}
        except (OSError, ValueError):
            data = {}
        data[key] = asdict(costs)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(json.dumps(data, indent=1))
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only home only costs a re-seed next time


def _seed_grid(n: int):
    """A jittered n x n x n grid split into tets, with a smooth scalar (the seeding mesh)."""
    return jittered_grid((n, n, n), jitter=0.2, scalar=(0.7, 0.2, 0.1))


def seed_costs(*, repeats: int = 3) -> Costs:
    """How fast this machine is, in a few tenths of a second: the reference costs, scaled.

    The ratios between the costs are properties of the code (measured once on the reference
    machine, :class:`Costs`' defaults); what differs between machines is mostly their speed. So
    the seed times the decoder and the streaming ray caster on a synthetic 15³ grid (13.7 k tets, a
    few image sizes and sample steps, best of ``repeats``) and scales the reference costs of each
    stage by measured / predicted. The frames a user renders then correct the rest
    (:meth:`TimeModel.observe`).
    """
    ref = Costs()
    big, small = _seed_grid(15), _seed_grid(9)
    # A forest where the first half of the vertices merge into the second half, in id order.
    half = big.n_points // 2
    parent = np.arange(big.n_points, dtype=np.int32)
    rank = np.full(big.n_points, ROOT_RANK, np.int32)
    parent[:half] = np.arange(half, 2 * half, dtype=np.int32)
    rank[:half] = np.arange(half, dtype=np.int32)
    reader = TetcReader(encode_tetc([LevelPayload(0, 0.0, 0, big, (parent, rank))]))

    def best_of(fn):
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t0)
        return best

    # one thread, as the reference costs were measured: with a second core the streaming render's
    # connectivity decodes ahead in a thread of its own, so a frame takes at most this plan
    decode_s = best_of(lambda: (reader.decode_mesh(0, jobs=1), ancestors(*reader.read_forest(0), half)))
    decode_scale = decode_s / ref.decode_s(Work(tets_decoded=big.n_tets, forest_points=big.n_points))

    step0 = float(np.linalg.norm(big.bbox[1] - big.bbox[0])) / 60
    ratios = []
    for mesh, size, step in ((big, 48, step0), (big, 96, step0 / 4), (small, 96, step0)):
        runs = [render_batches(mesh_batches(mesh), Camera(size, size, 30, 20), "default", step=step,
                               scalar_range=mesh.scalar_range).stats for _ in range(repeats)]
        st = min(runs, key=lambda r: r["render_s"])
        w = Work(0.0, 0.0, st["tets_rendered"] - st.get("tets_culled", 0), st["steps"], st["samples"],
                 len(mesh.boundary_faces()), st["rays"])
        ratios.append(st["render_s"] / ref.render_s(w))
    return ref.scaled(decode_scale, float(np.median(ratios)))


def machine_costs(*, reseed: bool = False) -> tuple[Costs, bool]:
    """(the costs of this machine, seeded_now): from the cache, else seeded and cached."""
    costs = None if reseed else load_costs()
    if costs is not None:
        return costs, False
    costs = seed_costs()
    save_costs(costs)
    return costs, True


# -- planning one file's render (tetc render --budget) ---------------------------------------------

PNG_S_PER_PIXEL = 5e-8  # writing the 8-bit PNG (zlib level 6), reference machine


def plan_file_budget(path_or_reader, view, budget_s: float, *, reseed: bool = False):
    """(Target, BudgetPlan, FramePlanner, seeded_now) for rendering a file within ``budget_s``.

    The budget covers the whole command from opening the file to the PNG written: what opening
    the file and the probe took is taken off it before planning. The seeding of the machine's
    costs (once per machine, the first budget render) is not: under a second, it would leave a
    budget of a few tenths nothing, and the frame would miss its budget anyway, drawn from the
    coarsest level at a fraction of its size (a 0.3 s budget on the 0.8 M-tet gmsh flange: 76
    tets at 64x64 instead of level 3's 59,837 tets at 256x256). When even the coarsest level cannot
    make it at the requested size, ``plan.scale < 1`` asks for a smaller image, to be scaled up.
    """
    if not (isinstance(budget_s, (int, float)) and math.isfinite(float(budget_s)) and budget_s >= 0):
        raise OptionError(f"--budget must be a number of seconds >= 0, got {budget_s}")
    t0 = time.perf_counter()
    reader = path_or_reader if isinstance(path_or_reader, TetcReader) else TetcReader(path_or_reader)
    t_seed = time.perf_counter()
    costs, seeded = machine_costs(reseed=reseed)
    t0 += time.perf_counter() - t_seed if seeded else 0.0
    lo, hi, _rng, step = file_render_defaults(reader)
    png_s = PNG_S_PER_PIXEL * costs.per_step / Costs().per_step  # as much faster or slower as rendering
    planner = FramePlanner(reader, TimeModel(costs, per_pixel_extra=png_s), step=view.step or step, mode=view.mode)
    planner.probe(reader, view)
    left = max(float(budget_s) - (time.perf_counter() - t0), 1e-3)
    plan = planner.plan(left, view.camera.fit(lo, hi), rescale=True)
    return planner.target(plan), plan, planner, seeded


def remember_frame(planner: FramePlanner, stats: dict, *, total_s: float) -> None:
    """Correct the machine's cached costs with a frame just rendered by ``tetc render --budget``.

    ``total_s``: from the start of the render to the PNG written. Each budget render moves the
    cached costs part way toward what it measured, so a seed taken while the machine was busy (or
    idle) does not mislead every later run.
    """
    planner.observe(stats, total_s=total_s)
    save_costs(planner.model.corrected_costs())


__all__ = ["remember_frame", "LevelSize", "Work", "Costs", "TimeModel", "WorkEstimator", "BudgetPlan", "plan_for_budget",
           "FramePlanner", "estimated_tets", "levels_of", "machine_costs", "seed_costs", "load_costs",
           "save_costs", "cache_dir", "plan_file_budget"]
